//! Tables tagged by `kind` (an obstacle's `shape`, `[[safe_sets]]`, `[[attacks]]`), read so that
//! an error names the key inside the table.
//!
//! serde's internally tagged enums (`#[serde(tag = "kind")]`) buffer the whole table before they
//! know the variant, and the buffer has neither keys nor places: a wrong value inside
//! `shape = { kind = "cuboid", half_extents = [0.1, "a", 0.1] }` used to be reported as
//! "invalid type: string "a", expected f64" at the obstacle's header, with no key. Here the
//! table is read first, its `kind` taken out, and the rest read as the variant of an
//! *externally* tagged mirror of the enum (which serde reads field by field) through
//! `serde_path_to_error`, so the error carries the key path inside the table. The mirror is
//! generated from the same definition by [`kind_tagged!`], so the two cannot drift apart;
//! serialisation keeps the internally tagged form.
//!
//! The error message is ``"`PATH`: MESSAGE"`` with `PATH` relative to the tagged table (e.g.
//! `half_extents\[1\]`, or `kind` when the tag is missing or unknown); the world loader
//! (`world::parse_error`) joins it to the table's own path and finds its line and column.

use serde::de::{DeserializeOwned, Error as _};
use serde::{Deserialize, Deserializer};
use serde_path_to_error::Segment;

/// The tag key.
const TAG: &str = "kind";

/// Kinds the world loader builds itself (`#[serde(skip_deserializing)]`), left out of the
/// kinds an error lists: an occupancy map comes from `environment.map`.
pub const LOADER_ONLY: &[&str] = &["occupancy_map"];

/// Reads a `kind`-tagged table from `d` as the externally tagged mirror `M` (see the module
/// docs). `kinds` lists the accepted tags, for the message of a missing or mistyped `kind`.
pub fn deserialize<'de, D, M>(d: D, kinds: &[&str]) -> Result<M, D::Error>
where
    D: Deserializer<'de>,
    M: DeserializeOwned,
{
    let expected = || {
        kinds
            .iter()
            .map(|k| format!("\"{k}\""))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let mut table = toml::Table::deserialize(d)?;
    let kind = match table.remove(TAG) {
        Some(toml::Value::String(s)) => s,
        Some(other) => {
            return Err(D::Error::custom(format!(
                "`{TAG}`: expected a string, one of {}, found {} {other}",
                expected(),
                other.type_str()
            )))
        }
        None => {
            return Err(D::Error::custom(format!(
                "`{TAG}`: missing; expected one of {}",
                expected()
            )))
        }
    };
    let mut outer = toml::Table::new();
    outer.insert(kind, toml::Value::Table(table));
    serde_path_to_error::deserialize(toml::Value::Table(outer)).map_err(|e| {
        // The first segment is the variant (the kind); an error at the variant itself is an
        // unknown kind.
        let message = e.inner().message();
        let inner = relative_path(e.path().iter().skip(1));
        let key = match field_named(message) {
            Some(f) if inner.is_empty() => f.to_string(),
            Some(f) if !inner.ends_with(f) => format!("{inner}.{f}"),
            _ if inner.is_empty() => TAG.to_string(),
            _ => inner,
        };
        D::Error::custom(format!("`{key}`: {message}"))
    })
}

/// The key a serde message about a missing or unknown key names (`missing field `x``,
/// `unknown field `x`, expected ...`): the key path of such an error is the table's plus `x`.
pub(crate) fn field_named(message: &str) -> Option<&str> {
    let rest = message
        .strip_prefix("missing field `")
        .or_else(|| message.strip_prefix("unknown field `"))?;
    rest.split('`').next()
}

/// A path of segments as a TOML key path (`a.b[2].c`); stops at a segment it cannot name.
pub(crate) fn relative_path<'a>(segments: impl Iterator<Item = &'a Segment>) -> String {
    let mut s = String::new();
    for seg in segments {
        match seg {
            Segment::Seq { index } => s.push_str(&format!("[{index}]")),
            Segment::Map { key } | Segment::Enum { variant: key } => {
                if !s.is_empty() {
                    s.push('.');
                }
                s.push_str(key);
            }
            Segment::Unknown => break,
        }
    }
    s
}

/// `CamelCase` → `snake_case` (the variant names as a world file writes them).
pub fn snake_case(name: &str) -> String {
    let mut s = String::with_capacity(name.len() + 4);
    for (i, c) in name.chars().enumerate() {
        if c.is_ascii_uppercase() {
            if i > 0 {
                s.push('_');
            }
            s.push(c.to_ascii_lowercase());
        } else {
            s.push(c);
        }
    }
    s
}

/// Declares an enum with struct variants that a world file writes as a table tagged by
/// `kind = "snake_case_variant"`, and its `Deserialize` through an externally tagged mirror
/// (module docs). The enum's own attributes are kept as written: give it
/// `#[derive(Serialize)]` and `#[serde(tag = "kind", rename_all = "snake_case", ...)]` for the
/// serialised form, and no `Deserialize` derive. Variant and field attributes (`alias`,
/// `default`, ...) apply to both.
macro_rules! kind_tagged {
    (
        $(#[$meta:meta])*
        $vis:vis enum $Name:ident via $Mirror:ident {
            $(
                $(#[$vmeta:meta])*
                $Variant:ident { $( $(#[$fmeta:meta])* $field:ident : $ty:ty ),* $(,)? }
            ),* $(,)?
        }
    ) => {
        $(#[$meta])*
        $vis enum $Name {
            $( $(#[$vmeta])* $Variant { $( $(#[$fmeta])* $field: $ty ),* } ),*
        }

        /// The externally tagged mirror `Deserialize` reads through (see `spec::tagged`).
        // A variant the loader builds itself (`skip_deserializing`) is never read into it.
        #[allow(dead_code)]
        #[derive(serde::Deserialize)]
        #[serde(rename_all = "snake_case", deny_unknown_fields)]
        enum $Mirror {
            $( $(#[$vmeta])* $Variant { $( $(#[$fmeta])* $field: $ty ),* } ),*
        }

        impl From<$Mirror> for $Name {
            fn from(m: $Mirror) -> Self {
                match m {
                    $( $Mirror::$Variant { $( $field ),* } => $Name::$Variant { $( $field ),* } ),*
                }
            }
        }

        impl<'de> serde::Deserialize<'de> for $Name {
            fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
                let kinds: Vec<String> = [$( stringify!($Variant) ),*]
                    .iter()
                    .map(|v| $crate::spec::tagged::snake_case(v))
                    .filter(|k| !$crate::spec::tagged::LOADER_ONLY.contains(&k.as_str()))
                    .collect();
                let kinds: Vec<&str> = kinds.iter().map(String::as_str).collect();
                $crate::spec::tagged::deserialize::<D, $Mirror>(d, &kinds).map(Self::from)
            }
        }
    };
}
pub(crate) use kind_tagged;

#[cfg(test)]
mod tests {
    use super::*;

    kind_tagged! {
        #[derive(Debug, PartialEq, serde::Serialize)]
        #[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
        enum Shape via ShapeByKind {
            Square { side: f64 },
            #[serde(alias = "disc")]
            RoundThing {
                radius: f64,
                #[serde(default)]
                points: Vec<[f64; 2]>,
            },
        }
    }

    fn read(text: &str) -> Result<Shape, String> {
        #[derive(Debug, Deserialize)]
        struct Doc {
            #[allow(dead_code)]
            shape: Shape,
        }
        toml::from_str::<Doc>(text)
            .map(|d| d.shape)
            .map_err(|e| e.message().to_string())
    }

    #[test]
    fn errors_inside_a_tagged_table_name_the_key() {
        assert_eq!(
            read("shape = { kind = \"square\", side = 2 }"),
            Ok(Shape::Square { side: 2.0 })
        );
        assert_eq!(
            read("shape = { radius = 1.0, kind = \"disc\" }"),
            Ok(Shape::RoundThing {
                radius: 1.0,
                points: vec![]
            })
        );
        let e = read("shape = { kind = \"square\", side = \"a\" }").unwrap_err();
        assert!(e.starts_with("`side`: invalid type: string \"a\""), "{e}");
        let e =
            read("shape = { kind = \"round_thing\", radius = 1, points = [[0, 0], [1, \"x\"]] }")
                .unwrap_err();
        assert!(e.starts_with("`points[1][1]`: invalid type: string"), "{e}");
        let e = read("shape = { kind = \"square\", sides = 2 }").unwrap_err();
        assert!(e.starts_with("`sides`: unknown field `sides`"), "{e}");
        let e = read("shape = { kind = \"square\" }").unwrap_err();
        assert_eq!(e, "`side`: missing field `side`");
        let e = read("shape = { kind = \"triangle\" }").unwrap_err();
        assert!(e.starts_with("`kind`: unknown variant `triangle`"), "{e}");
        let e = read("shape = { side = 2 }").unwrap_err();
        assert_eq!(
            e,
            "`kind`: missing; expected one of \"square\", \"round_thing\""
        );
        let e = read("shape = { kind = 3 }").unwrap_err();
        assert!(e.starts_with("`kind`: expected a string"), "{e}");
    }

    #[test]
    fn variant_names_in_snake_case() {
        assert_eq!(snake_case("ConvexHull"), "convex_hull");
        assert_eq!(snake_case("Cuboid"), "cuboid");
    }
}
