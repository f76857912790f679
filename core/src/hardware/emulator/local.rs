//! A whole emulated bench on loopback: a PI E-712 and a SmarAct MCS emulator on one clock (real time
//! or scaled),
//! an emulated laser, and a photodiode that sees a virtual bench's optics at the emulated axes'
//! positions. What the app's "Start local emulators" serves, so the drivers can be tried without
//! hardware. Owns the emulators for as long as it lives (dropping it closes their ports).

use super::smaract::ChannelKind;
use super::{EmuClock, EmuLaser, EmulatedLaser, PiEmulator, PiEmulatorConfig, SmarActEmulator, SmarActEmulatorConfig};
use crate::bench::{BenchPreset, VirtualBench};
use crate::hardware::controller_bench::{ControllerKind, HardwareConfig, Laser};
use crate::model::robot::RobotDescription;
use rand::{rngs::StdRng, SeedableRng};
use rand_distr::{Distribution, StandardNormal};
use std::io::ErrorKind;
use std::sync::{Arc, Mutex};

/// Where an emulated joint's axis is: on the PI or the MCS emulator, its index there, and the joint's
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

/// The two emulators, the laser and their clock.
pub struct LocalEmulators {
    /// Emulated E-712.
    pub pi: PiEmulator,
    /// Emulated MCS.
    pub mcs: SmarActEmulator,
    laser: Arc<EmuLaser>,
    clock: Arc<EmuClock>,
    nominal_nm: f64,
    pi_name: String,
    mcs_name: String,
}

impl LocalEmulators {
    /// Start both emulators on 127.0.0.1 (at `pi_port` and `mcs_port`, or any free port where that
    /// one is taken, e.g. by `photorobot emulate`), on a clock at `config.time_scale` (1: real time), wired as `robot`'s `drive` fields and
    /// `config`'s joint zeros say, the photodiode (and the wavelength monitor) fed by `preset`'s optics
    /// with its detector noise (`seed`).
    pub fn start(
        preset: &BenchPreset,
        seed: u64,
        robot: &RobotDescription,
        config: &HardwareConfig,
        pi_port: u16,
        mcs_port: u16,
    ) -> Result<Self, String> {
        let named = |kind: ControllerKind| {
            config.controllers.iter().find(|c| c.kind == kind).map(|c| c.name.clone()).ok_or_else(|| {
                format!("{}: the hardware configuration has no {kind:?} controller to emulate", config.name)
            })
        };
        let (pi_name, mcs_name) = (named(ControllerKind::PiGcs)?, named(ControllerKind::SmarActMcs)?);
        let pi_config = PiEmulatorConfig::default();
        let mcs_config = SmarActEmulatorConfig::default();
        let mut wires = Vec::new();
        for link in &robot.links {
            let d = link.drive.as_ref().ok_or_else(|| format!("joint {} has no `drive`", link.name))?;
            let index = if d.controller == pi_name {
                pi_config.axes.iter().position(|a| a.0 == d.channel)
            } else if d.controller == mcs_name {
                d.channel.parse::<usize>().ok().filter(|&c| c < mcs_config.channels.len())
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
        if wires.len() != 6 {
            return Err(format!("expected a six-joint robot, found {}", wires.len()));
        }
        let clock = EmuClock::new(config.time_scale);
        let pi = start_or_any("PI E-712", pi_port, |p| PiEmulator::start_on(p, clock.clone(), pi_config.clone()))?;
        let mcs =
            start_or_any("SmarAct MCS", mcs_port, |p| SmarActEmulator::start_on(p, clock.clone(), mcs_config.clone()))?;
        let nominal_nm = preset.laser.wavelength_nm;
        let laser = EmuLaser::new(clock.clone(), nominal_nm);
        let optics = Arc::new(VirtualBench::new(preset, Some(seed)).map_err(|e| e.to_string())?);
        let sigma = optics.white_noise_sigma_mw();
        let (pi_axes, mcs_axes, l) = (pi.axes(), mcs.axes(), laser.clone());
        let mcs_scale: Vec<f64> = mcs_config
            .channels
            .iter()
            .map(|c| match c.0 {
                ChannelKind::Linear => 1e-3,
                ChannelKind::Rotary => 1e-6,
            })
            .collect();
        let rng = Mutex::new(StdRng::seed_from_u64(seed));
        pi.set_photodiode(Arc::new(move |t| {
            let p: Vec<f64> = pi_axes.lock().map(|a| a.iter().map(|a| a.position_at(t)).collect()).unwrap_or_default();
            let m: Vec<f64> = mcs_axes
                .lock()
                .map(|a| a.iter().zip(&mcs_scale).map(|(a, s)| a.position_at(t) * s).collect())
                .unwrap_or_default();
            let q: [f64; 6] = std::array::from_fn(|j| {
                let w = wires[j];
                let at = if w.on_pi { p.get(w.index) } else { m.get(w.index) };
                at.map_or(f64::NAN, |v| (v - w.zero) * w.sign)
            });
            let noise: f64 = StandardNormal.sample(&mut *rng.lock().unwrap_or_else(|e| e.into_inner()));
            optics.reflected_power_mw(t, &q, l.wavelength_at(t)).unwrap_or(f64::NAN) + sigma * noise
        }));
        if let Some(input) = &config.photodiode.wavelength_input {
            let l = laser.clone();
            pi.set_input(input, Arc::new(move |t| l.wavelength_at(t)));
        }
        Ok(LocalEmulators { pi, mcs, laser, clock, nominal_nm, pi_name, mcs_name })
    }

    /// (controller name, host:port) of both emulators.
    pub fn addresses(&self) -> Vec<(String, String)> {
        vec![(self.pi_name.clone(), self.pi.addr().to_string()), (self.mcs_name.clone(), self.mcs.addr().to_string())]
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bench::AxisUnit;
    use crate::bench::{run_plan, RunControl};
    use crate::hardware::ControllerBench;
    use crate::plan::{JointTarget, Plan, Segment};
    use std::sync::atomic::AtomicBool;

    #[test]
    fn a_bench_on_the_local_emulators_moves_and_reports_every_axis() {
        let preset = BenchPreset::resolve("table2-ideal").unwrap();
        let robot = preset.robot_description().unwrap();
        let config = HardwareConfig::femto();
        let emu = LocalEmulators::start(&preset, 7, &robot, &config, 0, 0).unwrap();
        let addresses = emu.addresses();
        let config = config.with_addresses(&[
            (addresses[0].0.as_str(), addresses[0].1.clone()),
            (addresses[1].0.as_str(), addresses[1].1.clone()),
        ]);
        let mut bench =
            ControllerBench::connect(robot, config, preset.motion, preset.ambient, emu.laser(), emu.clock()).unwrap();
        let status = bench.axis_status();
        let q1 = &status[0];
        assert_eq!((q1.joint.as_str(), q1.controller.as_str(), q1.axis.as_str()), ("q1", "PI E-712", "3"));
        assert_eq!((q1.position, q1.q_display, q1.on_target), (Some(150.0), Some(0.0), Some(true)));
        assert_eq!((q1.servo_on, q1.referenced, q1.error.as_deref()), (Some(true), Some(true), None));
        let q6 = &status[5];
        assert_eq!((q6.controller.as_str(), q6.axis.as_str(), q6.unit), ("SmarAct MCS", "2", AxisUnit::Degree));
        assert_eq!((q6.servo_on, q6.referenced), (None, Some(true)));
        // A short recorded move of q1 (10 µm at 100 µm/s): the photodiode sees fringes.
        let to = [10.0, 0.0, 0.0, 0.0, 0.0, 0.5];
        let plan = Plan {
            name: "jog".into(),
            description: String::new(),
            segments: vec![Segment::Move { to: JointTarget::all(to), record: true, label: "jog".into() }],
        };
        let cancel = AtomicBool::new(false);
        let mut control = RunControl { cancel: &cancel, on_samples: &mut |_, _| {}, on_progress: &mut |_| {} };
        let run = run_plan(&mut bench, &plan, &mut control);
        run.outcome.unwrap();
        let trace = &run.traces[0];
        let (lo, hi) =
            trace.irradiance.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |a, &v| (a.0.min(v), a.1.max(v)));
        assert!(hi - lo > 0.1 * hi, "fringes on the emulated photodiode: {lo}..{hi}");
        let status = bench.axis_status();
        assert!((status[0].position.unwrap() - 160.0).abs() < 1e-6, "{:?}", status[0]);
        assert!((status[5].q_display.unwrap() - 0.5).abs() < 1e-6, "{:?}", status[5]);
        // Stopped emulators close their connections: the link's loss shows as the controller's last error, on its axes only.
        drop(emu);
        let status = bench.axis_status();
        let lost = status[0].error.clone().unwrap();
        assert!(lost.starts_with("PI E-712: connection lost during `POS? 3`"), "{lost}");
        // Later polls find the link closed: the error that closed it stays.
        assert_eq!(bench.axis_status()[1].error.as_deref(), Some(lost.as_str()));
        assert!(status[3].error.as_deref().is_some_and(|e| e.starts_with("SmarAct MCS: ")), "{:?}", status[3]);
    }
}
