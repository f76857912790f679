//! A whole emulated optical bench for `photorobot emulate all`: the PI E-712 and SmarAct MCS
//! emulators of [`LocalEmulators`] and a tunable-laser emulator serving the same emulated laser, so
//! the photodiode sees the sweeps the laser's driver starts.

use super::laser::{default_port, LaserEmulator, LaserEmulatorConfig};
use super::LocalEmulators;
use crate::bench::BenchPreset;
use crate::hardware::controller_bench::{HardwareConfig, LaserFamily};
use std::io::ErrorKind;
use std::sync::atomic::{AtomicBool, Ordering};

/// The emulators of one optical bench.
pub struct OpticalBenchEmulators {
    /// The stage controllers (and the photodiode).
    pub stages: LocalEmulators,
    /// The laser.
    pub laser: LaserEmulator,
}

impl OpticalBenchEmulators {
    /// Start the stage emulators on the controllers' default ports and the laser of `family` on its
    /// default port (any free port where one is taken), the photodiode fed by `preset`'s optics, on
    /// a clock `time_scale` times faster than real time.
    pub fn start(preset: &BenchPreset, family: LaserFamily, seed: u64, time_scale: f64) -> Result<Self, String> {
        let robot = preset.robot_description().map_err(|e| e.to_string())?;
        let config = HardwareConfig { time_scale, ..HardwareConfig::femto() };
        let stages = LocalEmulators::start(
            preset,
            seed,
            &robot,
            &config,
            crate::hardware::pi_gcs::DEFAULT_PORT,
            crate::hardware::smaract::DEFAULT_PORT,
        )?;
        let start = |port| LaserEmulator::start_on(port, stages.emu_laser(), LaserEmulatorConfig::new(family));
        let laser = match start(default_port(family)) {
            Err(e) if e.kind() == ErrorKind::AddrInUse => start(0),
            other => other,
        }
        .map_err(|e| format!("cannot start the {family:?} laser emulator: {e}"))?;
        Ok(OpticalBenchEmulators { stages, laser })
    }

    /// (name, host:port) of every emulator.
    pub fn addresses(&self, family: LaserFamily) -> Vec<(String, String)> {
        let mut a = self.stages.addresses();
        a.push((format!("{family:?} laser"), self.laser.addr().to_string()));
        a
    }
}

/// (name, host:port) of each emulator.
pub type Addresses = [(String, String)];

/// Serve a whole optical bench on a clock `time_scale` times faster than real time until `stop`
/// is set; `on_ready` gets every emulator's address.
pub fn run_optical_bench(
    preset: &BenchPreset,
    family: LaserFamily,
    time_scale: f64,
    stop: &AtomicBool,
    on_ready: &mut dyn FnMut(&Addresses),
) -> Result<(), String> {
    let emus = OpticalBenchEmulators::start(preset, family, 1, time_scale)?;
    on_ready(&emus.addresses(family));
    while !stop.load(Ordering::Relaxed) {
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    Ok(())
}
