//! The CLI campaign of issue #46 (`scripts/cli_campaign.py`) in its CI size: seeded mutated
//! worlds, URDFs, shards, results folders and flags against the built binary, each with a time
//! bound. It must find no panic or abort, no hang, no SAFE or "Theorem 3 applies" next to a
//! negative barrier, NaN or inf, and at least 95 % of the error messages must name the file or
//! the flag and what was expected (the script's classifier). `FTCBF_CAMPAIGN_N` (default 60)
//! and `FTCBF_CAMPAIGN_SEED` (default 46) change the size and the seed; the book's Testing page
//! gives the last full run.

use std::process::Command;

#[test]
fn the_cli_campaign_finds_no_panic_hang_or_unplaced_error() {
    let n = std::env::var("FTCBF_CAMPAIGN_N").unwrap_or_else(|_| "60".into());
    let seed = std::env::var("FTCBF_CAMPAIGN_SEED").unwrap_or_else(|_| "46".into());
    let root = env!("CARGO_MANIFEST_DIR");
    let o = Command::new("python3")
        .arg(format!("{root}/scripts/cli_campaign.py"))
        .args([
            "--bin",
            env!("CARGO_BIN_EXE_ftcbf"),
            "--n",
            &n,
            "--seed",
            &seed,
        ])
        .args(["--timeout", "120", "--show-bad", "50"])
        .output()
        .expect("python3 runs the campaign script");
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{out}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let counts: serde_json::Value = out
        .lines()
        .find_map(|l| l.strip_prefix("COUNTS "))
        .and_then(|j| serde_json::from_str(j).ok())
        .unwrap_or_else(|| panic!("a COUNTS line: {out}"));
    let get = |k: &str| {
        counts[k]
            .as_f64()
            .unwrap_or_else(|| panic!("{k} in {counts}"))
    };
    assert_eq!(get("invocations"), n.parse::<f64>().expect("N"), "{out}");
    for k in ["panics", "hangs", "safe_negative", "safe_nonfinite"] {
        assert_eq!(get(k), 0.0, "{k}: {out}");
    }
    assert!(get("errors") > 0.0, "the campaign provokes errors: {out}");
    assert!(get("good_fraction") >= 0.95, "{out}");
}
