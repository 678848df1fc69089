//! A moving obstacle's state from a noisy obstacle sensor (issue #51): a constant-velocity
//! Kalman filter fed with time-stamped detections of the obstacle's centre (world frame, m),
//! that yields the [`MoverState`] the controller reads **and** bounds on its error.
//!
//! **Model.** Per axis the state is (p, v) with p(t + τ) = p + v·τ + ∫∫a and ‖a‖ ≤ ā (the mover's
//! acceleration bound); a detection is z = p + n, n ~ N(0, σ² I₂) white. Both axes share one
//! gain, so the filter is a 2×2 recursion applied to the x and y columns.
//!
//! **Error bound.** Whatever gain the filter uses, its error e = x − x̂ is linear in the
//! initial error, the noise and the accelerations, and splits in two parts it propagates
//! beside the estimate (the same 2×2 matrices act on both axes):
//! - a Gaussian part from the detection noise, isotropic in the plane, of per-axis covariance
//!   Σ (Σ⁻ = FΣFᵀ, Σ⁺ = (I − KH)Σ⁻(I − KH)ᵀ + σ²KKᵀ): its planar norm exceeds r only with
//!   probability exp(−r²/(2Σ_pp)) (a χ² with 2 degrees of freedom);
//! - a deterministic part from the accelerations and the unknown initial velocity (at most the
//!   mover's speed bound v̄): a sum of terms c·wᵀ, c a (position, velocity) coefficient pair
//!   the filter's 2×2 matrices act on and w a planar vector of known largest norm (ā·τ²/2 and
//!   ā·τ for the position and velocity an acceleration ‖a‖ ≤ ā adds over τ; v̄ for the initial
//!   velocity). Its position part is then at most d_p = Σ|c_p|·‖w‖, its velocity part
//!   d_v = Σ|c_v|·‖w‖ (the triangle inequality: no cancellation is assumed). The last
//!   [`WINDOW`] detections' terms are kept one by one; older ones are folded into one bound β
//!   in the norm ‖c‖_L = sqrt(cᵀLc) in which the settled filter contracts (L from the Lyapunov
//!   equation AᵀLA − L = −I of its steady error matrix A), propagated as β ← ‖M‖_L·β and read
//!   as |c_p| ≤ sqrt((L⁻¹)_pp)·β: any L > 0 gives a valid bound, this one a small one.
//!
//! With the per-sample ε' split over the two events (position, velocity),
//! γ_p = d_p + sqrt(2 Σ_pp ln(2/ε')) and γ_v = d_v + sqrt(2 Σ_vv ln(2/ε')) bound the position
//! and velocity errors together with probability ≥ 1 − ε' at each reading: the same union-bound
//! style as the robot's γ (see [`crate::params`]). The gain itself is the Kalman gain of a
//! white acceleration of standard deviation `accel_std` (a design choice: it changes how fast
//! the filter follows, never whether the bound holds). What the bound assumes: the detections
//! are honest (an attack on them is outside it) and the acceleration bound holds (a scripted
//! path's corners are velocity jumps it does not cover).
//!
//! The velocity handed to the controller is clipped to the mover's speed bound (the truth lies
//! in that disc, so clipping never moves the estimate away from it): a reading's speed is at
//! most v̄, and its velocity error at most min(γ_v, 2v̄).

use std::collections::VecDeque;

use nalgebra::{Matrix2, Vector2};

use crate::barrier::MoverState;

/// What a [`MoverTracker`] is built from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MoverTrackerConfig {
    /// Standard deviation of a detection's noise per axis \[m\].
    pub position_std: f64,
    /// Standard deviation of the white acceleration the gain is designed for \[m/s²\].
    pub accel_std: f64,
    /// Bound on the norm of the mover's acceleration \[m/s²\] (enters the error bound).
    pub accel_bound: f64,
    /// Bound on the mover's speed \[m/s\] (its unknown initial velocity; the readings' clip).
    pub speed_bound: f64,
    /// Per-sample probability ε' that a reading's error exceeds its bounds (0 < ε' < 1).
    pub eps_per_sample: f64,
    /// The detection period the filter expects \[s\] (sets the norm its old error terms are
    /// bounded in; detections may come at any time).
    pub period: f64,
}

/// How many detections' error terms a tracker keeps one by one (older ones share one bound).
pub const WINDOW: usize = 64;

/// Why a tracker was not built or a detection not used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MoverTrackerError {
    /// A configuration value out of its range.
    #[error("mover tracker: `{key}` = {found}: expected {expected}")]
    Config {
        /// The field.
        key: &'static str,
        /// What was expected.
        expected: &'static str,
        /// What was given.
        found: f64,
    },
    /// A detection with a non-finite time or coordinate.
    #[error("detection at t = {t} s of ({x}, {y}) m: expected finite numbers")]
    NonFinite {
        /// Its time stamp \[s\].
        t: f64,
        /// Its x \[m\].
        x: f64,
        /// Its y \[m\].
        y: f64,
    },
    /// A detection older than the last one used.
    #[error("detection at t = {t} s: older than the last one used (t = {last} s)")]
    OutOfOrder {
        /// Its time stamp \[s\].
        t: f64,
        /// The last detection's time \[s\].
        last: f64,
    },
    /// A detection farther from the prediction than an honest one can be.
    #[error("detection at t = {t} s: {distance:.3} m from the prediction, more than the gate {gate:.3} m an honest detection stays within (probability ≥ 1 − ε')")]
    Gated {
        /// Its time stamp \[s\].
        t: f64,
        /// Its distance from the predicted position \[m\].
        distance: f64,
        /// The gate \[m\].
        gate: f64,
    },
}

/// A tracked mover's reading at one instant: estimate and error bounds, world frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackedReading {
    /// Estimated centre \[m\].
    pub position: [f64; 2],
    /// Estimated velocity, clipped to the speed bound \[m/s\].
    pub velocity: [f64; 2],
    /// γ_p: bound on the position error's norm \[m\].
    pub position_bound: f64,
    /// γ_v: bound on the (clipped) velocity error's norm \[m/s\].
    pub velocity_bound: f64,
}

impl TrackedReading {
    /// The [`MoverState`] of this reading for a barrier built with the mover at `origin` \[m\],
    /// with the mover's acceleration bound `accel_bound` \[m/s²\].
    pub fn mover_state(&self, origin: [f64; 2], accel_bound: f64) -> MoverState {
        MoverState {
            displacement: [self.position[0] - origin[0], self.position[1] - origin[1]],
            velocity: self.velocity,
            accel_bound,
            position_bound: self.position_bound,
            velocity_bound: self.velocity_bound,
        }
    }
}

/// The filter after at least one detection.
#[derive(Debug, Clone, PartialEq)]
struct Track {
    /// Time of the last detection used \[s\].
    t: f64,
    /// Estimate: rows (position, velocity), columns (x, y).
    x: Matrix2<f64>,
    /// The filter's covariance (per axis), which sets the gain.
    p: Matrix2<f64>,
    /// Covariance of the error's Gaussian part (per axis).
    sigma: Matrix2<f64>,
    /// The deterministic part's recent terms: coefficients c and the largest norm of w.
    terms: VecDeque<(Vector2<f64>, f64)>,
    /// Bound on the older terms' sum in the norm ‖·‖_L.
    beta: f64,
}

/// A constant-velocity Kalman filter with error bounds for one moving obstacle (see the
/// module's documentation).
#[derive(Debug, Clone, PartialEq)]
pub struct MoverTracker {
    cfg: MoverTrackerConfig,
    /// sqrt(2 ln(2/ε')): the radius of the noise part per standard deviation.
    radius: f64,
    /// The norm the older error terms are bounded in, and sqrt of its inverse's diagonal.
    metric: Matrix2<f64>,
    metric_inv_diag: Vector2<f64>,
    track: Option<Track>,
}

/// The process noise of a white acceleration of variance `s` over `tau` seconds.
fn process_noise(tau: f64, s: f64) -> Matrix2<f64> {
    let (t2, t3, t4) = (tau * tau, tau * tau * tau, tau * tau * tau * tau);
    Matrix2::new(t4 / 4.0, t3 / 2.0, t3 / 2.0, t2) * s
}

/// The Kalman update of covariance `p` by a position measurement of variance `r`: the gain K
/// and I − KH (H = (1, 0)).
fn gain(p: &Matrix2<f64>, r: f64) -> (Vector2<f64>, Matrix2<f64>) {
    let s = p[(0, 0)] + r;
    let k = Vector2::new(p[(0, 0)] / s, p[(1, 0)] / s);
    (k, Matrix2::new(1.0 - k[0], 0.0, -k[1], 1.0))
}

/// ‖m‖_L = sqrt(λ̄(L⁻¹mᵀLm)), the norm of `m` induced by ‖c‖_L = sqrt(cᵀLc).
fn induced_norm(m: &Matrix2<f64>, l: &Matrix2<f64>, l_inv: &Matrix2<f64>) -> f64 {
    let n = l_inv * m.transpose() * l * m;
    let (tr, det) = (n.trace(), n.determinant());
    let disc = (tr * tr - 4.0 * det).max(0.0).sqrt();
    ((tr + disc) / 2.0).max(0.0).sqrt()
}

/// L with AᵀLA − L = −I for the settled filter's error matrix A = (I − KH)F at the expected
/// period (the identity when the filter does not settle to a contracting A).
fn contraction_metric(cfg: &MoverTrackerConfig) -> Matrix2<f64> {
    let f = transition(cfg.period);
    let q = process_noise(cfg.period, cfg.accel_std * cfg.accel_std);
    let r = cfg.position_std * cfg.position_std;
    let mut p = Matrix2::identity() * r;
    for _ in 0..10_000 {
        let pred = f * p * f.transpose() + q;
        let (k, i_kh) = gain(&pred, r);
        let next = i_kh * pred * i_kh.transpose() + k * k.transpose() * r;
        let done = (next - p).abs().max() <= 1e-15 * next.abs().max();
        p = next;
        if done {
            break;
        }
    }
    let (_, i_kh) = gain(&(f * p * f.transpose() + q), r);
    let a = i_kh * f;
    let mut l = Matrix2::identity();
    for _ in 0..100_000 {
        let next = a.transpose() * l * a + Matrix2::identity();
        let done = (next - l).abs().max() <= 1e-12 * next.abs().max();
        l = next;
        if done {
            return if l.iter().all(|v| v.is_finite()) && l.determinant() > 0.0 {
                l
            } else {
                Matrix2::identity()
            };
        }
    }
    Matrix2::identity()
}

fn transition(tau: f64) -> Matrix2<f64> {
    Matrix2::new(1.0, tau, 0.0, 1.0)
}

/// The deterministic terms an acceleration ‖a‖ ≤ `a_bar` adds over `tau`, after `m`.
fn accel_terms(m: &Matrix2<f64>, tau: f64, a_bar: f64) -> [(Vector2<f64>, f64); 2] {
    [
        (m * Vector2::new(1.0, 0.0), a_bar * tau * tau / 2.0),
        (m * Vector2::new(0.0, 1.0), a_bar * tau),
    ]
}

impl MoverTracker {
    /// A tracker with no detection yet.
    pub fn new(cfg: MoverTrackerConfig) -> Result<Self, MoverTrackerError> {
        let check = |key, v: f64, ok: bool, expected| {
            if v.is_finite() && ok {
                Ok(())
            } else {
                Err(MoverTrackerError::Config {
                    key,
                    expected,
                    found: v,
                })
            }
        };
        let c = &cfg;
        check(
            "position_std",
            c.position_std,
            c.position_std > 0.0,
            "a noise standard deviation > 0 m",
        )?;
        check(
            "accel_std",
            c.accel_std,
            c.accel_std > 0.0,
            "an acceleration standard deviation > 0 m/s²",
        )?;
        check(
            "accel_bound",
            c.accel_bound,
            c.accel_bound >= 0.0,
            "an acceleration bound ≥ 0 m/s²",
        )?;
        check(
            "speed_bound",
            c.speed_bound,
            c.speed_bound >= 0.0,
            "a speed bound ≥ 0 m/s",
        )?;
        check(
            "eps_per_sample",
            c.eps_per_sample,
            c.eps_per_sample > 0.0 && c.eps_per_sample < 1.0,
            "a probability in (0, 1)",
        )?;
        check(
            "period",
            c.period,
            c.period > 0.0,
            "a detection period > 0 s",
        )?;
        let metric = contraction_metric(&cfg);
        let inv = metric.try_inverse().unwrap_or_else(Matrix2::identity);
        Ok(Self {
            cfg,
            radius: (2.0 * (2.0 / cfg.eps_per_sample).ln()).sqrt(),
            metric,
            metric_inv_diag: Vector2::new(inv[(0, 0)].max(0.0).sqrt(), inv[(1, 1)].max(0.0).sqrt()),
            track: None,
        })
    }

    /// Its configuration.
    pub fn config(&self) -> &MoverTrackerConfig {
        &self.cfg
    }

    fn metric_inv(&self) -> Matrix2<f64> {
        self.metric.try_inverse().unwrap_or_else(Matrix2::identity)
    }

    /// Bounds (d_p, d_v) on the deterministic error part of `track` moved on by `tau` seconds
    /// without a detection.
    fn deterministic(&self, track: &Track, tau: f64) -> Vector2<f64> {
        let f = transition(tau);
        let mut d = Vector2::zeros();
        let extra = accel_terms(&Matrix2::identity(), tau, self.cfg.accel_bound);
        for (c, w) in track.terms.iter().map(|(c, w)| (f * c, *w)).chain(extra) {
            d += c.abs() * w;
        }
        let old = induced_norm(&f, &self.metric, &self.metric_inv()) * track.beta;
        d + self.metric_inv_diag * old
    }

    /// (γ_p, γ_v) of `track` moved on by `tau` seconds.
    fn bounds(&self, track: &Track, tau: f64) -> (f64, f64) {
        let f = transition(tau);
        let sigma = f * track.sigma * f.transpose();
        let d = self.deterministic(track, tau);
        (
            d[0] + self.radius * sigma[(0, 0)].max(0.0).sqrt(),
            d[1] + self.radius * sigma[(1, 1)].max(0.0).sqrt(),
        )
    }

    /// Uses detection `z` (the mover's centre, world frame \[m\]) taken at `t` \[s\]. The first
    /// one starts the track (velocity 0, its error at most the speed bound); a later one is
    /// refused when it is not finite, older than the last one used, or farther from the
    /// prediction than an honest detection gets (its bound plus the noise's, at ε'). A refused
    /// detection leaves the tracker as it was: its bounds keep growing with the prediction.
    pub fn detect(&mut self, t: f64, z: [f64; 2]) -> Result<(), MoverTrackerError> {
        if !(t.is_finite() && z[0].is_finite() && z[1].is_finite()) {
            return Err(MoverTrackerError::NonFinite {
                t,
                x: z[0],
                y: z[1],
            });
        }
        let sd = self.cfg.position_std;
        let r = sd * sd;
        let Some(track) = &self.track else {
            let v = self.cfg.speed_bound;
            let mut terms = VecDeque::with_capacity(2 * WINDOW + 2);
            terms.push_back((Vector2::new(0.0, 1.0), v));
            self.track = Some(Track {
                t,
                x: Matrix2::new(z[0], z[1], 0.0, 0.0),
                p: Matrix2::new(r, 0.0, 0.0, v * v),
                sigma: Matrix2::new(r, 0.0, 0.0, 0.0),
                terms,
                beta: 0.0,
            });
            return Ok(());
        };
        if t < track.t {
            return Err(MoverTrackerError::OutOfOrder { t, last: track.t });
        }
        let tau = t - track.t;
        let f = transition(tau);
        let x = f * track.x;
        let innovation = Vector2::new(z[0] - x[(0, 0)], z[1] - x[(0, 1)]);
        let gate = self.bounds(track, tau).0 + self.radius * sd;
        let distance = innovation.norm();
        if distance.is_nan() || distance > gate {
            return Err(MoverTrackerError::Gated { t, distance, gate });
        }
        let p = f * track.p * f.transpose() + process_noise(tau, self.cfg.accel_std.powi(2));
        let (k, i_kh) = gain(&p, r);
        let m = i_kh * f;
        let mut terms: VecDeque<(Vector2<f64>, f64)> =
            track.terms.iter().map(|(c, w)| (m * c, *w)).collect();
        terms.extend(accel_terms(&i_kh, tau, self.cfg.accel_bound));
        let mut beta = induced_norm(&m, &self.metric, &self.metric_inv()) * track.beta;
        while terms.len() > 2 * WINDOW {
            if let Some((c, w)) = terms.pop_front() {
                beta += (c.transpose() * self.metric * c)[(0, 0)].max(0.0).sqrt() * w;
            }
        }
        let kkt = k * k.transpose() * r;
        self.track = Some(Track {
            t,
            x: x + k * innovation.transpose(),
            p: i_kh * p * i_kh.transpose() + kkt,
            sigma: i_kh * (f * track.sigma * f.transpose()) * i_kh.transpose() + kkt,
            terms,
            beta,
        });
        Ok(())
    }

    /// The reading at `t` \[s\] (the track predicted from its last detection; not before it),
    /// or `None` before the first detection.
    pub fn reading(&self, t: f64) -> Option<TrackedReading> {
        let track = self.track.as_ref()?;
        let tau = (t - track.t).max(0.0);
        let x = transition(tau) * track.x;
        let mut v = [x[(1, 0)], x[(1, 1)]];
        let speed = v[0].hypot(v[1]);
        let vb = self.cfg.speed_bound;
        if speed > vb {
            let s = if speed > 0.0 { vb / speed } else { 0.0 };
            v = [v[0] * s, v[1] * s];
        }
        let (gp, gv) = self.bounds(track, tau);
        Some(TrackedReading {
            position: [x[(0, 0)], x[(0, 1)]],
            velocity: v,
            position_bound: gp,
            velocity_bound: gv.min(2.0 * vb),
        })
    }

    /// The largest bounds (γ_p, γ_v) of the readings over `horizon` seconds, a detection every
    /// `cfg.period` seconds and a reading every `step` seconds between them (as a run reads it;
    /// the bounds do not depend on the detections' values). From the first detection on.
    pub fn horizon_bounds(
        cfg: MoverTrackerConfig,
        step: f64,
        horizon: f64,
    ) -> Result<(f64, f64), MoverTrackerError> {
        let mut tr = Self::new(cfg)?;
        tr.detect(0.0, [0.0, 0.0])?;
        let (mut gp, mut gv) = (0.0f64, 0.0f64);
        let readings = (horizon / step).ceil().min(1e7) as u64;
        let mut next = 1u64;
        for k in 0..=readings {
            let t = k as f64 * step;
            if t >= next as f64 * cfg.period - 1e-9 {
                tr.detect(t, [0.0, 0.0])?;
                next += 1;
            }
            if let Some(r) = tr.reading(t) {
                gp = gp.max(r.position_bound);
                gv = gv.max(r.velocity_bound);
            }
        }
        Ok((gp, gv))
    }

    /// The bounds (γ_p, γ_v) right after a detection once the filter has settled (its
    /// covariance and deterministic bound converged: 10 000 detections every `period` s).
    pub fn steady_bounds(cfg: MoverTrackerConfig) -> Result<(f64, f64), MoverTrackerError> {
        let period = cfg.period;
        let mut tr = Self::new(cfg)?;
        for k in 0..10_000 {
            tr.detect(k as f64 * period, [0.0, 0.0])?;
        }
        let r = tr
            .reading(9_999.0 * period)
            .map_or((f64::NAN, f64::NAN), |r| {
                (r.position_bound, r.velocity_bound)
            });
        Ok(r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_distr::StandardNormal;

    fn cfg() -> MoverTrackerConfig {
        MoverTrackerConfig {
            position_std: 0.03,
            accel_std: 0.5,
            accel_bound: 0.5,
            speed_bound: 0.6,
            eps_per_sample: 1e-4,
            period: 0.1,
        }
    }

    /// A mover on a circle of radius 1 m at 0.4 m/s (acceleration 0.16 m/s² ≤ ā = 0.5),
    /// detected at 10 Hz with σ = 3 cm and read at 50 Hz: after the first second the estimate
    /// is within a few cm and cm/s, and the bounds cover the error at every reading (ε' = 1e-4
    /// per reading: over 3000 readings fewer than one miss is expected; none is allowed).
    #[test]
    fn follows_a_mover_on_a_circle_and_its_bounds_cover_the_error() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(51);
        let mut tr = MoverTracker::new(cfg()).unwrap();
        let (r, w) = (1.0, 0.4);
        let truth = |t: f64| {
            let a = w / r * t;
            ([r * a.cos(), r * a.sin()], [-w * a.sin(), w * a.cos()])
        };
        let (mut misses, mut late_p, mut late_v, mut late_n) = (0, 0.0f64, 0.0f64, 0.0f64);
        for k in 0..3000 {
            let t = k as f64 * 0.02;
            let (p, v) = truth(t);
            if k % 5 == 0 {
                let n: [f64; 2] = [rng.sample(StandardNormal), rng.sample(StandardNormal)];
                tr.detect(t, [p[0] + 0.03 * n[0], p[1] + 0.03 * n[1]])
                    .unwrap();
            }
            let rd = tr.reading(t).unwrap();
            let ep = (rd.position[0] - p[0]).hypot(rd.position[1] - p[1]);
            let ev = (rd.velocity[0] - v[0]).hypot(rd.velocity[1] - v[1]);
            if ep > rd.position_bound || ev > rd.velocity_bound {
                misses += 1;
            }
            if t >= 5.0 {
                late_p += ep * ep;
                late_v += ev * ev;
                late_n += 1.0;
            }
        }
        assert_eq!(misses, 0);
        // After 5 s the estimate's RMS error is below a raw detection's (σ√2 = 4.2 cm), and
        // its velocity's below 0.1 m/s.
        let (rms_p, rms_v) = ((late_p / late_n).sqrt(), (late_v / late_n).sqrt());
        eprintln!("rms position {rms_p:.4} m, velocity {rms_v:.4} m/s");
        assert!(rms_p < 0.03 * 2f64.sqrt(), "position error {rms_p}");
        assert!(rms_v < 0.1, "velocity error {rms_v}");
        // The bounds settle: below 0.25 m and 0.6 m/s, and the horizon maximum is the
        // velocity's initial one (the unknown starting velocity, at most v̄).
        let (gp, gv) = MoverTracker::steady_bounds(cfg()).unwrap();
        eprintln!("steady γ_p {gp:.4} m, γ_v {gv:.4} m/s");
        assert!(gp > 0.03 && gp < 0.25, "γ_p {gp}");
        assert!(gv > 0.05 && gv < 0.6, "γ_v {gv}");
        let (hp, hv) = MoverTracker::horizon_bounds(cfg(), 0.02, 60.0).unwrap();
        assert!(hp >= gp && hv >= gv);
        assert!(hv >= 0.6 - 1e-12, "γ_v max {hv}");
    }

    /// The ε' of the bound, measured: a walk whose acceleration has norm ā in a random
    /// direction each 20 ms, 20 000 readings at ε' = 0.05: the bounds cover the error in at
    /// least 1 − ε' of them (the bound is conservative: it assumes no cancellation between
    /// accelerations, so the measured share outside is far below ε').
    #[test]
    fn the_share_of_readings_outside_the_bounds_is_at_most_eps() {
        let c = MoverTrackerConfig {
            eps_per_sample: 0.05,
            ..cfg()
        };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut tr = MoverTracker::new(c).unwrap();
        let (mut p, mut v) = ([0.0f64, 0.0], [0.2f64, 0.0]);
        let mut out = 0;
        let n = 20_000;
        for k in 0..n {
            let t = k as f64 * 0.02;
            if k % 5 == 0 {
                let z: [f64; 2] = [rng.sample(StandardNormal), rng.sample(StandardNormal)];
                tr.detect(t, [p[0] + 0.03 * z[0], p[1] + 0.03 * z[1]])
                    .unwrap();
            }
            let rd = tr.reading(t).unwrap();
            let ep = (rd.position[0] - p[0]).hypot(rd.position[1] - p[1]);
            let ev = (rd.velocity[0] - v[0]).hypot(rd.velocity[1] - v[1]);
            out += usize::from(ep > rd.position_bound || ev > rd.velocity_bound);
            // Next 20 ms at an acceleration of norm ≤ ā, turned back when fast.
            let ang: f64 = rng.random_range(0.0..std::f64::consts::TAU);
            let mut a = [0.5 * ang.cos(), 0.5 * ang.sin()];
            if v[0].hypot(v[1]) > 0.5 {
                let s = 0.5 / v[0].hypot(v[1]);
                a = [-v[0] * s, -v[1] * s];
            }
            let dt = 0.02;
            p = [
                p[0] + v[0] * dt + a[0] * dt * dt / 2.0,
                p[1] + v[1] * dt + a[1] * dt * dt / 2.0,
            ];
            v = [v[0] + a[0] * dt, v[1] + a[1] * dt];
        }
        eprintln!("{out} of {n} readings outside their bounds");
        assert!(
            (out as f64) / (n as f64) <= 0.05,
            "{out} of {n} readings outside their bounds"
        );
    }

    #[test]
    fn malformed_detections_are_refused_and_leave_the_track_as_it_was() {
        let mut tr = MoverTracker::new(cfg()).unwrap();
        assert!(tr.reading(0.0).is_none());
        assert!(matches!(
            tr.detect(0.0, [f64::NAN, 0.0]),
            Err(MoverTrackerError::NonFinite { .. })
        ));
        assert!(tr.reading(0.0).is_none());
        tr.detect(0.0, [1.0, 2.0]).unwrap();
        tr.detect(0.1, [1.0, 2.0]).unwrap();
        let before = tr.clone();
        assert!(matches!(
            tr.detect(0.2, [f64::INFINITY, 2.0]),
            Err(MoverTrackerError::NonFinite { .. })
        ));
        assert!(matches!(
            tr.detect(0.05, [1.0, 2.0]),
            Err(MoverTrackerError::OutOfOrder { .. })
        ));
        let e = tr.detect(0.2, [1e6, 2.0]).unwrap_err();
        assert!(e.to_string().contains("gate"), "{e}");
        assert_eq!(tr, before);
        // A refused detection: the reading's bound grows with the prediction.
        let r1 = tr.reading(0.1).unwrap();
        let r2 = tr.reading(0.5).unwrap();
        assert!(r2.position_bound > r1.position_bound);
        assert_eq!(r1.position, [1.0, 2.0]);
        // Bad configurations name their key.
        let bad = MoverTracker::new(MoverTrackerConfig {
            position_std: -1.0,
            ..cfg()
        })
        .unwrap_err();
        assert!(bad.to_string().contains("`position_std`"), "{bad}");
        let bad = MoverTracker::new(MoverTrackerConfig {
            eps_per_sample: 1.0,
            ..cfg()
        })
        .unwrap_err();
        assert!(bad.to_string().contains("`eps_per_sample`"), "{bad}");
    }
}
