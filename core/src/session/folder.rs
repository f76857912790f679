//! A session folder on disk: the session and autosave files, loading with the version checked
//! first, atomic saving, trace files checked against their recorded size, CRC-32 and length,
//! and finding a session to recover after a crash.

use super::{
    software, Progress, Session, SessionError, TraceRef, AUTOSAVE_FILE, EXPECTED, FORMAT_VERSION, MAX_SESSION_BYTES,
    SESSION_FILE, TRACES_DIR,
};
use crate::files::{self, FileError};
use crate::trace::{import::Sourced, ReadOptions, Trace};
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// Only the version, read first so that a file of another version is refused with advice
/// rather than with whatever its fields make the parser say.
#[derive(Deserialize)]
#[serde(rename = "Session")]
struct VersionProbe {
    /// [`MISSING`] when absent (RON would want `Some(1)` for an `Option`).
    #[serde(default = "version_missing")]
    format_version: u64,
}

const MISSING: u64 = u64::MAX;

fn version_missing() -> u64 {
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
    let autosaved = Session::load_file(&autosave)?;
    Ok(Some(Recovery {
        autosave,
        traces: autosaved.traces.len(),
        progress: autosaved.progress,
        saved_session_exists: session_path(dir).is_file(),
    }))
}

impl Session {
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
        let session = Self::load_file(&autosave_path(dir))?;
        for reference in &session.traces {
            session.load_trace(dir, reference)?;
        }
        Ok(session)
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

    /// [`Session::add_trace`] for each of `traces` in order (complete, no plan step), their CSV
    /// text formatted and their files written several at a time: the same files and references
    /// as one call per trace.
    pub fn add_traces(&mut self, dir: &Path, traces: &[Trace]) -> Result<(), SessionError> {
        use rayon::prelude::*;
        // A trace that cannot be written is named by the folder (its file name comes later).
        let origin = dir.join(TRACES_DIR);
        for group in traces.chunks(files::WRITE_AT_ONCE) {
            let bytes: Vec<Vec<u8>> = group.par_iter().map(|t| t.to_csv_bytes(&origin)).collect::<Result<_, _>>()?;
            let texts = group.iter().zip(bytes).map(|(t, b)| (t, TraceText::Formatted(b))).collect();
            self.add_trace_files(dir, texts, None, true)?;
        }
        Ok(())
    }

    /// [`Session::add_traces`] for traces read from files: a file in our format whose bytes are
    /// still those it was read from is copied as it is (no formatting, the recording's own
    /// text kept); any other trace is written as [`Session::add_trace`] writes it.
    pub fn add_sourced_traces(&mut self, dir: &Path, sourced: &Sourced) -> Result<(), SessionError> {
        // A group at a time: each file's temporary stays open until its group is renamed, and
        // 128 open files stay well under the usual limit of 1024.
        let at_once = 8 * files::WRITE_AT_ONCE;
        for (traces, sources) in sourced.traces.chunks(at_once).zip(sourced.files.chunks(at_once)) {
            let texts = traces
                .iter()
                .zip(sources)
                .map(|(trace, file)| match file.native {
                    Some((crc32, size_bytes)) => (trace, TraceText::File { path: &file.path, crc32, size_bytes }),
                    None => (trace, TraceText::Format),
                })
                .collect();
            self.add_trace_files(dir, texts, None, true)?;
        }
        Ok(())
    }

    /// [`Session::add_sourced_traces`] for traces recorded after the session's (a proposed plan
    /// recorded on its bench), on the session's clock ([`continue_clock`]): when their times
    /// move, their files are written anew; otherwise they are copied as they are. Returns the
    /// shift of their times (s; 0 when their clock continues the session's).
    pub fn add_later_traces(
        &mut self,
        dir: &Path,
        mut later: Sourced,
        session_end_s: f64,
        pause_s: f64,
    ) -> Result<f64, SessionError> {
        let shift_s = continue_clock(&mut later.traces, session_end_s, pause_s);
        if shift_s != 0.0 {
            later.files.iter_mut().for_each(|f| f.native = None);
        }
        self.add_sourced_traces(dir, &later)?;
        Ok(shift_s)
    }

    /// Write a trace into the session folder (a new `traces/NNN.csv`, atomically) and reference it.
    pub fn add_trace(
        &mut self,
        dir: &Path,
        trace: &Trace,
        step: Option<(usize, usize)>,
        complete: bool,
    ) -> Result<&TraceRef, SessionError> {
        let file = self.free_trace_files(dir, 1).remove(0);
        let bytes = trace.to_csv_bytes(&dir.join(&file))?;
        self.add_trace_files(dir, vec![(trace, TraceText::Formatted(bytes))], step, complete)?;
        Ok(self.traces.last().expect("just pushed"))
    }

    /// `count` trace file names, in order, that no file of the folder and no reference has: a
    /// trace file is never rewritten.
    fn free_trace_files(&self, dir: &Path, count: usize) -> Vec<String> {
        let mut names: Vec<String> = Vec::with_capacity(count);
        for n in self.traces.len().. {
            if names.len() == count {
                break;
            }
            let f = format!("{TRACES_DIR}/{n:03}.csv");
            if !dir.join(&f).exists() && self.traces.iter().all(|r| r.file != f) {
                names.push(f);
            }
        }
        names
    }

    /// Write traces into new files of the folder ([`files::write_atomic_with`]) and reference
    /// them in order, each with its file's size and CRC-32.
    fn add_trace_files(
        &mut self,
        dir: &Path,
        traces: Vec<(&Trace, TraceText)>,
        step: Option<(usize, usize)>,
        complete: bool,
    ) -> Result<(), SessionError> {
        let names = self.free_trace_files(dir, traces.len());
        create_dir(&dir.join(TRACES_DIR))?;
        let origin = dir.join(TRACES_DIR);
        let files: Vec<(PathBuf, (&Trace, TraceText))> = names.iter().map(|n| dir.join(n)).zip(traces).collect();
        let written = files::write_atomic_with(&files, |path, (trace, text)| -> Result<_, SessionError> {
            if let TraceText::File { path: source, crc32, size_bytes } = *text {
                if let Some(tmp) = files::Temporary::copy_of(path, source, crc32, size_bytes)? {
                    return Ok((tmp, (crc32, size_bytes)));
                }
            }
            let formatted;
            let bytes = match text {
                TraceText::Formatted(bytes) => bytes,
                _ => {
                    formatted = trace.to_csv_bytes(&origin)?;
                    &formatted
                }
            };
            Ok((files::Temporary::with_bytes(path, bytes)?, (crc32fast::hash(bytes), bytes.len() as u64)))
        })?;
        for (((trace, _), file), (crc32, bytes)) in files.iter().map(|(_, t)| t).zip(names).zip(written) {
            self.traces.push(TraceRef {
                file,
                label: trace.meta.label.clone(),
                kind: trace.meta.kind,
                samples: trace.len(),
                bytes,
                crc32,
                step,
                complete,
            });
        }
        Ok(())
    }

    /// Read one referenced trace, checked against its recorded size (before reading), CRC-32
    /// and number of samples.
    pub fn load_trace(&self, dir: &Path, reference: &TraceRef) -> Result<Trace, SessionError> {
        let path = dir.join(&reference.file);
        let index = self.traces.iter().position(|t| t == reference).unwrap_or(0);
        let field = format!("traces[{index}]");
        let wrong = |problem: String| FileError::Invalid { file: path.clone(), field: field.clone(), problem };
        let size = std::fs::metadata(&path)
            .map_err(|source| FileError::Io { file: path.clone(), action: "cannot read", source })?
            .len();
        if size != reference.bytes {
            return Err(wrong(format!(
                "{size} bytes, expected {} as recorded in {SESSION_FILE} (the file was truncated or changed after the session was saved)",
                reference.bytes
            ))
            .into());
        }
        let bytes = std::fs::read(&path).map_err(|source| FileError::Io {
            file: path.clone(),
            action: "cannot read",
            source,
        })?;
        let crc = crc32fast::hash(&bytes);
        if crc != reference.crc32 {
            return Err(wrong(format!(
                "CRC-32 {crc:#010x}, expected {:#010x} as recorded in {SESSION_FILE} (the file was changed after the session was saved)",
                reference.crc32
            ))
            .into());
        }
        let trace = Trace::from_csv_bytes(&bytes, &path, &ReadOptions::default())?;
        if trace.len() != reference.samples {
            return Err(wrong(format!(
                "{} samples, expected {} as recorded in {SESSION_FILE}",
                trace.len(),
                reference.samples
            ))
            .into());
        }
        Ok(trace)
    }

    /// Read every complete trace (those an identification uses), in order.
    pub fn load_traces(&self, dir: &Path) -> Result<Vec<Trace>, SessionError> {
        use rayon::prelude::*;
        self.traces
            .iter()
            .filter(|reference| reference.complete)
            .collect::<Vec<_>>()
            .par_iter()
            .map(|reference| self.load_trace(dir, reference))
            .collect::<Vec<_>>()
            // In order: the first failing trace is the one reported.
            .into_iter()
            .collect()
    }
}

/// The pause assumed between a session's last trace and traces recorded after it whose own
/// clock starts before the session's end (s): a recorder, or a bench, started afresh.
pub const LATER_PAUSE_S: f64 = 60.0;

/// Put traces recorded after a session on its clock: when their clock starts before
/// `session_end_s` (a recorder started afresh), every sample's time moves by the same amount so
/// that they start `pause_s` after it (a drift then goes on where it was). Returns that shift
/// (s; 0 when their clock already continues the session's).
pub fn continue_clock(later: &mut [Trace], session_end_s: f64, pause_s: f64) -> f64 {
    let first_s = later.iter().filter_map(|t| t.t_s.first().copied()).fold(f64::INFINITY, f64::min);
    if !(first_s.is_finite() && first_s < session_end_s) {
        return 0.0;
    }
    let shift_s = session_end_s + pause_s - first_s;
    for t in later {
        t.t_s.iter_mut().for_each(|v| *v += shift_s);
    }
    shift_s
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

fn create_dir(dir: &Path) -> Result<(), FileError> {
    std::fs::create_dir_all(dir).map_err(|source| FileError::Io {
        file: dir.to_path_buf(),
        action: "cannot create the folder",
        source,
    })
}

/// The text of a trace file to write into a session.
enum TraceText<'a> {
    /// Formatted already.
    Formatted(Vec<u8>),
    /// The file in our format it was read from, copied when it still has the size and CRC-32
    /// it was read with; formatted otherwise.
    File { path: &'a Path, crc32: u32, size_bytes: u64 },
    /// To be formatted (read through a column mapping).
    Format,
}
