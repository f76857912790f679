//! What a session gives the moves of the lamella: the calibrated model (the identified
//! extrinsics, their uncertainty, the effects a diagnosis added) and the poses whose gap its
//! sweeps measured, from which a bench without a tunable laser tracks the fringes.

use super::{DiagnosisRecord, Session, SessionError};
use crate::calibration::CalibrationReport;
use crate::identify::verdict::Verdict as FitVerdict;
use crate::model::phase::PhaseModel;
use crate::position::{MoveRecord, Placement, Reference, Uncertainty};
use crate::trace::{Trace, TraceKind};
use std::path::Path;

/// The placement a calibration gives on `base` (the bench's nominal robot, optics and air): its
/// extrinsics (the diagnosis's refit when it made one) with the calibration's uncertainty, and the
/// diagnosis's effects. Refused when the calibration's model does not fit its data.
pub fn placement_of(
    base: &PhaseModel,
    calibration: &CalibrationReport,
    diagnosis: Option<&DiagnosisRecord>,
    source: &str,
) -> Result<Placement, String> {
    if let Some(fit) = calibration.fit.as_ref().filter(|f| f.verdict != FitVerdict::Fits) {
        let why = match fit.verdict {
            FitVerdict::DoesNotFit => "the model does not fit its data",
            _ => "two branches fit its data equally well",
        };
        return Err(format!("the calibration is not a calibration ({why}): its extrinsics cannot place the lamella"));
    }
    let extrinsics = diagnosis.and_then(|d| d.extrinsics).unwrap_or(calibration.extrinsics);
    let effects = diagnosis.map(|d| d.model_effects.clone()).unwrap_or_default();
    Placement::new(base, extrinsics, Some(Uncertainty::of_report(calibration)), &effects, source)
        .map_err(|e| e.to_string())
}

/// The poses whose gap a sweep measured: every sweep of `traces` (analysed without the
/// extrinsics, at the tilt `model` gives there; one that cannot be analysed is left out) and the
/// end of every move of `moves` a sweep measured.
pub fn references_from(traces: &[&Trace], moves: &[MoveRecord], model: &PhaseModel) -> Vec<Reference> {
    let sweeps = traces.iter().filter(|t| crate::trace::is_sweep(t));
    let mut out: Vec<Reference> = sweeps
        .filter_map(|t| Reference::of_sweep(t, model, &format!("the calibration's sweep `{}`", t.meta.label)).ok())
        .collect();
    out.extend(moves.iter().filter_map(MoveRecord::as_reference));
    out
}

impl Session {
    /// The placement this session's calibration gives ([`placement_of`]); refused when the
    /// session holds no calibration.
    pub fn placement(&self, base: &PhaseModel, source: &str) -> Result<Placement, String> {
        let c = self.calibration.as_ref().ok_or("the session holds no calibration: calibrate first")?;
        placement_of(base, c, self.diagnosis.as_ref(), source)
    }

    /// The poses whose gap a sweep measured ([`references_from`]): the session's whole sweeps and
    /// the ends of its moves a sweep measured.
    pub fn position_references(&self, dir: &Path, model: &PhaseModel) -> Result<Vec<Reference>, SessionError> {
        let sweeps = self.traces.iter().filter(|t| t.complete && t.kind == TraceKind::WavelengthSweep);
        let traces = sweeps.map(|r| self.load_trace(dir, r)).collect::<Result<Vec<_>, _>>()?;
        Ok(references_from(&traces.iter().collect::<Vec<_>>(), &self.moves, model))
    }
}
