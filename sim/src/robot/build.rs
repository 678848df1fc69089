//! From a parsed URDF to a [`RobotDescription`]: links merged along fixed joints, mass
//! properties, collision shapes and visual meshes placed in their bodies' frames, the joint tree
//! checked, the drive wheels found and their colliders made.

use super::*;

pub(super) fn load(
    text: &str,
    origin: &str,
    base_dir: Option<&Path>,
    opts: &LoadOptions,
) -> Result<RobotDescription, RobotError> {
    check_xacro(text, origin)?;
    let parsed = urdf::parse(text, origin)?;
    build(&parsed, origin, base_dir, opts)
}

/// Blanks XML comments, CDATA sections and processing instructions (keeping newlines, so line
/// numbers still count), because text inside them is never markup: a commented
/// `<xacro:include filename="$(find pkg)/…"/>` is not a leftover. Each construct ends at its
/// first terminator (`-->`, `]]>`, `?>`) as XML 1.0 §2.5–2.7 defines; an unterminated one blanks
/// the rest, and the URDF parser then reports the malformed XML.
pub(super) fn mask_non_markup(text: &str) -> String {
    const KINDS: [(&str, &str); 3] = [("<!--", "-->"), ("<![CDATA[", "]]>"), ("<?", "?>")];
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some((start, (_, close))) = KINDS
        .iter()
        .filter_map(|k| rest.find(k.0).map(|i| (i, *k)))
        .min_by_key(|(i, _)| *i)
    {
        out.push_str(&rest[..start]);
        let body = &rest[start..];
        let end = body.find(close).map_or(body.len(), |e| e + close.len());
        out.extend(
            body[..end]
                .chars()
                .map(|c| if c == '\n' { '\n' } else { ' ' }),
        );
        rest = &body[end..];
    }
    out.push_str(rest);
    out
}

/// Rejects xacro leftovers with the line, enclosing element name and attribute. Comments, CDATA
/// and processing instructions are not searched (see [`mask_non_markup`]).
pub(super) fn check_xacro(text: &str, origin: &str) -> Result<(), RobotError> {
    let masked = mask_non_markup(text);
    let text = masked.as_str();
    // `xmlns:xacro` alone is not a leftover: xacro keeps the namespace declaration in its output.
    let markers = ["<xacro:", "${", "$("];
    let Some(pos) = markers.iter().filter_map(|m| text.find(m)).min() else {
        return Ok(());
    };
    let line = text[..pos].matches('\n').count() + 1;
    let rest = &text[pos..];
    let end = rest
        .find(['}', ')', '>', '\n', '"'])
        .map(|e| (e + 1).min(rest.len()))
        .unwrap_or(rest.len().min(40));
    let snippet = rest[..end].trim_end_matches(['"', '\n']).to_string();
    // Enclosing element: the last `<link name=` / `<joint name=` before the position.
    let before = &text[..pos];
    let mut context = String::from("the robot element");
    let last_link = before.rfind("<link");
    let last_joint = before.rfind("<joint");
    let (kind, at) = match (last_link, last_joint) {
        (Some(l), Some(j)) if j > l => ("joint", Some(j)),
        (Some(l), _) => ("link", Some(l)),
        (None, Some(j)) => ("joint", Some(j)),
        (None, None) => ("", None),
    };
    if let Some(at) = at {
        let elem = &text[at..];
        if let Some(n) = elem.find("name=\"") {
            let name_start = n + 6;
            if let Some(name_len) = elem[name_start..].find('"') {
                context = format!("{kind} `{}`", &elem[name_start..name_start + name_len]);
            }
        }
    }
    // Attribute: `attr="...${` on the same element.
    let line_start = before.rfind('\n').map(|i| i + 1).unwrap_or(0);
    let segment = &text[line_start..pos];
    if let Some(q) = segment.rfind("=\"") {
        let attr: String = segment[..q]
            .chars()
            .rev()
            .take_while(|c| c.is_alphanumeric() || *c == '_' || *c == ':')
            .collect::<Vec<_>>()
            .into_iter()
            .rev()
            .collect();
        if !attr.is_empty() && !segment[q + 2..].contains('"') {
            context = format!("{context}, attribute `{attr}`");
        }
    }
    Err(RobotError::Xacro {
        origin: origin.to_string(),
        line,
        snippet,
        context,
    })
}

pub(super) fn iso_from_pose(p: &urdf_rs::Pose) -> Isometry3<f64> {
    let [x, y, z] = p.xyz.0;
    let [r, pi, yw] = p.rpy.0;
    Isometry3::from_parts(
        Translation3::new(x, y, z),
        UnitQuaternion::from_euler_angles(r, pi, yw),
    )
}

/// Mass properties accumulated in a body frame: mass, first moment, inertia about the
/// body-frame origin.
#[derive(Debug, Clone, Copy)]
pub(super) struct MassAcc {
    pub(super) mass: f64,
    pub(super) moment: Vector3<f64>,
    pub(super) inertia_origin: Matrix3<f64>,
}

impl MassAcc {
    fn zero() -> Self {
        Self {
            mass: 0.0,
            moment: Vector3::zeros(),
            inertia_origin: Matrix3::zeros(),
        }
    }
    /// Adds a point-mass-distribution with mass m, centre c and inertia `i_com` (about c,
    /// in a frame rotated by `rot` relative to the body frame).
    fn add(&mut self, m: f64, c: Vector3<f64>, rot: &UnitQuaternion<f64>, i_com: &Matrix3<f64>) {
        let r = rot.to_rotation_matrix();
        let i_body = r.matrix() * i_com * r.matrix().transpose();
        let parallel = m * (Matrix3::identity() * c.dot(&c) - c * c.transpose());
        self.mass += m;
        self.moment += m * c;
        self.inertia_origin += i_body + parallel;
    }
    fn finish(&self) -> (f64, Vector3<f64>, Matrix3<f64>) {
        if self.mass <= 0.0 {
            return (self.mass, Vector3::zeros(), Matrix3::zeros());
        }
        let c = self.moment / self.mass;
        let parallel = self.mass * (Matrix3::identity() * c.dot(&c) - c * c.transpose());
        (self.mass, c, self.inertia_origin - parallel)
    }
}

/// A robot description from a parsed URDF, in phases: the link tree, the walk that merges links
/// over fixed joints into bodies, the links' mass and geometry, the bodies' masses, the drive
/// wheels, the drive limits and the footprint.
pub(super) fn build(
    parsed: &urdf::Parsed,
    origin: &str,
    base_dir: Option<&Path>,
    opts: &LoadOptions,
) -> Result<RobotDescription, RobotError> {
    let cx = Build {
        parsed,
        robot: &parsed.robot,
        origin,
        base_dir,
        opts,
    };
    if cx.robot.links.is_empty() {
        return Err(cx.structure("the URDF has no <link>".into()));
    }
    let tree = cx.link_tree()?;
    let mut kin = cx.walk(&tree)?;
    let (acc, mut warnings) = cx.link_contents(&mut kin)?;
    warnings.append(&mut kin.notes);
    let massless_wheels = cx.body_masses(&mut kin, &acc)?;
    let fixed_wheels = cx.fixed_wheel_joints(&tree, &kin);
    let wheels = find_wheels(
        cx.robot,
        origin,
        &kin.bodies,
        &kin.joints,
        &kin.joint_of_urdf,
        &fixed_wheels,
        opts,
    )?;
    wheel_colliders(&mut kin.bodies, &kin.joints, &wheels);
    cx.massless_wheel_masses(&mut kin, &massless_wheels, &mut warnings)?;
    let (limits, limits_source) = cx.drive_limits(&wheels)?;
    let (footprint_radius, centre_height, height) = cx.footprint(&kin.bodies)?;
    Ok(RobotDescription {
        name: cx.robot.name.clone(),
        origin: origin.to_string(),
        bodies: kin.bodies,
        joints: kin.joints,
        wheels,
        limits,
        limits_source,
        footprint_radius,
        centre_height,
        height,
        warnings,
        xacro_output: None,
    })
}

/// What [`build`] reads and reports against: the parsed file, its origin for messages, the
/// folder meshes resolve from, and the load options.
pub(super) struct Build<'a> {
    pub(super) parsed: &'a urdf::Parsed,
    pub(super) robot: &'a urdf_rs::Robot,
    pub(super) origin: &'a str,
    pub(super) base_dir: Option<&'a Path>,
    pub(super) opts: &'a LoadOptions,
}

/// The links as a tree: index by name, each link's parent joint and child joints, the root.
pub(super) struct LinkTree<'a> {
    pub(super) link_index: HashMap<&'a str, usize>,
    pub(super) parent_joint: Vec<Option<usize>>,
    pub(super) children: Vec<Vec<usize>>,
    pub(super) root: usize,
}

/// Where a link went: its body and its pose in that body.
pub(super) struct LinkInfo {
    pub(super) body: usize,
    pub(super) pose_in_body: Isometry3<f64>,
}

/// The bodies and joints the walk from the root makes.
pub(super) struct Kinematics {
    /// Per link: its body and pose (`None` for a link the walk did not reach).
    pub(super) info: Vec<Option<LinkInfo>>,
    pub(super) bodies: Vec<RobotBody>,
    /// Per body: the URDF joint making it movable (`None` for the root).
    pub(super) body_joint: Vec<Option<usize>>,
    pub(super) joints: Vec<RobotJoint>,
    /// URDF joint index → index in `joints`.
    pub(super) joint_of_urdf: HashMap<usize, usize>,
    /// Bodies of fixed joints driven as wheels because `[robot] wheels` names them.
    pub(super) promoted_bodies: Vec<usize>,
    /// Notes for the warnings (one per promoted joint).
    pub(super) notes: Vec<String>,
}

/// A body holding one link at its origin, with no mass or geometry yet.
pub(super) fn empty_body(link: &str, pose_in_root: Isometry3<f64>) -> RobotBody {
    RobotBody {
        name: link.to_string(),
        links: vec![link.to_string()],
        pose_in_root,
        mass: 0.0,
        com: Vector3::zeros(),
        inertia: Matrix3::zeros(),
        colliders: Vec::new(),
        visuals: Vec::new(),
    }
}

impl Build<'_> {
    fn structure(&self, message: String) -> RobotError {
        RobotError::Structure {
            origin: self.origin.to_string(),
            message,
        }
    }

    fn invalid(&self, what: String) -> RobotError {
        RobotError::InvalidValue {
            origin: self.origin.to_string(),
            what,
        }
    }

    /// `joint `x` (line N)`, for messages.
    fn jname(&self, ji: usize) -> String {
        format!(
            "joint `{}` (line {})",
            self.robot.joints[ji].name, self.parsed.joint_lines[ji]
        )
    }

    /// The link tree: every joint names existing links, no link has two parent joints, and
    /// exactly one link has none (the root).
    fn link_tree(&self) -> Result<LinkTree<'_>, RobotError> {
        let robot = self.robot;
        // Names are unique (the reader refuses duplicates).
        let link_index: HashMap<&str, usize> = robot
            .links
            .iter()
            .enumerate()
            .map(|(i, l)| (l.name.as_str(), i))
            .collect();
        let mut parent_joint: Vec<Option<usize>> = vec![None; robot.links.len()];
        let mut children: Vec<Vec<usize>> = vec![Vec::new(); robot.links.len()];
        let find = |ji: usize, which: &str, link: &str| {
            link_index.get(link).copied().ok_or_else(|| {
                self.structure(format!(
                    "{} names {which} link `{link}`, which does not exist",
                    self.jname(ji)
                ))
            })
        };
        for (ji, j) in robot.joints.iter().enumerate() {
            let p = find(ji, "parent", &j.parent.link)?;
            let c = find(ji, "child", &j.child.link)?;
            if let Some(first) = parent_joint[c] {
                return Err(self.structure(format!(
                    "link `{}` is the child of two joints, {} and {}",
                    j.child.link,
                    self.jname(first),
                    self.jname(ji)
                )));
            }
            parent_joint[c] = Some(ji);
            children[p].push(ji);
        }
        let roots: Vec<usize> = (0..robot.links.len())
            .filter(|&i| parent_joint[i].is_none())
            .collect();
        if roots.is_empty() {
            // Every link has a parent joint: following parents from any link must cycle.
            return Err(self.structure(format!(
                "no root link: the joints form a cycle ({})",
                joint_cycle(0, &parent_joint, robot, &|ji| self.jname(ji))
            )));
        }
        if roots.len() != 1 {
            let names: Vec<String> = roots
                .iter()
                .map(|&i| {
                    format!(
                        "`{}` (line {})",
                        robot.links[i].name, self.parsed.link_lines[i]
                    )
                })
                .collect();
            return Err(self.structure(format!(
                "the links must form one tree with a single root; roots found: {}",
                names.join(", ")
            )));
        }
        Ok(LinkTree {
            link_index,
            parent_joint,
            children,
            root: roots[0],
        })
    }

    /// Walks the tree from the root: a fixed joint merges its child link into the parent's
    /// body, any other joint starts a body of its own. Refuses loops, unsupported joint types
    /// and links the walk cannot reach.
    fn walk(&self, tree: &LinkTree) -> Result<Kinematics, RobotError> {
        let robot = self.robot;
        let root = tree.root;
        let mut info: Vec<Option<LinkInfo>> = (0..robot.links.len()).map(|_| None).collect();
        info[root] = Some(LinkInfo {
            body: 0,
            pose_in_body: Isometry3::identity(),
        });
        let mut kin = Kinematics {
            info,
            bodies: vec![empty_body(&robot.links[root].name, Isometry3::identity())],
            body_joint: vec![None],
            joints: Vec::new(),
            joint_of_urdf: HashMap::new(),
            promoted_bodies: Vec::new(),
            notes: Vec::new(),
        };
        let mut stack = vec![root];
        let mut visited = 1usize;
        while let Some(l) = stack.pop() {
            let (lbody, lpose) = match &kin.info[l] {
                Some(i) => (i.body, i.pose_in_body),
                None => continue,
            };
            for &ji in &tree.children[l] {
                let j = &robot.joints[ji];
                let c = tree.link_index[j.child.link.as_str()];
                if kin.info[c].is_some() {
                    return Err(
                        self.structure(format!("{} closes a kinematic loop", self.jname(ji)))
                    );
                }
                visited += 1;
                self.joint(&mut kin, ji, c, lbody, lpose)?;
                stack.push(c);
            }
        }
        if visited != robot.links.len() {
            // One root and one parent per link: a link the walk missed hangs off a cycle.
            let missed = (0..robot.links.len())
                .find(|&i| kin.info[i].is_none())
                .unwrap_or(0);
            return Err(self.structure(format!(
                "link `{}` is not connected to the root `{}`: the joints form a cycle ({})",
                robot.links[missed].name,
                robot.links[root].name,
                joint_cycle(missed, &tree.parent_joint, robot, &|ji| self.jname(ji))
            )));
        }
        Ok(kin)
    }

    /// URDF joint `ji` from a link of body `lbody` (at `lpose` in it) to link `c`: merges `c`
    /// into the body over a fixed joint, else makes `c` a body of its own and the joint a
    /// [`RobotJoint`]. A fixed joint that `[robot] wheels` names is driven as continuous.
    fn joint(
        &self,
        kin: &mut Kinematics,
        ji: usize,
        c: usize,
        lbody: usize,
        lpose: Isometry3<f64>,
    ) -> Result<(), RobotError> {
        let j = &self.robot.joints[ji];
        let origin_iso = iso_from_pose(&j.origin);
        // Fixed joints a world names as drive wheels (`[robot] wheels`): some published files
        // describe their drive wheels with fixed joints (a display model: Adept's Pioneer 3-DX
        // fixes `left_hub_joint` with `<!-- type="continuous" -->`); those are driven as
        // continuous joints.
        let named_wheel = self
            .opts
            .wheel_joints
            .as_ref()
            .is_some_and(|(l, r)| *l == j.name || *r == j.name);
        let promoted = j.joint_type == urdf_rs::JointType::Fixed && named_wheel;
        let kind = match j.joint_type {
            urdf_rs::JointType::Fixed if !promoted => {
                kin.info[c] = Some(LinkInfo {
                    body: lbody,
                    pose_in_body: lpose * origin_iso,
                });
                kin.bodies[lbody].links.push(j.child.link.clone());
                return Ok(());
            }
            urdf_rs::JointType::Continuous | urdf_rs::JointType::Fixed => JointKind::Continuous,
            urdf_rs::JointType::Revolute => JointKind::Revolute {
                lower: j.limit.lower,
                upper: j.limit.upper,
            },
            urdf_rs::JointType::Prismatic => JointKind::Prismatic {
                lower: j.limit.lower,
                upper: j.limit.upper,
            },
            ref other => {
                return Err(self.structure(format!(
                    "{} has type {other:?}; only fixed, continuous, revolute and \
                     prismatic joints are supported",
                    self.jname(ji)
                )))
            }
        };
        let axis_v = if promoted {
            self.promoted_joint_axis(ji, c, &mut kin.notes)?
        } else {
            Vector3::from(j.axis.xyz.0)
        };
        let axis = Unit::try_new(axis_v, 1e-9)
            .ok_or_else(|| self.invalid(format!("{}: <axis xyz> is zero", self.jname(ji))))?;
        let frame_in_parent = lpose * origin_iso;
        let pose_in_root = kin.bodies[lbody].pose_in_root * frame_in_parent;
        let b = kin.bodies.len();
        kin.bodies.push(empty_body(&j.child.link, pose_in_root));
        kin.body_joint.push(Some(ji));
        if promoted {
            kin.promoted_bodies.push(b);
        }
        kin.joint_of_urdf.insert(ji, kin.joints.len());
        kin.joints.push(RobotJoint {
            name: j.name.clone(),
            kind,
            parent: lbody,
            child: b,
            frame_in_parent,
            axis,
        });
        kin.info[c] = Some(LinkInfo {
            body: b,
            pose_in_body: Isometry3::identity(),
        });
        Ok(())
    }

    /// The axis of fixed joint `ji` (child link `c`) driven as a wheel, with a note saying
    /// where it came from; an error when the file gives none.
    fn promoted_joint_axis(
        &self,
        ji: usize,
        c: usize,
        notes: &mut Vec<String>,
    ) -> Result<Vector3<f64>, RobotError> {
        let j = &self.robot.joints[ji];
        let (axis_v, from) =
            promoted_axis(self.parsed, ji, &self.robot.links[c]).ok_or_else(|| {
                self.invalid(format!(
                    "{} is `fixed`, and [robot] wheels names it as a drive wheel: \
                     to drive it as a continuous joint it needs an <axis xyz> or \
                     a <cylinder> collision on link `{}` to take the axis from{}",
                    self.jname(ji),
                    j.child.link,
                    wheel_above(self.robot, &j.name)
                ))
            })?;
        // Rounded to 1e-6 (a cylinder turned by rpy -1.57079635 gives 2.7e-9 components);
        // `+ 0.0` prints -0 as 0.
        let short = |x: f64| (x * 1e6).round() / 1e6 + 0.0;
        notes.push(format!(
            "{}: {} is `fixed` in the URDF; [robot] wheels names it, so it \
             is driven as a continuous wheel joint about ({}, {}, {}) ({from})",
            self.origin,
            self.jname(ji),
            short(axis_v.x),
            short(axis_v.y),
            short(axis_v.z)
        ));
        Ok(axis_v)
    }

    /// Each reached link's inertial summed into its body's mass accumulator, its collisions
    /// added to the body's colliders and its visuals to the body's visuals. Returns the
    /// accumulators and the warnings so far (the parser's, then visuals that could not load).
    fn link_contents(
        &self,
        kin: &mut Kinematics,
    ) -> Result<(Vec<MassAcc>, Vec<String>), RobotError> {
        let mut acc = vec![MassAcc::zero(); kin.bodies.len()];
        let mut warnings = self.parsed.warnings.clone();
        for (li, link) in self.robot.links.iter().enumerate() {
            let Some(li_info) = &kin.info[li] else {
                continue;
            };
            let (b, pose) = (li_info.body, li_info.pose_in_body);
            self.add_inertial(link, pose, &mut acc[b])?;
            for col in &link.collision {
                let cpose = pose * iso_from_pose(&col.origin);
                let shape = collision_shape(
                    &col.geometry,
                    &link.name,
                    self.origin,
                    self.base_dir,
                    self.opts,
                )?;
                kin.bodies[b].colliders.push(RobotCollider {
                    link: link.name.clone(),
                    pose_in_body: cpose,
                    shape,
                    is_wheel: false,
                });
            }
            for vis in &link.visual {
                let vpose = pose * iso_from_pose(&vis.origin);
                match visual_mesh(&vis.geometry, &link.name, vpose, self.base_dir, self.opts) {
                    Ok(Some(v)) => kin.bodies[b].visuals.push(v),
                    Ok(None) => {}
                    Err(w) => warnings.push(format!("{}: {w}", self.origin)),
                }
            }
        }
        Ok((acc, warnings))
    }

    /// Adds `link`'s `<inertial>` (the link at `pose` in its body) to `acc`, after checking
    /// that its mass and inertia are finite and non-negative.
    fn add_inertial(
        &self,
        link: &urdf_rs::Link,
        pose: Isometry3<f64>,
        acc: &mut MassAcc,
    ) -> Result<(), RobotError> {
        let inertial = &link.inertial;
        let m = inertial.mass.value;
        if !m.is_finite() || m < 0.0 {
            return Err(self.invalid(format!(
                "link `{}`: <mass value> must be a finite number ≥ 0, got {m}",
                link.name
            )));
        }
        if m > 0.0 {
            let i = &inertial.inertia;
            let vals = [i.ixx, i.ixy, i.ixz, i.iyy, i.iyz, i.izz];
            if vals.iter().any(|v| !v.is_finite()) || i.ixx < 0.0 || i.iyy < 0.0 || i.izz < 0.0 {
                return Err(self.invalid(format!(
                    "link `{}`: <inertia> must be finite with ixx, iyy, izz ≥ 0",
                    link.name
                )));
            }
            let i_com = Matrix3::new(
                i.ixx, i.ixy, i.ixz, i.ixy, i.iyy, i.iyz, i.ixz, i.iyz, i.izz,
            );
            let io = pose * iso_from_pose(&inertial.origin);
            acc.add(m, io.translation.vector, &io.rotation, &i_com);
        }
        Ok(())
    }

    /// Each body's mass, centre of mass and inertia from its accumulator; an error for a body
    /// without mass, except a promoted wheel (returned: it gets its mass from its cylinder once
    /// the wheels are known).
    fn body_masses(&self, kin: &mut Kinematics, acc: &[MassAcc]) -> Result<Vec<usize>, RobotError> {
        // A promoted wheel whose links carry no <inertial> (the file fixes them to the chassis
        // and gives them no mass of their own) gets its mass once its wheel cylinder is known.
        let mut massless_wheels: Vec<usize> = Vec::new();
        for (b, a) in acc.iter().enumerate() {
            let (m, c, i) = a.finish();
            if m == 0.0 && kin.promoted_bodies.contains(&b) {
                massless_wheels.push(b);
                continue;
            }
            if m <= 0.0 {
                let joint = match kin.body_joint[b] {
                    Some(ji) => self.robot.joints[ji].name.clone(),
                    None => "root".to_string(),
                };
                return Err(RobotError::NonPositiveMass {
                    origin: self.origin.to_string(),
                    link: kin.bodies[b].name.clone(),
                    joint,
                    mass: m,
                });
            }
            kin.bodies[b].mass = m;
            kin.bodies[b].com = c;
            kin.bodies[b].inertia = i;
        }
        Ok(massless_wheels)
    }

    /// Fixed joints on the chassis shaped like drive wheels (a lateral axis, a wheel-like
    /// collision on the child link), named when no wheel is found.
    fn fixed_wheel_joints(&self, tree: &LinkTree, kin: &Kinematics) -> Vec<String> {
        let robot = self.robot;
        robot
            .joints
            .iter()
            .enumerate()
            .filter(|(ji, j)| {
                let (p, c) = (
                    tree.link_index[j.parent.link.as_str()],
                    tree.link_index[j.child.link.as_str()],
                );
                let Some(parent) = kin.info[p].as_ref().filter(|i| i.body == 0) else {
                    return false;
                };
                let wheel_like = robot.links[c].collision.iter().any(|col| {
                    matches!(
                        col.geometry,
                        urdf_rs::Geometry::Cylinder { .. } | urdf_rs::Geometry::Mesh { .. }
                    )
                });
                let rotation = (parent.pose_in_body * iso_from_pose(&j.origin)).rotation;
                j.joint_type == urdf_rs::JointType::Fixed
                    && wheel_like
                    && promoted_axis(self.parsed, *ji, &robot.links[c])
                        .is_some_and(|(a, _)| (rotation * a.normalize()).y.abs() >= 0.99)
            })
            .map(|(ji, _)| self.jname(ji))
            .collect()
    }

    /// A promoted wheel body without mass of its own gets the mass of its collision cylinder
    /// at [`WHEEL_DENSITY`], with a warning; an error when it has no cylinder.
    fn massless_wheel_masses(
        &self,
        kin: &mut Kinematics,
        massless_wheels: &[usize],
        warnings: &mut Vec<String>,
    ) -> Result<(), RobotError> {
        for &b in massless_wheels {
            let body = &mut kin.bodies[b];
            let cylinder = body.colliders.iter().find_map(|c| match c.shape {
                CollisionShape::Cylinder {
                    radius,
                    half_length,
                } if c.is_wheel => Some((c.pose_in_body, radius, 2.0 * half_length)),
                _ => None,
            });
            let Some((pose, r, width)) = cylinder else {
                return Err(RobotError::NonPositiveMass {
                    origin: self.origin.to_string(),
                    link: body.name.clone(),
                    joint: kin.body_joint[b]
                        .map(|ji| self.robot.joints[ji].name.clone())
                        .unwrap_or_default(),
                    mass: 0.0,
                });
            };
            let m = WHEEL_DENSITY * PI * r * r * width;
            let across = m * (3.0 * r * r + width * width) / 12.0;
            let i_com = Matrix3::from_diagonal(&Vector3::new(across, across, m * r * r / 2.0));
            let mut a = MassAcc::zero();
            a.add(m, pose.translation.vector, &pose.rotation, &i_com);
            let (m, c, i) = a.finish();
            (body.mass, body.com, body.inertia) = (m, c, i);
            warnings.push(format!(
                "{}: wheel link `{}` has no <inertial> (the URDF fixes it to the chassis); \
                 it is given the mass of its collision cylinder (radius {r:.4} m, width {width:.4} m) \
                 at {WHEEL_DENSITY} kg/m³: {m:.4} kg",
                self.origin, body.name
            ));
        }
        Ok(())
    }

    /// The drive limits: the options' override (positive and finite), else from the URDF.
    fn drive_limits(
        &self,
        wheels: &DriveWheels,
    ) -> Result<(DriveLimits, LimitsSource), RobotError> {
        match self.opts.limits {
            Some(l) => {
                let ok = |x: f64| x.is_finite() && x > 0.0;
                if !(ok(l.v_max) && ok(l.omega_max) && ok(l.wheel_speed_max)) {
                    return Err(self.invalid(format!(
                        "drive limits override must be positive and finite, got {l:?}"
                    )));
                }
                Ok((l, LimitsSource::Explicit))
            }
            None => derive_limits(self.parsed, self.origin, wheels),
        }
    }

    /// The footprint: the circumscribed radius of the collision geometry in the plane, and the
    /// middle height of it (from the ground up) and its top; an error when there is no
    /// collision geometry.
    fn footprint(&self, bodies: &[RobotBody]) -> Result<(f64, f64, f64), RobotError> {
        let mut r_max: f64 = 0.0;
        let (mut z_min, mut z_max) = (f64::INFINITY, f64::NEG_INFINITY);
        for body in bodies {
            for c in &body.colliders {
                let to_root = body.pose_in_root * c.pose_in_body;
                for p in c.shape.bounding_points() {
                    let q = to_root * p;
                    r_max = r_max.max(q.x.hypot(q.y));
                    z_min = z_min.min(q.z);
                    z_max = z_max.max(q.z);
                }
            }
        }
        if !z_min.is_finite() {
            return Err(self.structure("the robot has no collision geometry".into()));
        }
        Ok((r_max, 0.5 * (z_min.max(0.0) + z_max), z_max))
    }
}

/// Marks the wheel bodies' colliders as wheels; a wheel measured from its mesh rolls on the
/// cylinder of that extent instead (the mesh's convex hull is a polygon and would roll bumpily).
pub(super) fn wheel_colliders(
    bodies: &mut [RobotBody],
    joints: &[RobotJoint],
    wheels: &DriveWheels,
) {
    for w in wheels.all() {
        let axis = joints[w.joint].axis;
        let body = &mut bodies[w.body];
        if wheel_size(body, axis).is_some_and(|s| s.from_mesh) {
            if let Some(m) = mesh_extent(body, axis) {
                let z_to_axis = UnitQuaternion::rotation_between(&Vector3::z(), &axis)
                    .unwrap_or_else(|| UnitQuaternion::from_axis_angle(&Vector3::x_axis(), PI));
                let link = body
                    .colliders
                    .iter()
                    .find(|c| matches!(c.shape, CollisionShape::Mesh { .. }))
                    .map(|c| c.link.clone())
                    .unwrap_or_else(|| body.name.clone());
                body.colliders
                    .retain(|c| !matches!(c.shape, CollisionShape::Mesh { .. }));
                body.colliders.push(RobotCollider {
                    link,
                    pose_in_body: Isometry3::from_parts(
                        Translation3::from(axis.into_inner() * m.mid),
                        z_to_axis,
                    ),
                    shape: CollisionShape::Cylinder {
                        radius: m.radius,
                        half_length: m.width / 2.0,
                    },
                    is_wheel: true,
                });
            }
        }
        for c in &mut body.colliders {
            c.is_wheel = true;
        }
    }
}

/// The axis a `fixed` joint named as a drive wheel turns about, and where it came from: the
/// `<axis xyz>` written on it (ROS ignores it on a fixed joint; a file that once had the joint
/// continuous keeps it), else the axis of the child link's first `<cylinder>` collision.
pub(super) fn promoted_axis(
    parsed: &urdf::Parsed,
    joint: usize,
    child: &urdf_rs::Link,
) -> Option<(Vector3<f64>, String)> {
    if let Some(xyz) = parsed.fixed_axes.get(joint).copied().flatten() {
        let v = Vector3::from(xyz);
        if v.norm() > 1e-9 {
            return Some((
                v,
                "its <axis xyz>, which ROS ignores on a fixed joint".to_string(),
            ));
        }
    }
    child.collision.iter().find_map(|col| {
        matches!(col.geometry, urdf_rs::Geometry::Cylinder { .. }).then(|| {
            (
                iso_from_pose(&col.origin).rotation * Vector3::z(),
                format!("the axis of link `{}`'s <cylinder> collision", child.name),
            )
        })
    })
}

/// The joints met following parent joints up from link `start` until a link repeats, as
/// "joint `a` (line 3) → joint `b` (line 9)" (the cycle itself, in child-to-parent order).
pub(super) fn joint_cycle(
    start: usize,
    parent_joint: &[Option<usize>],
    robot: &urdf_rs::Robot,
    jname: &dyn Fn(usize) -> String,
) -> String {
    let index = |name: &str| robot.links.iter().position(|l| l.name == name);
    let mut seen: Vec<usize> = Vec::new();
    let mut path: Vec<usize> = Vec::new();
    let mut link = start;
    while !seen.contains(&link) {
        seen.push(link);
        let Some(ji) = parent_joint[link] else {
            break;
        };
        path.push(ji);
        match index(&robot.joints[ji].parent.link) {
            Some(p) => link = p,
            None => break,
        }
    }
    // Keep the part of the path from the first visit of the repeated link.
    let from = seen.iter().position(|&l| l == link).unwrap_or(0);
    path[from.min(path.len())..]
        .iter()
        .map(|&ji| jname(ji))
        .collect::<Vec<_>>()
        .join(" → ")
}

pub(super) fn collision_shape(
    g: &urdf_rs::Geometry,
    link: &str,
    origin: &str,
    base_dir: Option<&Path>,
    opts: &LoadOptions,
) -> Result<CollisionShape, RobotError> {
    let bad = |what: String| RobotError::InvalidValue {
        origin: origin.to_string(),
        what: format!("link `{link}` collision: {what}"),
    };
    let pos = |x: f64| x.is_finite() && x > 0.0;
    Ok(match g {
        urdf_rs::Geometry::Box { size } => {
            let s = size.0;
            if !s.iter().all(|v| pos(*v)) {
                return Err(bad(format!("<box size> must be positive, got {s:?}")));
            }
            CollisionShape::Box {
                half_extents: [s[0] / 2.0, s[1] / 2.0, s[2] / 2.0],
            }
        }
        urdf_rs::Geometry::Cylinder { radius, length } => {
            if !pos(*radius) || !pos(*length) {
                return Err(bad(format!(
                    "<cylinder radius length> must be positive, got {radius}, {length}"
                )));
            }
            CollisionShape::Cylinder {
                radius: *radius,
                half_length: length / 2.0,
            }
        }
        urdf_rs::Geometry::Capsule { radius, length } => {
            let length_ok = length.is_finite() && *length >= 0.0;
            if !pos(*radius) || !length_ok {
                return Err(bad(format!(
                    "<capsule radius length> must be positive, got {radius}, {length}"
                )));
            }
            CollisionShape::Capsule {
                radius: *radius,
                half_length: length / 2.0,
            }
        }
        urdf_rs::Geometry::Sphere { radius } => {
            if !pos(*radius) {
                return Err(bad(format!(
                    "<sphere radius> must be positive, got {radius}"
                )));
            }
            CollisionShape::Sphere { radius: *radius }
        }
        urdf_rs::Geometry::Mesh { filename, scale } => {
            let scale = scale.map(|s| s.0).unwrap_or([1.0; 3]);
            if !scale.iter().all(|v| v.is_finite() && *v != 0.0) {
                return Err(bad(format!(
                    "mesh scale must be finite and non-zero, got {scale:?}"
                )));
            }
            let mesh_err = |message: String| RobotError::CollisionMesh {
                origin: origin.to_string(),
                link: link.to_string(),
                filename: filename.clone(),
                message,
            };
            let path = resolve_mesh_path(filename, base_dir, &opts.package_paths, &opts.packages)
                .ok_or_else(|| mesh_err(not_found(filename, opts)))?;
            let (vertices, indices) =
                read_mesh(&path).map_err(|m| mesh_err(format!("{}: {m}", path.display())))?;
            let vertices = vertices
                .into_iter()
                .map(|v| [v[0] * scale[0], v[1] * scale[1], v[2] * scale[2]])
                .collect();
            CollisionShape::Mesh { vertices, indices }
        }
    })
}

/// The STL mesh of a `<visual>` (`Ok(None)` for primitives, which the collision shapes already
/// show); a missing or unreadable file is a warning (`Err`), never a load error.
pub(super) fn visual_mesh(
    g: &urdf_rs::Geometry,
    link: &str,
    pose_in_body: Isometry3<f64>,
    base_dir: Option<&Path>,
    opts: &LoadOptions,
) -> Result<Option<RobotVisual>, String> {
    let urdf_rs::Geometry::Mesh { filename, scale } = g else {
        return Ok(None);
    };
    let what = |m: &str| format!("visual mesh `{filename}` of link `{link}` {m} (ignored)");
    let path = resolve_mesh_path(filename, base_dir, &opts.package_paths, &opts.packages)
        .ok_or_else(|| what("not found"))?;
    let scale = scale.map(|s| s.0).unwrap_or([1.0; 3]);
    if !scale.iter().all(|v| v.is_finite() && *v != 0.0) {
        return Err(what(&format!("has a bad scale {scale:?}")));
    }
    let (vertices, indices) =
        read_mesh(&path).map_err(|m| what(&format!("unreadable ({}: {m})", path.display())))?;
    Ok(Some(RobotVisual {
        link: link.to_string(),
        pose_in_body,
        vertices: vertices
            .into_iter()
            .map(|v| [v[0] * scale[0], v[1] * scale[1], v[2] * scale[2]])
            .collect(),
        indices,
    }))
}
