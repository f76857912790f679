//! Temporary exploration.
use photorobot_core::bench::BenchPreset;
use photorobot_core::calibration::{identify, Mode};
use photorobot_core::identify::ObservationKind;
use photorobot_core::model::extrinsics::Extrinsics;
use photorobot_core::model::phase::PhaseModel;
use photorobot_e2e::independent::OpticsModel;
use photorobot_e2e::lab_recordings::LabCase;
use photorobot_e2e::two_beam::TwoBeamOptics;

fn family(o: &photorobot_core::identify::Observation) -> &'static str {
    match &o.kind {
        ObservationKind::GapChange { from_display, to_display, .. } => {
            if (3..6).any(|j| (from_display[j] - to_display[j]).abs() > 1e-3) { "rot" } else { "trans" }
        }
        ObservationKind::AbsoluteGap { .. } => "gap",
        ObservationKind::FringeAmplitude { .. } => "amp",
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let from: u64 = args.first().and_then(|a| a.parse().ok()).unwrap_or(0);
    let n: u64 = args.get(1).and_then(|a| a.parse().ok()).unwrap_or(4);
    let two = args.iter().any(|a| a == "--two");
    let no_back = args.iter().any(|a| a == "--no-back");
    let circ = args.iter().any(|a| a == "--circ");
    let nogouy = args.iter().any(|a| a == "--no-gouy");
    let preset = BenchPreset::resolve("table2-ideal").unwrap();
    let nominal = PhaseModel::of_preset(&preset, Extrinsics::nominal_design()).unwrap();
    for k in from..from + n {
        let mut o = TwoBeamOptics::default();
        if no_back { o.back_face = None; }
        if circ { o.mode = vec![photorobot_e2e::two_beam::ModeComponent { amplitude: 1.0, w_u_um: 5.2, w_v_um: 5.2 }]; }
        if nogouy { o.gouy = false; }
        let optics = if two { OpticsModel::TwoBeam(o) } else { OpticsModel::MultiBeam(Default::default()) };
        let case = LabCase::random(5000 + k, 1 + k, optics);
        let dir = std::path::PathBuf::from(format!("/tmp/i46/cases/{}-{}", if two { "two" } else { "multi" }, k));
        let _ = std::fs::remove_dir_all(&dir);
        case.record(&dir);
        let traces = photorobot_core::trace::import::read_folder(&dir, None).unwrap();
        let t0 = std::time::Instant::now();
        let id = identify(&traces, &nominal, Mode::Joint).unwrap();
        let r = &id.estimate.normalised_residuals;
        let mut fams: Vec<(&str, f64, usize)> = vec![];
        for (o, v) in id.observations.iter().zip(r) {
            let f = family(o);
            match fams.iter_mut().find(|x| x.0 == f) { Some(x) => { x.1 += v * v; x.2 += 1 } None => fams.push((f, v * v, 1)) }
        }
        println!("case {k} ({:.0} s): rms {:.2}", t0.elapsed().as_secs_f64(), (r.iter().map(|v| v*v).sum::<f64>() / r.len() as f64).sqrt());
        for f in &fams { println!("   {:<6} n {:>4} rms {:.2}", f.0, f.2, (f.1 / f.2 as f64).sqrt()); }
        let labels: Vec<String> = id.observations.iter().map(|o| o.label.clone()).collect();
        for t in photorobot_core::identify::verdict::worst_traces(&labels, r, 6) {
            let fam: Vec<&str> = id.observations.iter().filter(|o| o.label == t.label).map(family).collect();
            println!("   worst {:<12} {:.2}σ over {} ({:?})", t.label, t.rms_sigma, t.observations, fam.first());
        }
        let truth = case.truth.report_order();
        let est = id.estimate.extrinsics.to_array();
        println!("   est-truth: {:?}", truth.iter().zip(est).map(|(t, e)| format!("{} {:+.5}", t.0, e - t.1)).collect::<Vec<_>>());
        let dump = (truth.map(|t| t.1), est, id.observations.clone(), id.skipped.clone());
        std::fs::write(dir.join("id.json"), serde_json::to_string(&dump).unwrap()).unwrap();
    }
}
