//! What a diagnosis finds: the verdict, the named effects and the serialisable result, and why
//! a diagnosis cannot run.

use crate::diagnose::replay::{FamilyResidual, ResidualGroup};
use crate::model::extrinsics::Extrinsics;
use serde::{Deserialize, Serialize};

/// The overall finding.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// Effects were named and the residual is at the noise floor with them.
    Named,
    /// No significant missing effect: the residual is at the noise floor.
    None,
    /// The residual is above the noise floor and no candidate of the library explains it.
    Unexplained,
}

impl Verdict {
    /// The verdict's word, as in the JSON.
    pub fn word(self) -> &'static str {
        match self {
            Verdict::Named => "named",
            Verdict::None => "none",
            Verdict::Unexplained => "unexplained",
        }
    }
}

/// A named (added) effect.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NamedEffect {
    /// Candidate name, e.g. "pivot offset q4 along Z_w".
    pub name: String,
    /// Fitted value (with the extrinsics refitted).
    pub estimate: f64,
    /// Unit of the estimate and σ.
    pub unit: String,
    /// Standard uncertainty (`None` when the data do not determine it).
    pub sigma: Option<f64>,
    /// F statistic when it was named.
    pub score: f64,
    /// ΔBIC when it was named.
    pub delta_bic: f64,
    /// Share of its signature the extrinsics absorb on the data it was named on.
    pub absorbed_share: f64,
    /// Candidates that could not be told apart from it (nearly collinear projected signatures).
    pub ambiguous_with: Vec<String>,
    /// How much lower the χ² of the recorded traces, each predicted from the model fitted to
    /// the others, is with it than without it (leave-one-trace-out cross-validation, the other
    /// effects in both; `None` before it was checked).
    #[serde(default)]
    pub held_out_chi2_gain: Option<f64>,
}

/// The size the data rule out for a candidate they did not name (its unit).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Bound {
    /// Candidate name.
    pub name: String,
    /// Unit of the figures.
    pub unit: String,
    /// Its estimate on the last scoring.
    pub estimate: f64,
    /// Its σ.
    pub sigma: f64,
    /// |estimate| + 3σ: a larger effect would have been seen.
    pub below: f64,
}

impl Bound {
    /// The candidate, its estimate ± σ and the size a larger effect would exceed, all to the
    /// decimals that give σ three significant digits: "joint scale error q1: -86 ± 127 ppm,
    /// below 467 ppm".
    pub fn describe(&self) -> String {
        let d = if self.sigma > 0.0 && self.sigma.is_finite() {
            (2 - self.sigma.log10().floor() as i32).max(0) as usize
        } else {
            4
        };
        format!(
            "{}: {:.d$} ± {:.d$} {u}, below {:.d$} {u}",
            self.name,
            self.estimate,
            self.sigma,
            self.below,
            u = self.unit
        )
    }
}

/// The diagnosis result, serialisable (for sessions and `--json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DiagnosisResult {
    /// Named, none or unexplained.
    pub verdict: Verdict,
    /// The named effects with their estimates (empty unless the verdict is `named`).
    pub effects: Vec<NamedEffect>,
    /// RMS of the gap-change residuals with the baseline model (extrinsics refitted, no
    /// effect) on the final analysis of the data, the one "after" is computed on (nm).
    pub residual_rms_before_nm: f64,
    /// RMS of the gap-change residuals with the final model (nm).
    pub residual_rms_after_nm: f64,
    /// RMS of all whitened residuals with the baseline model (1 = noise floor).
    pub residual_rms_before_sigma: f64,
    /// The same with the final model.
    pub residual_rms_after_sigma: f64,
    /// Whitened RMS on the held-out motions, baseline model.
    pub held_out_rms_before_sigma: f64,
    /// Whitened RMS on the held-out motions, final model.
    pub held_out_rms_after_sigma: f64,
    /// Effects added that did not bring the residual to the noise floor (verdict unexplained).
    pub partial: Vec<NamedEffect>,
    /// Candidates the extrinsics absorb on every available motion: equivalent to an extrinsic change.
    pub equivalent_to_extrinsics: Vec<String>,
    /// Candidates the recorded data cannot tell from an extrinsic change (or cannot see at
    /// their typical size) but the designed motions would (when no bench ran them).
    pub need_motions: Vec<String>,
    /// Candidates whose signature at their typical size, after projecting out what the
    /// extrinsics explain, stays below the detection score ([`DETECTABLE_SCORE`]) on the fitted
    /// data and every motion run, and that no designed motion would show either: not ruled
    /// out, only invisible at that size here (a larger one would be seen). On table2-ideal a
    /// 0.6 mrad tilt of the q4 goniometer's axis toward its link x changes no gap change of the
    /// session or the pool by more than 0.3σ in all (`effect_visibility` example). Not the
    /// candidates a named effect cannot be told from: those are in its `ambiguous_with`.
    #[serde(default)]
    pub not_detectable: Vec<String>,
    /// Pairs of candidates each detectable alone whose signatures, once the extrinsics are
    /// projected out, are nearly collinear on these data (|cos| above
    /// [`crate::diagnose::scoring::AMBIGUITY_COSINE`]): sizes of the two that cancel leave the residual at
    /// the floor, so "none" does not rule out both. Not a named effect's `ambiguous_with`.
    #[serde(default)]
    pub cancelling_pairs: Vec<[String; 2]>,
    /// Every other candidate (neither named nor in a list above) with the size its data rule out:
    /// |estimate| + 3σ on the last scoring. "None" says only that each is below its bound.
    #[serde(default)]
    pub ruled_out_above: Vec<Bound>,
    /// Candidates that no observation can see at any size, never named: those no observation
    /// or pool motion depends on (dropped at the baseline), and, on observations from traces,
    /// the fringe nonlinearity, which the fringe analysis removes (it fits the fringe's
    /// harmonics).
    #[serde(default)]
    pub not_seen: Vec<String>,
    /// Discriminating motions designed (and run, when a bench was given).
    pub discriminating_motions: Vec<String>,
    /// Whether the discriminating motions were run.
    pub discriminating_motions_ran: bool,
    /// Nothing more to learn from the discriminating motions: no motion of the pool that the
    /// data lack would show a candidate they cannot (each is named, ruled out at its typical
    /// size, equivalent to an extrinsic change, or too small for any motion). When false, the
    /// designed motions would tell more.
    #[serde(default)]
    pub settled: bool,
    /// Where the final residual lives, worst groups first (unexplained structure).
    pub residual_where: Vec<ResidualGroup>,
    /// The residual of each family of observations, before and after the named effects.
    #[serde(default)]
    pub residual_by_family: Vec<FamilyResidual>,
    /// Extrinsics of the final model.
    pub extrinsics: Extrinsics,
}

impl DiagnosisResult {
    /// The family of observations the final model misses most (whitened RMS after), if any.
    pub fn worst_family(&self) -> Option<&FamilyResidual> {
        self.residual_by_family.iter().max_by(|a, b| a.after_sigma.total_cmp(&b.after_sigma))
    }

    /// The residual of each family of observations, before → after the effects, in one line:
    /// where the model and the data disagree (the gap changes for a kinematic effect, the
    /// fringe amplitudes for optics unlike the model's). `None` when no family was scored.
    pub fn family_line(&self) -> Option<String> {
        let parts: Vec<String> = self
            .residual_by_family
            .iter()
            .map(|f| format!("{} {:.2}σ → {:.2}σ (n = {})", f.family.words(), f.before_sigma, f.after_sigma, f.count))
            .collect();
        (!parts.is_empty()).then(|| format!("residual by family of observations, before → after: {}", parts.join("; ")))
    }

    /// What a settled result says of the pairs it leaves open, if it leaves any: with a bench
    /// the motions the pool has for each pair ran once (a pair the pool cannot separate has
    /// none); from recordings alone none is proposed for them.
    pub fn pairs_left_open(&self) -> Option<&'static str> {
        if !self.settled || self.cancelling_pairs.is_empty() {
            return None;
        }
        Some(if self.discriminating_motions_ran {
            "The pairs these data cannot tell apart are left open: the pool's motions for them, if it has any, ran and did not separate them."
        } else {
            "The pairs these data cannot tell apart are left open: from recordings alone no motion is proposed to separate them."
        })
    }
}

/// Why a diagnosis cannot run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DiagnoseError {
    /// Too few observations.
    #[error("{0} usable observations: the diagnosis needs at least 20")]
    TooFewObservations(usize),
    /// The model cannot be evaluated.
    #[error("model: {0}")]
    Model(String),
    /// The discriminating motions could not be run.
    #[error("{0}")]
    Bench(String),
    /// The caller's [`crate::diagnose::fit::StopCheck`] asked to stop.
    #[error("stopped")]
    Stopped,
}

impl From<crate::diagnose::fit::PredictError> for DiagnoseError {
    fn from(e: crate::diagnose::fit::PredictError) -> Self {
        match e {
            crate::diagnose::fit::PredictError::Stopped => DiagnoseError::Stopped,
            crate::diagnose::fit::PredictError::Effect(e) => DiagnoseError::Model(e.to_string()),
        }
    }
}
