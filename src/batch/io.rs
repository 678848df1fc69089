//! Batch files: JSON (plan + summaries + every trial record, enough to merge exactly) and CSV
//! (one row per trial and controller, for analysis).
//!
//! Exactness: floats are written in Rust's shortest round-trip form. Reading them back bit for
//! bit needs serde_json's `float_roundtrip` feature (its default parser may be off by one unit
//! in the last place); the test `json_round_trip_is_exact` guards this. Non-finite record values
//! are written as the strings "NaN", "inf", "-inf" (JSON has no such numbers).
//!
//! CSV columns, in order (an empty field is "none"):
//! `sweep_key, sweep_value` (the sweep point, empty without a sweep), `trial` (0-based index),
//! `seed`, `controller`, `safe`, `collided` (true/false), `first_collision_t` \[s\],
//! `first_collision_obstacle`, `first_violation_t` \[s\], `first_violation_set`,
//! `first_violation_value` (h(x_true) then), `min_barrier` (smallest h(x_true) over all sets and
//! obstacle barriers), `min_barrier_name`, `min_clearance` \[m\], `goal_reached`, `time_to_goal`
//! \[s\], `step1, clf_relaxed, step2, step3, infeasible` (control steps decided by each policy
//! step), `control_steps`, `rejected_readings`, `duration` \[s\], `outside_fault_patterns`,
//! `goal_settled` (inside the goal over the run's last 2 s), `final_goal_distance` \[m\],
//! `omega_sign_change_fraction` (control steps whose commanded ω changed sign),
//! `mean_abs_domega` [rad/s per step], `stalls` (the safety filter's tracker), `estimation`
//! (per filter of the bank, as a JSON array: `filter`, `honest` — it read no attacked channel —,
//! `max_ratio` — its largest ‖x − x̂‖/γ — and `exceeded` — it left γ).
//! Fields containing `,`, `"` or a line break are quoted (RFC 4180).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{anyhow, Context};
use serde::{Deserialize, Serialize};

use super::{ArgError, BatchPlan, BatchResult, TrialRecord};

/// Format tag of batch JSON files.
pub const FORMAT: &str = "ftcbf-batch/1";

/// The content of a batch JSON file: one result per sweep point (one without a sweep).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BatchFile<'a> {
    /// [`FORMAT`].
    pub format: &'static str,
    /// Results, in sweep order.
    pub results: &'a [BatchResult],
}

/// What is read back from a batch JSON file: the summaries are recomputed from the records.
#[derive(Debug, Deserialize)]
pub(crate) struct StoredFile {
    pub format: String,
    pub results: Vec<StoredResult>,
}

/// One stored result (the fields a merge needs).
#[derive(Debug, Deserialize)]
pub(crate) struct StoredResult {
    pub plan: BatchPlan,
    pub records: Vec<TrialRecord>,
}

/// Output format chosen by a file's extension.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OutFormat {
    /// `.csv`
    Csv,
    /// `.json`
    Json,
}

impl OutFormat {
    /// `.csv` or `.json` (case-insensitive), otherwise an error naming the file.
    pub fn from_path(path: &Path) -> Result<OutFormat, ArgError> {
        match path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase)
            .as_deref()
        {
            Some("csv") => Ok(OutFormat::Csv),
            Some("json") => Ok(OutFormat::Json),
            _ => Err(ArgError(format!(
                "output file `{}`: unknown format (expected a name ending in .csv or .json)",
                path.display()
            ))),
        }
    }
}

/// Serialise results as a batch JSON file (pretty, deterministic).
pub fn to_json(results: &[BatchResult]) -> anyhow::Result<String> {
    let file = BatchFile {
        format: FORMAT,
        results,
    };
    let mut s =
        serde_json::to_string_pretty(&file).context("could not serialise the batch result")?;
    s.push('\n');
    Ok(s)
}

/// Read a batch JSON file's text; `name` is used in errors.
pub(crate) fn from_json(text: &str, name: &str) -> anyhow::Result<StoredFile> {
    let file: StoredFile = serde_json::from_str(text).with_context(|| {
        format!("{name}: not a batch result file (ftcbf batch --out FILE.json)")
    })?;
    if file.format != FORMAT {
        return Err(anyhow!(
            "{name}: format `{}` is not supported (expected `{FORMAT}`)",
            file.format
        ));
    }
    if file.results.is_empty() {
        return Err(anyhow!("{name}: holds no results"));
    }
    Ok(file)
}

/// CSV header line (without the line break).
pub const CSV_HEADER: &str =
    "sweep_key,sweep_value,trial,seed,controller,safe,collided,first_collision_t,\
first_collision_obstacle,first_violation_t,first_violation_set,first_violation_value,min_barrier,\
min_barrier_name,min_clearance,goal_reached,time_to_goal,step1,clf_relaxed,step2,step3,infeasible,\
control_steps,rejected_readings,duration,outside_fault_patterns,goal_settled,final_goal_distance,\
omega_sign_change_fraction,mean_abs_domega,stalls,estimation";

fn csv_text(out: &mut String, s: &str) {
    if s.contains([',', '"', '\n', '\r']) {
        out.push('"');
        out.push_str(&s.replace('"', "\"\""));
        out.push('"');
    } else {
        out.push_str(s);
    }
}

fn float_text(x: f64) -> String {
    // Debug of f64 is the shortest text that parses back to the same bits ("NaN", "inf").
    format!("{x:?}")
}

/// One row per trial record, results in order, records in trial order.
pub fn to_csv(results: &[BatchResult]) -> String {
    let mut out = String::from(CSV_HEADER);
    out.push('\n');
    for res in results {
        let (key, value) = match res.plan.overrides.first() {
            Some(o) => (o.key.as_str(), float_text(o.value)),
            None => ("", String::new()),
        };
        for r in &res.records {
            csv_text(&mut out, key);
            out.push(',');
            out.push_str(&value);
            let opt_f = |x: Option<f64>| x.map(float_text).unwrap_or_default();
            let _ = write!(out, ",{},{},", r.trial, r.seed);
            csv_text(&mut out, &r.controller);
            let _ = write!(
                out,
                ",{},{},{},",
                r.safe,
                r.collided,
                opt_f(r.first_collision_t)
            );
            csv_text(
                &mut out,
                r.first_collision_obstacle.as_deref().unwrap_or(""),
            );
            let _ = write!(out, ",{},", opt_f(r.first_violation_t));
            csv_text(&mut out, r.first_violation_set.as_deref().unwrap_or(""));
            let _ = write!(
                out,
                ",{},{},",
                opt_f(r.first_violation_value),
                opt_f(r.min_barrier)
            );
            csv_text(&mut out, r.min_barrier_name.as_deref().unwrap_or(""));
            let _ = write!(
                out,
                ",{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},",
                opt_f(r.min_clearance),
                r.goal_reached,
                opt_f(r.time_to_goal),
                r.steps.step1,
                r.steps.clf_relaxed,
                r.steps.step2,
                r.steps.step3,
                r.steps.infeasible,
                r.control_steps,
                r.rejected_readings,
                float_text(r.duration),
                r.outside_fault_patterns,
                r.goal_settled,
                float_text(r.final_goal_distance),
                float_text(r.omega_sign_change_fraction),
                float_text(r.mean_abs_domega),
                r.stalls
            );
            // The per-filter rows as one JSON cell (quoted: it holds commas).
            let cell = serde_json::to_string(&r.estimation).unwrap_or_else(|_| "[]".into());
            csv_text(&mut out, &cell);
            out.push('\n');
        }
    }
    out
}

/// FNV-1a (64 bit) of a file's bytes, as `fnv1a64:<16 hex digits>`: the "same world" check
/// of a merge (not a cryptographic hash).
pub fn digest_file(path: &Path) -> anyhow::Result<String> {
    let bytes = std::fs::read(path)
        .with_context(|| format!("could not read the world file `{}`", path.display()))?;
    Ok(digest_bytes(&bytes))
}

/// FNV-1a (64 bit) of bytes as `fnv1a64:<hex>`.
pub fn digest_bytes(bytes: &[u8]) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    format!("fnv1a64:{h:016x}")
}

/// Check every output path's extension (before any trial runs).
pub fn check_outputs(paths: &[PathBuf]) -> anyhow::Result<()> {
    for p in paths {
        OutFormat::from_path(p)?;
    }
    Ok(())
}

/// Write `results` to every path, in the format its extension names.
pub fn write_outputs(paths: &[PathBuf], results: &[BatchResult]) -> anyhow::Result<()> {
    for p in paths {
        let text = match OutFormat::from_path(p)? {
            OutFormat::Csv => to_csv(results),
            OutFormat::Json => to_json(results)?,
        };
        std::fs::write(p, text).with_context(|| format!("could not write `{}`", p.display()))?;
    }
    Ok(())
}

/// serde adapter for record floats: finite values as JSON numbers, NaN and ±∞ as the strings
/// "NaN", "inf", "-inf"; reads either form.
pub(crate) mod float_or_text {
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    #[derive(Serialize, Deserialize)]
    #[serde(untagged)]
    enum Repr {
        Num(f64),
        Text(String),
    }

    fn to_repr(x: f64) -> Repr {
        if x.is_finite() {
            Repr::Num(x)
        } else {
            Repr::Text(format!("{x:?}"))
        }
    }

    fn from_repr<E: serde::de::Error>(r: Repr) -> Result<f64, E> {
        match r {
            Repr::Num(x) => Ok(x),
            Repr::Text(t) => match t.as_str() {
                "NaN" | "inf" | "-inf" => t.parse().map_err(E::custom),
                _ => Err(E::custom(format!("`{t}` is not a number"))),
            },
        }
    }

    /// Serialise an `f64`.
    pub fn serialize<S: Serializer>(x: &f64, s: S) -> Result<S::Ok, S::Error> {
        to_repr(*x).serialize(s)
    }

    /// Deserialise an `f64`.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        from_repr(Repr::deserialize(d)?)
    }

    /// The same for `Option<f64>` (`null` = `None`).
    pub mod option {
        use super::*;

        /// Serialise an `Option<f64>`.
        pub fn serialize<S: Serializer>(x: &Option<f64>, s: S) -> Result<S::Ok, S::Error> {
            x.map(to_repr).serialize(s)
        }

        /// Deserialise an `Option<f64>`.
        pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<f64>, D::Error> {
            Option::<Repr>::deserialize(d)?.map(from_repr).transpose()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::testutil::*;
    use super::super::*;
    use super::*;

    /// Minimal RFC 4180 reader for the round-trip test: rows of fields.
    fn parse_csv(text: &str) -> Vec<Vec<String>> {
        let mut rows = Vec::new();
        let mut row = Vec::new();
        let mut field = String::new();
        let mut chars = text.chars().peekable();
        let mut quoted = false;
        while let Some(c) = chars.next() {
            match (quoted, c) {
                (true, '"') if chars.peek() == Some(&'"') => {
                    field.push('"');
                    chars.next();
                }
                (true, '"') => quoted = false,
                (true, c) => field.push(c),
                (false, '"') => quoted = true,
                (false, ',') => row.push(std::mem::take(&mut field)),
                (false, '\n') => {
                    row.push(std::mem::take(&mut field));
                    rows.push(std::mem::take(&mut row));
                }
                (false, c) => field.push(c),
            }
        }
        rows
    }

    fn opt_f(s: &str) -> Option<f64> {
        (!s.is_empty()).then(|| s.parse().expect("float field"))
    }

    fn opt_s(s: &str) -> Option<String> {
        (!s.is_empty()).then(|| s.to_string())
    }

    fn record_from_row(f: &[String]) -> TrialRecord {
        let u = |i: usize| f[i].parse::<u64>().expect("integer field");
        let b = |i: usize| f[i].parse::<bool>().expect("bool field");
        TrialRecord {
            trial: u(2),
            seed: u(3),
            controller: f[4].clone(),
            safe: b(5),
            collided: b(6),
            first_collision_t: opt_f(&f[7]),
            first_collision_obstacle: opt_s(&f[8]),
            first_violation_t: opt_f(&f[9]),
            first_violation_set: opt_s(&f[10]),
            first_violation_value: opt_f(&f[11]),
            min_barrier: opt_f(&f[12]),
            min_barrier_name: opt_s(&f[13]),
            min_clearance: opt_f(&f[14]),
            goal_reached: b(15),
            time_to_goal: opt_f(&f[16]),
            steps: ftcbf_sim::summary::StepCounts {
                step1: u(17),
                clf_relaxed: u(18),
                step2: u(19),
                step3: u(20),
                infeasible: u(21),
            },
            control_steps: u(22),
            rejected_readings: u(23),
            duration: f[24].parse().expect("duration"),
            outside_fault_patterns: b(25),
            goal_settled: b(26),
            final_goal_distance: f[27].parse().expect("final_goal_distance"),
            omega_sign_change_fraction: f[28].parse().expect("omega_sign_change_fraction"),
            mean_abs_domega: f[29].parse().expect("mean_abs_domega"),
            stalls: u(30),
            estimation: serde_json::from_str(&f[31]).expect("estimation cell"),
        }
    }

    #[test]
    fn csv_round_trip_is_exact() {
        let runner = Synthetic {
            p_safe: 0.8,
            fail_seed: None,
        };
        let mut p = plan(50, None);
        p.overrides = vec![ParamOverride {
            key: "attacks[0].value".into(),
            value: 0.1 + 0.2,
        }];
        let mut res = run_batch(&runner, &p, SERIAL).expect("batch");
        // Non-finite and awkward text survive too.
        res.records[0].min_barrier = Some(f64::NEG_INFINITY);
        res.records[1].first_violation_value = Some(f64::NAN);
        res.records[2].first_violation_set = Some("line\nbreak".into());
        let text = to_csv(std::slice::from_ref(&res));
        let rows = parse_csv(&text);
        assert_eq!(rows[0].join(","), CSV_HEADER);
        assert_eq!(rows.len(), 1 + res.records.len());
        for (row, rec) in rows[1..].iter().zip(&res.records) {
            assert_eq!(row.len(), CSV_HEADER.split(',').count());
            assert_eq!(row[0], "attacks[0].value");
            assert_eq!(
                row[1].parse::<f64>().map(f64::to_bits).ok(),
                Some((0.1_f64 + 0.2).to_bits())
            );
            let back = record_from_row(row);
            if rec.first_violation_value.is_some_and(f64::is_nan) {
                assert!(back.first_violation_value.is_some_and(f64::is_nan));
                let mut a = back.clone();
                a.first_violation_value = None;
                let mut b = rec.clone();
                b.first_violation_value = None;
                assert_eq!(a, b);
            } else {
                assert_eq!(&back, rec);
            }
        }
        // The obstacle name of the synthetic runner contains a comma and quotes.
        assert!(text.contains("\"pillar, \"\"east\"\"\""));
    }

    #[test]
    fn json_round_trip_is_exact() {
        // Needs serde_json's `float_roundtrip` feature: without it ~1 in 10 of these differs.
        let mut bad = 0;
        for k in 0..20_000u64 {
            let x = unit(k, 0) * 10f64.powi((k % 40) as i32 - 20);
            let back: f64 =
                serde_json::from_str(&serde_json::to_string(&x).expect("ser")).expect("de");
            bad += u64::from(back.to_bits() != x.to_bits());
        }
        assert_eq!(
            bad, 0,
            "serde_json float parsing is not exact: enable its `float_roundtrip` feature"
        );

        let runner = Synthetic {
            p_safe: 0.8,
            fail_seed: None,
        };
        let mut res = run_batch(&runner, &plan(40, None), SERIAL).expect("batch");
        res.records[3].min_clearance = Some(f64::INFINITY);
        let text = to_json(std::slice::from_ref(&res)).expect("json");
        let stored = from_json(&text, "mem.json").expect("read back");
        assert_eq!(stored.results.len(), 1);
        let back = BatchResult::from_records(
            stored.results[0].plan.clone(),
            stored.results[0].records.clone(),
            Vec::new(),
        )
        .expect("aggregate");
        let again = BatchResult::from_records(res.plan.clone(), res.records.clone(), Vec::new())
            .expect("aggregate");
        assert_eq!(back, again);
        assert_eq!(
            to_json(&[back]).expect("json"),
            to_json(&[again]).expect("json")
        );
        assert!(text.contains("\"min_clearance\": \"inf\""));
    }

    #[test]
    fn bad_json_files_name_the_file() {
        let e = from_json("{}", "shard3.json").expect_err("not a batch file");
        assert!(format!("{e:#}").contains("shard3.json"));
        let e = from_json(r#"{"format":"other/9","results":[]}"#, "x.json").expect_err("format");
        assert!(e.to_string().contains("other/9") && e.to_string().contains("x.json"));
        let e =
            from_json(r#"{"format":"ftcbf-batch/1","results":[]}"#, "y.json").expect_err("empty");
        assert!(e.to_string().contains("y.json"));
    }

    #[test]
    fn output_format_from_extension() {
        assert_eq!(
            OutFormat::from_path(Path::new("a/results.CSV")),
            Ok(OutFormat::Csv)
        );
        assert_eq!(
            OutFormat::from_path(Path::new("r.json")),
            Ok(OutFormat::Json)
        );
        let e = OutFormat::from_path(Path::new("r.txt")).expect_err("txt");
        assert!(e.0.contains("r.txt") && e.0.contains(".csv or .json"));
        assert!(OutFormat::from_path(Path::new("noext")).is_err());
    }

    #[test]
    fn digest_is_fnv1a() {
        // Published FNV-1a 64 test vectors.
        assert_eq!(digest_bytes(b""), "fnv1a64:cbf29ce484222325");
        assert_eq!(digest_bytes(b"a"), "fnv1a64:af63dc4c8601ec8c");
        assert_eq!(digest_bytes(b"foobar"), "fnv1a64:85944171f73967e8");
    }
}
