//! Robots and the threat model through the `ftcbf` binary, as a user meets them: `check` prints
//! the wheel grouping of a skid-steer robot, `run`/`regress`/`batch` flag attacks that together
//! span two fault patterns, and `batch --fail-on` exits 4.

use std::path::PathBuf;

mod common;
use common::{ftcbf, text};

fn tmp(name: &str) -> PathBuf {
    common::tmp_in("robots-cli", name)
}

const SKID: &str = "tests/worlds_ros/skid_steer_pillars.toml";
const TWO: &str = "tests/worlds_threat/two_pattern_attack.toml";

#[test]
fn check_prints_the_skid_steer_grouping_and_track_width() {
    let o = ftcbf(&["check", SKID]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let t = text(&o);
    assert!(
        t.contains(
            "drive: skid steer, 4 wheels: left [`front_left_wheel_joint`, `rear_left_wheel_joint`], \
             right [`front_right_wheel_joint`, `rear_right_wheel_joint`]"
        ) && t.contains("effective track width 0.2600 m"),
        "{t}"
    );
    // The TurtleBot3 is a differential drive.
    let o = ftcbf(&["check", "worlds/paper_turtlebot.toml"]);
    let t = text(&o);
    assert!(
        t.contains("drive: differential, left `wheel_left_joint`, right `wheel_right_joint`; track width 0.1600 m"),
        "{t}"
    );
}

#[test]
fn run_and_regress_flag_attacks_that_together_span_two_patterns() {
    let o = ftcbf(&["run", TWO, "--no-record", "--json"]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON on stdout");
    assert_eq!(v["attacks_outside_fault_patterns"], true, "{v}");
    assert_eq!(v["attacks_together_outside_fault_patterns"], true, "{v}");
    // Each attack alone is inside one pattern.
    for w in v["attack_windows"].as_array().expect("windows") {
        assert_eq!(w["outside_fault_patterns"], false, "{w}");
    }
    let o = ftcbf(&["run", TWO, "--no-record"]);
    assert!(
        text(&o)
            .contains("attacks together: their channels lie in no single declared fault pattern"),
        "{}",
        text(&o)
    );
    // A world whose attack stays inside one pattern is not flagged.
    let o = ftcbf(&[
        "run",
        "worlds/paper_turtlebot.toml",
        "--no-record",
        "--json",
    ]);
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON on stdout");
    assert_eq!(v["attacks_outside_fault_patterns"], false);
    assert_eq!(v["attacks_together_outside_fault_patterns"], false);

    let o = ftcbf(&["regress", TWO]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(
        text(&o).contains("pass (outside the fault model: no guarantee applies)"),
        "{}",
        text(&o)
    );
}

#[test]
fn batch_marks_a_two_pattern_world_as_outside_the_model() {
    let out = tmp("two.json");
    let o = ftcbf(&[
        "batch",
        TWO,
        "--trials",
        "2",
        "--jobs",
        "1",
        "--controller",
        "ft-cbf-clf",
        "--out",
        out.to_str().expect("utf-8"),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(
        text(&o).contains("(*) some attacks lie outside the declared fault patterns"),
        "{}",
        text(&o)
    );
    let v: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&out).expect("written")).expect("JSON");
    assert_eq!(
        v["results"][0]["summaries"][0]["outside_fault_pattern_trials"], 2,
        "{v:.600}"
    );
}

#[test]
fn batch_fail_on_exits_4_after_writing_its_outputs() {
    // 6 trials can support no claim of 0.95 (the Clopper–Pearson lower bound of 6/6 is 0.54).
    let out = tmp("fail-on.json");
    let args = |level: &'static str| {
        vec![
            "batch",
            "worlds/paper_linear.toml",
            "--trials",
            "6",
            "--jobs",
            "1",
            "--controller",
            "ft-cbf-clf",
            "--fail-on",
            level,
        ]
    };
    let o = ftcbf(&args("refuted"));
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let mut a = args("unresolved");
    a.extend(["--out", out.to_str().expect("utf-8")]);
    let o = ftcbf(&a);
    assert_eq!(o.status.code(), Some(4), "{}", text(&o));
    let t = text(&o);
    assert!(
        t.contains("1 verdict(s) matched --fail-on unresolved")
            && t.contains("ft-cbf-clf: unresolved at this N"),
        "{t}"
    );
    assert!(out.is_file(), "the JSON is written before failing");
    // --help documents the level and the exit code.
    let o = ftcbf(&["batch", "--help"]);
    let t = text(&o);
    assert!(
        t.contains("--fail-on <LEVEL>") && t.contains("4 a verdict matched --fail-on"),
        "{t}"
    );
    // A world file that does not parse exits 2, as for the other commands.
    let bad = tmp("bad.toml");
    std::fs::write(&bad, "name = 3\n").expect("write");
    let o = ftcbf(&["batch", bad.to_str().expect("utf-8"), "--trials", "1"]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
}

#[test]
fn check_names_the_fixed_wheel_promotion_and_falsify_rebases_package_folders() {
    // `check` says which fixed joints are driven as wheels and what mass their hubs got.
    let o = ftcbf(&["check", "tests/worlds_ros/pioneer_fixed_wheels_block.toml"]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let t = text(&o);
    assert!(
        t.contains("joint `left_hub_joint` (line 98) is `fixed` in the URDF; [robot] wheels names it")
            && t.contains("wheel link `left_hub` has no <inertial>")
            && t.contains("drive: differential, left `left_hub_joint`, right `right_hub_joint`; track width 0.3200 m"),
        "{t}"
    );
    // A world written elsewhere by `falsify` keeps `[robot] packages` pointing at the folder.
    let out = tmp("qbot2e-worst.toml");
    let o = ftcbf(&[
        "falsify",
        "tests/worlds_ros/qbot2e_style_pillars.toml",
        "--budget",
        "24",
        "--jobs",
        "1",
        "--no-random",
        "--no-record",
        "--out",
        out.to_str().expect("utf-8"),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let written = std::fs::read_to_string(&out).expect("written");
    assert!(written.contains("ftcbf_qbot2e = "), "{written}");
    let o = ftcbf(&["check", out.to_str().expect("utf-8")]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(
        text(&o).contains("drive: differential, left `base_wheel_l_joint`"),
        "{}",
        text(&o)
    );
}
