//! Extremum detection and counting (the paper's λ/4 method): a zigzag detector with an
//! adaptive hysteresis, each extremum signed by the move's direction or by the motion hint.

use super::signal::{check_finite, check_optics, check_positive, FringeError};

/// Robust white-noise estimate from third differences (MAD, subsampled to at most 64 k
/// points). Over-estimates the noise when the fringes are sampled coarsely, which only
/// makes the extremum detector more conservative.
pub(crate) fn estimate_noise_sigma(y: &[f64], scratch: &mut Vec<f64>) -> f64 {
    if y.len() < 8 {
        return 0.0;
    }
    let m = y.len() - 3;
    let stride = m.div_ceil(65_536).max(1);
    scratch.clear();
    scratch.extend((0..m).step_by(stride).map(|k| (y[k + 3] - 3.0 * y[k + 2] + 3.0 * y[k + 1] - y[k]).abs()));
    let mid = scratch.len() / 2;
    let (_, med, _) = scratch.select_nth_unstable_by(mid, f64::total_cmp);
    // Var of a third difference of white noise: 20 σ².
    1.4826 * *med / 20f64.sqrt()
}

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
    pub(crate) fn validate(&self) -> Result<(), FringeError> {
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
    let mut out = Vec::new();
    extrema_into(signal, cfg, &mut Vec::new(), &mut out);
    Ok(out)
}

/// `detect_extrema` on a validated, non-empty signal, into reused buffers.
fn extrema_into(signal: &[f64], cfg: &HysteresisConfig, scratch: &mut Vec<f64>, out: &mut Vec<Extremum>) {
    let max_abs = signal.iter().fold(0f64, |m, v| m.max(v.abs()));
    extrema_into_scaled(signal, max_abs, cfg, scratch, out);
}

/// [`extrema_into`] with the signal's largest magnitude already known.
pub(crate) fn extrema_into_scaled(
    signal: &[f64],
    max_abs: f64,
    cfg: &HysteresisConfig,
    scratch: &mut Vec<f64>,
    out: &mut Vec<Extremum>,
) {
    let sigma = estimate_noise_sigma(signal, scratch);
    let scale = max_abs.max(f64::MIN_POSITIVE);
    let floor = (cfg.noise_floor_factor * sigma).max(1e-12 * scale);
    out.clear();
    zigzag(signal, floor, cfg.relative, out);
}

fn zigzag(y: &[f64], floor: f64, rel: f64, out: &mut Vec<Extremum>) {
    fn push(out: &mut Vec<Extremum>, index: usize, max: bool, value: f64) {
        out.push(Extremum { index, kind: if max { ExtremumKind::Max } else { ExtremumKind::Min }, value, direction: 0 })
    }
    let n = y.len();
    // Start: track the running max and min until the signal has swung by the noise floor.
    // An extremum there counts only if the signal also moved by the floor before it.
    let (mut hi, mut hi_i, mut lo, mut lo_i) = (y[0], 0usize, y[0], 0usize);
    let (mut hi_rise_ok, mut lo_fall_ok) = (false, false);
    let mut k = 0usize;
    // sgn = +1 while seeking a maximum, -1 while seeking a minimum (work on sgn·y)
    let (mut sgn, mut cand_i, mut last);
    loop {
        if k >= n {
            return;
        }
        let v = y[k];
        if v > hi {
            hi = v;
            hi_i = k;
            hi_rise_ok = hi - lo >= floor;
        }
        if v < lo {
            lo = v;
            lo_i = k;
            lo_fall_ok = hi - lo >= floor;
        }
        if v <= hi - floor && hi_i < k {
            if hi_rise_ok {
                push(out, hi_i, true, hi);
            }
            last = hi;
            sgn = -1.0;
            cand_i = k;
            break;
        }
        if v >= lo + floor && lo_i < k {
            if lo_fall_ok {
                push(out, lo_i, false, lo);
            }
            last = lo;
            sgn = 1.0;
            cand_i = k;
            break;
        }
        k += 1;
    }
    // Alternating search with a hysteresis that follows the recent swings.
    let mut cs = sgn * y[cand_i];
    let mut swings = [0.0f64; 4];
    let mut sw_i = 0usize;
    let mut h = floor;
    for (kk, &yv) in y.iter().enumerate().skip(cand_i + 1) {
        let v = sgn * yv;
        if v > cs {
            cs = v;
            cand_i = kk;
        } else if v <= cs - h {
            let value = y[cand_i];
            push(out, cand_i, sgn > 0.0, value);
            swings[sw_i % 4] = (value - last).abs();
            sw_i += 1;
            h = floor.max(rel * swings.iter().fold(0f64, |m, &s| m.max(s)));
            last = value;
            sgn = -sgn;
            cs = sgn * yv;
            cand_i = kk;
        }
    }
    // At the end of the trace the last candidate cannot be followed by a full hysteresis
    // swing: confirm it when the signal moved away from it by more than the noise floor.
    let away = y[cand_i..].iter().fold(f64::INFINITY, |m, &v| m.min(sgn * v));
    if cs - away >= floor {
        push(out, cand_i, sgn > 0.0, y[cand_i]);
    }
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

/// The λ/(4n) step an extremum stands for, from the hint's direction before and after it: the
/// phase goes through a fringe extremum only while the gap moves on both sides of it in the
/// same direction. Where the motion turns (opposite signs) it is a turning point; where the
/// hint stands still on one side, the intensity's swing there is not the motion's (noise, the
/// envelope, a gap the model misses by a few nm): counted, such a bump becomes a level of the
/// envelope and biases the phase by tens of nm on a motion whose gap hardly moves (test
/// `validate::tests::a_validation_circle_tracks_its_small_gap_change`).
fn fringe_direction(before: i8, after: i8) -> i8 {
    if before * after <= 0 {
        0
    } else {
        before
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
        extrema[j].direction = fringe_direction(before, after);
    }
}

/// `classify_with_hint` with the hint already read at each extremum (`ext_hint`, aligned
/// with `extrema`) and at the trace ends.
pub(crate) fn classify_recorded(extrema: &mut [Extremum], ext_hint: &[f64], first: f64, last: f64, tol_nm: f64) {
    let m = extrema.len();
    for j in 0..m {
        let hp = if j > 0 { ext_hint[j - 1] } else { first };
        let hn = if j + 1 < m { ext_hint[j + 1] } else { last };
        let before = sign_tol(ext_hint[j] - hp, tol_nm);
        let after = sign_tol(hn - ext_hint[j], tol_nm);
        extrema[j].direction = fringe_direction(before, after);
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
