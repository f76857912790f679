//! Benchmark: virtual-bench simulation throughput (target ≥ 10 M samples/s per core in release).
//! Run: `cargo bench -p photorobot-core --bench simulate`.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use photorobot_core::bench::{run_plan, RunControl, VirtualBench};
use photorobot_core::plan::{JointTarget, Plan, Segment};
use std::sync::atomic::AtomicBool;

fn simulate(c: &mut Criterion) {
    // A combined translation + rotation move: every sample pays the full DGM, cavity and optics.
    let plan = Plan {
        name: "bench".into(),
        description: String::new(),
        segments: vec![Segment::Move {
            to: JointTarget::all([100.0, 20.0, 100.0, 3.0, -3.0, 10.0]),
            record: true,
            label: "move".into(),
        }],
    };
    let mut group = c.benchmark_group("virtual bench");
    group.sample_size(10);
    for preset in ["table2-ideal", "femto-lab"] {
        let mut probe = VirtualBench::from_preset_name(preset, None).unwrap();
        let cancel = AtomicBool::new(false);
        let run = |b: &mut VirtualBench| {
            let mut control = RunControl { cancel: &cancel, on_samples: &mut |_, _| {}, on_progress: &mut |_| {} };
            run_plan(b, &plan, &mut control)
        };
        let samples = run(&mut probe).traces[0].len() as u64;
        group.throughput(Throughput::Elements(samples));
        group.bench_function(format!("{preset}: samples of a 6-joint move"), |b| {
            b.iter(|| {
                let mut bench = VirtualBench::from_preset_name(preset, None).unwrap();
                run(&mut bench).traces.len()
            })
        });
    }
    group.finish();
}

criterion_group!(benches, simulate);
criterion_main!(benches);
