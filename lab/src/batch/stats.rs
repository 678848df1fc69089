//! Small numerics for the Monte Carlo summary: log-gamma, the regularised incomplete beta
//! function and its inverse, exact (Clopper–Pearson) binomial intervals, the exact McNemar test
//! for paired outcomes, and sample quantiles.
//!
//! The special functions (log-gamma, the incomplete beta function) come from `statrs`; the
//! inverse is a bisection over it; the known-answer tests below (closed forms and published values) pin them.

use serde::{Deserialize, Serialize};

/// A closed interval `[lower, upper]` of a probability.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Interval {
    /// Lower bound.
    pub lower: f64,
    /// Upper bound.
    pub upper: f64,
}

/// ln Γ(x) (NaN for x ≤ 0): the controller crate's Lanczos implementation, one for the project.
pub use ftcbf_sim::ftcbf_controller::params::ln_gamma;

/// Regularised incomplete beta function I_x(a, b) = B(x; a, b) / B(a, b) for a, b > 0 and
/// x ∈ [0, 1] (x is clamped to [0, 1]; statrs' continued fraction). Returns NaN for
/// non-positive or NaN shape parameters.
pub fn reg_inc_beta(a: f64, b: f64, x: f64) -> f64 {
    if a.is_nan() || b.is_nan() || x.is_nan() || a <= 0.0 || b <= 0.0 {
        return f64::NAN;
    }
    if x <= 0.0 {
        return 0.0;
    }
    if x >= 1.0 {
        return 1.0;
    }
    statrs::function::beta::beta_reg(a, b, x).clamp(0.0, 1.0)
}

/// The x ∈ [0, 1] with I_x(a, b) = p (inverse of [`reg_inc_beta`] in x), by bisection on the
/// monotone function, carried on until no double lies strictly between the brackets or the
/// bracket is narrower than 1e-15 relative. Returns NaN for p outside [0, 1] or bad shapes.
///
/// Not statrs' `inv_beta_reg`: in its far tail (a = 0.5, b = 2, p = 1e-9) that is off by
/// orders of magnitude, which the known-answer test below catches.
pub fn inv_reg_inc_beta(a: f64, b: f64, p: f64) -> f64 {
    if a.is_nan() || b.is_nan() || p.is_nan() || a <= 0.0 || b <= 0.0 || !(0.0..=1.0).contains(&p) {
        return f64::NAN;
    }
    if p == 0.0 {
        return 0.0;
    }
    if p == 1.0 {
        return 1.0;
    }
    let (mut lo, mut hi) = (0.0_f64, 1.0_f64);
    // 1100 halvings reach the smallest subnormal; the loop normally stops far earlier.
    for _ in 0..1100 {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi || hi - lo <= 1e-15 * hi {
            break;
        }
        if reg_inc_beta(a, b, mid) < p {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// Exact two-sided Clopper–Pearson confidence interval at level `confidence` (e.g. 0.95) for a
/// binomial proportion with `successes` out of `trials`:
/// lower = B⁻¹(α/2; k, n − k + 1) (0 when k = 0), upper = B⁻¹(1 − α/2; k + 1, n − k) (1 when
/// k = n), α = 1 − confidence. `None` when `trials` is 0, `successes > trials` or the level is
/// not in (0, 1).
pub fn clopper_pearson(successes: u64, trials: u64, confidence: f64) -> Option<Interval> {
    if trials == 0 || successes > trials || !(confidence > 0.0 && confidence < 1.0) {
        return None;
    }
    let alpha = 1.0 - confidence;
    let (k, n) = (successes as f64, trials as f64);
    let lower = if successes == 0 {
        0.0
    } else {
        inv_reg_inc_beta(k, n - k + 1.0, alpha / 2.0)
    };
    let upper = if successes == trials {
        1.0
    } else {
        inv_reg_inc_beta(k + 1.0, n - k, 1.0 - alpha / 2.0)
    };
    Some(Interval { lower, upper })
}

/// The smallest number of trials n at which n safe out of n gives a Clopper–Pearson lower bound
/// ≥ `claimed` at level `confidence`, i.e. the smallest n with (α/2)^{1/n} ≥ claimed. Fewer
/// trials can never support the claim. `None` unless 0 < claimed < 1 and 0 < confidence < 1.
pub fn min_trials_to_support(claimed: f64, confidence: f64) -> Option<u64> {
    if !(claimed > 0.0 && claimed < 1.0 && confidence > 0.0 && confidence < 1.0) {
        return None;
    }
    let half_alpha = (1.0 - confidence) / 2.0;
    let supports = |n: u64| half_alpha.powf(1.0 / n as f64) >= claimed;
    let mut n = (half_alpha.ln() / claimed.ln()).ceil().max(1.0) as u64;
    // Guard the rounding of the logarithms: step to the exact smallest n.
    while n > 1 && supports(n - 1) {
        n -= 1;
    }
    while !supports(n) {
        n += 1;
    }
    Some(n)
}

/// Exact two-sided McNemar test of paired binary outcomes: with `b` pairs where only the first
/// condition succeeded and `c` where only the second did, under H0 (no difference) b ~ Bin(b + c,
/// 1/2). p = min(1, 2 · P(X ≤ min(b, c))), with P(X ≤ m) = I_{1/2}(n − m, m + 1). p = 1 when
/// there are no discordant pairs.
pub fn mcnemar_exact_p(b: u64, c: u64) -> f64 {
    let n = b + c;
    let m = b.min(c);
    if n == 0 || 2 * m >= n {
        return 1.0;
    }
    let cdf = reg_inc_beta((n - m) as f64, (m + 1) as f64, 0.5);
    (2.0 * cdf).min(1.0)
}

/// Sample quantile of `sorted` (ascending, non-empty) at probability `p` ∈ [0, 1], by linear
/// interpolation between order statistics at position (n − 1) p (Hyndman–Fan type 7, the
/// default of R and NumPy). `None` for an empty slice.
pub fn quantile_sorted(sorted: &[f64], p: f64) -> Option<f64> {
    let n = sorted.len();
    if n == 0 {
        return None;
    }
    let pos = (n - 1) as f64 * p.clamp(0.0, 1.0);
    let i = pos.floor() as usize;
    let frac = pos - i as f64;
    if i + 1 >= n {
        return Some(sorted[n - 1]);
    }
    Some(sorted[i] + frac * (sorted[i + 1] - sorted[i]))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol
    }

    #[test]
    fn ln_gamma_matches_factorials_and_half_integers() {
        // Γ(n) = (n − 1)!
        let mut fact = 1.0_f64;
        for n in 1..=20u32 {
            if n > 1 {
                fact *= f64::from(n - 1);
            }
            let got = ln_gamma(f64::from(n));
            assert!(
                close(got, fact.ln(), 1e-12 * fact.ln().abs().max(1.0)),
                "n={n}"
            );
        }
        // Γ(1/2) = √π, Γ(0.1) = 9.513507698668732.
        assert!(close(
            ln_gamma(0.5),
            std::f64::consts::PI.sqrt().ln(),
            1e-13
        ));
        assert!(close(ln_gamma(0.1), 9.513_507_698_668_732_f64.ln(), 1e-13));
        // Stirling with two correction terms at x = 1e6 (error ~1e-22).
        let x = 1e6_f64;
        let stirling =
            (x - 0.5) * x.ln() - x + 0.5 * (2.0 * std::f64::consts::PI).ln() + 1.0 / (12.0 * x)
                - 1.0 / (360.0 * x * x * x);
        assert!(
            close(ln_gamma(x), stirling, 1e-7 * 1.0),
            "{} vs {stirling}",
            ln_gamma(x)
        );
        assert!(ln_gamma(0.0).is_nan() && ln_gamma(-1.0).is_nan());
    }

    #[test]
    fn reg_inc_beta_matches_closed_forms() {
        for &x in &[1e-6_f64, 0.01, 0.2, 0.5, 0.73, 0.99, 0.999_999] {
            // I_x(1, b) = 1 − (1 − x)^b ; I_x(a, 1) = x^a ; I_x(1,1) = x.
            for &b in &[1.0, 2.5, 10.0, 400.0] {
                let want = 1.0 - (1.0_f64 - x).powf(b);
                assert!(close(reg_inc_beta(1.0, b, x), want, 1e-12), "x={x} b={b}");
                assert!(
                    close(reg_inc_beta(b, 1.0, x), x.powf(b), 1e-12),
                    "x={x} a={b}"
                );
            }
            // I_x(2, 2) = 3x² − 2x³.
            assert!(close(
                reg_inc_beta(2.0, 2.0, x),
                3.0 * x * x - 2.0 * x * x * x,
                1e-12
            ));
        }
        // Binomial tail: P(Bin(10, 0.3) ≤ 3) = I_{0.7}(7, 4) = 0.6496107184.
        assert!(close(reg_inc_beta(7.0, 4.0, 0.7), 0.649_610_718_4, 1e-9));
        // Large shapes: symmetric Beta(5000, 5000) has median 1/2.
        assert!(close(reg_inc_beta(5000.0, 5000.0, 0.5), 0.5, 1e-9));
        assert_eq!(reg_inc_beta(2.0, 3.0, 0.0), 0.0);
        assert_eq!(reg_inc_beta(2.0, 3.0, 1.0), 1.0);
        assert!(reg_inc_beta(0.0, 3.0, 0.5).is_nan());
    }

    #[test]
    fn inverse_reg_inc_beta_inverts() {
        for &(a, b) in &[
            (1.0, 1.0),
            (0.5, 2.0),
            (3.0, 8.0),
            (95.0, 6.0),
            (1.0, 1e5),
            (2e4, 3.0),
        ] {
            for &p in &[1e-9, 0.025, 0.3, 0.5, 0.975, 1.0 - 1e-9] {
                let x = inv_reg_inc_beta(a, b, p);
                assert!((0.0..=1.0).contains(&x));
                assert!(
                    close(reg_inc_beta(a, b, x), p, 1e-9 * p.max(1e-3)),
                    "a={a} b={b} p={p} x={x}"
                );
            }
        }
        // Closed form: I_x(1, b) = p  ⇔  x = 1 − (1 − p)^{1/b}.
        let x = inv_reg_inc_beta(1.0, 1e6, 0.025);
        let want = -((-0.025_f64).ln_1p() * 1e-6).exp_m1();
        // ln Γ(1e6 + 1) − ln Γ(1e6) cancels ~7 digits: 1e-8 relative is what f64 allows here.
        assert!(close(x, want, 1e-8 * want), "{x} vs {want}");
        assert!(inv_reg_inc_beta(1.0, 1.0, 1.5).is_nan());
    }

    #[test]
    fn clopper_pearson_matches_published_values() {
        let cases = [
            (0, 10, 0.0, 0.3085),
            (10, 10, 0.6915, 1.0),
            (5, 10, 0.1871, 0.8129),
            (95, 100, 0.8872, 0.9836),
            (1, 10, 0.0025, 0.4450),
        ];
        for (k, n, lo, hi) in cases {
            let ci = clopper_pearson(k, n, 0.95).expect("valid counts");
            assert!(close(ci.lower, lo, 1e-4), "{k}/{n}: lower {}", ci.lower);
            assert!(close(ci.upper, hi, 1e-4), "{k}/{n}: upper {}", ci.upper);
        }
        // k = n has the closed form lower = (α/2)^{1/n}.
        let ci = clopper_pearson(1000, 1000, 0.95).expect("valid counts");
        assert!(close(ci.lower, 0.025_f64.powf(1e-3), 1e-12));
        // k = 0: upper = 1 − (α/2)^{1/n}.
        let ci = clopper_pearson(0, 37, 0.95).expect("valid counts");
        assert!(close(ci.upper, 1.0 - 0.025_f64.powf(1.0 / 37.0), 1e-12));
        assert!(clopper_pearson(0, 0, 0.95).is_none());
        assert!(clopper_pearson(5, 4, 0.95).is_none());
        assert!(clopper_pearson(1, 4, 1.0).is_none());
    }

    #[test]
    fn trials_needed_to_support_a_claim() {
        // 0.025^(1/72) = 0.95005 ≥ 0.95 but 0.025^(1/71) = 0.94937.
        assert_eq!(min_trials_to_support(0.95, 0.95), Some(72));
        // ε = 0.01: ln 0.025 / ln 0.99 = 367.04 → 368.
        assert_eq!(min_trials_to_support(0.99, 0.95), Some(368));
        for (c, n) in [(0.95, 72u64), (0.99, 368), (0.9, 36)] {
            let at = clopper_pearson(n, n, 0.95).map(|i| i.lower).unwrap_or(0.0);
            let before = clopper_pearson(n - 1, n - 1, 0.95)
                .map(|i| i.lower)
                .unwrap_or(1.0);
            assert!(at >= c && before < c, "c={c} n={n}");
        }
        assert_eq!(min_trials_to_support(1.0, 0.95), None);
    }

    #[test]
    fn mcnemar_matches_hand_computed_binomial_tails() {
        // b = 0, c = 6: p = 2 · 2⁻⁶.
        assert!(close(mcnemar_exact_p(0, 6), 2.0 / 64.0, 1e-12));
        // b = 1, c = 9: p = 2 · (1 + 10) / 1024.
        assert!(close(mcnemar_exact_p(9, 1), 22.0 / 1024.0, 1e-12));
        assert_eq!(mcnemar_exact_p(4, 4), 1.0);
        assert_eq!(mcnemar_exact_p(0, 0), 1.0);
        // b = 2, c = 3: 2 · (1 + 5 + 10) / 32 = 1.0 → capped at 1.
        assert!(close(mcnemar_exact_p(2, 3), 1.0, 1e-12));
    }

    #[test]
    fn quantiles_interpolate_type_7() {
        let v = [1.0, 2.0, 4.0, 8.0, 16.0];
        assert_eq!(quantile_sorted(&v, 0.0), Some(1.0));
        assert_eq!(quantile_sorted(&v, 1.0), Some(16.0));
        assert_eq!(quantile_sorted(&v, 0.5), Some(4.0));
        // position 0.9 · 4 = 3.6 → 8 + 0.6 · 8.
        assert!(close(
            quantile_sorted(&v, 0.9).unwrap_or(f64::NAN),
            12.8,
            1e-12
        ));
        // position 0.1 · 4 = 0.4 → 1 + 0.4 · 1.
        assert!(close(
            quantile_sorted(&v, 0.1).unwrap_or(f64::NAN),
            1.4,
            1e-12
        ));
        assert_eq!(quantile_sorted(&[3.5], 0.9), Some(3.5));
        assert_eq!(quantile_sorted(&[], 0.5), None);
    }
}
