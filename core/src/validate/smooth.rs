//! What a smooth path leaves of a rotation's validation curve: the fringe shape's check.
//!
//! A rigid rotation about a fixed axis moves the cavity length smoothly with the angle (a
//! low-order function over the few degrees of a validation rotation), while a fringe shape
//! tracked at the wrong tilt (harmonics whose phase turns with `|L|·γ²`) reads the phase with a
//! cyclic error, one or two cycles per fringe. The residual of the curve about its best smooth
//! fit in the angle is that error: small when the shape fits the fringes, whatever the figure.

use nalgebra::{DMatrix, DVector};

/// Degree of the polynomial in the (normalised) angle that stands for the smooth path.
const DEGREE: usize = 6;
/// Rows of the fit at most (the curve is thinned evenly).
const MAX_ROWS: usize = 4000;

/// The peak to peak (nm) of `curve_nm` about its least-squares polynomial of degree
/// [`DEGREE`] in `angles_rad` (same length); `None` when the angle does not move.
pub fn cyclic_residual_nm(curve_nm: &[f64], angles_rad: &[f64]) -> Option<f64> {
    let n = curve_nm.len().min(angles_rad.len());
    let (lo, hi) = angles_rad[..n].iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
    if n <= 2 * DEGREE || hi - lo <= 0.0 {
        return None;
    }
    let x = |i: usize| (2.0 * angles_rad[i] - lo - hi) / (hi - lo);
    let stride = n.div_ceil(MAX_ROWS).max(1);
    let rows: Vec<usize> = (0..n).step_by(stride).collect();
    let a = DMatrix::from_fn(rows.len(), DEGREE + 1, |r, c| x(rows[r]).powi(c as i32));
    let b = DVector::from_iterator(rows.len(), rows.iter().map(|&i| curve_nm[i]));
    let coef = a.svd(true, true).solve(&b, 1e-12).ok()?;
    let fit = |i: usize| (0..=DEGREE).map(|c| coef[c] * x(i).powi(c as i32)).sum::<f64>();
    let r: Vec<f64> = (0..n).map(|i| curve_nm[i] - fit(i)).collect();
    Some(r.iter().copied().fold(f64::NEG_INFINITY, f64::max) - r.iter().copied().fold(f64::INFINITY, f64::min))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A smooth path leaves nothing; a cyclic error of ±4 nm over five cycles is read back.
    #[test]
    fn a_cyclic_error_is_read_and_a_smooth_path_left_alone() {
        let n = 20_000;
        let angles: Vec<f64> = (0..n).map(|i| (-3.0 + 6.0 * i as f64 / n as f64).to_radians()).collect();
        let smooth: Vec<f64> = angles.iter().map(|a| 900e3 * (1.0 / (a + 0.02).cos() - 1.0) + 40.0 * a).collect();
        assert!(cyclic_residual_nm(&smooth, &angles).unwrap() < 0.05);
        let cyclic: Vec<f64> = smooth
            .iter()
            .zip(&angles)
            .map(|(s, a)| s + 4.0 * (5.0 * 2.0 * std::f64::consts::PI * a / 0.1047).sin())
            .collect();
        let r = cyclic_residual_nm(&cyclic, &angles).unwrap();
        assert!((r - 8.0).abs() < 1.0, "{r}");
    }
}
