//! What the runner shows an observer (the rerun recorder, or a test): a static [`Scene`] once,
//! then one [`Frame`] per control step. Plain data, no rerun types, so the runner does not depend
//! on any recording backend.

use crate::state::TruthState;

/// A drawable shape in its own frame. Cylinders, capsules and cones stand along their local z.
#[derive(Debug, Clone, PartialEq)]
pub enum Geometry {
    /// Box with half extents \[m\].
    Cuboid {
        /// Half extents along x, y, z.
        half_extents: [f32; 3],
    },
    /// Sphere.
    Ball {
        /// \[m\]
        radius: f32,
    },
    /// Cylinder along local z.
    Cylinder {
        /// \[m\]
        radius: f32,
        /// \[m\]
        half_height: f32,
    },
    /// Capsule along local z.
    Capsule {
        /// \[m\]
        radius: f32,
        /// Half length of the segment between the cap centres \[m\].
        half_height: f32,
    },
    /// A triangle mesh (cones, hulls, meshes, and a finite patch of a half-space).
    Mesh {
        /// Vertices \[m\].
        vertices: Vec<[f32; 3]>,
        /// Triangles as vertex indices.
        triangles: Vec<[u32; 3]>,
    },
}

/// A shape with a pose (translation, rotation as quaternion x, y, z, w) in its parent frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Placed {
    /// Name (entity path segment).
    pub name: String,
    /// Shape.
    pub geometry: Geometry,
    /// \[m\]
    pub translation: [f32; 3],
    /// Quaternion (x, y, z, w).
    pub rotation: [f32; 4],
}

/// Everything that does not change during a run.
#[derive(Debug, Clone, Default)]
pub struct Scene {
    /// World name.
    pub world: String,
    /// Obstacles in the world frame.
    pub obstacles: Vec<Placed>,
    /// Names of the obstacles that are half-spaces, drawn as a finite patch (a [`Geometry::Mesh`]
    /// in world coordinates that the recording cuts to a low wall on the ground).
    pub half_space_walls: Vec<String>,
    /// Robot links: (link name, its shapes in the link frame).
    pub robot_links: Vec<(String, Vec<Placed>)>,
    /// Safe-set boundaries at zero velocity, as polylines on the ground (name, points).
    pub safe_set_outlines: Vec<(String, Vec<[f32; 3]>)>,
    /// Goal centre and radius \[m\].
    pub goal: ([f32; 2], f32),
    /// Sensor channel names, in measurement order.
    pub channels: Vec<String>,
    /// Estimator labels, in the order of [`Frame::estimates`].
    pub filters: Vec<String>,
    /// Barrier names (safe sets, then obstacles), in the order of [`Frame::barrier_values`] columns.
    pub barriers: Vec<String>,
    /// Attack labels, in the order of [`Frame::attacks_active`].
    pub attacks: Vec<String>,
    /// Per attack (in [`Scene::attacks`] order), the channels it targets.
    pub attack_channels: Vec<Vec<String>>,
    /// The names of the obstacles that move (issue #51), in the order of [`Frame::movers`];
    /// each is drawn in [`Scene::obstacles`] at its start.
    pub movers: Vec<String>,
}

/// One estimator's view at a control step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EstimateView {
    /// x̂ = (p_x, p_y, v_x, v_y).
    pub x: [f64; 4],
    /// Residue norm used by Step 3 (0 for the open-loop estimators).
    pub residue: f64,
    /// V(x̂) of the CLF.
    pub clf: f64,
    /// ‖x − x̂‖ / γ of this filter against the truth (NaN without γ): above 1 the bound of
    /// Theorem 1 that its rows assume does not hold at this step.
    pub error_ratio: f64,
}

/// One sensor channel at a control step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChannelView {
    /// The clean measurement (truth + noise + bias).
    pub clean: f64,
    /// What the controller received after the attacks.
    pub received: f64,
    /// A new sample arrived this step.
    pub fresh: bool,
    /// The residue detector's statistic for this reading: the all-channel filter's normalised
    /// one-step innovation z = (received − c x̂⁻)/√(c P⁻ cᵀ + r), before the update (NaN when
    /// the channel is not in the linear model or not fresh). |z| ≤ 3 is a 3σ detector's "normal".
    pub detector_z: f64,
    /// The controller threw this reading out (non-finite or beyond its plausible range).
    pub rejected: bool,
}

/// One control step.
#[derive(Debug, Clone)]
pub struct Frame<'a> {
    /// Simulation time \[s\].
    pub t: f64,
    /// Control step index.
    pub step: u64,
    /// Ground truth.
    pub truth: &'a TruthState,
    /// Per channel, in [`Scene::channels`] order.
    pub channels: &'a [ChannelView],
    /// Per estimator, in [`Scene::filters`] order.
    pub estimates: &'a [EstimateView],
    /// h(x̂) per estimator (row) and barrier (column), row-major. NaN: out of reach, not
    /// evaluated this step (a world with an active-barrier index, see
    /// [`ftcbf_controller::reach`]: far obstacles are not evaluated, so they are not logged).
    pub barrier_values: &'a [f64],
    /// h(x_true) per barrier. NaN: a far obstacle not evaluated this step (its certified lower
    /// bound is at or above its least value so far; worlds with an active-barrier index only).
    pub barrier_truth: &'a [f64],
    /// The input u = (a_x, a_y) [m/s²].
    pub u: [f64; 2],
    /// Body command (v [m/s], ω [rad/s]) sent to the drive (zero for the linear plant).
    pub body_cmd: [f64; 2],
    /// Which step of the policy decided (`step1`, `clf_relaxed`, `step2`, `step3`, `infeasible`).
    pub decided_by: &'a str,
    /// Why constraints were dropped this step (empty when nothing was dropped).
    pub decision_note: &'a str,
    /// Per attack: active now.
    pub attacks_active: &'a [bool],
    /// Robot link poses in the world frame (link name, translation, quaternion xyzw).
    pub link_poses: &'a [(String, [f32; 3], [f32; 4])],
    /// Collisions and safety violations that started this step.
    pub events: &'a [String],
    /// Each moving obstacle's state at `t` (in [`Scene::movers`] order): its displacement from
    /// its start \[m\] and its velocity \[m/s\], world frame.
    pub movers: &'a [ftcbf_controller::MoverState],
    /// Each moving obstacle as the controller read it at `t` (same order): a tracked mover's
    /// estimate with its error bounds; equal to [`Frame::movers`] for an exact reading.
    pub mover_readings: &'a [ftcbf_controller::MoverState],
    /// Contacts that started this step, with who moved (also in `events`, as text).
    pub contacts: &'a [Contact],
}

/// Who moved when a contact began (issue #51): the robot's guarantee covers its own motion,
/// so a mover walking into the stopped robot is told apart.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ContactCause {
    /// The robot touched an obstacle that stands still.
    Static,
    /// The robot, moving towards a mover (≥ [`crate::summary::STOPPED_SPEED`] towards its
    /// centre), touched it.
    RobotMoving,
    /// A mover walked into the robot while it stood still, or moved only sideways or away
    /// (pushed, or fleeing); `walker` when a walker did.
    MoverIntoStopped {
        /// The mover is a walker.
        walker: bool,
    },
}

impl ContactCause {
    /// Whose contact it is: `"robot"` (static or the robot moving) or `"mover"`.
    pub fn whose(self) -> &'static str {
        match self {
            Self::Static | Self::RobotMoving => "robot",
            Self::MoverIntoStopped { .. } => "mover",
        }
    }
}

/// A contact between the robot and an obstacle that began at one plant tick.
#[derive(Debug, Clone, PartialEq)]
pub struct Contact {
    /// The obstacle's name.
    pub obstacle: String,
    /// Simulation time \[s\].
    pub t: f64,
    /// The robot's position, world frame \[m\].
    pub at: [f64; 2],
    /// Who moved.
    pub cause: ContactCause,
}

/// Receives the scene once and every control step of a run.
pub trait Observer {
    /// Called once before the first step.
    fn scene(&mut self, scene: &Scene);
    /// Called after every control step.
    fn frame(&mut self, frame: &Frame<'_>);
}
