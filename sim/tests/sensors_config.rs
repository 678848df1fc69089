//! Sensor suite configuration (TOML schema, validation messages, fault patterns), sample timing and
//! reproducibility of the noise streams.

use ftcbf_sim::sensors::{
    resolve_patterns, ChannelSpec, FaultPatternSpec, Quantity, Sample, SensorError, SensorSuite,
};
use ftcbf_sim::state::TruthState;
use serde::Deserialize;

const DT: f64 = 0.02;

/// The shape a world file embeds.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Doc {
    sensors: Vec<ChannelSpec>,
    #[serde(default)]
    fault_patterns: Vec<FaultPatternSpec>,
}

fn parse(s: &str) -> Result<Doc, toml::de::Error> {
    toml::from_str(s)
}

/// The suite of eq. 6.5 (x, x, y, y, ẋ, ẏ) plus the attack-free heading, and the fault patterns of
/// §6.2 (F(r₁) = {2}, F(r₂) = {4}, 1-based).
const PAPER: &str = r#"
[[sensors]]
name = "x1"
measures = "x"
noise_std = 0.0316
[[sensors]]
name = "x2"
measures = "x"
noise_std = 0.0316
[[sensors]]
name = "y1"
measures = "y"
noise_std = 0.0316
[[sensors]]
name = "y2"
measures = "y"
noise_std = 0.0316
[[sensors]]
name = "vx"
measures = "vx"
noise_std = 0.0316
[[sensors]]
name = "vy"
measures = "vy"
noise_std = 0.0316
[[sensors]]
name = "heading"
measures = "heading"
noise_std = 0.0

[[fault_patterns]]
name = "r1"
channels = ["x2"]
[[fault_patterns]]
name = "r2"
channels = ["y2"]
"#;

fn truth(t: f64) -> TruthState {
    TruthState {
        t,
        x: 1.0 + 0.1 * t,
        y: 0.5 * t.sin(),
        theta: 0.3,
        vx: 0.1,
        vy: 0.5 * t.cos(),
        v_body: 0.2,
        omega: 0.0,
        ..Default::default()
    }
}

#[test]
fn paper_suite_parses_and_resolves() {
    let doc = parse(PAPER).unwrap();
    let suite = SensorSuite::new(&doc.sensors, DT, 1).unwrap();
    assert_eq!(suite.len(), 7);
    assert_eq!(suite.specs()[4].measures, Quantity::Vx);
    assert_eq!(suite.channel_index("y2"), Some(3));
    assert_eq!(suite.channel_index("nope"), None);
    // Defaults of the optional fields.
    let s = &suite.specs()[0];
    assert_eq!(
        (s.bias, s.bias_walk_std, s.dropout_prob, s.rate_hz),
        (0.0, 0.0, 0.0, None)
    );
    assert_eq!(
        suite.resolve_patterns(&doc.fault_patterns).unwrap(),
        vec![vec![1], vec![3]]
    );
}

#[test]
fn three_fix_suite_with_all_optional_fields() {
    let mut toml_text = String::new();
    for fix in 1..=3 {
        for axis in ["x", "y"] {
            toml_text.push_str(&format!(
                "[[sensors]]\nname = \"gnss{fix}_{axis}\"\nmeasures = \"{axis}\"\nnoise_std = 0.03\n\
                 bias = 0.01\nbias_walk_std = 0.002\nrate_hz = 10.0\ndropout_prob = 0.05\n"
            ));
        }
    }
    toml_text
        .push_str("[[sensors]]\nname = \"gyro\"\nmeasures = \"yaw_rate\"\nnoise_std = 0.001\n");
    toml_text.push_str("[[sensors]]\nname = \"wheel_v\"\nmeasures = \"speed\"\nnoise_std = 0.01\n");
    for fix in 1..=3 {
        toml_text.push_str(&format!(
            "[[fault_patterns]]\nname = \"gnss{fix}\"\nchannels = [\"gnss{fix}_x\", \"gnss{fix}_y\"]\n"
        ));
    }
    let doc = parse(&toml_text).unwrap();
    let suite = SensorSuite::new(&doc.sensors, DT, 1).unwrap();
    assert_eq!(suite.specs()[2].rate_hz, Some(10.0));
    assert_eq!(suite.specs()[7].measures, Quantity::Speed);
    assert_eq!(
        suite.resolve_patterns(&doc.fault_patterns).unwrap(),
        vec![vec![0, 1], vec![2, 3], vec![4, 5]]
    );
}

fn err_of(specs: &[ChannelSpec]) -> String {
    SensorSuite::new(specs, DT, 0).unwrap_err().to_string()
}

#[test]
fn validation_messages_name_channel_field_and_expectation() {
    let ok = ChannelSpec::new("a", Quantity::X, 0.1);
    // Duplicate channel.
    let msg = err_of(&[
        ok.clone(),
        ChannelSpec::new("b", Quantity::Y, 0.1),
        ok.clone(),
    ]);
    println!("{msg}");
    assert!(
        msg.contains("\"a\"")
            && msg.contains("twice")
            && msg.contains("sensors[0]")
            && msg.contains("sensors[2]"),
        "{msg}"
    );
    // Negative / non-finite noise.
    let msg = err_of(&[ChannelSpec::new("gnss1_x", Quantity::X, -0.1)]);
    println!("{msg}");
    assert!(
        msg.contains("\"gnss1_x\"")
            && msg.contains("noise_std")
            && msg.contains("-0.1")
            && msg.contains(">= 0"),
        "{msg}"
    );
    // NaN is how an absent noise_std reads (only a `from_wheels` channel may leave it out).
    let msg = err_of(&[ChannelSpec::new("n", Quantity::X, f64::NAN)]);
    assert!(
        msg.contains("noise_std") && msg.contains("missing"),
        "{msg}"
    );
    // Rates.
    for bad in [0.0, -10.0, f64::INFINITY] {
        let mut s = ok.clone();
        s.rate_hz = Some(bad);
        let msg = err_of(&[s]);
        assert!(msg.contains("rate_hz") && msg.contains("> 0"), "{msg}");
    }
    // Dropout probability.
    let mut s = ok.clone();
    s.dropout_prob = 1.5;
    let msg = err_of(&[s]);
    assert!(
        msg.contains("dropout_prob") && msg.contains("[0, 1]"),
        "{msg}"
    );
    // Negative walk, non-finite bias, empty name.
    let mut s = ok.clone();
    s.bias_walk_std = -1.0;
    assert!(err_of(&[s]).contains("bias_walk_std"));
    let mut s = ok.clone();
    s.bias = f64::INFINITY;
    assert!(err_of(&[s]).contains("`bias`"));
    assert!(err_of(&[ChannelSpec::new("", Quantity::X, 0.1)]).contains("empty"));
    // Control period.
    let e = SensorSuite::new(&[ok], 0.0, 0).unwrap_err();
    assert_eq!(e, SensorError::InvalidControlPeriod(0.0));
    assert!(e.to_string().contains("> 0"));
}

#[test]
fn fault_pattern_validation() {
    let doc = parse(PAPER).unwrap();
    let pat = |name: &str, ch: &[&str]| FaultPatternSpec {
        name: name.to_string(),
        channels: ch.iter().map(|c| c.to_string()).collect(),
    };
    let msg = resolve_patterns(&doc.sensors, &[pat("r1", &["x2", "gps_z"])])
        .unwrap_err()
        .to_string();
    println!("{msg}");
    assert!(
        msg.contains("\"r1\"")
            && msg.contains("unknown sensor channel \"gps_z\"")
            && msg.contains("\"y2\""),
        "{msg}"
    );
    let msg = resolve_patterns(
        &doc.sensors,
        &[pat("r1", &["x2", "y2"]), pat("r2", &["y2"])],
    )
    .unwrap_err()
    .to_string();
    println!("{msg}");
    assert!(
        msg.contains("\"r1\"")
            && msg.contains("\"r2\"")
            && msg.contains("overlap")
            && msg.contains("\"y2\"")
            && msg.contains("disjoint"),
        "{msg}"
    );
    let msg = resolve_patterns(&doc.sensors, &[pat("r1", &[])])
        .unwrap_err()
        .to_string();
    assert!(msg.contains("\"r1\"") && msg.contains("empty"), "{msg}");
    let msg = resolve_patterns(&doc.sensors, &[pat("r1", &["x2", "x2"])])
        .unwrap_err()
        .to_string();
    assert!(msg.contains("listed twice"), "{msg}");
    let msg = resolve_patterns(&doc.sensors, &[pat("r1", &["x2"]), pat("r1", &["y2"])])
        .unwrap_err()
        .to_string();
    assert!(msg.contains("declared twice"), "{msg}");
}

#[test]
fn toml_schema_rejects_unknown_keys_and_quantities() {
    let e =
        parse("[[sensors]]\nname = \"a\"\nmeasures = \"x\"\nnoise_std = 0.1\nnoise_sdt = 0.2\n")
            .unwrap_err()
            .to_string();
    println!("{e}");
    assert!(e.contains("noise_sdt"), "{e}");
    let e = parse("[[sensors]]\nname = \"a\"\nmeasures = \"z\"\nnoise_std = 0.1\n")
        .unwrap_err()
        .to_string();
    println!("{e}");
    assert!(e.contains("\"z\"") && e.contains("yaw_rate"), "{e}");
    // A missing noise_std parses (a `from_wheels` channel may leave it out) and is refused by
    // the channel's validation, naming the key.
    let doc = parse("[[sensors]]\nname = \"a\"\nmeasures = \"x\"\n").expect("parses");
    let e = doc.sensors[0].validate().unwrap_err().to_string();
    assert!(e.contains("noise_std") && e.contains("missing"), "{e}");
}

#[test]
fn ten_hz_channel_in_fifty_hz_loop_is_fresh_exactly_every_fifth_tick() {
    let mut spec = ChannelSpec::new("gnss_x", Quantity::X, 0.05);
    spec.rate_hz = Some(10.0);
    let mut suite = SensorSuite::new(&[spec], DT, 9).unwrap();
    let mut last_fresh: Option<Sample> = None;
    for k in 0..=1000i64 {
        let t = k as f64 * DT;
        let s = suite.sample(&truth(t))[0];
        assert_eq!(s.fresh, k % 5 == 0, "tick {k}");
        assert_eq!(
            s.age.to_bits(),
            ((k % 5) as f64 * DT).to_bits(),
            "age at tick {k}"
        );
        if s.fresh {
            // The sample is of the truth at this tick.
            assert_eq!(s.clean, truth(t).x);
            last_fresh = Some(s);
        } else {
            let f = last_fresh.unwrap();
            assert_eq!(
                (s.value.to_bits(), s.clean.to_bits()),
                (f.value.to_bits(), f.clean.to_bits())
            );
        }
    }
}

#[test]
fn schedule_is_immune_to_accumulated_float_time() {
    // t accumulated as t += dt drifts from k·dt; the tick and schedule must not.
    let mut spec = ChannelSpec::new("gnss_x", Quantity::X, 0.0);
    spec.rate_hz = Some(10.0);
    let mut suite = SensorSuite::new(&[spec], DT, 9).unwrap();
    let mut t = 0.0;
    let mut fresh_ticks = Vec::new();
    for k in 0..5000i64 {
        if suite.sample(&truth(t))[0].fresh {
            fresh_ticks.push(k);
        }
        t += DT;
    }
    assert_eq!(fresh_ticks, (0..1000).map(|n| 5 * n).collect::<Vec<i64>>());
}

#[test]
fn fractional_rate_takes_sample_n_at_first_tick_at_or_after_n_over_rate() {
    // 30 Hz in a 50 Hz loop: sample n is due at tick ⌈5n/3⌉.
    let mut spec = ChannelSpec::new("cam", Quantity::Y, 0.0);
    spec.rate_hz = Some(30.0);
    let mut suite = SensorSuite::new(&[spec], DT, 2).unwrap();
    let fresh: Vec<i64> = (0..500i64)
        .filter(|&k| suite.sample(&truth(k as f64 * DT))[0].fresh)
        .collect();
    let expected: Vec<i64> = (0..300i64).map(|n| (5 * n + 2) / 3).collect();
    assert_eq!(fresh, expected);
    assert_eq!(fresh.len(), 300, "exactly 30 samples per second over 10 s");
}

#[test]
fn faster_than_loop_first_call_and_repeated_tick() {
    let mut fast = ChannelSpec::new("imu", Quantity::YawRate, 0.0);
    fast.rate_hz = Some(200.0);
    let mut slow = ChannelSpec::new("gnss", Quantity::X, 0.0);
    slow.rate_hz = Some(1.0);
    let mut suite = SensorSuite::new(&[fast, slow], DT, 2).unwrap();
    // Start mid-period (t = 0.46 s): the first call always delivers.
    let s = suite.sample(&truth(0.46)).to_vec();
    assert!(s[0].fresh && s[1].fresh);
    // Same tick again: nothing new.
    let again = suite.sample(&truth(0.46)).to_vec();
    assert!(!again[0].fresh && !again[1].fresh);
    assert_eq!(again[1].value, s[1].value);
    // Then the 200 Hz channel is fresh every tick, the 1 Hz one next at t = 1.0 s (tick 50).
    for k in 24..=60i64 {
        let s = suite.sample(&truth(k as f64 * DT)).to_vec();
        assert!(s[0].fresh);
        assert_eq!(s[1].fresh, k == 50, "tick {k}");
        if k < 50 {
            assert_eq!(s[1].age.to_bits(), ((k - 23) as f64 * DT).to_bits());
        }
    }
}

#[test]
fn channel_that_never_delivered_reports_nan_and_infinite_age() {
    let mut spec = ChannelSpec::new("dead", Quantity::X, 0.1);
    spec.dropout_prob = 1.0;
    let mut suite = SensorSuite::new(&[spec], DT, 2).unwrap();
    for k in 0..100 {
        let s = suite.sample(&truth(k as f64 * DT))[0];
        assert!(!s.fresh && s.value.is_nan() && s.clean.is_nan() && s.age == f64::INFINITY);
    }
}

fn run(specs: &[ChannelSpec], seed: u64, ticks: i64) -> Vec<Vec<u64>> {
    let mut suite = SensorSuite::new(specs, DT, seed).unwrap();
    (0..ticks)
        .map(|k| {
            suite
                .sample(&truth(k as f64 * DT))
                .iter()
                .map(|s| s.value.to_bits())
                .collect()
        })
        .collect()
}

#[test]
fn reproducible_per_seed_and_independent_of_other_channels() {
    let doc = parse(PAPER).unwrap();
    let mut specs = doc.sensors.clone();
    specs[1].bias_walk_std = 0.01;
    specs[3].dropout_prob = 0.3;
    specs[2].rate_hz = Some(5.0);
    let a = run(&specs, 42, 500);
    let b = run(&specs, 42, 500);
    assert_eq!(a, b, "same seed → same readings bit for bit");
    let c = run(&specs, 43, 500);
    for ch in 0..6 {
        let differs = a.iter().zip(&c).filter(|(x, y)| x[ch] != y[ch]).count();
        assert!(
            differs > 90,
            "channel {ch}: only {differs} of 500 readings changed with the seed"
        );
    }
    // Insert a new channel first and reverse the order: every old channel keeps its readings.
    let mut more = vec![ChannelSpec::new("gnss3_x", Quantity::X, 0.2)];
    more.extend(specs.iter().rev().cloned());
    let d = run(&more, 42, 500);
    let n = specs.len();
    for ch in 0..n {
        let in_more = n - ch; // position of specs[ch] in `more`
        assert!(
            a.iter().zip(&d).all(|(x, y)| x[ch] == y[in_more]),
            "channel {ch} changed"
        );
    }
}

#[test]
fn noise_sequence_does_not_depend_on_dropout_or_bias_settings() {
    // Every due sample draws the same numbers whatever the configuration, so a channel with
    // dropout and a bias delivers, on the ticks it is not dropped, the base channel's reading + bias.
    let base = ChannelSpec::new("x", Quantity::X, 0.1);
    let mut variant = base.clone();
    variant.dropout_prob = 0.3;
    variant.bias = 0.5;
    let mut a = SensorSuite::new(&[base], DT, 5).unwrap();
    let mut b = SensorSuite::new(&[variant], DT, 5).unwrap();
    let mut compared = 0;
    for k in 0..1000i64 {
        let tr = truth(k as f64 * DT);
        let (sa, sb) = (a.sample(&tr)[0], b.sample(&tr)[0]);
        if sb.fresh {
            assert!((sb.value - sa.value - 0.5).abs() < 1e-12, "tick {k}");
            compared += 1;
        }
    }
    assert!(compared > 600, "{compared}");
}

#[test]
fn non_finite_truth_and_time_do_not_panic() {
    let doc = parse(PAPER).unwrap();
    let mut suite = SensorSuite::new(&doc.sensors, DT, 1).unwrap();
    let mut bad = truth(0.0);
    bad.x = f64::NAN;
    bad.theta = f64::INFINITY;
    let s = suite.sample(&bad).to_vec();
    assert!(s[0].value.is_nan() && s[6].value == f64::INFINITY && s[2].value.is_finite());
    // A NaN or huge time maps to a saturated tick: readings are held, nothing panics.
    for t in [f64::NAN, 1e300, -1e300, 0.5] {
        let mut tr = truth(0.5);
        tr.t = t;
        let s = suite.sample(&tr);
        assert_eq!(s.len(), 7);
    }
}
