//! SmarAct MCS (first generation) driver: the ASCII protocol over TCP (port 5000), synchronous mode.
//! Owns command formatting (`:SCM0`, `:GST`, `:GP`, `:GA`, `:MPA`, `:MPR`, `:MAA`, `:MAR`, `:GS`,
//! `:S`, `:FRM`, `:SCLS`, `:GPPK`, `:GSI`), reply parsing, MCS error codes, and each channel's kind
//! from its sensor type at connect.
//!
//! Sources: the MCS ASCII programming interface as SmarAct's SDK header states it
//! (`MCSControl.h`: status codes `SA_*_STATUS`, sensor types `SA_*_SENSOR_TYPE`, error codes) and
//! the EPICS driver `smarActMCSMotorDriver.cpp` (motorSmarAct: `:GST`, `:GS`, `:GP`/`:GA`,
//! `:SCLS`, `:GPPK`). The controller speaks nm for linear positioners and µ° plus a revolution
//! count for rotary ones; this driver speaks µm and degrees ([`crate::bench::AxisUnit`]).

use super::{AxisInfo, HwError, Link, StageController};
use crate::bench::AxisUnit;
use std::fmt;

/// The MCS Ethernet interface's default TCP port.
pub const DEFAULT_PORT: u16 = 5000;

/// Hold time sent with closed-loop moves: 60000 ms means "hold the target forever".
pub const HOLD_FOREVER_MS: u32 = 60000;

/// Channel status codes of `:GS` (MCS ASCII).
pub mod status {
    /// Stopped.
    pub const STOPPED: i64 = 0;
    /// Open-loop stepping.
    pub const STEPPING: i64 = 1;
    /// Scanning.
    pub const SCANNING: i64 = 2;
    /// Holding the target (closed loop, target reached).
    pub const HOLDING: i64 = 3;
    /// Moving to a closed-loop target.
    pub const TARGETING: i64 = 4;
    /// Waiting before a move.
    pub const MOVE_DELAY: i64 = 5;
    /// Calibrating.
    pub const CALIBRATING: i64 = 6;
    /// Finding the reference mark.
    pub const FINDING_REFERENCE: i64 = 7;
    /// Opening or closing a gripper end effector (`SA_OPENING_STATUS`).
    pub const OPENING: i64 = 8;
    /// Movement locked (by the hand control module or an emergency stop).
    pub const LOCKED: i64 = 9;
}

/// What a sensor type (`:GST`, `SA_*_SENSOR_TYPE` of `MCSControl.h`) says of the channel's
/// positioner: `Some(true)` rotary (goniometers `G…`, rotary stages `SR…`, `MR`, `RA`, `RB`,
/// `R20ME`), `Some(false)` linear, `None` for a type this table does not know (the channel is
/// then probed with `:GP`/`:GA`). Type 0 is "no sensor".
pub fn sensor_is_rotary(sensor_type: i64) -> Option<bool> {
    const ROTARY: &[i64] = &[
        2, 4, 8, 10, 11, 12, 13, 14, 15, 16, 17, 19, 20, 22, 23, 25, 26, 27, 28, 29, 30, 31, 33, 36, 37, 45, 46, 47,
        48, 49, 50, 51, 52, 53, 54, 55,
    ];
    const LINEAR: &[i64] = &[1, 3, 5, 6, 7, 9, 18, 21, 24, 32, 34, 35, 38, 40, 41, 42, 43, 44];
    if ROTARY.contains(&sensor_type) {
        Some(true)
    } else if LINEAR.contains(&sensor_type) {
        Some(false)
    } else {
        None
    }
}

/// MCS ASCII error codes and their meaning (SmarAct MCS ASCII programming interface).
pub const MCS_ERRORS: &[(u32, &str)] = &[
    (0, "No error"),
    (1, "Syntax error: the command could not be processed due to a syntactical error"),
    (2, "Invalid command: the command is not known to the system"),
    (3, "Overflow: a parameter is too large to be processed"),
    (4, "Parse error: the command could not be parsed"),
    (5, "Too few parameters"),
    (6, "Too many parameters"),
    (7, "Invalid parameter: a parameter is outside its valid range"),
    (8, "Wrong mode: the command is not available in the current communication mode"),
    (129, "No sensor present: the command needs sensor feedback and the positioner has none"),
    (140, "Sensor disabled"),
    (141, "Command overridden (by the hand control module)"),
    (142, "End stop reached: the target could not be reached because of a mechanical end stop"),
    (143, "Wrong sensor type: the command does not match the channel's sensor type (linear vs rotary)"),
    (144, "Could not find reference mark"),
    (145, "Wrong end effector type"),
    (146, "Movement locked"),
    (147, "Range limit reached: the positioner stopped at a defined range limit"),
    (148, "Physical position unknown: the positioner is not referenced"),
    (150, "Command not processable in the channel's current state"),
    (151, "Waiting for trigger"),
    (152, "Command not triggerable"),
    (153, "Command queue full"),
];

/// An MCS error reply `:E<channel>,<code>`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct McsError {
    /// The channel in the reply (-1 for system commands).
    pub channel: i64,
    /// The error code.
    pub code: u32,
}

impl McsError {
    /// SmarAct's text for the code.
    pub fn meaning(&self) -> &'static str {
        MCS_ERRORS.iter().find(|e| e.0 == self.code).map_or("unknown MCS error (see the MCS manual)", |e| e.1)
    }

    /// True for end stop and range limit errors.
    pub fn is_limit(&self) -> bool {
        matches!(self.code, 142 | 147)
    }
}

impl fmt::Display for McsError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "MCS error {} on channel {}: {}", self.code, self.channel, self.meaning())
    }
}

/// One reply of the MCS protocol, parsed.
#[derive(Debug, Clone, PartialEq)]
pub enum McsReply {
    /// `:E<ch>,<code>`: acknowledge (code 0) or error.
    Error(McsError),
    /// `:P<ch>,<nm>`.
    Position { channel: i64, nm: i64 },
    /// `:A<ch>,<µ°>,<revolution>`.
    Angle { channel: i64, micro_deg: i64, revolution: i64 },
    /// `:S<ch>,<status>`.
    Status { channel: i64, code: i64 },
    /// `:PPK<ch>,<0|1>`.
    PhysicalPositionKnown { channel: i64, known: bool },
    /// `:N<count>`.
    Channels(i64),
    /// `:ID<system id>`: the controller's serial system ID (`:GSI`).
    SystemId(u64),
    /// `:ST<ch>,<type>`: the channel's sensor type (`:GST`).
    SensorType { channel: i64, sensor: i64 },
}

/// Parse one reply line; `None` if it is not one of the replies above.
pub fn parse_reply(line: &str) -> Option<McsReply> {
    let body = line.trim().strip_prefix(':')?;
    let nums = |s: &str| -> Option<Vec<i64>> { s.split(',').map(|f| f.trim().parse::<i64>().ok()).collect() };
    // Longest prefixes first.
    if let Some(rest) = body.strip_prefix("ID") {
        return rest.trim().parse::<u64>().ok().map(McsReply::SystemId);
    }
    if let Some(rest) = body.strip_prefix("ST") {
        let v = nums(rest)?;
        return (v.len() == 2 && v[1] >= 0).then(|| McsReply::SensorType { channel: v[0], sensor: v[1] });
    }
    if let Some(rest) = body.strip_prefix("PPK") {
        let v = nums(rest)?;
        return (v.len() == 2 && (v[1] == 0 || v[1] == 1))
            .then(|| McsReply::PhysicalPositionKnown { channel: v[0], known: v[1] == 1 });
    }
    // The tag is one character, which may be any (a multi-byte one is no reply we know).
    let tag_len = body.chars().next().map_or(0, char::len_utf8);
    let (tag, rest) = body.split_at(tag_len);
    let v = nums(rest)?;
    match (tag, v.as_slice()) {
        ("E", [ch, code]) => u32::try_from(*code).ok().map(|code| McsReply::Error(McsError { channel: *ch, code })),
        ("P", [ch, nm]) => Some(McsReply::Position { channel: *ch, nm: *nm }),
        ("A", [ch, a, r]) => Some(McsReply::Angle { channel: *ch, micro_deg: *a, revolution: *r }),
        ("S", [ch, s]) => Some(McsReply::Status { channel: *ch, code: *s }),
        ("N", [n]) => Some(McsReply::Channels(*n)),
        _ => None,
    }
}

/// µ° in one revolution.
const MICRO_DEG_PER_REV: i64 = 360_000_000;

/// Split an angle (°) into the MCS's µ° in [0, 360e6) and a revolution count.
pub fn angle_to_mcs(deg: f64) -> (i64, i64) {
    let total = (deg * 1e6).round() as i64;
    (total.rem_euclid(MICRO_DEG_PER_REV), total.div_euclid(MICRO_DEG_PER_REV))
}

/// The angle (°) of an MCS angle and revolution count.
pub fn angle_from_mcs(micro_deg: i64, revolution: i64) -> f64 {
    (micro_deg as f64 + revolution as f64 * MICRO_DEG_PER_REV as f64) / 1e6
}

/// A connected MCS controller.
pub struct SmarActMcs {
    name: String,
    link: Link,
    axes: Vec<AxisInfo>,
    /// Travel range per channel (display unit): the MCS has no query for it; set by configuration.
    limits: Vec<(f64, f64)>,
    /// Last commanded target per channel, to tell "stopped at the target" from "stopped short".
    targets: Vec<Option<f64>>,
    /// The system ID `:GSI` answered; `None` where the firmware refuses the query.
    system_id: Option<u64>,
    /// Each channel's sensor type (`:GST`).
    sensors: Vec<i64>,
}

impl SmarActMcs {
    /// Connect, switch to synchronous mode (`:SCM0`), read the channel count (`:GNC`) and probe each
    /// channel: `:GP` answers on a linear positioner, `:GA` on a goniometer or rotary stage.
    /// `limits` gives each channel's travel range in its unit (µm or °); channels beyond it get ±∞.
    pub fn connect(name: &str, address: &str, timeout_s: f64, limits: &[(f64, f64)]) -> Result<Self, HwError> {
        let link = Link::connect(name, address, timeout_s)?;
        let mut m = SmarActMcs {
            name: name.to_string(),
            link,
            axes: vec![],
            limits: limits.to_vec(),
            targets: vec![],
            system_id: None,
            sensors: vec![],
        };
        m.init()?;
        Ok(m)
    }

    fn init(&mut self) -> Result<(), HwError> {
        self.ack(":SCM0", -1)?;
        let n = match self.request(":GNC")? {
            McsReply::Channels(n) if (1..=64).contains(&n) => n,
            other => return Err(self.bad(":GNC", &format!("{other:?}"), "`:N<count>` with 1 to 64 channels")),
        };
        let mut axes = Vec::new();
        let mut sensors = Vec::new();
        for ch in 0..n {
            let sensor = self.sensor_type(ch)?;
            let unit = match sensor_is_rotary(sensor) {
                Some(true) => AxisUnit::Degree,
                Some(false) => AxisUnit::Micrometre,
                None if sensor == 0 => {
                    return Err(HwError::Usage {
                        controller: self.name.clone(),
                        problem: format!("channel {ch} has no sensor (`:GST{ch}` = 0): closed-loop moves need one"),
                    })
                }
                None => self.probe_unit(ch)?,
            };
            axes.push(AxisInfo { id: ch.to_string(), unit });
            sensors.push(sensor);
        }
        self.sensors = sensors;
        self.targets = vec![None; axes.len()];
        self.limits.resize(axes.len(), (f64::NEG_INFINITY, f64::INFINITY));
        self.axes = axes;
        self.system_id = self.read_system_id()?;
        Ok(())
    }

    /// `:GST<ch>`: the channel's sensor type (MCS ASCII; EPICS `getVal("GST")`).
    fn sensor_type(&mut self, ch: i64) -> Result<i64, HwError> {
        let command = format!(":GST{ch}");
        match self.request(&command)? {
            McsReply::SensorType { channel, sensor } if channel == ch => Ok(sensor),
            McsReply::Error(e) => Err(self.mcs(&command, e)),
            other => Err(self.bad(&command, &format!("{other:?}"), &format!("`:ST{ch},<type>`"))),
        }
    }

    /// A sensor type this driver does not know: `:GP` answers on a linear positioner, `:GA` (after
    /// error 143, wrong sensor type) on a rotary one.
    fn probe_unit(&mut self, ch: i64) -> Result<AxisUnit, HwError> {
        match self.request(&format!(":GP{ch}"))? {
            McsReply::Position { channel, .. } if channel == ch => Ok(AxisUnit::Micrometre),
            McsReply::Error(e) if e.code == 143 => match self.request(&format!(":GA{ch}"))? {
                McsReply::Angle { channel, .. } if channel == ch => Ok(AxisUnit::Degree),
                McsReply::Error(e) => Err(self.mcs(&format!(":GA{ch}"), e)),
                other => Err(self.bad(&format!(":GA{ch}"), &format!("{other:?}"), "`:A<ch>,<µ°>,<rev>`")),
            },
            McsReply::Error(e) => Err(self.mcs(&format!(":GP{ch}"), e)),
            other => Err(self.bad(&format!(":GP{ch}"), &format!("{other:?}"), "`:P<ch>,<nm>`")),
        }
    }

    /// Each channel's sensor type read at connect (`:GST`; 0 for none).
    pub fn sensor_types(&self) -> &[i64] {
        &self.sensors
    }

    /// `:GSI`: the system ID, or `None` from a controller that answers it with an error (an
    /// older firmware); any other reply is a protocol error.
    fn read_system_id(&mut self) -> Result<Option<u64>, HwError> {
        match self.request(":GSI")? {
            McsReply::SystemId(id) => Ok(Some(id)),
            McsReply::Error(_) => Ok(None),
            other => Err(self.bad(":GSI", &format!("{other:?}"), "`:ID<system id>`")),
        }
    }

    /// The system ID read at connect, if the controller gave one.
    pub fn system_id(&self) -> Option<u64> {
        self.system_id
    }

    /// Record every command and reply.
    pub fn set_transcript(&mut self, t: Option<super::Transcript>) {
        self.link.set_transcript(t);
    }

    fn bad(&self, command: &str, reply: &str, expected: &str) -> HwError {
        HwError::bad_reply(&self.name, command, reply, expected)
    }

    fn mcs(&self, command: &str, error: McsError) -> HwError {
        HwError::Mcs { controller: self.name.clone(), command: command.into(), error }
    }

    /// Send a command and parse its one-line reply.
    fn request(&mut self, command: &str) -> Result<McsReply, HwError> {
        self.link.send(command)?;
        let line = self.link.read_line(command)?;
        parse_reply(&line).ok_or_else(|| {
            self.bad(command, &line, "an MCS reply `:E`, `:P`, `:A`, `:S`, `:ST`, `:PPK`, `:N` or `:ID`")
        })
    }

    /// Send a command whose only reply is the acknowledgement `:E<ch>,0`.
    fn ack(&mut self, command: &str, channel: i64) -> Result<(), HwError> {
        tracing::debug!(controller = %self.name, "{command}");
        match self.request(command)? {
            McsReply::Error(e) if e.code == 0 && (e.channel == channel || e.channel == -1) => Ok(()),
            McsReply::Error(e) => Err(self.mcs(command, e)),
            other => Err(self.bad(command, &format!("{other:?}"), &format!("`:E{channel},0`"))),
        }
    }

    fn channel(&self, axis: usize) -> Result<(i64, AxisUnit), HwError> {
        self.axes.get(axis).map(|a| (axis as i64, a.unit)).ok_or_else(|| HwError::Usage {
            controller: self.name.clone(),
            problem: format!("no channel with index {axis} (the controller has {})", self.axes.len()),
        })
    }

    fn position(&mut self, axis: usize) -> Result<f64, HwError> {
        let (ch, unit) = self.channel(axis)?;
        let command = match unit {
            AxisUnit::Micrometre => format!(":GP{ch}"),
            AxisUnit::Degree => format!(":GA{ch}"),
        };
        match (unit, self.request(&command)?) {
            (AxisUnit::Micrometre, McsReply::Position { channel, nm }) if channel == ch => Ok(nm as f64 / 1e3),
            (AxisUnit::Degree, McsReply::Angle { channel, micro_deg, revolution }) if channel == ch => {
                if !(0..MICRO_DEG_PER_REV).contains(&micro_deg) {
                    return Err(self.bad(&command, &micro_deg.to_string(), "an angle in [0, 360000000) µ°"));
                }
                Ok(angle_from_mcs(micro_deg, revolution))
            }
            (_, McsReply::Error(e)) => Err(self.mcs(&command, e)),
            (_, other) => Err(self.bad(&command, &format!("{other:?}"), "the position of the channel asked")),
        }
    }

    fn status(&mut self, axis: usize) -> Result<i64, HwError> {
        let (ch, _) = self.channel(axis)?;
        let command = format!(":GS{ch}");
        match self.request(&command)? {
            McsReply::Status { channel, code } if channel == ch => Ok(code),
            McsReply::Error(e) => Err(self.mcs(&command, e)),
            other => Err(self.bad(&command, &format!("{other:?}"), &format!("`:S{ch},<status>`"))),
        }
    }

    fn move_to(&mut self, axis: usize, target: f64, relative_from: Option<f64>) -> Result<(), HwError> {
        let (ch, unit) = self.channel(axis)?;
        let absolute = relative_from.map_or(target, |p| p + target);
        let (min, max) = self.limits[axis];
        if !(absolute.is_finite() && absolute >= min && absolute <= max) {
            return Err(HwError::OutOfRange {
                controller: self.name.clone(),
                axis: ch.to_string(),
                target: absolute,
                min,
                max,
                unit: unit.symbol(),
            });
        }
        let command = match (unit, relative_from.is_some()) {
            (AxisUnit::Micrometre, false) => format!(":MPA{ch},{},{HOLD_FOREVER_MS}", (target * 1e3).round() as i64),
            (AxisUnit::Micrometre, true) => format!(":MPR{ch},{},{HOLD_FOREVER_MS}", (target * 1e3).round() as i64),
            (AxisUnit::Degree, false) => {
                let (a, r) = angle_to_mcs(target);
                format!(":MAA{ch},{a},{r},{HOLD_FOREVER_MS}")
            }
            (AxisUnit::Degree, true) => {
                let (a, r) = angle_to_mcs(target);
                format!(":MAR{ch},{a},{r},{HOLD_FOREVER_MS}")
            }
        };
        self.ack(&command, ch)?;
        self.targets[axis] = Some(absolute);
        Ok(())
    }
}

impl StageController for SmarActMcs {
    fn name(&self) -> String {
        self.name.clone()
    }

    fn axes(&self) -> &[AxisInfo] {
        &self.axes
    }

    /// The system ID (`:GSI`) where the controller gives one, and the channels it found (`:GNC`,
    /// `:GP`/`:GA`).
    fn identification(&self) -> String {
        let kinds: Vec<String> = self
            .axes
            .iter()
            .zip(&self.sensors)
            .map(|(a, s)| format!("{} sensor {s}", if a.unit == AxisUnit::Degree { "rotary" } else { "linear" }))
            .collect();
        let id = self.system_id.map_or(String::new(), |id| format!(" system ID {id},"));
        format!("SmarAct MCS,{id} {} channels ({})", kinds.len(), kinds.join(", "))
    }

    fn move_absolute(&mut self, targets: &[(usize, f64)]) -> Result<(), HwError> {
        for &(a, t) in targets {
            self.move_to(a, t, None)?;
        }
        Ok(())
    }

    fn move_relative(&mut self, steps: &[(usize, f64)]) -> Result<(), HwError> {
        for &(a, d) in steps {
            let p = self.position(a)?;
            self.move_to(a, d, Some(p))?;
        }
        Ok(())
    }

    fn positions(&mut self, axes: &[usize]) -> Result<Vec<f64>, HwError> {
        axes.iter().map(|&a| self.position(a)).collect()
    }

    /// On target: holding (or stopped) at the last target. Stopped short of it is an end stop or a
    /// range limit, reported as [`HwError::LimitReached`].
    fn on_target(&mut self, axes: &[usize]) -> Result<Vec<bool>, HwError> {
        let mut out = Vec::with_capacity(axes.len());
        for &a in axes {
            let s = self.status(a)?;
            let done = match s {
                status::HOLDING => true,
                status::STOPPED => {
                    if let Some(target) = self.targets[a] {
                        let p = self.position(a)?;
                        let unit = self.axes[a].unit;
                        let tol = match unit {
                            AxisUnit::Micrometre => 0.01,
                            AxisUnit::Degree => 1e-4,
                        };
                        if (p - target).abs() > tol {
                            return Err(HwError::LimitReached {
                                controller: self.name.clone(),
                                axis: self.axes[a].id.clone(),
                                position: p,
                                target,
                                unit: unit.symbol(),
                                reason: "the channel stopped short of its target: end stop or range limit".into(),
                            });
                        }
                    }
                    true
                }
                status::TARGETING | status::MOVE_DELAY | status::FINDING_REFERENCE | status::CALIBRATING => false,
                status::STEPPING | status::SCANNING | status::OPENING => false,
                status::LOCKED => {
                    return Err(self.mcs(&format!(":GS{a}"), McsError { channel: a as i64, code: 146 }));
                }
                other => return Err(self.bad(&format!(":GS{a}"), &other.to_string(), "a status code 0 to 9")),
            };
            out.push(done);
        }
        Ok(out)
    }

    fn stop(&mut self) -> Result<(), HwError> {
        let mut first = None;
        for a in 0..self.axes.len() {
            let ch = a as i64;
            if let Err(e) = self.ack(&format!(":S{ch}"), ch) {
                first.get_or_insert(e);
                if !self.link.is_open() {
                    break;
                }
            }
            self.targets[a] = None;
        }
        first.map_or(Ok(()), Err)
    }

    /// `:SCLS`: closed-loop speed in nm/s (linear) or µ°/s (rotary).
    fn set_velocity(&mut self, axis: usize, per_s: f64) -> Result<(), HwError> {
        let (ch, unit) = self.channel(axis)?;
        let per_unit = match unit {
            AxisUnit::Micrometre => 1e3,
            AxisUnit::Degree => 1e6,
        };
        let v = (per_s.abs() * per_unit).round().max(1.0) as i64;
        self.ack(&format!(":SCLS{ch},{v}"), ch)
    }

    fn travel_limits(&mut self, axis: usize) -> Result<(f64, f64), HwError> {
        self.channel(axis)?;
        Ok(self.limits[axis])
    }

    fn is_referenced(&mut self, axis: usize) -> Result<bool, HwError> {
        let (ch, _) = self.channel(axis)?;
        let command = format!(":GPPK{ch}");
        match self.request(&command)? {
            McsReply::PhysicalPositionKnown { channel, known } if channel == ch => Ok(known),
            McsReply::Error(e) => Err(self.mcs(&command, e)),
            other => Err(self.bad(&command, &format!("{other:?}"), &format!("`:PPK{ch},<0|1>`"))),
        }
    }

    /// `:FRM<ch>,0,<hold>,1`: find the reference mark forward, hold, set the position to zero there.
    fn reference(&mut self, axis: usize) -> Result<(), HwError> {
        let (ch, _) = self.channel(axis)?;
        self.ack(&format!(":FRM{ch},0,{HOLD_FOREVER_MS},1"), ch)?;
        self.targets[axis] = None;
        Ok(())
    }

    fn reconnect(&mut self) -> Result<(), HwError> {
        self.link.reconnect()?;
        self.init()
    }

    fn traffic(&self) -> Option<super::Traffic> {
        Some(self.link.traffic())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn replies_parse_or_are_refused() {
        assert_eq!(parse_reply(":E-1,0"), Some(McsReply::Error(McsError { channel: -1, code: 0 })));
        assert_eq!(parse_reply(":P2,-123456"), Some(McsReply::Position { channel: 2, nm: -123456 }));
        assert_eq!(
            parse_reply(":A0,356000000,-1"),
            Some(McsReply::Angle { channel: 0, micro_deg: 356_000_000, revolution: -1 })
        );
        assert_eq!(parse_reply(":S1,4"), Some(McsReply::Status { channel: 1, code: 4 }));
        assert_eq!(parse_reply(":PPK0,1"), Some(McsReply::PhysicalPositionKnown { channel: 0, known: true }));
        assert_eq!(parse_reply(":N3"), Some(McsReply::Channels(3)));
        assert_eq!(parse_reply(":ID3118000001"), Some(McsReply::SystemId(3_118_000_001)));
        assert_eq!(parse_reply(":ST1,16"), Some(McsReply::SensorType { channel: 1, sensor: 16 }));
        for bad in
            ["", ":", "P0,1", ":P0", ":P0,x", ":A0,1", ":E0,-5", ":Q0,1", ":PPK0,2", ":S1,2,3", ":ID", ":ID-4", ":IDx"]
        {
            assert_eq!(parse_reply(bad), None, "{bad}");
        }
        // A multi-byte character after the colon is refused, not split inside.
        assert_eq!(parse_reply(":é0,1"), None);
        assert_eq!(parse_reply(":\u{80}"), None);
    }

    #[test]
    fn the_system_id_is_read_where_the_firmware_gives_one() {
        use crate::hardware::emulator::{EmuClock, SmarActEmulator, SmarActEmulatorConfig};
        let clock = EmuClock::new(1.0);
        let with = SmarActEmulator::start(clock.clone(), SmarActEmulatorConfig::default()).unwrap();
        let mcs = SmarActMcs::connect("MCS", &with.addr().to_string(), 1.0, &[]).unwrap();
        assert_eq!(mcs.system_id(), Some(3_118_000_001));
        assert_eq!(
            mcs.identification(),
            "SmarAct MCS, system ID 3118000001, 3 channels (rotary sensor 16, rotary sensor 17, rotary sensor 26)"
        );
        // An older firmware answers `:GSI` with an error: the controller still connects, named by its channels.
        let config = SmarActEmulatorConfig { system_id: None, ..Default::default() };
        let without = SmarActEmulator::start(clock, config).unwrap();
        let mcs = SmarActMcs::connect("MCS", &without.addr().to_string(), 1.0, &[]).unwrap();
        assert_eq!(mcs.system_id(), None);
        assert_eq!(
            mcs.identification(),
            "SmarAct MCS, 3 channels (rotary sensor 16, rotary sensor 17, rotary sensor 26)"
        );
    }

    proptest::proptest! {
        /// Any line, bytes from a wire read lossily included, parses or is refused: never a panic.
        #[test]
        fn any_reply_line_parses_or_is_refused(bytes in proptest::collection::vec(proptest::num::u8::ANY, 0..24)) {
            let mut line = vec![b':'];
            line.extend(bytes);
            let _ = parse_reply(&String::from_utf8_lossy(&line));
        }
    }

    #[test]
    fn angles_split_into_micro_degrees_and_revolutions() {
        assert_eq!(angle_to_mcs(-4.0), (356_000_000, -1));
        assert_eq!(angle_to_mcs(365.5), (5_500_000, 1));
        assert_eq!(angle_from_mcs(356_000_000, -1), -4.0);
        for deg in [-359.999999, -0.000001, 0.0, 2.5, 180.0, 720.25] {
            let (a, r) = angle_to_mcs(deg);
            assert!((0..MICRO_DEG_PER_REV).contains(&a));
            assert!((angle_from_mcs(a, r) - deg).abs() < 1e-9, "{deg}");
        }
    }

    #[test]
    fn errors_carry_the_mcs_meaning() {
        let e = McsError { channel: 0, code: 147 };
        assert!(e.is_limit());
        assert_eq!(
            e.to_string(),
            "MCS error 147 on channel 0: Range limit reached: the positioner stopped at a defined range limit"
        );
        assert!(McsError { channel: 1, code: 99 }.to_string().contains("unknown MCS error"));
    }
}
