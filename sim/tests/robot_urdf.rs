//! URDF loading: the shipped robots, a ROS-style TurtleBot3 file, meshes, and bad files.

use std::path::{Path, PathBuf};

use ftcbf_sim::robot::{CollisionShape, DriveLimits, LoadOptions, RobotDescription, RobotError};

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn fixtures() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/urdf")
}

/// A fresh scratch directory for this test.
fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("ftcbf-robot-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A binary STL cube of edge `edge` centred on the origin, whose 80-byte header starts with
/// "solid" (as some real exporters write it).
fn write_binary_stl_cube(path: &Path, edge: f32) {
    let h = edge / 2.0;
    let v = |i: u8| -> [f32; 3] {
        [
            if i & 1 != 0 { h } else { -h },
            if i & 2 != 0 { h } else { -h },
            if i & 4 != 0 { h } else { -h },
        ]
    };
    let quads: [[u8; 4]; 6] = [
        [0, 2, 3, 1],
        [4, 5, 7, 6],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 4, 6, 2],
        [1, 3, 7, 5],
    ];
    let mut tris = Vec::new();
    for q in quads {
        tris.push([v(q[0]), v(q[1]), v(q[2])]);
        tris.push([v(q[0]), v(q[2]), v(q[3])]);
    }
    let mut bytes = Vec::new();
    let mut header = b"solid exported by a CAD tool that writes binary STL".to_vec();
    header.resize(80, b' ');
    bytes.extend_from_slice(&header);
    bytes.extend_from_slice(&(tris.len() as u32).to_le_bytes());
    for t in tris {
        bytes.extend_from_slice(&[0u8; 12]); // normal (unused)
        for p in t {
            for c in p {
                bytes.extend_from_slice(&c.to_le_bytes());
            }
        }
        bytes.extend_from_slice(&[0u8; 2]);
    }
    std::fs::write(path, bytes).unwrap();
}

#[test]
fn burger_geometry_limits_and_mass_come_from_its_urdf() {
    let r = RobotDescription::from_file(
        repo().join("robots/turtlebot3_burger.urdf"),
        &LoadOptions::default(),
    )
    .unwrap();
    let g = r.wheels.geometry;
    assert!((g.radius - 0.033).abs() < 1e-12, "radius {}", g.radius);
    assert!(
        (g.separation - 0.160).abs() < 1e-12,
        "separation {}",
        g.separation
    );
    assert_eq!(r.wheels.left[0].joint_name, "wheel_left_joint");
    assert_eq!(r.wheels.right[0].joint_name, "wheel_right_joint");
    assert_eq!(r.wheels.left[0].forward_sign, 1.0);
    assert!((r.limits.v_max - 0.22).abs() < 1e-9);
    assert!((r.limits.omega_max - 2.75).abs() < 1e-9);
    assert!(
        (r.total_mass() - 1.002).abs() < 1e-9,
        "mass {}",
        r.total_mass()
    );
    // base_footprint + base_link + caster + lidar merged into one body; two wheels.
    assert_eq!(r.bodies.len(), 3);
    assert_eq!(
        r.bodies[0].links,
        [
            "base_footprint",
            "base_link",
            "caster_back_link",
            "base_scan"
        ]
    );
    assert_eq!(r.body_of_link("base_scan"), Some(0));
    // Footprint: base box corner (−0.102, ±0.070) is the farthest point in the plane.
    assert!(
        (r.footprint_radius - 0.102f64.hypot(0.070)).abs() < 1e-9,
        "{}",
        r.footprint_radius
    );
    // Lidar top at 0.010 + 0.172 − 0.0065 + 0.01575 = 0.19125 m; ground at 0.
    assert!(
        (r.centre_height - 0.19125 / 2.0).abs() < 1e-9,
        "{}",
        r.centre_height
    );
    // Wheel joint frame: −π/2 roll puts the cylinder axis along +y.
    let w = &r.bodies[r.wheels.left[0].body];
    assert!(
        (w.pose_in_root.translation.vector - nalgebra::Vector3::new(0.0, 0.08, 0.033)).norm()
            < 1e-12
    );
    assert!(r.warnings.is_empty());
}

#[test]
fn waffle_geometry_comes_from_its_urdf() {
    let r = RobotDescription::from_file(
        repo().join("robots/turtlebot3_waffle.urdf"),
        &LoadOptions::default(),
    )
    .unwrap();
    let g = r.wheels.geometry;
    assert!((g.radius - 0.033).abs() < 1e-12);
    assert!(
        (g.separation - 0.288).abs() < 1e-12,
        "separation {}",
        g.separation
    );
    assert!((r.limits.v_max - 0.26).abs() < 1e-9);
    assert!((r.limits.omega_max - 2.0 * 0.26 / 0.288).abs() < 1e-9);
    assert!((r.total_mass() - (1.3729096 + 2.0 * 0.0285 + 2.0 * 0.005 + 0.114)).abs() < 1e-9);
    assert!(
        (r.footprint_radius - 0.197f64.hypot(0.133)).abs() < 1e-9,
        "{}",
        r.footprint_radius
    );
}

#[test]
fn ros_style_file_loads_with_massless_frames_merged_and_meshes_resolved() {
    let path = fixtures().join("turtlebot3_burger_ros.urdf");
    // The file's wheel joints carry no velocity limits: explicit ones here (without them the
    // maker's published burger limits apply, see
    // `turtlebot3_files_without_wheel_limits_get_the_makers_published_limits`).
    let limits = DriveLimits {
        v_max: 0.22,
        omega_max: 2.84,
        wheel_speed_max: 0.22 / 0.033,
    };
    let opts = LoadOptions {
        limits: Some(limits),
        ..LoadOptions::default()
    };
    let r = RobotDescription::from_file(&path, &opts).unwrap();
    assert_eq!(r.bodies.len(), 3);
    assert_eq!(
        r.bodies[0].links,
        [
            "base_footprint",
            "base_link",
            "caster_back_link",
            "imu_link",
            "base_scan"
        ]
    );
    assert!((r.wheels.geometry.radius - 0.033).abs() < 1e-12);
    assert!((r.wheels.geometry.separation - 0.160).abs() < 1e-12);
    assert_eq!(r.limits, limits);
    // -1.57 instead of −π/2: the axis is still recognised as lateral.
    assert_eq!(r.wheels.left[0].forward_sign, 1.0);
    // Four visual meshes, none found: warnings, not errors.
    assert_eq!(r.warnings.len(), 4, "{:?}", r.warnings);
    assert!(r.warnings[0].contains("package://turtlebot3_description/meshes/bases/burger_base.stl"));
    assert!(r.warnings[0].contains("base_link"));
    // The caster's large inertia (0.001 kg·m² at 5 g) is merged into the base.
    let mass = r.total_mass();
    assert!(
        (mass - (0.82573504 + 2.0 * 0.02849894 + 0.005 + 0.114)).abs() < 1e-9,
        "{mass}"
    );

    // With a package path that holds two of the meshes, those warnings go away.
    let pkgs = scratch("pkgs");
    let meshes = pkgs.join("turtlebot3_description/meshes");
    std::fs::create_dir_all(meshes.join("bases")).unwrap();
    std::fs::create_dir_all(meshes.join("wheels")).unwrap();
    write_binary_stl_cube(&meshes.join("bases/burger_base.stl"), 100.0);
    write_binary_stl_cube(&meshes.join("wheels/left_tire.stl"), 66.0);
    let opts = LoadOptions {
        package_paths: vec![pkgs.clone()],
        limits: Some(limits),
        ..LoadOptions::default()
    };
    let r = RobotDescription::from_file(&path, &opts).unwrap();
    assert_eq!(r.warnings.len(), 2, "{:?}", r.warnings);
    assert!(r
        .warnings
        .iter()
        .all(|w| !w.contains("burger_base") && !w.contains("left_tire")));
    // The package directory itself also works as a search-path entry.
    let opts = LoadOptions {
        package_paths: vec![pkgs.join("turtlebot3_description")],
        limits: Some(limits),
        ..LoadOptions::default()
    };
    assert_eq!(
        RobotDescription::from_file(&path, &opts)
            .unwrap()
            .warnings
            .len(),
        2
    );
    let _ = std::fs::remove_dir_all(&pkgs);
}

const WHEELS: &str = r#"
  <joint name="wl" type="continuous">
    <parent link="base"/><child link="wheel_l"/>
    <origin xyz="0 0.1 0.05" rpy="-1.5707963267948966 0 0"/><axis xyz="0 0 1"/>
    <limit velocity="5" effort="1"/>
  </joint>
  <link name="wheel_l">
    <inertial><mass value="0.05"/><inertia ixx="1e-5" ixy="0" ixz="0" iyy="1e-5" iyz="0" izz="2e-5"/></inertial>
    <collision><geometry><cylinder radius="0.05" length="0.02"/></geometry></collision>
  </link>
  <joint name="wr" type="continuous">
    <parent link="base"/><child link="wheel_r"/>
    <origin xyz="0 -0.1 0.05" rpy="-1.5707963267948966 0 0"/><axis xyz="0 0 1"/>
    <limit velocity="5" effort="1"/>
  </joint>
  <link name="wheel_r">
    <inertial><mass value="0.05"/><inertia ixx="1e-5" ixy="0" ixz="0" iyy="1e-5" iyz="0" izz="2e-5"/></inertial>
    <collision><geometry><cylinder radius="0.05" length="0.02"/></geometry></collision>
  </link>
"#;

fn base(collision: &str) -> String {
    format!(
        r#"<link name="base">
    <inertial><mass value="1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>
    <collision><origin xyz="0 0 0.1"/><geometry>{collision}</geometry></collision>
  </link>"#
    )
}

fn robot(body: &str) -> String {
    format!("<?xml version=\"1.0\"?>\n<robot name=\"t\">\n{body}\n</robot>\n")
}

#[test]
fn collision_mesh_via_package_path_honours_scale_and_binary_solid_header() {
    let dir = scratch("mesh");
    std::fs::create_dir_all(dir.join("mypkg/meshes")).unwrap();
    write_binary_stl_cube(&dir.join("mypkg/meshes/body.stl"), 100.0); // mm
    let text = robot(&format!(
        "{}{WHEELS}",
        base(r#"<mesh filename="package://mypkg/meshes/body.stl" scale="0.001 0.002 0.001"/>"#)
    ));
    let opts = LoadOptions {
        package_paths: vec![dir.clone()],
        ..LoadOptions::default()
    };
    let r = RobotDescription::from_urdf_str(&text, &opts).unwrap();
    let c = r.bodies[0]
        .colliders
        .iter()
        .find(|c| c.link == "base")
        .unwrap();
    let CollisionShape::Mesh { vertices, indices } = &c.shape else {
        panic!("expected a mesh, got {:?}", c.shape)
    };
    assert_eq!(indices.len(), 12);
    let max = |k: usize| vertices.iter().map(|v| v[k]).fold(f64::MIN, f64::max);
    assert!(
        (max(0) - 0.05).abs() < 1e-6
            && (max(1) - 0.10).abs() < 1e-6
            && (max(2) - 0.05).abs() < 1e-6
    );
    // The derived limits: v = r·w = 0.25, ω = 2·0.25/0.2.
    assert!((r.limits.v_max - 0.25).abs() < 1e-12 && (r.limits.omega_max - 2.5).abs() < 1e-12);
    // And it builds into a physics world (mesh collides as its convex hull).
    let w = ftcbf_sim::physics::PhysicsWorld::new(&r, Default::default(), &[], &Default::default());
    assert!(w.is_ok());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn missing_collision_mesh_is_an_error_naming_link_and_file() {
    let text = robot(&format!(
        "{}{WHEELS}",
        base(r#"<mesh filename="package://nopkg/meshes/gone.stl"/>"#)
    ));
    let e = RobotDescription::from_urdf_str(&text, &LoadOptions::default()).unwrap_err();
    assert!(matches!(e, RobotError::CollisionMesh { .. }), "{e:?}");
    let msg = e.to_string();
    assert!(
        msg.contains("package://nopkg/meshes/gone.stl")
            && msg.contains("`base`")
            && msg.contains("not found"),
        "{msg}"
    );
}

#[test]
fn robot_without_wheels_is_an_error() {
    let text = robot(&base(r#"<box size="0.2 0.2 0.1"/>"#));
    let e = RobotDescription::from_urdf_str(&text, &LoadOptions::default()).unwrap_err();
    assert!(matches!(e, RobotError::Wheels { .. }), "{e:?}");
    let msg = e.to_string();
    assert!(
        msg.contains("cannot find the drive wheels") && msg.contains("found 0"),
        "{msg}"
    );
    // Naming joints that do not exist.
    let text = robot(&format!("{}{WHEELS}", base(r#"<box size="0.2 0.2 0.1"/>"#)));
    let opts = LoadOptions {
        wheel_joints: Some(("left".into(), "wr".into())),
        ..LoadOptions::default()
    };
    let msg = RobotDescription::from_urdf_str(&text, &opts)
        .unwrap_err()
        .to_string();
    assert!(msg.contains("no joint named `left`"), "{msg}");
    // Naming them explicitly works.
    let opts = LoadOptions {
        wheel_joints: Some(("wl".into(), "wr".into())),
        ..LoadOptions::default()
    };
    let r = RobotDescription::from_urdf_str(&text, &opts).unwrap();
    assert!(
        (r.wheels.geometry.separation - 0.2).abs() < 1e-12
            && (r.wheels.geometry.radius - 0.05).abs() < 1e-12
    );
}

#[test]
fn massless_moving_link_is_an_error() {
    let wheels = WHEELS.replacen(
        r#"<inertial><mass value="0.05"/><inertia ixx="1e-5" ixy="0" ixz="0" iyy="1e-5" iyz="0" izz="2e-5"/></inertial>"#,
        "",
        1,
    );
    let text = robot(&format!("{}{wheels}", base(r#"<box size="0.2 0.2 0.1"/>"#)));
    let e = RobotDescription::from_urdf_str(&text, &LoadOptions::default()).unwrap_err();
    assert!(matches!(e, RobotError::NonPositiveMass { .. }), "{e:?}");
    let msg = e.to_string();
    assert!(
        msg.contains("`wheel_l`") && msg.contains("joint `wl`") && msg.contains("mass is 0"),
        "{msg}"
    );
    // Negative mass is rejected too.
    let wheels = WHEELS.replacen(r#"<mass value="0.05"/>"#, r#"<mass value="-0.05"/>"#, 1);
    let text = robot(&format!("{}{wheels}", base(r#"<box size="0.2 0.2 0.1"/>"#)));
    let msg = RobotDescription::from_urdf_str(&text, &LoadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(msg.contains("`wheel_l`") && msg.contains("mass"), "{msg}");
}

#[test]
fn xacro_leftovers_are_rejected_with_line_link_and_attribute() {
    let text = robot(&format!(
        "{}{WHEELS}",
        base(r#"<box size="0.2 0.2 0.1"/>"#)
            .replace(r#"<link name="base">"#, r#"<link name="${prefix}base">"#)
    ));
    let e = RobotDescription::from_urdf_str(&text, &LoadOptions::default()).unwrap_err();
    let msg = e.to_string();
    assert!(matches!(e, RobotError::Xacro { line: 3, .. }), "{e:?}");
    assert!(
        msg.contains("${prefix}") && msg.contains("attribute `name`") && msg.contains("run `xacro"),
        "{msg}"
    );

    let text = robot(&format!(
        "{}{WHEELS}",
        base(r#"<box size="0.2 0.2 0.1"/>"#).replace(
            r#"<origin xyz="0 0 0.1"/>"#,
            r#"<origin xyz="0 0 ${h/2}"/>"#
        )
    ));
    let msg = RobotDescription::from_urdf_str(&text, &LoadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("link `base`") && msg.contains("attribute `xyz`") && msg.contains("${h/2}"),
        "{msg}"
    );

    let text = robot(&format!(
        "<xacro:include filename=\"common.xacro\"/>\n{}{WHEELS}",
        base(r#"<box size="0.2 0.2 0.1"/>"#)
    ));
    let msg = RobotDescription::from_urdf_str(&text, &LoadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("<xacro:include") && msg.contains("line 3"),
        "{msg}"
    );
}

#[test]
fn malformed_xml_is_a_parse_error() {
    for text in [
        "<robot name=\"t\"><link name=\"base\"></robot>",
        "not xml at all",
        "<robot name=\"t\"><link name=\"b\"><collision><geometry><box size=\"a b c\"/></geometry></collision></link></robot>",
    ] {
        let e = RobotDescription::from_urdf_str(text, &LoadOptions::default()).unwrap_err();
        assert!(matches!(e, RobotError::Parse { .. }), "{text}: {e:?}");
        assert!(e.to_string().contains("malformed URDF"), "{e}");
    }
    let e = RobotDescription::from_file("/nonexistent/robot.urdf", &LoadOptions::default())
        .unwrap_err();
    assert!(e.to_string().contains("/nonexistent/robot.urdf"), "{e}");
}

#[test]
fn invalid_geometry_and_structure_are_typed_errors() {
    let text = robot(&format!(
        "{}{WHEELS}",
        base(r#"<box size="0.2 -0.2 0.1"/>"#)
    ));
    let msg = RobotDescription::from_urdf_str(&text, &LoadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("link `base`") && msg.contains("<box size>"),
        "{msg}"
    );
    // Two roots.
    let text = robot(&format!(
        "{}{WHEELS}<link name=\"stray\"/>",
        base(r#"<box size="0.2 0.2 0.1"/>"#)
    ));
    let msg = RobotDescription::from_urdf_str(&text, &LoadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("single root") && msg.contains("stray"),
        "{msg}"
    );
}

#[test]
fn xacro_namespace_declaration_alone_is_accepted() {
    // xacro keeps `xmlns:xacro` on <robot> in the URDF it writes; that file is plain URDF.
    let text = robot(&format!("{}{WHEELS}", base(r#"<box size="0.2 0.2 0.1"/>"#))).replace(
        "<robot name=\"t\">",
        "<robot name=\"t\" xmlns:xacro=\"http://www.ros.org/wiki/xacro\">",
    );
    assert!(text.contains("xmlns:xacro"));
    let r = RobotDescription::from_urdf_str(&text, &LoadOptions::default()).unwrap();
    assert_eq!(r.name, "t");
}

#[test]
fn xacro_text_in_comments_and_processing_instructions_is_not_a_leftover() {
    // As ROS packages ship them: a commented include with `$(find …)` and a multi-line commented
    // block of `<xacro:property>` lines; a processing instruction mentioning `${…}`.
    let header = r#"<!-- <xacro:include filename="$(find my_description)/urdf/common.xacro"/> -->
  <!--
    <xacro:property name="wheel_radius" value="0.05"/>
    <xacro:property name="track" value="${2 * 0.1}"/>
  -->
  <?editor note="${not markup}"?>
"#;
    let text = robot(&format!(
        "{header}{}{WHEELS}",
        base(r#"<box size="0.2 0.2 0.1"/>"#)
    ));
    let r = RobotDescription::from_urdf_str(&text, &LoadOptions::default())
        .unwrap_or_else(|e| panic!("comments must not count as xacro: {e}"));
    assert_eq!(r.name, "t");

    // A real leftover after those comments is still found, on its own line (line 9: two header
    // lines, six comment/PI lines, then `<link name="${namespace}base">`).
    let text = robot(&format!(
        "{header}{}{WHEELS}",
        base(r#"<box size="0.2 0.2 0.1"/>"#)
            .replace(r#"<link name="base">"#, r#"<link name="${namespace}base">"#)
    ));
    let e = RobotDescription::from_urdf_str(&text, &LoadOptions::default()).unwrap_err();
    assert!(matches!(e, RobotError::Xacro { line: 9, .. }), "{e:?}");
    let msg = e.to_string();
    assert!(
        msg.contains("${namespace}") && msg.contains("attribute `name`"),
        "{msg}"
    );
}

fn ros_ws_src() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/ros_ws/src")
}

fn skid_urdf() -> PathBuf {
    ros_ws_src().join("ftcbf_skid_description/urdf/skid4.urdf")
}

fn skid_opts() -> LoadOptions {
    LoadOptions {
        package_paths: vec![ros_ws_src()],
        ..LoadOptions::default()
    }
}

/// The skid-steer fixture's text with `edit` applied, loaded with the workspace search path
/// (the file keeps its directory, so relative paths still resolve).
fn load_skid_edited(edit: impl Fn(&str) -> String) -> Result<RobotDescription, RobotError> {
    load_skid_edited_with(edit, &skid_opts())
}

fn load_skid_edited_with(
    edit: impl Fn(&str) -> String,
    opts: &LoadOptions,
) -> Result<RobotDescription, RobotError> {
    let text = std::fs::read_to_string(skid_urdf()).unwrap();
    let edited = edit(&text);
    assert_ne!(edited, text, "the edit must change the file");
    static EDITS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let n = EDITS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let dir = scratch(&format!("skid-edit-{n}"));
    let path = dir.join("skid4.urdf");
    std::fs::write(&path, edited).unwrap();
    let r = RobotDescription::from_file(&path, opts);
    let _ = std::fs::remove_dir_all(&dir);
    r
}

#[test]
fn skid_steer_ros_package_loads_grouped_by_side_with_a_collada_chassis() {
    let r = RobotDescription::from_file(skid_urdf(), &skid_opts())
        .unwrap_or_else(|e| panic!("the ROS-style skid-steer package must load: {e}"));
    assert_eq!(r.name, "ftcbf_skid4");
    let names = |ws: &[ftcbf_sim::robot::Wheel]| {
        ws.iter().map(|w| w.joint_name.clone()).collect::<Vec<_>>()
    };
    assert!(r.wheels.is_skid_steer());
    assert_eq!(
        names(&r.wheels.left),
        ["front_left_wheel_joint", "rear_left_wheel_joint"]
    );
    assert_eq!(
        names(&r.wheels.right),
        ["front_right_wheel_joint", "rear_right_wheel_joint"]
    );
    // Axis +y on every wheel: positive rotation rolls forward.
    assert!(r.wheels.all().all(|w| w.forward_sign == 1.0));
    assert!(r.wheels.all().all(|w| w.effort_limit == Some(3.0)));
    let g = r.wheels.geometry;
    assert!((g.radius - 0.05).abs() < 1e-12, "{g:?}");
    assert!((g.separation - 0.26).abs() < 1e-12, "{g:?}");
    // Limits from `<limit velocity="8">`: v = 0.05·8, ω = 2·0.4/0.26.
    assert!((r.limits.v_max - 0.4).abs() < 1e-12);
    assert!((r.limits.omega_max - 0.8 / 0.26).abs() < 1e-12);
    // Every wheel grips the ground; the chassis does not.
    for w in r.wheels.all() {
        assert!(r.bodies[w.body].colliders.iter().all(|c| c.is_wheel));
    }
    assert!(r.bodies[0].colliders.iter().all(|c| !c.is_wheel));

    // The Collada chassis: millimetres scaled by <unit meter="0.001">,
    // eight corners welded from the triangles' corners, twelve triangles.
    let chassis = r.bodies[0]
        .colliders
        .iter()
        .find(|c| c.link == "base_link")
        .expect("chassis collider");
    let CollisionShape::Mesh { vertices, indices } = &chassis.shape else {
        panic!("expected a mesh, got {:?}", chassis.shape)
    };
    assert_eq!((vertices.len(), indices.len()), (8, 12));
    let range = |k: usize| {
        vertices
            .iter()
            .map(|v| v[k])
            .fold((f64::MAX, f64::MIN), |(lo, hi), x| (lo.min(x), hi.max(x)))
    };
    for (k, (lo, hi)) in [(0, (-0.15, 0.15)), (1, (-0.10, 0.10)), (2, (-0.02, 0.08))] {
        let (a, b) = range(k);
        assert!(
            (a - lo).abs() < 1e-6 && (b - hi).abs() < 1e-6,
            "axis {k}: [{a}, {b}], expected [{lo}, {hi}]"
        );
    }
    // base_link sits 5 cm above base_footprint (the root frame).
    assert!((chassis.pose_in_body.translation.z - 0.05).abs() < 1e-12);

    // The visual STL is not installed: a warning naming the file, not an error.
    assert_eq!(r.warnings.len(), 1, "{:?}", r.warnings);
    assert!(
        r.warnings[0].contains("package://ftcbf_skid_description/meshes/chassis.stl")
            && r.warnings[0].contains("not found"),
        "{:?}",
        r.warnings
    );
    let text = r.wheels.describe();
    assert!(
        text.starts_with("skid steer, 4 wheels")
            && text.contains("left [`front_left_wheel_joint`, `rear_left_wheel_joint`]")
            && text.contains("effective track width 0.2600 m"),
        "{text}"
    );
    // And it builds into a physics world.
    let w = ftcbf_sim::physics::PhysicsWorld::new(&r, Default::default(), &[], &Default::default());
    assert!(w.is_ok());
}

#[test]
fn missing_collada_collision_mesh_names_the_file_and_the_search_path() {
    let elsewhere = std::env::temp_dir().join("ftcbf-no-such-workspace/src");
    let opts = LoadOptions {
        package_paths: vec![elsewhere.clone()],
        ..LoadOptions::default()
    };
    let e = RobotDescription::from_file(skid_urdf(), &opts).unwrap_err();
    assert!(matches!(e, RobotError::CollisionMesh { .. }), "{e:?}");
    let msg = e.to_string();
    assert!(
        msg.contains("package://ftcbf_skid_description/meshes/chassis_collision.dae")
            && msg.contains("`base_link`")
            && msg.contains("not found")
            && msg.contains(&elsewhere.display().to_string()),
        "{msg}"
    );
}

#[test]
fn odd_or_ambiguous_wheel_layouts_are_errors_naming_the_joints() {
    // Three wheels: the rear right one becomes a fixed (non-wheel) joint.
    let e = load_skid_edited(|t| {
        t.replace(
            r#"<joint name="rear_right_wheel_joint" type="continuous">"#,
            r#"<joint name="rear_right_wheel_joint" type="fixed">"#,
        )
    })
    .unwrap_err();
    assert!(matches!(e, RobotError::Wheels { .. }), "{e:?}");
    let msg = e.to_string();
    assert!(
        msg.contains("odd wheel layout")
            && msg.contains("2 wheel(s) on the left")
            && msg.contains("`front_left_wheel_joint`")
            && msg.contains("`rear_left_wheel_joint`")
            && msg.contains("1 on the right [`front_right_wheel_joint`"),
        "{msg}"
    );
    // A wheel on the centre line belongs to neither side.
    let msg = load_skid_edited(|t| {
        t.replace(
            r#"<origin xyz="-0.10 -0.13 0""#,
            r#"<origin xyz="-0.10 0 0""#,
        )
    })
    .unwrap_err()
    .to_string();
    assert!(
        msg.contains("ambiguous wheel layout")
            && msg.contains("`rear_right_wheel_joint` (y = +0.0000 m)"),
        "{msg}"
    );
    // Mixed radii are refused, naming two of the joints.
    let msg = load_skid_edited(|t| {
        t.replacen(
            r#"<collision>
      <origin xyz="0 0 0" rpy="1.570796 0 0"/>
      <geometry><cylinder radius="0.05" length="0.04"/></geometry>"#,
            r#"<collision>
      <origin xyz="0 0 0" rpy="1.570796 0 0"/>
      <geometry><cylinder radius="0.06" length="0.04"/></geometry>"#,
            1,
        )
    })
    .unwrap_err()
    .to_string();
    assert!(
        msg.contains("different radii") && msg.contains("`front_left_wheel_joint` 0.06 m"),
        "{msg}"
    );
    // Naming two of the four wheels makes a differential drive of them.
    let opts = LoadOptions {
        wheel_joints: Some((
            "front_left_wheel_joint".into(),
            "front_right_wheel_joint".into(),
        )),
        ..skid_opts()
    };
    let r = RobotDescription::from_file(skid_urdf(), &opts).unwrap();
    assert!(!r.wheels.is_skid_steer());
    assert!((r.wheels.geometry.separation - 0.26).abs() < 1e-12);
    assert!(r
        .wheels
        .describe()
        .starts_with("differential, left `front_left_wheel_joint`"));
}

#[test]
fn real_xacro_leftovers_in_a_ros_file_are_still_refused_with_line_and_attribute() {
    // With xacro expansion off (a file with markup is otherwise run through xacro, see
    // sim/tests/robot_xacro.rs), markup outside comments is refused with its line.
    let no_xacro = LoadOptions {
        xacro: ftcbf_sim::robot::XacroOptions {
            command: ftcbf_sim::robot::XacroCommand::Disabled,
            ..Default::default()
        },
        ..skid_opts()
    };
    // `${namespace}base_link` outside any comment, on the line of `<link name="base_link">`.
    let text = std::fs::read_to_string(skid_urdf()).unwrap();
    let line = text
        .lines()
        .position(|l| l.contains(r#"<link name="base_link">"#))
        .unwrap()
        + 1;
    let e = load_skid_edited_with(
        |t| {
            t.replace(
                r#"<link name="base_link">"#,
                r#"<link name="${namespace}base_link">"#,
            )
        },
        &no_xacro,
    )
    .unwrap_err();
    assert!(
        matches!(&e, RobotError::Xacro { line: l, .. } if *l == line),
        "{e:?} (expected line {line})"
    );
    let msg = e.to_string();
    assert!(
        msg.contains("${namespace}") && msg.contains("attribute `name`") && msg.contains("xacro"),
        "{msg}"
    );
    // `<xacro:arg>` as an element, not inside the comment block.
    let e = load_skid_edited_with(
        |t| {
            t.replace(
                "  <material name=\"dark_grey\">",
                "  <xacro:arg name=\"namespace\" default=\"\"/>\n  <material name=\"dark_grey\">",
            )
        },
        &no_xacro,
    )
    .unwrap_err();
    let arg_line = text
        .lines()
        .position(|l| l.contains("<material name=\"dark_grey\">"))
        .unwrap()
        + 1;
    assert!(
        matches!(&e, RobotError::Xacro { line: l, snippet, .. } if *l == arg_line && snippet.starts_with("<xacro:arg")),
        "{e:?}"
    );
}

#[test]
fn stl_ascii_obj_and_collada_meshes_read_through_one_loader() {
    let dir = scratch("formats");
    let ascii = "solid tetra\n\
        facet normal 0 0 -1\n outer loop\n  vertex 0 0 0\n  vertex 0 1 0\n  vertex 1 0 0\n endloop\nendfacet\n\
        facet normal 0 -1 0\n outer loop\n  vertex 0 0 0\n  vertex 1 0 0\n  vertex 0 0 1\n endloop\nendfacet\n\
        facet normal -1 0 0\n outer loop\n  vertex 0 0 0\n  vertex 0 0 1\n  vertex 0 1 0\n endloop\nendfacet\n\
        facet normal 1 1 1\n outer loop\n  vertex 1 0 0\n  vertex 0 1 0\n  vertex 0 0 1\n endloop\nendfacet\n\
        endsolid tetra\n";
    std::fs::write(dir.join("tetra.stl"), ascii).unwrap();
    let obj = "# a unit tetrahedron\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";
    std::fs::write(dir.join("tetra.obj"), obj).unwrap();
    for name in ["tetra.stl", "tetra.obj"] {
        let (v, i) = ftcbf_sim::robot::read_mesh(&dir.join(name)).unwrap();
        assert_eq!((v.len(), i.len()), (4, 4), "{name}");
        let max: f64 = v.iter().flatten().copied().fold(f64::MIN, f64::max);
        assert!((max - 1.0).abs() < 1e-12, "{name}");
    }
    let dae = ros_ws_src().join("ftcbf_skid_description/meshes/chassis_collision.dae");
    let (v, i) = ftcbf_sim::robot::read_mesh(&dae).unwrap();
    assert_eq!((v.len(), i.len()), (8, 12));
    // Not a mesh at all: a clear error, never a panic.
    std::fs::write(dir.join("broken.dae"), "<COLLADA><library_geometries>").unwrap();
    let e = ftcbf_sim::robot::read_mesh(&dir.join("broken.dae")).unwrap_err();
    assert!(e.contains("not a readable"), "{e}");
    std::fs::write(dir.join("empty.stl"), "solid nothing\nendsolid nothing\n").unwrap();
    let e = ftcbf_sim::robot::read_mesh(&dir.join("empty.stl")).unwrap_err();
    assert!(e.contains("no triangles"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn robotis_style_comments_in_a_plain_urdf_are_not_xacro() {
    // The fixture carries a commented `<xacro:include … $(find …)>` and a multi-line comment of
    // `<xacro:property>` lines, as the plain TurtleBot3 URDFs did.
    let path = fixtures().join("turtlebot3_burger_ros.urdf");
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.contains("<!-- <xacro:include filename=\"$(find turtlebot3_description)"));
    assert!(text.contains("<xacro:property name=\"r200_cam_depth_offset\" value=\"${"));
    let opts = LoadOptions {
        limits: Some(DriveLimits {
            v_max: 0.22,
            omega_max: 2.84,
            wheel_speed_max: 0.22 / 0.033,
        }),
        ..LoadOptions::default()
    };
    let r = RobotDescription::from_file(&path, &opts).unwrap();
    assert_eq!(r.name, "turtlebot3_burger");
    assert!(!r.wheels.is_skid_steer());
}

#[test]
fn turtlebot3_files_without_wheel_limits_get_the_makers_published_limits() {
    use ftcbf_sim::robot::LimitsSource;
    let path = fixtures().join("turtlebot3_burger_ros.urdf");
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(
        !text.contains("velocity="),
        "the ROS file carries no wheel limits"
    );
    let r = RobotDescription::from_file(&path, &LoadOptions::default()).unwrap();
    let LimitsSource::Maker(m) = r.limits_source else {
        panic!("{:?}", r.limits_source)
    };
    assert_eq!(m.robot_name, "turtlebot3_burger");
    assert!(m.source.contains("ROBOTIS e-manual"));
    assert_eq!((r.limits.v_max, r.limits.omega_max), (0.22, 2.84));
    assert!((r.limits.wheel_speed_max - 0.22 / 0.033).abs() < 1e-9);
    // The same file named as a waffle or waffle_pi gets those figures.
    for name in ["turtlebot3_waffle", "turtlebot3_waffle_pi"] {
        let renamed = text.replace(
            "<robot name=\"turtlebot3_burger\">",
            &format!("<robot name=\"{name}\">"),
        );
        let r = RobotDescription::from_urdf_str(&renamed, &LoadOptions::default()).unwrap();
        assert_eq!((r.limits.v_max, r.limits.omega_max), (0.26, 1.82), "{name}");
    }
    // Explicit limits (a world's [robot] limits) still win.
    let explicit = DriveLimits {
        v_max: 0.1,
        omega_max: 1.0,
        wheel_speed_max: 3.0,
    };
    let opts = LoadOptions {
        limits: Some(explicit),
        ..LoadOptions::default()
    };
    let r = RobotDescription::from_file(&path, &opts).unwrap();
    assert_eq!(
        (r.limits, r.limits_source),
        (explicit, LimitsSource::Explicit)
    );
    // Another robot without limits is still an error naming the joint and its line.
    let renamed = text.replace(
        "<robot name=\"turtlebot3_burger\">",
        "<robot name=\"my_burger_clone\">",
    );
    let line = text
        .lines()
        .position(|l| l.contains("<joint name=\"wheel_left_joint\""))
        .unwrap()
        + 1;
    let msg = RobotDescription::from_urdf_str(&renamed, &LoadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains(&format!(
            "wheel joint `wheel_left_joint` (line {line}) has no <limit velocity>"
        )) && msg.contains("my_burger_clone")
            && msg.contains("[robot] limits"),
        "{msg}"
    );
    // The shipped burger carries wheel limits: they are used, not the maker's.
    let r = RobotDescription::from_file(
        repo().join("robots/turtlebot3_burger.urdf"),
        &LoadOptions::default(),
    )
    .unwrap();
    assert_eq!(r.limits_source, LimitsSource::WheelJoints);
}
