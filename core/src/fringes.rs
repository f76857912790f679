//! Fringe analysis: turns a single-photodiode Fabry-Perot trace into the cavity-length change dL (nm) with its uncertainty.
//! Owns extremum counting (the paper's λ/4 method), motion-hint-guided sub-fringe phase tracking, a small two-beam test signal and the sign of dL from two wavelength sweeps.
//!
//! Signal model used here (a local two-beam model, independent of `model::optics`):
//! `I = A + B·(cos φ + h_c·cos 2φ + h_s·sin 2φ) + noise`, with the fringe phase
//! `φ = 4π·n_air·gap/λ - arctan(gap/z_R) + const`. A and B drift slowly with the motion.
//!
//! Conventions: lengths in nm (names carry units); the tracked phase increases when the
//! motion hint increases, so `dl_nm` is reported in the hint's sign convention.

use crate::sweep::GapEstimate;
use nalgebra::{Matrix3, SMatrix, SVector, Vector3};
use rand::Rng;
use rand_distr::{Distribution, Normal};
use std::f64::consts::{PI, TAU};
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
}

// ---------------------------------------------------------------------------------------
// Small numerical helpers
// ---------------------------------------------------------------------------------------

/// Fast `(sin x, cos x)`: Cody-Waite reduction by π/2 and the fdlibm minimax kernels.
/// Absolute error below 1e-15 for |x| < 1e6; used in the per-sample loops.
#[inline(always)]
pub(crate) fn sincos(x: f64) -> (f64, f64) {
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
    let kf = (x * std::f64::consts::FRAC_2_PI + TOINT) - TOINT;
    let r = (x - kf * PIO2_1) - kf * PIO2_1T;
    let q = kf as i64 as u64;
    let z = r * r;
    let s = r + r * z * (S1 + z * (S2 + z * (S3 + z * (S4 + z * (S5 + z * S6)))));
    let c = 1.0 - 0.5 * z + z * z * (C1 + z * (C2 + z * (C3 + z * (C4 + z * (C5 + z * C6)))));
    let (ss, cc) = if q & 1 == 0 { (s, c) } else { (c, s) };
    let sin = f64::from_bits(ss.to_bits() ^ ((q & 2) << 62));
    let cos = f64::from_bits(cc.to_bits() ^ ((q.wrapping_add(1) & 2) << 62));
    (sin, cos)
}

/// Phase per unit length change of the cavity, rad/nm: 4π·n_air/λ.
fn rad_per_nm(wavelength_nm: f64, n_air: f64) -> f64 {
    4.0 * PI * n_air / wavelength_nm
}

fn check_finite(what: &'static str, xs: &[f64]) -> Result<(), FringeError> {
    match xs.iter().position(|v| !v.is_finite()) {
        Some(index) => Err(FringeError::NonFinite { what, index, value: xs[index] }),
        None => Ok(()),
    }
}

fn check_optics(wavelength_nm: f64, n_air: f64) -> Result<(), FringeError> {
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

fn check_positive(name: &'static str, value: f64) -> Result<(), FringeError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(FringeError::InvalidParameter { name, value, reason: "must be finite and positive" })
    }
}

fn check_non_negative(name: &'static str, value: f64) -> Result<(), FringeError> {
    if value.is_finite() && value >= 0.0 {
        Ok(())
    } else {
        Err(FringeError::InvalidParameter { name, value, reason: "must be finite and non-negative" })
    }
}

/// Robust white-noise estimate from third differences (MAD, subsampled to at most 64 k
/// points). Over-estimates the noise when the fringes are sampled coarsely, which only
/// makes the extremum detector more conservative.
fn estimate_noise_sigma(y: &[f64]) -> f64 {
    if y.len() < 8 {
        return 0.0;
    }
    let m = y.len() - 3;
    let stride = m.div_ceil(65_536).max(1);
    let mut d: Vec<f64> =
        (0..m).step_by(stride).map(|k| (y[k + 3] - 3.0 * y[k + 2] + 3.0 * y[k + 1] - y[k]).abs()).collect();
    let mid = d.len() / 2;
    let (_, med, _) = d.select_nth_unstable_by(mid, f64::total_cmp);
    // Var of a third difference of white noise: 20 σ².
    1.4826 * *med / 20f64.sqrt()
}

// ---------------------------------------------------------------------------------------
// (a) Extremum detection and counting
// ---------------------------------------------------------------------------------------

/// Adaptive hysteresis of the extremum detector.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HysteresisConfig {
    /// An extremum is confirmed when the signal has moved away from it by this fraction of
    /// the recent peak-to-peak swing (max of the last four swings, so it follows A and B).
    pub relative: f64,
    /// Absolute floor of the hysteresis, in units of the estimated white-noise σ.
    pub noise_floor_factor: f64,
}

impl Default for HysteresisConfig {
    fn default() -> Self {
        Self { relative: 0.2, noise_floor_factor: 12.0 }
    }
}

impl HysteresisConfig {
    fn validate(&self) -> Result<(), FringeError> {
        if !(self.relative.is_finite() && self.relative > 0.0 && self.relative < 1.0) {
            return Err(FringeError::InvalidParameter {
                name: "hysteresis.relative",
                value: self.relative,
                reason: "must be in (0, 1)",
            });
        }
        check_positive("hysteresis.noise_floor_factor", self.noise_floor_factor)
    }
}

/// Kind of a signal extremum.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExtremumKind {
    /// Local maximum of the intensity.
    Max,
    /// Local minimum of the intensity.
    Min,
}

/// One confirmed extremum of the intensity.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Extremum {
    /// Sample index.
    pub index: usize,
    /// Maximum or minimum.
    pub kind: ExtremumKind,
    /// Raw sample value at `index`.
    pub value: f64,
    /// Signed λ/(4n) step this extremum stands for: +1 or -1, or 0 when it is not a fringe
    /// extremum (a turning point of the motion) or its direction is unknown.
    pub direction: i8,
}

/// Find the extrema of a trace with an adaptive hysteresis (a "zigzag" detector).
/// An extremum is reported only when the signal moved by the hysteresis on both sides of
/// it, so the trace ends are never reported. `direction` is left at 0.
pub fn detect_extrema(signal: &[f64], cfg: &HysteresisConfig) -> Result<Vec<Extremum>, FringeError> {
    if signal.is_empty() {
        return Err(FringeError::EmptyTrace);
    }
    check_finite("intensity", signal)?;
    cfg.validate()?;
    let sigma = estimate_noise_sigma(signal);
    let scale = signal.iter().fold(0f64, |m, v| m.max(v.abs())).max(f64::MIN_POSITIVE);
    let floor = (cfg.noise_floor_factor * sigma).max(1e-12 * scale);
    Ok(zigzag(signal, floor, cfg.relative))
}

fn zigzag(y: &[f64], floor: f64, rel: f64) -> Vec<Extremum> {
    #[derive(Clone, Copy, PartialEq)]
    enum Mode {
        Unknown,
        SeekMax,
        SeekMin,
    }
    let mut out = Vec::new();
    let mut mode = Mode::Unknown;
    let (mut hi, mut hi_i, mut lo, mut lo_i) = (y[0], 0usize, y[0], 0usize);
    let (mut hi_rise_ok, mut lo_fall_ok) = (false, false);
    let (mut cand, mut cand_i) = (y[0], 0usize);
    let mut last = y[0];
    let mut swings = [0.0f64; 4];
    let mut sw_i = 0usize;
    let mut h = floor;
    // farthest excursion away from the current candidate since it was set
    let mut away = f64::NAN;
    fn push(out: &mut Vec<Extremum>, index: usize, kind: ExtremumKind, value: f64) {
        out.push(Extremum { index, kind, value, direction: 0 })
    }
    for (k, &v) in y.iter().enumerate() {
        match mode {
            Mode::Unknown => {
                if v > hi {
                    hi = v;
                    hi_i = k;
                    hi_rise_ok = hi - lo >= h;
                }
                if v < lo {
                    lo = v;
                    lo_i = k;
                    lo_fall_ok = hi - lo >= h;
                }
                if v <= hi - h && hi_i < k {
                    if hi_rise_ok {
                        push(&mut out, hi_i, ExtremumKind::Max, hi);
                    }
                    last = hi;
                    mode = Mode::SeekMin;
                    cand = v;
                    cand_i = k;
                    away = v;
                } else if v >= lo + h && lo_i < k {
                    if lo_fall_ok {
                        push(&mut out, lo_i, ExtremumKind::Min, lo);
                    }
                    last = lo;
                    mode = Mode::SeekMax;
                    cand = v;
                    cand_i = k;
                    away = v;
                }
            }
            Mode::SeekMax => {
                if v > cand {
                    cand = v;
                    cand_i = k;
                    away = v;
                } else if v <= cand - h {
                    push(&mut out, cand_i, ExtremumKind::Max, cand);
                    swings[sw_i % 4] = cand - last;
                    sw_i += 1;
                    h = floor.max(rel * swings.iter().fold(0f64, |m, &s| m.max(s)));
                    last = cand;
                    mode = Mode::SeekMin;
                    cand = v;
                    cand_i = k;
                    away = v;
                }
            }
            Mode::SeekMin => {
                if v < cand {
                    cand = v;
                    cand_i = k;
                    away = v;
                } else if v >= cand + h {
                    push(&mut out, cand_i, ExtremumKind::Min, cand);
                    swings[sw_i % 4] = last - cand;
                    sw_i += 1;
                    h = floor.max(rel * swings.iter().fold(0f64, |m, &s| m.max(s)));
                    last = cand;
                    mode = Mode::SeekMax;
                    cand = v;
                    cand_i = k;
                    away = v;
                }
            }
        }
        match mode {
            Mode::SeekMax => away = away.min(v),
            Mode::SeekMin => away = away.max(v),
            Mode::Unknown => {}
        }
    }
    // At the end of the trace the last candidate cannot be followed by a full hysteresis
    // swing: confirm it when the signal moved away from it by more than the noise floor.
    match mode {
        Mode::SeekMax if cand - away >= floor => push(&mut out, cand_i, ExtremumKind::Max, cand),
        Mode::SeekMin if away - cand >= floor => push(&mut out, cand_i, ExtremumKind::Min, cand),
        _ => {}
    }
    out
}

/// Sign of `x` with a dead band: 0 when |x| <= tol.
fn sign_tol(x: f64, tol: f64) -> i8 {
    if x > tol {
        1
    } else if x < -tol {
        -1
    } else {
        0
    }
}

/// Give each extremum its direction from the motion hint: the hint's change from the
/// previous extremum (or trace start) and to the next one (or trace end). Opposite signs
/// mean the motion turned around here: the extremum is a turning point, not a fringe
/// extremum, and counts 0 (crossed and re-crossed, or not crossed at all).
fn classify_with_hint(extrema: &mut [Extremum], hint: &[f64], tol_nm: f64) {
    let n = hint.len();
    let m = extrema.len();
    for j in 0..m {
        let k = extrema[j].index;
        let kp = if j > 0 { extrema[j - 1].index } else { 0 };
        let kn = if j + 1 < m { extrema[j + 1].index } else { n - 1 };
        let before = sign_tol(hint[k] - hint[kp], tol_nm);
        let after = sign_tol(hint[kn] - hint[k], tol_nm);
        extrema[j].direction = if before * after < 0 { 0 } else { (before + after).signum() };
    }
}

/// Direction of a whole move.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MoveSign {
    /// The optical path (gap) grows during the move.
    Increasing,
    /// The optical path (gap) shrinks during the move.
    Decreasing,
}

/// Where extremum counting takes the direction of each step from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CountDirection<'a> {
    /// One sign for the whole (monotonic) move, e.g. from wavelength scans before and after
    /// (the paper's method). Every extremum counts.
    Given(MoveSign),
    /// The motion hint dL_hint(t) in nm, one value per sample: each extremum takes the
    /// hint's direction; extrema at turning points of the motion do not count.
    Hint(&'a [f64]),
}

/// Result of extremum counting.
#[derive(Debug, Clone, PartialEq)]
pub struct FringeCount {
    /// All confirmed extrema, with their signed step (0 = not counted).
    pub extrema: Vec<Extremum>,
    /// Signed number of λ/(4n) steps.
    pub count: i64,
    /// Number of extrema that counted (direction ≠ 0).
    pub counted: usize,
    /// dL = count·λ/(4n), nm.
    pub dl_nm: f64,
    /// One counting step λ/(4n), nm: the resolution (±) of `dl_nm`.
    pub resolution_nm: f64,
}

/// Count fringe extrema as the paper does: each extremum is a λ/(4·n_air) step of dL, its
/// sign given by the caller (monotonic move) or by the motion hint. The result is within
/// ±λ/(4n) of the true dL when no extremum is missed.
pub fn count_extrema(
    intensity: &[f64],
    direction: CountDirection<'_>,
    wavelength_nm: f64,
    n_air: f64,
    cfg: &HysteresisConfig,
) -> Result<FringeCount, FringeError> {
    if intensity.is_empty() {
        return Err(FringeError::EmptyTrace);
    }
    check_optics(wavelength_nm, n_air)?;
    let step_nm = wavelength_nm / (4.0 * n_air);
    if let CountDirection::Hint(h) = direction {
        if h.len() != intensity.len() {
            return Err(FringeError::LengthMismatch {
                intensity: intensity.len(),
                other: h.len(),
                what: "motion hint",
            });
        }
        check_finite("motion hint", h)?;
    }
    let mut extrema = detect_extrema(intensity, cfg)?;
    match direction {
        CountDirection::Given(sign) => {
            let d = if sign == MoveSign::Increasing { 1 } else { -1 };
            extrema.iter_mut().for_each(|e| e.direction = d);
        }
        CountDirection::Hint(h) => classify_with_hint(&mut extrema, h, 0.01 * step_nm),
    }
    let count: i64 = extrema.iter().map(|e| e.direction as i64).sum();
    let counted = extrema.iter().filter(|e| e.direction != 0).count();
    Ok(FringeCount { extrema, count, counted, dl_nm: count as f64 * step_nm, resolution_nm: step_nm })
}

/// Linear regression of the fringe order of counted extrema against the hint phase:
/// gives the scale g = dφ/dφ_hint and the coarse phase φ_lin(k) = intercept + g·κ·hint(k).
#[derive(Debug, Clone, Copy)]
struct ScaleFit {
    scale: f64,
    sigma: f64,
    intercept: f64,
}

fn scale_from_extrema(extrema: &[Extremum], hint: &[f64], kappa: f64) -> Option<ScaleFit> {
    let counted: Vec<&Extremum> = extrema.iter().filter(|e| e.direction != 0).collect();
    if counted.len() < 2 {
        return None;
    }
    // Fringe order m (phase = m·π): parity must match the kind (max = even).
    let mut m: i64 = if counted[0].kind == ExtremumKind::Max { 0 } else { 1 };
    let mut pts = Vec::with_capacity(counted.len());
    for (j, e) in counted.iter().enumerate() {
        if j > 0 {
            m += (counted[j - 1].direction as i64 + e.direction as i64) / 2;
        }
        let even = m.rem_euclid(2) == 0;
        if even != (e.kind == ExtremumKind::Max) {
            return None;
        }
        pts.push((kappa * hint[e.index], PI * m as f64));
    }
    let nf = pts.len() as f64;
    let mx = pts.iter().map(|p| p.0).sum::<f64>() / nf;
    let my = pts.iter().map(|p| p.1).sum::<f64>() / nf;
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    if sxx < (PI * PI) * 0.25 {
        return None;
    }
    let scale = sxy / sxx;
    let rss: f64 = pts.iter().map(|p| (p.1 - my - scale * (p.0 - mx)).powi(2)).sum();
    // Extremum timing is only good to ~0.1 rad: floor the scatter there.
    let s2 = if pts.len() > 2 { (rss / (nf - 2.0)).max(0.01) } else { 0.04 };
    Some(ScaleFit { scale, sigma: (s2 / sxx).sqrt(), intercept: my - scale * mx })
}

// ---------------------------------------------------------------------------------------
// (b) Phase tracking
// ---------------------------------------------------------------------------------------

/// Second-harmonic distortion of the fringe, relative to B:
/// `f(φ) = cos φ + cos_rel·cos 2φ + sin_rel·sin 2φ`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Harmonic {
    /// Coefficient of cos 2φ.
    pub cos_rel: f64,
    /// Coefficient of sin 2φ.
    pub sin_rel: f64,
}

impl Harmonic {
    #[inline(always)]
    fn f_and_slope(&self, s: f64, c: f64) -> (f64, f64) {
        let c2 = 2.0 * c * c - 1.0;
        let s2 = 2.0 * s * c;
        (c + self.cos_rel * c2 + self.sin_rel * s2, -s - 2.0 * self.cos_rel * s2 + 2.0 * self.sin_rel * c2)
    }

    /// (max, min) of f(φ) over a period (Newton from 0 and π).
    fn extremes(&self) -> (f64, f64) {
        let newton = |mut p: f64| {
            for _ in 0..8 {
                let (s, c) = p.sin_cos();
                let (s2, c2) = (2.0 * p).sin_cos();
                let d1 = -s - 2.0 * self.cos_rel * s2 + 2.0 * self.sin_rel * c2;
                let d2 = -c - 4.0 * self.cos_rel * c2 - 4.0 * self.sin_rel * s2;
                if d2.abs() > 1e-12 {
                    p -= (d1 / d2).clamp(-0.5, 0.5);
                }
            }
            let (s, c) = p.sin_cos();
            self.f_and_slope(s, c).0
        };
        (newton(0.0), newton(PI))
    }
}

/// An envelope known to the caller (e.g. from an earlier, longer trace), in the model
/// `I = offset + amplitude·f(φ)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KnownEnvelope {
    /// A, intensity units.
    pub offset: f64,
    /// B, intensity units (> 0).
    pub amplitude: f64,
    /// Harmonic distortion of the fringe (zero if unknown).
    pub harmonic: Harmonic,
}

/// Where the phase tracker takes the envelope A(t), B(t) from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum EnvelopeSource {
    /// From the data: levels of the fringe extrema, interpolated along the motion path.
    /// Needs a trace covering at least one fringe.
    FromData,
    /// Known constant envelope: allows traces shorter than one fringe.
    Known(KnownEnvelope),
}

/// Gouy-phase correction of the phase → length conversion:
/// φ = 4πn·gap/λ - arctan(gap/z_R) + const.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GouyCorrection {
    /// Rayleigh range z_R of the fiber mode, nm (≈ 54 µm for SMF-28 at 1560 nm).
    pub rayleigh_range_nm: f64,
    /// Absolute gap at the first sample, nm (from a wavelength sweep).
    pub gap_at_start_nm: f64,
    /// +1 if the gap grows when the hint (dL) grows, -1 otherwise.
    pub gap_sign: f64,
}

/// Settings of the phase tracker.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackConfig {
    /// Envelope source.
    pub envelope: EnvelopeSource,
    /// Optional Gouy correction (its effect is ~1e-5 of dL at a 900 µm gap).
    pub gouy: Option<GouyCorrection>,
    /// Extremum detector settings (envelope and hint-scale estimation).
    pub hysteresis: HysteresisConfig,
    /// Random-walk phase noise of the motion model, rad per √sample: what the hint cannot
    /// explain (stage noise, thermal drift).
    pub phase_noise_rad_per_sqrt_sample: f64,
    /// Random walk of the hint scale g, per √rad of hint phase travelled.
    pub scale_noise_per_sqrt_rad: f64,
    /// Prior standard deviation of the hint scale when the trace cannot measure it.
    pub scale_prior_sigma: f64,
}

impl Default for TrackConfig {
    fn default() -> Self {
        Self {
            envelope: EnvelopeSource::FromData,
            gouy: None,
            hysteresis: HysteresisConfig::default(),
            phase_noise_rad_per_sqrt_sample: 1e-5,
            scale_noise_per_sqrt_rad: 1e-4,
            scale_prior_sigma: 0.05,
        }
    }
}

impl TrackConfig {
    fn validate(&self) -> Result<(), FringeError> {
        self.hysteresis.validate()?;
        check_non_negative("phase_noise_rad_per_sqrt_sample", self.phase_noise_rad_per_sqrt_sample)?;
        check_non_negative("scale_noise_per_sqrt_rad", self.scale_noise_per_sqrt_rad)?;
        check_positive("scale_prior_sigma", self.scale_prior_sigma)?;
        if let EnvelopeSource::Known(k) = self.envelope {
            if !k.offset.is_finite() {
                return Err(FringeError::InvalidParameter {
                    name: "envelope.offset",
                    value: k.offset,
                    reason: "must be finite",
                });
            }
            check_positive("envelope.amplitude", k.amplitude)?;
            for (name, v) in
                [("envelope.harmonic.cos_rel", k.harmonic.cos_rel), ("envelope.harmonic.sin_rel", k.harmonic.sin_rel)]
            {
                if !(v.is_finite() && v.abs() < 0.2) {
                    return Err(FringeError::InvalidParameter { name, value: v, reason: "must be finite, |h| < 0.2" });
                }
            }
        }
        if let Some(g) = self.gouy {
            check_positive("gouy.rayleigh_range_nm", g.rayleigh_range_nm)?;
            check_positive("gouy.gap_at_start_nm", g.gap_at_start_nm)?;
            if g.gap_sign.abs() != 1.0 {
                return Err(FringeError::InvalidParameter {
                    name: "gouy.gap_sign",
                    value: g.gap_sign,
                    reason: "must be +1 or -1",
                });
            }
        }
        Ok(())
    }
}

/// Result of phase tracking.
#[derive(Debug, Clone, PartialEq)]
pub struct PhaseTrack {
    /// Unwrapped fringe phase per sample, rad, in the model `I = A + B·f(φ)`; it increases
    /// when the motion hint increases.
    pub phase_rad: Vec<f64>,
    /// dL(t) relative to the first sample, nm (hint sign convention).
    pub dl_nm: Vec<f64>,
    /// Per-sample standard uncertainty of `dl_nm` from the filter covariance (noise part
    /// only, see `sigma_total_nm` for the full budget at the end), nm.
    pub sigma_dl_nm: Vec<f64>,
    /// dL between the first and the last sample, nm.
    pub total_dl_nm: f64,
    /// Standard uncertainty of `total_dl_nm`, nm: filter part and envelope part in quadrature.
    pub sigma_total_nm: f64,
    /// Filter (noise) part of `sigma_total_nm`, scaled up by √χ² when the residuals are
    /// larger than the noise model, nm.
    pub sigma_filter_nm: f64,
    /// Envelope part of `sigma_total_nm`: the effect of the uncertainty of A and B at both
    /// ends, propagated through the filters, nm.
    pub sigma_envelope_nm: f64,
    /// Estimated ratio of true phase rate to hint phase rate (1/scale error of the hint).
    pub hint_scale: f64,
    /// Harmonic distortion used by the tracker (estimated or given).
    pub harmonic: Harmonic,
    /// White-noise σ of the intensity used by the filters (estimated), intensity units.
    pub noise_sigma: f64,
    /// Mean normalised squared innovation of the filters (≈ 1 when the model fits).
    pub normalized_chi2: f64,
    /// Extrema used for the envelope and the hint scale.
    pub extrema_used: usize,
    /// Largest disagreement between the forward and backward filters away from the ends,
    /// rad (large values mean a cycle slip somewhere).
    pub max_filter_disagreement_rad: f64,
    /// Human-readable warnings (inconsistent extremum count, filters disagreeing, ...).
    pub warnings: Vec<String>,
}

/// Level of an extremum of the envelope, placed at a path position (nm of hint travel).
#[derive(Debug, Clone, Copy)]
struct Knot {
    s: f64,
    level: f64,
    sigma: f64,
}

/// Piecewise-linear interpolation of knots along the motion path, with a cursor for
/// monotone queries and a clamped linear extrapolation beyond the end knots.
fn knot_value(knots: &[Knot], s: f64, cursor: &mut usize, max_extrap: f64) -> f64 {
    if knots.len() == 1 {
        return knots[0].level;
    }
    while *cursor + 2 < knots.len() && knots[*cursor + 1].s <= s {
        *cursor += 1;
    }
    let (k0, k1) = (knots[*cursor], knots[*cursor + 1]);
    let slope = if k1.s > k0.s { (k1.level - k0.level) / (k1.s - k0.s) } else { 0.0 };
    if s < k0.s {
        k0.level + slope * (s - k0.s).max(-max_extrap)
    } else if s > k1.s {
        k1.level + slope * (s - k1.s).min(max_extrap)
    } else {
        k0.level + slope * (s - k0.s)
    }
}

/// Refine the level of a fringe extremum by a local fit `a + b·cos Δ + c·sin Δ` in the
/// (scaled) hint phase Δ within ±1 rad. Returns (level, σ_level) or None if the window is
/// too short in phase.
fn fit_extremum_level(
    y: &[f64],
    hint: &[f64],
    k: usize,
    bounds: (usize, usize),
    gk: f64,
    is_max: bool,
) -> Option<(f64, f64)> {
    const HALF: f64 = 1.0;
    let h0 = hint[k];
    let mut i0 = k;
    while i0 > bounds.0 && (gk * (hint[i0 - 1] - h0)).abs() <= HALF {
        i0 -= 1;
    }
    let mut i1 = k;
    while i1 + 1 < bounds.1 && (gk * (hint[i1 + 1] - h0)).abs() <= HALF {
        i1 += 1;
    }
    let m = i1 - i0 + 1;
    if m < 6 {
        return None;
    }
    let mut ata = Matrix3::<f64>::zeros();
    let mut aty = Vector3::<f64>::zeros();
    let (mut dmin, mut dmax) = (f64::INFINITY, f64::NEG_INFINITY);
    for i in i0..=i1 {
        let d = gk * (hint[i] - h0);
        dmin = dmin.min(d);
        dmax = dmax.max(d);
        let (s, c) = sincos(d);
        let x = Vector3::new(1.0, c, s);
        ata += x * x.transpose();
        aty += x * y[i];
    }
    if dmax - dmin < 0.8 {
        return None;
    }
    let inv = ata.try_inverse()?;
    let p = inv * aty;
    let r = (p[1] * p[1] + p[2] * p[2]).sqrt();
    if r <= 0.0 {
        return None;
    }
    let peak = if is_max { p[2].atan2(p[1]) } else { (-p[2]).atan2(-p[1]) };
    if peak < dmin - 0.2 || peak > dmax + 0.2 {
        return None;
    }
    let level = if is_max { p[0] + r } else { p[0] - r };
    let mut rss = 0.0;
    for i in i0..=i1 {
        let (s, c) = sincos(gk * (hint[i] - h0));
        rss += (y[i] - p[0] - p[1] * c - p[2] * s).powi(2);
    }
    let s2 = rss / (m as f64 - 3.0);
    let sgn = if is_max { 1.0 } else { -1.0 };
    let v = Vector3::new(1.0, sgn * p[1] / r, sgn * p[2] / r);
    let var = s2 * (v.transpose() * inv * v)[0];
    Some((level, var.max(0.0).sqrt()))
}

/// Envelope of the fringes: knots of the upper and lower envelopes along the path, or a
/// known constant.
enum Envelope {
    Knots { upper: Vec<Knot>, lower: Vec<Knot> },
    Known(KnownEnvelope),
}

impl Envelope {
    /// Fill A and B per sample for the harmonic `harm` (upper = A + B·f_max, lower = A + B·f_min).
    fn fill(&self, path: &[f64], harm: &Harmonic, max_extrap: f64, a: &mut [f64], b: &mut [f64]) {
        match self {
            Envelope::Known(k) => {
                a.fill(k.offset);
                b.fill(k.amplitude);
            }
            Envelope::Knots { upper, lower } => {
                let (fmax, fmin) = harm.extremes();
                let inv = 1.0 / (fmax - fmin);
                let (mut cu, mut cl) = (0usize, 0usize);
                for ((&s, ak), bk) in path.iter().zip(a.iter_mut()).zip(b.iter_mut()) {
                    let u = knot_value(upper, s, &mut cu, max_extrap);
                    let l = knot_value(lower, s, &mut cl, max_extrap);
                    let bb = ((u - l) * inv).max(f64::MIN_POSITIVE);
                    *bk = bb;
                    *ak = u - bb * fmax;
                }
            }
        }
    }

    /// Standard uncertainty of (A, B) near path position `s`, from the knot fits and the
    /// scatter of the knot levels about their neighbours' interpolation.
    fn sigma_at(&self, s: f64, harm_sigma: f64, amplitude: f64) -> (f64, f64) {
        match self {
            Envelope::Known(_) => (0.0, 0.0),
            Envelope::Knots { upper, lower } => {
                let su = knot_sigma(upper, s);
                let sl = knot_sigma(lower, s);
                let sb = 0.5 * (su * su + sl * sl).sqrt();
                let sa = (sb * sb + (amplitude * harm_sigma).powi(2)).sqrt();
                (sa, sb)
            }
        }
    }
}

fn knot_sigma(knots: &[Knot], s: f64) -> f64 {
    // Nearest knot's fit σ; doubled when extrapolating beyond the end knots.
    let j = knots
        .iter()
        .enumerate()
        .min_by(|a, b| (a.1.s - s).abs().total_cmp(&(b.1.s - s).abs()))
        .map(|(j, _)| j)
        .unwrap_or(0);
    let outside = s < knots[0].s || s > knots[knots.len() - 1].s;
    let mut sig = knots[j].sigma;
    if knots.len() >= 3 {
        // Scatter about the neighbours' interpolation: captures noise and drift curvature.
        let mut acc = 0.0;
        let mut cnt = 0.0;
        for w in knots.windows(3) {
            let t = if w[2].s > w[0].s { (w[1].s - w[0].s) / (w[2].s - w[0].s) } else { 0.5 };
            let pred = w[0].level + t * (w[2].level - w[0].level);
            acc += (w[1].level - pred).powi(2);
            cnt += 1.0;
        }
        sig = sig.max((acc / cnt / 1.5).sqrt());
    }
    if outside {
        2.0 * sig
    } else {
        sig
    }
}

/// Motion windows: spans of about `width_nm` of hint travel. Returns (start window,
/// end window, reference index of the start = last sample before motion, reference index
/// of the end = first sample of the final rest).
fn motion_windows(path: &[f64], width_nm: f64) -> ((usize, usize), (usize, usize), usize, usize) {
    let n = path.len();
    let total = path[n - 1];
    let i_ref = path.partition_point(|&p| p <= 0.0).saturating_sub(1);
    let i1 = (path.partition_point(|&p| p < path[i_ref] + width_nm) + 1).min(n);
    let e_ref = path.partition_point(|&p| p < total).min(n - 1);
    let e0 = path.partition_point(|&p| p <= total - width_nm).saturating_sub(1);
    ((i_ref, i1.max(i_ref + 1)), (e0.min(e_ref), e_ref + 1), i_ref, e_ref)
}

/// Least-squares estimate of the second harmonic in a window, from the envelope-normalised
/// signal y' = (I - A0)/B0 fitted by 1, cos Δ, sin Δ, cos 2Δ, sin 2Δ.
fn window_harmonic(y: &[f64], hint: &[f64], a: &[f64], b: &[f64], win: (usize, usize), gk: f64) -> Option<WindowFit> {
    let (i0, i1) = win;
    let m = i1 - i0;
    if m < 20 {
        return None;
    }
    let stride = m.div_ceil(8192).max(1);
    let h0 = hint[i0];
    let mut ata = SMatrix::<f64, 5, 5>::zeros();
    let mut aty = SVector::<f64, 5>::zeros();
    let mut cnt = 0usize;
    for i in (i0..i1).step_by(stride) {
        let (s, c) = sincos(gk * (hint[i] - h0));
        let x = SVector::<f64, 5>::from([1.0, c, s, 2.0 * c * c - 1.0, 2.0 * s * c]);
        let yn = (y[i] - a[i]) / b[i];
        ata += x * x.transpose();
        aty += x * yn;
        cnt += 1;
    }
    if cnt < 20 {
        return None;
    }
    let eig = ata.symmetric_eigen();
    let (emin, emax) = eig.eigenvalues.iter().fold((f64::INFINITY, 0f64), |(lo, hi), &e| (lo.min(e), hi.max(e)));
    if emin < 0.05 * emax {
        return None;
    }
    let inv = ata.try_inverse()?;
    let p = inv * aty;
    let b1 = (p[1] * p[1] + p[2] * p[2]).sqrt();
    if b1 < 0.3 {
        return None;
    }
    let theta = (-p[2]).atan2(p[1]);
    // (h_c - i h_s) = (d - i e)·e^{-2iθ}/B1
    let (s2t, c2t) = (2.0 * theta).sin_cos();
    let (d, e) = (p[3], p[4]);
    let re = (d * c2t - e * s2t) / b1;
    let im = (-e * c2t - d * s2t) / b1;
    let mut rss = 0.0;
    let mut rss_raw = 0.0;
    for i in (i0..i1).step_by(stride) {
        let (s, c) = sincos(gk * (hint[i] - h0));
        let x = SVector::<f64, 5>::from([1.0, c, s, 2.0 * c * c - 1.0, 2.0 * s * c]);
        let r = (y[i] - a[i]) / b[i] - p.dot(&x);
        rss += r * r;
        rss_raw += (r * b[i]).powi(2);
    }
    let dof = (cnt as f64 - 5.0).max(1.0);
    let sigma = (rss / dof * 0.5 * (inv[(3, 3)] + inv[(4, 4)])).sqrt() / b1;
    Some(WindowFit { harm: Harmonic { cos_rel: re, sin_rel: -im }, sigma, rss_raw, dof })
}

/// Result of a local harmonic fit.
struct WindowFit {
    harm: Harmonic,
    sigma: f64,
    rss_raw: f64,
    dof: f64,
}

/// Phase at the reference index `iref` of a window, by a grid search then Gauss-Newton on
/// θ in the full model I = A + B·f(θ + g·κ·(hint - hint_ref)). Returns (θ, RSS, samples).
#[allow(clippy::too_many_arguments)]
fn anchor_phase(
    y: &[f64],
    hint: &[f64],
    a: &[f64],
    b: &[f64],
    harm: &Harmonic,
    win: (usize, usize),
    iref: usize,
    gk: f64,
) -> (f64, f64, usize) {
    let (i0, i1) = win;
    let m = i1 - i0;
    let stride = m.div_ceil(4096).max(1);
    let h0 = hint[iref];
    let pts: Vec<(f64, f64, f64, f64)> =
        (i0..i1).step_by(stride).map(|i| (gk * (hint[i] - h0), y[i], a[i], b[i])).collect();
    let cost = |theta: f64| -> f64 {
        pts.iter()
            .map(|&(d, yy, aa, bb)| {
                let (s, c) = sincos(d + theta);
                (yy - aa - bb * harm.f_and_slope(s, c).0).powi(2)
            })
            .sum()
    };
    const GRID: usize = 72;
    let mut best = (0.0, f64::INFINITY);
    for j in 0..GRID {
        let t = TAU * j as f64 / GRID as f64;
        let c = cost(t);
        if c < best.1 {
            best = (t, c);
        }
    }
    let mut theta = best.0;
    let mut cur = best.1;
    for _ in 0..20 {
        let (mut jr, mut jj) = (0.0, 0.0);
        for &(d, yy, aa, bb) in &pts {
            let (s, c) = sincos(d + theta);
            let (f, fp) = harm.f_and_slope(s, c);
            let r = yy - aa - bb * f;
            let jac = -bb * fp;
            jr += jac * r;
            jj += jac * jac;
        }
        if jj <= 0.0 {
            break;
        }
        let mut step = -jr / jj;
        let mut accepted = false;
        for _ in 0..10 {
            let c = cost(theta + step);
            if c <= cur {
                theta += step;
                cur = c;
                accepted = true;
                break;
            }
            step *= 0.5;
        }
        if !accepted || step.abs() < 1e-9 {
            break;
        }
    }
    (theta, cur, pts.len())
}

/// One direction of the extended Kalman filter on the state (φ, g), with the hint phase
/// increment as control input: φ ← φ + g·u. Also carries the linear sensitivities of the
/// state to a constant error of A (sa) and of B (sb).
#[derive(Debug, Clone, Copy)]
struct Ekf {
    phi: f64,
    g: f64,
    p00: f64,
    p01: f64,
    p11: f64,
    sa0: f64,
    sa1: f64,
    sb0: f64,
    sb1: f64,
}

impl Ekf {
    fn new(phi: f64, g: f64, var_phi: f64, var_g: f64) -> Self {
        Self { phi, g, p00: var_phi, p01: 0.0, p11: var_g, sa0: 0.0, sa1: 0.0, sb0: 0.0, sb1: 0.0 }
    }

    #[inline(always)]
    fn predict(&mut self, u: f64, q_phi: f64, q_g: f64) {
        self.phi += self.g * u;
        let p11u = self.p11 * u;
        self.p00 += u * (2.0 * self.p01 + p11u) + q_phi;
        self.p01 += p11u;
        self.p11 += q_g * u.abs();
        self.sa0 += u * self.sa1;
        self.sb0 += u * self.sb1;
    }

    /// Measurement update; returns (innovation, innovation variance).
    #[inline(always)]
    fn update(&mut self, y: f64, a: f64, b: f64, harm: &Harmonic, r: f64) -> (f64, f64) {
        let (s, c) = sincos(self.phi);
        let (f, fp) = harm.f_and_slope(s, c);
        let h = b * fp;
        let nu = y - a - b * f;
        let ph0 = self.p00 * h;
        let ph1 = self.p01 * h;
        let sv = h * ph0 + r;
        let inv = 1.0 / sv;
        let k0 = ph0 * inv;
        let k1 = ph1 * inv;
        self.phi += k0 * nu;
        self.g += k1 * nu;
        let rs = r * inv;
        self.p11 -= ph1 * k1;
        self.p00 *= rs;
        self.p01 *= rs;
        let ia = 1.0 - h * self.sa0;
        self.sa0 += k0 * ia;
        self.sa1 += k1 * ia;
        let ib = f - h * self.sb0;
        self.sb0 += k0 * ib;
        self.sb1 += k1 * ib;
        (nu, sv)
    }
}

/// Convert a phase change to a length change, with the optional Gouy correction.
fn phase_to_dl(dphi: f64, kappa: f64, gouy: &Option<GouyCorrection>) -> f64 {
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

/// Track the fringe phase sample by sample, guided by the motion hint.
///
/// `hint_dl_nm` is the predicted optical-path change from the robot model (one value per
/// sample; its rate sign must be right except very near turning points, its scale may be
/// off by a few %). Method: extrema give the envelope (interpolated along the motion path)
/// and the hint scale; local fits at both ends of the motion give the second harmonic, the
/// noise and the initial phases; then two extended Kalman filters on (φ, g), one forward
/// and one backward, run interleaved over the trace and are fused sample by sample. The
/// hint drives the prediction, so direction survives turning points and pauses, and near
/// fringe extrema (where the intensity carries no phase information) the phase follows the
/// motion model instead of an arccos.
///
/// Errors: empty or non-finite input, mismatched lengths, no motion, and (with
/// `EnvelopeSource::FromData`) traces covering less than one fringe.
pub fn track_phase(
    intensity: &[f64],
    hint_dl_nm: &[f64],
    wavelength_nm: f64,
    n_air: f64,
    cfg: &TrackConfig,
) -> Result<PhaseTrack, FringeError> {
    let n = intensity.len();
    if n == 0 {
        return Err(FringeError::EmptyTrace);
    }
    if hint_dl_nm.len() != n {
        return Err(FringeError::LengthMismatch { intensity: n, other: hint_dl_nm.len(), what: "motion hint" });
    }
    check_optics(wavelength_nm, n_air)?;
    cfg.validate()?;
    check_finite("intensity", intensity)?;
    check_finite("motion hint", hint_dl_nm)?;
    let kappa = rad_per_nm(wavelength_nm, n_air);
    let fringe_nm = wavelength_nm / (2.0 * n_air);
    let mut warnings = Vec::new();

    let __t = std::time::Instant::now();
    let __tm = std::env::var("PR_TIMING").is_ok();
    // Path travelled by the hint (nm): the envelope is a function of where the robot is,
    // so it is interpolated along this coordinate and stays constant during pauses.
    let mut path = Vec::with_capacity(n);
    let mut acc = 0.0;
    path.push(0.0);
    for w in hint_dl_nm.windows(2) {
        acc += (w[1] - w[0]).abs();
        path.push(acc);
    }
    if acc <= 0.0 {
        return Err(FringeError::NoMotion);
    }

    if __tm {
        eprintln!("TIMING {:>16}: {:?}", "path", __t.elapsed());
    }
    // Extrema, their direction from the hint, and the hint scale.
    let mut extrema = detect_extrema(intensity, &cfg.hysteresis)?;
    classify_with_hint(&mut extrema, hint_dl_nm, 0.005 * fringe_nm);
    let scale_fit = scale_from_extrema(&extrema, hint_dl_nm, kappa);
    let counted = extrema.iter().filter(|e| e.direction != 0).count();
    if counted >= 2 && scale_fit.is_none() {
        warnings.push(
            "extremum sequence inconsistent with the hint (missed or spurious extremum): \
             hint scale taken from the prior"
                .to_string(),
        );
    }
    let (mut g0, mut sigma_g0) = match scale_fit {
        Some(f) => (f.scale, (3.0 * f.sigma).clamp(1e-4, cfg.scale_prior_sigma)),
        None => (1.0, cfg.scale_prior_sigma),
    };
    if !(0.5..2.0).contains(&g0) {
        warnings.push(format!("hint scale from the extrema {g0:.3} is implausible: using 1 ± prior"));
        g0 = 1.0;
        sigma_g0 = cfg.scale_prior_sigma;
    }
    let gk = g0 * kappa;

    if __tm {
        eprintln!("TIMING {:>16}: {:?}", "extrema+scale", __t.elapsed());
    }
    // Envelope.
    let envelope = match cfg.envelope {
        EnvelopeSource::Known(k) => Envelope::Known(k),
        EnvelopeSource::FromData => {
            let mut upper = Vec::new();
            let mut lower = Vec::new();
            let used: Vec<&Extremum> = extrema.iter().filter(|e| e.direction != 0).collect();
            let (nmax, nmin) = used.iter().fold((0, 0), |(a, b), e| match e.kind {
                ExtremumKind::Max => (a + 1, b),
                ExtremumKind::Min => (a, b + 1),
            });
            if nmax == 0 || nmin == 0 {
                return Err(FringeError::TooFewFringes { maxima: nmax, minima: nmin });
            }
            let noise = estimate_noise_sigma(intensity);
            for (j, e) in extrema.iter().enumerate() {
                if e.direction == 0 {
                    continue;
                }
                let lo_b = if j > 0 { extrema[j - 1].index + 1 } else { 0 };
                let hi_b = if j + 1 < extrema.len() { extrema[j + 1].index } else { n };
                let is_max = e.kind == ExtremumKind::Max;
                let (level, sigma) = fit_extremum_level(intensity, hint_dl_nm, e.index, (lo_b, hi_b), gk, is_max)
                    .unwrap_or((e.value, 2.0 * noise));
                let knot = Knot { s: path[e.index], level, sigma };
                if is_max {
                    upper.push(knot);
                } else {
                    lower.push(knot);
                }
            }
            Envelope::Knots { upper, lower }
        }
    };

    if __tm {
        eprintln!("TIMING {:>16}: {:?}", "envelope knots", __t.elapsed());
    }
    // Envelope without harmonic correction, for the harmonic estimate.
    let mut a_arr = vec![0.0; n];
    let mut b_arr = vec![0.0; n];
    let max_extrap = 2.0 * fringe_nm;
    envelope.fill(&path, &Harmonic::default(), max_extrap, &mut a_arr, &mut b_arr);
    let width = 2.0 * fringe_nm;
    let (win_s, win_e, iref_s, iref_e) = motion_windows(&path, width);

    if __tm {
        eprintln!("TIMING {:>16}: {:?}", "fill1", __t.elapsed());
    }
    let mut noise_ls: Option<f64> = None;
    let (harm, harm_sigma) = match cfg.envelope {
        EnvelopeSource::Known(k) => (k.harmonic, 0.0),
        EnvelopeSource::FromData => {
            // Start, end and up to six windows in between.
            let total = path[n - 1];
            let mut wins = vec![win_s, win_e];
            for j in 1..7 {
                let c = total * j as f64 / 7.0;
                let w0 = path.partition_point(|&p| p < c - 0.5 * width);
                let w1 = path.partition_point(|&p| p < c + 0.5 * width).min(n);
                if w1 > w0 && c - 0.5 * width > path[win_s.1.min(n - 1)] && c + 0.5 * width < path[win_e.0] {
                    wins.push((w0, w1));
                }
            }
            let fits: Vec<WindowFit> =
                wins.iter().filter_map(|&w| window_harmonic(intensity, hint_dl_nm, &a_arr, &b_arr, w, gk)).collect();
            if !fits.is_empty() {
                let rss: f64 = fits.iter().map(|f| f.rss_raw).sum();
                let dof: f64 = fits.iter().map(|f| f.dof).sum();
                noise_ls = Some(rss / dof);
            }
            let ests: Vec<(Harmonic, f64)> = fits.iter().map(|f| (f.harm, f.sigma)).collect();
            if ests.is_empty() {
                warnings.push("no window covers enough phase to measure the fringe harmonic: assumed zero".to_string());
                (Harmonic::default(), 0.01)
            } else {
                let m = ests.len() as f64;
                let hc = ests.iter().map(|e| e.0.cos_rel).sum::<f64>() / m;
                let hs = ests.iter().map(|e| e.0.sin_rel).sum::<f64>() / m;
                let stat = (ests.iter().map(|e| e.1 * e.1).sum::<f64>() / m).sqrt() / m.sqrt();
                let scatter = if ests.len() > 1 {
                    (ests.iter().map(|e| (e.0.cos_rel - hc).powi(2) + (e.0.sin_rel - hs).powi(2)).sum::<f64>()
                        / (2.0 * (m - 1.0) * m))
                        .sqrt()
                } else {
                    0.0
                };
                (Harmonic { cos_rel: hc, sin_rel: hs }, stat.max(scatter))
            }
        }
    };
    if __tm {
        eprintln!("TIMING {:>16}: {:?}", "harmonic", __t.elapsed());
    }
    envelope.fill(&path, &harm, max_extrap, &mut a_arr, &mut b_arr);
    if std::env::var("DBG_ENV").is_ok() {
        if let Envelope::Knots { upper, lower } = &envelope {
            for k in upper.iter().take(3).chain(upper.iter().rev().take(3)) {
                eprintln!("U knot s {:.1} lvl {:.5} sig {:.2e}", k.s, k.level, k.sigma);
            }
            for k in lower.iter().take(3).chain(lower.iter().rev().take(3)) {
                eprintln!("L knot s {:.1} lvl {:.5} sig {:.2e}", k.s, k.level, k.sigma);
            }
        }
        for k in (0..n).step_by(n / 40) {
            eprintln!("env k {k} path {:.1} A {:.5} B {:.5}", path[k], a_arr[k], b_arr[k]);
        }
        eprintln!("g0 {g0} sigma_g0 {sigma_g0} harm {harm:?} win_s {win_s:?} win_e {win_e:?}");
    }

    if __tm {
        eprintln!("TIMING {:>16}: {:?}", "fill2", __t.elapsed());
    }
    // Initial phases at both ends and the measurement noise.
    let (theta_s, rss_s, m_s) = anchor_phase(intensity, hint_dl_nm, &a_arr, &b_arr, &harm, win_s, iref_s, gk);
    let (theta_e, rss_e, m_e) = anchor_phase(intensity, hint_dl_nm, &a_arr, &b_arr, &harm, win_e, iref_e, gk);
    let b_typ = b_arr.iter().sum::<f64>() / n as f64;
    // Measurement noise: from the local LS fits when available (they absorb slow envelope
    // errors, so they see the white noise), else from the anchor fits.
    let r_anchor = (rss_s + rss_e) / ((m_s + m_e) as f64 - 2.0).max(1.0);
    let r_meas = noise_ls.unwrap_or(r_anchor).max((1e-7 * b_typ).powi(2));
    let unwrap_near = |theta: f64, target: f64| theta + TAU * ((target - theta) / TAU).round();
    let (phi_ref_s, phi_ref_e) = match scale_fit {
        Some(f) => {
            let lin = |k: usize| f.intercept + f.scale * kappa * hint_dl_nm[k];
            (unwrap_near(theta_s, lin(iref_s)), unwrap_near(theta_e, lin(iref_e)))
        }
        None => {
            let ps = unwrap_near(theta_s, 0.0);
            let pred = ps + gk * (hint_dl_nm[iref_e] - hint_dl_nm[iref_s]);
            (ps, unwrap_near(theta_e, pred))
        }
    };
    let phi0 = phi_ref_s - gk * (hint_dl_nm[iref_s] - hint_dl_nm[0]);
    let phin = phi_ref_e + gk * (hint_dl_nm[n - 1] - hint_dl_nm[iref_e]);

    if __tm {
        eprintln!("TIMING {:>16}: {:?}", "anchors", __t.elapsed());
    }
    // Main pass: forward and backward filters interleaved (independent dependency chains).
    let q_phi = cfg.phase_noise_rad_per_sqrt_sample.powi(2);
    let q_g = cfg.scale_noise_per_sqrt_rad.powi(2);
    let var_phi0 = 0.1f64.powi(2);
    let var_g0 = sigma_g0 * sigma_g0;
    let mut fw = Ekf::new(phi0, g0, var_phi0, var_g0);
    let mut bw = Ekf::new(phin, g0, var_phi0, var_g0);
    let mut phase = vec![0.0; n]; // forward φ, then fused φ
    let mut var_f = vec![0.0; n]; // forward var, then fused var
    let mut phase_b = vec![0.0; n];
    let mut var_b = vec![0.0; n];
    let mut chi2 = 0.0;
    let mut fw_first = fw;
    let mut bw_first = bw;
    for i in 0..n {
        let j = n - 1 - i;
        if i > 0 {
            fw.predict(kappa * (hint_dl_nm[i] - hint_dl_nm[i - 1]), q_phi, q_g);
            bw.predict(kappa * (hint_dl_nm[j] - hint_dl_nm[j + 1]), q_phi, q_g);
        }
        let (nf, sf) = fw.update(intensity[i], a_arr[i], b_arr[i], &harm, r_meas);
        let (nb, sb) = bw.update(intensity[j], a_arr[j], b_arr[j], &harm, r_meas);
        chi2 += nf * nf / sf + nb * nb / sb;
        phase[i] = fw.phi;
        var_f[i] = fw.p00;
        phase_b[j] = bw.phi;
        var_b[j] = bw.p00;
        if i == 0 {
            fw_first = fw;
            bw_first = bw;
        }
    }
    let (fw_last, bw_last) = (fw, bw); // forward at n-1, backward at 0
    let chi2 = chi2 / (2 * n) as f64;

    if __tm {
        eprintln!("TIMING {:>16}: {:?}", "main loop", __t.elapsed());
    }
    // Fusion.
    let edge = (n / 20).max(1);
    let mut max_dis = 0f64;
    for (k, ((p, v), (pb, vb))) in
        phase.iter_mut().zip(var_f.iter_mut()).zip(phase_b.iter().zip(var_b.iter())).enumerate()
    {
        let d = *pb - *p;
        if k >= edge && k + edge < n {
            max_dis = max_dis.max(d.abs());
        }
        let w = *v / (*v + *vb);
        *p += w * d;
        *v *= 1.0 - w;
    }
    if max_dis > 0.5 {
        warnings.push(format!(
            "forward and backward filters disagree by {max_dis:.2} rad inside the trace: \
             possible cycle slip"
        ));
    }

    if __tm {
        eprintln!("TIMING {:>16}: {:?}", "fusion", __t.elapsed());
    }
    // Uncertainty of the total: filter covariance at both ends (inflated by √χ² when the
    // residuals exceed the noise model) and the envelope uncertainty propagated through
    // the filters' sensitivities to a constant error of A and of B.
    let nm_per_rad = 1.0 / kappa;
    let fuse_sens = |pf: f64, pb: f64, sf: f64, sb: f64| (sf * pb + sb * pf) / (pf + pb);
    let sa_0 = fuse_sens(fw_first.p00, bw_last.p00, fw_first.sa0, bw_last.sa0);
    let sb_0 = fuse_sens(fw_first.p00, bw_last.p00, fw_first.sb0, bw_last.sb0);
    let sa_n = fuse_sens(fw_last.p00, bw_first.p00, fw_last.sa0, bw_first.sa0);
    let sb_n = fuse_sens(fw_last.p00, bw_first.p00, fw_last.sb0, bw_first.sb0);
    let (sig_a0, sig_b0) = envelope.sigma_at(path[0], harm_sigma, b_arr[0]);
    let (sig_an, sig_bn) = envelope.sigma_at(path[n - 1], harm_sigma, b_arr[n - 1]);
    let env_var = (sa_0 * sig_a0).powi(2) + (sb_0 * sig_b0).powi(2) + (sa_n * sig_an).powi(2) + (sb_n * sig_bn).powi(2);
    let var0 = var_f[0];
    let filt_var = (var0 + var_f[n - 1]) * chi2.max(1.0);
    let sigma_filter_nm = filt_var.sqrt() * nm_per_rad;
    let sigma_envelope_nm = env_var.sqrt() * nm_per_rad;

    // Outputs: dL(t), per-sample σ.
    let phi_start = phase[0];
    let mut dl = Vec::with_capacity(n);
    let mut sig = Vec::with_capacity(n);
    for (&p, &v) in phase.iter().zip(var_f.iter()) {
        dl.push(phase_to_dl(p - phi_start, kappa, &cfg.gouy));
        sig.push((v + var0).sqrt() * nm_per_rad);
    }
    if __tm {
        eprintln!("TIMING {:>16}: {:?}", "outputs", __t.elapsed());
    }
    let total = dl[n - 1];
    Ok(PhaseTrack {
        phase_rad: phase,
        dl_nm: dl,
        sigma_dl_nm: sig,
        total_dl_nm: total,
        sigma_total_nm: (sigma_filter_nm.powi(2) + sigma_envelope_nm.powi(2)).sqrt(),
        sigma_filter_nm,
        sigma_envelope_nm,
        hint_scale: fw_last.g,
        harmonic: harm,
        noise_sigma: r_meas.sqrt(),
        normalized_chi2: chi2,
        extrema_used: counted,
        max_filter_disagreement_rad: max_dis,
        warnings,
    })
}

// ---------------------------------------------------------------------------------------
// (c) Sign of dL from wavelength sweeps
// ---------------------------------------------------------------------------------------

/// Sign of a move from the absolute gaps measured before and after it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SweepSign {
    /// Gap after minus gap before, nm.
    pub gap_change_nm: f64,
    /// Standard uncertainty of `gap_change_nm`, nm.
    pub sigma_nm: f64,
    /// +1 if the gap grew, -1 if it shrank, 0 if exactly equal.
    pub sign: i8,
    /// |change| / σ.
    pub z_score: f64,
    /// Whether |change| > k·σ.
    pub significant: bool,
}

/// Sign of the gap change between two wavelength-sweep gap estimates (the paper's way of
/// signing extremum counts). The change is significant when it exceeds `k_sigma` standard
/// uncertainties (independent sweeps: σ² = σ_before² + σ_after²).
pub fn sign_from_sweeps(before: &GapEstimate, after: &GapEstimate, k_sigma: f64) -> Result<SweepSign, FringeError> {
    check_positive("k_sigma", k_sigma)?;
    for (name, v) in [("before.gap_um", before.gap_um), ("after.gap_um", after.gap_um)] {
        if !v.is_finite() {
            return Err(FringeError::InvalidParameter { name, value: v, reason: "must be finite" });
        }
    }
    check_non_negative("before.sigma_um", before.sigma_um)?;
    check_non_negative("after.sigma_um", after.sigma_um)?;
    let change = (after.gap_um - before.gap_um) * 1e3;
    let sigma = (before.sigma_um.powi(2) + after.sigma_um.powi(2)).sqrt() * 1e3;
    let z = if sigma > 0.0 {
        change.abs() / sigma
    } else if change != 0.0 {
        f64::INFINITY
    } else {
        0.0
    };
    Ok(SweepSign {
        gap_change_nm: change,
        sigma_nm: sigma,
        sign: if change > 0.0 {
            1
        } else if change < 0.0 {
            -1
        } else {
            0
        },
        z_score: z,
        significant: z > k_sigma,
    })
}

// ---------------------------------------------------------------------------------------
// Local two-beam signal model (tests, benchmarks, demos)
// ---------------------------------------------------------------------------------------

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
    use rand::rngs::StdRng;
    use rand::SeedableRng;

    const WL: f64 = 1560.0;
    const N_AIR: f64 = 1.000_268;
    const GAP0: f64 = 900_000.0;
    const ZR: f64 = 54_000.0;

    fn step_nm() -> f64 {
        WL / (4.0 * N_AIR)
    }

    /// Velocity-limited move from `from` to `to` (any unit): raised-cosine ramps of `ramp`
    /// samples, cruise at `v` units/sample.
    fn move_segment(from: f64, to: f64, v: f64, ramp: usize) -> Vec<f64> {
        let dist = (to - from).abs();
        let sgn = (to - from).signum();
        let r = ramp as f64;
        let (v_eff, cruise) =
            if v * r >= dist { (dist / r, 0usize) } else { (v, ((dist - v * r) / v).round() as usize) };
        let mut vel = Vec::new();
        for i in 0..ramp {
            vel.push(v_eff * 0.5 * (1.0 - (PI * (i as f64 + 0.5) / r).cos()));
        }
        vel.extend(std::iter::repeat_n(v_eff, cruise));
        for i in 0..ramp {
            vel.push(v_eff * 0.5 * (1.0 + (PI * (i as f64 + 0.5) / r).cos()));
        }
        let sum: f64 = vel.iter().sum();
        let mut p = 0.0;
        vel.iter()
            .map(|dv| {
                p += dv * dist / sum;
                from + sgn * p
            })
            .collect()
    }

    fn pause(at: f64, n: usize) -> Vec<f64> {
        vec![at; n]
    }

    /// A synthetic trace: truth dL, envelope, signal, hint.
    struct Trace {
        dl: Vec<f64>,
        intensity: Vec<f64>,
        hint: Vec<f64>,
        signal: TwoBeamSignal,
    }

    /// Envelope as a function of the joint position normalised to its range (geometry):
    /// A(p), B(p).
    struct Drift {
        a: fn(f64) -> f64,
        b: fn(f64) -> f64,
    }

    /// `joint`: joint coordinate per sample; `dl_of`: dL (nm) as a function of it;
    /// the envelope depends on where the robot is (the joint), not on time.
    fn make_trace(
        joint: &[f64],
        dl_of: &dyn Fn(f64) -> f64,
        drift: &Drift,
        noise_rel: f64,
        phase_offset: f64,
        seed: u64,
    ) -> Trace {
        let jmin = joint.iter().cloned().fold(f64::INFINITY, f64::min);
        let jmax = joint.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
        let prog: Vec<f64> = joint.iter().map(|&q| (q - jmin) / (jmax - jmin)).collect();
        let dl: Vec<f64> = joint.iter().map(|&q| dl_of(q)).collect();
        let dl0 = dl[0];
        let dl: Vec<f64> = dl.iter().map(|d| d - dl0).collect();
        let a: Vec<f64> = prog.iter().map(|&p| (drift.a)(p)).collect();
        let b: Vec<f64> = prog.iter().map(|&p| (drift.b)(p)).collect();
        let bmax = b.iter().cloned().fold(0.0, f64::max);
        let signal = TwoBeamSignal {
            wavelength_nm: WL,
            n_air: N_AIR,
            gap_start_nm: GAP0,
            rayleigh_range_nm: Some(ZR),
            phase_offset_rad: phase_offset,
            harmonic_rel: 0.02,
            harmonic_phase_rad: 0.6,
            noise_sigma: noise_rel * bmax,
        };
        let mut rng = StdRng::seed_from_u64(seed);
        let intensity = signal.render(&dl, &a, &b, &mut rng).unwrap();
        let hint = dl.iter().map(|d| 1.03 * d + 37.0).collect();
        Trace { dl, intensity, hint, signal }
    }

    /// A few % of drift over a short move (coupling changes with gap and tilt).
    fn mild() -> Drift {
        Drift { a: |p| 1.0 - 0.05 * p, b: |p| 0.2 * (1.0 - 0.1 * p) }
    }

    /// Strategy-1 type: 300 µm lateral move, dL = 8e-3 of it (2.4 µm), pauses at both ends.
    fn lateral(noise: f64, phase: f64, seed: u64) -> Trace {
        let mut q = pause(0.0, 150);
        q.extend(move_segment(0.0, 300_000.0, 1000.0, 60));
        q.extend(pause(300_000.0, 150));
        make_trace(&q, &|x| 0.008 * x, &mild(), noise, phase, seed)
    }

    /// 20 µm axial move at ~31 samples per fringe, A and B drifting ×3 in opposite ways.
    fn axial(noise: f64, phase: f64, seed: u64) -> Trace {
        let mut q = pause(0.0, 100);
        q.extend(move_segment(0.0, 20_000.0, 25.0, 40));
        q.extend(pause(20_000.0, 100));
        // A falls ×3 while B rises ×3 over the move
        let drift = Drift { a: |p| 1.5 - p, b: |p| 0.1 * 3f64.powf(p) };
        make_trace(&q, &|x| x, &drift, noise, phase, seed)
    }

    /// Rotation-type: θ from -70 to +70 mrad at constant speed, dL = -a(θ - 5)²: up 3 µm,
    /// turning point in the middle of the motion, then down 2.25 µm.
    fn rotation(noise: f64, phase: f64, seed: u64) -> Trace {
        let mut q = pause(-70.0, 120);
        q.extend(move_segment(-70.0, 70.0, 0.25, 30));
        q.extend(pause(70.0, 120));
        let a = 3000.0 / 75.0f64.powi(2);
        // coupling peaks when the lamella is square to the beam (mid-rotation)
        let drift =
            Drift { a: |p| 1.0 - 0.2 * (2.0 * p - 1.0).powi(2), b: |p| 0.2 * (1.0 - 0.3 * (2.0 * p - 1.0).powi(2)) };
        make_trace(&q, &|t| -a * (t - 5.0).powi(2), &drift, noise, phase, seed)
    }

    /// Stop-and-reverse: +4 µm, stop, -2.5 µm. `turn_phase`: fringe phase at the turn.
    fn reversal(noise: f64, turn_phase: f64, seed: u64) -> Trace {
        let mut q = pause(0.0, 100);
        q.extend(move_segment(0.0, 4000.0, 20.0, 40));
        q.extend(pause(4000.0, 100));
        q.extend(move_segment(4000.0, 1500.0, 20.0, 40));
        q.extend(pause(1500.0, 100));
        // choose φ₀ so that φ(4000 nm) = turn_phase
        let probe = TwoBeamSignal {
            wavelength_nm: WL,
            n_air: N_AIR,
            gap_start_nm: GAP0,
            rayleigh_range_nm: Some(ZR),
            phase_offset_rad: 0.0,
            harmonic_rel: 0.0,
            harmonic_phase_rad: 0.0,
            noise_sigma: 0.0,
        };
        let phase = turn_phase - probe.phase_rad(4000.0);
        make_trace(&q, &|x| x, &mild(), noise, phase, seed)
    }

    struct Score {
        rms_nm: f64,
        max_nm: f64,
        total_err_nm: f64,
        sigma_nm: f64,
    }

    fn score(t: &Trace, cfg: &TrackConfig) -> Score {
        let tr = track_phase(&t.intensity, &t.hint, WL, N_AIR, cfg).unwrap();
        let n = t.dl.len();
        let errs: Vec<f64> = (0..n).map(|k| tr.dl_nm[k] - t.dl[k]).collect();
        let rms = (errs.iter().map(|e| e * e).sum::<f64>() / n as f64).sqrt();
        let max = errs.iter().fold(0f64, |m, e| m.max(e.abs()));
        Score { rms_nm: rms, max_nm: max, total_err_nm: errs[n - 1], sigma_nm: tr.sigma_total_nm }
    }

    fn gouy_cfg(t: &Trace) -> TrackConfig {
        TrackConfig {
            gouy: Some(GouyCorrection { rayleigh_range_nm: ZR, gap_at_start_nm: t.signal.gap_start_nm, gap_sign: 1.0 }),
            ..TrackConfig::default()
        }
    }

    fn check_scenario(name: &str, make: &dyn Fn(u64) -> Trace, seeds: std::ops::Range<u64>) {
        let mut worst = 0f64;
        for seed in seeds {
            let t = make(seed);
            let s = score(&t, &gouy_cfg(&t));
            eprintln!(
                "{name} seed {seed}: rms {:.3} nm, max {:.3} nm, total err {:.3} nm, σ {:.3} nm, true dL {:.1} nm",
                s.rms_nm,
                s.max_nm,
                s.total_err_nm,
                s.sigma_nm,
                t.dl[t.dl.len() - 1]
            );
            worst = worst.max(s.rms_nm);
            assert!(s.rms_nm < 5.0, "{name} seed {seed}: rms {} nm", s.rms_nm);
            // counting within one λ/4 step, hint-signed
            let c = count_extrema(&t.intensity, CountDirection::Hint(&t.hint), WL, N_AIR, &HysteresisConfig::default())
                .unwrap();
            let truth = t.dl[t.dl.len() - 1];
            assert!(
                (c.dl_nm - truth).abs() <= step_nm(),
                "{name} seed {seed}: count {} → {} nm vs {truth} nm",
                c.count,
                c.dl_nm
            );
        }
        eprintln!("{name}: worst rms {worst:.3} nm");
    }

    #[test]
    fn fast_sincos_matches_std() {
        let mut worst = 0f64;
        for i in 0..200_000 {
            let x = -3.0e5 + i as f64 * 3.000_07;
            let (s, c) = sincos(x);
            let (s0, c0) = x.sin_cos();
            worst = worst.max((s - s0).abs()).max((c - c0).abs());
        }
        assert!(worst < 1e-12, "worst {worst}");
        for x in [0.0, 1e-3, -PI / 4.0, PI / 4.0, PI, -PI, 2.5, 1e4] {
            let (s, c) = sincos(x);
            assert!((s - x.sin()).abs() < 1e-15 && (c - x.cos()).abs() < 1e-15, "{x}");
        }
    }

    #[test]
    fn lateral_move_tracks_within_5nm_rms() {
        check_scenario("lateral", &|s| lateral(1e-3, 0.3 + s as f64 * 1.7, s), 0..4);
    }

    #[test]
    fn axial_20um_move_with_3x_envelope_drift_tracks_within_5nm_rms() {
        check_scenario("axial", &|s| axial(1e-3, 1.1 + s as f64 * 2.3, s), 10..14);
    }

    #[test]
    fn rotation_with_mid_move_turning_point_tracks_within_5nm_rms() {
        check_scenario("rotation", &|s| rotation(1e-3, s as f64 * 0.9, s), 20..26);
    }

    #[test]
    fn stop_and_reverse_tracks_within_5nm_rms_even_turning_on_a_fringe_extremum() {
        // turn at a maximum, a minimum, mid-fringe and just past a maximum
        let phases = [0.0, PI, 1.3, 0.15];
        check_scenario("reversal", &|s| reversal(1e-3, phases[(s - 30) as usize % 4], s), 30..34);
    }

    #[test]
    fn counting_with_a_given_sign_is_within_one_step_on_monotonic_moves() {
        for (t, sign) in [(lateral(1e-3, 0.4, 1), MoveSign::Increasing), (axial(1e-3, 2.0, 2), MoveSign::Increasing)] {
            let c = count_extrema(&t.intensity, CountDirection::Given(sign), WL, N_AIR, &HysteresisConfig::default())
                .unwrap();
            let truth = t.dl[t.dl.len() - 1];
            assert!((c.dl_nm - truth).abs() <= step_nm(), "{} vs {truth}", c.dl_nm);
            assert_eq!(c.resolution_nm, step_nm());
        }
        // a decreasing move with the sign given
        let mut t = axial(1e-3, 0.7, 3);
        t.intensity.reverse();
        let c = count_extrema(
            &t.intensity,
            CountDirection::Given(MoveSign::Decreasing),
            WL,
            N_AIR,
            &HysteresisConfig::default(),
        )
        .unwrap();
        let truth = -t.dl[t.dl.len() - 1];
        assert!((c.dl_nm - truth).abs() <= step_nm(), "{} vs {truth}", c.dl_nm);
    }

    #[test]
    fn harmonic_is_estimated() {
        let t = axial(1e-3, 0.5, 7);
        let tr = track_phase(&t.intensity, &t.hint, WL, N_AIR, &TrackConfig::default()).unwrap();
        // synthetic: h·cos(2φ + ψ) = h cos ψ·cos 2φ - h sin ψ·sin 2φ
        let hc = 0.02 * 0.6f64.cos();
        let hs = -0.02 * 0.6f64.sin();
        eprintln!("harmonic {:?} vs ({hc}, {hs})", tr.harmonic);
        assert!((tr.harmonic.cos_rel - hc).abs() < 2e-3);
        assert!((tr.harmonic.sin_rel - hs).abs() < 2e-3);
        assert!((tr.hint_scale - 1.0 / 1.03).abs() < 1e-3, "scale {}", tr.hint_scale);
    }

    #[test]
    fn reported_uncertainty_covers_the_error_at_1e_2_noise() {
        let mut worst_z = 0f64;
        for seed in 0..8u64 {
            for (name, t) in [
                ("lateral", lateral(1e-2, 0.2 + seed as f64 * 0.77, 100 + seed)),
                ("axial", axial(1e-2, 0.9 + seed as f64 * 1.3, 200 + seed)),
                ("reversal", reversal(1e-2, seed as f64 * 0.8, 300 + seed)),
            ] {
                let s = score(&t, &gouy_cfg(&t));
                let z = s.total_err_nm.abs() / s.sigma_nm;
                worst_z = worst_z.max(z);
                eprintln!(
                    "{name} seed {seed}: total err {:.3} nm, σ {:.3} nm, z {z:.2}, rms {:.3} nm",
                    s.total_err_nm, s.sigma_nm, s.rms_nm
                );
                assert!(z < 3.0, "{name} seed {seed}: err {} σ {}", s.total_err_nm, s.sigma_nm);
                assert!(s.sigma_nm < 10.0, "σ implausibly large: {}", s.sigma_nm);
            }
        }
        eprintln!("worst |err|/σ = {worst_z:.2}");
    }

    #[test]
    fn short_move_needs_a_known_envelope() {
        // 300 nm of dL (< one fringe), constant envelope
        let mut q = pause(0.0, 100);
        q.extend(move_segment(0.0, 300.0, 8.0, 20));
        q.extend(pause(300.0, 100));
        let drift = Drift { a: |_| 1.0, b: |_| 0.2 };
        for (seed, phase) in [(1u64, 0.8), (2, 2.4), (3, 4.0)] {
            let t = make_trace(&q, &|x| x, &drift, 1e-3, phase, seed);
            let err = track_phase(&t.intensity, &t.hint, WL, N_AIR, &TrackConfig::default());
            assert!(matches!(err, Err(FringeError::TooFewFringes { .. }) | Err(FringeError::NoMotion)), "{err:?}");
            // known envelope, 0.3 % off, harmonic known
            let cfg = TrackConfig {
                envelope: EnvelopeSource::Known(KnownEnvelope {
                    offset: 1.0 + 0.0006,
                    amplitude: 0.2 * 0.997,
                    harmonic: Harmonic { cos_rel: 0.02 * 0.6f64.cos(), sin_rel: -0.02 * 0.6f64.sin() },
                }),
                ..gouy_cfg(&t)
            };
            let s = score(&t, &cfg);
            eprintln!(
                "short seed {seed}: rms {:.3} nm, total err {:.3} nm σ {:.3}",
                s.rms_nm, s.total_err_nm, s.sigma_nm
            );
            assert!(s.rms_nm < 5.0);
        }
    }

    #[test]
    fn bad_input_is_an_error_not_a_panic() {
        let cfg = TrackConfig::default();
        assert_eq!(track_phase(&[], &[], WL, N_AIR, &cfg).unwrap_err(), FringeError::EmptyTrace);
        assert!(matches!(track_phase(&[1.0, 2.0], &[0.0], WL, N_AIR, &cfg), Err(FringeError::LengthMismatch { .. })));
        assert!(matches!(
            track_phase(&[1.0, f64::NAN], &[0.0, 1.0], WL, N_AIR, &cfg),
            Err(FringeError::NonFinite { index: 1, .. })
        ));
        assert!(matches!(
            track_phase(&[1.0, 2.0], &[0.0, 1.0], -1.0, N_AIR, &cfg),
            Err(FringeError::InvalidParameter { .. })
        ));
        assert_eq!(
            track_phase(&[1.0, 2.0, 3.0], &[5.0, 5.0, 5.0], WL, N_AIR, &cfg).unwrap_err(),
            FringeError::NoMotion
        );
        assert!(matches!(
            count_extrema(&[], CountDirection::Given(MoveSign::Increasing), WL, N_AIR, &HysteresisConfig::default()),
            Err(FringeError::EmptyTrace)
        ));
        assert!(matches!(
            count_extrema(&[1.0, 2.0], CountDirection::Hint(&[0.0]), WL, N_AIR, &HysteresisConfig::default()),
            Err(FringeError::LengthMismatch { .. })
        ));
        let bad_cfg = TrackConfig { scale_prior_sigma: -1.0, ..TrackConfig::default() };
        assert!(matches!(
            track_phase(&[1.0, 2.0], &[0.0, 1.0], WL, N_AIR, &bad_cfg),
            Err(FringeError::InvalidParameter { .. })
        ));
    }

    #[test]
    fn sign_from_sweeps_is_significant_only_beyond_k_sigma() {
        use crate::sweep::GapMethod;
        let g = |gap_um: f64, sigma_um: f64| GapEstimate {
            method: GapMethod::ModelFit,
            gap_um,
            sigma_um,
            fringes_across_sweep: 10.0,
            fit_rms: 0.0,
        };
        let s = sign_from_sweeps(&g(900.0, 0.01), &g(900.2, 0.01), 3.0).unwrap();
        assert_eq!(s.sign, 1);
        assert!(s.significant);
        assert!((s.gap_change_nm - 200.0).abs() < 1e-6);
        let s = sign_from_sweeps(&g(900.0, 0.01), &g(899.98, 0.01), 3.0).unwrap();
        assert_eq!(s.sign, -1);
        assert!(!s.significant);
        assert!(sign_from_sweeps(&g(f64::NAN, 0.01), &g(1.0, 0.01), 3.0).is_err());
        assert!(sign_from_sweeps(&g(1.0, -0.01), &g(1.0, 0.01), 3.0).is_err());
    }

    #[test]
    fn debug_dump() {
        let which = std::env::var("DBG").unwrap_or_default();
        if which.is_empty() {
            return;
        }
        let seed: u64 = std::env::var("SEED").ok().and_then(|s| s.parse().ok()).unwrap_or(12);
        let noise: f64 = std::env::var("NOISE").ok().and_then(|s| s.parse().ok()).unwrap_or(1e-3);
        let t = match which.as_str() {
            "axial" => axial(noise, 1.1 + seed as f64 * 2.3, seed),
            "lateral" => lateral(noise, 0.3 + seed as f64 * 1.7, seed),
            "rotation" => rotation(noise, seed as f64 * 0.9, seed),
            _ => reversal(noise, [0.0, PI, 1.3, 0.15][(seed as usize + 2) % 4], seed),
        };
        let phase: Vec<f64> = t.dl.iter().map(|d| t.signal.phase_rad(*d)).collect();
        let mut ex = detect_extrema(&t.intensity, &HysteresisConfig::default()).unwrap();
        classify_with_hint(&mut ex, &t.hint, 0.005 * WL / (2.0 * N_AIR));
        for e in &ex {
            eprintln!(
                "ext {:5} {:?} val {:.4} dir {} truephase/pi {:.3}",
                e.index,
                e.kind,
                e.value,
                e.direction,
                phase[e.index] / PI
            );
        }
        eprintln!("phase/pi start {:.3} end {:.3}", phase[0] / PI, phase[phase.len() - 1] / PI);
        let tr = track_phase(&t.intensity, &t.hint, WL, N_AIR, &gouy_cfg(&t)).unwrap();
        eprintln!(
            "harm {:?} noise {} chi2 {} g {} warn {:?} sf {} se {} dis {}",
            tr.harmonic,
            tr.noise_sigma,
            tr.normalized_chi2,
            tr.hint_scale,
            tr.warnings,
            tr.sigma_filter_nm,
            tr.sigma_envelope_nm,
            tr.max_filter_disagreement_rad
        );
        let off = tr.phase_rad[0] - phase[0];
        let step = (t.dl.len() / 60).max(1);
        for k in (0..t.dl.len()).step_by(step) {
            eprintln!(
                "k {:5} dl {:9.2} err {:7.3} phase_err {:7.4} sig {:.3}",
                k,
                t.dl[k],
                tr.dl_nm[k] - t.dl[k],
                tr.phase_rad[k] - phase[k] - off,
                tr.sigma_dl_nm[k]
            );
        }
    }
}
