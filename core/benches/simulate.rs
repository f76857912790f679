//! Benchmark: virtual-bench simulation throughput (target ≥ 10 M samples/s per core in release).
//! Run: `cargo bench -p photorobot-core --bench simulate`.

use criterion::{criterion_group, criterion_main, BatchSize, Criterion, Throughput};
use photorobot_core::bench::{run_plan, RunControl, VirtualBench};
use photorobot_core::plan::{JointTarget, Plan, Segment};
use std::sync::atomic::AtomicBool;

fn simulate(c: &mut Criterion) {
    // A combined translation + rotation move, with every joint moving. The default (fast) path
    // interpolates the slowly varying parts between exact nodes; the exact path, kept as the
    // reference, pays the full DGM, cavity and optics at every sample.
    let plan = Plan {
        name: "bench".into(),
        description: String::new(),
        segments: vec![Segment::Move {
            to: JointTarget::all([100.0, 20.0, 100.0, 3.0, -3.0, 10.0]),
            record: true,
            label: "move".into(),
            through: false,
        }],
    };
    let mut group = c.benchmark_group("virtual bench");
    group.sample_size(10);
    for (preset, exact) in [("table2-ideal", false), ("femto-lab", false), ("femto-lab", true)] {
        let mut probe = VirtualBench::from_preset_name(preset, None).unwrap();
        probe.set_exact(exact);
        let cancel = AtomicBool::new(false);
        let run = |b: &mut VirtualBench| {
            let mut control = RunControl { cancel: &cancel, on_samples: &mut |_, _| {}, on_progress: &mut |_| {} };
            run_plan(b, &plan, &mut control)
        };
        let samples = run(&mut probe).traces[0].len() as u64;
        group.throughput(Throughput::Elements(samples));
        let name = if exact {
            format!("{preset}: samples of a 6-joint move, exact path")
        } else {
            format!("{preset}: samples of a 6-joint move")
        };
        // The bench is built from its preset outside the timing: that is a one-off cost per
        // session, timed on its own below.
        let fresh = || {
            let mut bench = VirtualBench::from_preset_name(preset, None).unwrap();
            bench.set_exact(exact);
            bench
        };
        group.bench_function(name, |b| {
            b.iter_batched_ref(fresh, |bench| run(bench).traces.len(), BatchSize::SmallInput)
        });
    }
    group.throughput(Throughput::Elements(1));
    for preset in ["table2-ideal", "femto-lab"] {
        group.bench_function(format!("{preset}: build the bench from its preset"), |b| {
            b.iter(|| VirtualBench::from_preset_name(preset, None).unwrap().sample_period_s())
        });
    }
    group.finish();
}

criterion_group!(benches, simulate);
criterion_main!(benches);
