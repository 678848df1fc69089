//! The closed loop (one control tick):
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
//! [`Simulation`] is that loop, one control step per [`Simulation::step`]; it drives any
//! [`ControlLaw`] (the FT-CBF-CLF controller, the baseline, the nominal controller, or a
//! user-written law). [`run`] — a loop over it — is the one library call the CLI, the
//! regression suite and `ftcbf batch` share; [`run_observed`] shows every step's
//! [`Frame`] to an [`Observer`] (the recorder).
//!
//! ```no_run
//! use ftcbf_sim::runner::{CompiledWorld, RunOptions, Simulation};
//! use ftcbf_sim::world::World;
//!
//! let world = World::load(std::path::Path::new("worlds/paper_linear.toml"), &[])?;
//! // Compile it once (γ, θ, η, barriers, CLF, planned path); runs borrow the result.
//! let compiled = CompiledWorld::new(world)?;
//! let mut sim = Simulation::new(&compiled, &RunOptions::default())?;
//! while let Some(frame) = sim.step() {
//!     if !frame.events.is_empty() {
//!         println!("t = {:.2} s: {:?}", frame.t, frame.events);
//!     }
//! }
//! println!("safe: {}", sim.summary().safe);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod errors;
pub mod heading;
mod monitor;
mod scene;
mod stop;
mod view;

use ftcbf_controller::controller::{Controller, ControllerConfig};
use ftcbf_controller::drive::{brake_input, realized_acceleration, BodyCommand};
use ftcbf_controller::estimator::FilterRole;
use ftcbf_controller::interface::{ControlLaw, Readings};
use ftcbf_controller::policy::{QpOutcome, SafeAction, Stage};
use ftcbf_controller::Input;
use std::borrow::Cow;

use crate::attacks::AttackStack;
use crate::movers::fleet::MoverSet;
use crate::observe::{Frame, Observer, Scene};
use crate::sensors::SensorSuite;
use crate::summary::{AttackWindow, FailClosedCounts, RunSummary, SmoothnessMeter, StepCounts};
use crate::world::{ControllerKindSpec, World};

use errors::ErrorMeter;
use monitor::Monitor;
use view::StepView;

use crate::model::setup::ControlSetup;
pub use crate::plant::Plant;
pub use scene::build_scene;

pub use crate::model::{setups_computed, CompiledWorld, RunError, Source};

/// Per-run choices that override the world file.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// Seed (default: the world's).
    pub seed: Option<u64>,
    /// Controller (default: the world's `control.controller`).
    pub controller: Option<ControllerKindSpec>,
    /// Simulated duration \[s\] (default: the world's).
    pub duration: Option<f64>,
}

/// Builds everything a run of `world` with its own controller builds at its start (controller
/// setup, sensors, attacks, the control law, the plant) and drops it: `Ok` exactly when
/// [`run`] would start. `ftcbf check` calls it so that it refuses what `run` refuses.
pub fn preflight<'w>(world: impl Into<Source<'w>>) -> Result<(), RunError> {
    Simulation::new(world, &RunOptions::default()).map(drop)
}

/// Runs `world` (a [`World`] or a [`CompiledWorld`]) headlessly and returns its summary.
pub fn run<'w>(world: impl Into<Source<'w>>, opts: &RunOptions) -> Result<RunSummary, RunError> {
    let mut sim = Simulation::new(world, opts)?;
    sim.run_to_end();
    Ok(sim.summary())
}

/// Runs `world`, showing the scene and then every control step to `observer` (the recorder, a
/// test).
pub fn run_observed<'w>(
    world: impl Into<Source<'w>>,
    opts: &RunOptions,
    observer: Option<&mut dyn Observer>,
) -> Result<RunSummary, RunError> {
    let mut sim = Simulation::new(world, opts)?;
    let Some(obs) = observer else {
        sim.run_to_end();
        return Ok(sim.summary());
    };
    sim.set_link_poses(true);
    obs.scene(&sim.scene());
    while let Some(frame) = sim.step() {
        obs.frame(&frame);
    }
    Ok(sim.summary())
}

pub(crate) fn stage_name(o: &QpOutcome) -> &'static str {
    match o {
        QpOutcome::Feasible { stage, .. } => match stage {
            Stage::Step1 => "step1",
            Stage::ClfRelaxation => "clf_relaxed",
            Stage::Step2 => "step2",
            Stage::Step3 => "step3",
            Stage::Fallback => "infeasible",
            Stage::SafeStop => "safe_stop",
        },
        QpOutcome::InfeasibleAfterStep3 { .. } => "infeasible",
        QpOutcome::SafeStop { .. } => "safe_stop",
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
            Stage::SafeStop => &mut c.safe_stop,
        },
        QpOutcome::InfeasibleAfterStep3 { .. } => &mut c.infeasible,
        QpOutcome::SafeStop { .. } => &mut c.safe_stop,
    };
    *counter += 1;
}

/// One closed-loop run of a world, stepped by the caller: [`Simulation::step`] advances one
/// control period (sensors → attacks → control law → drive → plant ticks) and returns that
/// step's [`Frame`]; [`Simulation::summary`] reports what was measured so far. The same world,
/// options and law give the same frames and summary, bit for bit.
pub struct Simulation<'w> {
    world: &'w World,
    seed: u64,
    control_dt: f64,
    n_steps: u64,
    k: u64,
    setup: Cow<'w, ControlSetup>,
    suite: SensorSuite,
    attacks: AttackStack,
    law: Box<dyn ControlLaw>,
    plant: Plant,
    heading_source: heading::HeadingSource,
    filters: Vec<String>,
    windows: Vec<(String, f64, Option<f64>)>,
    attack_windows: Vec<AttackWindow>,
    /// The attacks together span more than one fault pattern.
    attacks_together_outside: bool,
    y: Vec<f64>,
    fresh: Vec<bool>,
    monitor: Monitor,
    steps: StepCounts,
    rejected: u64,
    fail_closed: FailClosedCounts,
    view: StepView,
    link_poses: bool,
    smooth: SmoothnessMeter,
    errors: ErrorMeter,
    /// The acceleration the drive realised over the last period (None for the linear plant).
    applied: Option<Input>,
    /// The safe stops so far, and whether this step is one.
    stops: stop::StopMeter,
    braking: bool,
    /// Fault-pattern names, for the stop's reason.
    pattern_names: Vec<String>,
    /// The moving obstacles (issue #51) and their states at the last plant tick.
    movers: MoverSet,
    mover_now: Vec<ftcbf_controller::MoverState>,
}

impl<'w> Simulation<'w> {
    /// A run of `world` with the controller the options (or the world file) name. Given a
    /// [`CompiledWorld`], the run borrows its controller setup; given a [`World`], it computes
    /// one for itself.
    pub fn new(world: impl Into<Source<'w>>, opts: &RunOptions) -> Result<Self, RunError> {
        Self::with_law(world, opts, |config| {
            Controller::new(config.clone())
                .map(|c| Box::new(c) as Box<dyn ControlLaw>)
                .map_err(|e| e.to_string())
        })
    }

    /// A run of `world` driven by the law `make` builds from the controller configuration the
    /// world implies (linear model and its channels, barriers, goal, input limit). The
    /// configuration is that of `opts.controller` or the world's controller kind.
    pub fn with_law(
        world: impl Into<Source<'w>>,
        opts: &RunOptions,
        make: impl FnOnce(&ControllerConfig) -> Result<Box<dyn ControlLaw>, String>,
    ) -> Result<Self, RunError> {
        let source = world.into();
        let world = source.world();
        let file = &world.file;
        let seed = opts.seed.unwrap_or(file.seed);
        let kind = opts.controller.unwrap_or(file.control.controller);
        let duration = crate::world::ranges::check_duration(opts.duration.unwrap_or(file.duration))
            .map_err(RunError::Option)?;
        if duration > file.duration {
            // γ, θ, η (and the dead-reckoning bounds) are computed for the world's duration:
            // their union bound is over its samples, so a longer run is past their horizon.
            return Err(RunError::Option(format!(
                "--duration {duration}: past the world's duration ({} s), the horizon its γ, θ and η are computed for; give the world that duration (`--set duration={duration}`) so they are computed for it",
                file.duration
            )));
        }
        let steps = duration * file.control.rate_hz;
        let plant_steps = duration / world.plant_dt();
        if steps > crate::world::ranges::MAX_CONTROL_STEPS
            || plant_steps > crate::world::ranges::MAX_PLANT_STEPS
        {
            return Err(RunError::Option(format!(
                "--duration {duration}: {steps} control steps and {plant_steps} plant steps at this world's rates; at most {} and {} are supported",
                crate::world::ranges::MAX_CONTROL_STEPS,
                crate::world::ranges::MAX_PLANT_STEPS
            )));
        }
        let start_err = |what: &'static str, message: String| RunError::Start {
            world: world.path.display().to_string(),
            what,
            message,
        };
        let control_dt = world.control_dt();
        let setup = source.setup(kind)?;
        let mut suite = SensorSuite::new(&file.sensors, control_dt, seed)
            .map_err(|e| start_err("sensors", e.to_string()))?;
        let attacks = AttackStack::new(&file.attacks, &suite, seed)
            .map_err(|e| start_err("attacks", e.to_string()))?;
        let law = make(&setup.config).map_err(|e| start_err("controller", e))?;
        let plant = Plant::new(world, seed).map_err(|e| start_err("plant", e))?;
        suite.set_wheel_geometry(plant.wheel_geometry());
        Ok(Self::assemble(
            world, seed, duration, setup, suite, attacks, law, plant,
        ))
    }

    // One argument per component built (and checked) by `with_law`.
    #[allow(clippy::too_many_arguments)]
    fn assemble(
        world: &'w World,
        seed: u64,
        duration: f64,
        setup: Cow<'w, ControlSetup>,
        suite: SensorSuite,
        attacks: AttackStack,
        law: Box<dyn ControlLaw>,
        plant: Plant,
    ) -> Self {
        let file = &world.file;
        let control_dt = world.control_dt();
        let heading_source = heading::HeadingSource::new(world, plant.truth().theta);
        let filters = filter_labels(world, law.as_ref());
        let windows = attacks.windows();
        let attack_windows = attack_windows(&attacks, &windows, world);
        let attacks_together_outside = attacks.union_outside_fault_patterns(&world.patterns);
        let mut movers = MoverSet::new(
            &world.obstacles,
            &crate::world::structure::obstacle_barrier_config(world),
            seed,
        );
        movers.track(
            &world.obstacles,
            crate::model::setup::tracker_eps(world),
            seed,
        );
        let monitor = Monitor::new(world, &setup, &movers);
        let view = StepView::new(
            file.sensors.len(),
            filters.len(),
            monitor.barriers(),
            windows.len(),
        );
        let q = setup.sensor_of_channel.len();
        let errors = match law.estimators() {
            Some(bank) => ErrorMeter::new(
                &filters,
                &errors::filter_gammas(bank, &setup),
                &errors::honest_filters(bank, &attacks, world),
            ),
            None => ErrorMeter::default(),
        };
        Self {
            world,
            seed,
            control_dt,
            n_steps: world.control_steps(duration),
            k: 0,
            setup,
            suite,
            attacks,
            law,
            plant,
            heading_source,
            filters,
            windows,
            attack_windows,
            attacks_together_outside,
            y: vec![0.0; q],
            fresh: vec![false; q],
            monitor,
            steps: StepCounts::default(),
            rejected: 0,
            fail_closed: FailClosedCounts::default(),
            view,
            link_poses: false,
            smooth: SmoothnessMeter::default(),
            errors,
            applied: None,
            stops: stop::StopMeter::default(),
            braking: false,
            pattern_names: file.fault_patterns.iter().map(|p| p.name.clone()).collect(),
            movers,
            mover_now: Vec::new(),
        }
    }

    /// Also report the robot's link poses in every [`Frame`] (off by default: it costs a
    /// string per link and step; the recorder needs it).
    pub fn set_link_poses(&mut self, on: bool) {
        self.link_poses = on;
    }

    /// The static scene (obstacles, robot shapes, safe-set outlines, series names).
    pub fn scene(&self) -> Scene {
        build_scene(self.world, &self.setup, &self.filters, &self.windows)
    }

    /// The channel layout and controller configuration derived from the world.
    pub fn setup(&self) -> &ControlSetup {
        &self.setup
    }

    /// Control steps taken so far, and in the whole run.
    pub fn progress(&self) -> (u64, u64) {
        (self.k, self.n_steps)
    }

    /// Advances one control step and returns it; `None` once the run's duration is over.
    pub fn step(&mut self) -> Option<Frame<'_>> {
        let t = self.advance(true)?;
        Some(self.frame(t, self.k - 1))
    }

    /// Steps until the end of the run. No frame is shown to anyone, so the decision's note
    /// (text formatted from the policy's record, for frames only) is not written: the run and
    /// its summary are the same as [`Simulation::step`]'s, bit for bit.
    pub fn run_to_end(&mut self) {
        while self.advance(false).is_some() {}
    }

    /// One control step (writing the decision's note for a frame when `note`); its time, or
    /// `None` once the run's duration is over.
    fn advance(&mut self, note: bool) -> Option<f64> {
        if self.k >= self.n_steps {
            return None;
        }
        let t = self.k as f64 * self.control_dt;
        if !self.movers.is_empty() {
            let truth = self.plant.truth();
            let radius = self
                .world
                .robot
                .as_ref()
                .map_or(0.0, |r| r.footprint_radius);
            self.movers
                .control_step(t, self.control_dt, ([truth.x, truth.y], radius));
        }
        self.sense(t);
        let u = self.decide(t, note);
        self.actuate(u, t);
        self.k += 1;
        Some(t)
    }

    /// Sensors sample the truth, attacks rewrite the samples (a stealthy attacker reads the
    /// law's all-channel filter prediction), the channels the law reads are copied out.
    fn sense(&mut self, t: f64) {
        let mut truth = self.plant.truth();
        truth.t = t;
        self.view.truth = truth;
        self.view.events.clear();
        self.view.contacts.clear();
        let samples = self.suite.sample(&truth);
        for (v, s) in self.view.channels.iter_mut().zip(samples.iter()) {
            v.clean = s.value;
        }
        let bank = self.law.estimators();
        let map = &self.setup.channel_of_sensor;
        let conversion = &self.setup.conversion;
        // A stealthy attacker hides under the detector of a channel the filters read directly; a
        // converted or derived one has none to hide under.
        let detector = |ch: usize| {
            let b = bank?;
            let c = map.get(ch).copied().flatten()?;
            (conversion[c] == crate::world::structure::Conversion::Direct).then_some(())?;
            b.predicted_measurement(b.baseline_index(), c)
        };
        self.attacks.apply(t, samples, &detector);
        let samples = self.suite.propagate_attacks();
        // The heading as received (attacks included), or its fusion with the gyro: a `speed`
        // channel with `world_velocity` is turned into world-frame velocity with it, and the
        // drive keeps its own heading from it (see `HeadingSource::update`).
        let theta = self
            .heading_source
            .update(samples, self.control_dt, self.view.body_cmd[1]);
        for (c, &si) in self.setup.sensor_of_channel.iter().enumerate() {
            self.y[c] = self.setup.conversion[c].apply(samples[si].value, theta);
            self.fresh[c] = samples[si].fresh;
        }
        self.view.received(samples, map, bank);
    }

    /// The moving obstacles as the controller read them at the last control step (a tracked
    /// mover's estimate with its error bounds; the truth for an exact reading), in mover order.
    pub fn mover_readings(&self) -> &[ftcbf_controller::MoverState] {
        self.movers.states()
    }

    /// The law's step; counts the deciding policy stage and the rejected readings.
    fn decide(&mut self, t: f64, note: bool) -> Input {
        let readings = Readings {
            t,
            dt: self.control_dt,
            y: &self.y,
            fresh: &self.fresh,
            applied: self.applied,
            movers: self.movers.states(),
        };
        let decision = self.law.step(&readings);
        self.braking = false;
        if let Some(out) = decision.record {
            count_stage(&mut self.steps, &out.qp);
            // A safe stop that steps aside for a mover drives its input; the plain one brakes
            // on the encoders.
            self.braking = matches!(
                out.qp,
                QpOutcome::SafeStop {
                    evades_movers: false,
                    ..
                }
            );
            if let Some(line) = self.stops.observe(t, &out.qp, &self.pattern_names) {
                self.view.events.push(line);
            }
            self.rejected += out.rejected.count as u64;
            let fc = &mut self.fail_closed;
            fc.non_finite_row_steps += u64::from(out.decision.non_finite_rows > 0);
            fc.skipped_updates += out.rejected.skipped_updates as u64;
            fc.step2_retained_steps += u64::from(out.decision.step2_retained.is_some());
            fc.step3_saturated_steps += u64::from(out.decision.step3_saturated.is_some());
            self.smooth.set_stalls(out.stalls as u64);
            fc.brake_steps += u64::from(matches!(
                out.qp,
                QpOutcome::InfeasibleAfterStep3 {
                    action: SafeAction::Brake { .. },
                    ..
                }
            ));
            let map = &self.setup.channel_of_sensor;
            for (v, c) in self.view.channels.iter_mut().zip(map) {
                v.rejected = c.is_some_and(|c| out.rejected.channels.get(c) == Some(&true));
            }
        }
        self.view.decision(decision.record, &self.filters, note);
        let u = decision.u;
        self.view.u = [u[0], u[1]];
        self.view.estimates(self.law.estimators(), &mut self.errors);
        self.view.attacks_active.iter_mut().for_each(|a| *a = false);
        for i in self.attacks.active(t) {
            if let Some(a) = self.view.attacks_active.get_mut(i) {
                *a = true;
            }
        }
        u
    }

    /// Holds `u` through the drive for one control period of plant ticks, checking the truth.
    fn actuate(&mut self, u: Input, t: f64) {
        let before = self.view.body_cmd;
        let yaw = self.heading_source.drive_yaw();
        // The safe stop brakes on the wheel encoders' speed (not on a sensor channel, the
        // attack surface): along the heading the compensator uses, at the input box's
        // acceleration, with no turn (see `ftcbf_controller::drive::brake_input`).
        let u = match (self.braking, self.plant.encoder_speed()) {
            (true, Some(v)) => {
                let decel = self.world.brake_deceleration();
                brake_input(v, yaw, decel, self.control_dt)
            }
            _ => u,
        };
        self.view.body_cmd = self.plant.apply_input(&u, yaw, self.control_dt);
        // What the drive made of u, for the filters' next prediction (the linear plant
        // realises u exactly: nothing to report).
        self.applied = self.plant.wheel_geometry().and_then(|_| {
            let cmd = |c: [f64; 2]| BodyCommand {
                v: c[0],
                omega: c[1],
            };
            realized_acceleration(cmd(before), cmd(self.view.body_cmd), yaw, self.control_dt)
        });
        let p = [self.view.truth.x, self.view.truth.y];
        self.smooth.observe(self.view.body_cmd, p);
        let plant_dt = self.world.plant_dt();
        for j in 0..self.world.ticks_per_control {
            if !self.movers.is_empty() {
                // Where each mover is at the end of this tick.
                let tau = t + f64::from(j + 1) * plant_dt;
                self.movers.states_at(tau, &mut self.mover_now);
                for (m, &i) in self.mover_now.iter().zip(self.movers.obstacles()) {
                    self.plant.move_obstacle(i, m.displacement);
                }
            }
            self.plant.tick();
            self.monitor
                .after_tick(&self.plant, self.world, &self.mover_now, &mut self.view);
        }
        self.monitor.after_step(
            &self.plant,
            self.world,
            &self.mover_now,
            &mut self.view.barrier_truth,
        );
        if self.link_poses {
            self.plant.link_poses(&mut self.view.link_poses);
        }
    }

    fn frame(&self, t: f64, step: u64) -> Frame<'_> {
        let v = &self.view;
        Frame {
            t,
            step,
            truth: &v.truth,
            channels: &v.channels,
            estimates: &v.estimates,
            barrier_values: &v.barrier_values,
            barrier_truth: &v.barrier_truth,
            u: v.u,
            body_cmd: v.body_cmd,
            decided_by: match v.decided_by {
                Some(stage) => stage,
                None => self.law.name(),
            },
            decision_note: &v.note,
            attacks_active: &v.attacks_active,
            link_poses: &v.link_poses,
            events: &v.events,
            movers: self.movers.truth(),
            mover_readings: self.movers.states(),
            contacts: &v.contacts,
        }
    }

    /// What the run measured so far (the whole run after [`Simulation::run_to_end`]).
    pub fn summary(&self) -> RunSummary {
        let m = &self.monitor;
        let end = self.plant.truth();
        let collided = m.first_collision.is_some();
        let (goal_settled, final_goal_distance, final_clf_value) = m.goal_outcome(self.world, &end);
        let min_barrier = m.min_barrier();
        let final_state = [end.x, end.y, end.vx, end.vy];
        let non_finite =
            crate::summary::first_non_finite(&min_barrier, m.min_clearance, &final_state)
                .or_else(|| m.non_finite.clone());
        RunSummary {
            world: self.world.name.clone(),
            seed: self.seed,
            controller: self.law.name().to_string(),
            duration: self.k as f64 * self.control_dt,
            safe: !collided
                && m.first_violation.is_none()
                && non_finite.is_none()
                && m.disagreement.is_none(),
            non_finite,
            disagreement: m.disagreement.clone(),
            collided,
            first_collision: m.first_collision.clone(),
            first_violation: m.first_violation.clone(),
            min_barrier,
            min_clearance: m.min_clearance,
            goal_reached: m.time_to_goal.is_some(),
            time_to_goal: m.time_to_goal,
            goal_settled,
            final_goal_distance,
            final_clf_value,
            steps: self.steps,
            control_steps: self.k,
            rejected_readings: self.rejected,
            fail_closed: FailClosedCounts {
                refused_headings: self.heading_source.refused_readings(),
                ..self.fail_closed
            },
            attacks_outside_fault_patterns: self.attacks_together_outside
                || self.attack_windows.iter().any(|w| w.outside_fault_patterns),
            attacks_together_outside_fault_patterns: self.attacks_together_outside,
            attack_windows: self.attack_windows.clone(),
            final_state,
            smoothness: self.smooth.smoothness(),
            estimation_errors: self.errors.rows().to_vec(),
            safe_stop: self.stops.report(),
            collisions: m.collisions,
        }
    }
}

/// Estimator labels named after the world's fault patterns: drop_<F(r_i)>,
/// drop_<F(r_i)>+<F(r_j)>, all (none for a law without a bank).
fn filter_labels(world: &World, law: &dyn ControlLaw) -> Vec<String> {
    let Some(bank) = law.estimators() else {
        return Vec::new();
    };
    let pname = |i: usize| {
        world
            .file
            .fault_patterns
            .get(i)
            .map_or_else(|| format!("r{}", i + 1), |p| p.name.clone())
    };
    bank.filters()
        .iter()
        .map(|f| match f.role() {
            FilterRole::DropPattern(i) => format!("drop_{}", pname(i)),
            FilterRole::DropPair(i, j) => format!("drop_{}+{}", pname(i), pname(j)),
            FilterRole::Baseline => "all".to_string(),
        })
        .collect()
}

fn attack_windows(
    attacks: &AttackStack,
    windows: &[(String, f64, Option<f64>)],
    world: &World,
) -> Vec<AttackWindow> {
    let outside = attacks.outside_fault_patterns(&world.patterns);
    windows
        .iter()
        .enumerate()
        .map(|(i, (label, start, end))| AttackWindow {
            label: label.clone(),
            start: *start,
            end: *end,
            outside_fault_patterns: outside.contains(&i),
        })
        .collect()
}
