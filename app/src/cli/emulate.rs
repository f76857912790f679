//! `photorobot emulate pi|smaract [--port N]`: serve a stage-controller protocol emulator on loopback.
//! Owns only argument parsing and printing; the emulators are `photorobot_core::hardware::emulator`.

use super::common::CliError;
use photorobot_core::hardware::emulator::{run_emulator, EmulatorKind};
use std::io::Write;
use std::sync::atomic::AtomicBool;

/// Which controller to emulate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum EmulatedController {
    /// PI E-712, GCS 2 over TCP (default port 50000).
    Pi,
    /// SmarAct MCS, ASCII protocol over TCP (default port 5000).
    Smaract,
}

/// Arguments of `photorobot emulate`.
#[derive(Debug, clap::Args)]
pub struct EmulateArgs {
    /// The controller to emulate.
    #[arg(value_enum)]
    pub controller: EmulatedController,
    /// TCP port on 127.0.0.1 (default: the controller's, 50000 for PI, 5000 for SmarAct).
    #[arg(long)]
    pub port: Option<u16>,
}

/// Serve the emulator until the process is stopped (Ctrl-C).
pub fn emulate(a: &EmulateArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let kind = match a.controller {
        EmulatedController::Pi => EmulatorKind::Pi,
        EmulatedController::Smaract => EmulatorKind::SmarAct,
    };
    let stop = AtomicBool::new(false);
    let mut ready_error = None;
    run_emulator(kind, a.port, &stop, &mut |addr| {
        let name = match kind {
            EmulatorKind::Pi => "PI E-712 (GCS 2)",
            EmulatorKind::SmarAct => "SmarAct MCS (ASCII)",
        };
        if let Err(e) =
            writeln!(out, "{name} emulator listening on {addr}, real time; Ctrl-C to stop").and_then(|()| out.flush())
        {
            ready_error = Some(e);
        }
    })?;
    match ready_error {
        Some(e) => Err(e.into()),
        None => Ok(()),
    }
}
