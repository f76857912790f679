//! PI E-712 emulator: the GCS 2 subset of [`crate::hardware::pi_gcs`], with closed-loop axes moving
//! at finite speed, `ERR?` semantics (a failed command is silent and leaves its error pending),
//! analog inputs read through an ADC, and a data recorder ([`recorder`]).
//!
//! As strict as the instrument as the sources describe it (see `crate::hardware::pi_gcs`): `VEL`
//! acts only with velocity control on (`VCO`), otherwise a `MOV` is a step the servo follows at
//! once; an E-712 with absolute sensors does not know `FRF?` (GCS error 2); `TAV?` (volts), `TNS?`
//! (normalised, what record option 17 records) and `TSP?` (linearised, physical units) differ.

mod recorder;

use super::adc::Adc;
use super::{take_fault, EmuAxis, EmuClock, Fault, FaultSpec, Faults, PhotodiodeFn, Server, SharedAxes};
use recorder::Recorder;
use std::io::{BufReader, Write};
use std::net::{SocketAddr, TcpStream};
use std::sync::{Arc, Mutex};

/// The first rising edge on a digital input line after an emulated time (s), if one came.
pub type EdgeFn = Arc<dyn Fn(f64) -> Option<f64> + Send + Sync>;

/// What the emulated E-712 does that an ideal one would not.
#[derive(Debug, Clone, PartialEq)]
pub struct PiRealism {
    /// The ADC of the analog inputs (`None`: exact readings).
    pub adc: Option<Adc>,
    /// `VEL` acts only with `VCO` on; otherwise moves are steps at `step_speed_um_per_s`.
    pub velocity_needs_vco: bool,
    /// How fast the servo follows a step (µm/s).
    pub step_speed_um_per_s: f64,
    /// The controller knows `FRF?`/`FRF`.
    pub frf_supported: bool,
}

impl PiRealism {
    /// As strict and as imperfect as the instrument.
    pub fn realistic(seed: u64) -> Self {
        PiRealism {
            adc: Some(Adc::e712(seed)),
            velocity_needs_vco: true,
            step_speed_um_per_s: 50_000.0,
            frf_supported: false,
        }
    }

    /// An ideal controller: exact inputs, `VEL` always acts, `FRF?` answers.
    pub fn ideal() -> Self {
        PiRealism { adc: None, velocity_needs_vco: false, step_speed_um_per_s: 50_000.0, frf_supported: true }
    }
}

/// The emulated controller.
#[derive(Debug, Clone)]
pub struct PiEmulatorConfig {
    /// Axes: identifier, start position, travel range (µm).
    pub axes: Vec<(String, f64, f64, f64)>,
    /// Default speed (µm/s) until `VEL` changes it.
    pub speed_um_per_s: f64,
    /// How fast an axis changes speed (µm/s²). The E-7xx controllers have no acceleration
    /// setting: with velocity control on, the target ramps at the slew rate `VEL` sets ("Slew
    /// Rate Limitation", E-727 user manual E727T0005, Control Details; the E-712's servo works
    /// the same way), so every axis of the controller runs a straight ramp. The default changes
    /// speed within one servo cycle.
    pub accel_um_per_s2: f64,
    /// Analog input channel identifiers (the photodiode, the wavelength monitor).
    pub inputs: Vec<String>,
    /// Digital input lines (an external recorder trigger).
    pub digital_lines: Vec<String>,
    /// Servo cycle (s), `SPA? 1 0x0E000200`.
    pub servo_cycle_s: f64,
    /// Points of recorder memory, `SPA? 1 0x16000200`.
    pub record_points: usize,
    /// Record tables at power-up (`TNR?`), `SPA 1 0x16000300` changes it.
    pub record_tables: usize,
    /// What is not ideal.
    pub realism: PiRealism,
}

impl Default for PiEmulatorConfig {
    /// Three axes "1", "2", "3" of a P-563.3CD (0-300 µm, at the centre 150 µm), 100 µm/s,
    /// ramps that reach their speed within a 20 µs servo cycle (1e7 µm/s²), analog inputs "5" (the photodiode) and "6" (the laser's wavelength monitor),
    /// digital inputs "1" to "4", a 20 µs servo cycle and 2^18 recorder points in 8 tables;
    /// realistic.
    fn default() -> Self {
        PiEmulatorConfig {
            axes: ["1", "2", "3"].iter().map(|id| (id.to_string(), 150.0, 0.0, 300.0)).collect(),
            speed_um_per_s: 100.0,
            accel_um_per_s2: 1e7,
            inputs: vec!["5".into(), "6".into()],
            digital_lines: ["1", "2", "3", "4"].iter().map(|s| s.to_string()).collect(),
            servo_cycle_s: 20e-6,
            record_points: 1 << 18,
            record_tables: 8,
            realism: PiRealism::realistic(712),
        }
    }
}

impl PiEmulatorConfig {
    /// The default controller with ideal behaviour.
    pub fn ideal() -> Self {
        PiEmulatorConfig { realism: PiRealism::ideal(), ..Default::default() }
    }
}

pub(super) struct PiState {
    pub(super) ids: Vec<String>,
    pub(super) inputs: Vec<String>,
    pub(super) lines: Vec<String>,
    servo: Vec<bool>,
    vco: Vec<bool>,
    /// Speed set by `VEL` per axis (µm/s).
    vel: Vec<f64>,
    last_error: i64,
    pub(super) recorder: Recorder,
    faults: Faults,
}

pub(super) struct Shared {
    pub(super) clock: Arc<EmuClock>,
    state: Mutex<PiState>,
    pub(super) axes: SharedAxes,
    /// Signal sources of the analog inputs (volts), by input identifier.
    inputs: Mutex<Vec<(String, PhotodiodeFn)>>,
    /// Edge sources of the digital inputs, by line.
    edges: Mutex<Vec<(String, EdgeFn)>>,
    pub(super) config: PiEmulatorConfig,
}

/// A running E-712 emulator.
pub struct PiEmulator {
    server: Server,
    shared: Arc<Shared>,
}

enum Reply {
    None,
    Lines(Vec<String>),
    Drop,
}

impl PiEmulator {
    /// Start on an ephemeral loopback port.
    pub fn start(clock: Arc<EmuClock>, config: PiEmulatorConfig) -> std::io::Result<Self> {
        Self::start_on(0, clock, config)
    }

    /// Start on `port` of 127.0.0.1 (0: any free port).
    pub fn start_on(port: u16, clock: Arc<EmuClock>, config: PiEmulatorConfig) -> std::io::Result<Self> {
        let axes: Vec<EmuAxis> = config
            .axes
            .iter()
            .map(|(_, p, min, max)| EmuAxis::new(*p, *min, *max, config.speed_um_per_s, config.accel_um_per_s2))
            .collect();
        let n = config.axes.len();
        let shared = Arc::new(Shared {
            clock,
            state: Mutex::new(PiState {
                ids: config.axes.iter().map(|a| a.0.clone()).collect(),
                inputs: config.inputs.clone(),
                lines: config.digital_lines.clone(),
                servo: vec![false; n],
                vco: vec![false; n],
                vel: vec![config.speed_um_per_s; n],
                last_error: 0,
                recorder: Recorder::new(config.record_tables),
                faults: Faults::default(),
            }),
            axes: Arc::new(Mutex::new(axes)),
            inputs: Mutex::new(vec![]),
            edges: Mutex::new(vec![]),
            config,
        });
        let s2 = shared.clone();
        let server = Server::start(port, move |stream| serve(&s2, stream))?;
        Ok(PiEmulator { server, shared })
    }

    /// The address it listens on.
    pub fn addr(&self) -> SocketAddr {
        self.server.addr
    }

    /// The axes (µm), shared: a photodiode closure may read their positions at any time.
    pub fn axes(&self) -> SharedAxes {
        self.shared.axes.clone()
    }

    /// Feed the first analog input (the photodiode) from `f` (emulated time → volts).
    pub fn set_photodiode(&self, f: PhotodiodeFn) {
        if let Some(id) = self.shared.config.inputs.first().cloned() {
            self.set_input(&id, f);
        }
    }

    /// Feed the analog input `id` from `f` (emulated time → volts); inputs without a source read 0.
    pub fn set_input(&self, id: &str, f: PhotodiodeFn) {
        let mut inputs = self.shared.inputs.lock().unwrap_or_else(|e| e.into_inner());
        inputs.retain(|(i, _)| i != id);
        inputs.push((id.to_string(), f));
    }

    /// Wire the digital input `line` to an edge source (the laser's trigger output).
    pub fn set_digital_input(&self, line: &str, f: EdgeFn) {
        let mut edges = self.shared.edges.lock().unwrap_or_else(|e| e.into_inner());
        edges.retain(|(l, _)| l != line);
        edges.push((line.to_string(), f));
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
    /// text (empty for none), `None` when it drops the connection.
    pub fn reply_to(&self, command: &str) -> Option<String> {
        reply_text(&self.shared, command)
    }

    /// True while any axis moves.
    pub fn any_moving(&self) -> bool {
        let t = self.shared.clock.now_s();
        self.shared.axes.lock().unwrap_or_else(|e| e.into_inner()).iter().any(|a| a.moving_at(t))
    }
}

fn serve(shared: &Shared, stream: TcpStream) {
    let Ok(mut writer) = stream.try_clone() else { return };
    let mut reader = BufReader::new(stream);
    let mut buf = Vec::new();
    loop {
        let Some(command) = super::read_command(&mut reader, &mut buf) else { return };
        match reply_text(shared, &command) {
            None => {
                let _ = writer.shutdown(std::net::Shutdown::Both);
                return;
            }
            Some(text) => {
                if writer.write_all(text.as_bytes()).is_err() {
                    return;
                }
            }
        }
    }
}

/// The text sent back for one command line (lines after the first continue with a space before
/// the LF); empty for no reply, `None` when the connection is dropped.
fn reply_text(shared: &Shared, command: &str) -> Option<String> {
    match handle(shared, command) {
        Reply::None => Some(String::new()),
        Reply::Drop => None,
        Reply::Lines(lines) => {
            let n = lines.len();
            let mut text = String::with_capacity(n * 48);
            for (i, l) in lines.iter().enumerate() {
                text.push_str(l);
                text.push_str(if i + 1 < n { " \n" } else { "\n" });
            }
            Some(text)
        }
    }
}

/// Why a command fails: a GCS error number.
pub(super) type Gcs<T> = Result<T, i64>;

fn handle(shared: &Shared, command: &str) -> Reply {
    let (mut st, now, fired) = take_fault(&shared.state, |s| &mut s.faults, || shared.clock.now_s(), command);
    match fired {
        Some(Fault::DropConnection) => return Reply::Drop,
        Some(Fault::NoReply) => return Reply::None,
        Some(Fault::ErrorCode(c)) => {
            st.last_error = c;
            return Reply::None;
        }
        Some(Fault::Limit) => {
            let mut axes = shared.axes.lock().unwrap_or_else(|e| e.into_inner());
            for a in axes.iter_mut().filter(|a| a.moving_at(now)) {
                a.stop(now);
                a.at_limit = true;
            }
            st.last_error = 216;
        }
        Some(Fault::Delay(_)) | None => {}
    }
    let mut parts = command.split_whitespace();
    let name = parts.next().unwrap_or("").to_ascii_uppercase();
    let args: Vec<&str> = parts.collect();
    match execute(shared, &mut st, now, &name, &args) {
        Ok(lines) => lines.map_or(Reply::None, Reply::Lines),
        Err(code) => {
            st.last_error = code;
            Reply::None
        }
    }
}

fn axis_index(st: &PiState, id: &str) -> Gcs<usize> {
    st.ids.iter().position(|a| a == id).ok_or(15)
}

fn number(s: &str) -> Gcs<f64> {
    s.parse::<f64>().ok().filter(|v| v.is_finite()).ok_or(1)
}

fn pairs<'a>(args: &[&'a str]) -> Gcs<Vec<(&'a str, &'a str)>> {
    if args.is_empty() || args.len() % 2 != 0 {
        return Err(1);
    }
    Ok(args.chunks(2).map(|c| (c[0], c[1])).collect())
}

/// Axes named in a query, or all of them.
fn query_axes(st: &PiState, args: &[&str]) -> Gcs<Vec<usize>> {
    if args.is_empty() {
        Ok((0..st.ids.len()).collect())
    } else {
        args.iter().map(|a| axis_index(st, a)).collect()
    }
}

/// Run one command: the reply's lines (`None`: a command without reply), or a GCS error number.
fn execute(shared: &Shared, st: &mut PiState, now: f64, name: &str, args: &[&str]) -> Gcs<Option<Vec<String>>> {
    match name {
        "*IDN?" | "ERR?" | "SAI?" => identify(st, name),
        "SVO" | "SVO?" | "VCO" | "VCO?" => flags(st, name, args),
        "FRF" | "FRF?" if !shared.config.realism.frf_supported => Err(2),
        "MOV" | "MVR" | "VEL" | "FRF" | "STP" | "HLT" => motion(shared, st, now, name, args),
        "POS?" | "ONT?" | "VEL?" | "TMN?" | "TMX?" | "FRF?" => axis_query(shared, st, now, name, args),
        "TAV?" | "TNS?" | "TSP?" => {
            let [input] = args else { return Err(1) };
            if !st.inputs.iter().any(|i| i == input) {
                return Err(14);
            }
            let v = input_value(shared, name, input, now, now.to_bits());
            Ok(Some(vec![format!("{input}={v}")]))
        }
        "DRC" | "RTR" | "RTR?" | "DRT" | "DRL?" | "TNR?" | "SPA" | "SPA?" | "HDR?" => {
            recorder::setup(shared, st, now, name, args)
        }
        "DRR?" => recorder::recorded_data(shared, st, now, args),
        "" => Err(1),
        _ => Err(2),
    }
}

/// An analog input's value at emulated time `t_s` through the ADC (`key` names the sample):
/// `TAV?` volts, `TNS?` normalised (gain 1 here, what record option 17 records), `TSP?` the
/// linearised value in physical units (100 per normalised unit here).
pub(super) fn input_value(shared: &Shared, quantity: &str, input: &str, t_s: f64, key: u64) -> f64 {
    let source = {
        let inputs = shared.inputs.lock().unwrap_or_else(|e| e.into_inner());
        inputs.iter().find(|(i, _)| i == input).map(|(_, f)| f.clone())
    };
    let volts = source.map_or(0.0, |f| f(t_s));
    let id = input.bytes().fold(0u64, |h, b| h.wrapping_mul(31).wrapping_add(b as u64));
    let read = match &shared.config.realism.adc {
        Some(adc) => adc.read(volts, key ^ id.rotate_left(40)),
        None => volts,
    };
    match quantity {
        "TSP?" => 100.0 * read,
        _ => read,
    }
}

/// The first edge on digital `line` after `after_s`.
pub(super) fn edge_after(shared: &Shared, line: &str, after_s: f64) -> Option<f64> {
    let edges = shared.edges.lock().unwrap_or_else(|e| e.into_inner());
    edges.iter().find(|(l, _)| l == line).and_then(|(_, f)| f(after_s))
}

/// A line `id=value` per axis of `axes`.
fn per_axis(shared: &Shared, st: &PiState, axes: &[usize], f: &dyn Fn(&EmuAxis) -> String) -> Vec<String> {
    let ax = shared.axes.lock().unwrap_or_else(|e| e.into_inner());
    axes.iter().map(|&i| format!("{}={}", st.ids[i], f(&ax[i]))).collect()
}

/// Identification, the error register and the axis list.
fn identify(st: &mut PiState, name: &str) -> Gcs<Option<Vec<String>>> {
    match name {
        "*IDN?" => Ok(Some(vec!["(c)2026 Physik Instrumente (PI) GmbH & Co. KG, E-712 (emulated), 0, 1.0.0".into()])),
        "ERR?" => {
            let e = std::mem::take(&mut st.last_error);
            Ok(Some(vec![e.to_string()]))
        }
        "SAI?" => Ok(Some(st.ids.clone())),
        _ => Err(2),
    }
}

/// Closed-loop (servo) and velocity-control flags per axis.
fn flags(st: &mut PiState, name: &str, args: &[&str]) -> Gcs<Option<Vec<String>>> {
    let query = name.ends_with('?');
    if query {
        let axes = query_axes(st, args)?;
        let v = if name == "SVO?" { &st.servo } else { &st.vco };
        return Ok(Some(axes.iter().map(|&i| format!("{}={}", st.ids[i], u8::from(v[i]))).collect()));
    }
    let mut set = Vec::new();
    for (a, v) in pairs(args)? {
        let i = axis_index(st, a)?;
        let on = match v {
            "0" => false,
            "1" => true,
            _ => return Err(1),
        };
        set.push((i, on));
    }
    for (i, on) in set {
        if name == "SVO" {
            st.servo[i] = on;
        } else {
            st.vco[i] = on;
        }
    }
    Ok(None)
}

/// Commands that move or stop the axes, set their speed or reference them.
fn motion(shared: &Shared, st: &mut PiState, now: f64, name: &str, args: &[&str]) -> Gcs<Option<Vec<String>>> {
    match name {
        "MOV" | "MVR" => {
            let p = pairs(args)?;
            let mut ax = shared.axes.lock().unwrap_or_else(|e| e.into_inner());
            let mut moves = Vec::new();
            for (a, v) in p {
                let i = axis_index(st, a)?;
                let v = number(v)?;
                if !st.servo[i] {
                    return Err(5);
                }
                let target = if name == "MVR" { ax[i].target_at(now) + v } else { v };
                if target < ax[i].min || target > ax[i].max {
                    return Err(7);
                }
                moves.push((i, target));
            }
            let r = &shared.config.realism;
            for (i, target) in moves {
                // Without velocity control the move is a step the servo follows as fast as it can.
                ax[i].speed = if st.vco[i] || !r.velocity_needs_vco { st.vel[i] } else { r.step_speed_um_per_s };
                ax[i].start_move(now, target);
            }
            st.recorder.trigger_on_move(now);
            Ok(None)
        }
        "VEL" => {
            let mut set = Vec::new();
            for (a, v) in pairs(args)? {
                let i = axis_index(st, a)?;
                let v = number(v)?;
                if !(v > 0.0 && v <= 10_000.0) {
                    return Err(8);
                }
                set.push((i, v));
            }
            for (i, v) in set {
                st.vel[i] = v;
            }
            Ok(None)
        }
        "FRF" => {
            let axes = query_axes(st, args)?;
            let mut ax = shared.axes.lock().unwrap_or_else(|e| e.into_inner());
            for i in axes {
                ax[i].referenced = true;
            }
            Ok(None)
        }
        "STP" | "HLT" => {
            let axes = if name == "STP" { (0..st.ids.len()).collect() } else { query_axes(st, args)? };
            let mut ax = shared.axes.lock().unwrap_or_else(|e| e.into_inner());
            for i in axes {
                ax[i].stop(now);
            }
            Err(10)
        }
        _ => Err(2),
    }
}

/// Queries of the axes' state: position, on target, speed, travel range, referenced.
fn axis_query(shared: &Shared, st: &PiState, now: f64, name: &str, args: &[&str]) -> Gcs<Option<Vec<String>>> {
    let axes = query_axes(st, args)?;
    let lines = match name {
        "POS?" => per_axis(shared, st, &axes, &|a| a.position_at(now).to_string()),
        "ONT?" => per_axis(shared, st, &axes, &|a| {
            let on = !a.moving_at(now) && !a.at_limit && (a.position_at(now) - a.target_at(now)).abs() < 1e-9;
            u8::from(on).to_string()
        }),
        "VEL?" => axes.iter().map(|&i| format!("{}={}", st.ids[i], st.vel[i])).collect(),
        "TMN?" => per_axis(shared, st, &axes, &|a| a.min.to_string()),
        "TMX?" => per_axis(shared, st, &axes, &|a| a.max.to_string()),
        "FRF?" => per_axis(shared, st, &axes, &|a| u8::from(a.referenced).to_string()),
        _ => return Err(2),
    };
    Ok(Some(lines))
}
