//! Debug: tracker error on a clean two-beam signal whose fringe amplitude B varies along the
//! path like a Gaussian (as on a ±4° goniometer scan, where the tilt coupling exp(-(k·w0·θ)²/2)
//! changes B by up to 50 % per fringe). Exact hint, white noise 3.5e-6 (virtual bench level).
//! `cargo run --release -p photorobot-core --example envelope_gauss`
use photorobot_core::measure::track::{track_phase, TrackConfig};
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
                0.036
                    + b * (kappa * d + std::env::var("PH0").map_or(0.7, |v| v.parse().unwrap())).cos()
                    + noise.sample(&mut rng)
            })
            .collect();
        let cfg = TrackConfig {
            envelope_walk_per_sqrt_fringe: std::env::var("EW").map_or(0.003, |v| v.parse().unwrap()),
            phase_walk_rad_per_sqrt_fringe: std::env::var("PW").map_or(0.005, |v| v.parse().unwrap()),
            ..TrackConfig::default()
        };
        match track_phase(&y, &dl, wl, n_air, &cfg) {
            Ok(tr) => {
                let errs: Vec<String> =
                    (0..=20).map(|k| format!("{:.2}", tr.dl_nm[k * (n - 1) / 20] - dl[k * (n - 1) / 20])).collect();
                println!("Gaussian width {w} of the path: error (nm) every 5 %: {}", errs.join(" "));
                if std::env::var("ENDS").is_ok() {
                    let idx = |k: usize| k;
                    let start: Vec<String> =
                        (0..=16).map(|k| format!("{:.2}", tr.dl_nm[idx(k * 250)] - dl[idx(k * 250)])).collect();
                    let end: Vec<String> = (0..=16)
                        .map(|k| format!("{:.2}", tr.dl_nm[n - 1 - (16 - k) * 250] - dl[n - 1 - (16 - k) * 250]))
                        .collect();
                    println!("  first 4000 samples every 250: {}", start.join(" "));
                    println!("  last 4000 samples every 250: {}", end.join(" "));
                    println!("  warnings {:?} chi2 {:.3} iters {}", tr.warnings, tr.normalized_chi2, tr.iterations);
                }
            }
            Err(e) => println!("Gaussian width {w}: {e}"),
        }
    }
}
