//! Trace → measurement: the motion hint from the recorded joints, then fringe analysis (motions) or the absolute gap (sweeps).
//! Owns the choice of analysis for a trace. Lengths from fringes are phase-equivalent
//! ([`crate::model::phase`]), the quantity the identifier predicts from the same model, so
//! bench and fit cannot disagree on conventions.
//!
//! The analyses: extremum counting ([`extrema`]), sub-fringe phase tracking ([`track`]),
//! the absolute gap from a wavelength sweep ([`sweep`]), the signal quality before
//! calibration ([`alignment`]), and what they share ([`signal`]).

pub mod alignment;
pub mod extrema;
pub mod hint;
pub mod hint_led;
pub mod live_count;
pub mod model_free;
pub mod signal;
pub mod sweep;
pub mod track;

pub use self::sweep::full_model::refine_gap_full_model;

use self::extrema::{CountDirection, FringeCount, HysteresisConfig};
use self::signal::FringeError;
use self::sweep::{GapEstimate, SweepConfig, SweepFit};
use self::track::{PhaseTrack, TrackConfig};
use crate::model::phase::PhaseModel;
use crate::trace::Trace;
use thiserror::Error;

/// Why a trace could not be analysed.
#[derive(Debug, Error)]
pub enum MeasureError {
    /// The trace is empty or inconsistent.
    #[error("trace `{label}`: {problem}")]
    Trace {
        /// The trace's label.
        label: String,
        /// What is wrong.
        problem: String,
    },
    /// Fringe analysis failed.
    #[error("trace `{label}`: fringe analysis: {source}")]
    Fringes {
        /// The trace's label.
        label: String,
        /// The analysis error.
        source: FringeError,
    },
    /// Sweep analysis failed.
    #[error("trace `{label}`: wavelength sweep: {source}")]
    Sweep {
        /// The trace's label.
        label: String,
        /// The analysis error.
        source: sweep::SweepError,
    },
}

/// What a motion trace gave.
#[derive(Debug, Clone)]
pub struct MotionMeasurement {
    /// Sub-fringe phase tracking.
    pub track: PhaseTrack,
    /// Extremum counting (the paper's method), directions from the hint.
    pub count: FringeCount,
    /// The motion hint that was used (nm).
    pub hint_nm: Vec<f64>,
    /// Vacuum wavelength (nm) and air index used.
    pub wavelength_nm: f64,
    /// Air index used.
    pub n_air: f64,
    /// Whether the start phase came from the samples ([`AnalyseOptions::free_start`], or a
    /// motion shorter than [`SHORT_MOTION_FRINGES`]).
    pub free_start: bool,
    /// Whether the phase was tracked with the model's fringe shape ([`AnalyseOptions::shaped`]);
    /// false when it was not asked for, or when the model's shape could not be computed along
    /// the trace or tracked and the harmonic profile estimated from the data was used instead.
    pub shaped: bool,
    /// Why the shaped tracking was not used, when it was asked for and failed.
    pub shaped_fallback: Option<String>,
}

/// Motions shorter than this many fringes of hint travel are tracked with the free start
/// whatever the options say. Their harmonic windows do not fit, and the smoother traded the
/// unmodelled harmonic against the hint scale: a 1.5-fringe synthetic motion ended 8.79 nm
/// off without it and 1.55 nm off with it (`measure::track::tests::a_free_start_tracks_short_motions`).
/// On `tests/cli_diagnose.rs`'s hidden-pivot session the diagnosis then named the hidden
/// pivot itself, q4 along Z_w, at 19.93 ± 0.19 µm (an equivalent and a second pivot without).
pub const SHORT_MOTION_FRINGES: f64 = 2.0;

/// What a sweep trace gave.
#[derive(Debug, Clone)]
pub struct SweepMeasurement {
    /// The gap from the full multi-beam optics model fitted to the sweep (seeded by `fit`):
    /// the phase-equivalent gap, i.e. the perpendicular fiber-to-lamella distance.
    pub gap: GapEstimate,
    /// The two-beam model fit (with its FFT seed) that seeds the full-model fit.
    pub fit: SweepFit,
    /// The paper's reflection-peak method, when it works on this sweep.
    pub peak_fsr: Option<GapEstimate>,
}

/// The analysis of one trace.
#[derive(Debug, Clone)]
pub enum Measurement {
    /// A motion at a fixed wavelength: dL.
    Motion(MotionMeasurement),
    /// A wavelength sweep at fixed joints: the absolute gap.
    Sweep(SweepMeasurement),
}

/// Loose phase walk over the first fringe of a motion ([`TrackConfig::start_walk_rad`]) with
/// [`AnalyseOptions::free_start`]. Measured with `cargo test -p photorobot-e2e --test
/// fringes_on_virtual_bench tracked_gap`: with 2 µm of play on a lateral stage (a 20.8 nm
/// stall of the phase), tracked gap changes within 0.6 nm of the truth on single-joint traces
/// of 3 fringes, where the tracker had seen 0.8 nm of the 20.8 nm without it.
pub const START_WALK_RAD: f64 = 0.005;

/// How [`analyse_with`] tracks a motion.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct AnalyseOptions {
    /// The start phase from the samples alone ([`START_WALK_RAD`]), so that a stage taking up
    /// its play at the start of the motion (a reversal error) shows in dL. Off, the start
    /// phase follows the motion hint over the first fringe: dL then starts as if every
    /// moving stage had approached in its direction of motion
    /// ([`crate::identify::measurements`] models it so). Off is the better estimate
    /// otherwise: with it on, the start offsets on the calibration traces of table2-ideal
    /// grew from ≤ 0.3 nm to ≤ 1.4 nm on lateral moves and up to 36 nm on a tilt scan at a
    /// lateral offset (`PER_TRACE=1 cargo run --release -p photorobot-core --example
    /// calib_debug -- table2-ideal joint 1`).
    pub free_start: bool,
    /// `Some(k)`: the phase free to leave the motion hint in time
    /// ([`FREE_PHASE_RAD_PER_SQRT_SAMPLE`]) when the hint travels under
    /// [`SHORT_MOTION_FRINGES`] from sample `k` on: for a validation motion (after its
    /// envelope dither), planned so that the model's gap stands still, whose fringes measure
    /// how far the real gap strays from that plan. With the default walk (1e-5 rad per
    /// √sample, 0.5 nm over a 160 000-sample circle) the tracker shares a few nm of gap
    /// change, which moves the intensity less than a fringe would, between the phase and the
    /// envelope, and the validation figure comes out too small: a circle whose real gap
    /// moved by 8.1 nm read 3.9 nm, free 8.4 nm (`validation_truth` example; test
    /// `validate::tests::a_validation_circle_tracks_its_small_gap_change`). A motion whose
    /// hint moves by more keeps the default: its fringes pin the phase (see [`crate::validate`]).
    pub free_phase_after: Option<usize>,
    /// Track with the model's fringe shape at every sample (`track::track_phase_shaped`
    /// with [`PhaseModel::hint_and_shape`]) instead of a harmonic profile estimated from the data.
    pub shaped: bool,
}

/// The phase's random walk in time of [`AnalyseOptions::free_phase_after`], rad per √sample: 0.03
/// rad (4 nm) over a 100 000-sample motion. 1e-4 and 1e-3 tracked that circle alike (8.3 nm).
pub const FREE_PHASE_RAD_PER_SQRT_SAMPLE: f64 = 1e-4;

/// Analyse a trace with the phase model ([`analyse_with`], default options).
pub fn analyse(trace: &Trace, model: &PhaseModel) -> Result<Measurement, MeasureError> {
    analyse_with(trace, model, &AnalyseOptions::default())
}

/// Analyse a trace with the phase model.
pub fn analyse_with(trace: &Trace, model: &PhaseModel, options: &AnalyseOptions) -> Result<Measurement, MeasureError> {
    let label = trace.meta.label.clone();
    if trace.is_empty() {
        return Err(MeasureError::Trace { label, problem: "no samples".into() });
    }
    if crate::trace::is_sweep(trace) {
        return analyse_sweep(trace, model, None);
    }
    let wavelength_nm = trace.wavelength_nm[0];
    let trace_error = |problem| MeasureError::Trace { label: label.clone(), problem };
    let (hint, shape) = if options.shaped {
        model.hint_and_shape(trace, wavelength_nm).map(|(hint, shape)| (hint, Some(shape))).map_err(trace_error)?
    } else {
        (model.hint_nm(trace, wavelength_nm).map_err(trace_error)?, None)
    };
    // The motion hint comes from a smooth model of the whole bench: stiff random walks of the
    // phase and the envelope relative to it track best (measured on the virtual bench with a
    // hint from extrinsics 20 % off: strategy 2 rms 1.9 nm vs 5.8 nm with the defaults).
    let fringe_nm = wavelength_nm / (2.0 * model.n_air);
    // Whether the hint travels under SHORT_MOTION_FRINGES from sample k on.
    let short_from = |k: usize| {
        let travel_nm: f64 = hint.get(k..).unwrap_or(&[]).windows(2).map(|w| (w[1] - w[0]).abs()).sum();
        travel_nm < SHORT_MOTION_FRINGES * fringe_nm
    };
    let free_start = options.free_start || short_from(0);
    let free_phase = options.free_phase_after.is_some_and(short_from);
    let track_cfg = TrackConfig {
        per_sample_sigma: true,
        envelope_walk_per_sqrt_fringe: 0.003,
        phase_walk_rad_per_sqrt_fringe: 0.005,
        start_walk_rad: if free_start { START_WALK_RAD } else { 0.0 },
        phase_noise_rad_per_sqrt_sample: if free_phase {
            FREE_PHASE_RAD_PER_SQRT_SAMPLE
        } else {
            TrackConfig::default().phase_noise_rad_per_sqrt_sample
        },
        ..TrackConfig::default()
    };
    // By default the harmonics are estimated along the path, not taken from the optics model: the
    // shaped tracker (`track::track_phase_shaped` with `PhaseModel::hint_and_shape`) is far
    // better when the model is right (table2-ideal, tracked dL against the truth: rotations
    // 2.3 → 0.18 nm rms, tilt scans 9.6 → 0.06 nm), but fragile when it is not: with the
    // design extrinsics the modelled tilt is off by ~1°, the 2nd harmonic's phase (it turns by
    // 2k·θ²·L) by radians, and lateral moves come out 4 nm off instead of 0.07 nm; on the
    // hidden-pivot diagnosis the discriminating rotations go wrong.
    // `AnalyseOptions::shaped` is for a model already fitted (the diagnosis's re-analysis,
    // `diagnose::REANALYSE_OPTIONS`).
    // A trace the shaped tracker fails on is tracked the default way: the caller asked for the
    // better estimate, not for losing the trace.
    let shaped_track = shape.map(|shape| {
        track::track_phase_shaped(&trace.irradiance, &hint, &shape.as_model(), wavelength_nm, model.n_air, &track_cfg)
            .map_err(|e| e.to_string())
    });
    let (track, shaped, shaped_fallback) = match shaped_track {
        Some(Ok(track)) => (track, true, None),
        other => {
            let track = track::track_phase(&trace.irradiance, &hint, wavelength_nm, model.n_air, &track_cfg)
                .map_err(|source| MeasureError::Fringes { label: label.clone(), source })?;
            (track, false, other.and_then(Result::err))
        }
    };
    let count = extrema::count_extrema(
        &trace.irradiance,
        CountDirection::Hint(&hint),
        wavelength_nm,
        model.n_air,
        &HysteresisConfig::default(),
    )
    .map_err(|source| MeasureError::Fringes { label, source })?;
    Ok(Measurement::Motion(MotionMeasurement {
        track,
        count,
        hint_nm: hint,
        wavelength_nm,
        n_air: model.n_air,
        free_start,
        shaped,
        shaped_fallback,
    }))
}

/// The part of a sweep's analysis that does not depend on the extrinsics: the two-beam fit
/// with its FFT seed, and the paper's reflection-peak gap. They read only the air index and the
/// fiber's mode field, which every model of one bench shares, so an identifier that analyses the
/// same sweeps with several extrinsics computes them once ([`sweep_seed`], [`analyse_sweep`]).
#[derive(Debug, Clone)]
pub struct SweepSeed {
    cfg: SweepConfig,
    fit: SweepFit,
    peak_fsr: Option<GapEstimate>,
}

/// `estimate` (a gap from sweep `trace`) with the sweep's scale uncertainty added to its σ: a
/// sweep timed by a wavelength monitor knows its speed only to the monitor line's slope, and the
/// gap is off by the same fraction (30 ppm, 27 nm at 900 µm, on the E-712's 16-bit input).
pub fn with_scale_sigma(trace: &Trace, estimate: GapEstimate) -> GapEstimate {
    let scale_um = estimate.gap_um.abs() * trace.meta.wavelength_scale_sigma_ppm * 1e-6;
    GapEstimate { sigma_um: estimate.sigma_um.hypot(scale_um), ..estimate }
}

/// The sweep fit's configuration for a model: its air index and the fiber's mode field (Gouy).
fn sweep_config(model: &PhaseModel) -> SweepConfig {
    SweepConfig { n_air: model.n_air, gouy_waist_nm: Some(model.optics.mode_field_radius_um * 1e3) }
}

/// The extrinsics-free part of the analysis of sweep `trace` under `model` ([`SweepSeed`]).
pub fn sweep_seed(trace: &Trace, model: &PhaseModel) -> Result<SweepSeed, MeasureError> {
    let label = || trace.meta.label.clone();
    if trace.is_empty() {
        return Err(MeasureError::Trace { label: label(), problem: "no samples".into() });
    }
    let cfg = sweep_config(model);
    let mut fit = sweep::fit_gap(&trace.wavelength_nm, &trace.irradiance, &cfg)
        .map_err(|source| MeasureError::Sweep { label: label(), source })?;
    fit.estimate = with_scale_sigma(trace, fit.estimate);
    let peak_fsr = sweep::peak_fsr_gap(&trace.wavelength_nm, &trace.irradiance, model.n_air).ok();
    Ok(SweepSeed { cfg, fit, peak_fsr })
}

/// Analyse sweep `trace` with `model`: the two-beam fit ([`sweep_seed`], reused from `seed` when
/// it was made with the same air index and mode field), refined with the model's full optics at
/// the tilt its extrinsics give in the sweep's pose.
pub fn analyse_sweep(trace: &Trace, model: &PhaseModel, seed: Option<&SweepSeed>) -> Result<Measurement, MeasureError> {
    let fresh;
    let seed = match seed {
        Some(s) if s.cfg == sweep_config(model) => s,
        _ => {
            fresh = sweep_seed(trace, model)?;
            &fresh
        }
    };
    let gap = refine_gap_full_model(&trace.wavelength_nm, &trace.irradiance, trace.joints_display(0), model, &seed.fit)
        .map(|g| with_scale_sigma(trace, g))
        .map_err(|problem| MeasureError::Trace { label: trace.meta.label.clone(), problem })?;
    Ok(Measurement::Sweep(SweepMeasurement { gap, fit: seed.fit.clone(), peak_fsr: seed.peak_fsr }))
}

/// The gap along the beam (µm) of sweep `trace`, measured without the extrinsics: the two-beam
/// fit ([`sweep_seed`]: the air index and the fiber's mode field) refined with the model's full
/// optics at a tilt `tilt_rad` between the lamella normal and the beam that the caller knows
/// (a requested tilt), not the one the model's extrinsics give. Its σ is the fit's.
pub fn sweep_gap_along_beam(trace: &Trace, model: &PhaseModel, tilt_rad: f64) -> Result<GapEstimate, MeasureError> {
    let seed = sweep_seed(trace, model)?;
    let perpendicular =
        sweep::full_model::refine_gap_at_tilt(&trace.wavelength_nm, &trace.irradiance, tilt_rad, model, &seed.fit)
            .map(|g| with_scale_sigma(trace, g))
            .map_err(|problem| MeasureError::Trace { label: trace.meta.label.clone(), problem })?;
    // The fit pins g·(1 − θ²/2); the gap along the beam is g.
    let along = 1.0 - tilt_rad * tilt_rad / 2.0;
    Ok(GapEstimate { gap_um: perpendicular.gap_um / along, sigma_um: perpendicular.sigma_um / along, ..perpendicular })
}
