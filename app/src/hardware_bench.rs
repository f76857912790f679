//! A hardware bench from a hardware configuration: the stage controllers and the tunable laser it
//! names, modelled by a preset's robot, optics and motion limits. The Connection view and
//! `photorobot calibrate --bench <hardware file>` open their bench through [`open_hardware_bench`].

use photorobot_core::bench::{BenchError, BenchPreset};
use photorobot_core::hardware::controller_bench::{FixedLaser, HardwareConfig, Laser, LaserFamily};
use photorobot_core::hardware::emulator::EmuClock;
use photorobot_core::hardware::laser::ScpiLaser;
use photorobot_core::hardware::{ControllerBench, HwError};
use photorobot_core::model::robot::RobotDescription;
use std::sync::Arc;

/// What the tunable laser answered: `*IDN?`, its wavelength and whether it sweeps.
#[derive(Debug, Clone, PartialEq)]
pub struct LaserIdentity {
    /// The `*IDN?` reply.
    pub idn: String,
    /// The wavelength it reports (nm).
    pub wavelength_nm: f64,
    /// A sweep is running.
    pub sweeping: bool,
}

/// An error message that names the address it concerns.
pub fn at_address(e: &str, name: &str, address: &str) -> String {
    let mut msg = if e.contains(address) { e.to_string() } else { format!("{e} ({name} at {address})") };
    if e.contains("no reply to") {
        msg.push_str(": nothing answered in time; is this the right address and port, and a controller of this kind?");
    }
    msg
}

/// Open the laser `config` names and read its identity (`None`: no laser to drive, a
/// [`FixedLaser`] at `nominal_nm` on which sweeps are refused).
pub fn open_laser(config: &HardwareConfig, nominal_nm: f64) -> Result<(Box<dyn Laser>, Option<LaserIdentity>), String> {
    match &config.laser {
        Some(l) if l.family != LaserFamily::None => {
            let at = |e: HwError| at_address(&e.to_string(), &format!("{:?} laser", l.family), &l.address);
            let mut laser = ScpiLaser::connect(l.family, &l.address, l.timeout_s, nominal_nm).map_err(at)?;
            let wavelength_nm = laser.wavelength_nm().map_err(at)?;
            let sweeping = laser.sweep_running().map_err(at)?;
            let id = LaserIdentity { idn: laser.idn().to_string(), wavelength_nm, sweeping };
            Ok((Box::new(laser), Some(id)))
        }
        _ => Ok((Box::new(FixedLaser::new(nominal_nm)), None)),
    }
}

/// Connect the controllers and the laser of `config` as `robot` (its `drive` fields map the
/// joints), with `preset`'s motion limits and ambient conditions, on `clock` (the wall clock,
/// [`EmuClock::new`]`(config.time_scale)`, except on in-process emulators, which share theirs).
pub fn open_hardware_bench(
    preset: &BenchPreset,
    robot: RobotDescription,
    config: HardwareConfig,
    clock: Arc<EmuClock>,
) -> Result<(ControllerBench, Option<LaserIdentity>), String> {
    let (laser, identity) = open_laser(&config, preset.laser.wavelength_nm)?;
    let bench = ControllerBench::connect(robot, config, preset.motion, preset.ambient, laser, clock).map_err(|e| {
        match e {
            // The message names the controller and what happened; "bench fault:" adds nothing here.
            BenchError::Fault(m) | BenchError::Config(m) => m,
            other => other.to_string(),
        }
    })?;
    Ok((bench, identity))
}
