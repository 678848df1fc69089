//! The parameters the controller takes (γ_i, θ_ij, η_ij, W_ij) and their computation by §4.3.

use std::fmt;

use crate::model::LinearModel;
use crate::types::StateMatrix;

use super::*;

/// How [`FtComputed`] bounds the estimation errors.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BoundMethod {
    /// The paper's §4.3: γ from the steady-state covariance (a finite-horizon covariance from
    /// P0 where no steady state exists), θ_ij/2 = max(γ_i, γ_j) + γ_ij (triangle inequality).
    Paper,
    /// Over the run's horizon from the declared P0: γ_i from the largest covariance filter i
    /// reaches in `horizon_samples` steps (steady state included when it exists), and θ_ij from
    /// the covariance of the solution separation, `Cov(x̂_i − x̂_ij) = P_ij − P_i` when fault
    /// r_i occurs (both filters optimal for the same model, x̂_ij uses a subset of x̂_i's
    /// channels): θ_ij/2 = max over i, j of `sqrt(λ̄(P_ij − P_i) χ²₄⁻¹(1 − ε'))`.
    Horizon,
}

/// The parameters the controller's conditions are stated with (§4.3): γ_i, γ of the
/// all-channel filter, θ_ij, and Step 2's increment test (η_ij with its norm W_ij) and θ_ij(t).
/// One type wherever they are held: computed ([`FtComputed::ft`], with its
/// [`FtDerivation`] beside) and handed to the controller ([`crate::ControllerConfig::ft`], where
/// the simulator keeps the values in force for a world).
///
/// Per-pair lists are in the packed order of [`PairTable`] ((0,1), (0,2), …, (1,2), …); `theta`,
/// `eta` and `increment_metric` may instead hold one value for every pair.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct FtParams {
    /// γ_i per fault pattern: the bound on ‖x̂_i − x‖ of the filter that drops pattern i \[m, m/s\].
    pub gamma: Vec<f64>,
    /// γ of the all-channel filter (baseline and nominal controllers).
    pub gamma_baseline: f64,
    /// θ_ij: one value for all pairs, or C(m,2) values (empty when m < 2).
    pub theta: Vec<f64>,
    /// η_ij of Step 2's increment test, same layout as `theta`: η_ij/2 bounds how far x̂_a and
    /// x̂_ij of a fault-free a move apart over [`STEP2_WINDOW`] (empty: no increment test, the
    /// paper's Step 2).
    pub eta: Vec<f64>,
    /// W_ij of the increment test, same layout as `eta`: the increment is measured in the norm
    /// ‖z‖_W = √(zᵀ W z), W = C̄⁻¹ for a fixed C̄ that covers every increment covariance of the
    /// horizon up to the factor folded into η_ij (see [`increment_metric`]); empty: the
    /// Euclidean norm, W = I. Each must be symmetric positive semidefinite.
    pub increment_metric: Vec<StateMatrix>,
    /// θ_ij(t) over the horizon (the horizon bound method only): the same quantile of the
    /// solution separation's covariance at each step, not only at its worst. The pair filter's
    /// dead-reckoned error grows over the run, so θ_ij(t) is much tighter early on; it never
    /// exceeds `theta` (its last value), so condition 1 still holds with θ_ij. None: θ_ij
    /// throughout.
    pub theta_schedule: Option<ThetaSchedule>,
}

impl FtParams {
    /// Given values: γ for all `patterns` filters and the all-channel one, one θ for every pair,
    /// no increment test and no θ_ij(t) (a world file's `gamma = g`, `theta = t`).
    pub fn uniform(patterns: usize, gamma: f64, theta: f64) -> Self {
        Self {
            gamma: vec![gamma; patterns],
            gamma_baseline: gamma,
            theta: vec![theta],
            ..Self::default()
        }
    }

    /// The value of a per-pair list (one value for all, or one per pair in packed order) for
    /// the pair (i, j), i ≠ j, of `m` patterns; None when the list is empty or too short.
    pub fn per_pair<T: Copy>(values: &[T], m: usize, i: usize, j: usize) -> Option<T> {
        match values {
            [] => None,
            [one] => Some(*one),
            many => many.get(pair_slot(m, i, j)?).copied(),
        }
    }
}

/// γ_i, γ_ij and θ_ij computed for a model, patterns, sampling period, ε and horizon
/// ([`FtComputed::compute_scheduled`]): the parameters, and how they were obtained.
#[derive(Debug, Clone, PartialEq)]
pub struct FtComputed {
    /// The parameters the controller takes: γ_i per pattern, γ of the baseline (all channels)
    /// at the same per-sample ε', θ_ij per pair, and for [`BoundMethod::Horizon`] η_ij, W_ij
    /// and θ_ij(t) (empty/None for [`BoundMethod::Paper`]: the paper's Step 2 has no increment
    /// test).
    pub ft: FtParams,
    /// How they were obtained.
    pub derivation: FtDerivation,
}

/// How [`FtComputed::compute_scheduled`] obtained its [`FtParams`] (§4.3): the pair filters'
/// γ_ij, the triangle bound, ε', the Riccati recursions. It holds none of the parameters
/// themselves, so a report keeps them in one place (the parameters in force) and this beside.
#[derive(Debug, Clone, PartialEq)]
pub struct FtDerivation {
    /// γ_ij per pair in packed order ([`PairTable`]).
    pub gamma_pair: Vec<f64>,
    /// The §4.3 triangle bound 2(max(γ_i, γ_j) + γ_ij) in the same order (equal to
    /// [`FtParams::theta`] for [`BoundMethod::Paper`]).
    pub theta_triangle: Vec<f64>,
    /// Per-sample, per-event ε' = ε/(N m).
    pub eps_per_sample: f64,
    /// Riccati iterations per filter (singles, pairs, baseline).
    pub riccati_iterations: Vec<usize>,
    /// Whether every Riccati recursion converged (false: a pair filter without a steady state,
    /// whose γ_ij then comes from its covariance over the horizon).
    pub all_converged: bool,
    /// Whether each Riccati recursion reached a steady state, in the order of
    /// `riccati_iterations`.
    pub riccati_converged: Vec<bool>,
    /// Number of fault patterns (the single filters; the pairs follow them, then the baseline).
    pub patterns: usize,
    /// The method used.
    pub method: BoundMethod,
}

/// θ_ij(t) of Step 2 as a table: `theta[pair][k]` holds after k + 1 steps of `dt` (pairs in
/// the order of [`FtParams::theta`]); non-decreasing in k, and held at its last value past
/// the horizon.
#[derive(Debug, Clone, PartialEq)]
pub struct ThetaSchedule {
    /// Step of the table \[s\].
    pub dt: f64,
    /// Per pair, θ_ij after each step.
    pub theta: Vec<Vec<f64>>,
}

impl ThetaSchedule {
    /// θ of pair `pair` after `elapsed` seconds (the first entry before the first step).
    pub fn at(&self, pair: usize, elapsed: f64) -> Option<f64> {
        let row = self.theta.get(pair)?;
        let k = ((elapsed / self.dt).round().max(1.0) as usize - 1).min(row.len().checked_sub(1)?);
        row.get(k).copied()
    }
}

/// Length of the window of Step 2's increment test \[s\]: how far x̂_a and x̂_ij moved apart over
/// the last second.
pub const STEP2_WINDOW: f64 = 1.0;

impl FtComputed {
    /// Compute for total failure probability `eps` over `horizon_samples` samples, for filters
    /// started from a known state (P0 = 0) whose channels all update every step, by the paper's
    /// method. See [`FtComputed::compute_scheduled`].
    pub fn compute(
        model: &LinearModel,
        patterns: &[Vec<usize>],
        dt: f64,
        eps: f64,
        horizon_samples: usize,
    ) -> Self {
        Self::compute_scheduled(
            model,
            patterns,
            dt,
            eps,
            horizon_samples,
            &StateMatrix::zeros(),
            BoundMethod::Paper,
            &UpdateSchedule::every_step(),
        )
    }

    /// Compute for total failure probability `eps` over `horizon_samples` samples from the
    /// initial covariance `p0`, by `method` (see [`BoundMethod`]), for channels that update on
    /// `updates` ([`UpdateSchedule::every_step`]: the paper's setting; else a sensor slower than
    /// the control rate, or its longest gap under dropouts). Every Riccati recursion behind γ, θ
    /// and η is the periodic one ([`periodic_riccati`], [`horizon_riccati_from`],
    /// [`separation_moments_scheduled`]) and each bound takes its worst phase. A filter without
    /// a steady state (its channels leave a direction undetectable, e.g. two GNSS patterns
    /// dropped leave only odometry) uses the largest covariance it reaches within the horizon
    /// from `p0` ([`horizon_riccati`]), so γ and θ stay finite over the run.
    #[allow(clippy::too_many_arguments)]
    pub fn compute_scheduled(
        model: &LinearModel,
        patterns: &[Vec<usize>],
        dt: f64,
        eps: f64,
        horizon_samples: usize,
        p0: &StateMatrix,
        method: BoundMethod,
        updates: &UpdateSchedule,
    ) -> Self {
        let q = model.channels();
        let m = patterns.len().max(1);
        let n = horizon_samples.max(1);
        // Events per sample for fault r_i: ‖x̂_i − x‖ > γ_i, and per other pattern j the
        // absolute (and, for the horizon method, the increment) separation test.
        let events = match method {
            BoundMethod::Paper => m,
            BoundMethod::Horizon => 2 * m - 1,
        };
        let eps1 = eps / (n as f64 * events as f64);
        let mask = |drop: &[&Vec<usize>]| kept_channels(q, drop);
        let lmax = |p: &StateMatrix| ((p + p.transpose()) * 0.5).symmetric_eigenvalues().max();
        let mut iterations = Vec::new();
        let mut converged = Vec::new();
        let mut all_converged = true;
        // γ of one channel set: steady state (paper) or the worst of steady state and horizon.
        let mut gamma_of = |uses: &[bool], iterations: &mut Vec<usize>| -> f64 {
            let phases = updates.phases(uses);
            let s = periodic_riccati(model, &phases, dt);
            iterations.push(s.iterations);
            converged.push(s.converged);
            all_converged &= s.converged;
            let horizon = || horizon_riccati_from(model, &phases, 0, dt, p0, n);
            match (method, s.converged) {
                (BoundMethod::Paper, true) => gamma_bound(&s.posterior, eps1),
                (_, false) => gamma_bound(&horizon(), eps1),
                (BoundMethod::Horizon, true) => {
                    let h = horizon();
                    let worst = if lmax(&h) > lmax(&s.posterior) {
                        h
                    } else {
                        s.posterior
                    };
                    gamma_bound(&worst, eps1)
                }
            }
        };
        let gamma: Vec<f64> = patterns
            .iter()
            .map(|p| gamma_of(&mask(&[p]), &mut iterations))
            .collect();
        let mut gamma_pair = Vec::new();
        let mut theta = Vec::new();
        let mut theta_triangle = Vec::new();
        let mut eta = Vec::new();
        let mut metrics = Vec::new();
        let mut schedule = Vec::new();
        let separation = HorizonSeparation {
            model,
            updates,
            dt,
            p0,
            n,
            w: ((STEP2_WINDOW / dt).round() as usize).max(1),
            eps1,
        };
        for i in 0..patterns.len() {
            for j in (i + 1)..patterns.len() {
                let pair = mask(&[&patterns[i], &patterns[j]]);
                let gp = gamma_of(&pair, &mut iterations);
                gamma_pair.push(gp);
                let tri = 2.0 * (gamma[i].max(gamma[j]) + gp);
                theta_triangle.push(tri);
                match method {
                    BoundMethod::Paper => theta.push(tri),
                    BoundMethod::Horizon => {
                        let (th, row, e, metric) =
                            separation.pair(&mask(&[&patterns[i]]), &mask(&[&patterns[j]]), &pair);
                        theta.push(th);
                        schedule.push(row);
                        eta.push(e);
                        metrics.push(metric);
                    }
                }
            }
        }
        let gamma_baseline = gamma_of(&vec![true; q], &mut iterations);
        Self {
            ft: FtParams {
                gamma,
                gamma_baseline,
                theta,
                eta,
                increment_metric: metrics,
                theta_schedule: match method {
                    BoundMethod::Paper => None,
                    BoundMethod::Horizon => Some(ThetaSchedule {
                        dt,
                        theta: schedule,
                    }),
                },
            },
            derivation: FtDerivation {
                gamma_pair,
                theta_triangle,
                eps_per_sample: eps1,
                riccati_iterations: iterations,
                all_converged,
                riccati_converged: converged,
                patterns: patterns.len(),
                method,
            },
        }
    }
}

/// Which of `q` channels a filter keeps when the patterns `drop` are dropped.
fn kept_channels(q: usize, drop: &[&Vec<usize>]) -> Vec<bool> {
    let mut u = vec![true; q];
    for p in drop {
        for &c in p.iter() {
            if c < q {
                u[c] = false;
            }
        }
    }
    u
}

/// The horizon method's bounds on one pair of patterns, from the separation moments of each
/// single-drop filter against the pair filter (issue #45 split this out of
/// [`FtComputed::compute_scheduled`]; the arithmetic is unchanged).
struct HorizonSeparation<'a> {
    model: &'a LinearModel,
    updates: &'a UpdateSchedule,
    dt: f64,
    p0: &'a StateMatrix,
    /// Horizon in samples.
    n: usize,
    /// Step 2's window in samples.
    w: usize,
    /// Per-sample failure probability.
    eps1: f64,
}

impl HorizonSeparation<'_> {
    /// (θ_ij, θ_ij's schedule over the horizon, η_ij, the increment metric) of the filters
    /// using `single_i`, `single_j` and `pair` (channel masks).
    fn pair(
        &self,
        single_i: &[bool],
        single_j: &[bool],
        pair: &[bool],
    ) -> (f64, Vec<f64>, f64, StateMatrix) {
        let chi = chi_square_quantile(4, 1.0 - self.eps1);
        let pair_phases = self.updates.phases(pair);
        let sep = |single: &[bool]| {
            separation_moments_scheduled(
                self.model,
                &self.updates.phases(single),
                &pair_phases,
                self.dt,
                self.p0,
                self.n,
                self.w,
            )
        };
        let si = sep(single_i);
        let sj = sep(single_j);
        let theta = 2.0 * (si.worst_abs.max(sj.worst_abs).max(0.0) * chi).sqrt();
        let mut running = 0.0f64;
        let schedule = si
            .absolute
            .iter()
            .zip(&sj.absolute)
            .map(|(a, b)| {
                running = running.max(*a).max(*b).max(0.0);
                2.0 * (running * chi).sqrt()
            })
            .collect::<Vec<f64>>();
        let (metric, scale) = increment_metric(&si.increments, &sj.increments);
        (theta, schedule, 2.0 * (scale * chi).sqrt(), metric)
    }
}

impl fmt::Display for FtComputed {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.derivation.write_report(f, &self.ft)
    }
}

impl FtDerivation {
    /// The report of parameters `ft` obtained this way: ε', γ_i, the baseline's γ, per pair γ_ij
    /// and θ_ij (with the triangle bound and η_ij for the horizon method), the Riccati line.
    /// A θ or η given as one value for all pairs is shown for each pair.
    pub fn report(&self, ft: &FtParams) -> String {
        let mut out = String::new();
        self.write_report(&mut out, ft)
            .expect("writing to a String cannot fail");
        out
    }

    fn write_report(&self, f: &mut impl fmt::Write, ft: &FtParams) -> fmt::Result {
        let per_pair = |values: &[f64], k: usize| match values {
            [one] => Some(*one),
            many => many.get(k).copied(),
        };
        writeln!(f, "per-sample epsilon' = {:.3e}", self.eps_per_sample)?;
        for (i, g) in ft.gamma.iter().enumerate() {
            writeln!(f, "gamma_{} = {:.6}", i + 1, g)?;
        }
        writeln!(f, "gamma_baseline = {:.6}", ft.gamma_baseline)?;
        for (k, (g, tri)) in self.gamma_pair.iter().zip(&self.theta_triangle).enumerate() {
            let Some(t) = per_pair(&ft.theta, k) else {
                break;
            };
            match self.method {
                BoundMethod::Paper => {
                    writeln!(f, "pair {k}: gamma_ij = {g:.6}, theta_ij = {t:.6}")?
                }
                BoundMethod::Horizon => writeln!(
                    f,
                    "pair {k}: gamma_ij = {g:.6}, theta_ij = {t:.6} (solution separation; the triangle bound of §4.3 would be {tri:.6}), eta_ij = {:.6} (separation increment over {STEP2_WINDOW} s, in the covariance-weighted norm ‖z‖_W)",
                    per_pair(&ft.eta, k).unwrap_or(f64::NAN)
                )?,
            }
        }
        write!(f, "{}", self.riccati_line())
    }
}

impl FtDerivation {
    /// The filter a Riccati recursion belongs to, by its index in `riccati_iterations`:
    /// `filter 2` (pattern 2 dropped), `pair (1, 2)`, `baseline`.
    fn filter_name(&self, k: usize) -> String {
        let m = self.patterns;
        if k < m {
            return format!("filter {}", k + 1);
        }
        let mut idx = m;
        for i in 0..m {
            for j in (i + 1)..m {
                if idx == k {
                    return format!("pair ({}, {})", i + 1, j + 1);
                }
                idx += 1;
            }
        }
        "baseline".to_string()
    }

    /// The Riccati recursions in words: how many reach a steady state, which do not, and why
    /// that is expected (their bounds come from the covariance over the horizon).
    pub fn riccati_line(&self) -> String {
        let n = self.riccati_iterations.len();
        let steady = self.riccati_converged.iter().filter(|c| **c).count();
        let head = format!(
            "Riccati recursions (one per filter: singles, pairs, baseline; iterations {:?})",
            self.riccati_iterations
        );
        if steady == n {
            return format!("{head}: all {n} reach a steady state, which the bounds use");
        }
        let without: Vec<String> = (0..n)
            .filter(|k| !self.riccati_converged.get(*k).copied().unwrap_or(true))
            .map(|k| self.filter_name(k))
            .collect();
        format!(
            "{head}: {steady} of {n} reach a steady state; no steady state for {} (the channels \
             that filter keeps do not observe the whole state, e.g. a pair filter left with \
             odometry only). Expected, not a fault: such a filter's bounds come from the largest \
             covariance it reaches over the run's horizon instead, finite and valid for the \
             run's length",
            without.join(", "),
        )
    }
}
