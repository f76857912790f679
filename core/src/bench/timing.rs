//! Where a run's time goes: each segment's planned and bench time, how long the controllers kept it
//! waiting and how long reading the recorder took, gathered by [`TimedBench`] around any bench.
//! Owns the timing records, their totals per run and per stage, and their lines in the log.

use super::{Bench, BenchError, RunControl};
use crate::plan::TimedSegment;
use crate::trace::{Trace, TraceMeta};
use serde::{Deserialize, Serialize};
use std::time::Instant;

/// How a bench on controllers spent one segment (bench time, s), as the bench measured it:
/// `setup_s + motion_s + finish_s` is the segment's bench time.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct SegmentBreakdown {
    /// From the segment's start to its motion command: speeds set, the sweep configured, the
    /// recorder armed.
    pub setup_s: f64,
    /// From the motion command to the end the controllers report (on target and settled; a
    /// sweep: the laser done).
    pub motion_s: f64,
    /// From that end to the segment's end: the rest of the recorder read, the arrival checked,
    /// the laser back at its wavelength.
    pub finish_s: f64,
    /// Reading the recorder, over the whole segment (during the motion too).
    pub recorder_s: f64,
    /// Of `recorder_s`, the part after the motion's end (what the reading adds to the segment).
    pub recorder_after_s: f64,
    /// The motion as the bench commanded it (a move: the slowest joint's straight ramp at its
    /// speed limit, then the settling time; a sweep: the plan's time). The plan's timing model
    /// ramps up and down at the acceleration limits, which stages with acceleration control off
    /// do not.
    #[serde(default)]
    pub commanded_s: f64,
    /// From the first move command to the last one's answer, when the move's joints are on
    /// several controllers (0 when they are on one): the controllers start one command after
    /// another, and for this long the joints did not move together along the planned line.
    #[serde(default)]
    pub start_spread_s: f64,
}

/// One segment as it ran.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SegmentTiming {
    /// The stage of the command it ran in ("measure", "validate").
    pub stage: String,
    /// The plan run it belongs to, counted from 0 over the whole command.
    pub run: usize,
    /// Its index in its plan.
    pub index: usize,
    /// Its label.
    pub label: String,
    /// True when it recorded a trace.
    pub record: bool,
    /// Its duration in the plan's timing model (s): the motion at the limits' speeds, settling
    /// included.
    pub planned_s: f64,
    /// The bench time it took (s).
    pub bench_s: f64,
    /// The wall time it took (s): on a virtual bench, the simulation's cost.
    pub wall_s: f64,
    /// The bench's own account of it (benches on controllers).
    pub breakdown: Option<SegmentBreakdown>,
}

impl SegmentTiming {
    /// Bench time (s) reading the recorder after the motion ended.
    pub fn recorder_after_s(&self) -> f64 {
        self.breakdown.map_or(0.0, |b| b.recorder_after_s)
    }

    /// Bench time (s) the controllers kept the segment waiting: everything beyond its planned
    /// motion except reading the recorder after it (setting up, reporting the end late,
    /// checking the arrival).
    pub fn waiting_s(&self) -> f64 {
        (self.bench_s - self.planned_s - self.recorder_after_s()).max(0.0)
    }
}

/// One stage of a command and its wall time.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StageTime {
    /// The stage ("measure", "identify", "validate").
    pub stage: String,
    /// Its wall time (s).
    pub wall_s: f64,
}

/// The totals of several segments (a plan run, a stage).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TimingTotals {
    /// What they are ("validation: circle …", "measure").
    pub name: String,
    /// How many segments.
    pub segments: usize,
    /// Sum of their planned durations (s).
    pub planned_s: f64,
    /// Sum of their bench times (s).
    pub bench_s: f64,
    /// Sum of the time the controllers kept them waiting (s).
    pub waiting_s: f64,
    /// Sum of the recorder's reading after their motions (s).
    pub recorder_after_s: f64,
    /// Sum of their wall times (s).
    pub wall_s: f64,
}

impl TimingTotals {
    fn add(&mut self, s: &SegmentTiming) {
        self.segments += 1;
        self.planned_s += s.planned_s;
        self.bench_s += s.bench_s;
        self.waiting_s += s.waiting_s();
        self.recorder_after_s += s.recorder_after_s();
        self.wall_s += s.wall_s;
    }
}

/// Where a command's time went: its stages' wall times and every segment it ran.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct RunTiming {
    /// The stages, in order.
    pub stages: Vec<StageTime>,
    /// Every segment, in order.
    pub segments: Vec<SegmentTiming>,
}

impl RunTiming {
    /// The totals of each plan run, in order, named by the label most of its recorded segments
    /// carry (a validation motion's name), or its last segment's.
    pub fn runs(&self) -> Vec<(String, TimingTotals)> {
        let mut out: Vec<(String, TimingTotals)> = Vec::new();
        let mut i = 0;
        while i < self.segments.len() {
            let run = &self.segments[i];
            let end = i + self.segments[i..].iter().take_while(|s| s.run == run.run).count();
            let part = &self.segments[i..end];
            let mut totals = TimingTotals { name: run_name(part), ..TimingTotals::default() };
            part.iter().for_each(|s| totals.add(s));
            out.push((run.stage.clone(), totals));
            i = end;
        }
        out
    }

    /// The totals of each stage that ran segments, in order of first appearance.
    pub fn stage_totals(&self) -> Vec<TimingTotals> {
        let mut out: Vec<TimingTotals> = Vec::new();
        for s in &self.segments {
            match out.iter_mut().find(|t| t.name == s.stage) {
                Some(t) => t.add(s),
                None => {
                    let mut t = TimingTotals { name: s.stage.clone(), ..TimingTotals::default() };
                    t.add(s);
                    out.push(t);
                }
            }
        }
        out
    }
}

/// The label most of a run's recorded segments carry, else its last segment's.
fn run_name(part: &[SegmentTiming]) -> String {
    let mut counts: Vec<(&str, usize)> = Vec::new();
    for s in part.iter().filter(|s| s.record) {
        match counts.iter_mut().find(|(l, _)| *l == s.label) {
            Some((_, n)) => *n += 1,
            None => counts.push((&s.label, 1)),
        }
    }
    let most = counts.iter().max_by_key(|(_, n)| *n).map(|(l, _)| l.to_string());
    most.or_else(|| part.last().map(|s| s.label.clone())).unwrap_or_default()
}

/// A bench that times every segment run through it, in the stage its caller names: it forwards
/// everything to the bench it wraps.
pub struct TimedBench<'a> {
    inner: &'a mut dyn Bench,
    stage: String,
    run: usize,
    last_index: Option<usize>,
    timing: RunTiming,
}

impl<'a> TimedBench<'a> {
    /// Time the segments run on `inner`, in stage `stage` until [`Self::set_stage`].
    pub fn new(inner: &'a mut dyn Bench, stage: &str) -> Self {
        TimedBench { inner, stage: stage.to_string(), run: 0, last_index: None, timing: RunTiming::default() }
    }

    /// The stage the next segments run in; its previous plan run ends here.
    pub fn set_stage(&mut self, stage: &str) {
        self.stage = stage.to_string();
        self.last_index = None;
    }

    /// Log the totals of each run and stage (info) and hand the timing back.
    pub fn finish(self) -> RunTiming {
        for (stage, t) in self.timing.runs() {
            log_totals(&format!("{stage}: {}", t.name), &t);
        }
        for t in self.timing.stage_totals() {
            log_totals(&t.name, &t);
        }
        self.timing
    }

    /// The timing so far.
    pub fn timing(&self) -> &RunTiming {
        &self.timing
    }
}

fn log_totals(what: &str, t: &TimingTotals) {
    tracing::info!(
        segments = t.segments,
        planned_s = t.planned_s,
        bench_s = t.bench_s,
        waiting_s = t.waiting_s,
        recorder_after_s = t.recorder_after_s,
        wall_s = t.wall_s,
        "timed: {what}"
    );
}

impl Bench for TimedBench<'_> {
    crate::forward_bench_queries!(inner);

    fn run_segment(
        &mut self,
        segment: &TimedSegment,
        meta: TraceMeta,
        control: &mut RunControl<'_>,
    ) -> Result<Option<Trace>, BenchError> {
        // A plan starts again at its first segment: a new run.
        if self.last_index.is_some_and(|last| segment.index <= last) {
            self.run += 1;
        }
        if self.last_index.is_none() && !self.timing.segments.is_empty() {
            self.run += 1;
        }
        self.last_index = Some(segment.index);
        let (t0, wall0) = (self.inner.clock_s(), Instant::now());
        let out = self.inner.run_segment(segment, meta, control);
        let timing = SegmentTiming {
            stage: self.stage.clone(),
            run: self.run,
            index: segment.index,
            label: segment.label.clone(),
            record: segment.record,
            planned_s: self.inner.last_breakdown().map_or(segment.duration_s, |b| b.commanded_s),
            bench_s: self.inner.clock_s() - t0,
            wall_s: wall0.elapsed().as_secs_f64(),
            breakdown: self.inner.last_breakdown(),
        };
        let b = timing.breakdown.unwrap_or_default();
        tracing::debug!(
            stage = %timing.stage,
            run = timing.run,
            index = timing.index,
            planned_s = timing.planned_s,
            bench_s = timing.bench_s,
            waiting_s = timing.waiting_s(),
            setup_s = b.setup_s,
            motion_s = b.motion_s,
            finish_s = b.finish_s,
            recorder_s = b.recorder_s,
            recorder_after_s = b.recorder_after_s,
            wall_s = timing.wall_s,
            "segment timed: {}",
            timing.label
        );
        self.timing.segments.push(timing);
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bench::{run_plan, BenchPreset, VirtualBench};
    use crate::plan::{JointTarget, Plan, Segment};
    use std::sync::atomic::AtomicBool;

    fn plan(name: &str, label: &str, moves: usize) -> Plan {
        let segments = (0..moves)
            .map(|k| {
                let mut q = [0.0; 6];
                q[0] = 5.0 * (k + 1) as f64;
                Segment::Move { to: JointTarget::all(q), record: true, label: label.into(), through: false }
            })
            .collect();
        Plan { name: name.into(), description: String::new(), segments }
    }

    /// Every segment run through the wrapper is timed in its stage and run; runs are told apart
    /// where a plan starts again, named by their recorded segments' label; the totals add up.
    #[test]
    fn segments_are_timed_in_their_stage_and_run() {
        let preset = BenchPreset::resolve("table2-ideal").unwrap();
        let mut virt = VirtualBench::new(&preset, Some(3)).unwrap();
        let cancel = AtomicBool::new(false);
        let mut timed = TimedBench::new(&mut virt, "measure");
        let run = |bench: &mut TimedBench<'_>, p: &Plan| {
            let mut control = RunControl { cancel: &cancel, on_samples: &mut |_, _| {}, on_progress: &mut |_| {} };
            run_plan(bench, p, &mut control).outcome.unwrap();
        };
        run(&mut timed, &plan("a", "first", 2));
        timed.set_stage("validate");
        run(&mut timed, &plan("b", "second", 3));
        run(&mut timed, &plan("c", "third", 1));
        let timing = timed.finish();
        assert_eq!(timing.segments.len(), 6);
        let runs = timing.runs();
        let names: Vec<(&str, &str, usize)> =
            runs.iter().map(|(stage, t)| (stage.as_str(), t.name.as_str(), t.segments)).collect();
        assert_eq!(names, [("measure", "first", 2), ("validate", "second", 3), ("validate", "third", 1)]);
        for s in &timing.segments {
            // The virtual bench's clock is the timing model's.
            assert!((s.bench_s - s.planned_s).abs() < 1e-9, "{s:?}");
            assert!(s.planned_s > 0.0 && s.breakdown.is_none() && s.waiting_s() == 0.0);
        }
        let stages = timing.stage_totals();
        assert_eq!(
            stages.iter().map(|t| (t.name.as_str(), t.segments)).collect::<Vec<_>>(),
            [("measure", 2), ("validate", 4)]
        );
        let sum: f64 = timing.segments[2..].iter().map(|s| s.bench_s).sum();
        assert!((stages[1].bench_s - sum).abs() < 1e-12);
    }

    /// What the controllers cost beyond the planned motion is the waiting, less the recorder's
    /// reading after the motion.
    #[test]
    fn waiting_is_the_bench_time_beyond_the_motion_and_the_reading() {
        let s = SegmentTiming {
            stage: "validate".into(),
            run: 0,
            index: 3,
            label: "circle".into(),
            record: true,
            planned_s: 0.2,
            bench_s: 0.9,
            wall_s: 0.9,
            breakdown: Some(SegmentBreakdown {
                setup_s: 0.3,
                motion_s: 0.35,
                finish_s: 0.25,
                recorder_s: 0.2,
                recorder_after_s: 0.15,
                commanded_s: 0.2,
                start_spread_s: 0.0,
            }),
        };
        assert!((s.waiting_s() - 0.55).abs() < 1e-12);
        assert_eq!(s.recorder_after_s(), 0.15);
    }
}
