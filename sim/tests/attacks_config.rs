//! Attack specs: TOML schema, validation messages, windows, activity and the fault-pattern check.

use ftcbf_sim::attacks::{
    validate_attacks, AttackKind, AttackSpec, AttackStack, Direction, NonFiniteValue,
};
use ftcbf_sim::sensors::{ChannelSpec, FaultPatternSpec, Quantity, SensorSuite};
use serde::Deserialize;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Doc {
    attacks: Vec<AttackSpec>,
}

fn parse(s: &str) -> Result<Vec<AttackSpec>, toml::de::Error> {
    toml::from_str::<Doc>(s).map(|d| d.attacks)
}

fn suite() -> SensorSuite {
    let specs = [
        ChannelSpec::new("gnss1_x", Quantity::X, 0.03),
        ChannelSpec::new("gnss1_y", Quantity::Y, 0.03),
        ChannelSpec::new("gnss2_x", Quantity::X, 0.03),
        ChannelSpec::new("gnss2_y", Quantity::Y, 0.03),
        ChannelSpec::new("odom_vx", Quantity::Vx, 0.01),
        ChannelSpec::new("odom_vy", Quantity::Vy, 0.01),
    ];
    SensorSuite::new(&specs, 0.02, 1).unwrap()
}

const ALL_KINDS: &str = r#"
[[attacks]]
kind = "bias"
channels = ["gnss2_y"]
start = 0.0
end = 20.0
value = 1.0

[[attacks]]
kind = "drift"
channels = ["gnss2_x"]
start = 1.0
rate = 0.05
cap = 0.5

[[attacks]]
kind = "sinusoid"
label = "wobble"
channels = ["gnss1_x"]
amplitude = 0.2
frequency_hz = 0.5

[[attacks]]
kind = "stuck_at"
channels = ["odom_vx"]
start = 3.0

[[attacks]]
kind = "replay"
channels = ["gnss1_x", "gnss1_y"]
start = 10.0
end = 15.0
record_start = 2.0
length = 3.0

[[attacks]]
kind = "denial_of_service"
channels = ["odom_vy"]
start = 4.0
end = 5.0

[[attacks]]
kind = "scale"
channels = ["odom_vx"]
factor = 1.5

[[attacks]]
kind = "spikes"
channels = ["gnss1_y"]
probability = 0.01
magnitude = 3.0

[[attacks]]
kind = "non_finite"
channels = ["gnss2_x"]
start = 30.0
value = "-inf"

[[attacks]]
kind = "absurd"
channels = ["gnss2_y"]
start = 31.0

[[attacks]]
kind = "stealthy"
channels = ["gnss2_y"]
start = 5.0
max_rate = 0.1
threshold = 3.0
direction = "negative"

[[attacks]]
kind = "coordinated"
channels = ["gnss2_x", "gnss2_y"]
start = 8.0
velocity = [0.1, -0.05]
cap = 2.0
"#;

#[test]
fn every_kind_parses_with_defaults_and_aliases() {
    let specs = parse(ALL_KINDS).unwrap();
    assert_eq!(specs.len(), 12);
    assert_eq!(specs[0].kind, AttackKind::Bias { value: 1.0 });
    assert_eq!((specs[0].start, specs[0].end), (0.0, Some(20.0)));
    assert_eq!(
        specs[1].kind,
        AttackKind::Ramp {
            rate: 0.05,
            cap: Some(0.5)
        }
    );
    assert_eq!(
        specs[2].kind,
        AttackKind::Sinusoid {
            amplitude: 0.2,
            frequency_hz: 0.5,
            phase: 0.0
        }
    );
    assert_eq!(
        (specs[2].start, specs[2].end),
        (0.0, None),
        "start defaults to 0, end to forever"
    );
    assert_eq!(specs[2].label.as_deref(), Some("wobble"));
    assert_eq!(specs[3].kind, AttackKind::Freeze { value: None });
    assert_eq!(
        specs[4].kind,
        AttackKind::Replay {
            record_start: 2.0,
            length: 3.0
        }
    );
    assert_eq!(specs[5].kind, AttackKind::Dropout {});
    assert_eq!(
        specs[8].kind,
        AttackKind::NonFinite {
            value: NonFiniteValue::NegInf
        }
    );
    assert_eq!(specs[9].kind, AttackKind::Absurd { value: 1e12 });
    assert_eq!(
        specs[10].kind,
        AttackKind::Stealthy {
            max_rate: 0.1,
            threshold: 3.0,
            direction: Direction::Negative,
            max_bias: None
        }
    );
    assert_eq!(
        specs[11].kind,
        AttackKind::Coordinated {
            velocity: vec![0.1, -0.05],
            cap: Some(2.0)
        }
    );
    let stack = AttackStack::new(&specs, &suite(), 0).unwrap();
    assert_eq!(stack.len(), 12);
    // Round trip through TOML (Serialize is the same flat shape).
    let text = toml::to_string(&Doc2 {
        attacks: specs.clone(),
    })
    .unwrap();
    assert_eq!(parse(&text).unwrap(), specs);
}

#[derive(serde::Serialize)]
struct Doc2 {
    attacks: Vec<AttackSpec>,
}

#[test]
fn schema_errors_name_the_key() {
    let e = parse("[[attacks]]\nkind = \"bias\"\nchannels = [\"a\"]\nvalue = 1.0\nvalu = 2.0\n")
        .unwrap_err()
        .to_string();
    println!("{e}");
    assert!(e.contains("valu"), "{e}");
    let e = parse("[[attacks]]\nkind = \"bias\"\nchannels = [\"a\"]\nvalue = 1.0\nrate = 2.0\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("rate"), "{e}");
    let e = parse("[[attacks]]\nkind = \"teleport\"\nchannels = [\"a\"]\n")
        .unwrap_err()
        .to_string();
    println!("{e}");
    assert!(e.contains("teleport") && e.contains("stealthy"), "{e}");
    let e = parse("[[attacks]]\nkind = \"bias\"\nchannels = [\"a\"]\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("value"), "{e}");
    let e = parse("[[attacks]]\nkind = \"non_finite\"\nchannels = [\"a\"]\nvalue = \"huge\"\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("huge") && e.contains("nan"), "{e}");
}

fn err(toml_text: &str) -> String {
    let specs = parse(toml_text).unwrap();
    let msg = AttackStack::new(&specs, &suite(), 0)
        .unwrap_err()
        .to_string();
    println!("{msg}");
    msg
}

#[test]
fn validation_messages() {
    let m = err("[[attacks]]\nkind = \"bias\"\nchannels = [\"gnss9_y\"]\nvalue = 1.0\n");
    assert!(
        m.contains("attacks[0]")
            && m.contains("\"bias\"")
            && m.contains("unknown sensor channel \"gnss9_y\"")
            && m.contains("\"gnss2_y\""),
        "{m}"
    );
    let m = err("[[attacks]]\nkind = \"bias\"\nchannels = []\nvalue = 1.0\n");
    assert!(m.contains("`channels` is empty"), "{m}");
    let m =
        err("[[attacks]]\nkind = \"bias\"\nchannels = [\"gnss2_y\", \"gnss2_y\"]\nvalue = 1.0\n");
    assert!(m.contains("listed twice"), "{m}");
    let m = err("[[attacks]]\nkind = \"bias\"\nlabel = \"y4\"\nchannels = [\"gnss2_y\"]\nstart = 5.0\nend = 5.0\nvalue = 1.0\n");
    assert!(
        m.contains("label \"y4\"")
            && m.contains("end = 5 s")
            && m.contains("greater than start = 5 s"),
        "{m}"
    );
    let m = err("[[attacks]]\nkind = \"bias\"\nchannels = [\"gnss2_y\"]\nstart = 5.0\nend = 2.0\nvalue = 1.0\n");
    assert!(m.contains("end = 2 s"), "{m}");
    let m = err("[[attacks]]\nkind = \"spikes\"\nchannels = [\"gnss2_y\"]\nprobability = 1.2\nmagnitude = 1.0\n");
    assert!(
        m.contains("`probability` = 1.2") && m.contains("[0, 1]"),
        "{m}"
    );
    let m = err("[[attacks]]\nkind = \"stealthy\"\nchannels = [\"gnss2_y\"]\nmax_rate = -0.1\nthreshold = 3.0\n");
    assert!(m.contains("`max_rate` = -0.1") && m.contains("> 0"), "{m}");
    let m = err("[[attacks]]\nkind = \"stealthy\"\nchannels = [\"gnss2_y\"]\nmax_rate = 0.1\nthreshold = 0.0\n");
    assert!(m.contains("`threshold` = 0"), "{m}");
    let m = err("[[attacks]]\nkind = \"ramp\"\nchannels = [\"gnss2_y\"]\nrate = 0.1\ncap = -1.0\n");
    assert!(m.contains("`cap` = -1"), "{m}");
    let m = err("[[attacks]]\nkind = \"sinusoid\"\nchannels = [\"gnss2_y\"]\namplitude = 1.0\nfrequency_hz = -2.0\n");
    assert!(m.contains("frequency_hz"), "{m}");
    let m = err("[[attacks]]\nkind = \"coordinated\"\nchannels = [\"gnss2_x\", \"gnss2_y\"]\nvelocity = [0.1]\n");
    assert!(
        m.contains("`velocity` has 1 components but `channels` has 2"),
        "{m}"
    );
    let m = err("[[attacks]]\nkind = \"replay\"\nchannels = [\"gnss2_y\"]\nstart = 3.0\nrecord_start = 2.0\nlength = 2.0\n");
    assert!(
        m.contains("records [2, 4) s") && m.contains("start = 3 s"),
        "{m}"
    );
    let m = err("[[attacks]]\nkind = \"replay\"\nchannels = [\"gnss2_y\"]\nstart = 3.0\nrecord_start = 2.0\nlength = 0.0\n");
    assert!(m.contains("`length` = 0"), "{m}");
    let m = err("[[attacks]]\nkind = \"bias\"\nchannels = [\"gnss2_y\"]\nvalue = nan\n");
    assert!(m.contains("`value` = NaN") && m.contains("finite"), "{m}");
    // The second attack is the bad one: the index says so.
    let m = err("[[attacks]]\nkind = \"dropout\"\nchannels = [\"gnss2_y\"]\n[[attacks]]\nkind = \"scale\"\nchannels = [\"gnss2_y\"]\nfactor = inf\n");
    assert!(m.contains("attacks[1]") && m.contains("factor"), "{m}");
    // The free function gives the same result without building a suite.
    let specs =
        parse("[[attacks]]\nkind = \"dropout\"\nchannels = [\"gnss2_y\", \"gnss1_x\"]\n").unwrap();
    assert_eq!(
        validate_attacks(&specs, suite().specs()).unwrap(),
        vec![vec![3, 0]]
    );
}

#[test]
fn windows_active_and_fault_pattern_membership() {
    let specs = parse(ALL_KINDS).unwrap();
    let suite = suite();
    let stack = AttackStack::new(&specs, &suite, 0).unwrap();
    let w = stack.windows();
    assert_eq!(w[0], ("bias[gnss2_y]".to_string(), 0.0, Some(20.0)));
    assert_eq!(w[2], ("wobble".to_string(), 0.0, None));
    assert_eq!(
        w[4],
        ("replay[gnss1_x,gnss1_y]".to_string(), 10.0, Some(15.0))
    );
    // At t = 4.5: bias, drift, sinusoid, stuck_at, dos [4,5), scale, spikes.
    assert_eq!(
        stack.active(4.5).collect::<Vec<_>>(),
        vec![0, 1, 2, 3, 5, 6, 7]
    );
    // [start, end): active at start, inactive at end (with k·dt rounding tolerated).
    assert!(stack.active(4.0).any(|i| i == 5));
    assert!(!stack.active(5.0).any(|i| i == 5));
    assert!(
        stack.active(0.1 + 0.2 + 3.7).any(|i| i == 5),
        "4.000000000000001 is in [4, 5)"
    );
    assert!(
        stack.active(5.0 - 1e-12).all(|i| i != 5),
        "a rounding error below the end is outside"
    );
    assert_eq!(stack.active(20.0).filter(|&i| i == 0).count(), 0);

    let patterns = [
        FaultPatternSpec {
            name: "gnss1".into(),
            channels: vec!["gnss1_x".into(), "gnss1_y".into()],
        },
        FaultPatternSpec {
            name: "gnss2".into(),
            channels: vec!["gnss2_x".into(), "gnss2_y".into()],
        },
    ];
    let resolved = suite.resolve_patterns(&patterns).unwrap();
    // odom channels belong to no pattern: stuck_at (3), dos (5), scale (6) are outside.
    assert_eq!(stack.outside_fault_patterns(&resolved), vec![3, 5, 6]);
    // A replay over gnss1_x + gnss2_x spans two patterns: outside.
    let cross =
        parse("[[attacks]]\nkind = \"bias\"\nchannels = [\"gnss1_x\", \"gnss2_x\"]\nvalue = 1.0\n")
            .unwrap();
    let stack = AttackStack::new(&cross, &suite, 0).unwrap();
    assert_eq!(stack.outside_fault_patterns(&resolved), vec![0]);
    assert_eq!(stack.targets(0), Some(&[0usize, 2][..]));
}

#[test]
fn attacks_that_together_span_two_fault_patterns_are_outside_the_model() {
    let suite = suite();
    let single = |names: &[&str]| {
        names
            .iter()
            .map(|n| FaultPatternSpec {
                name: (*n).into(),
                channels: vec![(*n).into()],
            })
            .collect::<Vec<_>>()
    };
    // Patterns {gnss2_x} and {gnss2_y}: each attack alone lies in one of them.
    let patterns = suite
        .resolve_patterns(&single(&["gnss2_x", "gnss2_y"]))
        .unwrap();
    let two = parse(
        "[[attacks]]\nkind = \"bias\"\nchannels = [\"gnss2_y\"]\nvalue = 0.3\n\n\
         [[attacks]]\nkind = \"absurd\"\nchannels = [\"gnss2_x\"]\nstart = 5.0\nvalue = 1e9\n",
    )
    .unwrap();
    let stack = AttackStack::new(&two, &suite, 0).unwrap();
    assert!(
        stack.outside_fault_patterns(&patterns).is_empty(),
        "each attack alone is inside"
    );
    assert!(
        stack.union_outside_fault_patterns(&patterns),
        "together they touch two patterns"
    );
    // Windows that never overlap still count: the pattern r is fixed for the whole run.
    let apart = parse(
        "[[attacks]]\nkind = \"bias\"\nchannels = [\"gnss2_y\"]\nstart = 0.0\nend = 2.0\nvalue = 0.3\n\n\
         [[attacks]]\nkind = \"bias\"\nchannels = [\"gnss2_x\"]\nstart = 10.0\nend = 12.0\nvalue = 0.3\n",
    )
    .unwrap();
    let stack = AttackStack::new(&apart, &suite, 0).unwrap();
    assert!(stack.union_outside_fault_patterns(&patterns));
    // With one pattern {gnss2_x, gnss2_y} the same attacks are inside the model.
    let joint = suite
        .resolve_patterns(&[FaultPatternSpec {
            name: "gnss2".into(),
            channels: vec!["gnss2_x".into(), "gnss2_y".into()],
        }])
        .unwrap();
    assert!(!stack.union_outside_fault_patterns(&joint));
    // Two attacks on the same channel, and no attack at all, are inside.
    let same = parse(
        "[[attacks]]\nkind = \"bias\"\nchannels = [\"gnss2_y\"]\nvalue = 0.3\n\n\
         [[attacks]]\nkind = \"absurd\"\nchannels = [\"gnss2_y\"]\nstart = 5.0\nvalue = 1e9\n",
    )
    .unwrap();
    let stack = AttackStack::new(&same, &suite, 0).unwrap();
    assert!(!stack.union_outside_fault_patterns(&patterns));
    let none = AttackStack::new(&[], &suite, 0).unwrap();
    assert!(!none.union_outside_fault_patterns(&patterns));
}
