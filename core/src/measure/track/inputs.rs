//! Input checks and the scales of a trace: the first stages of the tracker.

use super::config::{FringeModel, TrackConfig};
use super::coordinates::{REFINE_START, T_KNOT};
use crate::measure::signal::{check_finite, rad_per_nm, FringeError};

/// The trace's length and the scales every stage works in.
pub(super) struct TrackScale {
    /// Samples in the trace.
    pub(super) n: usize,
    /// Fringe phase per nm of length change, rad/nm.
    pub(super) kappa: f64,
    /// One fringe of length change, nm; also the path travelled per knot of the grid.
    pub(super) fringe_nm: f64,
    /// Knot intervals over the first fringe of travel ([`super::coordinates::refine_start`]).
    pub(super) refine: f64,
    /// Decimation of the first Gauss-Newton iterations: every `decimation`-th sample.
    pub(super) decimation: usize,
}

impl TrackScale {
    /// The scales of a trace whose inputs passed [`check_inputs`].
    #[inline(always)]
    pub(super) fn new(hint_dl_nm: &[f64], wavelength_nm: f64, n_air: f64, cfg: &TrackConfig) -> Self {
        let n = hint_dl_nm.len();
        // Path estimate from every 16th sample (fringes are sampled ≥ 20 times, so this is
        // close): it sets the decimation before the single full pass over the hint.
        let path_est: f64 = hint_dl_nm
            .iter()
            .step_by(16)
            .zip(hint_dl_nm.iter().step_by(16).skip(1))
            .map(|(a, b)| (b - a).abs())
            .sum::<f64>();
        let kappa = rad_per_nm(wavelength_nm, n_air);
        let fringe_nm = wavelength_nm / (2.0 * n_air);
        let refine = if cfg.start_walk_rad > 0.0 { REFINE_START as f64 } else { 1.0 };
        // Decimation of the first Gauss-Newton iterations: about 8 samples per knot.
        let knots_est =
            if path_est.is_finite() { path_est / fringe_nm } else { 0.0 } + n as f64 / T_KNOT + 1.0 + refine;
        let decimation = if n >= 20_000 { ((n as f64 / knots_est) as usize / 8).clamp(1, 8) } else { 1 };
        Self { n, kappa, fringe_nm, refine, decimation }
    }
}

/// The sample-aligned inputs: a non-empty trace, a hint and a fringe model of its length, a
/// model with finite values, a positive amplitude and harmonics below half the fundamental.
#[inline(always)]
pub(super) fn check_inputs(
    intensity: &[f64],
    hint_dl_nm: &[f64],
    model: Option<&FringeModel>,
) -> Result<(), FringeError> {
    let n = intensity.len();
    if n == 0 {
        return Err(FringeError::EmptyTrace);
    }
    if hint_dl_nm.len() != n {
        return Err(FringeError::LengthMismatch { intensity: n, other: hint_dl_nm.len(), what: "motion hint" });
    }
    if let Some(fm) = model {
        for (len, what) in [
            (fm.harmonics.len(), "fringe model harmonics"),
            (fm.offset.len(), "fringe model offset"),
            (fm.amplitude.len(), "fringe model amplitude"),
        ] {
            if len != n {
                return Err(FringeError::LengthMismatch { intensity: n, other: len, what });
            }
        }
        check_finite("fringe model offset", fm.offset)?;
        check_finite("fringe model amplitude", fm.amplitude)?;
        if let Some(index) = fm.amplitude.iter().position(|&b| b <= 0.0) {
            return Err(FringeError::InvalidParameter {
                name: "fringe model amplitude",
                value: index as f64,
                reason: "must be positive (value: sample index)",
            });
        }
        let harmonics = fm.harmonics;
        if let Some(index) =
            harmonics.iter().position(|h| !h.coefficients().iter().all(|v| v.is_finite() && v.abs() < 0.5))
        {
            return Err(FringeError::InvalidParameter {
                name: "fringe shape",
                value: index as f64,
                reason: "harmonics must be finite and below 0.5 of the fundamental (value: sample index)",
            });
        }
    }
    Ok(())
}

/// One pass over the intensity: [`check_finite`], its largest magnitude, and every
/// `dec`-th sample appended to `decimated` (when `dec > 1`).
pub(super) fn scan_intensity(xs: &[f64], dec: usize, decimated: &mut Vec<f64>) -> Result<f64, FringeError> {
    const B: usize = 256;
    let mut max_abs = [0.0f64; 4];
    for (bi, block) in xs.chunks(B).enumerate() {
        let mut lanes = [0.0f64; 4];
        // four samples at a time with fixed lanes, so that the lanes stay in registers
        let quads = block.chunks_exact(4);
        let tail = quads.remainder();
        for q in quads {
            for l in 0..4 {
                lanes[l] += q[l] * 0.0;
                let a = q[l].abs();
                max_abs[l] = if a > max_abs[l] { a } else { max_abs[l] };
            }
        }
        for (l, &v) in tail.iter().enumerate() {
            lanes[l] += v * 0.0;
            let a = v.abs();
            max_abs[l] = if a > max_abs[l] { a } else { max_abs[l] };
        }
        if lanes.iter().any(|l| l.is_nan()) {
            if let Some(i) = block.iter().position(|v| !v.is_finite()) {
                let index = bi * B + i;
                return Err(FringeError::NonFinite { what: "intensity", index, value: xs[index] });
            }
        }
        if dec > 1 {
            let k0 = bi * B;
            decimated.extend(block.iter().skip(k0.next_multiple_of(dec) - k0).step_by(dec));
        }
    }
    Ok(max_abs.iter().fold(0f64, |m, &v| m.max(v)))
}
