//! The top-level controller the simulator's runner calls: FT-CBF-CLF, the all-channel
//! baseline (the paper's comparison, same CBF-CLF QP over one filter) and a nominal
//! CLF-only controller (all-channel filter, no barriers).
//!
//! One file (about 1,250 lines of code): the [`Controller`], its configuration and its step are
//! one sequence — readings → filters → each unit's rows (with the active-barrier index) →
//! [`crate::policy::resolve`] → the record — and the builder's documented defaults sit beside
//! the fields they fill. What stands alone already lives beside it: the rows
//! ([`crate::constraints`]), the policy, the estimator bank, the reach rule ([`crate::reach`]).

use std::sync::Arc;

use nalgebra::Matrix2;
use thiserror::Error;

use crate::barrier::{Barrier, MoverState};
use crate::constraints::{cbf_row, clf_row, CbfRow};
use crate::estimator::{EstimatorBank, RESIDUE_WINDOW_MAX_STEPS};
use crate::lyapunov::{ClfConfig, LyapunovError, QuadraticClf};
use crate::model::{validate_fault_patterns, LinearModel, ModelError};
use crate::nominal::{PathTracker, TrackerConfig, TrackerError};
use crate::params::{FtParams, PairTable, STEP2_WINDOW};
use crate::policy::{
    decide, prepare, DecisionRecord, Fallback, PolicyProblem, PolicyScratch, QpOutcome,
};
use crate::qp::QpSolver;
use crate::reach::{BarrierIndex, ReachTerms};
use crate::types::{Input, State, StateMatrix};

/// Weight of the shared slack in the QP cost (input cost R is O(1)): soft rows are violated
/// only as little as the other constraints force.
pub const SLACK_WEIGHT: f64 = 1e4;

/// Which controller.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ControllerKind {
    /// Fault-tolerant CBF-CLF (m single-drop filters, pair filters, Steps 1–3).
    FtCbfClf,
    /// The same CBF-CLF QP over the all-channel filter only.
    Baseline,
    /// CLF only over the all-channel filter (no barriers).
    Nominal,
}

/// Which problem the QP solves each step.
#[derive(Debug, Clone, PartialEq)]
pub enum ProblemForm {
    /// Problem (5.3), the paper's: min uᵀRu over the CBF rows Ω and the CLF rows Υ (the CLF
    /// drives the robot; its rows are relaxed with a slack when they conflict).
    Paper,
    /// The safety filter: a path tracker ([`crate::nominal`]) proposes u_nom from the estimate
    /// Step 3 would keep (smallest residue key), and the QP returns the closest safe input,
    /// min (u − u_nom)ᵀR(u − u_nom) over the same Ω rows and Steps 1–3. With `clf` the Υ rows
    /// are imposed too (as in the paper); without, only barriers constrain u.
    SafetyFilter {
        /// The nominal path-tracking law.
        tracker: TrackerConfig,
        /// Keep the CLF rows Υ.
        clf: bool,
    },
}

/// Configuration of a [`Controller`].
#[derive(Debug, Clone)]
pub struct ControllerConfig {
    /// Which controller.
    pub kind: ControllerKind,
    /// The linear model.
    pub model: LinearModel,
    /// Fault patterns F(r_i) as channel indices (disjoint, non-empty, in range).
    pub fault_patterns: Vec<Vec<usize>>,
    /// Safe sets; one Ω per (filter, barrier).
    pub barriers: Vec<Arc<dyn Barrier>>,
    /// Goal state x_g.
    pub goal: State,
    /// Goal radius d (state norm) (also the d of eq. 6.6).
    pub goal_radius: f64,
    /// γ_i, γ of the all-channel filter (baseline and nominal), θ_ij (one value for all pairs,
    /// or C(m,2) values in the order (0,1), (0,2), …, (1,2), …), η_ij and W_ij of Step 2's
    /// increment test (empty: none, the paper's Step 2; see [`crate::policy`]) and θ_ij(t)
    /// (each entry finite, > 0 and at most the pair's θ_ij).
    pub ft: FtParams,
    /// δ of X_t(δ): Ω is imposed when ĥ(x̂) < δ (may be +∞: always).
    pub delta: f64,
    /// Class-K gain κ of the CBF condition (`… ≥ −κ ĥ`); the paper uses 1.
    pub cbf_gain: f64,
    /// CLF configuration.
    pub clf: ClfConfig,
    /// Input cost R of (5.3) (symmetric positive definite).
    pub input_cost: Matrix2<f64>,
    /// Symmetric box |a_k| ≤ limit_k (m/s²), if any.
    pub input_limit: Option<Input>,
    /// Initial estimate.
    pub x0: State,
    /// Initial covariance.
    pub p0: StateMatrix,
    /// Readings with |y| above this, or non-finite, are rejected.
    pub max_abs_reading: f64,
    /// Which problem the QP solves.
    pub form: ProblemForm,
    /// What Step 3 does when it has no evidence which unit lies ([`Fallback::Paper`]: the
    /// thesis' Step 3, the builder's default; [`Fallback::Brake`]: the safe stop).
    pub fallback: Fallback,
    /// A spatial index over the barriers (issue #52, [`crate::reach`]): each step builds only
    /// the rows of the barriers it finds within reach of the estimates. Default: none, every
    /// row is built at every step.
    pub barrier_index: Option<Arc<dyn BarrierIndex>>,
}

/// Whether the controller uses a reading `value`: finite and |value| ≤ `max_abs_reading`
/// ([`ControllerConfig::max_abs_reading`]); any other is rejected and flags its filters.
pub fn accepts_reading(value: f64, max_abs_reading: f64) -> bool {
    value.is_finite() && value.abs() <= max_abs_reading
}

/// Readings with |y| above this are rejected by default \[m or m/s\] ([`ControllerConfig::max_abs_reading`]).
pub const DEFAULT_MAX_ABS_READING: f64 = 1e6;

impl ControllerConfig {
    /// A configuration of the FT-CBF-CLF controller for `model` with `fault_patterns` and the
    /// parameters `ft`, every other field at its documented default (see the setters of
    /// [`ControllerConfigBuilder`]); [`Controller::new`] validates the result.
    pub fn builder(
        model: LinearModel,
        fault_patterns: Vec<Vec<usize>>,
        ft: FtParams,
    ) -> ControllerConfigBuilder {
        ControllerConfigBuilder(ControllerConfig {
            kind: ControllerKind::FtCbfClf,
            model,
            fault_patterns,
            barriers: Vec::new(),
            goal: State::zeros(),
            goal_radius: DEFAULT_GOAL_RADIUS,
            ft,
            delta: f64::INFINITY,
            cbf_gain: 1.0,
            clf: ClfConfig::paper(0.0),
            input_cost: Matrix2::identity(),
            input_limit: None,
            x0: State::zeros(),
            p0: StateMatrix::zeros(),
            max_abs_reading: DEFAULT_MAX_ABS_READING,
            form: ProblemForm::Paper,
            fallback: Fallback::Paper,
            barrier_index: None,
        })
    }
}

/// The goal radius d of the paper's example (§6) \[m\], the builder's default.
pub const DEFAULT_GOAL_RADIUS: f64 = 0.05;

/// Builds a [`ControllerConfig`] from [`ControllerConfig::builder`]: each setter replaces one
/// default, [`ControllerConfigBuilder::build`] returns the configuration.
#[derive(Debug, Clone)]
pub struct ControllerConfigBuilder(ControllerConfig);

impl ControllerConfigBuilder {
    /// Which controller. Default: [`ControllerKind::FtCbfClf`], the controller this crate is
    /// about (the baseline and nominal ones are its comparisons).
    pub fn kind(mut self, kind: ControllerKind) -> Self {
        self.0.kind = kind;
        self
    }

    /// The safe sets. Default: none, so only the CLF shapes the input (a controller without
    /// a barrier guarantees nothing; add the sets it must keep).
    pub fn barriers(mut self, barriers: Vec<Arc<dyn Barrier>>) -> Self {
        self.0.barriers = barriers;
        self
    }

    /// A spatial index over the barriers ([`crate::reach`]): rows out of reach of every input
    /// of the box are not built. Default: none.
    pub fn barrier_index(mut self, index: Arc<dyn BarrierIndex>) -> Self {
        self.0.barrier_index = Some(index);
        self
    }

    /// Goal state x_g and radius d (state norm). Default: the origin with d =
    /// [`DEFAULT_GOAL_RADIUS`], the paper's example (§6).
    pub fn goal(mut self, goal: State, radius: f64) -> Self {
        self.0.goal = goal;
        self.0.goal_radius = radius;
        self
    }

    /// δ of X_t(δ): Ω is imposed when ĥ(x̂) < δ. Default: +∞, every barrier row every step
    /// (the safe choice; a finite δ leaves out rows far from their boundary to save work).
    pub fn delta(mut self, delta: f64) -> Self {
        self.0.delta = delta;
        self
    }

    /// Class-K gain κ of the CBF condition (`… ≥ −κ ĥ`). Default: 1, the paper's.
    pub fn cbf_gain(mut self, kappa: f64) -> Self {
        self.0.cbf_gain = kappa;
        self
    }

    /// The CLF. Default: [`ClfConfig::paper`] with V̄ = 0 (the paper's P_d, gain and rate ρ;
    /// with V̄ = 0 the CLF rows are imposed wherever V(x̂) > 0, i.e. until the goal is reached).
    pub fn clf(mut self, clf: ClfConfig) -> Self {
        self.0.clf = clf;
        self
    }

    /// Input cost R of (5.3), symmetric positive definite. Default: I, the paper's.
    pub fn input_cost(mut self, cost: Matrix2<f64>) -> Self {
        self.0.input_cost = cost;
        self
    }

    /// The symmetric box |a_k| ≤ limit_k \[m/s²\] (`None`: no box). Default: none, problem (5.3)
    /// as the paper states it (a real drive has one: set it).
    pub fn input_limit(mut self, limit: impl Into<Option<Input>>) -> Self {
        self.0.input_limit = limit.into();
        self
    }

    /// Initial estimate x̂(0) and its covariance P0. Default: the origin with P0 = 0, a start
    /// known exactly (the setting of [`crate::params::FtComputed::compute`]).
    pub fn start(mut self, x0: State, p0: StateMatrix) -> Self {
        self.0.x0 = x0;
        self.0.p0 = p0;
        self
    }

    /// Readings with |y| above this, or non-finite, are rejected. Default:
    /// [`DEFAULT_MAX_ABS_READING`], far beyond any honest position or speed of a ground
    /// robot, so only absurd values (an overflowed driver, a 10¹² spoof) are thrown out.
    pub fn max_abs_reading(mut self, limit: f64) -> Self {
        self.0.max_abs_reading = limit;
        self
    }

    /// Which problem the QP solves. Default: [`ProblemForm::Paper`], problem (5.3).
    pub fn form(mut self, form: ProblemForm) -> Self {
        self.0.form = form;
        self
    }

    /// What Step 3 does without evidence (see [`crate::policy`]). Default:
    /// [`Fallback::Paper`], the thesis' Step 3.
    pub fn fallback(mut self, fallback: Fallback) -> Self {
        self.0.fallback = fallback;
        self
    }

    /// The configuration (validated by [`Controller::new`]).
    pub fn build(self) -> ControllerConfig {
        self.0
    }
}

/// Configuration errors.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ConfigError {
    /// Model or fault patterns.
    #[error("invalid model or fault patterns: {0}")]
    Model(#[from] ModelError),
    /// CLF.
    #[error("invalid CLF: {0}")]
    Lyapunov(#[from] LyapunovError),
    /// A scalar out of range.
    #[error("controller config key `{key}` = {value}: expected {expected}")]
    BadValue {
        /// Key.
        key: &'static str,
        /// Value.
        value: f64,
        /// Expectation.
        expected: &'static str,
    },
    /// The nominal tracker of the safety-filter form.
    #[error("{0}")]
    Tracker(#[from] TrackerError),
    /// A list of the wrong length.
    #[error("controller config key `{key}` has {got} entries, expected {expected}")]
    Length {
        /// Key.
        key: &'static str,
        /// Expected.
        expected: String,
        /// Got.
        got: usize,
    },
}

/// Readings thrown out in one step.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RejectedReadings {
    /// Fresh readings rejected (non-finite or |y| > max_abs_reading).
    pub count: usize,
    /// Per channel.
    pub channels: Vec<bool>,
    /// Per fault pattern: a channel of it was rejected.
    pub patterns: Vec<bool>,
    /// `y`/`fresh` did not have q entries (missing entries treated as not fresh).
    pub length_mismatch: bool,
    /// `dt` was not finite and positive: the filters were not advanced.
    pub invalid_dt: bool,
    /// Accepted readings that a filter of the bank could not use because their innovation
    /// variance was not finite and positive, summed over the filters
    /// ([`crate::KalmanFilter::skipped_updates`]); each flags its filter.
    pub skipped_updates: usize,
}

/// Output of one step.
#[derive(Debug, Clone, PartialEq)]
pub struct ControlOutput {
    /// Input to apply (planar acceleration, world frame) (m/s²).
    pub u: Input,
    /// QP / policy outcome.
    pub qp: QpOutcome,
    /// Every constraint and what happened to it.
    pub decision: DecisionRecord,
    /// Rejected readings.
    pub rejected: RejectedReadings,
    /// h(x̂) per filter of the bank and barrier, index `filter * barriers + barrier`; NaN for
    /// a barrier out of reach (not evaluated: [`crate::reach`]).
    pub h_values: Vec<f64>,
    /// V(x̂) per filter of the bank.
    pub v_values: Vec<f64>,
    /// The nominal input u_nom of the safety-filter form (None in the paper's form) [m/s²].
    pub u_nom: Option<Input>,
    /// Stalls the nominal tracker detected so far (each starts an escape).
    pub stalls: usize,
}

/// The controller. `Send`; one per trial.
#[derive(Debug)]
pub struct Controller {
    kind: ControllerKind,
    barriers: Vec<Arc<dyn Barrier>>,
    /// γ, θ, η and θ(t) as configured (θ(t) read each step).
    ft: FtParams,
    h_bar: Vec<f64>,
    h_bar_baseline: Vec<f64>,
    delta: f64,
    cbf_gain: f64,
    max_abs_reading: f64,
    bank: EstimatorBank,
    clf: QuadraticClf,
    qp: QpSolver,
    problem: PolicyProblem,
    scratch: PolicyScratch,
    valid: Vec<bool>,
    rejected_buf: Vec<bool>,
    pattern_of_channel: Vec<Option<usize>>,
    u: Input,
    output: ControlOutput,
    /// The separations x̂_a − x̂_aj of the last steps with their times, for the increments of
    /// Step 2.
    separations: SeparationHistory,
    last_dt: f64,
    /// The time since the first step (sum of the valid dt), for θ_ij(t).
    elapsed: f64,
    /// The safety-filter form's tracker (None: problem 5.3).
    tracker: Option<PathTracker>,
    /// The acceleration the drive realised over the period now ending, when the platform
    /// reported it ([`Controller::set_applied_input`]); the next prediction uses it once.
    applied: Option<Input>,
    /// The moving obstacles' readings of this step ([`Controller::set_movers`]).
    movers: Vec<MoverState>,
    /// The active-barrier index and its buffers (None: every row is built).
    reach: Option<Reach>,
}

fn positive(key: &'static str, v: f64) -> Result<(), ConfigError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(ConfigError::BadValue {
            key,
            value: v,
            expected: "a finite number > 0",
        })
    }
}

fn nonneg(key: &'static str, v: f64) -> Result<(), ConfigError> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(ConfigError::BadValue {
            key,
            value: v,
            expected: "a finite number ≥ 0",
        })
    }
}

/// Validate a configuration (in this order: fault patterns, parameters, increment metrics,
/// θ schedule, the remaining numbers and matrices).
fn validate(cfg: &ControllerConfig) -> Result<(), ConfigError> {
    let q = cfg.model.channels();
    // Baseline and nominal use only the all-channel filter: fault patterns are optional for
    // them (a world with one receiver has none); FT-CBF-CLF needs m ≥ 1.
    if cfg.kind == ControllerKind::FtCbfClf || !cfg.fault_patterns.is_empty() {
        validate_fault_patterns(&cfg.fault_patterns, q)?;
    }
    let m = cfg.fault_patterns.len();
    let pairs = m * m.saturating_sub(1) / 2;
    validate_gamma_theta(cfg, m, pairs)?;
    validate_increment_metric(cfg)?;
    validate_theta_schedule(cfg, pairs)?;
    validate_numbers(cfg)
}

/// γ_i (one per pattern), γ_baseline, θ_ij and η_ij (one or one per pair; η_ij also none).
fn validate_gamma_theta(cfg: &ControllerConfig, m: usize, pairs: usize) -> Result<(), ConfigError> {
    let ft = &cfg.ft;
    if ft.gamma.len() != m {
        return Err(ConfigError::Length {
            key: "gamma",
            expected: format!("{m} (one per fault pattern)"),
            got: ft.gamma.len(),
        });
    }
    for &g in &ft.gamma {
        nonneg("gamma", g)?;
    }
    nonneg("gamma_baseline", ft.gamma_baseline)?;
    if !(ft.theta.len() == 1 || ft.theta.len() == pairs) {
        return Err(ConfigError::Length {
            key: "theta",
            expected: format!("1 or C(m,2) = {pairs}"),
            got: ft.theta.len(),
        });
    }
    for &t in &ft.theta {
        positive("theta", t)?;
    }
    if !(ft.eta.is_empty() || ft.eta.len() == 1 || ft.eta.len() == pairs) {
        return Err(ConfigError::Length {
            key: "eta",
            expected: format!("0, 1 or C(m,2) = {pairs}"),
            got: ft.eta.len(),
        });
    }
    for &t in &ft.eta {
        positive("eta", t)?;
    }
    Ok(())
}

/// The increment metrics: none or one per η_ij, each finite, symmetric and PSD.
fn validate_increment_metric(cfg: &ControllerConfig) -> Result<(), ConfigError> {
    let ft = &cfg.ft;
    if !(ft.increment_metric.is_empty() || ft.increment_metric.len() == ft.eta.len()) {
        return Err(ConfigError::Length {
            key: "increment_metric",
            expected: format!("0 or as many as eta ({})", ft.eta.len()),
            got: ft.increment_metric.len(),
        });
    }
    for w in &ft.increment_metric {
        let symmetric = (w - w.transpose()).norm() <= 1e-9 * w.norm();
        let least = if w.iter().all(|x| x.is_finite()) {
            w.symmetric_eigenvalues().min()
        } else {
            f64::NAN
        };
        if !symmetric || least.is_nan() || least < -1e-9 * w.norm() {
            return Err(ConfigError::BadValue {
                key: "increment_metric",
                value: least,
                expected: "finite, symmetric and positive semidefinite 4×4 matrices (value: the least eigenvalue)",
            });
        }
    }
    Ok(())
}

/// θ_ij(t): one non-empty row per pair, each value positive and at most the pair's θ_ij.
fn validate_theta_schedule(cfg: &ControllerConfig, pairs: usize) -> Result<(), ConfigError> {
    let Some(sched) = &cfg.ft.theta_schedule else {
        return Ok(());
    };
    positive("theta_schedule.dt", sched.dt)?;
    if sched.theta.len() != pairs || sched.theta.iter().any(Vec::is_empty) {
        return Err(ConfigError::Length {
            key: "theta_schedule",
            expected: format!("C(m,2) = {pairs} non-empty rows"),
            got: sched.theta.len(),
        });
    }
    for (idx, row) in sched.theta.iter().enumerate() {
        let cap = if cfg.ft.theta.len() == 1 {
            cfg.ft.theta[0]
        } else {
            cfg.ft.theta.get(idx).copied().unwrap_or(f64::NAN)
        };
        for &t in row {
            positive("theta_schedule", t)?;
            if t > cap * (1.0 + 1e-12) {
                return Err(ConfigError::BadValue {
                    key: "theta_schedule",
                    value: t,
                    expected: "at most the pair's theta (condition 1 is stated with theta)",
                });
            }
        }
    }
    Ok(())
}

/// δ, κ, the reading bound, the input box and cost, x0 and P0.
fn validate_numbers(cfg: &ControllerConfig) -> Result<(), ConfigError> {
    if cfg.delta.is_nan() || cfg.delta <= 0.0 {
        return Err(ConfigError::BadValue {
            key: "delta",
            value: cfg.delta,
            expected: "> 0 (may be +inf)",
        });
    }
    positive("cbf_gain", cfg.cbf_gain)?;
    positive("max_abs_reading", cfg.max_abs_reading)?;
    if let Fallback::Brake { evidence_z } = cfg.fallback {
        if !(evidence_z.is_finite() && evidence_z > 0.0) {
            return Err(ConfigError::BadValue {
                key: "fallback.evidence_z",
                value: evidence_z,
                expected: "a finite normal score > 0 (Fallback::brake(α) with 0 < α < 0.5)",
            });
        }
    }
    if let Some(l) = cfg.input_limit {
        positive("input_limit[0]", l[0])?;
        positive("input_limit[1]", l[1])?;
    }
    let r = cfg.input_cost;
    if r.iter().any(|v| !v.is_finite()) || r[(0, 0)] <= 0.0 || r.determinant() <= 0.0 {
        return Err(ConfigError::BadValue {
            key: "input_cost",
            value: r.determinant(),
            expected: "a symmetric positive definite 2×2 matrix",
        });
    }
    if cfg.x0.iter().any(|v| !v.is_finite()) {
        return Err(ConfigError::BadValue {
            key: "x0",
            value: f64::NAN,
            expected: "finite entries",
        });
    }
    let p0min = ((cfg.p0 + cfg.p0.transpose()) * 0.5)
        .symmetric_eigenvalues()
        .min();
    if cfg.p0.iter().any(|v| !v.is_finite()) || p0min < 0.0 {
        return Err(ConfigError::BadValue {
            key: "p0",
            value: p0min,
            expected: "a symmetric PSD matrix (min eigenvalue ≥ 0)",
        });
    }
    Ok(())
}

/// The active-barrier index of a controller ([`crate::reach`]) with what each step needs.
#[derive(Debug)]
struct Reach {
    index: Arc<dyn BarrierIndex>,
    /// Which barriers the index covers.
    covered: Vec<bool>,
    /// Per unit, the largest h̄_γ over the covered barriers.
    h_bar: Vec<f64>,
    /// ‖L‖₂ of the input box.
    limit_norm: f64,
    /// The barriers found near an estimate (capacity: every barrier).
    near: Vec<usize>,
    /// The largest reach radius of this step's units (the logging radius of the other filters).
    radius: f64,
    /// Which barriers a filter that is no unit's does not log (beyond `radius`).
    log_far: Vec<bool>,
}

impl Reach {
    /// None without an index, without an input box (nothing can be out of reach) or without
    /// barrier rows.
    fn new(
        cfg: &ControllerConfig,
        h_bar: &[f64],
        h_bar_baseline: &[f64],
        units: usize,
        barriers_used: usize,
    ) -> Option<Self> {
        let index = cfg.barrier_index.clone()?;
        let limit = cfg.input_limit?;
        if barriers_used == 0 {
            return None;
        }
        let nb = cfg.barriers.len();
        let covered: Vec<bool> = (0..nb).map(|b| index.covers(b)).collect();
        let worst = |hb: &[f64]| {
            hb.iter()
                .zip(&covered)
                .filter(|(_, &c)| c)
                .map(|(&h, _)| h)
                .fold(0.0_f64, f64::max)
        };
        let h_bar = (0..units)
            .map(|i| match cfg.kind {
                ControllerKind::FtCbfClf => worst(&h_bar[i * nb..(i + 1) * nb]),
                _ => worst(h_bar_baseline),
            })
            .collect();
        Some(Self {
            index,
            covered,
            h_bar,
            limit_norm: limit.norm(),
            near: Vec::with_capacity(nb),
            radius: 0.0,
            log_far: vec![false; nb],
        })
    }

    /// Marks unit `i`'s covered barriers out of reach of estimate `x` (filter gain terms `m`,
    /// `n`, error bound γ), then those the index finds within the reach radius back in reach;
    /// returns the lower bound of h at the radius (+∞ if nothing is out of reach).
    #[allow(clippy::too_many_arguments)]
    fn mark(
        &mut self,
        model: &LinearModel,
        i: usize,
        x: &State,
        m: &StateMatrix,
        n: &StateMatrix,
        gamma: f64,
        kappa: f64,
        delta: f64,
        far: &mut [bool],
    ) -> f64 {
        let terms = ReachTerms::new(
            &model.f,
            &model.g,
            self.limit_norm,
            x,
            m,
            n,
            gamma,
            kappa,
            self.h_bar[i],
            delta,
        );
        let radius = terms.radius(self.index.as_ref());
        self.radius = self.radius.max(radius);
        if !(radius.is_finite() && x[0].is_finite() && x[1].is_finite()) {
            far.iter_mut().for_each(|f| *f = false);
            return f64::INFINITY;
        }
        far.copy_from_slice(&self.covered[..far.len()]);
        self.near.clear();
        self.index.near([x[0], x[1]], radius, &mut self.near);
        for &b in &self.near {
            if let Some(f) = far.get_mut(b) {
                *f = false;
            }
        }
        self.index.far_bounds(radius, terms.speed).h_lower
    }

    /// `log_far`: the covered barriers beyond this step's largest reach radius from `x`'s
    /// position (h(x̂) of a filter that is no unit's is logged only within it).
    fn log_mask(&mut self, x: &State) {
        if !(self.radius.is_finite() && x[0].is_finite() && x[1].is_finite()) {
            self.log_far.iter_mut().for_each(|f| *f = false);
            return;
        }
        self.log_far.copy_from_slice(&self.covered);
        self.near.clear();
        self.index.near([x[0], x[1]], self.radius, &mut self.near);
        for &b in &self.near {
            if let Some(f) = self.log_far.get_mut(b) {
                *f = false;
            }
        }
    }
}

/// The policy's problem with its fixed parts filled in: δ, V̄, and θ_ij, η_ij and the
/// increment metric per ordered pair of units.
fn initial_problem(
    cfg: &ControllerConfig,
    units: usize,
    barriers_used: usize,
    m: usize,
) -> PolicyProblem {
    let mut problem = PolicyProblem::new(units, barriers_used);
    problem.use_clf = true;
    problem.delta = cfg.delta;
    problem.v_bar = cfg.clf.v_bar;
    let ft = &cfg.ft;
    problem.theta = PairTable::from_fn(units, |i, j| {
        FtParams::per_pair(&ft.theta, m, i, j).unwrap_or(f64::NAN)
    });
    problem.eta = PairTable::from_fn(units, |i, j| {
        FtParams::per_pair(&ft.eta, m, i, j).unwrap_or(f64::INFINITY)
    });
    problem.increment_metric = PairTable::from_fn(units, |i, j| {
        FtParams::per_pair(&ft.increment_metric, m, i, j).unwrap_or_else(StateMatrix::identity)
    });
    problem.gamma = (0..units)
        .map(|i| {
            let g = if units == m {
                ft.gamma.get(i).copied()
            } else {
                Some(ft.gamma_baseline)
            };
            g.unwrap_or(f64::INFINITY)
        })
        .collect();
    problem
}

/// The problem form's tracker (None for problem 5.3) and whether the CLF rows are imposed. The
/// tracker inherits the controller's input box when it has none of its own.
fn form_parts(
    form: ProblemForm,
    input_limit: Option<Input>,
    x0: &State,
) -> Result<(Option<PathTracker>, bool), ConfigError> {
    match form {
        ProblemForm::Paper => Ok((None, true)),
        ProblemForm::SafetyFilter { mut tracker, clf } => {
            if tracker.input_limit.is_none() {
                tracker.input_limit = input_limit;
            }
            Ok((Some(PathTracker::new(tracker, [x0[0], x0[1]])?), clf))
        }
    }
}

/// The output before the first step, with every buffer at its final size.
fn initial_output(
    units: usize,
    barriers_used: usize,
    channels: usize,
    patterns: usize,
    filters: usize,
    barriers: usize,
) -> ControlOutput {
    ControlOutput {
        u: Input::zeros(),
        qp: QpOutcome::Feasible {
            stage: crate::policy::Stage::Step1,
            clf_relaxed: false,
            clf_slack: 0.0,
            iterations: 0,
        },
        decision: DecisionRecord::with_capacity(units * (barriers_used + 1)),
        rejected: RejectedReadings {
            count: 0,
            channels: vec![false; channels],
            patterns: vec![false; patterns],
            length_mismatch: false,
            invalid_dt: false,
            skipped_updates: 0,
        },
        h_values: vec![0.0; filters * barriers],
        v_values: vec![0.0; filters],
        u_nom: None,
        stalls: 0,
    }
}

impl Controller {
    /// Validate the configuration and build the controller.
    pub fn new(cfg: ControllerConfig) -> Result<Self, ConfigError> {
        validate(&cfg)?;
        let q = cfg.model.channels();
        let m = cfg.fault_patterns.len();
        let clf = QuadraticClf::new(
            &cfg.model.f,
            &cfg.model.g,
            cfg.goal,
            cfg.goal_radius,
            &cfg.clf,
        )?;

        let nb = cfg.barriers.len();
        let units = match cfg.kind {
            ControllerKind::FtCbfClf => m,
            _ => 1,
        };
        let barriers_used = if cfg.kind == ControllerKind::Nominal {
            0
        } else {
            nb
        };
        let h_bar: Vec<f64> = cfg
            .ft
            .gamma
            .iter()
            .flat_map(|&g| cfg.barriers.iter().map(move |b| b.h_bar(g)))
            .collect();
        let h_bar_baseline: Vec<f64> = cfg
            .barriers
            .iter()
            .map(|b| b.h_bar(cfg.ft.gamma_baseline))
            .collect();

        let reach = Reach::new(&cfg, &h_bar, &h_bar_baseline, units, barriers_used);
        let mut problem = initial_problem(&cfg, units, barriers_used, m);
        let bank = EstimatorBank::new(cfg.model.clone(), &cfg.fault_patterns, cfg.x0, cfg.p0);
        let qp = QpSolver::new(
            units * barriers_used,
            units,
            cfg.input_cost,
            SLACK_WEIGHT,
            cfg.input_limit,
        );
        let mut pattern_of_channel = vec![None; q];
        for (p, pat) in cfg.fault_patterns.iter().enumerate() {
            for &c in pat {
                pattern_of_channel[c] = Some(p);
            }
        }
        let output = initial_output(units, barriers_used, q, m, bank.filters().len(), nb);
        let (tracker, use_clf) = form_parts(cfg.form, cfg.input_limit, &cfg.x0)?;
        problem.use_clf = use_clf;
        problem.step2_every_step = tracker.is_some();
        // A departure from the paper's Step 3 (book/src/theory/controller.md): it
        // turned the stealthy counterexample of `falsify` from 58/200 safe into 200/200.
        problem.step3_keeps_saturated = true;
        problem.fallback = cfg.fallback;
        problem.moving = (0..barriers_used)
            .map(|b| cfg.barriers.get(b).is_some_and(|x| x.mover().is_some()))
            .collect();
        Ok(Self {
            kind: cfg.kind,
            scratch: PolicyScratch::new(units, barriers_used),
            barriers: cfg.barriers,
            ft: cfg.ft,
            h_bar,
            h_bar_baseline,
            delta: cfg.delta,
            cbf_gain: cfg.cbf_gain,
            max_abs_reading: cfg.max_abs_reading,
            bank,
            clf,
            qp,
            problem,
            valid: vec![false; q],
            rejected_buf: vec![false; q],
            pattern_of_channel,
            u: Input::zeros(),
            output,
            separations: SeparationHistory::new(units * units),
            last_dt: 0.0,
            elapsed: 0.0,
            tracker,
            applied: None,
            movers: Vec::new(),
            reach,
        })
    }

    /// Reports the world-frame acceleration [m/s²] the platform's drive actually realised over
    /// the control period now ending (after its speed and yaw-rate limits, its low-speed law and
    /// its wheels' saturation; see [`crate::drive::realized_acceleration`]). The next
    /// [`Controller::step`] predicts its filters with it instead of the u it asked for: a
    /// unicycle cannot realise a lateral acceleration at rest, and a filter that believes it
    /// did carries a velocity error its γ does not cover. Non-finite values are ignored.
    pub fn set_applied_input(&mut self, a: Input) {
        self.applied = (a[0].is_finite() && a[1].is_finite()).then_some(a);
    }

    /// The moving obstacles' readings for the next [`Controller::step`] (issue #51): the rows
    /// of barriers with a [`Barrier::mover`] are built from them (a missing reading makes its
    /// rows NaN, which fail closed). Kept until replaced.
    pub fn set_movers(&mut self, movers: &[MoverState]) {
        self.movers.clear();
        self.movers.extend_from_slice(movers);
    }

    /// Which controller this is.
    pub fn kind(&self) -> ControllerKind {
        self.kind
    }
    /// The estimator bank (estimates, covariances, residues, labels).
    pub fn bank(&self) -> &EstimatorBank {
        &self.bank
    }
    /// The CLF.
    pub fn clf(&self) -> &QuadraticClf {
        &self.clf
    }
    /// The barriers.
    pub fn barriers(&self) -> &[Arc<dyn Barrier>] {
        &self.barriers
    }
    /// The last output.
    pub fn output(&self) -> &ControlOutput {
        &self.output
    }
    /// The input currently held.
    pub fn input(&self) -> Input {
        self.u
    }
    /// h(x̂) of bank filter `filter` for barrier `barrier` (as of the last step).
    pub fn barrier_value(&self, filter: usize, barrier: usize) -> Option<f64> {
        if barrier >= self.barriers.len() {
            return None;
        }
        self.output
            .h_values
            .get(filter * self.barriers.len() + barrier)
            .copied()
    }
    /// V(x̂) of bank filter `filter` (as of the last step).
    pub fn clf_value(&self, filter: usize) -> Option<f64> {
        self.output.v_values.get(filter).copied()
    }

    /// One control step: predict over `dt` with the previous input, update with the fresh and
    /// valid readings, then solve the policy. `y.len() == fresh.len() == q` is expected;
    /// missing entries count as not fresh (and `length_mismatch` is reported). Non-finite
    /// readings and readings with |y| > `max_abs_reading` are never used: they are counted,
    /// and the filters using that channel are flagged (largest residue in Step 3).
    pub fn step(&mut self, y: &[f64], fresh: &[bool], dt: f64) -> &ControlOutput {
        let q = self.valid.len();
        let rej = &mut self.output.rejected;
        rej.count = 0;
        rej.length_mismatch = y.len() != q || fresh.len() != q;
        rej.patterns.iter_mut().for_each(|p| *p = false);
        for k in 0..q {
            let is_fresh = fresh.get(k).copied().unwrap_or(false) && k < y.len();
            let v = y.get(k).copied().unwrap_or(f64::NAN);
            let ok = accepts_reading(v, self.max_abs_reading);
            self.valid[k] = is_fresh && ok;
            self.rejected_buf[k] = is_fresh && !ok;
            rej.channels[k] = self.rejected_buf[k];
            if self.rejected_buf[k] {
                rej.count += 1;
                if let Some(p) = self.pattern_of_channel[k] {
                    rej.patterns[p] = true;
                }
            }
        }
        rej.invalid_dt = !(dt.is_finite() && dt > 0.0);
        self.last_dt = if rej.invalid_dt { 0.0 } else { dt };
        self.elapsed += self.last_dt;
        if !rej.invalid_dt {
            // valid[k] implies k < y.len(): the filters only read valid channels.
            let predict_with = self.applied.take().unwrap_or(self.u);
            self.bank
                .step(&predict_with, dt, y, &self.valid, &self.rejected_buf);
        }
        self.output.rejected.skipped_updates = self
            .bank
            .filters()
            .iter()
            .map(|f| f.skipped_updates())
            .sum();
        self.fill_problem();
        let isolated = prepare(&self.problem, &mut self.scratch, &mut self.output.decision);
        self.propose_nominal();
        let (u, outcome) = decide(
            &self.problem,
            &mut self.qp,
            &mut self.scratch,
            &mut self.output.decision,
            isolated,
        );
        self.u = u;
        self.bank.set_last_input(u);
        self.output.u = u;
        self.output.qp = outcome;
        // logging values: a unit's filter's h(x̂) is its rows' (the same evaluation of the same
        // estimate, made in `fill_problem` this step), the other filters' are evaluated here
        // (NaN: out of reach, not evaluated; see crate::reach)
        let nb = self.barriers.len();
        let nbu = self.problem.barriers();
        let units = self.problem.units();
        for (fi, f) in self.bank.filters().iter().enumerate() {
            let unit = (0..units).find(|&i| nbu == nb && self.unit_filter(i) == fi);
            if unit.is_none() {
                if let Some(r) = self.reach.as_mut() {
                    r.log_mask(f.estimate());
                }
            }
            for (bi, b) in self.barriers.iter().enumerate() {
                self.output.h_values[fi * nb + bi] = match unit {
                    Some(i) if self.problem.cbf_far[i * nbu + bi] => f64::NAN,
                    Some(i) => self.problem.cbf[i * nbu + bi].h,
                    None if self.reach.as_ref().is_some_and(|r| r.log_far[bi]) => f64::NAN,
                    None => b.eval_moving(f.estimate(), &self.movers).0.value,
                };
            }
            self.output.v_values[fi] = self.clf.value(f.estimate());
        }
        &self.output
    }

    /// The filter whose estimate unit `i`'s rows use (as in `fill_problem`).
    fn unit_filter(&self, i: usize) -> usize {
        match self.kind {
            ControllerKind::FtCbfClf => i,
            _ => self.bank.baseline_index(),
        }
    }

    /// The safety-filter form: u_nom from the estimate of a unit Step 2's isolation kept (this
    /// step's [`prepare`] ran it), as the QP's reference: a kept unit whose filter is not starved
    /// (its one-σ position spread √tr P_pos within the error bound γ its rows assume; γ is
    /// several σ of the worst covariance the bounds allow, so only a filter that has lost
    /// channels for seconds exceeds it) when there is one, then the one Step 3 would keep
    /// (smallest residue key, then the lowest index). A unit that lost a channel (a receiver's x reading dropped)
    /// dead-reckons that axis, drifting, with a χ² score as good as the honest one's: the robot
    /// followed it 12 times in 20 and stopped off its goal (issue #36, a generated L turn).
    /// Preferring the more certain unit outright was tried and undone: it hands the reference to
    /// a stealthy attacker of the more precise receiver (`stealthy_gnss` came 0.08 m nearer its
    /// wall); so was a filter's variance against 4 × its least, which a 5–10 Hz receiver without
    /// velocity exceeds between readings (a generated corridor stopped entering its goal).
    /// Without the Step-2 filter a spoofed unit with a small residue steered u_nom even while
    /// Step 2 dropped its rows every step, and the robot dithered at the goal between the
    /// spoofed reference and the honest barrier row. (A component-wise median over units and
    /// pair filters was tried first: with three receivers and one biased, half of the six
    /// estimates carry the bias, and the robot parked 0.1 m off the goal in `three_gnss`.)
    fn propose_nominal(&mut self) {
        let Some(tracker) = self.tracker.as_mut() else {
            return;
        };
        let units = self.problem.units();
        let filters = self.bank.filters();
        let spread = |f: &crate::estimator::KalmanFilter| {
            let p = f.covariance();
            let v = p[(0, 0)] + p[(1, 1)];
            if v.is_finite() {
                v
            } else {
                f64::INFINITY
            }
        };
        // The unit's filter (the baseline's for the baseline's unit) is starved when its
        // position spread √tr P_pos exceeds the error bound γ its rows assume.
        let starved = |i: usize| {
            let (fi, gamma) = match self.kind {
                ControllerKind::FtCbfClf => (i, self.ft.gamma.get(i).copied()),
                _ => (self.bank.baseline_index(), Some(self.ft.gamma_baseline)),
            };
            match (filters.get(fi), gamma) {
                // `spread` maps a non-finite variance to +∞, so this is never a NaN comparison.
                (Some(f), Some(g)) => spread(f) > g * g,
                _ => true,
            }
        };
        let fed = (0..units).any(|i| self.scratch.kept(i) && !starved(i));
        let key = |i: usize| {
            (
                !self.scratch.kept(i),
                fed && starved(i),
                self.problem.residue_key[i],
            )
        };
        let best = (0..units)
            .min_by(|&a, &b| {
                let (ka, kb) = (key(a), key(b));
                ka.0.cmp(&kb.0)
                    .then(ka.1.cmp(&kb.1))
                    .then(ka.2.total_cmp(&kb.2))
            })
            .unwrap_or(0);
        let x = self.problem.estimates[best];
        let u_nom = tracker.propose([x[0], x[1]], [x[2], x[3]], self.last_dt);
        self.qp.set_reference(u_nom);
        self.output.u_nom = Some(u_nom);
        self.output.stalls = tracker.stalls();
    }

    /// The safety-filter form's tracker, if any.
    pub fn tracker(&self) -> Option<&PathTracker> {
        self.tracker.as_ref()
    }

    fn fill_problem(&mut self) {
        if let Some(r) = self.reach.as_mut() {
            r.radius = 0.0;
        }
        let model = self.bank.model();
        let nbu = self.problem.barriers();
        let units = self.problem.units();
        let m = self.bank.patterns();
        for i in 0..units {
            let (fi, gamma, hbars): (usize, f64, &[f64]) = match self.kind {
                ControllerKind::FtCbfClf => (
                    i,
                    self.ft.gamma[i],
                    &self.h_bar[i * self.barriers.len()..(i + 1) * self.barriers.len()],
                ),
                _ => (
                    self.bank.baseline_index(),
                    self.ft.gamma_baseline,
                    &self.h_bar_baseline,
                ),
            };
            let f = &self.bank.filters()[fi];
            let x = f.estimate();
            let far = &mut self.problem.cbf_far[i * nbu..(i + 1) * nbu];
            let h_far = match self.reach.as_mut() {
                Some(r) => r.mark(
                    model,
                    i,
                    x,
                    f.gain_drift(),
                    f.gain_diffusion(),
                    gamma,
                    self.cbf_gain,
                    self.delta,
                    far,
                ),
                None => f64::INFINITY,
            };
            for (b, &hb) in hbars.iter().enumerate().take(nbu) {
                let k = i * nbu + b;
                if self.problem.cbf_far[k] {
                    let h_hat = h_far - self.reach.as_ref().map_or(0.0, |r| r.h_bar[i]);
                    // Out of reach (crate::reach): every input of the box satisfies the row.
                    self.problem.cbf[k] = CbfRow {
                        lambda: Input::zeros(),
                        omega_bar: -1.0,
                        h: h_far,
                        h_hat,
                    };
                    // The radius makes ĥ ≥ δ when δ is finite: outside X_t(δ), as Step 1 has it.
                    self.problem.cbf_active[k] = self.delta == f64::INFINITY;
                    continue;
                }
                let (eval, dh_dt) = self.barriers[b].eval_moving(x, &self.movers);
                let mut row = cbf_row(
                    model,
                    &eval,
                    x,
                    f.gain_drift(),
                    f.gain_diffusion(),
                    gamma,
                    hb,
                    self.cbf_gain,
                );
                // A moving obstacle's row: ∂h/∂x(Fx̂ + Gu) + ∂h/∂t ≥ …, so ∂h/∂t moves ω̄
                // (a static barrier's is exactly 0 and leaves the row as it was, bit for bit).
                row.omega_bar -= dh_dt;
                // X_t(δ) = {ĥ < δ}; a NaN ĥ is imposed (and its row fails closed), never
                // left out as "far from the boundary".
                self.problem.cbf_active[k] = row.h_hat < self.delta || row.h_hat.is_nan();
                self.problem.cbf[k] = row;
            }
            let crow = clf_row(
                model,
                &self.clf,
                x,
                f.gain_drift(),
                f.gain_diffusion(),
                gamma,
            );
            self.problem.clf_active[i] = crow.v > self.clf.v_bar;
            self.problem.clf[i] = crow;
            self.problem.estimates[i] = *x;
            self.problem.residue_key[i] = f.residue_rank_key();
            self.problem.residue_stat[i] = f.window_statistic();
            self.problem.flagged[i] = f.flagged();
        }
        if self.kind == ControllerKind::FtCbfClf {
            for i in 0..m {
                for j in (i + 1)..m {
                    if let Some(p) = self.bank.pair(i, j) {
                        self.problem.pair_estimates[(i, j)] = *p.estimate();
                    }
                }
            }
            if self.last_dt > 0.0 {
                self.update_increments(m);
            }
            if let Some(sched) = &self.ft.theta_schedule {
                // θ_ij(t) rows are in the packed pair order the table stores.
                for (k, theta) in self.problem.theta.values_mut().iter_mut().enumerate() {
                    if let Some(t) = sched.at(k, self.elapsed) {
                        *theta = t;
                    }
                }
            }
        }
    }

    /// Step 2's increments Δ(x̂_a − x̂_aj) over the last [`STEP2_WINDOW`] seconds (from the start,
    /// where x̂_a = x̂_aj = x0, during the first window).
    fn update_increments(&mut self, m: usize) {
        let h = &mut self.separations;
        let reference = h.reference(self.elapsed);
        for a in 0..m {
            for j in 0..m {
                if a == j {
                    continue;
                }
                let k = a * m + j;
                let s = self.problem.estimates[a] - self.problem.pair_estimates[(a, j)];
                self.problem.separation_increment[k] = s - h.get(reference, k);
                h.store(k, s);
            }
        }
        h.push(self.elapsed);
    }
}

/// The separations of the last [`RESIDUE_WINDOW_MAX_STEPS`] control steps, each with the time
/// it was taken, in a ring allocated once. The increment's reference is the stored separation
/// taken nearest to [`STEP2_WINDOW`] before now (ties: the older), or the start (all zero at
/// t = 0) while it is nearer and no more than [`RESIDUE_WINDOW_MAX_STEPS`] steps back. With a
/// constant period this is the separation `round(1 s/dt)` steps back, as before; a change of
/// period keeps the history (issue #30: the ring used to restart from zero, so for a second
/// the increment was the whole separation, and Step 2 could drop the honest filter).
#[derive(Debug, Clone)]
struct SeparationHistory {
    /// Entries per slot.
    n: usize,
    /// Slot-major separations, `RESIDUE_WINDOW_MAX_STEPS` slots of `n`, the scratch slot last.
    ring: Vec<State>,
    /// The time of each slot's separations.
    time: Vec<f64>,
    /// The slot the next push fills.
    head: usize,
    /// Steps pushed so far.
    steps: usize,
}

impl SeparationHistory {
    fn new(n: usize) -> Self {
        Self {
            n,
            ring: vec![State::zeros(); (RESIDUE_WINDOW_MAX_STEPS + 1) * n],
            time: vec![0.0; RESIDUE_WINDOW_MAX_STEPS],
            head: 0,
            steps: 0,
        }
    }

    /// The slot of the reference separations for a step at time `now` (`None`: the start's).
    fn reference(&self, now: f64) -> Option<usize> {
        let cap = RESIDUE_WINDOW_MAX_STEPS;
        let target = now - STEP2_WINDOW;
        let mut best: Option<(usize, f64)> = None;
        for lag in 1..=self.steps.min(cap) {
            let slot = (self.head + cap - lag) % cap;
            let d = (self.time[slot] - target).abs();
            match best {
                Some((_, bd)) if d > bd => break, // times fall with the lag: past the nearest
                _ => best = Some((slot, d)),
            }
        }
        let start_in_reach = self.steps < cap;
        match best {
            Some((_, bd)) if start_in_reach && target.abs() <= bd => None,
            Some((slot, _)) => Some(slot),
            None => None,
        }
    }

    /// Entry `k` of the reference (zero for the start).
    fn get(&self, reference: Option<usize>, k: usize) -> State {
        reference.map_or_else(State::zeros, |slot| self.ring[slot * self.n + k])
    }

    /// Put entry `k` of this step's separations in the scratch slot (stored by [`Self::push`]).
    fn store(&mut self, k: usize, s: State) {
        self.ring[RESIDUE_WINDOW_MAX_STEPS * self.n + k] = s;
    }

    /// Store the scratch slot as the separations taken at `now`.
    fn push(&mut self, now: f64) {
        let k = RESIDUE_WINDOW_MAX_STEPS * self.n;
        let h = self.head * self.n;
        self.ring.copy_within(k..k + self.n, h);
        self.time[self.head] = now;
        self.head = (self.head + 1) % RESIDUE_WINDOW_MAX_STEPS;
        self.steps += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn assert_send<T: Send>() {}

    #[test]
    fn controller_is_send() {
        assert_send::<Controller>();
    }

    /// The builder's defaults are the ones its setters document, and a setter replaces only
    /// its own field.
    #[test]
    fn the_builder_fills_the_documented_defaults() {
        let model = LinearModel::paper_double_integrator(1e-3, 1e-3).unwrap();
        let ft = FtParams::uniform(2, 0.01, 0.2);
        let c =
            ControllerConfig::builder(model.clone(), vec![vec![1], vec![3]], ft.clone()).build();
        assert_eq!(c.kind, ControllerKind::FtCbfClf);
        assert_eq!(c.model, model);
        assert_eq!(c.fault_patterns, vec![vec![1], vec![3]]);
        assert_eq!(c.ft, ft);
        assert!(c.barriers.is_empty());
        assert_eq!(
            (c.goal, c.goal_radius),
            (State::zeros(), DEFAULT_GOAL_RADIUS)
        );
        assert_eq!(c.delta, f64::INFINITY);
        assert_eq!(c.cbf_gain, 1.0);
        assert_eq!(c.clf.v_bar, 0.0);
        assert_eq!(c.clf.scale, ClfConfig::paper(0.0).scale);
        assert_eq!(c.input_cost, Matrix2::identity());
        assert_eq!(c.input_limit, None);
        assert_eq!((c.x0, c.p0), (State::zeros(), StateMatrix::zeros()));
        assert_eq!(c.max_abs_reading, DEFAULT_MAX_ABS_READING);
        assert_eq!(c.form, ProblemForm::Paper);
        assert!(Controller::new(c).is_ok());

        let limit = Input::new(1.0, 2.0);
        let c = ControllerConfig::builder(model, vec![vec![1], vec![3]], ft)
            .kind(ControllerKind::Baseline)
            .goal(State::new(1.0, 2.0, 0.0, 0.0), 0.1)
            .delta(0.5)
            .cbf_gain(3.0)
            .input_limit(limit)
            .start(State::new(0.5, 0.0, 0.0, 0.0), StateMatrix::identity())
            .max_abs_reading(10.0)
            .build();
        assert_eq!(c.kind, ControllerKind::Baseline);
        assert_eq!(c.goal, State::new(1.0, 2.0, 0.0, 0.0));
        assert_eq!((c.goal_radius, c.delta, c.cbf_gain), (0.1, 0.5, 3.0));
        assert_eq!(c.input_limit, Some(limit));
        assert_eq!(
            (c.x0[0], c.p0, c.max_abs_reading),
            (0.5, StateMatrix::identity(), 10.0)
        );
        assert_eq!(c.input_cost, Matrix2::identity());
    }

    /// Push separation `value(t)` at each of `times` and return the increment at each step.
    fn increments(
        h: &mut SeparationHistory,
        times: &[f64],
        value: impl Fn(f64) -> f64,
    ) -> Vec<f64> {
        times
            .iter()
            .map(|&t| {
                let s = State::new(value(t), 0.0, 0.0, 0.0);
                let r = h.get(h.reference(t), 0)[0];
                h.store(0, s);
                h.push(t);
                s[0] - r
            })
            .collect()
    }

    /// Issue #30: a change of the control period keeps the separation history. A separation
    /// growing at 1 m/s has an increment of 1 m over any second; the old ring restarted at the
    /// change, so the increment became the whole separation (here up to 4 m).
    #[test]
    fn a_changed_period_keeps_the_increment_history() {
        let mut h = SeparationHistory::new(1);
        let mut times: Vec<f64> = (1..=150).map(|k| k as f64 * 0.02).collect(); // 3 s at 50 Hz
        let t0 = 3.0;
        times.extend((1..=100).map(|k| t0 + k as f64 * 0.01)); // then 1 s at 100 Hz
        let inc = increments(&mut h, &times, |t| t);
        // the first second: from the start (separation 0 at t = 0)
        assert!((inc[10] - times[10]).abs() < 1e-12, "{}", inc[10]);
        for (k, (&t, &d)) in times.iter().zip(&inc).enumerate().skip(50) {
            assert!(
                (d - 1.0).abs() < 0.011,
                "step {k} at t = {t}: increment {d}"
            );
        }
        // a constant period: exactly round(1 s/dt) steps back
        let mut h = SeparationHistory::new(1);
        let times: Vec<f64> = (1..=200).map(|k| k as f64 * 0.03).collect();
        let inc = increments(&mut h, &times, |t| t * t);
        for k in 40..200 {
            let back = times[k - 33];
            assert!(
                (inc[k] - (times[k] * times[k] - back * back)).abs() < 1e-9,
                "step {k}"
            );
        }
    }
}
