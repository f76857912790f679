//! The application state every view reads, grouped by the view that shows it: the worker handle,
//! the bench's position, the live signal, the wizard's steps and their traces, the identification
//! and validation results, the diagnosis, the robot view and the session file. Owns applying the
//! worker's events and moving a session between the views and [`crate::session_io`]; views only
//! read it and send commands.

use crate::decimate::Decimator;
use crate::dialogs::Dialogs;
use crate::session_io::{remember, Loaded, Snapshot};
use crate::settings::Settings;
use crate::worker::{CheckedMotion, Command, DiagnosisStart, EffectValidation, Event, Resume, ValidationPair, Worker};
use photorobot_core::bench::BenchPreset;
use photorobot_core::calibration::{CalibrationReport, Mode};
use photorobot_core::measure::alignment::SignalQuality;
use photorobot_core::measure::live_count::LiveCounter;
use photorobot_core::measure::Measurement;
use photorobot_core::model::extrinsics::Extrinsics;
use photorobot_core::model::kinematics::Chain;
use photorobot_core::plan::Plan;
use photorobot_core::position::{MovePlan, MoveRecord, Target};
use photorobot_core::session::{BenchInfo, Progress};
use photorobot_core::trace::Trace;
use std::collections::HashMap;
use std::path::Path;

/// The live signal: the scrolling trace, the counter and the latest readouts.
#[derive(Debug, Default)]
pub struct LiveSignal {
    /// Irradiance against bench time.
    pub trace: Decimator,
    /// Fringe counter.
    pub counter: LiveCounter,
    /// Frozen view (the trace still fills behind it).
    pub paused: bool,
    /// The model's gap at the latest sample (µm).
    pub gap_um: Option<f64>,
    /// Laser wavelength (nm).
    pub wavelength_nm: f64,
    /// Signal quality over the last second.
    pub quality: Option<SignalQuality>,
    /// Bench time (s) at which `quality` was computed.
    quality_at_s: f64,
}

/// Most samples kept in the live buffer.
pub const LIVE_CAPACITY: usize = 20_000_000;

impl LiveSignal {
    /// dL since the counter's reset (nm).
    pub fn dl_nm(&self, n_air: f64) -> f64 {
        self.counter.steps as f64 * self.wavelength_nm / (4.0 * n_air)
    }

    /// The last `window_s` seconds of samples.
    pub fn recent(&self, window_s: f64) -> &[f64] {
        let t = self.trace.times();
        let Some(&end) = t.last() else { return &[] };
        let i = t.partition_point(|&x| x < end - window_s);
        &self.trace.values()[i..]
    }

    fn push(&mut self, t_s: &[f64], irradiance: &[f64], model_step_nm: f64) {
        self.trace.extend(t_s, irradiance);
        if self.trace.len() > LIVE_CAPACITY {
            self.trace.keep_last(LIVE_CAPACITY / 2);
        }
        // The quality sorts a second of samples: refresh it four times per second of bench
        // time, not per batch (an unpaced run sends thousands of batches a second).
        let now = self.trace.times().last().copied().unwrap_or(0.0);
        if self.quality.is_none() || now - self.quality_at_s >= 0.25 || now < self.quality_at_s {
            self.quality = SignalQuality::of(self.recent(1.0));
            self.quality_at_s = now;
        }
        let hysteresis = self.quality.map_or(f64::INFINITY, |q| 0.3 * (q.max - q.min).max(6.0 * q.noise_sigma));
        self.counter.feed(irradiance, hysteresis, model_step_nm);
    }
}

/// Where a wizard step is.
#[derive(Debug, Clone, PartialEq)]
pub enum StepState {
    /// Not run yet.
    Pending,
    /// Running.
    Running,
    /// Ran to the end.
    Done,
    /// Stopped early (cancelled or failed): the traces recorded so far are kept.
    Stopped(String),
}

/// One measurement step of the wizard.
#[derive(Debug, Clone)]
pub struct MeasurementStep {
    /// Title.
    pub title: &'static str,
    /// What the robot does and why.
    pub explanation: &'static str,
    /// The plan.
    pub plan: Plan,
    /// Only the joint identifier uses it.
    pub joint_only: bool,
    /// The designed plan (the quick calibration), used instead of the paper's strategies.
    pub designed: bool,
    /// Where it is.
    pub state: StepState,
    /// Its recorded traces.
    pub traces: Vec<Trace>,
    /// Bench time it took (s).
    pub duration_s: f64,
    /// Where it stands when stopped before its end, to measure only the rest.
    pub resume: Option<Resume>,
}

/// The wizard's measurement steps.
pub fn measurement_steps() -> Vec<MeasurementStep> {
    let step = |title, explanation, plan, joint_only| MeasurementStep {
        title,
        explanation,
        plan,
        joint_only,
        designed: false,
        state: StepState::Pending,
        traces: vec![],
        duration_s: 0.0,
        resume: None,
    };
    vec![
        step(
            "Strategy 1: translations",
            "The XYZ stage translates the lamella along X_w and Z_w at several fixed offsets while the \
             goniometers hold still. Each translation changes the gap only through the angle between the \
             lamella normal and the fiber axis, so the fringes counted along X_w and Z_w give the two tilt \
             parameters of the lamella (β_et, θ_et) to a few 0.0001°.",
            Plan::strategy1(),
            false,
        ),
        step(
            "Strategy 2: rotations",
            "The goniometers rotate the lamella about q4 (at several q5) and about q5 (at several q4). How \
             the gap varies with the rotation says where the fiber is and how it points (β_wf, θ_wf, x_wf, \
             z_wf), and, with strategy 1, how far the lamella plane sits from the rotation centre.",
            Plan::strategy2(),
            false,
        ),
        step(
            "Extra measurements: tilt scans and absolute gaps",
            "Wavelength sweeps at fixed poses measure the absolute gap (fiber to lamella, to 0.01 µm), and \
             short rotation scans at offsets break the equivalences the paper's motions leave: without \
             them Z_et and y_wf cannot be told apart (the paper's steps leave them undetermined).",
            Plan::joint_extras(),
            true,
        ),
        MeasurementStep {
            designed: true,
            ..step(
                "The designed plan",
                "Motions chosen by the experiment design (photorobot design) to reach every required σ of the \
                 joint estimate in the least bench time: absolute-gap sweeps at lateral poses, and q4/q5 tilt \
                 scans at lateral offsets read for their phase and their fringe amplitude. It replaces the \
                 steps above; the joint identifier only.",
                Plan::optimised(),
                true,
            )
        },
    ]
}

/// The wizard: its measurement steps and the one running.
pub struct Wizard {
    /// The measurement steps.
    pub steps: Vec<MeasurementStep>,
    /// The quick calibration: the designed plan instead of the paper's strategies.
    pub quick: bool,
    /// A plan being designed for the bench at hand, or designed.
    pub design: crate::plan_design::PlanDesign,
    /// The step running, if one is.
    pub running: Option<RunningStep>,
    /// The step whose redo waits for the technician's answer (it holds traces).
    pub confirm_redo: Option<usize>,
}

/// The wizard step being measured and how far it got.
#[derive(Debug, Clone, PartialEq)]
pub struct RunningStep {
    /// Index of the step in [`Wizard::steps`].
    pub step: usize,
    /// Label of the segment recording (the plan's name at the start).
    pub label: String,
    /// Fraction of the plan done (0..1).
    pub fraction: f64,
    /// The step's traces kept from before when it resumes a stopped run (0 for a run from the start).
    pub kept: usize,
}

/// The identification and its validation, as the Results and Validation views show them.
#[derive(Default)]
pub struct Results {
    /// The identification result.
    pub report: Option<Box<CalibrationReport>>,
    /// Why identification failed.
    pub identify_error: Option<String>,
    /// Validation results.
    pub validation: Option<Vec<ValidationPair>>,
    /// The last check of the calibration on the bench ([`Command::Check`]).
    pub check: Option<Vec<CheckedMotion>>,
}

impl Results {
    /// Why the validation does not prove the calibration, one sentence per motion not confirmed
    /// within its target: from the latest run on this bench (the check, else the validation
    /// after calibration), else from the report's own validation.
    pub fn validation_failures(&self) -> Vec<String> {
        let line = |motion: photorobot_core::validate::ValidationMotion,
                    f: &Result<photorobot_core::validate::ValidationFigure, String>| match f {
            Ok(f) if f.evidence.within_target => None,
            Ok(f) => Some(format!("`{}`: {}", motion.name(), f.evidence.summary())),
            Err(e) => Some(format!("`{}`: not measured ({e})", motion.name())),
        };
        if let Some(check) = &self.check {
            return check.iter().filter_map(|c| line(c.motion, &c.figure)).collect();
        }
        if let Some(pairs) = &self.validation {
            return pairs.iter().filter_map(|p| line(p.motion, &p.after)).collect();
        }
        self.report.as_ref().map_or(vec![], |r| r.validation_failures())
    }
}

/// The diagnosis, as the Diagnosis view shows it.
#[derive(Default)]
pub struct DiagnosisState {
    /// The diagnosis steps so far (title, summary).
    pub steps: Vec<(String, String)>,
    /// The diagnosis result, or why it failed.
    pub result: Option<Result<Box<photorobot_core::diagnose::DiagnosisResult>, String>>,
    /// Whether the diagnosis started from identified extrinsics (else from the design ones).
    pub from_calibration: bool,
    /// The library effects the diagnosis added (its extended model; empty when none).
    pub effects: Vec<photorobot_core::model::effects::Effect>,
    /// The validation motions planned without and with those effects (`None` until it ran).
    pub validation: Option<EffectValidation>,
    /// The diagnosis record of an opened session, kept so that saving it again keeps it.
    pub loaded_record: Option<photorobot_core::session::DiagnosisRecord>,
    /// Propose the discriminating motions as a plan instead of running them on the bench.
    pub propose_only: bool,
    /// The plan the last diagnosis proposed (it ran no motion), to record and add.
    pub proposed_plan: Option<Plan>,
}

/// What a Position preview was planned for: it is planned again when any of it changes.
#[derive(Debug, Clone, PartialEq)]
pub struct PreviewKey {
    /// The target.
    pub target: Target,
    /// Hold the gap.
    pub keep_gap: bool,
    /// Measure the tilt at the end pose.
    pub measure_tilt: bool,
    /// The bench's joints (µm, °).
    pub from: [f64; 6],
    /// The extrinsics planned with.
    pub extrinsics: [f64; 8],
}

/// The Position view: the target being edited, the move planned for it, the moves made in the
/// session (saved with it) and why the last Go was refused.
pub struct PositionState {
    /// The target being edited.
    pub target: Target,
    /// Hold the gap while the rest moves.
    pub keep_gap: bool,
    /// Measure the tilt at the end pose (default on).
    pub measure_tilt: bool,
    /// The move planned for the target from the bench's joints, or why it is refused.
    pub preview: Option<(PreviewKey, Result<MovePlan, String>)>,
    /// The moves made in this session, in order.
    pub moves: Vec<MoveRecord>,
    /// Why the last Go was refused before anything moved.
    pub refused: Option<String>,
}

impl Default for PositionState {
    /// Parallel, 880 µm from the fiber, the beam about 100 µm from the lamella's origin along
    /// X_f and Z_f (near where q = 0 puts it on the reference bench).
    fn default() -> Self {
        Self {
            target: Target { gap_um: 880.0, tilt_deg: [0.0, 0.0], lateral_um: [-100.0, -100.0], rotation_deg: 0.0 },
            keep_gap: false,
            measure_tilt: true,
            preview: None,
            moves: Vec::new(),
            refused: None,
        }
    }
}

/// The orbit camera of the robot view.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    /// Rotation about world Z (rad).
    pub yaw: f32,
    /// Elevation (rad).
    pub pitch: f32,
    /// Zoom factor (1 = the whole scene fits).
    pub zoom: f32,
}

impl Default for Camera {
    fn default() -> Self {
        Self { yaw: -0.6, pitch: 0.45, zoom: 1.0 }
    }
}

/// The robot view: its camera, the selected frame and the jog targets.
#[derive(Default)]
pub struct RobotView {
    /// Selected frame-tree node.
    pub selected_frame: Option<usize>,
    /// The camera.
    pub camera: Camera,
    /// Joint targets of the jog controls (µm, °).
    pub jog_target: [f64; 6],
}

/// The session's folder and its saving.
pub struct SessionFile {
    /// The session folder (`None` until saved, or autosaved as untitled).
    pub dir: Option<std::path::PathBuf>,
    /// Changes since the last save that succeeded.
    pub dirty: bool,
    /// Counts changes, so that a save clears `dirty` only when nothing changed while it wrote.
    pub revision: u64,
    /// The technician's notes, saved with the session.
    pub notes: String,
    /// Who, when and in what air the session is measured (edited in the Lab record window).
    pub lab: photorobot_core::session::LabRecord,
    /// Saves running on other threads report here.
    saves: (std::sync::mpsc::Sender<SaveOutcome>, std::sync::mpsc::Receiver<SaveOutcome>),
    /// Number of saves still running.
    pub saving: usize,
    /// Why the last save of `session.ron` failed, until a save succeeds.
    pub save_error: Option<String>,
    /// The writer thread's queue (started at the first save): every save in order, one at a time.
    jobs: Option<std::sync::mpsc::Sender<crate::session_io::SaveJob>>,
    /// The lock of the session folder, held while the session is in it.
    pub lock: Option<photorobot_core::session::FolderLock>,
    /// Where untitled sessions are autosaved (and looked for at start).
    pub untitled_base: std::path::PathBuf,
}

/// What a save on another thread reports back.
struct SaveOutcome {
    /// The autosave file, or `session.ron`.
    autosave: bool,
    /// The session's revision when its snapshot was taken.
    revision: u64,
    /// The folder written.
    dir: std::path::PathBuf,
    /// Success, or the error's message.
    result: Result<(), String>,
}

impl SessionFile {
    /// Recording starts: the lab record gets the time (once) and the bench's identification.
    pub fn recording_starts(&mut self, identification: &[(String, String)]) {
        self.lab.stamp_start();
        if self.lab.controllers.is_empty() {
            self.lab.controllers = identification
                .iter()
                .map(|(name, identification)| photorobot_core::session::ControllerIdentity {
                    name: name.clone(),
                    identification: identification.clone(),
                })
                .collect();
        }
    }

    /// Record a change that a save must keep.
    pub fn mark_dirty(&mut self) {
        self.dirty = true;
        self.revision += 1;
    }
}

impl Default for SessionFile {
    fn default() -> Self {
        Self {
            dir: None,
            dirty: false,
            revision: 0,
            notes: String::new(),
            lab: photorobot_core::session::LabRecord::default(),
            saves: std::sync::mpsc::channel(),
            saving: 0,
            save_error: None,
            jobs: None,
            lock: None,
            untitled_base: crate::session_io::untitled_base(),
        }
    }
}

/// Everything the views share, grouped by the view that shows it.
pub struct AppState {
    /// Persisted settings.
    pub settings: Settings,
    /// The bench worker.
    pub worker: Worker,
    /// The robot model the software uses.
    pub chain: Chain,
    /// The extrinsics the views draw with: nominal, then the identified ones.
    pub extrinsics: Extrinsics,
    /// The bench's joints (µm, °).
    pub q_display: [f64; 6],
    /// What the worker is doing.
    pub busy: Option<String>,
    /// Latest message for the status bar.
    pub status: String,
    /// The live signal.
    pub live: LiveSignal,
    /// The wizard.
    pub wizard: Wizard,
    /// The identification and validation results.
    pub results: Results,
    /// The diagnosis.
    pub diagnosis: DiagnosisState,
    /// The robot view.
    pub robot_view: RobotView,
    /// Traces imported from files.
    pub imported: Vec<Trace>,
    /// Trace analyses by index in [`AppState::all_traces`].
    pub analyses: HashMap<usize, Result<Box<Measurement>, String>>,
    /// File dialogs (a real portal in the app, scripted in tests).
    pub dialogs: Box<dyn Dialogs>,
    /// The session folder and its saving.
    pub session: SessionFile,
    /// The stage controllers' view of every joint axis (a bench on controllers), and when it came.
    pub hardware_status: Option<(std::time::Instant, Vec<photorobot_core::bench::AxisStatus>)>,
    /// The tunable laser as it last reported itself (a bench on controllers), and when.
    pub laser_status: Option<(std::time::Instant, photorobot_core::bench::LaserStatus)>,
    /// The message of a panic the worker caught, until the technician closes it.
    pub worker_failure: Option<String>,
    /// Every status and error message, with its time (the message panel).
    pub messages: crate::messages::Messages,
    /// What leaving the sweeps out costs, forecast for a bench without a tunable laser.
    pub sweep_forecast: crate::sweep_forecast::SweepForecast,
    /// The Position view: the target, its planned move and the moves made.
    pub position: PositionState,
}

impl AppState {
    /// A state on the worker's bench.
    pub fn new(settings: Settings, worker: Worker, dialogs: Box<dyn Dialogs>) -> Self {
        let chain = worker.nominal.chain.clone();
        let extrinsics = worker.nominal.extrinsics;
        Self {
            settings,
            worker,
            chain,
            extrinsics,
            q_display: [0.0; 6],
            busy: None,
            status: String::new(),
            live: LiveSignal { wavelength_nm: 1550.0, ..Default::default() },
            wizard: Wizard {
                steps: measurement_steps(),
                quick: false,
                design: Default::default(),
                running: None,
                confirm_redo: None,
            },
            results: Results::default(),
            diagnosis: DiagnosisState::default(),
            robot_view: RobotView::default(),
            imported: vec![],
            analyses: HashMap::new(),
            dialogs,
            session: SessionFile::default(),
            hardware_status: None,
            laser_status: None,
            worker_failure: None,
            messages: Default::default(),
            sweep_forecast: Default::default(),
            position: Default::default(),
        }
    }

    /// Every trace: the wizard's in step order, then the imported ones.
    pub fn all_traces(&self) -> Vec<&Trace> {
        self.wizard.steps.iter().flat_map(|s| s.traces.iter()).chain(self.imported.iter()).collect()
    }

    /// Trace `i` of [`AppState::all_traces`].
    pub fn trace(&self, i: usize) -> Option<&Trace> {
        self.wizard.steps.iter().flat_map(|s| s.traces.iter()).chain(self.imported.iter()).nth(i)
    }

    /// Start a wizard step (clears its earlier traces: a redo).
    pub fn run_step(&mut self, i: usize) {
        self.start_step(i, false);
    }

    /// Measure the rest of a stopped wizard step: its whole traces are kept, the segment the stop
    /// interrupted is measured again in full from its start, then the segments after it. A step
    /// with nothing to resume runs from the start.
    pub fn resume_step(&mut self, i: usize) {
        self.start_step(i, true);
    }

    fn start_step(&mut self, i: usize, resume: bool) {
        if self.wizard.running.is_some() || self.busy.is_some() {
            return;
        }
        self.worker.live.store(false, std::sync::atomic::Ordering::Relaxed);
        let step = &mut self.wizard.steps[i];
        let from = step.resume.take().filter(|_| resume);
        // The whole traces stay; a trace the stop cut short is measured again.
        step.traces.truncate(from.map_or(0, |r| r.whole_traces));
        step.state = StepState::Running;
        if from.is_none() {
            step.duration_s = 0.0;
        }
        self.analyses.clear();
        self.live.counter = LiveCounter::default();
        let (label, kept) = (step.plan.name.clone(), step.traces.len());
        self.wizard.running = Some(RunningStep { step: i, label, fraction: 0.0, kept });
        self.worker.send(Command::SetPace(self.settings.pace()));
        let plan = self.plan_run(i);
        self.worker.send(Command::Run { job: i, plan, from: from.map(|r| r.progress) });
        self.session.recording_starts(&self.worker.bench_identification);
    }

    /// Step `i`'s plan as this bench runs it: a bench without a tunable laser runs its motions
    /// without its sweeps. Its segments are the ones a step's progress and traces count.
    pub fn plan_run(&self, i: usize) -> Plan {
        let plan = &self.wizard.steps[i].plan;
        if self.worker.tunable_laser {
            plan.clone()
        } else {
            plan.without_sweeps()
        }
    }

    /// Cancel what runs (the traces recorded so far are kept); nothing while nothing moves.
    pub fn cancel(&mut self) {
        self.stop_all();
    }

    /// Whether step `i` is measured for the chosen plan (the paper's strategies or the designed
    /// plan) and identifier (the designed plan is the joint identifier's).
    pub fn step_used(&self, i: usize) -> bool {
        let Some(st) = self.wizard.steps.get(i) else { return false };
        if self.wizard.quick {
            st.designed
        } else {
            !st.designed && (self.settings.joint_mode || !st.joint_only)
        }
    }

    /// The steps the chosen plan and identifier need, and whether they are all done.
    pub fn ready_to_identify(&self) -> bool {
        (0..self.wizard.steps.len())
            .filter(|&i| self.step_used(i))
            .all(|i| self.wizard.steps[i].state == StepState::Done)
    }

    /// The plans of the steps the chosen plan and identifier use.
    pub fn identifier_plans(&self) -> Vec<Plan> {
        (0..self.wizard.steps.len()).filter(|&i| self.step_used(i)).map(|i| self.wizard.steps[i].plan.clone()).collect()
    }

    /// On a bench without a tunable laser: what leaving the sweeps out costs, forecast for the
    /// chosen identifier's plans (`None` while it computes, or on a bench with a tunable laser).
    pub fn sweep_cost_forecast(&mut self) -> Option<&Result<photorobot_core::identify::sweep_cost::SweepCost, String>> {
        if self.worker.tunable_laser {
            return None;
        }
        let plans = self.identifier_plans();
        let (bench, preset, joint) = (&self.worker.bench_name, &self.settings.preset, self.settings.joint_mode);
        self.sweep_forecast.get(bench, preset, joint, || plans)
    }

    /// Identify from the recorded steps.
    pub fn identify(&mut self) {
        let mode = if self.settings.joint_mode || self.wizard.quick { Mode::Joint } else { Mode::Paper };
        let used: Vec<&MeasurementStep> =
            (0..self.wizard.steps.len()).filter(|&i| self.step_used(i)).map(|i| &self.wizard.steps[i]).collect();
        let traces = used.iter().flat_map(|s| s.traces.iter().cloned()).collect();
        let duration_s = used.iter().map(|s| s.duration_s).sum();
        self.results.identify_error = None;
        self.worker.send(Command::Identify { traces, duration_s, mode });
    }

    /// Start the diagnosis on every recorded and imported trace from the identified extrinsics.
    pub fn diagnose(&mut self) {
        let traces: Vec<Trace> = self.all_traces().into_iter().cloned().collect();
        let propose_only = self.diagnosis.propose_only;
        // A second pass (traces added since) may start where the first ended.
        let earlier = match &self.diagnosis.result {
            Some(Ok(r)) => Some(r.extrinsics),
            _ => self.diagnosis.loaded_record.as_ref().and_then(|r| r.extrinsics),
        };
        self.clear_diagnosis();
        self.diagnosis.propose_only = propose_only;
        self.diagnosis.from_calibration = self.extrinsics != self.worker.nominal.extrinsics;
        let branches = self.results.report.as_ref().map(|r| r.branch_extrinsics()).unwrap_or_default();
        self.worker.send(Command::Diagnose {
            traces,
            start: DiagnosisStart { extrinsics: self.extrinsics, branches, earlier },
            run_motions: !propose_only,
        });
    }

    /// Add traces recorded after the session (a proposed plan recorded on the bench) as imported
    /// ones, on the session's clock ([`photorobot_core::session::continue_clock`]); the status
    /// says what happened. Nothing is added when one of the files cannot be read.
    pub fn add_recorded_traces(&mut self, files: &[std::path::PathBuf]) {
        let mut later = Vec::new();
        for path in files {
            match Trace::read_csv(path) {
                Ok(t) => later.push(t),
                Err(e) => {
                    self.status = format!("traces not added: {e}");
                    return;
                }
            }
        }
        let end_s = self.all_traces().iter().filter_map(|t| t.t_s.last().copied()).fold(0.0, f64::max);
        let shift_s =
            photorobot_core::session::continue_clock(&mut later, end_s, photorobot_core::session::LATER_PAUSE_S);
        self.status = format!(
            "added {} recorded traces{}",
            later.len(),
            if shift_s != 0.0 {
                format!(" (their clock moved by {shift_s:+.1} s to continue the session's)")
            } else {
                String::new()
            }
        );
        self.imported.extend(later);
        self.session.mark_dirty();
    }

    /// A plan designed for this bench becomes the designed step's plan (when that step holds no
    /// traces: they were measured with the plan before).
    fn adopt_design(&mut self) {
        let Some((preset, Ok(d))) = &self.wizard.design.result else { return };
        let status = format!("plan designed for {preset}: {:.2} min of bench time", d.total_s / 60.0);
        let plan = d.plan.clone();
        if let Some(st) = self.wizard.steps.iter_mut().find(|st| st.designed && st.traces.is_empty()) {
            st.plan = plan;
            st.state = StepState::Pending;
            self.status = status;
        }
    }

    /// Forget the diagnosis (a new run, a new or opened session).
    pub fn clear_diagnosis(&mut self) {
        self.diagnosis.steps.clear();
        self.diagnosis.result = None;
        self.diagnosis.effects.clear();
        self.diagnosis.validation = None;
        self.diagnosis.from_calibration = false;
        self.diagnosis.loaded_record = None;
        self.diagnosis.proposed_plan = None;
    }

    /// Forget the session's data for a new one on the same bench: the steps, imported traces,
    /// results and diagnosis, back to the nominal extrinsics, no folder.
    pub fn start_new_session(&mut self) {
        for st in &mut self.wizard.steps {
            st.traces.clear();
            st.state = StepState::Pending;
            st.resume = None;
        }
        self.imported.clear();
        self.results.report = None;
        self.results.validation = None;
        self.results.check = None;
        self.clear_diagnosis();
        self.analyses.clear();
        self.extrinsics = self.worker.nominal.extrinsics;
        self.session.dir = None;
        self.session.dirty = false;
        self.session.notes.clear();
        self.session.lab = Default::default();
        self.session.lock = None;
        self.position.moves.clear();
        self.status = "new session".into();
    }

    /// Apply every pending event of the worker and of the saves.
    pub fn poll_worker(&mut self) {
        for e in self.worker.drain() {
            self.apply(e);
        }
        if self.wizard.design.poll() {
            self.adopt_design();
        }
        while let Ok(outcome) = self.session.saves.1.try_recv() {
            self.session.saving -= 1;
            self.apply_save_outcome(outcome);
        }
    }

    /// A save finished: a saved `session.ron` clears `dirty` (unless something changed while
    /// it wrote); a failed one keeps the session unsaved and its error on show.
    fn apply_save_outcome(&mut self, outcome: SaveOutcome) {
        let what = if outcome.autosave { "autosaved" } else { "saved" };
        match outcome.result {
            Ok(()) => {
                self.status = format!("{what} {}", outcome.dir.display());
                if !outcome.autosave {
                    // The session lives where it was saved from now on.
                    remember(&mut self.settings, &outcome.dir);
                    self.session.dir = Some(outcome.dir);
                    self.session.save_error = None;
                    if outcome.revision == self.session.revision {
                        self.session.dirty = false;
                    }
                }
            }
            Err(e) => {
                self.status = format!("NOT {what}: {e}");
                if !outcome.autosave {
                    self.session.save_error = Some(e);
                }
            }
        }
    }

    /// Save the session in `dir` on the writer thread (`autosave`: the autosave file, else
    /// `session.ron`), after every save queued before it; the result comes back as a status
    /// message. The folder is locked first: one held by another photorobot is not written.
    pub fn save_in_background(&mut self, dir: std::path::PathBuf, autosave: bool) {
        let revision = self.session.revision;
        self.session.saving += 1;
        let lock = match self.acquire_lock(&dir) {
            Ok(lock) => lock,
            Err(e) => {
                let _ = self.session.saves.0.send(SaveOutcome { autosave, revision, dir, result: Err(e) });
                return;
            }
        };
        if lock.is_some() {
            self.session.lock = lock;
        }
        let job = crate::session_io::SaveJob { snapshot: self.snapshot(), dir, autosave, revision };
        let tx = self.session.saves.0.clone();
        let jobs = self.session.jobs.get_or_insert_with(|| {
            crate::session_io::spawn_writer(Box::new(move |job, result| {
                let _ = tx.send(SaveOutcome {
                    autosave: job.autosave,
                    revision: job.revision,
                    dir: job.dir.clone(),
                    result,
                });
            }))
        });
        if let Err(std::sync::mpsc::SendError(job)) = jobs.send(job) {
            self.session.jobs = None;
            let result = Err("the session writer is not running; nothing was written".to_string());
            let _ = self.session.saves.0.send(SaveOutcome { autosave, revision, dir: job.dir, result });
        }
    }

    /// The lock of `dir` for this session: `None` when it holds it already, an error naming the
    /// folder when another photorobot has it open.
    pub fn acquire_lock(&self, dir: &Path) -> Result<Option<photorobot_core::session::FolderLock>, String> {
        if self.session.lock.as_ref().is_some_and(|l| l.dir() == dir) {
            return Ok(None);
        }
        photorobot_core::session::FolderLock::acquire(dir).map(Some).map_err(|e| e.to_string())
    }

    /// A segment of the running step was recorded: keep it and autosave, so that a crash costs
    /// at most the segment being measured.
    fn segment_done(&mut self, trace: Trace, progress: Progress) {
        let Some(step) = self.wizard.running.as_ref().and_then(|r| self.wizard.steps.get_mut(r.step)) else { return };
        step.traces.push(trace);
        // Where the step stands, autosaved with it: a crash leaves a step that can be resumed.
        step.resume = Some(Resume { progress, whole_traces: step.traces.len() });
        self.session.mark_dirty();
        let base = &self.session.untitled_base;
        let dir = self.session.dir.get_or_insert_with(|| crate::session_io::untitled_dir_in(base)).clone();
        self.save_in_background(dir, true);
    }

    /// A snapshot of what a session file keeps, for a save on another thread.
    pub fn snapshot(&self) -> Snapshot {
        // The designed plan's step is kept only when it is the plan chosen or holds traces: a
        // session of the paper's strategies lists their plans alone, as `calibrate` writes it.
        let kept: Vec<usize> = (0..self.wizard.steps.len())
            .filter(|&i| !self.wizard.steps[i].designed || self.step_used(i) || !self.wizard.steps[i].traces.is_empty())
            .collect();
        let progress = self
            .unfinished_step()
            .and_then(|p| kept.iter().position(|&i| i == p.plan).map(|k| Progress { plan: k, ..p }));
        Snapshot {
            bench: BenchInfo {
                name: self.worker.bench_name.clone(),
                preset: Some(self.settings.preset.clone()),
                description: BenchPreset::resolve(&self.settings.preset).ok(),
                seed: Some(self.settings.seed),
            },
            robot: self.chain.description().clone(),
            plans: kept.iter().map(|&i| self.plan_run(i)).collect(),
            steps: kept.iter().map(|&i| (self.wizard.steps[i].traces.clone(), self.whole_traces(i))).collect(),
            progress,
            imported: self.imported.clone(),
            calibration: self.results.report.as_deref().cloned(),
            diagnosis: match &self.diagnosis.result {
                Some(Ok(d)) => Some(self.diagnosis_record(d)),
                _ => self.diagnosis.loaded_record.clone(),
            },
            notes: self.session.notes.clone(),
            lab: self.session.lab.clone(),
            moves: self.position.moves.clone(),
        }
    }

    /// How many of step `i`'s traces are whole: all of a finished or running step's (a running
    /// step's come in whole segment by segment), a stopped step's up to where it resumes, else all
    /// but the last, which the stop may have cut short.
    fn whole_traces(&self, i: usize) -> usize {
        let st = &self.wizard.steps[i];
        let n = st.traces.len();
        match (&st.state, st.resume) {
            (StepState::Done | StepState::Running, _) => n,
            (_, Some(r)) => r.whole_traces.min(n),
            _ => n.saturating_sub(1),
        }
    }

    /// Where an unfinished step stands, as the session keeps it (`plan` the step's index): the
    /// running step, else the first stopped one that can be resumed.
    fn unfinished_step(&self) -> Option<Progress> {
        let running = self.wizard.running.as_ref().map(|r| r.step);
        let unfinished =
            |i: usize, st: &MeasurementStep| Some(i) == running || matches!(st.state, StepState::Stopped(_));
        let (i, resume) = (self.wizard.steps.iter().enumerate())
            .filter_map(|(i, st)| st.resume.filter(|_| unfinished(i, st)).map(|r| (i, r)))
            .min_by_key(|(i, _)| (Some(*i) != running, *i))?;
        Some(Progress { plan: i, ..resume.progress })
    }

    /// The diagnosis as the session keeps it, as `photorobot diagnose` writes it: the result, the
    /// extended model (effects and refitted extrinsics) and the validation without and with it.
    fn diagnosis_record(
        &self,
        d: &photorobot_core::diagnose::DiagnosisResult,
    ) -> photorobot_core::session::DiagnosisRecord {
        let rows = match &self.diagnosis.validation {
            Some(EffectValidation::Ran { rows, .. }) => rows.as_slice(),
            _ => &[],
        };
        photorobot_core::session::DiagnosisRecord::with_model(d, &self.diagnosis.effects, rows)
    }

    /// Put a loaded session into the state: the wizard's steps get the traces of the plans with the
    /// same name (done when the session says so), the rest are imported; the calibration is shown.
    pub fn apply_loaded(&mut self, loaded: Loaded, dir: &Path) {
        for st in &mut self.wizard.steps {
            st.traces.clear();
            st.state = StepState::Pending;
            st.resume = None;
        }
        self.imported = loaded.imported;
        // Per plan: its whole traces, and whether they all are.
        let whole: Vec<(usize, bool)> = (0..loaded.plans.len())
            .map(|p| {
                let of_plan = || loaded.session.traces.iter().filter(move |r| r.step.is_some_and(|(q, _)| q == p));
                (of_plan().filter(|r| r.complete).count(), of_plan().all(|r| r.complete))
            })
            .collect();
        let progress = loaded.session.progress;
        let runs: Vec<Plan> = (0..self.wizard.steps.len()).map(|i| self.plan_run(i)).collect();
        for (p, ((name, traces), (whole, complete))) in loaded.plans.into_iter().zip(whole).enumerate() {
            match self.wizard.steps.iter_mut().zip(&runs).find(|(st, _)| st.plan.name == name) {
                Some((st, run)) if !traces.is_empty() => {
                    st.traces = traces;
                    // The step the session was measuring resumes where it stood, when this
                    // bench runs the plan it ran (its progress counts that plan's segments).
                    let stood = progress.filter(|pr| pr.plan == p);
                    let same_plan = loaded.session.plans.get(p) == Some(run);
                    st.state = if complete && stood.is_none() {
                        StepState::Done
                    } else {
                        StepState::Stopped("recovered: incomplete".into())
                    };
                    st.resume = stood
                        .filter(|_| same_plan)
                        .map(|pr| Resume { progress: Progress { plan: 0, ..pr }, whole_traces: whole });
                }
                Some(_) => {}
                None => self.imported.extend(traces),
            }
        }
        // A session measured with the designed plan opens on it.
        self.wizard.quick = self.wizard.steps.iter().any(|st| st.designed && !st.traces.is_empty());
        self.results.report = loaded.session.calibration.map(Box::new);
        if let Some(r) = &self.results.report {
            self.extrinsics = r.extrinsics;
        }
        self.session.notes = loaded.session.notes;
        self.session.lab = loaded.session.lab;
        self.position.moves = loaded.session.moves;
        self.analyses.clear();
        self.results.validation = None;
        self.results.check = None;
        // The session's diagnosis record is kept for the next save and shown as a record by the
        // Diagnosis view (it is a summary, not a result: no steps, no residuals to draw).
        self.clear_diagnosis();
        self.diagnosis.loaded_record = loaded.session.diagnosis;
        self.session.dir = Some(dir.to_path_buf());
        self.session.dirty = false;
        remember(&mut self.settings, dir);
    }

    /// Apply one event.
    pub fn apply(&mut self, e: Event) {
        self.note_errors(&e);
        match e {
            Event::Samples { t_s, irradiance, q_display, wavelength_nm, gap_um, model_step_nm } => {
                self.live.push(&t_s, &irradiance, model_step_nm);
                self.live.gap_um = gap_um;
                self.live.wavelength_nm = wavelength_nm;
                self.q_display = q_display;
            }
            Event::Progress { label, fraction } => {
                if let Some(r) = self.wizard.running.as_mut() {
                    r.label = label;
                    r.fraction = fraction;
                }
            }
            Event::Position(q) => self.q_display = q,
            Event::PlanDone { job, traces, duration_s, outcome, resume } => {
                let kept = self.wizard.running.as_ref().filter(|r| r.step == job).map_or(0, |r| r.kept);
                if let Some(step) = self.wizard.steps.get_mut(job) {
                    // A resumed run's traces follow the ones kept from before.
                    step.traces.truncate(kept);
                    step.traces.extend(traces);
                    step.duration_s += duration_s;
                    step.resume = match (&outcome, resume) {
                        (_, Some(r)) => Some(Resume { whole_traces: kept + r.whole_traces, ..r }),
                        // A run the worker could not report on (it panicked) resumes after the
                        // last segment it handed on.
                        (Err(_), None) => step.resume.filter(|r| r.whole_traces <= step.traces.len()),
                        (Ok(()), None) => None,
                    };
                    step.state = match outcome {
                        Ok(()) => StepState::Done,
                        Err(e) => StepState::Stopped(e),
                    };
                    let n = step.traces.len();
                    self.status = format!("{}: {n} trace{} recorded", step.title, if n == 1 { "" } else { "s" });
                }
                self.wizard.running = None;
                // Autosave after every measured step: a crash never costs a measurement.
                self.session.mark_dirty();
                let base = &self.session.untitled_base;
                let dir = self.session.dir.get_or_insert_with(|| crate::session_io::untitled_dir_in(base)).clone();
                self.save_in_background(dir, true);
            }
            Event::SegmentDone(trace, progress) => self.segment_done(*trace, progress),
            Event::Identified(r) => match r {
                Ok(report) => {
                    self.extrinsics = report.extrinsics;
                    self.status = format!("identified from {} observations", report.observations);
                    self.results.report = Some(report);
                    self.results.validation = None;
                    self.results.check = None;
                    self.session.mark_dirty();
                }
                Err(e) => self.results.identify_error = Some(e),
            },
            Event::Validated(pairs) => {
                self.status = format!("validation done: {} motions, before and after", pairs.len());
                self.results.validation = Some(pairs);
                self.results.check = None;
            }
            Event::Checked(motions) => {
                let confirmed = motions.iter().filter(|m| m.figure.as_ref().is_ok_and(|f| f.evidence.within_target));
                self.status = format!(
                    "calibration checked: {} of {} motions confirmed within target",
                    confirmed.count(),
                    motions.len()
                );
                self.results.check = Some(motions);
            }
            Event::DiagnosisStep(title, summary) => self.diagnosis.steps.push((title, summary)),
            Event::DiagnosisPlan(plan) => self.diagnosis.proposed_plan = plan,
            Event::Diagnosed(r) => {
                self.status = match &r {
                    Ok(d) => format!("diagnosis: {}", d.verdict.word()),
                    Err(e) => format!("diagnosis failed: {e}"),
                };
                self.diagnosis.result = Some(r);
                self.session.mark_dirty();
            }
            Event::EffectsValidated { effects, validation } => {
                if let EffectValidation::Ran { rows, .. } = &validation {
                    self.status = format!("validation with and without the added effects: {} motions", rows.len());
                }
                self.diagnosis.effects = effects;
                self.diagnosis.validation = Some(validation);
                self.session.mark_dirty();
            }
            Event::Analysed { index, result } => {
                self.analyses.insert(index, result);
            }
            Event::HardwareStatus(axes) => self.hardware_status = Some((std::time::Instant::now(), axes)),
            Event::LaserStatus(laser) => self.laser_status = Some((std::time::Instant::now(), laser)),
            Event::Moved(Ok(record)) => {
                self.status = format!("move {}: {}", record.verdict.word(), record.note);
                self.position.moves.push(*record);
                self.session.mark_dirty();
            }
            Event::Moved(Err(e)) => {
                self.status = format!("move refused: {e}");
                self.position.refused = Some(e);
            }
            Event::WorkerPanicked(message) => {
                self.status = format!("the bench worker failed: {message}");
                self.worker_failure = Some(message);
            }
            Event::Busy(b) => {
                if let Some(msg) = &b {
                    self.status.clone_from(msg);
                }
                self.busy = b;
            }
        }
        self.messages.sync(&self.status);
    }

    /// List the errors an event carries that the status line does not show.
    fn note_errors(&mut self, e: &Event) {
        use crate::messages::Level;
        match e {
            Event::Identified(Err(e)) => self.messages.push(Level::Error, format!("identification failed: {e}")),
            Event::PlanDone { job, outcome: Err(e), .. } => {
                let title = self.wizard.steps.get(*job).map_or("measurement", |s| s.title);
                self.messages.push(Level::Error, format!("{title} stopped: {e}"));
            }
            _ => {}
        }
    }
}
