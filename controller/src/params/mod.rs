//! Parameter computation of §4.3 and checks of the sufficient conditions of §4.2.
//!
//! * γ_i: the estimation error of filter i at steady state is Gaussian, `e ~ N(0, P)`, with
//!   P the steady-state posterior covariance of the discrete Riccati recursion
//!   ([`steady_state_riccati`], iterated to convergence). Since `‖e‖² ≤ λ̄(P) eᵀP⁻¹e` and
//!   `eᵀP⁻¹e ~ χ²_n`, `γ = sqrt(λ̄(P) · χ²_n⁻¹(1 − ε'))` gives `Pr(‖e‖ > γ) ≤ ε'` at one
//!   sample ([`gamma_bound`]).
//! * The whole-horizon event of (4.5) is bounded by a union bound: for N samples and the
//!   m events per sample (filter i and the m − 1 pair filters x̂_ij), `ε' = ε/(N m)`.
//! * θ_ij: `‖x̂_i − x̂_ij‖ ≤ ‖x̂_i − x‖ + ‖x̂_ij − x‖ ≤ γ_i + γ_ij`, so θ_ij/2 =
//!   max(γ_i, γ_j) + γ_ij makes the Step-2 test of the fault-free filter pass on that event.
//! * χ² quantiles, the regularised incomplete gamma function and log-gamma come from `statrs`
//!   (thin wrappers here keep the NaN conventions the callers rely on).

mod detectability;
mod ft;
mod pairs;
mod riccati;
mod separation;
mod special;

pub use detectability::*;
pub use ft::*;
pub use pairs::*;
pub use riccati::*;
pub use separation::*;
pub use special::*;

#[cfg(test)]
mod tests {
    use super::riccati::riccati_step;
    use super::*;
    use crate::model::LinearModel;
    use crate::types::{Input, State, StateMatrix};

    /// The steady-state filter's response to a constant offset on its readings. An offset b on
    /// both x channels of the paper's observation moves the estimate to exactly (b, 0, 0, 0)
    /// (a still robot b further along x explains every reading). An offset on the ẋ channel
    /// alone, contradicted by the position channels, leaves a bounded position offset and a
    /// velocity offset short of the reading's.
    #[test]
    fn update_gains_move_the_estimate_by_the_filters_response() {
        let model = LinearModel::paper_double_integrator(1e-3, 1e-3).unwrap();
        let dt = 0.02;
        let phi = model.discretize(dt).phi;
        let uses = [true; 6];
        let ss = steady_state_riccati(&model, &uses, dt);
        assert!(ss.converged);
        let gains = update_gains(&model, &uses, &ss.prior);
        assert_eq!(gains.len(), 6);
        let settle = |d: [f64; 6], steps: usize| {
            let mut e = State::zeros();
            for _ in 0..steps {
                e = phi * e;
                for (k, kg, ikc) in &gains {
                    e = ikc * e + kg * d[*k];
                }
            }
            e
        };
        let fix = settle([0.3, 0.3, 0.0, 0.0, 0.0, 0.0], 20_000);
        assert!((fix[0] - 0.3).abs() < 1e-9, "{fix}");
        assert!(fix[1].abs() < 1e-12 && fix[2].abs() < 1e-9 && fix[3].abs() < 1e-12);
        let vel = settle([0.0, 0.0, 0.0, 0.0, 0.1, 0.0], 20_000);
        let later = settle([0.0, 0.0, 0.0, 0.0, 0.1, 0.0], 40_000);
        assert!((vel - later).amax() < 1e-9, "not settled: {vel} vs {later}");
        assert!(vel[0] > 0.0 && vel[0] < 1.0, "{vel}");
        assert!(vel[2] > 0.0 && vel[2] < 0.1, "{vel}");
    }

    /// The packed layout is the order (0,1), (0,2), …, (1,2), … in which [`FtComputed`]
    /// computes its pair values, whichever way round a pair is asked for.
    #[test]
    fn pair_table_packs_pairs_in_the_computation_order() {
        for m in 0..7 {
            let mut order = Vec::new();
            for i in 0..m {
                for j in (i + 1)..m {
                    order.push((i, j));
                }
            }
            assert_eq!(pair_count(m), order.len());
            for (k, &(i, j)) in order.iter().enumerate() {
                assert_eq!(pair_slot(m, i, j), Some(k));
                assert_eq!(pair_slot(m, j, i), Some(k));
            }
            for i in 0..m {
                assert_eq!(pair_slot(m, i, i), None);
                assert_eq!(pair_slot(m, i, m), None);
            }
            let mut t = PairTable::from_fn(m, |i, j| 10 * i + j);
            assert_eq!(t.items(), m);
            let listed: Vec<(usize, usize)> = t.iter().map(|(p, _)| p).collect();
            assert_eq!(listed, order);
            for &(i, j) in &order {
                assert_eq!((t[(i, j)], t[(j, i)]), (10 * i + j, 10 * i + j));
            }
            if m >= 3 {
                t[(2, 0)] = 99;
                assert_eq!(t.get(0, 2), Some(&99));
                assert_eq!(t.as_slice()[1], 99);
            }
            assert_eq!(t.get(0, 0), None);
        }
    }

    /// A per-pair list holds one value for all pairs or one per pair in packed order.
    #[test]
    fn per_pair_values_are_one_for_all_or_packed() {
        assert_eq!(FtParams::per_pair(&[0.5], 3, 2, 1), Some(0.5));
        assert_eq!(FtParams::per_pair(&[0.1, 0.2, 0.3], 3, 2, 1), Some(0.3));
        assert_eq!(FtParams::per_pair(&[0.1, 0.2, 0.3], 3, 0, 2), Some(0.2));
        assert_eq!(FtParams::per_pair::<f64>(&[], 3, 0, 1), None);
        assert_eq!(FtParams::per_pair(&[0.1, 0.2], 3, 1, 2), None);
        let p = FtParams::uniform(3, 0.01, 0.2);
        assert_eq!(
            (p.gamma, p.gamma_baseline, p.theta),
            (vec![0.01; 3], 0.01, vec![0.2])
        );
        assert!(p.eta.is_empty() && p.increment_metric.is_empty() && p.theta_schedule.is_none());
    }

    #[test]
    fn chi_square_quantiles_match_tables() {
        // Standard table values (upper-tail probability 0.05 and 0.01).
        let table = [
            (1, 0.95, 3.841_458_820_694_124),
            (2, 0.95, 5.991_464_547_107_979),
            (4, 0.95, 9.487_729_036_781_154),
            (4, 0.99, 13.276_704_135_987_62),
            (10, 0.95, 18.307_038_053_275_146),
            (4, 0.5, 3.356_693_980_033_322),
        ];
        for (k, p, x) in table {
            let q = chi_square_quantile(k, p);
            assert!((q - x).abs() < 1e-9 * x, "k={k} p={p}: {q} vs {x}");
            assert!((chi_square_cdf(k, x) - p).abs() < 1e-12);
        }
        // closed form for k = 2: cdf = 1 − e^{−x/2}
        assert!((chi_square_cdf(2, 3.0) - (1.0 - (-1.5f64).exp())).abs() < 1e-15);
        assert!((ln_gamma(5.0) - 24.0f64.ln()).abs() < 1e-13);
        assert!(chi_square_quantile(4, 1.0).is_nan());
    }

    #[test]
    fn riccati_converges_and_matches_filter() {
        let model = LinearModel::paper_double_integrator(1e-3, 1e-3).unwrap();
        let uses = [true, false, true, true, true, true];
        let s = steady_state_riccati(&model, &uses, 0.01);
        assert!(s.converged);
        assert!(
            s.iterations > 10 && s.iterations < 100_000,
            "{}",
            s.iterations
        );
        // a fixed point: one more predict+update leaves P⁺ unchanged
        let mut bank = crate::estimator::EstimatorBank::new(
            model.clone(),
            &[vec![1]],
            State::zeros(),
            s.posterior,
        );
        let y = [0.0; 6];
        bank.step(&Input::zeros(), 0.01, &y, &[true; 6], &[false; 6]);
        assert!((bank.single(0).covariance() - s.posterior).amax() < 1e-12 * s.posterior.amax());
    }

    #[test]
    fn a_schedule_unrolls_to_its_phases() {
        let sched = UpdateSchedule {
            every: vec![1, 5, 0, 2],
        };
        let phases = sched.phases(&[true, true, true, true]);
        assert_eq!(phases.len(), 10); // lcm(1, 5, 2); channel 2 never updates
        assert_eq!(phases[0], vec![true, true, false, true]);
        assert_eq!(phases[1], vec![true, false, false, false]);
        assert_eq!(phases[5], vec![true, true, false, false]);
        // a channel the filter does not use is left out, and so is its period
        assert_eq!(sched.phases(&[true, false, true, true]).len(), 2);
        assert_eq!(
            UpdateSchedule::every_step().phases(&[true, false]),
            vec![vec![true, false]]
        );
        // periods whose lcm exceeds the cap are coarsened to the longest one, all at once
        let coarse = UpdateSchedule {
            every: vec![9973, 9967],
        };
        let phases = coarse.phases(&[true, true]);
        assert_eq!(phases.len(), 9973);
        assert_eq!(phases[0], vec![true, true]);
        assert!(phases[1..].iter().all(|p| p == &vec![false, false]));
    }

    #[test]
    fn the_periodic_riccati_takes_its_worst_phase() {
        let model = LinearModel::paper_double_integrator(1e-3, 1e-3).unwrap();
        let uses = [true, false, true, false, true, true];
        let dt = 0.02;
        // every step: exactly the time-invariant recursion
        let one = periodic_riccati(&model, &UpdateSchedule::every_step().phases(&uses), dt);
        assert_eq!(one, steady_state_riccati(&model, &uses, dt));
        // the position channels every 5 steps: the worst phase is the last before an update,
        // and it is what a long run of the recursion reaches at most
        let sched = UpdateSchedule {
            every: vec![5, 5, 5, 5, 1, 1],
        };
        let phases = sched.phases(&uses);
        let s = periodic_riccati(&model, &phases, dt);
        assert!(s.converged);
        let lmax = |p: &StateMatrix| p.symmetric_eigenvalues().max();
        assert!(lmax(&s.posterior) > 1.5 * lmax(&one.posterior));
        let long = horizon_riccati_from(&model, &phases, 0, dt, &one.posterior, 5000);
        assert!(
            (lmax(&long) - lmax(&s.posterior)).abs() < 1e-9 * lmax(&s.posterior),
            "{} vs {}",
            lmax(&long),
            lmax(&s.posterior)
        );
        let d = model.discretize(dt);
        let mut p = s.posterior;
        // the worst is phase 4, four steps after an update; phases 0–3 that follow are smaller
        for (ph, uses) in phases.iter().enumerate().take(4) {
            p = riccati_step(&model, uses, &d, &p).1;
            assert!(lmax(&p) < lmax(&s.posterior), "phase {ph}");
        }
    }

    #[test]
    fn gamma_bound_scalar_case() {
        // P = σ² I: γ² = σ² χ²₄(1 − ε)
        let p = StateMatrix::identity() * 0.04;
        assert!((gamma_bound(&p, 0.05) - (0.04 * 9.487_729_036_781_154f64).sqrt()).abs() < 1e-9);
    }
}
