//! PI E-712 driver: the GCS 2 ASCII command subset the bench needs, over TCP (port 50000).
//! Owns command formatting, reply parsing (multi-line replies: a line ending in space-LF continues),
//! the `ERR?` check after every command, GCS error codes, closed loop and velocity control at
//! connect; the data recorder is [`recorder`].
//!
//! Sources: PI's GCS 2 command docstrings in PIPython (`pipython/pidevice/common/gcsbasecommands.py`,
//! release 2.13) and PI's EPICS driver (`PIGCSPiezoController.cpp`, motorPIGCS2). Positions are in
//! µm (the E-712's unit for the P-563.3CD axes). Errors keep the controller's number and PI's text
//! for it ([`GcsError`]).

pub mod recorder;

use super::pi_replies as replies;
use super::{parse_f64, AxisInfo, DataRecorder, HwError, Link, StageController, Traffic};
use crate::bench::AxisUnit;
use recorder::RecorderFacts;
use std::fmt;

/// The E-712's default TCP port.
pub const DEFAULT_PORT: u16 = 50000;

/// GCS error numbers and their meaning (PI GCS 2 error codes, as in PI's GCS DLL header): the
/// subset the driver and the emulator use or may meet.
pub const GCS_ERRORS: &[(i32, &str, &str)] = &[
    (0, "PI_CNTR_NO_ERROR", "No error"),
    (1, "PI_CNTR_PARAM_SYNTAX", "Parameter syntax error"),
    (2, "PI_CNTR_UNKNOWN_COMMAND", "Unknown command"),
    (3, "PI_CNTR_COMMAND_TOO_LONG", "Command length out of limits or command buffer overrun"),
    (
        5,
        "PI_CNTR_MOVE_WITHOUT_REF_OR_NO_SERVO",
        "Unallowable move attempted on unreferenced axis, or move attempted with servo off",
    ),
    (7, "PI_CNTR_POS_OUT_OF_LIMITS", "Position out of limits"),
    (8, "PI_CNTR_VEL_OUT_OF_LIMITS", "Velocity out of limits"),
    (10, "PI_CNTR_STOP", "Controller was stopped by command"),
    (14, "PI_CNTR_INVALID_ANALOG_INPUT", "Invalid analog channel"),
    (15, "PI_CNTR_INVALID_AXIS_IDENTIFIER", "Invalid axis identifier"),
    (17, "PI_CNTR_PARAM_OUT_OF_RANGE", "Parameter out of range"),
    (23, "PI_CNTR_ILLEGAL_AXIS", "Illegal axis"),
    (24, "PI_CNTR_PARAM_NR", "Incorrect number of parameters"),
    (25, "PI_CNTR_INVALID_REAL_NR", "Invalid floating point number"),
    (26, "PI_CNTR_MISSING_PARAM", "Parameter missing"),
    (54, "PI_CNTR_UNKNOWN_PARAMETER", "Unknown parameter"),
    (57, "PI_CNTR_INVALID_RECORDER_CHAN", "Data Record Table does not exist"),
    (58, "PI_CNTR_INVALID_RECORDER_SRC_OPT", "Source does not exist; number too low or too high"),
    (77, "PI_CNTR_NOT_ENOUGH_RECORDED_DATA", "Data Record Table does not hold enough recorded data"),
    (
        216,
        "PI_CNTR_ON_LIMIT_SWITCH",
        "The connected stage has driven into a limit switch, some controllers need CLR to resume operation",
    ),
    (308, "PI_CNTR_TIMEOUT", "A lengthy operation has not finished in the expected time"),
    (1024, "PI_CNTR_MOTION_ERROR", "Motion error: position error too large, servo is switched off automatically"),
];

/// A GCS error code with PI's name and text for it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GcsError {
    /// The number `ERR?` returned.
    pub code: i32,
}

impl GcsError {
    /// PI's symbolic name, if the code is in [`GCS_ERRORS`].
    pub fn name(&self) -> Option<&'static str> {
        GCS_ERRORS.iter().find(|e| e.0 == self.code).map(|e| e.1)
    }

    /// PI's text for the code ("Position out of limits"), or "unknown GCS error".
    pub fn meaning(&self) -> &'static str {
        GCS_ERRORS.iter().find(|e| e.0 == self.code).map_or("unknown GCS error (see the controller manual)", |e| e.2)
    }

    /// True for errors that say an axis hit a limit switch.
    pub fn is_limit(&self) -> bool {
        self.code == 216
    }
}

impl fmt::Display for GcsError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.name() {
            Some(n) => write!(f, "GCS error {} ({n}): {}", self.code, self.meaning()),
            None => write!(f, "GCS error {}: {}", self.code, self.meaning()),
        }
    }
}

/// A connected E-712.
pub struct PiGcs {
    pub(super) name: String,
    link: Link,
    axes: Vec<AxisInfo>,
    idn: String,
    /// Data recorder state: recorded axes (indices) and tables.
    pub(super) armed_axes: Vec<usize>,
    pub(super) armed_inputs: usize,
    /// What the recorder is (servo cycle, capacity, options), read at connect.
    pub(super) recorder: RecorderFacts,
    /// Travel ranges read once per connection (`TMN?`, `TMX?`).
    limits: Vec<Option<(f64, f64)>>,
    /// `FRF?` answered (`None`: not asked yet); an E-712 with absolute sensors may not know it.
    frf_known: Option<bool>,
}

impl PiGcs {
    /// A link to `address`, nothing asked yet.
    fn open(name: &str, address: &str, timeout_s: f64) -> Result<Self, HwError> {
        Ok(PiGcs {
            name: name.to_string(),
            link: Link::connect(name, address, timeout_s)?,
            axes: vec![],
            idn: String::new(),
            armed_axes: vec![],
            armed_inputs: 0,
            recorder: RecorderFacts::default(),
            limits: vec![],
            frf_known: None,
        })
    }

    /// Connect, read `*IDN?` and the axes (`SAI?`), switch every axis to closed loop (`SVO`) and
    /// velocity control (`VCO`), read both back, and read what the data recorder is.
    pub fn connect(name: &str, address: &str, timeout_s: f64) -> Result<Self, HwError> {
        let mut pi = Self::open(name, address, timeout_s)?;
        pi.init()?;
        Ok(pi)
    }

    /// Ask a controller at `address` who it is (`*IDN?`) and which axes it has (`SAI?`), changing
    /// nothing (no `SVO`): the connection panel's "Identify". A reply in another protocol (a SmarAct
    /// MCS answers `:E-1,1`) is refused as not a GCS controller.
    pub fn identify(name: &str, address: &str, timeout_s: f64) -> Result<(String, Vec<AxisInfo>), HwError> {
        let mut pi = Self::open(name, address, timeout_s)?;
        pi.read_identity()?;
        Ok((pi.idn, pi.axes))
    }

    fn read_identity(&mut self) -> Result<(), HwError> {
        let lines = self.query("*IDN?")?;
        self.idn = replies::identity(&self.name, &lines)?;
        let lines = self.query("SAI?")?;
        self.axes = replies::axis_ids(&self.name, &lines)?
            .into_iter()
            .map(|id| AxisInfo { id, unit: AxisUnit::Micrometre })
            .collect();
        Ok(())
    }

    fn init(&mut self) -> Result<(), HwError> {
        self.read_identity()?;
        self.limits = vec![None; self.axes.len()];
        self.frf_known = None;
        let all: Vec<usize> = (0..self.axes.len()).collect();
        // GCS 2 `SVO`: closed-loop operation; `VEL` "only takes effect when the given axis is in
        // closed-loop operation" (PIPython `VEL` docstring).
        self.set_flags("SVO", &all)?;
        // GCS 2 `VCO`: "When velocity-control is on, the axes move with the velocity set with VEL"
        // (PIPython `VCO` docstring); without it a MOV is a step the servo follows at once.
        self.set_flags("VCO", &all)?;
        self.recorder = RecorderFacts::read(self)?;
        Ok(())
    }

    /// Switch a per-axis flag on (`SVO`, `VCO`) and read it back (`SVO?`, `VCO?`).
    fn set_flags(&mut self, command: &str, axes: &[usize]) -> Result<(), HwError> {
        let ids = self.axis_list(axes)?;
        let pairs: Vec<String> = ids.iter().map(|id| format!("{id} 1")).collect();
        self.command(&format!("{command} {}", pairs.join(" ")))?;
        let query = format!("{command}?");
        let values = self.query_per_axis(&query, axes)?;
        let set = replies::flags(&self.name, &query, &values)?;
        if let Some(k) = set.iter().position(|&on| !on) {
            return Err(HwError::Usage {
                controller: self.name.clone(),
                problem: format!("axis {} reads back `{query}` = 0 after `{command} {} 1`", ids[k], ids[k]),
            });
        }
        Ok(())
    }

    /// The controller's identification string (`*IDN?`).
    pub fn idn(&self) -> &str {
        &self.idn
    }

    /// Record every command and reply.
    pub fn set_transcript(&mut self, t: Option<super::Transcript>) {
        self.link.set_transcript(t);
    }

    pub(super) fn bad(&self, command: &str, reply: &str, expected: &str) -> HwError {
        HwError::bad_reply(&self.name, command, reply, expected)
    }

    /// Read a reply: lines ending in a space continue, the last line does not.
    fn read_reply(&mut self, command: &str) -> Result<Vec<String>, HwError> {
        let mut lines = Vec::new();
        loop {
            let line = self.link.read_line(command)?;
            let more = line.ends_with(' ');
            lines.push(line.trim_end().to_string());
            if !more {
                return Ok(lines);
            }
            if lines.len() > 10_000_000 {
                return Err(self.bad(command, "", "a reply of at most 10 million lines"));
            }
        }
    }

    /// Send a query and return its reply lines. When the controller stays silent, ask `ERR?`: a
    /// silent query with an error pending is that error, not a timeout.
    pub fn query(&mut self, command: &str) -> Result<Vec<String>, HwError> {
        self.link.send(command)?;
        match self.read_reply(command) {
            Ok(lines) => Ok(lines),
            Err(HwError::Timeout { .. }) => {
                let timeout = HwError::Timeout {
                    controller: self.name.clone(),
                    command: command.into(),
                    timeout_s: self.link.timeout_s(),
                };
                // The link was closed by the timeout; a fresh one tells whether an error is pending.
                if self.link.reconnect().is_ok() {
                    if let Ok(code) = self.error_code() {
                        if code != 0 {
                            return Err(HwError::Gcs {
                                controller: self.name.clone(),
                                command: command.into(),
                                error: GcsError { code },
                            });
                        }
                    }
                }
                self.link.close();
                Err(timeout)
            }
            Err(e) => Err(e),
        }
    }

    /// `ERR?`: the pending error code (0 for none); reading it clears it.
    pub fn error_code(&mut self) -> Result<i32, HwError> {
        let lines = self.query_raw("ERR?")?;
        replies::error_code(&self.name, &lines)
    }

    fn query_raw(&mut self, command: &str) -> Result<Vec<String>, HwError> {
        self.link.send(command)?;
        self.read_reply(command)
    }

    /// Send a command that has no reply, then `ERR?`; a non-zero code is a typed error.
    pub fn command(&mut self, command: &str) -> Result<(), HwError> {
        tracing::debug!(controller = %self.name, "{command}");
        self.link.send(command)?;
        let code = self.error_code()?;
        if code != 0 {
            return Err(HwError::Gcs {
                controller: self.name.clone(),
                command: command.into(),
                error: GcsError { code },
            });
        }
        Ok(())
    }

    pub(super) fn axis_list(&self, axes: &[usize]) -> Result<Vec<String>, HwError> {
        axes.iter()
            .map(|&a| {
                self.axes.get(a).map(|x| x.id.clone()).ok_or_else(|| HwError::Usage {
                    controller: self.name.clone(),
                    problem: format!("no axis with index {a} (the controller has {})", self.axes.len()),
                })
            })
            .collect()
    }

    /// A per-axis query (`POS? 1 2`): `id=value` lines, returned in the order asked.
    pub(super) fn query_per_axis(&mut self, cmd: &str, axes: &[usize]) -> Result<Vec<String>, HwError> {
        let ids = self.axis_list(axes)?;
        let command = format!("{cmd} {}", ids.join(" "));
        let lines = self.query(&command)?;
        replies::per_axis(&self.name, &command, &lines, &ids)
    }

    fn query_f64(&mut self, cmd: &str, axes: &[usize]) -> Result<Vec<f64>, HwError> {
        let values = self.query_per_axis(cmd, axes)?;
        values.iter().map(|v| parse_f64(&self.name, cmd, v, v)).collect()
    }

    /// `HLT`: stop the axes smoothly (error 10 is then pending and cleared here).
    pub fn halt(&mut self) -> Result<(), HwError> {
        self.link.send("HLT")?;
        let code = self.error_code()?;
        if code != 0 && code != 10 {
            return Err(HwError::Gcs {
                controller: self.name.clone(),
                command: "HLT".into(),
                error: GcsError { code },
            });
        }
        Ok(())
    }

    fn check_range(&mut self, targets: &[(usize, f64)]) -> Result<(), HwError> {
        for &(a, t) in targets {
            let (min, max) = self.travel_limits(a)?;
            if !(t.is_finite() && t >= min && t <= max) {
                return Err(HwError::OutOfRange {
                    controller: self.name.clone(),
                    axis: self.axes[a].id.clone(),
                    target: t,
                    min,
                    max,
                    unit: "µm",
                });
            }
        }
        Ok(())
    }

    fn format_pairs(&self, pairs: &[(usize, f64)]) -> Result<String, HwError> {
        let ids = self.axis_list(&pairs.iter().map(|p| p.0).collect::<Vec<_>>())?;
        Ok(ids.iter().zip(pairs).map(|(id, p)| format!("{id} {:.6}", p.1)).collect::<Vec<_>>().join(" "))
    }
}

impl StageController for PiGcs {
    fn name(&self) -> String {
        self.name.clone()
    }

    fn axes(&self) -> &[AxisInfo] {
        &self.axes
    }

    fn identification(&self) -> String {
        self.idn.clone()
    }

    fn move_absolute(&mut self, targets: &[(usize, f64)]) -> Result<(), HwError> {
        if targets.is_empty() {
            return Ok(());
        }
        self.check_range(targets)?;
        let args = self.format_pairs(targets)?;
        self.command(&format!("MOV {args}"))
    }

    fn move_relative(&mut self, steps: &[(usize, f64)]) -> Result<(), HwError> {
        if steps.is_empty() {
            return Ok(());
        }
        let axes: Vec<usize> = steps.iter().map(|s| s.0).collect();
        let now = self.positions(&axes)?;
        let targets: Vec<(usize, f64)> = steps.iter().zip(&now).map(|(s, p)| (s.0, p + s.1)).collect();
        self.check_range(&targets)?;
        let args = self.format_pairs(steps)?;
        self.command(&format!("MVR {args}"))
    }

    fn positions(&mut self, axes: &[usize]) -> Result<Vec<f64>, HwError> {
        self.query_f64("POS?", axes)
    }

    /// `ONT?`, then `ERR?` so that an error raised during the motion (limit switch, motion error)
    /// shows while waiting.
    fn on_target(&mut self, axes: &[usize]) -> Result<Vec<bool>, HwError> {
        let values = self.query_per_axis("ONT?", axes)?;
        let out = replies::flags(&self.name, "ONT?", &values)?;
        let code = self.error_code()?;
        if code != 0 {
            return Err(HwError::Gcs {
                controller: self.name.clone(),
                command: "ONT? (while moving)".into(),
                error: GcsError { code },
            });
        }
        Ok(out)
    }

    fn stop(&mut self) -> Result<(), HwError> {
        self.link.send("STP")?;
        let code = self.error_code()?;
        // STP raises error 10 by design.
        if code != 0 && code != 10 {
            return Err(HwError::Gcs {
                controller: self.name.clone(),
                command: "STP".into(),
                error: GcsError { code },
            });
        }
        Ok(())
    }

    fn set_velocity(&mut self, axis: usize, per_s: f64) -> Result<(), HwError> {
        let args = self.format_pairs(&[(axis, per_s)])?;
        self.command(&format!("VEL {args}"))
    }

    /// `TMN?` and `TMX?`, read once per connection.
    fn travel_limits(&mut self, axis: usize) -> Result<(f64, f64), HwError> {
        if let Some(Some(l)) = self.limits.get(axis) {
            return Ok(*l);
        }
        let min = self.query_f64("TMN?", &[axis])?[0];
        let max = self.query_f64("TMX?", &[axis])?[0];
        self.limits[axis] = Some((min, max));
        Ok((min, max))
    }

    /// `FRF?` where the controller knows it; an E-712 with capacitive sensors measures absolute
    /// positions, and one that answers `FRF?` with GCS error 2 (unknown command) is referenced, as
    /// PI's EPICS driver reads it (`PIGCSPiezoController::getReferencedState`).
    fn is_referenced(&mut self, axis: usize) -> Result<bool, HwError> {
        if self.frf_known == Some(false) {
            self.axis_list(&[axis])?;
            return Ok(true);
        }
        match self.query_per_axis("FRF?", &[axis]) {
            Ok(v) => {
                self.frf_known = Some(true);
                Ok(replies::flags(&self.name, "FRF?", &v)?[0])
            }
            Err(HwError::Gcs { error: GcsError { code: 2 }, .. }) => {
                self.frf_known = Some(false);
                Ok(true)
            }
            Err(e) => Err(e),
        }
    }

    /// `SVO?`.
    fn servo_on(&mut self, axes: &[usize]) -> Result<Option<Vec<bool>>, HwError> {
        let values = self.query_per_axis("SVO?", axes)?;
        replies::flags(&self.name, "SVO?", &values).map(Some)
    }

    fn reference(&mut self, axis: usize) -> Result<(), HwError> {
        let id = self.axis_list(&[axis])?;
        self.command(&format!("FRF {}", id[0]))
    }

    fn reconnect(&mut self) -> Result<(), HwError> {
        self.link.reconnect()?;
        // Clear a pending error left by the fault, then restore closed loop.
        let _ = self.error_code()?;
        self.init()
    }

    fn recorder(&mut self) -> Option<&mut dyn DataRecorder> {
        Some(self)
    }

    fn traffic(&self) -> Option<Traffic> {
        Some(self.link.traffic())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gcs_errors_use_pis_numbers_and_texts() {
        let cases = [
            (1, "GCS error 1 (PI_CNTR_PARAM_SYNTAX): Parameter syntax error"),
            (2, "GCS error 2 (PI_CNTR_UNKNOWN_COMMAND): Unknown command"),
            (
                5,
                "GCS error 5 (PI_CNTR_MOVE_WITHOUT_REF_OR_NO_SERVO): Unallowable move attempted on unreferenced axis, or move attempted with servo off",
            ),
            (7, "GCS error 7 (PI_CNTR_POS_OUT_OF_LIMITS): Position out of limits"),
            (10, "GCS error 10 (PI_CNTR_STOP): Controller was stopped by command"),
            (15, "GCS error 15 (PI_CNTR_INVALID_AXIS_IDENTIFIER): Invalid axis identifier"),
        ];
        for (code, want) in cases {
            assert_eq!(GcsError { code }.to_string(), want);
        }
        assert!(GcsError { code: 216 }.is_limit());
        assert_eq!(
            GcsError { code: 9999 }.to_string(),
            "GCS error 9999: unknown GCS error (see the controller manual)"
        );
        // Every code in the table once.
        for (i, e) in GCS_ERRORS.iter().enumerate() {
            assert!(GCS_ERRORS[..i].iter().all(|o| o.0 != e.0), "code {} twice", e.0);
        }
    }
}
