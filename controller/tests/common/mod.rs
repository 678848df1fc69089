//! Helpers shared by the controller's policy tests: hand-made Ω rows, a two-unit problem, one
//! call of the policy, and the verdict a unit's constraint got.
#![allow(dead_code)] // each test binary uses its own subset

use ftcbf_controller::constraints::CbfRow;
use ftcbf_controller::policy::{
    resolve, ConstraintKind, DecisionRecord, PolicyProblem, PolicyScratch, QpOutcome, Verdict,
};
use std::sync::Arc;

use ftcbf_controller::barrier::HalfPlane;
use ftcbf_controller::qp::QpSolver;
use ftcbf_controller::{
    ClfConfig, ControllerConfig, FtParams, Input, LinearModel, State, StateMatrix,
};
use nalgebra::Matrix2;

/// Ω as `Λu ≥ ω̄`.
pub fn cbf(lx: f64, ly: f64, omega: f64) -> CbfRow {
    CbfRow {
        lambda: Input::new(lx, ly),
        omega_bar: omega,
        h: 0.0,
        h_hat: 0.0,
    }
}

/// Two units, one barrier each, no CLF, θ as `PolicyProblem::new` leaves it.
pub fn two_units(rows: [CbfRow; 2]) -> PolicyProblem {
    let mut p = PolicyProblem::new(2, 1);
    p.cbf[0] = rows[0];
    p.cbf[1] = rows[1];
    p.cbf_active = vec![true, true];
    p.use_clf = false;
    p
}

/// Steps 1–3 on `p` with a fresh solver (R = I, CLF slack weight 1e4).
pub fn run(p: &PolicyProblem, limit: Option<Input>) -> (Input, QpOutcome, DecisionRecord) {
    let mut qp = QpSolver::new(2, 2, Matrix2::identity(), 1e4, limit);
    let mut s = PolicyScratch::new(2, 1);
    let mut rec = DecisionRecord::with_capacity(4);
    let (u, o) = resolve(p, &mut qp, &mut s, &mut rec);
    (u, o, rec)
}

/// The verdict recorded for `unit`'s constraint of `kind`.
pub fn verdict(rec: &DecisionRecord, unit: usize, kind: ConstraintKind) -> Verdict {
    rec.decisions
        .iter()
        .find(|d| d.unit == unit && d.kind == kind)
        .map(|d| d.verdict)
        .expect("decision recorded")
}

/// The paper's double integrator with its two single-channel patterns, γ = 0.001 and θ = 0.045,
/// one lifted half-plane, δ = 1, V̄ = 1 and a ±2 m/s² box, started at (1, 0).
pub fn small_config() -> ControllerConfig {
    ControllerConfig::builder(
        LinearModel::paper_double_integrator(1e-3, 1e-3).expect("model"),
        vec![vec![1], vec![3]],
        FtParams::uniform(2, 0.001, 0.045),
    )
    .barriers(vec![Arc::new(HalfPlane::new(
        "h",
        State::new(0.0, 1.0, 0.0, 0.2),
        -0.05,
    ))])
    .goal(State::zeros(), 0.05)
    .delta(1.0)
    .clf(ClfConfig::paper(1.0))
    .input_limit(Input::new(2.0, 2.0))
    .start(
        State::new(1.0, 0.0, 0.0, 0.0),
        StateMatrix::identity() * 1e-3,
    )
    .build()
}
