//! Protocol emulators of the PI E-712, the SmarAct MCS and MCS2 and the tunable lasers on loopback
//! TCP: stage state, finite-speed motion on a (time-scaled) clock, a photodiode fed by a closure,
//! and fault injection; as strict and as imperfect as the instruments by default.
//! Owns what the drivers are tested against; [`run_emulator`] serves one from the command line.
//!
//! Motion is analytic: every axis keeps the history of its moves (trapezoidal profiles), so its
//! position at any past time is exact. The PI data recorder therefore computes its samples when they
//! are read, at their own sample times, and a photodiode closure can ask any emulator where its axes
//! were at that time.

pub mod adc;
pub mod emu_laser;
pub mod laser;
pub mod local;
pub mod mcs2;
pub mod optical_bench;
pub mod pi;
pub mod smaract;

pub use crate::hardware::clock::EmuClock;
use crate::hardware::controller_bench::Laser;
use crate::hardware::HwError;
use crate::plan::TrapezoidProfile;
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

pub use emu_laser::{EmuLaser, SweepProfile};
pub use laser::{LaserEmulator, LaserEmulatorConfig, LaserRealism};
pub use local::{EmulatedHardware, LocalEmulators};
pub use mcs2::{Mcs2Emulator, Mcs2EmulatorConfig};
pub use pi::{PiEmulator, PiEmulatorConfig, PiRealism};
pub use smaract::{SmarActEmulator, SmarActEmulatorConfig};

/// One move of an axis: from `from` at `t0_s` to `to`, trapezoidal.
#[derive(Debug, Clone, Copy)]
struct Move {
    t0_s: f64,
    from: f64,
    to: f64,
    profile: TrapezoidProfile,
}

impl Move {
    fn at(&self, t_s: f64) -> f64 {
        let s = self.profile.fraction_at(t_s - self.t0_s);
        if s >= 1.0 {
            self.to
        } else {
            self.from + s * (self.to - self.from)
        }
    }

    fn end_s(&self) -> f64 {
        self.t0_s + self.profile.duration_s
    }
}

/// An emulated axis: its travel range, speed, acceleration and the history of its moves.
#[derive(Debug, Clone)]
pub struct EmuAxis {
    /// Travel range (controller units).
    pub min: f64,
    /// Travel range (controller units).
    pub max: f64,
    /// Speed (controller units per s).
    pub speed: f64,
    /// Acceleration (controller units per s²).
    pub accel: f64,
    /// Referenced (absolute position known).
    pub referenced: bool,
    /// The axis stopped short of its target (limit); cleared by the next move.
    pub at_limit: bool,
    history: Vec<Move>,
}

impl EmuAxis {
    /// An axis at `position`, not moving.
    pub fn new(position: f64, min: f64, max: f64, speed: f64, accel: f64) -> Self {
        EmuAxis {
            min,
            max,
            speed,
            accel,
            referenced: true,
            at_limit: false,
            history: vec![Move {
                t0_s: f64::NEG_INFINITY,
                from: position,
                to: position,
                profile: TrapezoidProfile::INSTANT,
            }],
        }
    }

    fn current(&self, t_s: f64) -> &Move {
        let k = self.history.partition_point(|m| m.t0_s <= t_s);
        &self.history[k.saturating_sub(1)]
    }

    /// Position at emulated time `t_s` (past or present).
    pub fn position_at(&self, t_s: f64) -> f64 {
        self.current(t_s).at(t_s)
    }

    /// The target of the move running (or last run) at `t_s`.
    pub fn target_at(&self, t_s: f64) -> f64 {
        self.current(t_s).to
    }

    /// True while a move runs at `t_s`.
    pub fn moving_at(&self, t_s: f64) -> bool {
        t_s < self.current(t_s).end_s()
    }

    /// Start a move to `target` at `t_s`, from wherever the axis is.
    pub fn start_move(&mut self, t_s: f64, target: f64) {
        let from = self.position_at(t_s);
        let d = (target - from).abs();
        let profile =
            if d == 0.0 { TrapezoidProfile::INSTANT } else { TrapezoidProfile::new(self.speed / d, self.accel / d) };
        self.at_limit = false;
        self.push(Move { t0_s: t_s, from, to: target, profile });
    }

    /// Stop now where the axis is.
    pub fn stop(&mut self, t_s: f64) {
        let p = self.position_at(t_s);
        self.push(Move { t0_s: t_s, from: p, to: p, profile: TrapezoidProfile::INSTANT });
    }

    fn push(&mut self, m: Move) {
        // Later moves replace any recorded after t0 (never happens with a monotonic clock).
        let k = self.history.partition_point(|h| h.t0_s <= m.t0_s);
        self.history.truncate(k);
        self.history.push(m);
        // Keep the history bounded: the oldest moves are not needed after an hour of emulated time.
        if self.history.len() > 100_000 {
            self.history.drain(..50_000);
        }
    }
}

/// Axes shared between an emulator and whoever needs their positions (a photodiode closure).
pub type SharedAxes = Arc<Mutex<Vec<EmuAxis>>>;

/// The acceleration of a channel whose acceleration control is off (controller units/s²): it
/// runs at its speed from the start of a move, a ramp.
pub(crate) const NO_ACCELERATION_CONTROL: f64 = 1e18;

/// The photodiode signal at emulated time `t_s` (controller input units).
pub type PhotodiodeFn = Arc<dyn Fn(f64) -> f64 + Send + Sync>;

/// What goes wrong.
#[derive(Debug, Clone, PartialEq)]
pub enum Fault {
    /// Close the connection without replying.
    DropConnection,
    /// Swallow the command: no reply, the connection stays open.
    NoReply,
    /// Refuse the command with this controller error code (GCS error number, MCS error code).
    ErrorCode(i64),
    /// Every moving axis stops where it is, on a limit (PI: error 216 pending; MCS: stopped short).
    Limit,
    /// The command is taken this long (s, real time) after it arrives, as on a busy host or
    /// network: a move starts that much later, a query reads the state then.
    Delay(f64),
}

/// When it goes wrong.
#[derive(Debug, Clone, PartialEq)]
pub enum Trigger {
    /// At the `(skip + 1)`-th command starting with `prefix` from now on.
    Command {
        /// Command prefix, e.g. "MOV", "ONT?", ":GS".
        prefix: String,
        /// Matching commands let through first.
        skip: usize,
    },
    /// At the `(skip + 1)`-th command starting with the last of `steps`, once commands starting
    /// with each of the others have been seen in order (other commands may come between). Pins a
    /// fault to a point of a step: `["DRT", "ONT?"]` is "the 1st `ONT?` after the recorder is armed".
    Sequence {
        /// Command prefixes, in order.
        steps: Vec<String>,
        /// Matching commands of the last step let through first.
        skip: usize,
    },
    /// At the first command received at or after this emulated time (s).
    AtTime(f64),
}

/// A fault armed in an emulator; it fires once.
#[derive(Debug, Clone, PartialEq)]
pub struct FaultSpec {
    /// When.
    pub trigger: Trigger,
    /// What.
    pub fault: Fault,
}

impl FaultSpec {
    /// `fault` at the `(skip + 1)`-th command starting with `prefix`.
    pub fn on_command(prefix: &str, skip: usize, fault: Fault) -> Self {
        FaultSpec { trigger: Trigger::Command { prefix: prefix.into(), skip }, fault }
    }

    /// `fault` at a point of a sequence of commands ([`Trigger::Sequence`]).
    pub fn after(steps: &[&str], skip: usize, fault: Fault) -> Self {
        FaultSpec { trigger: Trigger::Sequence { steps: steps.iter().map(|s| s.to_string()).collect(), skip }, fault }
    }
}

/// Pending faults of an emulator; `take` returns the fault that fires at this command, if any.
#[derive(Debug, Default)]
pub(crate) struct Faults {
    armed: Vec<FaultSpec>,
    /// Faults that fired, with the command they fired on (for tests).
    pub fired: Vec<(String, Fault)>,
}

/// A matching trigger fires once its `skip` count of earlier matches is used up.
fn count_down(skip: &mut usize) -> bool {
    if *skip == 0 {
        true
    } else {
        *skip -= 1;
        false
    }
}

impl Faults {
    pub(crate) fn take(&mut self, command: &str, now_s: f64) -> Option<Fault> {
        let mut hit = None;
        for (i, f) in self.armed.iter_mut().enumerate() {
            let fires = match &mut f.trigger {
                Trigger::Command { prefix, skip } => command.starts_with(prefix.as_str()) && count_down(skip),
                Trigger::Sequence { steps, skip } => {
                    if steps.len() > 1 {
                        if command.starts_with(steps[0].as_str()) {
                            steps.remove(0);
                        }
                        false
                    } else {
                        steps.first().is_some_and(|p| command.starts_with(p.as_str())) && count_down(skip)
                    }
                }
                Trigger::AtTime(t) => now_s >= *t,
            };
            if fires && hit.is_none() {
                hit = Some(i);
            }
        }
        let f = self.armed.remove(hit?);
        self.fired.push((command.to_string(), f.fault.clone()));
        Some(f.fault)
    }
}

/// The emulator's state locked for `command`, the emulated time it is taken at, and the fault it
/// meets. A [`Fault::Delay`] is served here (the lock released while the thread sleeps): the
/// command then runs as if it had just arrived, without a fault.
pub(crate) fn take_fault<'a, S>(
    state: &'a Mutex<S>,
    faults: impl Fn(&mut S) -> &mut Faults,
    now_s: impl Fn() -> f64,
    command: &str,
) -> (std::sync::MutexGuard<'a, S>, f64, Option<Fault>) {
    let lock = || state.lock().unwrap_or_else(|e| e.into_inner());
    let now = now_s();
    let mut st = lock();
    match faults(&mut st).take(command, now) {
        Some(Fault::Delay(s)) => {
            drop(st);
            std::thread::sleep(std::time::Duration::from_secs_f64(s.max(0.0)));
            (lock(), now_s(), None)
        }
        fired => (st, now, fired),
    }
}

/// A running TCP server: accepts connections on loopback and serves each on its own thread.
pub(crate) struct Server {
    pub addr: SocketAddr,
    stop: Arc<AtomicBool>,
    /// The open connections, closed when the server stops (a stopped emulator answers no one).
    connections: Arc<Mutex<Vec<TcpStream>>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Server {
    pub(crate) fn start<F>(port: u16, serve: F) -> std::io::Result<Self>
    where
        F: Fn(TcpStream) + Send + Sync + 'static,
    {
        let listener = TcpListener::bind(("127.0.0.1", port))?;
        listener.set_nonblocking(true)?;
        let addr = listener.local_addr()?;
        let stop = Arc::new(AtomicBool::new(false));
        let stop2 = stop.clone();
        let serve = Arc::new(serve);
        let connections = Arc::new(Mutex::new(Vec::<TcpStream>::new()));
        let open = connections.clone();
        let thread = std::thread::spawn(move || {
            while !stop2.load(Ordering::Relaxed) {
                match listener.accept() {
                    Ok((stream, _)) => {
                        let _ = stream.set_nonblocking(false);
                        let _ = stream.set_nodelay(true);
                        if let Ok(mut open) = open.lock() {
                            // Forget connections that are gone, so the list does not grow.
                            open.retain(|s| s.peer_addr().is_ok());
                            if let Ok(s) = stream.try_clone() {
                                open.push(s);
                            }
                        }
                        let serve = serve.clone();
                        std::thread::spawn(move || serve(stream));
                    }
                    Err(_) => std::thread::sleep(std::time::Duration::from_millis(1)),
                }
            }
        });
        Ok(Server { addr, stop, connections, thread: Some(thread) })
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        for s in self.connections.lock().unwrap_or_else(|e| e.into_inner()).drain(..) {
            let _ = s.shutdown(std::net::Shutdown::Both);
        }
    }
}

/// The emulated laser ([`EmuLaser`]) as a [`Laser`].
pub struct EmulatedLaser {
    laser: Arc<EmuLaser>,
    nominal_nm: f64,
}

impl EmulatedLaser {
    /// Drive `laser`, whose resting wavelength is `nominal_nm`.
    pub fn new(laser: Arc<EmuLaser>, nominal_nm: f64) -> Self {
        EmulatedLaser { laser, nominal_nm }
    }
}

impl Laser for EmulatedLaser {
    fn nominal_nm(&self) -> f64 {
        self.nominal_nm
    }
    fn set_wavelength(&mut self, nm: f64) -> Result<(), HwError> {
        self.laser.set(nm);
        Ok(())
    }
    fn start_sweep(&mut self, from_nm: f64, to_nm: f64, rate_nm_per_s: f64) -> Result<(), HwError> {
        self.laser.sweep(from_nm, to_nm, rate_nm_per_s);
        Ok(())
    }
}

/// Which emulator to run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EmulatorKind {
    /// PI E-712 (GCS 2), default port 50000.
    Pi,
    /// SmarAct MCS (ASCII), default port 5000.
    SmarAct,
    /// SmarAct MCS2 (ASCII, SCPI-like), default port 55551.
    Mcs2,
}

impl EmulatorKind {
    /// "pi" or "smaract".
    pub fn parse(text: &str) -> Option<Self> {
        match text.to_ascii_lowercase().as_str() {
            "pi" | "e-712" | "e712" => Some(EmulatorKind::Pi),
            "smaract" | "mcs" => Some(EmulatorKind::SmarAct),
            "mcs2" => Some(EmulatorKind::Mcs2),
            _ => None,
        }
    }

    /// The controller's default TCP port.
    pub fn default_port(self) -> u16 {
        match self {
            EmulatorKind::Pi => super::pi_gcs::DEFAULT_PORT,
            EmulatorKind::SmarAct => super::smaract::DEFAULT_PORT,
            EmulatorKind::Mcs2 => super::smaract_mcs2::DEFAULT_PORT,
        }
    }
}

/// Serve an emulator of `kind` on 127.0.0.1:`port` (the default port for `None`) on a clock
/// `time_scale` times faster than real time (1: real time), realistic or ideal, with
/// the femto-6dof bench's axes, until `stop` is set. `on_ready` gets the address once listening.
/// The PI emulator's photodiode input reads a slow test signal (a sine of its first axis, volts).
pub fn run_emulator(
    kind: EmulatorKind,
    port: Option<u16>,
    time_scale: f64,
    realistic: bool,
    stop: &AtomicBool,
    on_ready: &mut dyn FnMut(SocketAddr),
) -> std::io::Result<()> {
    let clock = EmuClock::new(time_scale);
    let port = port.unwrap_or(kind.default_port());
    match kind {
        EmulatorKind::Pi => {
            let config = if realistic { PiEmulatorConfig::default() } else { PiEmulatorConfig::ideal() };
            let emu = PiEmulator::start_on(port, clock, config)?;
            let axes = emu.axes();
            emu.set_photodiode(Arc::new(move |t| {
                let x = axes.lock().map(|a| a.first().map_or(0.0, |a| a.position_at(t))).unwrap_or(0.0);
                2.5 + 1.0 * (x * 2.0 * std::f64::consts::PI / 0.78).cos()
            }));
            on_ready(emu.addr());
            while !stop.load(Ordering::Relaxed) {
                std::thread::sleep(std::time::Duration::from_millis(50));
            }
        }
        EmulatorKind::SmarAct => {
            let emu = SmarActEmulator::start_on(port, clock, smaract::SmarActEmulatorConfig::default())?;
            on_ready(emu.addr());
            while !stop.load(Ordering::Relaxed) {
                std::thread::sleep(std::time::Duration::from_millis(50));
            }
        }
        EmulatorKind::Mcs2 => {
            let emu = Mcs2Emulator::start_on(port, clock, mcs2::Mcs2EmulatorConfig::default())?;
            on_ready(emu.addr());
            while !stop.load(Ordering::Relaxed) {
                std::thread::sleep(std::time::Duration::from_millis(50));
            }
        }
    }
    Ok(())
}

/// The next command line from a client, without its LF (or CR LF); `None` once the client is gone.
/// Bytes that are not UTF-8 are kept as U+FFFD, so that the command is refused as the controller
/// would refuse it instead of the connection being dropped.
pub(crate) fn read_command(reader: &mut impl std::io::BufRead, buf: &mut Vec<u8>) -> Option<String> {
    buf.clear();
    match reader.read_until(b'\n', buf) {
        Ok(0) | Err(_) => None,
        Ok(_) => Some(String::from_utf8_lossy(buf).trim_end_matches(['\n', '\r']).to_string()),
    }
}
