//! Statistical properties of the sensor channels: noise mean and standard deviation, bias random
//! walk variance, dropout fraction, heading wrapping. Tolerances are stated in standard errors (SE)
//! of the estimator; all runs are seeded, so each test is deterministic.

use std::f64::consts::PI;

use ftcbf_sim::sensors::{ChannelSpec, Quantity, SensorSuite};
use ftcbf_sim::state::TruthState;

const DT: f64 = 0.02;

fn truth_at(k: i64) -> TruthState {
    TruthState {
        t: k as f64 * DT,
        x: 3.0,
        y: -1.5,
        theta: PI - 0.001,
        vx: 0.2,
        vy: -0.1,
        v_body: 0.25,
        omega: 0.05,
        ..Default::default()
    }
}

#[test]
fn noise_has_configured_mean_and_std() {
    let mut spec = ChannelSpec::new("gnss1_x", Quantity::X, 0.5);
    spec.bias = 0.2;
    let mut suite = SensorSuite::new(&[spec], DT, 7).unwrap();
    let n = 10_000usize;
    let errors: Vec<f64> = (0..n as i64)
        .map(|k| {
            let s = suite.sample(&truth_at(k))[0];
            assert!(s.fresh, "every-tick channel must be fresh at tick {k}");
            assert_eq!(s.clean, 3.0);
            s.value - s.clean
        })
        .collect();
    let mean = errors.iter().sum::<f64>() / n as f64;
    let var = errors.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / (n as f64 - 1.0);
    let std = var.sqrt();
    // SE of the mean: σ/√n = 0.005; SE of the std: σ/√(2(n−1)) ≈ 0.00354. Bound: 4 SE.
    let se_mean = 0.5 / (n as f64).sqrt();
    let se_std = 0.5 / (2.0 * (n as f64 - 1.0)).sqrt();
    println!(
        "mean error {mean:.5} (expected 0.2 ± {:.4}), std {std:.5} (expected 0.5 ± {:.4})",
        4.0 * se_mean,
        4.0 * se_std
    );
    assert!((mean - 0.2).abs() <= 4.0 * se_mean, "mean {mean}");
    assert!((std - 0.5).abs() <= 4.0 * se_std, "std {std}");
}

#[test]
fn bias_walk_variance_grows_like_sigma_squared_t() {
    // 2000 independent channels (independent streams by name), noise-free, walk intensity 0.1 /√s.
    let sigma_b = 0.1;
    let n_ch = 2000;
    let specs: Vec<ChannelSpec> = (0..n_ch)
        .map(|i| {
            let mut s = ChannelSpec::new(format!("walk{i}"), Quantity::Y, 0.0);
            s.bias_walk_std = sigma_b;
            s
        })
        .collect();
    let mut suite = SensorSuite::new(&specs, DT, 11).unwrap();
    let checkpoints = [125i64, 250, 500]; // t = 2.5, 5, 10 s
    let mut at: Vec<Vec<f64>> = vec![Vec::new(); checkpoints.len()];
    for k in 0..=500i64 {
        let samples = suite.sample(&truth_at(k));
        if k == 0 {
            assert!(
                samples.iter().all(|s| s.value == s.clean),
                "walk starts at exactly 0"
            );
        }
        if let Some(c) = checkpoints.iter().position(|&kc| kc == k) {
            at[c] = samples.iter().map(|s| s.value - s.clean).collect();
        }
    }
    let var = |v: &[f64]| {
        let m = v.iter().sum::<f64>() / v.len() as f64;
        v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len() as f64 - 1.0)
    };
    // Relative SE of a sample variance of Gaussian data: √(2/(n−1)) ≈ 3.2 %; bound: 4 SE ≈ 12.7 %.
    let tol = 4.0 * (2.0 / (n_ch as f64 - 1.0)).sqrt();
    for (c, &k) in checkpoints.iter().enumerate() {
        let t = k as f64 * DT;
        let expected = sigma_b * sigma_b * t;
        let got = var(&at[c]);
        println!(
            "t = {t} s: Var b = {got:.6}, σ²t = {expected:.6}, rel err {:.3} (tol {tol:.3})",
            got / expected - 1.0
        );
        assert!(
            (got / expected - 1.0).abs() <= tol,
            "t = {t}: {got} vs {expected}"
        );
    }
    // Independent increments: Var(b(10) − b(5)) = σ²·5.
    let inc: Vec<f64> = at[2].iter().zip(&at[1]).map(|(a, b)| a - b).collect();
    let expected = sigma_b * sigma_b * 5.0;
    let got = var(&inc);
    println!("increment 5..10 s: Var = {got:.6}, σ²·5 = {expected:.6}");
    assert!((got / expected - 1.0).abs() <= tol);
}

#[test]
fn dropout_fraction_and_held_value() {
    let mut spec = ChannelSpec::new("odom_vx", Quantity::Vx, 0.01);
    spec.dropout_prob = 0.2;
    let mut suite = SensorSuite::new(&[spec], DT, 3).unwrap();
    let n = 10_000i64;
    let mut dropped = 0usize;
    let mut prev = suite.sample(&truth_at(0))[0];
    assert!(prev.value.is_finite() || !prev.fresh);
    for k in 1..=n {
        let s = suite.sample(&truth_at(k))[0];
        if !s.fresh {
            dropped += 1;
            // The last sample is held (bit for bit) and ages by one tick.
            assert_eq!(s.value.to_bits(), prev.value.to_bits());
            if prev.age.is_finite() {
                assert!((s.age - (prev.age + DT)).abs() < 1e-12);
            }
        } else {
            assert_eq!(s.age, 0.0);
        }
        prev = s;
    }
    let frac = dropped as f64 / n as f64;
    // SE = √(p(1−p)/n) = 0.004; bound 4 SE = 0.016.
    let se = (0.2f64 * 0.8 / n as f64).sqrt();
    println!(
        "dropout fraction {frac:.4} (expected 0.2 ± {:.4})",
        4.0 * se
    );
    assert!((frac - 0.2).abs() <= 4.0 * se);
}

#[test]
fn heading_readings_are_wrapped_to_minus_pi_pi() {
    // θ = π − 0.001 with σ = 0.01: about half the raw readings exceed π and must wrap.
    let spec = ChannelSpec::new("compass", Quantity::Heading, 0.01);
    let mut suite = SensorSuite::new(&[spec], DT, 5).unwrap();
    let mut wrapped = 0;
    for k in 0..2000 {
        let s = suite.sample(&truth_at(k))[0];
        assert!(
            s.value > -PI && s.value <= PI,
            "reading {} outside (−π, π]",
            s.value
        );
        let d = (s.value - s.clean).rem_euclid(2.0 * PI);
        let circ = d.min(2.0 * PI - d);
        assert!(circ < 0.06, "circular error {circ} beyond 6σ");
        if s.value < 0.0 {
            wrapped += 1;
        }
    }
    // P(raw > π) = P(z > 0.1) ≈ 0.46: with 2000 draws, far more than 500 wrap.
    assert!(wrapped > 500, "only {wrapped} readings wrapped");
}
