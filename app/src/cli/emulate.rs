//! `photorobot emulate pi|smaract|mcs2|laser|all [--port N] [--family keysight|santec] [--time-scale S]
//! [--ideal] [--hardware FILE] [--seed N]`: serve a stage-controller or tunable-laser protocol emulator
//! (or all of them as one optical bench) on loopback, as strict and as imperfect as the instruments
//! unless `--ideal`. Owns only argument parsing and printing; the emulators are
//! `photorobot_core::hardware::emulator`.

use super::common::CliError;
use photorobot_core::bench::BenchPreset;
use photorobot_core::hardware::controller_bench::{HardwareConfig, LaserFamily, MAX_TIME_SCALE};
use photorobot_core::hardware::emulator::laser::run_laser_emulator;
use photorobot_core::hardware::emulator::optical_bench::run_optical_bench;
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
    /// SmarAct MCS2, its ASCII (SCPI-like) protocol over TCP (default port 55551).
    Mcs2,
    /// A tunable laser, SCPI over a raw socket (default port 5025 Keysight, 5000 Santec).
    Laser,
    /// The PI, the MCS (or MCS2) and the laser on one emulated optical bench (default ports).
    All,
}

/// The laser's command set.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum LaserKind {
    /// Keysight 816x / N777x.
    Keysight,
    /// Santec TSL-570.
    Santec,
}

/// Arguments of `photorobot emulate`.
#[derive(Debug, clap::Args)]
pub struct EmulateArgs {
    /// The controller to emulate.
    #[arg(value_enum)]
    pub controller: EmulatedController,
    /// TCP port on 127.0.0.1 (default: the device's; not with `all`).
    #[arg(long)]
    pub port: Option<u16>,
    /// The laser's command set (`laser`, `all`).
    #[arg(long, value_enum, default_value = "keysight")]
    pub family: LaserKind,
    /// The virtual-bench preset whose optics the photodiode sees (`all`).
    #[arg(long, default_value = "table2-ideal")]
    pub bench: String,
    /// Emulated seconds per real second (1: real time). A bench on these emulators names the same
    /// `time_scale` in its hardware bench file.
    #[arg(long, value_name = "S", default_value_t = 1.0, value_parser = time_scale)]
    pub time_scale: f64,
    /// Ideal instruments: no ADC noise or quantisation, no sweep latency or run-up, `VEL` without
    /// `VCO` (the default is as strict and as imperfect as the real ones).
    #[arg(long)]
    pub ideal: bool,
    /// The hardware bench file whose controllers and wiring `all` emulates (default: the embedded
    /// femto-hardware: an E-712 and an MCS; a file naming an MCS2 gets one).
    #[arg(long, value_name = "FILE")]
    pub hardware: Option<std::path::PathBuf>,
    /// Seed of the emulated detector's noise (`all`; default: from the clock, a new bench each run).
    #[arg(long)]
    pub seed: Option<u64>,
}

/// A clock scale in (0, MAX_TIME_SCALE], or a message clap shows after the flag's name.
fn time_scale(text: &str) -> Result<f64, String> {
    let v: f64 =
        text.trim().parse().map_err(|_| format!("expected a number (emulated s per real s), found `{text}`"))?;
    if v.is_finite() && v > 0.0 && v <= MAX_TIME_SCALE {
        Ok(v)
    } else {
        Err(format!("expected emulated seconds per real second in (0, {MAX_TIME_SCALE}], found {v}"))
    }
}

/// How the clock runs, for the ready line.
fn pace(scale: f64) -> String {
    if scale == 1.0 {
        "real time".into()
    } else {
        format!("{scale}× real time")
    }
}

/// The emulators' kind, for the ready line.
fn realism(ideal: bool) -> &'static str {
    if ideal {
        "ideal"
    } else {
        "realistic"
    }
}

/// A seed from the clock: a new emulated bench each run.
fn clock_seed() -> u64 {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(1, |d| d.as_nanos() as u64)
}

fn family(k: LaserKind) -> LaserFamily {
    match k {
        LaserKind::Keysight => LaserFamily::Keysight,
        LaserKind::Santec => LaserFamily::Santec,
    }
}

/// Serve the emulator until the process is stopped (Ctrl-C).
pub fn emulate(a: &EmulateArgs, out: &mut dyn Write) -> Result<(), CliError> {
    serve(a, out, &AtomicBool::new(false))
}

/// Serve until `stop` is set.
fn serve(a: &EmulateArgs, out: &mut dyn Write, stop: &AtomicBool) -> Result<(), CliError> {
    let mut ready_error = None;
    let mut say = |text: String| {
        if let Err(e) = writeln!(out, "{text}").and_then(|()| out.flush()) {
            ready_error = Some(e);
        }
    };
    let kind = match a.controller {
        EmulatedController::Pi => EmulatorKind::Pi,
        EmulatedController::Smaract => EmulatorKind::SmarAct,
        EmulatedController::Mcs2 => EmulatorKind::Mcs2,
        EmulatedController::Laser => {
            let f = family(a.family);
            run_laser_emulator(f, a.port, a.time_scale, !a.ideal, stop, &mut |addr| {
                let (pace, kind) = (pace(a.time_scale), realism(a.ideal));
                say(format!("{f:?} laser (SCPI) emulator listening on {addr}, {pace}, {kind}; Ctrl-C to stop"))
            })?;
            return ready_error.map_or(Ok(()), |e| Err(e.into()));
        }
        EmulatedController::All => {
            if a.port.is_some() {
                return Err(CliError::Argument {
                    argument: "--port",
                    problem: "`emulate all` serves every emulator on its default port; give no --port".into(),
                });
            }
            let preset = BenchPreset::resolve(&a.bench)?;
            let mut hardware = match &a.hardware {
                Some(path) => HardwareConfig::load(path)?,
                None => HardwareConfig::femto(),
            };
            hardware.time_scale = a.time_scale;
            let f = family(a.family);
            let seed = a.seed.unwrap_or_else(clock_seed);
            run_optical_bench(&preset, &hardware, (f, seed, !a.ideal), stop, &mut |addresses| {
                let list: Vec<String> = addresses.iter().map(|(n, at)| format!("{n} at {at}")).collect();
                let (name, pace, kind) = (&preset.name, pace(a.time_scale), realism(a.ideal));
                say(format!(
                    "optical bench `{name}` emulated: {}; {pace}, {kind}, seed {seed}; Ctrl-C to stop",
                    list.join(", ")
                ))
            })
            .map_err(|problem| CliError::Failed { what: "emulate all", problem })?;
            return ready_error.map_or(Ok(()), |e| Err(e.into()));
        }
    };
    run_emulator(kind, a.port, a.time_scale, !a.ideal, stop, &mut |addr| {
        let name = match kind {
            EmulatorKind::Pi => "PI E-712 (GCS 2)",
            EmulatorKind::SmarAct => "SmarAct MCS (ASCII)",
            EmulatorKind::Mcs2 => "SmarAct MCS2 (ASCII)",
        };
        let (pace, kind) = (pace(a.time_scale), realism(a.ideal));
        say(format!("{name} emulator listening on {addr}, {pace}, {kind}; Ctrl-C to stop"))
    })?;
    ready_error.map_or(Ok(()), |e| Err(e.into()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;
    use std::io::{BufRead, BufReader};
    use std::sync::atomic::Ordering;

    fn args(line: &[&str]) -> EmulateArgs {
        match super::super::Cli::try_parse_from(line).unwrap().command {
            Some(super::super::Command::Emulate(a)) => a,
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn emulate_laser_serves_the_santec_command_set() {
        let a = args(&["photorobot", "emulate", "laser", "--family", "santec", "--port", "0", "--time-scale", "4"]);
        assert_eq!((a.controller, a.family, a.time_scale), (EmulatedController::Laser, LaserKind::Santec, 4.0));
        let stop = AtomicBool::new(false);
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::scope(|s| {
            let server = s.spawn(|| {
                let mut out = Vec::new();
                let mut w = TellFirstLine { out: &mut out, tx: Some(tx) };
                serve(&a, &mut w, &stop)
            });
            let line = rx.recv_timeout(std::time::Duration::from_secs(5)).unwrap();
            assert!(line.starts_with("Santec laser (SCPI) emulator listening on 127.0.0.1:"), "{line}");
            assert!(line.contains(", 4× real time, realistic;"), "{line}");
            let addr = line.split_whitespace().find(|w| w.starts_with("127.0.0.1:")).unwrap().trim_end_matches(',');
            let stream = std::net::TcpStream::connect(addr).unwrap();
            stream.set_read_timeout(Some(std::time::Duration::from_secs(2))).unwrap();
            (&stream).write_all(b"*IDN?\n").unwrap();
            let mut reply = String::new();
            BufReader::new(&stream).read_line(&mut reply).unwrap();
            assert!(reply.starts_with("SANTEC,TSL-570"), "{reply}");
            stop.store(true, Ordering::Relaxed);
            server.join().unwrap().unwrap();
        });
        let e = serve(&args(&["photorobot", "emulate", "all", "--port", "1"]), &mut Vec::new(), &stop).unwrap_err();
        assert!(e.to_string().contains("give no --port"), "{e}");
        let e = super::super::Cli::try_parse_from(["photorobot", "emulate", "all", "--time-scale", "0"]).unwrap_err();
        assert!(e.to_string().contains("expected emulated seconds per real second in (0, 1000], found 0"), "{e}");
    }

    /// A writer that sends the first line written to a channel.
    struct TellFirstLine<'a> {
        out: &'a mut Vec<u8>,
        tx: Option<std::sync::mpsc::Sender<String>>,
    }

    impl Write for TellFirstLine<'_> {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            self.out.extend_from_slice(buf);
            if let (Some(tx), Some(end)) = (&self.tx, self.out.iter().position(|&b| b == b'\n')) {
                let _ = tx.send(String::from_utf8_lossy(&self.out[..end]).into_owned());
                self.tx = None;
            }
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }
}
