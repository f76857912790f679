//! SmarAct MCS2 emulator: the ASCII subset of [`crate::hardware::smaract_mcs2`] on loopback TCP,
//! commands and replies ended by CR LF, set commands silent with their errors queued
//! (`:SYST:ERR:COUN?`, `:SYST:ERR?`), a refused query silent too, channels in pm or n° moving at
//! finite speed (velocity control off at `:CHANn:VEL 0`: the channel runs at its fastest), and the
//! channel state bits; fault injection as the other emulators.

use super::{take_fault, EmuAxis, EmuClock, Fault, FaultSpec, Faults, Server, SharedAxes};
use crate::hardware::smaract_mcs2::state;
use std::collections::VecDeque;
use std::io::{BufReader, Write};
use std::net::{SocketAddr, TcpStream};
use std::sync::{Arc, Mutex};

/// The emulated MCS2.
#[derive(Debug, Clone)]
pub struct Mcs2EmulatorConfig {
    /// Channels: movement type (0 linear, 1 rotary, 2 goniometer), start position and travel range
    /// (pm or n°).
    pub channels: Vec<(i64, f64, f64, f64)>,
    /// Closed-loop speed of linear channels (pm/s) until `:CHANn:VEL` changes it.
    pub linear_speed_pm_per_s: f64,
    /// Closed-loop speed of rotary channels (n°/s).
    pub rotary_speed_ndeg_per_s: f64,
    /// Acceleration of linear channels (pm/s²).
    pub linear_accel_pm_per_s2: f64,
    /// Acceleration of rotary channels (n°/s²).
    pub rotary_accel_ndeg_per_s2: f64,
    /// `:DEV:SNUM?`.
    pub serial: String,
}

impl Default for Mcs2EmulatorConfig {
    /// The paper's wrist on an MCS2: two goniometers (±12°) and a rotary stage (±360°), at 0°,
    /// 2 °/s, 20 °/s².
    fn default() -> Self {
        Mcs2EmulatorConfig {
            channels: vec![(2, 0.0, -12e9, 12e9), (2, 0.0, -12e9, 12e9), (1, 0.0, -360e9, 360e9)],
            linear_speed_pm_per_s: 1e9,
            rotary_speed_ndeg_per_s: 2e9,
            linear_accel_pm_per_s2: 1e10,
            rotary_accel_ndeg_per_s2: 20e9,
            serial: "MCS2-00001234".into(),
        }
    }
}

struct Channel {
    movement_type: i64,
    move_mode: i64,
    hold_ms: i64,
    /// `:CHANn:VEL` (0: velocity control off).
    vel: i64,
    acc: i64,
    fastest: f64,
    referencing: bool,
    /// Stopped on a limit (end stop) by an injected fault.
    end_stop: bool,
}

struct State {
    channels: Vec<Channel>,
    errors: VecDeque<(i64, String)>,
    faults: Faults,
    serial: String,
}

struct Shared {
    clock: Arc<EmuClock>,
    state: Mutex<State>,
    axes: SharedAxes,
}

/// A running MCS2 emulator.
pub struct Mcs2Emulator {
    server: Server,
    shared: Arc<Shared>,
}

impl Mcs2Emulator {
    /// Start on an ephemeral loopback port.
    pub fn start(clock: Arc<EmuClock>, config: Mcs2EmulatorConfig) -> std::io::Result<Self> {
        Self::start_on(0, clock, config)
    }

    /// Start on `port` of 127.0.0.1 (0: any free port).
    pub fn start_on(port: u16, clock: Arc<EmuClock>, config: Mcs2EmulatorConfig) -> std::io::Result<Self> {
        let speed = |t: i64| {
            if t == 0 {
                (config.linear_speed_pm_per_s, config.linear_accel_pm_per_s2)
            } else {
                (config.rotary_speed_ndeg_per_s, config.rotary_accel_ndeg_per_s2)
            }
        };
        let axes =
            config.channels.iter().map(|&(t, p, min, max)| EmuAxis::new(p, min, max, speed(t).0, speed(t).1)).collect();
        let channels = config
            .channels
            .iter()
            .map(|&(t, ..)| Channel {
                movement_type: t,
                move_mode: 0,
                hold_ms: 1000,
                vel: speed(t).0 as i64,
                acc: speed(t).1 as i64,
                fastest: speed(t).0 * 10.0,
                referencing: false,
                end_stop: false,
            })
            .collect();
        let shared = Arc::new(Shared {
            clock,
            state: Mutex::new(State {
                channels,
                errors: VecDeque::new(),
                faults: Faults::default(),
                serial: config.serial,
            }),
            axes: Arc::new(Mutex::new(axes)),
        });
        let s2 = shared.clone();
        let server = Server::start(port, move |stream| serve(&s2, stream))?;
        Ok(Mcs2Emulator { server, shared })
    }

    /// The address it listens on.
    pub fn addr(&self) -> SocketAddr {
        self.server.addr
    }

    /// The channels (pm or n°), shared: a photodiode closure may read their positions at any time.
    pub fn axes(&self) -> SharedAxes {
        self.shared.axes.clone()
    }

    /// Arm a fault.
    pub fn inject(&self, fault: FaultSpec) {
        self.shared.state.lock().unwrap_or_else(|e| e.into_inner()).faults.armed.push(fault);
    }

    /// Faults that fired so far.
    pub fn fired(&self) -> Vec<(String, Fault)> {
        self.shared.state.lock().unwrap_or_else(|e| e.into_inner()).faults.fired.clone()
    }

    /// True while any channel moves.
    pub fn any_moving(&self) -> bool {
        let t = self.shared.clock.now_s();
        self.shared.axes.lock().unwrap_or_else(|e| e.into_inner()).iter().any(|a| a.moving_at(t))
    }

    /// Mark a channel as not referenced.
    pub fn set_referenced(&self, channel: usize, referenced: bool) {
        if let Some(a) = self.shared.axes.lock().unwrap_or_else(|e| e.into_inner()).get_mut(channel) {
            a.referenced = referenced;
        }
    }
}

fn serve(shared: &Shared, stream: TcpStream) {
    let Ok(mut writer) = stream.try_clone() else { return };
    let mut reader = BufReader::new(stream);
    let mut buf = Vec::new();
    loop {
        let Some(command) = super::read_command(&mut reader, &mut buf) else { return };
        if command.trim().is_empty() {
            continue;
        }
        match handle(shared, command.trim()) {
            None => {
                let _ = writer.shutdown(std::net::Shutdown::Both);
                return;
            }
            Some(Some(reply)) => {
                if writer.write_all(format!("{reply}\r\n").as_bytes()).is_err() {
                    return;
                }
            }
            Some(None) => {}
        }
    }
}

/// An MCS2 error: its code and text (SCPI codes, `SA_CTL_ERROR_*`).
type Err2 = (i64, &'static str);
const UNDEFINED: Err2 = (-113, "Undefined header");
const DATA_TYPE: Err2 = (-104, "Data type error");
const MISSING: Err2 = (-109, "Missing parameter");
const BAD_CHANNEL: Err2 = (34, "Invalid channel index");

/// `None`: drop the connection; `Some(None)`: no reply; `Some(Some(line))`: reply.
fn handle(shared: &Shared, command: &str) -> Option<Option<String>> {
    let (mut st, now, fired) = take_fault(&shared.state, |s| &mut s.faults, || shared.clock.now_s(), command);
    match fired {
        Some(Fault::DropConnection) => return None,
        Some(Fault::NoReply) => return Some(None),
        Some(Fault::ErrorCode(c)) => {
            st.errors.push_back((c, "Injected error".into()));
            return Some(None);
        }
        Some(Fault::Limit) => {
            let mut axes = shared.axes.lock().unwrap_or_else(|e| e.into_inner());
            for (a, c) in axes.iter_mut().zip(st.channels.iter_mut()) {
                if a.moving_at(now) {
                    a.stop(now);
                    c.end_stop = true;
                }
            }
        }
        Some(Fault::Delay(_)) | None => {}
    }
    match execute(shared, &mut st, now, command) {
        Ok(reply) => Some(reply),
        Err((code, text)) => {
            if st.errors.len() < 64 {
                st.errors.push_back((code, text.into()));
            }
            Some(None)
        }
    }
}

/// The channel number after a prefix (`:CHAN2:…`, `:MOVE2`), and the rest.
fn channel_of<'a>(st: &State, text: &'a str, prefix: &str) -> Result<Option<(usize, &'a str)>, Err2> {
    let Some(rest) = text.strip_prefix(prefix) else { return Ok(None) };
    let digits = rest.find(|c: char| !c.is_ascii_digit()).unwrap_or(rest.len());
    let ch = rest[..digits].parse::<usize>().map_err(|_| UNDEFINED)?;
    if ch >= st.channels.len() {
        return Err(BAD_CHANNEL);
    }
    Ok(Some((ch, &rest[digits..])))
}

fn int_arg(arg: &str) -> Result<i64, Err2> {
    if arg.is_empty() {
        return Err(MISSING);
    }
    arg.parse::<i64>().or_else(|_| arg.parse::<f64>().map(|v| v.round() as i64)).map_err(|_| DATA_TYPE)
}

fn execute(shared: &Shared, st: &mut State, now: f64, command: &str) -> Result<Option<String>, Err2> {
    let (header, arg) = match command.split_once(char::is_whitespace) {
        Some((h, a)) => (h.to_ascii_uppercase(), a.trim()),
        None => (command.to_ascii_uppercase(), ""),
    };
    let reply = |s: String| Ok(Some(s));
    match header.as_str() {
        "*IDN?" => return reply(format!("SmarAct,MCS2 (emulated),{},1.0", st.serial)),
        ":DEV:SNUM?" => return reply(format!("\"{}\"", st.serial)),
        ":DEV:NOCH?" => return reply(st.channels.len().to_string()),
        ":SYST:ERR:COUN?" => return reply(st.errors.len().to_string()),
        ":SYST:ERR?" | ":SYST:ERR:NEXT?" => {
            let (code, text) = st.errors.pop_front().unwrap_or((0, "No error".into()));
            return reply(format!("{code},\"{text}\""));
        }
        _ => {}
    }
    let mut axes = shared.axes.lock().unwrap_or_else(|e| e.into_inner());
    if let Some((c, _)) = channel_of(st, &header, ":MOVE")? {
        let v = int_arg(arg)? as f64;
        let target = if st.channels[c].move_mode == 1 { axes[c].target_at(now) + v } else { v };
        let ch = &mut st.channels[c];
        ch.end_stop = false;
        ch.referencing = false;
        axes[c].speed = if ch.vel == 0 { ch.fastest } else { ch.vel as f64 };
        // Beyond its range the channel stops at the range limit, with the flag set.
        let (min, max) = (axes[c].min, axes[c].max);
        axes[c].start_move(now, target.clamp(min, max));
        axes[c].at_limit = target < min || target > max;
        return Ok(None);
    }
    if let Some((c, "")) = channel_of(st, &header, ":STOP")? {
        axes[c].stop(now);
        st.channels[c].referencing = false;
        return Ok(None);
    }
    if let Some((c, "")) = channel_of(st, &header, ":REF")? {
        axes[c].speed = st.channels[c].fastest / 10.0;
        axes[c].start_move(now, 0.0);
        st.channels[c].referencing = true;
        return Ok(None);
    }
    let Some((c, property)) = channel_of(st, &header, ":CHAN")? else { return Err(UNDEFINED) };
    channel_property(st, &mut axes, now, c, property, arg)
}

/// `:CHANn:<property>` queries and settings.
fn channel_property(
    st: &mut State,
    axes: &mut [EmuAxis],
    now: f64,
    c: usize,
    property: &str,
    arg: &str,
) -> Result<Option<String>, Err2> {
    let ch = &mut st.channels[c];
    let a = &mut axes[c];
    if ch.referencing && !a.moving_at(now) {
        ch.referencing = false;
        a.referenced = true;
    }
    let reply = |v: String| Ok(Some(v));
    match property {
        ":TUN:MTYP?" => reply(ch.movement_type.to_string()),
        ":STAT?" => {
            let mut bits = state::CLOSED_LOOP_ACTIVE | state::SENSOR_PRESENT | 0x0040;
            if a.moving_at(now) {
                bits |= state::ACTIVELY_MOVING;
            }
            if ch.referencing {
                bits |= state::REFERENCING;
            }
            if a.referenced {
                bits |= state::IS_REFERENCED;
            }
            if ch.end_stop {
                bits |= state::END_STOP_REACHED;
            }
            if a.at_limit && !a.moving_at(now) {
                bits |= state::RANGE_LIMIT_REACHED;
            }
            reply(bits.to_string())
        }
        ":POS?" => reply((a.position_at(now).round() as i64).to_string()),
        ":POS:TARG?" => reply((a.target_at(now).round() as i64).to_string()),
        ":MMOD?" => reply(ch.move_mode.to_string()),
        ":HOLD?" => reply(ch.hold_ms.to_string()),
        ":VEL?" => reply(ch.vel.to_string()),
        ":ACC?" => reply(ch.acc.to_string()),
        ":MMOD" => {
            let m = int_arg(arg)?;
            if !(0..=4).contains(&m) {
                return Err((-222, "Data out of range"));
            }
            ch.move_mode = m;
            Ok(None)
        }
        ":HOLD" => {
            ch.hold_ms = int_arg(arg)?;
            Ok(None)
        }
        ":VEL" | ":ACC" => {
            let v = int_arg(arg)?;
            if v < 0 {
                return Err((-222, "Data out of range"));
            }
            if property == ":VEL" {
                ch.vel = v;
            } else {
                ch.acc = v;
                // 0: acceleration control off, the move runs at its velocity from the start.
                a.accel = if v > 0 { v as f64 } else { super::NO_ACCELERATION_CONTROL };
            }
            Ok(None)
        }
        ":REF:OPT" => int_arg(arg).map(|_| None),
        _ => Err(UNDEFINED),
    }
}
