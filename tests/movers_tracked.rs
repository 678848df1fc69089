//! Movers read through a noisy obstacle sensor and its filter (issue #51): the world file's
//! `tracker`, the controller reading the filter's estimate instead of the truth, its error
//! within the bounds the row is lowered by, the run repeating bit for bit with the seed, a
//! declared attack, and bad keys naming themselves.

use std::path::{Path, PathBuf};

use ftcbf_sim::analysis::check::{check_world, Status};
use ftcbf_sim::runner::{run, RunOptions, Simulation};
use ftcbf_sim::world::{ControllerKindSpec, World};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

const TRACKED: &str = "tests/worlds_movers/tracked_crossing.toml";

fn world(rel: &str) -> World {
    World::load(&root().join(rel), &[]).unwrap_or_else(|e| panic!("{e}"))
}

/// The tracked world with `from` replaced by `to` in its text.
fn tracked_with(from: &str, to: &str) -> Result<World, String> {
    let path = root().join(TRACKED);
    let text = std::fs::read_to_string(&path).expect("readable");
    assert!(text.contains(from), "`{from}` not in the world");
    let text = text.replacen(from, to, 1);
    World::from_str(&text, Path::new(&path), &[]).map_err(|e| e.to_string())
}

fn opts(seed: u64) -> RunOptions {
    RunOptions {
        seed: Some(seed),
        controller: Some(ControllerKindSpec::FtCbfClf),
        ..RunOptions::default()
    }
}

/// At every control step of a seeded run, each tracked mover's reading (what the controller
/// read) differs from the truth by no more than its bounds γ_p (position) and γ_v (velocity):
/// ε' = ε/(N·M) = 1.25e-5 per reading makes a miss in 6000 readings unlikely (≤ 0.075 by the
/// union bound), so none is allowed. The readings are not the truth (noise), and their bounds
/// are positive and finite.
#[test]
fn the_controller_reads_the_filter_and_its_error_stays_within_the_bounds() {
    let w = world(TRACKED);
    let mut sim = Simulation::new(&w, &opts(3)).expect("builds");
    let (mut steps, mut differ, mut worst) = (0u64, 0u64, [0.0f64; 2]);
    while let Some(truth) = sim.step().map(|f| f.movers.to_vec()) {
        let read = sim.mover_readings();
        assert_eq!(read.len(), 2);
        for (r, t) in read.iter().zip(&truth) {
            assert!(
                r.position_bound > 0.0 && r.position_bound.is_finite(),
                "{r:?}"
            );
            assert!(
                r.velocity_bound > 0.0 && r.velocity_bound.is_finite(),
                "{r:?}"
            );
            let ep = (r.displacement[0] - t.displacement[0])
                .hypot(r.displacement[1] - t.displacement[1]);
            let ev = (r.velocity[0] - t.velocity[0]).hypot(r.velocity[1] - t.velocity[1]);
            assert!(
                ep <= r.position_bound && ev <= r.velocity_bound,
                "step {steps}: error {ep:.4} m, {ev:.4} m/s over the bounds {:.4} m, {:.4} m/s",
                r.position_bound,
                r.velocity_bound
            );
            worst = [
                worst[0].max(ep / r.position_bound),
                worst[1].max(ev / r.velocity_bound),
            ];
            differ += u64::from(ep > 0.0);
        }
        steps += 1;
    }
    assert_eq!(steps, 3000);
    assert!(
        differ > 5000,
        "{differ} of 6000 readings differ from the truth"
    );
    eprintln!(
        "worst error / bound: position {:.3}, velocity {:.3}",
        worst[0], worst[1]
    );
}

/// The tracked run repeats bit for bit with its seed, and another seed draws other detections.
/// The world is safe and settles on both.
#[test]
fn tracked_runs_repeat_with_the_seed() {
    let w = world(TRACKED);
    let a = run(&w, &opts(5)).expect("runs");
    assert_eq!(a.to_string(), run(&w, &opts(5)).expect("runs").to_string());
    let b = run(&w, &opts(6)).expect("runs");
    assert_ne!(a.min_clearance, b.min_clearance);
    assert!(a.safe && b.safe, "{a}\n{b}");
}

/// Without the trackers the same world reads its movers exactly: the controller's readings
/// are the truth at every step.
#[test]
fn without_a_tracker_the_reading_is_the_truth() {
    let path = root().join(TRACKED);
    let text: String = std::fs::read_to_string(&path)
        .expect("readable")
        .lines()
        .filter(|l| !l.starts_with("tracker ="))
        .map(|l| format!("{l}\n"))
        .collect();
    let w = World::from_str(&text, Path::new(&path), &[]).expect("loads");
    let mut sim = Simulation::new(&w, &opts(3)).expect("builds");
    for _ in 0..500 {
        let truth = sim.step().expect("steps").movers.to_vec();
        assert_eq!(sim.mover_readings(), truth.as_slice());
    }
}

fn status_of(w: &World, name: &str) -> (Status, String) {
    let report = check_world(w).expect("checks");
    let f = report
        .hypotheses
        .iter()
        .find(|f| f.name.contains(name))
        .unwrap_or_else(|| panic!("no finding `{name}`"));
    (f.status, f.detail.clone())
}

/// `check` prints each tracker's bounds and margin, assumes honest detections without a
/// declared attack, and refuses the guarantee with one (one sensor: nothing to vote with).
#[test]
fn check_states_the_trackers_bounds_and_refuses_a_declared_attack() {
    let w = world(TRACKED);
    let (s, d) = status_of(&w, "tracker of `cart`");
    assert_eq!(s, Status::Assumed);
    assert!(d.contains("γ_p = 0.0") && d.contains("margin grows"), "{d}");
    let (s, d) = status_of(&w, "are honest");
    assert_eq!(s, Status::Assumed, "{d}");
    let (s, _) = status_of(&w, "input to escape tracked `person`");
    assert_eq!(s, Status::Holds);
    let r = check_world(&w).expect("checks");
    assert!(r.verdict.applies, "{:?}", r.verdict.reasons);
    // The tracked readings' ε is added to the claim: 1 − 0.05 − 0.05.
    assert!(
        r.verdict.line().contains("1 − ε − ε_tracked = 0.9 "),
        "{}",
        r.verdict.line()
    );
    let attacked = world("tests/worlds_movers/tracked_crossing_attacked.toml");
    let (s, d) = status_of(&attacked, "attack on the tracker of `cart`");
    assert_eq!(s, Status::Fails);
    assert!(d.contains("no redundancy") && d.contains("0.150 m"), "{d}");
    assert!(!check_world(&attacked).expect("checks").verdict.applies);
}

#[test]
fn bad_tracker_keys_are_errors_naming_the_obstacle_and_key() {
    let line = "tracker = { position_std = 0.03, rate = 10.0 }";
    for (to, key, expected) in [
        ("tracker = { position_std = -0.03, rate = 10.0 }", "obstacles[0].tracker.position_std", "noise standard deviation"),
        ("tracker = { position_std = nan, rate = 10.0 }", "obstacles[0].tracker.position_std", "found NaN"),
        ("tracker = { position_std = 0.03, rate = 500.0 }", "obstacles[0].tracker.rate", "at most the control rate"),
        ("tracker = { position_std = 0.03, rate = 0.0 }", "obstacles[0].tracker.rate", "detection rate"),
        ("tracker = { position_std = 0.03, rate = 10.0, accel_std = 0.0 }", "obstacles[0].tracker.accel_std", "> 0"),
        ("tracker = { position_std = 0.03, rate = 10.0, attack = { bias = [inf, 0.0] } }", "obstacles[0].tracker.attack.bias", "finite"),
        ("tracker = { position_std = 0.03, rate = 10.0, attack = { bias = [0.1, 0.0], start = 5.0, end = 2.0 } }", "obstacles[0].tracker.attack.end", "after `start`"),
        ("tracker = { position_std = 0.03, rate = 10.0, range = 4.0 }", "range", "unknown field"),
        ("tracker = { rate = 10.0 }", "position_std", "missing"),
    ] {
        let e = tracked_with(line, to).expect_err(to);
        assert!(
            e.contains(key) && e.contains(expected),
            "{to}: {e} (expected `{key}` and `{expected}`)"
        );
        if key.starts_with("obstacles[0]") {
            assert!(e.contains("`cart`"), "{to}: {e} does not name the obstacle");
        }
    }
    // On an obstacle that stands still.
    let e = tracked_with(
        "motion = { kind = \"velocity\", velocity = [0.0, 0.08] }\n",
        "",
    )
    .expect_err("a tracker on a static obstacle");
    assert!(
        e.contains("obstacles[0].tracker") && e.contains("no `motion`") && e.contains("`cart`"),
        "{e}"
    );
}
