//! `photorobot validate --bench <preset|hardware file> --extrinsics E.ron [--json]`: check a
//! calibration made earlier on the bench today, without recalibrating (has the bench drifted
//! since?). Owns only argument parsing and printing; the work is
//! `photorobot_core::validate::before_after::check_calibration`, the validation `calibrate` runs.
//!
//! Exit code 0 when every motion is confirmed within its target, 1 otherwise (the figures are
//! printed either way).

use super::common::{hardware_bench_file, json_text, nominal_model, timed, CliError};
use crate::hardware_bench::open_hardware_bench;
use photorobot_core::bench::{Bench, BenchPreset, VirtualBench};
use photorobot_core::hardware::emulator::EmuClock;
use photorobot_core::model::extrinsics::Extrinsics;
use photorobot_core::validate::before_after::check_calibration;
use photorobot_core::validate::evidence::Evidence;
use photorobot_core::validate::StopSettings;
use serde::Serialize;
use std::io::Write;
use std::path::PathBuf;

/// Arguments of `photorobot validate`.
#[derive(Debug, clap::Args)]
pub struct ValidateArgs {
    /// Bench: an embedded preset name (table2-ideal, femto-lab), a preset file (RON), or a
    /// hardware bench file (a HardwareConfig) whose controllers run the motions, modelled by --model.
    #[arg(long, value_name = "PRESET")]
    pub bench: String,
    /// With a hardware bench file: the preset whose robot, optics and motion limits model it.
    #[arg(long, value_name = "PRESET", default_value = "table2-ideal")]
    pub model: String,
    /// The calibration to check: an extrinsics file (RON), as `calibrate` writes it.
    #[arg(long, value_name = "FILE")]
    pub extrinsics: PathBuf,
    /// Random seed of the virtual bench (default: the preset's).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Stops along each motion where the bench measures the fringe contrast (and an absolute
    /// gap): the rotations' tilt term needs two, the optical axis's three poses with the start.
    #[arg(long, default_value_t = StopSettings::default().stops, value_name = "N")]
    pub stops: usize,
    /// No wavelength sweeps at the poses (a bench without a tunable laser has none anyway).
    #[arg(long)]
    pub no_sweeps: bool,
    /// Print the result as JSON.
    #[arg(long)]
    pub json: bool,
}

/// One motion's result: its proof, or why it could not run.
struct MotionResult {
    motion: &'static str,
    figure: Result<Evidence, String>,
}

impl MotionResult {
    fn within_target(&self) -> bool {
        self.figure.as_ref().is_ok_and(|e| e.within_target)
    }

    /// The JSON entry: the motion's name and every field of its proof (`measured_nm` first among
    /// them), or `measured_nm` and `verdict` null with the error.
    fn json(&self) -> serde_json::Value {
        match &self.figure {
            Ok(e) => {
                let mut v = serde_json::to_value(e).unwrap_or_default();
                if let Some(map) = v.as_object_mut() {
                    map.insert("motion".into(), self.motion.into());
                }
                v
            }
            Err(error) => serde_json::json!({
                "motion": self.motion, "measured_nm": null, "verdict": null, "within_target": false, "error": error,
            }),
        }
    }
}

/// The JSON document.
#[derive(Debug, Serialize)]
struct ValidateDoc {
    bench: String,
    extrinsics: Extrinsics,
    /// True when every motion is confirmed within its target.
    confirmed: bool,
    /// The four motions in order: circle, X_f, Z_f, optical axis.
    validation: Vec<serde_json::Value>,
}

/// Run the four validation motions with the extrinsics given and print their proof.
pub fn validate(a: &ValidateArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let extrinsics = Extrinsics::load(&a.extrinsics)?;
    extrinsics.validate().map_err(|e| CliError::Argument {
        argument: "--extrinsics",
        problem: format!("{}: {e}", a.extrinsics.display()),
    })?;
    let hardware = hardware_bench_file(&a.bench)?;
    let preset = BenchPreset::resolve(if hardware.is_some() { &a.model } else { &a.bench })?;
    let model = nominal_model(&preset)?;
    let stops = StopSettings { stops: a.stops, sweeps: !a.no_sweeps };
    let mut bench: Box<dyn Bench> = match hardware {
        Some(config) => {
            let clock = EmuClock::new(config.time_scale);
            let (bench, _) = open_hardware_bench(&preset, preset.robot_description()?, config, clock)
                .map_err(|problem| CliError::Failed { what: "the hardware bench", problem })?;
            Box::new(bench)
        }
        None => Box::new(VirtualBench::new(&preset, a.seed)?),
    };
    let figures = timed("validate", || check_calibration(bench.as_mut(), &model, &extrinsics, &stops));
    let results: Vec<MotionResult> = figures
        .into_iter()
        .map(|(motion, figure)| MotionResult {
            motion: motion.name(),
            figure: figure.map(|f| f.evidence).map_err(|e| e.to_string()),
        })
        .collect();
    let confirmed = results.iter().all(MotionResult::within_target);
    if a.json {
        let validation = results.iter().map(MotionResult::json).collect();
        let doc = ValidateDoc { bench: bench.name(), extrinsics, confirmed, validation };
        writeln!(out, "{}", json_text(&doc)?)?;
    } else {
        print(&bench.name(), &results, out)?;
    }
    if confirmed {
        return Ok(());
    }
    let failed: Vec<String> = results
        .iter()
        .filter(|m| !m.within_target())
        .map(|m| match &m.figure {
            Ok(e) => format!("`{}`: {}", m.motion, e.summary()),
            Err(err) => format!("`{}`: {err}", m.motion),
        })
        .collect();
    Err(CliError::Failed { what: "validation", problem: format!("not confirmed within target: {}", failed.join("; ")) })
}

/// The result as text: one line per motion, then every comparison of the motions not confirmed.
fn print(bench: &str, results: &[MotionResult], out: &mut dyn Write) -> std::io::Result<()> {
    writeln!(out, "validation on {bench} (cavity length |L|, peak to peak):")?;
    writeln!(
        out,
        "  {:<52} {:>10} {:>9} {:>10} {:>11} {:>9} {:>9}  verdict",
        "motion", "measured", "target", "tracked", "model-free", "count ≥", "sweeps"
    )?;
    let f = |x: Option<f64>| x.map_or("-".to_string(), |v| format!("{v:.1}"));
    for m in results {
        let e = match &m.figure {
            Ok(e) => e,
            Err(err) => {
                writeln!(out, "  {:<52} FAILED: {err}", m.motion)?;
                continue;
            }
        };
        let word = if e.within_target { "confirmed within target" } else { e.verdict.word() };
        writeln!(
            out,
            "  {:<52} {:>10} {:>9.0} {:>10} {:>11} {:>9} {:>9}  {word}",
            m.motion,
            f(Some(e.measured_nm)),
            e.target_nm,
            f(Some(e.tracked_nm)),
            e.model_free_words().unwrap_or("-".into()),
            f(e.bounds.map(|b| b.lower_nm)),
            f(e.sweep_spread_nm),
        )?;
    }
    for (m, e) in results.iter().filter(|m| !m.within_target()).filter_map(|m| m.figure.as_ref().ok().map(|e| (m, e))) {
        writeln!(out, "\n{}: {}", m.motion, e.verdict.word())?;
        for c in &e.checks {
            writeln!(out, "  {} {}: {}", if c.agrees { "agrees   " } else { "DISAGREES" }, c.name, c.detail)?;
        }
        for n in &e.notes {
            writeln!(out, "  note: {n}")?;
        }
    }
    Ok(())
}
