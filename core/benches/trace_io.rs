//! Criterion benchmark of reading a trace CSV (a million rows, the size of a long recording):
//! streamed through the `csv` crate's reader, and from memory (a whole file's bytes, as files are read).
//! Owns nothing but timings: `cargo bench -p photorobot-core --bench trace_io`.

use criterion::{criterion_group, criterion_main, Criterion};
use photorobot_core::trace::{ReadOptions, Trace, TraceMeta};
use std::hint::black_box;
use std::path::Path;

const ROWS: usize = 1_000_000;

/// A million rows of a translation with a slow goniometer wobble and a fringe-like signal.
fn csv_bytes() -> Vec<u8> {
    let mut t = Trace::with_capacity(TraceMeta::default(), ROWS);
    for i in 0..ROWS {
        let x = i as f64 * 1e-3;
        let q = [-150.0 + 3e-4 * i as f64, 0.0, 12.5, 0.0, 1.0 + x.sin() * 1e-3, 0.0];
        t.push_sample(x, q, 1560.0, 0.5 + 0.4 * (x * 7.0).cos());
    }
    t.to_csv_bytes(Path::new("speed.csv")).unwrap()
}

fn read(c: &mut Criterion) {
    let bytes = csv_bytes();
    let mut group = c.benchmark_group("trace_io");
    group.sample_size(10);
    group.throughput(criterion::Throughput::Elements(ROWS as u64));
    group.bench_function("read_csv_1M_rows", |b| {
        b.iter(|| Trace::from_csv_reader(black_box(&bytes[..]), Path::new("speed.csv")).unwrap().len())
    });
    group.bench_function("read_csv_bytes_1M_rows", |b| {
        b.iter(|| {
            Trace::from_csv_bytes(black_box(&bytes), Path::new("speed.csv"), &ReadOptions::default()).unwrap().len()
        })
    });
    group.finish();
}

criterion_group!(benches, read);
criterion_main!(benches);
