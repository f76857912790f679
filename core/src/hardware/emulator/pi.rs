//! PI E-712 emulator: the GCS 2 subset of [`crate::hardware::pi_gcs`], with closed-loop axes moving at
//! finite speed, `ERR?` semantics (a failed command is silent and leaves its error pending), and a data
//! recorder that samples axis positions and the photodiode input at their own sample times.

use super::{EmuAxis, EmuClock, Fault, FaultSpec, Faults, PhotodiodeFn, Server, SharedAxes};
use crate::hardware::pi_gcs::{RECORD_ACTUAL_POSITION, RECORD_INPUT_SIGNAL, SERVO_CYCLE_S, TRIGGER_ON_MOVE};
use std::io::{BufReader, Write};
use std::net::{SocketAddr, TcpStream};
use std::sync::{Arc, Mutex};

/// Most samples a record table holds.
pub const MAX_RECORD_POINTS: usize = 1 << 21;
/// Number of record tables.
pub const RECORD_TABLES: usize = 8;

/// The emulated controller.
#[derive(Debug, Clone)]
pub struct PiEmulatorConfig {
    /// Axes: identifier, start position, travel range (µm).
    pub axes: Vec<(String, f64, f64, f64)>,
    /// Default speed (µm/s) until `VEL` changes it.
    pub speed_um_per_s: f64,
    /// Acceleration (µm/s²).
    pub accel_um_per_s2: f64,
    /// Analog input channel identifiers (the photodiode).
    pub inputs: Vec<String>,
}

impl Default for PiEmulatorConfig {
    /// Three axes "1", "2", "3" of a P-563.3CD (0-300 µm, at the centre 150 µm), 100 µm/s,
    /// 1000 µm/s², analog inputs "5" (the photodiode) and "6" (the laser's wavelength monitor).
    fn default() -> Self {
        PiEmulatorConfig {
            axes: ["1", "2", "3"].iter().map(|id| (id.to_string(), 150.0, 0.0, 300.0)).collect(),
            speed_um_per_s: 100.0,
            accel_um_per_s2: 1000.0,
            inputs: vec!["5".into(), "6".into()],
        }
    }
}

#[derive(Debug, Default)]
struct Recorder {
    tables: [Option<(String, u32)>; RECORD_TABLES],
    rate: u32,
    armed: bool,
    t_trigger: Option<f64>,
}

struct PiState {
    ids: Vec<String>,
    inputs: Vec<String>,
    servo: Vec<bool>,
    last_error: i64,
    recorder: Recorder,
    faults: Faults,
}

struct Shared {
    clock: Arc<EmuClock>,
    state: Mutex<PiState>,
    axes: SharedAxes,
    /// Signal sources of the analog inputs, by input identifier.
    inputs: Mutex<Vec<(String, PhotodiodeFn)>>,
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
        let shared = Arc::new(Shared {
            clock,
            state: Mutex::new(PiState {
                ids: config.axes.iter().map(|a| a.0.clone()).collect(),
                inputs: config.inputs.clone(),
                servo: vec![false; config.axes.len()],
                last_error: 0,
                recorder: Recorder { rate: 1, ..Default::default() },
                faults: Faults::default(),
            }),
            axes: Arc::new(Mutex::new(axes)),
            inputs: Mutex::new(vec![]),
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

    /// Feed the first analog input (the photodiode) from `f` (emulated time → input value).
    pub fn set_photodiode(&self, f: PhotodiodeFn) {
        let first = self.shared.state.lock().unwrap_or_else(|e| e.into_inner()).inputs.first().cloned();
        if let Some(id) = first {
            self.set_input(&id, f);
        }
    }

    /// Feed the analog input `id` from `f` (emulated time → input value); inputs without a source read 0.
    pub fn set_input(&self, id: &str, f: PhotodiodeFn) {
        let mut inputs = self.shared.inputs.lock().unwrap_or_else(|e| e.into_inner());
        inputs.retain(|(i, _)| i != id);
        inputs.push((id.to_string(), f));
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
    let Ok(write_half) = stream.try_clone() else { return };
    let mut writer = write_half;
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
            let mut text = String::new();
            for (i, l) in lines.iter().enumerate() {
                text.push_str(l);
                text.push_str(if i + 1 < n { " \n" } else { "\n" });
            }
            Some(text)
        }
    }
}

/// Why a command fails: a GCS error number.
type Gcs<T> = Result<T, i64>;

fn handle(shared: &Shared, command: &str) -> Reply {
    let now = shared.clock.now_s();
    let mut st = shared.state.lock().unwrap_or_else(|e| e.into_inner());
    match st.faults.take(command, now) {
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
        None => {}
    }
    let mut parts = command.split_whitespace();
    let name = parts.next().unwrap_or("").to_ascii_uppercase();
    let args: Vec<&str> = parts.collect();
    let result = execute(shared, &mut st, now, &name, &args);
    match result {
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
        "SVO" | "SVO?" => servo(st, name, args),
        "MOV" | "MVR" | "VEL" | "FRF" | "STP" | "HLT" => motion(shared, st, now, name, args),
        "POS?" | "ONT?" | "VEL?" | "TMN?" | "TMX?" | "FRF?" => axis_query(shared, st, now, name, args),
        "TSP?" => {
            if args.len() != 1 || !st.inputs.iter().any(|i| i == args[0]) {
                return Err(14);
            }
            let f = input_source(shared, args[0]);
            let v = f.map_or(0.0, |f| f(now));
            Ok(Some(vec![format!("{}={v}", args[0])]))
        }
        "DRC" | "RTR" | "RTR?" | "DRT" | "DRL?" => recorder_setup(st, now, name, args),
        "DRR?" => recorded_data(shared, st, now, args),
        "" => Err(1),
        _ => Err(2),
    }
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

/// Closed-loop (servo) mode.
fn servo(st: &mut PiState, name: &str, args: &[&str]) -> Gcs<Option<Vec<String>>> {
    match name {
        "SVO" => {
            let p = pairs(args)?;
            let mut set = Vec::new();
            for (a, v) in p {
                let i = axis_index(st, a)?;
                let on = match v {
                    "0" => false,
                    "1" => true,
                    _ => return Err(1),
                };
                set.push((i, on));
            }
            for (i, on) in set {
                st.servo[i] = on;
            }
            Ok(None)
        }
        "SVO?" => {
            let axes = query_axes(st, args)?;
            Ok(Some(axes.iter().map(|&i| format!("{}={}", st.ids[i], u8::from(st.servo[i]))).collect()))
        }
        _ => Err(2),
    }
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
            for (i, target) in moves {
                ax[i].start_move(now, target);
            }
            if st.recorder.armed && st.recorder.t_trigger.is_none() {
                st.recorder.t_trigger = Some(now);
            }
            Ok(None)
        }
        "VEL" => {
            let p = pairs(args)?;
            let mut set = Vec::new();
            for (a, v) in p {
                let i = axis_index(st, a)?;
                let v = number(v)?;
                if !(v > 0.0 && v <= 10_000.0) {
                    return Err(8);
                }
                set.push((i, v));
            }
            let mut ax = shared.axes.lock().unwrap_or_else(|e| e.into_inner());
            for (i, v) in set {
                ax[i].speed = v;
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
    match name {
        "POS?" => {
            let axes = query_axes(st, args)?;
            Ok(Some(per_axis(shared, st, &axes, &|a| a.position_at(now).to_string())))
        }
        "ONT?" => {
            let axes = query_axes(st, args)?;
            Ok(Some(per_axis(shared, st, &axes, &|a| {
                let on = !a.moving_at(now) && !a.at_limit && (a.position_at(now) - a.target_at(now)).abs() < 1e-9;
                u8::from(on).to_string()
            })))
        }
        "VEL?" => {
            let axes = query_axes(st, args)?;
            Ok(Some(per_axis(shared, st, &axes, &|a| a.speed.to_string())))
        }
        "TMN?" => {
            let axes = query_axes(st, args)?;
            Ok(Some(per_axis(shared, st, &axes, &|a| a.min.to_string())))
        }
        "TMX?" => {
            let axes = query_axes(st, args)?;
            Ok(Some(per_axis(shared, st, &axes, &|a| a.max.to_string())))
        }
        "FRF?" => {
            let axes = query_axes(st, args)?;
            Ok(Some(per_axis(shared, st, &axes, &|a| u8::from(a.referenced).to_string())))
        }
        _ => Err(2),
    }
}

/// The data recorder's configuration: tables, rate, trigger, and the number of points recorded.
fn recorder_setup(st: &mut PiState, now: f64, name: &str, args: &[&str]) -> Gcs<Option<Vec<String>>> {
    match name {
        "DRC" => {
            if args.len() != 3 {
                return Err(1);
            }
            let table = args[0].parse::<usize>().map_err(|_| 1)?;
            if table == 0 || table > RECORD_TABLES {
                return Err(57);
            }
            let option = args[2].parse::<u32>().map_err(|_| 1)?;
            let ok = match option {
                RECORD_ACTUAL_POSITION => st.ids.iter().any(|i| i == args[1]),
                RECORD_INPUT_SIGNAL => st.inputs.iter().any(|i| i == args[1]),
                0 => true,
                _ => false,
            };
            if !ok {
                return Err(58);
            }
            st.recorder.tables[table - 1] = (option != 0).then(|| (args[1].to_string(), option));
            Ok(None)
        }
        "RTR" => {
            let rate = args.first().and_then(|a| a.parse::<u32>().ok()).filter(|&r| r >= 1 && args.len() == 1);
            st.recorder.rate = rate.ok_or(17)?;
            Ok(None)
        }
        "RTR?" => Ok(Some(vec![st.recorder.rate.to_string()])),
        "DRT" => {
            if args.len() != 3 || args[0] != "0" {
                return Err(1);
            }
            if args[1].parse::<u32>().ok() != Some(TRIGGER_ON_MOVE) {
                return Err(17);
            }
            st.recorder.armed = true;
            st.recorder.t_trigger = None;
            Ok(None)
        }
        "DRL?" => {
            let table = args.first().and_then(|a| a.parse::<usize>().ok()).filter(|t| (1..=RECORD_TABLES).contains(t));
            let table = table.ok_or(57)?;
            Ok(Some(vec![format!("{table}={}", recorded(st, now))]))
        }
        _ => Err(2),
    }
}

/// `DRR?`: the recorded samples of the given tables, a GCS data-recorder header then one row per sample.
fn recorded_data(shared: &Shared, st: &PiState, now: f64, args: &[&str]) -> Gcs<Option<Vec<String>>> {
    if args.len() < 3 {
        return Err(1);
    }
    let start = args[0].parse::<usize>().map_err(|_| 1)?;
    let count = args[1].parse::<usize>().map_err(|_| 1)?;
    let tables: Vec<usize> = args[2..].iter().map(|t| t.parse::<usize>().map_err(|_| 1)).collect::<Gcs<_>>()?;
    if start == 0 || tables.iter().any(|&t| t == 0 || t > RECORD_TABLES) {
        return Err(17);
    }
    let sources: Vec<(String, u32)> =
        tables.iter().map(|&t| st.recorder.tables[t - 1].clone().ok_or(78)).collect::<Gcs<_>>()?;
    // Checked: a huge count from the wire is an error, not an overflow.
    if (start - 1).checked_add(count).is_none_or(|end| end > recorded(st, now)) {
        return Err(77);
    }
    let dt = st.recorder.rate as f64 * SERVO_CYCLE_S;
    let t0 = st.recorder.t_trigger.unwrap_or(now);
    let ids = st.ids.clone();
    // Sample outside the locks: the photodiode closure reads the axes itself.
    let axes = shared.axes.lock().unwrap_or_else(|e| e.into_inner()).clone();
    let sources_fn: Vec<Option<PhotodiodeFn>> = sources.iter().map(|(src, _)| input_source(shared, src)).collect();
    let mut lines = vec![
        "# REM E-712 data recorder (emulated)".to_string(),
        "# VERSION = 1".into(),
        "# TYPE = 1".into(),
        "# SEPARATOR = 32".into(),
        format!("# DIM = {}", tables.len()),
        format!("# SAMPLE_TIME = {dt}"),
        format!("# NDATA = {count}"),
    ];
    for (k, (src, opt)) in sources.iter().enumerate() {
        lines.push(format!("# NAME{k} = {} of {src}", if *opt == 2 { "Actual Position" } else { "Input Signal" }));
    }
    lines.push("# END_HEADER".into());
    for k in 0..count {
        let t = t0 + (start - 1 + k) as f64 * dt;
        let row: Vec<String> = sources
            .iter()
            .zip(&sources_fn)
            .map(|((src, opt), f)| {
                // Fixed precision, like the controller's: 1e-9 µm, 12 significant digits.
                if *opt == RECORD_ACTUAL_POSITION {
                    let p = ids.iter().position(|i| i == src).map_or(0.0, |i| axes[i].position_at(t));
                    format!("{p:.9}")
                } else {
                    format!("{:.11e}", f.as_ref().map_or(0.0, |f| f(t)))
                }
            })
            .collect();
        lines.push(row.join(" "));
    }
    Ok(Some(lines))
}

fn recorded(st: &PiState, now: f64) -> usize {
    match st.recorder.t_trigger {
        None => 0,
        Some(t0) => {
            let dt = st.recorder.rate as f64 * SERVO_CYCLE_S;
            ((((now - t0) / dt).floor() as usize) + 1).min(MAX_RECORD_POINTS)
        }
    }
}

fn input_source(shared: &Shared, id: &str) -> Option<PhotodiodeFn> {
    let inputs = shared.inputs.lock().unwrap_or_else(|e| e.into_inner());
    inputs.iter().find(|(i, _)| i == id).map(|(_, f)| f.clone())
}
