//! Obstacles that move (issue #51): the world file's `motion`, the physics moving them, the
//! time-varying rows keeping the robot off them, collisions counted by who moved, reruns bit
//! for bit, and what `check` says (escape, liveness: waits vs blocked for good).

use std::path::{Path, PathBuf};

use ftcbf_sim::analysis::check::{check_world, Status};
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

/// `tests/worlds_movers/aisle_crossing.toml` with one more obstacle, a thin crate standing at
/// `x` beside the cart's aisle (x = 1.5, radius 0.15).
fn aisle_with_crate(x: f64) -> World {
    let path = root().join("tests/worlds_movers/aisle_crossing.toml");
    let text = std::fs::read_to_string(&path).expect("readable");
    let text = text.replacen(
        "[[obstacles]]",
        &format!(
            "[[obstacles]]\nname = \"crate\"\nposition = [{x}, 0.0, 0.2]\nshape = {{ kind = \"cuboid\", half_extents = [0.05, 0.3, 0.2] }}\n\n[[obstacles]]"
        ),
        1,
    );
    World::from_str(&text, Path::new(&path), &[]).unwrap_or_else(|e| panic!("{e}"))
}

fn finding<'a>(
    r: &'a ftcbf_sim::analysis::check::CheckReport,
    name: &str,
) -> (ftcbf_sim::analysis::check::Status, &'a str) {
    r.hypotheses
        .iter()
        .find(|h| h.name == name)
        .map(|h| (h.status, h.detail.as_str()))
        .unwrap_or_else(|| panic!("no hypothesis `{name}`"))
}

/// A mover that passes a static obstacle closer than the robot's width can pin the robot
/// there (two barriers at once): check says the guarantee does not apply, with the gap; with
/// the obstacle far enough, the finding holds.
#[test]
fn check_says_a_mover_passing_an_obstacle_closer_than_the_robot_is_wide_voids_the_guarantee() {
    let name = "`cart` cannot pin the robot against a static obstacle";
    // The crate's face at x = 1.75, the cart's side at 1.65: a 0.100 m gap.
    let near = check_world(&aisle_with_crate(1.8)).expect("checks");
    let (status, detail) = finding(&near, name);
    assert_eq!(status, Status::Fails, "{detail}");
    assert!(detail.contains("passes 0.100 m from `crate`"), "{detail}");
    assert!(!near.verdict.applies);
    // The face at 2.45: a 0.800 m gap, wider than 2(r + margin).
    let far = check_world(&aisle_with_crate(2.5)).expect("checks");
    let (status, detail) = finding(&far, name);
    assert_eq!(status, Status::Holds, "{detail}");
}

/// The mover's lift is raised so that a robot stopped on its boundary turns a quarter turn
/// and pulls away before the mover reaches it: k_m = max(k, t_turn + v_o/(2a) − margin/v_o).
#[test]
fn a_movers_lift_covers_the_quarter_turn_of_a_stopped_robot() {
    use ftcbf_sim::model::setup::{mover_lift, quarter_turn_time};
    let w = world("tests/worlds_movers/aisle_crossing.toml");
    let bcfg = ftcbf_sim::world::structure::obstacle_barrier_config(&w);
    let t = quarter_turn_time(&w).expect("a robot");
    let omega = w.robot.as_ref().expect("a robot").limits.omega_max;
    assert!(t >= std::f64::consts::FRAC_PI_2 / omega - 1e-12, "{t}");
    let cart = &w.obstacles[0].spec;
    let k = mover_lift(&w, cart, &bcfg);
    let v = 0.1;
    let a = w.brake_deceleration();
    let want = bcfg.k.max(t + v / (2.0 * a) - bcfg.margin / v);
    assert!((k - want).abs() < 1e-12, "k_m = {k}, expected {want}");
    assert!(k > bcfg.k, "k_m = {k} did not rise above k = {}", bcfg.k);
    // Stopped at d = margin + k_m·v, the robot turns and pulls away within that room.
    assert!(v * t + v * v / (2.0 * a) <= bcfg.margin + k * v + 1e-12);
    let r = check_world(&w).expect("checks");
    let (status, detail) = finding(&r, "the drive turns away from `cart` in time");
    assert_eq!(status, Status::Holds, "{detail}");
}

/// A cart shuttling over a short stretch of the path leaves it free too briefly to cross:
/// liveness says the robot waits for good, and the run does not settle.
#[test]
fn a_mover_that_keeps_coming_back_over_the_path_blocks_it() {
    let path = root().join("tests/worlds_movers/aisle_crossing.toml");
    let text = std::fs::read_to_string(&path).expect("readable");
    let motion = text
        .lines()
        .find(|l| l.starts_with("motion ="))
        .expect("the cart moves");
    let text = text
        .replace("position = [1.5, -1.0, 0.2]", "position = [1.5, -0.45, 0.2]")
        .replace(
            motion,
            r#"motion = { kind = "waypoints", points = [[1.5, 0.45]], speed = 0.1, repeat = "reverse" }"#,
        );
    let shuttle = World::from_str(&text, Path::new(&path), &[]).unwrap_or_else(|e| panic!("{e}"));
    let l = check_world(&shuttle).expect("checks").liveness;
    assert!(!l.live(), "{}", l.line());
    assert!(l.line().contains("keeps coming back"), "{}", l.line());
    let s = run(&shuttle, &opts(1, ControllerKindSpec::FtCbfClf)).expect("runs");
    assert!(!s.goal_settled, "settled through a shuttling cart: {s}");
}

/// A trolley pacing the far half of a ward corridor (written by hand, not generated): the
/// robot could stand beside it where h ≥ h̄, but the trolley's lift makes its rows' robustness
/// term large, and the rows hold the robot at rest farther out, running at it farther still;
/// with that room `check` finds no way past (the search along h̄ alone had predicted live), and
/// the run does not settle (none of 200 trials did).
#[test]
fn a_trolley_pacing_a_corridor_holds_the_robot_out_by_the_rows_not_by_h_bar() {
    let ward = world("tests/worlds_movers/ward_trolley.toml");
    let l = check_world(&ward).expect("checks").liveness;
    assert!(!l.live(), "{}", l.line());
    assert!(
        l.line().contains("`trolley` keeps coming back"),
        "{}",
        l.line()
    );
    let s = run(&ward, &opts(5103, ControllerKindSpec::FtCbfClf)).expect("runs");
    assert!(!s.goal_settled, "settled past the trolley: {s}");
}

/// Every frame carries each mover's state: the cart (0.1 m/s up its aisle from y = −1) is
/// displaced by (0, 0.1·t) at t ≤ 20 s, and the scene names it.
#[test]
fn frames_carry_the_movers_where_the_script_puts_them() {
    use ftcbf_sim::runner::Simulation;
    let w = world("tests/worlds_movers/aisle_crossing.toml");
    let mut sim = Simulation::new(&w, &opts(1, ControllerKindSpec::FtCbfClf)).expect("builds");
    assert_eq!(sim.scene().movers, vec!["cart".to_string()]);
    let mut seen = 0;
    while let Some(f) = sim.step() {
        if f.t > 20.0 {
            break;
        }
        assert_eq!(f.movers.len(), 1);
        let d = f.movers[0].displacement;
        assert!(
            d[0].abs() < 1e-12 && (d[1] - 0.1 * f.t).abs() < 1e-9,
            "t = {}: {d:?}",
            f.t
        );
        seen += 1;
    }
    assert!(seen > 900, "{seen} frames");
}

/// Every contact a run's frames carry, with who moved.
fn contacts_of(
    w: &World,
    controller: ControllerKindSpec,
) -> Vec<(ftcbf_sim::observe::Contact, Vec<String>)> {
    use ftcbf_sim::runner::Simulation;
    let mut sim = Simulation::new(w, &opts(1, controller)).expect("builds");
    let mut out = Vec::new();
    while let Some(f) = sim.step() {
        for c in f.contacts {
            out.push((c.clone(), f.events.to_vec()));
        }
    }
    out
}

/// Contacts are marked by who moved: the nominal controller driving across the aisle meets
/// the cart while moving (the robot's); a robot holding its goal at its start, which the cart
/// drives into, is hit while stopped (the mover's). Both are named in the event text, and the
/// run's counts agree.
#[test]
fn contacts_are_marked_by_who_moved() {
    use ftcbf_sim::observe::ContactCause;
    let w = world("tests/worlds_movers/aisle_crossing.toml");
    let moving = contacts_of(&w, ControllerKindSpec::Nominal);
    let (first, events) = moving.first().expect("the nominal robot meets the cart");
    assert_eq!(first.obstacle, "cart");
    assert_eq!(first.cause, ContactCause::RobotMoving);
    assert_eq!(first.cause.whose(), "robot");
    assert!(
        events
            .iter()
            .any(|e| e.starts_with("collision with cart") && e.ends_with("the robot's")),
        "{events:?}"
    );
    // The cart at the robot's start, coming at it along x at 0.1 m/s; the goal is the start.
    let path = root().join("tests/worlds_movers/aisle_crossing.toml");
    let text = std::fs::read_to_string(&path)
        .expect("readable")
        .replace("center = [3.0, 0.0]", "center = [0.0, 0.0]")
        .replace("position = [1.5, -1.0, 0.2]", "position = [1.0, 0.0, 0.2]");
    let line = text
        .lines()
        .find(|l| l.starts_with("motion ="))
        .expect("moves");
    let text = text.replace(
        line,
        "motion = { kind = \"velocity\", velocity = [-0.1, 0.0] }",
    );
    let still = World::from_str(&text, Path::new(&path), &[]).unwrap_or_else(|e| panic!("{e}"));
    let hit = contacts_of(&still, ControllerKindSpec::Nominal);
    let (first, events) = hit.first().expect("the cart reaches the robot");
    assert_eq!(
        first.cause,
        ContactCause::MoverIntoStopped { walker: false }
    );
    assert_eq!(first.cause.whose(), "mover");
    // The robot still at its start; the cart's 0.15 m body meets the burger's collision
    // shapes, inside its footprint circle (0.1237 m) and short of its centre: the cart's
    // centre between 0.274 m and 0.15 m off, so between t = 7.26 s and 8.5 s.
    assert!(
        first.at[0].abs() < 0.02 && first.at[1].abs() < 0.02,
        "{:?}",
        first.at
    );
    assert!((7.26..8.5).contains(&first.t), "t = {}", first.t);
    assert!(
        events
            .iter()
            .any(|e| e.contains("walked into the stopped robot")),
        "{events:?}"
    );
    let s = run(&still, &opts(1, ControllerKindSpec::Nominal)).expect("runs");
    assert!(
        s.collisions.mover_robot_stopped >= 1 && s.collisions.mover_robot_moving == 0,
        "{s}"
    );
}
