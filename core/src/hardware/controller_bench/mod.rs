//! A [`Bench`] over real stage controllers: q1..q6 mapped to controller axes by the robot description's
//! `drive` fields and a hardware configuration (`assets/benches/*-hardware.ron`), motions started on the
//! controllers, the photodiode (and the laser's wavelength monitor) recorded by the data recorder of the
//! controller that has the analog input, the other controllers' axes polled during the motion.
//!
//! Faults during a segment (disconnect, timeout, error reply, limit) stop every stage (reconnecting
//! once to a controller whose link dropped, to send the stop), keep the samples recorded so far and
//! return [`BenchError::Interrupted`] with a message saying what happened, where and what was done.
//! [`ControllerBench::reconnect`] then [`crate::bench::resume_plan`] run the rest of the plan.

mod acquisition;
mod config;
mod laser;
mod run;
mod sweep;
pub mod sweep_timing;

use super::clock::EmuClock;
use super::{HwError, PiGcs, SmarActMcs, SmarActMcs2, StageController};
use crate::bench::{AxisStatus, AxisUnit, Bench, BenchError, LaserStatus, RunControl, SegmentBreakdown};
use crate::model::air::AmbientConditions;
use crate::model::robot::{JointType, LinkDescription, RobotDescription};
use crate::plan::{MotionLimits, TimedSegment};
use crate::trace::{Trace, TraceMeta};
use acquisition::Acquisition;
use run::{Marks, Stop};
use std::sync::Arc;

pub use config::{ControllerConfig, ControllerKind, HardwareConfig, JointConfig, PhotodiodeConfig, FEMTO_HARDWARE_RON};
pub use config::{LaserConfig, LaserFamily, MAX_TIME_SCALE};
pub use laser::{FixedLaser, LambdaLog, Laser, SweepSetup};

/// What times a laser sweep on the recorder's clock.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SweepTimeBase {
    /// The laser's wavelength monitor, recorded on an analog input.
    Monitor {
        /// The input.
        input: String,
    },
    /// The laser's trigger output, starting the recorder from a digital input.
    Trigger {
        /// The digital input line.
        line: String,
    },
}

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
    /// Where each joint is driven.
    joints: [JointMap; 6],
    /// Index of the controller with the photodiode's input and the data recorder.
    recorder_controller: usize,
    laser: Box<dyn Laser>,
    clock: Arc<EmuClock>,
    /// The joints (µm, °) as last read.
    q_display: [f64; 6],
    /// The speed last set on each joint's axis (µm/s, °/s; NaN: not set since connecting).
    velocities: [f64; 6],
    /// The last error of each controller (a fault during a segment, a failed status query).
    last_errors: Vec<Option<String>>,
    /// Where the segment running (or last run) is, in bench time.
    marks: Marks,
    /// How the last segment spent its bench time.
    breakdown: SegmentBreakdown,
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
                ControllerKind::SmarActMcs2 => {
                    Box::new(SmarActMcs2::connect(&c.name, &c.address, c.timeout_s, &c.travel).map_err(fault)?)
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
        let joints =
            robot.links.iter().map(|link| map_joint(link, &config, &controllers)).collect::<Result<Vec<_>, _>>()?;
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
            marks: Marks::default(),
            breakdown: SegmentBreakdown::default(),
        };
        bench.q_display = bench.read_joints().map_err(fault)?;
        if bench.laser.tunable() && bench.sweep_time_base().is_none() {
            tracing::warn!(
                "{}: the laser's sweeps have no time base (neither `photodiode.wavelength_input` nor \
                 `photodiode.laser_trigger_input` is wired): the plans run without their sweeps",
                bench.config.name
            );
        }
        Ok(bench)
    }

    /// What times the laser's sweeps on the recorder's clock: its wavelength monitor on an input,
    /// or its trigger output starting the recorder; `None` when neither is wired.
    pub fn sweep_time_base(&self) -> Option<SweepTimeBase> {
        let p = &self.config.photodiode;
        match (&p.wavelength_input, &p.laser_trigger_input) {
            (Some(input), _) => Some(SweepTimeBase::Monitor { input: input.clone() }),
            (None, Some(line)) => Some(SweepTimeBase::Trigger { line: line.clone() }),
            (None, None) => None,
        }
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
        self.laser.reconnect().map_err(fault)?;
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
}

/// Where the joint of `link` is driven: its controller and axis by the link's `drive`, checked
/// against the connected controllers' axes and units, and its zero and direction from `config`.
fn map_joint(
    link: &LinkDescription,
    config: &HardwareConfig,
    controllers: &[Box<dyn StageController>],
) -> Result<JointMap, BenchError> {
    let cfg_err = |m: String| BenchError::Config(format!("{}: {m}", config.name));
    let drive = link.drive.as_ref().ok_or_else(|| {
        cfg_err(format!("joint {} has no `drive` (controller and channel) in the robot description", link.name))
    })?;
    let controller = config.controllers.iter().position(|k| k.name == drive.controller).ok_or_else(|| {
        cfg_err(format!(
            "joint {} is driven by `{}`, which is not among the configured controllers",
            link.name, drive.controller
        ))
    })?;
    let axes = controllers.get(controller).map(|k| k.axes().to_vec()).unwrap_or_default();
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
    let joint_config = config.joints.iter().find(|j| j.joint == link.name);
    Ok(JointMap {
        controller,
        axis,
        zero: joint_config.map_or(0.0, |j| j.zero),
        sign: joint_config.map_or(1.0, |j| j.sign),
    })
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

fn fault(e: HwError) -> BenchError {
    BenchError::Fault(e.to_string())
}

impl Bench for ControllerBench {
    fn name(&self) -> String {
        let at: Vec<String> = self.config.controllers.iter().map(|c| format!("{} at {}", c.name, c.address)).collect();
        format!("{} ({})", self.config.name, at.join(", "))
    }

    fn identification(&self) -> Vec<(String, String)> {
        self.config
            .controllers
            .iter()
            .zip(&self.controllers)
            .map(|(c, d)| (c.name.clone(), d.identification()))
            .collect()
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

    /// A driven laser whose sweeps this bench can time.
    fn tunable_laser(&self) -> bool {
        self.laser.tunable() && self.sweep_time_base().is_some()
    }

    fn hardware_status(&mut self) -> Option<Vec<AxisStatus>> {
        Some(self.axis_status())
    }

    fn laser_status(&mut self) -> Option<LaserStatus> {
        if !self.laser.tunable() {
            return None;
        }
        let mut error = None;
        let wavelength_nm = self.laser.wavelength_now_nm().unwrap_or_else(|e| {
            error = Some(e.to_string());
            None
        });
        let sweeping = self.laser.sweep_running().map_err(|e| error = Some(e.to_string())).ok();
        Some(LaserStatus { name: self.laser.name(), wavelength_nm, sweeping, error })
    }

    fn reconnect(&mut self) -> Result<(), BenchError> {
        ControllerBench::reconnect(self)
    }

    fn last_breakdown(&self) -> Option<SegmentBreakdown> {
        Some(self.breakdown)
    }

    fn run_segment(
        &mut self,
        segment: &TimedSegment,
        meta: TraceMeta,
        control: &mut RunControl<'_>,
    ) -> Result<Option<Trace>, BenchError> {
        self.marks = Marks { start_s: self.bench_now(), ..Marks::default() };
        let ramp_s = self.ramp_s(segment);
        let commanded_s = match segment.motion {
            crate::plan::TimedMotion::Move { settle_s, .. } if ramp_s > 0.0 => ramp_s + settle_s,
            _ => segment.duration_s,
        };
        self.breakdown = SegmentBreakdown { commanded_s, ..SegmentBreakdown::default() };
        let out = self.run_segment_kept(segment, meta, control);
        self.close_breakdown();
        out
    }
}

impl ControllerBench {
    /// Run the segment; after a cancel or a fault, stop everything and keep what was recorded.
    fn run_segment_kept(
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
                Ok(take_trace(acq))
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
                    let _ = self.read_recorder(a, None, usize::MAX);
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
