//! The estimation error of every filter of the bank against the truth, next to its γ: the
//! hypothesis Pr(sup_t ‖x_t − x̂_i,t‖ ≤ γ_i) ≥ 1 − ε of Theorem 3 (thesis Theorem 1, §4.3)
//! measured where it can be, in a simulator that knows x_t.

use ftcbf_controller::estimator::{EstimatorBank, FilterRole};
use ftcbf_controller::params::pair_slot;

use crate::attacks::AttackStack;
use crate::summary::EstimationError;
use crate::world::World;

use crate::model::setup::ControlSetup;

/// The γ each filter of the bank is held to: γ_i for the filter that drops pattern i, γ_ij for
/// the one that drops i and j (computed bounds only), γ of the baseline for `all`.
pub fn filter_gammas(bank: &EstimatorBank, setup: &ControlSetup) -> Vec<Option<f64>> {
    let ft = &setup.config.ft;
    let m = bank.patterns();
    bank.filters()
        .iter()
        .map(|f| match f.role() {
            FilterRole::DropPattern(i) => ft.gamma.get(i).copied(),
            // γ_ij in the packed pair order of FtDerivation::gamma_pair.
            FilterRole::DropPair(i, j) => setup
                .params
                .derivation
                .as_ref()
                .zip(pair_slot(m, i, j))
                .and_then(|(c, k)| c.gamma_pair.get(k).copied()),
            FilterRole::Baseline => Some(ft.gamma_baseline),
        })
        .map(|g| g.filter(|g| g.is_finite() && *g > 0.0))
        .collect()
}

/// Whether each filter reads no attacked channel: every attack's targets lie in the patterns
/// the filter drops (all filters without attacks; never the baseline under attack).
pub fn honest_filters(bank: &EstimatorBank, attacks: &AttackStack, world: &World) -> Vec<bool> {
    let dropped = |role: FilterRole| -> Vec<usize> {
        let of = |i: usize| world.patterns.get(i).cloned().unwrap_or_default();
        match role {
            FilterRole::DropPattern(i) => of(i),
            FilterRole::DropPair(i, j) => [of(i), of(j)].concat(),
            FilterRole::Baseline => Vec::new(),
        }
    };
    bank.filters()
        .iter()
        .map(|f| {
            let d = dropped(f.role());
            (0..attacks.len()).all(|a| {
                attacks
                    .targets(a)
                    .is_none_or(|t| t.iter().all(|s| d.contains(s)))
            })
        })
        .collect()
}

/// Raises the running maximum `max` to `v`. A non-finite `v` is the worst there is (NaN never
/// wins a `>`), so it pins the maximum at ∞. Returns whether the maximum rose.
fn raise(max: &mut f64, v: f64) -> bool {
    let v = if v.is_finite() { v } else { f64::INFINITY };
    let rose = v > *max;
    if rose {
        *max = v;
    }
    rose
}

/// Running maxima of ‖x − x̂_i‖ per filter (allocated once per run).
#[derive(Debug, Clone, Default)]
pub struct ErrorMeter {
    rows: Vec<EstimationError>,
}

impl ErrorMeter {
    /// A meter for filters with these labels, bounds and honesty.
    pub fn new(labels: &[String], gammas: &[Option<f64>], honest: &[bool]) -> Self {
        let rows = labels
            .iter()
            .enumerate()
            .map(|(i, l)| EstimationError {
                filter: l.clone(),
                gamma: gammas.get(i).copied().flatten(),
                honest: honest.get(i).copied().unwrap_or(false),
                max_error: 0.0,
                max_position_error: 0.0,
                max_velocity_error: 0.0,
                max_ratio: gammas.get(i).copied().flatten().map(|_| 0.0),
                t_worst: 0.0,
                steps_over: 0,
            })
            .collect();
        Self { rows }
    }

    /// Compares filter `i`'s estimate `xh` with the truth `x` = (p_x, p_y, v_x, v_y) at time
    /// `t`; returns its ‖x − x̂‖ / γ (NaN without γ, or for an unknown filter).
    pub fn observe(&mut self, i: usize, t: f64, x: [f64; 4], xh: [f64; 4]) -> f64 {
        let Some(row) = self.rows.get_mut(i) else {
            return f64::NAN;
        };
        let d = [x[0] - xh[0], x[1] - xh[1], x[2] - xh[2], x[3] - xh[3]];
        let pos = d[0].hypot(d[1]);
        let vel = d[2].hypot(d[3]);
        let err = pos.hypot(vel);
        raise(&mut row.max_position_error, pos);
        raise(&mut row.max_velocity_error, vel);
        let err_rose = raise(&mut row.max_error, err);
        let ratio = row.gamma.map_or(f64::NAN, |g| err / g);
        // The worst step is the largest ratio, or the largest error without γ.
        let worst_rose = match row.max_ratio.as_mut() {
            Some(m) => {
                if ratio.is_nan() || ratio > 1.0 {
                    row.steps_over += 1;
                }
                raise(m, ratio)
            }
            None => err_rose,
        };
        if worst_rose {
            row.t_worst = t;
        }
        ratio
    }

    /// The rows so far.
    pub fn rows(&self) -> &[EstimationError] {
        &self.rows
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn maxima_ratio_and_steps_over() {
        let labels = vec!["a".to_string(), "b".to_string()];
        let mut m = ErrorMeter::new(&labels, &[Some(0.5), None], &[true, false]);
        // a: error (0.3, 0.4) → 0.5, ratio 1.0 (not over); b: no γ
        let r = m.observe(0, 0.1, [0.0; 4], [0.3, 0.4, 0.0, 0.0]);
        assert!((r - 1.0).abs() < 1e-12);
        assert!(m.observe(1, 0.1, [0.0; 4], [0.0, 0.0, 0.1, 0.0]).is_nan());
        // a: velocity error 0.6 → ratio 1.2 (over)
        m.observe(0, 0.2, [0.0; 4], [0.0, 0.0, 0.6, 0.0]);
        m.observe(1, 0.2, [0.0; 4], [0.0; 4]);
        assert!(
            m.observe(2, 0.2, [0.0; 4], [0.0; 4]).is_nan(),
            "no such filter"
        );
        let a = &m.rows()[0];
        assert_eq!(a.steps_over, 1);
        assert!((a.max_ratio.unwrap() - 1.2).abs() < 1e-12);
        assert!((a.max_position_error - 0.5).abs() < 1e-12);
        assert!((a.max_velocity_error - 0.6).abs() < 1e-12);
        assert!((a.t_worst - 0.2).abs() < 1e-12);
        assert!(a.exceeded());
        let b = &m.rows()[1];
        assert!(!b.exceeded());
        assert!((b.max_error - 0.1).abs() < 1e-12);
        assert!((b.t_worst - 0.1).abs() < 1e-12);
    }

    #[test]
    fn non_finite_estimate_counts_as_over() {
        let labels = vec!["a".to_string()];
        let mut m = ErrorMeter::new(&labels, &[Some(1.0)], &[true]);
        m.observe(0, 0.0, [0.0; 4], [f64::NAN, 0.0, 0.0, 0.0]);
        m.observe(0, 0.1, [0.0; 4], [0.1, 0.0, 0.0, 0.0]);
        let a = &m.rows()[0];
        assert!(a.max_error.is_infinite());
        assert_eq!(a.max_ratio, Some(f64::INFINITY));
        assert_eq!(a.steps_over, 1);
        assert!(a.exceeded());
        assert_eq!(a.t_worst, 0.0);
    }
}
