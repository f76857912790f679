//! Tunable-laser emulator on loopback TCP, for either command family of [`crate::hardware::laser`]:
//! the wavelength (an [`EmuLaser`] a photodiode closure may read), `*IDN?`, an SCPI error queue
//! read by `:SYST:ERR?`, the sweep ([`sweep`]), and fault injection:
//! [`Fault::DropConnection`], [`Fault::NoReply`], [`Fault::ErrorCode`] (queued, the command ignored)
//! and [`Fault::Limit`], which aborts a running sweep where it is.
//!
//! As strict as the manuals describe the instruments (see `crate::hardware::laser::keysight` and
//! `santec`): numbers with unit suffixes (Keysight's units table), the Santec's two command sets
//! (it starts in SCPI: metres and 8-byte logs; Legacy: nm and 0.1 pm integers) and its CR-ended
//! replies with no terminator after a binary block, and a Keysight that starts with amplitude
//! modulation on and its trigger output off.

mod sweep;

use super::emu_laser::{EmuLaser, SweepProfile};
use super::{take_fault, EmuClock, Fault, FaultSpec, Faults, Server, Trigger};
use crate::hardware::controller_bench::LaserFamily;
use std::collections::VecDeque;
use std::io::{BufRead, BufReader, Write};
use std::net::{SocketAddr, TcpStream};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use sweep::Sweep;

/// What the emulated laser does that an ideal one would not.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LaserRealism {
    /// Start latency and acceleration of a sweep.
    pub profile: SweepProfile,
    /// From the end of a sweep to its lambda log being ready (s; Keysight `FLAG?` turns 2).
    pub post_processing_s: f64,
}

impl LaserRealism {
    /// As slow as an instrument: tens of ms to start, a run-up at 1000 nm/s², a log ready 50 ms
    /// after the sweep (emulator assumptions, to be measured on the device).
    pub fn realistic(family: LaserFamily) -> Self {
        let latency_s = if family == LaserFamily::Santec { 0.06 } else { 0.04 };
        LaserRealism { profile: SweepProfile { latency_s, accel_nm_per_s2: 1000.0 }, post_processing_s: 0.05 }
    }

    /// A sweep that starts at once at full speed, its log ready at its end.
    pub fn ideal() -> Self {
        LaserRealism { profile: SweepProfile::INSTANT, post_processing_s: 0.0 }
    }
}

/// The emulated laser's tuning range and limits.
#[derive(Debug, Clone)]
pub struct LaserEmulatorConfig {
    /// Command set.
    pub family: LaserFamily,
    /// Tuning range (nm).
    pub min_nm: f64,
    /// Tuning range (nm).
    pub max_nm: f64,
    /// Slowest sweep (nm/s; Keysight `:WAV:SWE:SPE? MIN`).
    pub min_speed_nm_per_s: f64,
    /// Fastest sweep (nm/s; Keysight `:WAV:SWE:SPE? MAX`).
    pub max_speed_nm_per_s: f64,
    /// What is not ideal.
    pub realism: LaserRealism,
}

impl LaserEmulatorConfig {
    /// A C+L-band laser (1450-1650 nm) of `family`, realistic; Keysight sweeps 0.5 to 80 nm/s
    /// (an 81600B-like module; assumed), Santec at its eight speeds.
    pub fn new(family: LaserFamily) -> Self {
        LaserEmulatorConfig {
            family,
            min_nm: 1450.0,
            max_nm: 1650.0,
            min_speed_nm_per_s: 0.5,
            max_speed_nm_per_s: if family == LaserFamily::Santec { 200.0 } else { 80.0 },
            realism: LaserRealism::realistic(family),
        }
    }

    /// The same laser without latency or run-up.
    pub fn ideal(family: LaserFamily) -> Self {
        LaserEmulatorConfig { realism: LaserRealism::ideal(), ..Self::new(family) }
    }
}

/// The laser's settings and state.
pub(super) struct State {
    pub(super) config: LaserEmulatorConfig,
    pub(super) start_nm: f64,
    pub(super) stop_nm: f64,
    pub(super) speed: f64,
    pub(super) step: f64,
    /// Keysight `:WAV:SWE:MODE CONT` / Santec `:WAV:SWE:MOD` 1 or 3.
    pub(super) continuous: bool,
    /// Keysight `:WAV:SWE:REP TWOW` / Santec mode 3.
    pub(super) two_way: bool,
    /// Keysight `:AM:STAT`.
    pub(super) modulation: bool,
    /// Trigger output mode: Keysight `STF` etc., Santec `0`..`3`.
    pub(super) trigger_out: String,
    /// Keysight `:WAV:SWE:LLOG`.
    pub(super) lambda_logging: bool,
    /// Santec `:SYST:COMM:COD 1` (SCPI: metres); Keysight always speaks SCPI.
    pub(super) scpi_units: bool,
    power_mw: f64,
    pub(super) sweep: Option<Sweep>,
    errors: VecDeque<(i64, String)>,
    faults: Faults,
    /// A sweep abort armed for an emulated time ([`Fault::Limit`] at [`Trigger::AtTime`]).
    abort_at_s: Option<f64>,
}

impl State {
    fn new(config: LaserEmulatorConfig) -> Self {
        let keysight = config.family == LaserFamily::Keysight;
        State {
            config,
            start_nm: 1540.0,
            stop_nm: 1560.0,
            speed: 10.0,
            step: 0.001,
            continuous: false,
            two_way: false,
            modulation: keysight,
            trigger_out: if keysight { "DIS".into() } else { "0".into() },
            lambda_logging: false,
            scpi_units: true,
            power_mw: 1.0,
            sweep: None,
            errors: VecDeque::new(),
            faults: Faults::default(),
            abort_at_s: None,
        }
    }

    pub(super) fn keysight(&self) -> bool {
        self.config.family == LaserFamily::Keysight
    }
}

pub(super) struct Shared {
    pub(super) laser: Arc<EmuLaser>,
    state: Mutex<State>,
}

/// A running laser emulator.
pub struct LaserEmulator {
    server: Server,
    shared: Arc<Shared>,
}

pub(super) enum Reply {
    None,
    Text(String),
    Bytes(Vec<u8>),
    Drop,
}

/// Why a command fails: an SCPI error code and message.
pub(super) type Scpi<T> = Result<T, (i64, &'static str)>;
pub(super) const UNDEFINED_HEADER: (i64, &str) = (-113, "Undefined header");
pub(super) const DATA_TYPE: (i64, &str) = (-104, "Data type error");
pub(super) const OUT_OF_RANGE: (i64, &str) = (-222, "Data out of range");
pub(super) const CONFLICT: (i64, &str) = (-221, "Settings conflict");

impl LaserEmulator {
    /// Start on `port` of 127.0.0.1 (0: any free port), driving `laser` (its clock is the
    /// emulator's; a photodiode closure may read its wavelength).
    pub fn start_on(port: u16, laser: Arc<EmuLaser>, config: LaserEmulatorConfig) -> std::io::Result<Self> {
        let shared = Arc::new(Shared { laser, state: Mutex::new(State::new(config)) });
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
        self.lock().sweep.is_some_and(|s| now < s.busy_until_s)
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, State> {
        self.shared.state.lock().unwrap_or_else(|e| e.into_inner())
    }
}

fn serve(shared: &Shared, stream: TcpStream) {
    let Ok(mut writer) = stream.try_clone() else { return };
    let santec = shared.state.lock().unwrap_or_else(|e| e.into_inner()).config.family == LaserFamily::Santec;
    let mut reader = BufReader::new(stream);
    let mut line = Vec::new();
    loop {
        line.clear();
        // Commands end with LF, CR or CR LF.
        match read_until_either(&mut reader, &mut line) {
            Ok(0) | Err(_) => return,
            Ok(_) => {}
        }
        let command = String::from_utf8_lossy(&line).trim().to_string();
        if command.is_empty() {
            continue;
        }
        let end: &[u8] = if santec { b"\r" } else { b"\n" };
        let bytes = match handle(shared, &command) {
            Reply::None => continue,
            Reply::Drop => {
                let _ = writer.shutdown(std::net::Shutdown::Both);
                return;
            }
            Reply::Text(t) => [t.as_bytes(), end].concat(),
            // The Santec sends its block with no terminator after it (QMI reads it so).
            Reply::Bytes(b) if santec => b,
            Reply::Bytes(b) => [b.as_slice(), end].concat(),
        };
        if writer.write_all(&bytes).is_err() {
            return;
        }
    }
}

/// Read up to and including the first CR or LF.
fn read_until_either(reader: &mut impl BufRead, out: &mut Vec<u8>) -> std::io::Result<usize> {
    let mut read = 0;
    loop {
        let available = reader.fill_buf()?;
        if available.is_empty() {
            return Ok(read);
        }
        match available.iter().position(|&b| b == b'\n' || b == b'\r') {
            Some(i) => {
                out.extend_from_slice(&available[..i]);
                reader.consume(i + 1);
                return Ok(read + i + 1);
            }
            None => {
                let n = available.len();
                out.extend_from_slice(available);
                reader.consume(n);
                read += n;
            }
        }
    }
}

/// Run one command line: faults first, then the command; a failed command queues its error.
fn handle(shared: &Shared, command: &str) -> Reply {
    let (mut st, now, fired) = take_fault(&shared.state, |s| &mut s.faults, || shared.laser.clock().now_s(), command);
    if let Some(t) = st.abort_at_s.filter(|&t| now >= t) {
        st.abort_at_s = None;
        st.faults.fired.push((command.to_string(), Fault::Limit));
        sweep::abort(shared, &mut st, t);
    }
    match fired {
        Some(Fault::DropConnection) => return Reply::Drop,
        Some(Fault::NoReply) => return Reply::None,
        Some(Fault::ErrorCode(c)) => {
            st.errors.push_back((c, "Injected error".into()));
            return Reply::None;
        }
        Some(Fault::Limit) => sweep::abort(shared, &mut st, now),
        Some(Fault::Delay(_)) | None => {}
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

/// Known SCPI nodes, short form then long form: a node is either form or anything between.
const NODES: &[(&str, &str)] = &[
    ("SOUR", "SOURCE"),
    ("WAV", "WAVELENGTH"),
    ("SWE", "SWEEP"),
    ("STAR", "START"),
    ("STOP", "STOP"),
    ("SPE", "SPEED"),
    ("STEP", "STEP"),
    ("MOD", "MODE"),
    ("CYCL", "CYCLES"),
    ("LLOG", "LLOGGING"),
    ("REP", "REPEAT"),
    ("CHEC", "CHECKPARAMS"),
    ("FLAG", "FLAG"),
    ("STAT", "STATE"),
    ("READ", "READOUT"),
    ("POIN", "POINTS"),
    ("DATA", "DATA"),
    ("SYST", "SYSTEM"),
    ("COMM", "COMMUNICATE"),
    ("COD", "CODE"),
    ("ERR", "ERROR"),
    ("POW", "POWER"),
    ("UNIT", "UNIT"),
    ("AM", "AM"),
    ("TRIG", "TRIGGER"),
    ("OUTP", "OUTPUT"),
];

/// A header (`:SOURce0:WAVelength:SWEep?`) in short form without the source/trigger number
/// (`SOUR:WAV:SWE?`), the optional `:STATe` of the sweep dropped, or `None` for an unknown node.
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
    let joined = out.join(":");
    let joined = joined.strip_suffix(":SWE:STAT").map_or(joined.clone(), |p| format!("{p}:SWE"));
    Some(joined + query)
}

/// A number with an optional unit suffix, in nm (wavelengths, `per_s` false) or nm/s (`per_s`
/// true): the Keysight guide's "Units and allowed Mnemonics" (PM, NM, UM, MM, M; NM/S, UM/S,
/// MM/S, M/S), unitless values in `default_nm` nm per unit.
pub(super) fn quantity(arg: &str, default_nm: f64, per_s: bool) -> Scpi<f64> {
    let arg = arg.trim().to_ascii_uppercase();
    let split = arg.find(|c: char| c.is_ascii_alphabetic() && c != 'E').unwrap_or(arg.len());
    let (number, unit) = arg.split_at(split);
    let unit = unit.trim();
    let scale = match (unit, per_s) {
        ("", _) => default_nm,
        ("PM", false) => 1e-3,
        ("NM", false) | ("NM/S", true) => 1.0,
        ("UM", false) | ("UM/S", true) => 1e3,
        ("MM", false) | ("MM/S", true) => 1e6,
        ("M", false) | ("M/S", true) => 1e9,
        _ => return Err(DATA_TYPE),
    };
    number.trim().parse::<f64>().ok().filter(|v| v.is_finite()).map(|v| v * scale).ok_or(DATA_TYPE)
}

/// nm per unitless wavelength argument or reply: metres for Keysight and the Santec SCPI set.
pub(super) fn unit_nm(st: &State) -> f64 {
    if st.scpi_units {
        1e9
    } else {
        1.0
    }
}

pub(super) fn wavelength_arg(st: &State, arg: &str) -> Scpi<f64> {
    let nm = quantity(arg, unit_nm(st), false)?;
    if nm < st.config.min_nm || nm > st.config.max_nm {
        return Err(OUT_OF_RANGE);
    }
    Ok(nm)
}

fn identity(family: LaserFamily) -> &'static str {
    match family {
        LaserFamily::Santec => "SANTEC,TSL-570 (emulated),00000000,1.0",
        _ => "Keysight Technologies,8164B (emulated),MY00000000,V5.25(72637)",
    }
}

/// Run one well-formed command.
fn execute(shared: &Shared, st: &mut State, now: f64, command: &str) -> Scpi<Reply> {
    let (header, arg) = match command.split_once(char::is_whitespace) {
        Some((h, a)) => (h, a.trim()),
        None => (command, ""),
    };
    let key = normalize_header(header).ok_or(UNDEFINED_HEADER)?;
    let keysight = st.keysight();
    // The Keysight set addresses the laser as SOURce0 and its trigger as TRIGger0; the Santec set has no SOURce.
    let key = match key.strip_prefix("SOUR:") {
        Some(rest) if keysight => rest.to_string(),
        Some(_) => return Err(UNDEFINED_HEADER),
        None => key,
    };
    let text = |s: String| Ok(Reply::Text(s));
    let bool_word = |arg: &str| match arg.to_ascii_uppercase().as_str() {
        "1" | "ON" => Ok(true),
        "0" | "OFF" => Ok(false),
        _ => Err(DATA_TYPE),
    };
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
        "SYST:COMM:COD" if !keysight => {
            st.scpi_units = bool_word(arg)?;
            Ok(Reply::None)
        }
        "SYST:COMM:COD?" if !keysight => text(u8::from(st.scpi_units).to_string()),
        "WAV?" => text(format!("{}", shared.laser.wavelength_at(now) / unit_nm(st))),
        "WAV" => {
            let nm = wavelength_arg(st, arg)?;
            if sweep::busy(st, now) {
                return Err(CONFLICT);
            }
            shared.laser.set(nm);
            Ok(Reply::None)
        }
        "POW" => {
            st.power_mw = quantity(arg.trim_end_matches(|c: char| c.is_ascii_alphabetic()), 1.0, false)?;
            Ok(Reply::None)
        }
        "POW?" => text(format!("{}", st.power_mw)),
        "POW:UNIT" => Ok(Reply::None),
        "AM:STAT" if keysight => {
            st.modulation = bool_word(arg)?;
            Ok(Reply::None)
        }
        "AM:STAT?" if keysight => text(u8::from(st.modulation).to_string()),
        "TRIG:OUTP" => {
            let ok = if keysight {
                ["DIS", "AVG", "MEAS", "MOD", "STF", "SWF", "SWST"].contains(&arg.to_ascii_uppercase().as_str())
            } else {
                ["0", "1", "2", "3"].contains(&arg)
            };
            if !ok {
                return Err(DATA_TYPE);
            }
            st.trigger_out = arg.to_ascii_uppercase();
            Ok(Reply::None)
        }
        "TRIG:OUTP?" => text(st.trigger_out.clone()),
        "READ:POIN?" | "READ:DATA?" => sweep::log_readout(st, now, &key, arg),
        _ => sweep::command(shared, st, now, &key, arg),
    }
}

/// The family's usual raw-socket port: 5025 (Keysight), 5000 (Santec TSL-570).
pub fn default_port(family: LaserFamily) -> u16 {
    match family {
        LaserFamily::Santec => 5000,
        _ => 5025,
    }
}

/// Serve a laser emulator of `family` on 127.0.0.1:`port` (the family's default for `None`) on a
/// clock `time_scale` times faster than real time, resting at 1550 nm, realistic or ideal, until
/// `stop` is set. `on_ready` gets the address once listening.
pub fn run_laser_emulator(
    family: LaserFamily,
    port: Option<u16>,
    time_scale: f64,
    realistic: bool,
    stop: &AtomicBool,
    on_ready: &mut dyn FnMut(SocketAddr),
) -> std::io::Result<()> {
    let config = if realistic { LaserEmulatorConfig::new(family) } else { LaserEmulatorConfig::ideal(family) };
    let emu = LaserEmulator::start_on(
        port.unwrap_or(default_port(family)),
        EmuLaser::new(EmuClock::new(time_scale), 1550.0),
        config,
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
        assert_eq!(normalize_header(":WAV:SWE:STAT?").as_deref(), Some("WAV:SWE?"));
        assert_eq!(normalize_header(":READout:POINts?").as_deref(), Some("READ:POIN?"));
        assert_eq!(normalize_header(":TRIG0:OUTP").as_deref(), Some("TRIG:OUTP"));
        assert_eq!(normalize_header(":WAVX"), None);
    }

    #[test]
    fn numbers_take_the_units_of_the_keysight_table() {
        assert_eq!(quantity("1555.5NM", 1e9, false), Ok(1555.5));
        assert!((quantity("1.5555E-6", 1e9, false).unwrap() - 1555.5).abs() < 1e-9);
        assert!((quantity("1.5555um", 1e9, false).unwrap() - 1555.5).abs() < 1e-9);
        assert_eq!(quantity("10NM/S", 1e9, true), Ok(10.0));
        assert_eq!(quantity("10NM/S", 1e9, false), Err(DATA_TYPE));
        assert_eq!(quantity("10 furlongs", 1e9, false), Err(DATA_TYPE));
    }

    proptest! {
        /// Any command line leaves the emulator answering (no panic, no poisoned lock).
        #[test]
        fn arbitrary_command_lines_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..48)) {
            for family in [LaserFamily::Santec, LaserFamily::Keysight] {
                let shared = Shared {
                    laser: EmuLaser::new(EmuClock::new(1.0), 1550.0),
                    state: Mutex::new(State::new(LaserEmulatorConfig::new(family))),
                };
                let line = String::from_utf8_lossy(&bytes).trim().to_string();
                let _ = handle(&shared, &line);
                let _ = normalize_header(&line);
                prop_assert!(matches!(handle(&shared, "*IDN?"), Reply::Text(_)));
            }
        }
    }
}
