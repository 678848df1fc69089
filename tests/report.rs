//! `ftcbf report` on the repository's own results (issue #33): the committed pages are exactly
//! what the stored JSON renders to, `--check` fails naming a page that was edited by hand or a
//! figure no page uses, and `ftcbf report` puts both right.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).expect("mkdir");
    for e in std::fs::read_dir(from).expect("list") {
        let e = e.expect("entry");
        let target = to.join(e.file_name());
        if e.path().is_dir() {
            copy_dir(&e.path(), &target);
        } else {
            std::fs::copy(e.path(), &target).expect("copy");
        }
    }
}

/// A scratch repository root (one per test: they run in parallel) holding copies of `results/` and `book/src/results/`.
fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&dir);
    copy_dir(&Path::new(ROOT).join("results"), &dir.join("results"));
    copy_dir(
        &Path::new(ROOT).join("book/src/results"),
        &dir.join("book/src/results"),
    );
    dir
}

fn report(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_ftcbf"))
        .arg("report")
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run ftcbf report")
}

#[test]
fn the_committed_results_pages_are_what_the_stored_json_renders() {
    let dir = scratch("report-ok");
    let out = report(&dir, &["--check"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn check_names_an_edited_page_and_a_stray_figure_and_report_puts_them_right() {
    let dir = scratch("report-edited");
    let page = dir.join("book/src/results/catalogue.md");
    let text = std::fs::read_to_string(&page).expect("catalogue page");
    // an edit by hand (whatever the trial counts the pages were measured at)
    std::fs::write(&page, format!("{text}\nedited by hand\n")).expect("edit");
    let stray = dir.join("book/src/results/figures/old_world.svg");
    std::fs::write(&stray, "<svg/>").expect("stray figure");

    let out = report(&dir, &["--check"]);
    assert_eq!(out.status.code(), Some(1), "an edited page fails --check");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("catalogue.md"), "names the page: {err}");
    assert!(
        err.contains("old_world.svg"),
        "names the stray figure: {err}"
    );
    assert!(
        !err.contains("falsify.md"),
        "does not name a page that is fine: {err}"
    );

    let out = report(&dir, &[]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(
        std::fs::read_to_string(&page).expect("page"),
        text,
        "report writes the page back"
    );
    assert!(!stray.exists(), "report removes the figure no page uses");
    assert!(report(&dir, &["--check"]).status.success());
}

#[test]
fn a_json_file_the_stamp_lists_but_that_is_missing_is_an_error_naming_it() {
    let dir = scratch("report-missing");
    std::fs::remove_file(dir.join("results/batch/paper_linear.json")).expect("remove");
    let out = report(&dir, &["--check"]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("results/batch/paper_linear.json") && err.contains("stamp.toml"),
        "{err}"
    );
}

/// Issue #46 item 3: `--results` an absolute copy of `results/`, run from a directory that has
/// no `results/` of its own: the files the stamp lists are read from the copy.
#[test]
fn an_absolute_copy_of_the_results_is_read_from_another_directory() {
    let dir = scratch("report-elsewhere");
    let copy = dir.join("copied/results-copy");
    copy_dir(&dir.join("results"), &copy);
    std::fs::remove_dir_all(dir.join("results")).expect("remove the original");
    let elsewhere = dir.join("elsewhere");
    std::fs::create_dir_all(&elsewhere).expect("mkdir");
    let pages = dir.join("book/src/results");
    let out = report(
        &elsewhere,
        &[
            "--check",
            "--results",
            copy.to_str().expect("utf-8"),
            "--out",
            pages.to_str().expect("utf-8"),
        ],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // a missing listed file is named by where it was looked for: inside the copy
    std::fs::remove_file(copy.join("batch/paper_linear.json")).expect("remove");
    let out = report(
        &elsewhere,
        &["--check", "--results", copy.to_str().expect("utf-8")],
    );
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    let missing = copy.join("batch/paper_linear.json");
    assert!(
        err.contains(&missing.display().to_string()),
        "names the file inside the copy: {err}"
    );
}
