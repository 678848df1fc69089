//! No safety constraint may vanish silently (issue 16): Step 2 keeps the last unit with CBF
//! rows, a non-finite row is violated (never satisfied), the fallback brakes against the best
//! finite velocity estimate, and each of these is in the decision record.

use std::sync::Arc;

use ftcbf_controller::barrier::{Barrier, BarrierEval, HalfPlane};
use ftcbf_controller::constraints::HalfSpace;
use ftcbf_controller::feasibility::Line;
use ftcbf_controller::params::FtParams;
use ftcbf_controller::policy::{
    resolve, settle, BrakeReason, BrakeVelocity, ConstraintKind, DecisionRecord, DropReason,
    PolicyScratch, QpOutcome, SafeAction, Settled, Stage, Step2Retained, Verdict,
    BRAKE_TIME_CONSTANT,
};
use ftcbf_controller::qp::{QpResult, QpSolver};
use ftcbf_controller::{
    Controller, ControllerConfig, ControllerKind, Input, LinearModel, State, StateMatrix,
};
use nalgebra::Matrix2;

mod common;
use common::{cbf, run, two_units, verdict};

fn cbf_verdict(rec: &DecisionRecord, unit: usize) -> Verdict {
    verdict(rec, unit, ConstraintKind::Cbf { barrier: 0 })
}

/// Both single-drop estimates sit more than θ/2 from a drifting pair estimate: the pair test
/// drops both units. Before the fix the problem was left with no CBF row and reported
/// `Feasible { stage: Step2 }` with u = 0; now the unit Step 3 would keep stays.
#[test]
fn step2_never_drops_the_last_unit_with_cbf_rows() {
    // u_y ≥ 1 (unit 0) and u_y ≤ −1 (unit 1): infeasible together.
    let mut p = two_units([cbf(0.0, 1.0, 1.0), cbf(0.0, -1.0, 1.0)]);
    p.estimates = vec![
        State::new(0.0, 1.0, 0.0, 0.0),
        State::new(0.0, -1.0, 0.0, 0.0),
    ];
    p.pair_estimates[(0, 1)] = State::new(5.0, 0.0, 0.0, 0.0); // drifted far from both
    p.theta[(0, 1)] = 0.1;
    p.residue_key = vec![2.0, 0.5]; // Step 3 would keep unit 1
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
    // unit 1 is kept, so its barrier holds: u_y ≤ −1
    assert!((u - Input::new(0.0, -1.0)).norm() < 1e-6, "{u}");
    assert_eq!(cbf_verdict(&rec, 1), Verdict::Kept);
    assert!(matches!(
        cbf_verdict(&rec, 0),
        Verdict::Dropped {
            stage: Stage::Step2,
            ..
        }
    ));
    match rec.step2_retained {
        Some(Step2Retained {
            unit: 1,
            failed_test:
                DropReason::PairwiseDeviation {
                    other: 0,
                    distance,
                    theta,
                    deviation_from_pair,
                },
        }) => {
            assert!((distance - 2.0).abs() < 1e-12 && theta == 0.1);
            assert!((deviation_from_pair - 26f64.sqrt()).abs() < 1e-12);
        }
        r => panic!("record says {r:?}"),
    }
    // ties in the residue key: the lowest index stays
    p.residue_key = vec![1.0, 1.0];
    let (u, _, rec) = run(&p, None);
    assert_eq!(rec.step2_retained.map(|r| r.unit), Some(0));
    assert!((u - Input::new(0.0, 1.0)).norm() < 1e-6, "{u}");
    // when the pair test leaves one unit, nothing is retained
    p.pair_estimates[(0, 1)] = State::new(0.0, -0.99, 0.0, 0.0);
    let (_, _, rec) = run(&p, None);
    assert_eq!(rec.step2_retained, None);
}

/// A NaN constraint normal with a finite, non-negative offset used to become the always-true
/// `0·u ≤ 1`, so Step 1 decided as if the barrier held. Now the row is violated: the unit
/// carrying it is resolved by the Steps, and where it remains the fallback brakes.
#[test]
fn a_nan_normal_is_violated_and_the_fallback_brakes() {
    let mut p = two_units([cbf(f64::NAN, 1.0, -0.5), cbf(0.0, 1.0, 0.2)]);
    p.estimates = vec![
        State::new(0.0, 0.0, 0.4, -0.2),
        State::new(0.0, 0.0, 0.1, 0.1),
    ];
    // Step 3 drops unit 1 (larger residue); unit 0's NaN row stays: fallback.
    p.residue_key = vec![0.5, 2.0];
    let limit = Some(Input::new(2.0, 2.0));
    let (u, o, rec) = run(&p, limit);
    assert_eq!(rec.non_finite_rows, 1);
    match o {
        QpOutcome::InfeasibleAfterStep3 {
            action:
                SafeAction::Brake {
                    reason: BrakeReason::NonFiniteRow,
                    velocity: BrakeVelocity::Remaining { unit: 0 },
                },
            max_cbf_violation,
        } => assert_eq!(max_cbf_violation, f64::INFINITY),
        o => panic!("unexpected {o:?}"),
    }
    assert_eq!(rec.stage, Stage::Fallback);
    let want = -Input::new(0.4, -0.2) / BRAKE_TIME_CONSTANT;
    assert!((u - want).norm() < 1e-12, "{u}");
    assert!(matches!(
        cbf_verdict(&rec, 1),
        Verdict::Dropped {
            stage: Stage::Step3,
            ..
        }
    ));
    // If unit 0 has the larger residue, Step 3 drops it and unit 1's barrier decides.
    p.residue_key = vec![2.0, 0.5];
    let (u, o, rec) = run(&p, limit);
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
    assert!((u - Input::new(0.0, 0.2)).norm() < 1e-6, "{u}");
    assert_eq!(rec.non_finite_rows, 1);
    // An infinite offset with an infinite normal, and an infinite normal: same verdict.
    for row in [
        cbf(f64::INFINITY, 0.0, 0.0),
        cbf(1.0, 0.0, f64::NEG_INFINITY),
    ] {
        let mut q = two_units([row, cbf(0.0, 1.0, 0.2)]);
        q.residue_key = vec![0.5, 2.0];
        let (_, o, rec) = run(&q, limit);
        assert!(
            matches!(
                o,
                QpOutcome::InfeasibleAfterStep3 {
                    action: SafeAction::Brake {
                        reason: BrakeReason::NonFiniteRow,
                        ..
                    },
                    ..
                }
            ),
            "{row:?}: {o:?}"
        );
        assert_eq!(rec.non_finite_rows, 1);
    }
}

/// The last-resort action used to coast (u = 0) when the remaining unit's velocity estimate
/// was not finite. It now brakes against the best finite velocity estimate there is (here a
/// dropped unit's), and the record says whose.
#[test]
fn brake_uses_the_best_finite_velocity_estimate() {
    let nan = f64::NAN;
    // unit 0's estimate is NaN, so its row is NaN too; unit 1 is finite.
    let mut p = two_units([cbf(nan, nan, nan), cbf(0.0, 1.0, 0.2)]);
    p.estimates = vec![
        State::new(nan, nan, nan, nan),
        State::new(1.0, 2.0, 0.3, 0.6),
    ];
    p.residue_key = vec![0.5, 2.0]; // Step 3 drops unit 1: unit 0 remains
    let (u, o, rec) = run(&p, Some(Input::new(1.0, 1.0)));
    assert!(
        matches!(
            o,
            QpOutcome::InfeasibleAfterStep3 {
                action: SafeAction::Brake {
                    reason: BrakeReason::NonFiniteRow,
                    velocity: BrakeVelocity::Dropped { unit: 1 },
                },
                ..
            }
        ),
        "{o:?}"
    );
    // −v̂/τ = (−0.6, −1.2), clipped to the box |u| ≤ 1
    assert!((u - Input::new(-0.6, -1.0)).norm() < 1e-12, "{u}");
    assert_eq!(rec.non_finite_rows, 1);
    // No finite velocity anywhere: u = 0, and the record says so.
    p.estimates[1] = State::new(1.0, 2.0, f64::INFINITY, 0.6);
    let (u, o, _) = run(&p, Some(Input::new(1.0, 1.0)));
    assert_eq!(u, Input::zeros());
    assert!(
        matches!(
            o,
            QpOutcome::InfeasibleAfterStep3 {
                action: SafeAction::Brake {
                    velocity: BrakeVelocity::NoneFinite,
                    ..
                },
                ..
            }
        ),
        "{o:?}"
    );
}

/// A barrier whose value and gradient are NaN at every state (a broken geometry query).
#[derive(Debug)]
struct NanBarrier;

impl Barrier for NanBarrier {
    fn name(&self) -> &str {
        "nan"
    }
    fn eval(&self, _x: &State) -> BarrierEval {
        BarrierEval {
            value: f64::NAN,
            gradient: State::from_element(f64::NAN),
            hessian: StateMatrix::zeros(),
        }
    }
    fn h_bar(&self, _gamma: f64) -> f64 {
        0.0
    }
}

/// End to end through the controller: a NaN barrier with a finite δ used to be left out of
/// X_t(δ) (`NaN < δ` is false) and the step was `Feasible { Step1 }` on the other barrier
/// alone. Now it is imposed, counted, and the step brakes.
#[test]
fn a_nan_barrier_is_imposed_and_fails_closed_in_the_controller() {
    for kind in [ControllerKind::FtCbfClf, ControllerKind::Baseline] {
        let model = LinearModel::paper_double_integrator(1e-3, 1e-3).unwrap();
        let cfg = ControllerConfig::builder(
            model,
            vec![vec![1], vec![3]],
            FtParams::uniform(2, 0.01, 0.5),
        )
        .kind(kind)
        .barriers(vec![
            Arc::new(HalfPlane::new(
                "y ≥ −1",
                State::new(0.0, 1.0, 0.0, 0.5),
                -1.0,
            )),
            Arc::new(NanBarrier),
        ])
        .goal(State::zeros(), 0.05)
        .delta(0.5)
        .input_limit(Input::new(2.0, 2.0))
        .start(
            State::new(1.0, 0.0, 0.2, 0.0),
            StateMatrix::identity() * 1e-3,
        )
        .build();
        let mut c = Controller::new(cfg).unwrap();
        let out = c.step(&[1.0, 1.0, 0.0, 0.0, 0.2, 0.0], &[true; 6], 0.01);
        let units = if kind == ControllerKind::FtCbfClf {
            2
        } else {
            1
        };
        assert_eq!(out.decision.non_finite_rows, units, "{kind:?}");
        assert!(
            matches!(
                out.qp,
                QpOutcome::InfeasibleAfterStep3 {
                    action: SafeAction::Brake {
                        reason: BrakeReason::NonFiniteRow,
                        velocity: BrakeVelocity::Remaining { .. },
                    },
                    ..
                }
            ),
            "{kind:?}: {:?}",
            out.qp
        );
        // braking against v̂_x ≈ 0.2 m/s
        assert!(out.u[0] < -0.3 && out.u[0] > -0.5, "{kind:?}: {}", out.u);
    }
}

/// Step 3 and a box too small for one estimator (issue #10): unit 0's row u_y ≥ 1.5 cannot be
/// met with |u| ≤ 1, unit 1's u_y ≤ 0.2 can. Unit 0 has the larger residue. The paper's Step 3
/// drops it and applies unit 1's input (u_y ≤ 0.2); with `step3_keeps_saturated` (what the
/// controller runs) nothing is dropped by residue, the record names the saturated unit, and the
/// fallback weighs both rows: u_y is pushed up toward unit 0's demand.
#[test]
fn step3_does_not_drop_an_estimator_the_box_cannot_satisfy() {
    let limit = Some(Input::new(1.0, 1.0));
    let mut p = two_units([cbf(0.0, 1.0, 1.5), cbf(0.0, -1.0, -0.2)]);
    p.residue_key = vec![3.0, 0.1];
    let (u, o, rec) = run(&p, limit);
    let stage = match o {
        QpOutcome::Feasible { stage, .. } => Some(stage),
        QpOutcome::InfeasibleAfterStep3 { .. } | QpOutcome::SafeStop { .. } => None,
    };
    assert_eq!(stage, Some(Stage::Step3), "{o:?}");
    assert!(u[1] <= 0.2 + 1e-6, "{u}");
    assert_eq!(rec.step3_saturated, None);

    p.step3_keeps_saturated = true;
    let (u, o, rec) = run(&p, limit);
    assert!(
        matches!(
            o,
            QpOutcome::InfeasibleAfterStep3 {
                action: SafeAction::MinimiseMaxViolation,
                ..
            }
        ),
        "{o:?}"
    );
    assert_eq!(rec.step3_saturated, Some(0));
    assert_eq!(cbf_verdict(&rec, 0), Verdict::Relaxed);
    assert_eq!(cbf_verdict(&rec, 1), Verdict::Relaxed);
    // min over |u| ≤ 1 of max(1.5 − u_y, u_y − 0.2) (unit-norm rows): u_y = 0.85
    assert!((u[1] - 0.85).abs() < 1e-3, "{u}");
}

/// Issue #30: when the exact 2-D test certifies a feasible set, a solver failure on it must not
/// send the policy on to Step 3 (which drops a unit, possibly the honest one): the stage decides
/// with the test's witness. A solver built for one CBF row fails (`TooManyRows`) on Step 1's two.
#[test]
fn a_certified_feasible_set_uses_the_witness_when_the_solver_fails() {
    // u_y ≥ 1 (unit 0) and u_x ≥ 1 (unit 1): feasible together in |u| ≤ 2.
    let mut p = two_units([cbf(0.0, 1.0, 1.0), cbf(1.0, 0.0, 1.0)]);
    p.residue_key = vec![2.0, 0.5];
    let limit = Some(Input::new(2.0, 2.0));
    let mut qp = QpSolver::new(1, 0, Matrix2::identity(), 1e4, limit);
    let mut s = PolicyScratch::new(2, 1);
    let mut rec = DecisionRecord::with_capacity(4);
    let (u, o) = resolve(&p, &mut qp, &mut s, &mut rec);
    assert!(
        matches!(
            o,
            QpOutcome::Feasible {
                stage: Stage::Step1,
                ..
            }
        ),
        "{o:?}"
    );
    assert_eq!((rec.solver_failures, rec.witness_inputs), (1, 1));
    assert!(u[0] >= 1.0 - 1e-7 && u[1] >= 1.0 - 1e-7, "{u}");
    assert!(u[0] <= 2.0 + 1e-7 && u[1] <= 2.0 + 1e-7, "{u}");
    assert_eq!(cbf_verdict(&rec, 0), Verdict::Kept);
    assert_eq!(cbf_verdict(&rec, 1), Verdict::Kept);
}

/// Issue #30: clarabel's AlmostSolved (or any) answer is rechecked against the hard rows the
/// test certified; one that violates a row is replaced by the witness, and the reported slack is
/// the soft rows' largest violation at the witness.
#[test]
fn a_solver_answer_that_violates_a_hard_row_is_replaced_by_the_witness() {
    let hard = [Line::from_half_space(&HalfSpace {
        normal: Input::new(0.0, -2.0),
        offset: -2.0, // u_y ≥ 1
    })];
    let soft = [HalfSpace {
        normal: Input::new(1.0, 0.0),
        offset: -0.5, // u_x ≤ −0.5, soft
    }];
    let witness = Input::new(1.0, 1.5);
    let limit = Some(Input::new(2.0, 2.0));
    let bad = QpResult::Feasible {
        u: Input::new(0.0, 0.99),
        slack: 0.0,
        iterations: 7,
    };
    let s = settle(bad, &hard, limit, witness, &soft);
    assert!(s.witness_used);
    match s.result {
        QpResult::Feasible { u, slack, .. } => {
            // moved along the segment to the witness just far enough: t = 0.01/0.51
            let t = 0.01 / 0.51;
            assert!((u - Input::new(t, 0.99 + 0.51 * t)).norm() < 1e-9, "{u}");
            assert!(u[1] >= 1.0 - 1e-9, "{u}");
            assert!((slack - (t + 0.5)).abs() < 1e-9, "{slack}");
        }
        r => panic!("{r:?}"),
    }
    // a failed solve: the witness itself
    let failed = QpResult::SolverFailure {
        status: clarabel::solver::SolverStatus::InsufficientProgress,
    };
    let s = settle(failed, &hard, limit, witness, &soft);
    assert_eq!(
        s.result,
        QpResult::Feasible {
            u: witness,
            slack: 1.5,
            iterations: 0
        }
    );
    // an answer inside the rows (within the test's tolerance) is kept as it is
    let good = QpResult::Feasible {
        u: Input::new(-0.5, 1.0 - 1e-9),
        slack: 0.0,
        iterations: 7,
    };
    assert_eq!(
        settle(good, &hard, limit, witness, &soft),
        Settled {
            result: good,
            witness_used: false
        }
    );
    // outside the box, or not finite: replaced by an input inside both
    for u in [Input::new(2.5, 1.0), Input::new(f64::NAN, 1.0)] {
        let r = QpResult::Feasible {
            u,
            slack: 0.0,
            iterations: 1,
        };
        let s = settle(r, &hard, limit, witness, &soft);
        assert!(s.witness_used, "{u}");
        match s.result {
            QpResult::Feasible { u: v, .. } => {
                assert!(
                    ftcbf_controller::feasibility::admits(&hard, limit, v),
                    "{u} → {v}"
                )
            }
            r => panic!("{r:?}"),
        }
    }
}
