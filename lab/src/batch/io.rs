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
//! `max_ratio` — its largest ‖x − x̂‖/γ — and `exceeded` — it left γ), `safe_stop`,
//! `first_stop_t` \[s\], `stop_reason`, and the contacts that began by who moved (issue #51):
//! `static_collisions`, `mover_collisions_moving` (the robot moved), `mover_collisions_stopped`
//! (it stood below 0.01 m/s) and of those `walker_collisions_stopped`.
//! Fields containing `,`, `"` or a line break are quoted (RFC 4180). Written and read through the
//! `csv` crate with serde (one row type, its field names the header); [`from_csv`] reads a file
//! back exactly, a field that does not parse an error naming the file, trial and column.

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
omega_sign_change_fraction,mean_abs_domega,stalls,estimation,safe_stop,first_stop_t,stop_reason,\
static_collisions,mover_collisions_moving,mover_collisions_stopped,walker_collisions_stopped";

fn float_text(x: f64) -> String {
    // Debug of f64 is the shortest text that parses back to the same bits ("NaN", "inf").
    format!("{x:?}")
}

/// One CSV row: the columns of [`CSV_HEADER`], in order (serde writes the header from the field
/// names). Floats are kept as [`float_text`] (exact, "NaN"/"inf" included; empty = none), the
/// estimation rows as one JSON cell.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct CsvRow {
    sweep_key: String,
    sweep_value: String,
    trial: u64,
    seed: u64,
    controller: String,
    safe: bool,
    collided: bool,
    first_collision_t: String,
    first_collision_obstacle: String,
    first_violation_t: String,
    first_violation_set: String,
    first_violation_value: String,
    min_barrier: String,
    min_barrier_name: String,
    min_clearance: String,
    goal_reached: bool,
    time_to_goal: String,
    step1: u64,
    clf_relaxed: u64,
    step2: u64,
    step3: u64,
    infeasible: u64,
    control_steps: u64,
    rejected_readings: u64,
    duration: String,
    outside_fault_patterns: bool,
    goal_settled: bool,
    final_goal_distance: String,
    omega_sign_change_fraction: String,
    mean_abs_domega: String,
    stalls: u64,
    estimation: String,
    #[serde(default)]
    safe_stop: u64,
    #[serde(default)]
    first_stop_t: String,
    #[serde(default)]
    stop_reason: String,
    #[serde(default)]
    static_collisions: u64,
    #[serde(default)]
    mover_collisions_moving: u64,
    #[serde(default)]
    mover_collisions_stopped: u64,
    #[serde(default)]
    walker_collisions_stopped: u64,
}

impl CsvRow {
    fn of(sweep: &(String, String), r: &TrialRecord) -> Self {
        let opt_f = |x: Option<f64>| x.map(float_text).unwrap_or_default();
        let opt_s = |x: &Option<String>| x.clone().unwrap_or_default();
        CsvRow {
            sweep_key: sweep.0.clone(),
            sweep_value: sweep.1.clone(),
            trial: r.trial,
            seed: r.seed,
            controller: r.controller.clone(),
            safe: r.safe,
            collided: r.collided,
            first_collision_t: opt_f(r.first_collision_t),
            first_collision_obstacle: opt_s(&r.first_collision_obstacle),
            first_violation_t: opt_f(r.first_violation_t),
            first_violation_set: opt_s(&r.first_violation_set),
            first_violation_value: opt_f(r.first_violation_value),
            min_barrier: opt_f(r.min_barrier),
            min_barrier_name: opt_s(&r.min_barrier_name),
            min_clearance: opt_f(r.min_clearance),
            goal_reached: r.goal_reached,
            time_to_goal: opt_f(r.time_to_goal),
            step1: r.steps.step1,
            clf_relaxed: r.steps.clf_relaxed,
            step2: r.steps.step2,
            step3: r.steps.step3,
            infeasible: r.steps.infeasible,
            safe_stop: r.steps.safe_stop,
            first_stop_t: opt_f(r.first_stop_t),
            stop_reason: opt_s(&r.stop_reason),
            control_steps: r.control_steps,
            rejected_readings: r.rejected_readings,
            duration: float_text(r.duration),
            outside_fault_patterns: r.outside_fault_patterns,
            goal_settled: r.goal_settled,
            final_goal_distance: float_text(r.final_goal_distance),
            omega_sign_change_fraction: float_text(r.omega_sign_change_fraction),
            mean_abs_domega: float_text(r.mean_abs_domega),
            stalls: r.stalls,
            estimation: serde_json::to_string(&r.estimation).unwrap_or_else(|_| "[]".into()),
            static_collisions: r.collisions.static_obstacles,
            mover_collisions_moving: r.collisions.mover_robot_moving,
            mover_collisions_stopped: r.collisions.mover_robot_stopped,
            walker_collisions_stopped: r.collisions.walker_robot_stopped,
        }
    }
}

/// One row per trial record, results in order, records in trial order.
pub fn to_csv(results: &[BatchResult]) -> anyhow::Result<String> {
    let mut w = csv::WriterBuilder::new()
        .terminator(csv::Terminator::Any(b'\n'))
        .from_writer(Vec::new());
    let mut rows = 0;
    for res in results {
        let sweep = match res.plan.overrides.first() {
            Some(o) => (o.key.clone(), float_text(o.value)),
            None => (String::new(), String::new()),
        };
        for r in &res.records {
            w.serialize(CsvRow::of(&sweep, r))
                .context("writing a CSV row")?;
            rows += 1;
        }
    }
    if rows == 0 {
        w.write_record(CSV_HEADER.split(','))
            .context("writing the CSV header")?;
    }
    let bytes = w.into_inner().context("finishing the CSV")?;
    String::from_utf8(bytes).context("the CSV is not UTF-8")
}

impl CsvRow {
    /// The trial record of this row (the sweep columns aside).
    fn record(&self) -> anyhow::Result<TrialRecord> {
        let f = |name: &str, text: &str| -> anyhow::Result<f64> {
            text.parse()
                .map_err(|_| anyhow!("column `{name}`: expected a number, found `{text}`"))
        };
        let opt_f = |name: &str, text: &str| -> anyhow::Result<Option<f64>> {
            (!text.is_empty()).then(|| f(name, text)).transpose()
        };
        let opt_s = |text: &str| (!text.is_empty()).then(|| text.to_string());
        Ok(TrialRecord {
            trial: self.trial,
            seed: self.seed,
            controller: self.controller.clone(),
            safe: self.safe,
            collided: self.collided,
            first_collision_t: opt_f("first_collision_t", &self.first_collision_t)?,
            first_collision_obstacle: opt_s(&self.first_collision_obstacle),
            first_violation_t: opt_f("first_violation_t", &self.first_violation_t)?,
            first_violation_set: opt_s(&self.first_violation_set),
            first_violation_value: opt_f("first_violation_value", &self.first_violation_value)?,
            min_barrier: opt_f("min_barrier", &self.min_barrier)?,
            min_barrier_name: opt_s(&self.min_barrier_name),
            min_clearance: opt_f("min_clearance", &self.min_clearance)?,
            goal_reached: self.goal_reached,
            time_to_goal: opt_f("time_to_goal", &self.time_to_goal)?,
            steps: ftcbf_sim::summary::StepCounts {
                step1: self.step1,
                clf_relaxed: self.clf_relaxed,
                step2: self.step2,
                step3: self.step3,
                infeasible: self.infeasible,
                safe_stop: self.safe_stop,
            },
            control_steps: self.control_steps,
            rejected_readings: self.rejected_readings,
            duration: f("duration", &self.duration)?,
            outside_fault_patterns: self.outside_fault_patterns,
            goal_settled: self.goal_settled,
            final_goal_distance: f("final_goal_distance", &self.final_goal_distance)?,
            omega_sign_change_fraction: f(
                "omega_sign_change_fraction",
                &self.omega_sign_change_fraction,
            )?,
            mean_abs_domega: f("mean_abs_domega", &self.mean_abs_domega)?,
            stalls: self.stalls,
            estimation: serde_json::from_str(&self.estimation)
                .context("column `estimation`: expected a JSON array of filter rows")?,
            first_stop_t: opt_f("first_stop_t", &self.first_stop_t)?,
            stop_reason: opt_s(&self.stop_reason),
            collisions: ftcbf_sim::summary::CollisionCounts {
                static_obstacles: self.static_collisions,
                mover_robot_moving: self.mover_collisions_moving,
                mover_robot_stopped: self.mover_collisions_stopped,
                walker_robot_stopped: self.walker_collisions_stopped,
            },
        })
    }
}

/// One row of a batch CSV read back.
#[derive(Debug, Clone, PartialEq)]
pub struct CsvTrial {
    /// The sweep point's key and value (`None` without a sweep).
    pub sweep: Option<(String, f64)>,
    /// The trial record.
    pub record: TrialRecord,
}

/// Reads a batch CSV (as [`to_csv`] writes it) back: per row, the sweep point (key and value,
/// `None` without a sweep) and the trial record, floats bit for bit. A row that does not parse
/// is an error naming its line and column.
pub fn from_csv(text: &str, name: &str) -> anyhow::Result<Vec<CsvTrial>> {
    let mut reader = csv::ReaderBuilder::new().from_reader(text.as_bytes());
    let header: Vec<String> = reader
        .headers()
        .with_context(|| format!("{name}: reading the CSV header"))?
        .iter()
        .map(str::to_string)
        .collect();
    if header.join(",") != CSV_HEADER {
        return Err(anyhow!(
            "{name}: not a batch CSV (expected the header `{CSV_HEADER}`)"
        ));
    }
    let mut out = Vec::new();
    for row in reader.deserialize::<CsvRow>() {
        let row = row.with_context(|| format!("{name}: a CSV row"))?;
        let sweep = if row.sweep_key.is_empty() {
            None
        } else {
            let v = row.sweep_value.parse().map_err(|_| {
                anyhow!(
                    "column `sweep_value`: expected a number, found `{}`",
                    row.sweep_value
                )
            });
            Some((
                row.sweep_key.clone(),
                v.with_context(|| format!("{name}: trial {}", row.trial))?,
            ))
        };
        let record = row
            .record()
            .with_context(|| format!("{name}: trial {} of {}", row.trial, row.controller))?;
        out.push(CsvTrial { sweep, record });
    }
    Ok(out)
}

/// FNV-1a (64 bit) of a file's bytes, as `fnv1a64:<16 hex digits>`: the "same world" check
/// of a merge (not a cryptographic hash).
pub fn digest_file(path: &Path) -> anyhow::Result<String> {
    let bytes = std::fs::read(path).with_context(|| {
        format!(
            "could not read the world file `{}` (expected a readable TOML file)",
            path.display()
        )
    })?;
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
            OutFormat::Csv => to_csv(results)?,
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

    #[test]
    fn csv_round_trip_is_exact() {
        let runner = Synthetic {
            p_safe: 0.8,
            fail_seed: None,
        };
        let mut p = plan(50, None);
        p.overrides = vec![Override {
            key: "attacks[0].value".into(),
            value: 0.1 + 0.2,
        }];
        let mut res = run_batch(&runner, &p, SERIAL).expect("batch");
        // Non-finite and awkward text survive too.
        res.records[0].min_barrier = Some(f64::NEG_INFINITY);
        res.records[1].first_violation_value = Some(f64::NAN);
        res.records[2].first_violation_set = Some("line\nbreak".into());
        let text = to_csv(std::slice::from_ref(&res)).expect("csv");
        assert_eq!(text.lines().next(), Some(CSV_HEADER));
        let rows = from_csv(&text, "mem.csv").expect("reads back");
        assert_eq!(rows.len(), res.records.len());
        for (row, rec) in rows.iter().zip(&res.records) {
            let (key, value) = row.sweep.as_ref().expect("a sweep point");
            let back = &row.record;
            assert_eq!(key, "attacks[0].value");
            assert_eq!(value.to_bits(), (0.1_f64 + 0.2).to_bits());
            if rec.first_violation_value.is_some_and(f64::is_nan) {
                assert!(back.first_violation_value.is_some_and(f64::is_nan));
                let mut a = back.clone();
                a.first_violation_value = None;
                let mut b = rec.clone();
                b.first_violation_value = None;
                assert_eq!(a, b);
            } else {
                assert_eq!(back, rec);
            }
        }
        // The obstacle name of the synthetic runner contains a comma and quotes.
        assert!(text.contains("\"pillar, \"\"east\"\"\""));
    }

    #[test]
    fn a_csv_field_that_does_not_parse_is_an_error_naming_it() {
        let runner = Synthetic {
            p_safe: 0.8,
            fail_seed: None,
        };
        let res = run_batch(&runner, &plan(3, None), SERIAL).expect("batch");
        let text = to_csv(std::slice::from_ref(&res)).expect("csv");
        let d = float_text(res.records[1].duration);
        let bad = text.replacen(&format!(",{d},"), ",1.5s,", 2);
        let e = from_csv(&bad, "bad.csv").expect_err("refused");
        let msg = format!("{e:#}");
        assert!(
            msg.contains("bad.csv") && msg.contains("`duration`") && msg.contains("1.5s"),
            "{msg}"
        );
        let e = from_csv(&text.replacen("true", "yes", 1), "bad.csv").expect_err("refused");
        assert!(format!("{e:#}").contains("bad.csv"), "{e:#}");
        // Without records: the header alone.
        let empty = BatchResult {
            records: Vec::new(),
            ..res
        };
        assert_eq!(to_csv(&[empty]).expect("csv"), format!("{CSV_HEADER}\n"));
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
