//! A path from the start to the goal around the declared obstacles, for the safety filter's
//! nominal tracker (`[goal] plan`, on by default with `form = "safety_filter"`).
//!
//! Each leg (start → waypoint → … → goal) is kept straight when it has line of sight; otherwise
//! an A* search (the `pathfinding` crate's) on an 8-connected grid (cell `resolution`, default
//! 5 cm) finds a path through cells whose clearance — the signed distance of the robot disc to
//! the nearest obstacle, half-spaces included — is at least `inflate` (the obstacle barrier
//! margin plus a corridor of 8 cm by default, so the tracker does not ask the safety filter to
//! cut corners). The grid path is then shortened by line of sight (string pulling). Clearances
//! are evaluated lazily, only for the cells the search visits, and the plan is made once per
//! run.
//!
//! Closed-form safe sets (half-planes in the state, ellipses) are not obstacles to the planner:
//! they constrain the state, and the safety filter keeps them.
//!
//! **Bounded work.** A plan makes at most [`PlannerConfig::max_evaluations`] clearance
//! evaluations (line-of-sight samples, grid cells the search visits, string pulling) and ends
//! with [`BudgetExceeded`], naming the leg, when it would need more: a leg kilometres long with
//! an obstacle across it has a grid of 10¹⁰ cells, whose search would run for minutes.

use std::cell::{Cell as Counter, RefCell};
use std::cmp::Ordering;
use std::collections::HashMap;

use pathfinding::directed::astar::astar;

/// Planner settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlannerConfig {
    /// Required clearance of the robot disc along the path \[m\].
    pub inflate: f64,
    /// Grid cell \[m\].
    pub resolution: f64,
    /// How far beyond the leg's end points the grid reaches \[m\].
    pub border: f64,
    /// Spacing of the line-of-sight samples \[m\].
    pub sample: f64,
    /// The most clearance evaluations one plan may make, over all its legs.
    pub max_evaluations: u64,
}

/// [`PlannerConfig::max_evaluations`] by default: 10⁶ (a grid of 1,000 × 1,000 cells, 50 m
/// square at 5 cm, searched in full; some 100 MB for the search's maps).
pub const DEFAULT_MAX_EVALUATIONS: u64 = 1_000_000;

/// A plan that would need more clearance work than its budget.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error(
    "planning leg {leg} (from ({:.3}, {:.3}) to ({:.3}, {:.3})) around the obstacles needs more than {limit} {}, the planner's limit",
    from[0], from[1], to[0], to[1],
    if *.queries { "obstacle distance queries" } else { "clearance evaluations" }
)]
pub struct BudgetExceeded {
    /// The leg (0: start → first stop).
    pub leg: usize,
    /// Where the leg starts \[m\].
    pub from: [f64; 2],
    /// Where it ends \[m\].
    pub to: [f64; 2],
    /// The budget.
    pub limit: u64,
    /// The budget counts obstacle distance queries ([`plan_with_cost`]), not evaluations.
    pub queries: bool,
}

impl Default for PlannerConfig {
    fn default() -> Self {
        Self {
            inflate: 0.10,
            resolution: 0.05,
            border: 2.0,
            sample: 0.02,
            max_evaluations: DEFAULT_MAX_EVALUATIONS,
        }
    }
}

/// A planned path.
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    /// The points to pass after the start, the goal last \[m\].
    pub points: Vec<[f64; 2]>,
    /// Legs that had no collision-free grid path and were left straight.
    pub unplanned_legs: usize,
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

/// How much less than its clearance a sample may trust for its neighbours \[m\]: the clearance is
/// a distance (1-Lipschitz) computed in f32 by parry (errors ~1e-6 m), so samples within
/// `clearance − need − slack` of a sample that passes pass as well.
const LIPSCHITZ_SLACK: f64 = 1e-3;

/// Whether the segment a–b keeps at least min(inflate, clearance at its end points) clearance
/// at its samples (every `sample` metres). A sample with clearance c to spare vouches for the
/// samples within c − need − [`LIPSCHITZ_SLACK`] of it, which are skipped: the answer is the
/// one every sample would give, and a long leg in open space takes a few evaluations instead
/// of one per `sample`.
fn line_of_sight(
    a: [f64; 2],
    b: [f64; 2],
    clear: &dyn Fn([f64; 2]) -> f64,
    c: &PlannerConfig,
) -> bool {
    let need = c.inflate.min(clear(a)).min(clear(b)) - 1e-9;
    let length = dist(a, b);
    let n = (length / c.sample).ceil().max(1.0) as usize;
    let spacing = length / n as f64;
    let mut k = 0;
    while k <= n {
        let t = k as f64 / n as f64;
        let here = clear([a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]);
        if here.is_nan() || here < need {
            return false;
        }
        let spare = (here - need - LIPSCHITZ_SLACK) / spacing;
        let skip = if spare >= 1.0 {
            // saturating: ∞ (no obstacle, or a zero-length leg) ends the walk
            spare.min(n as f64) as usize
        } else {
            0
        };
        k += 1 + skip;
    }
    true
}

/// The cost of a grid path for the A* search: its length \[m\], and a tie-break key that only
/// the heuristic carries (the cell itself; steps add none). Ordered by length, then by key, so
/// of the open cells with equal f = g + h the search expands the smallest cell first: the order
/// is deterministic, whatever the heap's internal order.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Cost {
    length: f64,
    key: Cell,
}

/// A grid cell (column, row) from the grid's origin.
type Cell = (i64, i64);

impl Cost {
    fn step(length: f64) -> Self {
        Self {
            length,
            key: (0, 0),
        }
    }
}

impl std::ops::Add for Cost {
    type Output = Self;
    fn add(self, o: Self) -> Self {
        Self {
            length: self.length + o.length,
            key: (self.key.0 + o.key.0, self.key.1 + o.key.1),
        }
    }
}

impl pathfinding::num_traits::Zero for Cost {
    fn zero() -> Self {
        Self::step(0.0)
    }
    fn is_zero(&self) -> bool {
        self.length == 0.0 && self.key == (0, 0)
    }
}

impl Eq for Cost {}

impl Ord for Cost {
    fn cmp(&self, o: &Self) -> Ordering {
        self.length
            .total_cmp(&o.length)
            .then_with(|| self.key.cmp(&o.key))
    }
}

impl PartialOrd for Cost {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}

/// The 8 neighbour offsets, in the order the search tries them.
const NEIGHBOURS: [Cell; 8] = [
    (1, 0),
    (-1, 0),
    (0, 1),
    (0, -1),
    (1, 1),
    (1, -1),
    (-1, 1),
    (-1, -1),
];

/// A* (the `pathfinding` crate's) from `a` to `b` on the grid; `None` when no free path exists
/// in the grid's bounds. Cells are free when their centre's clearance is at least `inflate`
/// (evaluated once per cell, on first visit); the start and goal cells always are. A diagonal
/// step needs both cells beside it free (no corner cutting).
fn grid_path(
    a: [f64; 2],
    b: [f64; 2],
    clear: &dyn Fn([f64; 2]) -> f64,
    c: &PlannerConfig,
) -> Option<Vec<[f64; 2]>> {
    let r = c.resolution;
    let origin = [a[0].min(b[0]) - c.border, a[1].min(b[1]) - c.border];
    let nx = (((a[0] - b[0]).abs() + 2.0 * c.border) / r).ceil() as i64;
    let ny = (((a[1] - b[1]).abs() + 2.0 * c.border) / r).ceil() as i64;
    let cell_of = |p: [f64; 2]| {
        (
            ((p[0] - origin[0]) / r).round() as i64,
            ((p[1] - origin[1]) / r).round() as i64,
        )
    };
    let centre = |q: Cell| [origin[0] + q.0 as f64 * r, origin[1] + q.1 as f64 * r];
    let (start, goal) = (cell_of(a), cell_of(b));
    let free_cache: RefCell<HashMap<Cell, bool>> = RefCell::default();
    let free = |q: Cell| -> bool {
        if q == start || q == goal {
            return true;
        }
        if q.0 < 0 || q.1 < 0 || q.0 > nx || q.1 > ny {
            return false;
        }
        *free_cache
            .borrow_mut()
            .entry(q)
            .or_insert_with(|| clear(centre(q)) >= c.inflate)
    };
    let successors = |&cell: &Cell| {
        NEIGHBOURS.iter().filter_map(move |&(dx, dy)| {
            let q = (cell.0 + dx, cell.1 + dy);
            let diagonal = dx != 0 && dy != 0;
            let corner_free = || free((cell.0 + dx, cell.1)) && free((cell.0, cell.1 + dy));
            let step = if diagonal {
                r * std::f64::consts::SQRT_2
            } else {
                r
            };
            (free(q) && (!diagonal || corner_free())).then_some((q, Cost::step(step)))
        })
    };
    let heuristic = |&q: &Cell| {
        let (dx, dy) = ((q.0 - goal.0).abs() as f64, (q.1 - goal.1).abs() as f64);
        Cost {
            length: r * (dx.max(dy) + (std::f64::consts::SQRT_2 - 1.0) * dx.min(dy)),
            key: q,
        }
    };
    let (cells, _) = astar(&start, successors, heuristic, |&q| q == goal)?;
    let mut pts: Vec<[f64; 2]> = cells.into_iter().map(centre).collect();
    pts[0] = a;
    let last = pts.len() - 1;
    pts[last] = b;
    Some(pts)
}
/// Shortens a grid path by line of sight.
fn string_pull(
    pts: &[[f64; 2]],
    clear: &dyn Fn([f64; 2]) -> f64,
    c: &PlannerConfig,
) -> Vec<[f64; 2]> {
    let mut out = Vec::new();
    let mut i = 0;
    while i + 1 < pts.len() {
        let mut j = pts.len() - 1;
        while j > i + 1 && !line_of_sight(pts[i], pts[j], clear, c) {
            j -= 1;
        }
        out.push(pts[j]);
        i = j;
    }
    out
}

/// Plans start → waypoints → goal around the obstacles whose robot-disc clearance \[m\] is
/// `clear(p)`, within [`PlannerConfig::max_evaluations`] evaluations of `clear`.
pub fn plan(
    start: [f64; 2],
    waypoints: &[[f64; 2]],
    goal: [f64; 2],
    clear: &dyn Fn([f64; 2]) -> f64,
    cfg: &PlannerConfig,
) -> Result<Plan, BudgetExceeded> {
    let costed = |p: [f64; 2]| (clear(p), 1);
    plan_inner(start, waypoints, goal, &costed, cfg, false)
}

/// [`plan`] with a clearance that reports its own cost (the obstacle distance queries it
/// made): [`PlannerConfig::max_evaluations`] bounds the total cost instead of the number of
/// evaluations, so a clearance that skips far obstacles buys a longer search.
pub fn plan_with_cost(
    start: [f64; 2],
    waypoints: &[[f64; 2]],
    goal: [f64; 2],
    clear: &dyn Fn([f64; 2]) -> (f64, u64),
    cfg: &PlannerConfig,
) -> Result<Plan, BudgetExceeded> {
    plan_inner(start, waypoints, goal, clear, cfg, true)
}

fn plan_inner(
    start: [f64; 2],
    waypoints: &[[f64; 2]],
    goal: [f64; 2],
    clear: &dyn Fn([f64; 2]) -> (f64, u64),
    cfg: &PlannerConfig,
    queries: bool,
) -> Result<Plan, BudgetExceeded> {
    let used = Counter::new(0u64);
    let exhausted = Counter::new(false);
    // Past the budget every point is blocked: line of sight fails at its first sample, the
    // search finds no new free cell and ends, and the leg is reported below.
    let counted = |p: [f64; 2]| {
        if used.get() >= cfg.max_evaluations {
            exhausted.set(true);
            return f64::NEG_INFINITY;
        }
        let (c, cost) = clear(p);
        used.set(used.get() + cost.max(1));
        c
    };
    let clear: &dyn Fn([f64; 2]) -> f64 = &counted;
    let mut stops = waypoints.to_vec();
    stops.push(goal);
    let mut points = Vec::new();
    let mut from = start;
    let mut unplanned_legs = 0;
    for (leg, &to) in stops.iter().enumerate() {
        if line_of_sight(from, to, clear, cfg) {
            points.push(to);
        } else {
            match grid_path(from, to, clear, cfg) {
                Some(p) => points.extend(string_pull(&p, clear, cfg)),
                None => {
                    unplanned_legs += 1;
                    points.push(to);
                }
            }
        }
        if exhausted.get() {
            return Err(BudgetExceeded {
                leg,
                from,
                to,
                limit: cfg.max_evaluations,
                queries,
            });
        }
        from = to;
    }
    Ok(Plan {
        points,
        unplanned_legs,
    })
}

/// For a leg with no route at `cfg.inflate` clearance: the route that keeps the most
/// clearance (bisected to 1/64 of `cfg.inflate` between 0 and it) and that clearance, or
/// `None` when no route keeps the robot disc clear of the obstacles at all. The budget is
/// [`PlannerConfig::max_evaluations`] over all the searches, in the clearance's cost.
#[allow(clippy::type_complexity)]
pub fn widest_route(
    from: [f64; 2],
    to: [f64; 2],
    clear: &dyn Fn([f64; 2]) -> (f64, u64),
    cfg: &PlannerConfig,
) -> Result<Option<(Vec<[f64; 2]>, f64)>, BudgetExceeded> {
    let spent = Counter::new(0u64);
    let costed = |p: [f64; 2]| {
        let (c, n) = clear(p);
        spent.set(spent.get() + n.max(1));
        (c, n)
    };
    let attempt = |inflate: f64| -> Result<Option<Vec<[f64; 2]>>, BudgetExceeded> {
        let left = cfg.max_evaluations.saturating_sub(spent.get()).max(1);
        let c = PlannerConfig {
            inflate,
            max_evaluations: left,
            ..*cfg
        };
        let p = plan_inner(from, &[], to, &costed, &c, true).map_err(|e| BudgetExceeded {
            limit: cfg.max_evaluations,
            ..e
        })?;
        Ok((p.unplanned_legs == 0).then_some(p.points))
    };
    let Some(mut best) = attempt(0.0)? else {
        return Ok(None);
    };
    let (mut lo, mut hi) = (0.0, cfg.inflate);
    for _ in 0..6 {
        let mid = 0.5 * (lo + hi);
        match attempt(mid)? {
            Some(p) => {
                best = p;
                lo = mid;
            }
            None => hi = mid,
        }
    }
    let mut path = vec![from];
    path.extend(best);
    Ok(Some((path, lo)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A wall x ∈ [0.9, 1.1] with a doorway y ∈ [0.8, 1.4], the robot a point.
    fn doorway(p: [f64; 2]) -> f64 {
        let dx = (p[0] - 1.0).abs() - 0.1;
        let in_door = p[1] > 0.8 && p[1] < 1.4;
        if in_door {
            // distance to the door posts
            let post = |y: f64| (dx.max(0.0)).hypot(p[1] - y);
            post(0.8).min(post(1.4))
        } else {
            dx
        }
    }

    #[test]
    fn a_clear_leg_stays_straight() {
        let p = plan(
            [0.0, 0.0],
            &[],
            [2.0, 0.0],
            &|_| 10.0,
            &PlannerConfig::default(),
        )
        .expect("within budget");
        assert_eq!(p.points, vec![[2.0, 0.0]]);
        assert_eq!(p.unplanned_legs, 0);
    }

    #[test]
    fn goes_through_the_doorway_with_the_clearance_asked() {
        let cfg = PlannerConfig::default();
        let p = plan([0.0, 0.0], &[], [2.0, 0.0], &doorway, &cfg).expect("within budget");
        assert_eq!(p.unplanned_legs, 0);
        assert_eq!(*p.points.last().expect("points"), [2.0, 0.0]);
        assert!(p.points.len() >= 2, "{:?}", p.points);
        let mut from = [0.0, 0.0];
        for &to in &p.points {
            let n = 100;
            for k in 0..=n {
                let t = k as f64 / n as f64;
                let q = [
                    from[0] + t * (to[0] - from[0]),
                    from[1] + t * (to[1] - from[1]),
                ];
                assert!(doorway(q) >= cfg.inflate - 0.02, "{q:?} on {:?}", p.points);
            }
            from = to;
        }
    }

    #[test]
    fn a_closed_wall_leaves_the_leg_unplanned() {
        let wall = |p: [f64; 2]| (p[0] - 1.0).abs() - 0.1;
        let p = plan(
            [0.0, 0.0],
            &[],
            [2.0, 0.0],
            &wall,
            &PlannerConfig::default(),
        )
        .expect("within budget");
        assert_eq!(p.unplanned_legs, 1);
        assert_eq!(p.points, vec![[2.0, 0.0]]);
    }

    /// A block centred on a diagonal leg leaves two detours of equal length, round either
    /// side. The search takes the same one every time: of the open cells with equal
    /// f = g + h it expands the smallest first (the order the hand-written A* had, kept through
    /// [`Cost`]'s tie-break key). Without the key the crate breaks those ties by its heap's
    /// order and this plan passes the other side, through (1.35, 0.6).
    #[test]
    fn equal_detours_resolve_the_same_way() {
        let block = |p: [f64; 2]| ((p[0] - 1.0).abs() - 0.2).max((p[1] - 1.0).abs() - 0.3);
        let p = plan(
            [0.0, 0.0],
            &[],
            [2.0, 2.0],
            &block,
            &PlannerConfig::default(),
        )
        .expect("within budget");
        let want = [[0.7, 1.4], [2.0, 2.0]];
        assert_eq!(p.points.len(), want.len(), "{:?}", p.points);
        for (got, want) in p.points.iter().zip(want) {
            assert!(dist(*got, want) < 1e-12, "{:?}", p.points);
        }
    }
    /// A leg 14 km long with a block across its start: its grid would have 8·10¹⁰ cells. The
    /// plan stops at its budget, having evaluated the clearance at most that many times, and
    /// names the leg.
    #[test]
    fn a_leg_beyond_the_budget_ends_after_at_most_the_budget() {
        let calls = Counter::new(0u64);
        let block = |p: [f64; 2]| {
            calls.set(calls.get() + 1);
            ((p[0] - 1.0).abs() - 0.3).max((p[1] - 1.0).abs() - 0.3)
        };
        let cfg = PlannerConfig {
            max_evaluations: 50_000,
            ..PlannerConfig::default()
        };
        let e =
            plan([0.0, 0.0], &[[1e4, 1e4]], [0.0, 5.0], &block, &cfg).expect_err("over the budget");
        assert_eq!(e.leg, 0);
        assert_eq!(e.limit, 50_000);
        assert_eq!(e.to, [1e4, 1e4]);
        assert!(calls.get() <= 50_000, "{} evaluations", calls.get());
    }

    /// A clear leg 10 km long, 100 m from the one obstacle: line of sight takes a few dozen
    /// evaluations, not one per 2 cm sample (5·10⁵).
    #[test]
    fn a_long_clear_leg_takes_few_evaluations() {
        let calls = Counter::new(0u64);
        let far = |p: [f64; 2]| {
            calls.set(calls.get() + 1);
            (p[0] - 5000.0).hypot(p[1] - 100.0) - 1.0
        };
        let p = plan([0.0, 0.0], &[], [1e4, 0.0], &far, &PlannerConfig::default())
            .expect("within budget");
        assert_eq!(p.points, vec![[1e4, 0.0]]);
        assert!(calls.get() < 100, "{} evaluations", calls.get());
    }

    /// Skipping the samples a clearance vouches for gives the answer every sample gives: 4,096
    /// segments among the doorway's posts, against a check of every 2 cm sample.
    #[test]
    fn skipping_samples_gives_the_answer_every_sample_gives() {
        let cfg = PlannerConfig::default();
        let every = |a: [f64; 2], b: [f64; 2]| {
            let need = cfg.inflate.min(doorway(a)).min(doorway(b)) - 1e-9;
            let n = (dist(a, b) / cfg.sample).ceil().max(1.0) as usize;
            (0..=n).all(|k| {
                let t = k as f64 / n as f64;
                doorway([a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]) >= need
            })
        };
        let grid: Vec<[f64; 2]> = (0..64)
            .map(|i| [-0.5 + 0.4 * (i % 8) as f64, -0.5 + 0.4 * (i / 8) as f64])
            .collect();
        let mut blocked = 0;
        for &a in &grid {
            for &b in &grid {
                let want = every(a, b);
                assert_eq!(line_of_sight(a, b, &doorway, &cfg), want, "{a:?} → {b:?}");
                blocked += usize::from(!want);
            }
        }
        assert!(blocked > 500 && blocked < 3500, "{blocked} of 4096 blocked");
    }
}
