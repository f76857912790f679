//! A run killed mid-strategy (a simulated crash: the process panics inside the bench after a
//! few segments) loses no completed step: every trace measured before the crash is recovered
//! bit for bit from the autosave, and the measurement resumes from there to the end.

use photorobot_core::bench::{Bench, BenchError, BenchPreset, RunControl, VirtualBench};
use photorobot_core::plan::{Plan, TimedSegment};
use photorobot_core::session::recording::record;
use photorobot_core::session::{find_recovery, BenchInfo, Session, SessionWriter};
use photorobot_core::trace::{Trace, TraceMeta};
use std::path::Path;
use std::sync::atomic::AtomicBool;

/// A virtual bench that crashes (panics, as a killed process stops) when asked to run its
/// `crash_at`-th segment, and keeps a copy of every trace it returned.
struct CrashingBench {
    inner: VirtualBench,
    segments_run: usize,
    crash_at: usize,
    returned: Vec<Trace>,
}

impl Bench for CrashingBench {
    photorobot_core::forward_bench_queries!(inner);

    fn run_segment(
        &mut self,
        segment: &TimedSegment,
        meta: TraceMeta,
        control: &mut RunControl<'_>,
    ) -> Result<Option<Trace>, BenchError> {
        if self.segments_run == self.crash_at {
            panic!("simulated crash in segment {}", self.segments_run);
        }
        self.segments_run += 1;
        let t = self.inner.run_segment(segment, meta, control)?;
        self.returned.extend(t.clone());
        Ok(t)
    }
}

fn plan(name: &str, text: &str) -> Plan {
    Plan::from_ron_str(text, Path::new(name)).unwrap()
}

/// Two short plans: 7 recorded steps in all (moves and sweeps), 2 unrecorded moves.
fn plans() -> Vec<Plan> {
    vec![
        plan(
            "a.ron",
            r#"Plan(name: "a", segments: [
                Move(to: (q1_um: 0.0, q2_um: 0.0, q3_um: -20.0, q4_deg: 0.0, q5_deg: 0.0, q6_deg: 0.0), record: false, label: "setup a"),
                Sweep(from_nm: 1555.0, to_nm: 1565.0, rate_nm_per_s: 5.0, label: "a sweep before"),
                Move(to: (q3_um: 20.0), label: "a X_w +40 µm"),
                Sweep(from_nm: 1555.0, to_nm: 1565.0, rate_nm_per_s: 5.0, label: "a sweep after"),
                Move(to: (q2_um: 5.0), label: "a Y_w +5 µm"),
            ])"#,
        ),
        plan(
            "b.ron",
            r#"Plan(name: "b", segments: [
                Move(to: (q1_um: -20.0, q2_um: 0.0, q3_um: 0.0), record: false, label: "setup b"),
                Move(to: (q1_um: 20.0), label: "b Z_w +40 µm"),
                Move(to: (q2_um: -5.0), label: "b Y_w -10 µm"),
                Dwell(duration_s: 0.2, label: "b dwell"),
            ])"#,
        ),
    ]
}

fn new_session(bench: &dyn Bench) -> Session {
    let info = BenchInfo { name: bench.name(), preset: Some("table2-ideal".into()), description: None, seed: Some(11) };
    let mut session = Session::new(info, bench.robot().clone());
    session.plans = plans();
    session
}

fn virtual_bench() -> VirtualBench {
    VirtualBench::new(&BenchPreset::resolve("table2-ideal").unwrap(), Some(11)).unwrap()
}

#[test]
fn a_crash_mid_strategy_loses_no_completed_step_and_the_run_resumes() {
    let recorded_steps: usize = plans().iter().map(|p| p.segments.iter().filter(|s| s.is_recorded()).count()).sum();
    assert_eq!(recorded_steps, 7, "the test plans record 7 steps");
    let cancel = AtomicBool::new(false);
    // Crash in each plan: in the middle of plan "a" (segment 3) and in plan "b" (segment 7 of 9).
    for crash_at in [3usize, 7] {
        let dir = tempfile::tempdir().unwrap();
        let mut bench = CrashingBench { inner: virtual_bench(), segments_run: 0, crash_at, returned: vec![] };
        let mut session = SessionWriter::new(dir.path(), new_session(&bench));
        let crashed = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            let mut control = RunControl { cancel: &cancel, on_samples: &mut |_, _| {}, on_progress: &mut |_| {} };
            record(&mut bench, &mut session, &mut control)
        }));
        assert!(crashed.is_err(), "the bench crashed");
        let completed = bench.returned.clone();
        assert!(
            !completed.is_empty() && completed.len() < recorded_steps,
            "{} steps before the crash",
            completed.len()
        );
        drop(session); // the crashed process's memory is gone

        // Recovery is offered, and it holds every completed step, bit for bit.
        let offer = find_recovery(dir.path()).unwrap().expect("an autosave to recover");
        assert_eq!(offer.traces, completed.len());
        assert!(!offer.saved_session_exists);
        let recovered = Session::recover(dir.path()).unwrap();
        assert_eq!(recovered.load_traces(dir.path()).unwrap(), completed, "crash at segment {crash_at}");
        // The folder cannot be opened as a saved session, and says why.
        let err = Session::load(dir.path()).unwrap_err().to_string();
        assert!(err.contains("a measurement did not finish"), "{err}");

        // Resume on a fresh bench (the old one is gone with the crash) and finish.
        let mut fresh = virtual_bench();
        let mut control = RunControl { cancel: &cancel, on_samples: &mut |_, _| {}, on_progress: &mut |_| {} };
        let mut recovered = SessionWriter::new(dir.path(), recovered);
        let done = record(&mut fresh, &mut recovered, &mut control).unwrap();
        done.outcome.unwrap();
        assert!(recovered.session().measured());
        recovered.save().unwrap();
        assert_eq!(find_recovery(dir.path()).unwrap(), None, "nothing left to recover after saving");

        // Every recorded step of both plans, once, in plan order, the crashed ones unchanged.
        let all = Session::load(dir.path()).unwrap();
        let traces = all.load_traces(dir.path()).unwrap();
        assert_eq!(traces.len(), recorded_steps);
        assert_eq!(&traces[..completed.len()], &completed[..]);
        let labels: Vec<&str> = traces.iter().map(|t| t.meta.label.as_str()).collect();
        let expected: Vec<&str> =
            all.plans.iter().flat_map(|p| p.segments.iter().filter(|s| s.is_recorded()).map(|s| s.label())).collect();
        assert_eq!(labels, expected);
        let steps: Vec<(usize, usize)> = all.traces.iter().map(|r| r.step.unwrap()).collect();
        assert_eq!(steps, [(0, 1), (0, 2), (0, 3), (0, 4), (1, 1), (1, 2), (1, 3)]);
        // The resumed step starts where the plan says it starts.
        let resumed = &traces[completed.len()];
        let from = |t: &Trace| t.joints_display(0);
        let again = {
            let mut uninterrupted_bench = virtual_bench();
            let uninterrupted_dir = tempfile::tempdir().unwrap();
            let mut uninterrupted = SessionWriter::new(uninterrupted_dir.path(), new_session(&uninterrupted_bench));
            let mut control = RunControl { cancel: &cancel, on_samples: &mut |_, _| {}, on_progress: &mut |_| {} };
            record(&mut uninterrupted_bench, &mut uninterrupted, &mut control).unwrap().outcome.unwrap();
            uninterrupted.session().load_traces(uninterrupted_dir.path()).unwrap()
        };
        for (k, (a, b)) in from(resumed).iter().zip(from(&again[completed.len()])).enumerate() {
            assert!((a - b).abs() < 0.05, "joint {k}: resumed step starts at {a}, uninterrupted at {b}");
        }
    }
}
