//! Readings as a ROS robot has them, turned into the channels of the linear model (6.2).
//!
//! Frames and signs follow REP-103 and REP-105:
//! - **World** (`map` or `odom`): ENU, x east, y north [m]. The model's state is
//!   (p_x, p_y, v_x, v_y) in this frame, and a GNSS fix (converted to local ENU) is a position
//!   reading in it.
//! - **Body** (`base_footprint`): x forward, y left, z up. Wheel odometry
//!   (`nav_msgs/Odometry` twist.linear.x) is the forward speed v [m/s] in this frame.
//! - **Yaw** θ [rad]: the heading of the body x axis, counter-clockwise from world +x, from an
//!   IMU orientation quaternion (`sensor_msgs/Imu` orientation) or a compass.
//!
//! A differential-drive robot does not slide sideways, so its world-frame velocity is
//! v·(cos θ, sin θ). With a measured yaw θ̂ = θ + e_θ, the converted velocity's error is
//! e_v·(cos θ̂, sin θ̂) + v·e_θ·(−sin θ, cos θ) to first order, and each axis' error variance is at
//! most σ_v² + v_max²·σ_θ² ([`world_velocity_variance`]). A yaw bias enters that bound as if it were
//! noise: conservative for the variance, but the error is then correlated in time, which the
//! filters do not model.

/// Yaw [rad] from a unit quaternion (x, y, z, w) (`geometry_msgs/Quaternion`): the rotation
/// about the world z axis, in (−π, π].
pub fn yaw_from_quaternion(x: f64, y: f64, z: f64, w: f64) -> f64 {
    (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z))
}

/// World-frame velocity (v_x, v_y) [m/s] of a robot moving forward at `v` [m/s] with yaw `yaw`
/// [rad]. A non-finite input gives non-finite output, which the controller rejects as a
/// malformed reading.
pub fn body_speed_to_world_velocity(v: f64, yaw: f64) -> [f64; 2] {
    [v * yaw.cos(), v * yaw.sin()]
}

/// Variance [(m/s)²] to declare for each axis of [`body_speed_to_world_velocity`]:
/// σ_v² + v_max²·(σ_θ² + b_θ² + w_θ²·T). Here σ_v [m/s] is the speed noise, v_max [m/s] the
/// robot's speed bound, σ_θ [rad] the yaw noise, b_θ [rad] a yaw bias bound, and w_θ
/// [rad/√s] a yaw bias walk over the horizon T [s].
pub fn world_velocity_variance(
    speed_std: f64,
    v_max: f64,
    yaw_std: f64,
    yaw_bias: f64,
    yaw_walk_std: f64,
    horizon: f64,
) -> f64 {
    let yaw_var = yaw_std * yaw_std + yaw_bias * yaw_bias + yaw_walk_std * yaw_walk_std * horizon;
    speed_std * speed_std + v_max * v_max * yaw_var
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::{FRAC_PI_2, PI};

    #[test]
    fn yaw_and_world_velocity_follow_rep_103() {
        // 90° about +z: facing north (y), counter-clockwise positive.
        let (s, c) = (FRAC_PI_2 / 2.0).sin_cos();
        assert!((yaw_from_quaternion(0.0, 0.0, s, c) - FRAC_PI_2).abs() < 1e-12);
        assert!((yaw_from_quaternion(0.0, 0.0, 1.0, 0.0).abs() - PI).abs() < 1e-12);
        let v = body_speed_to_world_velocity(0.2, FRAC_PI_2);
        assert!(v[0].abs() < 1e-12 && (v[1] - 0.2).abs() < 1e-12, "{v:?}");
        assert!(body_speed_to_world_velocity(f64::NAN, 0.0)[0].is_nan());
        // σ_v = 0.01, v_max = 0.22, σ_θ = 0.005: 1e-4 + 0.0484·2.5e-5
        let r = world_velocity_variance(0.01, 0.22, 0.005, 0.0, 0.0, 20.0);
        assert!((r - 1.0121e-4).abs() < 1e-9, "{r}");
    }
}
