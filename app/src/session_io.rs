//! The workbench's session files: a snapshot of the wizard's data written as a
//! `photorobot_core::session` by one writer thread, in the order queued (saved, or autosaved after
//! every measured segment), the untitled sessions a crash left to recover,
//! a session read back sorted by plan, recovery of an autosave, recent folders and the HTML
//! report export. Owns no format (that is the core's) and no UI state: [`crate::state`] takes the
//! snapshot and puts a loaded session into the views.

use crate::settings::Settings;
use photorobot_core::session::{
    autosave_path, find_recovery, session_path, BenchInfo, FolderLock, Session, SessionWriter,
};
use photorobot_core::trace::Trace;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{channel, Sender};

/// Most recent session folders kept in the settings.
pub const RECENT: usize = 8;

/// Everything a save needs, copied off the UI state so the writing runs on another thread.
#[derive(Debug, Clone)]
pub struct Snapshot {
    /// The bench the session was measured on.
    pub bench: BenchInfo,
    /// The robot description the software uses.
    pub robot: photorobot_core::model::robot::RobotDescription,
    /// The wizard's plans as the bench runs them (without sweeps on a bench without a tunable
    /// laser), in step order.
    pub plans: Vec<photorobot_core::plan::Plan>,
    /// Per step: traces, and how many of them are whole (the others were cut short by a stop).
    pub steps: Vec<(Vec<Trace>, usize)>,
    /// Where an unfinished step stands (`plan` its index): the step that runs, else the first
    /// stopped one that can be resumed.
    pub progress: Option<photorobot_core::session::Progress>,
    /// Traces imported from files.
    pub imported: Vec<Trace>,
    /// The calibration, when identified.
    pub calibration: Option<photorobot_core::calibration::CalibrationReport>,
    /// The diagnosis record, when there is one.
    pub diagnosis: Option<photorobot_core::session::DiagnosisRecord>,
    /// The technician's notes.
    pub notes: String,
    /// The lab record.
    pub lab: photorobot_core::session::LabRecord,
    /// The moves of the lamella made with the calibration.
    pub moves: Vec<photorobot_core::position::MoveRecord>,
}

impl Snapshot {
    /// Put the snapshot into the writer's session: its fields, and its traces referenced (the
    /// ones already on disk as they are, new ones written to new files).
    pub fn write_into(&self, writer: &mut SessionWriter) -> Result<(), String> {
        let mut traces = Vec::new();
        for (p, (step, whole)) in self.steps.iter().enumerate() {
            // The k-th trace of a step is its plan's k-th recorded segment.
            let recorded: Vec<usize> =
                self.plans[p].segments.iter().enumerate().filter(|(_, g)| g.is_recorded()).map(|(i, _)| i).collect();
            for (k, t) in step.iter().enumerate() {
                let segment = recorded.get(k).copied().unwrap_or(k);
                traces.push((t, Some((p, segment)), k < *whole));
            }
        }
        traces.extend(self.imported.iter().map(|t| (t, None, true)));
        writer.set_traces(traces).map_err(|e| e.to_string())?;
        let session = writer.session_mut();
        session.bench = self.bench.clone();
        session.robot = self.robot.clone();
        session.plans = self.plans.clone();
        session.progress = self.progress;
        session.notes = self.notes.clone();
        session.lab = self.lab.clone();
        session.calibration = self.calibration.clone();
        session.diagnosis = self.diagnosis.clone();
        session.moves = self.moves.clone();
        Ok(())
    }

    /// Write the session's HTML report (traces are not needed for it).
    pub fn export_report(self, path: &Path) -> Result<(), String> {
        let mut session = Session::new(self.bench, self.robot);
        session.plans = self.plans;
        session.calibration = self.calibration;
        session.diagnosis = self.diagnosis;
        session.notes = self.notes;
        session.lab = self.lab;
        session.moves = self.moves;
        let html = photorobot_core::report::render_html(&session);
        photorobot_core::files::write_atomic(path, html.as_bytes()).map_err(|e| e.to_string())
    }
}

/// A session read back for the workbench: traces sorted into the wizard's steps by plan name.
#[derive(Debug)]
pub struct Loaded {
    /// The session.
    pub session: Session,
    /// Per plan of the session: its name and traces.
    pub plans: Vec<(String, Vec<Trace>)>,
    /// Traces that belong to no plan (imported).
    pub imported: Vec<Trace>,
}

/// Read a session folder, or its autosave when `recover`.
pub fn load(dir: &Path, recover: bool) -> Result<Loaded, String> {
    let session = if recover { Session::recover(dir) } else { Session::load(dir) }.map_err(|e| e.to_string())?;
    let traces = session.load_traces(dir).map_err(|e| e.to_string())?;
    let mut plans: Vec<(String, Vec<Trace>)> = session.plans.iter().map(|p| (p.name.clone(), vec![])).collect();
    let mut imported = vec![];
    for (r, t) in session.traces.iter().zip(traces) {
        match r.step.and_then(|(p, _)| plans.get_mut(p)) {
            Some(p) => p.1.push(t),
            None => imported.push(t),
        }
    }
    Ok(Loaded { session, plans, imported })
}

/// Put `dir` first in the recent folders.
pub fn remember(settings: &mut Settings, dir: &Path) {
    let d = dir.display().to_string();
    settings.recent.retain(|r| r != &d);
    settings.recent.insert(0, d);
    settings.recent.truncate(RECENT);
}

/// Number of traces an autosave in `dir` would recover, if there is one.
pub fn recoverable(dir: &Path) -> Option<usize> {
    find_recovery(dir).ok().flatten().map(|r| r.traces)
}

/// The folder of the untitled sessions (`~/.local/share/photorobot`).
pub fn untitled_base() -> PathBuf {
    let base = std::env::var_os("HOME").map_or_else(std::env::temp_dir, |h| PathBuf::from(h).join(".local/share"));
    base.join("photorobot")
}

/// A new untitled session folder in `base` (named by the time and the process): where the
/// workbench autosaves a session that has no folder yet.
pub fn untitled_dir_in(base: &Path) -> PathBuf {
    let stamp = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs());
    base.join(format!("untitled-{stamp}-{}", std::process::id()))
}

/// Whether `dir` is an untitled session's folder.
pub fn is_untitled(dir: &Path) -> bool {
    dir.file_name().is_some_and(|n| n.to_string_lossy().starts_with("untitled-"))
}

/// The newest untitled session in `base` that a crash left unsaved (an autosave, no
/// `session.ron`, not open in another photorobot), and how many traces it holds.
pub fn newest_untitled(base: &Path) -> Option<(PathBuf, usize)> {
    let mut found: Vec<(std::time::SystemTime, PathBuf)> = std::fs::read_dir(base)
        .ok()?
        .flatten()
        .map(|e| e.path())
        .filter(|d| is_untitled(d) && !session_path(d).exists())
        .filter_map(|d| Some((std::fs::metadata(autosave_path(&d)).ok()?.modified().ok()?, d)))
        .collect();
    found.sort();
    found.into_iter().rev().find_map(|(_, d)| {
        // A folder another photorobot holds is its session, not a crashed one.
        FolderLock::acquire(&d).ok()?;
        recoverable(&d).map(|n| (d, n))
    })
}

/// A save for the writer thread.
pub struct SaveJob {
    /// What to write.
    pub snapshot: Snapshot,
    /// The session folder.
    pub dir: PathBuf,
    /// The autosave file, or `session.ron`.
    pub autosave: bool,
    /// The session's revision when the snapshot was taken.
    pub revision: u64,
}

/// Called by the writer thread after each job, with its result.
pub type SaveDone = Box<dyn FnMut(&SaveJob, Result<(), String>) + Send>;

/// Start the thread that writes every save and autosave of the workbench, one at a time in the
/// order queued (two saves never write the same folder at once). It ends when the sender is
/// dropped; if it cannot start, sending fails and the caller reports the save as failed.
pub fn spawn_writer(mut done: SaveDone) -> Sender<SaveJob> {
    let (tx, rx) = channel::<SaveJob>();
    let _ = std::thread::Builder::new().name("session writer".into()).spawn(move || {
        let mut writer: Option<SessionWriter> = None;
        for job in rx {
            let result = write_job(&mut writer, &job);
            done(&job, result);
        }
    });
    tx
}

/// One save: the writer of the job's folder (a new one, knowing the trace files the folder's
/// session and autosave reference, when the folder changed), then the session or autosave.
fn write_job(writer: &mut Option<SessionWriter>, job: &SaveJob) -> Result<(), String> {
    let previous = writer.as_ref().map(|w| w.dir().to_path_buf());
    if previous.as_deref() != Some(job.dir.as_path()) {
        let bench = job.snapshot.bench.clone();
        let mut w = SessionWriter::new(&job.dir, Session::new(bench, job.snapshot.robot.clone()));
        for file in [session_path(&job.dir), autosave_path(&job.dir)] {
            if let Ok(on_disk) = Session::load_file(&file) {
                w.adopt_files(&on_disk);
            }
        }
        *writer = Some(w);
    }
    let Some(w) = writer.as_mut() else { return Err("no session writer".into()) };
    job.snapshot.write_into(w)?;
    if job.autosave { w.autosave() } else { w.save() }.map_err(|e| e.to_string())?;
    // Saved elsewhere, the untitled folder it was autosaved in is a copy: removed, so that it is
    // not offered for recovery at the next start.
    if let Some(untitled) = previous.filter(|p| !job.autosave && p != &job.dir && is_untitled(p)) {
        let _ = std::fs::remove_dir_all(untitled);
    }
    Ok(())
}
