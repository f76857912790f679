//! Debug: tracked dL vs model truth on one lateral motion, fast vs exact bench path.
use photorobot_core::bench::{run_plan, BenchPreset, RunControl, VirtualBench};
use photorobot_core::measure::{self, Measurement, PhaseModel};
use photorobot_core::plan::{JointTarget, Plan, Segment};
use std::sync::atomic::AtomicBool;

fn main() {
    let preset = BenchPreset::resolve("table2-ideal").unwrap();
    let mut m = PhaseModel::new(
        preset.robot_description().unwrap(),
        preset.truth,
        preset.optics,
        &preset.ambient,
        preset.laser.wavelength_nm,
    )
    .unwrap();
    m.extrinsics = preset.truth;
    let args: Vec<f64> = std::env::args().skip(1).map(|a| a.parse().unwrap()).collect();
    let (q2, noise) = (args.first().copied().unwrap_or(150.0), args.get(1).copied().unwrap_or(1.0));
    for exact in [false, true] {
        let mut p = preset.clone();
        p.detector.white_noise_rel_fringe *= noise;
        let mut bench = VirtualBench::new(&p, Some(3)).unwrap();
        bench.set_exact(exact);
        let plan = Plan {
            name: "t".into(),
            description: String::new(),
            segments: vec![
                Segment::Move {
                    to: JointTarget::all([-150.0, q2, 0.0, 0.0, 0.0, 0.0]),
                    record: false,
                    label: "s".into(),
                },
                Segment::Move {
                    to: JointTarget::all([150.0, q2, 0.0, 0.0, 0.0, 0.0]),
                    record: true,
                    label: "Z".into(),
                },
            ],
        };
        let cancel = AtomicBool::new(false);
        let mut control = RunControl { cancel: &cancel, on_samples: &mut |_, _| {}, on_progress: &mut |_| {} };
        let run = run_plan(&mut bench, &plan, &mut control);
        let t = &run.traces[0];
        let truth = m.hint_nm(t, 1560.0).unwrap();
        let Ok(Measurement::Motion(mm)) = measure::analyse(t, &m) else { panic!() };
        let n = t.len();
        let errs: Vec<String> =
            (0..=10).map(|k| format!("{:.2}", mm.track.dl_nm[k * (n - 1) / 10] - truth[k * (n - 1) / 10])).collect();
        println!("exact {exact}: I0 {:.5} errs {}", t.irradiance[0], errs.join(" "));
    }
}
