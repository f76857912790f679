//! The whole analysis of a session's traces, as `photorobot calibrate --traces` and the GUI's
//! Identify run it: `report_from_traces` (every sweep and motion analysed, every start of the
//! identification carried through its passes, the report) in joint mode, on the traces of a
//! short plan (`tests/fixtures/small-plan.ron`: 4 sweeps, 3 translations, 2 rotations, about a
//! minute of bench time) recorded on a `table2-ideal` virtual bench, seed 7.
//! `cargo bench -p photorobot-core --bench session`; target < 1 s.

use criterion::{criterion_group, criterion_main, Criterion};
use photorobot_core::bench::{BenchPreset, VirtualBench};
use photorobot_core::calibration::{measure, report_from_traces, Mode};
use photorobot_core::model::extrinsics::Extrinsics;
use photorobot_core::model::phase::PhaseModel;
use photorobot_core::plan::Plan;
use std::path::Path;

const PLAN: &str = include_str!("../../tests/fixtures/small-plan.ron");

fn session(c: &mut Criterion) {
    let preset = BenchPreset::resolve("table2-ideal").unwrap();
    let plan = Plan::from_ron_str(PLAN, Path::new("small-plan.ron")).unwrap();
    let mut bench = VirtualBench::new(&preset, Some(7)).unwrap();
    let (traces, duration_s) = measure(&mut bench, &[plan]).unwrap();
    let nominal = PhaseModel::of_preset(&preset, Extrinsics::nominal_design()).unwrap();
    let samples: usize = traces.iter().map(|t| t.len()).sum();
    let check = report_from_traces(traces.clone(), duration_s, "bench".into(), &nominal, Mode::Joint).unwrap();
    assert!(check.converged, "{}", check.termination);
    eprintln!("{} traces, {samples} samples, {} observations", traces.len(), check.observations);
    c.bench_function(&format!("report_from_traces, {} traces, {samples} samples", traces.len()), |b| {
        b.iter(|| report_from_traces(traces.clone(), duration_s, "bench".into(), &nominal, Mode::Joint))
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10);
    targets = session
}
criterion_main!(benches);
