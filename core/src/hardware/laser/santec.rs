//! The Santec TSL-570 commands and rules, in its Legacy command set (`:SYST:COMM:COD 0`): unitless
//! wavelengths in nm and speeds in nm/s (in the SCPI set they would be metres), commands and
//! replies ended by a bare CR over LAN, the wavelength log as a binary block of 4-byte
//! little-endian integers in 0.1 pm (the SCPI set sends 8-byte doubles in metres).
//!
//! Sources: Santec's own samples (`SYST:COMM:COD 0` "Set communication into LEGACY command"; the
//! LAN socket opened with `write_termination = read_termination = '\r'`), the QuTech QMI driver
//! `qmi/instruments/santec/tsl_570.py` (sweep speeds 1, 2, 5, 10, 20, 50, 100, 200 nm/s;
//! `:WAV:SWE:MOD` 0-3; `:WAV:SWE:STAT` 0 stopped, 1 running, 3 standing by trigger, 4 preparing;
//! `:TRIG:OUTP` 0 none, 1 stop, 2 start, 3 step; `:READout:DATa?` "in units of 0.1pm … Legacy
//! mode", read without a terminator after the block).

/// What an identification of this family contains (lower case).
pub const VENDORS: &[&str] = &["santec"];

/// The only sweep speeds the TSL-570 accepts (nm/s).
pub const SPEEDS_NM_PER_S: [f64; 8] = [1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0];

/// Highest trigger rate assumed (the TSL-770 manual's 20 kHz; to check for the TSL-570).
pub const MAX_TRIGGER_HZ: f64 = 20e3;

/// Select the Legacy command set (units: nm, nm/s), then read it back.
pub const LEGACY: &str = ":SYST:COMM:COD 0";
/// The command set in use: 0 Legacy, 1 SCPI.
pub const COMMAND_SET: &str = ":SYST:COMM:COD?";

/// Go to a wavelength (nm).
pub fn set_wavelength(nm: f64) -> String {
    format!(":WAV {nm:.4}")
}

/// Read the wavelength back (reply in nm).
pub const WAVELENGTH_QUERY: &str = ":WAV?";

/// The commands of a continuous one-way sweep with a trigger, hence a logged point, every step:
/// `:WAV:SWE:MOD 1` (continuous, one way), start, stop, speed, `:TRIG:OUTP 3` (step) and its step.
pub fn configure_sweep(from_nm: f64, to_nm: f64, rate_nm_per_s: f64, step_nm: f64) -> Vec<String> {
    vec![
        ":WAV:SWE:MOD 1".into(),
        format!(":WAV:SWE:STAR {from_nm:.4}"),
        format!(":WAV:SWE:STOP {to_nm:.4}"),
        format!(":WAV:SWE:SPE {rate_nm_per_s}"),
        ":TRIG:OUTP 3".into(),
        format!(":TRIG:OUTP:STEP {step_nm:.4}"),
    ]
}

/// What the sweep's settings read back as: (query, nm it must equal).
pub fn readback(from_nm: f64, to_nm: f64, step_nm: f64) -> [(&'static str, f64); 3] {
    [(":WAV:SWE:STAR?", from_nm), (":WAV:SWE:STOP?", to_nm), (":TRIG:OUTP:STEP?", step_nm)]
}

/// The speed the laser accepted (nm/s).
pub const SPEED_QUERY: &str = ":WAV:SWE:SPE?";

/// Settings read back as words.
pub const STATE_READBACK: [(&str, &str); 2] = [(":WAV:SWE:MOD?", "1"), (":TRIG:OUTP?", "3")];

/// Start, stop and state of the sweep (`:WAV:SWE:STAT`).
pub const START: &str = ":WAV:SWE:STAT 1";
/// Stop the sweep.
pub const STOP: &str = ":WAV:SWE:STAT 0";
/// The sweep's state: non-zero while running, preparing or waiting for its trigger.
pub const STATE: &str = ":WAV:SWE:STAT?";

/// Number of logged points, and the log.
pub const LOG_POINTS: &str = ":READout:POINts?";
/// The log's data.
pub const LOG_DATA: &str = ":READout:DATa?";

/// Output power in mW.
pub fn power(mw: f64) -> Vec<String> {
    vec![":POW:UNIT 1".into(), format!(":POW {mw}")]
}

/// The allowed speed nearest `rate_nm_per_s` from below (the slowest allowed when all are above).
pub fn allowed_speed(rate_nm_per_s: f64) -> f64 {
    SPEEDS_NM_PER_S.iter().rev().copied().find(|&s| s <= rate_nm_per_s * (1.0 + 1e-9)).unwrap_or(SPEEDS_NM_PER_S[0])
}
