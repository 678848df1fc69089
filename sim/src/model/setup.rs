//! From a validated [`World`] to the controller's configuration: which channels the linear model
//! observes, its noise model, the barriers, and the parameters (given, or computed per §4.3).
//!
//! One file (about 1,100 lines): [`ControlSetup::new`] derives in one order — channels, noise,
//! barriers, parameters, gain, problem form, configuration — and each step's helper sits where
//! the order needs it; the world's own structure (channels as sensors, timing, bounds) is in
//! `crate::world::structure`, the identification of q in `identify`.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use ftcbf_controller::barrier::HalfPlane;
use ftcbf_controller::controller::ControllerConfig;
use ftcbf_controller::lyapunov::{ClfConfig, QuadraticClf};
use ftcbf_controller::model::LinearModel;
use ftcbf_controller::params::{
    gain_product, steady_state_riccati, BoundMethod, FtComputed, FtDerivation, FtParams,
};
use ftcbf_controller::policy::DEFAULT_EVIDENCE_ALPHA;
use ftcbf_controller::{
    Barrier, Fallback, Input, MovingBarrier, ProblemForm, State, StateMatrix, TrackerConfig,
};
use nalgebra::Matrix2;

use crate::obstacles::BarrierConfig;
use crate::planner::{plan_with_cost, widest_route, PlannerConfig};
use crate::safe_sets::{LiftedEllipse, LiftedProp1};
use crate::world::{
    BoundsSpec, ControllerKindSpec, Dynamics, FallbackSpec, FormSpec, Param, ProcessModel,
    SafeSetSpec, World,
};

use crate::world::structure::{
    check_h_bar_inputs, model_patterns, obstacle_barrier_config, sensor_timing, speed_bound,
    Channels, Conversion, SensorTiming, StructureError,
};

use super::RunError;

/// Readings larger than this are rejected by the controller as absurd [m or m/s].
pub const MAX_ABS_READING: f64 = ftcbf_controller::controller::DEFAULT_MAX_ABS_READING;

/// How many times a world's controller setup (channels, model, barriers, γ/θ/η, κ, CLF, planned
/// path) has been computed in this process: [`ControlSetup::new`] counts each. Read it before
/// and after some work to see how often that work compiled a world (a batch: once per sweep
/// point, whatever its trials and controllers).
pub fn setups_computed() -> u64 {
    SETUPS_COMPUTED.load(Ordering::Relaxed)
}

static SETUPS_COMPUTED: AtomicU64 = AtomicU64::new(0);

/// Everything a run derives from its world for the controller (computed once per world by
/// [`CompiledWorld`](super::CompiledWorld)).
#[derive(Clone)]
pub struct ControlSetup {
    /// The configuration handed to `Controller::new`.
    pub config: ControllerConfig,
    /// For each controller channel, the sensor index it reads.
    pub sensor_of_channel: Vec<usize>,
    /// For each sensor, its (first) controller channel (None: heading, yaw rate, a speed that
    /// is only recorded).
    pub channel_of_sensor: Vec<Option<usize>>,
    /// For each controller channel, how its value comes from its sensor's sample.
    pub conversion: Vec<Conversion>,
    /// Barrier names: safe sets, then obstacles.
    pub barrier_names: Vec<String>,
    /// Number of closed-form safe sets (the first barriers).
    pub safe_sets: usize,
    /// The parameters used, and how they were obtained (for `check` and logs).
    pub params: ParamSources,
    /// κ in force and how it was chosen.
    pub gain: GainChoice,
}

/// The planner's default corridor beyond the obstacle margin \[m\] ([`PlannerConfig`]), and the
/// band beyond h̄_γ within which `cbf_gain = "auto"` makes every obstacle row hold the robot at
/// rest (ĥ ≥ band ⇒ u = 0 meets the row): the rate-tunable rule κ ≥ R/band at rest.
pub const HOLD_BAND: f64 = 0.10;

/// How κ was chosen.
#[derive(Debug, Clone, PartialEq)]
pub enum GainSource {
    /// The world file gives it.
    Declared,
    /// `"auto"`: the smallest κ ≥ the floor with which every single-drop filter's obstacle rows
    /// hold the robot at rest once ĥ = h − h̄_γ ≥ [`HOLD_BAND`], κ ≥ R / band, capped at
    /// κ·dt ≤ 1/2. The planned path then keeps h̄_γ + R/κ from the obstacles where it can.
    Auto {
        /// The largest robust term γ_i‖(K_i c̄_i)ᵀ∂H‖ at rest over the filters and directions [m/s²].
        robust: f64,
        /// R/band before the floor and the cap.
        needed: f64,
        /// The floor.
        floor: f64,
        /// The cap 1/(2 dt).
        cap: f64,
    },
}

/// κ in force, how it was chosen, and the clearance at which its rows hold the robot at rest.
#[derive(Debug, Clone, PartialEq)]
pub struct GainChoice {
    /// κ.
    pub kappa: f64,
    /// Why.
    pub source: GainSource,
    /// h̄ + R/κ: the clearance beyond the margin where u = 0 meets every obstacle row at rest \[m\]
    /// (0 without obstacles).
    pub hold_clearance: f64,
}

impl std::fmt::Display for GainChoice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match &self.source {
            GainSource::Declared => write!(f, "κ = {} (declared)", self.kappa)?,
            GainSource::Auto {
                robust,
                needed,
                floor,
                cap,
            } => write!(
                f,
                "κ = {} (auto: every obstacle row holds the robot at rest once ĥ ≥ {HOLD_BAND} m when κ ≥ R/{HOLD_BAND} = {robust:.4}/{HOLD_BAND} = {needed:.4}; floor {floor}, cap 1/(2·dt) = {cap})",
                self.kappa
            )?,
        }
        write!(
            f,
            "; at rest the obstacle rows hold u = 0 from h̄_γ + R/κ = {:.4} m beyond the margin",
            self.hold_clearance
        )
    }
}

/// The largest robust term at rest of the obstacle rows, γ_i‖(K_i c̄_i)ᵀ(n, k n)‖ over the
/// single-drop filters (the all-channel filter when the world has no fault pattern) and 72
/// directions n, and the largest h̄_γ of an obstacle. Filters without a finite steady-state gain
/// are left out (their bounds are finite-horizon; `check` reports them).
fn obstacle_rest_terms(
    world: &World,
    model: &LinearModel,
    patterns: &[Vec<usize>],
    gamma: &[f64],
    gamma_all: f64,
    obstacles: &[Arc<dyn Barrier>],
) -> (f64, f64) {
    let dt = world.control_dt();
    let k = world.file.control.obstacle_lift;
    let q = model.channels();
    let filters: Vec<(Vec<bool>, f64)> = if patterns.is_empty() {
        vec![(vec![true; q], gamma_all)]
    } else {
        (0..patterns.len())
            .map(|i| (channel_mask(q, patterns, &[i]), gamma[i]))
            .collect()
    };
    let mut robust: f64 = 0.0;
    let mut h_bar: f64 = 0.0;
    for (mask, g) in filters {
        let kc = ftcbf_controller::params::steady_state_gain_product(model, &mask, dt);
        if !kc.iter().all(|v| v.is_finite()) || !g.is_finite() {
            continue;
        }
        for d in 0..72 {
            let a = f64::from(d) * 5f64.to_radians();
            let grad = State::new(a.cos(), a.sin(), k * a.cos(), k * a.sin());
            robust = robust.max(g * (kc.transpose() * grad).norm());
        }
        for b in obstacles {
            h_bar = h_bar.max(b.h_bar(g));
        }
    }
    (robust, h_bar)
}

/// κ in force (see [`GainSource`]).
pub fn choose_gain(
    world: &World,
    model: &LinearModel,
    patterns: &[Vec<usize>],
    ft: &FtParams,
    obstacles: &[Arc<dyn Barrier>],
) -> GainChoice {
    let c = &world.file.control;
    let (robust, h_bar) = if obstacles.is_empty() {
        (0.0, 0.0)
    } else {
        obstacle_rest_terms(
            world,
            model,
            patterns,
            &ft.gamma,
            ft.gamma_baseline,
            obstacles,
        )
    };
    let hold = |kappa: f64| {
        if obstacles.is_empty() {
            0.0
        } else {
            h_bar + robust / kappa
        }
    };
    if !c.cbf_gain_auto {
        return GainChoice {
            kappa: c.cbf_gain,
            source: GainSource::Declared,
            hold_clearance: hold(c.cbf_gain),
        };
    }
    let floor = c.cbf_gain;
    let cap = world.kappa_max().max(floor);
    let needed = robust / HOLD_BAND;
    let kappa = if needed.is_finite() {
        needed.clamp(floor, cap)
    } else {
        cap
    };
    GainChoice {
        kappa,
        source: GainSource::Auto {
            robust,
            needed,
            floor,
            cap,
        },
        hold_clearance: hold(kappa),
    }
}

/// Where the parameters in force came from, for reports. The parameters themselves (γ_i, γ of
/// the all-channel filter, θ_ij, and η_ij, W_ij and θ_ij(t) of Step 2's increment test) are held
/// once, in the controller's configuration ([`ControlSetup::config`]'s `ft`).
#[derive(Debug, Clone)]
pub struct ParamSources {
    /// δ (∞ = constraints always active).
    pub delta: f64,
    /// δ was not given and was chosen for Prop. 1 ([`auto_delta`]).
    pub delta_auto: bool,
    /// How §4.3 computed them (`auto`); None when the world file gives γ and θ.
    pub derivation: Option<FtDerivation>,
    /// ε the computed parameters are for.
    pub epsilon: f64,
    /// How the filter channels' readings arrive in the worst case γ, θ and η are computed for.
    pub timing: SensorTiming,
}

/// Barriers for the world's safe sets (closed form, from the controller crate). Without a
/// [`speed_bound`] the ellipses' h̄_γ uses v_max = 0, which is exact only for `lift = 0`
/// ([`ControlSetup::new`] refuses a lifted ellipse without a speed bound).
pub fn safe_set_barriers(world: &World) -> Vec<Arc<dyn Barrier>> {
    world
        .file
        .safe_sets
        .iter()
        .map(|s| -> Arc<dyn Barrier> {
            match (s, lifted_ellipse(world, s)) {
                (SafeSetSpec::HalfPlane { name, a, b }, _) => Arc::new(HalfPlane::new(
                    name.clone(),
                    State::new(a[0], a[1], a[2], a[3]),
                    *b,
                )),
                (_, Some(e)) => Arc::new(e),
                (_, None) => unreachable!("every non-half-plane safe set is an ellipse"),
            }
        })
        .collect()
}

/// Prop. 1 in position space ([`LiftedEllipse::prop1`]) for an ellipse safe set of `world`,
/// with the parameters in force: θ̄ = max θ_ij, h̄ = max_i h̄_γi of the barrier that runs, δ,
/// and (keep-out ellipses) estimates outside the ellipse (`h_low = 0`). `None` for a
/// half-plane. For `ftcbf check` and any report of the guarantees a world has.
pub fn ellipse_prop1(
    world: &World,
    setup: &ControlSetup,
    spec: &SafeSetSpec,
) -> Option<LiftedProp1> {
    let e = lifted_ellipse(world, spec)?;
    let p = &setup.config.ft;
    let theta_bar = p.theta.iter().copied().fold(0.0_f64, f64::max);
    let h_bar = p
        .gamma
        .iter()
        .map(|&g| e.h_bar(g))
        .fold(f64::NEG_INFINITY, f64::max)
        .max(0.0);
    Some(e.prop1(theta_bar, h_bar, setup.params.delta, 0.0))
}

/// The barrier that runs for an ellipse safe set (with the world's [`speed_bound`], 0 when
/// none), e.g. to evaluate [`LiftedEllipse::prop1`] on it; `None` for a half-plane.
pub fn lifted_ellipse(world: &World, spec: &SafeSetSpec) -> Option<LiftedEllipse> {
    let v_max = speed_bound(world).unwrap_or(0.0);
    match spec {
        SafeSetSpec::HalfPlane { .. } => None,
        SafeSetSpec::EllipseInside {
            name,
            center,
            semi_axes,
            angle,
            lift,
        }
        | SafeSetSpec::EllipseOutside {
            name,
            center,
            semi_axes,
            angle,
            lift,
        } => Some(LiftedEllipse::new(
            name.clone(),
            *center,
            *semi_axes,
            *angle,
            matches!(spec, SafeSetSpec::EllipseInside { .. }),
            *lift,
            v_max,
        )),
    }
}

impl ControlSetup {
    /// Builds the controller configuration for `world` run with `kind`.
    pub fn new(world: &World, kind: ControllerKindSpec) -> Result<Self, RunError> {
        SETUPS_COMPUTED.fetch_add(1, Ordering::Relaxed);
        let file = &world.file;
        let ch = Channels::of(world).map_err(structure(world))?;
        let patterns = model_patterns(world, &ch.channels_of_sensor).map_err(structure(world))?;
        let (q, _) = process_noise(world)?;
        let model = LinearModel::new(
            LinearModel::double_integrator_f(),
            LinearModel::double_integrator_g(),
            ch.c_rows,
            filter_process_noise(world, q),
            ch.r,
        )
        .map_err(|e| setup_err(world, "sensors", e.to_string()))?;

        // Barriers: closed-form safe sets, then obstacles.
        let bcfg = obstacle_barrier_config(world);
        check_h_bar_inputs(world, &bcfg).map_err(structure(world))?;
        let mut barriers = safe_set_barriers(world);
        let safe_sets = barriers.len();
        let mut mover = 0;
        for ob in &world.obstacles {
            if ob.spec.motion.is_none() {
                for b in ob.barriers(&bcfg) {
                    barriers.push(Arc::new(b));
                }
                continue;
            }
            // A moving obstacle's barrier at its start, moved by its reading; its h̄_γ bound
            // is for the relative speed (the robot's bound plus the obstacle's).
            let cfg = BarrierConfig {
                v_max: bcfg.v_max + crate::movers::fleet::max_speed(&ob.spec),
                k: mover_lift(world, &ob.spec, &bcfg),
                ..bcfg
            };
            let base: Arc<dyn Barrier> = Arc::new(ob.barrier(&cfg));
            barriers.push(Arc::new(MovingBarrier::new(base, mover)));
            mover += 1;
        }
        let barrier_names = barriers.iter().map(|b| b.name().to_string()).collect();
        let (ft, params) = parameters(world, &model, &patterns, &ch.sensor_of_channel);
        let gain = choose_gain(world, &model, &patterns, &ft, &barriers[safe_sets..]);
        let form = problem_form(
            world,
            &bcfg,
            &model,
            &patterns,
            &ft.gamma,
            &barriers[..safe_sets],
            &gain,
        )?;

        let goal = State::new(file.goal.center[0], file.goal.center[1], 0.0, 0.0);
        let clf = clf_config(world, &model, goal)?;
        let units = match kind {
            ControllerKindSpec::FtCbfClf => patterns.len(),
            _ => 1,
        };
        let index = active_index(world, &bcfg, units, safe_sets, barriers.len());
        let builder = ControllerConfig::builder(model, patterns, ft);
        let builder = match index {
            Some(index) => builder.barrier_index(index),
            None => builder,
        };
        let config = builder
            .kind(kind.into())
            .barriers(barriers)
            .goal(goal, file.goal.radius)
            .delta(params.delta)
            .cbf_gain(gain.kappa)
            .clf(clf)
            .input_cost(Matrix2::identity())
            .input_limit(file.control.input_limit.map(|l| Input::new(l, l)))
            .start(initial_estimate(world), initial_covariance(world))
            .max_abs_reading(MAX_ABS_READING)
            .form(form)
            .fallback(match file.control.fallback {
                FallbackSpec::Paper => Fallback::Paper,
                FallbackSpec::Brake => {
                    Fallback::brake(DEFAULT_EVIDENCE_ALPHA).expect("the default α is in (0, 0.5)")
                }
            })
            .build();
        Ok(Self {
            config,
            sensor_of_channel: ch.sensor_of_channel,
            channel_of_sensor: ch
                .channels_of_sensor
                .iter()
                .map(|c| c.first().copied())
                .collect(),
            conversion: ch.conversion,
            barrier_names,
            safe_sets,
            params,
            gain,
        })
    }
}

/// The least time the drive takes to turn a quarter turn from rest \[s\] (a differential
/// drive reverses, so π/2 is the most it turns to face an escape direction): at ω_max, after
/// the yaw acceleration limit when the drive has one. None without a robot (a point robot
/// accelerates in any direction).
pub fn quarter_turn_time(world: &World) -> Option<f64> {
    let robot = world.robot.as_ref()?;
    let w = robot.limits.omega_max;
    let theta = std::f64::consts::FRAC_PI_2;
    let drive = crate::plant::drive_config(world, &robot.limits);
    Some(match drive.domega_max {
        Some(a) if a > 0.0 && theta <= w * w / a => 2.0 * (theta / a).sqrt(),
        Some(a) if a > 0.0 => theta / w + w / a,
        _ => theta / w,
    })
}

/// The per-sample probability ε' a tracked mover's reading may break its error bounds
/// (issue #51, [`crate::movers::tracked`]): ε/(N·M) with ε the world's `control.epsilon`, N
/// its control steps over its duration and M its tracked movers (a union bound over them all).
pub fn tracker_eps(world: &World) -> f64 {
    let n = world.control_steps(world.file.duration).max(1) as f64;
    let m = world
        .obstacles
        .iter()
        .filter(|o| o.spec.motion.is_some() && o.spec.tracker.is_some())
        .count()
        .max(1) as f64;
    world.file.control.epsilon / (n * m)
}

/// The lift k of moving obstacle `spec`'s barrier \[s\] (issue #51): the world's
/// `obstacle_lift`, raised so that a robot stopped on the mover's boundary (d = margin + k·v_o)
/// with the mover heading at it square to its heading can turn a quarter turn
/// ([`quarter_turn_time`]) and reach v_o at the brake deceleration a before contact:
/// k ≥ t_turn + v_o/(2a) − margin/v_o.
pub fn mover_lift(
    world: &World,
    spec: &crate::obstacles::ObstacleSpec,
    bcfg: &BarrierConfig,
) -> f64 {
    let v_o = crate::movers::fleet::max_speed(spec);
    match quarter_turn_time(world) {
        Some(t) if v_o > 0.0 => {
            let a = world.brake_deceleration();
            bcfg.k.max(t + v_o / (2.0 * a) - bcfg.margin / v_o)
        }
        _ => bcfg.k,
    }
}

/// The active-barrier index ([`crate::active`]) when a step can have more barrier rows
/// (units × barriers: fault patterns for ft-cbf-clf, one for the others) than [`ftcbf_controller::qp::COMPACT_CBF_ROWS`], the most a QP
/// holds all of; below, every row is built and solved row for row as before (every catalogue
/// world, so their results stay bit-identical).
pub fn active_index(
    world: &World,
    bcfg: &BarrierConfig,
    units: usize,
    safe_sets: usize,
    barriers: usize,
) -> Option<Arc<dyn ftcbf_controller::reach::BarrierIndex>> {
    if units.max(1) * barriers <= ftcbf_controller::qp::COMPACT_CBF_ROWS {
        return None;
    }
    let index = crate::active::ObstacleIndex::new(&world.obstacles, safe_sets, barriers, bcfg);
    (index.covered_count() > 0).then(|| Arc::new(index) as _)
}

/// `[control] form` with its tracker: the path through `[goal] waypoints`, planned around the
/// obstacles when `[goal] plan` (see [`crate::planner`]).
fn problem_form(
    world: &World,
    bcfg: &BarrierConfig,
    model: &LinearModel,
    patterns: &[Vec<usize>],
    gamma: &[f64],
    safe_set_barriers: &[Arc<dyn Barrier>],
    gain: &GainChoice,
) -> Result<ProblemForm, RunError> {
    let file = &world.file;
    waypoints_inside(world, safe_set_barriers)?;
    if file.control.form == FormSpec::Paper {
        return Ok(ProblemForm::Paper);
    }
    let n = &file.control.nominal;
    let limit = file.control.input_limit.map(|l| Input::new(l, l));
    let mut t = TrackerConfig::turtlebot(file.goal.center, file.goal.radius, limit);
    let set = |slot: &mut f64, v: Option<f64>| {
        if let Some(v) = v {
            *slot = v;
        }
    };
    // default cruise: 90 % of the robot's speed limit (the tracker's own default for a point)
    if let Some(robot) = &world.robot {
        t.cruise_speed = 0.9 * robot.limits.v_max;
    }
    set(&mut t.cruise_speed, n.cruise_speed);
    set(&mut t.speed_gain, n.speed_gain);
    set(&mut t.arrive_accel, n.arrive_accel);
    set(&mut t.lookahead, n.lookahead);
    set(&mut t.smoothing, n.smoothing);
    set(&mut t.stall_progress, n.stall_progress);
    set(&mut t.stall_time, n.stall_time);
    set(&mut t.escape_time, n.escape_time);
    set(&mut t.escape_angle, n.escape_angle);
    if n.jerk_limit.is_some() {
        t.jerk_limit = n.jerk_limit;
    }
    let start = initial_estimate(world);
    // With κ chosen from the world, the path keeps where its rows hold the robot at rest; a
    // declared κ keeps the planner's default corridor (the catalogue's tuned worlds).
    let hold = match gain.source {
        GainSource::Auto { .. } => gain.hold_clearance,
        GainSource::Declared => HOLD_BAND,
    };
    t.waypoints = planned_path(world, bcfg, [start[0], start[1]], hold)?;
    // the tracker appends the goal itself
    t.waypoints.pop();
    let rest = rest_targets(world, model, patterns, gamma, safe_set_barriers, gain.kappa);
    for w in &mut t.waypoints {
        *w = viable_point(&rest, *w, None);
    }
    t.goal = viable_point(&rest, t.goal, Some(0.8 * file.goal.radius));
    // validate now, so a bad key is named with the file
    ftcbf_controller::PathTracker::new(t.clone(), [start[0], start[1]])
        .map_err(|e| setup_err(world, "control.nominal", e.to_string()))?;
    Ok(ProblemForm::SafetyFilter {
        tracker: t,
        clf: n.clf,
    })
}

/// Refuses a waypoint outside a safe set (h < 0 there at rest): the robot is to pass it, and the
/// safety filter keeps the robot out of that set, so it never could. (The tracker used to move
/// such a waypoint to the set's boundary without a word.)
fn waypoints_inside(world: &World, safe_sets: &[Arc<dyn Barrier>]) -> Result<(), RunError> {
    for (i, w) in world.file.goal.waypoints.iter().enumerate() {
        let at_rest = State::new(w[0], w[1], 0.0, 0.0);
        for b in safe_sets {
            let h = b.eval(&at_rest).value;
            if h.is_nan() || h < 0.0 {
                return Err(setup_err(
                    world,
                    &format!("goal.waypoints[{i}]"),
                    format!(
                        "({}, {}) is outside safe set `{}` (h = {h:.6} at rest there); expected a waypoint inside every safe set (h ≥ 0): the safety filter keeps the robot out, so it could never pass it",
                        w[0],
                        w[1],
                        b.name()
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// The points from the start to the goal (the goal last): `[goal] waypoints`, with legs
/// planned around the obstacles when `[goal] plan`, keeping [`HOLD_BAND`] beyond the margin, or
/// `hold` where the rows need more to hold the robot at rest (see [`GainChoice`]) and such a
/// path exists (else the [`HOLD_BAND`] path: `check`'s liveness prediction then judges it).
pub fn planned_path(
    world: &World,
    bcfg: &BarrierConfig,
    start: [f64; 2],
    hold: f64,
) -> Result<Vec<[f64; 2]>, RunError> {
    let goal = &world.file.goal;
    if !goal.plan || world.obstacles.is_empty() {
        let mut pts = goal.waypoints.clone();
        pts.push(goal.center);
        return Ok(pts);
    }
    // The path is planned around the obstacles that stand still (movers are avoided by their
    // rows as they come).
    let (barriers, boxes) = planner_barriers(world, bcfg);
    let clear = |p: [f64; 2]| nearest_clearance(&barriers, &boxes, bcfg.robot_radius, p);
    // The budget is in obstacle distance queries (far obstacles are not queried).
    let max_evaluations = PLANNER_QUERIES;
    let with = |band: f64| PlannerConfig {
        inflate: bcfg.margin + band,
        max_evaluations,
        ..PlannerConfig::default()
    };
    let over_budget = |e: crate::planner::BudgetExceeded| {
        let key = match goal.waypoints.get(e.leg) {
            Some(_) => format!("goal.waypoints[{}]", e.leg),
            None => "goal.center".to_string(),
        };
        setup_err(
            world,
            &key,
            format!(
                "{e} (an evaluation queries the obstacles whose bounding box could be nearest, of {}); expected a leg the planner can search: put waypoints closer together (in free space a leg only needs line of sight), or set `[goal] plan = false`",
                barriers.len(),
            ),
        )
    };
    if hold > HOLD_BAND {
        let p = plan_with_cost(start, &goal.waypoints, goal.center, &clear, &with(hold))
            .map_err(over_budget)?;
        if p.unplanned_legs == 0 {
            return Ok(p.points);
        }
    }
    let band = with(HOLD_BAND);
    let p =
        plan_with_cost(start, &goal.waypoints, goal.center, &clear, &band).map_err(over_budget)?;
    if p.unplanned_legs == 0 {
        return Ok(p.points);
    }
    // A leg without a route at the band's clearance takes the widest route there is (never a
    // straight line through an obstacle); `check` names its narrowest gap ([`route_notes`]).
    let mut stops = goal.waypoints.clone();
    stops.push(goal.center);
    let mut points = Vec::new();
    let mut from = start;
    for to in stops {
        match leg_route(from, to, &clear, &band).map_err(over_budget)? {
            Some(route) => points.extend(route),
            None => {
                // Over its budget the widest search leaves the leg straight; `check` says so.
                match widest_route(from, to, &clear, &widest_cfg(&band))
                    .ok()
                    .flatten()
                {
                    Some((path, _)) => points.extend(path.into_iter().skip(1)),
                    None => points.push(to),
                }
            }
        }
        from = to;
    }
    Ok(points)
}

/// Borders \[m\] a leg's grid reaches beyond its end points, tried in turn: a route around a
/// wall longer than the leg (the house's doorways) lies outside the default 2 m.
const LEG_BORDERS: [f64; 3] = [2.0, 4.0, 8.0];

/// The widest-route search's settings: the grid reaching the last of [`LEG_BORDERS`].
fn widest_cfg(cfg: &PlannerConfig) -> PlannerConfig {
    PlannerConfig {
        border: LEG_BORDERS[LEG_BORDERS.len() - 1],
        ..*cfg
    }
}

/// One leg planned with the grid reaching [`LEG_BORDERS`] in turn; `None` when none has a
/// route (the points after `from`, `to` last).
fn leg_route(
    from: [f64; 2],
    to: [f64; 2],
    clear: &dyn Fn([f64; 2]) -> (f64, u64),
    cfg: &PlannerConfig,
) -> Result<Option<Vec<[f64; 2]>>, crate::planner::BudgetExceeded> {
    for border in LEG_BORDERS {
        let c = PlannerConfig { border, ..*cfg };
        let p = plan_with_cost(from, &[], to, clear, &c)?;
        if p.unplanned_legs == 0 {
            return Ok(Some(p.points));
        }
    }
    Ok(None)
}

/// What `check` says about the route: for each leg with no route that keeps the planner's
/// clearance (obstacle margin + [`HOLD_BAND`]), the clearance the widest route keeps, where its
/// narrowest gap is and the two obstacles that make it, and the gap width this robot needs;
/// empty when every leg has a route (or the world does not plan).
pub fn route_notes(world: &World) -> Vec<String> {
    let goal = &world.file.goal;
    if !goal.plan || world.obstacles.is_empty() {
        return Vec::new();
    }
    let bcfg = obstacle_barrier_config(world);
    let (barriers, boxes) = planner_barriers(world, &bcfg);
    let clear = |p: [f64; 2]| nearest_clearance(&barriers, &boxes, bcfg.robot_radius, p);
    let cfg = PlannerConfig {
        inflate: bcfg.margin + HOLD_BAND,
        max_evaluations: PLANNER_QUERIES,
        ..PlannerConfig::default()
    };
    let start = initial_estimate(world);
    let mut stops = goal.waypoints.clone();
    stops.push(goal.center);
    let mut from = [start[0], start[1]];
    let mut out = Vec::new();
    for to in stops {
        match leg_route(from, to, &clear, &cfg) {
            Ok(Some(_)) => {}
            Ok(None) => out.push(no_route_note(&barriers, &bcfg, &cfg, from, to, &clear)),
            Err(_) => break,
        }
        from = to;
    }
    out
}

/// The note of one leg without a route (see [`route_notes`]).
fn no_route_note(
    barriers: &[crate::obstacles::ObstacleBarrier],
    bcfg: &BarrierConfig,
    cfg: &PlannerConfig,
    from: [f64; 2],
    to: [f64; 2],
    clear: &dyn Fn([f64; 2]) -> (f64, u64),
) -> String {
    let head = format!(
        "no route from ({:.2}, {:.2}) to ({:.2}, {:.2}) with clearance {:.3} m (obstacle_margin {:.3} + {HOLD_BAND} m); gaps narrower than {:.2} m are impassable for this robot with this clearance",
        from[0], from[1], to[0], to[1], cfg.inflate, bcfg.margin, 2.0 * (bcfg.robot_radius + cfg.inflate)
    );
    let widest = match widest_route(from, to, clear, &widest_cfg(cfg)) {
        Ok(Some(w)) => w,
        Ok(None) => return format!("{head}: none keeps the robot clear of the obstacles at all"),
        Err(e) => return format!("{head}; the widest route was not searched: {e}"),
    };
    let (path, kept) = widest;
    let mut worst = (f64::INFINITY, from);
    for seg in path.windows(2) {
        let n = ((seg[1][0] - seg[0][0]).hypot(seg[1][1] - seg[0][1]) / 0.02)
            .ceil()
            .max(1.0);
        for k in 0..=n as usize {
            let t = k as f64 / n;
            let q = [
                seg[0][0] + t * (seg[1][0] - seg[0][0]),
                seg[0][1] + t * (seg[1][1] - seg[0][1]),
            ];
            let c = clear(q).0;
            if c < worst.0 {
                worst = (c, q);
            }
        }
    }
    let q = nalgebra::Vector2::new(worst.1[0], worst.1[1]);
    let mut near: Vec<(f64, &str)> = barriers
        .iter()
        .map(|b| {
            let name = b.name();
            (
                b.clearance(q),
                name.strip_prefix("obstacle:").unwrap_or(name),
            )
        })
        .collect();
    near.sort_by(|a, b| a.0.total_cmp(&b.0));
    let names: Vec<&str> = near.iter().take(2).map(|n| n.1).collect();
    format!(
        "{head}; the widest route (grid reaching {} m beyond the leg) keeps {kept:.3} m, closest at ({:.2}, {:.2}), between {}",
        LEG_BORDERS[LEG_BORDERS.len() - 1],
        worst.1[0],
        worst.1[1],
        names.join(" and ")
    )
}

/// The barriers the planner plans against, of the obstacles that stand still — the controller's (an occupancy map's pieces, not
/// its field), so a route keeps the clearance the rows keep — with their bounding rectangles.
#[allow(clippy::type_complexity)]
pub fn planner_barriers(
    world: &World,
    bcfg: &BarrierConfig,
) -> (
    Vec<crate::obstacles::ObstacleBarrier>,
    Vec<Option<[f64; 4]>>,
) {
    let mut barriers = Vec::new();
    let mut boxes = Vec::new();
    for o in statics(world) {
        barriers.extend(o.barriers(bcfg));
        if o.outlines().is_empty() {
            boxes.push(planar_box(o));
        } else {
            boxes.extend(o.outlines().iter().map(|p| Some(p.bounds())));
        }
    }
    (barriers, boxes)
}

/// The world's obstacles that stand still (the planner's).
fn statics(world: &World) -> impl Iterator<Item = &crate::obstacles::Obstacle> {
    world.obstacles.iter().filter(|o| o.spec.motion.is_none())
}

/// An obstacle's bounding rectangle in the plane (x_min, y_min, x_max, y_max) \[m\], world
/// frame; `None` for a half-space (unbounded).
fn planar_box(o: &crate::obstacles::Obstacle) -> Option<[f64; 4]> {
    if o.is_half_space() {
        return None;
    }
    let b = o.shape().compute_aabb(o.shape_pose());
    let r = [b.mins.x, b.mins.y, b.maxs.x, b.maxs.y].map(f64::from);
    r.iter().all(|v| v.is_finite()).then_some(r)
}

/// The least robot-disc clearance over the obstacles at `p`, and how many were queried: an
/// obstacle whose bounding rectangle is farther (less the disc radius and 1 mm for parry's f32)
/// than the least clearance found so far cannot be nearer, so the obstacles are queried from the
/// nearest rectangle out until the next is farther than the best. The result is the minimum
/// over every obstacle, exactly.
fn nearest_clearance(
    barriers: &[crate::obstacles::ObstacleBarrier],
    boxes: &[Option<[f64; 4]>],
    robot_radius: f64,
    p: [f64; 2],
) -> (f64, u64) {
    let mut order: Vec<(f64, usize)> = boxes
        .iter()
        .enumerate()
        .map(|(i, b)| {
            let lower = b.map_or(f64::NEG_INFINITY, |b| {
                let dx = (b[0] - p[0]).max(p[0] - b[2]).max(0.0);
                let dy = (b[1] - p[1]).max(p[1] - b[3]).max(0.0);
                let d = dx.hypot(dy);
                if d > 0.0 {
                    d - robot_radius - 1e-3
                } else {
                    f64::NEG_INFINITY
                }
            });
            (lower, i)
        })
        .collect();
    order.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let mut best = f64::INFINITY;
    let mut queries = 0;
    for (lower, i) in order {
        if lower >= best {
            break;
        }
        queries += 1;
        best = best.min(barriers[i].clearance(nalgebra::Vector2::new(p[0], p[1])));
    }
    (best, queries)
}

/// The planner's work limit, in obstacle distance queries (one clearance evaluation queries
/// the obstacles whose bounding rectangle could hold the nearest, `nearest_clearance`; the
/// house of the ROBOTIS TurtleBot3 worlds has 68 obstacles a burger can touch): 2·10⁵. A query costs ~5 µs for a primitive and ~15 µs for a mesh, and a
/// world may plan twice (with the rows' stand-off, then the narrow band) in `check` and again in
/// `run`: a refused leg costs a few seconds of one core at most. The catalogue's largest plan
/// (doorway_clutter) makes 4,878 evaluations of 4 obstacles, 19,512 queries: 10 times below.
/// 2·10⁶ left 13 of 3,000 fuzz inputs with far waypoints past the fuzz's 30 s bound on a
/// loaded machine, 5·10⁵ one of 10,000 (a far leg blocked by an STL mesh: 7 s of CPU for
/// `check` alone).
pub const PLANNER_QUERIES: u64 = 200_000;

/// Which channels a filter that drops the fault patterns `drop` keeps.
pub fn channel_mask(q: usize, patterns: &[Vec<usize>], drop: &[usize]) -> Vec<bool> {
    let mut u = vec![true; q];
    for &pi in drop {
        for &c in &patterns[pi] {
            u[c] = false;
        }
    }
    u
}

/// Holding still against a half-plane: for the filter x̂_i that drops fault pattern i, the
/// smallest h(x̂_i) at which its CBF row holds with u = 0 at rest, h̄_γi + γ_i‖(K_i c̄_i)ᵀa‖/κ
/// (steady-state gain), and the standard deviation of h(x̂_i) − h(x), √(aᵀP_i a) (steady-state
/// posterior covariance). `ftcbf check` reports the first against the goal set; the safety
/// filter's tracker aims where both fit (see `viable_point`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RestHold {
    /// h̄_γ + γ‖(Kc̄)ᵀa‖/κ.
    pub needed_h: f64,
    /// √(aᵀ P a).
    pub sigma_h: f64,
}

/// [`RestHold`] of half-plane `a` (barrier `barrier`) for the filter dropping pattern `i`.
#[allow(clippy::too_many_arguments)]
pub fn rest_hold(
    world: &World,
    model: &LinearModel,
    patterns: &[Vec<usize>],
    gamma: f64,
    i: usize,
    barrier: &dyn Barrier,
    a: &State,
    kappa: f64,
) -> RestHold {
    let dt = world.control_dt();
    let mask = channel_mask(model.channels(), patterns, &[i]);
    let p = steady_state_riccati(model, &mask, dt).posterior;
    let kc = gain_product(model, &mask, &p, dt);
    RestHold {
        needed_h: barrier.h_bar(gamma) + gamma * (kc.transpose() * a).norm() / kappa,
        sigma_h: (a.transpose() * p * a)[0].max(0.0).sqrt(),
    }
}

/// Per half-plane safe set: its position normal (a_x, a_y), offset b, and the h the tracker
/// aims for at rest, max over the fault-pattern filters of needed_h + 3σ_h: there the honest
/// filter's row holds with u = 0 and its noise rarely makes it bind. `barriers` are the safe
/// sets' barriers, in `[[safe_sets]]` order.
fn rest_targets(
    world: &World,
    model: &LinearModel,
    patterns: &[Vec<usize>],
    gamma: &[f64],
    barriers: &[Arc<dyn Barrier>],
    kappa: f64,
) -> Vec<([f64; 2], f64, f64)> {
    let mut out = Vec::new();
    for (bi, s) in world.file.safe_sets.iter().enumerate() {
        if let SafeSetSpec::HalfPlane { a, b, .. } = s {
            let av = State::new(a[0], a[1], a[2], a[3]);
            let target = (0..patterns.len().min(gamma.len()))
                .map(|i| {
                    let r = rest_hold(
                        world,
                        model,
                        patterns,
                        gamma[i],
                        i,
                        &*barriers[bi],
                        &av,
                        kappa,
                    );
                    r.needed_h + 3.0 * r.sigma_h
                })
                .filter(|h| h.is_finite())
                .fold(f64::NEG_INFINITY, f64::max);
            if target.is_finite() && (a[0] != 0.0 || a[1] != 0.0) {
                out.push(([a[0], a[1]], *b, target));
            }
        }
    }
    out
}

/// `p` moved along each half-plane's position normal until h at rest reaches its target (see
/// [`rest_targets`]); with `cap`, by at most that distance in all (a goal stays inside its
/// ball). Without the move a goal a few centimetres inside a half-plane's robust band (the
/// paper's goal, 5 cm above the floor line) has the tracker push into the barrier row, which
/// then binds on the estimate's noise and the turn command chatters.
fn viable_point(rest: &[([f64; 2], f64, f64)], p: [f64; 2], cap: Option<f64>) -> [f64; 2] {
    let mut q = p;
    for &(n, b, target) in rest {
        let h = n[0] * q[0] + n[1] * q[1] - b;
        if h < target {
            let k = (target - h) / (n[0] * n[0] + n[1] * n[1]);
            q = [q[0] + k * n[0], q[1] + k * n[1]];
        }
    }
    if let Some(cap) = cap {
        let d = (q[0] - p[0]).hypot(q[1] - p[1]);
        if d > cap && d > 0.0 {
            q = [
                p[0] + (q[0] - p[0]) * cap / d,
                p[1] + (q[1] - p[1]) * cap / d,
            ];
        }
    }
    q
}

fn setup_err(world: &World, key: &str, message: String) -> RunError {
    RunError::Setup {
        world: world.path.display().to_string(),
        key: key.to_string(),
        message,
    }
}

/// The [`RunError`] of a world whose sensing structure the controller cannot take.
fn structure(world: &World) -> impl Fn(StructureError) -> RunError + '_ {
    move |e| setup_err(world, &e.key, e.message)
}

/// Where the filters' process noise enters, with the world's default (`isotropic` for the
/// linear plant, whose own noise it is; `acceleration` for a rapier robot).
pub fn process_model(world: &World) -> ProcessModel {
    world
        .file
        .control
        .process_model
        .unwrap_or(match world.file.dynamics {
            Dynamics::Linear => ProcessModel::Isotropic,
            Dynamics::Rapier => ProcessModel::Acceleration,
        })
}

/// Where the filters' process noise q came from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum NoiseSource {
    /// `[control] process_noise` in the world file.
    WorldFile,
    /// The linear plant's own noise, `[linear] process_noise`.
    LinearPlant,
    /// Identified from the robot's drive ([`super::identify`]).
    Identified(super::identify::DriveIdentification),
}

/// The filters' process-noise intensity q [(m/s²)²·s or unit²/s] and where it came from: the
/// world file's `[control] process_noise`, else the linear plant's own noise, else identified
/// from the robot's drive (a short run of the robot alone; see [`super::identify`]).
pub fn process_noise(world: &World) -> Result<(f64, NoiseSource), RunError> {
    let file = &world.file;
    if let Some(q) = file.control.process_noise {
        return Ok((q, NoiseSource::WorldFile));
    }
    match file.dynamics {
        Dynamics::Linear => Ok((
            file.linear.as_ref().map_or(1e-3, |l| l.process_noise),
            NoiseSource::LinearPlant,
        )),
        Dynamics::Rapier => {
            let id = super::identify::identify(world).map_err(|e| {
                setup_err(
                    world,
                    "control.process_noise",
                    format!("identifying the filters' process noise from the robot's drive: {e}"),
                )
            })?;
            Ok((id.q, NoiseSource::Identified(id)))
        }
    }
}

/// The filters' Q for intensity `q`: diag(0, 0, q, q) (white acceleration) or q·I₄ (the
/// paper's).
pub fn filter_process_noise(world: &World, q: f64) -> StateMatrix {
    match process_model(world) {
        ProcessModel::Isotropic => StateMatrix::identity() * q,
        ProcessModel::Acceleration => {
            StateMatrix::from_diagonal(&ftcbf_controller::State::new(0.0, 0.0, q, q))
        }
    }
}

/// The filters' initial covariance P0 = diag(σ_p², σ_p², σ_v², σ_v²) from `[control] initial_std`.
pub fn initial_covariance(world: &World) -> StateMatrix {
    let [sp, sv] = world.file.control.initial_std;
    StateMatrix::from_diagonal(&State::new(sp * sp, sp * sp, sv * sv, sv * sv))
}

/// γ_i, γ of the all-channel filter, θ_ij and δ: given, or computed per §4.3 (`auto`).
/// With dropouts on a filter channel, half of ε bounds the gaps ([`sensor_timing`]) and half the
/// estimation errors.
fn parameters(
    world: &World,
    model: &LinearModel,
    patterns: &[Vec<usize>],
    sensor_of_channel: &[usize],
) -> (FtParams, ParamSources) {
    let file = &world.file;
    let control_dt = world.control_dt();
    let horizon = world.horizon_ticks();
    let timing = sensor_timing(world, sensor_of_channel, horizon);
    let needs_auto =
        matches!(file.control.gamma, Param::Auto) || matches!(file.control.theta, Param::Auto);
    let computed = needs_auto.then(|| {
        FtComputed::compute_scheduled(
            model,
            patterns,
            control_dt,
            file.control.epsilon - timing.eps_gaps,
            horizon,
            &initial_covariance(world),
            match file.control.bounds {
                BoundsSpec::Horizon => BoundMethod::Horizon,
                BoundsSpec::Paper => BoundMethod::Paper,
            },
            &timing.schedule,
        )
    });
    // Computed where `auto` (all of it, or nothing when both are given), then the given values.
    let (mut ft, derivation) = match computed {
        Some(c) => (c.ft, Some(c.derivation)),
        None => (FtParams::default(), None),
    };
    if let Param::Value(g) = file.control.gamma {
        ft.gamma = vec![g; patterns.len()];
        ft.gamma_baseline = g;
    }
    if let Param::Value(t) = file.control.theta {
        // A given θ has no increment test and no θ_ij(t).
        ft = FtParams {
            theta: vec![t],
            eta: Vec::new(),
            increment_metric: Vec::new(),
            theta_schedule: None,
            ..ft
        };
    }
    let auto = match file.control.delta {
        Some(_) => None,
        None => auto_delta(world, &ft.theta, &ft.gamma),
    };
    let sources = ParamSources {
        delta: file.control.delta.or(auto).unwrap_or(f64::INFINITY),
        delta_auto: auto.is_some(),
        derivation,
        epsilon: file.control.epsilon,
        timing,
    };
    (ft, sources)
}

/// δ for a world that gives none and has an inside (arena) ellipse: Prop. 1 needs the estimates
/// whose rows are active to stay away from the centre, where Λ = k∇h = 0, so with δ = ∞ it
/// cannot hold ([`LiftedEllipse::prop1`]). Its proof takes any
/// δ < 1 − h̄ − 2k√λ̄·v_max − ½λ̄θ̄² (the lift's term included); this is half the smallest such
/// bound over the arenas, leaving the other half as the law of cosines' margin. `None` when the
/// world has no arena or no δ > 0 works (then `check` reports Prop. 1 failing).
pub fn auto_delta(world: &World, theta: &[f64], gamma: &[f64]) -> Option<f64> {
    let theta_bar = theta.iter().copied().fold(0.0_f64, f64::max);
    let bound = world
        .file
        .safe_sets
        .iter()
        .filter_map(|spec| lifted_ellipse(world, spec))
        .filter(LiftedEllipse::is_inside)
        .map(|e| {
            let h_bar = gamma.iter().map(|&g| e.h_bar(g)).fold(0.0_f64, f64::max);
            let full = e.prop1(theta_bar, h_bar, 0.0, 0.0);
            // z_min² at δ = 0 is 1 − h̄ − 2k√λ̄·v_max; δ may take what exceeds ½λ̄θ̄²
            full.z_min_sq - 0.5 * full.lambda_max * theta_bar * theta_bar
        })
        .reduce(f64::min)?;
    (bound > 0.0 && bound.is_finite()).then_some(0.5 * bound)
}

/// The filters' initial estimate: the linear plant's x0, or the robot's start at rest.
fn initial_estimate(world: &World) -> State {
    let file = &world.file;
    let (start_x, start_y) = match (&file.robot, &file.linear) {
        (Some(r), _) => (r.start.x, r.start.y),
        (None, Some(l)) => (l.x0[0], l.x0[1]),
        (None, None) => (0.0, 0.0),
    };
    match &file.linear {
        Some(l) => State::new(l.x0[0], l.x0[1], l.x0[2], l.x0[3]),
        None => State::new(start_x, start_y, 0.0, 0.0),
    }
}

/// The CLF: the world's ρ, and V̄ given or derived from the goal radius.
fn clf_config(world: &World, model: &LinearModel, goal: State) -> Result<ClfConfig, RunError> {
    let file = &world.file;
    let mut clf = ClfConfig::paper(0.0);
    clf.rho = file.control.clf.rho;
    clf.v_bar = match file.control.clf.v_bar {
        Some(v) => v,
        None => {
            // The largest V-level set inside the goal ball ‖x − x_g‖ ≤ d: inside it the CLF
            // rows rest (Y_t(V̄) of §5.1). With noise the stochastic CLF condition (5.1)
            // cannot hold at the goal itself (its Itô term is a positive constant while
            // ∇V → 0), so without a V̄ > 0 the rows would demand ever larger inputs there.
            let v = QuadraticClf::new(&model.f, &model.g, goal, file.goal.radius, &clf)
                .map_err(|e| setup_err(world, "control.clf", e.to_string()))?;
            v.p_d.symmetric_eigenvalues().min() * file.goal.radius * file.goal.radius
        }
    };
    Ok(clf)
}
