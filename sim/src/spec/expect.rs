//! `[expect]`: what a correct run of a world shows, over one seed or several.
//!
//! ```toml
//! [expect]
//! seeds = 8                                   # the world seed and 7 seeds derived from it
//! safe = true                                 # in every seed (false: in none)
//! collided = { at_most = 1 }                  # in at most 1 of the 8 seeds
//! reaches_goal = { at_least = 7 }             # in at least 7 of the 8 seeds
//! min_clearance = { at_least = 0.12, tolerance = 0.01 }   # worst seed ≥ 0.12 − 0.01 m
//! time_to_goal = { at_most = 7.3, tolerance = 0.5 }       # worst seed ≤ 7.3 + 0.5 s
//!
//! [expect.baseline]                           # the same seeds, the baseline controller
//! safe = false
//! ```
//!
//! Event keys ([`EVENTS`]) take `true`/`false` (every seed / no seed) or a count
//! `{ at_least = K }` / `{ at_most = K }` of seeds. Metric keys ([`METRICS`]) take a margin:
//! `at_least` and/or `at_most` bound the worst seed's value, and `tolerance` (required, ≥ 0) is
//! how far beyond the bound a run may go before it counts as a regression. Both lists live next
//! to [`RunSummary`](crate::summary::RunSummary): a new summary field becomes a key by one entry
//! there. Unknown keys are errors that list the accepted ones.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::summary::{EVENTS, METRICS};

/// How many of the regression seeds must show an event.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(untagged)]
pub enum Count {
    /// `true`: every seed shows it; `false`: no seed does.
    Every(bool),
    /// At least this many seeds show it.
    AtLeast {
        /// Seeds.
        at_least: u32,
    },
    /// At most this many seeds show it.
    AtMost {
        /// Seeds.
        at_most: u32,
    },
}

impl Count {
    /// Whether `shown` of `n` seeds meets the count.
    pub fn holds(self, shown: usize, n: usize) -> bool {
        match self {
            Count::Every(true) => shown == n,
            Count::Every(false) => shown == 0,
            Count::AtLeast { at_least } => shown >= at_least as usize,
            Count::AtMost { at_most } => shown <= at_most as usize,
        }
    }

    /// Whether one run judged alone can refute the count (it can for "every" and "none", and
    /// for `at_most = 0`); the other counts only mean something over all seeds.
    pub fn per_run(self) -> bool {
        matches!(self, Count::Every(_) | Count::AtMost { at_most: 0 })
    }
}

impl std::fmt::Display for Count {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Count::Every(true) => write!(f, "in every seed"),
            Count::Every(false) => write!(f, "in no seed"),
            Count::AtLeast { at_least } => write!(f, "in at least {at_least}"),
            Count::AtMost { at_most } => write!(f, "in at most {at_most}"),
        }
    }
}

/// A numeric margin: the worst seed's value against `at_least` / `at_most`, with a tolerance.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Margin {
    /// Lower bound (the smallest value over the seeds is checked).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub at_least: Option<f64>,
    /// Upper bound (the largest value over the seeds is checked).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub at_most: Option<f64>,
    /// How far beyond a bound a value may go before it fails (≥ 0, same unit).
    pub tolerance: f64,
}

/// Expected outcome of one controller on a world, over the regression seeds.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct ExpectOutcome {
    /// Event key → how many seeds show it.
    #[serde(flatten)]
    pub counts: BTreeMap<&'static str, Count>,
    /// Metric key → margin.
    #[serde(flatten)]
    pub margins: BTreeMap<&'static str, Margin>,
}

impl ExpectOutcome {
    /// Nothing expected.
    pub fn is_empty(&self) -> bool {
        self.counts.is_empty() && self.margins.is_empty()
    }
}

/// `[expect]`: the top-level keys apply to the world's own `control.controller`;
/// `[expect.baseline]` and `[expect.nominal]` add paired runs of the comparison controllers on
/// the same seeds.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Expect {
    /// Number of seeds the expectations are judged over (default 1: the world's seed).
    pub seeds: u32,
    /// For the world's own controller.
    #[serde(flatten)]
    pub own: ExpectOutcome,
    /// For the `baseline` controller on the same world and seeds.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub baseline: Option<ExpectOutcome>,
    /// For the `nominal` controller on the same world and seeds.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub nominal: Option<ExpectOutcome>,
}

/// Upper bound of `seeds`: a regression suite, not a batch (use `ftcbf batch` for rates).
pub const MAX_SEEDS: u32 = 100;

const COUNT_FORM: &str = "true, false or a count of seeds { at_least = K } / { at_most = K }";
const MARGIN_FORM: &str =
    "a margin { at_least = X, tolerance = T } and/or { at_most = X, tolerance = T }";

fn accepted_keys(top: bool) -> String {
    let mut keys: Vec<&str> = Vec::new();
    if top {
        keys.extend(["seeds", "baseline", "nominal"]);
    }
    keys.extend(EVENTS.iter().map(|e| e.key));
    keys.extend(METRICS.iter().map(|m| m.key));
    keys.join(", ")
}

fn number(v: &toml::Value) -> Option<f64> {
    match v {
        toml::Value::Float(x) => Some(*x),
        toml::Value::Integer(i) => Some(*i as f64),
        _ => None,
    }
}

fn seed_count(key: &str, v: &toml::Value, seeds: u32) -> Result<u32, String> {
    match v {
        toml::Value::Integer(k) if (0..=i64::from(seeds)).contains(k) => Ok(*k as u32),
        toml::Value::Integer(k) => Err(format!(
            "`{key}`: expected a number of seeds between 0 and seeds = {seeds}, found {k}"
        )),
        other => Err(format!(
            "`{key}`: expected a whole number of seeds, found {}",
            other.type_str()
        )),
    }
}

fn parse_count(key: &str, v: &toml::Value, seeds: u32) -> Result<Count, String> {
    match v {
        toml::Value::Boolean(b) => Ok(Count::Every(*b)),
        toml::Value::Table(t) if t.len() == 1 => {
            let (k, v) = t.iter().next().expect("one entry");
            match k.as_str() {
                "at_least" => Ok(Count::AtLeast {
                    at_least: seed_count(&format!("{key}.at_least"), v, seeds)?,
                }),
                "at_most" => Ok(Count::AtMost {
                    at_most: seed_count(&format!("{key}.at_most"), v, seeds)?,
                }),
                other => Err(format!(
                    "`{key}`: unknown key `{other}`; expected {COUNT_FORM}"
                )),
            }
        }
        toml::Value::Table(_) => Err(format!(
            "`{key}`: expected {COUNT_FORM} (exactly one of at_least, at_most)"
        )),
        other => Err(format!(
            "`{key}`: expected {COUNT_FORM}, found {}",
            other.type_str()
        )),
    }
}

fn parse_margin(key: &str, v: &toml::Value) -> Result<Margin, String> {
    let toml::Value::Table(t) = v else {
        return Err(format!(
            "`{key}`: expected {MARGIN_FORM}, found {}",
            v.type_str()
        ));
    };
    let mut m = Margin {
        at_least: None,
        at_most: None,
        tolerance: f64::NAN,
    };
    for (k, v) in t {
        let x = number(v)
            .filter(|x| x.is_finite())
            .ok_or_else(|| format!("`{key}.{k}`: expected a finite number, found {v}"))?;
        match k.as_str() {
            "at_least" => m.at_least = Some(x),
            "at_most" => m.at_most = Some(x),
            "tolerance" if x >= 0.0 => m.tolerance = x,
            "tolerance" => {
                return Err(format!(
                    "`{key}.tolerance`: expected a number ≥ 0, found {x}"
                ))
            }
            other => {
                return Err(format!(
                    "`{key}`: unknown key `{other}`; expected at_least, at_most, tolerance"
                ))
            }
        }
    }
    if m.at_least.is_none() && m.at_most.is_none() {
        return Err(format!(
            "`{key}`: expected {MARGIN_FORM}: give at_least or at_most"
        ));
    }
    if m.tolerance.is_nan() {
        return Err(format!(
            "`{key}`: missing `tolerance` (how far beyond the bound a run may go, ≥ 0); expected {MARGIN_FORM}"
        ));
    }
    if let (Some(lo), Some(hi)) = (m.at_least, m.at_most) {
        if lo > hi {
            return Err(format!("`{key}`: at_least = {lo} is above at_most = {hi}"));
        }
    }
    Ok(m)
}

fn parse_outcome(
    prefix: &str,
    table: &toml::Table,
    seeds: u32,
    top: bool,
) -> Result<ExpectOutcome, String> {
    let mut out = ExpectOutcome::default();
    for (k, v) in table {
        let key = format!("{prefix}.{k}");
        if let Some(e) = EVENTS.iter().find(|e| e.key == k) {
            out.counts.insert(e.key, parse_count(&key, v, seeds)?);
        } else if let Some(m) = METRICS.iter().find(|m| m.key == k) {
            out.margins.insert(m.key, parse_margin(&key, v)?);
        } else if !(top && matches!(k.as_str(), "seeds" | "baseline" | "nominal")) {
            return Err(format!(
                "unknown key `{key}`; expected one of {}",
                accepted_keys(top)
            ));
        }
    }
    Ok(out)
}

impl Expect {
    /// Parses an `[expect]` table (errors name the key path and what was expected).
    pub fn from_table(table: &toml::Table) -> Result<Self, String> {
        let seeds = match table.get("seeds") {
            None => 1,
            Some(toml::Value::Integer(n)) if (1..=i64::from(MAX_SEEDS)).contains(n) => *n as u32,
            Some(v) => {
                return Err(format!(
                "`expect.seeds`: expected a whole number of seeds from 1 to {MAX_SEEDS}, found {v}"
            ))
            }
        };
        let own = parse_outcome("expect", table, seeds, true)?;
        let comparison = |name: &str| -> Result<Option<ExpectOutcome>, String> {
            match table.get(name) {
                None => Ok(None),
                Some(toml::Value::Table(t)) => {
                    parse_outcome(&format!("expect.{name}"), t, seeds, false).map(Some)
                }
                Some(v) => Err(format!(
                    "`expect.{name}`: expected a table [expect.{name}], found {}",
                    v.type_str()
                )),
            }
        };
        let baseline = comparison("baseline")?;
        let nominal = comparison("nominal")?;
        Ok(Expect {
            seeds,
            own,
            baseline,
            nominal,
        })
    }
}

impl<'de> Deserialize<'de> for Expect {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let table = toml::Table::deserialize(d)?;
        Expect::from_table(&table).map_err(serde::de::Error::custom)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Expect, String> {
        let t: toml::Table = toml::from_str(text).map_err(|e| e.to_string())?;
        Expect::from_table(&t)
    }

    #[test]
    fn counts_margins_and_comparison_tables_parse() {
        let e = parse(
            "seeds = 8\nsafe = true\ncollided = { at_most = 1 }\nreaches_goal = { at_least = 7 }\n\
             min_clearance = { at_least = 0.12, tolerance = 0.01 }\n\
             [baseline]\nsafe = false\ntime_to_goal = { at_most = 9, tolerance = 0.5 }\n",
        )
        .unwrap();
        assert_eq!(e.seeds, 8);
        assert_eq!(e.own.counts["safe"], Count::Every(true));
        assert_eq!(e.own.counts["collided"], Count::AtMost { at_most: 1 });
        assert_eq!(e.own.counts["reaches_goal"], Count::AtLeast { at_least: 7 });
        assert_eq!(e.own.margins["min_clearance"].at_least, Some(0.12));
        let b = e.baseline.unwrap();
        assert_eq!(b.counts["safe"], Count::Every(false));
        assert_eq!(b.margins["time_to_goal"].at_most, Some(9.0));
        assert!(e.nominal.is_none());
    }

    #[test]
    fn one_seed_by_default() {
        assert_eq!(parse("safe = true").unwrap().seeds, 1);
    }

    #[test]
    fn bad_tables_name_the_key_and_the_expected_form() {
        for (text, needle) in [
            ("safe = 1", "`expect.safe`: expected true, false or a count"),
            (
                "seeds = 0",
                "`expect.seeds`: expected a whole number of seeds from 1",
            ),
            (
                "seeds = 4\nsafe = { at_least = 5 }",
                "between 0 and seeds = 4",
            ),
            (
                "safe = { at_least = 1, at_most = 2 }",
                "exactly one of at_least, at_most",
            ),
            (
                "min_h = { at_least = 0.1 }",
                "`expect.min_h`: missing `tolerance`",
            ),
            ("min_h = { tolerance = 0.1 }", "give at_least or at_most"),
            ("min_h = 0.1", "`expect.min_h`: expected a margin"),
            (
                "min_h = { at_least = 0.1, tolerance = -1 }",
                "`expect.min_h.tolerance`",
            ),
            (
                "min_h = { at_least = 0.1, tolerance = 0.1, within = 2 }",
                "unknown key `within`",
            ),
            (
                "min_clearence = { at_least = 0.1, tolerance = 0 }",
                "unknown key `expect.min_clearence`; expected one of seeds",
            ),
            (
                "[baseline]\nseeds = 3",
                "unknown key `expect.baseline.seeds`",
            ),
            ("baseline = true", "expected a table [expect.baseline]"),
            (
                "time_to_goal = { at_least = 5, at_most = 4, tolerance = 0 }",
                "above at_most",
            ),
        ] {
            let e = parse(text).expect_err(text);
            assert!(e.contains(needle), "{text:?}: {e:?} lacks {needle:?}");
        }
    }

    #[test]
    fn every_registered_key_is_accepted() {
        for e in EVENTS {
            assert!(parse(&format!("{} = true", e.key)).is_ok(), "{}", e.key);
        }
        for m in METRICS {
            let text = format!("{} = {{ at_most = 1, tolerance = 0 }}", m.key);
            assert!(parse(&text).is_ok(), "{}", m.key);
        }
    }

    #[test]
    fn counts_hold_as_stated() {
        assert!(Count::Every(true).holds(8, 8) && !Count::Every(true).holds(7, 8));
        assert!(Count::Every(false).holds(0, 8) && !Count::Every(false).holds(1, 8));
        assert!(Count::AtLeast { at_least: 7 }.holds(7, 8));
        assert!(!Count::AtLeast { at_least: 7 }.holds(6, 8));
        assert!(Count::AtMost { at_most: 1 }.holds(1, 8));
        assert!(!Count::AtMost { at_most: 1 }.holds(2, 8));
    }
}
