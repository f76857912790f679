//! The `photorobot` binary: with no arguments it starts the workbench GUI, otherwise it runs a CLI command.
//! Owns only process-level concerns (exit codes, stderr).

use std::process::ExitCode;

fn main() -> ExitCode {
    let mut stdout = std::io::stdout().lock();
    match photorobot_app::cli::run(std::env::args_os(), &mut stdout) {
        Ok(photorobot_app::cli::Outcome::Done) => ExitCode::SUCCESS,
        Ok(photorobot_app::cli::Outcome::StartGui) => {
            drop(stdout);
            match photorobot_app::gui::run_native() {
                Ok(()) => ExitCode::SUCCESS,
                Err(e) => {
                    eprintln!("error: cannot start the GUI: {e}");
                    ExitCode::from(1)
                }
            }
        }
        Err(photorobot_app::cli::CliError::Usage(e)) => {
            // clap formats help, version and usage errors itself.
            let _ = e.print();
            ExitCode::from(if e.use_stderr() { 2 } else { 0 })
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(e.exit_code())
        }
    }
}
