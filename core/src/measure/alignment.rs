//! Pre-alignment: is the reflected signal good enough to calibrate? Owns the signal-quality
//! figures computed from a short recording taken while the lamella is dithered along the beam
//! (mean reflected power, fringe visibility, fringe amplitude over the noise) and the thresholds
//! that say "ready".
//!
//! The thresholds come from what the fringe analysis needs: phase tracking resolves dL to the
//! nanometre when the fringe amplitude is at least [`MIN_FRINGE_SNR`] times the sample noise,
//! and extremum detection with the default hysteresis needs a visibility of at least
//! [`MIN_VISIBILITY`]. Below either, the technician keeps positioning the fiber.

use serde::Serialize;

/// Smallest fringe visibility `(I_max − I_min)/(I_max + I_min)` accepted for calibration.
pub const MIN_VISIBILITY: f64 = 0.05;

/// Smallest ratio of the fringe half peak-to-peak amplitude to the sample noise σ accepted for
/// calibration.
pub const MIN_FRINGE_SNR: f64 = 20.0;

/// Signal quality over a window of samples.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SignalQuality {
    /// Mean reflected power (the trace's irradiance unit, mW on the benches).
    pub mean: f64,
    /// Smallest and largest sample (robust: 0.5 and 99.5 percentiles).
    pub min: f64,
    /// Largest sample (99.5 percentile).
    pub max: f64,
    /// Fringe visibility `(max − min)/(max + min)`, 0..1.
    pub visibility: f64,
    /// Sample noise σ, from the second differences of the samples (MAD, robust to the fringes).
    pub noise_sigma: f64,
    /// Half peak-to-peak over the noise σ.
    pub fringe_snr: f64,
    /// Whether both thresholds are met.
    pub ready: bool,
}

impl SignalQuality {
    /// The figures of a window of samples; `None` with fewer than 16 samples.
    pub fn of(samples: &[f64]) -> Option<Self> {
        if samples.len() < 16 || samples.iter().any(|v| !v.is_finite()) {
            return None;
        }
        let mut sorted = samples.to_vec();
        sorted.sort_by(f64::total_cmp);
        let pick = |p: f64| sorted[((sorted.len() - 1) as f64 * p).round() as usize];
        let (min, max) = (pick(0.005), pick(0.995));
        let mean = samples.iter().sum::<f64>() / samples.len() as f64;
        // Second differences cancel the fringes' slope (what is left of the signal is its
        // curvature, negligible at the sampling rates of a bench); for white noise they have
        // σ√6, and their median absolute value is 0.6745σ√6.
        let mut diffs: Vec<f64> = samples.windows(3).map(|w| (w[2] - 2.0 * w[1] + w[0]).abs()).collect();
        diffs.sort_by(f64::total_cmp);
        let noise_sigma = diffs[diffs.len() / 2] / (0.674_489_75 * 6f64.sqrt());
        let visibility = if max + min > 0.0 { ((max - min) / (max + min)).clamp(0.0, 1.0) } else { 0.0 };
        let half = 0.5 * (max - min);
        let fringe_snr = if noise_sigma > 0.0 { half / noise_sigma } else { f64::INFINITY };
        let ready = visibility >= MIN_VISIBILITY && fringe_snr >= MIN_FRINGE_SNR;
        Some(Self { mean, min, max, visibility, noise_sigma, fringe_snr, ready })
    }

    /// What to do, in words.
    pub fn advice(&self) -> String {
        if self.ready {
            format!(
                "ready to calibrate: visibility {:.2} (≥ {MIN_VISIBILITY}), fringe amplitude {:.0}× the noise (≥ {MIN_FRINGE_SNR})",
                self.visibility, self.fringe_snr
            )
        } else if self.visibility < MIN_VISIBILITY {
            format!(
                "not yet: visibility {:.3} is below {MIN_VISIBILITY}; tilt the lamella (q4, q5) or move the fiber to bring the reflection back into the core",
                self.visibility
            )
        } else {
            format!(
                "not yet: fringe amplitude only {:.1}× the noise (needs {MIN_FRINGE_SNR}); increase the reflected power",
                self.fringe_snr
            )
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fringes(mean: f64, amplitude: f64, noise: f64, n: usize) -> Vec<f64> {
        // Deterministic pseudo-noise: a fixed LCG mapped to a roughly Gaussian sum of uniforms.
        let mut s: u64 = 12345;
        let mut uniform = || {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        (0..n)
            .map(|i| {
                let g: f64 = (0..12).map(|_| uniform()).sum::<f64>() - 6.0;
                mean + amplitude * (i as f64 * 0.01).cos() + noise * g
            })
            .collect()
    }

    #[test]
    fn figures_match_the_signal_that_made_them() {
        let q = SignalQuality::of(&fringes(1.0, 0.3, 0.002, 20_000)).unwrap();
        assert!((q.mean - 1.0).abs() < 0.01, "{q:?}");
        assert!((q.visibility - 0.3).abs() < 0.01, "{q:?}");
        assert!((q.noise_sigma - 0.002).abs() < 0.0002, "{q:?}");
        assert!((q.fringe_snr - 150.0).abs() < 20.0, "{q:?}");
        assert!(q.ready);
        assert!(q.advice().starts_with("ready"));
    }

    #[test]
    fn weak_fringes_or_weak_signal_are_not_ready_and_say_why() {
        let low_vis = SignalQuality::of(&fringes(1.0, 0.02, 0.0001, 20_000)).unwrap();
        assert!(!low_vis.ready && low_vis.advice().contains("visibility"), "{low_vis:?}");
        let noisy = SignalQuality::of(&fringes(1.0, 0.2, 0.05, 20_000)).unwrap();
        assert!(!noisy.ready && noisy.advice().contains("noise"), "{noisy:?}");
        assert!(SignalQuality::of(&[1.0; 5]).is_none());
        assert!(SignalQuality::of(&[f64::NAN; 100]).is_none());
    }
}
