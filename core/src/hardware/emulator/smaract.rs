//! SmarAct MCS emulator: the ASCII subset of [`crate::hardware::smaract`] in synchronous mode, with
//! linear (nm) and rotary (µ° plus revolutions) channels moving at finite speed, each with its
//! sensor type (`:GST`), and a channel that can be locked (status 9, moves refused with error 146).

use super::{take_fault, EmuAxis, EmuClock, Fault, FaultSpec, Faults, Server, SharedAxes, NO_ACCELERATION_CONTROL};
use crate::hardware::smaract::{angle_to_mcs, status};
use std::io::{BufReader, Write};
use std::net::{SocketAddr, TcpStream};
use std::sync::{Arc, Mutex};

/// The kind of positioner on a channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ChannelKind {
    /// Linear, positions in nm.
    Linear,
    /// Goniometer or rotary stage, angles in µ°.
    Rotary,
}

/// The emulated controller.
#[derive(Debug, Clone)]
pub struct SmarActEmulatorConfig {
    /// Channels: kind, start position and travel range (nm or µ°).
    pub channels: Vec<(ChannelKind, f64, f64, f64)>,
    /// Closed-loop speed of linear channels (nm/s) until `:SCLS` changes it.
    pub linear_speed_nm_per_s: f64,
    /// Closed-loop speed of rotary channels (µ°/s).
    pub rotary_speed_udeg_per_s: f64,
    /// Acceleration (nm/s² or µ°/s²).
    pub linear_accel_nm_per_s2: f64,
    /// Acceleration (µ°/s²).
    pub rotary_accel_udeg_per_s2: f64,
    /// The system ID `:GSI` answers; `None` emulates a firmware that refuses the query (error 2).
    pub system_id: Option<u64>,
    /// Each channel's sensor type `:GST` answers (`SA_*_SENSOR_TYPE` of `MCSControl.h`).
    pub sensor_types: Vec<i64>,
}

impl Default for SmarActEmulatorConfig {
    /// The paper's wrist: two goniometers (SGO-60.5, SGO-77.5; ±12° of travel here; sensor types
    /// G605S = 16 and G775S = 17) and a rotary stage (SR-3610; ±360°; SR36M = 26), at 0°, 2 °/s,
    /// 20 °/s².
    fn default() -> Self {
        SmarActEmulatorConfig {
            channels: vec![
                (ChannelKind::Rotary, 0.0, -12e6, 12e6),
                (ChannelKind::Rotary, 0.0, -12e6, 12e6),
                (ChannelKind::Rotary, 0.0, -360e6, 360e6),
            ],
            linear_speed_nm_per_s: 1e6,
            rotary_speed_udeg_per_s: 2e6,
            linear_accel_nm_per_s2: 1e7,
            rotary_accel_udeg_per_s2: 20e6,
            system_id: Some(3_118_000_001),
            sensor_types: vec![16, 17, 26],
        }
    }
}

struct Channel {
    kind: ChannelKind,
    sensor: i64,
    holding: bool,
    referencing: bool,
    locked: bool,
    max_speed: f64,
    /// Closed-loop acceleration as `:SCLA` set it (nm/s² or µ°/s²; 0: control off).
    accel: i64,
}

struct McsState {
    channels: Vec<Channel>,
    faults: Faults,
    system_id: Option<u64>,
}

struct Shared {
    clock: Arc<EmuClock>,
    state: Mutex<McsState>,
    axes: SharedAxes,
}

/// A running MCS emulator.
pub struct SmarActEmulator {
    server: Server,
    shared: Arc<Shared>,
}

impl SmarActEmulator {
    /// Start on an ephemeral loopback port.
    pub fn start(clock: Arc<EmuClock>, config: SmarActEmulatorConfig) -> std::io::Result<Self> {
        Self::start_on(0, clock, config)
    }

    /// Start on `port` of 127.0.0.1 (0: any free port).
    pub fn start_on(port: u16, clock: Arc<EmuClock>, config: SmarActEmulatorConfig) -> std::io::Result<Self> {
        let speed = |k: ChannelKind| match k {
            ChannelKind::Linear => (config.linear_speed_nm_per_s, config.linear_accel_nm_per_s2),
            ChannelKind::Rotary => (config.rotary_speed_udeg_per_s, config.rotary_accel_udeg_per_s2),
        };
        let axes =
            config.channels.iter().map(|&(k, p, min, max)| EmuAxis::new(p, min, max, speed(k).0, speed(k).1)).collect();
        let channels = config
            .channels
            .iter()
            .enumerate()
            .map(|(i, &(kind, ..))| Channel {
                kind,
                sensor: config.sensor_types.get(i).copied().unwrap_or(match kind {
                    ChannelKind::Linear => 1,
                    ChannelKind::Rotary => 2,
                }),
                holding: false,
                referencing: false,
                locked: false,
                max_speed: speed(kind).0 * 10.0,
                accel: speed(kind).1 as i64,
            })
            .collect();
        let shared = Arc::new(Shared {
            clock,
            state: Mutex::new(McsState { channels, faults: Faults::default(), system_id: config.system_id }),
            axes: Arc::new(Mutex::new(axes)),
        });
        let s2 = shared.clone();
        let server = Server::start(port, move |stream| serve(&s2, stream))?;
        Ok(SmarActEmulator { server, shared })
    }

    /// The address it listens on.
    pub fn addr(&self) -> SocketAddr {
        self.server.addr
    }

    /// The channels (nm or µ°), shared: a photodiode closure may read their positions at any time.
    pub fn axes(&self) -> SharedAxes {
        self.shared.axes.clone()
    }

    /// Arm a fault.
    pub fn inject(&self, fault: FaultSpec) {
        self.shared.state.lock().unwrap_or_else(|e| e.into_inner()).faults.armed.push(fault);
    }

    /// Faults that fired so far, with the command they fired on.
    pub fn fired(&self) -> Vec<(String, Fault)> {
        self.shared.state.lock().unwrap_or_else(|e| e.into_inner()).faults.fired.clone()
    }

    /// What the emulator sends back for one command line (without its LF), as over TCP: the reply
    /// line (empty for none), `None` when it drops the connection.
    pub fn reply_to(&self, command: &str) -> Option<String> {
        handle(&self.shared, command).map(|r| r.map_or(String::new(), |line| format!("{line}\n")))
    }

    /// True while any channel moves.
    pub fn any_moving(&self) -> bool {
        let t = self.shared.clock.now_s();
        self.shared.axes.lock().unwrap_or_else(|e| e.into_inner()).iter().any(|a| a.moving_at(t))
    }

    /// Lock a channel's movement (status 9; moves refused with error 146), or release it.
    pub fn set_locked(&self, channel: usize, locked: bool) {
        let mut st = self.shared.state.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(c) = st.channels.get_mut(channel) {
            c.locked = locked;
        }
    }

    /// Mark a channel as not referenced (its physical position unknown).
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
        match handle(shared, &command) {
            Some(Some(reply)) => {
                if writer.write_all(format!("{reply}\n").as_bytes()).is_err() {
                    return;
                }
            }
            Some(None) => {}
            None => {
                let _ = writer.shutdown(std::net::Shutdown::Both);
                return;
            }
        }
    }
}

/// The channel number a command starts with, for error replies.
fn leading_channel(args: &str) -> i64 {
    args.split(',').next().and_then(|c| c.trim().parse::<i64>().ok()).unwrap_or(-1)
}

/// `None`: drop the connection; `Some(None)`: no reply; `Some(Some(line))`: reply.
fn handle(shared: &Shared, command: &str) -> Option<Option<String>> {
    let (mut st, now, fired) = take_fault(&shared.state, |s| &mut s.faults, || shared.clock.now_s(), command);
    let Some(body) = command.strip_prefix(':') else {
        return Some(Some(":E-1,1".into()));
    };
    // Longer names before their prefixes (GSI before GS).
    const NAMES: [&str; 17] = [
        "SCLA", "SCLS", "SCM", "GCLA", "GNC", "GPPK", "GP", "GA", "GSI", "GST", "GS", "MPA", "MPR", "MAA", "MAR",
        "FRM", "S",
    ];
    let name = NAMES.iter().find(|n| body.starts_with(*n)).copied();
    let args = name.map_or("", |n| &body[n.len()..]);
    let limit_on_move = fired == Some(Fault::Limit) && name.is_some_and(|n| n.starts_with('M') || n == "FRM");
    match fired {
        Some(Fault::DropConnection) => return None,
        Some(Fault::NoReply) => return Some(None),
        Some(Fault::ErrorCode(c)) => return Some(Some(format!(":E{},{c}", leading_channel(args)))),
        Some(Fault::Limit) => {
            let mut axes = shared.axes.lock().unwrap_or_else(|e| e.into_inner());
            for (a, c) in axes.iter_mut().zip(st.channels.iter_mut()) {
                if a.moving_at(now) {
                    a.stop(now);
                    a.at_limit = true;
                    c.holding = false;
                }
            }
        }
        Some(Fault::Delay(_)) | None => {}
    }
    let Some(name) = name else {
        return Some(Some(":E-1,2".into()));
    };
    let reply = execute(shared, &mut st, now, name, args).unwrap_or_else(|(ch, code)| format!(":E{ch},{code}"));
    if limit_on_move {
        // The move starts into an end stop: the channel stops at once, short of its target.
        let c = usize::try_from(leading_channel(args)).ok();
        let mut axes = shared.axes.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((a, ch)) = c.and_then(|c| axes.get_mut(c).zip(st.channels.get_mut(c))) {
            let t = shared.clock.now_s().max(now + 1e-3);
            a.stop(t);
            a.at_limit = true;
            ch.holding = false;
        }
    }
    Some(Some(reply))
}

/// A reply, or the channel and MCS error code of an error reply.
type Mcs<T> = Result<T, (i64, u32)>;

/// The comma-separated integer fields of a command.
struct Fields {
    nums: Vec<i64>,
}

impl Fields {
    /// The fields of `args`, or error 4 for one that is not an integer.
    fn parse(args: &str) -> Mcs<Self> {
        let fields: Vec<&str> = if args.is_empty() { vec![] } else { args.split(',').collect() };
        let nums: Vec<i64> =
            fields.iter().map(|f| f.trim().parse::<i64>().map_err(|_| (-1, 4))).collect::<Result<_, _>>()?;
        Ok(Fields { nums })
    }

    /// Exactly `n` fields, or the error for too few (5) or too many (6).
    fn count(&self, n: usize) -> Mcs<()> {
        let ch = self.nums.first().copied().unwrap_or(-1);
        match self.nums.len().cmp(&n) {
            std::cmp::Ordering::Less => Err((ch, 5)),
            std::cmp::Ordering::Greater => Err((ch, 6)),
            std::cmp::Ordering::Equal => Ok(()),
        }
    }

    /// The channel the first field names, or the error for a channel the controller does not have (7).
    fn channel(&self, st: &McsState) -> Mcs<usize> {
        let ch = self.nums.first().copied().unwrap_or(-1);
        usize::try_from(ch).ok().filter(|&c| c < st.channels.len()).ok_or((ch, 7))
    }
}

/// Run one command (its name and the fields after it): the reply line, or an error reply's channel and code.
fn execute(shared: &Shared, st: &mut McsState, now: f64, name: &str, args: &str) -> Mcs<String> {
    let fields = Fields::parse(args)?;
    let mut axes = shared.axes.lock().unwrap_or_else(|e| e.into_inner());
    match name {
        "SCM" | "GNC" | "GSI" | "GST" | "GPPK" | "GP" | "GA" | "GS" | "GCLA" => {
            query(st, &mut axes, now, name, &fields)
        }
        "MPA" | "MPR" | "MAA" | "MAR" => move_channel(st, &mut axes, now, name, &fields),
        "S" | "SCLS" | "SCLA" | "FRM" => control(st, &mut axes, now, name, &fields),
        _ => Err((-1, 2)),
    }
}

/// Queries: communication mode, channel count, referenced, position or angle, status (which
/// also ends a finished reference move).
fn query(st: &mut McsState, axes: &mut [EmuAxis], now: f64, name: &str, fields: &Fields) -> Mcs<String> {
    let nums = &fields.nums;
    match name {
        "SCM" => {
            fields.count(1)?;
            if nums[0] != 0 {
                return Err((-1, 7));
            }
            Ok(":E-1,0".into())
        }
        "GNC" => {
            fields.count(0)?;
            Ok(format!(":N{}", st.channels.len()))
        }
        "GSI" => {
            fields.count(0)?;
            st.system_id.map(|id| format!(":ID{id}")).ok_or((-1, 2))
        }
        "GST" => {
            fields.count(1)?;
            let c = fields.channel(st)?;
            Ok(format!(":ST{c},{}", st.channels[c].sensor))
        }
        "GCLA" => {
            fields.count(1)?;
            let c = fields.channel(st)?;
            Ok(format!(":CLA{c},{}", st.channels[c].accel))
        }
        "GPPK" => {
            fields.count(1)?;
            let c = fields.channel(st)?;
            Ok(format!(":PPK{c},{}", u8::from(axes[c].referenced)))
        }
        "GP" | "GA" => {
            fields.count(1)?;
            let c = fields.channel(st)?;
            let p = axes[c].position_at(now).round();
            match (name, st.channels[c].kind) {
                ("GP", ChannelKind::Linear) => Ok(format!(":P{c},{}", p as i64)),
                ("GA", ChannelKind::Rotary) => {
                    let (a, r) = angle_to_mcs(p * 1e-6);
                    Ok(format!(":A{c},{a},{r}"))
                }
                _ => Err((c as i64, 143)),
            }
        }
        "GS" => {
            fields.count(1)?;
            let c = fields.channel(st)?;
            let ch = &mut st.channels[c];
            let code = if ch.locked {
                status::LOCKED
            } else if axes[c].moving_at(now) {
                if ch.referencing {
                    status::FINDING_REFERENCE
                } else {
                    status::TARGETING
                }
            } else {
                if ch.referencing {
                    ch.referencing = false;
                    axes[c].referenced = true;
                }
                if ch.holding {
                    status::HOLDING
                } else {
                    status::STOPPED
                }
            };
            Ok(format!(":S{c},{code}"))
        }
        _ => Err((-1, 2)),
    }
}

/// An absolute or relative move of a linear (`MP*`) or rotary (`MA*`) channel.
fn move_channel(st: &mut McsState, axes: &mut [EmuAxis], now: f64, name: &str, fields: &Fields) -> Mcs<String> {
    let nums = &fields.nums;
    let rotary = name.starts_with("MA");
    fields.count(if rotary { 4 } else { 3 })?;
    let c = fields.channel(st)?;
    let kind = st.channels[c].kind;
    if st.channels[c].locked {
        return Err((c as i64, 146));
    }
    if rotary != (kind == ChannelKind::Rotary) {
        return Err((c as i64, 143));
    }
    let value = if rotary {
        if !(0..360_000_000).contains(&nums[1]) {
            return Err((c as i64, 7));
        }
        nums[1] as f64 + nums[2] as f64 * 360e6
    } else {
        nums[1] as f64
    };
    let hold = nums[nums.len() - 1];
    if !(0..=60000).contains(&hold) {
        return Err((c as i64, 7));
    }
    let target = if name.ends_with('R') { axes[c].target_at(now) + value } else { value };
    if target < axes[c].min || target > axes[c].max {
        return Err((c as i64, 7));
    }
    axes[c].start_move(now, target);
    st.channels[c].holding = true;
    st.channels[c].referencing = false;
    Ok(format!(":E{c},0"))
}

/// Stop, closed-loop speed, and the reference move.
fn control(st: &mut McsState, axes: &mut [EmuAxis], now: f64, name: &str, fields: &Fields) -> Mcs<String> {
    let nums = &fields.nums;
    match name {
        "S" => {
            fields.count(1)?;
            let c = fields.channel(st)?;
            axes[c].stop(now);
            st.channels[c].holding = false;
            st.channels[c].referencing = false;
            Ok(format!(":E{c},0"))
        }
        "SCLS" => {
            fields.count(2)?;
            let c = fields.channel(st)?;
            if nums[1] < 0 {
                return Err((c as i64, 7));
            }
            axes[c].speed = if nums[1] == 0 { st.channels[c].max_speed } else { nums[1] as f64 };
            Ok(format!(":E{c},0"))
        }
        "SCLA" => {
            fields.count(2)?;
            let c = fields.channel(st)?;
            if nums[1] < 0 {
                return Err((c as i64, 7));
            }
            st.channels[c].accel = nums[1];
            // Off (0): the move runs at its speed from the start, a ramp.
            axes[c].accel = if nums[1] == 0 { NO_ACCELERATION_CONTROL } else { nums[1] as f64 };
            Ok(format!(":E{c},0"))
        }
        "FRM" => {
            fields.count(4)?;
            let c = fields.channel(st)?;
            // The reference mark sits at the zero position.
            axes[c].start_move(now, 0.0);
            st.channels[c].holding = nums[2] > 0;
            st.channels[c].referencing = true;
            Ok(format!(":E{c},0"))
        }
        _ => Err((-1, 2)),
    }
}
