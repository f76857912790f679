//! The scatter of repeated absolute-gap sweeps at rest against the σ each fit reports, on the
//! emulated controllers over TCP (the E-712's ADC reading the laser's wavelength monitor) and on
//! the virtual bench: whether a sweep's σ covers what it really scatters.
//!
//!     cargo run --profile test -p photorobot-e2e --example sweep_scatter -- [N] [SEED]

use photorobot_core::bench::{run_plan, Bench, BenchPreset, RunControl, VirtualBench};
use photorobot_core::hardware::emulator::EmulatedHardware;
use photorobot_core::hardware::HardwareConfig;
use photorobot_core::measure::sweep::{fit_gap, SweepConfig};
use photorobot_core::model::phase::PhaseModel;
use photorobot_core::plan::{JointTarget, Plan, Segment};
use photorobot_core::validate::stops::{SWEEP_HALF_SPAN_NM, SWEEP_RATE_NM_PER_S};
use photorobot_core::validate::{waypoints, ValidationMotion};
use std::sync::atomic::AtomicBool;

type Truth<'a> = Option<&'a dyn Fn(f64) -> f64>;

fn sweeps(
    bench: &mut dyn Bench,
    pose: [f64; 6],
    n: usize,
    centre: f64,
    cfg: &SweepConfig,
    truth: Truth,
) -> Vec<(f64, f64)> {
    let mut segments =
        vec![Segment::Move { to: JointTarget::all(pose), record: false, label: "to".into(), through: false }];
    for k in 0..n {
        segments.push(Segment::Sweep {
            from_nm: centre - SWEEP_HALF_SPAN_NM,
            to_nm: centre + SWEEP_HALF_SPAN_NM,
            rate_nm_per_s: SWEEP_RATE_NM_PER_S,
            label: format!("sweep {k}"),
        });
    }
    let plan = Plan { name: "sweeps".into(), description: String::new(), segments };
    let cancel = AtomicBool::new(false);
    let mut control = RunControl { cancel: &cancel, on_samples: &mut |_, _| {}, on_progress: &mut |_| {} };
    let run = run_plan(bench, &plan, &mut control);
    run.outcome.unwrap();
    run.traces
        .iter()
        .filter(|t| t.meta.label.starts_with("sweep"))
        .map(|t| {
            let mut f = fit_gap(&t.wavelength_nm, &t.irradiance, cfg).unwrap();
            eprintln!("   scale σ {:.1} ppm", t.meta.wavelength_scale_sigma_ppm);
            f.estimate = photorobot_core::measure::with_scale_sigma(t, f.estimate);
            {
                if let Some(truth) = truth {
                    let true_nm: Vec<f64> = t.t_s.iter().map(|&x| truth(x)).collect();
                    let err: Vec<f64> = true_nm.iter().zip(&t.wavelength_nm).map(|(a, b)| b - a).collect();
                    let mean = err.iter().sum::<f64>() / err.len() as f64;
                    let rms = (err.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / err.len() as f64).sqrt();
                    let g = fit_gap(&true_nm, &t.irradiance, cfg).unwrap();
                    eprintln!(
                        "   monitor error mean {:.4} pm rms {:.4} pm; gap with the true wavelengths {:.1} nm ± {:.1}",
                        mean * 1e3,
                        rms * 1e3,
                        g.estimate.gap_um * 1e3,
                        g.estimate.sigma_um * 1e3
                    );
                }
                eprintln!(
                    "   σ {:.4} nm, rms {:.3e}, B {:.3e}, n {}",
                    f.estimate.sigma_um * 1e3,
                    f.estimate.fit_rms,
                    f.amplitude,
                    t.len()
                );
                (f.estimate.gap_um * 1e3, f.estimate.sigma_um * 1e3)
            }
        })
        .collect()
}

fn report(name: &str, v: &[(f64, f64)]) {
    let n = v.len() as f64;
    let mean = v.iter().map(|x| x.0).sum::<f64>() / n;
    let sd = (v.iter().map(|x| (x.0 - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    let sig = (v.iter().map(|x| x.1 * x.1).sum::<f64>() / n).sqrt();
    println!("{name}: {} sweeps, mean {:.1} nm, scatter {sd:.1} nm, reported σ (rms) {sig:.1} nm", v.len(), mean);
    for x in v {
        println!("   {:+8.1} ± {:.1}", x.0 - mean, x.1);
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let n: usize = args.first().map_or(10, |s| s.parse().unwrap());
    let seed: u64 = args.get(1).map_or(17, |s| s.parse().unwrap());
    let preset = BenchPreset::resolve("table2-ideal").unwrap();
    let model = PhaseModel::of_preset(&preset, preset.truth).unwrap();
    let cfg = SweepConfig { n_air: model.n_air, gouy_waist_nm: Some(model.optics.mode_field_radius_um * 1e3) };
    let tilted = waypoints(&model, &preset.truth, ValidationMotion::RotationXf, [0.0; 6], 13).unwrap()[0];
    let centre = preset.laser.wavelength_nm;
    let emulated =
        EmulatedHardware::start(&preset, seed, HardwareConfig { time_scale: 2.0, ..HardwareConfig::femto() }).unwrap();
    let (mut hw, _) = photorobot_app::hardware_bench::open_hardware_bench(
        &preset,
        preset.robot_description().unwrap(),
        emulated.config.clone(),
        emulated.stages.clock(),
    )
    .unwrap();
    let laser = emulated.stages.emu_laser();
    let mut virt = VirtualBench::new(&preset, Some(seed)).unwrap();
    for (name, pose) in [("at q = 0", [0.0; 6]), ("tilted (rotation about X_f's start)", tilted)] {
        report(&format!("virtual bench, {name}"), &sweeps(&mut virt, pose, n, centre, &cfg, None));
        report(
            &format!("emulators, {name}"),
            &sweeps(&mut hw, pose, n, centre, &cfg, Some(&|t| laser.wavelength_at(t))),
        );
    }
}
