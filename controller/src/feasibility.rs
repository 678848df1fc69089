//! Exact, allocation-free feasibility test of a set of input half-planes in R² (plus the
//! input box), used by [`crate::policy`] to decide every "is this constraint set feasible?"
//! question without an interior-point solve.
//!
//! # Rows
//!
//! Every [`HalfSpace`] `nᵀu ≤ o` is scaled exactly as [`crate::qp`] scales it before clarabel
//! sees it ([`Line::from_half_space`] is the one function both use): `n/‖n‖ · u ≤ o/‖n‖`, so a
//! violation `a·u − b` is a distance in input space (m/s²). A row with a vanishing (finite)
//! normal becomes `0 ≤ 1` (finite `o ≥ 0`: always holds) or `0 ≤ −1` (otherwise: never
//! holds). A row whose normal or offset is **not finite** (NaN or ±∞) becomes `0 ≤ −1`
//! whatever its offset: a constraint that cannot be evaluated fails closed, it is never
//! treated as satisfied.
//!
//! # Method: vertex enumeration
//!
//! The rows and the four edges of the box `|u_k| ≤ L_k` bound a polygon
//! `P = {u : a_i·u ≤ b_i ∀i, |u_k| ≤ L_k}`. `P` is bounded, so when it is non-empty it has a
//! vertex, and every vertex is the intersection of two of the lines `a_i·u = b_i` (rows or box
//! edges) whose normals are not parallel. The test computes the intersection of every
//! non-parallel pair and accepts the first one that satisfies **all** rows and box edges
//! within the tolerance below; it is rejected otherwise. `u = 0` is tried first (it is inside
//! every box). Cost: `O(N³)` multiply-adds for `N` lines, no allocation (for `N = 10`,
//! 45 pairs × 10 rows).
//!
//! **A "feasible" answer is a certificate**: the witness returned satisfies every row to
//! within `tol`, however it was computed (Cramer's rule on nearly parallel lines is
//! inaccurate, but an inaccurate vertex can only fail the check, never pass it wrongly).
//! An "infeasible" answer is exact except in two degenerate situations, both outside any
//! realistic control problem: (a) every vertex of `P` is the intersection of lines at an
//! angle below ~ε·scale/tol ≈ 1e-9 rad (a needle-shaped `P` whose width is then of the
//! order of the tolerance), and (b) without a box, see [`VIRTUAL_BOX`].
//!
//! # Tolerance (how feasibility was judged before)
//!
//! Before this module, feasibility was clarabel's status (Solved/AlmostSolved versus
//! PrimalInfeasible/AlmostPrimalInfeasible, a failure counting as "not shown feasible") on
//! the same scaled rows; clarabel accepts a point whose primal residual is below
//! `tol_feas = 1e-8` relative to the size of the data (`max(1, ‖b‖∞, …)`). The test accepts a
//! vertex `v` when, for every row and box edge, `a·v − b ≤ FEASIBILITY_TOL · max(1, max |b_i|)`
//! (rows and the real box, not the virtual one), plus the floating-point bound of
//! evaluating `a·v − b`. With `φ = min_u max_i (a_i·u − b_i)` (the smallest achievable
//! largest violation, m/s², box edges included), the answer is "feasible" whenever `φ ≤ 0`
//! and "infeasible" whenever `φ > tol`; only the band `0 < φ ≤ tol` can go either way.
//!
//! `FEASIBILITY_TOL` is 1e-7, ten times clarabel's, on purpose: inside the band the test
//! leans to "feasible". The policy then calls clarabel, and if clarabel does not solve the
//! set (it reports PrimalInfeasible, or — as it does on sets infeasible by ~1e-9…4e-7 —
//! InsufficientProgress) the policy moves on exactly as it did when clarabel alone decided.
//! The other direction (the test rejects a set clarabel would have solved) is the only one
//! that can change a decision, and needs clarabel to accept a residual above its own
//! tolerance. The tests cross-check this against clarabel on thousands of random problems,
//! a third of them pushed to within 1e-10…1e-3 of the boundary.

use crate::constraints::HalfSpace;
use crate::types::Input;

/// Relative feasibility tolerance (scaled rows, relative to `max(1, max |b_i|)` in m/s²):
/// ten times clarabel's default `tol_feas` (see the module docs for why).
pub const FEASIBILITY_TOL: f64 = 1e-7;

/// Half-width of the box used when the problem has no input box (m/s²).
///
/// Without a box, the test decides feasibility inside `|u_k| ≤ VIRTUAL_BOX`. This cannot
/// change the answer unless every input satisfying all rows has a component above
/// 1e6 m/s² (about 10⁵ g): a non-empty constraint set always contains its minimum-norm
/// point, which is what the QP would command, so a different answer requires the policy's
/// answer itself to be an input of that size — for the planar robot's CBF/CLF rows, whose
/// scaled offsets are accelerations of order 1–10 m/s², that is only a wedge of two
/// almost antiparallel rows (angle ~1e-6 rad) meeting far away, which no realistic problem
/// produces and clarabel itself could not resolve reliably (its tolerances are relative
/// to the iterate's size).
pub const VIRTUAL_BOX: f64 = 1e6;

/// A scaled half-plane `a·u ≤ b` with `‖a‖ = 1`, or `a = 0` and `b = ±1`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Line {
    /// Unit normal (or zero).
    pub a: [f64; 2],
    /// Offset (m/s² for a unit normal).
    pub b: f64,
}

impl Line {
    /// The scaling of [`crate::qp`]: `n/‖n‖ · u ≤ o/‖n‖`. A normal or offset that is not
    /// finite (or a normal whose norm overflows) gives `0 ≤ −1`: violated by every input
    /// (fail closed). A vanishing finite normal (`‖n‖ ≤ 1e-12`) gives `0 ≤ 1` if the offset is
    /// non-negative and `0 ≤ −1` otherwise.
    pub fn from_half_space(h: &HalfSpace) -> Self {
        let n = h.normal.norm();
        let finite = n.is_finite() && h.offset.is_finite();
        if finite && n > 1e-12 {
            Self {
                a: [h.normal[0] / n, h.normal[1] / n],
                b: h.offset / n,
            }
        } else if finite && h.offset >= 0.0 {
            Self {
                a: [0.0, 0.0],
                b: 1.0,
            }
        } else {
            Self {
                a: [0.0, 0.0],
                b: -1.0,
            }
        }
    }

    /// `a·u − b` (≤ 0 when satisfied).
    #[inline]
    pub fn violation(&self, u: [f64; 2]) -> f64 {
        self.a[0] * u[0] + self.a[1] * u[1] - self.b
    }

    /// Where the boundaries of `self` and `other` cross; `None` when they are parallel (or
    /// one is degenerate). The point may be non-finite when they are nearly parallel.
    #[inline]
    fn meet(&self, other: &Line) -> Option<[f64; 2]> {
        let det = self.a[0] * other.a[1] - self.a[1] * other.a[0];
        if det == 0.0 {
            return None;
        }
        Some([
            (self.b * other.a[1] - other.b * self.a[1]) / det,
            (self.a[0] * other.b - other.a[0] * self.b) / det,
        ])
    }

    #[inline]
    fn is_degenerate(&self) -> bool {
        self.a[0] == 0.0 && self.a[1] == 0.0
    }
}

/// The verdict of the test.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Feasibility {
    /// Some input satisfies every row and the box within the tolerance.
    Feasible {
        /// Such an input (a vertex of the feasible polygon, or 0).
        witness: Input,
    },
    /// No input does (see the module docs for the tolerance band).
    Infeasible,
}

impl Feasibility {
    /// True for [`Feasibility::Feasible`].
    pub fn is_feasible(&self) -> bool {
        matches!(self, Self::Feasible { .. })
    }
}

/// The box half-widths used by the test: the real limits (each capped at [`VIRTUAL_BOX`];
/// a NaN limit counts as [`VIRTUAL_BOX`]) or the virtual box.
fn box_half_widths(input_limit: Option<Input>) -> [f64; 2] {
    match input_limit {
        Some(l) => [l[0].min(VIRTUAL_BOX), l[1].min(VIRTUAL_BOX)],
        None => [VIRTUAL_BOX; 2],
    }
}

/// The four edges `±u_k ≤ L_k` of the box the test uses (the real limits, capped at
/// [`VIRTUAL_BOX`], or the virtual box).
pub fn box_edges(input_limit: Option<Input>) -> [Line; 4] {
    let half = box_half_widths(input_limit);
    [
        Line {
            a: [1.0, 0.0],
            b: half[0],
        },
        Line {
            a: [-1.0, 0.0],
            b: half[0],
        },
        Line {
            a: [0.0, 1.0],
            b: half[1],
        },
        Line {
            a: [0.0, -1.0],
            b: half[1],
        },
    ]
}

/// Decide whether `{u : a_i·u ≤ b_i ∀i}` meets the box `|u_k| ≤ limit_k` (or the
/// [`VIRTUAL_BOX`] when `input_limit` is `None`). Allocation-free.
pub fn check(lines: &[Line], input_limit: Option<Input>) -> Feasibility {
    let half = box_half_widths(input_limit);
    if !(half[0] >= 0.0 && half[1] >= 0.0) {
        return Feasibility::Infeasible; // a negative box is empty
    }
    let Some(tol) = tolerance(lines, input_limit) else {
        return Feasibility::Infeasible; // 0 ≤ −1
    };
    let edges = box_edges(input_limit);
    let n = lines.len();
    let line = |k: usize| if k < n { lines[k] } else { edges[k - n] };
    // `v` satisfies every row within tol (+ the rounding bound of a·v − b). The box holds
    // exactly at its own vertices and is checked with the same rule elsewhere.
    let admissible = |v: [f64; 2]| {
        let ok = |l: &Line| within(l, v, tol);
        lines.iter().all(ok) && edges.iter().all(ok)
    };
    if admissible([0.0, 0.0]) {
        return Feasibility::Feasible {
            witness: Input::zeros(),
        };
    }
    let total = n + edges.len();
    for i in 0..total {
        let li = line(i);
        if li.is_degenerate() {
            continue;
        }
        for j in (i + 1)..total {
            let Some(v) = li.meet(&line(j)) else {
                continue; // parallel (or degenerate): no single intersection
            };
            if v[0].is_finite() && v[1].is_finite() && admissible(v) {
                return Feasibility::Feasible {
                    witness: Input::new(v[0], v[1]),
                };
            }
        }
    }
    Feasibility::Infeasible
}

/// The input of `{u : every row of lines, the box}` nearest `target` (Euclidean), or `None`
/// when no candidate is admitted. The nearest point of a convex polygon is the target itself,
/// its projection on an edge, or a vertex: every one of those is tried and the nearest that
/// [`admits`] accepts is returned. The policy decides with it when clarabel fails on a set the
/// test certified feasible (issue #30): the witness of [`check`] is any vertex, which can stop
/// the robot where the solver's optimum, near the nominal input, would not.
pub fn nearest(lines: &[Line], input_limit: Option<Input>, target: Input) -> Option<Input> {
    if admits(lines, input_limit, target) {
        return Some(target);
    }
    let edges = box_edges(input_limit);
    let n = lines.len();
    let line = |k: usize| if k < n { lines[k] } else { edges[k - n] };
    let total = n + edges.len();
    let mut best: Option<(f64, Input)> = None;
    let mut consider = |v: [f64; 2]| {
        let u = Input::new(v[0], v[1]);
        if admits(lines, input_limit, u) {
            let d = (u - target).norm();
            if best.is_none_or(|(bd, _)| d < bd) {
                best = Some((d, u));
            }
        }
    };
    for i in 0..total {
        let li = line(i);
        if li.is_degenerate() {
            continue;
        }
        let f = li.violation([target[0], target[1]]);
        consider([target[0] - f * li.a[0], target[1] - f * li.a[1]]);
        for j in (i + 1)..total {
            if let Some(v) = li.meet(&line(j)) {
                consider(v);
            }
        }
    }
    best.map(|(_, u)| u)
}

/// Whether `u` satisfies every row of `lines` and the box `|u_k| ≤ limit_k` within the
/// tolerance [`check`] accepts its witnesses with (a NaN or infinite `u` never does). The
/// policy checks clarabel's answers with it: a solve reported as Solved or AlmostSolved is
/// used only when its input meets the hard rows the test certified (issue #30).
pub fn admits(lines: &[Line], input_limit: Option<Input>, u: Input) -> bool {
    let v = [u[0], u[1]];
    let half = box_half_widths(input_limit);
    let Some(tol) = tolerance(lines, input_limit) else {
        return false;
    };
    v[0].is_finite()
        && v[1].is_finite()
        && lines.iter().all(|l| within(l, v, tol))
        && v[0].abs() <= half[0] + tol
        && v[1].abs() <= half[1] + tol
}

/// The tolerance of [`check`]: [`FEASIBILITY_TOL`] relative to the data clarabel sees (rows and
/// the real box); `None` when a degenerate row is `0 ≤ −1`.
fn tolerance(lines: &[Line], input_limit: Option<Input>) -> Option<f64> {
    let mut scale = 1.0_f64;
    for l in lines {
        if l.is_degenerate() {
            if l.b < 0.0 {
                return None;
            }
        } else {
            scale = scale.max(l.b.abs());
        }
    }
    if input_limit.is_some() {
        let half = box_half_widths(input_limit);
        scale = scale.max(half[0]).max(half[1]);
    }
    Some(FEASIBILITY_TOL * scale)
}

/// `v` satisfies `l` within `tol`, plus the floating-point bound of evaluating `a·v − b`.
fn within(l: &Line, v: [f64; 2], tol: f64) -> bool {
    let round =
        4.0 * f64::EPSILON * (l.a[0].abs() * v[0].abs() + l.a[1].abs() * v[1].abs() + l.b.abs());
    l.violation(v) <= tol + round
}

/// Scale the rows of `first` and `second` into `lines` (cleared first; allocation-free once
/// it has room for all rows) and [`check`] them with the box.
pub fn check_half_spaces(
    first: &[HalfSpace],
    second: &[HalfSpace],
    input_limit: Option<Input>,
    lines: &mut Vec<Line>,
) -> Feasibility {
    lines.clear();
    lines.extend(first.iter().chain(second).map(Line::from_half_space));
    check(lines, input_limit)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hs(nx: f64, ny: f64, o: f64) -> HalfSpace {
        HalfSpace {
            normal: Input::new(nx, ny),
            offset: o,
        }
    }

    fn verdict(rows: &[HalfSpace], limit: Option<Input>) -> Feasibility {
        let mut buf = Vec::new();
        check_half_spaces(rows, &[], limit, &mut buf)
    }

    /// A feasible witness must satisfy every (unscaled) row to the tolerance.
    fn assert_witness(rows: &[HalfSpace], limit: Option<Input>) -> Input {
        match verdict(rows, limit) {
            Feasibility::Feasible { witness } => {
                for h in rows {
                    let l = Line::from_half_space(h);
                    assert!(
                        l.violation([witness[0], witness[1]]) <= 1e-7,
                        "{witness} violates {h:?}"
                    );
                }
                if let Some(lim) = limit {
                    assert!(witness[0].abs() <= lim[0] + 1e-9 && witness[1].abs() <= lim[1] + 1e-9);
                }
                witness
            }
            Feasibility::Infeasible => panic!("{rows:?} should be feasible"),
        }
    }

    #[test]
    fn empty_set_of_rows_is_feasible() {
        assert_eq!(
            verdict(&[], None),
            Feasibility::Feasible {
                witness: Input::zeros()
            }
        );
    }

    #[test]
    fn scaling_matches_the_qp_rows() {
        let l = Line::from_half_space(&hs(3.0, 4.0, 10.0));
        assert_eq!(l.a, [0.6, 0.8]);
        assert!((l.b - 2.0).abs() < 1e-15);
        assert_eq!(Line::from_half_space(&hs(0.0, 0.0, 0.3)).b, 1.0);
        assert_eq!(Line::from_half_space(&hs(0.0, 0.0, -0.3)).b, -1.0);
        assert_eq!(Line::from_half_space(&hs(1.0, 1.0, f64::NAN)).b, -1.0);
    }

    #[test]
    fn non_finite_rows_fail_closed() {
        // A NaN or infinite normal is violated whatever the offset (it used to become the
        // always-satisfied 0·u ≤ 1 when the offset was finite and ≥ 0).
        for n in [
            [f64::NAN, 1.0],
            [1.0, f64::INFINITY],
            [f64::NEG_INFINITY, 0.0],
            [1e200, 1e200], // the norm overflows
        ] {
            for o in [0.3, 0.0, -0.3, f64::INFINITY] {
                let l = Line::from_half_space(&hs(n[0], n[1], o));
                assert_eq!((l.a, l.b), ([0.0, 0.0], -1.0), "normal {n:?}, offset {o}");
                assert_eq!(
                    verdict(&[hs(n[0], n[1], o), hs(0.0, 1.0, 1.0)], None),
                    Feasibility::Infeasible,
                    "normal {n:?}, offset {o}"
                );
            }
        }
    }

    #[test]
    fn degenerate_rows() {
        // 0·u ≤ −1 can never hold; 0·u ≤ 1 always holds
        assert_eq!(
            verdict(&[hs(0.0, 0.0, -0.1)], None),
            Feasibility::Infeasible
        );
        assert!(verdict(&[hs(0.0, 0.0, 0.1), hs(1.0, 0.0, -3.0)], None).is_feasible());
        // a NaN offset is a violated row (as in the QP)
        assert_eq!(
            verdict(&[hs(1.0, 0.0, f64::NAN)], None),
            Feasibility::Infeasible
        );
    }

    #[test]
    fn parallel_strips() {
        // 1 ≤ u_y ≤ 2: non-empty strip (no vertex among the rows themselves)
        let w = assert_witness(&[hs(0.0, -1.0, -1.0), hs(0.0, 2.0, 4.0)], None);
        assert!(w[1] >= 1.0 - 1e-9 && w[1] <= 2.0 + 1e-9);
        // u_y ≥ 2 and u_y ≤ 1: empty
        assert_eq!(
            verdict(&[hs(0.0, -1.0, -2.0), hs(0.0, 1.0, 1.0)], None),
            Feasibility::Infeasible
        );
        // same direction, both hold somewhere
        assert!(verdict(&[hs(0.0, 1.0, -5.0), hs(0.0, 3.0, 2.0)], None).is_feasible());
    }

    #[test]
    fn degenerate_single_point_and_segment() {
        // u_x = 1 and u_y = −0.5 as four half-planes: exactly one point
        let rows = [
            hs(1.0, 0.0, 1.0),
            hs(-1.0, 0.0, -1.0),
            hs(0.0, 1.0, -0.5),
            hs(0.0, -1.0, 0.5),
        ];
        let w = assert_witness(&rows, None);
        assert!((w - Input::new(1.0, -0.5)).norm() < 1e-12, "{w}");
        // the line u_x + u_y = 1 (two opposite half-planes), unbounded segment
        let rows = [hs(1.0, 1.0, 1.0), hs(-1.0, -1.0, -1.0)];
        assert_witness(&rows, None);
        // three lines through one point, as a triangle of zero area
        let rows = [hs(1.0, 0.0, 0.0), hs(0.0, 1.0, 0.0), hs(-1.0, -1.0, 0.0)];
        let w = assert_witness(&rows, None);
        assert!(w.norm() < 1e-12, "{w}");
        // the same shifted by 1e-3 inward-out: empty
        let rows = [hs(1.0, 0.0, 0.0), hs(0.0, 1.0, 0.0), hs(-1.0, -1.0, -1e-3)];
        assert_eq!(verdict(&rows, None), Feasibility::Infeasible);
    }

    #[test]
    fn box_edges() {
        let lim = Some(Input::new(1.0, 2.0));
        // u_x ≥ 1: exactly on the box edge — feasible
        let w = assert_witness(&[hs(-1.0, 0.0, -1.0)], lim);
        assert!((w[0] - 1.0).abs() < 1e-12);
        // u_x ≥ 1 + 1e-6: outside the box (far beyond the tolerance)
        assert_eq!(
            verdict(&[hs(-1.0, 0.0, -1.0 - 1e-6)], lim),
            Feasibility::Infeasible
        );
        // without a box the same row is feasible
        assert!(verdict(&[hs(-1.0, 0.0, -1.0 - 1e-6)], None).is_feasible());
        // u_x + u_y ≥ 3: the box corner (1, 2) only
        let w = assert_witness(&[hs(-1.0, -1.0, -3.0)], lim);
        assert!((w - Input::new(1.0, 2.0)).norm() < 1e-12, "{w}");
        assert_eq!(
            verdict(&[hs(-1.0, -1.0, -3.0 - 1e-6)], lim),
            Feasibility::Infeasible
        );
        // a zero-width box is the single point 0
        assert!(verdict(&[hs(1.0, 1.0, 0.0)], Some(Input::zeros())).is_feasible());
        assert_eq!(
            verdict(&[hs(1.0, 1.0, -1e-3)], Some(Input::zeros())),
            Feasibility::Infeasible
        );
        // a negative box is empty
        assert_eq!(
            verdict(&[], Some(Input::new(-1.0, 1.0))),
            Feasibility::Infeasible
        );
    }

    #[test]
    fn unbounded_without_box() {
        // a wedge far from the origin: u_x ≥ 1e3, u_y ≥ 1e3
        let w = assert_witness(&[hs(-1.0, 0.0, -1e3), hs(0.0, -1.0, -1e3)], None);
        assert!(w[0] >= 1e3 - 1e-6 && w[1] >= 1e3 - 1e-6);
        // a half-plane alone, and a thin wedge of angle 1e-3 rad ending 2e3 m/s² out
        assert_witness(&[hs(0.3, -0.7, -50.0)], None);
        let e: f64 = 1e-3;
        let rows = [hs(1.0, 0.0, -1.0), hs(-e.cos(), e.sin(), -1.0)];
        let w = assert_witness(&rows, None);
        assert!(w[1] < -1.9e3, "{w}");
        // with a 2 m/s² box the same wedge is out of reach
        assert_eq!(
            verdict(&rows, Some(Input::new(2.0, 2.0))),
            Feasibility::Infeasible
        );
        // beyond the virtual box: documented limit (every feasible input has |u_x| > 1e6)
        assert_eq!(
            verdict(&[hs(-1.0, 0.0, -2e6)], None),
            Feasibility::Infeasible
        );
    }

    #[test]
    fn triangle_inside_and_outside() {
        // u_y ≥ 0, u_y ≤ 1 − |u_x|: a triangle
        let tri = [hs(0.0, -1.0, 0.0), hs(1.0, 1.0, 1.0), hs(-1.0, 1.0, 1.0)];
        assert_witness(&tri, None);
        let mut more = tri.to_vec();
        more.push(hs(0.0, -1.0, -1.0 - 1e-6)); // u_y ≥ 1 + 1e-6: above the apex
        assert_eq!(verdict(&more, None), Feasibility::Infeasible);
        more.pop();
        more.push(hs(0.0, -1.0, -1.0)); // u_y ≥ 1: the apex only
        let w = assert_witness(&more, None);
        assert!((w - Input::new(0.0, 1.0)).norm() < 1e-12, "{w}");
    }

    /// The nearest admitted point: the target itself when feasible, its projection on the one
    /// violated row, a vertex when the projection leaves the set, None for an empty set.
    #[test]
    fn nearest_is_the_target_its_projection_or_a_vertex() {
        let lim = Some(Input::new(1.0, 1.0));
        let rows = [Line::from_half_space(&hs(1.0, 0.0, 0.5))]; // u_x ≤ 0.5
        let t = Input::new(0.2, 0.3);
        assert_eq!(nearest(&rows, lim, t), Some(t));
        let p = nearest(&rows, lim, Input::new(0.9, 0.3)).unwrap();
        assert!((p - Input::new(0.5, 0.3)).norm() < 1e-12, "{p}");
        let v = nearest(&rows, lim, Input::new(0.9, 3.0)).unwrap();
        assert!((v - Input::new(0.5, 1.0)).norm() < 1e-12, "{v}");
        let empty = [Line::from_half_space(&hs(1.0, 0.0, -2.0))]; // u_x ≤ −2 outside the box
        assert_eq!(nearest(&empty, lim, t), None);
    }
}
