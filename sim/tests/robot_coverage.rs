//! Coverage over robot files written in the style of public ROS description packages
//! (`tests/fixtures/ros_ws/src/ftcbf_coverage_description`): the Pioneer's attribute typo,
//! `package://` meshes in STL, Collada and OBJ, wheels measured from their collision meshes,
//! a swivel caster whose wheel is a continuous joint, sphere casters, a four-wheel skid steer
//! written as xacro with arguments. Files ROS would refuse are refused with element and line.

use std::path::{Path, PathBuf};

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
    for (k, case) in cases.iter().enumerate() {
        refused_at_line(&dir, k, &text, *case, &opts());
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

/// Case `k`: `text` with `from` replaced by `to` (once), written to `dir/case{k}.urdf`, is refused
/// with a parse error at the line holding `marker`, whose message names the file, that line and
/// `words`.
fn refused_at_line(
    dir: &Path,
    k: usize,
    text: &str,
    (from, to, marker, words): (&str, &str, &str, &str),
    opts: &LoadOptions,
) {
    let edited = text.replacen(from, to, 1);
    assert_ne!(edited, text, "case {k}");
    let path = dir.join(format!("case{k}.urdf"));
    std::fs::write(&path, &edited).unwrap();
    let e = RobotDescription::from_file(&path, opts).unwrap_err();
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

/// Line (1-based) of the first line of `text` containing `marker`.
fn line_of(text: &str, marker: &str) -> usize {
    text.lines()
        .position(|l| l.contains(marker))
        .unwrap_or_else(|| panic!("no line with {marker}"))
        + 1
}

/// A scratch directory of this test process.
fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("ftcbf-coverage-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn limits() -> ftcbf_sim::robot::DriveLimits {
    ftcbf_sim::robot::DriveLimits {
        v_max: 0.3,
        omega_max: 2.0,
        wheel_speed_max: 3.3,
    }
}

/// `package://meshes/…` of the Pioneer-style file: the package is the `meshes` folder of the
/// description directory.
fn pioneer_opts(wheels: Option<(&str, &str)>) -> LoadOptions {
    LoadOptions {
        package_paths: vec![src().join("ftcbf_coverage_description")],
        wheel_joints: wheels.map(|(l, r)| (l.to_string(), r.to_string())),
        limits: Some(limits()),
        ..LoadOptions::default()
    }
}

#[test]
fn pioneer_file_with_fixed_wheel_joints_drives_the_hubs_a_world_names() {
    let path = file("pioneer_fixed_wheels.urdf");
    let text = std::fs::read_to_string(&path).unwrap();
    let left_line = line_of(&text, r#"<joint name="left_hub_joint""#);
    let right_line = line_of(&text, r#"<joint name="right_hub_joint""#);

    // Found automatically: no continuous wheel joint, and the error names the fixed joints that
    // look like wheels, with their lines, and what to write.
    let e = RobotDescription::from_file(&path, &pioneer_opts(None)).unwrap_err();
    assert!(matches!(e, RobotError::Wheels { .. }), "{e:?}");
    let msg = e.to_string();
    assert!(
        msg.contains(&format!(
            "fixes joint `left_hub_joint` (line {left_line}), joint `right_hub_joint` (line {right_line}) to the chassis"
        )) && msg.contains("[robot] wheels"),
        "{msg}"
    );

    // Named: both hubs are driven as continuous joints about their written <axis>.
    let r = RobotDescription::from_file(
        &path,
        &pioneer_opts(Some(("left_hub_joint", "right_hub_joint"))),
    )
    .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(r.wheels.left[0].joint_name, "left_hub_joint");
    assert_eq!(r.wheels.right[0].joint_name, "right_hub_joint");
    let g = r.wheels.geometry;
    assert!(
        (g.radius - 0.0925).abs() < 1e-12 && (g.separation - 0.32).abs() < 1e-12,
        "{g:?}"
    );
    for w in r.wheels.all() {
        let j = &r.joints[w.joint];
        assert_eq!(
            j.kind,
            ftcbf_sim::robot::JointKind::Continuous,
            "{}",
            j.name
        );
        assert!(
            (j.axis.into_inner() - nalgebra::Vector3::y()).norm() < 1e-12,
            "{:?}",
            j.axis
        );
        assert_eq!(w.forward_sign, 1.0);
    }
    // The tyre (fixed to the hub, visual only) moves with the hub.
    let hub = r.body_of_link("left_hub").unwrap();
    assert_eq!(r.body_of_link("left_wheel"), Some(hub));
    assert_ne!(Some(hub), r.body_of_link("base_link"));
    // Hub and tyre have no <inertial>: the hub body gets its cylinder's mass at 1000 kg/m³
    // and that solid cylinder's inertia (axis along y of the hub frame).
    let m = 1000.0 * std::f64::consts::PI * 0.0925 * 0.0925 * 0.02;
    let b = &r.bodies[hub];
    assert!((b.mass - m).abs() < 1e-9, "{} vs {m}", b.mass);
    assert!(b.com.norm() < 1e-12, "{:?}", b.com);
    let (axial, across) = (
        m * 0.0925 * 0.0925 / 2.0,
        m * (3.0 * 0.0925 * 0.0925 + 0.0004) / 12.0,
    );
    assert!((b.inertia[(1, 1)] - axial).abs() < 1e-9, "{}", b.inertia);
    assert!((b.inertia[(0, 0)] - across).abs() < 1e-9 && (b.inertia[(2, 2)] - across).abs() < 1e-9);
    // The swivel joint has no <axis>: the URDF default (1, 0, 0), as urdfdom reads it.
    let swivel = r
        .joints
        .iter()
        .find(|j| j.name == "base_swivel_joint")
        .unwrap();
    assert!((swivel.axis.into_inner() - nalgebra::Vector3::x()).norm() < 1e-12);
    // Every tolerated oddity is a warning with its line; the promotions and masses are said.
    let has = |words: &str| r.warnings.iter().any(|w| w.contains(words));
    for words in [
        &format!("line {}: unknown attribute `xzy`", line_of(&text, "xzy=")),
        "unknown element <anchor>",
        "unknown element <joint_properties>",
        "unknown attribute `k_velocity`",
        "unknown attribute `name` on <geometry>",
        "unknown element <create>",
        &format!(
            "joint `left_hub_joint` (line {left_line}) is `fixed` in the URDF; [robot] wheels names it, \
             so it is driven as a continuous wheel joint about (0, 1, 0) (its <axis xyz>"
        ),
        "wheel link `right_hub` has no <inertial>",
    ] {
        assert!(has(words), "{words}: {:#?}", r.warnings);
    }
    // Visual meshes under package://meshes/ were found (no "not found" warning).
    assert!(!has("not found"), "{:#?}", r.warnings);
    assert!(r.bodies[0].visuals.iter().any(|v| v.link == "base_link"));

    // Without limits: the fixed joints carry no <limit velocity>; the error names the joint.
    let o = LoadOptions {
        limits: None,
        ..pioneer_opts(Some(("left_hub_joint", "right_hub_joint")))
    };
    let msg = RobotDescription::from_file(&path, &o)
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains(&format!(
            "wheel joint `left_hub_joint` (line {left_line}) has no <limit velocity>"
        )),
        "{msg}"
    );

    // Naming the tyre joints (as the file's Gazebo plugin does): the tyre has no collision to
    // take an axis from; the error points at the hub joint above it.
    let msg = RobotDescription::from_file(
        &path,
        &pioneer_opts(Some(("left_wheel_joint", "right_wheel_joint"))),
    )
    .unwrap_err()
    .to_string();
    assert!(
        msg.contains("is `fixed`, and [robot] wheels names it as a drive wheel")
            && (msg.contains("fixed by joint `left_hub_joint`: name that joint instead")
                || msg.contains("fixed by joint `right_hub_joint`: name that joint instead")),
        "{msg}"
    );
}

#[test]
fn a_named_fixed_wheel_takes_its_axis_from_its_cylinder_else_it_is_refused() {
    let text = std::fs::read_to_string(file("pioneer_fixed_wheels.urdf")).unwrap();
    let dir = scratch("fixed-axis");
    let opts = pioneer_opts(Some(("left_hub_joint", "right_hub_joint")));
    // No <axis> on the hub joints: the axis of the hub's collision cylinder (its z turned by
    // rpy (-1.57079635, 0, 0), i.e. +y to 1e-8).
    let no_axis = text.replace(
        r#"    <child link="left_hub"/>
    <axis xyz="0 1 0"/>"#,
        r#"    <child link="left_hub"/>"#,
    );
    assert_ne!(no_axis, text);
    let path = dir.join("no_axis.urdf");
    std::fs::write(&path, &no_axis).unwrap();
    let r = RobotDescription::from_file(&path, &opts).unwrap_or_else(|e| panic!("{e}"));
    let left = &r.joints[r.wheels.left[0].joint];
    assert!(
        (left.axis.into_inner() - nalgebra::Vector3::y()).norm() < 1e-7,
        "{:?}",
        left.axis
    );
    assert!(
        r.warnings
            .iter()
            .any(|w| w.contains("(the axis of link `left_hub`'s <cylinder> collision)")),
        "{:#?}",
        r.warnings
    );
    // Neither an <axis> nor a cylinder: refused, naming the joint and its line.
    let neither = no_axis.replacen(
        r#"<cylinder length="0.02" radius="0.0925"/>"#,
        r#"<box size="0.185 0.02 0.185"/>"#,
        1,
    );
    let path = dir.join("neither.urdf");
    std::fs::write(&path, &neither).unwrap();
    let e = RobotDescription::from_file(&path, &opts).unwrap_err();
    let line = line_of(&neither, r#"<joint name="left_hub_joint""#);
    assert!(matches!(e, RobotError::InvalidValue { .. }), "{e:?}");
    let msg = e.to_string();
    assert!(
        msg.contains(&format!("joint `left_hub_joint` (line {line}) is `fixed`"))
            && msg.contains("needs an <axis xyz> or a <cylinder> collision on link `left_hub`"),
        "{msg}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn pioneer_file_edits_ros_refuses_are_refused_with_element_and_line() {
    let text = std::fs::read_to_string(file("pioneer_fixed_wheels.urdf")).unwrap();
    let dir = scratch("fixed-refused");
    let opts = pioneer_opts(Some(("left_hub_joint", "right_hub_joint")));
    let cases: [(&str, &str, &str, &str); 4] = [
        // (edit from, edit to, marker of the reported line, words of the message)
        (
            r#"<limit effort="50" k_velocity="0" velocity="50"/>"#,
            r#"<limit effort="50" k_velocity="0"/>"#,
            r#"<limit effort="50" k_velocity="0"/>"#,
            "<limit> of <joint> `base_swivel_joint` has no `velocity`",
        ),
        (
            r#"<mass value="4.0"/>"#,
            r#"<mass value="4.0 kg"/>"#,
            r#"<mass value="4.0 kg"/>"#,
            "`value=\"4.0 kg\"` is not a finite number",
        ),
        (
            r#"<cylinder length="0.02" radius="0.0925"/>"#,
            r#"<cylinder length="0.02"/>"#,
            r#"<cylinder length="0.02"/>"#,
            "<cylinder> in <geometry> of <collision> of <link> `left_hub` has no `radius`",
        ),
        (
            r#"<joint name="left_wheel_joint" type="fixed">"#,
            r#"<joint name="left_wheel_joint" type="rigid">"#,
            r#"type="rigid""#,
            "<joint> `left_wheel_joint` has type `rigid`",
        ),
    ];
    for (k, case) in cases.iter().enumerate() {
        refused_at_line(&dir, k, &text, *case, &opts);
    }
    // A tyre joint naming a hub that does not exist: the joint and its line.
    let edited = text.replacen(
        r#"<parent link="left_hub"/>"#,
        r#"<parent link="left_hubb"/>"#,
        1,
    );
    let path = dir.join("missing_parent.urdf");
    std::fs::write(&path, &edited).unwrap();
    let msg = RobotDescription::from_file(&path, &opts)
        .unwrap_err()
        .to_string();
    let line = line_of(&edited, r#"<joint name="left_wheel_joint""#);
    assert!(
        msg.contains(&format!(
            "joint `left_wheel_joint` (line {line}) names parent link `left_hubb`, which does not exist"
        )),
        "{msg}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn qbot2e_file_finds_its_package_under_another_folder_name_when_mapped() {
    let path = file("qbot2e_style.urdf");
    let limits = ftcbf_sim::robot::DriveLimits {
        v_max: 0.3,
        omega_max: 2.0,
        wheel_speed_max: 8.5,
    };
    // `package://ftcbf_qbot2e/` with only the search path: no folder of that name; the error
    // says where it looked and how to map the package.
    let o = LoadOptions {
        limits: Some(limits),
        ..opts()
    };
    let e = RobotDescription::from_file(&path, &o).unwrap_err();
    assert!(matches!(e, RobotError::CollisionMesh { .. }), "{e:?}");
    let msg = e.to_string();
    assert!(
        msg.contains("no package `ftcbf_qbot2e` in the package search path")
            && msg.contains(r#"[robot] packages = { ftcbf_qbot2e = "path/to/folder" }"#),
        "{msg}"
    );
    // Mapped to the folder that holds it (named ftcbf_coverage_description).
    let folder = src().join("ftcbf_coverage_description");
    let mapped = LoadOptions {
        packages: [("ftcbf_qbot2e".to_string(), folder.clone())].into(),
        limits: Some(limits),
        ..LoadOptions::default()
    };
    let r = RobotDescription::from_file(&path, &mapped).unwrap_or_else(|e| panic!("{e}"));
    assert!(r.warnings.is_empty(), "{:?}", r.warnings);
    // Binary STL wheels, 35 mm radius, 20 mm wide, lying on +y of their frames; the right one
    // is turned by yaw 3.14 (not pi) and still counts as lateral.
    let g = r.wheels.geometry;
    assert!(
        (g.radius - 0.035).abs() < 1e-6 && (g.separation - 0.22).abs() < 1e-12,
        "{g:?}"
    );
    assert_eq!(r.wheels.left[0].joint_name, "base_wheel_l_joint");
    assert_eq!(r.wheels.right[0].joint_name, "base_wheel_r_joint");
    assert_eq!(
        (
            r.wheels.left[0].forward_sign,
            r.wheels.right[0].forward_sign
        ),
        (1.0, -1.0)
    );
    for (joint, y) in [("base_wheel_l_joint", 0.12), ("base_wheel_r_joint", -0.12)] {
        let (radius, half) = wheel_cylinder(&r, joint);
        assert!(
            (radius - 0.035).abs() < 1e-6 && (half - 0.01).abs() < 1e-6,
            "{joint}"
        );
        // The rolling cylinder sits in the middle of the mesh's extent along the axle.
        let w = r.wheels.all().find(|w| w.joint_name == joint).unwrap();
        let b = &r.bodies[w.body];
        let c = b.colliders.iter().find(|c| c.is_wheel).unwrap();
        let centre = (b.pose_in_root * c.pose_in_body).translation.vector;
        assert!(
            (centre.y - y).abs() < 1e-4 && centre.z > 0.0349,
            "{joint}: {centre:?}"
        );
    }
    // The Collada base is in centimetres and moved up by its node's <translate>: it spans
    // 1 mm to 119 mm above the base frame, radius 174 mm.
    let base = &r.bodies[0];
    let (mut z_lo, mut z_hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for c in base.colliders.iter().filter(|c| c.link == "base") {
        let CollisionShape::Mesh { vertices, .. } = &c.shape else {
            panic!("{:?}", c.shape)
        };
        for v in vertices {
            z_lo = z_lo.min(v[2]);
            z_hi = z_hi.max(v[2]);
        }
    }
    assert!(
        (z_lo - 0.001).abs() < 1e-6 && (z_hi - 0.119).abs() < 1e-6,
        "{z_lo} {z_hi}"
    );
    assert!(
        (r.footprint_radius - 0.174).abs() < 1e-6,
        "{}",
        r.footprint_radius
    );
    // The sensor hangs on a revolute joint whose limits are all zero.
    let sensor = r
        .joints
        .iter()
        .find(|j| j.name == "base_sensor_joint")
        .unwrap();
    assert_eq!(
        sensor.kind,
        ftcbf_sim::robot::JointKind::Revolute {
            lower: 0.0,
            upper: 0.0
        }
    );
    // A mapped folder without the file: the error names the folder.
    let elsewhere = LoadOptions {
        packages: [("ftcbf_qbot2e".to_string(), src())].into(),
        ..mapped
    };
    let msg = RobotDescription::from_file(&path, &elsewhere)
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("file not found in package `ftcbf_qbot2e`'s folder")
            && msg.contains("[robot] packages"),
        "{msg}"
    );
}
