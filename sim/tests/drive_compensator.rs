//! The compensator (6.3)–(6.4), its guard at v ≈ 0, limits and wheel kinematics.

use ftcbf_controller::Input;
use ftcbf_sim::drivetrain::{BodyCommand, Drive, DriveConfig, DriveError};
use ftcbf_sim::robot::{DriveLimits, WheelGeometry};

const GEOM: WheelGeometry = WheelGeometry {
    radius: 0.033,
    separation: 0.160,
};
const LIMITS: DriveLimits = DriveLimits {
    v_max: 0.22,
    omega_max: 2.84,
    wheel_speed_max: 0.22 / 0.033,
};

fn drive() -> Drive {
    Drive::new(&GEOM, &LIMITS, DriveConfig::default()).unwrap()
}

#[test]
fn forward_speed_integrates_the_along_heading_acceleration() {
    let mut d = drive();
    // θ = π/2: the heading is +y, so only u₂ accelerates.
    let theta = std::f64::consts::FRAC_PI_2;
    let mut cmd = BodyCommand::default();
    for _ in 0..10 {
        cmd = d.command(Input::new(0.0, 0.5), theta, 0.02);
    }
    assert!((cmd.v - 0.1).abs() < 1e-12, "v = {}", cmd.v);
    assert!(cmd.omega.abs() < 1e-12, "ω = {}", cmd.omega);
    // Acceleration across the heading does not change v.
    let c2 = d.command(Input::new(0.7, 0.0), theta, 0.02);
    assert!((c2.v - 0.1).abs() < 1e-12);
}

#[test]
fn yaw_rate_is_eq_6_4_away_from_the_guard() {
    let mut d = drive();
    d.reset(0.2);
    let c = d.command(Input::new(0.0, 0.1), 0.0, 0.0);
    assert!((c.omega - 0.5).abs() < 1e-12, "ω = {}", c.omega);
    // Rotated heading: θ = 0.3, a⊥ = u₂cosθ − u₁sinθ.
    let th: f64 = 0.3;
    let u = Input::new(0.05, 0.08);
    let c = d.command(u, th, 0.0);
    let expect = (u[1] * th.cos() - u[0] * th.sin()) / 0.2;
    assert!((c.omega - expect).abs() < 1e-12);
    // Reversing: v < 0 flips the sign as (6.4) says.
    d.reset(-0.2);
    let c = d.command(Input::new(0.0, 0.1), 0.0, 0.0);
    assert!((c.omega + 0.5).abs() < 1e-12, "ω = {}", c.omega);
}

#[test]
fn guard_at_zero_speed_floors_the_denominator() {
    let mut d = drive();
    let c = d.command(Input::new(0.0, 0.1), 0.0, 0.0);
    assert!(c.omega.is_finite());
    // ω = a⊥ / v_floor = 0.1 / 0.05
    assert!((c.omega - 2.0).abs() < 1e-12, "ω = {}", c.omega);
    assert_eq!(c.v, 0.0);
    // Just above the floor the exact formula is used.
    d.reset(0.06);
    let c = d.command(Input::new(0.0, 0.1), 0.0, 0.0);
    assert!((c.omega - 0.1 / 0.06).abs() < 1e-12);
    // Below the floor on the negative side: −v_floor.
    d.reset(-0.01);
    let c = d.command(Input::new(0.0, 0.1), 0.0, 0.0);
    assert!((c.omega + 2.0).abs() < 1e-12);
}

#[test]
fn limits_clamp_speed_and_yaw_rate() {
    let mut d = drive();
    let c = d.command(Input::new(10.0, 0.0), 0.0, 1.0);
    assert_eq!(c.v, 0.22);
    let c = d.command(Input::new(-100.0, 0.0), 0.0, 1.0);
    assert_eq!(c.v, -0.22);
    d.reset(0.1);
    let c = d.command(Input::new(0.0, 5.0), 0.0, 0.0);
    assert_eq!(c.omega, 2.84);
    let c = d.command(Input::new(0.0, -5.0), 0.0, 0.0);
    assert_eq!(c.omega, -2.84);
}

#[test]
fn non_finite_inputs_hold_speed_and_stop_turning() {
    let mut d = drive();
    d.reset(0.15);
    for (u, th, dt) in [
        (Input::new(f64::NAN, 0.0), 0.0, 0.02),
        (Input::new(0.0, f64::INFINITY), 0.0, 0.02),
        (Input::new(0.1, 0.1), f64::NAN, 0.02),
        (Input::new(0.1, 0.1), 0.0, f64::NAN),
    ] {
        let c = d.command(u, th, dt);
        assert_eq!(c.v, 0.15);
        assert_eq!(c.omega, 0.0);
    }
    d.reset(f64::NAN);
    assert_eq!(d.speed(), 0.0);
}

#[test]
fn wheel_speeds_and_inverse_round_trip() {
    let d = drive();
    let cmd = BodyCommand { v: 0.1, omega: 0.5 };
    let (l, r) = d.wheel_speeds(cmd);
    assert!((l - (0.1 - 0.04) / 0.033).abs() < 1e-12);
    assert!((r - (0.1 + 0.04) / 0.033).abs() < 1e-12);
    let back = d.body_from_wheels(l, r);
    assert!((back.v - 0.1).abs() < 1e-12 && (back.omega - 0.5).abs() < 1e-12);
    // Turning in place.
    let (l, r) = d.wheel_speeds(BodyCommand { v: 0.0, omega: 1.0 });
    assert!((l + r).abs() < 1e-12 && (r - 0.08 / 0.033).abs() < 1e-12);
}

#[test]
fn saturated_wheel_speeds_keep_the_curvature() {
    let d = drive();
    let cmd = BodyCommand {
        v: 0.22,
        omega: 2.0,
    };
    let (l, r) = d.wheel_speeds(cmd);
    assert!((r - LIMITS.wheel_speed_max).abs() < 1e-12, "r = {r}");
    assert!(l.abs() <= LIMITS.wheel_speed_max);
    let got = d.body_from_wheels(l, r);
    // Curvature ω/v unchanged.
    assert!((got.omega / got.v - 2.0 / 0.22).abs() < 1e-9);
    assert!(got.v < 0.22);
}

#[test]
fn invalid_construction_is_a_typed_error() {
    let bad = WheelGeometry {
        radius: 0.0,
        separation: 0.16,
    };
    let e = Drive::new(&bad, &LIMITS, DriveConfig::default()).unwrap_err();
    assert!(matches!(
        e,
        DriveError::InvalidValue {
            key: "wheel radius",
            ..
        }
    ));
    assert!(e.to_string().contains("wheel radius"));
    let e = Drive::new(
        &GEOM,
        &LIMITS,
        DriveConfig {
            v_floor: -1.0,
            ..DriveConfig::default()
        },
    )
    .unwrap_err();
    assert!(e.to_string().contains("v_floor"));
}

#[test]
fn closed_loop_restarts_from_the_measured_speed() {
    // Open loop, the integrator runs ahead of a robot that did not follow (e.g. blocked by a
    // wall): after 10 steps of 0.5 m/s² it commands 0.1 m/s whatever the wheels did.
    let mut open = Drive::new(
        &GEOM,
        &LIMITS,
        DriveConfig {
            speed_gain: 0.0,
            ..DriveConfig::default()
        },
    )
    .unwrap();
    let mut closed = Drive::new(
        &GEOM,
        &LIMITS,
        DriveConfig {
            speed_gain: 1.0,
            ..DriveConfig::default()
        },
    )
    .unwrap();
    for _ in 0..10 {
        open.step(Input::new(0.5, 0.0), 0.0, 0.02, Some(0.0), true);
        closed.step(Input::new(0.5, 0.0), 0.0, 0.02, Some(0.0), true);
    }
    assert!(
        (open.speed() - 0.1).abs() < 1e-12,
        "open loop v = {}",
        open.speed()
    );
    // Closed loop, each step starts from the measured 0 m/s: v = a·dt = 0.01 m/s.
    assert!(
        (closed.speed() - 0.01).abs() < 1e-12,
        "closed loop v = {}",
        closed.speed()
    );
    // A non-finite measurement (a failed encoder read) is ignored, not integrated.
    let (cmd, _) = closed.step(Input::new(0.5, 0.0), 0.0, 0.02, Some(f64::NAN), true);
    assert!((cmd.v - 0.02).abs() < 1e-12, "v = {}", cmd.v);
    let (cmd, _) = closed.step(Input::new(0.5, 0.0), 0.0, 0.02, None, true);
    assert!((cmd.v - 0.03).abs() < 1e-12, "v = {}", cmd.v);
    // The default gain 0.1 pulls a tenth of the way: from 0.1 with 0 measured, 0.09 + a·dt.
    let mut d = drive();
    d.reset(0.1);
    let (cmd, _) = d.step(Input::new(0.5, 0.0), 0.0, 0.02, Some(0.0), true);
    assert!((cmd.v - 0.1).abs() < 1e-12, "v = {}", cmd.v);
}

#[test]
fn wheel_saturation_is_fed_back_to_the_integrator() {
    // Full speed and a hard turn: the outer wheel saturates, both are scaled, and the
    // compensator continues from the speed the wheels actually follow, not from v_max.
    let mut d = drive();
    d.reset(0.22);
    let (sent, (l, r)) = d.step(Input::new(0.0, 0.4), 0.0, 0.02, None, true);
    assert!((r - LIMITS.wheel_speed_max).abs() < 1e-12, "r = {r}");
    assert!(l.abs() < r);
    assert!(sent.v < 0.22 - 1e-3, "sent v = {}", sent.v);
    assert_eq!(d.speed(), sent.v, "integrator = sent speed");
    let back = d.body_from_wheels(l, r);
    assert!((back.v - sent.v).abs() < 1e-15 && (back.omega - sent.omega).abs() < 1e-15);
    // Unsaturated, the sent command is the compensator's.
    let mut d = drive();
    d.reset(0.1);
    let (sent, _) = d.step(Input::new(0.0, 0.05), 0.0, 0.02, None, true);
    assert!((sent.v - 0.1).abs() < 1e-12 && (sent.omega - 0.5).abs() < 1e-12);
}
