//! The validation before and after calibration: every validation motion planned with the
//! nominal extrinsics and with the identified ones, run one after the other on the same bench and
//! both measured with the identified model (the best knowledge of the cavity); and the check of
//! a calibration already made, its motions alone. Each motion carries its proof
//! ([`crate::validate::evidence`]).

use crate::bench::Bench;
use crate::model::extrinsics::Extrinsics;
use crate::model::phase::PhaseModel;
use crate::validate::{
    record_validation, Compensation, RecordedValidation, StopSettings, ValidationError, ValidationFigure,
    ValidationMotion,
};
use std::sync::atomic::AtomicBool;
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

type Slot = Mutex<Option<Result<ValidationFigure, ValidationError>>>;

/// Every motion of [`ValidationMotion::ALL`] from q = 0, in order, planned with each of
/// `planned` in turn and measured with `analysis`, stopping where `stops` says. The bench runs
/// the motions one after the other; each run's fringe analysis starts on the compute pool as
/// soon as it is recorded, beside the bench's next run (the same figures as measuring each right
/// after its run: the analysis reads only the recorded trace).
fn run_all<const K: usize>(
    bench: &mut dyn Bench,
    analysis: &PhaseModel,
    planned: [Extrinsics; K],
    stops: &StopSettings,
) -> Vec<[Result<ValidationFigure, ValidationError>; K]> {
    let none = Compensation::default();
    let slots: Vec<[Slot; K]> =
        ValidationMotion::ALL.iter().map(|_| std::array::from_fn(|_| Mutex::new(None))).collect();
    // In place: the bench stays on this thread, only the analyses go to the pool.
    rayon::in_place_scope(|scope| {
        for (motion, row) in ValidationMotion::ALL.into_iter().zip(&slots) {
            for (planned_with, slot) in planned.iter().zip(row) {
                let recorded = record_validation(
                    bench,
                    analysis,
                    planned_with,
                    motion,
                    [0.0; 6],
                    &none,
                    stops,
                    &AtomicBool::new(false),
                );
                scope.spawn(move |_| {
                    let figure = recorded.and_then(|r: RecordedValidation| r.measure(analysis));
                    *slot.lock().unwrap_or_else(PoisonError::into_inner) = Some(figure);
                });
            }
        }
    });
    slots
        .into_iter()
        .map(|row| {
            row.map(|slot| {
                slot.into_inner().unwrap_or_else(PoisonError::into_inner).expect("every analysis ran in the scope")
            })
        })
        .collect()
}

/// Every motion of [`ValidationMotion::ALL`] from q = 0, in order, "before" then "after" for
/// each; `nominal` is the software's model before calibration.
pub fn run_before_and_after(
    bench: &mut dyn Bench,
    nominal: &PhaseModel,
    identified: &Extrinsics,
    stops: &StopSettings,
) -> Vec<BeforeAndAfter> {
    let analysis = PhaseModel { extrinsics: *identified, ..nominal.clone() };
    ValidationMotion::ALL
        .into_iter()
        .zip(run_all(bench, &analysis, [nominal.extrinsics, *identified], stops))
        .map(|(motion, [before, after])| BeforeAndAfter { motion, before, after })
        .collect()
}

/// Check a calibration made earlier, without recalibrating: every motion of
/// [`ValidationMotion::ALL`] planned with `extrinsics` through the robot of `model` and measured
/// with the model carrying them, with their proof (what `photorobot validate` and the workbench's
/// check run).
pub fn check_calibration(
    bench: &mut dyn Bench,
    model: &PhaseModel,
    extrinsics: &Extrinsics,
    stops: &StopSettings,
) -> Vec<(ValidationMotion, Result<ValidationFigure, ValidationError>)> {
    let analysis = PhaseModel { extrinsics: *extrinsics, ..model.clone() };
    ValidationMotion::ALL
        .into_iter()
        .zip(run_all(bench, &analysis, [*extrinsics], stops))
        .map(|(motion, [figure])| (motion, figure))
        .collect()
}
