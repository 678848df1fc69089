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
//!
//! # Planar barriers, and indexes with their own condition
//!
//! A barrier whose h depends on the position (x₀, x₁) only has ∂h = (∂h_p, 0) and a Hessian
//! with only its position block, so each term above needs only the position rows (subscript p)
//! of G, F x̂, M and the position block of N: the right side is at most
//! `‖∂h_p‖·A_p + ‖∇²h_pp‖_F·B_p` with `A_p = ‖G_p‖_F‖L‖₂ + ‖(F x̂)_p‖₂ + γ‖M_p‖_F` and
//! `B_p = ½‖N_pp‖_F` ([`ReachTerms::a_planar`], [`ReachTerms::b_planar`]; A_p ≤ A, B_p ≤ B). For
//! the double integrator G_p = 0: the box term vanishes.
//!
//! Bounds of h, ‖∂h‖ and ‖∇²h‖ that hold at every distance ≥ D do not exist for every barrier:
//! the quadratic h of an ellipse grows with the distance and so does its gradient. An index
//! may therefore decide the reach condition itself ([`BarrierIndex::out_of_reach`]) from a
//! sharper argument, as long as what it certifies is the reach condition, barrier by barrier,
//! for every covered barrier at distance ≥ D, and stays true for every larger D (the radius is
//! found by bisection). [`crate::ellipse_index::EllipseIndex`] does so for ellipses.

use crate::types::{InputMatrix, State, StateMatrix};

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
    /// Whether the reach condition (module docs) holds for every covered barrier at planar
    /// distance ≥ `dist` from its region under `terms`; once true at a distance it must be true
    /// at every larger one. Default: the condition on [`BarrierIndex::far_bounds`]
    /// ([`ReachTerms::slack_under`]).
    fn out_of_reach(&self, terms: &ReachTerms, dist: f64) -> bool {
        terms.slack_under(&self.far_bounds(dist, terms.speed))
    }
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
    /// A_p = ‖G_p‖_F‖L‖₂ + ‖(F x̂)_p‖₂ + γ‖M_p‖_F (position rows only): A for barriers that
    /// depend on the position only (module docs). At most A; A itself is a valid value.
    pub a_planar: f64,
    /// B_p = ½‖N_pp‖_F (position block only). At most B; B itself is a valid value.
    pub b_planar: f64,
    /// δ of Step 1 (+∞: none).
    pub delta: f64,
    /// ‖v̂‖ \[m/s\].
    pub speed: f64,
}

impl ReachTerms {
    /// The terms for estimate `x` of a model with drift `f` and input map `g`, the input box
    /// of norm `limit_norm` = ‖L‖₂, with the filter's gain terms `m` (K c̄) and `n`
    /// (Kν̄ν̄ᵀKᵀ).
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        f: &StateMatrix,
        g: &InputMatrix,
        limit_norm: f64,
        x: &State,
        m: &StateMatrix,
        n: &StateMatrix,
        gamma: f64,
        kappa: f64,
        h_bar: f64,
        delta: f64,
    ) -> Self {
        let fx = f * x;
        Self {
            kappa,
            h_bar,
            a: g.norm() * limit_norm + fx.norm() + gamma * m.norm(),
            b: 0.5 * n.norm(),
            a_planar: g.fixed_rows::<2>(0).norm() * limit_norm
                + fx.fixed_rows::<2>(0).norm()
                + gamma * m.fixed_rows::<2>(0).norm(),
            b_planar: 0.5 * n.fixed_view::<2, 2>(0, 0).norm(),
            delta,
            speed: x[2].hypot(x[3]),
        }
    }

    /// Whether the reach condition (module docs) holds with the bounds `fb`:
    /// κ(h_lower − h̄) > gradient·A + hessian·B, and h_lower − h̄ ≥ δ when δ is finite.
    pub fn slack_under(&self, fb: &FarBounds) -> bool {
        self.condition(fb.h_lower, fb.gradient * self.a + fb.hessian * self.b)
    }

    /// κ(h_lower − h̄) > `need`, h_lower − h̄ ≥ δ when δ is finite, `need` finite: the reach
    /// condition once its right side `need` is bounded.
    pub fn condition(&self, h_lower: f64, need: f64) -> bool {
        let h_hat = h_lower - self.h_bar;
        let slack = self.kappa * h_hat > need;
        let outside_delta = self.delta == f64::INFINITY || h_hat >= self.delta;
        // Non-finite terms compare false: never out of reach.
        slack && outside_delta && need.is_finite()
    }

    /// Whether the reach condition (module docs) holds at distance `dist`.
    pub fn out_of_reach_at(&self, index: &dyn BarrierIndex, dist: f64) -> bool {
        index.out_of_reach(self, dist)
    }

    /// The reach radius D (module docs): the smallest distance, to within 1 mm, at which the
    /// reach condition holds; +∞ when it holds nowhere up to 10⁶ m or a term is not finite.
    pub fn radius(&self, index: &dyn BarrierIndex) -> f64 {
        let finite = [self.a, self.b, self.a_planar, self.b_planar];
        if !(self.kappa > 0.0 && finite.iter().all(|v| v.is_finite())) {
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
            a_planar: 1.5,
            b_planar: 0.0,
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
