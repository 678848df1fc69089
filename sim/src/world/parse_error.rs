//! Reading the world schema from TOML text with errors that have a place: the dotted key path
//! (array indices included, e.g. `obstacles[2].shape.half_extents\[1\]`), the line and column of
//! that key in the file, and serde's statement of what was found and what was expected.
//!
//! The key path comes from `serde_path_to_error` over toml's deserializer; inside a
//! `kind`-tagged table (an obstacle's `shape`, `[[safe_sets]]`, `[[attacks]]`) the table's own
//! deserializer adds the path inside it ([`crate::spec::tagged`]). The line and column are those of
//! the deepest part of that path the file contains, found in toml's spanned document.

use std::ops::Range;
use std::path::Path;

use serde::de::DeserializeOwned;
use toml::de::{DeTable, DeValue};
use toml::Spanned;

use super::WorldError;
use crate::spec::tagged::{field_named, relative_path};

/// Parses `text` (the file at `path`) as `T`: a syntax error as toml reports it (line, column
/// and the line itself), a schema error as [`WorldError::Schema`].
pub(super) fn from_text<T: DeserializeOwned>(text: &str, path: &Path) -> Result<T, WorldError> {
    let de = toml::Deserializer::parse(text).map_err(|e| {
        // toml names no place for its key-depth limit and no limit for its nesting one: find
        // the line and say the limit.
        let recursion = e.message().contains("recursion");
        let message = match super::toml_limits::first_excess(text) {
            Some((line, what)) if recursion || e.span().is_none() => {
                format!("line {line}: {what}")
            }
            _ => e.to_string(),
        };
        WorldError::Parse {
            path: path.to_path_buf(),
            message,
        }
    })?;
    serde_path_to_error::deserialize(de).map_err(|e| {
        let (key, mut message) = key_and_message(e.path(), e.inner().message());
        if message == "wanted string or table" {
            message = enum_values::<T>(text, &key).map_or_else(
                || {
                    "expected a string naming one of its values (see the world-file reference)"
                        .into()
                },
                |values| format!("expected a string, {values}"),
            );
        }
        let span = DeTable::parse(text)
            .ok()
            .and_then(|doc| span_of(&doc, &key))
            .or_else(|| e.inner().span());
        let place = span.map(|s| line_column(text, s.start));
        WorldError::Schema {
            path: path.to_path_buf(),
            key,
            excerpt: place.map_or(String::new(), |(l, c)| excerpt(text, l, c)),
            place,
            message,
        }
    })
}

/// The values a named-value key (`measures`, `controller`, …) takes, as serde lists them
/// ("one of `x`, `y`, …"): toml's own message for a number or an array there is "wanted string
/// or table". Found by reading the file again with a string no key takes at `key`.
fn enum_values<T: DeserializeOwned>(text: &str, key: &str) -> Option<String> {
    let mut doc: toml::Value = toml::from_str(text).ok()?;
    let mut cur = &mut doc;
    for step in steps(key) {
        cur = match step {
            Step::Key(k) => cur.as_table_mut()?.get_mut(k)?,
            Step::Index(i) => cur.as_array_mut()?.get_mut(i)?,
        };
    }
    *cur = toml::Value::String("\u{1}".into());
    let Err(e) = serde_path_to_error::deserialize::<_, T>(doc) else {
        return None;
    };
    let m = e.inner().message().to_string();
    m.find("one of ").map(|i| m[i..].to_string())
}

/// Deserializes `T` from a TOML value (a file after `--set` overrides: no places left), naming
/// the key path of an error: `(key, message)`.
pub(super) fn from_value<T: DeserializeOwned>(value: toml::Value) -> Result<T, (String, String)> {
    serde_path_to_error::deserialize(value)
        .map_err(|e| key_and_message(e.path(), e.inner().message()))
}

/// The full key path of an error at `path` with toml's `message`, and the message to show.
/// A message from a tagged table starts with its path inside the table in backquotes; one from
/// `[expect]` starts with its own full path (it reads its table by hand); serde's missing- and
/// unknown-field messages name the key they are about.
fn key_and_message(path: &serde_path_to_error::Path, message: &str) -> (String, String) {
    let outer = relative_path(path.iter());
    let inner = message
        .strip_prefix('`')
        .and_then(|rest| rest.split_once("`: "));
    let (key, message) = match inner {
        Some((q, rest))
            if !outer.is_empty()
                && (q == outer
                    || q.starts_with(&format!("{outer}."))
                    || q.starts_with(&format!("{outer}["))) =>
        {
            (q.to_string(), rest.to_string())
        }
        Some((q, rest)) if !outer.is_empty() => (join(&outer, q), rest.to_string()),
        _ => match field_named(message) {
            Some(f) if !outer.ends_with(f) => (join(&outer, f), message.to_string()),
            _ => (outer, message.to_string()),
        },
    };
    let key = if key.is_empty() {
        "(top level)".to_string()
    } else {
        key
    };
    (key, plain_types(&message))
}

fn join(outer: &str, inner: &str) -> String {
    if outer.is_empty() {
        inner.to_string()
    } else if inner.starts_with('[') {
        format!("{outer}{inner}")
    } else {
        format!("{outer}.{inner}")
    }
}

/// serde's Rust type names in a message, as a world file's author reads them.
fn plain_types(message: &str) -> String {
    let mut m = message.to_string();
    for (rust, plain) in [
        ("expected f64", "expected a number"),
        ("expected u64", "expected a whole number ≥ 0"),
        ("expected u32", "expected a whole number ≥ 0"),
        ("expected usize", "expected a whole number ≥ 0"),
        ("expected a sequence", "expected an array"),
        ("expected a borrowed string", "expected a string"),
    ] {
        m = m.replace(rust, plain);
    }
    m
}

/// One step of a key path.
enum Step<'a> {
    Key(&'a str),
    Index(usize),
}

/// The steps of a key path as [`relative_path`] writes it (`a.b[2].c`).
fn steps(key: &str) -> Vec<Step<'_>> {
    let mut out = Vec::new();
    for part in key.split('.') {
        let (name, mut rest) = part.split_once('[').map_or((part, ""), |(n, r)| (n, r));
        if !name.is_empty() {
            out.push(Step::Key(name));
        }
        while let Some((idx, after)) = rest.split_once(']') {
            match idx.parse() {
                Ok(i) => out.push(Step::Index(i)),
                Err(_) => return out,
            }
            rest = after.strip_prefix('[').unwrap_or(after);
        }
    }
    out
}

/// The span of the deepest part of `key` present in `doc`: a key's own span for a table key,
/// an element's for an array index.
fn span_of(doc: &Spanned<DeTable<'_>>, key: &str) -> Option<Range<usize>> {
    let mut value: Option<&Spanned<DeValue<'_>>> = None;
    let mut table: Option<&DeTable<'_>> = Some(doc.get_ref());
    let mut found = None;
    for step in steps(key) {
        match step {
            Step::Key(k) => {
                let Some((kspan, v)) = table.and_then(|t| {
                    t.iter()
                        .find(|(name, _)| name.get_ref().as_ref() == k)
                        .map(|(name, v)| (name.span(), v))
                }) else {
                    return found;
                };
                found = Some(kspan);
                value = Some(v);
            }
            Step::Index(i) => {
                let Some(DeValue::Array(a)) = value.map(Spanned::get_ref) else {
                    return found;
                };
                let Some(v) = a.get(i) else {
                    return found;
                };
                found = Some(v.span());
                value = Some(v);
            }
        }
        table = match value.map(Spanned::get_ref) {
            Some(DeValue::Table(t)) => Some(t),
            _ => None,
        };
    }
    found
}

/// 1-based line and column (in characters) of byte `offset` of `text`.
fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let mut offset = offset.min(text.len());
    while !text.is_char_boundary(offset) {
        offset -= 1;
    }
    let before = &text[..offset];
    let line = before.matches('\n').count() + 1;
    let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, column)
}

/// Line `line` of `text` with a caret under `column`, indented like rustc's and toml's.
fn excerpt(text: &str, line: usize, column: usize) -> String {
    let Some(src) = text.lines().nth(line - 1) else {
        return String::new();
    };
    let gutter = " ".repeat(line.to_string().len());
    format!(
        "\n{gutter} |\n{line} | {src}\n{gutter} | {}^",
        " ".repeat(column - 1)
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn key_paths_split_into_steps_and_find_their_place() {
        let text =
            "a = 1\n[[obs]]\nname = \"x\"\n[[obs]]\nshape = { kind = \"c\", h = [1, 2, \"z\"] }\n";
        let doc = DeTable::parse(text).unwrap();
        let at = |k: &str| span_of(&doc, k).map(|s| line_column(text, s.start));
        assert_eq!(at("a"), Some((1, 1)));
        assert_eq!(at("obs[1].shape"), Some((5, 1)));
        assert_eq!(at("obs[1].shape.h"), Some((5, 23)));
        assert_eq!(at("obs[1].shape.h[2]"), Some((5, 34)));
        // A missing key: the deepest part that is there.
        assert_eq!(at("obs[1].shape.radius"), Some((5, 1)));
        assert_eq!(at("nothing"), None);
    }

    #[test]
    fn the_excerpt_puts_a_caret_under_the_column() {
        assert_eq!(
            excerpt("a = 1\nb = \"x\"\n", 2, 5),
            "\n  |\n2 | b = \"x\"\n  |     ^"
        );
    }

    #[test]
    fn line_and_column_count_characters() {
        assert_eq!(line_column("ab\ncé = x", 7), (2, 4));
        assert_eq!(line_column("", 0), (1, 1));
    }
}
