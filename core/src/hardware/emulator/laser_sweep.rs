//! The emulated laser's continuous sweep: its settings as each family takes them (units, allowed
//! speeds, Keysight's parameter check and lambda-logging prerequisites, the start-below-stop rule),
//! the start with its latency and run-up, the state and `FLAG?` queries, the abort, and the log of
//! every step reached, ready only after the sweep's post-processing.

use super::laser::{
    quantity, unit_nm, wavelength_arg, Reply, Scpi, Shared, State, CONFLICT, DATA_TYPE, OUT_OF_RANGE, UNDEFINED_HEADER,
};
use crate::hardware::laser::scpi::encode_block;
use crate::hardware::laser::{keysight, santec};

/// A sweep: from, to (nm), speed (nm/s), log step (nm); the first log point reached at `t0_s`,
/// the stop (or the abort) at `end_s`, the laser busy (run-out, return) until `busy_until_s`,
/// the log ready at `log_ready_s`.
#[derive(Debug, Clone, Copy)]
pub(super) struct Sweep {
    from: f64,
    to: f64,
    rate: f64,
    step: f64,
    t_cmd_s: f64,
    t0_s: f64,
    pub(super) end_s: f64,
    pub(super) busy_until_s: f64,
    log_ready_s: f64,
    /// The laser logs its wavelength at each trigger (Keysight: lambda logging on).
    logging: bool,
}

impl Sweep {
    /// The logged wavelengths (nm): every step reached before the sweep ended.
    fn log(&self) -> Vec<f64> {
        if !self.logging {
            return vec![];
        }
        let total = ((self.to - self.from).abs() / self.step + 1e-6).floor() as usize + 1;
        let dir = (self.to - self.from).signum();
        (0..total)
            .take_while(|&k| self.t0_s + k as f64 * self.step / self.rate <= self.end_s + 1e-12)
            .map(|k| self.from + dir * k as f64 * self.step)
            .collect()
    }
}

/// The laser is sweeping (or still running out) at `now`.
pub(super) fn busy(st: &State, now: f64) -> bool {
    st.sweep.is_some_and(|s| now < s.busy_until_s)
}

/// Stop a running sweep where it is at `at_s` (now, or an armed abort's time already passed).
pub(super) fn abort(shared: &Shared, st: &mut State, at_s: f64) {
    if let Some(s) = st.sweep.as_mut().filter(|s| at_s < s.busy_until_s && at_s >= s.t_cmd_s) {
        s.end_s = s.end_s.min(at_s);
        s.busy_until_s = at_s;
        s.log_ready_s = s.log_ready_s.min(at_s);
        let w = shared.laser.wavelength_at(at_s);
        shared.laser.rest_from(at_s, w);
    }
}

/// Keysight `:WAV:SWE:CHEC?`: what makes the settings inconsistent, if anything (the guide's
/// conditions for a continuous sweep and for lambda logging).
fn check(st: &State) -> Option<(i64, &'static str)> {
    if !st.continuous {
        return Some((1, "Sweep mode must be continuous"));
    }
    if st.start_nm >= st.stop_nm {
        return Some((2, "Start wavelength must be less than stop wavelength"));
    }
    if st.speed / st.step > keysight::MAX_TRIGGER_HZ * (1.0 + 1e-9) {
        return Some((3, "Trigger frequency (speed / step) exceeds 40 kHz"));
    }
    if (st.stop_nm - st.start_nm) / st.step + 1.0 > keysight::MAX_TRIGGERS as f64 {
        return Some((4, "Number of triggers exceeds 100001"));
    }
    if st.lambda_logging && (st.trigger_out != "STF" || st.modulation) {
        return Some((5, "Lambda logging needs trigger output STF and modulation off"));
    }
    None
}

/// Sweep settings, start, stop, state and flag.
pub(super) fn command(shared: &Shared, st: &mut State, now: f64, key: &str, arg: &str) -> Scpi<Reply> {
    let keysight = st.keysight();
    let text = |s: String| Ok(Reply::Text(s));
    let unit = unit_nm(st);
    match key {
        "WAV:SWE:STAR" => st.start_nm = wavelength_arg(st, arg)?,
        "WAV:SWE:STOP" => st.stop_nm = wavelength_arg(st, arg)?,
        "WAV:SWE:STAR?" => return text(format!("{:e}", st.start_nm / unit)),
        "WAV:SWE:STOP?" => return text(format!("{:e}", st.stop_nm / unit)),
        "WAV:SWE:SPE" => {
            let v = quantity(arg, if keysight { 1e9 } else { unit }, true)?;
            let allowed = if keysight {
                v >= st.config.min_speed_nm_per_s && v <= st.config.max_speed_nm_per_s
            } else {
                santec::SPEEDS_NM_PER_S.iter().any(|s| (s - v).abs() < 1e-9)
            };
            if !allowed {
                return Err(OUT_OF_RANGE);
            }
            st.speed = v;
        }
        "WAV:SWE:SPE?" => {
            let scale = if keysight { 1e9 } else { unit };
            let v = match arg.to_ascii_uppercase().as_str() {
                "" => st.speed,
                "MIN" if keysight => st.config.min_speed_nm_per_s,
                "MAX" if keysight => st.config.max_speed_nm_per_s,
                _ => return Err(DATA_TYPE),
            };
            return text(format!("{:e}", v / scale));
        }
        "WAV:SWE:STEP" if keysight => st.step = step_arg(st, arg)?,
        "WAV:SWE:STEP?" if keysight => return text(format!("{:e}", st.step / unit)),
        "TRIG:OUTP:STEP" if !keysight => st.step = step_arg(st, arg)?,
        "TRIG:OUTP:STEP?" if !keysight => return text(format!("{}", st.step / unit)),
        "WAV:SWE:MOD" => mode(st, arg)?,
        "WAV:SWE:MOD?" => {
            let v = match (keysight, st.continuous, st.two_way) {
                (true, true, _) => "CONT".to_string(),
                (true, false, _) => "STEP".to_string(),
                (false, c, t) => (u8::from(c) + 2 * u8::from(t)).to_string(),
            };
            return text(v);
        }
        "WAV:SWE:REP" if keysight => {
            st.two_way = match arg.to_ascii_uppercase().as_str() {
                "ONEW" | "ONEWAY" => false,
                "TWOW" | "TWOWAY" => true,
                _ => return Err(DATA_TYPE),
            }
        }
        "WAV:SWE:CYCL" if keysight => {
            if arg != "1" {
                return Err(OUT_OF_RANGE);
            }
        }
        "WAV:SWE:LLOG" if keysight => st.lambda_logging = matches!(arg.to_ascii_uppercase().as_str(), "1" | "ON"),
        "WAV:SWE:LLOG?" if keysight => return text(u8::from(st.lambda_logging).to_string()),
        "WAV:SWE:CHEC?" if keysight => {
            return text(check(st).map_or("0,OK".to_string(), |(c, m)| format!("{c},{m}")));
        }
        "WAV:SWE:FLAG?" if keysight => {
            let flag = st.sweep.map_or(0, |s| if now >= s.log_ready_s { 2 } else { 0 });
            return text(format!("{flag:+}"));
        }
        "WAV:SWE?" => return text(state(st, now)),
        "WAV:SWE" => match arg.to_ascii_uppercase().as_str() {
            "1" | "STAR" | "START" => start(shared, st, now)?,
            "0" | "STOP" => abort(shared, st, now),
            _ => return Err(DATA_TYPE),
        },
        _ => return Err(UNDEFINED_HEADER),
    }
    Ok(Reply::None)
}

/// Keysight `CONT` (or `CONTinuous`); Santec 0-3 (step/continuous, one/two way).
fn mode(st: &mut State, arg: &str) -> Scpi<()> {
    if st.keysight() {
        st.continuous = match arg.to_ascii_uppercase().as_str() {
            "CONT" | "CONTINUOUS" => true,
            "STEP" | "STEPPED" | "MAN" | "MANUAL" => false,
            _ => return Err(DATA_TYPE),
        };
    } else {
        let m = arg.parse::<u8>().ok().filter(|m| *m <= 3).ok_or(OUT_OF_RANGE)?;
        (st.continuous, st.two_way) = (m % 2 == 1, m >= 2);
    }
    Ok(())
}

/// The sweep's state: Keysight +1 while busy; Santec 4 preparing, 1 running, 0 stopped.
fn state(st: &State, now: f64) -> String {
    let running = busy(st, now);
    if st.keysight() {
        return format!("{:+}", u8::from(running));
    }
    match st.sweep {
        Some(s) if running && now < s.t0_s - (s.t0_s - s.t_cmd_s) / 2.0 => "4".into(),
        _ => u8::from(running).to_string(),
    }
}

fn start(shared: &Shared, st: &mut State, now: f64) -> Scpi<()> {
    let keysight = st.keysight();
    if !st.continuous || st.two_way || st.start_nm == st.stop_nm || busy(st, now) {
        return Err(CONFLICT);
    }
    if keysight && check(st).is_some() {
        // "When the sweep is started the status 'Sweep parameters inconsistent' will be returned
        // and Lambda Logging will automatically be turned off."
        st.lambda_logging = false;
        return Err(CONFLICT);
    }
    let stepping = if keysight { st.trigger_out == "STF" } else { st.trigger_out == "3" };
    let logging = if keysight { st.lambda_logging } else { stepping };
    let (from, to, rate, step) = (st.start_nm, st.stop_nm, st.speed, st.step);
    let realism = st.config.realism;
    let (t0_s, end_s) = shared.laser.sweep_with(from, to, rate, realism.profile, stepping.then_some(step));
    let run_out =
        if realism.profile.accel_nm_per_s2.is_finite() { rate / realism.profile.accel_nm_per_s2 } else { 0.0 };
    let busy_until_s = end_s + run_out;
    st.sweep = Some(Sweep {
        from,
        to,
        rate,
        step,
        t_cmd_s: now,
        t0_s,
        end_s,
        busy_until_s,
        // The Keysight post-processes its log after the sweep (its FLAG? says when it is ready).
        log_ready_s: busy_until_s + if keysight { realism.post_processing_s } else { 0.0 },
        logging,
    });
    // "Lambda logging is disabled at the end of a sweep."
    st.lambda_logging = false;
    Ok(())
}

/// The log step: Keysight in metres (with units), Santec in the command set's unit.
fn step_arg(st: &State, arg: &str) -> Scpi<f64> {
    let nm = quantity(arg, unit_nm(st), false)?;
    if !(1e-4 - 1e-9..=10.0).contains(&nm) {
        return Err(OUT_OF_RANGE);
    }
    Ok(nm)
}

/// The lambda log of the last sweep: its number of points or its data as a binary block (Keysight:
/// f64 metres; Santec: u32 0.1 pm in Legacy, f64 metres in SCPI), once the log is ready.
pub(super) fn log_readout(st: &State, now: f64, key: &str, arg: &str) -> Scpi<Reply> {
    let keysight = st.keysight();
    if keysight != arg.eq_ignore_ascii_case("LLOG") && !(keysight && arg.eq_ignore_ascii_case("LLOGGING")) {
        return Err(DATA_TYPE);
    }
    let sweep = st.sweep.ok_or(CONFLICT)?;
    if now < sweep.log_ready_s {
        return Err(CONFLICT);
    }
    let log = sweep.log();
    if key == "READ:POIN?" {
        return Ok(Reply::Text(if keysight { format!("+{}", log.len()) } else { log.len().to_string() }));
    }
    let data: Vec<u8> = if keysight || st.scpi_units {
        log.iter().flat_map(|nm| (nm * 1e-9).to_le_bytes()).collect()
    } else {
        log.iter().flat_map(|nm| ((nm * 1e4).round() as u32).to_le_bytes()).collect()
    };
    Ok(Reply::Bytes(encode_block(&data)))
}
