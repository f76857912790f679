//! The session's record of a discrepancy diagnosis: generic fields, so that the session format
//! does not change when the diagnosis does.

use serde::{Deserialize, Serialize};

/// Results of the discrepancy diagnosis (filled by the diagnosis work): generic on purpose, so
/// that the session format does not change when the diagnosis does.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct DiagnosisRecord {
    /// The candidate effects examined, best first.
    pub effects: Vec<EffectFinding>,
    /// The conclusion in words ("residual at the noise floor after adding …", "no candidate
    /// explains the residual: it lives in …").
    pub verdict: String,
    /// The extended model: the library effects added, with their values (empty when none).
    #[serde(default)]
    pub model_effects: Vec<crate::model::effects::Effect>,
    /// The extrinsics refitted with those effects, when the diagnosis changed them.
    #[serde(default)]
    pub extrinsics: Option<crate::model::extrinsics::Extrinsics>,
    /// The validation motions planned without and with the effects.
    #[serde(default)]
    pub validation: Vec<crate::diagnose::validation::EffectValidationRow>,
}

/// One candidate effect as the diagnosis scored it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EffectFinding {
    /// The effect's name (as in the effect library, e.g. "joint-4 pivot offset along Y_w").
    pub name: String,
    /// Estimated size, in `unit`.
    pub estimate: f64,
    /// Unit of `estimate` and `sigma` ("µm", "ppm", "°", "nm/s").
    pub unit: String,
    /// Standard uncertainty of the estimate, `None` when not determined.
    #[serde(default)]
    pub sigma: Option<f64>,
    /// Score (larger is more likely), as described by `score_kind`.
    pub score: f64,
    /// What the score is ("ΔBIC", "F statistic", …).
    #[serde(default)]
    pub score_kind: String,
    /// Fraction (0..1) of the effect's signature the extrinsics would absorb, when known.
    #[serde(default)]
    pub absorbed_fraction: Option<f64>,
    /// Free text (ambiguity set, confirmation on held-out motions…).
    #[serde(default)]
    pub note: String,
}

impl DiagnosisRecord {
    /// The session's record of a diagnosis result: the named effects (then the partial ones),
    /// the verdict in words with the residual before and after.
    pub fn from_result(result: &crate::diagnose::DiagnosisResult) -> Self {
        let finding = |e: &crate::diagnose::NamedEffect, note: &str| EffectFinding {
            name: e.name.clone(),
            estimate: e.estimate,
            unit: e.unit.clone(),
            sigma: e.sigma,
            score: e.score,
            score_kind: "F statistic".into(),
            absorbed_fraction: Some(e.absorbed_share),
            note: if e.ambiguous_with.is_empty() {
                note.to_string()
            } else {
                format!("{note}cannot be told from: {}", e.ambiguous_with.join(", "))
            },
        };
        let mut effects: Vec<EffectFinding> = result.effects.iter().map(|e| finding(e, "")).collect();
        effects.extend(result.partial.iter().map(|e| finding(e, "added, residual still above the noise; ")));
        let verdict = match result.verdict {
            crate::diagnose::Verdict::Named => "named",
            crate::diagnose::Verdict::None => "none: no significant missing effect",
            crate::diagnose::Verdict::Unexplained => "unexplained structure remains",
        };
        let mut verdict = format!(
            "{verdict}; gap-change residual RMS {:.2} nm before, {:.2} nm after",
            result.residual_rms_before_nm, result.residual_rms_after_nm
        );
        if let Some(g) =
            result.residual_where.first().filter(|_| result.verdict == crate::diagnose::Verdict::Unexplained)
        {
            verdict.push_str(&format!("; worst: {} {} at {:.1} σ", g.by, g.key, g.rms_sigma));
            if let Some(f) = result.worst_family() {
                verdict.push_str(&format!("; most in the {} at {:.1} σ", f.family.words(), f.after_sigma));
            }
        }
        Self { effects, verdict, ..Default::default() }
    }

    /// [`DiagnosisRecord::from_result`] with the extended model (the library `effects` of the
    /// final model and the refitted extrinsics) and its validation without and with them: what
    /// `photorobot diagnose` and the GUI save.
    pub fn with_model(
        result: &crate::diagnose::DiagnosisResult,
        effects: &[crate::model::effects::Effect],
        validation: &[crate::diagnose::validation::EffectValidationRow],
    ) -> Self {
        Self {
            model_effects: effects.to_vec(),
            extrinsics: Some(result.extrinsics),
            validation: validation.to_vec(),
            ..Self::from_result(result)
        }
    }
}
