//! Readings as a ROS robot has them, turned into the channels of the linear model (6.2).
//!
//! Frames and signs follow REP-103 and REP-105:
//! - **World** (`map` or `odom`): ENU, x east, y north \[m\]. The model's state is
//!   (p_x, p_y, v_x, v_y) in this frame, and a GNSS fix (converted to local ENU) is a position
//!   reading in it.
//! - **Body** (`base_footprint`): x forward, y left, z up. Wheel odometry
//!   (`nav_msgs/Odometry` twist.linear.x) is the forward speed v [m/s] in this frame.
//! - **Yaw** θ \[rad\]: the heading of the body x axis, counter-clockwise from world +x, from an
//!   IMU orientation quaternion (`sensor_msgs/Imu` orientation) or a compass.
//!
//! A differential-drive robot does not slide sideways, so its world-frame velocity is
//! v·(cos θ, sin θ). With a measured yaw θ̂ = θ + e_θ, the converted velocity's error is
//! e_v·(cos θ̂, sin θ̂) + v·e_θ·(−sin θ, cos θ) to first order, and each axis' error variance is at
//! most σ_v² + v_max²·σ_θ² ([`world_velocity_variance`]). A yaw bias enters that bound as if it were
//! noise: conservative for the variance, but the error is then correlated in time, which the
//! filters do not model.
//!
//! A compass alone is often too noisy (a magnetometer near motors). [`HeadingFilter`] fuses it with
//! the IMU gyro (`sensor_msgs/Imu` angular_velocity.z, counter-clockwise positive): a two-state
//! Kalman filter on (θ, b_g) that integrates the gyro and estimates its bias from the compass.
//! [`fused_yaw_variance`] gives the yaw variance to put into [`world_velocity_variance`] for it.

/// Yaw \[rad\] from a unit quaternion (x, y, z, w) (`geometry_msgs/Quaternion`): the rotation
/// about the world z axis, in (−π, π].
pub fn yaw_from_quaternion(x: f64, y: f64, z: f64, w: f64) -> f64 {
    (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z))
}

/// World-frame velocity (v_x, v_y) [m/s] of a robot moving forward at `v` [m/s] with yaw `yaw`
/// \[rad\]. A non-finite input gives non-finite output, which the controller rejects as a
/// malformed reading.
pub fn body_speed_to_world_velocity(v: f64, yaw: f64) -> [f64; 2] {
    [v * yaw.cos(), v * yaw.sin()]
}

/// Variance [(m/s)²] to declare for each axis of [`body_speed_to_world_velocity`]:
/// σ_v² + v_max²·(σ_θ² + b_θ² + w_θ²·T). Here σ_v [m/s] is the speed noise, v_max [m/s] the
/// robot's speed bound, σ_θ \[rad\] the yaw noise, b_θ \[rad\] a yaw bias bound, and w_θ
/// [rad/√s] a yaw bias walk over the horizon T \[s\].
pub fn world_velocity_variance(
    speed_std: f64,
    v_max: f64,
    yaw_std: f64,
    yaw_bias: f64,
    yaw_walk_std: f64,
    horizon: f64,
) -> f64 {
    let yaw_var = yaw_std * yaw_std + yaw_bias * yaw_bias + yaw_walk_std * yaw_walk_std * horizon;
    speed_std * speed_std + v_max * v_max * yaw_var
}

/// `true` for a usable yaw reading \[rad\]: finite and in [−π, π] (a yaw from a quaternion, or a
/// wrapped compass, always is; anything else is a fault or an attack).
pub fn valid_yaw(yaw: f64) -> bool {
    yaw.abs() <= std::f64::consts::PI + 1e-9
}

/// Wraps an angle to (−π, π]. Non-finite input is returned unchanged.
pub fn wrap_angle(a: f64) -> f64 {
    use std::f64::consts::{PI, TAU};
    if !a.is_finite() {
        return a;
    }
    let w = (a + PI).rem_euclid(TAU) - PI;
    if w <= -PI {
        w + TAU
    } else {
        w
    }
}

/// Flags a stuck sensor: a sensor with noise never repeats a reading bit for bit, so a fresh
/// reading equal to the previous one is a driver republishing its last message (or a `freeze`
/// attack). For a noise-free sensor nothing is flagged.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RepeatDetector {
    noisy: bool,
    last: u64,
}

impl RepeatDetector {
    /// A detector for a sensor with noise σ `noise_std` (> 0: repeats are flagged).
    pub fn new(noise_std: f64) -> Self {
        Self {
            noisy: noise_std > 0.0,
            last: f64::NAN.to_bits(),
        }
    }

    /// `true` when the fresh `reading` repeats the previous fresh one bit for bit.
    pub fn is_repeat(&mut self, reading: f64) -> bool {
        let repeated = self.noisy && reading.to_bits() == self.last;
        self.last = reading.to_bits();
        repeated
    }
}

/// Noise figures of a [`HeadingFilter`], from the sensors' data sheets.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeadingFilterParams {
    /// Gyro white noise per reading [rad/s] (σ of one `angular_velocity.z` sample).
    pub gyro_std: f64,
    /// Gyro bias random walk [rad/s/√s].
    pub gyro_bias_walk: f64,
    /// 1σ of the gyro bias before the first reading [rad/s].
    pub gyro_bias_prior: f64,
    /// Compass (yaw reading) noise \[rad\].
    pub compass_std: f64,
    /// Gyro readings with |ω| above this [rad/s] are malformed and skipped (an IMU's full scale;
    /// 2000 °/s = 34.9 rad/s is common).
    pub gyro_range: f64,
    /// 1σ of the start yaw given to [`HeadingFilter::started_at`] \[rad\] (a marked start pose);
    /// ∞ when the start is unknown and the first compass reading starts the filter.
    pub initial_yaw_std: f64,
    /// Innovation gate \[σ\]: a compass reading further than this many standard deviations of the
    /// innovation from the gyro-propagated yaw is rejected (a frozen or jumping compass while the
    /// gyro sees the robot turn). The gate widens by itself while readings are rejected, since
    /// the yaw variance keeps growing with the gyro's noise and bias uncertainty.
    pub gate_sigma: f64,
}

impl HeadingFilterParams {
    /// Parameters with a 0.01 rad/s bias prior, a 34.9 rad/s (2000 °/s) gyro range, an unknown
    /// start yaw and a 5σ innovation gate.
    pub fn new(gyro_std: f64, gyro_bias_walk: f64, compass_std: f64) -> Self {
        Self {
            gyro_std,
            gyro_bias_walk,
            gyro_bias_prior: 0.01,
            compass_std,
            gyro_range: 34.9,
            initial_yaw_std: f64::INFINITY,
            gate_sigma: 5.0,
        }
    }
}

/// Yaw from gyro + compass: a Kalman filter on x = (θ, b_g), θ̇ = ω_gyro − b_g + noise,
/// ḃ_g = walk, corrected by compass readings of θ (innovations wrapped to (−π, π]).
/// Allocation-free. Non-finite or out-of-range readings are skipped (the estimate is held), so a
/// malformed reading cannot corrupt it; the yaw is NaN until the first compass reading.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeadingFilter {
    params: HeadingFilterParams,
    yaw: f64,
    bias: f64,
    /// Covariance [[P_θθ, P_θb], [P_θb, P_bb]].
    p: [f64; 3],
    /// Compass readings rejected (repeats of the last one, or outside the innovation gate).
    rejected: u64,
    repeats: RepeatDetector,
}

impl HeadingFilter {
    /// A filter that has seen nothing yet.
    pub fn new(params: HeadingFilterParams) -> Self {
        Self {
            params,
            yaw: f64::NAN,
            bias: 0.0,
            p: [f64::INFINITY, 0.0, params.gyro_bias_prior.powi(2)],
            rejected: 0,
            repeats: RepeatDetector::new(params.compass_std),
        }
    }

    /// A filter that starts at a known yaw `yaw` \[rad\] with σ `params.initial_yaw_std` (the
    /// robot set down at a marked pose); with an infinite σ it is [`HeadingFilter::new`].
    pub fn started_at(params: HeadingFilterParams, yaw: f64) -> Self {
        let mut f = Self::new(params);
        if params.initial_yaw_std.is_finite() && yaw.is_finite() {
            f.yaw = wrap_angle(yaw);
            f.p[0] = params.initial_yaw_std.powi(2);
        }
        f
    }

    /// Integrates one gyro reading `gyro` [rad/s] over `dt` \[s\]. Before the first compass
    /// reading only the bias uncertainty grows.
    pub fn predict(&mut self, gyro: f64, dt: f64) {
        if !(gyro.is_finite() && gyro.abs() <= self.params.gyro_range && dt > 0.0) {
            return;
        }
        if self.yaw.is_finite() {
            self.yaw = wrap_angle(self.yaw + (gyro - self.bias) * dt);
        }
        self.predict_covariance(dt);
    }

    /// P ← F P Fᵀ + Q with F = [[1, −dt], [0, 1]]; before the first compass reading only the
    /// bias variance grows. It does not depend on the readings.
    fn predict_covariance(&mut self, dt: f64) {
        let q_theta = (self.params.gyro_std * dt).powi(2);
        let q_bias = self.params.gyro_bias_walk.powi(2) * dt;
        let [a, b, c] = self.p;
        if self.yaw.is_finite() {
            self.p = [
                a - 2.0 * dt * b + dt * dt * c + q_theta,
                b - dt * c,
                c + q_bias,
            ];
        } else {
            self.p[2] = c + q_bias;
        }
    }

    /// Corrects with one fresh compass reading `yaw` \[rad\]. Skipped: a reading outside [−π, π]
    /// (non-finite, absurd), one that repeats the previous reading bit for bit while the compass
    /// has noise (stuck: [`RepeatDetector`]), and one outside the innovation gate.
    pub fn correct(&mut self, yaw: f64) {
        if !valid_yaw(yaw) {
            return;
        }
        if self.repeats.is_repeat(yaw) || self.outside_gate(yaw) {
            self.rejected += 1;
            return;
        }
        self.update(yaw);
    }

    /// `true` when `yaw` lies more than `gate_sigma` innovation standard deviations from the
    /// propagated yaw (never before the first reading).
    fn outside_gate(&self, yaw: f64) -> bool {
        let s = self.p[0] + self.params.compass_std.powi(2);
        let innovation = wrap_angle(yaw - self.yaw);
        self.yaw.is_finite() && innovation * innovation > self.params.gate_sigma.powi(2) * s
    }

    /// The Kalman update with a compass reading (the first one starts the yaw).
    fn update(&mut self, yaw: f64) {
        let r = self.params.compass_std.powi(2);
        if !self.yaw.is_finite() {
            self.yaw = wrap_angle(yaw);
            self.p = [r, 0.0, self.p[2]];
            return;
        }
        let [a, b, c] = self.p;
        let s = a + r;
        if s.is_nan() || s <= 0.0 {
            return;
        }
        let innovation = wrap_angle(yaw - self.yaw);
        let (k0, k1) = (a / s, b / s);
        self.yaw = wrap_angle(self.yaw + k0 * innovation);
        self.bias += k1 * innovation;
        // P ← (I − K H) P with H = [1, 0].
        self.p = [(1.0 - k0) * a, (1.0 - k0) * b, c - k1 * b];
    }

    /// The yaw estimate \[rad\] (NaN before the first compass reading).
    pub fn yaw(&self) -> f64 {
        self.yaw
    }

    /// The variance of the yaw estimate \[rad²\].
    pub fn yaw_variance(&self) -> f64 {
        self.p[0]
    }

    /// The gyro bias estimate [rad/s].
    pub fn gyro_bias(&self) -> f64 {
        self.bias
    }

    /// Compass readings rejected so far (stuck repeats and innovation-gate rejections).
    pub fn rejected(&self) -> u64 {
        self.rejected
    }
}

/// The yaw variance \[rad²\] to put into [`world_velocity_variance`] (as σ_θ², with the compass's
/// bias and bias walk added there) for a [`HeadingFilter`] run at period `dt` \[s\] with a compass
/// reading every `compass_every` steps, over `horizon` \[s\], started as
/// [`HeadingFilter::started_at`] does. The robot starts at rest and cannot be
/// faster than min(v_max, a_max·t), so the bound is max over t of
/// (min(v_max, a_max·t)/v_max)²·P_θθ(t): the filter's early, large variance weighs little because
/// the speed it multiplies is small. `a_max` [m/s²] is the input limit (∞: none).
pub fn fused_yaw_variance(
    params: HeadingFilterParams,
    dt: f64,
    compass_every: usize,
    horizon: f64,
    v_max: f64,
    a_max: f64,
) -> f64 {
    // The covariance does not depend on the readings: run its recursion alone (a zero
    // innovation keeps the yaw at 0).
    let mut f = HeadingFilter::started_at(params, 0.0);
    let steps = (horizon / dt).ceil().max(1.0) as usize;
    let every = compass_every.max(1);
    let mut worst: f64 = 0.0;
    for k in 0..steps {
        if k > 0 {
            f.predict_covariance(dt);
        }
        if k % every == 0 {
            f.update(0.0);
        }
        let t = k as f64 * dt;
        let share = if v_max > 0.0 {
            (a_max * t / v_max).min(1.0)
        } else {
            1.0
        };
        let p = f.yaw_variance();
        if p.is_finite() {
            worst = worst.max(share * share * p);
        }
    }
    worst
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::{FRAC_PI_2, PI};

    #[test]
    fn yaw_and_world_velocity_follow_rep_103() {
        // 90° about +z: facing north (y), counter-clockwise positive.
        let (s, c) = (FRAC_PI_2 / 2.0).sin_cos();
        assert!((yaw_from_quaternion(0.0, 0.0, s, c) - FRAC_PI_2).abs() < 1e-12);
        assert!((yaw_from_quaternion(0.0, 0.0, 1.0, 0.0).abs() - PI).abs() < 1e-12);
        let v = body_speed_to_world_velocity(0.2, FRAC_PI_2);
        assert!(v[0].abs() < 1e-12 && (v[1] - 0.2).abs() < 1e-12, "{v:?}");
        assert!(body_speed_to_world_velocity(f64::NAN, 0.0)[0].is_nan());
        // σ_v = 0.01, v_max = 0.22, σ_θ = 0.005: 1e-4 + 0.0484·2.5e-5
        let r = world_velocity_variance(0.01, 0.22, 0.005, 0.0, 0.0, 20.0);
        assert!((r - 1.0121e-4).abs() < 1e-9, "{r}");
    }

    #[test]
    fn heading_filter_estimates_the_gyro_bias_and_beats_the_compass() {
        // A turning robot (0.5 rad/s), gyro bias 0.02 rad/s, compass σ 0.1 rad, 50 Hz: the fused
        // yaw's error must fall well below the compass's, and the bias be found.
        let params = HeadingFilterParams::new(0.01, 0.0005, 0.1);
        let mut f = HeadingFilter::new(params);
        let dt = 0.02;
        let mut state = 12345u64;
        let mut gauss = || {
            // Box-Muller on a small LCG (deterministic, no dev-dependency needed here).
            let mut u = || {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
            };
            let (a, b) = (u(), u());
            (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
        };
        let (mut theta, mut sq, mut n) = (0.3, 0.0, 0);
        for k in 0..3000 {
            if k > 0 {
                theta = wrap_angle(theta + 0.5 * dt);
                f.predict(0.5 + 0.02 + 0.01 * gauss(), dt);
            }
            f.correct(theta + 0.1 * gauss());
            if k >= 1500 {
                sq += wrap_angle(f.yaw() - theta).powi(2);
                n += 1;
            }
        }
        let rms = (sq / n as f64).sqrt();
        assert!(rms < 0.03, "fused yaw rms {rms} rad (compass alone: 0.1)");
        assert!(
            (f.gyro_bias() - 0.02).abs() < 0.005,
            "bias {}",
            f.gyro_bias()
        );
        assert!(
            (f.yaw_variance().sqrt() - rms).abs() < 0.5 * rms,
            "σ {} vs rms {rms}",
            f.yaw_variance().sqrt()
        );
        // Malformed readings are skipped.
        let before = f;
        f.predict(f64::NAN, dt);
        f.predict(1e12, dt);
        f.correct(f64::INFINITY);
        f.correct(1e12);
        assert_eq!(f, before);
    }

    /// A compass that freezes (repeats its reading) while the gyro sees the robot turn is
    /// refused as stuck, and one that jumps by 1 rad (a bias switched on) is gated out: the yaw
    /// follows the gyro. Without both, the frozen reading drags the yaw back (the filter explains
    /// the turn by a gyro bias) and the jump is taken in.
    #[test]
    fn stuck_and_jumping_compasses_are_refused() {
        let params = HeadingFilterParams {
            initial_yaw_std: 0.01,
            ..HeadingFilterParams::new(0.01, 0.0005, 0.02)
        };
        let run = |p: HeadingFilterParams, lie: &dyn Fn(usize, f64) -> f64| {
            let mut f = HeadingFilter::started_at(p, 0.0);
            let (dt, mut theta) = (0.02, 0.0);
            for k in 1..=500 {
                theta += 0.3 * dt;
                f.predict(0.3, dt);
                // Honest readings carry a small deterministic noise pattern.
                let noise = 0.01 * ((k * 7919 % 13) as f64 / 6.0 - 1.0);
                f.correct(lie(k, theta + noise));
            }
            (wrap_angle(f.yaw() - theta).abs(), f.rejected())
        };
        let frozen = |k: usize, honest: f64| if k < 10 { honest } else { 0.054 };
        let jump = |k: usize, honest: f64| {
            if k < 100 {
                honest
            } else {
                wrap_angle(honest + 1.0)
            }
        };
        let (err, rejected) = run(params, &frozen);
        assert!(
            err < 0.02 && rejected > 480,
            "frozen: error {err} rad, {rejected} refused"
        );
        let (err, rejected) = run(params, &jump);
        assert!(
            err < 0.02 && rejected > 390,
            "jump: error {err} rad, {rejected} refused"
        );
        // Without the checks (a noise-free compass declared, no gate) both drag the yaw off.
        let bare = HeadingFilterParams {
            compass_std: 0.0,
            gate_sigma: f64::INFINITY,
            ..params
        };
        assert!(run(bare, &frozen).0 > 0.5);
        assert!(run(bare, &jump).0 > 0.5);
    }

    #[test]
    fn fused_yaw_variance_is_below_the_compass_and_weights_the_start() {
        let params = HeadingFilterParams::new(0.01, 0.0005, 0.1);
        let v = fused_yaw_variance(params, 0.02, 1, 20.0, 0.22, 1.0);
        assert!(v < 0.1f64.powi(2) / 10.0, "{v}");
        // Without an input limit the first reading's variance counts in full: the compass's.
        let v_inf = fused_yaw_variance(params, 0.02, 1, 20.0, 0.22, f64::INFINITY);
        assert!((v_inf - 0.01).abs() < 1e-12, "{v_inf}");
        // A marked start (σ 0.01 rad) and a 10 Hz compass: the bound is about 0.023 rad, a
        // quarter of the compass's 0.1 (a Python transcription of the recursion gives 0.02284).
        let marked = HeadingFilterParams {
            initial_yaw_std: 0.01,
            ..params
        };
        let v = fused_yaw_variance(marked, 0.02, 5, 20.0, 0.22, 1.25 * std::f64::consts::SQRT_2);
        assert!((v.sqrt() - 0.02284).abs() < 2e-4, "{}", v.sqrt());
    }
}
