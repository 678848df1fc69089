//! The numerical study of §6.2, reproduced.
//!
//! Truth: eq. 6.2 with process-noise intensity Q = 1e-3·I, integrated by Euler–Maruyama
//! ([`LinearModel::euler_maruyama_step`]) with step `DT_SIM` = 1 ms (10 substeps per control
//! period). Measurements (eq. 6.5) are sampled every `DT` = 10 ms with per-sample noise
//! variance 1e-3 on each channel, plus the attack a = (0,0,0,1,0,0) on y4 (0-based channel 3)
//! from t = 0. The controller holds u over each control period. Duration `T_END` = 30 s.
//!
//! Safety is h(x) = x₂ + 0.2 ẋ₂ + 0.05 ≥ 0 on the **true** state at every substep; the goal
//! is ‖x − 0‖₂ ≤ d = 0.05 on the true state at some time.

use std::sync::Arc;

use ftcbf_controller::barrier::{Barrier, HalfPlane};
use ftcbf_controller::params::FtParameters;
use ftcbf_controller::policy::{Stage, Verdict};
use ftcbf_controller::{
    ClfConfig, Controller, ControllerConfig, ControllerKind, Input, LinearModel, QpOutcome,
    QuadraticClf, State, StateMatrix,
};
use nalgebra::Matrix2;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

const DT: f64 = 0.01;
const SUBSTEPS: usize = 10;
const T_END: f64 = 30.0;
const NOISE: f64 = 1e-3;
const D_GOAL: f64 = 0.05;
const INPUT_LIMIT: f64 = 2.0;

fn model() -> LinearModel {
    LinearModel::paper_double_integrator(NOISE, NOISE).expect("paper model is valid")
}

fn safe_set() -> HalfPlane {
    HalfPlane::new("x2 + 0.2 v2 + 0.05", State::new(0.0, 1.0, 0.0, 0.2), -0.05)
}

/// Parameters that differ between the paper's values and the computed ones.
#[derive(Clone, Debug)]
struct StudyParams {
    gamma: Vec<f64>,
    gamma_baseline: f64,
    theta: Vec<f64>,
}

fn paper_params() -> StudyParams {
    StudyParams {
        gamma: vec![0.001, 0.001],
        gamma_baseline: 0.001,
        theta: vec![0.045],
    }
}

fn config(kind: ControllerKind, p: &StudyParams) -> ControllerConfig {
    let m = model();
    // V̄: the largest level set of V inside the ball of radius d/2 around the goal.
    let probe =
        QuadraticClf::new(&m.f, &m.g, State::zeros(), D_GOAL, &ClfConfig::paper(0.0)).expect("clf");
    let v_bar = probe.v_bar_inside_ball(D_GOAL / 2.0);
    ControllerConfig {
        kind,
        model: m,
        fault_patterns: vec![vec![1], vec![3]],
        barriers: vec![Arc::new(safe_set())],
        goal: State::zeros(),
        goal_radius: D_GOAL,
        gamma: p.gamma.clone(),
        gamma_baseline: p.gamma_baseline,
        theta: p.theta.clone(),
        delta: 1.0,
        cbf_gain: 1.0,
        clf: ClfConfig::paper(v_bar),
        input_cost: Matrix2::identity(),
        input_limit: Some(Input::new(INPUT_LIMIT, INPUT_LIMIT)),
        x0: State::new(1.0, 0.0, 0.0, 0.0),
        p0: StateMatrix::identity() * 1e-3,
        max_abs_reading: 1e6,
    }
}

#[derive(Debug, Clone)]
struct Trial {
    safe: bool,
    min_h: f64,
    goal_time: Option<f64>,
    final_dist: f64,
    stages: [usize; 5],
    step2_drops: [usize; 2],
}

fn stage_index(s: Stage) -> usize {
    match s {
        Stage::Step1 => 0,
        Stage::Step2 => 1,
        Stage::ClfRelaxation => 2,
        Stage::Step3 => 3,
        Stage::Fallback => 4,
    }
}

fn simulate(kind: ControllerKind, p: &StudyParams, seed: u64) -> Trial {
    let m = model();
    let h = safe_set();
    let mut ctrl = Controller::new(config(kind, p)).expect("valid config");
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut x = State::new(1.0, 0.0, 0.0, 0.0);
    let attack = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0];
    let fresh = [true; 6];
    let mut y = [0.0; 6];
    let mut u = Input::zeros();
    let mut min_h = h.eval(&x).value;
    let mut goal_time = None;
    let mut stages = [0usize; 5];
    let mut step2_drops = [0usize; 2];
    let steps = (T_END / DT).round() as usize;
    for k in 0..steps {
        for _ in 0..SUBSTEPS {
            let w = State::from_fn(|_, _| StandardNormal.sample(&mut rng));
            x = m.euler_maruyama_step(&x, &u, DT / SUBSTEPS as f64, &w);
            min_h = min_h.min(h.eval(&x).value);
        }
        if goal_time.is_none() && x.norm() <= D_GOAL {
            goal_time = Some((k + 1) as f64 * DT);
        }
        for (c, yc) in y.iter_mut().enumerate() {
            let v: f64 = StandardNormal.sample(&mut rng);
            *yc = m.measure(c, &x) + attack[c] + NOISE.sqrt() * v;
        }
        let out = ctrl.step(&y, &fresh, DT);
        u = out.u;
        let st = match out.qp {
            QpOutcome::Feasible { stage, .. } => stage,
            QpOutcome::InfeasibleAfterStep3 { .. } => Stage::Fallback,
        };
        stages[stage_index(st)] += 1;
        for (unit, drops) in step2_drops.iter_mut().enumerate() {
            if out.decision.decisions.iter().any(|d| {
                d.unit == unit
                    && matches!(
                        d.verdict,
                        Verdict::Dropped {
                            stage: Stage::Step2,
                            ..
                        }
                    )
            }) {
                *drops += 1;
            }
        }
    }
    Trial {
        safe: min_h >= 0.0,
        min_h,
        goal_time,
        final_dist: x.norm(),
        stages,
        step2_drops,
    }
}

#[derive(Debug)]
struct Rates {
    safe: f64,
    goal: f64,
    /// Worst min_t h(x_t) over the seeds.
    worst_min_h: f64,
    /// Mean over seeds of min_t h(x_t).
    mean_min_h: f64,
    /// Mean goal-entry time over the seeds that entered [s].
    mean_goal_time: f64,
    /// Steps (all seeds) at which Step 2 dropped the honest filter x̂_2.
    honest_step2_drops: usize,
    /// Steps (all seeds) decided by each stage: Step1, Step2, ClfRelaxation, Step3, Fallback.
    stages: [usize; 5],
}

fn rates(kind: ControllerKind, p: &StudyParams, seeds: u64) -> Rates {
    let mut safe = 0;
    let mut goal = 0;
    let mut worst = f64::INFINITY;
    let mut sum_min_h = 0.0;
    let mut sum_goal_t = 0.0;
    let mut honest = 0;
    let mut stages = [0usize; 5];
    for s in 0..seeds {
        let t = simulate(kind, p, 1000 + s);
        safe += t.safe as usize;
        goal += t.goal_time.is_some() as usize;
        sum_goal_t += t.goal_time.unwrap_or(0.0);
        worst = worst.min(t.min_h);
        sum_min_h += t.min_h;
        honest += t.step2_drops[1];
        for (a, b) in stages.iter_mut().zip(t.stages) {
            *a += b;
        }
    }
    Rates {
        safe: safe as f64 / seeds as f64,
        goal: goal as f64 / seeds as f64,
        worst_min_h: worst,
        mean_min_h: sum_min_h / seeds as f64,
        mean_goal_time: if goal > 0 {
            sum_goal_t / goal as f64
        } else {
            f64::NAN
        },
        honest_step2_drops: honest,
        stages,
    }
}

#[test]
fn ft_cbf_clf_is_safe_and_reaches_goal_baseline_violates() {
    let p = paper_params();
    let ft = simulate(ControllerKind::FtCbfClf, &p, 7);
    let base = simulate(ControllerKind::Baseline, &p, 7);
    println!("FT-CBF-CLF: {ft:?}");
    println!("baseline:   {base:?}");
    assert!(ft.safe, "FT-CBF-CLF violated safety: min h = {}", ft.min_h);
    assert!(
        ft.goal_time.is_some(),
        "FT-CBF-CLF never entered the goal set (final distance {})",
        ft.final_dist
    );
    // Step 2 removes the attacked filter (x̂_1 uses y4), never the honest one in this run.
    assert!(ft.step2_drops[0] > 0);
    assert!(!base.safe, "baseline stayed safe: min h = {}", base.min_h);
    assert!(
        base.min_h < -0.1,
        "baseline violation too small: {}",
        base.min_h
    );
}

/// The paper's parameters (γ_i = 0.001, θ = 0.045) over 100 seeds.
///
/// They do **not** reach a 0.95 safe rate for FT-CBF-CLF (measured: 0.25): γ = 0.001 is ~50×
/// smaller than the estimation error it is meant to bound (item 7 gives γ = 0.033 pointwise,
/// 0.054 over the horizon, for ε = 0.05), so h̄_γ = 0.001 leaves no margin, and the goal set
/// sits only h = 0.05 from the boundary while the robot hovers there for ~15 s. The
/// violations are small (noise-sized, a few cm) compared with the baseline's (≈ −0.5, the
/// attack's bias). Asserted: FT goal rate ≥ 0.95, baseline safe rate ≤ 0.05, FT's worst
/// violation is within 0.1 (noise) while the baseline's mean minimum is below −0.4, and the
/// FT rate is printed. See `computed_parameters_for_eps_005` for the ≥ 0.95 safe case.
#[test]
fn hundred_seeds_safe_and_goal_rates() {
    let p = paper_params();
    let ft = rates(ControllerKind::FtCbfClf, &p, 100);
    let base = rates(ControllerKind::Baseline, &p, 100);
    println!("paper parameters (gamma = 0.001, theta = 0.045), 100 seeds:\n  FT-CBF-CLF {ft:?}\n  baseline   {base:?}");
    assert!(ft.goal >= 0.95, "FT-CBF-CLF goal rate {}", ft.goal);
    assert!(base.safe <= 0.05, "baseline safe rate {}", base.safe);
    assert!(
        ft.worst_min_h > -0.1,
        "FT-CBF-CLF worst violation {}",
        ft.worst_min_h
    );
    assert!(
        base.mean_min_h < -0.4,
        "baseline mean min h {}",
        base.mean_min_h
    );
    assert!(ft.safe > base.safe);
    assert!(ft.mean_goal_time < T_END);
    // Steps past Step 1 happen (the attack makes Step 1 infeasible), and Step 2 almost never
    // removes the honest filter (< 0.1 % of all steps).
    assert!(ft.stages[1] + ft.stages[2] > 0, "{:?}", ft.stages);
    let all_steps: usize = ft.stages.iter().sum();
    assert!(
        (ft.honest_step2_drops as f64) < 1e-3 * all_steps as f64,
        "{}",
        ft.honest_step2_drops
    );
}

/// Item 7 for ε = 0.05. Two variants:
/// * pointwise (the recipe of §4.3: Pr(‖x̂_i − x‖ > γ) ≤ ε at each time, split over the m
///   events of (4.5)): `horizon_samples = 1`;
/// * whole horizon (union bound over the N = T/dt samples of the run): more rigorous for the
///   sup over t, but γ is then so large that the robust term γ‖∂h K c̄‖ of (4.3) keeps every
///   estimate far from the boundary: both controllers are safe and neither reaches the goal.
#[test]
fn computed_parameters_for_eps_005() {
    let m = model();
    let steps = (T_END / DT).round() as usize;
    for (label, horizon) in [("pointwise", 1usize), ("whole-horizon", steps)] {
        let fp = FtParameters::compute(&m, &[vec![1], vec![3]], DT, 0.05, horizon);
        println!("{label}: {fp}");
        assert!(fp.all_converged);
        assert_eq!((fp.gamma.len(), fp.theta.len()), (2, 1));
        assert!(fp.theta[0] > 2.0 * fp.gamma[0]);
        let p = StudyParams {
            gamma: fp.gamma.clone(),
            gamma_baseline: fp.gamma_baseline,
            theta: fp.theta.clone(),
        };
        let ft = rates(ControllerKind::FtCbfClf, &p, 100);
        let base = rates(ControllerKind::Baseline, &p, 100);
        println!("computed parameters ({label}, eps = 0.05), 100 seeds:\n  FT-CBF-CLF {ft:?}\n  baseline   {base:?}");
        assert!(ft.safe >= 0.95, "{label}: FT-CBF-CLF safe rate {}", ft.safe);
        if horizon == 1 {
            assert!(
                base.safe <= 0.05,
                "{label}: baseline safe rate {}",
                base.safe
            );
        }
    }
}
