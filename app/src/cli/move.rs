//! `photorobot move --bench B [--seed N] (--session S | --extrinsics E) --gap-um G [--tilt-deg β,θ]
//! [--lateral-um x,z] [--rotation-deg r] [--keep-gap] [--json]`, or `--recipe FILE [--resume]`:
//! place the lamella relative to the fiber with a calibration and prove it. Owns only argument
//! parsing, choosing the bench and printing; the work is `photorobot_core::position::move_to`.
//!
//! With `--session` every move is appended to the session's history (`moves` in `session.ron`,
//! saved after each move) and the folder is locked meanwhile. A recipe runs its steps in order,
//! each proven before the next; it stops at the first move not confirmed. Ctrl-C stops the move
//! in hand (recorded as stopped) and prints the `--resume` line that continues the recipe.

use super::common::{hardware_bench_file, json_text, CliError};
use super::progress::INTERRUPT;
use crate::hardware_bench::open_hardware_bench;
use photorobot_core::bench::{Bench, BenchPreset, RunControl, VirtualBench};
use photorobot_core::files::FileError;
use photorobot_core::hardware::emulator::EmuClock;
use photorobot_core::model::extrinsics::Extrinsics;
use photorobot_core::model::phase::PhaseModel;
use photorobot_core::position::recipe::Recipe;
use photorobot_core::position::{move_to, MoveError, MoveRecord, Placement, ProofOptions, Target, Verdict};
use photorobot_core::session::{now_utc_rfc3339, FolderLock, Session};
use serde::Serialize;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;

/// Arguments of `photorobot move`.
#[derive(Debug, clap::Args)]
pub struct MoveArgs {
    /// Bench: an embedded preset (table2-ideal, femto-lab), a preset file, or a hardware bench
    /// file (a HardwareConfig: the stage controllers and laser it names, modelled by --model).
    #[arg(long, value_name = "PRESET")]
    pub bench: String,
    /// With a hardware bench file: the preset whose robot, optics and motion limits model it.
    #[arg(long, value_name = "PRESET", default_value = "table2-ideal")]
    pub model: String,
    /// Random seed of the virtual bench (default: the preset's + 1).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Session folder whose calibration places the lamella (its extrinsics, their uncertainty,
    /// the diagnosis's effects); the moves are recorded in it.
    #[arg(long, value_name = "DIR", required_unless_present = "extrinsics")]
    pub session: Option<PathBuf>,
    /// Extrinsics file instead of a session: taken as exact (no forecast), nothing recorded.
    #[arg(long, value_name = "FILE", conflicts_with = "session")]
    pub extrinsics: Option<PathBuf>,
    /// Gap along the beam (µm).
    #[arg(long, value_name = "UM", required_unless_present = "recipe", conflicts_with = "recipe")]
    pub gap_um: Option<f64>,
    /// Lamella tilt against the fiber's end face, β about X_f and θ about Z_f (°; default 0,0:
    /// parallel).
    #[arg(long, value_name = "BETA,THETA", value_delimiter = ',', allow_hyphen_values = true)]
    pub tilt_deg: Option<Vec<f64>>,
    /// The lamella's origin relative to the beam, along X_f and Z_f (µm; default 0,0).
    #[arg(long, value_name = "X,Z", value_delimiter = ',', allow_hyphen_values = true)]
    pub lateral_um: Option<Vec<f64>>,
    /// Rotation of the lamella about the beam (°; default 0).
    #[arg(long, value_name = "DEG", allow_hyphen_values = true)]
    pub rotation_deg: Option<f64>,
    /// Hold the gap (the larger of start and end) while the rest moves.
    #[arg(long)]
    pub keep_gap: bool,
    /// Run the targets of a recipe file (RON) one after the other, each proven before the next.
    #[arg(long, value_name = "FILE")]
    pub recipe: Option<PathBuf>,
    /// Continue the recipe after its last confirmed step in the session's history.
    #[arg(long, requires_all = ["recipe", "session"])]
    pub resume: bool,
    /// Prove by the fringes along the path (from a pose a sweep measured) instead of a sweep at
    /// the end, as on a bench without a tunable laser.
    #[arg(long)]
    pub no_sweeps: bool,
    /// Do not measure the tilt at the end pose (two ±3° rotations about X_f and Z_f, about 20 s
    /// of bench time per move): the gap is then read at the requested tilt, as the extrinsics say.
    #[arg(long)]
    pub no_tilt: bool,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

/// The document `--json` prints.
#[derive(Serialize)]
struct JsonOut<'a> {
    bench: String,
    recipe: Option<&'a str>,
    moves: &'a [MoveRecord],
}

/// Where the moves come from: a single target, or a recipe's steps from one on.
struct Steps {
    recipe: Option<(Recipe, PathBuf)>,
    steps: Vec<(usize, String, Target, bool)>,
}

/// Place the lamella and print what happened.
pub fn move_lamella(a: &MoveArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let hardware = hardware_bench_file(&a.bench)?;
    let preset = BenchPreset::resolve(if hardware.is_some() { &a.model } else { &a.bench })?;
    let base = PhaseModel::new(
        preset.robot_description()?,
        Extrinsics::nominal_design(),
        preset.optics,
        &preset.ambient,
        preset.laser.wavelength_nm,
    )
    .map_err(|problem| CliError::Argument { argument: "--bench", problem })?;
    let _lock = a.session.as_deref().map(FolderLock::acquire).transpose()?;
    let mut session = a.session.as_deref().map(Session::load).transpose()?;
    let placement = placement(a, session.as_ref(), &base)?;
    let steps = steps(a, session.as_ref())?;
    let mut bench: Box<dyn Bench> = match hardware {
        Some(config) => {
            let clock = EmuClock::new(config.time_scale);
            let robot = preset.robot_description()?;
            Box::new(
                open_hardware_bench(&preset, robot, config, clock)
                    .map_err(|problem| CliError::Failed { what: "the hardware bench", problem })?
                    .0,
            )
        }
        None => Box::new(VirtualBench::new(&preset, Some(a.seed.unwrap_or(preset.seed + 1)))?),
    };
    let references = match (&session, a.session.as_deref()) {
        (Some(s), Some(dir)) if a.no_sweeps || !bench.tunable_laser() => {
            s.position_references(dir, &placement.model)?
        }
        _ => Vec::new(),
    };
    if !a.json {
        writeln!(out, "moving on {} with the extrinsics of {}", bench.name(), placement.source)?;
    }
    let mut records = Vec::new();
    for (index, label, target, keep_gap) in &steps.steps {
        let mut control = RunControl { cancel: &INTERRUPT, on_samples: &mut |_, _| {}, on_progress: &mut |_| {} };
        let started = now_utc_rfc3339();
        let mut record =
            move_to(bench.as_mut(), &placement, target, *keep_gap, &references, proof_options(a), &mut control)
                .map_err(|e| refused(&steps, *index, e))?;
        record.label = label.clone();
        record.recipe = steps.recipe.as_ref().map(|(r, _)| (r.name.clone(), *index));
        record.started_utc = Some(started);
        tracing::info!(verdict = record.verdict.word(), "move: {}", record.note);
        if let (Some(s), Some(dir)) = (session.as_mut(), a.session.as_deref()) {
            s.moves.push(record.clone());
            s.save(dir)?;
        }
        if !a.json {
            print_move(&record, out)?;
        }
        let done = record.verdict == Verdict::Confirmed;
        records.push(record);
        if !done {
            break;
        }
    }
    if a.json {
        let doc = JsonOut {
            bench: bench.name(),
            recipe: steps.recipe.as_ref().map(|(r, _)| r.name.as_str()),
            moves: &records,
        };
        writeln!(out, "{}", json_text(&doc)?)?;
    }
    outcome(a, &steps, &records)
}

/// The placement of `--session` (its calibration) or `--extrinsics` (taken as exact).
fn placement(a: &MoveArgs, session: Option<&Session>, base: &PhaseModel) -> Result<Placement, CliError> {
    match (session, &a.session, &a.extrinsics) {
        (Some(s), Some(dir), _) => s.placement(base, &format!("session {}", dir.display())).map_err(|problem| {
            CliError::File(FileError::Invalid {
                file: photorobot_core::session::session_path(dir),
                field: "calibration".into(),
                problem,
            })
        }),
        (_, _, Some(file)) => {
            let e = Extrinsics::load(file)?;
            Placement::new(base, e, None, &[], &format!("file {} (taken as exact)", file.display()))
                .map_err(|e| CliError::Failed { what: "the positioning model", problem: e.to_string() })
        }
        _ => {
            Err(CliError::Argument { argument: "--session", problem: "give --session DIR or --extrinsics FILE".into() })
        }
    }
}

/// The one target of the command line, or the recipe's steps (from the first not confirmed
/// in the session with `--resume`).
fn steps(a: &MoveArgs, session: Option<&Session>) -> Result<Steps, CliError> {
    if let Some(file) = &a.recipe {
        let recipe = Recipe::load(file)?;
        let first = match (a.resume, session) {
            (true, Some(s)) => recipe.next_step(&s.moves),
            _ => 0,
        };
        let steps =
            recipe.steps.iter().enumerate().skip(first).map(|(i, s)| (i, s.label.clone(), s.target, s.keep_gap));
        let steps = steps.collect();
        return Ok(Steps { recipe: Some((recipe, file.clone())), steps });
    }
    let pair = |v: &Option<Vec<f64>>, argument: &'static str| -> Result<[f64; 2], CliError> {
        match v.as_deref() {
            None => Ok([0.0, 0.0]),
            Some([x, y]) => Ok([*x, *y]),
            Some(other) => Err(CliError::Argument {
                argument,
                problem: format!("expected two comma-separated numbers, found {}", other.len()),
            }),
        }
    };
    let target = Target {
        gap_um: a.gap_um.unwrap_or(f64::NAN),
        tilt_deg: pair(&a.tilt_deg, "--tilt-deg")?,
        lateral_um: pair(&a.lateral_um, "--lateral-um")?,
        rotation_deg: a.rotation_deg.unwrap_or(0.0),
    };
    target.check().map_err(|problem| CliError::Argument { argument: "--gap-um/--tilt-deg/--lateral-um", problem })?;
    Ok(Steps { recipe: None, steps: vec![(0, String::new(), target, a.keep_gap)] })
}

/// A move refused before anything moved: a wrong target on the command line (exit 2), or in
/// the recipe file (exit 3, naming its step).
fn refused(steps: &Steps, index: usize, e: MoveError) -> CliError {
    match &steps.recipe {
        Some((_, file)) => CliError::File(FileError::Invalid {
            file: file.clone(),
            field: format!("steps[{index}].target"),
            problem: e.to_string(),
        }),
        None => {
            CliError::Argument { argument: "--gap-um/--tilt-deg/--lateral-um/--rotation-deg", problem: e.to_string() }
        }
    }
}

/// Exit 0 when every move ran confirmed, 130 when Ctrl-C stopped one (with the line that
/// resumes a recipe), 1 otherwise.
fn outcome(a: &MoveArgs, steps: &Steps, records: &[MoveRecord]) -> Result<(), CliError> {
    let Some(last) = records.last() else { return Ok(()) };
    if last.verdict == Verdict::Stopped && INTERRUPT.load(Ordering::SeqCst) {
        if let (Some((_, file)), Some(dir)) = (&steps.recipe, &a.session) {
            return Err(CliError::Interrupted { session: dir.clone(), resume: resume_command(a, file, dir) });
        }
    }
    match last.verdict {
        Verdict::Confirmed => Ok(()),
        v => Err(CliError::Failed { what: "move", problem: format!("{}: {}", v.word(), last.note) }),
    }
}

/// The command line that continues a recipe from its first step not confirmed.
fn resume_command(a: &MoveArgs, recipe: &Path, session: &Path) -> String {
    let mut cmd = format!("photorobot move --bench {}", a.bench);
    if let Some(seed) = a.seed {
        cmd += &format!(" --seed {seed}");
    }
    cmd += &format!(" --session {} --recipe {} --resume", session.display(), recipe.display());
    if a.no_sweeps {
        cmd += " --no-sweeps";
    }
    if a.no_tilt {
        cmd += " --no-tilt";
    }
    cmd
}

/// What the proof of each move measures, as the flags ask.
fn proof_options(a: &MoveArgs) -> ProofOptions {
    ProofOptions { sweeps: !a.no_sweeps, tilt: !a.no_tilt }
}

/// One move as text: requested, forecast, measured, verdict.
fn print_move(r: &MoveRecord, out: &mut dyn Write) -> Result<(), CliError> {
    let name = if r.label.is_empty() { String::new() } else { format!(" ({})", r.label) };
    writeln!(out, "\nmove{name}: {}", r.requested.describe())?;
    let q = r.joints_end;
    writeln!(
        out,
        "  joints at the end: q1 {:.3} µm, q2 {:.3} µm, q3 {:.3} µm, q4 {:.4}°, q5 {:.4}°, q6 {:.4}° ({} waypoints)",
        q.q1_um, q.q2_um, q.q3_um, q.q4_deg, q.q5_deg, q.q6_deg, r.waypoints
    )?;
    match &r.forecast {
        Some(f) => writeln!(
            out,
            "  forecast σ: gap {:.2} nm, tilt ({:.5}°, {:.5}°), lateral ({:.4}, {:.4}) µm, rotation {:.5}°",
            f.gap_sigma_nm,
            f.tilt_sigma_deg[0],
            f.tilt_sigma_deg[1],
            f.lateral_sigma_um[0],
            f.lateral_sigma_um[1],
            f.rotation_sigma_deg
        )?,
        None => writeln!(out, "  forecast: none (the extrinsics are taken as exact)")?,
    }
    if let Some(m) = &r.measurement {
        writeln!(out, "  measured gap: {:.4} µm ± {:.2} nm ({})", m.gap_um, m.sigma_nm, m.method)?;
    }
    if let Some(t) = &r.tilt {
        writeln!(out, "  {}", t.describe())?;
    }
    writeln!(out, "  {}: {}", r.verdict.word().to_uppercase(), r.note)?;
    writeln!(out, "  {}", r.model_only)?;
    Ok(())
}
