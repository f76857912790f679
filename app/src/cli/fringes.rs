//! `photorobot fringes TRACE [--extrinsics FILE] [ambient] [--json]`: fringe count, dL and its
//! uncertainty of a recorded motion, or the absolute gap of a sweep. Owns only argument parsing and
//! printing; the work is `photorobot_core::measure`.

use super::common::{json_text, load_extrinsics, CliError};
use photorobot_core::measure::{self, Measurement};
use photorobot_core::model::air::AmbientConditions;
use photorobot_core::model::optics::OpticalParams;
use photorobot_core::model::phase::PhaseModel;
use photorobot_core::model::robot::RobotDescription;
use photorobot_core::trace::Trace;
use serde_json::json;
use std::io::Write;
use std::path::PathBuf;

/// Ambient conditions, for the air index.
#[derive(Debug, Clone, clap::Args)]
pub struct AmbientArgs {
    /// Air temperature (°C).
    #[arg(long, default_value_t = 20.0, value_name = "°C")]
    pub temperature_c: f64,
    /// Air pressure (hPa).
    #[arg(long, default_value_t = 1013.25, value_name = "hPa")]
    pub pressure_hpa: f64,
    /// Relative humidity (%).
    #[arg(long, default_value_t = 50.0, value_name = "%")]
    pub humidity_percent: f64,
}

impl AmbientArgs {
    fn conditions(&self) -> AmbientConditions {
        AmbientConditions {
            temperature_c: self.temperature_c,
            pressure_hpa: self.pressure_hpa,
            relative_humidity_percent: self.humidity_percent,
            ..Default::default()
        }
    }
}

/// Arguments of `photorobot fringes`.
#[derive(Debug, clap::Args)]
pub struct FringesArgs {
    /// The trace (CSV with header t_s,q1_um,q2_um,q3_um,q4_deg,q5_deg,q6_deg,wavelength_nm,irradiance).
    pub trace: PathBuf,
    /// Extrinsics used to predict the motion's direction (default: Table II).
    #[arg(long, value_name = "FILE")]
    pub extrinsics: Option<PathBuf>,
    /// Ambient conditions.
    #[command(flatten)]
    pub ambient: AmbientArgs,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Analyse the trace and print the measurement.
pub fn fringes(a: &FringesArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let trace = Trace::read_csv(&a.trace)?;
    let extrinsics = load_extrinsics(&a.extrinsics)?;
    let wavelength = trace.wavelength_nm.first().copied().unwrap_or(1560.0);
    let model = PhaseModel::new(
        RobotDescription::femto_6dof(),
        extrinsics,
        OpticalParams::default(),
        &a.ambient.conditions(),
        wavelength,
    )
    .map_err(|problem| CliError::Argument { argument: "--temperature-c/--pressure-hpa/--humidity-percent", problem })?;
    let m = measure::analyse(&trace, &model)?;
    match (&m, a.json) {
        (Measurement::Motion(mm), true) => {
            let doc = json!({
                "trace": a.trace.display().to_string(),
                "kind": "motion",
                "samples": trace.len(),
                "wavelength_nm": mm.wavelength_nm,
                "n_air": mm.n_air,
                "fringe_count": mm.count.count,
                "extrema": mm.count.extrema.len(),
                "count_dl_um": mm.count.dl_nm * 1e-3,
                "count_resolution_um": mm.count.resolution_nm * 1e-3,
                "dl_um": mm.track.total_dl_nm * 1e-3,
                "sigma_um": mm.track.sigma_total_nm * 1e-3,
                "predicted_dl_um": mm.hint_nm.last().copied().unwrap_or(0.0) * 1e-3,
            });
            writeln!(out, "{}", json_text(&doc)?)?;
        }
        (Measurement::Motion(mm), false) => {
            writeln!(
                out,
                "trace {} ({} samples, λ = {:.3} nm, n_air - 1 = {:.1} ppm)",
                a.trace.display(),
                trace.len(),
                mm.wavelength_nm,
                (mm.n_air - 1.0) * 1e6
            )?;
            writeln!(
                out,
                "fringe count: {} extrema, signed count {} → dL = {:.3} µm ± {:.3} µm (one λ/4 step)",
                mm.count.extrema.len(),
                mm.count.count,
                mm.count.dl_nm * 1e-3,
                mm.count.resolution_nm * 1e-3
            )?;
            writeln!(
                out,
                "phase tracking: dL = {:.4} µm, standard uncertainty {:.4} µm",
                mm.track.total_dl_nm * 1e-3,
                mm.track.sigma_total_nm * 1e-3
            )?;
            writeln!(out, "(nominal model predicted {:.4} µm)", mm.hint_nm.last().copied().unwrap_or(0.0) * 1e-3)?;
        }
        (Measurement::Sweep(s), json) => {
            let e = &s.gap;
            if json {
                let doc = json!({
                    "trace": a.trace.display().to_string(),
                    "kind": "sweep",
                    "samples": trace.len(),
                    "gap_um": e.gap_um,
                    "sigma_um": e.sigma_um,
                    "fringes_across_sweep": e.fringes_across_sweep,
                    "method": e.method.name(),
                    "peak_fsr_gap_um": s.peak_fsr.map(|p| p.gap_um),
                    "peak_fsr_sigma_um": s.peak_fsr.map(|p| p.sigma_um),
                });
                writeln!(out, "{}", json_text(&doc)?)?;
            } else {
                writeln!(
                    out,
                    "trace {} is a wavelength sweep ({} samples, {:.1} fringes across it)",
                    a.trace.display(),
                    trace.len(),
                    e.fringes_across_sweep
                )?;
                writeln!(out, "absolute gap: {:.4} µm ± {:.4} µm ({})", e.gap_um, e.sigma_um, e.method.name())?;
                if let Some(p) = s.peak_fsr {
                    writeln!(out, "paper's peak-FSR method: {:.3} µm ± {:.3} µm", p.gap_um, p.sigma_um)?;
                }
            }
        }
    }
    Ok(())
}
