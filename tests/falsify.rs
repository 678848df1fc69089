//! `ftcbf falsify` end to end: it finds an unsafe attack on the all-sensor baseline, the written
//! world replays it with `ftcbf run`, outputs are deterministic for any --jobs, and the threat
//! model is respected.

use std::path::{Path, PathBuf};

use serde_json::Value;

mod common;
use common::{ftcbf, text};

fn tmp(name: &str) -> PathBuf {
    common::tmp_in("falsify", name)
}

fn read_json(p: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(p).expect("json file")).expect("valid JSON")
}

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

/// The acceptance test: budget 200 against the baseline on paper_turtlebot finds an
/// unsafe attack, and `ftcbf run` on the written world reproduces its robustness exactly.
#[test]
fn baseline_on_paper_turtlebot_is_falsified_and_the_world_replays_it() {
    let worst = tmp("paper_worst.toml");
    let json = tmp("paper.json");
    let o = ftcbf(&[
        "falsify",
        "worlds/paper_turtlebot.toml",
        "--controller",
        "baseline",
        "--budget",
        "200",
        "--no-random",
        "--no-record",
        "--out",
        s(&worst),
        "--json",
        s(&json),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let out = text(&o);
    assert!(out.contains("patterns are never combined"), "{out}");
    assert!(out.contains("UNSAFE"), "{out}");
    let v = read_json(&json);
    let witness = &v["methods"][0]["witness"];
    let rho = witness["robustness"]["value"].as_f64().expect("ρ");
    assert!(rho < 0.0, "no unsafe attack found: ρ = {rho}");
    assert_eq!(v["methods"][0]["runs"], 200);
    assert_eq!(v["replay"]["robustness"], witness["robustness"]);
    // The search's time and run count on stderr: the budget plus the attack-free reference.
    let runs = 200 + v["plan"]["final_seeds"].as_u64().expect("final_seeds");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("searched paper_turtlebot in ") && err.contains(&format!(" s ({runs} runs)")),
        "{err}"
    );

    // The written world is an ordinary world: `ftcbf run` replays the worst run with the
    // seed and controller it names.
    let o = ftcbf(&["run", s(&worst), "--no-record", "--json"]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let summary: Value = serde_json::from_slice(&o.stdout).expect("summary JSON");
    assert_eq!(summary["controller"], "baseline");
    assert_eq!(summary["safe"], false);
    assert_eq!(summary["seed"], witness["seed"]);
    assert_eq!(summary["min_barrier"][0]["name"], "floor");
    assert_eq!(summary["min_barrier"][0]["value"].as_f64(), Some(rho));
    // …and with --controller baseline given explicitly, as a user would type it.
    let o = ftcbf(&[
        "run",
        s(&worst),
        "--no-record",
        "--json",
        "--controller",
        "baseline",
    ]);
    let again: Value = serde_json::from_slice(&o.stdout).expect("summary JSON");
    assert_eq!(again, summary);
    // Every attack in the written world is on one channel of one declared pattern.
    let text = std::fs::read_to_string(&worst).expect("world");
    assert!(text.starts_with("# Written by `ftcbf falsify"), "{text}");
    assert!(!text.contains("\n[expect"), "{text}");
    let doc: toml::Table = toml::from_str(&text).expect("TOML");
    let attacks = doc["attacks"].as_array().expect("attacks");
    assert!(!attacks.is_empty());
    for a in attacks {
        let ch = a["channels"].as_array().expect("channels");
        assert!(
            ch.iter().all(|c| c.as_str() == Some("gnss2_x"))
                || ch.iter().all(|c| c.as_str() == Some("gnss2_y")),
            "{a:?}"
        );
    }
}

/// Same command → byte-identical world and JSON files, whatever --jobs; the recording replays
/// the same run; a world whose own attacks leave the model is warned about, and every searched
/// attack stays inside one pattern.
#[test]
fn outputs_do_not_depend_on_jobs_and_the_threat_model_holds() {
    let run = |jobs: &str| {
        let worst = tmp("lin.toml");
        let json = tmp("lin.json");
        let o = ftcbf(&[
            "falsify",
            "worlds/paper_linear.toml",
            "--budget",
            "30",
            "--seed",
            "5",
            "--jobs",
            jobs,
            "--out",
            s(&worst),
            "--json",
            s(&json),
        ]);
        assert_eq!(o.status.code(), Some(0), "{}", text(&o));
        (
            std::fs::read(&worst).expect("world"),
            std::fs::read(&json).expect("json"),
            String::from_utf8_lossy(&o.stdout).into_owned(),
            worst,
            json,
        )
    };
    let (w1, j1, out1, ..) = run("1");
    let (w2, j2, out2, worst, json) = run("2");
    assert!(w1 == w2, "the world files differ between --jobs 1 and 2");
    assert!(j1 == j2, "the JSON files differ between --jobs 1 and 2");
    assert_eq!(out1, out2);
    assert!(worst.with_extension("rrd").exists());
    let v = read_json(&json);
    assert_eq!(v["methods"].as_array().map(Vec::len), Some(2));
    assert_eq!(v["methods"][1]["method"], "random");
    // Same run count for both methods.
    assert_eq!(v["methods"][0]["runs"], v["methods"][1]["runs"]);
    // The CEM's refinement (its fourth finalist's runs) descends from the worst run it had
    // before (searched or held-out) on that run's seed, and the witness is at least as bad;
    // random search does not refine.
    let rho = |r: &Value| {
        if r["robustness"]["collided"].as_bool() == Some(true) {
            f64::NEG_INFINITY
        } else {
            r["robustness"]["value"].as_f64().expect("rho")
        }
    };
    let evals = |m: usize| {
        let m = &v["methods"][m];
        let mut e = m["search"].as_array().expect("search").clone();
        e.extend(
            m["finalists"]
                .as_array()
                .expect("finalists")
                .iter()
                .cloned(),
        );
        e
    };
    let (refined, before): (Vec<_>, Vec<_>) = evals(0)
        .into_iter()
        .partition(|e| e["refinement"].as_bool() == Some(true));
    assert!(!refined.is_empty());
    assert!(evals(1).iter().all(|e| e["refinement"] == false));
    let start = before
        .iter()
        .flat_map(|e| e["runs"].as_array().expect("runs").clone())
        .min_by(|a, b| rho(a).total_cmp(&rho(b)))
        .expect("runs");
    for e in &refined {
        let runs = e["runs"].as_array().expect("runs");
        assert!(runs.len() == 1 && runs[0]["seed"] == start["seed"], "{e}");
    }
    let witness = &v["methods"][0]["witness"];
    assert!(rho(witness) <= rho(&start), "{witness} vs {start}");
    assert_eq!(
        witness["found_in"] == "refinement",
        rho(witness) < rho(&start),
        "{witness}"
    );
    // The paired comparison plays both best attacks on the same held-out seeds and counts, seed
    // by seed, which is worse; the counts match the finalists' runs.
    let best_runs = |m: usize| -> Vec<(u64, f64)> {
        v["methods"][m]["finalists"][0]["runs"]
            .as_array()
            .expect("runs")
            .iter()
            .map(|r| {
                (
                    r["seed"].as_u64().expect("seed"),
                    r["robustness"]["value"].as_f64().expect("rho"),
                )
            })
            .collect()
    };
    let (a, b) = (best_runs(0), best_runs(1));
    let cem_worse = a
        .iter()
        .zip(&b)
        .filter(|((sa, ra), (sb, rb))| sa == sb && ra < rb)
        .count();
    let paired = &v["paired"];
    assert_eq!(paired["seeds"].as_u64(), Some(a.len() as u64), "{paired}");
    assert_eq!(
        paired["cem_worse"].as_u64(),
        Some(cem_worse as u64),
        "{paired}"
    );
    assert!(out1.contains("best attacks, paired on the"), "{out1}");
    // The attack-free reference runs the world without attacks on the same held-out seeds, each
    // run as `ftcbf run` of the world with its [[attacks]] removed gives it, and counts, seed by
    // seed, where each method's best attack is the worse.
    let free = &v["attack_free"];
    let free_runs: Vec<(u64, f64)> = free["runs"]
        .as_array()
        .expect("attack_free.runs")
        .iter()
        .map(|r| (r["seed"].as_u64().expect("seed"), rho(r)))
        .collect();
    assert_eq!(
        free_runs.iter().map(|r| r.0).collect::<Vec<_>>(),
        a.iter().map(|r| r.0).collect::<Vec<_>>()
    );
    for (m, best) in [(0, &a), (1, &b)] {
        let moved = &free["moved"][m];
        let worse = best
            .iter()
            .zip(&free_runs)
            .filter(|((_, ra), (_, rf))| ra < rf)
            .count();
        assert_eq!(
            moved["attack_worse"].as_u64(),
            Some(worse as u64),
            "{moved}"
        );
        assert_eq!(moved["seeds"].as_u64(), Some(best.len() as u64), "{moved}");
    }
    let mut plain: toml::Table = std::fs::read_to_string("worlds/paper_linear.toml")
        .expect("world")
        .parse()
        .expect("toml");
    plain.remove("attacks");
    plain.remove("expect");
    let plain_path = tmp("lin_attack_free.toml");
    std::fs::write(&plain_path, toml::to_string(&plain).expect("toml")).expect("write");
    let (seed, rho_free) = free_runs[free_runs.len() - 1];
    let o = ftcbf(&[
        "run",
        s(&plain_path),
        "--seed",
        &seed.to_string(),
        "--no-record",
        "--json",
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let summary: Value = serde_json::from_slice(&o.stdout).expect("run json");
    let replayed = summary["min_barrier"]
        .as_array()
        .expect("min_barrier")
        .iter()
        .map(|b| b["value"].as_f64().expect("h"))
        .chain(summary["min_clearance"].as_f64())
        .fold(f64::INFINITY, f64::min);
    assert_eq!(replayed, rho_free, "{summary}");
    assert!(out1.contains("no attack, on the same"), "{out1}");
    let patterns: Vec<Vec<String>> = v["patterns"]
        .as_array()
        .expect("patterns")
        .iter()
        .map(|p| {
            p["channels"]
                .as_array()
                .expect("channels")
                .iter()
                .map(|c| c[0].as_str().expect("name").to_string())
                .collect()
        })
        .collect();
    for m in v["methods"].as_array().expect("methods") {
        for e in m["search"]
            .as_array()
            .expect("search")
            .iter()
            .chain(m["finalists"].as_array().expect("finalists"))
        {
            let chans: Vec<String> = e["attacks"]
                .as_array()
                .expect("attacks")
                .iter()
                .flat_map(|a| a["channels"].as_array().expect("channels").clone())
                .map(|c| c.as_str().expect("name").to_string())
                .collect();
            assert!(
                patterns.iter().any(|p| chans.iter().all(|c| p.contains(c))),
                "{chans:?} is not inside one pattern of {patterns:?}"
            );
        }
    }

    let o = ftcbf(&[
        "falsify",
        "worlds/outside_model.toml",
        "--budget",
        "24",
        "--no-random",
        "--no-record",
        "--out",
        s(&tmp("outside.toml")),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(
        text(&o).contains("warning: the world's own attacks[0]")
            && text(&o).contains("leaves the paper's threat model"),
        "{}",
        text(&o)
    );
}

#[test]
fn bad_input_is_named() {
    let o = ftcbf(&["falsify", "worlds/nope.toml", "--no-record"]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("nope.toml"), "{}", text(&o));
    // clap's range error is a usage error: exit 64, not the invalid-world 2.
    let o = ftcbf(&["falsify", "worlds/paper_linear.toml", "--budget", "5"]);
    assert_eq!(o.status.code(), Some(64), "{}", text(&o));
    assert!(text(&o).contains("--budget"), "{}", text(&o));
    let o = ftcbf(&[
        "falsify",
        "worlds/paper_linear.toml",
        "--budget",
        "24",
        "--out",
        "x.yaml",
    ]);
    assert_ne!(o.status.code(), Some(0), "{}", text(&o));
}

/// The counterexamples `falsify` found inside worlds where `check` said Theorem 3 applies
/// (tests/worlds_falsify, README "Worst attacks found"): each stays inside one declared fault
/// pattern, `check` now names the hypothesis that fails (the explanation its header gives), and
/// `regress` confirms the behaviour its [expect] records (since Step 3 keeps saturated
/// estimators, FT-CBF-CLF is safe there).
#[test]
fn falsify_counterexamples_are_explained_and_regressed() {
    let dir = "tests/worlds_falsify";
    let mut worlds: Vec<PathBuf> = std::fs::read_dir(dir)
        .expect("tests/worlds_falsify")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    worlds.sort();
    assert!(!worlds.is_empty());
    for w in &worlds {
        let o = ftcbf(&["check", s(w)]);
        assert_eq!(o.status.code(), Some(0), "{}", text(&o));
        assert!(
            text(&o).contains("verdict: Theorem 3 does NOT apply")
                && text(&o).contains("[FAILS  ] condition 1 under the input limit")
                && text(&o).contains("[HOLDS  ] attacks inside one fault pattern"),
            "{}: {}",
            w.display(),
            text(&o)
        );
        let body = std::fs::read_to_string(w).expect("world");
        assert!(
            body.starts_with("# A counterexample `ftcbf falsify` found"),
            "{}",
            w.display()
        );
    }
    let o = ftcbf(&["regress", dir]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(text(&o).contains("0 failed"), "{}", text(&o));
}

/// `--scenario` (issue #31): the same seed gives the same report and worst-run world for any
/// --jobs (the time aside); the JSON counts the variants tried, accepted by `check` and the
/// unsafe runs where it applies; the written worst run replays with `ftcbf run`; the [falsify]
/// table of the world file moves the ranges.
#[test]
fn scenario_search_is_deterministic_counts_and_replays() {
    let world = "worlds/corridor_spoof.toml";
    let mut reports = Vec::new();
    let mut worlds = Vec::new();
    for jobs in ["1", "2"] {
        let json = tmp(&format!("scenario-{jobs}.json"));
        let out = tmp(&format!("scenario-{jobs}.toml"));
        let o = ftcbf(&[
            "falsify",
            world,
            "--scenario",
            "--budget",
            "8",
            "--jobs",
            jobs,
            "--json",
            s(&json),
            "--out",
            s(&out),
            "--defects",
            s(&tmp("scenario-defects")),
        ]);
        assert_eq!(o.status.code(), Some(0), "{}", text(&o));
        assert!(text(&o).contains("variants: "), "{}", text(&o));
        let mut v = read_json(&json);
        assert!(v["time_seconds"].as_f64().is_some_and(|t| t > 0.0));
        v["time_seconds"] = Value::Null;
        reports.push(v);
        worlds.push(std::fs::read_to_string(&out).expect("worst world"));
    }
    assert_eq!(reports[0], reports[1]);
    assert_eq!(worlds[0], worlds[1]);
    let v = &reports[0];
    // budget 8 with the world's own attack: 1 variant × (own + 3 uniform) + 2 + 2 CMA-ES runs.
    assert_eq!(v["plan"]["runs_per_variant"], 4);
    assert_eq!(v["plan"]["variants_wanted"], 1);
    let tried = v["variants_tried"].as_u64().expect("tried");
    let accepted = v["variants_accepted"].as_u64().expect("accepted");
    let rejected = [
        "variants_invalid",
        "variants_not_applies",
        "variants_not_live",
    ]
    .iter()
    .map(|k| v[k].as_u64().expect("count"))
    .sum::<u64>();
    assert_eq!(accepted, 1, "{v}");
    assert!(tried >= accepted && rejected <= tried - accepted, "{v}");
    assert_eq!(v["runs"], 8);
    assert_eq!(v["unsafe_where_applies"], 0);
    assert_eq!(v["defects"].as_array().map(Vec::len), Some(0));
    // The variant moved the world: the written worst run is not the catalogue file's start.
    let written: toml::Table = toml::from_str(&worlds[0]).expect("TOML");
    let original: toml::Table =
        toml::from_str(&std::fs::read_to_string(world).expect("world")).expect("TOML");
    assert_ne!(written["goal"]["center"], original["goal"]["center"]);
    assert!(worlds[0].starts_with("# Written by `ftcbf falsify"));
    let o = ftcbf(&["run", s(&tmp("scenario-1.toml")), "--no-record", "--json"]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let summary: Value = serde_json::from_slice(&o.stdout).expect("summary JSON");
    let worst = v["worst"]["robustness"]["value"].as_f64().expect("ρ");
    let margins: Vec<f64> = summary["min_barrier"]
        .as_array()
        .expect("min_barrier")
        .iter()
        .filter_map(|b| b["value"].as_f64())
        .chain(summary["min_clearance"].as_f64())
        .collect();
    assert!(margins.contains(&worst), "{worst} not in {margins:?}");

    // A [falsify] table narrows the ranges: with every range 0 the variant is the world itself.
    let still = tmp("still.toml");
    let body = std::fs::read_to_string(world).expect("world");
    std::fs::write(
        &still,
        format!(
            "{}\n[falsify]\nobstacle_shift = 0.0\nobstacle_scale = 0.0\nstart_shift = 0.0\nstart_heading = 0.0\ngoal_shift = 0.0\nnoise = 0.0\nonset_shift = 0.0\n",
            body.replace("../robots/", &format!("{}/robots/", env!("CARGO_MANIFEST_DIR")))
        ),
    )
    .expect("write");
    let json = tmp("still.json");
    let o = ftcbf(&[
        "falsify",
        s(&still),
        "--scenario",
        "--budget",
        "8",
        "--json",
        s(&json),
        "--defects",
        s(&tmp("still-defects")),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let v = read_json(&json);
    assert_eq!(v["ranges"]["goal_shift"], 0.0);
    let accepted = &v["accepted"][0];
    assert_eq!(accepted["goal"], serde_json::json!([0.0, 0.0]));
    assert!(accepted["noise"]
        .as_array()
        .expect("noise")
        .iter()
        .all(|k| k.as_f64() == Some(1.0)));
}

#[test]
fn scenario_ranges_are_checked() {
    // Unknown or out-of-range --range values are usage errors.
    for bad in ["nosie=0.1", "noise=1.5", "goal_shift=x"] {
        let o = ftcbf(&[
            "falsify",
            "worlds/corridor_spoof.toml",
            "--scenario",
            "--range",
            bad,
        ]);
        assert_ne!(o.status.code(), Some(0), "{bad}: {}", text(&o));
        assert!(
            text(&o).contains("--range") || text(&o).contains("range"),
            "{}",
            text(&o)
        );
    }
    // --range without --scenario is a usage error; so is a budget below 8 with it.
    let o = ftcbf(&[
        "falsify",
        "worlds/corridor_spoof.toml",
        "--range",
        "noise=0.1",
    ]);
    assert_eq!(o.status.code(), Some(64), "{}", text(&o));
    let o = ftcbf(&[
        "falsify",
        "worlds/corridor_spoof.toml",
        "--scenario",
        "--budget",
        "7",
    ]);
    assert_eq!(o.status.code(), Some(64), "{}", text(&o));
    assert!(text(&o).contains("--budget 7"), "{}", text(&o));
    // A typo in the [falsify] table is an invalid world naming the key; a bad value names it too.
    let body = std::fs::read_to_string("worlds/corridor_spoof.toml").expect("world");
    let body = body.replace(
        "../robots/",
        &format!("{}/robots/", env!("CARGO_MANIFEST_DIR")),
    );
    let typo = tmp("typo.toml");
    std::fs::write(&typo, format!("{body}\n[falsify]\nobstacle_shfit = 0.1\n")).expect("write");
    let o = ftcbf(&["falsify", s(&typo), "--scenario", "--budget", "8"]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("obstacle_shfit"), "{}", text(&o));
    let bad = tmp("bad_range.toml");
    std::fs::write(&bad, format!("{body}\n[falsify]\nnoise = 2.0\n")).expect("write");
    let o = ftcbf(&["falsify", s(&bad), "--scenario", "--budget", "8"]);
    assert_ne!(o.status.code(), Some(0), "{}", text(&o));
    assert!(
        text(&o).contains("bad_range.toml") && text(&o).contains("[falsify] `noise` = 2"),
        "{}",
        text(&o)
    );
}

/// The library reports to the caller's `Progress` (it draws nothing itself): the search starts
/// it at `Settings::runs` and advances it exactly that many times, with and without random
/// search.
#[test]
fn the_library_search_advances_the_callers_progress_once_per_run() {
    use ftcbf_lab::falsify::{falsify, Settings, WorldTemplate};
    use ftcbf_lab::progress::Progress;
    use std::sync::atomic::{AtomicU64, Ordering};
    /// (announced length, units advanced, finished).
    #[derive(Default)]
    struct Count(AtomicU64, AtomicU64, AtomicU64);
    impl Progress for Count {
        fn start(&self, len: u64, _label: &str) {
            self.0.store(len, Ordering::Relaxed);
        }
        fn advance(&self, n: u64) {
            self.1.fetch_add(n, Ordering::Relaxed);
        }
        fn phase(&self, _label: &str) {}
        fn finish(&self) {
            self.2.fetch_add(1, Ordering::Relaxed);
        }
    }
    let template = WorldTemplate::load(Path::new("worlds/paper_linear.toml")).expect("world");
    for compare_random in [false, true] {
        let settings = Settings {
            controller: template.world.file.control.controller,
            budget: 24,
            seed: 1,
            jobs: Some(2),
            compare_random,
            family: ftcbf_lab::falsify::Family::Injectors,
        };
        let count = Count::default();
        let report = falsify(&template, &settings, &count).expect("search");
        assert_eq!(report.methods.len(), 1 + usize::from(compare_random));
        let runs = settings.runs().expect("runs");
        let seen = [&count.0, &count.1, &count.2].map(|a| a.load(Ordering::Relaxed));
        assert_eq!(seen, [runs, runs, 1], "random search: {compare_random}");
        // The budget is per method; the two methods share their first generation; the
        // attack-free reference adds one run per held-out seed, outside the budgets.
        let reference = report.plan.final_seeds as u64;
        assert_eq!(
            report.attack_free.as_ref().map(|a| a.runs.len() as u64),
            Some(reference)
        );
        if compare_random {
            assert!(24 + reference < runs && runs < 48 + reference, "{runs}");
        } else {
            assert_eq!(runs, 24 + reference);
        }
    }
}
