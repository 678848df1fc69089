//! Parameter computation of §4.3 and checks of the sufficient conditions of §4.2.
//!
//! * γ_i: the estimation error of filter i at steady state is Gaussian, `e ~ N(0, P)`, with
//!   P the steady-state posterior covariance of the discrete Riccati recursion
//!   ([`steady_state_riccati`], iterated to convergence). Since `‖e‖² ≤ λ̄(P) eᵀP⁻¹e` and
//!   `eᵀP⁻¹e ~ χ²_n`, `γ = sqrt(λ̄(P) · χ²_n⁻¹(1 − ε'))` gives `Pr(‖e‖ > γ) ≤ ε'` at one
//!   sample ([`gamma_bound`]).
//! * The whole-horizon event of (4.5) is bounded by a union bound: for N samples and the
//!   m events per sample (filter i and the m − 1 pair filters x̂_ij), `ε' = ε/(N m)`.
//! * θ_ij: `‖x̂_i − x̂_ij‖ ≤ ‖x̂_i − x‖ + ‖x̂_ij − x‖ ≤ γ_i + γ_ij`, so θ_ij/2 =
//!   max(γ_i, γ_j) + γ_ij makes the Step-2 test of the fault-free filter pass on that event.
//! * χ² quantiles, the regularised incomplete gamma function and log-gamma come from `statrs`
//!   (thin wrappers here keep the NaN conventions the callers rely on).

use std::fmt;

use nalgebra::RowVector4;

use crate::model::LinearModel;
use crate::types::{Input, InputMatrix, State, StateMatrix};

// ------------------------------------------------------------------------------------------
// Special functions (statrs)
// ------------------------------------------------------------------------------------------

/// ln Γ(x) for x > 0 (statrs' Lanczos approximation); NaN for x ≤ 0 or NaN. The project's one
/// log-gamma: the batch statistics use it too.
pub fn ln_gamma(x: f64) -> f64 {
    if x.is_nan() || x <= 0.0 {
        return f64::NAN;
    }
    statrs::function::gamma::ln_gamma(x)
}

/// Regularised lower incomplete gamma P(a, x) = γ(a, x)/Γ(a), a > 0, x ≥ 0 (NaN for a ≤ 0 or
/// NaN arguments; 0 for x ≤ 0; 1 for x = ∞).
pub fn regularized_gamma_p(a: f64, x: f64) -> f64 {
    if a.is_nan() || a <= 0.0 || x.is_nan() {
        return f64::NAN;
    }
    if x <= 0.0 {
        return 0.0;
    }
    if x.is_infinite() {
        return 1.0;
    }
    statrs::function::gamma::gamma_lr(a, x).clamp(0.0, 1.0)
}

/// χ² cumulative distribution with `k` degrees of freedom.
pub fn chi_square_cdf(k: u32, x: f64) -> f64 {
    regularized_gamma_p(k as f64 / 2.0, x / 2.0)
}

/// χ² quantile: the x with `chi_square_cdf(k, x) = p`, for 0 < p < 1 (NaN otherwise, and for
/// k = 0), from statrs' χ² distribution.
pub fn chi_square_quantile(k: u32, p: f64) -> f64 {
    use statrs::distribution::{ChiSquared, ContinuousCDF};
    if k == 0 || !(p > 0.0 && p < 1.0) {
        return f64::NAN;
    }
    match ChiSquared::new(f64::from(k)) {
        Ok(d) => d.inverse_cdf(p),
        Err(_) => f64::NAN,
    }
}

// ------------------------------------------------------------------------------------------
// Riccati and γ, θ
// ------------------------------------------------------------------------------------------

/// Steady state of the discrete Kalman Riccati recursion for a channel subset.
#[derive(Debug, Clone, PartialEq)]
pub struct RiccatiSolution {
    /// Prior covariance P⁻.
    pub prior: StateMatrix,
    /// Posterior covariance P⁺.
    pub posterior: StateMatrix,
    /// Iterations used.
    pub iterations: usize,
    /// Whether the relative change fell below the tolerance.
    pub converged: bool,
}

/// One step of the Riccati recursion: predict P⁻ = ΦP⁺Φᵀ + Q_d, then the sequential (Joseph
/// form) updates of the channels where `uses[k]`. Returns (P⁻, P⁺).
fn riccati_step(
    model: &LinearModel,
    uses: &[bool],
    d: &crate::model::Discretization,
    post: &StateMatrix,
) -> (StateMatrix, StateMatrix) {
    let prior = d.phi * post * d.phi.transpose() + d.qd;
    let mut p = prior;
    for (k, &u) in uses.iter().enumerate() {
        if !u || k >= model.channels() {
            continue;
        }
        let (kg, ikc) = scalar_gain(model, k, &p);
        p = joseph(model, k, &p, &kg, &ikc);
    }
    (prior, p)
}

/// The sequential scalar updates one filter step applies with the channels where `uses[k]`,
/// starting from the prior covariance `prior`: `(k, K_k, I − K_k c_k)` in update order.
///
/// At a steady-state prior ([`RiccatiSolution::prior`]) these gains are the same every step,
/// so the estimate responds linearly to an offset `d` added to its readings: after `e ← Φ e`,
/// `e ← (I − K_k c_k) e + K_k d_k` for each update. That is how far an attack on the readings
/// moves the estimate, whatever the state and the input.
pub fn update_gains(
    model: &LinearModel,
    uses: &[bool],
    prior: &StateMatrix,
) -> Vec<(usize, State, StateMatrix)> {
    let mut p = *prior;
    let mut out = Vec::new();
    for (k, &u) in uses.iter().enumerate() {
        if !u || k >= model.channels() {
            continue;
        }
        let (kg, ikc) = scalar_gain(model, k, &p);
        p = joseph(model, k, &p, &kg, &ikc);
        out.push((k, kg, ikc));
    }
    out
}

/// The gain K = P cᵀ/(c P cᵀ + r) of a scalar update with channel `k`, and I − K c.
fn scalar_gain(model: &LinearModel, k: usize, p: &StateMatrix) -> (State, StateMatrix) {
    let c: RowVector4<f64> = model.c[k];
    let pc = p * c.transpose();
    let s = (c * pc)[0] + model.r[k];
    let kg = pc / s;
    (kg, StateMatrix::identity() - kg * c)
}

/// The Joseph-form posterior (I − Kc) P (I − Kc)ᵀ + K r Kᵀ, symmetrised.
fn joseph(
    model: &LinearModel,
    k: usize,
    p: &StateMatrix,
    kg: &State,
    ikc: &StateMatrix,
) -> StateMatrix {
    let p = ikc * p * ikc.transpose() + kg * kg.transpose() * model.r[k];
    (p + p.transpose()) * 0.5
}

/// The longest joint period [`UpdateSchedule::phases`] unrolls; a schedule whose periods have a
/// longer least common multiple is coarsened (every channel updates every `max(every)` steps, all
/// at once: fewer updates, so a larger covariance).
pub const MAX_SCHEDULE_PERIOD: usize = 10_000;

/// When each channel updates, in filter steps: channel k at the steps s (s = 0, 1, … from the
/// start) with `s % every[k] == 0`; `every[k] = 0`: never; a missing entry: every step. A sensor
/// at rate r sampled with the control period dt has `every = ⌈1/(r·dt)⌉`; the worst case over a
/// run with dropouts stretches it to the longest gap the run's ε budget allows (the caller's
/// choice, see `ftcbf_sim`'s setup). The Riccati recursions with a schedule are periodic
/// (time-varying); γ and θ take their worst phase.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct UpdateSchedule {
    /// Steps between updates per channel (0: never).
    pub every: Vec<usize>,
}

impl UpdateSchedule {
    /// Every channel every step (the paper's setting; the recursions are then exactly the
    /// time-invariant ones).
    pub fn every_step() -> Self {
        Self { every: Vec::new() }
    }

    /// Steps between updates of channel `k` (0: never).
    pub fn of(&self, k: usize) -> usize {
        self.every.get(k).copied().unwrap_or(1)
    }

    /// The channel masks of one period for a filter that uses the channels where `uses[k]`:
    /// entry s holds the channels that update at steps ≡ s (mod the period). One entry when every
    /// used channel updates every step. The period is the least common multiple of the used
    /// channels' `every` (coarsened above [`MAX_SCHEDULE_PERIOD`]).
    pub fn phases(&self, uses: &[bool]) -> Vec<Vec<bool>> {
        fn gcd(a: usize, b: usize) -> usize {
            if b == 0 {
                a
            } else {
                gcd(b, a % b)
            }
        }
        let used: Vec<usize> = (0..uses.len())
            .filter(|&k| uses[k])
            .map(|k| self.of(k))
            .filter(|&e| e > 0)
            .collect();
        let mut period = 1usize;
        let mut coarse = false;
        for &e in &used {
            period = period / gcd(period, e) * e;
            if period > MAX_SCHEDULE_PERIOD {
                coarse = true;
                break;
            }
        }
        let longest = used.iter().copied().max().unwrap_or(1);
        if coarse {
            period = longest;
        }
        (0..period)
            .map(|s| {
                (0..uses.len())
                    .map(|k| {
                        let e = if coarse && self.of(k) > 0 {
                            longest
                        } else {
                            self.of(k)
                        };
                        uses[k] && e > 0 && s % e == 0
                    })
                    .collect()
            })
            .collect()
    }
}

/// The channels any phase uses.
fn union_of(phases: &[Vec<bool>]) -> Vec<bool> {
    let q = phases.iter().map(Vec::len).max().unwrap_or(0);
    (0..q)
        .map(|k| phases.iter().any(|p| p.get(k).copied().unwrap_or(false)))
        .collect()
}

/// Iterate predict (Φ, Q_d at `dt`) + update with the channels where `uses[k]` until the
/// relative change of P⁺ is below 1e-13 (max 1e6 iterations). A channel set that does not
/// make the state detectable (e.g. open loop) has no steady state: the recursion stops with
/// `converged = false` once P exceeds 1e12.
pub fn steady_state_riccati(model: &LinearModel, uses: &[bool], dt: f64) -> RiccatiSolution {
    periodic_riccati(model, &[uses.to_vec()], dt)
}

/// The periodic steady state of the Riccati recursion whose step s updates with the channels of
/// `phases[s % L]` ([`UpdateSchedule::phases`]): iterated period by period until P⁺ at the
/// period's end changes by less than 1e-13 (relative; at most 1e6 steps), then the phase with
/// the largest λ̄(P⁺) of one more period is returned (its P⁻ and P⁺; `iterations` counts periods).
/// With one phase this is [`steady_state_riccati`]. Observability is decided on the channels any
/// phase uses.
pub fn periodic_riccati(model: &LinearModel, phases: &[Vec<bool>], dt: f64) -> RiccatiSolution {
    let d = model.discretize(dt);
    let union = union_of(phases);
    if phases.is_empty() || !observable(model, &union, &d.phi) {
        // Every eigenvalue of Φ lies on the unit circle for the double integrator, so an
        // unobservable channel set is undetectable: P grows without bound; no need to iterate.
        let p = StateMatrix::identity() * f64::INFINITY;
        return RiccatiSolution {
            prior: p,
            posterior: p,
            iterations: 0,
            converged: false,
        };
    }
    let mut post = StateMatrix::identity();
    let mut prior = post;
    let max_iter = (1_000_000 / phases.len()).max(1);
    let lmax = |p: &StateMatrix| p.symmetric_eigenvalues().max();
    for it in 1..=max_iter {
        let start = post;
        let mut p = post;
        for uses in phases {
            (prior, p) = riccati_step(model, uses, &d, &p);
        }
        let change = (p - start).amax() / p.amax().max(1e-300);
        post = p;
        if change < 1e-13 {
            if phases.len() > 1 {
                // The worst phase of one more period from the periodic steady state.
                let (mut worst_prior, mut worst) = (prior, post);
                let mut p = post;
                for uses in phases {
                    let pr;
                    (pr, p) = riccati_step(model, uses, &d, &p);
                    if lmax(&p) > lmax(&worst) {
                        (worst_prior, worst) = (pr, p);
                    }
                }
                (prior, post) = (worst_prior, worst);
            }
            return RiccatiSolution {
                prior,
                posterior: post,
                iterations: it,
                converged: true,
            };
        }
        if !post.amax().is_finite() || post.amax() > 1e12 {
            return RiccatiSolution {
                prior,
                posterior: post,
                iterations: it,
                converged: false,
            };
        }
    }
    RiccatiSolution {
        prior,
        posterior: post,
        iterations: max_iter,
        converged: false,
    }
}

/// Whether (Φ, C̄) is observable, C̄ = the rows of the channels where `uses[k]`: the stacked
/// matrix [C̄; C̄Φ; C̄Φ²; C̄Φ³] has rank 4 (singular values above 1e-9 of the largest).
pub fn observable(model: &LinearModel, uses: &[bool], phi: &StateMatrix) -> bool {
    let rows: Vec<RowVector4<f64>> = (0..model.channels())
        .filter(|&k| uses.get(k).copied().unwrap_or(false))
        .map(|k| model.c[k])
        .collect();
    if rows.is_empty() {
        return false;
    }
    let mut o = nalgebra::DMatrix::<f64>::zeros(4 * rows.len(), 4);
    let mut power = StateMatrix::identity();
    for blk in 0..4 {
        for (r, c) in rows.iter().enumerate() {
            let row = c * power;
            o.row_mut(blk * rows.len() + r).copy_from(&row);
        }
        power *= phi;
    }
    let sv = o.singular_values();
    let max = sv.max();
    max > 0.0 && sv.iter().filter(|&&v| v > 1e-9 * max).count() == 4
}

/// Names of the state coordinates (p_x, p_y, v_x, v_y), for reports.
pub const STATE_NAMES: [&str; 4] = ["x position", "y position", "x velocity", "y velocity"];

/// Detectability of (F, C̄) for one channel subset (the PBH test) and its unobservable subspace.
#[derive(Debug, Clone, PartialEq)]
pub struct Detectability {
    /// Whether (F, C̄) is detectable: `rank [λI − F; C̄] = n` for every eigenvalue λ of F with
    /// Re λ ≥ 0.
    pub detectable: bool,
    /// The eigenvalues (re, im) of F with Re λ ≥ 0 at which the PBH rank test fails.
    pub failing_eigenvalues: Vec<(f64, f64)>,
    /// Dimension of the unobservable subspace (kernel of [C̄; C̄F; C̄F²; C̄F³]).
    pub unobservable_dim: usize,
    /// The unobservable subspace in state terms: coordinate names when it is spanned by
    /// coordinate axes (e.g. "x position"), else its basis vectors written out.
    pub unobservable: Vec<String>,
    /// An orthonormal basis of the unobservable subspace.
    pub unobservable_basis: Vec<State>,
}

/// The PBH detectability test of (F, C̄), C̄ = the rows of the channels where `uses[k]`
/// (continuous-time F; for the double integrator every eigenvalue is 0, so detectable =
/// observable). Rank decisions use singular values above 1e-9 of the largest (and 1e-12
/// absolute).
pub fn detectability(model: &LinearModel, uses: &[bool]) -> Detectability {
    use nalgebra::{Complex, DMatrix};
    let rows: Vec<RowVector4<f64>> = (0..model.channels())
        .filter(|&k| uses.get(k).copied().unwrap_or(false))
        .map(|k| model.c[k])
        .collect();
    let rank = |sv: &nalgebra::DVector<f64>| {
        let max = sv.max();
        sv.iter().filter(|&&v| v > 1e-12 && v > 1e-9 * max).count()
    };
    // PBH at each eigenvalue with Re λ ≥ 0.
    let mut failing = Vec::new();
    let eig = model.f.complex_eigenvalues();
    let mut seen: Vec<Complex<f64>> = Vec::new();
    for lam in eig.iter() {
        if lam.re < -1e-12 || seen.iter().any(|s| (s - lam).norm() < 1e-9) {
            continue;
        }
        seen.push(*lam);
        let mut m = DMatrix::<Complex<f64>>::zeros(4 + rows.len(), 4);
        for r in 0..4 {
            for c in 0..4 {
                let id = if r == c { *lam } else { Complex::new(0.0, 0.0) };
                m[(r, c)] = id - Complex::new(model.f[(r, c)], 0.0);
            }
        }
        for (k, row) in rows.iter().enumerate() {
            for c in 0..4 {
                m[(4 + k, c)] = Complex::new(row[c], 0.0);
            }
        }
        if rank(&m.singular_values()) < 4 {
            failing.push((lam.re, lam.im));
        }
    }
    // Unobservable subspace.
    let mut o = DMatrix::<f64>::zeros(4 * rows.len().max(1), 4);
    let mut power = StateMatrix::identity();
    for blk in 0..4 {
        for (r, c) in rows.iter().enumerate() {
            o.row_mut(blk * rows.len() + r).copy_from(&(c * power));
        }
        power *= model.f;
    }
    let unobservable_dim = if rows.is_empty() {
        4
    } else {
        4 - rank(&o.singular_values())
    };
    let scale = o.amax().max(1.0);
    let named: Vec<String> = (0..4)
        .filter(|&k| o.column(k).amax() <= 1e-12 * scale)
        .map(|k| STATE_NAMES[k].to_string())
        .collect();
    // A basis of the kernel: right singular vectors of the smallest singular values.
    let svd = o.clone().svd(false, true);
    let vt = svd.v_t.unwrap_or_else(|| DMatrix::identity(4, 4));
    let mut order: Vec<usize> = (0..svd.singular_values.len()).collect();
    order.sort_by(|&a, &b| svd.singular_values[a].total_cmp(&svd.singular_values[b]));
    let mut basis: Vec<State> = order
        .into_iter()
        .take(unobservable_dim)
        .map(|i| State::new(vt[(i, 0)], vt[(i, 1)], vt[(i, 2)], vt[(i, 3)]))
        .collect();
    if rows.is_empty() {
        basis = (0..4)
            .map(|k| State::from_fn(|r, _| f64::from(r == k)))
            .collect();
    }
    let unobservable = if named.len() == unobservable_dim {
        named
    } else {
        // Not axis-aligned: write the basis out.
        basis
            .iter()
            .map(|v| {
                format!(
                    "({:.3}·p_x + {:.3}·p_y + {:.3}·v_x + {:.3}·v_y)",
                    v[0], v[1], v[2], v[3]
                )
            })
            .collect()
    };
    Detectability {
        detectable: failing.is_empty(),
        failing_eigenvalues: failing,
        unobservable_dim,
        unobservable,
        unobservable_basis: basis,
    }
}

/// The posterior covariance with the largest λ̄ over `n` steps of the Riccati recursion started
/// at `p0` (predict with Φ, Q_d at `dt`, then the sequential updates of the channels where
/// `uses[k]`). For a channel set without a steady state (an open-loop or dead-reckoning
/// filter, e.g. one that drops every position fix) this is the largest error covariance the
/// filter reaches within a run of `n` samples.
pub fn horizon_riccati(
    model: &LinearModel,
    uses: &[bool],
    dt: f64,
    p0: &StateMatrix,
    n: usize,
) -> StateMatrix {
    horizon_riccati_from(model, &[uses.to_vec()], 0, dt, p0, n)
}

/// [`horizon_riccati`] with a schedule: step s (s = `first`, `first` + 1, …) updates with the
/// channels of `phases[s % L]`.
pub fn horizon_riccati_from(
    model: &LinearModel,
    phases: &[Vec<bool>],
    first: usize,
    dt: f64,
    p0: &StateMatrix,
    n: usize,
) -> StateMatrix {
    let d = model.discretize(dt);
    let lmax = |p: &StateMatrix| p.symmetric_eigenvalues().max();
    let mut post = *p0;
    let mut worst = post;
    let none = Vec::new();
    for s in first..first + n {
        let uses = phases.get(s % phases.len().max(1)).unwrap_or(&none);
        post = riccati_step(model, uses, &d, &post).1;
        if lmax(&post) > lmax(&worst) {
            worst = post;
        }
    }
    worst
}

/// The largest posterior covariance (by λ̄) of the `n` estimates a filter started at `p0`
/// produces: [`horizon_riccati`] without P0 itself, which no estimate carries (every estimate
/// is posterior to at least one update). `p0` for `n = 0`.
pub fn horizon_posterior_max(
    model: &LinearModel,
    uses: &[bool],
    dt: f64,
    p0: &StateMatrix,
    n: usize,
) -> StateMatrix {
    horizon_posterior_max_scheduled(model, &[uses.to_vec()], dt, p0, n)
}

/// [`horizon_posterior_max`] with a schedule (step s updates with `phases[s % L]`).
pub fn horizon_posterior_max_scheduled(
    model: &LinearModel,
    phases: &[Vec<bool>],
    dt: f64,
    p0: &StateMatrix,
    n: usize,
) -> StateMatrix {
    if n == 0 || phases.is_empty() {
        return *p0;
    }
    let d = model.discretize(dt);
    let first = riccati_step(model, &phases[0], &d, p0).1;
    horizon_riccati_from(model, phases, 1, dt, &first, n - 1)
}

/// Steady-state `K c̄ = P∞⁺ c̄ᵀ R⁻¹ c̄ / dt` of a channel subset (the K of §4.2.1 used by
/// [`crate::barrier::HigherOrderHalfPlane`]).
pub fn steady_state_gain_product(model: &LinearModel, uses: &[bool], dt: f64) -> StateMatrix {
    gain_product(
        model,
        uses,
        &steady_state_riccati(model, uses, dt).posterior,
        dt,
    )
}

/// `K c̄ = P⁺ c̄ᵀ R⁻¹ c̄ / dt` of a channel subset for a given posterior covariance P⁺ (e.g. a
/// [`steady_state_riccati`] solution already at hand).
pub fn gain_product(
    model: &LinearModel,
    uses: &[bool],
    posterior: &StateMatrix,
    dt: f64,
) -> StateMatrix {
    let mut info = StateMatrix::zeros();
    for (k, &u) in uses.iter().enumerate() {
        if u && k < model.channels() {
            info += model.c[k].transpose() * model.c[k] / model.r[k];
        }
    }
    posterior * info / dt
}

/// `γ = sqrt(λ̄(P) χ²_n⁻¹(1 − ε))`: `Pr(‖e‖₂ > γ) ≤ ε` for `e ~ N(0, P)`, n = 4.
pub fn gamma_bound(p: &StateMatrix, eps: f64) -> f64 {
    let sym = (p + p.transpose()) * 0.5;
    let lmax = sym.symmetric_eigenvalues().max().max(0.0);
    (lmax * chi_square_quantile(4, 1.0 - eps)).sqrt()
}

/// How [`FtParameters`] bounds the estimation errors.
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
/// One type for the three places that hold them: computed ([`FtParameters::ft`]), in force for
/// a world (the simulator's parameter report) and handed to the controller
/// ([`crate::ControllerConfig::ft`]).
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

/// Values per unordered pair {i, j}, i ≠ j, of `m` items (fault patterns, units of the policy),
/// stored packed in the order (0,1), (0,2), …, (0,m−1), (1,2), …: the one layout of pair data in
/// the crate (θ_ij, γ_ij, η_ij, the pair filters). (i, j) and (j, i) are the same entry.
#[derive(Debug, Clone, PartialEq)]
pub struct PairTable<T> {
    m: usize,
    values: Vec<T>,
}

/// C(m, 2): the number of pairs of `m` items (the length of a [`PairTable`]).
pub fn pair_count(m: usize) -> usize {
    m * m.saturating_sub(1) / 2
}

/// The packed index of the pair (i, j) of `m` items (either order) in a [`PairTable`]; None
/// when i = j or either is out of range.
pub fn pair_slot(m: usize, i: usize, j: usize) -> Option<usize> {
    let (a, b) = (i.min(j), i.max(j));
    (a != b && b < m).then(|| a * (2 * m - a - 1) / 2 + (b - a - 1))
}

impl<T> PairTable<T> {
    /// The table of `m` items with `f(i, j)` (i < j) for each pair, in packed order.
    pub fn from_fn(m: usize, mut f: impl FnMut(usize, usize) -> T) -> Self {
        let mut values = Vec::with_capacity(pair_count(m));
        for i in 0..m {
            for j in (i + 1)..m {
                values.push(f(i, j));
            }
        }
        Self { m, values }
    }

    /// Number of items the pairs are drawn from.
    pub fn items(&self) -> usize {
        self.m
    }

    /// The value of the pair (i, j) (either order); None when i = j or out of range.
    pub fn get(&self, i: usize, j: usize) -> Option<&T> {
        self.values.get(pair_slot(self.m, i, j)?)
    }

    /// The value of the pair (i, j) (either order), mutably.
    pub fn get_mut(&mut self, i: usize, j: usize) -> Option<&mut T> {
        let k = pair_slot(self.m, i, j)?;
        self.values.get_mut(k)
    }

    /// ((i, j), value) for every pair, i < j, in packed order.
    pub fn iter(&self) -> impl Iterator<Item = ((usize, usize), &T)> + '_ {
        let m = self.m;
        (0..m)
            .flat_map(move |i| ((i + 1)..m).map(move |j| (i, j)))
            .zip(&self.values)
    }

    /// The values in packed order.
    pub fn as_slice(&self) -> &[T] {
        &self.values
    }

    /// The values in packed order, mutably.
    pub fn values_mut(&mut self) -> &mut [T] {
        &mut self.values
    }
}

impl<T> std::ops::Index<(usize, usize)> for PairTable<T> {
    type Output = T;
    /// The value of the pair (i, j); panics when i = j or either is out of range.
    fn index(&self, (i, j): (usize, usize)) -> &T {
        match self.get(i, j) {
            Some(v) => v,
            None => panic!("pair ({i}, {j}) of {} items", self.m),
        }
    }
}

impl<T> std::ops::IndexMut<(usize, usize)> for PairTable<T> {
    fn index_mut(&mut self, (i, j): (usize, usize)) -> &mut T {
        let m = self.m;
        match self.get_mut(i, j) {
            Some(v) => v,
            None => panic!("pair ({i}, {j}) of {m} items"),
        }
    }
}

/// γ_i, γ_ij and θ_ij computed for a model, patterns, sampling period, ε and horizon.
#[derive(Debug, Clone, PartialEq)]
pub struct FtParameters {
    /// The parameters the controller takes: γ_i per pattern, γ of the baseline (all channels)
    /// at the same per-sample ε', θ_ij per pair, and for [`BoundMethod::Horizon`] η_ij, W_ij
    /// and θ_ij(t) (empty/None for [`BoundMethod::Paper`]: the paper's Step 2 has no increment
    /// test).
    pub ft: FtParams,
    /// γ_ij per pair in packed order ([`PairTable`]).
    pub gamma_pair: Vec<f64>,
    /// The §4.3 triangle bound 2(max(γ_i, γ_j) + γ_ij) in the same order (equal to `ft.theta`
    /// for [`BoundMethod::Paper`]).
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

/// One filter's sequential update as a linear map of its prior error and the measurement noise:
/// `e⁺ = A e⁻ + B v` (all channels where `uses[k]` fresh), with the posterior covariance.
fn update_map(
    model: &LinearModel,
    uses: &[bool],
    prior: &StateMatrix,
) -> (StateMatrix, nalgebra::DMatrix<f64>, StateMatrix) {
    let q = model.channels();
    let mut a = StateMatrix::identity();
    let mut b = nalgebra::DMatrix::<f64>::zeros(4, q);
    let mut p = *prior;
    for (k, &u) in uses.iter().enumerate() {
        if !u || k >= q {
            continue;
        }
        let (kg, ikc) = scalar_gain(model, k, &p);
        a = ikc * a;
        b = nalgebra::DMatrix::from_fn(4, q, |r, cc| {
            (0..4).map(|m| ikc[(r, m)] * b[(m, cc)]).sum::<f64>()
        });
        for r in 0..4 {
            b[(r, k)] += kg[r];
        }
        p = joseph(model, k, &p, &kg, &ikc);
    }
    (a, b, p)
}

/// Exact second moments of the solution separation `s = x̂_a − x̂_b` of two filters run on the
/// same measurements from the same start (x̂_a(0) = x̂_b(0), error covariance `p0`), over `n`
/// steps: the joint error (e_a, e_b) is a linear Gaussian process whose transition and noise
/// follow from each filter's gains.
#[derive(Debug, Clone, PartialEq)]
pub struct SeparationMoments {
    /// The largest λ̄ over the horizon of `Cov(s_k)`.
    pub worst_abs: f64,
    /// λ̄(Cov(s_k)) for k = 1..=n.
    pub absolute: Vec<f64>,
    /// `Cov(s_k − s_{k−w})` for k = 1..=n (the increment over the last `w` steps; from the
    /// start while k < w).
    pub increments: Vec<StateMatrix>,
}

/// See [`SeparationMoments`].
pub fn separation_moments(
    model: &LinearModel,
    uses_a: &[bool],
    uses_b: &[bool],
    dt: f64,
    p0: &StateMatrix,
    n: usize,
    w: usize,
) -> SeparationMoments {
    separation_moments_scheduled(model, &[uses_a.to_vec()], &[uses_b.to_vec()], dt, p0, n, w)
}

/// [`separation_moments`] with a schedule: at step s filter a updates with the channels of
/// `phases_a[s % L_a]`, filter b with `phases_b[s % L_b]` ([`UpdateSchedule::phases`]).
pub fn separation_moments_scheduled(
    model: &LinearModel,
    phases_a: &[Vec<bool>],
    phases_b: &[Vec<bool>],
    dt: f64,
    p0: &StateMatrix,
    n: usize,
    w: usize,
) -> SeparationMoments {
    type M8 = nalgebra::SMatrix<f64, 8, 8>;
    let d = model.discretize(dt);
    let q = model.channels();
    let r = nalgebra::DMatrix::from_diagonal(&nalgebra::DVector::from_vec(model.r.clone()));
    let mut sigma = M8::zeros();
    for (bi, bj) in [(0, 0), (0, 4), (4, 0), (4, 4)] {
        sigma.fixed_view_mut::<4, 4>(bi, bj).copy_from(p0);
    }
    let (mut pa, mut pb) = (*p0, *p0);
    let sep_cov = |s: &M8| -> StateMatrix {
        let h = |i: usize, j: usize| s.fixed_view::<4, 4>(i, j).into_owned();
        h(0, 0) + h(4, 4) - h(0, 4) - h(4, 0)
    };
    let lmax = |m: &StateMatrix| ((m + m.transpose()) * 0.5).symmetric_eigenvalues().max();
    // Σ_{k−w..k}, and the product 𝒜_k ⋯ 𝒜_{k−w+1} of the last w transitions kept by a
    // two-stack sliding-window product (amortised three 8×8 products per step): `back` holds
    // the newer transitions with their running product `back_prod` (newest on the left),
    // `front` the older ones, each with the product of itself and the newer ones in `front`
    // (the oldest, next to leave, on top).
    let w = w.max(1);
    let mut sigmas: std::collections::VecDeque<M8> = std::collections::VecDeque::new();
    let mut back: Vec<M8> = Vec::new();
    let mut back_prod = M8::identity();
    let mut front: Vec<M8> = Vec::new();
    sigmas.push_back(sigma);
    let mut worst_abs = 0.0f64;
    let mut absolute = Vec::with_capacity(n);
    let mut increments = Vec::with_capacity(n);
    fn phase(phases: &[Vec<bool>], s: usize) -> &[bool] {
        phases
            .get(s % phases.len().max(1))
            .map_or(&[], Vec::as_slice)
    }
    for s in 0..n {
        let prior_a = d.phi * pa * d.phi.transpose() + d.qd;
        let prior_b = d.phi * pb * d.phi.transpose() + d.qd;
        let (aa, ba, post_a) = update_map(model, phase(phases_a, s), &prior_a);
        let (ab, bb, post_b) = update_map(model, phase(phases_b, s), &prior_b);
        pa = post_a;
        pb = post_b;
        let mut t = M8::zeros();
        t.fixed_view_mut::<4, 4>(0, 0).copy_from(&(aa * d.phi));
        t.fixed_view_mut::<4, 4>(4, 4).copy_from(&(ab * d.phi));
        // noise: −[A_a; A_b] w + [B_a; B_b] v
        let mut aw = nalgebra::SMatrix::<f64, 8, 4>::zeros();
        aw.fixed_view_mut::<4, 4>(0, 0).copy_from(&aa);
        aw.fixed_view_mut::<4, 4>(4, 0).copy_from(&ab);
        let mut bv = nalgebra::DMatrix::<f64>::zeros(8, q);
        bv.view_mut((0, 0), (4, q)).copy_from(&ba);
        bv.view_mut((4, 0), (4, q)).copy_from(&bb);
        let nv = &bv * &r * bv.transpose();
        let noise = aw * d.qd * aw.transpose() + M8::from_fn(|i, j| nv[(i, j)]);
        sigma = t * sigma * t.transpose() + noise;
        sigma = (sigma + sigma.transpose()) * 0.5;
        back.push(t);
        back_prod = t * back_prod;
        sigmas.push_back(sigma);
        if sigmas.len() > w + 1 {
            sigmas.pop_front();
            if front.is_empty() {
                let mut acc = M8::identity();
                for e in back.drain(..).rev() {
                    acc *= e;
                    front.push(acc);
                }
                back_prod = M8::identity();
            }
            front.pop();
        }
        let abs_k = lmax(&sep_cov(&sigma));
        absolute.push(abs_k);
        worst_abs = worst_abs.max(abs_k);
        // Cov(z_k, z_{k−w}) = 𝒜_k ⋯ 𝒜_{k−w+1} Σ_{k−w}
        let old = sigmas[0];
        let prod = match front.last() {
            Some(f) => back_prod * f,
            None => back_prod,
        };
        let cross = prod * old;
        let inc = sigma + old - cross - cross.transpose();
        let c = sep_cov(&inc);
        increments.push((c + c.transpose()) * 0.5);
    }
    SeparationMoments {
        worst_abs,
        absolute,
        increments,
    }
}

/// The fixed norm of Step 2's increment test for one pair, from the increment covariances of
/// both single filters against the pair filter over the horizon (`a`, `b`, as
/// [`SeparationMoments::increments`]): C̄ = C_a(k_a) + C_b(k_b) at the steps of largest trace
/// (plus a ridge of 10⁻⁹ of its trace, so it is invertible), W = C̄⁻¹, and the factor
/// c = max over both sequences of λ̄(L⁻¹ C_k L⁻ᵀ) (C̄ = L Lᵀ). Then C_k ≼ c C̄, so
/// zᵀ W z ≤ c · zᵀ C_k⁻¹ z, and Pr(‖z‖²_W > c q) ≤ Pr(χ²₄ > q): η/2 = √(c q) keeps the false-alarm
/// rate of every step of the horizon at most that of the χ²₄ quantile q. Returns (W, c).
/// The covariance weighting is what makes the test sharp: the honest separation of two filters
/// fed the same odometry barely moves in velocity, while a spoof drags the velocity estimate.
pub fn increment_metric(a: &[StateMatrix], b: &[StateMatrix]) -> (StateMatrix, f64) {
    let largest = |cs: &[StateMatrix]| {
        cs.iter()
            .copied()
            .max_by(|x, y| x.trace().total_cmp(&y.trace()))
            .unwrap_or_else(StateMatrix::zeros)
    };
    let mut bar = largest(a) + largest(b);
    let ridge = 1e-9 * bar.trace().max(f64::MIN_POSITIVE);
    bar += StateMatrix::identity() * ridge;
    let Some(chol) = bar.cholesky() else {
        return (
            StateMatrix::identity(),
            bar.symmetric_eigenvalues().max().max(0.0),
        );
    };
    let l_inv = chol.l().try_inverse().unwrap_or_else(StateMatrix::identity);
    let scale = a
        .iter()
        .chain(b)
        .map(|c| {
            let m = l_inv * c * l_inv.transpose();
            ((m + m.transpose()) * 0.5).symmetric_eigenvalues().max()
        })
        .fold(0.0f64, f64::max);
    (chol.inverse(), scale)
}

impl FtParameters {
    /// Compute for total failure probability `eps` over `horizon_samples` samples, for filters
    /// started from a known state (P0 = 0) whose channels all update every step, by the paper's
    /// method. See [`FtParameters::compute_scheduled`].
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
            gamma_pair,
            theta_triangle,
            eps_per_sample: eps1,
            riccati_iterations: iterations,
            all_converged,
            riccati_converged: converged,
            patterns: patterns.len(),
            method,
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
/// [`FtParameters::compute_scheduled`]; the arithmetic is unchanged).
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

impl fmt::Display for FtParameters {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "per-sample epsilon' = {:.3e}", self.eps_per_sample)?;
        for (i, g) in self.ft.gamma.iter().enumerate() {
            writeln!(f, "gamma_{} = {:.6}", i + 1, g)?;
        }
        writeln!(f, "gamma_baseline = {:.6}", self.ft.gamma_baseline)?;
        for (k, ((g, t), tri)) in self
            .gamma_pair
            .iter()
            .zip(&self.ft.theta)
            .zip(&self.theta_triangle)
            .enumerate()
        {
            match self.method {
                BoundMethod::Paper => {
                    writeln!(f, "pair {k}: gamma_ij = {g:.6}, theta_ij = {t:.6}")?
                }
                BoundMethod::Horizon => writeln!(
                    f,
                    "pair {k}: gamma_ij = {g:.6}, theta_ij = {t:.6} (solution separation; the triangle bound of §4.3 would be {tri:.6}), eta_ij = {:.6} (separation increment over {STEP2_WINDOW} s, in the covariance-weighted norm ‖z‖_W)",
                    self.ft.eta.get(k).copied().unwrap_or(f64::NAN)
                )?,
            }
        }
        write!(f, "{}", self.riccati_line())
    }
}

impl FtParameters {
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

// ------------------------------------------------------------------------------------------
// Checks
// ------------------------------------------------------------------------------------------

/// Lemma 1 for a half-plane `aᵀx − b`: `aᵀG ≠ 0`; otherwise the relative degree (the
/// smallest i with `aᵀFⁱG ≠ 0`) for the lift of §4.2.1.
#[derive(Debug, Clone, PartialEq)]
pub struct Lemma1Verdict {
    /// aᵀG.
    pub a_g: Input,
    /// Whether aᵀG ≠ 0 (‖aᵀG‖ > 1e-12‖a‖‖G‖).
    pub holds: bool,
    /// Smallest i ≤ n with aᵀFⁱG ≠ 0, if any.
    pub relative_degree: Option<usize>,
}

/// Check Lemma 1.
pub fn check_lemma1(a: &State, f: &StateMatrix, g: &InputMatrix) -> Lemma1Verdict {
    let tol = 1e-12 * a.norm().max(1e-300) * g.norm().max(1e-300);
    let a_g: Input = g.transpose() * a;
    let mut fi = StateMatrix::identity();
    let mut rd = None;
    for i in 0..=4 {
        let v: Input = g.transpose() * fi.transpose() * a;
        if v.norm() > tol {
            rd = Some(i + 1);
            break;
        }
        fi *= f;
    }
    Lemma1Verdict {
        a_g,
        holds: a_g.norm() > tol,
        relative_degree: rd,
    }
}

impl fmt::Display for Lemma1Verdict {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "Lemma 1 (a^T G != 0): {} — a^T G = ({:.6}, {:.6}); relative degree {}",
            if self.holds { "HOLDS" } else { "FAILS" },
            self.a_g[0],
            self.a_g[1],
            self.relative_degree
                .map_or("none (uncontrollable direction)".to_string(), |r| r
                    .to_string())
        )
    }
}

/// Proposition 1 for an ellipsoid: `θ̄ ≤ sqrt(2(1 − h̄)/λ̄(Φ))` and `rank G = n`.
#[derive(Debug, Clone, PartialEq)]
pub struct Prop1Verdict {
    /// rank G.
    pub rank_g: usize,
    /// n = 4.
    pub n: usize,
    /// λ̄(Φ).
    pub lambda_max: f64,
    /// θ̄ = max θ_ij.
    pub theta_bar: f64,
    /// h̄ = max h̄_γi.
    pub h_bar: f64,
    /// sqrt(2(1 − h̄)/λ̄).
    pub bound: f64,
    /// Both conditions.
    pub holds: bool,
}

/// Check Proposition 1.
pub fn check_prop1(phi: &StateMatrix, g: &InputMatrix, theta_bar: f64, h_bar: f64) -> Prop1Verdict {
    let rank_g = g.rank(1e-12);
    let lambda_max = ((phi + phi.transpose()) * 0.5)
        .symmetric_eigenvalues()
        .max();
    let bound = (2.0 * (1.0 - h_bar) / lambda_max).max(0.0).sqrt();
    Prop1Verdict {
        rank_g,
        n: 4,
        lambda_max,
        theta_bar,
        h_bar,
        bound,
        holds: rank_g == 4 && theta_bar <= bound,
    }
}

impl fmt::Display for Prop1Verdict {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "Proposition 1: {} — rank G = {} (needs {}), theta_bar = {:.6} vs bound sqrt(2(1-h_bar)/lambda_max) = {:.6} (h_bar = {:.6}, lambda_max = {:.6})",
            if self.holds { "HOLDS" } else { "FAILS" },
            self.rank_g,
            self.n,
            self.theta_bar,
            self.bound,
            self.h_bar,
            self.lambda_max
        )
    }
}

/// Theorem 5 (rank G < n): the auxiliary half-plane `(x − x')ᵀΦv < 0` with `v = G w`.
#[derive(Debug, Clone, PartialEq)]
pub struct Thm5Verdict {
    /// rank G.
    pub rank_g: usize,
    /// v = G w.
    pub v: State,
    /// Normal of the auxiliary half-plane, Φv.
    pub normal: State,
    /// max_i (x̂_i − x')ᵀΦv over the estimates (must be < 0: condition (4.12) for Gu = v).
    pub max_inner: f64,
    /// min_i h(x̂_i) of the ellipsoid (must be ≥ 0: x̂_i ∈ C).
    pub min_h: f64,
    /// −vᵀv (condition (4.13), must be < 0).
    pub aux_rate: f64,
    /// All conditions.
    pub holds: bool,
}

/// Check Theorem 5 for an inside-ellipsoid `1 − (x − x')ᵀΦ(x − x')`, a direction `w` in input
/// space (v = G w) and the current estimates.
pub fn check_theorem5(
    phi: &StateMatrix,
    center: &State,
    g: &InputMatrix,
    w: &Input,
    estimates: &[State],
) -> Thm5Verdict {
    let v: State = g * w;
    let normal = phi * v;
    let mut max_inner = f64::NEG_INFINITY;
    let mut min_h = f64::INFINITY;
    for x in estimates {
        let e = x - center;
        max_inner = max_inner.max(e.dot(&normal));
        min_h = min_h.min(1.0 - e.dot(&(phi * e)));
    }
    let aux_rate = -v.dot(&v);
    let holds = max_inner < 0.0 && min_h >= 0.0 && aux_rate < 0.0;
    Thm5Verdict {
        rank_g: g.rank(1e-12),
        v,
        normal,
        max_inner,
        min_h,
        aux_rate,
        holds,
    }
}

impl fmt::Display for Thm5Verdict {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "Theorem 5: {} — rank G = {}, v = ({:.4}, {:.4}, {:.4}, {:.4}), max (x_i - x')^T Phi v = {:.6} (< 0), min h = {:.6} (>= 0), -v^T v = {:.6} (< 0)",
            if self.holds { "HOLDS" } else { "FAILS" },
            self.rank_g,
            self.v[0],
            self.v[1],
            self.v[2],
            self.v[3],
            self.max_inner,
            self.min_h,
            self.aux_rate
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The steady-state filter's response to a constant offset on its readings. An offset b on
    /// both x channels of the paper's observation moves the estimate to exactly (b, 0, 0, 0)
    /// (a still robot b further along x explains every reading). An offset on the ẋ channel
    /// alone, contradicted by the position channels, leaves a bounded position offset and a
    /// velocity offset short of the reading's.
    #[test]
    fn update_gains_move_the_estimate_by_the_filters_response() {
        let model = LinearModel::paper_double_integrator(1e-3, 1e-3).unwrap();
        let dt = 0.02;
        let phi = model.discretize(dt).phi;
        let uses = [true; 6];
        let ss = steady_state_riccati(&model, &uses, dt);
        assert!(ss.converged);
        let gains = update_gains(&model, &uses, &ss.prior);
        assert_eq!(gains.len(), 6);
        let settle = |d: [f64; 6], steps: usize| {
            let mut e = State::zeros();
            for _ in 0..steps {
                e = phi * e;
                for (k, kg, ikc) in &gains {
                    e = ikc * e + kg * d[*k];
                }
            }
            e
        };
        let fix = settle([0.3, 0.3, 0.0, 0.0, 0.0, 0.0], 20_000);
        assert!((fix[0] - 0.3).abs() < 1e-9, "{fix}");
        assert!(fix[1].abs() < 1e-12 && fix[2].abs() < 1e-9 && fix[3].abs() < 1e-12);
        let vel = settle([0.0, 0.0, 0.0, 0.0, 0.1, 0.0], 20_000);
        let later = settle([0.0, 0.0, 0.0, 0.0, 0.1, 0.0], 40_000);
        assert!((vel - later).amax() < 1e-9, "not settled: {vel} vs {later}");
        assert!(vel[0] > 0.0 && vel[0] < 1.0, "{vel}");
        assert!(vel[2] > 0.0 && vel[2] < 0.1, "{vel}");
    }

    /// The packed layout is the order (0,1), (0,2), …, (1,2), … in which [`FtParameters`]
    /// computes its pair values, whichever way round a pair is asked for.
    #[test]
    fn pair_table_packs_pairs_in_the_computation_order() {
        for m in 0..7 {
            let mut order = Vec::new();
            for i in 0..m {
                for j in (i + 1)..m {
                    order.push((i, j));
                }
            }
            assert_eq!(pair_count(m), order.len());
            for (k, &(i, j)) in order.iter().enumerate() {
                assert_eq!(pair_slot(m, i, j), Some(k));
                assert_eq!(pair_slot(m, j, i), Some(k));
            }
            for i in 0..m {
                assert_eq!(pair_slot(m, i, i), None);
                assert_eq!(pair_slot(m, i, m), None);
            }
            let mut t = PairTable::from_fn(m, |i, j| 10 * i + j);
            assert_eq!(t.items(), m);
            let listed: Vec<(usize, usize)> = t.iter().map(|(p, _)| p).collect();
            assert_eq!(listed, order);
            for &(i, j) in &order {
                assert_eq!((t[(i, j)], t[(j, i)]), (10 * i + j, 10 * i + j));
            }
            if m >= 3 {
                t[(2, 0)] = 99;
                assert_eq!(t.get(0, 2), Some(&99));
                assert_eq!(t.as_slice()[1], 99);
            }
            assert_eq!(t.get(0, 0), None);
        }
    }

    /// A per-pair list holds one value for all pairs or one per pair in packed order.
    #[test]
    fn per_pair_values_are_one_for_all_or_packed() {
        assert_eq!(FtParams::per_pair(&[0.5], 3, 2, 1), Some(0.5));
        assert_eq!(FtParams::per_pair(&[0.1, 0.2, 0.3], 3, 2, 1), Some(0.3));
        assert_eq!(FtParams::per_pair(&[0.1, 0.2, 0.3], 3, 0, 2), Some(0.2));
        assert_eq!(FtParams::per_pair::<f64>(&[], 3, 0, 1), None);
        assert_eq!(FtParams::per_pair(&[0.1, 0.2], 3, 1, 2), None);
        let p = FtParams::uniform(3, 0.01, 0.2);
        assert_eq!(
            (p.gamma, p.gamma_baseline, p.theta),
            (vec![0.01; 3], 0.01, vec![0.2])
        );
        assert!(p.eta.is_empty() && p.increment_metric.is_empty() && p.theta_schedule.is_none());
    }

    #[test]
    fn chi_square_quantiles_match_tables() {
        // Standard table values (upper-tail probability 0.05 and 0.01).
        let table = [
            (1, 0.95, 3.841_458_820_694_124),
            (2, 0.95, 5.991_464_547_107_979),
            (4, 0.95, 9.487_729_036_781_154),
            (4, 0.99, 13.276_704_135_987_62),
            (10, 0.95, 18.307_038_053_275_146),
            (4, 0.5, 3.356_693_980_033_322),
        ];
        for (k, p, x) in table {
            let q = chi_square_quantile(k, p);
            assert!((q - x).abs() < 1e-9 * x, "k={k} p={p}: {q} vs {x}");
            assert!((chi_square_cdf(k, x) - p).abs() < 1e-12);
        }
        // closed form for k = 2: cdf = 1 − e^{−x/2}
        assert!((chi_square_cdf(2, 3.0) - (1.0 - (-1.5f64).exp())).abs() < 1e-15);
        assert!((ln_gamma(5.0) - 24.0f64.ln()).abs() < 1e-13);
        assert!(chi_square_quantile(4, 1.0).is_nan());
    }

    #[test]
    fn riccati_converges_and_matches_filter() {
        let model = LinearModel::paper_double_integrator(1e-3, 1e-3).unwrap();
        let uses = [true, false, true, true, true, true];
        let s = steady_state_riccati(&model, &uses, 0.01);
        assert!(s.converged);
        assert!(
            s.iterations > 10 && s.iterations < 100_000,
            "{}",
            s.iterations
        );
        // a fixed point: one more predict+update leaves P⁺ unchanged
        let mut bank = crate::estimator::EstimatorBank::new(
            model.clone(),
            &[vec![1]],
            State::zeros(),
            s.posterior,
        );
        let y = [0.0; 6];
        bank.step(&Input::zeros(), 0.01, &y, &[true; 6], &[false; 6]);
        assert!((bank.single(0).covariance() - s.posterior).amax() < 1e-12 * s.posterior.amax());
    }

    #[test]
    fn a_schedule_unrolls_to_its_phases() {
        let sched = UpdateSchedule {
            every: vec![1, 5, 0, 2],
        };
        let phases = sched.phases(&[true, true, true, true]);
        assert_eq!(phases.len(), 10); // lcm(1, 5, 2); channel 2 never updates
        assert_eq!(phases[0], vec![true, true, false, true]);
        assert_eq!(phases[1], vec![true, false, false, false]);
        assert_eq!(phases[5], vec![true, true, false, false]);
        // a channel the filter does not use is left out, and so is its period
        assert_eq!(sched.phases(&[true, false, true, true]).len(), 2);
        assert_eq!(
            UpdateSchedule::every_step().phases(&[true, false]),
            vec![vec![true, false]]
        );
        // periods whose lcm exceeds the cap are coarsened to the longest one, all at once
        let coarse = UpdateSchedule {
            every: vec![9973, 9967],
        };
        let phases = coarse.phases(&[true, true]);
        assert_eq!(phases.len(), 9973);
        assert_eq!(phases[0], vec![true, true]);
        assert!(phases[1..].iter().all(|p| p == &vec![false, false]));
    }

    #[test]
    fn the_periodic_riccati_takes_its_worst_phase() {
        let model = LinearModel::paper_double_integrator(1e-3, 1e-3).unwrap();
        let uses = [true, false, true, false, true, true];
        let dt = 0.02;
        // every step: exactly the time-invariant recursion
        let one = periodic_riccati(&model, &UpdateSchedule::every_step().phases(&uses), dt);
        assert_eq!(one, steady_state_riccati(&model, &uses, dt));
        // the position channels every 5 steps: the worst phase is the last before an update,
        // and it is what a long run of the recursion reaches at most
        let sched = UpdateSchedule {
            every: vec![5, 5, 5, 5, 1, 1],
        };
        let phases = sched.phases(&uses);
        let s = periodic_riccati(&model, &phases, dt);
        assert!(s.converged);
        let lmax = |p: &StateMatrix| p.symmetric_eigenvalues().max();
        assert!(lmax(&s.posterior) > 1.5 * lmax(&one.posterior));
        let long = horizon_riccati_from(&model, &phases, 0, dt, &one.posterior, 5000);
        assert!(
            (lmax(&long) - lmax(&s.posterior)).abs() < 1e-9 * lmax(&s.posterior),
            "{} vs {}",
            lmax(&long),
            lmax(&s.posterior)
        );
        let d = model.discretize(dt);
        let mut p = s.posterior;
        // the worst is phase 4, four steps after an update; phases 0–3 that follow are smaller
        for (ph, uses) in phases.iter().enumerate().take(4) {
            p = riccati_step(&model, uses, &d, &p).1;
            assert!(lmax(&p) < lmax(&s.posterior), "phase {ph}");
        }
    }

    #[test]
    fn gamma_bound_scalar_case() {
        // P = σ² I: γ² = σ² χ²₄(1 − ε)
        let p = StateMatrix::identity() * 0.04;
        assert!((gamma_bound(&p, 0.05) - (0.04 * 9.487_729_036_781_154f64).sqrt()).abs() < 1e-9);
    }

    #[test]
    fn checks_report_numbers() {
        let g = LinearModel::double_integrator_g();
        let f = LinearModel::double_integrator_f();
        let l = check_lemma1(&State::new(0.0, 1.0, 0.0, 0.2), &f, &g);
        assert!(l.holds && l.relative_degree == Some(1));
        assert_eq!(l.a_g, Input::new(0.0, 0.2));
        let l2 = check_lemma1(&State::new(0.0, 1.0, 0.0, 0.0), &f, &g);
        assert!(!l2.holds);
        assert_eq!(l2.relative_degree, Some(2));
        assert!(l2.to_string().contains("FAILS"));
        let p = check_prop1(&StateMatrix::identity(), &g, 0.1, 0.0);
        assert_eq!(p.rank_g, 2);
        assert!(!p.holds);
        assert!((p.bound - 2f64.sqrt()).abs() < 1e-12);
        let p4 = check_prop1(
            &(StateMatrix::identity() * 4.0),
            &crate::types::InputMatrix::zeros(),
            0.1,
            0.5,
        );
        assert!((p4.bound - 0.5).abs() < 1e-12);
        let phi = StateMatrix::identity();
        let t = check_theorem5(
            &phi,
            &State::zeros(),
            &g,
            &Input::new(1.0, 0.0),
            &[State::new(0.0, 0.0, -0.5, 0.0)],
        );
        assert!(t.holds, "{t}");
        let t2 = check_theorem5(
            &phi,
            &State::zeros(),
            &g,
            &Input::new(1.0, 0.0),
            &[State::new(0.0, 0.0, 0.5, 0.0)],
        );
        assert!(!t2.holds);
    }
}
