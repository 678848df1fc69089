//! Obstacles that move (issue #51): the world file's `motion`, the physics moving them, the
//! time-varying rows keeping the robot off them, collisions counted by who moved, reruns bit
//! for bit, and what `check` says (escape, liveness: waits vs blocked for good).

use std::path::{Path, PathBuf};

use ftcbf_sim::analysis::check::check_world;
use ftcbf_sim::runner::{run, RunOptions};
use ftcbf_sim::world::{ControllerKindSpec, World};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn world(rel: &str) -> World {
    World::load(&root().join(rel), &[]).unwrap_or_else(|e| panic!("{e}"))
}

/// `tests/worlds_movers/aisle_crossing.toml` with its cart's `motion` line replaced.
fn aisle_with(motion: &str) -> Result<World, String> {
    let path = root().join("tests/worlds_movers/aisle_crossing.toml");
    let text = std::fs::read_to_string(&path).expect("readable");
    let line = text
        .lines()
        .find(|l| l.starts_with("motion ="))
        .expect("the cart moves");
    let text = text.replace(line, &format!("motion = {motion}"));
    World::from_str(&text, Path::new(&path), &[]).map_err(|e| e.to_string())
}

fn opts(seed: u64, controller: ControllerKindSpec) -> RunOptions {
    RunOptions {
        seed: Some(seed),
        controller: Some(controller),
        ..RunOptions::default()
    }
}

/// The nominal controller drives into the cart crossing its route; the FT-CBF-CLF's rows,
/// with the cart's ∂h/∂t, keep it off and it still reaches its goal.
#[test]
fn the_rows_keep_the_robot_off_a_crossing_cart_that_the_nominal_controller_hits() {
    let w = world("tests/worlds_movers/aisle_crossing.toml");
    let nominal = run(&w, &opts(1, ControllerKindSpec::Nominal)).expect("runs");
    assert!(nominal.collided, "the nominal controller missed the cart");
    assert_eq!(
        nominal
            .first_collision
            .as_ref()
            .map(|c| c.obstacle.as_str()),
        Some("cart")
    );
    assert!(nominal.collisions.movers() > 0 && nominal.collisions.static_obstacles == 0);
    let ft = run(&w, &opts(1, ControllerKindSpec::FtCbfClf)).expect("runs");
    assert!(ft.safe && !ft.collided, "{ft}");
    assert_eq!(ft.collisions.movers(), 0);
    let clearance = ft.min_clearance.expect("an obstacle");
    assert!(clearance > 0.05, "min clearance {clearance} m");
    assert!(ft.goal_settled, "{ft}");
}

/// Walkers are seeded from the trial seed: the same seed reruns bit for bit, another walks
/// another way.
#[test]
fn walkers_rerun_bit_for_bit_with_the_seed() {
    let w = world("tests/worlds_movers/room_two_people.toml");
    let a = run(&w, &opts(3, ControllerKindSpec::FtCbfClf)).expect("runs");
    let b = run(&w, &opts(3, ControllerKindSpec::FtCbfClf)).expect("runs");
    assert_eq!(
        serde_json::to_string(&a).unwrap(),
        serde_json::to_string(&b).unwrap()
    );
    let c = run(&w, &opts(4, ControllerKindSpec::FtCbfClf)).expect("runs");
    assert_ne!(a.final_state, c.final_state);
}

#[test]
fn a_bad_motion_is_an_error_naming_its_key() {
    for (motion, key, expected) in [
        (
            r#"{ kind = "waypoints", points = [[1.5, 1.0]], speed = 0.0 }"#,
            "obstacles[0].motion",
            "`speed`: expected a positive speed",
        ),
        (
            r#"{ kind = "waypoints", points = [], speed = 0.1 }"#,
            "obstacles[0].motion",
            "`points`",
        ),
        (
            r#"{ kind = "walker", goals = [[1.0, 1.0]], speed = nan }"#,
            "obstacles[0].motion",
            "`speed`",
        ),
        (
            r#"{ kind = "waypoints", points = [[1.5, 1.0]], speed = 0.1, repeat = "bounce" }"#,
            "repeat",
            "loop",
        ),
        (r#"{ kind = "teleport" }"#, "kind", "waypoints"),
    ] {
        let e = aisle_with(motion).expect_err(motion);
        assert!(
            e.contains(key) && e.contains(expected),
            "{motion}: {e} (expected `{key}` and `{expected}`)"
        );
    }
}

/// A mover faster than the robot can flee: Theorem 3 does not apply, with the numbers.
#[test]
fn check_refuses_the_guarantee_for_a_mover_faster_than_the_robot() {
    let fast = aisle_with(
        r#"{ kind = "waypoints", points = [[1.5, 1.0]], speed = 0.5, repeat = "reverse" }"#,
    )
    .expect("valid");
    let r = check_world(&fast).expect("checks");
    assert!(!r.verdict.applies);
    assert!(
        r.verdict
            .reasons
            .iter()
            .any(|s| s.contains("0.500 m/s") && s.contains("v_max = 0.220")),
        "{:?}",
        r.verdict.reasons
    );
    let slow = check_world(&world("tests/worlds_movers/aisle_crossing.toml")).expect("checks");
    assert!(slow.verdict.applies, "{:?}", slow.verdict.reasons);
}

/// Liveness: a cart that crosses and goes on is waited for; one that stops on the path blocks
/// the robot for good, and the run agrees.
#[test]
fn a_mover_that_parks_on_the_path_blocks_for_good_and_one_that_passes_is_waited_for() {
    let passes = check_world(&world("tests/worlds_movers/aisle_crossing.toml"))
        .expect("checks")
        .liveness;
    assert!(passes.live(), "{}", passes.line());
    assert!(
        passes.line().contains("wait for mover `cart`"),
        "{}",
        passes.line()
    );
    let parks = aisle_with(
        r#"{ kind = "waypoints", points = [[1.5, 0.0]], speed = 0.1, repeat = "once" }"#,
    )
    .expect("valid");
    let l = check_world(&parks).expect("checks").liveness;
    assert!(!l.live(), "{}", l.line());
    assert!(l.line().contains("blocked for good"), "{}", l.line());
    let s = run(&parks, &opts(1, ControllerKindSpec::FtCbfClf)).expect("runs");
    assert!(s.safe, "{s}");
    assert!(
        !s.goal_reached,
        "reached the goal through a parked cart: {s}"
    );
}
