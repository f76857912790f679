//! The session folder as `photorobot diagnose` reads and extends it: the traces `session.ron`
//! references (or a folder of bare traces), traces recorded later added to it (`--add`), what the
//! calibration said, and the plan files of proposed motions. Owns no science.

use super::common::CliError;
use photorobot_core::files::FileError;
use photorobot_core::identify::verdict::Verdict as FitVerdict;
use photorobot_core::session::{session_path, Session, LATER_PAUSE_S, TRACES_DIR};
use photorobot_core::trace::import::read_folder_sourced;
use photorobot_core::trace::Trace;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Where `--bench none` writes the discriminating motions it proposes, in the session folder
/// (a later pass that proposes more writes `discriminating-motions-2.ron`, and so on).
pub const PROPOSED_PLAN_FILE: &str = "discriminating-motions.ron";

/// Traces added to the session by `--add`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AddedTraces {
    /// The folder they came from.
    pub from: PathBuf,
    /// How many.
    pub traces: usize,
    /// How far their times moved to continue the session's clock (s; 0 when they did).
    pub clock_shift_s: f64,
}

/// The traces to diagnose and what the session says about them.
pub struct SessionTraces {
    /// The traces, in the session's order (complete ones), or the folder's file-name order.
    pub traces: Vec<Trace>,
    /// The session file, when the folder has one.
    pub session: Option<Session>,
    /// Traces added by `--add`, per folder.
    pub added: Vec<AddedTraces>,
    /// What the user should know before trusting the diagnosis.
    pub warnings: Vec<String>,
}

fn invalid(file: &Path, field: &str, problem: String) -> CliError {
    CliError::File(FileError::Invalid { file: file.to_path_buf(), field: field.into(), problem })
}

/// The session's traces: those `session.ron` references, after the traces of the `add` folders
/// joined them; without a `session.ron`, every trace of `traces/` (a folder of bare traces).
pub fn read(session_dir: &Path, add: &[PathBuf]) -> Result<SessionTraces, CliError> {
    if !session_path(session_dir).exists() {
        if let Some(first) = add.first() {
            return Err(CliError::Argument {
                argument: "--add",
                problem: format!(
                    "{} has no session.ron to add {} to: --add extends a session written by `photorobot calibrate --out`",
                    session_dir.display(),
                    first.display()
                ),
            });
        }
        return bare_folder(session_dir);
    }
    let mut session = Session::load(session_dir)?;
    let mut traces = session.load_traces(session_dir)?;
    let mut added = Vec::new();
    for dir in add {
        let later = read_folder_sourced(dir, None)?;
        let count = later.traces.len();
        let end_s = traces.iter().filter_map(|t| t.t_s.last().copied()).fold(0.0, f64::max);
        let clock_shift_s = session.add_later_traces(session_dir, later, end_s, LATER_PAUSE_S)?;
        // Saved at once: the files are written and referenced, and a later save keeps them.
        session.save(session_dir)?;
        traces = session.load_traces(session_dir)?;
        added.push(AddedTraces { from: dir.clone(), traces: count, clock_shift_s });
    }
    let mut warnings = calibration_warnings(&session);
    let unreferenced = unreferenced_files(session_dir, &session);
    if !unreferenced.is_empty() {
        warnings.push(format!(
            "{} file(s) in {} that session.ron does not reference are not used ({}): add recorded traces \
             with `photorobot diagnose {} --add FOLDER`",
            unreferenced.len(),
            session_dir.join(TRACES_DIR).display(),
            unreferenced.join(", "),
            session_dir.display()
        ));
    }
    Ok(SessionTraces { traces, session: Some(session), added, warnings })
}

/// A folder with `traces/*.csv` and no session file: every trace, in file-name order.
fn bare_folder(dir: &Path) -> Result<SessionTraces, CliError> {
    let traces_dir = dir.join(TRACES_DIR);
    if !traces_dir.is_dir() {
        let problem = "not a folder: expected a session written by `photorobot calibrate --out`";
        return Err(invalid(&traces_dir, "traces", problem.into()));
    }
    let traces = photorobot_core::trace::import::read_folder(&traces_dir, None)?;
    Ok(SessionTraces { traces, session: None, added: Vec::new(), warnings: Vec::new() })
}

/// What the session's calibration said, when it was not a calibration: the diagnosis then starts
/// from the best extrinsics of a refused (or tied) fit, as the user should know.
fn calibration_warnings(session: &Session) -> Vec<String> {
    let Some(fit) = session.calibration.as_ref().and_then(|c| c.fit.as_ref()) else { return Vec::new() };
    match fit.verdict {
        FitVerdict::Fits => Vec::new(),
        FitVerdict::DoesNotFit => vec![format!(
            "the session's calibration was refused (the model does not fit: residual {:.2}σ, above the {:.2}σ \
             noise allows): the diagnosis starts from its best extrinsics, and what it names is what the \
             model lacks; recalibrate with the named effects in the model before using the extrinsics",
            fit.rms_sigma, fit.threshold_sigma
        )],
        FitVerdict::Ambiguous => vec![format!(
            "the session's calibration is ambiguous (branches tie; not determined: {}): the diagnosis starts \
             from the chosen branch",
            fit.ambiguous_parameters.join(", ")
        )],
    }
}

/// CSV files of `traces/` that the session does not reference.
fn unreferenced_files(dir: &Path, session: &Session) -> Vec<String> {
    let Ok(entries) = std::fs::read_dir(dir.join(TRACES_DIR)) else { return Vec::new() };
    let mut out: Vec<String> = entries
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|name| name.to_ascii_lowercase().ends_with(".csv"))
        .filter(|name| !session.traces.iter().any(|r| r.file == format!("{TRACES_DIR}/{name}")))
        .collect();
    out.sort();
    out
}

/// A new plan file name in the session folder for proposed motions: [`PROPOSED_PLAN_FILE`], or
/// the first `discriminating-motions-N.ron` not there yet (an earlier pass's plan is kept).
pub fn free_plan_file(session_dir: &Path) -> PathBuf {
    let first = session_dir.join(PROPOSED_PLAN_FILE);
    if !first.exists() {
        return first;
    }
    (2..).map(|n| session_dir.join(format!("discriminating-motions-{n}.ron"))).find(|p| !p.exists()).unwrap_or(first)
}
