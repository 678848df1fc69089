//! The controller on readings as a ROS robot has them, without the simulator: two GNSS fixes
//! (converted to local ENU, `map` frame), wheel odometry (`nav_msgs/Odometry` twist.linear.x in
//! `base_footprint`) and an IMU (`sensor_msgs/Imu`: the orientation's REP-103 yaw from a poor
//! magnetometer, ±0.05 rad, fused with angular_velocity.z, biased by 0.003 rad/s, in a
//! `HeadingFilter`). Out comes the
//! planar acceleration the FT-CBF QP allows and the `cmd_vel` (v, ω) the compensator turns it
//! into.
//!
//! The task is the paper's: drive from (1, 0) to the origin while y + 0.2·ẏ + 0.05 ≥ 0. The
//! fault patterns are the two receivers, and receiver 2 reports y 0.3 m too high from t = 1 s.
//! The readings are hand-made: a unicycle that executes each `cmd_vel` exactly for one period
//! (three lines of kinematics stand in for the robot), read out with a fixed ±1 cm GNSS noise
//! pattern (no random numbers).
//!
//! Run: `cargo run --release -p ftcbf-controller --example ros_readings`

use std::f64::consts::PI;
use std::sync::Arc;

use ftcbf_controller::barrier::HalfPlane;
use ftcbf_controller::drive::{Compensator, CompensatorConfig, LowSpeedLaw};
use ftcbf_controller::odometry::{
    body_speed_to_world_velocity, fused_yaw_variance, world_velocity_variance, wrap_angle,
    yaw_from_quaternion, HeadingFilter, HeadingFilterParams,
};
use ftcbf_controller::params::{BoundMethod, FtComputed, UpdateSchedule};
use ftcbf_controller::{
    Controller, ControllerConfig, Input, LinearModel, ProblemForm, State, StateMatrix,
    TrackerConfig,
};
use nalgebra::RowVector4;

const DT: f64 = 0.02; // 50 Hz
const V_MAX: f64 = 0.22; // burger [m/s]

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // Channels, in the order the readings are passed: gnss1 (x, y), gnss2 (x, y), odometry
    // turned into world-frame velocity (x, y).
    let pos = |k: usize| {
        let mut r = RowVector4::zeros();
        r[k] = 1.0;
        r
    };
    let gnss_var = 0.02_f64 * 0.02;
    // The yaw: gyro (σ 0.01 rad/s, bias walk 0.0005 rad/s/√s) fused with a ±0.05 rad compass,
    // started at the marked start yaw (σ 0.01 rad). Its yaw variance, weighted by how fast the
    // robot can be going, enters the odometry's variance.
    let heading = HeadingFilterParams {
        initial_yaw_std: 0.01,
        ..HeadingFilterParams::new(0.01, 0.0005, 0.05)
    };
    let yaw_var = fused_yaw_variance(heading, DT, 1, 10.0, V_MAX, 2.0_f64.sqrt());
    let odom_var = world_velocity_variance(0.01, V_MAX, yaw_var.sqrt(), 0.0, 0.0, 10.0);
    let mut yaw_filter = HeadingFilter::started_at(heading, PI);
    let model = LinearModel::new(
        LinearModel::double_integrator_f(),
        LinearModel::double_integrator_g(),
        vec![pos(0), pos(1), pos(0), pos(1), pos(2), pos(3)],
        StateMatrix::from_diagonal(&State::new(0.0, 0.0, 1e-3, 1e-3)),
        vec![gnss_var, gnss_var, gnss_var, gnss_var, odom_var, odom_var],
    )?;
    let patterns = vec![vec![0, 1], vec![2, 3]];
    let p0 = StateMatrix::from_diagonal(&State::new(1e-4, 1e-4, 1e-4, 1e-4));
    let params = FtComputed::compute_scheduled(
        &model,
        &patterns,
        DT,
        0.05,
        500,
        &p0,
        BoundMethod::Horizon,
        &UpdateSchedule::every_step(),
    );
    let limit = Input::new(1.0, 1.0);
    let mut tracker = TrackerConfig::turtlebot([0.0, 0.03], 0.05, Some(limit));
    tracker.cruise_speed = 0.9 * V_MAX;
    let mut ctl = Controller::new(
        ControllerConfig::builder(model, patterns, params.ft.clone())
            .barriers(vec![Arc::new(HalfPlane::new(
                "floor",
                State::new(0.0, 1.0, 0.0, 0.2),
                -0.05,
            ))])
            .goal(State::zeros(), 0.05)
            .cbf_gain(10.0)
            .input_limit(limit)
            .start(State::new(1.0, 0.0, 0.0, 0.0), p0)
            .form(ProblemForm::SafetyFilter {
                tracker,
                clf: false,
            })
            .build(),
    )?;
    let mut drive = Compensator::new(CompensatorConfig {
        v_max: V_MAX,
        omega_max: 2.84,
        dv_max: Some(1.0),
        domega_max: Some(3.0),
        low_speed: LowSpeedLaw::Regularised { v_soft: 0.05 },
        speed_gain: 0.1,
        omega_resolution: 0.033 * 0.02398 / 0.16,
    })?;

    println!(
        "γ_i = {:?}, θ_12 = {:?}; fused yaw σ bound {:.4} rad (compass alone 0.05)",
        params.ft.gamma,
        params.ft.theta,
        yaw_var.sqrt()
    );
    println!(
        "   t [s] | (x, y) [m]       | cmd_vel v, ω    | u [m/s²]         | stage | dropped units"
    );
    // The hand-made robot: position [m], yaw [rad] (facing −x, west), forward speed [m/s].
    let (mut px, mut py, mut yaw_true, mut v, mut omega) = (1.0_f64, 0.0_f64, PI, 0.0, 0.0);
    let mut worst_yaw_error = 0.0_f64;
    for k in 0..400 {
        let t = k as f64 * DT;
        let noise = if k % 2 == 0 { 0.01 } else { -0.01 };
        // What the robot reports: the IMU orientation as a quaternion about +z (a magnetometer's
        // yaw, ±0.05 rad) and its gyro's angular_velocity.z, wheel odometry (forward speed), and
        // two GNSS fixes in local ENU.
        let compass = yaw_true + 5.0 * noise;
        let (qz, qw) = ((compass / 2.0).sin(), (compass / 2.0).cos());
        if k > 0 {
            yaw_filter.predict(omega + 0.003 + noise, DT);
        }
        yaw_filter.correct(yaw_from_quaternion(0.0, 0.0, qz, qw));
        let yaw = yaw_filter.yaw();
        let err = wrap_angle(yaw - yaw_true);
        worst_yaw_error = worst_yaw_error.max(err.abs());
        let [vx, vy] = body_speed_to_world_velocity(v, yaw);
        let spoof = if t >= 1.0 { 0.3 } else { 0.0 };
        let y = [
            px + noise,
            py + noise,
            px - noise,
            py - noise + spoof,
            vx,
            vy,
        ];
        let out = ctl.step(&y, &[true; 6], DT);
        let u = out.u;
        drive.observe_speed(v);
        let cmd = drive.command(u, yaw, DT);
        if k % 25 == 0 {
            // Unit i is x̂_{i+1}, the filter that ignores receiver i + 1.
            let dropped: Vec<String> = (0..2)
                .filter(|&i| out.decision.unit_dropped(i))
                .map(|i| format!("x̂_{} (reads gnss{})", i + 1, 2 - i))
                .collect();
            println!(
                "{t:8.2} | ({px:+.3}, {py:+.3}) | {:+.3}, {:+.4} | ({:+.3}, {:+.3}) | {:?} | {:?}",
                cmd.v, cmd.omega, u[0], u[1], out.decision.stage, dropped
            );
        }
        // The robot executes cmd_vel for one period.
        v = cmd.v;
        omega = cmd.omega;
        px += v * yaw_true.cos() * DT;
        py += v * yaw_true.sin() * DT;
        yaw_true += cmd.omega * DT;
    }
    println!(
        "end: ({px:+.3}, {py:+.3}), h = y + 0.2·ẏ + 0.05 = {:+.3} (≥ 0: safe), distance to the goal {:.3} m",
        py + 0.2 * v * yaw_true.sin() + 0.05,
        px.hypot(py)
    );
    println!(
        "fused yaw: largest error {worst_yaw_error:.4} rad (compass ±0.05), gyro bias estimate {:.4} rad/s (true 0.003)",
        yaw_filter.gyro_bias()
    );
    Ok(())
}
