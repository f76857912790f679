//! Benches: the interface every bench implements (virtual, real controllers, recorded data), what it
//! reports (errors, the stage controllers' axis status) and, in [`run`], the plan runner.
//! The hardware layer implements these traits; nothing here depends on it.

pub mod preset;
pub mod run;
pub mod timing;
pub mod virtual_bench;

use crate::files::FileError;
use crate::model::air::AmbientConditions;
use crate::model::robot::RobotDescription;
use crate::plan::{MotionLimits, TimedSegment};
use crate::trace::{Trace, TraceMeta};
use serde::{Deserialize, Serialize};
use std::sync::atomic::{AtomicBool, Ordering};
use thiserror::Error;

pub use preset::BenchPreset;
pub use run::{resume_plan, resume_plan_with, run_plan, run_plan_with, OnStep, PlanRun, RunError, StepDone};
pub use timing::{RunTiming, SegmentBreakdown, SegmentTiming, StageTime, TimedBench, TimingTotals};
pub use virtual_bench::VirtualBench;

/// Why a bench operation failed.
#[derive(Debug, Error)]
pub enum BenchError {
    /// The bench is misconfigured (preset, robot, optics).
    #[error("{0}")]
    Config(String),
    /// The user cancelled; the samples recorded so far in this segment are kept.
    #[error("cancelled by the user")]
    Cancelled {
        /// What was recorded of the interrupted segment.
        partial: Option<Box<Trace>>,
    },
    /// The hardware reported a fault.
    #[error("bench fault: {0}")]
    Fault(String),
    /// A hardware fault (disconnect, timeout, error reply, limit) interrupted the segment: the stages
    /// were stopped and the samples recorded so far are kept. Resume with [`resume_plan`] once the
    /// cause is cleared (reconnect).
    #[error("{fault}")]
    Interrupted {
        /// What happened, where, and what was done about it.
        fault: String,
        /// What was recorded of the interrupted segment.
        partial: Option<Box<Trace>>,
    },
}

impl From<FileError> for BenchError {
    fn from(e: FileError) -> Self {
        BenchError::Config(e.to_string())
    }
}

impl BenchError {
    /// The samples recorded before a cancel or a hardware fault, if any.
    pub fn partial(&self) -> Option<&Trace> {
        match self {
            BenchError::Cancelled { partial } | BenchError::Interrupted { partial, .. } => partial.as_deref(),
            _ => None,
        }
    }
}

/// The unit an axis is commanded in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum AxisUnit {
    /// A linear axis, in µm.
    Micrometre,
    /// A rotary axis (goniometer, rotation stage), in degrees.
    Degree,
}

impl AxisUnit {
    /// The unit symbol ("µm", "°").
    pub fn symbol(self) -> &'static str {
        match self {
            AxisUnit::Micrometre => "µm",
            AxisUnit::Degree => "°",
        }
    }
}

/// One joint's axis as its stage controller reports it now (the connection panel's status table).
#[derive(Debug, Clone, PartialEq)]
pub struct AxisStatus {
    /// Joint name ("q1").
    pub joint: String,
    /// Controller name ("PI E-712").
    pub controller: String,
    /// Axis or channel identifier on the controller.
    pub axis: String,
    /// Unit of `position` and `q_display` (µm or °).
    pub unit: AxisUnit,
    /// The controller's position of the axis (µm or °), `None` when the query failed.
    pub position: Option<f64>,
    /// The joint value, `(position - zero)·sign` (µm or °).
    pub q_display: Option<f64>,
    /// On target and standing still (`false`: moving).
    pub on_target: Option<bool>,
    /// Closed loop on (`None`: the controller does not report it, or the query failed).
    pub servo_on: Option<bool>,
    /// Referenced (absolute position known).
    pub referenced: Option<bool>,
    /// The last error of this axis' controller (a failed query now, or the last fault).
    pub error: Option<String>,
}

/// The tunable laser as it reports itself now (the connection panel's status).
#[derive(Debug, Clone, PartialEq)]
pub struct LaserStatus {
    /// The laser ("Keysight laser").
    pub name: String,
    /// Its wavelength (nm), `None` when the query failed.
    pub wavelength_nm: Option<f64>,
    /// A sweep runs, `None` when the query failed.
    pub sweeping: Option<bool>,
    /// The failed query, if one failed.
    pub error: Option<String>,
}

/// Callbacks and the cancel flag for a running segment.
pub struct RunControl<'a> {
    /// Set to request a stop; the bench checks it often (every 50 ms of bench time at most).
    pub cancel: &'a AtomicBool,
    /// Called with the trace so far and the index of the first sample not yet reported.
    pub on_samples: &'a mut dyn FnMut(&Trace, usize),
    /// Called with the fraction of the segment done (0..1).
    pub on_progress: &'a mut dyn FnMut(f64),
}

impl RunControl<'_> {
    /// True once a stop has been requested.
    pub fn cancelled(&self) -> bool {
        self.cancel.load(Ordering::Relaxed)
    }
}

/// Inside `impl Bench for Wrapper { … }` of a bench that wraps another (the field `$inner`) and
/// changes only how segments run: every other method of [`Bench`] forwarded to it, so that no
/// wrapper hides what the bench under it says (its identification, laser, controllers, timing).
#[macro_export]
macro_rules! forward_bench_queries {
    ($inner:ident) => {
        fn name(&self) -> String {
            self.$inner.name()
        }
        fn robot(&self) -> &$crate::model::robot::RobotDescription {
            self.$inner.robot()
        }
        fn motion_limits(&self) -> &$crate::plan::MotionLimits {
            self.$inner.motion_limits()
        }
        fn position_display(&self) -> [f64; 6] {
            self.$inner.position_display()
        }
        fn wavelength_nm(&self) -> f64 {
            self.$inner.wavelength_nm()
        }
        fn ambient(&self) -> $crate::model::air::AmbientConditions {
            self.$inner.ambient()
        }
        fn identification(&self) -> Vec<(String, String)> {
            self.$inner.identification()
        }
        fn clock_s(&self) -> f64 {
            self.$inner.clock_s()
        }
        fn tunable_laser(&self) -> bool {
            self.$inner.tunable_laser()
        }
        fn hardware_status(&mut self) -> Option<Vec<$crate::bench::AxisStatus>> {
            self.$inner.hardware_status()
        }
        fn laser_status(&mut self) -> Option<$crate::bench::LaserStatus> {
            self.$inner.laser_status()
        }
        fn reconnect(&mut self) -> Result<(), $crate::bench::BenchError> {
            self.$inner.reconnect()
        }
        fn last_breakdown(&self) -> Option<$crate::bench::SegmentBreakdown> {
            self.$inner.last_breakdown()
        }
    };
}

/// What every bench offers: the robot it believes it has, its state, and running one timed
/// segment of a plan while recording.
pub trait Bench: Send {
    /// A name for the user ("virtual bench table2-ideal", "PI E-712 at 10.0.0.2").
    fn name(&self) -> String;
    /// The robot description the software uses for this bench (nominal, never the truth).
    fn robot(&self) -> &RobotDescription;
    /// Speeds and accelerations of the stages.
    fn motion_limits(&self) -> &MotionLimits;
    /// Current joint positions (µm, °).
    fn position_display(&self) -> [f64; 6];
    /// Current laser wavelength (nm).
    fn wavelength_nm(&self) -> f64;
    /// Ambient conditions as measured at the bench (they set the air index).
    fn ambient(&self) -> AmbientConditions;
    /// Each controller's name and identification reply (`*IDN?`), for the lab record; a simulated
    /// bench identifies itself.
    fn identification(&self) -> Vec<(String, String)> {
        vec![(self.name(), format!("{} (simulated by photorobot-core {})", self.name(), env!("CARGO_PKG_VERSION")))]
    }
    /// Bench time since the start of the session (s).
    fn clock_s(&self) -> f64;
    /// The bench has a tunable laser the software drives: plans may sweep the wavelength. A
    /// bench without one refuses sweeps, and calibrations skip them
    /// ([`crate::plan::Plan::without_sweeps`]).
    fn tunable_laser(&self) -> bool {
        true
    }
    /// Run one segment; return its trace when the segment records.
    fn run_segment(
        &mut self,
        segment: &TimedSegment,
        meta: TraceMeta,
        control: &mut RunControl<'_>,
    ) -> Result<Option<Trace>, BenchError>;
    /// The stage controllers' view of every joint axis, for a bench on controllers (`None` for a
    /// simulated bench).
    fn hardware_status(&mut self) -> Option<Vec<AxisStatus>> {
        None
    }
    /// The tunable laser of a bench on controllers, read now (`None` for a simulated bench or
    /// one whose laser the software does not drive).
    fn laser_status(&mut self) -> Option<LaserStatus> {
        None
    }
    /// Open the links to the stage controllers again after a fault (nothing to do on a simulated bench).
    fn reconnect(&mut self) -> Result<(), BenchError> {
        Ok(())
    }
    /// How the last segment run spent its bench time, for a bench on controllers (`None` for a
    /// simulated bench, whose clock is the plan's timing model).
    fn last_breakdown(&self) -> Option<SegmentBreakdown> {
        None
    }
}
