//! The discrepancy workflow on simulated observations: the paper's calibration observations
//! (model predictions + Gaussian noise of their σ) with a hidden 1 µm reversal error of q3,
//! diagnosed from the true extrinsics with the simulated bench running the discriminating
//! motions: baseline, scores, design, naming, the re-test. What a session's diagnosis costs
//! beyond its trace analysis. `cargo bench -p photorobot-core --bench diagnose`; target < 10 s
//! for the whole `photorobot diagnose` of a joint-mode session (docs/diagnosis.md, "Speed").

use criterion::{criterion_group, criterion_main, Criterion};
use photorobot_core::diagnose::motions::{paper_calibration, SimulatedBench};
use photorobot_core::diagnose::{Diagnosis, Verdict};
use photorobot_core::model::air::AmbientConditions;
use photorobot_core::model::effects::Effect;
use photorobot_core::model::extrinsics::Extrinsics;
use photorobot_core::model::optics::OpticalParams;
use photorobot_core::model::phase::PhaseModel;
use photorobot_core::model::robot::RobotDescription;

fn hidden_reversal(c: &mut Criterion) {
    let base = PhaseModel::new(
        RobotDescription::femto_6dof(),
        Extrinsics::table2(),
        OpticalParams::default(),
        &AmbientConditions::default(),
        1560.0,
    )
    .unwrap();
    let effects = vec![Effect::ReversalError { joint: "q3".into(), step: 1.0 }];
    let run = || {
        let mut bench = SimulatedBench::new(&base, Extrinsics::table2(), effects.clone(), 5).unwrap();
        let obs = bench.simulate(&paper_calibration()).unwrap();
        let d = Diagnosis::new(&base, obs, Extrinsics::table2()).unwrap();
        d.run(Some(&mut bench)).unwrap().0
    };
    let check = run();
    assert_eq!(check.verdict, Verdict::Named, "{check:?}");
    assert_eq!(check.effects[0].name, "reversal error q3", "{check:?}");
    eprintln!("named {} = {:.4} µm", check.effects[0].name, check.effects[0].estimate);
    c.bench_function("diagnosis of the paper's calibration, hidden q3 reversal", |b| b.iter(run));
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10);
    targets = hidden_reversal
}
criterion_main!(benches);
