//! Known answers for the path behind θ_ij in worlds whose pair filters dead-reckon:
//! [`observable`] decides whether a channel set has a steady state, and [`horizon_riccati`]
//! gives the largest covariance over a run when it has none.

use ftcbf_controller::estimator::EstimatorBank;
use ftcbf_controller::params::{horizon_riccati, observable, steady_state_riccati};
use ftcbf_controller::{Input, LinearModel, State, StateMatrix};

/// Channels of the paper's observation (eq. 6.5): 0, 1 = x; 2, 3 = y; 4 = v_x; 5 = v_y.
fn uses(channels: &[usize]) -> Vec<bool> {
    (0..6).map(|k| channels.contains(&k)).collect()
}

#[test]
fn observability_of_channel_sets_of_the_double_integrator() {
    let model = LinearModel::paper_double_integrator(1e-3, 1e-3).unwrap();
    let phi = model.discretize(0.02).phi;
    let cases: [(&[usize], bool); 8] = [
        (&[0, 1, 2, 3, 4, 5], true),
        (&[0, 2], true),     // both positions: velocities follow from Φ
        (&[1, 3], true),     // the redundant fixes alone
        (&[0, 1, 2], true),  // x twice and y
        (&[4, 5], false),    // odometry only: the position is not observable
        (&[0, 4, 5], false), // y never measured
        (&[0, 1], false),    // x only
        (&[], false),
    ];
    for (channels, want) in cases {
        assert_eq!(
            observable(&model, &uses(channels), &phi),
            want,
            "channels {channels:?}"
        );
    }
    // Φ = I (dt = 0): positions alone no longer reveal the velocities.
    assert!(!observable(
        &model,
        &uses(&[0, 2]),
        &StateMatrix::identity()
    ));
    assert!(observable(
        &model,
        &uses(&[0, 2, 4, 5]),
        &StateMatrix::identity()
    ));
    // an unobservable set has no steady state
    let s = steady_state_riccati(&model, &uses(&[4, 5]), 0.02);
    assert!(!s.converged && s.iterations == 0);
}

/// Open loop from P0 = 0 with Q = q·I: the exact (Van Loan) discretisation makes the n-step
/// covariance the continuous one at T = n·dt, per axis [[qT + qT³/3, qT²/2], [qT²/2, qT]].
/// It grows, so the largest over the horizon is the last.
#[test]
fn horizon_riccati_open_loop_is_the_continuous_covariance() {
    let q = 2e-3;
    let model = LinearModel::paper_double_integrator(q, 1e-3).unwrap();
    for (dt, n) in [(0.02, 1usize), (0.02, 500), (0.1, 37)] {
        let p = horizon_riccati(&model, &uses(&[]), dt, &StateMatrix::zeros(), n);
        let t = n as f64 * dt;
        let mut want = StateMatrix::zeros();
        for a in 0..2 {
            want[(a, a)] = q * t + q * t.powi(3) / 3.0;
            want[(a, a + 2)] = q * t * t / 2.0;
            want[(a + 2, a)] = q * t * t / 2.0;
            want[(a + 2, a + 2)] = q * t;
        }
        let err = (p - want).amax() / want.amax();
        assert!(
            err < 1e-9,
            "dt = {dt}, n = {n}: relative error {err}\n{p}\n{want}"
        );
    }
    // n = 0: nothing happens, the start covariance is returned
    let p0 = StateMatrix::identity() * 0.3;
    assert_eq!(horizon_riccati(&model, &uses(&[]), 0.02, &p0, 0), p0);
}

#[test]
fn horizon_riccati_keeps_the_largest_covariance() {
    let model = LinearModel::paper_double_integrator(1e-3, 1e-3).unwrap();
    // All channels from a large P0: every update shrinks P, so the largest is P0 itself.
    let p0 = StateMatrix::identity() * 100.0;
    assert_eq!(
        horizon_riccati(&model, &uses(&[0, 1, 2, 3, 4, 5]), 0.02, &p0, 200),
        p0
    );
    // Dead reckoning (velocities only): the position variance grows for ever, so the largest
    // is the last step's, which the bank's own filter (an independent implementation of the
    // same recursion) reaches after the same number of steps.
    let p0 = StateMatrix::identity() * 1e-2;
    let n = 300;
    let p = horizon_riccati(&model, &uses(&[4, 5]), 0.02, &p0, n);
    let mut bank = EstimatorBank::new(model.clone(), &[vec![0, 1, 2, 3]], State::zeros(), p0);
    for _ in 0..n {
        bank.step(&Input::zeros(), 0.02, &[0.0; 6], &[true; 6], &[false; 6]);
    }
    let f = bank.single(0).covariance();
    assert!(
        (p - f).amax() < 1e-12 * f.amax(),
        "{p}\nvs the filter's\n{f}"
    );
    // and it is larger than at any earlier step
    let earlier = horizon_riccati(&model, &uses(&[4, 5]), 0.02, &p0, n / 2);
    assert!(p[(0, 0)] > earlier[(0, 0)] && p[(1, 1)] > earlier[(1, 1)]);
}
