//! Issue #29: never report SAFE on a number that is not one. `check` and `run` refuse the same
//! worlds with exit 2 naming the user's key; `check` fails the start outside the safe set and
//! a goal inside an obstacle; usage errors have their own exit code; messages have a place.

use std::path::{Path, PathBuf};
use std::process::Command;

use ftcbf_sim::analysis::check::{check_world, Status};
use ftcbf_sim::world::World;

mod common;
use common::{ftcbf, root, text};

fn world_with(file: &str, from: &str, to: &str) -> World {
    let p = root().join("worlds").join(file);
    let t = std::fs::read_to_string(&p).expect("catalogue world");
    assert!(t.contains(from), "{file} has no `{from}`");
    World::from_str(&t.replacen(from, to, 1), &p, &[]).expect("a valid world")
}

fn hypothesis(w: &World, prefix: &str) -> (Status, String, bool) {
    let r = check_world(w).expect("check runs");
    let h = r
        .hypotheses
        .iter()
        .find(|h| h.name.starts_with(prefix))
        .unwrap_or_else(|| panic!("no hypothesis `{prefix}`"));
    (h.status, h.detail.clone(), r.verdict.applies)
}

#[test]
fn a_start_outside_the_safe_set_fails_theorem_3() {
    // The floor is y + 0.2·ẏ + 0.05 ≥ 0: a start at y = −0.5 has h = −0.45.
    let w = world_with("paper_turtlebot_receivers.toml", "y = 0.0,", "y = -0.5,");
    let (status, detail, applies) = hypothesis(&w, "start inside every safe set");
    assert_eq!(status, Status::Fails, "{detail}");
    assert!(detail.contains("h(floor) = -0.45"), "{detail}");
    assert!(!applies);
    // The catalogue's own start holds.
    let p = root().join("worlds/paper_turtlebot_receivers.toml");
    let w = World::load(&p, &[]).expect("catalogue");
    let (status, detail, applies) = hypothesis(&w, "start inside every safe set");
    assert_eq!(status, Status::Holds, "{detail}");
    assert!(applies);
}

#[test]
fn a_start_inside_an_obstacle_fails_and_the_run_is_unsafe_at_once() {
    // doorway_clutter's pillar stands at (1.9, 0) with radius 0.15.
    let w = world_with(
        "doorway_clutter.toml",
        "start = { x = 0.0, y = 0.0, theta = 0.0 }",
        "start = { x = 1.9, y = 0.0, theta = 0.0 }",
    );
    let (status, detail, applies) = hypothesis(&w, "start inside every safe set");
    assert_eq!(status, Status::Fails, "{detail}");
    assert!(detail.contains("obstacle:pillar"), "{detail}");
    assert!(!applies);
    let o = ftcbf(&["check", "worlds/doorway_clutter.toml"]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(!text(&o).contains("NaN"), "{}", text(&o));
}

#[test]
fn a_goal_inside_an_obstacle_fails() {
    let w = world_with(
        "doorway_clutter.toml",
        "center = [3.0, 0.0]",
        "center = [1.9, 0.0]",
    );
    let (status, detail, applies) = hypothesis(&w, "goal clear of the obstacles");
    assert_eq!(status, Status::Fails, "{detail}");
    assert!(detail.contains("obstacle:pillar"), "{detail}");
    assert!(!applies);
}

/// Every invalid world is refused by `check` and by `run` alike: exit 2, the file named.
#[test]
fn check_and_run_refuse_every_invalid_world_with_exit_2() {
    let dir = root().join("tests/invalid_worlds");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .expect("tests/invalid_worlds")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    files.sort();
    let mut problems = Vec::new();
    for f in &files {
        let rel = f.strip_prefix(root()).unwrap_or(f).display().to_string();
        let name = f.file_name().and_then(|n| n.to_str()).unwrap_or_default();
        for cmd in [vec!["check", &rel], vec!["run", &rel, "--no-record"]] {
            let o = ftcbf(&cmd);
            let t = text(&o);
            if o.status.code() != Some(2) || !t.contains(name) || t.contains("panicked") {
                problems.push(format!("{} {rel}: exit {:?}: {t}", cmd[0], o.status.code()));
            }
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

#[test]
fn the_issues_run_reproducers_are_refused_naming_the_key() {
    for (set, key) in [
        ("robot.start.y=-1e308", "robot.start.y"),
        ("control.rate_hz=1e-9", "control.rate_hz"),
        ("goal.radius=1e-300", "goal.radius"),
        ("control.epsilon=5e-324", "control.epsilon"),
        ("control.initial_std[0]=1e308", "control.initial_std[0]"),
        // `check` never returned (rate 1e-300) or took seconds (a start or goal at 1e6 m: the
        // planner's grid); goal and ellipse centres at 1e300 gave null final states.
        ("control.rate_hz=1e-300", "control.rate_hz"),
        ("robot.start.x=1e6", "robot.start.x"),
        ("goal.center[0]=1e300", "goal.center[0]"),
        ("control.process_noise=1e-320", "control.process_noise"),
        ("safe_sets[0].b=1e300", "safe_sets[0].b"),
    ] {
        let o = ftcbf(&[
            "run",
            "worlds/paper_turtlebot.toml",
            "--no-record",
            "--duration",
            "2",
            "--set",
            set,
        ]);
        let t = text(&o);
        assert_eq!(o.status.code(), Some(2), "{set}: {t}");
        assert!(t.contains(&format!("`{key}`")), "{set}: {t}");
        assert!(!t.contains("SAFE"), "{set}: {t}");
    }
    let o = ftcbf(&[
        "run",
        "worlds/doorway_clutter.toml",
        "--no-record",
        "--set",
        "obstacles[0].position[2]=1e308",
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(
        text(&o).contains("`obstacles[0].position[2]`"),
        "{}",
        text(&o)
    );
}

#[test]
fn usage_errors_exit_64_and_a_negative_duration_is_a_range_error() {
    let o = ftcbf(&["run", "worlds/paper_linear.toml", "--duration", "-1"]);
    assert_eq!(o.status.code(), Some(64), "{}", text(&o));
    assert!(
        text(&o).contains("--duration -1: expected a number of seconds in (0, 3600] s"),
        "{}",
        text(&o)
    );
    let o = ftcbf(&["run", "worlds/paper_linear.toml", "--duration", "1e5"]);
    assert_eq!(o.status.code(), Some(64), "{}", text(&o));
    let o = ftcbf(&["run", "worlds/paper_linear.toml", "--no-such-flag"]);
    assert_eq!(o.status.code(), Some(64), "{}", text(&o));
    let o = ftcbf(&["--help"]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
}

#[test]
fn invalid_utf8_is_named_once_with_its_byte_offset() {
    let dir = common::tmp_in("reliability", "utf8");
    std::fs::create_dir_all(&dir).expect("scratch");
    let f = dir.join("latin1.toml");
    // "café" in Latin-1: byte 0xE9 at offset 31, line 3, column 6.
    std::fs::write(&f, b"name = \"x\"\nduration = 1.0\n# caf\xe9\n").expect("write");
    let e = World::load(&f, &[]).expect_err("refused").to_string();
    assert!(
        e.contains("invalid byte 0xe9 at byte offset 31 (line 3, column 6)"),
        "{e}"
    );
    let o = ftcbf(&["check", f.to_str().expect("utf-8 path")]);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(2), "{t}");
    assert_eq!(t.matches("byte offset").count(), 1, "{t}");
    // A missing file's cause is said once, not twice.
    let o = ftcbf(&["check", "worlds/no_such_world.toml"]);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(2), "{t}");
    assert_eq!(t.matches("No such file").count(), 1, "{t}");
}

#[test]
fn check_agrees_with_run_on_the_catalogue() {
    // Every catalogue world passes validation, check and the run's preflight alike.
    for e in std::fs::read_dir(root().join("worlds")).expect("worlds/") {
        let p = e.expect("entry").path();
        if p.extension().is_none_or(|x| x != "toml") {
            continue;
        }
        let w = World::load(Path::new(&p), &[]).expect("catalogue world is valid");
        assert!(check_world(&w).is_ok(), "{}", p.display());
        assert!(ftcbf_sim::runner::preflight(&w).is_ok(), "{}", p.display());
    }
}

/// The exit-70 path: a panic inside a command, on the main thread or in a worker thread of the
/// trial pool, ends with exit 70 and one error line naming the panic and its place, instead of
/// Rust's exit 101 and its panic text. No input is known to panic any more, so the binary's test
/// hook `FTCBF_TEST_PANIC` (README, "Development") injects one.
#[test]
fn a_contained_panic_exits_70_with_its_message_and_place() {
    let ftcbf_with = |hook: &str, args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_ftcbf"))
            .args(args)
            .env("FTCBF_TEST_PANIC", hook)
            .current_dir(root())
            .output()
            .expect("the binary runs")
    };
    for (hook, args) in [
        ("main", ["run", "worlds/paper_linear.toml", "--no-record"]),
        ("worker", ["check", "worlds/paper_linear.toml", "--strict"]),
    ] {
        let o = ftcbf_with(hook, &args);
        let t = text(&o);
        assert_eq!(o.status.code(), Some(70), "{hook}: {t}");
        assert!(o.stdout.is_empty(), "{hook}: {t}");
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(stderr.lines().count(), 1, "{hook}: {stderr}");
        assert!(
            stderr.starts_with(&format!(
                "error: internal error: the simulation stopped on a panic (FTCBF_TEST_PANIC={hook}: \
                 a panic injected to test the exit-70 path at src/main.rs:"
            )),
            "{hook}: {stderr}"
        );
        assert!(
            stderr
                .contains("this is a bug — please report it with the world file and command line"),
            "{stderr}"
        );
        assert!(!stderr.contains("panicked at"), "{stderr}");
    }
    // Any other value leaves the command alone.
    let o = ftcbf_with("", &["check", "worlds/paper_linear.toml"]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
}

/// Fail closed in the run summary: a world built in code (validation is the loader's, and a
/// library user can bypass it) whose barrier value overflows to +∞ ends UNSAFE with the quantity
/// named, never SAFE with min h = ∞ (issue #29: `robot.start.y = -1e308` printed "SAFE, min
/// h(floor) = inf"). +∞ lies above every bound, so only the non-finite check makes the run
/// UNSAFE.
#[test]
fn a_run_with_a_non_finite_barrier_value_is_unsafe_and_names_it() {
    use ftcbf_sim::runner::{run, RunOptions};
    let p = root().join("worlds/paper_linear.toml");
    let opts = RunOptions {
        duration: Some(0.2),
        ..RunOptions::default()
    };
    let w = World::load(&p, &[]).expect("catalogue world");
    let s = run(&w, &opts).expect("runs");
    assert!(
        s.safe && s.non_finite.is_none(),
        "the catalogue start is safe"
    );
    // h(floor) = y + 0.2·ẏ + 0.05 overflows: 1.7e308 + 3.4e307 = +∞, from finite numbers.
    let mut w = World::load(&p, &[]).expect("catalogue world");
    let x0 = &mut w.file.linear.as_mut().expect("a linear world").x0;
    x0[1] = 1.7e308;
    x0[3] = 1.7e308;
    let s = run(&w, &opts).expect("runs");
    assert!(!s.safe, "{:?}", s.min_barrier);
    let named = s.non_finite.as_deref().unwrap_or_default();
    assert!(named.contains("h(floor) = inf"), "{named:?}");
}

/// Issue #29, "bounded, or their cost shown": every size a world may grow has a cap, stated in
/// the README's world-file reference, and one entry past it is a clean error naming the key and
/// the cap — for the lists, the hull points, and the run's length in control and plant steps.
#[test]
fn every_size_cap_is_a_clean_error_one_past_it() {
    let p = root().join("worlds/paper_linear.toml");
    let base = std::fs::read_to_string(&p).expect("catalogue world");
    let refused = |text: &str| -> String {
        World::from_str(text, &p, &[])
            .expect_err("one past the cap")
            .to_string()
    };
    let count = |header: &str| base.matches(&format!("\n{header}\n")).count();
    let appended = |n: usize, entry: &dyn Fn(usize) -> String| -> String {
        let mut t = base.clone();
        for i in 0..n {
            t.push('\n');
            t.push_str(&entry(i));
        }
        t
    };
    let cases: Vec<(String, String)> = vec![
        (
            appended(257, &|i| {
                format!(
                    "[[obstacles]]\nname = \"o{i}\"\nposition = [{}, 50.0, 0.0]\nshape = {{ kind = \"ball\", radius = 0.1 }}\n",
                    10 + i
                )
            }),
            "`obstacles`: 257 entries; at most 256 are supported".into(),
        ),
        (
            appended(65 - count("[[safe_sets]]"), &|i| {
                format!("[[safe_sets]]\nkind = \"half_plane\"\nname = \"s{i}\"\na = [0.0, 1.0, 0.0, 0.2]\nb = -{i}.0\n")
            }),
            "`safe_sets`: 65 entries; at most 64 are supported".into(),
        ),
        (
            appended(65 - count("[[sensors]]"), &|i| {
                format!("[[sensors]]\nname = \"extra{i}\"\nmeasures = \"x\"\nnoise_std = 0.03\n")
            }),
            "`sensors`: 65 entries; at most 64 are supported".into(),
        ),
        (
            appended(65 - count("[[attacks]]"), &|_| {
                "[[attacks]]\nkind = \"bias\"\nchannels = [\"y1_x\"]\nvalue = 0.1\n".to_string()
            }),
            "`attacks`: 65 entries; at most 64 are supported".into(),
        ),
        (
            base.replacen(
                "[goal]\n",
                &format!(
                    "[goal]\nwaypoints = [{}]\n",
                    vec!["[0.5, 0.5]"; 257].join(", ")
                ),
                1,
            ),
            "`goal.waypoints`: 257 entries; at most 256 are supported".into(),
        ),
        (
            appended(1, &|_| {
                format!(
                    "[[obstacles]]\nname = \"hull\"\nposition = [9.0, 9.0, 0.0]\nshape = {{ kind = \"convex_hull\", points = [{}] }}\n",
                    vec!["[0.1, 0.2, 0.3]"; 100_001].join(", ")
                )
            }),
            "`obstacles[0].shape.points`: 100001 entries; at most 100000 are supported".into(),
        ),
        (
            // 3600 s at 1000 Hz: 3.6e6 control steps.
            base.replacen("rate_hz = 100.0", "rate_hz = 1000.0", 1)
                .replacen("duration = 20.0", "duration = 3600.0", 1),
            "`duration`: 3600 s at control.rate_hz = 1000 Hz is 3600000 control steps; at most 500000 are supported".into(),
        ),
        (
            // 3600 s at a 1e-4 s plant step: 3.6e7 plant steps.
            base.replacen("dt = 0.001 ", "dt = 0.0001 ", 1)
                .replacen("duration = 20.0", "duration = 3600.0", 1),
            "plant steps; at most 20000000 are supported".into(),
        ),
    ];
    for (text, want) in &cases {
        let e = refused(text);
        assert!(e.contains(want.as_str()), "want {want:?} in {e}");
        assert!(e.contains("paper_linear.toml"), "{e}");
    }
    // At the caps themselves the lists are accepted (the cap is where the message says).
    let at_cap = appended(256, &|i| {
        format!(
            "[[obstacles]]\nname = \"o{i}\"\nposition = [{}, 50.0, 0.0]\nshape = {{ kind = \"ball\", radius = 0.1 }}\n",
            10 + i
        )
    })
    .replacen("[linear]\n", "[linear]\nv_max = 1.0\n", 1);
    World::from_str(&at_cap, &p, &[]).expect("256 obstacles are accepted");
}

/// A reader that goes away (`ftcbf check W | head -1`) ends `ftcbf` by SIGPIPE, as it ends `cat`
/// or `grep`: not exit 70 with "internal error … failed printing to stdout: Broken pipe", which
/// called a closed pipe a bug, nor Rust's exit 101.
#[cfg(unix)]
#[test]
fn a_closed_output_pipe_ends_the_command_like_any_unix_tool() {
    use std::os::unix::process::ExitStatusExt;
    use std::process::Stdio;
    // Close the read end before the command starts, so its first write meets a closed pipe
    // whatever the scheduler does (closing it after `spawn` raced the child's output into the
    // pipe's buffer on a loaded CI machine: exit 0, no signal).
    let (reader, writer) = std::io::pipe().expect("a pipe");
    drop(reader);
    let o = Command::new(env!("CARGO_BIN_EXE_ftcbf"))
        .args(["check", "worlds/paper_turtlebot.toml"])
        .current_dir(root())
        .stdout(Stdio::from(writer))
        .stderr(Stdio::piped())
        .output()
        .expect("the binary runs");
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(
        o.status.signal(),
        Some(libc::SIGPIPE),
        "{:?}: {stderr}",
        o.status
    );
    assert!(stderr.is_empty(), "{stderr}");
}

/// Issue #29: "(4.4) … angular spread of Λ_i = NaN rad" whenever the start is inside an
/// obstacle, and "needs NaN × the box's authority" for a half-plane without a velocity term.
/// Through the CLI: `check` prints no NaN, fails the hypothesis with its number, and the
/// verdict does not apply.
#[test]
fn check_prints_no_nan_for_a_start_inside_an_obstacle_or_a_half_plane_without_velocity() {
    let dir = common::tmp_in("reliability", "nan_worlds");
    std::fs::create_dir_all(&dir).expect("scratch");
    let robots = root().join("robots");
    let write = |name: &str, world: &str, from: &str, to: &str| -> String {
        let t = std::fs::read_to_string(root().join("worlds").join(world)).expect("catalogue");
        assert_eq!(t.matches(from).count(), 1, "{world}: {from}");
        let t = t
            .replacen(from, to, 1)
            .replace("\"../robots/", &format!("\"{}/", robots.display()));
        let f = dir.join(name);
        std::fs::write(&f, t).expect("write");
        f.to_str().expect("utf-8 path").to_string()
    };
    let inside = write(
        "start_in_pillar.toml",
        "doorway_clutter.toml",
        "start = { x = 0.0, y = 0.0, theta = 0.0 }",
        "start = { x = 1.9, y = 0.0, theta = 0.0 }",
    );
    let flat = write(
        "floor_without_velocity.toml",
        "paper_turtlebot.toml",
        "a = [0.0, 1.0, 0.0, 0.2]",
        "a = [0.0, 1.0, 0.0, 0.0]",
    );
    for (f, says) in [
        (&inside, "[FAILS  ] start inside every safe set (x(0) ∈ C): the start x(0) = (1.9000, 0.0000) is outside the safe set: h(obstacle:pillar) = -0.293709"),
        (&flat, "[FAILS  ] condition 1 under the input limit for floor: at rest on ĥ = 0 the row of x̂_1 (drops gnss2_x) needs inf × the box's authority"),
    ] {
        let o = ftcbf(&["check", f]);
        let t = text(&o);
        assert_eq!(o.status.code(), Some(0), "{t}");
        assert!(!t.contains("NaN"), "{t}");
        assert!(t.contains(says), "{t}");
        assert!(t.contains("verdict: Theorem 3 does NOT apply"), "{t}");
        let o = ftcbf(&["check", "--strict", f]);
        assert_eq!(o.status.code(), Some(4), "{}", text(&o));
    }
    // The advice for a barrier the input cannot act on at rest is a velocity term, not an
    // infinite box.
    let t = text(&ftcbf(&["check", &flat]));
    assert!(!t.contains("≥ (inf"), "{t}");
    assert!(t.contains("no input limit can meet its robust row"), "{t}");
}

/// Found by the 10,000-input fuzz (a hang): a linear world with `process_noise = 0` gave its
/// filters no process noise either, and every Riccati recursion of `check` and of the run's
/// setup ran to its 10⁶-iteration limit (10 s for `check` on a loaded machine). Refused now,
/// naming the key and the way out; a noiseless plant with the filters' own q is accepted and
/// checked at once.
#[test]
fn a_noiseless_linear_plant_needs_the_filters_own_process_noise() {
    let p = root().join("worlds/paper_linear.toml");
    let t = std::fs::read_to_string(&p).expect("catalogue world");
    let noiseless = t.replacen("process_noise = 1e-3 ", "process_noise = 0.0 ", 1);
    assert_ne!(noiseless, t);
    let e = World::from_str(&noiseless, &p, &[])
        .expect_err("the filters would have q = 0")
        .to_string();
    assert!(
        e.contains("`linear.process_noise`: 0 (a noiseless plant) would also be the filters' process noise")
            && e.contains("set control.process_noise to a number in [1e-9, 1000]"),
        "{e}"
    );
    let own = noiseless.replacen("[control]\n", "[control]\nprocess_noise = 1e-3\n", 1);
    let w = World::from_str(&own, &p, &[]).expect("a noiseless plant, filters with q");
    let started = std::time::Instant::now();
    let r = check_world(&w).expect("check runs");
    assert!(
        r.context
            .iter()
            .any(|l| l.contains("reach a steady state, which the bounds use")),
        "{r}"
    );
    assert!(
        started.elapsed().as_secs_f64() < 5.0,
        "{:?}",
        started.elapsed()
    );
}

/// Validation runs before any work in every command: `batch`, `falsify` and `regress` refuse an
/// invalid world with exit 2 and the key named, as `check` and `run` do (the batch message had
/// an empty "with :" where a sweep point goes).
#[test]
fn every_command_refuses_an_invalid_world_with_exit_2_naming_the_key() {
    let w = "tests/invalid_worlds/goal_radius_tiny.toml";
    for args in [
        vec!["check", w],
        vec!["run", w, "--no-record"],
        vec!["batch", w, "--trials", "2"],
        vec!["falsify", w, "--budget", "24", "--no-record"],
        vec!["regress", w],
    ] {
        let o = ftcbf(&args);
        let t = text(&o);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {t}");
        assert!(
            t.contains("goal_radius_tiny.toml: `goal.radius`: expected a number in [1e-4, 1000] m, found 1e-300"),
            "{args:?}: {t}"
        );
        assert!(!t.contains("with :"), "{args:?}: {t}");
    }
}
