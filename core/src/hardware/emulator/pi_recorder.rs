//! The emulated E-712 data recorder: a memory of `SPA? 1 0x16000200` points shared by `TNR?`
//! tables (`SPA 1 0x16000300` re-splits it), a rate in servo cycles (`RTR`), a trigger on the
//! next move or on an edge of a digital input (`DRT`), and samples computed when read, at their
//! own times, through the inputs' ADC. A table that is full stops recording (`DRL?` stays at its
//! capacity), as the instrument's does.

use super::pi::{edge_after, input_value, Gcs, PiState, Shared};
use crate::hardware::pi_recorder::{
    PARAM_DATA_REC_CHAN_NUMBER, PARAM_DATA_REC_MAX_POINTS, PARAM_SERVO_UPDATE_TIME, RECORD_ACTUAL_POSITION,
    RECORD_INPUT_NORMALIZED, TRIGGER_EXTERNAL, TRIGGER_ON_MOVE,
};

/// Most record tables the memory may be split into.
pub const MAX_TABLES: usize = 16;

/// The recorder's state.
#[derive(Debug, Default)]
pub(super) struct Recorder {
    /// Per table: (source, record option), or nothing.
    tables: Vec<Option<(String, u32)>>,
    rate: u32,
    armed: bool,
    /// The digital line of an external trigger, when that is the trigger.
    external_line: Option<String>,
    armed_at: f64,
    t_trigger: Option<f64>,
}

impl Recorder {
    pub(super) fn new(tables: usize) -> Self {
        Recorder { tables: vec![None; tables.clamp(1, MAX_TABLES)], rate: 1, ..Default::default() }
    }

    /// A position-changing command: it starts a recording armed for one.
    pub(super) fn trigger_on_move(&mut self, now: f64) {
        if self.armed && self.external_line.is_none() && self.t_trigger.is_none() {
            self.t_trigger = Some(now);
        }
    }

    /// Samples each table holds.
    fn capacity(&self, points: usize) -> usize {
        points / self.tables.len().max(1)
    }
}

/// The bench time the recording started, resolving an external trigger that has come.
fn started(shared: &Shared, st: &mut PiState, now: f64) -> Option<f64> {
    let r = &mut st.recorder;
    if r.t_trigger.is_none() && r.armed {
        if let Some(line) = r.external_line.clone() {
            if let Some(edge) = edge_after(shared, &line, r.armed_at).filter(|&e| e <= now) {
                r.t_trigger = Some(edge);
            }
        }
    }
    r.t_trigger
}

/// Samples recorded by `now` (at most a table's capacity).
fn recorded(shared: &Shared, st: &mut PiState, now: f64) -> usize {
    let cap = st.recorder.capacity(shared.config.record_points);
    let dt = st.recorder.rate as f64 * shared.config.servo_cycle_s;
    match started(shared, st, now) {
        None => 0,
        Some(t0) => ((((now - t0) / dt).floor() as usize) + 1).min(cap),
    }
}

/// `SPA? 1 <param>`'s value, as the controller prints it.
fn param(shared: &Shared, st: &PiState, id: u32) -> Gcs<String> {
    match id {
        PARAM_SERVO_UPDATE_TIME => Ok(format!("{:e}", shared.config.servo_cycle_s)),
        PARAM_DATA_REC_MAX_POINTS => Ok(shared.config.record_points.to_string()),
        PARAM_DATA_REC_CHAN_NUMBER => Ok(st.recorder.tables.len().to_string()),
        _ => Err(54),
    }
}

fn param_id(text: &str) -> Gcs<u32> {
    let hex = text.strip_prefix("0x").or_else(|| text.strip_prefix("0X")).ok_or(1)?;
    u32::from_str_radix(hex, 16).map_err(|_| 1)
}

/// The recorder's configuration: tables, rate, trigger, parameters, and the points recorded.
pub(super) fn setup(
    shared: &Shared,
    st: &mut PiState,
    now: f64,
    name: &str,
    args: &[&str],
) -> Gcs<Option<Vec<String>>> {
    let one = |v: String| Ok(Some(vec![v]));
    match name {
        "DRC" => {
            let [table, source, option] = args else { return Err(1) };
            let table = table.parse::<usize>().map_err(|_| 1)?;
            if table == 0 || table > st.recorder.tables.len() {
                return Err(57);
            }
            let option = option.parse::<u32>().map_err(|_| 1)?;
            let ok = match option {
                RECORD_ACTUAL_POSITION => st.ids.iter().any(|i| i == source),
                RECORD_INPUT_NORMALIZED => st.inputs.iter().any(|i| i == source),
                0 => true,
                _ => false,
            };
            if !ok {
                return Err(58);
            }
            st.recorder.tables[table - 1] = (option != 0).then(|| (source.to_string(), option));
            Ok(None)
        }
        "RTR" => {
            let rate = args.first().and_then(|a| a.parse::<u32>().ok()).filter(|&r| r >= 1 && args.len() == 1);
            st.recorder.rate = rate.ok_or(17)?;
            Ok(None)
        }
        "RTR?" => one(st.recorder.rate.to_string()),
        "DRT" => {
            let [table, trigger, value] = args else { return Err(1) };
            if *table != "0" {
                return Err(1);
            }
            let line = match trigger.parse::<u32>().ok() {
                Some(TRIGGER_ON_MOVE) => None,
                Some(TRIGGER_EXTERNAL) if st.lines.iter().any(|l| l == value) => Some(value.to_string()),
                _ => return Err(17),
            };
            let r = &mut st.recorder;
            (r.armed, r.external_line, r.armed_at, r.t_trigger) = (true, line, now, None);
            Ok(None)
        }
        "DRL?" => {
            let table = args.first().and_then(|a| a.parse::<usize>().ok());
            let table = table.filter(|t| (1..=st.recorder.tables.len()).contains(t)).ok_or(57)?;
            one(format!("{table}={}", recorded(shared, st, now)))
        }
        "TNR?" => one(st.recorder.tables.len().to_string()),
        "SPA?" => {
            let [item, id] = args else { return Err(1) };
            let id = param_id(id)?;
            let v = param(shared, st, id)?;
            one(format!("{item} 0x{id:08X}={v}"))
        }
        "SPA" => {
            let [item, id, value] = args else { return Err(1) };
            if *item != "1" || param_id(id)? != PARAM_DATA_REC_CHAN_NUMBER {
                return Err(if param(shared, st, param_id(id)?).is_ok() { 17 } else { 54 });
            }
            let n = value.parse::<usize>().ok().filter(|n| (1..=MAX_TABLES).contains(n)).ok_or(17)?;
            st.recorder.tables = vec![None; n];
            st.recorder.armed = false;
            Ok(None)
        }
        "HDR?" => {
            let cap = st.recorder.capacity(shared.config.record_points);
            Ok(Some(vec![
                "#RecordOptions".into(),
                "0=Nothing is recorded".into(),
                format!("{RECORD_ACTUAL_POSITION}=Actual position of axis"),
                format!("{RECORD_INPUT_NORMALIZED}=Normalized value of input signal channel"),
                "#TriggerOptions".into(),
                "0=Default".into(),
                format!("{TRIGGER_ON_MOVE}=Any command changing position"),
                format!("{TRIGGER_EXTERNAL}=External trigger on a digital input line"),
                "#Additional information".into(),
                format!("{cap} datapoints per table"),
            ]))
        }
        _ => Err(2),
    }
}

/// `DRR?`: the recorded samples of the given tables, a GCS data-recorder header then one row per sample.
pub(super) fn recorded_data(shared: &Shared, st: &mut PiState, now: f64, args: &[&str]) -> Gcs<Option<Vec<String>>> {
    if args.len() < 3 {
        return Err(1);
    }
    let start = args[0].parse::<usize>().map_err(|_| 1)?;
    let count = args[1].parse::<usize>().map_err(|_| 1)?;
    let tables: Vec<usize> = args[2..].iter().map(|t| t.parse::<usize>().map_err(|_| 1)).collect::<Gcs<_>>()?;
    if start == 0 || tables.iter().any(|&t| t == 0 || t > st.recorder.tables.len()) {
        return Err(17);
    }
    let sources: Vec<(String, u32)> =
        tables.iter().map(|&t| st.recorder.tables[t - 1].clone().ok_or(78)).collect::<Gcs<_>>()?;
    // Checked: a huge count from the wire is an error, not an overflow.
    if (start - 1).checked_add(count).is_none_or(|end| end > recorded(shared, st, now)) {
        return Err(77);
    }
    let dt = st.recorder.rate as f64 * shared.config.servo_cycle_s;
    let t0 = st.recorder.t_trigger.unwrap_or(now);
    let ids = st.ids.clone();
    // Sample outside the locks: the photodiode closure reads the axes itself.
    let axes = shared.axes.lock().unwrap_or_else(|e| e.into_inner()).clone();
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
        let what = if *opt == RECORD_ACTUAL_POSITION { "Actual Position" } else { "Normalized Input Signal" };
        lines.push(format!("# NAME{k} = {what} of {src}"));
    }
    lines.push("# END_HEADER".into());
    let trigger_key = t0.to_bits();
    for k in 0..count {
        let index = start - 1 + k;
        let t = t0 + index as f64 * dt;
        let row: Vec<String> = sources
            .iter()
            .map(|(src, opt)| {
                // Fixed precision, like the controller's: 1e-9 µm, 12 significant digits.
                if *opt == RECORD_ACTUAL_POSITION {
                    let p = ids.iter().position(|i| i == src).map_or(0.0, |i| axes[i].position_at(t));
                    format!("{p:.9}")
                } else {
                    let v =
                        input_value(shared, "TNS?", src, t, trigger_key ^ (index as u64).wrapping_mul(0x100_0000_01B3));
                    format!("{v:.11e}")
                }
            })
            .collect();
        lines.push(row.join(" "));
    }
    Ok(Some(lines))
}
