//! The hardware configuration of a bench on controllers (`assets/benches/*-hardware.ron`): the
//! controllers on the network, the joints' zeros and directions, the photodiode's inputs, and the
//! recorder's and the polling's timing.

use crate::files::{self, FileError};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The hardware configuration of the paper's bench, embedded.
pub const FEMTO_HARDWARE_RON: &str = include_str!("../../../../assets/benches/femto-hardware.ron");

/// Which driver speaks to a controller.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum ControllerKind {
    /// PI GCS 2 over TCP (E-712).
    PiGcs,
    /// SmarAct MCS (first generation) ASCII over TCP (port 5000).
    SmarActMcs,
    /// SmarAct MCS2 ASCII (SCPI-like) over TCP (port 55551).
    SmarActMcs2,
}

/// One controller on the network.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ControllerConfig {
    /// Name, as in the robot description's `drive.controller` ("PI E-712").
    pub name: String,
    /// Driver.
    pub kind: ControllerKind,
    /// host:port.
    pub address: String,
    /// Reply timeout (s, real time). Default 2 s.
    #[serde(default = "default_timeout")]
    pub timeout_s: f64,
    /// Travel range per channel (µm or °) for controllers that cannot report it (MCS, MCS2); default
    /// unlimited (the robot's joint limits are checked before any move anyway).
    #[serde(default)]
    pub travel: Vec<(f64, f64)>,
}

fn default_timeout() -> f64 {
    2.0
}
fn one() -> f64 {
    1.0
}
fn default_sample_period() -> f64 {
    0.0005
}
fn default_poll_period() -> f64 {
    0.001
}
fn default_margin() -> f64 {
    10.0
}

/// Where joint zero sits on its axis and which way the joint runs: controller position =
/// `zero + sign·q` (µm or °).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointConfig {
    /// Joint name ("q1").
    pub joint: String,
    /// Controller position of the joint's zero (µm or °). Default 0.
    #[serde(default)]
    pub zero: f64,
    /// +1 or -1. Default +1.
    #[serde(default = "one")]
    pub sign: f64,
}

/// The photodiode and the laser's wavelength monitor on a controller's analog inputs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PhotodiodeConfig {
    /// Controller with the analog inputs and the data recorder.
    pub controller: String,
    /// Input channel of the photodiode.
    pub input: String,
    /// Optical power per input unit (mW per unit). Default 1.
    #[serde(default = "one")]
    pub mw_per_unit: f64,
    /// Input channel of the laser's wavelength monitor, if wired: the time base of the laser's
    /// sweeps (its readings, fitted, time the laser's log on the recorder's clock).
    #[serde(default)]
    pub wavelength_input: Option<String>,
    /// The monitor's scale: nm per input unit (default 1).
    #[serde(default = "one")]
    pub wavelength_nm_per_unit: f64,
    /// The monitor's offset: nm at input 0 (default 0).
    #[serde(default)]
    pub wavelength_offset_nm: f64,
    /// Digital input line of the same controller wired to the laser's trigger output, if any:
    /// the recorder of a sweep then starts at the laser's first logged point (E-712 `DRT` with an
    /// external trigger). A bench whose laser has neither this nor the monitor cannot time its
    /// sweeps and runs its plans without them.
    #[serde(default)]
    pub laser_trigger_input: Option<String>,
}

/// Which command set a tunable laser speaks (SCPI over a raw TCP socket).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum LaserFamily {
    /// Keysight 816x / N777x: `:SOUR0:WAV...` in metres, lambda log of f64 metres.
    Keysight,
    /// Santec TSL-570: `:WAV...` in nm, wavelength log of u32 in 0.1 pm.
    Santec,
    /// No laser the software can drive: it rests at the preset's wavelength and sweeps are refused.
    None,
}

/// The bench's tunable laser on the network.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LaserConfig {
    /// Command set.
    pub family: LaserFamily,
    /// host:port (the instrument's raw SCPI socket, e.g. port 5025).
    #[serde(default)]
    pub address: String,
    /// Reply timeout (s, real time). Default 2 s.
    #[serde(default = "default_timeout")]
    pub timeout_s: f64,
}

/// How a bench's controllers are reached and mapped to the joints.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HardwareConfig {
    /// Name of the bench.
    pub name: String,
    /// What it is.
    #[serde(default)]
    pub description: String,
    /// The controllers.
    pub controllers: Vec<ControllerConfig>,
    /// Joint zeros and directions (joints not listed: zero 0, sign +1).
    #[serde(default)]
    pub joints: Vec<JointConfig>,
    /// The photodiode.
    pub photodiode: PhotodiodeConfig,
    /// Recorder sampling period (s). Default 0.5 ms.
    #[serde(default = "default_sample_period")]
    pub sample_period_s: f64,
    /// Polling period while waiting (s, real time). Default 1 ms.
    #[serde(default = "default_poll_period")]
    pub poll_period_s: f64,
    /// Extra time allowed for a segment beyond twice its planned duration (s, bench time). Default 10 s.
    #[serde(default = "default_margin")]
    pub timeout_margin_s: f64,
    /// The tunable laser, if the software drives one (default: none).
    #[serde(default)]
    pub laser: Option<LaserConfig>,
    /// Bench seconds per real second: 1 for real hardware (the default); emulators served with
    /// `photorobot emulate --time-scale S` run S times faster, and a bench on them must run its
    /// clock at the same S.
    #[serde(default = "one")]
    pub time_scale: f64,
}

/// The fastest emulated clock a hardware file may name (bench seconds per real second).
pub const MAX_TIME_SCALE: f64 = 1000.0;

const EXPECTED: &str =
    "a HardwareConfig(name, controllers: [...], joints: [...], photodiode: (...)) as in assets/benches/femto-hardware.ron";

impl HardwareConfig {
    /// The paper's bench (PI E-712 and SmarAct MCS on the lab network), embedded.
    pub fn femto() -> Self {
        Self::from_ron_str(FEMTO_HARDWARE_RON, Path::new("assets/benches/femto-hardware.ron"))
            .expect("the embedded hardware configuration is valid (checked by tests)")
    }

    /// Load a configuration file.
    pub fn load(path: &Path) -> Result<Self, FileError> {
        let text = files::read_text(path)?;
        Self::from_ron_str(&text, path)
    }

    /// Parse configuration text; `origin` names it in errors.
    pub fn from_ron_str(text: &str, origin: &Path) -> Result<Self, FileError> {
        let c: Self = files::parse_ron(text, origin, EXPECTED)?;
        let bad = |field: &str, problem: String| FileError::Invalid {
            file: origin.to_path_buf(),
            field: field.into(),
            problem,
        };
        if c.controllers.is_empty() {
            return Err(bad("controllers", "expected at least one controller, found none".into()));
        }
        for (name, v) in [("sample_period_s", c.sample_period_s), ("poll_period_s", c.poll_period_s)] {
            if !(v.is_finite() && v > 0.0) {
                return Err(bad(name, format!("expected a positive number of seconds, found {v}")));
            }
        }
        if !(c.time_scale.is_finite() && c.time_scale > 0.0 && c.time_scale <= MAX_TIME_SCALE) {
            return Err(bad(
                "time_scale",
                format!("expected bench seconds per real second in (0, {MAX_TIME_SCALE}], found {}", c.time_scale),
            ));
        }
        let p = &c.photodiode;
        for (name, v) in
            [("photodiode.mw_per_unit", p.mw_per_unit), ("photodiode.wavelength_nm_per_unit", p.wavelength_nm_per_unit)]
        {
            if !(v.is_finite() && v != 0.0) {
                return Err(bad(name, format!("expected a finite non-zero scale, found {v}")));
            }
        }
        for (i, j) in c.joints.iter().enumerate() {
            if j.sign != 1.0 && j.sign != -1.0 {
                return Err(bad(&format!("joints[{i}].sign"), format!("expected 1.0 or -1.0, found {}", j.sign)));
            }
        }
        if let Some(l) = &c.laser {
            if l.family != LaserFamily::None && !l.address.contains(':') {
                return Err(bad("laser.address", format!("expected host:port, found `{}`", l.address)));
            }
            if !(l.timeout_s.is_finite() && l.timeout_s > 0.0) {
                return Err(bad(
                    "laser.timeout_s",
                    format!("expected a positive number of seconds, found {}", l.timeout_s),
                ));
            }
        }
        if !c.controllers.iter().any(|k| k.name == c.photodiode.controller) {
            return Err(bad(
                "photodiode.controller",
                format!("expected one of the controllers' names, found `{}`", c.photodiode.controller),
            ));
        }
        Ok(c)
    }

    /// This configuration with every controller's address replaced (e.g. by emulators' addresses).
    pub fn with_addresses(mut self, addresses: &[(&str, String)]) -> Self {
        for c in &mut self.controllers {
            if let Some((_, a)) = addresses.iter().find(|(n, _)| *n == c.name) {
                c.address = a.clone();
            }
        }
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::robot::RobotDescription;

    #[test]
    fn the_embedded_configuration_maps_every_joint_of_the_robot() {
        let c = HardwareConfig::femto();
        assert_eq!(c.controllers.len(), 2);
        let robot = RobotDescription::femto_6dof();
        for l in &robot.links {
            let d = l.drive.as_ref().expect("every joint has a drive");
            assert!(c.controllers.iter().any(|k| k.name == d.controller), "{}", l.name);
        }
        assert_eq!(c.photodiode.wavelength_input.as_deref(), Some("6"));
        assert_eq!(c.time_scale, 1.0, "real hardware runs in real time");
    }

    #[test]
    fn the_mcs2_bench_file_names_an_mcs2_where_femto_hardware_has_an_mcs() {
        let text = include_str!("../../../../assets/benches/femto-mcs2-hardware.ron");
        let c = HardwareConfig::from_ron_str(text, Path::new("assets/benches/femto-mcs2-hardware.ron")).unwrap();
        let femto = HardwareConfig::femto();
        assert_eq!(
            (c.controllers[1].kind, femto.controllers[1].kind),
            (ControllerKind::SmarActMcs2, ControllerKind::SmarActMcs)
        );
        assert_eq!(c.controllers[1].address, "127.0.0.1:55551");
        assert_eq!((c.joints.clone(), c.photodiode.clone()), (femto.joints, femto.photodiode), "the same wiring");
    }

    #[test]
    fn the_laser_entry_is_optional_and_checked() {
        let c = HardwareConfig::femto();
        let laser = c.laser.as_ref().expect("the embedded bench names its laser");
        assert_eq!((laser.family, laser.address.as_str()), (LaserFamily::Keysight, "127.0.0.1:5025"));
        let line = "    laser: Some((family: Keysight, address: \"127.0.0.1:5025\", timeout_s: 2.0)),\n";
        assert!(FEMTO_HARDWARE_RON.contains(line));
        let without = HardwareConfig::from_ron_str(&FEMTO_HARDWARE_RON.replace(line, ""), Path::new("hw.ron")).unwrap();
        assert_eq!(without.laser, None, "a file written before the laser entry still loads");
        let bad = FEMTO_HARDWARE_RON.replace("address: \"127.0.0.1:5025\"", "address: \"lab-laser\"");
        let err = HardwareConfig::from_ron_str(&bad, Path::new("hw.ron")).unwrap_err().to_string();
        assert!(err.contains("field `laser.address`: expected host:port, found `lab-laser`"), "{err}");
        let none = FEMTO_HARDWARE_RON.replace(line, "    laser: Some((family: None)),\n");
        assert_eq!(
            HardwareConfig::from_ron_str(&none, Path::new("hw.ron")).unwrap().laser.unwrap().family,
            LaserFamily::None
        );
    }

    #[test]
    fn bad_configurations_name_the_field() {
        let cases = [
            (
                "sign",
                "(joint: \"q1\", zero: 150.0)",
                "(joint: \"q1\", zero: 150.0, sign: 2.0)",
                "field `joints[0].sign`: expected 1.0 or -1.0",
            ),
            (
                "photodiode",
                "controller: \"PI E-712\", input",
                "controller: \"PI E-999\", input",
                "field `photodiode.controller`",
            ),
            ("period", "sample_period_s: 0.0005", "sample_period_s: -1.0", "field `sample_period_s`"),
            ("time scale", "timeout_margin_s: 10.0,", "timeout_margin_s: 10.0, time_scale: 0.0,", "field `time_scale`"),
        ];
        for (what, from, to, want) in cases {
            assert!(FEMTO_HARDWARE_RON.contains(from), "{what}");
            let err = HardwareConfig::from_ron_str(&FEMTO_HARDWARE_RON.replacen(from, to, 1), Path::new("hw.ron"))
                .unwrap_err()
                .to_string();
            assert!(err.contains(want), "{what}: {err}");
        }
    }
}
