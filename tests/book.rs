//! The book's code blocks are tested (issue #33):
//!
//! - a fenced block after `<!-- book-test: save FILE -->` is written to FILE in a scratch
//!   folder that links the repository's `robots/`, `worlds/` and `tests/`;
//! - a fenced shell block after `<!-- book-test: run -->` (optionally `run; expect: TEXT; …`)
//!   runs there under `bash -euo pipefail`, with the built `ftcbf` first on `PATH`, and must
//!   exit 0 and print every TEXT;
//! - every ```rust block consists of `{{#include FILE…}}` lines naming files that exist, so the
//!   book shows Rust only from files the build compiles (examples, tests);
//! - the README's world is the book's first world, byte for byte.

use std::path::{Path, PathBuf};
use std::process::Command;

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

/// One fenced block: its info string, its text, the marker before it, and where it starts.
struct Block {
    info: String,
    text: String,
    marker: Option<String>,
    file: PathBuf,
    line: usize,
}

fn blocks(file: &Path) -> Vec<Block> {
    let text = std::fs::read_to_string(file).expect("read a page");
    let mut out = Vec::new();
    let mut marker: Option<String> = None;
    let mut open: Option<Block> = None;
    for (i, line) in text.lines().enumerate() {
        let trimmed = line.trim_start();
        if let Some(b) = open.as_mut() {
            if trimmed.starts_with("```") {
                out.push(open.take().expect("open block"));
            } else {
                b.text.push_str(line);
                b.text.push('\n');
            }
            continue;
        }
        if let Some(info) = trimmed.strip_prefix("```") {
            open = Some(Block {
                info: info.trim().to_string(),
                text: String::new(),
                marker: marker.take(),
                file: file.to_path_buf(),
                line: i + 1,
            });
        } else if let Some(m) = trimmed
            .strip_prefix("<!-- book-test:")
            .and_then(|m| m.strip_suffix("-->"))
        {
            marker = Some(m.trim().to_string());
        } else if !trimmed.is_empty() {
            marker = None;
        }
    }
    assert!(open.is_none(), "{}: an unclosed code block", file.display());
    out
}

fn pages() -> Vec<PathBuf> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        for e in std::fs::read_dir(dir).expect("list the book") {
            let p = e.expect("entry").path();
            if p.is_dir() {
                walk(&p, out);
            } else if p.extension().is_some_and(|x| x == "md") {
                out.push(p);
            }
        }
    }
    let mut out = Vec::new();
    walk(&Path::new(ROOT).join("book/src"), &mut out);
    out.sort();
    assert!(out.len() > 10, "the book has its pages: {out:?}");
    out
}

fn scratch() -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("book-blocks");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(dir.join("runs")).expect("scratch folder");
    for d in ["robots", "worlds", "tests"] {
        std::os::unix::fs::symlink(Path::new(ROOT).join(d), dir.join(d)).expect("link");
    }
    dir
}

#[test]
fn the_books_command_blocks_run_and_print_what_they_promise() {
    let dir = scratch();
    let bin_dir = Path::new(env!("CARGO_BIN_EXE_ftcbf"))
        .parent()
        .expect("bin dir")
        .to_path_buf();
    let path = format!(
        "{}:{}",
        bin_dir.display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let all: Vec<Block> = pages().iter().flat_map(|p| blocks(p)).collect();
    let mut ran = 0;
    // Saves first, in page order, then runs, so a page may use a file another page saves.
    for b in &all {
        if let Some(name) = b.marker.as_deref().and_then(|m| m.strip_prefix("save ")) {
            std::fs::write(dir.join(name.trim()), &b.text).expect("save a block");
        }
    }
    for b in &all {
        let Some(m) = b.marker.as_deref() else {
            continue;
        };
        let mut parts = m.split(';').map(str::trim);
        if parts.next() != Some("run") {
            continue;
        }
        assert!(
            matches!(b.info.as_str(), "sh" | "bash" | "console"),
            "{}:{}: a run block must be a shell block, found ```{}",
            b.file.display(),
            b.line,
            b.info
        );
        let out = Command::new("bash")
            .args(["-euo", "pipefail", "-c", &b.text])
            .current_dir(&dir)
            .env("PATH", &path)
            .output()
            .expect("bash");
        let stdout = String::from_utf8_lossy(&out.stdout);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            out.status.success(),
            "{}:{}: the block failed ({}):\n{}\n--- stdout\n{stdout}\n--- stderr\n{stderr}",
            b.file.display(),
            b.line,
            out.status,
            b.text
        );
        for want in parts.filter_map(|p| p.strip_prefix("expect:")) {
            assert!(
                stdout.contains(want.trim()),
                "{}:{}: the output lacks {:?}:\n{stdout}",
                b.file.display(),
                b.line,
                want.trim()
            );
        }
        ran += 1;
    }
    assert!(
        ran >= 1,
        "no command block is marked `<!-- book-test: run -->`"
    );
}

#[test]
fn the_books_rust_blocks_include_compiled_files_only() {
    let mut seen = 0;
    for b in pages().iter().flat_map(|p| blocks(p)) {
        if b.info.split([',', ' ']).next() != Some("rust") {
            continue;
        }
        for line in b.text.lines().filter(|l| !l.trim().is_empty()) {
            let inner = line
                .trim()
                .strip_prefix("{{#include ")
                .and_then(|l| l.strip_suffix("}}"))
                .unwrap_or_else(|| {
                    panic!(
                        "{}:{}: a Rust block shows code that no build compiles; include it from \
                         an example or a test with {{{{#include FILE}}}} instead:\n{}",
                        b.file.display(),
                        b.line,
                        b.text
                    )
                });
            let file = inner.split(':').next().expect("path").trim();
            let target = b.file.parent().expect("page dir").join(file);
            assert!(
                target.is_file(),
                "{}:{}: {{{{#include {file}}}}} names no file ({})",
                b.file.display(),
                b.line,
                target.display()
            );
            seen += 1;
        }
    }
    assert!(
        seen >= 1,
        "the book includes at least one compiled Rust file"
    );
}

#[test]
fn the_readme_world_is_the_books_first_world() {
    let book: Vec<Block> = blocks(&Path::new(ROOT).join("book/src/guide/first-world.md"));
    let first = book
        .iter()
        .find(|b| b.marker.as_deref() == Some("save my_world.toml"))
        .expect("the first world is saved by a marked block");
    let readme = blocks(&Path::new(ROOT).join("README.md"));
    let world = readme
        .iter()
        .find(|b| b.info == "toml")
        .expect("the README shows a world");
    assert_eq!(
        world.text, first.text,
        "README.md's world differs from the book's"
    );
    assert!(
        world.text.lines().count() <= 10,
        "the README's world is at most 10 lines"
    );
}
