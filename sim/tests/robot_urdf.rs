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
    assert_eq!(r.wheels.left.joint_name, "wheel_left_joint");
    assert_eq!(r.wheels.right.joint_name, "wheel_right_joint");
    assert_eq!(r.wheels.left.forward_sign, 1.0);
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
    let w = &r.bodies[r.wheels.left.body];
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
    // Without wheel velocity limits in the file the caller must give them.
    let e = RobotDescription::from_file(&path, &LoadOptions::default()).unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.contains("wheel_") && msg.contains("<limit velocity>"),
        "{msg}"
    );

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
    assert_eq!(r.wheels.left.forward_sign, 1.0);
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
