//! What every fringe analysis shares: the error type of its inputs and their checks, the fast
//! `sincos` of the per-sample loops, the fringe phase per unit length, and a small two-beam
//! signal that renders synthetic traces (tests, benchmarks, demos).

use rand::Rng;
use rand_distr::{Distribution, Normal};
use std::f64::consts::PI;
use thiserror::Error;

/// What is wrong with the input of a fringe analysis.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum FringeError {
    /// The trace has no samples.
    #[error("empty trace: no samples to analyse")]
    EmptyTrace,
    /// Two arrays that must be sample-aligned have different lengths.
    #[error("trace has {intensity} intensity samples but {other} {what} samples")]
    LengthMismatch {
        /// Number of intensity samples.
        intensity: usize,
        /// Length of the other array.
        other: usize,
        /// Name of the other array.
        what: &'static str,
    },
    /// A sample is NaN or infinite.
    #[error("non-finite {what} at sample {index}: {value}")]
    NonFinite {
        /// Which array.
        what: &'static str,
        /// Sample index.
        index: usize,
        /// The offending value.
        value: f64,
    },
    /// A scalar parameter is out of its valid range.
    #[error("invalid parameter {name} = {value}: {reason}")]
    InvalidParameter {
        /// Parameter name.
        name: &'static str,
        /// Its value.
        value: f64,
        /// Why it is rejected.
        reason: &'static str,
    },
    /// The trace does not cover a full fringe, so the envelope (A, B) cannot be measured.
    #[error(
        "too few fringes to measure the envelope: found {maxima} fringe maxima and {minima} minima \
         (need at least one of each, i.e. a trace covering one full fringe); \
         pass a known envelope for shorter traces"
    )]
    TooFewFringes {
        /// Fringe maxima found (turning points of the motion excluded).
        maxima: usize,
        /// Fringe minima found (turning points of the motion excluded).
        minima: usize,
    },
    /// The motion hint is constant: there is no motion whose phase could be tracked.
    #[error("the motion hint never changes: nothing to track")]
    NoMotion,
    /// The motion is too fast for the sampling: the fringe phase would alias.
    #[error(
        "motion undersampled at sample {index}: the hint moves {step_nm:.1} nm in one sample, \
         more than a quarter fringe ({max_nm:.1} nm); at least ~20 samples per fringe are needed"
    )]
    Undersampled {
        /// Sample index where the hint jumps.
        index: usize,
        /// Hint change over that sample, nm.
        step_nm: f64,
        /// Largest trackable change per sample, nm.
        max_nm: f64,
    },
    /// The phase fit produced non-finite numbers (degenerate data).
    #[error("the phase fit diverged: {0}")]
    FitDiverged(&'static str),
}

/// Fast `(sin x, cos x)`: Cody-Waite reduction by π/2 and the fdlibm minimax kernels,
/// branch-free so that lane-wise loops vectorise. Absolute error below 1e-15 for
/// |x| < 1e6; used in the per-sample loops.
#[inline(always)]
pub(crate) fn sincos(x: f64) -> (f64, f64) {
    sincos_k::<false>(x)
}

/// [`sincos`] with the polynomials fused (one rounding per multiply-add) when `FMA`: for
/// callers compiled with the FMA feature.
#[inline(always)]
pub(crate) fn sincos_k<const FMA: bool>(x: f64) -> (f64, f64) {
    const PIO2_1: f64 = 1.570_796_326_734_125_6; // first 33 bits of π/2
    const PIO2_1T: f64 = 6.077_100_506_506_192e-11; // π/2 - PIO2_1
    const TOINT: f64 = 6_755_399_441_055_744.0; // 1.5·2^52: round to nearest integer
    const S1: f64 = -1.666_666_666_666_663_2e-1;
    const S2: f64 = 8.333_333_333_322_49e-3;
    const S3: f64 = -1.984_126_982_985_795e-4;
    const S4: f64 = 2.755_731_370_707_007e-6;
    const S5: f64 = -2.505_076_025_340_686e-8;
    const S6: f64 = 1.589_690_995_211_55e-10;
    const C1: f64 = 4.166_666_666_666_66e-2;
    const C2: f64 = -1.388_888_888_887_411e-3;
    const C3: f64 = 2.480_158_728_947_673e-5;
    const C4: f64 = -2.755_731_435_139_066_3e-7;
    const C5: f64 = 2.087_572_321_298_175e-9;
    const C6: f64 = -1.135_964_755_778_819_5e-11;
    let kp = x * std::f64::consts::FRAC_2_PI + TOINT;
    // the low mantissa bits of kp hold the rounded multiple of π/2 (mod 4)
    let q = kp.to_bits();
    let kf = kp - TOINT;
    let r = (x - kf * PIO2_1) - kf * PIO2_1T;
    let z = r * r;
    let (s, c) = if FMA {
        let ps =
            madd::<true>(z, madd::<true>(z, madd::<true>(z, madd::<true>(z, madd::<true>(z, S6, S5), S4), S3), S2), S1);
        let pc =
            madd::<true>(z, madd::<true>(z, madd::<true>(z, madd::<true>(z, madd::<true>(z, C6, C5), C4), C3), C2), C1);
        (madd::<true>(r * z, ps, r), madd::<true>(z * z, pc, madd::<true>(-0.5, z, 1.0)))
    } else {
        (
            r + r * z * (S1 + z * (S2 + z * (S3 + z * (S4 + z * (S5 + z * S6))))),
            1.0 - 0.5 * z + z * z * (C1 + z * (C2 + z * (C3 + z * (C4 + z * (C5 + z * C6))))),
        )
    };
    let swap = 0u64.wrapping_sub(q & 1);
    let (sb, cb) = (s.to_bits(), c.to_bits());
    let ss = (sb & !swap) | (cb & swap);
    let cc = (cb & !swap) | (sb & swap);
    let sin = f64::from_bits(ss ^ ((q & 2) << 62));
    let cos = f64::from_bits(cc ^ ((q.wrapping_add(1) & 2) << 62));
    (sin, cos)
}

/// Phase per unit length change of the cavity, rad/nm: 4π·n_air/λ.
pub(crate) fn rad_per_nm(wavelength_nm: f64, n_air: f64) -> f64 {
    4.0 * PI * n_air / wavelength_nm
}

/// a·b + c, fused when the caller is compiled with FMA.
#[inline(always)]
pub(crate) fn madd<const FMA: bool>(a: f64, b: f64, c: f64) -> f64 {
    if FMA {
        a.mul_add(b, c)
    } else {
        a * b + c
    }
}

pub(crate) fn check_finite(what: &'static str, xs: &[f64]) -> Result<(), FringeError> {
    // Branch-free test per block (it vectorises; x·0 is NaN exactly when x is not finite),
    // the index searched only in a failing block.
    const B: usize = 256;
    for (bi, block) in xs.chunks(B).enumerate() {
        let mut lanes = [0.0f64; 4];
        let quads = block.chunks_exact(4);
        for (l, &v) in quads.remainder().iter().enumerate() {
            lanes[l] += v * 0.0;
        }
        for q in quads {
            for l in 0..4 {
                lanes[l] += q[l] * 0.0;
            }
        }
        if lanes.iter().any(|l| l.is_nan()) {
            if let Some(i) = block.iter().position(|v| !v.is_finite()) {
                let index = bi * B + i;
                return Err(FringeError::NonFinite { what, index, value: xs[index] });
            }
        }
    }
    Ok(())
}

pub(crate) fn check_optics(wavelength_nm: f64, n_air: f64) -> Result<(), FringeError> {
    if !(wavelength_nm.is_finite() && wavelength_nm > 0.0) {
        return Err(FringeError::InvalidParameter {
            name: "wavelength_nm",
            value: wavelength_nm,
            reason: "must be finite and positive",
        });
    }
    if !(n_air.is_finite() && (1.0..2.0).contains(&n_air)) {
        return Err(FringeError::InvalidParameter { name: "n_air", value: n_air, reason: "must be finite, in [1, 2)" });
    }
    Ok(())
}

pub(crate) fn check_positive(name: &'static str, value: f64) -> Result<(), FringeError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(FringeError::InvalidParameter { name, value, reason: "must be finite and positive" })
    }
}

pub(crate) fn check_non_negative(name: &'static str, value: f64) -> Result<(), FringeError> {
    if value.is_finite() && value >= 0.0 {
        Ok(())
    } else {
        Err(FringeError::InvalidParameter { name, value, reason: "must be finite and non-negative" })
    }
}

/// A small two-beam fringe signal with envelope, harmonic and noise, used to generate
/// synthetic traces: `I = A + B·(cos φ + h·cos(2φ + ψ)) + N(0, σ²)` with
/// `φ = 4πn·gap/λ - arctan(gap/z_R) + φ₀` and `gap = gap_start + dL`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TwoBeamSignal {
    /// Vacuum wavelength, nm.
    pub wavelength_nm: f64,
    /// Refractive index of air.
    pub n_air: f64,
    /// Gap at dL = 0, nm.
    pub gap_start_nm: f64,
    /// Rayleigh range for the Gouy phase, nm (None: no Gouy phase).
    pub rayleigh_range_nm: Option<f64>,
    /// Phase offset φ₀, rad.
    pub phase_offset_rad: f64,
    /// Second-harmonic amplitude h relative to B.
    pub harmonic_rel: f64,
    /// Second-harmonic phase ψ, rad.
    pub harmonic_phase_rad: f64,
    /// White-noise σ, intensity units.
    pub noise_sigma: f64,
}

impl TwoBeamSignal {
    /// Fringe phase at a length change dL (nm).
    pub fn phase_rad(&self, dl_nm: f64) -> f64 {
        let gap = self.gap_start_nm + dl_nm;
        let gouy = self.rayleigh_range_nm.map_or(0.0, |z| (gap / z).atan());
        rad_per_nm(self.wavelength_nm, self.n_air) * gap - gouy + self.phase_offset_rad
    }

    /// Render a trace for per-sample dL (nm), offset A and amplitude B.
    pub fn render<R: Rng + ?Sized>(
        &self,
        dl_nm: &[f64],
        offset: &[f64],
        amplitude: &[f64],
        rng: &mut R,
    ) -> Result<Vec<f64>, FringeError> {
        let n = dl_nm.len();
        if n == 0 {
            return Err(FringeError::EmptyTrace);
        }
        for (what, len) in [("offset", offset.len()), ("amplitude", amplitude.len())] {
            if len != n {
                return Err(FringeError::LengthMismatch { intensity: n, other: len, what });
            }
        }
        check_optics(self.wavelength_nm, self.n_air)?;
        check_non_negative("noise_sigma", self.noise_sigma)?;
        let noise = Normal::new(0.0, self.noise_sigma).map_err(|_| FringeError::InvalidParameter {
            name: "noise_sigma",
            value: self.noise_sigma,
            reason: "invalid normal distribution",
        })?;
        Ok(dl_nm
            .iter()
            .zip(offset.iter().zip(amplitude.iter()))
            .map(|(&d, (&a, &b))| {
                let p = self.phase_rad(d);
                a + b * (p.cos() + self.harmonic_rel * (2.0 * p + self.harmonic_phase_rad).cos()) + noise.sample(rng)
            })
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fast_sincos_matches_std() {
        let mut worst = 0f64;
        for i in 0..200_000 {
            let x = -3.0e5 + i as f64 * 3.000_07;
            let (s0, c0) = x.sin_cos();
            for (s, c) in [sincos(x), sincos_k::<true>(x)] {
                worst = worst.max((s - s0).abs()).max((c - c0).abs());
            }
        }
        assert!(worst < 1e-12, "worst {worst}");
        for x in [0.0, 1e-3, -PI / 4.0, PI / 4.0, PI, -PI, 2.5, 1e4] {
            let (s, c) = sincos(x);
            assert!((s - x.sin()).abs() < 1e-15 && (c - x.cos()).abs() < 1e-15, "{x}");
        }
    }
}
