//! The workbench's session files: converting the wizard's state to a `photorobot_core::session`
//! and back, saving off the UI thread, autosaving after every measured step, recovery of an
//! autosave, recent folders and the HTML report export. Owns no format: that is the core's.

use crate::state::{AppState, StepState};
use photorobot_core::bench::BenchPreset;
use photorobot_core::session::{find_recovery, BenchInfo, Session};
use photorobot_core::trace::Trace;
use std::path::{Path, PathBuf};

/// Most recent session folders kept in the settings.
pub const RECENT: usize = 8;

/// Everything a save needs, copied off the UI state so the writing runs on another thread.
#[derive(Debug, Clone)]
pub struct Snapshot {
    bench: BenchInfo,
    robot: photorobot_core::model::robot::RobotDescription,
    plans: Vec<photorobot_core::plan::Plan>,
    /// Per step: traces and whether the step ran to the end.
    steps: Vec<(Vec<Trace>, bool)>,
    imported: Vec<Trace>,
    calibration: Option<photorobot_core::identify::calibration::CalibrationReport>,
    diagnosis: Option<photorobot_core::session::DiagnosisRecord>,
    notes: String,
}

/// A snapshot of the state.
pub fn snapshot(s: &AppState) -> Snapshot {
    Snapshot {
        bench: BenchInfo {
            name: s.worker.bench_name.clone(),
            preset: Some(s.settings.preset.clone()),
            description: BenchPreset::resolve(&s.settings.preset).ok(),
            seed: Some(s.settings.seed),
        },
        robot: s.chain.description().clone(),
        plans: s.wizard.steps.iter().map(|st| st.plan.clone()).collect(),
        steps: s.wizard.steps.iter().map(|st| (st.traces.clone(), st.state == StepState::Done)).collect(),
        imported: s.imported.clone(),
        calibration: s.results.report.as_deref().cloned(),
        diagnosis: match &s.diagnosis.result {
            Some(Ok(d)) => Some(diagnosis_record(s, d)),
            _ => s.diagnosis.loaded_record.clone(),
        },
        notes: s.session.notes.clone(),
    }
}

/// The diagnosis as the session keeps it, as `photorobot diagnose` writes it: the result, the
/// extended model (effects and refitted extrinsics) and the validation without and with it.
fn diagnosis_record(
    s: &AppState,
    d: &photorobot_core::diagnose::DiagnosisResult,
) -> photorobot_core::session::DiagnosisRecord {
    let rows = match &s.diagnosis.validation {
        Some(crate::worker::EffectValidation::Ran { rows, .. }) => rows.as_slice(),
        _ => &[],
    };
    photorobot_core::session::DiagnosisRecord::with_model(d, &s.diagnosis.effects, rows)
}

impl Snapshot {
    /// The session, its traces written into `dir/traces/`.
    pub fn write(&self, dir: &Path) -> Result<Session, String> {
        let mut session = Session::new(self.bench.clone(), self.robot.clone());
        session.plans = self.plans.clone();
        session.notes = self.notes.clone();
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

/// Put a loaded session into the state: the wizard's steps get the traces of the plans with the
/// same name (done when the session says so), the rest are imported; the calibration is shown.
pub fn apply(s: &mut AppState, loaded: Loaded, dir: &Path) {
    for st in &mut s.wizard.steps {
        st.traces.clear();
        st.state = StepState::Pending;
    }
    s.imported = loaded.imported;
    let complete_plans: Vec<bool> = (0..loaded.plans.len())
        .map(|p| loaded.session.traces.iter().filter(|r| r.step.is_some_and(|(q, _)| q == p)).all(|r| r.complete))
        .collect();
    for ((name, traces), complete) in loaded.plans.into_iter().zip(complete_plans) {
        match s.wizard.steps.iter_mut().find(|st| st.plan.name == name) {
            Some(st) if !traces.is_empty() => {
                st.traces = traces;
                st.state = if complete { StepState::Done } else { StepState::Stopped("recovered: incomplete".into()) };
            }
            Some(_) => {}
            None => s.imported.extend(traces),
        }
    }
    s.results.report = loaded.session.calibration.map(Box::new);
    if let Some(r) = &s.results.report {
        s.extrinsics = r.extrinsics;
    }
    s.session.notes = loaded.session.notes;
    s.analyses.clear();
    s.results.validation = None;
    // The session's diagnosis record is kept for the next save and shown as a record by the
    // Diagnosis view (it is a summary, not a result: no steps, no residuals to draw).
    s.clear_diagnosis();
    s.diagnosis.loaded_record = loaded.session.diagnosis;
    s.session.dir = Some(dir.to_path_buf());
    s.session.dirty = false;
    remember(s, dir);
}

/// Put `dir` first in the recent folders.
pub fn remember(s: &mut AppState, dir: &Path) {
    let d = dir.display().to_string();
    s.settings.recent.retain(|r| r != &d);
    s.settings.recent.insert(0, d);
    s.settings.recent.truncate(RECENT);
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

/// Write the HTML report of the state's session (traces are not needed for it).
pub fn export_report(s: &AppState, path: &Path) -> Result<(), String> {
    let snap = snapshot(s);
    let mut session = Session::new(snap.bench, snap.robot);
    session.plans = snap.plans;
    session.calibration = snap.calibration;
    session.diagnosis = snap.diagnosis;
    session.notes = snap.notes;
    let html = photorobot_core::report::render_html(&session);
    photorobot_core::files::write_atomic(path, html.as_bytes()).map_err(|e| e.to_string())
}
