//! Closed-form safe sets of a world file that act on the position only, lifted to relative
//! degree 2 (§4.2.1): an ellipse h(p) = ±(1 − (p − c)ᵀΦ(p − c)) does not involve the velocity,
//! so ∂h/∂x · G = 0 and no input appears in its CBF condition. The lift
//! H(x) = h(p) + k·ḣ = h(p) + k·∇h(p)·v makes the input appear (∂H/∂v = k∇h).

use ftcbf_controller::{Barrier, BarrierEval, State, StateMatrix};
use nalgebra::{Matrix2, Vector2};

/// Φ (2×2) of an ellipse with semi-axes `semi` along its own axes, rotated by `angle` [rad]:
/// the ellipse is {p : (p − c)ᵀΦ(p − c) = 1}.
pub fn ellipse_phi(semi: [f64; 2], angle: f64) -> Matrix2<f64> {
    let (s, c) = angle.sin_cos();
    let r = Matrix2::new(c, -s, s, c);
    let d = Matrix2::new(
        1.0 / (semi[0] * semi[0]),
        0.0,
        0.0,
        1.0 / (semi[1] * semi[1]),
    );
    r * d * r.transpose()
}

/// The same ellipse as a 4×4 Φ over the planar state (position block only), as the paper's
/// ellipsoid results (Prop. 1, Thm. 5) take it.
pub fn ellipse_phi_state(semi: [f64; 2], angle: f64) -> StateMatrix {
    let mut phi = StateMatrix::zeros();
    phi.fixed_view_mut::<2, 2>(0, 0)
        .copy_from(&ellipse_phi(semi, angle));
    phi
}

/// The inside (arena) or outside (keep-out zone) of an ellipse over the position, lifted.
#[derive(Debug, Clone)]
pub struct LiftedEllipse {
    name: String,
    center: Vector2<f64>,
    phi: Matrix2<f64>,
    /// +1: inside is safe; −1: outside is safe.
    sign: f64,
    /// Lift gain k [s].
    k: f64,
    /// Speed bound used in the h̄_γ bound [m/s].
    v_max: f64,
}

impl LiftedEllipse {
    /// Ellipse with centre `center`, semi-axes `semi` along its own axes, rotated by `angle` [rad]
    /// from the world x axis; `inside` selects which side is safe. `k` ≥ 0 is the lift gain.
    pub fn new(
        name: impl Into<String>,
        center: [f64; 2],
        semi: [f64; 2],
        angle: f64,
        inside: bool,
        k: f64,
        v_max: f64,
    ) -> Self {
        Self {
            name: name.into(),
            center: Vector2::new(center[0], center[1]),
            phi: ellipse_phi(semi, angle),
            sign: if inside { 1.0 } else { -1.0 },
            k,
            v_max,
        }
    }

    /// The un-lifted h(p) (its zero set is the ellipse).
    pub fn position_value(&self, p: Vector2<f64>) -> f64 {
        let d = p - self.center;
        self.sign * (1.0 - d.dot(&(self.phi * d)))
    }

    /// Largest semi-axis [m].
    fn major(&self) -> f64 {
        let l = self.phi.symmetric_eigen().eigenvalues;
        1.0 / l.min().sqrt()
    }
}

impl Barrier for LiftedEllipse {
    fn name(&self) -> &str {
        &self.name
    }

    fn eval(&self, x: &State) -> BarrierEval {
        let d = Vector2::new(x[0], x[1]) - self.center;
        let v = Vector2::new(x[2], x[3]);
        let s = self.sign;
        let k = self.k;
        // h = s(1 − dᵀΦd), ∇h = −2sΦd, ∇²h = −2sΦ (third derivatives vanish: the lift is exact).
        let h = s * (1.0 - d.dot(&(self.phi * d)));
        let g = -2.0 * s * (self.phi * d);
        let hh = -2.0 * s * self.phi;
        let value = h + k * g.dot(&v);
        let gp = g + k * (hh * v);
        let gv = k * g;
        let mut hess = StateMatrix::zeros();
        hess.fixed_view_mut::<2, 2>(0, 0).copy_from(&hh);
        hess.fixed_view_mut::<2, 2>(0, 2).copy_from(&(k * hh));
        hess.fixed_view_mut::<2, 2>(2, 0).copy_from(&(k * hh));
        BarrierEval {
            value,
            gradient: State::new(gp.x, gp.y, gv.x, gv.y),
            hessian: hess,
        }
    }

    /// γ·L with L a bound of ‖∇H‖ over positions within the ellipse's bounding disc and speeds
    /// up to `v_max`: ‖∇_p H‖ ≤ 2λ̄(a + k·v_max), ‖∇_v H‖ ≤ 2kλ̄a (a = major semi-axis). An
    /// upper bound of h̄_γ, hence conservative.
    fn h_bar(&self, gamma: f64) -> f64 {
        let lmax = self.phi.symmetric_eigen().eigenvalues.max();
        let a = self.major();
        let gp = 2.0 * lmax * (a + self.k * self.v_max);
        let gv = 2.0 * self.k * lmax * a;
        gamma * (gp * gp + gv * gv).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn numeric_grad(b: &dyn Barrier, x: &State) -> State {
        let e = 1e-6;
        State::from_fn(|i, _| {
            let mut xp = *x;
            let mut xm = *x;
            xp[i] += e;
            xm[i] -= e;
            (b.eval(&xp).value - b.eval(&xm).value) / (2.0 * e)
        })
    }

    #[test]
    fn gradient_and_hessian_match_finite_differences() {
        for inside in [true, false] {
            let b = LiftedEllipse::new("e", [0.3, -0.2], [2.0, 1.0], 0.4, inside, 0.5, 0.3);
            let x = State::new(0.9, 0.4, 0.1, -0.2);
            let ev = b.eval(&x);
            let ng = numeric_grad(&b, &x);
            assert!(
                (ev.gradient - ng).amax() < 1e-6,
                "{} vs {}",
                ev.gradient,
                ng
            );
            let e = 1e-5;
            for i in 0..4 {
                let mut xp = x;
                let mut xm = x;
                xp[i] += e;
                xm[i] -= e;
                let col = (b.eval(&xp).gradient - b.eval(&xm).gradient) / (2.0 * e);
                assert!((ev.hessian.column(i) - col).amax() < 1e-6);
            }
        }
    }

    #[test]
    fn zero_set_is_the_ellipse_at_rest_and_sides_are_right() {
        let b = LiftedEllipse::new("arena", [0.0, 0.0], [2.0, 1.0], 0.0, true, 0.5, 0.3);
        assert!(b.eval(&State::new(2.0, 0.0, 0.0, 0.0)).value.abs() < 1e-12);
        assert!(b.eval(&State::new(0.0, 1.0, 0.0, 0.0)).value.abs() < 1e-12);
        assert!(b.eval(&State::zeros()).value > 0.0);
        assert!(b.eval(&State::new(2.5, 0.0, 0.0, 0.0)).value < 0.0);
        // Moving outward lowers H, inward raises it.
        let out = b.eval(&State::new(1.0, 0.0, 0.2, 0.0)).value;
        let inn = b.eval(&State::new(1.0, 0.0, -0.2, 0.0)).value;
        assert!(out < inn);
        let o = LiftedEllipse::new("rock", [0.0, 0.0], [0.5, 0.5], 0.0, false, 0.5, 0.3);
        assert!(o.eval(&State::zeros()).value < 0.0);
        assert!(o.eval(&State::new(1.0, 0.0, 0.0, 0.0)).value > 0.0);
    }

    #[test]
    fn h_bar_bounds_the_sup_near_the_boundary() {
        let b = LiftedEllipse::new("arena", [0.0, 0.0], [2.0, 1.0], 0.3, true, 0.5, 0.3);
        let gamma = 0.05;
        let bound = b.h_bar(gamma);
        // Sample points at distance ≤ γ from rest states on the boundary.
        let mut worst: f64 = 0.0;
        for i in 0..360 {
            let a = i as f64 * std::f64::consts::TAU / 360.0;
            let (s, c) = 0.3f64.sin_cos();
            let (px, py) = (2.0 * a.cos(), 1.0 * a.sin());
            let p0 = [c * px - s * py, s * px + c * py];
            for j in 0..16 {
                let dir = j as f64 * std::f64::consts::TAU / 16.0;
                for (dv, dp) in [(0.0, 1.0), (0.7, 0.7), (1.0, 0.0)] {
                    let x = State::new(
                        p0[0] + gamma * dp * dir.cos(),
                        p0[1] + gamma * dp * dir.sin(),
                        gamma * dv * dir.cos(),
                        gamma * dv * dir.sin(),
                    );
                    worst = worst.max(b.eval(&x).value);
                }
            }
        }
        assert!(
            worst > 0.0 && worst <= bound,
            "sup {worst} vs bound {bound}"
        );
    }
}
