//! Each motion trace of a session kept by `independent_hidden --keep DIR` (`recorded/` and
//! `proposed-1/`), tracked from the motion hint of the calibration's extrinsics
//! (`session/extrinsics.ron`) and of the independent simulator's true ones, against the fringe
//! extrema its signal shows: the tracked travel in steps of λ/(4n) beside the count of extrema
//! (the paper's count, `MotionMeasurement::count`), as the calibration's check measures them
//! (`measure::hint_led`). A tracking its hint led astray travels far more, or less, than its
//! signal's extrema allow, and is marked; a right one is within about one step.
//!
//!     cargo run --release -p photorobot-e2e --example tracked_against_count -- DIR/CASE [--seed 301]

use photorobot_core::bench::BenchPreset;
use photorobot_core::measure::hint_led::{hint_led, tracked_travel_steps};
use photorobot_core::measure::{analyse_with, Measurement};
use photorobot_core::model::extrinsics::Extrinsics;
use photorobot_core::model::phase::PhaseModel;
use photorobot_core::trace::Trace;
use std::path::PathBuf;

/// One line per motion trace: its tracked travel and net change (steps) and its extrema counted.
fn table(name: &str, model: &PhaseModel, traces: &[Trace]) {
    println!("== tracked from the hint of the {name} extrinsics");
    for t in traces.iter().filter(|t| !photorobot_core::trace::is_sweep(t)) {
        match analyse_with(t, model, &Default::default()) {
            Ok(Measurement::Motion(m)) => {
                let step = m.count.resolution_nm;
                let dl = &m.track.dl_nm;
                let travel = tracked_travel_steps(dl, step);
                let net = (dl[dl.len() - 1] - dl[0]) / step;
                let led = if hint_led(&m).is_some() { "  hint-led" } else { "" };
                println!(
                    "{:<46} travel {travel:6.1} net {net:+7.1} steps; extrema counted {:3}{led}",
                    t.meta.label, m.count.counted
                );
            }
            Ok(_) => {}
            Err(e) => println!("{:<46} not analysed: {e}", t.meta.label),
        }
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let dir =
        PathBuf::from(args.iter().find(|a| !a.starts_with("--")).expect("a folder kept by independent_hidden --keep"));
    let seed = args.iter().position(|a| a == "--seed").and_then(|k| args.get(k + 1)?.parse().ok()).unwrap_or(301);
    let mut traces = Vec::new();
    for sub in ["recorded", "proposed-1"] {
        if dir.join(sub).is_dir() {
            traces.extend(photorobot_core::trace::import::read_folder(&dir.join(sub), None).expect("the traces read"));
        }
    }
    let preset = BenchPreset::resolve("table2-ideal").expect("the preset");
    let robot = preset.robot_description().expect("its robot");
    let base = PhaseModel::new(
        robot,
        Extrinsics::nominal_design(),
        preset.optics,
        &preset.ambient,
        preset.laser.wavelength_nm,
    )
    .expect("the model");
    let calibrated = Extrinsics::load(&dir.join("session").join("extrinsics.ron")).expect("the session's extrinsics");
    let t = photorobot_e2e::independent::Recorder::new(seed).truth;
    let truth = Extrinsics {
        x_wf_um: t.x_wf_um,
        y_wf_um: t.y_wf_um,
        z_wf_um: t.z_wf_um,
        beta_wf_deg: t.beta_wf_deg,
        theta_wf_deg: t.theta_wf_deg,
        z_et_um: t.z_et_um,
        beta_et_deg: t.beta_et_deg,
        theta_et_deg: t.theta_et_deg,
    };
    table("calibration's", &PhaseModel { extrinsics: calibrated, ..base.clone() }, &traces);
    table("true", &PhaseModel { extrinsics: truth, ..base }, &traces);
}
