//! The book's code blocks are tested (issue #33):
//!
//! - a fenced block after `<!-- book-test: save FILE -->` is written to FILE in a scratch
//!   folder that links the repository's `robots/`, `worlds/` and `tests/`;
//! - a fenced shell block after `<!-- book-test: run -->` (optionally `run; expect: TEXT; …`,
//!   and `exit: N` for a block whose last command fails on purpose) runs there under
//!   `bash -euo pipefail`, with the built `ftcbf` first on `PATH`, and must exit 0 (or N) and
//!   print every TEXT;
//! - a fenced block after `<!-- book-test: output -->` quotes the output of the run block just
//!   before it on the same page (issue #49): every line it shows must be a line of that output
//!   (stdout or stderr, either). `…` in a quoted line stands for text left out, so
//!   `verdict: Theorem 3 applies: … over the run's 30 s` matches a line that starts with the
//!   text before `…` and ends with the text after it; a line that is only `…` stands for lines
//!   left out. The quoted lines must appear in the order the page shows them;
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
    let mut last: Option<(&Block, String)> = None;
    let mut quoted = 0;
    for b in &all {
        let Some(m) = b.marker.as_deref() else {
            continue;
        };
        if m == "output" {
            let (run, output) = last
                .as_ref()
                .filter(|(r, _)| r.file == b.file)
                .unwrap_or_else(|| {
                    panic!(
                        "{}:{}: an output block must follow a run block on the same page",
                        b.file.display(),
                        b.line
                    )
                });
            if let Err(e) = quotes_in_order(&b.text, output) {
                panic!(
                    "{}:{}: the page quotes output that the command at line {} does not print: \
                     {e}\n--- output\n{output}",
                    b.file.display(),
                    b.line,
                    run.line
                );
            }
            quoted += 1;
            continue;
        }
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
        let options: Vec<&str> = parts.collect();
        let exit: i32 = options
            .iter()
            .find_map(|p| p.strip_prefix("exit:"))
            .map_or(0, |n| n.trim().parse().expect("`exit: N` takes a number"));
        let out = Command::new("bash")
            .args(["-euo", "pipefail", "-c", &b.text])
            .current_dir(&dir)
            .env("PATH", &path)
            .output()
            .expect("bash");
        let stdout = String::from_utf8_lossy(&out.stdout);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            out.status.code() == Some(exit),
            "{}:{}: the block ended with {} (expected exit code {exit}):\n{}\n--- stdout\n{stdout}\n--- stderr\n{stderr}",
            b.file.display(),
            b.line,
            out.status,
            b.text
        );
        for want in options.iter().filter_map(|p| p.strip_prefix("expect:")) {
            assert!(
                stdout.contains(want.trim()),
                "{}:{}: the output lacks {:?}:\n{stdout}",
                b.file.display(),
                b.line,
                want.trim()
            );
        }
        last = Some((b, format!("{stdout}{stderr}")));
        ran += 1;
    }
    assert!(
        quoted >= 3,
        "only {quoted} output blocks are marked `<!-- book-test: output -->`"
    );
    assert!(
        ran >= 1,
        "no command block is marked `<!-- book-test: run -->`"
    );
}

/// Whether `line` of the output matches one quoted line: equal after trimming, or, with `…`
/// in the quote, starting with the text before the first `…`, ending with the text after the
/// last, and holding the pieces between in order.
fn line_matches(quote: &str, line: &str) -> bool {
    let (quote, line) = (quote.trim(), line.trim());
    let pieces: Vec<&str> = quote.split('…').map(str::trim).collect();
    if pieces.len() == 1 {
        return quote == line;
    }
    let (first, last) = (pieces[0], pieces[pieces.len() - 1]);
    if !line.starts_with(first) || !line.ends_with(last) || line.len() < first.len() + last.len() {
        return false;
    }
    let mut rest = &line[first.len()..line.len() - last.len()];
    for p in &pieces[1..pieces.len() - 1] {
        match rest.find(p) {
            Some(i) => rest = &rest[i + p.len()..],
            None => return false,
        }
    }
    true
}

/// Every quoted line (but `…` alone) matches a line of `output`, in the quoted order.
fn quotes_in_order(quoted: &str, output: &str) -> Result<(), String> {
    let lines: Vec<&str> = output.lines().collect();
    let mut at = 0;
    for q in quoted
        .lines()
        .filter(|q| !q.trim().is_empty() && q.trim() != "…")
    {
        match lines[at..].iter().position(|l| line_matches(q, l)) {
            Some(i) => at += i + 1,
            None if lines.iter().any(|l| line_matches(q, l)) => {
                return Err(format!(
                    "{q:?} is printed, but not after the line quoted before it"
                ))
            }
            None => return Err(format!("{q:?} is not printed")),
        }
    }
    Ok(())
}

#[test]
fn quoted_lines_match_with_elisions_and_in_order() {
    let out =
        "check: world.toml\nverdict: Theorem 3 applies: Pr(safe) ≥ 0.95 over 30 s\ndrive: ok\n";
    assert!(quotes_in_order("verdict: Theorem 3 applies: … over 30 s", out).is_ok());
    assert!(quotes_in_order("check: world.toml\n…\ndrive: ok", out).is_ok());
    assert!(quotes_in_order("verdict: Theorem 3 applies … 0.95 … 30 s", out).is_ok());
    // a changed number, a line that is not there, and lines out of order all fail
    assert!(quotes_in_order("verdict: Theorem 3 applies: … over 20 s", out).is_err());
    assert!(quotes_in_order("verdict: Theorem 3 does NOT apply", out).is_err());
    let e = quotes_in_order("drive: ok\ncheck: world.toml", out).unwrap_err();
    assert!(e.contains("not after"), "{e}");
    // a quote is a whole line, not a piece of one
    assert!(quotes_in_order("Theorem 3 applies", out).is_err());
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
