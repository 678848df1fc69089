//! A [`BarrierIndex`] over planar ellipse obstacles (issue #52), for a user of this crate with
//! many [`EllipsoidOutside`] barriers (discs and ellipses on the floor) and no simulator: a
//! step then builds rows only for the ellipses within its reach radius of each estimate
//! ([`crate::reach`]), and a far ellipse costs next to nothing.
//!
//! ```
//! use std::sync::Arc;
//! use ftcbf_controller::ellipse_index::EllipseIndex;
//! use ftcbf_controller::{Barrier, EllipsoidOutside, HalfPlane, State};
//!
//! let discs: Vec<EllipsoidOutside> = (0..100)
//!     .map(|i| EllipsoidOutside::disc(format!("post{i}"), 0.5 * i as f64, 4.0, 0.1))
//!     .collect();
//! let mut barriers: Vec<Arc<dyn Barrier>> =
//!     vec![Arc::new(HalfPlane::new("floor", State::new(0.0, 1.0, 0.0, 0.2), -0.05))];
//! // The discs follow the floor: positions 1..=100 of the controller's list.
//! let index = EllipseIndex::new(101, discs.iter().enumerate().map(|(i, d)| (i + 1, d)))?;
//! barriers.extend(discs.into_iter().map(|d| Arc::new(d) as Arc<dyn Barrier>));
//! // ControllerConfig::builder(..).barriers(barriers).barrier_index(Arc::new(index))
//! # let _ = (barriers, index);
//! # Ok::<(), ftcbf_controller::ellipse_index::EllipseIndexError>(())
//! ```
//!
//! # What is covered
//!
//! An `EllipsoidOutside` whose Φ acts on the position only: its entries in the velocity rows
//! and columns are zero and its position block P (2×2) is positive definite. Then
//! `h(x) = eᵀPe − 1` with e = p − c (p the position, c the centre), and its region is the
//! ellipse E = {p : eᵀPe ≤ 1}, with semi-axes 1/√λ_max(P) ≤ 1/√λ_min(P) =: β_k. Anything else
//! is refused by [`EllipseIndex::new`] (it would have to be evaluated at every step anyway).
//!
//! # The bound, and why it certifies the reach condition
//!
//! Write s = √(eᵀPe), so h = s² − 1.
//!
//! 1. **h grows with the distance.** Scaling E about c by t ≥ 1 moves each point q of E by
//!    (t − 1)‖q − c‖ ≤ (t − 1)β_k, so tE lies within distance (t − 1)β_k of E. A position at
//!    distance ≥ D from E is therefore outside (1 + D/β_k)E: s ≥ 1 + D/β_k ≥ 1 + D/β =: s₀
//!    with β the largest β_k over the covered ellipses, and h ≥ s₀² − 1 (the `h_lower` of
//!    [`BarrierIndex::far_bounds`]).
//! 2. **The gradient grows only linearly in s.** ∂h = (2Pe, 0), and
//!    ‖Pe‖ = ‖P^½(P^½e)‖ ≤ √λ_max(P)·s, so ‖∂h_p‖ ≤ 2αs with α the largest √λ_max(P) over the
//!    covered ellipses; the Hessian's position block is 2P: ‖∇²h_pp‖_F = 2‖P‖_F ≤ 2φ, φ the
//!    largest ‖P‖_F. No bound on ‖∂h‖ holds at every distance ≥ D (it grows with s), which is
//!    why this index decides the reach condition itself ([`BarrierIndex::out_of_reach`]).
//! 3. **The condition.** h depends on the position only, so (module docs of
//!    [`crate::reach`]) the row of ellipse k holds for every input of the box when
//!    κ(h − h̄) > ‖∂h_p‖A_p + ‖∇²h_pp‖_F B_p, with h̄ ≥ h̄_γ of ellipse k (the controller
//!    passes the largest over the covered barriers). By 1–2 this follows from
//!    `f(s) := κ(s² − 1 − h̄) − 2αA_p·s − 2φB_p > 0`. f is a parabola opening upwards with its
//!    vertex at s_v = αA_p/κ, so f(s₀) > 0 with s₀ ≥ s_v gives f(s) > 0 for every s ≥ s₀, in
//!    particular at every covered ellipse's own s. The index's condition at distance D is
//!    exactly `s₀ ≥ s_v and f(s₀) > 0` (and s₀² − 1 − h̄ ≥ δ for a finite δ): true at D, it
//!    stays true at every larger D (s₀ grows with D), as the radius search needs.
//!
//! The tree returns every covered ellipse whose bounding box comes within the radius of the
//! query point (the box contains the ellipse, so an ellipse it does not return is farther than
//! the radius). Every computed bound is widened by a relative 1e-9, far above the rounding of
//! the eigenvalues and boxes it is computed from.

use crate::barrier::{Barrier, EllipsoidOutside};
use crate::reach::{BarrierIndex, FarBounds, ReachTerms};

/// Relative widening of every computed bound and box (far above f64 rounding).
const PAD: f64 = 1e-9;

/// Leaves hold at most this many ellipses.
const LEAF: usize = 4;

/// Why an [`EllipseIndex`] cannot be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EllipseIndexError {
    /// The barrier is not an ellipse on the floor (module docs).
    #[error("barrier {position} ('{name}') cannot be indexed: {reason}")]
    NotPlanar {
        /// Its position in the controller's barrier list.
        position: usize,
        /// Its name.
        name: String,
        /// What was expected.
        reason: &'static str,
    },
    /// A position beyond the controller's barrier list.
    #[error("barrier position {position} is outside the controller's list of {total} barriers")]
    OutOfRange {
        /// The position given.
        position: usize,
        /// The number of barriers of the controller.
        total: usize,
    },
    /// A position given twice.
    #[error("barrier position {position} is given twice")]
    Duplicate {
        /// The position given.
        position: usize,
    },
}

/// A node of the bounding-box tree: its box and either a range of `items` (a leaf) or two
/// children.
#[derive(Debug, Clone, Copy)]
struct Node {
    bbox: [f64; 4],
    start: usize,
    end: usize,
    children: Option<(usize, usize)>,
}

/// A [`BarrierIndex`] over planar ellipses (module docs): a bounding-box tree and the
/// certified reach condition.
#[derive(Debug, Clone)]
pub struct EllipseIndex {
    covered: Vec<bool>,
    /// Bounding boxes `[x_min, y_min, x_max, y_max]` of the covered ellipses with their
    /// barrier positions, in tree order.
    items: Vec<([f64; 4], usize)>,
    nodes: Vec<Node>,
    /// β: the largest semi-axis \[m\].
    semi_axis: f64,
    /// α: the largest √λ_max(P) \[1/m\].
    sqrt_lambda: f64,
    /// φ: the largest ‖P‖_F \[1/m²\].
    phi_norm: f64,
}

/// The planar quantities of one ellipse: (bounding box, β_k, √λ_max, ‖P‖_F).
fn planar(
    position: usize,
    e: &EllipsoidOutside,
) -> Result<([f64; 4], f64, f64, f64), EllipseIndexError> {
    let err = |reason| EllipseIndexError::NotPlanar {
        position,
        name: e.name().to_string(),
        reason,
    };
    let phi = &e.phi;
    let velocity_free = (0..4).all(|i| (2..4).all(|j| phi[(i, j)] == 0.0 && phi[(j, i)] == 0.0));
    if !velocity_free {
        return Err(err(
            "Φ must act on the position only (zero velocity rows and columns)",
        ));
    }
    let (a, b, d) = (phi[(0, 0)], phi[(0, 1)], phi[(1, 1)]);
    let (cx, cy) = (e.center[0], e.center[1]);
    if ![a, b, d, cx, cy].iter().all(|v| v.is_finite()) {
        return Err(err("Φ and the centre's position must be finite"));
    }
    let det = a * d - b * b;
    if !(a > 0.0 && det > 0.0) {
        return Err(err(
            "Φ's position block must be positive definite (a bounded ellipse)",
        ));
    }
    let lambda_max = 0.5 * (a + d) + (0.5 * (a - d)).hypot(b);
    let lambda_min = det / lambda_max;
    let semi = (1.0 + PAD) / lambda_min.sqrt();
    // Half-widths of the ellipse eᵀPe ≤ 1: √((P⁻¹)₀₀), √((P⁻¹)₁₁).
    let (wx, wy) = ((d / det).sqrt(), (a / det).sqrt());
    let pad = |c: f64, w: f64| PAD * (1.0 + c.abs() + w);
    let bbox = [
        cx - wx - pad(cx, wx),
        cy - wy - pad(cy, wy),
        cx + wx + pad(cx, wx),
        cy + wy + pad(cy, wy),
    ];
    let frob = (a * a + 2.0 * b * b + d * d).sqrt();
    if !(bbox.iter().all(|v| v.is_finite()) && semi.is_finite()) {
        return Err(err("the ellipse's extent must be finite"));
    }
    Ok((
        bbox,
        semi,
        (1.0 + PAD) * lambda_max.sqrt(),
        (1.0 + PAD) * frob,
    ))
}

/// The planar distance from `p` to the box `b` (0 inside).
fn box_distance(b: &[f64; 4], p: [f64; 2]) -> f64 {
    let dx = (b[0] - p[0]).max(p[0] - b[2]).max(0.0);
    let dy = (b[1] - p[1]).max(p[1] - b[3]).max(0.0);
    dx.hypot(dy)
}

/// The box holding every box of `items`.
fn union(items: &[([f64; 4], usize)]) -> [f64; 4] {
    items.iter().fold(
        [
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        ],
        |u, (b, _)| {
            [
                u[0].min(b[0]),
                u[1].min(b[1]),
                u[2].max(b[2]),
                u[3].max(b[3]),
            ]
        },
    )
}

/// Builds the subtree over `items[start..end]` (reordering them), returning its node.
fn build(
    items: &mut [([f64; 4], usize)],
    start: usize,
    end: usize,
    nodes: &mut Vec<Node>,
) -> usize {
    let bbox = union(&items[start..end]);
    let at = nodes.len();
    nodes.push(Node {
        bbox,
        start,
        end,
        children: None,
    });
    if end - start > LEAF {
        // Split at the median centre along the longer side (ties by barrier position: the
        // tree does not depend on the sort's stability).
        let axis = usize::from(bbox[3] - bbox[1] > bbox[2] - bbox[0]);
        items[start..end].sort_by(|(p, i), (q, j)| {
            (p[axis] + p[axis + 2])
                .total_cmp(&(q[axis] + q[axis + 2]))
                .then(i.cmp(j))
        });
        let mid = start + (end - start) / 2;
        let left = build(items, start, mid, nodes);
        let right = build(items, mid, end, nodes);
        nodes[at].children = Some((left, right));
    }
    at
}

impl EllipseIndex {
    /// The index over `ellipses` given with their positions in the controller's list of
    /// `total` barriers. Errors: an ellipse that is not planar (module docs), a position out
    /// of range or given twice.
    pub fn new<'a>(
        total: usize,
        ellipses: impl IntoIterator<Item = (usize, &'a EllipsoidOutside)>,
    ) -> Result<Self, EllipseIndexError> {
        let mut covered = vec![false; total];
        let mut items = Vec::new();
        let (mut semi_axis, mut sqrt_lambda, mut phi_norm) = (0.0_f64, 0.0_f64, 0.0_f64);
        for (position, e) in ellipses {
            match covered.get_mut(position) {
                None => return Err(EllipseIndexError::OutOfRange { position, total }),
                Some(true) => return Err(EllipseIndexError::Duplicate { position }),
                Some(c) => *c = true,
            }
            let (bbox, semi, sl, pn) = planar(position, e)?;
            semi_axis = semi_axis.max(semi);
            sqrt_lambda = sqrt_lambda.max(sl);
            phi_norm = phi_norm.max(pn);
            items.push((bbox, position));
        }
        let mut nodes = Vec::new();
        if !items.is_empty() {
            let n = items.len();
            build(&mut items, 0, n, &mut nodes);
        }
        Ok(Self {
            covered,
            items,
            nodes,
            semi_axis,
            sqrt_lambda,
            phi_norm,
        })
    }

    /// Number of covered barriers.
    pub fn covered_count(&self) -> usize {
        self.items.len()
    }

    fn visit(&self, node: usize, p: [f64; 2], radius: f64, out: &mut Vec<usize>) {
        let n = self.nodes[node];
        if box_distance(&n.bbox, p) > radius {
            return;
        }
        match n.children {
            Some((l, r)) => {
                self.visit(l, p, radius, out);
                self.visit(r, p, radius, out);
            }
            None => {
                for (b, position) in &self.items[n.start..n.end] {
                    if box_distance(b, p) <= radius {
                        out.push(*position);
                    }
                }
            }
        }
    }
}

impl BarrierIndex for EllipseIndex {
    fn covers(&self, b: usize) -> bool {
        self.covered.get(b).copied().unwrap_or(false)
    }

    /// h ≥ (1 + D/β)² − 1 and ‖∇²h‖_F ≤ 2φ (module docs); no bound on ‖∂h‖ holds at every
    /// distance ≥ D, so `gradient` is +∞ (the reach condition is decided by
    /// [`EllipseIndex::out_of_reach`]).
    fn far_bounds(&self, dist: f64, _speed: f64) -> FarBounds {
        if self.items.is_empty() {
            // Nothing is covered: every statement about the covered barriers holds.
            return FarBounds {
                h_lower: f64::INFINITY,
                gradient: 0.0,
                hessian: 0.0,
            };
        }
        let s = 1.0 + dist.max(0.0) / self.semi_axis;
        FarBounds {
            h_lower: if dist >= 0.0 {
                s * s - 1.0
            } else {
                f64::NEG_INFINITY
            },
            gradient: f64::INFINITY,
            hessian: 2.0 * self.phi_norm,
        }
    }

    fn near(&self, p: [f64; 2], radius: f64, out: &mut Vec<usize>) {
        if !self.nodes.is_empty() {
            self.visit(0, p, radius, out);
        }
    }

    /// `s₀ ≥ αA_p/κ` and `κ(s₀² − 1 − h̄) > 2αA_p·s₀ + 2φB_p` with s₀ = 1 + D/β (module docs).
    fn out_of_reach(&self, terms: &ReachTerms, dist: f64) -> bool {
        if self.items.is_empty() {
            return true;
        }
        if dist.is_nan() || dist < 0.0 {
            return false;
        }
        let s = 1.0 + dist / self.semi_axis;
        let slope = self.sqrt_lambda * terms.a_planar;
        let past_vertex = terms.kappa * s >= slope;
        let need = 2.0 * slope * s + 2.0 * self.phi_norm * terms.b_planar;
        past_vertex && terms.condition(s * s - 1.0, need)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::types::{State, StateMatrix};

    fn terms() -> ReachTerms {
        ReachTerms {
            kappa: 1.0,
            h_bar: 1.1025,
            a: 4.5,
            b: 0.0,
            a_planar: 0.5,
            b_planar: 0.0,
            delta: f64::INFINITY,
            speed: 0.5,
        }
    }

    #[test]
    fn refuses_what_it_cannot_bound() {
        let disc = EllipsoidOutside::disc("d", 0.0, 0.0, 0.1);
        let mut phi = disc.phi;
        phi[(0, 2)] = 1.0;
        let lifted = EllipsoidOutside::new("v", State::zeros(), phi);
        let e = EllipseIndex::new(2, [(1, &lifted)]).unwrap_err();
        assert!(
            matches!(e, EllipseIndexError::NotPlanar { position: 1, .. }),
            "{e}"
        );
        let strip = EllipsoidOutside::new(
            "strip",
            State::zeros(),
            StateMatrix::from_diagonal(&State::new(1.0, 0.0, 0.0, 0.0)),
        );
        assert!(EllipseIndex::new(1, [(0, &strip)]).is_err());
        assert_eq!(
            EllipseIndex::new(1, [(1, &disc)]).unwrap_err(),
            EllipseIndexError::OutOfRange {
                position: 1,
                total: 1
            }
        );
        assert_eq!(
            EllipseIndex::new(2, [(0, &disc), (0, &disc)]).unwrap_err(),
            EllipseIndexError::Duplicate { position: 0 }
        );
    }

    #[test]
    fn near_returns_exactly_the_boxes_within_the_radius() {
        let discs: Vec<_> = (0..300)
            .map(|i| {
                let (x, y) = ((i % 20) as f64 * 0.7 - 5.0, (i / 20) as f64 * 0.9 - 6.0);
                EllipsoidOutside::disc(format!("d{i}"), x, y, 0.05 + 0.01 * (i % 7) as f64)
            })
            .collect();
        let index = EllipseIndex::new(301, discs.iter().enumerate().map(|(i, d)| (i + 1, d)))
            .expect("planar discs");
        assert_eq!(index.covered_count(), 300);
        assert!(!index.covers(0) && index.covers(1) && index.covers(300));
        let mut out = Vec::with_capacity(301);
        for (p, r) in [([0.3, -0.2], 1.5), ([-7.0, 9.0], 2.0), ([2.0, 2.0], 0.0)] {
            out.clear();
            index.near(p, r, &mut out);
            out.sort_unstable();
            let expected: Vec<usize> = discs
                .iter()
                .enumerate()
                .filter(|(_, d)| {
                    let rad = 1.0 / d.phi[(0, 0)].sqrt();
                    let c = [d.center[0], d.center[1]];
                    box_distance(&[c[0] - rad, c[1] - rad, c[0] + rad, c[1] + rad], p) <= r
                })
                .map(|(i, _)| i + 1)
                .collect();
            assert_eq!(out, expected, "p = {p:?}, r = {r}");
        }
    }

    /// The certified condition against the rows' own terms: at every sampled state whose
    /// position is beyond the radius of a disc, the right side of the reach condition computed
    /// from the barrier's actual ∂h and ∇²h is below κ(h − h̄).
    #[test]
    fn beyond_the_radius_every_ellipse_is_slack() {
        let ellipses = [
            EllipsoidOutside::disc("disc", 1.0, 2.0, 0.1),
            EllipsoidOutside::new(
                "ellipse",
                State::new(-1.0, 0.5, 0.0, 0.0),
                StateMatrix::from_diagonal(&State::new(4.0, 100.0, 0.0, 0.0)),
            ),
        ];
        let index = EllipseIndex::new(2, ellipses.iter().enumerate()).expect("planar");
        let mut t = terms();
        t.b_planar = 1e-3;
        let radius = t.radius(&index);
        assert!(radius.is_finite() && radius > 0.0, "{radius}");
        // s₀ = 1 + D/β with β = 1/√4 = 0.5: the disc's own s is larger.
        assert!(!index.out_of_reach(&t, radius - 2e-3));
        for k in 0..400 {
            let angle = k as f64 * 0.157;
            let extra = (k % 9) as f64 * 0.7;
            for e in &ellipses {
                // a point at distance ≥ radius from the ellipse: beyond its bounding circle
                let semi = 1.0 / e.phi[(0, 0)].min(e.phi[(1, 1)]).sqrt();
                let reach = semi + radius + extra;
                let x = State::new(
                    e.center[0] + reach * angle.cos(),
                    e.center[1] + reach * angle.sin(),
                    0.3,
                    -0.2,
                );
                let ev = e.eval(&x);
                let grad_p = ev.gradient.fixed_rows::<2>(0).norm();
                let hess_pp = ev.hessian.fixed_view::<2, 2>(0, 0).norm();
                let need = grad_p * t.a_planar + hess_pp * t.b_planar;
                assert!(
                    t.kappa * (ev.value - t.h_bar) > need,
                    "{} at {x:?}: h = {}, need {need}",
                    e.name(),
                    ev.value
                );
                assert!(ev.value >= index.far_bounds(radius, 0.0).h_lower);
            }
        }
    }

    #[test]
    fn the_condition_is_monotone_in_the_distance() {
        let d = EllipsoidOutside::disc("d", 0.0, 0.0, 0.2);
        let index = EllipseIndex::new(1, [(0, &d)]).expect("planar");
        for a in [0.0, 0.3, 2.0, 10.0] {
            let mut t = terms();
            t.a_planar = a;
            t.h_bar = -5.0; // even a nonsensical h̄ keeps the vertex rule monotone
            let mut seen = false;
            for k in 0..2000 {
                let holds = index.out_of_reach(&t, k as f64 * 0.01);
                assert!(!seen || holds, "a = {a}: true then false at {k}");
                seen |= holds;
            }
            assert!(seen, "a = {a}: never out of reach within 20 m");
        }
    }
}
