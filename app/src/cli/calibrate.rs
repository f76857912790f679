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

use super::common::{hardware_bench_file, json_text, load_plan, nominal_model, timed, CliError};
use super::progress::{Progress, INTERRUPT};
use crate::hardware_bench::open_hardware_bench;
use photorobot_core::bench::{Bench, BenchPreset, RunControl, RunTiming, StageTime, TimedBench, VirtualBench};
use photorobot_core::calibration::{
    identify, plan_durations, plans, predicted_validation_rows, report_from_identification, report_from_traces,
    validation_rows_as_asked, CalibrationReport, Mode,
};
use photorobot_core::files::{save_ron, write_atomic, FileError};
use photorobot_core::hardware::emulator::EmuClock;
use photorobot_core::hardware::HardwareConfig;
use photorobot_core::identify::signs::{SignSource, TranslationSign};
use photorobot_core::identify::sweep_cost::{self, Evidence, SweepCost};
use photorobot_core::identify::verdict::{BranchSummary, FitCheck, Verdict};
use photorobot_core::model::phase::PhaseModel;
use photorobot_core::plan::Plan;
use photorobot_core::session::{
    self as lab, autosave_path, find_recovery, recording::record_with, BenchInfo, ControllerIdentity, FolderLock,
    LabRecord, Session, SessionWriter, AUTOSAVE_FILE,
};
use photorobot_core::trace::import::{read_folder_with, ColumnMapping, Constants, FolderOptions};
use photorobot_core::trace::Trace;
use photorobot_core::validate::StopSettings;
use std::cell::RefCell;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;

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
    /// --traces, the model of the bench that recorded them (robot, optics, laser). Or a hardware
    /// bench file (a HardwareConfig, e.g. assets/benches/femto-hardware.ron): the plans run on its
    /// stage controllers and laser, modelled by --model.
    #[arg(long, value_name = "PRESET")]
    pub bench: String,
    /// With a hardware bench file: the preset whose robot, optics and motion limits model it.
    #[arg(long, value_name = "PRESET", default_value = "table2-ideal")]
    pub model: String,
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
    /// Column mapping (RON) for traces from another acquisition system (default: our format, or
    /// a lab's export whose column names carry their units).
    #[arg(long, value_name = "FILE", requires = "traces")]
    pub mapping: Option<PathBuf>,
    /// With --traces: the laser's fixed wavelength (nm) for files that have neither a wavelength
    /// column nor a `# wavelength_nm:` line.
    #[arg(long, value_name = "NM", requires = "traces", value_parser = wavelength_nm)]
    pub wavelength_nm: Option<f64>,
    /// Measure these plans instead of the mode's (repeatable, run in order): a plan file (RON) or
    /// an embedded plan (strategy1, strategy2, joint-extras, optimised). Joint mode on
    /// `--plan optimised` runs the experiment design's plan (`photorobot design`).
    #[arg(long = "plan", value_name = "PLAN", conflicts_with_all = ["traces", "resume"])]
    pub plans: Vec<String>,
    /// Leave the plans' wavelength sweeps out, as on a bench without a tunable laser (a bench
    /// without one does so by itself); the report says what that costs.
    #[arg(long, conflicts_with = "traces")]
    pub no_sweeps: bool,
    /// Identify without running the validation motions after it (minutes of bench time on a
    /// real bench; the GUI's Validation view runs them later on the session). The report says
    /// they were not run.
    #[arg(long, conflicts_with = "traces")]
    pub no_validation: bool,
    /// Run each validation motion twice: planned with the nominal (design) extrinsics as well as
    /// with the identified ones, the paper's before-and-after comparison (twice the validation's
    /// bench time; with --traces, twice its prediction's time). Without it only the identified
    /// extrinsics are validated.
    #[arg(long, conflicts_with = "no_validation")]
    pub before: bool,
    /// Continue the measurement autosaved in --out (after a crash) instead of starting anew.
    #[arg(long)]
    pub resume: bool,
    /// Print the report as JSON instead of tables.
    #[arg(long)]
    pub json: bool,
    /// The lab record: who measured, and the ambient conditions read in the lab.
    #[command(flatten)]
    pub lab: LabArgs,
}

/// The lab record's flags (each optional; the start time and the bench's identification are
/// recorded by themselves).
#[derive(Debug, Default, clap::Args)]
pub struct LabArgs {
    /// Who runs the measurement (kept in the session and the report).
    #[arg(long, value_name = "NAME")]
    pub operator: Option<String>,
    /// Ambient air temperature in the lab (°C, -40 to 60).
    #[arg(long, value_name = "CELSIUS", value_parser = temperature_c, allow_negative_numbers = true)]
    pub ambient_temperature_c: Option<f64>,
    /// Ambient air pressure in the lab (hPa, 500 to 1100).
    #[arg(long, value_name = "HPA", value_parser = pressure_hpa)]
    pub pressure_hpa: Option<f64>,
    /// Relative humidity in the lab (%, 0 to 100).
    #[arg(long, value_name = "PERCENT", value_parser = humidity_percent, allow_negative_numbers = true)]
    pub humidity_percent: Option<f64>,
}

/// A number within `range`, or a message clap shows after the flag's name (exit code 2).
fn in_range(text: &str, what: &str, range: &std::ops::RangeInclusive<f64>, unit: &str) -> Result<f64, String> {
    let v: f64 = text.trim().parse().map_err(|_| format!("expected a number ({unit}), found `{text}`"))?;
    lab::check_range(what, v, range, unit)
}

fn temperature_c(text: &str) -> Result<f64, String> {
    in_range(text, "temperature", &lab::TEMPERATURE_RANGE_C, "°C")
}

fn pressure_hpa(text: &str) -> Result<f64, String> {
    in_range(text, "pressure", &lab::PRESSURE_RANGE_HPA, "hPa")
}

fn humidity_percent(text: &str) -> Result<f64, String> {
    in_range(text, "relative humidity", &lab::HUMIDITY_RANGE_PERCENT, "%")
}

fn wavelength_nm(text: &str) -> Result<f64, String> {
    let v: f64 = text.trim().parse().map_err(|_| format!("expected a wavelength in nm, found `{text}`"))?;
    match (200.0..=20_000.0).contains(&v) {
        true => Ok(v),
        false => Err(format!("expected a vacuum wavelength in nm between 200 and 20000, found {v}")),
    }
}

impl LabArgs {
    /// Put the flags given into the session's lab record (a flag not given keeps what is there).
    fn apply(&self, record: &mut LabRecord) {
        if let Some(o) = &self.operator {
            record.operator = Some(o.clone());
        }
        record.ambient_temperature_c = self.ambient_temperature_c.or(record.ambient_temperature_c);
        record.pressure_hpa = self.pressure_hpa.or(record.pressure_hpa);
        record.relative_humidity_percent = self.humidity_percent.or(record.relative_humidity_percent);
    }
}

/// Run the calibration and write the session.
pub fn calibrate(a: &CalibrateArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let hardware = hardware_bench_file(&a.bench)?;
    let preset = BenchPreset::resolve(if hardware.is_some() { &a.model } else { &a.bench })?;
    let nominal = nominal_model(&preset)?;
    let mode = match a.mode {
        ModeArg::Paper => Mode::Paper,
        ModeArg::Joint => Mode::Joint,
    };
    // The folder is ours until the session is written: a second photorobot is refused.
    let _lock = FolderLock::acquire(&a.out)?;
    refuse_saved_session(a)?;
    open_log(a, mode);
    let (mut session, mut report) = match &a.traces {
        Some(dir) => calibrate_from_traces(a, dir, &preset, &nominal, mode)?,
        None => match hardware {
            Some(config) => calibrate_on_hardware(a, config, &preset, &nominal, mode)?,
            None => calibrate_on_virtual_bench(a, &preset, &nominal, mode)?,
        },
    };
    a.lab.apply(&mut session.lab);
    let json = timed("write_session", || write_session(a, session, &mut report))?;
    tracing::info!(session = %a.out.display(), converged = report.converged, "session written");
    if a.json {
        writeln!(out, "{json}")?;
    } else {
        print_report(&report, out)?;
        writeln!(out, "\nsession written to {}", a.out.display())?;
    }
    calibration_verdict(a, &report)
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
    let options = FolderOptions { mapping: mapping.as_ref(), constants: Constants { wavelength_nm: a.wavelength_nm } };
    let sourced = timed("read_traces", || read_folder_with(dir, &options))?;
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
    let duration_s = sourced.traces.iter().map(span_s).sum();
    let name = session.bench.name.clone();
    // The copy into the session mostly waits for the disk: it runs beside the identification
    // and the validation, which is predicted for the extrinsics the report gives (the
    // estimate's, angles wrapped).
    let (copied, identified) = std::thread::scope(|scope| {
        let copy = scope.spawn(|| timed("copy_traces", || session.add_sourced_traces(&a.out, &sourced)));
        let identified = timed("identify", || identify(&sourced.traces, nominal, mode)).and_then(|id| {
            let extrinsics = id.estimate.extrinsics.with_angles_wrapped();
            let validation = timed("validate", || predicted_validation_rows(preset, nominal, &extrinsics, a.before))?;
            Ok((id, validation))
        });
        (copy.join().unwrap_or_else(|panic| std::panic::resume_unwind(panic)), identified)
    });
    copied?;
    let (id, validation) = identified.map_err(calibration_failed)?;
    let mut report =
        timed("report", || report_from_identification(&id, sourced.traces, duration_s, name, nominal, mode));
    debug_assert_eq!(report.extrinsics, id.estimate.extrinsics.with_angles_wrapped());
    report.validation = validation;
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
    let seed = Some(a.seed.unwrap_or(preset.seed));
    measure_identify_validate(a, preset, nominal, mode, &mut bench, (seed, &[]))
}

/// Measure the plans on the stage controllers and the laser of `config` (the same bench the
/// Connection view opens), identify, and run the validation motions on them.
fn calibrate_on_hardware(
    a: &CalibrateArgs,
    config: HardwareConfig,
    preset: &BenchPreset,
    nominal: &PhaseModel,
    mode: Mode,
) -> Result<(Session, CalibrationReport), CliError> {
    let robot = preset.robot_description()?;
    let laser_name = config.laser.as_ref().map_or(String::new(), |l| format!("{:?} laser", l.family));
    // Real hardware runs in real time; emulators may run faster (the file's `time_scale`).
    let clock = EmuClock::new(config.time_scale);
    let (mut bench, laser) = open_hardware_bench(preset, robot, config, clock)
        .map_err(|problem| CliError::Failed { what: "the hardware bench", problem })?;
    match &laser {
        Some(l) => tracing::info!(laser = %l.idn, wavelength_nm = l.wavelength_nm, "laser connected"),
        None => tracing::warn!("no tunable laser: the plans run without their wavelength sweeps"),
    }
    // The lab record names the laser beside the controllers.
    let extra: Vec<(String, String)> = laser.map(|l| (laser_name, l.idn)).into_iter().collect();
    measure_identify_validate(a, preset, nominal, mode, &mut bench, (None, &extra))
}

/// Measure the session's plans on `bench` (each trace saved as it is recorded, the session
/// autosaved after it), identify, and run the validation motions on the same bench. Every
/// segment's timing and every stage's wall time go into the report.
fn measure_identify_validate(
    a: &CalibrateArgs,
    preset: &BenchPreset,
    nominal: &PhaseModel,
    mode: Mode,
    bench: &mut dyn Bench,
    identity: (Option<u64>, &[(String, String)]),
) -> Result<(Session, CalibrationReport), CliError> {
    let session = if a.resume { recover(&a.out)? } else { new_session(a, preset, &*bench, mode, identity)? };
    // Each plan's bench time from the timing model, every plan from the start (q = 0).
    let durations = plan_durations(&session.plans, &session.robot, &preset.motion, [0.0; 6])
        .map_err(|problem| plan_error(a, problem))?;
    let progress =
        RefCell::new(Progress::new(session.plans.iter().map(|p| (p.name.clone(), p.segments.len())).collect()));
    let mut on_progress = |done: f64| progress.borrow_mut().fraction(done);
    let mut control = RunControl { cancel: &INTERRUPT, on_samples: &mut |_, _| {}, on_progress: &mut on_progress };
    let mut writer = SessionWriter::new(&a.out, session).keeping_traces();
    let mut stages = Vec::new();
    let mut bench = TimedBench::new(bench, "measure");
    let recorded = stage(&mut stages, "measure", || {
        record_with(&mut bench, &mut writer, &mut control, &mut |p, s| progress.borrow_mut().segment(p, s))
    })?;
    if let Err(e) = recorded.outcome {
        progress.borrow_mut().finish();
        if INTERRUPT.load(Ordering::SeqCst) {
            tracing::warn!("measurement interrupted: {e}");
            return Err(CliError::Interrupted { session: a.out.clone(), resume: resume_command(a) });
        }
        return Err(e.into());
    }
    tracing::info!(bench_time_s = recorded.duration_s, "measurement done");
    progress.borrow_mut().stage("identifying");
    // The traces this run recorded stay in memory; those of an interrupted run are read back.
    let traces = stage(&mut stages, "read_traces", || writer.take_traces())?;
    let session = writer.into_session();
    let name = session.bench.name.clone();
    let mut report =
        stage(&mut stages, "identify", || report_from_traces(traces, recorded.duration_s, name, nominal, mode))
            .map_err(calibration_failed)?;
    tracing::info!(
        converged = report.converged,
        residual_rms_sigma = report.residual_rms_sigma,
        "identification: {}",
        report.termination
    );
    report.plan_durations = durations;
    if session.plans.iter().all(|p| p.sweeps() == 0) && skips_sweeps(a, &bench) {
        progress.borrow_mut().stage("assessing what the missing sweeps cost");
        let cost = sweep_cost(a, preset, mode, &session, &report)?;
        for s in cost.sentences() {
            tracing::warn!("no sweeps: {s}");
        }
        report.sweep_cost = Some(cost);
    }
    if a.no_validation {
        report.validation_not_run = true;
        tracing::info!("validation not run (--no-validation)");
    } else {
        progress.borrow_mut().stage("validating");
        let stops = StopSettings { sweeps: !a.no_sweeps, ..StopSettings::default() };
        bench.set_stage("validate");
        report.validation = stage(&mut stages, "validate", || {
            validation_rows_as_asked(&mut bench, nominal, &report.extrinsics, &stops, a.before)
        });
        tracing::info!(motions = report.validation.len(), "validation done");
    }
    progress.borrow_mut().finish();
    report.timing = Some(RunTiming { stages, ..bench.finish() });
    Ok((session, report))
}

/// Run one stage with [`timed`], keeping its wall time in `stages`.
fn stage<T>(stages: &mut Vec<StageTime>, name: &str, f: impl FnOnce() -> T) -> T {
    let t0 = std::time::Instant::now();
    let out = timed(name, f);
    stages.push(StageTime { stage: name.to_string(), wall_s: t0.elapsed().as_secs_f64() });
    out
}

/// The session autosaved in `dir`, refused when a plan other than the one it resumes was
/// measured in part by the workbench (it would be measured again from its start).
fn recover(dir: &Path) -> Result<Session, CliError> {
    if !autosave_path(dir).exists() {
        let problem = if photorobot_core::session::session_path(dir).exists() {
            format!("{} holds a finished session (session.ron) and nothing to resume", dir.display())
        } else {
            format!(
                "{} holds no measurement to resume (no {AUTOSAVE_FILE}: nothing was measured); run the command \
                 without --resume",
                dir.display()
            )
        };
        return Err(CliError::Argument { argument: "--resume", problem });
    }
    let session = Session::recover(dir)?;
    if let Some((p, whole, recorded)) = session.partly_measured_besides_progress() {
        let problem = format!(
            "plan {} ({}) has whole traces for {whole} of its {recorded} recorded segments and no resume point \
             here: --resume would measure it again from its start; resume or redo that step in the workbench",
            p + 1,
            session.plans[p].name
        );
        return Err(FileError::Invalid { file: autosave_path(dir), field: "traces".into(), problem }.into());
    }
    Ok(session)
}

/// Plans that cannot run on the bench: `--plan`'s when given, else the mode's or the resumed
/// session's, which no argument names.
fn plan_error(a: &CalibrateArgs, problem: String) -> CliError {
    match (a.plans.is_empty(), a.resume) {
        (false, _) => CliError::Argument { argument: "--plan", problem },
        (true, true) => CliError::Failed { what: "the resumed session's plans", problem },
        (true, false) => CliError::Failed { what: "the mode's plans", problem },
    }
}

/// Log into the session folder from now on (`photorobot.log`), starting with what runs.
fn open_log(a: &CalibrateArgs, mode: Mode) {
    match crate::log::open_session_log(&a.out) {
        Ok(path) => tracing::debug!(log = %path.display(), "session log opened"),
        Err(e) => tracing::warn!("cannot write the log {}: {e}", a.out.join(crate::log::LOG_FILE).display()),
    }
    tracing::info!(
        bench = %a.bench, seed = ?a.seed, mode = ?mode, resume = a.resume, traces = ?a.traces,
        "calibrate into {}", a.out.display()
    );
}

/// The command line that continues this run from its autosave: the same bench, seed and mode,
/// with `--resume` (the plans are in the autosave).
pub fn resume_command(a: &CalibrateArgs) -> String {
    let mode = match a.mode {
        ModeArg::Paper => "paper",
        ModeArg::Joint => "joint",
    };
    let mut cmd = format!("photorobot calibrate --bench {} --mode {mode}", shell_quote(&a.bench));
    if let Some(seed) = a.seed {
        cmd += &format!(" --seed {seed}");
    }
    if a.model != "table2-ideal" {
        cmd += &format!(" --model {}", shell_quote(&a.model));
    }
    if a.no_sweeps {
        cmd += " --no-sweeps";
    }
    if a.no_validation {
        cmd += " --no-validation";
    }
    if a.before {
        cmd += " --before";
    }
    cmd += &format!(" --out {} --resume", shell_quote(&a.out.display().to_string()));
    if a.json {
        cmd += " --json";
    }
    cmd
}

/// A word as a POSIX shell reads it back: quoted when it holds anything but safe characters.
fn shell_quote(word: &str) -> String {
    let safe = |c: char| c.is_ascii_alphanumeric() || "-_./=:,+@%".contains(c);
    if !word.is_empty() && word.chars().all(safe) {
        word.to_string()
    } else {
        format!("'{}'", word.replace('\'', "'\\''"))
    }
}

/// A new session on the bench with the plans to measure (the mode's or `--plan`'s); refused when
/// `--out` holds an unfinished measurement that `--resume` should continue.
fn new_session(
    a: &CalibrateArgs,
    preset: &BenchPreset,
    bench: &dyn Bench,
    mode: Mode,
    (seed, extra): (Option<u64>, &[(String, String)]),
) -> Result<Session, CliError> {
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
        seed,
    };
    let mut s = Session::new(info, preset.robot_description()?);
    // Recording starts now: the lab record gets the time, the flags and the bench's identification.
    s.lab.stamp_start();
    a.lab.apply(&mut s.lab);
    s.lab.controllers = photorobot_core::bench::Bench::identification(bench)
        .into_iter()
        .chain(extra.iter().cloned())
        .map(|(name, identification)| ControllerIdentity { name, identification })
        .collect();
    s.plans = requested_plans(a, mode)?;
    if skips_sweeps(a, bench) {
        s.plans = s.plans.iter().map(Plan::without_sweeps).collect();
    }
    Ok(s)
}

/// The plans `--plan` names, or the mode's.
fn requested_plans(a: &CalibrateArgs, mode: Mode) -> Result<Vec<Plan>, CliError> {
    if a.plans.is_empty() {
        Ok(plans(mode))
    } else {
        a.plans.iter().map(|p| load_plan(p)).collect()
    }
}

/// The sweeps are left out: asked for, or the bench has no tunable laser.
fn skips_sweeps(a: &CalibrateArgs, bench: &dyn Bench) -> bool {
    a.no_sweeps || !bench.tunable_laser()
}

/// What leaving the sweeps out cost this measurement: its analysis against a pilot run of the
/// plans with their sweeps (those requested; on --resume the mode's when the session measured
/// them, else the session's own).
fn sweep_cost(
    a: &CalibrateArgs,
    preset: &BenchPreset,
    mode: Mode,
    session: &Session,
    report: &CalibrationReport,
) -> Result<SweepCost, CliError> {
    let mut with = if a.resume { plans(mode) } else { requested_plans(a, mode)? };
    let names = |p: &[Plan]| p.iter().map(|p| p.name.clone()).collect::<Vec<_>>();
    if names(&with) != names(&session.plans) {
        with = session.plans.clone();
    }
    let measured = Evidence { identifiability: &report.identifiability, signs: &report.translation_signs };
    sweep_cost::measured(preset, &with, measured, report.fit.as_ref()).map_err(calibration_failed)
}

/// Write the identified extrinsics, the report and, last, the session with its calibration
/// (which removes the autosave and the trace files of segments a crash left unreferenced); the
/// report's JSON text is returned for printing. Until `session.ron` is written the autosave
/// stays, so a run killed in here is resumed like any other.
fn write_session(a: &CalibrateArgs, mut session: Session, report: &mut CalibrationReport) -> Result<String, CliError> {
    // Extrinsics beyond ±90° feed no inverse model: kept in the session's record only.
    if report.extrinsics.validate().is_ok() {
        save_ron(&a.out.join("extrinsics.ron"), &report.extrinsics)?;
    }
    let json = json_text(report)?;
    write_atomic(&a.out.join("report.json"), json.as_bytes())?;
    // The session keeps the report without its traces (they are its trace files): set aside
    // while the rest is copied, rather than copied and dropped.
    let traces = std::mem::take(&mut report.traces);
    session.calibration = Some(report.clone());
    report.traces = traces;
    SessionWriter::new(&a.out, session).save()?;
    Ok(json)
}

/// A fit that fails, a solver that did not converge, data that determine no parameter, or a
/// validation run on the bench that does not confirm every motion within its target is not a
/// calibration, though written.
fn calibration_verdict(a: &CalibrateArgs, report: &CalibrationReport) -> Result<(), CliError> {
    let refused = |problem: String| Err(CliError::NotACalibration { session: a.out.clone(), problem });
    if let Some(fit) = report.fit.as_ref().filter(|fit| fit.verdict != Verdict::Fits) {
        return refused(fit.summary.clone());
    }
    // Sweeps measured but not analysed leave the calibration without what they determine.
    if let Some(cost) = report.sweep_cost.as_ref().filter(|c| !c.lost.is_empty() && !c.is_free()) {
        return refused(format!("the calibration is incomplete: {}", cost.sentences().join("; ")));
    }
    if report.parameters.iter().all(|p| !p.determined) {
        return refused("these data determine none of the parameters (the table says why for each)".into());
    }
    if let Err(e) = report.extrinsics.validate() {
        return refused(format!("the fit ended outside the extrinsics' range: {e}"));
    }
    if !report.converged {
        return refused(format!("the solver did not converge ({})", report.termination));
    }
    let failures = report.validation_failures();
    if !failures.is_empty() {
        return refused(format!("its validation does not prove it: {}", failures.join("; ")));
    }
    Ok(())
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
    print_parameters(r, out)?;
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
    print_validation(r, out)?;
    if !r.validation_forecast.is_empty() {
        writeln!(out, "\nvalidation forecast (true gap, peak to peak, 95 % from the extrinsics' uncertainty):")?;
        for f in &r.validation_forecast {
            let word = if f.within_target() { "within" } else { "ABOVE" };
            writeln!(out, "  {:<52} {:>8.1} nm  {word} its {:.0} nm target", f.motion, f.expected_nm, f.target_nm)?;
        }
    }
    print_signs(&r.translation_signs, out)?;
    if let Some(t) = &r.timing {
        print_timing(t, out)?;
    }
    if let Some(cost) = &r.sweep_cost {
        if cost.lost.is_empty() {
            writeln!(out, "\nno wavelength sweeps (no tunable laser, or --no-sweeps): what that costs")?;
        } else {
            writeln!(out, "\nsweeps lost (measured, their analysis refused): what that costs")?;
        }
        for s in cost.sentences() {
            writeln!(out, "  {s}")?;
        }
    }
    for w in &r.warnings {
        writeln!(out, "warning: {w}")?;
    }
    Ok(())
}

/// The Table II-style table: each parameter's value with its total σ and the two parts of it,
/// noise and systematic (what noise cannot explain), or why it is not determined; then the
/// families of observations that disagree with the others.
fn print_parameters(r: &CalibrationReport, out: &mut dyn Write) -> std::io::Result<()> {
    writeln!(
        out,
        "\n{:<10} {:>14} {:<4} {:>12} {:>12} {:>12}  determined",
        "parameter", "value", "unit", "σ noise", "σ systematic", "σ total"
    )?;
    let f = |s: Option<f64>| s.map_or("-".to_string(), |s| format!("{s:.5}"));
    for p in &r.parameters {
        let sigmas = format!("{:>12} {:>12} {:>12}", f(p.sigma_noise.or(p.sigma)), f(p.sigma_systematic), f(p.sigma));
        if p.determined {
            writeln!(out, "{:<10} {:>14.5} {:<4} {sigmas}  yes", p.name, p.value, p.unit)?;
        } else {
            let why = p.reason.as_deref().unwrap_or("not determined by these data");
            writeln!(out, "{:<10} {:>14} {:<4} {sigmas}  NO: {why}", p.name, format!("({:.3})", p.value), p.unit)?;
        }
    }
    for family in r.model_discrepancy.iter().flat_map(|d| &d.families) {
        let test = if family.disagrees { "DISAGREES with the others" } else { "agrees with the others" };
        writeln!(
            out,
            "  {:<18} {:>4} observations, Birge ratio {:.2}, scatter beyond noise {:.3} {}; left out: χ² {:.1} for {} ({test})",
            family.family.words(),
            family.observations,
            family.birge_ratio,
            family.excess_sigma,
            family.unit,
            family.shift_chi2,
            family.shift_dof
        )?;
    }
    Ok(())
}

/// The validation rows, or why there are none: before and after (the figures the proofs stand
/// behind), after as tracked with the identified extrinsics alone and model-free, the count's
/// bounds and the verdict.
fn print_validation(r: &CalibrationReport, out: &mut dyn Write) -> std::io::Result<()> {
    if r.validation_not_run {
        return writeln!(out, "\nvalidation NOT RUN (--no-validation): run its motions in the GUI's Validation view");
    }
    if r.validation_predicted {
        writeln!(out, "\nvalidation PREDICTED on a virtual bench with the identified extrinsics (no bench was run):")?;
    } else {
        writeln!(out, "\nvalidation (FP cavity variation: |L| along the beam, peak to peak; each figure the one its verdict stands behind):")?;
        if r.validation.iter().all(|v| v.before_nm.is_none() && v.before_curve_nm.is_empty()) {
            writeln!(out, "  (before: not run; --before also runs each motion planned with the nominal extrinsics)")?;
        }
    }
    writeln!(
        out,
        "  {:<52} {:>10} {:>10} {:>10} {:>11} {:>12} {:<13} {:>6}",
        "motion", "before nm", "after nm", "tracked", "model-free", "count ≥", "verdict", "paper"
    )?;
    for v in &r.validation {
        let f = |x: Option<f64>| x.map_or("-".to_string(), |v| format!("{v:.1}"));
        let e = v.after_evidence.as_ref();
        writeln!(
            out,
            "  {:<52} {:>10} {:>10} {:>10} {:>11} {:>12} {:<13} {:>6.0}{}",
            v.motion,
            f(v.before_nm),
            f(v.after_nm),
            f(e.map(|e| e.tracked_nm)),
            e.and_then(|e| e.model_free_words()).unwrap_or("-".into()),
            f(e.and_then(|e| e.bounds).map(|b| b.lower_nm)),
            e.map_or("-", |e| e.verdict.word()),
            v.paper_nm,
            v.note.as_ref().map_or(String::new(), |n| format!("  ({n})"))
        )?;
    }
    for failure in r.validation_failures() {
        writeln!(out, "  NOT PROVEN: {failure}")?;
    }
    Ok(())
}

/// Where the time went: each stage's wall time, then each plan run's and each stage's bench time
/// against the plans' timing model, the controllers' waiting and the recorder's reading.
fn print_timing(t: &RunTiming, out: &mut dyn Write) -> std::io::Result<()> {
    writeln!(out, "\ntime (s):")?;
    for s in &t.stages {
        writeln!(out, "  {:<14} {:>8.2} wall", s.stage, s.wall_s)?;
    }
    writeln!(
        out,
        "  {:<62} {:>5} {:>8} {:>8} {:>8} {:>8} {:>8}",
        "bench time", "segs", "planned", "bench", "waiting", "recorder", "wall"
    )?;
    let runs = t.runs();
    let rows = runs.iter().map(|(stage, r)| (format!("{stage}: {}", r.name), r));
    let totals = t.stage_totals();
    for (name, r) in rows.chain(totals.iter().map(|r| (format!("total {}", r.name), r))) {
        writeln!(
            out,
            "  {:<62} {:>5} {:>8.2} {:>8.2} {:>8.2} {:>8.2} {:>8.2}",
            name, r.segments, r.planned_s, r.bench_s, r.waiting_s, r.recorder_after_s, r.wall_s
        )?;
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
        writeln!(
            out,
            "  branch from {:<16} χ² {:>12.1}  rms {:>7.2} σ  {:<11} (β_et {:.4}°, θ_et {:.4}°, β_wf {:.4}°, θ_wf {:.4}°){}",
            b.start,
            b.chi2,
            b.rms_sigma,
            fit.standing(k).word(),
            b.extrinsics.beta_et_deg,
            b.extrinsics.theta_et_deg,
            b.extrinsics.beta_wf_deg,
            b.extrinsics.theta_wf_deg,
            charges(b)
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

/// What a branch is charged beside its χ² and the cost it is ranked by, when it is charged: a
/// branch listed after the chosen one may show the lower χ².
fn charges(b: &BranchSummary) -> String {
    if b.skipped_traces == 0 && b.hint_led_traces == 0 {
        return String::new();
    }
    format!(
        "  cost {:.1}: {} traces skipped, {} motions led by its hint",
        b.cost(),
        b.skipped_traces,
        b.hint_led_traces
    )
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

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    fn args(line: &[&str]) -> CalibrateArgs {
        match crate::cli::Cli::parse_from(line).command {
            Some(crate::cli::Command::Calibrate(a)) => a,
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn plans_that_cannot_run_blame_the_argument_only_when_one_gave_them() {
        let limits = "segment 3 leaves the limits of q1".to_string();
        let given = args(&["photorobot", "calibrate", "--bench", "b", "--out", "o", "--plan", "p.ron"]);
        assert_eq!(plan_error(&given, limits.clone()).to_string(), format!("argument --plan: {limits}"));
        let default = args(&["photorobot", "calibrate", "--bench", "b", "--out", "o"]);
        let e = plan_error(&default, limits.clone());
        assert_eq!(e.to_string(), format!("the mode's plans failed: {limits}"));
        assert_eq!(e.exit_code(), 1, "not a wrong command line");
        let resumed = args(&["photorobot", "calibrate", "--bench", "b", "--out", "o", "--resume"]);
        assert!(!plan_error(&resumed, limits).to_string().contains("--"), "no argument to blame");
    }

    #[test]
    fn before_runs_only_when_the_validation_does_and_is_resumed_with_it() {
        let a = args(&["photorobot", "calibrate", "--bench", "b", "--out", "o", "--before"]);
        assert!(a.before);
        assert_eq!(resume_command(&a), "photorobot calibrate --bench b --mode joint --before --out o --resume");
        assert!(!args(&["photorobot", "calibrate", "--bench", "b", "--out", "o"]).before, "after only by default");
        let line = ["photorobot", "calibrate", "--bench", "b", "--out", "o", "--before", "--no-validation"];
        let e = crate::cli::Cli::try_parse_from(line).unwrap_err();
        assert!(e.to_string().contains("--before"), "{e}");
        let traces = args(&["photorobot", "calibrate", "--bench", "b", "--traces", "t", "--out", "o", "--before"]);
        assert!(traces.before, "the prediction for traces takes --before too");
    }

    #[test]
    fn the_resume_command_repeats_bench_mode_seed_and_folder_quoted_for_the_shell() {
        let a = args(&[
            "photorobot",
            "calibrate",
            "--bench",
            "femto-lab",
            "--seed",
            "3",
            "--mode",
            "paper",
            "--out",
            "my run/s",
        ]);
        assert_eq!(
            resume_command(&a),
            "photorobot calibrate --bench femto-lab --mode paper --seed 3 --out 'my run/s' --resume"
        );
        let a = args(&["photorobot", "calibrate", "--bench", "it's.ron", "--out", "s", "--json"]);
        assert_eq!(
            resume_command(&a),
            "photorobot calibrate --bench 'it'\\''s.ron' --mode joint --out s --resume --json"
        );
    }

    /// A branch charged for the motions its hint led is listed after the chosen one with its
    /// lower χ² and the cost that ranks it; an uncharged branch prints no cost.
    #[test]
    fn a_charged_branch_prints_the_cost_that_ranks_it() {
        use photorobot_core::model::extrinsics::Extrinsics;
        let branch = |start: &str, chi2: f64, hint_led_traces: usize, beta: f64| BranchSummary {
            start: start.into(),
            extrinsics: Extrinsics { beta_et_deg: beta, ..Extrinsics::nominal_design() },
            chi2,
            rms_sigma: 1.0,
            skipped_traces: 0,
            hint_led_traces,
        };
        let fit = FitCheck {
            verdict: Verdict::Fits,
            rms_sigma: 1.0,
            threshold_sigma: 3.0,
            worst_traces: vec![],
            branches: vec![branch("fringe travel 2", 279.0, 0, 0.7), branch("absolute gaps", 93.0, 9, 3.7)],
            tied_branches: vec![],
            ambiguous_parameters: vec![],
            summary: "fits".into(),
        };
        let mut out = Vec::new();
        print_fit(&fit, &mut out).unwrap();
        let out = String::from_utf8(out).unwrap();
        let lines: Vec<&str> = out.lines().filter(|l| l.contains("branch from")).collect();
        assert!(!lines[0].contains("cost"), "{out}");
        assert!(lines[1].contains("worse") && lines[1].contains("χ²         93.0"), "{out}");
        assert!(lines[1].contains("cost 993.0: 0 traces skipped, 9 motions led by its hint"), "{out}");
    }
}
