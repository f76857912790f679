//! A whole emulated optical bench for `photorobot emulate all`: the PI E-712 and SmarAct MCS (or
//! MCS2) emulators of [`LocalEmulators`] and a tunable-laser emulator serving the same emulated
//! laser, so the photodiode sees the sweeps the laser's driver starts.

use super::laser::{default_port, LaserEmulator, LaserEmulatorConfig};
use super::LocalEmulators;
use crate::bench::BenchPreset;
use crate::hardware::controller_bench::{ControllerKind, HardwareConfig, LaserFamily};
use std::io::ErrorKind;
use std::sync::atomic::{AtomicBool, Ordering};

/// The emulators of one optical bench.
pub struct OpticalBenchEmulators {
    /// The stage controllers (and the photodiode).
    pub stages: LocalEmulators,
    /// The laser.
    pub laser: LaserEmulator,
}

/// The default port of the controller of `kind`.
fn default_controller_port(kind: ControllerKind) -> u16 {
    match kind {
        ControllerKind::PiGcs => crate::hardware::pi_gcs::DEFAULT_PORT,
        ControllerKind::SmarActMcs => crate::hardware::smaract::DEFAULT_PORT,
        ControllerKind::SmarActMcs2 => crate::hardware::smaract_mcs2::DEFAULT_PORT,
    }
}

impl OpticalBenchEmulators {
    /// Start the stage emulators `hardware` names on their controllers' default ports and the
    /// laser of `family` on its default port (any free port where one is taken), the photodiode
    /// fed by `preset`'s optics, on a clock `hardware.time_scale` times faster than real time;
    /// realistic or ideal.
    pub fn start(
        preset: &BenchPreset,
        hardware: &HardwareConfig,
        family: LaserFamily,
        seed: u64,
        realistic: bool,
    ) -> Result<Self, String> {
        let robot = preset.robot_description().map_err(|e| e.to_string())?;
        let port = |kinds: &[ControllerKind]| {
            hardware.controllers.iter().find(|c| kinds.contains(&c.kind)).map_or(0, |c| default_controller_port(c.kind))
        };
        let ports = (port(&[ControllerKind::PiGcs]), port(&[ControllerKind::SmarActMcs, ControllerKind::SmarActMcs2]));
        let stages = LocalEmulators::start_with(preset, seed, &robot, hardware, ports, realistic)?;
        let config = if realistic { LaserEmulatorConfig::new(family) } else { LaserEmulatorConfig::ideal(family) };
        let start = |port| LaserEmulator::start_on(port, stages.emu_laser(), config.clone());
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

/// Serve a whole optical bench as `hardware` wires it (its clock's `time_scale` included), the
/// laser of `family`, the detector noise seeded by `seed`, realistic or ideal, until `stop` is set;
/// `on_ready` gets every emulator's address.
pub fn run_optical_bench(
    preset: &BenchPreset,
    hardware: &HardwareConfig,
    (family, seed, realistic): (LaserFamily, u64, bool),
    stop: &AtomicBool,
    on_ready: &mut dyn FnMut(&Addresses),
) -> Result<(), String> {
    let emus = OpticalBenchEmulators::start(preset, hardware, family, seed, realistic)?;
    on_ready(&emus.addresses(family));
    while !stop.load(Ordering::Relaxed) {
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    Ok(())
}
