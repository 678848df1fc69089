//! `ftcbf gen --map` (issue #47 item 6): worlds drawn on an occupancy map — the office fixture
//! tests/worlds_map/office.yaml — are the same for the same seed, reference the map instead of
//! listing obstacles, have every start/goal pair reachable by the project's planner with the
//! generator's spare, and load and `check` as any world file does.

use std::path::{Path, PathBuf};

use ftcbf_sim::analysis::check::check_world;
use ftcbf_sim::world::World;
use ftcbf_sim::worldgen::{
    generate, reach, write_worlds, GenConfig, GenError, Kind, PAIR_DISTANCE, SPARE,
};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn out_dir(tag: &str) -> PathBuf {
    std::env::temp_dir().join(format!("ftcbf-gen-map-{}-{tag}", std::process::id()))
}

fn config(tag: &str) -> GenConfig {
    GenConfig {
        seed: 47,
        kind: None,
        robot: None,
        suite: None,
        robots_dir: root().join("robots"),
        out_dir: out_dir(tag),
        map: Some(root().join("tests/worlds_map/office.yaml")),
    }
}

#[test]
fn worlds_drawn_on_a_map_repeat_reach_their_goals_and_check() {
    let a = generate(&config("a"), 4).unwrap_or_else(|e| panic!("{e}"));
    // A sibling directory: the same relative map and robot paths, so the same text.
    let b = generate(&config("b"), 4).unwrap_or_else(|e| panic!("{e}"));
    for (x, y) in a.iter().zip(&b) {
        assert_eq!(x.text, y.text, "{}", x.file_name);
    }
    let pairs: std::collections::BTreeSet<String> = a
        .iter()
        .map(|w| format!("{:?}", w.reach.path.last()))
        .collect();
    assert!(pairs.len() > 1, "every world has the same goal: {pairs:?}");
    let paths = write_worlds(&out_dir("a"), &a).unwrap_or_else(|e| panic!("{e}"));
    for (w, path) in a.iter().zip(&paths) {
        assert_eq!(w.kind, Kind::Map);
        // The map by its path relative to the output directory.
        assert!(
            w.text.contains("[environment]\nmap = \"")
                && w.text.contains("tests/worlds_map/office.yaml\""),
            "{}",
            w.text
        );
        assert!(!w.text.contains("[[obstacles]]"), "{}", w.text);
        assert!(w.text.contains("--map "), "{}", w.text);
        let world = World::load(path, &[]).unwrap_or_else(|e| panic!("{e}"));
        assert!(world.obstacles.iter().any(|o| o.map_field().is_some()));
        let r = world.file.robot.as_ref().unwrap().start;
        let g = world.file.goal.center;
        let d = (g[0] - r.x).hypot(g[1] - r.y);
        assert!(
            d >= PAIR_DISTANCE.0 && d <= PAIR_DISTANCE.1,
            "{}: {d} m apart",
            w.file_name
        );
        // Reachable as the loaded file says, with the generator's spare.
        let route = reach(&world, SPARE)
            .expect("a robot")
            .unwrap_or_else(|e| panic!("{}: {e}", w.file_name));
        assert!(route.path_clearance >= SPARE && route.length >= d - 1e-9);
        let report = check_world(&world).unwrap_or_else(|e| panic!("{}: {e}", w.file_name));
        assert!(report.liveness.path_length > 0.0, "{}", w.file_name);
    }
    let _ = std::fs::remove_dir_all(out_dir("a"));
    let _ = std::fs::remove_dir_all(out_dir("b"));
}

#[test]
fn a_kind_with_a_map_and_a_map_without_room_are_refused_naming_the_map() {
    let cfg = GenConfig {
        kind: Some(Kind::Room),
        ..config("kind")
    };
    match generate(&cfg, 1) {
        Err(e @ GenError::Map { .. }) => {
            let s = e.to_string();
            assert!(s.contains("office.yaml") && s.contains("--kind"), "{s}");
        }
        other => panic!("expected a map error, got {other:?}"),
    }
    // A map whose image is missing: the loader's error, under the map's name.
    let cfg = GenConfig {
        map: Some(root().join("tests/worlds_map/missing_image.yaml")),
        ..config("missing")
    };
    match generate(&cfg, 1) {
        Err(e @ GenError::Map { .. }) => {
            let s = e.to_string();
            assert!(
                s.contains("missing_image.yaml") && s.contains("image"),
                "{s}"
            );
        }
        other => panic!("expected a map error, got {other:?}"),
    }
    let _ = std::fs::remove_dir_all(out_dir("kind"));
    let _ = std::fs::remove_dir_all(out_dir("missing"));
}
