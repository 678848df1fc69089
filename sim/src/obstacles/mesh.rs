//! Triangle meshes for obstacles: loading (STL, Collada, OBJ) with scale, and orienting a
//! closed mesh's faces outward whatever their winding ([`orient_mesh`]).

use super::*;

pub(super) fn mesh_err(name: &str, message: String) -> ObstacleError {
    ObstacleError::Mesh {
        name: name.to_string(),
        message,
    }
}

/// A triangle mesh: its vertices \[m\] and its triangles as vertex indices.
pub(super) type Triangles = (Vec<[f64; 3]>, Vec<[u32; 3]>);

/// A triangle mesh's vertices and triangles: read from `file` (relative to `base_dir`) and
/// scaled, or written inline, not both.
pub(super) fn mesh_data(
    name: &str,
    vertices: &[[f64; 3]],
    indices: &[[u32; 3]],
    file: Option<&Path>,
    scale: Option<MeshScale>,
    base_dir: Option<&Path>,
) -> Result<Triangles, ObstacleError> {
    match file {
        Some(f) => {
            if !vertices.is_empty() || !indices.is_empty() {
                return Err(mesh_err(
                    name,
                    "give either `file` or `vertices`/`indices`, not both".into(),
                ));
            }
            let s = match scale.unwrap_or(MeshScale::Uniform(1.0)) {
                MeshScale::Uniform(s) => {
                    positive(name, "scale", s)?;
                    [s; 3]
                }
                MeshScale::PerAxis(s) => {
                    for (i, v) in s.iter().enumerate() {
                        if !(v.is_finite() && *v != 0.0) {
                            return Err(invalid(
                                name,
                                &format!("shape.scale[{i}]"),
                                "a finite non-zero factor",
                                format!("{v}"),
                            ));
                        }
                    }
                    s
                }
            };
            let path = match base_dir {
                Some(d) if f.is_relative() => d.join(f),
                _ => f.to_path_buf(),
            };
            let (v, i) = crate::robot::read_mesh(&path)
                .map_err(|m| mesh_err(name, format!("{}: {m}", path.display())))?;
            let scaled = v
                .into_iter()
                .map(|p| [p[0] * s[0], p[1] * s[1], p[2] * s[2]])
                .collect();
            Ok((scaled, i))
        }
        None => {
            if scale.is_some() {
                return Err(mesh_err(name, "`scale` applies only to `file`".into()));
            }
            Ok((vertices.to_vec(), indices.to_vec()))
        }
    }
}

/// A triangle mesh from checked vertices and triangles. A closed mesh is wound outward first
/// ([`orient_mesh`]: inside and outside do not depend on the file's winding) and gets parry's
/// pseudo-normals (a signed distance); an open one is a surface (unsigned distance), with a note
/// that names it.
pub(super) fn tri_mesh(
    name: &str,
    verts: Vec<[f64; 3]>,
    idx: Vec<[u32; 3]>,
) -> Result<(SharedShape, Option<String>), ObstacleError> {
    if idx.is_empty() {
        return Err(mesh_err(name, "no triangles".into()));
    }
    if verts.iter().any(|p| !p.iter().all(|v| v.is_finite())) {
        return Err(mesh_err(name, "non-finite vertex coordinates".into()));
    }
    if let Some(bad) = idx.iter().flatten().find(|&&i| i as usize >= verts.len()) {
        return Err(mesh_err(
            name,
            format!("index {bad} out of range ({} vertices)", verts.len()),
        ));
    }
    let mesh = orient_mesh(&verts, &idx);
    if mesh.triangles.is_empty() {
        return Err(mesh_err(
            name,
            "every triangle repeats a vertex: no triangles".into(),
        ));
    }
    let pts: Vec<Vector> = mesh.vertices.iter().map(|p| v3(*p)).collect();
    let (flags, note) = match &mesh.open {
        None => (TriMeshFlags::ORIENTED, None),
        Some(why) => (
            TriMeshFlags::empty(),
            Some(format!(
                "obstacle `{name}`: tri_mesh is not a closed surface ({why}): it has no inside, \
                 so its distance is unsigned and a robot inside it is not seen as inside"
            )),
        ),
    };
    SharedShape::trimesh_with_flags(pts, mesh.triangles, flags)
        .map(|s| (s, note))
        .map_err(|e| mesh_err(name, format!("{e:?}")))
}

/// A triangle mesh as [`orient_mesh`] leaves it.
#[derive(Debug, Clone, PartialEq)]
pub struct OrientedMesh {
    /// The distinct vertices \[m\].
    pub vertices: Vec<[f64; 3]>,
    /// The triangles, wound outward when the mesh is closed.
    pub triangles: Vec<[u32; 3]>,
    /// Why the mesh is not a closed, orientable surface enclosing a volume (`None` when it is).
    pub open: Option<String>,
}

/// The key of an edge (its vertices in increasing order) and whether triangle `t` runs it
/// forward (from the smaller to the larger vertex).
pub(super) fn edges_of(t: [u32; 3]) -> [((u32, u32), bool); 3] {
    let e = |a: u32, b: u32| ((a.min(b), a.max(b)), a < b);
    [e(t[0], t[1]), e(t[1], t[2]), e(t[2], t[0])]
}

/// Edge → the triangles on it, with whether each runs it forward.
pub(super) type EdgeMap = std::collections::HashMap<(u32, u32), Vec<(usize, bool)>>;

/// Merges vertices with equal coordinates (as the f32 parry stores), drops triangles that repeat
/// a vertex, and, when the mesh is closed (every edge on exactly two triangles) and orientable,
/// winds every triangle outward: within each connected piece each pair of neighbours runs their
/// shared edge in opposite directions, and each piece encloses a positive volume. Linear in the
/// number of triangles (hash maps, one breadth-first pass).
pub fn orient_mesh(verts: &[[f64; 3]], idx: &[[u32; 3]]) -> OrientedMesh {
    let mut id: std::collections::HashMap<[u32; 3], u32> = std::collections::HashMap::new();
    let mut vertices: Vec<[f64; 3]> = Vec::new();
    // `+ 0.0` makes −0 and +0 one vertex.
    let remap: Vec<u32> = verts
        .iter()
        .map(|p| {
            let key = p.map(|c| (c as f32 + 0.0).to_bits());
            *id.entry(key).or_insert_with(|| {
                vertices.push(*p);
                (vertices.len() - 1) as u32
            })
        })
        .collect();
    let mut triangles: Vec<[u32; 3]> = idx
        .iter()
        .map(|t| t.map(|i| remap[i as usize]))
        .filter(|t| t[0] != t[1] && t[1] != t[2] && t[2] != t[0])
        .collect();
    let mut edges = EdgeMap::new();
    for (ti, t) in triangles.iter().enumerate() {
        for (key, forward) in edges_of(*t) {
            edges.entry(key).or_default().push((ti, forward));
        }
    }
    let boundary = edges.values().filter(|v| v.len() == 1).count();
    let shared = edges.values().filter(|v| v.len() > 2).count();
    let open = |why: String, triangles: Vec<[u32; 3]>, vertices: Vec<[f64; 3]>| OrientedMesh {
        vertices,
        triangles,
        open: Some(why),
    };
    if boundary > 0 || shared > 0 {
        let why =
            format!("{boundary} edge(s) on one triangle only, {shared} edge(s) on more than two");
        return open(why, triangles, vertices);
    }
    let Some(flip) = consistent_flips(&triangles, &edges) else {
        let why = "its triangles cannot be wound consistently: a one-sided surface".to_string();
        return open(why, triangles, vertices);
    };
    for (t, (f, _)) in triangles.iter_mut().zip(&flip) {
        if *f {
            t.swap(1, 2);
        }
    }
    // Each piece's enclosed volume, by the divergence theorem: Σ a·(b × c) / 6.
    let pieces = flip.iter().map(|(_, c)| c + 1).max().unwrap_or(0);
    let mut volume = vec![0.0f64; pieces];
    let v = |i: u32| Vector3::from(vertices[i as usize]);
    for (t, (_, c)) in triangles.iter().zip(&flip) {
        volume[*c] += v(t[0]).dot(&v(t[1]).cross(&v(t[2]))) / 6.0;
    }
    let extent = vertices
        .iter()
        .flatten()
        .fold(0.0f64, |m, c| m.max(c.abs()))
        .max(f64::MIN_POSITIVE);
    if volume.iter().any(|w| w.abs() <= 1e-9 * extent.powi(3)) {
        let why = "a closed piece of it encloses no volume".to_string();
        return open(why, triangles, vertices);
    }
    for (t, (_, c)) in triangles.iter_mut().zip(&flip) {
        if volume[*c] < 0.0 {
            t.swap(1, 2);
        }
    }
    OrientedMesh {
        vertices,
        triangles,
        open: None,
    }
}

/// For a closed mesh: per triangle, whether to reverse it so that neighbours run each shared
/// edge in opposite directions, and its connected piece; `None` when no such choice exists.
pub(super) fn consistent_flips(
    triangles: &[[u32; 3]],
    edges: &EdgeMap,
) -> Option<Vec<(bool, usize)>> {
    let mut flip: Vec<Option<(bool, usize)>> = vec![None; triangles.len()];
    let mut queue = std::collections::VecDeque::new();
    let mut pieces = 0;
    for seed in 0..triangles.len() {
        if flip[seed].is_some() {
            continue;
        }
        flip[seed] = Some((false, pieces));
        queue.push_back(seed);
        while let Some(t) = queue.pop_front() {
            let (ft, _) = flip[t]?;
            for (key, forward) in edges_of(triangles[t]) {
                // Whether t, as it will be wound, runs the edge forward.
                let runs = forward != ft;
                for &(u, fu) in &edges[&key] {
                    if u == t {
                        continue;
                    }
                    // u must run it the other way: (fu XOR flip_u) = !runs.
                    let want = fu == runs;
                    match flip[u] {
                        None => {
                            flip[u] = Some((want, pieces));
                            queue.push_back(u);
                        }
                        Some((got, _)) if got != want => return None,
                        Some(_) => {}
                    }
                }
            }
        }
        pieces += 1;
    }
    flip.into_iter().collect()
}
