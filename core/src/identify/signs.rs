//! The sign of each translation's gap change and what fixed it. Owns the sources and their agreement.
//!
//! A single-channel fringe signal does not say which way the gap moved. The paper sweeps the
//! wavelength before and after each translation and compares the absolute gaps (section IV);
//! here every source the data offer is read: those sweeps when the session has them at the
//! translation's two ends, and the model fitted to all the data, whose prediction for the
//! translation has a sign when it stands clear of its own uncertainty. The report lists, for
//! each translation, the sign measured, every source that fixes it, and whether they agree.

use crate::identify::joint::JointEstimate;
use crate::identify::multistart::is_translation;
use crate::identify::{Observation, ObservationKind};
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

/// A source of the sign of a translation's gap change.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SignSource {
    /// Absolute gaps from wavelength sweeps at the translation's start and end poses.
    SweepsBeforeAndAfter,
    /// The model fitted to all the data: its predicted gap change stands clear of its uncertainty.
    FittedModel,
}

impl SignSource {
    /// The source in words, for warnings and reports.
    pub fn words(self) -> &'static str {
        match self {
            SignSource::SweepsBeforeAndAfter => "the sweeps before and after",
            SignSource::FittedModel => "the model fitted to all the data",
        }
    }
}

/// One source's sign.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct SignEvidence {
    /// The source.
    pub source: SignSource,
    /// The sign it gives (+1: the gap grows).
    pub sign: i8,
}

/// The sign of one translation's gap change.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TranslationSign {
    /// The trace's label.
    pub label: String,
    /// The gap change measured over the whole translation (nm).
    pub dl_nm: f64,
    /// Its σ (nm).
    pub sigma_nm: f64,
    /// Every source that fixes the sign, in the order of [`SignSource`].
    pub evidence: Vec<SignEvidence>,
    /// The first source that fixes it; `None` when none does (the change is too small to sign,
    /// or nothing in the data tells).
    pub fixed_by: Option<SignSource>,
    /// Every source agrees with the measured sign.
    pub agrees: bool,
}

/// Sources fix a sign only beyond this many σ.
const SIGN_SIGMA: f64 = 3.0;

/// Poses closer than this (µm, °) are the same pose for pairing a sweep with a translation's end.
const SAME_POSE: [f64; 6] = [0.5, 0.5, 0.5, 0.005, 0.005, 0.005];

fn same_pose(a: &[f64; 6], b: &[f64; 6]) -> bool {
    (0..6).all(|j| (a[j] - b[j]).abs() <= SAME_POSE[j])
}

fn sign(v: f64) -> i8 {
    if v >= 0.0 {
        1
    } else {
        -1
    }
}

/// The sign of every translation in `observations` (the whole-move gap change of each label),
/// from the sweeps at its ends and from `estimate`, the fit of all of them.
pub fn translation_signs(observations: &[Observation], estimate: &JointEstimate) -> Vec<TranslationSign> {
    let covariance = parameter_covariance(estimate);
    let gaps: Vec<(&[f64; 6], f64, f64)> = observations
        .iter()
        .filter_map(|o| match &o.kind {
            ObservationKind::AbsoluteGap { at_display, gap_um, .. } => Some((at_display, *gap_um, o.sigma)),
            _ => None,
        })
        .collect();
    let gap_at = |q: &[f64; 6]| gaps.iter().find(|g| same_pose(g.0, q)).map(|g| (g.1, g.2));
    let mut out: Vec<TranslationSign> = Vec::new();
    for (k, o) in observations.iter().enumerate() {
        let ObservationKind::GapChange { from_display, to_display, dl_nm } = &o.kind else { continue };
        if !is_translation(o) {
            continue;
        }
        // Keep the whole move: the observation of the label that ends last.
        if let Some(prev) = out.iter().position(|t| t.label == o.label) {
            out.remove(prev);
        }
        let mut evidence = Vec::new();
        if let (Some((g0, s0)), Some((g1, s1))) = (gap_at(from_display), gap_at(to_display)) {
            if (g1 - g0).abs() > SIGN_SIGMA * s0.hypot(s1) {
                evidence.push(SignEvidence { source: SignSource::SweepsBeforeAndAfter, sign: sign(g1 - g0) });
            }
        }
        if let (Some(c), Some(predicted)) = (&covariance, estimate.residuals.get(k).map(|r| dl_nm - r)) {
            let row = estimate.weighted_jacobian.row(k) * o.sigma;
            let sigma_pred = (&row * c * row.transpose())[(0, 0)].max(0.0).sqrt();
            if predicted.abs() > SIGN_SIGMA * sigma_pred && predicted.abs() > SIGN_SIGMA * o.sigma {
                evidence.push(SignEvidence { source: SignSource::FittedModel, sign: sign(predicted) });
            }
        }
        let measured = sign(*dl_nm);
        let signed = dl_nm.abs() > SIGN_SIGMA * o.sigma;
        out.push(TranslationSign {
            label: o.label.clone(),
            dl_nm: *dl_nm,
            sigma_nm: o.sigma,
            fixed_by: if signed { evidence.first().map(|e| e.source) } else { None },
            agrees: evidence.iter().all(|e| e.sign == measured) || !signed,
            evidence,
        });
    }
    out
}

/// The covariance of the fitted parameters (internal units), the SVD pseudo-inverse of JᵀJ
/// scaled by the reduced χ² when above 1; `None` without redundancy.
fn parameter_covariance(estimate: &JointEstimate) -> Option<DMatrix<f64>> {
    let j = &estimate.weighted_jacobian;
    let (m, n) = (j.nrows(), j.ncols());
    if m <= n || n == 0 {
        return None;
    }
    let chi2: f64 = estimate.normalised_residuals.iter().map(|r| r * r).sum();
    let scale = (chi2 / (m - n) as f64).max(1.0);
    let normal = j.transpose() * j;
    let tolerance = 1e-12 * normal.norm();
    let inverse = normal.pseudo_inverse(tolerance).ok()?;
    Some(inverse * scale)
}
