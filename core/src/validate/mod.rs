//! Validation motions through the IGM with a given set of extrinsics: a circle in the lamella plane and
//! rotations about the fiber's transverse axes and the optical axis with P_r fixed. Owns their plans and figures of merit.
//!
//! Figure of merit: the peak-to-peak variation of the cavity length L along the beam during the
//! motion, as implied by the fringes. The fringe phase follows `|L|·cos γ` (see
//! [`crate::measure`]); a rotation about P_r keeps L but changes γ, so the measured
//! phase-equivalent change is corrected by the model's tilt term (phase-equivalent gap − |L|) before the
//! peak-to-peak is taken. With perfect extrinsics the figure is the noise.

pub mod before_after;
pub mod contrast;
pub mod evidence;
pub mod forecast;
pub mod path_watch;
pub mod smooth;
pub mod stops;

pub use stops::{StopSettings, ABSOLUTE_GAP, CONTRAST_DITHER, ENVELOPE_DITHER};

use crate::bench::{run_plan, Bench, RunControl};
use crate::measure::{self, Measurement};
use crate::model::effects::Backlash;
use crate::model::extrinsics::Extrinsics;
use crate::model::kinematics::{IgmError, LimitViolation};
use crate::model::phase::PhaseModel;
use crate::plan::Plan;
use crate::trace::{ExtraColumn, Trace};
use nalgebra::{Isometry3, Translation3, Unit, UnitQuaternion, Vector3};
use serde::Serialize;
use std::sync::atomic::AtomicBool;
use thiserror::Error;

/// The validation motions of the paper.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum ValidationMotion {
    /// A circle of radius 100 µm in the lamella plane.
    Circle,
    /// A rotation of 6° (−3°..+3°) about the fiber's X axis through P_r.
    RotationXf,
    /// A rotation of 6° about the fiber's other transverse axis (Z_f here, the paper's Y_f) through P_r.
    RotationZf,
    /// A rotation of 45.5° about the optical axis through P_r.
    RotationOpticalAxis,
}

impl ValidationMotion {
    /// All four.
    pub const ALL: [ValidationMotion; 4] =
        [Self::Circle, Self::RotationXf, Self::RotationZf, Self::RotationOpticalAxis];

    /// Short name.
    pub fn name(self) -> &'static str {
        match self {
            Self::Circle => "circle r = 100 µm in the lamella plane",
            Self::RotationXf => "rotation 6° about X_f through P_r",
            Self::RotationZf => "rotation 6° about Z_f (paper: Y_f) through P_r",
            Self::RotationOpticalAxis => "rotation 45.5° about the optical axis through P_r",
        }
    }

    /// The target a validation must meet (nm): 10 for the circle, 20 for the rotations.
    pub fn target_nm(self) -> f64 {
        forecast::target_nm(self)
    }

    /// The paper's reported figure after calibration (nm), for comparison.
    pub fn paper_after_nm(self) -> f64 {
        match self {
            Self::Circle => 390.0,
            Self::RotationXf | Self::RotationZf => 1560.0,
            Self::RotationOpticalAxis => 858.0,
        }
    }
}

/// Why a validation motion cannot be planned or measured.
#[derive(Debug, Error)]
pub enum ValidationError {
    /// A waypoint has no IGM solution.
    #[error("{motion}: waypoint {waypoint}: {source}")]
    Igm {
        /// The motion.
        motion: &'static str,
        /// Index of the waypoint.
        waypoint: usize,
        /// Why.
        source: IgmError,
    },
    /// A waypoint is out of the joint limits (checked before anything moves).
    #[error("{motion}: waypoint {waypoint}: {source}")]
    Limits {
        /// The motion.
        motion: &'static str,
        /// Index of the waypoint.
        waypoint: usize,
        /// The violation.
        source: LimitViolation,
    },
    /// The motion failed on the bench.
    #[error("{motion}: {problem}")]
    Run {
        /// The motion.
        motion: &'static str,
        /// What happened.
        problem: String,
    },
}

impl ValidationMotion {
    /// Waypoints a validation plans this motion with (the motion is linear in the joints
    /// between them).
    pub fn waypoint_count(self) -> usize {
        match self {
            ValidationMotion::Circle => 72,
            ValidationMotion::RotationOpticalAxis => 46,
            _ => 24,
        }
    }
}

/// Waypoints (µm, °) of a validation motion planned with `extrinsics` from the pose `start` (µm, °).
pub fn waypoints(
    model: &PhaseModel,
    extrinsics: &Extrinsics,
    motion: ValidationMotion,
    start: [f64; 6],
    count: usize,
) -> Result<Vec<[f64; 6]>, ValidationError> {
    waypoints_shifted(model, extrinsics, motion, start, count, &[])
}

/// [`waypoints`] with the tool moved along the fiber's axis by `axial_um[k]` (µm, in the
/// direction that lengthens the cavity) at waypoint `k`: the drift compensation of
/// [`run_validation_planned`]. Missing values are zero.
pub fn waypoints_shifted(
    model: &PhaseModel,
    extrinsics: &Extrinsics,
    motion: ValidationMotion,
    start: [f64; 6],
    count: usize,
    axial_um: &[f64],
) -> Result<Vec<[f64; 6]>, ValidationError> {
    let chain = &model.chain;
    let desc = chain.description();
    let q0 = desc.q_from_display(&start);
    let wte0 = chain.end_effector(&q0);
    let ett = extrinsics.ee_to_tool();
    let wtt0 = wte0 * ett;
    let cavity =
        extrinsics.cavity(&wte0).map_err(|e| ValidationError::Run { motion: motion.name(), problem: e.to_string() })?;
    let p_r = cavity.reflection_point_world_um;
    let fiber = extrinsics.world_to_fiber().rotation;
    // The direction a move of the tool lengthens the cavity along the beam.
    let lengthen = {
        let n = cavity.n_f;
        let moved = extrinsics
            .cavity(&(Translation3::from(n.into_inner()) * wte0))
            .map(|c| c.length_um.abs())
            .unwrap_or(cavity.length_um.abs());
        if moved >= cavity.length_um.abs() {
            n
        } else {
            -n
        }
    };
    let about = |axis: Vector3<f64>, angle: f64| -> Isometry3<f64> {
        let r = UnitQuaternion::from_axis_angle(&Unit::new_normalize(axis), angle);
        Translation3::from(p_r.coords)
            * Isometry3::from_parts(Translation3::identity(), r)
            * Translation3::from(-p_r.coords)
    };
    let mut out = Vec::with_capacity(count + 1);
    let mut q_ref = q0.clone();
    for k in 0..=count {
        let s = k as f64 / count as f64;
        let wtt = match motion {
            ValidationMotion::Circle => {
                let a = s * 2.0 * std::f64::consts::PI;
                wtt0 * Translation3::new(100.0 * a.cos(), 100.0 * a.sin(), 0.0)
            }
            ValidationMotion::RotationXf => about(fiber * Vector3::x(), (-3.0 + 6.0 * s).to_radians()) * wtt0,
            ValidationMotion::RotationZf => about(fiber * Vector3::z(), (-3.0 + 6.0 * s).to_radians()) * wtt0,
            ValidationMotion::RotationOpticalAxis => about(cavity.n_f.into_inner(), (45.5 * s).to_radians()) * wtt0,
        };
        let wtt = match axial_um.get(k) {
            Some(&a) if a != 0.0 => Translation3::from(lengthen.into_inner() * a) * wtt,
            _ => wtt,
        };
        let wte = wtt * ett.inverse();
        let q = chain.igm(&wte, &q_ref).map_err(|source| match source {
            IgmError::OutOfLimits(v) => ValidationError::Limits { motion: motion.name(), waypoint: k, source: v },
            source => ValidationError::Igm { motion: motion.name(), waypoint: k, source },
        })?;
        chain.check_limits(&q).map_err(|source| ValidationError::Limits {
            motion: motion.name(),
            waypoint: k,
            source,
        })?;
        let qd = desc.q_to_display(&q);
        out.push(std::array::from_fn(|i| qd[i]));
        q_ref = q;
    }
    Ok(out)
}

/// The plan of a validation motion: an unrecorded move to the first waypoint, a recorded axial
/// dither of 1 µm out and back (the fringe envelope), then recorded moves through the waypoints,
/// with no stop ([`stops::plan_reaching`] says how stages with play are handled). Returns the
/// plan and the stages' state at its first recorded sample (for [`modelled_real_joints`]).
pub fn plan_with_play(motion: ValidationMotion, waypoints: &[[f64; 6]], play: &[f64; 6]) -> (Plan, Backlash) {
    let (plan, state, _) = plan_through(&format!("validation: {}", motion.name()), motion.name(), waypoints, play);
    (plan, state)
}

/// The plan of [`plan_with_play`] for any path through `waypoints` (µm, °): named `name`, its
/// moves after the dither labelled `label`; with the stages' state at its first recorded sample
/// and the index of the segment that reaches each wanted pose (the dither's far end, its return
/// to the first waypoint, then every later waypoint).
pub fn plan_through(name: &str, label: &str, waypoints: &[[f64; 6]], play: &[f64; 6]) -> (Plan, Backlash, Vec<usize>) {
    let p = stops::plan_reaching(name, label, waypoints, play, &[], None);
    (p.plan, p.state, p.reaching)
}

/// What a validation plan compensates from the extended model: the stages' play (reversal
/// errors, display units) and the gap's drift in time. Default: nothing.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Compensation {
    /// Play of each stage (display units, µm or °): [`crate::model::effects::reversal_play`].
    pub play: [f64; 6],
    /// The effects that drift the gap in time ([`crate::model::effects::Effect::ThermalDrift`]).
    pub drift: Vec<crate::model::effects::Effect>,
}

impl Compensation {
    /// The compensation a list of effects calls for, on `robot`.
    pub fn of_effects(
        effects: &[crate::model::effects::Effect],
        robot: &crate::model::robot::RobotDescription,
    ) -> Self {
        Compensation {
            play: crate::model::effects::reversal_play(effects, robot),
            drift: effects
                .iter()
                .filter(|e| matches!(e, crate::model::effects::Effect::ThermalDrift { .. }))
                .cloned()
                .collect(),
        }
    }

    /// The gap's drift (nm) at bench time `t_s` (s).
    fn drift_nm(&self, t_s: f64) -> f64 {
        self.drift.iter().map(|e| e.gap_change_nm(t_s, 0.0)).sum()
    }
}

/// The trace with its joints replaced by where stages of play `play` (display units) were,
/// from their state `state` at its first sample, following its recorded commands
/// ([`Backlash`]): what the analysis model's motion hint, fringe shape and tilt correction need.
pub fn modelled_real_joints(trace: &Trace, play: &[f64; 6], mut state: Backlash) -> Trace {
    follow_real_joints(trace, play, &mut state)
}

/// [`modelled_real_joints`] from `state`, left at the trace's last sample.
fn follow_real_joints(trace: &Trace, play: &[f64; 6], state: &mut Backlash) -> Trace {
    let mut out = trace.clone();
    for i in 0..trace.len() {
        let q = trace.joints_display(i);
        state.follow(&q, play);
        let real = state.real();
        out.q1_um[i] = real[0];
        out.q2_um[i] = real[1];
        out.q3_um[i] = real[2];
        out.q4_deg[i] = real[3];
        out.q5_deg[i] = real[4];
        out.q6_deg[i] = real[5];
    }
    out
}

/// One validation result.
#[derive(Debug, Clone, Serialize)]
pub struct ValidationFigure {
    /// The motion.
    pub motion: ValidationMotion,
    /// Peak-to-peak variation of L implied by the fringes (nm).
    pub peak_to_peak_nm: f64,
    /// The recorded trace (all waypoints joined).
    #[serde(skip)]
    pub trace: Trace,
    /// L variation per sample (nm), for plots.
    #[serde(skip)]
    pub variation_nm: Vec<f64>,
    /// The first sample of the motion proper in `trace` (after the envelope dither).
    #[serde(skip)]
    pub motion_start: usize,
    /// The tracked phase-equivalent gap change from the trace's first sample (nm), per sample:
    /// what the fringes measured, before the tilt correction.
    #[serde(skip)]
    pub tracked_dl_nm: Vec<f64>,
    /// Its σ (nm), per sample.
    #[serde(skip)]
    pub tracked_sigma_nm: Vec<f64>,
    /// Whether the fringes were tracked with the analysis model's fringe shape; false when it
    /// could not be tracked on and the profile estimated from the data was used (the reason in
    /// `shape_fallback`).
    pub tracked_with_model_shape: bool,
    /// Why the model's fringe shape was not used.
    pub shape_fallback: Option<String>,
    /// The figures that do not use the extrinsics under test, and the verdict.
    pub evidence: evidence::Evidence,
}

impl ValidationFigure {
    /// A line for a report when the fringes were not tracked with the model's fringe shape.
    pub fn tracking_note(&self) -> Option<String> {
        self.shape_fallback.as_ref().map(|why| {
            format!("{}: tracked with the fringe profile estimated from the data ({why})", self.motion.name())
        })
    }
}

/// Why a validation pair's figures are missing or were measured the less precise way: the
/// first error, else the first tracking note.
pub fn pair_note(
    a: &Result<ValidationFigure, ValidationError>,
    b: &Result<ValidationFigure, ValidationError>,
) -> Option<String> {
    match (a, b) {
        (Err(e), _) | (_, Err(e)) => Some(e.to_string()),
        (Ok(a), Ok(b)) => a.tracking_note().or_else(|| b.tracking_note()),
    }
}

/// Join the recorded traces of a plan run into one.
pub(crate) fn join(traces: &[Trace]) -> Option<Trace> {
    let first = traces.first()?;
    let mut out = Trace::with_capacity(first.meta.clone(), traces.iter().map(Trace::len).sum());
    out.extra = first.extra.iter().map(|c| ExtraColumn { name: c.name.clone(), values: Vec::new() }).collect();
    for t in traces {
        out.append_later(t);
    }
    Some(out)
}

/// Plan with `planned_with`, run on the bench from `start`, and measure with `analysis` (the
/// best model available: it sets the motion hint and the tilt correction).
pub fn run_validation(
    bench: &mut dyn Bench,
    analysis: &PhaseModel,
    planned_with: &Extrinsics,
    motion: ValidationMotion,
    start: [f64; 6],
) -> Result<ValidationFigure, ValidationError> {
    run_validation_planned(bench, analysis, planned_with, analysis, motion, start, &Compensation::default())
}

/// [`run_validation`] with the motion planned through the IGM of `planning` (its robot chain:
/// e.g. the nominal robot, or the robot with the effects a diagnosis added) and measured with
/// `analysis`, compensating what `compensation` says (default: nothing), without stops
/// ([`StopSettings::NONE`]). Stages with play: the commands compensate it ([`plan_with_play`])
/// and the analysis models the stages' real joints along the trace ([`modelled_real_joints`]).
/// A drifting gap: each waypoint of the motion is moved along the beam by the drift expected
/// between the motion's start and the time the bench reaches it ([`Plan::expand`] on the
/// bench's limits), so that the gap stands still; the figure measures what the robot and the
/// drift leave together.
pub fn run_validation_planned(
    bench: &mut dyn Bench,
    planning: &PhaseModel,
    planned_with: &Extrinsics,
    analysis: &PhaseModel,
    motion: ValidationMotion,
    start: [f64; 6],
    compensation: &Compensation,
) -> Result<ValidationFigure, ValidationError> {
    let cancel = AtomicBool::new(false);
    record_validation(bench, planning, planned_with, motion, start, compensation, &StopSettings::NONE, &cancel)?
        .measure(analysis)
}

/// A validation motion recorded on a bench, not yet measured ([`RecordedValidation::measure`]):
/// the bench runs one motion after another, the fringe analyses of several can then run at once.
#[derive(Debug, Clone)]
pub struct RecordedValidation {
    motion: ValidationMotion,
    /// The recorded trace (the envelope dither and the motion's waypoints joined).
    trace: Trace,
    /// The trace with the stages' modelled real joints, for stages with play.
    real: Option<Trace>,
    /// The first sample of the motion proper (after the envelope dither).
    dither_end: usize,
    /// The start, then each stop: their dithers and sweeps.
    poses: Vec<evidence::PoseRecord>,
    /// Per run made, the departure from the path its start spreads imply (nm); this run is the
    /// one that departed least ([`path_watch`]).
    departures_nm: Vec<f64>,
}

/// The bench half of [`run_validation_planned`]: plan with `planned_with` through the IGM of
/// `planning`, compensate what `compensation` says, and run on the bench from `start`, stopping
/// where `stops` says. The plan runs piece by piece: a sweep the bench refuses or fails costs
/// that pose's absolute gap (recorded as its problem), not the motion. Setting `cancel` stops it
/// (the bench checks it as it runs): an error naming the motion, whose unfinished recording
/// proves nothing.
///
/// A run whose controllers started their moves so far apart that the lamella left its path by
/// more than [`path_watch::MAX_PATH_DEPARTURE_NM`] is made again, up to
/// [`path_watch::MAX_RUNS`] runs; the run that departed least is kept.
#[allow(clippy::too_many_arguments)]
pub fn record_validation(
    bench: &mut dyn Bench,
    planning: &PhaseModel,
    planned_with: &Extrinsics,
    motion: ValidationMotion,
    start: [f64; 6],
    compensation: &Compensation,
    stops: &StopSettings,
    cancel: &AtomicBool,
) -> Result<RecordedValidation, ValidationError> {
    let inputs = RecordingInputs { planning, planned_with, motion, start, compensation, stops };
    let run = |bench: &mut dyn Bench| {
        let mut watch = path_watch::PathWatch::new(bench);
        let run = record_once(&mut watch, &inputs, cancel)?;
        Ok::<_, ValidationError>((watch.departure_nm(planning), run))
    };
    let mut kept = run(bench)?;
    let mut departures_nm = vec![kept.0];
    while kept.0 > path_watch::MAX_PATH_DEPARTURE_NM && departures_nm.len() < path_watch::MAX_RUNS {
        let last = departures_nm[departures_nm.len() - 1];
        tracing::info!(
            motion = motion.name(),
            departure_nm = last,
            "the controllers started the moves apart: |L| left its path by up to {last:.1} nm; run again"
        );
        let again = run(bench)?;
        departures_nm.push(again.0);
        if again.0 < kept.0 {
            kept = again;
        }
    }
    Ok(RecordedValidation { departures_nm, ..kept.1 })
}

/// What every run of one [`record_validation`] records from: its arguments but the bench.
struct RecordingInputs<'a> {
    planning: &'a PhaseModel,
    planned_with: &'a Extrinsics,
    motion: ValidationMotion,
    start: [f64; 6],
    compensation: &'a Compensation,
    stops: &'a StopSettings,
}

/// One run of [`record_validation`].
fn record_once(
    bench: &mut dyn Bench,
    inputs: &RecordingInputs,
    cancel: &AtomicBool,
) -> Result<RecordedValidation, ValidationError> {
    let RecordingInputs { planning, planned_with, motion, start, compensation, stops } = *inputs;
    let count = motion.waypoint_count();
    let play = &compensation.play;
    let stop_at = stops::stop_waypoints(motion, count, stops.stops);
    let sweep_nm = (stops.sweeps && bench.tunable_laser()).then(|| bench.wavelength_nm());
    let mut w = waypoints(planning, planned_with, motion, start, count)?;
    let plan = |w: &[[f64; 6]]| {
        let mut p =
            stops::plan_reaching(&format!("validation: {}", motion.name()), motion.name(), w, play, &stop_at, sweep_nm);
        stops::run_through(&mut p.plan.segments, motion.name());
        p
    };
    let mut p = plan(&w);
    if !compensation.drift.is_empty() {
        let run_error = |e: String| ValidationError::Run { motion: motion.name(), problem: e };
        let timed = p
            .plan
            .expand(bench.robot(), bench.position_display(), bench.motion_limits())
            .map_err(|e| run_error(e.to_string()))?;
        let t0 = bench.clock_s();
        // reaching[1] is the return from the dither: the motion starts there.
        let at = |k: usize| t0 + timed[p.reaching[k]].end_s();
        let start_nm = compensation.drift_nm(at(1));
        let axial_um: Vec<f64> = (0..=count).map(|k| -(compensation.drift_nm(at(k + 1)) - start_nm) * 1e-3).collect();
        w = waypoints_shifted(planning, planned_with, motion, start, count, &axial_um)?;
        p = plan(&w);
    }
    let (traces, refused) = run_pieces(bench, &p.plan, motion, cancel)?;
    // Stages with play: their real joints follow every recorded command in order, the stops'
    // dithers included.
    let real = play.iter().any(|w| *w != 0.0).then(|| {
        let mut state = p.state;
        let real: Vec<Trace> = traces.iter().map(|t| follow_real_joints(t, play, &mut state)).collect();
        sort_recorded(motion, real, refused.clone(), stop_at.len()).map(|r| r.0)
    });
    let (trace, dither_end, poses) = sort_recorded(motion, traces, refused, stop_at.len())?;
    let real = real.transpose()?;
    Ok(RecordedValidation { motion, trace, real, dither_end, poses, departures_nm: Vec::new() })
}

/// Every trace a motion recorded, and each sweep that failed with why (its label, the problem).
type Pieces = (Vec<Trace>, Vec<(String, String)>);

/// Run `plan` in pieces split at its sweeps: every trace recorded, and each sweep that failed
/// with why (its label, the problem); any other failure is the motion's.
fn run_pieces(
    bench: &mut dyn Bench,
    plan: &Plan,
    motion: ValidationMotion,
    cancel: &AtomicBool,
) -> Result<Pieces, ValidationError> {
    let mut traces = Vec::new();
    let mut refused = Vec::new();
    let mut piece: Vec<crate::plan::Segment> = Vec::new();
    let mut pieces = Vec::new();
    for seg in &plan.segments {
        if matches!(seg, crate::plan::Segment::Sweep { .. }) {
            pieces.push(std::mem::take(&mut piece));
            pieces.push(vec![seg.clone()]);
        } else {
            piece.push(seg.clone());
        }
    }
    pieces.push(piece);
    for segments in pieces.into_iter().filter(|p| !p.is_empty()) {
        let sweep = matches!(segments[0], crate::plan::Segment::Sweep { .. });
        let label = segments[0].label().to_string();
        let part = Plan { name: plan.name.clone(), description: String::new(), segments };
        let mut control = RunControl { cancel, on_samples: &mut |_, _| {}, on_progress: &mut |_| {} };
        let run = run_plan(bench, &part, &mut control);
        match run.outcome {
            Ok(()) => traces.extend(run.traces),
            Err(e) if sweep => refused.push((label, e.to_string())),
            Err(e) => return Err(ValidationError::Run { motion: motion.name(), problem: e.to_string() }),
        }
    }
    Ok((traces, refused))
}

/// The number after a stop's label (`contrast dither 2`, `absolute gap 0`).
fn pose_number(label: &str, prefix: &str) -> Option<usize> {
    label.strip_prefix(prefix)?.trim().parse().ok()
}

/// The motion's trace (envelope dither and motion joined), where the motion starts, and each
/// pose's dither and sweep with its sample in that trace.
fn sort_recorded(
    motion: ValidationMotion,
    traces: Vec<Trace>,
    refused: Vec<(String, String)>,
    stops: usize,
) -> Result<(Trace, usize, Vec<evidence::PoseRecord>), ValidationError> {
    let mut poses: Vec<evidence::PoseRecord> =
        (0..=stops).map(|_| evidence::PoseRecord { sample: 0, dither: None, sweep: None }).collect();
    let mut along: Vec<Trace> = Vec::new();
    let mut dithers: Vec<Vec<Trace>> = vec![Vec::new(); stops + 1];
    let (mut length, mut dither_end) = (0usize, 0usize);
    let mut last_t: Option<f64> = None;
    for t in traces {
        let label = t.meta.label.clone();
        if label == ENVELOPE_DITHER || label == motion.name() {
            // Counted as [`join`] keeps them: a segment's samples at or before the last one kept
            // (the shared boundary) are dropped.
            let from = last_t.map_or(0, |last| t.t_s.partition_point(|&x| x <= last));
            length += t.len() - from;
            last_t = t.t_s.last().copied().or(last_t);
            if label == ENVELOPE_DITHER {
                dither_end = length;
            }
            along.push(t);
        } else if let Some(k) = pose_number(&label, CONTRAST_DITHER).filter(|k| *k <= stops) {
            poses[k].sample = length.saturating_sub(1);
            dithers[k].push(t);
        } else if let Some(k) = pose_number(&label, ABSOLUTE_GAP).filter(|k| *k <= stops) {
            poses[k].sample = if k == 0 { dither_end } else { length.saturating_sub(1) };
            poses[k].sweep = Some(Ok(t));
        }
    }
    for (label, problem) in refused {
        if let Some(k) = pose_number(&label, ABSOLUTE_GAP).filter(|k| *k <= stops) {
            poses[k].sweep = Some(Err(problem));
        }
    }
    for (pose, d) in poses.iter_mut().zip(dithers) {
        pose.dither = join(&d);
    }
    poses[0].sample = dither_end;
    let trace =
        join(&along).ok_or(ValidationError::Run { motion: motion.name(), problem: "nothing recorded".into() })?;
    Ok((trace, dither_end, poses))
}

impl RecordedValidation {
    /// The analysis half of [`run_validation_planned`]: the figure of merit measured with
    /// `analysis` (the best model available: it sets the motion hint and the tilt correction).
    pub fn measure(self, analysis: &PhaseModel) -> Result<ValidationFigure, ValidationError> {
        let RecordedValidation { motion, trace, real, dither_end, poses, departures_nm } = self;
        let analysed = real.as_ref().unwrap_or(&trace);
        // A motion whose model gap moves less than two fringes after the dither (the circle, the
        // rotation about the optical axis) is tracked with the phase free of the hint in time: its
        // own fringes do not pin the phase, and the default walk pulls it toward the plan
        // ([`measure::AnalyseOptions::free_phase_after`]). The rotations about X_f and Z_f, whose
        // gap moves by 3-6 fringes, track closer to the truth with the default: on the hidden-pivot
        // diagnosis's model (`validation_truth` example, tracked with the data's harmonic profile)
        // 12.3 and 9.4 nm at worst, 14.4 and 11.5 nm free; the circle 4.1 nm default, 0.5 nm free;
        // the optical axis 1.3 and 0.8 nm. With the model's fringe shape (below) the circle still
        // needs it: 4.2 nm off the truth with the default walk, 0.1 nm free.
        //
        // Every validation motion is tracked with the analysis model's fringe shape: that model is
        // a fitted one (the calibrated or the diagnosed model), which is what the shaped tracker
        // needs, and the rotations' tilt changes the fringe's contrast about fivefold, which the
        // harmonic profile estimated from the data follows late. On the `validation_truth`
        // example the rotations about X_f and Z_f tracked 0.2 and 0.3 nm off the truth at worst
        // (12.3 and 9.4 nm with the estimated profile); the circle 0.1 nm, the optical axis 0.0 nm
        // (test `validation_rotations_track_their_gap_within_a_nanometre`). A trace the model's
        // shape cannot be tracked on falls back to the estimated profile (`analyse_with`).
        let options =
            measure::AnalyseOptions { free_phase_after: Some(dither_end), shaped: true, ..Default::default() };
        let Measurement::Motion(m) = measure::analyse_with(analysed, analysis, &options)
            .map_err(|e| ValidationError::Run { motion: motion.name(), problem: e.to_string() })?
        else {
            return Err(ValidationError::Run { motion: motion.name(), problem: "not a motion trace".into() });
        };
        // Tilt correction: the model's phase-equivalent gap (the hint, relative to the first
        // sample) minus the geometric |L| (nm).
        let lengths = analysis
            .gap_um_along(analysed)
            .map_err(|problem| ValidationError::Run { motion: motion.name(), problem })?;
        let tilt_term = |i: usize| m.hint_nm[i] - lengths[i] * 1e3;
        let t0 = tilt_term(dither_end);
        let d0 = m.track.dl_nm[dither_end];
        let variation: Vec<f64> =
            (dither_end..trace.len()).map(|i| m.track.dl_nm[i] - d0 - (tilt_term(i) - t0)).collect();
        let (lo, hi) = variation.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| (a.min(v), b.max(v)));
        let mut evidence = evidence::assess(&evidence::Inputs {
            motion,
            trace: analysed,
            motion_start: dither_end,
            tracked_dl_nm: &m.track.dl_nm,
            tracked_sigma_nm: &m.track.sigma_dl_nm,
            tracked_nm: hi - lo,
            variation_nm: &variation,
            poses: &poses,
            analysis,
        });
        evidence.note_runs(departures_nm);
        Ok(ValidationFigure {
            motion,
            evidence,
            peak_to_peak_nm: hi - lo,
            trace,
            variation_nm: variation,
            motion_start: dither_end,
            tracked_dl_nm: m.track.dl_nm,
            tracked_sigma_nm: m.track.sigma_dl_nm,
            tracked_with_model_shape: m.shaped,
            shape_fallback: m.shaped_fallback,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Segments that share their boundary sample, as a bench records them: each stop's pose
    /// sample is the joined trace's sample where the stop was reached (its time and joints), not
    /// one counted with the shared samples twice.
    #[test]
    fn a_stops_sample_is_where_the_joined_trace_reached_it() {
        let segment = |label: &str, t0: f64, q0: f64| {
            let meta = crate::trace::TraceMeta { label: label.into(), ..Default::default() };
            let mut t = Trace::new(meta);
            for k in 0..=10 {
                let q = q0 + k as f64;
                t.push_sample(t0 + 0.1 * k as f64, [q, 0.0, 0.0, 0.0, 0.0, 0.0], 1560.0, 0.5);
            }
            t
        };
        let motion = ValidationMotion::Circle;
        let name = motion.name();
        let mut traces = vec![segment(ENVELOPE_DITHER, 0.0, 0.0)];
        for (k, t0) in [1.0, 2.0, 3.0, 4.0].iter().enumerate() {
            traces.push(segment(name, *t0, 10.0 * (k + 1) as f64));
            if k == 1 || k == 3 {
                traces.push(segment(&format!("{CONTRAST_DITHER} {}", k / 2 + 1), 10.0 + *t0, 0.0));
            }
        }
        let (trace, start, poses) = sort_recorded(motion, traces, vec![], 2).unwrap();
        assert_eq!(trace.len(), 51, "five segments of eleven samples sharing four");
        assert_eq!(start, 11);
        for (k, end_t) in [(1, 3.0), (2, 5.0)] {
            let i = poses[k].sample;
            assert!(i < trace.len(), "pose {k} at {i} of {}", trace.len());
            assert!((trace.t_s[i] - end_t).abs() < 1e-9, "pose {k} at t = {}", trace.t_s[i]);
        }
    }
    use crate::bench::{BenchPreset, VirtualBench};
    use crate::model::robot::RobotDescription;
    use crate::plan::Segment;

    fn figure(planned_with: Extrinsics, analysis_with: Extrinsics, motion: ValidationMotion) -> f64 {
        let preset = BenchPreset::resolve("table2-ideal").unwrap();
        let mut bench = VirtualBench::new(&preset, Some(2)).unwrap();
        let model =
            PhaseModel::new(RobotDescription::femto_6dof(), analysis_with, preset.optics, &preset.ambient, 1560.0)
                .unwrap();
        run_validation(&mut bench, &model, &planned_with, motion, [0.0; 6]).unwrap().peak_to_peak_nm
    }

    /// A 100 µm circle in the nominal plane gives 3.33 µm peak to peak with Table II tilts.
    #[test]
    fn circle_in_the_nominal_plane_varies_by_3_33_um() {
        let p = figure(Extrinsics::nominal_design(), Extrinsics::table2(), ValidationMotion::Circle);
        assert!((p - 3330.0).abs() < 40.0, "{p} nm");
    }

    /// With perfect extrinsics every motion is flat to the fringe-tracking error, under 2 nm
    /// (paper: 390 nm, 1.56 µm, 0.858 µm). The rotations' tilt sweep changes the fringe's
    /// contrast about fivefold: tracked with a profile estimated from the data they read up to
    /// 20 nm, with the model's fringe shape 0.18 and 0.25 nm (seed 2).
    #[test]
    fn with_the_true_extrinsics_validation_motions_are_flat_to_the_tracking_error() {
        let t = Extrinsics::table2();
        for m in ValidationMotion::ALL {
            let p = figure(t, t, m);
            eprintln!("{}: {p:.2} nm (paper after calibration: {} nm)", m.name(), m.paper_after_nm());
            assert!(p < 2.0, "{}: {p} nm", m.name());
        }
    }

    /// A validation motion measures how far the real gap strays from the plan of the model it
    /// was planned with, which expects it to stand still. Planned with the lamella's tilt off
    /// by 0.0025° (44 µrad), the 100 µm circle's real gap rises and falls by about 8 nm: less
    /// than a fringe moves the intensity, and no fringe extremum is crossed. The tracked gap
    /// along it against the truth (the bench's own extrinsics at the recorded joints) stays
    /// within 1.5 nm at 12 points along it: a small bump at its end must not be taken for a
    /// fringe maximum, nor the phase walk shared with the envelope.
    #[test]
    fn a_validation_circle_tracks_its_small_gap_change() {
        let preset = BenchPreset::resolve("table2-ideal").unwrap();
        let truth = PhaseModel::of_preset(&preset, preset.truth).unwrap();
        for (seed, d_beta_deg) in [(2, 0.0025), (3, -0.004)] {
            let planned = Extrinsics { beta_et_deg: preset.truth.beta_et_deg + d_beta_deg, ..preset.truth };
            let model = PhaseModel { extrinsics: planned, ..truth.clone() };
            let mut bench = VirtualBench::new(&preset, Some(seed)).unwrap();
            let f = run_validation(&mut bench, &model, &planned, ValidationMotion::Circle, [0.0; 6]).unwrap();
            let real = truth.hint_nm(&f.trace, f.trace.wavelength_nm[0]).unwrap();
            let (s, n) = (f.motion_start, f.trace.len());
            let (mut lo, mut hi, mut worst) = (f64::INFINITY, f64::NEG_INFINITY, 0.0f64);
            for k in 0..=12 {
                let i = s + k * (n - 1 - s) / 12;
                let (tracked, want) = (f.tracked_dl_nm[i] - f.tracked_dl_nm[s], real[i] - real[s]);
                eprintln!("seed {seed}: sample {i}: tracked {tracked:7.2} nm, real {want:7.2} nm");
                (lo, hi) = (lo.min(want), hi.max(want));
                worst = worst.max((tracked - want).abs());
            }
            eprintln!("seed {seed}: figure {:.2} nm, real gap {:.2} nm peak to peak", f.peak_to_peak_nm, hi - lo);
            assert!(hi - lo > 5.0, "the real gap must move: {} nm", hi - lo);
            assert!(worst < 1.5, "seed {seed}: tracked {worst:.2} nm off the real gap");
            assert!((f.peak_to_peak_nm - (hi - lo)).abs() < 2.0, "seed {seed}: {} nm", f.peak_to_peak_nm);
        }
    }

    /// The rotations about the fiber's transverse axes move the phase-equivalent gap by 3-6
    /// fringes (the tilt term) while the real |L| should stand still: the validation figure is
    /// the small difference of two large ones. Tracked with a harmonic profile estimated from
    /// the data (the default tracker), whose envelope lags the tilt's fivefold change of the
    /// fringe's contrast, the tracked gap is 9-12 nm off the truth at worst and the
    /// calibration's rotations read 14 nm; tracked with the calibrated model's fringe shape,
    /// under a nanometre. Planned and measured with the lamella's tilt off by +0.0025° (the
    /// calibrated model is never exact): the tracked phase-equivalent gap against the bench's
    /// own at the recorded joints, and the figure against the one perfect tracking would give
    /// (the real gap change less the analysis model's tilt term, which carries the model's
    /// own error: a few nm here, where the real |L| moves by 0.02 nm).
    #[test]
    fn validation_rotations_track_their_gap_within_a_nanometre() {
        let preset = BenchPreset::resolve("table2-ideal").unwrap();
        let truth = PhaseModel::of_preset(&preset, preset.truth).unwrap();
        let planned = Extrinsics { beta_et_deg: preset.truth.beta_et_deg + 0.0025, ..preset.truth };
        let model = PhaseModel { extrinsics: planned, ..truth.clone() };
        let desc = model.chain.description();
        for motion in [ValidationMotion::RotationXf, ValidationMotion::RotationZf] {
            let mut bench = VirtualBench::new(&preset, Some(4)).unwrap();
            let f = run_validation(&mut bench, &model, &planned, motion, [0.0; 6]).unwrap();
            let wavelength_nm = f.trace.wavelength_nm[0];
            let real = truth.hint_nm(&f.trace, wavelength_nm).unwrap();
            let modelled = model.hint_nm(&f.trace, wavelength_nm).unwrap();
            let l_nm = |i: usize| {
                let q = desc.q_from_display(&f.trace.joints_display(i));
                planned.cavity(&model.chain.end_effector(&q)).unwrap().length_um.abs() * 1e3
            };
            let (s, n) = (f.motion_start, f.trace.len());
            let l_s = l_nm(s);
            let mut worst = 0.0f64;
            let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
            for i in s..n {
                worst = worst.max((f.tracked_dl_nm[i] - f.tracked_dl_nm[s] - (real[i] - real[s])).abs());
                let ideal = real[i] - real[s] - (modelled[i] - modelled[s] - (l_nm(i) - l_s));
                (lo, hi) = (lo.min(ideal), hi.max(ideal));
            }
            eprintln!(
                "{}: tracked at worst {worst:.2} nm off the real phase-equivalent gap; figure {:.2} nm, \
                 {:.2} nm with perfect tracking",
                motion.name(),
                f.peak_to_peak_nm,
                hi - lo
            );
            assert!(f.tracked_with_model_shape, "{:?}", f.shape_fallback);
            assert!(worst < 1.0, "{}: tracked {worst:.2} nm off the real gap", motion.name());
            assert!((f.peak_to_peak_nm - (hi - lo)).abs() < 1.0, "{}: {} nm", motion.name(), f.peak_to_peak_nm);
        }
    }

    /// The commands of a plan for stages with play, followed by stages with that play from
    /// any state (the virtual bench's [`Backlash`]), put the stages in the state the plan
    /// says at its first recorded sample and on every wanted pose; a take-up move leaves them
    /// where they are.
    #[test]
    fn a_plan_with_play_puts_the_stages_on_its_waypoints() {
        let play = [0.0, 0.4, 1.0, 0.02, 0.0, 0.0];
        let waypoints: Vec<[f64; 6]> = (0..=36)
            .map(|k| {
                let a = k as f64 / 36.0 * std::f64::consts::TAU;
                [100.0 * a.cos(), 1.3 * a.sin(), 100.0 * a.sin(), 0.5 * (2.0 * a).cos(), 0.0, 0.0]
            })
            .collect();
        let (plan, start) = plan_with_play(ValidationMotion::Circle, &waypoints, &play);
        let mut wanted = vec![waypoints[0]];
        wanted[0][1] += 1.0;
        wanted.extend(waypoints.iter().copied());
        for history in [-5.0, 5.0] {
            let mut stages = Backlash::default();
            stages.follow(&[history; 6], &play);
            let (mut k, mut take_ups) = (0, 0);
            for seg in &plan.segments {
                let Segment::Move { to, record, .. } = seg else { panic!("moves only") };
                let before = stages;
                stages.follow(&to.resolve(stages.command), &play);
                if !*record {
                    continue;
                }
                if k == 0 && take_ups == 0 {
                    for j in 0..6 {
                        assert!((before.offset[j] - start.offset[j]).abs() < 1e-12, "history {history}: joint {j}");
                        assert!((before.command[j] - start.command[j]).abs() < 1e-12, "history {history}: joint {j}");
                    }
                }
                let moved = (0..6).any(|j| (stages.real()[j] - before.real()[j]).abs() > 1e-12);
                if !moved {
                    take_ups += 1;
                    continue;
                }
                for (j, (real, want)) in stages.real().iter().zip(&wanted[k]).enumerate() {
                    assert!((real - want).abs() < 1e-9, "history {history}: pose {k} joint {j}");
                }
                k += 1;
            }
            assert_eq!(k, wanted.len(), "every wanted pose reached");
            // q2 reverses at the dither's end and twice along the circle, q3 and q4 twice or
            // more: take-ups were needed.
            assert!(take_ups >= 4, "{take_ups} take-ups");
        }
    }

    /// The figures of `motions` on table2-ideal with `effect` hidden (true extrinsics, seed 3),
    /// planned without compensating it and with ([`Compensation::of_effects`]).
    fn without_and_with(effect: crate::model::effects::Effect, motions: &[ValidationMotion]) -> Vec<(f64, f64)> {
        let mut preset = BenchPreset::resolve("table2-ideal").unwrap();
        preset.effects = vec![effect];
        let model = PhaseModel::of_preset(&preset, preset.truth).unwrap();
        let compensation = Compensation::of_effects(&preset.effects, model.chain.description());
        assert_ne!(compensation, Compensation::default());
        let t = preset.truth;
        motions
            .iter()
            .map(|&motion| {
                let mut bench = VirtualBench::new(&preset, Some(3)).unwrap();
                let without = run_validation(&mut bench, &model, &t, motion, [0.0; 6]).unwrap().peak_to_peak_nm;
                let with = run_validation_planned(&mut bench, &model, &t, &model, motion, [0.0; 6], &compensation)
                    .unwrap()
                    .peak_to_peak_nm;
                eprintln!("{}: {without:.2} nm without compensating, {with:.2} nm with", motion.name());
                (without, with)
            })
            .collect()
    }

    /// A hidden 1 µm reversal error on q3 (table2-ideal, true extrinsics): the 100 µm circle
    /// and the rotation about Z_f planned without knowing the play stray by over 10 nm (the
    /// stages lag behind their commands after each reversal); planned with the play, the
    /// commands compensate it and the figures fall to the tracking floor (16.24 → 0.01 nm,
    /// 17.80 → 0.21 nm).
    #[test]
    fn validation_with_the_play_compensates_a_reversal_error() {
        let reversal = crate::model::effects::Effect::ReversalError { joint: "q3".into(), step: 1.0 };
        for (without, with) in without_and_with(reversal, &[ValidationMotion::Circle, ValidationMotion::RotationZf]) {
            assert!(without > 10.0 && with < 2.0, "{without} → {with} nm");
        }
    }

    /// A hidden thermal drift of 0.5 nm/s (table2-ideal, true extrinsics): the validation
    /// motions, which last tens of seconds, read the drift over their duration; planned with
    /// it, each waypoint moves along the beam by the drift expected when the bench reaches it,
    /// and the figures fall to the tracking floor (circle 8.09 → 0.08 nm, optical axis 14.72 →
    /// 0.29 nm).
    #[test]
    fn validation_with_the_drift_compensates_it() {
        let drift = crate::model::effects::Effect::ThermalDrift { nm_per_s: 0.5, nm_per_s2: 0.0 };
        let motions = [ValidationMotion::Circle, ValidationMotion::RotationOpticalAxis];
        for (without, with) in without_and_with(drift, &motions) {
            assert!(without > 5.0 && with < 2.0, "{without} → {with} nm");
        }
    }

    /// The true model on table2-ideal with a detector 100 times cleaner (1e-5 of the fringe): a
    /// circle planned with it keeps the real gap still, and its figure must say so wherever the
    /// start sits on the fringe (0.0002-0.0003 nm). The start is moved along the beam (q2) to
    /// the phases where a noise floor of 1e-7 of the amplitude stops the tracker on a phase ramp
    /// (32.8, 44.9, 113.3 and 149.1 nm; near a fringe's foot, its top and between).
    #[test]
    fn a_validation_on_a_clean_signal_reads_a_still_gap_at_any_start_phase() {
        let mut preset = BenchPreset::resolve("table2-ideal").unwrap().without_noise();
        preset.detector.white_noise_rel_fringe = 1e-5;
        let model = PhaseModel::of_preset(&preset, preset.truth).unwrap();
        for q2_um in [0.10, 0.20, 0.45, 0.50] {
            let mut bench = VirtualBench::new(&preset, Some(2)).unwrap();
            let start = [0.0, q2_um, 0.0, 0.0, 0.0, 0.0];
            let figure = run_validation(&mut bench, &model, &preset.truth, ValidationMotion::Circle, start).unwrap();
            // 0.0002-0.0003 nm measured: twice that.
            assert!(figure.peak_to_peak_nm < 6e-4, "start q2 +{q2_um} µm: {} nm", figure.peak_to_peak_nm);
        }
    }

    #[test]
    fn waypoints_out_of_range_are_refused_before_moving() {
        let preset = BenchPreset::resolve("table2-ideal").unwrap();
        let model =
            PhaseModel::new(RobotDescription::femto_6dof(), preset.truth, preset.optics, &preset.ambient, 1560.0)
                .unwrap();
        let err = waypoints(&model, &preset.truth, ValidationMotion::Circle, [140.0, 0.0, 140.0, 0.0, 0.0, 0.0], 36)
            .unwrap_err();
        assert!(
            err.to_string().contains("above its upper limit") || err.to_string().contains("below its lower limit"),
            "{err}"
        );
    }
}
#[cfg(test)]
mod exp_hint;
