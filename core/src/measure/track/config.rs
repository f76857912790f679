//! The tracker's inputs besides the samples: its settings ([`TrackConfig`]), an envelope
//! known to the caller, the Gouy correction and a model of the fringe along the trace.

use super::harmonic::Harmonic;
use crate::measure::extrema::HysteresisConfig;
use crate::measure::signal::{check_non_negative, check_positive, FringeError};

/// An envelope known to the caller (e.g. from an earlier, longer trace), in the model
/// `I = offset + amplitude·f(φ)`, constant over the trace.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KnownEnvelope {
    /// A, intensity units.
    pub offset: f64,
    /// B, intensity units (> 0).
    pub amplitude: f64,
    /// Harmonic distortion of the fringe (zero if unknown).
    pub harmonic: Harmonic,
    /// Standard uncertainty of A (propagated into the phase uncertainty).
    pub offset_sigma: f64,
    /// Standard uncertainty of B (propagated into the phase uncertainty).
    pub amplitude_sigma: f64,
}

/// Where the phase tracker takes the envelope A(t), B(t) from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum EnvelopeSource {
    /// From the data: fringe-extremum levels interpolated along the motion (path travelled
    /// and time), then refined jointly with the phase. Needs a trace covering at least one fringe.
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

/// Floor of the noise σ the samples are weighted with, relative to the fringe amplitude B. The
/// fringe model (harmonics, envelope walks, or a model's shape) is not exact to better than about
/// 1e-4 of B; weighting cleaner samples beyond that makes the smoother so stiff that Gauss-Newton
/// stops on a phase ramp where the gap stands still near a fringe extremum: a validation circle
/// planned with the true model on table2-ideal at 1e-5 detector noise read 0.0 to 149 nm with the
/// start phase at a floor of 1e-7, 0.0002-0.0003 nm at 1e-4 (test
/// `validate::tests::a_validation_on_a_clean_signal_reads_a_still_gap_at_any_start_phase`).
pub(super) const NOISE_FLOOR_REL: f64 = 1e-4;

/// Settings of the phase tracker. The random walks are the priors of the smoother: how
/// fast the phase may depart from the hint and the envelope may change, per fringe of
/// motion and per sample of time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackConfig {
    /// Envelope source.
    pub envelope: EnvelopeSource,
    /// Optional Gouy correction (its effect is ~1e-5 of dL at a 900 µm gap).
    pub gouy: Option<GouyCorrection>,
    /// Extremum detector settings (initial envelope and hint scale).
    pub hysteresis: HysteresisConfig,
    /// Random walk of the phase relative to the scaled hint, rad per √fringe of travel
    /// (hint nonlinearity, local scale errors).
    pub phase_walk_rad_per_sqrt_fringe: f64,
    /// Random walk of the phase in time, rad per √sample (thermal drift, stage noise).
    pub phase_noise_rad_per_sqrt_sample: f64,
    /// Random walk of A and B relative to B, per √fringe of travel (coupling changes).
    pub envelope_walk_per_sqrt_fringe: f64,
    /// Random walk of A and B relative to B, per √sample (laser power drift).
    pub envelope_noise_per_sqrt_sample: f64,
    /// Prior standard deviation of the relative hint-scale error when the extrema cannot
    /// measure it (upper bound otherwise).
    pub scale_prior_sigma: f64,
    /// Phase walk (rad, 1σ) allowed per 1/64 of the first fringe of travel, on top of the
    /// walks above; 0 turns it off. Set, the start phase comes from the samples before a
    /// stage has taken up its play (reversal error), not from the hint over the first
    /// fringe; a start on a fringe extremum is then less well pinned (phase known there
    /// only up to its sign).
    pub start_walk_rad: f64,
    /// Most Gauss-Newton iterations.
    pub max_iterations: usize,
    /// Fill `PhaseTrack::sigma_dl_nm` (one more n-sample buffer).
    pub per_sample_sigma: bool,
}

impl Default for TrackConfig {
    fn default() -> Self {
        Self {
            envelope: EnvelopeSource::FromData,
            gouy: None,
            hysteresis: HysteresisConfig::default(),
            phase_walk_rad_per_sqrt_fringe: 0.02,
            phase_noise_rad_per_sqrt_sample: 1e-5,
            envelope_walk_per_sqrt_fringe: 0.01,
            envelope_noise_per_sqrt_sample: 1e-5,
            scale_prior_sigma: 0.05,
            start_walk_rad: 0.0,
            max_iterations: 20,
            per_sample_sigma: false,
        }
    }
}

impl TrackConfig {
    pub(super) fn validate(&self) -> Result<(), FringeError> {
        self.hysteresis.validate()?;
        check_positive("phase_walk_rad_per_sqrt_fringe", self.phase_walk_rad_per_sqrt_fringe)?;
        check_non_negative("phase_noise_rad_per_sqrt_sample", self.phase_noise_rad_per_sqrt_sample)?;
        check_non_negative("start_walk_rad", self.start_walk_rad)?;
        check_positive("envelope_walk_per_sqrt_fringe", self.envelope_walk_per_sqrt_fringe)?;
        check_non_negative("envelope_noise_per_sqrt_sample", self.envelope_noise_per_sqrt_sample)?;
        check_positive("scale_prior_sigma", self.scale_prior_sigma)?;
        if self.max_iterations == 0 {
            return Err(FringeError::InvalidParameter {
                name: "max_iterations",
                value: 0.0,
                reason: "must be at least 1",
            });
        }
        if let EnvelopeSource::Known(k) = self.envelope {
            if !k.offset.is_finite() {
                return Err(FringeError::InvalidParameter {
                    name: "envelope.offset",
                    value: k.offset,
                    reason: "must be finite",
                });
            }
            check_positive("envelope.amplitude", k.amplitude)?;
            check_non_negative("envelope.offset_sigma", k.offset_sigma)?;
            check_non_negative("envelope.amplitude_sigma", k.amplitude_sigma)?;
            let names = [
                "envelope.harmonic.cos_rel",
                "envelope.harmonic.sin_rel",
                "envelope.harmonic.cos3_rel",
                "envelope.harmonic.sin3_rel",
            ];
            for (name, v) in names.into_iter().zip(k.harmonic.coefficients()) {
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

/// A model of the fringe along a trace, per sample: the tracker fits
/// `I = A + B·f(φ)` with f's harmonics taken from `harmonics`, and starts its envelope from
/// `A ≈ o + g·offset`, `B ≈ g·amplitude` (detector offset o and gain g fitted to the fringe
/// extrema), so that only departures from the model's envelope are a random walk.
#[derive(Debug, Clone, Copy)]
pub struct FringeModel<'a> {
    /// Harmonics relative to the fundamental.
    pub harmonics: &'a [Harmonic],
    /// Fringe offset, any unit (the same as `amplitude`).
    pub offset: &'a [f64],
    /// Fundamental's amplitude (> 0), the unit of `offset`.
    pub amplitude: &'a [f64],
}
