//! Mesh files of robots and obstacles: `package://` and relative paths resolved against the search
//! path, STL, Collada and OBJ read through mesh-loader with their parts and transforms.

use super::*;

/// Why a mesh file was not found: for `package://NAME/…`, where `NAME` was looked for, and how
/// to map a package whose folder has another name.
pub(super) fn not_found(filename: &str, opts: &LoadOptions) -> String {
    let Some((pkg, _)) = filename
        .strip_prefix("package://")
        .and_then(|r| r.split_once('/'))
    else {
        return "file not found".to_string();
    };
    if let Some(dir) = opts.packages.get(pkg) {
        return format!(
            "file not found in package `{pkg}`'s folder {} ([robot] packages)",
            dir.display()
        );
    }
    let found = opts
        .package_paths
        .iter()
        .any(|d| d.join(pkg).is_dir() || d.file_name().is_some_and(|n| n == pkg));
    if found {
        format!(
            "file not found in package `{pkg}` (package search path: {:?})",
            opts.package_paths
        )
    } else {
        format!(
            "file not found: no package `{pkg}` in the package search path {:?} (a folder `{pkg}` \
             in one of them, or one of them named `{pkg}`); if the package's folder has another \
             name, map it: \
             [robot] packages = {{ {pkg} = \"path/to/folder\" }}",
            opts.package_paths
        )
    }
}

/// Resolves a mesh filename (`package://`, `file://`, absolute or relative) to an existing file.
/// `package://NAME/rest` is `packages[NAME]/rest` when the map names the package, else the
/// first of `DIR/NAME/rest` and (when `DIR` is itself named `NAME`) `DIR/rest` over
/// `package_paths`.
pub fn resolve_mesh_path(
    filename: &str,
    base_dir: Option<&Path>,
    package_paths: &[PathBuf],
    packages: &BTreeMap<String, PathBuf>,
) -> Option<PathBuf> {
    if let Some(rest) = filename.strip_prefix("package://") {
        let (pkg, rel) = rest.split_once('/')?;
        if let Some(dir) = packages.get(pkg) {
            let cand = dir.join(rel);
            return cand.is_file().then_some(cand);
        }
        for dir in package_paths {
            let cand = dir.join(pkg).join(rel);
            if cand.is_file() {
                return Some(cand);
            }
            if dir.file_name().is_some_and(|n| n == pkg) {
                let cand = dir.join(rel);
                if cand.is_file() {
                    return Some(cand);
                }
            }
        }
        return None;
    }
    let plain = filename.strip_prefix("file://").unwrap_or(filename);
    let p = Path::new(plain);
    let cand = if p.is_absolute() {
        p.to_path_buf()
    } else {
        base_dir
            .map(|d| d.join(p))
            .unwrap_or_else(|| p.to_path_buf())
    };
    cand.is_file().then_some(cand)
}

/// One mesh of a file, placed in the file's frame \[m\].
#[derive(Debug, Clone)]
pub struct MeshPart {
    /// What names it: the mesh's name (a Collada geometry's `id`, else the file's own
    /// name), a Collada geometry's `name` and the names of the nodes that instance it.
    pub names: Vec<String>,
    /// Vertices \[m\], in the file's frame (node transforms and `<unit>` applied).
    pub vertices: Vec<[f64; 3]>,
    /// Triangles as indices into [`Self::vertices`].
    pub triangles: Vec<[u32; 3]>,
}

/// The meshes of a mesh file and what the user should know about how they were read.
#[derive(Debug, Clone, Default)]
pub struct MeshParts {
    /// Every mesh of the file: for Collada, one per instanced geometry (a geometry instanced
    /// by two nodes is two parts; a file without a visual scene gives its geometries as they
    /// are).
    pub parts: Vec<MeshPart>,
    /// Collada's declared `<up_axis>`, when the file declares one.
    pub up_axis: Option<String>,
    /// Non-fatal problems (a Collada `<skew>`, an unresolved `<instance_node>`).
    pub warnings: Vec<String>,
}

/// The meshes of a mesh file, read with `mesh-loader`: STL (ASCII or binary; a binary file
/// whose 80-byte header starts with `solid` is still read as binary), Collada (`.dae`: every
/// instanced geometry placed by its node's composed transform and scaled by the document's
/// `<unit>`, see [`crate::environment::collada`]) or Wavefront OBJ. The format is chosen by the
/// extension, else by the content.
pub fn read_mesh_parts(path: &Path) -> Result<MeshParts, String> {
    // Collada is XML, parsed by a tokenizer that recurses per nesting level: refuse absurd
    // nesting before it can overflow the stack.
    let mut bytes = std::fs::read(path).map_err(|e| format!("cannot read: {e}"))?;
    let mut scene = None;
    if let Ok(text) = std::str::from_utf8(&bytes) {
        if text
            .trim_start_matches('\u{feff}')
            .trim_start()
            .starts_with('<')
        {
            if let Some((line, tag)) = urdf::too_deep(text, MAX_URDF_DEPTH) {
                return Err(format!(
                    "line {line}: <{tag}> is nested more than {MAX_URDF_DEPTH} levels deep; \
                     not a readable Collada mesh"
                ));
            }
            scene = crate::environment::collada::scene(text)
                .map_err(|e| format!("not a readable Collada mesh: {e}"))?;
        }
    }
    if let Some(s) = &scene {
        bytes = s.geometry_text.clone().into_bytes();
    }
    let loaded = mesh_loader::Loader::default()
        .load_from_slice(&bytes, path)
        .map_err(|e| format!("not a readable STL, Collada or OBJ mesh: {e}"))?;
    let mut out = MeshParts::default();
    for mesh in &loaded.meshes {
        if mesh
            .vertices
            .iter()
            .any(|v| !v.iter().all(|c| c.is_finite()))
        {
            return Err("the mesh has non-finite vertices".into());
        }
        let raw: Vec<[f64; 3]> = mesh.vertices.iter().map(|v| v.map(f64::from)).collect();
        let mut triangles = Vec::with_capacity(mesh.faces.len());
        for f in &mesh.faces {
            if f.iter().any(|&i| i as usize >= raw.len()) {
                return Err("the mesh has an out-of-range vertex index".into());
            }
            triangles.push(*f);
        }
        let Some(s) = &scene else {
            out.parts.push(MeshPart {
                names: vec![mesh.name.clone()],
                vertices: raw,
                triangles,
            });
            continue;
        };
        let mut names = vec![mesh.name.clone()];
        names.extend(s.geometry_names.get(&mesh.name).cloned());
        let uses: Vec<_> = s
            .instances
            .iter()
            .filter(|i| i.geometry == mesh.name)
            .collect();
        if uses.is_empty() && s.instances.is_empty() {
            let vertices = raw.iter().map(|v| v.map(|c| c * s.unit)).collect();
            out.parts.push(MeshPart {
                names: names.clone(),
                vertices,
                triangles: triangles.clone(),
            });
        }
        for inst in uses {
            let vertices = raw
                .iter()
                .map(|v| {
                    let p = inst.transform.transform_point(&Point3::from(*v)) * s.unit;
                    [p.x, p.y, p.z]
                })
                .collect();
            let mut names = names.clone();
            names.extend(inst.nodes.iter().filter(|n| !n.is_empty()).cloned());
            out.parts.push(MeshPart {
                names,
                vertices,
                triangles: triangles.clone(),
            });
        }
    }
    if let Some(s) = scene {
        out.up_axis = s.up_axis;
        out.warnings = s.warnings;
    }
    Ok(out)
}

/// Vertices and triangles of a mesh file ([`read_mesh_parts`]): all meshes of the file joined
/// into one, and vertices with identical coordinates (as f32) welded in order of first
/// appearance, so an STL's triangle soup becomes an indexed mesh.
#[allow(clippy::type_complexity)]
pub fn read_mesh(path: &Path) -> Result<(Vec<[f64; 3]>, Vec<[u32; 3]>), String> {
    join_parts(&read_mesh_parts(path)?.parts)
}

/// The parts joined into one mesh, vertices welded (see [`read_mesh`]).
#[allow(clippy::type_complexity)]
pub fn join_parts(parts: &[MeshPart]) -> Result<(Vec<[f64; 3]>, Vec<[u32; 3]>), String> {
    let mut vertices: Vec<[f64; 3]> = Vec::new();
    let mut indices: Vec<[u32; 3]> = Vec::new();
    let mut weld: HashMap<[u32; 3], u32> = HashMap::new();
    for part in parts {
        let mut local = Vec::with_capacity(part.vertices.len());
        for v in &part.vertices {
            let next = u32::try_from(vertices.len())
                .map_err(|_| "the mesh has more than 2³² vertices".to_string())?;
            let id = *weld
                .entry(v.map(|c| (c as f32).to_bits()))
                .or_insert_with(|| {
                    vertices.push(*v);
                    next
                });
            local.push(id);
        }
        for t in &part.triangles {
            indices.push(t.map(|i| local[i as usize]));
        }
    }
    if indices.is_empty() {
        return Err("the mesh has no triangles".into());
    }
    Ok((vertices, indices))
}
