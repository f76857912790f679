//! The joint identification from extracted observations: the observation set of the joint-mode
//! plans (strategy 1, strategy 2, extra measurements: every recorded move's gap change, every
//! sweep's absolute gap), predicted from Table II with noise at the measured σ, estimated from
//! the design extrinsics. `cargo bench -p photorobot-core --bench identify`; target < 50 ms.

use criterion::{criterion_group, criterion_main, Criterion};
use photorobot_core::calibration::{plans, Mode};
use photorobot_core::identify::joint::{estimate, JointOptions};
use photorobot_core::identify::{predict, Observation, ObservationKind};
use photorobot_core::model::air::AmbientConditions;
use photorobot_core::model::extrinsics::Extrinsics;
use photorobot_core::model::optics::{FabryPerot, OpticalParams};
use photorobot_core::model::phase::PhaseModel;
use photorobot_core::model::robot::RobotDescription;
use photorobot_core::plan::{MotionLimits, TimedMotion};

fn observations(model: &PhaseModel, truth: &Extrinsics) -> Vec<Observation> {
    let fp = FabryPerot::new(&model.optics, 1560.0, model.n_air).unwrap();
    let mut state: u64 = 0x5eed;
    let mut gauss = move || {
        // Sum of 12 uniforms: a deterministic, roughly Gaussian noise.
        (0..12)
            .map(|_| {
                state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                (state >> 11) as f64 / (1u64 << 53) as f64
            })
            .sum::<f64>()
            - 6.0
    };
    let mut out = Vec::new();
    let mut start = [0.0; 6];
    for plan in plans(Mode::Joint) {
        let segments = plan.expand(model.chain.description(), start, &MotionLimits::default()).unwrap();
        for s in &segments {
            let (kind, sigma) = match s.motion {
                TimedMotion::Move { .. } if s.record && s.from_display != s.to_display => (
                    ObservationKind::GapChange { from_display: s.from_display, to_display: s.to_display, dl_nm: 0.0 },
                    2.0,
                ),
                TimedMotion::Sweep { .. } => (
                    ObservationKind::AbsoluteGap { at_display: s.from_display, gap_um: 0.0, sweep_nm_per_s: 0.0 },
                    0.02,
                ),
                _ => continue,
            };
            let mut o = Observation {
                label: s.label.clone(),
                kind,
                sigma,
                wavelength_nm: 1560.0,
                time_s: [0.0; 2],
                approach: Default::default(),
            };
            let v = predict(model, &fp, truth, &o, 1.0) + sigma * gauss();
            match &mut o.kind {
                ObservationKind::GapChange { dl_nm, .. } => *dl_nm = v,
                ObservationKind::AbsoluteGap { gap_um, .. } => *gap_um = v,
                ObservationKind::FringeAmplitude { amplitude_mw, .. } => *amplitude_mw = v,
            }
            out.push(o);
        }
        start = segments.last().map_or(start, |s| s.to_display);
    }
    out
}

fn joint(c: &mut Criterion) {
    let model = PhaseModel::new(
        RobotDescription::femto_6dof(),
        Extrinsics::nominal_design(),
        OpticalParams::default(),
        &AmbientConditions::default(),
        1560.0,
    )
    .unwrap();
    let truth = Extrinsics::table2();
    let obs = observations(&model, &truth);
    let options = JointOptions::default();
    let check = estimate(&model, &obs, &model.extrinsics, &options);
    assert!(check.converged, "{}", check.termination);
    eprintln!("{} observations, {} evaluations", obs.len(), check.evaluations);
    c.bench_function(&format!("joint estimate, {} observations", obs.len()), |b| {
        b.iter(|| estimate(&model, &obs, &model.extrinsics, &options))
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20);
    targets = joint
}
criterion_main!(benches);
