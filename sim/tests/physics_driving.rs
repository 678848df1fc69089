//! The burger driving in rapier: straight line, turning in place, no sinking/tipping/drift,
//! collisions with a wall at the analytic time, none when passing beside an obstacle.

use std::path::PathBuf;

use ftcbf_sim::drivetrain::{BodyCommand, Drive, DriveConfig};
use ftcbf_sim::obstacles::{Obstacle, ObstacleSpec, ShapeSpec};
use ftcbf_sim::physics::{PhysicsConfig, PhysicsWorld, Pose2};
use ftcbf_sim::robot::{LoadOptions, RobotDescription};

fn burger() -> RobotDescription {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../robots/turtlebot3_burger.urdf");
    RobotDescription::from_file(p, &LoadOptions::default()).unwrap()
}

fn run_command(
    world: &mut PhysicsWorld,
    drive: &Drive,
    cmd: BodyCommand,
    seconds: f64,
    mut each: impl FnMut(&PhysicsWorld),
) {
    let (l, r) = drive.wheel_speeds(cmd);
    world.set_wheel_speeds(l, r);
    let n = (seconds / world.config().dt).round() as usize;
    for _ in 0..n {
        world.step();
        each(world);
    }
}

#[test]
fn straight_0_2_m_s_for_2_s_travels_0_40_m_without_sinking_tipping_or_drifting() {
    let robot = burger();
    let cfg = PhysicsConfig::default();
    let mut w = PhysicsWorld::new(&robot, Pose2::default(), &[], &cfg).unwrap();
    let drive = Drive::new(
        &robot.wheels.geometry,
        &robot.limits,
        DriveConfig::default(),
    )
    .unwrap();
    let (mut z_min, mut z_max, mut tilt_max, mut lat_max) = (f64::MAX, f64::MIN, 0.0_f64, 0.0_f64);
    run_command(
        &mut w,
        &drive,
        BodyCommand { v: 0.2, omega: 0.0 },
        2.0,
        |w| {
            let z = w.root_height();
            z_min = z_min.min(z);
            z_max = z_max.max(z);
            tilt_max = tilt_max.max(w.tilt());
            lat_max = lat_max.max(w.truth().y.abs());
        },
    );
    let t = w.truth();
    println!(
        "straight: x = {:.4} m, y = {:.5} m, θ = {:.5}, v = {:.4}, z ∈ [{z_min:.5}, {z_max:.5}], tilt ≤ {tilt_max:.5}",
        t.x, t.y, t.theta, t.v_body
    );
    assert!((t.x - 0.40).abs() <= 0.02, "travelled {} m", t.x);
    assert!(lat_max < 0.01, "lateral drift {lat_max} m");
    assert!(
        z_min > -0.003 && z_max < 0.003,
        "root height in [{z_min}, {z_max}]"
    );
    assert!(tilt_max < 0.05, "tilt {tilt_max} rad");
    assert!((t.v_body - 0.2).abs() < 0.01, "speed {}", t.v_body);
    assert!((w.time() - 2.0).abs() < 1e-9);
    let (wl, wr) = w.wheel_speeds();
    assert!(
        (wl - 0.2 / 0.033).abs() < 0.3 && (wr - 0.2 / 0.033).abs() < 0.3,
        "{wl} {wr}"
    );
}

#[test]
fn turning_in_place_matches_the_commanded_yaw_rate() {
    let robot = burger();
    let cfg = PhysicsConfig::default();
    let mut w = PhysicsWorld::new(
        &robot,
        Pose2 {
            x: 0.5,
            y: -0.3,
            theta: 0.4,
        },
        &[],
        &cfg,
    )
    .unwrap();
    let drive = Drive::new(
        &robot.wheels.geometry,
        &robot.limits,
        DriveConfig::default(),
    )
    .unwrap();
    let omega = 1.0;
    // Spin up for 0.5 s, then measure the mean yaw rate over 2 s by unwrapping θ.
    run_command(&mut w, &drive, BodyCommand { v: 0.0, omega }, 0.5, |_| {});
    let t0 = w.truth();
    let (mut prev, mut total) = (t0.theta, 0.0);
    let mut max_drift: f64 = 0.0;
    run_command(&mut w, &drive, BodyCommand { v: 0.0, omega }, 2.0, |w| {
        let t = w.truth();
        let mut d = t.theta - prev;
        d = (d + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI)
            - std::f64::consts::PI;
        total += d;
        prev = t.theta;
        max_drift = max_drift.max(((t.x - 0.5).powi(2) + (t.y + 0.3).powi(2)).sqrt());
    });
    let rate = total / 2.0;
    println!("turn: mean ω = {rate:.4} rad/s (commanded {omega}), centre drift ≤ {max_drift:.4} m, tilt {:.5}", w.tilt());
    assert!((rate - omega).abs() <= 0.05 * omega, "ω = {rate}");
    assert!(max_drift < 0.02, "the centre wandered {max_drift} m");
    assert!(w.tilt() < 0.05);
}

fn wall_at(x: f64) -> Obstacle {
    Obstacle::from_spec(
        &ObstacleSpec {
            name: "wall".into(),
            position: [x, 0.0, 0.0],
            rpy: [0.0; 3],
            shape: ShapeSpec::HalfSpace {
                normal: [-1.0, 0.0, 0.0],
            },
            motion: None,
            tracker: None,
        },
        None,
    )
    .unwrap()
}

#[test]
fn driving_into_a_wall_is_a_collision_at_the_analytic_time() {
    let robot = burger();
    let cfg = PhysicsConfig::default();
    let wall_x = 0.6;
    let mut w = PhysicsWorld::new(&robot, Pose2::default(), &[wall_at(wall_x)], &cfg).unwrap();
    let drive = Drive::new(
        &robot.wheels.geometry,
        &robot.limits,
        DriveConfig::default(),
    )
    .unwrap();
    // Front of the burger's collision geometry: base box and lidar both reach x = +0.038 m.
    let front = 0.038;
    let v = 0.2;
    run_command(&mut w, &drive, BodyCommand { v, omega: 0.0 }, 1.0, |w| {
        assert_eq!(
            w.contacts().count(),
            0,
            "contact before reaching the wall at t = {}",
            w.time()
        );
    });
    // At steady speed: expected contact time from the remaining gap and the mean speed
    // over the last 0.5 s.
    let x_half = w.truth().x;
    run_command(&mut w, &drive, BodyCommand { v, omega: 0.0 }, 0.5, |_| {});
    let v_meas = (w.truth().x - x_half) / 0.5;
    let t0 = w.time();
    let gap = wall_x - front - w.truth().x;
    let expected = t0 + gap / v_meas;
    let mut first = None;
    let mut clear = Vec::new();
    run_command(&mut w, &drive, BodyCommand { v, omega: 0.0 }, 3.0, |w| {
        if first.is_none() && w.contacts().any(|i| i == 0) {
            first = Some(w.time());
            w.clearances(&mut clear);
        }
    });
    let first = first.expect("no collision reported");
    println!(
        "wall: contact at {first:.4} s, analytic {expected:.4} s, clearance then {:.5} m",
        clear[0]
    );
    // Tolerance 0.01 s = 2 mm of travel (one 1/240 s step is 0.8 mm; contact threshold 1 mm).
    assert!(
        (first - expected).abs() < 0.01,
        "contact at {first}, expected {expected}"
    );
    assert!(clear[0] <= 2e-3, "clearance at contact {}", clear[0]);
    // Pushing against the wall: still in contact and not through it.
    assert_eq!(w.contacts().collect::<Vec<_>>(), vec![0]);
    assert!(w.truth().x + front < wall_x + 0.01);
}

#[test]
fn passing_5_cm_beside_an_obstacle_is_not_a_collision() {
    let robot = burger();
    let cfg = PhysicsConfig::default();
    // The burger's widest point is the outer wheel face at y = ±(0.080 + 0.009) = ±0.089 m.
    let half_width = 0.089;
    let inner_face = half_width + 0.05;
    let block = Obstacle::from_spec(
        &ObstacleSpec {
            name: "block".into(),
            position: [0.3, inner_face + 0.1, 0.1],
            rpy: [0.0; 3],
            shape: ShapeSpec::Cuboid {
                half_extents: [0.1, 0.1, 0.1],
            },
            motion: None,
            tracker: None,
        },
        None,
    )
    .unwrap();
    let mut w = PhysicsWorld::new(&robot, Pose2::default(), &[block], &cfg).unwrap();
    let drive = Drive::new(
        &robot.wheels.geometry,
        &robot.limits,
        DriveConfig::default(),
    )
    .unwrap();
    let mut min_clear = f64::MAX;
    let mut buf = Vec::new();
    let mut contacts = 0;
    run_command(
        &mut w,
        &drive,
        BodyCommand { v: 0.2, omega: 0.0 },
        3.5,
        |w| {
            contacts += w.contacts().count();
            w.clearances(&mut buf);
            min_clear = min_clear.min(buf[0]);
        },
    );
    println!(
        "beside: min clearance {min_clear:.5} m, x end {:.3}",
        w.truth().x
    );
    assert_eq!(contacts, 0);
    assert!(w.truth().x > 0.6, "the robot did not pass the block");
    assert!(
        (min_clear - 0.05).abs() < 0.005,
        "min clearance {min_clear}"
    );
}

#[test]
fn link_poses_and_truth_are_consistent_and_deterministic() {
    let robot = burger();
    let cfg = PhysicsConfig::default();
    let run = || {
        let mut w = PhysicsWorld::new(
            &robot,
            Pose2 {
                x: 1.0,
                y: 2.0,
                theta: 1.0,
            },
            &[wall_at(3.0)],
            &cfg,
        )
        .unwrap();
        w.set_wheel_speeds(3.0, 5.0);
        for _ in 0..240 {
            w.step();
        }
        let poses: Vec<(String, [f32; 3], [f32; 4])> = w
            .link_poses()
            .map(|(n, t, q)| (n.to_string(), t, q))
            .collect();
        (w.truth(), poses)
    };
    let (t1, p1) = run();
    let (t2, p2) = run();
    assert_eq!(t1, t2, "same inputs must give bit-identical truth");
    assert_eq!(p1, p2);
    assert_eq!(p1.len(), robot.bodies.len());
    assert_eq!(p1[0].0, "base_footprint");
    assert!(((p1[0].1[0] as f64) - t1.x).abs() < 1e-5 && ((p1[0].1[1] as f64) - t1.y).abs() < 1e-5);
    // Unequal wheel speeds turn left (right wheel faster).
    assert!(t1.omega > 0.1, "ω = {}", t1.omega);
    assert!(t1.v_body > 0.0);
}

#[test]
fn invalid_physics_config_is_a_typed_error() {
    let robot = burger();
    let cfg = PhysicsConfig {
        dt: 0.0,
        ..PhysicsConfig::default()
    };
    let e = PhysicsWorld::new(&robot, Pose2::default(), &[], &cfg).unwrap_err();
    assert!(e.to_string().contains("`dt`"), "{e}");
    let e = PhysicsWorld::new(
        &robot,
        Pose2 {
            x: f64::NAN,
            y: 0.0,
            theta: 0.0,
        },
        &[],
        &PhysicsConfig::default(),
    )
    .unwrap_err();
    assert!(e.to_string().contains("start pose"), "{e}");
}

#[test]
fn waffle_and_ros_style_burger_drive_with_their_own_geometry() {
    use ftcbf_sim::robot::DriveLimits;
    let waffle = RobotDescription::from_file(
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../robots/turtlebot3_waffle.urdf"),
        &LoadOptions::default(),
    )
    .unwrap();
    let ros = RobotDescription::from_file(
        PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("tests/fixtures/urdf/turtlebot3_burger_ros.urdf"),
        &LoadOptions {
            limits: Some(DriveLimits {
                v_max: 0.22,
                omega_max: 2.84,
                wheel_speed_max: 0.22 / 0.033,
            }),
            ..LoadOptions::default()
        },
    )
    .unwrap();
    for robot in [waffle, ros] {
        let cfg = PhysicsConfig::default();
        let drive = Drive::new(
            &robot.wheels.geometry,
            &robot.limits,
            DriveConfig::default(),
        )
        .unwrap();
        // Turn in place at 0.8 rad/s for 2 s after 0.5 s spin-up.
        let mut w = PhysicsWorld::new(&robot, Pose2::default(), &[], &cfg).unwrap();
        run_command(
            &mut w,
            &drive,
            BodyCommand { v: 0.0, omega: 0.8 },
            0.5,
            |_| {},
        );
        let (mut prev, mut total) = (w.truth().theta, 0.0);
        run_command(
            &mut w,
            &drive,
            BodyCommand { v: 0.0, omega: 0.8 },
            2.0,
            |w| {
                let t = w.truth().theta;
                total += (t - prev + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI)
                    - std::f64::consts::PI;
                prev = t;
            },
        );
        let rate = total / 2.0;
        // Straight 0.15 m/s for 2 s.
        let mut w = PhysicsWorld::new(&robot, Pose2::default(), &[], &cfg).unwrap();
        let mut tilt: f64 = 0.0;
        run_command(
            &mut w,
            &drive,
            BodyCommand {
                v: 0.15,
                omega: 0.0,
            },
            2.0,
            |w| tilt = tilt.max(w.tilt()),
        );
        let t = w.truth();
        println!(
            "{}: ω {rate:.4} (0.8), x {:.4} (0.30), y {:.5}, tilt ≤ {tilt:.5}",
            robot.origin, t.x, t.y
        );
        assert!((rate - 0.8).abs() <= 0.04, "{}: ω {rate}", robot.origin);
        assert!((t.x - 0.30).abs() <= 0.015, "{}: x {}", robot.origin, t.x);
        assert!(t.y.abs() < 0.01 && tilt < 0.05 && w.root_height().abs() < 0.003);
    }
}
