//! A planner that tells (issue #47, item 4): with no route that keeps the rows' clearance,
//! `check` says so, names the narrowest gap and the two obstacles that make it; with another,
//! wider gap the plan takes it instead of the one the robot cannot pass.

use std::path::Path;

use ftcbf_sim::model::setup::{planned_path, route_notes};
use ftcbf_sim::world::structure::obstacle_barrier_config;
use ftcbf_sim::world::World;

/// A burger at (0, 0) heading for (3, 0) among box walls (name, x0, x1, y0, y1) 0.6 m high.
fn world(walls: &[(&str, f64, f64, f64, f64)]) -> World {
    let mut text = String::from(
        r#"name = "gap"
duration = 20.0
seed = 1
robot = { urdf = "../../robots/turtlebot3_burger.urdf", start = { x = 0.0, y = 0.0, theta = 0.0 } }
goal = { center = [3.0, 0.0], radius = 0.15 }
sensors = [{ name = "a_x", measures = "x", noise_std = 0.03 }, { name = "a_y", measures = "y", noise_std = 0.03 },
  { name = "b_x", measures = "x", noise_std = 0.03 }, { name = "b_y", measures = "y", noise_std = 0.03 },
  { name = "odom", measures = "speed", noise_std = 0.01 }, { name = "compass", measures = "heading", noise_std = 0.01 }]
fault_patterns = [{ name = "a", channels = ["a_x", "a_y"] }, { name = "b", channels = ["b_x", "b_y"] }]
"#,
    );
    for (name, x0, x1, y0, y1) in walls {
        text.push_str(&format!(
            "[[obstacles]]\nname = \"{name}\"\nposition = [{}, {}, 0.3]\nshape = {{ kind = \"cuboid\", half_extents = [{}, {}, 0.3] }}\n",
            0.5 * (x0 + x1),
            0.5 * (y0 + y1),
            0.5 * (x1 - x0),
            0.5 * (y1 - y0)
        ));
    }
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/worlds_map");
    World::from_str(&text, &dir.join("gap.toml"), &[]).unwrap()
}

/// Where the path crosses x = 1.5 (the wall's line).
fn crossings(start: [f64; 2], pts: &[[f64; 2]]) -> Vec<f64> {
    let mut out = Vec::new();
    let mut a = start;
    for &b in pts {
        if (a[0] - 1.5) * (b[0] - 1.5) <= 0.0 && a[0] != b[0] {
            let t = (1.5 - a[0]) / (b[0] - a[0]);
            out.push(a[1] + t * (b[1] - a[1]));
        }
        a = b;
    }
    out
}

#[test]
fn with_no_route_check_names_the_narrowest_gap_and_the_obstacles_that_make_it() {
    // a room x ∈ [−1, 1.6], y ∈ [−1, 1] whose only way out is a 0.4 m gap in its east wall
    let w = world(&[
        ("west", -1.2, -1.0, -1.2, 1.2),
        ("top", -1.0, 1.6, 1.0, 1.2),
        ("bottom", -1.0, 1.6, -1.2, -1.0),
        ("south", 1.4, 1.6, -1.0, -0.2),
        ("north", 1.4, 1.6, 0.2, 1.0),
    ]);
    let notes = route_notes(&w);
    assert_eq!(notes.len(), 1, "{notes:?}");
    let n = &notes[0];
    assert!(
        n.starts_with("no route from (0.00, 0.00) to (3.00, 0.00) with clearance"),
        "{n}"
    );
    assert!(n.contains("gaps narrower than"), "{n}");
    // the narrowest point of the widest route is in the gap, between its two posts
    assert!(
        n.contains("between north and south") || n.contains("between south and north"),
        "{n}"
    );
    let at = n.split("closest at (").nth(1).unwrap();
    let xy: Vec<f64> = at
        .split(')')
        .next()
        .unwrap()
        .split(", ")
        .map(|v| v.parse().unwrap())
        .collect();
    assert!(
        (xy[0] - 1.5).abs() <= 0.11 && xy[1].abs() <= 0.05,
        "{xy:?} in {n}"
    );
    // the width it names is 2 (r + clearance): the burger's footprint radius and the clearance
    let bcfg = obstacle_barrier_config(&w);
    // the number the message prints after `label`
    let number_after = |label: &str| -> f64 {
        let rest = n
            .split(label)
            .nth(1)
            .unwrap_or_else(|| panic!("no {label:?} in {n}"));
        rest.split(' ').next().unwrap().parse().unwrap()
    };
    let clearance = number_after("with clearance ");
    let width = number_after("gaps narrower than ");
    assert!(
        (width - 2.0 * (bcfg.robot_radius + clearance)).abs() < 0.006,
        "{n}"
    );
    assert!(width > 0.4, "the 0.4 m gap must be impassable: {n}");
}

#[test]
fn the_plan_takes_a_wider_gap_rather_than_one_the_robot_cannot_pass() {
    // a wall x ∈ [1.4, 1.6] with the 0.4 m gap at y ∈ [−0.2, 0.2] and a 1 m one at
    // y ∈ [1.5, 2.5]; beyond y = ±5 it is closed by walls back to x = −1
    let w = world(&[
        ("south", 1.4, 1.6, -5.0, -0.2),
        ("post", 1.4, 1.6, 0.2, 1.5),
        ("north", 1.4, 1.6, 2.5, 5.0),
        ("top", -1.0, 1.6, 5.0, 5.2),
        ("bottom", -1.0, 1.6, -5.2, -5.0),
        ("west", -1.2, -1.0, -5.2, 5.2),
    ]);
    assert!(route_notes(&w).is_empty(), "{:?}", route_notes(&w));
    let bcfg = obstacle_barrier_config(&w);
    let path = planned_path(&w, &bcfg, [0.0, 0.0], 0.0).unwrap();
    assert_eq!(*path.last().unwrap(), [3.0, 0.0]);
    let cross = crossings([0.0, 0.0], &path);
    assert_eq!(cross.len(), 1, "{path:?}");
    // through the 1 m gap y ∈ [1.5, 2.5], clear of both posts by the footprint at least
    let y = cross[0];
    let r = bcfg.robot_radius;
    assert!(y > 1.5 + r && y < 2.5 - r, "crosses at y = {y}: {path:?}");
}
