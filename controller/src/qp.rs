//! Problem 5.3 through clarabel, with one reused solver.
//!
//! Variables `z = (u₁, u₂, s)`: the input and one shared slack `s ≥ 0` (m/s²).
//! Cost `(u − u_ref)ᵀR(u − u_ref) + w s²` (clarabel's ½zᵀPz + qᵀz with P = diag(2R, 2w) and
//! q = (−2R·u_ref, 0)); u_ref = 0 is problem 5.3, a nominal input u_nom the safety-filter form
//! ([`QpSolver::set_reference`]).
//! Rows (all `a·z ≤ b`, nonnegative cone), fixed layout and a fixed **dense** sparsity
//! pattern so the solver can be reused with `update_A`/`update_b` (presolve, zero-dropping,
//! and equilibration are off):
//!
//! * `cbf_capacity` CBF rows `n·u (− s if soft) ≤ o`,
//! * `clf_capacity` CLF rows `n·u (− s if soft) ≤ o`,
//! * 4 input-box rows (`±u_k ≤ limit_k`, or the inactive `0·z ≤ 1` when unbounded),
//! * `−s ≤ 0`.
//!
//! **Compaction.** When more than [`COMPACT_CBF_ROWS`] CBF rows can occur, the solver is first
//! built for [`COMPACT_START_ROWS`] of them, so a world with hundreds of obstacles does not make every
//! interior-point iteration factor a KKT system with a row per (filter, obstacle). When more
//! CBF rows are passed than the solver holds, the rows whose half-space contains the whole
//! input box (`|n₁|L₁ + |n₂|L₂ < o`: every admissible input, and any slack s ≥ 0, satisfies
//! them) are left out: the feasible set, hence the problem, is unchanged, and a far obstacle's
//! row is such a row (its ĥ makes the offset exceed what the box can reach). Only when the
//! remaining rows still do not fit is the solver rebuilt for more (doubling, up to every row).
//! Problems with at most [`COMPACT_CBF_ROWS`] CBF rows are solved exactly as before, row for
//! row.
//!
//! Unused rows are the inactive `0·z ≤ 1`. **Every row is scaled to a unit-norm input
//! normal** (`n/‖n‖ · u ≤ o/‖n‖`), an equivalent problem; this removes the 1e8 of the CLF
//! (eq. 6.6) from the numerics, and is why equilibration can stay off across reuses.
//! A row with a vanishing finite normal becomes `0 ≤ 1` (if `o ≥ 0`, always satisfied) or
//! `0 ≤ −1` (if `o < 0`: infeasible, as it should be); a row whose normal or offset is not
//! finite becomes `0 ≤ −1` (fail closed: never treated as satisfied).
//!
//! "Hard" rows have no slack; "soft" rows share the slack s (so the solver minimises the
//! largest violation, weighted against the input cost). The scaling is
//! [`Line::from_half_space`], shared with the geometric test of [`crate::feasibility`] that
//! the policy uses to decide feasibility before calling the solver. The solver's status
//! ([`QpResult`]) is always checked, and a reused solver that does not return
//! Solved/PrimalInfeasible is rebuilt once from scratch before a failure is reported.

use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettings, DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT,
};
use nalgebra::Matrix2;

use crate::constraints::HalfSpace;
use crate::feasibility::Line;
use crate::types::Input;

/// Number of variables (u₁, u₂, s).
const NV: usize = 3;

/// The most CBF rows a solver is built to hold all of: with more possible rows, the rows the
/// input box satisfies are left out (see the module documentation).
pub const COMPACT_CBF_ROWS: usize = 12;

/// CBF rows a solver is first built for when more than [`COMPACT_CBF_ROWS`] are possible.
/// Every unused row is an inactive `0·z ≤ 1` that each interior-point iteration still factors,
/// and with active barriers ([`crate::reach`]) only the rows near the robot reach the solver:
/// 4 (8 before) made the 200-disc control step 1.15× the 2-disc one instead of 1.5×
/// (`step_m2_clutter_*`, issue #52). A step with more rows that can bind grows it (doubling).
pub const COMPACT_START_ROWS: usize = 4;

/// The outcome of one QP solve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum QpResult {
    /// A solution (status Solved or AlmostSolved).
    Feasible {
        /// Optimal input.
        u: Input,
        /// Optimal slack (0 when no row is soft).
        slack: f64,
        /// Interior-point iterations.
        iterations: u32,
    },
    /// The hard rows (and the box) admit no input (PrimalInfeasible or AlmostPrimalInfeasible).
    Infeasible {
        /// Iterations spent.
        iterations: u32,
    },
    /// Neither a solution nor an infeasibility certificate (after one rebuild).
    SolverFailure {
        /// clarabel's status.
        status: SolverStatus,
    },
    /// More rows were passed than the solver was built for.
    TooManyRows {
        /// Rows passed (cbf, clf).
        given: (usize, usize),
        /// Capacity (cbf, clf).
        capacity: (usize, usize),
    },
}

/// Whether a group of rows is hard or soft.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RowMode {
    /// No slack: must hold exactly.
    Hard,
    /// Shares the slack s.
    Soft,
}

/// A reusable clarabel solver for problem 5.3.
pub struct QpSolver {
    /// CBF rows the current solver holds.
    cbf_capacity: usize,
    /// The most CBF rows a solve may be given.
    cbf_limit: usize,
    clf_capacity: usize,
    rows: usize,
    p_values: [f64; 4],
    p: CscMatrix<f64>,
    a_dense: Vec<f64>,
    a_values: Vec<f64>,
    b: Vec<f64>,
    q: Vec<f64>,
    input_limit: Option<Input>,
    /// The reference input u_ref of the cost (0 until [`QpSolver::set_reference`]).
    reference: Input,
    solver: Option<DefaultSolver<f64>>,
    last_x: [f64; NV],
    last_z: Vec<f64>,
    solves: u64,
    rebuilds: u64,
}

impl std::fmt::Debug for QpSolver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("QpSolver")
            .field("cbf_capacity", &self.cbf_capacity)
            .field("cbf_limit", &self.cbf_limit)
            .field("clf_capacity", &self.clf_capacity)
            .field("input_limit", &self.input_limit)
            .field("solves", &self.solves)
            .field("rebuilds", &self.rebuilds)
            .finish()
    }
}

fn settings() -> DefaultSettings<f64> {
    let mut s = DefaultSettingsBuilder::default()
        .build()
        .unwrap_or_default();
    s.verbose = false;
    s.presolve_enable = false;
    s.input_sparse_dropzeros = false;
    s.equilibrate_enable = false;
    s.max_iter = 100;
    s
}

impl QpSolver {
    /// A solver for up to `cbf_capacity` CBF rows and `clf_capacity` CLF rows, input cost
    /// `R` (symmetric positive definite), slack weight `w` and an optional symmetric input box
    /// `|u_k| ≤ limit_k`.
    pub fn new(
        cbf_capacity: usize,
        clf_capacity: usize,
        r: Matrix2<f64>,
        slack_weight: f64,
        input_limit: Option<Input>,
    ) -> Self {
        let cbf_limit = cbf_capacity;
        // Up to COMPACT_CBF_ROWS rows: room for all of them, as before. Beyond, rows are left
        // out anyway: start small, grow to what binds.
        let cbf_capacity = if cbf_limit <= COMPACT_CBF_ROWS {
            cbf_limit
        } else {
            COMPACT_START_ROWS
        };
        let rows = cbf_capacity + clf_capacity + 5;
        // P upper triangle, CSC: col0 (0,0); col1 (0,1),(1,1); col2 (2,2).
        let p_values = [
            2.0 * r[(0, 0)],
            2.0 * 0.5 * (r[(0, 1)] + r[(1, 0)]),
            2.0 * r[(1, 1)],
            2.0 * slack_weight,
        ];
        let p = CscMatrix::new(
            NV,
            NV,
            vec![0, 1, 3, 4],
            vec![0, 0, 1, 2],
            p_values.to_vec(),
        );
        Self {
            cbf_capacity,
            cbf_limit,
            clf_capacity,
            rows,
            p_values,
            p,
            a_dense: vec![0.0; rows * NV],
            a_values: vec![0.0; rows * NV],
            b: vec![1.0; rows],
            q: vec![0.0; NV],
            input_limit,
            reference: Input::zeros(),
            solver: None,
            last_x: [0.0; NV],
            last_z: vec![0.0; rows],
            solves: 0,
            rebuilds: 0,
        }
    }

    /// Total rows of the problem.
    pub fn rows(&self) -> usize {
        self.rows
    }
    /// The input box, if any.
    pub fn input_limit(&self) -> Option<Input> {
        self.input_limit
    }
    /// The reference input u_ref of the cost (0 for problem 5.3).
    pub fn reference(&self) -> Input {
        self.reference
    }

    /// Sets the reference input u_ref of the cost: from the next solve on the problem is
    /// `min (u − u_ref)ᵀR(u − u_ref) + w s²` (the safety-filter form; u_ref = 0 is problem 5.3).
    /// A non-finite reference is ignored (the previous one stays).
    pub fn set_reference(&mut self, u_ref: Input) {
        if !(u_ref[0].is_finite() && u_ref[1].is_finite()) {
            return;
        }
        self.reference = u_ref;
        // ½zᵀPz + qᵀz with P = 2R: q = −2R·u_ref = −P·u_ref.
        self.q[0] = -(self.p_values[0] * u_ref[0] + self.p_values[1] * u_ref[1]);
        self.q[1] = -(self.p_values[1] * u_ref[0] + self.p_values[2] * u_ref[1]);
    }

    /// Number of solves and of from-scratch builds so far.
    pub fn counters(&self) -> (u64, u64) {
        (self.solves, self.rebuilds)
    }

    fn set_row(&mut self, row: usize, h: &HalfSpace, soft: bool) {
        // the scaling shared with the geometric feasibility test
        let line = Line::from_half_space(h);
        let base = row * NV;
        self.a_dense[base] = line.a[0];
        self.a_dense[base + 1] = line.a[1];
        self.a_dense[base + 2] = if soft { -1.0 } else { 0.0 };
        self.b[row] = line.b;
    }

    fn set_inactive(&mut self, row: usize) {
        let base = row * NV;
        self.a_dense[base..base + NV]
            .iter_mut()
            .for_each(|v| *v = 0.0);
        self.b[row] = 1.0;
    }

    /// Solve `min (u − u_ref)ᵀR(u − u_ref) + w s²` (u_ref from [`QpSolver::set_reference`],
    /// zero by default) s.t. the CBF rows, CLF rows (each group hard or soft), the box.
    pub fn solve(
        &mut self,
        cbf: &[HalfSpace],
        cbf_mode: RowMode,
        clf: &[HalfSpace],
        clf_mode: RowMode,
    ) -> QpResult {
        if cbf.len() > self.cbf_limit || clf.len() > self.clf_capacity {
            return QpResult::TooManyRows {
                given: (cbf.len(), clf.len()),
                capacity: (self.cbf_limit, self.clf_capacity),
            };
        }
        // More rows than the solver holds: leave out those the input box satisfies.
        let compact = cbf.len() > self.cbf_capacity;
        let needed = if compact {
            cbf.iter().filter(|h| !self.box_satisfies(h)).count()
        } else {
            cbf.len()
        };
        if needed > self.cbf_capacity {
            self.grow(needed);
        }
        let mut r = 0;
        for h in cbf {
            if compact && self.box_satisfies(h) {
                continue;
            }
            self.set_row(r, h, cbf_mode == RowMode::Soft);
            r += 1;
        }
        for r in r..self.cbf_capacity {
            self.set_inactive(r);
        }
        for r in 0..self.clf_capacity {
            let row = self.cbf_capacity + r;
            match clf.get(r) {
                Some(h) => self.set_row(row, h, clf_mode == RowMode::Soft),
                None => self.set_inactive(row),
            }
        }
        let box_row = self.cbf_capacity + self.clf_capacity;
        for k in 0..4 {
            let row = box_row + k;
            match self.input_limit {
                Some(lim) => {
                    let base = row * NV;
                    let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
                    self.a_dense[base] = if k / 2 == 0 { sign } else { 0.0 };
                    self.a_dense[base + 1] = if k / 2 == 1 { sign } else { 0.0 };
                    self.a_dense[base + 2] = 0.0;
                    self.b[row] = lim[k / 2];
                }
                None => self.set_inactive(row),
            }
        }
        let srow = box_row + 4;
        let base = srow * NV;
        self.a_dense[base] = 0.0;
        self.a_dense[base + 1] = 0.0;
        self.a_dense[base + 2] = -1.0;
        self.b[srow] = 0.0;
        // dense row-major → CSC column-major values
        for c in 0..NV {
            for r in 0..self.rows {
                self.a_values[c * self.rows + r] = self.a_dense[r * NV + c];
            }
        }
        self.solves += 1;
        if let Some(s) = self.solver.as_mut() {
            if s.update_A(&self.a_values).is_ok()
                && s.update_b(&self.b).is_ok()
                && s.update_q(&self.q).is_ok()
            {
                if let Ok(r) = self.run() {
                    return r;
                }
            }
        }
        // Build from scratch: first solve, rejected update, or an inconclusive reused solve.
        if !self.build() {
            return QpResult::SolverFailure {
                status: SolverStatus::NumericalError,
            };
        }
        match self.run() {
            Ok(r) => r,
            Err(status) => {
                self.solver = None;
                QpResult::SolverFailure { status }
            }
        }
    }

    /// Whether every input of the box (and any slack s ≥ 0) satisfies `h`: `nᵀu ≤ o` for all
    /// `|u_k| ≤ L_k`, i.e. `|n₁|L₁ + |n₂|L₂ < o`, with a relative margin of 1e-12 against
    /// rounding. Never for a non-finite row (it must stay, and fail closed) or without a box.
    pub fn box_satisfies(&self, h: &HalfSpace) -> bool {
        let Some(lim) = self.input_limit else {
            return false;
        };
        let reach = h.normal[0].abs() * lim[0] + h.normal[1].abs() * lim[1];
        let margin = 1e-12 * (reach.abs() + h.offset.abs());
        reach.is_finite() && h.offset.is_finite() && reach + margin < h.offset
    }

    /// Rebuilds the buffers for at least `needed` CBF rows (doubling, at most the limit); the
    /// solver is built anew on the next solve.
    fn grow(&mut self, needed: usize) {
        let mut cap = self.cbf_capacity.max(1);
        while cap < needed {
            cap *= 2;
        }
        self.cbf_capacity = cap.min(self.cbf_limit);
        self.rows = self.cbf_capacity + self.clf_capacity + 5;
        self.a_dense = vec![0.0; self.rows * NV];
        self.a_values = vec![0.0; self.rows * NV];
        self.b = vec![1.0; self.rows];
        self.last_z = vec![0.0; self.rows];
        self.solver = None;
    }

    fn build(&mut self) -> bool {
        self.rebuilds += 1;
        let rowval: Vec<usize> = (0..NV).flat_map(|_| 0..self.rows).collect();
        let colptr: Vec<usize> = (0..=NV).map(|c| c * self.rows).collect();
        let a = CscMatrix::new(self.rows, NV, colptr, rowval, self.a_values.clone());
        self.p.nzval.copy_from_slice(&self.p_values);
        let cones = [SupportedConeT::NonnegativeConeT(self.rows)];
        match DefaultSolver::new(&self.p, &self.q, &a, &self.b, &cones, settings()) {
            Ok(s) => {
                self.solver = Some(s);
                true
            }
            Err(_) => {
                self.solver = None;
                false
            }
        }
    }

    /// Solve with the current solver; `Err(status)` when the status is inconclusive.
    fn run(&mut self) -> Result<QpResult, SolverStatus> {
        let Some(s) = self.solver.as_mut() else {
            return Err(SolverStatus::Unsolved);
        };
        s.solve();
        let sol = &s.solution;
        match sol.status {
            SolverStatus::Solved | SolverStatus::AlmostSolved
                if sol.x.iter().all(|v| v.is_finite()) =>
            {
                self.last_x.copy_from_slice(&sol.x[..NV]);
                self.last_z.copy_from_slice(&sol.z[..self.rows]);
                Ok(QpResult::Feasible {
                    u: Input::new(sol.x[0], sol.x[1]),
                    slack: sol.x[2].max(0.0),
                    iterations: sol.iterations,
                })
            }
            SolverStatus::PrimalInfeasible | SolverStatus::AlmostPrimalInfeasible => {
                Ok(QpResult::Infeasible {
                    iterations: sol.iterations,
                })
            }
            status => Err(status),
        }
    }

    /// The last problem's rows (scaled), row-major `rows × 3` over (u₁, u₂, s).
    pub fn last_rows(&self) -> (&[f64], &[f64]) {
        (&self.a_dense, &self.b)
    }
    /// The last feasible primal (u₁, u₂, s) and dual (one per row) solution.
    pub fn last_primal_dual(&self) -> (&[f64; NV], &[f64]) {
        (&self.last_x, &self.last_z)
    }
    /// P values (upper triangle: P₀₀, P₀₁, P₁₁, P₂₂).
    pub fn cost_diagonal(&self) -> [f64; 4] {
        self.p_values
    }
}
