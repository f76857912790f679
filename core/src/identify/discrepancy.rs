//! What noise alone cannot explain: a model-discrepancy term for every parameter's σ, from independent views of the
//! same data (families of observations, and traces). Owns the families, their consistency tests and the floor per family.
//!
//! A model that lacks something (another coupling law, a second reflection, a Gouy phase it
//! should not have) errs on every observation in a way the extrinsics mostly absorb: the fit still
//! reaches the noise floor while the parameters move. What it cannot absorb is the disagreement
//! between views of the same bench that the missing physics touches differently. So, as a
//! random-effects ("dark uncertainty") evaluation among independent methods:
//!
//! - **Families.** The observations fall into four families that see the extrinsics through
//!   different physics: gap changes of translations (the lamella normal), gap changes of rotations
//!   (the beam's hit point and the pivots), absolute gaps from sweeps (the gap, and the normal from
//!   gaps at several poses), and fringe amplitudes (the coupling law: where the lamella faces the
//!   fiber).
//! - **Leaving a family out.** The estimate without family f moves by δ_f = (H − H_f)⁺ J_fᵀ r_f
//!   (linearised; H = JᵀJ of the weighted Jacobian). Were the model right and σ right, δ_f would
//!   scatter as V_f = (H − H_f)⁺ − H⁺ (the Hausman difference of two efficient estimates), so
//!   χ²_f = δ_fᵀ V_f⁺ δ_f follows χ²(rank V_f) over the parameters the other families still see. A
//!   family whose χ²_f exceeds its 99 % quantile disagrees with the rest beyond its noise.
//! - **The systematic σ.** For a family that disagrees, each parameter it moves by more than
//!   2 of its own null σ (δ_fi² > 4·V_fii) gets the part of δ_fi² that noise does not explain,
//!   δ_fi² − V_fii, as a systematic variance (the DerSimonian-Laird moment estimate for two
//!   methods); over the families the largest counts. Where one trace, not a family, disagrees, the
//!   jackknife over traces ([`super::verdict::jackknife_sigma`]) already measures it: its excess over
//!   the noise σ is the other candidate. `σ_total² = σ_noise² + σ_systematic²`.
//! - **The floor per family** ([`FamilyFloor`]): each family's residual Birge ratio
//!   `R_f = √(χ²_f / ν_f)` (ν_f: its observations less the leverage the fit spends on them) and the
//!   scatter beyond noise it implies, `σ̄_f·√(R_f² − 1)` in the family's unit: how far this model
//!   misses these data in each family, for a diagnosis that must name only effects that explain
//!   more.
//!
//! A bias that every view shares equally is not seen by any comparison: the term covers what the
//! data can show, not every possible error.

use crate::identify::{parameter_scale, Observation, ObservationKind, N_EXTRINSICS};
use nalgebra::{DMatrix, DVector, SymmetricEigen};
use serde::{Deserialize, Serialize};

/// A family of observations: one physical view of the extrinsics.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Family {
    /// Gap changes of motions that move only the prismatic stages.
    Translations,
    /// Gap changes of motions that turn a revolute joint.
    Rotations,
    /// Absolute gaps from wavelength sweeps.
    AbsoluteGaps,
    /// Fringe amplitudes (the reflected power along rotations).
    FringeAmplitudes,
}

impl Family {
    /// All four, in the order reported.
    pub const ALL: [Family; 4] =
        [Family::Translations, Family::Rotations, Family::AbsoluteGaps, Family::FringeAmplitudes];

    /// The family of an observation.
    pub fn of(o: &Observation) -> Family {
        match &o.kind {
            ObservationKind::GapChange { from_display, to_display, .. } => {
                if (3..6).any(|j| (from_display[j] - to_display[j]).abs() > 1e-6) {
                    Family::Rotations
                } else {
                    Family::Translations
                }
            }
            ObservationKind::AbsoluteGap { .. } => Family::AbsoluteGaps,
            ObservationKind::FringeAmplitude { .. } => Family::FringeAmplitudes,
        }
    }

    /// Its name in reports.
    pub fn words(self) -> &'static str {
        match self {
            Family::Translations => "translations",
            Family::Rotations => "rotations",
            Family::AbsoluteGaps => "absolute gaps",
            Family::FringeAmplitudes => "fringe amplitudes",
        }
    }

    /// The unit of its observations.
    pub fn unit(self) -> &'static str {
        match self {
            Family::Translations | Family::Rotations => "nm",
            Family::AbsoluteGaps => "µm",
            Family::FringeAmplitudes => "mW",
        }
    }
}

/// How one family's observations stand against the model and against the other families.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FamilyFloor {
    /// The family.
    pub family: Family,
    /// Its observations and the traces they come from.
    pub observations: usize,
    pub traces: usize,
    /// Rms of its normalised residuals (σ).
    pub rms_sigma: f64,
    /// Its Birge ratio, √(χ² / ν) with ν its observations less their leverage (1 at the noise floor).
    pub birge_ratio: f64,
    /// The scatter beyond noise its residuals imply, σ̄·√(R² − 1) (0 below the floor), in `unit`.
    pub excess_sigma: f64,
    /// The unit of `excess_sigma`.
    pub unit: String,
    /// Leaving it out: χ² of the estimate's move against what noise gives, and its degrees of
    /// freedom (0 when the other families see nothing it sees).
    pub shift_chi2: f64,
    pub shift_dof: usize,
    /// The move is beyond the 99 % quantile of χ²(dof): this family disagrees with the others.
    pub disagrees: bool,
}

/// The model-discrepancy term of an identification.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct ModelDiscrepancy {
    /// Per family present, in [`Family::ALL`] order.
    pub families: Vec<FamilyFloor>,
    /// Systematic σ per extrinsic parameter (display units, in the order of
    /// [`crate::model::extrinsics::PARAMETER_NAMES`]) from the families that disagree; `None` for a
    /// parameter the estimate does not free.
    pub sigma_from_families: Vec<Option<f64>>,
}

/// Two-sided 99 % quantile of χ²(k) (Wilson-Hilferty).
pub fn chi2_quantile_99(k: usize) -> f64 {
    const Z: f64 = 2.326_347_874; // standard normal 99 % quantile
    let k = k.max(1) as f64;
    let a = 2.0 / (9.0 * k);
    k * (1.0 - a + Z * a.sqrt()).powi(3)
}

/// Relative eigenvalue below which a direction of a normal matrix is not seen.
const NULL_TOLERANCE: f64 = 1e-10;
/// A family's move of a parameter counts only beyond this many of its null σ.
const PARAMETER_GATE_SIGMA: f64 = 2.0;

/// The pseudo-inverse of a symmetric positive semi-definite matrix, and for each column the share
/// of its direction in the null space.
fn pinv_sym(h: &DMatrix<f64>) -> (DMatrix<f64>, Vec<f64>) {
    let n = h.nrows();
    if n == 0 {
        return (DMatrix::zeros(0, 0), vec![]);
    }
    let eig = SymmetricEigen::new(h.clone());
    let max = eig.eigenvalues.iter().fold(0.0f64, |a, &b| a.max(b.abs()));
    let tol = NULL_TOLERANCE * max.max(f64::MIN_POSITIVE);
    let mut inv = DMatrix::zeros(n, n);
    let mut null_share = vec![0.0; n];
    for (k, &l) in eig.eigenvalues.iter().enumerate() {
        let v = eig.eigenvectors.column(k);
        if l > tol {
            inv += v * v.transpose() / l;
        } else {
            for (i, share) in null_share.iter_mut().enumerate() {
                *share += v[i] * v[i];
            }
        }
    }
    (inv, null_share)
}

/// The model-discrepancy term of a fit: `jacobian` its weighted Jacobian (rows: the observations,
/// then priors; columns internal units), `residuals` the observations' normalised residuals,
/// `observations` the observations in row order, `column_parameter` the extrinsic each column is
/// (gains: `None`). See the module documentation.
pub fn model_discrepancy(
    jacobian: &DMatrix<f64>,
    residuals: &[f64],
    observations: &[Observation],
    column_parameter: &[Option<usize>],
) -> ModelDiscrepancy {
    let m = observations.len().min(residuals.len()).min(jacobian.nrows());
    let h = jacobian.transpose() * jacobian;
    let (c, _) = pinv_sym(&h);
    let families: Vec<Family> = observations.iter().take(m).map(Family::of).collect();
    let extrinsic: Vec<usize> = (0..column_parameter.len()).filter(|&k| column_parameter[k].is_some()).collect();
    let mut systematic = vec![0.0f64; column_parameter.len()];
    let mut floors = Vec::new();
    for family in Family::ALL {
        let rows: Vec<usize> = (0..m).filter(|&k| families[k] == family).collect();
        if rows.is_empty() {
            continue;
        }
        let jf = jacobian.select_rows(rows.iter());
        let rf = DVector::from_iterator(rows.len(), rows.iter().map(|&k| residuals[k]));
        let (c_out, null_share) = pinv_sym(&(&h - jf.transpose() * &jf));
        let delta = &c_out * (jf.transpose() * &rf);
        let v = &c_out - &c;
        // The parameters the other families still see, with a finite null spread.
        let seen: Vec<usize> = extrinsic.iter().copied().filter(|&k| null_share[k] < 1e-6 && v[(k, k)] > 0.0).collect();
        let d = DVector::from_iterator(seen.len(), seen.iter().map(|&k| delta[k]));
        let vs = DMatrix::from_fn(seen.len(), seen.len(), |a, b| v[(seen[a], seen[b])]);
        let (vs_inv, vs_null) = pinv_sym(&vs);
        let dof = vs_null.iter().filter(|&&s| s < 0.5).count().min(seen.len());
        let chi2 = if seen.is_empty() { 0.0 } else { (d.transpose() * &vs_inv * &d)[(0, 0)] };
        let disagrees = dof > 0 && chi2 > chi2_quantile_99(dof);
        if disagrees {
            for &k in &seen {
                let (dk, vk) = (delta[k], v[(k, k)]);
                if dk * dk > PARAMETER_GATE_SIGMA.powi(2) * vk {
                    systematic[k] = systematic[k].max(dk * dk - vk);
                }
            }
        }
        floors.push(floor(family, &rows, (&jf, &rf, &c), observations, (chi2, dof, disagrees)));
    }
    let mut sigma_from_families = vec![None; N_EXTRINSICS];
    for (k, p) in column_parameter.iter().enumerate() {
        if let Some(i) = *p {
            sigma_from_families[i] = Some(systematic[k].sqrt() * parameter_scale(i));
        }
    }
    ModelDiscrepancy { families: floors, sigma_from_families }
}

/// One family's [`FamilyFloor`]: its residuals against its leverage, and the leave-out test.
fn floor(
    family: Family,
    rows: &[usize],
    (jf, rf, c): (&DMatrix<f64>, &DVector<f64>, &DMatrix<f64>),
    observations: &[Observation],
    (shift_chi2, shift_dof, disagrees): (f64, usize, bool),
) -> FamilyFloor {
    let n = rows.len();
    let chi2 = rf.norm_squared();
    let leverage: f64 = (0..n).map(|a| (jf.row(a) * c * jf.row(a).transpose())[(0, 0)]).sum();
    let nu = (n as f64 - leverage).max(1.0);
    let birge_ratio = (chi2 / nu).sqrt();
    let sigma_rms = (rows.iter().map(|&k| observations[k].sigma.powi(2)).sum::<f64>() / n as f64).sqrt();
    let mut traces: Vec<&str> = rows.iter().map(|&k| observations[k].label.as_str()).collect();
    traces.sort_unstable();
    traces.dedup();
    FamilyFloor {
        family,
        observations: n,
        traces: traces.len(),
        rms_sigma: (chi2 / n as f64).sqrt(),
        birge_ratio,
        excess_sigma: sigma_rms * (birge_ratio * birge_ratio - 1.0).max(0.0).sqrt(),
        unit: family.unit().to_string(),
        shift_chi2,
        shift_dof,
        disagrees,
    }
}

#[cfg(test)]
mod tests;
