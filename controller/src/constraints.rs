//! The linear input constraints Ω_i (eq. 4.3) and Υ_i (eq. 5.2).
//!
//! With the gain terms of [`crate::estimator`] (`M = K c̄`, `N = K ν̄ν̄ᵀKᵀ`):
//!
//! Ω_i: `∂h(F x̂ + G u) − γ_i‖∂h M_i‖ + ½tr(∇²h N_i) ≥ −κ ĥ(x̂)`, `ĥ = h − h̄_γ`, i.e.
//! `Λ u ≥ ω̄` with `Λ = ∂h G`, `ω̄ = −κĥ − ∂h F x̂ + γ‖∂h M‖ − ½tr(∇²h N)`.
//! κ is the class-K gain of the CBF condition (the paper uses κ = 1).
//!
//! Υ_i: `∂V(F x̂ + G u) + γ_i‖∂V M_i‖ + ½tr(∇²V N_i) ≤ −ρ V(x̂)`, i.e. `Γ u ≤ τ̄` with
//! `Γ = ∂V G` ([`ClfRow::lg_v`], L_G V), `τ̄ = −ρV − ∂V F x̂ − γ‖∂V M‖ − ½tr(∇²V N)` (the strict inequality of 5.2 is
//! imposed as ≤).
//!
//! Both are returned as a [`HalfSpace`] `nᵀu ≤ o` for the QP.

use crate::barrier::BarrierEval;
use crate::lyapunov::QuadraticClf;
use crate::model::LinearModel;
use crate::types::{Input, State, StateMatrix};

/// A half-space of inputs `normalᵀ u ≤ offset`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HalfSpace {
    /// Normal n.
    pub normal: Input,
    /// Offset o.
    pub offset: f64,
}

impl HalfSpace {
    /// `nᵀu − o` (≤ 0 when satisfied).
    pub fn violation(&self, u: &Input) -> f64 {
        self.normal.dot(u) - self.offset
    }
}

/// Ω of one (filter, barrier): `Λ u ≥ ω̄`, with the numbers behind it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CbfRow {
    /// Λ = ∂h/∂x G.
    pub lambda: Input,
    /// ω̄.
    pub omega_bar: f64,
    /// h(x̂).
    pub h: f64,
    /// ĥ(x̂) = h(x̂) − h̄_γ.
    pub h_hat: f64,
}

impl CbfRow {
    /// As `−Λ u ≤ −ω̄`.
    pub fn half_space(&self) -> HalfSpace {
        HalfSpace {
            normal: -self.lambda,
            offset: -self.omega_bar,
        }
    }
}

/// Build Ω (eq. 4.3) for estimate `x_hat` with gain terms `m_drift` (K c̄) and `n_diff`
/// (Kν̄ν̄ᵀKᵀ), robustness γ, h̄_γ and class-K gain κ.
#[allow(clippy::too_many_arguments)]
pub fn cbf_row(
    model: &LinearModel,
    eval: &BarrierEval,
    x_hat: &State,
    m_drift: &StateMatrix,
    n_diff: &StateMatrix,
    gamma: f64,
    h_bar: f64,
    kappa: f64,
) -> CbfRow {
    let dh = eval.gradient;
    let lambda: Input = model.g.transpose() * dh;
    let drift = dh.dot(&(model.f * x_hat));
    let robust = gamma * (m_drift.transpose() * dh).norm();
    let ito = 0.5 * (eval.hessian * n_diff).trace();
    let h_hat = eval.value - h_bar;
    CbfRow {
        lambda,
        omega_bar: -kappa * h_hat - drift + robust - ito,
        h: eval.value,
        h_hat,
    }
}

/// Υ of one filter: `Γ u ≤ τ̄`, with V.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClfRow {
    /// L_G V = ∂V/∂x G, the row of u in the CLF condition (the thesis writes Γ; named apart
    /// from the error bound γ and the discretised input map Γ).
    pub lg_v: Input,
    /// τ̄.
    pub tau_bar: f64,
    /// V(x̂).
    pub v: f64,
}

impl ClfRow {
    /// As `Γ u ≤ τ̄`.
    pub fn half_space(&self) -> HalfSpace {
        HalfSpace {
            normal: self.lg_v,
            offset: self.tau_bar,
        }
    }
}

/// Build Υ (eq. 5.2) for estimate `x_hat`.
pub fn clf_row(
    model: &LinearModel,
    clf: &QuadraticClf,
    x_hat: &State,
    m_drift: &StateMatrix,
    n_diff: &StateMatrix,
    gamma: f64,
) -> ClfRow {
    let dv = clf.gradient(x_hat);
    let v = clf.value(x_hat);
    let lg_v: Input = model.g.transpose() * dv;
    let drift = dv.dot(&(model.f * x_hat));
    let robust = gamma * (m_drift.transpose() * dv).norm();
    let ito = 0.5 * (clf.hessian() * n_diff).trace();
    ClfRow {
        lg_v,
        tau_bar: -clf.rho * v - drift - robust - ito,
        v,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::barrier::{Barrier, EllipsoidInside, HalfPlane};

    #[test]
    fn half_plane_row_by_hand() {
        let model = LinearModel::paper_double_integrator(1e-3, 1e-3).unwrap();
        let hp = HalfPlane::new("h", State::new(0.0, 1.0, 0.0, 0.2), -0.05);
        let x = State::new(1.0, 0.1, 0.3, -0.5);
        let mut m = StateMatrix::zeros();
        m[(1, 1)] = 3.0; // aᵀM = (0, 3, 0, 0)
        let row = cbf_row(
            &model,
            &hp.eval(&x),
            &x,
            &m,
            &StateMatrix::identity(),
            0.01,
            hp.h_bar(0.01),
            1.0,
        );
        assert_eq!(row.lambda, Input::new(0.0, 0.2));
        let h = 0.1 - 0.1 + 0.05;
        let h_hat = h - 0.01 * (1.04f64).sqrt();
        // ∂hFx = a·(vx, vy, 0, 0) = vy = −0.5; robust = 0.01·3; ito = 0
        let omega = -h_hat + 0.5 + 0.03;
        assert!((row.omega_bar - omega).abs() < 1e-14);
        assert!((row.h - h).abs() < 1e-15);
    }

    #[test]
    fn ellipsoid_ito_term_enters() {
        let model = LinearModel::paper_double_integrator(1e-3, 1e-3).unwrap();
        let e = EllipsoidInside::new("e", State::zeros(), StateMatrix::identity());
        let x = State::new(0.5, 0.0, 0.0, 0.0);
        let n = StateMatrix::identity() * 0.1;
        let row = cbf_row(
            &model,
            &e.eval(&x),
            &x,
            &StateMatrix::zeros(),
            &n,
            0.0,
            0.0,
            1.0,
        );
        // h = 0.75, ∂hFx = 0 (v = 0), ito = ½ tr(−2I · 0.1I) = −0.4 → ω̄ = −0.75 + 0.4
        assert!((row.omega_bar - (-0.35)).abs() < 1e-14);
    }
}
