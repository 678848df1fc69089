//! Barrier functions h(x) with value, gradient and Hessian (safe set C = {x : h(x) ≥ 0}, eq. 3.3).

use crate::types::{State, StateMatrix};

/// h, ∂h/∂x and ∂²h/∂x² evaluated at one state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BarrierEval {
    /// h(x); the safe set is h ≥ 0.
    pub value: f64,
    /// ∂h/∂x (as a column vector).
    pub gradient: State,
    /// ∂²h/∂x².
    pub hessian: StateMatrix,
}

/// A barrier function over the planar state. Implemented in closed form here (half-plane,
/// ellipsoid inside/outside, the relative-degree-2 lift of §4.2.1) and from obstacle geometry
/// in the simulator (signed distance to a parry shape).
pub trait Barrier: Send + Sync + std::fmt::Debug {
    /// A stable, human-readable name (used in logs and decision records).
    fn name(&self) -> &str;
    /// Value, gradient and Hessian at `x`.
    fn eval(&self, x: &State) -> BarrierEval;
    /// h̄_γ of Theorem 2/3: sup { h(x) : ‖x − x⁰‖₂ ≤ γ for some x⁰ with h(x⁰) = 0 }.
    /// Closed form where known (γ‖a‖ for a half-plane, Prop. 3 for an ellipsoid); an upper
    /// bound (γ times a Lipschitz constant of h) otherwise — an upper bound is conservative.
    fn h_bar(&self, gamma: f64) -> f64;
    /// The moving obstacle whose reading this barrier needs (an index into the readings of
    /// [`Barrier::eval_moving`]); `None` for a barrier that does not depend on time.
    fn mover(&self) -> Option<usize> {
        None
    }
    /// h(x, t), its derivatives in x and a lower bound of ∂h/∂t at the instant the obstacle
    /// readings `movers` describe. A time-invariant barrier: [`Barrier::eval`] and ∂h/∂t = 0.
    fn eval_moving(&self, x: &State, movers: &[MoverState]) -> (BarrierEval, f64) {
        let _ = movers;
        (self.eval(x), 0.0)
    }
}

/// A moving obstacle as the controller reads it at one instant (issue #51): where it is
/// relative to where its barrier was built, how fast it moves, and a bound on its
/// acceleration. Known exactly from the script for a scripted path; a walker's is read from
/// the simulator's crowd in this first version (also exact: no obstacle sensor, no attack).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct MoverState {
    /// Displacement from the pose its barrier was built at, world frame \[m\].
    pub displacement: [f64; 2],
    /// Velocity, world frame \[m/s\].
    pub velocity: [f64; 2],
    /// Bound on the norm of its acceleration \[m/s²\] (0 for a piecewise-constant velocity:
    /// the jumps at a path's corners are not covered, see the book's moving-obstacles page).
    pub accel_bound: f64,
    /// γ_p: bound on the error of `displacement` \[m\] (0 for an exact reading; a tracked
    /// mover's, see [`crate::mover_track`]).
    pub position_bound: f64,
    /// γ_v: bound on the error of `velocity` \[m/s\] (0 for an exact reading).
    pub velocity_bound: f64,
}

/// A barrier that moves with an obstacle by translation: h(x, t) = h₀(p − δ(t), v − v_c(t))
/// with δ the obstacle's displacement and v_c its velocity (so a velocity lift on h₀ is on
/// the relative velocity). With h₀'s gradient (∇_p, ∇_v) at the shifted state,
/// ∂h/∂t = −∇_p h₀·v_c − ∇_v h₀·a_c ≥ −∇_p h₀·v_c − ‖∇_v h₀‖·ā, the bound returned.
///
/// A reading with error bounds γ_p, γ_v (a tracked mover): h is lowered by
/// ‖∇_p h₀‖·γ_p + ‖∇_v h₀‖·γ_v (to first order, the most the true h can be below the one at the
/// estimate) and ∂h/∂t by ‖∇_p h₀‖·γ_v (the true velocity may differ from the estimate by γ_v);
/// the gradient and Hessian stay those of h₀ at the estimate. Exact readings (both 0) give h₀
/// and the bound above unchanged, bit for bit; a NaN bound makes h NaN (the row fails closed).
#[derive(Debug, Clone)]
pub struct MovingBarrier {
    base: std::sync::Arc<dyn Barrier>,
    mover: usize,
}

impl MovingBarrier {
    /// `base` (the obstacle's barrier at its starting pose) moved by reading `mover`.
    pub fn new(base: std::sync::Arc<dyn Barrier>, mover: usize) -> Self {
        Self { base, mover }
    }
}

impl Barrier for MovingBarrier {
    fn name(&self) -> &str {
        self.base.name()
    }
    /// h at the obstacle's starting pose, standing still (without a reading).
    fn eval(&self, x: &State) -> BarrierEval {
        self.base.eval(x)
    }
    /// The base's bound: it must be built for the relative speed (the robot's bound plus the
    /// obstacle's largest speed).
    fn h_bar(&self, gamma: f64) -> f64 {
        self.base.h_bar(gamma)
    }
    fn mover(&self) -> Option<usize> {
        Some(self.mover)
    }
    /// Without its reading, h is NaN (the row fails closed).
    fn eval_moving(&self, x: &State, movers: &[MoverState]) -> (BarrierEval, f64) {
        let Some(m) = movers.get(self.mover) else {
            let nan = BarrierEval {
                value: f64::NAN,
                gradient: State::repeat(f64::NAN),
                hessian: StateMatrix::repeat(f64::NAN),
            };
            return (nan, f64::NAN);
        };
        let shifted = x - State::new(
            m.displacement[0],
            m.displacement[1],
            m.velocity[0],
            m.velocity[1],
        );
        let mut e = self.base.eval(&shifted);
        let g = e.gradient;
        let mut dh_dt =
            -(g[0] * m.velocity[0] + g[1] * m.velocity[1]) - g[2].hypot(g[3]) * m.accel_bound;
        if !(m.position_bound == 0.0 && m.velocity_bound == 0.0) {
            let (gp, gv) = (g[0].hypot(g[1]), g[2].hypot(g[3]));
            e.value -= gp * m.position_bound + gv * m.velocity_bound;
            dh_dt -= gp * m.velocity_bound;
        }
        (e, dh_dt)
    }
}

// ---------------------------------------------------------------------------------------------
// Closed-form barriers (added by the controller crate; the trait above is unchanged).
// ---------------------------------------------------------------------------------------------

/// Largest eigenvalue of a symmetric 4×4 matrix (0 for the zero matrix).
fn lambda_max_sym(m: &StateMatrix) -> f64 {
    let sym = (m + m.transpose()) * 0.5;
    sym.symmetric_eigenvalues().max()
}

/// Half-plane safe set `h(x) = aᵀx − b ≥ 0` (§4.2.1).
#[derive(Debug, Clone, PartialEq)]
pub struct HalfPlane {
    name: String,
    /// Normal `a` (the gradient of h).
    pub a: State,
    /// Offset `b`.
    pub b: f64,
}

impl HalfPlane {
    /// `h(x) = aᵀx − b`.
    pub fn new(name: impl Into<String>, a: State, b: f64) -> Self {
        Self {
            name: name.into(),
            a,
            b,
        }
    }
}

impl Barrier for HalfPlane {
    fn name(&self) -> &str {
        &self.name
    }
    fn eval(&self, x: &State) -> BarrierEval {
        BarrierEval {
            value: self.a.dot(x) - self.b,
            gradient: self.a,
            hessian: StateMatrix::zeros(),
        }
    }
    /// Exact: `h̄_γ = γ‖a‖₂` (h grows fastest along `a`).
    fn h_bar(&self, gamma: f64) -> f64 {
        gamma * self.a.norm()
    }
}

/// Ellipsoidal safe set, inside: `h(x) = 1 − (x − x')ᵀΦ(x − x') ≥ 0` (§4.2.2).
/// Φ must be symmetric positive semidefinite (positive definite in the paper; a PSD Φ
/// gives an elliptic cylinder, which is handled by the same formulas).
#[derive(Debug, Clone, PartialEq)]
pub struct EllipsoidInside {
    name: String,
    /// Centre x'.
    pub center: State,
    /// Shape matrix Φ (symmetric PSD).
    pub phi: StateMatrix,
    lambda_max: f64,
}

impl EllipsoidInside {
    /// `h(x) = 1 − (x − center)ᵀ Φ (x − center)`; Φ is symmetrised.
    pub fn new(name: impl Into<String>, center: State, phi: StateMatrix) -> Self {
        let phi = (phi + phi.transpose()) * 0.5;
        let lambda_max = lambda_max_sym(&phi);
        Self {
            name: name.into(),
            center,
            phi,
            lambda_max,
        }
    }
}

impl Barrier for EllipsoidInside {
    fn name(&self) -> &str {
        &self.name
    }
    fn eval(&self, x: &State) -> BarrierEval {
        let e = x - self.center;
        let pe = self.phi * e;
        BarrierEval {
            value: 1.0 - e.dot(&pe),
            gradient: -2.0 * pe,
            hessian: -2.0 * self.phi,
        }
    }
    /// Exact, Proposition 3: `1` if `γ ≥ 1/√λ̄(Φ)`, else `1 − (1 − γ√λ̄(Φ))²`.
    fn h_bar(&self, gamma: f64) -> f64 {
        let s = gamma * self.lambda_max.max(0.0).sqrt();
        if s >= 1.0 {
            1.0
        } else {
            1.0 - (1.0 - s) * (1.0 - s)
        }
    }
}

/// Ellipsoidal obstacle, safe outside: `h(x) = (x − x')ᵀΦ(x − x') − 1 ≥ 0`.
///
/// For a round obstacle of radius r at position c, use `Φ = diag(1/r², 1/r², 0, 0)`: a PSD
/// matrix of rank 2 acting on position only (the set is a cylinder in state space).
#[derive(Debug, Clone, PartialEq)]
pub struct EllipsoidOutside {
    name: String,
    /// Centre x'.
    pub center: State,
    /// Shape matrix Φ (symmetric PSD; rank 2 on position is the usual case).
    pub phi: StateMatrix,
    lambda_max: f64,
}

impl EllipsoidOutside {
    /// `h(x) = (x − center)ᵀ Φ (x − center) − 1`; Φ is symmetrised.
    pub fn new(name: impl Into<String>, center: State, phi: StateMatrix) -> Self {
        let phi = (phi + phi.transpose()) * 0.5;
        let lambda_max = lambda_max_sym(&phi);
        Self {
            name: name.into(),
            center,
            phi,
            lambda_max,
        }
    }

    /// A disc obstacle of `radius` (m) centred at `(px, py)` in the world frame.
    pub fn disc(name: impl Into<String>, px: f64, py: f64, radius: f64) -> Self {
        let k = 1.0 / (radius * radius);
        Self::new(
            name,
            State::new(px, py, 0.0, 0.0),
            StateMatrix::from_diagonal(&State::new(k, k, 0.0, 0.0)),
        )
    }
}

impl Barrier for EllipsoidOutside {
    fn name(&self) -> &str {
        &self.name
    }
    fn eval(&self, x: &State) -> BarrierEval {
        let e = x - self.center;
        let pe = self.phi * e;
        BarrierEval {
            value: e.dot(&pe) - 1.0,
            gradient: 2.0 * pe,
            hessian: 2.0 * self.phi,
        }
    }
    /// Exact for the outside case: `h̄_γ = (1 + γ√λ̄(Φ))² − 1`.
    ///
    /// Upper bound: with z = Φ^½(x − x'), ‖z‖ ≤ ‖Φ^½(x⁰ − x')‖ + ‖Φ^½(x − x⁰)‖ ≤ 1 + γ√λ̄.
    /// Attained by x⁰ = x' + v/√λ̄ and x = x⁰ + γv with v the unit eigenvector of λ̄.
    /// Unlike the inside case there is no saturation: h is unbounded outside.
    fn h_bar(&self, gamma: f64) -> f64 {
        let s = gamma * self.lambda_max.max(0.0).sqrt();
        (1.0 + s) * (1.0 + s) - 1.0
    }
}

/// The relative-degree lift of §4.2.1 for a half-plane `h₀ = aᵀx − b` with `aᵀG = 0`:
///
/// `h₁(x) = ∂h₀/∂x F x + ½tr(σᵀ∇²h₀σ) − γ‖∂h₀/∂x K c‖ + h₀(x)
///        = (Fᵀa + a)ᵀx − b − γ‖aᵀ K c‖`   (∇²h₀ = 0 for a half-plane).
///
/// `K c` is the continuous-time-equivalent gain product of the filter whose estimate the
/// constraint uses; this crate uses the **steady-state** value `P∞⁺ c̄ᵀ R⁻¹ c̄ / dt` (see
/// [`crate::params::steady_state_gain_product`]), so h₁ is again a half-plane and its
/// h̄_γ is exact (γ‖Fᵀa + a‖). By Theorem 4, imposing the CBF condition on h₁ keeps
/// `h₀ ≥ 0` provided `x₀ ∈ C₀ ∩ C₁`; [`HigherOrderHalfPlane::base`] gives h₀ for logging.
#[derive(Debug, Clone, PartialEq)]
pub struct HigherOrderHalfPlane {
    base: HalfPlane,
    lifted: HalfPlane,
}

impl HigherOrderHalfPlane {
    /// Build h₁ from h₀ = `base`, the drift matrix `f`, the gain product `kc` (n×n) and γ.
    pub fn new(base: HalfPlane, f: &StateMatrix, kc: &StateMatrix, gamma: f64) -> Self {
        let a1 = f.transpose() * base.a + base.a;
        let b1 = base.b + gamma * (kc.transpose() * base.a).norm();
        let lifted = HalfPlane::new(format!("{}-lift1", base.name), a1, b1);
        Self { base, lifted }
    }
    /// The original barrier h₀.
    pub fn base(&self) -> &HalfPlane {
        &self.base
    }
    /// The lifted barrier h₁ as a half-plane.
    pub fn lifted(&self) -> &HalfPlane {
        &self.lifted
    }
}

impl Barrier for HigherOrderHalfPlane {
    fn name(&self) -> &str {
        self.lifted.name()
    }
    fn eval(&self, x: &State) -> BarrierEval {
        self.lifted.eval(x)
    }
    /// Exact for the lifted half-plane: γ‖Fᵀa + a‖.
    fn h_bar(&self, gamma: f64) -> f64 {
        self.lifted.h_bar(gamma)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::types::InputMatrix;

    #[test]
    fn higher_order_lift_of_a_position_half_plane() {
        // h₀ = y − 0.3 has aᵀG = 0 for the double integrator; h₁ = y + ẏ − 0.3 − γ‖aᵀKc‖.
        let f = crate::model::LinearModel::double_integrator_f();
        let g: InputMatrix = crate::model::LinearModel::double_integrator_g();
        let base = HalfPlane::new("y>=0.3", State::new(0.0, 1.0, 0.0, 0.0), 0.3);
        let mut kc = StateMatrix::zeros();
        kc[(1, 1)] = 4.0;
        let lift = HigherOrderHalfPlane::new(base, &f, &kc, 0.01);
        assert_eq!(lift.lifted().a, State::new(0.0, 1.0, 0.0, 1.0));
        assert!((lift.lifted().b - (0.3 + 0.04)).abs() < 1e-15);
        let lambda = g.transpose() * lift.eval(&State::zeros()).gradient;
        assert_eq!(lambda, crate::types::Input::new(0.0, 1.0));
        assert!((lift.h_bar(0.1) - 0.1 * 2f64.sqrt()).abs() < 1e-15);
        assert_eq!(lift.base().a, State::new(0.0, 1.0, 0.0, 0.0));
    }

    /// A disc moving at (0.3, 0): h and ∂h/∂t of the moved barrier are those of the disc at
    /// its new place, and ∂h/∂t is −∇h·v_c (minus the acceleration term).
    #[test]
    fn a_moving_disc_is_the_disc_moved_with_its_time_derivative() {
        let disc: std::sync::Arc<dyn Barrier> =
            std::sync::Arc::new(EllipsoidOutside::disc("d", 0.0, 0.0, 1.0));
        let m = MovingBarrier::new(disc, 1);
        assert_eq!(m.mover(), Some(1));
        let reading = MoverState {
            displacement: [1.0, 0.0],
            velocity: [0.3, 0.0],
            accel_bound: 0.0,
            ..MoverState::default()
        };
        let x = State::new(3.0, 0.0, 0.0, 0.0);
        let (e, dh_dt) = m.eval_moving(&x, &[MoverState::default(), reading]);
        // Distance 2 from the moved centre: h = 4 − 1 = 3, ∇_p h = (4, 0).
        assert!((e.value - 3.0).abs() < 1e-12);
        assert!((dh_dt - (-4.0 * 0.3)).abs() < 1e-12);
        // Without its reading the row fails closed.
        assert!(m.eval_moving(&x, &[]).0.value.is_nan());
        // A static barrier: eval and 0.
        let d = EllipsoidOutside::disc("s", 0.0, 0.0, 1.0);
        assert_eq!(d.eval_moving(&x, &[reading]), (d.eval(&x), 0.0));
        // A tracked reading with γ_p = 0.1 m, γ_v = 0.05 m/s: h lowered by ‖∇_p h‖γ_p = 0.4
        // (∇_v h = 0 for a disc on position), ∂h/∂t by ‖∇_p h‖γ_v = 0.2.
        let tracked = MoverState {
            position_bound: 0.1,
            velocity_bound: 0.05,
            ..reading
        };
        let (t, t_dt) = m.eval_moving(&x, &[MoverState::default(), tracked]);
        assert!((t.value - (3.0 - 0.4)).abs() < 1e-12, "{}", t.value);
        assert!((t_dt - (-1.2 - 0.2)).abs() < 1e-12, "{t_dt}");
        assert_eq!(t.gradient, e.gradient);
        let broken = MoverState {
            position_bound: f64::NAN,
            ..reading
        };
        assert!(m
            .eval_moving(&x, &[MoverState::default(), broken])
            .0
            .value
            .is_nan());
    }

    #[test]
    fn ellipsoid_values_gradients_and_disc() {
        let d = EllipsoidOutside::disc("disc", 1.0, 2.0, 0.5);
        let x = State::new(1.5, 2.0, 3.0, -1.0);
        let e = d.eval(&x);
        assert!(e.value.abs() < 1e-15); // on the boundary; velocities do not matter
        assert_eq!(e.gradient, State::new(4.0, 0.0, 0.0, 0.0));
        // rank-2 Φ: λ̄ = 4, h̄ = (1 + 2γ)² − 1
        assert!((d.h_bar(0.1) - (1.2f64 * 1.2 - 1.0)).abs() < 1e-14);
        let inside = EllipsoidInside::new("in", State::zeros(), StateMatrix::identity() * 4.0);
        assert!((inside.h_bar(0.1) - (1.0 - 0.8 * 0.8)).abs() < 1e-14);
        assert_eq!(inside.h_bar(0.5), 1.0);
    }
}
