//! The command-line interface: clap parsing and dispatch to one module per command, each printing
//! a core result as plain text or JSON. Owns no science: each command calls `photorobot_core`.
//! Arrows go one way: this module -> the command modules -> `common`.

pub mod calibrate;
pub mod common;
pub mod design;
pub mod diagnose;
pub mod diagnose_session;
pub mod emulate;
pub mod frames;
pub mod fringes;
pub mod r#move;
pub mod progress;
pub mod report;
pub mod simulate;
pub mod validate;

pub use common::{json_text, CliError, JSON_SCHEMA};

use clap::{Parser, Subcommand};
use std::ffi::OsString;
use std::io::Write;

/// photorobot: calibrate a photonics assembly bench from Fabry-Perot fringes.
/// With no command, starts the workbench GUI on the virtual bench.
#[derive(Debug, Parser)]
#[command(name = "photorobot", version, about, long_about = None)]
pub struct Cli {
    /// What to do (default: start the GUI).
    #[command(subcommand)]
    pub command: Option<Command>,
    /// No progress bars; only errors on stderr.
    #[arg(long, short, global = true)]
    pub quiet: bool,
    /// More on stderr: -v info, -vv debug (RUST_LOG overrides).
    #[arg(long, short, global = true, action = clap::ArgAction::Count)]
    pub verbose: u8,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Print every frame's pose, the signed cavity length L and the reflection point P_r.
    Frames(frames::FramesArgs),
    /// Run a motion plan on a virtual bench and write the recorded traces as CSV.
    Simulate(simulate::SimulateArgs),
    /// Analyse a recorded trace: fringe count, dL and its uncertainty (or the absolute gap of a sweep).
    Fringes(fringes::FringesArgs),
    /// Measure, identify and validate end to end on a bench; write the session.
    Calibrate(calibrate::CalibrateArgs),
    /// Choose motions that reach the required uncertainties in the least bench time; write the plan.
    Design(design::DesignArgs),
    /// Find where model and data disagree on a calibration session, name the missing effect, add it.
    Diagnose(diagnose::DiagnoseArgs),
    /// Write a session's calibration report as one self-contained HTML file.
    Report(report::ReportArgs),
    /// Place the lamella at a gap, tilt, lateral offset and rotation relative to the fiber with a
    /// calibration, and prove the gap by a measurement that does not use the extrinsics.
    Move(r#move::MoveArgs),
    /// Check a calibration on the bench without recalibrating: the validation motions with their proof.
    Validate(validate::ValidateArgs),
    /// Start the workbench GUI (the default when no command is given).
    Gui,
    /// Serve a stage-controller or tunable-laser protocol emulator (PI E-712, SmarAct MCS, Keysight or
    /// Santec laser, or all on one optical bench) on 127.0.0.1.
    Emulate(emulate::EmulateArgs),
}

/// What the caller should do after [`run`].
#[derive(Debug, PartialEq, Eq)]
pub enum Outcome {
    /// The command ran and printed its output.
    Done,
    /// No command was given: start the GUI.
    StartGui,
}

/// Parse `args` (including the program name) and run the command, writing to `out`.
pub fn run<I, T>(args: I, out: &mut dyn Write) -> Result<Outcome, CliError>
where
    I: IntoIterator<Item = T>,
    T: Into<OsString> + Clone,
{
    run_parsed(Cli::try_parse_from(args)?, out)
}

/// Run a parsed command line, writing to `out`.
pub fn run_parsed(cli: Cli, out: &mut dyn Write) -> Result<Outcome, CliError> {
    progress::set_quiet(cli.quiet);
    match cli.command {
        None | Some(Command::Gui) => Ok(Outcome::StartGui),
        Some(Command::Frames(a)) => frames::frames(&a, out).map(|()| Outcome::Done),
        Some(Command::Simulate(a)) => simulate::simulate(&a, out).map(|()| Outcome::Done),
        Some(Command::Fringes(a)) => fringes::fringes(&a, out).map(|()| Outcome::Done),
        Some(Command::Calibrate(a)) => calibrate::calibrate(&a, out).map(|()| Outcome::Done),
        Some(Command::Design(a)) => design::run_design(&a, out).map(|()| Outcome::Done),
        Some(Command::Diagnose(a)) => diagnose::diagnose(&a, out).map(|()| Outcome::Done),
        Some(Command::Report(a)) => report::report(&a, out).map(|()| Outcome::Done),
        Some(Command::Move(a)) => r#move::move_lamella(&a, out).map(|()| Outcome::Done),
        Some(Command::Validate(a)) => validate::validate(&a, out).map(|()| Outcome::Done),
        Some(Command::Emulate(a)) => emulate::emulate(&a, out).map(|()| Outcome::Done),
    }
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
