//! How much a sweep's absolute gap depends on the model it is analysed with: the sweeps of a
//! traces folder analysed with the nominal design and with a bench preset's truth.
//!
//!     cargo run --release -p photorobot-core --example sweep_tilt_dependence -- TRACES_DIR [PRESET]
//!
//! The full-model sweep fit takes the lamella's tilt at the sweep's pose from the model; a
//! square model against Table II's 1.1° moves the gap by about 0.35 µm (70σ of a sweep), which
//! is why the identification analyses the sweeps again with each branch's estimate.

use photorobot_core::bench::BenchPreset;
use photorobot_core::identify::measurements::observations_from_traces;
use photorobot_core::identify::multistart::extract_options;
use photorobot_core::model::extrinsics::Extrinsics;
use photorobot_core::model::phase::PhaseModel;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(dir) = args.first() else {
        eprintln!("usage: sweep_tilt_dependence TRACES_DIR [PRESET]");
        std::process::exit(2);
    };
    let preset = BenchPreset::resolve(args.get(1).map_or("table2-ideal", String::as_str)).expect("a bench preset");
    let traces = photorobot_core::trace::import::read_folder(std::path::Path::new(dir), None).expect("a traces folder");
    let sweeps: Vec<_> = traces.into_iter().filter(photorobot_core::trace::is_sweep).collect();
    let analyse = |e: Extrinsics| {
        let model = PhaseModel::of_preset(&preset, e).expect("the model");
        observations_from_traces(&sweeps, &model, &extract_options()).observations
    };
    let (nominal, truth) = (analyse(Extrinsics::nominal_design()), analyse(preset.truth));
    println!("{:<40} {:>14} {:>14} {:>10} {:>8}", "sweep", "nominal (µm)", "truth (µm)", "diff (µm)", "σ (µm)");
    for (a, b) in nominal.iter().zip(&truth) {
        let d = a.value() - b.value();
        println!("{:<40} {:>14.4} {:>14.4} {:>10.4} {:>8.4}", a.label, a.value(), b.value(), d, b.sigma);
    }
}
