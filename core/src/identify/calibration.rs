//! A whole calibration: run the measurement plans on a bench, turn traces into observations, identify
//! (paper mode or joint estimate), report uncertainties and validate. Owns the order of those steps and the report.
//!
//! The motion hint of the fringe analysis needs a rough model first: lateral moves show no
//! fringes in a model with square lamella and fiber. The wavelength sweeps measure absolute
//! gaps at many poses, and gap differences between poses give the lamella normal n_t, so the
//! first estimate comes from the sweeps alone (a bootstrap); the traces are then analysed
//! with it, the full estimate made, and the traces analysed once more with that estimate.

use crate::bench::{run_plan, Bench, RunControl};
use crate::identify::joint::{self, JointEstimate, JointOptions};
use crate::identify::measurements::{observations_from_traces, ExtractOptions};
use crate::identify::observability::IdentifiabilityReport;
use crate::identify::{paper, Observation, ObservationKind, N_EXTRINSICS};
use crate::measure::PhaseModel;
use crate::model::extrinsics::{Extrinsics, PARAMETER_NAMES};
use crate::plan::Plan;
use crate::trace::Trace;
use crate::validate::{run_validation, ValidationMotion};
use serde::{Deserialize, Serialize};
use std::sync::atomic::AtomicBool;

/// Which identifier.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Mode {
    /// The paper's steps A, B, C on strategies 1 and 2.
    Paper,
    /// Every parameter from every measurement at once, with tilt scans and absolute gaps.
    Joint,
}

/// One row of the Table II-style result.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ParameterRow {
    /// Parameter name (paper's).
    pub name: String,
    /// Value (display unit).
    pub value: f64,
    /// Unit.
    pub unit: String,
    /// Standard uncertainty, `None` when the data do not determine the parameter.
    pub sigma: Option<f64>,
    /// Whether the data determine it.
    pub determined: bool,
    /// Why not, when not.
    pub reason: Option<String>,
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
    /// The identified extrinsics.
    pub extrinsics: Extrinsics,
    /// The recorded traces.
    #[serde(skip)]
    pub traces: Vec<Trace>,
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

fn model_with(base: &PhaseModel, e: Extrinsics) -> PhaseModel {
    PhaseModel { extrinsics: e, ..base.clone() }
}

/// Identify from recorded traces. `nominal` is the model before calibration (design
/// extrinsics); it also supplies the robot, optics and air.
pub fn identify(traces: &[Trace], nominal: &PhaseModel, mode: Mode) -> Result<Identification, String> {
    let opts = ExtractOptions::default();
    // The motion traces need the model's motion hint, so they are analysed again with each
    // better model. The sweeps depend on the model only through the small tilt correction of
    // the phase: the nominal analysis serves the bootstrap and the first pass, and they are
    // analysed again with the first estimate for the final pass.
    let (sweeps, motions): (Vec<Trace>, Vec<Trace>) = traces.iter().cloned().partition(crate::measure::is_sweep);
    let mut swept = observations_from_traces(&sweeps, nominal, &opts);
    if swept.observations.len() < 3 {
        return Err(format!(
            "{} usable absolute-gap sweeps (at least 3 at different poses are needed to start the identification)",
            swept.observations.len()
        ));
    }
    // Bootstrap from the absolute gaps: the lamella normal and the gap.
    let boot_opts = JointOptions { free: [true, true, false, false, false, false, true, false], ..Default::default() };
    let boot = joint::estimate(nominal, &swept.observations, &nominal.extrinsics, &boot_opts);
    let mut current = boot.extrinsics;
    let mut last = None;
    // Paper mode analyses the traces once, with the bootstrap model: its steps leave the
    // fiber direction and the gap split undetermined, so its estimate is no better model for
    // the motion hints than the bootstrap.
    let passes = match mode {
        Mode::Joint => 2,
        Mode::Paper => 1,
    };
    for pass in 0..passes {
        if pass > 0 {
            swept = observations_from_traces(&sweeps, &model_with(nominal, current), &opts);
        }
        let model = model_with(nominal, current);
        let mut extracted = observations_from_traces(&motions, &model, &opts);
        extracted.skipped.extend(swept.skipped.iter().cloned());
        let mut obs = swept.observations.clone();
        obs.append(&mut extracted.observations);
        let (est, step_a, obs) = match mode {
            Mode::Joint => (joint::estimate(nominal, &obs, &current, &JointOptions::default()), None, obs),
            Mode::Paper => {
                let translations: Vec<Observation> = obs.iter().filter(|o| is_translation(o)).cloned().collect();
                let rotations: Vec<Observation> = obs.iter().filter(|o| is_rotation(o)).cloned().collect();
                let a = paper::step_a_with(&nominal.chain, &translations, &current, true);
                let b = paper::step_b(&nominal.chain, &rotations, a.angles_deg);
                let e = Extrinsics {
                    beta_et_deg: a.angles_deg[0],
                    theta_et_deg: a.angles_deg[1],
                    beta_wf_deg: a.angles_deg[2],
                    theta_wf_deg: a.angles_deg[3],
                    z_et_um: b.origins_um[0],
                    x_wf_um: b.origins_um[1],
                    y_wf_um: b.origins_um[2],
                    z_wf_um: b.origins_um[3],
                };
                // Uncertainties of the paper's result: the joint machinery evaluated at it,
                // on the paper's data only (one evaluation, no move).
                // Step A's data only: step B reads the fringes as the change of L along the beam
                // where they measure the perpendicular distance (a bias of |L|·(1 − cos γ), µm
                // over the 4° rotations), so its residuals say nothing about the noise, and the
                // origins stay undetermined by the data the method can trust.
                // Evaluated with the bootstrap's origins (translations barely depend on them),
                // then the step B origins put back for the report.
                let at = Extrinsics {
                    z_et_um: current.z_et_um,
                    x_wf_um: current.x_wf_um,
                    y_wf_um: current.y_wf_um,
                    z_wf_um: current.z_wf_um,
                    ..e
                };
                let mut est = joint::evaluate(nominal, &translations, &at, &JointOptions::default());
                est.extrinsics = e;
                est.converged = a.converged;
                est.termination = format!("step A: {}", if a.converged { "converged" } else { "did not converge" });
                (est, Some(a), translations)
            }
        };
        current = est.extrinsics;
        last = Some(Identification { estimate: est, observations: obs, step_a, skipped: extracted.skipped });
    }
    last.ok_or_else(|| "no identification pass ran".to_string())
}

/// What [`identify`] found.
#[derive(Debug, Clone)]
pub struct Identification {
    /// The estimate with its Jacobian and residuals.
    pub estimate: JointEstimate,
    /// The observations it used.
    pub observations: Vec<Observation>,
    /// Paper mode: step A's details.
    pub step_a: Option<paper::StepA>,
    /// Traces that gave no observation (label, why).
    pub skipped: Vec<(String, String)>,
}

fn joints_changed(o: &Observation) -> Option<[bool; 6]> {
    match o.kind {
        ObservationKind::GapChange { from_display, to_display, .. } => {
            Some(std::array::from_fn(|i| (from_display[i] - to_display[i]).abs() > 1e-9))
        }
        _ => None,
    }
}

fn is_translation(o: &Observation) -> bool {
    joints_changed(o).is_some_and(|c| c[..3].iter().any(|&x| x) && !c[3..].iter().any(|&x| x))
}

fn is_rotation(o: &Observation) -> bool {
    joints_changed(o).is_some_and(|c| c[3..].iter().any(|&x| x) && !c[..3].iter().any(|&x| x))
}

/// The identifiability report of a joint estimate: its weighted Jacobian and residuals, the
/// free extrinsics with their useful bounds, and the detector gains as nuisance parameters.
pub fn analyse_estimate(est: &JointEstimate) -> IdentifiabilityReport {
    use crate::identify::observability::{analyse, Options, ParamInfo};
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

/// Rows of the Table II-style result from an estimate and its identifiability report.
pub fn parameter_rows(e: &Extrinsics, report: &IdentifiabilityReport) -> Vec<ParameterRow> {
    let values = e.to_array();
    (0..N_EXTRINSICS)
        .map(|i| {
            let (name, unit) = PARAMETER_NAMES[i];
            let u = report.parameters.iter().find(|p| p.name == name);
            ParameterRow {
                name: name.to_string(),
                value: values[i],
                unit: unit.to_string(),
                sigma: u.and_then(|u| u.sigma),
                determined: u.is_some_and(|u| u.determined),
                reason: match u {
                    Some(u) => u.reason.clone(),
                    None => Some("held fixed (masked)".into()),
                },
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
    report.validation = validation_rows(bench, nominal, &report.extrinsics);
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
    let (est, obs) = (id.estimate, id.observations);
    let report = analyse_estimate(&est);
    let mut warnings = report.warnings.clone();
    for (label, why) in &id.skipped {
        warnings.push(format!("trace `{label}` not used: {why}"));
    }
    if !est.converged {
        warnings
            .push(format!("the solver did not converge ({}): the values below are not a calibration", est.termination));
    }
    let rms = (est.normalised_residuals.iter().map(|r| r * r).sum::<f64>()
        / est.normalised_residuals.len().max(1) as f64)
        .sqrt();
    Ok(CalibrationReport {
        mode,
        bench: bench_name,
        parameters: parameter_rows(&est.extrinsics, &report),
        identifiability: report,
        converged: est.converged,
        termination: est.termination.clone(),
        residual_rms_sigma: rms,
        residuals: obs
            .iter()
            .zip(&est.residuals)
            .map(|(o, r)| (o.label.clone(), o.unit().to_string(), *r, o.sigma))
            .collect(),
        validation: Vec::new(),
        validation_predicted: false,
        measurement_duration_s: duration_s,
        plan_durations: Vec::new(),
        observations: obs.len(),
        warnings,
        extrinsics: est.extrinsics,
        traces,
    })
}

/// The validation motions planned with the nominal extrinsics (before) and with `identified`
/// (after), run on the bench and measured with the identified model.
pub fn validation_rows(bench: &mut dyn Bench, nominal: &PhaseModel, identified: &Extrinsics) -> Vec<ValidationRow> {
    let after_model = model_with(nominal, *identified);
    ValidationMotion::ALL
        .iter()
        .map(|&m| {
            let before = run_validation(bench, &after_model, &nominal.extrinsics, m, [0.0; 6]);
            let after = run_validation(bench, &after_model, identified, m, [0.0; 6]);
            let note = crate::validate::pair_note(&before, &after);
            ValidationRow {
                motion: m.name().to_string(),
                before_nm: before.as_ref().ok().map(|f| f.peak_to_peak_nm),
                after_nm: after.as_ref().ok().map(|f| f.peak_to_peak_nm),
                paper_nm: m.paper_after_nm(),
                note,
                before_curve_nm: before.as_ref().map_or(vec![], |f| thin(&f.variation_nm, CURVE_POINTS)),
                after_curve_nm: after.as_ref().map_or(vec![], |f| thin(&f.variation_nm, CURVE_POINTS)),
            }
        })
        .collect()
}

/// Validation predicted without a bench (traces recorded elsewhere): the validation motions run
/// on a virtual bench built from `preset` whose truth is `identified` and which hides no
/// effects. "Before" then says what the nominal extrinsics would do on a bench that really has
/// the identified ones; "after" is the tracking floor of the identified model.
pub fn predicted_validation_rows(
    preset: &crate::bench::BenchPreset,
    nominal: &PhaseModel,
    identified: &Extrinsics,
) -> Result<Vec<ValidationRow>, String> {
    let mut p = preset.clone();
    p.truth = *identified;
    p.effects.clear();
    let mut bench = crate::bench::VirtualBench::new(&p, None).map_err(|e| e.to_string())?;
    Ok(validation_rows(&mut bench, nominal, identified))
}
