//! Conflict resolution, Steps 1–3 of §4.1/§5.1, as a deterministic function of its inputs
//! ([`resolve`]) that returns the input and a record of every constraint kept or dropped,
//! at which stage and why.
//!
//! A *unit* is one estimator whose constraints are decided together: the m filters x̂_i for
//! FT-CBF-CLF, or the single all-channel filter for the baseline/nominal controllers.
//!
//! Stages (in order; the first feasible one decides):
//! 1. **Step 1** — all Ω_i (units with ĥ_i < δ, per barrier) and all Υ_i (V(x̂_i) > V̄), hard.
//! 2. **Step 2** — for each pair with ‖x̂_i − x̂_j‖ > θ_ij, drop unit i (resp. j), i.e. both
//!    its Ω and Υ, if ‖x̂_i − x̂_ij‖ > θ_ij/2 (resp. for j). Resolve, hard. (Skipped for a
//!    single unit; not re-solved when nothing was dropped.) With increment thresholds η_ij
//!    (finite [`PolicyProblem::eta`]) the test uses the seminorm
//!    S(z) = max(‖z(t)‖/(θ_ij/2), ‖z(t) − z(t − 1 s)‖_W/(η_ij/2)) of the estimate trajectories
//!    (‖·‖_W the covariance-weighted norm of [`PolicyProblem::increment_metric`]):
//!    the pair conflicts when S(x̂_i − x̂_j) > 2 and unit a goes when S(x̂_a − x̂_ij) > 1.
//!    S is a seminorm (the max of two), so the triangle inequality of Theorem 3's case (iii)
//!    holds for it, and S(x̂_j − x̂_k) ≤ 2 still implies ‖x̂_j − x̂_k‖ ≤ θ_jk for condition 1.
//!    The increment sees a drifting spoof long before its offset reaches θ_ij/2.
//!    Step 2 keeps the invariant of
//!    Step 3: when its pair tests would drop **every** unit that has CBF rows, the one Step 3
//!    would keep (smallest residue key, then lowest index) stays, and the record says so
//!    ([`DecisionRecord::step2_retained`]) — otherwise the problem would have no barrier at
//!    all and would pass as `Feasible { stage: Step2 }`.
//! 3. **CLF relaxation** (design decision, not in the paper) — the CLF rows become soft:
//!    they share one slack that is minimised with a large weight, so the input still makes
//!    the most progress the CBF rows allow. Its feasibility is that of the CBF rows alone.
//!    It comes *before* Step 3 because Step 3 may drop the constraints of an honest filter:
//!    trading safety for progress is never done. It comes *after* Step 2 because Step 2 only
//!    drops unit i when x̂_i has moved more than θ_ij/2 from x̂_ij; under the event (4.5) of
//!    Theorem 3 that never happens to the fault-free filter, so Step 2 keeps the paper's
//!    guarantee, and it is what removes the faulty filter's CLF (whose pull is the usual
//!    reason Step 1 is infeasible under an attack).
//! 4. **Step 3** — drop the unit with the largest residue key — the normal score of a windowed
//!    χ² test of its normalised innovations over the last second, ≈ N(0, 1) for an honest
//!    filter (flagged units, i.e. with a rejected reading, rank as +∞) among those that still have CBF rows, and resolve, until
//!    feasible. The last unit with CBF rows is never dropped: dropping it would leave no
//!    barrier at all.
//!    **Safe stop** ([`Fallback::Brake`], a departure from the thesis; book/src/theory/safe-stop.md):
//!    before each drop Step 3 asks whether the residues are *evidence*: the unit it would drop
//!    has a rejected reading this step (flagged), or its key exceeds z_α = Φ⁻¹(1 − α) — an
//!    honest filter's windowed χ² score exceeds z_α with probability ≈ α in a step, so under a
//!    single fault pattern a unit dropped on this evidence is the honest one with probability
//!    at most α. Without evidence (a slow ramp leaves no residue; two sources and nothing else
//!    leave Step 2 nothing to isolate, as its pair filter keeps no channel) nothing is dropped:
//!    every kept unit keeps its rows in the record, the input brakes
//!    (`u = −v̂/τ_s`, [`SAFE_STOP_TIME_CONSTANT`], clipped to the box, v̂ as in the fallback's
//!    braking below) and the outcome is [`QpOutcome::SafeStop`] with its [`StopReason`]. The
//!    next step decides afresh: the robot resumes as soon as the rows agree again, a unit is
//!    isolated by Step 2, or a residue becomes evidence. Units Step 2 isolated stay dropped;
//!    any further drop needs evidence too. With evidence a unit goes even when a kept unit is
//!    saturated (`step3_keeps_saturated` below); without evidence the saturated rule still
//!    decides when no two kept units are further apart than γ_a + γ_b ([`PolicyProblem::gamma`]:
//!    all may be honest, the box keeps the rows apart), and the robot brakes otherwise.
//!    [`Fallback::Paper`] is Step 3 as written (with the saturated rule).
//! 5. **Fallback** (typed, reported, never silent) — if the CBF rows are still infeasible
//!    (possible with an input box), the input minimises the largest violation of the
//!    remaining CBF rows inside the box (soft CBF rows; CLF ignored). If even that fails
//!    (solver failure), or a remaining CBF row is not finite (see below), the input is
//!    braking: `u = −v̂/τ_b` (τ_b = 0.5 s), clipped to the box. v̂ is the best available
//!    velocity estimate: that of the remaining unit with the smallest residue key whose
//!    velocity is finite; if none, that of a dropped unit (same ranking); only if no unit has
//!    a finite velocity is `u = 0`. The record says which ([`BrakeVelocity`]).
//!
//! **Non-finite rows fail closed.** A CBF or CLF row whose normal or offset is NaN or ±∞
//! (e.g. a barrier whose gradient is NaN at the estimate) is a row that *no* input satisfies
//! (`0·u ≤ −1`, see [`crate::feasibility::Line::from_half_space`]); it is counted in
//! [`DecisionRecord::non_finite_rows`]. Every stage that imposes it is infeasible; when one
//! remains in the fallback, the fallback brakes ([`BrakeReason::NonFiniteRow`]) instead of
//! solving the soft problem (as a soft row it would loosen every other row by its slack).
//!
//! **Feasibility** of each stage's hard rows (Step 1 and Step 2: CBF and CLF rows; CLF
//! relaxation and each Step-3 removal: the CBF rows alone, which is the feasibility of the
//! problem with soft CLF rows) and the box is decided by the exact geometric test of
//! [`crate::feasibility`] (same scaled rows; its tolerance, 10× clarabel's, leans to
//! "feasible" inside the boundary band). clarabel runs only when that test finds the set
//! feasible, to compute the input of the stage that decides, and in the fallback. Its status is always checked: a solver failure is counted
//! in [`DecisionRecord::solver_failures`] (after [`QpSolver`]'s one rebuild); a solve that
//! reports the set infeasible although the test found it feasible (only possible within the
//! tolerance band at the boundary) is counted in
//! [`DecisionRecord::feasibility_disagreements`]. In both cases, and when clarabel's input
//! (Solved or AlmostSolved) violates a hard row beyond the test's tolerance, the stage decides
//! with the test's witness, which is certified to meet every hard row ([`settle`], counted in
//! [`DecisionRecord::witness_inputs`]): a numerical failure on a set shown feasible never makes
//! Step 3 drop a unit (issue #30).
//!
//! One file (about 1,300 lines): Steps 1–3 and the fallback read one [`PolicyProblem`] in one
//! order and write one [`DecisionRecord`]; kept together, the order of the stages and what each
//! one drops can be read top to bottom, as the paper states them.

use clarabel::solver::SolverStatus;

use crate::constraints::{CbfRow, ClfRow, HalfSpace};
use crate::feasibility::{admits, box_edges, check_half_spaces, nearest, Feasibility, Line};
use crate::params::PairTable;
use crate::qp::{QpResult, QpSolver, RowMode};
use crate::types::{Input, State, StateMatrix};

/// Braking time constant of the last-resort action (s).
pub const BRAKE_TIME_CONSTANT: f64 = 0.5;

/// Braking time constant of the safe stop (s): `u = −v̂/τ_s`, clipped to the box. From
/// 0.22 m/s (a TurtleBot3 burger's top speed) the unclipped law travels v·τ_s = 4.4 cm before
/// it is at rest; a platform that brakes on its own wheel encoders
/// ([`crate::drive::brake_input`]) stops in v²/(2a) (2.4 cm at 1 m/s²).
pub const SAFE_STOP_TIME_CONSTANT: f64 = 0.2;

/// The stage that decided the input.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stage {
    /// Step 1: all constraints.
    Step1,
    /// Step 2: pairwise-deviation pruning.
    Step2,
    /// CLF rows made soft.
    ClfRelaxation,
    /// Step 3: largest-residue pruning.
    Step3,
    /// No feasible CBF set: safe action.
    Fallback,
    /// Step 3 would have dropped a unit without evidence that it lies: the robot brakes
    /// ([`QpOutcome::SafeStop`]).
    SafeStop,
}

/// Why a constraint is not imposed at all this step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum InactiveReason {
    /// ĥ(x̂) ≥ δ: not in X_t(δ).
    FarFromBoundary {
        /// ĥ(x̂).
        h_hat: f64,
        /// δ.
        delta: f64,
    },
    /// V(x̂) ≤ V̄: not in Y_t(V̄).
    InsideGoalLevel {
        /// V(x̂).
        v: f64,
        /// V̄.
        v_bar: f64,
    },
}

/// Why a unit was dropped.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DropReason {
    /// Step 2: ‖x̂_i − x̂_j‖ > θ_ij and ‖x̂_i − x̂_ij‖ > θ_ij/2.
    PairwiseDeviation {
        /// The other unit j.
        other: usize,
        /// ‖x̂_i − x̂_j‖.
        distance: f64,
        /// θ_ij.
        theta: f64,
        /// ‖x̂_i − x̂_ij‖ (compared with θ_ij/2).
        deviation_from_pair: f64,
    },
    /// Step 2, increment test: ‖Δ(x̂_i − x̂_j)‖ > η_ij or ‖x̂_i − x̂_j‖ > θ_ij, and
    /// ‖Δ(x̂_i − x̂_ij)‖ > η_ij/2 (Δ: change over the last second).
    SeparationIncrement {
        /// The other unit j.
        other: usize,
        /// ‖Δ(x̂_i − x̂_j)‖.
        increment_distance: f64,
        /// η_ij.
        eta: f64,
        /// ‖Δ(x̂_i − x̂_ij)‖ (compared with η_ij/2).
        increment_from_pair: f64,
    },
    /// Step 3: the largest residue among the units with CBF rows.
    LargestResidue {
        /// Its ranking key (+∞ when flagged): the normal score of the windowed χ² test of its
        /// innovations (see [`crate::estimator`]).
        residue: f64,
        /// A reading of a channel it uses was rejected this step.
        flagged: bool,
        /// The windowed statistic S = Σ e²/S_k behind the key.
        window_chi2: f64,
        /// Its degrees of freedom (scalar innovations in the window).
        window_dof: u32,
    },
}

/// What happened to one constraint.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Verdict {
    /// Not imposed (outside X_t(δ) or Y_t(V̄)).
    Inactive(InactiveReason),
    /// Imposed (hard) in the deciding stage.
    Kept,
    /// A CLF row imposed softly (CLF relaxation / Step 3), or a CBF row imposed softly in
    /// the fallback.
    Relaxed,
    /// Removed with its unit.
    Dropped {
        /// Stage that dropped it.
        stage: Stage,
        /// Why.
        reason: DropReason,
    },
}

/// Which constraint.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ConstraintKind {
    /// Ω of barrier `barrier`.
    Cbf {
        /// Barrier index.
        barrier: usize,
    },
    /// Υ.
    Clf,
}

/// One constraint's fate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConstraintDecision {
    /// Unit index (filter i for FT; 0 = the all-channel filter for the baseline).
    pub unit: usize,
    /// Which constraint.
    pub kind: ConstraintKind,
    /// Its fate.
    pub verdict: Verdict,
}

/// The record of one policy evaluation.
#[derive(Debug, Clone, PartialEq)]
pub struct DecisionRecord {
    /// Deciding stage.
    pub stage: Stage,
    /// One entry per (unit, barrier) Ω and per unit Υ (when the CLF is used).
    pub decisions: Vec<ConstraintDecision>,
    /// clarabel solves this step (the geometric feasibility tests are not counted).
    pub qp_solves: u32,
    /// Solves that ended in a solver failure (treated as "not shown feasible").
    pub solver_failures: u32,
    /// Solves that reported infeasible a set the geometric test of [`crate::feasibility`]
    /// found feasible (treated as "not shown feasible"; see the module docs).
    pub feasibility_disagreements: u32,
    /// Imposed rows (CBF rows in X_t(δ), CLF rows in Y_t(V̄)) of any unit whose normal or
    /// offset is not finite this step. Each is treated as violated (fail closed).
    pub non_finite_rows: u32,
    /// Stages decided with the geometric test's witness because clarabel failed, reported the
    /// certified set infeasible, or returned an input that violates a hard row (see
    /// [`settle`]).
    pub witness_inputs: u32,
    /// Set when Step 2's pair tests would have dropped every unit that has CBF rows: the unit
    /// kept instead (the one Step 3 would keep) and the test it failed.
    pub step2_retained: Option<Step2Retained>,
    /// Set when Step 3 stopped because this unit's own CBF rows cannot be met in the input box
    /// (`PolicyProblem::step3_keeps_saturated`): the fallback then weighed every kept unit.
    pub step3_saturated: Option<usize>,
}

/// A unit Step 2 did not drop although its pair test said so, because it was the last unit
/// with CBF rows (the invariant Step 3 also keeps).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Step2Retained {
    /// The unit kept (smallest Step-3 residue key among the units with CBF rows; ties: the
    /// lowest index).
    pub unit: usize,
    /// The pair test it failed (a [`DropReason::PairwiseDeviation`]).
    pub failed_test: DropReason,
}

impl DecisionRecord {
    /// An empty record with room for `capacity` decisions.
    pub fn with_capacity(capacity: usize) -> Self {
        Self {
            stage: Stage::Step1,
            decisions: Vec::with_capacity(capacity),
            qp_solves: 0,
            solver_failures: 0,
            feasibility_disagreements: 0,
            non_finite_rows: 0,
            witness_inputs: 0,
            step2_retained: None,
            step3_saturated: None,
        }
    }
    /// Decisions about Ω rows of `unit`.
    pub fn cbf_verdicts(&self, unit: usize) -> impl Iterator<Item = &ConstraintDecision> {
        self.decisions
            .iter()
            .filter(move |d| d.unit == unit && matches!(d.kind, ConstraintKind::Cbf { .. }))
    }
    /// True when any constraint of `unit` was dropped.
    pub fn unit_dropped(&self, unit: usize) -> bool {
        self.decisions
            .iter()
            .any(|d| d.unit == unit && matches!(d.verdict, Verdict::Dropped { .. }))
    }
}

/// The safe action of the fallback.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SafeAction {
    /// The input in the box minimising the largest violation of the remaining CBF rows.
    MinimiseMaxViolation,
    /// Braking, `u = −v̂/τ_b` clipped to the box (see the module docs).
    Brake {
        /// Why the fallback braked.
        reason: BrakeReason,
        /// Whose velocity estimate v̂ the input opposes.
        velocity: BrakeVelocity,
    },
}

/// Why the fallback braked instead of minimising the largest violation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BrakeReason {
    /// The soft problem failed in the solver.
    SolverFailure {
        /// The solver's status of the failed soft solve, if it ran.
        solver_status: Option<SolverStatus>,
    },
    /// A remaining CBF row is not finite: no input is known to satisfy it.
    NonFiniteRow,
}

/// The velocity estimate the braking input opposes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BrakeVelocity {
    /// A unit that still had its constraints (smallest residue key with a finite velocity).
    Remaining {
        /// Unit index.
        unit: usize,
    },
    /// No remaining unit had a finite velocity: a dropped unit's (same ranking).
    Dropped {
        /// Unit index.
        unit: usize,
    },
    /// No unit had a finite velocity estimate: `u = 0`.
    NoneFinite,
}

/// Result of the policy.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum QpOutcome {
    /// A feasible problem (all imposed CBF rows hold).
    Feasible {
        /// Deciding stage.
        stage: Stage,
        /// Whether the CLF rows were soft.
        clf_relaxed: bool,
        /// Largest CLF violation (scaled row units, m/s²); 0 when hard.
        clf_slack: f64,
        /// Solver iterations of the deciding solve.
        iterations: u32,
    },
    /// Infeasible after Step 3: the safe action was applied.
    InfeasibleAfterStep3 {
        /// What was done.
        action: SafeAction,
        /// Largest violation `max(ω̄ − Λu)/‖Λ‖` of the remaining CBF rows at the applied input
        /// (m/s²) (0 when they all hold).
        max_cbf_violation: f64,
    },
    /// The safe stop ([`Fallback::Brake`]): no input meets every kept unit's CBF rows, and the
    /// evidence cannot say which unit lies, so the input brakes instead of dropping a unit
    /// by residue.
    SafeStop {
        /// Why the policy stopped instead of choosing.
        reason: StopReason,
        /// Whose velocity estimate the braking input opposes.
        velocity: BrakeVelocity,
        /// Largest violation `max(ω̄ − Λu)/‖Λ‖` of the kept units' CBF rows at the braking input
        /// (m/s²).
        max_cbf_violation: f64,
        /// The input is not the plain brake but the one nearest it that meets every kept
        /// unit's rows of the moving obstacles ([`PolicyProblem::moving`]): the stopped robot
        /// steps aside for a mover coming at it.
        evades_movers: bool,
    },
}

/// What the policy does where Step 3 would drop a unit (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Fallback {
    /// The thesis' Step 3 as written: drop the unit with the largest residue until feasible.
    Paper,
    /// The safe stop: drop the unit with the largest residue only when its residue is evidence
    /// that it lies (flagged, or its windowed χ² normal score above `evidence_z`); otherwise
    /// brake ([`QpOutcome::SafeStop`]).
    Brake {
        /// z_α: the normal score an honest filter's windowed χ² test exceeds with probability
        /// α in one step (`Φ⁻¹(1 − α)`; see [`Fallback::brake`]).
        evidence_z: f64,
    },
}

/// Default false-alarm probability α of the evidence test of [`Fallback::Brake`], per unit and
/// control step: over a 90 s run at 50 Hz with two units the union bound on "an honest unit's
/// residue ever looks like evidence" is 4500 · 2 · 10⁻⁶ ≈ 0.009.
pub const DEFAULT_EVIDENCE_ALPHA: f64 = 1e-6;

impl Fallback {
    /// [`Fallback::Brake`] with the evidence threshold `z_α = Φ⁻¹(1 − α)`; `None` unless
    /// 0 < α < 0.5.
    pub fn brake(alpha: f64) -> Option<Self> {
        use statrs::distribution::{ContinuousCDF, Normal};
        if !(alpha > 0.0 && alpha < 0.5) {
            return None;
        }
        let z = Normal::standard().inverse_cdf(1.0 - alpha);
        z.is_finite().then_some(Self::Brake { evidence_z: z })
    }
}

/// Why the safe stop was chosen: the two units Step 3 would have chosen between.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StopReason {
    /// The unit Step 3 would have dropped (largest residue key among the kept units with CBF
    /// rows).
    pub would_drop: usize,
    /// Its residue key.
    pub would_drop_key: f64,
    /// The kept unit with CBF rows with the next largest key (the one Step 3 would have
    /// trusted instead when two remain).
    pub other: usize,
    /// Its residue key.
    pub other_key: f64,
    /// Distance between the two units' position estimates \[m\].
    pub separation: f64,
    /// θ of that pair (Step 2's state-norm threshold: it isolates a unit only beyond it).
    pub theta: f64,
    /// The evidence threshold z_α the key did not exceed.
    pub evidence_z: f64,
    /// Whether Step 2 dropped any unit this step.
    pub step2_isolated: bool,
}

/// The inputs of one policy evaluation (preallocated; the controller refills it each step).
#[derive(Debug, Clone)]
pub struct PolicyProblem {
    units: usize,
    barriers: usize,
    /// Ω rows, index `unit * barriers + barrier`.
    pub cbf: Vec<CbfRow>,
    /// Whether each Ω is in X_t(δ) (ĥ < δ).
    pub cbf_active: Vec<bool>,
    /// Whether each Ω is out of reach ([`crate::reach`]): every input of the box satisfies
    /// it, so it is not built (its [`CbfRow`] holds the certified lower bounds of h and ĥ,
    /// Λ = 0 and ω̄ = −1) and not handed to the QP or the feasibility test. It still counts as
    /// its unit's row in X_t(δ) where Steps 2–3 ask whether a unit has rows.
    pub cbf_far: Vec<bool>,
    /// Υ rows per unit.
    pub clf: Vec<ClfRow>,
    /// Whether each Υ is in Y_t(V̄).
    pub clf_active: Vec<bool>,
    /// Whether the CLF is part of the problem at all.
    pub use_clf: bool,
    /// Run Step 2's isolation tests every step, not only when Step 1 is infeasible (the
    /// safety-filter form: otherwise a spoofed filter whose rows can all be met by braking
    /// freezes the robot and is never tested).
    pub step2_every_step: bool,
    /// Step 3 never drops a unit while some kept unit's own CBF rows cannot be met in the input
    /// box (a "saturated" unit): it stops, and the fallback minimises the largest violation over
    /// every unit still kept. Dropping resolves disagreement between estimators, not a box too
    /// small for one of them, and the residue ranking cannot tell an honest filter from one fed
    /// by a stealthy attacker. [`crate::Controller`] always sets it; [`PolicyProblem::new`]
    /// leaves it off, which is the paper's Step 3 as written.
    pub step3_keeps_saturated: bool,
    /// What Step 3 does without evidence ([`Fallback::Paper`] in [`PolicyProblem::new`]).
    pub fallback: Fallback,
    /// γ_i per unit (the error bound its rows assume; +∞ in [`PolicyProblem::new`]): two kept
    /// units further apart than γ_a + γ_b cannot both be honest (see [`Fallback::Brake`]).
    pub gamma: Vec<f64>,
    /// Estimates x̂_i per unit.
    pub estimates: Vec<State>,
    /// Pair estimates x̂_ij per pair of units.
    pub pair_estimates: PairTable<State>,
    /// θ_ij per pair of units.
    pub theta: PairTable<f64>,
    /// η_ij of the increment test per pair of units (+∞: no increment test).
    pub eta: PairTable<f64>,
    /// Δ(x̂_a − x̂_aj) over the Step-2 window per *ordered* pair (a, j), index `a * units + j`
    /// (x̂_a − x̂_aj and x̂_j − x̂_aj differ, so this is not a [`PairTable`]).
    pub separation_increment: Vec<State>,
    /// W of the increment test per pair of units (the norm ‖z‖_W = √(zᵀ W z) in which `eta` is
    /// measured; identity: Euclidean).
    pub increment_metric: PairTable<StateMatrix>,
    /// Step-3 ranking keys (+∞ when flagged).
    pub residue_key: Vec<f64>,
    /// The windowed χ² statistic and its degrees of freedom behind each key (for the record).
    pub residue_stat: Vec<(f64, u32)>,
    /// Flagged units.
    pub flagged: Vec<bool>,
    /// δ (for the record).
    pub delta: f64,
    /// V̄ (for the record).
    pub v_bar: f64,
    /// Per barrier, whether it is a moving obstacle's ([`crate::Barrier::mover`]; all false in
    /// [`PolicyProblem::new`]). The safe stop keeps every kept unit's rows of these: braking
    /// holds a static obstacle's row at rest, not a mover's, which comes at the robot.
    pub moving: Vec<bool>,
}

impl PolicyProblem {
    /// Room for `units` units and `barriers` barriers.
    pub fn new(units: usize, barriers: usize) -> Self {
        let zero_cbf = CbfRow {
            lambda: Input::zeros(),
            omega_bar: 0.0,
            h: 0.0,
            h_hat: 0.0,
        };
        let zero_clf = ClfRow {
            lg_v: Input::zeros(),
            tau_bar: 0.0,
            v: 0.0,
        };
        Self {
            units,
            barriers,
            cbf: vec![zero_cbf; units * barriers],
            cbf_active: vec![false; units * barriers],
            cbf_far: vec![false; units * barriers],
            clf: vec![zero_clf; units],
            clf_active: vec![false; units],
            use_clf: true,
            step2_every_step: false,
            step3_keeps_saturated: false,
            fallback: Fallback::Paper,
            gamma: vec![f64::INFINITY; units],
            estimates: vec![State::zeros(); units],
            pair_estimates: PairTable::from_fn(units, |_, _| State::zeros()),
            theta: PairTable::from_fn(units, |_, _| f64::INFINITY),
            eta: PairTable::from_fn(units, |_, _| f64::INFINITY),
            separation_increment: vec![State::zeros(); units * units],
            increment_metric: PairTable::from_fn(units, |_, _| StateMatrix::identity()),
            residue_key: vec![0.0; units],
            residue_stat: vec![(0.0, 0); units],
            flagged: vec![false; units],
            delta: f64::INFINITY,
            v_bar: 0.0,
            moving: vec![false; barriers],
        }
    }
    /// Number of units.
    pub fn units(&self) -> usize {
        self.units
    }
    /// Number of barriers.
    pub fn barriers(&self) -> usize {
        self.barriers
    }
}

/// Reusable buffers of [`resolve`].
#[derive(Debug, Clone, Default)]
pub struct PolicyScratch {
    alive: Vec<bool>,
    cbf_rows: Vec<HalfSpace>,
    clf_rows: Vec<HalfSpace>,
    drop_reason: Vec<Option<(Stage, DropReason)>>,
    lines: Vec<Line>,
}

impl PolicyScratch {
    /// Whether unit `i` is still kept (not dropped) in the decision under way; false for an
    /// index out of range.
    pub fn kept(&self, i: usize) -> bool {
        self.alive.get(i).copied().unwrap_or(false)
    }

    /// Buffers for `units` units and `barriers` barriers.
    pub fn new(units: usize, barriers: usize) -> Self {
        Self {
            alive: Vec::with_capacity(units),
            cbf_rows: Vec::with_capacity(units * barriers),
            clf_rows: Vec::with_capacity(units),
            drop_reason: Vec::with_capacity(units),
            lines: Vec::with_capacity(units * barriers + units),
        }
    }
}

/// Appends unit `i`'s imposed CBF rows (those in X_t(δ)) to `out`, except the rows out of
/// reach (every input of the box satisfies them: leaving them out changes no feasible set).
fn push_cbf_rows(p: &PolicyProblem, i: usize, out: &mut Vec<HalfSpace>) {
    push_cbf_rows_of(p, i, |_| true, out);
}

/// Unit `i`'s rows of the barriers `of` keeps that are in X_t(δ) and not out of reach.
fn push_cbf_rows_of(
    p: &PolicyProblem,
    i: usize,
    of: impl Fn(usize) -> bool,
    out: &mut Vec<HalfSpace>,
) {
    for b in (0..p.barriers).filter(|&b| of(b)) {
        let k = i * p.barriers + b;
        if p.cbf_active[k] && !p.cbf_far[k] {
            out.push(p.cbf[k].half_space());
        }
    }
}

fn collect(p: &PolicyProblem, s: &mut PolicyScratch) {
    s.cbf_rows.clear();
    s.clf_rows.clear();
    for i in 0..p.units {
        if !s.alive[i] {
            continue;
        }
        push_cbf_rows(p, i, &mut s.cbf_rows);
        if p.use_clf && p.clf_active[i] {
            s.clf_rows.push(p.clf[i].half_space());
        }
    }
}

fn unit_has_cbf(p: &PolicyProblem, i: usize) -> bool {
    (0..p.barriers).any(|b| p.cbf_active[i * p.barriers + b])
}

fn solve(
    qp: &mut QpSolver,
    s: &PolicyScratch,
    cbf: RowMode,
    clf: RowMode,
    rec: &mut DecisionRecord,
) -> QpResult {
    rec.qp_solves += 1;
    let r = qp.solve(&s.cbf_rows, cbf, &s.clf_rows, clf);
    if matches!(
        r,
        QpResult::SolverFailure { .. } | QpResult::TooManyRows { .. }
    ) {
        rec.solver_failures += 1;
    }
    r
}

/// Decide a stage: the geometric test of the CBF rows (and the CLF rows when they are hard)
/// with the box; clarabel only when the test finds them feasible, and its answer through
/// [`settle`]. Returns `QpResult::Infeasible { iterations: 0 }` without a solve when the test
/// finds them infeasible.
fn attempt(
    qp: &mut QpSolver,
    s: &mut PolicyScratch,
    clf: RowMode,
    rec: &mut DecisionRecord,
) -> QpResult {
    let hard_clf: &[HalfSpace] = match clf {
        RowMode::Hard => &s.clf_rows,
        RowMode::Soft => &[],
    };
    let verdict = check_half_spaces(&s.cbf_rows, hard_clf, qp.input_limit(), &mut s.lines);
    let Feasibility::Feasible { witness } = verdict else {
        return QpResult::Infeasible { iterations: 0 };
    };
    let r = solve(qp, s, RowMode::Hard, clf, rec);
    if matches!(r, QpResult::Infeasible { .. }) {
        rec.feasibility_disagreements += 1;
    }
    // When clarabel's answer is not usable, the certified set's point nearest the cost's
    // reference (u_nom in the safety-filter form, 0 in problem 5.3) stands in for its optimum.
    let witness = match r {
        QpResult::Feasible { u, .. } if admits(&s.lines, qp.input_limit(), u) => witness,
        _ => nearest(&s.lines, qp.input_limit(), qp.reference()).unwrap_or(witness),
    };
    let soft_clf: &[HalfSpace] = match clf {
        RowMode::Hard => &[],
        RowMode::Soft => &s.clf_rows,
    };
    let settled = settle(r, &s.lines, qp.input_limit(), witness, soft_clf);
    if settled.witness_used {
        rec.witness_inputs += 1;
    }
    settled.result
}

/// A stage's solver answer, settled against the hard rows the geometric test certified.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settled {
    /// The result the stage decides with.
    pub result: QpResult,
    /// The test's witness replaced the solver's answer.
    pub witness_used: bool,
}

/// The answer of a stage whose hard rows `hard` (scaled, with the box `limit`) the geometric
/// test found feasible with `witness` (fail closed, issue #30). clarabel's input is used when it
/// meets those rows within the test's tolerance ([`admits`]). An AlmostSolved (or any) input that
/// violates one is moved towards the witness, along the segment between them, just far enough
/// to meet every hard row (the set is convex and holds the witness, so the segment enters it;
/// the input stays as near clarabel's as the rows allow). When clarabel failed or reported the
/// set infeasible, the stage decides with the witness itself. Dropping units because the solver
/// failed on a set shown feasible would trade an honest filter's constraints for a numerical
/// failure. The slack reported for a replaced input is the largest violation of the `soft` rows
/// (scaled, m/s²) at it.
pub fn settle(
    result: QpResult,
    hard: &[Line],
    limit: Option<Input>,
    witness: Input,
    soft: &[HalfSpace],
) -> Settled {
    let u = match result {
        QpResult::Feasible { u, .. } if admits(hard, limit, u) => {
            return Settled {
                result,
                witness_used: false,
            }
        }
        QpResult::Feasible { u, .. } => toward(u, witness, hard, limit),
        _ => witness,
    };
    let slack = soft
        .iter()
        .map(|h| Line::from_half_space(h).violation([u[0], u[1]]))
        .fold(0.0_f64, f64::max);
    Settled {
        result: QpResult::Feasible {
            u,
            slack,
            iterations: 0,
        },
        witness_used: true,
    }
}

/// The point of the segment from `u` to `witness` (which meets every hard row and the box)
/// nearest `u` that meets them too; the witness when `u` is not finite or the point, through
/// rounding, is not admitted.
fn toward(u: Input, witness: Input, hard: &[Line], limit: Option<Input>) -> Input {
    if !(u[0].is_finite() && u[1].is_finite()) {
        return witness;
    }
    let edges = box_edges(limit);
    // f(t) = a·(u + t(w − u)) − b is affine in t with f(1) ≤ 0 (up to the test's tolerance):
    // the smallest t with f(t) ≤ 0 for every row.
    let t = hard
        .iter()
        .chain(&edges)
        .map(|l| {
            let f0 = l.violation([u[0], u[1]]);
            let f1 = l.violation([witness[0], witness[1]]);
            if f0 <= 0.0 || f0 - f1 <= 0.0 {
                0.0
            } else {
                (f0 / (f0 - f1)).min(1.0)
            }
        })
        .fold(0.0_f64, f64::max);
    let v = u + (witness - u) * t;
    if admits(hard, limit, v) {
        v
    } else {
        witness
    }
}

/// Where the stages have got to: the stage that ran last, whether the CLF rows of its
/// problem are soft, and its result.
struct Progress {
    stage: Stage,
    clf_relaxed: bool,
    result: QpResult,
}

impl Progress {
    fn feasible(&self) -> bool {
        matches!(self.result, QpResult::Feasible { .. })
    }
}

/// Run Steps 1–3 (see the module docs). Fills `record` and returns the input and outcome.
pub fn resolve(
    p: &PolicyProblem,
    qp: &mut QpSolver,
    s: &mut PolicyScratch,
    record: &mut DecisionRecord,
) -> (Input, QpOutcome) {
    let isolated = prepare(p, s, record);
    decide(p, qp, s, record, isolated)
}

/// The first half of [`resolve`]: reset the record and the scratch and, with
/// `step2_every_step`, run Step 2's isolation (its tests do not depend on Step 1, so one solve
/// then serves both steps). Returns whether isolation dropped a unit. Between this and
/// [`decide`] a caller may read [`PolicyScratch::kept`] (e.g. to take the safety filter's
/// reference from a unit Step 2 kept) and set the QP's reference.
pub fn prepare(p: &PolicyProblem, s: &mut PolicyScratch, record: &mut DecisionRecord) -> bool {
    start(p, s, record);
    p.step2_every_step && p.units > 1 && step2_isolate(p, s, record)
}

/// The second half of [`resolve`]: Step 1 (or the Step-2 solve after [`prepare`]'s isolation),
/// the CLF relaxation, Step 3 and the fallback.
pub fn decide(
    p: &PolicyProblem,
    qp: &mut QpSolver,
    s: &mut PolicyScratch,
    record: &mut DecisionRecord,
    isolated: bool,
) -> (Input, QpOutcome) {
    // Step 1
    collect(p, s);
    let mut at = Progress {
        stage: if isolated { Stage::Step2 } else { Stage::Step1 },
        clf_relaxed: false,
        result: attempt(qp, s, RowMode::Hard, record),
    };
    if !at.feasible() && !p.step2_every_step && p.units > 1 {
        step2(p, qp, s, record, &mut at);
    }
    if !at.feasible() && !s.clf_rows.is_empty() {
        relax_clf(qp, s, record, &mut at);
    }
    let mut stop = None;
    if !at.feasible() && p.units > 1 {
        stop = step3(p, qp, s, record, &mut at);
    }
    if let Some(reason) = stop {
        return safe_stop(p, qp, s, record, reason);
    }

    let (u, outcome) = match at.result {
        QpResult::Feasible {
            u,
            slack,
            iterations,
        } => (
            u,
            QpOutcome::Feasible {
                stage: at.stage,
                clf_relaxed: at.clf_relaxed,
                clf_slack: if at.clf_relaxed { slack } else { 0.0 },
                iterations,
            },
        ),
        _ => {
            at.stage = Stage::Fallback;
            fallback(p, qp, s, record)
        }
    };
    record.stage = at.stage;
    record_decisions(p, s, at.stage, at.clf_relaxed, record);
    (u, outcome)
}

/// Reset the record and the scratch for a new decision (every unit alive, nothing dropped)
/// and count the imposed rows that are not finite.
fn start(p: &PolicyProblem, s: &mut PolicyScratch, record: &mut DecisionRecord) {
    record.decisions.clear();
    record.qp_solves = 0;
    record.solver_failures = 0;
    record.feasibility_disagreements = 0;
    record.non_finite_rows = 0;
    record.witness_inputs = 0;
    record.step2_retained = None;
    record.step3_saturated = None;
    s.alive.clear();
    s.alive.resize(p.units, true);
    s.drop_reason.clear();
    s.drop_reason.resize(p.units, None);
    for i in 0..p.units {
        for b in 0..p.barriers {
            let k = i * p.barriers + b;
            if p.cbf_active[k] && !is_finite_row(&p.cbf[k].half_space()) {
                record.non_finite_rows += 1;
            }
        }
        if p.use_clf && p.clf_active[i] && !is_finite_row(&p.clf[i].half_space()) {
            record.non_finite_rows += 1;
        }
    }
}

/// Step 2: drop the units the pair tests single out, keep the last unit with CBF rows, and
/// resolve (hard) when something was dropped.
fn step2(
    p: &PolicyProblem,
    qp: &mut QpSolver,
    s: &mut PolicyScratch,
    record: &mut DecisionRecord,
    at: &mut Progress,
) {
    at.stage = Stage::Step2;
    if step2_isolate(p, s, record) {
        collect(p, s);
        at.result = attempt(qp, s, RowMode::Hard, record);
    }
}

/// Step 2's tests on every pair (dropping the units they single out) and the last-unit rule;
/// true when a unit was dropped.
fn step2_isolate(p: &PolicyProblem, s: &mut PolicyScratch, record: &mut DecisionRecord) -> bool {
    let mut dropped_any = false;
    for i in 0..p.units {
        for j in (i + 1)..p.units {
            if step2_pair(p, s, i, j) {
                dropped_any = true;
            }
        }
    }
    step2_keep_last_cbf_unit(p, s, record);
    dropped_any
}

/// ‖z‖_W = √(zᵀ W z) (a negative rounding of the quadratic form counts as 0).
fn w_norm(metric: &StateMatrix, z: State) -> f64 {
    (z.transpose() * metric * z)[0].max(0.0).sqrt()
}

/// Step 2's test of the pair (i, j), i < j: when the pair conflicts, drop each unit still
/// alive that has moved too far from x̂_ij. Returns whether it dropped one.
fn step2_pair(p: &PolicyProblem, s: &mut PolicyScratch, i: usize, j: usize) -> bool {
    let theta = p.theta[(i, j)];
    let eta = p.eta[(i, j)];
    let distance = (p.estimates[i] - p.estimates[j]).norm();
    let inc_i = p.separation_increment[i * p.units + j];
    let inc_j = p.separation_increment[j * p.units + i];
    let metric = &p.increment_metric[(i, j)];
    let inc_distance = w_norm(metric, inc_i - inc_j);
    // S(z) = max(‖z‖/(θ/2), ‖Δz‖/(η/2)) is a seminorm: the pair conflicts when
    // S(x̂_i − x̂_j) > 2, and unit a goes when S(x̂_a − x̂_ij) > 1.
    let conflict = distance > theta || inc_distance > eta;
    if !conflict {
        return false;
    }
    let pair = p.pair_estimates[(i, j)];
    let mut dropped = false;
    for (a, other, inc) in [(i, j, inc_i), (j, i, inc_j)] {
        if !s.alive[a] {
            continue;
        }
        let dev = (p.estimates[a] - pair).norm();
        let inc_dev = w_norm(metric, inc);
        let reason = if dev > theta / 2.0 {
            DropReason::PairwiseDeviation {
                other,
                distance,
                theta,
                deviation_from_pair: dev,
            }
        } else if inc_dev > eta / 2.0 {
            DropReason::SeparationIncrement {
                other,
                increment_distance: inc_distance,
                eta,
                increment_from_pair: inc_dev,
            }
        } else {
            continue;
        };
        s.alive[a] = false;
        dropped = true;
        s.drop_reason[a] = Some((Stage::Step2, reason));
    }
    dropped
}

/// The invariant of Step 3: never drop the last unit with CBF rows. Keep the one Step 3 would
/// keep (smallest residue key, then lowest index) and say so.
fn step2_keep_last_cbf_unit(p: &PolicyProblem, s: &mut PolicyScratch, record: &mut DecisionRecord) {
    let had_cbf = (0..p.units).any(|i| unit_has_cbf(p, i));
    let kept_cbf = (0..p.units).any(|i| s.alive[i] && unit_has_cbf(p, i));
    if had_cbf && !kept_cbf {
        let keep = (0..p.units)
            .filter(|&i| unit_has_cbf(p, i))
            .min_by(|&a, &b| p.residue_key[a].total_cmp(&p.residue_key[b]));
        if let Some(k) = keep {
            s.alive[k] = true;
            if let Some((_, failed_test)) = s.drop_reason[k].take() {
                record.step2_retained = Some(Step2Retained {
                    unit: k,
                    failed_test,
                });
            }
        }
    }
}

/// CLF relaxation: the CLF rows of the units still alive become soft.
fn relax_clf(
    qp: &mut QpSolver,
    s: &mut PolicyScratch,
    record: &mut DecisionRecord,
    at: &mut Progress,
) {
    at.stage = Stage::ClfRelaxation;
    at.clf_relaxed = true;
    at.result = attempt(qp, s, RowMode::Soft, record);
}

/// Step 3: drop the unit with the largest residue key among those with CBF rows and resolve
/// (soft CLF rows), until feasible or one such unit is left. With [`Fallback::Brake`], a unit
/// is dropped only on evidence ([`has_evidence`]); otherwise, unless a kept unit is saturated,
/// Step 3 stops and returns why ([`stop_reason`]), and the policy brakes.
fn step3(
    p: &PolicyProblem,
    qp: &mut QpSolver,
    s: &mut PolicyScratch,
    record: &mut DecisionRecord,
    at: &mut Progress,
) -> Option<StopReason> {
    loop {
        let (candidates, worst) = largest_residue(p, s);
        let Some(w) = worst else { break };
        if candidates <= 1 {
            break;
        }
        // With `Fallback::Brake` a unit goes on evidence even when a kept unit is saturated
        // (gen3_066: the saturated unit was the attacked one, its key far above z_α, and the
        // saturated rule's soft problem weighed its rows into the wall). Without evidence, when
        // the kept units are close enough to all be honest (no pair further apart than
        // γ_a + γ_b), the box, not a lie, keeps the rows apart: the saturated rule's fallback
        // decides as before (braking there only slows the catalogue's box-limited worlds).
        // Otherwise one of them lies and the robot brakes.
        let evidence = has_evidence(p, w);
        let box_not_lie = p.fallback == Fallback::Paper || (!evidence && !disagree(p, s));
        if p.step3_keeps_saturated && box_not_lie {
            if let Some(sat) = saturated_unit(p, qp.input_limit(), s) {
                record.step3_saturated = Some(sat);
                break;
            }
        }
        if !evidence {
            if let Some(reason) = stop_reason(p, s, w) {
                return Some(reason);
            }
        }
        at.stage = Stage::Step3;
        s.alive[w] = false;
        s.drop_reason[w] = Some((
            Stage::Step3,
            DropReason::LargestResidue {
                residue: p.residue_key[w],
                flagged: p.flagged[w],
                window_chi2: p.residue_stat.get(w).map_or(f64::NAN, |s| s.0),
                window_dof: p.residue_stat.get(w).map_or(0, |s| s.1),
            },
        ));
        collect(p, s);
        at.clf_relaxed = !s.clf_rows.is_empty();
        at.result = attempt(qp, s, RowMode::Soft, record);
        if at.feasible() {
            break;
        }
    }
    None
}

/// The evidence test before Step 3 drops unit `w` (the largest residue key among the kept units
/// with CBF rows): true with [`Fallback::Paper`] (the thesis drops without asking); with
/// [`Fallback::Brake`] true when a reading of `w` was rejected this step (flagged) or its key
/// exceeds z_α — an honest filter's windowed χ² score exceeds z_α with probability ≈ α in a step,
/// so under a single fault pattern a unit dropped on this evidence is the honest one with
/// probability at most α. A NaN key is no evidence.
fn has_evidence(p: &PolicyProblem, w: usize) -> bool {
    match p.fallback {
        Fallback::Paper => true,
        Fallback::Brake { evidence_z } => p.flagged[w] || p.residue_key[w] > evidence_z,
    }
}

/// Some two kept units with CBF rows are further apart than γ_a + γ_b: under Theorem 1's event
/// both cannot be honest, so the conflict is a lie, not only the input box.
fn disagree(p: &PolicyProblem, s: &PolicyScratch) -> bool {
    let kept: Vec<usize> = (0..p.units)
        .filter(|&i| s.alive[i] && unit_has_cbf(p, i))
        .collect();
    kept.iter().enumerate().any(|(k, &a)| {
        kept[k + 1..].iter().any(|&b| {
            let bound = p.gamma.get(a).copied().unwrap_or(f64::INFINITY)
                + p.gamma.get(b).copied().unwrap_or(f64::INFINITY);
            (p.estimates[a] - p.estimates[b]).norm() > bound
        })
    })
}

/// Why the policy stops instead of dropping `w` (`None` with [`Fallback::Paper`]): `w`, the
/// kept unit with CBF rows with the next largest key, their keys and distance.
fn stop_reason(p: &PolicyProblem, s: &PolicyScratch, w: usize) -> Option<StopReason> {
    let Fallback::Brake { evidence_z } = p.fallback else {
        return None;
    };
    let other = (0..p.units)
        .filter(|&i| i != w && s.alive[i] && unit_has_cbf(p, i))
        .max_by(|&a, &b| p.residue_key[a].total_cmp(&p.residue_key[b]))
        .unwrap_or(w);
    let (lo, hi) = (w.min(other), w.max(other));
    let theta = if lo == hi {
        f64::NAN
    } else {
        p.theta[(lo, hi)]
    };
    let d = p.estimates[w] - p.estimates[other];
    Some(StopReason {
        would_drop: w,
        would_drop_key: p.residue_key[w],
        other,
        other_key: p.residue_key[other],
        separation: d[0].hypot(d[1]),
        theta,
        evidence_z,
        step2_isolated: s
            .drop_reason
            .iter()
            .any(|d| matches!(d, Some((Stage::Step2, _)))),
    })
}

/// The safe stop: every kept unit stays kept (nothing is dropped by residue), the input brakes
/// (`u = −v̂/τ_b` clipped to the box, v̂ as in the fallback's braking, see [`brake`]), and the
/// record says why.
fn safe_stop(
    p: &PolicyProblem,
    qp: &QpSolver,
    s: &mut PolicyScratch,
    record: &mut DecisionRecord,
    reason: StopReason,
) -> (Input, QpOutcome) {
    collect(p, s);
    s.clf_rows.clear();
    let (brake_u, velocity) = brake(p, s, qp.input_limit(), SAFE_STOP_TIME_CONSTANT);
    let evading = evade_movers(p, s, qp.input_limit(), brake_u);
    let u = evading.unwrap_or(brake_u);
    collect(p, s);
    s.clf_rows.clear();
    record.stage = Stage::SafeStop;
    record_decisions(p, s, Stage::SafeStop, false, record);
    (
        u,
        QpOutcome::SafeStop {
            reason,
            velocity,
            max_cbf_violation: max_cbf_violation(&s.cbf_rows, &u),
            evades_movers: evading.is_some_and(|e| e != brake_u),
        },
    )
}

/// The input nearest `brake_u` that meets every kept unit's rows of the moving obstacles in
/// the box, when there are such rows and an input meets them all (None otherwise: the plain
/// brake). Each kept unit's mover row holds for the honest one among them, as in Step 1, and a
/// mover's row, unlike a static obstacle's, is not met at rest: its ∂h/∂t asks the robot to
/// keep the distance the mover closes. The static rows are left to the brake (they are what
/// the kept units disagree on, which is why the robot stops).
fn evade_movers(
    p: &PolicyProblem,
    s: &mut PolicyScratch,
    limit: Option<Input>,
    brake_u: Input,
) -> Option<Input> {
    if !p.moving.iter().any(|&m| m) {
        return None;
    }
    s.cbf_rows.clear();
    for i in (0..p.units).filter(|&i| s.alive[i]) {
        push_cbf_rows_of(p, i, |b| p.moving[b], &mut s.cbf_rows);
    }
    if s.cbf_rows.is_empty() {
        return None;
    }
    match check_half_spaces(&s.cbf_rows, &[], limit, &mut s.lines) {
        Feasibility::Feasible { .. } => nearest(&s.lines, limit, brake_u),
        _ => None,
    }
}

/// The first unit still alive whose own CBF rows are infeasible in the input box, if any.
fn saturated_unit(p: &PolicyProblem, limit: Option<Input>, s: &mut PolicyScratch) -> Option<usize> {
    let mut rows = std::mem::take(&mut s.cbf_rows);
    let mut found = None;
    for i in (0..p.units).filter(|&i| s.alive[i] && unit_has_cbf(p, i)) {
        rows.clear();
        push_cbf_rows(p, i, &mut rows);
        if !check_half_spaces(&rows, &[], limit, &mut s.lines).is_feasible() {
            found = Some(i);
            break;
        }
    }
    s.cbf_rows = rows;
    collect(p, s);
    found
}

/// The units still alive that have CBF rows (how many), and the one with the largest residue
/// key among them (ties: the highest index).
fn largest_residue(p: &PolicyProblem, s: &PolicyScratch) -> (usize, Option<usize>) {
    let mut candidates = 0;
    let mut worst: Option<usize> = None;
    for i in 0..p.units {
        if s.alive[i] && unit_has_cbf(p, i) {
            candidates += 1;
            match worst {
                Some(w) if p.residue_key[i] <= p.residue_key[w] => {}
                _ => worst = Some(i),
            }
        }
    }
    (candidates, worst)
}

/// Fallback: soft CBF rows of the surviving units, no CLF; brake when a surviving CBF row is
/// not finite (no input is known to satisfy it) or the solver fails.
fn fallback(
    p: &PolicyProblem,
    qp: &mut QpSolver,
    s: &mut PolicyScratch,
    record: &mut DecisionRecord,
) -> (Input, QpOutcome) {
    s.clf_rows.clear();
    let non_finite = s.cbf_rows.iter().any(|h| !is_finite_row(h));
    let soft = if non_finite {
        None
    } else {
        Some(solve(qp, s, RowMode::Soft, RowMode::Hard, record))
    };
    let (u, action) = match soft {
        Some(QpResult::Feasible { u, .. }) => (u, SafeAction::MinimiseMaxViolation),
        other => {
            let reason = brake_reason(other);
            let (u, velocity) = brake(p, s, qp.input_limit(), BRAKE_TIME_CONSTANT);
            (u, SafeAction::Brake { reason, velocity })
        }
    };
    (
        u,
        QpOutcome::InfeasibleAfterStep3 {
            action,
            max_cbf_violation: max_cbf_violation(&s.cbf_rows, &u),
        },
    )
}

/// Why the fallback brakes, from its soft solve (`None`: not attempted, a row is not finite).
fn brake_reason(soft: Option<QpResult>) -> BrakeReason {
    match soft {
        None => BrakeReason::NonFiniteRow,
        Some(QpResult::SolverFailure { status }) => BrakeReason::SolverFailure {
            solver_status: Some(status),
        },
        Some(_) => BrakeReason::SolverFailure {
            solver_status: None,
        },
    }
}

/// Largest violation of the remaining CBF rows at u; +∞ when a row is not finite (its
/// violation is unknown, so it is never reported as small).
fn max_cbf_violation(rows: &[HalfSpace], u: &Input) -> f64 {
    rows.iter()
        .map(|h| {
            let n = h.normal.norm();
            if !is_finite_row(h) {
                f64::INFINITY
            } else if n > 1e-12 {
                h.violation(u) / n
            } else {
                -h.offset
            }
        })
        .fold(0.0_f64, f64::max)
}

/// The record: one decision per (unit, barrier) CBF row and per unit CLF row.
fn record_decisions(
    p: &PolicyProblem,
    s: &PolicyScratch,
    stage: Stage,
    clf_relaxed: bool,
    record: &mut DecisionRecord,
) {
    for i in 0..p.units {
        for b in 0..p.barriers {
            record.decisions.push(ConstraintDecision {
                unit: i,
                kind: ConstraintKind::Cbf { barrier: b },
                verdict: cbf_verdict(p, s, stage, i, b),
            });
        }
        if p.use_clf {
            record.decisions.push(ConstraintDecision {
                unit: i,
                kind: ConstraintKind::Clf,
                verdict: clf_verdict(p, s, stage, clf_relaxed, i),
            });
        }
    }
}

fn cbf_verdict(p: &PolicyProblem, s: &PolicyScratch, stage: Stage, i: usize, b: usize) -> Verdict {
    let k = i * p.barriers + b;
    if !p.cbf_active[k] {
        Verdict::Inactive(InactiveReason::FarFromBoundary {
            h_hat: p.cbf[k].h_hat,
            delta: p.delta,
        })
    } else if let Some((st, reason)) = s.drop_reason[i] {
        Verdict::Dropped { stage: st, reason }
    } else if matches!(stage, Stage::Fallback | Stage::SafeStop) {
        Verdict::Relaxed
    } else {
        Verdict::Kept
    }
}

fn clf_verdict(
    p: &PolicyProblem,
    s: &PolicyScratch,
    stage: Stage,
    clf_relaxed: bool,
    i: usize,
) -> Verdict {
    if !p.clf_active[i] {
        Verdict::Inactive(InactiveReason::InsideGoalLevel {
            v: p.clf[i].v,
            v_bar: p.v_bar,
        })
    } else if let Some((st, reason)) = s.drop_reason[i] {
        Verdict::Dropped { stage: st, reason }
    } else if clf_relaxed || matches!(stage, Stage::Fallback | Stage::SafeStop) {
        Verdict::Relaxed
    } else {
        Verdict::Kept
    }
}

/// The normal (and its norm) and the offset are finite: the rows
/// [`crate::feasibility::Line::from_half_space`] does not turn into `0 ≤ −1` for that reason.
fn is_finite_row(h: &HalfSpace) -> bool {
    h.normal.norm().is_finite() && h.offset.is_finite()
}

/// `u = −v̂/τ_b` clipped to the box, with v̂ the best available finite velocity estimate (see
/// the module docs), and where it came from.
fn brake(
    p: &PolicyProblem,
    s: &PolicyScratch,
    limit: Option<Input>,
    tau: f64,
) -> (Input, BrakeVelocity) {
    let velocity = |i: usize| Input::new(p.estimates[i][2], p.estimates[i][3]);
    let best = |remaining: bool| {
        (0..p.units)
            .filter(|&i| s.alive[i] == remaining && velocity(i).iter().all(|v| v.is_finite()))
            .min_by(|&a, &b| p.residue_key[a].total_cmp(&p.residue_key[b]))
    };
    let (v, source) = match (best(true), best(false)) {
        (Some(i), _) => (velocity(i), BrakeVelocity::Remaining { unit: i }),
        (None, Some(i)) => (velocity(i), BrakeVelocity::Dropped { unit: i }),
        (None, None) => (Input::zeros(), BrakeVelocity::NoneFinite),
    };
    let mut u = -v / tau;
    if let Some(l) = limit {
        u[0] = u[0].clamp(-l[0], l[0]);
        u[1] = u[1].clamp(-l[1], l[1]);
    }
    if u.iter().any(|x| !x.is_finite()) {
        // only with a non-finite box (the controller validates it): never command NaN
        u = Input::zeros();
    }
    (u, source)
}
