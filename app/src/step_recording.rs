//! A wizard step recorded through the core's recording function (`session::recording::record`,
//! as `photorobot calibrate` records): each whole segment's trace is handed on at once with where
//! the step stands after it (the worker sends both to the UI, to be autosaved by its writer
//! thread, so a crash leaves a step that can be resumed), and a stopped step reports where it
//! stands, to be resumed.

use photorobot_core::bench::{Bench, RunControl};
use photorobot_core::plan::Plan;
use photorobot_core::session::recording::{record, RecordSink};
use photorobot_core::session::{Progress, SessionError};
use photorobot_core::trace::Trace;

/// Where a stopped wizard step stands: the plan's progress (the segment to measure again and
/// the pose the plan started from), and how many of its traces are whole (one after them, if
/// any, was cut short by the stop).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Resume {
    /// The plan's progress.
    pub progress: Progress,
    /// The traces before the interrupted segment.
    pub whole_traces: usize,
}

/// How a run on the worker ended: the traces, the bench time (s), the outcome, and where a
/// stopped wizard step stands.
pub(crate) struct Ran {
    pub traces: Vec<Trace>,
    pub duration_s: f64,
    pub outcome: Result<(), String>,
    pub resume: Option<Resume>,
}

/// Record wizard step `plan` on `bench`, from the start or from where a stopped run of it
/// stands (`from`), each whole segment's trace handed to `on_segment` as soon as it is recorded,
/// with the plan's progress after it.
pub(crate) fn record_step(
    bench: &mut dyn Bench,
    plan: &Plan,
    from: Option<Progress>,
    control: &mut RunControl<'_>,
    on_segment: &mut dyn FnMut(&Trace, Progress),
) -> Ran {
    let mut sink =
        StepRecording { plan: plan.clone(), progress: from, traces: Vec::new(), whole: 0, handed: 0, on_segment };
    let (duration_s, outcome) = match record(bench, &mut sink, control) {
        Ok(r) => (r.duration_s, r.outcome.map_err(|e| e.to_string())),
        Err(e) => (0.0, Err(e.to_string())),
    };
    let resume =
        sink.progress.filter(|_| outcome.is_err()).map(|progress| Resume { progress, whole_traces: sink.whole });
    Ran { traces: sink.traces, duration_s, outcome, resume }
}

/// A wizard step's recording: its one plan; each complete segment's trace handed on at once, and
/// every trace, a stopped segment's partial one included, kept for the step's report.
struct StepRecording<'a> {
    plan: Plan,
    progress: Option<Progress>,
    traces: Vec<Trace>,
    /// How many of `traces` are whole.
    whole: usize,
    /// How many of `traces` went to `on_segment` (each once its progress is known).
    handed: usize,
    on_segment: &'a mut dyn FnMut(&Trace, Progress),
}

impl RecordSink for StepRecording<'_> {
    fn plans(&self) -> Vec<Plan> {
        vec![self.plan.clone()]
    }

    fn progress(&self) -> Option<Progress> {
        self.progress
    }

    fn keep_trace(&mut self, trace: &Trace, _at: (usize, usize), complete: bool) -> Result<(), SessionError> {
        // A partial trace is never handed on: it is measured again on resuming.
        if complete {
            self.whole += 1;
        }
        self.traces.push(trace.clone());
        Ok(())
    }

    /// The core sets the progress after keeping each whole segment's trace: the trace goes on
    /// with it.
    fn set_progress(&mut self, progress: Progress) -> Result<(), SessionError> {
        self.progress = Some(progress);
        if self.handed < self.whole {
            self.handed = self.whole;
            if let Some(trace) = self.traces.last() {
                (self.on_segment)(trace, progress);
            }
        }
        Ok(())
    }
}
