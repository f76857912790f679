//! The paper's gap from a sweep: the free spectral range from the spacing of the reflection peaks.

use super::{check_n_air, validate, GapEstimate, GapMethod, SweepError};
use crate::measure::extrema::{detect_extrema, ExtremumKind, HysteresisConfig};
use nalgebra::Vector3;
use std::f64::consts::TAU;

/// The paper's method: free spectral range from the spacing of the reflection peaks,
/// Δλ_FSR = λ²/(2·n·L) (paper eq. 35/36). Each peak is located by a quadratic fit in λ to
/// its top; L comes from a weighted regression of 1/λ_peak on the peak order
/// (1/λ_j = const - j/(2nL)). σ from the peak-position uncertainties, scaled by the
/// regression's χ² when there are three peaks or more. It ignores the offset slope and the
/// Gouy phase, which shift the peaks.
pub fn peak_fsr_gap(wavelength_nm: &[f64], irradiance: &[f64], n_air: f64) -> Result<GapEstimate, SweepError> {
    check_n_air(n_air)?;
    let sp = validate(wavelength_nm, irradiance)?;
    // λ ascending
    let lam: Vec<f64> = sp.k.iter().rev().map(|k| TAU / k).collect();
    let y: Vec<f64> = sp.y.iter().rev().copied().collect();
    let n = lam.len();
    let ext = detect_extrema(&y, &HysteresisConfig::default())
        .map_err(|e| SweepError::FitFailed(format!("peak detection: {e}")))?;
    let mut peaks = Vec::new(); // (λ, σ_λ)
    let mut rss_all = 0.0;
    let mut cnt_all = 0usize;
    for (j, e) in ext.iter().enumerate() {
        if e.kind != ExtremumKind::Max {
            continue;
        }
        let mut neigh = f64::NEG_INFINITY;
        if j > 0 {
            neigh = neigh.max(ext[j - 1].value);
        }
        if j + 1 < ext.len() {
            neigh = neigh.max(ext[j + 1].value);
        }
        if !neigh.is_finite() {
            continue;
        }
        let thr = e.value - 0.25 * (e.value - neigh);
        let (mut i0, mut i1) = (e.index, e.index);
        while i0 > 0 && y[i0 - 1] >= thr {
            i0 -= 1;
        }
        while i1 + 1 < n && y[i1 + 1] >= thr {
            i1 += 1;
        }
        if i1 - i0 + 1 < 5 || i0 == 0 || i1 == n - 1 {
            continue;
        }
        let t0 = lam[e.index];
        let mut ata = nalgebra::Matrix3::<f64>::zeros();
        let mut aty = Vector3::<f64>::zeros();
        for i in i0..=i1 {
            let t = lam[i] - t0;
            let x = Vector3::new(1.0, t, t * t);
            ata += x * x.transpose();
            aty += x * y[i];
        }
        let Some(inv) = ata.try_inverse() else {
            continue;
        };
        let c = inv * aty;
        if c[2] >= 0.0 {
            continue;
        }
        let tv = -c[1] / (2.0 * c[2]);
        if tv < lam[i0] - t0 || tv > lam[i1] - t0 {
            continue;
        }
        let mut rss = 0.0;
        for i in i0..=i1 {
            let t = lam[i] - t0;
            rss += (y[i] - c[0] - c[1] * t - c[2] * t * t).powi(2);
        }
        let m = (i1 - i0 + 1) as f64;
        rss_all += rss;
        cnt_all += i1 - i0 + 1;
        let s2 = rss / (m - 3.0);
        let grad = Vector3::new(0.0, -1.0 / (2.0 * c[2]), c[1] / (2.0 * c[2] * c[2]));
        let var = s2 * (grad.transpose() * inv * grad)[0];
        peaks.push((t0 + tv, var.max(0.0).sqrt()));
    }
    if peaks.len() < 2 {
        return Err(SweepError::TooFewPeaks { found: peaks.len() });
    }
    // Weighted regression of 1/λ on the order index j (consecutive peaks).
    let pts: Vec<(f64, f64, f64)> = peaks
        .iter()
        .enumerate()
        .map(|(j, &(l, s))| {
            let sv = (s / (l * l)).max(1e-18);
            (j as f64, 1.0 / l, 1.0 / (sv * sv))
        })
        .collect();
    let sw: f64 = pts.iter().map(|p| p.2).sum();
    let xm = pts.iter().map(|p| p.0 * p.2).sum::<f64>() / sw;
    let ym = pts.iter().map(|p| p.1 * p.2).sum::<f64>() / sw;
    let sxx: f64 = pts.iter().map(|p| p.2 * (p.0 - xm).powi(2)).sum();
    let sxy: f64 = pts.iter().map(|p| p.2 * (p.0 - xm) * (p.1 - ym)).sum();
    let slope = sxy / sxx;
    let decreasing = slope < 0.0; // false for NaN too
    if !decreasing {
        return Err(SweepError::FitFailed("peak orders not increasing".to_string()));
    }
    let mut var_slope = 1.0 / sxx;
    if pts.len() >= 3 {
        let chi2: f64 =
            pts.iter().map(|p| p.2 * (p.1 - ym - slope * (p.0 - xm)).powi(2)).sum::<f64>() / (pts.len() as f64 - 2.0);
        var_slope *= chi2.max(1.0);
    }
    let l = -1.0 / (2.0 * n_air * slope);
    let sigma_l = l * var_slope.sqrt() / slope.abs();
    let fringes = 2.0 * n_air * l * (1.0 / lam[0] - 1.0 / lam[n - 1]);
    Ok(GapEstimate {
        method: GapMethod::PeakFsr,
        gap_um: l * 1e-3,
        sigma_um: sigma_l * 1e-3,
        fringes_across_sweep: fringes,
        fit_rms: if cnt_all > 0 { (rss_all / cnt_all as f64).sqrt() } else { 0.0 },
    })
}
