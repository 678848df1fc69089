//! Gazebo SDF worlds and models, read as Gazebo reads them: their collision geometry a ground
//! robot can touch, as obstacle specs in the world frame.
//!
//! Read with roxmltree rather than the `sdformat` crate: that crate is a serde schema of one SDF
//! version that rejects elements outside it, resolves no `<include>`, composes no poses and
//! gives no line numbers, while Gazebo loads a file with unknown elements and warns (sdformat's
//! "XML Element[...] not defined in SDF"); here every element is looked at by name, unknown
//! ones warned about with their line, and namespaced extension elements (`gz:…`) passed over
//! silently, as libsdformat does.
//!
//! - `<include>`: `model://NAME/rest` resolved through the world's `model_paths`, then
//!   `GZ_SIM_RESOURCE_PATH` and `GAZEBO_MODEL_PATH` (colon-separated); a directory's model file
//!   is the one its `model.config` names for the highest `<sdf version>`, else `model.sdf`. A
//!   Fuel URL (`https://fuel…`) is skipped and reported. The include's `<name>` and `<pose>`
//!   replace the model's own.
//! - Poses: `<pose>` is `x y z roll pitch yaw` (SDF's fixed-axis roll-pitch-yaw, radians, or
//!   degrees with `degrees="true"`) or `x y z qx qy qz qw` with `rotation_format="quat_xyzw"`;
//!   `relative_to` (SDF ≥ 1.7, or `frame` before it) names a frame of the same scope (a link, a
//!   nested model, a `<frame>`, `__model__`, `world`); without it a model's pose is relative to
//!   its parent, a link's to its model, a collision's to its link, a frame's to what it is
//!   attached to.
//! - Geometry: box, cylinder (along z), sphere, capsule (`length` of the cylindrical part),
//!   ellipsoid (the convex hull of a circumscribed polyhedron), plane (a half-space; a ground
//!   plane is dropped), polyline (a prism from the collision frame's z = 0 to `height`), mesh
//!   (STL, Collada, OBJ; per-axis `<scale>`; `<submesh>` with `<center>`), heightmap (dropped).

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Point3, Quaternion, Translation3, UnitQuaternion};

use crate::environment::{DropReason, Dropped, EnvironmentError, EnvironmentReport};
use crate::obstacles::{MeshScale, ObstacleSpec, ShapeSpec};

mod geometry;

/// Deepest chain of includes and nested models followed.
const MAX_DEPTH: usize = 32;
/// Most collision elements one environment may give (what a world's obstacle list can hold).
pub const MAX_COLLISIONS: usize = 4096;

/// An environment loaded: its obstacles (world frame) and the report.
#[derive(Debug, Clone, Default)]
pub struct Environment {
    /// The obstacles, named by their scoped SDF names.
    pub obstacles: Vec<ObstacleSpec>,
    /// What was kept and dropped.
    pub report: EnvironmentReport,
}

/// How an SDF file is loaded.
#[derive(Debug, Clone, Default)]
pub struct SdfOptions {
    /// Directories searched first for `model://` URIs.
    pub model_paths: Vec<PathBuf>,
    /// The robot's height \[m\]: a collision wholly above it is dropped (`None`: all kept).
    pub robot_height: Option<f64>,
    /// Read `GZ_SIM_RESOURCE_PATH` and `GAZEBO_MODEL_PATH` too (default in [`load`]).
    pub no_environment_variables: bool,
}

type Node<'a, 'i> = roxmltree::Node<'a, 'i>;

fn elements<'a, 'i>(n: Node<'a, 'i>) -> impl Iterator<Item = Node<'a, 'i>> + 'a {
    n.children().filter(|c| c.is_element())
}

fn child<'a, 'i>(n: Node<'a, 'i>, tag: &str) -> Option<Node<'a, 'i>> {
    elements(n).find(|c| c.tag_name().name() == tag)
}

fn text_of(n: Option<Node>) -> Option<String> {
    n.and_then(|n| n.text()).map(|t| t.trim().to_string())
}

/// A pose as written: the transform and the frame it is relative to (`None`: the default).
#[derive(Debug, Clone)]
struct PoseSpec {
    iso: Isometry3<f64>,
    relative_to: Option<String>,
}

/// A named frame of a scope: its pose, and the frame that pose is relative to by default.
#[derive(Debug, Clone)]
struct FrameEntry {
    pose: Option<PoseSpec>,
    default_parent: Option<String>,
}

/// The frames of one scope (a model or the world), resolved to the scope's own frame.
struct Scope {
    root: &'static str,
    frames: HashMap<String, FrameEntry>,
}

/// What an `<include>` says of the model it brings in.
#[derive(Debug, Clone, Default)]
struct Including {
    /// Its `<name>`, which replaces the model's own.
    name: Option<String>,
    /// Its `<pose>` (world frame), which replaces the model's own.
    pose: Option<Isometry3<f64>>,
    /// The names of the `<plugin>`s it attaches to the model.
    plugins: Vec<String>,
    /// Its `<static>`, which overrides the model's own.
    is_static: Option<bool>,
}

/// An SDF boolean (`true`/`1`, `false`/`0`); `None` for anything else.
fn sdf_bool(text: Option<String>) -> Option<bool> {
    match text.as_deref() {
        Some("true" | "1") => Some(true),
        Some("false" | "0") => Some(false),
        _ => None,
    }
}

/// One document being read: its path (for messages and relative URIs) and parsed text.
struct Doc<'a, 'i> {
    path: &'a Path,
    xml: &'a roxmltree::Document<'i>,
}

impl Doc<'_, '_> {
    fn line(&self, n: Node) -> u32 {
        self.xml.text_pos_at(n.range().start).row
    }

    fn err(&self, n: Node, message: impl Into<String>) -> EnvironmentError {
        EnvironmentError::Sdf {
            path: self.path.to_path_buf(),
            line: Some(self.line(n)),
            message: message.into(),
        }
    }

    fn at(&self, n: Node) -> String {
        format!("{}:{}", self.path.display(), self.line(n))
    }

    /// `n`'s text as `count` finite numbers.
    fn numbers(&self, n: Node, count: usize) -> Result<Vec<f64>, EnvironmentError> {
        let text = n.text().unwrap_or("").trim();
        let v: Result<Vec<f64>, _> = text.split_whitespace().map(str::parse::<f64>).collect();
        match v {
            Ok(v) if v.len() == count && v.iter().all(|x| x.is_finite()) => Ok(v),
            _ => Err(self.err(
                n,
                format!(
                    "<{}> expects {count} finite numbers, found {text:?}",
                    n.tag_name().name()
                ),
            )),
        }
    }

    /// A positive length from child `tag` of `n` (`default` when absent).
    fn length(&self, n: Node, tag: &str, default: Option<f64>) -> Result<f64, EnvironmentError> {
        let v = match (child(n, tag), default) {
            (Some(c), _) => self.numbers(c, 1)?[0],
            (None, Some(d)) => d,
            (None, None) => {
                return Err(self.err(n, format!("<{}> needs <{tag}>", n.tag_name().name())))
            }
        };
        if v > 0.0 {
            Ok(v)
        } else {
            Err(self.err(n, format!("<{tag}> must be > 0 [m], found {v}")))
        }
    }

    /// A `<pose>` element.
    fn pose(&self, n: Node) -> Result<PoseSpec, EnvironmentError> {
        let text = n.text().unwrap_or("").trim();
        let relative_to = n
            .attribute("relative_to")
            .or_else(|| n.attribute("frame"))
            .filter(|s| !s.trim().is_empty())
            .map(str::to_string);
        if text.is_empty() {
            return Ok(PoseSpec {
                iso: Isometry3::identity(),
                relative_to,
            });
        }
        let quat = n.attribute("rotation_format") == Some("quat_xyzw");
        let v = self.numbers(n, if quat { 7 } else { 6 })?;
        let t = Translation3::new(v[0], v[1], v[2]);
        let r = if quat {
            UnitQuaternion::from_quaternion(Quaternion::new(v[6], v[3], v[4], v[5]))
        } else {
            let k = match n.attribute("degrees") {
                Some("true") | Some("1") => std::f64::consts::PI / 180.0,
                _ => 1.0,
            };
            UnitQuaternion::from_euler_angles(v[3] * k, v[4] * k, v[5] * k)
        };
        Ok(PoseSpec {
            iso: Isometry3::from_parts(t, r),
            relative_to,
        })
    }

    fn pose_of(&self, n: Node) -> Result<Option<PoseSpec>, EnvironmentError> {
        child(n, "pose").map(|p| self.pose(p)).transpose()
    }
}

impl Scope {
    /// The frame `name` in the scope's frame; `visiting` guards against cycles.
    fn resolve(
        &self,
        doc: &Doc,
        at: Node,
        name: &str,
        visiting: &mut Vec<String>,
    ) -> Result<Isometry3<f64>, EnvironmentError> {
        if name == self.root || name == "__model__" || name == "world" {
            return Ok(Isometry3::identity());
        }
        let Some(entry) = self.frames.get(name) else {
            return Err(doc.err(
                at,
                format!(
                    "relative_to=\"{name}\" names no frame of this scope (expected a link, a \
                     nested model, a <frame> or {})",
                    self.root
                ),
            ));
        };
        if visiting.iter().any(|v| v == name) {
            return Err(doc.err(
                at,
                format!(
                    "the poses form a cycle: {} -> {name}",
                    visiting.join(" -> ")
                ),
            ));
        }
        visiting.push(name.to_string());
        let (iso, parent) = match &entry.pose {
            Some(p) => (p.iso, p.relative_to.clone()),
            None => (Isometry3::identity(), None),
        };
        let parent = parent.or_else(|| entry.default_parent.clone());
        let base = match parent {
            Some(p) => self.resolve(doc, at, &p, visiting)?,
            None => Isometry3::identity(),
        };
        visiting.pop();
        Ok(base * iso)
    }

    /// A pose written in this scope (relative to its `relative_to`, else to `default`).
    fn place(
        &self,
        doc: &Doc,
        at: Node,
        pose: Option<&PoseSpec>,
        default: Option<&str>,
    ) -> Result<Isometry3<f64>, EnvironmentError> {
        let parent = pose
            .and_then(|p| p.relative_to.as_deref())
            .or(default)
            .unwrap_or(self.root);
        let base = self.resolve(doc, at, parent, &mut Vec::new())?;
        Ok(base * pose.map_or(Isometry3::identity(), |p| p.iso))
    }
}

/// The loader's state: options, where includes resolve, and what it has found.
struct Loader {
    search: Vec<PathBuf>,
    /// Mesh files whose `<up_axis>` has been reported (once per file).
    up_axis_told: std::collections::HashSet<PathBuf>,
    robot_height: Option<f64>,
    obstacles: Vec<ObstacleSpec>,
    report: EnvironmentReport,
}

/// Loads the SDF world or model file at `path`.
pub fn load(path: &Path, opts: &SdfOptions) -> Result<Environment, EnvironmentError> {
    let mut search = opts.model_paths.clone();
    if !opts.no_environment_variables {
        for var in ["GZ_SIM_RESOURCE_PATH", "GAZEBO_MODEL_PATH"] {
            if let Some(v) = std::env::var_os(var) {
                search.extend(std::env::split_paths(&v).filter(|p| !p.as_os_str().is_empty()));
            }
        }
    }
    let mut loader = Loader {
        search,
        up_axis_told: Default::default(),
        robot_height: opts.robot_height,
        obstacles: Vec::new(),
        report: EnvironmentReport {
            source: path.to_path_buf(),
            robot_height: opts.robot_height,
            ..EnvironmentReport::default()
        },
    };
    loader.file(path, None, &Isometry3::identity(), "", 0)?;
    loader.report.kept = loader.obstacles.iter().map(|o| o.name.clone()).collect();
    Ok(Environment {
        obstacles: loader.obstacles,
        report: loader.report,
    })
}

fn read(path: &Path) -> Result<String, EnvironmentError> {
    std::fs::read_to_string(path).map_err(|e| EnvironmentError::Io {
        path: path.to_path_buf(),
        message: e.to_string(),
    })
}

fn parse<'i>(path: &Path, text: &'i str) -> Result<roxmltree::Document<'i>, EnvironmentError> {
    if let Some((line, tag)) = crate::robot::urdf::too_deep(text, 200) {
        return Err(EnvironmentError::Sdf {
            path: path.to_path_buf(),
            line: Some(line as u32),
            message: format!("<{tag}> is nested more than 200 levels deep"),
        });
    }
    roxmltree::Document::parse(text).map_err(|e| EnvironmentError::Sdf {
        path: path.to_path_buf(),
        line: Some(e.pos().row),
        message: format!("not XML: {e}"),
    })
}

impl Loader {
    fn warn(&mut self, message: String) {
        self.report.warnings.push(message);
    }

    fn drop(&mut self, name: String, reason: DropReason) {
        self.report.dropped.push(Dropped { name, reason });
    }

    /// An element no loader branch knows: a warning with its line, as libsdformat gives,
    /// unless it is a namespaced extension element.
    fn unknown(&mut self, doc: &Doc, n: Node, parent: &str) {
        if n.tag_name().namespace().is_some() {
            return;
        }
        self.warn(format!(
            "{}: <{}> is not an SDF element of <{parent}>; ignored",
            doc.at(n),
            n.tag_name().name()
        ));
    }

    /// An SDF file: its world, or its model(s). `include` is what an including element says
    /// (its name and pose replace the model's own).
    fn file(
        &mut self,
        path: &Path,
        include: Option<Including>,
        parent: &Isometry3<f64>,
        prefix: &str,
        depth: usize,
    ) -> Result<(), EnvironmentError> {
        let text = read(path)?;
        let xml = parse(path, &text)?;
        let doc = Doc { path, xml: &xml };
        let root = xml.root_element();
        if root.tag_name().name() != "sdf" {
            return Err(doc.err(
                root,
                format!(
                    "expected an <sdf> document, found <{}>",
                    root.tag_name().name()
                ),
            ));
        }
        let mut found = false;
        for n in elements(root) {
            match n.tag_name().name() {
                "world" if include.is_none() && !found => {
                    found = true;
                    self.world(&doc, n)?;
                }
                "model" if !found => {
                    found = true;
                    let inc = include.clone().unwrap_or_default();
                    let own = doc.pose_of(n)?.map(|p| p.iso);
                    let x = parent * inc.pose.or(own).unwrap_or_else(Isometry3::identity);
                    self.model(&doc, n, &inc, &x, prefix, depth)?;
                }
                "actor" => self.drop(attr_name(n, "actor"), DropReason::Actor),
                "world" | "model" | "light" => {}
                _ => self.unknown(&doc, n, "sdf"),
            }
        }
        if !found {
            return Err(doc.err(root, "expected a <world> or a <model> in the <sdf> element"));
        }
        Ok(())
    }

    /// A `<world>`: its models and includes, placed in the world frame.
    fn world(&mut self, doc: &Doc, w: Node) -> Result<(), EnvironmentError> {
        let scope = self.scope(doc, w, "world")?;
        for n in elements(w) {
            match n.tag_name().name() {
                "model" => {
                    let pose = doc.pose_of(n)?;
                    let x = scope.place(doc, n, pose.as_ref(), None)?;
                    self.model(doc, n, &Including::default(), &x, "", 1)?;
                }
                "include" => self.include(doc, n, &scope, &Isometry3::identity(), "", 1)?,
                "actor" => self.drop(attr_name(n, "actor"), DropReason::Actor),
                "plugin" => self.drop(plugin_name(n), DropReason::Plugin),
                "physics"
                | "scene"
                | "gui"
                | "light"
                | "gravity"
                | "magnetic_field"
                | "atmosphere"
                | "spherical_coordinates"
                | "wind"
                | "audio"
                | "state"
                | "population"
                | "road"
                | "frame"
                | "joint" => {}
                _ => self.unknown(doc, n, "world"),
            }
        }
        Ok(())
    }

    /// The named frames of a model or world element.
    fn scope(&mut self, doc: &Doc, n: Node, root: &'static str) -> Result<Scope, EnvironmentError> {
        let mut frames = HashMap::new();
        for c in elements(n) {
            let tag = c.tag_name().name();
            let (name, default_parent) = match tag {
                "link" | "model" => (c.attribute("name"), None),
                "include" => (
                    c.children()
                        .find(|k| k.tag_name().name() == "name")
                        .and_then(|k| k.text()),
                    None,
                ),
                "frame" => (c.attribute("name"), c.attribute("attached_to")),
                "joint" => (c.attribute("name"), None),
                _ => continue,
            };
            let Some(name) = name.map(str::trim).filter(|s| !s.is_empty()) else {
                continue;
            };
            let default_parent = match tag {
                "joint" => text_of(child(c, "child")),
                _ => default_parent.map(str::to_string),
            };
            frames.insert(
                name.to_string(),
                FrameEntry {
                    pose: doc.pose_of(c)?,
                    default_parent: default_parent.filter(|s| !s.is_empty()),
                },
            );
        }
        Ok(Scope { root, frames })
    }

    /// A `<model>` at `x` (world frame), brought in by `inc` (default: written in place).
    ///
    /// A model that is not static and carries a `<plugin>` (its own or its include's) is moved
    /// by code nothing here runs (the DQN stages' turning obstacles): its collision geometry is
    /// dropped, not frozen at its initial pose.
    fn model(
        &mut self,
        doc: &Doc,
        m: Node,
        inc: &Including,
        x: &Isometry3<f64>,
        prefix: &str,
        depth: usize,
    ) -> Result<(), EnvironmentError> {
        if depth > MAX_DEPTH {
            return Err(doc.err(m, format!("models nest more than {MAX_DEPTH} deep")));
        }
        let own = inc.name.clone().unwrap_or_else(|| attr_name(m, "model"));
        let name = scoped(prefix, &own);
        let is_static = inc.is_static.or(sdf_bool(text_of(child(m, "static"))));
        let mut plugins = inc.plugins.clone();
        plugins.extend(
            elements(m)
                .filter(|n| n.tag_name().name() == "plugin")
                .map(plugin_name),
        );
        let driven = is_static != Some(true) && !plugins.is_empty();
        let before = self.obstacles.len();
        if is_static == Some(false) && prefix.is_empty() && !driven {
            self.warn(format!(
                "{}: model `{name}` is not static in the SDF; its obstacles are fixed here at \
                 their initial poses",
                doc.at(m)
            ));
        }
        let scope = self.scope(doc, m, "__model__")?;
        for n in elements(m) {
            match n.tag_name().name() {
                "link" => self.link(doc, n, &scope, x, &name)?,
                "model" => {
                    let pose = doc.pose_of(n)?;
                    let xc = x * scope.place(doc, n, pose.as_ref(), None)?;
                    self.model(doc, n, &Including::default(), &xc, &name, depth + 1)?;
                }
                "include" => self.include(doc, n, &scope, x, &name, depth + 1)?,
                "plugin" => self.drop(plugin_name(n), DropReason::Plugin),
                "static" | "self_collide" | "allow_auto_disable" | "enable_wind" | "pose"
                | "joint" | "gripper" | "frame" => {}
                _ => self.unknown(doc, n, "model"),
            }
        }
        if driven {
            let moved: Vec<ObstacleSpec> = self.obstacles.drain(before..).collect();
            self.warn(format!(
                "{}: model `{name}` is not static and is moved by plugin {} (not run here): \
                 its {} obstacle(s) are left out",
                doc.at(m),
                plugins.join(", "),
                moved.len()
            ));
            for o in moved {
                self.drop(o.name, DropReason::PluginDriven);
            }
        }
        Ok(())
    }

    /// An `<include>` in a scope whose frame is at `x` (world frame).
    fn include(
        &mut self,
        doc: &Doc,
        n: Node,
        scope: &Scope,
        x: &Isometry3<f64>,
        prefix: &str,
        depth: usize,
    ) -> Result<(), EnvironmentError> {
        let Some(uri) = text_of(child(n, "uri")) else {
            return Err(doc.err(n, "<include> needs a <uri>"));
        };
        let mut plugins = Vec::new();
        for c in elements(n) {
            match c.tag_name().name() {
                "plugin" => {
                    plugins.push(plugin_name(c));
                    self.drop(plugin_name(c), DropReason::Plugin);
                }
                "placement_frame" => self.warn(format!(
                    "{}: <placement_frame> is not supported; the include's <pose> places the \
                     model's own frame",
                    doc.at(c)
                )),
                "uri" | "name" | "pose" | "static" => {}
                _ => self.unknown(doc, c, "include"),
            }
        }
        if uri.starts_with("http://") || uri.starts_with("https://") {
            // Named in the report's "dropped, Fuel include" line: nothing is fetched.
            self.drop(uri.clone(), DropReason::FuelInclude);
            return Ok(());
        }
        let file = self.model_file(doc, n, &uri)?;
        let pose = doc.pose_of(n)?;
        let placed = match &pose {
            Some(p) => Some(scope.place(doc, n, Some(p), None)?),
            None => None,
        };
        let including = Including {
            name: text_of(child(n, "name")),
            pose: placed,
            plugins,
            is_static: sdf_bool(text_of(child(n, "static"))),
        };
        self.file(&file, Some(including), x, prefix, depth + 1)
    }

    /// The SDF file an include's URI names.
    fn model_file(&self, doc: &Doc, n: Node, uri: &str) -> Result<PathBuf, EnvironmentError> {
        let dir = self.resolve_uri(doc, n, uri)?;
        if dir.is_file() {
            return Ok(dir);
        }
        let config = dir.join("model.config");
        let named = std::fs::read_to_string(&config)
            .ok()
            .and_then(|t| best_sdf_of_config(&t));
        let file = dir.join(named.unwrap_or_else(|| "model.sdf".into()));
        if file.is_file() {
            Ok(file)
        } else {
            Err(doc.err(
                n,
                format!(
                    "<include> {uri}: {} has no model file (expected the file model.config \
                     names, or model.sdf)",
                    dir.display()
                ),
            ))
        }
    }

    /// A `model://` URI (or a path relative to the including file) as a path that exists.
    fn resolve_uri(&self, doc: &Doc, n: Node, uri: &str) -> Result<PathBuf, EnvironmentError> {
        let here = doc.path.parent().unwrap_or_else(|| Path::new("."));
        if let Some(rest) = uri.strip_prefix("model://") {
            let rest = rest.trim_start_matches('/');
            let found = self
                .search
                .iter()
                .map(|d| d.join(rest))
                .find(|p| p.exists());
            return found.ok_or_else(|| {
                doc.err(n, format!("{uri} not found; searched {}", self.searched()))
            });
        }
        let plain = uri.strip_prefix("file://").unwrap_or(uri);
        let p = here.join(plain);
        if p.exists() {
            Ok(p)
        } else {
            Err(doc.err(n, format!("{uri}: {} does not exist", p.display())))
        }
    }

    /// A `<link>` of a model whose frame is at `x`.
    fn link(
        &mut self,
        doc: &Doc,
        l: Node,
        scope: &Scope,
        x: &Isometry3<f64>,
        model: &str,
    ) -> Result<(), EnvironmentError> {
        let lname = attr_name(l, "link");
        let pose = doc.pose_of(l)?;
        let xl = x * scope.place(doc, l, pose.as_ref(), None)?;
        let link = scoped(model, &lname);
        let (mut collisions, mut visuals) = (0, 0);
        for c in elements(l) {
            match c.tag_name().name() {
                "collision" => {
                    collisions += 1;
                    let cpose = doc.pose_of(c)?;
                    let xc = match cpose.as_ref().and_then(|p| p.relative_to.as_deref()) {
                        Some(_) => x * scope.place(doc, c, cpose.as_ref(), None)?,
                        None => xl * cpose.map_or(Isometry3::identity(), |p| p.iso),
                    };
                    let name = scoped(&link, &attr_name(c, "collision"));
                    self.collision(doc, c, &name, &xc)?;
                }
                "visual" => visuals += 1,
                "plugin" => self.drop(plugin_name(c), DropReason::Plugin),
                "gravity" | "enable_wind" | "self_collide" | "kinematic" | "must_be_base_link"
                | "velocity_decay" | "pose" | "inertial" | "sensor" | "projector"
                | "audio_sink" | "audio_source" | "battery" | "light" | "particle_emitter"
                | "frame" => {}
                _ => self.unknown(doc, c, "link"),
            }
        }
        if collisions == 0 && visuals > 0 {
            self.drop(link, DropReason::VisualOnly);
        }
        Ok(())
    }

    /// A `<collision>` at `x` (world frame).
    fn collision(
        &mut self,
        doc: &Doc,
        c: Node,
        name: &str,
        x: &Isometry3<f64>,
    ) -> Result<(), EnvironmentError> {
        for k in elements(c) {
            match k.tag_name().name() {
                "geometry" | "pose" | "laser_retro" | "max_contacts" | "surface" => {}
                _ => self.unknown(doc, k, "collision"),
            }
        }
        let Some(g) = child(c, "geometry") else {
            return Err(doc.err(c, format!("collision `{name}` has no <geometry>")));
        };
        let Some(shape) = elements(g).find(|k| k.tag_name().namespace().is_none()) else {
            self.drop(name.to_string(), DropReason::NoGeometry);
            return Ok(());
        };
        if self.obstacles.len() >= MAX_COLLISIONS {
            return Err(doc.err(
                c,
                format!("more than {MAX_COLLISIONS} collision elements; not a world to load whole"),
            ));
        }
        for (spec, (z_lo, z_hi)) in geometry::geometry(self, doc, shape, name, x)? {
            if self.robot_height.is_some_and(|h| z_lo > h) {
                self.drop(spec.name, DropReason::AboveRobot);
            } else if z_hi <= 1e-6 {
                self.drop(spec.name, DropReason::Ground);
            } else {
                self.obstacles.push(spec);
            }
        }
        Ok(())
    }
}

/// The model file `model.config` names for the highest `<sdf version>`.
fn best_sdf_of_config(text: &str) -> Option<String> {
    let xml = roxmltree::Document::parse(text).ok()?;
    let version = |v: &str| -> Vec<u32> { v.split('.').filter_map(|p| p.parse().ok()).collect() };
    xml.root_element()
        .descendants()
        .filter(|n| n.is_element() && n.tag_name().name() == "sdf")
        .filter_map(|n| {
            Some((
                version(n.attribute("version").unwrap_or("0")),
                n.text()?.trim(),
            ))
        })
        .max_by(|a, b| a.0.cmp(&b.0))
        .map(|(_, f)| f.to_string())
}

fn attr_name(n: Node, what: &str) -> String {
    n.attribute("name")
        .map(str::to_string)
        .unwrap_or_else(|| format!("unnamed_{what}"))
}

fn plugin_name(n: Node) -> String {
    n.attribute("name")
        .or_else(|| n.attribute("filename"))
        .unwrap_or("plugin")
        .to_string()
}

/// Gazebo's scoped name `parent::child`.
fn scoped(prefix: &str, name: &str) -> String {
    if prefix.is_empty() {
        name.to_string()
    } else {
        format!("{prefix}::{name}")
    }
}

/// World-frame z range of `pts` (obstacle frame) placed at `x`.
pub(super) fn z_range(x: &Isometry3<f64>, pts: impl Iterator<Item = [f64; 3]>) -> (f64, f64) {
    pts.map(|p| (x * Point3::from(p)).z)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), z| {
            (lo.min(z), hi.max(z))
        })
}

/// An obstacle spec at `x`.
pub(super) fn spec_at(name: &str, x: &Isometry3<f64>, shape: ShapeSpec) -> ObstacleSpec {
    let (r, p, y) = x.rotation.euler_angles();
    let t = x.translation.vector;
    ObstacleSpec {
        name: name.to_string(),
        position: [t.x, t.y, t.z],
        rpy: [r, p, y],
        shape,
        motion: None,
        tracker: None,
    }
}

/// A mesh's scale as a spec writes it (`None` when it is 1 on every axis).
pub(super) fn mesh_scale(s: [f64; 3]) -> Option<MeshScale> {
    if s == [1.0; 3] {
        None
    } else if s[0] == s[1] && s[1] == s[2] && s[0] > 0.0 {
        Some(MeshScale::Uniform(s[0]))
    } else {
        Some(MeshScale::PerAxis(s))
    }
}

impl Loader {
    /// A mesh URI (`model://…`, `file://…` or relative to the SDF file) as a file that exists.
    fn resolve_mesh(&self, doc_path: &Path, uri: &str) -> Result<PathBuf, String> {
        if let Some(rest) = uri.strip_prefix("model://") {
            let rest = rest.trim_start_matches('/');
            return self
                .search
                .iter()
                .map(|d| d.join(rest))
                .find(|p| p.is_file())
                .ok_or_else(|| format!("{uri} not found; searched {}", self.searched()));
        }
        let here = doc_path.parent().unwrap_or_else(|| Path::new("."));
        let p = here.join(uri.strip_prefix("file://").unwrap_or(uri));
        if p.is_file() {
            Ok(p)
        } else {
            Err(format!("{uri}: {} is not a file", p.display()))
        }
    }

    /// The directories `model://` searches, for a message.
    fn searched(&self) -> String {
        if self.search.is_empty() {
            return "no directories (set environment.model_paths, GZ_SIM_RESOURCE_PATH or \
                    GAZEBO_MODEL_PATH)"
                .into();
        }
        let dirs: Vec<String> = self
            .search
            .iter()
            .map(|d| d.display().to_string())
            .collect();
        format!(
            "{} (environment.model_paths, then GZ_SIM_RESOURCE_PATH and GAZEBO_MODEL_PATH)",
            dirs.join(", ")
        )
    }
}
