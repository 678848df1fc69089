//! Whether a filter can see the state: observability of (Φ, C̄) and the PBH test of which
//! directions are undetectable, with their names.

use nalgebra::RowVector4;

use crate::model::LinearModel;
use crate::types::{State, StateMatrix};

/// Whether (Φ, C̄) is observable, C̄ = the rows of the channels where `uses[k]`: the stacked
/// matrix [C̄; C̄Φ; C̄Φ²; C̄Φ³] has rank 4 (singular values above 1e-9 of the largest).
pub fn observable(model: &LinearModel, uses: &[bool], phi: &StateMatrix) -> bool {
    let rows: Vec<RowVector4<f64>> = (0..model.channels())
        .filter(|&k| uses.get(k).copied().unwrap_or(false))
        .map(|k| model.c[k])
        .collect();
    if rows.is_empty() {
        return false;
    }
    let mut o = nalgebra::DMatrix::<f64>::zeros(4 * rows.len(), 4);
    let mut power = StateMatrix::identity();
    for blk in 0..4 {
        for (r, c) in rows.iter().enumerate() {
            let row = c * power;
            o.row_mut(blk * rows.len() + r).copy_from(&row);
        }
        power *= phi;
    }
    let sv = o.singular_values();
    let max = sv.max();
    max > 0.0 && sv.iter().filter(|&&v| v > 1e-9 * max).count() == 4
}

/// Names of the state coordinates (p_x, p_y, v_x, v_y), for reports.
pub const STATE_NAMES: [&str; 4] = ["x position", "y position", "x velocity", "y velocity"];

/// Detectability of (F, C̄) for one channel subset (the PBH test) and its unobservable subspace.
#[derive(Debug, Clone, PartialEq)]
pub struct Detectability {
    /// Whether (F, C̄) is detectable: `rank [λI − F; C̄] = n` for every eigenvalue λ of F with
    /// Re λ ≥ 0.
    pub detectable: bool,
    /// The eigenvalues (re, im) of F with Re λ ≥ 0 at which the PBH rank test fails.
    pub failing_eigenvalues: Vec<(f64, f64)>,
    /// Dimension of the unobservable subspace (kernel of [C̄; C̄F; C̄F²; C̄F³]).
    pub unobservable_dim: usize,
    /// The unobservable subspace in state terms: coordinate names when it is spanned by
    /// coordinate axes (e.g. "x position"), else its basis vectors written out.
    pub unobservable: Vec<String>,
    /// An orthonormal basis of the unobservable subspace.
    pub unobservable_basis: Vec<State>,
}

/// The PBH detectability test of (F, C̄), C̄ = the rows of the channels where `uses[k]`
/// (continuous-time F; for the double integrator every eigenvalue is 0, so detectable =
/// observable). Rank decisions use singular values above 1e-9 of the largest (and 1e-12
/// absolute).
pub fn detectability(model: &LinearModel, uses: &[bool]) -> Detectability {
    use nalgebra::{Complex, DMatrix};
    let rows: Vec<RowVector4<f64>> = (0..model.channels())
        .filter(|&k| uses.get(k).copied().unwrap_or(false))
        .map(|k| model.c[k])
        .collect();
    let rank = |sv: &nalgebra::DVector<f64>| {
        let max = sv.max();
        sv.iter().filter(|&&v| v > 1e-12 && v > 1e-9 * max).count()
    };
    // PBH at each eigenvalue with Re λ ≥ 0.
    let mut failing = Vec::new();
    let eig = model.f.complex_eigenvalues();
    let mut seen: Vec<Complex<f64>> = Vec::new();
    for lam in eig.iter() {
        if lam.re < -1e-12 || seen.iter().any(|s| (s - lam).norm() < 1e-9) {
            continue;
        }
        seen.push(*lam);
        let mut m = DMatrix::<Complex<f64>>::zeros(4 + rows.len(), 4);
        for r in 0..4 {
            for c in 0..4 {
                let id = if r == c { *lam } else { Complex::new(0.0, 0.0) };
                m[(r, c)] = id - Complex::new(model.f[(r, c)], 0.0);
            }
        }
        for (k, row) in rows.iter().enumerate() {
            for c in 0..4 {
                m[(4 + k, c)] = Complex::new(row[c], 0.0);
            }
        }
        if rank(&m.singular_values()) < 4 {
            failing.push((lam.re, lam.im));
        }
    }
    // Unobservable subspace.
    let mut o = DMatrix::<f64>::zeros(4 * rows.len().max(1), 4);
    let mut power = StateMatrix::identity();
    for blk in 0..4 {
        for (r, c) in rows.iter().enumerate() {
            o.row_mut(blk * rows.len() + r).copy_from(&(c * power));
        }
        power *= model.f;
    }
    let unobservable_dim = if rows.is_empty() {
        4
    } else {
        4 - rank(&o.singular_values())
    };
    let scale = o.amax().max(1.0);
    let named: Vec<String> = (0..4)
        .filter(|&k| o.column(k).amax() <= 1e-12 * scale)
        .map(|k| STATE_NAMES[k].to_string())
        .collect();
    // A basis of the kernel: right singular vectors of the smallest singular values.
    let svd = o.clone().svd(false, true);
    let vt = svd.v_t.unwrap_or_else(|| DMatrix::identity(4, 4));
    let mut order: Vec<usize> = (0..svd.singular_values.len()).collect();
    order.sort_by(|&a, &b| svd.singular_values[a].total_cmp(&svd.singular_values[b]));
    let mut basis: Vec<State> = order
        .into_iter()
        .take(unobservable_dim)
        .map(|i| State::new(vt[(i, 0)], vt[(i, 1)], vt[(i, 2)], vt[(i, 3)]))
        .collect();
    if rows.is_empty() {
        basis = (0..4)
            .map(|k| State::from_fn(|r, _| f64::from(r == k)))
            .collect();
    }
    let unobservable = if named.len() == unobservable_dim {
        named
    } else {
        // Not axis-aligned: write the basis out.
        basis
            .iter()
            .map(|v| {
                format!(
                    "({:.3}·p_x + {:.3}·p_y + {:.3}·v_x + {:.3}·v_y)",
                    v[0], v[1], v[2], v[3]
                )
            })
            .collect()
    };
    Detectability {
        detectable: failing.is_empty(),
        failing_eigenvalues: failing,
        unobservable_dim,
        unobservable,
        unobservable_basis: basis,
    }
}
