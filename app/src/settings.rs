//! The settings kept between runs (eframe storage): theme, bench preset and seed, identifier,
//! pacing, live window, recent session folders and the connection panel's controllers and axis
//! mapping. Data is not kept here: sessions are files.

use crate::worker::Pace;
use photorobot_core::hardware::controller_bench::{ControllerKind, HardwareConfig, LaserFamily};
use photorobot_core::model::robot::RobotDescription;
use serde::{Deserialize, Serialize};

/// Settings kept between runs (eframe storage). Data is not kept here: sessions are files.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Settings {
    /// Dark theme (else light).
    pub dark: bool,
    /// Bench preset (embedded name or file).
    pub preset: String,
    /// Random seed of the virtual bench.
    pub seed: u64,
    /// Identify with the joint estimator (else the paper's steps).
    pub joint_mode: bool,
    /// Bench clock speed against the wall clock while running plans; 0 = as fast as possible.
    pub speed: f64,
    /// Width of the scrolling live window (s).
    pub live_window_s: f64,
    /// Recently opened or saved session folders, newest first.
    pub recent: Vec<String>,
    /// The connection panel: controller addresses, ports, axis mapping.
    pub connection: ConnectionSettings,
}

impl Default for Settings {
    fn default() -> Self {
        Self {
            dark: true,
            preset: "table2-ideal".into(),
            seed: 7,
            joint_mode: true,
            speed: 0.0,
            live_window_s: 5.0,
            recent: vec![],
            connection: Default::default(),
        }
    }
}

impl Settings {
    /// The pacing these settings ask for.
    pub fn pace(&self) -> Pace {
        if self.speed > 0.0 {
            Pace::Speed(self.speed)
        } else {
            Pace::Unpaced
        }
    }
}

/// One controller's place on the network.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ControllerAddress {
    /// Name, as in the robot description's `drive.controller` ("PI E-712").
    pub name: String,
    /// Driver.
    pub kind: ControllerKind,
    /// Host name or IP address.
    pub host: String,
    /// TCP port (E-712: 50000, MCS: 5000).
    pub port: u16,
}

impl ControllerAddress {
    /// host:port.
    pub fn address(&self) -> String {
        format!("{}:{}", self.host.trim(), self.port)
    }
}

/// Which controller and channel drives a joint.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct JointDrive {
    /// Joint name ("q1").
    pub joint: String,
    /// Controller name.
    pub controller: String,
    /// Axis (PI) or channel (MCS) identifier.
    pub channel: String,
}

/// The connection settings kept between runs. The app always starts on the virtual bench:
/// hardware is connected by hand.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ConnectionSettings {
    /// The panel shows the hardware bench (else the virtual one).
    pub hardware: bool,
    /// The controllers.
    pub controllers: Vec<ControllerAddress>,
    /// Reply timeout (s, real time).
    pub timeout_s: f64,
    /// q1..q6 to controller and channel.
    pub mapping: Vec<JointDrive>,
    /// The tunable laser.
    pub laser: LaserAddress,
}

/// The tunable laser's command set and place on the network (family `None`: a laser the
/// software does not drive; sweeps are refused).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct LaserAddress {
    /// Command set.
    pub family: LaserFamily,
    /// Host name or IP address.
    pub host: String,
    /// TCP port of the raw SCPI socket (Keysight: 5025, Santec TSL-570: 5000).
    pub port: u16,
}

impl Default for LaserAddress {
    /// The laser of `assets/benches/femto-hardware.ron`, on 127.0.0.1.
    fn default() -> Self {
        let family = HardwareConfig::femto().laser.map_or(LaserFamily::None, |l| l.family);
        LaserAddress { family, host: "127.0.0.1".into(), port: laser_default_port(family) }
    }
}

impl LaserAddress {
    /// host:port.
    pub fn address(&self) -> String {
        format!("{}:{}", self.host.trim(), self.port)
    }
}

/// The laser family's usual raw-socket port.
pub fn laser_default_port(family: LaserFamily) -> u16 {
    photorobot_core::hardware::emulator::laser::default_port(family)
}

impl Default for ConnectionSettings {
    /// The controllers of `assets/benches/femto-hardware.ron` on 127.0.0.1 at their default ports,
    /// the mapping of the femto-6dof robot description.
    fn default() -> Self {
        let config = HardwareConfig::femto();
        let controllers = config
            .controllers
            .iter()
            .map(|c| ControllerAddress {
                name: c.name.clone(),
                kind: c.kind,
                host: "127.0.0.1".into(),
                port: default_port(c.kind),
            })
            .collect();
        Self {
            hardware: false,
            controllers,
            timeout_s: config.controllers.first().map_or(2.0, |c| c.timeout_s),
            mapping: mapping_of(&RobotDescription::femto_6dof()),
            laser: LaserAddress::default(),
        }
    }
}

/// The controller's TCP port when none is set.
pub fn default_port(kind: ControllerKind) -> u16 {
    match kind {
        ControllerKind::PiGcs => photorobot_core::hardware::pi_gcs::DEFAULT_PORT,
        ControllerKind::SmarActMcs => photorobot_core::hardware::smaract::DEFAULT_PORT,
        ControllerKind::SmarActMcs2 => photorobot_core::hardware::smaract_mcs2::DEFAULT_PORT,
    }
}

/// The `drive` fields of a robot description.
pub fn mapping_of(robot: &RobotDescription) -> Vec<JointDrive> {
    robot
        .links
        .iter()
        .map(|l| JointDrive {
            joint: l.name.clone(),
            controller: l.drive.as_ref().map_or(String::new(), |d| d.controller.clone()),
            channel: l.drive.as_ref().map_or(String::new(), |d| d.channel.clone()),
        })
        .collect()
}
