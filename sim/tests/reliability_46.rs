//! Issue #46, items 1, 2 and 5, in the library: never SAFE next to the run's own contradiction
//! (a mesh's winding decided its inside), no unbounded planning or URDF loading, and three inputs
//! that were accepted though wrong. `tests/reliability_46.rs` (the root package) has what the
//! `ftcbf` binary prints and its exit codes.

use std::path::{Path, PathBuf};

use ftcbf_sim::analysis::check::{check_world, Status};
use ftcbf_sim::runner::{preflight, run, RunOptions};
use ftcbf_sim::summary::{disagree, DISAGREEMENT_TOLERANCE};
use ftcbf_sim::world::World;
use nalgebra::Vector3;

#[path = "../../tests/common/mesh.rs"]
mod mesh;
use mesh::{cube, stl_text};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the workspace root")
        .to_path_buf()
}

/// A path named `name` in a per-process temporary directory.
fn tmp_in(tag: &str, name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("ftcbf-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&d).expect("temp dir");
    d.join(name)
}

fn catalogue(file: &str) -> (PathBuf, String) {
    let p = root().join("worlds").join(file);
    let t = std::fs::read_to_string(&p).expect("catalogue world");
    (p, t)
}

fn inward(t: &[[u32; 3]]) -> Vec<[u32; 3]> {
    t.iter().map(|x| [x[0], x[2], x[1]]).collect()
}

fn list<T: std::fmt::Debug>(items: &[T]) -> String {
    let parts: Vec<String> = items
        .iter()
        .map(|x| format!("{x:?}").replace('(', "[").replace(')', "]"))
        .collect();
    format!("[{}]", parts.join(", "))
}

fn write_stl(path: &Path, v: &[[f64; 3]], t: &[[u32; 3]]) {
    std::fs::write(path, stl_text("cube", v, t)).expect("STL written");
}

/// doorway_clutter with one more obstacle `mesh` (the TOML shape given).
fn with_mesh(shape: &str) -> World {
    let (p, t) = catalogue("doorway_clutter.toml");
    let extra =
        format!("\n[[obstacles]]\nname = \"mesh\"\nposition = [0.0, 0.0, 0.0]\nshape = {shape}\n");
    let t = t.replacen("\n[[sensors]]", &format!("{extra}\n[[sensors]]"), 1);
    World::from_str(&t, &p, &[]).unwrap_or_else(|e| panic!("{e}"))
}

/// The mesh's signed distance from the robot's start (at the barrier's height) \[m\].
fn start_distance(w: &World) -> f64 {
    let o = w.obstacles.iter().find(|o| o.name == "mesh").expect("mesh");
    o.signed_distance(Vector3::new(0.0, 0.0, 0.1))
}

fn start_hypothesis(w: &World) -> (Status, String) {
    let r = check_world(w).expect("check runs");
    let h = r
        .hypotheses
        .iter()
        .find(|h| h.name.starts_with("start inside every safe set"))
        .expect("the start hypothesis");
    (h.status, h.detail.clone())
}

/// Item 1 (a): a closed mesh 0.6 m behind the start, inline and from an STL file, wound
/// outward and inward, and the same points as a convex hull: the same signed distance at the
/// start (within 1e-5 m: parry's f32), `check` finds the start inside the safe set for all, and
/// short runs report the same smallest h within 1e-6.
#[test]
fn a_closed_meshs_inside_does_not_depend_on_its_winding() {
    let (v, t) = cube([-0.75, 0.0, 0.15], 0.15);
    let inline = |t: &[[u32; 3]]| {
        format!(
            "{{ kind = \"tri_mesh\", vertices = {}, indices = {} }}",
            list(&v),
            list(t)
        )
    };
    let stl = tmp_in("rel46", "cube_inward.stl");
    write_stl(&stl, &v, &inward(&t));
    let worlds = [
        ("inline outward", with_mesh(&inline(&t))),
        ("inline inward", with_mesh(&inline(&inward(&t)))),
        (
            "STL inward",
            with_mesh(&format!(
                "{{ kind = \"tri_mesh\", file = \"{}\" }}",
                stl.display()
            )),
        ),
        (
            "convex hull",
            with_mesh(&format!(
                "{{ kind = \"convex_hull\", points = {} }}",
                list(&v)
            )),
        ),
    ];
    let reference = start_distance(&worlds[0].1);
    // 0.6 m from the cube's face at x = -0.6.
    assert!((reference - 0.6).abs() < 1e-5, "{reference}");
    let opts = RunOptions {
        duration: Some(0.5),
        ..RunOptions::default()
    };
    let mut min_h = Vec::new();
    for (what, w) in &worlds {
        let d = start_distance(w);
        assert!((d - reference).abs() < 1e-5, "{what}: {d} vs {reference}");
        let o = w.obstacles.iter().find(|o| o.name == "mesh").expect("mesh");
        assert_eq!(o.note, None, "{what}: a closed mesh has no note");
        let (status, detail) = start_hypothesis(w);
        assert_eq!(status, Status::Holds, "{what}: {detail}");
        let s = run(w, &opts).expect("runs");
        assert_eq!(s.disagreement, None, "{what}");
        let h = s
            .min_barrier
            .iter()
            .find(|b| b.name == "obstacle:mesh")
            .expect("the mesh's barrier")
            .value;
        assert!(h > 0.3, "{what}: min h = {h}");
        min_h.push(h);
    }
    for h in &min_h {
        assert!((h - min_h[0]).abs() < 1e-6, "{min_h:?}");
    }
}

/// Item 1 (a): an open mesh (one triangle missing) is a surface: its distance is never negative,
/// and `check` warns, naming it.
#[test]
fn an_open_mesh_is_unsigned_and_named_in_a_warning() {
    let (v, mut t) = cube([-0.75, 0.0, 0.15], 0.15);
    t.pop();
    let w = with_mesh(&format!(
        "{{ kind = \"tri_mesh\", vertices = {}, indices = {} }}",
        list(&v),
        list(&t)
    ));
    let o = w.obstacles.iter().find(|o| o.name == "mesh").expect("mesh");
    let note = o.note.clone().expect("an open mesh has a note");
    assert!(
        note.contains("obstacle `mesh`") && note.contains("not a closed surface"),
        "{note}"
    );
    assert!(
        note.contains("1 edge(s) on one triangle only") || note.contains("edge(s)"),
        "{note}"
    );
    // The cube's centre is 0.15 m from every face: unsigned, so +0.15, not −0.15.
    let d = o.signed_distance(Vector3::new(-0.75, 0.0, 0.15));
    assert!((d - 0.15).abs() < 1e-5, "{d}");
    let r = check_world(&w).expect("check runs");
    let shown = r.to_string();
    assert!(
        shown.contains("warning: obstacle `mesh`: tri_mesh is not a closed surface"),
        "{shown}"
    );
}

/// Item 1 (b): a robot that starts inside a closed mesh box (clear of its faces): the barrier
/// has its centre inside while the physics, which sees a mesh as a surface, measures clearance.
/// The run has no verdict (never SAFE); `tests/reliability_46.rs` has `ftcbf run`'s exit 1.
#[test]
fn a_run_whose_barrier_and_physics_disagree_has_no_verdict() {
    let (v, t) = cube([0.0, 0.0, 0.2], 0.5);
    let shape = format!(
        "{{ kind = \"tri_mesh\", vertices = {}, indices = {} }}",
        list(&v),
        list(&inward(&t))
    );
    let w = with_mesh(&shape);
    let (status, detail) = start_hypothesis(&w);
    assert_eq!(status, Status::Fails, "{detail}");
    assert!(detail.contains("obstacle:mesh"), "{detail}");
    let s = run(
        &w,
        &RunOptions {
            duration: Some(0.5),
            ..RunOptions::default()
        },
    )
    .expect("runs");
    assert!(!s.safe);
    let d = s.disagreement.clone().expect("a disagreement");
    assert_eq!(d.obstacle, "mesh");
    assert!(d.centre_distance < -0.3, "{d:?}");
    assert!(d.physics_clearance > DISAGREEMENT_TOLERANCE, "{d:?}");
    let shown = s.to_string();
    assert!(shown.contains("safety:    NO VERDICT"), "{shown}");
    assert!(!shown.contains("SAFE\n"), "{shown}");
}

/// Item 1 (b): the consistency rule itself.
#[test]
fn the_consistency_rule_flags_opposite_signs_beyond_its_tolerance() {
    let tol = DISAGREEMENT_TOLERANCE;
    // The run: centre inside by the barrier (h −0.71), clearance 0.509 by the physics.
    assert!(disagree(-0.5, -0.6, 0.509));
    // The disc clear, the colliders 2 cm into the obstacle.
    assert!(disagree(0.3, 0.2, -0.02));
    // Agreement: both clear, both in contact, or either within the tolerance of 0.
    assert!(!disagree(0.4, 0.3, 0.35));
    assert!(!disagree(-0.2, -0.3, -0.01));
    assert!(!disagree(-0.5 * tol, -0.1, 0.3));
    assert!(!disagree(-0.3, -0.4, 0.5 * tol));
    assert!(!disagree(0.2, 0.5 * tol, -0.3));
    // The disc overlaps (centre outside) while the body is clear: a footprint, not a contradiction.
    assert!(!disagree(0.05, -0.05, 0.02));
    // A lifted barrier below 0 with clearance is not compared here: the rule reads distances.
}

/// doorway_clutter with its obstacles replaced by `obstacles` and `[goal]` given `waypoints`.
fn doorway_with(obstacles: Option<&str>, waypoints: &str) -> World {
    let (p, t) = catalogue("doorway_clutter.toml");
    let mut t = t.replacen("[goal]\n", &format!("[goal]\nwaypoints = {waypoints}\n"), 1);
    if let Some(o) = obstacles {
        let a = t.find("# The wall at x = 1.2").expect("the walls");
        let b = t.find("\n[[sensors]]").expect("the sensors");
        t.replace_range(a..b, o);
    }
    World::from_str(&t, &p, &[]).unwrap_or_else(|e| panic!("{e}"))
}

/// Either the world is accepted, or refused with the planner's limit named at a goal key.
fn finishes_or_names_the_limit(w: &World) -> Option<String> {
    match preflight(w) {
        Ok(()) => {
            check_world(w).expect("check runs");
            None
        }
        Err(e) => {
            let m = e.to_string();
            assert!(
                m.contains("`goal.waypoints[") || m.contains("`goal.center`"),
                "{m}"
            );
            assert!(
                m.contains("obstacle distance queries, the planner's limit"),
                "{m}"
            );
            assert!(e.is_invalid_world(), "{m}");
            Some(m)
        }
    }
}

/// Item 2: one waypoint at (1e4, 1e4) behind one obstacle on the diagonal. The leg's grid has
/// 4·10¹⁰ cells; the planner stops at its budget and names the waypoint and the limit.
#[test]
fn a_waypoint_at_the_range_edge_ends_with_the_planners_limit() {
    let ball = "[[obstacles]]\nname = \"ball\"\nposition = [1.0, 1.0, 0.2]\nshape = { kind = \"ball\", radius = 0.3 }\n";
    let w = doorway_with(Some(ball), "[[10000.0, 10000.0]]");
    let m = finishes_or_names_the_limit(&w).expect("over the limit");
    assert!(m.contains("`goal.waypoints[0]`"), "{m}");
    assert!(m.contains("200000 obstacle distance queries"), "{m}");
}

/// Item 2: waypoints at ±5000 m on doorway_clutter, and the 256-waypoint cap within ±50 m:
/// a result or the limit, named.
#[test]
fn far_and_many_waypoints_end_with_a_plan_or_the_limit() {
    let w = doorway_with(None, "[[5000.0, 5000.0], [-5000.0, -5000.0]]");
    finishes_or_names_the_limit(&w);
    // 256 points of a fixed pseudo-random sequence within ±50 m (a linear congruence).
    let mut x: u64 = 46;
    let mut next = || {
        x = x
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((x >> 11) as f64 / (1u64 << 53) as f64) * 100.0 - 50.0
    };
    let pts: Vec<String> = (0..256)
        .map(|_| format!("[{:.3}, {:.3}]", next(), next()))
        .collect();
    let w = doorway_with(None, &format!("[{}]", pts.join(", ")));
    finishes_or_names_the_limit(&w);
}

/// Item 2: a URDF with a 50,000-link chain of fixed joints loads (in linear time: the link,
/// joint and material names are checked in a hash map) and merges into the base's body.
#[test]
fn a_50000_link_fixed_chain_loads_into_one_body() {
    let urdf =
        std::fs::read_to_string(root().join("robots/turtlebot3_burger.urdf")).expect("the burger");
    let n = 50_000;
    let mut chain = String::with_capacity(n * 200);
    for i in 0..n {
        let parent = if i == 0 {
            "base_link".to_string()
        } else {
            format!("chain_{}", i - 1)
        };
        chain.push_str(&format!(
            "<link name=\"chain_{i}\"/>\n<joint name=\"chain_joint_{i}\" type=\"fixed\"><parent link=\"{parent}\"/><child link=\"chain_{i}\"/><origin xyz=\"0 0 0.0001\"/></joint>\n"
        ));
    }
    let urdf = urdf.replacen("</robot>", &format!("{chain}</robot>"), 1);
    let path = tmp_in("rel46", "chain.urdf");
    std::fs::write(&path, urdf).expect("URDF written");
    let (p, t) = catalogue("doorway_clutter.toml");
    let t = t.replacen(
        "urdf = \"../robots/turtlebot3_burger.urdf\"",
        &format!("urdf = \"{}\"", path.display()),
        1,
    );
    let w = World::from_str(&t, &p, &[]).unwrap_or_else(|e| panic!("{e}"));
    let robot = w.robot.as_ref().expect("a robot");
    let base = robot.body_of_link("chain_49999").expect("the chain's end");
    assert_eq!(base, robot.body_of_link("base_link").expect("base"));
    let chain = robot.bodies[base]
        .links
        .iter()
        .filter(|l| l.starts_with("chain_"))
        .count();
    assert_eq!(chain, n, "every chain link in the base's body");
    preflight(&w).expect("the world runs");
}

/// Item 5: `from_wheels` with three entries is refused, naming the key and that exactly two,
/// [left, right], are expected.
#[test]
fn from_wheels_with_three_entries_is_refused() {
    let (p, t) = catalogue("turtlebot_encoders.toml");
    let t = t.replacen(
        "from_wheels = [\"enc_left\", \"enc_right\"]",
        "from_wheels = [\"enc_left\", \"enc_right\", \"enc_left\"]",
        1,
    );
    let e = World::from_str(&t, &p, &[])
        .expect_err("refused")
        .to_string();
    assert!(e.contains("from_wheels"), "{e}");
    assert!(e.contains("sensors["), "{e}");
    assert!(
        e.contains("expected exactly two wheel channel names, [left, right]; got 3"),
        "{e}"
    );
}

/// Item 5: a replay recorded from before the run (`record_start = -1`) is refused, naming the
/// key and the range.
#[test]
fn a_replay_recorded_before_the_run_is_refused() {
    let (p, t) = catalogue("field_replay.toml");
    let t = t.replacen("record_start = 0.0", "record_start = -1.0", 1);
    let e = World::from_str(&t, &p, &[])
        .expect_err("refused")
        .to_string();
    assert!(e.contains("`record_start` = -1"), "{e}");
    assert!(
        e.contains("expected a time in [0, start - length] s"),
        "{e}"
    );
}

/// Item 5: a waypoint outside the floor's safe set is refused by `check` and `run` alike, naming
/// the waypoint, the set and h — not moved to the boundary without a word while `check` said
/// "Theorem 3 applies" (`tests/reliability_46.rs` has the CLI's exit 2).
#[test]
fn a_waypoint_outside_the_floors_safe_set_is_refused() {
    let (p, t) = catalogue("paper_turtlebot_sf.toml");
    // The floor is y + 0.2·ẏ + 0.05 ≥ 0: at rest, y = −1 has h = −0.95.
    let t = t.replacen("[goal]\n", "[goal]\nwaypoints = [[1.0, -1.0]]\n", 1);
    let w = World::from_str(&t, &p, &[]).unwrap_or_else(|e| panic!("{e}"));
    let e = preflight(&w).expect_err("refused").to_string();
    assert!(e.contains("`goal.waypoints[0]`"), "{e}");
    assert!(e.contains("outside safe set `floor`"), "{e}");
    assert!(e.contains("h = -0.95"), "{e}");
    assert!(check_world(&w).is_err(), "check refuses it too");
    // Inside the set (h = 0.45 at rest) it is accepted.
    let ok = t.replace("[[1.0, -1.0]]", "[[1.0, 0.4]]");
    let w = World::from_str(&ok, &p, &[]).unwrap_or_else(|e| panic!("{e}"));
    preflight(&w).expect("a waypoint inside the floor is accepted");
}
