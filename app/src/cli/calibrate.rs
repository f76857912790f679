//! `photorobot calibrate --bench <preset> [--seed N] [--mode paper|joint] --out <session> [--json]`: measure,
//! identify and validate end to end; with `--traces <dir> [--mapping <file>]`, identify from traces recorded
//! elsewhere. Owns only argument parsing and printing; the work is `photorobot_core::calibration`,
//! `photorobot_core::session` and `photorobot_core::trace::import`.
//!
//! The session folder gets `session.ron` (the session: bench, robot, plans, trace references,
//! the calibration), every recorded trace (`traces/NNN.csv`, each saved as soon as it is
//! measured, with the session autosaved after it), the identified extrinsics (`extrinsics.ron`,
//! loadable by `photorobot frames --extrinsics`) and the whole report (`report.json`). Every file
//! is written atomically. `--resume` continues a measurement a crash interrupted. The folder is locked
//! while calibrate runs: a second photorobot writing into it is refused.

use super::common::{json_text, load_plan, CliError};
use photorobot_core::bench::{BenchPreset, RunControl, VirtualBench};
use photorobot_core::calibration::{
    plan_durations, plans, predicted_validation_rows, report_from_traces, validation_rows, CalibrationReport, Mode,
};
use photorobot_core::files::{save_ron, write_atomic};
use photorobot_core::identify::signs::{SignSource, TranslationSign};
use photorobot_core::identify::verdict::{FitCheck, Verdict};
use photorobot_core::model::extrinsics::Extrinsics;
use photorobot_core::model::phase::PhaseModel;
use photorobot_core::session::{
    find_recovery, recording::record, BenchInfo, FolderLock, Session, SessionWriter, AUTOSAVE_FILE,
};
use photorobot_core::trace::import::{read_folder, ColumnMapping};
use photorobot_core::trace::Trace;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

/// Which identifier.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ModeArg {
    /// The paper's steps A, B, C on strategies 1 and 2 (10.9 min of bench time).
    Paper,
    /// Every parameter from every measurement, with tilt scans and absolute gaps (2.0 min more; or --plan).
    Joint,
}

/// Arguments of `photorobot calibrate`.
#[derive(Debug, clap::Args)]
pub struct CalibrateArgs {
    /// Bench preset: an embedded name (table2-ideal, femto-lab) or a preset file (RON). With
    /// --traces, the model of the bench that recorded them (robot, optics, laser).
    #[arg(long, value_name = "PRESET")]
    pub bench: String,
    /// Random seed of the virtual bench (default: the preset's).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Identifier.
    #[arg(long, value_enum, default_value_t = ModeArg::Joint)]
    pub mode: ModeArg,
    /// Session folder to create (session.ron, traces, extrinsics.ron, report.json).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Identify from a folder of CSV traces (one motion or sweep per file) instead of measuring.
    #[arg(long, value_name = "DIR", conflicts_with = "resume")]
    pub traces: Option<PathBuf>,
    /// Column mapping (RON) for traces from another acquisition system (default: our format).
    #[arg(long, value_name = "FILE", requires = "traces")]
    pub mapping: Option<PathBuf>,
    /// Measure these plans instead of the mode's (repeatable, run in order): a plan file (RON) or
    /// an embedded plan (strategy1, strategy2, joint-extras, optimised). Joint mode on
    /// `--plan optimised` runs the experiment design's plan (`photorobot design`).
    #[arg(long = "plan", value_name = "PLAN", conflicts_with_all = ["traces", "resume"])]
    pub plans: Vec<String>,
    /// Continue the measurement autosaved in --out (after a crash) instead of starting anew.
    #[arg(long)]
    pub resume: bool,
    /// Print the report as JSON instead of tables.
    #[arg(long)]
    pub json: bool,
}

/// Run the calibration and write the session.
pub fn calibrate(a: &CalibrateArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let preset = BenchPreset::resolve(&a.bench)?;
    let nominal = nominal_model(&preset)?;
    let mode = match a.mode {
        ModeArg::Paper => Mode::Paper,
        ModeArg::Joint => Mode::Joint,
    };
    // The folder is ours until the session is written: a second photorobot is refused.
    let _lock = FolderLock::acquire(&a.out)?;
    refuse_saved_session(a)?;
    let (mut session, report) = match &a.traces {
        Some(dir) => calibrate_from_traces(a, dir, &preset, &nominal, mode)?,
        None => calibrate_on_virtual_bench(a, &preset, &nominal, mode)?,
    };
    let json = write_session(a, &mut session, &report)?;
    if a.json {
        writeln!(out, "{json}")?;
    } else {
        print_report(&report, out)?;
        writeln!(out, "\nsession written to {}", a.out.display())?;
    }
    calibration_verdict(a, &report)
}

/// The software's model: the bench's robot description and optics, the design extrinsics.
fn nominal_model(preset: &BenchPreset) -> Result<PhaseModel, CliError> {
    PhaseModel::new(
        preset.robot_description()?,
        Extrinsics::nominal_design(),
        preset.optics,
        &preset.ambient,
        preset.laser.wavelength_nm,
    )
    .map_err(|problem| CliError::Argument { argument: "--bench", problem })
}

/// Never overwrite recorded data: a folder that holds a saved session is left alone.
fn refuse_saved_session(a: &CalibrateArgs) -> Result<(), CliError> {
    if photorobot_core::session::session_path(&a.out).exists() && !a.resume {
        return Err(CliError::Argument {
            argument: "--out",
            problem: format!("{} already holds a session (session.ron); choose another folder", a.out.display()),
        });
    }
    Ok(())
}

/// A calibration that could not be computed.
fn calibration_failed(problem: String) -> CliError {
    CliError::Failed { what: "calibration", problem }
}

/// `--traces`: identify from a folder of traces recorded elsewhere; the validation is predicted
/// on a virtual bench, since no bench runs.
fn calibrate_from_traces(
    a: &CalibrateArgs,
    dir: &Path,
    preset: &BenchPreset,
    nominal: &PhaseModel,
    mode: Mode,
) -> Result<(Session, CalibrationReport), CliError> {
    let mapping = a.mapping.as_deref().map(ColumnMapping::load).transpose()?;
    let traces = read_folder(dir, mapping.as_ref())?;
    if std::fs::canonicalize(dir).ok() == std::fs::canonicalize(a.out.join("traces")).ok() {
        return Err(CliError::Argument {
            argument: "--out",
            problem: format!("{} would overwrite the traces it reads from; choose another folder", a.out.display()),
        });
    }
    let bench = BenchInfo {
        name: format!("recorded traces from {}", dir.display()),
        preset: Some(a.bench.clone()),
        description: Some(preset.clone()),
        seed: None,
    };
    let mut session = Session::new(bench, preset.robot_description()?);
    session.notes = match &a.mapping {
        Some(m) => format!("traces imported from {} with the column mapping {}", dir.display(), m.display()),
        None => format!("traces imported from {}", dir.display()),
    };
    for t in &traces {
        session.add_trace(&a.out, t, None, true)?;
    }
    let duration_s = traces.iter().map(span_s).sum();
    let name = session.bench.name.clone();
    let mut report = report_from_traces(traces, duration_s, name, nominal, mode).map_err(calibration_failed)?;
    report.validation = predicted_validation_rows(preset, nominal, &report.extrinsics).map_err(calibration_failed)?;
    report.validation_predicted = true;
    Ok((session, report))
}

/// Measure the plans on a virtual bench of the preset (each trace saved as it is recorded),
/// identify, and run the validation motions on the same bench.
fn calibrate_on_virtual_bench(
    a: &CalibrateArgs,
    preset: &BenchPreset,
    nominal: &PhaseModel,
    mode: Mode,
) -> Result<(Session, CalibrationReport), CliError> {
    let mut bench = VirtualBench::new(preset, a.seed)?;
    let session = if a.resume { Session::recover(&a.out)? } else { new_session(a, preset, &bench, mode)? };
    // Each plan's bench time from the timing model, every plan from the start (q = 0).
    let durations = plan_durations(&session.plans, &session.robot, &preset.motion, [0.0; 6])
        .map_err(|problem| CliError::Argument { argument: "--plan", problem })?;
    let cancel = AtomicBool::new(false);
    let mut control = RunControl { cancel: &cancel, on_samples: &mut |_, _| {}, on_progress: &mut |_| {} };
    let mut writer = SessionWriter::new(&a.out, session);
    let recorded = record(&mut bench, &mut writer, &mut control)?;
    let session = writer.into_session();
    recorded.outcome?;
    let traces = session.load_traces(&a.out)?;
    let name = session.bench.name.clone();
    let mut report =
        report_from_traces(traces, recorded.duration_s, name, nominal, mode).map_err(calibration_failed)?;
    report.plan_durations = durations;
    report.validation = validation_rows(&mut bench, nominal, &report.extrinsics);
    Ok((session, report))
}

/// A new session on the bench with the plans to measure (the mode's or `--plan`'s); refused when
/// `--out` holds an unfinished measurement that `--resume` should continue.
fn new_session(a: &CalibrateArgs, preset: &BenchPreset, bench: &VirtualBench, mode: Mode) -> Result<Session, CliError> {
    if find_recovery(&a.out)?.is_some() {
        return Err(CliError::Argument {
            argument: "--out",
            problem: format!(
                "{} holds an unfinished measurement ({AUTOSAVE_FILE}); add --resume to continue it, or choose another folder",
                a.out.display()
            ),
        });
    }
    let info = BenchInfo {
        name: photorobot_core::bench::Bench::name(bench),
        preset: Some(a.bench.clone()),
        description: Some(preset.clone()),
        seed: Some(a.seed.unwrap_or(preset.seed)),
    };
    let mut s = Session::new(info, preset.robot_description()?);
    s.plans = if a.plans.is_empty() {
        plans(mode)
    } else {
        a.plans.iter().map(|p| load_plan(p)).collect::<Result<_, _>>()?
    };
    Ok(s)
}

/// Write the session with its calibration, the identified extrinsics and the report; the
/// report's JSON text is returned for printing.
fn write_session(a: &CalibrateArgs, session: &mut Session, report: &CalibrationReport) -> Result<String, CliError> {
    session.calibration = Some(CalibrationReport { traces: Vec::new(), ..report.clone() });
    session.save(&a.out)?;
    save_ron(&a.out.join("extrinsics.ron"), &report.extrinsics)?;
    let json = json_text(report)?;
    write_atomic(&a.out.join("report.json"), json.as_bytes())?;
    Ok(json)
}

/// A fit that fails or a solver that did not converge is not a calibration, though written.
fn calibration_verdict(a: &CalibrateArgs, report: &CalibrationReport) -> Result<(), CliError> {
    match &report.fit {
        Some(fit) if fit.verdict != Verdict::Fits => {
            Err(CliError::NotACalibration { session: a.out.clone(), problem: fit.summary.clone() })
        }
        _ if !report.converged => Err(CliError::NotACalibration {
            session: a.out.clone(),
            problem: format!("the solver did not converge ({})", report.termination),
        }),
        _ => Ok(()),
    }
}

/// Duration of a trace (s).
fn span_s(t: &Trace) -> f64 {
    match (t.t_s.first(), t.t_s.last()) {
        (Some(a), Some(b)) => b - a,
        _ => 0.0,
    }
}

/// The report as text: the Table II-style table, identifiability, residuals, validation.
pub fn print_report(r: &CalibrationReport, out: &mut dyn Write) -> std::io::Result<()> {
    writeln!(
        out,
        "calibration ({:?} mode) on {}: {} observations, {:.1} min of bench time",
        r.mode,
        r.bench,
        r.observations,
        r.measurement_duration_s / 60.0
    )?;
    for p in &r.plan_durations {
        writeln!(
            out,
            "  plan {:<16} {:>7.1} s = {:>5.2} min of bench time",
            p.name,
            p.duration_s,
            p.duration_s / 60.0
        )?;
    }
    // The termination words already say "converged (...)" or "stopped: ...".
    if r.converged {
        writeln!(out, "solver: {}", r.termination)?;
    } else {
        writeln!(out, "solver: NOT CONVERGED, {}", r.termination)?;
    }
    if let Some(fit) = &r.fit {
        print_fit(fit, out)?;
    }
    writeln!(out, "\n{:<10} {:>14} {:<4} {:>12}  determined", "parameter", "value", "unit", "σ")?;
    for p in &r.parameters {
        let sigma = p.sigma.map_or("-".to_string(), |s| format!("{s:.5}"));
        if p.determined {
            writeln!(out, "{:<10} {:>14.5} {:<4} {:>12}  yes", p.name, p.value, p.unit, sigma)?;
        } else {
            writeln!(
                out,
                "{:<10} {:>14} {:<4} {:>12}  NO: {}",
                p.name,
                format!("({:.3})", p.value),
                p.unit,
                sigma,
                p.reason.as_deref().unwrap_or("not determined by these data")
            )?;
        }
    }
    let id = &r.identifiability;
    writeln!(out, "\nidentifiability: rank {} of {} columns", id.rank, id.parameters.len())?;
    if let Some(c) = id.condition_number {
        writeln!(out, "  condition number {c:.3e}{}", if c > 100.0 { " (above 100)" } else { "" })?;
    }
    if let Some(c) = id.condition_number_determined {
        writeln!(out, "  condition number of the determined parameters {c:.3e}")?;
    }
    for (a, b, rho) in &id.strong_correlations {
        writeln!(out, "  strongly correlated: {a} and {b} (ρ = {rho:+.3})")?;
    }
    for c in &id.unobservable {
        writeln!(out, "  {}", c.description)?;
    }
    writeln!(
        out,
        "  residual RMS {:.2} σ (1 = at the noise floor); uncertainties scaled by {:.2}",
        r.residual_rms_sigma, id.covariance_scale
    )?;
    // Residuals per measurement (RMS over the observations of each trace label).
    let mut per_label: Vec<(String, String, f64, f64, usize)> = Vec::new();
    for (label, unit, res, sigma) in &r.residuals {
        match per_label.iter_mut().find(|p| &p.0 == label && &p.1 == unit) {
            Some(p) => {
                p.2 += res * res;
                p.3 += (res / sigma).powi(2);
                p.4 += 1;
            }
            None => per_label.push((label.clone(), unit.clone(), res * res, (res / sigma).powi(2), 1)),
        }
    }
    writeln!(out, "\nresiduals per measurement (RMS):")?;
    for (label, unit, ss, ss_n, n) in per_label {
        let n = n as f64;
        writeln!(out, "  {:>10.4} {:<3} {:>6.2} σ  {}", (ss / n).sqrt(), unit, (ss_n / n).sqrt(), label)?;
    }
    if r.validation_predicted {
        writeln!(out, "\nvalidation PREDICTED on a virtual bench with the identified extrinsics (no bench was run):")?;
    } else {
        writeln!(out, "\nvalidation (FP cavity variation, peak to peak):")?;
    }
    writeln!(out, "  {:<28} {:>12} {:>12} {:>12}", "motion", "before (nm)", "after (nm)", "paper (nm)")?;
    for v in &r.validation {
        let f = |x: Option<f64>| x.map_or("-".to_string(), |v| format!("{v:.1}"));
        writeln!(
            out,
            "  {:<28} {:>12} {:>12} {:>12.0}{}",
            v.motion,
            f(v.before_nm),
            f(v.after_nm),
            v.paper_nm,
            v.note.as_ref().map_or(String::new(), |n| format!("  ({n})"))
        )?;
    }
    if !r.validation_forecast.is_empty() {
        writeln!(out, "\nvalidation forecast (true gap, peak to peak, 95 % from the extrinsics' uncertainty):")?;
        for f in &r.validation_forecast {
            let word = if f.within_target() { "within" } else { "ABOVE" };
            writeln!(out, "  {:<52} {:>8.1} nm  {word} its {:.0} nm target", f.motion, f.expected_nm, f.target_nm)?;
        }
    }
    print_signs(&r.translation_signs, out)?;
    for w in &r.warnings {
        writeln!(out, "warning: {w}")?;
    }
    Ok(())
}

/// The verdict on the fit: its word, the branches run and, when it fails, the worst traces.
fn print_fit(fit: &FitCheck, out: &mut dyn Write) -> std::io::Result<()> {
    let word = match fit.verdict {
        Verdict::Fits => "FITS",
        Verdict::DoesNotFit => "DOES NOT FIT",
        Verdict::Ambiguous => "AMBIGUOUS",
    };
    writeln!(out, "fit: {word}: {}", fit.summary)?;
    for (k, b) in fit.branches.iter().enumerate() {
        let tag = if k == 0 {
            "chosen"
        } else if fit.tied_branches.contains(&k) {
            "TIED"
        } else {
            "worse"
        };
        writeln!(
            out,
            "  branch from {:<16} χ² {:>12.1}  rms {:>7.2} σ  {:<6} (β_et {:.4}°, θ_et {:.4}°, β_wf {:.4}°, θ_wf {:.4}°)",
            b.start,
            b.chi2,
            b.rms_sigma,
            tag,
            b.extrinsics.beta_et_deg,
            b.extrinsics.theta_et_deg,
            b.extrinsics.beta_wf_deg,
            b.extrinsics.theta_wf_deg
        )?;
    }
    if fit.verdict == Verdict::DoesNotFit {
        writeln!(out, "  worst traces:")?;
        for t in &fit.worst_traces {
            writeln!(out, "    {:>8.2} σ rms over {:>3} observations  {}", t.rms_sigma, t.observations, t.label)?;
        }
    }
    Ok(())
}

/// The sign of each translation and what fixed it.
fn print_signs(signs: &[TranslationSign], out: &mut dyn Write) -> std::io::Result<()> {
    if signs.is_empty() {
        return Ok(());
    }
    writeln!(out, "\nsign of each translation's gap change:")?;
    for s in signs {
        let source = match s.fixed_by {
            Some(SignSource::SweepsBeforeAndAfter) => "sweeps before and after",
            Some(SignSource::FittedModel) => "the model fitted to all the data",
            None => "nothing: too small to sign, or no source",
        };
        let agree = if s.agrees { "" } else { "  DISAGREES with another source" };
        writeln!(out, "  {:>+10.1} nm  fixed by {source:<34}{agree}  {}", s.dl_nm, s.label)?;
    }
    Ok(())
}
