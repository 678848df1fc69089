//! Every attack kind against the real controller in the loop (paper_turtlebot, the attack on
//! gnss2_y, inside its fault pattern): the run completes, no input or estimate is ever
//! non-finite, bad readings are counted as rejected, and FT-CBF-CLF keeps the robot safe.

use std::path::PathBuf;

use ftcbf_sim::observe::{Frame, Observer, Scene};
use ftcbf_sim::runner::{run_observed, RunOptions};
use ftcbf_sim::world::World;

const KINDS: &[(&str, &str)] = &[
    ("bias", "kind = \"bias\"\nvalue = 0.3"),
    ("ramp", "kind = \"ramp\"\nrate = 0.05\ncap = 0.5"),
    ("sinusoid", "kind = \"sinusoid\"\namplitude = 0.3\nfrequency_hz = 0.5\nphase = 0.0"),
    ("freeze", "kind = \"freeze\""),
    ("replay", "kind = \"replay\"\nrecord_start = 0.0\nlength = 2.0"),
    ("dropout", "kind = \"dropout\""),
    ("scale", "kind = \"scale\"\nfactor = 3.0"),
    ("spikes", "kind = \"spikes\"\nprobability = 0.2\nmagnitude = 2.0"),
    ("nan", "kind = \"non_finite\"\nvalue = \"nan\""),
    ("+inf", "kind = \"non_finite\"\nvalue = \"inf\""),
    ("-inf", "kind = \"non_finite\"\nvalue = \"-inf\""),
    ("absurd", "kind = \"absurd\"\nvalue = 1e12"),
    (
        "stealthy",
        "kind = \"stealthy\"\nmax_rate = 0.05\nthreshold = 3.0\ndirection = \"positive\"\nmax_bias = 0.6",
    ),
    ("coordinated", "kind = \"coordinated\"\nvelocity = [0.05]"),
];

#[derive(Default)]
struct Finite {
    frames: u64,
    bad: Vec<String>,
}

impl Observer for Finite {
    fn scene(&mut self, _: &Scene) {}
    fn frame(&mut self, f: &Frame<'_>) {
        self.frames += 1;
        if !(f.u[0].is_finite() && f.u[1].is_finite()) {
            self.bad.push(format!("t = {}: u = {:?}", f.t, f.u));
        }
        for e in f.estimates {
            if e.x.iter().any(|v| !v.is_finite()) {
                self.bad.push(format!("t = {}: estimate {:?}", f.t, e.x));
            }
        }
    }
}

#[test]
fn every_attack_kind_is_survived_in_closed_loop() {
    let base = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("worlds/paper_turtlebot.toml");
    let text = std::fs::read_to_string(&base).expect("readable");
    let (head, tail) = text.split_at(text.find("[[attacks]]").expect("has attacks"));
    let tail = &tail[tail.find("[expect]").expect("has expect")..];
    let mut problems = Vec::new();
    for (name, spec) in KINDS {
        let world_text =
            format!("{head}[[attacks]]\nchannels = [\"gnss2_y\"]\nstart = 2.0\n{spec}\n\n{tail}");
        let world = World::from_str(&world_text, &base, &[])
            .unwrap_or_else(|e| panic!("{name}: world does not load: {e}"));
        let mut obs = Finite::default();
        let s = run_observed(&world, &RunOptions::default(), Some(&mut obs))
            .unwrap_or_else(|e| panic!("{name}: run failed: {e}"));
        assert_eq!(obs.frames, s.control_steps, "{name}: every step observed");
        if !obs.bad.is_empty() {
            problems.push(format!(
                "{name}: non-finite values: {:?}",
                &obs.bad[..obs.bad.len().min(3)]
            ));
        }
        if !s.safe {
            problems.push(format!(
                "{name}: unsafe: {:?} {:?}",
                s.first_violation, s.first_collision
            ));
        }
        let bad_values = matches!(*name, "nan" | "+inf" | "-inf" | "absurd");
        // gnss2_y samples at 50 Hz from t = 2 s to 20 s: 900 bad readings.
        if bad_values && s.rejected_readings != 900 {
            problems.push(format!(
                "{name}: {} readings rejected, expected 900",
                s.rejected_readings
            ));
        }
        if !bad_values && s.rejected_readings != 0 {
            problems.push(format!(
                "{name}: {} readings rejected, expected none",
                s.rejected_readings
            ));
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

/// Records, per control step, the attacked channel's detector statistic and attack offset.
struct Stealth {
    channel: usize,
    z: Vec<(f64, f64)>,
    offset: Vec<f64>,
}

impl Observer for Stealth {
    fn scene(&mut self, s: &Scene) {
        self.channel = s
            .channels
            .iter()
            .position(|c| c == "gnss2_y")
            .expect("gnss2_y is a channel");
    }
    fn frame(&mut self, f: &Frame<'_>) {
        let c = f.channels[self.channel];
        if c.fresh && c.detector_z.is_finite() {
            self.z.push((f.t, c.detector_z));
        }
        self.offset.push(c.received - c.clean);
    }
}

/// The stealthy world against the real controller: the attacker keeps the all-channel filter's
/// normalised innovation on gnss2_y within its 3σ threshold at every step, while its bias grows
/// past 10× the channel's noise standard deviation (0.02 m).
#[test]
fn stealthy_attack_stays_under_the_real_detector() {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("worlds/stealthy_gnss.toml");
    let world = World::load(&p, &[]).expect("world loads");
    let mut obs = Stealth {
        channel: 0,
        z: Vec::new(),
        offset: Vec::new(),
    };
    run_observed(&world, &RunOptions::default(), Some(&mut obs)).expect("runs");
    let attacked: Vec<&(f64, f64)> = obs.z.iter().filter(|(t, _)| *t >= 1.0).collect();
    assert!(
        attacked.len() > 1000,
        "only {} attacked samples",
        attacked.len()
    );
    let worst = attacked.iter().map(|(_, z)| z.abs()).fold(0.0, f64::max);
    assert!(worst <= 3.0 + 1e-6, "detector statistic reached {worst}");
    let max_offset = obs.offset.iter().copied().fold(0.0, f64::max);
    assert!(
        max_offset >= 10.0 * 0.02,
        "bias only reached {max_offset} m"
    );
    eprintln!("stealthy: max |z| = {worst:.3}, max bias = {max_offset:.3} m");
}
