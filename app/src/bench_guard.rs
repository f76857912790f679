//! The worker's bench, guarded: every segment any caller runs on it (a wizard plan, a validation
//! or diagnosis motion whose core function made its own cancel flag, a jog, the live dither)
//! obeys the one shared stop flag, and the traces of the plan being recorded are kept aside so
//! that a panic in the worker does not lose them.

use photorobot_core::bench::{Bench, BenchError, RunControl};
use photorobot_core::plan::TimedSegment;
use photorobot_core::trace::{Trace, TraceMeta};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};

/// The traces a guarded bench keeps aside while keeping is on.
#[derive(Debug, Default)]
pub struct Kept {
    /// Keep the traces of the segments run from now on.
    pub on: bool,
    /// The traces (and partial traces) recorded since keeping was turned on.
    pub traces: Vec<Trace>,
}

/// Shared handle on what a [`GuardedBench`] keeps.
pub type KeptTraces = Arc<Mutex<Kept>>;

/// Lock `kept`, whatever a panicking holder left behind (the traces are still worth having).
pub fn lock(kept: &KeptTraces) -> MutexGuard<'_, Kept> {
    kept.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// A bench whose segments run with the caller-independent `stop` flag.
pub struct GuardedBench {
    inner: Box<dyn Bench>,
    stop: Arc<AtomicBool>,
    kept: KeptTraces,
}

impl GuardedBench {
    /// Guard `inner` with the shared `stop` flag, keeping traces into `kept` while it says so.
    pub fn new(inner: Box<dyn Bench>, stop: Arc<AtomicBool>, kept: KeptTraces) -> Self {
        Self { inner, stop, kept }
    }
}

impl Bench for GuardedBench {
    photorobot_core::forward_bench_queries!(inner);

    /// Run the segment with the shared stop flag in place of the caller's (a stop already
    /// requested refuses it at once), keeping its trace when keeping is on.
    fn run_segment(
        &mut self,
        segment: &TimedSegment,
        meta: TraceMeta,
        control: &mut RunControl<'_>,
    ) -> Result<Option<Trace>, BenchError> {
        let stop = self.stop.clone();
        if stop.load(Ordering::Relaxed) || control.cancelled() {
            return Err(BenchError::Cancelled { partial: None });
        }
        let mut shared =
            RunControl { cancel: &stop, on_samples: &mut *control.on_samples, on_progress: &mut *control.on_progress };
        let result = self.inner.run_segment(segment, meta, &mut shared);
        let mut kept = lock(&self.kept);
        if kept.on {
            match &result {
                Ok(Some(trace)) => kept.traces.push(trace.clone()),
                Err(e) => kept.traces.extend(e.partial().filter(|p| !p.is_empty()).cloned()),
                Ok(None) => {}
            }
        }
        result
    }
}

/// The text of a panic's payload (a `&str` or a `String`, as `panic!` makes them).
pub fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    payload
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "a panic without a message".into())
}
