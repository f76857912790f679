//! What the Position view asks of the state: the placement the session's calibration gives, the
//! move planned for the target from where the bench stands (previewed as the fields change), and
//! sending the move to the worker. Planning and running are `photorobot_core::position`; the
//! state itself is [`crate::state::PositionState`].

use crate::state::{AppState, PreviewKey};
use crate::worker::Command;
use photorobot_core::position::{plan_move, MovePlan, Placement, ProofKind};
use photorobot_core::session::{placement_of, DiagnosisRecord};
use photorobot_core::trace::Trace;

impl AppState {
    /// The placement the session's calibration gives: the identified extrinsics with their
    /// uncertainty and the diagnosis's effects; why not, without a calibration that fits.
    pub fn placement(&self) -> Result<Placement, String> {
        let report = self.results.report.as_deref().ok_or("no calibration yet: run the wizard and Identify first")?;
        let diagnosis: Option<DiagnosisRecord> = match &self.diagnosis.result {
            Some(Ok(d)) => Some(DiagnosisRecord::with_model(d, &self.diagnosis.effects, &[])),
            _ => self.diagnosis.loaded_record.clone(),
        };
        placement_of(&self.worker.nominal, report, diagnosis.as_ref(), "this session's calibration")
    }

    /// The move planned for the target from where the bench stands (planned again when the
    /// target, the bench's joints or the calibration change); `None` without a calibration.
    pub fn position_preview(&mut self) -> Option<&Result<MovePlan, String>> {
        let placement = self.placement().ok()?;
        let p = &self.position;
        let key = PreviewKey {
            target: p.target,
            keep_gap: p.keep_gap,
            measure_tilt: p.measure_tilt,
            from: self.q_display,
            extrinsics: placement.model.extrinsics.to_array(),
        };
        if self.position.preview.as_ref().is_none_or(|(k, _)| *k != key) {
            let proof = if self.worker.tunable_laser {
                ProofKind::Sweep
            } else {
                ProofKind::None(
                    "the fringes from the nearest pose a sweep measured (chosen when the move starts)".into(),
                )
            };
            let planned = plan_move(&placement, self.q_display, &key.target, key.keep_gap, proof)
                .map(|mut plan| {
                    plan.measure_tilt = key.measure_tilt;
                    plan
                })
                .map_err(|e| e.to_string());
            self.position.preview = Some((key, planned));
        }
        self.position.preview.as_ref().map(|(_, r)| r)
    }

    /// Move the lamella to the target (the worker runs it; the record comes back as
    /// [`crate::worker::Event::Moved`]). On a bench without a tunable laser the worker tracks the
    /// fringes from the nearest pose the session's sweeps or earlier moves measured.
    pub fn go_position(&mut self) {
        if self.busy.is_some() || self.wizard.running.is_some() {
            return;
        }
        let placement = match self.placement() {
            Ok(p) => p,
            Err(e) => {
                self.position.refused = Some(e);
                return;
            }
        };
        self.worker.live.store(false, std::sync::atomic::Ordering::Relaxed);
        self.position.refused = None;
        let sweeps: Vec<Trace> = if self.worker.tunable_laser {
            Vec::new()
        } else {
            self.all_traces().into_iter().filter(|t| photorobot_core::trace::is_sweep(t)).cloned().collect()
        };
        let references = photorobot_core::session::references_from(
            &sweeps.iter().collect::<Vec<_>>(),
            &self.position.moves,
            &placement.model,
        );
        let (target, keep_gap, measure_tilt) =
            (self.position.target, self.position.keep_gap, self.position.measure_tilt);
        self.worker.send(Command::SetPace(self.settings.pace()));
        self.worker.send(Command::Move { placement: Box::new(placement), target, keep_gap, references, measure_tilt });
    }
}
