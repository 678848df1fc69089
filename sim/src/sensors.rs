//! Redundant sensor channels: what the robot's sensors report about the truth, before any attack.
//!
//! A [`SensorSuite`] is an ordered list of channels. Each channel measures one scalar component of
//! the [`TruthState`] ([`Quantity`]: world-frame position x, y, world-frame velocity ẋ, ẏ, heading θ,
//! forward body speed v, yaw rate ω) and corrupts it the way a real sensor does:
//!
//! * additive zero-mean Gaussian noise with standard deviation `noise_std`;
//! * a constant `bias`;
//! * a bias random walk (Gazebo-style): the walk `b(t)` is a Wiener process with intensity
//!   `bias_walk_std` [unit/√s], so `Var b(t) = bias_walk_std² · (t − t₀)` where `t₀` is the channel's
//!   first sample;
//! * a sample rate `rate_hz` (absent: a sample every control tick). Between samples the consumer
//!   keeps seeing the last sample with `fresh = false` and its `age`;
//! * a `dropout_prob`: each due sample is lost with this probability (the last sample is held).
//!
//! Wheel encoders (`wheel_left`, `wheel_right`) read the rapier wheel joints, so they turn while a
//! wheel slips; with `ticks_per_rev` they count whole encoder steps. A `speed` or `yaw_rate`
//! channel with `from_wheels` is computed from two wheel channels' readings (diff-drive
//! kinematics, [`WheelGeometry::odometry`]) after they are sampled, and
//! [`SensorSuite::propagate_attacks`] carries an attack on an encoder into it.
//!
//! The suite of eq. 6.5 of the thesis (x, x, y, y, ẋ, ẏ, plus an attack-free heading) is one
//! instance; suites with more redundancy (three position fixes per axis) are others.
//!
//! # Timing
//! The suite is built with the control period `dt`. [`SensorSuite::sample`] is called once per
//! control tick; the tick index is `k = round(truth.t / dt)`, and every schedule decision is integer
//! arithmetic on `k`: a channel whose period is an integer number `p` of ticks (10 Hz in a 50 Hz loop:
//! `p = 5`) takes its samples at the ticks `k ≡ 0 (mod p)`, i.e. at t = 0, 0.1, 0.2, … exactly. A
//! channel whose period is not a whole number of ticks (30 Hz in a 50 Hz loop) takes sample number
//! `n = ⌊k·dt·rate + 10⁻⁹⌋` at the first tick at or after its nominal time `n / rate`; a channel at
//! least as fast as the loop samples every tick. The very first call always delivers a sample (unless
//! it is dropped). `age = (k − k_sample) · dt`.
//!
//! # Reproducibility
//! Each channel draws from its own ChaCha20 stream: key from the run seed, stream number from a
//! stable 64-bit FNV-1a hash of the channel NAME (see [`stream_rng`]). Adding, removing or
//! reordering channels therefore never changes another channel's noise. Every due sample draws, in
//! this order and whatever the configuration, one uniform (dropout) and two standard normals
//! (measurement noise, bias-walk increment), so changing `dropout_prob` or `bias_walk_std` leaves the
//! measurement-noise sequence of the channel unchanged.

use std::collections::HashMap;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha20Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};
use thiserror::Error;

pub use ftcbf_controller::odometry::wrap_angle;

use crate::robot::WheelGeometry;
use crate::state::TruthState;

/// Tolerance added before flooring a sample-slot number, so that `k·dt·rate` computed in floating
/// point (e.g. 2.9999999999999996 for an exact 3) lands on the intended slot.
const SLOT_EPS: f64 = 1e-9;

/// The scalar quantity a channel measures. TOML: `x | y | vx | vy | heading | speed | yaw_rate`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Quantity {
    /// World-frame position x \[m\].
    X,
    /// World-frame position y \[m\].
    Y,
    /// World-frame velocity ẋ [m/s].
    Vx,
    /// World-frame velocity ẏ [m/s].
    Vy,
    /// Heading θ (yaw about +z) \[rad\]; readings are wrapped to (−π, π].
    Heading,
    /// Forward body speed v [m/s].
    Speed,
    /// Yaw rate ω [rad/s].
    YawRate,
    /// Left drive wheel's angular speed relative to the base [rad/s], positive = rolling forward
    /// (a wheel encoder, ROS `sensor_msgs/JointState` velocity of the wheel joint). Robot worlds
    /// only.
    WheelLeft,
    /// Right drive wheel's angular speed [rad/s]. Robot worlds only.
    WheelRight,
}

impl Quantity {
    /// The true value of this quantity in `truth`.
    pub fn of(self, truth: &TruthState) -> f64 {
        match self {
            Quantity::X => truth.x,
            Quantity::Y => truth.y,
            Quantity::Vx => truth.vx,
            Quantity::Vy => truth.vy,
            Quantity::Heading => truth.theta,
            Quantity::Speed => truth.v_body,
            Quantity::YawRate => truth.omega,
            Quantity::WheelLeft => truth.wheel_left,
            Quantity::WheelRight => truth.wheel_right,
        }
    }

    /// SI unit of the quantity (also the unit of `noise_std` and `bias`).
    pub fn unit(self) -> &'static str {
        match self {
            Quantity::X | Quantity::Y => "m",
            Quantity::Vx | Quantity::Vy | Quantity::Speed => "m/s",
            Quantity::Heading => "rad",
            Quantity::YawRate | Quantity::WheelLeft | Quantity::WheelRight => "rad/s",
        }
    }

    /// The name used in world files.
    pub fn as_str(self) -> &'static str {
        match self {
            Quantity::X => "x",
            Quantity::Y => "y",
            Quantity::Vx => "vx",
            Quantity::Vy => "vy",
            Quantity::Heading => "heading",
            Quantity::Speed => "speed",
            Quantity::YawRate => "yaw_rate",
            Quantity::WheelLeft => "wheel_left",
            Quantity::WheelRight => "wheel_right",
        }
    }

    /// `true` for the wheel-encoder quantities.
    pub fn is_wheel(self) -> bool {
        matches!(self, Quantity::WheelLeft | Quantity::WheelRight)
    }

    /// The accumulated wheel rotation \[rad\] behind a wheel quantity (what its encoder counts).
    fn wheel_angle(self, truth: &TruthState) -> f64 {
        match self {
            Quantity::WheelLeft => truth.wheel_angle_left,
            Quantity::WheelRight => truth.wheel_angle_right,
            _ => f64::NAN,
        }
    }
}

/// One sensor channel as a world file declares it (`[[sensors]]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChannelSpec {
    /// Unique channel name (e.g. `gnss1_x`); also the key of the channel's random stream.
    pub name: String,
    /// What the channel measures.
    pub measures: Quantity,
    /// Standard deviation of the additive Gaussian noise, in the unit of the quantity. Required,
    /// except on a channel derived `from_wheels` (default 0 there: the encoders' noise reaches it
    /// through the derivation). NaN while absent.
    #[serde(default = "absent")]
    pub noise_std: f64,
    /// Constant bias (unit of the quantity). Default 0.
    #[serde(default)]
    pub bias: f64,
    /// Bias random-walk intensity [unit/√s]. Default 0 (no walk).
    #[serde(default)]
    pub bias_walk_std: f64,
    /// Sample rate \[Hz\]. Absent: a sample every control tick.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rate_hz: Option<f64>,
    /// Probability that a due sample is lost. Default 0.
    #[serde(default)]
    pub dropout_prob: f64,
    /// For a `speed` channel (wheel odometry: the forward speed of the base frame, ROS
    /// `nav_msgs/Odometry` twist.linear.x in `base_footprint`): feed it to the controller's filters
    /// as the world-frame velocity v·(cos θ̂, sin θ̂), θ̂ from the world's heading channel, as the
    /// file declares it. Absent: true when the world has a heading channel (a speed channel
    /// without one reaches no filter), see [`ChannelSpec::world_velocity`].
    #[serde(
        default,
        rename = "world_velocity",
        skip_serializing_if = "Option::is_none"
    )]
    pub world_velocity_declared: Option<bool>,
    /// Whether the channel reaches the filters as world-frame velocity (as declared, or the
    /// default; set by `WorldFile::resolve_defaults`).
    #[serde(skip)]
    pub world_velocity: bool,
    /// For a `wheel_left`/`wheel_right` channel: the encoder's counts per wheel revolution
    /// (TurtleBot3's Dynamixel XL430: 4096). The reading is then the count difference since the
    /// channel's previous sample over the time between them, so it is quantised to
    /// 2π/(N·Δt) rad/s. Absent: the joint's speed itself.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ticks_per_rev: Option<u32>,
    /// For a `speed` or `yaw_rate` channel: derive it from two wheel channels `[left, right]` as a
    /// differential-drive odometry does (ROS diff_drive_controller): v = r(ω_l + ω_r)/2,
    /// ω = r(ω_r − ω_l)/L with the robot's wheel radius r and separation L. The wheel readings are
    /// taken as received, so an attack on an encoder reaches the odometry. The channel's own
    /// `noise_std`, `bias` and `bias_walk_std` are added on top (0 for a pure derivation); it is
    /// fresh whenever a wheel reading is.
    #[serde(
        default,
        deserialize_with = "wheel_pair",
        skip_serializing_if = "Option::is_none"
    )]
    pub from_wheels: Option<[String; 2]>,
    /// For the `heading` channel: fuse it with this `yaw_rate` channel (the IMU gyro) in a
    /// Kalman filter on (θ, gyro bias) (`ftcbf_controller::odometry::HeadingFilter`); the drive
    /// and the wheel-odometry conversion then use the fused yaw, and the conversion's variance uses
    /// the filter's. Absent: the heading reading itself.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gyro: Option<String>,
}

/// Serde default of a required number that may be left out in some cases (checked later).
fn absent() -> f64 {
    f64::NAN
}

/// `from_wheels`: exactly two channel names, `[left, right]`. Serde's own `[String; 2]` reads the
/// first two entries of a longer array and ignores the rest (`["l", "r", "l"]` was accepted).
fn wheel_pair<'de, D>(d: D) -> Result<Option<[String; 2]>, D::Error>
where
    D: serde::Deserializer<'de>,
{
    let names = Vec::<String>::deserialize(d)?;
    let n = names.len();
    <[String; 2]>::try_from(names).map(Some).map_err(|names| {
        serde::de::Error::custom(format!(
            "expected exactly two wheel channel names, [left, right]; got {n}: {names:?}"
        ))
    })
}

impl ChannelSpec {
    /// A noiseless, bias-free channel sampled every tick (builder start; set fields afterwards).
    pub fn new(name: impl Into<String>, measures: Quantity, noise_std: f64) -> Self {
        ChannelSpec {
            name: name.into(),
            measures,
            noise_std,
            bias: 0.0,
            bias_walk_std: 0.0,
            rate_hz: None,
            dropout_prob: 0.0,
            world_velocity_declared: None,
            world_velocity: false,
            ticks_per_rev: None,
            from_wheels: None,
            gyro: None,
        }
    }

    /// Checks the numeric fields of this one channel (names are checked by [`validate_channels`]).
    pub fn validate(&self) -> Result<(), SensorError> {
        let bad = |field: &'static str, value: f64, expected: &'static str| {
            Err(SensorError::InvalidField {
                channel: self.name.clone(),
                field,
                value,
                expected,
            })
        };
        if self.noise_std.is_nan() && self.from_wheels.is_none() {
            return Err(SensorError::Missing {
                channel: self.name.clone(),
                key: "noise_std",
                expected: "the standard deviation of the channel's noise, in its unit (only a channel derived `from_wheels` may leave it out)",
            });
        }
        if !(self.noise_std.is_finite() && self.noise_std >= 0.0) {
            return bad("noise_std", self.noise_std, "a finite number >= 0");
        }
        if !self.bias.is_finite() {
            return bad("bias", self.bias, "a finite number");
        }
        if !(self.bias_walk_std.is_finite() && self.bias_walk_std >= 0.0) {
            return bad("bias_walk_std", self.bias_walk_std, "a finite number >= 0");
        }
        if let Some(rate) = self.rate_hz {
            if !(rate.is_finite() && rate > 0.0) {
                return bad(
                    "rate_hz",
                    rate,
                    "a finite number > 0 (or omit it: every tick)",
                );
            }
        }
        if !(self.dropout_prob >= 0.0 && self.dropout_prob <= 1.0) {
            return bad("dropout_prob", self.dropout_prob, "a probability in [0, 1]");
        }
        if let Some(n) = self.ticks_per_rev {
            if !self.measures.is_wheel() {
                return bad(
                    "ticks_per_rev",
                    f64::from(n),
                    "no value: only a wheel_left or wheel_right channel has encoder counts",
                );
            }
            if n == 0 {
                return bad(
                    "ticks_per_rev",
                    0.0,
                    "a whole number of counts per revolution >= 1",
                );
            }
        }
        if self.from_wheels.is_some() {
            if !matches!(self.measures, Quantity::Speed | Quantity::YawRate) {
                return Err(SensorError::BadWheelSource {
                    channel: self.name.clone(),
                    problem: format!(
                        "it measures {}; only a speed or yaw_rate channel is derived from the wheels",
                        self.measures.as_str()
                    ),
                });
            }
            if self.rate_hz.is_some() || self.dropout_prob > 0.0 {
                return Err(SensorError::BadWheelSource {
                    channel: self.name.clone(),
                    problem: "a derived channel takes its timing from its wheel channels; remove `rate_hz` and `dropout_prob` (set them on the wheel channels)".to_string(),
                });
            }
        }
        Ok(())
    }
}

/// A fault pattern F(r_i) of the thesis (§3.1): the set of channels one fault may corrupt
/// (`[[fault_patterns]]`). Patterns must be non-empty and pairwise disjoint.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FaultPatternSpec {
    /// Unique pattern name (e.g. `gnss2`).
    pub name: String,
    /// Names of the channels in the pattern.
    pub channels: Vec<String>,
}

/// A configuration error in the sensor channels or fault patterns. Every message names the channel
/// or pattern, the field, and what was expected.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum SensorError {
    /// A channel with an empty name.
    #[error("sensors[{index}]: `name` is empty; expected a non-empty channel name")]
    EmptyChannelName {
        /// Position of the channel in the list (0-based).
        index: usize,
    },
    /// Two channels share a name.
    #[error("sensor channel \"{name}\" is declared twice (sensors[{first}] and sensors[{second}]); channel names must be unique")]
    DuplicateChannel {
        /// The repeated name.
        name: String,
        /// First declaration (0-based).
        first: usize,
        /// Second declaration (0-based).
        second: usize,
    },
    /// A required key is absent.
    #[error("sensor channel \"{channel}\": `{key}` is missing; expected {expected}")]
    Missing {
        /// Channel name.
        channel: String,
        /// The key.
        key: &'static str,
        /// What it must hold.
        expected: &'static str,
    },
    /// A numeric field out of range.
    #[error("sensor channel \"{channel}\": `{field}` = {value} is invalid; expected {expected}")]
    InvalidField {
        /// Channel name.
        channel: String,
        /// Field name as written in the world file.
        field: &'static str,
        /// The offending value.
        value: f64,
        /// What is accepted.
        expected: &'static str,
    },
    /// The control period handed to [`SensorSuite::new`] is not a positive finite number.
    #[error("control period dt = {0} s is invalid; expected a finite number > 0")]
    InvalidControlPeriod(f64),
    /// A fault pattern with an empty name.
    #[error("fault_patterns[{index}]: `name` is empty; expected a non-empty pattern name")]
    EmptyPatternName {
        /// Position of the pattern in the list (0-based).
        index: usize,
    },
    /// Two fault patterns share a name.
    #[error("fault pattern \"{name}\" is declared twice; pattern names must be unique")]
    DuplicatePattern {
        /// The repeated name.
        name: String,
    },
    /// A fault pattern without channels.
    #[error(
        "fault pattern \"{pattern}\": `channels` is empty; expected at least one sensor channel"
    )]
    EmptyPattern {
        /// Pattern name.
        pattern: String,
    },
    /// A fault pattern names a channel that is not declared.
    #[error("fault pattern \"{pattern}\": unknown sensor channel \"{channel}\"; declared channels are: {known}")]
    UnknownChannel {
        /// Pattern name.
        pattern: String,
        /// The unknown channel name.
        channel: String,
        /// Comma-separated declared channel names.
        known: String,
    },
    /// A fault pattern lists the same channel twice.
    #[error("fault pattern \"{pattern}\": channel \"{channel}\" is listed twice")]
    RepeatedChannelInPattern {
        /// Pattern name.
        pattern: String,
        /// The repeated channel.
        channel: String,
    },
    /// A `from_wheels` that does not name a left and a right wheel channel, or sits on the wrong
    /// kind of channel.
    #[error("sensor channel \"{channel}\": `from_wheels` is invalid: {problem}")]
    BadWheelSource {
        /// The derived channel.
        channel: String,
        /// What is wrong and what was expected.
        problem: String,
    },
    /// A `gyro` that does not name a yaw-rate channel, or sits on a non-heading channel.
    #[error("sensor channel \"{channel}\": `gyro` is invalid: {problem}")]
    BadGyro {
        /// The channel with the key.
        channel: String,
        /// What is wrong and what was expected.
        problem: String,
    },
    /// Two fault patterns share a channel.
    #[error("fault patterns \"{first}\" and \"{second}\" overlap on channel \"{channel}\"; fault patterns must be disjoint (F(r_i) ∩ F(r_j) = ∅, thesis §3.1)")]
    OverlappingPatterns {
        /// The earlier pattern.
        first: String,
        /// The later pattern.
        second: String,
        /// The shared channel.
        channel: String,
    },
}

/// Checks every channel's fields and that names are non-empty and unique.
pub fn validate_channels(specs: &[ChannelSpec]) -> Result<(), SensorError> {
    let mut seen: HashMap<&str, usize> = HashMap::with_capacity(specs.len());
    for (index, spec) in specs.iter().enumerate() {
        if spec.name.is_empty() {
            return Err(SensorError::EmptyChannelName { index });
        }
        if let Some(&first) = seen.get(spec.name.as_str()) {
            return Err(SensorError::DuplicateChannel {
                name: spec.name.clone(),
                first,
                second: index,
            });
        }
        seen.insert(spec.name.as_str(), index);
        spec.validate()?;
    }
    for spec in specs {
        if let Some(g) = &spec.gyro {
            let found = seen.get(g.as_str()).map(|&i| specs[i].measures);
            if spec.measures != Quantity::Heading || found != Some(Quantity::YawRate) {
                return Err(SensorError::BadGyro {
                    channel: spec.name.clone(),
                    problem: if spec.measures != Quantity::Heading {
                        format!(
                            "it measures {}; only the heading channel is fused with a gyro",
                            spec.measures.as_str()
                        )
                    } else {
                        format!(
                            "\"{g}\" {}; expected the name of a `yaw_rate` channel",
                            found.map_or("is not a declared channel".to_string(), |q| format!(
                                "measures {}",
                                q.as_str()
                            ))
                        )
                    },
                });
            }
        }
        let Some(pair) = &spec.from_wheels else {
            continue;
        };
        for (name, want) in pair.iter().zip([Quantity::WheelLeft, Quantity::WheelRight]) {
            let found = seen.get(name.as_str()).map(|&i| specs[i].measures);
            if found != Some(want) {
                return Err(SensorError::BadWheelSource {
                    channel: spec.name.clone(),
                    problem: format!(
                        "\"{name}\" {}; expected [left, right]: the name of a `wheel_left` channel, then of a `wheel_right` channel",
                        found.map_or("is not a declared channel".to_string(), |q| format!(
                            "measures {}",
                            q.as_str()
                        ))
                    ),
                });
            }
        }
    }
    Ok(())
}

/// The indices of the wheel channels (left, right) a channel is derived from (`from_wheels`).
pub fn wheel_sources(specs: &[ChannelSpec], channel: usize) -> Option<[usize; 2]> {
    let pair = specs.get(channel)?.from_wheels.as_ref()?;
    let find = |n: &String| specs.iter().position(|s| &s.name == n);
    Some([find(&pair[0])?, find(&pair[1])?])
}

/// Resolves fault patterns to channel indices (in the order of `channels`), checking that every
/// pattern is non-empty, names only declared channels (each once) and that patterns are disjoint.
pub fn resolve_patterns(
    channels: &[ChannelSpec],
    patterns: &[FaultPatternSpec],
) -> Result<Vec<Vec<usize>>, SensorError> {
    let index_of: HashMap<&str, usize> = channels
        .iter()
        .enumerate()
        .map(|(i, c)| (c.name.as_str(), i))
        .collect();
    let mut owner: HashMap<usize, &str> = HashMap::new();
    let mut names: HashMap<&str, ()> = HashMap::new();
    let mut out = Vec::with_capacity(patterns.len());
    for (index, pattern) in patterns.iter().enumerate() {
        if pattern.name.is_empty() {
            return Err(SensorError::EmptyPatternName { index });
        }
        if names.insert(pattern.name.as_str(), ()).is_some() {
            return Err(SensorError::DuplicatePattern {
                name: pattern.name.clone(),
            });
        }
        if pattern.channels.is_empty() {
            return Err(SensorError::EmptyPattern {
                pattern: pattern.name.clone(),
            });
        }
        let mut members = Vec::with_capacity(pattern.channels.len());
        for channel in &pattern.channels {
            let Some(&i) = index_of.get(channel.as_str()) else {
                return Err(SensorError::UnknownChannel {
                    pattern: pattern.name.clone(),
                    channel: channel.clone(),
                    known: join_names(channels.iter().map(|c| c.name.as_str())),
                });
            };
            if members.contains(&i) {
                return Err(SensorError::RepeatedChannelInPattern {
                    pattern: pattern.name.clone(),
                    channel: channel.clone(),
                });
            }
            if let Some(first) = owner.get(&i) {
                return Err(SensorError::OverlappingPatterns {
                    first: (*first).to_string(),
                    second: pattern.name.clone(),
                    channel: channel.clone(),
                });
            }
            owner.insert(i, pattern.name.as_str());
            members.push(i);
        }
        out.push(members);
    }
    Ok(out)
}

/// `"a", "b", "c"` for error messages.
pub(crate) fn join_names<'a>(names: impl Iterator<Item = &'a str>) -> String {
    let list: Vec<String> = names.map(|n| format!("\"{n}\"")).collect();
    if list.is_empty() {
        "(none)".to_string()
    } else {
        list.join(", ")
    }
}

/// 64-bit FNV-1a of `domain`, a 0 separator byte, then `key`. Stable across platforms, Rust
/// versions and runs (unlike `std`'s randomised hasher).
pub fn stable_hash(domain: &str, key: &str) -> u64 {
    const OFFSET: u64 = 0xcbf2_9ce4_8422_2325;
    const PRIME: u64 = 0x0000_0100_0000_01b3;
    let mut h = OFFSET;
    for &b in domain
        .as_bytes()
        .iter()
        .chain([0u8].iter())
        .chain(key.as_bytes())
    {
        h ^= u64::from(b);
        h = h.wrapping_mul(PRIME);
    }
    h
}

/// The random stream of one named noise source: a ChaCha20 generator keyed by the run `seed`
/// (expanded by rand_core's portable `seed_from_u64`), on stream number `stable_hash(domain, key)`.
/// Distinct keys give independent streams; the same `(seed, domain, key)` always gives the same
/// stream. Sensors use domain `"sensor"` and the channel name as key.
pub fn stream_rng(seed: u64, domain: &str, key: &str) -> ChaCha20Rng {
    let mut rng = ChaCha20Rng::seed_from_u64(seed);
    rng.set_stream(stable_hash(domain, key));
    rng
}

/// What a channel delivers at one control tick (and what attacks then modify).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// The reading the consumer receives (unit of the quantity). `NaN` before the channel's first
    /// sample has arrived.
    pub value: f64,
    /// The noise-, bias- and attack-free value of the measured quantity at the time the current
    /// sample was taken (for logging and metrics; never given to the controller). `NaN` before the
    /// first sample.
    pub clean: f64,
    /// `true` only on the tick a new sample arrived.
    pub fresh: bool,
    /// Time since the current sample was taken \[s\]; 0 when fresh, `+∞` before the first sample.
    pub age: f64,
}

impl Sample {
    /// The placeholder before any sample has arrived.
    pub const NONE: Sample = Sample {
        value: f64::NAN,
        clean: f64::NAN,
        fresh: false,
        age: f64::INFINITY,
    };
}

/// When a channel takes samples, in control ticks.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Schedule {
    /// A sample every `period` ticks (`k ≡ 0 mod period`); `period = 1` is every tick.
    EveryTicks(i64),
    /// Sample number `⌊k·ticks_to_slots + ε⌋` (a period that is not a whole number of ticks).
    Fractional(f64),
}

impl Schedule {
    fn new(rate_hz: Option<f64>, dt: f64) -> Self {
        let Some(rate) = rate_hz else {
            return Schedule::EveryTicks(1);
        };
        let ticks_per_sample = 1.0 / (rate * dt);
        if ticks_per_sample <= 1.0 + SLOT_EPS {
            return Schedule::EveryTicks(1);
        }
        let nearest = ticks_per_sample.round();
        if (ticks_per_sample - nearest).abs() <= SLOT_EPS * ticks_per_sample && nearest < 1e15 {
            Schedule::EveryTicks(nearest as i64)
        } else {
            Schedule::Fractional(rate * dt)
        }
    }

    /// Number of the latest sample slot at or before tick `k`.
    fn slot(self, k: i64) -> i64 {
        match self {
            Schedule::EveryTicks(p) => k.div_euclid(p),
            Schedule::Fractional(slots_per_tick) => {
                ((k as f64) * slots_per_tick + SLOT_EPS).floor() as i64
            }
        }
    }
}

/// Mutable state of one channel.
#[derive(Debug, Clone)]
struct ChannelState {
    rng: ChaCha20Rng,
    schedule: Schedule,
    /// Slot of the last due sample (delivered or dropped).
    last_slot: Option<i64>,
    /// Current sample (value, clean, tick it was taken).
    held: Option<(f64, f64, i64)>,
    /// Bias random-walk value and the tick it was last advanced.
    walk: f64,
    walk_tick: Option<i64>,
    /// A quantised encoder's count (⌊angle·N/2π⌋) at its last delivered sample, and that tick.
    count: Option<(f64, i64)>,
    /// The wheel channels (left, right) a derived channel is computed from.
    sources: Option<[usize; 2]>,
}

impl WheelGeometry {
    /// What a channel measuring `q` reads from wheel speeds (left, right) [rad/s]: forward speed
    /// r(ω_l + ω_r)/2 [m/s] or yaw rate r(ω_r − ω_l)/L [rad/s]. Linear in the wheel speeds, so it
    /// maps a change of the wheel readings to the change of the odometry as well.
    pub fn odometry(self, q: Quantity, left: f64, right: f64) -> f64 {
        match q {
            Quantity::Speed => self.radius * (left + right) / 2.0,
            Quantity::YawRate => self.radius * (right - left) / self.separation,
            _ => f64::NAN,
        }
    }
}

/// The sensor suite: validated channel specs plus each channel's random stream and schedule.
#[derive(Debug, Clone)]
pub struct SensorSuite {
    specs: Vec<ChannelSpec>,
    dt: f64,
    channels: Vec<ChannelState>,
    out: Vec<Sample>,
    /// This tick's readings before attacks (for [`SensorSuite::propagate_attacks`]).
    pre_attack: Vec<f64>,
    wheels: Option<WheelGeometry>,
}

impl SensorSuite {
    /// Validates `specs` and builds the suite for a control loop of period `dt` \[s\] (the suite is
    /// sampled once per control tick). `seed` is the run seed.
    pub fn new(specs: &[ChannelSpec], dt: f64, seed: u64) -> Result<Self, SensorError> {
        if !(dt.is_finite() && dt > 0.0) {
            return Err(SensorError::InvalidControlPeriod(dt));
        }
        validate_channels(specs)?;
        let channels = specs
            .iter()
            .enumerate()
            .map(|(i, spec)| ChannelState {
                rng: stream_rng(seed, "sensor", &spec.name),
                schedule: Schedule::new(spec.rate_hz, dt),
                last_slot: None,
                held: None,
                walk: 0.0,
                walk_tick: None,
                count: None,
                sources: wheel_sources(specs, i),
            })
            .collect();
        Ok(SensorSuite {
            specs: specs.to_vec(),
            dt,
            channels,
            out: vec![Sample::NONE; specs.len()],
            pre_attack: vec![f64::NAN; specs.len()],
            wheels: None,
        })
    }

    /// Sets the wheel geometry that `from_wheels` channels use (without it they read NaN).
    pub fn set_wheel_geometry(&mut self, geometry: Option<WheelGeometry>) {
        self.wheels = geometry;
    }

    /// After attacks have rewritten this tick's samples (the buffer [`SensorSuite::sample`]
    /// returned): every `from_wheels` channel gets the odometry of its wheel readings' change, so
    /// an attack on an encoder reaches the speed and yaw rate derived from it (an attack on the
    /// derived channel itself stays). Returns the samples.
    pub fn propagate_attacks(&mut self) -> &mut [Sample] {
        let samples = &mut self.out;
        let Some(g) = self.wheels else {
            return samples;
        };
        for (i, ch) in self.channels.iter().enumerate() {
            let Some([l, r]) = ch.sources else {
                continue;
            };
            let dl = samples[l].value - self.pre_attack[l];
            let dr = samples[r].value - self.pre_attack[r];
            if dl != 0.0 || dr != 0.0 {
                samples[i].value += g.odometry(self.specs[i].measures, dl, dr);
            }
        }
        samples
    }

    /// The channel specs, in suite order (the order of the measurement vector y).
    pub fn specs(&self) -> &[ChannelSpec] {
        &self.specs
    }

    /// Number of channels.
    pub fn len(&self) -> usize {
        self.specs.len()
    }

    /// `true` when the suite has no channel.
    pub fn is_empty(&self) -> bool {
        self.specs.is_empty()
    }

    /// The control period the suite was built for \[s\].
    pub fn control_dt(&self) -> f64 {
        self.dt
    }

    /// Index of the channel called `name`.
    pub fn channel_index(&self, name: &str) -> Option<usize> {
        self.specs.iter().position(|s| s.name == name)
    }

    /// Resolves fault patterns against this suite's channels (see [`resolve_patterns`]).
    pub fn resolve_patterns(
        &self,
        patterns: &[FaultPatternSpec],
    ) -> Result<Vec<Vec<usize>>, SensorError> {
        resolve_patterns(&self.specs, patterns)
    }

    /// The control tick of time `t`: `round(t / dt)` (saturating; a NaN time maps to tick 0).
    pub fn tick_of(&self, t: f64) -> i64 {
        (t / self.dt).round() as i64
    }

    /// Samples every channel at control tick `round(truth.t / dt)`; call once per control tick.
    /// Returns this tick's samples in suite order; the slice is an output buffer rewritten on every
    /// call from the suite's internal state, so attacks may modify it in place without affecting
    /// what the sensors hold. Calling twice at the same tick delivers nothing fresh the second time.
    pub fn sample(&mut self, truth: &TruthState) -> &mut [Sample] {
        let k = self.tick_of(truth.t);
        let dt = self.dt;
        // Measured channels first, then the channels derived from their readings.
        for derived in [false, true] {
            for i in 0..self.specs.len() {
                if self.channels[i].sources.is_some() != derived {
                    continue;
                }
                let spec = &self.specs[i];
                let due = match self.channels[i].sources {
                    Some([l, r]) => self.out[l].fresh || self.out[r].fresh,
                    None => {
                        let ch = &self.channels[i];
                        let slot = ch.schedule.slot(k);
                        let due = ch.last_slot.is_none_or(|last| slot > last);
                        if due {
                            self.channels[i].last_slot = Some(slot);
                        }
                        due
                    }
                };
                let mut fresh = false;
                if due {
                    let ch = &mut self.channels[i];
                    // Fixed draw order, independent of the configuration (see module docs).
                    let u: f64 = ch.rng.random();
                    let z_noise: f64 = ch.rng.sample(StandardNormal);
                    let z_walk: f64 = ch.rng.sample(StandardNormal);
                    if let Some(kw) = ch.walk_tick {
                        let elapsed = k.saturating_sub(kw) as f64 * dt;
                        if elapsed > 0.0 {
                            ch.walk += spec.bias_walk_std * elapsed.sqrt() * z_walk;
                        }
                    }
                    ch.walk_tick = Some(k);
                    if u >= spec.dropout_prob {
                        let clean = spec.measures.of(truth);
                        let measured = match (ch.sources, spec.ticks_per_rev) {
                            (Some([l, r]), _) => self.wheels.map_or(f64::NAN, |g| {
                                g.odometry(spec.measures, self.out[l].value, self.out[r].value)
                            }),
                            (None, Some(n)) => {
                                let angle = spec.measures.wheel_angle(truth);
                                encoder_speed(&mut ch.count, angle, clean, n, k, dt)
                            }
                            (None, None) => clean,
                        };
                        let mut value = measured + spec.bias + ch.walk + spec.noise_std * z_noise;
                        if spec.measures == Quantity::Heading {
                            value = wrap_angle(value);
                        }
                        ch.held = Some((value, clean, k));
                        fresh = true;
                    }
                }
                self.out[i] = match self.channels[i].held {
                    Some((value, clean, k_sample)) => Sample {
                        value,
                        clean,
                        fresh,
                        age: k.saturating_sub(k_sample) as f64 * dt,
                    },
                    None => Sample::NONE,
                };
            }
        }
        for (p, o) in self.pre_attack.iter_mut().zip(&self.out) {
            *p = o.value;
        }
        &mut self.out
    }
}

/// A quantised encoder's speed reading [rad/s]: the count ⌊angle·N/2π⌋ now minus the count at the
/// previous delivered sample, over the time between them. The first sample has no previous count
/// and reads the true speed rounded to the encoder's step 2π/(N·dt).
fn encoder_speed(
    count: &mut Option<(f64, i64)>,
    angle: f64,
    speed: f64,
    ticks_per_rev: u32,
    k: i64,
    dt: f64,
) -> f64 {
    let n = f64::from(ticks_per_rev);
    let now = (angle * n / std::f64::consts::TAU).floor();
    let value = match *count {
        Some((before, k0)) if k > k0 => {
            (now - before) * std::f64::consts::TAU / (n * (k - k0) as f64 * dt)
        }
        _ => {
            let step = std::f64::consts::TAU / (n * dt);
            (speed / step).round() * step
        }
    };
    *count = Some((now, k));
    value
}
