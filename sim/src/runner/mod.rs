//! The closed loop (DESIGN.md, "Data flow of one control tick"):
//!
//! ```text
//! plant ──truth──► sensors ──y──► attacks ──ỹ──► controller ──u──► drive ──wheel speeds──► plant
//! ```
//!
//! Per control step k (t = k·Δt_control): read the truth, sample the sensors, apply the attacks
//! (a stealthy attacker sees the all-channel filter's predicted measurement and innovation
//! spread — it knows the detector), step the controller, then advance the plant by
//! `ticks_per_control` plant steps with that input held. Safe sets are checked on the truth after
//! every plant step; contacts after every physics step.
//!
//! [`run`] is the one library call the CLI, the regression suite and `ftcbf batch` share.

mod plant;
mod scene;
pub mod setup;

use ftcbf_controller::controller::Controller;
use ftcbf_controller::estimator::FilterRole;
use ftcbf_controller::policy::{DropReason, QpOutcome, Stage, Verdict};

use crate::attacks::AttackStack;
use crate::observe::{ChannelView, EstimateView, Frame, Observer};
use crate::sensors::{Quantity, SensorSuite};
use crate::state::TruthState;
use crate::summary::{
    AttackWindow, CollisionEvent, NamedValue, RunSummary, StepCounts, ViolationEvent,
};
use crate::world::{ControllerKindSpec, GoalMetric, World};

pub use plant::Plant;
pub use scene::build_scene;
use setup::{controller_name, ControlSetup};

/// Per-run choices that override the world file.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// Seed (default: the world's).
    pub seed: Option<u64>,
    /// Controller (default: the world's `control.controller`).
    pub controller: Option<ControllerKindSpec>,
    /// Simulated duration [s] (default: the world's).
    pub duration: Option<f64>,
}

/// Why a run could not be carried out (the world itself was valid).
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// The world does not fit the controller or plant.
    #[error("{world}: `{key}`: {message}")]
    Setup {
        /// World file.
        world: String,
        /// Key path.
        key: String,
        /// What is wrong.
        message: String,
    },
    /// A component refused to start.
    #[error("{world}: {what}: {message}")]
    Start {
        /// World file.
        world: String,
        /// Component.
        what: &'static str,
        /// Its error.
        message: String,
    },
    /// A run option is out of range.
    #[error("{0}")]
    Option(String),
}

/// Runs `world` headlessly and returns its summary.
pub fn run(world: &World, opts: &RunOptions) -> Result<RunSummary, RunError> {
    run_observed(world, opts, None)
}

fn stage_name(o: &QpOutcome) -> &'static str {
    match o {
        QpOutcome::Feasible { stage, .. } => match stage {
            Stage::Step1 => "step1",
            Stage::ClfRelaxation => "clf_relaxed",
            Stage::Step2 => "step2",
            Stage::Step3 => "step3",
            Stage::Fallback => "infeasible",
        },
        QpOutcome::InfeasibleAfterStep3 { .. } => "infeasible",
    }
}

fn count_stage(c: &mut StepCounts, o: &QpOutcome) {
    let counter = match o {
        QpOutcome::Feasible { stage, .. } => match stage {
            Stage::Step1 => &mut c.step1,
            Stage::ClfRelaxation => &mut c.clf_relaxed,
            Stage::Step2 => &mut c.step2,
            Stage::Step3 => &mut c.step3,
            Stage::Fallback => &mut c.infeasible,
        },
        QpOutcome::InfeasibleAfterStep3 { .. } => &mut c.infeasible,
    };
    *counter += 1;
}

/// Runs `world`, showing every control step to `observer` (the recorder, a test).
pub fn run_observed(
    world: &World,
    opts: &RunOptions,
    mut observer: Option<&mut dyn Observer>,
) -> Result<RunSummary, RunError> {
    let file = &world.file;
    let seed = opts.seed.unwrap_or(file.seed);
    let kind = opts.controller.unwrap_or(file.control.controller);
    let duration = opts.duration.unwrap_or(file.duration);
    if !(duration.is_finite() && duration > 0.0) {
        return Err(RunError::Option(format!(
            "--duration: expected a finite number of seconds > 0, found {duration}"
        )));
    }
    let wname = world.path.display().to_string();
    let start_err = |what: &'static str, message: String| RunError::Start {
        world: wname.clone(),
        what,
        message,
    };

    let control_dt = world.control_dt();
    let setup = ControlSetup::new(world, kind)?;
    let mut suite = SensorSuite::new(&file.sensors, control_dt, seed)
        .map_err(|e| start_err("sensors", e.to_string()))?;
    let mut attacks = AttackStack::new(&file.attacks, &suite, seed)
        .map_err(|e| start_err("attacks", e.to_string()))?;
    let barriers = setup.config.barriers.clone();
    let mut controller = Controller::new(setup.config.clone())
        .map_err(|e| start_err("controller", e.to_string()))?;
    let mut plant = Plant::new(world, seed).map_err(|e| start_err("plant", e))?;
    let heading_channel = file
        .sensors
        .iter()
        .position(|s| s.measures == Quantity::Heading);
    let baseline = controller.bank().baseline_index();
    // Filters named after the world's fault patterns: drop_<F(r_i)>, drop_<F(r_i)>+<F(r_j)>, all.
    let pname = |i: usize| {
        file.fault_patterns
            .get(i)
            .map_or_else(|| format!("r{}", i + 1), |p| p.name.clone())
    };
    let filters: Vec<String> = controller
        .bank()
        .filters()
        .iter()
        .map(|f| match f.role() {
            FilterRole::DropPattern(i) => format!("drop_{}", pname(i)),
            FilterRole::DropPair(i, j) => format!("drop_{}+{}", pname(i), pname(j)),
            FilterRole::Baseline => "all".to_string(),
        })
        .collect();

    let windows = attacks.windows();
    let outside = attacks.outside_fault_patterns(&world.patterns);
    let attack_windows: Vec<AttackWindow> = windows
        .iter()
        .enumerate()
        .map(|(i, (label, start, end))| AttackWindow {
            label: label.clone(),
            start: *start,
            end: *end,
            outside_fault_patterns: outside.contains(&i),
        })
        .collect();

    if let Some(obs) = observer.as_deref_mut() {
        obs.scene(&build_scene(world, &setup, &filters, &windows));
    }

    let q = setup.sensor_of_channel.len();
    let nb = barriers.len();
    let mut y = vec![0.0; q];
    let mut fresh = vec![false; q];
    let mut min_barrier = vec![f64::INFINITY; nb];
    let mut barrier_truth = vec![0.0; nb];
    let mut clearances: Vec<f64> = Vec::new();
    let mut min_clearance: Option<f64> = None;
    let mut first_collision: Option<CollisionEvent> = None;
    let mut first_violation: Option<ViolationEvent> = None;
    let mut time_to_goal: Option<f64> = None;
    let mut steps = StepCounts::default();
    let mut rejected: u64 = 0;
    let mut heading = plant.truth().theta;
    let mut in_contact = vec![false; world.obstacles.len()];

    // Observer-only buffers.
    let mut channels_view = vec![
        ChannelView {
            clean: 0.0,
            received: 0.0,
            fresh: false,
            detector_z: f64::NAN,
            rejected: false,
        };
        file.sensors.len()
    ];
    let mut estimates_view = vec![
        EstimateView {
            x: [0.0; 4],
            residue: 0.0,
            clf: 0.0
        };
        filters.len()
    ];
    let mut attacks_active = vec![false; windows.len()];
    let mut link_poses: Vec<(String, [f32; 3], [f32; 4])> = Vec::new();
    let mut events: Vec<String> = Vec::new();
    let mut note = String::new();

    let n_steps = (duration / control_dt).round().max(1.0) as u64;
    let goal = file.goal.center;
    let goal_r = file.goal.radius;
    let in_goal = |t: &TruthState| match file.goal.metric {
        GoalMetric::Position => (t.x - goal[0]).hypot(t.y - goal[1]) <= goal_r,
        GoalMetric::State => {
            let d = [t.x - goal[0], t.y - goal[1], t.vx, t.vy];
            d.iter().map(|v| v * v).sum::<f64>().sqrt() <= goal_r
        }
    };

    for k in 0..n_steps {
        let t = k as f64 * control_dt;
        let mut truth = plant.truth();
        truth.t = t;
        events.clear();

        // Sensors, then attacks (the stealthy attacker reads the all-channel filter's prediction).
        let samples = suite.sample(&truth);
        if observer.is_some() {
            for (v, s) in channels_view.iter_mut().zip(samples.iter()) {
                v.clean = s.value;
            }
        }
        {
            let bank = controller.bank();
            let map = &setup.channel_of_sensor;
            let detector = |ch: usize| {
                map.get(ch)
                    .copied()
                    .flatten()
                    .and_then(|c| bank.predicted_measurement(baseline, c))
            };
            attacks.apply(t, samples, &detector);
        }
        for (c, &si) in setup.sensor_of_channel.iter().enumerate() {
            y[c] = samples[si].value;
            fresh[c] = samples[si].fresh;
        }
        if let Some(h) = heading_channel {
            let s = samples[h];
            if s.fresh && s.value.is_finite() {
                heading = s.value;
            }
        }
        if observer.is_some() {
            let bank = controller.bank();
            for (si, (v, s)) in channels_view.iter_mut().zip(samples.iter()).enumerate() {
                v.received = s.value;
                v.fresh = s.fresh;
                v.detector_z = match setup.channel_of_sensor[si] {
                    Some(c) if s.fresh => bank
                        .predicted_measurement(baseline, c)
                        .map_or(f64::NAN, |(mean, std)| (s.value - mean) / std),
                    _ => f64::NAN,
                };
            }
        }

        // Controller.
        controller.step(&y, &fresh, control_dt);
        let out = controller.output();
        let u = out.u;
        count_stage(&mut steps, &out.qp);
        rejected += out.rejected.count as u64;
        if observer.is_some() {
            for (v, c) in channels_view.iter_mut().zip(&setup.channel_of_sensor) {
                v.rejected = c.is_some_and(|c| out.rejected.channels.get(c) == Some(&true));
            }
        }

        if observer.is_some() {
            note.clear();
            for d in &out.decision.decisions {
                if let Verdict::Dropped { stage, reason } = d.verdict {
                    let who = filters.get(d.unit).map_or("?", |s| s.as_str());
                    let why = match reason {
                        DropReason::PairwiseDeviation {
                            other,
                            distance,
                            theta,
                            deviation_from_pair,
                        } => format!(
                            "‖x̂_{who} − x̂_{}‖ = {distance:.4} > θ = {theta:.4} and ‖x̂_{who} − x̂_pair‖ = {deviation_from_pair:.4} > θ/2",
                            filters.get(other).map_or("?", |s| s.as_str())
                        ),
                        DropReason::LargestResidue { residue, flagged } => format!(
                            "largest residue {residue:.4}{}",
                            if flagged { " (flagged: rejected reading)" } else { "" }
                        ),
                    };
                    note.push_str(&format!("{who} dropped at {stage:?}: {why}; "));
                }
            }
            if let QpOutcome::InfeasibleAfterStep3 {
                action,
                max_cbf_violation,
            } = out.qp
            {
                note.push_str(&format!(
                    "infeasible after Step 3: safe action {action:?}, max CBF violation {max_cbf_violation:.4} m/s²"
                ));
            }
            let bank = controller.bank();
            for (i, f) in bank.filters().iter().enumerate() {
                let x = f.estimate();
                estimates_view[i] = EstimateView {
                    x: [x[0], x[1], x[2], x[3]],
                    residue: f.residue_norm(),
                    clf: out.v_values.get(i).copied().unwrap_or(f64::NAN),
                };
            }
            attacks_active.iter_mut().for_each(|a| *a = false);
            for i in attacks.active(t) {
                if let Some(a) = attacks_active.get_mut(i) {
                    *a = true;
                }
            }
        }

        // Drive and plant.
        let body_cmd = plant.apply_input(&u, heading, control_dt);
        for _ in 0..world.ticks_per_control {
            plant.tick();
            let tt = plant.truth();
            let x = tt.planar();
            for (j, b) in barriers.iter().enumerate().take(setup.safe_sets) {
                let h = b.eval(&x).value;
                if h < min_barrier[j] {
                    min_barrier[j] = h;
                }
                if h < 0.0 && first_violation.is_none() {
                    first_violation = Some(ViolationEvent {
                        t: tt.t,
                        set: setup.barrier_names[j].clone(),
                        value: h,
                    });
                    events.push(format!(
                        "safety violation: left {} at t = {:.3} s (h = {h:.4})",
                        setup.barrier_names[j], tt.t
                    ));
                }
            }
            for (oi, touching) in in_contact.iter_mut().enumerate() {
                let now = plant.in_contact(oi);
                if now && !*touching {
                    let name = world.obstacles[oi].name.clone();
                    events.push(format!("collision with {name} at t = {:.3} s", tt.t));
                    if first_collision.is_none() {
                        first_collision = Some(CollisionEvent {
                            t: tt.t,
                            obstacle: name,
                        });
                    }
                }
                *touching = now;
            }
            if time_to_goal.is_none() && in_goal(&tt) {
                time_to_goal = Some(tt.t);
            }
        }

        // Per control step: obstacle barriers on the truth, clearances.
        let tt = plant.truth();
        let x = tt.planar();
        for j in setup.safe_sets..nb {
            let h = barriers[j].eval(&x).value;
            min_barrier[j] = min_barrier[j].min(h);
        }
        if !world.obstacles.is_empty() {
            plant.clearances(&mut clearances);
            let m = clearances.iter().copied().fold(f64::INFINITY, f64::min);
            min_clearance = Some(min_clearance.map_or(m, |c: f64| c.min(m)));
        }

        if let Some(obs) = observer.as_deref_mut() {
            for (j, b) in barriers.iter().enumerate() {
                barrier_truth[j] = b.eval(&x).value;
            }
            plant.link_poses(&mut link_poses);
            obs.frame(&Frame {
                t,
                step: k,
                truth: &truth,
                channels: &channels_view,
                estimates: &estimates_view,
                barrier_values: &controller.output().h_values,
                barrier_truth: &barrier_truth,
                u: [u[0], u[1]],
                body_cmd,
                decided_by: stage_name(&controller.output().qp),
                decision_note: &note,
                attacks_active: &attacks_active,
                link_poses: &link_poses,
                events: &events,
            });
        }
    }

    let end = plant.truth();
    let collided = first_collision.is_some();
    Ok(RunSummary {
        world: world.name.clone(),
        seed,
        controller: controller_name(kind).to_string(),
        duration: n_steps as f64 * control_dt,
        safe: !collided && first_violation.is_none(),
        collided,
        first_collision,
        first_violation,
        min_barrier: setup
            .barrier_names
            .iter()
            .zip(min_barrier)
            .map(|(name, value)| NamedValue {
                name: name.clone(),
                value,
            })
            .collect(),
        min_clearance,
        goal_reached: time_to_goal.is_some(),
        time_to_goal,
        steps,
        control_steps: n_steps,
        rejected_readings: rejected,
        attack_windows,
        attacks_outside_fault_patterns: !outside.is_empty(),
        final_state: [end.x, end.y, end.vx, end.vy],
    })
}
