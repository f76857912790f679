//! Debug: the fundamental's phase of the exact multi-beam signal (Fourier projection over one
//! fringe at fixed tilt) against `FabryPerot::fringe_phase_rad`, along tilt at a 900 µm gap.
//! `cargo run --release -p photorobot-core --example phase_pulling`
use photorobot_core::bench::BenchPreset;
use photorobot_core::model::optics::FabryPerot;
use std::f64::consts::PI;

fn main() {
    let preset = BenchPreset::resolve("table2-ideal").unwrap();
    let n_air = 1.000268;
    let fp = FabryPerot::new(&preset.optics, 1560.0, n_air).unwrap();
    let k = fp.wavenumber_per_um();
    for gap in [100.0, 900.0] {
        println!("gap {gap} µm");
        for i in 0..=20 {
            let theta = 0.005 * i as f64;
            // one period of Φ = k·L·(2 - θ²)
            let period = 2.0 * PI / (k * (2.0 - theta * theta));
            let n = 256;
            let (mut re, mut im) = (0.0, 0.0);
            for j in 0..n {
                let l = gap + period * j as f64 / n as f64;
                let p = fp.power(l, theta);
                let ph = fp.fringe_phase_rad(l, theta);
                re += p * ph.cos();
                im += p * ph.sin();
            }
            // P ≈ A + B·cos(φ_model + e): projection gives e
            let e = im.atan2(re);
            let amp = 2.0 * (re * re + im * im).sqrt() / n as f64;
            println!(
                "  θ {:.3} rad: fundamental phase - model {:+.4} rad = {:+.3} nm, amplitude {:.3e}",
                theta,
                -e,
                -e / (2.0 * k) * 1e3,
                amp
            );
        }
    }
}
