//! The fringe's envelope (offset A, half peak-to-peak B) from a short axial dither that crosses a
//! few fringes: the mean of its maxima and minima, each refined by a parabola through its
//! neighbours. Model-free: only the samples.

use crate::measure::extrema::{detect_extrema, estimate_noise_sigma, ExtremumKind, HysteresisConfig};

/// Offset and half peak-to-peak of a fringe, with the standard uncertainty of the latter and the
/// white-noise σ of the signal it came from (intensity units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Envelope {
    /// A: midway between the fringe's top and bottom.
    pub offset: f64,
    /// B: half the distance from the fringe's bottom to its top (> 0).
    pub amplitude: f64,
    /// Standard uncertainty of `amplitude`.
    pub sigma_amplitude: f64,
    /// White-noise σ of the samples.
    pub noise_sigma: f64,
}

impl Envelope {
    /// The normalised value (I − A)/B of a sample.
    pub fn normalised(&self, irradiance: f64) -> f64 {
        (irradiance - self.offset) / self.amplitude
    }
}

/// Samples on each side of an extremum for its parabola: enough to average the noise, few enough
/// that the parabola holds (a fringe near its top is a parabola over about a tenth of a fringe).
pub(super) fn half_window(samples_per_fringe: f64) -> usize {
    ((samples_per_fringe / 16.0).round() as usize).clamp(1, 50)
}

/// The vertex value of the parabola through `y[i - w ..= i + w]` and its variance for white noise
/// of variance `var` (that of the intercept of a centred quadratic fit, 9/(4m) for m points).
pub(super) fn vertex(y: &[f64], i: usize, w: usize, var: f64) -> Option<(f64, f64)> {
    let (a, b) = (i.checked_sub(w)?, i + w);
    if b >= y.len() {
        return None;
    }
    // Least squares y = c0 + c1·x + c2·x² on x = -w..=w.
    let (mut s0, mut s2, mut s4, mut t0, mut t1, mut t2) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    for (k, &v) in y[a..=b].iter().enumerate() {
        let x = k as f64 - w as f64;
        s0 += 1.0;
        s2 += x * x;
        s4 += x * x * x * x;
        t0 += v;
        t1 += x * v;
        t2 += x * x * v;
    }
    let det = s0 * s4 - s2 * s2;
    if det.abs() < 1e-12 || s2 == 0.0 {
        return Some((y[i], var));
    }
    let c0 = (t0 * s4 - t2 * s2) / det;
    let c2 = (s0 * t2 - s2 * t0) / det;
    let c1 = t1 / s2;
    // The vertex, kept inside the window (a flat top has none nearby: its centre then).
    let x = if c2.abs() > 1e-300 { (-c1 / (2.0 * c2)).clamp(-(w as f64), w as f64) } else { 0.0 };
    Some((c0 + c1 * x + c2 * x * x, var * 9.0 / (4.0 * s0)))
}

/// The envelope of `signal`, a dither across at least one fringe top and one bottom; `None` when
/// it has no maximum or no minimum beyond its noise. Extrema short of the highest top or the
/// lowest bottom (the dither's turning point) are left out.
pub fn dither_envelope(signal: &[f64]) -> Option<Envelope> {
    dither_envelope_where(signal).map(|e| e.0)
}

/// [`dither_envelope`] with where along the dither it stands: the mean sample index of the tops
/// and that of the bottoms it used, averaged (the amplitude changes with the gap along a dither).
pub fn dither_envelope_where(signal: &[f64]) -> Option<(Envelope, f64)> {
    let noise_sigma = estimate_noise_sigma(signal, &mut Vec::new());
    let cfg = HysteresisConfig { relative: 0.3, noise_floor_factor: super::NOISE_HYSTERESIS_SIGMA };
    let extrema = detect_extrema(signal, &cfg).ok()?;
    let var = noise_sigma * noise_sigma;
    let mut tops = Vec::new();
    let mut bottoms = Vec::new();
    for (k, e) in extrema.iter().enumerate() {
        // The fringe's period where the extremum is: twice the distance to its nearest neighbour
        // (the whole dither's count would include its pauses, and a wider parabola reads the
        // cosine's top lower).
        let near = [k.checked_sub(1).map(|j| extrema[j].index), extrema.get(k + 1).map(|n| n.index)]
            .into_iter()
            .flatten()
            .map(|i| i.abs_diff(e.index))
            .min()
            .unwrap_or(signal.len());
        let w = half_window(2.0 * near as f64);
        let Some((v, var_v)) = vertex(signal, e.index, w, var) else { continue };
        match e.kind {
            ExtremumKind::Max => tops.push((v, var_v, e.index)),
            ExtremumKind::Min => bottoms.push((v, var_v, e.index)),
        }
    }
    if tops.is_empty() || bottoms.is_empty() {
        return None;
    }
    // The dither's far end is a turning point of the gap: its extremum lies short of the fringe's
    // top (or bottom), by up to the whole swing. Only the extrema level with the highest top (the
    // lowest bottom) within their noise are the fringe's.
    let level = |v: &mut Vec<(f64, f64, usize)>, sign: f64| {
        let best = v.iter().map(|p| sign * p.0).fold(f64::NEG_INFINITY, f64::max);
        v.retain(|p| best - sign * p.0 <= 4.0 * (2.0 * p.1).sqrt() + 1e-12 * best.abs());
    };
    level(&mut tops, 1.0);
    level(&mut bottoms, -1.0);
    let mean = |v: &[(f64, f64, usize)]| {
        let n = v.len() as f64;
        (v.iter().map(|p| p.0).sum::<f64>() / n, v.iter().map(|p| p.1).sum::<f64>() / (n * n))
    };
    let at = |v: &[(f64, f64, usize)]| v.iter().map(|p| p.2 as f64).sum::<f64>() / v.len() as f64;
    let index = 0.5 * (at(&tops) + at(&bottoms));
    let ((top, var_top), (bottom, var_bottom)) = (mean(&tops), mean(&bottoms));
    let amplitude = 0.5 * (top - bottom);
    let envelope = Envelope {
        offset: 0.5 * (top + bottom),
        amplitude,
        sigma_amplitude: 0.5 * (var_top + var_bottom).sqrt(),
        noise_sigma,
    };
    (amplitude > 0.0).then_some((envelope, index))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A distorted fringe over 2.5 fringes out and back with noise: A and B within a few σ of
    /// the truth (A ± B are the fringe's top and bottom, found numerically).
    #[test]
    fn the_envelope_of_a_dither_is_its_top_and_bottom() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        let noise = Normal::new(0.0, 1e-3).unwrap();
        let f = |phi: f64| 2.0 + 0.8 * (phi.cos() + 0.05 * (2.0 * phi + 0.4).cos());
        let (top, bottom) = (0..100_000)
            .map(|k| f(k as f64 * 1e-4 * std::f64::consts::TAU))
            .fold((f64::NEG_INFINITY, f64::INFINITY), |(a, b), v| (a.max(v), b.min(v)));
        let n = 1200;
        let signal: Vec<f64> = (0..n)
            .map(|i| {
                let s = i as f64 / n as f64;
                let u = 2.5 * (1.0 - (2.0 * s - 1.0).abs());
                f(0.3 + u * std::f64::consts::TAU) + noise.sample(&mut rng)
            })
            .collect();
        let e = dither_envelope(&signal).unwrap();
        assert!((e.amplitude - 0.5 * (top - bottom)).abs() < 4.0 * e.sigma_amplitude + 2e-5, "{e:?}");
        assert!((e.offset - 0.5 * (top + bottom)).abs() < 1e-3, "{e:?}");
        assert!(e.sigma_amplitude < 5e-4 && (e.noise_sigma - 1e-3).abs() < 3e-4, "{e:?}");
        assert!(dither_envelope(&vec![1.0; 500]).is_none(), "no fringe, no envelope");
    }
}
