//! The linear algebra of the analysis: the SVD pseudo-inverse, scaled condition numbers, the pivot order
//! of a rank-revealing QR, and a sparse basis of the null space.

use nalgebra::{DMatrix, DVector};

/// The SVD pseudo-inverse of `JᵀJ`.
#[derive(Debug, Clone, PartialEq)]
pub struct PseudoInverse {
    /// `Σ_{k not null} v_k v_kᵀ / s_k²` (internal units², noise model only).
    pub covariance: DMatrix<f64>,
    /// Number of singular values above the tolerance.
    pub rank: usize,
    /// Singular values, descending, one per column.
    pub singular_values: Vec<f64>,
    /// Right singular vectors as columns, in the order of `singular_values`.
    pub v: DMatrix<f64>,
    /// The absolute tolerance used: `relative_tolerance · s_max · max(m, n)`.
    pub tolerance: f64,
}

/// SVD of `j` with a complete `V` (zero rows are appended when `j` is wide), singular values descending.
fn full_svd(j: &DMatrix<f64>) -> (Vec<f64>, DMatrix<f64>) {
    let (m, n) = j.shape();
    if n == 0 {
        return (Vec::new(), DMatrix::zeros(0, 0));
    }
    let a = if m < n { j.clone().resize_vertically(n, 0.0) } else { j.clone() };
    let svd = a.svd(false, true);
    let v_t = svd.v_t.expect("V was requested");
    (svd.singular_values.iter().copied().collect(), v_t.transpose())
}

/// The covariance of the least-squares estimate for a weighted Jacobian `j` (noise model only, internal units),
/// from the SVD pseudo-inverse of `JᵀJ`: directions with `s ≤ relative_tolerance · s_max · max(m, n)` are left
/// out. Equals `(JᵀJ)⁻¹` when `j` has full column rank.
pub fn pseudo_inverse_covariance(j: &DMatrix<f64>, relative_tolerance: f64) -> PseudoInverse {
    let (m, n) = j.shape();
    let (s, v) = full_svd(j);
    let s_max = s.first().copied().unwrap_or(0.0);
    let tolerance = relative_tolerance * s_max * m.max(n) as f64;
    let rank = s.iter().filter(|&&sk| sk > tolerance).count();
    // The covariance from the SVD of the column-equilibrated matrix J·D⁻¹ (unit-norm columns),
    // C = D⁻¹ (Σ_k v_k v_kᵀ / s_k²) D⁻¹ over its `rank` largest singular values: the raw SVD
    // loses accuracy when column scales differ by decades.
    let norms: Vec<f64> = j.column_iter().map(|c| c.norm()).collect();
    let scaled = DMatrix::from_fn(m, n, |i, k| if norms[k] > 0.0 { j[(i, k)] / norms[k] } else { 0.0 });
    let (ss, sv) = full_svd(&scaled);
    let mut order: Vec<usize> = (0..ss.len()).collect();
    order.sort_by(|&a, &b| ss[b].total_cmp(&ss[a]));
    let mut covariance = DMatrix::zeros(n, n);
    for &k in order.iter().take(rank) {
        if ss[k] > 0.0 {
            let vk = sv.column(k);
            covariance += (vk * vk.transpose()) / (ss[k] * ss[k]);
        }
    }
    for a in 0..n {
        for b in 0..n {
            let d = norms[a] * norms[b];
            covariance[(a, b)] = if d > 0.0 { covariance[(a, b)] / d } else { 0.0 };
        }
    }
    PseudoInverse { covariance, rank, singular_values: s, v, tolerance }
}

/// Condition number of `a` with each non-zero column scaled to unit norm: `s_max / s_min`, infinite when singular
/// (a zero column, fewer rows than columns, or a zero singular value). `None` for no columns.
pub(super) fn scaled_condition_number(a: &DMatrix<f64>) -> Option<f64> {
    let (m, n) = a.shape();
    if n == 0 {
        return None;
    }
    if m < n {
        return Some(f64::INFINITY);
    }
    let mut b = a.clone();
    for mut c in b.column_iter_mut() {
        let norm = c.norm();
        if norm > 0.0 {
            c /= norm;
        }
    }
    let s = b.singular_values();
    let s_max = s.max();
    let s_min = s.min();
    Some(if s_min > 0.0 { s_max / s_min } else { f64::INFINITY })
}

/// Column order of a Businger–Golub pivoted QR: at each step the column with the largest norm after removing
/// what the already chosen columns explain (modified Gram-Schmidt with one re-orthogonalisation).
pub(super) fn pivot_order(a: &DMatrix<f64>) -> Vec<usize> {
    let (m, n) = a.shape();
    let mut cols: Vec<DVector<f64>> = (0..n).map(|j| a.column(j).into_owned()).collect();
    let mut remaining: Vec<usize> = (0..n).collect();
    let mut basis: Vec<DVector<f64>> = Vec::new();
    let mut order = Vec::with_capacity(n);
    while !remaining.is_empty() {
        let mut best = 0;
        let mut best_norm = -1.0;
        for (p, &j) in remaining.iter().enumerate() {
            let norm = cols[j].norm();
            if norm > best_norm {
                best = p;
                best_norm = norm;
            }
        }
        let j = remaining.remove(best);
        order.push(j);
        if basis.len() < m && best_norm > 0.0 {
            let mut q = cols[j].clone();
            for _ in 0..2 {
                for b in &basis {
                    let c = b.dot(&q);
                    q.axpy(-c, b, 1.0);
                }
            }
            let norm = q.norm();
            if norm > 0.0 {
                q /= norm;
                for &k in &remaining {
                    for _ in 0..2 {
                        let c = q.dot(&cols[k]);
                        cols[k].axpy(-c, &q, 1.0);
                    }
                }
                basis.push(q);
            }
        }
    }
    order
}

/// Rows spanning the same space as the rows of `basis` (each row a null vector), made sparse by Gauss-Jordan
/// elimination with largest-entry pivoting: each row has a 1 at its pivot column and 0 at the others' pivots.
pub(super) fn sparsify(mut basis: DMatrix<f64>) -> DMatrix<f64> {
    let (d, n) = basis.shape();
    let mut used = vec![false; n];
    for r in 0..d {
        let mut best = (r, 0, 0.0);
        for i in r..d {
            for (c, &u) in used.iter().enumerate() {
                if !u && basis[(i, c)].abs() > best.2 {
                    best = (i, c, basis[(i, c)].abs());
                }
            }
        }
        if best.2 == 0.0 {
            break;
        }
        let (i, c, _) = best;
        basis.swap_rows(r, i);
        used[c] = true;
        let pivot = basis[(r, c)];
        let row = basis.row(r) / pivot;
        basis.set_row(r, &row);
        for i in 0..d {
            if i != r {
                let f = basis[(i, c)];
                if f != 0.0 {
                    let new = basis.row(i) - row.clone() * f;
                    basis.set_row(i, &new);
                }
            }
        }
    }
    basis
}
