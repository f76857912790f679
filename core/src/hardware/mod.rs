//! Real stage controllers and their emulators: the hardware abstraction every stage driver implements
//! (PI E-712 over GCS 2, SmarAct MCS and MCS2 over their ASCII protocols, and the virtual bench through
//! an adapter),
//! the line-based TCP link they share, and the [`ControllerBench`] that runs plans on real controllers.
//!
//! The layer above [`crate::bench`]: the controller bench implements its [`crate::bench::Bench`] trait.
//!
//! Units: every position crossing the [`StageController`] trait is in the axis' display unit,
//! µm for a linear axis and degrees for a rotary one ([`AxisUnit`]); drivers convert to what the
//! controller speaks (µm for the E-712, nm and µ° for the MCS). Times are seconds.
//!
//! Network data is never trusted: every reply is parsed into a typed value or a
//! [`HwError::BadReply`] naming the command, the reply and what was expected.

pub mod clock;
pub mod controller_bench;
pub mod emulator;
pub mod laser;
pub mod link;
pub mod pi_gcs;
pub mod pi_replies;
pub mod probe;
pub mod smaract;
pub mod smaract_mcs2;
pub mod virtual_stages;

use crate::bench::AxisUnit;
use std::time::{Duration, Instant};
use thiserror::Error;

pub use controller_bench::{ControllerBench, HardwareConfig};
pub use link::{LineEnd, Link, Traffic, Transcript};
pub use pi_gcs::{GcsError, PiGcs};
pub use smaract::{McsError, SmarActMcs};
pub use smaract_mcs2::SmarActMcs2;
pub use virtual_stages::VirtualStages;

/// One axis of a controller.
#[derive(Debug, Clone, PartialEq)]
pub struct AxisInfo {
    /// The controller's identifier of the axis or channel ("1", "0").
    pub id: String,
    /// Unit of every position and speed of the axis (µm or °).
    pub unit: AxisUnit,
}

/// Why a controller operation failed. Every message names the controller, the command and what
/// happened.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum HwError {
    /// The TCP connection could not be opened.
    #[error("{controller}: cannot connect to {address}: {reason}")]
    Connect {
        /// Controller name.
        controller: String,
        /// host:port.
        address: String,
        /// The system's reason.
        reason: String,
    },
    /// The connection dropped (closed by the peer or a network error).
    #[error("{controller}: connection lost during `{command}`: {reason}")]
    Disconnected {
        /// Controller name.
        controller: String,
        /// The command in flight.
        command: String,
        /// The system's reason.
        reason: String,
    },
    /// No (complete) reply in time. The link is closed afterwards: a late reply would desynchronise it.
    #[error("{controller}: no reply to `{command}` within {timeout_s:.3} s")]
    Timeout {
        /// Controller name.
        controller: String,
        /// The command.
        command: String,
        /// The timeout (s).
        timeout_s: f64,
    },
    /// The link was closed after an earlier fault; reconnect first.
    #[error("{controller}: not connected (the link was closed after an earlier fault; reconnect first)")]
    NotConnected {
        /// Controller name.
        controller: String,
    },
    /// A PI GCS controller reported an error code.
    #[error("{controller}: `{command}` failed: {error}")]
    Gcs {
        /// Controller name.
        controller: String,
        /// The command that failed.
        command: String,
        /// The GCS error.
        error: GcsError,
    },
    /// A SmarAct MCS controller reported an error code.
    #[error("{controller}: `{command}` failed: {error}")]
    Mcs {
        /// Controller name.
        controller: String,
        /// The command that failed.
        command: String,
        /// The MCS error.
        error: McsError,
    },
    /// A reply that does not follow the protocol.
    #[error("{controller}: bad reply to `{command}`: expected {expected}, found {reply:?}")]
    BadReply {
        /// Controller name.
        controller: String,
        /// The command.
        command: String,
        /// The reply as received.
        reply: String,
        /// What the protocol says.
        expected: String,
    },
    /// A target outside the axis' travel range: refused before anything moved.
    #[error(
        "{controller}: axis {axis}: target {target:.4} {unit} is outside the travel range [{min:.4}, {max:.4}] {unit}"
    )]
    OutOfRange {
        /// Controller name.
        controller: String,
        /// Axis id.
        axis: String,
        /// The target.
        target: f64,
        /// Lower travel limit.
        min: f64,
        /// Upper travel limit.
        max: f64,
        /// Unit symbol.
        unit: &'static str,
    },
    /// An axis stopped before its target (end stop, limit switch, range limit).
    #[error(
        "{controller}: axis {axis} stopped at {position:.4} {unit} before its target {target:.4} {unit} ({reason})"
    )]
    LimitReached {
        /// Controller name.
        controller: String,
        /// Axis id.
        axis: String,
        /// Where it stopped.
        position: f64,
        /// Where it was going.
        target: f64,
        /// Unit symbol.
        unit: &'static str,
        /// What the controller said.
        reason: String,
    },
    /// Axes still moving when the wait ended.
    #[error("{controller}: axes {axes} not on target within {timeout_s:.3} s")]
    WaitTimeout {
        /// Controller name.
        controller: String,
        /// Axis ids, comma-separated.
        axes: String,
        /// How long it waited (s).
        timeout_s: f64,
    },
    /// An index or request the controller does not have.
    #[error("{controller}: {problem}")]
    Usage {
        /// Controller name.
        controller: String,
        /// What is wrong.
        problem: String,
    },
}

impl HwError {
    /// A reply from `controller` to `command` that does not follow the protocol.
    pub fn bad_reply(controller: &str, command: &str, reply: &str, expected: &str) -> Self {
        HwError::BadReply {
            controller: controller.into(),
            command: command.into(),
            reply: reply.into(),
            expected: expected.into(),
        }
    }

    /// The controller the error comes from (as named in messages).
    pub fn controller(&self) -> &str {
        match self {
            HwError::Connect { controller, .. }
            | HwError::Disconnected { controller, .. }
            | HwError::Timeout { controller, .. }
            | HwError::NotConnected { controller }
            | HwError::Gcs { controller, .. }
            | HwError::Mcs { controller, .. }
            | HwError::BadReply { controller, .. }
            | HwError::OutOfRange { controller, .. }
            | HwError::LimitReached { controller, .. }
            | HwError::WaitTimeout { controller, .. }
            | HwError::Usage { controller, .. } => controller,
        }
    }

    /// True when the link is gone (disconnect, timeout, not connected): reconnect before going on.
    pub fn needs_reconnect(&self) -> bool {
        matches!(self, HwError::Disconnected { .. } | HwError::Timeout { .. } | HwError::NotConnected { .. })
    }
}

/// A block of recorded samples: one column per recorded axis (display unit) and per analog input.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RecordedBlock {
    /// Index of the first sample (0-based, since the trigger).
    pub start: usize,
    /// Positions per recorded axis (µm or °), in the order given to [`DataRecorder::arm`].
    pub axes: Vec<Vec<f64>>,
    /// Readings per recorded analog input (photodiode, laser wavelength monitor), in the order given
    /// to [`DataRecorder::arm`], in the controller's input unit.
    pub inputs: Vec<Vec<f64>>,
}

/// What starts a recording.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum RecordTrigger {
    /// The next command of this controller that changes a position (the segment's move).
    NextMove,
    /// An edge on a digital input line of this controller (the laser's trigger output).
    External {
        /// The controller's identifier of the line.
        line: String,
    },
}

/// What a recording needs.
#[derive(Debug, Clone, PartialEq)]
pub struct RecorderRequest {
    /// Recorded axes (indices into [`StageController::axes`]).
    pub axes: Vec<usize>,
    /// Recorded analog inputs (photodiode, then the wavelength monitor if wired).
    pub inputs: Vec<String>,
    /// The sampling period wanted (s); the controller rounds it to its servo cycle and lengthens
    /// it when `duration_s` would not fit its tables at that period.
    pub sample_period_s: f64,
    /// The longest the recording may last (s): the segment with its margins.
    pub duration_s: f64,
    /// What starts it.
    pub trigger: RecordTrigger,
}

/// How the recorder was set up.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RecorderSetup {
    /// The sampling period it runs at (s).
    pub sample_period_s: f64,
    /// Samples each table holds (`None`: no limit the driver knows of).
    pub capacity: Option<usize>,
}

/// A controller's synchronized data recorder: axis positions and analog inputs (the photodiode,
/// the laser's wavelength monitor) sampled on the controller's clock.
pub trait DataRecorder {
    /// Configure the recorder for `request` and arm it: recording starts at its trigger.
    fn arm(&mut self, request: &RecorderRequest) -> Result<RecorderSetup, HwError>;
    /// Number of samples recorded since the trigger.
    fn recorded_len(&mut self) -> Result<usize, HwError>;
    /// Read `count` samples from `start` (0-based).
    fn read(&mut self, start: usize, count: usize) -> Result<RecordedBlock, HwError>;
    /// One reading of an analog input now, the same quantity the recorder records.
    fn read_input(&mut self, input: &str) -> Result<f64, HwError>;
}

/// What every stage controller offers (the real drivers and the virtual bench's adapter alike).
/// Axes are addressed by their index in [`StageController::axes`]; positions are in the axis unit.
pub trait StageController: Send {
    /// A name for messages ("PI E-712 at 10.0.0.2:50000").
    fn name(&self) -> String;
    /// The axes, in controller order.
    fn axes(&self) -> &[AxisInfo];
    /// What the controller answered when asked who it is (`*IDN?`), for the lab record.
    fn identification(&self) -> String {
        self.name()
    }
    /// Start an absolute move of several axes together (returns at once).
    fn move_absolute(&mut self, targets: &[(usize, f64)]) -> Result<(), HwError>;
    /// Start a relative move of several axes together (returns at once).
    fn move_relative(&mut self, steps: &[(usize, f64)]) -> Result<(), HwError>;
    /// Current positions of `axes`.
    fn positions(&mut self, axes: &[usize]) -> Result<Vec<f64>, HwError>;
    /// Whether each of `axes` has reached its target and stands still.
    fn on_target(&mut self, axes: &[usize]) -> Result<Vec<bool>, HwError>;
    /// Stop every axis now.
    fn stop(&mut self) -> Result<(), HwError>;
    /// Set the speed of an axis (µm/s or °/s).
    fn set_velocity(&mut self, axis: usize, per_s: f64) -> Result<(), HwError>;
    /// The travel range of an axis (min, max).
    fn travel_limits(&mut self, axis: usize) -> Result<(f64, f64), HwError>;
    /// Whether the axis knows its absolute position (referenced).
    fn is_referenced(&mut self, axis: usize) -> Result<bool, HwError>;
    /// Start a reference move of the axis (returns at once; wait with [`StageController::wait_on_target`]).
    fn reference(&mut self, axis: usize) -> Result<(), HwError>;
    /// Whether each of `axes` is in closed-loop (servo) mode, where the controller reports it
    /// (`None`: the controller has no such query; the MCS positioners always move closed loop).
    fn servo_on(&mut self, _axes: &[usize]) -> Result<Option<Vec<bool>>, HwError> {
        Ok(None)
    }
    /// Open the link again after a fault (and restore the session settings).
    fn reconnect(&mut self) -> Result<(), HwError>;
    /// The data recorder, if the controller has one.
    fn recorder(&mut self) -> Option<&mut dyn DataRecorder> {
        None
    }
    /// The traffic on the controller's link so far, for the log's summaries (`None`: no link).
    fn traffic(&self) -> Option<Traffic> {
        None
    }
    /// True while any of `axes` moves.
    fn is_moving(&mut self, axes: &[usize]) -> Result<bool, HwError> {
        Ok(self.on_target(axes)?.iter().any(|&t| !t))
    }
    /// Poll until every one of `axes` is on target, at most `timeout_s` (real time).
    fn wait_on_target(&mut self, axes: &[usize], timeout_s: f64) -> Result<(), HwError> {
        let start = Instant::now();
        loop {
            if self.on_target(axes)?.iter().all(|&t| t) {
                return Ok(());
            }
            if start.elapsed().as_secs_f64() > timeout_s {
                let ids: Vec<&str> = axes.iter().filter_map(|&a| self.axes().get(a)).map(|a| a.id.as_str()).collect();
                return Err(HwError::WaitTimeout { controller: self.name(), axes: ids.join(","), timeout_s });
            }
            std::thread::sleep(Duration::from_micros(500));
        }
    }
}

/// Parse a number from the network, or say what was expected.
pub(crate) fn parse_f64(controller: &str, command: &str, reply: &str, field: &str) -> Result<f64, HwError> {
    field.trim().parse::<f64>().ok().filter(|v| v.is_finite()).ok_or_else(|| HwError::BadReply {
        controller: controller.into(),
        command: command.into(),
        reply: reply.into(),
        expected: format!("a finite number, found `{}`", field.trim()),
    })
}

/// Parse an integer from the network, or say what was expected.
pub(crate) fn parse_i64(controller: &str, command: &str, reply: &str, field: &str) -> Result<i64, HwError> {
    field.trim().parse::<i64>().map_err(|_| HwError::BadReply {
        controller: controller.into(),
        command: command.into(),
        reply: reply.into(),
        expected: format!("an integer, found `{}`", field.trim()),
    })
}
