//! Active barriers (issue #52): which barriers' rows a control step must build at all.
//!
//! A world with hundreds of obstacles gives hundreds of barriers, and each step of the
//! controller would evaluate every one of them for every filter. Most are far: their row is
//! satisfied by every input of the box, so it cannot bind. A [`BarrierIndex`] (the simulator
//! builds one over the obstacles' bounding boxes with parry's BVH) lets a step find the barriers
//! near an estimate without touching the others, and certifies bounds on the far ones from
//! their distance alone.
//!
//! # The rule, and why dropping a far row changes nothing
//!
//! Unit i's row for barrier h at the estimate x̂ (eq. 4.3, [`crate::constraints::cbf_row`]) is
//! `Λu ≥ ω̄` with `Λ = ∂h G`, `ω̄ = −κĥ − ∂h F x̂ + γ‖∂h M‖ − ½tr(∇²h N)`, `ĥ = h(x̂) − h̄_γ`.
//! With the input box `|u_k| ≤ L_k`, the row holds for every admissible u as soon as
//! `min_u Λu = −Σ|Λ_k|L_k ≥ ω̄`, i.e.
//!
//! ```text
//! κ·ĥ ≥ Σ|Λ_k|L_k − ∂h F x̂ + γ‖Mᵀ∂h‖ − ½tr(∇²h N)
//! ```
//!
//! and the right side is at most `‖∂h‖·A + ‖∇²h‖_F·B` with
//! `A = ‖G‖_F‖L‖₂ + ‖F x̂‖₂ + γ‖M‖_F` and `B = ½‖N‖_F` (Cauchy–Schwarz, and
//! |tr(XY)| ≤ ‖X‖_F‖Y‖_F). The index certifies, for every barrier it covers whose region is at
//! planar distance ≥ D from the estimate's position p̂ and at the estimate's speed s = ‖v̂‖,
//! `h(x̂) ≥ h_lower(D, s)`, `‖∂h‖ ≤ g(D, s)` and `‖∇²h‖_F ≤ H(D, s)` ([`FarBounds`]; h_lower
//! non-decreasing and g, H non-increasing in D). So with h̄ the largest h̄_γ of unit i over
//! the covered barriers, every covered barrier at distance ≥ D where
//!
//! ```text
//! κ·(h_lower(D, s) − h̄) > g(D, s)·A + H(D, s)·B            (the reach condition)
//! ```
//!
//! has a row that no input of the box can violate: the feasible set of every stage (Steps 1–3,
//! the fallback), hence each stage's verdict and the QP's solution, is the same with or without
//! it. Such a row is *out of reach*: it is not built, and it is not handed to the QP or to the
//! geometric feasibility test ([`crate::policy::PolicyProblem::cbf_far`]). It still counts as
//! the unit's row where Steps 2–3 ask whether a unit has CBF rows, as it did before. With a
//! finite δ the reach radius also makes `h_lower − h̄ ≥ δ`, so an out-of-reach row is exactly a
//! row outside X_t(δ), as the paper's Step 1 has it. Without an input box nothing is out of
//! reach (no row can be shown not to bind).
//!
//! The radius D_i of unit i is the smallest distance (to within 1 mm) at which the reach
//! condition holds; the index returns the barriers whose region comes within D_i of p̂ (a
//! superset of them is fine), and only those are evaluated.

use crate::types::{State, StateMatrix};

/// Bounds certified for every covered barrier at a planar distance ≥ `dist` from its region.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FarBounds {
    /// h(x) ≥ `h_lower`.
    pub h_lower: f64,
    /// ‖∂h/∂x‖₂ ≤ `gradient`.
    pub gradient: f64,
    /// ‖∂²h/∂x²‖_F ≤ `hessian` (as [`crate::Barrier::eval`] computes it).
    pub hessian: f64,
}

/// A spatial index over some of a controller's barriers (by their position in
/// [`crate::ControllerConfig::barriers`]), with the far-field bounds of the module docs.
pub trait BarrierIndex: Send + Sync + std::fmt::Debug {
    /// Whether barrier `b` is covered: it has a planar region, and [`BarrierIndex::far_bounds`]
    /// holds for it. Uncovered barriers are evaluated at every step.
    fn covers(&self, b: usize) -> bool;
    /// Bounds for every covered barrier at states whose position is at planar distance ≥
    /// `dist` \[m\] from the barrier's region and whose speed is ≤ `speed` \[m/s\]. h_lower must
    /// not decrease and the other two must not increase with `dist`. Return `h_lower = −∞`
    /// where nothing is known.
    fn far_bounds(&self, dist: f64, speed: f64) -> FarBounds;
    /// Appends to `out` every covered barrier whose region comes within `radius` of the planar
    /// point `p` (more is allowed). Must not allocate when `out` has room for every barrier.
    fn near(&self, p: [f64; 2], radius: f64, out: &mut Vec<usize>);
}

/// The terms of the reach condition of one unit at one step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReachTerms {
    /// κ, the class-K gain of the rows.
    pub kappa: f64,
    /// The largest h̄_γ of the unit over the covered barriers.
    pub h_bar: f64,
    /// A = ‖G‖_F‖L‖₂ + ‖F x̂‖₂ + γ‖M‖_F.
    pub a: f64,
    /// B = ½‖N‖_F.
    pub b: f64,
    /// δ of Step 1 (+∞: none).
    pub delta: f64,
    /// ‖v̂‖ \[m/s\].
    pub speed: f64,
}

impl ReachTerms {
    /// The terms for estimate `x` with the filter's gain terms `m` (K c̄) and `n` (Kν̄ν̄ᵀKᵀ).
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        f: &StateMatrix,
        g_norm: f64,
        limit_norm: f64,
        x: &State,
        m: &StateMatrix,
        n: &StateMatrix,
        gamma: f64,
        kappa: f64,
        h_bar: f64,
        delta: f64,
    ) -> Self {
        Self {
            kappa,
            h_bar,
            a: g_norm * limit_norm + (f * x).norm() + gamma * m.norm(),
            b: 0.5 * n.norm(),
            delta,
            speed: x[2].hypot(x[3]),
        }
    }

    /// Whether the reach condition (module docs) holds at distance `dist`.
    pub fn out_of_reach_at(&self, index: &dyn BarrierIndex, dist: f64) -> bool {
        let fb = index.far_bounds(dist, self.speed);
        let h_hat = fb.h_lower - self.h_bar;
        let need = fb.gradient * self.a + fb.hessian * self.b;
        let slack = self.kappa * h_hat > need;
        let outside_delta = self.delta == f64::INFINITY || h_hat >= self.delta;
        // Non-finite terms compare false: never out of reach.
        slack && outside_delta && need.is_finite()
    }

    /// The reach radius D (module docs): the smallest distance, to within 1 mm, at which the
    /// reach condition holds; +∞ when it holds nowhere up to 10⁶ m or a term is not finite.
    pub fn radius(&self, index: &dyn BarrierIndex) -> f64 {
        if !(self.kappa > 0.0 && self.a.is_finite() && self.b.is_finite()) {
            return f64::INFINITY;
        }
        if !(self.h_bar.is_finite() && self.speed.is_finite()) {
            return f64::INFINITY;
        }
        let mut hi = 0.5;
        while !self.out_of_reach_at(index, hi) {
            hi *= 2.0;
            if hi > 1e6 {
                return f64::INFINITY;
            }
        }
        let mut lo = 0.0;
        while hi - lo > 1e-3 {
            let mid = 0.5 * (lo + hi);
            if self.out_of_reach_at(index, mid) {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        hi
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Disc-like bounds: h ≥ D − 1, ‖∂h‖ ≤ 2, ‖∇²h‖ ≤ 1/D.
    #[derive(Debug)]
    struct Discs;
    impl BarrierIndex for Discs {
        fn covers(&self, _: usize) -> bool {
            true
        }
        fn far_bounds(&self, dist: f64, _: f64) -> FarBounds {
            FarBounds {
                h_lower: dist - 1.0,
                gradient: 2.0,
                hessian: 1.0 / dist,
            }
        }
        fn near(&self, _: [f64; 2], _: f64, _: &mut Vec<usize>) {}
    }

    fn terms(delta: f64) -> ReachTerms {
        ReachTerms {
            kappa: 1.0,
            h_bar: 0.5,
            a: 1.5,
            b: 0.0,
            delta,
            speed: 0.0,
        }
    }

    #[test]
    fn radius_is_where_the_row_starts_to_be_slack() {
        // κ(D − 1 − 0.5) > 2·1.5 ⇔ D > 4.5
        let d = terms(f64::INFINITY).radius(&Discs);
        assert!((d - 4.5).abs() <= 1e-3, "{d}");
        assert!(terms(f64::INFINITY).out_of_reach_at(&Discs, d));
        assert!(!terms(f64::INFINITY).out_of_reach_at(&Discs, 4.49));
    }

    #[test]
    fn a_finite_delta_widens_the_radius() {
        // ĥ = D − 1.5 ≥ 7 ⇔ D ≥ 8.5
        let d = terms(7.0).radius(&Discs);
        assert!((d - 8.5).abs() <= 1e-3, "{d}");
    }

    #[test]
    fn no_gain_or_non_finite_terms_reach_everything() {
        let mut t = terms(f64::INFINITY);
        t.kappa = 0.0;
        assert_eq!(t.radius(&Discs), f64::INFINITY);
        let mut t = terms(f64::INFINITY);
        t.a = f64::NAN;
        assert_eq!(t.radius(&Discs), f64::INFINITY);
    }
}
