//! The command-line interface: clap parsing and plain-text or JSON printing of core results.
//! Owns no science: each subcommand calls `photorobot_core` and formats what it returns.

use clap::{Parser, Subcommand};
use photorobot_core::bench::{run_plan, Bench, BenchError, RunControl, RunError, VirtualBench};
use photorobot_core::files::FileError;
use photorobot_core::measure::{self, MeasureError, Measurement};
use photorobot_core::model::air::AmbientConditions;
use photorobot_core::model::extrinsics::Extrinsics;
use photorobot_core::model::frames::FrameTree;
use photorobot_core::model::kinematics::{Chain, LimitViolation};
use photorobot_core::model::optics::OpticalParams;
use photorobot_core::model::phase::PhaseModel;
use photorobot_core::model::robot::RobotDescription;
use photorobot_core::plan::Plan;
use photorobot_core::trace::{Trace, TraceError};
use serde_json::json;
use std::ffi::OsString;
use std::io::Write;
use std::path::PathBuf;
use thiserror::Error;

/// photorobot: calibrate a photonics assembly bench from Fabry-Perot fringes.
/// With no command, starts the workbench GUI on the virtual bench.
#[derive(Debug, Parser)]
#[command(name = "photorobot", version, about, long_about = None)]
pub struct Cli {
    /// What to do (default: start the GUI).
    #[command(subcommand)]
    pub command: Option<Command>,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Print every frame's pose, the signed cavity length L and the reflection point P_r.
    Frames(FramesArgs),
    /// Run a motion plan on a virtual bench and write the recorded traces as CSV.
    Simulate(SimulateArgs),
    /// Analyse a recorded trace: fringe count, dL and its uncertainty (or the absolute gap of a sweep).
    Fringes(FringesArgs),
    /// Measure, identify and validate end to end on a bench; write the session.
    Calibrate(crate::cli_calibrate::CalibrateArgs),
    /// Choose motions that reach the required uncertainties in the least bench time; write the plan.
    Design(crate::cli_design::DesignArgs),
    /// Find where model and data disagree on a calibration session, name the missing effect, add it.
    Diagnose(crate::cli_diagnose::DiagnoseArgs),
    /// Write a session's calibration report as one self-contained HTML file.
    Report(ReportArgs),
    /// Start the workbench GUI (the default when no command is given).
    Gui,
    /// Serve a stage-controller protocol emulator (PI E-712 or SmarAct MCS) on 127.0.0.1.
    Emulate(crate::cli_emulate::EmulateArgs),
}

/// Arguments of `photorobot report`.
#[derive(Debug, clap::Args)]
pub struct ReportArgs {
    /// The session: its folder or its session.ron.
    pub session: PathBuf,
    /// The HTML file to write.
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
}

/// Arguments of `photorobot simulate`.
#[derive(Debug, clap::Args)]
pub struct SimulateArgs {
    /// Bench preset: an embedded name (table2-ideal, femto-lab) or a preset file (RON).
    #[arg(long, value_name = "PRESET")]
    pub bench: String,
    /// Motion plan file (RON), or an embedded plan: strategy1, strategy2.
    #[arg(long, value_name = "PLAN")]
    pub plan: String,
    /// Output: a directory (one CSV per recorded segment) or, for a plan that records one trace, a .csv file.
    #[arg(long, value_name = "DIR|FILE")]
    pub out: PathBuf,
    /// Random seed (default: the preset's).
    #[arg(long)]
    pub seed: Option<u64>,
}

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

/// Arguments of `photorobot frames`.
#[derive(Debug, clap::Args)]
pub struct FramesArgs {
    /// Joint values q1,..,q6: prismatic joints in µm, revolute joints in degrees (default: all 0).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true, value_name = "q1,..,q6")]
    pub q: Option<Vec<f64>>,
    /// Extrinsic parameters file (RON; default: the paper's Table II, assets/extrinsics/table2.ron).
    #[arg(long, value_name = "FILE")]
    pub extrinsics: Option<PathBuf>,
    /// Robot description file (RON; default: assets/robots/femto-6dof.ron).
    #[arg(long, value_name = "FILE")]
    pub robot: Option<PathBuf>,
    /// Print JSON (lengths in µm) instead of text.
    #[arg(long)]
    pub json: bool,
}

/// What the caller should do after [`run`].
#[derive(Debug, PartialEq, Eq)]
pub enum Outcome {
    /// The command ran and printed its output.
    Done,
    /// No command was given: start the GUI.
    StartGui,
}

/// Why a command failed. Every message names the file, field or argument and what was expected.
#[derive(Debug, Error)]
pub enum CliError {
    /// Bad command line (clap prints it, with usage).
    #[error("{0}")]
    Usage(#[from] clap::Error),
    /// A data file could not be used.
    #[error(transparent)]
    File(#[from] FileError),
    /// An argument has the wrong form.
    #[error("argument {argument}: {problem}")]
    Argument {
        /// The argument, e.g. `--q`.
        argument: &'static str,
        /// What is wrong and what was expected.
        problem: String,
    },
    /// A joint value is outside its limits.
    #[error("argument --q: {0}")]
    Limits(#[from] LimitViolation),
    /// A bench could not be built or failed.
    #[error(transparent)]
    Bench(#[from] BenchError),
    /// A plan failed.
    #[error(transparent)]
    Run(#[from] RunError),
    /// A trace file could not be read or written.
    #[error(transparent)]
    Trace(#[from] TraceError),
    /// A session could not be read or written.
    #[error(transparent)]
    Session(#[from] photorobot_core::session::SessionError),
    /// A trace could not be analysed.
    #[error(transparent)]
    Measure(#[from] MeasureError),
    /// Output could not be written.
    #[error("cannot write output: {0}")]
    Output(#[from] std::io::Error),
    /// The work itself failed (a calibration, design or diagnosis that could not be computed).
    #[error("{what} failed: {problem}")]
    Failed {
        /// What failed, e.g. "calibration".
        what: &'static str,
        /// Why.
        problem: String,
    },
    /// The run finished and its session was written, but it is not a calibration (the model does
    /// not fit the data, branches tie, or the solver did not converge).
    #[error("not a calibration: {problem} (session written to {})", session.display())]
    NotACalibration {
        /// Where the session was written.
        session: std::path::PathBuf,
        /// What is wrong.
        problem: String,
    },
}

/// The version of every command's JSON output, in its `schema` field: raised when a field is
/// renamed, removed or changes meaning (new fields do not raise it).
pub const JSON_SCHEMA: u32 = 1;

/// A command's JSON document as printed, with `schema` ([`JSON_SCHEMA`]) added.
pub fn json_text<T: serde::Serialize>(doc: &T) -> std::io::Result<String> {
    let mut doc = serde_json::to_value(doc).map_err(std::io::Error::other)?;
    if let Some(map) = doc.as_object_mut() {
        map.insert("schema".into(), JSON_SCHEMA.into());
    }
    serde_json::to_string_pretty(&doc).map_err(std::io::Error::other)
}

impl CliError {
    /// The process exit code: 1 for a run that failed or finished without a result (not a
    /// calibration, a bench or plan that failed, a trace that could not be analysed, output that
    /// could not be written), 2 for a command line that is wrong, 3 for a file that cannot be
    /// used (a plan, preset, trace or session that is missing or malformed, a bench preset that
    /// cannot be built).
    pub fn exit_code(&self) -> u8 {
        match self {
            CliError::Bench(BenchError::Config(_)) => 3,
            CliError::NotACalibration { .. }
            | CliError::Failed { .. }
            | CliError::Bench(_)
            | CliError::Run(_)
            | CliError::Measure(_)
            | CliError::Output(_) => 1,
            CliError::Usage(_) | CliError::Argument { .. } | CliError::Limits(_) => 2,
            CliError::File(_) | CliError::Trace(_) | CliError::Session(_) => 3,
        }
    }
}

/// Parse `args` (including the program name) and run the command, writing to `out`.
pub fn run<I, T>(args: I, out: &mut dyn Write) -> Result<Outcome, CliError>
where
    I: IntoIterator<Item = T>,
    T: Into<OsString> + Clone,
{
    let cli = Cli::try_parse_from(args)?;
    match cli.command {
        None | Some(Command::Gui) => Ok(Outcome::StartGui),
        Some(Command::Frames(a)) => frames(&a, out).map(|()| Outcome::Done),
        Some(Command::Simulate(a)) => simulate(&a, out).map(|()| Outcome::Done),
        Some(Command::Fringes(a)) => fringes(&a, out).map(|()| Outcome::Done),
        Some(Command::Calibrate(a)) => crate::cli_calibrate::calibrate(&a, out).map(|()| Outcome::Done),
        Some(Command::Design(a)) => crate::cli_design::run_design(&a, out).map(|()| Outcome::Done),
        Some(Command::Diagnose(a)) => crate::cli_diagnose::diagnose(&a, out).map(|()| Outcome::Done),
        Some(Command::Report(a)) => report(&a, out).map(|()| Outcome::Done),
        Some(Command::Emulate(a)) => crate::cli_emulate::emulate(&a, out).map(|()| Outcome::Done),
    }
}

/// `photorobot report`: the session's HTML report, written atomically.
fn report(a: &ReportArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let session = photorobot_core::session::Session::load(&a.session)?;
    let html = photorobot_core::report::render_html(&session);
    photorobot_core::files::write_atomic(&a.out, html.as_bytes())?;
    writeln!(out, "report written to {}", a.out.display())?;
    Ok(())
}

fn load_robot(path: &Option<PathBuf>) -> Result<RobotDescription, CliError> {
    Ok(match path {
        Some(p) => RobotDescription::load(p)?,
        None => RobotDescription::femto_6dof(),
    })
}

fn load_extrinsics(path: &Option<PathBuf>) -> Result<Extrinsics, CliError> {
    Ok(match path {
        Some(p) => Extrinsics::load(p)?,
        None => Extrinsics::table2(),
    })
}

/// Joint vector from `--q` in display units (µm, °), checked for length, finiteness and limits.
fn joints_from_arg(robot: &RobotDescription, q: &Option<Vec<f64>>) -> Result<Vec<f64>, CliError> {
    let q_display = q.clone().unwrap_or_else(|| vec![0.0; robot.dof()]);
    if q_display.len() != robot.dof() {
        return Err(CliError::Argument {
            argument: "--q",
            problem: format!(
                "expected {} comma-separated joint values ({}), found {}",
                robot.dof(),
                robot.joint_names().join(","),
                q_display.len()
            ),
        });
    }
    if let Some((i, v)) = q_display.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(CliError::Argument {
            argument: "--q",
            problem: format!("joint {} must be a finite number, found {v}", robot.links[i].name),
        });
    }
    let q = robot.q_from_display(&q_display);
    Chain::new(robot.clone()).check_limits(&q)?;
    Ok(q)
}

fn frames(a: &FramesArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let robot = load_robot(&a.robot)?;
    let extrinsics = load_extrinsics(&a.extrinsics)?;
    let q = joints_from_arg(&robot, &a.q)?;
    let chain = Chain::new(robot.clone());
    let tree = FrameTree::new(&chain, &extrinsics, &q);
    let q_display = robot.q_to_display(&q);
    if a.json {
        let cavity = match &tree.cavity {
            Ok(c) => json!({
                "cavity_length_um": c.length_um,
                "gap_um": c.length_um.abs(),
                "reflection_point_world_um": [c.reflection_point_world_um.x, c.reflection_point_world_um.y, c.reflection_point_world_um.z],
                "reflection_point_tool_um": [c.reflection_point_tool_um.x, c.reflection_point_tool_um.y, c.reflection_point_tool_um.z],
                "n_f": [c.n_f.x, c.n_f.y, c.n_f.z],
                "n_t": [c.n_t.x, c.n_t.y, c.n_t.z],
                "tilt_mrad": c.tilt_rad * 1e3,
            }),
            Err(e) => json!({ "cavity_length_um": null, "cavity_error": e.to_string() }),
        };
        let joints: Vec<_> = robot
            .links
            .iter()
            .zip(&q_display)
            .map(|(l, v)| json!({ "name": l.name, "value": v, "unit": l.joint.display_unit() }))
            .collect();
        let mut doc = json!({
            "robot": robot.name,
            "q": joints,
            "frames": tree.records(),
        });
        doc.as_object_mut().unwrap().extend(cavity.as_object().unwrap().clone());
        writeln!(out, "{}", json_text(&doc)?)?;
        return Ok(());
    }
    let origin = |p: &Option<PathBuf>, default: &str| match p {
        Some(p) => p.display().to_string(),
        None => format!("{default} (embedded)"),
    };
    writeln!(out, "robot:      {} ({})", robot.name, origin(&a.robot, "assets/robots/femto-6dof.ron"))?;
    writeln!(out, "extrinsics: {}", origin(&a.extrinsics, "assets/extrinsics/table2.ron"))?;
    let qs: Vec<String> = robot
        .links
        .iter()
        .zip(&q_display)
        .map(|(l, v)| format!("{} = {v:.3} {}", l.name, l.joint.display_unit()))
        .collect();
    writeln!(out, "joints:     {}", qs.join(", "))?;
    writeln!(out)?;
    writeln!(out, "{:<28} {:>34}   rotation (rows; columns are the frame's axes)", "frame", "origin in world (µm)")?;
    for (i, n) in tree.nodes.iter().enumerate() {
        let p = n.world.translation.vector;
        let m = n.world.rotation.to_rotation_matrix().into_inner();
        let row = |r: usize| format!("{:+.6} {:+.6} {:+.6}", m[(r, 0)], m[(r, 1)], m[(r, 2)]);
        let name = format!("{}{}", "  ".repeat(tree.depth(i)), n.name);
        writeln!(
            out,
            "{name:<28} ({:>10.3}, {:>10.3}, {:>10.3})   [{}] [{}] [{}]",
            p.x,
            p.y,
            p.z,
            row(0),
            row(1),
            row(2)
        )?;
    }
    writeln!(out)?;
    match &tree.cavity {
        Ok(c) => {
            writeln!(out, "signed cavity length L = {:.3} µm (gap |L| = {:.3} µm)", c.length_um, c.length_um.abs())?;
            let (w, t) = (c.reflection_point_world_um, c.reflection_point_tool_um);
            writeln!(out, "reflection point P_r in world = ({:.3}, {:.3}, {:.3}) µm", w.x, w.y, w.z)?;
            writeln!(out, "reflection point P_r in tool  = ({:.3}, {:.3}, {:.3}) µm", t.x, t.y, t.z)?;
            writeln!(out, "optical axis n_f = ({:.6}, {:.6}, {:.6})", c.n_f.x, c.n_f.y, c.n_f.z)?;
            writeln!(out, "lamella normal n_t = ({:.6}, {:.6}, {:.6})", c.n_t.x, c.n_t.y, c.n_t.z)?;
            writeln!(
                out,
                "angle between n_t and n_f = {:.3} mrad ({:.4}°)",
                c.tilt_rad * 1e3,
                c.tilt_rad.to_degrees()
            )?;
        }
        Err(e) => writeln!(out, "no cavity: {e}")?,
    }
    Ok(())
}

/// A plan file, or an embedded plan by name: strategy1, strategy2, joint-extras, optimised.
pub(crate) fn load_plan(name_or_path: &str) -> Result<Plan, CliError> {
    Ok(match name_or_path {
        "strategy1" => Plan::from_ron_str(
            photorobot_core::plan::STRATEGY1_RON,
            std::path::Path::new("assets/plans/strategy1.ron"),
        )?,
        "strategy2" => Plan::from_ron_str(
            photorobot_core::plan::STRATEGY2_RON,
            std::path::Path::new("assets/plans/strategy2.ron"),
        )?,
        "joint-extras" => Plan::joint_extras(),
        "optimised" => Plan::optimised(),
        path => Plan::load(std::path::Path::new(path))?,
    })
}

/// A file-system-safe name for a trace file.
fn slug(label: &str) -> String {
    let s: String =
        label.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' || c == '.' { c } else { '_' }).collect();
    let s = s.trim_matches('_').to_string();
    if s.is_empty() {
        "trace".into()
    } else {
        s.chars().take(60).collect()
    }
}

fn simulate(a: &SimulateArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let mut bench = VirtualBench::from_preset_name(&a.bench, a.seed)?;
    let plan = load_plan(&a.plan)?;
    let cancel = std::sync::atomic::AtomicBool::new(false);
    let mut control = RunControl { cancel: &cancel, on_samples: &mut |_, _| {}, on_progress: &mut |_| {} };
    let run = run_plan(&mut bench, &plan, &mut control);
    let single_file = a.out.extension().is_some_and(|e| e.eq_ignore_ascii_case("csv"));
    if single_file && run.traces.len() > 1 {
        return Err(CliError::Argument {
            argument: "--out",
            problem: format!(
                "the plan recorded {} traces: give a directory, not the file {}",
                run.traces.len(),
                a.out.display()
            ),
        });
    }
    // Whatever happened, the traces recorded so far are written first.
    let mut written = Vec::new();
    if single_file {
        if let Some(t) = run.traces.first() {
            t.write_csv(&a.out)?;
            written.push(a.out.clone());
        }
    } else {
        std::fs::create_dir_all(&a.out).map_err(|source| FileError::Io {
            file: a.out.clone(),
            action: "cannot create directory",
            source,
        })?;
        for (i, t) in run.traces.iter().enumerate() {
            let path = a.out.join(format!("{:03}-{}.csv", i + 1, slug(&t.meta.label)));
            t.write_csv(&path)?;
            written.push(path);
        }
    }
    let samples: usize = run.traces.iter().map(Trace::len).sum();
    writeln!(
        out,
        "{}: plan {} ran {:.1} s of bench time; {} traces, {} samples written to {}",
        bench.name(),
        plan.name,
        run.duration_s,
        written.len(),
        samples,
        a.out.display()
    )?;
    run.outcome?;
    Ok(())
}

fn fringes(a: &FringesArgs, out: &mut dyn Write) -> Result<(), CliError> {
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

#[cfg(test)]
mod tests {
    use super::*;

    fn exit_code(args: &[&str]) -> u8 {
        let mut out = Vec::new();
        run(args.iter().copied(), &mut out).map(|_| 0).unwrap_or_else(|e| e.exit_code())
    }

    #[test]
    fn a_wrong_command_line_exits_2_and_an_unusable_file_3() {
        assert_eq!(exit_code(&["photorobot", "frames", "--no-such-flag"]), 2);
        assert_eq!(exit_code(&["photorobot", "frames", "--q", "1,2,3"]), 2, "three joints for six");
        let dir = tempfile::tempdir().unwrap();
        let plan = dir.path().join("missing-plan.ron");
        let out = dir.path().join("out");
        let (plan, out) = (plan.to_str().unwrap(), out.to_str().unwrap());
        assert_eq!(exit_code(&["photorobot", "simulate", "--bench", "table2-ideal", "--plan", plan, "--out", out]), 3);
        std::fs::write(dir.path().join("bench.ron"), "BenchPreset(name: 1)").unwrap();
        let bench = dir.path().join("bench.ron");
        let args = ["photorobot", "simulate", "--bench", bench.to_str().unwrap(), "--plan", "strategy1", "--out", out];
        assert_eq!(exit_code(&args), 3, "a malformed preset");
        assert_eq!(exit_code(&["photorobot", "frames"]), 0);
    }

    #[test]
    fn json_output_carries_its_schema_version() {
        let mut out = Vec::new();
        run(["photorobot", "frames", "--json"], &mut out).unwrap();
        let doc: serde_json::Value = serde_json::from_slice(&out).unwrap();
        assert_eq!(doc["schema"], JSON_SCHEMA);
        assert!(doc["frames"].is_array(), "the document itself is kept: {doc}");
    }

    #[test]
    fn a_run_without_a_result_exits_1() {
        let e = CliError::NotACalibration { session: "s".into(), problem: "the model does not fit".into() };
        assert_eq!(e.exit_code(), 1);
        assert_eq!(CliError::Output(std::io::Error::other("disk full")).exit_code(), 1);
        assert_eq!(CliError::Failed { what: "diagnosis", problem: "no result".into() }.exit_code(), 1);
    }
}
