//! The identifiability report of a joint estimate, as the calibration and the tests read it.

use super::analysis::analyse;
use super::input::{Options, ParamInfo};
use super::report::IdentifiabilityReport;
use crate::identify::joint::JointEstimate;

/// The identifiability report of a joint estimate: its weighted Jacobian and residuals, the
/// free extrinsics with their useful bounds, and the detector gains as nuisance parameters.
pub fn analyse_estimate(est: &JointEstimate) -> IdentifiabilityReport {
    let all = ParamInfo::extrinsics();
    let params: Vec<ParamInfo> = est
        .column_parameter
        .iter()
        .zip(&est.column_names)
        .map(|(p, name)| match p {
            Some(i) => all[*i].clone(),
            None => ParamInfo::new(name.clone(), "(gain)", 1.0),
        })
        .collect();
    let rows = est.weighted_jacobian.nrows();
    let mut r = nalgebra::DVector::zeros(rows);
    for (k, v) in est.normalised_residuals.iter().enumerate().take(rows) {
        r[k] = *v;
    }
    match analyse(&est.weighted_jacobian, &r, &params, &Options::default()) {
        Ok(report) => report,
        Err(e) => {
            // Inconsistent input is a bug, but the user still gets a report that says so.
            let mut report = analyse(
                &nalgebra::DMatrix::zeros(1, params.len()),
                &nalgebra::DVector::zeros(1),
                &params,
                &Options::default(),
            )
            .expect("a zero Jacobian is valid input");
            report.warnings.push(format!("identifiability analysis failed: {e}"));
            report
        }
    }
}
