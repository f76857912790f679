//! The PI E-712 data recorder: what it is (servo cycle, points, tables and options, read at
//! connect, never assumed), how a recording is set up (tables allocated for what is recorded, the
//! rate chosen so the segment fits, the trigger) and read (`DRL?`, `DRR?`, `TNS?`).
//!
//! Sources: PIPython 2.13 (`pipython/pidevice/gcs2/gcs2datarectools.py`: `RecordOptions`,
//! `TriggerSources`, `getservotime` reads parameter 0x0E000200 SERVO_UPDATE_TIME, `getmaxnumvalues`
//! reads 0x16000200 DATA_REC_MAX_POINTS over 0x16000300 DATA_REC_CHAN_NUMBER "for E-709, E-712,
//! E-725…", `get_hdr_options` parses `HDR?`; `gcsbasecommands.py`: `TNR?`, `TNS?` "normalized value
//! of input signal channels", `TSP?` "position in physical units", `TAV?` "voltage of analog input").

use super::pi_gcs::PiGcs;
use super::pi_replies as replies;
use super::{parse_f64, DataRecorder, HwError, RecordTrigger, RecordedBlock, RecorderRequest, RecorderSetup};

/// Record option: actual position of an axis (PIPython `ACTUAL_POSITION_2`).
pub const RECORD_ACTUAL_POSITION: u32 = 2;
/// Record option: normalised value of an input signal channel (PIPython `SENSOR_NORMALIZED_17`),
/// the quantity `TNS?` reads; `TSP?` (linearised, physical units) and `TAV?` (volts) are others.
pub const RECORD_INPUT_NORMALIZED: u32 = 17;
/// Trigger option: any command changing a position (`MOV`, `MVR`; PIPython
/// `POSITION_CHANGING_COMMAND_1`).
pub const TRIGGER_ON_MOVE: u32 = 1;
/// Trigger option: an external trigger on a digital input line (PIPython `EXTERNAL_TRIGGER_3`).
pub const TRIGGER_EXTERNAL: u32 = 3;
/// Parameter: servo update time (s) (PIPython `getservotime`).
pub const PARAM_SERVO_UPDATE_TIME: u32 = 0x0E00_0200;
/// Parameter: points of the recorder's memory, shared by its tables (PIPython `getmaxnumvalues`).
pub const PARAM_DATA_REC_MAX_POINTS: u32 = 0x1600_0200;
/// Parameter: number of record tables the memory is split into (PIPython `getmaxnumvalues`).
pub const PARAM_DATA_REC_CHAN_NUMBER: u32 = 0x1600_0300;

/// What the recorder of a connected E-712 is.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RecorderFacts {
    /// Servo cycle (s): the recorder samples every `RTR` cycles of it.
    pub servo_cycle_s: f64,
    /// Points of recorder memory, shared by the tables.
    pub max_points: usize,
    /// Record tables the memory is split into now (`TNR?`).
    pub tables: usize,
    /// Record options `HDR?` lists.
    pub record_options: Vec<u32>,
    /// Trigger options `HDR?` lists.
    pub trigger_options: Vec<u32>,
    /// Samples per table of the last recording armed.
    pub capacity: Option<usize>,
}

impl RecorderFacts {
    /// Read the recorder's servo cycle, memory, tables and options from the controller.
    pub(super) fn read(pi: &mut PiGcs) -> Result<Self, HwError> {
        let servo = param(pi, PARAM_SERVO_UPDATE_TIME)?;
        let servo_cycle_s = parse_f64(&pi.name, "SPA?", &servo, &servo)?;
        let points = param(pi, PARAM_DATA_REC_MAX_POINTS)?;
        let max_points = parse_count(pi, "SPA?", &points)?;
        let tables = tables(pi)?;
        if !(servo_cycle_s > 0.0 && servo_cycle_s < 0.1) || max_points == 0 {
            return Err(pi.bad(
                "SPA?",
                &format!("{servo} s, {points} points"),
                "a servo cycle in (0, 0.1) s and recorder points > 0",
            ));
        }
        let lines = pi.query("HDR?")?;
        let (record_options, trigger_options, _) = replies::record_options(&lines);
        let facts =
            RecorderFacts { servo_cycle_s, max_points, tables, record_options, trigger_options, capacity: None };
        for (option, listed, what) in [
            (RECORD_ACTUAL_POSITION, &facts.record_options, "record option"),
            (RECORD_INPUT_NORMALIZED, &facts.record_options, "record option"),
            (TRIGGER_ON_MOVE, &facts.trigger_options, "trigger option"),
        ] {
            if !listed.contains(&option) {
                return Err(HwError::Usage {
                    controller: pi.name.clone(),
                    problem: format!(
                        "`HDR?` does not list {what} {option}, which the recording needs (it lists {listed:?})"
                    ),
                });
            }
        }
        Ok(facts)
    }
}

/// `SPA? 1 <param>`: a controller parameter (item 1), as text.
fn param(pi: &mut PiGcs, id: u32) -> Result<String, HwError> {
    let command = format!("SPA? 1 0x{id:08X}");
    let lines = pi.query(&command)?;
    replies::param_value(&pi.name, &command, &lines, "1", id)
}

fn parse_count(pi: &PiGcs, command: &str, text: &str) -> Result<usize, HwError> {
    text.trim().parse::<usize>().map_err(|_| pi.bad(command, text, "a whole number"))
}

/// `TNR?`: the record tables available now.
fn tables(pi: &mut PiGcs) -> Result<usize, HwError> {
    let lines = pi.query("TNR?")?;
    replies::count(&pi.name, "TNR?", &lines)
}

impl PiGcs {
    /// Split the recorder's memory into `n` tables (`SPA 1 0x16000300 n`) and read it back
    /// (`TNR?`): the fewer the tables, the longer each one.
    fn allocate_tables(&mut self, n: usize) -> Result<(), HwError> {
        if self.recorder.tables != n {
            self.command(&format!("SPA 1 0x{PARAM_DATA_REC_CHAN_NUMBER:08X} {n}"))?;
            let now = tables(self)?;
            if now != n {
                return Err(HwError::Usage {
                    controller: self.name.clone(),
                    problem: format!("`TNR?` reads {now} record tables after asking for {n}"),
                });
            }
            self.recorder.tables = now;
        }
        Ok(())
    }

    /// The record-table rate (servo cycles per sample) nearest `period_s`, lengthened until
    /// `duration_s` fits `capacity` samples.
    fn recorder_rate(&self, period_s: f64, duration_s: f64, capacity: usize) -> u64 {
        let cycle = self.recorder.servo_cycle_s;
        let wanted = (period_s / cycle).round().max(1.0) as u64;
        let fits = (duration_s / (capacity.saturating_sub(1).max(1) as f64 * cycle)).ceil().max(1.0) as u64;
        wanted.max(fits)
    }
}

impl DataRecorder for PiGcs {
    /// `DRC` per table (positions: option 2; inputs: option 17), `RTR` read back with `RTR?`, and
    /// `DRT 0 <trigger> <value>`: 1 (next move) or 3 (external, on the given digital line).
    fn arm(&mut self, request: &RecorderRequest) -> Result<RecorderSetup, HwError> {
        let ids = self.axis_list(&request.axes)?;
        let n = ids.len() + request.inputs.len();
        if n == 0 {
            return Err(HwError::Usage { controller: self.name.clone(), problem: "nothing to record".into() });
        }
        self.allocate_tables(n)?;
        let capacity = self.recorder.max_points / n;
        for (k, id) in ids.iter().enumerate() {
            self.command(&format!("DRC {} {id} {RECORD_ACTUAL_POSITION}", k + 1))?;
        }
        for (k, input) in request.inputs.iter().enumerate() {
            self.command(&format!("DRC {} {input} {RECORD_INPUT_NORMALIZED}", ids.len() + k + 1))?;
        }
        let rate = self.recorder_rate(request.sample_period_s, request.duration_s, capacity);
        self.command(&format!("RTR {rate}"))?;
        let lines = self.query("RTR?")?;
        if replies::count(&self.name, "RTR?", &lines)? as u64 != rate {
            return Err(self.bad("RTR?", &lines.join(" "), &format!("{rate}, the rate just set")));
        }
        let (option, value) = match &request.trigger {
            RecordTrigger::NextMove => (TRIGGER_ON_MOVE, "0".to_string()),
            RecordTrigger::External { line } => (TRIGGER_EXTERNAL, line.clone()),
        };
        if !self.recorder.trigger_options.contains(&option) {
            return Err(HwError::Usage {
                controller: self.name.clone(),
                problem: format!(
                    "`HDR?` does not list trigger option {option} (it lists {:?})",
                    self.recorder.trigger_options
                ),
            });
        }
        self.command(&format!("DRT 0 {option} {value}"))?;
        self.armed_axes = request.axes.clone();
        self.armed_inputs = request.inputs.len();
        self.recorder.capacity = Some(capacity);
        let sample_period_s = rate as f64 * self.recorder.servo_cycle_s;
        if sample_period_s > request.sample_period_s * 1.5 {
            tracing::info!(
                controller = %self.name,
                duration_s = request.duration_s,
                capacity,
                "recorder sampling every {:.2} ms (asked {:.2} ms) so that the segment fits its tables",
                sample_period_s * 1e3,
                request.sample_period_s * 1e3
            );
        }
        Ok(RecorderSetup { sample_period_s, capacity: Some(capacity) })
    }

    fn recorded_len(&mut self) -> Result<usize, HwError> {
        let lines = self.query("DRL? 1")?;
        replies::count(&self.name, "DRL?", &lines)
    }

    fn read(&mut self, start: usize, count: usize) -> Result<RecordedBlock, HwError> {
        let tables = self.armed_axes.len() + self.armed_inputs;
        if count == 0 || tables == 0 {
            return Ok(RecordedBlock {
                start,
                axes: vec![vec![]; self.armed_axes.len()],
                inputs: vec![vec![]; self.armed_inputs],
            });
        }
        let list: Vec<String> = (1..=tables).map(|t| t.to_string()).collect();
        let command = format!("DRR? {} {count} {}", start + 1, list.join(" "));
        let lines = self.query(&command)?;
        let mut columns = replies::data_block(&self.name, &command, &lines, tables)?;
        let inputs = columns.split_off(self.armed_axes.len());
        Ok(RecordedBlock { start, axes: columns, inputs })
    }

    /// `TNS?`: the normalised input value, what record option 17 records (so that `mw_per_unit`
    /// means the same for both).
    fn read_input(&mut self, input: &str) -> Result<f64, HwError> {
        let command = format!("TNS? {input}");
        let lines = self.query(&command)?;
        replies::input_value(&self.name, &command, &lines)
    }
}
