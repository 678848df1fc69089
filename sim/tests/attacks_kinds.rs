//! Each injector on a known clean signal: it matches its definition inside its window and leaves
//! readings untouched outside it (and leaves untargeted channels alone).

use std::f64::consts::PI;

use ftcbf_sim::attacks::{AttackSpec, AttackStack, NoDetector};
use ftcbf_sim::sensors::{ChannelSpec, Quantity, Sample, SensorSuite};
use ftcbf_sim::state::TruthState;
use serde::Deserialize;

const DT: f64 = 0.02;

#[derive(Debug, Deserialize)]
struct Doc {
    attacks: Vec<AttackSpec>,
}

fn truth(t: f64) -> TruthState {
    TruthState {
        t,
        x: 1.0 + 0.5 * t,
        y: -2.0 + t.sin(),
        theta: 0.0,
        vx: 0.5,
        vy: t.cos(),
        v_body: 0.5,
        omega: 0.0,
        ..Default::default()
    }
}

/// Channels: 0 "a" = x (noise-free), 1 "b" = y (noise-free), 2 "n" = y with noise 0.1,
/// 3 "slow" = x at 10 Hz, noise 0.05.
fn channels() -> Vec<ChannelSpec> {
    let mut slow = ChannelSpec::new("slow", Quantity::X, 0.05);
    slow.rate_hz = Some(10.0);
    vec![
        ChannelSpec::new("a", Quantity::X, 0.0),
        ChannelSpec::new("b", Quantity::Y, 0.0),
        ChannelSpec::new("n", Quantity::Y, 0.1),
        slow,
    ]
}

struct Tick {
    t: f64,
    clean: Vec<Sample>,
    attacked: Vec<Sample>,
}

/// Runs `ticks` control ticks: sensor readings before and after the stack.
fn run_seeded(attacks: &str, ticks: i64, seed: u64) -> Vec<Tick> {
    let doc: Doc = toml::from_str(attacks).unwrap();
    let mut suite = SensorSuite::new(&channels(), DT, 99).unwrap();
    let mut stack = AttackStack::new(&doc.attacks, &suite, seed).unwrap();
    (0..ticks)
        .map(|k| {
            let t = k as f64 * DT;
            let samples = suite.sample(&truth(t));
            let clean = samples.to_vec();
            stack.apply(t, samples, &NoDetector);
            Tick {
                t,
                clean,
                attacked: samples.to_vec(),
            }
        })
        .collect()
}

fn run(attacks: &str, ticks: i64) -> Vec<Tick> {
    run_seeded(attacks, ticks, 0)
}

fn same(a: &Sample, b: &Sample) -> bool {
    a.value.to_bits() == b.value.to_bits()
        && a.fresh == b.fresh
        && a.age.to_bits() == b.age.to_bits()
        && a.clean.to_bits() == b.clean.to_bits()
}

/// Asserts untouched readings outside `[start, end)` on channel `c` and on all other channels always.
fn untouched_outside(ticks: &[Tick], c: usize, start: f64, end: f64) {
    for tk in ticks {
        for ch in 0..4 {
            if ch != c || tk.t < start - 1e-9 || tk.t >= end - 1e-9 {
                assert!(
                    same(&tk.clean[ch], &tk.attacked[ch]),
                    "t = {} ch {ch}: {:?} vs {:?}",
                    tk.t,
                    tk.clean[ch],
                    tk.attacked[ch]
                );
            }
        }
    }
}

fn inside(ticks: &[Tick], start: f64, end: f64) -> impl Iterator<Item = &Tick> {
    ticks
        .iter()
        .filter(move |tk| tk.t >= start - 1e-9 && tk.t < end - 1e-9)
}

#[test]
fn bias_adds_a_constant() {
    let ticks = run(
        "[[attacks]]\nkind = \"bias\"\nchannels = [\"b\"]\nstart = 1.0\nend = 2.0\nvalue = 1.0\n",
        200,
    );
    untouched_outside(&ticks, 1, 1.0, 2.0);
    let mut n = 0;
    for tk in inside(&ticks, 1.0, 2.0) {
        assert_eq!(tk.attacked[1].value, tk.clean[1].value + 1.0);
        assert!(tk.attacked[1].fresh && tk.attacked[1].clean == tk.clean[1].clean);
        n += 1;
    }
    assert_eq!(n, 50, "window [1, 2) holds exactly 50 ticks of 20 ms");
}

#[test]
fn ramp_grows_linearly_up_to_its_cap() {
    let ticks = run("[[attacks]]\nkind = \"ramp\"\nchannels = [\"a\"]\nstart = 1.0\nend = 3.0\nrate = 0.5\ncap = 0.4\n", 200);
    untouched_outside(&ticks, 0, 1.0, 3.0);
    for tk in inside(&ticks, 1.0, 3.0) {
        let expected = (0.5 * (tk.t - 1.0)).min(0.4);
        assert!(
            (tk.attacked[0].value - tk.clean[0].value - expected).abs() < 1e-12,
            "t = {}",
            tk.t
        );
    }
    // Negative rate, no cap.
    let ticks = run(
        "[[attacks]]\nkind = \"drift\"\nchannels = [\"a\"]\nstart = 0.5\nrate = -0.2\n",
        200,
    );
    for tk in inside(&ticks, 0.5, 10.0) {
        assert!((tk.attacked[0].value - tk.clean[0].value + 0.2 * (tk.t - 0.5)).abs() < 1e-12);
    }
}

#[test]
fn sinusoid_matches_its_formula() {
    let ticks = run("[[attacks]]\nkind = \"sinusoid\"\nchannels = [\"n\"]\nstart = 0.5\nend = 3.5\namplitude = 0.3\nfrequency_hz = 2.0\nphase = 0.7\n", 200);
    untouched_outside(&ticks, 2, 0.5, 3.5);
    for tk in inside(&ticks, 0.5, 3.5) {
        let expected = 0.3 * (2.0 * PI * 2.0 * (tk.t - 0.5) + 0.7).sin();
        assert!((tk.attacked[2].value - tk.clean[2].value - expected).abs() < 1e-12);
    }
}

#[test]
fn freeze_holds_the_last_reading_before_start_or_a_given_value() {
    let ticks = run(
        "[[attacks]]\nkind = \"freeze\"\nchannels = [\"n\"]\nstart = 1.0\nend = 2.0\n",
        150,
    );
    untouched_outside(&ticks, 2, 1.0, 2.0);
    let before = ticks[49].clean[2].value; // t = 0.98
    for tk in inside(&ticks, 1.0, 2.0) {
        assert_eq!(tk.attacked[2].value.to_bits(), before.to_bits());
        assert_eq!(
            (tk.attacked[2].fresh, tk.attacked[2].age),
            (tk.clean[2].fresh, tk.clean[2].age),
            "keeps reporting"
        );
    }
    let ticks = run(
        "[[attacks]]\nkind = \"stuck_at\"\nchannels = [\"a\"]\nstart = 1.0\nvalue = -7.5\n",
        150,
    );
    untouched_outside(&ticks, 0, 1.0, 1e9);
    assert!(inside(&ticks, 1.0, 10.0).all(|tk| tk.attacked[0].value == -7.5));
    // Window starting at t = 0: holds the first reading.
    let ticks = run("[[attacks]]\nkind = \"freeze\"\nchannels = [\"n\"]\n", 50);
    assert!(ticks
        .iter()
        .all(|tk| tk.attacked[2].value == ticks[0].clean[2].value));
}

#[test]
fn replay_plays_back_the_recording_bit_for_bit_and_cycles() {
    // Record [1, 2) s (50 ticks) on the noisy every-tick channel and the 10 Hz channel; play from
    // 3 s to 5.5 s (125 ticks: 2.5 cycles).
    let ticks = run(
        "[[attacks]]\nkind = \"replay\"\nchannels = [\"n\", \"slow\"]\nstart = 3.0\nend = 5.5\nrecord_start = 1.0\nlength = 1.0\n",
        400,
    );
    for ch in [0, 1] {
        assert!(ticks.iter().all(|tk| same(&tk.clean[ch], &tk.attacked[ch])));
    }
    let mut played = 0;
    for (k, tk) in ticks.iter().enumerate() {
        for ch in [2, 3] {
            if (150..275).contains(&k) {
                let rec = &ticks[50 + (k - 150) % 50].clean[ch];
                let out = &tk.attacked[ch];
                assert_eq!(out.value.to_bits(), rec.value.to_bits(), "tick {k} ch {ch}");
                assert_eq!(
                    (out.fresh, out.age.to_bits()),
                    (rec.fresh, rec.age.to_bits()),
                    "tick {k} ch {ch}"
                );
                assert_eq!(
                    out.clean.to_bits(),
                    tk.clean[ch].clean.to_bits(),
                    "clean stays the truth"
                );
                played += 1;
            } else {
                assert!(same(&tk.clean[ch], &tk.attacked[ch]), "tick {k} ch {ch}");
            }
        }
    }
    assert_eq!(played, 250);
    // The replayed noise is not the live noise.
    assert!(
        ticks[150..200]
            .iter()
            .filter(|tk| tk.attacked[2].value != tk.clean[2].value)
            .count()
            > 45
    );
}

#[test]
fn dropout_delivers_nothing_new_and_ages_the_last_sample() {
    let ticks = run(
        "[[attacks]]\nkind = \"dropout\"\nchannels = [\"n\", \"slow\"]\nstart = 1.0\nend = 2.0\n",
        150,
    );
    for ch in [0, 1] {
        assert!(ticks.iter().all(|tk| same(&tk.clean[ch], &tk.attacked[ch])));
    }
    let last = &ticks[49]; // t = 0.98: last tick before the window
    for tk in inside(&ticks, 1.0, 2.0) {
        for ch in [2, 3] {
            let s = &tk.attacked[ch];
            assert!(!s.fresh);
            assert_eq!(s.value.to_bits(), last.clean[ch].value.to_bits());
            let expected_age = last.clean[ch].age + (tk.t - last.t);
            assert!(
                (s.age - expected_age).abs() < 1e-12,
                "age {} vs {expected_age}",
                s.age
            );
        }
    }
    // After the window the live readings come back.
    for tk in &ticks[100..] {
        assert!(same(&tk.clean[2], &tk.attacked[2]) && same(&tk.clean[3], &tk.attacked[3]));
    }
    assert!(ticks[100].attacked[2].fresh);
}

#[test]
fn scale_multiplies() {
    let ticks = run("[[attacks]]\nkind = \"scale\"\nchannels = [\"a\"]\nstart = 0.4\nend = 1.0\nfactor = -2.5\n", 100);
    untouched_outside(&ticks, 0, 0.4, 1.0);
    for tk in inside(&ticks, 0.4, 1.0) {
        assert_eq!(tk.attacked[0].value, tk.clean[0].value * -2.5);
    }
}

#[test]
fn spikes_hit_with_the_configured_probability_and_are_seeded() {
    let spec = "[[attacks]]\nkind = \"spikes\"\nchannels = [\"b\"]\nstart = 1.0\nend = 201.0\nprobability = 0.3\nmagnitude = 5.0\n";
    let ticks = run_seeded(spec, 10_100, 4);
    untouched_outside(&ticks, 1, 1.0, 201.0);
    let (mut hits, mut up, mut n) = (0, 0, 0);
    for tk in inside(&ticks, 1.0, 201.0) {
        let d = tk.attacked[1].value - tk.clean[1].value;
        n += 1;
        if d != 0.0 {
            assert!((d.abs() - 5.0).abs() < 1e-9, "spike of {d}");
            hits += 1;
            up += usize::from(d > 0.0);
        }
    }
    assert_eq!(n, 10_000);
    let frac = hits as f64 / n as f64;
    // SE √(0.3·0.7/10⁴) ≈ 0.0046; bound 4 SE. Signs: SE of the up-fraction √(0.25/hits); bound 4 SE.
    println!(
        "spike fraction {frac:.4}, positive fraction {:.4}",
        up as f64 / hits as f64
    );
    assert!((frac - 0.3).abs() <= 4.0 * (0.21f64 / n as f64).sqrt());
    assert!((up as f64 / hits as f64 - 0.5).abs() <= 4.0 * (0.25 / hits as f64).sqrt());
    let again = run_seeded(spec, 10_100, 4);
    assert!(
        ticks
            .iter()
            .zip(&again)
            .all(|(a, b)| same(&a.attacked[1], &b.attacked[1])),
        "same seed, same spikes"
    );
    let other = run_seeded(spec, 10_100, 5);
    let differ = ticks
        .iter()
        .zip(&other)
        .filter(|(a, b)| !same(&a.attacked[1], &b.attacked[1]))
        .count();
    assert!(
        differ > 1000,
        "another seed gives other spikes ({differ} differ)"
    );
}

#[test]
fn non_finite_and_absurd_readings_replace_the_value_without_panicking() {
    let ticks = run(
        "[[attacks]]\nkind = \"non_finite\"\nchannels = [\"a\"]\nstart = 0.2\nend = 0.4\nvalue = \"nan\"\n\
         [[attacks]]\nkind = \"non_finite\"\nchannels = [\"a\"]\nstart = 0.4\nend = 0.6\nvalue = \"inf\"\n\
         [[attacks]]\nkind = \"non_finite\"\nchannels = [\"a\"]\nstart = 0.6\nend = 0.8\nvalue = \"-inf\"\n\
         [[attacks]]\nkind = \"absurd\"\nchannels = [\"a\"]\nstart = 0.8\nend = 1.0\n\
         [[attacks]]\nkind = \"absurd\"\nchannels = [\"a\"]\nstart = 1.0\nend = 1.2\nvalue = -1e300\n\
         [[attacks]]\nkind = \"scale\"\nchannels = [\"a\"]\nstart = 0.0\nfactor = 2.0\n\
         [[attacks]]\nkind = \"stealthy\"\nchannels = [\"a\"]\nstart = 0.0\nmax_rate = 1.0\nthreshold = 3.0\n",
        100,
    );
    for tk in &ticks {
        let v = tk.attacked[0].value;
        let base = tk.clean[0].value * 2.0 + tk.t; // scale, then the stealthy bias at max_rate
        match tk.t {
            t if t < 0.2 - 1e-9 => assert!((v - base).abs() < 1e-9),
            t if t < 0.4 - 1e-9 => assert!(v.is_nan()),
            t if t < 0.6 - 1e-9 => assert_eq!(v, f64::INFINITY),
            t if t < 0.8 - 1e-9 => assert_eq!(v, f64::NEG_INFINITY),
            t if t < 1.0 - 1e-9 => assert!((v - (2e12 + tk.t)).abs() < 1e-3),
            t if t < 1.2 - 1e-9 => assert_eq!(v, -2e300),
            _ => assert!((v - base).abs() < 1e-9),
        }
    }
}

#[test]
fn coordinated_spoofs_channels_along_a_path_with_a_norm_cap() {
    let ticks = run("[[attacks]]\nkind = \"coordinated\"\nchannels = [\"a\", \"b\"]\nstart = 1.0\nend = 6.0\nvelocity = [0.3, -0.4]\ncap = 1.0\n", 400);
    for tk in &ticks {
        for ch in [2, 3] {
            assert!(same(&tk.clean[ch], &tk.attacked[ch]));
        }
    }
    untouched_outside(&ticks[..50], 0, 1.0, 6.0);
    untouched_outside(&ticks[300..], 0, 1.0, 6.0);
    for tk in inside(&ticks, 1.0, 6.0) {
        // |v| = 0.5 m/s: the offset reaches the cap of 1 m at t − start = 2 s.
        let s = (tk.t - 1.0).min(2.0);
        let (dx, dy) = (
            tk.attacked[0].value - tk.clean[0].value,
            tk.attacked[1].value - tk.clean[1].value,
        );
        assert!(
            (dx - 0.3 * s).abs() < 1e-12 && (dy + 0.4 * s).abs() < 1e-12,
            "t = {}: ({dx}, {dy})",
            tk.t
        );
    }
}

#[test]
fn injectors_compose_in_file_order() {
    let bias_then_scale = run("[[attacks]]\nkind = \"bias\"\nchannels = [\"a\"]\nvalue = 1.0\n[[attacks]]\nkind = \"scale\"\nchannels = [\"a\"]\nfactor = 2.0\n", 20);
    let scale_then_bias = run("[[attacks]]\nkind = \"scale\"\nchannels = [\"a\"]\nfactor = 2.0\n[[attacks]]\nkind = \"bias\"\nchannels = [\"a\"]\nvalue = 1.0\n", 20);
    for (p, q) in bias_then_scale.iter().zip(&scale_then_bias) {
        assert_eq!(p.attacked[0].value, (p.clean[0].value + 1.0) * 2.0);
        assert_eq!(q.attacked[0].value, q.clean[0].value * 2.0 + 1.0);
    }
}

#[test]
fn value_effects_act_on_samples_and_are_held_with_them() {
    // Ramp from t = 1.01 s on the 10 Hz channel: the sample held from t = 1.0 s stays clean until
    // the next sample (t = 1.1 s), which carries rate·(1.1 − 1.01) and keeps it while held.
    let ticks = run("[[attacks]]\nkind = \"ramp\"\nchannels = [\"slow\"]\nstart = 1.01\nend = 1.25\nrate = 1.0\n", 100);
    for (k, tk) in ticks.iter().enumerate() {
        let d = tk.attacked[3].value - tk.clean[3].value;
        let expected = match k {
            0..=54 => 0.0,         // before the first sample in the window
            55..=59 => 1.1 - 1.01, // sample of t = 1.1 s, held until 1.18 s
            60..=64 => 1.2 - 1.01, // sample of t = 1.2 s (inside), held past the end
            _ => 0.0,              // sample of t = 1.3 s is after the window
        };
        assert!(
            (d - expected).abs() < 1e-9,
            "tick {k}: offset {d}, expected {expected}"
        );
    }
}
