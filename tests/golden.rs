//! Golden outputs: every catalogue world's run summary (three controllers) and a small batch
//! JSON, captured before the runner became a steppable `Simulation`. A refactoring of the loop
//! must reproduce them bit for bit. The comparison is "golden ⊆ actual": every key of the golden
//! JSON must be present with exactly the same value (floats compared through their round-trip
//! representation), so a colleague adding a new summary field does not invalidate the goldens,
//! while any change to an existing number does.
//!
//! Regenerate (only when behaviour is changed on purpose, and say so in the commit):
//! `ftcbf run worlds/W.toml --controller C --no-record --json > tests/golden/W.C.json` and
//! `ftcbf batch worlds/paper_linear.toml --trials 8 --seed 3 -j 1 --out tests/golden/batch_paper_linear.json`.

use std::path::{Path, PathBuf};
use std::process::Command;

use ftcbf_sim::runner::{run, RunOptions};
use ftcbf_sim::world::{ControllerKindSpec, World};
use serde_json::Value;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn golden(name: &str) -> Value {
    let path = root().join("tests/golden").join(name);
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Every key of `want` is in `got` with the same value; returns the first difference's path.
fn contained(want: &Value, got: &Value, at: &str) -> Result<(), String> {
    match (want, got) {
        (Value::Object(w), Value::Object(g)) => w.iter().try_for_each(|(k, v)| match g.get(k) {
            Some(gv) => contained(v, gv, &format!("{at}.{k}")),
            None => Err(format!("{at}.{k}: missing")),
        }),
        (Value::Array(w), Value::Array(g)) if w.len() == g.len() => w
            .iter()
            .zip(g)
            .enumerate()
            .try_for_each(|(i, (a, b))| contained(a, b, &format!("{at}[{i}]"))),
        _ if want == got => Ok(()),
        _ => Err(format!("{at}: golden {want}, now {got}")),
    }
}

const CONTROLLERS: [(ControllerKindSpec, &str); 3] = [
    (ControllerKindSpec::FtCbfClf, "ft-cbf-clf"),
    (ControllerKindSpec::Baseline, "baseline"),
    (ControllerKindSpec::Nominal, "nominal"),
];

fn world_files() -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(root().join("worlds"))
        .expect("worlds/ is readable")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    v.sort();
    v
}

fn check_world(path: &Path) -> Vec<String> {
    let stem = path.file_stem().expect("a file name").to_string_lossy();
    let world = World::load(path, &[]).unwrap_or_else(|e| panic!("{e}"));
    let mut diffs = Vec::new();
    for (kind, name) in CONTROLLERS {
        let file = format!("{stem}.{name}.json");
        if !root().join("tests/golden").join(&file).exists() {
            diffs.push(format!("{file}: no golden (a new world? capture it)"));
            continue;
        }
        let opts = RunOptions {
            controller: Some(kind),
            ..RunOptions::default()
        };
        let summary = run(&world, &opts).unwrap_or_else(|e| panic!("{e}"));
        let got = serde_json::to_value(&summary).expect("serialises");
        if let Err(d) = contained(&golden(&file), &got, &file) {
            diffs.push(d);
        }
    }
    diffs
}

#[test]
fn every_catalogue_summary_matches_its_golden_bit_for_bit() {
    let files = world_files();
    assert!(files.len() >= 9, "the catalogue has at least nine worlds");
    let diffs: Vec<String> = files.iter().flat_map(|p| check_world(p)).collect();
    assert!(diffs.is_empty(), "summaries changed:\n{}", diffs.join("\n"));
}

#[test]
fn batch_json_matches_its_golden_bit_for_bit() {
    let dir = std::env::temp_dir().join(format!("ftcbf-golden-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let out = dir.join("batch.json");
    let o = Command::new(env!("CARGO_BIN_EXE_ftcbf"))
        .args([
            "batch",
            "worlds/paper_linear.toml",
            "--trials",
            "8",
            "--seed",
            "3",
        ])
        .args(["-j", "1", "--out"])
        .arg(&out)
        .current_dir(root())
        .output()
        .expect("the binary runs");
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let text = std::fs::read_to_string(&out).expect("batch JSON written");
    let got: Value = serde_json::from_str(&text).expect("valid JSON");
    let want = golden("batch_paper_linear.json");
    if let Err(d) = contained(&want, &got, "batch") {
        panic!("batch JSON changed: {d}");
    }
    std::fs::remove_dir_all(&dir).ok();
}
