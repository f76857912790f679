//! Benchmark: direct geometric model plus signed cavity length per pose (target < 200 ns in release).
//! Run: `cargo bench -p photorobot-core --bench kinematics`.

use criterion::{criterion_group, criterion_main, Criterion};
use photorobot_core::model::extrinsics::Extrinsics;
use photorobot_core::model::kinematics::Chain;
use std::hint::black_box;

fn dgm_and_cavity_length(c: &mut Criterion) {
    let chain = Chain::femto_6dof();
    let e = Extrinsics::table2();
    let geometry = e.geometry();
    // A small set of poses so the branch predictor and caches see varied input.
    let poses: Vec<[f64; 6]> = (0..64)
        .map(|i| {
            let s = i as f64 / 64.0 - 0.5;
            [100.0 * s, -80.0 * s, 60.0 * s, 0.1 * s, -0.08 * s, 0.5 * s]
        })
        .collect();
    let mut k = 0;
    c.bench_function("dgm + cavity length per pose", |b| {
        b.iter(|| {
            k = (k + 1) & 63;
            let wte = chain.end_effector(black_box(&poses[k]));
            black_box(e.cavity_length_um(&wte, &geometry))
        })
    });
    c.bench_function("dgm + full cavity (L, P_r in world and tool) per pose", |b| {
        b.iter(|| {
            k = (k + 1) & 63;
            let wte = chain.end_effector(black_box(&poses[k]));
            black_box(e.cavity(&wte).map(|c| c.length_um))
        })
    });
}

criterion_group!(benches, dgm_and_cavity_length);
criterion_main!(benches);
