//! What a calibration without wavelength sweeps costs (a bench without a tunable laser): the
//! parameters the sweeps would determine and the data without them do not (the absolute gap),
//! the parameters whose sign branches that fit equally well leave open, and the translations
//! whose gap-change sign the sweeps before and after would fix and nothing else does. Owns the
//! comparison and its sentences; every fact in it comes from the identifier's own analyses
//! (the observability report, the multistart branches, the translation signs), none is listed
//! by hand.
//!
//! A sweep measured but whose analysis was refused is lost the same way ([`lost`]): the same
//! observations are analysed with an absolute gap where each lost sweep was (the value the
//! estimate predicts there) and without it.
//!
//! Before a measurement the cost is predicted ([`predict`]): the plans run once on a pilot
//! virtual bench misaligned as the paper measured its bench ([`pilot_truth`]), and the same
//! traces are analysed with and without their sweeps. Not at the square design: there a
//! translation does not change the gap, so no sweep has a sign to give. After a sweep-less measurement the
//! "without" side is the measurement itself ([`SweepCost::assess`] with its report), the "with"
//! side the pilot's prediction for the same plans with their sweeps.

use crate::bench::{run_plan, BenchPreset, RunControl, VirtualBench};
use crate::identify::joint::{self, analyse_estimate, JointOptions};
use crate::identify::measurements::{observations_from_traces, ExtractOptions};
use crate::identify::multistart::extract_options;
use crate::identify::observability::IdentifiabilityReport;
use crate::identify::signs::{translation_signs, SignSource, TranslationSign};
use crate::identify::verdict::FitCheck;
use crate::identify::{Observation, ObservationKind};
use crate::model::extrinsics::{Extrinsics, PARAMETER_NAMES};
use crate::model::optics::FabryPerot;
use crate::model::phase::PhaseModel;
use crate::plan::Plan;
use serde::{Deserialize, Serialize};
use std::sync::atomic::AtomicBool;

/// What one set of data says: the identifiability of the extrinsics and the translations' signs.
#[derive(Debug, Clone, Copy)]
pub struct Evidence<'a> {
    /// The observability analysis.
    pub identifiability: &'a IdentifiabilityReport,
    /// The sign of each translation and what fixes it.
    pub signs: &'a [TranslationSign],
}

/// A parameter the sweeps would determine and the data without them do not.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LostParameter {
    /// The parameter's name.
    pub name: String,
    /// Why the data without sweeps do not determine it (the analysis's words).
    pub reason: String,
}

/// A sweep measured whose analysis was refused.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LostSweep {
    /// The trace's label.
    pub label: String,
    /// Where it was measured (µm, °).
    pub at_display: [f64; 6],
    /// Its middle wavelength (nm).
    pub wavelength_nm: f64,
    /// Bench time of its start and end (s).
    pub time_s: [f64; 2],
    /// Why its analysis was refused.
    pub why: String,
}

/// The cost of leaving out the sweeps.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct SweepCost {
    /// The sweeps measured but lost (their analysis refused); empty when the sweeps were left out
    /// of the plans.
    #[serde(default)]
    pub lost: Vec<LostSweep>,
    /// Parameters determined with the sweeps and not without them.
    pub undetermined: Vec<LostParameter>,
    /// The combinations the data without sweeps do not see, or see too weakly, that the data
    /// with them do (the analysis's sentences).
    pub unseen: Vec<String>,
    /// Parameters whose sign differs between branches that fit the data equally well (only
    /// known after a measurement: the branches are the identification's).
    pub sign_open: Vec<String>,
    /// Translations whose gap-change sign the sweeps before and after would fix (labels).
    pub signed_by_sweeps: Vec<String>,
    /// Of those, the ones nothing fixes without the sweeps (labels); the others keep the sign
    /// of the model fitted to all the data.
    pub unsigned: Vec<String>,
    /// A prediction from a pilot run of the plans (before measuring), not the analysis of a
    /// sweep-less measurement.
    pub predicted: bool,
}

impl SweepCost {
    /// Compare the data `with` the sweeps and `without` them; `fit` is the verdict on the
    /// sweep-less identification (its tied branches), when one ran.
    pub fn assess(with: Evidence<'_>, without: Evidence<'_>, fit: Option<&FitCheck>, predicted: bool) -> Self {
        let determined = |r: &IdentifiabilityReport, name: &str| {
            r.parameters.iter().find(|p| p.name == name).is_some_and(|p| p.determined)
        };
        let undetermined = PARAMETER_NAMES
            .iter()
            .filter(|(n, _)| determined(with.identifiability, n) && !determined(without.identifiability, n))
            .map(|(n, _)| LostParameter {
                name: n.to_string(),
                reason: without
                    .identifiability
                    .parameters
                    .iter()
                    .find(|p| p.name == *n)
                    .and_then(|p| p.reason.clone())
                    .unwrap_or_else(|| "not determined by these data".into()),
            })
            .collect();
        let unseen = without
            .identifiability
            .unobservable
            .iter()
            .filter(|c| !with.identifiability.unobservable.iter().any(|w| w.description == c.description))
            .map(|c| c.description.clone())
            .collect();
        let by_sweeps = |s: &TranslationSign| s.evidence.iter().any(|e| e.source == SignSource::SweepsBeforeAndAfter);
        let signed_by_sweeps: Vec<String> =
            with.signs.iter().filter(|s| by_sweeps(s)).map(|s| s.label.clone()).collect();
        let unsigned = signed_by_sweeps
            .iter()
            .filter(|l| without.signs.iter().find(|s| &s.label == *l).is_none_or(|s| s.evidence.is_empty()))
            .cloned()
            .collect();
        SweepCost {
            lost: vec![],
            undetermined,
            unseen,
            sign_open: sign_open(fit),
            signed_by_sweeps,
            unsigned,
            predicted,
        }
    }

    /// Leaving the sweeps out costs nothing these analyses can see.
    pub fn is_free(&self) -> bool {
        self.undetermined.is_empty() && self.unseen.is_empty() && self.sign_open.is_empty() && self.unsigned.is_empty()
    }

    /// The cost in sentences, for the report and the wizard.
    pub fn sentences(&self) -> Vec<String> {
        let mut out = Vec::new();
        let (rests, are_not) = if self.predicted { ("will rest", "will not be") } else { ("rest", "are not") };
        let without = if self.lost.is_empty() { "without wavelength sweeps" } else { "without the lost sweeps" };
        if !self.lost.is_empty() {
            let each: Vec<String> = self.lost.iter().map(|l| format!("`{}` ({})", l.label, l.why)).collect();
            out.push(format!("{} sweep(s) measured but not analysed: {}", self.lost.len(), each.join("; ")));
        }
        if !self.undetermined.is_empty() {
            let names: Vec<&str> = self.undetermined.iter().map(|p| p.name.as_str()).collect();
            out.push(format!(
                "{without} the absolute gaps are not measured: {} {are_not} determined (the sweeps would determine {})",
                names.join(", "),
                if names.len() == 1 { "it" } else { "them" }
            ));
            for p in &self.undetermined {
                out.push(format!("{}: {}", p.name, p.reason));
            }
        }
        out.extend(self.unseen.iter().map(|u| format!("{without}: {u}")));
        if !self.sign_open.is_empty() {
            out.push(format!(
                "the sign of {} is not fixed: branches of opposite sign fit the data {without} equally well",
                self.sign_open.join(", ")
            ));
        }
        if !self.signed_by_sweeps.is_empty() {
            let n = self.signed_by_sweeps.len();
            let rest = n - self.unsigned.len();
            out.push(format!(
                "{n} translation(s) would get the sign of their gap change from sweeps before and after: \
                 {} {rests} on the model fitted to all the data, {} on nothing",
                rest,
                self.unsigned.len()
            ));
        }
        if out.len() == self.lost.len().min(1) {
            out.push(if self.lost.is_empty() {
                "leaving the sweeps out loses no parameter and no sign these plans determine".into()
            } else {
                "losing them loses no parameter and no sign these data determine".into()
            });
        }
        out
    }
}

/// What losing the sweeps `lost` cost a measurement analysed without them (`observations`, its
/// estimate `at`, the verdict `fit` on it): the identifier's analyses of the same observations
/// with an absolute gap where each lost sweep was (the value the estimate predicts there, with
/// the σ of the sweeps kept, or the analysis's floor) and without, compared.
pub fn lost(
    model: &PhaseModel,
    observations: &[Observation],
    at: &Extrinsics,
    lost: Vec<LostSweep>,
    fit: Option<&FitCheck>,
) -> SweepCost {
    let mut sigmas: Vec<f64> = observations
        .iter()
        .filter(|o| matches!(o.kind, ObservationKind::AbsoluteGap { .. }))
        .map(|o| o.sigma)
        .collect();
    sigmas.sort_by(f64::total_cmp);
    let sigma = sigmas.get(sigmas.len() / 2).copied().unwrap_or(ExtractOptions::default().gap_sigma_floor_um);
    let mut with = observations.to_vec();
    for l in &lost {
        let mut o = Observation {
            label: l.label.clone(),
            // The identification models no drift, so the sweep's rate moves no reading.
            kind: ObservationKind::AbsoluteGap { at_display: l.at_display, gap_um: 0.0, sweep_nm_per_s: 0.0 },
            sigma,
            wavelength_nm: l.wavelength_nm,
            time_s: l.time_s,
            approach: Default::default(),
        };
        let Ok(fp) = FabryPerot::new(&model.optics, l.wavelength_nm, model.n_air) else { continue };
        let v = crate::identify::predict(model, &fp, at, &o, 1.0);
        if let ObservationKind::AbsoluteGap { gap_um, .. } = &mut o.kind {
            *gap_um = v;
        }
        if v.is_finite() {
            with.push(o);
        }
    }
    let analyse = |obs: &[Observation]| {
        let est = joint::evaluate(model, obs, at, &JointOptions::default());
        PilotAnalysis { identifiability: analyse_estimate(&est), signs: translation_signs(obs, &est) }
    };
    let (w, wo) = (analyse(&with), analyse(observations));
    let mut cost = SweepCost::assess(w.evidence(), wo.evidence(), fit, false);
    cost.lost = lost;
    cost
}

/// Parameters whose sign differs between the chosen branch and one that ties with it.
fn sign_open(fit: Option<&FitCheck>) -> Vec<String> {
    let Some(fit) = fit else { return vec![] };
    let Some(chosen) = fit.branches.first() else { return vec![] };
    let a = chosen.extrinsics.to_array();
    PARAMETER_NAMES
        .iter()
        .enumerate()
        .filter(|(i, _)| {
            fit.tied_branches.iter().filter_map(|&k| fit.branches.get(k)).any(|b| {
                let v = b.extrinsics.to_array()[*i];
                v * a[*i] < 0.0
            })
        })
        .map(|(_, (n, _))| n.to_string())
        .collect()
}

/// One analysis of pilot traces: the joint Jacobian at the pilot's truth.
struct PilotAnalysis {
    identifiability: IdentifiabilityReport,
    signs: Vec<TranslationSign>,
}

impl PilotAnalysis {
    fn evidence(&self) -> Evidence<'_> {
        Evidence { identifiability: &self.identifiability, signs: &self.signs }
    }
}

fn analyse_pilot(traces: &[crate::trace::Trace], model: &PhaseModel) -> PilotAnalysis {
    let obs = observations_from_traces(traces, model, &extract_options()).observations;
    let est = joint::evaluate(model, &obs, &model.extrinsics, &JointOptions::default());
    PilotAnalysis { identifiability: analyse_estimate(&est), signs: translation_signs(&obs, &est) }
}

/// The pilot's analyses of `plans` with their sweeps and without them: the plans run once on a
/// virtual bench of `preset` whose truth is `prior` (no hidden effects), the same traces
/// analysed twice.
fn pilot(preset: &BenchPreset, prior: &Extrinsics, plans: &[Plan]) -> Result<(PilotAnalysis, PilotAnalysis), String> {
    let mut p = preset.clone();
    p.truth = *prior;
    p.effects.clear();
    p.laser.tunable = true;
    let mut bench = VirtualBench::new(&p, Some(p.seed)).map_err(|e| e.to_string())?;
    let model = PhaseModel::of_preset(&p, *prior)?;
    let cancel = AtomicBool::new(false);
    let mut traces = Vec::new();
    for plan in plans {
        let mut control = RunControl { cancel: &cancel, on_samples: &mut |_, _| {}, on_progress: &mut |_| {} };
        let run = run_plan(&mut bench, plan, &mut control);
        traces.extend(run.traces);
        run.outcome.map_err(|e| format!("pilot run of plan {}: {e}", plan.name))?;
    }
    let with = analyse_pilot(&traces, &model);
    traces.retain(|t| !crate::trace::is_sweep(t));
    Ok((with, analyse_pilot(&traces, &model)))
}

/// The pilot bench's extrinsics: a typical misalignment, the paper's measured one (Table II,
/// lamella and fiber tilted by about a degree). At the square design the translations of the
/// paper's strategy 1 leave the gap unchanged and the sweeps around them sign nothing, so the
/// cost of leaving them out would read as nothing.
pub fn pilot_truth() -> Extrinsics {
    Extrinsics::table2()
}

/// Predict what leaving the sweeps out of `plans` costs on a bench modelled by `preset`,
/// misaligned as [`pilot_truth`].
pub fn predict(preset: &BenchPreset, plans: &[Plan]) -> Result<SweepCost, String> {
    let (with, without) = pilot(preset, &pilot_truth(), plans)?;
    Ok(SweepCost::assess(with.evidence(), without.evidence(), None, true))
}

/// What leaving the sweeps out of `plans` cost a measurement whose sweep-less analysis is
/// `measured` (with the verdict `fit` on it): compared with the pilot's analysis of the same
/// plans with their sweeps.
pub fn measured(
    preset: &BenchPreset,
    plans: &[Plan],
    measured: Evidence<'_>,
    fit: Option<&FitCheck>,
) -> Result<SweepCost, String> {
    let (with, _) = pilot(preset, &pilot_truth(), plans)?;
    Ok(SweepCost::assess(with.evidence(), measured, fit, false))
}

#[cfg(test)]
mod tests;
