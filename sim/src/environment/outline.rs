//! The barriers of an occupancy map: the outlines of its blocked cells, simplified.
//!
//! One barrier on the map's whole distance field ([`super::MapField`]) has a kink wherever two
//! walls pull equally (the field's medial axis) and corners at every step of a staircase wall;
//! interpolated over a cell, its curvature reached κ ≈ 39 1/m on the nav2 map of
//! turtlebot3_world, and with h̄_γ = γ·L growing with κ the robot stalled in 80 of 80 trials.
//! A union of obstacles is better served the way an SDF world is: one barrier per piece, each
//! smooth, and the QP keeps all of them at once (where two walls pull equally, two rows do).
//!
//! # The pieces
//! The boundary between blocked and free cells (blocked cells as in [`super::MapField`]: the
//! occupied ones and, unless `environment.unknown = "free"`, the unknown ones and beyond the
//! map's edge) is traced into closed loops along the cell edges, blocked cells on the left.
//! Each loop becomes:
//! - **one convex polygon** when it goes round a blob counter-clockwise and every point of the
//!   loop lies within the tolerance ε of the convex hull's boundary (a pillar, a box, a lone
//!   cell): the barrier is the signed distance to the hull, which contains the blob;
//! - otherwise **segments**: the loop simplified by Douglas–Peucker with tolerance ε, each
//!   segment with its own `inflate` δ ≤ ε, the largest distance from it of the loop's stretch
//!   it replaces. The barrier is the distance to the segment less δ.
//!
//! **Why the robot stays off the blocked cells.** Every point of a loop is within δ of its
//! segment (Douglas–Peucker keeps every vertex of the stretch within δ, and the distance to a
//! segment is convex, so the stretch's edges are within δ too), so a disc whose every
//! segment barrier is ≥ 0 touches no boundary point; it starts in free space and moves
//! continuously, so it never enters a blocked cell. A hull contains its blob. **What it
//! costs:** the conservatism is at most 2ε beyond the cells (a segment may lie up to ε on the
//! free side of the cells it stands for, and δ ≤ ε is added) — ε = one cell by default
//! ([`DEFAULT_TOLERANCE_CELLS`]), the grid's resolution in the margin.
//!
//! **What the pieces give the controller.** Each is the distance to a convex set (a segment, a
//! polygon), less a constant: ‖∇d‖ = 1 and ‖∇²d‖ ≤ 1/ρ at distance ρ, so a robot disc of
//! radius r gets κ ≤ 1/(r + δ) — the bound every convex SDF obstacle gets — instead of the
//! field's κ. Gradient and curvature are closed forms.

use nalgebra::{Matrix2, Vector2};

use super::map::{Cell, OccupancyGrid, UnknownCells};

/// ε in cells by default: the simplification tolerance (and at most the extra stand-off on
/// each side is 2ε).
pub const DEFAULT_TOLERANCE_CELLS: f64 = 1.0;

/// One barrier piece of a map, world frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Outline {
    /// Two points (a segment), or the vertices of a convex polygon counter-clockwise \[m\].
    pub points: Vec<Vector2<f64>>,
    /// δ: how far the cells' boundary may lie beyond the segment \[m\] (0 for a polygon).
    pub inflate: f64,
}

impl Outline {
    /// Whether the piece is a convex polygon (signed distance) rather than a segment.
    pub fn is_polygon(&self) -> bool {
        self.points.len() >= 3
    }

    /// The edges: one for a segment, all (closing too) for a polygon.
    fn edges(&self) -> impl Iterator<Item = (Vector2<f64>, Vector2<f64>)> + '_ {
        let n = self.points.len();
        let count = if n >= 3 { n } else { 1 };
        (0..count).map(move |i| (self.points[i], self.points[(i + 1) % n]))
    }

    /// The signed distance from `p` to the piece less δ \[m\] (negative inside a polygon), its
    /// gradient and Hessian: flat (zero Hessian) where the nearest point is inside an edge, round
    /// ((I − ggᵀ)/ρ) where it is a vertex.
    pub fn distance_terms(&self, p: Vector2<f64>) -> (f64, Vector2<f64>, Matrix2<f64>) {
        let mut best = (f64::INFINITY, Vector2::zeros(), true);
        for (a, b) in self.edges() {
            let ab = b - a;
            let t = segment_parameter(p, a, b);
            let q = a + ab * t;
            let rho = (p - q).norm();
            if rho < best.0 {
                best = (rho, q, t <= 0.0 || t >= 1.0);
            }
        }
        let (rho, q, at_vertex) = best;
        let inside = self.is_polygon()
            && self.edges().all(|(a, b)| {
                let (e, w) = (b - a, p - a);
                e.x * w.y - e.y * w.x >= 0.0
            });
        if rho <= 1e-12 {
            // On the boundary: any unit vector; the outward normal of the nearest edge would
            // need the edge, and the value is what matters here.
            return (-self.inflate, Vector2::x(), Matrix2::zeros());
        }
        let sign = if inside { -1.0 } else { 1.0 };
        let g = sign * (p - q) / rho;
        let m = if at_vertex && !inside {
            (Matrix2::identity() - g * g.transpose()) / rho
        } else {
            Matrix2::zeros()
        };
        (sign * rho - self.inflate, g, m)
    }

    /// The piece's bounding rectangle grown by δ (x_min, y_min, x_max, y_max) \[m\].
    pub fn bounds(&self) -> [f64; 4] {
        let mut r = [
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        ];
        for q in &self.points {
            r = [r[0].min(q.x), r[1].min(q.y), r[2].max(q.x), r[3].max(q.y)];
        }
        let d = self.inflate;
        [r[0] - d, r[1] - d, r[2] + d, r[3] + d]
    }
}

/// A corner of the cell grid, in cells from the map's origin corner.
type Corner = (i64, i64);

/// Whether cell (i, j) is blocked; cells beyond the map are like unknown ones.
fn blocked_at(grid: &OccupancyGrid, unknown: UnknownCells, i: i64, j: i64) -> bool {
    if i < 0 || j < 0 || i >= grid.width as i64 || j >= grid.height as i64 {
        Cell::Unknown.blocked(unknown)
    } else {
        grid.cell(i as usize, j as usize).blocked(unknown)
    }
}

/// The cell edges between blocked and free cells, directed with the blocked cell on the left,
/// as (from, to) corners; at most two leave a corner (a saddle), listed in cell order.
fn boundary_edges(grid: &OccupancyGrid, unknown: UnknownCells) -> Vec<(Corner, Corner)> {
    let b = |i: i64, j: i64| blocked_at(grid, unknown, i, j);
    let (w, h) = (grid.width as i64, grid.height as i64);
    let mut edges = Vec::new();
    for j in -1..=h {
        for i in -1..=w {
            if !b(i, j) {
                continue;
            }
            if !b(i, j - 1) {
                edges.push(((i, j), (i + 1, j)));
            }
            if !b(i + 1, j) {
                edges.push(((i + 1, j), (i + 1, j + 1)));
            }
            if !b(i, j + 1) {
                edges.push(((i + 1, j + 1), (i, j + 1)));
            }
            if !b(i - 1, j) {
                edges.push(((i, j + 1), (i, j)));
            }
        }
    }
    edges
}

/// The boundary traced into closed loops (each a corner list, not repeating its first). At a
/// saddle the loop turns left, keeping diagonal blocked cells apart.
fn loops(edges: &[(Corner, Corner)]) -> Vec<Vec<Corner>> {
    let mut out_of: std::collections::HashMap<Corner, Vec<usize>> = Default::default();
    for (k, (a, _)) in edges.iter().enumerate() {
        out_of.entry(*a).or_default().push(k);
    }
    let mut used = vec![false; edges.len()];
    let mut loops = Vec::new();
    for first in 0..edges.len() {
        if used[first] {
            continue;
        }
        let mut corners = vec![edges[first].0];
        let mut k = first;
        loop {
            used[k] = true;
            let (a, c) = edges[k];
            let dir = (c.0 - a.0, c.1 - a.1);
            let left = (-dir.1, dir.0);
            let next = out_of.get(&c).and_then(|outs| {
                let free: Vec<usize> = outs.iter().copied().filter(|&e| !used[e]).collect();
                let turn_left = free.iter().copied().find(|&e| {
                    let (p, q) = edges[e];
                    (q.0 - p.0, q.1 - p.1) == left
                });
                turn_left.or_else(|| free.first().copied())
            });
            corners.push(c);
            match next {
                // back at the first corner: the loop is closed (a saddle's other edge starts
                // a loop of its own)
                Some(e) if c != edges[first].0 => k = e,
                _ => break,
            }
        }
        // The walk ends back at the first corner (every corner has as many edges in as out).
        if corners.len() > 1 && corners.last() == corners.first() {
            corners.pop();
        }
        loops.push(corners);
    }
    loops
}

/// The largest distance from the points `pts[1..n-1]` to the segment pts[0]–pts[n-1], and where.
fn farthest(pts: &[Vector2<f64>]) -> (f64, usize) {
    let (a, b) = (pts[0], pts[pts.len() - 1]);
    let mut best = (0.0, 0);
    for (i, p) in pts.iter().enumerate().take(pts.len() - 1).skip(1) {
        let d = segment_distance(*p, a, b);
        if d > best.0 {
            best = (d, i);
        }
    }
    best
}

/// Where the point of segment a–b nearest `p` lies: t ∈ [0, 1] along a → b (0 for a
/// degenerate segment).
fn segment_parameter(p: Vector2<f64>, a: Vector2<f64>, b: Vector2<f64>) -> f64 {
    let ab = b - a;
    let l2 = ab.norm_squared();
    if l2 > 0.0 {
        ((p - a).dot(&ab) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    }
}

fn segment_distance(p: Vector2<f64>, a: Vector2<f64>, b: Vector2<f64>) -> f64 {
    (p - a - (b - a) * segment_parameter(p, a, b)).norm()
}

/// Douglas–Peucker on the open polyline `pts` with tolerance `tol`: the segments, each with
/// the largest distance δ of its stretch from it. Iterative (no recursion depth on long walls).
fn simplify(pts: &[Vector2<f64>], tol: f64) -> Vec<Outline> {
    let mut out = Vec::new();
    let mut stack = vec![(0usize, pts.len() - 1)];
    while let Some((lo, hi)) = stack.pop() {
        let (d, at) = farthest(&pts[lo..=hi]);
        if hi - lo >= 2 && d > tol {
            // hi half first on the stack, so the lo half comes out first: segments in order
            stack.push((lo + at, hi));
            stack.push((lo, lo + at));
        } else {
            out.push(Outline {
                points: vec![pts[lo], pts[hi]],
                inflate: d,
            });
        }
    }
    out
}

/// The convex hull of `pts` (Andrew's monotone chain), counter-clockwise, without collinear
/// points.
fn convex_hull(pts: &[Vector2<f64>]) -> Vec<Vector2<f64>> {
    let mut p = pts.to_vec();
    p.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    p.dedup();
    if p.len() < 3 {
        return p;
    }
    let cross = |o: Vector2<f64>, a: Vector2<f64>, b: Vector2<f64>| {
        (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x)
    };
    let mut hull: Vec<Vector2<f64>> = Vec::with_capacity(2 * p.len());
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &Vector2<f64>>> = if pass == 0 {
            Box::new(p.iter())
        } else {
            Box::new(p.iter().rev())
        };
        for &q in iter {
            while hull.len() >= start + 2
                && cross(hull[hull.len() - 2], hull[hull.len() - 1], q) <= 0.0
            {
                hull.pop();
            }
            hull.push(q);
        }
        hull.pop();
    }
    hull
}

/// Twice the signed area of a closed loop (positive counter-clockwise).
fn twice_area(pts: &[Vector2<f64>]) -> f64 {
    (0..pts.len())
        .map(|i| {
            let (a, b) = (pts[i], pts[(i + 1) % pts.len()]);
            a.x * b.y - a.y * b.x
        })
        .sum()
}

/// One loop (cells) as its pieces (cells, map frame): a hull when the loop is a blob's outer
/// boundary within `tol` of its hull, else Douglas–Peucker segments.
fn loop_pieces(corners: &[Corner], tol: f64) -> Vec<Outline> {
    let pts: Vec<Vector2<f64>> = corners
        .iter()
        .map(|&(i, j)| Vector2::new(i as f64, j as f64))
        .collect();
    if twice_area(&pts) > 0.0 {
        let hull = convex_hull(&pts);
        let off = pts
            .iter()
            .map(|p| {
                (0..hull.len())
                    .map(|k| segment_distance(*p, hull[k], hull[(k + 1) % hull.len()]))
                    .fold(f64::INFINITY, f64::min)
            })
            .fold(0.0, f64::max);
        if hull.len() >= 3 && off <= tol {
            return vec![Outline {
                points: hull,
                inflate: 0.0,
            }];
        }
    }
    // A closed loop as an open polyline from its first corner round to it, split at the corner
    // farthest from it (Douglas–Peucker needs distinct end points).
    let far = (0..pts.len())
        .max_by(|&a, &b| {
            (pts[a] - pts[0])
                .norm_squared()
                .total_cmp(&(pts[b] - pts[0]).norm_squared())
                .then(b.cmp(&a))
        })
        .unwrap_or(0);
    let mut pieces = simplify(&pts[..=far], tol);
    let mut back: Vec<Vector2<f64>> = pts[far..].to_vec();
    back.push(pts[0]);
    pieces.extend(simplify(&back, tol));
    pieces
}

/// The map's barrier pieces (module docs), world frame, with tolerance `tol_cells` ε in cells.
/// Deterministic: the same grid gives the same pieces in the same order.
pub fn outlines(grid: &OccupancyGrid, unknown: UnknownCells, tol_cells: f64) -> Vec<Outline> {
    let edges = boundary_edges(grid, unknown);
    let r = grid.resolution;
    let mut out = Vec::new();
    for corners in loops(&edges) {
        if corners.len() < 3 {
            continue;
        }
        for piece in loop_pieces(&corners, tol_cells) {
            out.push(Outline {
                points: piece
                    .points
                    .iter()
                    .map(|q| Vector2::from(grid.to_world(q.x, q.y)))
                    .collect(),
                inflate: piece.inflate * r,
            });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn grid(width: usize, height: usize, blocked: &dyn Fn(usize, usize) -> bool) -> OccupancyGrid {
        let mut cells = Vec::new();
        for j in 0..height {
            for i in 0..width {
                cells.push(if blocked(i, j) {
                    Cell::Occupied
                } else {
                    Cell::Free
                });
            }
        }
        OccupancyGrid {
            width,
            height,
            resolution: 0.05,
            origin: [1.0, -2.0, 0.5],
            cells,
        }
    }

    fn min_distance(pieces: &[Outline], p: Vector2<f64>) -> f64 {
        pieces
            .iter()
            .map(|o| o.distance_terms(p).0)
            .fold(f64::INFINITY, f64::min)
    }

    /// The exact distance from `p` to the union of the blocked cells' squares (brute force).
    fn true_distance(g: &OccupancyGrid, p: Vector2<f64>) -> f64 {
        let (s, c) = g.origin[2].sin_cos();
        let d = p - Vector2::new(g.origin[0], g.origin[1]);
        let local = Vector2::new(c * d.x + s * d.y, -s * d.x + c * d.y) / g.resolution;
        let mut best = f64::INFINITY;
        for j in 0..g.height {
            for i in 0..g.width {
                if g.cell(i, j).blocked(UnknownCells::Free) {
                    let dx = (i as f64 - local.x)
                        .max(local.x - (i as f64 + 1.0))
                        .max(0.0);
                    let dy = (j as f64 - local.y)
                        .max(local.y - (j as f64 + 1.0))
                        .max(0.0);
                    best = best.min(dx.hypot(dy));
                }
            }
        }
        best * g.resolution
    }

    #[test]
    fn a_lone_cell_is_one_square_polygon_placed_by_the_origin_and_its_yaw() {
        let g = grid(5, 5, &|i, j| i == 2 && j == 1);
        let pieces = outlines(&g, UnknownCells::Free, DEFAULT_TOLERANCE_CELLS);
        assert_eq!(pieces.len(), 1);
        let sq = &pieces[0];
        assert!(sq.is_polygon());
        assert_eq!(sq.points.len(), 4);
        assert_eq!(sq.inflate, 0.0);
        // the centre of cell (2, 1): origin + R(0.5)·(2.5, 1.5)·0.05
        let (s, c) = 0.5f64.sin_cos();
        let (lx, ly) = (0.125, 0.075);
        let centre = Vector2::new(1.0 + c * lx - s * ly, -2.0 + s * lx + c * ly);
        let (d, _, _) = sq.distance_terms(centre);
        assert!((d + 0.025).abs() < 1e-12, "inside by half a cell, got {d}");
        // 0.1 m beyond the cell's +x face (local frame)
        let (lx, ly) = (0.15 + 0.1, 0.075);
        let out = Vector2::new(1.0 + c * lx - s * ly, -2.0 + s * lx + c * ly);
        let (d, g, m) = sq.distance_terms(out);
        assert!((d - 0.1).abs() < 1e-12, "{d}");
        assert!((g - Vector2::new(c, s)).norm() < 1e-12);
        assert_eq!(m, Matrix2::zeros());
    }

    #[test]
    fn a_diagonal_staircase_wall_becomes_a_few_segments() {
        // free on and below the diagonal j ≤ i of a 40 × 40 map, blocked above it and beyond
        // the map's edge: the free triangle's outline, three walls, one a staircase
        let g = grid(40, 40, &|i, j| j > i);
        let pieces = outlines(&g, UnknownCells::Obstacle, DEFAULT_TOLERANCE_CELLS);
        assert!(pieces.iter().all(|p| !p.is_polygon()));
        assert!((3..=6).contains(&pieces.len()), "{} pieces", pieces.len());
        assert!(pieces.iter().all(|p| p.inflate <= 0.05 + 1e-12));
    }

    #[test]
    fn a_blob_within_a_cell_of_its_hull_is_one_polygon() {
        // the blocked triangle above the diagonal, free beyond the map: its staircase side lies
        // within a cell of the hull
        let g = grid(40, 40, &|i, j| j > i);
        let pieces = outlines(&g, UnknownCells::Free, DEFAULT_TOLERANCE_CELLS);
        assert_eq!(pieces.len(), 1);
        assert!(pieces[0].is_polygon());
    }

    /// On random maps every free point's distance to the pieces is at most its distance to the
    /// cells (the robot kept by the pieces never touches a cell) and at least that less 2ε.
    #[test]
    fn the_pieces_never_overstate_the_distance_and_understate_it_by_at_most_two_cells() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(47);
        for trial in 0..20 {
            let fill = 0.05 + 0.05 * (trial % 4) as f64;
            let cells: Vec<bool> = (0..30 * 30).map(|_| rng.random_bool(fill)).collect();
            let g = grid(30, 30, &|i, j| cells[j * 30 + i]);
            let pieces = outlines(&g, UnknownCells::Free, DEFAULT_TOLERANCE_CELLS);
            for _ in 0..200 {
                let p = Vector2::new(rng.random_range(0.5..3.0), rng.random_range(-2.5..0.5));
                let truth = true_distance(&g, p);
                if !truth.is_finite() || truth <= 0.0 {
                    continue;
                }
                let d = min_distance(&pieces, p);
                assert!(d <= truth + 1e-9, "trial {trial}: {d} > {truth} at {p:?}");
                assert!(
                    d >= truth - 2.0 * 0.05 - 1e-9,
                    "trial {trial}: {d} ≪ {truth}"
                );
            }
        }
    }

    #[test]
    fn the_gradient_and_hessian_match_finite_differences() {
        let o = Outline {
            points: vec![Vector2::new(0.0, 0.0), Vector2::new(1.0, 0.5)],
            inflate: 0.03,
        };
        for p in [
            Vector2::new(0.4, 0.6),
            Vector2::new(-0.3, 0.2),
            Vector2::new(1.4, 0.1),
        ] {
            let (_, g, m) = o.distance_terms(p);
            let h = 1e-6;
            for k in 0..2 {
                let mut e = Vector2::zeros();
                e[k] = h;
                let fd = (o.distance_terms(p + e).0 - o.distance_terms(p - e).0) / (2.0 * h);
                assert!((fd - g[k]).abs() < 1e-6, "{fd} vs {}", g[k]);
                let fdg = (o.distance_terms(p + e).1 - o.distance_terms(p - e).1) / (2.0 * h);
                assert!((fdg - m.column(k)).norm() < 1e-5, "{fdg:?} vs {m:?}");
            }
        }
    }
}
