//! Worlds written as a user writes them (issue #36): only the keys a user needs — robot, start,
//! goal, obstacles, sensors, fault patterns, attacks, an input limit — and every tuning key at its
//! default. They must be as safe, smooth and live as the catalogue, judged by their `[expect]`
//! over 8 seeds through the same library call as `ftcbf regress`.

mod common;

use std::path::PathBuf;

use ftcbf_lab::regress::Plan;
use ftcbf_sim::world::{FormSpec, LowSpeedSpec, World};

fn dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/worlds_user")
}

#[test]
fn user_worlds_with_defaults_only_are_safe_and_reach_their_goals() {
    let plan = Plan::load(&[dir()]).unwrap_or_else(|e| panic!("{e}"));
    assert!(plan.cases.len() >= 2, "only {} cases", plan.cases.len());
    for c in &plan.cases {
        let f = &c.world.world().file;
        // No tuning key in the files: the defaults are what is tested.
        assert!(
            f.control.form_declared.is_none(),
            "{}: form",
            c.world.world().name
        );
        assert!(
            f.control.cbf_gain_declared.is_none(),
            "{}: cbf_gain",
            c.world.world().name
        );
        assert!(
            f.control.process_noise.is_none(),
            "{}: process_noise",
            c.world.world().name
        );
        assert!(
            f.control.drive.low_speed.is_none(),
            "{}: drive",
            c.world.world().name
        );
    }
    common::assert_plan_passes(&plan);
}

fn parse(text: &str) -> Result<World, String> {
    let path = dir().join("inline.toml");
    World::from_str(text, &path, &[]).map_err(|e| e.to_string())
}

const ROBOT: &str = r#"
[robot]
urdf = "../../robots/turtlebot3_burger.urdf"
start = { x = 0.0, y = 0.0, theta = 0.0 }
[goal]
center = [1.0, 0.0]
radius = 0.1
"#;

#[test]
fn a_world_without_control_takes_the_robot_defaults() {
    let text = format!(
        "duration = 5.0\n{ROBOT}
[[sensors]]
name = \"gx\"
measures = \"x\"
noise_std = 0.02
[[sensors]]
name = \"gy\"
measures = \"y\"
noise_std = 0.02
[[sensors]]
name = \"el\"
measures = \"wheel_left\"
noise_std = 0.0
[[sensors]]
name = \"er\"
measures = \"wheel_right\"
noise_std = 0.0
[[sensors]]
name = \"odom\"
measures = \"speed\"
from_wheels = [\"el\", \"er\"]
[[sensors]]
name = \"compass\"
measures = \"heading\"
noise_std = 0.01
[[fault_patterns]]
name = \"gnss\"
channels = [\"gx\", \"gy\"]
"
    );
    let w = parse(&text).expect("a world with no [control] table loads");
    let c = &w.file.control;
    assert_eq!(c.form, FormSpec::SafetyFilter);
    assert!((c.cbf_gain - 10.0).abs() < 1e-12);
    assert!((c.rate_hz - 50.0).abs() < 1e-12);
    assert!(
        c.drive.low_speed.is_none(),
        "resolved by the drive, not the file"
    );
    let odom = w
        .file
        .sensors
        .iter()
        .find(|s| s.name == "odom")
        .expect("odom");
    assert_eq!(
        odom.noise_std, 0.0,
        "a derived channel adds no noise of its own"
    );
    assert!(
        odom.world_velocity,
        "odometry reaches the filters with a heading"
    );
    // The linear plant keeps the thesis' form and gain.
    let lin = parse(
        "duration = 5.0\ndynamics = \"linear\"\n[linear]\ndt = 0.001\nx0 = [1.0, 0.0, 0.0, 0.0]
[goal]\ncenter = [0.0, 0.0]\nradius = 0.05
[[sensors]]\nname = \"x\"\nmeasures = \"x\"\nnoise_std = 0.03
[[sensors]]\nname = \"y\"\nmeasures = \"y\"\nnoise_std = 0.03
[[sensors]]\nname = \"vx\"\nmeasures = \"vx\"\nnoise_std = 0.03
[[sensors]]\nname = \"vy\"\nmeasures = \"vy\"\nnoise_std = 0.03
[[fault_patterns]]\nname = \"r\"\nchannels = [\"x\"]\n",
    )
    .expect("linear world");
    assert_eq!(lin.file.control.form, FormSpec::Paper);
    assert!((lin.file.control.cbf_gain - 1.0).abs() < 1e-12);
}

#[test]
fn declared_keys_win_and_a_measured_channel_still_needs_its_noise() {
    let declared = format!(
        "duration = 5.0\n{ROBOT}
[control]
form = \"paper\"
cbf_gain = 2.5
[control.drive]
low_speed = \"floor\"
[[sensors]]
name = \"gx\"
measures = \"x\"
noise_std = 0.02
[[sensors]]
name = \"gy\"
measures = \"y\"
noise_std = 0.02
[[sensors]]
name = \"odom\"
measures = \"speed\"
noise_std = 0.01
world_velocity = false
[[sensors]]
name = \"compass\"
measures = \"heading\"
noise_std = 0.01
[[fault_patterns]]
name = \"gnss\"
channels = [\"gx\"]
"
    );
    let w = parse(&declared).expect("loads");
    assert_eq!(w.file.control.form, FormSpec::Paper);
    assert!((w.file.control.cbf_gain - 2.5).abs() < 1e-12);
    assert_eq!(w.file.control.drive.low_speed, Some(LowSpeedSpec::Floor));
    assert!(
        !w.file.sensors[2].world_velocity,
        "an explicit opt-out holds"
    );

    let missing = format!(
        "duration = 5.0\n{ROBOT}
[[sensors]]
name = \"gx\"
measures = \"x\"
[[sensors]]
name = \"gy\"
measures = \"y\"
noise_std = 0.02
[[sensors]]
name = \"compass\"
measures = \"heading\"
noise_std = 0.01
"
    );
    let e = parse(&missing).expect_err("a GNSS channel without noise_std is refused");
    assert!(e.contains("gx") && e.contains("noise_std"), "{e}");
}

/// "A knob every catalogue world sets is a default that is wrong" (issue #36): no catalogue
/// world sets a tuning key any more (`form`, `cbf_gain`, `[control.drive]`), except the paper's
/// own form and κ in the worlds that reproduce the thesis (the paper form, or the linear model).
#[test]
fn catalogue_worlds_set_no_tuning_key_but_the_papers_own() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("worlds");
    let mut n = 0;
    for entry in std::fs::read_dir(&root).expect("worlds/ is readable") {
        let path = entry.expect("a directory entry").path();
        if path.extension().is_none_or(|x| x != "toml") {
            continue;
        }
        let w = World::load(&path, &[]).unwrap_or_else(|e| panic!("{e}"));
        let c = &w.file.control;
        let paper = c.form_declared == Some(FormSpec::Paper)
            || matches!(w.file.dynamics, ftcbf_sim::world::Dynamics::Linear);
        assert!(
            c.form_declared.is_none() || paper,
            "{}: form = safety_filter is the default",
            w.name
        );
        if !paper {
            assert!(c.cbf_gain_declared.is_none(), "{}: cbf_gain", w.name);
        }
        let d = &c.drive;
        assert!(
            d.low_speed.is_none()
                && d.low_speed_scale.is_none()
                && d.dv_max.is_none()
                && d.domega_max.is_none()
                && d.wheel_speed_resolution.is_none(),
            "{}: [control.drive]",
            w.name
        );
        n += 1;
    }
    assert!(n >= 16, "only {n} catalogue worlds");
}
