//! A compact CMA-ES (covariance matrix adaptation evolution strategy, Hansen's standard
//! parameters, "The CMA Evolution Strategy: A Tutorial", 2016) on the box [0, 1]^n, in
//! ask-and-tell form: [`Cmaes::ask`] draws λ points (clipped to the box: the clipped point is
//! both evaluated and used in the update, the "repair" handling of bounds), [`Cmaes::tell`]
//! ranks them by their objective (lower is better) and moves the mean, the step size σ (path
//! length control) and the covariance C (rank-one and rank-μ updates).
//!
//! Written here rather than taken from a crate: the maintained `cmaes` crate (0.2.2) pulls a
//! second nalgebra (0.33) and rand 0.8 into the tree, and `falsify` needs only the ask-and-tell
//! core on a few (≤ 12) box-bounded coordinates with the caller's seeded ChaCha stream.

use nalgebra::{DMatrix, DVector, SymmetricEigen};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

/// Smallest step size (in units of the box): below it the search has converged.
pub const SIGMA_MIN: f64 = 1e-12;

/// The state of one CMA-ES run.
#[derive(Debug, Clone)]
pub struct Cmaes {
    n: usize,
    lambda: usize,
    weights: Vec<f64>,
    mueff: f64,
    cc: f64,
    cs: f64,
    c1: f64,
    cmu: f64,
    damps: f64,
    chi_n: f64,
    mean: DVector<f64>,
    sigma: f64,
    c: DMatrix<f64>,
    b: DMatrix<f64>,
    d: DVector<f64>,
    pc: DVector<f64>,
    ps: DVector<f64>,
    generation: usize,
}

/// The default population size for dimension `n`: 4 + ⌊3 ln n⌋.
pub fn default_lambda(n: usize) -> usize {
    4 + (3.0 * (n.max(1) as f64).ln()).floor() as usize
}

impl Cmaes {
    /// Starts at `mean` (clipped to the box) with step `sigma` and covariance `diag(scales²)`
    /// (normalised so its largest entry is 1; all ones = isotropic), λ = `lambda` (at least 2).
    pub fn new(mean: &[f64], sigma: f64, scales: &[f64], lambda: usize) -> Self {
        let n = mean.len();
        let lambda = lambda.max(2);
        let mu = lambda / 2;
        let raw: Vec<f64> = (0..mu)
            .map(|i| ((lambda as f64 + 1.0) / 2.0).ln() - ((i + 1) as f64).ln())
            .collect();
        let sum: f64 = raw.iter().sum();
        let weights: Vec<f64> = raw.iter().map(|w| w / sum).collect();
        let mueff = 1.0 / weights.iter().map(|w| w * w).sum::<f64>();
        let nf = n as f64;
        let cc = (4.0 + mueff / nf) / (nf + 4.0 + 2.0 * mueff / nf);
        let cs = (mueff + 2.0) / (nf + mueff + 5.0);
        let c1 = 2.0 / ((nf + 1.3).powi(2) + mueff);
        let cmu = (1.0 - c1).min(2.0 * (mueff - 2.0 + 1.0 / mueff) / ((nf + 2.0).powi(2) + mueff));
        let damps = 1.0 + 2.0 * (0.0f64).max(((mueff - 1.0) / (nf + 1.0)).sqrt() - 1.0) + cs;
        let chi_n = nf.sqrt() * (1.0 - 1.0 / (4.0 * nf) + 1.0 / (21.0 * nf * nf));
        let top = scales.iter().fold(0.0f64, |m, s| m.max(s.abs()));
        let d = DVector::from_iterator(
            n,
            (0..n).map(|i| {
                let s = scales.get(i).map_or(1.0, |s| s.abs());
                if top > 0.0 {
                    (s / top).max(1e-3)
                } else {
                    1.0
                }
            }),
        );
        let c = DMatrix::from_diagonal(&d.map(|x| x * x));
        Self {
            n,
            lambda,
            weights,
            mueff,
            cc,
            cs,
            c1,
            cmu,
            damps,
            chi_n,
            mean: DVector::from_iterator(n, mean.iter().map(|v| v.clamp(0.0, 1.0))),
            sigma,
            c,
            b: DMatrix::identity(n, n),
            d,
            pc: DVector::zeros(n),
            ps: DVector::zeros(n),
            generation: 0,
        }
    }

    /// λ.
    pub fn lambda(&self) -> usize {
        self.lambda
    }

    /// The current mean.
    pub fn mean(&self) -> Vec<f64> {
        self.mean.iter().copied().collect()
    }

    /// The current step size σ.
    pub fn sigma(&self) -> f64 {
        self.sigma
    }

    /// Generations told so far.
    pub fn generation(&self) -> usize {
        self.generation
    }

    /// Converged: the step size along every principal axis is below `tol`.
    pub fn converged(&self, tol: f64) -> bool {
        self.sigma * self.d.max() < tol
    }

    /// λ new points, each in [0, 1]^n.
    pub fn ask(&self, rng: &mut ChaCha8Rng) -> Vec<Vec<f64>> {
        (0..self.lambda)
            .map(|_| {
                let z =
                    DVector::from_iterator(self.n, (0..self.n).map(|_| StandardNormal.sample(rng)));
                let y = &self.b * self.d.component_mul(&z);
                (&self.mean + self.sigma * y)
                    .iter()
                    .map(|v| v.clamp(0.0, 1.0))
                    .collect()
            })
            .collect()
    }

    /// Spends `budget` evaluations: generations of λ points (the last one smaller if `budget`
    /// is not a multiple of λ), each evaluated by `evaluate` (one objective value per point,
    /// lower is better) and told. Returns the lowest value seen (∞ if `budget` is 0).
    pub fn spend<E>(
        &mut self,
        rng: &mut ChaCha8Rng,
        budget: usize,
        mut evaluate: impl FnMut(&[Vec<f64>]) -> Result<Vec<f64>, E>,
    ) -> Result<f64, E> {
        let mut best = f64::INFINITY;
        let mut left = budget;
        while left > 0 {
            let mut xs = self.ask(rng);
            xs.truncate(left);
            left -= xs.len();
            let f = evaluate(&xs)?;
            best = f.iter().copied().fold(best, f64::min);
            self.tell(&xs, &f);
        }
        Ok(best)
    }

    /// Updates from the points `xs` (as [`Cmaes::ask`] returned them, or any points of the box)
    /// and their objective values `f` (lower is better; NaN ranks last).
    pub fn tell(&mut self, xs: &[Vec<f64>], f: &[f64]) {
        let mut order: Vec<usize> = (0..xs.len().min(f.len())).collect();
        order.sort_by(|&a, &b| {
            let (fa, fb) = (f[a], f[b]);
            fa.is_nan().cmp(&fb.is_nan()).then(fa.total_cmp(&fb))
        });
        let mu = self.weights.len().min(order.len());
        if mu == 0 {
            return;
        }
        let old = self.mean.clone();
        let ys: Vec<DVector<f64>> = order[..mu]
            .iter()
            .map(|&i| (DVector::from_column_slice(&xs[i]) - &old) / self.sigma)
            .collect();
        let wsum: f64 = self.weights[..mu].iter().sum();
        let mut yw = DVector::zeros(self.n);
        for (y, w) in ys.iter().zip(&self.weights) {
            yw += y * (w / wsum);
        }
        self.mean = (&old + self.sigma * &yw).map(|v| v.clamp(0.0, 1.0));
        // C^{-1/2} y_w = B D^{-1} Bᵀ y_w.
        let inv_sqrt_y = &self.b * (self.b.transpose() * &yw).component_div(&self.d);
        self.ps = (1.0 - self.cs) * &self.ps
            + (self.cs * (2.0 - self.cs) * self.mueff).sqrt() * inv_sqrt_y;
        self.generation += 1;
        let nf = self.n as f64;
        let ps_norm = self.ps.norm();
        let hsig =
            ps_norm / (1.0 - (1.0 - self.cs).powi(2 * self.generation as i32)).sqrt() / self.chi_n
                < 1.4 + 2.0 / (nf + 1.0);
        let hs = if hsig { 1.0 } else { 0.0 };
        self.pc =
            (1.0 - self.cc) * &self.pc + hs * (self.cc * (2.0 - self.cc) * self.mueff).sqrt() * &yw;
        let mut rank_mu = DMatrix::zeros(self.n, self.n);
        for (y, w) in ys.iter().zip(&self.weights) {
            rank_mu += (w / wsum) * y * y.transpose();
        }
        let delta = (1.0 - hs) * self.cc * (2.0 - self.cc);
        self.c = (1.0 - self.c1 - self.cmu + self.c1 * delta) * &self.c
            + self.c1 * &self.pc * self.pc.transpose()
            + self.cmu * rank_mu;
        self.sigma *= ((self.cs / self.damps) * (ps_norm / self.chi_n - 1.0)).exp();
        self.sigma = self.sigma.clamp(SIGMA_MIN, 1.0);
        // Eigendecomposition of the symmetrised C (n ≤ 12: every generation is cheap).
        let sym = (&self.c + self.c.transpose()) * 0.5;
        let eig = SymmetricEigen::new(sym);
        self.d = eig.eigenvalues.map(|l| l.max(1e-20).sqrt());
        self.b = eig.eigenvectors;
        self.c = &self.b * DMatrix::from_diagonal(&self.d.map(|x| x * x)) * self.b.transpose();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn minimise(
        f: impl Fn(&[f64]) -> f64,
        start: &[f64],
        generations: usize,
        seed: u64,
    ) -> (Cmaes, f64) {
        let n = start.len();
        let mut es = Cmaes::new(start, 0.2, &vec![1.0; n], default_lambda(n));
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut best = f64::INFINITY;
        for _ in 0..generations {
            let xs = es.ask(&mut rng);
            let fs: Vec<f64> = xs.iter().map(|x| f(x)).collect();
            best = fs.iter().copied().fold(best, f64::min);
            es.tell(&xs, &fs);
            if es.converged(1e-9) {
                break;
            }
        }
        (es, best)
    }

    /// On a sphere centred at 0.7 it converges to the centre from a corner, on every seed:
    /// f < 1e-12 and the mean within 1e-5 of the optimum in every coordinate.
    #[test]
    fn converges_on_a_sphere() {
        let sphere = |x: &[f64]| x.iter().map(|v| (v - 0.7).powi(2)).sum::<f64>();
        for seed in 0..5 {
            let (es, best) = minimise(sphere, &[0.1; 7], 400, seed);
            assert!(best < 1e-12, "seed {seed}: best {best}");
            assert!(
                es.mean().iter().all(|m| (m - 0.7).abs() < 1e-5),
                "seed {seed}: {:?}",
                es.mean()
            );
            assert!(es.generation() < 400, "seed {seed}: did not converge");
        }
    }

    /// On a scaled, rotated ellipsoid (condition 10⁴) the covariance adapts: it converges where
    /// an isotropic step would crawl.
    #[test]
    fn converges_on_an_ill_conditioned_ellipsoid() {
        let f = |x: &[f64]| {
            let a = x[0] + x[1] - 1.0;
            let b = x[0] - x[1];
            let c = x[2] - 0.3;
            let d = x[3] - 0.6;
            1e4 * a * a + b * b + 1e2 * c * c + 1e3 * d * d
        };
        for seed in 0..3 {
            let (es, best) = minimise(f, &[0.9, 0.1, 0.9, 0.1], 600, seed);
            assert!(best < 1e-10, "seed {seed}: best {best}");
            let m = es.mean();
            assert!(
                (m[0] - 0.5).abs() < 1e-4 && (m[1] - 0.5).abs() < 1e-4,
                "seed {seed}: {m:?}"
            );
        }
    }

    /// Rosenbrock (4-D, shifted into the box: optimum at 0.75 in every coordinate), a curved
    /// valley, is solved to 1e-8.
    #[test]
    fn converges_on_rosenbrock() {
        let f = |x: &[f64]| {
            let y: Vec<f64> = x.iter().map(|v| 4.0 * v - 2.0).collect();
            (0..y.len() - 1)
                .map(|i| 100.0 * (y[i + 1] - y[i] * y[i]).powi(2) + (1.0 - y[i]).powi(2))
                .sum::<f64>()
        };
        let mut solved = 0;
        for seed in 0..5 {
            let (_, best) = minimise(f, &[0.3; 4], 2000, seed);
            solved += usize::from(best < 1e-8);
        }
        // Rosenbrock in 4-D has a local minimum near y = (−1, 1, 1, 1) that a small population
        // can end in; most seeds find the global one.
        assert!(solved >= 4, "solved on {solved}/5 seeds");
    }

    #[test]
    fn spend_uses_exactly_the_budget() {
        let mut es = Cmaes::new(&[0.5; 3], 0.2, &[1.0; 3], 4);
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mut calls = Vec::new();
        let best = es
            .spend(&mut rng, 10, |xs| {
                calls.push(xs.len());
                Ok::<_, ()>(xs.iter().map(|x| x.iter().map(|v| v * v).sum()).collect())
            })
            .expect("spend");
        assert_eq!(calls, vec![4, 4, 2]);
        assert_eq!(es.generation(), 3);
        assert!(best < 0.75, "{best}");
    }

    #[test]
    fn bounds_are_respected_and_an_optimum_on_the_boundary_is_found() {
        let f = |x: &[f64]| x.iter().map(|v| (v + 0.5).powi(2)).sum::<f64>();
        let (es, _) = minimise(f, &[0.5; 3], 300, 1);
        assert!(
            es.mean().iter().all(|m| (0.0..=1e-6).contains(m)),
            "{:?}",
            es.mean()
        );
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let wide = Cmaes::new(&[0.5; 3], 1.0, &[1.0; 3], 6);
        assert!(wide
            .ask(&mut rng)
            .iter()
            .flatten()
            .all(|v| (0.0..=1.0).contains(v)));
    }
}
