//! Quadratic control Lyapunov function of eq. 6.6.
//!
//! `V(x) = (x − x_g)ᵀ P_d (x − x_g)` with
//! `P_d = s · D P_L D`, `D = diag(1/d, 1/d, 1, 1)` (the d-scaling of eq. 6.6, position rows
//! scaled by the goal radius d), `s` the paper's scale (1e8) and P_L solving
//! `AᵀP_L + P_L A = −I`.
//!
//! **Which A.** The paper leaves A implicit. F of the double integrator is not Hurwitz (the
//! Lyapunov equation has no PD solution), so this crate uses the closed loop
//! `A = F − G K` with a stated stabilising gain K; the default is
//! [`crate::model::double_integrator_lqr_gain`] (the LQR gain for weights I, I). The solver
//! [`solve_lyapunov`] is general (Kronecker / vectorisation), not specialised to one A.
//!
//! `ρ = 1/(d λ̄(P_d))` (the paper's choice) unless overridden.

use nalgebra::{DMatrix, Matrix2x4};
use thiserror::Error;

use crate::types::{InputMatrix, State, StateMatrix};

/// Errors of the Lyapunov construction.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum LyapunovError {
    /// A is not square or Q has another size.
    #[error("Lyapunov equation needs square A and Q of the same size (A is {a_rows}×{a_cols}, Q is {q_rows}×{q_cols})")]
    Shape {
        /// Rows of A.
        a_rows: usize,
        /// Columns of A.
        a_cols: usize,
        /// Rows of Q.
        q_rows: usize,
        /// Columns of Q.
        q_cols: usize,
    },
    /// The Kronecker system is singular (A has eigenvalues λ_i + λ_j = 0).
    #[error("Lyapunov equation AᵀP + PA = −Q is singular (A has eigenvalue pairs summing to 0)")]
    Singular,
    /// The closed loop is not Hurwitz, so P is not positive definite.
    #[error("closed loop A = F − G K is not Hurwitz (max real part of eigenvalues {max_real_part}); choose a stabilising gain")]
    NotHurwitz {
        /// Largest real part of the eigenvalues of A.
        max_real_part: f64,
    },
    /// A configuration value out of range.
    #[error("CLF parameter {key} = {value} is invalid: {expected}")]
    BadParameter {
        /// The key.
        key: &'static str,
        /// The value.
        value: f64,
        /// What was expected.
        expected: &'static str,
    },
}

/// Solve `AᵀP + PA = −Q` for P by vectorisation:
/// `(I ⊗ Aᵀ + Aᵀ ⊗ I) vec(P) = −vec(Q)` (column-major vec), for any square A.
pub fn solve_lyapunov(a: &DMatrix<f64>, q: &DMatrix<f64>) -> Result<DMatrix<f64>, LyapunovError> {
    let n = a.nrows();
    if a.ncols() != n || q.nrows() != n || q.ncols() != n {
        return Err(LyapunovError::Shape {
            a_rows: a.nrows(),
            a_cols: a.ncols(),
            q_rows: q.nrows(),
            q_cols: q.ncols(),
        });
    }
    let at = a.transpose();
    let eye = DMatrix::<f64>::identity(n, n);
    let k = eye.kronecker(&at) + at.kronecker(&eye);
    let rhs = -DMatrix::from_column_slice(n * n, 1, q.as_slice());
    let lu = k.lu();
    let sol = lu.solve(&rhs).ok_or(LyapunovError::Singular)?;
    if sol.iter().any(|v| !v.is_finite()) {
        return Err(LyapunovError::Singular);
    }
    let p = DMatrix::from_column_slice(n, n, sol.as_slice());
    Ok((&p + p.transpose()) * 0.5)
}

/// Configuration of the CLF.
#[derive(Debug, Clone, PartialEq)]
pub struct ClfConfig {
    /// V̄: CLF rows are imposed only for filters with V(x̂) > V̄ (Y_t(V̄) of §5.1).
    pub v_bar: f64,
    /// The scale s of P_d (the paper uses 1e8).
    pub scale: f64,
    /// Stabilising gain K for the closed loop A = F − G K.
    pub gain: Matrix2x4<f64>,
    /// Override of the decay rate ρ; `None` uses the paper's ρ = 1/(d λ̄(P_d)).
    pub rho: Option<f64>,
}

impl ClfConfig {
    /// The paper's CLF: scale 1e8, LQR gain, ρ = 1/(d λ̄(P_d)), with the given V̄.
    pub fn paper(v_bar: f64) -> Self {
        Self {
            v_bar,
            scale: 1e8,
            gain: crate::model::double_integrator_lqr_gain(),
            rho: None,
        }
    }
}

/// The quadratic CLF `V = (x − x_g)ᵀ P_d (x − x_g)`.
#[derive(Debug, Clone, PartialEq)]
pub struct QuadraticClf {
    /// Goal state x_g.
    pub goal: State,
    /// P_d.
    pub p_d: StateMatrix,
    /// P_L (solution of AᵀP_L + P_L A = −I).
    pub p_l: StateMatrix,
    /// Decay rate ρ.
    pub rho: f64,
    /// V̄.
    pub v_bar: f64,
}

impl QuadraticClf {
    /// Build from the drift F, input matrix G, goal, goal radius d and configuration.
    pub fn new(
        f: &StateMatrix,
        g: &InputMatrix,
        goal: State,
        d: f64,
        cfg: &ClfConfig,
    ) -> Result<Self, LyapunovError> {
        if !(d.is_finite() && d > 0.0) {
            return Err(LyapunovError::BadParameter {
                key: "goal_radius",
                value: d,
                expected: "finite and > 0 [m]",
            });
        }
        if !(cfg.scale.is_finite() && cfg.scale > 0.0) {
            return Err(LyapunovError::BadParameter {
                key: "clf.scale",
                value: cfg.scale,
                expected: "finite and > 0",
            });
        }
        if !(cfg.v_bar.is_finite() && cfg.v_bar >= 0.0) {
            return Err(LyapunovError::BadParameter {
                key: "clf.v_bar",
                value: cfg.v_bar,
                expected: "finite and ≥ 0",
            });
        }
        let a = f - g * cfg.gain;
        let max_real_part = a
            .complex_eigenvalues()
            .iter()
            .map(|l| l.re)
            .fold(f64::NEG_INFINITY, f64::max);
        if max_real_part.is_nan() || max_real_part >= 0.0 {
            return Err(LyapunovError::NotHurwitz { max_real_part });
        }
        let ad = DMatrix::from_column_slice(4, 4, a.as_slice());
        let pl = solve_lyapunov(&ad, &DMatrix::identity(4, 4))?;
        let p_l = StateMatrix::from_column_slice(pl.as_slice());
        let dm = StateMatrix::from_diagonal(&State::new(1.0 / d, 1.0 / d, 1.0, 1.0));
        let p_d = dm * p_l * dm * cfg.scale;
        let lmax = p_d.symmetric_eigenvalues().max();
        let rho = match cfg.rho {
            Some(r) if r.is_finite() && r >= 0.0 => r,
            Some(r) => {
                return Err(LyapunovError::BadParameter {
                    key: "clf.rho",
                    value: r,
                    expected: "finite and ≥ 0",
                })
            }
            None => 1.0 / (d * lmax),
        };
        Ok(Self {
            goal,
            p_d,
            p_l,
            rho,
            v_bar: cfg.v_bar,
        })
    }

    /// V(x).
    pub fn value(&self, x: &State) -> f64 {
        let e = x - self.goal;
        e.dot(&(self.p_d * e))
    }
    /// ∂V/∂x = 2 P_d (x − x_g).
    pub fn gradient(&self, x: &State) -> State {
        2.0 * self.p_d * (x - self.goal)
    }
    /// ∂²V/∂x² = 2 P_d.
    pub fn hessian(&self) -> StateMatrix {
        2.0 * self.p_d
    }
    /// The largest V̄ with {V ≤ V̄} inside the ball ‖x − x_g‖ ≤ r: λ_min(P_d) r².
    pub fn v_bar_inside_ball(&self, r: f64) -> f64 {
        self.p_d.symmetric_eigenvalues().min() * r * r
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lyapunov_solution_satisfies_equation_for_general_a() {
        let a = DMatrix::from_row_slice(3, 3, &[-1.0, 2.0, 0.0, -0.5, -3.0, 1.0, 0.2, 0.0, -2.0]);
        let q = DMatrix::from_row_slice(3, 3, &[2.0, 0.1, 0.0, 0.1, 1.0, 0.3, 0.0, 0.3, 1.5]);
        let p = solve_lyapunov(&a, &q).unwrap();
        let res = a.transpose() * &p + &p * &a + &q;
        assert!(res.amax() < 1e-12, "residual {}", res.amax());
        assert!(p.symmetric_eigenvalues().min() > 0.0);
    }

    #[test]
    fn scalar_lyapunov_known_value() {
        // a = −2: −4p = −1 → p = 1/4
        let p = solve_lyapunov(
            &DMatrix::from_element(1, 1, -2.0),
            &DMatrix::from_element(1, 1, 1.0),
        )
        .unwrap();
        assert!((p[(0, 0)] - 0.25).abs() < 1e-15);
        assert_eq!(
            solve_lyapunov(
                &DMatrix::from_element(1, 1, 0.0),
                &DMatrix::from_element(1, 1, 1.0)
            ),
            Err(LyapunovError::Singular)
        );
    }

    #[test]
    fn clf_rho_and_not_hurwitz() {
        let f = crate::model::LinearModel::double_integrator_f();
        let g = crate::model::LinearModel::double_integrator_g();
        let clf = QuadraticClf::new(&f, &g, State::zeros(), 0.05, &ClfConfig::paper(1.0)).unwrap();
        let lmax = clf.p_d.symmetric_eigenvalues().max();
        assert!((clf.rho * 0.05 * lmax - 1.0).abs() < 1e-12);
        let a = f - g * crate::model::double_integrator_lqr_gain();
        let res = a.transpose() * clf.p_l + clf.p_l * a + StateMatrix::identity();
        assert!(res.amax() < 1e-12);
        let mut cfg = ClfConfig::paper(1.0);
        cfg.gain = Matrix2x4::zeros();
        assert!(matches!(
            QuadraticClf::new(&f, &g, State::zeros(), 0.05, &cfg),
            Err(LyapunovError::NotHurwitz { .. })
        ));
    }
}
