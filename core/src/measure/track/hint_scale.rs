//! The hint scale from the extrema: each extremum's direction from the hint, the fringe
//! order of the counted ones, and a regression of that order on the hint phase.

use super::config::FringeModel;
use super::inputs::TrackScale;
use crate::measure::extrema::{classify_recorded, Extremum, ExtremumKind};
use std::f64::consts::PI;

/// Linear regression of the fringe order of counted extrema against the hint phase:
/// the hint scale g = dφ/dφ_hint and the coarse phase φ_lin(k) = intercept + g·κ·hint(k).
/// The residuals at the extrema (position in the extremum list, rad) go to `residuals`.
#[derive(Debug, Clone, Copy)]
pub(super) struct ScaleFit {
    pub(super) scale: f64,
    pub(super) sigma: f64,
    pub(super) intercept: f64,
}

/// Fringe orders m (phase = m·π) of the counted extrema, in order, as (hint phase, m·π,
/// position in `extrema`) into `pts`; false if the parity of m contradicts the kind of an
/// extremum (max = even). `ext_hint`: the hint at each extremum. `ext_offset` (empty or
/// one per extremum): where the extremum sits relative to m·π, rad (a fringe model's
/// harmonics and amplitude slope move it).
pub(super) fn fringe_orders(
    extrema: &[Extremum],
    ext_hint: &[f64],
    ext_offset: &[f64],
    kappa: f64,
    pts: &mut Vec<(f64, f64, usize)>,
) -> bool {
    pts.clear();
    let mut m: i64 = 0;
    let mut prev_dir: Option<i8> = None;
    for (i, e) in extrema.iter().enumerate().filter(|(_, e)| e.direction != 0) {
        match prev_dir {
            None => m = if e.kind == ExtremumKind::Max { 0 } else { 1 },
            Some(d) => m += (d as i64 + e.direction as i64) / 2,
        }
        prev_dir = Some(e.direction);
        if (m.rem_euclid(2) == 0) != (e.kind == ExtremumKind::Max) {
            return false;
        }
        pts.push((kappa * ext_hint[i], PI * m as f64 + ext_offset.get(i).copied().unwrap_or(0.0), i));
    }
    true
}

pub(super) fn scale_from_extrema(
    extrema: &[Extremum],
    ext_hint: &[f64],
    ext_offset: &[f64],
    kappa: f64,
    pts: &mut Vec<(f64, f64, usize)>,
    residuals: &mut Vec<(usize, f64)>,
) -> Option<ScaleFit> {
    residuals.clear();
    if !fringe_orders(extrema, ext_hint, ext_offset, kappa, pts) || pts.len() < 2 {
        return None;
    }
    let nf = pts.len() as f64;
    let mx = pts.iter().map(|p| p.0).sum::<f64>() / nf;
    let my = pts.iter().map(|p| p.1).sum::<f64>() / nf;
    let (mut sxx, mut sxy) = (0.0, 0.0);
    for &(x, y, _) in pts.iter() {
        sxx += (x - mx) * (x - mx);
        sxy += (x - mx) * (y - my);
    }
    if sxx < (PI * PI) * 0.25 {
        return None;
    }
    let scale = sxy / sxx;
    let intercept = my - scale * mx;
    let mut rss = 0.0;
    for &(x, y, k) in pts.iter() {
        let r = y - intercept - scale * x;
        rss += r * r;
        residuals.push((k, r));
    }
    // Extremum timing is only good to ~0.1 rad: floor the scatter there.
    let s2 = if nf > 2.0 { (rss / (nf - 2.0)).max(0.01) } else { 0.04 };
    Some(ScaleFit { scale, sigma: (s2 / sxx).sqrt(), intercept })
}

/// The extrema's directions from the hint (turning points of the motion excluded) and the
/// hint scale they give: the regression (None when the extrema cannot give it, with a
/// warning when they should have) and the number of extrema that counted.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(super) fn hint_scale(
    extrema: &mut [Extremum],
    ext_hint: &[f64],
    ext_offset: &mut Vec<f64>,
    points: &mut Vec<(f64, f64, usize)>,
    residuals: &mut Vec<(usize, f64)>,
    hint_dl_nm: &[f64],
    model: Option<&FringeModel>,
    scale: &TrackScale,
    warnings: &mut Vec<String>,
) -> (Option<ScaleFit>, usize) {
    let (n, kappa) = (scale.n, scale.kappa);
    classify_recorded(extrema, ext_hint, hint_dl_nm[0], hint_dl_nm[n - 1], 0.005 * scale.fringe_nm);
    let counted = extrema.iter().filter(|e| e.direction != 0).count();
    // With a fringe model, where each extremum sits on the fundamental's phase: the maximum
    // of B(φ)·f(φ) solves f'(φ) + β·f(φ) = 0, β = d ln B/dφ along the motion. On rotations β
    // reaches 0.07 and changes along the trace: ignoring it biased the hint scale by 0.3 %.
    ext_offset.clear();
    if let Some(fm) = model {
        ext_offset.extend(extrema.iter().map(|e| {
            let k = e.index;
            let (k0, k1) = (k.saturating_sub(8), (k + 8).min(n - 1));
            let dphi = kappa * (hint_dl_nm[k1] - hint_dl_nm[k0]);
            let beta = if dphi.abs() > 1e-6 { (fm.amplitude[k1] / fm.amplitude[k0]).ln() / dphi } else { 0.0 };
            let start = if e.kind == ExtremumKind::Max { 0.0 } else { PI };
            fm.harmonics[k].extremum_near(start, beta) - start
        }));
    }
    let mut scale_fit = scale_from_extrema(extrema, ext_hint, ext_offset, kappa, points, residuals);
    if counted >= 2 && scale_fit.is_none() {
        warnings.push(
            "extremum sequence inconsistent with the hint (missed or spurious extremum): \
             hint scale assumed 1"
                .to_string(),
        );
    }
    if let Some(f) = &scale_fit {
        if !(0.5..2.0).contains(&f.scale) {
            warnings.push(format!("hint scale from the extrema {:.3} is implausible: assumed 1", f.scale));
            scale_fit = None;
        }
    }
    (scale_fit, counted)
}
