//! The default blueprint: what the viewer shows, with no clicking, when a recording opens.
//!
//! Left: the 3D scene (robot, estimates with trails, safe sets, goal) above the event log.
//! Right, top to bottom: h on the truth and on each estimate per barrier (tabs, safe sets
//! first); clean vs received per channel (tabs, attacked channels first, attack windows drawn);
//! each filter's estimation error against γ, the Step-3 residues, detector statistics and V/V₀
//! (tabs); v, ω, u and the attack windows (tabs).
//!
//! The 3D view's eye is set in the blueprint ([`eye`]): above the ground's −y side, looking down
//! at its centre at [`EYE_ELEVATION`], far enough to frame the whole ground. rerun 0.36.3's Rust
//! `Spatial3DView` has no setter for it (its `View::add_property` is crate-private), so [`send`]
//! logs the `EyeControls3D` view property into the blueprint store itself, at
//! `view/<id>/EyeControls3D` — where rerun's Python `Spatial3DView(eye_controls=…)` puts it.

use rerun::blueprint::{
    Blueprint, BlueprintActivation, BlueprintPanel, ContainerLike, Horizontal, SelectionPanel,
    Spatial3DView, Tabs, TextLogView, TimePanel, TimeSeriesView, Vertical,
};
use rerun::external::re_log_types::BlueprintActivationCommand;
use rerun::external::re_sdk_types::blueprint::archetypes::EyeControls3D;
use rerun::log::{Chunk, LogMsg};
use rerun::{EntityPath, RecordingStreamBuilder, StoreKind, TimePoint, Timeline};

use super::draw::{self, colour_name, seg, Rect};
use crate::observe::{Geometry, Scene};

/// Angle of the eye above the ground plane \[rad\]: steep enough that a 0.3 m wall hides at most
/// 0.17 m of floor behind it, low enough to read heights.
pub const EYE_ELEVATION: f32 = 60.0 * std::f32::consts::PI / 180.0;
/// The viewer's vertical field of view (rerun's `Eye::DEFAULT_FOV_Y`) \[rad\].
const FOV_Y: f32 = 55.0 * std::f32::consts::PI / 180.0;
/// Width / height of the 3D view in the default layout (left column, upper three quarters) on a
/// 16:10 window; a wider view only adds margin left and right.
const VIEW_ASPECT: f32 = 1.2;
/// The ground fills at most 1 / this of the view's width or height.
const EYE_MARGIN: f32 = 1.1;

/// Height up to which the scene is kept in view (half-space walls are drawn 0.3 m high) \[m\].
const FRAMED_HEIGHT: f32 = 0.3;

/// The 3D view's starting eye for `ground`: position and look target (both in `world`, z up).
///
/// The eye looks at the ground's centre from the −y side (the +y side when `from_plus_y`),
/// [`EYE_ELEVATION`] above the plane, at
/// the smallest distance where every corner of the ground, on the floor and [`FRAMED_HEIGHT`]
/// above it, lies inside the view (perspective included) with a margin of [`EYE_MARGIN`].
pub(crate) fn eye(ground: &Rect, from_plus_y: bool) -> ([f32; 3], [f32; 3]) {
    let side = if from_plus_y { -1.0 } else { 1.0 };
    let c = [
        (ground.lo[0] + ground.hi[0]) / 2.0,
        (ground.lo[1] + ground.hi[1]) / 2.0,
    ];
    let t = (FOV_Y / 2.0).tan() / EYE_MARGIN;
    let (s, co) = EYE_ELEVATION.sin_cos();
    // Eye frame for an eye at c + d·(0, −cos e, sin e): right = x, up = (0, sin e, cos e),
    // forward = (0, cos e, −sin e). A point q (relative to c) is in view when
    // |q·right| ≤ aspect·t·(d + q·forward) and |q·up| ≤ t·(d + q·forward).
    let mut d: f32 = 0.5;
    for x in [ground.lo[0], ground.hi[0]] {
        for y in [ground.lo[1], ground.hi[1]] {
            for z in [0.0, FRAMED_HEIGHT] {
                // Seen from +y the scene is mirrored in y (x stays across the view's width).
                let q = [x - c[0], side * (y - c[1]), z];
                let ahead = q[1] * co - q[2] * s;
                let up = q[1] * s + q[2] * co;
                d = d
                    .max(q[0].abs() / (VIEW_ASPECT * t) - ahead)
                    .max(up.abs() / t - ahead);
            }
        }
    }
    ([c[0], c[1] - side * d * co, d * s], [c[0], c[1], 0.0])
}

/// Whether the eye should look from the +y side: when the half-space walls (patches given in
/// world coordinates) stand, on average, on the −y side of the ground's centre, so the eye is
/// on their free side and does not look over them at a robot driving along them.
fn walls_on_minus_y(scene: &Scene, ground: &Rect) -> bool {
    let cy = (ground.lo[1] + ground.hi[1]) / 2.0;
    let (mut sum, mut n) = (0.0f32, 0usize);
    for ob in &scene.obstacles {
        let wall = scene.half_space_walls.contains(&ob.name);
        if let (true, Geometry::Mesh { vertices, .. }) = (wall, &ob.geometry) {
            for v in vertices {
                sum += v[1] - cy;
                n += 1;
            }
        }
    }
    n > 0 && sum / (n as f32) < -1e-3
}

fn plot(name: String, origin: String) -> ContainerLike {
    TimeSeriesView::new(name).with_origin(origin).into()
}

/// Channels in the order their tabs appear: attacked ones first.
fn channel_order(scene: &Scene) -> Vec<(&String, bool)> {
    let attacked = |c: &String| scene.attack_channels.iter().any(|a| a.contains(c));
    let mut v: Vec<(&String, bool)> = scene.channels.iter().map(|c| (c, attacked(c))).collect();
    v.sort_by_key(|(_, a)| !*a);
    v
}

/// At most this many barriers get a plot tab of their own; the farther obstacles share one.
pub const BARRIER_TABS: usize = 8;

/// The barriers with a plot tab of their own — every safe set, then the obstacles nearest the
/// straight line from `start` to the goal, up to [`BARRIER_TABS`] in all — and the obstacles'
/// barriers that share one plot (their h on the truth), nearest first.
fn barrier_tabs(scene: &Scene, start: [f32; 2]) -> (Vec<&String>, Vec<&String>) {
    let obstacle = |b: &str| {
        b.strip_prefix("obstacle:")
            .and_then(|n| scene.obstacles.iter().find(|o| o.name == n))
    };
    let (mut own, mut obstacles): (Vec<&String>, Vec<(f32, &String)>) = (Vec::new(), Vec::new());
    for b in &scene.barriers {
        match obstacle(b) {
            Some(o) => obstacles.push((draw::distance_to_segment(o, start, scene.goal.0), b)),
            None => own.push(b),
        }
    }
    obstacles.sort_by(|a, b| a.0.total_cmp(&b.0));
    let room = BARRIER_TABS.saturating_sub(own.len()).max(1);
    let split = if obstacles.len() > room + 1 {
        room
    } else {
        obstacles.len()
    };
    own.extend(obstacles[..split].iter().map(|(_, b)| *b));
    (own, obstacles[split..].iter().map(|(_, b)| *b).collect())
}

/// The viewer layout for `scene` (the robot starting at `start`), and the blueprint path of its
/// 3D view.
fn blueprint(scene: &Scene, start: [f32; 2]) -> (Blueprint, Option<EntityPath>) {
    let names: Vec<String> = scene
        .filters
        .iter()
        .enumerate()
        .map(|(i, f)| format!("{f} ({})", colour_name(i)))
        .collect();
    let view3d: ContainerLike = Spatial3DView::new(format!(
        "{}: robot and trail (black) = truth; estimates {}; safe sets red, goal green",
        scene.world,
        names.join(", ")
    ))
    .with_origin("/world")
    .into();
    let view3d_path = match &view3d {
        ContainerLike::View(v) => Some(v.blueprint_path()),
        _ => None,
    };
    let log = TextLogView::new("events: policy, safety, attacks").with_origin("/events");
    let (own, rest) = barrier_tabs(scene, start);
    let mut tabs: Vec<ContainerLike> = own
        .iter()
        .map(|b| {
            plot(
                format!("h_{b}: truth (black) and per estimate; below 0 is unsafe"),
                format!("/barriers/{}", seg(b)),
            )
        })
        .collect();
    if !rest.is_empty() {
        tabs.push(
            TimeSeriesView::new(format!(
                "h of the {} farther obstacles, on the truth; below 0 is unsafe",
                rest.len()
            ))
            .with_contents(
                rest.iter()
                    .map(|b| format!("/barriers/{}/truth", seg(b)))
                    .collect::<Vec<_>>(),
            )
            .into(),
        );
    }
    let barriers = Tabs::new(tabs);
    let sensors = Tabs::new(channel_order(scene).into_iter().map(|(c, attacked)| {
        let what = if attacked { " (attacked)" } else { "" };
        plot(
            format!("{c}{what}: clean (grey) vs received (red), rejected (dots)"),
            format!("/sensors/{}", seg(c)),
        )
    }));
    // The estimation error first: whether each filter kept the γ its rows assume (Theorem 1's
    // hypothesis, measured against the truth) is what a recording can show that a run's
    // summary line cannot.
    let stats = Tabs::new([
        plot(
            "estimation error ‖x − x̂‖/γ against the truth (above 1: γ does not hold)".into(),
            "/estimation_error".into(),
        ),
        plot(
            "Step-3 residue per estimator, log10".into(),
            "/residues".into(),
        ),
        plot(
            "detector statistic z per channel (|z| ≤ 3 normal)".into(),
            "/detector".into(),
        ),
        plot("CLF V/V₀ per estimator".into(), "/clf".into()),
    ]);
    let control = Tabs::new([
        TimeSeriesView::new("command to the drive: v [m/s], ω [rad/s]")
            .with_contents(["/control/v", "/control/omega"])
            .into(),
        TimeSeriesView::new("controller input u [m/s²]")
            .with_contents(["/control/u_x", "/control/u_y"])
            .into(),
        plot("attack windows (1 = active)".into(), "/attacks".into()),
    ]);
    let plots = Vertical::new([
        barriers.into(),
        sensors.into(),
        stats.into(),
        control.into(),
    ]);
    let left = Vertical::new([view3d, log.into()]).with_row_shares([3.0, 1.0]);
    let bp =
        Blueprint::new(Horizontal::new([left.into(), plots.into()]).with_column_shares([1.2, 1.0]))
            .with_auto_views(false)
            .with_blueprint_panel(BlueprintPanel::new().with_state(collapsed()))
            .with_selection_panel(SelectionPanel::new().with_state(collapsed()))
            .with_time_panel(
                TimePanel::new()
                    .with_timeline("sim_time")
                    .with_state(collapsed()),
            );
    (bp, view3d_path)
}

/// The default blueprint for `scene` (the 3D eye framed on `ground`, barrier tabs for the
/// obstacles nearest the path from `start`) as the messages of
/// application `app`'s blueprint store and their activation: the viewer shows it unless the
/// user has edited the layout of this application id (`make_default`, not `make_active`).
///
/// rerun's `Blueprint::send` writes into an in-memory stream first; its blueprint-store messages
/// are kept with one more chunk, the 3D view's `EyeControls3D`, before the activation command.
/// They must reach the file before any message of the recording (see `Recorder::open`).
pub(crate) fn messages(
    app: &rerun::ApplicationId,
    scene: &Scene,
    ground: &Rect,
    start: [f32; 2],
) -> Result<(Vec<LogMsg>, BlueprintActivationCommand), String> {
    let e = |x: &dyn std::fmt::Display| format!("default blueprint: {x}");
    let (bp, view3d) = blueprint(scene, start);
    let view3d = view3d.ok_or_else(|| e(&"the 3D view is not a view"))?;
    let (mem, storage) = RecordingStreamBuilder::new(app.clone())
        .memory()
        .map_err(|x| e(&x))?;
    bp.send(
        &mem,
        BlueprintActivation {
            make_active: false,
            make_default: true,
        },
    )
    .map_err(|x| e(&x))?;
    let mut msgs = Vec::new();
    let mut activation = None;
    for m in storage.take() {
        match m {
            LogMsg::BlueprintActivationCommand(cmd) => activation = Some(cmd),
            m if m.store_id().kind() == StoreKind::Blueprint => msgs.push(m),
            _ => {}
        }
    }
    mem.disconnect();
    let activation = activation.ok_or_else(|| e(&"rerun sent no activation command"))?;
    let (position, look_target) = eye(ground, walls_on_minus_y(scene, ground));
    let eye = EyeControls3D::new()
        .with_position(position)
        .with_look_target(look_target)
        .with_eye_up([0.0f32, 0.0, 1.0]);
    let chunk = Chunk::builder(view3d.join(&EntityPath::from_single_string("EyeControls3D")))
        .with_archetype_auto_row(
            TimePoint::default().with(Timeline::new_sequence("blueprint"), 0),
            &eye,
        )
        .build()
        .map_err(|x| e(&x))?;
    let arrow = chunk.to_arrow_msg().map_err(|x| e(&x))?;
    msgs.push(LogMsg::ArrowMsg(activation.blueprint_id.clone(), arrow));
    Ok((msgs, activation))
}

fn collapsed() -> rerun::blueprint::components::PanelState {
    rerun::blueprint::components::PanelState::Collapsed
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `p` in the eye's frame (right, up, forward) for an eye at `pos` looking at `target`, z up.
    fn in_eye_frame(pos: [f32; 3], target: [f32; 3], p: [f32; 3]) -> [f32; 3] {
        let sub = |a: [f32; 3], b: [f32; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
        let dot = |a: [f32; 3], b: [f32; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        let cross = |a: [f32; 3], b: [f32; 3]| {
            [
                a[1] * b[2] - a[2] * b[1],
                a[2] * b[0] - a[0] * b[2],
                a[0] * b[1] - a[1] * b[0],
            ]
        };
        let unit = |a: [f32; 3]| {
            let n = dot(a, a).sqrt();
            [a[0] / n, a[1] / n, a[2] / n]
        };
        let fwd = unit(sub(target, pos));
        let right = unit(cross(fwd, [0.0, 0.0, 1.0]));
        let up = cross(right, fwd);
        let d = sub(p, pos);
        [dot(d, right), dot(d, up), dot(d, fwd)]
    }

    /// Every ground corner and 0.3 m above it lies inside the view's frustum, and the ground fills it.
    fn assert_framed(ground: Rect, from_plus_y: bool) {
        let (pos, target) = eye(&ground, from_plus_y);
        let t = (FOV_Y / 2.0).tan();
        let mut filled: f32 = 0.0;
        for x in [ground.lo[0], ground.hi[0]] {
            for y in [ground.lo[1], ground.hi[1]] {
                for z in [0.0, 0.3] {
                    let [r, u, f] = in_eye_frame(pos, target, [x, y, z]);
                    assert!(f > 0.0, "({x}, {y}, {z}) behind the eye {pos:?}");
                    let (rx, ry) = ((r / f).abs() / (VIEW_ASPECT * t), (u / f).abs() / t);
                    assert!(rx <= 1.0 / EYE_MARGIN + 1e-4, "({x}, {y}, {z}): x at {rx}");
                    assert!(ry <= 1.0 / EYE_MARGIN + 1e-4, "({x}, {y}, {z}): y at {ry}");
                    filled = filled.max(rx).max(ry);
                }
            }
        }
        // Not farther than needed (grounds under 0.5 m are framed from 0.5 m).
        let small = ground.hi[0] - ground.lo[0] < 0.5 && ground.hi[1] - ground.lo[1] < 0.5;
        assert!(
            small || filled > 0.99 / EYE_MARGIN,
            "the ground fills only {filled}"
        );
    }

    #[test]
    fn the_eye_looks_down_on_the_ground_centre_from_the_minus_y_side() {
        // corridor_spoof's ground: 5 m walls at y = ±0.55, start (0, 0), goal (3, 0).
        let ground = Rect {
            lo: [-1.3, -0.9],
            hi: [4.3, 0.9],
        };
        let (pos, target) = eye(&ground, false);
        assert!((target[0] - 1.5).abs() < 1e-5 && target[1] == 0.0 && target[2] == 0.0);
        assert!((pos[0] - 1.5).abs() < 1e-6 && pos[1] < 0.0, "{pos:?}");
        let elevation = (pos[2] / (pos[1] - target[1]).abs()).atan();
        assert!((elevation - EYE_ELEVATION).abs() < 1e-5, "{elevation}");
        assert_framed(ground, false);
        let (north, _) = eye(&ground, true);
        assert!(
            (north[1] + pos[1]).abs() < 1e-5 && north[2] == pos[2],
            "{north:?}"
        );
    }

    #[test]
    fn long_wide_and_tiny_grounds_are_all_framed() {
        for (w, h) in [(6.0, 1.8), (1.8, 6.0), (10.0, 10.0), (0.2, 0.2)] {
            for from_plus_y in [false, true] {
                let ground = Rect {
                    lo: [-1.0, 2.0],
                    hi: [-1.0 + w, 2.0 + h],
                };
                assert_framed(ground, from_plus_y);
            }
        }
    }
}

#[cfg(test)]
mod side_tests {
    use super::*;
    use crate::observe::Placed;

    #[test]
    fn the_eye_stands_on_the_free_side_of_a_half_space_wall() {
        let ground = Rect {
            lo: [-0.3, -0.4],
            hi: [3.4, 0.4],
        };
        let wall = |y: f32| Placed {
            name: "wall".into(),
            geometry: Geometry::Mesh {
                vertices: vec![[3.0, y, 3.0], [3.0, y, -3.0], [-3.0, y, -3.0]],
                triangles: vec![[0, 1, 2]],
            },
            translation: [0.0; 3],
            rotation: [0.0, 0.0, 0.0, 1.0],
        };
        let scene = |obstacles| Scene {
            obstacles,
            half_space_walls: vec!["wall".into()],
            ..Scene::default()
        };
        assert!(walls_on_minus_y(&scene(vec![wall(-0.3)]), &ground));
        assert!(!walls_on_minus_y(&scene(vec![wall(0.3)]), &ground));
        assert!(!walls_on_minus_y(&scene(vec![]), &ground));
    }
}

#[cfg(test)]
mod tab_tests {
    use super::*;
    use crate::observe::Placed;

    fn pillar(name: String, y: f32) -> Placed {
        Placed {
            name,
            geometry: Geometry::Cylinder {
                radius: 0.1,
                half_height: 0.2,
            },
            translation: [1.0, y, 0.2],
            rotation: [0.0, 0.0, 0.0, 1.0],
        }
    }

    #[test]
    fn safe_sets_and_the_nearest_obstacles_get_tabs_the_farther_ones_share_a_plot() {
        // Pillars 0.5 m, 1.0 m, … off the start–goal line y = 0, listed farthest first.
        let n = 20;
        let obstacles: Vec<Placed> = (0..n)
            .rev()
            .map(|k| pillar(format!("p{k}"), 0.5 * (k + 1) as f32))
            .collect();
        let mut barriers = vec!["safe_set:floor".to_string(), "safe_set:room".to_string()];
        barriers.extend(obstacles.iter().map(|o| format!("obstacle:{}", o.name)));
        let scene = Scene {
            obstacles,
            barriers,
            goal: ([3.0, 0.0], 0.1),
            ..Scene::default()
        };
        let (own, rest) = barrier_tabs(&scene, [0.0, 0.0]);
        let own: Vec<&str> = own.iter().map(|s| s.as_str()).collect();
        assert_eq!(own.len(), BARRIER_TABS);
        assert_eq!(
            &own[..3],
            ["safe_set:floor", "safe_set:room", "obstacle:p0"]
        );
        assert_eq!(own[BARRIER_TABS - 1], "obstacle:p5");
        assert_eq!(rest.len(), 2 + n - BARRIER_TABS);
        assert_eq!(rest[0].as_str(), "obstacle:p6");
        assert_eq!(rest.last().map(|s| s.as_str()), Some("obstacle:p19"));
        // Few barriers: each its own tab, none shared (not even one left over).
        let few = Scene {
            barriers: scene.barriers[..BARRIER_TABS + 1].to_vec(),
            ..scene.clone()
        };
        let (own, rest) = barrier_tabs(&few, [0.0, 0.0]);
        assert_eq!((own.len(), rest.len()), (BARRIER_TABS + 1, 0));
    }
}
