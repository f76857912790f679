//! Positioning: the lamella placed where the technician asks, relative to the fiber, with the
//! identified model, and the placement proven by a measurement that does not use the extrinsics.
//! Owns the move (plan, limit check, run, proof, verdict) that the CLI's `move` and the GUI's
//! Position view both call.
//!
//! A move: the target ([`target::Target`]) becomes a straight task-space path from where the
//! lamella is ([`path`]), every waypoint solved by the IGM of the calibrated robot (with any
//! effects a diagnosis added) and checked against the limits before anything moves; the plan
//! compensates the stages' play ([`crate::validate::plan_through`]); the bench runs it, then
//! measures the gap ([`proof`]); the forecast at the end pose ([`forecast`]) and the
//! measurement's σ bound the error a confirmed move may show ([`record::Verdict`]).
//!
//! The tilt is measured at the end pose from the fringe contrast along two small rotations
//! ([`tilt`]), to a few thousandths of a degree: what turns the distance the fringes see into
//! the gap along the beam without the extrinsics, though coarser than the calibration places it.
//! The lateral position and the rotation about the beam are placed through the model: no
//! measurement on this bench sees them without the extrinsics. The record says so.

pub mod forecast;
pub mod path;
pub mod proof;
pub mod recipe;
pub mod record;
pub mod target;
pub mod tilt;

pub use forecast::{PoseForecast, Uncertainty};
pub use proof::{ProofKind, Reference, TiltForGap};
pub use record::{Achieved, GapMeasurement, Joints, MoveRecord, Verdict};
pub use target::{Target, TaskFrame};
pub use tilt::TiltMeasurement;

use crate::bench::{run_plan, Bench, RunControl};
use crate::model::effects::{self, Effect};
use crate::model::extrinsics::Extrinsics;
use crate::model::phase::PhaseModel;
use crate::plan::{Plan, Segment};
use crate::trace::Trace;
use crate::validate::{join, modelled_real_joints, plan_through, ENVELOPE_DITHER};
use thiserror::Error;

/// Why a move was refused. Nothing moved.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum MoveError {
    /// The target's fields are not a target.
    #[error("target: {0}")]
    BadTarget(String),
    /// The target, or a point on the way, is out of the robot's reach.
    #[error("target {}: out of reach: {reason}; nothing moved", target.describe())]
    Unreachable {
        /// The target.
        target: Target,
        /// Why, with the joint and its limit.
        reason: String,
    },
    /// The beam misses the lamella at the start.
    #[error("at joints {joints:?} the beam misses the lamella: no cavity to place from")]
    NoCavity {
        /// The joints (µm, °).
        joints: [f64; 6],
    },
    /// The model could not be built.
    #[error("the positioning model: {0}")]
    Model(String),
}

/// What a move is planned with: the calibrated model and what is known of its uncertainty.
#[derive(Debug, Clone)]
pub struct Placement {
    /// The robot (with any effects a diagnosis added), the identified extrinsics, the optics
    /// and the air.
    pub model: PhaseModel,
    /// The uncertainty of the extrinsics; `None`: taken as exact (an extrinsics file).
    pub uncertainty: Option<Uncertainty>,
    /// The stages' play the plans compensate (display units).
    pub play: [f64; 6],
    /// Where the extrinsics come from, for the record.
    pub source: String,
}

impl Placement {
    /// The placement on `base` (the bench's nominal robot, optics and air) with `extrinsics`,
    /// their uncertainty, and the `effects` of a diagnosis (geometric ones on the robot, optical
    /// ones on the optics, reversal play compensated; a drift is not: it goes on after the move).
    pub fn new(
        base: &PhaseModel,
        extrinsics: Extrinsics,
        uncertainty: Option<Uncertainty>,
        effects: &[Effect],
        source: &str,
    ) -> Result<Self, MoveError> {
        let robot = base.chain.description();
        let extended = effects::apply_all(effects, robot).map_err(|e| MoveError::Model(e.to_string()))?;
        let model = PhaseModel {
            chain: crate::model::kinematics::Chain::new(extended),
            extrinsics,
            optics: effects::apply_optics(effects, &base.optics),
            n_air: base.n_air,
        };
        let play = effects::reversal_play(effects, robot);
        Ok(Self { model, uncertainty, play, source: source.to_string() })
    }
}

/// A move planned, before it runs: what the Position view previews and [`run_move`] runs.
#[derive(Debug, Clone)]
pub struct MovePlan {
    /// The target.
    pub target: Target,
    /// The gap is held while the rest moves.
    pub keep_gap: bool,
    /// The path (joints and task coordinates of every waypoint).
    pub path: path::Path,
    /// The forecast at the end pose; `None` without an uncertainty.
    pub forecast: Option<PoseForecast>,
    /// How the move will be proven.
    pub proof: ProofKind,
    /// The bench's plan: the approach, the envelope dither, the path, the sweep.
    pub plan: Plan,
    /// The stages' state at the plan's first recorded sample (stages with play).
    state: effects::Backlash,
    /// Measure the tilt at the end pose ([`tilt`]); else the gap is read at the requested tilt.
    pub measure_tilt: bool,
}

/// What a move's proof measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ProofOptions {
    /// A sweep at the end pose when the bench has a tunable laser; else the fringes from a pose a
    /// sweep measured.
    pub sweeps: bool,
    /// The tilt at the end pose from the fringe contrast (two ±3° rotations).
    pub tilt: bool,
}

impl Default for ProofOptions {
    /// Both.
    fn default() -> Self {
        ProofOptions { sweeps: true, tilt: true }
    }
}

/// Plan a move to `target` from joints `from` (µm, °; the path starts at the reference pose
/// instead when the fringes prove it): the path through the IGM, the limits of every waypoint,
/// the forecast and the bench plan. Refused (nothing moves) when anything is out of reach.
pub fn plan_move(
    placement: &Placement,
    from: [f64; 6],
    target: &Target,
    keep_gap: bool,
    proof: ProofKind,
) -> Result<MovePlan, MoveError> {
    target.check().map_err(MoveError::BadTarget)?;
    let model = &placement.model;
    let start = match &proof {
        ProofKind::Fringes(r) => r.joints,
        _ => from,
    };
    let frame = TaskFrame::at(model, &model.extrinsics, &start).ok_or(MoveError::NoCavity { joints: start })?;
    let path = path::plan_path(model, &frame, start, target, keep_gap)?;
    let forecast = placement.uncertainty.as_ref().and_then(|u| forecast::forecast_at(model, &frame, u, &path.end()));
    let (mut plan, state, _) = plan_through("position", proof::PATH_LABEL, &path.joints, &placement.play);
    if proof == ProofKind::Sweep {
        let (from_nm, to_nm, rate_nm_per_s) = proof::SWEEP_NM;
        plan.segments.push(Segment::Sweep { from_nm, to_nm, rate_nm_per_s, label: proof::SWEEP_LABEL.into() });
    }
    plan.description = format!("move to {}", target.describe());
    Ok(MovePlan { target: *target, keep_gap, path, forecast, proof, plan, state, measure_tilt: true })
}

/// Run a planned move on the bench (stoppable through `control`) and prove it: the record of
/// what happened, whatever happened (a stop, a fault and an analysis that failed included).
pub fn run_move(
    bench: &mut dyn Bench,
    placement: &Placement,
    plan: &MovePlan,
    control: &mut RunControl<'_>,
) -> MoveRecord {
    let t0 = bench.clock_s();
    let run = run_plan(bench, &plan.plan, control);
    let mut record = MoveRecord {
        label: String::new(),
        recipe: None,
        started_utc: None,
        extrinsics_source: placement.source.clone(),
        requested: plan.target,
        keep_gap: plan.keep_gap,
        joints_start: plan.path.joints[0].into(),
        joints_end: plan.path.end().into(),
        waypoints: plan.path.joints.len() - 1,
        forecast: plan.forecast,
        measurement: None,
        tilt: None,
        achieved: None,
        gap_error_nm: None,
        bound_nm: None,
        model_only: MODEL_ONLY.into(),
        verdict: Verdict::Failed,
        note: String::new(),
        bench_time_s: bench.clock_s() - t0,
    };
    if let Err(e) = run.outcome {
        record.verdict = if control.cancelled() { Verdict::Stopped } else { Verdict::Failed };
        record.note = e.to_string();
        return record;
    }
    let model = &placement.model;
    let read = bench.position_display();
    let frame = TaskFrame::at(model, &model.extrinsics, &read);
    record.achieved =
        frame.and_then(|f| f.target_at(model, &read)).map(|t| Achieved { gap_um: None, gap_sigma_nm: None, model: t });
    if let ProofKind::None(why) = &plan.proof {
        record.verdict = Verdict::Unconfirmed;
        record.note = format!("placed through the model; the gap is not measured: {why}");
        return record;
    }
    let measured_tilt = match plan.measure_tilt {
        true => tilt::measure_at(bench, placement, plan.path.end(), control),
        false => Err("not asked for".to_string()),
    };
    let (tilt, tilt_note) = match measured_tilt {
        Ok(t) => {
            record.tilt = Some(t);
            record.model_only = MODEL_ONLY_TILT_MEASURED.into();
            let (rad, sigma_rad) = t.rad();
            (TiltForGap { rad, sigma_rad }, None)
        }
        Err(why) => {
            let sigma_deg = plan.forecast.map_or(0.0, |f| f.tilt_angle_sigma_deg());
            let t = TiltForGap { rad: plan.target.tilt_angle_rad(), sigma_rad: sigma_deg.to_radians() };
            (t, Some(format!("; the gap read at the requested tilt, which was not measured: {why}")))
        }
    };
    record.bench_time_s = bench.clock_s() - t0;
    let measured = match &plan.proof {
        ProofKind::Fringes(r) => fringes_of(&run.traces, plan, placement)
            .and_then(|(path, real, d)| proof::gap_from_fringes(&path, real.as_ref(), d, model, r, Some(&tilt)))
            .map(|(g, s)| (g, s, format!("fringes along the path from a pose at {:.4} µm ({})", r.gap_um, r.source))),
        _ => sweep_of(&run.traces)
            .and_then(|s| proof::gap_from_sweep(s, model, &tilt))
            .map(|(g, s)| (g, s, proof::SWEEP_METHOD.to_string())),
    };
    judge(&mut record, plan, measured);
    record.note.push_str(&tilt_note.unwrap_or_default());
    judge_tilt(&mut record, plan);
    if control.cancelled() {
        // The gap measured before the stop is kept; the move is not proven.
        record.verdict = Verdict::Stopped;
        record.note = format!("stopped while the tilt was measured at the end pose; {}", record.note);
    }
    record
}

/// The tilt measured at the end pose against the model's there: beyond
/// [`record::BOUND_SIGMAS`] × the combined σ of the measurement and the forecast, a confirmed
/// move is off (the extrinsics placed the lamella at another tilt than they say).
fn judge_tilt(record: &mut MoveRecord, plan: &MovePlan) {
    let Some(t) = record.tilt else { return };
    let forecast_deg = plan.forecast.map_or(0.0, |f| f.tilt_angle_sigma_deg());
    let bound_deg = record::BOUND_SIGMAS * t.sigma_deg.hypot(forecast_deg);
    let within = (t.tilt_deg - t.model_deg).abs() <= bound_deg;
    record.note.push_str(&format!(
        "; tilt from the contrast {:.4}° against the model's {:.4}°, {} ±{bound_deg:.4}°",
        t.tilt_deg,
        t.model_deg,
        if within { "within" } else { "beyond" }
    ));
    if !within && record.verdict == Verdict::Confirmed {
        record.verdict = Verdict::Off;
    }
}

/// Plan and run a move from where the bench stands, proven as the bench allows and `options`
/// ask (a sweep with a tunable laser when they allow it, else the fringes from the nearest of
/// `references`; the tilt at the end pose when they ask for it): the one function the CLI and
/// the GUI call. `Err` only when the move is refused before anything moves.
pub fn move_to(
    bench: &mut dyn Bench,
    placement: &Placement,
    target: &Target,
    keep_gap: bool,
    references: &[Reference],
    options: ProofOptions,
    control: &mut RunControl<'_>,
) -> Result<MoveRecord, MoveError> {
    let from = bench.position_display();
    let proof = ProofKind::choose(options.sweeps && bench.tunable_laser(), references, &from);
    let plan = MovePlan { measure_tilt: options.tilt, ..plan_move(placement, from, target, keep_gap, proof)? };
    Ok(run_move(bench, placement, &plan, control))
}

/// What the record says of the coordinates no measurement here sees.
pub const MODEL_ONLY: &str = "tilt, lateral position and rotation placed through the model only: no measurement on \
     this bench sees them without the extrinsics (their σ is the forecast's)";
/// [`MODEL_ONLY`] when the tilt was measured at the end pose.
pub const MODEL_ONLY_TILT_MEASURED: &str = "lateral position and rotation placed through the model only: no \
     measurement on this bench sees them without the extrinsics (their σ is the forecast's); the tilt is measured \
     from the fringe contrast";

/// The verdict from the measured gap: confirmed within [`record::BOUND_SIGMAS`] × the combined
/// σ of the forecast and the measurement, off beyond.
fn judge(record: &mut MoveRecord, plan: &MovePlan, measured: Result<(f64, f64, String), String>) {
    let (gap_um, sigma_nm, method) = match measured {
        Ok(m) => m,
        Err(e) => {
            record.verdict = Verdict::Failed;
            record.note = format!("the gap could not be measured: {e}");
            return;
        }
    };
    let error_nm = (gap_um - plan.target.gap_um) * 1e3;
    let forecast_nm = plan.forecast.map(|f| f.gap_sigma_nm);
    let bound_nm = record::BOUND_SIGMAS * forecast_nm.unwrap_or(0.0).hypot(sigma_nm);
    record.measurement = Some(GapMeasurement { method, gap_um, sigma_nm });
    if let Some(a) = record.achieved.as_mut() {
        a.gap_um = Some(gap_um);
        a.gap_sigma_nm = Some(sigma_nm);
    }
    record.gap_error_nm = Some(error_nm);
    record.bound_nm = Some(bound_nm);
    let basis = match forecast_nm {
        Some(f) => format!("the forecast's σ {f:.2} nm and the measurement's {sigma_nm:.2} nm"),
        None => format!("the measurement's σ {sigma_nm:.2} nm alone (no calibration uncertainty: the extrinsics are taken as exact)"),
    };
    let within = error_nm.abs() <= bound_nm;
    record.verdict = if within { Verdict::Confirmed } else { Verdict::Off };
    record.note = format!(
        "measured gap {error_nm:+.2} nm from the requested, {} ±{bound_nm:.2} nm ({}σ of {basis})",
        if within { "within" } else { "beyond" },
        record::BOUND_SIGMAS
    );
}

/// The sweep of a move's run.
fn sweep_of(traces: &[Trace]) -> Result<&Trace, String> {
    traces.iter().find(|t| t.meta.label == proof::SWEEP_LABEL).ok_or_else(|| "the sweep was not recorded".into())
}

/// The dither and the path of a move's run joined, the joints the stages really went through
/// (stages with play), and the first sample after the dither.
fn fringes_of(
    traces: &[Trace],
    plan: &MovePlan,
    placement: &Placement,
) -> Result<(Trace, Option<Trace>, usize), String> {
    let moves: Vec<Trace> = traces.iter().filter(|t| t.meta.label != proof::SWEEP_LABEL).cloned().collect();
    let path = join(&moves).ok_or("the path was not recorded")?;
    let dither: Vec<Trace> = moves.iter().filter(|t| t.meta.label == ENVELOPE_DITHER).cloned().collect();
    let dither_end = join(&dither).map_or(0, |d| d.len());
    let real =
        placement.play.iter().any(|p| *p != 0.0).then(|| modelled_real_joints(&path, &placement.play, plan.state));
    Ok((path, real, dither_end))
}

#[cfg(test)]
mod tests;
