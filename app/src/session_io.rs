//! The workbench's session files: a snapshot of the wizard's data written as a
//! `photorobot_core::session` off the UI thread (saved, or autosaved after every measured step),
//! a session read back sorted by plan, recovery of an autosave, recent folders and the HTML
//! report export. Owns no format (that is the core's) and no UI state: [`crate::state`] takes the
//! snapshot and puts a loaded session into the views.

use crate::settings::Settings;
use photorobot_core::session::{find_recovery, BenchInfo, Session};
use photorobot_core::trace::Trace;
use std::path::{Path, PathBuf};

/// Most recent session folders kept in the settings.
pub const RECENT: usize = 8;

/// Everything a save needs, copied off the UI state so the writing runs on another thread.
#[derive(Debug, Clone)]
pub struct Snapshot {
    /// The bench the session was measured on.
    pub bench: BenchInfo,
    /// The robot description the software uses.
    pub robot: photorobot_core::model::robot::RobotDescription,
    /// The wizard's plans, in step order.
    pub plans: Vec<photorobot_core::plan::Plan>,
    /// Per step: traces and whether the step ran to the end.
    pub steps: Vec<(Vec<Trace>, bool)>,
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
}

impl Snapshot {
    /// The session, its traces written into `dir/traces/`.
    pub fn write(&self, dir: &Path) -> Result<Session, String> {
        let mut session = Session::new(self.bench.clone(), self.robot.clone());
        session.plans = self.plans.clone();
        session.notes = self.notes.clone();
        session.lab = self.lab.clone();
        for (p, (traces, complete)) in self.steps.iter().enumerate() {
            // The k-th trace of a step is its plan's k-th recorded segment.
            let recorded: Vec<usize> =
                self.plans[p].segments.iter().enumerate().filter(|(_, g)| g.is_recorded()).map(|(i, _)| i).collect();
            for (k, t) in traces.iter().enumerate() {
                let segment = recorded.get(k).copied().unwrap_or(k);
                // The last trace of a stopped step may be partial.
                let whole = *complete || k + 1 < traces.len();
                session.add_trace(dir, t, Some((p, segment)), whole).map_err(|e| e.to_string())?;
            }
        }
        for t in &self.imported {
            session.add_trace(dir, t, None, true).map_err(|e| e.to_string())?;
        }
        session.calibration = self.calibration.clone();
        session.diagnosis = self.diagnosis.clone();
        Ok(session)
    }

    /// Save as `session.ron` in `dir` (atomic; removes the autosave).
    pub fn save(&self, dir: &Path) -> Result<(), String> {
        self.write(dir)?.save(dir).map_err(|e| e.to_string())
    }

    /// Save as the autosave file of `dir`.
    pub fn autosave(&self, dir: &Path) -> Result<(), String> {
        self.write(dir)?.autosave(dir).map_err(|e| e.to_string())
    }

    /// Write the session's HTML report (traces are not needed for it).
    pub fn export_report(self, path: &Path) -> Result<(), String> {
        let mut session = Session::new(self.bench, self.robot);
        session.plans = self.plans;
        session.calibration = self.calibration;
        session.diagnosis = self.diagnosis;
        session.notes = self.notes;
        session.lab = self.lab;
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

/// Where the workbench autosaves a session that has no folder yet.
pub fn untitled_dir() -> PathBuf {
    let base = std::env::var_os("HOME").map_or_else(std::env::temp_dir, |h| PathBuf::from(h).join(".local/share"));
    let stamp = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs());
    base.join("photorobot").join(format!("untitled-{stamp}"))
}
