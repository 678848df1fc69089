//! Time series: buffered per control step, cut to a plot range, and sent once as columns.
//!
//! Plot ranges (so one absurd value cannot squash a plot; every clipped value is drawn at the
//! edge of the range and marked with a magenta cross in the entity `<plot>/clipped`):
//! - a sensor channel: the clean signal's range widened by its span (at least [`MIN_SPAN`]) on
//!   each side; received and rejected readings are cut to it;
//! - a barrier: the true h's range widened the same way; h on the estimates is cut to it;
//! - V on an estimate is shown as V/V₀ (V₀ = its first value), cut to [0, [`V_RATIO_MAX`]];
//! - the estimation error ‖x − x̂‖/γ of each estimate against the truth is cut to
//!   [0, [`GAMMA_RATIO_MAX`]], with the bound 1 drawn as a line;
//! - Step-3 residues are drawn as log10, cut to [−6, 6]
//!   ([`RESIDUE_FLOOR`], [`RESIDUE_MAX`]); detector statistics are cut to ±[`Z_MAX`].

use crate::observe::{Frame, Scene};

use super::draw::{other, palette, seg, ATTACK, CLEAN, MARK, RECEIVED, TRUTH};

/// Smallest span used to widen a reference range (in the signal's unit).
pub const MIN_SPAN: f64 = 0.5;
/// Upper end of the ‖x − x̂‖/γ plot.
pub const GAMMA_RATIO_MAX: f64 = 5.0;
/// Upper end of the V/V₀ plot.
pub const V_RATIO_MAX: f64 = 10.0;
/// Residues are plotted as log10(residue), cut to [log10 RESIDUE_FLOOR, log10 RESIDUE_MAX]
/// (they span decades: noise-level for clean estimators, large for attacked ones).
pub const RESIDUE_MAX: f64 = 1e6;
/// Lower end of the residue plot (before the logarithm).
pub const RESIDUE_FLOOR: f64 = 1e-6;
/// Detector statistic plot range ±Z_MAX (|z| ≤ 3 is a 3σ detector's "normal").
pub const Z_MAX: f64 = 10.0;

/// One scalar series, buffered until the end of the run.
#[derive(Debug, Clone, Default)]
pub(crate) struct Series {
    pub path: String,
    t: Vec<f64>,
    step: Vec<i64>,
    v: Vec<f64>,
}

impl Series {
    fn new(path: String) -> Self {
        Self {
            path,
            ..Self::default()
        }
    }
    /// Appends a finite value (NaN and ±∞ are not drawable; the events say when they came).
    fn push(&mut self, t: f64, step: u64, v: f64) {
        if v.is_finite() {
            self.t.push(t);
            self.step.push(step as i64);
            self.v.push(v);
        }
    }
    fn range(&self) -> Option<(f64, f64)> {
        let lo = self.v.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = self.v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        (lo <= hi).then_some((lo, hi))
    }
    /// Cuts every value to [lo, hi]; each cut value is also pushed to `marks` at the edge.
    fn clip(&mut self, (lo, hi): (f64, f64), marks: &mut Series) {
        for i in 0..self.v.len() {
            let c = self.v[i].clamp(lo, hi);
            if c != self.v[i] {
                self.v[i] = c;
                marks.t.push(self.t[i]);
                marks.step.push(self.step[i]);
                marks.v.push(c);
            }
        }
    }
    /// A constant line over the time span of `like`.
    fn constant(path: String, like: &Series, value: f64) -> Self {
        let mut s = Self::new(path);
        if let (Some(&t0), Some(&t1)) = (like.t.first(), like.t.last()) {
            s.push(t0, like.step[0] as u64, value);
            s.push(t1, *like.step.last().unwrap_or(&0) as u64, value);
        }
        s
    }
}

/// The reference range `r` widened by its span (at least `MIN_SPAN`) on each side.
fn widened(r: Option<(f64, f64)>) -> (f64, f64) {
    let (lo, hi) = r.unwrap_or((-MIN_SPAN, MIN_SPAN));
    let m = (hi - lo).max(MIN_SPAN);
    (lo - m, hi + m)
}

/// How a series is drawn.
#[derive(Debug, Clone, Copy)]
enum Look {
    Line(rerun::Color, f32),
    Step(rerun::Color),
    Dots(rerun::Color, rerun::components::MarkerShape),
}

/// Every plotted series of a run.
#[derive(Debug, Default)]
pub(crate) struct Plots {
    filters: Vec<String>,
    channels: Vec<String>,
    attack_labels: Vec<String>,
    clf: Vec<Series>,
    residues: Vec<Series>,
    /// ‖x − x̂‖/γ per filter.
    gamma_ratio: Vec<Series>,
    clean: Vec<Series>,
    received: Vec<Series>,
    rejected: Vec<Series>,
    z: Vec<Series>,
    /// Per channel: the attacks that target it, and their window as a 0/1 series.
    channel_attacks: Vec<Vec<usize>>,
    window: Vec<Series>,
    h_truth: Vec<Series>,
    /// [barrier][filter]
    h_est: Vec<Vec<Series>>,
    control: Vec<Series>,
    attacks: Vec<Series>,
}

/// Names of the control series, in [`Plots::control`] order.
pub(crate) const CONTROL: [&str; 4] = ["v", "omega", "u_x", "u_y"];

impl Plots {
    pub(crate) fn new(scene: &Scene) -> Self {
        let per = |prefix: &str, names: &[String], leaf: &str| -> Vec<Series> {
            names
                .iter()
                .map(|n| Series::new(format!("{prefix}/{}{leaf}", seg(n))))
                .collect()
        };
        let f = &scene.filters;
        let c = &scene.channels;
        Self {
            filters: f.clone(),
            channels: c.clone(),
            attack_labels: scene.attacks.clone(),
            clf: per("clf", f, ""),
            residues: per("residues", f, ""),
            gamma_ratio: per("estimation_error", f, ""),
            clean: per("sensors", c, "/clean"),
            received: per("sensors", c, "/received"),
            rejected: per("sensors", c, "/rejected"),
            z: per("detector", c, ""),
            channel_attacks: c
                .iter()
                .map(|ch| {
                    (0..scene.attack_channels.len())
                        .filter(|&a| scene.attack_channels[a].contains(ch))
                        .collect()
                })
                .collect(),
            window: per("sensors", c, "/attack_window"),
            h_truth: per("barriers", &scene.barriers, "/truth"),
            h_est: scene
                .barriers
                .iter()
                .map(|b| per(&format!("barriers/{}", seg(b)), f, ""))
                .collect(),
            control: CONTROL
                .iter()
                .map(|n| Series::new(format!("control/{n}")))
                .collect(),
            attacks: per("attacks", &scene.attacks, ""),
        }
    }

    pub(crate) fn push(&mut self, f: &Frame<'_>) {
        let (t, k) = (f.t, f.step);
        for (i, e) in f.estimates.iter().enumerate().take(self.clf.len()) {
            self.clf[i].push(t, k, e.clf);
            self.residues[i].push(t, k, e.residue);
            self.gamma_ratio[i].push(t, k, e.error_ratio);
        }
        for (i, c) in f.channels.iter().enumerate().take(self.clean.len()) {
            self.clean[i].push(t, k, c.clean);
            if c.fresh {
                let to = if c.rejected {
                    &mut self.rejected[i]
                } else {
                    &mut self.received[i]
                };
                // A rejected NaN/∞ has no value to draw: it is marked at the plot's edge.
                let v = if c.rejected && !c.received.is_finite() {
                    f64::MAX.copysign(c.received)
                } else {
                    c.received
                };
                to.push(t, k, v);
            }
            self.z[i].push(t, k, c.detector_z);
            if !self.channel_attacks[i].is_empty() {
                let on = self.channel_attacks[i]
                    .iter()
                    .any(|&a| f.attacks_active.get(a) == Some(&true));
                self.window[i].push(t, k, if on { 1.0 } else { 0.0 });
            }
        }
        let nb = self.h_truth.len();
        for (j, truth) in self.h_truth.iter_mut().enumerate() {
            truth.push(t, k, f.barrier_truth.get(j).copied().unwrap_or(f64::NAN));
            for (i, s) in self.h_est[j].iter_mut().enumerate() {
                let v = f.barrier_values.get(i * nb + j);
                s.push(t, k, v.copied().unwrap_or(f64::NAN));
            }
        }
        let u = [f.body_cmd[0], f.body_cmd[1], f.u[0], f.u[1]];
        for (s, v) in self.control.iter_mut().zip(u) {
            s.push(t, k, v);
        }
        for (s, on) in self.attacks.iter_mut().zip(f.attacks_active) {
            s.push(t, k, if *on { 1.0 } else { 0.0 });
        }
    }

    /// Cuts, normalises and sends every series with its look; returns the first error.
    pub(crate) fn send(mut self, rec: &rerun::RecordingStream) -> Result<(), String> {
        use rerun::components::MarkerShape;
        let mut out: Vec<(Series, String, Look)> = Vec::new();
        let line = |c| Look::Line(c, 1.5);
        let cross = Look::Dots(MARK, MarkerShape::Cross);
        // Sensors: clean vs received, rejected apart, clipped marked.
        for (i, clean) in std::mem::take(&mut self.clean).into_iter().enumerate() {
            let r = widened(clean.range());
            let base = clean.path.trim_end_matches("/clean").to_string();
            let mut marks = Series::new(format!("{base}/clipped"));
            let mut received = std::mem::take(&mut self.received[i]);
            let mut rejected = std::mem::take(&mut self.rejected[i]);
            received.clip(r, &mut marks);
            rejected.clip(r, &mut Series::default());
            // The attack window as a staircase between the plot's bottom and top edges.
            let mut window = std::mem::take(&mut self.window[i]);
            window
                .v
                .iter_mut()
                .for_each(|v| *v = if *v > 0.5 { r.1 } else { r.0 });
            out.push((
                window,
                "attack window (up = active)".into(),
                Look::Step(ATTACK),
            ));
            out.push((clean, "clean".into(), line(CLEAN)));
            out.push((received, "received".into(), line(RECEIVED)));
            out.push((
                rejected,
                "rejected reading".into(),
                Look::Dots(MARK, MarkerShape::Circle),
            ));
            out.push((marks, "clipped to plot range".into(), cross));
        }
        self.barriers(&mut out);
        self.estimator_stats(&mut out);
        for (s, n) in std::mem::take(&mut self.control).into_iter().zip(CONTROL) {
            let c = match n {
                "v" => other(0),
                "omega" => other(1),
                "u_x" => other(2),
                _ => other(3),
            };
            out.push((s, n.into(), line(c)));
        }
        let attacks = std::mem::take(&mut self.attacks);
        for (i, (s, label)) in attacks.into_iter().zip(&self.attack_labels).enumerate() {
            out.push((s, label.clone(), Look::Step(other(i))));
        }
        let mut first = None;
        for (s, name, look) in &out {
            if let Err(e) = send_one(rec, s, name, *look) {
                first.get_or_insert(e);
            }
        }
        first.map_or(Ok(()), Err)
    }

    fn barriers(&mut self, out: &mut Vec<(Series, String, Look)>) {
        let cross = Look::Dots(MARK, rerun::components::MarkerShape::Cross);
        for (j, truth) in std::mem::take(&mut self.h_truth).into_iter().enumerate() {
            let r = widened(truth.range());
            let base = truth.path.trim_end_matches("/truth").to_string();
            let mut marks = Series::new(format!("{base}/clipped"));
            for (i, mut s) in std::mem::take(&mut self.h_est[j]).into_iter().enumerate() {
                s.clip(r, &mut marks);
                out.push((s, self.filters[i].clone(), Look::Line(palette(i), 1.5)));
            }
            let zero = Series::constant(format!("{base}/zero"), &truth, 0.0);
            out.push((zero, "h = 0 (boundary)".into(), Look::Line(MARK, 1.0)));
            out.push((truth, "truth".into(), Look::Line(TRUTH, 2.5)));
            out.push((marks, "clipped to plot range".into(), cross));
        }
    }

    fn estimator_stats(&mut self, out: &mut Vec<(Series, String, Look)>) {
        let cross = Look::Dots(MARK, rerun::components::MarkerShape::Cross);
        let mut v_marks = Series::new("clf/clipped".into());
        let mut r_marks = Series::new("residues/clipped".into());
        for (i, mut v) in std::mem::take(&mut self.clf).into_iter().enumerate() {
            let v0 = v.v.first().copied().filter(|v0| *v0 > 0.0).unwrap_or(1.0);
            v.v.iter_mut().for_each(|x| *x /= v0);
            v.clip((0.0, V_RATIO_MAX), &mut v_marks);
            out.push((v, self.filters[i].clone(), Look::Line(palette(i), 1.5)));
        }
        for (i, mut r) in std::mem::take(&mut self.residues).into_iter().enumerate() {
            r.v.iter_mut()
                .for_each(|x| *x = x.max(RESIDUE_FLOOR).log10());
            r.clip((RESIDUE_FLOOR.log10(), RESIDUE_MAX.log10()), &mut r_marks);
            out.push((r, self.filters[i].clone(), Look::Line(palette(i), 1.5)));
        }
        let mut g_marks = Series::new("estimation_error/clipped".into());
        let mut g_span = Series::default();
        for (i, mut g) in std::mem::take(&mut self.gamma_ratio)
            .into_iter()
            .enumerate()
        {
            g.clip((0.0, GAMMA_RATIO_MAX), &mut g_marks);
            if g_span.t.len() < g.t.len() {
                g_span = g.clone();
            }
            out.push((g, self.filters[i].clone(), Look::Line(palette(i), 1.5)));
        }
        if !g_span.t.is_empty() {
            out.push((
                Series::constant("estimation_error/bound".into(), &g_span, 1.0),
                "γ (Theorem 1's bound)".into(),
                Look::Line(MARK, 1.0),
            ));
            out.push((g_marks, "clipped to plot range".into(), cross));
        }
        let mut z_marks = Series::new("detector/clipped".into());
        let mut span = Series::default();
        for (i, mut z) in std::mem::take(&mut self.z).into_iter().enumerate() {
            z.clip((-Z_MAX, Z_MAX), &mut z_marks);
            if span.t.len() < z.t.len() {
                span = z.clone();
            }
            out.push((z, self.channels[i].clone(), Look::Line(other(i), 1.5)));
        }
        let bound = |path: &str, v| Series::constant(path.into(), &span, v);
        out.push((
            bound("detector/bound_hi", 3.0),
            "+3σ".into(),
            Look::Line(MARK, 1.0),
        ));
        out.push((
            bound("detector/bound_lo", -3.0),
            "−3σ".into(),
            Look::Line(MARK, 1.0),
        ));
        out.push((v_marks, "clipped to plot range".into(), cross));
        out.push((r_marks, "clipped to plot range".into(), cross));
        out.push((z_marks, "clipped to plot range".into(), cross));
    }
}

/// Sends one series: its look as static styling, its values as columns on both timelines.
fn send_one(
    rec: &rerun::RecordingStream,
    s: &Series,
    name: &str,
    look: Look,
) -> Result<(), String> {
    if s.v.is_empty() {
        return Ok(());
    }
    let e = |e: rerun::RecordingStreamError| e.to_string();
    let path = s.path.as_str();
    match look {
        Look::Line(c, w) => rec.log_static(
            path,
            &rerun::SeriesLines::new()
                .with_colors([c])
                .with_widths([w])
                .with_names([name]),
        ),
        Look::Step(c) => rec.log_static(
            path,
            &rerun::SeriesLines::new()
                .with_colors([c])
                .with_widths([2.0])
                .with_names([name])
                .with_interpolation_mode(rerun::components::InterpolationMode::StepAfter),
        ),
        Look::Dots(c, m) => rec.log_static(
            path,
            &rerun::SeriesPoints::new()
                .with_colors([c])
                .with_markers([m])
                .with_marker_sizes([3.0])
                .with_names([name]),
        ),
    }
    .map_err(e)?;
    let cols = rerun::Scalars::new(s.v.iter().copied())
        .columns_of_unit_batches()
        .map_err(|e| e.to_string())?;
    rec.send_columns(
        path,
        [
            rerun::TimeColumn::new_duration_secs("sim_time", s.t.iter().copied()),
            rerun::TimeColumn::new_sequence("step", s.step.iter().copied()),
        ],
        cols,
    )
    .map_err(e)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_absurd_value_is_cut_to_the_widened_range_and_marked() {
        let mut clean = Series::new("sensors/x/clean".into());
        let mut received = Series::new("sensors/x/received".into());
        for (k, v) in [0.0, 1.0, 2.0].into_iter().enumerate() {
            clean.push(k as f64, k as u64, v);
            received.push(k as f64, k as u64, if k == 1 { 1e12 } else { v });
        }
        received.push(3.0, 3, f64::NAN);
        let r = widened(clean.range());
        assert_eq!(r, (-2.0, 4.0));
        let mut marks = Series::default();
        received.clip(r, &mut marks);
        assert_eq!(received.v, vec![0.0, 4.0, 2.0]);
        assert_eq!((marks.t, marks.v), (vec![1.0], vec![4.0]));
    }

    #[test]
    fn a_flat_reference_still_gets_a_range() {
        assert_eq!(widened(Some((1.0, 1.0))), (0.5, 1.5));
        assert_eq!(widened(None), (-1.5, 1.5));
    }
}
