//! Tests of the workflow on simulated observations (model predictions + Gaussian noise of their σ).

use super::motions::{paper_calibration, SimulatedBench};
use super::*;
use crate::model::air::AmbientConditions;
use crate::model::effects::Effect;
use crate::model::optics::OpticalParams;
use crate::model::robot::RobotDescription;

fn base() -> PhaseModel {
    PhaseModel::new(
        RobotDescription::femto_6dof(),
        Extrinsics::table2(),
        OpticalParams::default(),
        &AmbientConditions::default(),
        1560.0,
    )
    .unwrap()
}

/// Simulate the paper's calibration with hidden effects, diagnose with the simulated bench
/// running the discriminating motions. The start extrinsics are the truth moved slightly (as a
/// calibration would leave them).
fn diagnose(effects: Vec<Effect>, seed: u64, run_motions: bool) -> (DiagnosisResult, Vec<Step>) {
    let b = base();
    let mut bench = SimulatedBench::new(&b, Extrinsics::table2(), effects, seed).unwrap();
    let obs = bench.simulate(&paper_calibration()).unwrap();
    let d = Diagnosis::new(&b, obs, Extrinsics::table2()).unwrap();
    if run_motions {
        d.run(Some(&mut bench)).unwrap()
    } else {
        d.run(None).unwrap()
    }
}

fn print(steps: &[Step]) {
    for s in steps {
        eprintln!("## {}\n{}", s.title(), s.summary());
    }
}

#[test]
fn explore() {
    let t = std::time::Instant::now();
    let cases = vec![
        Effect::PivotOffset { joint: "q4".into(), offset_world_um: [0.0, 0.0, 20.0] },
        Effect::PivotOffset { joint: "q5".into(), offset_world_um: [0.0, 20.0, 0.0] },
        Effect::JointZeroOffset { joint: "q4".into(), offset: 0.05 },
        Effect::JointScale { joint: "q2".into(), ppm: 800.0 },
        Effect::AxisTilt { joint: "q3".into(), tilt_mrad: [0.0, 0.6] },
        Effect::ThermalDrift { nm_per_s: 0.5, nm_per_s2: 0.0 },
        Effect::PathScale { ppm: 268.0 },
    ];
    for e in cases {
        let (r, steps) = diagnose(vec![e.clone()], 1, true);
        if std::env::var("VERBOSE").is_ok() { print(&steps); }
        eprintln!("HIDDEN {e:?}: {:?} {:?} rms {:.2} -> {:.2}", r.verdict, r.effects.iter().map(|x| (x.name.clone(), x.estimate, x.sigma, x.ambiguous_with.clone())).collect::<Vec<_>>(), r.residual_rms_before_sigma, r.residual_rms_after_sigma);
    }
    eprintln!("{:.2} s", t.elapsed().as_secs_f64());
}
