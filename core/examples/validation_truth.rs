//! The validation motions planned with a diagnosed model on the `hidden-pivot` virtual bench, their
//! tracked gap against the real one (the bench's own extrinsics and hidden pivot at the recorded
//! joints). The model is the one the workbench's diagnosis of that bench gives (GUI test
//! `diagnosis_view_validates_with_and_without_the_named_effect`); a circle tracked with the
//! hint pulling its phase reads 39.5 nm where the real gap changes by 8 nm
//! (`validate::tests::a_validation_circle_tracks_its_small_gap_change`). Arguments pick the
//! effects kept (indices into the four), all by default.
//! `cargo run --release -p photorobot-core --example validation_truth [-- 0 1 ...]`
use photorobot_core::bench::{BenchPreset, VirtualBench};
use photorobot_core::diagnose::validation::extended_model;
use photorobot_core::model::effects::Effect;
use photorobot_core::model::extrinsics::Extrinsics;
use photorobot_core::model::phase::PhaseModel;
use photorobot_core::validate::{run_validation_planned, ValidationMotion};

fn main() {
    let preset = BenchPreset::resolve("hidden-pivot").unwrap();
    let base = PhaseModel::of_preset(&preset, preset.truth).unwrap();
    let diagnosed = Extrinsics {
        x_wf_um: 112.34483092012746,
        y_wf_um: 899.7619898309466,
        z_wf_um: 113.67014290582381,
        beta_wf_deg: 0.7322012103305795,
        theta_wf_deg: -0.5181783100701762,
        z_et_um: 1.2832491268242443,
        beta_et_deg: 0.7438473490774588,
        theta_et_deg: -0.5969615444167694,
    };
    let all = vec![
        Effect::PivotOffset { joint: "q4".into(), offset_world_um: [0.0, 0.0, 20.4085] },
        Effect::JointScale { joint: "q1".into(), ppm: 732.6243 },
        Effect::ReversalError { joint: "q3".into(), step: -0.0836 },
        Effect::AxisTilt { joint: "q3".into(), tilt_mrad: [0.0, -0.4271] },
    ];
    let which: Vec<usize> = std::env::args().skip(1).filter_map(|a| a.parse().ok()).collect();
    let effects: Vec<Effect> = if which.is_empty() { all } else { which.iter().map(|&k| all[k].clone()).collect() };
    let model = extended_model(&base, diagnosed, &effects).unwrap();
    let truth = extended_model(&base, preset.truth, &preset.effects).unwrap();
    for motion in ValidationMotion::ALL {
        let mut bench = VirtualBench::new(&preset, Some(7)).unwrap();
        let f = run_validation_planned(&mut bench, &model, &diagnosed, &model, motion, [0.0; 6], &Default::default())
            .unwrap();
        let t = &f.trace;
        let true_dl = truth.hint_nm(t, t.wavelength_nm[0]).unwrap();
        let model_dl = model.hint_nm(t, t.wavelength_nm[0]).unwrap();
        let s = f.motion_start;
        let n = t.len();
        let (mut lo, mut hi, mut worst) = (f64::INFINITY, f64::NEG_INFINITY, 0.0f64);
        for i in s..n {
            let real = true_dl[i] - true_dl[s];
            (lo, hi) = (lo.min(real), hi.max(real));
            worst = worst.max((f.tracked_dl_nm[i] - f.tracked_dl_nm[s] - real).abs());
        }
        println!(
            "{}: figure {:.1} nm; real phase-equivalent gap {:.1} nm peak to peak, tracked at worst {:.1} nm off it",
            motion.name(),
            f.peak_to_peak_nm,
            hi - lo,
            worst
        );
        for k in 0..=12 {
            let i = s + k * (n - 1 - s) / 12;
            println!(
                "  {i:6} tracked {:8.2} truth {:8.2} model {:8.2}  I {:.4}",
                f.tracked_dl_nm[i] - f.tracked_dl_nm[s],
                true_dl[i] - true_dl[s],
                model_dl[i] - model_dl[s],
                t.irradiance[i]
            );
        }
    }
}
