//! The world catalogue is the regression suite: every world under worlds/ with an [expect]
//! table must meet it over its regression seeds, through the same library call as
//! `ftcbf regress`.

mod common;

use std::path::PathBuf;

use ftcbf_lab::regress::Plan;
use ftcbf_sim::analysis::expectations::collect_world_files;

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
        "quickstart",
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
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("worlds");
    let plan = Plan::load(&[dir]).unwrap_or_else(|e| panic!("{e}"));
    assert!(
        plan.skipped.is_empty(),
        "worlds without [expect]: {:?}",
        plan.skipped
    );
    // Every world judged over several seeds, with at least one numeric margin per case.
    for c in &plan.cases {
        assert!(
            c.seeds.len() >= 4,
            "{}: only {} seed(s)",
            c.world.world().name,
            c.seeds.len()
        );
        assert!(
            !c.expected.margins.is_empty(),
            "{} / {:?}: no numeric margin",
            c.world.world().name,
            c.controller
        );
    }
    assert!(plan.cases.len() >= 17, "only {} cases", plan.cases.len());
    common::assert_plan_passes(&plan);
}
