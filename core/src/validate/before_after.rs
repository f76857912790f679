//! The validation before and after calibration: every validation motion planned with the
//! nominal extrinsics and with the identified ones, run one after the other on the same bench and
//! both measured with the identified model (the best knowledge of the cavity).

use crate::bench::Bench;
use crate::model::extrinsics::Extrinsics;
use crate::model::phase::PhaseModel;
use crate::validate::{
    record_validation, Compensation, RecordedValidation, ValidationError, ValidationFigure, ValidationMotion,
};
use std::sync::{Mutex, PoisonError};

/// One validation motion, planned before and after calibration.
#[derive(Debug)]
pub struct BeforeAndAfter {
    /// The motion.
    pub motion: ValidationMotion,
    /// Planned with the nominal extrinsics.
    pub before: Result<ValidationFigure, ValidationError>,
    /// Planned with the identified extrinsics.
    pub after: Result<ValidationFigure, ValidationError>,
}

/// Every motion of [`ValidationMotion::ALL`] from q = 0, in order, "before" then "after" for
/// each; `nominal` is the software's model before calibration. The bench runs the motions one
/// after the other; each run's fringe analysis starts on the compute pool as soon as it is
/// recorded, beside the bench's next run (the same figures as measuring each right after its
/// run: the analysis reads only the recorded trace).
pub fn run_before_and_after(
    bench: &mut dyn Bench,
    nominal: &PhaseModel,
    identified: &Extrinsics,
) -> Vec<BeforeAndAfter> {
    let analysis = PhaseModel { extrinsics: *identified, ..nominal.clone() };
    let planned = [nominal.extrinsics, *identified];
    let none = Compensation::default();
    type Slot = Mutex<Option<Result<ValidationFigure, ValidationError>>>;
    let slots: Vec<[Slot; 2]> = ValidationMotion::ALL.iter().map(|_| [Mutex::new(None), Mutex::new(None)]).collect();
    // In place: the bench stays on this thread, only the analyses go to the pool.
    rayon::in_place_scope(|scope| {
        for (motion, pair) in ValidationMotion::ALL.into_iter().zip(&slots) {
            for (planned_with, slot) in planned.iter().zip(pair) {
                let recorded = record_validation(bench, &analysis, planned_with, motion, [0.0; 6], &none);
                let analysis = &analysis;
                scope.spawn(move |_| {
                    let figure = recorded.and_then(|r: RecordedValidation| r.measure(analysis));
                    *slot.lock().unwrap_or_else(PoisonError::into_inner) = Some(figure);
                });
            }
        }
    });
    ValidationMotion::ALL
        .into_iter()
        .zip(slots)
        .map(|(motion, [before, after])| {
            let figure = |slot: Slot| {
                slot.into_inner().unwrap_or_else(PoisonError::into_inner).expect("every analysis ran in the scope")
            };
            BeforeAndAfter { motion, before: figure(before), after: figure(after) }
        })
        .collect()
}
