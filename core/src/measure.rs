//! Trace → measurement: the motion hint from the recorded joints, then fringe analysis (motions) or the absolute gap (sweeps).
//! Owns the choice of analysis for a trace and the phase convention shared with the identifier.
//!
//! Phase convention: every length measured from fringes is *phase-equivalent*:
//! `Δφ·λ/(4π·n_air)`, with φ the model's fringe phase ([`FabryPerot::fringe_phase_rad`]),
//! which includes the tilt path term (the fringes follow the perpendicular fiber-to-lamella
//! distance, `L·cos γ`) and the Gouy phase. The identifier predicts the same quantity from the
//! same model, so bench and fit cannot disagree on conventions.

use crate::fringes::{self, CountDirection, FringeCount, HysteresisConfig, PhaseTrack, TrackConfig};
use crate::model::air::{air_index_ciddor, AmbientConditions};
use crate::model::extrinsics::Extrinsics;
use crate::model::kinematics::Chain;
use crate::model::optics::{FabryPerot, OpticalParams};
use crate::model::robot::RobotDescription;
use crate::sweep::{self, GapEstimate, SweepConfig, SweepFit};
use crate::trace::Trace;
use std::f64::consts::PI;
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
        source: fringes::FringeError,
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

/// The model the analysis uses to predict the phase from the joints: the nominal (or current
/// best) robot and extrinsics, the optics and the air.
#[derive(Debug, Clone)]
pub struct PhaseModel {
    /// Robot chain.
    pub chain: Chain,
    /// Extrinsics (nominal before calibration).
    pub extrinsics: Extrinsics,
    /// Optics.
    pub optics: OpticalParams,
    /// Air index.
    pub n_air: f64,
}

impl PhaseModel {
    /// The model with the given parts; the air index from the ambient conditions at `wavelength_nm`.
    pub fn new(
        robot: RobotDescription,
        extrinsics: Extrinsics,
        optics: OpticalParams,
        ambient: &AmbientConditions,
        wavelength_nm: f64,
    ) -> Result<Self, String> {
        let n_air = air_index_ciddor(wavelength_nm, ambient).map_err(|e| format!("ambient conditions: {e}"))?;
        Ok(Self { chain: Chain::new(robot), extrinsics, optics, n_air })
    }

    /// The phase-equivalent gap (nm) at joints `q_display` (µm, °) and vacuum wavelength
    /// `wavelength_nm`: `φ·λ/(4π·n)`.
    pub fn phase_gap_nm(&self, fp: &FabryPerot, q_display: &[f64; 6]) -> f64 {
        let q = self.chain.description().q_from_display(q_display);
        let wte = self.chain.end_effector(&q);
        match self.extrinsics.cavity(&wte) {
            Ok(c) => {
                fp.fringe_phase_rad(c.length_um.abs(), c.tilt_rad) * fp.wavelength_nm() / (4.0 * PI * fp.medium_index())
            }
            Err(_) => f64::NAN,
        }
    }

    /// The motion hint of a trace: predicted phase-equivalent gap change (nm) per sample,
    /// relative to the first sample.
    pub fn hint_nm(&self, trace: &Trace, wavelength_nm: f64) -> Result<Vec<f64>, String> {
        let fp = FabryPerot::new(&self.optics, wavelength_nm, self.n_air).map_err(|e| e.to_string())?;
        let mut out = Vec::with_capacity(trace.len());
        let mut first = None;
        for i in 0..trace.len() {
            let g = self.phase_gap_nm(&fp, &trace.joints_display(i));
            if !g.is_finite() {
                return Err(format!("sample {i}: the beam misses the lamella at these joints"));
            }
            let g0 = *first.get_or_insert(g);
            out.push(g - g0);
        }
        Ok(out)
    }
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
}

/// What a sweep trace gave.
#[derive(Debug, Clone)]
pub struct SweepMeasurement {
    /// The model fit (with its FFT seed).
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

/// True when the trace is a wavelength sweep: the wavelength varies while the joints stay.
pub fn is_sweep(trace: &Trace) -> bool {
    let span = |c: &[f64]| {
        let (lo, hi) = c.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| (a.min(v), b.max(v)));
        hi - lo
    };
    let wl = span(&trace.wavelength_nm);
    let joints_still = (0..6).all(|j| span(trace.joint_column(j)) < 0.05);
    wl > 0.1 && joints_still
}

/// Analyse a trace with the phase model.
pub fn analyse(trace: &Trace, model: &PhaseModel) -> Result<Measurement, MeasureError> {
    let label = trace.meta.label.clone();
    if trace.is_empty() {
        return Err(MeasureError::Trace { label, problem: "no samples".into() });
    }
    if is_sweep(trace) {
        let cfg = SweepConfig { n_air: model.n_air, gouy_waist_nm: Some(model.optics.mode_field_radius_um * 1e3) };
        let fit = sweep::fit_gap(&trace.wavelength_nm, &trace.irradiance, &cfg)
            .map_err(|source| MeasureError::Sweep { label: label.clone(), source })?;
        let peak_fsr = sweep::peak_fsr_gap(&trace.wavelength_nm, &trace.irradiance, model.n_air).ok();
        return Ok(Measurement::Sweep(SweepMeasurement { fit, peak_fsr }));
    }
    let wavelength_nm = trace.wavelength_nm[0];
    let hint = model.hint_nm(trace, wavelength_nm).map_err(|problem| MeasureError::Trace { label: label.clone(), problem })?;
    let track = fringes::track_phase(&trace.irradiance, &hint, wavelength_nm, model.n_air, &TrackConfig::default())
        .map_err(|source| MeasureError::Fringes { label: label.clone(), source })?;
    let count = fringes::count_extrema(
        &trace.irradiance,
        CountDirection::Hint(&hint),
        wavelength_nm,
        model.n_air,
        &HysteresisConfig::default(),
    )
    .map_err(|source| MeasureError::Fringes { label, source })?;
    Ok(Measurement::Motion(MotionMeasurement { track, count, hint_nm: hint, wavelength_nm, n_air: model.n_air }))
}
