//! Recorded traces → observations for the identifiers: gap changes along motions, absolute gaps
//! from sweeps, fringe amplitudes along tilt scans. Owns how a trace is cut into observations and what σ each gets.

use crate::fringes::{detect_extrema, HysteresisConfig};
use crate::identify::{Observation, ObservationKind};
use crate::measure::{self, MeasureError, Measurement, PhaseModel};
use crate::trace::Trace;

/// How traces become observations.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExtractOptions {
    /// Gap-change observations per motion (evenly spaced from the start; the end always).
    pub points_per_motion: usize,
    /// Floor of the gap-change σ (nm): what the fringe analysis cannot see (stage noise, drift)
    /// and its own systematic error on multi-beam fringes (2.3 nm rms against the model truth
    /// over the motions of strategies 1, 2 and the joint extras on table2-ideal, seed 3, see
    /// `core/examples/calib_debug.rs` with `PER_TRACE=1`).
    pub sigma_floor_nm: f64,
    /// Floor of the absolute-gap σ (µm): wavelength calibration and model limits.
    pub gap_sigma_floor_um: f64,
}

impl Default for ExtractOptions {
    fn default() -> Self {
        Self { points_per_motion: 4, sigma_floor_nm: 2.5, gap_sigma_floor_um: 0.005 }
    }
}

/// Observations from one trace, labelled with the trace's label. Traces whose label starts
/// with "tilt scan" also give fringe amplitudes (one gain group per such trace, `group`).
pub fn observations_from_trace(
    trace: &Trace,
    model: &PhaseModel,
    options: &ExtractOptions,
    group: usize,
) -> Result<Vec<Observation>, MeasureError> {
    let label = trace.meta.label.clone();
    let wavelength_nm = trace.wavelength_nm.first().copied().unwrap_or(1560.0);
    let mut out = Vec::new();
    match measure::analyse(trace, model)? {
        Measurement::Sweep(s) => {
            out.push(Observation {
                label,
                kind: ObservationKind::AbsoluteGap { at_display: trace.joints_display(0), gap_um: s.gap.gap_um },
                sigma: s.gap.sigma_um.hypot(options.gap_sigma_floor_um),
                wavelength_nm: trace.wavelength_nm[trace.len() / 2],
                time_s: [trace.t_s[0], trace.t_s[trace.len() - 1]],
            });
        }
        Measurement::Motion(m) => {
            let n = trace.len();
            let k = options.points_per_motion.max(1);
            // The tracker estimates the noise from its own residuals, so a signal its model does
            // not fit (an envelope or a fringe shape changing faster than its knots and its one
            // harmonic follow: tilt scans, turning points) still looks like χ² = 1. The
            // detector noise seen sample to sample is independent of that model: the ratio of
            // the two (a Birge ratio, ≥ 1) scales the fit part of the σ.
            let misfit = detector_noise(&trace.irradiance)
                .filter(|&d| d > 0.0)
                .map_or(1.0, |d| (m.track.noise_sigma / d).max(1.0));
            // A tilt scan is for its fringe amplitudes: its envelope changes by a factor of two
            // within a few fringes and its phase has a turning point, and the tracker's dL there
            // is off by 11 nm rms (against the model truth, table2-ideal seed 3: `PER_TRACE=1
            // cargo run --release -p photorobot-core --example calib_debug -- table2-ideal joint 3`)
            // where other motions are off by 2.3 nm. Its gap changes are not used.
            let gap_changes = if label.starts_with("tilt scan") { 0 } else { k };
            for p in 1..=gap_changes {
                let i = (p * (n - 1)) / k;
                let fit_nm = if i == n - 1 { m.track.sigma_fit_nm } else { m.track.sigma_dl_nm[i] };
                // The cyclic error of the harmonic estimate acts at every point, not only at
                // the end.
                let sigma = (misfit * fit_nm).hypot(m.track.sigma_harmonic_nm);
                out.push(Observation {
                    label: label.clone(),
                    kind: ObservationKind::GapChange {
                        from_display: trace.joints_display(0),
                        to_display: trace.joints_display(i),
                        dl_nm: m.track.dl_nm[i],
                    },
                    sigma: sigma.hypot(options.sigma_floor_nm),
                    wavelength_nm,
                    time_s: [trace.t_s[0], trace.t_s[i]],
                });
            }
            if label.starts_with("tilt scan") {
                let half_fringe_nm = wavelength_nm / (4.0 * model.n_air);
                out.extend(amplitudes(trace, &m.track.dl_nm, half_fringe_nm, group, wavelength_nm));
            }
        }
    }
    Ok(out)
}

/// Fringe amplitude (half peak-to-peak between neighbouring extrema) along a trace, at the
/// joints midway between them; σ from the detector noise estimated from sample differences.
/// Only pairs a half fringe apart on the tracked gap `dl_nm` count: an intensity extremum at a
/// turning point of the phase (the gap stops and comes back) is not a fringe extremum.
fn amplitudes(trace: &Trace, dl_nm: &[f64], half_fringe_nm: f64, group: usize, wavelength_nm: f64) -> Vec<Observation> {
    let v = &trace.irradiance;
    let Ok(ext) = detect_extrema(v, &HysteresisConfig::default()) else { return vec![] };
    let Some(sigma) = detector_noise(v) else { return vec![] };
    let half_fringe_apart = |a: usize, b: usize| match (dl_nm.get(a), dl_nm.get(b)) {
        (Some(a), Some(b)) => ((b - a).abs() / half_fringe_nm - 1.0).abs() < 0.15,
        _ => false,
    };
    // Seven alternating extrema, each pair a half fringe apart: the amplitude at the middle one
    // is half its distance to the opposite envelope there, interpolated (cubic Lagrange in the
    // sample index) from the four opposite extrema around it. In a tilt scan the mean level
    // changes as fast as the amplitude (both follow the coupling, a Gaussian in the tilt): the
    // half difference of two neighbours reads that trend as amplitude (alternating in sign),
    // and the mean of the two neighbours its curvature (a few % of the amplitude per fringe).
    let mut out: Vec<Observation> = ext
        .windows(7)
        .filter(|w| w.windows(2).all(|p| p[0].kind != p[1].kind && half_fringe_apart(p[0].index, p[1].index)))
        .map(|w| {
            let mid = w[3].index;
            // A tenth of the shorter half fringe on either side, in samples.
            let reach = (w[3].index - w[2].index).min(w[4].index - w[3].index) / 10;
            let level = |e: &crate::fringes::Extremum| peak_level(v, e.index, reach, sigma);
            let centre = level(&w[3]);
            let opposite = [&w[0], &w[2], &w[4], &w[6]];
            let xs = opposite.map(|e| e.index as f64);
            let weights = lagrange_weights(&xs, mid as f64);
            let levels = opposite.map(level);
            let envelope: f64 = weights.iter().zip(&levels).map(|(w, l)| w * l.0).sum();
            let envelope_var: f64 = weights.iter().zip(&levels).map(|(w, l)| (w * l.1).powi(2)).sum();
            Observation {
                label: trace.meta.label.clone(),
                kind: ObservationKind::FringeAmplitude {
                    at_display: trace.joints_display(mid),
                    amplitude_mw: (centre.0 - envelope).abs() / 2.0,
                    group,
                },
                sigma: (centre.1 * centre.1 + envelope_var).sqrt().max(1e-12) / 2.0,
                wavelength_nm,
                time_s: [trace.t_s[mid]; 2],
            }
        })
        .collect();
    // The amplitude along a scan is a smooth function of the sample index (the coupling is a
    // Gaussian in the tilt): its scatter about a quartic fitted through the scan is what one
    // estimate really varies by (the noise, and what the envelope model misses). It is a floor
    // of the σ whenever there are enough estimates to fit one.
    if let Some(scatter) = scatter_about_quartic(&out) {
        for o in &mut out {
            o.sigma = o.sigma.max(scatter);
        }
    }
    out
}

/// Root mean square deviation of the amplitudes of one scan from a least-squares quartic in the
/// sample time, with the degrees of freedom counted; `None` with fewer than 10 amplitudes.
fn scatter_about_quartic(amplitudes: &[Observation]) -> Option<f64> {
    const TERMS: usize = 5;
    if amplitudes.len() < 2 * TERMS {
        return None;
    }
    let (t0, t1) = (amplitudes.first()?.time_s[0], amplitudes.last()?.time_s[0]);
    let span = (t1 - t0).abs().max(1e-12);
    let x = |o: &Observation| 2.0 * (o.time_s[0] - t0) / span - 1.0;
    let a = nalgebra::DMatrix::from_fn(amplitudes.len(), TERMS, |i, j| x(&amplitudes[i]).powi(j as i32));
    let y = nalgebra::DVector::from_iterator(amplitudes.len(), amplitudes.iter().map(Observation::value));
    let coef = a.clone().svd(true, true).solve(&y, 1e-12).ok()?;
    let rss = (y - a * coef).norm_squared();
    Some((rss / (amplitudes.len() - TERMS) as f64).sqrt())
}

/// Weights of the Lagrange polynomial through the nodes `xs`, evaluated at `x`.
fn lagrange_weights<const N: usize>(xs: &[f64; N], x: f64) -> [f64; N] {
    std::array::from_fn(|j| (0..N).filter(|&m| m != j).map(|m| (x - xs[m]) / (xs[j] - xs[m])).product())
}

/// The level of a fringe extremum near sample `i` and its σ: the vertex of a parabola fitted by
/// least squares over `i ± reach` samples (within a tenth of a half fringe the fringe is a
/// parabola to 4e-4 of its amplitude). The extreme sample itself is biased by the noise (the
/// largest of the samples near a flat peak: about 1.5σ on a slow fringe); the fit is not. With
/// fewer than 5 samples in reach, the raw sample with 2σ (noise and that bias).
fn peak_level(v: &[f64], i: usize, reach: usize, noise: f64) -> (f64, f64) {
    let (lo, hi) = (i.saturating_sub(reach), (i + reach).min(v.len().saturating_sub(1)));
    let n = hi + 1 - lo;
    if reach < 2 || n < 5 {
        return (v[i], 2.0 * noise);
    }
    // Normal equations of y = a + b·x + c·x², x centred on i and scaled to [-1, 1].
    let scale = reach as f64;
    let mut m = nalgebra::Matrix3::<f64>::zeros();
    let mut r = nalgebra::Vector3::<f64>::zeros();
    for (k, y) in v[lo..=hi].iter().enumerate() {
        let x = (lo + k) as f64 / scale - i as f64 / scale;
        let f = nalgebra::Vector3::new(1.0, x, x * x);
        m += f * f.transpose();
        r += f * *y;
    }
    let Some(inv) = m.try_inverse() else { return (v[i], 2.0 * noise) };
    let p = inv * r;
    let (a, b, c) = (p[0], p[1], p[2]);
    if c.abs() < 1e-300 {
        return (v[i], 2.0 * noise);
    }
    // Vertex, kept inside the window (a vertex outside means no clear peak: take the centre).
    let x0 = (-b / (2.0 * c)).clamp(-1.0, 1.0);
    let level = a + b * x0 + c * x0 * x0;
    // σ of the level at x0: fᵀ (MᵀM)⁻¹ f · noise².
    let f = nalgebra::Vector3::new(1.0, x0, x0 * x0);
    let var = (f.transpose() * inv * f)[0].max(0.0);
    (level, noise * var.sqrt())
}

/// White-noise σ of a sampled signal from the median absolute second difference (robust to
/// the signal itself while a fringe spans many samples; an overestimate when it does not).
/// `None` for fewer than three samples.
pub fn detector_noise(v: &[f64]) -> Option<f64> {
    let mut d2: Vec<f64> = v.windows(3).map(|w| (w[0] - 2.0 * w[1] + w[2]).abs()).collect();
    if d2.is_empty() {
        return None;
    }
    let mid = d2.len() / 2;
    let (_, median, _) = d2.select_nth_unstable_by(mid, f64::total_cmp);
    Some(*median / 0.6745 / 6f64.sqrt())
}

/// Observations from many traces, and the traces that could not be analysed.
#[derive(Debug, Clone, Default)]
pub struct Extracted {
    /// Every usable observation; amplitude groups numbered in trace order.
    pub observations: Vec<Observation>,
    /// Traces whose analysis failed: their label and why. Their data stay in the session;
    /// they only give no observation with the current model.
    pub skipped: Vec<(String, String)>,
}

/// Observations from many traces; a trace whose analysis fails is listed in
/// [`Extracted::skipped`] and the others are still used.
pub fn observations_from_traces(traces: &[Trace], model: &PhaseModel, options: &ExtractOptions) -> Extracted {
    use rayon::prelude::*;
    // Traces are independent: analyse them in parallel, then number the amplitude groups in
    // trace order.
    let results: Vec<Result<Vec<Observation>, MeasureError>> =
        traces.par_iter().map(|t| observations_from_trace(t, model, options, 0)).collect();
    let mut out = Extracted::default();
    let mut group = 0;
    for (t, r) in traces.iter().zip(results) {
        let mut obs = match r {
            Ok(o) => o,
            Err(e) => {
                out.skipped.push((t.meta.label.clone(), e.to_string()));
                continue;
            }
        };
        let mut has_amplitudes = false;
        for o in &mut obs {
            if let ObservationKind::FringeAmplitude { group: g, .. } = &mut o.kind {
                *g = group;
                has_amplitudes = true;
            }
        }
        if has_amplitudes {
            group += 1;
        }
        // An observation without a finite value and a positive finite σ carries no information.
        out.observations
            .extend(obs.into_iter().filter(|o| o.value().is_finite() && o.sigma.is_finite() && o.sigma > 0.0));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::trace::TraceMeta;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    const LAMBDA_NM: f64 = 1560.0;

    /// A tilt-scan-like trace: 13 fringes, the amplitude B and the mean level A = 3B + c both a
    /// Gaussian of time of width `width` (as the coupling is of the tilt), white noise `noise`.
    /// Returns the trace, its tracked dL (exact) and B per sample.
    fn scan(width: f64, noise: f64, seed: u64) -> (Trace, Vec<f64>, Vec<f64>) {
        let n = 26_000;
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let white = Normal::new(0.0, noise).unwrap();
        let mut t = Trace::new(TraceMeta { label: "tilt scan test".into(), ..Default::default() });
        let (mut dl, mut b) = (Vec::new(), Vec::new());
        for i in 0..n {
            let s = i as f64 / (n - 1) as f64;
            let bi = 0.0075 * (-((s - 0.4) / width).powi(2)).exp();
            let phase = 13.0 * std::f64::consts::TAU * s;
            t.t_s.push(s * 2.6);
            for c in [&mut t.q1_um, &mut t.q2_um, &mut t.q3_um, &mut t.q5_deg, &mut t.q6_deg] {
                c.push(0.0);
            }
            t.q4_deg.push(-2.5 + 5.0 * s);
            t.wavelength_nm.push(LAMBDA_NM);
            t.irradiance.push(3.0 * bi + 0.01 + bi * phase.cos() + white.sample(&mut rng));
            dl.push(phase * LAMBDA_NM / (4.0 * std::f64::consts::PI));
            b.push(bi);
        }
        (t, dl, b)
    }

    /// (estimate − B)/σ and (estimate − B)/B of every amplitude of a scan, and the same relative
    /// error of the half difference of two neighbouring extrema at those points.
    fn amplitude_errors(width: f64, seed: u64) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let (t, dl, b) = scan(width, 7.5e-6, seed);
        let obs = amplitudes(&t, &dl, LAMBDA_NM / 4.0, 0, LAMBDA_NM);
        assert!(obs.len() >= 15, "{} amplitudes", obs.len());
        let (mut z, mut rel, mut naive) = (Vec::new(), Vec::new(), Vec::new());
        for o in &obs {
            let ObservationKind::FringeAmplitude { amplitude_mw, .. } = o.kind else { unreachable!() };
            let i = t.t_s.iter().position(|&ti| ti >= o.time_s[0]).unwrap();
            z.push((amplitude_mw - b[i]) / o.sigma);
            rel.push((amplitude_mw - b[i]) / b[i]);
            let half = 1000; // a half fringe in samples
            naive.push(((t.irradiance[i] - t.irradiance[i + half]).abs() / 2.0 - b[i]) / b[i]);
        }
        (z, rel, naive)
    }

    fn rms(v: &[f64]) -> f64 {
        (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
    }

    #[test]
    fn detector_noise_recovers_white_noise_under_a_slow_fringe() {
        let (t, _, _) = scan(0.6, 1e-5, 1);
        let got = detector_noise(&t.irradiance).unwrap();
        assert!((got / 1e-5 - 1.0).abs() < 0.05, "{got}");
        assert_eq!(detector_noise(&[1.0, 2.0]), None);
    }

    #[test]
    fn amplitudes_have_honest_sigma_under_a_slowly_changing_envelope() {
        // Oracle: the envelope B the trace was made with.
        let z: Vec<f64> = (0..4).flat_map(|seed| amplitude_errors(2.0, seed).0).collect();
        let r = rms(&z);
        assert!((0.4..=1.5).contains(&r), "normalised rms {r} over {} amplitudes", z.len());
    }

    #[test]
    fn amplitudes_follow_a_fast_changing_envelope() {
        // The mean level changes by 10 % of the amplitude per fringe at the ends: the half
        // difference of two neighbouring extrema reads half of that as amplitude, with a sign
        // alternating extremum to extremum. The stencil estimate keeps only a second-order
        // bias (the extremum of the signal is not where the phase is a multiple of π).
        for seed in 0..2 {
            let (_, rel, naive) = amplitude_errors(0.6, seed);
            let worst = rel.iter().fold(0.0f64, |m, x| m.max(x.abs()));
            let naive_worst = naive.iter().fold(0.0f64, |m, x| m.max(x.abs()));
            assert!(worst < 0.006, "worst relative error {worst}");
            assert!(naive_worst > 5.0 * worst, "naive worst {naive_worst} vs {worst}");
        }
    }

    #[test]
    fn peak_level_is_unbiased_where_the_extreme_sample_is_not() {
        let normal = Normal::new(0.0, 1e-3).unwrap();
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        let (mut fit, mut raw) = (0.0, 0.0);
        let trials = 200;
        for _ in 0..trials {
            // A flat cosine peak of amplitude 1 sampled at 0.01 rad: about 50 samples within 1σ.
            let v: Vec<f64> = (-300..=300).map(|k| (k as f64 * 0.01).cos() + normal.sample(&mut rng)).collect();
            let i = (0..v.len()).max_by(|&a, &b| v[a].total_cmp(&v[b])).unwrap();
            let (level, sigma) = peak_level(&v, i, 30, 1e-3);
            assert!(sigma > 0.0 && sigma < 1e-3);
            fit += (level - 1.0) / trials as f64;
            raw += (v[i] - 1.0) / trials as f64;
        }
        assert!(raw > 0.8e-3, "the extreme sample is biased by {raw}");
        assert!(fit.abs() < 2e-4, "the fitted level is biased by {fit}");
    }

    #[test]
    fn lagrange_weights_reproduce_cubics() {
        let xs = [0.0, 2.0, 5.0, 7.5];
        let f = |x: f64| 1.0 - 2.0 * x + 0.5 * x * x - 0.03 * x * x * x;
        let w = lagrange_weights(&xs, 3.3);
        let got: f64 = w.iter().zip(xs).map(|(w, x)| w * f(x)).sum();
        assert!((got - f(3.3)).abs() < 1e-12);
    }
}
