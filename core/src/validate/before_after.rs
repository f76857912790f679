//! The validation before and after calibration: every validation motion planned with the
//! nominal extrinsics and with the identified ones, run one after the other on the same bench and
//! both measured with the identified model (the best knowledge of the cavity).

use crate::bench::Bench;
use crate::model::extrinsics::Extrinsics;
use crate::model::phase::PhaseModel;
use crate::validate::{run_validation, ValidationError, ValidationFigure, ValidationMotion};

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
/// each; `nominal` is the software's model before calibration.
pub fn run_before_and_after(
    bench: &mut dyn Bench,
    nominal: &PhaseModel,
    identified: &Extrinsics,
) -> Vec<BeforeAndAfter> {
    let analysis = PhaseModel { extrinsics: *identified, ..nominal.clone() };
    let planned_nominal = nominal.extrinsics;
    let mut pairs = Vec::new();
    for motion in ValidationMotion::ALL {
        let before = run_validation(bench, &analysis, &planned_nominal, motion, [0.0; 6]);
        let after = run_validation(bench, &analysis, identified, motion, [0.0; 6]);
        pairs.push(BeforeAndAfter { motion, before, after });
    }
    pairs
}
