//! The yaw the drive linearises about and the odometry is turned with, kept step by step from
//! the heading channel's samples (and its gyro fusion): per-run state of the closed loop.

use ftcbf_controller::odometry;

use crate::sensors::wrap_angle;
use crate::world::structure::{heading_fusion, heading_sensor};
use crate::world::World;

/// Where the yaw comes from that the drive linearises about and that wheel odometry is turned
/// into world-frame velocity with: the heading channel's reading, or its fusion with the gyro.
#[derive(Debug, Clone)]
pub struct HeadingSource {
    channel: Option<usize>,
    fusion: Option<(usize, odometry::HeadingFilter)>,
    /// A fresh reading of a noisy heading channel that repeats the last one bit for bit is a
    /// stuck sensor (a driver republishing its last message, a `freeze` attack).
    repeats: odometry::RepeatDetector,
    /// Fresh readings refused as repeats.
    stuck: u64,
    /// The heading the drive linearises about \[rad\].
    drive: f64,
}

impl HeadingSource {
    /// The source `world` declares; a heading filter starts at the world's start yaw, and the
    /// drive's heading at `start_yaw` (the plant's true start).
    pub fn new(world: &World, start_yaw: f64) -> Self {
        let start = world
            .file
            .robot
            .as_ref()
            .map_or(f64::NAN, |r| r.start.theta);
        let channel = heading_sensor(world);
        Self {
            channel,
            fusion: heading_fusion(world)
                .map(|(g, p)| (g, odometry::HeadingFilter::started_at(p, start))),
            repeats: odometry::RepeatDetector::new(
                channel.map_or(0.0, |h| world.file.sensors[h].noise_std),
            ),
            stuck: 0,
            drive: start_yaw,
        }
    }

    /// Fresh heading readings refused so far: repeats of the previous one bit for bit (a noisy
    /// channel), and with fusion also readings outside the filter's innovation gate.
    pub fn refused_readings(&self) -> u64 {
        self.stuck + self.fusion.as_ref().map_or(0, |(_, f)| f.rejected())
    }

    /// The heading \[rad\] the drive linearises about ([`HeadingSource::update`] keeps it).
    pub fn drive_yaw(&self) -> f64 {
        self.drive
    }

    /// Takes this tick's samples as received (attacks included) and returns the yaw \[rad\] the
    /// odometry is turned with: the heading channel's current sample, or with fusion the
    /// filter's yaw after it integrated the gyro over `dt` and took a fresh compass reading.
    /// NaN while there is none or when it is outside [−π, π] (malformed: the odometry made with
    /// it is then NaN, which the controller rejects).
    ///
    /// The drive's heading takes a new, well-formed yaw; otherwise (malformed, stuck, denied,
    /// between a slow compass's samples) it dead-reckons with `omega` [rad/s], the yaw rate the
    /// drive executed over the last period, instead of holding a stale heading while the robot
    /// turns.
    pub fn update(&mut self, samples: &[crate::sensors::Sample], dt: f64, omega: f64) -> f64 {
        let (yaw, new_reading) = match (self.channel, &mut self.fusion) {
            (None, _) => (f64::NAN, false),
            (Some(h), None) => {
                let s = samples[h];
                let repeated = s.fresh && self.repeats.is_repeat(s.value);
                self.stuck += u64::from(repeated);
                (s.value, s.fresh && !repeated)
            }
            // The filter refuses repeats itself (and gates jumps against the gyro).
            (Some(h), Some((g, filter))) => {
                filter.predict(samples[*g].value, dt);
                if samples[h].fresh {
                    filter.correct(samples[h].value);
                }
                (filter.yaw(), true)
            }
        };
        let yaw = if odometry::valid_yaw(yaw) {
            yaw
        } else {
            f64::NAN
        };
        self.drive = if new_reading && !yaw.is_nan() {
            yaw
        } else {
            wrap_angle(self.drive + omega * dt)
        };
        yaw
    }
}
