//! Real stage controllers and their emulators: the hardware abstraction every stage driver implements
//! (PI E-712 over GCS 2, SmarAct MCS over its ASCII protocol, and the virtual bench through an adapter),
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
pub mod pi_gcs;
pub mod pi_replies;
pub mod probe;
pub mod smaract;
pub mod virtual_stages;

use crate::bench::AxisUnit;
use std::io::{BufRead, BufReader, ErrorKind, Write};
use std::net::{TcpStream, ToSocketAddrs};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use thiserror::Error;

pub use controller_bench::{ControllerBench, HardwareConfig};
pub use pi_gcs::{GcsError, PiGcs};
pub use smaract::{McsError, SmarActMcs};
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

/// A controller's synchronized data recorder: axis positions and an analog input (the photodiode)
/// sampled on the controller's clock.
pub trait DataRecorder {
    /// Configure the recorder for `axes` (indices into [`StageController::axes`]) and the analog
    /// `inputs`, sampling every `sample_period_s` (rounded to what the controller can do; the actual
    /// period is returned). Recording starts with the next motion command of this controller.
    fn arm(&mut self, axes: &[usize], inputs: &[String], sample_period_s: f64) -> Result<f64, HwError>;
    /// Number of samples recorded since the trigger.
    fn recorded_len(&mut self) -> Result<usize, HwError>;
    /// Read `count` samples from `start` (0-based).
    fn read(&mut self, start: usize, count: usize) -> Result<RecordedBlock, HwError>;
    /// One reading of an analog input, now.
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

/// Every command sent and reply received on a link, for logs and test fixtures: `> command` and
/// `< reply line` entries.
pub type Transcript = Arc<Mutex<Vec<String>>>;

/// A line-oriented TCP link (LF-terminated commands and replies) with a read timeout.
pub struct Link {
    controller: String,
    address: String,
    timeout_s: f64,
    reader: Option<BufReader<TcpStream>>,
    transcript: Option<Transcript>,
}

impl Link {
    /// Connect to `address` (host:port).
    pub fn connect(controller: &str, address: &str, timeout_s: f64) -> Result<Self, HwError> {
        let mut link = Link {
            controller: controller.to_string(),
            address: address.to_string(),
            timeout_s,
            reader: None,
            transcript: None,
        };
        link.reconnect()?;
        Ok(link)
    }

    /// Close and open the connection again.
    pub fn reconnect(&mut self) -> Result<(), HwError> {
        self.reader = None;
        let err = |reason: String| HwError::Connect {
            controller: self.controller.clone(),
            address: self.address.clone(),
            reason,
        };
        let timeout = Duration::from_secs_f64(self.timeout_s.max(1e-3));
        let addr = self
            .address
            .to_socket_addrs()
            .map_err(|e| err(e.to_string()))?
            .next()
            .ok_or_else(|| err("the address resolves to nothing".into()))?;
        let stream = TcpStream::connect_timeout(&addr, timeout).map_err(|e| err(e.to_string()))?;
        tracing::info!(controller = %self.controller, address = %self.address, "connected");
        stream.set_read_timeout(Some(timeout)).map_err(|e| err(e.to_string()))?;
        stream.set_write_timeout(Some(timeout)).map_err(|e| err(e.to_string()))?;
        let _ = stream.set_nodelay(true);
        self.reader = Some(BufReader::new(stream));
        Ok(())
    }

    /// True while the connection is open.
    pub fn is_open(&self) -> bool {
        self.reader.is_some()
    }

    /// Close the connection.
    pub fn close(&mut self) {
        self.reader = None;
    }

    /// Record every command and reply in `transcript`.
    pub fn set_transcript(&mut self, transcript: Option<Transcript>) {
        self.transcript = transcript;
    }

    /// The read timeout (s).
    pub fn timeout_s(&self) -> f64 {
        self.timeout_s
    }

    fn log(&self, entry: String) {
        if let Some(t) = &self.transcript {
            if let Ok(mut t) = t.lock() {
                t.push(entry);
            }
        }
    }

    /// Send one command line (LF appended).
    pub fn send(&mut self, command: &str) -> Result<(), HwError> {
        let controller = self.controller.clone();
        let reader = self.reader.as_mut().ok_or(HwError::NotConnected { controller: controller.clone() })?;
        let mut line = Vec::with_capacity(command.len() + 1);
        line.extend_from_slice(command.as_bytes());
        line.push(b'\n');
        if let Err(e) = reader.get_mut().write_all(&line) {
            self.reader = None;
            tracing::warn!(controller = %controller, command, "send failed: {e}");
            return Err(HwError::Disconnected { controller, command: command.into(), reason: e.to_string() });
        }
        tracing::debug!(controller = %self.controller, "> {command}");
        self.log(format!("> {command}"));
        Ok(())
    }

    /// Read one reply line (without its LF; a trailing space is kept). `command` names the request
    /// in errors.
    pub fn read_line(&mut self, command: &str) -> Result<String, HwError> {
        let reply = self.read_line_inner(command);
        if let Err(e) = &reply {
            tracing::warn!(controller = %self.controller, command, "no reply: {e}");
        }
        reply
    }

    fn read_line_inner(&mut self, command: &str) -> Result<String, HwError> {
        let controller = self.controller.clone();
        let timeout_s = self.timeout_s;
        let reader = self.reader.as_mut().ok_or(HwError::NotConnected { controller: controller.clone() })?;
        let mut buf = Vec::new();
        // A line longer than this is not a reply of these protocols (a DRR? data line is < 200 bytes).
        const MAX_LINE_BYTES: u64 = 1 << 20;
        let result = std::io::Read::take(&mut *reader, MAX_LINE_BYTES).read_until(b'\n', &mut buf);
        if buf.len() as u64 >= MAX_LINE_BYTES && buf.last() != Some(&b'\n') {
            self.reader = None;
            return Err(HwError::BadReply {
                controller,
                command: command.into(),
                reply: String::from_utf8_lossy(&buf[..80]).into_owned() + "…",
                expected: format!("a reply line shorter than {MAX_LINE_BYTES} bytes"),
            });
        }
        match result {
            Ok(0) => {
                self.reader = None;
                Err(HwError::Disconnected { controller, command: command.into(), reason: "closed by the peer".into() })
            }
            Ok(_) if buf.last() != Some(&b'\n') => {
                self.reader = None;
                Err(HwError::Disconnected {
                    controller,
                    command: command.into(),
                    reason: "closed by the peer in the middle of a reply".into(),
                })
            }
            Ok(_) => {
                buf.pop();
                if buf.last() == Some(&b'\r') {
                    buf.pop();
                }
                let line = String::from_utf8_lossy(&buf).into_owned();
                tracing::debug!(controller = %controller, "< {line}");
                self.log(format!("< {line}"));
                Ok(line)
            }
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {
                self.reader = None;
                Err(HwError::Timeout { controller, command: command.into(), timeout_s })
            }
            Err(e) => {
                self.reader = None;
                Err(HwError::Disconnected { controller, command: command.into(), reason: e.to_string() })
            }
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
