//! No function in the sim crate is longer than 120 lines (issue #28): the long constructors and
//! validators are split into named phases, one concern per function, and this keeps them so.
//!
//! A function's length is counted from the line of its `fn` keyword to the line of its body's
//! closing brace, both included, so nested items and closures count towards the function that
//! holds them. The scan masks comments and string, byte-string, raw-string and character
//! literals before it matches braces, so a `{` in a message or a doc comment does not count.
//! Run with `--nocapture` to see the longest functions.

use std::path::{Path, PathBuf};

/// The longest a function may be, in lines (no tolerance above it).
const MAX_LINES: usize = 120;

/// One function found by the scan.
#[derive(Debug, PartialEq)]
struct Function {
    name: String,
    /// 1-based line of the `fn` keyword.
    line: usize,
    /// Lines from the `fn` keyword to the closing brace of the body, both included.
    lines: usize,
}

/// The source with every comment and every string, byte-string, raw-string and character
/// literal replaced by spaces (newlines kept, so line numbers stay), leaving code only.
fn mask(source: &str) -> Vec<char> {
    let s: Vec<char> = source.chars().collect();
    let mut out = s.clone();
    let blank = |out: &mut Vec<char>, from: usize, to: usize| {
        for c in &mut out[from..to.min(s.len())] {
            if *c != '\n' {
                *c = ' ';
            }
        }
    };
    let ident = |c: char| c.is_alphanumeric() || c == '_';
    let mut i = 0;
    while i < s.len() {
        let at = |k: usize| s.get(k).copied().unwrap_or('\0');
        let c = s[i];
        if c == '/' && at(i + 1) == '/' {
            let end = (i..s.len()).find(|&k| s[k] == '\n').unwrap_or(s.len());
            blank(&mut out, i, end);
            i = end;
        } else if c == '/' && at(i + 1) == '*' {
            // Block comments nest in Rust.
            let (mut depth, mut k) = (1, i + 2);
            while k < s.len() && depth > 0 {
                if s[k] == '/' && at(k + 1) == '*' {
                    depth += 1;
                    k += 2;
                } else if s[k] == '*' && at(k + 1) == '/' {
                    depth -= 1;
                    k += 2;
                } else {
                    k += 1;
                }
            }
            blank(&mut out, i, k);
            i = k;
        } else if (c == 'r' || (c == 'b' && at(i + 1) == 'r')) && (i == 0 || !ident(s[i - 1])) && {
            let q = if c == 'b' { i + 2 } else { i + 1 };
            let hashes = (q..s.len()).take_while(|&k| s[k] == '#').count();
            at(q + hashes) == '"'
        } {
            // Raw string r"…", r#"…"#, br"…": ends at a quote followed by as many hashes.
            let q = if c == 'b' { i + 2 } else { i + 1 };
            let hashes = (q..s.len()).take_while(|&k| s[k] == '#').count();
            let mut k = q + hashes + 1;
            while k < s.len() && !(s[k] == '"' && (1..=hashes).all(|h| at(k + h) == '#')) {
                k += 1;
            }
            let end = k + 1 + hashes;
            blank(&mut out, i, end);
            i = end;
        } else if c == '"' {
            let mut k = i + 1;
            while k < s.len() && s[k] != '"' {
                k += if s[k] == '\\' { 2 } else { 1 };
            }
            blank(&mut out, i, k + 1);
            i = k + 1;
        } else if c == '\'' {
            // A character literal ('x', '\n', '\u{7f}', b'x') or a lifetime/label ('a, 'static).
            if at(i + 1) == '\\' {
                let mut k = i + 2;
                while k < s.len() && s[k] != '\'' {
                    k += 1;
                }
                blank(&mut out, i, k + 1);
                i = k + 1;
            } else if at(i + 2) == '\'' {
                blank(&mut out, i, i + 3);
                i += 3;
            } else {
                i += 1;
            }
        } else {
            i += 1;
        }
    }
    out
}

/// Every function with a body in `source`, with its length in lines.
fn functions(source: &str) -> Vec<Function> {
    let s = mask(source);
    let line_of = |k: usize| s[..k].iter().filter(|&&c| c == '\n').count() + 1;
    let ident = |c: char| c.is_alphanumeric() || c == '_';
    let mut found = Vec::new();
    for i in 0..s.len() {
        let keyword = s[i] == 'f'
            && s.get(i + 1) == Some(&'n')
            && (i == 0 || !ident(s[i - 1]))
            && s.get(i + 2).is_some_and(|c| c.is_whitespace());
        if !keyword {
            continue;
        }
        let start = (i + 2..s.len()).find(|&k| !s[k].is_whitespace());
        let Some(start) = start.filter(|&k| ident(s[k])) else {
            continue; // `fn(…)`: a function-pointer type, not an item
        };
        let name: String = s[start..].iter().take_while(|&&c| ident(c)).collect();
        // The body opens at the first `{` outside parentheses and brackets; a `;` there first
        // means a declaration without a body (a trait method or an extern function).
        let mut depth = 0i32;
        let mut open = None;
        for (k, &c) in s.iter().enumerate().skip(start) {
            match c {
                '(' | '[' => depth += 1,
                ')' | ']' => depth -= 1,
                ';' if depth == 0 => break,
                '{' if depth == 0 => {
                    open = Some(k);
                    break;
                }
                _ => {}
            }
        }
        let Some(open) = open else { continue };
        let mut braces = 0i32;
        let close = (open..s.len()).find(|&k| {
            match s[k] {
                '{' => braces += 1,
                '}' => braces -= 1,
                _ => {}
            }
            braces == 0
        });
        let close = close.unwrap_or_else(|| panic!("fn {name}: no closing brace"));
        let line = line_of(i);
        found.push(Function {
            name,
            line,
            lines: line_of(close) - line + 1,
        });
    }
    found
}

/// Every `.rs` file under `dir`, sorted.
fn rust_files(dir: &Path) -> Vec<PathBuf> {
    let mut files = Vec::new();
    let entries = std::fs::read_dir(dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
    for entry in entries {
        let path = entry.expect("directory entry").path();
        if path.is_dir() {
            files.extend(rust_files(&path));
        } else if path.extension().is_some_and(|e| e == "rs") {
            files.push(path);
        }
    }
    files.sort();
    files
}

#[test]
fn no_function_in_the_sim_crate_is_over_120_lines() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut all = Vec::new();
    for file in rust_files(&src) {
        let text =
            std::fs::read_to_string(&file).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
        let shown = file
            .strip_prefix(&src)
            .unwrap_or(&file)
            .display()
            .to_string();
        all.extend(functions(&text).into_iter().map(|f| (shown.clone(), f)));
    }
    assert!(
        all.len() > 500,
        "the scan found only {} functions in {}",
        all.len(),
        src.display()
    );
    all.sort_by_key(|(_, f)| std::cmp::Reverse(f.lines));
    println!("{} functions; the longest:", all.len());
    for (file, f) in all.iter().take(15) {
        println!("{:>5} lines  {file}:{} fn {}", f.lines, f.line, f.name);
    }
    let over: Vec<String> = all
        .iter()
        .filter(|(_, f)| f.lines > MAX_LINES)
        .map(|(file, f)| format!("{file}:{} fn {} is {} lines", f.line, f.name, f.lines))
        .collect();
    assert!(
        over.is_empty(),
        "functions over {MAX_LINES} lines:\n{}",
        over.join("\n")
    );
}

/// The scan itself: braces in strings, raw strings, characters and comments do not count,
/// lifetimes are not character literals, nested functions count towards their holder,
/// declarations without a body and function-pointer types are not functions.
#[test]
fn the_scan_measures_bodies_and_ignores_braces_in_literals_and_comments() {
    let source = r####"
trait T {
    fn declared(&self) -> u8;
}
fn outer<'a>(x: &'a str, f: fn(u8) -> u8) -> usize {
    let open = "{ {";
    let raw = r#"} "quoted" {"#;
    let brace = '{';
    let escaped = '\'';
    // a } in a comment
    /* and { in /* a nested */ block } */
    fn inner() -> [u8; 2] {
        [b'}', 0]
    }
    x.len()
}
fn last() {}
"####;
    let found = functions(source);
    let expect = |name: &str, line, lines| Function {
        name: name.into(),
        line,
        lines,
    };
    assert_eq!(
        found,
        vec![
            expect("outer", 5, 12),
            expect("inner", 12, 3),
            expect("last", 17, 1)
        ]
    );
}
