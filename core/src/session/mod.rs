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

pub mod recording;

use crate::bench::BenchPreset;
use crate::calibration::CalibrationReport;
use crate::files::{self, FieldError, FileError};
use crate::model::robot::RobotDescription;
use crate::plan::Plan;
use crate::trace::{Trace, TraceError, TraceKind};
use serde::{Deserialize, Serialize};
use std::path::{Component, Path, PathBuf};
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

const EXPECTED: &str = "a Session(format_version: 1, software, bench, robot, plans, traces, progress, calibration, diagnosis, notes) as in docs/session-format.md";

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
    #[serde(default = "yes")]
    pub complete: bool,
}

fn yes() -> bool {
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
}

/// Only the version, read first so that a file of another version is refused with advice
/// rather than with whatever its fields make the parser say.
#[derive(Deserialize)]
#[serde(rename = "Session")]
struct VersionProbe {
    /// [`MISSING`] when absent (RON would want `Some(1)` for an `Option`).
    #[serde(default = "missing")]
    format_version: u64,
}

const MISSING: u64 = u64::MAX;

fn missing() -> u64 {
    MISSING
}

/// The session file of a folder.
pub fn session_path(dir: &Path) -> PathBuf {
    dir.join(SESSION_FILE)
}

/// The autosave file of a folder.
pub fn autosave_path(dir: &Path) -> PathBuf {
    dir.join(AUTOSAVE_FILE)
}

/// What can be recovered in a session folder after a crash.
#[derive(Debug, Clone, PartialEq)]
pub struct Recovery {
    /// The autosave file.
    pub autosave: PathBuf,
    /// Number of traces recorded in it.
    pub traces: usize,
    /// Where the measurement stood.
    pub progress: Option<Progress>,
    /// Whether a saved `session.ron` exists beside it (the autosave is newer work).
    pub saved_session_exists: bool,
}

/// A session to recover in `dir`, if an autosave file is there (a run that did not end with
/// [`Session::save`]). The GUI offers it when opening the folder; the CLI resumes it.
pub fn find_recovery(dir: &Path) -> Result<Option<Recovery>, SessionError> {
    let autosave = autosave_path(dir);
    if !autosave.is_file() {
        return Ok(None);
    }
    let s = Session::load_file(&autosave)?;
    Ok(Some(Recovery {
        autosave,
        traces: s.traces.len(),
        progress: s.progress,
        saved_session_exists: session_path(dir).is_file(),
    }))
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
        }
    }

    /// Parse and check session text; `origin` names it in errors. The version is checked first.
    pub fn from_ron_str(text: &str, origin: &Path) -> Result<Self, SessionError> {
        let probe: VersionProbe = files::parse_ron(text, origin, EXPECTED)?;
        check_version((probe.format_version != MISSING).then_some(probe.format_version), origin)?;
        let session: Session = files::parse_ron(text, origin, EXPECTED)?;
        session.validate().map_err(|e| e.in_file(origin))?;
        Ok(session)
    }

    /// Load a session file (refused unread above [`MAX_SESSION_BYTES`]).
    pub fn load_file(path: &Path) -> Result<Self, SessionError> {
        let text = files::read_text_limited(
            path,
            MAX_SESSION_BYTES,
            "a session file",
            "a session.ron holds references to its traces, not the samples: is this the right file?",
        )?;
        Self::from_ron_str(&text, path)
    }

    /// Load the session of a folder (or a `session.ron` given directly). The traces are not
    /// read: see [`Session::load_traces`].
    pub fn load(dir_or_file: &Path) -> Result<Self, SessionError> {
        if dir_or_file.is_file() {
            return Self::load_file(dir_or_file);
        }
        let path = session_path(dir_or_file);
        if !path.exists() && dir_or_file.join("report.json").exists() {
            return Err(FileError::Invalid {
                file: path,
                field: "format_version".into(),
                problem: format!(
                    "no session file: this folder was written by a photorobot from before sessions \
                     (traces/, extrinsics.ron and report.json only); expected a session format {FORMAT_VERSION} \
                     file. Re-create it from its traces: photorobot calibrate --traces {}/traces --bench <preset> --out <new folder>",
                    dir_or_file.display()
                ),
            }
            .into());
        }
        if !path.exists() && autosave_path(dir_or_file).exists() {
            return Err(FileError::Invalid {
                file: path,
                field: "(file)".into(),
                problem: format!(
                    "not saved yet, but {AUTOSAVE_FILE} is there: a measurement did not finish. \
                     Recover it (Session::recover, or photorobot calibrate --resume {})",
                    dir_or_file.display()
                ),
            }
            .into());
        }
        Self::load_file(&path)
    }

    /// Load the autosave file of a folder, with every trace it references checked.
    pub fn recover(dir: &Path) -> Result<Self, SessionError> {
        let s = Self::load_file(&autosave_path(dir))?;
        for r in &s.traces {
            s.load_trace(dir, r)?;
        }
        Ok(s)
    }

    /// Save atomically as `session.ron` in `dir` (created if needed) and remove the autosave file.
    pub fn save(&self, dir: &Path) -> Result<(), SessionError> {
        let path = session_path(dir);
        self.validate().map_err(|e| e.in_file(&path))?;
        create_dir(dir)?;
        files::save_ron(&path, self)?;
        match std::fs::remove_file(autosave_path(dir)) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                Err(FileError::Io { file: autosave_path(dir), action: "cannot remove the autosave file", source: e }
                    .into())
            }
            _ => Ok(()),
        }
    }

    /// Save atomically as the autosave file of `dir` (after every measured step).
    pub fn autosave(&self, dir: &Path) -> Result<(), SessionError> {
        let path = autosave_path(dir);
        self.validate().map_err(|e| e.in_file(&path))?;
        create_dir(dir)?;
        Ok(files::save_ron(&path, self)?)
    }

    /// Write a trace into the session folder (`traces/NNN.csv`, atomically) and reference it.
    pub fn add_trace(
        &mut self,
        dir: &Path,
        trace: &Trace,
        step: Option<(usize, usize)>,
        complete: bool,
    ) -> Result<&TraceRef, SessionError> {
        let file = format!("{TRACES_DIR}/{:03}.csv", self.traces.len());
        let path = dir.join(&file);
        create_dir(&dir.join(TRACES_DIR))?;
        let bytes = trace.to_csv_bytes(&path)?;
        files::write_atomic(&path, &bytes)?;
        self.traces.push(TraceRef {
            file,
            label: trace.meta.label.clone(),
            kind: trace.meta.kind,
            samples: trace.len(),
            bytes: bytes.len() as u64,
            crc32: crc32fast::hash(&bytes),
            step,
            complete,
        });
        Ok(self.traces.last().expect("just pushed"))
    }

    /// Read one referenced trace, checked against its recorded size (before reading), CRC-32
    /// and number of samples.
    pub fn load_trace(&self, dir: &Path, r: &TraceRef) -> Result<Trace, SessionError> {
        let path = dir.join(&r.file);
        let index = self.traces.iter().position(|t| t == r).unwrap_or(0);
        let field = format!("traces[{index}]");
        let wrong = |problem: String| FileError::Invalid { file: path.clone(), field: field.clone(), problem };
        let size = std::fs::metadata(&path)
            .map_err(|source| FileError::Io { file: path.clone(), action: "cannot read", source })?
            .len();
        if size != r.bytes {
            return Err(wrong(format!(
                "{size} bytes, expected {} as recorded in {SESSION_FILE} (the file was truncated or changed after the session was saved)",
                r.bytes
            ))
            .into());
        }
        let bytes = std::fs::read(&path).map_err(|source| FileError::Io {
            file: path.clone(),
            action: "cannot read",
            source,
        })?;
        let crc = crc32fast::hash(&bytes);
        if crc != r.crc32 {
            return Err(wrong(format!(
                "CRC-32 {crc:#010x}, expected {:#010x} as recorded in {SESSION_FILE} (the file was changed after the session was saved)",
                r.crc32
            ))
            .into());
        }
        let trace = Trace::from_csv_reader(&bytes[..], &path)?;
        if trace.len() != r.samples {
            return Err(wrong(format!(
                "{} samples, expected {} as recorded in {SESSION_FILE}",
                trace.len(),
                r.samples
            ))
            .into());
        }
        Ok(trace)
    }

    /// Read every complete trace (those an identification uses), in order.
    pub fn load_traces(&self, dir: &Path) -> Result<Vec<Trace>, SessionError> {
        self.traces.iter().filter(|r| r.complete).map(|r| self.load_trace(dir, r)).collect()
    }

    /// Whether every plan has been measured.
    pub fn measured(&self) -> bool {
        self.progress.is_some_and(|p| p.plan >= self.plans.len())
    }

    /// Checks beyond the syntax: version, robot, plans, trace references inside `traces/`,
    /// unique and consistent, progress within the plans, finite results.
    pub fn validate(&self) -> Result<(), FieldError> {
        if self.format_version != FORMAT_VERSION {
            return Err(FieldError::new(
                "format_version",
                format!("expected {FORMAT_VERSION}, found {}", self.format_version),
            ));
        }
        self.robot.validate().map_err(|e| FieldError::new(format!("robot.{}", e.field), e.problem))?;
        if let Some(p) = &self.bench.description {
            p.validate().map_err(|e| FieldError::new(format!("bench.description.{}", e.field), e.problem))?;
        }
        for (k, p) in self.plans.iter().enumerate() {
            p.validate().map_err(|e| {
                FieldError::new(
                    format!("plans[{k}].{}", e.field_path().unwrap_or_else(|| "segments".into())),
                    e.labelled_problem(),
                )
            })?;
        }
        for (k, r) in self.traces.iter().enumerate() {
            let field = |f: &str| format!("traces[{k}].{f}");
            if !is_trace_path(&r.file) {
                return Err(FieldError::new(
                    field("file"),
                    format!("expected a path `{TRACES_DIR}/<name>.csv` inside the session folder, found `{}`", r.file),
                ));
            }
            if let Some(j) = self.traces[..k].iter().position(|o| o.file == r.file) {
                return Err(FieldError::new(
                    field("file"),
                    format!("`{}` is also traces[{j}]; expected each file once", r.file),
                ));
            }
            if let Some((plan, segment)) = r.step {
                let n = self.plans.get(plan).map(|p| p.segments.len());
                if n.is_none_or(|n| segment >= n) {
                    return Err(FieldError::new(
                        field("step"),
                        format!("({plan}, {segment}) is not a segment of the session's {} plan(s)", self.plans.len()),
                    ));
                }
            }
        }
        if let Some(p) = &self.progress {
            let beyond = p.plan > self.plans.len()
                || self.plans.get(p.plan).is_some_and(|plan| p.next_segment > plan.segments.len());
            if beyond {
                return Err(FieldError::new(
                    "progress",
                    format!(
                        "plan {} segment {} is beyond the session's {} plan(s)",
                        p.plan,
                        p.next_segment,
                        self.plans.len()
                    ),
                ));
            }
            if let Some(j) = p.plan_start_display.iter().position(|v| !v.is_finite()) {
                return Err(FieldError::new(format!("progress.plan_start_display[{j}]"), "expected a finite number"));
            }
        }
        if let Some(c) = &self.calibration {
            for (k, p) in c.parameters.iter().enumerate() {
                if !p.value.is_finite() {
                    return Err(FieldError::new(
                        format!("calibration.parameters[{k}].value"),
                        "expected a finite number",
                    ));
                }
                if p.sigma.is_some_and(|s| !(s.is_finite() && s >= 0.0)) {
                    return Err(FieldError::new(
                        format!("calibration.parameters[{k}].sigma"),
                        "expected a finite, non-negative number or None",
                    ));
                }
            }
            c.extrinsics
                .validate()
                .map_err(|e| FieldError::new(format!("calibration.extrinsics.{}", e.field), e.problem))?;
        }
        if let Some(d) = &self.diagnosis {
            for (k, e) in d.effects.iter().enumerate() {
                for (name, v) in [("estimate", Some(e.estimate)), ("sigma", e.sigma), ("score", Some(e.score))] {
                    if v.is_some_and(|v| !v.is_finite()) {
                        return Err(FieldError::new(
                            format!("diagnosis.effects[{k}].{name}"),
                            "expected a finite number",
                        ));
                    }
                }
            }
        }
        Ok(())
    }
}

/// `photorobot-core <version>`.
pub fn software() -> String {
    format!("photorobot-core {}", env!("CARGO_PKG_VERSION"))
}

/// Refuse a version this program cannot read, saying what to do.
fn check_version(found: Option<u64>, origin: &Path) -> Result<(), FileError> {
    let problem = match found {
        Some(v) if v == u64::from(FORMAT_VERSION) => return Ok(()),
        None => format!(
            "missing; expected `format_version: {FORMAT_VERSION}` at the top of a session file (is this a photorobot session?)"
        ),
        Some(v) if v > u64::from(FORMAT_VERSION) => format!(
            "found {v}, but this program ({}) reads session formats up to {FORMAT_VERSION}: the session was written by a newer photorobot; open it with that version or newer",
            software()
        ),
        Some(v) => format!(
            "found {v}, which is older than any released session format (this program reads {FORMAT_VERSION}); \
             re-create the session from its traces: photorobot calibrate --traces <folder>/traces --bench <preset> --out <new folder>"
        ),
    };
    Err(FileError::Invalid { file: origin.to_path_buf(), field: "format_version".into(), problem })
}

fn is_trace_path(file: &str) -> bool {
    let p = Path::new(file);
    let mut parts = p.components();
    matches!(parts.next(), Some(Component::Normal(d)) if d == TRACES_DIR)
        && matches!(parts.next(), Some(Component::Normal(_)))
        && parts.next().is_none()
        && p.extension().is_some_and(|e| e == "csv")
        && !file.contains('\\')
}

fn create_dir(dir: &Path) -> Result<(), FileError> {
    std::fs::create_dir_all(dir).map_err(|source| FileError::Io {
        file: dir.to_path_buf(),
        action: "cannot create the folder",
        source,
    })
}

#[cfg(test)]
pub(crate) mod tests;

impl DiagnosisRecord {
    /// The session's record of a diagnosis result: the named effects (then the partial ones),
    /// the verdict in words with the residual before and after.
    pub fn from_result(r: &crate::diagnose::DiagnosisResult) -> Self {
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
        let mut effects: Vec<EffectFinding> = r.effects.iter().map(|e| finding(e, "")).collect();
        effects.extend(r.partial.iter().map(|e| finding(e, "added, residual still above the noise; ")));
        let verdict = match r.verdict {
            crate::diagnose::Verdict::Named => "named",
            crate::diagnose::Verdict::None => "none: no significant missing effect",
            crate::diagnose::Verdict::Unexplained => "unexplained structure remains",
        };
        let mut verdict = format!(
            "{verdict}; gap-change residual RMS {:.2} nm before, {:.2} nm after",
            r.residual_rms_before_nm, r.residual_rms_after_nm
        );
        if let Some(g) = r.residual_where.first().filter(|_| r.verdict == crate::diagnose::Verdict::Unexplained) {
            verdict.push_str(&format!("; worst: {} {} at {:.1} σ", g.by, g.key, g.rms_sigma));
        }
        Self { effects, verdict, ..Default::default() }
    }

    /// [`DiagnosisRecord::from_result`] with the extended model (the library `effects` of the
    /// final model and the refitted extrinsics) and its validation without and with them: what
    /// `photorobot diagnose` and the GUI save.
    pub fn with_model(
        r: &crate::diagnose::DiagnosisResult,
        effects: &[crate::model::effects::Effect],
        validation: &[crate::diagnose::validation::EffectValidationRow],
    ) -> Self {
        Self {
            model_effects: effects.to_vec(),
            extrinsics: Some(r.extrinsics),
            validation: validation.to_vec(),
            ..Self::from_result(r)
        }
    }
}
