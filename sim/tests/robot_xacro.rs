//! Xacro sources run through the real `xacro` (PyPI package `xacro`): a namespaced
//! ROBOTIS-style TurtleBot3 file (`<xacro:arg name="namespace">`, `${ns}base_link`,
//! `$(arg namespace)wheel_left_joint`, comments with xacro text, `package://` meshes).
//!
//! Tests that need xacro skip with a printed reason when it is not installed, except under CI
//! (`CI=true`), where a missing xacro fails them (`.ci/run` installs it).

use std::path::PathBuf;
use std::process::Command;

use ftcbf_sim::robot::{
    LimitsSource, LoadOptions, RobotDescription, RobotError, XacroCommand, XacroOptions,
};

fn fixture() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/urdf/turtlebot3_burger_ns.urdf")
}

/// The repository's STL stand-ins for the TurtleBot3 visual meshes.
fn mesh_packages() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/mesh_packages")
}

/// True when xacro can run; false (after printing why) when it cannot and this is not CI.
/// Panics when CI=true and xacro is missing.
fn xacro_or_skip(test: &str) -> bool {
    let program = Command::new("xacro").arg("--help").output();
    let module = Command::new("python3")
        .args(["-c", "import xacro"])
        .output();
    let ok = program.is_ok_and(|o| o.status.success()) || module.is_ok_and(|o| o.status.success());
    if ok {
        return true;
    }
    if std::env::var("CI").is_ok_and(|v| v == "true") {
        panic!("{test}: CI=true but xacro is not installed (.ci/run runs `python3 -m pip install xacro`)");
    }
    eprintln!("{test}: SKIPPED: xacro is not installed (pip install xacro)");
    false
}

fn opts(args: &[(&str, &str)]) -> LoadOptions {
    LoadOptions {
        package_paths: vec![mesh_packages()],
        xacro: XacroOptions {
            args: args
                .iter()
                .map(|(k, v)| (k.to_string(), v.to_string()))
                .collect(),
            command: XacroCommand::Auto,
        },
        ..LoadOptions::default()
    }
}

#[test]
fn namespaced_robotis_style_file_is_expanded_by_xacro_with_its_defaults() {
    if !xacro_or_skip("namespaced_robotis_style_file_is_expanded_by_xacro_with_its_defaults") {
        return;
    }
    let r = RobotDescription::from_file(fixture(), &opts(&[])).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(r.name, "turtlebot3_burger");
    // namespace defaults to "": the plain names.
    assert_eq!(r.bodies[0].name, "base_footprint");
    assert_eq!(r.wheels.left[0].joint_name, "wheel_left_joint");
    assert_eq!(r.wheels.right[0].joint_name, "wheel_right_joint");
    let g = r.wheels.geometry;
    assert!((g.radius - 0.033).abs() < 1e-12, "{g:?}");
    assert!((g.separation - 0.160).abs() < 1e-12, "{g:?}");
    // No wheel velocity limits in the file: the published burger limits apply.
    assert!(
        matches!(r.limits_source, LimitsSource::Maker(m) if m.robot_name == "turtlebot3_burger")
    );
    assert_eq!((r.limits.v_max, r.limits.omega_max), (0.22, 2.84));
    // The package:// meshes resolve; nothing is left unread.
    assert!(r.warnings.is_empty(), "{:?}", r.warnings);
    let visuals: usize = r.bodies.iter().map(|b| b.visuals.len()).sum();
    assert_eq!(visuals, 4);
    // The expansion is kept on disk, plain URDF.
    let out = r.xacro_output.clone().expect("expanded by xacro");
    let text = std::fs::read_to_string(&out).unwrap();
    assert!(!text.contains("${") && !text.contains("$(arg") && !text.contains("<xacro:arg"));
    assert!(
        out.starts_with(std::env::temp_dir().join("ftcbf-xacro")),
        "{}",
        out.display()
    );
    // Loading again in this process reuses the expansion (same file, same content).
    let again = RobotDescription::from_file(fixture(), &opts(&[])).unwrap();
    assert_eq!(again.xacro_output.as_ref(), Some(&out));
    assert_eq!(again.wheels, r.wheels);
}

#[test]
fn xacro_args_set_the_namespace() {
    if !xacro_or_skip("xacro_args_set_the_namespace") {
        return;
    }
    let r = RobotDescription::from_file(fixture(), &opts(&[("namespace", "tb3_0/")]))
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(r.bodies[0].name, "tb3_0/base_footprint");
    assert_eq!(r.wheels.left[0].joint_name, "tb3_0/wheel_left_joint");
    assert!(r.body_of_link("tb3_0/base_scan").is_some());
    let plain = RobotDescription::from_file(fixture(), &opts(&[])).unwrap();
    assert_ne!(
        r.xacro_output, plain.xacro_output,
        "cached per argument set"
    );
    assert_eq!(r.wheels.geometry, plain.wheels.geometry);
}

#[test]
fn a_failing_expansion_reports_xacros_message() {
    if !xacro_or_skip("a_failing_expansion_reports_xacros_message") {
        return;
    }
    let dir = std::env::temp_dir().join(format!("ftcbf-xacro-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("broken.urdf");
    let text = std::fs::read_to_string(fixture())
        .unwrap()
        .replace("${wheel_y}", "${wheel_why}");
    std::fs::write(&path, text).unwrap();
    let e = RobotDescription::from_file(&path, &opts(&[])).unwrap_err();
    let msg = e.to_string();
    assert!(matches!(e, RobotError::XacroFailed { .. }), "{e:?}");
    assert!(
        msg.contains("broken.urdf") && msg.contains("xacro failed") && msg.contains("wheel_why"),
        "{msg}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn without_xacro_the_error_says_how_to_install_it() {
    // Runs everywhere: the command is one that does not exist.
    let o = LoadOptions {
        xacro: XacroOptions {
            command: XacroCommand::Program(vec!["/nonexistent/bin/xacro".into()]),
            ..XacroOptions::default()
        },
        ..opts(&[])
    };
    let e = RobotDescription::from_file(fixture(), &o).unwrap_err();
    let text = std::fs::read_to_string(fixture()).unwrap();
    let line = text
        .lines()
        .position(|l| l.contains("<xacro:arg name=\"namespace\""))
        .unwrap()
        + 1;
    assert!(
        matches!(&e, RobotError::XacroUnavailable { line: l, .. } if *l == line),
        "{e:?} (expected line {line})"
    );
    let msg = e.to_string();
    assert!(
        msg.contains("pip install xacro")
            && msg.contains("<xacro:arg")
            && msg.contains("/nonexistent/bin/xacro"),
        "{msg}"
    );
    // With expansion disabled the file is refused as a xacro source, with its line.
    let o = LoadOptions {
        xacro: XacroOptions {
            command: XacroCommand::Disabled,
            ..XacroOptions::default()
        },
        ..opts(&[])
    };
    let e = RobotDescription::from_file(fixture(), &o).unwrap_err();
    assert!(
        matches!(&e, RobotError::Xacro { line: l, .. } if *l == line),
        "{e:?}"
    );
}
