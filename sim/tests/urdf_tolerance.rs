//! URDF read the way ROS's parser (urdfdom) reads it: unknown elements and attributes are
//! warnings with their line, missing optional values take the spec's defaults, and what ROS
//! refuses is refused with the element, its name and the line. Deep nesting is a clean error.

use ftcbf_sim::robot::{LoadOptions, RobotDescription, RobotError, MAX_URDF_DEPTH};

/// A small differential-drive robot, one element per line so that lines are easy to state.
/// `{EXTRA}` is replaced by test-specific lines inside <robot>.
const ROBOT: &str = r#"<?xml version="1.0"?>
<robot name="tol">
  <link name="base_footprint"/>
  <joint name="base_joint" type="fixed">
    <parent link="base_footprint"/>
    <child link="base_link"/>
    <origin xyz="0 0 0.01"/>
  </joint>
  <link name="base_link">
    <inertial>
      <mass value="2.0"/>
      <inertia ixx="0.02" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.03"/>
    </inertial>
    <collision>
      <origin xyz="0 0 0.08"/>
      <geometry>
        <box size="0.3 0.25 0.1"/>
      </geometry>
    </collision>
  </link>
  <joint name="left_wheel_joint" type="continuous">
    <parent link="base_link"/>
    <child link="left_wheel"/>
    <origin xyz="0 0.14 0.04" rpy="-1.5707963267948966 0 0"/>
    <axis xyz="0 0 1"/>
    <limit effort="2" velocity="8"/>
  </joint>
  <link name="left_wheel">
    <inertial>
      <mass value="0.1"/>
      <inertia ixx="5e-5" ixy="0" ixz="0" iyy="5e-5" iyz="0" izz="8e-5"/>
    </inertial>
    <collision>
      <geometry>
        <cylinder radius="0.05" length="0.02"/>
      </geometry>
    </collision>
  </link>
  <joint name="right_wheel_joint" type="continuous">
    <parent link="base_link"/>
    <child link="right_wheel"/>
    <origin xyz="0 -0.14 0.04" rpy="-1.5707963267948966 0 0"/>
    <axis xyz="0 0 1"/>
    <limit effort="2" velocity="8"/>
  </joint>
  <link name="right_wheel">
    <inertial>
      <mass value="0.1"/>
      <inertia ixx="5e-5" ixy="0" ixz="0" iyy="5e-5" iyz="0" izz="8e-5"/>
    </inertial>
    <collision>
      <geometry>
        <cylinder radius="0.05" length="0.02"/>
      </geometry>
    </collision>
  </link>
{EXTRA}
</robot>
"#;

/// Line (1-based) of the first line of `text` containing `marker`.
fn line_of(text: &str, marker: &str) -> usize {
    text.lines()
        .position(|l| l.contains(marker))
        .unwrap_or_else(|| panic!("marker {marker:?} not in the text"))
        + 1
}

fn load(text: &str) -> Result<RobotDescription, RobotError> {
    RobotDescription::from_urdf_str(text, &LoadOptions::default())
}

fn with_extra(extra: &str) -> String {
    ROBOT.replace("{EXTRA}", extra)
}

/// Loads `text`, expecting a parse error on the line holding `marker`; returns the message.
fn refused_at(text: &str, marker: &str) -> String {
    let e = load(text).expect_err("ROS refuses this file, so must we");
    let line = line_of(text, marker);
    assert!(
        matches!(&e, RobotError::Parse { line: Some(l), .. } if *l == line),
        "expected a parse error on line {line} ({marker:?}), got {e:?}"
    );
    let msg = e.to_string();
    assert!(msg.contains(&format!("line {line}: ")), "{msg}");
    msg
}

#[test]
fn the_base_file_loads_without_warnings() {
    let r = load(&with_extra("")).unwrap();
    assert!(r.warnings.is_empty(), "{:?}", r.warnings);
    assert!((r.wheels.geometry.radius - 0.05).abs() < 1e-12);
    assert!((r.wheels.geometry.separation - 0.28).abs() < 1e-12);
}

#[test]
fn pioneer_style_axis_typo_on_a_fixed_joint_is_a_warning_not_an_error() {
    // As in both public Pioneer 3-DX files: `xzy` for `xyz` on a fixed joint's axis.
    let text = with_extra(
        r#"  <joint name="top_plate_joint" type="fixed">
    <parent link="base_link"/>
    <child link="top_plate"/>
    <origin xyz="0.003 0 0.274"/>
    <axis xzy="0 0 1"/>
  </joint>
  <link name="top_plate"/>"#,
    );
    let r = load(&text).unwrap_or_else(|e| panic!("ROS loads this file: {e}"));
    let line = line_of(&text, "xzy=");
    assert_eq!(r.warnings.len(), 1, "{:?}", r.warnings);
    let w = &r.warnings[0];
    assert!(
        w.contains(&format!("line {line}: "))
            && w.contains("unknown attribute `xzy`")
            && w.contains("<axis> of <joint> `top_plate_joint`"),
        "{w}"
    );
    // The fixed link was merged into the base body.
    assert_eq!(r.body_of_link("top_plate"), r.body_of_link("base_link"));
}

#[test]
fn unknown_elements_and_attributes_are_warnings_with_lines_ros_extensions_are_silent() {
    let text = with_extra(
        r#"  <gazebo reference="left_wheel">
    <mu1>1.0</mu1>
  </gazebo>
  <transmission name="t1"><type>transmission_interface/SimpleTransmission</type></transmission>
  <ros2_control name="sys" type="system"/>
  <sensor_rig name="rig"/>
  <link name="camera_link" colour="red">
    <visual>
      <geometry>
        <box size="0.01 0.02 0.02"/>
      </geometry>
      <shininess value="3"/>
    </visual>
  </link>
  <joint name="camera_joint" type="fixed">
    <parent link="base_link"/>
    <child link="camera_link"/>
  </joint>"#,
    );
    let r = load(&text).unwrap();
    let expect = [
        (
            line_of(&text, "<sensor_rig"),
            "unknown element <sensor_rig> in <robot>",
        ),
        (
            line_of(&text, "colour="),
            "unknown attribute `colour` on <link> `camera_link`",
        ),
        (
            line_of(&text, "<shininess"),
            "unknown element <shininess> in <visual> of <link> `camera_link`",
        ),
    ];
    assert_eq!(r.warnings.len(), expect.len(), "{:?}", r.warnings);
    for (w, (line, what)) in r.warnings.iter().zip(expect) {
        assert!(
            w.contains(&format!("line {line}: ")) && w.contains(what),
            "{w} (expected line {line}: {what})"
        );
    }
    // The joint without <origin> sits at the parent's origin (the spec's default).
    let b = r.body_of_link("camera_link").unwrap();
    assert_eq!(b, r.body_of_link("base_link").unwrap());
}

#[test]
fn missing_optional_values_take_the_spec_defaults() {
    // A continuous joint without <axis> turns about x (1, 0, 0); <origin> with only rpy has a
    // zero xyz; an <axis> without xyz on a moving joint falls back to (1, 0, 0) with a warning.
    let text = with_extra(
        r#"  <joint name="spinner_joint" type="continuous">
    <parent link="base_link"/>
    <child link="spinner"/>
    <origin rpy="0 0 0.5"/>
  </joint>
  <link name="spinner">
    <inertial>
      <mass value="0.01"/>
      <inertia ixx="1e-6" ixy="0" ixz="0" iyy="1e-6" iyz="0" izz="1e-6"/>
    </inertial>
  </link>
  <joint name="flap_joint" type="revolute">
    <parent link="base_link"/>
    <child link="flap"/>
    <axis xzy="0 1 0"/>
    <limit effort="1" velocity="1"/>
  </joint>
  <link name="flap">
    <inertial>
      <mass value="0.01"/>
      <inertia ixx="1e-6" ixy="0" ixz="0" iyy="1e-6" iyz="0" izz="1e-6"/>
    </inertial>
  </link>"#,
    );
    let r = load(&text).unwrap();
    let spinner = r.joints.iter().find(|j| j.name == "spinner_joint").unwrap();
    assert!((spinner.axis.into_inner() - nalgebra::Vector3::x()).norm() < 1e-15);
    // No xyz: the joint sits at base_link's origin, 0.01 m above the root body's frame.
    let t = spinner.frame_in_parent.translation.vector;
    assert!(
        (t - nalgebra::Vector3::new(0.0, 0.0, 0.01)).norm() < 1e-15,
        "{t:?}"
    );
    let flap = r.joints.iter().find(|j| j.name == "flap_joint").unwrap();
    assert!((flap.axis.into_inner() - nalgebra::Vector3::x()).norm() < 1e-15);
    // <limit> without lower/upper: both 0, as urdfdom reads them.
    assert_eq!(
        flap.kind,
        ftcbf_sim::robot::JointKind::Revolute {
            lower: 0.0,
            upper: 0.0
        }
    );
    let axis_line = line_of(&text, "<axis xzy=\"0 1 0\"/>");
    assert!(
        r.warnings
            .iter()
            .any(|w| w.contains(&format!("line {axis_line}: "))
                && w.contains("<axis> of <joint> `flap_joint` has no `xyz`")
                && w.contains("(1, 0, 0)")),
        "{:?}",
        r.warnings
    );
}

#[test]
fn what_ros_refuses_is_refused_with_element_name_and_line() {
    // A wheel cylinder without its radius.
    let text = ROBOT.replacen(
        r#"<cylinder radius="0.05" length="0.02"/>"#,
        r#"<cylinder length="0.02"/>"#,
        1,
    );
    let msg = refused_at(&text, r#"<cylinder length="0.02"/>"#);
    assert!(
        msg.contains(
            "<cylinder> in <geometry> of <collision> of <link> `left_wheel` has no `radius`"
        ),
        "{msg}"
    );
    // <limit> without velocity (urdfdom: "joint limit: no velocity").
    let text = ROBOT.replacen(
        r#"<limit effort="2" velocity="8"/>"#,
        r#"<limit effort="2"/>"#,
        1,
    );
    let msg = refused_at(&text, r#"<limit effort="2"/>"#);
    assert!(
        msg.contains("<limit> of <joint> `left_wheel_joint` has no `velocity`"),
        "{msg}"
    );
    // An unknown joint type.
    let text = ROBOT.replacen(r#"type="continuous""#, r#"type="contiuous""#, 1);
    let msg = refused_at(&text, r#"type="contiuous""#);
    assert!(
        msg.contains("<joint> `left_wheel_joint` has type `contiuous`"),
        "{msg}"
    );
    // A link without a name.
    let text = with_extra("  <link/>");
    let msg = refused_at(&text, "<link/>");
    assert!(msg.contains("<link> has no `name`"), "{msg}");
    // A revolute joint without <limit>.
    let text = with_extra(
        r#"  <joint name="arm_joint" type="revolute">
    <parent link="base_link"/>
    <child link="arm"/>
  </joint>
  <link name="arm"/>"#,
    );
    let msg = refused_at(&text, r#"<joint name="arm_joint""#);
    assert!(msg.contains("is revolute but has no <limit>"), "{msg}");
    // An <inertial> without <inertia>.
    let text = ROBOT.replacen(
        r#"      <inertia ixx="0.02" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.03"/>
"#,
        "",
        1,
    );
    let msg = refused_at(&text, "<inertial>");
    assert!(
        msg.contains("<inertial> of <link> `base_link` has no <inertia>"),
        "{msg}"
    );
    // A number that is not one, a vector of two numbers, an unknown shape.
    let text = ROBOT.replacen(r#"<mass value="2.0"/>"#, r#"<mass value="2.0kg"/>"#, 1);
    let msg = refused_at(&text, "2.0kg");
    assert!(
        msg.contains("`value=\"2.0kg\"` is not a finite number"),
        "{msg}"
    );
    let text = ROBOT.replacen(
        r#"<origin xyz="0 0 0.08"/>"#,
        r#"<origin xyz="0 0.08"/>"#,
        1,
    );
    let msg = refused_at(&text, r#"<origin xyz="0 0.08"/>"#);
    assert!(msg.contains("is not 3 finite numbers"), "{msg}");
    let text = ROBOT.replacen(
        r#"<box size="0.3 0.25 0.1"/>"#,
        r#"<cone radius="0.1"/>"#,
        1,
    );
    let msg = refused_at(&text, "<cone");
    assert!(msg.contains("unknown shape <cone>"), "{msg}");
    // A collision without geometry.
    let text = ROBOT.replacen(
        r#"      <geometry>
        <box size="0.3 0.25 0.1"/>
      </geometry>
"#,
        "",
        1,
    );
    let msg = refused_at(&text, "<collision>");
    assert!(msg.contains("has no <geometry>"), "{msg}");
    // Two links of one name; the message points at the first.
    let text = with_extra("  <link name=\"left_wheel\"/>");
    let msg = refused_at(&text, "<link name=\"left_wheel\"/>");
    let first = line_of(&text, "<link name=\"left_wheel\">");
    assert!(
        msg.contains(&format!(
            "`left_wheel` is defined twice (first on line {first})"
        )),
        "{msg}"
    );
    // Not a robot at all.
    let msg = refused_at("<?xml version=\"1.0\"?>\n<sdf version=\"1.6\"/>\n", "<sdf");
    assert!(msg.contains("the root element is <sdf>"), "{msg}");
}

#[test]
fn joint_cycles_and_dangling_links_name_the_joints_and_their_lines() {
    // `loop_a` → `loop_b` → `loop_a`: both links have a parent, so they hang off no root.
    let text = with_extra(
        r#"  <link name="loop_a"/>
  <link name="loop_b"/>
  <joint name="a_to_b" type="fixed">
    <parent link="loop_a"/>
    <child link="loop_b"/>
  </joint>
  <joint name="b_to_a" type="fixed">
    <parent link="loop_b"/>
    <child link="loop_a"/>
  </joint>"#,
    );
    let e = load(&text).unwrap_err();
    assert!(matches!(e, RobotError::Structure { .. }), "{e:?}");
    let msg = e.to_string();
    let (la, lb) = (line_of(&text, "\"a_to_b\""), line_of(&text, "\"b_to_a\""));
    assert!(
        msg.contains("the joints form a cycle")
            && msg.contains(&format!("joint `a_to_b` (line {la})"))
            && msg.contains(&format!("joint `b_to_a` (line {lb})")),
        "{msg}"
    );
    // A joint naming a link that does not exist.
    let text = with_extra(
        r#"  <joint name="lidar_joint" type="fixed">
    <parent link="base_lnk"/>
    <child link="lidar"/>
  </joint>
  <link name="lidar"/>"#,
    );
    let msg = load(&text).unwrap_err().to_string();
    let l = line_of(&text, "\"lidar_joint\"");
    assert!(
        msg.contains(&format!(
            "joint `lidar_joint` (line {l}) names parent link `base_lnk`"
        )),
        "{msg}"
    );
    // A link with two parents.
    let text = with_extra(
        r#"  <joint name="second_parent" type="fixed">
    <parent link="base_link"/>
    <child link="left_wheel"/>
  </joint>"#,
    );
    let msg = load(&text).unwrap_err().to_string();
    assert!(
        msg.contains(
            "link `left_wheel` is the child of two joints, joint `left_wheel_joint` (line"
        ) && msg.contains(&format!(
            "joint `second_parent` (line {})",
            line_of(&text, "\"second_parent\"")
        )),
        "{msg}"
    );
}

/// `depth` nested `<elem>` inside the robot's <gazebo> block.
fn deeply_nested(depth: usize) -> String {
    let mut s = String::with_capacity(depth * 16 + ROBOT.len());
    s.push_str("  <gazebo>\n");
    for _ in 0..depth {
        s.push_str("<elem>");
    }
    for _ in 0..depth {
        s.push_str("</elem>");
    }
    s.push_str("\n  </gazebo>");
    with_extra(&s)
}

#[test]
fn twenty_thousand_nested_elements_are_a_clean_error_not_a_stack_overflow() {
    // Issue #29: "thread 'main' has overflowed its stack". Run on a thread with a small stack
    // (256 KiB): nothing in the reader may recurse per nesting level.
    for depth in [20_000, 200_000] {
        let text = deeply_nested(depth);
        let res = std::thread::Builder::new()
            .stack_size(256 * 1024)
            .spawn(move || load(&text).map(|_| ()).map_err(|e| (e.to_string(), e)))
            .unwrap()
            .join()
            .expect("no panic, no overflow");
        let (msg, e) = res.expect_err("too deep");
        assert!(matches!(e, RobotError::Parse { .. }), "{e:?}");
        assert!(
            msg.contains(&format!("more than {MAX_URDF_DEPTH} levels")),
            "{msg}"
        );
        let line = line_of(&deeply_nested(1), "<elem>");
        assert!(msg.contains(&format!("line {line}: ")), "{msg}");
    }
    // Nesting at the limit is accepted (robot = level 1, gazebo = 2).
    let r = load(&deeply_nested(MAX_URDF_DEPTH - 2)).unwrap();
    assert!(r.warnings.is_empty(), "{:?}", r.warnings);
    assert!(load(&deeply_nested(MAX_URDF_DEPTH - 1)).is_err());
}
