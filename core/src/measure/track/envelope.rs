//! The envelope A, B of the fringe: levels placed along the motion and interpolated, the
//! initial envelope from the extrema (or known), and a fringe model's envelope.

use super::config::{EnvelopeSource, FringeModel, KnownEnvelope};
use super::grid::{Grid, PathView};
use super::harmonic::HarmonicProfile;
use crate::measure::extrema::{Extremum, ExtremumKind};
use crate::measure::signal::FringeError;

/// How far beyond the end knots the envelope is extrapolated linearly, in units of the
/// envelope's coordinate (a fringe of travel or [`T_ENVELOPE`] samples).
pub(super) const MAX_EXTRAP: f64 = 2.0;

/// Level of an envelope point (or any quantity) placed at a position along the motion.
#[derive(Debug, Clone, Copy)]
pub(super) struct Knot {
    pub(super) s: f64,
    pub(super) level: f64,
}

/// Interpolation of knots along the motion path: cubic Hermite (Catmull-Rom slopes from
/// the neighbouring knots) inside, clamped linear extrapolation beyond the end knots.
/// `knots` are sorted by `s`; `cursor` speeds up monotone queries (a few steps ahead are
/// walked, farther ones found by bisection).
pub(super) fn knot_value(knots: &[Knot], s: f64, cursor: &mut usize, max_extrap: f64) -> f64 {
    let m = knots.len();
    if m == 1 {
        return knots[0].level;
    }
    let mut walk = 0;
    while *cursor + 2 < m && knots[*cursor + 1].s <= s {
        *cursor += 1;
        walk += 1;
        if walk == 4 {
            *cursor += knots[*cursor + 1..m - 1].partition_point(|k| k.s <= s);
            break;
        }
    }
    let i = *cursor;
    let (k0, k1) = (knots[i], knots[i + 1]);
    let h = k1.s - k0.s;
    let slope = if h > 0.0 { (k1.level - k0.level) / h } else { 0.0 };
    if s < k0.s {
        return k0.level + slope * (s - k0.s).max(-max_extrap);
    }
    if s > k1.s {
        return k1.level + slope * (s - k1.s).min(max_extrap);
    }
    if h <= 0.0 {
        return k0.level;
    }
    // Catmull-Rom tangents (one-sided at the ends)
    let tangent = |j: usize| -> f64 {
        let (a, b) = (j.saturating_sub(1), (j + 1).min(m - 1));
        let d = knots[b].s - knots[a].s;
        if d > 0.0 {
            (knots[b].level - knots[a].level) / d
        } else {
            slope
        }
    };
    let (m0, m1) = (tangent(i) * h, tangent(i + 1) * h);
    let t = (s - k0.s) / h;
    let (t2, t3) = (t * t, t * t * t);
    (2.0 * t3 - 3.0 * t2 + 1.0) * k0.level
        + (t3 - 2.0 * t2 + t) * m0
        + (-2.0 * t3 + 3.0 * t2) * k1.level
        + (t3 - t2) * m1
}

/// Initial envelope: fringe-extremum levels along the path, or a known constant.
pub(super) enum Envelope<'a> {
    Knots { upper: &'a [Knot], lower: &'a [Knot] },
    Known(KnownEnvelope),
}

impl Envelope<'_> {
    /// A and B at monotone envelope coordinates `c` ([`envelope_coordinate`]) and their path
    /// positions `s` (the harmonic profile's coordinate), upper = A + B·f_max and
    /// lower = A + B·f_min, written to `a` and `b`.
    pub(super) fn eval_into(
        &self,
        c: &[f64],
        s: &[f64],
        harm: &HarmonicProfile,
        max_extrap: f64,
        a: &mut Vec<f64>,
        b: &mut Vec<f64>,
    ) {
        a.clear();
        b.clear();
        match self {
            Envelope::Known(k) => {
                a.resize(s.len(), k.offset);
                b.resize(s.len(), k.amplitude);
            }
            Envelope::Knots { upper, lower } => {
                let (mut cu, mut cl, mut ch) = (0usize, 0usize, 0usize);
                for (&q, &p) in c.iter().zip(s) {
                    let (fmax, fmin) = harm.extremes_at(p, &mut ch);
                    let inv = 1.0 / (fmax - fmin);
                    let u = knot_value(upper, q, &mut cu, max_extrap);
                    let l = knot_value(lower, q, &mut cl, max_extrap);
                    let bb = ((u - l) * inv).max(f64::MIN_POSITIVE);
                    a.push(u - bb * fmax);
                    b.push(bb);
                }
            }
        }
    }

    pub(super) fn eval(&self, c: &[f64], s: &[f64], harm: &HarmonicProfile, max_extrap: f64) -> (Vec<f64>, Vec<f64>) {
        let (mut a, mut b) = (Vec::new(), Vec::new());
        self.eval_into(c, s, harm, max_extrap, &mut a, &mut b);
        (a, b)
    }
}

/// Least squares of y ≈ o·w + g·x over (w, x, y) points (w = 1 for an offset row, 0 for a
/// row without offset): (o, g), or None when singular or g ≤ 0.
pub(super) fn fit_offset_gain(pts: &[(f64, f64, f64)]) -> Option<(f64, f64)> {
    let (mut sww, mut swx, mut sxx, mut swy, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for &(w, x, y) in pts {
        sww += w * w;
        swx += w * x;
        sxx += x * x;
        swy += w * y;
        sxy += x * y;
    }
    let det = sww * sxx - swx * swx;
    if det.is_nan() || det <= 1e-12 * sww * sxx {
        return None;
    }
    let o = (sxx * swy - swx * sxy) / det;
    let g = (sww * sxy - swx * swy) / det;
    (g > 0.0 && g.is_finite() && o.is_finite()).then_some((o, g))
}

/// The initial envelope: the levels of the counted fringe extrema along the motion, or the
/// known constant. An error when the extrema do not cover one fringe (a maximum and a minimum).
#[inline(always)]
pub(super) fn initial_envelope<'a>(
    source: &EnvelopeSource,
    extrema: &[Extremum],
    path: &PathView,
    upper: &'a mut Vec<Knot>,
    lower: &'a mut Vec<Knot>,
) -> Result<Envelope<'a>, FringeError> {
    upper.clear();
    lower.clear();
    match *source {
        EnvelopeSource::Known(k) => Ok(Envelope::Known(k)),
        EnvelopeSource::FromData => {
            for e in extrema.iter().filter(|e| e.direction != 0) {
                let knot = Knot { s: path.envelope_at(e.index), level: e.value };
                match e.kind {
                    ExtremumKind::Max => upper.push(knot),
                    ExtremumKind::Min => lower.push(knot),
                }
            }
            if upper.is_empty() || lower.is_empty() {
                return Err(FringeError::TooFewFringes { maxima: upper.len(), minima: lower.len() });
            }
            let (upper, lower): (&'a Vec<Knot>, &'a Vec<Knot>) = (upper, lower);
            Ok(Envelope::Knots { upper, lower })
        }
    }
}

/// A fringe model's envelope at the knots, for the envelope taken from the data:
/// (offset, amplitude) per knot in model units, and the detector gain g of
/// `value ≈ o + g·(offset + amplitude·f)` fitted to the extrema. The initial envelope
/// `a`, `b` becomes `o + g·offset`, `g·amplitude` at the knots. Empty and None without a
/// model, or (with a warning) when the model's envelope does not match the extrema.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(super) fn model_envelope_at_knots(
    model: Option<&FringeModel>,
    source: &EnvelopeSource,
    grid: &Grid,
    cgrid: &[f64],
    extrema: &[Extremum],
    a: &mut [f64],
    b: &mut [f64],
    warnings: &mut Vec<String>,
) -> (Vec<(f64, f64)>, Option<f64>) {
    let n = cgrid.len();
    let n_knots = grid.knot_k.len();
    // the last knot (beyond the data, grid coordinate n_knots - 1 > c at the last sample)
    // extrapolated so that the last segment's interpolation meets the model at the last sample
    let mut knot_model: Vec<(f64, f64)> = Vec::new();
    let mut model_gain = None;
    if let (Some(fm), EnvelopeSource::FromData) = (model, source) {
        knot_model.extend(grid.knot_k.iter().map(|&kf| {
            let k = (kf.round().max(0.0) as usize).min(n - 1);
            (fm.offset[k], fm.amplitude[k])
        }));
        if n_knots >= 3 {
            let t_end = cgrid[n - 1] - (n_knots - 2) as f64;
            if t_end > 0.2 && t_end < 1.0 {
                let (p0, p1) = knot_model[n_knots - 2];
                let (e0, e1) = (fm.offset[n - 1], fm.amplitude[n - 1]);
                knot_model[n_knots - 1] = (p0 + (e0 - p0) / t_end, (p1 + (e1 - p1) / t_end).max(0.1 * e1));
            }
        }
        // Detector offset o and gain g from the extrema: value ≈ o + g·(offset + amplitude·f).
        let pts: Vec<(f64, f64, f64)> = extrema
            .iter()
            .filter(|e| e.direction != 0)
            .map(|e| {
                let k = e.index;
                let (fmax, fmin) = fm.harmonics[k].extremes();
                let f = if e.kind == ExtremumKind::Max { fmax } else { fmin };
                (1.0, fm.offset[k] + fm.amplitude[k] * f, e.value)
            })
            .collect();
        match fit_offset_gain(&pts) {
            Some((o, g)) => {
                model_gain = Some(g);
                for (j, &(p0, p1)) in knot_model.iter().enumerate() {
                    a[j] = o + g * p0;
                    b[j] = g * p1;
                }
            }
            None => {
                warnings.push("the fringe model's envelope does not match the extrema: not used".to_string());
                knot_model.clear();
            }
        }
    }
    (knot_model, model_gain)
}

/// The model's envelope shape within the segments (shaped tracking): B = r·(linear
/// interpolation of the knots), A = linear + ca, so that knots at o + g·P0 and g·P1
/// reproduce the model exactly between them. Linear interpolation of an amplitude that falls
/// to a quarter over three fringes (a tilt scan) biased the phase by 9 nm. r = 1 and ca = 0
/// when the model's envelope is not used; both empty without a model.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(super) fn model_envelope_shape(
    model: Option<&FringeModel>,
    model_gain: Option<f64>,
    knot_model: &[(f64, f64)],
    grid: &Grid,
    cgrid: &[f64],
    env_r: &mut Vec<f64>,
    env_ca: &mut Vec<f64>,
) {
    let n = cgrid.len();
    let n_knots = grid.knot_k.len();
    env_r.clear();
    env_ca.clear();
    if let (Some(fm), Some(g)) = (model, model_gain.filter(|_| !knot_model.is_empty())) {
        env_r.resize(n, 1.0);
        env_ca.resize(n, 0.0);
        for j in 0..n_knots - 1 {
            let (k0, k1) = (grid.seg_first[j], grid.seg_first[j + 1]);
            let ((p0a, p1a), (p0b, p1b)) = (knot_model[j], knot_model[j + 1]);
            for k in k0..k1 {
                let t = cgrid[k] - j as f64;
                let lin1 = (1.0 - t) * p1a + t * p1b;
                if lin1 > 0.0 {
                    env_r[k] = (fm.amplitude[k] / lin1).clamp(0.1, 10.0);
                }
                env_ca[k] = g * (fm.offset[k] - ((1.0 - t) * p0a + t * p0b));
            }
        }
    } else if model.is_some() {
        env_r.resize(n, 1.0);
        env_ca.resize(n, 0.0);
    }
}
