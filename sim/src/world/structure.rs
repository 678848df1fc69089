//! The world's sensing structure, derived from its sensors and fault patterns once it is
//! validated: which controller channels the linear model observes and how each is made from its
//! sensor's samples, the fault patterns as controller channels, the worst-case sensor timing,
//! the speed and turn-rate bounds, and the obstacle barriers' geometry settings.
//! [`World::load`](super::World::load) refuses a world whose structure the controller cannot
//! take ([`check_structure`]), so `check` and `run` refuse the same worlds, naming the user's
//! key; the model ([`crate::model`]) builds the controller's configuration on it.

use ftcbf_controller::odometry;
use ftcbf_controller::params::UpdateSchedule;
use nalgebra::RowVector4;

use crate::obstacles::BarrierConfig;
use crate::sensors::Quantity;

use super::{SafeSetSpec, World};

/// Variance floor for a channel declared noise-free, so R stays invertible \[unit²\].
pub const MIN_VARIANCE: f64 = 1e-8;

/// A world whose sensing structure the controller cannot take: the key to fix and what is
/// wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("`{key}`: {message}")]
pub struct StructureError {
    /// Key path.
    pub key: String,
    /// What is wrong.
    pub message: String,
}

fn structure_err(key: &str, message: String) -> StructureError {
    StructureError {
        key: key.to_string(),
        message,
    }
}

/// One filter channel's worst-case update schedule ([`sensor_timing`]).
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelTiming {
    /// The controller channel.
    pub channel: usize,
    /// The sensor whose samples time it (for a channel derived from wheels, the wheel whose
    /// worst gap is shortest).
    pub sensor: usize,
    /// Control ticks between its samples, ⌈1/(rate·dt)⌉ (1: every tick).
    pub period: usize,
    /// Probability a due sample is lost.
    pub dropout: f64,
    /// Consecutive lost samples the run's gap budget allows.
    pub missed: usize,
    /// Ticks between updates in the worst case, `period·(missed + 1)`; 0: never (every sample
    /// lost, or the gap is longer than the run).
    pub every: usize,
}

/// The filter channels' update schedule γ, θ and η are computed for, and the share of ε it takes.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SensorTiming {
    /// Per controller channel.
    pub channels: Vec<ChannelTiming>,
    /// The share of ε spent on gaps longer than allowed (0 without dropouts; else ε/2).
    pub eps_gaps: f64,
    /// The sensors with dropouts the gap budget is split over.
    pub lossy_sensors: usize,
    /// The schedule handed to the Riccati recursions.
    pub schedule: UpdateSchedule,
}

impl SensorTiming {
    /// Whether every filter channel reads every tick (γ, θ, η are then the paper's).
    pub fn every_tick(&self) -> bool {
        self.channels.iter().all(|c| c.every == 1)
    }
}

/// The worst-case update schedule of the filter channels over a run of `horizon` ticks. A sensor
/// at `rate_hz` is sampled every `period = ⌈1/(rate·dt)⌉` ticks (the longer gap of a rate that is
/// not a whole number of ticks); with `dropout_prob` p > 0 each due sample is lost independently,
/// so n + 1 consecutive losses somewhere among its N = ⌈horizon/period⌉ slots have probability at
/// most N·p^(n+1) (a union bound over the first slot lost). Half of ε goes to these events, split
/// evenly over the D sensors with dropouts: `missed` is the smallest n with N·p^(n+1) ≤ ε/(2D),
/// and the channel is modelled as updating every `period·(n + 1)` ticks (all its updates spaced by
/// the longest gap: fewer updates than any run outside the ε/2 event). The other half of ε is what
/// γ, θ and η are computed for. A channel derived from wheel channels (`from_wheels`) is fresh when
/// either wheel is, so it takes the shorter of their worst gaps.
pub fn sensor_timing(world: &World, sensor_of_channel: &[usize], horizon: usize) -> SensorTiming {
    let sensors = &world.file.sensors;
    let lossy = lossy_sensors(world, sensor_of_channel);
    let eps = world.file.control.epsilon;
    let eps_gaps = if lossy.is_empty() { 0.0 } else { eps / 2.0 };
    let timing_of = |channel: usize, t: usize| -> ChannelTiming {
        let (period, missed, every) = sample_gaps(world, t, horizon, lossy.len());
        ChannelTiming {
            channel,
            sensor: t,
            period,
            dropout: sensors[t].dropout_prob,
            missed: missed.unwrap_or(usize::MAX),
            every,
        }
    };
    let channels: Vec<ChannelTiming> = sensor_of_channel
        .iter()
        .enumerate()
        .map(|(c, &si)| {
            sampled_by(sensors, si)
                .into_iter()
                .map(|t| timing_of(c, t))
                .min_by_key(|t| if t.every == 0 { usize::MAX } else { t.every })
                .unwrap_or_else(|| timing_of(c, si))
        })
        .collect();
    let schedule = if channels.iter().all(|c| c.every == 1) {
        UpdateSchedule::every_step()
    } else {
        UpdateSchedule {
            every: channels.iter().map(|c| c.every).collect(),
        }
    };
    SensorTiming {
        channels,
        eps_gaps,
        lossy_sensors: lossy.len(),
        schedule,
    }
}

/// The sensors whose samples a channel of sensor `si` is fresh with: both wheels of odometry
/// derived from wheels (`from_wheels`), else the sensor itself.
fn sampled_by(sensors: &[crate::sensors::ChannelSpec], si: usize) -> Vec<usize> {
    crate::sensors::wheel_sources(sensors, si).map_or(vec![si], |w| w.to_vec())
}

/// The sensors whose dropouts the gap budget of [`sensor_timing`] covers: every sensor a filter
/// channel is read from (both wheels of one derived from wheels) and, when a channel turns a
/// speed into world-frame velocity, the heading channel it is turned with (a lost heading sample
/// leaves the conversion with an older one).
fn lossy_sensors(world: &World, sensor_of_channel: &[usize]) -> Vec<usize> {
    let sensors = &world.file.sensors;
    let converts = sensor_of_channel
        .iter()
        .any(|&si| sensors[si].world_velocity);
    let mut lossy: Vec<usize> = sensor_of_channel
        .iter()
        .flat_map(|&si| sampled_by(sensors, si))
        .chain(heading_sensor(world).filter(|_| converts))
        .filter(|&t| sensors[t].dropout_prob > 0.0)
        .collect();
    lossy.sort_unstable();
    lossy.dedup();
    lossy
}

/// Sensor `t`'s worst-case sampling over `horizon` ticks when the gap budget (ε/2) is split over
/// `lossy` sensors with dropouts ([`sensor_timing`]): (ticks between its samples, the consecutive
/// losses the budget allows — `None`: unbounded —, ticks between fresh samples in the worst case,
/// 0 for never).
fn sample_gaps(
    world: &World,
    t: usize,
    horizon: usize,
    lossy: usize,
) -> (usize, Option<usize>, usize) {
    let s = &world.file.sensors[t];
    let dt = world.control_dt();
    let per_sensor = world.file.control.epsilon / 2.0 / lossy.max(1) as f64;
    let period = s
        .rate_hz
        .map_or(1, |r| ((1.0 / (r * dt)) - 1e-9).ceil().max(1.0) as usize);
    let slots = horizon.div_ceil(period).max(1) as f64;
    let p = s.dropout_prob;
    let missed = if p <= 0.0 {
        Some(0)
    } else if p >= 1.0 {
        None
    } else {
        // Smallest n with slots·p^(n+1) ≤ per_sensor.
        let n = ((per_sensor / slots).ln() / p.ln() - 1.0).ceil().max(0.0);
        (n.is_finite() && n < horizon as f64).then_some(n as usize)
    };
    let every = missed
        .map(|n| period.saturating_mul(n + 1))
        .filter(|&e| e == 1 || e <= horizon)
        .unwrap_or(0);
    (period, missed, every)
}

/// How old the heading a speed channel is turned into world-frame velocity with can be, in the
/// worst case the gap budget allows ([`sensor_timing`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeadingHold {
    /// The heading sensor.
    pub sensor: usize,
    /// Control ticks between its fresh samples in the worst case (0: never).
    pub every: usize,
    /// Without gyro fusion, the age \[s\] of the held sample the conversion uses at worst,
    /// (every − 1)·dt (∞ for never); with fusion 0 (the filter propagates the yaw with the gyro
    /// between compass readings, and [`odometry::fused_yaw_variance`] covers that).
    pub age: f64,
    /// Whether the heading is fused with a gyro.
    pub fused: bool,
}

/// The heading channel's worst-case hold when some channel converts a speed with it.
pub fn heading_hold(world: &World) -> Option<HeadingHold> {
    let sensors = &world.file.sensors;
    let h = heading_sensor(world)?;
    let channel_sensors: Vec<usize> = (0..sensors.len())
        .filter(|&si| sensors[si].world_velocity || observation_row(sensors[si].measures).is_some())
        .collect();
    if !channel_sensors.iter().any(|&si| sensors[si].world_velocity) {
        return None;
    }
    let lossy = lossy_sensors(world, &channel_sensors).len();
    let (_, _, every) = sample_gaps(world, h, world.horizon_ticks(), lossy);
    let fused = heading_fusion(world).is_some();
    let age = match (fused, every) {
        (true, _) => 0.0,
        (false, 0) => f64::INFINITY,
        (false, e) => (e - 1) as f64 * world.control_dt(),
    };
    Some(HeadingHold {
        sensor: h,
        every,
        age,
        fused,
    })
}

/// The robot's turn-rate bound \[rad/s\] (its drive limits), if it has one.
pub fn turn_rate_bound(world: &World) -> Option<f64> {
    world.robot.as_ref().map(|r| r.limits.omega_max)
}

/// The planar-state row of a sensed quantity, if the linear model observes it.
fn observation_row(q: Quantity) -> Option<RowVector4<f64>> {
    match q {
        Quantity::X => Some(RowVector4::new(1.0, 0.0, 0.0, 0.0)),
        Quantity::Y => Some(RowVector4::new(0.0, 1.0, 0.0, 0.0)),
        Quantity::Vx => Some(RowVector4::new(0.0, 0.0, 1.0, 0.0)),
        Quantity::Vy => Some(RowVector4::new(0.0, 0.0, 0.0, 1.0)),
        Quantity::Heading
        | Quantity::Speed
        | Quantity::YawRate
        | Quantity::WheelLeft
        | Quantity::WheelRight => None,
    }
}

/// The speed bound the h̄_γ bounds of lifted barriers rest on [m/s]: the robot's limit, or
/// `[linear] v_max` for the linear plant (which has no limit of its own). `None` when the world
/// gives none; [`ControlSetup::new`](crate::model::setup::ControlSetup::new) refuses a world whose barriers need it.
pub fn speed_bound(world: &World) -> Option<f64> {
    match &world.robot {
        Some(r) => Some(r.limits.v_max),
        None => world.file.linear.as_ref().and_then(|l| l.v_max),
    }
}

/// The obstacle barriers' geometry settings for this world's robot (a point for `linear`, with
/// v_max = `[linear] v_max`, or 0 when not given — see [`speed_bound`]).
pub fn obstacle_barrier_config(world: &World) -> BarrierConfig {
    let c = &world.file.control;
    match &world.robot {
        Some(robot) => BarrierConfig::for_robot(robot, c.obstacle_margin, c.obstacle_lift),
        None => BarrierConfig {
            robot_radius: 0.0,
            centre_height: 0.0,
            margin: c.obstacle_margin,
            k: c.obstacle_lift,
            v_max: speed_bound(world).unwrap_or(0.0),
            fd_step: 2e-3,
        },
    }
}

/// Refuse a world whose h̄_γ bounds would rest on an invented number: a lifted barrier without
/// a speed bound, or a point robot's lifted barrier on a shape with edges (no curvature bound).
pub(crate) fn check_h_bar_inputs(
    world: &World,
    bcfg: &BarrierConfig,
) -> Result<(), StructureError> {
    let file = &world.file;
    let needs_speed = |what: String| {
        structure_err("linear.v_max",
            format!(
                "{what} has an h̄_γ bound that depends on the speed, and the linear plant has no speed limit of its own; give one in [linear] as `v_max = …` [m/s]"
            ),
        )
    };
    if speed_bound(world).is_none() {
        for (i, s) in file.safe_sets.iter().enumerate() {
            if let SafeSetSpec::EllipseInside { lift, .. }
            | SafeSetSpec::EllipseOutside { lift, .. } = s
            {
                if *lift > 0.0 {
                    return Err(needs_speed(format!(
                        "safe_sets[{i}] (an ellipse with lift = {lift} s)"
                    )));
                }
            }
        }
    }
    if bcfg.k > 0.0 {
        for (i, ob) in world.obstacles.iter().enumerate() {
            if ob.is_half_space() {
                continue;
            }
            if speed_bound(world).is_none() {
                return Err(needs_speed(format!(
                    "obstacles[{i}] (`{}`, lifted with control.obstacle_lift = {} s)",
                    ob.name, bcfg.k
                )));
            }
            if ob.barrier(bcfg).curvature_bound().is_none() {
                return Err(structure_err(
                    &format!("obstacles[{i}].shape"),
                    format!(
                        "obstacle `{}` is a {}: for a point robot (dynamics = \"linear\") the \
                         distance to its edges and vertices has unbounded curvature, so its \
                         lifted barrier (control.obstacle_lift = {} s) has no h̄_γ bound; use a \
                         ball, a vertical cylinder or capsule, or a half_space, set \
                         control.obstacle_lift = 0, or simulate a robot (dynamics = \"rapier\")",
                        ob.name,
                        ob.spec.shape.kind(),
                        bcfg.k
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// What the controller needs of the world's structure, decided without computing anything
/// costly (no Riccati, no planning): the channels the linear model observes, the fault patterns
/// as controller channels — disjoint in effect, a sensor taking along every channel its readings
/// flow into — and the inputs of the h̄_γ bounds. [`World::load`](crate::world::World::load)
/// runs it, so `check` and `run` refuse the same worlds, naming the user's key.
pub fn check_structure(world: &World) -> Result<(), StructureError> {
    let ch = Channels::of(world)?;
    model_patterns(world, &ch.channels_of_sensor)?;
    check_h_bar_inputs(world, &obstacle_barrier_config(world))
}

/// The heading channel (the first sensor that measures `heading`): the drive linearises about
/// it, and `speed` channels with `world_velocity` are turned into world-frame velocity with it.
pub fn heading_sensor(world: &World) -> Option<usize> {
    world
        .file
        .sensors
        .iter()
        .position(|s| s.measures == Quantity::Heading)
}

/// The heading channel's gyro fusion (`gyro` on the heading channel): the gyro's index and the
/// filter's parameters from the two channels' specs.
pub fn heading_fusion(world: &World) -> Option<(usize, odometry::HeadingFilterParams)> {
    let sensors = &world.file.sensors;
    let h = &sensors[heading_sensor(world)?];
    let g = sensors
        .iter()
        .position(|s| Some(&s.name) == h.gyro.as_ref())?;
    let gyro = &sensors[g];
    Some((
        g,
        odometry::HeadingFilterParams {
            initial_yaw_std: START_YAW_STD,
            ..odometry::HeadingFilterParams::new(gyro.noise_std, gyro.bias_walk_std, h.noise_std)
        },
    ))
}

/// 1σ of the start yaw the heading filter is given \[rad\] (0.6°): the run starts at the world's
/// marked start pose, as the filters' `initial_std` assumes for the position.
pub const START_YAW_STD: f64 = 0.01;

/// How a controller channel's value comes from its sensor's sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Conversion {
    /// The sample itself (x, y, vx, vy).
    Direct,
    /// v·cos θ̂ of a `speed` channel with `world_velocity`, θ̂ the heading channel's sample.
    SpeedX,
    /// v·sin θ̂.
    SpeedY,
}

impl Conversion {
    /// The channel's value from its sensor's sample `v` and the heading sample `theta` \[rad\].
    pub fn apply(self, v: f64, theta: f64) -> f64 {
        match self {
            Conversion::Direct => v,
            Conversion::SpeedX => odometry::body_speed_to_world_velocity(v, theta)[0],
            Conversion::SpeedY => odometry::body_speed_to_world_velocity(v, theta)[1],
        }
    }
}

/// The channels the linear model observes, in sensor order.
pub(crate) struct Channels {
    pub(crate) c_rows: Vec<RowVector4<f64>>,
    pub(crate) r: Vec<f64>,
    pub(crate) sensor_of_channel: Vec<usize>,
    pub(crate) channels_of_sensor: Vec<Vec<usize>>,
    pub(crate) conversion: Vec<Conversion>,
}

impl Channels {
    pub(crate) fn of(world: &World) -> Result<Self, StructureError> {
        let sensors = &world.file.sensors;
        let mut ch = Channels {
            c_rows: Vec::new(),
            r: Vec::new(),
            sensor_of_channel: Vec::new(),
            channels_of_sensor: vec![Vec::new(); sensors.len()],
            conversion: Vec::new(),
        };
        let push = |ch: &mut Channels, si: usize, row: RowVector4<f64>, r: f64, c: Conversion| {
            ch.channels_of_sensor[si].push(ch.c_rows.len());
            ch.sensor_of_channel.push(si);
            ch.c_rows.push(row);
            ch.r.push(r.max(MIN_VARIANCE));
            ch.conversion.push(c);
        };
        for (si, s) in sensors.iter().enumerate() {
            if s.world_velocity {
                let r = speed_conversion_variance(world, si)?;
                push(
                    &mut ch,
                    si,
                    RowVector4::new(0.0, 0.0, 1.0, 0.0),
                    r,
                    Conversion::SpeedX,
                );
                push(
                    &mut ch,
                    si,
                    RowVector4::new(0.0, 0.0, 0.0, 1.0),
                    r,
                    Conversion::SpeedY,
                );
            } else if let Some(row) = observation_row(s.measures) {
                push(
                    &mut ch,
                    si,
                    row,
                    s.noise_std * s.noise_std,
                    Conversion::Direct,
                );
            }
        }
        Ok(ch)
    }
}

/// The variance of v·cos θ̂ (and of v·sin θ̂) for the `speed` channel `si` with
/// `world_velocity`: σ_v² + v_max²·(σ_θ² + b_θ² + w_θ²·T), with the heading channel's noise σ_θ,
/// bias b_θ and bias walk w_θ over the run's duration T. For a robot without sideslip the
/// converted velocity's error is e_v·(cos θ̂, sin θ̂) + v·e_θ·(−sin θ, cos θ) to first order, so
/// each axis' error is bounded by that; the heading bias enters as if it were noise (a
/// conservative bound, not a white-noise model of it).
fn speed_conversion_variance(world: &World, si: usize) -> Result<f64, StructureError> {
    let sensors = &world.file.sensors;
    let s = &sensors[si];
    let key = format!("sensors[{si}].world_velocity");
    if s.measures != Quantity::Speed {
        return Err(structure_err(&key,
            format!(
                "channel \"{}\" measures {}; only a `speed` channel (body-frame forward speed) can be converted to world-frame velocity",
                s.name,
                s.measures.as_str()
            ),
        ));
    }
    let Some(h) = heading_sensor(world).map(|h| &sensors[h]) else {
        return Err(structure_err(&key,
            format!(
                "channel \"{}\" needs a heading channel (`measures = \"heading\"`, e.g. a compass or the IMU's yaw) to turn its speed into world-frame velocity",
                s.name
            ),
        ));
    };
    let Some(v_max) = speed_bound(world) else {
        return Err(structure_err(
            &key,
            "the conversion's variance needs a speed bound: give [linear] v_max".to_string(),
        ));
    };
    let hold = heading_hold(world);
    let yaw_std = match heading_fusion(world) {
        None => {
            // A held sample is up to `age` old: the robot may have turned ω_max·age since.
            let age = hold.map_or(0.0, |h| h.age);
            let stale = if age > 0.0 {
                let Some(omega_max) = turn_rate_bound(world) else {
                    return Err(structure_err(&key,
                        format!(
                            "heading channel \"{}\" is read every {age:.3} s at worst, and the conversion's variance needs a turn-rate bound for the robot's turn in between: give a robot with drive limits, or read the heading every control step",
                            h.name
                        ),
                    ));
                };
                omega_max * age
            } else {
                0.0
            };
            h.noise_std.hypot(stale)
        }
        Some((_, params)) => {
            let dt = world.control_dt();
            // Never a fresh compass reading: only the start's (`usize::MAX` ticks apart).
            let every = hold.map_or(1, |h| if h.every == 0 { usize::MAX } else { h.every });
            let a_max = world
                .file
                .control
                .input_limit
                .map_or(f64::INFINITY, |u| std::f64::consts::SQRT_2 * u);
            odometry::fused_yaw_variance(params, dt, every, world.file.duration, v_max, a_max)
                .sqrt()
        }
    };
    Ok(odometry::world_velocity_variance(
        speed_std(world, si),
        v_max,
        yaw_std,
        h.bias,
        h.bias_walk_std,
        world.file.duration,
    ))
}

/// The noise σ [m/s] of a `speed` channel: its own, plus for one derived from wheel channels
/// (`from_wheels`) the wheels' noise and quantisation carried through v = r(ω_l + ω_r)/2. A
/// count-difference reading's error is the difference of two uniform rounding errors: variance
/// q²/6 for the step q = 2π/(N·T_s).
pub fn speed_std(world: &World, si: usize) -> f64 {
    let sensors = &world.file.sensors;
    let own = sensors[si].noise_std;
    let (Some(pair), Some(robot)) = (
        crate::sensors::wheel_sources(sensors, si),
        world.robot.as_ref(),
    ) else {
        return own;
    };
    let r = robot.wheels.geometry.radius;
    let dt = world.control_dt();
    let wheel_var = |w: &crate::sensors::ChannelSpec| {
        let quant = w.ticks_per_rev.map_or(0.0, |n| {
            let period = w.rate_hz.map_or(dt, |hz| (1.0 / hz).max(dt));
            (std::f64::consts::TAU / (f64::from(n) * period)).powi(2) / 6.0
        });
        w.noise_std * w.noise_std + quant
    };
    let var = own * own + 0.25 * r * r * pair.iter().map(|&w| wheel_var(&sensors[w])).sum::<f64>();
    var.sqrt()
}

/// The sensors a sensor's readings flow into, itself included: a wheel channel into the odometry
/// derived from it (`from_wheels`), the heading channel and its fused gyro into every `speed`
/// channel turned into world-frame velocity with the yaw.
pub fn sensor_dependents(world: &World, si: usize) -> Vec<usize> {
    let sensors = &world.file.sensors;
    let mut out = vec![si];
    let heading = heading_sensor(world);
    let gyro = heading_fusion(world).map(|(g, _)| g);
    let feeds_yaw = Some(si) == heading || Some(si) == gyro;
    for (d, s) in sensors.iter().enumerate() {
        let from_wheel = crate::sensors::wheel_sources(sensors, d).is_some_and(|w| w.contains(&si));
        if d != si && (from_wheel || (feeds_yaw && s.world_velocity)) {
            out.push(d);
        }
    }
    out
}

/// The world's fault patterns as controller channel indices: a sensor in a pattern takes along
/// every controller channel its readings flow into ([`sensor_dependents`]).
pub(crate) fn model_patterns(
    world: &World,
    channels_of_sensor: &[Vec<usize>],
) -> Result<Vec<Vec<usize>>, StructureError> {
    let sensors = &world.file.sensors;
    let mut patterns: Vec<Vec<usize>> = Vec::with_capacity(world.patterns.len());
    for (pi, p) in world.patterns.iter().enumerate() {
        let mut mapped: Vec<usize> = Vec::with_capacity(p.len());
        for &si in p {
            let dependents = sensor_dependents(world, si);
            let feeds = dependents
                .iter()
                .any(|&d| !channels_of_sensor[d].is_empty());
            if !feeds && sensors[si].measures != Quantity::Heading {
                return Err(structure_err(&format!("fault_patterns[{pi}].channels"),
                    format!(
                        "channel \"{}\" measures {}, and nothing the controller's linear model uses is made from it; \
                         fault patterns may hold x, y, vx and vy channels, a speed channel with \
                         `world_velocity = true`, the wheel channels it is derived from (`from_wheels`), \
                         and the heading channel and gyro those use",
                        sensors[si].name,
                        sensors[si].measures.as_str()
                    ),
                ));
            }
            for d in dependents {
                for &c in &channels_of_sensor[d] {
                    if !mapped.contains(&c) {
                        mapped.push(c);
                    }
                }
            }
        }
        // A sensor takes along every channel its readings flow into, so two patterns that are
        // disjoint as written can share a controller channel (a wheel channel in one, the
        // odometry made from it in another): refused here, naming both, as the controller would.
        for (pj, earlier) in patterns.iter().enumerate() {
            if let Some(&c) = mapped.iter().find(|c| earlier.contains(c)) {
                let sensor = channels_of_sensor
                    .iter()
                    .position(|cs| cs.contains(&c))
                    .map_or("?", |s| sensors[s].name.as_str());
                let pname = |i: usize| {
                    world
                        .file
                        .fault_patterns
                        .get(i)
                        .map_or(format!("#{i}"), |p| format!("\"{}\"", p.name))
                };
                return Err(structure_err(&format!("fault_patterns[{pi}].channels"),
                    format!(
                        "fault patterns {} (fault_patterns[{pj}]) and {} both reach the controller channel of \"{sensor}\" \
                         (a sensor in a pattern takes along every channel made from its readings: odometry from wheel \
                         channels, world velocity from the heading); patterns must be disjoint in effect (§3.1) — put those sensors in one pattern",
                        pname(pj),
                        pname(pi)
                    ),
                ));
            }
        }
        patterns.push(mapped);
    }
    Ok(patterns)
}

/// Declared attacks that touch more than one fault pattern (or a sensor in none): Theorem 3
/// covers one pattern at a time.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("the declared attacks touch {}; Theorem 3 covers one fault pattern at a time", .touched.join(" and "))]
pub struct AttacksAcrossPatterns {
    /// The fault patterns touched, by name, in the order the attacked sensors are declared; a
    /// sensor in no pattern as `name (in no pattern)`.
    pub touched: Vec<String>,
    /// The first pattern (index in `[[fault_patterns]]`) holding an attacked sensor, if any.
    pub first: Option<usize>,
}

/// The fault pattern the declared attacks lie in: the one (index in `[[fault_patterns]]`) whose
/// sensors contain every attacked sensor; `Ok(None)` without attacks. The one definition of
/// "the attacked pattern": `check` states it as a hypothesis, liveness places the spoofed
/// estimates with it (falling back to [`AttacksAcrossPatterns::first`]).
pub fn attacked_pattern(world: &World) -> Result<Option<usize>, AttacksAcrossPatterns> {
    let sensors = &world.file.sensors;
    let mut attacked: Vec<usize> = Vec::new();
    for c in world.file.attacks.iter().flat_map(|a| &a.channels) {
        if let Some(i) = sensors.iter().position(|s| &s.name == c) {
            if !attacked.contains(&i) {
                attacked.push(i);
            }
        }
    }
    if attacked.is_empty() {
        return Ok(None);
    }
    if let Some(pi) = (world.patterns.iter()).position(|p| attacked.iter().all(|c| p.contains(c))) {
        return Ok(Some(pi));
    }
    let mut touched: Vec<String> = Vec::new();
    for &c in &attacked {
        let name = match world.patterns.iter().position(|p| p.contains(&c)) {
            Some(pi) => world.file.fault_patterns[pi].name.clone(),
            None => format!("{} (in no pattern)", sensors[c].name),
        };
        if !touched.contains(&name) {
            touched.push(name);
        }
    }
    let first = (world.patterns.iter()).position(|p| attacked.iter().any(|c| p.contains(c)));
    Err(AttacksAcrossPatterns { touched, first })
}
