//! A whole emulated bench on loopback: a PI E-712 and a SmarAct MCS or MCS2 emulator on one clock
//! (real time or scaled), an emulated laser, and a photodiode that sees a virtual bench's optics at
//! the emulated axes' positions through its amplifier and the E-712's ADC; the laser's wavelength
//! monitor and trigger output wired as the hardware configuration says. What the app's "Start
//! local emulators" serves, so the drivers can be tried without hardware. Owns the emulators for as
//! long as it lives (dropping it closes their ports).

use super::mcs2::{Mcs2Emulator, Mcs2EmulatorConfig};
use super::smaract::ChannelKind;
use super::{
    EmuClock, EmuLaser, EmulatedLaser, Fault, FaultSpec, PiEmulator, PiEmulatorConfig, PiRealism, SharedAxes,
    SmarActEmulator, SmarActEmulatorConfig,
};
use crate::bench::{BenchPreset, VirtualBench};
use crate::hardware::controller_bench::{ControllerKind, HardwareConfig, Laser};
use crate::model::robot::RobotDescription;
use rand::{rngs::StdRng, SeedableRng};
use rand_distr::{Distribution, StandardNormal};
use std::io::ErrorKind;
use std::net::SocketAddr;
use std::sync::{Arc, Mutex};

/// The emulated photodiode's transimpedance gain (V per mW of optical power): the hardware file's
/// `photodiode.mw_per_unit` is its inverse, 0.02.
pub const PHOTODIODE_V_PER_MW: f64 = 50.0;
/// The emulated wavelength monitor's scale (nm per V) and offset (nm at 0 V): 1450-1650 nm on
/// 0-8 V; the hardware file's `wavelength_nm_per_unit` and `wavelength_offset_nm`.
pub const MONITOR_NM_PER_V: f64 = 25.0;
/// See [`MONITOR_NM_PER_V`].
pub const MONITOR_OFFSET_NM: f64 = 1450.0;

/// Where an emulated joint's axis is: on the PI or the wrist emulator, its index there, and the joint's
/// zero and direction (controller position = `zero + sign·q`).
#[derive(Debug, Clone, Copy)]
struct Wire {
    on_pi: bool,
    index: usize,
    zero: f64,
    sign: f64,
}

/// Start on `port`, or on any free port when that one is taken.
fn start_or_any<T>(what: &str, port: u16, start: impl Fn(u16) -> std::io::Result<T>) -> Result<T, String> {
    match start(port) {
        Err(e) if e.kind() == ErrorKind::AddrInUse && port != 0 => start(0),
        other => other,
    }
    .map_err(|e| format!("cannot start the {what} emulator on 127.0.0.1:{port}: {e}"))
}

/// The emulated wrist controller: an MCS or an MCS2.
pub enum WristEmulator {
    /// SmarAct MCS (first generation).
    Mcs(SmarActEmulator),
    /// SmarAct MCS2.
    Mcs2(Mcs2Emulator),
}

impl WristEmulator {
    /// The address it listens on.
    pub fn addr(&self) -> SocketAddr {
        match self {
            WristEmulator::Mcs(e) => e.addr(),
            WristEmulator::Mcs2(e) => e.addr(),
        }
    }

    /// Its channels (nm or µ° on an MCS, pm or n° on an MCS2).
    pub fn axes(&self) -> SharedAxes {
        match self {
            WristEmulator::Mcs(e) => e.axes(),
            WristEmulator::Mcs2(e) => e.axes(),
        }
    }

    /// True while any channel moves.
    pub fn any_moving(&self) -> bool {
        match self {
            WristEmulator::Mcs(e) => e.any_moving(),
            WristEmulator::Mcs2(e) => e.any_moving(),
        }
    }

    /// Arm a fault.
    pub fn inject(&self, fault: FaultSpec) {
        match self {
            WristEmulator::Mcs(e) => e.inject(fault),
            WristEmulator::Mcs2(e) => e.inject(fault),
        }
    }

    /// Faults that fired so far.
    pub fn fired(&self) -> Vec<(String, Fault)> {
        match self {
            WristEmulator::Mcs(e) => e.fired(),
            WristEmulator::Mcs2(e) => e.fired(),
        }
    }
}

/// The two emulators, the laser and their clock.
pub struct LocalEmulators {
    /// Emulated E-712.
    pub pi: PiEmulator,
    /// Emulated MCS or MCS2.
    pub mcs: WristEmulator,
    laser: Arc<EmuLaser>,
    clock: Arc<EmuClock>,
    nominal_nm: f64,
    pi_name: String,
    mcs_name: String,
    tap: JointTap,
}

/// The true joints (display units) the photodiode saw at each emulated time it was sampled, while
/// a test or an example asks for them: the reference a recording's joints are checked against.
pub type JointTap = Arc<Mutex<Option<Vec<(f64, [f64; 6])>>>>;

impl LocalEmulators {
    /// [`LocalEmulators::start_with`], realistic.
    pub fn start(
        preset: &BenchPreset,
        seed: u64,
        robot: &RobotDescription,
        config: &HardwareConfig,
        pi_port: u16,
        mcs_port: u16,
    ) -> Result<Self, String> {
        Self::start_with(preset, seed, robot, config, (pi_port, mcs_port), true)
    }

    /// Start the E-712 emulator and the wrist's (an MCS or an MCS2, as `config` names it) on
    /// 127.0.0.1 (at `ports`, or any free port where one is taken, e.g. by `photorobot emulate`),
    /// on a clock at `config.time_scale` (1: real time), wired as `robot`'s `drive` fields and
    /// `config`'s joint zeros say; the photodiode fed by `preset`'s optics with its detector noise
    /// (`seed`), the laser's monitor and trigger output on the inputs `config` names. `realistic`:
    /// the E-712's ADC and strict behaviour; else ideal.
    pub fn start_with(
        preset: &BenchPreset,
        seed: u64,
        robot: &RobotDescription,
        config: &HardwareConfig,
        (pi_port, mcs_port): (u16, u16),
        realistic: bool,
    ) -> Result<Self, String> {
        let named = |kinds: &[ControllerKind]| {
            config.controllers.iter().find(|c| kinds.contains(&c.kind)).map(|c| (c.name.clone(), c.kind)).ok_or_else(
                || format!("{}: the hardware configuration has no {kinds:?} controller to emulate", config.name),
            )
        };
        let (pi_name, _) = named(&[ControllerKind::PiGcs])?;
        let (mcs_name, wrist_kind) = named(&[ControllerKind::SmarActMcs, ControllerKind::SmarActMcs2])?;
        let pi_config = PiEmulatorConfig {
            realism: if realistic { PiRealism::realistic(seed) } else { PiRealism::ideal() },
            ..PiEmulatorConfig::default()
        };
        let mcs_config = SmarActEmulatorConfig::default();
        let mcs2_config = Mcs2EmulatorConfig::default();
        // Controller units per display unit of each wrist channel.
        let wrist_scale: Vec<f64> = match wrist_kind {
            ControllerKind::SmarActMcs2 => {
                mcs2_config.channels.iter().map(|c| if c.0 == 0 { 1e6 } else { 1e9 }).collect()
            }
            _ => mcs_config.channels.iter().map(|c| if c.0 == ChannelKind::Linear { 1e3 } else { 1e6 }).collect(),
        };
        let wires = wire(robot, config, &pi_config, (&pi_name, &mcs_name), wrist_scale.len())?;
        let clock = EmuClock::new(config.time_scale);
        let pi = start_or_any("PI E-712", pi_port, |p| PiEmulator::start_on(p, clock.clone(), pi_config.clone()))?;
        let mcs = match wrist_kind {
            ControllerKind::SmarActMcs2 => WristEmulator::Mcs2(start_or_any("SmarAct MCS2", mcs_port, |p| {
                Mcs2Emulator::start_on(p, clock.clone(), mcs2_config.clone())
            })?),
            _ => WristEmulator::Mcs(start_or_any("SmarAct MCS", mcs_port, |p| {
                SmarActEmulator::start_on(p, clock.clone(), mcs_config.clone())
            })?),
        };
        let nominal_nm = preset.laser.wavelength_nm;
        let laser = EmuLaser::new(clock.clone(), nominal_nm);
        let optics = Arc::new(VirtualBench::new(preset, Some(seed)).map_err(|e| e.to_string())?);
        let sigma = optics.white_noise_sigma_mw();
        let (pi_axes, mcs_axes, l) = (pi.axes(), mcs.axes(), laser.clone());
        let rng = Mutex::new(StdRng::seed_from_u64(seed));
        let tap: JointTap = Arc::new(Mutex::new(None));
        let seen = tap.clone();
        pi.set_photodiode(Arc::new(move |t| {
            let p: Vec<f64> = pi_axes.lock().map(|a| a.iter().map(|a| a.position_at(t)).collect()).unwrap_or_default();
            let m: Vec<f64> = mcs_axes
                .lock()
                .map(|a| a.iter().zip(&wrist_scale).map(|(a, s)| a.position_at(t) / s).collect())
                .unwrap_or_default();
            let q: [f64; 6] = std::array::from_fn(|j| {
                let w = wires[j];
                let at = if w.on_pi { p.get(w.index) } else { m.get(w.index) };
                at.map_or(f64::NAN, |v| (v - w.zero) * w.sign)
            });
            if let Some(log) = seen.lock().unwrap_or_else(|e| e.into_inner()).as_mut() {
                log.push((t, q));
            }
            let noise: f64 = StandardNormal.sample(&mut *rng.lock().unwrap_or_else(|e| e.into_inner()));
            let mw = optics.reflected_power_mw(t, &q, l.wavelength_at(t)).unwrap_or(f64::NAN) + sigma * noise;
            mw * PHOTODIODE_V_PER_MW
        }));
        if let Some(input) = &config.photodiode.wavelength_input {
            let l = laser.clone();
            pi.set_input(input, Arc::new(move |t| (l.wavelength_at(t) - MONITOR_OFFSET_NM) / MONITOR_NM_PER_V));
        }
        if let Some(line) = &config.photodiode.laser_trigger_input {
            let l = laser.clone();
            pi.set_digital_input(line, Arc::new(move |t| l.trigger_edge_after(t)));
        }
        Ok(LocalEmulators { pi, mcs, laser, clock, nominal_nm, pi_name, mcs_name, tap })
    }

    /// (controller name, host:port) of both emulators.
    pub fn addresses(&self) -> Vec<(String, String)> {
        vec![(self.pi_name.clone(), self.pi.addr().to_string()), (self.mcs_name.clone(), self.mcs.addr().to_string())]
    }

    /// Start keeping the true joints at each photodiode sample ([`JointTap`]), or stop and take
    /// what was kept.
    pub fn tap_joints(&self, on: bool) -> Vec<(f64, [f64; 6])> {
        let mut tap = self.tap.lock().unwrap_or_else(|e| e.into_inner());
        std::mem::replace(&mut *tap, on.then(Vec::new)).unwrap_or_default()
    }

    /// The emulated laser, for a [`crate::hardware::ControllerBench`] on these emulators.
    pub fn laser(&self) -> Box<dyn Laser> {
        Box::new(EmulatedLaser::new(self.laser.clone(), self.nominal_nm))
    }

    /// The emulated laser the photodiode sees, for a [`super::LaserEmulator`] serving it over SCPI.
    pub fn emu_laser(&self) -> Arc<EmuLaser> {
        self.laser.clone()
    }

    /// The clock the emulators run on (the bench clock of a bench on them).
    pub fn clock(&self) -> Arc<EmuClock> {
        self.clock.clone()
    }
}

/// Each joint of `robot` on its emulated axis, by its `drive` and `config`'s zeros and signs.
fn wire(
    robot: &RobotDescription,
    config: &HardwareConfig,
    pi_config: &PiEmulatorConfig,
    (pi_name, mcs_name): (&str, &str),
    wrist_channels: usize,
) -> Result<[Wire; 6], String> {
    let mut wires = Vec::new();
    for link in &robot.links {
        let d = link.drive.as_ref().ok_or_else(|| format!("joint {} has no `drive`", link.name))?;
        let index = if d.controller == pi_name {
            pi_config.axes.iter().position(|a| a.0 == d.channel)
        } else if d.controller == mcs_name {
            d.channel.parse::<usize>().ok().filter(|&c| c < wrist_channels)
        } else {
            None
        }
        .ok_or_else(|| format!("joint {}: no emulated axis `{}` on `{}`", link.name, d.channel, d.controller))?;
        let jc = config.joints.iter().find(|j| j.joint == link.name);
        wires.push(Wire {
            on_pi: d.controller == pi_name,
            index,
            zero: jc.map_or(0.0, |j| j.zero),
            sign: jc.map_or(1.0, |j| j.sign),
        });
    }
    <[Wire; 6]>::try_from(wires).map_err(|w| format!("expected a six-joint robot, found {}", w.len()))
}

/// The stage emulators and a Keysight laser emulator on free loopback ports, and the hardware
/// configuration pointing at them: a bench that tests and examples drive through TCP.
pub struct EmulatedHardware {
    pub stages: LocalEmulators,
    pub laser: super::LaserEmulator,
    /// `config` as given, with the emulators' addresses and the laser.
    pub config: HardwareConfig,
}

impl EmulatedHardware {
    /// Serve `preset`'s optics (detector noise seeded by `seed`) on `config`'s clock.
    pub fn start(preset: &BenchPreset, seed: u64, config: HardwareConfig) -> Result<Self, String> {
        use crate::hardware::controller_bench::{LaserConfig, LaserFamily};
        let robot = preset.robot_description().map_err(|e| e.to_string())?;
        let stages = LocalEmulators::start(preset, seed, &robot, &config, 0, 0)?;
        let laser_config = super::LaserEmulatorConfig::new(LaserFamily::Keysight);
        let laser = super::LaserEmulator::start_on(0, stages.emu_laser(), laser_config)
            .map_err(|e| format!("the laser emulator: {e}"))?;
        let addresses = stages.addresses();
        let named: Vec<(&str, String)> = addresses.iter().map(|(n, a)| (n.as_str(), a.clone())).collect();
        let mut config = config.with_addresses(&named);
        config.laser =
            Some(LaserConfig { family: LaserFamily::Keysight, address: laser.addr().to_string(), timeout_s: 2.0 });
        Ok(Self { stages, laser, config })
    }
}
