//! A world file can drive a TurtleBot3 URDF as ROS ships it: its wheel joints carry no speed
//! limits, so the world's `[robot] limits` supply them; missing visual meshes are warnings.

use std::path::PathBuf;

use ftcbf_sim::runner::{run, RunOptions};
use ftcbf_sim::world::{Override, World};

fn path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/worlds_ros/ros_burger.toml")
}

#[test]
fn ros_urdf_runs_with_limits_from_the_world() {
    let w = World::load(&path(), &[]).expect("loads");
    let robot = w.robot.as_ref().expect("rapier world");
    assert!(
        (robot.limits.omega_max - 2.84).abs() < 1e-12,
        "limits from the world file"
    );
    assert!((robot.wheels.geometry.radius - 0.033).abs() < 1e-9);
    assert!(
        !robot.warnings.is_empty(),
        "missing visual meshes are reported as warnings"
    );
    let s = run(&w, &RunOptions::default()).expect("runs");
    assert!(s.safe && !s.collided, "{s:?}");
    assert!(
        s.goal_reached,
        "reaches (1, 0) within 12 s: {:?}",
        s.final_state
    );
}

#[test]
fn bad_limits_name_their_key() {
    let e = World::load(
        &path(),
        &[Override {
            key: "robot.limits.omega_max".into(),
            value: -1.0,
        }],
    )
    .expect_err("negative limit");
    assert!(e.to_string().contains("robot.limits.omega_max"), "{e}");
}

#[test]
fn skid_steer_ros_robot_drives_between_pillars_to_the_goal_under_attack() {
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/worlds_ros/skid_steer_pillars.toml");
    let w = World::load(&path, &[]).expect("loads");
    let robot = w.robot.as_ref().expect("rapier world");
    assert!(robot.wheels.is_skid_steer());
    assert_eq!((robot.wheels.left.len(), robot.wheels.right.len()), (2, 2));
    let s = run(&w, &RunOptions::default()).expect("runs");
    assert!(s.safe && !s.collided, "{s:?}");
    assert!(!s.attacks_outside_fault_patterns, "{s:?}");
    assert!(
        s.goal_reached,
        "reaches (2.5, 0) within 25 s: {:?}",
        s.final_state
    );
    let clearance = s.min_clearance.expect("obstacles");
    assert!(clearance > 0.0, "{clearance}");
}

/// True when xacro can run; false (after printing why) when it cannot and this is not CI.
/// Panics when CI=true and xacro is missing (`.ci/run` installs it).
fn xacro_or_skip(test: &str) -> bool {
    use std::process::Command;
    let program = Command::new("xacro").arg("--help").output();
    let module = Command::new("python3")
        .args(["-c", "import xacro"])
        .output();
    if program.is_ok_and(|o| o.status.success()) || module.is_ok_and(|o| o.status.success()) {
        return true;
    }
    if std::env::var("CI").is_ok_and(|v| v == "true") {
        panic!("{test}: CI=true but xacro is not installed (.ci/run runs `python3 -m pip install xacro`)");
    }
    eprintln!("{test}: SKIPPED: xacro is not installed (pip install xacro)");
    false
}

#[test]
fn namespaced_xacro_turtlebot_drives_past_a_block_under_attack() {
    if !xacro_or_skip("namespaced_xacro_turtlebot_drives_past_a_block_under_attack") {
        return;
    }
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/worlds_ros/tb3_xacro_ns.toml");
    let w = World::load(&path, &[]).unwrap_or_else(|e| panic!("{e}"));
    let robot = w.robot.as_ref().expect("rapier world");
    // `[robot] xacro_args = { namespace = "tb3_" }` reached xacro.
    assert_eq!(robot.wheels.left[0].joint_name, "tb3_wheel_left_joint");
    assert!(robot.xacro_output.is_some());
    // Limits: ROBOTIS's published burger figures (the file has none, the world gives none).
    assert_eq!((robot.limits.v_max, robot.limits.omega_max), (0.22, 2.84));
    assert!(robot.warnings.is_empty(), "{:?}", robot.warnings);
    let s = run(&w, &RunOptions::default()).expect("runs");
    assert!(s.safe && !s.collided, "{s:?}");
    assert!(
        s.goal_reached,
        "reaches (2, 0) within 25 s: {:?}",
        s.final_state
    );
    assert!(s.min_clearance.expect("an obstacle") > 0.0, "{s:?}");
}

/// Loads and runs a world of `tests/worlds_ros/`, asserting safe, no collision, goal reached.
fn drives_safely_to_the_goal(name: &str) -> ftcbf_sim::world::World {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/worlds_ros")
        .join(name);
    let w = World::load(&path, &[]).unwrap_or_else(|e| panic!("{e}"));
    let s = run(&w, &RunOptions::default()).expect("runs");
    assert!(s.safe && !s.collided, "{name}: {s:?}");
    assert!(!s.attacks_outside_fault_patterns, "{name}: {s:?}");
    assert!(s.goal_reached, "{name}: {:?}", s.final_state);
    assert!(s.min_clearance.expect("obstacles") > 0.0, "{name}: {s:?}");
    w
}

#[test]
fn pioneer_style_robot_with_mesh_wheels_drives_past_a_block_under_attack() {
    let w = drives_safely_to_the_goal("pioneer_style_block.toml");
    let r = w.robot.as_ref().expect("rapier");
    assert!((r.wheels.geometry.radius - 0.0975).abs() < 1e-6);
}

#[test]
fn qbot_style_robot_with_collada_wheels_drives_between_pillars_under_attack() {
    let w = drives_safely_to_the_goal("qbot_style_pillars.toml");
    let r = w.robot.as_ref().expect("rapier");
    assert!((r.wheels.geometry.radius - 0.035).abs() < 1e-6);
}

#[test]
fn pioneer_robot_with_fixed_wheel_joints_drives_when_the_world_names_them() {
    let w = drives_safely_to_the_goal("pioneer_fixed_wheels_block.toml");
    let r = w.robot.as_ref().expect("rapier");
    assert_eq!(r.wheels.left[0].joint_name, "left_hub_joint");
    assert!((r.wheels.geometry.radius - 0.0925).abs() < 1e-12);
    // The hubs' mass came from their cylinders (the file gives them none).
    let hub = r.body_of_link("left_hub").expect("hub body");
    assert!(
        r.bodies[hub].mass > 0.5 && r.bodies[hub].mass < 0.55,
        "{}",
        r.bodies[hub].mass
    );
}

#[test]
fn qbot2e_robot_drives_with_its_package_folder_mapped_by_name() {
    let w = drives_safely_to_the_goal("qbot2e_style_pillars.toml");
    let r = w.robot.as_ref().expect("rapier");
    assert!((r.wheels.geometry.radius - 0.035).abs() < 1e-6);
    assert!(r.warnings.is_empty(), "{:?}", r.warnings);
}
