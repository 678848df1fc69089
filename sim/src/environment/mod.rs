//! Environments: obstacles loaded from the files robots already live in (issue #47). A world
//! file's `[environment] sdf = "…"` names a Gazebo SDF world or model file (read by `crate::world::sdf`); what it
//! holds that a ground robot can touch becomes ordinary [`ObstacleSpec`](crate::obstacles::ObstacleSpec)s appended to the
//! world's own `obstacles`, so physics, barriers, planner, `check` and recording take them as
//! they take any other obstacle. [`EnvironmentReport`] says what was kept and what was dropped
//! and why. `[environment] map = "…"` is a ROS occupancy map ([`map`]).

pub mod collada;
pub mod map;
pub mod outline;

pub use map::{MapError, MapField, OccupancyGrid, UnknownCells};

use std::path::PathBuf;

/// Why an SDF element that could be an obstacle is not one.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum DropReason {
    /// Its lowest point is above the top of the robot.
    AboveRobot,
    /// It lies at or below the ground (z ≤ 0), or is a ground plane.
    Ground,
    /// A link with visual geometry and no collision geometry.
    VisualOnly,
    /// A `<plugin>` (code Gazebo runs; nothing here runs it).
    Plugin,
    /// The collision geometry of a model that is not static and carries a `<plugin>`: code
    /// Gazebo runs moves it, nothing here does, so it is not frozen into an obstacle.
    PluginDriven,
    /// An `<actor>` (animated; moving obstacles are not part of an environment).
    Actor,
    /// A `<heightmap>` (terrain, not an obstacle of a ground robot on flat ground).
    Heightmap,
    /// An `<include>` of a Gazebo Fuel URL (nothing is fetched).
    FuelInclude,
    /// Geometry with nothing to collide with (`<empty>`, `<image>`).
    NoGeometry,
}

impl DropReason {
    /// How `check` says it.
    pub fn describe(self) -> &'static str {
        match self {
            DropReason::AboveRobot => "above the robot",
            DropReason::Ground => "the ground (at or below z = 0)",
            DropReason::VisualOnly => "visual only (no collision geometry)",
            DropReason::Plugin => "plugin (not run)",
            DropReason::PluginDriven => "moved by a plugin (not run; left out)",
            DropReason::Actor => "actor (moving; not loaded)",
            DropReason::Heightmap => "heightmap (terrain)",
            DropReason::FuelInclude => "Fuel include (not fetched)",
            DropReason::NoGeometry => "no solid geometry",
        }
    }
}

/// One element that was not made an obstacle.
#[derive(Debug, Clone, PartialEq)]
pub struct Dropped {
    /// Its scoped name (`model::link::collision`, a plugin's `name`, a Fuel URI).
    pub name: String,
    /// Why.
    pub reason: DropReason,
}

/// What an environment file gave: how many obstacles were kept, what was dropped and why, and
/// the loader's warnings (unknown elements with their lines, far-off meshes, …).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct EnvironmentReport {
    /// The file read.
    pub source: PathBuf,
    /// Names of the obstacles made, in order.
    pub kept: Vec<String>,
    /// What was left out.
    pub dropped: Vec<Dropped>,
    /// Non-fatal problems, each naming its file and line where it has one.
    pub warnings: Vec<String>,
    /// The robot height the elements were judged against \[m\] (`None`: every height kept).
    pub robot_height: Option<f64>,
}

impl EnvironmentReport {
    /// The report's lines for `check`: one line of counts, one per drop reason (naming up to
    /// three elements, then "and K more"), then the warnings.
    pub fn lines(&self) -> Vec<String> {
        let mut out = vec![format!(
            "{}: {} obstacles kept, {} elements dropped{}",
            self.source.display(),
            self.kept.len(),
            self.dropped.len(),
            self.robot_height
                .map_or(String::new(), |h| format!(" (robot height {h:.3} m)"))
        )];
        let mut reasons: Vec<DropReason> = self.dropped.iter().map(|d| d.reason).collect();
        reasons.sort();
        reasons.dedup();
        for r in reasons {
            let names: Vec<&str> = self
                .dropped
                .iter()
                .filter(|d| d.reason == r)
                .map(|d| d.name.as_str())
                .collect();
            out.push(format!(
                "  dropped, {}: {} ({})",
                r.describe(),
                names.len(),
                name_list(&names, 3)
            ));
        }
        out.extend(self.warnings.iter().map(|w| format!("  warning: {w}")));
        out
    }
}

/// Up to `max` names, then "and K more".
pub fn name_list(names: &[&str], max: usize) -> String {
    let shown: Vec<&str> = names.iter().take(max).copied().collect();
    let rest = names.len().saturating_sub(max);
    if rest == 0 {
        shown.join(", ")
    } else {
        format!("{} and {rest} more", shown.join(", "))
    }
}

/// Why an environment file cannot be loaded. Each names the file, and the line where there is
/// one.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EnvironmentError {
    /// A file that cannot be read.
    #[error("{path}: cannot read: {message}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        message: String,
    },
    /// Not XML, or not an SDF this loader can use.
    #[error("{path}{}: {message}", .line.map_or(String::new(), |l| format!(":{l}")))]
    Sdf {
        /// The file.
        path: PathBuf,
        /// Line (1-based) of the offending element.
        line: Option<u32>,
        /// What is wrong and what was expected.
        message: String,
    },
}
