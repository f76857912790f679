//! A whole calibration: run the measurement plans on a bench, turn traces into observations, identify
//! (paper mode or joint estimate), report uncertainties and validate. Owns the order of those steps and the report.
//!
//! The identification itself (starts, passes, the choice of branch) is
//! [`crate::identify::multistart`]; this module adds the verdict on the fit as a whole
//! ([`crate::identify::verdict`]), the Table II-style rows and the validation. It sits above
//! identify and validate so that neither depends on the other; the CLI and the GUI call it.

use crate::bench::{run_plan, Bench, RunControl};
use crate::identify::discrepancy::{model_discrepancy, ModelDiscrepancy};
use crate::identify::joint::analyse_estimate;
pub use crate::identify::multistart::{identify, Identification, Mode};
use crate::identify::observability::IdentifiabilityReport;
use crate::identify::signs::{translation_signs, TranslationSign};
use crate::identify::sweep_cost::LostSweep;
use crate::identify::verdict::{
    differing_parameters, jackknife_sigma, rms_threshold, worst_traces, FitCheck, Verdict, WORST_TRACES,
};
use crate::identify::N_EXTRINSICS;
use crate::model::extrinsics::{Extrinsics, PARAMETER_NAMES};
use crate::model::phase::PhaseModel;
use crate::plan::Plan;
use crate::trace::Trace;
use crate::validate::before_after::{check_calibration, run_before_and_after, BeforeAndAfter};
use crate::validate::evidence::{Evidence, Verdict as MotionVerdict};
use crate::validate::forecast::{forecast, ValidationForecast};
use crate::validate::StopSettings;
use serde::{Deserialize, Serialize};
use std::sync::atomic::AtomicBool;

/// One row of the Table II-style result.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ParameterRow {
    /// Parameter name (paper's).
    pub name: String,
    /// Value (display unit).
    pub value: f64,
    /// Unit.
    pub unit: String,
    /// Total standard uncertainty, √(σ_noise² + σ_systematic²); `None` when the data do not
    /// determine the parameter.
    pub sigma: Option<f64>,
    /// The part the noise model gives (the covariance of the fit, scaled up by the residual's χ²
    /// when above 1). `None` when not determined, or in reports that predate it.
    #[serde(default)]
    pub sigma_noise: Option<f64>,
    /// The part noise cannot explain: how far independent views of the data (families of
    /// observations, traces) disagree beyond their noise (`identify::discrepancy`). `None` as
    /// `sigma_noise`.
    #[serde(default)]
    pub sigma_systematic: Option<f64>,
    /// Whether the data determine it (its total σ within the parameter's useful bound).
    pub determined: bool,
    /// Why not, when not.
    pub reason: Option<String>,
    /// The systematic part is the spread of the estimate over the traces (jackknife), not a
    /// disagreement between families of observations.
    #[serde(default)]
    pub sigma_from_jackknife: bool,
}

/// One validation result.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ValidationRow {
    /// The motion.
    pub motion: String,
    /// Peak-to-peak L variation planned with the nominal (pre-calibration) extrinsics (nm).
    pub before_nm: Option<f64>,
    /// The same planned with the identified extrinsics (nm).
    pub after_nm: Option<f64>,
    /// The paper's figure after calibration (nm).
    pub paper_nm: f64,
    /// Why a figure is missing.
    pub note: Option<String>,
    /// L variation along the motion planned with the nominal extrinsics (nm), at most
    /// [`CURVE_POINTS`] evenly spaced samples, for plots.
    #[serde(default)]
    pub before_curve_nm: Vec<f64>,
    /// The same planned with the identified extrinsics (nm).
    #[serde(default)]
    pub after_curve_nm: Vec<f64>,
    /// The proof of the motion planned with the nominal extrinsics: its figures that do not use
    /// the extrinsics under test, and its verdict (`before_nm` is the figure it stands behind).
    #[serde(default)]
    pub before_evidence: Option<Evidence>,
    /// The same for the motion planned with the identified extrinsics: the calibration's proof.
    #[serde(default)]
    pub after_evidence: Option<Evidence>,
}

impl ValidationRow {
    /// Why this motion does not prove the calibration (not measured, contradicted, unconfirmed
    /// or above its target); `None` when it does.
    pub fn failure(&self) -> Option<String> {
        let Some(e) = &self.after_evidence else {
            return Some(format!("`{}`: not measured ({})", self.motion, self.note.as_deref().unwrap_or("no figure")));
        };
        if e.within_target {
            return None;
        }
        Some(match e.verdict {
            MotionVerdict::Confirmed => {
                format!("`{}`: {:.1} nm, above its {:.0} nm target", self.motion, e.measured_nm, e.target_nm)
            }
            _ => format!("`{}`: {}", self.motion, e.summary()),
        })
    }
}

/// Most points kept of a validation curve in a report or session.
pub const CURVE_POINTS: usize = 400;

/// At most `n` evenly spaced samples of `v` (the first and the last included).
pub(crate) fn thin(v: &[f64], n: usize) -> Vec<f64> {
    if v.len() <= n || n < 2 {
        return v.to_vec();
    }
    (0..n).map(|k| v[k * (v.len() - 1) / (n - 1)]).collect()
}

/// The whole calibration report (saved in sessions and `report.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CalibrationReport {
    /// Identifier used.
    pub mode: Mode,
    /// The bench's name.
    pub bench: String,
    /// The Table II-style result.
    pub parameters: Vec<ParameterRow>,
    /// Identifiability and uncertainty.
    pub identifiability: IdentifiabilityReport,
    /// Solver convergence (joint mode: the solver's report; paper mode: step A's).
    pub converged: bool,
    /// The solver's words.
    pub termination: String,
    /// RMS of the normalised residuals (1 = at the noise floor).
    pub residual_rms_sigma: f64,
    /// Residual per observation: label, unit, measured − predicted, σ.
    pub residuals: Vec<(String, String, f64, f64)>,
    /// Validation figures.
    pub validation: Vec<ValidationRow>,
    /// True when the validation figures are predictions on a virtual bench whose truth is the
    /// identified extrinsics (traces recorded elsewhere, no bench to run on), not measurements.
    #[serde(default)]
    pub validation_predicted: bool,
    /// True when the validation motions were left out at the user's request (they cost minutes
    /// of bench time on a real bench; the GUI's Validation view runs them later): `validation`
    /// is then empty, and nothing says the calibration validates.
    #[serde(default)]
    pub validation_not_run: bool,
    /// What the uncertainty of the extrinsics allows each validation motion planned with them
    /// (only when the model fits, with no tie): above a motion's target, no run can meet it.
    #[serde(default)]
    pub validation_forecast: Vec<ValidationForecast>,
    /// Bench time of the measurements (s).
    pub measurement_duration_s: f64,
    /// Bench time of each plan run, in order, from the plans' timing model (empty for traces
    /// recorded elsewhere).
    #[serde(default)]
    pub plan_durations: Vec<PlanDuration>,
    /// Number of observations used.
    pub observations: usize,
    /// Sentences for the user.
    pub warnings: Vec<String>,
    /// The verdict on the fit as a whole (does the model fit, is the branch unique); `None` in
    /// reports saved without one.
    #[serde(default)]
    pub fit: Option<FitCheck>,
    /// The sign of each translation's gap change and the sources that fix it.
    #[serde(default)]
    pub translation_signs: Vec<TranslationSign>,
    /// The model-discrepancy term: each family of observations against the model and against the
    /// others (`identify::discrepancy`); `None` in reports saved without one.
    #[serde(default)]
    pub model_discrepancy: Option<ModelDiscrepancy>,
    /// What leaving the wavelength sweeps out cost (a bench without a tunable laser, or
    /// `calibrate --no-sweeps`), or losing sweeps whose analysis was refused; `None` when every
    /// planned sweep was measured and analysed.
    #[serde(default)]
    pub sweep_cost: Option<crate::identify::sweep_cost::SweepCost>,
    /// Where the command's time went: its stages' wall times and each segment's bench time, the
    /// controllers' waiting and the recorder's reading; `None` in reports saved without one.
    #[serde(default)]
    pub timing: Option<crate::bench::RunTiming>,
    /// The identified extrinsics.
    pub extrinsics: Extrinsics,
    /// The recorded traces.
    #[serde(skip)]
    pub traces: Vec<Trace>,
}

impl CalibrationReport {
    /// The extrinsics of every branch the fit tried, the chosen one first (none without a fit):
    /// the diagnosis refits them once it names an effect the calibration's model lacked.
    pub fn branch_extrinsics(&self) -> Vec<Extrinsics> {
        self.fit.as_ref().map(|f| f.branches.iter().map(|b| b.extrinsics).collect()).unwrap_or_default()
    }

    /// Why the validation does not prove this calibration, one sentence per motion that is not
    /// confirmed within its target; empty when every motion is (or when the validation was not
    /// run, or predicted: the report says so instead).
    pub fn validation_failures(&self) -> Vec<String> {
        if self.validation_not_run || self.validation_predicted {
            return vec![];
        }
        self.validation.iter().filter_map(ValidationRow::failure).collect()
    }
}

/// The bench time of one plan of a calibration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlanDuration {
    /// The plan's name.
    pub name: String,
    /// Its bench time (s), setup moves and settling included.
    pub duration_s: f64,
}

/// The bench time of each plan run one after the other from `start_display` (µm, °), from the
/// plan timing model ([`Plan::expand`]); a plan that does not fit gives its error.
pub fn plan_durations(
    plans: &[Plan],
    robot: &crate::model::robot::RobotDescription,
    limits: &crate::plan::MotionLimits,
    start_display: [f64; 6],
) -> Result<Vec<PlanDuration>, String> {
    let mut at = start_display;
    plans
        .iter()
        .map(|p| {
            let segs = p.expand(robot, at, limits).map_err(|e| format!("plan {}: {e}", p.name))?;
            at = segs.last().map_or(at, |s| s.to_display);
            Ok(PlanDuration { name: p.name.clone(), duration_s: crate::plan::total_duration_s(&segs) })
        })
        .collect()
}

/// The plans a mode measures.
pub fn plans(mode: Mode) -> Vec<Plan> {
    match mode {
        Mode::Paper => vec![Plan::strategy1(), Plan::strategy2()],
        Mode::Joint => vec![Plan::strategy1(), Plan::strategy2(), Plan::joint_extras()],
    }
}

/// Run the plans on the bench; every trace recorded is returned, with the bench time used.
pub fn measure(bench: &mut dyn Bench, plans: &[Plan]) -> Result<(Vec<Trace>, f64), String> {
    let cancel = AtomicBool::new(false);
    let mut traces = Vec::new();
    let mut duration = 0.0;
    for p in plans {
        let mut control = RunControl { cancel: &cancel, on_samples: &mut |_, _| {}, on_progress: &mut |_| {} };
        let run = run_plan(bench, p, &mut control);
        duration += run.duration_s;
        traces.extend(run.traces);
        run.outcome.map_err(|e| format!("plan {}: {e}", p.name))?;
    }
    Ok((traces, duration))
}

/// Rows of the Table II-style result from an estimate and its identifiability report.
pub fn parameter_rows(extrinsics: &Extrinsics, report: &IdentifiabilityReport) -> Vec<ParameterRow> {
    let values = extrinsics.to_array();
    (0..N_EXTRINSICS)
        .map(|i| {
            let (name, unit) = PARAMETER_NAMES[i];
            let uncertainty = report.parameters.iter().find(|p| p.name == name);
            ParameterRow {
                name: name.to_string(),
                value: values[i],
                unit: unit.to_string(),
                sigma: uncertainty.and_then(|u| u.sigma),
                sigma_noise: uncertainty.and_then(|u| u.sigma),
                sigma_systematic: uncertainty.and_then(|u| u.sigma).map(|_| 0.0),
                determined: uncertainty.is_some_and(|u| u.determined),
                reason: match uncertainty {
                    Some(u) => u.reason.clone(),
                    None => Some("held fixed (masked)".into()),
                },
                sigma_from_jackknife: false,
            }
        })
        .collect()
}

/// Measure, identify, report and validate on a bench.
pub fn calibrate(bench: &mut dyn Bench, nominal: &PhaseModel, mode: Mode) -> Result<CalibrationReport, String> {
    let plans = plans(mode);
    let durations = plan_durations(&plans, bench.robot(), bench.motion_limits(), bench.position_display())?;
    let (traces, duration) = measure(bench, &plans)?;
    let mut report = report_from_traces(traces, duration, bench.name(), nominal, mode)?;
    report.plan_durations = durations;
    report.validation = validation_rows(bench, nominal, &report.extrinsics, &StopSettings::default());
    Ok(report)
}

/// Identify from recorded traces and build the report (without validation, which needs a
/// bench: see [`validation_rows`]). `bench_name` says where the traces come from.
pub fn report_from_traces(
    traces: Vec<Trace>,
    duration_s: f64,
    bench_name: String,
    nominal: &PhaseModel,
    mode: Mode,
) -> Result<CalibrationReport, String> {
    let id = identify(&traces, nominal, mode)?;
    Ok(report_from_identification(&id, traces, duration_s, bench_name, nominal, mode))
}

/// [`report_from_traces`] of an identification already made from `traces`.
pub fn report_from_identification(
    id: &Identification,
    traces: Vec<Trace>,
    duration_s: f64,
    bench_name: String,
    nominal: &PhaseModel,
    mode: Mode,
) -> CalibrationReport {
    let report = analyse_estimate(&id.estimate);
    let fit = fit_check(id, &report);
    // Reported with their angles wrapped to ±180° (the same rotations): an angle the data do not
    // see can end whole turns away. The identification itself runs on the solver's values.
    let extrinsics = id.estimate.extrinsics.with_angles_wrapped();
    let mut parameters = parameter_rows(&extrinsics, &report);
    let discrepancy = discrepancy_of(id);
    add_systematic(&mut parameters, id, &discrepancy);
    withhold_undetermined(&mut parameters, &fit);
    let lost = lost_sweeps(id, &traces, nominal, &fit);
    if let Some(cost) = &lost {
        withhold_lost(&mut parameters, cost);
    }
    let (est, obs) = (&id.estimate, &id.observations);
    let mut warnings = report.warnings.clone();
    if let Some(cost) = lost.as_ref().filter(|c| !c.is_free()) {
        warnings.insert(0, format!("not a complete calibration: {}", cost.sentences().join("; ")));
    }
    if fit.verdict != Verdict::Fits {
        warnings.insert(0, fit.summary.clone());
    }
    for (label, factor) in &id.downweighted {
        warnings.push(format!(
            "trace `{label}`: residual {factor:.1}σ rms, an outlier: its σ multiplied by {factor:.1} in the estimate"
        ));
    }
    for (label, why) in &id.skipped {
        warnings.push(format!("trace `{label}` not used: {why}"));
    }
    for (label, why) in &id.hint_led {
        warnings.push(format!("trace `{label}`: {why}"));
    }
    if !est.converged {
        warnings
            .push(format!("the solver did not converge ({}): the values below are not a calibration", est.termination));
    }
    // Only a fit has an uncertainty to carry: tied branches leave parameters without one.
    let validation_forecast = match fit.verdict {
        Verdict::Fits => forecast_validation(nominal, &est.extrinsics, &parameters, &report),
        _ => vec![],
    };
    for f in validation_forecast.iter().filter(|f| !f.within_target()) {
        warnings.push(format!(
            "`{}`: planned with these extrinsics it can move the gap by up to {:.0} nm (95 %, from their \
             uncertainty), above its {:.0} nm target: the data do not determine them well enough for it",
            f.motion, f.expected_nm, f.target_nm
        ));
    }
    let signs = translation_signs(obs, est);
    for s in signs.iter().filter(|s| !s.agrees) {
        warnings.push(format!(
            "translation `{}`: its measured gap change ({:+.1} nm) disagrees in sign with {}",
            s.label,
            s.dl_nm,
            s.evidence.iter().map(|e| e.source.words()).collect::<Vec<_>>().join(", ")
        ));
    }
    CalibrationReport {
        mode,
        bench: bench_name,
        parameters,
        identifiability: report,
        converged: est.converged,
        termination: est.termination.clone(),
        residual_rms_sigma: fit.rms_sigma,
        residuals: obs
            .iter()
            .zip(&est.residuals)
            .map(|(o, r)| (o.label.clone(), o.unit().to_string(), *r, o.sigma))
            .collect(),
        validation: Vec::new(),
        validation_predicted: false,
        validation_not_run: false,
        validation_forecast,
        measurement_duration_s: duration_s,
        plan_durations: Vec::new(),
        observations: obs.len(),
        warnings,
        fit: Some(fit),
        translation_signs: signs,
        model_discrepancy: Some(discrepancy),
        sweep_cost: lost,
        timing: None,
        extrinsics,
        traces,
    }
}

/// What the sweeps whose analysis the identification refused cost it
/// ([`crate::identify::sweep_cost::lost`]); `None` when none was lost.
fn lost_sweeps(
    id: &Identification,
    traces: &[Trace],
    nominal: &PhaseModel,
    fit: &FitCheck,
) -> Option<crate::identify::sweep_cost::SweepCost> {
    let lost: Vec<LostSweep> = id
        .skipped
        .iter()
        .filter_map(|(label, why)| {
            let t = traces.iter().find(|t| &t.meta.label == label && crate::trace::is_sweep(t))?;
            Some(LostSweep {
                label: label.clone(),
                at_display: t.joints_display(0),
                wavelength_nm: t.wavelength_nm[t.len() / 2],
                time_s: [t.t_s[0], t.t_s[t.len() - 1]],
                why: why.clone(),
            })
        })
        .collect();
    if lost.is_empty() {
        return None;
    }
    let model = PhaseModel { extrinsics: id.estimate.extrinsics, ..nominal.clone() };
    Some(crate::identify::sweep_cost::lost(&model, &id.observations, &id.estimate.extrinsics, lost, Some(fit)))
}

/// No parameter is determined that the lost sweeps would determine and the rest of the data do not.
fn withhold_lost(rows: &mut [ParameterRow], cost: &crate::identify::sweep_cost::SweepCost) {
    let labels: Vec<&str> = cost.lost.iter().map(|l| l.label.as_str()).collect();
    for row in rows.iter_mut().filter(|r| cost.undetermined.iter().any(|p| p.name == r.name)) {
        row.determined = false;
        (row.sigma, row.sigma_noise, row.sigma_systematic) = (None, None, None);
        row.reason = Some(format!("its sweeps were lost (their analysis refused): `{}`", labels.join("`, `")));
    }
}

/// The validation forecast ([`forecast`]) of the parameters reported: their σ (withheld ones
/// left out) and the identifiability's correlations.
fn forecast_validation(
    nominal: &PhaseModel,
    identified: &Extrinsics,
    parameters: &[ParameterRow],
    report: &IdentifiabilityReport,
) -> Vec<ValidationForecast> {
    let (sigma, correlation) = uncertainty_of(parameters, report);
    forecast(nominal, identified, &sigma, &correlation)
}

/// The uncertainty of the extrinsics as the forecasts take it: the σ of each parameter of
/// [`PARAMETER_NAMES`] the data determine (`None`: withheld or not determined) and the
/// identifiability's correlations (0 where undefined).
pub fn uncertainty_of(
    parameters: &[ParameterRow],
    report: &IdentifiabilityReport,
) -> ([Option<f64>; 8], [[f64; 8]; 8]) {
    let index = |name: &str| report.parameters.iter().position(|p| p.name == name);
    let sigma: [Option<f64>; 8] = std::array::from_fn(|i| {
        parameters.iter().find(|p| p.name == PARAMETER_NAMES[i].0 && p.determined).and_then(|p| p.sigma)
    });
    let correlation: [[f64; 8]; 8] = std::array::from_fn(|i| {
        std::array::from_fn(|j| match (index(PARAMETER_NAMES[i].0), index(PARAMETER_NAMES[j].0)) {
            (Some(a), Some(b)) => report.correlation.get(a).and_then(|r| r.get(b).copied().flatten()).unwrap_or(0.0),
            _ => 0.0,
        })
    });
    (sigma, correlation)
}

/// The verdict on the identification's fit: its residual against [`rms_threshold`], the worst
/// traces, and the branches that tie with it.
pub fn fit_check(id: &Identification, report: &IdentifiabilityReport) -> FitCheck {
    let est = &id.estimate;
    let normalised = &id.raw_normalised_residuals();
    let rms_sigma = (normalised.iter().map(|v| v * v).sum::<f64>() / normalised.len().max(1) as f64).sqrt();
    let threshold_sigma = rms_threshold(normalised.len(), est.weighted_jacobian.ncols());
    let labels: Vec<String> = id.observations.iter().map(|o| o.label.clone()).collect();
    let sigma: Vec<Option<f64>> = PARAMETER_NAMES
        .iter()
        .map(|(name, _)| report.parameters.iter().find(|p| p.name == *name).and_then(|p| p.sigma))
        .collect();
    let mut ambiguous_parameters: Vec<String> = Vec::new();
    // Tied branches may differ freely where the data determine nothing: only a determined
    // parameter they disagree on makes the result ambiguous.
    let determined = |name: &str| report.parameters.iter().any(|p| p.name == name && p.determined);
    for &t in &id.tied {
        for p in differing_parameters(&est.extrinsics, &id.branches[t].extrinsics, &sigma, 3.0) {
            if determined(&p) && !ambiguous_parameters.contains(&p) {
                ambiguous_parameters.push(p);
            }
        }
    }
    let (verdict, summary) = if rms_sigma > threshold_sigma || !rms_sigma.is_finite() {
        (
            Verdict::DoesNotFit,
            format!(
                "the model does not fit these data: residual {rms_sigma:.2}σ rms, above the {threshold_sigma:.2}σ that \
                 noise allows for {} observations; no parameter is determined (worst traces listed)",
                normalised.len()
            ),
        )
    } else if !ambiguous_parameters.is_empty() {
        (
            Verdict::Ambiguous,
            format!(
                "{} branches fit these data equally well; they differ in {}, which are not determined",
                id.tied.len() + 1,
                ambiguous_parameters.join(", ")
            ),
        )
    } else {
        (Verdict::Fits, format!("the model fits: residual {rms_sigma:.2}σ rms (threshold {threshold_sigma:.2}σ)"))
    };
    FitCheck {
        verdict,
        rms_sigma,
        threshold_sigma,
        worst_traces: worst_traces(&labels, normalised, WORST_TRACES),
        branches: id.branches.clone(),
        tied_branches: id.tied.clone(),
        ambiguous_parameters,
        summary,
    }
}

/// The model-discrepancy term of an identification's fit ([`model_discrepancy`]).
pub fn discrepancy_of(id: &Identification) -> ModelDiscrepancy {
    let est = &id.estimate;
    let m = id.observations.len().min(est.weighted_jacobian.nrows());
    model_discrepancy(&est.weighted_jacobian, &est.normalised_residuals[..m], &id.observations, &est.column_parameter)
}

/// Each determined parameter's systematic σ, what noise cannot explain: the larger of the
/// families' disagreement ([`ModelDiscrepancy::sigma_from_families`]) and the jackknife σ over the
/// traces in excess of the noise σ ([`jackknife_sigma`]); the total σ is both in quadrature. A
/// parameter whose total σ exceeds its useful bound is not determined.
fn add_systematic(rows: &mut [ParameterRow], id: &Identification, discrepancy: &ModelDiscrepancy) {
    use crate::identify::observability::{DEFAULT_USEFUL_ANGLE_DEG, DEFAULT_USEFUL_LENGTH_UM};
    let est = &id.estimate;
    let m = id.observations.len().min(est.weighted_jacobian.nrows());
    let labels: Vec<String> = id.observations.iter().take(m).map(|o| o.label.clone()).collect();
    let jacobian = est.weighted_jacobian.rows(0, m).into_owned();
    let jack = jackknife_sigma(&jacobian, &est.normalised_residuals[..m], &labels);
    for row in rows.iter_mut().filter(|r| r.determined) {
        let Some(i) = PARAMETER_NAMES.iter().position(|(n, _)| *n == row.name) else { continue };
        let Some(noise) = row.sigma_noise else { continue };
        let c = est.column_parameter.iter().position(|p| *p == Some(i));
        let spread = match (&jack, c) {
            (Some(jack), Some(c)) => (jack[c] * crate::identify::parameter_scale(i)).powi(2) - noise * noise,
            _ => 0.0,
        };
        let families = discrepancy.sigma_from_families.get(i).copied().flatten().unwrap_or(0.0).powi(2);
        let systematic = spread.max(families).max(0.0).sqrt();
        let total = noise.hypot(systematic);
        row.sigma = Some(total);
        row.sigma_systematic = Some(systematic);
        row.sigma_from_jackknife = spread > families && spread > 0.0;
        let bound = if row.unit == "°" { DEFAULT_USEFUL_ANGLE_DEG } else { DEFAULT_USEFUL_LENGTH_UM };
        if total > bound {
            let why =
                if row.sigma_from_jackknife { "the traces disagree" } else { "the families of observations disagree" };
            row.determined = false;
            row.reason = Some(format!("{why}: total σ {total:.3} {} (above its useful bound)", row.unit));
            (row.sigma, row.sigma_noise, row.sigma_systematic) = (None, None, None);
        }
    }
}

/// No parameter is determined by a fit that does not fit, nor one that tied branches disagree on.
fn withhold_undetermined(rows: &mut [ParameterRow], fit: &FitCheck) {
    for row in rows.iter_mut() {
        let reason = match fit.verdict {
            Verdict::DoesNotFit => Some(format!(
                "the model does not fit these data ({:.2}σ rms > {:.2}σ)",
                fit.rms_sigma, fit.threshold_sigma
            )),
            Verdict::Ambiguous if fit.ambiguous_parameters.contains(&row.name) => {
                let i = PARAMETER_NAMES.iter().position(|(n, _)| *n == row.name).unwrap_or(0);
                let values: Vec<String> = std::iter::once(0)
                    .chain(fit.tied_branches.iter().copied())
                    .filter_map(|b| fit.branches.get(b))
                    .map(|b| format!("{:.4}", b.extrinsics.to_array()[i]))
                    .collect();
                Some(format!("tied branches disagree: {} {}", values.join(" or "), row.unit))
            }
            _ => None,
        };
        if let Some(reason) = reason {
            row.determined = false;
            (row.sigma, row.sigma_noise, row.sigma_systematic) = (None, None, None);
            row.reason = Some(reason);
        }
    }
}

/// The validation motions planned with the nominal extrinsics (before) and with `identified`
/// (after), run on the bench with the stops `stops` and measured with the identified model
/// ([`run_before_and_after`], what the GUI's validation runs). Each figure is the one its proof
/// stands behind ([`Evidence::measured_nm`]).
pub fn validation_rows(
    bench: &mut dyn Bench,
    nominal: &PhaseModel,
    identified: &Extrinsics,
    stops: &StopSettings,
) -> Vec<ValidationRow> {
    run_before_and_after(bench, nominal, identified, stops)
        .into_iter()
        .map(|BeforeAndAfter { motion: m, before, after }| ValidationRow {
            motion: m.name().to_string(),
            before_nm: before.as_ref().ok().map(|f| f.evidence.measured_nm),
            after_nm: after.as_ref().ok().map(|f| f.evidence.measured_nm),
            paper_nm: m.paper_after_nm(),
            note: crate::validate::pair_note(&before, &after),
            before_curve_nm: before.as_ref().map_or(vec![], |f| thin(&f.variation_nm, CURVE_POINTS)),
            after_curve_nm: after.as_ref().map_or(vec![], |f| thin(&f.variation_nm, CURVE_POINTS)),
            before_evidence: before.as_ref().ok().map(|f| f.evidence.clone()),
            after_evidence: after.as_ref().ok().map(|f| f.evidence.clone()),
        })
        .collect()
}

/// The validation motions planned with `identified` alone, run on the bench and measured with
/// the identified model ([`check_calibration`]): the proof of the calibration without the
/// comparison with the nominal extrinsics, in half the bench time (`before_nm` stays empty).
pub fn validation_rows_after(
    bench: &mut dyn Bench,
    nominal: &PhaseModel,
    identified: &Extrinsics,
    stops: &StopSettings,
) -> Vec<ValidationRow> {
    check_calibration(bench, nominal, identified, stops)
        .into_iter()
        .map(|(m, after)| ValidationRow {
            motion: m.name().to_string(),
            before_nm: None,
            after_nm: after.as_ref().ok().map(|f| f.evidence.measured_nm),
            paper_nm: m.paper_after_nm(),
            note: match &after {
                Err(e) => Some(e.to_string()),
                Ok(f) => f.tracking_note(),
            },
            before_curve_nm: vec![],
            after_curve_nm: after.as_ref().map_or(vec![], |f| thin(&f.variation_nm, CURVE_POINTS)),
            before_evidence: None,
            after_evidence: after.as_ref().ok().map(|f| f.evidence.clone()),
        })
        .collect()
}

/// Validation predicted without a bench (traces recorded elsewhere): the validation motions run
/// on a virtual bench built from `preset` whose truth is `identified` and which hides no
/// effects. "After" is the tracking floor of the identified model; with `before`, each motion
/// also runs planned with the nominal extrinsics, which says what they would do on a bench that
/// really has the identified ones (twice the time, as on a bench: [`validation_rows`]).
pub fn predicted_validation_rows(
    preset: &crate::bench::BenchPreset,
    nominal: &PhaseModel,
    identified: &Extrinsics,
    before: bool,
) -> Result<Vec<ValidationRow>, String> {
    let mut p = preset.clone();
    p.truth = *identified;
    p.effects.clear();
    let mut bench = crate::bench::VirtualBench::new(&p, None).map_err(|e| e.to_string())?;
    Ok(validation_rows_as_asked(&mut bench, nominal, identified, &StopSettings::default(), before))
}

/// The validation a calibration asks for: each motion planned with the nominal extrinsics as
/// well with `before` ([`validation_rows`]), else with the identified ones alone
/// ([`validation_rows_after`]).
pub fn validation_rows_as_asked(
    bench: &mut dyn Bench,
    nominal: &PhaseModel,
    identified: &Extrinsics,
    stops: &StopSettings,
    before: bool,
) -> Vec<ValidationRow> {
    match before {
        true => validation_rows(bench, nominal, identified, stops),
        false => validation_rows_after(bench, nominal, identified, stops),
    }
}
