//! # ftcbf-controller
//!
//! The Fault-Tolerant Control Barrier Function + Control Lyapunov Function controller of
//! *Control Barrier Functions for Safe CPS Under Sensor Faults and Attacks* (the thesis in
//! `shared/paper/ft-cbf-thesis.md`; equation numbers in this crate refer to it).
//!
//! Pure math: depends on `nalgebra` and `clarabel` only (plus `thiserror` for typed errors),
//! so it can run on a real robot without the simulator, physics or recording.
//!
//! State convention (the feedback-linearised wheeled robot, eq. 6.2), world frame, SI units:
//! `x = (p_x, p_y, v_x, v_y)`; input `u = (a_x, a_y)` planar acceleration in m/s².
//!
//! Modules, one idea each: [`model`] (F, G, C, Q, R; fault patterns; Euler–Maruyama),
//! [`estimator`] (Kalman filters and the bank of eq. 4.1/4.2), [`barrier`] (h, ∂h, ∂²h, h̄_γ),
//! [`lyapunov`] (the CLF of eq. 6.6), [`constraints`] (Ω of eq. 4.3, Υ of eq. 5.2),
//! [`qp`] (problem 5.3 through clarabel), [`policy`] (Steps 1–3 with a decision record),
//! [`params`] (γ, θ, χ² quantiles, checks of Lemma 1 / Prop. 1 / Thm. 5),
//! [`conditions`] (condition (4.4) of Theorem 3 decided on the barriers that run) and
//! [`controller`] (the top-level FT-CBF-CLF, baseline and nominal controllers) and
//! [`drive`] (the compensator 6.3–6.4 turning u into a body command (v, ω)) and [`nominal`]
//! (the path-tracking nominal law of the safety-filter form).

pub mod barrier;
pub mod conditions;
pub mod constraints;
pub mod controller;
pub mod drive;
pub mod estimator;
pub mod feasibility;
pub mod interface;
pub mod lyapunov;
pub mod model;
pub mod nominal;
pub mod odometry;
pub mod params;
pub mod policy;
pub mod qp;
pub mod types;

pub use barrier::{
    Barrier, BarrierEval, EllipsoidInside, EllipsoidOutside, HalfPlane, HigherOrderHalfPlane,
};
pub use controller::{
    ConfigError, ControlOutput, Controller, ControllerConfig, ControllerKind, ProblemForm,
    RejectedReadings,
};
pub use estimator::{EstimatorBank, FilterRole, KalmanFilter};
pub use interface::{ControlLaw, Decision, Readings};
pub use lyapunov::{ClfConfig, QuadraticClf};
pub use model::{LinearModel, ModelError};
pub use nominal::{PathTracker, TrackerConfig, TrackerError};
pub use policy::{DecisionRecord, QpOutcome, SafeAction, Stage};
pub use types::{Input, InputMatrix, State, StateMatrix};
