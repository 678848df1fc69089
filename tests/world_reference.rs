//! The world-file reference lists every key the loader accepts (issue #49, item 5).
//!
//! The keys are not copied from the source: the test asks the loader. Every table refuses a key
//! it does not know and names the ones it accepts ("unknown field `zzz`, expected one of `a`,
//! `b`"), and an enum names its values the same way. So for each table of a world file the test
//! writes a small world with an unknown key in that table, loads it with `World::from_str` (what
//! `check` and `run` call), reads the accepted keys from the error, and checks that the
//! reference (`book/src/reference/world-file.md`) has a row `` | `key` | `` for each in the
//! table's section, a section for each `kind`, and each allowed value of a string key in its
//! section. A key added to the schema without a line in the reference fails here, naming it.

use std::path::Path;

use ftcbf_sim::summary::{EVENTS, METRICS};
use ftcbf_sim::world::World;
use toml::{Table, Value};

const ROOT: &str = env!("CARGO_MANIFEST_DIR");
const UNKNOWN: &str = "zzz_not_a_key";

/// A world with every table present, each with its required keys.
const BASE: &str = r#"
duration = 1.0
dynamics = "linear"

[robot]
urdf = "robot.urdf"
start = { x = 0.0, y = 0.0, theta = 0.0 }
limits = { v_max = 1.0, omega_max = 1.0, wheel_speed_max = 1.0 }

[physics]
dt = 0.005

[linear]
x0 = [0.0, 0.0, 0.0, 0.0]

[control]
rate_hz = 50.0

[control.nominal]
lookahead = 0.3

[control.drive]
low_speed = "floor"

[control.clf]
rho = 1.0

[goal]
center = [1.0, 0.0]
radius = 0.1

[[safe_sets]]
kind = "half_plane"
name = "floor"
a = [0.0, 1.0, 0.0, 0.0]
b = -1.0

[[obstacles]]
name = "box"
shape = { kind = "cuboid", half_extents = [0.1, 0.1, 0.1] }
tracker = { position_std = 0.03, rate = 10.0, attack = { bias = [0.1, 0.0] } }

[[sensors]]
name = "x"
measures = "x"
noise_std = 0.01

[[fault_patterns]]
name = "p"
channels = ["x"]

[[attacks]]
kind = "bias"
channels = ["x"]
value = 1.0

[environment]

[expect]
seeds = 1

[falsify]
noise = 0.1
"#;

fn base() -> Table {
    toml::from_str(BASE).expect("the base world is TOML")
}

/// The table at `path` (`control.drive`, `attacks.0`, `obstacles.0.shape`; "" for the root).
/// An array of tables stands for its first entry (the `.0`).
fn table_at<'a>(root: &'a mut Table, path: &str) -> &'a mut Table {
    let mut t = root;
    for seg in path.split('.').filter(|s| !s.is_empty() && *s != "0") {
        let v = t
            .get_mut(seg)
            .unwrap_or_else(|| panic!("no `{seg}` in {path}"));
        t = match v {
            Value::Table(t) => t,
            Value::Array(a) => match a.get_mut(0) {
                Some(Value::Table(t)) => t,
                _ => panic!("`{seg}` is not an array of tables"),
            },
            _ => panic!("`{seg}` is not a table"),
        };
    }
    t
}

/// Loads `world` and returns the loader's error (the world must be refused).
fn refusal(world: &Table) -> String {
    let text = toml::to_string(world).expect("serialises");
    match World::from_str(&text, Path::new("reference_probe.toml"), &[]) {
        Ok(_) => panic!("the loader accepted a world it should refuse:\n{text}"),
        Err(e) => e.to_string(),
    }
}

/// The names in backquotes after "expected" in a serde message: the accepted keys or values.
fn accepted(message: &str, probe: &str) -> Vec<String> {
    assert!(
        message.contains(probe),
        "the loader's error is not about the probe `{probe}`: {message}"
    );
    let Some(at) = message.find("expected") else {
        if message.contains("there are no fields") {
            return Vec::new();
        }
        panic!("the error names no accepted keys: {message}");
    };
    // serde names the accepted values in backticks; a hand-written message (a stealthy
    // attack's `direction`) in double quotes, as a TOML string is written.
    let tail = message[at..].lines().next().unwrap_or_default();
    let quote = if tail.contains('`') { '`' } else { '"' };
    tail.split(quote)
        .skip(1)
        .step_by(2)
        .map(str::to_string)
        .collect()
}

/// The keys a table accepts: its unknown-key error, with `kind` for a tagged table.
fn keys_of(mut world: Table, path: &str) -> Vec<String> {
    table_at(&mut world, path).insert(UNKNOWN.into(), Value::Integer(1));
    accepted(&refusal(&world), UNKNOWN)
}

/// The values a string key accepts: the error for a value that is none of them.
fn values_of(mut world: Table, path: &str, key: &str) -> Vec<String> {
    table_at(&mut world, path).insert(key.into(), Value::String(UNKNOWN.into()));
    accepted(&refusal(&world), UNKNOWN)
}

/// `world` with the first entry of `array` replaced by a table of `kind` and `extra` keys.
fn with_kind(array: &str, kind: &str, extra: &[(&str, Value)]) -> Table {
    let mut w = base();
    let mut t = Table::new();
    t.insert("kind".into(), Value::String(kind.into()));
    for (k, v) in extra {
        t.insert((*k).into(), v.clone());
    }
    match array {
        "obstacles.0.shape" => {
            table_at(&mut w, "obstacles.0").insert("shape".into(), Value::Table(t));
        }
        "obstacles.0.motion" => {
            table_at(&mut w, "obstacles.0").insert("motion".into(), Value::Table(t));
        }
        _ => {
            w.insert(array.into(), Value::Array(vec![Value::Table(t)]));
        }
    }
    w
}

struct Reference {
    text: String,
}

impl Reference {
    fn load() -> Self {
        let path = Path::new(ROOT).join("book/src/reference/world-file.md");
        Reference {
            text: std::fs::read_to_string(path).expect("the world-file reference"),
        }
    }

    /// The section under the heading that is exactly `heading`, to the next heading of the
    /// same or a higher level.
    fn section(&self, heading: &str) -> &str {
        let level = heading.chars().take_while(|c| *c == '#').count();
        let start = self
            .text
            .lines()
            .position(|l| l.trim_end() == heading)
            .unwrap_or_else(|| panic!("the reference has no heading {heading:?}"));
        let lines: Vec<&str> = self.text.lines().collect();
        let end = lines[start + 1..]
            .iter()
            .position(|l| {
                let n = l.chars().take_while(|c| *c == '#').count();
                n > 0 && n <= level && l.chars().nth(n) == Some(' ')
            })
            .map_or(lines.len(), |i| start + 1 + i);
        let from = self
            .text
            .match_indices('\n')
            .nth(start)
            .map_or(0, |(i, _)| i + 1);
        let to = self
            .text
            .match_indices('\n')
            .nth(end.saturating_sub(1))
            .map_or(self.text.len(), |(i, _)| i);
        &self.text[from..to.max(from)]
    }

    /// Keys of `keys` with no table row `` | `key` | `` in any of `headings`' sections.
    fn missing_rows(&self, headings: &[&str], keys: &[String]) -> Vec<String> {
        keys.iter()
            .filter(|k| {
                let row = format!("| `{k}` |");
                !headings
                    .iter()
                    .any(|h| self.section(h).lines().any(|l| l.starts_with(&row)))
            })
            .map(|k| format!("`{k}` (in {headings:?})"))
            .collect()
    }
}

const TABLES: [(&str, &str); 17] = [
    ("", "## Top level"),
    ("robot", "## `[robot]`"),
    ("robot.start", "### `[robot.start]`"),
    ("robot.limits", "### `[robot.limits]`"),
    ("physics", "## `[physics]`"),
    ("linear", "## `[linear]`"),
    ("control", "## `[control]`"),
    ("control.nominal", "### `[control.nominal]`"),
    ("control.drive", "### `[control.drive]`"),
    ("control.clf", "### `[control.clf]`"),
    ("goal", "## `[goal]`"),
    ("obstacles.0", "## `[[obstacles]]`"),
    ("obstacles.0.tracker", "### Obstacle `tracker`"),
    (
        "obstacles.0.tracker.attack",
        "### Obstacle `tracker.attack`",
    ),
    ("sensors.0", "## `[[sensors]]`"),
    ("fault_patterns.0", "## `[[fault_patterns]]`"),
    ("environment", "## `[environment]`"),
];

#[test]
fn every_key_of_every_table_is_in_the_reference() {
    let r = Reference::load();
    let mut missing = Vec::new();
    let mut seen = 0;
    for (path, heading) in TABLES {
        let keys = keys_of(base(), path);
        assert!(!keys.is_empty(), "`{path}`: the loader named no keys");
        seen += keys.len();
        missing.extend(r.missing_rows(&[heading], &keys));
    }
    let falsify = keys_of(base(), "falsify");
    seen += falsify.len();
    missing.extend(r.missing_rows(&["## `[falsify]`"], &falsify));
    // `[expect]` is read by its own parser, from the summary's lists of events and metrics.
    let mut expect: Vec<String> = ["seeds", "baseline", "nominal"].map(String::from).to_vec();
    expect.extend(EVENTS.iter().map(|e| e.key.to_string()));
    expect.extend(METRICS.iter().map(|m| m.key.to_string()));
    seen += expect.len();
    missing.extend(r.missing_rows(&["## `[expect]`"], &expect));
    assert!(seen > 90, "only {seen} keys read from the loader");
    assert!(
        missing.is_empty(),
        "keys the loader accepts but the reference does not list:\n{}",
        missing.join("\n")
    );
}

#[test]
fn every_kind_and_its_keys_are_in_the_reference() {
    let r = Reference::load();
    let mut missing = Vec::new();
    for (array, what, common, table) in [
        ("safe_sets", "Safe set kind", None, "## `[[safe_sets]]`"),
        (
            "obstacles.0.shape",
            "Shape kind",
            None,
            "## `[[obstacles]]`",
        ),
        (
            "obstacles.0.motion",
            "Motion kind",
            None,
            "## `[[obstacles]]`",
        ),
        (
            "attacks",
            "Attack kind",
            Some("## `[[attacks]]`"),
            "## `[[attacks]]`",
        ),
    ] {
        let kinds = values_of(with_kind(array, "bias", &[]), array, "kind");
        assert!(kinds.len() >= 3, "{array}: kinds {kinds:?}");
        for kind in &kinds {
            let heading = format!("### {what} `{kind}`");
            if !r.text.lines().any(|l| l.trim_end() == heading) {
                // Another spelling of a kind (serde lists aliases too) is named in the table's
                // section (`kind = "drift"`); any other kind needs its own section.
                if !r.section(table).contains(&format!("kind = \"{kind}\"")) {
                    missing.push(format!(
                        "a section {heading:?} (or, for another spelling of a kind, \
                         `kind = \"{kind}\"` in {table:?})"
                    ));
                }
                continue;
            }
            let mut w = with_kind(array, kind, &[]);
            let path = if array.starts_with("obstacles.0.") {
                array.to_string()
            } else {
                format!("{array}.0")
            };
            table_at(&mut w, &path).insert(UNKNOWN.into(), Value::Integer(1));
            let keys = accepted(&refusal(&w), UNKNOWN);
            let mut headings = vec![heading.as_str()];
            headings.extend(common);
            if array != "attacks" {
                // the tag itself has a row in each kind's table
                missing.extend(r.missing_rows(&headings, &["kind".to_string()]));
            }
            missing.extend(r.missing_rows(&headings, &keys));
        }
    }
    assert!(
        missing.is_empty(),
        "kinds or keys the loader accepts but the reference does not list:\n{}",
        missing.join("\n")
    );
}

#[test]
fn every_allowed_value_of_a_string_key_is_in_the_reference() {
    let r = Reference::load();
    let stealthy = with_kind(
        "attacks",
        "stealthy",
        &[
            ("channels", Value::Array(vec![Value::String("x".into())])),
            ("max_rate", Value::Float(0.1)),
            ("threshold", Value::Float(3.0)),
        ],
    );
    let non_finite = with_kind(
        "attacks",
        "non_finite",
        &[("channels", Value::Array(vec![Value::String("x".into())]))],
    );
    let waypoints = with_kind(
        "obstacles.0.motion",
        "waypoints",
        &[
            (
                "points",
                Value::Array(vec![Value::Array(vec![
                    Value::Float(1.0),
                    Value::Float(0.0),
                ])]),
            ),
            ("speed", Value::Float(0.1)),
        ],
    );
    let cases: Vec<(Table, &str, &str, &str)> = vec![
        (
            waypoints,
            "obstacles.0.motion",
            "repeat",
            "### Motion kind `waypoints`",
        ),
        (base(), "", "dynamics", "## Top level"),
        (base(), "control", "controller", "## `[control]`"),
        (base(), "control", "form", "## `[control]`"),
        (base(), "control", "bounds", "## `[control]`"),
        (base(), "control", "process_model", "## `[control]`"),
        (
            base(),
            "control.drive",
            "low_speed",
            "### `[control.drive]`",
        ),
        (base(), "goal", "metric", "## `[goal]`"),
        (base(), "sensors.0", "measures", "## `[[sensors]]`"),
        (
            stealthy,
            "attacks.0",
            "direction",
            "### Attack kind `stealthy`",
        ),
        (
            non_finite,
            "attacks.0",
            "value",
            "### Attack kind `non_finite`",
        ),
    ];
    let mut missing = Vec::new();
    for (world, path, key, heading) in cases {
        let values = values_of(world, path, key);
        assert!(values.len() >= 2, "`{path}.{key}`: values {values:?}");
        let section = r.section(heading);
        for v in values {
            if !section.contains(&format!("\"{v}\"")) {
                missing.push(format!("`{key} = \"{v}\"` in {heading:?}"));
            }
        }
    }
    assert!(
        missing.is_empty(),
        "values the loader accepts but the reference does not show:\n{}",
        missing.join("\n")
    );
}

#[test]
fn the_reference_check_notices_a_missing_row() {
    // The checker itself: a key that is not in a section is reported, one that is is not.
    let r = Reference {
        text: "## `[goal]`\n\n| key | type |\n|---|---|\n| `center` | float |\n\n## `[x]`\n\n| `radius` | float |\n"
            .to_string(),
    };
    let keys = ["center".to_string(), "radius".to_string()];
    assert_eq!(
        r.missing_rows(&["## `[goal]`"], &keys),
        vec!["`radius` (in [\"## `[goal]`\"])".to_string()]
    );
}
