//! Absolute gap from a wavelength sweep: irradiance against wavelength, joints fixed → cavity gap (µm) with a standard uncertainty.
//! Owns the wavenumber resampling and FFT seed, the nonlinear model fit (levenberg-marquardt), the paper's peak-FSR method, the Cramér-Rao references and a two-beam sweep test signal.
//!
//! Model fitted (two-beam, k = 2π/λ, x = (k - k0)/(half the k span)):
//! `I(k) = A·(1 + a1·x + a2·x²) + B·cos(2·n·L·(k - k0) + ψ0 - [G(k, L) - G(k0, L)])`, with the
//! optional Gouy phase `G = arctan(L/z_R(k))`, `z_R = π·w0²/λ = w0²·k/2`. The absolute
//! phase 2·n·L·k0 is absorbed in ψ0 (the fringe order is not resolved), so the gap comes
//! from the fringe frequency across the sweep.

use crate::fringes::{detect_extrema, sincos, ExtremumKind, HysteresisConfig};
use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{storage::Owned, Dyn, OMatrix, OVector, SMatrix, SVector, Vector3, U6};
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
    k: Vec<f64>,
    y: Vec<f64>,
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

/// Gouy phase G(k, L) = arctan(L/z_R(k)) and ∂G/∂L, with z_R = w0²·k/2.
#[inline]
fn gouy(k: f64, l: f64, w0: Option<f64>) -> (f64, f64) {
    match w0 {
        None => (0.0, 0.0),
        Some(w) => {
            let zr = 0.5 * w * w * k;
            let x = l / zr;
            (x.atan(), 1.0 / (zr * (1.0 + x * x)))
        }
    }
}

/// Fringe phase relative to the centre (without ψ0) and its derivative in L.
#[inline]
fn fringe_phase(k: f64, k0: f64, l: f64, n_air: f64, w0: Option<f64>, g0: (f64, f64)) -> (f64, f64) {
    let (g, dg) = gouy(k, l, w0);
    (2.0 * n_air * l * (k - k0) - (g - g0.0), 2.0 * n_air * (k - k0) - (dg - g0.1))
}

/// FFT seed: spectrum resampled uniformly in k by linear interpolation, detrended,
/// Hann-windowed, zero-padded 16×; the peak (above 0.5 fringe) with parabolic
/// interpolation. Returns (L in nm, fringes across the sweep).
fn fft_seed(sp: &Spectrum, n_air: f64) -> Result<(f64, f64), SweepError> {
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
    // detrend
    let nf = n as f64;
    let xm = (nf - 1.0) / 2.0;
    let ym = u.iter().sum::<f64>() / nf;
    let sxx: f64 = (0..n).map(|i| (i as f64 - xm).powi(2)).sum();
    let sxy: f64 = u.iter().enumerate().map(|(i, v)| (i as f64 - xm) * (v - ym)).sum();
    let slope = sxy / sxx;
    let m = (16 * n).next_power_of_two();
    let mut planner = RealFftPlanner::<f64>::new();
    let r2c = planner.plan_fft_forward(m);
    let mut input = r2c.make_input_vec();
    for (i, v) in u.iter().enumerate() {
        let w = 0.5 - 0.5 * (TAU * i as f64 / (nf - 1.0)).cos();
        input[i] = (v - ym - slope * (i as f64 - xm)) * w;
    }
    let mut spec = r2c.make_output_vec();
    r2c.process(&mut input, &mut spec).map_err(|e| SweepError::FitFailed(format!("FFT: {e}")))?;
    let mag: Vec<f64> = spec.iter().map(|c| c.norm()).collect();
    // fringes across the sweep for bin b: b·(n-1)/m
    let bin_of_fringes = |f: f64| f * m as f64 / (n - 1) as f64;
    let lo = bin_of_fringes(0.5).ceil() as usize;
    let hi = mag.len() - 1;
    if lo + 2 >= hi {
        return Err(SweepError::TooFewSamples { n, min: MIN_SAMPLES });
    }
    let (mut best, mut bi) = (f64::NEG_INFINITY, lo);
    for (b, &v) in mag.iter().enumerate().take(hi).skip(lo) {
        if v > best {
            best = v;
            bi = b;
        }
    }
    let (a, b, c) = (mag[bi - 1], mag[bi], mag[bi + 1]);
    let den = a - 2.0 * b + c;
    let delta = if den < 0.0 { (0.5 * (a - c) / den).clamp(-0.5, 0.5) } else { 0.0 };
    let fringes = (bi as f64 + delta) * (n - 1) as f64 / m as f64;
    let l = PI * fringes / (n_air * (kmax - kmin));
    Ok((l, fringes))
}

/// Samples kept for the variable-projection grid that seeds the sweep fit.
const GRID_SAMPLES: usize = 8192;

/// Linear least squares of the model at fixed L: basis 1, x, x², cos θ, sin θ.
/// Returns (coefficients, RSS).
fn linear_at(sp: &Spectrum, k0: f64, half: f64, l: f64, n_air: f64, w0: Option<f64>) -> (SVector<f64, 5>, f64) {
    let g0 = gouy(k0, l, w0);
    let mut ata = SMatrix::<f64, 5, 5>::zeros();
    let mut aty = SVector::<f64, 5>::zeros();
    let mut yy = 0.0;
    for (&k, &y) in sp.k.iter().zip(sp.y.iter()) {
        let (th, _) = fringe_phase(k, k0, l, n_air, w0, g0);
        let (s, c) = sincos(th);
        let x = (k - k0) / half;
        let v = SVector::<f64, 5>::from([1.0, x, x * x, c, s]);
        ata += v * v.transpose();
        aty += v * y;
        yy += y * y;
    }
    match ata.cholesky() {
        Some(ch) => {
            let p = ch.solve(&aty);
            (p, (yy - p.dot(&aty)).max(0.0))
        }
        None => (SVector::zeros(), f64::INFINITY),
    }
}

/// Residuals and (optionally) the Jacobian of the sweep model.
type Evaluation = (OVector<f64, Dyn>, Option<OMatrix<f64, Dyn, U6>>);

/// The LM problem: parameters (A, a1, a2, B, L, ψ0).
struct SweepProblem<'a> {
    sp: &'a Spectrum,
    k0: f64,
    half: f64,
    n_air: f64,
    w0: Option<f64>,
    p: SVector<f64, 6>,
}

impl SweepProblem<'_> {
    fn eval(&self, with_jac: bool) -> Evaluation {
        let n = self.sp.k.len();
        let [a, a1, a2, b, l, psi] = [self.p[0], self.p[1], self.p[2], self.p[3], self.p[4], self.p[5]];
        let g0 = gouy(self.k0, l, self.w0);
        let mut r = OVector::<f64, Dyn>::zeros(n);
        let mut j = if with_jac { Some(OMatrix::<f64, Dyn, U6>::zeros(n)) } else { None };
        for (i, (&k, &y)) in self.sp.k.iter().zip(self.sp.y.iter()).enumerate() {
            let x = (k - self.k0) / self.half;
            let (th, dth) = fringe_phase(k, self.k0, l, self.n_air, self.w0, g0);
            let (s, c) = sincos(th + psi);
            let shape = 1.0 + a1 * x + a2 * x * x;
            r[i] = a * shape + b * c - y;
            if let Some(j) = j.as_mut() {
                j[(i, 0)] = shape;
                j[(i, 1)] = a * x;
                j[(i, 2)] = a * x * x;
                j[(i, 3)] = c;
                j[(i, 4)] = -b * s * dth;
                j[(i, 5)] = -b * s;
            }
        }
        (r, j)
    }
}

impl LeastSquaresProblem<f64, Dyn, U6> for SweepProblem<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, U6>;
    type ParameterStorage = Owned<f64, U6>;

    fn set_params(&mut self, x: &SVector<f64, 6>) {
        self.p.copy_from(x);
    }

    fn params(&self) -> SVector<f64, 6> {
        self.p
    }

    fn residuals(&self) -> Option<OVector<f64, Dyn>> {
        Some(self.eval(false).0)
    }

    fn jacobian(&self) -> Option<OMatrix<f64, Dyn, U6>> {
        self.eval(true).1
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
    let (_, rss) = linear_at(sp, k0, 0.5 * span, l, n_air, None);
    let l_per_fringe = PI / (n_air * span);
    Ok(GapEstimate {
        method: GapMethod::FftPeak,
        gap_um: l * 1e-3,
        sigma_um: 0.5 / 3f64.sqrt() * l_per_fringe * 1e-3,
        fringes_across_sweep: fringes,
        fit_rms: (rss / n as f64).sqrt(),
    })
}

/// Absolute gap by nonlinear least squares (levenberg-marquardt) of the two-beam model,
/// seeded by the FFT peak and a variable-projection grid over ±2.5 fringes (which removes
/// the leakage bias of the seed when there are few fringes). σ from the fit covariance
/// σ²·(JᵀJ)⁻¹ (pseudo-inverse) with σ² = RSS/(N - 6).
pub fn fit_gap(wavelength_nm: &[f64], irradiance: &[f64], cfg: &SweepConfig) -> Result<SweepFit, SweepError> {
    check_n_air(cfg.n_air)?;
    if let Some(w) = cfg.gouy_waist_nm {
        if !(w.is_finite() && w > 0.0) {
            return Err(SweepError::InvalidParameter {
                name: "gouy_waist_nm",
                value: w,
                reason: "must be finite and positive",
            });
        }
    }
    let sp = validate(wavelength_nm, irradiance)?;
    let n = sp.k.len();
    let n_air = cfg.n_air;
    let seed = fft_estimate(&sp, n_air)?;
    let span = sp.k[n - 1] - sp.k[0];
    let half = 0.5 * span;
    let k0 = 0.5 * (sp.k[0] + sp.k[n - 1]);
    let l_per_fringe = PI / (n_air * span);

    // Variable-projection grid in fringes across the sweep.
    let f_seed = seed.fringes_across_sweep;
    let step = 0.02;
    let f_lo = (f_seed - 2.5).max(0.3);
    let f_hi = f_seed + 2.5;
    let count = ((f_hi - f_lo) / step).ceil() as usize + 1;
    // The grid only places the start of the fit: every sample is not needed to find the RSS
    // minimum (a few thousand spread over tens of fringes), the fit below uses them all.
    let stride = (n / GRID_SAMPLES).max(1);
    let coarse = Spectrum {
        k: sp.k.iter().step_by(stride).copied().collect(),
        y: sp.y.iter().step_by(stride).copied().collect(),
    };
    let rss: Vec<f64> = (0..count)
        .map(|i| linear_at(&coarse, k0, half, (f_lo + step * i as f64) * l_per_fringe, n_air, cfg.gouy_waist_nm).1)
        .collect();
    let (bi, _) = rss.iter().enumerate().fold(
        (0usize, f64::INFINITY),
        |(bi, bv), (i, &v)| {
            if v < bv {
                (i, v)
            } else {
                (bi, bv)
            }
        },
    );
    let mut f_best = f_lo + step * bi as f64;
    if bi > 0 && bi + 1 < count {
        let (a, b, c) = (rss[bi - 1], rss[bi], rss[bi + 1]);
        let den = a - 2.0 * b + c;
        if den > 0.0 {
            f_best += step * (0.5 * (a - c) / den).clamp(-0.5, 0.5);
        }
    }
    let l_start = f_best * l_per_fringe;
    let (lin, _) = linear_at(&sp, k0, half, l_start, n_air, cfg.gouy_waist_nm);
    let a_start = lin[0];
    let (a1_start, a2_start) = if a_start != 0.0 { (lin[1] / a_start, lin[2] / a_start) } else { (0.0, 0.0) };
    let b_start = (lin[3] * lin[3] + lin[4] * lin[4]).sqrt();
    let psi_start = (-lin[4]).atan2(lin[3]);

    let problem = SweepProblem {
        sp: &sp,
        k0,
        half,
        n_air,
        w0: cfg.gouy_waist_nm,
        p: SVector::<f64, 6>::from([a_start, a1_start, a2_start, b_start, l_start, psi_start]),
    };
    let (problem, report) = LevenbergMarquardt::new().minimize(problem);
    if !report.termination.was_successful() {
        // the most useful diagnosis first: a sweep too short for this gap
        let fringes = 2.0 * n_air * problem.p[4].abs().max(l_start) * span / TAU;
        if fringes < MIN_FRINGES {
            return Err(SweepError::TooFewFringes { fringes, min: MIN_FRINGES });
        }
        return Err(SweepError::FitFailed(crate::solver::termination_words(&report.termination)));
    }
    let mut p = problem.p;
    if p.iter().any(|v| !v.is_finite()) {
        return Err(SweepError::FitFailed("non-finite parameters".to_string()));
    }
    let (r, j) = problem.eval(true);
    let j = j.ok_or_else(|| SweepError::FitFailed("no Jacobian".to_string()))?;
    let rss = r.norm_squared();
    let dof = (n as f64 - 6.0).max(1.0);
    let s2 = rss / dof;
    let jtj: SMatrix<f64, 6, 6> = j.transpose() * &j;
    let cov = pseudo_inverse_sym(&jtj) * s2;
    if p[3] < 0.0 {
        p[3] = -p[3];
        p[5] += PI;
    }
    let l = p[4];
    let fringes = 2.0 * n_air * l * span / TAU;
    let sigma_b = cov[(3, 3)].max(0.0).sqrt();
    let significant = p[3] > 5.0 * sigma_b; // false for NaN too
    if !significant {
        return Err(SweepError::NoFringeContrast { amplitude: p[3], sigma: sigma_b });
    }
    if fringes < MIN_FRINGES {
        return Err(SweepError::TooFewFringes { fringes, min: MIN_FRINGES });
    }
    Ok(SweepFit {
        estimate: GapEstimate {
            method: GapMethod::ModelFit,
            gap_um: l * 1e-3,
            sigma_um: cov[(4, 4)].max(0.0).sqrt() * 1e-3,
            fringes_across_sweep: fringes,
            fit_rms: (rss / n as f64).sqrt(),
        },
        seed,
        offset: p[0],
        offset_slope: p[1],
        offset_curvature: p[2],
        amplitude: p[3],
        phase_rad: p[5].rem_euclid(TAU),
        center_wavenumber: k0,
        sigma_amplitude: sigma_b,
        evaluations: report.number_of_evaluations,
    })
}

/// Pseudo-inverse of a symmetric positive semi-definite matrix by eigen-decomposition
/// (stays defined when the Jacobian is rank-deficient).
fn pseudo_inverse_sym(m: &SMatrix<f64, 6, 6>) -> SMatrix<f64, 6, 6> {
    let eig = m.symmetric_eigen();
    let emax = eig.eigenvalues.iter().fold(0f64, |a, &e| a.max(e.abs()));
    let mut inv = SMatrix::<f64, 6, 6>::zeros();
    for i in 0..6 {
        let e = eig.eigenvalues[i];
        if e > emax * 1e-14 {
            let v = eig.eigenvectors.column(i);
            inv += v * v.transpose() / e;
        }
    }
    inv
}

/// The paper's method: free spectral range from the spacing of the reflection peaks,
/// Δλ_FSR = λ²/(2·n·L) (SPEC eq. 35/36). Each peak is located by a quadratic fit in λ to
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

/// Cramér-Rao bound on the gap from the fringe frequency across a sweep (SPEC §5):
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

#[cfg(test)]
mod tests {
    use super::*;
    use rand::rngs::StdRng;
    use rand::SeedableRng;

    const N_AIR: f64 = 1.000_268;
    const CENTER: f64 = 1560.0;
    const SPAN: f64 = 40.0;
    const W0: f64 = 5200.0;
    const B: f64 = 0.2;

    fn wavelengths(n: usize) -> Vec<f64> {
        (0..n).map(|i| CENTER - 0.5 * SPAN + SPAN * i as f64 / (n - 1) as f64).collect()
    }

    fn sweep(gap_nm: f64, noise_rel: f64, phase: f64, seed: u64) -> (Vec<f64>, Vec<f64>) {
        let wl = wavelengths(4000);
        let sig = TwoBeamSweep {
            gap_nm,
            n_air: N_AIR,
            offset: 1.0,
            offset_slope_per_nm: 0.05 / SPAN,
            center_nm: CENTER,
            amplitude: B,
            phase_rad: phase,
            gouy_waist_nm: Some(W0),
            noise_sigma: noise_rel * B,
        };
        let mut rng = StdRng::seed_from_u64(seed);
        let y = sig.render(&wl, &mut rng).unwrap();
        (wl, y)
    }

    fn cfg() -> SweepConfig {
        SweepConfig { n_air: N_AIR, gouy_waist_nm: Some(W0) }
    }

    #[test]
    fn crlb_matches_the_spec_example() {
        // SPEC §5: 40 nm sweep, N = 4000, η = 1000 → 8.4 nm (frequency), 62 pm (phase)
        let f = crlb_frequency_nm(40.0, 1560.0, 1000.0, 4000, 1.0);
        let p = crlb_phase_nm(1560.0, 1000.0, 4000, 1.0);
        assert!((f - 8.38).abs() < 0.05, "{f}");
        assert!((p - 0.062).abs() < 0.001, "{p}");
    }

    #[test]
    fn fit_recovers_the_gap_within_20nm_with_honest_sigma() {
        // 900 µm: ~30 fringes; 100 µm: 3.3 fringes; 50 µm: 1.6 fringes across 40 nm
        for gap_um in [900.0, 100.0, 50.0] {
            let mut worst = 0f64;
            let mut worst_z = 0f64;
            for seed in 0..6u64 {
                let (wl, y) = sweep(gap_um * 1e3, 1e-3, 0.4 + 1.1 * seed as f64, seed);
                let fit = fit_gap(&wl, &y, &cfg()).unwrap();
                let err_nm = (fit.estimate.gap_um - gap_um) * 1e3;
                let sigma_nm = fit.estimate.sigma_um * 1e3;
                worst = worst.max(err_nm.abs());
                worst_z = worst_z.max(err_nm.abs() / sigma_nm);
                assert!(err_nm.abs() < 20.0, "{gap_um} µm seed {seed}: err {err_nm} nm");
                assert!(err_nm.abs() < 3.0 * sigma_nm, "{gap_um} µm seed {seed}: err {err_nm} σ {sigma_nm}");
                assert_eq!(fit.estimate.method, GapMethod::ModelFit);
            }
            let crlb = crlb_frequency_nm(SPAN, CENTER, 1.0 / (2.0 * 1e-6), 4000, N_AIR);
            eprintln!("{gap_um} µm: worst |err| {worst:.3} nm, worst |err|/σ {worst_z:.2}, CRLB {crlb:.3} nm");
        }
    }

    #[test]
    fn reported_sigma_is_of_the_order_of_the_crlb_and_of_the_scatter() {
        // η = B²/(2σ²) = 1000 as in the SPEC example: CRLB 8.4 nm
        let noise_rel = (1.0f64 / 2000.0).sqrt();
        let crlb = crlb_frequency_nm(SPAN, CENTER, 1000.0, 4000, N_AIR);
        let mut errs = Vec::new();
        let mut sigmas = Vec::new();
        for seed in 0..24u64 {
            let (wl, y) = sweep(900e3, noise_rel, 0.3 * seed as f64, 1000 + seed);
            let fit = fit_gap(&wl, &y, &cfg()).unwrap();
            errs.push((fit.estimate.gap_um - 900.0) * 1e3);
            sigmas.push(fit.estimate.sigma_um * 1e3);
        }
        let rms = (errs.iter().map(|e| e * e).sum::<f64>() / errs.len() as f64).sqrt();
        let mean_sigma = sigmas.iter().sum::<f64>() / sigmas.len() as f64;
        eprintln!("η=1000: CRLB {crlb:.2} nm, mean σ {mean_sigma:.2} nm, rms error {rms:.2} nm");
        assert!(mean_sigma > 0.9 * crlb && mean_sigma < 2.0 * crlb, "σ {mean_sigma} vs CRLB {crlb}");
        assert!(rms > 0.5 * mean_sigma && rms < 1.6 * mean_sigma, "rms {rms} vs σ {mean_sigma}");
    }

    #[test]
    fn fft_seed_is_biased_with_few_fringes_and_the_fit_removes_the_bias() {
        let (wl, y) = sweep(50e3, 1e-3, 1.0, 7);
        let seed = fft_gap(&wl, &y, N_AIR).unwrap();
        let fit = fit_gap(&wl, &y, &cfg()).unwrap();
        let seed_err = (seed.gap_um - 50.0) * 1e3;
        let fit_err = (fit.estimate.gap_um - 50.0) * 1e3;
        eprintln!(
            "50 µm ({:.2} fringes): FFT err {seed_err:.0} nm, fit err {fit_err:.2} nm",
            fit.estimate.fringes_across_sweep
        );
        assert!(fit.estimate.fringes_across_sweep < 2.0);
        assert!(seed_err.abs() > 500.0, "the seed should be visibly biased: {seed_err}");
        assert!(fit_err.abs() < 20.0);
    }

    #[test]
    fn peak_fsr_method_is_much_worse_than_the_fit_at_100um() {
        let mut worst_ratio = f64::INFINITY;
        for seed in 0..4u64 {
            let (wl, y) = sweep(100e3, 1e-3, 0.5 + seed as f64, 40 + seed);
            let fsr = peak_fsr_gap(&wl, &y, N_AIR).unwrap();
            let fit = fit_gap(&wl, &y, &cfg()).unwrap();
            let fsr_err = (fsr.gap_um - 100.0) * 1e3;
            let fit_err = (fit.estimate.gap_um - 100.0) * 1e3;
            eprintln!(
                "100 µm seed {seed}: FSR err {fsr_err:.1} nm (σ {:.1}), fit err {fit_err:.2} nm (σ {:.2})",
                fsr.sigma_um * 1e3,
                fit.estimate.sigma_um * 1e3
            );
            assert_eq!(fsr.method, GapMethod::PeakFsr);
            // worse in error, or at least reported with a larger σ
            let worse = fsr_err.abs() > 5.0 * fit_err.abs().max(1.0) || fsr.sigma_um > 3.0 * fit.estimate.sigma_um;
            assert!(worse, "seed {seed}");
            worst_ratio = worst_ratio.min(fsr_err.abs() / fit_err.abs().max(1e-3));
        }
        eprintln!("smallest FSR/fit error ratio {worst_ratio:.1}");
    }

    #[test]
    fn ignoring_the_gouy_phase_biases_short_gaps() {
        let (wl, y) = sweep(100e3, 1e-3, 0.9, 3);
        let with = fit_gap(&wl, &y, &cfg()).unwrap();
        let without = fit_gap(&wl, &y, &SweepConfig { gouy_waist_nm: None, ..cfg() }).unwrap();
        let e_with = (with.estimate.gap_um - 100.0) * 1e3;
        let e_without = (without.estimate.gap_um - 100.0) * 1e3;
        eprintln!("100 µm: err with Gouy {e_with:.2} nm, without {e_without:.1} nm");
        assert!(e_without.abs() > 20.0 && e_without.abs() > 10.0 * e_with.abs());
    }

    #[test]
    fn decreasing_wavelengths_give_the_same_gap() {
        let (mut wl, mut y) = sweep(300e3, 1e-3, 0.2, 11);
        let up = fit_gap(&wl, &y, &cfg()).unwrap();
        wl.reverse();
        y.reverse();
        let down = fit_gap(&wl, &y, &cfg()).unwrap();
        assert!((up.estimate.gap_um - down.estimate.gap_um).abs() < 1e-9);
    }

    #[test]
    fn bad_sweeps_are_errors_not_panics() {
        let c = cfg();
        assert_eq!(fit_gap(&[], &[], &c).unwrap_err(), SweepError::EmptySweep);
        assert!(matches!(fit_gap(&[1.0, 2.0], &[1.0], &c), Err(SweepError::LengthMismatch { .. })));
        assert!(matches!(fit_gap(&[1.0, 2.0], &[1.0, 2.0], &c), Err(SweepError::TooFewSamples { .. })));
        let (wl, mut y) = sweep(100e3, 1e-3, 0.0, 1);
        y[17] = f64::NAN;
        assert!(matches!(fit_gap(&wl, &y, &c), Err(SweepError::NonFinite { index: 17, .. })));
        let (mut wl, y) = sweep(100e3, 1e-3, 0.0, 1);
        wl[100] = wl[99];
        assert!(matches!(fit_gap(&wl, &y, &c), Err(SweepError::NonMonotonicWavelength { index: 100, .. })));
        // 5 µm gap: 0.16 fringe across the sweep
        let (wl, y) = sweep(5e3, 1e-3, 0.0, 1);
        assert!(matches!(
            fit_gap(&wl, &y, &c),
            Err(SweepError::TooFewFringes { .. }) | Err(SweepError::NoFringeContrast { .. })
        ));
        // no fringes at all
        let wl = wavelengths(4000);
        let mut rng = StdRng::seed_from_u64(2);
        let noise = Normal::new(0.0, 1e-3).unwrap();
        let y: Vec<f64> = wl.iter().map(|_| 1.0 + noise.sample(&mut rng)).collect();
        assert!(fit_gap(&wl, &y, &c).is_err());
        assert!(matches!(peak_fsr_gap(&wl, &y, N_AIR), Err(SweepError::TooFewPeaks { .. })));
        assert!(matches!(fit_gap(&wl, &y, &SweepConfig { n_air: 0.5, ..c }), Err(SweepError::InvalidParameter { .. })));
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]
        #[test]
        fn arbitrary_sweeps_never_panic(
            ys in proptest::collection::vec(-10.0f64..10.0, 0..64),
            start in 1000.0f64..2000.0,
            step in -1.0f64..1.0,
            n_air in 0.9f64..1.1,
        ) {
            let wl: Vec<f64> = (0..ys.len()).map(|i| start + step * i as f64).collect();
            let _ = fit_gap(&wl, &ys, &SweepConfig { n_air, gouy_waist_nm: Some(W0) });
            let _ = fft_gap(&wl, &ys, n_air);
            let _ = peak_fsr_gap(&wl, &ys, n_air);
        }
    }
}
