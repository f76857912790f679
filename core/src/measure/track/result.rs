//! What the tracker returns.

use super::harmonic::Harmonic;

/// Result of phase tracking.
#[derive(Debug, Clone, PartialEq)]
pub struct PhaseTrack {
    /// Unwrapped fringe phase per sample, rad, in the model `I = A + B·f(φ)`; it increases
    /// when the motion hint increases.
    pub phase_rad: Vec<f64>,
    /// dL(t) relative to the first sample, nm (hint sign convention).
    pub dl_nm: Vec<f64>,
    /// Per-sample standard uncertainty of `dl_nm`, nm (from the marginal variances at the
    /// sample and at the start, correlation ignored: conservative); empty unless
    /// `TrackConfig::per_sample_sigma`.
    pub sigma_dl_nm: Vec<f64>,
    /// dL between the first and the last sample, nm.
    pub total_dl_nm: f64,
    /// Standard uncertainty of `total_dl_nm`, nm: fit part and harmonic part in quadrature.
    pub sigma_total_nm: f64,
    /// Fit part of `sigma_total_nm`: noise and envelope uncertainty (the envelope is
    /// estimated jointly and marginalised), scaled up by √χ² when the residuals exceed the
    /// noise model, nm.
    pub sigma_fit_nm: f64,
    /// Harmonic part of `sigma_total_nm`: cyclic error allowed by the uncertainty of the
    /// second-harmonic estimate at both ends, nm (zero with a fringe model, whose harmonics
    /// are taken as exact).
    pub sigma_harmonic_nm: f64,
    /// Ratio of true phase rate to hint phase rate (fitted; 1/(1 + hint scale error)).
    pub hint_scale: f64,
    /// Standard uncertainty of `hint_scale`.
    pub hint_scale_sigma: f64,
    /// Harmonic distortion used by the tracker (estimated or given; with a fringe model, the
    /// model's harmonics averaged over the trace).
    pub harmonic: Harmonic,
    /// White-noise σ of the intensity used as weight (estimated), intensity units.
    pub noise_sigma: f64,
    /// Mean squared residual over the noise variance (≈ 1 when the model fits).
    pub normalized_chi2: f64,
    /// Extrema used for the initial envelope and the hint scale.
    pub extrema_used: usize,
    /// Gauss-Newton iterations run.
    pub iterations: usize,
    /// Largest phase update of the last iteration, rad.
    pub last_update_rad: f64,
    /// Human-readable warnings (inconsistent extremum count, no convergence, ...).
    pub warnings: Vec<String>,
}

impl Default for PhaseTrack {
    fn default() -> Self {
        Self {
            phase_rad: Vec::new(),
            dl_nm: Vec::new(),
            sigma_dl_nm: Vec::new(),
            total_dl_nm: 0.0,
            sigma_total_nm: f64::NAN,
            sigma_fit_nm: f64::NAN,
            sigma_harmonic_nm: f64::NAN,
            hint_scale: f64::NAN,
            hint_scale_sigma: f64::NAN,
            harmonic: Harmonic::default(),
            noise_sigma: f64::NAN,
            normalized_chi2: f64::NAN,
            extrema_used: 0,
            iterations: 0,
            last_update_rad: f64::NAN,
            warnings: Vec::new(),
        }
    }
}
