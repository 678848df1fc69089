//! Unit tests with known answers: the policy's stages on constructed cases, KKT of the QP,
//! Proposition 3 against a numerical minimisation of (A.1), and sensor-reading hygiene.

use ftcbf_controller::barrier::{Barrier, EllipsoidInside, EllipsoidOutside};
use ftcbf_controller::constraints::{CbfRow, ClfRow, HalfSpace};
use ftcbf_controller::policy::{
    ConstraintKind, DropReason, PolicyProblem, QpOutcome, SafeAction, Stage, Verdict,
};
use ftcbf_controller::qp::{QpResult, QpSolver, RowMode};
use ftcbf_controller::{Controller, ControllerKind, Input, State, StateMatrix};
use nalgebra::Matrix2;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

// ------------------------------------------------------------------------------------------
// Policy stages
// ------------------------------------------------------------------------------------------

mod common;
use common::{cbf, run, verdict};

/// Two units, one barrier, no CLF unless set; θ finite on the pair (10), ∞ on the diagonal.
fn two_units(rows: [CbfRow; 2]) -> PolicyProblem {
    let mut p = common::two_units(rows);
    p.theta[(0, 1)] = 10.0;
    p
}

const OMEGA: ConstraintKind = ConstraintKind::Cbf { barrier: 0 };
const TOL: f64 = 1e-6;

#[test]
fn step1_decides_when_constraints_are_compatible() {
    let p = two_units([cbf(0.0, 1.0, 0.5), cbf(0.0, 2.0, 0.4)]);
    let (u, o, rec) = run(&p, None);
    assert!(
        matches!(
            o,
            QpOutcome::Feasible {
                stage: Stage::Step1,
                clf_relaxed: false,
                ..
            }
        ),
        "{o:?}"
    );
    assert_eq!(rec.stage, Stage::Step1);
    // min ‖u‖² s.t. u_y ≥ 0.5, 2u_y ≥ 0.4 → (0, 0.5)
    assert!((u - Input::new(0.0, 0.5)).norm() < TOL, "{u}");
    assert_eq!(verdict(&rec, 0, OMEGA), Verdict::Kept);
    assert_eq!(verdict(&rec, 1, OMEGA), Verdict::Kept);
    assert_eq!(rec.qp_solves, 1);
}

#[test]
fn step2_drops_the_filter_far_from_the_pair_estimate() {
    // u_y ≥ 1 (unit 0) and u_y ≤ −1 (unit 1): infeasible together.
    let mut p = two_units([cbf(0.0, 1.0, 1.0), cbf(0.0, -1.0, 1.0)]);
    p.estimates = vec![State::new(0.0, 1.0, 0.0, 0.0), State::zeros()];
    let pair = State::new(0.0, 0.01, 0.0, 0.0);
    p.pair_estimates[(0, 1)] = pair;
    p.theta[(0, 1)] = 0.1;
    p.residue_key = vec![0.0, 100.0]; // Step 3 would drop unit 1: Step 2 must decide first
    let (u, o, rec) = run(&p, None);
    assert!(
        matches!(
            o,
            QpOutcome::Feasible {
                stage: Stage::Step2,
                ..
            }
        ),
        "{o:?}"
    );
    assert!((u - Input::new(0.0, -1.0)).norm() < TOL, "{u}");
    match verdict(&rec, 0, OMEGA) {
        Verdict::Dropped {
            stage: Stage::Step2,
            reason:
                DropReason::PairwiseDeviation {
                    other,
                    distance,
                    theta,
                    deviation_from_pair,
                },
        } => {
            assert_eq!(other, 1);
            assert!((distance - 1.0).abs() < 1e-12 && theta == 0.1);
            assert!((deviation_from_pair - 0.99).abs() < 1e-12);
        }
        v => panic!("unexpected {v:?}"),
    }
    assert_eq!(verdict(&rec, 1, OMEGA), Verdict::Kept);
}

#[test]
fn step3_drops_the_largest_residue() {
    let mut p = two_units([cbf(0.0, 1.0, 1.0), cbf(0.0, -1.0, 1.0)]);
    // θ large: Step 2 drops nothing
    p.residue_key = vec![5.0, 1.0];
    let (u, o, rec) = run(&p, None);
    assert!(
        matches!(
            o,
            QpOutcome::Feasible {
                stage: Stage::Step3,
                ..
            }
        ),
        "{o:?}"
    );
    assert!((u - Input::new(0.0, -1.0)).norm() < TOL, "{u}");
    assert_eq!(
        verdict(&rec, 0, OMEGA),
        Verdict::Dropped {
            stage: Stage::Step3,
            reason: DropReason::LargestResidue {
                residue: 5.0,
                flagged: false,
                window_chi2: 0.0,
                window_dof: 0,
            }
        }
    );
    // a flagged filter ranks first regardless of its numeric residue
    p.residue_key = vec![5.0, f64::INFINITY];
    p.flagged = vec![false, true];
    let (u, _, rec) = run(&p, None);
    assert!((u - Input::new(0.0, 1.0)).norm() < TOL, "{u}");
    assert!(matches!(
        verdict(&rec, 1, OMEGA),
        Verdict::Dropped {
            stage: Stage::Step3,
            reason: DropReason::LargestResidue { flagged: true, .. }
        }
    ));
}

#[test]
fn clf_is_relaxed_before_any_barrier_is_dropped() {
    let mut p = two_units([cbf(0.0, 1.0, 1.0), cbf(0.0, 1.0, 0.5)]);
    p.use_clf = true;
    // unit 1's CLF wants u_y ≤ −1: conflicts with both CBF rows
    p.clf[1] = ClfRow {
        lg_v: Input::new(0.0, 1.0),
        tau_bar: -1.0,
        v: 10.0,
    };
    p.clf_active = vec![false, true];
    p.residue_key = vec![5.0, 1.0];
    let (u, o, rec) = run(&p, None);
    match o {
        QpOutcome::Feasible {
            stage: Stage::ClfRelaxation,
            clf_relaxed: true,
            clf_slack,
            ..
        } => {
            assert!((clf_slack - 2.0).abs() < 1e-3, "slack {clf_slack}")
        }
        o => panic!("unexpected {o:?}"),
    }
    // both barriers still hold: u_y ≥ 1
    assert!(u[1] >= 1.0 - TOL, "{u}");
    assert_eq!(verdict(&rec, 0, OMEGA), Verdict::Kept);
    assert_eq!(verdict(&rec, 1, OMEGA), Verdict::Kept);
    assert_eq!(verdict(&rec, 1, ConstraintKind::Clf), Verdict::Relaxed);
    assert!(matches!(
        verdict(&rec, 0, ConstraintKind::Clf),
        Verdict::Inactive(_)
    ));
}

#[test]
fn infeasible_after_step3_is_a_typed_outcome_with_a_safe_action() {
    // box |u| ≤ 1; unit 1 needs u_y ≥ 2 (impossible even alone), unit 0 needs u_x ≥ 0.5
    let mut p = two_units([cbf(1.0, 0.0, 0.5), cbf(0.0, 1.0, 2.0)]);
    p.residue_key = vec![3.0, 1.0];
    let (u, o, rec) = run(&p, Some(Input::new(1.0, 1.0)));
    match o {
        QpOutcome::InfeasibleAfterStep3 {
            action: SafeAction::MinimiseMaxViolation,
            max_cbf_violation,
        } => {
            assert!(
                (max_cbf_violation - 1.0).abs() < 1e-3,
                "{max_cbf_violation}"
            );
        }
        o => panic!("unexpected {o:?}"),
    }
    assert_eq!(rec.stage, Stage::Fallback);
    // unit 0 (largest residue) was dropped by Step 3; the remaining row is pushed to the box
    assert!(matches!(
        verdict(&rec, 0, OMEGA),
        Verdict::Dropped {
            stage: Stage::Step3,
            ..
        }
    ));
    assert_eq!(verdict(&rec, 1, OMEGA), Verdict::Relaxed);
    assert!((u[1] - 1.0).abs() < 1e-3, "{u}");
    assert!(u.amax() <= 1.0 + TOL);
}

// ------------------------------------------------------------------------------------------
// KKT
// ------------------------------------------------------------------------------------------

/// KKT of min ½zᵀPz s.t. Az ≤ b: Pz + Aᵀλ = 0, Az ≤ b, λ ≥ 0, λ_i (b_i − a_i z) = 0.
/// Tolerance 1e-6 relative to the scale of the cost gradient, `max(1, ‖Pz‖∞)` (clarabel's
/// default tolerances are 1e-8 relative; the slack weight 1e4 makes ‖Pz‖ large when s > 0).
#[test]
fn qp_solutions_satisfy_kkt() {
    let mut rng = ChaCha8Rng::seed_from_u64(42);
    let mut qp = QpSolver::new(
        3,
        2,
        Matrix2::new(2.0, 0.3, 0.3, 1.0),
        1e4,
        Some(Input::new(3.0, 3.0)),
    );
    let mut checked = 0;
    for trial in 0..200 {
        let mk = |rng: &mut ChaCha8Rng| HalfSpace {
            normal: Input::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0)),
            offset: rng.random_range(-1.0..0.5),
        };
        let cbf: Vec<HalfSpace> = (0..3).map(|_| mk(&mut rng)).collect();
        let clf: Vec<HalfSpace> = (0..2).map(|_| mk(&mut rng)).collect();
        let mode = if trial % 2 == 0 {
            RowMode::Hard
        } else {
            RowMode::Soft
        };
        match qp.solve(&cbf, RowMode::Hard, &clf, mode) {
            QpResult::Feasible { .. } => {
                let (a, b) = qp.last_rows();
                let (x, z) = qp.last_primal_dual();
                let pv = qp.cost_diagonal();
                let px = [
                    pv[0] * x[0] + pv[1] * x[1],
                    pv[1] * x[0] + pv[2] * x[1],
                    pv[3] * x[2],
                ];
                let rows = b.len();
                let tol = 1e-6 * px.iter().fold(1.0_f64, |m, v| m.max(v.abs()));
                for c in 0..3 {
                    let s: f64 = (0..rows).map(|r| a[r * 3 + c] * z[r]).sum();
                    assert!((px[c] + s).abs() < tol, "stationarity {c}: {}", px[c] + s);
                }
                for r in 0..rows {
                    let ax: f64 = (0..3).map(|c| a[r * 3 + c] * x[c]).sum();
                    assert!(ax <= b[r] + tol, "primal row {r}: {ax} > {}", b[r]);
                    assert!(z[r] >= -tol, "dual {r}: {}", z[r]);
                    assert!(
                        (z[r] * (b[r] - ax)).abs() < tol,
                        "complementarity trial {trial} row {r}: z = {}, gap = {}, x = {x:?}",
                        z[r],
                        b[r] - ax
                    );
                }
                checked += 1;
            }
            QpResult::Infeasible { .. } => {}
            other => panic!("solver failure {other:?}"),
        }
    }
    assert!(checked > 50, "only {checked} feasible problems");
}

// ------------------------------------------------------------------------------------------
// Proposition 3
// ------------------------------------------------------------------------------------------

/// min over ‖x − x0‖ ≤ γ of (x − x')ᵀΦ(x − x') (or max when `maximise`), projected gradient.
fn ball_extremum(phi: &StateMatrix, x0: &State, gamma: f64, maximise: bool) -> f64 {
    let lmax = phi.symmetric_eigenvalues().max();
    let step = 0.5 / lmax;
    let mut x = *x0;
    let sign = if maximise { -1.0 } else { 1.0 };
    if maximise {
        // start at the boundary point along the gradient to leave the saddle
        x = x0 + x0.normalize() * gamma;
    }
    for _ in 0..400 {
        let grad = 2.0 * phi * x;
        x -= sign * step * grad;
        let d = x - x0;
        if d.norm() > gamma {
            x = x0 + d * (gamma / d.norm());
        }
    }
    x.dot(&(phi * x))
}

/// h̄ by brute force: sample x0 on {xᵀΦx = 1} (Φ-normalised random directions, plus the
/// eigen-axes), solve the inner ball problem for each.
fn h_bar_brute(phi: &StateMatrix, gamma: f64, inside: bool, rng: &mut ChaCha8Rng) -> f64 {
    let mut best = f64::NEG_INFINITY;
    let mut dirs: Vec<State> = (0..4)
        .map(|i| State::from_fn(|r, _| if r == i { 1.0 } else { 0.0 }))
        .collect();
    for _ in 0..3000 {
        dirs.push(State::from_fn(|_, _| rng.random_range(-1.0..1.0)));
    }
    for d in dirs {
        let x0 = d / d.dot(&(phi * d)).sqrt();
        let v = ball_extremum(phi, &x0, gamma, !inside);
        let h = if inside { 1.0 - v } else { v - 1.0 };
        best = best.max(h);
    }
    best
}

#[test]
fn proposition3_matches_numerical_minimisation() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let phi = StateMatrix::from_diagonal(&State::new(4.0, 1.0, 2.0, 0.5));
    let e = EllipsoidInside::new("e", State::zeros(), phi);
    for gamma in [0.05, 0.2, 0.4, 0.6] {
        let brute = h_bar_brute(&phi, gamma, true, &mut rng);
        let closed = e.h_bar(gamma);
        assert!(
            (brute - closed).abs() < 1e-6,
            "γ = {gamma}: brute {brute} vs Prop. 3 {closed}"
        );
    }
    // saturated case γ ≥ 1/√λ̄ = 0.5
    assert_eq!(e.h_bar(0.6), 1.0);
    // outside case: (1 + γ√λ̄)² − 1
    let o = EllipsoidOutside::new("o", State::zeros(), phi);
    for gamma in [0.05, 0.3] {
        let brute = h_bar_brute(&phi, gamma, false, &mut rng);
        assert!(
            (brute - o.h_bar(gamma)).abs() < 1e-6,
            "outside γ = {gamma}: {brute} vs {}",
            o.h_bar(gamma)
        );
    }
}

// ------------------------------------------------------------------------------------------
// Reading hygiene
// ------------------------------------------------------------------------------------------

#[test]
fn nan_inf_and_absurd_readings_never_reach_an_update() {
    let y_ok = [1.0, 1.0, 0.0, 0.0, 0.0, 0.0];
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 1e12] {
        let mut attacked = Controller::new(common::small_config()).expect("config");
        let mut reference = Controller::new(common::small_config()).expect("config");
        for _ in 0..20 {
            let mut y = y_ok;
            y[3] = bad;
            let out = attacked.step(&y, &[true; 6], 0.01).clone();
            // the reference never sees channel 3 at all
            let mut fresh = [true; 6];
            fresh[3] = false;
            reference.step(&y_ok, &fresh, 0.01);
            assert_eq!(out.rejected.count, 1);
            assert!(out.rejected.channels[3] && out.rejected.patterns == vec![false, true]);
            assert!(out.u.iter().all(|v| v.is_finite()));
        }
        for (fa, fr) in attacked
            .bank()
            .filters()
            .iter()
            .zip(reference.bank().filters())
        {
            assert_eq!(
                fa.estimate(),
                fr.estimate(),
                "{} moved with a rejected reading ({bad})",
                fa.label()
            );
            assert_eq!(fa.covariance(), fr.covariance());
            // filters that use channel 3 are flagged and rank first in Step 3
            assert_eq!(fa.flagged(), fa.uses_channel(3));
            assert_eq!(fa.residue_rank_key() == f64::INFINITY, fa.uses_channel(3));
        }
    }
}

#[test]
fn bad_configs_are_typed_errors() {
    let mut c = common::small_config();
    c.fault_patterns = vec![vec![1, 3], vec![3]];
    assert!(matches!(
        Controller::new(c),
        Err(ftcbf_controller::ConfigError::Model(
            ftcbf_controller::ModelError::OverlappingPatterns { channel: 3, .. }
        ))
    ));
    let mut c = common::small_config();
    c.ft.gamma = vec![0.001];
    assert!(matches!(
        Controller::new(c),
        Err(ftcbf_controller::ConfigError::Length { key: "gamma", .. })
    ));
    let mut c = common::small_config();
    c.ft.theta = vec![f64::NAN];
    assert!(matches!(
        Controller::new(c),
        Err(ftcbf_controller::ConfigError::BadValue { key: "theta", .. })
    ));
    let mut c = common::small_config();
    c.delta = f64::INFINITY;
    assert!(Controller::new(c).is_ok());
}

#[test]
fn short_inputs_and_bad_dt_do_not_panic() {
    let mut c = Controller::new(common::small_config()).expect("config");
    let before = *c.bank().single(0).estimate();
    let out = c.step(&[1.0, 1.0], &[true, true, true], f64::NAN);
    assert!(out.rejected.length_mismatch && out.rejected.invalid_dt);
    assert!(out.u.iter().all(|v| v.is_finite()));
    assert_eq!(*c.bank().single(0).estimate(), before);
    let out = c.step(&[1.0, 1.0], &[true, true], 0.01);
    assert!(out.rejected.length_mismatch && !out.rejected.invalid_dt);
}

#[test]
fn same_inputs_give_bit_identical_outputs() {
    let mut a = Controller::new(common::small_config()).expect("config");
    let mut b = Controller::new(common::small_config()).expect("config");
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    for _ in 0..300 {
        let y: Vec<f64> = (0..6).map(|_| rng.random_range(-0.1..1.1)).collect();
        let ua = a.step(&y, &[true; 6], 0.01).u;
        let ub = b.step(&y, &[true; 6], 0.01).u;
        assert_eq!(ua.as_slice(), ub.as_slice());
    }
}

#[test]
fn baseline_and_nominal_use_the_all_channel_filter() {
    let mut cfg = common::small_config();
    cfg.kind = ControllerKind::Nominal;
    let mut nominal = Controller::new(cfg).expect("config");
    let y = [1.0, 1.0, 0.0, 0.0, 0.0, 0.0];
    for _ in 0..100 {
        let out = nominal.step(&y, &[true; 6], 0.01);
        // no barrier rows at all; one CLF decision for the single unit
        assert_eq!(out.decision.decisions.len(), 1);
        assert_eq!(out.decision.decisions[0].kind, ConstraintKind::Clf);
    }
    // at x = (1, 0, 0, 0) the CLF pushes towards the goal at the origin
    assert!(nominal.output().u[0] < 0.0, "{}", nominal.output().u);
    let mut cfg = common::small_config();
    cfg.kind = ControllerKind::Baseline;
    let mut baseline = Controller::new(cfg).expect("config");
    let mut y4 = y;
    y4[3] = 1.0; // attacked y4 biases the all-channel estimate by about +0.5 in y
    for _ in 0..200 {
        let out = baseline.step(&y4, &[true; 6], 0.01);
        assert!(out.decision.decisions.iter().all(|d| d.unit == 0));
        assert_eq!(out.decision.decisions.len(), 2);
    }
    let est = baseline.bank().baseline().estimate();
    assert!(est[1] > 0.3 && est[1] < 0.7, "{est}");
    // logging values: h per (filter, barrier) and V per filter; 4 filters, 1 barrier
    assert_eq!(
        baseline.output().h_values.len(),
        baseline.bank().filters().len()
    );
    let hb = baseline
        .barrier_value(baseline.bank().baseline_index(), 0)
        .expect("h");
    assert!((hb - (est[1] + 0.2 * est[3] + 0.05)).abs() < 1e-12);
    assert!(baseline.clf_value(0).expect("V") > 0.0);
}

#[test]
fn the_reused_solver_is_built_once() {
    let mut qp = QpSolver::new(2, 2, Matrix2::identity(), 1e4, Some(Input::new(2.0, 2.0)));
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    for _ in 0..500 {
        let rows = [
            HalfSpace {
                normal: Input::new(rng.random_range(-1.0..1.0), 1.0),
                offset: rng.random_range(-1.0..1.0),
            },
            HalfSpace {
                normal: Input::new(1.0, rng.random_range(-1.0..1.0)),
                offset: rng.random_range(-1.0..1.0),
            },
        ];
        let r = qp.solve(&rows, RowMode::Hard, &rows[..1], RowMode::Soft);
        assert!(
            matches!(r, QpResult::Feasible { .. } | QpResult::Infeasible { .. }),
            "{r:?}"
        );
    }
    let (solves, builds) = qp.counters();
    assert_eq!(solves, 500);
    assert!(builds <= 2, "{builds} from-scratch builds");
}
