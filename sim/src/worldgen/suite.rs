//! The sensor suites of the book's "Your sensors" guide (book/src/guide/sensors.md), with
//! noise levels from the data sheets of the parts a user puts on a TurtleBot-class robot:
//! GNSS/UWB receivers 1–5 cm, their Doppler velocity 2–10 cm/s, a magnetometer or IMU yaw
//! 0.005–0.05 rad (0.02–0.1 rad when fused with a gyro, as a raw magnetometer indoors), a MEMS
//! gyro 0.005–0.02 rad/s with a turn-on bias of a few mrad/s, wheel odometry 0.5–2 cm/s,
//! encoders of 1024–4096 counts per revolution.

use rand::Rng;

use super::layout::pick;
use super::text::Sensor;
use super::Suite;

/// The sensors and fault patterns of one world.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Sensors {
    pub sensors: Vec<Sensor>,
    /// (name, channels): one per receiver, and one per other redundant source the suite has.
    pub patterns: Vec<(String, Vec<String>)>,
    /// The names of the patterns that are not a receiver's.
    pub other_patterns: Vec<String>,
    /// The phrase for the header.
    pub summary: String,
}

fn channel(name: String, measures: &'static str, noise: f64) -> Sensor {
    Sensor {
        name,
        measures,
        noise_std: Some(noise),
        ..Sensor::default()
    }
}

/// A receiver's x and y channels (and vx, vy when it reports velocity), one fault pattern.
fn receiver<R: Rng>(
    rng: &mut R,
    prefix: &str,
    k: usize,
    velocity: bool,
    out: &mut Sensors,
) -> Vec<String> {
    let sigma = pick(rng, 0.01, 0.05, 0.005);
    let rate = if rng.random_bool(0.35) {
        Some([5.0, 10.0, 20.0][rng.random_range(0..3)])
    } else {
        None
    };
    let dropout = if rng.random_bool(0.2) {
        Some(pick(rng, 0.01, 0.05, 0.01))
    } else {
        None
    };
    let mut names = Vec::new();
    for axis in ["x", "y"] {
        let name = format!("{prefix}{k}_{axis}");
        let mut c = channel(name.clone(), axis, sigma);
        c.rate_hz = rate;
        c.dropout_prob = dropout;
        if axis == "x" {
            c.comment = Some(format!("receiver {k}, east [m]"));
        }
        out.sensors.push(c);
        names.push(name);
    }
    if velocity {
        let sv = pick(rng, 0.02, 0.1, 0.01);
        for axis in ["vx", "vy"] {
            let name = format!("{prefix}{k}_{axis}");
            let mut c = channel(name.clone(), axis, sv);
            c.rate_hz = rate;
            if axis == "vx" {
                c.comment = Some(format!("receiver {k}'s velocity, east [m/s]"));
            }
            out.sensors.push(c);
            names.push(name);
        }
    }
    out.patterns.push((format!("{prefix}{k}"), names.clone()));
    names
}

/// A compass (or the IMU's yaw), fused with `gyro` when given.
fn compass<R: Rng>(rng: &mut R, gyro: Option<String>) -> Sensor {
    let fused = gyro.is_some();
    let mut c = channel(
        "compass".into(),
        "heading",
        if fused {
            pick(rng, 0.02, 0.1, 0.01)
        } else {
            pick(rng, 0.005, 0.05, 0.005)
        },
    );
    c.comment = Some("yaw from +x, counter-clockwise [rad]".into());
    if fused && rng.random_bool(0.5) {
        c.rate_hz = Some([10.0, 20.0][rng.random_range(0..2)]);
    }
    c.gyro = gyro;
    c
}

/// Draws the sensors of `suite`.
pub(crate) fn draw<R: Rng>(rng: &mut R, suite: Suite) -> Sensors {
    let prefix = if rng.random_bool(0.5) { "gnss" } else { "uwb" };
    let mut s = Sensors {
        sensors: Vec::new(),
        patterns: Vec::new(),
        other_patterns: Vec::new(),
        summary: String::new(),
    };
    match suite {
        Suite::TwoReceivers => {
            receiver(rng, prefix, 1, false, &mut s);
            receiver(rng, prefix, 2, false, &mut s);
            s.sensors.push(compass(rng, None));
            s.summary = format!("two {prefix} receivers (x, y) and an IMU heading");
        }
        Suite::ThreeReceivers => {
            for k in 1..=3 {
                receiver(rng, prefix, k, false, &mut s);
            }
            s.sensors.push(compass(rng, None));
            s.summary = format!("three {prefix} receivers (x, y) and a compass");
        }
        Suite::Odometry => {
            receiver(rng, prefix, 1, false, &mut s);
            receiver(rng, prefix, 2, false, &mut s);
            let odom = if rng.random_bool(0.5) {
                "odom"
            } else {
                "wheel_speed"
            };
            let mut o = channel(odom.into(), "speed", pick(rng, 0.005, 0.02, 0.005));
            o.comment = Some("wheel odometry, twist.linear.x [m/s]".into());
            s.sensors.push(o);
            s.sensors.push(compass(rng, None));
            // the odometry is a redundant velocity source: its own pattern, or with the compass
            // it is turned with (as in the catalogue's turtlebot_odometry_bias), or none
            match rng.random_range(0..5) {
                0 | 1 => s.patterns.push(("odometry".into(), vec![odom.into()])),
                2 => s
                    .patterns
                    .push(("odometry".into(), vec![odom.into(), "compass".into()])),
                _ => {}
            }
            s.summary = format!("two {prefix} receivers, wheel odometry and a compass");
        }
        Suite::Encoders => {
            receiver(rng, prefix, 1, false, &mut s);
            receiver(rng, prefix, 2, false, &mut s);
            let ticks = match rng.random_range(0..4) {
                0 => None,
                1 => Some(1024),
                _ => Some(4096),
            };
            for (name, side) in [("enc_left", "wheel_left"), ("enc_right", "wheel_right")] {
                let mut e = channel(name.into(), side, 0.0);
                e.ticks_per_rev = ticks;
                if side == "wheel_left" {
                    e.comment = Some("wheel encoder [rad/s]".into());
                }
                s.sensors.push(e);
            }
            s.sensors.push(Sensor {
                name: "odom".into(),
                measures: "speed",
                from_wheels: Some(["enc_left".into(), "enc_right".into()]),
                comment: Some("diff-drive odometry from the encoders".into()),
                ..Sensor::default()
            });
            let mut g = channel("gyro_z".into(), "yaw_rate", pick(rng, 0.005, 0.02, 0.001));
            g.bias = Some(pick(rng, 0.0, 0.005, 0.001)).filter(|b| *b != 0.0);
            if rng.random_bool(0.5) {
                g.bias_walk_std = Some(pick(rng, 0.0001, 0.001, 0.0001));
            }
            g.comment = Some("IMU angular_velocity.z [rad/s]".into());
            s.sensors.push(g);
            s.sensors.push(compass(rng, Some("gyro_z".into())));
            if rng.random_bool(0.5) {
                s.patterns.push((
                    "encoders".into(),
                    vec!["enc_left".into(), "enc_right".into()],
                ));
            }
            s.summary = format!(
                "two {prefix} receivers, wheel encoders → odometry, a gyro fused with a compass"
            );
        }
        Suite::ReceiverVelocity => {
            receiver(rng, prefix, 1, true, &mut s);
            receiver(rng, prefix, 2, false, &mut s);
            s.sensors.push(compass(rng, None));
            s.summary =
                format!("two {prefix} receivers, the first also reporting velocity, and a compass");
        }
    }
    s.other_patterns = s
        .patterns
        .iter()
        .map(|(n, _)| n.clone())
        .filter(|n| n == "odometry" || n == "encoders")
        .collect();
    s
}
