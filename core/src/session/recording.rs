//! Measuring into a session: the session's plans run on a bench with every completed step kept at
//! once, and resumed after a crash, a fault or a stop. Owns the order "trace, then progress" that
//! makes a crash lose no step; the command line and the workbench both record through it.
//!
//! After each completed segment the trace goes to the [`RecordSink`], then the progress (the next
//! step). A [`SessionWriter`] writes the trace (atomically) to a new `traces/NNN.csv`, then the
//! session, now referencing it, to the autosave file. A crash between the two leaves an
//! unreferenced trace file that the resumed run leaves alone (it writes under the next free name);
//! a crash at any other point leaves every completed step in the autosave.
//! [`record`] starts where the sink's progress says, so the same call measures a new session and
//! resumes a recovered or stopped one ([`super::Session::recover`]).

use super::{Progress, SessionError, SessionWriter, TraceRef};
use crate::bench::{resume_plan_with, run_plan_with, Bench, RunControl, RunError, StepDone};
use crate::plan::Plan;
use crate::trace::Trace;

/// Where [`record_with`] keeps what it measures, and where it starts.
pub trait RecordSink {
    /// The plans to measure.
    fn plans(&self) -> Vec<Plan>;
    /// Where the measurement stands (`None`: nothing measured yet).
    fn progress(&self) -> Option<Progress>;
    /// The trace of segment `at` (plan, segment), `complete` false for one a stop or a fault
    /// interrupted.
    fn keep_trace(&mut self, trace: &Trace, at: (usize, usize), complete: bool) -> Result<(), SessionError>;
    /// Where the measurement stands now, every trace before it kept.
    fn set_progress(&mut self, progress: Progress) -> Result<(), SessionError>;
    /// How far plan `p` is measured, when the sink knows: its recorded segments with a whole
    /// trace, and its recorded segments. The workbench measures its steps in any order, so a
    /// plan after the one the progress names may be measured already and one before it not at
    /// all.
    fn coverage(&self, _p: usize) -> Option<(usize, usize)> {
        None
    }
    /// The file the last trace kept went to, when the sink writes files: named in the log's
    /// line for each completed segment.
    fn last_file(&self) -> Option<&TraceRef> {
        None
    }
}

/// The session folder: each trace to a new file, each progress to the autosave.
impl RecordSink for SessionWriter {
    fn plans(&self) -> Vec<Plan> {
        self.session().plans.clone()
    }

    fn progress(&self) -> Option<Progress> {
        self.session().progress
    }

    fn keep_trace(&mut self, trace: &Trace, at: (usize, usize), complete: bool) -> Result<(), SessionError> {
        self.add_trace(trace, Some(at), complete).map(|_| ())
    }

    fn set_progress(&mut self, progress: Progress) -> Result<(), SessionError> {
        self.session_mut().progress = Some(progress);
        self.autosave()
    }

    fn coverage(&self, p: usize) -> Option<(usize, usize)> {
        Some(self.session().plan_coverage(p))
    }

    fn last_file(&self) -> Option<&TraceRef> {
        self.session().traces.last()
    }
}

/// The plans [`record_with`] measures, in order: from the one the progress resumes (the first
/// without a progress) to the last, but for those measured whole already, then those before it
/// not measured at all. A workbench session's steps run in any order; in one the command line
/// measured, the plans before the progress's are whole and those after it not begun.
fn plans_to_measure(sink: &dyn RecordSink, count: usize) -> Vec<usize> {
    let resumed = sink.progress().map(|p| p.plan);
    let first = resumed.unwrap_or(0);
    let whole = |p: usize| sink.coverage(p).is_some_and(|(whole, recorded)| recorded > 0 && whole == recorded);
    let unmeasured = |p: usize| sink.coverage(p).is_some_and(|(whole, recorded)| recorded > 0 && whole == 0);
    let after = (first..count).filter(|&p| Some(p) == resumed || !whole(p));
    let before = (0..first.min(count)).filter(|&p| unmeasured(p));
    let order: Vec<usize> = after.chain(before).collect();
    for p in (0..count).filter(|p| !order.contains(p) && *p >= first) {
        tracing::info!("plan {} of {count} already measured: skipped", p + 1);
    }
    order
}

/// How a [`record`] call ended.
#[derive(Debug)]
pub struct Recorded {
    /// Bench time used by this call (s).
    pub duration_s: f64,
    /// `Ok` when every plan has been measured.
    pub outcome: Result<(), RunError>,
}

/// Measure the sink's plans on the bench from where its progress says (the start for a new
/// session), keeping every completed step (trace, then progress). A partial trace of an
/// interrupted segment is kept too (marked incomplete). Errors keeping a step stop the run after
/// the step in hand (its data is in memory and in the returned error).
pub fn record(
    bench: &mut dyn Bench,
    sink: &mut dyn RecordSink,
    control: &mut RunControl<'_>,
) -> Result<Recorded, SessionError> {
    record_with(bench, sink, control, &mut |_, _| {})
}

/// [`record`], calling `on_segment(plan, segment)` with each segment about to run (segment
/// indices in the plan's own numbering), for progress displays.
pub fn record_with(
    bench: &mut dyn Bench,
    sink: &mut dyn RecordSink,
    control: &mut RunControl<'_>,
    on_segment: &mut dyn FnMut(usize, usize),
) -> Result<Recorded, SessionError> {
    let start_s = bench.clock_s();
    let plans = sink.plans();
    for p in plans_to_measure(&*sink, plans.len()) {
        let plan = &plans[p];
        // A recovered session goes back to where its plan started (recorded in the autosave).
        let resuming = sink.progress().filter(|pr| pr.plan == p);
        let progress =
            resuming.unwrap_or(Progress { plan: p, next_segment: 0, plan_start_display: bench.position_display() });
        sink.set_progress(progress)?;
        tracing::info!(plan = %plan.name, from_segment = progress.next_segment, "measuring plan {} of {}", p + 1, plans.len());
        on_segment(p, progress.next_segment);
        let mut on_step = |step: StepDone<'_>| -> Result<(), String> {
            if let Some(t) = step.trace {
                sink.keep_trace(t, (p, step.segment), true).map_err(|e| e.to_string())?;
            }
            sink.set_progress(Progress { next_segment: step.segment + 1, ..progress }).map_err(|e| e.to_string())?;
            // Written once the segment is kept for good: every segment this line names is in
            // the session, its trace in the file named with that size and CRC-32.
            let file = step.trace.and(sink.last_file());
            tracing::debug!(
                plan = %plans[p].name, plan_index = p, segment = step.segment, label = step.label,
                recorded = step.trace.is_some(), file = file.map(|r| r.file.as_str()),
                bytes = file.map(|r| r.bytes), crc32 = file.map(|r| r.crc32),
                "segment done, autosaved"
            );
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
                    sink.keep_trace(partial, (p, segment.min(plan.segments.len() - 1)), false)?;
                    // Kept with the progress it belongs to (the autosave, in a session folder).
                    sink.set_progress(sink.progress().unwrap_or(progress))?;
                }
            }
            return Ok(Recorded { duration_s: bench.clock_s() - start_s, outcome: Err(e) });
        }
    }
    sink.set_progress(Progress { plan: plans.len(), next_segment: 0, plan_start_display: bench.position_display() })?;
    Ok(Recorded { duration_s: bench.clock_s() - start_s, outcome: Ok(()) })
}
