//! Local least-squares fits over windows of the motion: the fringe harmonics and the white
//! noise along the path, and the phase at the start when the extrema cannot give it.

use super::config::{EnvelopeSource, TrackConfig};
use super::envelope::{Envelope, MAX_EXTRAP};
use super::grid::PathView;
use super::harmonic::{Harmonic, HarmonicProfile};
use super::inputs::TrackScale;
use crate::measure::extrema::estimate_noise_sigma;
use crate::measure::signal::sincos;
use nalgebra::{SMatrix, SVector};
use std::f64::consts::TAU;

/// At most `max_pts` evenly strided samples of a window, with the envelope evaluated there.
pub(super) struct WindowData {
    pub(super) y: Vec<f64>,
    pub(super) hint: Vec<f64>,
    pub(super) a: Vec<f64>,
    pub(super) b: Vec<f64>,
}

#[allow(clippy::too_many_arguments)]
pub(super) fn window_data(
    path: &PathView,
    y: &[f64],
    hint: &[f64],
    envelope: &Envelope,
    harm: &HarmonicProfile,
    max_extrap: f64,
    (w0, w1): (usize, usize),
    max_pts: usize,
) -> WindowData {
    let stride = (w1 - w0).div_ceil(max_pts).max(1);
    let idx = (w0..w1).step_by(stride);
    let s: Vec<f64> = idx.clone().map(|k| path.at(k)).collect();
    let c: Vec<f64> = idx.clone().map(|k| path.envelope_at(k)).collect();
    let (a, b) = envelope.eval(&c, &s, harm, max_extrap);
    WindowData { y: idx.clone().map(|k| y[k]).collect(), hint: idx.map(|k| hint[k]).collect(), a, b }
}

/// Result of a local harmonic fit.
pub(super) struct WindowFit {
    pub(super) harm: Harmonic,
    pub(super) sigma: f64,
    pub(super) rss_raw: f64,
    pub(super) dof: f64,
}

/// Number of regressors of a window fit.
pub(super) const WINDOW_P: usize = 12;

/// Regressors of a window fit at phase offset Δ and centred, normalised position u ∈ [-1, 1]:
/// 1, cos Δ, sin Δ, cos 2Δ, sin 2Δ, cos 3Δ, sin 3Δ, then u, u·cos Δ, u·sin Δ, u·cos 2Δ,
/// u·sin 2Δ. The u terms absorb a linear trend of the envelope, of the fundamental's
/// amplitude and phase (a hint-scale error) and of the 2nd harmonic across the window.
#[inline]
pub(super) fn window_regressors(delta: f64, u: f64) -> SVector<f64, WINDOW_P> {
    let (s, c) = sincos(delta);
    let (c2, s2) = (2.0 * c * c - 1.0, 2.0 * s * c);
    SVector::<f64, WINDOW_P>::from([
        1.0,
        c,
        s,
        c2,
        s2,
        c * c2 - s * s2,
        s * c2 + c * s2,
        u,
        u * c,
        u * s,
        u * c2,
        u * s2,
    ])
}

/// Least-squares estimate of the 2nd and 3rd harmonics at the centre of a window, from the
/// envelope-normalised signal y' = (I - A0)/B0 fitted by [`window_regressors`] with
/// Δ = g·κ·(hint - hint₀). `a`, `b`: initial envelope over the window's samples.
///
/// The fit is linear. Without the trend terms, a hint-scale error ε biases the harmonics by
/// about ε·(phase span of the window) (a 0.06 % scale error over two fringes: 4e-4, 2.5 % of a
/// 2.8 % harmonic), which the smoother then folds into envelope swings and nm of phase error.
pub(super) fn window_harmonic(
    y: &[f64],
    hint: &[f64],
    a: &[f64],
    b: &[f64],
    rad_per_hint_nm: f64,
) -> Option<WindowFit> {
    const P: usize = WINDOW_P;
    let m = y.len();
    if m < 40 {
        return None;
    }
    let stride = m.div_ceil(8192).max(1);
    let h0 = hint[0];
    let (lo, hi) = (0..m)
        .step_by(stride)
        .map(|i| hint[i])
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| (l.min(v), h.max(v)));
    let mid = 0.5 * (lo + hi);
    let half = 0.5 * (hi - lo);
    if half.is_nan() || half <= 0.0 {
        return None;
    }
    let pos = |i: usize| (hint[i] - mid) / half;
    let mut ata = SMatrix::<f64, P, P>::zeros();
    let mut aty = SVector::<f64, P>::zeros();
    let mut cnt = 0usize;
    for i in (0..m).step_by(stride) {
        let x = window_regressors(rad_per_hint_nm * (hint[i] - h0), pos(i));
        let yn = (y[i] - a[i]) / b[i];
        ata += x * x.transpose();
        aty += x * yn;
        cnt += 1;
    }
    if cnt < 40 {
        return None;
    }
    let eig = ata.symmetric_eigen();
    let (emin, emax) = eig.eigenvalues.iter().fold((f64::INFINITY, 0f64), |(lo, hi), &e| (lo.min(e), hi.max(e)));
    if emin < 0.01 * emax {
        return None;
    }
    let inv = ata.try_inverse()?;
    let p = inv * aty;
    // the fundamental at the window centre (u = 0)
    let b1 = (p[1] * p[1] + p[2] * p[2]).sqrt();
    if b1 < 0.3 {
        return None;
    }
    let theta = (-p[2]).atan2(p[1]);
    // (h_c - i h_s) = (d - i e)·e^{-ikθ}/B1 for harmonic k
    let rotate = |k: f64, d: f64, e: f64| {
        let (skt, ckt) = (k * theta).sin_cos();
        let re = (d * ckt - e * skt) / b1;
        let im = (-e * ckt - d * skt) / b1;
        (re, -im)
    };
    let (c2, s2) = rotate(2.0, p[3], p[4]);
    let (c3, s3) = rotate(3.0, p[5], p[6]);
    let mut rss = 0.0;
    let mut rss_raw = 0.0;
    for i in (0..m).step_by(stride) {
        let x = window_regressors(rad_per_hint_nm * (hint[i] - h0), pos(i));
        let r = (y[i] - a[i]) / b[i] - p.dot(&x);
        rss += r * r;
        rss_raw += (r * b[i]).powi(2);
    }
    let dof = (cnt as f64 - P as f64).max(1.0);
    // σ of one harmonic coefficient (the four are about equally well determined)
    let sigma = (rss / dof * 0.25 * (inv[(3, 3)] + inv[(4, 4)] + inv[(5, 5)] + inv[(6, 6)])).sqrt() / b1;
    Some(WindowFit { harm: Harmonic { cos_rel: c2, sin_rel: s2, cos3_rel: c3, sin3_rel: s3 }, sigma, rss_raw, dof })
}

/// Most interior windows of the harmonic profile.
pub(super) const MAX_HARMONIC_WINDOWS: usize = 30;

/// Standard uncertainty of one harmonic coefficient of the profile at a trace end: the
/// statistical σ of the end windows, or how badly the profile interpolates (leave-one-out
/// over the interior windows: each predicted from its neighbours), whichever is larger.
/// With two windows only, half their difference stands for the variation between them.
pub(super) fn harmonic_profile_sigma(fits: &[(f64, WindowFit)]) -> f64 {
    let m = fits.len();
    let stat =
        if m == 1 { fits[0].1.sigma } else { ((fits[0].1.sigma.powi(2) + fits[m - 1].1.sigma.powi(2)) / 2.0).sqrt() };
    let dist = |a: &Harmonic, b: &Harmonic| {
        (a.coefficients().iter().zip(b.coefficients()).map(|(x, y)| (x - y).powi(2)).sum::<f64>() / 4.0).sqrt()
    };
    let model = match m {
        0 | 1 => 0.0,
        2 => 0.5 * dist(&fits[0].1.harm, &fits[1].1.harm),
        _ => {
            let mut sq = 0.0;
            for i in 1..m - 1 {
                let (s0, s1, s) = (fits[i - 1].0, fits[i + 1].0, fits[i].0);
                let t = if s1 > s0 { ((s - s0) / (s1 - s0)).clamp(0.0, 1.0) } else { 0.5 };
                let p = HarmonicProfile::new(vec![(0.0, fits[i - 1].1.harm), (1.0, fits[i + 1].1.harm)]);
                let pred = p.at(t, &mut 0);
                // the prediction error has the variance of the window and of its interpolation
                sq += dist(&fits[i].1.harm, &pred).powi(2) / 1.5;
            }
            (sq / (m - 2) as f64).sqrt()
        }
    };
    stat.max(model)
}

/// Phase at the first sample of a window, by a grid search then Gauss-Newton on θ in the
/// model I = A + B·f(θ + κ·(hint - hint₀)) (hint scale 1). Returns (θ, RSS, samples).
pub(super) fn anchor_phase(
    y: &[f64],
    hint: &[f64],
    a: &[f64],
    b: &[f64],
    harm: &Harmonic,
    kappa: f64,
) -> (f64, f64, usize) {
    let m = y.len();
    let stride = m.div_ceil(4096).max(1);
    let h0 = hint[0];
    let pts: Vec<(f64, f64, f64, f64)> =
        (0..m).step_by(stride).map(|i| (kappa * (hint[i] - h0), y[i], a[i], b[i])).collect();
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
    let (mut theta, mut cur) = best;
    for _ in 0..20 {
        let (mut jr, mut jj) = (0.0, 0.0);
        for &(d, yy, aa, bb) in &pts {
            let (s, c) = sincos(d + theta);
            let (f, fp) = harm.f_and_slope(s, c);
            let jac = -bb * fp;
            jr += jac * (yy - aa - bb * f);
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

/// Start and end windows of the motion ([`super::grid::motion_windows`], two fringes wide).
pub(super) type MotionWindows = ((usize, usize), (usize, usize));

/// Harmonics and white noise from local fits: windows of two fringes at the start, at the
/// end and every two fringes or so in between. Returns the harmonic profile, the standard
/// uncertainty of one of its coefficients and the noise variance of the fits (None without
/// fits). A fringe model's shape replaces the profile (the initial envelope then ignores
/// harmonics); a known envelope brings its own harmonic.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(super) fn fit_harmonics(
    cfg: &TrackConfig,
    shaped: bool,
    path: &PathView,
    intensity: &[f64],
    hint_dl_nm: &[f64],
    envelope: &Envelope,
    windows: MotionWindows,
    rad_per_hint_nm: f64,
    scale: &TrackScale,
    scratch: &mut Vec<f64>,
    warnings: &mut Vec<String>,
) -> (HarmonicProfile, f64, Option<f64>) {
    match cfg.envelope {
        _ if shaped => (HarmonicProfile::default(), 0.0, None),
        EnvelopeSource::Known(k) => (HarmonicProfile::constant(k.harmonic), 0.0, None),
        EnvelopeSource::FromData => {
            let wins = harmonic_windows(cfg, path, intensity, windows, scale, scratch);
            // about 16 k samples over all windows (at least 256 a window)
            let max_pts = (16_384 / wins.len()).clamp(256, 4096);
            let none = HarmonicProfile::default();
            let fits: Vec<(f64, WindowFit)> = wins
                .iter()
                .filter_map(|&w| {
                    let d = window_data(path, intensity, hint_dl_nm, envelope, &none, MAX_EXTRAP, w, max_pts);
                    let centre = 0.5 * (path.at(w.0) + path.at(w.1 - 1));
                    window_harmonic(&d.y, &d.hint, &d.a, &d.b, rad_per_hint_nm).map(|f| (centre, f))
                })
                .collect();
            let mut noise_ls = None;
            if !fits.is_empty() {
                let rss: f64 = fits.iter().map(|f| f.1.rss_raw).sum();
                let dof: f64 = fits.iter().map(|f| f.1.dof).sum();
                noise_ls = Some(rss / dof);
            }
            if fits.is_empty() {
                warnings.push("no window covers enough phase to measure the fringe harmonic: assumed zero".to_string());
                (HarmonicProfile::default(), 0.01, noise_ls)
            } else {
                let profile = HarmonicProfile::new(fits.iter().map(|(c, f)| (*c, f.harm)).collect());
                (profile, harmonic_profile_sigma(&fits), noise_ls)
            }
        }
    }
}

/// The windows of the harmonic fits: the start window, at most [`MAX_HARMONIC_WINDOWS`]
/// interior ones evenly along the path, and the end window.
///
/// With the loose start walk, the start window begins where the intensity first leaves its
/// starting level by 6σ of the white noise. A stage taking up its play stalls the phase at
/// the start while the hint moves; a window fit over that stall (phase linear in the hint)
/// got a wrong harmonic that the profile carried over the whole trace (2–13 nm off with 2 µm
/// of lateral play). Not by default: it changed the default tracking enough that the
/// hidden-pivot diagnosis (tests/cli_diagnose.rs) named a q1 scale error instead of the pivot.
#[inline(always)]
pub(super) fn harmonic_windows(
    cfg: &TrackConfig,
    path: &PathView,
    intensity: &[f64],
    (win_s, win_e): MotionWindows,
    scale: &TrackScale,
    scratch: &mut Vec<f64>,
) -> Vec<(usize, usize)> {
    let (n, fringe_nm) = (scale.n, scale.fringe_nm);
    let width = 2.0 * fringe_nm;
    let total = path.at(n - 1);
    let harm_s = {
        let head = &intensity[..n.min(4096)];
        let sigma = estimate_noise_sigma(head, scratch);
        let m0 = head.len().min(8);
        let level = head[..m0].iter().sum::<f64>() / m0 as f64;
        let onset = intensity.iter().position(|&v| (v - level).abs() > 6.0 * sigma).unwrap_or(0);
        let p0 = path.at(onset.max(win_s.0));
        if cfg.start_walk_rad > 0.0 && onset > win_s.0 && p0 < total - 1.25 * fringe_nm {
            let w1 = (path.partition_point(|p| p < p0 + width) + 1).min(n);
            (onset.min(w1 - 1), w1)
        } else {
            win_s
        }
    };
    let mut wins = vec![harm_s];
    let interior = ((total / width) as usize).saturating_sub(1).min(MAX_HARMONIC_WINDOWS);
    for j in 1..=interior {
        let cpos = total * j as f64 / (interior + 1) as f64;
        let w0 = path.partition_point(|p| p < cpos - 0.5 * width);
        let w1 = path.partition_point(|p| p < cpos + 0.5 * width).min(n);
        if w1 > w0 && w0 >= harm_s.1 && w1 <= win_e.0 {
            wins.push((w0, w1));
        }
    }
    wins.push((win_e.0.max(harm_s.0), win_e.1));
    wins
}
