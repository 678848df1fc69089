//! Issue #46, items 1 and 5, as the `ftcbf` binary shows them: a run whose barrier and physics
//! disagree has no verdict and exits 1; a waypoint outside the floor's safe set is refused by
//! `check` and `run` with exit 2. `sim/tests/reliability_46.rs` has the library's side (mesh
//! winding, the consistency rule, the planner's and the URDF loader's bounds, item 5's keys).

mod common;
use common::{ftcbf, root, text, tmp_in};

/// A cube's 8 corners (half-size `h`, centred on `c`) and its 12 triangles wound inward.
fn inward_cube(c: [f64; 3], h: f64) -> String {
    let v: Vec<String> = (0..8)
        .map(|i| {
            let s = |b: usize| if i & b != 0 { h } else { -h };
            format!("[{}, {}, {}]", c[0] + s(1), c[1] + s(2), c[2] + s(4))
        })
        .collect();
    let t = "[[0, 1, 2], [1, 3, 2], [4, 6, 5], [5, 6, 7], [0, 4, 1], [1, 4, 5], [2, 3, 6], [3, 7, 6], [0, 2, 4], [2, 6, 4], [1, 5, 3], [3, 5, 7]]";
    format!(
        "{{ kind = \"tri_mesh\", vertices = [{}], indices = {t} }}",
        v.join(", ")
    )
}

/// A catalogue world with its robot's URDF path made absolute, `edit` applied, written to a
/// temporary file.
fn written(file: &str, name: &str, edit: &dyn Fn(String) -> String) -> String {
    let base = std::fs::read_to_string(root().join("worlds").join(file)).expect("catalogue");
    let t = base.replace(
        "urdf = \"../robots/",
        &format!("urdf = \"{}/robots/", root().display()),
    );
    let path = tmp_in("rel46-cli", name);
    std::fs::write(&path, edit(t)).expect("world written");
    path.display().to_string()
}

/// Item 1 (b): the robot starts inside a closed mesh box, clear of its faces: the barrier has
/// its centre inside, the physics (a mesh is a surface to it) measures clearance. `run` prints
/// NO VERDICT with both numbers and exits 1, never "safety: SAFE".
#[test]
fn run_exits_1_without_a_verdict_when_barrier_and_physics_disagree() {
    let f = written("doorway_clutter.toml", "inside_mesh.toml", &|t| {
        t.replacen(
            "\n[[sensors]]",
            &format!(
                "\n[[obstacles]]\nname = \"mesh\"\nposition = [0.0, 0.0, 0.0]\nshape = {}\n\n[[sensors]]",
                inward_cube([0.0, 0.0, 0.2], 0.5)
            ),
            1,
        )
    });
    let o = ftcbf(&["run", &f, "--no-record", "--duration", "0.5"]);
    let out = text(&o);
    assert_eq!(o.status.code(), Some(1), "{out}");
    assert!(out.contains("safety:    NO VERDICT"), "{out}");
    assert!(out.contains("disagreement: at t = "), "{out}");
    assert!(out.contains("no safety verdict"), "{out}");
    assert!(out.contains("obstacle `mesh`"), "{out}");
    assert!(!out.contains("safety:    SAFE"), "{out}");
}

/// Item 5: a waypoint below the floor (h = −0.95 at rest) is refused by `check` and `run` with
/// exit 2, naming `goal.waypoints[0]`; neither says "Theorem 3 applies".
#[test]
fn a_waypoint_outside_the_floor_exits_2_for_check_and_run() {
    let f = written(
        "paper_turtlebot_sf.toml",
        "waypoint_below_floor.toml",
        &|t| t.replacen("[goal]\n", "[goal]\nwaypoints = [[1.0, -1.0]]\n", 1),
    );
    for args in [
        vec!["check", f.as_str()],
        vec!["run", f.as_str(), "--no-record"],
    ] {
        let o = ftcbf(&args);
        let out = text(&o);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {out}");
        assert!(out.contains("goal.waypoints[0]"), "{args:?}: {out}");
        assert!(out.contains("outside safe set `floor`"), "{args:?}: {out}");
        assert!(!out.contains("Theorem 3 applies"), "{args:?}: {out}");
    }
}
