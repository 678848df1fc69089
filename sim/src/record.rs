//! Headless rerun recording of a run to an `.rrd` file (feature `record`).
//!
//! Entity paths (stable; the README describes what the viewer shows):
//! - `world/ground`, `world/obstacles/<name>`, `world/safe_sets/<name>`, `world/goal` — static scene;
//! - `world/robot/<link>` — link transforms every control step, link shapes (static) below them;
//! - `world/trail` — the whole true path (static, written at the end); `world/estimates/<filter>`
//!   — each estimator's position every control step;
//! - `sensors/<channel>/{clean,received,detector_z}`, `barriers/<barrier>/{truth,<filter>}`, `clf/<filter>`,
//!   `residues/<filter>`, `control/{u_x,u_y,v,omega}`, `attacks/<label>` — time series;
//! - `events/policy` (dropped constraints and why), `events/safety` (collisions, violations) — text logs.
//!
//! Timelines: `sim_time` (seconds) and `step` (control step). The recording id is derived from the
//! world, the controller and the seed, and log time is not recorded, so a file says what ran, not when.
//!
//! Cost: transforms and estimate points are logged as they happen; every time series is kept in
//! memory and sent once, as columns, by [`Recorder::finish`] (one chunk per series instead of one
//! message per value).

use std::path::Path;

use rerun::{RecordingStream, RecordingStreamBuilder};

use crate::observe::{Frame, Geometry, Observer, Placed, Scene};

/// Why a recording could not be written.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// The file could not be created.
    #[error("cannot create the recording {path}: {message}")]
    Create {
        /// The .rrd path.
        path: String,
        /// The SDK's message.
        message: String,
    },
    /// The SDK failed while logging or flushing.
    #[error("recording {path}: {message}")]
    Write {
        /// The .rrd path.
        path: String,
        /// The SDK's message.
        message: String,
    },
}

/// Writes a run to an `.rrd` file. Logging errors are kept and reported by [`Recorder::finish`].
pub struct Recorder {
    rec: RecordingStream,
    path: String,
    scene: Scene,
    trail: Vec<[f32; 3]>,
    series: Vec<Series>,
    first_error: Option<String>,
}

/// One scalar time series, buffered until [`Recorder::finish`].
struct Series {
    path: String,
    t: Vec<f64>,
    step: Vec<i64>,
    v: Vec<f64>,
}

impl Series {
    fn new(path: String) -> Self {
        Self {
            path,
            t: Vec::new(),
            step: Vec::new(),
            v: Vec::new(),
        }
    }
    /// Appends a finite value (a plot cannot show NaN or ±∞; the events say when they came).
    fn push(&mut self, t: f64, step: u64, v: f64) {
        if v.is_finite() {
            self.t.push(t);
            self.step.push(step as i64);
            self.v.push(v);
        }
    }
}

/// Index of the first series of each group, in the order `scene` creates them.
const U_SERIES: [&str; 4] = ["control/u_x", "control/u_y", "control/v", "control/omega"];

fn palette(i: usize) -> rerun::Color {
    const C: [[u8; 3]; 10] = [
        [31, 119, 180],
        [255, 127, 14],
        [44, 160, 44],
        [214, 39, 40],
        [148, 103, 189],
        [140, 86, 75],
        [227, 119, 194],
        [127, 127, 127],
        [188, 189, 34],
        [23, 190, 207],
    ];
    let [r, g, b] = C[i % C.len()];
    rerun::Color::from_rgb(r, g, b)
}

/// An entity-path segment: letters, digits, `_`, `-` and `+` kept, any other run of characters
/// becomes one `_`, no `_` at either end.
fn seg(name: &str) -> String {
    let mut s = String::with_capacity(name.len());
    for c in name.chars() {
        if c.is_ascii_alphanumeric() || c == '_' || c == '-' || c == '+' {
            s.push(c);
        } else if !s.ends_with('_') {
            s.push('_');
        }
    }
    let t = s.trim_matches('_');
    if t.is_empty() {
        "_".into()
    } else {
        t.to_string()
    }
}

impl Recorder {
    /// Creates `path` (and its directory) and a stream with a recording id fixed by `recording_id`.
    pub fn create(path: &Path, recording_id: &str) -> Result<Self, RecordError> {
        let p = path.display().to_string();
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| RecordError::Create {
                path: p.clone(),
                message: e.to_string(),
            })?;
        }
        let rec = RecordingStreamBuilder::new("ftcbf")
            .recording_id(recording_id)
            .recording_name(recording_id)
            .enabled(true)
            .save(path)
            .map_err(|e| RecordError::Create {
                path: p.clone(),
                message: e.to_string(),
            })?;
        rec.set_log_time_enabled(false);
        Ok(Self {
            rec,
            path: p,
            scene: Scene::default(),
            trail: Vec::new(),
            series: Vec::new(),
            first_error: None,
        })
    }

    fn keep<T, E: std::fmt::Display>(&mut self, r: Result<T, E>) {
        if let Err(e) = r {
            self.first_error.get_or_insert_with(|| e.to_string());
        }
    }

    fn log_placed(&mut self, base: &str, p: &Placed, color: rerun::Color) {
        let path = format!("{base}/{}", seg(&p.name));
        let tf = rerun::Transform3D::from_translation_rotation(
            p.translation,
            rerun::Quaternion::from_xyzw(p.rotation),
        );
        let r = self.rec.log_static(path.as_str(), &tf);
        self.keep(r);
        let r = match &p.geometry {
            Geometry::Cuboid { half_extents } => self.rec.log_static(
                path.as_str(),
                &rerun::Boxes3D::from_half_sizes([*half_extents])
                    .with_colors([color])
                    .with_fill_mode(rerun::FillMode::Solid),
            ),
            Geometry::Ball { radius } => self.rec.log_static(
                path.as_str(),
                &rerun::Ellipsoids3D::from_radii([*radius])
                    .with_colors([color])
                    .with_fill_mode(rerun::FillMode::Solid),
            ),
            Geometry::Cylinder {
                radius,
                half_height,
            } => self.rec.log_static(
                path.as_str(),
                &rerun::Cylinders3D::from_lengths_and_radii([2.0 * half_height], [*radius])
                    .with_colors([color])
                    .with_fill_mode(rerun::FillMode::Solid),
            ),
            Geometry::Capsule {
                radius,
                half_height,
            } => self.rec.log_static(
                path.as_str(),
                // rerun capsules run from the origin along +z: give the endpoints, centred.
                &rerun::Capsules3D::from_endpoints_and_radii(
                    [[0.0, 0.0, -half_height]],
                    [[0.0, 0.0, *half_height]],
                    [*radius],
                )
                .with_colors([color]),
            ),
            Geometry::Mesh {
                vertices,
                triangles,
            } => self.rec.log_static(
                path.as_str(),
                &rerun::Mesh3D::new(vertices.iter().copied())
                    .with_triangle_indices(triangles.iter().copied())
                    .with_albedo_factor(color.0),
            ),
        };
        self.keep(r);
    }

    /// Flushes and closes the file; reports the first logging error, if any.
    pub fn finish(mut self) -> Result<(), RecordError> {
        for sr in std::mem::take(&mut self.series) {
            if sr.v.is_empty() {
                continue;
            }
            let r = rerun::Scalars::new(sr.v)
                .columns_of_unit_batches()
                .map_err(|e| e.to_string())
                .and_then(|cols| {
                    self.rec
                        .send_columns(
                            sr.path.as_str(),
                            [
                                rerun::TimeColumn::new_duration_secs("sim_time", sr.t),
                                rerun::TimeColumn::new_sequence("step", sr.step),
                            ],
                            cols,
                        )
                        .map_err(|e| e.to_string())
                });
            self.keep(r);
        }
        if !self.trail.is_empty() {
            let r = self.rec.log_static(
                "world/trail",
                &rerun::LineStrips3D::new([std::mem::take(&mut self.trail)])
                    .with_colors([rerun::Color::from_rgb(0, 0, 0)]),
            );
            self.keep(r);
        }
        let r = self.rec.flush_blocking();
        self.keep(r);
        self.rec.disconnect();
        match self.first_error {
            Some(message) => Err(RecordError::Write {
                path: self.path,
                message,
            }),
            None => Ok(()),
        }
    }
}

impl Observer for Recorder {
    fn scene(&mut self, scene: &Scene) {
        self.scene = scene.clone();
        let r = self
            .rec
            .log_static("world", &rerun::ViewCoordinates::RIGHT_HAND_Z_UP());
        self.keep(r);
        let r = self.rec.log_static(
            "world/ground",
            &rerun::Boxes3D::from_centers_and_half_sizes([[0.0, 0.0, -0.005]], [[5.0, 5.0, 0.005]])
                .with_colors([rerun::Color::from_rgb(200, 200, 200)]),
        );
        self.keep(r);
        for ob in &scene.obstacles {
            self.log_placed("world/obstacles", ob, rerun::Color::from_rgb(120, 120, 140));
        }
        for (name, pts) in &scene.safe_set_outlines {
            let r = self.rec.log_static(
                format!("world/safe_sets/{}", seg(name)).as_str(),
                &rerun::LineStrips3D::new([pts.clone()])
                    .with_colors([rerun::Color::from_rgb(214, 39, 40)])
                    .with_labels([name.as_str()]),
            );
            self.keep(r);
        }
        let ([gx, gy], gr) = scene.goal;
        let circle: Vec<[f32; 3]> = (0..=64)
            .map(|k| {
                let a = k as f32 / 64.0 * std::f32::consts::TAU;
                [gx + gr * a.cos(), gy + gr * a.sin(), 0.002]
            })
            .collect();
        let r = self.rec.log_static(
            "world/goal",
            &rerun::LineStrips3D::new([circle])
                .with_colors([rerun::Color::from_rgb(44, 160, 44)])
                .with_labels(["goal"]),
        );
        self.keep(r);
        for (link, shapes) in &scene.robot_links {
            let base = format!("world/robot/{}", seg(link));
            for s in shapes {
                self.log_placed(&base, s, rerun::Color::from_rgb(60, 60, 60));
            }
        }
        for (i, f) in scene.filters.iter().enumerate() {
            let r = self.rec.log_static(
                format!("world/estimates/{}", seg(f)).as_str(),
                &rerun::Points3D::new([[0.0f32, 0.0, 0.0]])
                    .with_colors([palette(i)])
                    .with_radii([0.012f32])
                    .with_labels([f.as_str()]),
            );
            self.keep(r);
        }
        // Time series, in the order `frame` fills them.
        let mut series = Vec::new();
        for f in &scene.filters {
            series.push(Series::new(format!("clf/{}", seg(f))));
            series.push(Series::new(format!("residues/{}", seg(f))));
        }
        for c in &scene.channels {
            series.push(Series::new(format!("sensors/{}/clean", seg(c))));
            series.push(Series::new(format!("sensors/{}/received", seg(c))));
            series.push(Series::new(format!("sensors/{}/detector_z", seg(c))));
        }
        for b in &scene.barriers {
            series.push(Series::new(format!("barriers/{}/truth", seg(b))));
            for f in &scene.filters {
                series.push(Series::new(format!("barriers/{}/{}", seg(b), seg(f))));
            }
        }
        for u in U_SERIES {
            series.push(Series::new(u.to_string()));
        }
        for a in &scene.attacks {
            series.push(Series::new(format!("attacks/{}", seg(a))));
        }
        self.series = series;
    }

    fn frame(&mut self, f: &Frame<'_>) {
        self.rec.set_duration_secs("sim_time", f.t);
        self.rec.set_time_sequence("step", f.step as i64);
        let mut results = Vec::new();
        for (name, pos, quat) in f.link_poses {
            results.push(self.rec.log(
                format!("world/robot/{}", seg(name)).as_str(),
                &rerun::Transform3D::from_translation_rotation(
                    *pos,
                    rerun::Quaternion::from_xyzw(*quat),
                ),
            ));
        }
        self.trail.push([f.truth.x as f32, f.truth.y as f32, 0.003]);
        for (i, e) in f.estimates.iter().enumerate() {
            let Some(label) = self.scene.filters.get(i) else {
                continue;
            };
            results.push(
                self.rec.log(
                    format!("world/estimates/{}", seg(label)).as_str(),
                    &rerun::Points3D::new([[e.x[0] as f32, e.x[1] as f32, 0.01]])
                        .with_colors([palette(i)])
                        .with_radii([0.012f32]),
                ),
            );
        }
        // Series, in the order `scene` created them.
        let (t, k) = (f.t, f.step);
        let nf = self.scene.filters.len();
        let nc = self.scene.channels.len();
        let nb = self.scene.barriers.len();
        let mut it = self.series.iter_mut();
        for i in 0..nf {
            let e = f.estimates.get(i);
            if let Some(sr) = it.next() {
                sr.push(t, k, e.map_or(f64::NAN, |e| e.clf));
            }
            if let Some(sr) = it.next() {
                sr.push(t, k, e.map_or(f64::NAN, |e| e.residue));
            }
        }
        for i in 0..nc {
            let c = f.channels.get(i);
            if let Some(sr) = it.next() {
                sr.push(t, k, c.map_or(f64::NAN, |c| c.clean));
            }
            if let Some(sr) = it.next() {
                sr.push(t, k, c.map_or(f64::NAN, |c| c.received));
            }
            if let Some(sr) = it.next() {
                sr.push(t, k, c.map_or(f64::NAN, |c| c.detector_z));
            }
        }
        for j in 0..nb {
            if let Some(sr) = it.next() {
                sr.push(t, k, f.barrier_truth.get(j).copied().unwrap_or(f64::NAN));
            }
            for i in 0..nf {
                if let Some(sr) = it.next() {
                    sr.push(
                        t,
                        k,
                        f.barrier_values
                            .get(i * nb + j)
                            .copied()
                            .unwrap_or(f64::NAN),
                    );
                }
            }
        }
        for v in [f.u[0], f.u[1], f.body_cmd[0], f.body_cmd[1]] {
            if let Some(sr) = it.next() {
                sr.push(t, k, v);
            }
        }
        for on in f.attacks_active {
            if let Some(sr) = it.next() {
                sr.push(t, k, if *on { 1.0 } else { 0.0 });
            }
        }
        if !f.decision_note.is_empty() {
            results.push(
                self.rec.log(
                    "events/policy",
                    &rerun::TextLog::new(format!("[{}] {}", f.decided_by, f.decision_note))
                        .with_level(rerun::TextLogLevel::INFO),
                ),
            );
        }
        for e in f.events {
            results.push(self.rec.log(
                "events/safety",
                &rerun::TextLog::new(e.as_str()).with_level(rerun::TextLogLevel::ERROR),
            ));
        }
        for r in results {
            self.keep(r);
        }
    }
}
