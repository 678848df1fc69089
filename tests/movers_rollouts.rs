//! Liveness with movers decided by runs of the closed loop (issue #51): where the search past
//! the movers finds no way but the robot gets past, and where it does not get past, `check`'s
//! verdict is the runs', and the runs are `ftcbf batch`'s trials at the seed it prints.

mod common;

use ftcbf_lab::trials::check_rolled_out;
use ftcbf_sim::analysis::check::check_compiled;
use ftcbf_sim::analysis::liveness::rollout::{Rollouts, ROLLOUTS, ROLLOUT_SALT};
use ftcbf_sim::runner::CompiledWorld;
use ftcbf_sim::world::World;
use ftcbf_sim::worldgen::{generate, write_worlds, GenConfig, Kind};

/// `ftcbf batch PATH --controller KIND --seed SEED --trials N` at the rollouts' controller,
/// base seed and count: how many trials settled in the goal.
fn batch_settled(path: &str, r: &Rollouts, out: &std::path::Path) -> u64 {
    let (seed, n) = (r.base_seed, r.runs);
    let o = common::ftcbf(&[
        "batch",
        path,
        "--controller",
        r.controller,
        "--seed",
        &seed.to_string(),
        "--trials",
        &n.to_string(),
        "--out",
        out.to_str().expect("utf-8 path"),
    ]);
    assert!(o.status.success(), "{}", common::text(&o));
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out).expect("batch wrote its JSON"))
            .expect("JSON");
    v["results"][0]["summaries"][0]["settled"]
        .as_u64()
        .expect("a settled count")
}

fn rollouts(c: &CompiledWorld) -> (bool, String, Rollouts) {
    let l = check_rolled_out(c, ROLLOUTS).liveness;
    let r = l
        .rollouts
        .clone()
        .expect("a world with movers is rolled out");
    (l.live(), l.line(), r)
}

/// gen51_008 (`ftcbf gen --seed 51 --count 56 --kind dqn_loops`): a looper that jitters
/// between two points 4 cm apart just off the burger's path. The search past the movers finds
/// no way by it (it keeps to a band beside the path), but the robot goes round it: 20 of 20
/// trials of `scripts/movers_sweep.sh 51` settle, and 16 of 16 at the rollouts' seed. The
/// runs decide: live. And `tests/worlds_movers/ward_trolley.toml`, where the trolley pacing the
/// corridor holds the robot out (0 of 200 settle): the runs say NOT live, as the search does.
#[test]
fn runs_of_the_closed_loop_decide_liveness_where_movers_are() {
    let out = common::tmp_in("movers-rollouts", "gen");
    let cfg = GenConfig {
        seed: 51,
        kind: Some(Kind::DqnLoops),
        robot: None,
        suite: None,
        robots_dir: common::root().join("robots"),
        out_dir: out.clone(),
        map: None,
    };
    let generated = generate(&cfg, 56).unwrap_or_else(|e| panic!("{e}"));
    let paths = write_worlds(&out, &generated).unwrap_or_else(|e| panic!("{e}"));
    let path = paths
        .iter()
        .find(|p| p.ends_with("gen51_008_dqn_loops.toml"))
        .expect("seed 51 generates gen51_008_dqn_loops");
    let looper = CompiledWorld::new(World::load(path, &[]).unwrap_or_else(|e| panic!("{e}")))
        .unwrap_or_else(|e| panic!("{e}"));

    // the search alone: blocked for good by the looper
    let search = check_compiled(&looper).liveness;
    assert!(!search.live(), "{}", search.line());
    assert!(search.rollouts.is_none());
    assert!(search.line().contains("obstacle1"), "{}", search.line());

    // the runs: every one settles, so live, and the line still says what the search found
    let (live, line, r) = rollouts(&looper);
    assert!(live, "{line}");
    assert_eq!(
        (r.settled, r.runs, r.first_miss),
        (ROLLOUTS, ROLLOUTS, None)
    );
    assert_eq!(r.base_seed, looper.world().file.seed ^ ROLLOUT_SALT);
    assert!(
        line.contains("6 of 6 runs of the closed loop settled")
            && line.contains("the search past the movers finds no way"),
        "{line}"
    );
    // `--rollouts 0`: the search's verdict, unchanged
    assert_eq!(check_rolled_out(&looper, 0).liveness, search);

    let ward_path = "tests/worlds_movers/ward_trolley.toml";
    let ward = CompiledWorld::new(
        World::load(&common::root().join(ward_path), &[]).unwrap_or_else(|e| panic!("{e}")),
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let (live, line, w) = rollouts(&ward);
    assert!(!live, "{line}");
    assert_eq!(w.settled, 0, "{line}");
    let (seed, _) = w.first_miss.expect("a run that did not settle");
    assert!(
        line.contains("may NOT settle in its goal with the movers: 0 of 6 runs")
            && line.contains(&format!("--seed {seed}")),
        "{line}"
    );

    // the commands the line prints replay the runs
    let path = path.to_str().expect("utf-8 path");
    let json = common::tmp_in("movers-rollouts", "looper.json");
    assert_eq!(batch_settled(path, &r, &json), 6);
    let json = common::tmp_in("movers-rollouts", "ward.json");
    assert_eq!(batch_settled(ward_path, &w, &json), 0);
    let _ = std::fs::remove_dir_all(out.parent().expect("a temp dir"));
}
