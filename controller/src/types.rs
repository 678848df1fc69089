//! Fixed-size state and input types of the planar double integrator (eq. 6.2).
//!
//! The controller is deliberately specialised to n = 4 states and p = 2 inputs: every
//! per-step quantity lives on the stack, so a control step performs no heap allocation
//! outside the QP solver.

/// Planar state in the world frame: `(p_x, p_y, v_x, v_y)` [m, m, m/s, m/s].
pub type State = nalgebra::Vector4<f64>;
/// A 4×4 matrix over the state (F, Q, P, Hessians).
pub type StateMatrix = nalgebra::Matrix4<f64>;
/// Planar acceleration input in the world frame: `(a_x, a_y)` [m/s²].
pub type Input = nalgebra::Vector2<f64>;
/// The 4×2 input matrix G.
pub type InputMatrix = nalgebra::Matrix4x2<f64>;
