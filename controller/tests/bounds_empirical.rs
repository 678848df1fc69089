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
use ftcbf_controller::params::{BoundMethod, FtParameters};
use ftcbf_controller::{Input, LinearModel, State, StateMatrix};
use nalgebra::RowVector4;
use rand::SeedableRng;
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

#[test]
fn gamma_and_theta_bound_the_fault_free_errors_as_epsilon_promises() {
    let model = corridor_model();
    let patterns = vec![vec![0, 1], vec![2, 3]];
    let p0 = StateMatrix::from_diagonal(&State::new(1e-4, 1e-4, 1e-4, 1e-4));
    let params =
        FtParameters::compute_with(&model, &patterns, DT, EPS, STEPS, &p0, BoundMethod::Horizon);
    let theta_half = params.theta[0] / 2.0;
    // The separation bound is tighter than the §4.3 triangle bound.
    assert!(
        params.theta[0] < params.theta_triangle[0],
        "{} vs {}",
        params.theta[0],
        params.theta_triangle[0]
    );
    let d = model.discretize(DT);
    let qd_sqrt = sqrt_psd(&d.qd);
    let p0_sqrt = sqrt_psd(&p0);
    let x_hat0 = State::new(0.0, 0.0, 0.1, 0.0);
    let mut runs_exceeding = 0u64;
    let mut worst_gamma_ratio = 0.0f64;
    let mut worst_theta_ratio = 0.0f64;
    for seed in 0..RUNS {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut x = x_hat0 + p0_sqrt * normal4(&mut rng);
        let mut bank = EstimatorBank::new(model.clone(), &patterns, x_hat0, p0);
        let u = Input::new(0.0, 0.0);
        let mut exceeded = false;
        let mut y = [0.0; 6];
        for _ in 0..STEPS {
            x = d.phi * x + d.gamma * u + qd_sqrt * normal4(&mut rng);
            for (k, yk) in y.iter_mut().enumerate() {
                let v: f64 = StandardNormal.sample(&mut rng);
                *yk = model.measure(k, &x) + model.r[k].sqrt() * v;
            }
            bank.step(&u, DT, &y, &[true; 6], &[false; 6]);
            let pair = *bank.pair(0, 1).expect("pair filter").estimate();
            for i in 0..2 {
                let xi = *bank.single(i).estimate();
                let g = (xi - x).norm() / params.gamma[i];
                let t = (xi - pair).norm() / theta_half;
                worst_gamma_ratio = worst_gamma_ratio.max(g);
                worst_theta_ratio = worst_theta_ratio.max(t);
                if g > 1.0 || t > 1.0 {
                    exceeded = true;
                }
            }
        }
        if exceeded {
            runs_exceeding += 1;
        }
    }
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
