//! Debug: tracker error on exact multi-beam signals along a bench motion, vs beam count.
//! `cargo run --release -p photorobot-core --example tracker_multibeam -- [q2]`; TRACE_CSV replaces
//! the bench trace, EW/PW set the tracker's walks, BENCH_NOISE adds noise to the model signals.
use photorobot_core::bench::{run_plan, BenchPreset, RunControl, VirtualBench};
use photorobot_core::measure::track::{self, TrackConfig};
use photorobot_core::model::optics::FabryPerot;
use photorobot_core::model::phase::PhaseModel;
use photorobot_core::plan::{JointTarget, Plan, Segment};
use photorobot_core::trace::Trace;
use std::sync::atomic::AtomicBool;

/// Runs a noiseless sweep of axis 1 from -150 to 150 at axis 2 = `q2` and returns the recorded trace.
fn simulate_sweep(preset: &BenchPreset, q2: f64) -> Trace {
    let mut p = preset.clone();
    p.detector.white_noise_rel_fringe = 0.0;
    let mut bench = VirtualBench::new(&p, Some(3)).unwrap();
    let plan = Plan {
        name: "t".into(),
        description: String::new(),
        segments: vec![
            Segment::Move {
                to: JointTarget::all([-150.0, q2, 0.0, 0.0, 0.0, 0.0]),
                record: false,
                label: "s".into(),
                through: false,
            },
            Segment::Move {
                to: JointTarget::all([150.0, q2, 0.0, 0.0, 0.0, 0.0]),
                record: true,
                label: "Z".into(),
                through: false,
            },
        ],
    };
    let cancel = AtomicBool::new(false);
    let mut control = RunControl { cancel: &cancel, on_samples: &mut |_, _| {}, on_progress: &mut |_| {} };
    let mut run = run_plan(&mut bench, &plan, &mut control);
    run.traces.swap_remove(0)
}

/// The tracker configuration: per-sample σ, walks from EW and PW when set.
fn track_config() -> TrackConfig {
    TrackConfig {
        per_sample_sigma: true,
        envelope_walk_per_sqrt_fringe: std::env::var("EW").ok().and_then(|v| v.parse().ok()).unwrap_or(0.003),
        phase_walk_rad_per_sqrt_fringe: std::env::var("PW").ok().and_then(|v| v.parse().ok()).unwrap_or(0.005),
        ..TrackConfig::default()
    }
}

/// What every signal is tracked against: the true path difference along the motion.
struct Reference<'a> {
    truth: &'a [f64],
    n: usize,
    n_air: f64,
    cfg: &'a TrackConfig,
}

impl Reference<'_> {
    /// Tracks `y` and prints the harmonic, χ², scale, σ and the error at 21 points.
    fn report(&self, name: &str, y: &[f64]) {
        let (truth, n) = (self.truth, self.n);
        let tr = match track::track_phase(y, truth, 1560.0, self.n_air, self.cfg) {
            Ok(t) => t,
            Err(e) => {
                println!("{name}: {e}");
                return;
            }
        };
        let errs: Vec<String> =
            (0..=20).map(|k| format!("{:.2}", tr.dl_nm[k * (n - 1) / 20] - truth[k * (n - 1) / 20])).collect();
        println!(
            "{name}: h ({:.4},{:.4}) chi2 {:.3} scale {:.6} σ {:.2}\n   errs {}",
            tr.harmonic.cos_rel,
            tr.harmonic.sin_rel,
            tr.normalized_chi2,
            tr.hint_scale,
            tr.sigma_total_nm,
            errs.join(" ")
        );
    }

    /// Two-beam signals with added 2nd/3rd harmonics and Gaussian noise (a fixed xorshift
    /// stream shared across the cases, in this order).
    fn report_synthetic(&self) {
        let kph = 4.0 * std::f64::consts::PI * self.n_air / 1560.0;
        let mut rng: u64 = 12345;
        let mut gauss = move || {
            let mut u = || {
                rng ^= rng << 13;
                rng ^= rng >> 7;
                rng ^= rng << 17;
                (rng >> 11) as f64 / (1u64 << 53) as f64
            };
            let (a, b) = (u().max(1e-300), u());
            (-2.0 * a.ln()).sqrt() * (2.0 * std::f64::consts::PI * b).cos()
        };
        for (h2, h3, noise) in [
            (0.0, 0.0, 0.0),
            (0.0, 0.001, 0.0),
            (0.0, 0.003, 0.0),
            (0.028, 0.0, 0.0),
            (0.028, 0.001, 0.0),
            (0.0, 0.001, 1e-3),
            (0.028, 0.001, 1e-3),
            (0.028, 0.0, 1e-3),
        ] {
            let y: Vec<f64> = self
                .truth
                .iter()
                .map(|d| {
                    let p = d * kph + 0.86;
                    1.0 + p.cos() + h2 * (2.0 * p - 0.6).cos() + h3 * (3.0 * p + 2.5).cos() + noise * gauss()
                })
                .collect();
            self.report(&format!("synthetic h2 {h2} h3 {h3} noise {noise}"), &y);
        }
    }

    /// Fourier content of `y` over whole fringes (phase from the truth hint): the first four
    /// harmonics relative to the first, with their arguments.
    fn print_fourier(&self, y: &[f64]) {
        let n = self.n;
        let kph = 4.0 * std::f64::consts::PI * self.n_air / 1560.0;
        let phi: Vec<f64> = self.truth.iter().map(|d| d * kph).collect();
        let nf = (phi[n - 1] - phi[0]).abs() / (2.0 * std::f64::consts::PI);
        let mut end = n;
        while (phi[end - 1] - phi[0]).abs() > nf.floor() * 2.0 * std::f64::consts::PI {
            end -= 1;
        }
        let mut line = String::new();
        let w: Vec<f64> = (0..end).map(|i| if i + 1 < end { (phi[i + 1] - phi[i]).abs() } else { 0.0 }).collect();
        let ws: f64 = w.iter().sum();
        let mut c1 = (0.0, 0.0);
        for k in 1..=4 {
            let (mut a, mut b) = (0.0, 0.0);
            for i in 0..end {
                a += w[i] * y[i] * (k as f64 * phi[i]).cos();
                b += w[i] * y[i] * (k as f64 * phi[i]).sin();
            }
            a *= 2.0 / ws;
            b *= 2.0 / ws;
            if k == 1 {
                c1 = (a, b);
            }
            let amp = (a * a + b * b).sqrt();
            let rel = amp / (c1.0 * c1.0 + c1.1 * c1.1).sqrt();
            line += &format!(" h{k}: {rel:.5} arg {:.4};", b.atan2(a));
        }
        println!("   fourier{line}");
    }
}

/// The model's `beams`-beam power along the joints of `t`, plus a deterministic pseudo-noise of
/// amplitude `bench_noise`.
fn model_signal(m: &PhaseModel, preset: &BenchPreset, t: &Trace, beams: usize, bench_noise: f64) -> Vec<f64> {
    let mut o = preset.optics;
    o.beams = beams;
    let fp = FabryPerot::new(&o, 1560.0, m.n_air).unwrap();
    (0..t.len())
        .map(|i| {
            let q = m.chain.description().q_from_display(&t.joints_display(i));
            let c = m.extrinsics.cavity(&m.chain.end_effector(&q)).unwrap();
            fp.power(c.length_um, c.tilt_rad) + bench_noise * (((i as f64) * 12.9898).sin() * 43758.5453).fract()
        })
        .collect()
}

fn main() {
    let preset = BenchPreset::resolve("table2-ideal").unwrap();
    let m = PhaseModel::of_preset(&preset, preset.truth).unwrap();
    let args: Vec<f64> = std::env::args().skip(1).map(|a| a.parse().unwrap()).collect();
    let q2 = args.first().copied().unwrap_or(150.0);
    let simulated = simulate_sweep(&preset, q2);
    let loaded;
    let t = if let Ok(p) = std::env::var("TRACE_CSV") {
        loaded = Trace::read_csv(std::path::Path::new(&p)).unwrap();
        &loaded
    } else {
        &simulated
    };
    let truth = m.hint_nm(t, 1560.0).unwrap();
    let n = t.len();
    println!("n {n}, total dL {:.1} nm, fringes {:.2}", truth[n - 1], truth[n - 1] / 780.0 * 1.0003);
    let cfg = track_config();
    let reference = Reference { truth: &truth, n, n_air: m.n_air, cfg: &cfg };
    reference.report("bench", &t.irradiance);
    reference.report_synthetic();
    let bench_noise: f64 = std::env::var("BENCH_NOISE").ok().and_then(|v| v.parse().ok()).unwrap_or(0.0) * 3f64.sqrt();
    for beams in [1usize, 2, 3, 4] {
        let y = model_signal(&m, &preset, t, beams, bench_noise);
        if beams == 4 {
            let d: f64 = y.iter().zip(&t.irradiance).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
            println!("max |model - bench| {d:.3e}");
        }
        reference.report(&format!("beams {beams}"), &y);
        reference.print_fourier(&y);
    }
}
