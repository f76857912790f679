//! Benchmarks of the fringe analysis: phase tracking and extremum counting on 1 M-sample traces.
//! Traces are synthetic two-beam signals: a dense back-and-forth scan (worst case) and a calibration-like move.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use photorobot_core::measure::extrema::{count_extrema, CountDirection, HysteresisConfig};
use photorobot_core::measure::signal::TwoBeamSignal;
use photorobot_core::measure::track::{track_phase, PhaseTracker, TrackConfig};
use rand::rngs::StdRng;
use rand::SeedableRng;
use std::hint::black_box;

const N: usize = 1_000_000;
const WL: f64 = 1560.0;
const N_AIR: f64 = 1.000_268;

struct Trace {
    intensity: Vec<f64>,
    hint: Vec<f64>,
}

fn render(dl: &[f64], seed: u64) -> Trace {
    let offset: Vec<f64> = dl.iter().map(|d| 1.0 - 2e-6 * d).collect();
    let amplitude: Vec<f64> = dl.iter().map(|d| 0.2 * (1.0 - 5e-6 * d)).collect();
    let signal = TwoBeamSignal {
        wavelength_nm: WL,
        n_air: N_AIR,
        gap_start_nm: 900_000.0,
        rayleigh_range_nm: Some(54_000.0),
        phase_offset_rad: 0.7,
        harmonic_rel: 0.02,
        harmonic_phase_rad: 0.6,
        noise_sigma: 2e-4,
    };
    let mut rng = StdRng::seed_from_u64(seed);
    let intensity = signal.render(dl, &offset, &amplitude, &mut rng).expect("valid synthetic trace");
    let hint = dl.iter().map(|d| 1.03 * d + 37.0).collect();
    Trace { intensity, hint }
}

/// Worst case: ±10 µm sinusoidal back-and-forth, ~40 samples per fringe at full speed,
/// 500 turning points, 25 000 fringes in 1 M samples.
fn dense() -> Trace {
    let dl: Vec<f64> = (0..N).map(|k| 10_000.0 * (1.0 - (std::f64::consts::TAU * k as f64 / 4000.0).cos())).collect();
    render(&dl, 1)
}

/// Calibration-like: pause, smooth 20 µm move, pause (~51 fringes in 1 M samples).
fn calibration() -> Trace {
    let dl: Vec<f64> = (0..N)
        .map(|k| {
            let x = ((k as f64 / N as f64 - 0.1) / 0.8).clamp(0.0, 1.0);
            20_000.0 * x * x * (3.0 - 2.0 * x)
        })
        .collect();
    render(&dl, 2)
}

fn bench_fringes(c: &mut Criterion) {
    let cfg = TrackConfig::default();
    for (name, t) in [("dense", dense()), ("calibration", calibration())] {
        let mut g = c.benchmark_group(format!("fringes_1M_{name}"));
        g.throughput(Throughput::Elements(N as u64));
        g.sample_size(20);
        g.bench_function("track_phase", |b| {
            b.iter(|| {
                track_phase(black_box(&t.intensity), black_box(&t.hint), WL, N_AIR, &cfg).expect("tracking succeeds")
            })
        });
        let mut tracker = PhaseTracker::new(WL, N_AIR, cfg).expect("valid configuration");
        g.bench_function("PhaseTracker::track", |b| {
            b.iter(|| {
                tracker.track(black_box(&t.intensity), black_box(&t.hint)).expect("tracking succeeds").total_dl_nm
            })
        });
        g.bench_function("count_extrema_hint", |b| {
            b.iter(|| {
                count_extrema(
                    black_box(&t.intensity),
                    CountDirection::Hint(black_box(&t.hint)),
                    WL,
                    N_AIR,
                    &HysteresisConfig::default(),
                )
                .expect("counting succeeds")
            })
        });
        g.finish();
    }
}

criterion_group!(benches, bench_fringes);
criterion_main!(benches);
