//! Measuring into a session: the session's plans run on a bench with every completed step saved at once, and
//! resumed after a crash or a fault. Owns the order "trace file, then autosave" that makes a crash lose no step.
//!
//! After each completed segment the trace is written (atomically) to a new `traces/NNN.csv`, then
//! the session (now referencing it, with the next step in [`Progress`]) is written atomically to
//! the autosave file, both through the [`SessionWriter`]. A crash between the two leaves an
//! unreferenced trace file that the resumed run leaves alone (it writes under the next free name);
//! a crash at any other point leaves every completed step in the autosave.
//! [`record`] starts where [`super::Session::progress`] says, so the same call measures a new session
//! and resumes a recovered one ([`super::Session::recover`]).

use super::{Progress, SessionError, SessionWriter};
use crate::bench::{resume_plan_with, run_plan_with, Bench, RunControl, RunError, StepDone};

/// How a [`record`] call ended.
#[derive(Debug)]
pub struct Recorded {
    /// Bench time used by this call (s).
    pub duration_s: f64,
    /// `Ok` when every plan has been measured.
    pub outcome: Result<(), RunError>,
}

/// Measure the writer's session's plans on the bench from where [`super::Session::progress`] says (the
/// start for a new session), saving every completed step in the writer's folder (trace, then
/// autosave). A partial
/// trace of an interrupted segment is kept too (marked incomplete). Errors writing the session
/// stop the run after the step in hand (its data is in memory and in the returned error).
pub fn record(
    bench: &mut dyn Bench,
    writer: &mut SessionWriter,
    control: &mut RunControl<'_>,
) -> Result<Recorded, SessionError> {
    record_with(bench, writer, control, &mut |_, _| {})
}

/// [`record`], calling `on_segment(plan, segment)` with each segment about to run (segment
/// indices in the plan's own numbering), for progress displays.
pub fn record_with(
    bench: &mut dyn Bench,
    writer: &mut SessionWriter,
    control: &mut RunControl<'_>,
    on_segment: &mut dyn FnMut(usize, usize),
) -> Result<Recorded, SessionError> {
    let start_s = bench.clock_s();
    let first = writer.session().progress.map_or(0, |p| p.plan);
    let plans = writer.session().plans.clone();
    for (p, plan) in plans.iter().enumerate().skip(first) {
        // A recovered session goes back to where its plan started (recorded in the autosave).
        let resuming = writer.session().progress.filter(|pr| pr.plan == p);
        let progress =
            resuming.unwrap_or(Progress { plan: p, next_segment: 0, plan_start_display: bench.position_display() });
        writer.session_mut().progress = Some(progress);
        writer.autosave()?;
        tracing::info!(plan = %plan.name, from_segment = progress.next_segment, "measuring plan {} of {}", p + 1, plans.len());
        on_segment(p, progress.next_segment);
        let mut on_step = |step: StepDone<'_>| -> Result<(), String> {
            if let Some(t) = step.trace {
                writer.add_trace(t, Some((p, step.segment)), true).map_err(|e| e.to_string())?;
            }
            writer.session_mut().progress = Some(Progress { next_segment: step.segment + 1, ..progress });
            writer.autosave().map_err(|e| e.to_string())?;
            tracing::debug!(plan = %plans[p].name, segment = step.segment, label = step.label, recorded = step.trace.is_some(), "segment done, autosaved");
            on_segment(p, step.segment + 1);
            Ok(())
        };
        let run = match resuming {
            None => run_plan_with(bench, plan, control, &mut on_step),
            Some(_) => {
                resume_plan_with(bench, plan, progress.plan_start_display, progress.next_segment, control, &mut on_step)
            }
        };
        if let Err(e) = run.outcome {
            tracing::warn!(plan = %plan.name, "measurement stopped: {e}");
            if let RunError::Segment { segment, error, .. } = &e {
                // Resumed runs count the return move as segment 0.
                let segment = segment.saturating_sub(usize::from(resuming.is_some())) + progress.next_segment;
                if let Some(partial) = error.partial().filter(|t| !t.is_empty()) {
                    writer.add_trace(partial, Some((p, segment.min(plan.segments.len() - 1))), false)?;
                    writer.autosave()?;
                }
            }
            return Ok(Recorded { duration_s: bench.clock_s() - start_s, outcome: Err(e) });
        }
    }
    writer.session_mut().progress =
        Some(Progress { plan: plans.len(), next_segment: 0, plan_start_display: bench.position_display() });
    writer.autosave()?;
    Ok(Recorded { duration_s: bench.clock_s() - start_s, outcome: Ok(()) })
}
