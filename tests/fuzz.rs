//! Issue #29: a seeded mutation fuzz of world and robot files, in process, on stable Rust.
//!
//! Each input is a catalogue world (worlds/*.toml) with one to three mutations — a number set to
//! an extreme (0, −x, ±1e308, 1e-320, 5e-324, NaN, ±∞, x·1e±6), a key deleted, an entry of an
//! array of tables duplicated — and, for a quarter of the robot worlds, one number of the robot's
//! URDF set to an extreme as well. Half the mutations aim at the keys added since (#46):
//! waypoints (near, at ±5000 m, at the ±1e4 m edge, the 256 cap within ±50 m, non-finite),
//! sensor rates and dropouts, `from_wheels` (two, three or one entries, swapped, unknown), an STL
//! obstacle (wound outward, inward or mixed, open, degenerate, not an STL), replay and stealthy
//! attacks, `[expect]` keys (judged on the run as `ftcbf run` judges them). Every input goes
//! through what the CLI does: load and validate, `check`, the run's preflight and a short run.
//! The properties:
//!
//! - no panic anywhere (a panic is caught and counted, with the input that caused it);
//! - no input over the time bound ([`TIME_BOUND`], a hang is counted and the input named);
//! - no SAFE summary with a non-finite barrier value, clearance or state, and no "Theorem 3
//!   applies" with a NaN or ∞ in a hypothesis or a parameter;
//! - `check` and `run` agree on validity (both accept the world or both refuse it);
//! - no SAFE next to a safe-set barrier below 0, a collision, or a barrier/physics disagreement
//!   (such a run has no verdict; these are counted and printed, as are SAFE runs whose lifted
//!   obstacle barrier dipped below 0 inside its margin without contact).
//!
//! CI runs [`DEFAULT_INPUTS`] inputs (well under a minute in release); `FTCBF_FUZZ_N=10000`
//! runs more, `FTCBF_FUZZ_SEED` picks another seed. The README ("Fuzzing") has the last large
//! run's numbers.

use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use toml_edit::{DocumentMut, Item, Value};

use ftcbf_sim::analysis::check::check_world;
use ftcbf_sim::analysis::expectations::{expectation_for, failures_of_run};
use ftcbf_sim::runner::{preflight, run, RunOptions};
use ftcbf_sim::summary::NamedValue;
use ftcbf_sim::world::World;

#[path = "common/mesh.rs"]
mod mesh;
use mesh::{cube, stl_text};

/// Inputs per CI run.
const DEFAULT_INPUTS: usize = 120;
/// Seed of the CI run.
const DEFAULT_SEED: u64 = 29;
/// An input taking longer than this (load + check + preflight + a 0.25 s run) is a hang.
const TIME_BOUND: Duration = Duration::from_secs(30);
/// Simulated seconds of each input's run.
const RUN_SECONDS: f64 = 0.25;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// One step of a path into a TOML document.
#[derive(Debug, Clone)]
enum Seg {
    Key(String),
    Index(usize),
}

fn show(path: &[Seg]) -> String {
    let mut s = String::new();
    for seg in path {
        match seg {
            Seg::Key(k) => {
                if !s.is_empty() {
                    s.push('.');
                }
                s.push_str(k);
            }
            Seg::Index(i) => s.push_str(&format!("[{i}]")),
        }
    }
    s
}

/// Paths of the document's numbers, of every key (deletable), and of every array of tables.
#[derive(Default)]
struct Paths {
    numbers: Vec<Vec<Seg>>,
    keys: Vec<Vec<Seg>>,
    table_arrays: Vec<Vec<Seg>>,
}

fn walk_item(item: &Item, path: &mut Vec<Seg>, out: &mut Paths) {
    match item {
        Item::Table(t) => {
            for (k, v) in t.iter() {
                path.push(Seg::Key(k.to_string()));
                out.keys.push(path.clone());
                walk_item(v, path, out);
                path.pop();
            }
        }
        Item::ArrayOfTables(a) => {
            out.table_arrays.push(path.clone());
            for (i, t) in a.iter().enumerate() {
                path.push(Seg::Index(i));
                for (k, v) in t.iter() {
                    path.push(Seg::Key(k.to_string()));
                    out.keys.push(path.clone());
                    walk_item(v, path, out);
                    path.pop();
                }
                path.pop();
            }
        }
        Item::Value(v) => walk_value(v, path, out),
        Item::None => {}
    }
}

fn walk_value(v: &Value, path: &mut Vec<Seg>, out: &mut Paths) {
    match v {
        Value::Integer(_) | Value::Float(_) => out.numbers.push(path.clone()),
        Value::Array(a) => {
            for (i, e) in a.iter().enumerate() {
                path.push(Seg::Index(i));
                walk_value(e, path, out);
                path.pop();
            }
        }
        Value::InlineTable(t) => {
            for (k, e) in t.iter() {
                path.push(Seg::Key(k.to_string()));
                out.keys.push(path.clone());
                walk_value(e, path, out);
                path.pop();
            }
        }
        _ => {}
    }
}

fn at<'a>(doc: &'a mut DocumentMut, path: &[Seg]) -> &'a mut Item {
    let mut cur = doc.as_item_mut();
    for seg in path {
        cur = match seg {
            Seg::Key(k) => &mut cur[k.as_str()],
            Seg::Index(i) => &mut cur[*i],
        };
    }
    cur
}

/// An extreme replacement for the number `x`.
fn extreme(rng: &mut ChaCha8Rng, x: f64) -> f64 {
    match rng.random_range(0..13) {
        0 => 0.0,
        1 => -x,
        2 => 1e308,
        3 => -1e308,
        4 => 1e-320,
        5 => 5e-324,
        6 => f64::NAN,
        7 => f64::INFINITY,
        8 => f64::NEG_INFINITY,
        9 => x * 1e6,
        10 => x * 1e-6,
        11 => 1e300,
        _ => -1e-300,
    }
}

/// Applies one random mutation to `doc`; returns what it did.
fn mutate(doc: &mut DocumentMut, rng: &mut ChaCha8Rng) -> String {
    let mut paths = Paths::default();
    walk_item(doc.as_item(), &mut Vec::new(), &mut paths);
    let choice = rng.random_range(0..10);
    if choice < 7 && !paths.numbers.is_empty() {
        let p = &paths.numbers[rng.random_range(0..paths.numbers.len())];
        let item = at(doc, p);
        let old = item
            .as_float()
            .or_else(|| item.as_integer().map(|i| i as f64))
            .unwrap_or(1.0);
        if item.is_integer() && rng.random_bool(0.5) {
            let v: i64 = match rng.random_range(0..4) {
                0 => 0,
                1 => -1,
                2 => i64::MAX,
                _ => -(old as i64),
            };
            *item = toml_edit::value(v);
            return format!("{} = {v}", show(p));
        }
        let v = extreme(rng, old);
        *item = toml_edit::value(v);
        return format!("{} = {v:e}", show(p));
    }
    if choice < 9 && !paths.keys.is_empty() {
        let p = paths.keys[rng.random_range(0..paths.keys.len())].clone();
        let (last, parent) = p.split_last().expect("a key path is not empty");
        let Seg::Key(k) = last else {
            return "no-op".into();
        };
        let parent = at(doc, parent);
        if let Some(t) = parent.as_table_like_mut() {
            t.remove(k);
        }
        return format!("delete {}", show(&p));
    }
    if !paths.table_arrays.is_empty() {
        let p = paths.table_arrays[rng.random_range(0..paths.table_arrays.len())].clone();
        if let Some(a) = at(doc, &p).as_array_of_tables_mut() {
            if !a.is_empty() {
                let i = rng.random_range(0..a.len());
                let t = a.get(i).cloned();
                if let Some(t) = t {
                    a.push(t);
                    return format!("duplicate {}[{i}]", show(&p));
                }
            }
        }
    }
    "no-op".into()
}

/// A number for a key added since #29: mostly ordinary, sometimes at or past its range.
fn wild(rng: &mut ChaCha8Rng, typical: f64) -> f64 {
    match rng.random_range(0..8) {
        0..=3 => typical * rng.random_range(0.0..2.0),
        _ => extreme(rng, typical),
    }
}

/// A waypoint list: a few points near the route, far ones (±5000 m, ±1e4 m: the documented
/// range's edge), up to the 256 cap within ±50 m, or non-finite coordinates.
fn waypoints(rng: &mut ChaCha8Rng) -> (Value, String) {
    let (n, span, what) = match rng.random_range(0..5) {
        0 => (rng.random_range(1..=4), 3.0, "near"),
        1 => (rng.random_range(1..=3), 5000.0, "±5000 m"),
        2 => (1, 1.0e4, "±1e4 m"),
        3 => (256, 50.0, "256 within ±50 m"),
        _ => (rng.random_range(1..=3), f64::NAN, "non-finite"),
    };
    let mut arr = toml_edit::Array::new();
    for _ in 0..n {
        let mut p = toml_edit::Array::new();
        for _ in 0..2 {
            let v = if span.is_nan() {
                extreme(rng, 1.0)
            } else if span == 1.0e4 {
                if rng.random_bool(0.5) {
                    1.0e4
                } else {
                    -1.0e4
                }
            } else {
                rng.random_range(-span..=span)
            };
            p.push(v);
        }
        arr.push(p);
    }
    (Value::Array(arr), format!("goal.waypoints: {n} {what}"))
}

/// An STL obstacle file: a cube wound outward, inward, at random per triangle, open (a face
/// missing), degenerate, or not an STL at all; returns the file's note.
fn stl_file(rng: &mut ChaCha8Rng, path: &Path) -> String {
    let (v, mut t) = cube([0.0, 0.0, 0.15], 0.15);
    let what = match rng.random_range(0..6) {
        0 => "outward",
        1 => {
            t.iter_mut().for_each(|x| x.swap(1, 2));
            "inward"
        }
        2 => {
            t.iter_mut().for_each(|x| {
                if rng.random_bool(0.5) {
                    x.swap(1, 2);
                }
            });
            "mixed winding"
        }
        3 => {
            t.truncate(10);
            "open"
        }
        4 => {
            t.iter_mut().for_each(|x| x[2] = x[1]);
            "degenerate"
        }
        _ => {
            let _ = std::fs::write(path, "solid broken\nfacet normal 0 0\n");
            return "not an STL".into();
        }
    };
    let _ = std::fs::write(path, stl_text("fuzz", &v, &t));
    what.into()
}

/// The channel names of the document's `[[sensors]]`, with what each measures.
fn channels(doc: &DocumentMut) -> Vec<(String, String)> {
    doc.get("sensors")
        .and_then(Item::as_array_of_tables)
        .map(|a| {
            a.iter()
                .filter_map(|t| {
                    Some((
                        t.get("name")?.as_str()?.to_string(),
                        t.get("measures")?.as_str()?.to_string(),
                    ))
                })
                .collect()
        })
        .unwrap_or_default()
}

/// Appends `[[name]]` `table` to the document.
fn push_table(doc: &mut DocumentMut, name: &str, table: toml_edit::Table) {
    if doc.get(name).and_then(Item::as_array_of_tables).is_none() {
        doc[name] = Item::ArrayOfTables(toml_edit::ArrayOfTables::new());
    }
    if let Some(a) = doc[name].as_array_of_tables_mut() {
        a.push(table);
    }
}

/// A replay or stealthy attack on a random channel, with parameters in and out of range.
fn attack(doc: &mut DocumentMut, rng: &mut ChaCha8Rng) -> String {
    let names = channels(doc);
    if names.is_empty() {
        return "no channels: no attack".into();
    }
    let (ch, _) = &names[rng.random_range(0..names.len())];
    let mut t = toml_edit::Table::new();
    let mut a = toml_edit::Array::new();
    a.push(ch.as_str());
    t["channels"] = toml_edit::value(a);
    let start = wild(rng, 3.0);
    t["start"] = toml_edit::value(start);
    if rng.random_bool(0.5) {
        t["kind"] = toml_edit::value("replay");
        let record_start = match rng.random_range(0..4) {
            0 => -1.0,
            1 => 0.0,
            2 => start,
            _ => wild(rng, 1.0),
        };
        t["record_start"] = toml_edit::value(record_start);
        t["length"] = toml_edit::value(wild(rng, 1.0));
        push_table(doc, "attacks", t);
        return format!("replay on {ch} from {start:e}, record_start {record_start:e}");
    }
    t["kind"] = toml_edit::value("stealthy");
    t["max_rate"] = toml_edit::value(wild(rng, 0.05));
    t["threshold"] = toml_edit::value(wild(rng, 3.0));
    t["max_bias"] = toml_edit::value(wild(rng, 0.5));
    match rng.random_range(0..4) {
        0 => t["direction"] = toml_edit::value("positive"),
        1 => t["direction"] = toml_edit::value("negative"),
        2 => {
            let mut d = toml_edit::Array::new();
            d.push(1.0);
            d.push(-1.0);
            t["direction"] = toml_edit::value(d);
        }
        _ => {}
    }
    push_table(doc, "attacks", t);
    format!("stealthy on {ch} from {start:e}")
}

/// `from_wheels` on a speed or yaw-rate channel: a correct pair, three entries, one, swapped,
/// or an unknown name.
fn from_wheels(doc: &mut DocumentMut, rng: &mut ChaCha8Rng) -> String {
    let names = channels(doc);
    let wheel = |m: &str| names.iter().find(|(_, q)| q == m).map(|(n, _)| n.clone());
    let (l, r) = (
        wheel("wheel_left").unwrap_or_else(|| "enc_left".into()),
        wheel("wheel_right").unwrap_or_else(|| "enc_right".into()),
    );
    let list: Vec<String> = match rng.random_range(0..5) {
        0 => vec![l, r],
        1 => vec![l.clone(), r, l],
        2 => vec![l],
        3 => vec![r, l],
        _ => vec![l, "no_such_channel".into()],
    };
    let Some(sensors) = doc
        .get_mut("sensors")
        .and_then(Item::as_array_of_tables_mut)
    else {
        return "no sensors: no from_wheels".into();
    };
    let n = sensors.len();
    let i = rng.random_range(0..n);
    let Some(t) = sensors.get_mut(i) else {
        return "no sensor".into();
    };
    let mut a = toml_edit::Array::new();
    for s in &list {
        a.push(s.as_str());
    }
    t["from_wheels"] = toml_edit::value(a);
    format!("sensors[{i}].from_wheels = {list:?}")
}

/// One mutation of a key added since the harness was written (#46): waypoints, a sensor's rate
/// or dropout, `from_wheels`, an STL obstacle, a replay or stealthy attack, an `[expect]` key.
fn mutate_new_keys(doc: &mut DocumentMut, rng: &mut ChaCha8Rng, stl: &Path) -> String {
    match rng.random_range(0..7) {
        0 => {
            let (v, what) = waypoints(rng);
            doc["goal"]["waypoints"] = Item::Value(v);
            what
        }
        1 | 2 => {
            let n = doc
                .get("sensors")
                .and_then(Item::as_array_of_tables)
                .map_or(0, |a| a.len());
            if n == 0 {
                return "no sensors".into();
            }
            let i = rng.random_range(0..n);
            let (key, v) = if rng.random_bool(0.5) {
                ("rate_hz", wild(rng, 10.0))
            } else {
                let p = match rng.random_range(0..4) {
                    0 => 1.0,
                    1 => 0.999_999,
                    2 => rng.random_range(0.0..0.5),
                    _ => extreme(rng, 0.1),
                };
                ("dropout_prob", p)
            };
            doc["sensors"][i][key] = toml_edit::value(v);
            format!("sensors[{i}].{key} = {v:e}")
        }
        3 => from_wheels(doc, rng),
        4 => {
            let what = stl_file(rng, stl);
            let mut t = toml_edit::Table::new();
            t["name"] = toml_edit::value("fuzz_mesh");
            let mut pos = toml_edit::Array::new();
            pos.push(rng.random_range(-1.0..2.0));
            pos.push(rng.random_range(-1.0..1.0));
            pos.push(0.0);
            t["position"] = toml_edit::value(pos);
            let mut shape = toml_edit::InlineTable::new();
            shape.insert("kind", "tri_mesh".into());
            shape.insert("file", stl.display().to_string().into());
            if rng.random_bool(0.3) {
                shape.insert("scale", wild(rng, 1.0).into());
            }
            t["shape"] = toml_edit::value(shape);
            push_table(doc, "obstacles", t);
            format!("STL obstacle ({what})")
        }
        5 => attack(doc, rng),
        _ => {
            let keys = ["seeds", "min_h", "min_clearance", "time_to_goal", "safe"];
            let k = keys[rng.random_range(0..keys.len())];
            let v = match k {
                "seeds" => toml_edit::value(rng.random_range(-2..40i64)),
                "safe" => toml_edit::value(rng.random_bool(0.5)),
                _ => {
                    let mut m = toml_edit::InlineTable::new();
                    let side = if rng.random_bool(0.5) {
                        "at_least"
                    } else {
                        "at_most"
                    };
                    m.insert(side, extreme(rng, 0.1).into());
                    if rng.random_bool(0.5) {
                        m.insert("tolerance", extreme(rng, 0.01).into());
                    }
                    toml_edit::value(m)
                }
            };
            if doc.get("expect").is_none() {
                doc["expect"] = toml_edit::table();
            }
            doc["expect"][k] = v;
            format!("expect.{k} mutated")
        }
    }
}

/// Sets one number in an attribute of the URDF `text` to an extreme.
fn mutate_urdf(text: &str, rng: &mut ChaCha8Rng) -> (String, String) {
    // Byte ranges of numeric tokens inside attribute values ("…").
    let mut spans = Vec::new();
    let bytes = text.as_bytes();
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'=' && i + 1 < bytes.len() && bytes[i + 1] == b'"' {
            let start = i + 2;
            let Some(len) = text[start..].find('"') else {
                break;
            };
            let value = &text[start..start + len];
            let mut off = 0;
            for tok in value.split(' ') {
                if !tok.is_empty() && tok.parse::<f64>().is_ok() {
                    spans.push((start + off, start + off + tok.len()));
                }
                off += tok.len() + 1;
            }
            i = start + len + 1;
        } else {
            i += 1;
        }
    }
    if spans.is_empty() {
        return (text.to_string(), "urdf no-op".into());
    }
    let (a, b) = spans[rng.random_range(0..spans.len())];
    let old: f64 = text[a..b].parse().unwrap_or(1.0);
    let v = extreme(rng, old);
    let line = text[..a].matches('\n').count() + 1;
    let mut out = String::with_capacity(text.len() + 16);
    out.push_str(&text[..a]);
    out.push_str(&format!("{v:e}"));
    out.push_str(&text[b..]);
    (out, format!("urdf line {line}: {} → {v:e}", &text[a..b]))
}

/// What one input did.
#[derive(Debug)]
enum Outcome {
    /// Refused by load/validation or by both check and run (a clean error).
    Invalid,
    /// Accepted and run.
    Ran(Ran),
    /// A property failed (the message says which).
    Violation(String),
}

/// What a run that was carried out showed, beyond the properties.
#[derive(Debug, Default, Clone, Copy)]
struct Ran {
    /// No verdict: its barrier and physics disagreed (a typed outcome, not a violation).
    no_verdict: bool,
    /// SAFE with an obstacle barrier below 0 (its margin or velocity lift; no contact).
    safe_below_obstacle_margin: bool,
}

/// The hypotheses and numbers of a check report that show a non-finite number.
fn non_finite_word(text: &str) -> bool {
    text.split(|c: char| !(c.is_alphanumeric() || c == '_'))
        .any(|w| w == "NaN" || w == "inf")
}

fn evaluate(text: &str, path: &Path) -> Outcome {
    let world = match World::from_str(text, path, &[]) {
        Ok(w) => w,
        Err(e) => {
            let msg = e.to_string();
            if msg.is_empty() {
                return Outcome::Violation("an empty error message".into());
            }
            return Outcome::Invalid;
        }
    };
    let check = check_world(&world);
    let pre = preflight(&world);
    match (&check, &pre) {
        (Ok(_), Ok(())) => {}
        (Err(_), Err(_)) => return Outcome::Invalid,
        (Ok(_), Err(e)) => {
            return Outcome::Violation(format!("check accepts, run refuses: {e}"));
        }
        (Err(e), Ok(())) => {
            return Outcome::Violation(format!("run accepts, check refuses: {e}"));
        }
    }
    let report = check.expect("matched Ok above");
    if report.verdict.applies {
        for h in &report.hypotheses {
            if non_finite_word(&h.detail) {
                return Outcome::Violation(format!(
                    "Theorem 3 applies with a non-finite number in `{}`: {}",
                    h.name, h.detail
                ));
            }
        }
    }
    let opts = RunOptions {
        duration: Some(RUN_SECONDS.min(world.file.duration)),
        ..RunOptions::default()
    };
    match run(&world, &opts) {
        Err(e) => Outcome::Violation(format!("preflight passed but the run refused: {e}")),
        Ok(s) => {
            // The world's `[expect]` judged on the run, as `ftcbf run` does (no panic).
            if let Some(e) = expectation_for(&world, world.file.control.controller) {
                let _ = failures_of_run(&e, &s);
            }
            let finite = s.min_barrier.iter().all(|b| b.value.is_finite())
                && s.min_clearance.is_none_or(f64::is_finite)
                && s.final_state.iter().all(|v| v.is_finite());
            let obstacle = |b: &&NamedValue| b.name.starts_with("obstacle:");
            let negative_set = s.min_barrier.iter().find(|b| !obstacle(b) && b.value < 0.0);
            if s.safe && !finite {
                Outcome::Violation(format!(
                    "SAFE with a non-finite number: min_barrier {:?}, clearance {:?}, final state {:?}",
                    s.min_barrier, s.min_clearance, s.final_state
                ))
            } else if !finite && s.non_finite.is_none() {
                Outcome::Violation("a non-finite number the summary does not name".into())
            } else if s.safe && (negative_set.is_some() || s.collided || s.disagreement.is_some()) {
                Outcome::Violation(format!(
                    "SAFE next to a negative barrier, a collision or a disagreement: min_barrier {:?}, collided {}, disagreement {:?}",
                    s.min_barrier, s.collided, s.disagreement
                ))
            } else {
                Outcome::Ran(Ran {
                    no_verdict: s.disagreement.is_some(),
                    safe_below_obstacle_margin: s.safe
                        && s.min_barrier.iter().any(|b| obstacle(&b) && b.value < 0.0),
                })
            }
        }
    }
}

/// The counts of a fuzz run.
#[derive(Debug, Default)]
struct Tally {
    inputs: usize,
    invalid: usize,
    ran: usize,
    no_verdict: usize,
    safe_below_obstacle_margin: usize,
    panics: Vec<String>,
    hangs: Vec<String>,
    violations: Vec<String>,
    slowest: (f64, String),
}

/// Runs input `k` of the campaign with `seed`: the world it mutates and what it found.
fn one_input(
    seed: u64,
    k: usize,
    worlds: &[(PathBuf, String)],
    scratch: &Path,
) -> (String, Result<Outcome, String>, f64) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ (k as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
    let (path, text) = &worlds[rng.random_range(0..worlds.len())];
    let mut doc: DocumentMut = text.parse().expect("catalogue worlds parse");
    let mut what = vec![format!("{}", path.display())];
    let stl = scratch.join(format!("input_{seed}_{k}.stl"));
    for _ in 0..rng.random_range(1..=3) {
        // Half the mutations aim at the keys added since #29 (#46).
        let m = if rng.random_bool(0.5) {
            mutate_new_keys(&mut doc, &mut rng, &stl)
        } else {
            mutate(&mut doc, &mut rng)
        };
        what.push(m);
    }
    let urdf = doc
        .get("robot")
        .and_then(|r| r.get("urdf"))
        .and_then(|u| u.as_str())
        .map(str::to_string);
    if let Some(rel) = urdf {
        if rng.random_bool(0.25) {
            let src = path.parent().expect("in worlds/").join(rel);
            if let Ok(xml) = std::fs::read_to_string(&src) {
                let (mutated, note) = mutate_urdf(&xml, &mut rng);
                let out = scratch.join(format!("input_{seed}_{k}.urdf"));
                if std::fs::write(&out, mutated).is_ok() {
                    doc["robot"]["urdf"] = toml_edit::value(out.display().to_string());
                    what.push(note);
                }
            }
        }
    }
    let text = doc.to_string();
    let label = what.join("; ");
    let path = path.clone();
    let (tx, rx) = mpsc::channel();
    let started = Instant::now();
    // Its own thread (the binary's 8 MiB stack): a hang is detected and left behind.
    let spawned = std::thread::Builder::new()
        .stack_size(8 << 20)
        .spawn(move || {
            let r = std::panic::catch_unwind(|| evaluate(&text, &path)).map_err(|p| {
                p.downcast_ref::<&str>()
                    .map(|s| s.to_string())
                    .or_else(|| p.downcast_ref::<String>().cloned())
                    .unwrap_or_else(|| "non-string panic".into())
            });
            let _ = tx.send(r);
        });
    if let Err(e) = spawned {
        return (label, Err(format!("cannot spawn: {e}")), 0.0);
    }
    match rx.recv_timeout(TIME_BOUND) {
        Ok(r) => (label, r, started.elapsed().as_secs_f64()),
        Err(_) => (label, Ok(Outcome::Violation("HANG".into())), f64::INFINITY),
    }
}

#[test]
fn mutated_worlds_and_robots_never_panic_hang_or_certify_a_non_finite_number() {
    let n: usize = std::env::var("FTCBF_FUZZ_N")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(DEFAULT_INPUTS);
    let seed: u64 = std::env::var("FTCBF_FUZZ_SEED")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(DEFAULT_SEED);
    let dir = root().join("worlds");
    let mut worlds: Vec<(PathBuf, String)> = std::fs::read_dir(&dir)
        .expect("worlds/")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .map(|p| {
            let t = std::fs::read_to_string(&p).expect("readable");
            (p, t)
        })
        .collect();
    worlds.sort();
    assert!(
        worlds.len() >= 10,
        "the catalogue has {} worlds",
        worlds.len()
    );
    let scratch = std::env::temp_dir().join(format!("ftcbf_fuzz_{}", std::process::id()));
    std::fs::create_dir_all(&scratch).expect("scratch directory");

    // Panics are caught and counted; keep the default hook from printing each one.
    let hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let started = Instant::now();
    let results: Vec<_> = (0..n)
        .into_par_iter()
        .map(|k| one_input(seed, k, &worlds, &scratch))
        .collect();
    std::panic::set_hook(hook);
    let _ = std::fs::remove_dir_all(&scratch);

    let mut t = Tally {
        inputs: n,
        ..Tally::default()
    };
    for (label, r, secs) in results {
        if secs.is_finite() && secs > t.slowest.0 {
            t.slowest = (secs, label.clone());
        }
        match r {
            Err(p) => t.panics.push(format!("{label}: panic: {p}")),
            Ok(Outcome::Invalid) => t.invalid += 1,
            Ok(Outcome::Ran(r)) => {
                t.ran += 1;
                t.no_verdict += usize::from(r.no_verdict);
                t.safe_below_obstacle_margin += usize::from(r.safe_below_obstacle_margin);
            }
            Ok(Outcome::Violation(v)) if v == "HANG" => t.hangs.push(label),
            Ok(Outcome::Violation(v)) => t.violations.push(format!("{label}: {v}")),
        }
    }
    println!(
        "fuzz (seed {seed}): {} inputs in {:.1} s — {} refused with an error, {} ran ({} without a verdict: barrier and physics disagreed; {} SAFE with an obstacle barrier below 0 inside its margin, no contact); {} panics, {} hangs (> {} s), {} property violations (check/run disagreements, SAFE next to a negative safe-set barrier, a collision, a disagreement, NaN or ∞); slowest input {:.2} s ({})",
        t.inputs,
        started.elapsed().as_secs_f64(),
        t.invalid,
        t.ran,
        t.no_verdict,
        t.safe_below_obstacle_margin,
        t.panics.len(),
        t.hangs.len(),
        TIME_BOUND.as_secs(),
        t.violations.len(),
        t.slowest.0,
        t.slowest.1
    );
    let show = |v: &[String]| v.iter().take(20).cloned().collect::<Vec<_>>().join("\n  ");
    assert!(
        t.panics.is_empty() && t.hangs.is_empty() && t.violations.is_empty(),
        "panics:\n  {}\nhangs:\n  {}\nviolations:\n  {}",
        show(&t.panics),
        show(&t.hangs),
        show(&t.violations)
    );
    assert!(
        t.ran > 0 && t.invalid > 0,
        "the mutations should give both valid and invalid worlds: {} ran, {} refused",
        t.ran,
        t.invalid
    );
}
