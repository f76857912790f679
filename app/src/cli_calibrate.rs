//! `photorobot calibrate --bench <preset> [--seed N] [--mode paper|joint] --out <session> [--json]`: measure,
//! identify and validate end to end. Owns only argument parsing, the session folder and printing; the work is
//! `photorobot_core::identify::calibration`.
//!
//! The session folder gets every recorded trace (`traces/NNN.csv`), the identified extrinsics
//! (`extrinsics.ron`, loadable by `photorobot frames --extrinsics`) and the whole report
//! (`report.json`). Every file is written atomically.

use crate::cli::CliError;
use photorobot_core::bench::{BenchPreset, VirtualBench};
use photorobot_core::files::{save_ron, write_atomic};
use photorobot_core::identify::calibration::{calibrate as run_calibration, CalibrationReport, Mode};
use photorobot_core::measure::PhaseModel;
use photorobot_core::model::extrinsics::Extrinsics;
use std::io::Write;
use std::path::PathBuf;

/// Which identifier.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ModeArg {
    /// The paper's steps A, B, C on strategies 1 and 2 (about 13 min of bench time).
    Paper,
    /// Every parameter from every measurement, with tilt scans and absolute gaps (about 13 min more).
    Joint,
}

/// Arguments of `photorobot calibrate`.
#[derive(Debug, clap::Args)]
pub struct CalibrateArgs {
    /// Bench preset: an embedded name (table2-ideal, femto-lab) or a preset file (RON).
    #[arg(long, value_name = "PRESET")]
    pub bench: String,
    /// Random seed of the virtual bench (default: the preset's).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Identifier.
    #[arg(long, value_enum, default_value_t = ModeArg::Joint)]
    pub mode: ModeArg,
    /// Session folder to create (traces, extrinsics.ron, report.json).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Print the report as JSON instead of tables.
    #[arg(long)]
    pub json: bool,
}

/// Run the calibration and write the session.
pub fn calibrate(a: &CalibrateArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let preset = BenchPreset::resolve(&a.bench)?;
    let mut bench = VirtualBench::new(&preset, a.seed)?;
    // The software's model: the bench's robot description and optics, the design extrinsics.
    let nominal = PhaseModel::new(
        preset.robot_description()?,
        Extrinsics::nominal_design(),
        preset.optics,
        &preset.ambient,
        preset.laser.wavelength_nm,
    )
    .map_err(|problem| CliError::Argument { argument: "--bench", problem })?;
    let mode = match a.mode {
        ModeArg::Paper => Mode::Paper,
        ModeArg::Joint => Mode::Joint,
    };
    let report = run_calibration(&mut bench, &nominal, mode).map_err(|problem| CliError::Argument {
        argument: "--bench",
        problem: format!("calibration failed: {problem}"),
    })?;
    write_session(a, &report)?;
    if a.json {
        let text = serde_json::to_string_pretty(&report).map_err(std::io::Error::other)?;
        writeln!(out, "{text}")?;
    } else {
        print_report(&report, out)?;
        writeln!(out, "\nsession written to {}", a.out.display())?;
    }
    Ok(())
}

fn write_session(a: &CalibrateArgs, report: &CalibrationReport) -> Result<(), CliError> {
    let traces = a.out.join("traces");
    std::fs::create_dir_all(&traces)?;
    for (i, t) in report.traces.iter().enumerate() {
        t.write_csv(&traces.join(format!("{i:03}.csv")))?;
    }
    save_ron(&a.out.join("extrinsics.ron"), &report.extrinsics)?;
    let json = serde_json::to_string_pretty(report).map_err(std::io::Error::other)?;
    write_atomic(&a.out.join("report.json"), json.as_bytes())?;
    Ok(())
}

/// The report as text: the Table II-style table, identifiability, residuals, validation.
pub fn print_report(r: &CalibrationReport, out: &mut dyn Write) -> std::io::Result<()> {
    writeln!(
        out,
        "calibration ({:?} mode) on {}: {} observations, {:.1} min of bench time",
        r.mode,
        r.bench,
        r.observations,
        r.measurement_duration_s / 60.0
    )?;
    writeln!(out, "solver: {} ({})", if r.converged { "converged" } else { "NOT CONVERGED" }, r.termination)?;
    writeln!(out, "\n{:<10} {:>14} {:<4} {:>12}  determined", "parameter", "value", "unit", "σ")?;
    for p in &r.parameters {
        let sigma = p.sigma.map_or("-".to_string(), |s| format!("{s:.5}"));
        if p.determined {
            writeln!(out, "{:<10} {:>14.5} {:<4} {:>12}  yes", p.name, p.value, p.unit, sigma)?;
        } else {
            writeln!(
                out,
                "{:<10} {:>14} {:<4} {:>12}  NO: {}",
                p.name,
                format!("({:.3})", p.value),
                p.unit,
                sigma,
                p.reason.as_deref().unwrap_or("not determined by these data")
            )?;
        }
    }
    let id = &r.identifiability;
    writeln!(out, "\nidentifiability: rank {} of {} columns", id.rank, id.parameters.len())?;
    if let Some(c) = id.condition_number {
        writeln!(out, "  condition number {c:.3e}{}", if c > 100.0 { " (above 100)" } else { "" })?;
    }
    if let Some(c) = id.condition_number_determined {
        writeln!(out, "  condition number of the determined parameters {c:.3e}")?;
    }
    for (a, b, rho) in &id.strong_correlations {
        writeln!(out, "  strongly correlated: {a} and {b} (ρ = {rho:+.3})")?;
    }
    for c in &id.unobservable {
        writeln!(out, "  {}", c.description)?;
    }
    writeln!(
        out,
        "  residual RMS {:.2} σ (1 = at the noise floor); uncertainties scaled by {:.2}",
        r.residual_rms_sigma, id.covariance_scale
    )?;
    // Residuals per measurement (RMS over the observations of each trace label).
    let mut per_label: Vec<(String, String, f64, f64, usize)> = Vec::new();
    for (label, unit, res, sigma) in &r.residuals {
        match per_label.iter_mut().find(|p| &p.0 == label && &p.1 == unit) {
            Some(p) => {
                p.2 += res * res;
                p.3 += (res / sigma).powi(2);
                p.4 += 1;
            }
            None => per_label.push((label.clone(), unit.clone(), res * res, (res / sigma).powi(2), 1)),
        }
    }
    writeln!(out, "\nresiduals per measurement (RMS):")?;
    for (label, unit, ss, ss_n, n) in per_label {
        let n = n as f64;
        writeln!(out, "  {:>10.4} {:<3} {:>6.2} σ  {}", (ss / n).sqrt(), unit, (ss_n / n).sqrt(), label)?;
    }
    writeln!(out, "\nvalidation (FP cavity variation, peak to peak):")?;
    writeln!(out, "  {:<28} {:>12} {:>12} {:>12}", "motion", "before (nm)", "after (nm)", "paper (nm)")?;
    for v in &r.validation {
        let f = |x: Option<f64>| x.map_or("-".to_string(), |v| format!("{v:.1}"));
        writeln!(
            out,
            "  {:<28} {:>12} {:>12} {:>12.0}{}",
            v.motion,
            f(v.before_nm),
            f(v.after_nm),
            v.paper_nm,
            v.note.as_ref().map_or(String::new(), |n| format!("  ({n})"))
        )?;
    }
    for w in &r.warnings {
        writeln!(out, "warning: {w}")?;
    }
    Ok(())
}
