//! Nothing in the repository points outside it (issue #49, item 12): no absolute path of one
//! machine (a home folder, a scratch folder), no folder next to the clone, and no
//! document that is not in the repository (a design note, the thesis as a local file). A reader
//! with a clone and nothing else can follow every reference; the thesis is cited by its public
//! reference (book/src/theory/thesis.md).

use std::path::Path;
use std::process::Command;

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

/// The forbidden fragments, each with what it is. Written in two halves so that this file does
/// not match itself.
fn forbidden() -> Vec<(String, &'static str)> {
    [
        (["/ho", "me/"], "a home folder of one machine"),
        (["/Us", "ers/"], "a home folder of one machine"),
        (["/ro", "ot/"], "the root user's home folder"),
        (["/wo", "rk/"], "a scratch folder of one machine"),
        (["../sha", "red"], "a folder next to the clone"),
        (
            ["DESIGN", ".md"],
            "a design note that is not in the repository",
        ),
        (
            ["ft-cbf-thesis", ".md"],
            "the thesis as a local file (cite it by its reference)",
        ),
    ]
    .into_iter()
    .map(|(parts, what)| (parts.concat(), what))
    .collect()
}

fn tracked_files() -> Vec<String> {
    let out = Command::new("git")
        .args(["ls-files", "-z"])
        .current_dir(ROOT)
        .output()
        .expect("git runs (the test lists the tracked files with `git ls-files`)");
    assert!(
        out.status.success(),
        "git ls-files failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout)
        .expect("file names are UTF-8")
        .split('\0')
        .filter(|s| !s.is_empty())
        .map(str::to_string)
        .collect()
}

#[test]
fn no_tracked_file_points_outside_the_repository() {
    let files = tracked_files();
    assert!(files.len() > 100, "git lists the repository: {files:?}");
    let patterns = forbidden();
    let mut found = Vec::new();
    let mut read = 0;
    for f in &files {
        // Text files only (images, binary fixtures are skipped); a file that is listed but
        // deleted in the work tree is skipped too.
        let Ok(text) = std::fs::read_to_string(Path::new(ROOT).join(f)) else {
            continue;
        };
        read += 1;
        for (i, line) in text.lines().enumerate() {
            for (p, what) in &patterns {
                if line.contains(p.as_str()) {
                    found.push(format!("{f}:{}: `{p}` ({what}): {}", i + 1, line.trim()));
                }
            }
        }
    }
    assert!(read > 100, "only {read} text files read");
    assert!(
        found.is_empty(),
        "references outside the repository:\n{}",
        found.join("\n")
    );
}

#[test]
fn the_check_finds_each_kind_of_outside_path() {
    // The patterns above catch what issue #49 found, written as it was found.
    let samples = [
        "(`/wo\u{72}k/shared/paper/ft-cbf-thesi\u{73}.md`, §4.1–4.3)",
        "What differs from `../sha\u{72}ed/DESI\u{47}N.md`:",
        "package_paths = [\"/ho\u{6d}e/me/ros2_ws/src\"]",
        "//! The closed loop (DESI\u{47}N.md, \"Data flow\")",
    ];
    for s in samples {
        assert!(
            forbidden().iter().any(|(p, _)| s.contains(p.as_str())),
            "not caught: {s}"
        );
    }
    assert!(
        !forbidden()
            .iter()
            .any(|(p, _)| "package_paths = [\"../ros2_ws/src\"]".contains(p.as_str())),
        "a relative path inside a world is allowed"
    );
}
