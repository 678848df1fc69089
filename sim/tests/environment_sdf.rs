//! Gazebo SDF worlds loaded as they ship (issue #47): tests/worlds_sdf/room.world and its
//! models, written in the style of the ROBOTIS TurtleBot3 packages (Fuel includes, `model://`
//! URIs, a wrapper model around an include, nested models, `relative_to` and `<frame>`,
//! degrees, nested Collada nodes in inches with an `up_axis` the data does not follow,
//! per-axis mesh scales, `<submesh>`, plugins and an actor to skip, an unknown element).
//! Every position is hand-computed in the comments and asserted within 1 cm.

use std::path::{Path, PathBuf};

use ftcbf_sim::environment::{DropReason, EnvironmentError};
use ftcbf_sim::obstacles::{MeshScale, Obstacle, ObstacleSpec, ShapeSpec};
use ftcbf_sim::world::sdf::{load, Environment, SdfOptions};
use ftcbf_sim::world::World;
use nalgebra::Vector3;

const TOL: f64 = 0.01;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/worlds_sdf")
}

fn opts(height: Option<f64>) -> SdfOptions {
    SdfOptions {
        model_paths: vec![root().join("models")],
        robot_height: height,
        no_environment_variables: true,
    }
}

fn find<'a>(obs: &'a [ObstacleSpec], name: &str) -> &'a ObstacleSpec {
    obs.iter()
        .find(|o| o.name == name)
        .unwrap_or_else(|| panic!("no obstacle `{name}` in {:?}", names(obs)))
}

fn names(obs: &[ObstacleSpec]) -> Vec<&str> {
    obs.iter().map(|o| o.name.as_str()).collect()
}

fn near(got: [f64; 3], want: [f64; 3], what: &str) {
    let d = (0..3)
        .map(|k| (got[k] - want[k]).powi(2))
        .sum::<f64>()
        .sqrt();
    assert!(
        d < TOL,
        "{what}: at {got:?}, expected {want:?} (off by {d:.4} m)"
    );
}

/// The signed distance from `p` to obstacle `name` built as the world builds it.
fn sd(obs: &[ObstacleSpec], name: &str, p: [f64; 3]) -> f64 {
    let ob = Obstacle::from_spec(find(obs, name), None).expect("builds");
    ob.signed_distance(Vector3::new(p[0], p[1], p[2]))
}

const ROOM: &str = "ftcbf_room::ftcbf_room";

#[test]
fn primitives_land_where_their_composed_poses_put_them() {
    let env = load(&root().join("room.world"), &opts(Some(0.2))).expect("loads");
    let o = &env.obstacles;
    // The wrapper model is at (0.5, 0, 0); the included room adds nothing.
    // Wall_1: link (2, 0, 0, yaw 90°), collision (0, 0, 0.25) → (2.5, 0, 0.25), yaw 90°.
    let wall = find(o, &format!("{ROOM}::Wall_1::Wall_1_Collision"));
    near(wall.position, [2.5, 0.0, 0.25], "Wall_1");
    assert!(
        (wall.rpy[2] - std::f64::consts::FRAC_PI_2).abs() < 1e-3,
        "{:?}",
        wall.rpy
    );
    assert_eq!(
        wall.shape,
        ShapeSpec::Cuboid {
            half_extents: [2.0, 0.075, 0.25]
        }
    );
    // pillar: relative_to the frame `corner` at (1, 1, 0) in the model, plus (0.5, 0, 0),
    // collision 0.25 up → (2.0, 1.0, 0.25); a cylinder of length 0.5 is half_height 0.25.
    let pillar = find(o, &format!("{ROOM}::pillar::pillar_collision"));
    near(pillar.position, [2.0, 1.0, 0.25], "pillar");
    assert_eq!(
        pillar.shape,
        ShapeSpec::Cylinder {
            radius: 0.15,
            half_height: 0.25
        }
    );
    // posts: link at (0, −1, 0) turned 90° (degrees="true"): (x, y) → (−y, x).
    // capsule (0.5, 0, 0.3) → (0, −0.5) → (0.5, −0.5, 0.3); ball (−0.5, 0, 0.2) → (0.5, −1.5,
    // 0.2); ellipsoid (0, 0.6, 0.15) → (−0.6, −1) → (−0.1, −1.0, 0.15).
    near(
        find(o, &format!("{ROOM}::posts::capsule")).position,
        [0.5, -0.5, 0.3],
        "capsule",
    );
    near(
        find(o, &format!("{ROOM}::posts::ball")).position,
        [0.5, -1.5, 0.2],
        "ball",
    );
    near(
        find(o, &format!("{ROOM}::posts::egg")).position,
        [-0.1, -1.0, 0.15],
        "egg",
    );
    // The ellipsoid's hull contains the ellipsoid and hugs it: 0.1 m semi-axis along the
    // link's y, which is world −x after the turn.
    let d = sd(o, &format!("{ROOM}::posts::egg"), [-0.1 - 0.3, -1.0, 0.15]);
    assert!(d > 0.2 - TOL && d <= 0.2 + 1e-5, "egg distance {d}");
    // The nested model `shelf` at (−1, 1, 0): its side (0, 0, 0.4) → (−0.5, 1.0, 0.4).
    near(
        find(o, &format!("{ROOM}::shelf::link::side")).position,
        [-0.5, 1.0, 0.4],
        "shelf side",
    );
}

#[test]
fn meshes_are_scaled_per_axis_and_nested_collada_nodes_composed() {
    let env = load(&root().join("room.world"), &opts(Some(0.2))).expect("loads");
    let o = &env.obstacles;
    // crate: the unit cube [0, 1]³ scaled (0.4, 0.2, 0.3) at the link (−1, −1, 0) → (−0.5, −1,
    // 0): it spans x ∈ [−0.5, −0.1], y ∈ [−1, −0.8], z ∈ [0, 0.3].
    let crate_ = find(o, &format!("{ROOM}::crate::crate_collision"));
    near(crate_.position, [-0.5, -1.0, 0.0], "crate");
    assert!(matches!(
        crate_.shape,
        ShapeSpec::TriMesh { scale: Some(MeshScale::PerAxis(s)), .. } if s == [0.4, 0.2, 0.3]
    ));
    let d = sd(
        o,
        &format!("{ROOM}::crate::crate_collision"),
        [-0.3, -0.3, 0.15],
    );
    assert!((d - 0.5).abs() < TOL, "crate: distance {d}, expected 0.5");
    // The mailbox box: the cube ±1 in, child node translate (10, 0, 1) in, parent scale (2, 2,
    // 4) then rotate 90° about z → centre (0, 20, 4) in = (0, 0.508, 0.1016) m, half extents
    // (0.0508, 0.0508, 0.1016) m. The include turns the model 180° at (−2, 0.5): centre
    // (−2, −0.008, 0.1016). (mesh-loader's own composition put it elsewhere.)
    let mb = "front_mailbox::link::collision";
    near(find(o, mb).position, [-2.0, 0.5, 0.0], "mailbox frame");
    let d = sd(o, mb, [-2.0, -0.008 + 0.3, 0.1]);
    assert!((d - (0.3 - 0.0508)).abs() < TOL, "mailbox: distance {d}");
    let d = sd(o, mb, [-2.0 + 0.3, -0.008, 0.1]);
    assert!((d - (0.3 - 0.0508)).abs() < TOL, "mailbox: distance {d}");
    // The post submesh, centred: ±1 × ±1 × ±4 in, scaled (1, 2, 0.5) → half extents (0.0254,
    // 0.0508, 0.0508) m, at the collision pose (0.5, 0, 0) turned 180° → (−2.5, 0.5, 0).
    let post = "front_mailbox::link::post";
    near(find(o, post).position, [-2.5, 0.5, 0.0], "post");
    let d = sd(o, post, [-2.5, 0.5 + 0.3, 0.0]);
    assert!((d - (0.3 - 0.0508)).abs() < TOL, "post: distance {d}");
    let d = sd(o, post, [-2.5 + 0.3, 0.5, 0.0]);
    assert!((d - (0.3 - 0.0254)).abs() < TOL, "post: distance {d}");
    // The declared Y_UP is reported, not applied (Gazebo reads the data with z up).
    assert!(
        env.report
            .warnings
            .iter()
            .any(|w| w.contains("mailbox_nested.dae") && w.contains("<up_axis>Y_UP</up_axis>")),
        "{:#?}",
        env.report.warnings
    );
}

#[test]
fn a_non_convex_polyline_is_a_prism_with_its_notch() {
    let env = load(&root().join("room.world"), &opts(Some(0.2))).expect("loads");
    let o = &env.obstacles;
    let kerb = "kerb::link::kerb";
    near(find(o, kerb).position, [0.0, -2.5, 0.0], "kerb");
    // Inside the left lobe: (0.2, 0.2) is below the edge from (0.5, 0.1) to (0, 0.4).
    assert!(sd(o, kerb, [0.2, -2.5 + 0.2, 0.05]) < 0.0);
    // Above the notch at x = 0.5, 0.2 m over its vertex (0.5, 0.1): the nearest points are on
    // the edges leaving the vertex along (±0.5, 0.3), at 0.2·0.5/√0.34 = 0.1715 m.
    let d = sd(o, kerb, [0.5, -2.5 + 0.3, 0.05]);
    assert!((d - 0.1 / 0.34f64.sqrt()).abs() < TOL, "notch distance {d}");
    // Outside the bottom edge: 0.3 m below y = 0.
    let d = sd(o, kerb, [0.5, -2.5 - 0.3, 0.05]);
    assert!((d - 0.3).abs() < TOL, "bottom distance {d}");
}

/// The names of the elements `env` dropped for reason `r`, in the report's order.
fn dropped_for(env: &Environment, r: DropReason) -> Vec<&str> {
    (env.report.dropped.iter())
        .filter(|d| d.reason == r)
        .map(|d| d.name.as_str())
        .collect()
}

#[test]
fn what_a_ground_robot_cannot_touch_is_dropped_and_said_why() {
    let env = load(&root().join("room.world"), &opts(Some(0.2))).expect("loads");
    let kept = names(&env.obstacles);
    assert_eq!(kept.len(), 10, "{kept:?}");
    let dropped = |r: DropReason| dropped_for(&env, r);
    assert_eq!(
        dropped(DropReason::AboveRobot),
        [
            format!("{ROOM}::Wall_1_lintel::lintel"),
            format!("{ROOM}::shelf::link::board")
        ]
    );
    assert_eq!(dropped(DropReason::VisualOnly), [format!("{ROOM}::poster")]);
    assert_eq!(
        dropped(DropReason::Ground),
        ["floor_tiles::link::tiles", "floor_tiles::link::ground"]
    );
    assert_eq!(dropped(DropReason::Actor), ["walker"]);
    assert_eq!(
        dropped(DropReason::Plugin),
        [
            "gz::sim::systems::Physics",
            "gz::sim::systems::SceneBroadcaster",
            "room_lights"
        ]
    );
    assert_eq!(dropped(DropReason::FuelInclude).len(), 2);
    // The unknown element is a warning with its line, as libsdformat gives it.
    let world = root().join("room.world");
    let line = std::fs::read_to_string(&world)
        .unwrap()
        .lines()
        .position(|l| l.contains("<sparkle>"))
        .unwrap()
        + 1;
    let want = format!(
        "{}:{line}: <sparkle> is not an SDF element of <model>",
        world.display()
    );
    assert!(
        env.report.warnings.iter().any(|w| w.starts_with(&want)),
        "{want} in {:#?}",
        env.report.warnings
    );
    // model.config's highest <sdf version> (model.sdf, 1.7) is read, not model-1_4.sdf.
    assert!(!kept.iter().any(|n| n.contains("wrong")));
    // Without a robot height, the lintel and the board are kept.
    let all = load(&world, &opts(None)).expect("loads");
    assert_eq!(all.obstacles.len(), 12);
}

#[test]
fn an_unresolved_model_uri_names_the_paths_searched() {
    let dir = std::env::temp_dir().join(format!("ftcbf_sdf_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let f = dir.join("w.world");
    std::fs::write(
        &f,
        "<?xml version=\"1.0\"?>\n<sdf version=\"1.8\">\n  <world name=\"w\">\n    <include>\n      \
         <uri>model://no_such_model</uri>\n    </include>\n  </world>\n</sdf>\n",
    )
    .unwrap();
    let e = load(&f, &opts(Some(0.2))).unwrap_err();
    let EnvironmentError::Sdf { line, message, .. } = &e else {
        panic!("{e}")
    };
    assert_eq!(*line, Some(4), "{e}");
    assert!(
        message.contains("model://no_such_model not found; searched"),
        "{e}"
    );
    assert!(message.contains("worlds_sdf/models"), "{e}");
    std::fs::write(&f, "<sdf version=\"1.8\"><world name=\"w\"><model name=\"m\"><link name=\"l\"><collision name=\"c\"><geometry><box><size>1 x 1</size></box></geometry></collision></link></model></world></sdf>").unwrap();
    let e = load(&f, &opts(Some(0.2))).unwrap_err().to_string();
    assert!(
        e.contains("w.world:1: <size> expects 3 finite numbers"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_world_file_loads_the_sdf_and_check_says_what_was_kept() {
    let world = World::load(&root().join("room.toml"), &[]).expect("room.toml loads");
    let report = world.environment.as_ref().expect("an environment");
    assert_eq!(world.obstacles.len(), 10);
    assert_eq!(report.kept.len(), 10);
    // The burger's collision geometry is 0.192 m tall: the lintel (from 1.9 m) and the shelf
    // board (from 1.19 m) are above it.
    let h = report.robot_height.unwrap();
    assert!(h > 0.15 && h < 0.25, "burger height {h}");
    assert!(world.file.environment.as_ref().unwrap().sdf.is_none());
    // An edited copy does not load the environment a second time.
    let again = world.with_file(world.file.clone()).expect("revalidates");
    assert_eq!(again.obstacles.len(), 10);
    assert_eq!(again.environment, world.environment);
    let check = ftcbf_sim::analysis::check::check_world(&world).expect("checks");
    let text = check.to_string();
    assert!(
        text.contains("room.world: 10 obstacles kept, 11 elements dropped"),
        "{text}"
    );
    assert!(
        text.contains("dropped, above the robot: 2 (ftcbf_room::ftcbf_room::Wall_1_lintel::lintel, ftcbf_room::ftcbf_room::shelf::link::board)"),
        "{text}"
    );
}

#[test]
fn a_per_axis_scale_is_accepted_in_a_world_file() {
    let text = std::fs::read_to_string(root().join("room.toml"))
        .unwrap()
        .replace(
            "[environment]\nsdf = \"room.world\"\nmodel_paths = [\"models\"]\n",
            "[[obstacles]]\nname = \"crate\"\nposition = [-1.0, -1.0, 0.0]\nshape = { kind = \"tri_mesh\", file = \"models/ftcbf_room/meshes/unit_cube.stl\", scale = [0.4, 0.2, 0.3] }\n",
        );
    let world = World::from_str(&text, &root().join("inline.toml"), &[]).expect("loads");
    let d = world.obstacles[0].signed_distance(Vector3::new(-0.8, -0.3, 0.15));
    assert!((d - 0.5).abs() < TOL, "distance {d}");
    let bad = text.replace("scale = [0.4, 0.2, 0.3]", "scale = [0.4, 0.2]");
    let e = World::from_str(&bad, &root().join("inline.toml"), &[])
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("expected a number or three numbers [sx, sy, sz], found 2 numbers"),
        "{e}"
    );
}

/// tests/worlds_sdf/stage.world, in the style of the DQN stages: sub-models of one model
/// directory (`model://ftcbf_arena/inner`), an include's pose in degrees replacing the model's
/// own, a plugin on an include that moves a dynamic model, a dynamic model without one.
#[test]
fn a_dqn_style_stage_places_its_walls_and_leaves_out_what_a_plugin_moves() {
    let env = load(&root().join("stage.world"), &opts(Some(0.2))).expect("loads");
    let o = &env.obstacles;
    let yaw = |spec: &ObstacleSpec| spec.rpy[2];
    // The wrapper model `ftcbf_arena` (static, at the origin) around the included square.
    let east = find(o, "ftcbf_arena::ftcbf_square::Wall_E::Wall_E_Collision");
    near(east.position, [1.925, 0.0, 0.25], "Wall_E");
    // 1.5708 in the file: a quarter turn within 4e-6 rad.
    assert!(
        (yaw(east) - std::f64::consts::FRAC_PI_2).abs() < 1e-4,
        "{:?}",
        east.rpy
    );
    assert_eq!(
        east.shape,
        ShapeSpec::Cuboid {
            half_extents: [2.0, 0.075, 0.25]
        }
    );
    near(
        find(o, "ftcbf_arena::ftcbf_square::Wall_S::Wall_S_Collision").position,
        [0.0, -1.925, 0.25],
        "Wall_S",
    );
    // inner: the include's pose (0.5, −0.25, 0, yaw 30°) replaces the model's (5, 5, 0).
    // inner_wall_1: link (1, 0, 0.25, yaw −90°) → R(30°)(1, 0) = (0.8660, 0.5) → (1.3660,
    // 0.25, 0.25), yaw 30° − 90° = −60°.
    let w1 = find(o, "inner_walls::inner_wall_1::inner_wall_1_collision");
    near(w1.position, [1.3660, 0.25, 0.25], "inner_wall_1");
    assert!((yaw(w1) + 60f64.to_radians()).abs() < 1e-4, "{:?}", w1.rpy);
    // Its thin side faces along R(−60°)(0, 1) = (0.8660, 0.5): 0.5 m out, 0.5 − 0.075 away.
    let d = sd(
        o,
        "inner_walls::inner_wall_1::inner_wall_1_collision",
        [1.3660 + 0.5 * 0.8660, 0.25 + 0.5 * 0.5, 0.25],
    );
    assert!((d - 0.425).abs() < TOL, "inner_wall_1 distance {d}");
    // inner_wall_2: link (0, 0.5, 0) and collision (−0.5, 0, 0.25) → (−0.5, 0.5) in the
    // model → R(30°)(−0.5, 0.5) = (−0.6830, 0.1830) → (−0.1830, −0.0670, 0.25), yaw 30°.
    let w2 = find(o, "inner_walls::inner_wall_2::inner_wall_2_collision");
    near(w2.position, [-0.1830, -0.0670, 0.25], "inner_wall_2");
    assert!((yaw(w2) - 30f64.to_radians()).abs() < 1e-4, "{:?}", w2.rpy);
    near(
        find(o, "pillars::pillar_1::pillar_1_collision").position,
        [-1.0, -1.0, 0.25],
        "pillar_1",
    );
    // crate_a (the include's <name>): model (1.2, −1.2, 0), link (0, 0, 0.2, yaw 45°),
    // collision (0.1, 0, 0) in the link → (0.0707, 0.0707) → (1.2707, −1.1293, 0.2).
    let crate_a = find(o, "crate_a::body::body_collision");
    near(crate_a.position, [1.2707, -1.1293, 0.2], "crate_a");
    assert!((yaw(crate_a) - 45f64.to_radians()).abs() < 1e-4);
    assert_eq!(o.len(), 9, "{:?}", names(o));

    let dropped = |r: DropReason| dropped_for(&env, r);
    // The spinner is dynamic and its include attaches a plugin: Gazebo moves it, nothing
    // here does, so it is left out (not frozen where it starts), and a warning says so.
    assert_eq!(
        dropped(DropReason::PluginDriven),
        ["spinner::link::spinner_collision"]
    );
    assert!(!names(o).iter().any(|n| n.starts_with("spinner")));
    assert!(
        env.report.warnings.iter().any(|w| w.contains("`spinner`")
            && w.contains("ftcbf_tests::SpinnerPlugin")
            && w.contains("left out")),
        "{:#?}",
        env.report.warnings
    );
    // The crate is dynamic with no plugin: kept where it stands, with a warning.
    assert!(
        env.report
            .warnings
            .iter()
            .any(|w| w.contains("`crate_a` is not static")),
        "{:#?}",
        env.report.warnings
    );
    assert_eq!(
        dropped(DropReason::Plugin),
        [
            "gz::sim::systems::Physics",
            "gz::sim::systems::Imu",
            "ftcbf_tests::SpinnerPlugin"
        ]
    );
    assert_eq!(
        dropped(DropReason::AboveRobot),
        ["pillars::lamp::lamp_collision"]
    );
    assert_eq!(dropped(DropReason::Actor), ["pedestrian"]);
    assert_eq!(dropped(DropReason::FuelInclude).len(), 1);
    // check's lines name the plugin-driven drop on a line of its own.
    assert!(
        env.report
            .lines()
            .iter()
            .any(|l| l.contains("moved by a plugin") && l.contains("spinner::link")),
        "{:#?}",
        env.report.lines()
    );
}
