//! The guarantee bookkeeping on the catalogue: what `check` decides for the shipped worlds, and
//! whether the detectors behind Step 2 and Step 3 do what the bounds promise in closed loop.

use std::path::PathBuf;

use ftcbf_sim::analysis::check::{check_world, CovarianceBound, Status};
use ftcbf_sim::runner::{RunOptions, Simulation};
use ftcbf_sim::world::World;

fn path(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("worlds")
        .join(name)
}

fn world(name: &str) -> World {
    World::load(&path(name), &[]).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn corridor_applies_over_its_horizon_with_a_dead_reckoning_pair_filter() {
    let r = check_world(&world("corridor_spoof.toml")).expect("check");
    assert!(r.verdict.applies, "{r}");
    assert_eq!(r.verdict.horizon, Some(25.0), "{r}");
    let pair = r
        .filters
        .iter()
        .find(|f| f.label.starts_with("x̂_12"))
        .expect("pair filter");
    assert!(!pair.detectability.detectable);
    assert_eq!(
        pair.detectability.unobservable,
        vec!["x position".to_string(), "y position".to_string()]
    );
    assert_eq!(pair.channels, vec!["odom_vx", "odom_vy"]);
    assert!(matches!(
        pair.bound,
        CovarianceBound::FiniteHorizon { seconds } if seconds == 25.0
    ));
    // The singles keep one receiver and the odometry: detectable, steady state.
    for f in r.filters.iter().take(2) {
        assert!(f.detectability.detectable, "{}", f.label);
        assert_eq!(f.bound, CovarianceBound::SteadyState);
    }
    let text = r.to_string();
    assert!(
        text.contains("NOT detectable (PBH fails at λ = 0; unobservable: x position, y position)"),
        "{text}"
    );
    assert!(text.contains("verdict: Theorem 3 applies"), "{text}");
}

#[test]
fn attacks_on_two_patterns_void_the_guarantee() {
    let p = path("corridor_spoof.toml");
    let text = std::fs::read_to_string(&p).expect("world");
    let text = text.replace(
        "channels = [\"gnss2_x\", \"gnss2_y\"]\nstart = 2.0",
        "channels = [\"gnss2_x\", \"gnss1_y\"]\nstart = 2.0",
    );
    let w = World::from_str(&text, &p, &[]).expect("world");
    let r = check_world(&w).expect("check");
    assert!(!r.verdict.applies);
    assert!(
        r.verdict
            .line()
            .contains("the declared attacks touch gnss2 and gnss1"),
        "{}",
        r.verdict.line()
    );
}

#[test]
fn paper_linear_says_why_the_goal_cannot_be_held() {
    let r = check_world(&world("paper_linear.toml")).expect("check");
    // Its 2 m/s² box is 1.79× too small for the robust row at rest on the floor (see
    // `paper_worlds_boxes_are_too_small_for_their_robust_rows`).
    assert!(!r.verdict.applies, "{r}");
    // #10: at rest the CBF needs h ≥ h̄ + γ‖aKc̄‖/κ ≈ 0.106 (the number, for x̂_2) while
    // the goal ball reaches ≈ 0.101. x̂_1 keeps other channels, so its Kc̄ differs (0.1255).
    assert_eq!(r.goal.len(), 2);
    for g in &r.goal {
        assert!(!g.holds(), "{g:?}");
        assert!((g.max_h_in_goal - 0.10099).abs() < 1e-4, "{g:?}");
    }
    assert!(
        (r.goal[1].needed_h - 0.1063).abs() < 1e-3,
        "{:?}",
        r.goal[1]
    );
    assert!(
        (r.goal[0].needed_h - 0.1255).abs() < 1e-3,
        "{:?}",
        r.goal[0]
    );
    assert!(r
        .hypotheses
        .iter()
        .any(|h| h.status == Status::Info && h.detail.contains("cannot settle")));
}

/// Condition 1 under the input limit (#10): the paper's worlds keep the paper's boxes, which the
/// robust CBF rows outgrow at rest on the floor line, so `check` says Theorem 3 does not apply
/// and names the box it would need; the numbers are γ_i‖(K_i c̄_i)ᵀa‖ / (|a_v|·l).
#[test]
fn paper_worlds_boxes_are_too_small_for_their_robust_rows() {
    for (name, ratio, needed) in [
        (
            "paper_linear.toml",
            1.790,
            "raise control.input_limit to ≥ (3.581, 3.581) m/s²",
        ),
        (
            "paper_turtlebot.toml",
            6.509,
            "raise control.input_limit to ≥ (3.254, 3.254) m/s²",
        ),
    ] {
        let r = check_world(&world(name)).expect("check");
        assert!(!r.verdict.applies, "{r}");
        let h = r
            .hypotheses
            .iter()
            .find(|h| h.name == "condition 1 under the input limit for floor")
            .expect("input-limit hypothesis");
        assert_eq!(h.status, Status::Fails, "{name}: {}", h.detail);
        assert!(
            h.detail
                .contains(&format!("needs {ratio:.3} × the box's authority")),
            "{name}: {}",
            h.detail
        );
        assert!(r.verdict.line().contains(needed), "{}", r.verdict.line());
    }
}

/// The stealthy two-axis attack `falsify` found (#14) refutes the receivers world with a
/// 0.5 m/s² box, where the honest filter's row needs 0.79 m/s² at rest: `check` now says so.
/// With the catalogue's 1 m/s² box the hypothesis holds, and the same attack is safe in every
/// regression seed (`tests/worlds_guarantees/paper_turtlebot_receivers_stealthy.toml`).
#[test]
fn the_stealthy_counterexample_is_outside_the_theorem_and_the_fixed_world_is_inside() {
    let bad = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/worlds_falsify/paper_turtlebot_receivers_stealthy.toml");
    let r = check_world(&World::load(&bad, &[]).expect("world")).expect("check");
    assert!(!r.verdict.applies, "{r}");
    assert!(
        r.verdict
            .line()
            .contains("needs 1.588 × the box's authority"),
        "{}",
        r.verdict.line()
    );
    let good = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/worlds_guarantees/paper_turtlebot_receivers_stealthy.toml");
    let r = check_world(&World::load(&good, &[]).expect("world")).expect("check");
    assert!(r.verdict.applies, "{r}");
    let h = r
        .hypotheses
        .iter()
        .find(|h| h.name == "condition 1 under the input limit for floor")
        .expect("input-limit hypothesis");
    assert_eq!(h.status, Status::Holds, "{}", h.detail);
    assert!(h.detail.contains("needs 0.794 ×"), "{}", h.detail);
}

#[test]
fn per_receiver_paper_world_applies_over_its_horizon() {
    let r = check_world(&world("paper_turtlebot_receivers.toml")).expect("check");
    assert!(r.verdict.applies, "{r}");
    assert_eq!(r.verdict.horizon, Some(20.0));
    // The drive model is a checked hypothesis since #35 (the filters predict with the realised
    // acceleration; q is identified from the drive), no longer an assumption.
    let h = r
        .hypotheses
        .iter()
        .find(|h| h.name == "the filters' model is true of the drive")
        .expect("drive-model hypothesis");
    assert_eq!(h.status, Status::Holds, "{}", h.detail);
}

/// Step 2 in the corridor: over several seeds, the spoofed filter's test
/// S(x̂_1 − x̂_12) > 1 (‖x̂_1 − x̂_12‖ > θ_12(t)/2 or its change over the last second, in the
/// covariance-weighted norm ‖·‖_W, > η_12/2)
/// fires within about a second of the spoof's start, and the honest filter's does in at most the
/// fraction ε of runs: the event (4.5) of Theorem 3 is "the fault-free filter is never flagged
/// during the run", so ε bounds the runs in which it is flagged at all, not the steps (issue #30:
/// this test bounded flags per step, which a filter flagged once in every run would pass).
#[test]
fn corridor_step2_test_flags_the_spoofed_filter_and_spares_the_honest_one() {
    let w = world("corridor_spoof.toml");
    let eps = w.file.control.epsilon;
    let onset = 2.0;
    let mut honest_flagged_runs = 0u64;
    let mut runs = 0u64;
    let mut delays = Vec::new();
    for seed in 1..=6u64 {
        let mut sim = Simulation::new(
            &w,
            &RunOptions {
                seed: Some(seed),
                ..RunOptions::default()
            },
        )
        .expect("simulation");
        let theta = sim.setup().config.ft.theta[0];
        let schedule = sim
            .setup()
            .config
            .ft
            .theta_schedule
            .clone()
            .expect("θ_ij(t)");
        let dt = w.control_dt();
        let eta_half = sim.setup().config.ft.eta[0] / 2.0;
        let metric = sim.setup().config.ft.increment_metric[0];
        let window = (1.0 / w.control_dt()).round() as usize;
        // separations x̂_a − x̂_12 of the last `window` steps (zero at the start)
        let mut hist: Vec<[[f64; 4]; 2]> = vec![[[0.0; 4]; 2]; window];
        let mut first: Option<f64> = None;
        let mut honest_flags = 0u64;
        let mut k = 0usize;
        while let Some(f) = sim.step() {
            // bank order: x̂_1 (drops gnss1: reads the spoofed gnss2), x̂_2 (drops gnss2), x̂_12
            let e = f.estimates;
            let mut flag = [false; 2];
            for (a, fl) in flag.iter_mut().enumerate() {
                let s: [f64; 4] = std::array::from_fn(|c| e[a].x[c] - e[2].x[c]);
                let old = hist[k % window][a];
                let norm = |v: [f64; 4]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
                let inc: [f64; 4] = std::array::from_fn(|c| s[c] - old[c]);
                let z = ftcbf_controller::State::from(inc);
                let w_norm = (z.transpose() * metric * z)[0].max(0.0).sqrt();
                let half = schedule.at(0, (k + 1) as f64 * dt).expect("pair 0") / 2.0;
                assert!(half <= theta / 2.0);
                *fl = norm(s) > half || w_norm > eta_half;
                hist[k % window][a] = s;
            }
            k += 1;
            if flag[1] {
                honest_flags += 1;
            }
            if first.is_none() && flag[0] {
                first = Some(f.t);
            }
        }
        runs += 1;
        if honest_flags > 0 {
            honest_flagged_runs += 1;
        }
        let t = first.unwrap_or(f64::INFINITY);
        assert!(t > onset, "seed {seed}: flagged at {t} s, before the spoof");
        delays.push(t - onset);
    }
    let worst = delays.iter().copied().fold(0.0, f64::max);
    // Measured 0.80–2.12 s (6 seeds). Not the "about a second": x̂_1 follows the spoofed
    // fix with a lag of ≈ 0.5 s (its position gain is small because the odometry pins its
    // velocity), and at the union-bound rate ε' = 1.3e-5 the separation has to reach
    // θ_12(t)/2 ≈ 5.5 cm (set by the 1 cm start uncertainty the pair filter never forgets),
    // i.e. ≈ 1.1 s of a 5 cm/s walk; the 1 s increment (5 cm at most) stays below η/2.
    assert!(worst < 2.5, "detection delays after onset {delays:?} s");
    assert!(
        (honest_flagged_runs as f64) <= eps * runs as f64,
        "honest filter flagged in {honest_flagged_runs} of {runs} runs"
    );
}

/// The guarantee worlds that carry an [expect] table hold it (`ftcbf regress`), the stealthy
/// two-axis attack against the 1 m/s² receivers world among them.
#[test]
fn guarantee_worlds_meet_their_expectations() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/worlds_guarantees");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_ftcbf"))
        .arg("regress")
        .arg(&dir)
        .output()
        .expect("ftcbf regress");
    let t = format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    assert_eq!(o.status.code(), Some(0), "{t}");
    assert!(
        t.lines().any(|l| l
            .split_whitespace()
            .take(2)
            .eq(["paper_turtlebot_receivers_stealthy", "ft-cbf-clf"])),
        "{t}"
    );
    assert!(t.contains(", 0 failed"), "{t}");
}

/// The goal the safety filter's tracker aims for in the world `name`.
fn tracker_goal(name: &str) -> [f64; 2] {
    use ftcbf_sim::ftcbf_controller::ProblemForm;
    use ftcbf_sim::model::setup::ControlSetup;
    use ftcbf_sim::world::ControllerKindSpec;
    let s = ControlSetup::new(&world(name), ControllerKindSpec::FtCbfClf).expect("setup");
    match &s.config.form {
        ProblemForm::SafetyFilter { tracker, .. } => tracker.goal,
        ProblemForm::Paper => panic!("{name} runs the safety-filter form"),
    }
}

/// The safety filter's tracker aims where the honest filter's floor row holds at rest with a
/// 3σ margin (#11): in the receivers world the row needs h ≥ 0.0617 (`check`, with q identified
/// from the drive since #35; 0.0692 at q = 1e-3), σ of h(x̂) is 0.0032, so the tracker's goal
/// moves from (0, 0) up to h = 0.0714, y = 0.0214 — inside the 5 cm goal ball. The world's goal itself is unchanged (that is what `goal reached` judges).
#[test]
fn the_tracker_aims_where_the_floor_row_can_be_held() {
    let w = world("paper_turtlebot_receivers.toml");
    let goal = tracker_goal("paper_turtlebot_receivers.toml");
    assert!(goal[0].abs() < 1e-12, "{goal:?}");
    assert!((goal[1] - 0.0214).abs() < 5e-4, "{goal:?}");
    assert!(goal[1] < 0.8 * w.file.goal.radius);
    assert_eq!(w.file.goal.center, [0.0, 0.0]);
    // A world without half-plane safe sets keeps its goal as written.
    let c = world("corridor_spoof.toml");
    assert_eq!(tracker_goal("corridor_spoof.toml"), c.file.goal.center);
}

/// Wheel odometry as robots have it (#12): a `speed` channel with `world_velocity = true` is
/// fed to the filters as v·(cos θ̂, sin θ̂) with the compass heading, as two channels. A sensor in
/// a fault pattern takes along every controller channel made from it, so `check` says whether
/// the patterns stay disjoint in effect: the odometry's sources (speed, compass, encoders, fused
/// gyro) in at most one pattern keep them; sources in two patterns do not (a fault in either
/// would corrupt the odometry).
#[test]
fn converted_wheel_odometry_keeps_the_patterns_disjoint_only_with_its_heading() {
    let r = check_world(&world("turtlebot_realistic.toml")).expect("check");
    assert!(r.verdict.applies, "{r}");
    let x12 = r
        .filters
        .iter()
        .find(|f| f.label.starts_with("x̂_12"))
        .expect("pair filter");
    assert_eq!(x12.channels, vec!["wheel_speed→vx", "wheel_speed→vy"]);
    let odo = |r: &ftcbf_sim::analysis::check::CheckReport| {
        r.hypotheses
            .iter()
            .find(|h| h.name.starts_with("odometry wheel_speed → world velocity"))
            .cloned()
            .expect("odometry hypothesis")
    };
    let h = odo(&r);
    assert_eq!(h.status, Status::Holds);
    assert!(h.detail.contains("trusted"), "{}", h.detail);

    let r = check_world(&world("turtlebot_odometry_bias.toml")).expect("check");
    let h = odo(&r);
    assert_eq!(h.status, Status::Holds, "{}", h.detail);
    assert!(
        h.detail.contains("wheel_speed, compass in odometry"),
        "{}",
        h.detail
    );

    // The compass in receiver 1's pattern: that pattern's filter then drops the odometry too,
    // so the patterns stay disjoint in effect.
    let p = path("turtlebot_realistic.toml");
    let text = std::fs::read_to_string(&p).expect("world");
    let text = text.replace(
        "channels = [\"gnss1_x\", \"gnss1_y\"]",
        "channels = [\"gnss1_x\", \"gnss1_y\", \"compass\"]",
    );
    let w = World::from_str(&text, &p, &[]).expect("world");
    let r = check_world(&w).expect("check");
    assert_eq!(odo(&r).status, Status::Holds, "{}", odo(&r).detail);
    let x1 = r
        .filters
        .iter()
        .find(|f| f.label.starts_with("x̂_1 "))
        .expect("gnss1 filter");
    assert!(
        !x1.channels.iter().any(|c| c.starts_with("wheel_speed")),
        "{:?}",
        x1.channels
    );
    // But the drive turns u into wheel speeds about that compass, outside every filter: a fault
    // in gnss1 would misapply u, so the theorem does not cover it.
    let drive = |r: &ftcbf_sim::analysis::check::CheckReport| {
        r.hypotheses
            .iter()
            .find(|h| h.name.starts_with("the drive's heading is trusted"))
            .cloned()
            .expect("drive heading hypothesis")
    };
    assert_eq!(drive(&r).status, Status::Fails, "{}", drive(&r).detail);
    assert!(drive(&r).detail.contains("compass is in gnss1"));
    assert!(!r.verdict.applies);
    // ... and the wheel speed in receiver 2's: one fault in either corrupts the odometry.
    let text = text.replace(
        "channels = [\"gnss2_x\", \"gnss2_y\"]",
        "channels = [\"gnss2_x\", \"gnss2_y\", \"wheel_speed\"]",
    );
    // Two patterns reaching the same controller channel: the world is invalid (issue 29:
    // `check` used to report it while `run` refused it with an internal message), with the
    // pattern's key named.
    let e = World::from_str(&text, &p, &[])
        .expect_err("refused")
        .to_string();
    assert!(
        e.contains("`fault_patterns[1].channels`")
            && e.contains("disjoint in effect")
            && e.contains("\"gnss1\"")
            && e.contains("\"gnss2\""),
        "{e}"
    );
}

/// `world_velocity` on a channel that is not a `speed` is refused with the key named (a robot
/// world always has the heading channel the conversion needs: the world file refuses it
/// otherwise).
#[test]
fn world_velocity_needs_a_speed_channel() {
    let p = path("turtlebot_realistic.toml");
    let text = std::fs::read_to_string(&p).expect("world");
    let on_gnss = text.replacen(
        "measures = \"x\"\nnoise_std = 0.02\n",
        "measures = \"x\"\nnoise_std = 0.02\nworld_velocity = true\n",
        1,
    );
    // Refused when the world is loaded, so `check` and `run` refuse it alike (issue 29).
    let e = World::from_str(&on_gnss, &p, &[])
        .expect_err("refused")
        .to_string();
    assert!(
        e.contains("sensors[0].world_velocity") && e.contains("only a `speed` channel"),
        "{e}"
    );
}

/// The odometry's R for each axis: σ_v² + v_max²·σ_θ² (+ the compass bias terms).
fn odometry_variance(w: &World, name: &str) -> f64 {
    use ftcbf_sim::model::setup::ControlSetup;
    use ftcbf_sim::world::ControllerKindSpec;
    let s = ControlSetup::new(w, ControllerKindSpec::FtCbfClf).expect("setup");
    let si = w
        .file
        .sensors
        .iter()
        .position(|c| c.name == name)
        .expect("channel");
    let c = s
        .sensor_of_channel
        .iter()
        .position(|&x| x == si)
        .expect("controller channel");
    s.config.model.r[c]
}

/// A poor compass (σ 0.1 rad, 10 Hz) fused with the gyro (#12): the wheel odometry is turned
/// into world-frame velocity with the heading filter's yaw, and its R uses the filter's yaw
/// variance, bounded over the run from a marked start: 1.45e-4 (m/s)², against 6.03e-4 with the
/// compass alone (σ_v² = 1e-4 plus v_max²·(σ_θ² + b_θ²) with σ_θ = 0.0228 rad instead of 0.1,
/// b_θ = 0.02 rad).
#[test]
fn gyro_fusion_shrinks_the_odometry_variance() {
    let w = world("turtlebot_gyro_compass.toml");
    let fused = odometry_variance(&w, "wheel_speed");
    let p = path("turtlebot_gyro_compass.toml");
    let text = std::fs::read_to_string(&p)
        .expect("world")
        .replace("gyro = \"gyro_z\"", "");
    let alone = odometry_variance(
        &World::from_str(&text, &p, &[]).expect("world"),
        "wheel_speed",
    );
    // The compass's 0.02 rad bias is unobservable to both: it enters as b_θ². Alone, the 10 Hz
    // compass's sample is also up to 4 ticks (0.08 s) old while the burger turns at up to
    // 2.75 rad/s: (ω_max·age)² more (issue #30 item 4).
    let bias = 0.02f64.powi(2);
    let stale = (2.75f64 * 0.08).powi(2);
    assert!(
        (alone - (1e-4 + 0.22f64.powi(2) * (0.01 + bias + stale))).abs() < 1e-9,
        "{alone}"
    );
    assert!(
        (fused - (1.252e-4 + 0.22f64.powi(2) * bias)).abs() < 2e-6,
        "{fused}"
    );
    // The gyro feeds the odometry, so it rides with the odometry's fault pattern.
    let r = check_world(&w).expect("check");
    let h = r
        .hypotheses
        .iter()
        .find(|h| h.name.starts_with("odometry wheel_speed"))
        .expect("odometry hypothesis");
    assert!(h.detail.contains("gyro_z"), "{}", h.detail);
}

/// Odometry from quantised wheel encoders (#12): its σ is the encoders' count-difference
/// quantisation carried through v = r(ω_l + ω_r)/2: q = 2π/(4096·0.02 s) = 0.0767 rad/s per
/// wheel, variance q²/6 each, so σ_v = 0.033/2·√(2q²/6) = 0.73 mm/s.
#[test]
fn encoder_odometry_variance_is_the_quantisation() {
    let w = world("turtlebot_encoders.toml");
    let si = w
        .file
        .sensors
        .iter()
        .position(|c| c.name == "odom")
        .expect("odom");
    let sigma = ftcbf_sim::world::structure::speed_std(&w, si);
    let q = std::f64::consts::TAU / (4096.0 * 0.02);
    let want = 0.033 / 2.0 * (2.0 * q * q / 6.0).sqrt();
    assert!((sigma - want).abs() < 1e-6 * want, "{sigma} vs {want}");
    assert!((sigma - 7.3e-4).abs() < 1e-5, "{sigma}");
}

/// Issue #30, item 1: the ellipse test is Prop. 1 in position space on the running barrier
/// (`ellipse_prop1`), with δ. The arena world gives no δ, so `auto` chooses half the largest δ
/// Prop. 1 allows and the verdict applies; with δ = 10 every row is always active, an estimate
/// at the centre has Λ = 0, and `check` refuses (the old test, without δ, said "applies").
#[test]
fn the_arena_needs_a_finite_delta_and_auto_chooses_it() {
    let r = check_world(&world("elliptic_arena_drift.toml")).expect("check");
    assert!(r.verdict.applies, "{r}");
    let h = r
        .hypotheses
        .iter()
        .find(|h| h.name.starts_with("condition 1 (4.4) for arena"))
        .expect("the arena's condition 1");
    assert_eq!(h.status, Status::Holds, "{}", h.detail);
    assert!(h.detail.contains("δ = 0.2803 (auto"), "{}", h.detail);
    let large = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/worlds_check/elliptic_arena_delta_large.toml");
    let w = World::load(&large, &[]).unwrap_or_else(|e| panic!("{e}"));
    let r = check_world(&w).expect("check");
    assert!(!r.verdict.applies, "{r}");
    assert!(
        r.verdict
            .line()
            .contains("with δ = 10 an estimate whose row is active may sit where Λ = k∇h ≈ 0"),
        "{}",
        r.verdict.line()
    );
}

/// Issue #30, items 2, 3 and 5: with several barriers the verdict names what it assumes (the
/// joint rows off the planned path and at speed, Step 3's saturation rule), and the joint rows
/// at rest along the path are decided.
#[test]
fn several_barriers_apply_only_assuming_what_check_cannot_decide() {
    let r = check_world(&world("corridor_spoof.toml")).expect("check");
    let line = r.verdict.line();
    assert!(line.starts_with("Theorem 3 applies, assuming "), "{line}");
    assert!(
        line.contains("case (i) jointly over the barriers"),
        "{line}"
    );
    assert!(line.contains("Step 3's saturation rule"), "{line}");
    let h = r
        .hypotheses
        .iter()
        .find(|h| h.name.starts_with("case (i):"))
        .expect("the joint rows");
    assert_eq!(h.status, Status::Assumed, "{}", h.detail);
    assert!(
        h.detail.contains("decided at rest along the planned path"),
        "{}",
        h.detail
    );
    // a single half-plane assumes none of it
    let r = check_world(&world("paper_turtlebot_sf.toml")).expect("check");
    assert_eq!(
        r.verdict.line(),
        "Theorem 3 applies: Pr(safe) ≥ 1 − ε = 0.95 for any single fault pattern"
    );
}

/// Issue #30, items 2 and 3: two walls each pass (4.4) and the one-row input-limit test, but
/// under the declared attack their rows for the units Step 2 keeps admit no input in the box at a
/// point of the planned path: case (i) of the proof fails there, and `check` refuses (the old
/// `check`, per barrier at the start estimate, said "applies").
#[test]
fn a_narrow_corridor_fails_case_i_jointly_although_each_wall_passes() {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/worlds_check/corridor_narrow_spoof.toml");
    let w = World::load(&p, &[]).unwrap_or_else(|e| panic!("{e}"));
    let r = check_world(&w).expect("check");
    assert!(!r.verdict.applies, "{r}");
    let h = r
        .hypotheses
        .iter()
        .find(|h| h.name.starts_with("case (i):"))
        .expect("the joint rows");
    assert_eq!(h.status, Status::Fails, "{}", h.detail);
    assert!(
        h.detail.contains("under the declared attack"),
        "{}",
        h.detail
    );
    assert!(
        h.detail
            .contains("no input in the box meets the rows of every unit Step 2 keeps"),
        "{}",
        h.detail
    );
    // each wall on its own passes the old tests
    for wall in ["left_wall", "right_wall"] {
        let one = r
            .hypotheses
            .iter()
            .find(|h| h.name == format!("condition 1 under the input limit for obstacle:{wall}"))
            .expect("input-limit test");
        assert_ne!(one.status, Status::Fails, "{}", one.detail);
    }
}

/// The hypothesis of `r` whose name starts with `prefix`.
fn hypothesis<'a>(
    r: &'a ftcbf_sim::analysis::check::CheckReport,
    prefix: &str,
) -> &'a ftcbf_sim::analysis::check::Hypothesis {
    r.hypotheses
        .iter()
        .find(|h| h.name.starts_with(prefix))
        .unwrap_or_else(|| panic!("no hypothesis {prefix:?} in\n{r}"))
}

/// Issue #30 item 4, written by hand: `paper_turtlebot_receivers` with the honest receiver's y
/// declaring a constant bias of +0.3 m. γ, θ and η model white noise, so before the fix `check`
/// said "applies" here; the run leaves the floor at about 1 s (min h ≈ −0.23). `check` now fails
/// the white-noise hypothesis, naming the channel and its bias.
#[test]
fn a_declared_bias_on_a_filter_channel_fails_the_white_noise_hypothesis() {
    let p =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/worlds_check/biased_receiver.toml");
    let w = World::load(&p, &[]).unwrap_or_else(|e| panic!("{e}"));
    let r = check_world(&w).expect("check");
    assert!(!r.verdict.applies, "{r}");
    let h = hypothesis(&r, "white, unbiased noise");
    assert_eq!(h.status, Status::Fails, "{}", h.detail);
    assert!(
        h.detail.contains("\"gnss1_y\" declares bias 0.3 m"),
        "{}",
        h.detail
    );
    let s = ftcbf_sim::runner::run(&w, &RunOptions::default()).expect("runs");
    assert!(
        !s.safe,
        "the biased world's run is unsafe: {:?}",
        s.min_barrier
    );
    // The catalogue world it is made from has no biased filter channel.
    let r = check_world(&world("paper_turtlebot_receivers.toml")).expect("check");
    let h = hypothesis(&r, "white, unbiased noise");
    assert_eq!(h.status, Status::Holds, "{}", h.detail);
}

/// Issue #30 item 4: a compass bias b_θ turns the odometry's world velocity by b_θ, a constant
/// cross-track error the odometry-only pair filter integrates: v_max·b_θ·T over the run.
/// `turtlebot_gyro_compass` declares b_θ = 0.02 rad (R took it as noise); `check` now names it
/// with that bound, and the verdict does not apply.
#[test]
fn a_compass_bias_is_named_with_its_dead_reckoning_drift() {
    let r = check_world(&world("turtlebot_gyro_compass.toml")).expect("check");
    assert!(!r.verdict.applies, "{r}");
    let h = hypothesis(&r, "white, unbiased noise");
    assert_eq!(h.status, Status::Fails, "{}", h.detail);
    // v_max = 0.22 m/s (burger), b_θ = 0.02 rad, T = 20 s: 0.0044 m/s, 0.088 m.
    assert!(
        h.detail.contains("\"compass\" declares bias 0.02 rad"),
        "{}",
        h.detail
    );
    assert!(h.detail.contains("v_max·b_θ = 0.0044 m/s"), "{}", h.detail);
    assert!(h.detail.contains("0.088 m over 20 s"), "{}", h.detail);
}

/// Issue #30 item 4: a slow compass without a gyro fused into it leaves the odometry's world
/// velocity turned with a heading up to (every − 1)·dt old, while the robot turns at up to ω_max.
/// `tests/worlds_check/slow_compass.toml` (2 Hz compass, 50 Hz control: held up to 0.48 s; burger
/// v_max 0.22 m/s, ω_max 2.75 rad/s): before, R took only the compass's noise and `check` said
/// "applies" (batch, 200 trials: 184 safe, the honest filter over γ in 184). Now the conversion's
/// variance carries (ω_max·age)², and the white-noise hypothesis fails, naming the compass.
#[test]
fn a_slow_compass_without_a_gyro_puts_its_staleness_in_r_and_fails_white_noise() {
    use ftcbf_sim::model::setup::ControlSetup;
    use ftcbf_sim::world::structure::heading_hold;
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/worlds_check/slow_compass.toml");
    let slow = World::load(&p, &[]).unwrap_or_else(|e| panic!("{e}"));
    let hold = heading_hold(&slow).expect("odometry is turned with the compass");
    assert!(!hold.fused);
    assert_eq!(hold.every, 25, "{hold:?}");
    assert!((hold.age - 0.48).abs() < 1e-12, "{hold:?}");
    let r = check_world(&slow).expect("check");
    assert!(!r.verdict.applies, "{r}");
    let h = hypothesis(&r, "white, unbiased noise");
    assert_eq!(h.status, Status::Fails, "{}", h.detail);
    assert!(
        h.detail
            .contains("\"compass\" (no gyro fused) is held up to 0.480 s"),
        "{}",
        h.detail
    );
    assert!(
        h.detail.contains("v_max·ω_max·age = 0.2904 m/s"),
        "{}",
        h.detail
    );
    // R of the converted channels: σ_v² + v_max²·(σ_θ² + (ω_max·age)²), against σ_v² + v_max²·σ_θ²
    // for the same compass read every tick.
    let text = std::fs::read_to_string(&p).expect("world");
    let every_tick = World::from_str(&text.replace("rate_hz = 2.0\n", ""), &p, &[]).expect("world");
    assert!(heading_hold(&every_tick).expect("converted").age == 0.0);
    let kind = slow.file.control.controller;
    let r_of = |w: &World| {
        let s = ControlSetup::new(w, kind).expect("setup");
        let c = s
            .conversion
            .iter()
            .position(|c| *c != ftcbf_sim::world::structure::Conversion::Direct)
            .expect("a converted channel");
        s.config.model.r[c]
    };
    let (v_max, sv, sth, stale) = (0.22_f64, 0.01_f64, 0.005_f64, 2.75 * 0.48);
    let expect_slow = sv * sv + v_max * v_max * (sth * sth + stale * stale);
    let expect_fast = sv * sv + v_max * v_max * sth * sth;
    assert!(
        (r_of(&slow) / expect_slow - 1.0).abs() < 1e-3,
        "{} vs {expect_slow}",
        r_of(&slow)
    );
    assert!(
        (r_of(&every_tick) / expect_fast - 1.0).abs() < 1e-3,
        "{} vs {expect_fast}",
        r_of(&every_tick)
    );
    // With the staleness in R the world's run keeps the floor.
    let s = ftcbf_sim::runner::run(&slow, &RunOptions::default()).expect("runs");
    assert!(s.safe, "{:?}", s.min_barrier);
}

/// Issue #30 item 4: γ, θ and η come from the sensors as declared. `corridor_spoof` with
/// receiver gnss1 at 10 Hz (a sample every 5 ticks at 50 Hz) losing 20 % of its samples: over the
/// 1250 ticks (250 slots) with ε/2 split over its two lossy channels, 250·0.2^(n+1) ≤ 0.0125 gives
/// n = 6 lost in a row, so the filters are computed for an update every 35 ticks at ε/2: Step 2's
/// η_12 grows by a third, and `check` prints the schedule. Before, the rate and the dropouts were ignored.
#[test]
fn a_slow_lossy_receiver_widens_the_bounds_by_its_worst_gap() {
    use ftcbf_sim::model::setup::ControlSetup;
    let p = path("corridor_spoof.toml");
    let text = std::fs::read_to_string(&p).expect("world");
    let slow = ["gnss1_x", "gnss1_y"].iter().fold(text.clone(), |t, n| {
        t.replace(
            &format!("name = \"{n}\"\nmeasures = "),
            &format!("name = \"{n}\"\nrate_hz = 10.0\ndropout_prob = 0.2\nmeasures = "),
        )
    });
    assert_ne!(slow, text);
    let every_tick = World::from_str(&text, &p, &[]).expect("world");
    let slow = World::from_str(&slow, &p, &[]).expect("world");
    let kind = slow.file.control.controller;
    let fast = ControlSetup::new(&every_tick, kind).expect("setup");
    let setup = ControlSetup::new(&slow, kind).expect("setup");
    assert!(fast.params.timing.every_tick());
    let t = &setup.params.timing;
    assert_eq!(t.eps_gaps, 0.025);
    assert_eq!(t.lossy_sensors, 2);
    let gnss1: Vec<_> = t.channels.iter().filter(|c| c.every != 1).collect();
    assert_eq!(gnss1.len(), 2, "{t:?}");
    for c in gnss1 {
        assert_eq!((c.period, c.missed, c.every), (5, 6, 35), "{c:?}");
    }
    let eps1 = |s: &ControlSetup| s.params.derivation.as_ref().expect("auto").eps_per_sample;
    assert!((eps1(&setup) / eps1(&fast) - 0.5).abs() < 1e-12);
    // γ here is set by the start uncertainty (P0 over the first steps), so it grows only by the
    // halved ε; η_12, the 1 s increment of the separation, sees the gaps: 12.7 → 17.2 (measured).
    assert!(setup.config.ft.gamma[1] > fast.config.ft.gamma[1]);
    let (e_fast, e_slow) = (fast.config.ft.eta[0], setup.config.ft.eta[0]);
    assert!(
        e_slow > 1.3 * e_fast,
        "η_12 {e_slow} vs every tick {e_fast}"
    );
    let r = check_world(&slow).expect("check");
    let h = hypothesis(&r, "γ, θ, η for the sensors' rates");
    assert!(
        h.detail
            .contains("dropout 0.2: up to 6 lost in a row) modelled as every 35 ticks"),
        "{}",
        h.detail
    );
}
