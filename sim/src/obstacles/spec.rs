//! An obstacle as the world file writes it: [`ObstacleSpec`], its `shape` ([`ShapeSpec`],
//! tagged by `kind`), a mesh's scale and the `repeat` key.

use super::*;

/// One obstacle as written in a world file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObstacleSpec {
    /// Name used in logs, collision reports and barrier names.
    pub name: String,
    /// Position of the obstacle frame, world frame \[m\].
    #[serde(default)]
    pub position: [f64; 3],
    /// Roll, pitch, yaw of the obstacle frame \[rad\].
    #[serde(default)]
    pub rpy: [f64; 3],
    /// The shape in the obstacle frame.
    pub shape: ShapeSpec,
    /// How the obstacle moves (issue #51); absent: it stands still.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub motion: Option<MotionSpec>,
    /// An obstacle sensor that detects a moving obstacle's centre (issue #51); absent: the
    /// controller reads the mover's state exactly. See [`crate::movers::tracked`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tracker: Option<TrackerSpec>,
}

/// A moving obstacle's detector and its filter (`obstacles[i].tracker`): detections of the
/// obstacle's centre, world frame, at `rate` Hz with white Gaussian noise of `position_std` m
/// per axis, fed to a constant-velocity Kalman filter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrackerSpec {
    /// Standard deviation of a detection's noise per axis \[m\].
    pub position_std: f64,
    /// Detection rate \[Hz\] (at most the control rate).
    pub rate: f64,
    /// Standard deviation of the white acceleration the filter's gain is designed for
    /// \[m/s²\]; default: the mover's acceleration bound, or its speed bound per second for a
    /// scripted path (whose acceleration bound is 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub accel_std: Option<f64>,
    /// A declared attack on the detections (the threat model covers it only when declared).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub attack: Option<TrackerAttackSpec>,
}

/// A bias added to a tracker's detections in a time window (`obstacles[i].tracker.attack`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrackerAttackSpec {
    /// Offset added to each detection, world frame \[m\].
    pub bias: [f64; 2],
    /// Window start \[s\] (default 0).
    #[serde(default)]
    pub start: f64,
    /// Window end \[s\], exclusive; absent: to the end of the run.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub end: Option<f64>,
}

/// What `[repeat]` a waypoint path does after its last point (`motion.repeat`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RepeatSpec {
    /// Back to the obstacle's own position and round again (default).
    #[default]
    Loop,
    /// Back along the same points, and forth again.
    Reverse,
    /// Stop at the last point.
    Once,
}

crate::spec::tagged::kind_tagged! {
/// How an obstacle moves, in the world's x–y plane (it keeps its height and orientation).
/// See [`crate::movers`].
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum MotionSpec via MotionByKind {
    /// Along `points` (after the obstacle's own position) at `speed`.
    Waypoints {
        /// Points to move through, world frame \[m\].
        points: Vec<[f64; 2]>,
        /// Speed along the path \[m/s\].
        speed: f64,
        /// After the last point: `loop` (default), `reverse` or `once`.
        #[serde(default)]
        repeat: RepeatSpec,
        /// Time the motion starts \[s\] (default 0).
        #[serde(default)]
        start: f64,
    },
    /// At a constant velocity from the obstacle's own position.
    Velocity {
        /// \[m/s\], world frame.
        velocity: [f64; 2],
    },
    /// A walker (social force, [`crate::movers::Walker`]) heading for `goals` in turn.
    Walker {
        /// Goals, world frame \[m\].
        goals: Vec<[f64; 2]>,
        /// Desired speed \[m/s\] (each trial draws the walker's own within ±20 %).
        speed: f64,
    },
}
}

crate::spec::tagged::kind_tagged! {
/// Obstacle shapes. Cylinders, capsules and cones stand along the obstacle frame's z axis.
/// Written as a table tagged by `kind`, read through `spec::tagged` so that an error names
/// the key inside the table.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum ShapeSpec via ShapeByKind {
    /// Box.
    Cuboid {
        /// Half extents along x, y, z \[m\].
        half_extents: [f64; 3],
    },
    /// Sphere.
    Ball {
        /// \[m\]
        radius: f64,
    },
    /// Cylinder along z.
    Cylinder {
        /// \[m\]
        radius: f64,
        /// Half of the height \[m\].
        half_height: f64,
    },
    /// Capsule along z (`half_height` of the cylindrical part).
    Capsule {
        /// \[m\]
        radius: f64,
        /// \[m\]
        half_height: f64,
    },
    /// Cone along z, apex at +half_height.
    Cone {
        /// Base radius \[m\].
        radius: f64,
        /// \[m\]
        half_height: f64,
    },
    /// Convex hull of points (obstacle frame) \[m\].
    ConvexHull {
        /// At least 4 non-coplanar points.
        points: Vec<[f64; 3]>,
    },
    /// Solid half-space behind the plane through `position` with outward `normal`.
    HalfSpace {
        /// Outward normal (obstacle frame), any non-zero length.
        normal: [f64; 3],
    },
    /// An occupancy map (`environment.map`): built by the world loader from the map's files,
    /// never written in `[[obstacles]]`.
    #[serde(skip_deserializing)]
    OccupancyMap {
        /// map_server's YAML file, relative to the world file's directory.
        file: PathBuf,
        /// Whether unknown cells are obstacles.
        unknown: crate::environment::UnknownCells,
    },
    /// Triangle mesh given inline or as an STL file.
    TriMesh {
        /// Vertices (obstacle frame) \[m\].
        #[serde(default)]
        vertices: Vec<[f64; 3]>,
        /// Triangles as vertex indices.
        #[serde(default)]
        indices: Vec<[u32; 3]>,
        /// STL file (instead of vertices/indices), relative to the world file's directory.
        #[serde(default)]
        file: Option<PathBuf>,
        /// Scale applied to the file's vertices (default 1): one factor, or one per axis
        /// `[sx, sy, sz]` as SDF's `<mesh><scale>` writes it.
        #[serde(default)]
        scale: Option<MeshScale>,
    },
}
}

/// A mesh file's scale: one factor for every axis, or one per axis (`[sx, sy, sz]`, obstacle
/// frame; a negative factor mirrors the mesh, as SDF allows).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(untagged)]
pub enum MeshScale {
    /// The same factor on x, y and z.
    Uniform(f64),
    /// Factors on x, y and z.
    PerAxis([f64; 3]),
}

impl MeshScale {
    /// The factors on x, y and z.
    pub fn factors(self) -> [f64; 3] {
        match self {
            MeshScale::Uniform(s) => [s; 3],
            MeshScale::PerAxis(s) => s,
        }
    }
}

impl<'de> Deserialize<'de> for MeshScale {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Raw {
            One(f64),
            Three(Vec<f64>),
        }
        let expected = "expected a number or three numbers [sx, sy, sz]";
        match Raw::deserialize(d).map_err(|_| serde::de::Error::custom(expected))? {
            Raw::One(s) => Ok(MeshScale::Uniform(s)),
            Raw::Three(v) => <[f64; 3]>::try_from(v.as_slice())
                .map(MeshScale::PerAxis)
                .map_err(|_| {
                    serde::de::Error::custom(format!("{expected}, found {} numbers", v.len()))
                }),
        }
    }
}

impl ShapeSpec {
    /// The `kind` tag as written in a world file.
    pub fn kind(&self) -> &'static str {
        match self {
            ShapeSpec::Cuboid { .. } => "cuboid",
            ShapeSpec::Ball { .. } => "ball",
            ShapeSpec::Cylinder { .. } => "cylinder",
            ShapeSpec::Capsule { .. } => "capsule",
            ShapeSpec::Cone { .. } => "cone",
            ShapeSpec::ConvexHull { .. } => "convex_hull",
            ShapeSpec::HalfSpace { .. } => "half_space",
            ShapeSpec::TriMesh { .. } => "tri_mesh",
            ShapeSpec::OccupancyMap { .. } => "occupancy_map",
        }
    }
}
