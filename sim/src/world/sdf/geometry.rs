//! SDF `<geometry>` → obstacle shapes (see the parent module for the conventions).

use nalgebra::{Isometry3, Vector3};

use super::{
    child, elements, mesh_scale, spec_at, z_range, Doc, DropReason, EnvironmentError, Loader, Node,
};
use crate::obstacles::{ObstacleSpec, ShapeSpec};

/// A built obstacle and its world-frame z range \[m\].
type Placed = (ObstacleSpec, (f64, f64));

/// Corners of the box ±h.
fn corners(h: [f64; 3]) -> impl Iterator<Item = [f64; 3]> {
    (0..8).map(move |i| {
        [
            if i & 1 == 0 { -h[0] } else { h[0] },
            if i & 2 == 0 { -h[1] } else { h[1] },
            if i & 4 == 0 { -h[2] } else { h[2] },
        ]
    })
}

/// The obstacles of one geometry element `g` of collision `name` at `x` (world frame); what
/// is dropped is reported to `l` and gives none.
pub(super) fn geometry(
    l: &mut Loader,
    doc: &Doc,
    g: Node,
    name: &str,
    x: &Isometry3<f64>,
) -> Result<Vec<Placed>, EnvironmentError> {
    let boxed =
        |shape: ShapeSpec, h: [f64; 3]| vec![(spec_at(name, x, shape), z_range(x, corners(h)))];
    Ok(match g.tag_name().name() {
        "box" => {
            let s = match child(g, "size") {
                Some(c) => doc.numbers(c, 3)?,
                None => vec![1.0; 3],
            };
            if s.iter().any(|v| *v <= 0.0) {
                return Err(doc.err(g, format!("<box><size> must be > 0 [m], found {s:?}")));
            }
            let h = [s[0] / 2.0, s[1] / 2.0, s[2] / 2.0];
            boxed(ShapeSpec::Cuboid { half_extents: h }, h)
        }
        "cylinder" | "capsule" => {
            let radius = doc.length(
                g,
                "radius",
                Some(if g.tag_name().name() == "cylinder" {
                    1.0
                } else {
                    0.5
                }),
            )?;
            let half_height = doc.length(g, "length", Some(1.0))? / 2.0;
            if g.tag_name().name() == "cylinder" {
                let h = [radius, radius, half_height];
                boxed(
                    ShapeSpec::Cylinder {
                        radius,
                        half_height,
                    },
                    h,
                )
            } else {
                let h = [radius, radius, half_height + radius];
                boxed(
                    ShapeSpec::Capsule {
                        radius,
                        half_height,
                    },
                    h,
                )
            }
        }
        "sphere" => {
            let radius = doc.length(g, "radius", Some(1.0))?;
            boxed(ShapeSpec::Ball { radius }, [radius; 3])
        }
        "ellipsoid" => {
            let r = match child(g, "radii") {
                Some(c) => doc.numbers(c, 3)?,
                None => vec![1.0; 3],
            };
            if r.iter().any(|v| *v <= 0.0) {
                return Err(doc.err(
                    g,
                    format!("<ellipsoid><radii> must be > 0 [m], found {r:?}"),
                ));
            }
            let points = ellipsoid_hull([r[0], r[1], r[2]]);
            let z = z_range(x, points.iter().copied());
            vec![(spec_at(name, x, ShapeSpec::ConvexHull { points }), z)]
        }
        "plane" => plane(l, doc, g, name, x)?,
        "polyline" => polylines(doc, g, name, x)?,
        "mesh" => vec![mesh(l, doc, g, name, x)?],
        "heightmap" | "image" => {
            l.drop(name.to_string(), DropReason::Heightmap);
            vec![]
        }
        "empty" => {
            l.drop(name.to_string(), DropReason::NoGeometry);
            vec![]
        }
        other => {
            l.warn(format!(
                "{}: <{other}> is not an SDF geometry; collision `{name}` ignored",
                doc.at(g)
            ));
            l.drop(name.to_string(), DropReason::NoGeometry);
            vec![]
        }
    })
}

/// Points whose convex hull contains the ellipsoid with semi-axes `r`: a 24 × 12 latitude-
/// longitude net on the unit sphere pushed out by 1/cos(π/24) per angle (a polygon of n sides
/// circumscribes its circle when its vertices sit at 1/cos(π/n)), then scaled by `r`.
fn ellipsoid_hull(r: [f64; 3]) -> Vec<[f64; 3]> {
    let (n_lon, n_lat) = (24usize, 12usize);
    let out = 1.0 / (std::f64::consts::PI / n_lon as f64).cos().powi(2);
    let mut pts = Vec::with_capacity(n_lon * (n_lat + 1));
    for i in 0..=n_lat {
        let lat = -std::f64::consts::FRAC_PI_2 + std::f64::consts::PI * i as f64 / n_lat as f64;
        for j in 0..n_lon {
            let lon = 2.0 * std::f64::consts::PI * j as f64 / n_lon as f64;
            let p = [lat.cos() * lon.cos(), lat.cos() * lon.sin(), lat.sin()];
            pts.push([p[0] * out * r[0], p[1] * out * r[1], p[2] * out * r[2]]);
        }
    }
    pts
}

/// A `<plane>`: a ground plane (normal within 25° of world +z) is dropped, a ceiling above the
/// robot too; any other is the half-space behind it.
fn plane(
    l: &mut Loader,
    doc: &Doc,
    g: Node,
    name: &str,
    x: &Isometry3<f64>,
) -> Result<Vec<Placed>, EnvironmentError> {
    let n = match child(g, "normal") {
        Some(c) => doc.numbers(c, 3)?,
        None => vec![0.0, 0.0, 1.0],
    };
    let n = Vector3::new(n[0], n[1], n[2]);
    if n.norm() < 1e-12 {
        return Err(doc.err(g, "<plane><normal> must not be zero"));
    }
    let nw = x.rotation * n.normalize();
    if nw.z > 0.9 {
        l.drop(name.to_string(), DropReason::Ground);
        return Ok(vec![]);
    }
    if nw.z < -0.9 && l.robot_height.is_some_and(|h| x.translation.vector.z > h) {
        l.drop(name.to_string(), DropReason::AboveRobot);
        return Ok(vec![]);
    }
    let spec = spec_at(
        name,
        x,
        ShapeSpec::HalfSpace {
            normal: [n.x, n.y, n.z],
        },
    );
    Ok(vec![(spec, (f64::NEG_INFINITY, f64::INFINITY))])
}

/// `<polyline>`s: each a prism over its points from z = 0 to `height` (collision frame).
fn polylines(
    doc: &Doc,
    g: Node,
    name: &str,
    x: &Isometry3<f64>,
) -> Result<Vec<Placed>, EnvironmentError> {
    let lines: Vec<Node> = elements(g)
        .filter(|c| c.tag_name().name() == "polyline")
        .collect();
    let lines = if lines.is_empty() { vec![g] } else { lines };
    let mut out = Vec::new();
    for (k, p) in lines.iter().enumerate() {
        let height = doc.length(*p, "height", Some(1.0))?;
        let mut pts: Vec<[f64; 2]> = Vec::new();
        for c in elements(*p).filter(|c| c.tag_name().name() == "point") {
            let v = doc.numbers(c, 2)?;
            pts.push([v[0], v[1]]);
        }
        if pts.len() > 1 && pts.first() == pts.last() {
            pts.pop();
        }
        let oname = if lines.len() > 1 {
            format!("{name}[{k}]")
        } else {
            name.to_string()
        };
        let shape = prism(&pts, height).ok_or_else(|| {
            doc.err(*p, format!("polyline of `{name}` needs at least 3 points enclosing an area, without self-intersections"))
        })?;
        let z = z_range(x, [[0.0, 0.0, 0.0], [0.0, 0.0, height]].into_iter());
        out.push((spec_at(&oname, x, shape), z));
    }
    Ok(out)
}

/// Signed area of a polygon (positive: counter-clockwise).
fn area(p: &[[f64; 2]]) -> f64 {
    (0..p.len())
        .map(|i| {
            let (a, b) = (p[i], p[(i + 1) % p.len()]);
            a[0] * b[1] - b[0] * a[1]
        })
        .sum::<f64>()
        / 2.0
}

fn cross(o: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
}

/// Triangles of a simple counter-clockwise polygon by ear clipping (`None`: no ear found, the
/// polygon intersects itself).
fn ears(p: &[[f64; 2]]) -> Option<Vec<[u32; 3]>> {
    let mut idx: Vec<usize> = (0..p.len()).collect();
    let mut tris = Vec::with_capacity(p.len().saturating_sub(2));
    while idx.len() > 3 {
        let n = idx.len();
        let ear = (0..n).find(|&i| {
            let (a, b, c) = (p[idx[(i + n - 1) % n]], p[idx[i]], p[idx[(i + 1) % n]]);
            cross(a, b, c) > 1e-12
                && idx.iter().all(|&j| {
                    let q = p[j];
                    q == a
                        || q == b
                        || q == c
                        || !(cross(a, b, q) >= 0.0
                            && cross(b, c, q) >= 0.0
                            && cross(c, a, q) >= 0.0)
                })
        })?;
        tris.push([
            idx[(ear + n - 1) % n] as u32,
            idx[ear] as u32,
            idx[(ear + 1) % n] as u32,
        ]);
        idx.remove(ear);
    }
    tris.push([idx[0] as u32, idx[1] as u32, idx[2] as u32]);
    Some(tris)
}

/// The prism over `pts` from z = 0 to `height`: a convex hull when the polygon is convex, else
/// a closed triangle mesh.
fn prism(pts: &[[f64; 2]], height: f64) -> Option<ShapeSpec> {
    if pts.len() < 3 || area(pts).abs() < 1e-12 {
        return None;
    }
    let mut p = pts.to_vec();
    if area(&p) < 0.0 {
        p.reverse();
    }
    let n = p.len();
    let convex = (0..n).all(|i| cross(p[i], p[(i + 1) % n], p[(i + 2) % n]) >= -1e-12);
    let vertices: Vec<[f64; 3]> = p
        .iter()
        .map(|q| [q[0], q[1], 0.0])
        .chain(p.iter().map(|q| [q[0], q[1], height]))
        .collect();
    if convex {
        return Some(ShapeSpec::ConvexHull { points: vertices });
    }
    let top = ears(&p)?;
    let m = n as u32;
    let mut indices: Vec<[u32; 3]> = top.iter().map(|t| [t[0] + m, t[1] + m, t[2] + m]).collect();
    indices.extend(top.iter().map(|t| [t[2], t[1], t[0]]));
    for i in 0..m {
        let j = (i + 1) % m;
        indices.push([i, j, j + m]);
        indices.push([i, j + m, i + m]);
    }
    Some(ShapeSpec::TriMesh {
        vertices,
        indices,
        file: None,
        scale: None,
    })
}

/// A `<mesh>`: the file from its URI, scaled per axis; a `<submesh>` is taken out of the file
/// (and centred if asked). Warns when the mesh lies far from its pose.
fn mesh(
    l: &mut Loader,
    doc: &Doc,
    g: Node,
    name: &str,
    x: &Isometry3<f64>,
) -> Result<Placed, EnvironmentError> {
    let Some(uri) = child(g, "uri").and_then(|u| u.text()).map(str::trim) else {
        return Err(doc.err(g, format!("mesh of `{name}` needs a <uri>")));
    };
    let path = l.resolve_mesh(doc.path, uri).map_err(|e| doc.err(g, e))?;
    // Absolute: the spec's `file` would otherwise be joined to the world file's directory a
    // second time when the obstacle is built (a world file named by a relative path).
    let path = std::path::absolute(&path).unwrap_or(path);
    let scale = match child(g, "scale") {
        Some(c) => doc.numbers(c, 3)?,
        None => vec![1.0; 3],
    };
    if scale.contains(&0.0) {
        return Err(doc.err(
            g,
            format!("<mesh><scale> must be non-zero, found {scale:?}"),
        ));
    }
    let s = [scale[0], scale[1], scale[2]];
    let read = crate::robot::read_mesh_parts(&path)
        .map_err(|e| doc.err(g, format!("{}: {e}", path.display())))?;
    let file = path.display().to_string();
    if l.up_axis_told.insert(path.clone()) {
        if let Some(up) = read.up_axis.as_deref().filter(|u| *u != "Z_UP") {
            l.warn(format!(
                "{file}: declares <up_axis>{up}</up_axis>; read with z up, as Gazebo reads it \
                 (first used by `{name}`)"
            ));
        }
        l.report
            .warnings
            .extend(read.warnings.iter().map(|w| format!("{file}: {w}")));
    }
    let submesh = child(g, "submesh");
    let (mut vertices, indices) = match submesh {
        Some(sm) => submesh_of(doc, sm, &read.parts, name)?,
        None => {
            crate::robot::join_parts(&read.parts).map_err(|e| doc.err(g, format!("{file}: {e}")))?
        }
    };
    for v in &mut vertices {
        *v = [v[0] * s[0], v[1] * s[1], v[2] * s[2]];
    }
    far_warning(l, &vertices, name, &file, doc, g);
    let z = z_range(x, vertices.iter().copied());
    let shape = match submesh {
        Some(_) => ShapeSpec::TriMesh {
            vertices,
            indices,
            file: None,
            scale: None,
        },
        None => ShapeSpec::TriMesh {
            vertices: vec![],
            indices: vec![],
            file: Some(path),
            scale: mesh_scale(s),
        },
    };
    Ok((spec_at(name, x, shape), z))
}

/// The parts of a mesh file a `<submesh>` names, joined, centred on their bounding box if
/// `<center>` is true.
#[allow(clippy::type_complexity)]
fn submesh_of(
    doc: &Doc,
    sm: Node,
    parts: &[crate::robot::MeshPart],
    name: &str,
) -> Result<(Vec<[f64; 3]>, Vec<[u32; 3]>), EnvironmentError> {
    let Some(want) = child(sm, "name").and_then(|n| n.text()).map(str::trim) else {
        return Err(doc.err(sm, "<submesh> needs a <name>"));
    };
    let chosen: Vec<_> = parts
        .iter()
        .filter(|p| p.names.iter().any(|n| n == want))
        .cloned()
        .collect();
    if chosen.is_empty() {
        let mut all: Vec<&str> = parts
            .iter()
            .flat_map(|p| p.names.iter().map(String::as_str))
            .collect();
        all.sort_unstable();
        all.dedup();
        return Err(doc.err(
            sm,
            format!(
                "<submesh> `{want}` of `{name}` is not in the file (it has: {})",
                all.join(", ")
            ),
        ));
    }
    let (mut v, i) = crate::robot::join_parts(&chosen).map_err(|e| doc.err(sm, e))?;
    let center = child(sm, "center").and_then(|c| c.text()).map(str::trim);
    if matches!(center, Some("true") | Some("1")) {
        let (lo, hi) = bounds(&v);
        let c = [0, 1, 2].map(|k| (lo[k] + hi[k]) / 2.0);
        v.iter_mut()
            .for_each(|p| *p = [p[0] - c[0], p[1] - c[1], p[2] - c[2]]);
    }
    Ok((v, i))
}

fn bounds(v: &[[f64; 3]]) -> ([f64; 3], [f64; 3]) {
    v.iter().fold(
        ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]),
        |(lo, hi), p| {
            (
                [0, 1, 2].map(|k| lo[k].min(p[k])),
                [0, 1, 2].map(|k| hi[k].max(p[k])),
            )
        },
    )
}

/// Warns when a mesh's bounding box lies farther from its frame's origin than 1 m and than
/// twice its own diagonal: a misplaced node transform or unit, not a shape placed off its pose.
fn far_warning(l: &mut Loader, v: &[[f64; 3]], name: &str, file: &str, doc: &Doc, g: Node) {
    let (lo, hi) = bounds(v);
    let gap: f64 = (0..3)
        .map(|k| (lo[k].max(0.0) + (-hi[k]).max(0.0)).powi(2))
        .sum::<f64>()
        .sqrt();
    let diag: f64 = (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt();
    if gap > 1.0 && gap > 2.0 * diag {
        l.warn(format!(
            "{}: the mesh of `{name}` ({file}) lies {gap:.2} m from its pose (its bounding box \
             spans [{:.2}, {:.2}, {:.2}] to [{:.2}, {:.2}, {:.2}], {diag:.2} m across); check the \
             file's node transforms and <unit>",
            doc.at(g),
            lo[0],
            lo[1],
            lo[2],
            hi[0],
            hi[1],
            hi[2]
        ));
    }
}
