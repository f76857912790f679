//! The `photorobot` binary: with no arguments it starts the workbench GUI, otherwise it runs a CLI command.
//! Owns only process-level concerns (exit codes, stderr, the log, Ctrl-C).

use clap::Parser;
use photorobot_app::cli::{progress, Cli, CliError, Command, Outcome};
use std::process::ExitCode;

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => return usage(e),
    };
    photorobot_app::log::init(cli.verbose, cli.quiet);
    // Commands that record stop cleanly on Ctrl-C; the others keep its default (quit at once).
    if matches!(cli.command, Some(Command::Calibrate(_) | Command::Simulate(_) | Command::Move(_))) {
        progress::install_ctrl_c();
    }
    let mut stdout = std::io::stdout().lock();
    let result = photorobot_app::cli::run_parsed(cli, &mut stdout);
    photorobot_app::log::close_session_log();
    match result {
        Ok(Outcome::Done) => ExitCode::SUCCESS,
        Ok(Outcome::StartGui) => {
            drop(stdout);
            match photorobot_app::gui::run_native() {
                Ok(()) => ExitCode::SUCCESS,
                Err(e) => {
                    eprintln!("error: cannot start the GUI: {e}");
                    ExitCode::from(1)
                }
            }
        }
        Err(CliError::Usage(e)) => usage(e),
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(e.exit_code())
        }
    }
}

/// clap formats help, version and usage errors itself.
fn usage(e: clap::Error) -> ExitCode {
    let _ = e.print();
    ExitCode::from(if e.use_stderr() { 2 } else { 0 })
}
