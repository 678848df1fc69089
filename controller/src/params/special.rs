//! Special functions through `statrs`: log-gamma, the regularised incomplete gamma function and
//! the χ² distribution (thin wrappers that keep the NaN conventions the callers rely on).

/// ln Γ(x) for x > 0 (statrs' Lanczos approximation); NaN for x ≤ 0 or NaN. The project's one
/// log-gamma: the batch statistics use it too.
pub fn ln_gamma(x: f64) -> f64 {
    if x.is_nan() || x <= 0.0 {
        return f64::NAN;
    }
    statrs::function::gamma::ln_gamma(x)
}

/// Regularised lower incomplete gamma P(a, x) = γ(a, x)/Γ(a), a > 0, x ≥ 0 (NaN for a ≤ 0 or
/// NaN arguments; 0 for x ≤ 0; 1 for x = ∞).
pub fn regularized_gamma_p(a: f64, x: f64) -> f64 {
    if a.is_nan() || a <= 0.0 || x.is_nan() {
        return f64::NAN;
    }
    if x <= 0.0 {
        return 0.0;
    }
    if x.is_infinite() {
        return 1.0;
    }
    statrs::function::gamma::gamma_lr(a, x).clamp(0.0, 1.0)
}

/// χ² cumulative distribution with `k` degrees of freedom.
pub fn chi_square_cdf(k: u32, x: f64) -> f64 {
    regularized_gamma_p(k as f64 / 2.0, x / 2.0)
}

/// χ² quantile: the x with `chi_square_cdf(k, x) = p`, for 0 < p < 1 (NaN otherwise, and for
/// k = 0), from statrs' χ² distribution.
pub fn chi_square_quantile(k: u32, p: f64) -> f64 {
    use statrs::distribution::{ChiSquared, ContinuousCDF};
    if k == 0 || !(p > 0.0 && p < 1.0) {
        return f64::NAN;
    }
    match ChiSquared::new(f64::from(k)) {
        Ok(d) => d.inverse_cdf(p),
        Err(_) => f64::NAN,
    }
}
