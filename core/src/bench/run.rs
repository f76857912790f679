//! Running a motion plan on a bench, segment by segment, keeping every recorded trace even when a
//! step fails, and resuming a plan after an interruption.

use super::{Bench, BenchError, RunControl};
use crate::plan::{Plan, PlanError, TimedMotion};
use crate::trace::{Trace, TraceKind, TraceMeta};
use thiserror::Error;

/// Why a plan stopped. The traces recorded before the stop are in [`PlanRun::traces`].
#[derive(Debug, Error)]
pub enum RunError {
    /// The plan is invalid or leaves the joint limits; nothing was moved.
    #[error(transparent)]
    Plan(#[from] PlanError),
    /// The per-step callback asked to stop after a completed segment (e.g. an autosave failed).
    #[error("stopped after segment {segment} ({label}): {reason}")]
    Stopped {
        /// Index of the last completed segment.
        segment: usize,
        /// Its label.
        label: String,
        /// Why.
        reason: String,
    },
    /// A segment failed or was cancelled.
    #[error("segment {segment} ({label}): {error}")]
    Segment {
        /// Index of the segment in the plan.
        segment: usize,
        /// Its label.
        label: String,
        /// What happened.
        error: BenchError,
    },
}

/// The result of running a plan: every trace recorded, and how it ended.
#[derive(Debug)]
pub struct PlanRun {
    /// Recorded traces, in plan order (a partial trace of an interrupted segment included).
    pub traces: Vec<Trace>,
    /// Bench time used (s).
    pub duration_s: f64,
    /// `Ok` when every segment ran.
    pub outcome: Result<(), RunError>,
}

/// A segment that has just completed, as reported to the per-step callback of [`run_plan_with`].
#[derive(Debug, Clone, Copy)]
pub struct StepDone<'a> {
    /// Index of the segment in the plan.
    pub segment: usize,
    /// Its label.
    pub label: &'a str,
    /// Its trace, when the segment records.
    pub trace: Option<&'a Trace>,
}

/// Called after every completed segment (to autosave, for example); an `Err` stops the plan
/// before the next segment with [`RunError::Stopped`].
pub type OnStep<'a> = dyn FnMut(StepDone<'_>) -> Result<(), String> + 'a;

/// Run a plan: expand and check it against the limits first (nothing moves if any move is out
/// of range), then run segment by segment. Data already recorded is never lost: it is in the
/// returned [`PlanRun`] whatever the outcome.
pub fn run_plan(bench: &mut dyn Bench, plan: &Plan, control: &mut RunControl<'_>) -> PlanRun {
    run_plan_with(bench, plan, control, &mut |_| Ok(()))
}

/// [`run_plan`], calling `on_step` after every completed segment.
pub fn run_plan_with(
    bench: &mut dyn Bench,
    plan: &Plan,
    control: &mut RunControl<'_>,
    on_step: &mut OnStep<'_>,
) -> PlanRun {
    let start = bench.clock_s();
    let segments = match plan.expand(bench.robot(), bench.position_display(), bench.motion_limits()) {
        Ok(s) => s,
        Err(e) => return PlanRun { traces: vec![], duration_s: 0.0, outcome: Err(e.into()) },
    };
    let mut traces = Vec::new();
    let count = segments.len();
    for (i, seg) in segments.iter().enumerate() {
        let meta = TraceMeta {
            label: seg.label.clone(),
            kind: if matches!(seg.motion, TimedMotion::Sweep { .. }) {
                TraceKind::WavelengthSweep
            } else {
                TraceKind::Motion
            },
            bench: bench.name(),
            irradiance_unit: "mW".into(),
            notes: format!("plan {}, segment {} of {}", plan.name, i + 1, count),
            wavelength_scale_sigma_ppm: 0.0,
        };
        match bench.run_segment(seg, meta, control) {
            Ok(trace) => {
                let stop = on_step(StepDone { segment: i, label: &seg.label, trace: trace.as_ref() });
                traces.extend(trace);
                if let Err(reason) = stop {
                    return PlanRun {
                        traces,
                        duration_s: bench.clock_s() - start,
                        outcome: Err(RunError::Stopped { segment: i, label: seg.label.clone(), reason }),
                    };
                }
            }
            Err(error) => {
                if let Some(p) = error.partial() {
                    if !p.is_empty() {
                        traces.push(p.clone());
                    }
                }
                return PlanRun {
                    traces,
                    duration_s: bench.clock_s() - start,
                    outcome: Err(RunError::Segment { segment: i, label: seg.label.clone(), error }),
                };
            }
        }
    }
    PlanRun { traces, duration_s: bench.clock_s() - start, outcome: Ok(()) }
}

/// Run the rest of a plan after an interruption: first back (unrecorded) to where segment
/// `from_segment` started, then that segment and every one after it, so an interrupted recorded
/// move is measured again in full. `plan_start_display` is the joint vector (µm, °) the plan was
/// first run from (it fixes where each segment starts). Segment indices in the returned outcome
/// count from the return move (index 0), then `from_segment` as 1, and so on.
pub fn resume_plan(
    bench: &mut dyn Bench,
    plan: &Plan,
    plan_start_display: [f64; 6],
    from_segment: usize,
    control: &mut RunControl<'_>,
) -> PlanRun {
    resume_plan_with(bench, plan, plan_start_display, from_segment, control, &mut |_| Ok(()))
}

/// [`resume_plan`], calling `on_step` after every completed segment of the original plan, with
/// the segment's index in the original plan (the return move is not reported).
pub fn resume_plan_with(
    bench: &mut dyn Bench,
    plan: &Plan,
    plan_start_display: [f64; 6],
    from_segment: usize,
    control: &mut RunControl<'_>,
    on_step: &mut OnStep<'_>,
) -> PlanRun {
    let segments = match plan.expand(bench.robot(), plan_start_display, bench.motion_limits()) {
        Ok(s) => s,
        Err(e) => return PlanRun { traces: vec![], duration_s: 0.0, outcome: Err(e.into()) },
    };
    let Some(first) = segments.get(from_segment) else {
        return PlanRun { traces: vec![], duration_s: 0.0, outcome: Ok(()) };
    };
    let mut rest = vec![crate::plan::Segment::Move {
        to: crate::plan::JointTarget::all(first.from_display),
        record: false,
        label: format!("resume: back to the start of segment {from_segment} ({})", first.label),
        through: false,
    }];
    rest.extend(plan.segments[from_segment..].iter().cloned());
    let remainder = Plan {
        name: format!("{} (resumed at segment {from_segment})", plan.name),
        description: plan.description.clone(),
        segments: rest,
    };
    run_plan_with(bench, &remainder, control, &mut |step: StepDone<'_>| match step.segment {
        0 => Ok(()),
        k => on_step(StepDone { segment: from_segment + k - 1, ..step }),
    })
}
