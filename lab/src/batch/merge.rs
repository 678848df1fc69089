//! Merging shard files (`ftcbf merge`) into the result the unsharded batch gives.
//!
//! Rules: every file must hold the same sweep points, and per point the same experiment (world
//! name and digest, overrides, trials, base seed, controllers, ε, confidence; the world file's
//! path may differ). Each file's records must be consistent with its own plan (seeds, shard
//! membership, complete shard). The files must be disjoint (no trial twice). The union must cover
//! every trial — or, when `allow_incomplete` is set, the result carries a warning saying how
//! many trials are missing and its statistics are over the trials present.

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::{anyhow, Context};

use super::io::{self, StoredResult};
use super::{BatchPlan, BatchResult, Shard};

/// Read and merge batch JSON files (see the module docs). One result per sweep point.
pub fn merge(paths: &[PathBuf], allow_incomplete: bool) -> anyhow::Result<Vec<BatchResult>> {
    let mut texts = Vec::with_capacity(paths.len());
    for p in paths {
        let text = std::fs::read_to_string(p)
            .with_context(|| format!("could not read `{}`", p.display()))?;
        texts.push((p.display().to_string(), text));
    }
    merge_texts(&texts, allow_incomplete)
}

/// Merge the texts of batch JSON files given as (name, text); names are used in errors.
pub(crate) fn merge_texts(
    files: &[(String, String)],
    allow_incomplete: bool,
) -> anyhow::Result<Vec<BatchResult>> {
    if files.is_empty() {
        return Err(anyhow!("no files to merge"));
    }
    let mut stored = Vec::with_capacity(files.len());
    for (name, text) in files {
        stored.push((name.as_str(), io::from_json(text, name)?));
    }
    let (first_name, first) = (&stored[0].0, &stored[0].1);
    for (name, file) in &stored[1..] {
        let same_points = file.results.len() == first.results.len()
            && file
                .results
                .iter()
                .zip(&first.results)
                .all(|(a, b)| a.plan.overrides == b.plan.overrides);
        if !same_points {
            return Err(anyhow!(
                "`{name}` holds sweep points {} but `{first_name}` holds {}: not shards of the same batch",
                points_label(&file.results),
                points_label(&first.results)
            ));
        }
    }
    (0..first.results.len())
        .map(|p| {
            let parts: Vec<(&str, &StoredResult)> =
                stored.iter().map(|(n, f)| (*n, &f.results[p])).collect();
            merge_point(&parts, allow_incomplete)
        })
        .collect()
}

fn points_label(results: &[StoredResult]) -> String {
    let pts: Vec<String> = results
        .iter()
        .map(|r| {
            let o: Vec<String> = r
                .plan
                .overrides
                .iter()
                .map(|o| format!("{}={}", o.key, o.value))
                .collect();
            if o.is_empty() {
                "(no sweep)".to_string()
            } else {
                o.join(" ")
            }
        })
        .collect();
    format!("[{}]", pts.join(", "))
}

/// The first field in which two plans describe different experiments.
fn plan_difference(a: &BatchPlan, b: &BatchPlan) -> Option<String> {
    let diff = |field: &str, x: String, y: String| (x != y).then(|| format!("{field}: {x} vs {y}"));
    diff("world", a.world.clone(), b.world.clone())
        .or_else(|| {
            diff(
                "world file content (digest)",
                a.world_digest.clone(),
                b.world_digest.clone(),
            )
        })
        .or_else(|| {
            diff(
                "overrides",
                format!("{:?}", a.overrides),
                format!("{:?}", b.overrides),
            )
        })
        .or_else(|| diff("trials", a.trials.to_string(), b.trials.to_string()))
        .or_else(|| diff("seed", a.base_seed.to_string(), b.base_seed.to_string()))
        .or_else(|| {
            diff(
                "controllers",
                a.controllers.join(","),
                b.controllers.join(","),
            )
        })
        .or_else(|| {
            diff(
                "epsilon",
                format!("{:?}", a.epsilon),
                format!("{:?}", b.epsilon),
            )
        })
        .or_else(|| {
            diff(
                "confidence",
                format!("{:?}", a.confidence),
                format!("{:?}", b.confidence),
            )
        })
}

fn shard_label(s: Option<Shard>) -> String {
    s.map_or_else(|| "unsharded".to_string(), |s| format!("shard {s}"))
}

/// A shard file holds exactly the trials of its shard.
fn check_shard(name: &str, part: &StoredResult, own: &BatchResult) -> anyhow::Result<()> {
    if let Some(s) = part.plan.shard {
        if let Some(r) = own.records.iter().find(|r| !s.contains(r.trial)) {
            return Err(anyhow!(
                "`{name}`: trial {} does not belong to its shard {s}",
                r.trial
            ));
        }
        let expected = s.trials(part.plan.trials).count() as u64;
        if own.trials_covered != expected {
            return Err(anyhow!(
                "`{name}`: shard {s} of {} trials should hold {expected} trials but holds {} (truncated file?)",
                part.plan.trials,
                own.trials_covered
            ));
        }
    }
    Ok(())
}

/// "incomplete cover: …", naming the first missing trial and, when every file is a shard of the
/// same N, the missing shards.
fn incomplete_cover_message(
    parts: &[(&str, &StoredResult)],
    owner: &BTreeMap<u64, usize>,
    total: u64,
) -> String {
    let covered = owner.len() as u64;
    let first_missing = (0..total).find(|k| !owner.contains_key(k)).unwrap_or(0);
    let mut msg = format!(
        "incomplete cover: {} of {total} trials missing (first missing trial: {first_missing})",
        total - covered
    );
    // When every file is a shard of the same N, name the missing shards.
    let counts: Vec<Option<u64>> = parts
        .iter()
        .map(|(_, p)| p.plan.shard.map(|s| s.count))
        .collect();
    if let Some(Some(n)) = counts
        .first()
        .copied()
        .filter(|_| counts.windows(2).all(|w| w[0] == w[1]))
    {
        let missing: Vec<String> = (1..=n)
            .filter(|k| {
                !parts
                    .iter()
                    .any(|(_, p)| p.plan.shard.map(|s| s.index) == Some(*k))
            })
            .map(|k| format!("{k}/{n}"))
            .collect();
        msg.push_str(&format!("; missing shard(s): {}", missing.join(", ")));
    }
    msg
}

fn merge_point(
    parts: &[(&str, &StoredResult)],
    allow_incomplete: bool,
) -> anyhow::Result<BatchResult> {
    let (first_name, first) = parts[0];
    let mut owner: BTreeMap<u64, usize> = BTreeMap::new();
    let mut records = Vec::new();
    for (i, (name, part)) in parts.iter().enumerate() {
        if let Some(d) = plan_difference(&first.plan, &part.plan) {
            return Err(anyhow!(
                "`{name}` is not a shard of the same batch as `{first_name}`: {d}"
            ));
        }
        // Each file must be consistent on its own (seeds, controllers, one record each).
        let own = BatchResult::from_records(part.plan.clone(), part.records.clone(), Vec::new())
            .with_context(|| format!("`{name}` is inconsistent"))?;
        check_shard(name, part, &own)?;
        for r in own.records.iter().step_by(part.plan.controllers.len()) {
            if let Some(&j) = owner.get(&r.trial) {
                return Err(anyhow!(
                    "trial {} is in both `{}` ({}) and `{name}` ({}): the files overlap; expected each trial in exactly one file",
                    r.trial,
                    parts[j].0,
                    shard_label(parts[j].1.plan.shard),
                    shard_label(part.plan.shard)
                ));
            }
            owner.insert(r.trial, i);
        }
        records.extend(own.records);
    }
    let total = first.plan.trials;
    let covered = owner.len() as u64;
    let mut warnings = Vec::new();
    if covered < total {
        let msg = incomplete_cover_message(parts, &owner, total);
        if !allow_incomplete {
            let files: Vec<String> = parts.iter().map(|(n, _)| format!("`{n}`")).collect();
            return Err(anyhow!(
                "{msg} in the files merged ({}); expected every trial of the batch (pass \
                 --allow-incomplete to summarise the trials present)",
                files.join(", ")
            ));
        }
        warnings.push(msg);
    }
    let mut plan = first.plan.clone();
    plan.shard = None;
    BatchResult::from_records(plan, records, warnings)
}

#[cfg(test)]
mod tests {
    use super::super::testutil::*;
    use super::super::*;
    use super::*;

    fn shard_texts(trials: u64, n: u64, runner: &Synthetic) -> Vec<(String, String)> {
        (1..=n)
            .map(|k| {
                let res = run_batch(
                    runner,
                    &plan(trials, Some(Shard { index: k, count: n })),
                    SERIAL,
                )
                .expect("shard");
                (format!("shard{k}.json"), io::to_json(&[res]).expect("json"))
            })
            .collect()
    }

    #[test]
    fn merged_shards_equal_the_unsharded_run() {
        let runner = Synthetic {
            p_safe: 0.85,
            fail_seed: None,
        };
        let full = run_batch(&runner, &plan(103, None), SERIAL).expect("full");
        for n in [1, 2, 4, 7] {
            let mut texts = shard_texts(103, n, &runner);
            texts.reverse(); // order of the files does not matter
            let merged = merge_texts(&texts, false).expect("merge");
            assert_eq!(merged.len(), 1);
            assert_eq!(merged[0], full, "N = {n}");
            assert_eq!(
                io::to_json(&merged).ok(),
                io::to_json(std::slice::from_ref(&full)).ok()
            );
        }
        // Shards of different N that still tile the trials: 1/2 + (2/4, 4/4).
        let half = io::to_json(&[run_batch(
            &runner,
            &plan(103, Some(Shard { index: 1, count: 2 })),
            SERIAL,
        )
        .expect("s")])
        .expect("j");
        let q2 = io::to_json(&[run_batch(
            &runner,
            &plan(103, Some(Shard { index: 2, count: 4 })),
            SERIAL,
        )
        .expect("s")])
        .expect("j");
        let q4 = io::to_json(&[run_batch(
            &runner,
            &plan(103, Some(Shard { index: 4, count: 4 })),
            SERIAL,
        )
        .expect("s")])
        .expect("j");
        let merged = merge_texts(
            &[("h".into(), half), ("a".into(), q2), ("b".into(), q4)],
            false,
        )
        .expect("merge");
        assert_eq!(merged[0], full);
    }

    #[test]
    fn merge_rejects_overlap_gaps_and_foreign_plans() {
        let runner = Synthetic {
            p_safe: 0.85,
            fail_seed: None,
        };
        let texts = shard_texts(40, 4, &runner);

        let dup = vec![
            texts[0].clone(),
            texts[1].clone(),
            texts[1].clone(),
            texts[2].clone(),
            texts[3].clone(),
        ];
        let e = merge_texts(&dup, false).expect_err("overlap").to_string();
        assert!(
            e.contains("shard2.json") && e.contains("overlap") && e.contains("shard 2/4"),
            "{e}"
        );

        let gap = vec![texts[0].clone(), texts[1].clone(), texts[3].clone()];
        let e = merge_texts(&gap, false).expect_err("gap").to_string();
        assert!(
            e.contains("10 of 40 trials missing")
                && e.contains("missing shard(s): 3/4")
                && e.contains("`shard1.json`, `shard2.json`, `shard4.json`"),
            "names the files: {e}"
        );
        let partial = merge_texts(&gap, true).expect("allowed");
        assert_eq!(partial[0].trials_covered, 30);
        assert_eq!(partial[0].summaries[0].trials, 30);
        assert_eq!(partial[0].warnings.len(), 1);

        let mut other = plan(40, Some(Shard { index: 4, count: 4 }));
        other.base_seed = 7;
        let other = io::to_json(&[run_batch(&runner, &other, SERIAL).expect("s")]).expect("j");
        let mixed = vec![
            texts[0].clone(),
            texts[1].clone(),
            texts[2].clone(),
            ("odd.json".to_string(), other),
        ];
        let e = merge_texts(&mixed, false).expect_err("seed").to_string();
        assert!(e.contains("odd.json") && e.contains("seed: 42 vs 7"), "{e}");

        // A truncated shard (a trial's records removed) is named.
        let mut res = run_batch(
            &runner,
            &plan(40, Some(Shard { index: 2, count: 4 })),
            SERIAL,
        )
        .expect("s");
        res.records.truncate(res.records.len() - 2);
        let cut = ("cut.json".to_string(), io::to_json(&[res]).expect("j"));
        let e = merge_texts(
            &[texts[0].clone(), cut, texts[2].clone(), texts[3].clone()],
            false,
        )
        .expect_err("cut");
        assert!(
            e.to_string().contains("cut.json")
                && e.to_string().contains("should hold 10 trials but holds 9"),
            "{e}"
        );

        // A tampered seed is caught with the file name.
        let mut res = run_batch(
            &runner,
            &plan(40, Some(Shard { index: 1, count: 4 })),
            SERIAL,
        )
        .expect("s");
        res.records[0].seed ^= 1;
        let bad = ("bad.json".to_string(), io::to_json(&[res]).expect("j"));
        let e = merge_texts(
            &[bad, texts[1].clone(), texts[2].clone(), texts[3].clone()],
            false,
        )
        .expect_err("seed");
        assert!(
            format!("{e:#}").contains("bad.json")
                && format!("{e:#}").contains("is not the batch seed"),
            "{e:#}"
        );

        // A hand-edited file with a zero shard count is an error naming it, not a panic.
        let zero = texts[0].1.replace("\"count\": 4", "\"count\": 0");
        assert_ne!(zero, texts[0].1);
        let e = merge_texts(&[("zero.json".to_string(), zero)], true).expect_err("zero count");
        assert!(
            format!("{e:#}").contains("zero.json") && format!("{e:#}").contains("invalid"),
            "{e:#}"
        );

        assert!(merge_texts(&[], false).is_err());
    }

    #[test]
    fn sweep_files_merge_point_by_point() {
        let runner = Synthetic {
            p_safe: 0.85,
            fail_seed: None,
        };
        let point = |v: f64, shard: Option<Shard>| {
            let mut p = plan(20, shard);
            p.overrides = vec![Override {
                key: "noise.scale".into(),
                value: v,
            }];
            run_batch(&runner, &p, SERIAL).expect("point")
        };
        let full = vec![point(0.5, None), point(2.0, None)];
        let s1 = io::to_json(&[
            point(0.5, Some(Shard { index: 1, count: 2 })),
            point(2.0, Some(Shard { index: 1, count: 2 })),
        ])
        .expect("j");
        let s2 = io::to_json(&[
            point(0.5, Some(Shard { index: 2, count: 2 })),
            point(2.0, Some(Shard { index: 2, count: 2 })),
        ])
        .expect("j");
        let merged =
            merge_texts(&[("1".into(), s1.clone()), ("2".into(), s2)], false).expect("merge");
        assert_eq!(merged, full);
        let lone = io::to_json(&[point(0.5, Some(Shard { index: 2, count: 2 }))]).expect("j");
        let e = merge_texts(&[("1".into(), s1), ("lone.json".into(), lone)], false)
            .expect_err("points")
            .to_string();
        assert!(e.contains("lone.json") && e.contains("sweep points"), "{e}");
    }
}
