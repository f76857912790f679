//! Validation with and without the named effects: the validation motions are planned through
//! the IGM of the calibrated model (the nominal robot and the calibrated extrinsics) and through
//! the IGM of the extended model (the robot with the geometric effects the diagnosis added, and
//! the extrinsics refitted with them), run on the bench, and both measured with the extended
//! model. The extended model's reversal errors and drift are compensated in its plan ([`crate::validate::Compensation`]):
//! its commands lead the wanted poses by half of each stage's play in its direction of travel
//! ([`crate::validate::plan_with_play`]), and its waypoints move along the beam against the
//! drift expected when the bench reaches them.

use crate::bench::Bench;
use crate::calibration::{thin, CURVE_POINTS};
use crate::model::effects::{apply_all, apply_optics, Effect, EffectError};
use crate::model::extrinsics::Extrinsics;
use crate::model::phase::PhaseModel;
use crate::validate::{run_validation_planned, Compensation, ValidationMotion};
use serde::{Deserialize, Serialize};

/// One validation motion run with the model without and with the effects.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EffectValidationRow {
    /// The motion.
    pub motion: String,
    /// FP cavity variation, peak to peak, planned with the calibrated model (nm).
    pub without_effect_nm: Option<f64>,
    /// The same planned with the extended model (nm).
    pub with_effect_nm: Option<f64>,
    /// Why a figure is missing.
    #[serde(default)]
    pub note: Option<String>,
    /// The variation along the motion planned without the effects (nm, thinned for plots).
    #[serde(default)]
    pub without_curve_nm: Vec<f64>,
    /// The same planned with them (nm).
    #[serde(default)]
    pub with_curve_nm: Vec<f64>,
}

/// The model with the geometric effects applied to its robot, the optical ones (a back face,
/// the Gouy phase) to its optics, and the given extrinsics. The optics set the fringe's shape
/// that the validation measurement and the diagnosis's re-analysis track with. Path effects
/// (drift, path scale) do not change where the IGM sends the robot nor the fringe's shape;
/// they are left out.
pub fn extended_model(
    base: &PhaseModel,
    extrinsics: Extrinsics,
    effects: &[Effect],
) -> Result<PhaseModel, EffectError> {
    let robot = apply_all(effects, base.chain.description())?;
    Ok(PhaseModel {
        chain: crate::model::kinematics::Chain::new(robot),
        extrinsics,
        optics: apply_optics(effects, &base.optics),
        ..base.clone()
    })
}

/// Run every validation motion twice on `bench`: planned with `base` (the nominal robot) and the
/// calibrated extrinsics `without`, and planned with the extended model (`effects` on the robot,
/// extrinsics `with`); both measured with the extended model.
pub fn validate_with_effects(
    bench: &mut dyn Bench,
    base: &PhaseModel,
    without: &Extrinsics,
    with: &Extrinsics,
    effects: &[Effect],
) -> Result<Vec<EffectValidationRow>, EffectError> {
    let extended = extended_model(base, *with, effects)?;
    // The extended model's reversal errors and drift: its plan compensates them.
    let compensation = Compensation::of_effects(effects, base.chain.description());
    let plain = PhaseModel { extrinsics: *without, ..base.clone() };
    Ok(ValidationMotion::ALL
        .iter()
        .map(|&m| {
            let a = run_validation_planned(bench, &plain, without, &extended, m, [0.0; 6], &Compensation::default());
            let b = run_validation_planned(bench, &extended, with, &extended, m, [0.0; 6], &compensation);
            let note = crate::validate::pair_note(&a, &b);
            let curve = |v: &[f64]| thin(v, CURVE_POINTS);
            EffectValidationRow {
                motion: m.name().to_string(),
                without_effect_nm: a.as_ref().ok().map(|f| f.peak_to_peak_nm),
                with_effect_nm: b.as_ref().ok().map(|f| f.peak_to_peak_nm),
                note,
                without_curve_nm: a.as_ref().map_or(vec![], |f| curve(&f.variation_nm)),
                with_curve_nm: b.as_ref().map_or(vec![], |f| curve(&f.variation_nm)),
            }
        })
        .collect())
}
