//! The fringe contrast's own shape against the tilt, from the optics model alone, and the tilt
//! term of a rotation about a transverse axis fitted to it with the width free: a Gaussian with a
//! quartic leaves the model's own contrast 8 nm off at the end of a 6° rotation, this shape
//! a fraction of a nanometre.

use super::{half_peak_to_peak, TiltTerm};
use crate::model::optics::FabryPerot;
use nalgebra::{Matrix3, Vector3};

/// Tabulation step and range of the tilt (rad).
const STEP_RAD: f64 = 2e-4;
const MAX_RAD: f64 = 0.15;

/// `ln B(γ) − ln B(0)` of the optics model's fringe at one gap, tabulated against the tilt γ.
#[derive(Debug, Clone)]
pub struct ContrastShape {
    ln_b: Vec<f64>,
}

impl ContrastShape {
    /// The shape of `fp`'s contrast at gap `gap_um`.
    pub fn of(fp: &FabryPerot, gap_um: f64) -> Self {
        let n = (MAX_RAD / STEP_RAD) as usize + 2;
        let b0 = half_peak_to_peak(fp, gap_um, 0.0).ln();
        Self { ln_b: (0..n).map(|k| half_peak_to_peak(fp, gap_um, k as f64 * STEP_RAD).ln() - b0).collect() }
    }

    /// `ln B(γ) − ln B(0)`, linearly interpolated; `None` beyond the table.
    pub fn at(&self, gamma_rad: f64) -> Option<f64> {
        let x = gamma_rad.abs() / STEP_RAD;
        let i = x.floor() as usize;
        let (a, b) = (*self.ln_b.get(i)?, *self.ln_b.get(i + 1)?);
        Some(a + (b - a) * (x - i as f64))
    }
}

/// The tilt along a rotation by φ about an axis square to the beam, from the start's in-plane
/// component `c2 = sin γ_in`: `cos γ = √(1 − c2²)·cos φ + c2·sin φ` (the out-of-plane tilt, of
/// second order, left out).
fn tilt_at(c2: f64, phi: f64) -> f64 {
    ((1.0 - c2 * c2).max(0.0).sqrt() * phi.cos() + c2 * phi.sin()).clamp(-1.0, 1.0).acos()
}

/// Fit `ln B = α + F(k·γ(φ))` to `samples` (angle (rad), amplitude, σ of the amplitude), with
/// `F` the optics' `shape`, the width factor `k` free (a mode field not the model's) and the
/// relative error `floor` added to each amplitude's; Gauss-Newton from `start_c2`. With the
/// tilt term at cavity length `gap_um`, and `k`.
pub fn fit_with_shape(
    samples: &[(f64, f64, f64)],
    gap_um: f64,
    shape: &ContrastShape,
    start_c2: f64,
    floor: f64,
) -> Option<(TiltTerm, f64)> {
    let residuals = |th: &Vector3<f64>| -> Option<Vec<f64>> {
        samples
            .iter()
            .map(|&(phi, b, sigma)| {
                let w = 1.0 / (sigma / b).hypot(floor);
                Some(w * (b.ln() - th[0] - shape.at(th[2] * tilt_at(th[1], phi))?))
            })
            .collect()
    };
    let n = samples.len();
    let alpha0 =
        samples.iter().map(|&(phi, b, _)| b.ln() - shape.at(tilt_at(start_c2, phi)).unwrap_or(0.0)).sum::<f64>()
            / n.max(1) as f64;
    let mut th = Vector3::new(alpha0, start_c2, 1.0);
    let steps = [0.0, 1e-7, 1e-6];
    let mut normal = Matrix3::zeros();
    let mut r = residuals(&th)?;
    for _ in 0..40 {
        let mut jac = vec![[0.0; 3]; n];
        for (p, h) in steps.iter().enumerate() {
            if p == 0 {
                jac.iter_mut().zip(samples).for_each(|(row, s)| row[0] = -1.0 / (s.2 / s.1).hypot(floor));
                continue;
            }
            let (mut up, mut down) = (th, th);
            up[p] += h;
            down[p] -= h;
            let (ru, rd) = (residuals(&up)?, residuals(&down)?);
            for i in 0..n {
                jac[i][p] = (ru[i] - rd[i]) / (2.0 * h);
            }
        }
        normal = Matrix3::zeros();
        let mut grad = Vector3::zeros();
        for (row, ri) in jac.iter().zip(&r) {
            let j = Vector3::new(row[0], row[1], row[2]);
            normal += j * j.transpose();
            grad += j * *ri;
        }
        let step = normal.try_inverse()? * -grad;
        th += step;
        r = residuals(&th)?;
        if step[1].abs() < 1e-11 && step[2].abs() < 1e-10 {
            break;
        }
    }
    let chi2 = r.iter().map(|v| v * v).sum::<f64>();
    let scale = if n > 3 { (chi2 / (n - 3) as f64).max(1.0) } else { 1.0 };
    let var_c2 = normal.try_inverse()?[(1, 1)] * scale;
    let c2 = th[1];
    let c1 = (1.0 - c2 * c2).max(0.0).sqrt();
    let g = [-c2 / c1, 1.0];
    let cov = [[g[0] * g[0] * var_c2, g[0] * var_c2], [g[0] * var_c2, var_c2]];
    (th[2] > 0.0 && c2.abs() < 1.0).then_some((TiltTerm { gap_um, c: [c1, c2], cov, relative: 0.0 }, th[2]))
}
