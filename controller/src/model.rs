//! The linear continuous-time model (eq. 4.9 with observation 3.2):
//!
//! `dx = (F x + G u) dt + σ dW`, `Q = σσᵀ` (process noise intensity per unit time),
//! and sampled measurements `y_k = C x(t_k) + a_k + v_k`, `v_k ~ N(0, R)`.
//!
//! **R is the covariance of one sample** and must be **diagonal** (independent channels):
//! it is stored as the per-channel variances [`LinearModel::r`]. The Kalman filters of
//! [`crate::estimator`] rely on this (sequential scalar updates are exact for diagonal R).
//!
//! Channels are indexed `0..q`; a fault pattern F(r_i) is a set of channel indices
//! ([`validate_fault_patterns`]).

use nalgebra::{Matrix2x4, RowVector4, SMatrix};
use thiserror::Error;

use crate::types::{Input, InputMatrix, State, StateMatrix};

/// Errors in a model or fault-pattern description.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ModelError {
    /// The observation matrix has no rows.
    #[error("observation matrix C has no rows (q = 0); at least one sensor channel is required")]
    NoChannels,
    /// `r` and `c` disagree on q.
    #[error("R has {r} diagonal entries but C has {q} rows; expected one variance per channel")]
    ChannelCountMismatch {
        /// Rows of C.
        q: usize,
        /// Entries of diag R.
        r: usize,
    },
    /// A non-finite number in a model matrix.
    #[error("model matrix {what} contains a non-finite entry")]
    NonFinite {
        /// Which matrix.
        what: &'static str,
    },
    /// A measurement variance that is not strictly positive.
    #[error("measurement variance R[{channel}] = {value} must be finite and > 0")]
    NonPositiveVariance {
        /// Channel index.
        channel: usize,
        /// Offending value.
        value: f64,
    },
    /// Q is not symmetric positive semidefinite.
    #[error("process noise Q must be symmetric positive semidefinite (min eigenvalue {min_eigenvalue}, asymmetry {asymmetry})")]
    NotPsd {
        /// Smallest eigenvalue of the symmetric part.
        min_eigenvalue: f64,
        /// max |Q − Qᵀ|.
        asymmetry: f64,
    },
    /// No fault pattern was given.
    #[error("no fault patterns given; the FT controller needs m ≥ 1 patterns")]
    NoPatterns,
    /// A fault pattern with no channel.
    #[error("fault pattern {pattern} is empty; each F(r_i) must name at least one channel")]
    EmptyPattern {
        /// Pattern index.
        pattern: usize,
    },
    /// A channel index ≥ q.
    #[error("fault pattern {pattern} names channel {channel}, but channels are 0..{q}")]
    ChannelOutOfRange {
        /// Pattern index.
        pattern: usize,
        /// Channel index.
        channel: usize,
        /// Number of channels.
        q: usize,
    },
    /// A channel repeated inside one pattern.
    #[error("fault pattern {pattern} lists channel {channel} twice")]
    DuplicateChannel {
        /// Pattern index.
        pattern: usize,
        /// Channel index.
        channel: usize,
    },
    /// Two patterns share a channel (§3.1 requires disjoint F(r_i)).
    #[error("fault patterns {first} and {second} both contain channel {channel}; patterns must be disjoint (§3.1)")]
    OverlappingPatterns {
        /// First pattern index.
        first: usize,
        /// Second pattern index.
        second: usize,
        /// Shared channel.
        channel: usize,
    },
}

/// The linear model `(F, G, C, Q, R)`; see the module docs for the noise conventions.
#[derive(Debug, Clone, PartialEq)]
pub struct LinearModel {
    /// Drift matrix F (4×4).
    pub f: StateMatrix,
    /// Input matrix G (4×2).
    pub g: InputMatrix,
    /// Observation rows c_k, k = 0..q.
    pub c: Vec<RowVector4<f64>>,
    /// Process noise intensity Q = σσᵀ (state²/s).
    pub q: StateMatrix,
    /// Diagonal of R: variance of one sample of channel k.
    pub r: Vec<f64>,
    /// σ = Q^½ (symmetric square root), used by [`LinearModel::euler_maruyama_step`].
    sigma: StateMatrix,
}

impl LinearModel {
    /// Validate and build a model.
    pub fn new(
        f: StateMatrix,
        g: InputMatrix,
        c: Vec<RowVector4<f64>>,
        q: StateMatrix,
        r: Vec<f64>,
    ) -> Result<Self, ModelError> {
        if c.is_empty() {
            return Err(ModelError::NoChannels);
        }
        if c.len() != r.len() {
            return Err(ModelError::ChannelCountMismatch {
                q: c.len(),
                r: r.len(),
            });
        }
        if f.iter().any(|v| !v.is_finite()) {
            return Err(ModelError::NonFinite { what: "F" });
        }
        if g.iter().any(|v| !v.is_finite()) {
            return Err(ModelError::NonFinite { what: "G" });
        }
        if c.iter().any(|row| row.iter().any(|v| !v.is_finite())) {
            return Err(ModelError::NonFinite { what: "C" });
        }
        if q.iter().any(|v| !v.is_finite()) {
            return Err(ModelError::NonFinite { what: "Q" });
        }
        for (k, &v) in r.iter().enumerate() {
            if !(v.is_finite() && v > 0.0) {
                return Err(ModelError::NonPositiveVariance {
                    channel: k,
                    value: v,
                });
            }
        }
        let asymmetry = (q - q.transpose()).amax();
        let sym = (q + q.transpose()) * 0.5;
        let eig = sym.symmetric_eigen();
        let min_eigenvalue = eig.eigenvalues.min();
        let scale = eig.eigenvalues.amax().max(1e-300);
        if asymmetry > 1e-12 * scale.max(1.0) || min_eigenvalue < -1e-12 * scale {
            return Err(ModelError::NotPsd {
                min_eigenvalue,
                asymmetry,
            });
        }
        let sqrt_vals = eig.eigenvalues.map(|l| l.max(0.0).sqrt());
        let sigma = eig.eigenvectors
            * StateMatrix::from_diagonal(&sqrt_vals)
            * eig.eigenvectors.transpose();
        Ok(Self {
            f,
            g,
            c,
            q: sym,
            r,
            sigma,
        })
    }

    /// The planar double integrator of eq. 6.2: `ṗ = v`, `v̇ = u`.
    pub fn double_integrator_f() -> StateMatrix {
        let mut f = StateMatrix::zeros();
        f[(0, 2)] = 1.0;
        f[(1, 3)] = 1.0;
        f
    }

    /// G of eq. 6.2.
    pub fn double_integrator_g() -> InputMatrix {
        let mut g = InputMatrix::zeros();
        g[(2, 0)] = 1.0;
        g[(3, 1)] = 1.0;
        g
    }

    /// The paper's six-sensor observation of eq. 6.5: channels (x, x, y, y, ẋ, ẏ).
    pub fn paper_observation() -> Vec<RowVector4<f64>> {
        let row = |i: usize| {
            let mut r = RowVector4::zeros();
            r[i] = 1.0;
            r
        };
        vec![row(0), row(0), row(1), row(1), row(2), row(3)]
    }

    /// The double integrator (6.2) with the observation (6.5), isotropic process noise
    /// intensity `q_intensity·I` and per-sample measurement variance `r_variance` on every
    /// channel (the paper's study uses 1e-3 for both).
    pub fn paper_double_integrator(q_intensity: f64, r_variance: f64) -> Result<Self, ModelError> {
        Self::new(
            Self::double_integrator_f(),
            Self::double_integrator_g(),
            Self::paper_observation(),
            StateMatrix::identity() * q_intensity,
            vec![r_variance; 6],
        )
    }

    /// Number of channels q.
    pub fn channels(&self) -> usize {
        self.c.len()
    }

    /// σ = Q^½ (symmetric square root).
    pub fn sigma(&self) -> &StateMatrix {
        &self.sigma
    }

    /// Noise-free measurement `C x` of channel `k`.
    pub fn measure(&self, k: usize, x: &State) -> f64 {
        (self.c[k] * x)[0]
    }

    /// One Euler–Maruyama step of `dx = (Fx + Gu)dt + σ dW` over `dt`:
    /// `x + (Fx + Gu) dt + σ √dt w`, where `w_std_normal` holds four independent N(0,1)
    /// draws supplied by the caller (this crate has no random number generator).
    pub fn euler_maruyama_step(
        &self,
        x: &State,
        u: &Input,
        dt: f64,
        w_std_normal: &State,
    ) -> State {
        x + (self.f * x + self.g * u) * dt + self.sigma * w_std_normal * dt.sqrt()
    }

    /// Exact zero-order-hold discretisation over `dt` (see [`Discretization`]).
    pub fn discretize(&self, dt: f64) -> Discretization {
        // Φ and Γ: exp([[F, G], [0, 0]] dt) = [[Φ, Γ], [0, I]].
        let mut m6 = SMatrix::<f64, 6, 6>::zeros();
        m6.fixed_view_mut::<4, 4>(0, 0).copy_from(&(self.f * dt));
        m6.fixed_view_mut::<4, 2>(0, 4).copy_from(&(self.g * dt));
        let e6 = m6.exp();
        let phi: StateMatrix = e6.fixed_view::<4, 4>(0, 0).into_owned();
        let input_map: InputMatrix = e6.fixed_view::<4, 2>(0, 4).into_owned();
        // Van Loan: exp([[-F, Q], [0, Fᵀ]] dt) = [[·, E12], [0, E22]], Φ = E22ᵀ, Q_d = Φ E12.
        let mut m8 = SMatrix::<f64, 8, 8>::zeros();
        m8.fixed_view_mut::<4, 4>(0, 0).copy_from(&(-self.f * dt));
        m8.fixed_view_mut::<4, 4>(0, 4).copy_from(&(self.q * dt));
        m8.fixed_view_mut::<4, 4>(4, 4)
            .copy_from(&(self.f.transpose() * dt));
        let e8 = m8.exp();
        let e12: StateMatrix = e8.fixed_view::<4, 4>(0, 4).into_owned();
        let qd = phi * e12;
        let qd = (qd + qd.transpose()) * 0.5;
        Discretization {
            dt,
            phi,
            input_map,
            qd,
        }
    }
}

/// Exact discretisation of the continuous model over one sampling period with the input
/// held constant (zero-order hold): `x_{k+1} = Φ x_k + Γ u_k + w_k`, `w_k ~ N(0, Q_d)` with
/// `Φ = exp(F dt)`, `Γ = ∫₀^dt exp(F s) ds G`, `Q_d = ∫₀^dt exp(F s) Q exp(Fᵀ s) ds`
/// (Van Loan's method; for the double integrator with `Q = q I` this equals the closed
/// form `Q_d = q [[dt + dt³/3, dt²/2], [dt²/2, dt]]` per axis, checked in the tests).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Discretization {
    /// Sampling period (s).
    pub dt: f64,
    /// Φ = exp(F dt).
    pub phi: StateMatrix,
    /// Γ = ∫ exp(Fs) ds G, the input map of one period (named apart from the error bound γ).
    pub input_map: InputMatrix,
    /// Q_d.
    pub qd: StateMatrix,
}

/// Check fault patterns: non-empty, in range `0..q`, no duplicates, pairwise disjoint.
pub fn validate_fault_patterns(patterns: &[Vec<usize>], q: usize) -> Result<(), ModelError> {
    if patterns.is_empty() {
        return Err(ModelError::NoPatterns);
    }
    let mut owner: Vec<Option<usize>> = vec![None; q];
    for (p, pat) in patterns.iter().enumerate() {
        if pat.is_empty() {
            return Err(ModelError::EmptyPattern { pattern: p });
        }
        for &ch in pat {
            if ch >= q {
                return Err(ModelError::ChannelOutOfRange {
                    pattern: p,
                    channel: ch,
                    q,
                });
            }
            match owner[ch] {
                Some(o) if o == p => {
                    return Err(ModelError::DuplicateChannel {
                        pattern: p,
                        channel: ch,
                    })
                }
                Some(o) => {
                    return Err(ModelError::OverlappingPatterns {
                        first: o,
                        second: p,
                        channel: ch,
                    })
                }
                None => owner[ch] = Some(p),
            }
        }
    }
    Ok(())
}

/// The stabilising state feedback used for the CLF's closed loop (see [`crate::lyapunov`]):
/// `K = [I, √3 I]`, which is the exact continuous LQR gain of the double integrator for
/// state weight I and input weight I (per axis `K = [1, √3]` solves the CARE).
pub fn double_integrator_lqr_gain() -> Matrix2x4<f64> {
    let s3 = 3.0_f64.sqrt();
    Matrix2x4::new(1.0, 0.0, s3, 0.0, 0.0, 1.0, 0.0, s3)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn overlapping_out_of_range_empty_duplicate_rejected() {
        assert_eq!(validate_fault_patterns(&[vec![1], vec![3]], 6), Ok(()));
        assert_eq!(
            validate_fault_patterns(&[vec![1, 2], vec![2, 3]], 6),
            Err(ModelError::OverlappingPatterns {
                first: 0,
                second: 1,
                channel: 2
            })
        );
        assert_eq!(
            validate_fault_patterns(&[vec![1], vec![6]], 6),
            Err(ModelError::ChannelOutOfRange {
                pattern: 1,
                channel: 6,
                q: 6
            })
        );
        assert_eq!(
            validate_fault_patterns(&[vec![1], vec![]], 6),
            Err(ModelError::EmptyPattern { pattern: 1 })
        );
        assert_eq!(
            validate_fault_patterns(&[vec![1, 1]], 6),
            Err(ModelError::DuplicateChannel {
                pattern: 0,
                channel: 1
            })
        );
        assert_eq!(validate_fault_patterns(&[], 6), Err(ModelError::NoPatterns));
    }

    #[test]
    fn bad_models_rejected() {
        let f = LinearModel::double_integrator_f();
        let g = LinearModel::double_integrator_g();
        let c = LinearModel::paper_observation();
        let q = StateMatrix::identity();
        assert!(matches!(
            LinearModel::new(f, g, c.clone(), q, vec![1.0; 5]),
            Err(ModelError::ChannelCountMismatch { q: 6, r: 5 })
        ));
        let mut r = vec![1.0; 6];
        r[3] = 0.0;
        assert!(matches!(
            LinearModel::new(f, g, c.clone(), q, r),
            Err(ModelError::NonPositiveVariance { channel: 3, .. })
        ));
        assert!(matches!(
            LinearModel::new(f, g, c.clone(), -q, vec![1.0; 6]),
            Err(ModelError::NotPsd { .. })
        ));
        let mut fnan = f;
        fnan[(0, 0)] = f64::NAN;
        assert!(matches!(
            LinearModel::new(fnan, g, c, q, vec![1.0; 6]),
            Err(ModelError::NonFinite { what: "F" })
        ));
    }

    #[test]
    fn van_loan_matches_double_integrator_closed_form() {
        let m = LinearModel::paper_double_integrator(0.3, 1e-3).unwrap();
        let dt = 0.02;
        let d = m.discretize(dt);
        let qi = 0.3;
        // Q = q I (noise on position and velocity): per axis
        // Q_d = q [[dt + dt³/3, dt²/2], [dt²/2, dt]]
        let expect = [
            ((0, 0), qi * (dt + dt.powi(3) / 3.0)),
            ((0, 2), qi * dt * dt / 2.0),
            ((2, 2), qi * dt),
            ((1, 1), qi * (dt + dt.powi(3) / 3.0)),
            ((1, 3), qi * dt * dt / 2.0),
            ((3, 3), qi * dt),
            ((0, 1), 0.0),
        ];
        for ((i, j), v) in expect {
            assert!(
                (d.qd[(i, j)] - v).abs() < 1e-14,
                "Qd[{i},{j}] = {} vs {v}",
                d.qd[(i, j)]
            );
        }
        assert!((d.phi[(0, 2)] - dt).abs() < 1e-15);
        assert!((d.input_map[(0, 0)] - dt * dt / 2.0).abs() < 1e-15);
        assert!((d.input_map[(2, 0)] - dt).abs() < 1e-15);
    }

    #[test]
    fn euler_maruyama_uses_sigma_sqrt_dt() {
        let m = LinearModel::paper_double_integrator(4.0, 1e-3).unwrap();
        let x = State::new(1.0, 2.0, 3.0, 4.0);
        let u = Input::new(0.5, -1.0);
        let w = State::new(1.0, 0.0, 0.0, -1.0);
        let dt = 0.01;
        let xn = m.euler_maruyama_step(&x, &u, dt, &w);
        // σ = 2 I
        let expect = State::new(
            1.0 + 3.0 * dt + 2.0 * 0.1,
            2.0 + 4.0 * dt,
            3.0 + 0.5 * dt,
            4.0 - dt - 2.0 * 0.1,
        );
        assert!((xn - expect).norm() < 1e-14, "{xn} vs {expect}");
    }
}
