//! One attack inside one fault pattern, of a given kind, with an onset and a size a user would
//! choose for that kind of channel: a receiver spoofed by tens of centimetres to a metre, a
//! velocity by a few tenths of a m/s, a heading by a few tenths of a radian, an encoder by a few
//! rad/s.

use rand::Rng;

use super::layout::pick;
use super::text::{dec, Attack, Sensor, Value};

/// Every `kind` the world file accepts in `[[attacks]]` (book/src/reference/world-file.md, "Attack kinds").
pub const ATTACK_KINDS: [&str; 12] = [
    "bias",
    "ramp",
    "sinusoid",
    "freeze",
    "replay",
    "dropout",
    "scale",
    "spikes",
    "non_finite",
    "absurd",
    "stealthy",
    "coordinated",
];

/// The size of a plausible attack on a channel measuring `measures`, in its unit.
fn scale(measures: &str) -> f64 {
    match measures {
        "x" | "y" => 1.0,
        "vx" | "vy" => 0.3,
        "speed" => 0.1,
        "heading" | "yaw_rate" => 0.5,
        _ => 3.0, // wheel_left, wheel_right [rad/s]
    }
}

fn signed<R: Rng>(rng: &mut R, lo: f64, hi: f64, step: f64) -> f64 {
    let x = pick(rng, lo, hi, step);
    if rng.random_bool(0.5) {
        x
    } else {
        -x
    }
}

/// Draws an attack of `kind` on channels of the pattern `pattern` (its channel names): the
/// channels, the start, the kind's keys, the end, in that order from `rng`.
pub(crate) fn draw<R: Rng>(
    rng: &mut R,
    kind: &'static str,
    pattern: &[String],
    sensors: &[Sensor],
    duration: f64,
) -> Attack {
    let measures = |name: &str| {
        sensors
            .iter()
            .find(|s| s.name == name)
            .map_or("x", |s| s.measures)
    };
    let channels = draw_channels(rng, pattern, &measures);
    let mut start = pick(rng, 1.0, (0.4 * duration).max(2.0), 0.5);
    let keys = draw_keys(rng, kind, &channels, &mut start, &measures);
    let end = if rng.random_bool(0.3) {
        Some(dec(start + pick(rng, 3.0, 15.0, 0.5), 3))
    } else {
        None
    };
    Attack {
        kind,
        channels,
        start,
        end,
        keys,
    }
}

/// Which channels of `pattern` the attack hits: one of them, or all of them, or (a receiver
/// with velocity) its positions.
fn draw_channels<R: Rng>(
    rng: &mut R,
    pattern: &[String],
    measures: &dyn Fn(&str) -> &'static str,
) -> Vec<String> {
    let positions: Vec<String> = pattern
        .iter()
        .filter(|c| matches!(measures(c), "x" | "y"))
        .cloned()
        .collect();
    match rng.random_range(0..4) {
        0 | 1 if pattern.len() > 1 => vec![pattern[rng.random_range(0..pattern.len())].clone()],
        2 if positions.len() > 1 && positions.len() < pattern.len() => positions,
        _ => pattern.to_vec(),
    }
}

/// The keys of an attack of `kind` on `channels`, sized in the first channel's unit; a replay
/// moves `start` to after its recording.
fn draw_keys<R: Rng>(
    rng: &mut R,
    kind: &'static str,
    channels: &[String],
    start: &mut f64,
    measures: &dyn Fn(&str) -> &'static str,
) -> Vec<(&'static str, Value)> {
    let s = scale(measures(&channels[0]));
    let mut keys: Vec<(&'static str, Value)> = Vec::new();
    match kind {
        "bias" => keys.push(("value", Value::Num(dec(signed(rng, 0.1, 1.0, 0.05) * s, 3)))),
        "ramp" => {
            keys.push(("rate", Value::Num(dec(signed(rng, 0.02, 0.2, 0.01) * s, 4))));
            if rng.random_bool(0.5) {
                keys.push(("cap", Value::Num(dec(pick(rng, 0.3, 1.5, 0.1) * s, 3))));
            }
        }
        "sinusoid" => {
            keys.push((
                "amplitude",
                Value::Num(dec(pick(rng, 0.1, 0.6, 0.05) * s, 3)),
            ));
            keys.push(("frequency_hz", Value::Num(pick(rng, 0.05, 1.0, 0.05))));
            if rng.random_bool(0.5) {
                keys.push(("phase", Value::Num(pick(rng, 0.0, 3.1, 0.1))));
            }
        }
        "freeze" => {
            if channels.len() == 1 && rng.random_bool(0.4) {
                // stuck at zero: a receiver or sensor reporting its reset value
                keys.push(("value", Value::Num(0.0)));
            }
        }
        "replay" => {
            let length = pick(rng, 2.0, 6.0, 0.5);
            *start = start.max(length + 1.0);
            let record_start = pick(rng, 0.0, *start - length, 0.5);
            keys.push(("record_start", Value::Num(record_start)));
            keys.push(("length", Value::Num(length)));
        }
        "dropout" => {}
        "scale" => {
            let f = if rng.random_bool(0.5) {
                pick(rng, 0.5, 0.9, 0.05)
            } else {
                pick(rng, 1.1, 2.0, 0.05)
            };
            keys.push(("factor", Value::Num(f)));
        }
        "spikes" => {
            keys.push(("probability", Value::Num(pick(rng, 0.02, 0.3, 0.01))));
            keys.push((
                "magnitude",
                Value::Num(dec(pick(rng, 0.5, 3.0, 0.1) * s, 3)),
            ));
        }
        "non_finite" => {
            let v = ["nan", "inf", "-inf"][rng.random_range(0..3)];
            keys.push(("value", Value::Str(v.into())));
        }
        "absurd" => {
            if rng.random_bool(0.5) {
                let v = [1e6, -1e6, 1e9, 99999.0][rng.random_range(0..4)];
                keys.push(("value", Value::Num(v)));
            }
        }
        "stealthy" => {
            keys.push((
                "max_rate",
                Value::Num(dec(pick(rng, 0.01, 0.1, 0.01) * s, 4)),
            ));
            keys.push(("threshold", Value::Num(pick(rng, 1.0, 4.0, 0.5))));
            if rng.random_bool(0.5) {
                keys.push(("direction", Value::Str("negative".into())));
            }
            if rng.random_bool(0.5) {
                keys.push(("max_bias", Value::Num(dec(pick(rng, 0.2, 1.0, 0.1) * s, 3))));
            }
        }
        _ => {
            // coordinated: one offset velocity per channel, in that channel's unit
            let v: Vec<f64> = channels
                .iter()
                .map(|c| dec(signed(rng, 0.02, 0.2, 0.01) * scale(measures(c)), 4))
                .collect();
            keys.push(("velocity", Value::List(v)));
            if rng.random_bool(0.5) {
                keys.push(("cap", Value::Num(dec(pick(rng, 0.3, 1.5, 0.1) * s, 3))));
            }
        }
    }
    keys
}
