//! The attack family `falsify` searches: one declared fault pattern, one injector kind, and a
//! point z ∈ [0, 1]^D that the decoder turns into `[[attacks]]` entries on that pattern's channels.
//!
//! Layout of z (D = 5 + the most channels any pattern has):
//!
//! | index | meaning |
//! |---|---|
//! | 0 | onset: `start = z₀ · 0.75 · T` (T = the world's duration; replay: at least 0.1 · T) |
//! | 1 | duration: `end = start + 1.25 · z₁ · (T − start)`; an end at or after T means "forever" |
//! | 2 | magnitude or rate, log-uniform over the kind's range (below), times the channel scale |
//! | 3 | the kind's second parameter (frequency, threshold, probability, factor, …) |
//! | 4 | the kind's third parameter (phase, cap, largest bias, recording length) |
//! | 5 + i | weight wᵢ = 2 z − 1 of the pattern's i-th channel: the channel is attacked iff \|wᵢ\| ≥ 0.2 (if none is, the largest \|wᵢ\|), with sign sign(wᵢ) and relative size \|wᵢ\| / maxⱼ \|wⱼ\| |
//!
//! The [`Family::Fallback`] kinds read the same z with their own meanings (see [`Family`]);
//! `timed_ramp` reads z₀, z₁ and z₃ as the moment of its full offset, its growth time and its
//! hold.
//!
//! Channel scale: 1 m for x and y; 0.5 m/s for vx and vy; 0.2 m/s for a (wheel-odometry) speed;
//! 0.5 rad for a heading and 0.5 rad/s for a yaw rate; 6 rad/s for a wheel encoder (0.2 m/s on a
//! TurtleBot3 wheel). A stealthy attacker on a channel the filters do not read directly (a speed
//! turned into world-frame velocity, an encoder, the heading) has no detector to hide under and
//! grows at its rate up to its cap. Every decoded number is rounded to four
//! significant digits, so the written world file is readable and replays the evaluated attack
//! exactly.

use std::f64::consts::PI;

use ftcbf_sim::attacks::{AttackKind, AttackSpec, Direction, NonFiniteValue};
use ftcbf_sim::sensors::Quantity;
use ftcbf_sim::world::World;
use serde::{Deserialize, Serialize};

/// Number of z coordinates before the channel weights.
const HEAD: usize = 5;
/// A channel whose |weight| is below this is not attacked.
const CHANNEL_ON: f64 = 0.2;

/// The injector kinds of `sim/src/attacks.rs`, all of which the search covers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Kind {
    /// Constant offset.
    Bias,
    /// Offset growing at a rate, optionally capped.
    Ramp,
    /// Sinusoidal offset.
    Sinusoid,
    /// Reading held at its last value.
    Freeze,
    /// Earlier readings played back.
    Replay,
    /// Denial of service.
    Dropout,
    /// Reading multiplied.
    Scale,
    /// Random outliers.
    Spikes,
    /// NaN / ±∞.
    NonFinite,
    /// A finite absurd value (below 10⁶ it is not rejected by the controller).
    Absurd,
    /// Bias growing as fast as the detector allows.
    Stealthy,
    /// Channels spoofed consistently along a path.
    Coordinated,
    /// Fallback family: a stealthy bias whose detector threshold sits around the edge of the
    /// safe stop's evidence test, held at a size.
    Undercut,
    /// Fallback family: a ramp timed to reach its full offset at a chosen moment, then held.
    TimedRamp,
    /// Fallback family: a slow sinusoid, so the rows conflict, agree and conflict again.
    Alternating,
    /// Fallback family: the pattern's channels spoofed along one direction up to a held offset
    /// (the two estimates kept a chosen distance apart).
    HeldOffset,
}

/// Every injector kind, in a fixed order (the categorical distribution's index): the
/// [`Family::Injectors`] family.
pub const KINDS: [Kind; 12] = [
    Kind::Bias,
    Kind::Ramp,
    Kind::Sinusoid,
    Kind::Freeze,
    Kind::Replay,
    Kind::Dropout,
    Kind::Scale,
    Kind::Spikes,
    Kind::NonFinite,
    Kind::Absurd,
    Kind::Stealthy,
    Kind::Coordinated,
];

/// The [`Family::Fallback`] family, aimed at the safe stop's weak spots (see [`Family`]).
pub const FALLBACK_KINDS: [Kind; 4] = [
    Kind::Undercut,
    Kind::TimedRamp,
    Kind::Alternating,
    Kind::HeldOffset,
];

/// Which attacks a search draws from.
///
/// - `Injectors` (the default): every injector kind of the simulator over its whole range.
/// - `Fallback`: attacks aimed at the safe stop (`[control] fallback = "brake"`, issue #50),
///   which brakes where the kept units' rows conflict and the residues are no evidence. Its
///   weak spots are a liar that stays under the evidence test while it misleads the rows, an
///   offset that keeps two estimates just close enough for the saturated rule to weigh the
///   lying row instead of braking, a ramp whose full offset arrives when the robot is at its
///   closest to a wall, and a conflict that comes and goes (each resume starts from the honest
///   estimate's margin less the braking distance). Each kind puts one of these regions inside
///   [0, 1]^D, so the CEM and CMA-ES can reach it:
///   - `undercut`: `stealthy` with its detector threshold in [0.5, 3] σ (the evidence test's
///     z_α = 4.753 over a 1 s window is reached by a steady 1.35 σ per reading at 100 readings a
///     second, two channels at 50 Hz, and by 2.2 σ at 10), its largest rate log-uniform in
///     [0.002, 0.5]·scale and always capped (log-uniform in [0.02, 3]·scale);
///   - `timed_ramp`: `ramp` capped at its full offset (log-uniform in [0.02, 3]·scale), which
///     it reaches at t_full = (0.05 + 0.9·z₀)·T after growing for a share z₁ of t_full (at
///     least 0.5 s), held until `end` (z₃; 1.25·z₃·(T − t_full) after t_full, "forever" past T);
///   - `alternating`: `sinusoid` of amplitude log-uniform in [0.02, 3]·scale and frequency
///     log-uniform in [0.005, 0.2] Hz (a period of 5 to 200 s), phase 2π·z₄;
///   - `held_offset`: `coordinated` at a speed log-uniform in [0.002, 0.2]·scale per channel,
///     always capped at a norm log-uniform in [0.02, 2]·scale.
///
/// The objective is the same as the injectors' ([`super::Robustness`]): the run's ρ, the
/// minimum over time of the true clearance and of h(x_true); the family decides where the
/// search looks, not what it minimises.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Family {
    /// Every injector kind ([`KINDS`]).
    #[default]
    Injectors,
    /// The attacks aimed at the safe stop ([`FALLBACK_KINDS`]).
    Fallback,
}

impl Family {
    /// The kinds of the family, in the categorical distribution's order.
    pub fn kinds(self) -> &'static [Kind] {
        match self {
            Family::Injectors => &KINDS,
            Family::Fallback => &FALLBACK_KINDS,
        }
    }

    /// The `--family` value.
    pub fn name(self) -> &'static str {
        match self {
            Family::Injectors => "injectors",
            Family::Fallback => "fallback",
        }
    }
}

impl Kind {
    /// The search's name of the kind (the world file's `kind` string for an injector kind; a
    /// [`Family::Fallback`] kind names the shape it gives an injector, see [`Kind::injector`]).
    pub fn name(self) -> &'static str {
        match self {
            Kind::Bias => "bias",
            Kind::Ramp => "ramp",
            Kind::Sinusoid => "sinusoid",
            Kind::Freeze => "freeze",
            Kind::Replay => "replay",
            Kind::Dropout => "dropout",
            Kind::Scale => "scale",
            Kind::Spikes => "spikes",
            Kind::NonFinite => "non_finite",
            Kind::Absurd => "absurd",
            Kind::Stealthy => "stealthy",
            Kind::Coordinated => "coordinated",
            Kind::Undercut => "undercut",
            Kind::TimedRamp => "timed_ramp",
            Kind::Alternating => "alternating",
            Kind::HeldOffset => "held_offset",
        }
    }

    /// The world file's `kind` string of the entries the kind decodes to.
    pub fn injector(self) -> &'static str {
        match self {
            Kind::Undercut => "stealthy",
            Kind::TimedRamp => "ramp",
            Kind::Alternating => "sinusoid",
            Kind::HeldOffset => "coordinated",
            k => k.name(),
        }
    }
}

/// One declared fault pattern: its name and channels (name, what it measures).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Pattern {
    /// The pattern's name in the world file.
    pub name: String,
    /// Its channels, in the world file's order.
    pub channels: Vec<(String, Quantity)>,
}

/// A point of the search space.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Candidate {
    /// Index of the fault pattern.
    pub pattern: usize,
    /// Injector kind.
    pub kind: Kind,
    /// The continuous parameters, each in [0, 1].
    pub z: Vec<f64>,
}

impl Candidate {
    /// The same pattern and kind with continuous parameters `z`.
    pub fn with_z(&self, z: &[f64]) -> Candidate {
        Candidate {
            pattern: self.pattern,
            kind: self.kind,
            z: z.to_vec(),
        }
    }
}

/// The search space of one world: its fault patterns and duration.
#[derive(Debug, Clone)]
pub struct SearchSpace {
    /// The declared fault patterns.
    pub patterns: Vec<Pattern>,
    /// The world's duration T \[s\].
    pub duration: f64,
    /// Length of z.
    pub dim: usize,
    /// The attacks searched.
    pub family: Family,
}

/// Why a world cannot be searched.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SpaceError {
    /// No `[[fault_patterns]]`: the threat model allows no attack.
    #[error("the world declares no [[fault_patterns]], so the threat model allows no attack to search; declare the channels that may fail together")]
    NoPatterns,
}

/// The channels of `pattern` a candidate attacks, with signed relative weights (the largest
/// magnitude 1): those whose weight reaches [`CHANNEL_ON`], or else the strongest one.
fn attacked_channels(pattern: &Pattern, z: &dyn Fn(usize) -> f64) -> Vec<(usize, f64)> {
    let weights: Vec<f64> = (0..pattern.channels.len())
        .map(|i| 2.0 * z(HEAD + i) - 1.0)
        .collect();
    let wmax = weights.iter().fold(0.0f64, |m, w| m.max(w.abs()));
    let mut on: Vec<(usize, f64)> = weights
        .iter()
        .enumerate()
        .filter(|(_, w)| w.abs() >= CHANNEL_ON)
        .map(|(i, &w)| (i, if wmax > 0.0 { w / wmax } else { 1.0 }))
        .collect();
    if on.is_empty() {
        let (i, w) = weights
            .iter()
            .enumerate()
            .fold((0, 0.0f64), |(bi, bw), (i, &w)| {
                if w.abs() > bw.abs() {
                    (i, w)
                } else {
                    (bi, bw)
                }
            });
        on.push((i, if w < 0.0 { -1.0 } else { 1.0 }));
    }
    on
}

/// A candidate being turned into attack entries: its pattern, attacked channels and window.
struct Decoding<'a> {
    pattern: &'a Pattern,
    c: &'a Candidate,
    on: Vec<(usize, f64)>,
    start: f64,
    end: Option<f64>,
    /// How long a [`Kind::TimedRamp`] grows before its full offset (0 for other kinds) \[s\].
    ramp_time: f64,
}

impl Decoding<'_> {
    /// The candidate's entries, one per attacked channel or one for them all, by kind.
    fn specs(&self) -> Vec<AttackSpec> {
        let (c, pattern, on, start, end) = (self.c, self.pattern, &self.on, self.start, self.end);
        let z = |i: usize| c.z.get(i).copied().unwrap_or(0.5).clamp(0.0, 1.0);
        let names: Vec<String> = on
            .iter()
            .map(|&(i, _)| pattern.channels[i].0.clone())
            .collect();
        let sc = |i: usize| scale(pattern.channels[i].1);
        let cap = |a: f64, i: usize| {
            (a >= 0.5).then(|| round4(sc(i) * log_range(2.0 * (a - 0.5), 0.05, 3.0)))
        };
        let spec = |channels: Vec<String>, kind: AttackKind| AttackSpec {
            label: None,
            channels,
            start,
            end,
            kind,
        };
        let per_channel = |f: &dyn Fn(usize, f64) -> AttackKind| -> Vec<AttackSpec> {
            on.iter()
                .map(|&(i, w)| spec(vec![pattern.channels[i].0.clone()], f(i, w)))
                .collect()
        };
        match c.kind {
            Kind::Bias => per_channel(&|i, w| AttackKind::Bias {
                value: round4(w * sc(i) * log_range(z(2), 0.01, 3.0)),
            }),
            Kind::Ramp => per_channel(&|i, w| AttackKind::Ramp {
                rate: round4(w * sc(i) * log_range(z(2), 0.002, 0.5)),
                cap: cap(z(4), i),
            }),
            Kind::Sinusoid => per_channel(&|i, w| AttackKind::Sinusoid {
                amplitude: round4(w * sc(i) * log_range(z(2), 0.01, 3.0)),
                frequency_hz: round4(log_range(z(3), 0.01, 2.0)),
                phase: round4(2.0 * PI * z(4)),
            }),
            Kind::Freeze => vec![spec(names, AttackKind::Freeze { value: None })],
            Kind::Replay => {
                let record_start = round4(z(3) * 0.9 * start);
                let length = round4(((start - record_start) * (0.05 + 0.95 * z(4))).max(0.02));
                let length = if record_start + length > start {
                    start - record_start
                } else {
                    length
                };
                vec![spec(
                    names,
                    AttackKind::Replay {
                        record_start,
                        length,
                    },
                )]
            }
            Kind::Dropout => vec![spec(names, AttackKind::Dropout {})],
            Kind::Scale => vec![spec(
                names,
                AttackKind::Scale {
                    factor: round4(-1.0 + 4.0 * z(3)),
                },
            )],
            Kind::Spikes => {
                let i = on[0].0;
                vec![spec(
                    names,
                    AttackKind::Spikes {
                        probability: round4(log_range(z(3), 0.01, 0.5)),
                        magnitude: round4(sc(i) * log_range(z(2), 0.05, 5.0)),
                    },
                )]
            }
            Kind::NonFinite => {
                let value = match (z(3) * 3.0) as usize {
                    0 => NonFiniteValue::Nan,
                    1 => NonFiniteValue::PosInf,
                    _ => NonFiniteValue::NegInf,
                };
                vec![spec(names, AttackKind::NonFinite { value })]
            }
            Kind::Absurd => per_channel(&|_, w| AttackKind::Absurd {
                value: round4(w.signum() * 10f64.powf(3.0 + 9.0 * z(2))),
            }),
            Kind::Stealthy => per_channel(&|i, w| AttackKind::Stealthy {
                max_rate: round4(w.abs() * sc(i) * log_range(z(2), 0.002, 0.5)),
                threshold: round4(0.5 + 3.5 * z(3)),
                direction: if w < 0.0 {
                    Direction::Negative
                } else {
                    Direction::Positive
                },
                max_bias: cap(z(4), i),
            }),
            Kind::Coordinated => {
                let velocity = on
                    .iter()
                    .map(|&(i, w)| round4(w * sc(i) * log_range(z(2), 0.002, 0.5)))
                    .collect();
                vec![spec(
                    names,
                    AttackKind::Coordinated {
                        velocity,
                        cap: cap(z(4), on[0].0),
                    },
                )]
            }
            Kind::Undercut | Kind::TimedRamp | Kind::Alternating | Kind::HeldOffset => {
                self.fallback_specs()
            }
        }
    }
}

impl Decoding<'_> {
    /// The entries of a [`Family::Fallback`] kind (see [`Family`]).
    fn fallback_specs(&self) -> Vec<AttackSpec> {
        let (c, pattern, on) = (self.c, self.pattern, &self.on);
        let z = |i: usize| c.z.get(i).copied().unwrap_or(0.5).clamp(0.0, 1.0);
        let sc = |i: usize| scale(pattern.channels[i].1);
        let spec = |channels: Vec<String>, kind: AttackKind| AttackSpec {
            label: None,
            channels,
            start: self.start,
            end: self.end,
            kind,
        };
        let per_channel = |f: &dyn Fn(usize, f64) -> AttackKind| -> Vec<AttackSpec> {
            on.iter()
                .map(|&(i, w)| spec(vec![pattern.channels[i].0.clone()], f(i, w)))
                .collect()
        };
        let names: Vec<String> = on
            .iter()
            .map(|&(i, _)| pattern.channels[i].0.clone())
            .collect();
        match c.kind {
            Kind::Undercut => per_channel(&|i, w| AttackKind::Stealthy {
                max_rate: round4(w.abs() * sc(i) * log_range(z(2), 0.002, 0.5)),
                threshold: round4(0.5 + 2.5 * z(3)),
                direction: if w < 0.0 {
                    Direction::Negative
                } else {
                    Direction::Positive
                },
                max_bias: Some(round4(w.abs() * sc(i) * log_range(z(4), 0.02, 3.0))),
            }),
            Kind::TimedRamp => {
                // The window starts when the ramp does: its full offset arrives `ramp_time`
                // later.
                let grow = self.ramp_time.max(0.02);
                per_channel(&|i, w| {
                    let full = w * sc(i) * log_range(z(2), 0.02, 3.0);
                    AttackKind::Ramp {
                        rate: round4(full / grow),
                        cap: Some(round4(full.abs())),
                    }
                })
            }
            Kind::Alternating => per_channel(&|i, w| AttackKind::Sinusoid {
                amplitude: round4(w * sc(i) * log_range(z(2), 0.02, 3.0)),
                frequency_hz: round4(log_range(z(3), 0.005, 0.2)),
                phase: round4(2.0 * PI * z(4)),
            }),
            Kind::HeldOffset => {
                let velocity = on
                    .iter()
                    .map(|&(i, w)| round4(w * sc(i) * log_range(z(2), 0.002, 0.2)))
                    .collect();
                vec![spec(
                    names,
                    AttackKind::Coordinated {
                        velocity,
                        cap: Some(round4(sc(on[0].0) * log_range(z(4), 0.02, 2.0))),
                    },
                )]
            }
            // The injector kinds.
            _ => self.specs(),
        }
    }
}

/// The window of a [`Kind::TimedRamp`] candidate in a run of `t_end` seconds: `(start, end,
/// growth time)`. The full offset arrives at t_full = (0.05 + 0.9·z₀)·T after a growth of
/// max(0.5 s, z₁·t_full) (at most t_full); it is held for 1.25·z₃·(T − t_full), "forever"
/// (`None`) when that reaches T.
fn timed_window(z: &dyn Fn(usize) -> f64, t_end: f64) -> (f64, Option<f64>, f64) {
    let t_full = (0.05 + 0.9 * z(0)) * t_end;
    let grow = (z(1) * t_full).max(0.5).min(t_full);
    let start = round4(t_full - grow);
    let end_raw = t_full + 1.25 * z(3) * (t_end - t_full);
    let end = (end_raw < t_end).then(|| round4(end_raw.max(start + 0.02)));
    (start, end, t_full - start)
}

/// The channel scale used for magnitudes and rates [unit].
fn scale(q: Quantity) -> f64 {
    match q {
        Quantity::X | Quantity::Y => 1.0,
        Quantity::Vx | Quantity::Vy | Quantity::Heading | Quantity::YawRate => 0.5,
        Quantity::Speed => 0.2,
        Quantity::WheelLeft | Quantity::WheelRight => 6.0,
    }
}

/// `lo · (hi / lo)^a`: log-uniform in [lo, hi] for a uniform a ∈ [0, 1].
fn log_range(a: f64, lo: f64, hi: f64) -> f64 {
    lo * (hi / lo).powf(a.clamp(0.0, 1.0))
}

/// Rounds to four significant digits (exact zero stays zero).
fn round4(x: f64) -> f64 {
    if x == 0.0 || !x.is_finite() {
        return x;
    }
    format!("{x:.3e}").parse().unwrap_or(x)
}

impl SearchSpace {
    /// The search space of `world`: its declared fault patterns, whatever their channels measure.
    pub fn new(world: &World) -> Result<Self, SpaceError> {
        let f = &world.file;
        if world.patterns.is_empty() {
            return Err(SpaceError::NoPatterns);
        }
        let mut patterns = Vec::with_capacity(world.patterns.len());
        for (spec, idx) in f.fault_patterns.iter().zip(&world.patterns) {
            let mut channels = Vec::with_capacity(idx.len());
            for &c in idx {
                let ch = &f.sensors[c];
                channels.push((ch.name.clone(), ch.measures));
            }
            patterns.push(Pattern {
                name: spec.name.clone(),
                channels,
            });
        }
        let widest = patterns.iter().map(|p| p.channels.len()).max().unwrap_or(1);
        Ok(Self {
            patterns,
            duration: f.duration,
            dim: HEAD + widest,
            family: Family::Injectors,
        })
    }

    /// The same space searching `family`'s attacks.
    pub fn with_family(self, family: Family) -> Self {
        Self { family, ..self }
    }

    /// The kinds searched, in the categorical distribution's order.
    pub fn kinds(&self) -> &'static [Kind] {
        self.family.kinds()
    }

    /// The `[[attacks]]` entries of `c`: all on channels of pattern `c.pattern` (never of two
    /// patterns), in a fixed order.
    pub fn decode(&self, c: &Candidate) -> Vec<AttackSpec> {
        let pattern = &self.patterns[c.pattern.min(self.patterns.len() - 1)];
        let z = |i: usize| c.z.get(i).copied().unwrap_or(0.5).clamp(0.0, 1.0);
        let t_end = self.duration;
        let mut start = z(0) * 0.75 * t_end;
        if c.kind == Kind::Replay {
            start = start.max(0.1 * t_end);
        }
        let start = round4(start);
        let end_raw = start + 1.25 * z(1) * (t_end - start);
        let end = (end_raw < t_end).then(|| round4(end_raw.max(start + 0.02)));
        let (start, end, ramp_time) = if c.kind == Kind::TimedRamp {
            timed_window(&z, t_end)
        } else {
            (start, end, 0.0)
        };
        Decoding {
            pattern,
            c,
            on: attacked_channels(pattern, &z),
            start,
            end,
            ramp_time,
        }
        .specs()
    }

    /// A one-line description of `c`'s attack, e.g.
    /// `pattern gnss2: ramp[gnss2_y] rate = 0.05 from t = 3 s, forever`.
    pub fn describe(&self, c: &Candidate) -> String {
        let specs = self.decode(c);
        let window = specs.first().map_or(String::new(), |s| match s.end {
            Some(e) => format!("in [{}, {}) s", s.start, e),
            None => format!("from t = {} s, forever", s.start),
        });
        let parts: Vec<String> = specs
            .iter()
            .map(|s| format!("{} {}", s.display_label(), kind_params(&s.kind)))
            .collect();
        format!(
            "pattern {}: {} {window}",
            self.patterns[c.pattern.min(self.patterns.len() - 1)].name,
            parts.join("; ")
        )
    }
}

/// The kind's parameters as `key = value` text.
fn kind_params(k: &AttackKind) -> String {
    let opt = |v: &Option<f64>| v.map_or("none".to_string(), |v| v.to_string());
    match k {
        AttackKind::Bias { value } => format!("value = {value}"),
        AttackKind::Ramp { rate, cap } => format!("rate = {rate}, cap = {}", opt(cap)),
        AttackKind::Sinusoid {
            amplitude,
            frequency_hz,
            phase,
        } => format!("amplitude = {amplitude}, frequency_hz = {frequency_hz}, phase = {phase}"),
        AttackKind::Freeze { value } => format!("value = {}", opt(value)),
        AttackKind::Replay {
            record_start,
            length,
        } => format!("record_start = {record_start}, length = {length}"),
        AttackKind::Dropout {} => String::new(),
        AttackKind::Scale { factor } => format!("factor = {factor}"),
        AttackKind::Spikes {
            probability,
            magnitude,
        } => format!("probability = {probability}, magnitude = {magnitude}"),
        AttackKind::NonFinite { value } => format!("value = {}", value.value()),
        AttackKind::Absurd { value } => format!("value = {value}"),
        AttackKind::Stealthy {
            max_rate,
            threshold,
            direction,
            max_bias,
        } => format!(
            "max_rate = {max_rate}, threshold = {threshold}, direction = {}, max_bias = {}",
            if *direction == Direction::Negative {
                "negative"
            } else {
                "positive"
            },
            opt(max_bias)
        ),
        AttackKind::Coordinated { velocity, cap } => {
            format!("velocity = {velocity:?}, cap = {}", opt(cap))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn space() -> SearchSpace {
        SearchSpace {
            patterns: vec![
                Pattern {
                    name: "gnss1".into(),
                    channels: vec![("g1x".into(), Quantity::X), ("g1y".into(), Quantity::Y)],
                },
                Pattern {
                    name: "odo".into(),
                    channels: vec![("ovx".into(), Quantity::Vx)],
                },
            ],
            duration: 20.0,
            dim: HEAD + 2,
            family: Family::Injectors,
        }
    }

    #[test]
    fn every_kind_decodes_inside_one_pattern() {
        let s = space();
        let zs = [
            vec![0.0; 7],
            vec![1.0; 7],
            vec![0.5; 7],
            vec![0.3, 0.9, 0.7, 0.1, 0.8, 0.95, 0.05],
        ];
        for kind in KINDS.into_iter().chain(FALLBACK_KINDS) {
            for pattern in 0..2 {
                for z in &zs {
                    let c = Candidate {
                        pattern,
                        kind,
                        z: z.clone(),
                    };
                    let specs = s.decode(&c);
                    assert!(!specs.is_empty());
                    let allowed: Vec<&str> = s.patterns[pattern]
                        .channels
                        .iter()
                        .map(|(n, _)| n.as_str())
                        .collect();
                    for sp in &specs {
                        assert_eq!(sp.kind.name(), kind.injector());
                        assert!(!sp.channels.is_empty());
                        assert!(sp.channels.iter().all(|n| allowed.contains(&n.as_str())));
                        let latest = if kind == Kind::TimedRamp { 19.0 } else { 15.0 };
                        assert!((0.0..=latest).contains(&sp.start), "{sp:?}");
                        if let Some(e) = sp.end {
                            assert!(e > sp.start && e < 20.0, "{sp:?}");
                        }
                    }
                    // The specs pass the simulator's own validation.
                    let chans: Vec<ftcbf_sim::sensors::ChannelSpec> = s
                        .patterns
                        .iter()
                        .flat_map(|p| p.channels.iter())
                        .map(|(n, q)| ftcbf_sim::sensors::ChannelSpec::new(n.clone(), *q, 0.01))
                        .collect();
                    ftcbf_sim::attacks::validate_attacks(&specs, &chans)
                        .unwrap_or_else(|e| panic!("{kind:?} {z:?}: {e}"));
                }
            }
        }
    }

    #[test]
    fn weights_choose_channels_and_signs() {
        let s = space();
        // Channel 0 off (|w| = 0.1), channel 1 negative: one bias on g1y, negative.
        let c = Candidate {
            pattern: 0,
            kind: Kind::Bias,
            z: vec![0.0, 1.0, 1.0, 0.5, 0.5, 0.55, 0.0],
        };
        let specs = s.decode(&c);
        assert_eq!(specs.len(), 1);
        assert_eq!(specs[0].channels, vec!["g1y".to_string()]);
        assert_eq!(specs[0].kind, AttackKind::Bias { value: -3.0 });
        assert_eq!((specs[0].start, specs[0].end), (0.0, None));
        // Magnitude 0 of the log range is its lower end; the onset at z0 = 1 is 0.75 T.
        let c = Candidate {
            pattern: 0,
            kind: Kind::Ramp,
            z: vec![1.0, 0.0, 0.0, 0.5, 0.0, 1.0, 1.0],
        };
        let specs = s.decode(&c);
        assert_eq!(specs.len(), 2);
        assert_eq!(specs[0].start, 15.0);
        assert_eq!(specs[0].end, Some(15.02));
        assert_eq!(
            specs[1].kind,
            AttackKind::Ramp {
                rate: 0.002,
                cap: None
            }
        );
    }

    /// The fallback family's kinds put their regions where the docs say: a timed ramp's full
    /// offset arrives at t_full and is held; the undercut's threshold straddles the evidence
    /// edge (≈ 1.35 σ at 100 readings a second) and its bias is capped; the alternation is
    /// slow; the held offset is always capped.
    #[test]
    fn fallback_kinds_decode_to_their_regions() {
        let s = space().with_family(Family::Fallback);
        assert_eq!(s.kinds(), &FALLBACK_KINDS[..]);
        let c = |kind, z: Vec<f64>| Candidate {
            pattern: 0,
            kind,
            z,
        };
        // t_full = (0.05 + 0.9 · 0.5) · 20 = 10 s, grown for 0.4 · 10 = 4 s, offset
        // 0.02 · 150^0.5 = 0.2449 m on g1x (weight +1), held forever (z₃ = 1).
        let specs = s.decode(&c(Kind::TimedRamp, vec![0.5, 0.4, 0.5, 1.0, 0.5, 1.0, 0.5]));
        assert_eq!(specs.len(), 1);
        assert_eq!((specs[0].start, specs[0].end), (6.0, None));
        let AttackKind::Ramp {
            rate,
            cap: Some(cap),
        } = specs[0].kind
        else {
            panic!("{specs:?}");
        };
        assert_eq!(cap, 0.2449);
        assert!((rate * 4.0 - cap).abs() < 1e-3, "{rate} · 4 s vs {cap}");
        // A short growth is at least 0.5 s; the hold ends before T when z₃ < 1.
        let specs = s.decode(&c(Kind::TimedRamp, vec![0.0, 0.0, 0.0, 0.2, 0.5, 0.0, 0.5]));
        assert_eq!(specs[0].start, 0.5);
        assert_eq!(specs[0].end, Some(round4(1.0 + 0.25 * 19.0)));
        assert!(
            matches!(specs[0].kind, AttackKind::Ramp { rate, cap: Some(cap) }
            if rate == -0.04 && cap == 0.02)
        );
        for (z3, want) in [(0.0, 0.5), (0.34, 1.35), (1.0, 3.0)] {
            let specs = s.decode(&c(Kind::Undercut, vec![0.1, 1.0, 0.5, z3, 0.0, 1.0, 0.5]));
            assert!(
                matches!(specs[0].kind, AttackKind::Stealthy { threshold, max_bias: Some(b), .. }
                if threshold == want && b == 0.02),
                "{specs:?}"
            );
        }
        let specs = s.decode(&c(
            Kind::Alternating,
            vec![0.1, 1.0, 1.0, 0.0, 0.25, 0.0, 0.5],
        ));
        assert!(
            matches!(specs[0].kind, AttackKind::Sinusoid { amplitude, frequency_hz, .. }
            if amplitude == -3.0 && frequency_hz == 0.005),
            "{specs:?}"
        );
        let specs = s.decode(&c(
            Kind::HeldOffset,
            vec![0.1, 1.0, 0.0, 0.5, 1.0, 1.0, 0.0],
        ));
        assert_eq!(specs.len(), 1);
        assert!(
            matches!(&specs[0].kind, AttackKind::Coordinated { velocity, cap: Some(cap) }
            if velocity == &vec![0.002, -0.002] && *cap == 2.0),
            "{specs:?}"
        );
    }

    #[test]
    fn rounding_keeps_four_digits() {
        assert_eq!(round4(0.123456), 0.1235);
        assert_eq!(round4(-98765.4), -98770.0);
        assert_eq!(round4(0.0), 0.0);
        assert_eq!(log_range(0.5, 0.01, 1.0), 0.1);
    }
}
