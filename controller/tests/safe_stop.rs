//! The safe stop (issue #50, `Fallback::Brake`): where Steps 1–2 leave no input meeting every
//! kept unit's rows and the residues are no evidence which unit lies, the policy brakes and
//! keeps every unit's rows on the record instead of dropping one by residue; with evidence
//! (a flagged unit, or a key above z_α) it drops as Step 3 does; `Fallback::Paper` is Step 3.

use ftcbf_controller::policy::{
    BrakeVelocity, ConstraintKind, DropReason, Fallback, QpOutcome, SafeAction, Stage, Verdict,
    DEFAULT_EVIDENCE_ALPHA, SAFE_STOP_TIME_CONSTANT,
};
use ftcbf_controller::{Controller, Input, State};

mod common;
use common::{cbf, run, small_config, two_units, verdict};

/// u_y ≥ 1 (unit 0) and u_y ≤ −1 (unit 1): no input meets both; Step 2 has nothing to isolate
/// (θ = +∞ as `PolicyProblem::new` leaves it).
fn conflicting(keys: [f64; 2]) -> ftcbf_controller::policy::PolicyProblem {
    let mut p = two_units([cbf(0.0, 1.0, 1.0), cbf(0.0, -1.0, 1.0)]);
    p.estimates = vec![
        State::new(0.0, 0.3, 0.1, -0.2),
        State::new(0.0, -0.9, 0.4, 0.5),
    ];
    p.residue_key = keys.to_vec();
    p.fallback = Fallback::brake(DEFAULT_EVIDENCE_ALPHA).expect("α in (0, 0.5)");
    // γ = 0.1 each: the estimates (1.3 m apart in state norm) cannot both be honest.
    p.gamma = vec![0.1, 0.1];
    p
}

fn evidence_z() -> f64 {
    match Fallback::brake(DEFAULT_EVIDENCE_ALPHA) {
        Some(Fallback::Brake { evidence_z }) => evidence_z,
        other => panic!("{other:?}"),
    }
}

#[test]
fn the_evidence_threshold_is_the_normal_quantile_of_alpha() {
    // Φ⁻¹(1 − 10⁻⁶) = 4.753424 (tables); out-of-range α is refused.
    assert!((evidence_z() - 4.753_424).abs() < 1e-5, "{}", evidence_z());
    assert!(Fallback::brake(0.0).is_none());
    assert!(Fallback::brake(0.5).is_none());
    assert!(Fallback::brake(f64::NAN).is_none());
}

#[test]
fn without_evidence_the_policy_brakes_and_keeps_every_units_rows() {
    // Keys 1.0 and 2.5: both within what an honest filter's noise gives (z ≈ 4.75).
    let p = conflicting([1.0, 2.5]);
    let (u, o, rec) = run(&p, Some(Input::new(1.0, 1.0)));
    let QpOutcome::SafeStop {
        reason, velocity, ..
    } = o
    else {
        panic!("expected a safe stop, got {o:?}");
    };
    assert_eq!(rec.stage, Stage::SafeStop);
    assert_eq!(
        (reason.would_drop, reason.other),
        (1, 0),
        "Step 3 would drop unit 1"
    );
    assert_eq!(reason.would_drop_key, 2.5);
    assert!(
        (reason.separation - 1.2).abs() < 1e-12,
        "position distance: {}",
        reason.separation
    );
    assert!(!reason.step2_isolated);
    // Nobody dropped: both rows are on the record, relaxed (not met).
    for unit in 0..2 {
        assert!(!rec.unit_dropped(unit));
        assert_eq!(
            verdict(&rec, unit, ConstraintKind::Cbf { barrier: 0 }),
            Verdict::Relaxed
        );
    }
    // u = −v̂/τ_s from the kept unit with the smallest key (unit 0, v̂ = (0.1, −0.2)).
    assert_eq!(velocity, BrakeVelocity::Remaining { unit: 0 });
    let want = Input::new(-0.1, 0.2) / SAFE_STOP_TIME_CONSTANT;
    assert!((u - want).norm() < 1e-12, "u = {u}, want {want}");
}

#[test]
fn without_evidence_a_unit_the_box_cannot_satisfy_keeps_the_saturated_rule_when_both_may_be_honest()
{
    // Unit 0 needs u_y ≥ 1.5 with |u_y| ≤ 1: saturated, no evidence against either unit.
    let mut p = conflicting([1.0, 2.5]);
    p.cbf[0] = cbf(0.0, 1.0, 1.5);
    p.step3_keeps_saturated = true;
    // Further apart than γ_0 + γ_1: one lies, the robot brakes.
    let (_, o, _) = run(&p, Some(Input::new(1.0, 1.0)));
    assert!(matches!(o, QpOutcome::SafeStop { .. }), "{o:?}");
    // Within γ_0 + γ_1 both may be honest: the box, not a lie, keeps the rows apart.
    p.gamma = vec![1.0, 1.0];
    let (_, o, rec) = run(&p, Some(Input::new(1.0, 1.0)));
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
    // With evidence against unit 1 it is dropped although unit 0 is saturated.
    p.residue_key = vec![1.0, evidence_z() + 1.0];
    let (_, _, rec) = run(&p, Some(Input::new(1.0, 1.0)));
    assert!(rec.unit_dropped(1) && rec.step3_saturated.is_none());
}

#[test]
fn with_evidence_step3_drops_as_the_thesis_does() {
    // Unit 1's key is above z_α: it is dropped, unit 0's row decides.
    let p = conflicting([1.0, evidence_z() + 0.5]);
    let (u, o, rec) = run(&p, Some(Input::new(2.0, 2.0)));
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
    assert!(rec.unit_dropped(1) && !rec.unit_dropped(0));
    assert!(u[1] >= 1.0 - 1e-6, "unit 0's row u_y ≥ 1 holds: {u}");

    // A flagged unit (a rejected reading this step) is evidence whatever its key.
    let mut p = conflicting([1.0, f64::INFINITY]);
    p.flagged = vec![false, true];
    let (_, o, rec) = run(&p, Some(Input::new(2.0, 2.0)));
    assert!(matches!(o, QpOutcome::Feasible { .. }), "{o:?}");
    assert!(matches!(
        rec.cbf_verdicts(1).next().map(|d| d.verdict),
        Some(Verdict::Dropped {
            stage: Stage::Step3,
            reason: DropReason::LargestResidue { flagged: true, .. }
        })
    ));
}

#[test]
fn the_paper_fallback_drops_the_largest_residue_without_evidence() {
    let mut p = conflicting([1.0, 2.5]);
    p.fallback = Fallback::Paper;
    let (u, o, rec) = run(&p, Some(Input::new(2.0, 2.0)));
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
    assert!(rec.unit_dropped(1));
    assert!(u[1] >= 1.0 - 1e-6, "{u}");
}

#[test]
fn when_the_rows_agree_again_the_policy_resumes() {
    // Same residues, but the rows now admit u_y ∈ [−1, 1]: Step 1 decides, nobody dropped.
    let mut p = conflicting([1.0, 2.5]);
    p.cbf[0] = cbf(0.0, 1.0, -1.0);
    let (_, o, rec) = run(&p, Some(Input::new(2.0, 2.0)));
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
    assert!(!rec.unit_dropped(0) && !rec.unit_dropped(1));
}

#[test]
fn an_invalid_evidence_threshold_is_refused_with_the_key_named() {
    let mut cfg = small_config();
    cfg.fallback = Fallback::Brake {
        evidence_z: f64::NAN,
    };
    let err = Controller::new(cfg).expect_err("NaN z refused").to_string();
    assert!(err.contains("fallback.evidence_z"), "{err}");
}

/// The safe stop steps aside for a mover: with a second barrier that moves (its rows ask
/// u_x ≥ 0.3 of both units, as a mover coming from −x would), the stopped robot's input is the
/// one nearest the brake that meets both units' mover rows, not the brake; the static rows
/// still conflict, so it is still a safe stop. Without the barrier marked as moving, the same
/// problem brakes.
#[test]
fn the_safe_stop_steps_aside_for_a_mover_and_brakes_otherwise() {
    use ftcbf_controller::policy::{resolve, PolicyProblem, PolicyScratch};
    use ftcbf_controller::qp::QpSolver;
    use ftcbf_controller::DecisionRecord;
    let solve = |moving: bool| {
        let mut p = PolicyProblem::new(2, 2);
        // Barrier 0 (static): u_y ≥ 1 for unit 0, u_y ≤ −1 for unit 1. Barrier 1: u_x ≥ 0.3.
        p.cbf[0] = cbf(0.0, 1.0, 1.0);
        p.cbf[1] = cbf(1.0, 0.0, 0.3);
        p.cbf[2] = cbf(0.0, -1.0, 1.0);
        p.cbf[3] = cbf(1.0, 0.0, 0.3);
        p.cbf_active = vec![true; 4];
        p.use_clf = false;
        p.moving = vec![false, moving];
        p.estimates = vec![
            State::new(0.0, 0.3, 0.1, -0.2),
            State::new(0.0, -0.9, 0.4, 0.5),
        ];
        p.residue_key = vec![1.0, 2.5];
        p.fallback = Fallback::brake(DEFAULT_EVIDENCE_ALPHA).expect("α in (0, 0.5)");
        p.gamma = vec![0.1, 0.1];
        let limit = Some(Input::new(1.0, 1.0));
        let mut qp = QpSolver::new(4, 2, nalgebra::Matrix2::identity(), 1e4, limit);
        let mut s = PolicyScratch::new(2, 2);
        let mut rec = DecisionRecord::with_capacity(4);
        resolve(&p, &mut qp, &mut s, &mut rec)
    };
    let brake = Input::new(-0.1, 0.2) / SAFE_STOP_TIME_CONSTANT;
    let (u, o) = solve(true);
    let QpOutcome::SafeStop { evades_movers, .. } = o else {
        panic!("expected a safe stop, got {o:?}");
    };
    assert!(evades_movers);
    // The nearest point to the brake with u_x ≥ 0.3: u_x = 0.3, u_y the brake's.
    assert!(
        (u[0] - 0.3).abs() < 1e-9 && (u[1] - brake[1]).abs() < 1e-9,
        "{u:?}"
    );
    let (u, o) = solve(false);
    let QpOutcome::SafeStop { evades_movers, .. } = o else {
        panic!("expected a safe stop, got {o:?}");
    };
    assert!(!evades_movers);
    assert!((u - brake).norm() < 1e-12, "{u:?}");
}
