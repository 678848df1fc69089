//! Numeric overrides of a world file by key path (`attacks[0].value=0.5`), applied to the parsed
//! TOML document before it is deserialised, so an override is validated exactly like the file.

use std::fmt;

/// One override: a key path into the world document and the number to put there. Serialised as
/// `{ key, value }` (a batch's sweep point in its JSON file).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Override {
    /// Dotted key path with array indices, e.g. `attacks[0].value` or `control.gamma`.
    pub key: String,
    /// The value to set. Written as a TOML integer when the key already holds an integer and the
    /// value is whole, as a float otherwise.
    pub value: f64,
}

impl Override {
    /// Parses `KEY=NUMBER`.
    pub fn parse(text: &str) -> Result<Self, String> {
        let (key, value) = text
            .split_once('=')
            .ok_or_else(|| format!("`{text}`: expected KEY=NUMBER, e.g. attacks[0].value=0.5"))?;
        let value: f64 = value
            .trim()
            .parse()
            .map_err(|_| format!("`{text}`: `{}` is not a number", value.trim()))?;
        if !value.is_finite() {
            return Err(format!("`{text}`: the value must be finite"));
        }
        parse_path(key.trim())?;
        Ok(Self {
            key: key.trim().to_string(),
            value,
        })
    }
}

impl fmt::Display for Override {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}={}", self.key, short_number(self.value))
    }
}

/// `v` as Rust writes it, except very large or very small magnitudes in exponent form
/// (`-1e308`, not its 309 digits).
pub fn short_number(v: f64) -> String {
    let a = v.abs();
    if a != 0.0 && !(1e-5..1e16).contains(&a) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

/// The largest whole number an override carries exactly (2⁵³: `value` is an f64).
const MAX_EXACT_WHOLE: f64 = 9_007_199_254_740_992.0;

#[derive(Debug, Clone, PartialEq)]
enum Segment {
    Key(String),
    Index(usize),
}

fn parse_path(path: &str) -> Result<Vec<Segment>, String> {
    let mut out = Vec::new();
    if path.is_empty() {
        return Err("empty key path".into());
    }
    for part in path.split('.') {
        let (name, mut rest) = match part.find('[') {
            Some(i) => (&part[..i], &part[i..]),
            None => (part, ""),
        };
        if name.is_empty()
            || !name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
        {
            return Err(format!(
                "`{path}`: `{part}` is not a key (letters, digits, _ and - optionally followed by [index])"
            ));
        }
        out.push(Segment::Key(name.to_string()));
        while !rest.is_empty() {
            let close = rest
                .find(']')
                .ok_or_else(|| format!("`{path}`: unclosed `[` in `{part}`"))?;
            let idx: usize = rest[1..close]
                .parse()
                .map_err(|_| format!("`{path}`: `{}` is not an array index", &rest[1..close]))?;
            out.push(Segment::Index(idx));
            rest = &rest[close + 1..];
            if !rest.is_empty() && !rest.starts_with('[') {
                return Err(format!("`{path}`: unexpected `{rest}` after an index"));
            }
        }
    }
    Ok(out)
}

/// Applies `ov` to `doc`. The last key may be new (the schema then checks it like any key); every
/// table and array on the way must exist.
pub(crate) fn apply(doc: &mut toml::Value, ov: &Override) -> Result<(), String> {
    let path = parse_path(&ov.key)?;
    let mut cur = doc;
    let last = path.len() - 1;
    for (i, seg) in path.iter().enumerate() {
        match seg {
            Segment::Key(k) => {
                let table = cur
                    .as_table_mut()
                    .ok_or_else(|| format!("`{}`: `{k}` is not inside a table", ov.key))?;
                if i == last {
                    let new = number_like(table.get(k), ov)?;
                    table.insert(k.clone(), new);
                    return Ok(());
                }
                cur = table
                    .get_mut(k)
                    .ok_or_else(|| format!("`{}`: no key `{k}` in the world file", ov.key))?;
            }
            Segment::Index(idx) => {
                let arr = cur.as_array_mut().ok_or_else(|| {
                    format!(
                        "`{}`: [{idx}] used on something that is not an array",
                        ov.key
                    )
                })?;
                let len = arr.len();
                let slot = arr.get_mut(*idx).ok_or_else(|| {
                    format!(
                        "`{}`: index {idx} is out of range (the array has {len} entries)",
                        ov.key
                    )
                })?;
                if i == last {
                    *slot = number_like(Some(slot), ov)?;
                    return Ok(());
                }
                cur = slot;
            }
        }
    }
    Ok(())
}

/// The override's value as the TOML value it replaces: a whole number where the file holds an
/// integer (the seed, counts) and the value is whole, refused when it is whole but beyond 2⁵³
/// (an f64 no longer carries it exactly); a float otherwise (the schema then says whether the
/// key takes one).
fn number_like(existing: Option<&toml::Value>, ov: &Override) -> Result<toml::Value, String> {
    let v = ov.value;
    match existing {
        Some(toml::Value::Integer(_)) if v.fract() == 0.0 => {
            if v.abs() <= MAX_EXACT_WHOLE {
                Ok(toml::Value::Integer(v as i64))
            } else {
                Err(format!(
                    "`{}`: the file holds a whole number there; expected a whole number within \
                     ±{MAX_EXACT_WHOLE:.0}, found {}",
                    ov.key,
                    short_number(v)
                ))
            }
        }
        _ => Ok(toml::Value::Float(v)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn doc() -> toml::Value {
        toml::from_str("seed = 3\n[[attacks]]\nvalue = 1.0\n[control]\nrate_hz = 50.0\n").unwrap()
    }

    #[test]
    fn sets_nested_and_indexed_keys() {
        let mut d = doc();
        apply(&mut d, &Override::parse("attacks[0].value=0.25").unwrap()).unwrap();
        apply(&mut d, &Override::parse("seed=7").unwrap()).unwrap();
        apply(&mut d, &Override::parse("control.gamma=0.5").unwrap()).unwrap();
        assert_eq!(d["attacks"][0]["value"].as_float(), Some(0.25));
        assert_eq!(d["seed"].as_integer(), Some(7));
        assert_eq!(d["control"]["gamma"].as_float(), Some(0.5));
    }

    /// Issue #46: `--set seed=-1e308` was echoed with 309 digits; a whole number beyond what
    /// an f64 carries exactly is refused where the file holds an integer, and numbers print
    /// short.
    #[test]
    fn a_huge_whole_number_for_an_integer_key_is_refused_and_printed_short() {
        let mut d = doc();
        let ov = Override::parse("seed=-1e308").unwrap();
        assert_eq!(ov.to_string(), "seed=-1e308");
        let e = apply(&mut d, &ov).unwrap_err();
        assert!(
            e.contains("`seed`") && e.contains("expected a whole number within ±9007199254740992"),
            "{e}"
        );
        assert!(e.contains("found -1e308") && e.len() < 200, "{e}");
        apply(&mut d, &Override::parse("seed=9007199254740992").unwrap()).unwrap();
        assert_eq!(Override::parse("x=0.5").unwrap().to_string(), "x=0.5");
        assert_eq!(Override::parse("x=3").unwrap().to_string(), "x=3");
        assert_eq!(Override::parse("x=1e-9").unwrap().to_string(), "x=1e-9");
    }

    #[test]
    fn rejects_bad_paths_with_reasons() {
        let mut d = doc();
        let e = apply(&mut d, &Override::parse("attacks[3].value=1").unwrap()).unwrap_err();
        assert!(e.contains("out of range") && e.contains("1 entries"), "{e}");
        let e = apply(&mut d, &Override::parse("nope.value=1").unwrap()).unwrap_err();
        assert!(e.contains("no key `nope`"), "{e}");
        assert!(Override::parse("attacks[x].value=1")
            .unwrap_err()
            .contains("not an array index"));
        assert!(Override::parse("seed").unwrap_err().contains("KEY=NUMBER"));
        assert!(Override::parse("seed=abc")
            .unwrap_err()
            .contains("not a number"));
        assert!(Override::parse("seed=inf").unwrap_err().contains("finite"));
    }
}
