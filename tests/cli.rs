//! The `ftcbf` binary as a user drives it: exit codes, JSON, recordings, checks, regressions,
//! and batches with the real closed-loop runner.

use std::path::{Path, PathBuf};

mod common;
use common::{ftcbf, root, text};

fn tmp(name: &str) -> PathBuf {
    common::tmp_in("cli", name)
}

#[test]
fn run_meets_expectations_and_prints_json() {
    let o = ftcbf(&["run", "worlds/paper_linear.toml", "--no-record", "--json"]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON on stdout");
    assert_eq!(v["safe"], true);
    assert_eq!(v["goal_reached"], true);
    assert_eq!(v["controller"], "ft-cbf-clf");
    // The baseline's expectation is to violate; meeting it exits 0 too.
    let o = ftcbf(&[
        "run",
        "worlds/paper_linear.toml",
        "--no-record",
        "--controller",
        "baseline",
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(text(&o).contains("UNSAFE"), "{}", text(&o));
}

#[test]
fn failed_expectation_exits_3_and_says_why() {
    // Without the attack the baseline stays safe, so "expect.baseline.safe = false" fails.
    let o = ftcbf(&[
        "run",
        "worlds/paper_linear.toml",
        "--no-record",
        "--controller",
        "baseline",
        "--set",
        "attacks[0].value=0",
    ]);
    assert_eq!(o.status.code(), Some(3), "{}", text(&o));
    assert!(text(&o).contains("expected safe = false"), "{}", text(&o));
}

#[test]
fn invalid_world_exits_2_naming_file_and_key() {
    let o = ftcbf(&["run", "tests/invalid_worlds/negative_rate.toml"]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    let t = text(&o);
    assert!(
        t.contains("negative_rate.toml") && t.contains("control.rate_hz"),
        "{t}"
    );
    // A malformed --set is a usage error (64), not an invalid world.
    let o = ftcbf(&["run", "worlds/paper_linear.toml", "--set", "nonsense"]);
    assert_eq!(o.status.code(), Some(64), "{}", text(&o));
    assert!(text(&o).contains("KEY=NUMBER"), "{}", text(&o));
}

#[test]
fn run_writes_a_rerun_recording() {
    let out = tmp("paper_turtlebot.rrd");
    let o = ftcbf(&[
        "run",
        "worlds/paper_turtlebot.toml",
        "--duration",
        "2",
        "--out",
        out.to_str().expect("utf-8"),
    ]);
    // A 2 s run does not reach the goal: the expectation fails (exit 3) but the file is written.
    assert_eq!(o.status.code(), Some(3), "{}", text(&o));
    let bytes = std::fs::read(&out).expect("recording written");
    assert!(bytes.len() > 10_000, "only {} bytes", bytes.len());
    assert_eq!(&bytes[..4], b"RRF2", "rerun .rrd magic");
}

#[test]
fn check_prints_parameters_and_conditions() {
    let o = ftcbf(&["check", "worlds/paper_linear.toml"]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let t = text(&o);
    for needle in [
        "gamma_1",
        "theta_ij",
        "h̄_γ(floor)",
        "Lemma 1",
        "HOLDS",
        "fault pattern r2 = {y4_y}",
        "[FAILS  ] condition 1 under the input limit for floor",
        "verdict: Theorem 3 does NOT apply",
    ] {
        assert!(t.contains(needle), "missing {needle:?} in\n{t}");
    }
}

/// Two receivers as the fault patterns and no velocity sensor: the pair filter keeps no channel.
const NO_POSITION_FIX: &str = r#"
name = "two_receivers_no_odometry"
duration = 10.0
[robot]
urdf = "URDF"
start = { x = 1.0, y = 0.0, theta = 3.14159265 }
[control]
input_limit = 0.5
[goal]
center = [0.0, 0.0]
radius = 0.1
[[safe_sets]]
kind = "half_plane"
name = "floor"
a = [0.0, 1.0, 0.0, 0.2]
b = -0.05
[[sensors]]
name = "gnss1_x"
measures = "x"
noise_std = 0.02
[[sensors]]
name = "gnss1_y"
measures = "y"
noise_std = 0.02
[[sensors]]
name = "gnss2_x"
measures = "x"
noise_std = 0.02
[[sensors]]
name = "gnss2_y"
measures = "y"
noise_std = 0.02
[[sensors]]
name = "compass"
measures = "heading"
noise_std = 0.0
[[fault_patterns]]
name = "gnss1"
channels = ["gnss1_x", "gnss1_y"]
[[fault_patterns]]
name = "gnss2"
channels = ["gnss2_x", "gnss2_y"]
"#;

#[test]
fn check_strict_refuses_a_pair_filter_without_any_fix() {
    let urdf = root().join("robots").join("turtlebot3_burger.urdf");
    let path = tmp("no_position_fix.toml");
    std::fs::write(
        &path,
        NO_POSITION_FIX.replace("URDF", &urdf.to_string_lossy()),
    )
    .expect("fixture world");
    let p = path.to_string_lossy().into_owned();
    let lax = ftcbf(&["check", &p]);
    let strict = ftcbf(&["check", "--strict", &p]);
    assert_eq!(lax.status.code(), Some(0), "{}", text(&lax));
    let t = text(&lax);
    assert!(t.contains("verdict: Theorem 3 does NOT apply"), "{t}");
    assert!(
        t.contains("x̂_12 (drops gnss1 ∪ gnss2) keeps no channel at all"),
        "{t}"
    );
    assert!(t.contains("no position and no velocity fix"), "{t}");
    assert_eq!(strict.status.code(), Some(4), "{}", text(&strict));
    assert!(text(&strict).contains("--strict"), "{}", text(&strict));
    // A world where it applies passes --strict.
    let ok = ftcbf(&["check", "--strict", "worlds/paper_turtlebot_receivers.toml"]);
    assert_eq!(ok.status.code(), Some(0), "{}", text(&ok));
}

#[test]
fn regress_runs_paired_cases() {
    let o = ftcbf(&[
        "regress",
        "worlds/paper_linear.toml",
        "worlds/outside_model.toml",
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(
        text(&o).contains("3 case(s), 24 run(s), 0 failed"),
        "{}",
        text(&o)
    );
}

#[test]
fn every_command_has_help_with_an_example() {
    for cmd in ["run", "check", "regress", "batch", "merge", "gen"] {
        let o = ftcbf(&[cmd, "--help"]);
        assert_eq!(o.status.code(), Some(0), "{cmd}");
        assert!(
            text(&o).contains("Example"),
            "`ftcbf {cmd} --help` has no example"
        );
    }
}

fn batch_json(args: &[&str], out: &Path) -> serde_json::Value {
    let mut a = vec![
        "batch",
        "worlds/paper_linear.toml",
        "--trials",
        "6",
        "--out",
    ];
    a.push(out.to_str().expect("utf-8"));
    a.extend_from_slice(args);
    let o = ftcbf(&a);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    serde_json::from_slice(&std::fs::read(out).expect("written")).expect("JSON")
}

#[test]
fn batch_is_independent_of_jobs_and_shards_merge_exactly() {
    let j1 = batch_json(&["--jobs", "1"], &tmp("j1.json"));
    let j2 = batch_json(&["--jobs", "2"], &tmp("j2.json"));
    assert_eq!(j1, j2, "--jobs must not change results");
    let s1 = tmp("s1.json");
    let s2 = tmp("s2.json");
    batch_json(&["--shard", "1/2"], &s1);
    batch_json(&["--shard", "2/2"], &s2);
    let merged = tmp("merged.json");
    let o = ftcbf(&[
        "merge",
        s1.to_str().expect("utf-8"),
        s2.to_str().expect("utf-8"),
        "--out",
        merged.to_str().expect("utf-8"),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let m: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&merged).expect("written")).expect("JSON");
    assert_eq!(m, j1, "merged shards must equal the unsharded batch");
}

#[test]
fn a_batch_trial_reruns_alone_with_its_seed() {
    let v = batch_json(&["--controller", "ft-cbf-clf"], &tmp("seeds.json"));
    let text_all = v.to_string();
    // Take the first trial record's seed and final state from the JSON, re-run it alone.
    let rec = &v["results"][0]["records"][2];
    let seed = rec["seed"]
        .as_u64()
        .unwrap_or_else(|| panic!("no seed in {text_all:.400}"));
    let o = ftcbf(&[
        "run",
        "worlds/paper_linear.toml",
        "--no-record",
        "--json",
        "--seed",
        &seed.to_string(),
    ]);
    let s: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON");
    assert_eq!(s["safe"], rec["safe"]);
    assert_eq!(s["time_to_goal"], rec["time_to_goal"]);
    assert_eq!(s["min_barrier"][0]["value"], rec["min_barrier"]);
}
