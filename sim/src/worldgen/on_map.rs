//! Worlds drawn on an occupancy map (`ftcbf gen --map FILE.yaml`, issue #47 item 6): the map is
//! the scene, written into each file as `[environment] map = "…"` (relative to the output
//! directory, as a world file's paths are), and each world is a start and a goal drawn from its
//! free cells, a room's width to a few rooms apart, that the project's planner joins with
//! [`SPARE`] to spare. The map is read once; the cells a start or goal may take (free, and
//! clear of blocked cells by the largest robot footprint and [`SPARE`] by the map's distance
//! field, a lower bound) are listed once, in row order, so a draw is an index and the same seed
//! gives the same pairs.

use std::path::{Path, PathBuf};

use rand::Rng;

use super::layout::Layout;
use super::text::dec;
use super::{reach_among, relative_path, GenError, Route, MAX_DRAWS, SPARE};
use crate::environment::{OccupancyGrid, UnknownCells};
use crate::obstacles::{Obstacle, ObstacleSpec, ShapeSpec};
use crate::robot::RobotDescription;

/// The straight-line distance between a drawn start and goal \[m\]: from across a room to a
/// few rooms apart, which a robot at 0.22 m/s covers within one run.
pub const PAIR_DISTANCE: (f64, f64) = (1.0, 5.0);

/// An occupancy map the generator draws worlds on.
#[derive(Debug, Clone)]
pub(crate) struct MapScene {
    /// The map as a world file loads it (`[environment] map`, unknown cells blocked).
    obstacle: Obstacle,
    /// The `map` key as written: the file relative to the output directory.
    pub key: String,
    /// The file's name, for the header.
    file_name: String,
    /// Width and height in cells, and the cell size \[m\].
    size: (usize, usize, f64),
    /// Centres of the free cells a start or goal may take \[m\], rounded to centimetres.
    candidates: Vec<[f64; 2]>,
}

impl MapScene {
    /// Reads the map at `path`; `footprint` is the largest robot footprint radius \[m\].
    pub fn load(path: &Path, out_dir: &Path, footprint: f64) -> Result<Self, GenError> {
        let err = |message: String| GenError::Map {
            path: path.to_path_buf(),
            message,
        };
        let grid = OccupancyGrid::load(path).map_err(|e| err(e.to_string()))?;
        let abs = std::path::absolute(path).unwrap_or_else(|_| PathBuf::from(path));
        let spec = ObstacleSpec {
            name: "map".into(),
            position: [0.0; 3],
            rpy: [0.0; 3],
            shape: ShapeSpec::OccupancyMap {
                file: abs.clone(),
                unknown: UnknownCells::Obstacle,
            },
            motion: None,
            tracker: None,
        };
        let obstacle = Obstacle::from_spec(&spec, None).map_err(|e| err(e.to_string()))?;
        let field = obstacle
            .map_field()
            .ok_or_else(|| err("not an occupancy map".into()))?;
        let need = footprint + SPARE;
        let mut candidates = Vec::new();
        for j in 0..grid.height {
            for i in 0..grid.width {
                if grid.cell(i, j).blocked(UnknownCells::Obstacle) {
                    continue;
                }
                let c = grid.cell_centre(i, j);
                let p = [dec(c[0], 2), dec(c[1], 2)];
                if field.blocked_cell_at(p).is_none() && field.signed_distance(p).0 >= need {
                    candidates.push(p);
                }
            }
        }
        if candidates.len() < 2 {
            return Err(err(format!(
                "fewer than two free cells are {need:.3} m clear of blocked cells (the largest \
                 robot footprint and the {SPARE} m spare): no start and goal can be drawn"
            )));
        }
        Ok(Self {
            obstacle,
            key: relative_path(out_dir, &abs)
                .to_string_lossy()
                .replace('\\', "/"),
            file_name: path.file_name().map_or_else(
                || path.display().to_string(),
                |n| n.to_string_lossy().into(),
            ),
            size: (grid.width, grid.height, grid.resolution),
            candidates,
        })
    }

    /// Draws start/goal pairs until the planner joins one for `robot` (a goal of
    /// `goal_radius`), at most [`MAX_DRAWS`] times: the scene (no obstacles of its own: the
    /// map is the file's `[environment]`), its reach and the draws it took. `None` when no
    /// draw was reachable.
    pub fn draw_reachable<R: Rng>(
        &self,
        rng: &mut R,
        robot: &RobotDescription,
        goal_radius: f64,
    ) -> Option<(Layout, Route, usize)> {
        let n = self.candidates.len();
        for draw in 1..=MAX_DRAWS {
            let start = self.candidates[rng.random_range(0..n)];
            let goal = self.candidates[rng.random_range(0..n)];
            let d = (goal[0] - start[0]).hypot(goal[1] - start[1]);
            if !(PAIR_DISTANCE.0..=PAIR_DISTANCE.1).contains(&d) {
                continue;
            }
            let obstacles = std::slice::from_ref(&self.obstacle);
            if let Ok(r) = reach_among(obstacles, robot, start, goal, goal_radius, SPARE) {
                let (w, h, res) = self.size;
                let summary = format!(
                    "a start and a goal {d:.2} m apart on the occupancy map {} ({w} × {h} cells \
                     of {res} m; unknown cells blocked), joined by a {:.2} m path",
                    self.file_name, r.length
                );
                let layout = Layout {
                    obstacles: Vec::new(),
                    start,
                    goal,
                    summary,
                };
                return Some((layout, r, draw));
            }
        }
        None
    }
}
