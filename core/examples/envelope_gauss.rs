//! Debug: tracker error on a clean two-beam signal whose fringe amplitude B varies along the
//! path like a Gaussian (as on a ±4° goniometer scan, where the tilt coupling exp(-(k·w0·θ)²/2)
//! changes B by up to 50 % per fringe). Exact hint, white noise 3.5e-6 (virtual bench level).
//! `cargo run --release -p photorobot-core --example envelope_gauss`
use photorobot_core::fringes::{track_phase, TrackConfig};
use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

fn main() {
    let (wl, n_air) = (1560.0, 1.000268);
    let kappa = 4.0 * std::f64::consts::PI * n_air / wl;
    let n = 40_000;
    let total = 14_000.0;
    for (w, centre) in [(1e9, 0.5), (0.5, 0.5), (0.35, 0.5)] {
        let mut rng = StdRng::seed_from_u64(1);
        let noise = Normal::new(0.0, 3.5e-6).unwrap();
        let dl: Vec<f64> = (0..n).map(|i| total * i as f64 / (n - 1) as f64).collect();
        let y: Vec<f64> = dl
            .iter()
            .map(|&d| {
                let p = d / total;
                let b = 0.0047 * (-((p - centre) / w).powi(2)).exp();
                0.036 + b * (kappa * d + 0.7).cos() + noise.sample(&mut rng)
            })
            .collect();
        let cfg = TrackConfig {
            envelope_walk_per_sqrt_fringe: 0.003,
            phase_walk_rad_per_sqrt_fringe: 0.005,
            ..TrackConfig::default()
        };
        match track_phase(&y, &dl, wl, n_air, &cfg) {
            Ok(tr) => {
                let errs: Vec<String> =
                    (0..=20).map(|k| format!("{:.2}", tr.dl_nm[k * (n - 1) / 20] - dl[k * (n - 1) / 20])).collect();
                println!("Gaussian width {w} of the path: error (nm) every 5 %: {}", errs.join(" "));
            }
            Err(e) => println!("Gaussian width {w}: {e}"),
        }
    }
}
