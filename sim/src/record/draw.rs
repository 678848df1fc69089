//! Static drawing of the scene: colours, entity names, the ground sized to the world, shapes
//! standing on the floor, and safe-set lines cut to the ground.

use crate::observe::{Geometry, Placed, Scene};

/// Margin around the scene's extent when sizing the ground \[m\].
const GROUND_MARGIN: f32 = 0.3;

/// An opaque colour (const; rerun's `Color::from_rgb` is not).
const fn rgb(r: u8, g: u8, b: u8) -> rerun::Color {
    rerun::Color(rerun::datatypes::Rgba32(
        (r as u32) << 24 | (g as u32) << 16 | (b as u32) << 8 | 0xff,
    ))
}

/// One colour per estimator (index in [`Scene::filters`]), used in the 3D view and every plot.
pub(crate) fn palette(i: usize) -> rerun::Color {
    const C: [[u8; 3]; 8] = [
        [31, 119, 180],
        [255, 127, 14],
        [44, 160, 44],
        [148, 103, 189],
        [23, 190, 207],
        [227, 119, 194],
        [188, 189, 34],
        [140, 86, 75],
    ];
    let [r, g, b] = C[i % C.len()];
    rerun::Color::from_rgb(r, g, b)
}

/// The name of [`palette`]`(i)`, for titles.
pub(crate) fn colour_name(i: usize) -> &'static str {
    const N: [&str; 8] = [
        "blue", "orange", "green", "purple", "cyan", "pink", "olive", "brown",
    ];
    N[i % N.len()]
}

/// Colours for what is not an estimator (channels, control signals, attacks): dark tones
/// that the estimator palette does not use.
pub(crate) fn other(i: usize) -> rerun::Color {
    const C: [[u8; 3]; 4] = [[70, 70, 160], [160, 90, 40], [40, 120, 100], [120, 40, 90]];
    let [r, g, b] = C[i % C.len()];
    rerun::Color::from_rgb(r, g, b)
}

/// Ground truth in the 3D view and the plots.
pub(crate) const TRUTH: rerun::Color = rgb(20, 20, 20);
/// The clean sensor signal.
pub(crate) const CLEAN: rerun::Color = rgb(120, 120, 120);
/// What the controller received.
pub(crate) const RECEIVED: rerun::Color = rgb(214, 39, 40);
/// Attack windows.
pub(crate) const ATTACK: rerun::Color = rgb(255, 150, 150);
/// The robot's links.
pub(crate) const ROBOT: rerun::Color = rgb(70, 70, 70);
/// A moving obstacle and its path (issue #51): orange, apart from the grey obstacles that stand.
pub(crate) const MOVER: rerun::Color = rgb(225, 120, 30);
/// A tracked mover's estimate (its reading), drawn beside it with its bound γ_p as radius.
pub(crate) const MOVER_ESTIMATE: rerun::Color = rgb(250, 190, 90);
/// A contact that is the robot's (a static obstacle, or the robot moving into a mover).
pub(crate) const COLLISION_ROBOT: rerun::Color = rgb(220, 30, 30);
/// A contact that is a mover's (it walked into the stopped robot).
pub(crate) const COLLISION_MOVER: rerun::Color = rgb(150, 60, 200);
/// Safe-set boundaries.
pub(crate) const SAFE_SET: rerun::Color = rgb(214, 39, 40);
/// Goal region.
pub(crate) const GOAL: rerun::Color = rgb(44, 160, 44);
/// Marks for values clipped to a plot's range, and rejected readings.
pub(crate) const MARK: rerun::Color = rgb(230, 0, 230);

/// An entity-path segment: ASCII letters, digits, `_` and `-` kept, any other run of characters
/// becomes one `_`, no `_` at either end (nothing the viewer has to escape).
pub(crate) fn seg(name: &str) -> String {
    let mut s = String::with_capacity(name.len());
    for c in name.chars() {
        if c.is_ascii_alphanumeric() || c == '_' || c == '-' {
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

/// Axis-aligned rectangle on the ground, (min x, min y, max x, max y) \[m\].
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Rect {
    pub lo: [f32; 2],
    pub hi: [f32; 2],
}

impl Rect {
    fn around(p: [f32; 2]) -> Self {
        Self { lo: p, hi: p }
    }
    fn add(&mut self, p: [f32; 2], r: [f32; 2]) {
        if p.iter().chain(&r).all(|v| v.is_finite()) {
            self.lo = [self.lo[0].min(p[0] - r[0]), self.lo[1].min(p[1] - r[1])];
            self.hi = [self.hi[0].max(p[0] + r[0]), self.hi[1].max(p[1] + r[1])];
        }
    }
    fn padded(self, m: f32) -> Self {
        Self {
            lo: [self.lo[0] - m, self.lo[1] - m],
            hi: [self.hi[0] + m, self.hi[1] + m],
        }
    }
    /// Cuts the segment a–b to the rectangle (Liang–Barsky); `None` when it misses.
    pub(crate) fn clip(&self, a: [f32; 3], b: [f32; 3]) -> Option<([f32; 3], [f32; 3])> {
        let d = [b[0] - a[0], b[1] - a[1]];
        let (mut t0, mut t1) = (0.0f32, 1.0f32);
        for k in 0..2 {
            for (p, q) in [(-d[k], a[k] - self.lo[k]), (d[k], self.hi[k] - a[k])] {
                if p == 0.0 {
                    if q < 0.0 {
                        return None;
                    }
                } else {
                    let r = q / p;
                    if p < 0.0 {
                        t0 = t0.max(r);
                    } else {
                        t1 = t1.min(r);
                    }
                }
            }
        }
        let at = |t: f32| [a[0] + t * d[0], a[1] + t * d[1], a[2] + t * (b[2] - a[2])];
        (t0 <= t1).then(|| (at(t0), at(t1)))
    }
}

/// Half extents (x, y) of a shape's footprint on the ground, for a shape turned by `yaw`
/// (bounding circle for anything not a box).
fn footprint(g: &Geometry, yaw: f32) -> [f32; 2] {
    match g {
        Geometry::Cuboid { half_extents: h } => {
            let (s, c) = (yaw.sin().abs(), yaw.cos().abs());
            [c * h[0] + s * h[1], s * h[0] + c * h[1]]
        }
        Geometry::Ball { radius } | Geometry::Cylinder { radius, .. } => [*radius; 2],
        Geometry::Capsule {
            radius,
            half_height,
        } => [radius + half_height; 2],
        Geometry::Mesh { .. } => [0.0; 2],
    }
}

/// Yaw of a quaternion (x, y, z, w) \[rad\].
fn yaw(q: [f32; 4]) -> f32 {
    let [x, y, z, w] = q;
    (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z))
}

/// The part of the ground the run uses: start, goal, obstacles, and closed safe-set
/// outlines (open lines, i.e. half-planes, are cut to this rectangle instead), with a margin.
pub(crate) fn scene_extent(scene: &Scene, start: [f32; 2]) -> Rect {
    let mut r = Rect::around(start);
    let ([gx, gy], gr) = scene.goal;
    r.add([gx, gy], [gr; 2]);
    for ob in &scene.obstacles {
        match &ob.geometry {
            // A half-space's 6 m wall patch counts by its origin only, so it does not stretch
            // the ground; other meshes (cones, hulls, walls) by their footprint.
            Geometry::Mesh { .. } if scene.half_space_walls.contains(&ob.name) => {
                r.add([ob.translation[0], ob.translation[1]], [0.0; 2])
            }
            Geometry::Mesh { .. } => {
                let (lo, hi) = mesh_footprint(ob);
                r.add(lo, [0.0; 2]);
                r.add(hi, [0.0; 2]);
            }
            g => r.add(
                [ob.translation[0], ob.translation[1]],
                footprint(g, yaw(ob.rotation)),
            ),
        }
    }
    for (_, pts) in &scene.safe_set_outlines {
        if pts.len() > 2 {
            for p in pts {
                r.add([p[0], p[1]], [0.0; 2]);
            }
        }
    }
    r.padded(GROUND_MARGIN)
}

/// How far a shape of `p` reaches below its origin along world z (0 for meshes, which parry
/// stores in their world pose). Only upright shapes are considered (tilted ones are drawn as given).
fn depth_below_origin(p: &Placed) -> f32 {
    let [x, y, _, _] = p.rotation;
    if x.abs() > 1e-4 || y.abs() > 1e-4 {
        return 0.0;
    }
    match &p.geometry {
        Geometry::Cuboid { half_extents } => half_extents[2],
        Geometry::Ball { radius } => *radius,
        Geometry::Cylinder { half_height, .. } => *half_height,
        Geometry::Capsule {
            radius,
            half_height,
        } => radius + half_height,
        Geometry::Mesh { .. } => 0.0,
    }
}

/// An obstacle as drawn: one that reaches below the floor (z = 0) while its centre is above
/// −depth is lifted to stand on it. The planar problem ignores z; this only fixes the picture.
pub(crate) fn standing(p: &Placed) -> Placed {
    let mut q = p.clone();
    let bottom = p.translation[2] - depth_below_origin(p);
    if bottom < 0.0 && p.translation[2] >= -1e-6 {
        q.translation[2] -= bottom;
    }
    q
}

/// Height of a half-space wall as drawn \[m\].
const WALL_HEIGHT: f32 = 0.3;

/// A half-space's wall patch (`wall`: a mesh given in world coordinates) that reaches outside
/// the ground is cut to the ground and [`WALL_HEIGHT`]: its vertices are clamped to the box, so
/// a 6 m patch becomes a wall along the ground's edge or across it. Anything else is returned
/// as is.
pub(crate) fn cut_to_ground(p: &Placed, r: &Rect, wall: bool) -> Placed {
    let mut q = p.clone();
    if let (true, Geometry::Mesh { vertices, .. }) = (wall, &mut q.geometry) {
        let outside = vertices
            .iter()
            .any(|v| v[0] < r.lo[0] || v[0] > r.hi[0] || v[1] < r.lo[1] || v[1] > r.hi[1]);
        if outside {
            for v in vertices.iter_mut() {
                v[0] = v[0].clamp(r.lo[0], r.hi[0]);
                v[1] = v[1].clamp(r.lo[1], r.hi[1]);
                v[2] = v[2].clamp(0.0, WALL_HEIGHT);
            }
        }
    }
    q
}

/// Opacity (of 255) of an obstacle drawn see-through.
pub(crate) const SEE_THROUGH_ALPHA: u8 = 70;

/// Whether a mesh obstacle surrounds one of `points` on the ground: the point lies inside the
/// mesh's footprint (its world-frame bounding box in x and y). The robot cannot be inside a
/// solid there, so the mesh is an enclosing wall (an arena, a room's walls as one mesh) and is
/// drawn see-through, or the default eye, outside it, would see its outside and not the robot.
pub(crate) fn encloses(p: &Placed, points: &[[f32; 2]]) -> bool {
    if !matches!(p.geometry, Geometry::Mesh { .. }) {
        return false;
    }
    let (lo, hi) = mesh_footprint(p);
    points
        .iter()
        .any(|q| (lo[0]..=hi[0]).contains(&q[0]) && (lo[1]..=hi[1]).contains(&q[1]))
}

/// The world-frame bounding box (x, y) of a mesh's vertices: (lo, hi); an empty box (lo > hi)
/// for anything else.
fn mesh_footprint(p: &Placed) -> ([f32; 2], [f32; 2]) {
    let (mut lo, mut hi) = ([f32::INFINITY; 2], [f32::NEG_INFINITY; 2]);
    let Geometry::Mesh { vertices, .. } = &p.geometry else {
        return (lo, hi);
    };
    let [x, y, z, w] = p.rotation;
    for v in vertices {
        // v turned by q = (x, y, z, w): v + w t + q × t with t = 2 q × v; then translated.
        let t = [
            2.0 * (y * v[2] - z * v[1]),
            2.0 * (z * v[0] - x * v[2]),
            2.0 * (x * v[1] - y * v[0]),
        ];
        let a = v[0] + w * t[0] + y * t[2] - z * t[1] + p.translation[0];
        let b = v[1] + w * t[1] + z * t[0] - x * t[2] + p.translation[1];
        lo = [lo[0].min(a), lo[1].min(b)];
        hi = [hi[0].max(a), hi[1].max(b)];
    }
    (lo, hi)
}

/// Distance on the ground from the segment a–b to an obstacle's footprint (its bounding box
/// in x and y; 0 when they overlap) \[m\]: the segment is sampled every ≤ 5 cm.
pub(crate) fn distance_to_segment(p: &Placed, a: [f32; 2], b: [f32; 2]) -> f32 {
    let (lo, hi) = match &p.geometry {
        Geometry::Mesh { .. } => mesh_footprint(p),
        g => {
            let r = footprint(g, yaw(p.rotation));
            let c = [p.translation[0], p.translation[1]];
            ([c[0] - r[0], c[1] - r[1]], [c[0] + r[0], c[1] + r[1]])
        }
    };
    let len = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt();
    let n = ((len / 0.05).ceil() as usize).clamp(1, 10_000);
    (0..=n)
        .map(|k| {
            let t = k as f32 / n as f32;
            let q = [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])];
            let dx = (lo[0] - q[0]).max(q[0] - hi[0]).max(0.0);
            let dy = (lo[1] - q[1]).max(q[1] - hi[1]).max(0.0);
            (dx * dx + dy * dy).sqrt()
        })
        .fold(f32::INFINITY, f32::min)
}

/// Logs a placed shape (transform and solid shape) as static data under `base/<name>`.
pub(crate) fn log_placed(
    rec: &rerun::RecordingStream,
    base: &str,
    p: &Placed,
    color: rerun::Color,
) -> Result<(), rerun::RecordingStreamError> {
    let path = format!("{base}/{}", seg(&p.name));
    rec.log_static(
        path.as_str(),
        &rerun::Transform3D::from_translation_rotation(
            p.translation,
            rerun::Quaternion::from_xyzw(p.rotation),
        ),
    )?;
    let solid = rerun::FillMode::Solid;
    match &p.geometry {
        Geometry::Cuboid { half_extents } => rec.log_static(
            path.as_str(),
            &rerun::Boxes3D::from_half_sizes([*half_extents])
                .with_colors([color])
                .with_fill_mode(solid),
        ),
        Geometry::Ball { radius } => rec.log_static(
            path.as_str(),
            &rerun::Ellipsoids3D::from_radii([*radius])
                .with_colors([color])
                .with_fill_mode(solid),
        ),
        Geometry::Cylinder {
            radius,
            half_height,
        } => rec.log_static(
            path.as_str(),
            &rerun::Cylinders3D::from_lengths_and_radii([2.0 * half_height], [*radius])
                .with_colors([color])
                .with_fill_mode(solid),
        ),
        Geometry::Capsule {
            radius,
            half_height,
        } => rec.log_static(
            path.as_str(),
            // rerun capsules run between two end points: give them, centred on the origin.
            &rerun::Capsules3D::from_endpoints_and_radii(
                [[0.0, 0.0, -half_height]],
                [[0.0, 0.0, *half_height]],
                [*radius],
            )
            .with_colors([color])
            .with_fill_mode(solid),
        ),
        Geometry::Mesh {
            vertices,
            triangles,
        } => rec.log_static(
            path.as_str(),
            &rerun::Mesh3D::new(vertices.iter().copied())
                .with_triangle_indices(triangles.iter().copied())
                .with_albedo_factor(color.0),
        ),
    }
}

/// A circle of radius `r` around `c` at height `z`, as a closed polyline.
pub(crate) fn circle(c: [f32; 2], r: f32, z: f32) -> Vec<[f32; 3]> {
    (0..=64)
        .map(|k| {
            let a = k as f32 / 64.0 * std::f32::consts::TAU;
            [c[0] + r * a.cos(), c[1] + r * a.sin(), z]
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segments_need_no_escaping() {
        assert_eq!(seg("gnss1_x"), "gnss1_x");
        assert_eq!(
            seg("bias+drift[gnss1_x, gnss2_y]"),
            "bias_drift_gnss1_x_gnss2_y"
        );
        assert_eq!(seg("ε/δ"), "_");
        assert_eq!(seg("a b"), "a_b");
    }

    #[test]
    fn half_plane_lines_are_cut_to_the_ground() {
        let r = Rect {
            lo: [-1.0, -1.0],
            hi: [2.0, 1.0],
        };
        let (a, b) = r.clip([-6.0, 0.5, 0.0], [6.0, 0.5, 0.0]).unwrap();
        assert!((a[0] + 1.0).abs() < 1e-6 && (b[0] - 2.0).abs() < 1e-6);
        assert!((a[1] - 0.5).abs() < 1e-6 && (b[1] - 0.5).abs() < 1e-6);
        assert!(r.clip([-6.0, 3.0, 0.0], [6.0, 3.0, 0.0]).is_none());
    }

    #[test]
    fn pillars_stand_on_the_floor() {
        let pillar = Placed {
            name: "p".into(),
            geometry: Geometry::Cylinder {
                radius: 0.1,
                half_height: 0.25,
            },
            translation: [1.0, 2.0, 0.0],
            rotation: [0.0, 0.0, 0.0, 1.0],
        };
        assert_eq!(standing(&pillar).translation, [1.0, 2.0, 0.25]);
        let crate_ = Placed {
            geometry: Geometry::Cuboid {
                half_extents: [0.1, 0.1, 0.1],
            },
            translation: [0.0, 0.0, 0.1],
            ..pillar.clone()
        };
        assert_eq!(standing(&crate_).translation, [0.0, 0.0, 0.1]);
    }

    #[test]
    fn a_half_space_patch_becomes_a_low_wall_on_the_ground() {
        let r = Rect {
            lo: [-1.0, -1.0],
            hi: [2.0, 1.0],
        };
        let patch = Placed {
            name: "wall".into(),
            geometry: Geometry::Mesh {
                vertices: vec![
                    [3.0, -0.3, 3.0],
                    [3.0, -0.3, -3.0],
                    [-3.0, -0.3, -3.0],
                    [-3.0, -0.3, 3.0],
                ],
                triangles: vec![[0, 1, 2], [0, 2, 3]],
            },
            translation: [0.0; 3],
            rotation: [0.0, 0.0, 0.0, 1.0],
        };
        let Geometry::Mesh { vertices, .. } = cut_to_ground(&patch, &r, true).geometry else {
            panic!("still a mesh")
        };
        assert_eq!(vertices[0], [2.0, -0.3, WALL_HEIGHT]);
        assert_eq!(vertices[2], [-1.0, -0.3, 0.0]);
    }

    /// A square ring (walls 0.1 m thick around a 4 m room) given as one mesh, placed at `at`.
    fn ring(at: [f32; 3]) -> Placed {
        let mut vertices = Vec::new();
        for r in [2.0f32, 1.9] {
            for (x, y) in [(r, r), (-r, r), (-r, -r), (r, -r)] {
                vertices.push([x, y, 0.0]);
                vertices.push([x, y, 0.4]);
            }
        }
        Placed {
            name: "arena".into(),
            geometry: Geometry::Mesh {
                vertices,
                triangles: vec![[0, 1, 2]],
            },
            translation: at,
            rotation: [0.0, 0.0, 0.0, 1.0],
        }
    }

    #[test]
    fn a_mesh_around_the_robot_is_see_through_and_framed_whole_a_pillar_is_not() {
        let arena = ring([1.0, 0.0, 0.0]);
        assert!(encloses(&arena, &[[0.0, 0.0]]));
        assert!(
            encloses(&arena, &[[9.0, 9.0], [2.5, 1.5]]),
            "the goal inside"
        );
        assert!(!encloses(&arena, &[[3.5, 0.0]]), "outside its footprint");
        let pillar = Placed {
            geometry: Geometry::Cylinder {
                radius: 0.1,
                half_height: 0.3,
            },
            ..arena.clone()
        };
        assert!(!encloses(&pillar, &[[1.0, 0.0]]), "only meshes enclose");
        // Not a half-space: its walls are not cut to the ground, and the ground frames it.
        let r = Rect {
            lo: [-0.5, -0.5],
            hi: [0.5, 0.5],
        };
        assert_eq!(cut_to_ground(&arena, &r, false), arena);
        let scene = Scene {
            obstacles: vec![arena],
            goal: ([0.5, 0.0], 0.1),
            ..Scene::default()
        };
        let g = scene_extent(&scene, [0.0, 0.0]);
        assert!(g.lo[0] <= -1.0 && g.hi[0] >= 3.0 && g.lo[1] <= -2.0 && g.hi[1] >= 2.0);
    }

    #[test]
    fn the_ground_frames_goal_and_obstacles_not_half_plane_lines() {
        let scene = Scene {
            goal: ([2.5, 0.6], 0.1),
            safe_set_outlines: vec![("wall".into(), vec![[-6.0, 1.0, 0.0], [6.0, 1.0, 0.0]])],
            ..Scene::default()
        };
        let r = scene_extent(&scene, [0.0, 0.0]);
        assert!((r.hi[0] - (2.6 + GROUND_MARGIN)).abs() < 1e-6);
        assert!((r.lo[0] + GROUND_MARGIN).abs() < 1e-6);
        assert!((r.hi[1] - (0.7 + GROUND_MARGIN)).abs() < 1e-6);
    }

    #[test]
    fn a_long_wall_widens_the_ground_along_its_length_only() {
        let wall = Placed {
            name: "wall".into(),
            geometry: Geometry::Cuboid {
                half_extents: [2.5, 0.05, 0.15],
            },
            translation: [1.5, 0.55, 0.15],
            rotation: [0.0, 0.0, 0.0, 1.0],
        };
        let scene = Scene {
            obstacles: vec![wall],
            goal: ([3.0, 0.0], 0.1),
            ..Scene::default()
        };
        let r = scene_extent(&scene, [0.0, 0.0]);
        assert!((r.lo[0] - (-1.0 - GROUND_MARGIN)).abs() < 1e-5, "{r:?}");
        assert!((r.hi[1] - (0.6 + GROUND_MARGIN)).abs() < 1e-5, "{r:?}");
    }
}
