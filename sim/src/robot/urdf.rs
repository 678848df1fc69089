//! URDF XML → `urdf_rs::Robot`, read the way ROS's parser (urdfdom) reads it.
//!
//! urdf-rs's own serde reader refuses files that ROS loads (an unknown attribute such as the
//! Pioneer 3-DX's `<axis xzy="0 0 1"/>` on a fixed joint gives "missing field `xyz`"), names no
//! line, and recurses once per nesting level (a deeply nested file overflowed the stack). This
//! reader parses the XML with `roxmltree` (positions for every node; its tree builder is not
//! recursive) and walks the known elements itself, never recursing:
//!
//! - Unknown elements and attributes are ignored, as urdfdom ignores them, and reported as
//!   warnings with their line. `<gazebo>`, `<transmission>` and `<ros2_control>` (simulator and
//!   controller extensions every ROS package carries) are ignored silently.
//! - Missing optional values take the spec's (and urdfdom's) defaults: `<origin>` and its
//!   `xyz`/`rpy` zero; no `<axis>` on a moving joint (1, 0, 0); `<limit lower/upper>` 0; a fixed
//!   or floating joint's `<axis>` is never read.
//! - What urdfdom refuses is refused, with the element, its `name` and the line: a `<link>` or
//!   `<joint>` without a name, an unknown joint type, a `<limit>` without `effort` or
//!   `velocity`, a revolute/prismatic joint without `<limit>`, an `<inertial>` without `<mass
//!   value>` or a complete `<inertia>`, a `<visual>`/`<collision>` without `<geometry>`, an
//!   unknown geometry, a shape without its size, a number or vector that does not parse,
//!   duplicate link, joint or material names, a top-level `<material>` without colour or
//!   texture. The structure (one tree, no cycle, links that exist) is checked afterwards by the
//!   loader, which names the joint and its line.
//! - Elements nested deeper than [`MAX_DEPTH`] are refused before anything else is read.

use std::collections::HashMap;

use roxmltree::{Document, Node, ParsingOptions};

use super::RobotError;

/// Deepest element nesting accepted. A URDF needs five levels (`robot/link/visual/material/
/// color`); `<gazebo>` plugin blocks a few more. XML parsers used by ROS cap nesting too
/// (tinyxml2 refuses deep nesting with "Element nesting is too deep").
pub const MAX_DEPTH: usize = 100;

/// A parsed URDF with the line of each link and joint (1-based, parallel to `robot.links` and
/// `robot.joints`) and the warnings about what was ignored.
#[derive(Debug, Clone)]
pub(crate) struct Parsed {
    pub robot: urdf_rs::Robot,
    pub link_lines: Vec<usize>,
    pub joint_lines: Vec<usize>,
    /// The `<axis xyz>` written on each `fixed` joint (parallel to `robot.joints`; `None` for
    /// other joints and when absent or unparsable). urdfdom never reads it; the loader uses it
    /// only when a world names a fixed joint as a drive wheel.
    pub fixed_axes: Vec<Option<[f64; 3]>>,
    pub warnings: Vec<String>,
}

/// The line and tag name of the first start tag nested deeper than `limit` elements, found by
/// a linear scan that never recurses (comments, CDATA, processing instructions, the DOCTYPE
/// and quoted attribute values are skipped). Malformed text is left to the XML parser.
pub fn too_deep(text: &str, limit: usize) -> Option<(usize, String)> {
    let b = text.as_bytes();
    let skip_to = |from: usize, end: &str| {
        text[from..]
            .find(end)
            .map_or(b.len(), |k| from + k + end.len())
    };
    // End of a tag starting at `i` (after its `>`), honouring quoted values and `[ … ]`.
    let tag_end = |mut i: usize| {
        let (mut quote, mut brackets) = (0u8, 0usize);
        while i < b.len() {
            let c = b[i];
            if quote != 0 {
                if c == quote {
                    quote = 0;
                }
            } else if c == b'"' || c == b'\'' {
                quote = c;
            } else if c == b'[' {
                brackets += 1;
            } else if c == b']' {
                brackets = brackets.saturating_sub(1);
            } else if c == b'>' && brackets == 0 {
                return i + 1;
            }
            i += 1;
        }
        b.len()
    };
    let mut depth = 0usize;
    let mut i = 0usize;
    while let Some(k) = text[i..].find('<') {
        let at = i + k;
        let rest = &text[at..];
        if rest.starts_with("<!--") {
            i = skip_to(at + 4, "-->");
        } else if rest.starts_with("<![CDATA[") {
            i = skip_to(at + 9, "]]>");
        } else if rest.starts_with("<?") {
            i = skip_to(at + 2, "?>");
        } else if rest.starts_with("<!") {
            i = tag_end(at + 2);
        } else if rest.starts_with("</") {
            depth = depth.saturating_sub(1);
            i = tag_end(at + 2);
        } else {
            let end = tag_end(at + 1);
            let self_closing = end >= 2 && b.get(end - 2) == Some(&b'/') && b[end - 1] == b'>';
            if !self_closing {
                depth += 1;
                if depth > limit {
                    let line = text[..at].matches('\n').count() + 1;
                    let name: String = rest[1..]
                        .chars()
                        .take_while(|c| !c.is_whitespace() && *c != '>' && *c != '/')
                        .take(40)
                        .collect();
                    return Some((line, name));
                }
            }
            i = end;
        }
        if i >= b.len() {
            break;
        }
    }
    None
}

/// Top-level elements ROS packages carry for other tools; ignored without a warning.
const SILENT_TOP: [&str; 3] = ["gazebo", "transmission", "ros2_control"];

struct Reader<'a, 'input> {
    origin: &'a str,
    doc: &'a Document<'input>,
    line_starts: Vec<usize>,
    warnings: Vec<String>,
}

/// Parses URDF text. `origin` names the file in messages.
pub(crate) fn parse(text: &str, origin: &str) -> Result<Parsed, RobotError> {
    // roxmltree's tokenizer recurses once per nesting level: measure the depth first.
    if let Some((line, tag)) = too_deep(text, MAX_DEPTH) {
        return Err(RobotError::Parse {
            origin: origin.to_string(),
            line: Some(line),
            message: format!(
                "<{tag}> is nested more than {MAX_DEPTH} levels deep, which no robot description \
                 needs (a URDF needs 5); refused before parsing"
            ),
        });
    }
    let opts = ParsingOptions {
        allow_dtd: true,
        ..ParsingOptions::default()
    };
    let doc = Document::parse_with_options(text, opts).map_err(|e| {
        let pos = e.pos();
        RobotError::Parse {
            origin: origin.to_string(),
            line: Some(pos.row as usize),
            message: format!("not well-formed XML: {e}"),
        }
    })?;
    let mut line_starts = vec![0];
    line_starts.extend(text.match_indices('\n').map(|(i, _)| i + 1));
    let mut r = Reader {
        origin,
        doc: &doc,
        line_starts,
        warnings: Vec::new(),
    };
    r.robot()
}

fn attr_list(names: &[&str]) -> String {
    names
        .iter()
        .map(|n| format!("`{n}`"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// `<joint>` `wheel_left_joint` / `<link>` (unnamed).
fn describe(n: Node) -> String {
    match n.attribute("name") {
        Some(name) => format!("<{}> `{name}`", n.tag_name().name()),
        None => format!("<{}>", n.tag_name().name()),
    }
}

impl<'a, 'input> Reader<'a, 'input> {
    fn line(&self, n: Node) -> usize {
        let pos = n.range().start;
        self.line_starts.partition_point(|&s| s <= pos)
    }

    fn err(&self, n: Node, message: String) -> RobotError {
        RobotError::Parse {
            origin: self.origin.to_string(),
            line: Some(self.line(n)),
            message,
        }
    }

    fn warn(&mut self, n: Node, message: String) {
        let line = self.line(n);
        self.warnings
            .push(format!("{}: line {line}: {message}", self.origin));
    }

    /// Warns about attributes not in `known` (namespace declarations are not attributes here).
    fn attrs(&mut self, n: Node, known: &[&str], ctx: &str) {
        for a in n.attributes() {
            if a.namespace().is_some() || !known.contains(&a.name()) {
                let known = if known.is_empty() {
                    "it takes none".to_string()
                } else {
                    format!("known: {}", attr_list(known))
                };
                let msg = format!(
                    "unknown attribute `{}` on {ctx} ignored (as ROS's urdfdom ignores it; {known})",
                    a.name()
                );
                self.warn(n, msg);
            }
        }
    }

    /// Warns about child elements not in `known`.
    fn children(&mut self, n: Node, known: &[&str], ctx: &str) {
        for c in n.children().filter(Node::is_element) {
            let name = c.tag_name().name();
            if c.tag_name().namespace().is_some() || !known.contains(&name) {
                let msg = format!(
                    "unknown element <{name}> in {ctx} ignored (as ROS's urdfdom ignores it)"
                );
                self.warn(c, msg);
            }
        }
    }

    fn number(&self, n: Node, attr: &str, ctx: &str) -> Result<Option<f64>, RobotError> {
        let Some(s) = n.attribute(attr) else {
            return Ok(None);
        };
        parse_number(s)
            .map(Some)
            .ok_or_else(|| self.err(n, format!("{ctx}: `{attr}=\"{s}\"` is not a finite number")))
    }

    fn required_number(&self, n: Node, attr: &str, ctx: &str) -> Result<f64, RobotError> {
        self.number(n, attr, ctx)?
            .ok_or_else(|| self.err(n, format!("{ctx} has no `{attr}` (required)")))
    }

    fn vector<const N: usize>(
        &self,
        n: Node,
        attr: &str,
        ctx: &str,
    ) -> Result<Option<[f64; N]>, RobotError> {
        let Some(s) = n.attribute(attr) else {
            return Ok(None);
        };
        let parts: Vec<&str> = s.split_whitespace().collect();
        let bad = || {
            self.err(
                n,
                format!("{ctx}: `{attr}=\"{s}\"` is not {N} finite numbers"),
            )
        };
        if parts.len() != N {
            return Err(bad());
        }
        let mut out = [0.0; N];
        for (o, p) in out.iter_mut().zip(parts) {
            *o = parse_number(p).ok_or_else(bad)?;
        }
        Ok(Some(out))
    }

    fn name(&self, n: Node, ctx: &str) -> Result<String, RobotError> {
        n.attribute("name")
            .map(str::to_string)
            .ok_or_else(|| self.err(n, format!("{ctx} has no `name` (required)")))
    }

    /// `<origin xyz rpy>` (the first one); missing element or attributes are zero.
    fn origin_of(&mut self, parent: Node, ctx: &str) -> Result<urdf_rs::Pose, RobotError> {
        let Some(o) = first(parent, "origin") else {
            return Ok(urdf_rs::Pose::default());
        };
        let ctx = format!("<origin> of {ctx}");
        self.attrs(o, &["xyz", "rpy"], &ctx);
        let xyz = self.vector::<3>(o, "xyz", &ctx)?.unwrap_or([0.0; 3]);
        let rpy = self.vector::<3>(o, "rpy", &ctx)?.unwrap_or([0.0; 3]);
        Ok(urdf_rs::Pose {
            xyz: urdf_rs::Vec3(xyz),
            rpy: urdf_rs::Vec3(rpy),
        })
    }

    fn robot(&mut self) -> Result<Parsed, RobotError> {
        let root = self.doc.root_element();
        if root.tag_name().name() != "robot" {
            return Err(self.err(
                root,
                format!(
                    "the root element is <{}>; a URDF's is <robot>",
                    root.tag_name().name()
                ),
            ));
        }
        let name = self.name(root, "<robot>")?;
        self.attrs(root, &["name", "version"], "<robot>");
        let mut robot = urdf_rs::Robot {
            name,
            version: root.attribute("version").map(str::to_string),
            links: Vec::new(),
            joints: Vec::new(),
            materials: Vec::new(),
        };
        let (mut link_lines, mut joint_lines) = (vec![], vec![]);
        let mut fixed_axes: Vec<Option<[f64; 3]>> = Vec::new();
        let mut material_lines: Vec<usize> = Vec::new();
        // Name → index of the first definition: duplicates are found in linear time (a list
        // search made 50,000 links quadratic).
        let mut link_at: HashMap<String, usize> = HashMap::new();
        let mut joint_at: HashMap<String, usize> = HashMap::new();
        let mut material_at: HashMap<String, usize> = HashMap::new();
        for c in root.children().filter(Node::is_element) {
            let tag = c.tag_name().name();
            let plain = c.tag_name().namespace().is_none();
            match tag {
                "link" if plain => {
                    let link = self.link(c)?;
                    if let Some(&k) = link_at.get(&link.name) {
                        return Err(self.err(
                            c,
                            format!(
                                "<link> `{}` is defined twice (first on line {})",
                                link.name, link_lines[k]
                            ),
                        ));
                    }
                    link_at.insert(link.name.clone(), robot.links.len());
                    robot.links.push(link);
                    link_lines.push(self.line(c));
                }
                "joint" if plain => {
                    let (joint, fixed_axis) = self.joint(c)?;
                    if let Some(&k) = joint_at.get(&joint.name) {
                        return Err(self.err(
                            c,
                            format!(
                                "<joint> `{}` is defined twice (first on line {})",
                                joint.name, joint_lines[k]
                            ),
                        ));
                    }
                    joint_at.insert(joint.name.clone(), robot.joints.len());
                    robot.joints.push(joint);
                    joint_lines.push(self.line(c));
                    fixed_axes.push(fixed_axis);
                }
                "material" if plain => {
                    let m = self.material(c, "<robot>", false)?;
                    if let Some(&k) = material_at.get(&m.name) {
                        return Err(self.err(
                            c,
                            format!(
                                "<material> `{}` is defined twice (first on line {})",
                                m.name, material_lines[k]
                            ),
                        ));
                    }
                    material_at.insert(m.name.clone(), robot.materials.len());
                    robot.materials.push(m);
                    material_lines.push(self.line(c));
                }
                t if plain && SILENT_TOP.contains(&t) => {}
                _ => {
                    let msg = format!(
                        "unknown element <{tag}> in <robot> ignored (as ROS's urdfdom ignores it)"
                    );
                    self.warn(c, msg);
                }
            }
        }
        Ok(Parsed {
            robot,
            link_lines,
            joint_lines,
            fixed_axes,
            warnings: std::mem::take(&mut self.warnings),
        })
    }

    fn material(
        &mut self,
        n: Node,
        ctx: &str,
        only_name_is_ok: bool,
    ) -> Result<urdf_rs::Material, RobotError> {
        let name = self.name(n, &format!("<material> in {ctx}"))?;
        let what = format!("<material> `{name}`");
        self.attrs(n, &["name"], &what);
        self.children(n, &["color", "texture"], &what);
        let color = match first(n, "color") {
            Some(c) => {
                let cctx = format!("<color> of {what}");
                self.attrs(c, &["rgba"], &cctx);
                let rgba = self
                    .vector::<4>(c, "rgba", &cctx)?
                    .ok_or_else(|| self.err(c, format!("{cctx} has no `rgba` (required)")))?;
                Some(urdf_rs::Color {
                    rgba: urdf_rs::Vec4(rgba),
                })
            }
            None => None,
        };
        let texture = match first(n, "texture") {
            Some(t) => {
                let tctx = format!("<texture> of {what}");
                self.attrs(t, &["filename"], &tctx);
                t.attribute("filename").map(|f| urdf_rs::Texture {
                    filename: f.to_string(),
                })
            }
            None => None,
        };
        if !only_name_is_ok && color.is_none() && texture.is_none() {
            return Err(self.err(
                n,
                format!("{what} defines neither a <color rgba> nor a <texture filename>"),
            ));
        }
        Ok(urdf_rs::Material {
            name,
            color,
            texture,
        })
    }

    fn link(&mut self, n: Node) -> Result<urdf_rs::Link, RobotError> {
        let name = self.name(n, "<link>")?;
        let what = format!("<link> `{name}`");
        self.attrs(n, &["name", "type"], &what);
        self.children(n, &["inertial", "visual", "collision"], &what);
        let mut inertial = urdf_rs::Inertial::default();
        let inertials = all(n, "inertial");
        let mut inertials = inertials.into_iter();
        if let Some(i) = inertials.next() {
            inertial = self.inertial(i, &what)?;
        }
        if let Some(extra) = inertials.next() {
            let msg = format!("second <inertial> in {what} ignored (only the first counts)");
            self.warn(extra, msg);
        }
        let mut visual = Vec::new();
        for v in all(n, "visual") {
            let vname = v.attribute("name").map(str::to_string);
            let ctx = format!("<visual> of {what}");
            self.attrs(v, &["name"], &ctx);
            self.children(v, &["origin", "geometry", "material"], &ctx);
            let origin = self.origin_of(v, &ctx)?;
            let geometry = self.geometry(v, &ctx)?;
            let material = match first(v, "material") {
                Some(m) => Some(self.material(m, &ctx, true)?),
                None => None,
            };
            visual.push(urdf_rs::Visual {
                name: vname,
                origin,
                geometry,
                material,
            });
        }
        let mut collision = Vec::new();
        for c in all(n, "collision") {
            let cname = c.attribute("name").map(str::to_string);
            let ctx = format!("<collision> of {what}");
            self.attrs(c, &["name"], &ctx);
            self.children(c, &["origin", "geometry"], &ctx);
            let origin = self.origin_of(c, &ctx)?;
            let geometry = self.geometry(c, &ctx)?;
            collision.push(urdf_rs::Collision {
                name: cname,
                origin,
                geometry,
            });
        }
        Ok(urdf_rs::Link {
            name,
            inertial,
            visual,
            collision,
        })
    }

    fn inertial(&mut self, n: Node, link: &str) -> Result<urdf_rs::Inertial, RobotError> {
        let ctx = format!("<inertial> of {link}");
        self.attrs(n, &[], &ctx);
        self.children(n, &["origin", "mass", "inertia"], &ctx);
        let origin = self.origin_of(n, &ctx)?;
        let m = first(n, "mass")
            .ok_or_else(|| self.err(n, format!("{ctx} has no <mass> (required)")))?;
        let mctx = format!("<mass> of {link}");
        self.attrs(m, &["value"], &mctx);
        let value = self.required_number(m, "value", &mctx)?;
        let i = first(n, "inertia")
            .ok_or_else(|| self.err(n, format!("{ctx} has no <inertia> (required)")))?;
        const SIX: [&str; 6] = ["ixx", "ixy", "ixz", "iyy", "iyz", "izz"];
        let ictx = format!("<inertia> of {link}");
        self.attrs(i, &SIX, &ictx);
        let mut v = [0.0; 6];
        for (slot, a) in v.iter_mut().zip(SIX) {
            *slot = self.required_number(i, a, &ictx)?;
        }
        Ok(urdf_rs::Inertial {
            origin,
            mass: urdf_rs::Mass { value },
            inertia: urdf_rs::Inertia {
                ixx: v[0],
                ixy: v[1],
                ixz: v[2],
                iyy: v[3],
                iyz: v[4],
                izz: v[5],
            },
        })
    }

    fn geometry(&mut self, parent: Node, ctx: &str) -> Result<urdf_rs::Geometry, RobotError> {
        let g = first(parent, "geometry")
            .ok_or_else(|| self.err(parent, format!("{ctx} has no <geometry> (required)")))?;
        let gctx = format!("<geometry> of {ctx}");
        self.attrs(g, &[], &gctx);
        let mut shapes = g.children().filter(Node::is_element);
        let s = shapes.next().ok_or_else(|| {
            self.err(
                g,
                format!("{gctx} holds no shape (<box>, <cylinder>, <sphere> or <mesh>)"),
            )
        })?;
        if let Some(extra) = shapes.next() {
            let msg = format!(
                "<{}> in {gctx} ignored: only the first shape counts",
                extra.tag_name().name()
            );
            self.warn(extra, msg);
        }
        let sctx = format!("<{}> in {gctx}", s.tag_name().name());
        Ok(match s.tag_name().name() {
            "box" => {
                self.attrs(s, &["size"], &sctx);
                let size = self
                    .vector::<3>(s, "size", &sctx)?
                    .ok_or_else(|| self.err(s, format!("{sctx} has no `size` (required)")))?;
                urdf_rs::Geometry::Box {
                    size: urdf_rs::Vec3(size),
                }
            }
            "cylinder" => {
                self.attrs(s, &["radius", "length"], &sctx);
                urdf_rs::Geometry::Cylinder {
                    radius: self.required_number(s, "radius", &sctx)?,
                    length: self.required_number(s, "length", &sctx)?,
                }
            }
            "capsule" => {
                self.attrs(s, &["radius", "length"], &sctx);
                let msg = format!(
                    "{sctx}: <capsule> is not in ROS's urdfdom (ROS refuses it); read as a capsule"
                );
                self.warn(s, msg);
                urdf_rs::Geometry::Capsule {
                    radius: self.required_number(s, "radius", &sctx)?,
                    length: self.required_number(s, "length", &sctx)?,
                }
            }
            "sphere" => {
                self.attrs(s, &["radius"], &sctx);
                urdf_rs::Geometry::Sphere {
                    radius: self.required_number(s, "radius", &sctx)?,
                }
            }
            "mesh" => {
                self.attrs(s, &["filename", "scale"], &sctx);
                let filename = s
                    .attribute("filename")
                    .ok_or_else(|| self.err(s, format!("{sctx} has no `filename` (required)")))?
                    .to_string();
                let scale = self.vector::<3>(s, "scale", &sctx)?.map(urdf_rs::Vec3);
                urdf_rs::Geometry::Mesh { filename, scale }
            }
            other => {
                return Err(self.err(
                    s,
                    format!(
                        "{gctx}: unknown shape <{other}> (URDF knows <box>, <cylinder>, <sphere> \
                         and <mesh>)"
                    ),
                ))
            }
        })
    }

    /// The joint, and for a `fixed` joint the `<axis xyz>` written on it (never an error: ROS
    /// does not read it). Reads, in order: the type, origin, parent and child links, axis,
    /// limit, and the optional calibration, dynamics, mimic and safety controller.
    fn joint(&mut self, n: Node) -> Result<(urdf_rs::Joint, Option<[f64; 3]>), RobotError> {
        let name = self.name(n, "<joint>")?;
        let what = describe(n);
        self.attrs(n, &["name", "type"], &what);
        self.children(
            n,
            &[
                "origin",
                "parent",
                "child",
                "axis",
                "limit",
                "calibration",
                "dynamics",
                "mimic",
                "safety_controller",
            ],
            &what,
        );
        let (joint_type, type_str) = self.joint_type(n, &what)?;
        let origin = self.origin_of(n, &what)?;
        let parent = self.joint_link(n, "parent", &what)?;
        let child = self.joint_link(n, "child", &what)?;
        let (axis, fixed_axis) = self.joint_axis(n, &what, &joint_type)?;
        let limit = self.joint_limit(n, &what, &joint_type, type_str)?;
        let joint = urdf_rs::Joint {
            name,
            joint_type,
            origin,
            parent: urdf_rs::LinkName { link: parent },
            child: urdf_rs::LinkName { link: child },
            axis,
            limit,
            calibration: self.calibration(n, &what)?,
            dynamics: self.dynamics(n, &what)?,
            mimic: self.mimic(n, &what)?,
            safety_controller: self.safety_controller(n, &what)?,
        };
        Ok((joint, fixed_axis))
    }

    /// The joint's `type` (required), with the text it was read from.
    fn joint_type<'n>(
        &self,
        n: Node<'n, '_>,
        what: &str,
    ) -> Result<(urdf_rs::JointType, &'n str), RobotError> {
        use urdf_rs::JointType as T;
        let type_str = n
            .attribute("type")
            .ok_or_else(|| self.err(n, format!("{what} has no `type` (required)")))?;
        let joint_type = match type_str {
            "fixed" => T::Fixed,
            "continuous" => T::Continuous,
            "revolute" => T::Revolute,
            "prismatic" => T::Prismatic,
            "floating" => T::Floating,
            "planar" => T::Planar,
            other => {
                return Err(self.err(
                    n,
                    format!(
                        "{what} has type `{other}`; URDF joint types are fixed, continuous, \
                         revolute, prismatic, floating and planar"
                    ),
                ))
            }
        };
        Ok((joint_type, type_str))
    }

    /// The `link` of the joint's `<parent>` or `<child>` (`tag`), both required.
    fn joint_link(&mut self, n: Node, tag: &str, what: &str) -> Result<String, RobotError> {
        let e = first(n, tag)
            .ok_or_else(|| self.err(n, format!("{what} has no <{tag} link=…> (required)")))?;
        let ctx = format!("<{tag}> of {what}");
        self.attrs(e, &["link"], &ctx);
        e.attribute("link")
            .map(str::to_string)
            .ok_or_else(|| self.err(e, format!("{ctx} has no `link` (required)")))
    }

    /// The joint's `<axis>` (default (1, 0, 0), with a warning when `xyz` is missing), and for
    /// a fixed joint the `xyz` written on it, which urdfdom does not read.
    fn joint_axis(
        &mut self,
        n: Node,
        what: &str,
        joint_type: &urdf_rs::JointType,
    ) -> Result<(urdf_rs::Axis, Option<[f64; 3]>), RobotError> {
        use urdf_rs::JointType as T;
        let mut axis = urdf_rs::Axis::default();
        let mut fixed_axis = None;
        if let Some(a) = first(n, "axis") {
            let ctx = format!("<axis> of {what}");
            self.attrs(a, &["xyz"], &ctx);
            // urdfdom never reads the axis of a fixed or floating joint.
            if !matches!(joint_type, T::Fixed | T::Floating) {
                match self.vector::<3>(a, "xyz", &ctx)? {
                    Some(xyz) => axis.xyz = urdf_rs::Vec3(xyz),
                    None => {
                        let msg =
                            format!("{ctx} has no `xyz`; using the URDF default axis (1, 0, 0)");
                        self.warn(a, msg);
                    }
                }
            } else if *joint_type == T::Fixed {
                fixed_axis = self.vector::<3>(a, "xyz", &ctx).ok().flatten();
            }
        }
        Ok((axis, fixed_axis))
    }

    /// The joint's `<limit>`, required for revolute and prismatic joints.
    fn joint_limit(
        &mut self,
        n: Node,
        what: &str,
        joint_type: &urdf_rs::JointType,
        type_str: &str,
    ) -> Result<urdf_rs::JointLimit, RobotError> {
        use urdf_rs::JointType as T;
        let mut limit = urdf_rs::JointLimit::default();
        match first(n, "limit") {
            Some(l) => {
                let ctx = format!("<limit> of {what}");
                self.attrs(
                    l,
                    &[
                        "lower",
                        "upper",
                        "effort",
                        "velocity",
                        "acceleration",
                        "deceleration",
                        "jerk",
                    ],
                    &ctx,
                );
                limit.lower = self.number(l, "lower", &ctx)?.unwrap_or(0.0);
                limit.upper = self.number(l, "upper", &ctx)?.unwrap_or(0.0);
                limit.effort = self.required_number(l, "effort", &ctx)?;
                limit.velocity = self.required_number(l, "velocity", &ctx)?;
            }
            None if matches!(joint_type, T::Revolute | T::Prismatic) => {
                return Err(self.err(
                    n,
                    format!(
                        "{what} is {type_str} but has no <limit> (required for {type_str} joints)"
                    ),
                ))
            }
            None => {}
        }
        Ok(limit)
    }

    /// The joint's optional `<calibration>`.
    fn calibration(
        &mut self,
        n: Node,
        what: &str,
    ) -> Result<Option<urdf_rs::Calibration>, RobotError> {
        let Some(c) = first(n, "calibration") else {
            return Ok(None);
        };
        let ctx = format!("<calibration> of {what}");
        self.attrs(c, &["rising", "falling", "reference_position"], &ctx);
        Ok(Some(urdf_rs::Calibration {
            rising: self.number(c, "rising", &ctx)?,
            falling: self.number(c, "falling", &ctx)?,
        }))
    }

    /// The joint's optional `<dynamics>`, which needs `damping` or `friction`.
    fn dynamics(&mut self, n: Node, what: &str) -> Result<Option<urdf_rs::Dynamics>, RobotError> {
        let Some(d) = first(n, "dynamics") else {
            return Ok(None);
        };
        let ctx = format!("<dynamics> of {what}");
        self.attrs(d, &["damping", "friction"], &ctx);
        let damping = self.number(d, "damping", &ctx)?;
        let friction = self.number(d, "friction", &ctx)?;
        if damping.is_none() && friction.is_none() {
            return Err(self.err(d, format!("{ctx} has neither `damping` nor `friction`")));
        }
        Ok(Some(urdf_rs::Dynamics {
            damping: damping.unwrap_or(0.0),
            friction: friction.unwrap_or(0.0),
        }))
    }

    /// The joint's optional `<mimic>`, which needs `joint`.
    fn mimic(&mut self, n: Node, what: &str) -> Result<Option<urdf_rs::Mimic>, RobotError> {
        let Some(m) = first(n, "mimic") else {
            return Ok(None);
        };
        let ctx = format!("<mimic> of {what}");
        self.attrs(m, &["joint", "multiplier", "offset"], &ctx);
        let joint = m
            .attribute("joint")
            .ok_or_else(|| self.err(m, format!("{ctx} has no `joint` (required)")))?
            .to_string();
        Ok(Some(urdf_rs::Mimic {
            joint,
            multiplier: self.number(m, "multiplier", &ctx)?,
            offset: self.number(m, "offset", &ctx)?,
        }))
    }

    /// The joint's optional `<safety_controller>`, which needs `k_velocity`.
    fn safety_controller(
        &mut self,
        n: Node,
        what: &str,
    ) -> Result<Option<urdf_rs::SafetyController>, RobotError> {
        let Some(s) = first(n, "safety_controller") else {
            return Ok(None);
        };
        let ctx = format!("<safety_controller> of {what}");
        self.attrs(
            s,
            &[
                "soft_lower_limit",
                "soft_upper_limit",
                "k_position",
                "k_velocity",
            ],
            &ctx,
        );
        Ok(Some(urdf_rs::SafetyController {
            soft_lower_limit: self.number(s, "soft_lower_limit", &ctx)?.unwrap_or(0.0),
            soft_upper_limit: self.number(s, "soft_upper_limit", &ctx)?.unwrap_or(0.0),
            k_position: self.number(s, "k_position", &ctx)?.unwrap_or(0.0),
            k_velocity: self.required_number(s, "k_velocity", &ctx)?,
        }))
    }
}

/// A finite decimal number (`inf` and `nan`, which ROS's parser refuses, are refused).
fn parse_number(s: &str) -> Option<f64> {
    s.trim().parse::<f64>().ok().filter(|v| v.is_finite())
}

/// The first child element `<tag>` (no namespace).
fn first<'b, 'input>(n: Node<'b, 'input>, tag: &str) -> Option<Node<'b, 'input>> {
    n.children().find(|c| {
        c.is_element() && c.tag_name().name() == tag && c.tag_name().namespace().is_none()
    })
}

/// Every child element `<tag>` (no namespace).
fn all<'b, 'input>(n: Node<'b, 'input>, tag: &'static str) -> Vec<Node<'b, 'input>> {
    n.children()
        .filter(|c| {
            c.is_element() && c.tag_name().name() == tag && c.tag_name().namespace().is_none()
        })
        .collect()
}
