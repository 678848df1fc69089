//! Ground truth of the robot, read from physics (or from the linear model), never given to the
//! controller directly: sensors measure it, attacks corrupt the measurements.

/// The robot's true planar state at one instant, world frame, SI units.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TruthState {
    /// Simulation time \[s\].
    pub t: f64,
    /// Position of the robot's reference point (base_link origin projected on the ground) \[m\].
    pub x: f64,
    /// \[m\]
    pub y: f64,
    /// Heading (yaw about +z) \[rad\], wrapped to (−π, π].
    pub theta: f64,
    /// World-frame velocity of the reference point [m/s].
    pub vx: f64,
    /// [m/s]
    pub vy: f64,
    /// Forward body speed v = vx cosθ + vy sinθ [m/s].
    pub v_body: f64,
    /// Yaw rate ω [rad/s].
    pub omega: f64,
    /// Left drive wheel's angular speed relative to the base [rad/s], positive = rolling forward
    /// (the revolute joint's velocity, as a wheel encoder sees it: it turns while slipping too).
    /// NaN for a plant without wheels (the linear model).
    pub wheel_left: f64,
    /// Right drive wheel's angular speed [rad/s]; NaN without wheels.
    pub wheel_right: f64,
    /// Left wheel's accumulated rotation since the start \[rad\] (what an encoder counts); NaN
    /// without wheels.
    pub wheel_angle_left: f64,
    /// Right wheel's accumulated rotation \[rad\]; NaN without wheels.
    pub wheel_angle_right: f64,
}

impl TruthState {
    /// The controller's linearised state (p_x, p_y, v_x, v_y) of eq. 6.2.
    pub fn planar(&self) -> ftcbf_controller::State {
        ftcbf_controller::State::new(self.x, self.y, self.vx, self.vy)
    }
}
