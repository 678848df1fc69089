//! Where a TOML text goes past the TOML reader's nesting limits. The `toml` crate refuses a key
//! of more than [`MAX_KEY_PARTS`] dotted parts, and arrays or inline tables nested deeper than
//! [`MAX_NESTING`], with "recursion limit" and no place; this finds the first line that does
//! so, to name it with the limit in the error.

/// The most dotted parts a key or table header may have (`toml` 0.9: its recursion limit of
/// 80 counts the parts before the last).
pub const MAX_KEY_PARTS: usize = 80;

/// The deepest nesting of arrays and inline tables `toml` 0.9 reads.
pub const MAX_NESTING: usize = 80;

/// The first line past a limit, as `(line, what)`: a key or header with more than
/// [`MAX_KEY_PARTS`] dotted parts, or arrays and inline tables nested deeper than
/// [`MAX_NESTING`]. Strings (basic, literal, multi-line) and comments are skipped.
pub fn first_excess(text: &str) -> Option<(usize, String)> {
    let mut depth = 0usize;
    let mut multiline: Option<&str> = None;
    for (i, line) in text.lines().enumerate() {
        let n = i + 1;
        if let Some(close) = multiline {
            if line.contains(close) {
                multiline = None;
            }
            continue;
        }
        let trimmed = line.trim_start();
        if depth == 0 {
            if trimmed.starts_with('[') {
                let header = trimmed.trim_start_matches('[');
                let end = unquoted_find(header, |c| c == ']').unwrap_or(header.len());
                let parts = dotted_parts(&header[..end]);
                if parts > MAX_KEY_PARTS {
                    return Some((n, key_excess("table header", parts)));
                }
                continue;
            }
            let Some(eq) = unquoted_find(trimmed, |c| c == '=') else {
                continue;
            };
            let parts = dotted_parts(&trimmed[..eq]);
            if parts > MAX_KEY_PARTS {
                return Some((n, key_excess("key", parts)));
            }
            let value = &trimmed[eq + 1..];
            if let Some(close) = opens_multiline(value) {
                multiline = Some(close);
                continue;
            }
            match nest(value, depth) {
                Some(d) => depth = d,
                None => return Some((n, nesting_excess())),
            }
        } else {
            match nest(trimmed, depth) {
                Some(d) => depth = d,
                None => return Some((n, nesting_excess())),
            }
        }
    }
    None
}

fn key_excess(what: &str, parts: usize) -> String {
    format!(
        "a {what} of {parts} dotted parts; the TOML reader accepts at most {MAX_KEY_PARTS} (its \
         recursion limit)"
    )
}

fn nesting_excess() -> String {
    format!(
        "arrays or inline tables nested more than {MAX_NESTING} deep; the TOML reader accepts \
         at most {MAX_NESTING} levels (its recursion limit)"
    )
}

/// The characters of `s` outside quoted strings (basic `"…"` with `\\` escapes, literal
/// `'…'`), with their byte offsets, up to a comment (`#` outside quotes). The quotes themselves
/// are not yielded.
fn unquoted(s: &str) -> impl Iterator<Item = (usize, char)> + '_ {
    let mut quote: Option<char> = None;
    let mut escaped = false;
    s.char_indices()
        .map_while(move |(i, c)| match quote {
            Some(q) => {
                if escaped {
                    escaped = false;
                } else if c == '\\' && q == '"' {
                    escaped = true;
                } else if c == q {
                    quote = None;
                }
                Some(None)
            }
            None if c == '"' || c == '\'' => {
                quote = Some(c);
                Some(None)
            }
            None if c == '#' => None,
            None => Some(Some((i, c))),
        })
        .flatten()
}

/// The nesting depth of arrays and inline tables after `s`, starting at `depth`; `None` once
/// it passes [`MAX_NESTING`].
fn nest(s: &str, mut depth: usize) -> Option<usize> {
    for (_, c) in unquoted(s) {
        match c {
            '[' | '{' => depth += 1,
            ']' | '}' => depth = depth.saturating_sub(1),
            _ => {}
        }
        if depth > MAX_NESTING {
            return None;
        }
    }
    Some(depth)
}

/// The byte offset of the first character outside quotes that `pred` accepts.
fn unquoted_find(s: &str, pred: impl Fn(char) -> bool) -> Option<usize> {
    unquoted(s).find(|&(_, c)| pred(c)).map(|(i, _)| i)
}

/// The number of dotted parts of a key (dots inside quotes do not count).
fn dotted_parts(key: &str) -> usize {
    let mut parts = 1;
    let mut rest = key;
    while let Some(i) = unquoted_find(rest, |c| c == '.') {
        parts += 1;
        rest = &rest[i + 1..];
    }
    parts
}

/// The closing delimiter when `value` opens a multi-line string it does not close.
fn opens_multiline(value: &str) -> Option<&'static str> {
    let v = value.trim_start();
    for delim in ["\"\"\"", "'''"] {
        if let Some(rest) = v.strip_prefix(delim) {
            return (!rest.contains(delim)).then_some(delim);
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quoted_text_and_comments_are_skipped() {
        let seen: String = unquoted(r#"a."b.#c\"[".'d[e'.f # g.h"#)
            .map(|(_, c)| c)
            .collect();
        assert_eq!(seen, "a...f ");
        assert_eq!(unquoted_find(r#""x.y".z"#, |c| c == '.'), Some(5));
        assert_eq!(nest(r#"[ "[[[" , { a = '{' } ] # [[["#, 0), Some(0));
    }

    fn key(parts: usize) -> String {
        vec!["a"; parts].join(".")
    }

    fn nested(depth: usize) -> String {
        format!("x = {}1{}\n", "[".repeat(depth), "]".repeat(depth))
    }

    #[test]
    fn the_limits_are_those_the_toml_reader_applies() {
        for (text, ok) in [
            (format!("[{}]\n", key(MAX_KEY_PARTS)), true),
            (format!("[{}]\n", key(MAX_KEY_PARTS + 1)), false),
            (format!("{} = 1\n", key(MAX_KEY_PARTS)), true),
            (format!("{} = 1\n", key(MAX_KEY_PARTS + 1)), false),
            (nested(MAX_NESTING), true),
            (nested(MAX_NESTING + 1), false),
        ] {
            let parsed = toml::from_str::<toml::Table>(&text);
            assert_eq!(parsed.is_ok(), ok, "toml on {text:.40}…: {parsed:?}");
            assert_eq!(first_excess(&text).is_none(), ok, "scan of {text:.40}…");
        }
    }

    #[test]
    fn the_line_and_the_count_are_named() {
        let text = format!("name = \"x\"\n# a.b.c\n[{}]\nv = 1\n", key(100));
        let (line, what) = first_excess(&text).expect("excess");
        assert_eq!(line, 3);
        assert!(what.contains("table header of 100 dotted parts"), "{what}");
        assert!(what.contains("at most 80"), "{what}");
        let text = format!("a = [\n  {}1{}\n]\n", "{ b = ".repeat(90), " }".repeat(90));
        let (line, what) = first_excess(&text).expect("excess");
        assert_eq!(line, 2);
        assert!(what.contains("nested more than 80 deep"), "{what}");
    }

    #[test]
    fn dots_and_brackets_in_strings_and_comments_do_not_count() {
        let dots = ".".repeat(200);
        let brackets = "[".repeat(200);
        let text = format!(
            "\"{dots}\" = 1\nb = '{brackets}'\nc = 1 # {brackets}\nd = \"\"\"\n{brackets}\n\"\"\"\n[\"t{dots}\"]\n"
        );
        assert!(toml::from_str::<toml::Table>(&text).is_ok());
        assert_eq!(first_excess(&text), None);
    }
}
