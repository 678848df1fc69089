//! The objective: how close one run came to being unsafe, measured on the truth.

use std::cmp::Ordering;

use ftcbf_sim::summary::RunSummary;
use ftcbf_sim::world::World;
use serde::{Deserialize, Serialize};

/// The robustness ρ of one run: the minimum over time of every safety margin on the true state,
/// namely h(x_true) of each declared safe set (the value whose sign decides a safe-set violation)
/// and the signed robot–obstacle clearance \[m\] (negative = penetration). ρ < 0 means unsafe.
///
/// A collision is always worse than any run without one ("collisions are the most negative"):
/// runs are ordered first by `collided`, then by `value` (see [`Robustness::cmp_worse`]). A
/// grazing contact can have a `value` slightly above 0 (contacts are detected every physics tick,
/// clearances measured every control step); it is still a collision.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Robustness {
    /// min over time and over margins [unit of the binding margin].
    pub value: f64,
    /// The robot touched an obstacle.
    pub collided: bool,
    /// Which margin attains the minimum: a safe-set name, or `clearance to obstacles`.
    pub binding: String,
}

/// What [`Robustness::binding`] says for the obstacle clearance.
pub const CLEARANCE: &str = "clearance to obstacles";

impl Robustness {
    /// ρ of a run of `world` (the safe-set minima are the first `world.file.safe_sets.len()`
    /// entries of `summary.min_barrier`; obstacle barriers there are lifted and not a safety
    /// measure, so the true clearance is used for obstacles instead). `None` when the world has
    /// neither safe sets nor obstacles (nothing can be unsafe).
    pub fn of(world: &World, summary: &RunSummary) -> Option<Robustness> {
        let sets = world.file.safe_sets.len().min(summary.min_barrier.len());
        let mut best: Option<(f64, String)> = None;
        let mut consider = |v: f64, name: &str| {
            // A non-finite margin (a plant that blew up) counts as −∞.
            let v = if v.is_nan() { f64::NEG_INFINITY } else { v };
            if best.as_ref().is_none_or(|(b, _)| v < *b) {
                best = Some((v, name.to_string()));
            }
        };
        for b in &summary.min_barrier[..sets] {
            consider(b.value, &b.name);
        }
        if let Some(c) = summary.min_clearance {
            consider(c, CLEARANCE);
        }
        let (value, binding) = best?;
        Some(Robustness {
            value,
            collided: summary.collided,
            binding,
        })
    }

    /// `Less` when `self` is less robust (worse for the controller) than `other`: a collision
    /// before none, then the smaller value.
    pub fn cmp_worse(&self, other: &Robustness) -> Ordering {
        other
            .collided
            .cmp(&self.collided)
            .then(self.value.total_cmp(&other.value))
    }

    /// Unsafe: a collision or a negative margin.
    pub fn is_unsafe(&self) -> bool {
        self.collided || self.value < 0.0
    }

    /// `-0.1234 (floor)` or `-0.0008 (clearance to obstacles, collision)`.
    pub fn display(&self) -> String {
        format!(
            "{:.4} ({}{})",
            self.value,
            self.binding,
            if self.collided { ", collision" } else { "" }
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn r(value: f64, collided: bool) -> Robustness {
        Robustness {
            value,
            collided,
            binding: "x".into(),
        }
    }

    #[test]
    fn collisions_rank_below_everything() {
        assert_eq!(r(0.01, true).cmp_worse(&r(-5.0, false)), Ordering::Less);
        assert_eq!(r(-0.2, false).cmp_worse(&r(-0.1, false)), Ordering::Less);
        assert_eq!(r(-0.2, true).cmp_worse(&r(-0.1, true)), Ordering::Less);
        assert_eq!(r(0.3, false).cmp_worse(&r(0.3, false)), Ordering::Equal);
        assert!(r(0.01, true).is_unsafe() && r(-1e-9, false).is_unsafe());
        assert!(!r(0.0, false).is_unsafe());
    }
}
