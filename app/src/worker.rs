//! The bench worker: a thread that owns the bench and does every slow thing (running plans,
//! jogging, the live dither, identification, validation, trace analysis), so the UI never blocks.
//! Owns the command and event types; the UI sends [`Command`]s and drains [`Event`]s each frame.
//!
//! Samples stream out while a segment records; pacing holds the bench clock to the wall clock
//! (times a speed factor) so a virtual bench looks like a real one, or runs as fast as it can.

use photorobot_core::bench::{run_plan_with, Bench, BenchPreset, RunControl, VirtualBench};
use photorobot_core::calibration::{report_from_traces, CalibrationReport, Mode};
use photorobot_core::diagnose::fit::StopCheck;
use photorobot_core::diagnose::motions::BenchRunner;
use photorobot_core::diagnose::validation::{validate_with_effects, EffectValidationRow};
use photorobot_core::diagnose::{Diagnosis, DiagnosisResult};
use photorobot_core::measure::{self, Measurement};
use photorobot_core::model::effects::Effect;
use photorobot_core::model::extrinsics::Extrinsics;
use photorobot_core::model::phase::PhaseModel;
use photorobot_core::plan::{JointTarget, Plan, Segment};
use photorobot_core::position::{move_to, MoveRecord, Placement, ProofOptions, Reference, Target};
use photorobot_core::session::Progress;
use photorobot_core::trace::Trace;
use photorobot_core::validate::before_after::{check_calibration, run_before_and_after};
use photorobot_core::validate::{StopSettings, ValidationFigure, ValidationMotion};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{channel, Receiver, RecvTimeoutError, Sender};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crate::bench_guard::{lock, panic_message, GuardedBench, KeptTraces};
pub use crate::step_recording::Resume;
use crate::step_recording::{record_step, Ran};

/// How fast the bench clock runs against the wall clock.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum Pace {
    /// Bench time = wall time × this factor.
    Speed(f64),
    /// No waiting (a virtual bench simulates as fast as it can).
    Unpaced,
}

/// Where a diagnosis starts.
#[derive(Debug, Clone)]
pub struct DiagnosisStart {
    /// The calibrated extrinsics.
    pub extrinsics: Extrinsics,
    /// The other branches the calibration tried ([`Diagnosis::set_branches`]).
    pub branches: Vec<Extrinsics>,
    /// Where an earlier diagnosis of the session ended ([`Diagnosis::set_earlier`]): a second
    /// pass, traces added since, may start there.
    pub earlier: Option<Extrinsics>,
}

/// What the UI asks for.
#[derive(Debug)]
pub enum Command {
    /// Run a plan; its traces come back in [`Event::PlanDone`] with the same `job`.
    Run {
        /// Caller's tag.
        job: usize,
        /// The plan.
        plan: Plan,
        /// Where a stopped run of it stands, to measure only the rest; `None`: from the start.
        from: Option<Progress>,
    },
    /// Move (unrecorded) to joint values (µm, °).
    Jog([f64; 6]),
    /// Identify from traces (joint or paper mode).
    Identify {
        /// The recorded traces.
        traces: Vec<Trace>,
        /// Bench time they took (s).
        duration_s: f64,
        /// The identifier.
        mode: Mode,
    },
    /// Run the four validation motions planned with the nominal and with the identified extrinsics.
    Validate {
        /// The identified extrinsics.
        identified: Extrinsics,
    },
    /// Check a calibration on the bench without recalibrating: the four validation motions
    /// planned with its extrinsics, with their proof (what `photorobot validate` runs).
    Check {
        /// The calibration's extrinsics.
        extrinsics: Extrinsics,
    },
    /// Analyse a recorded trace (phase tracking, extremum counting or sweep fit) with the model.
    Analyse {
        /// Caller's tag (the trace's index).
        index: usize,
        /// The trace.
        trace: Box<Trace>,
        /// Extrinsics of the model used for the motion hint.
        extrinsics: Extrinsics,
    },
    /// Run the discrepancy workflow on the traces from the calibrated extrinsics, with
    /// discriminating motions on this bench, or (`run_motions` false) proposed as a plan.
    Diagnose {
        /// The recorded traces.
        traces: Vec<Trace>,
        /// The extrinsics it starts from.
        start: DiagnosisStart,
        /// Run the discriminating motions on the bench; otherwise propose them
        /// ([`Event::DiagnosisPlan`]) to be recorded and added later.
        run_motions: bool,
    },
    /// Place the lamella at a target ([`photorobot_core::position::move_to`]), proven as the bench
    /// allows; the record comes back in [`Event::Moved`].
    Move {
        /// The calibrated model the move is planned with.
        placement: Box<Placement>,
        /// Where the lamella goes.
        target: Target,
        /// Hold the gap while the rest moves.
        keep_gap: bool,
        /// Poses whose gap a sweep measured (a bench without a tunable laser tracks from them).
        references: Vec<Reference>,
        /// Measure the tilt at the end pose.
        measure_tilt: bool,
    },
    /// Report the stage controllers' view of every joint axis ([`Event::HardwareStatus`]; nothing on a
    /// simulated bench).
    HardwareStatus,
    /// Open the links to the stage controllers again after a fault (the outcome in the status).
    Reconnect,
    /// Change the pacing.
    SetPace(Pace),
    /// Stop the thread.
    Shutdown,
}

/// One validation motion, planned before and after calibration.
#[derive(Debug, Clone)]
pub struct ValidationPair {
    /// The motion.
    pub motion: ValidationMotion,
    /// Planned with the nominal extrinsics.
    pub before: Result<ValidationFigure, String>,
    /// Planned with the identified extrinsics.
    pub after: Result<ValidationFigure, String>,
}

/// One validation motion of a check of the calibration ([`Command::Check`]).
#[derive(Debug, Clone)]
pub struct CheckedMotion {
    /// The motion.
    pub motion: ValidationMotion,
    /// Its figures and proof, or why it did not run.
    pub figure: Result<ValidationFigure, String>,
}

/// The validation motions after a diagnosis, planned without and with the effects it added.
#[derive(Debug, Clone, PartialEq)]
pub enum EffectValidation {
    /// The diagnosis added no effect: there is no extended model to validate.
    NoEffect,
    /// Run on the bench (its name); one row per validation motion.
    Ran {
        /// The bench the motions ran on.
        bench: String,
        /// Peak-to-peak cavity variation without and with the effects, per motion.
        rows: Vec<EffectValidationRow>,
    },
    /// The extended model could not be built or the bench refused the motions.
    Failed(String),
}

/// The worker's [`Event::Busy`] text while it runs the validation motions after a diagnosis.
pub const BUSY_EFFECT_VALIDATION: &str = "validating with and without the added effects";
/// The worker's [`Event::Busy`] text while it runs the validation motions before and after.
pub const BUSY_VALIDATING: &str = "validating";
/// The worker's [`Event::Busy`] text while it runs the diagnosis.
pub const BUSY_DIAGNOSING: &str = "diagnosing";
/// The worker's [`Event::Busy`] text while it moves the lamella to a target.
pub const BUSY_MOVING: &str = "moving the lamella to the target";
/// The worker's [`Event::Busy`] text while it jogs the robot.
pub const BUSY_JOGGING: &str = "jogging";

/// What the worker reports.
#[derive(Debug)]
pub enum Event {
    /// New samples of the segment being recorded.
    Samples {
        /// Bench time (s).
        t_s: Vec<f64>,
        /// Irradiance (the trace's unit, mW).
        irradiance: Vec<f64>,
        /// Joints at the last sample (µm, °).
        q_display: [f64; 6],
        /// Laser wavelength at the last sample (nm).
        wavelength_nm: f64,
        /// The model's gap |L| at the last sample (µm), `None` when the beam misses the lamella.
        gap_um: Option<f64>,
        /// The model's phase-equivalent gap change since the previous batch (nm): its sign is
        /// the direction of the fringes.
        model_step_nm: f64,
    },
    /// Progress of the running segment.
    Progress {
        /// Segment label.
        label: String,
        /// Fraction of the plan done (0..1).
        fraction: f64,
    },
    /// Joint positions after a move (µm, °).
    Position([f64; 6]),
    /// A plan finished, failed or was cancelled; every recorded trace is here.
    PlanDone {
        /// The caller's tag.
        job: usize,
        /// Recorded traces (a partial one of an interrupted segment included).
        traces: Vec<Trace>,
        /// Bench time used (s).
        duration_s: f64,
        /// `Err` with the reason when it did not run to the end.
        outcome: Result<(), String>,
        /// Where a plan that did not run to the end stands, to resume it.
        resume: Option<Resume>,
    },
    /// A segment of the running plan was recorded (its whole trace), before the next one starts;
    /// with where the plan stands after it.
    SegmentDone(Box<Trace>, Progress),
    /// Identification finished.
    Identified(Result<Box<CalibrationReport>, String>),
    /// Validation finished.
    Validated(Vec<ValidationPair>),
    /// The check of the calibration finished.
    Checked(Vec<CheckedMotion>),
    /// A trace analysis finished.
    Analysed {
        /// The caller's tag.
        index: usize,
        /// The analysis.
        result: Result<Box<Measurement>, String>,
    },
    /// One step of the diagnosis: its title and summary.
    DiagnosisStep(String, String),
    /// The diagnosis finished (or failed).
    Diagnosed(Result<Box<DiagnosisResult>, String>),
    /// After a diagnosis that ran no motion: the discriminating motions it proposes as a plan
    /// (`None`: settled, or nothing would help).
    DiagnosisPlan(Option<Plan>),
    /// After a diagnosis that finished: the effects it added (its extended model, empty when
    /// none) and the validation motions planned without and with them.
    EffectsValidated {
        /// The library effects of the final model (named, or added and kept as partial).
        effects: Vec<Effect>,
        /// The validation.
        validation: EffectValidation,
    },
    /// A move of the lamella ran (its record, a stopped one included) or was refused before
    /// anything moved (why).
    Moved(Result<Box<MoveRecord>, String>),
    /// The worker started (`Some(what)`) or finished (`None`) a job.
    Busy(Option<String>),
    /// The stage controllers' view of every joint axis (a bench on controllers only).
    HardwareStatus(Vec<photorobot_core::bench::AxisStatus>),
    /// The tunable laser as it reports itself (a bench on controllers with a driven laser).
    LaserStatus(photorobot_core::bench::LaserStatus),
    /// A command panicked in the worker (the message): the worker caught it and serves the next
    /// command; a plan it interrupted was reported first with the traces recorded before.
    WorkerPanicked(String),
}

/// The UI's handle on the worker thread.
pub struct Worker {
    commands: Sender<Command>,
    events: Receiver<Event>,
    /// Set to stop the running motion: the one flag every segment on this worker's bench obeys
    /// (plans, validation and diagnosis motions, jogs, the live dither).
    pub cancel: Arc<AtomicBool>,
    /// While set and idle, the worker dithers the lamella along the beam and streams the signal.
    pub live: Arc<AtomicBool>,
    handle: Option<JoinHandle<()>>,
    /// The bench's name.
    pub bench_name: String,
    /// Each controller's name and identification reply (a virtual bench's own), for the lab record.
    pub bench_identification: Vec<(String, String)>,
    /// The software's model before calibration.
    pub nominal: PhaseModel,
    /// The bench has a tunable laser: plans may sweep (else the wizard leaves the sweeps out).
    pub tunable_laser: bool,
}

/// Why a run ended early when the technician stopped it.
pub const STOPPED: &str = "stopped by the user";

/// Step of the live view's dither staircase along the beam (µm).
pub const DITHER_STEP_UM: f64 = 0.1;
/// Steps per half-cycle: 2 µm, about 2.6 fringes at 1.55 µm, in about 0.8 s.
pub const DITHER_STEPS: usize = 20;

impl Worker {
    /// Start a worker on the virtual bench of `preset` with random seed `seed`. `notify` is
    /// called after every event (the GUI passes `request_repaint`).
    pub fn virtual_bench(
        preset_name: &str,
        seed: Option<u64>,
        pace: Pace,
        notify: Box<dyn Fn() + Send>,
    ) -> Result<Self, String> {
        let preset = BenchPreset::resolve(preset_name).map_err(|e| e.to_string())?;
        let bench = VirtualBench::new(&preset, seed).map_err(|e| e.to_string())?;
        let nominal = PhaseModel::new(
            preset.robot_description().map_err(|e| e.to_string())?,
            Extrinsics::nominal_design(),
            preset.optics,
            &preset.ambient,
            preset.laser.wavelength_nm,
        )?;
        Ok(Self::start(Box::new(bench), nominal, pace, notify))
    }

    /// Start a worker on any bench.
    pub fn start(bench: Box<dyn Bench>, nominal: PhaseModel, pace: Pace, notify: Box<dyn Fn() + Send>) -> Self {
        let (commands, rx) = channel();
        let (tx, events) = channel();
        let cancel = Arc::new(AtomicBool::new(false));
        let live = Arc::new(AtomicBool::new(false));
        let bench_name = bench.name();
        let bench_identification = bench.identification();
        let tunable_laser = bench.tunable_laser();
        let kept = KeptTraces::default();
        let bench = Box::new(GuardedBench::new(bench, cancel.clone(), kept.clone()));
        let mut state = Thread {
            bench,
            nominal: nominal.clone(),
            pace,
            tx,
            notify,
            cancel: cancel.clone(),
            live: live.clone(),
            dither_up: true,
            kept,
            current: None,
        };
        let handle = std::thread::Builder::new()
            .name("bench worker".into())
            .spawn(move || state.supervise(rx))
            .expect("the OS starts a thread");
        Self {
            commands,
            events,
            cancel,
            live,
            handle: Some(handle),
            bench_name,
            bench_identification,
            nominal,
            tunable_laser,
        }
    }

    /// Send a command (ignored once the thread is gone).
    pub fn send(&self, c: Command) {
        // A new motion starts with the stop flag down (a stop pressed before it was asked for
        // is not its stop).
        if matches!(
            c,
            Command::Run { .. }
                | Command::Jog(_)
                | Command::Validate { .. }
                | Command::Check { .. }
                | Command::Diagnose { .. }
                | Command::Move { .. }
        ) {
            self.cancel.store(false, Ordering::Relaxed);
        }
        let _ = self.commands.send(c);
    }

    /// Start or stop the live dither; starting it puts the stop flag down.
    pub fn set_live(&self, on: bool) {
        if on {
            self.cancel.store(false, Ordering::Relaxed);
        }
        self.live.store(on, Ordering::Relaxed);
    }

    /// Every event received since the last call.
    pub fn drain(&self) -> Vec<Event> {
        self.events.try_iter().collect()
    }

    /// Wait up to `timeout` for one event.
    pub fn recv_timeout(&self, timeout: Duration) -> Option<Event> {
        self.events.recv_timeout(timeout).ok()
    }
}

impl Drop for Worker {
    fn drop(&mut self) {
        self.cancel.store(true, Ordering::Relaxed);
        self.live.store(false, Ordering::Relaxed);
        let _ = self.commands.send(Command::Shutdown);
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

struct Thread {
    bench: Box<dyn Bench>,
    nominal: PhaseModel,
    pace: Pace,
    tx: Sender<Event>,
    notify: Box<dyn Fn() + Send>,
    cancel: Arc<AtomicBool>,
    live: Arc<AtomicBool>,
    dither_up: bool,
    /// The traces of the running plan, kept by the guarded bench for a panic's report.
    kept: KeptTraces,
    /// The wizard job running and the bench time it started at (s).
    current: Option<(usize, f64)>,
}

impl Thread {
    fn send(&self, e: Event) {
        let _ = self.tx.send(e);
        (self.notify)();
    }

    /// Serve commands until shutdown; a panic in a command is reported and the serving goes on.
    fn supervise(&mut self, rx: Receiver<Command>) {
        loop {
            match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| self.serve(&rx))) {
                Ok(()) => return,
                Err(payload) => self.recover(panic_message(&*payload)),
            }
        }
    }

    /// After a panic: the interrupted plan's traces recorded so far go back as a stopped run,
    /// the live dither stops, and the UI is told why and that the worker is idle.
    fn recover(&mut self, message: String) {
        self.live.store(false, Ordering::Relaxed);
        let traces = std::mem::take(&mut lock(&self.kept).traces);
        lock(&self.kept).on = false;
        if let Some((job, start_s)) = self.current.take() {
            let end_s = traces.last().and_then(|t| t.t_s.last().copied()).unwrap_or(start_s);
            let outcome = Err(format!("the worker panicked: {message}"));
            let duration_s = (end_s - start_s).max(0.0);
            self.send(Event::PlanDone { job, traces, duration_s, outcome, resume: None });
        }
        self.send(Event::WorkerPanicked(message));
        self.send(Event::Busy(None));
    }

    /// Note the command starting: a wizard plan's traces are kept aside while it runs.
    fn begin(&mut self, command: &Command) {
        let mut kept = lock(&self.kept);
        kept.traces.clear();
        kept.on = matches!(command, Command::Run { .. });
        self.current = match command {
            Command::Run { job, .. } => Some((*job, self.bench.clock_s())),
            _ => None,
        };
    }

    /// The command finished: nothing is kept aside any more.
    fn end(&mut self) {
        *lock(&self.kept) = Default::default();
        self.current = None;
    }

    fn serve(&mut self, rx: &Receiver<Command>) {
        self.send(Event::Position(self.bench.position_display()));
        loop {
            let command = match rx.recv_timeout(Duration::from_millis(20)) {
                Ok(c) => c,
                Err(RecvTimeoutError::Timeout) => {
                    if self.live.load(Ordering::Relaxed) {
                        self.dither();
                    }
                    continue;
                }
                Err(RecvTimeoutError::Disconnected) => return,
            };
            self.begin(&command);
            match command {
                Command::Shutdown => return,
                Command::SetPace(p) => self.pace = p,
                Command::Reconnect => {
                    self.send(Event::Busy(Some("reconnecting to the controllers".into())));
                    let outcome = match self.bench.reconnect() {
                        Ok(()) => "reconnected".to_string(),
                        Err(e) => format!("reconnect failed: {e}"),
                    };
                    self.send(Event::Position(self.bench.position_display()));
                    self.send(Event::Busy(Some(outcome)));
                    self.send(Event::Busy(None));
                }
                Command::HardwareStatus => {
                    if let Some(status) = self.bench.hardware_status() {
                        self.send(Event::HardwareStatus(status));
                    }
                    if let Some(status) = self.bench.laser_status() {
                        self.send(Event::LaserStatus(status));
                    }
                }
                Command::Run { job, plan, from } => {
                    self.send(Event::Busy(Some(format!("running {}", plan.name))));
                    let pace = self.pace;
                    let ran = self.run(&plan, pace, Run::Step(from));
                    let (traces, duration_s, outcome, resume) = (ran.traces, ran.duration_s, ran.outcome, ran.resume);
                    self.send(Event::PlanDone { job, traces, duration_s, outcome, resume });
                    self.send(Event::Busy(None));
                }
                Command::Jog(to) => {
                    self.send(Event::Busy(Some(BUSY_JOGGING.into())));
                    let plan = Plan {
                        name: "jog".into(),
                        description: String::new(),
                        segments: vec![Segment::Move {
                            to: JointTarget::all(to),
                            record: false,
                            label: "jog".into(),
                            through: false,
                        }],
                    };
                    if let Err(e) = self.run(&plan, Pace::Unpaced, Run::Motion).outcome {
                        self.send(Event::Busy(Some(format!("jog refused: {e}"))));
                    } else {
                        self.send(Event::Busy(Some("jog done".into())));
                    }
                    self.send(Event::Busy(None));
                }
                Command::Identify { traces, duration_s, mode } => {
                    self.send(Event::Busy(Some("identifying".into())));
                    let r = report_from_traces(traces, duration_s, self.bench.name(), &self.nominal, mode);
                    self.send(Event::Identified(r.map(Box::new)));
                    self.send(Event::Busy(None));
                }
                Command::Validate { identified } => {
                    self.send(Event::Busy(Some(BUSY_VALIDATING.into())));
                    let pairs =
                        run_before_and_after(self.bench.as_mut(), &self.nominal, &identified, &StopSettings::default())
                            .into_iter()
                            .map(|p| ValidationPair {
                                motion: p.motion,
                                before: p.before.map_err(|e| e.to_string()),
                                after: p.after.map_err(|e| e.to_string()),
                            })
                            .collect();
                    self.send(Event::Position(self.bench.position_display()));
                    self.send(Event::Validated(pairs));
                    self.send(Event::Busy(None));
                }
                Command::Check { extrinsics } => {
                    self.send(Event::Busy(Some(BUSY_VALIDATING.into())));
                    let checked =
                        check_calibration(self.bench.as_mut(), &self.nominal, &extrinsics, &StopSettings::default())
                            .into_iter()
                            .map(|(motion, figure)| CheckedMotion { motion, figure: figure.map_err(|e| e.to_string()) })
                            .collect();
                    self.send(Event::Position(self.bench.position_display()));
                    self.send(Event::Checked(checked));
                    self.send(Event::Busy(None));
                }
                Command::Diagnose { traces, start, run_motions } => self.serve_diagnose(&traces, &start, run_motions),
                Command::Move { placement, target, keep_gap, references, measure_tilt } => {
                    self.serve_move(&placement, &target, keep_gap, &references, measure_tilt)
                }
                Command::Analyse { index, trace, extrinsics } => {
                    let model = PhaseModel { extrinsics, ..self.nominal.clone() };
                    let result = measure::analyse(&trace, &model).map(Box::new).map_err(|e| e.to_string());
                    self.send(Event::Analysed { index, result });
                }
            }
            self.end();
        }
    }

    /// The validation motions planned with the nominal robot and the calibrated extrinsics
    /// `without`, and with the extended model (`effects` on the robot, extrinsics `with`), run on
    /// this bench.
    fn validate_with_effects(
        &mut self,
        without: &Extrinsics,
        with: &Extrinsics,
        effects: &[Effect],
    ) -> EffectValidation {
        let base = PhaseModel { extrinsics: *without, ..self.nominal.clone() };
        match validate_with_effects(self.bench.as_mut(), &base, without, with, effects) {
            Ok(rows) => EffectValidation::Ran { bench: self.bench.name(), rows },
            Err(e) => EffectValidation::Failed(format!("extended model: {e}")),
        }
    }

    /// Move the lamella to `target` with the calibrated `placement`, paced as the plans are.
    fn serve_move(
        &mut self,
        placement: &Placement,
        target: &Target,
        keep_gap: bool,
        references: &[Reference],
        measure_tilt: bool,
    ) {
        self.send(Event::Busy(Some(BUSY_MOVING.into())));
        // Paced as the plans are: a virtual bench's move takes the time a real one does.
        let (pace, wall0, bench_t0) = (self.pace, Instant::now(), self.bench.clock_s());
        let mut on_samples = |tr: &Trace, _: usize| {
            if let (Pace::Speed(f), Some(t)) = (pace, tr.t_s.last()) {
                let due = Duration::from_secs_f64(((t - bench_t0) / f.max(1e-6)).max(0.0));
                if let Some(wait) = due.checked_sub(wall0.elapsed()) {
                    std::thread::sleep(wait.min(Duration::from_millis(500)));
                }
            }
        };
        let mut control = RunControl { cancel: &self.cancel, on_samples: &mut on_samples, on_progress: &mut |_| {} };
        let started = photorobot_core::session::now_utc_rfc3339();
        let options = ProofOptions { sweeps: true, tilt: measure_tilt };
        let record = move_to(self.bench.as_mut(), placement, target, keep_gap, references, options, &mut control)
            .map(|mut r| {
                r.started_utc = Some(started);
                Box::new(r)
            })
            .map_err(|e| e.to_string());
        self.send(Event::Position(self.bench.position_display()));
        self.send(Event::Moved(record));
        self.send(Event::Busy(None));
    }

    /// A diagnosis of `traces` from `extrinsics`, then the validation motions with and without
    /// the named effects.
    fn serve_diagnose(&mut self, traces: &[Trace], start: &DiagnosisStart, run_motions: bool) {
        self.send(Event::Busy(Some("diagnosing".into())));
        let outcome = self.diagnose(traces, start, run_motions);
        let extrinsics = start.extrinsics;
        self.send(Event::Position(self.bench.position_display()));
        match outcome {
            Ok((result, effects, proposed)) => {
                let with = result.extrinsics;
                self.send(Event::Diagnosed(Ok(Box::new(result))));
                if !run_motions {
                    self.send(Event::DiagnosisPlan(proposed));
                }
                // As `photorobot diagnose` does: the validation motions planned with
                // the calibrated model and with the extended one, on this bench.
                let validation = if effects.is_empty() {
                    EffectValidation::NoEffect
                } else if self.cancel.load(Ordering::Relaxed) {
                    EffectValidation::Failed(STOPPED.into())
                } else {
                    self.send(Event::Busy(Some(BUSY_EFFECT_VALIDATION.into())));
                    let v = self.validate_with_effects(&extrinsics, &with, &effects);
                    self.send(Event::Position(self.bench.position_display()));
                    v
                };
                self.send(Event::EffectsValidated { effects, validation });
            }
            Err(e) => self.send(Event::Diagnosed(Err(e))),
        }
        self.send(Event::Busy(None));
    }

    /// The diagnosis, step by step (each step reported), discriminating motions on this bench
    /// (or, without `run_motions`, proposed); the result, the library effects of its final
    /// model and the proposed plan.
    fn diagnose(
        &mut self,
        traces: &[Trace],
        start: &DiagnosisStart,
        run_motions: bool,
    ) -> Result<(DiagnosisResult, Vec<Effect>, Option<Plan>), String> {
        // The stop ends the computing too: the traces' analysis within one trace, the steps
        // within one model evaluation.
        let cancel = self.cancel.clone();
        let stop = StopCheck::new(move || cancel.load(Ordering::Relaxed));
        let (mut d, skipped) = match Diagnosis::from_traces(&self.nominal, traces, start.extrinsics, stop) {
            Ok(d) => d,
            Err(_) if self.cancel.load(Ordering::Relaxed) => return Err(STOPPED.into()),
            Err(e) => return Err(e.to_string()),
        };
        d.set_branches(&start.branches);
        if let Some(e) = start.earlier {
            d.set_earlier(e);
        }
        if !skipped.is_empty() {
            let _ = self.tx.send(Event::DiagnosisStep(
                "0. traces".into(),
                format!("{} traces gave no observation (e.g. {}: {})", skipped.len(), skipped[0].0, skipped[0].1),
            ));
        }
        if let Some((label, why)) = d.hint_led.first() {
            let _ = self.tx.send(Event::DiagnosisStep(
                "0. traces".into(),
                format!("{} tracked motions do not match their fringe count (e.g. {label}: {why})", d.hint_led.len()),
            ));
        }
        // The bench's own times are already after the session when it recorded it (its clock
        // runs on); a bench started since (a session opened from disk) is shifted after it.
        let offset = (d.end_time_s() + photorobot_core::session::LATER_PAUSE_S - self.bench.clock_s()).max(0.0);
        let mut runner = BenchRunner::new(self.bench.as_mut(), offset);
        let tx = self.tx.clone();
        // One call can add several steps (an effect added, then one removed): each is sent.
        let mut sent = d.steps.len();
        loop {
            let runner =
                run_motions.then_some(&mut runner as &mut dyn photorobot_core::diagnose::motions::MotionRunner);
            match d.step(runner) {
                Ok(Some(_)) => {}
                Ok(None) => break,
                // A motion the stop cancelled fails the step: it was stopped all the same.
                Err(_) if self.cancel.load(Ordering::Relaxed) => return Err(STOPPED.into()),
                Err(e) => return Err(e.to_string()),
            }
            for step in &d.steps[sent..] {
                let _ = tx.send(Event::DiagnosisStep(step.title().to_string(), step.summary()));
            }
            sent = d.steps.len();
            (self.notify)();
        }
        let effects = d.state().map(|s| s.library_effects()).unwrap_or_default();
        let result = d.result().cloned().ok_or("the diagnosis ended without a result")?;
        Ok((result, effects, d.proposed_plan()))
    }

    /// One live dither half-cycle along the beam (q2), at real time: a staircase of small recorded
    /// steps (the stages' speed limits would make one move of a few fringes last milliseconds).
    fn dither(&mut self) {
        let q = self.bench.position_display();
        let limits = self.bench.robot().links[1].limits;
        let mut step = if self.dither_up { DITHER_STEP_UM } else { -DITHER_STEP_UM };
        let span = step * DITHER_STEPS as f64;
        if q[1] + span > limits.max || q[1] + span < limits.min {
            step = -step;
        }
        self.dither_up = !self.dither_up;
        let segments = (1..=DITHER_STEPS)
            .map(|k| {
                let mut to = q;
                to[1] = q[1] + step * k as f64;
                Segment::Move { to: JointTarget::all(to), record: true, label: "live dither".into(), through: false }
            })
            .collect();
        let plan = Plan { name: "live dither".into(), description: String::new(), segments };
        if self.run(&plan, Pace::Speed(1.0), Run::Motion).outcome.is_err() {
            self.live.store(false, Ordering::Relaxed);
        }
    }

    /// Run a plan, streaming samples (paced) and, for a wizard step, progress.
    fn run(&mut self, plan: &Plan, pace: Pace, kind: Run) -> Ran {
        let report_progress = matches!(kind, Run::Step(_));
        let wall0 = Instant::now();
        let bench_t0 = self.bench.clock_s();
        let total_s = plan
            .duration_s(self.bench.robot(), self.bench.position_display(), self.bench.motion_limits())
            .unwrap_or(1.0)
            .max(1e-9);
        let tx = self.tx.clone();
        let notify = &self.notify;
        let model = &self.nominal;
        let fp =
            photorobot_core::model::optics::FabryPerot::new(&model.optics, self.bench.wavelength_nm(), model.n_air)
                .ok();
        let mut last_gap_nm: Option<f64> = None;
        let mut on_samples = |tr: &Trace, from: usize| {
            if from >= tr.len() {
                return;
            }
            let last = tr.len() - 1;
            let q = tr.joints_display(last);
            let gap_um = model
                .extrinsics
                .cavity(&model.chain.end_effector(&model.chain.description().q_from_display(&q)))
                .ok()
                .map(|c| c.length_um.abs());
            let phase_gap = fp.as_ref().map(|fp| model.phase_gap_nm(fp, &q)).filter(|g| g.is_finite());
            let step = match (phase_gap, last_gap_nm) {
                (Some(g), Some(prev)) => g - prev,
                (Some(g), None) => g - fp.as_ref().map_or(g, |fp| model.phase_gap_nm(fp, &tr.joints_display(from))),
                _ => 0.0,
            };
            last_gap_nm = phase_gap.or(last_gap_nm);
            let _ = tx.send(Event::Samples {
                t_s: tr.t_s[from..].to_vec(),
                irradiance: tr.irradiance[from..].to_vec(),
                q_display: q,
                wavelength_nm: tr.wavelength_nm[last],
                gap_um,
                model_step_nm: step,
            });
            notify();
            if let Pace::Speed(f) = pace {
                let due = Duration::from_secs_f64(((tr.t_s[last] - bench_t0) / f.max(1e-6)).max(0.0));
                if let Some(wait) = due.checked_sub(wall0.elapsed()) {
                    std::thread::sleep(wait.min(Duration::from_millis(500)));
                }
            }
            if report_progress {
                let _ = tx.send(Event::Progress {
                    label: tr.meta.label.clone(),
                    fraction: ((tr.t_s[last] - bench_t0) / total_s).clamp(0.0, 1.0),
                });
            }
        };
        let mut on_progress = |_: f64| {};
        let mut control =
            RunControl { cancel: &self.cancel, on_samples: &mut on_samples, on_progress: &mut on_progress };
        let run = match kind {
            // A wizard step records as the command line does, each segment to the UI at once.
            Run::Step(from) => {
                // Each recorded segment goes to the UI at once, to be autosaved.
                let mut on_segment = |trace: &Trace, progress: Progress| {
                    let _ = self.tx.send(Event::SegmentDone(Box::new(trace.clone()), progress));
                    notify();
                };
                record_step(self.bench.as_mut(), plan, from, &mut control, &mut on_segment)
            }
            Run::Motion => {
                let run = run_plan_with(self.bench.as_mut(), plan, &mut control, &mut |_| Ok(()));
                let outcome = run.outcome.map_err(|e| e.to_string());
                Ran { traces: run.traces, duration_s: run.duration_s, outcome, resume: None }
            }
        };
        if report_progress {
            let done = (self.bench.clock_s() - bench_t0) / total_s;
            let _ = self.tx.send(Event::Progress { label: plan.name.clone(), fraction: done.clamp(0.0, 1.0) });
        }
        self.send(Event::Position(self.bench.position_display()));
        run
    }
}

/// What [`Thread::run`] runs: a wizard step (recorded, with progress; from the start or from
/// where a stopped run of it stands) or a motion (jog, dither).
#[derive(Debug, Clone, Copy, PartialEq)]
enum Run {
    Step(Option<Progress>),
    Motion,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_live_dither_streams_samples_at_real_time_up_and_down_the_beam() {
        let w = Worker::virtual_bench("table2-ideal", Some(3), Pace::Unpaced, Box::new(|| {})).unwrap();
        w.live.store(true, Ordering::Relaxed);
        let start = Instant::now();
        let (mut samples, mut bench_span, mut q2) = (0usize, (f64::INFINITY, f64::NEG_INFINITY), vec![]);
        while start.elapsed() < Duration::from_secs(3) {
            if let Some(Event::Samples { t_s, q_display, .. }) = w.recv_timeout(Duration::from_millis(100)) {
                samples += t_s.len();
                bench_span = (bench_span.0.min(t_s[0]), bench_span.1.max(*t_s.last().unwrap()));
                q2.push(q_display[1]);
            }
        }
        w.live.store(false, Ordering::Relaxed);
        let span = bench_span.1 - bench_span.0;
        // Paced at real time: about as much bench time as wall time (less the start-up).
        assert!(span > 1.0 && span < 3.2, "bench time {span} s in 3 s");
        assert!(samples > 10_000, "{samples} samples");
        let (lo, hi) = q2.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |a, &v| (a.0.min(v), a.1.max(v)));
        assert!(hi - lo > 1.5 && hi - lo < 2.1 + 1e-9, "q2 range {lo}..{hi}");
        assert!(lo >= -1e-9, "starts at 0 and goes up first: {lo}");
    }
}
