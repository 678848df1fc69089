//! The filters' covariance: the discrete Riccati recursion at steady state, periodic (channels
//! read on a schedule) and over a horizon, the update gains, and γ from a covariance (§4.3).

use nalgebra::RowVector4;

use crate::model::LinearModel;
use crate::types::{State, StateMatrix};

use super::*;

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
pub(super) fn riccati_step(
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
pub(super) fn scalar_gain(model: &LinearModel, k: usize, p: &StateMatrix) -> (State, StateMatrix) {
    let c: RowVector4<f64> = model.c[k];
    let pc = p * c.transpose();
    let s = (c * pc)[0] + model.r[k];
    let kg = pc / s;
    (kg, StateMatrix::identity() - kg * c)
}

/// The Joseph-form posterior (I − Kc) P (I − Kc)ᵀ + K r Kᵀ, symmetrised.
pub(super) fn joseph(
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
