//! Coverage over robot files written in the style of public ROS description packages
//! (`tests/fixtures/ros_ws/src/ftcbf_coverage_description`): the Pioneer's attribute typo,
//! `package://` meshes in STL, Collada and OBJ, wheels measured from their collision meshes,
//! a swivel caster whose wheel is a continuous joint, sphere casters, a four-wheel skid steer
//! written as xacro with arguments. Files ROS would refuse are refused with element and line.

use std::path::PathBuf;

use ftcbf_sim::robot::{
    CollisionShape, LimitsSource, LoadOptions, RobotDescription, RobotError, XacroCommand,
    XacroOptions,
};

fn src() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/ros_ws/src")
}

fn file(name: &str) -> PathBuf {
    src().join("ftcbf_coverage_description/urdf").join(name)
}

fn opts() -> LoadOptions {
    LoadOptions {
        package_paths: vec![src()],
        ..LoadOptions::default()
    }
}

/// The wheel collider of `joint`'s body: after loading, a cylinder (a mesh wheel rolls on the
/// cylinder of its measured extent).
fn wheel_cylinder(r: &RobotDescription, joint: &str) -> (f64, f64) {
    let w = r
        .wheels
        .all()
        .find(|w| w.joint_name == joint)
        .unwrap_or_else(|| panic!("no wheel {joint}"));
    let cyl: Vec<(f64, f64)> = r.bodies[w.body]
        .colliders
        .iter()
        .filter_map(|c| match c.shape {
            CollisionShape::Cylinder {
                radius,
                half_length,
            } => Some((radius, half_length)),
            _ => None,
        })
        .collect();
    assert_eq!(cyl.len(), 1, "{:?}", r.bodies[w.body].colliders);
    assert!(r.bodies[w.body].colliders.iter().all(|c| c.is_wheel));
    cyl[0]
}

#[test]
fn pioneer_style_file_loads_with_stl_mesh_wheels_and_a_swivel_caster() {
    let r = RobotDescription::from_file(file("pioneer_style.urdf"), &opts())
        .unwrap_or_else(|e| panic!("{e}"));
    // The typo is a warning, the stray element too; nothing else.
    assert_eq!(r.warnings.len(), 2, "{:?}", r.warnings);
    assert!(
        r.warnings[0].contains("unknown attribute `xzy`"),
        "{:?}",
        r.warnings
    );
    assert!(
        r.warnings[1].contains("unknown element <sensor_note>"),
        "{:?}",
        r.warnings
    );
    // Wheels: the two hub joints (the caster's wheel hangs from its swivel and is no drive
    // wheel), radius and width measured from the STL about the joint axis (0.0975 m, 0.037 m;
    // the file's corners lie on the radius, written with 6 decimals).
    assert!(!r.wheels.is_skid_steer());
    assert_eq!(r.wheels.left[0].joint_name, "left_hub_joint");
    assert_eq!(r.wheels.right[0].joint_name, "right_hub_joint");
    let g = r.wheels.geometry;
    assert!((g.radius - 0.0975).abs() < 1e-6, "{g:?}");
    assert!((g.separation - 0.316).abs() < 1e-12, "{g:?}");
    for j in ["left_hub_joint", "right_hub_joint"] {
        let (radius, half) = wheel_cylinder(&r, j);
        assert!((radius - 0.0975).abs() < 1e-6 && (half - 0.0185).abs() < 1e-6);
    }
    // Limits from <limit velocity="3">: v = r·3.
    assert_eq!(r.limits_source, LimitsSource::WheelJoints);
    assert!(
        (r.limits.v_max - 0.0975 * 3.0).abs() < 5e-6,
        "{:?}",
        r.limits
    );
    // The caster joints are movable joints of the model, not wheels.
    assert!(r.joints.iter().any(|j| j.name == "swivel_joint"));
    assert!(r.joints.iter().any(|j| j.name == "center_wheel_joint"));
}

#[test]
fn qbot_style_file_loads_with_collada_wheels_an_obj_chassis_and_sphere_casters() {
    // No wheel velocity limits and no maker figures for this name: an error naming the joint
    // and its line, unless limits are given.
    let e = RobotDescription::from_file(file("qbot_style.urdf"), &opts()).unwrap_err();
    let msg = e.to_string();
    let text = std::fs::read_to_string(file("qbot_style.urdf")).unwrap();
    let line = text
        .lines()
        .position(|l| l.contains("<joint name=\"wheel_left_joint\""))
        .unwrap()
        + 1;
    assert!(
        msg.contains(&format!(
            "wheel joint `wheel_left_joint` (line {line}) has no <limit velocity>"
        )),
        "{msg}"
    );
    let limits = ftcbf_sim::robot::DriveLimits {
        v_max: 0.3,
        omega_max: 2.0,
        wheel_speed_max: 8.57,
    };
    let r = RobotDescription::from_file(
        file("qbot_style.urdf"),
        &LoadOptions {
            limits: Some(limits),
            ..opts()
        },
    )
    .unwrap_or_else(|e| panic!("{e}"));
    assert!(r.warnings.is_empty(), "{:?}", r.warnings);
    // The Collada wheel is in millimetres (<unit meter="0.001">): 35 mm radius, 21 mm wide,
    // about the joint's z axis (positions written with 4 decimals in mm).
    let g = r.wheels.geometry;
    assert!((g.radius - 0.035).abs() < 1e-6, "{g:?}");
    assert!((g.separation - 0.23).abs() < 1e-12, "{g:?}");
    let (radius, half) = wheel_cylinder(&r, "wheel_right_joint");
    assert!((radius - 0.035).abs() < 1e-6 && (half - 0.0105).abs() < 1e-6);
    // The OBJ chassis (a 24-gon of radius 0.176 m) sets the footprint.
    assert!(
        (r.footprint_radius - 0.176).abs() < 1e-5,
        "{}",
        r.footprint_radius
    );
    // Sphere casters and the massless camera frame are part of the chassis body.
    let chassis = r.body_of_link("base_link").unwrap();
    for l in [
        "caster_front_link",
        "caster_back_link",
        "camera_link",
        "base_footprint",
    ] {
        assert_eq!(r.body_of_link(l), Some(chassis), "{l}");
    }
}

#[test]
fn skid_steer_xacro_with_arguments_loads_through_xacro() {
    let xacro_ok = std::process::Command::new("xacro")
        .arg("--help")
        .output()
        .is_ok_and(|o| o.status.success())
        || std::process::Command::new("python3")
            .args(["-c", "import xacro"])
            .output()
            .is_ok_and(|o| o.status.success());
    if !xacro_ok {
        if std::env::var("CI").is_ok_and(|v| v == "true") {
            panic!("CI=true but xacro is not installed");
        }
        eprintln!("skid_steer_xacro_with_arguments_loads_through_xacro: SKIPPED: xacro is not installed (pip install xacro)");
        return;
    }
    let with_args = |args: &[(&str, &str)]| LoadOptions {
        xacro: XacroOptions {
            args: args
                .iter()
                .map(|(k, v)| (k.to_string(), v.to_string()))
                .collect(),
            command: XacroCommand::Auto,
        },
        ..opts()
    };
    // The file's defaults: wheel_radius 0.06, no prefix.
    let r = RobotDescription::from_file(file("skid4.urdf.xacro"), &with_args(&[]))
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(r.wheels.is_skid_steer());
    assert_eq!(r.wheels.left.len() + r.wheels.right.len(), 4);
    assert_eq!(r.wheels.left[0].joint_name, "front_left_wheel_joint");
    assert!((r.wheels.geometry.radius - 0.06).abs() < 1e-12);
    assert!((r.wheels.geometry.separation - 0.34).abs() < 1e-12);
    // velocity = 0.5 / r in the macro: v_max = 0.5 m/s whatever the radius.
    assert!((r.limits.v_max - 0.5).abs() < 1e-9, "{:?}", r.limits);
    // Arguments: a bigger wheel and a prefix.
    let r = RobotDescription::from_file(
        file("skid4.urdf.xacro"),
        &with_args(&[("wheel_radius", "0.07"), ("prefix", "rover1_")]),
    )
    .unwrap_or_else(|e| panic!("{e}"));
    assert!((r.wheels.geometry.radius - 0.07).abs() < 1e-12);
    assert_eq!(
        r.wheels.right[1].joint_name,
        "rover1_rear_right_wheel_joint"
    );
    assert!((r.limits.v_max - 0.5).abs() < 1e-9, "{:?}", r.limits);
}

#[test]
fn files_ros_refuses_are_refused_with_element_and_line() {
    let text = std::fs::read_to_string(file("pioneer_style.urdf")).unwrap();
    let line_of = |t: &str, m: &str| t.lines().position(|l| l.contains(m)).unwrap() + 1;
    let dir = std::env::temp_dir().join(format!("ftcbf-coverage-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let cases: [(&str, &str, &str, &str); 4] = [
        // (edit from, edit to, marker of the reported line, words of the message)
        (
            r#"<limit effort="20" velocity="3"/>"#,
            r#"<limit effort="20"/>"#,
            r#"<limit effort="20"/>"#,
            "<limit> of <joint> `left_hub_joint` has no `velocity`",
        ),
        (
            r#"<mesh filename="package://ftcbf_coverage_description/meshes/pioneer_wheel.stl"/>
      </geometry>
    </collision>"#,
            r#"<mesh scale="1 1 1"/>
      </geometry>
    </collision>"#,
            r#"<mesh scale="1 1 1"/>"#,
            "<mesh> in <geometry> of <collision> of <link> `left_wheel` has no `filename`",
        ),
        (
            r#"<joint name="swivel_joint" type="continuous">"#,
            r#"<joint name="swivel_joint" type="caster">"#,
            r#"type="caster""#,
            "<joint> `swivel_joint` has type `caster`",
        ),
        (
            r#"<inertia ixx="0.11" ixy="0" ixz="0" iyy="0.13" iyz="0" izz="0.20"/>"#,
            r#"<inertia ixx="0.11" ixy="0" ixz="0" iyy="0.13" iyz="0"/>"#,
            r#"iyz="0"/>"#,
            "<inertia> of <link> `base_link` has no `izz`",
        ),
    ];
    for (k, (from, to, marker, words)) in cases.iter().enumerate() {
        let edited = text.replacen(from, to, 1);
        assert_ne!(edited, text, "case {k}");
        let path = dir.join(format!("case{k}.urdf"));
        std::fs::write(&path, &edited).unwrap();
        let e = RobotDescription::from_file(&path, &opts()).unwrap_err();
        let line = line_of(&edited, marker);
        assert!(
            matches!(&e, RobotError::Parse { line: Some(l), .. } if *l == line),
            "case {k}: {e:?} (expected line {line})"
        );
        let msg = e.to_string();
        assert!(
            msg.contains(words) && msg.contains(&format!("case{k}.urdf: line {line}: ")),
            "case {k}: {msg}"
        );
    }
    // A wheel named explicitly whose link has neither a cylinder nor a mesh collision.
    let edited = text.replace(
        r#"<mesh filename="package://ftcbf_coverage_description/meshes/pioneer_wheel.stl"/>
      </geometry>
    </collision>"#,
        r#"<sphere radius="0.0975"/>
      </geometry>
    </collision>"#,
    );
    let path = dir.join("sphere_wheels.urdf");
    std::fs::write(&path, &edited).unwrap();
    let o = LoadOptions {
        wheel_joints: Some(("left_hub_joint".into(), "right_hub_joint".into())),
        ..opts()
    };
    let msg = RobotDescription::from_file(&path, &o)
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("wheel link of joint `left_hub_joint` has no <cylinder> or <mesh> collision"),
        "{msg}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
