//! Sessions: what a calibration measured and found, kept as a folder a technician can file, move and reopen.
//! Owns the versioned `session.ron` format, its checks, loading (with trace length and CRC checks), atomic saving,
//! the autosave file and finding a session to recover after a crash. Schema: `docs/session-format.md`.
//!
//! A session folder:
//!
//! ```text
//! session/
//!   session.ron            this format (written by Session::save)
//!   session.autosave.ron   the same, rewritten after every measured step; removed by Session::save
//!   traces/000.csv …       the recorded traces (crate::trace format), referenced from session.ron
//!   extrinsics.ron         the identified extrinsics (photorobot calibrate; for `frames --extrinsics`)
//!   report.json            the calibration report as JSON (photorobot calibrate)
//! ```
//!
//! Loading never trusts a file: the session file is refused above [`MAX_SESSION_BYTES`] from its
//! size, its `format_version` is checked before anything else is interpreted, every trace is
//! checked against its recorded length and CRC-32 before it is parsed, and every error names
//! the file and the line or field and says what was expected.
//!
//! Files: `folder` loads and saves a session folder (version first, traces checked), `checks`
//! holds the checks beyond the syntax, `diagnosis` the diagnosis record, `recording` measuring
//! into a session, `writer` the incremental writing both the recording and the workbench use
//! (trace files never rewritten, the session file last), `lock` the lock of an open folder.

mod checks;
mod diagnosis;
mod folder;
mod lab;
pub mod lock;
mod moves;
pub mod recording;
pub mod writer;

pub use diagnosis::{DiagnosisRecord, EffectFinding};
pub use folder::{autosave_path, continue_clock, find_recovery, session_path, Recovery, LATER_PAUSE_S};
pub use lab::{
    check_range, now_utc_rfc3339, ControllerIdentity, LabRecord, HUMIDITY_RANGE_PERCENT, PRESSURE_RANGE_HPA,
    TEMPERATURE_RANGE_C,
};
pub use lock::{FolderLock, LOCK_FILE};
pub use moves::{placement_of, references_from};
pub use writer::SessionWriter;

use crate::bench::BenchPreset;
use crate::calibration::CalibrationReport;
use crate::files::FileError;
use crate::model::robot::RobotDescription;
use crate::plan::Plan;
use crate::trace::{TraceError, TraceKind};
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// The session format this program writes, and the newest it reads.
pub const FORMAT_VERSION: u32 = 1;
/// Name of the session file in a session folder.
pub const SESSION_FILE: &str = "session.ron";
/// Name of the autosave file in a session folder.
pub const AUTOSAVE_FILE: &str = "session.autosave.ron";
/// Folder of the traces in a session folder.
pub const TRACES_DIR: &str = "traces";
/// Largest session file read (bytes): 32 MiB. A session holds references to its traces, not the
/// samples, so a real one is a few hundred kB; anything larger is refused unread.
pub const MAX_SESSION_BYTES: u64 = 32 << 20;

const EXPECTED: &str = "a Session(format_version: 1, software, bench, robot, plans, traces, progress, calibration, diagnosis, notes, lab, moves) as in docs/session-format.md";

/// Why a session could not be loaded, saved or used. Every message names the file and the
/// line or field.
#[derive(Debug, Error)]
pub enum SessionError {
    /// The session file (or a folder) could not be read, parsed or written.
    #[error(transparent)]
    File(#[from] FileError),
    /// A trace of the session could not be read or written.
    #[error(transparent)]
    Trace(#[from] TraceError),
    /// The folder is open in another photorobot (its lock file is held).
    #[error("{}", lock::locked_message(.dir, *.pid))]
    Locked {
        /// The session folder.
        dir: std::path::PathBuf,
        /// The process holding it, when it wrote its id.
        pid: Option<u32>,
    },
}

/// The bench a session was measured on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BenchInfo {
    /// The bench's name as it reports it ("virtual bench table2-ideal", "PI E-712 at 10.0.0.2").
    pub name: String,
    /// The preset it was built from: an embedded name (`table2-ideal`) or a file path.
    #[serde(default)]
    pub preset: Option<String>,
    /// The preset itself, embedded so the session is self-contained (virtual benches; for
    /// recorded traces, the bench model used to identify).
    #[serde(default)]
    pub description: Option<BenchPreset>,
    /// Random seed of a virtual bench.
    #[serde(default)]
    pub seed: Option<u64>,
}

/// A recorded trace: a CSV file of the session folder, with what is needed to check it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TraceRef {
    /// Path relative to the session folder, `traces/NNN.csv`.
    pub file: String,
    /// The trace's label (as in its `# label:` line).
    pub label: String,
    /// What it records.
    pub kind: TraceKind,
    /// Number of samples (data rows).
    pub samples: usize,
    /// Size of the file (bytes).
    pub bytes: u64,
    /// CRC-32 (IEEE) of the file's bytes.
    pub crc32: u32,
    /// Index of the plan in [`Session::plans`] and of the segment in that plan, for traces
    /// measured from the session's plans; `None` for imported traces.
    #[serde(default)]
    pub step: Option<(usize, usize)>,
    /// False for the partial trace of a segment interrupted by a fault or a cancel: kept (never
    /// lose data) but not used to identify; the resumed run measures the segment again in full.
    #[serde(default = "complete_by_default")]
    pub complete: bool,
}

/// A trace reference that does not say `complete` is a complete trace.
fn complete_by_default() -> bool {
    true
}

/// Where a measurement stands: the next step to measure. With `plan == plans.len()` every plan
/// has been measured.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Progress {
    /// Index of the plan being measured.
    pub plan: usize,
    /// Index of its next segment to run.
    pub next_segment: usize,
    /// Joint vector (µm, °) the plan started from: it fixes where every segment starts.
    pub plan_start_display: [f64; 6],
}

/// A calibration session: the bench, the robot, the plans, the recorded traces (by reference),
/// the identified parameters and the diagnosis, and notes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Session {
    /// Format version of the file ([`FORMAT_VERSION`] when written by this program).
    pub format_version: u32,
    /// Program and version that wrote it, e.g. `photorobot-core 0.1.0`.
    pub software: String,
    /// The bench.
    pub bench: BenchInfo,
    /// The robot description used (nominal, as the software believes it).
    pub robot: RobotDescription,
    /// The plans measured, in order.
    #[serde(default)]
    pub plans: Vec<Plan>,
    /// Every recorded trace, in the order recorded.
    #[serde(default)]
    pub traces: Vec<TraceRef>,
    /// Where the measurement stands (`None` before measuring and for imported traces).
    #[serde(default)]
    pub progress: Option<Progress>,
    /// The identification: parameters with uncertainties, identifiability, residuals, validation.
    #[serde(default)]
    pub calibration: Option<CalibrationReport>,
    /// The discrepancy diagnosis, when one was run.
    #[serde(default)]
    pub diagnosis: Option<DiagnosisRecord>,
    /// Free text by the technician.
    #[serde(default)]
    pub notes: String,
    /// When, by whom and in what air it was measured, and the controllers' identification
    /// (absent in older files: empty).
    #[serde(default)]
    pub lab: LabRecord,
    /// The moves of the lamella made with this calibration, in order, each with its proof
    /// (absent in older files: none).
    #[serde(default)]
    pub moves: Vec<crate::position::MoveRecord>,
}

impl Session {
    /// A new, empty session on a bench.
    pub fn new(bench: BenchInfo, robot: RobotDescription) -> Self {
        Self {
            format_version: FORMAT_VERSION,
            software: software(),
            bench,
            robot,
            plans: Vec::new(),
            traces: Vec::new(),
            progress: None,
            calibration: None,
            diagnosis: None,
            notes: String::new(),
            lab: LabRecord::default(),
            moves: Vec::new(),
        }
    }

    /// Whether every plan has been measured.
    pub fn measured(&self) -> bool {
        self.progress.is_some_and(|p| p.plan >= self.plans.len())
    }

    /// How far plan `p` is measured: its recorded segments that have a whole trace, and its
    /// recorded segments. The workbench measures its steps in any order, so a plan after the
    /// session's progress may be measured already.
    pub fn plan_coverage(&self, p: usize) -> (usize, usize) {
        let Some(plan) = self.plans.get(p) else { return (0, 0) };
        let recorded: Vec<usize> = (0..plan.segments.len()).filter(|&i| plan.segments[i].is_recorded()).collect();
        let whole = recorded.iter().filter(|&&i| self.traces.iter().any(|t| t.complete && t.step == Some((p, i))));
        (whole.count(), recorded.len())
    }

    /// The first plan other than the progress's that is measured in part (some of its recorded
    /// segments have a whole trace, not all), as (plan, whole, recorded): the workbench stopped
    /// it and keeps no resume point for it here, so a run over the plans would measure it again
    /// from its start and count its earlier traces twice.
    pub fn partly_measured_besides_progress(&self) -> Option<(usize, usize, usize)> {
        let resumed = self.progress.map(|p| p.plan);
        (0..self.plans.len())
            .filter(|&p| Some(p) != resumed)
            .map(|p| (p, self.plan_coverage(p)))
            .find(|(_, (whole, recorded))| *whole > 0 && whole < recorded)
            .map(|(p, (whole, recorded))| (p, whole, recorded))
    }
}

/// `photorobot-core <version>`.
pub fn software() -> String {
    format!("photorobot-core {}", env!("CARGO_PKG_VERSION"))
}

#[cfg(test)]
pub(crate) mod tests;
