//! Attack and fault injectors: what turns the sensor readings `y` into what the controller receives.
//!
//! An [`AttackStack`] is built from the `[[attacks]]` of a world file. Each injector targets a set of
//! channels (by name) and an activation window `[start, end)` (`end` absent = forever); injectors
//! compose, applied in file order, each one seeing the output of the previous ones. Attacks model
//! the fault vector `a_t` of eq. 3.2 — but unlike the thesis' assumption they may also touch channels
//! outside any declared fault pattern ([`AttackStack::outside_fault_patterns`] tells which do).
//!
//! # Kinds (TOML `kind = "…"`, kind-specific keys in parentheses)
//! * `bias` (keys: `value`): adds a constant (the thesis' `+1` on y₄).
//! * `ramp` / `drift` (keys: `rate`, optional `cap`): adds `rate·(t − start)`, clamped to `±cap`.
//! * `sinusoid` (keys: `amplitude`, `frequency_hz`, `phase` = 0): adds `amplitude·sin(2π·f·(t − start) + phase)`.
//! * `freeze` / `stuck_at` (keys: optional `value`): the reading is held at `value`, or at the last
//!   reading the injector saw before `start` (the first reading in the window if there is none);
//!   the channel keeps reporting at its rate (`fresh`, `age` untouched).
//! * `replay` (keys: `record_start`, `length`): records the readings (value, fresh, age) of the ticks in
//!   `[record_start, record_start + length)` and plays them back, one per tick, from `start`,
//!   bit for bit, cycling if the window is longer than the recording. The recording must end at or
//!   before `start`. If nothing was recorded (no tick fell in the recording window), readings pass
//!   through unchanged.
//! * `dropout` / `denial_of_service` (no keys): no new samples reach the controller: `fresh = false`, the
//!   last delivered value is held and its age keeps growing (`NaN`/`+∞` if none was ever delivered).
//! * `scale` (keys: `factor`): multiplies the reading.
//! * `spikes` (keys: `probability`, `magnitude`): each sample is, with `probability`, offset by
//!   `±magnitude` (sign equally likely); seeded, one stream per (attack, channel).
//! * `non_finite` (keys: `value` = `"nan"` | `"inf"` | `"-inf"`): the reading is replaced.
//! * `absurd` (keys: `value` = 1e12): the reading is replaced by a finite but absurd number.
//! * `stealthy` (keys: `max_rate`, `threshold`, `direction` = `"positive"`, optional `max_bias`): a bias that
//!   grows as fast as the defender's detector allows; see below.
//! * `coordinated` (keys: `velocity` (one per channel), optional `cap`): the channels (e.g. both axes of
//!   one GNSS) are spoofed consistently along a path: offset vector `o(t) = velocity·(t − start)`,
//!   scaled down to Euclidean norm `cap` if longer; channel `i` gets `o_i`.
//!
//! # Samples, not ticks
//! The value-transforming kinds (bias, ramp, sinusoid, scale, spikes, non_finite, absurd, stealthy,
//! coordinated) act on *samples*: the effect is decided when a fresh sample passes through the
//! injector at tick `t` (active iff `t ∈ [start, end)`), and held with that sample while the channel
//! repeats it (`fresh = false`). So a slow channel's held reading never changes between samples, and
//! the effect starts with the first sample taken in the window and ends with the first sample
//! taken after it. For channels sampled every tick this is the same as acting on ticks. `freeze`,
//! `replay` and `dropout` act on ticks. Window bounds are compared with a 1 ns tolerance so that tick
//! times computed as `k·dt` never miss a boundary by rounding.
//!
//! # Stealthy bias and the detector
//! The attacker knows the defender's detector ([`DetectorView`]): for its channel, the attacked
//! filter's predicted measurement `ŷ = c·x̂⁻` and innovation standard deviation
//! `s = sqrt(c P⁻ cᵀ + r)` for the coming update, and its own unattacked reading `y` (the injector's
//! input). With direction `d = ±1` and bias magnitude `β ≥ 0` the defender sees the innovation
//! `y + d·β − ŷ`, and the detector stays silent while `|y + d·β − ŷ| ≤ threshold·s` (`threshold`
//! in standard deviations; for a χ²(1) quantile `q` use `threshold = √q`). The stealthy values of
//! `β` form the interval `[lo, hi]` with `lo = −threshold·s − d·(y − ŷ)` and
//! `hi = threshold·s − d·(y − ŷ)`. At every fresh sample in the window, `Δ` seconds after the
//! previous one (or after `start`), the injector sets
//!
//! ```text
//! grow = min(β_{k−1} + max_rate·Δ, max_bias)
//! β_k  = max(0, min(grow, hi), min(lo, max_bias))
//! ```
//!
//! (with `threshold` shrunk by a relative 10⁻⁹ so floating-point rounding of `y + d·β − ŷ` cannot
//! tip the innovation over the bound), i.e. the largest bias not above the rate-limited growth that
//! keeps the innovation inside the threshold; if even that growth leaves the innovation below `−threshold·s` (the filter has been
//! dragged towards the attacked readings and the sensor's own reading now looks suspiciously low),
//! the bias is raised to `lo` — stealth takes precedence over the rate limit, not over `max_bias`.
//! The bias never goes below 0 (never into the opposite direction): if even `β = 0` is detectable
//! (`hi < 0`, the sensor's own innovation is beyond the threshold on the attack's side) the attacker
//! backs off to 0 and the residue is the sensor's own. Hence whenever the sensor's own innovation
//! is not beyond `+threshold·s` in direction `d` (and `max_bias` does not bind), the attacked
//! innovation is within `±threshold·s`. With no prediction (`NoDetector`, `None`, or a non-finite /
//! non-positive prediction or reading) the bias grows at `max_rate` (up to `max_bias`).
//!
//! One file (about 1,100 lines): every attack kind is matched on the same [`AttackKind`] by its
//! validation, its injector and its closed-form offset ([`open_loop_offset`]), so a new kind is
//! added in one place and no match can miss it.

use rand::Rng;
use rand_chacha::ChaCha20Rng;
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::sensors::{join_names, stream_rng, ChannelSpec, Sample, SensorSuite};

/// Tolerance on window boundaries \[s\].
const WINDOW_EPS: f64 = 1e-9;

/// What the attacker knows of the defender's detector: for a channel, the attacked filter's
/// predicted measurement c·x̂⁻ and innovation standard deviation sqrt(c P⁻ cᵀ + r) for the coming
/// update.
pub trait DetectorView {
    /// `(predicted measurement, innovation std)` for `channel` (suite index), or `None` if unknown.
    fn predicted(&self, channel: usize) -> Option<(f64, f64)>;
}

/// An attacker without knowledge of the detector: `predicted` is always `None`, so a stealthy
/// injector grows its bias at its maximum rate.
#[derive(Debug, Clone, Copy, Default)]
pub struct NoDetector;

impl DetectorView for NoDetector {
    fn predicted(&self, _channel: usize) -> Option<(f64, f64)> {
        None
    }
}

impl<F: Fn(usize) -> Option<(f64, f64)>> DetectorView for F {
    fn predicted(&self, channel: usize) -> Option<(f64, f64)> {
        self(channel)
    }
}

/// Replacement value of a `non_finite` attack.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum NonFiniteValue {
    /// Not-a-number.
    #[serde(rename = "nan", alias = "NaN")]
    Nan,
    /// +∞.
    #[serde(rename = "inf", alias = "+inf")]
    PosInf,
    /// −∞.
    #[serde(rename = "-inf", alias = "neg_inf")]
    NegInf,
}

impl NonFiniteValue {
    /// The floating-point value.
    pub fn value(self) -> f64 {
        match self {
            NonFiniteValue::Nan => f64::NAN,
            NonFiniteValue::PosInf => f64::INFINITY,
            NonFiniteValue::NegInf => f64::NEG_INFINITY,
        }
    }
}

/// Direction of a stealthy bias; read from `"positive"` or `"negative"` (anything else, an
/// array included, is refused with both values named).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Direction {
    /// Readings pushed up.
    #[default]
    Positive,
    /// Readings pushed down.
    Negative,
}

impl<'de> Deserialize<'de> for Direction {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Visitor;
        impl serde::de::Visitor<'_> for Visitor {
            type Value = Direction;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("\"positive\" or \"negative\"")
            }
            fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<Direction, E> {
                match v {
                    "positive" => Ok(Direction::Positive),
                    "negative" => Ok(Direction::Negative),
                    other => Err(E::invalid_value(serde::de::Unexpected::Str(other), &self)),
                }
            }
        }
        d.deserialize_str(Visitor)
    }
}

impl Direction {
    /// +1 or −1.
    pub fn sign(self) -> f64 {
        match self {
            Direction::Positive => 1.0,
            Direction::Negative => -1.0,
        }
    }
}

fn default_absurd() -> f64 {
    1e12
}

/// Declares [`AttackKind`] and the flat serde form `RawAttack` (common keys + kind keys in one
/// table, internally tagged by `kind`, unknown keys rejected) with conversions both ways.
macro_rules! attack_kinds {
    ($(
        $(#[$vmeta:meta])*
        $Variant:ident { $( $(#[$fmeta:meta])* $field:ident : $ty:ty ),* $(,)? }
    ),* $(,)?) => {
        /// The kind of an attack and its kind-specific parameters (see the module docs).
        #[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
        #[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
        pub enum AttackKind {
            $( $(#[$vmeta])* $Variant { $( $(#[$fmeta])* $field: $ty ),* } ),*
        }

        // Read through `spec::tagged`, so that an error names the key inside the table.
        $crate::spec::tagged::kind_tagged! {
            #[derive(Debug, Clone, Serialize)]
            #[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
            enum RawAttack via RawAttackByKind {
                $( $(#[$vmeta])* $Variant {
                    #[serde(default, skip_serializing_if = "Option::is_none")]
                    label: Option<String>,
                    channels: Vec<String>,
                    #[serde(default)]
                    start: f64,
                    #[serde(default, skip_serializing_if = "Option::is_none")]
                    end: Option<f64>,
                    $( $(#[$fmeta])* $field: $ty ),*
                } ),*
            }
        }

        impl From<RawAttack> for AttackSpec {
            fn from(raw: RawAttack) -> Self {
                match raw {
                    $( RawAttack::$Variant { label, channels, start, end, $( $field ),* } => AttackSpec {
                        label, channels, start, end, kind: AttackKind::$Variant { $( $field ),* },
                    } ),*
                }
            }
        }

        impl From<AttackSpec> for RawAttack {
            fn from(spec: AttackSpec) -> Self {
                let AttackSpec { label, channels, start, end, kind } = spec;
                match kind {
                    $( AttackKind::$Variant { $( $field ),* } => RawAttack::$Variant {
                        label, channels, start, end, $( $field ),*
                    } ),*
                }
            }
        }
    };
}

attack_kinds! {
    /// Adds a constant.
    Bias {
        /// Added to the reading (unit of the channel).
        value: f64,
    },
    /// Adds `rate·(t − start)`, clamped to `±cap`.
    #[serde(alias = "drift")]
    Ramp {
        /// Growth rate [unit/s].
        rate: f64,
        /// Largest |offset| (unit of the channel); absent = unbounded.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        cap: Option<f64>,
    },
    /// Adds `amplitude·sin(2π·frequency_hz·(t − start) + phase)`.
    Sinusoid {
        /// Amplitude (unit of the channel).
        amplitude: f64,
        /// Frequency \[Hz\].
        frequency_hz: f64,
        /// Phase at `start` \[rad\]. Default 0.
        #[serde(default)]
        phase: f64,
    },
    /// Holds the reading at `value`, or at the last reading before `start`.
    #[serde(alias = "stuck_at")]
    Freeze {
        /// Stuck-at value; absent = last reading before `start`.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        value: Option<f64>,
    },
    /// Plays back the readings recorded in `[record_start, record_start + length)` from `start`.
    Replay {
        /// Start of the recording \[s\].
        record_start: f64,
        /// Duration of the recording \[s\].
        length: f64,
    },
    /// Denial of service: no new samples.
    #[serde(alias = "denial_of_service")]
    Dropout {},
    /// Multiplies the reading.
    Scale {
        /// Factor.
        factor: f64,
    },
    /// Random outliers.
    Spikes {
        /// Probability that a sample is hit.
        probability: f64,
        /// Size of the outlier (unit of the channel); the sign is random.
        magnitude: f64,
    },
    /// Replaces the reading by NaN, +∞ or −∞.
    NonFinite {
        /// Which non-finite value.
        value: NonFiniteValue,
    },
    /// Replaces the reading by a finite absurd number.
    Absurd {
        /// The replacement (default 1e12).
        #[serde(default = "default_absurd")]
        value: f64,
    },
    /// A bias that grows only as fast as the detector allows.
    Stealthy {
        /// Largest growth rate of the bias [unit/s].
        max_rate: f64,
        /// Detector threshold in innovation standard deviations.
        threshold: f64,
        /// Sign of the bias. Default positive.
        #[serde(default)]
        direction: Direction,
        /// Largest bias magnitude; absent = unbounded.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        max_bias: Option<f64>,
    },
    /// Several channels spoofed consistently along a path.
    Coordinated {
        /// Offset velocity per channel, in the order of `channels` [unit/s].
        velocity: Vec<f64>,
        /// Largest Euclidean norm of the offset vector; absent = unbounded.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        cap: Option<f64>,
    },
}

impl AttackKind {
    /// The `kind` string of the world file.
    pub fn name(&self) -> &'static str {
        match self {
            AttackKind::Bias { .. } => "bias",
            AttackKind::Ramp { .. } => "ramp",
            AttackKind::Sinusoid { .. } => "sinusoid",
            AttackKind::Freeze { .. } => "freeze",
            AttackKind::Replay { .. } => "replay",
            AttackKind::Dropout {} => "dropout",
            AttackKind::Scale { .. } => "scale",
            AttackKind::Spikes { .. } => "spikes",
            AttackKind::NonFinite { .. } => "non_finite",
            AttackKind::Absurd { .. } => "absurd",
            AttackKind::Stealthy { .. } => "stealthy",
            AttackKind::Coordinated { .. } => "coordinated",
        }
    }
}

/// One `[[attacks]]` entry: common keys plus the kind.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(from = "RawAttack", into = "RawAttack")]
pub struct AttackSpec {
    /// Optional human-readable label (logs, run summary). Default: `kind[channels]`.
    pub label: Option<String>,
    /// Names of the targeted channels.
    pub channels: Vec<String>,
    /// Window start \[s\]. Default 0.
    pub start: f64,
    /// Window end \[s\], exclusive; `None` = forever.
    pub end: Option<f64>,
    /// What the attack does.
    pub kind: AttackKind,
}

impl AttackSpec {
    /// The label used in logs: `label` if given, else `kind[ch1,ch2]`.
    pub fn display_label(&self) -> String {
        match &self.label {
            Some(l) => l.clone(),
            None => format!("{}[{}]", self.kind.name(), self.channels.join(",")),
        }
    }

    /// `true` when `t` lies in `[start, end)` (1 ns tolerance on both bounds).
    pub fn contains(&self, t: f64) -> bool {
        window_contains(self.start, self.end, t)
    }
}

fn window_contains(start: f64, end: Option<f64>, t: f64) -> bool {
    t >= start - WINDOW_EPS && end.is_none_or(|e| t < e - WINDOW_EPS)
}

/// A configuration error in the attacks. Every message names the attack (`attacks[i]`, its kind and
/// label), the key, and what was expected.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum AttackError {
    /// `channels` is empty.
    #[error("{attack}: `channels` is empty; expected at least one sensor channel")]
    NoChannels {
        /// Which attack.
        attack: String,
    },
    /// A targeted channel is not declared.
    #[error("{attack}: unknown sensor channel \"{channel}\"; declared channels are: {known}")]
    UnknownChannel {
        /// Which attack.
        attack: String,
        /// The unknown name.
        channel: String,
        /// Comma-separated declared channel names.
        known: String,
    },
    /// A channel listed twice.
    #[error("{attack}: channel \"{channel}\" is listed twice in `channels`")]
    RepeatedChannel {
        /// Which attack.
        attack: String,
        /// The repeated name.
        channel: String,
    },
    /// `end` ≤ `start`.
    #[error("{attack}: window end = {end} s must be greater than start = {start} s")]
    EmptyWindow {
        /// Which attack.
        attack: String,
        /// Window start.
        start: f64,
        /// Window end.
        end: f64,
    },
    /// A numeric key out of range.
    #[error("{attack}: `{field}` = {value} is invalid; expected {expected}")]
    InvalidField {
        /// Which attack.
        attack: String,
        /// Key name.
        field: &'static str,
        /// The offending value.
        value: f64,
        /// What is accepted.
        expected: &'static str,
    },
    /// `velocity` of a coordinated attack does not match `channels`.
    #[error("{attack}: `velocity` has {got} components but `channels` has {expected}; expected one velocity per channel")]
    VelocityLength {
        /// Which attack.
        attack: String,
        /// Components given.
        got: usize,
        /// Channels listed.
        expected: usize,
    },
    /// A replay whose recording overlaps its playback.
    #[error("{attack}: replay records [{record_start}, {record_end}) s but plays back from start = {start} s; the recording must end at or before `start`")]
    ReplayOverlap {
        /// Which attack.
        attack: String,
        /// Recording start.
        record_start: f64,
        /// Recording end.
        record_end: f64,
        /// Playback start.
        start: f64,
    },
}

fn attack_name(index: usize, spec: &AttackSpec) -> String {
    match &spec.label {
        Some(l) => format!(
            "attacks[{index}] (kind \"{}\", label \"{l}\")",
            spec.kind.name()
        ),
        None => format!("attacks[{index}] (kind \"{}\")", spec.kind.name()),
    }
}

/// Validates attack specs against the declared channels; returns each attack's channel indices.
pub fn validate_attacks(
    specs: &[AttackSpec],
    channels: &[ChannelSpec],
) -> Result<Vec<Vec<usize>>, AttackError> {
    specs
        .iter()
        .enumerate()
        .map(|(i, spec)| validate_one(i, spec, channels))
        .collect()
}

/// One attack checked: its channels exist, once each (returned as indices), its window is
/// finite and not empty, and its kind's parameters are in range.
fn validate_one(
    index: usize,
    spec: &AttackSpec,
    channels: &[ChannelSpec],
) -> Result<Vec<usize>, AttackError> {
    let attack = attack_name(index, spec);
    let targets = attack_targets(&attack, spec, channels)?;
    check_window(&attack, spec)?;
    check_kind(&attack, spec)?;
    Ok(targets)
}

/// `attack`'s `field` is `value`, not what was `expected`.
fn invalid_field(
    attack: &str,
    field: &'static str,
    value: f64,
    expected: &'static str,
) -> AttackError {
    AttackError::InvalidField {
        attack: attack.to_string(),
        field,
        value,
        expected,
    }
}

/// The indices of the channels the attack names: at least one, each known and named once.
fn attack_targets(
    attack: &str,
    spec: &AttackSpec,
    channels: &[ChannelSpec],
) -> Result<Vec<usize>, AttackError> {
    if spec.channels.is_empty() {
        return Err(AttackError::NoChannels {
            attack: attack.to_string(),
        });
    }
    let mut targets = Vec::with_capacity(spec.channels.len());
    for name in &spec.channels {
        let Some(i) = channels.iter().position(|c| &c.name == name) else {
            return Err(AttackError::UnknownChannel {
                attack: attack.to_string(),
                channel: name.clone(),
                known: join_names(channels.iter().map(|c| c.name.as_str())),
            });
        };
        if targets.contains(&i) {
            return Err(AttackError::RepeatedChannel {
                attack: attack.to_string(),
                channel: name.clone(),
            });
        }
        targets.push(i);
    }
    Ok(targets)
}

/// A finite start, and an end (if any) that is finite and after it.
fn check_window(attack: &str, spec: &AttackSpec) -> Result<(), AttackError> {
    if !spec.start.is_finite() {
        return Err(invalid_field(
            attack,
            "start",
            spec.start,
            "a finite time in seconds",
        ));
    }
    if let Some(end) = spec.end {
        if !end.is_finite() {
            return Err(invalid_field(
                attack,
                "end",
                end,
                "a finite time in seconds (or omit it: forever)",
            ));
        }
        if end <= spec.start {
            return Err(AttackError::EmptyWindow {
                attack: attack.to_string(),
                start: spec.start,
                end,
            });
        }
    }
    Ok(())
}

/// The kind's parameters in range: finite values, positive caps, lengths and rates, a
/// probability in [0, 1], a replay recorded before it plays, one velocity per channel.
fn check_kind(attack: &str, spec: &AttackSpec) -> Result<(), AttackError> {
    let invalid = |field, value, expected| invalid_field(attack, field, value, expected);
    let finite = |field: &'static str, v: f64| {
        if v.is_finite() {
            Ok(())
        } else {
            Err(invalid(field, v, "a finite number"))
        }
    };
    let positive_cap = |field: &'static str, cap: Option<f64>| match cap {
        Some(c) if !(c.is_finite() && c > 0.0) => Err(invalid(field, c, "a finite number > 0")),
        _ => Ok(()),
    };
    match &spec.kind {
        AttackKind::Bias { value } => finite("value", *value)?,
        AttackKind::Ramp { rate, cap } => {
            finite("rate", *rate)?;
            positive_cap("cap", *cap)?;
        }
        AttackKind::Sinusoid {
            amplitude,
            frequency_hz,
            phase,
        } => {
            finite("amplitude", *amplitude)?;
            if !(frequency_hz.is_finite() && *frequency_hz >= 0.0) {
                return Err(invalid(
                    "frequency_hz",
                    *frequency_hz,
                    "a finite number >= 0",
                ));
            }
            finite("phase", *phase)?;
        }
        AttackKind::Freeze { value } => {
            if let Some(v) = value {
                finite("value", *v)?;
            }
        }
        AttackKind::Replay {
            record_start,
            length,
        } => {
            finite("record_start", *record_start)?;
            if *record_start < 0.0 {
                return Err(invalid(
                    "record_start",
                    *record_start,
                    "a time in [0, start - length] s: the recording is made during the run, which starts at t = 0",
                ));
            }
            if !(length.is_finite() && *length > 0.0) {
                return Err(invalid("length", *length, "a finite duration > 0 s"));
            }
            let record_end = record_start + length;
            if record_end > spec.start + WINDOW_EPS {
                return Err(AttackError::ReplayOverlap {
                    attack: attack.to_string(),
                    record_start: *record_start,
                    record_end,
                    start: spec.start,
                });
            }
        }
        AttackKind::Dropout {} | AttackKind::NonFinite { .. } => {}
        AttackKind::Scale { factor } => finite("factor", *factor)?,
        AttackKind::Spikes {
            probability,
            magnitude,
        } => {
            if !(*probability >= 0.0 && *probability <= 1.0) {
                return Err(invalid(
                    "probability",
                    *probability,
                    "a probability in [0, 1]",
                ));
            }
            finite("magnitude", *magnitude)?;
        }
        AttackKind::Absurd { value } => finite("value", *value)?,
        AttackKind::Stealthy {
            max_rate,
            threshold,
            max_bias,
            ..
        } => {
            if !(max_rate.is_finite() && *max_rate > 0.0) {
                return Err(invalid("max_rate", *max_rate, "a finite rate > 0"));
            }
            if !(threshold.is_finite() && *threshold > 0.0) {
                return Err(invalid(
                    "threshold",
                    *threshold,
                    "a finite number of standard deviations > 0",
                ));
            }
            positive_cap("max_bias", *max_bias)?;
        }
        AttackKind::Coordinated { velocity, cap } => {
            if velocity.len() != spec.channels.len() {
                return Err(AttackError::VelocityLength {
                    attack: attack.to_string(),
                    got: velocity.len(),
                    expected: spec.channels.len(),
                });
            }
            for v in velocity {
                finite("velocity", *v)?;
            }
            positive_cap("cap", *cap)?;
        }
    }
    Ok(())
}

/// How a value-transforming injector changes the readings of one sample.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Effect {
    None,
    Add(f64),
    Mul(f64),
    Set(f64),
}

impl Effect {
    fn apply(self, v: f64) -> f64 {
        match self {
            Effect::None => v,
            Effect::Add(a) => v + a,
            Effect::Mul(m) => v * m,
            Effect::Set(s) => s,
        }
    }
}

/// Per-(injector, channel) mutable state.
#[derive(Debug, Clone)]
struct ChannelState {
    /// Effect decided at the last fresh sample (value-transforming kinds).
    effect: Effect,
    /// Spikes: this channel's random stream.
    rng: Option<ChaCha20Rng>,
    /// Stealthy: current bias magnitude and time of the last fresh sample in the window.
    beta: f64,
    last_fresh: Option<f64>,
    /// Freeze: last reading seen before the window, and the frozen value once active.
    last_value: Option<f64>,
    frozen: Option<f64>,
    /// Dropout: last delivered (value, age, tick time).
    delivered: Option<(f64, f64, f64)>,
    /// Replay: recorded (value, fresh, age).
    recording: Vec<(f64, bool, f64)>,
}

impl ChannelState {
    /// The state of a channel before its attack's window: nothing decided, seen or recorded.
    fn fresh(rng: Option<ChaCha20Rng>) -> Self {
        Self {
            effect: Effect::None,
            rng,
            beta: 0.0,
            last_fresh: None,
            last_value: None,
            frozen: None,
            delivered: None,
            recording: Vec::new(),
        }
    }
}

/// A validated injector with its state.
#[derive(Debug, Clone)]
struct Injector {
    spec: AttackSpec,
    targets: Vec<usize>,
    channels: Vec<ChannelState>,
    /// Replay: ticks played back so far.
    played: usize,
}

/// The composed attack/fault injectors of a run, in file order.
#[derive(Debug, Clone)]
pub struct AttackStack {
    injectors: Vec<Injector>,
}

impl AttackStack {
    /// Validates `specs` against `suite`'s channels and builds the stack. `seed` is the run seed;
    /// each random injector (spikes) draws from its own stream keyed by (attack index, channel name).
    pub fn new(specs: &[AttackSpec], suite: &SensorSuite, seed: u64) -> Result<Self, AttackError> {
        let targets = validate_attacks(specs, suite.specs())?;
        let injectors = specs
            .iter()
            .zip(targets)
            .enumerate()
            .map(|(index, (spec, targets))| {
                let channels = targets
                    .iter()
                    .map(|&c| {
                        ChannelState::fresh(matches!(spec.kind, AttackKind::Spikes { .. }).then(
                            || {
                                stream_rng(
                                    seed,
                                    "attack",
                                    &format!("{index}/{}", suite.specs()[c].name),
                                )
                            },
                        ))
                    })
                    .collect();
                Injector {
                    spec: spec.clone(),
                    targets,
                    channels,
                    played: 0,
                }
            })
            .collect();
        Ok(AttackStack { injectors })
    }

    /// The specs, in file order.
    pub fn specs(&self) -> impl Iterator<Item = &AttackSpec> + '_ {
        self.injectors.iter().map(|i| &i.spec)
    }

    /// Number of injectors.
    pub fn len(&self) -> usize {
        self.injectors.len()
    }

    /// `true` when there is no injector.
    pub fn is_empty(&self) -> bool {
        self.injectors.is_empty()
    }

    /// Channel indices targeted by attack `index`.
    pub fn targets(&self, index: usize) -> Option<&[usize]> {
        self.injectors.get(index).map(|i| i.targets.as_slice())
    }

    /// Indices of the attacks whose window contains `t` (for logging).
    pub fn active(&self, t: f64) -> impl Iterator<Item = usize> + '_ {
        self.injectors
            .iter()
            .enumerate()
            .filter(move |(_, inj)| inj.spec.contains(t))
            .map(|(i, _)| i)
    }

    /// `(label, start, end)` of every attack, in file order.
    pub fn windows(&self) -> Vec<(String, f64, Option<f64>)> {
        self.injectors
            .iter()
            .map(|i| (i.spec.display_label(), i.spec.start, i.spec.end))
            .collect()
    }

    /// Indices of the attacks whose channels do not all lie inside one single declared fault
    /// pattern (`patterns` as resolved by [`SensorSuite::resolve_patterns`]): such attacks break the
    /// thesis' fault model (supp(a_t) ⊆ F(r)), so no guarantee covers them.
    pub fn outside_fault_patterns(&self, patterns: &[Vec<usize>]) -> Vec<usize> {
        self.injectors
            .iter()
            .enumerate()
            .filter(|(_, inj)| {
                !patterns
                    .iter()
                    .any(|p| inj.targets.iter().all(|c| p.contains(c)))
            })
            .map(|(i, _)| i)
            .collect()
    }

    /// True when the attacks, taken together, touch channels of more than one declared fault
    /// pattern: the union of every attack's channels over the whole run (so also over windows
    /// that overlap, or follow one another) lies inside no single pattern. The thesis' model has
    /// one fault pattern r, fixed but unknown, with supp(a_t) ⊆ F(r) at every t; attacks that
    /// each stay inside one pattern but together span two are outside it, and no guarantee
    /// applies. `false` when there is no attack.
    pub fn union_outside_fault_patterns(&self, patterns: &[Vec<usize>]) -> bool {
        let mut union: Vec<usize> = self
            .injectors
            .iter()
            .flat_map(|i| i.targets.iter().copied())
            .collect();
        union.sort_unstable();
        union.dedup();
        !union.is_empty() && !patterns.iter().any(|p| union.iter().all(|c| p.contains(c)))
    }

    /// Applies every injector, in file order, to this tick's `samples` (suite order) at time `t`.
    /// Call once per control tick, after [`SensorSuite::sample`], with the detector's predictions
    /// for the coming update. Never panics on any reading (non-finite readings pass through the
    /// arithmetic).
    pub fn apply(&mut self, t: f64, samples: &mut [Sample], detector: &dyn DetectorView) {
        for inj in &mut self.injectors {
            inj.apply(t, samples, detector);
        }
    }
}

impl Injector {
    fn apply(&mut self, t: f64, samples: &mut [Sample], detector: &dyn DetectorView) {
        let spec = &self.spec;
        let active = spec.contains(t);
        match &spec.kind {
            AttackKind::Freeze { value } => {
                for (st, &c) in self.channels.iter_mut().zip(&self.targets) {
                    let Some(s) = samples.get_mut(c) else {
                        continue;
                    };
                    if active {
                        let frozen = *st
                            .frozen
                            .get_or_insert_with(|| value.or(st.last_value).unwrap_or(s.value));
                        s.value = frozen;
                    } else {
                        st.last_value = Some(s.value);
                    }
                }
            }
            AttackKind::Dropout {} => {
                for (st, &c) in self.channels.iter_mut().zip(&self.targets) {
                    let Some(s) = samples.get_mut(c) else {
                        continue;
                    };
                    if active {
                        s.fresh = false;
                        match st.delivered {
                            Some((value, age, t0)) => {
                                s.value = value;
                                s.age = age + (t - t0);
                            }
                            None => {
                                s.value = f64::NAN;
                                s.age = f64::INFINITY;
                            }
                        }
                    } else {
                        st.delivered = Some((s.value, s.age, t));
                    }
                }
            }
            AttackKind::Replay {
                record_start,
                length,
            } => {
                let recording = window_contains(*record_start, Some(record_start + length), t);
                for (st, &c) in self.channels.iter_mut().zip(&self.targets) {
                    let Some(s) = samples.get_mut(c) else {
                        continue;
                    };
                    if recording {
                        st.recording.push((s.value, s.fresh, s.age));
                    }
                    if active && !st.recording.is_empty() {
                        let (value, fresh, age) = st.recording[self.played % st.recording.len()];
                        s.value = value;
                        s.fresh = fresh;
                        s.age = age;
                    }
                }
                if active {
                    self.played += 1;
                }
            }
            kind => {
                for (j, (st, &c)) in self.channels.iter_mut().zip(&self.targets).enumerate() {
                    let Some(s) = samples.get_mut(c) else {
                        continue;
                    };
                    if s.fresh {
                        st.effect = if active {
                            fresh_effect(kind, spec, j, c, t, s.value, st, detector)
                        } else {
                            Effect::None
                        };
                    }
                    s.value = st.effect.apply(s.value);
                }
            }
        }
    }
}

/// A `stealthy` injector played against a linear model of the detector it hides under (the
/// liveness prediction's counterpart of [`open_loop_offset`], which lets the bias grow at its
/// largest rate): each call is one fresh reading, with the detector's honest innovation `nu`
/// (what the innovation would be without any attack), the offset `moved` the attack has
/// already given the detector's prediction c·x̂⁻, and its innovation standard deviation `s`.
/// The injector's own arithmetic (`fresh_effect`) decides the bias, so the played offset is the
/// one a run with those innovations injects.
#[derive(Debug, Clone)]
pub struct StealthyPlay {
    st: ChannelState,
}

impl Default for StealthyPlay {
    fn default() -> Self {
        Self {
            st: ChannelState::fresh(None),
        }
    }
}

impl StealthyPlay {
    /// What the injector adds to the `j`-th channel of `spec` at `t` (0 outside its window).
    pub fn offset(
        &mut self,
        spec: &AttackSpec,
        j: usize,
        t: f64,
        nu: f64,
        moved: f64,
        s: f64,
    ) -> f64 {
        if !spec.contains(t) {
            return 0.0;
        }
        // Offsets from the truth: the reading is the truth (0) and the prediction is off by
        // the attack's pull minus the honest innovation, so reading − prediction = nu − moved.
        let predicted = moved - nu;
        let detector = |_: usize| Some((predicted, s));
        let v = fresh_effect(&spec.kind, spec, j, 0, t, 0.0, &mut self.st, &detector).apply(0.0);
        if v.is_finite() {
            v
        } else {
            0.0
        }
    }
}

/// What the attack adds to a fresh reading of its `j`-th channel at time `t` when the true
/// value is `truth(t)`, played open loop: no detector feedback (a stealthy bias grows at its
/// largest rate), no random draws (spikes add nothing on average), readings the controller
/// rejects (non-finite, absurd) add nothing, a frozen channel holds its value (or the truth at
/// the window's start), a replayed one plays the truth recorded in its recording window. 0
/// outside the window. The injector's own arithmetic (`fresh_effect`) decides the value
/// kinds, so a prediction made from this matches what a run injects.
pub fn open_loop_offset(spec: &AttackSpec, j: usize, t: f64, truth: &dyn Fn(f64) -> f64) -> f64 {
    if !spec.contains(t) {
        return 0.0;
    }
    let now = truth(t);
    match &spec.kind {
        AttackKind::Freeze { value } => value.unwrap_or_else(|| truth(spec.start)) - now,
        AttackKind::Replay {
            record_start,
            length,
        } => {
            let played = if *length > 0.0 {
                (t - spec.start).rem_euclid(*length)
            } else {
                0.0
            };
            truth(record_start + played) - now
        }
        AttackKind::Dropout {} | AttackKind::NonFinite { .. } | AttackKind::Absurd { .. } => 0.0,
        kind => {
            let mut st = ChannelState::fresh(None);
            let v = fresh_effect(kind, spec, j, 0, t, now, &mut st, &NoDetector).apply(now);
            if v.is_finite() {
                v - now
            } else {
                0.0
            }
        }
    }
}

/// The effect a value-transforming injector applies to a fresh sample inside its window.
#[allow(clippy::too_many_arguments)]
fn fresh_effect(
    kind: &AttackKind,
    spec: &AttackSpec,
    j: usize,
    channel: usize,
    t: f64,
    reading: f64,
    st: &mut ChannelState,
    detector: &dyn DetectorView,
) -> Effect {
    let since = t - spec.start;
    match kind {
        AttackKind::Bias { value } => Effect::Add(*value),
        AttackKind::Ramp { rate, cap } => {
            let off = rate * since;
            Effect::Add(match cap {
                Some(c) => off.clamp(-c, *c),
                None => off,
            })
        }
        AttackKind::Sinusoid {
            amplitude,
            frequency_hz,
            phase,
        } => Effect::Add(
            amplitude * (2.0 * std::f64::consts::PI * frequency_hz * since + phase).sin(),
        ),
        AttackKind::Scale { factor } => Effect::Mul(*factor),
        AttackKind::Spikes {
            probability,
            magnitude,
        } => match st.rng.as_mut() {
            Some(rng) => {
                let u: f64 = rng.random();
                let up: bool = rng.random();
                if u < *probability {
                    Effect::Add(if up { *magnitude } else { -magnitude })
                } else {
                    Effect::None
                }
            }
            None => Effect::None,
        },
        AttackKind::NonFinite { value } => Effect::Set(value.value()),
        AttackKind::Absurd { value } => Effect::Set(*value),
        AttackKind::Coordinated { velocity, cap } => {
            let norm = velocity
                .iter()
                .map(|v| v * since)
                .map(|o| o * o)
                .sum::<f64>()
                .sqrt();
            let scale = match cap {
                Some(c) if norm > *c => c / norm,
                _ => 1.0,
            };
            Effect::Add(velocity.get(j).copied().unwrap_or(0.0) * since * scale)
        }
        AttackKind::Stealthy {
            max_rate,
            threshold,
            direction,
            max_bias,
        } => {
            let d = direction.sign();
            let elapsed = (t - st.last_fresh.unwrap_or(spec.start)).max(0.0);
            st.last_fresh = Some(t);
            let cap = max_bias.unwrap_or(f64::INFINITY);
            let mut beta = (st.beta + max_rate * elapsed).min(cap);
            if let Some((predicted, std)) = detector.predicted(channel) {
                if predicted.is_finite() && std.is_finite() && std > 0.0 && reading.is_finite() {
                    let own = d * (reading - predicted);
                    // Aim a relative 1e-9 inside the bound so rounding cannot tip it over.
                    let bound = threshold * std * (1.0 - 1e-9);
                    let hi = bound - own;
                    let lo = -bound - own;
                    beta = beta.min(hi).max(lo.min(cap));
                }
            }
            st.beta = beta.max(0.0);
            Effect::Add(d * st.beta)
        }
        // Tick-based kinds are handled by the caller.
        AttackKind::Freeze { .. } | AttackKind::Replay { .. } | AttackKind::Dropout {} => {
            Effect::None
        }
    }
}
