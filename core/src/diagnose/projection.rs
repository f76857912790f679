//! Projection off a Jacobian's determined column space: what the fit and the scoring both use to
//! take out of a signature what the other parameters already explain.

use nalgebra::{DMatrix, DVector};

/// Relative singular-value threshold below which a direction counts as undetermined.
pub const RANK_TOLERANCE: f64 = 1e-7;

/// Projection onto the orthogonal complement of a matrix's determined column space.
#[derive(Debug, Clone)]
pub struct Projector {
    u: DMatrix<f64>,
}

impl Projector {
    /// The projector for `j`; columns below [`RANK_TOLERANCE`] of the largest singular value are
    /// treated as absent.
    pub fn new(j: &DMatrix<f64>) -> Self {
        if j.ncols() == 0 || j.nrows() == 0 {
            return Self { u: DMatrix::zeros(j.nrows(), 0) };
        }
        let svd = j.clone().svd(true, false);
        let smax = svd.singular_values.max();
        let u = svd.u.expect("U requested");
        let keep: Vec<usize> =
            (0..svd.singular_values.len()).filter(|&k| svd.singular_values[k] > RANK_TOLERANCE * smax).collect();
        Self { u: u.select_columns(keep.iter()) }
    }

    /// The part of `s` orthogonal to the column space.
    pub fn orthogonal(&self, s: &DVector<f64>) -> DVector<f64> {
        if self.u.ncols() == 0 {
            return s.clone();
        }
        s - &self.u * (self.u.transpose() * s)
    }
}
