//! A [`Bench`] over real stage controllers: q1..q6 mapped to controller axes by the robot description's
//! `drive` fields and a hardware configuration (`assets/benches/*-hardware.ron`), motions started on the
//! controllers, the photodiode (and the laser's wavelength monitor) recorded by the data recorder of the
//! controller that has the analog input, the other controllers' axes polled during the motion.
//!
//! Faults during a segment (disconnect, timeout, error reply, limit) stop every stage (reconnecting
//! once to a controller whose link dropped, to send the stop), keep the samples recorded so far and
//! return [`BenchError::Interrupted`] with a message saying what happened, where and what was done.
//! [`ControllerBench::reconnect`] then [`crate::bench::resume_plan`] run the rest of the plan.

use super::emulator::{EmuClock, EmuLaser};
use super::{HwError, PiGcs, SmarActMcs, StageController};
use crate::bench::{AxisStatus, AxisUnit, Bench, BenchError, RunControl};
use crate::files::{self, FileError};
use crate::model::air::AmbientConditions;
use crate::model::robot::{JointType, RobotDescription};
use crate::plan::{MotionLimits, TimedMotion, TimedSegment};
use crate::trace::{Trace, TraceMeta};
use serde::{Deserialize, Serialize};
use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

/// The hardware configuration of the paper's bench, embedded.
pub const FEMTO_HARDWARE_RON: &str = include_str!("../../../assets/benches/femto-hardware.ron");

/// Which driver speaks to a controller.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum ControllerKind {
    /// PI GCS 2 over TCP (E-712).
    PiGcs,
    /// SmarAct MCS ASCII over TCP.
    SmarActMcs,
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
    /// Travel range per channel (µm or °) for controllers that cannot report it (MCS); default
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
    /// Input channel of the laser's wavelength monitor (nm per unit 1), if wired; otherwise the
    /// trace's wavelength column is the commanded sweep.
    #[serde(default)]
    pub wavelength_input: Option<String>,
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
}

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
        for (i, j) in c.joints.iter().enumerate() {
            if j.sign != 1.0 && j.sign != -1.0 {
                return Err(bad(&format!("joints[{i}].sign"), format!("expected 1.0 or -1.0, found {}", j.sign)));
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

/// A tunable laser.
pub trait Laser: Send {
    /// The wavelength when not sweeping (nm).
    fn nominal_nm(&self) -> f64;
    /// Go to a fixed wavelength (nm).
    fn set_wavelength(&mut self, nm: f64) -> Result<(), HwError>;
    /// Start a linear sweep (returns at once).
    fn start_sweep(&mut self, from_nm: f64, to_nm: f64, rate_nm_per_s: f64) -> Result<(), HwError>;
}

/// The emulated laser ([`EmuLaser`]) as a [`Laser`].
pub struct EmulatedLaser {
    laser: Arc<EmuLaser>,
    nominal_nm: f64,
}

impl EmulatedLaser {
    /// Drive `laser`, whose resting wavelength is `nominal_nm`.
    pub fn new(laser: Arc<EmuLaser>, nominal_nm: f64) -> Self {
        EmulatedLaser { laser, nominal_nm }
    }
}

impl Laser for EmulatedLaser {
    fn nominal_nm(&self) -> f64 {
        self.nominal_nm
    }
    fn set_wavelength(&mut self, nm: f64) -> Result<(), HwError> {
        self.laser.set(nm);
        Ok(())
    }
    fn start_sweep(&mut self, from_nm: f64, to_nm: f64, rate_nm_per_s: f64) -> Result<(), HwError> {
        self.laser.sweep(from_nm, to_nm, rate_nm_per_s);
        Ok(())
    }
}

/// A laser the software cannot drive (no laser driver yet): it stays at its nominal wavelength, and a
/// plan that sweeps is refused with a message saying so.
pub struct FixedLaser {
    nominal_nm: f64,
}

impl FixedLaser {
    /// A laser resting at `nominal_nm`.
    pub fn new(nominal_nm: f64) -> Self {
        FixedLaser { nominal_nm }
    }
}

impl Laser for FixedLaser {
    fn nominal_nm(&self) -> f64 {
        self.nominal_nm
    }
    fn set_wavelength(&mut self, nm: f64) -> Result<(), HwError> {
        if (nm - self.nominal_nm).abs() < 1e-9 {
            Ok(())
        } else {
            Err(self.refuse())
        }
    }
    fn start_sweep(&mut self, _from_nm: f64, _to_nm: f64, _rate_nm_per_s: f64) -> Result<(), HwError> {
        Err(self.refuse())
    }
}

impl FixedLaser {
    fn refuse(&self) -> HwError {
        HwError::Usage {
            controller: "laser".into(),
            problem: format!(
                "no tunable-laser driver on this bench (fixed at {} nm): wavelength sweeps cannot run",
                self.nominal_nm
            ),
        }
    }
}

/// Longest round trip (s, real time) of a position poll kept in a recording.
const MAX_POLL_RTT_S: f64 = 0.002;

/// Where a joint is driven.
#[derive(Debug, Clone, Copy)]
struct JointMap {
    controller: usize,
    axis: usize,
    zero: f64,
    sign: f64,
}

/// A bench over real (or emulated) controllers.
pub struct ControllerBench {
    config: HardwareConfig,
    robot: RobotDescription,
    motion: MotionLimits,
    ambient: AmbientConditions,
    controllers: Vec<Box<dyn StageController>>,
    joints: [JointMap; 6],
    recorder_controller: usize,
    laser: Box<dyn Laser>,
    clock: Arc<EmuClock>,
    q_display: [f64; 6],
    velocities: [f64; 6],
    /// The last error of each controller (a fault during a segment, a failed status query).
    last_errors: Vec<Option<String>>,
}

/// Samples read from the recorder, not yet turned into trace rows.
struct Acquisition {
    t_trigger_s: f64,
    dt_s: f64,
    read: usize,
    /// Recorder joints (joint index, column).
    recorded_joints: Vec<usize>,
    columns: Vec<Vec<f64>>,
    inputs: Vec<Vec<f64>>,
    /// Polls of the other joints: (bench time, display values of every joint).
    polls: Vec<(f64, [f64; 6])>,
    emitted: usize,
    trace: Trace,
}

impl ControllerBench {
    /// Connect to every controller of `config`, map q1..q6 by the robot's `drive` fields, check units
    /// and referencing, set closed-loop speeds from `motion`, and read the joints. `clock` is the bench
    /// clock shared with the laser ([`EmuClock::new`]`(1.0)` for real hardware).
    pub fn connect(
        robot: RobotDescription,
        config: HardwareConfig,
        motion: MotionLimits,
        ambient: AmbientConditions,
        laser: Box<dyn Laser>,
        clock: Arc<EmuClock>,
    ) -> Result<Self, BenchError> {
        if robot.dof() != 6 {
            return Err(BenchError::Config(format!(
                "{}: expected a six-joint robot, found {}",
                config.name,
                robot.dof()
            )));
        }
        let mut controllers: Vec<Box<dyn StageController>> = Vec::new();
        for c in &config.controllers {
            let driver: Box<dyn StageController> = match c.kind {
                ControllerKind::PiGcs => Box::new(PiGcs::connect(&c.name, &c.address, c.timeout_s).map_err(fault)?),
                ControllerKind::SmarActMcs => {
                    Box::new(SmarActMcs::connect(&c.name, &c.address, c.timeout_s, &c.travel).map_err(fault)?)
                }
            };
            controllers.push(driver);
        }
        Self::with_controllers(robot, config, motion, ambient, controllers, laser, clock)
    }

    /// Build over controllers already connected (in the order of `config.controllers`).
    pub fn with_controllers(
        robot: RobotDescription,
        config: HardwareConfig,
        motion: MotionLimits,
        ambient: AmbientConditions,
        mut controllers: Vec<Box<dyn StageController>>,
        laser: Box<dyn Laser>,
        clock: Arc<EmuClock>,
    ) -> Result<Self, BenchError> {
        let cfg_err = |m: String| BenchError::Config(format!("{}: {m}", config.name));
        if controllers.len() != config.controllers.len() {
            return Err(cfg_err(format!(
                "{} controllers configured, {} connected",
                config.controllers.len(),
                controllers.len()
            )));
        }
        let mut joints = Vec::new();
        for link in &robot.links {
            let drive = link.drive.as_ref().ok_or_else(|| {
                cfg_err(format!("joint {} has no `drive` (controller and channel) in the robot description", link.name))
            })?;
            let c = config.controllers.iter().position(|c| c.name == drive.controller).ok_or_else(|| {
                cfg_err(format!(
                    "joint {} is driven by `{}`, which is not among the configured controllers",
                    link.name, drive.controller
                ))
            })?;
            let axes = controllers.get(c).map(|k| k.axes().to_vec()).unwrap_or_default();
            let axis = axes.iter().position(|a| a.id == drive.channel).ok_or_else(|| {
                cfg_err(format!(
                    "joint {}: `{}` has no axis `{}` (it has {})",
                    link.name,
                    drive.controller,
                    drive.channel,
                    axes.iter().map(|a| a.id.as_str()).collect::<Vec<_>>().join(", ")
                ))
            })?;
            let want = match link.joint {
                JointType::Prismatic => AxisUnit::Micrometre,
                JointType::Revolute => AxisUnit::Degree,
            };
            if axes[axis].unit != want {
                return Err(cfg_err(format!(
                    "joint {} is {:?} but `{}` axis `{}` is in {}",
                    link.name,
                    link.joint,
                    drive.controller,
                    drive.channel,
                    axes[axis].unit.symbol()
                )));
            }
            let jc = config.joints.iter().find(|j| j.joint == link.name);
            joints.push(JointMap {
                controller: c,
                axis,
                zero: jc.map_or(0.0, |j| j.zero),
                sign: jc.map_or(1.0, |j| j.sign),
            });
        }
        let joints: [JointMap; 6] = std::array::from_fn(|j| joints[j]);
        let recorder_controller = config
            .controllers
            .iter()
            .position(|c| c.name == config.photodiode.controller)
            .ok_or_else(|| cfg_err("the photodiode's controller is not configured".into()))?;
        if controllers.get_mut(recorder_controller).and_then(|c| c.recorder()).is_none() {
            return Err(cfg_err(format!("`{}` has no data recorder for the photodiode", config.photodiode.controller)));
        }
        for (j, m) in joints.iter().enumerate() {
            if !controllers[m.controller].is_referenced(m.axis).map_err(fault)? {
                return Err(cfg_err(format!(
                    "joint {} (`{}` axis {}) is not referenced: reference it first",
                    robot.links[j].name,
                    config.controllers[m.controller].name,
                    controllers[m.controller].axes()[m.axis].id
                )));
            }
        }
        let n_controllers = controllers.len();
        let mut bench = ControllerBench {
            config,
            robot,
            motion,
            ambient,
            controllers,
            joints,
            recorder_controller,
            laser,
            clock,
            q_display: [0.0; 6],
            velocities: [f64::NAN; 6],
            last_errors: vec![None; n_controllers],
        };
        bench.q_display = bench.read_joints().map_err(fault)?;
        Ok(bench)
    }

    /// The controllers (for diagnostics and tests).
    pub fn controllers_mut(&mut self) -> &mut [Box<dyn StageController>] {
        &mut self.controllers
    }

    /// Reconnect every controller (after a fault), restore the session and read the joints.
    pub fn reconnect(&mut self) -> Result<(), BenchError> {
        for (c, e) in self.controllers.iter_mut().zip(&mut self.last_errors) {
            c.reconnect().map_err(fault)?;
            *e = None;
        }
        self.velocities = [f64::NAN; 6];
        self.q_display = self.read_joints().map_err(fault)?;
        Ok(())
    }

    /// Every joint's axis as its controller reports it now: position, on target, servo, referenced,
    /// and the controller's last error. A failed query leaves its field `None` and becomes the
    /// controller's last error; a link closed by a fault is not reopened here ([`Self::reconnect`]).
    pub fn axis_status(&mut self) -> Vec<AxisStatus> {
        let mut out = Vec::with_capacity(6);
        for (j, m) in self.joints.iter().enumerate() {
            let c = &mut self.controllers[m.controller];
            let mut error: Option<HwError> = None;
            let position = keep(&mut error, c.positions(&[m.axis])).and_then(|p| p.first().copied());
            let on_target = keep(&mut error, c.on_target(&[m.axis])).and_then(|p| p.first().copied());
            let servo_on = keep(&mut error, c.servo_on(&[m.axis])).flatten().and_then(|p| p.first().copied());
            let referenced = keep(&mut error, c.is_referenced(m.axis));
            // A link closed by a fault answers "not connected" from then on: keep the fault that closed it.
            if let Some(e) = error {
                let last = &mut self.last_errors[m.controller];
                if !(matches!(e, HwError::NotConnected { .. }) && last.is_some()) {
                    *last = Some(e.to_string());
                }
            }
            let axis = c.axes()[m.axis].clone();
            out.push(AxisStatus {
                joint: self.robot.links[j].name.clone(),
                controller: self.config.controllers[m.controller].name.clone(),
                axis: axis.id,
                unit: axis.unit,
                position,
                q_display: position.map(|p| (p - m.zero) * m.sign),
                on_target,
                servo_on,
                referenced,
                error: self.last_errors[m.controller].clone(),
            });
        }
        out
    }

    /// Remember a fault as its controller's last error (every controller's when it names none of them).
    fn remember(&mut self, e: &HwError) {
        let named = self.config.controllers.iter().position(|c| c.name == e.controller());
        for (i, last) in self.last_errors.iter_mut().enumerate() {
            if named.is_none_or(|n| n == i) {
                *last = Some(e.to_string());
            }
        }
    }

    /// Read every joint (µm, °).
    pub fn read_joints(&mut self) -> Result<[f64; 6], HwError> {
        let mut q = [0.0; 6];
        for (j, m) in self.joints.iter().enumerate() {
            let p = self.controllers[m.controller].positions(&[m.axis])?;
            q[j] = (p[0] - m.zero) * m.sign;
        }
        Ok(q)
    }

    fn to_controller(&self, j: usize, q: f64) -> f64 {
        self.joints[j].zero + self.joints[j].sign * q
    }

    /// Joints on the recorder's controller (recorded), the others polled.
    fn recorded_joints(&self) -> Vec<usize> {
        (0..6).filter(|&j| self.joints[j].controller == self.recorder_controller).collect()
    }

    fn set_speeds(&mut self, seg: &TimedSegment) -> Result<(), HwError> {
        let d: [f64; 6] = std::array::from_fn(|j| (seg.to_display[j] - seg.from_display[j]).abs());
        let limit = |j: usize| self.motion.for_joint(self.robot.links[j].joint).0;
        // All joints arrive together: the slowest sets the time.
        let time = (0..6).map(|j| d[j] / limit(j)).fold(0.0, f64::max);
        for (j, &dj) in d.iter().enumerate() {
            let v = if dj > 0.0 && time > 0.0 { dj / time } else { limit(j) };
            if (v - self.velocities[j]).abs() > 1e-9 * v || self.velocities[j].is_nan() {
                let m = self.joints[j];
                self.controllers[m.controller].set_velocity(m.axis, v)?;
                self.velocities[j] = v;
            }
        }
        Ok(())
    }

    /// Start the segment's motion: the recorder's controller first (its move command triggers the
    /// recorder, even when it does not move), then the others. Returns the bench time at which the
    /// recorder started: when the move command was sent. The polls of the other axes are stamped
    /// when their request is sent too, so the one-way latency to the controllers cancels; stamping
    /// at the reply would add whatever delay the host takes to read it (measured: under load,
    /// stamps at the middle of the exchange put q4/q5 several nm of dL off).
    fn start_motion(&mut self, seg: &TimedSegment) -> Result<f64, HwError> {
        let n = self.controllers.len();
        let mut t_trigger = self.bench_now();
        let order = std::iter::once(self.recorder_controller).chain((0..n).filter(|&c| c != self.recorder_controller));
        for c in order {
            let targets: Vec<(usize, f64)> = (0..6)
                .filter(|&j| self.joints[j].controller == c)
                .filter(|&j| c == self.recorder_controller || seg.to_display[j] != seg.from_display[j])
                .map(|j| (self.joints[j].axis, self.to_controller(j, seg.to_display[j])))
                .collect();
            if c == self.recorder_controller {
                // Travel limits are cached after the first move: only the move command is timed.
                for &(a, _) in &targets {
                    self.controllers[c].travel_limits(a)?;
                }
                t_trigger = self.bench_now();
                self.controllers[c].move_absolute(&targets)?;
            } else {
                self.controllers[c].move_absolute(&targets)?;
            }
        }
        Ok(t_trigger)
    }

    fn all_on_target(&mut self) -> Result<bool, HwError> {
        for c in 0..self.controllers.len() {
            let axes: Vec<usize> =
                (0..6).filter(|&j| self.joints[j].controller == c).map(|j| self.joints[j].axis).collect();
            if !axes.is_empty() && !self.controllers[c].on_target(&axes)?.iter().all(|&t| t) {
                return Ok(false);
            }
        }
        Ok(true)
    }

    fn poll(&mut self, acq: &mut Acquisition, keep: bool) -> Result<(), HwError> {
        let polled: Vec<usize> = (0..6).filter(|j| !acq.recorded_joints.contains(j)).collect();
        if polled.is_empty() {
            return Ok(());
        }
        let t_before = self.bench_now();
        let mut q = [0.0; 6];
        for &j in &polled {
            let m = self.joints[j];
            let p = self.controllers[m.controller].positions(&[m.axis])?;
            q[j] = (p[0] - m.zero) * m.sign;
        }
        let t_after = self.bench_now();
        // A poll whose exchange took long (the host was busy) may have been read late: drop it,
        // unless it is the first or `keep` (at rest, where the time does not matter).
        let rtt_real_s = (t_after - t_before) / self.clock.scale();
        if keep || rtt_real_s <= MAX_POLL_RTT_S || acq.polls.is_empty() {
            acq.polls.push((t_before, q));
        }
        Ok(())
    }

    fn read_recorder(&mut self, acq: &mut Acquisition, up_to_s: Option<f64>) -> Result<(), HwError> {
        let Some(rec) = self.controllers[self.recorder_controller].recorder() else { return Ok(()) };
        let mut available = rec.recorded_len()?;
        if let Some(end) = up_to_s {
            let last = ((end - acq.t_trigger_s) / acq.dt_s).floor().max(0.0) as usize + 1;
            available = available.min(last);
        }
        while acq.read < available {
            let count = (available - acq.read).min(50_000);
            let block = rec.read(acq.read, count)?;
            for (col, new) in acq.columns.iter_mut().zip(block.axes) {
                col.extend(new);
            }
            for (col, new) in acq.inputs.iter_mut().zip(block.inputs) {
                col.extend(new);
            }
            acq.read += count;
        }
        Ok(())
    }

    /// Turn recorded samples into trace rows, up to the last poll (or all of them with `all`).
    fn emit(&self, acq: &mut Acquisition, seg: &TimedSegment, all: bool) {
        let last_poll = acq.polls.last().map(|p| p.0);
        let wavelength_recorded = self.config.photodiode.wavelength_input.is_some();
        let mw = self.config.photodiode.mw_per_unit;
        while acq.emitted < acq.read {
            let k = acq.emitted;
            let t = acq.t_trigger_s + k as f64 * acq.dt_s;
            if !all && acq.recorded_joints.len() < 6 && last_poll.is_none_or(|lp| t > lp) {
                break;
            }
            let mut q = seg.to_display;
            // Polled joints: linear interpolation between polls (clamped at the ends).
            if acq.recorded_joints.len() < 6 {
                let i = acq.polls.partition_point(|p| p.0 <= t);
                let value = |j: usize| -> f64 {
                    match (i.checked_sub(1).and_then(|a| acq.polls.get(a)), acq.polls.get(i)) {
                        (Some(a), Some(b)) if b.0 > a.0 => a.1[j] + (b.1[j] - a.1[j]) * (t - a.0) / (b.0 - a.0),
                        (Some(a), _) => a.1[j],
                        (None, Some(b)) => b.1[j],
                        (None, None) => seg.from_display[j],
                    }
                };
                for (j, qj) in q.iter_mut().enumerate() {
                    if !acq.recorded_joints.contains(&j) {
                        *qj = value(j);
                    }
                }
            }
            for (c, &j) in acq.recorded_joints.iter().enumerate() {
                let m = self.joints[j];
                q[j] = (acq.columns[c][k] - m.zero) * m.sign;
            }
            let wavelength = if wavelength_recorded {
                acq.inputs[1][k]
            } else {
                seg.wavelength_at(t - acq.t_trigger_s).unwrap_or(self.laser.nominal_nm())
            };
            acq.trace.push_sample(t, q, wavelength, acq.inputs[0][k] * mw);
            acq.emitted += 1;
        }
    }

    fn bench_now(&self) -> f64 {
        self.clock.now_s()
    }

    fn sleep_poll(&self) {
        std::thread::sleep(Duration::from_secs_f64(self.config.poll_period_s));
    }

    /// Run the segment; on a fault return it with what was acquired.
    fn run_inner(
        &mut self,
        seg: &TimedSegment,
        meta: &TraceMeta,
        acq: &mut Option<Acquisition>,
        control: &mut RunControl<'_>,
    ) -> Result<Stop, HwError> {
        self.set_speeds(seg)?;
        if let TimedMotion::Sweep { from_nm, .. } = seg.motion {
            self.laser.set_wavelength(from_nm)?;
        }
        if seg.record {
            let recorded_joints = self.recorded_joints();
            let axes: Vec<usize> = recorded_joints.iter().map(|&j| self.joints[j].axis).collect();
            let mut inputs = vec![self.config.photodiode.input.clone()];
            inputs.extend(self.config.photodiode.wavelength_input.clone());
            let period = self.config.sample_period_s;
            let rec = self.controllers[self.recorder_controller].recorder().ok_or_else(|| HwError::Usage {
                controller: self.config.photodiode.controller.clone(),
                problem: "no data recorder".into(),
            })?;
            let dt_s = rec.arm(&axes, &inputs, period)?;
            *acq = Some(Acquisition {
                t_trigger_s: 0.0,
                dt_s,
                read: 0,
                columns: vec![vec![]; recorded_joints.len()],
                inputs: vec![vec![]; inputs.len()],
                recorded_joints,
                polls: vec![],
                emitted: 0,
                trace: Trace::new(meta.clone()),
            });
            if let Some(a) = acq.as_mut() {
                self.poll(a, true)?;
            }
        }
        let t_start = self.bench_now();
        let t_trigger = self.start_motion(seg)?;
        if let Some(a) = acq.as_mut() {
            a.t_trigger_s = t_trigger;
        }
        if let TimedMotion::Sweep { from_nm, to_nm } = seg.motion {
            let rate = (to_nm - from_nm).abs() / seg.duration_s.max(f64::MIN_POSITIVE);
            self.laser.start_sweep(from_nm, to_nm, rate)?;
        }
        let settle_s = match seg.motion {
            TimedMotion::Move { settle_s, .. } => settle_s,
            _ => 0.0,
        };
        let deadline = t_start + 2.0 * seg.duration_s + self.config.timeout_margin_s;
        let mut done_at: Option<f64> = None;
        let mut reported = 0;
        loop {
            let now = self.bench_now();
            if control.cancelled() {
                return Ok(Stop::Cancelled);
            }
            if let Some(a) = acq.as_mut() {
                self.poll(a, false)?;
                self.read_recorder(a, None)?;
                self.emit(a, seg, false);
                if a.trace.len() > reported {
                    (control.on_samples)(&a.trace, reported);
                    reported = a.trace.len();
                }
            }
            (control.on_progress)(((now - t_start) / seg.duration_s.max(1e-9)).clamp(0.0, 1.0));
            match done_at {
                Some(t) if now >= t => break,
                Some(_) => {}
                None => {
                    let finished = match seg.motion {
                        TimedMotion::Move { .. } => self.all_on_target()?,
                        _ => now >= t_start + seg.duration_s,
                    };
                    if finished {
                        // The stages stand still from here: a poll now is exact whatever its round
                        // trip, and bounds the interpolation at the end of the motion (polls during
                        // the motion may all have been dropped on a busy host).
                        if let Some(a) = acq.as_mut() {
                            self.poll(a, true)?;
                        }
                        done_at = Some(now + settle_s);
                    } else if now > deadline {
                        return Err(HwError::WaitTimeout {
                            controller: self.config.name.clone(),
                            axes: (0..6)
                                .filter(|&j| seg.to_display[j] != seg.from_display[j])
                                .map(|j| self.robot.links[j].name.clone())
                                .collect::<Vec<_>>()
                                .join(","),
                            timeout_s: deadline - t_start,
                        });
                    }
                }
            }
            self.sleep_poll();
        }
        if matches!(seg.motion, TimedMotion::Move { .. }) {
            // A lost command looks like a finished move: check that every joint got there.
            let q = self.read_joints()?;
            for (j, &qj) in q.iter().enumerate() {
                let (tol, unit) = match self.robot.links[j].joint {
                    JointType::Prismatic => (0.01, "µm"),
                    JointType::Revolute => (1e-4, "°"),
                };
                if (qj - seg.to_display[j]).abs() > tol {
                    let m = self.joints[j];
                    return Err(HwError::LimitReached {
                        controller: self.config.controllers[m.controller].name.clone(),
                        axis: format!(
                            "{} (joint {})",
                            self.controllers[m.controller].axes()[m.axis].id,
                            self.robot.links[j].name
                        ),
                        position: qj,
                        target: seg.to_display[j],
                        unit,
                        reason: "the move ended off its target: a lost command, an end stop or a limit".into(),
                    });
                }
            }
        }
        if let Some(a) = acq.as_mut() {
            self.poll(a, true)?;
            let end = done_at.unwrap_or_else(|| self.bench_now());
            // The recorder may lag a poll behind: wait for the last samples.
            let needed = ((end - a.t_trigger_s) / a.dt_s).floor().max(0.0) as usize + 1;
            let wait_until = self.bench_now() + 1.0;
            loop {
                let rec = self.controllers[self.recorder_controller].recorder();
                let have = match rec {
                    Some(r) => r.recorded_len()?,
                    None => needed,
                };
                if have >= needed || self.bench_now() > wait_until {
                    break;
                }
                self.sleep_poll();
            }
            self.read_recorder(a, Some(end))?;
            self.emit(a, seg, true);
        }
        if matches!(seg.motion, TimedMotion::Sweep { .. }) {
            let nominal = self.laser.nominal_nm();
            self.laser.set_wavelength(nominal)?;
        }
        Ok(Stop::Done)
    }

    /// Stop everything after a fault; say what was done.
    fn stop_all(&mut self) -> String {
        let mut said = Vec::new();
        for (c, cfg) in self.controllers.iter_mut().zip(&self.config.controllers) {
            let outcome = match c.stop() {
                Ok(()) => "stopped".to_string(),
                Err(e) if e.needs_reconnect() => match c.reconnect().and_then(|()| c.stop()) {
                    Ok(()) => "reconnected and stopped".to_string(),
                    Err(e2) => format!("NOT stopped ({e2})"),
                },
                Err(e) => format!("NOT stopped ({e})"),
            };
            said.push(format!("{}: {outcome}", cfg.name));
        }
        let nominal = self.laser.nominal_nm();
        if self.laser.set_wavelength(nominal).is_err() {
            said.push("laser: could not return to its nominal wavelength".into());
        }
        said.join(", ")
    }
}

/// The value of `r`, or `None` with its error kept in `error` (the first one wins).
fn keep<T>(error: &mut Option<HwError>, r: Result<T, HwError>) -> Option<T> {
    match r {
        Ok(v) => Some(v),
        Err(e) => {
            error.get_or_insert(e);
            None
        }
    }
}

enum Stop {
    Done,
    Cancelled,
}

fn fault(e: HwError) -> BenchError {
    BenchError::Fault(e.to_string())
}

impl Bench for ControllerBench {
    fn name(&self) -> String {
        let at: Vec<String> = self.config.controllers.iter().map(|c| format!("{} at {}", c.name, c.address)).collect();
        format!("{} ({})", self.config.name, at.join(", "))
    }

    fn robot(&self) -> &RobotDescription {
        &self.robot
    }

    fn motion_limits(&self) -> &MotionLimits {
        &self.motion
    }

    fn position_display(&self) -> [f64; 6] {
        self.q_display
    }

    fn wavelength_nm(&self) -> f64 {
        self.laser.nominal_nm()
    }

    fn ambient(&self) -> AmbientConditions {
        self.ambient
    }

    fn clock_s(&self) -> f64 {
        self.clock.now_s()
    }

    fn hardware_status(&mut self) -> Option<Vec<AxisStatus>> {
        Some(self.axis_status())
    }

    fn reconnect(&mut self) -> Result<(), BenchError> {
        ControllerBench::reconnect(self)
    }

    fn run_segment(
        &mut self,
        segment: &TimedSegment,
        meta: TraceMeta,
        control: &mut RunControl<'_>,
    ) -> Result<Option<Trace>, BenchError> {
        let t0 = self.bench_now();
        let mut acq = None;
        let result = self.run_inner(segment, &meta, &mut acq, control);
        let take_trace = |acq: Option<Acquisition>| acq.map(|a| a.trace);
        match result {
            Ok(Stop::Done) => {
                self.q_display = self.read_joints().unwrap_or(segment.to_display);
                let mut trace = take_trace(acq);
                if let (Some(t), TimedMotion::Sweep { .. }) = (trace.as_mut(), segment.motion) {
                    trim_to_sweep(t);
                }
                Ok(trace)
            }
            Ok(Stop::Cancelled) => {
                self.stop_all();
                if let Some(a) = acq.as_mut() {
                    self.emit(a, segment, true);
                }
                self.q_display = self.read_joints().unwrap_or(self.q_display);
                Err(BenchError::Cancelled { partial: take_trace(acq).map(Box::new) })
            }
            Err(e) => {
                self.remember(&e);
                // Keep whatever the recorder still holds (its link may be the healthy one).
                if let Some(a) = acq.as_mut() {
                    let _ = self.read_recorder(a, None);
                    self.emit(a, segment, true);
                }
                let stops = self.stop_all();
                let elapsed = self.bench_now() - t0;
                let partial = take_trace(acq);
                let kept = match &partial {
                    Some(t) => format!("{} samples recorded before the fault are kept", t.len()),
                    None => "the segment records nothing".into(),
                };
                self.q_display = self.read_joints().unwrap_or(self.q_display);
                Err(BenchError::Interrupted {
                    fault: format!(
                        "segment `{}` interrupted after {elapsed:.3} s of bench time: {e}. Stages: {stops}. {kept}. Reconnect, then resume the plan from this segment.",
                        segment.label
                    ),
                    partial: partial.map(Box::new),
                })
            }
        }
    }
}

/// Keep the samples of a sweep trace from the last one at the start wavelength to the first one at
/// the end wavelength: the laser rests before the sweep starts and after it ends, and sweep analysis
/// needs a strictly monotonic wavelength.
fn trim_to_sweep(t: &mut Trace) {
    let w = &t.wavelength_nm;
    let n = w.len();
    if n < 3 {
        return;
    }
    let first = (0..n - 1).find(|&i| w[i + 1] != w[i]).unwrap_or(0);
    let last = (1..n).rev().find(|&i| w[i] != w[i - 1]).unwrap_or(n - 1);
    if last <= first {
        return;
    }
    let keep = |c: &mut Vec<f64>| {
        c.truncate(last + 1);
        c.drain(..first);
    };
    keep(&mut t.t_s);
    keep(&mut t.q1_um);
    keep(&mut t.q2_um);
    keep(&mut t.q3_um);
    keep(&mut t.q4_deg);
    keep(&mut t.q5_deg);
    keep(&mut t.q6_deg);
    keep(&mut t.wavelength_nm);
    keep(&mut t.irradiance);
    for e in &mut t.extra {
        keep(&mut e.values);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
        ];
        for (what, from, to, want) in cases {
            assert!(FEMTO_HARDWARE_RON.contains(from), "{what}");
            let err = HardwareConfig::from_ron_str(&FEMTO_HARDWARE_RON.replacen(from, to, 1), Path::new("hw.ron"))
                .unwrap_err()
                .to_string();
            assert!(err.contains(want), "{what}: {err}");
        }
    }

    #[test]
    fn sweep_traces_are_trimmed_to_the_sweep() {
        let mut t = Trace::new(TraceMeta::default());
        for (i, w) in [1550.0, 1550.0, 1550.0, 1550.5, 1551.0, 1551.5, 1552.0, 1552.0].iter().enumerate() {
            t.push_sample(i as f64, [0.0; 6], *w, i as f64);
        }
        trim_to_sweep(&mut t);
        assert_eq!(t.wavelength_nm, [1550.0, 1550.5, 1551.0, 1551.5, 1552.0]);
        assert_eq!(t.irradiance, [2.0, 3.0, 4.0, 5.0, 6.0]);
    }
}
