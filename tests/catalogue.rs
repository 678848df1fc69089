//! The world catalogue is the regression suite: every world under worlds/ with an [expect]
//! table must meet it, through the same library call as `ftcbf regress`.

use std::path::PathBuf;

use ftcbf_sim::regress::{check_file, collect_world_files};

fn worlds() -> Vec<PathBuf> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("worlds");
    collect_world_files(&[dir]).expect("worlds/ is readable")
}

#[test]
fn catalogue_holds_the_required_scenarios() {
    let names: Vec<String> = worlds()
        .iter()
        .filter_map(|p| p.file_stem().map(|s| s.to_string_lossy().into_owned()))
        .collect();
    for required in [
        "paper_linear",
        "paper_turtlebot",
        "corridor_spoof",
        "field_replay",
        "elliptic_arena_drift",
        "three_gnss",
        "stealthy_gnss",
        "outside_model",
        "waffle_pillars",
    ] {
        assert!(
            names.iter().any(|n| n == required),
            "worlds/{required}.toml is missing"
        );
    }
}

#[test]
fn every_world_meets_its_expectations() {
    let mut failures = Vec::new();
    let mut runs = 0;
    for path in worlds() {
        let rows = check_file(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        assert!(!rows.is_empty(), "{}: no [expect] table", path.display());
        for row in rows {
            runs += 1;
            if !row.passed() {
                failures.push(format!(
                    "{} / {}: {}",
                    row.world,
                    row.summary.controller,
                    row.failures.join("; ")
                ));
            }
        }
    }
    assert!(runs >= 15, "only {runs} regression runs");
    assert!(
        failures.is_empty(),
        "{} failed:\n{}",
        failures.len(),
        failures.join("\n")
    );
}
