//! Headless rerun recording of a run to an `.rrd` file (feature `record`), with a default
//! blueprint so the viewer shows the run, with no clicking, as `layout` describes.
//!
//! Entity paths (stable; segments hold only ASCII letters, digits, `_` and `-`):
//! - `world/ground` (sized to the run), `world/obstacles/<name>` (solid, standing on the floor;
//!   a half-space's wall patch cut to the ground, 0.3 m high), `world/movers/<name>/<name>` (a
//!   moving obstacle, issue #51: its shape at its start, static, under `world/movers/<name>`,
//!   whose translation over time is its displacement) and its path `world/trails/movers/<name>`,
//!   `world/safe_sets/<name>` (boundary at rest; half-planes cut to the ground), `world/goal`,
//!   `world/collisions/{robot,mover}` (a marker where each contact began, by who moved: the
//!   robot's — a static obstacle, or the robot moving into a mover — or a mover's walking into
//!   the stopped robot; labelled with the obstacle and the time);
//! - `world/robot/<link>` — link pose over time, its shapes (static) below it: the body's URDF
//!   visual meshes where they were found, its collision shapes otherwise;
//! - `world/estimates/<filter>` — each estimator's position over time (colour and radius
//!   static); `world/trails/{truth,<filter>}` — paths growing with time (a point every
//!   [`TRAIL_EVERY`] control steps);
//! - plots, as `plots` describes: `barriers/<barrier>/{truth,<filter>,zero,clipped}`,
//!   `sensors/<channel>/{clean,received,rejected,attack_window,clipped}`, `detector/<channel>`,
//!   `residues/<filter>`, `clf/<filter>` (V/V₀), `estimation_error/<filter>` (‖x − x̂‖/γ against
//!   the truth, with `estimation_error/bound` at 1), `control/{v,omega,u_x,u_y}`, `attacks/<label>`;
//! - `events/policy` (stage changes and dropped constraints; WARN when infeasible, naming the
//!   tightest constraint), `events/safety` (WARN: collisions and violations, naming the obstacle
//!   or set), `events/attacks` (WARN at a window's start, INFO at its end).
//!
//! One colour per estimator (`draw::palette`) in the 3D view and in every plot. The 3D view
//! opens looking down on the ground from its −y side (`layout`: eye position and target are in
//! the blueprint), so no wall stands between the eye and the robot.
//! Timelines: `sim_time` (seconds) and `step` (control step). The application id and the
//! recording name are `ftcbf-<world>-<controller>-seed<N>`, so each world/controller/seed has its
//! own stored layout in the viewer; log time is not recorded. The blueprint's view ids are random
//! (rerun's API), so two files of the same run differ there and nowhere in the data.
//!
//! Cost: positions, transforms and series are buffered and sent once, as columns, by
//! [`Recorder::finish`]; only trails and events are logged as the run goes.

mod draw;
mod events;
mod layout;
mod plots;

use std::path::Path;

use rerun::external::re_log_types::BlueprintActivationCommand;
use rerun::log::LogMsg;
use rerun::sink::{FileSink, LogSink};
use rerun::{RecordingStream, RecordingStreamBuilder};

use crate::observe::{Frame, Observer, Scene};
use draw::{
    log_placed, palette, seg, Rect, COLLISION_MOVER, COLLISION_ROBOT, GOAL, MOVER, ROBOT, SAFE_SET,
    TRUTH,
};
use plots::Plots;

pub use layout::EYE_ELEVATION;
pub use plots::{MIN_SPAN, RESIDUE_FLOOR, RESIDUE_MAX, V_RATIO_MAX, Z_MAX};

/// Trails get a point, and are re-logged, every this many control steps.
pub const TRAIL_EVERY: u64 = 10;

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

/// What a recording is of: the same world, controller and seed give the same name, id and
/// application id (so the viewer keeps one stored layout per world, controller and seed).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RecordingName {
    /// The world's name (its file stem).
    pub world: String,
    /// The controller's name, as `--controller` takes it.
    pub controller: String,
    /// The run's seed.
    pub seed: u64,
}

impl RecordingName {
    /// `<world>-<controller>-seed<N>`: the recording id and the name the viewer lists.
    pub fn id(&self) -> String {
        format!("{}-{}-seed{}", self.world, self.controller, self.seed)
    }

    /// The recording's name and properties (`world`, `controller`, `seed` under `ftcbf`), which
    /// the viewer shows for the recording in its source list.
    fn send(&self, rec: &RecordingStream) -> Result<(), String> {
        use rerun::components::Text;
        rec.send_recording_name(self.id())
            .map_err(|e| e.to_string())?;
        let props = rerun::AnyValues::default()
            .with_component::<Text>("world", [self.world.as_str()])
            .with_component::<Text>("controller", [self.controller.as_str()])
            .with_component::<Text>("seed", [self.seed.to_string()]);
        rec.send_property("ftcbf", &props)
            .map_err(|e| e.to_string())
    }
}

/// A robot link's name, translations and quaternions (x, y, z, w) at every step.
type LinkTrack = (String, Vec<[f32; 3]>, Vec<[f32; 4]>);

/// Writes a run to an `.rrd` file. Logging errors are kept and reported by [`Recorder::finish`].
pub struct Recorder {
    rec: RecordingStream,
    file: std::path::PathBuf,
    app: rerun::ApplicationId,
    name: RecordingName,
    path: String,
    scene: Scene,
    plots: Plots,
    ground: Option<Rect>,
    time: Vec<f64>,
    steps: Vec<i64>,
    /// Per estimator, its position at every step.
    positions: Vec<Vec<[f32; 3]>>,
    /// Per link, (translation, quaternion xyzw) at every step.
    links: Vec<LinkTrack>,
    /// Truth first, then one per estimator.
    trails: Vec<Vec<[f32; 3]>>,
    /// Per mover, its displacement from its start at every step.
    mover_moves: Vec<Vec<[f32; 3]>>,
    /// Per mover, its start in the plane and its path (a point every [`TRAIL_EVERY`] steps).
    mover_trails: Vec<([f32; 2], Vec<[f32; 3]>)>,
    /// Per mover, where the controller read it (its tracker's estimate) and its bound γ_p at
    /// every step, and whether that ever differed from the truth (a tracked mover).
    mover_readings: Vec<(Vec<[f32; 3]>, Vec<f32>, bool)>,
    /// Contacts so far: (the robot's, position, label); markers under `world/collisions/`.
    contacts: Vec<(bool, [f32; 3], String)>,
    last_policy: String,
    last_attacks: Vec<bool>,
    first_error: Option<String>,
}

impl Recorder {
    /// Checks that `path` (and its directory) can be created and names the stream by `name`:
    /// recording id, recording name (`<world>-<controller>-seed<N>`), application id and the
    /// recording's properties. The file is written from the first frame on
    /// ([`Observer::frame`]), because the default blueprint needs the scene's names and the
    /// robot's start.
    pub fn create(path: &Path, name: &RecordingName) -> Result<Self, RecordError> {
        let p = path.display().to_string();
        let create_err = |message: String| RecordError::Create {
            path: p.clone(),
            message,
        };
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| create_err(e.to_string()))?;
        }
        std::fs::File::create(path).map_err(|e| create_err(e.to_string()))?;
        let app = rerun::ApplicationId::try_new(format!("ftcbf-{}", seg(&name.id())))
            .map_err(|e| create_err(e.to_string()))?;
        Ok(Self {
            rec: RecordingStream::disabled(),
            file: path.to_path_buf(),
            app,
            name: name.clone(),
            path: p,
            scene: Scene::default(),
            plots: Plots::default(),
            ground: None,
            time: Vec::new(),
            steps: Vec::new(),
            positions: Vec::new(),
            links: Vec::new(),
            trails: Vec::new(),
            mover_moves: Vec::new(),
            mover_trails: Vec::new(),
            mover_readings: Vec::new(),
            contacts: Vec::new(),
            last_policy: String::new(),
            last_attacks: Vec::new(),
            first_error: None,
        })
    }

    /// Opens the file stream at the first frame, when the robot's start is known. The file
    /// starts with the default blueprint and its activation (its 3D eye is framed on the ground,
    /// which the start is part of), and only then the recording's store info, its name and
    /// properties, and the static scene — ground, obstacles, safe sets, goal, robot shapes,
    /// estimator colours. The order matters to the viewer: a recording it sees before its
    /// blueprint becomes active at once, its heuristics fill an empty blueprint, and a default
    /// blueprint that arrives later is stored but not shown (measured with the rerun 0.36.3
    /// viewer; rerun's Python `rr.save(…, default_blueprint=…)` writes the blueprint first too).
    /// The stream is therefore created buffered, the blueprint written to the file sink
    /// directly, and the sink swapped in afterwards (the stream's backlog, store info first,
    /// follows the blueprint).
    fn open(&mut self, start: [f32; 2]) {
        let ground = draw::scene_extent(&self.scene, start);
        self.ground = Some(ground);
        let sink = match FileSink::new(&self.file) {
            Ok(sink) => sink,
            Err(e) => return self.keep::<(), _>(Err(e)),
        };
        let blueprint = layout::messages(&self.app, &self.scene, &ground, start);
        match start_stream(&self.app, &self.name, Box::new(sink), blueprint) {
            Ok(rec) => self.rec = rec,
            Err(e) => return self.keep::<(), _>(Err(e)),
        }
        self.log_scene();
        self.log_ground(ground, start);
    }

    fn keep<T, E: std::fmt::Display>(&mut self, r: Result<T, E>) {
        if let Err(e) = r {
            self.first_error.get_or_insert_with(|| e.to_string());
        }
    }

    /// The ground (`r`), the obstacles and the safe sets. A mesh around the robot's `start` or
    /// the goal (an arena's or a room's walls) is drawn see-through ([`draw::encloses`]).
    fn log_ground(&mut self, r: Rect, start: [f32; 2]) {
        let c = [(r.lo[0] + r.hi[0]) / 2.0, (r.lo[1] + r.hi[1]) / 2.0, -0.005];
        let h = [(r.hi[0] - r.lo[0]) / 2.0, (r.hi[1] - r.lo[1]) / 2.0, 0.005];
        let res = self.rec.log_static(
            "world/ground",
            &rerun::Boxes3D::from_centers_and_half_sizes([c], [h])
                .with_colors([rerun::Color::from_rgb(225, 225, 220)])
                .with_fill_mode(rerun::FillMode::Solid),
        );
        self.keep(res);
        let ([gx, gy], _) = self.scene.goal;
        for ob in &self.scene.obstacles {
            let wall = self.scene.half_space_walls.contains(&ob.name);
            let alpha = if draw::encloses(ob, &[start, [gx, gy]]) {
                draw::SEE_THROUGH_ALPHA
            } else {
                255
            };
            let moves = self.scene.movers.contains(&ob.name);
            let (base, color) = if moves {
                (format!("world/movers/{}", seg(&ob.name)), MOVER)
            } else {
                (
                    "world/obstacles".to_string(),
                    rerun::Color::from_unmultiplied_rgba(130, 130, 150, alpha),
                )
            };
            let res = log_placed(
                &self.rec,
                &base,
                &draw::cut_to_ground(&draw::standing(ob), &r, wall),
                color,
            );
            if let Err(e) = res {
                self.first_error.get_or_insert_with(|| e.to_string());
            }
        }
        for (name, pts) in self.scene.safe_set_outlines.clone() {
            let pts = match pts.as_slice() {
                [a, b] => match r.clip(*a, *b) {
                    Some((a, b)) => vec![a, b],
                    None => continue,
                },
                _ => pts,
            };
            let res = self.rec.log_static(
                format!("world/safe_sets/{}", seg(&name)).as_str(),
                &rerun::LineStrips3D::new([pts])
                    .with_colors([SAFE_SET])
                    .with_radii([0.006f32])
                    .with_labels([name.as_str()]),
            );
            self.keep(res);
        }
    }

    /// World axes, goal, robot shapes (static, under each link's moving pose) and the
    /// estimators' colours and radii (static; their positions are temporal).
    fn log_scene(&mut self) {
        let r = self
            .rec
            .log_static("world", &rerun::ViewCoordinates::RIGHT_HAND_Z_UP());
        self.keep(r);
        let ([gx, gy], gr) = self.scene.goal;
        let r = self.rec.log_static(
            "world/goal",
            &rerun::LineStrips3D::new([draw::circle([gx, gy], gr, 0.003)])
                .with_colors([GOAL])
                .with_radii([0.008f32])
                .with_labels(["goal"]),
        );
        self.keep(r);
        let mut results = Vec::new();
        for (link, shapes) in &self.scene.robot_links {
            let base = format!("world/robot/{}", seg(link));
            for s in shapes {
                results.push(log_placed(&self.rec, &base, s, ROBOT));
            }
        }
        for (i, f) in self.scene.filters.iter().enumerate() {
            results.push(
                self.rec.log_static(
                    format!("world/estimates/{}", seg(f)).as_str(),
                    &rerun::Points3D::update_fields()
                        .with_colors([palette(i)])
                        .with_radii([0.03f32]),
                ),
            );
        }
        for r in results {
            self.keep(r);
        }
    }

    /// Re-logs every trail (at the current time), so it grows with time.
    fn log_trails(&mut self) {
        for (i, pts) in self.trails.iter().enumerate() {
            let (path, color) = match i {
                0 => ("world/trails/truth".to_string(), TRUTH),
                _ => (
                    format!("world/trails/{}", seg(&self.scene.filters[i - 1])),
                    palette(i - 1),
                ),
            };
            let r = self.rec.log(
                path.as_str(),
                &rerun::LineStrips3D::new([pts.clone()])
                    .with_colors([color])
                    .with_radii([if i == 0 { 0.006f32 } else { 0.004 }]),
            );
            if let Err(e) = r {
                self.first_error.get_or_insert_with(|| e.to_string());
            }
        }
        for (name, (_, pts)) in self.scene.movers.iter().zip(&self.mover_trails) {
            let r = self.rec.log(
                format!("world/trails/movers/{}", seg(name)).as_str(),
                &rerun::LineStrips3D::new([pts.clone()])
                    .with_colors([MOVER])
                    .with_radii([0.005f32]),
            );
            if let Err(e) = r {
                self.first_error.get_or_insert_with(|| e.to_string());
            }
        }
    }

    /// Sends the buffered positions and link poses as columns.
    fn send_poses(&mut self) -> Result<(), String> {
        let times = || {
            [
                rerun::TimeColumn::new_duration_secs("sim_time", self.time.iter().copied()),
                rerun::TimeColumn::new_sequence("step", self.steps.iter().copied()),
            ]
        };
        let e = |e: &dyn std::fmt::Display| e.to_string();
        for (i, pos) in self.positions.iter().enumerate() {
            let cols = rerun::Points3D::update_fields()
                .with_positions(pos.iter().copied())
                .columns_of_unit_batches()
                .map_err(|x| e(&x))?;
            let path = format!("world/estimates/{}", seg(&self.scene.filters[i]));
            self.rec
                .send_columns(path.as_str(), times(), cols)
                .map_err(|x| e(&x))?;
        }
        for (name, tr, q) in &self.links {
            let cols = rerun::Transform3D::update_fields()
                .with_many_translation(tr.iter().copied())
                .with_many_quaternion(q.iter().map(|q| rerun::Quaternion::from_xyzw(*q)))
                .columns_of_unit_batches()
                .map_err(|x| e(&x))?;
            let path = format!("world/robot/{}", seg(name));
            self.rec
                .send_columns(path.as_str(), times(), cols)
                .map_err(|x| e(&x))?;
        }
        for (name, moves) in self.scene.movers.iter().zip(&self.mover_moves) {
            let cols = rerun::Transform3D::update_fields()
                .with_many_translation(moves.iter().copied())
                .columns_of_unit_batches()
                .map_err(|x| e(&x))?;
            let path = format!("world/movers/{}", seg(name));
            self.rec
                .send_columns(path.as_str(), times(), cols)
                .map_err(|x| e(&x))?;
        }
        self.send_mover_readings()
    }

    /// A tracked mover's reading (issue #51) beside it: a point at the estimated centre, its
    /// radius the position bound γ_p, at `world/mover_estimates/<name>` (movers read exactly
    /// have none).
    fn send_mover_readings(&mut self) -> Result<(), String> {
        let times = || {
            [
                rerun::TimeColumn::new_duration_secs("sim_time", self.time.iter().copied()),
                rerun::TimeColumn::new_sequence("step", self.steps.iter().copied()),
            ]
        };
        for (name, (pos, radii, tracked)) in self.scene.movers.iter().zip(&self.mover_readings) {
            if !*tracked {
                continue;
            }
            let cols = rerun::Points3D::update_fields()
                .with_positions(pos.iter().copied())
                .with_radii(radii.iter().copied())
                .with_colors(pos.iter().map(|_| draw::MOVER_ESTIMATE))
                .columns_of_unit_batches()
                .map_err(|x| x.to_string())?;
            let path = format!("world/mover_estimates/{}", seg(name));
            self.rec
                .send_columns(path.as_str(), times(), cols)
                .map_err(|x| x.to_string())?;
        }
        Ok(())
    }

    /// Flushes and closes the file; reports the first logging error, if any.
    pub fn finish(mut self) -> Result<(), RecordError> {
        if self.ground.is_none() && self.first_error.is_none() {
            self.first_error = Some("the run ended before its first step was recorded".into());
        }
        self.log_trails();
        let r = self.send_poses();
        self.keep(r);
        let r = std::mem::take(&mut self.plots).send(&self.rec);
        self.keep(r);
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

    /// Events of this frame: policy changes, safety events, attack windows starting/ending.
    fn log_events(&mut self, f: &Frame<'_>) {
        let mut results = Vec::new();
        let (key, policy) = events::policy_line(&self.scene, f);
        if key != self.last_policy {
            let level = if f.decided_by == "infeasible" {
                rerun::TextLogLevel::WARN
            } else {
                rerun::TextLogLevel::INFO
            };
            results.push(self.rec.log(
                "events/policy",
                &rerun::TextLog::new(policy.as_str()).with_level(level),
            ));
            self.last_policy = key;
        }
        for e in f.events {
            results.push(self.rec.log(
                "events/safety",
                &rerun::TextLog::new(e.as_str()).with_level(rerun::TextLogLevel::WARN),
            ));
        }
        self.last_attacks.resize(f.attacks_active.len(), false);
        for (a, &on) in f.attacks_active.iter().enumerate() {
            if on != self.last_attacks[a] {
                let line = events::attack_line(&self.scene, a, on, f.t);
                let level = if on {
                    rerun::TextLogLevel::WARN
                } else {
                    rerun::TextLogLevel::INFO
                };
                results.push(self.rec.log(
                    "events/attacks",
                    &rerun::TextLog::new(line).with_level(level),
                ));
                self.last_attacks[a] = on;
            }
        }
        for r in results {
            self.keep(r);
        }
        if !f.contacts.is_empty() {
            self.log_contacts(f.contacts);
        }
    }

    /// Marks contacts where the robot was, by who moved: `world/collisions/robot` (red: a
    /// static obstacle, or the robot moving into a mover) and `world/collisions/mover` (purple:
    /// a mover walking into the stopped robot), each labelled with the obstacle and the time.
    /// Every marker so far is re-logged, so all stay drawn from their time on.
    fn log_contacts(&mut self, new: &[crate::observe::Contact]) {
        for c in new {
            let whose = c.cause.whose();
            self.contacts.push((
                whose == "robot",
                [c.at[0] as f32, c.at[1] as f32, 0.05],
                format!("{} ({whose}'s) t = {:.2} s", c.obstacle, c.t),
            ));
        }
        for (robots, path, colour) in [
            (true, "world/collisions/robot", COLLISION_ROBOT),
            (false, "world/collisions/mover", COLLISION_MOVER),
        ] {
            let (pts, labels): (Vec<[f32; 3]>, Vec<String>) = self
                .contacts
                .iter()
                .filter(|c| c.0 == robots)
                .map(|c| (c.1, c.2.clone()))
                .unzip();
            if pts.is_empty() {
                continue;
            }
            let r = self.rec.log(
                path,
                &rerun::Points3D::new(pts)
                    .with_colors([colour])
                    .with_radii([0.04f32])
                    .with_labels(labels),
            );
            self.keep(r);
        }
    }
}

/// A recording stream of application `app` named `name` on `sink`, which receives the default
/// `blueprint` and its activation before any message of the recording (see `Recorder::open`
/// for why), then the recording's store info, name and properties. Log time is off.
fn start_stream(
    app: &rerun::ApplicationId,
    name: &RecordingName,
    sink: Box<dyn LogSink>,
    blueprint: Result<(Vec<LogMsg>, BlueprintActivationCommand), String>,
) -> Result<RecordingStream, String> {
    let rec = RecordingStreamBuilder::new(app.clone())
        .recording_id(name.id())
        .enabled(true)
        .buffered()
        .map_err(|e| e.to_string())?;
    rec.set_log_time_enabled(false);
    let (msgs, activation) = blueprint?;
    sink.send_blueprint(msgs, activation);
    rec.set_sink(sink);
    name.send(&rec)?;
    Ok(rec)
}

impl Observer for Recorder {
    fn scene(&mut self, scene: &Scene) {
        self.scene = scene.clone();
        self.plots = Plots::new(scene);
        self.positions = vec![Vec::new(); scene.filters.len()];
        self.trails = vec![Vec::new(); scene.filters.len() + 1];
        self.mover_moves = vec![Vec::new(); scene.movers.len()];
        self.mover_readings = vec![(Vec::new(), Vec::new(), false); scene.movers.len()];
        self.mover_trails = scene
            .movers
            .iter()
            .map(|m| {
                let start = scene
                    .obstacles
                    .iter()
                    .find(|o| &o.name == m)
                    .map_or([0.0; 2], |o| [o.translation[0], o.translation[1]]);
                (start, Vec::new())
            })
            .collect();
    }

    fn frame(&mut self, f: &Frame<'_>) {
        let truth = [f.truth.x as f32, f.truth.y as f32];
        if self.ground.is_none() {
            self.open(truth);
        }
        self.rec.set_duration_secs("sim_time", f.t);
        self.rec.set_time_sequence("step", f.step as i64);
        self.time.push(f.t);
        self.steps.push(f.step as i64);
        if self.links.is_empty() {
            self.links = f
                .link_poses
                .iter()
                .map(|(n, _, _)| (n.clone(), Vec::new(), Vec::new()))
                .collect();
        }
        for ((_, tr, q), (_, p, r)) in self.links.iter_mut().zip(f.link_poses) {
            tr.push(*p);
            q.push(*r);
        }
        let est = |e: &crate::observe::EstimateView| [e.x[0] as f32, e.x[1] as f32, 0.02];
        let finite = |p: &[f32; 3]| p.iter().all(|v| v.is_finite());
        for (pos, e) in self.positions.iter_mut().zip(f.estimates) {
            pos.push(est(e));
        }
        for (moves, m) in self.mover_moves.iter_mut().zip(f.movers) {
            moves.push([m.displacement[0] as f32, m.displacement[1] as f32, 0.0]);
        }
        let starts = self.mover_trails.iter().map(|(s, _)| *s);
        for ((r, m), (s, t)) in self
            .mover_readings
            .iter_mut()
            .zip(f.mover_readings)
            .zip(starts.zip(f.movers))
        {
            let d = m.displacement;
            r.0.push([s[0] + d[0] as f32, s[1] + d[1] as f32, 0.02]);
            r.1.push(m.position_bound as f32);
            r.2 |= m != t;
        }
        if f.step.is_multiple_of(TRAIL_EVERY) {
            if let Some(t) = self.trails.first_mut() {
                t.push([truth[0], truth[1], 0.004]);
            }
            for (t, e) in self.trails.iter_mut().skip(1).zip(f.estimates) {
                let p = est(e);
                if finite(&p) {
                    t.push(p);
                }
            }
            for ((start, t), m) in self.mover_trails.iter_mut().zip(f.movers) {
                let d = m.displacement;
                t.push([start[0] + d[0] as f32, start[1] + d[1] as f32, 0.003]);
            }
            self.log_trails();
        }
        self.plots.push(f);
        self.log_events(f);
    }
}

#[cfg(test)]
mod tests {
    use std::sync::{Arc, Mutex};

    use rerun::sink::CallbackSink;
    use rerun::StoreKind;

    use super::*;

    /// What the viewer needs to show the designed layout: every blueprint message and the
    /// activation before the recording's first message; and the recording named.
    #[test]
    fn the_blueprint_and_its_activation_come_before_the_recording() {
        let seen: Arc<Mutex<Vec<String>>> = Arc::default();
        let log = seen.clone();
        let sink = CallbackSink::new(move |msgs: &[LogMsg]| {
            let mut log = log.lock().expect("log");
            for m in msgs {
                let kind = match m {
                    LogMsg::BlueprintActivationCommand(_) => "activation",
                    m if m.store_id().kind() == StoreKind::Blueprint => "blueprint",
                    _ => "recording",
                };
                log.push(kind.to_string());
            }
        });
        let name = RecordingName {
            world: "w".into(),
            controller: "ft-cbf-clf".into(),
            seed: 7,
        };
        let app = rerun::ApplicationId::try_new(format!("ftcbf-{}", name.id())).expect("app id");
        let ground = Rect {
            lo: [-1.0, -1.0],
            hi: [1.0, 1.0],
        };
        let blueprint = layout::messages(&app, &Scene::default(), &ground, [0.0, 0.0]);
        let rec = start_stream(&app, &name, Box::new(sink), blueprint).expect("stream");
        rec.log_static("world/x", &rerun::Points3D::new([[0.0f32, 0.0, 0.0]]))
            .expect("log");
        rec.flush_blocking().expect("flush");
        let seen = seen.lock().expect("seen").clone();
        let first = |k: &str| seen.iter().position(|s| s == k);
        let (bp, act, data) = (first("blueprint"), first("activation"), first("recording"));
        assert!(bp.is_some() && act.is_some() && data.is_some(), "{seen:?}");
        assert!(bp < act && act < data, "order {seen:?}");
        let last_bp = seen.iter().rposition(|s| s == "blueprint");
        assert!(
            last_bp < act,
            "a blueprint message after the activation: {seen:?}"
        );
        assert_eq!(name.id(), "w-ft-cbf-clf-seed7");
    }
}
