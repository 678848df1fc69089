//! The solution separation of two filters: its exact second moments over a horizon and the
//! increment metric of Step 2's test.

use crate::model::LinearModel;
use crate::types::StateMatrix;

use super::riccati::{joseph, scalar_gain};

/// One filter's sequential update as a linear map of its prior error and the measurement noise:
/// `e⁺ = A e⁻ + B v` (all channels where `uses[k]` fresh), with the posterior covariance.
fn update_map(
    model: &LinearModel,
    uses: &[bool],
    prior: &StateMatrix,
) -> (StateMatrix, nalgebra::DMatrix<f64>, StateMatrix) {
    let q = model.channels();
    let mut a = StateMatrix::identity();
    let mut b = nalgebra::DMatrix::<f64>::zeros(4, q);
    let mut p = *prior;
    for (k, &u) in uses.iter().enumerate() {
        if !u || k >= q {
            continue;
        }
        let (kg, ikc) = scalar_gain(model, k, &p);
        a = ikc * a;
        b = nalgebra::DMatrix::from_fn(4, q, |r, cc| {
            (0..4).map(|m| ikc[(r, m)] * b[(m, cc)]).sum::<f64>()
        });
        for r in 0..4 {
            b[(r, k)] += kg[r];
        }
        p = joseph(model, k, &p, &kg, &ikc);
    }
    (a, b, p)
}

/// Exact second moments of the solution separation `s = x̂_a − x̂_b` of two filters run on the
/// same measurements from the same start (x̂_a(0) = x̂_b(0), error covariance `p0`), over `n`
/// steps: the joint error (e_a, e_b) is a linear Gaussian process whose transition and noise
/// follow from each filter's gains.
#[derive(Debug, Clone, PartialEq)]
pub struct SeparationMoments {
    /// The largest λ̄ over the horizon of `Cov(s_k)`.
    pub worst_abs: f64,
    /// λ̄(Cov(s_k)) for k = 1..=n.
    pub absolute: Vec<f64>,
    /// `Cov(s_k − s_{k−w})` for k = 1..=n (the increment over the last `w` steps; from the
    /// start while k < w).
    pub increments: Vec<StateMatrix>,
}

/// See [`SeparationMoments`].
pub fn separation_moments(
    model: &LinearModel,
    uses_a: &[bool],
    uses_b: &[bool],
    dt: f64,
    p0: &StateMatrix,
    n: usize,
    w: usize,
) -> SeparationMoments {
    separation_moments_scheduled(model, &[uses_a.to_vec()], &[uses_b.to_vec()], dt, p0, n, w)
}

/// [`separation_moments`] with a schedule: at step s filter a updates with the channels of
/// `phases_a[s % L_a]`, filter b with `phases_b[s % L_b]` ([`UpdateSchedule::phases`](super::UpdateSchedule::phases)).
pub fn separation_moments_scheduled(
    model: &LinearModel,
    phases_a: &[Vec<bool>],
    phases_b: &[Vec<bool>],
    dt: f64,
    p0: &StateMatrix,
    n: usize,
    w: usize,
) -> SeparationMoments {
    type M8 = nalgebra::SMatrix<f64, 8, 8>;
    let d = model.discretize(dt);
    let q = model.channels();
    let r = nalgebra::DMatrix::from_diagonal(&nalgebra::DVector::from_vec(model.r.clone()));
    let mut sigma = M8::zeros();
    for (bi, bj) in [(0, 0), (0, 4), (4, 0), (4, 4)] {
        sigma.fixed_view_mut::<4, 4>(bi, bj).copy_from(p0);
    }
    let (mut pa, mut pb) = (*p0, *p0);
    let sep_cov = |s: &M8| -> StateMatrix {
        let h = |i: usize, j: usize| s.fixed_view::<4, 4>(i, j).into_owned();
        h(0, 0) + h(4, 4) - h(0, 4) - h(4, 0)
    };
    let lmax = |m: &StateMatrix| ((m + m.transpose()) * 0.5).symmetric_eigenvalues().max();
    // Σ_{k−w..k}, and the product 𝒜_k ⋯ 𝒜_{k−w+1} of the last w transitions kept by a
    // two-stack sliding-window product (amortised three 8×8 products per step): `back` holds
    // the newer transitions with their running product `back_prod` (newest on the left),
    // `front` the older ones, each with the product of itself and the newer ones in `front`
    // (the oldest, next to leave, on top).
    let w = w.max(1);
    let mut sigmas: std::collections::VecDeque<M8> = std::collections::VecDeque::new();
    let mut back: Vec<M8> = Vec::new();
    let mut back_prod = M8::identity();
    let mut front: Vec<M8> = Vec::new();
    sigmas.push_back(sigma);
    let mut worst_abs = 0.0f64;
    let mut absolute = Vec::with_capacity(n);
    let mut increments = Vec::with_capacity(n);
    fn phase(phases: &[Vec<bool>], s: usize) -> &[bool] {
        phases
            .get(s % phases.len().max(1))
            .map_or(&[], Vec::as_slice)
    }
    for s in 0..n {
        let prior_a = d.phi * pa * d.phi.transpose() + d.qd;
        let prior_b = d.phi * pb * d.phi.transpose() + d.qd;
        let (aa, ba, post_a) = update_map(model, phase(phases_a, s), &prior_a);
        let (ab, bb, post_b) = update_map(model, phase(phases_b, s), &prior_b);
        pa = post_a;
        pb = post_b;
        let mut t = M8::zeros();
        t.fixed_view_mut::<4, 4>(0, 0).copy_from(&(aa * d.phi));
        t.fixed_view_mut::<4, 4>(4, 4).copy_from(&(ab * d.phi));
        // noise: −[A_a; A_b] w + [B_a; B_b] v
        let mut aw = nalgebra::SMatrix::<f64, 8, 4>::zeros();
        aw.fixed_view_mut::<4, 4>(0, 0).copy_from(&aa);
        aw.fixed_view_mut::<4, 4>(4, 0).copy_from(&ab);
        let mut bv = nalgebra::DMatrix::<f64>::zeros(8, q);
        bv.view_mut((0, 0), (4, q)).copy_from(&ba);
        bv.view_mut((4, 0), (4, q)).copy_from(&bb);
        let nv = &bv * &r * bv.transpose();
        let noise = aw * d.qd * aw.transpose() + M8::from_fn(|i, j| nv[(i, j)]);
        sigma = t * sigma * t.transpose() + noise;
        sigma = (sigma + sigma.transpose()) * 0.5;
        back.push(t);
        back_prod = t * back_prod;
        sigmas.push_back(sigma);
        if sigmas.len() > w + 1 {
            sigmas.pop_front();
            if front.is_empty() {
                let mut acc = M8::identity();
                for e in back.drain(..).rev() {
                    acc *= e;
                    front.push(acc);
                }
                back_prod = M8::identity();
            }
            front.pop();
        }
        let abs_k = lmax(&sep_cov(&sigma));
        absolute.push(abs_k);
        worst_abs = worst_abs.max(abs_k);
        // Cov(z_k, z_{k−w}) = 𝒜_k ⋯ 𝒜_{k−w+1} Σ_{k−w}
        let old = sigmas[0];
        let prod = match front.last() {
            Some(f) => back_prod * f,
            None => back_prod,
        };
        let cross = prod * old;
        let inc = sigma + old - cross - cross.transpose();
        let c = sep_cov(&inc);
        increments.push((c + c.transpose()) * 0.5);
    }
    SeparationMoments {
        worst_abs,
        absolute,
        increments,
    }
}

/// The fixed norm of Step 2's increment test for one pair, from the increment covariances of
/// both single filters against the pair filter over the horizon (`a`, `b`, as
/// [`SeparationMoments::increments`]): C̄ = C_a(k_a) + C_b(k_b) at the steps of largest trace
/// (plus a ridge of 10⁻⁹ of its trace, so it is invertible), W = C̄⁻¹, and the factor
/// c = max over both sequences of λ̄(L⁻¹ C_k L⁻ᵀ) (C̄ = L Lᵀ). Then C_k ≼ c C̄, so
/// zᵀ W z ≤ c · zᵀ C_k⁻¹ z, and Pr(‖z‖²_W > c q) ≤ Pr(χ²₄ > q): η/2 = √(c q) keeps the false-alarm
/// rate of every step of the horizon at most that of the χ²₄ quantile q. Returns (W, c).
/// The covariance weighting is what makes the test sharp: the honest separation of two filters
/// fed the same odometry barely moves in velocity, while a spoof drags the velocity estimate.
pub fn increment_metric(a: &[StateMatrix], b: &[StateMatrix]) -> (StateMatrix, f64) {
    let largest = |cs: &[StateMatrix]| {
        cs.iter()
            .copied()
            .max_by(|x, y| x.trace().total_cmp(&y.trace()))
            .unwrap_or_else(StateMatrix::zeros)
    };
    let mut bar = largest(a) + largest(b);
    let ridge = 1e-9 * bar.trace().max(f64::MIN_POSITIVE);
    bar += StateMatrix::identity() * ridge;
    let Some(chol) = bar.cholesky() else {
        return (
            StateMatrix::identity(),
            bar.symmetric_eigenvalues().max().max(0.0),
        );
    };
    let l_inv = chol.l().try_inverse().unwrap_or_else(StateMatrix::identity);
    let scale = a
        .iter()
        .chain(b)
        .map(|c| {
            let m = l_inv * c * l_inv.transpose();
            ((m + m.transpose()) * 0.5).symmetric_eigenvalues().max()
        })
        .fold(0.0f64, f64::max);
    (chol.inverse(), scale)
}
