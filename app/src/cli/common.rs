//! What every command shares: the error type and its exit codes, the JSON document form and the
//! loaders of the files several commands take (extrinsics, plans).

use photorobot_core::bench::{BenchError, BenchPreset, RunError};
use photorobot_core::files::FileError;
use photorobot_core::hardware::HardwareConfig;
use photorobot_core::measure::MeasureError;
use photorobot_core::model::extrinsics::Extrinsics;
use photorobot_core::model::kinematics::LimitViolation;
use photorobot_core::model::phase::PhaseModel;
use photorobot_core::plan::Plan;
use photorobot_core::trace::TraceError;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// Why a command failed. Every message names the file, field or argument and what was expected.
#[derive(Debug, Error)]
pub enum CliError {
    /// Bad command line (clap prints it, with usage).
    #[error("{0}")]
    Usage(#[from] clap::Error),
    /// A data file could not be used.
    #[error(transparent)]
    File(#[from] FileError),
    /// An argument has the wrong form.
    #[error("argument {argument}: {problem}")]
    Argument {
        /// The argument, e.g. `--q`.
        argument: &'static str,
        /// What is wrong and what was expected.
        problem: String,
    },
    /// A joint value is outside its limits.
    #[error("argument --q: {0}")]
    Limits(#[from] LimitViolation),
    /// A bench could not be built or failed.
    #[error(transparent)]
    Bench(#[from] BenchError),
    /// A plan failed.
    #[error(transparent)]
    Run(#[from] RunError),
    /// A trace file could not be read or written.
    #[error(transparent)]
    Trace(#[from] TraceError),
    /// A session could not be read or written.
    #[error(transparent)]
    Session(#[from] photorobot_core::session::SessionError),
    /// A trace could not be analysed.
    #[error(transparent)]
    Measure(#[from] MeasureError),
    /// Output could not be written.
    #[error("cannot write output: {0}")]
    Output(#[from] std::io::Error),
    /// The work itself failed (a calibration, design or diagnosis that could not be computed).
    #[error("{what} failed: {problem}")]
    Failed {
        /// What failed, e.g. "calibration".
        what: &'static str,
        /// Why.
        problem: String,
    },
    /// Ctrl-C stopped the run at a segment; everything measured is saved in the session's
    /// autosave and `resume` continues it.
    #[error("interrupted: the measurement so far is saved in {}; to continue it:\n  {resume}", session.display())]
    Interrupted {
        /// The session folder.
        session: std::path::PathBuf,
        /// The command line that continues the run.
        resume: String,
    },
    /// The run finished and its session was written, but it is not a calibration (the model does
    /// not fit the data, branches tie, the solver did not converge, or the data determine no
    /// parameter).
    #[error("not a calibration: {problem} (session written to {})", session.display())]
    NotACalibration {
        /// Where the session was written.
        session: std::path::PathBuf,
        /// What is wrong.
        problem: String,
    },
}

/// The version of every command's JSON output, in its `schema` field: raised when a field is
/// renamed, removed or changes meaning (new fields do not raise it).
pub const JSON_SCHEMA: u32 = 1;

/// A command's JSON document as printed, with `schema` ([`JSON_SCHEMA`]) added.
pub fn json_text<T: serde::Serialize>(doc: &T) -> std::io::Result<String> {
    let mut doc = serde_json::to_value(doc).map_err(std::io::Error::other)?;
    if let Some(map) = doc.as_object_mut() {
        map.insert("schema".into(), JSON_SCHEMA.into());
    }
    serde_json::to_string_pretty(&doc).map_err(std::io::Error::other)
}

impl CliError {
    /// The process exit code: 1 for a run that failed or finished without a result (not a
    /// calibration, a bench or plan that failed, a trace that could not be analysed, output that
    /// could not be written), 2 for a command line that is wrong, 3 for a file that cannot be
    /// used (a plan, preset, trace or session that is missing or malformed, a bench preset that
    /// cannot be built), 130 for a run stopped by Ctrl-C (its session saved).
    pub fn exit_code(&self) -> u8 {
        match self {
            CliError::Interrupted { .. } => super::progress::INTERRUPTED_EXIT_CODE,
            CliError::Bench(BenchError::Config(_)) => 3,
            CliError::NotACalibration { .. }
            | CliError::Failed { .. }
            | CliError::Bench(_)
            | CliError::Run(_)
            | CliError::Measure(_)
            | CliError::Output(_) => 1,
            CliError::Usage(_) | CliError::Argument { .. } | CliError::Limits(_) => 2,
            CliError::File(_) | CliError::Trace(_) | CliError::Session(_) => 3,
        }
    }
}

/// The extrinsics file given, or the paper's Table II when none is.
pub fn load_extrinsics(path: &Option<PathBuf>) -> Result<Extrinsics, CliError> {
    Ok(match path {
        Some(p) => Extrinsics::load(p)?,
        None => Extrinsics::table2(),
    })
}

/// A plan file, or an embedded plan by name: strategy1, strategy2, joint-extras, optimised.
pub fn load_plan(name_or_path: &str) -> Result<Plan, CliError> {
    Ok(match name_or_path {
        "strategy1" => Plan::from_ron_str(
            photorobot_core::plan::STRATEGY1_RON,
            std::path::Path::new("assets/plans/strategy1.ron"),
        )?,
        "strategy2" => Plan::from_ron_str(
            photorobot_core::plan::STRATEGY2_RON,
            std::path::Path::new("assets/plans/strategy2.ron"),
        )?,
        "joint-extras" => Plan::joint_extras(),
        "optimised" => Plan::optimised(),
        path => Plan::load(std::path::Path::new(path))?,
    })
}

/// The software's model: the bench's robot description and optics, the design extrinsics.
pub fn nominal_model(preset: &BenchPreset) -> Result<PhaseModel, CliError> {
    PhaseModel::new(
        preset.robot_description()?,
        Extrinsics::nominal_design(),
        preset.optics,
        &preset.ambient,
        preset.laser.wavelength_nm,
    )
    .map_err(|problem| CliError::Argument { argument: "--bench", problem })
}

/// `--bench` as a hardware bench file, when it is one (a file that parses as a HardwareConfig, or
/// names `controllers:` and is then reported as a broken one); `None` for a preset.
pub fn hardware_bench_file(bench: &str) -> Result<Option<HardwareConfig>, CliError> {
    let path = Path::new(bench);
    if !path.is_file() {
        return Ok(None);
    }
    let text = photorobot_core::files::read_text(path)?;
    match HardwareConfig::from_ron_str(&text, path) {
        Ok(config) => Ok(Some(config)),
        Err(e) if text.contains("controllers:") => Err(e.into()),
        Err(_) => Ok(None),
    }
}

/// Run one stage of a command, logging its wall time at info level (`-v` on stderr, and the
/// session log): `stage done stage=<name> elapsed_s=<seconds>`.
pub fn timed<T>(stage: &str, f: impl FnOnce() -> T) -> T {
    let t0 = std::time::Instant::now();
    let out = f();
    tracing::info!(stage = %stage, elapsed_s = t0.elapsed().as_secs_f64(), "stage done");
    out
}
