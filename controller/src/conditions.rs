//! Condition 1 of Theorem 3, eq. (4.4), evaluated on the barriers that actually run.
//!
//! Theorem 3 needs, for every set X' of active estimates that are within θ_ij of each other,
//! an input u with `Λ_i(x̂_i) u > 0` for all i ∈ X', where `Λ_i = ∂h/∂x(x̂_i) G`. Lemma 1
//! (half-planes), Prop. 1 (ellipsoids with rank G = n) and Thm. 5 (ellipsoids with an
//! auxiliary half-plane) are sufficient conditions for it on the paper's closed-form sets.
//! The barriers the simulator runs are lifted (H = h + k∇h·v, see `ftcbf_sim::safe_sets` and
//! `ftcbf_sim::obstacles`), for which `Λ = ∂H/∂v = k∇h(p)`: rank G = 2 < n = 4, so Prop. 1
//! never applies to them as stated, and Thm. 5's auxiliary direction `v = Gw` has no position
//! component, so Thm. 5 on the 4×4 position-block Φ is vacuous (Φv = 0).
//!
//! [`condition_4_4`] decides (4.4) **exactly** for given estimates and any [`Barrier`], by
//! evaluating the barrier's own gradient at each estimate: in R² a set of vectors admits a
//! common direction with a strictly positive inner product iff none is zero and they lie in
//! an open half-plane (their angular spread is below π). This is Thm. 5's witness (a common
//! direction w with Λ_i w > 0, the role of `Gu = v`) found rather than guessed. Call it on
//! the estimates of each control step (e.g. from a simulation frame) to see whether the
//! hypothesis of Theorem 3 held along a run.

use std::fmt;

use crate::barrier::Barrier;
use crate::types::{Input, InputMatrix, State, StateMatrix};

/// The verdict of [`condition_4_4`].
#[derive(Debug, Clone, PartialEq)]
pub struct Condition44Verdict {
    /// Λ_i = ∂h/∂x(x̂_i) G per estimate.
    pub lambdas: Vec<Input>,
    /// A unit input with Λ_i u > 0 for all i, when one exists.
    pub witness: Option<Input>,
    /// min_i Λ_i·u / ‖Λ_i‖ at the witness (the cosine of the worst angle; in (0, 1] when
    /// the condition holds), or `None`.
    pub margin: Option<f64>,
    /// The largest angle between the Λ_i's directions and the direction opposite to it \[rad\]
    /// (the angular spread; (4.4) holds iff it is < π and no Λ_i vanishes).
    pub spread: f64,
    /// Estimates whose Λ_i vanishes (‖Λ_i‖ ≤ 1e-12) or is not finite: (4.4) fails for them.
    pub degenerate: Vec<usize>,
    /// (4.4) holds for these estimates.
    pub holds: bool,
}

/// Decide (4.4) for `barrier` at `estimates` with input matrix `g` (see the module docs).
/// An empty set of estimates holds trivially (witness `(1, 0)`, margin 1).
pub fn condition_4_4(
    barrier: &dyn Barrier,
    g: &InputMatrix,
    estimates: &[State],
) -> Condition44Verdict {
    let lambdas: Vec<Input> = estimates
        .iter()
        .map(|x| g.transpose() * barrier.eval(x).gradient)
        .collect();
    let degenerate: Vec<usize> = lambdas
        .iter()
        .enumerate()
        .filter(|(_, l)| !(l.norm().is_finite() && l.norm() > 1e-12))
        .map(|(i, _)| i)
        .collect();
    let fail = |spread: f64, lambdas: Vec<Input>, degenerate: Vec<usize>| Condition44Verdict {
        lambdas,
        witness: None,
        margin: None,
        spread,
        degenerate,
        holds: false,
    };
    if !degenerate.is_empty() {
        return fail(f64::NAN, lambdas, degenerate);
    }
    if lambdas.is_empty() {
        return Condition44Verdict {
            lambdas,
            witness: Some(Input::new(1.0, 0.0)),
            margin: Some(1.0),
            spread: 0.0,
            degenerate,
            holds: true,
        };
    }
    // Angles sorted on the circle; the largest gap between neighbours (cyclically) is the arc
    // free of Λ's; the Λ's span the rest, 2π − gap. The witness bisects the spanned arc.
    let mut ang: Vec<f64> = lambdas.iter().map(|l| l[1].atan2(l[0])).collect();
    ang.sort_by(f64::total_cmp);
    let tau = std::f64::consts::TAU;
    let n = ang.len();
    let (mut gap, mut after) = (tau - (ang[n - 1] - ang[0]), 0usize);
    for k in 1..n {
        let d = ang[k] - ang[k - 1];
        if d > gap {
            gap = d;
            after = k;
        }
    }
    let spread = tau - gap;
    if spread >= std::f64::consts::PI {
        return fail(spread, lambdas, degenerate);
    }
    let start = ang[after];
    let mid = start + spread / 2.0;
    let u = Input::new(mid.cos(), mid.sin());
    let margin = lambdas
        .iter()
        .map(|l| l.dot(&u) / l.norm())
        .fold(f64::INFINITY, f64::min);
    let holds = margin > 0.0;
    Condition44Verdict {
        lambdas,
        witness: holds.then_some(u),
        margin: holds.then_some(margin),
        spread,
        degenerate,
        holds,
    }
}

impl fmt::Display for Condition44Verdict {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "condition (4.4): {} — {} estimate(s), ",
            if self.holds { "HOLDS" } else { "FAILS" },
            self.lambdas.len(),
        )?;
        if self.spread.is_finite() {
            write!(
                f,
                "angular spread of Λ_i = {:.4} rad (< π needed)",
                self.spread
            )?;
        } else {
            // A degenerate Λ_i has no direction: no spread to report, and (4.4) fails.
            write!(f, "angular spread of Λ_i undefined")?;
        }
        if let (Some(u), Some(m)) = (self.witness, self.margin) {
            write!(f, ", u = ({:.4}, {:.4}) with min cos = {m:.4}", u[0], u[1])?;
        }
        if !self.degenerate.is_empty() {
            write!(
                f,
                ", Λ_i = 0 or not finite at estimates {:?}",
                self.degenerate
            )?;
        }
        Ok(())
    }
}

// The sufficient conditions of §4.2 on the paper's closed-form sets (Lemma 1, Prop. 1, Thm. 5).

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
    use crate::barrier::{EllipsoidOutside, HalfPlane};
    use crate::model::LinearModel;
    use crate::types::StateMatrix;

    /// A barrier whose gradient is given directly (velocity block = Λ for the double integrator).
    #[derive(Debug)]
    struct Grad(Vec<(State, Input)>);
    impl Barrier for Grad {
        fn name(&self) -> &str {
            "grad"
        }
        fn eval(&self, x: &State) -> crate::barrier::BarrierEval {
            let l = self
                .0
                .iter()
                .find(|(s, _)| s == x)
                .map_or(Input::zeros(), |(_, l)| *l);
            crate::barrier::BarrierEval {
                value: 0.0,
                gradient: State::new(0.0, 0.0, l[0], l[1]),
                hessian: StateMatrix::zeros(),
            }
        }
        fn h_bar(&self, _g: f64) -> f64 {
            0.0
        }
    }

    fn verdict(dirs: &[(f64, f64)]) -> Condition44Verdict {
        let pts: Vec<(State, Input)> = dirs
            .iter()
            .enumerate()
            .map(|(i, &(a, b))| (State::new(i as f64, 0.0, 0.0, 0.0), Input::new(a, b)))
            .collect();
        let est: Vec<State> = pts.iter().map(|p| p.0).collect();
        condition_4_4(&Grad(pts), &LinearModel::double_integrator_g(), &est)
    }

    #[test]
    fn known_answers_in_the_plane() {
        // (1,0) and (0,1): spread π/2, witness the diagonal, min cos = cos(π/4)
        let v = verdict(&[(1.0, 0.0), (0.0, 2.0)]);
        assert!(v.holds);
        assert!((v.spread - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        let u = v.witness.unwrap();
        assert!(
            (u - Input::new(1.0, 1.0) / 2f64.sqrt()).norm() < 1e-12,
            "{u}"
        );
        assert!((v.margin.unwrap() - 0.5f64.sqrt()).abs() < 1e-12);
        // opposite vectors: no common direction
        assert!(!verdict(&[(1.0, 0.0), (-3.0, 0.0)]).holds);
        // three vectors spanning more than π (across the ±π cut)
        let v = verdict(&[(-1.0, 0.1), (-1.0, -0.1), (1.0, -0.2), (0.0, 1.0)]);
        assert!(!v.holds && v.spread > std::f64::consts::PI);
        // across the ±π cut but within a half-plane: witness points left
        let v = verdict(&[(-1.0, 0.5), (-1.0, -0.5)]);
        assert!(v.holds);
        assert!((v.witness.unwrap() - Input::new(-1.0, 0.0)).norm() < 1e-12);
        // a vanishing Λ fails and is named
        let v = verdict(&[(1.0, 0.0), (0.0, 0.0)]);
        assert!(!v.holds && v.degenerate == vec![1]);
        assert!(v.to_string().contains("FAILS"));
        assert!(verdict(&[]).holds);
    }

    #[test]
    fn half_planes_and_ellipsoids_that_the_paper_covers() {
        let g = LinearModel::double_integrator_g();
        // Lemma 1: aᵀG ≠ 0 → holds at any estimates
        let hp = HalfPlane::new("h", State::new(0.0, 1.0, 0.0, 0.2), 0.0);
        let est = [State::new(5.0, -3.0, 1.0, 2.0), State::zeros()];
        assert!(condition_4_4(&hp, &g, &est).holds);
        // position-only half-plane: aᵀG = 0 → Λ = 0, fails (relative degree 2)
        let hp0 = HalfPlane::new("h0", State::new(0.0, 1.0, 0.0, 0.0), 0.0);
        assert!(!condition_4_4(&hp0, &g, &est).holds);
        // a position ellipsoid (rank-2 Φ on position): ∂h/∂x G = 0 too
        let disc = EllipsoidOutside::disc("d", 0.0, 0.0, 1.0);
        assert!(!condition_4_4(&disc, &g, &est).holds);
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
