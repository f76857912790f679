//! The joints a validation recording holds against the joints the emulated photodiode saw, and the
//! true gap along each, through TCP on the emulated controllers: where a validation's figure on
//! hardware comes from.
//!
//!     cargo run --profile test -p photorobot-e2e --example validation_joints -- [SEED] [TIME_SCALE] [own]

use photorobot_core::bench::BenchPreset;
use photorobot_core::hardware::emulator::EmulatedHardware;
use photorobot_core::hardware::HardwareConfig;
use photorobot_core::model::phase::PhaseModel;
use photorobot_core::validate::before_after::check_calibration;
use photorobot_core::validate::StopSettings;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let seed: u64 = args.first().map_or(17, |s| s.parse().unwrap());
    let scale: f64 = args.get(1).map_or(2.0, |s| s.parse().unwrap());
    let preset = BenchPreset::resolve("table2-ideal").unwrap();
    let emulated =
        EmulatedHardware::start(&preset, seed, HardwareConfig { time_scale: scale, ..HardwareConfig::femto() })
            .unwrap();
    let (mut bench, _) = photorobot_app::hardware_bench::open_hardware_bench(
        &preset,
        preset.robot_description().unwrap(),
        emulated.config.clone(),
        if args.get(2).is_some_and(|a| a == "own") {
            photorobot_core::hardware::clock::EmuClock::new(scale)
        } else {
            emulated.stages.clock()
        },
    )
    .unwrap();
    let model = PhaseModel::of_preset(&preset, preset.truth).unwrap();
    emulated.stages.tap_joints(true);
    let figures = check_calibration(&mut bench, &model, &preset.truth, &StopSettings::default());
    let tap = emulated.stages.tap_joints(false);
    println!("tap: {} samples, t {:.3}..{:.3}", tap.len(), tap.first().unwrap().0, tap.last().unwrap().0);
    for (motion, figure) in figures {
        let f = figure.unwrap();
        let tr = &f.trace;
        let n = tr.len();
        println!(
            "\n{}: {} samples, t {:.4}..{:.4}, ptp {:.1} nm",
            motion.name(),
            n,
            tr.t_s[0],
            tr.t_s[n - 1],
            f.peak_to_peak_nm
        );
        // Nearest tap sample for each trace sample.
        let mut worst = [0.0f64; 6];
        let (mut gmin, mut gmax, mut rmin, mut rmax) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        let mut dt_worst: f64 = 0.0;
        let mut rows = Vec::new();
        for i in f.motion_start..n {
            let t = tr.t_s[i];
            let k = tap.partition_point(|s| s.0 < t);
            let cand = [k.saturating_sub(1), k.min(tap.len() - 1)];
            let best = *cand.iter().min_by(|&&a, &&b| (tap[a].0 - t).abs().total_cmp(&(tap[b].0 - t).abs())).unwrap();
            dt_worst = dt_worst.max((tap[best].0 - t).abs());
            let q_true = tap[best].1;
            let q_rec = tr.joints_display(i);
            for j in 0..6 {
                worst[j] = worst[j].max((q_rec[j] - q_true[j]).abs());
            }
            let g_true = model.gap_and_tilt(&q_true).unwrap().0 * 1e3;
            let g_rec = model.gap_and_tilt(&q_rec).unwrap().0 * 1e3;
            gmin = gmin.min(g_true);
            gmax = gmax.max(g_true);
            rmin = rmin.min(g_rec);
            rmax = rmax.max(g_rec);
            rows.push((t, g_true, g_rec, f.variation_nm[i - f.motion_start]));
        }
        let e = &f.evidence;
        let (imin, imax) = tr.irradiance.iter().fold((f64::MAX, f64::MIN), |(a, b), &v| (a.min(v), b.max(v)));
        println!("  irradiance {imin:.5} .. {imax:.5} {}", tr.meta.irradiance_unit);
        println!("  {}", e.summary());
        println!(
            "  model-free {:?} (gap {:?}, alt {:?}, floor {:?}), tilt from contrast {:?} ± {:?}, sweeps {:?} ± {:?}",
            e.model_free_nm,
            e.model_free_gap_nm,
            e.model_free_gap_alternative_nm,
            e.model_free_floor_nm,
            e.tilt_from_contrast_nm,
            e.tilt_sigma_nm,
            e.sweep_spread_nm,
            e.sweep_sigma_nm
        );
        for p in &e.poses {
            println!(
                "  pose {}: gap {:?} µm ± {:?}, tracked change {:.1} nm, {:?}",
                p.pose, p.gap_um, p.sigma_um, p.tracked_change_nm, p.problem
            );
        }
        println!("  worst time match {:.2e} s", dt_worst);
        println!("  worst |q_rec - q_true|: {:?}", worst.map(|w| format!("{w:.2e}")));
        println!(
            "  true gap along the true joints: ptp {:.1} nm; along the recorded joints: ptp {:.1} nm",
            gmax - gmin,
            rmax - rmin
        );
        if f.peak_to_peak_nm < 20.0 {
            continue;
        }
        let step = (rows.len() / 60).max(1);
        let (g0, r0) = (rows[0].1, rows[0].2);
        for r in rows.iter().step_by(step) {
            println!("  t {:9.4}  true {:8.1}  rec {:8.1}  reported {:8.1}", r.0, r.1 - g0, r.2 - r0, r.3);
        }
    }
}
