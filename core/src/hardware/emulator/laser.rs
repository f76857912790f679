//! Tunable-laser emulator on loopback TCP, for either command family of [`crate::hardware::laser`]:
//! the wavelength (an [`EmuLaser`] a photodiode closure may read), a continuous sweep running on the
//! emulator clock, the lambda log it keeps (one point per log step reached), `*IDN?`, an SCPI error
//! queue read by `:SYST:ERR?` (an unknown command queues -113 "Undefined header"), and fault
//! injection: [`Fault::DropConnection`], [`Fault::NoReply`], [`Fault::ErrorCode`] (queued, the
//! command ignored) and [`Fault::Limit`], which aborts a running sweep where it is.

use super::{EmuClock, EmuLaser, Fault, FaultSpec, Faults, Server, Trigger};
use crate::hardware::controller_bench::LaserFamily;
use crate::hardware::laser::scpi::encode_block;
use std::collections::VecDeque;
use std::io::{BufRead, BufReader, Write};
use std::net::{SocketAddr, TcpStream};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

/// The emulated laser's tuning range and limits.
#[derive(Debug, Clone)]
pub struct LaserEmulatorConfig {
    /// Command set.
    pub family: LaserFamily,
    /// Tuning range (nm).
    pub min_nm: f64,
    /// Tuning range (nm).
    pub max_nm: f64,
    /// Fastest sweep (nm/s).
    pub max_speed_nm_per_s: f64,
}

impl LaserEmulatorConfig {
    /// A C+L-band laser (1450-1650 nm, sweeps up to 200 nm/s) of `family`.
    pub fn new(family: LaserFamily) -> Self {
        LaserEmulatorConfig { family, min_nm: 1450.0, max_nm: 1650.0, max_speed_nm_per_s: 200.0 }
    }
}

/// A sweep: from, to (nm), speed (nm/s), log step (nm), started at `t0_s`, ended (done or aborted)
/// at `end_s`.
#[derive(Debug, Clone, Copy)]
struct Sweep {
    from: f64,
    to: f64,
    rate: f64,
    step: f64,
    t0_s: f64,
    end_s: f64,
}

impl Sweep {
    fn planned_end_s(&self) -> f64 {
        self.t0_s + (self.to - self.from).abs() / self.rate
    }

    /// The logged wavelengths (nm): every step reached before the sweep ended.
    fn log(&self) -> Vec<f64> {
        let total = ((self.to - self.from).abs() / self.step + 1e-6).floor() as usize + 1;
        let dir = (self.to - self.from).signum();
        (0..total)
            .take_while(|&k| self.t0_s + k as f64 * self.step / self.rate <= self.end_s + 1e-12)
            .map(|k| self.from + dir * k as f64 * self.step)
            .collect()
    }
}

struct State {
    config: LaserEmulatorConfig,
    /// Sweep settings: start, stop (nm), speed (nm/s), log step (nm), continuous mode set.
    start_nm: f64,
    stop_nm: f64,
    speed: f64,
    step: f64,
    continuous: bool,
    power_mw: f64,
    sweep: Option<Sweep>,
    errors: VecDeque<(i64, String)>,
    faults: Faults,
    /// A sweep abort armed for an emulated time ([`Fault::Limit`] at [`Trigger::AtTime`]).
    abort_at_s: Option<f64>,
}

struct Shared {
    laser: Arc<EmuLaser>,
    state: Mutex<State>,
}

/// A running laser emulator.
pub struct LaserEmulator {
    server: Server,
    shared: Arc<Shared>,
}

enum Reply {
    None,
    Text(String),
    Bytes(Vec<u8>),
    Drop,
}

/// Why a command fails: an SCPI error code and message.
type Scpi<T> = Result<T, (i64, &'static str)>;
const UNDEFINED_HEADER: (i64, &str) = (-113, "Undefined header");
const DATA_TYPE: (i64, &str) = (-104, "Data type error");
const OUT_OF_RANGE: (i64, &str) = (-222, "Data out of range");
const CONFLICT: (i64, &str) = (-221, "Settings conflict");

impl LaserEmulator {
    /// Start on `port` of 127.0.0.1 (0: any free port), driving `laser` (its clock is the
    /// emulator's; a photodiode closure may read its wavelength).
    pub fn start_on(port: u16, laser: Arc<EmuLaser>, config: LaserEmulatorConfig) -> std::io::Result<Self> {
        let state = State {
            config,
            start_nm: 1540.0,
            stop_nm: 1560.0,
            speed: 10.0,
            step: 0.001,
            continuous: false,
            power_mw: 1.0,
            sweep: None,
            errors: VecDeque::new(),
            faults: Faults::default(),
            abort_at_s: None,
        };
        let shared = Arc::new(Shared { laser, state: Mutex::new(state) });
        let s2 = shared.clone();
        let server = Server::start(port, move |stream| serve(&s2, stream))?;
        Ok(LaserEmulator { server, shared })
    }

    /// Start on an ephemeral port with a laser of its own at `nominal_nm` on `clock`.
    pub fn start(clock: Arc<EmuClock>, nominal_nm: f64, config: LaserEmulatorConfig) -> std::io::Result<Self> {
        Self::start_on(0, EmuLaser::new(clock, nominal_nm), config)
    }

    /// The address it listens on.
    pub fn addr(&self) -> SocketAddr {
        self.server.addr
    }

    /// The emulated laser (its wavelength at any time).
    pub fn laser(&self) -> Arc<EmuLaser> {
        self.shared.laser.clone()
    }

    /// Arm a fault. A [`Fault::Limit`] at a time aborts the sweep running at that time, at that
    /// time (seen from the next command on); at a command it aborts the sweep when that command comes.
    pub fn inject(&self, fault: FaultSpec) {
        let mut st = self.lock();
        match (&fault.trigger, &fault.fault) {
            (Trigger::AtTime(t), Fault::Limit) => st.abort_at_s = Some(*t),
            _ => st.faults.armed.push(fault),
        }
    }

    /// Faults that fired so far, with the command they fired on.
    pub fn fired(&self) -> Vec<(String, Fault)> {
        self.lock().faults.fired.clone()
    }

    /// True while a sweep runs.
    pub fn sweeping(&self) -> bool {
        let now = self.shared.laser.clock().now_s();
        self.lock().sweep.is_some_and(|s| now < s.end_s)
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, State> {
        self.shared.state.lock().unwrap_or_else(|e| e.into_inner())
    }
}

fn serve(shared: &Shared, stream: TcpStream) {
    let Ok(mut writer) = stream.try_clone() else { return };
    let mut reader = BufReader::new(stream);
    let mut line = Vec::new();
    loop {
        line.clear();
        match reader.read_until(b'\n', &mut line) {
            Ok(0) | Err(_) => return,
            Ok(_) => {}
        }
        let command = String::from_utf8_lossy(&line).trim().to_string();
        let bytes = match handle(shared, &command) {
            Reply::None => continue,
            Reply::Drop => {
                let _ = writer.shutdown(std::net::Shutdown::Both);
                return;
            }
            Reply::Text(t) => (t + "\n").into_bytes(),
            Reply::Bytes(mut b) => {
                b.push(b'\n');
                b
            }
        };
        if writer.write_all(&bytes).is_err() {
            return;
        }
    }
}

/// Run one command line: faults first, then the command; a failed command queues its error.
fn handle(shared: &Shared, command: &str) -> Reply {
    let now = shared.laser.clock().now_s();
    let mut st = shared.state.lock().unwrap_or_else(|e| e.into_inner());
    if let Some(t) = st.abort_at_s.filter(|&t| now >= t) {
        st.abort_at_s = None;
        st.faults.fired.push((command.to_string(), Fault::Limit));
        abort(shared, &mut st, t);
    }
    match st.faults.take(command, now) {
        Some(Fault::DropConnection) => return Reply::Drop,
        Some(Fault::NoReply) => return Reply::None,
        Some(Fault::ErrorCode(c)) => {
            st.errors.push_back((c, "Injected error".into()));
            return Reply::None;
        }
        Some(Fault::Limit) => abort(shared, &mut st, now),
        None => {}
    }
    if command.is_empty() {
        return Reply::None;
    }
    match execute(shared, &mut st, now, command) {
        Ok(r) => r,
        Err((code, message)) => {
            if st.errors.len() < 30 {
                st.errors.push_back((code, message.into()));
            }
            Reply::None
        }
    }
}

/// Stop a running sweep where it is at `at_s` (now, or an armed abort's time already passed).
fn abort(shared: &Shared, st: &mut State, at_s: f64) {
    if let Some(s) = st.sweep.as_mut().filter(|s| at_s < s.end_s && at_s >= s.t0_s) {
        s.end_s = at_s;
        let w = shared.laser.wavelength_at(at_s);
        let mut schedule = shared.laser.schedule.lock().unwrap_or_else(|e| e.into_inner());
        let k = schedule.partition_point(|e| e.0 <= at_s);
        schedule.insert(k, (at_s, w, w, 0.0));
    }
}

/// Known SCPI nodes, short form then long form: a node is either form or anything between.
const NODES: &[(&str, &str)] = &[
    ("SOUR", "SOURCE"),
    ("WAV", "WAVELENGTH"),
    ("SWE", "SWEEP"),
    ("STAR", "START"),
    ("STOP", "STOP"),
    ("SPE", "SPEED"),
    ("STEP", "STEP"),
    ("MODE", "MODE"),
    ("CYCL", "CYCLES"),
    ("LLOG", "LLOGGING"),
    ("READ", "READOUT"),
    ("POIN", "POINTS"),
    ("DATA", "DATA"),
    ("SYST", "SYSTEM"),
    ("ERR", "ERROR"),
    ("POW", "POWER"),
    ("UNIT", "UNIT"),
    ("TRIG", "TRIGGER"),
    ("OUTP", "OUTPUT"),
];

/// A header (`:SOURce0:WAVelength:SWEep?`) in short form without the source/trigger number
/// (`SOUR:WAV:SWE?`), or `None` for an unknown node.
pub fn normalize_header(header: &str) -> Option<String> {
    let upper = header.to_ascii_uppercase();
    let (path, query) = match upper.strip_suffix('?') {
        Some(p) => (p, "?"),
        None => (upper.as_str(), ""),
    };
    if path.starts_with('*') {
        return Some(upper.clone());
    }
    let mut out = Vec::new();
    for node in path.strip_prefix(':').unwrap_or(path).split(':') {
        let node = node.trim_end_matches(|c: char| c.is_ascii_digit());
        let short = NODES.iter().find(|(s, l)| node.starts_with(s) && l.starts_with(node))?.0;
        out.push(short);
    }
    Some(out.join(":") + query)
}

/// Run one well-formed command.
fn execute(shared: &Shared, st: &mut State, now: f64, command: &str) -> Scpi<Reply> {
    let (header, arg) = match command.split_once(char::is_whitespace) {
        Some((h, a)) => (h, a.trim()),
        None => (command, ""),
    };
    let key = normalize_header(header).ok_or(UNDEFINED_HEADER)?;
    let keysight = st.config.family == LaserFamily::Keysight;
    // The Keysight set addresses the laser as SOURce0 and its trigger as TRIGger0; the Santec set has no SOURce.
    let key = match key.strip_prefix("SOUR:") {
        Some(rest) if keysight => rest.to_string(),
        Some(_) => return Err(UNDEFINED_HEADER),
        None => key,
    };
    let text = |s: String| Ok(Reply::Text(s));
    match key.as_str() {
        "*IDN?" => text(identity(st.config.family).into()),
        "*CLS" => {
            st.errors.clear();
            Ok(Reply::None)
        }
        "SYST:ERR?" => {
            let (code, message) = st.errors.pop_front().unwrap_or((0, "No error".into()));
            text(if keysight { format!("{code:+},\"{message}\"") } else { format!("{code},\"{message}\"") })
        }
        "WAV?" => text(format!("{}", shared.laser.wavelength_at(now) / unit_nm(st))),
        "WAV" => {
            let nm = wavelength_arg(st, arg)?;
            if st.sweep.is_some_and(|s| now < s.end_s) {
                return Err(CONFLICT);
            }
            shared.laser.set(nm);
            Ok(Reply::None)
        }
        "POW" => {
            st.power_mw = number(arg.trim_end_matches("MW"))?;
            Ok(Reply::None)
        }
        "POW?" => text(format!("{}", st.power_mw)),
        "POW:UNIT" | "TRIG:OUTP" => Ok(Reply::None),
        "READ:POIN?" | "READ:DATA?" => log_readout(st, now, &key, arg),
        _ => sweep_command(shared, st, now, &key, arg),
    }
}

/// Sweep settings, start, stop and state.
fn sweep_command(shared: &Shared, st: &mut State, now: f64, key: &str, arg: &str) -> Scpi<Reply> {
    let keysight = st.config.family == LaserFamily::Keysight;
    match key {
        "WAV:SWE:STAR" => st.start_nm = wavelength_arg(st, arg)?,
        "WAV:SWE:STOP" => st.stop_nm = wavelength_arg(st, arg)?,
        "WAV:SWE:SPE" => {
            let v = number(arg)? * unit_nm(st);
            if !(v > 0.0 && v <= st.config.max_speed_nm_per_s) {
                return Err(OUT_OF_RANGE);
            }
            st.speed = v;
        }
        "WAV:SWE:STEP" if keysight => st.step = step_arg(st, arg)?,
        "TRIG:OUTP:STEP" if !keysight => st.step = step_arg(st, arg)?,
        "WAV:SWE:MODE" => {
            let want = if keysight { "CONT" } else { "1" };
            let long_form = keysight && arg.eq_ignore_ascii_case("CONTINUOUS");
            if !(arg.eq_ignore_ascii_case(want) || long_form) {
                return Err(OUT_OF_RANGE);
            }
            st.continuous = true;
        }
        "WAV:SWE:CYCL" | "WAV:SWE:LLOG" if keysight => {
            if arg != "1" {
                return Err(OUT_OF_RANGE);
            }
        }
        "WAV:SWE?" => {
            let running = st.sweep.is_some_and(|s| now < s.end_s);
            let v = u8::from(running);
            return Ok(Reply::Text(if keysight { format!("+{v}") } else { v.to_string() }));
        }
        "WAV:SWE" => match arg.to_ascii_uppercase().as_str() {
            "1" | "STAR" | "START" => {
                if !st.continuous || st.start_nm == st.stop_nm || st.sweep.is_some_and(|s| now < s.end_s) {
                    return Err(CONFLICT);
                }
                let (from, to, rate) = (st.start_nm, st.stop_nm, st.speed);
                let t0_s = shared.laser.sweep(from, to, rate);
                let mut s = Sweep { from, to, rate, step: st.step, t0_s, end_s: 0.0 };
                s.end_s = s.planned_end_s();
                st.sweep = Some(s);
            }
            "0" | "STOP" => abort(shared, st, now),
            _ => return Err(DATA_TYPE),
        },
        _ => return Err(UNDEFINED_HEADER),
    }
    Ok(Reply::None)
}

/// The lambda log of the last sweep: its number of points or its data as a binary block.
fn log_readout(st: &State, now: f64, key: &str, arg: &str) -> Scpi<Reply> {
    let keysight = st.config.family == LaserFamily::Keysight;
    if keysight != arg.eq_ignore_ascii_case("LLOG") && !(keysight && arg.eq_ignore_ascii_case("LLOGGING")) {
        return Err(DATA_TYPE);
    }
    let sweep = st.sweep.ok_or(CONFLICT)?;
    if now < sweep.end_s {
        return Err(CONFLICT);
    }
    let log = sweep.log();
    if key == "READ:POIN?" {
        return Ok(Reply::Text(if keysight { format!("+{}", log.len()) } else { log.len().to_string() }));
    }
    let data: Vec<u8> = if keysight {
        log.iter().flat_map(|nm| (nm * 1e-9).to_le_bytes()).collect()
    } else {
        log.iter().flat_map(|nm| ((nm * 1e4).round() as u32).to_le_bytes()).collect()
    };
    Ok(Reply::Bytes(encode_block(&data)))
}

fn identity(family: LaserFamily) -> &'static str {
    match family {
        LaserFamily::Santec => "SANTEC,TSL-570 (emulated),00000000,1.0",
        _ => "Keysight Technologies,8164B (emulated),MY00000000,V5.25(72637)",
    }
}

/// nm per unit of the family's wavelength arguments (metres or nm).
fn unit_nm(st: &State) -> f64 {
    if st.config.family == LaserFamily::Keysight {
        1e9
    } else {
        1.0
    }
}

fn number(s: &str) -> Scpi<f64> {
    s.trim().parse::<f64>().ok().filter(|v| v.is_finite()).ok_or(DATA_TYPE)
}

fn wavelength_arg(st: &State, arg: &str) -> Scpi<f64> {
    let nm = number(arg)? * unit_nm(st);
    if nm < st.config.min_nm || nm > st.config.max_nm {
        return Err(OUT_OF_RANGE);
    }
    Ok(nm)
}

fn step_arg(st: &State, arg: &str) -> Scpi<f64> {
    let nm = number(arg)? * unit_nm(st);
    if !(1e-4 - 1e-9..=10.0).contains(&nm) {
        return Err(OUT_OF_RANGE);
    }
    Ok(nm)
}

/// The family's usual raw-socket port: 5025 (Keysight), 5000 (Santec TSL-570).
pub fn default_port(family: LaserFamily) -> u16 {
    match family {
        LaserFamily::Santec => 5000,
        _ => 5025,
    }
}

/// Serve a laser emulator of `family` on 127.0.0.1:`port` (the family's default for `None`) on a
/// clock `time_scale` times faster than real time, resting at 1550 nm, until `stop` is set. `on_ready` gets the address once listening.
pub fn run_laser_emulator(
    family: LaserFamily,
    port: Option<u16>,
    time_scale: f64,
    stop: &AtomicBool,
    on_ready: &mut dyn FnMut(SocketAddr),
) -> std::io::Result<()> {
    let emu = LaserEmulator::start_on(
        port.unwrap_or(default_port(family)),
        EmuLaser::new(EmuClock::new(time_scale), 1550.0),
        LaserEmulatorConfig::new(family),
    )?;
    on_ready(emu.addr());
    while !stop.load(Ordering::Relaxed) {
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn headers_normalize_to_short_forms() {
        assert_eq!(normalize_header(":SOURce0:WAVelength:SWEep?").as_deref(), Some("SOUR:WAV:SWE?"));
        assert_eq!(normalize_header(":READout:POINts?").as_deref(), Some("READ:POIN?"));
        assert_eq!(normalize_header(":TRIG0:OUTP").as_deref(), Some("TRIG:OUTP"));
        assert_eq!(normalize_header(":WAVX"), None);
    }

    proptest! {
        /// Any command line leaves the emulator answering (no panic, no poisoned lock).
        #[test]
        fn arbitrary_command_lines_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..48)) {
            let laser = EmuLaser::new(EmuClock::new(1.0), 1550.0);
            let shared = Shared {
                laser,
                state: Mutex::new(State {
                    config: LaserEmulatorConfig::new(LaserFamily::Santec),
                    start_nm: 1540.0, stop_nm: 1560.0, speed: 10.0, step: 0.001, continuous: false,
                    power_mw: 1.0, sweep: None, errors: VecDeque::new(), faults: Faults::default(),
                    abort_at_s: None,
                }),
            };
            let line = String::from_utf8_lossy(&bytes).trim().to_string();
            let _ = handle(&shared, &line);
            let _ = normalize_header(&line);
            prop_assert!(matches!(handle(&shared, "*IDN?"), Reply::Text(_)));
        }
    }
}
