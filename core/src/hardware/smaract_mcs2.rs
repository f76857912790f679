//! SmarAct MCS2 driver: its ASCII (SCPI-like) command set over TCP (port 55551), commands and
//! replies ended by CR LF. Owns command formatting, the error queue (`:SYST:ERR:COUN?`,
//! `:SYST:ERR?`) read after every set command, the channel state bits, and the units.
//!
//! Sources: SmarAct's SDK header `SmarActControlConstants.h` (channel state bits
//! `SA_CTL_CH_STATE_BIT_*`, movement types, `SA_CTL_HOLD_TIME_INFINITE` = -1, error codes), the
//! EPICS driver `smarActMCS2MotorDriver.cpp` (motorSmarAct: `:DEV:SNUM?`, `:CHANn:STAT?`,
//! `:CHANn:MMOD`, `:CHANn:VEL`, `:MOVEn`, `:STOPn`, `:CHANn:REF:OPT`, `:REFn`, `:CHANn:POS?`,
//! CR LF terminators), ESRF BLISS `SmarAct_MCS2` (`:DEV:NOCH?`, `:CHANn:HOLD -1`, `:MMOD 0`,
//! "pico-meter for linear, nano-degree for rotary", the error queue) and a Tango driver's
//! `:CHANn:TUN:MTYP?` (0 linear, 1 rotary, 2 goniometer, 3 tilt). Positions cross the trait in µm
//! and degrees; the controller speaks pm and n°.

use super::{parse_i64, AxisInfo, HwError, LineEnd, Link, StageController, Traffic};
use crate::bench::AxisUnit;

/// The MCS2's default TCP port for its ASCII interface (BLISS `SmarAct_MCS2.DEFAULT_PORT`).
pub const DEFAULT_PORT: u16 = 55551;

/// Channel state bits of `:CHANn:STAT?` (`SA_CTL_CH_STATE_BIT_*`).
pub mod state {
    /// The channel is moving.
    pub const ACTIVELY_MOVING: u32 = 0x0001;
    /// The control loop is closed.
    pub const CLOSED_LOOP_ACTIVE: u32 = 0x0002;
    /// Calibrating.
    pub const CALIBRATING: u32 = 0x0004;
    /// Looking for the reference mark.
    pub const REFERENCING: u32 = 0x0008;
    /// A sensor is present.
    pub const SENSOR_PRESENT: u32 = 0x0020;
    /// The physical position is known.
    pub const IS_REFERENCED: u32 = 0x0080;
    /// Stopped at a mechanical end stop.
    pub const END_STOP_REACHED: u32 = 0x0100;
    /// Stopped at the software range limit.
    pub const RANGE_LIMIT_REACHED: u32 = 0x0200;
    /// The following error grew past its limit.
    pub const FOLLOWING_LIMIT_REACHED: u32 = 0x0400;
    /// The movement failed.
    pub const MOVEMENT_FAILED: u32 = 0x0800;
}

/// Movement types of `:CHANn:TUN:MTYP?` (`SA_CTL_POS_MOVEMENT_TYPE_*`).
fn movement_is_rotary(movement_type: i64) -> Option<bool> {
    match movement_type {
        0 => Some(false),
        1 | 2 => Some(true),
        _ => None,
    }
}

/// A connected MCS2.
pub struct SmarActMcs2 {
    name: String,
    link: Link,
    axes: Vec<AxisInfo>,
    /// Travel range per channel (µm or °): set by configuration.
    limits: Vec<(f64, f64)>,
    /// Last commanded target per channel.
    targets: Vec<Option<f64>>,
    /// `:DEV:SNUM?`.
    serial: String,
}

impl SmarActMcs2 {
    /// Connect, empty the error queue, read the serial number and channel count, and set up each
    /// channel: its movement type (linear or rotary), a sensor present, absolute moves
    /// (`:CHANn:MMOD 0`, read back) and holding the target forever (`:CHANn:HOLD -1`).
    pub fn connect(name: &str, address: &str, timeout_s: f64, limits: &[(f64, f64)]) -> Result<Self, HwError> {
        let link = Link::connect_with(name, address, timeout_s, LineEnd::CrLf)?;
        let mut m = SmarActMcs2 {
            name: name.to_string(),
            link,
            axes: vec![],
            limits: limits.to_vec(),
            targets: vec![],
            serial: String::new(),
        };
        m.init()?;
        Ok(m)
    }

    fn init(&mut self) -> Result<(), HwError> {
        self.drain_errors()?;
        self.serial = self.query(":DEV:SNUM?")?.trim().trim_matches('"').to_string();
        let n = self.query_int(":DEV:NOCH?")?;
        if !(1..=64).contains(&n) {
            return Err(HwError::bad_reply(&self.name, ":DEV:NOCH?", &n.to_string(), "1 to 64 channels"));
        }
        let mut axes = Vec::new();
        for ch in 0..n {
            let command = format!(":CHAN{ch}:TUN:MTYP?");
            let kind = self.query_int(&command)?;
            let unit = match movement_is_rotary(kind) {
                Some(true) => AxisUnit::Degree,
                Some(false) => AxisUnit::Micrometre,
                None => {
                    return Err(HwError::bad_reply(
                        &self.name,
                        &command,
                        &kind.to_string(),
                        "0 (linear), 1 (rotary) or 2 (goniometer)",
                    ))
                }
            };
            if self.state(ch as usize)? & state::SENSOR_PRESENT == 0 {
                return Err(HwError::Usage {
                    controller: self.name.clone(),
                    problem: format!("channel {ch} has no sensor: closed-loop moves need one"),
                });
            }
            self.command(&format!(":CHAN{ch}:MMOD 0"))?;
            let mode = self.query_int(&format!(":CHAN{ch}:MMOD?"))?;
            if mode != 0 {
                return Err(HwError::bad_reply(
                    &self.name,
                    &format!(":CHAN{ch}:MMOD?"),
                    &mode.to_string(),
                    "0 (absolute) as just set",
                ));
            }
            self.command(&format!(":CHAN{ch}:HOLD -1"))?;
            axes.push(AxisInfo { id: ch.to_string(), unit });
        }
        self.targets = vec![None; axes.len()];
        self.limits.resize(axes.len(), (f64::NEG_INFINITY, f64::INFINITY));
        self.axes = axes;
        Ok(())
    }

    /// The serial number read at connect.
    pub fn serial(&self) -> &str {
        &self.serial
    }

    /// Record every command and reply.
    pub fn set_transcript(&mut self, t: Option<super::Transcript>) {
        self.link.set_transcript(t);
    }

    /// A query and its one-line reply. An MCS2 that refuses a query answers nothing and queues the
    /// error: after a silent query the queue is read on a fresh connection, so the refusal is
    /// reported, not a timeout.
    fn query(&mut self, command: &str) -> Result<String, HwError> {
        match self.query_raw(command) {
            Err(HwError::Timeout { timeout_s, .. }) => {
                let timeout = HwError::Timeout { controller: self.name.clone(), command: command.into(), timeout_s };
                if self.link.reconnect().is_ok() {
                    if let Ok(errors) = self.take_errors() {
                        if let Some((code, text)) = errors.first() {
                            return Err(HwError::Usage {
                                controller: self.name.clone(),
                                problem: format!("`{command}` failed: MCS2 error {code}, \"{text}\""),
                            });
                        }
                    }
                }
                self.link.close();
                Err(timeout)
            }
            other => other,
        }
    }

    fn query_raw(&mut self, command: &str) -> Result<String, HwError> {
        self.link.send(command)?;
        self.link.read_line(command)
    }

    fn query_int(&mut self, command: &str) -> Result<i64, HwError> {
        let reply = self.query(command)?;
        parse_i64(&self.name, command, &reply, &reply)
    }

    /// `:SYST:ERR:COUN?` then that many `:SYST:ERR?` (BLISS `_flush_errors`): the errors queued.
    fn take_errors(&mut self) -> Result<Vec<(i64, String)>, HwError> {
        let reply = self.query_raw(":SYST:ERR:COUN?")?;
        let count = parse_i64(&self.name, ":SYST:ERR:COUN?", &reply, &reply)?;
        let mut out = Vec::new();
        for _ in 0..count.clamp(0, 64) {
            let reply = self.query_raw(":SYST:ERR?")?;
            let (code, text) = reply.split_once(',').unwrap_or((reply.as_str(), ""));
            let code = parse_i64(&self.name, ":SYST:ERR?", &reply, code)?;
            out.push((code, text.trim().trim_matches('"').to_string()));
        }
        Ok(out)
    }

    fn drain_errors(&mut self) -> Result<(), HwError> {
        self.take_errors().map(|_| ())
    }

    /// Send a set command (no reply), then read the error queue: an error is the command's.
    fn command(&mut self, command: &str) -> Result<(), HwError> {
        tracing::debug!(controller = %self.name, "{command}");
        self.link.send(command)?;
        let errors = self.take_errors()?;
        match errors.first() {
            None => Ok(()),
            Some((code, text)) => Err(HwError::Usage {
                controller: self.name.clone(),
                problem: format!("`{command}` failed: MCS2 error {code}, \"{text}\""),
            }),
        }
    }

    fn channel(&self, axis: usize) -> Result<AxisUnit, HwError> {
        self.axes.get(axis).map(|a| a.unit).ok_or_else(|| HwError::Usage {
            controller: self.name.clone(),
            problem: format!("no channel with index {axis} (the controller has {})", self.axes.len()),
        })
    }

    /// `:CHANn:STAT?`: the channel state bits.
    fn state(&mut self, axis: usize) -> Result<u32, HwError> {
        let command = format!(":CHAN{axis}:STAT?");
        let v = self.query_int(&command)?;
        u32::try_from(v).map_err(|_| HwError::bad_reply(&self.name, &command, &v.to_string(), "a 32-bit state word"))
    }

    /// pm (linear) or n° (rotary) per µm or °.
    fn base_per_unit(unit: AxisUnit) -> f64 {
        match unit {
            AxisUnit::Micrometre => 1e6,
            AxisUnit::Degree => 1e9,
        }
    }

    fn position(&mut self, axis: usize) -> Result<f64, HwError> {
        let unit = self.channel(axis)?;
        let v = self.query_int(&format!(":CHAN{axis}:POS?"))?;
        Ok(v as f64 / Self::base_per_unit(unit))
    }

    fn move_to(&mut self, axis: usize, target: f64) -> Result<(), HwError> {
        let unit = self.channel(axis)?;
        let (min, max) = self.limits[axis];
        if !(target.is_finite() && target >= min && target <= max) {
            return Err(HwError::OutOfRange {
                controller: self.name.clone(),
                axis: axis.to_string(),
                target,
                min,
                max,
                unit: unit.symbol(),
            });
        }
        let base = (target * Self::base_per_unit(unit)).round() as i64;
        self.command(&format!(":MOVE{axis} {base}"))?;
        self.targets[axis] = Some(target);
        Ok(())
    }

    fn limit_error(&mut self, axis: usize, bits: u32) -> Result<HwError, HwError> {
        let position = self.position(axis)?;
        let unit = self.axes[axis].unit;
        let reason = [
            (state::END_STOP_REACHED, "end stop reached"),
            (state::RANGE_LIMIT_REACHED, "range limit reached"),
            (state::FOLLOWING_LIMIT_REACHED, "following error limit reached"),
            (state::MOVEMENT_FAILED, "movement failed"),
        ]
        .iter()
        .filter(|(b, _)| bits & b != 0)
        .map(|(_, t)| *t)
        .collect::<Vec<_>>()
        .join(", ");
        Ok(HwError::LimitReached {
            controller: self.name.clone(),
            axis: axis.to_string(),
            position,
            target: self.targets[axis].unwrap_or(position),
            unit: unit.symbol(),
            reason: format!("`:CHAN{axis}:STAT?` = 0x{bits:04X}: {reason}"),
        })
    }
}

impl StageController for SmarActMcs2 {
    fn name(&self) -> String {
        self.name.clone()
    }

    fn axes(&self) -> &[AxisInfo] {
        &self.axes
    }

    fn identification(&self) -> String {
        let kinds: Vec<&str> =
            self.axes.iter().map(|a| if a.unit == AxisUnit::Degree { "rotary" } else { "linear" }).collect();
        format!("SmarAct MCS2, serial {}, {} channels ({})", self.serial, kinds.len(), kinds.join(", "))
    }

    fn move_absolute(&mut self, targets: &[(usize, f64)]) -> Result<(), HwError> {
        for &(a, t) in targets {
            self.move_to(a, t)?;
        }
        Ok(())
    }

    fn move_relative(&mut self, steps: &[(usize, f64)]) -> Result<(), HwError> {
        for &(a, d) in steps {
            let p = self.position(a)?;
            self.move_to(a, p + d)?;
        }
        Ok(())
    }

    fn positions(&mut self, axes: &[usize]) -> Result<Vec<f64>, HwError> {
        axes.iter().map(|&a| self.position(a)).collect()
    }

    /// Not moving, calibrating nor referencing; a channel that stopped on an end stop, a range or
    /// following limit, or a failed movement is a [`HwError::LimitReached`].
    fn on_target(&mut self, axes: &[usize]) -> Result<Vec<bool>, HwError> {
        let mut out = Vec::with_capacity(axes.len());
        for &a in axes {
            self.channel(a)?;
            let bits = self.state(a)?;
            let faults = state::END_STOP_REACHED
                | state::RANGE_LIMIT_REACHED
                | state::FOLLOWING_LIMIT_REACHED
                | state::MOVEMENT_FAILED;
            if bits & faults != 0 {
                return Err(self.limit_error(a, bits)?);
            }
            out.push(bits & (state::ACTIVELY_MOVING | state::CALIBRATING | state::REFERENCING) == 0);
        }
        Ok(out)
    }

    fn stop(&mut self) -> Result<(), HwError> {
        let mut first = None;
        for a in 0..self.axes.len() {
            if let Err(e) = self.command(&format!(":STOP{a}")) {
                first.get_or_insert(e);
                if !self.link.is_open() {
                    break;
                }
            }
            self.targets[a] = None;
        }
        first.map_or(Ok(()), Err)
    }

    /// `:CHANn:VEL <pm/s | n°/s>`, read back; 0 would switch velocity control off (BLISS), so
    /// at least one base unit per second is sent.
    fn set_velocity(&mut self, axis: usize, per_s: f64) -> Result<(), HwError> {
        let unit = self.channel(axis)?;
        let v = (per_s.abs() * Self::base_per_unit(unit)).round().max(1.0) as i64;
        self.command(&format!(":CHAN{axis}:VEL {v}"))?;
        let read = self.query_int(&format!(":CHAN{axis}:VEL?"))?;
        if read != v {
            return Err(HwError::bad_reply(
                &self.name,
                &format!(":CHAN{axis}:VEL?"),
                &read.to_string(),
                &format!("{v}, the velocity just set"),
            ));
        }
        Ok(())
    }

    fn travel_limits(&mut self, axis: usize) -> Result<(f64, f64), HwError> {
        self.channel(axis)?;
        Ok(self.limits[axis])
    }

    fn is_referenced(&mut self, axis: usize) -> Result<bool, HwError> {
        self.channel(axis)?;
        Ok(self.state(axis)? & state::IS_REFERENCED != 0)
    }

    /// `:CHANn:REF:OPT 4` (auto zero) then `:REFn` (EPICS `home`, BLISS `find_reference_mark`).
    fn reference(&mut self, axis: usize) -> Result<(), HwError> {
        self.channel(axis)?;
        self.command(&format!(":CHAN{axis}:REF:OPT 4"))?;
        self.command(&format!(":REF{axis}"))?;
        self.targets[axis] = None;
        Ok(())
    }

    fn reconnect(&mut self) -> Result<(), HwError> {
        self.link.reconnect()?;
        self.init()
    }

    fn traffic(&self) -> Option<Traffic> {
        Some(self.link.traffic())
    }
}
