//! The drive wheels and their limits: which joints drive, their radius and width (from the
//! collision cylinder or the mesh), the sides, and the limits from the URDF or the maker's figures.

use super::*;

/// Size of a wheel body about its joint axis.
#[derive(Debug, Clone, Copy)]
pub(super) struct WheelSize {
    pub(super) radius: f64,
    pub(super) from_mesh: bool,
}

/// Extent of a body's collision meshes about an axis through the body origin.
#[derive(Debug, Clone, Copy)]
pub(super) struct MeshExtent {
    /// Largest distance of a vertex from the axis \[m\].
    pub(super) radius: f64,
    /// Extent along the axis \[m\].
    pub(super) width: f64,
    /// Middle of that extent, along the axis \[m\].
    pub(super) mid: f64,
}

/// The extent of every collision mesh of `body` about `axis` (body frame; for a wheel body the
/// body frame is the joint frame, so the axis passes through its origin).
pub(super) fn mesh_extent(body: &RobotBody, axis: Unit<Vector3<f64>>) -> Option<MeshExtent> {
    let (mut r2, mut lo, mut hi) = (0.0f64, f64::INFINITY, f64::NEG_INFINITY);
    for c in &body.colliders {
        let CollisionShape::Mesh { vertices, .. } = &c.shape else {
            continue;
        };
        for v in vertices {
            let p = c.pose_in_body * Point3::new(v[0], v[1], v[2]);
            let a = p.coords.dot(&axis);
            r2 = r2.max((p.coords - axis.into_inner() * a).norm_squared());
            lo = lo.min(a);
            hi = hi.max(a);
        }
    }
    (lo <= hi && r2 > 0.0).then(|| MeshExtent {
        radius: r2.sqrt(),
        width: hi - lo,
        mid: 0.5 * (lo + hi),
    })
}

/// A wheel's radius: its `<cylinder>` collision's, else the extent of its collision meshes
/// about the joint axis.
pub(super) fn wheel_size(body: &RobotBody, axis: Unit<Vector3<f64>>) -> Option<WheelSize> {
    if let Some(radius) = body.colliders.iter().find_map(|c| match c.shape {
        CollisionShape::Cylinder { radius, .. } => Some(radius),
        _ => None,
    }) {
        return Some(WheelSize {
            radius,
            from_mesh: false,
        });
    }
    let m = mesh_extent(body, axis)?;
    (m.width > 0.0).then_some(WheelSize {
        radius: m.radius,
        from_mesh: true,
    })
}

/// Density [kg/m³] that gives a promoted wheel without `<inertial>` its mass from its
/// collision cylinder: water's, the default MuJoCo uses to infer inertia from geometry.
pub(super) const WHEEL_DENSITY: f64 = 1000.0;

/// Distance from the root frame's x axis below which a wheel cannot be assigned to a side \[m\].
pub(super) const CENTRE_LINE_TOLERANCE: f64 = 1e-3;

/// One candidate drive wheel, measured in the root frame.
#[derive(Debug, Clone, Copy)]
pub(super) struct WheelCandidate {
    pub(super) joint: usize,
    pub(super) radius: f64,
    pub(super) from_mesh: bool,
    pub(super) position: Vector3<f64>,
    pub(super) forward_sign: f64,
    pub(super) effort: Option<f64>,
}

/// The drive wheels, in phases: the candidate joints (those `[robot] wheels` names, else the
/// wheel-like continuous joints on the chassis), each measured in the root frame, split into
/// left and right, and checked for equal radii and a separation.
pub(super) fn find_wheels(
    robot: &urdf_rs::Robot,
    origin: &str,
    bodies: &[RobotBody],
    joints: &[RobotJoint],
    joint_of_urdf: &HashMap<usize, usize>,
    fixed_wheels: &[String],
    opts: &LoadOptions,
) -> Result<DriveWheels, RobotError> {
    let search = WheelSearch {
        robot,
        origin,
        bodies,
        joints,
    };
    let werr = |message: String| search.error(message);
    let candidates = search.candidates(joint_of_urdf, fixed_wheels, opts)?;
    let wheels = candidates
        .iter()
        .map(|&k| search.measure(k))
        .collect::<Result<Vec<_>, _>>()?;
    let (left, right) = match &opts.wheel_joints {
        // Named: the caller says which is which; it must agree with the geometry.
        Some(_) => {
            let (a, b) = (wheels[0], wheels[1]);
            if a.position.y <= b.position.y {
                return Err(werr(format!(
                    "the left wheel joint `{}` is not on the +y side of the right one `{}`",
                    joints[a.joint].name, joints[b.joint].name
                )));
            }
            (vec![a], vec![b])
        }
        None => group_sides(&wheels, joints, &werr)?,
    };
    search.check_radii(&wheels)?;
    let separation = search.separation(&left, &right)?;
    let radius = wheels.iter().map(|w| w.radius).sum::<f64>() / wheels.len() as f64;
    let mk = |w: &WheelCandidate| Wheel {
        joint_name: joints[w.joint].name.clone(),
        joint: w.joint,
        body: joints[w.joint].child,
        forward_sign: w.forward_sign,
        effort_limit: w.effort,
    };
    Ok(DriveWheels {
        left: left.iter().map(mk).collect(),
        right: right.iter().map(mk).collect(),
        geometry: WheelGeometry { radius, separation },
    })
}

/// What [`find_wheels`] measures: the robot's bodies and joints, and the file for messages.
pub(super) struct WheelSearch<'a> {
    pub(super) robot: &'a urdf_rs::Robot,
    pub(super) origin: &'a str,
    pub(super) bodies: &'a [RobotBody],
    pub(super) joints: &'a [RobotJoint],
}

impl WheelSearch<'_> {
    fn error(&self, message: String) -> RobotError {
        RobotError::Wheels {
            origin: self.origin.to_string(),
            message,
        }
    }

    /// The wheel size of joint `k`'s child body, from its collision geometry.
    fn size(&self, k: usize) -> Option<WheelSize> {
        wheel_size(&self.bodies[self.joints[k].child], self.joints[k].axis)
    }

    /// Joint `k`'s frame in the root frame.
    fn frame_in_root(&self, k: usize) -> Isometry3<f64> {
        let j = &self.joints[k];
        self.bodies[j.parent].pose_in_root * j.frame_in_parent
    }

    /// The joints as "`a`, `b`", for messages.
    fn names(&self, ks: &mut dyn Iterator<Item = usize>) -> String {
        ks.map(|k| format!("`{}`", self.joints[k].name))
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// The candidate wheel joints (indices into the joints): the two `[robot] wheels` names,
    /// else every continuous joint on the chassis with a lateral axis and a wheel-like
    /// collision. An error when fewer than two are found, naming fixed joints that look like
    /// wheels.
    fn candidates(
        &self,
        joint_of_urdf: &HashMap<usize, usize>,
        fixed_wheels: &[String],
        opts: &LoadOptions,
    ) -> Result<Vec<usize>, RobotError> {
        // Lateral in the root frame: a drive wheel's axle, not a swivel's vertical axis.
        let lateral = |k: usize| {
            (self.frame_in_root(k).rotation * self.joints[k].axis.into_inner())
                .y
                .abs()
                >= 0.99
        };
        let candidates: Vec<usize> = match &opts.wheel_joints {
            Some((l, r)) => {
                let mut v = Vec::new();
                for name in [l, r] {
                    let ji = self
                        .robot
                        .joints
                        .iter()
                        .position(|j| &j.name == name)
                        .ok_or_else(|| self.error(format!("no joint named `{name}`")))?;
                    let k = *joint_of_urdf.get(&ji).ok_or_else(|| {
                        self.error(format!("joint `{name}` is not a joint a wheel can turn on"))
                    })?;
                    v.push(k);
                }
                v
            }
            // Continuous joints on the chassis (the root body) with a lateral axis and a
            // cylinder or mesh collision; a caster's wheel hangs from its swivel, not from the
            // chassis.
            None => self
                .joints
                .iter()
                .enumerate()
                .filter(|&(k, j)| {
                    matches!(j.kind, JointKind::Continuous)
                        && j.parent == 0
                        && lateral(k)
                        && self.size(k).is_some()
                })
                .map(|(k, _)| k)
                .collect(),
        };
        if candidates.len() < 2 {
            let fixed = if fixed_wheels.is_empty() {
                String::new()
            } else {
                format!(
                    "; the URDF fixes {} to the chassis, shaped like wheels (a display model \
                     describes its drive wheels so): name two of them in [robot] wheels to drive \
                     them as continuous joints",
                    fixed_wheels.join(", ")
                )
            };
            return Err(self.error(format!(
                "expected 2 (differential drive) or 4 or more (skid steer) continuous joints on the \
                 chassis with a lateral axis whose child link has a <cylinder> or <mesh> collision, \
                 found {} [{}]; name the wheel joints explicitly if the URDF has others{fixed}",
                candidates.len(),
                self.names(&mut candidates.iter().copied())
            )));
        }
        Ok(candidates)
    }

    /// Candidate joint `k` measured in the root frame: its radius, position, which way it turns
    /// forward and its effort limit. An error for a prismatic joint, a wheel without a
    /// cylinder or mesh collision, or an axis that is not lateral.
    fn measure(&self, k: usize) -> Result<WheelCandidate, RobotError> {
        let j = &self.joints[k];
        if matches!(j.kind, JointKind::Prismatic { .. }) {
            return Err(self.error(format!("joint `{}` is prismatic", j.name)));
        }
        let WheelSize { radius, from_mesh } = self.size(k).ok_or_else(|| {
            self.error(format!(
                "wheel link of joint `{}` has no <cylinder> or <mesh> collision to read the \
                 radius from{}",
                j.name,
                wheel_above(self.robot, &j.name)
            ))
        })?;
        let frame_root = self.frame_in_root(k);
        let axis_root = frame_root.rotation * j.axis.into_inner();
        if axis_root.y.abs() < 0.99 {
            return Err(self.error(format!(
                "joint `{}`: the wheel axis in the root frame is {:?}, not lateral (±y)",
                j.name,
                axis_root.as_slice()
            )));
        }
        let urdf_j = self.robot.joints.iter().find(|u| u.name == j.name);
        let effort = urdf_j
            .map(|u| u.limit.effort)
            .filter(|e| e.is_finite() && *e > 0.0);
        Ok(WheelCandidate {
            joint: k,
            radius,
            from_mesh,
            position: frame_root.translation.vector,
            forward_sign: axis_root.y.signum(),
            effort,
        })
    }

    /// The wheels' radii agree: cylinders within 0.1 mm, a radius measured from a mesh within
    /// 1 % (a mesh is a polygon, and left and right meshes are often exported separately).
    fn check_radii(&self, wheels: &[WheelCandidate]) -> Result<(), RobotError> {
        let tolerance = if wheels.iter().any(|w| w.from_mesh) {
            (0.01 * wheels[0].radius).max(1e-4)
        } else {
            1e-4
        };
        match wheels
            .iter()
            .find(|w| (w.radius - wheels[0].radius).abs() > tolerance)
        {
            Some(w) => Err(self.error(format!(
                "the wheels have different radii (`{}` {} m, `{}` {} m)",
                self.joints[wheels[0].joint].name,
                wheels[0].radius,
                self.joints[w.joint].name,
                w.radius
            ))),
            None => Ok(()),
        }
    }

    /// The distance in the plane between the left and right wheels (between the sides'
    /// centroids for a skid steer); an error when it is zero.
    fn separation(
        &self,
        left: &[WheelCandidate],
        right: &[WheelCandidate],
    ) -> Result<f64, RobotError> {
        let centroid = |side: &[WheelCandidate]| {
            side.iter().map(|w| w.position).sum::<Vector3<f64>>() / side.len() as f64
        };
        let separation = if left.len() == 1 {
            (left[0].position.xy() - right[0].position.xy()).norm()
        } else {
            (centroid(left).xy() - centroid(right).xy()).norm()
        };
        if separation <= 0.0 || !separation.is_finite() {
            return Err(self.error(format!(
                "the wheel joints {} and {} are at the same place",
                self.names(&mut left.iter().map(|w| w.joint)),
                self.names(&mut right.iter().map(|w| w.joint))
            )));
        }
        Ok(separation)
    }
}

/// When joint `name`'s parent link is wheel-shaped (a `<cylinder>` or `<mesh>` collision) and is
/// itself fixed by another joint, "; its parent link … : name that joint instead" (Adept's
/// Pioneer 3-DX fixes the tyre `left_wheel` to the hub `left_hub`, which holds the collision, and
/// the hub to the chassis).
pub(super) fn wheel_above(robot: &urdf_rs::Robot, name: &str) -> String {
    let Some(j) = robot.joints.iter().find(|u| u.name == name) else {
        return String::new();
    };
    let wheel_like = robot
        .links
        .iter()
        .find(|l| l.name == j.parent.link)
        .is_some_and(|l| {
            l.collision.iter().any(|c| {
                matches!(
                    c.geometry,
                    urdf_rs::Geometry::Cylinder { .. } | urdf_rs::Geometry::Mesh { .. }
                )
            })
        });
    let above = robot
        .joints
        .iter()
        .find(|u| u.child.link == j.parent.link && u.joint_type == urdf_rs::JointType::Fixed);
    match above {
        Some(u) if wheel_like => format!(
            "; its parent link `{}` has one and is fixed by joint `{}`: name that joint instead",
            j.parent.link, u.name
        ),
        _ => String::new(),
    }
}

/// Splits automatically found wheels into (left, right) by the side of the root frame's x axis
/// their joint origins lie on, each side sorted front to back. Errors name the joints.
#[allow(clippy::type_complexity)]
pub(super) fn group_sides(
    wheels: &[WheelCandidate],
    joints: &[RobotJoint],
    werr: &dyn Fn(String) -> RobotError,
) -> Result<(Vec<WheelCandidate>, Vec<WheelCandidate>), RobotError> {
    let describe = |side: &[WheelCandidate]| {
        side.iter()
            .map(|w| format!("`{}` (y = {:+.4} m)", joints[w.joint].name, w.position.y))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let centre: Vec<WheelCandidate> = wheels
        .iter()
        .copied()
        .filter(|w| w.position.y.abs() < CENTRE_LINE_TOLERANCE)
        .collect();
    if !centre.is_empty() {
        return Err(werr(format!(
            "ambiguous wheel layout: {} on the robot's centre line (|y| < {} m), so neither \
             left nor right; name the two drive wheel joints explicitly",
            describe(&centre),
            CENTRE_LINE_TOLERANCE
        )));
    }
    let front_to_back = |mut v: Vec<WheelCandidate>| {
        v.sort_by(|a, b| b.position.x.total_cmp(&a.position.x));
        v
    };
    let left = front_to_back(
        wheels
            .iter()
            .copied()
            .filter(|w| w.position.y > 0.0)
            .collect(),
    );
    let right = front_to_back(
        wheels
            .iter()
            .copied()
            .filter(|w| w.position.y < 0.0)
            .collect(),
    );
    if left.len() != right.len() || left.is_empty() {
        return Err(werr(format!(
            "odd wheel layout: {} wheel(s) on the left [{}] and {} on the right [{}]; a \
             differential drive needs one wheel per side and a skid-steer robot the same number \
             on each side; name the two drive wheel joints explicitly if the others are passive",
            left.len(),
            describe(&left),
            right.len(),
            describe(&right)
        )));
    }
    Ok((left, right))
}

/// Limits from the wheel joints' `<limit velocity>`; when a wheel joint has none, the maker's
/// published limits for a robot of this name ([`MAKER_LIMITS`]); else an error naming the joint
/// and its line.
pub(super) fn derive_limits(
    parsed: &urdf::Parsed,
    origin: &str,
    wheels: &DriveWheels,
) -> Result<(DriveLimits, LimitsSource), RobotError> {
    let robot = &parsed.robot;
    let g = wheels.geometry;
    let mut w_max = f64::INFINITY;
    for w in wheels.all() {
        let ji = robot.joints.iter().position(|j| j.name == w.joint_name);
        let v = ji.map(|k| robot.joints[k].limit.velocity).unwrap_or(0.0);
        if !(v.is_finite() && v > 0.0) {
            if let Some(m) = MAKER_LIMITS.iter().find(|m| m.robot_name == robot.name) {
                let limits = DriveLimits {
                    v_max: m.v_max,
                    omega_max: m.omega_max,
                    wheel_speed_max: m.v_max / g.radius,
                };
                return Ok((limits, LimitsSource::Maker(m)));
            }
            let line = ji
                .map(|k| format!(" (line {})", parsed.joint_lines[k]))
                .unwrap_or_default();
            return Err(RobotError::InvalidValue {
                origin: origin.to_string(),
                what: format!(
                    "wheel joint `{}`{line} has no <limit velocity> (rad/s) to derive the drive \
                     limits from, and robot `{}` is none of those with published limits ({}); \
                     add one or give [robot] limits in the world",
                    w.joint_name,
                    robot.name,
                    MAKER_LIMITS
                        .iter()
                        .map(|m| m.robot_name)
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            });
        }
        w_max = w_max.min(v);
    }
    Ok((
        DriveLimits {
            v_max: g.radius * w_max,
            omega_max: 2.0 * g.radius * w_max / g.separation,
            wheel_speed_max: w_max,
        },
        LimitsSource::WheelJoints,
    ))
}
