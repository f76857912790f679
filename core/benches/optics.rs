//! Criterion benchmark of the Fabry-Perot signal model (the virtual bench's hot path).
//! Owns nothing but timings: `cargo bench -p photorobot-core --bench optics`.

use criterion::{criterion_group, criterion_main, Criterion};
use photorobot_core::model::optics::{reflected_power, BackFace, FabryPerot, OpticalParams};
use std::hint::black_box;

const GAPS: usize = 1024;

fn gaps() -> Vec<f64> {
    (0..GAPS).map(|i| -898.83 + 0.0137 * i as f64).collect()
}

fn power(c: &mut Criterion) {
    let gaps = gaps();
    for (name, params, tilt) in [
        ("power_4_beams_square", OpticalParams::default(), 0.0),
        ("power_4_beams_tilted", OpticalParams::default(), 0.0195),
        (
            "power_4_beams_back_face",
            OpticalParams { back_face: Some(BackFace::default()), ..OpticalParams::default() },
            0.0195,
        ),
        ("power_1_beam", OpticalParams { beams: 1, ..OpticalParams::default() }, 0.0195),
    ] {
        let fp = FabryPerot::new(&params, 1560.0, 1.000268).unwrap();
        c.bench_function(&format!("{name} (x{GAPS})"), |b| {
            b.iter(|| {
                let mut sum = 0.0;
                for &g in &gaps {
                    sum += fp.power(black_box(g), black_box(tilt));
                }
                sum
            })
        });
    }
    let params = OpticalParams::default();
    c.bench_function(&format!("reflected_power_with_construction (x{GAPS})"), |b| {
        b.iter(|| {
            let mut sum = 0.0;
            for &g in &gaps {
                sum += reflected_power(&params, black_box(g), 0.0195, 1560.0, 1.000268).unwrap();
            }
            sum
        })
    });
}

criterion_group!(benches, power);
criterion_main!(benches);
