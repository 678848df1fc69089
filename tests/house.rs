//! The house rules of the workspace's source (issues #28 and #45), checked on every crate's
//! `src/` (the simulator, the controller, the experiments library, the command line and the
//! Python package):
//!
//! - no function is longer than 120 lines: long constructors and validators are split into
//!   named phases, one concern per function;
//! - no import circle among a crate's modules: the modules of a crate, with an arrow from each
//!   to every module whose items it names (`crate::…`, `super::sibling`, `self::child`; a
//!   module naming its own ancestors is the tree, not an arrow), form no cycle;
//! - the simulator's modules in the order a world flows ([`SIM_LAYERS`]): `spec` (the schema)
//!   → `world` (load and validate) → `model` (compiled once) → `runner` (the simulation) and `analysis` (check,
//!   liveness, expectations); no layer names one above it, and `runner` and `analysis` never
//!   name each other.
//!
//! A function's length is counted from the line of its `fn` keyword to the line of its body's
//! closing brace, both included, so nested items and closures count towards the function that
//! holds them. The scan masks comments and string, byte-string, raw-string and character
//! literals before it matches braces, so a `{` in a message or a doc comment does not count.
//! Run with `--nocapture` to see the longest functions.

use std::collections::{BTreeMap, BTreeSet};
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

/// The `src/` folder of every crate in the workspace, relative to the repository root.
const CRATES: [&str; 5] = ["sim/src", "controller/src", "lab/src", "src", "python/src"];

/// The repository root (this test belongs to the root package).
fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// Every source file of every crate: (crate `src/` folder, file, text).
fn sources() -> Vec<(&'static str, PathBuf, String)> {
    let mut out = Vec::new();
    for krate in CRATES {
        for file in rust_files(&root().join(krate)) {
            let text = std::fs::read_to_string(&file)
                .unwrap_or_else(|e| panic!("{}: {e}", file.display()));
            out.push((krate, file, text));
        }
    }
    out
}

/// `file` relative to the repository root, for messages.
fn shown(file: &Path) -> String {
    file.strip_prefix(root())
        .unwrap_or(file)
        .display()
        .to_string()
}

#[test]
fn no_function_in_any_crate_is_over_120_lines() {
    let mut all = Vec::new();
    for (_, file, text) in sources() {
        all.extend(functions(&text).into_iter().map(|f| (shown(&file), f)));
    }
    assert!(
        all.len() > 1500,
        "the scan found only {} functions in {CRATES:?}",
        all.len()
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

/// Lines beyond which a source file must say in its module docs why it is one file.
const LONG_FILE: usize = 1_000;

/// A long file says why it is one ("One file (…): …" in its leading `//!` docs), so that a
/// file grows past the size only with a reason a reviewer can judge; test modules are exempt.
#[test]
fn a_file_over_a_thousand_lines_says_why_it_is_one_file() {
    let mut long = 0;
    let mut silent = Vec::new();
    for (_, file, text) in sources() {
        let lines = text.lines().count();
        let is_tests = file.file_stem().is_some_and(|s| s == "tests");
        if lines <= LONG_FILE || is_tests {
            continue;
        }
        long += 1;
        let docs: String = (text.lines())
            .take_while(|l| l.starts_with("//!"))
            .collect::<Vec<_>>()
            .join("\n");
        if !docs.contains("One file (") {
            silent.push(format!("{} ({lines} lines)", shown(&file)));
        }
    }
    println!("{long} files over {LONG_FILE} lines");
    assert!(
        silent.is_empty(),
        "files over {LONG_FILE} lines whose module docs do not say why they are one file \
         (\"One file (…): …\"):\n{}",
        silent.join("\n")
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

/// A module of a crate: its path below the crate root (empty: the root itself).
type Module = Vec<String>;

/// The simulator's layers, each with the modules it must never name: a world file is read by
/// its schema (`spec`), loaded and validated (`world`, with the physical `plant` and the leaves below), compiled once (`model`),
/// then run (`runner`) or analysed (`analysis`).
const SIM_LAYERS: &[(&str, &[&str])] = &[
    ("spec", &["world", "model", "runner", "analysis", "plant"]),
    ("world", &["model", "runner", "analysis", "plant"]),
    ("plant", &["model", "runner", "analysis"]),
    ("model", &["runner", "analysis"]),
    ("runner", &["analysis"]),
    ("analysis", &["runner"]),
];

/// Each source file of `krate` (one of [`CRATES`]) with the module it holds, and its text.
fn modules_of(krate: &str) -> Vec<(Module, String)> {
    let src = root().join(krate);
    sources()
        .into_iter()
        .filter(|(k, _, _)| *k == krate)
        .map(|(_, file, text)| (module_of(&src, &file), text))
        .collect()
}

/// The module a file under `src` holds (`a/b.rs` and `a/b/mod.rs` are `a::b`; `lib.rs` and
/// `main.rs` the root).
fn module_of(src: &Path, file: &Path) -> Module {
    let rel = file.strip_prefix(src).unwrap_or(file).with_extension("");
    let mut m: Module = rel
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect();
    if matches!(m.last().map(String::as_str), Some("mod" | "lib" | "main")) {
        m.pop();
    }
    m
}

/// The code of `source` with comments, literals and `#[cfg(test)] mod … { … }` blanked: test
/// modules may reach anywhere.
fn code_without_tests(source: &str) -> String {
    let mut s = mask(source);
    let text: String = s.iter().collect();
    let mut from = 0;
    while let Some(at) = text[from..].find("#[cfg(test)]").map(|k| k + from) {
        from = at + 1;
        let after = text[at + 12..].trim_start();
        if !after.starts_with("mod ") && !after.starts_with("pub(crate) mod ") {
            continue;
        }
        // Character indices equal byte indices only for ASCII; find the brace in chars.
        let start = text[..at].chars().count();
        let Some(open) = (start..s.len()).find(|&k| s[k] == '{') else {
            continue;
        };
        let mut depth = 0i32;
        for c in &mut s[open..] {
            match *c {
                '{' => depth += 1,
                '}' => depth -= 1,
                _ => {}
            }
            if *c != '\n' {
                *c = ' ';
            }
            if depth == 0 {
                break;
            }
        }
    }
    s.into_iter().collect()
}

/// The arrows of one crate: from each module to every other module whose items it names.
fn arrows(files: &[(Module, String)]) -> BTreeMap<Module, BTreeSet<Module>> {
    let known: BTreeSet<&Module> = files.iter().map(|(m, _)| m).collect();
    let ident = |c: char| c.is_alphanumeric() || c == '_';
    let mut out: BTreeMap<Module, BTreeSet<Module>> = BTreeMap::new();
    for (m, source) in files {
        let code: Vec<char> = code_without_tests(source).chars().collect();
        let mut i = 0;
        while i < code.len() {
            let word: String = code[i..].iter().take_while(|&&c| ident(c)).collect();
            let boundary = i == 0 || !(ident(code[i - 1]) || code[i - 1] == ':');
            if word.is_empty() || !boundary {
                i += word.len().max(1);
                continue;
            }
            let mut base: Module = match word.as_str() {
                "crate" => Vec::new(),
                "self" | "super" => m.clone(),
                _ => {
                    i += word.len();
                    continue;
                }
            };
            if word == "super" {
                base.pop();
            }
            let mut k = i + word.len();
            // Further `::super` and `::name` segments, then maybe a `::{…}` group.
            let mut heads: Vec<Vec<String>> = vec![Vec::new()];
            while code.get(k) == Some(&':') && code.get(k + 1) == Some(&':') {
                k += 2;
                if code.get(k) == Some(&'{') {
                    let close = (k..code.len())
                        .find(|&j| code[j] == '}')
                        .unwrap_or(code.len());
                    let group: String = code[k + 1..close].iter().collect();
                    let prefix = heads.pop().unwrap_or_default();
                    heads = group
                        .split(',')
                        .map(|item| {
                            let mut h = prefix.clone();
                            h.extend(
                                item.split("::")
                                    .map(|p| p.trim().to_string())
                                    .take_while(|p| !p.is_empty() && p.chars().all(ident)),
                            );
                            h
                        })
                        .collect();
                    k = close;
                    break;
                }
                let seg: String = code[k..].iter().take_while(|&&c| ident(c)).collect();
                if seg.is_empty() {
                    break;
                }
                k += seg.len();
                if seg == "super" && heads.len() == 1 && heads[0].is_empty() {
                    base.pop();
                } else if let Some(h) = heads.last_mut() {
                    h.push(seg);
                }
            }
            for head in heads {
                let mut target = base.clone();
                for seg in head {
                    target.push(seg);
                    if !known.contains(&target) {
                        target.pop();
                        break;
                    }
                }
                // A module naming itself or one of its ancestors is the tree, not an arrow.
                if !m.starts_with(&target) {
                    out.entry(m.clone()).or_default().insert(target);
                }
            }
            i = k.max(i + 1);
        }
    }
    out
}

/// The strongly connected components of more than one module (Tarjan), each sorted, as
/// `a::b` names.
fn circles(
    modules: &BTreeSet<Module>,
    arrows: &BTreeMap<Module, BTreeSet<Module>>,
) -> Vec<Vec<String>> {
    struct Tarjan<'g> {
        arrows: &'g BTreeMap<Module, BTreeSet<Module>>,
        index: BTreeMap<&'g Module, (usize, usize)>,
        stack: Vec<&'g Module>,
        found: Vec<Vec<String>>,
    }
    impl<'g> Tarjan<'g> {
        fn visit(&mut self, v: &'g Module) {
            let n = self.index.len();
            self.index.insert(v, (n, n));
            self.stack.push(v);
            for w in self.arrows.get(v).into_iter().flatten() {
                if !self.index.contains_key(w) {
                    self.visit(w);
                    let low = self.index[w].1.min(self.index[v].1);
                    self.index.get_mut(v).expect("visited").1 = low;
                } else if self.stack.contains(&w) {
                    let low = self.index[w].0.min(self.index[v].1);
                    self.index.get_mut(v).expect("visited").1 = low;
                }
            }
            if self.index[v].0 == self.index[v].1 {
                let at = self
                    .stack
                    .iter()
                    .rposition(|x| *x == v)
                    .expect("on the stack");
                let component: Vec<&Module> = self.stack.split_off(at);
                if component.len() > 1 {
                    let mut names: Vec<String> = component.iter().map(|m| m.join("::")).collect();
                    names.sort();
                    self.found.push(names);
                }
            }
        }
    }
    let mut t = Tarjan {
        arrows,
        index: BTreeMap::new(),
        stack: Vec::new(),
        found: Vec::new(),
    };
    for m in modules {
        if !t.index.contains_key(m) {
            t.visit(m);
        }
    }
    t.found.sort();
    t.found
}

#[test]
fn no_crate_has_an_import_circle() {
    let mut found: Vec<(String, Vec<String>)> = Vec::new();
    let mut modules_seen = 0;
    for krate in CRATES {
        let files = modules_of(krate);
        let modules: BTreeSet<Module> = files.iter().map(|(m, _)| m.clone()).collect();
        modules_seen += modules.len();
        for circle in circles(&modules, &arrows(&files)) {
            found.push((krate.to_string(), circle));
        }
    }
    assert!(
        modules_seen > 100,
        "the scan found only {modules_seen} modules"
    );
    assert!(
        found.is_empty(),
        "import circles (crate, modules): {found:?}; a circle is a module importing upward"
    );
}

/// No simulator module names a layer above its own, and `runner` and `analysis` never name each
/// other ([`SIM_LAYERS`]).
#[test]
fn the_simulator_flows_world_model_then_runner_or_analysis() {
    let files = modules_of("sim/src");
    let mut upward = Vec::new();
    for (from, tos) in arrows(&files) {
        let Some((layer, forbidden)) = SIM_LAYERS
            .iter()
            .find(|(l, _)| from.first().map(String::as_str) == Some(*l))
        else {
            continue;
        };
        for to in tos {
            if forbidden.contains(&to.first().map_or("", String::as_str)) {
                upward.push(format!("{} ({layer}) → {}", from.join("::"), to.join("::")));
            }
        }
    }
    for (layer, _) in SIM_LAYERS {
        assert!(
            files
                .iter()
                .any(|(m, _)| m.first().map(String::as_str) == Some(*layer)),
            "the simulator has no module `{layer}`: SIM_LAYERS is out of date"
        );
    }
    assert!(upward.is_empty(), "arrows against the flow: {upward:#?}");
}

/// The graph itself, on a small crate: `crate::`, `super::sibling`, `self::child` and groups
/// make arrows; naming an ancestor, comments, strings and test modules do not.
#[test]
fn the_graph_reads_paths_groups_and_ignores_ancestors_comments_and_tests() {
    let m = |s: &str| -> Module {
        if s.is_empty() {
            Vec::new()
        } else {
            s.split("::").map(String::from).collect()
        }
    };
    let files = vec![
        (m(""), "mod a; mod b; mod c; pub use a::Thing;".to_string()),
        (
            m("a"),
            "use crate::{b::B, c};\nuse super::Root; // crate::c::x in a comment".to_string(),
        ),
        (
            m("b"),
            "pub struct B; fn f() { let s = \"crate::a\"; super::c::go(); }".to_string(),
        ),
        (
            m("c"),
            "pub fn go() {}\n#[cfg(test)]\nmod tests { use crate::a::Thing; }".to_string(),
        ),
        (
            m("c::d"),
            "use super::super::b::B; use self::e; use super::go;".to_string(),
        ),
        (m("c::d::e"), "".to_string()),
    ];
    let got = arrows(&files);
    let set = |v: &[&str]| v.iter().map(|s| m(s)).collect::<BTreeSet<_>>();
    assert_eq!(
        got.get(&m("")),
        None,
        "the root's `a::Thing` is a child, not an arrow"
    );
    assert_eq!(got[&m("a")], set(&["b", "c"]));
    assert_eq!(got[&m("b")], set(&["c"]));
    assert_eq!(got.get(&m("c")), None, "c's test module is not scanned");
    assert_eq!(got[&m("c::d")], set(&["b", "c::d::e"]));
    let modules: BTreeSet<Module> = files.iter().map(|(m, _)| m.clone()).collect();
    assert!(circles(&modules, &got).is_empty());
    let mut looped = got.clone();
    looped.entry(m("c")).or_default().insert(m("a"));
    assert_eq!(
        circles(&modules, &looped),
        vec![vec!["a".to_string(), "b".into(), "c".into()]]
    );
}
