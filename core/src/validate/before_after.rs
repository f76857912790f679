//! The validation before and after calibration: every validation motion planned with the
//! nominal extrinsics and with the identified ones, run one after the other on the same bench and
//! both measured with the identified model (the best knowledge of the cavity).

use crate::bench::Bench;
use crate::model::extrinsics::Extrinsics;
use crate::model::phase::PhaseModel;
use crate::validate::{
    record_validation, Compensation, RecordedValidation, ValidationError, ValidationFigure, ValidationMotion,
};

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
/// after the other; their fringe analyses then run in parallel (the same figures as measuring
/// each right after its run: the analysis reads only the recorded trace).
pub fn run_before_and_after(
    bench: &mut dyn Bench,
    nominal: &PhaseModel,
    identified: &Extrinsics,
) -> Vec<BeforeAndAfter> {
    use rayon::prelude::*;
    let analysis = PhaseModel { extrinsics: *identified, ..nominal.clone() };
    let planned_nominal = nominal.extrinsics;
    let none = Compensation::default();
    let mut recorded = Vec::new();
    for motion in ValidationMotion::ALL {
        let before = record_validation(bench, &analysis, &planned_nominal, motion, [0.0; 6], &none);
        let after = record_validation(bench, &analysis, identified, motion, [0.0; 6], &none);
        recorded.push((motion, before, after));
    }
    let measure = |r: Result<RecordedValidation, ValidationError>| r.and_then(|r| r.measure(&analysis));
    recorded
        .into_par_iter()
        .map(|(motion, before, after)| {
            let (before, after) = rayon::join(|| measure(before), || measure(after));
            BeforeAndAfter { motion, before, after }
        })
        .collect()
}
