//! The tracker's last stages: the uncertainty of the total from the inverse normal matrix,
//! and the per-sample outputs φ(t), dL(t) and σ(t).

use super::config::GouyCorrection;
use super::factor::Factor;
use super::grid::Grid;
use super::harmonic::{Harmonic, HarmonicProfile};
use super::kernel::State;
use nalgebra::Vector3;

/// Convert a phase change to a length change, with the optional Gouy correction.
pub(super) fn phase_to_dl(dphi: f64, kappa: f64, gouy: &Option<GouyCorrection>) -> f64 {
    let mut dl = dphi / kappa;
    if let Some(g) = gouy {
        let zr = g.rayleigh_range_nm;
        let g0 = g.gap_at_start_nm;
        let a0 = (g0 / zr).atan();
        for _ in 0..3 {
            let gap = g0 + g.gap_sign * dl;
            let x = gap / zr;
            let res = kappa * dl - g.gap_sign * (x.atan() - a0) - dphi;
            let der = kappa - 1.0 / (zr * (1.0 + x * x));
            dl -= res / der;
        }
    }
    dl
}

/// var(φ(end) - φ(start)) from the inverse normal matrix (δ at both ends and γ): `c_end` is
/// the grid coordinate of the last sample, `e_gamma` the phase lever of γ between the ends;
/// `e` and `ze` are scratch.
#[inline(always)]
pub(super) fn total_phase_variance(
    c_end: f64,
    factor: &mut Factor,
    z_border: &[Vector3<f64>],
    schur: f64,
    e_gamma: f64,
    e: &mut Vec<Vector3<f64>>,
    ze: &mut Vec<Vector3<f64>>,
) -> f64 {
    let n_knots = z_border.len();
    let j_end = (c_end as usize).min(n_knots - 2);
    let t_end = c_end - j_end as f64;
    e.clear();
    e.resize(n_knots, Vector3::zeros());
    e[0][0] -= 1.0;
    e[j_end][0] += 1.0 - t_end;
    e[j_end + 1][0] += t_end;
    ze.clear();
    ze.resize(n_knots, Vector3::zeros());
    factor.solve_into(e, ze);
    let ez: f64 = e.iter().zip(z_border.iter()).map(|(a, b)| a.dot(b)).sum();
    e.iter().zip(ze.iter()).map(|(a, b)| a.dot(b)).sum::<f64>() + (ez - e_gamma).powi(2) / schur
}

/// What the per-sample outputs are computed from besides the state and the grid.
pub(super) struct OutputScale<'a> {
    /// The δδ variances at the knots.
    pub(super) dvar: &'a [f64],
    /// The system's inverse applied to the border.
    pub(super) z_border: &'a [Vector3<f64>],
    /// Schur complement of γ.
    pub(super) schur: f64,
    /// Factor on the variances: χ² when above 1.
    pub(super) inflate: f64,
    /// Fringe phase per nm of length change, rad/nm.
    pub(super) kappa: f64,
}

/// φ(t), dL(t) and (when `sigma` is to be filled) σ(t), segment by segment (elementwise).
/// `phase` holds the grid coordinate of every sample on entry and φ(t) on return.
#[inline(always)]
pub(super) fn phase_and_dl(
    state: &State,
    grid: &Grid,
    hint_dl_nm: &[f64],
    scale: &OutputScale,
    phase: &mut [f64],
    dl: &mut Vec<f64>,
    sigma: Option<&mut Vec<f64>>,
) {
    let (dvar, z_border, schur) = (scale.dvar, scale.z_border, scale.schur);
    let n_knots = grid.knot_k.len();
    let nm_per_rad = 1.0 / scale.kappa;
    let phase_scale = 1.0 + state.gamma;
    let var0 = dvar[0] + z_border[0][0].powi(2) / schur; // u = 0 at the first sample
    let phi0 = state.intercept + state.delta[0];
    let sig_scale = scale.inflate * nm_per_rad * nm_per_rad;
    let mut sigma = sigma;
    for j in 0..n_knots - 1 {
        let (k0, k1) = (grid.seg_first[j], grid.seg_first[j + 1]);
        let jf = j as f64;
        let (d0, d1) = (state.delta[j], state.delta[j + 1]);
        if let Some(sigma) = sigma.as_deref_mut() {
            let (v0, v1) = (dvar[j], dvar[j + 1]);
            let (z0, z1) = (z_border[j][0], z_border[j + 1][0]);
            sigma.extend(phase[k0..k1].iter().zip(&hint_dl_nm[k0..k1]).map(|(&c, &h)| {
                let t = c - jf;
                let w0 = 1.0 - t;
                let u = state.rad_per_hint_nm * (h - state.hint_ref);
                let zd = w0 * z0 + t * z1;
                let v = w0 * v0 + t * v1 + (zd - u) * (zd - u) / schur;
                ((v + var0) * sig_scale).max(0.0).sqrt()
            }));
        }
        for (p, &h) in phase[k0..k1].iter_mut().zip(&hint_dl_nm[k0..k1]) {
            let t = *p - jf;
            let u = state.rad_per_hint_nm * (h - state.hint_ref);
            *p = state.intercept + u * phase_scale + (1.0 - t) * d0 + t * d1;
        }
        dl.extend(phase[k0..k1].iter().map(|&p| (p - phi0) * nm_per_rad));
    }
}

/// The Gouy correction of dL. It is smooth in dL: the exact inversion is tabulated over the
/// trace's range and interpolated (error ≪ 1 pm).
#[inline(always)]
pub(super) fn apply_gouy(dl: &mut [f64], g: &GouyCorrection, kappa: f64) {
    let gouy = Some(*g);
    let (lo, hi) = dl.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &d| (a.min(d), b.max(d)));
    const TABLE: usize = 512;
    let step = ((hi - lo) / TABLE as f64).max(f64::MIN_POSITIVE);
    let table: Vec<f64> = (0..=TABLE)
        .map(|i| {
            let d0 = lo + step * i as f64;
            phase_to_dl(d0 * kappa, kappa, &gouy) - d0
        })
        .collect();
    for d in dl.iter_mut() {
        let x = ((*d - lo) / step).clamp(0.0, TABLE as f64);
        let i = (x as usize).min(TABLE - 1);
        let t = x - i as f64;
        *d += table[i] + t * (table[i + 1] - table[i]);
    }
}

/// The harmonic reported: a fringe model's harmonics averaged over the trace (they turn on
/// rotations), else the mean of the profile.
#[inline(always)]
pub(super) fn reported_harmonic(shape: Option<&[Harmonic]>, harm: &HarmonicProfile) -> Harmonic {
    match shape {
        Some(sh) => {
            let n = sh.len();
            let stride = (n / 1024).max(1);
            let m = n.div_ceil(stride) as f64;
            let sum = |f: fn(&Harmonic) -> f64| sh.iter().step_by(stride).map(f).sum::<f64>() / m;
            Harmonic {
                cos_rel: sum(|h| h.cos_rel),
                sin_rel: sum(|h| h.sin_rel),
                cos3_rel: sum(|h| h.cos3_rel),
                sin3_rel: sum(|h| h.sin3_rel),
            }
        }
        None => harm.mean(),
    }
}
