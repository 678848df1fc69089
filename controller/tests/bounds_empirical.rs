//! Empirical check of γ_i and θ_ij (the event (4.5) of Theorem 3) on the model they are computed
//! for: the corridor's sensor suite (two GNSS receivers as two fault patterns, odometry), white
//! acceleration noise, no fault. For every filter i (each is fault-free here) and every step,
//! the events ‖x̂_i − x_t‖ > γ_i and ‖x̂_i − x̂_ij‖ > θ_ij/2 must, over a whole run, happen in at
//! most a fraction ε of runs; and the bounds must not be absurdly loose (the largest normalised
//! deviation seen is a sizeable part of the bound).
//!
//! Truth: the exact discretisation of ẋ = Fx + Gu + w (Φ, Γ, Q_d of the model), the start drawn
//! from N(x̂0, P0); measurements y = Cx + v, v ~ N(0, R) per channel, every step.

use ftcbf_controller::estimator::EstimatorBank;
use ftcbf_controller::params::{BoundMethod, FtComputed, UpdateSchedule};
use ftcbf_controller::{Input, LinearModel, State, StateMatrix};
use nalgebra::RowVector4;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

const DT: f64 = 0.02;
const STEPS: usize = 1250; // 25 s at 50 Hz, the corridor's horizon
const RUNS: u64 = 200;
const EPS: f64 = 0.05;

fn corridor_model() -> LinearModel {
    let row = |i: usize| {
        let mut r = RowVector4::zeros();
        r[i] = 1.0;
        r
    };
    // gnss1_x, gnss1_y, gnss2_x, gnss2_y, odom_vx, odom_vy (σ = 0.02 each)
    LinearModel::new(
        LinearModel::double_integrator_f(),
        LinearModel::double_integrator_g(),
        vec![row(0), row(1), row(0), row(1), row(2), row(3)],
        StateMatrix::from_diagonal(&State::new(0.0, 0.0, 1e-3, 1e-3)),
        vec![4e-4; 6],
    )
    .expect("valid model")
}

fn sqrt_psd(m: &StateMatrix) -> StateMatrix {
    let e = ((m + m.transpose()) * 0.5).symmetric_eigen();
    let s = e.eigenvalues.map(|l| l.max(0.0).sqrt());
    e.eigenvectors * StateMatrix::from_diagonal(&s) * e.eigenvectors.transpose()
}

fn normal4(rng: &mut ChaCha8Rng) -> State {
    State::from_fn(|_, _| StandardNormal.sample(rng))
}

/// The horizon bounds for ε = [`EPS`] over [`STEPS`] with every channel fresh every step.
fn every_step_bounds(model: &LinearModel, patterns: &[Vec<usize>], p0: &StateMatrix) -> FtComputed {
    FtComputed::compute_scheduled(
        model,
        patterns,
        DT,
        EPS,
        STEPS,
        p0,
        BoundMethod::Horizon,
        &UpdateSchedule::every_step(),
    )
}

#[test]
fn gamma_and_theta_bound_the_fault_free_errors_as_epsilon_promises() {
    let model = corridor_model();
    let patterns = vec![vec![0, 1], vec![2, 3]];
    let p0 = StateMatrix::from_diagonal(&State::new(1e-4, 1e-4, 1e-4, 1e-4));
    let params = every_step_bounds(&model, &patterns, &p0);
    // The separation bound is tighter than the §4.3 triangle bound.
    assert!(
        params.ft.theta[0] < params.derivation.theta_triangle[0],
        "{} vs {}",
        params.ft.theta[0],
        params.derivation.theta_triangle[0]
    );
    let seen = monte_carlo(&model, &patterns, &params, &p0, &Timing::EVERY_STEP, RUNS);
    let (runs_exceeding, worst_gamma_ratio, worst_theta_ratio) = (
        seen.runs_exceeding,
        seen.worst_gamma_ratio,
        seen.worst_theta_ratio,
    );
    assert!(
        (runs_exceeding as f64) <= EPS * RUNS as f64,
        "{runs_exceeding} of {RUNS} runs left the event (4.5)"
    );
    // Honest, not vacuous: the bounds are within a factor of a few of what is seen.
    assert!(
        worst_gamma_ratio > 0.3 && worst_theta_ratio > 0.3,
        "γ ratio {worst_gamma_ratio:.3}, θ/2 ratio {worst_theta_ratio:.3}: bounds too loose"
    );
}

/// When the receivers (channels 0–3) deliver: every `every` steps, each due sample lost with
/// probability `dropout`; the odometry (channels 4, 5) every step.
struct Timing {
    every: usize,
    dropout: f64,
}

impl Timing {
    const EVERY_STEP: Timing = Timing {
        every: 1,
        dropout: 0.0,
    };
}

/// What [`monte_carlo`] saw over its runs.
struct Seen {
    /// Runs in which some filter left γ_i or θ_12/2 at some step.
    runs_exceeding: u64,
    worst_gamma_ratio: f64,
    worst_theta_ratio: f64,
}

/// `runs` fault-free runs of the corridor's bank under `timing`, each judged against `params`.
fn monte_carlo(
    model: &LinearModel,
    patterns: &[Vec<usize>],
    params: &FtComputed,
    p0: &StateMatrix,
    timing: &Timing,
    runs: u64,
) -> Seen {
    let theta_half = params.ft.theta[0] / 2.0;
    let d = model.discretize(DT);
    let qd_sqrt = sqrt_psd(&d.qd);
    let p0_sqrt = sqrt_psd(p0);
    let x_hat0 = State::new(0.0, 0.0, 0.1, 0.0);
    let mut seen = Seen {
        runs_exceeding: 0,
        worst_gamma_ratio: 0.0,
        worst_theta_ratio: 0.0,
    };
    for seed in 0..runs {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut x = x_hat0 + p0_sqrt * normal4(&mut rng);
        let mut bank = EstimatorBank::new(model.clone(), patterns, x_hat0, *p0);
        let u = Input::new(0.0, 0.0);
        let mut exceeded = false;
        let mut y = [0.0; 6];
        let mut fresh = [true; 6];
        for step in 0..STEPS {
            x = d.phi * x + d.input_map * u + qd_sqrt * normal4(&mut rng);
            for (k, yk) in y.iter_mut().enumerate() {
                let v: f64 = StandardNormal.sample(&mut rng);
                *yk = model.measure(k, &x) + model.r[k].sqrt() * v;
            }
            if timing.every != 1 || timing.dropout > 0.0 {
                for f in fresh.iter_mut().take(4) {
                    let lost = rng.random::<f64>() < timing.dropout;
                    *f = step % timing.every == 0 && !lost;
                }
            }
            bank.step(&u, DT, &y, &fresh, &[false; 6]);
            let pair = *bank.pair(0, 1).expect("pair filter").estimate();
            for i in 0..2 {
                let xi = *bank.single(i).estimate();
                let g = (xi - x).norm() / params.ft.gamma[i];
                let t = (xi - pair).norm() / theta_half;
                seen.worst_gamma_ratio = seen.worst_gamma_ratio.max(g);
                seen.worst_theta_ratio = seen.worst_theta_ratio.max(t);
                if g > 1.0 || t > 1.0 {
                    exceeded = true;
                }
            }
        }
        if exceeded {
            seen.runs_exceeding += 1;
        }
    }
    seen
}

/// Issue #30 item 4: receivers at 10 Hz (every 5th step at 50 Hz) that lose 20 % of their samples.
/// γ and θ are computed on the schedule with the receivers' worst gap that ε/2 allows
/// (N·p^(n+1) ≤ ε/(2·4) over N = 250 slots: n = 6 lost in a row, so every 35 steps) and must hold
/// in at most ε of the fault-free runs in which the receivers really deliver that way.
///
/// The search for a counterexample to the old every-step bounds on this model found none: with
/// the receivers every 5, 25 or 50 steps and 20 % or 50 % dropouts, P0 = 1e-4·I or 1e-6·I, 50 runs
/// each, no run left them (the largest ‖x̂ − x‖/γ was 0.86): the odometry pins the velocity and
/// the union bound's quantile (ε' ≈ 1e-5) leaves room. The bounds are now those of the schedule
/// the filters really see, not that one.
#[test]
fn slow_lossy_receivers_get_gamma_and_theta_from_their_schedule() {
    let model = corridor_model();
    let patterns = vec![vec![0, 1], vec![2, 3]];
    let p0 = StateMatrix::from_diagonal(&State::new(1e-4, 1e-4, 1e-4, 1e-4));
    let timing = Timing {
        every: 5,
        dropout: 0.2,
    };
    let runs = 100;
    let every_step = every_step_bounds(&model, &patterns, &p0);
    let slots = STEPS / timing.every;
    let n = (0..)
        .find(|&n| slots as f64 * timing.dropout.powi(n + 1) <= EPS / 2.0 / 4.0)
        .expect("a finite gap") as usize;
    assert_eq!(n, 6);
    let updates = UpdateSchedule {
        every: vec![timing.every * (n + 1); 4],
    };
    let scheduled = FtComputed::compute_scheduled(
        &model,
        &patterns,
        DT,
        EPS / 2.0,
        STEPS,
        &p0,
        BoundMethod::Horizon,
        &updates,
    );
    let seen = monte_carlo(&model, &patterns, &scheduled, &p0, &timing, runs);
    assert!(
        (seen.runs_exceeding as f64) <= EPS * runs as f64,
        "scheduled bounds left in {} of {runs} runs (γ {:?}, θ {:?})",
        seen.runs_exceeding,
        scheduled.ft.gamma,
        scheduled.ft.theta
    );
    assert!(
        seen.worst_gamma_ratio > 0.3,
        "γ ratio {:.3}: too loose",
        seen.worst_gamma_ratio
    );
    assert!(
        scheduled.ft.gamma[0] > every_step.ft.gamma[0],
        "γ {:?} vs every step {:?}",
        scheduled.ft.gamma,
        every_step.ft.gamma
    );
}
