//! Absolute gap from a wavelength sweep: irradiance against wavelength, joints fixed → cavity gap (µm) with a standard uncertainty.
//! Owns the wavenumber resampling and FFT seed, the nonlinear model fit (levenberg-marquardt), the paper's peak-FSR method, the Cramér-Rao references and a two-beam sweep test signal.
//!
//! Model fitted (two-beam, k = 2π/λ, x = (k - k0)/(half the k span)):
//! `I(k) = A·(1 + a1·x + a2·x²) + B·cos(2·n·L·(k - k0) + ψ0 - [G(k, L) - G(k0, L)])`, with the
//! optional Gouy phase `G = arctan(L/z_R(k))`, `z_R = π·w0²/λ = w0²·k/2`. The absolute
//! phase 2·n·L·k0 is absorbed in ψ0 (the fringe order is not resolved), so the gap comes
//! from the fringe frequency across the sweep.

mod fit;
pub mod full_model;
mod peak_fsr;
mod sign;
#[cfg(test)]
mod tests;

pub use fit::fit_gap;
pub use peak_fsr::peak_fsr_gap;
pub use sign::{sign_from_sweeps, SweepSign};

use crate::measure::signal::sincos;
use nalgebra::{SMatrix, SVector};
use rand::Rng;
use rand_distr::{Distribution, Normal};
use realfft::RealFftPlanner;
use std::f64::consts::{PI, TAU};
use thiserror::Error;

/// Fewest samples a sweep may have.
pub const MIN_SAMPLES: usize = 16;
/// Fewest fringes across the sweep for the model fit.
pub const MIN_FRINGES: f64 = 1.0;

/// What is wrong with a sweep or its analysis.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum SweepError {
    /// No samples.
    #[error("empty sweep: no samples")]
    EmptySweep,
    /// Too few samples to analyse.
    #[error("sweep has {n} samples, at least {min} are needed")]
    TooFewSamples {
        /// Samples given.
        n: usize,
        /// Minimum.
        min: usize,
    },
    /// Wavelength and irradiance arrays differ in length.
    #[error("sweep has {wavelengths} wavelengths but {irradiances} irradiance samples")]
    LengthMismatch {
        /// Length of the wavelength array.
        wavelengths: usize,
        /// Length of the irradiance array.
        irradiances: usize,
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
    /// The wavelengths are not strictly increasing or strictly decreasing.
    #[error("wavelengths are not strictly monotonic at sample {index} ({previous} nm then {value} nm)")]
    NonMonotonicWavelength {
        /// Index of the offending sample.
        index: usize,
        /// The sample before.
        previous: f64,
        /// The offending value.
        value: f64,
    },
    /// A scalar parameter is out of range.
    #[error("invalid parameter {name} = {value}: {reason}")]
    InvalidParameter {
        /// Parameter name.
        name: &'static str,
        /// Its value.
        value: f64,
        /// Why it is rejected.
        reason: &'static str,
    },
    /// Too few fringes across the sweep for the method.
    #[error("only {fringes:.2} fringes across the sweep, {min} needed: widen the sweep")]
    TooFewFringes {
        /// Fringes found.
        fringes: f64,
        /// Minimum.
        min: f64,
    },
    /// The peak-FSR method needs two reflection peaks.
    #[error("found {found} reflection peak(s) in the sweep, at least 2 are needed for the FSR")]
    TooFewPeaks {
        /// Peaks found.
        found: usize,
    },
    /// The fitted fringe amplitude is not significant.
    #[error("no fringe contrast: amplitude {amplitude:.3e} vs its uncertainty {sigma:.3e}")]
    NoFringeContrast {
        /// Fitted amplitude B.
        amplitude: f64,
        /// Its standard uncertainty.
        sigma: f64,
    },
    /// The numerical fit failed.
    #[error("fit failed: {0}")]
    FitFailed(String),
}

/// Which method produced a gap estimate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GapMethod {
    /// Peak of the FFT of the spectrum resampled uniformly in wavenumber (the seed).
    FftPeak,
    /// Nonlinear least-squares fit of the two-beam model.
    ModelFit,
    /// Free spectral range from the spacing of reflection peaks (paper eq. 35/36).
    PeakFsr,
}

impl GapMethod {
    /// Human-readable method name.
    pub fn name(&self) -> &'static str {
        match self {
            GapMethod::FftPeak => "FFT peak (wavenumber-resampled)",
            GapMethod::ModelFit => "two-beam model fit (Levenberg-Marquardt)",
            GapMethod::PeakFsr => "reflection-peak FSR (paper eq. 35/36)",
        }
    }
}

/// An absolute gap from one sweep.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GapEstimate {
    /// Method used.
    pub method: GapMethod,
    /// Gap |L|, µm.
    pub gap_um: f64,
    /// Standard uncertainty of the gap, µm (statistical; for `FftPeak` a resolution).
    pub sigma_um: f64,
    /// Number of fringes across the sweep, 2·n·L·Δk/(2π).
    pub fringes_across_sweep: f64,
    /// RMS of the residuals of the method's fit, irradiance units.
    pub fit_rms: f64,
}

/// Settings of the model fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SweepConfig {
    /// Refractive index of air.
    pub n_air: f64,
    /// Mode-field radius w0 of the fiber for the Gouy phase, nm (None: no Gouy term).
    /// With a fixed z_R the Gouy term is a constant phase and has no effect; with
    /// z_R = π·w0²/λ it varies across the sweep and biases L by up to ~50 nm at 100 µm if
    /// ignored.
    pub gouy_waist_nm: Option<f64>,
}

impl Default for SweepConfig {
    fn default() -> Self {
        Self { n_air: 1.000_268, gouy_waist_nm: None }
    }
}

/// Full result of the model fit.
#[derive(Debug, Clone, PartialEq)]
pub struct SweepFit {
    /// The gap estimate of the fit.
    pub estimate: GapEstimate,
    /// The FFT seed it started from.
    pub seed: GapEstimate,
    /// A: mean irradiance.
    pub offset: f64,
    /// a1: relative change of the offset from the centre to the short-wavelength end.
    pub offset_slope: f64,
    /// a2: relative curvature of the offset across the sweep.
    pub offset_curvature: f64,
    /// B: fringe amplitude (≥ 0).
    pub amplitude: f64,
    /// ψ0: fringe phase at the centre wavenumber k0, rad in [0, 2π).
    pub phase_rad: f64,
    /// Centre wavenumber k0 = 2π/λ0, rad/nm.
    pub center_wavenumber: f64,
    /// Standard uncertainty of B.
    pub sigma_amplitude: f64,
    /// Residual evaluations used by the optimiser.
    pub evaluations: usize,
}

/// A validated sweep sorted by increasing wavenumber.
struct Spectrum {
    /// Wavenumber 2π/λ, rad/nm, increasing.
    k: Vec<f64>,
    /// Irradiance at each wavenumber.
    y: Vec<f64>,
}

impl Spectrum {
    /// Every so many samples, about `samples` of them spread over the whole sweep (all of them
    /// when there are fewer).
    fn strided(&self, samples: usize) -> Spectrum {
        let stride = (self.k.len() / samples.max(1)).max(1);
        Spectrum {
            k: self.k.iter().step_by(stride).copied().collect(),
            y: self.y.iter().step_by(stride).copied().collect(),
        }
    }

    /// The means of wavenumber and irradiance over blocks of `block` consecutive samples (the
    /// last block may be shorter).
    fn binned(&self, block: usize) -> Spectrum {
        let mean = |c: &[f64]| c.iter().sum::<f64>() / c.len() as f64;
        Spectrum { k: self.k.chunks(block).map(mean).collect(), y: self.y.chunks(block).map(mean).collect() }
    }
}

fn check_n_air(n_air: f64) -> Result<(), SweepError> {
    if n_air.is_finite() && (1.0..2.0).contains(&n_air) {
        Ok(())
    } else {
        Err(SweepError::InvalidParameter { name: "n_air", value: n_air, reason: "must be finite, in [1, 2)" })
    }
}

fn validate(wavelength_nm: &[f64], irradiance: &[f64]) -> Result<Spectrum, SweepError> {
    let n = wavelength_nm.len();
    if n == 0 && irradiance.is_empty() {
        return Err(SweepError::EmptySweep);
    }
    if n != irradiance.len() {
        return Err(SweepError::LengthMismatch { wavelengths: n, irradiances: irradiance.len() });
    }
    if n < MIN_SAMPLES {
        return Err(SweepError::TooFewSamples { n, min: MIN_SAMPLES });
    }
    for (what, xs) in [("wavelength", wavelength_nm), ("irradiance", irradiance)] {
        if let Some(index) = xs.iter().position(|v| !v.is_finite()) {
            return Err(SweepError::NonFinite { what, index, value: xs[index] });
        }
    }
    if let Some(index) = wavelength_nm.iter().position(|&l| l <= 0.0) {
        return Err(SweepError::InvalidParameter {
            name: "wavelength_nm",
            value: wavelength_nm[index],
            reason: "wavelengths must be positive",
        });
    }
    let increasing = wavelength_nm[1] > wavelength_nm[0];
    for i in 1..n {
        let ok =
            if increasing { wavelength_nm[i] > wavelength_nm[i - 1] } else { wavelength_nm[i] < wavelength_nm[i - 1] };
        if !ok {
            return Err(SweepError::NonMonotonicWavelength {
                index: i,
                previous: wavelength_nm[i - 1],
                value: wavelength_nm[i],
            });
        }
    }
    // increasing k = decreasing λ
    let mut k: Vec<f64> = wavelength_nm.iter().map(|l| TAU / l).collect();
    let mut y = irradiance.to_vec();
    if increasing {
        k.reverse();
        y.reverse();
    }
    Ok(Spectrum { k, y })
}

/// Gouy phase G(k, L) = arctan(L/z_R(k)), with z_R = w0²·k/2.
#[inline]
fn gouy_phase(k: f64, l: f64, w0: f64) -> f64 {
    (l / (0.5 * w0 * w0 * k)).atan()
}

/// ∂G/∂L = z_R/(z_R² + L²).
#[inline]
fn gouy_slope(k: f64, l: f64, w0: f64) -> f64 {
    let zr = 0.5 * w0 * w0 * k;
    zr / (zr * zr + l * l)
}

/// Highest degree of the Gouy phase's series; a sweep too wide for it (beyond about 14 % of its
/// centre wavenumber on each side) takes the arctangent at every sample.
const GOUY_SERIES_MAX_DEGREE: usize = 12;
/// What the series may be off by, rad.
const GOUY_SERIES_TOLERANCE_RAD: f64 = 1e-12;

/// The fringe phase of one gap L relative to the sweep's centre k0, without ψ0:
/// `θ(k) = 2·n·L·(k - k0) - [G(k, L) - G(k0, L)]`, and ∂θ/∂L.
#[derive(Clone, Copy)]
struct FringePhase {
    k0: f64,
    l: f64,
    n_air: f64,
    w0: Option<f64>,
    /// ∂G/∂L at k0.
    dg0: f64,
    /// G(k) - G(k0) = Σ cₙ·δⁿ (n = 1..=degree, δ = k - k0) when the series is used.
    series: [f64; GOUY_SERIES_MAX_DEGREE],
    degree: usize,
}

impl FringePhase {
    /// For the gap `l` (nm) on a sweep of centre `k0` and half-width `half` (rad/nm).
    fn new(k0: f64, half: f64, l: f64, n_air: f64, w0: Option<f64>) -> Self {
        let dg0 = w0.map_or(0.0, |w| gouy_slope(k0, l, w));
        let mut phase = Self { k0, l, n_air, w0, dg0, series: [0.0; GOUY_SERIES_MAX_DEGREE], degree: 0 };
        if let Some(w) = w0 {
            phase.expand_gouy(half, 2.0 * l / (w * w));
        }
        phase
    }

    /// The series of G(k) - G(k0) when it reaches the tolerance within its highest degree:
    /// G(k) = arctan(a/k) = arg(k + i·a), a = 2L/w0², so G(k) - G(k0) = Im ln(1 + z) with
    /// z = δ/(k0 + i·a), whose terms are (-1)ⁿ⁺¹·zⁿ/n and whose remainder after degree N is
    /// below |z|ᴺ⁺¹/((N + 1)·(1 - |z|)).
    fn expand_gouy(&mut self, half: f64, a: f64) {
        let w = nalgebra::Complex::new(self.k0, a).inv();
        let r = half.abs() * w.norm();
        let Some(degree) = (1..=GOUY_SERIES_MAX_DEGREE)
            .find(|&n| r < 1.0 && r.powi(n as i32 + 1) / ((n + 1) as f64 * (1.0 - r)) <= GOUY_SERIES_TOLERANCE_RAD)
        else {
            return;
        };
        let mut wn = w;
        for n in 1..=degree {
            let sign = if n % 2 == 1 { 1.0 } else { -1.0 };
            self.series[n - 1] = sign * wn.im / n as f64;
            wn *= w;
        }
        self.degree = degree;
    }

    /// θ(k).
    #[inline]
    fn phase(&self, k: f64) -> f64 {
        2.0 * self.n_air * self.l * (k - self.k0) - self.gouy_change(k)
    }

    /// θ(k) and ∂θ/∂L.
    #[inline]
    fn phase_and_slope(&self, k: f64) -> (f64, f64) {
        let dg = self.w0.map_or(0.0, |w| gouy_slope(k, self.l, w));
        (self.phase(k), 2.0 * self.n_air * (k - self.k0) - (dg - self.dg0))
    }

    /// G(k, L) - G(k0, L).
    #[inline]
    fn gouy_change(&self, k: f64) -> f64 {
        let d = k - self.k0;
        match self.w0 {
            Some(_) if self.degree > 0 => d * self.series[..self.degree].iter().rev().fold(0.0, |acc, &c| c + d * acc),
            Some(w) => gouy_phase(k, self.l, w) - gouy_phase(self.k0, self.l, w),
            None => 0.0,
        }
    }
}

/// FFT seed: spectrum resampled uniformly in k by linear interpolation, averaged over blocks
/// down to about [`SEED_SAMPLES`], detrended, Hann-windowed, zero-padded 4×; the peak (above
/// 0.5 fringe) with parabolic interpolation. Returns (L in nm, fringes across the sweep).
///
/// A block mean passes fringes far below the averaged series' Nyquist frequency and nulls
/// the ones that would alias next to them; a peak above a sixteenth of that frequency, or a
/// sweep whose fringes the averaging took most of the power from, is looked for again in the
/// full series.
fn fft_seed(sp: &Spectrum, n_air: f64) -> Result<(f64, f64), SweepError> {
    let n = sp.k.len();
    let uniform = uniform_in_k(sp);
    let block = n / SEED_SAMPLES;
    if block >= 2 {
        let means: Vec<f64> = uniform.chunks_exact(block).map(|c| c.iter().sum::<f64>() / block as f64).collect();
        let (averaged, full) = (detrended_variance(&means), detrended_variance(&uniform));
        let (l, fringes) = fft_peak(sp, &means, block, n_air)?;
        if fringes < means.len() as f64 / 32.0 && averaged >= 0.5 * full {
            return Ok((l, fringes));
        }
    }
    fft_peak(sp, &uniform, 1, n_air)
}

/// The sweep's irradiance at `n` wavenumbers evenly spaced over its span, linearly interpolated.
fn uniform_in_k(sp: &Spectrum) -> Vec<f64> {
    let n = sp.k.len();
    let (kmin, kmax) = (sp.k[0], sp.k[n - 1]);
    let dk = (kmax - kmin) / (n - 1) as f64;
    let mut u = Vec::with_capacity(n);
    let mut j = 0usize;
    for i in 0..n {
        let kk = kmin + dk * i as f64;
        while j + 2 < n && sp.k[j + 1] < kk {
            j += 1;
        }
        let t = ((kk - sp.k[j]) / (sp.k[j + 1] - sp.k[j])).clamp(0.0, 1.0);
        u.push(sp.y[j] + t * (sp.y[j + 1] - sp.y[j]));
    }
    u
}

/// The mean and slope of the straight line through `u` against its index.
fn trend(u: &[f64]) -> (f64, f64) {
    let nf = u.len() as f64;
    let xm = (nf - 1.0) / 2.0;
    let ym = u.iter().sum::<f64>() / nf;
    let sxx = nf * (nf * nf - 1.0) / 12.0;
    let sxy: f64 = u.iter().enumerate().map(|(i, v)| (i as f64 - xm) * (v - ym)).sum();
    (ym, sxy / sxx)
}

/// The variance of `u` about its straight line.
fn detrended_variance(u: &[f64]) -> f64 {
    let (ym, slope) = trend(u);
    let xm = (u.len() as f64 - 1.0) / 2.0;
    u.iter().enumerate().map(|(i, v)| (v - ym - slope * (i as f64 - xm)).powi(2)).sum::<f64>() / u.len() as f64
}

/// The FFT peak of `u`, the sweep's irradiance evenly spaced in k, each value the mean of
/// `block` samples of the full spacing: (L in nm, fringes across the sweep).
fn fft_peak(sp: &Spectrum, u: &[f64], block: usize, n_air: f64) -> Result<(f64, f64), SweepError> {
    let (n, nu) = (sp.k.len(), u.len());
    let nf = nu as f64;
    let xm = (nf - 1.0) / 2.0;
    let (ym, slope) = trend(u);
    // Padded 4×: the peak to a quarter fringe before the parabola; the fit's grid searches
    // ±2.5 fringes around it anyway.
    let m = (4 * nu).next_power_of_two();
    thread_local! {
        // Plans cached per length: a session's sweeps share one.
        static PLANNER: std::cell::RefCell<RealFftPlanner<f64>> = std::cell::RefCell::new(RealFftPlanner::new());
    }
    let r2c = PLANNER.with(|p| p.borrow_mut().plan_fft_forward(m));
    let mut input = r2c.make_input_vec();
    for (i, v) in u.iter().enumerate() {
        let w = 0.5 - 0.5 * (TAU * i as f64 / (nf - 1.0)).cos();
        input[i] = (v - ym - slope * (i as f64 - xm)) * w;
    }
    let mut spec = r2c.make_output_vec();
    r2c.process(&mut input, &mut spec).map_err(|e| SweepError::FitFailed(format!("FFT: {e}")))?;
    // fringes across the sweep for bin b: b·(n-1)/(m·block)
    let fringes_per_bin = (n - 1) as f64 / (m * block) as f64;
    let lo = (0.5 / fringes_per_bin).ceil() as usize;
    let hi = spec.len() - 1;
    if lo + 2 >= hi {
        return Err(SweepError::TooFewSamples { n, min: MIN_SAMPLES });
    }
    let (mut best, mut bi) = (f64::NEG_INFINITY, lo);
    for (b, v) in spec.iter().enumerate().take(hi).skip(lo) {
        if v.norm_sqr() > best {
            best = v.norm_sqr();
            bi = b;
        }
    }
    let (a, b, c) = (spec[bi - 1].norm(), spec[bi].norm(), spec[bi + 1].norm());
    let den = a - 2.0 * b + c;
    let delta = if den < 0.0 { (0.5 * (a - c) / den).clamp(-0.5, 0.5) } else { 0.0 };
    let fringes = (bi as f64 + delta) * fringes_per_bin;
    let l = PI * fringes / (n_air * (sp.k[n - 1] - sp.k[0]));
    Ok((l, fringes))
}

/// Samples the FFT seed averages a sweep down to.
const SEED_SAMPLES: usize = 16384;

/// Samples kept for the variable-projection grid that seeds the sweep fit.
const GRID_SAMPLES: usize = 8192;

/// Linear least squares of the model at fixed L: basis 1, x, x², cos θ, sin θ.
/// Returns (coefficients, RSS).
fn linear_at(sp: &Spectrum, k0: f64, half: f64, l: f64, n_air: f64, w0: Option<f64>) -> (SVector<f64, 5>, f64) {
    let theta = FringePhase::new(k0, half, l, n_air, w0);
    // AᵀA's upper triangle, row by row, and Aᵀy, summed in arrays the compiler unrolls.
    let (mut ata, mut aty, mut yy) = ([0.0; 15], [0.0; 5], 0.0);
    for (&k, &y) in sp.k.iter().zip(sp.y.iter()) {
        let (s, c) = sincos(theta.phase(k));
        let x = (k - k0) / half;
        let v = [1.0, x, x * x, c, s];
        let mut at = 0;
        for r in 0..5 {
            aty[r] += v[r] * y;
            for vc in &v[r..] {
                ata[at] += v[r] * vc;
                at += 1;
            }
        }
        yy += y * y;
    }
    let upper = |r: usize, c: usize| r * 5 - r * (r + 1) / 2 + c;
    let ata = SMatrix::<f64, 5, 5>::from_fn(|r, c| ata[upper(r.min(c), r.max(c))]);
    let aty = SVector::<f64, 5>::from(aty);
    match ata.cholesky() {
        Some(ch) => {
            let p = ch.solve(&aty);
            (p, (yy - p.dot(&aty)).max(0.0))
        }
        None => (SVector::zeros(), f64::INFINITY),
    }
}

/// FFT-peak gap (the seed of the fit, biased by leakage when there are few fringes). Its
/// σ is a resolution: a uniform error over ± half a bin of the unpadded FFT.
pub fn fft_gap(wavelength_nm: &[f64], irradiance: &[f64], n_air: f64) -> Result<GapEstimate, SweepError> {
    check_n_air(n_air)?;
    let sp = validate(wavelength_nm, irradiance)?;
    fft_estimate(&sp, n_air)
}

fn fft_estimate(sp: &Spectrum, n_air: f64) -> Result<GapEstimate, SweepError> {
    let n = sp.k.len();
    let (l, fringes) = fft_seed(sp, n_air)?;
    let span = sp.k[n - 1] - sp.k[0];
    let k0 = 0.5 * (sp.k[0] + sp.k[n - 1]);
    // The rms of the linear fit at the seed's gap, over samples spread across the sweep.
    let coarse = sp.strided(GRID_SAMPLES);
    let (_, rss) = linear_at(&coarse, k0, 0.5 * span, l, n_air, None);
    let l_per_fringe = PI / (n_air * span);
    Ok(GapEstimate {
        method: GapMethod::FftPeak,
        gap_um: l * 1e-3,
        sigma_um: 0.5 / 3f64.sqrt() * l_per_fringe * 1e-3,
        fringes_across_sweep: fringes,
        fit_rms: (rss / coarse.k.len() as f64).sqrt(),
    })
}

/// Cramér-Rao bound on the gap from the fringe frequency across a sweep:
/// σ_L ≥ √3/(n·K·√(η·N)), K = 2π·Δλ/λ², η = B²/(2σ²). nm.
pub fn crlb_frequency_nm(span_nm: f64, center_nm: f64, eta: f64, samples: usize, n_air: f64) -> f64 {
    let k = TAU * span_nm / (center_nm * center_nm);
    3f64.sqrt() / (n_air * k * (eta * samples as f64).sqrt())
}

/// Cramér-Rao bound on the gap from the absolute fringe phase (once the order is known):
/// σ_L ≥ λ/(4π·n·√(η·N)). nm.
pub fn crlb_phase_nm(center_nm: f64, eta: f64, samples: usize, n_air: f64) -> f64 {
    center_nm / (4.0 * PI * n_air * (eta * samples as f64).sqrt())
}

/// Two-beam sweep test signal:
/// `I(λ) = A·(1 + s·(λ - λc)) + B·cos(4π·n·L/λ + φ0 - arctan(L/z_R(λ))) + N(0, σ²)`,
/// with z_R = π·w0²/λ when a waist is given.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TwoBeamSweep {
    /// Gap L, nm.
    pub gap_nm: f64,
    /// Refractive index of air.
    pub n_air: f64,
    /// Offset A at the centre wavelength.
    pub offset: f64,
    /// Relative slope s of the offset, per nm of wavelength.
    pub offset_slope_per_nm: f64,
    /// Centre wavelength λc of the slope, nm.
    pub center_nm: f64,
    /// Fringe amplitude B.
    pub amplitude: f64,
    /// Phase φ0, rad.
    pub phase_rad: f64,
    /// Mode-field radius w0 for the Gouy phase, nm.
    pub gouy_waist_nm: Option<f64>,
    /// White-noise σ, irradiance units.
    pub noise_sigma: f64,
}

impl TwoBeamSweep {
    /// Render the irradiance at the given wavelengths.
    pub fn render<R: Rng + ?Sized>(&self, wavelength_nm: &[f64], rng: &mut R) -> Result<Vec<f64>, SweepError> {
        if !(self.noise_sigma.is_finite() && self.noise_sigma >= 0.0) {
            return Err(SweepError::InvalidParameter {
                name: "noise_sigma",
                value: self.noise_sigma,
                reason: "must be finite and non-negative",
            });
        }
        let noise = Normal::new(0.0, self.noise_sigma).map_err(|_| SweepError::InvalidParameter {
            name: "noise_sigma",
            value: self.noise_sigma,
            reason: "invalid normal distribution",
        })?;
        Ok(wavelength_nm
            .iter()
            .map(|&l| {
                let gouy = self.gouy_waist_nm.map_or(0.0, |w| {
                    let zr = PI * w * w / l;
                    (self.gap_nm / zr).atan()
                });
                let th = 4.0 * PI * self.n_air * self.gap_nm / l + self.phase_rad - gouy;
                self.offset * (1.0 + self.offset_slope_per_nm * (l - self.center_nm))
                    + self.amplitude * th.cos()
                    + noise.sample(rng)
            })
            .collect())
    }
}
