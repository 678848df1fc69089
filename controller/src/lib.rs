//! # ftcbf-controller
//!
//! The Fault-Tolerant Control Barrier Function + Control Lyapunov Function controller of
//! *Control Barrier Functions for Safe CPS Under Sensor Faults and Attacks* (H. Zhang, M.S.
//! thesis, Worcester Polytechnic Institute; A. Clark, Z. Li, H. Zhang, IEEE CDC 2020). Equation
//! numbers in this crate refer to the thesis; the book's "The thesis in brief"
//! (book/src/theory/thesis.md) states what they mean.
//!
//! Pure math: depends on `nalgebra`, `clarabel` (the QP), `statrs` (χ² and normal quantiles) and
//! `thiserror` (typed errors) only — never on the simulator, physics or recording — so it runs
//! on a real robot as it runs in `ftcbf-sim`.
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
//! [`reach`] and [`ellipse_index`] (active barriers: rows only for the obstacles within reach),
//! [`controller`] (the top-level FT-CBF-CLF, baseline and nominal controllers) and
//! [`drive`] (the compensator 6.3–6.4 turning u into a body command (v, ω)) and [`nominal`]
//! (the path-tracking nominal law of the safety-filter form); [`odometry`] turns ROS-style
//! readings (quaternions, body-frame speed, gyro) into the model's channels.
//!
//! # On a robot
//!
//! Two position receivers, one of them lying, and a world-frame velocity; a floor
//! `y ≥ −0.05 m` the robot must not cross on its way to the origin. Each control period the
//! robot hands the controller its readings and sends the compensator's `cmd_vel` (v, ω) to the
//! wheels. The "robot" here is three lines of unicycle kinematics; on a real one the readings
//! come from its drivers and the command goes to its base controller.
//!
//! ```
//! use std::sync::Arc;
//! use ftcbf_controller::drive::{Compensator, CompensatorConfig, LowSpeedLaw};
//! use ftcbf_controller::params::{BoundMethod, FtComputed, UpdateSchedule};
//! use ftcbf_controller::{
//!     Controller, ControllerConfig, HalfPlane, Input, LinearModel, ProblemForm, State,
//!     StateMatrix, TrackerConfig,
//! };
//! use nalgebra::RowVector4;
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let dt = 0.02; // 50 Hz
//! let row = |k: usize| RowVector4::from_fn(|_, j| if j == k { 1.0 } else { 0.0 });
//! // Channels: gnss1 x, y; gnss2 x, y; velocity x, y. Variances of one sample.
//! let model = LinearModel::new(
//!     LinearModel::double_integrator_f(),
//!     LinearModel::double_integrator_g(),
//!     vec![row(0), row(1), row(0), row(1), row(2), row(3)],
//!     StateMatrix::from_diagonal(&State::new(0.0, 0.0, 1e-3, 1e-3)),
//!     vec![4e-4, 4e-4, 4e-4, 4e-4, 1e-4, 1e-4],
//! )?;
//! let patterns = vec![vec![0, 1], vec![2, 3]]; // each receiver may fail
//! let p0 = StateMatrix::from_diagonal(&State::new(1e-4, 1e-4, 1e-4, 1e-4));
//! let params = FtComputed::compute_scheduled(
//!     &model, &patterns, dt, 0.05, 500, &p0, BoundMethod::Horizon, &UpdateSchedule::every_step(),
//! );
//! let limit = Input::new(1.0, 1.0);
//! let mut ctl = Controller::new(
//!     ControllerConfig::builder(model, patterns, params.ft)
//!         // h = p_y + 0.2·v_y + 0.05 ≥ 0: the floor, lifted with the velocity.
//!         .barriers(vec![Arc::new(HalfPlane::new("floor", State::new(0.0, 1.0, 0.0, 0.2), -0.05))])
//!         .goal(State::zeros(), 0.05)
//!         .cbf_gain(10.0)
//!         .input_limit(limit)
//!         .start(State::new(1.0, 0.0, 0.0, 0.0), p0)
//!         .form(ProblemForm::SafetyFilter {
//!             tracker: TrackerConfig::turtlebot([0.0, 0.03], 0.05, Some(limit)),
//!             clf: false,
//!         })
//!         .build(),
//! )?;
//! let mut drive = Compensator::new(CompensatorConfig {
//!     v_max: 0.22,
//!     omega_max: 2.84,
//!     dv_max: Some(1.0),
//!     domega_max: Some(3.0),
//!     low_speed: LowSpeedLaw::Regularised { v_soft: 0.05 },
//!     speed_gain: 0.1,
//!     omega_resolution: 0.0,
//! })?;
//!
//! let (mut x, mut y, mut yaw, mut v) = (1.0_f64, 0.0_f64, std::f64::consts::PI, 0.0_f64);
//! let mut lowest_h = f64::INFINITY;
//! let mut gnss2_filter_dropped = false;
//! for k in 0..400 {
//!     let t = k as f64 * dt;
//!     let noise = if k % 2 == 0 { 0.01 } else { -0.01 };
//!     let spoof = if t >= 1.0 { 0.3 } else { 0.0 }; // gnss2 reports y + 0.3 m from t = 1 s
//!     let (vx, vy) = (v * yaw.cos(), v * yaw.sin());
//!     let readings = [x + noise, y + noise, x - noise, y - noise + spoof, vx, vy];
//!     let out = ctl.step(&readings, &[true; 6], dt); // every channel fresh this period
//!     // Unit 0 drops gnss1's pattern, so it is the filter that reads the spoofed gnss2.
//!     gnss2_filter_dropped |= out.decision.unit_dropped(0);
//!     drive.observe_speed(v);
//!     let cmd = drive.command(out.u, yaw, dt); // cmd_vel for the base controller
//!     v = cmd.v;
//!     x += v * yaw.cos() * dt;
//!     y += v * yaw.sin() * dt;
//!     yaw += cmd.omega * dt;
//!     lowest_h = lowest_h.min(y + 0.2 * v * yaw.sin() + 0.05);
//! }
//! assert!(gnss2_filter_dropped, "Step 2 isolates the lying receiver");
//! assert!(lowest_h >= 0.0, "the true state stayed in the safe set: min h = {lowest_h}");
//! assert!(x.hypot(y) < 0.3, "and the robot drove towards its goal: at ({x:.3}, {y:.3})");
//! # Ok(())
//! # }
//! ```
//!
//! `controller/examples/ros_readings.rs` does the same from readings as ROS publishes them
//! (a quaternion, body-frame odometry, a biased gyro fused with the compass).

#![warn(missing_docs)]

pub mod barrier;
pub mod conditions;
pub mod constraints;
pub mod controller;
pub mod drive;
pub mod ellipse_index;
pub mod estimator;
pub mod feasibility;
pub mod interface;
pub mod lyapunov;
pub mod model;
pub mod mover_track;
pub mod nominal;
pub mod odometry;
pub mod params;
pub mod policy;
pub mod qp;
pub mod reach;
pub mod types;

pub use barrier::{
    Barrier, BarrierEval, EllipsoidInside, EllipsoidOutside, HalfPlane, HigherOrderHalfPlane,
    MoverState, MovingBarrier,
};
pub use controller::{
    ConfigError, ControlOutput, Controller, ControllerConfig, ControllerConfigBuilder,
    ControllerKind, ProblemForm, RejectedReadings,
};
pub use estimator::{EstimatorBank, FilterRole, KalmanFilter};
pub use interface::{ControlLaw, Decision, Readings};
pub use lyapunov::{ClfConfig, QuadraticClf};
pub use model::{LinearModel, ModelError};
pub use mover_track::{MoverTracker, MoverTrackerConfig, MoverTrackerError, TrackedReading};
pub use nominal::{PathTracker, TrackerConfig, TrackerError};
pub use params::{FtParams, PairTable};
pub use policy::{DecisionRecord, Fallback, QpOutcome, SafeAction, Stage, StopReason};
pub use types::{Input, InputMatrix, State, StateMatrix};
