//! What a session gives the moves of the lamella: the calibrated model (the identified
//! extrinsics, their uncertainty, the effects a diagnosis added) and the poses whose gap its
//! sweeps measured, from which a bench without a tunable laser tracks the fringes.

use super::{Session, SessionError};
use crate::identify::verdict::Verdict as FitVerdict;
use crate::model::phase::PhaseModel;
use crate::position::{Placement, Reference, Uncertainty};
use crate::trace::TraceKind;
use std::path::Path;

impl Session {
    /// The placement this session's calibration gives on `base` (the bench's nominal robot,
    /// optics and air): its extrinsics (the diagnosis's refit when it made one) with the
    /// calibration's uncertainty, and the diagnosis's effects. Refused when the session holds
    /// no calibration, or one whose model does not fit its data.
    pub fn placement(&self, base: &PhaseModel, source: &str) -> Result<Placement, String> {
        let c = self.calibration.as_ref().ok_or("the session holds no calibration: calibrate first")?;
        if let Some(fit) = c.fit.as_ref().filter(|f| f.verdict != FitVerdict::Fits) {
            let why = match fit.verdict {
                FitVerdict::DoesNotFit => "the model does not fit its data",
                _ => "two branches fit its data equally well",
            };
            return Err(format!(
                "the session's calibration is not a calibration ({why}): its extrinsics cannot place the lamella"
            ));
        }
        let diagnosis = self.diagnosis.as_ref();
        let extrinsics = diagnosis.and_then(|d| d.extrinsics).unwrap_or(c.extrinsics);
        let effects = diagnosis.map(|d| d.model_effects.clone()).unwrap_or_default();
        Placement::new(base, extrinsics, Some(Uncertainty::of_report(c)), &effects, source).map_err(|e| e.to_string())
    }

    /// The poses whose gap a sweep measured: every whole sweep of the session's calibration
    /// (analysed without the extrinsics, at the tilt `model` gives there) and the end of every
    /// move a sweep measured. A sweep that cannot be analysed is left out.
    pub fn position_references(&self, dir: &Path, model: &PhaseModel) -> Result<Vec<Reference>, SessionError> {
        let mut out = Vec::new();
        for r in self.traces.iter().filter(|t| t.complete && t.kind == TraceKind::WavelengthSweep) {
            let trace = self.load_trace(dir, r)?;
            if let Ok(reference) = Reference::of_sweep(&trace, model, &format!("the calibration's sweep `{}`", r.label))
            {
                out.push(reference);
            }
        }
        out.extend(self.moves.iter().filter_map(|m| m.as_reference()));
        Ok(out)
    }
}
