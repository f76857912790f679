//! The Keysight 816x / N777x tunable-laser commands and rules (8163A/B, 8164A/B & 8166A/B Mainframes
//! Programming Guide, chapter 4 "Measurement Operations & Settings", the SOURce subsystem and
//! `:TRIGger[n]:OUTPut`): wavelengths sent with their unit (the guide's "Units and allowed
//! Mnemonics": PM, NM, UM, MM, M; NM/S … M/S), replies in metres, the lambda log as an IEEE 488.2
//! binary block of little-endian f64 metres.

/// What an identification of this family contains (lower case, any of).
pub const VENDORS: &[&str] = &["keysight", "agilent", "hewlett-packard"];

/// Highest trigger (hence lambda-log) rate of a continuous sweep: "the trigger frequency, derived
/// from the sweep speed and sweep step, is <= 40kHz" (guide, `WAVelength:SWEep:LLOGging`).
pub const MAX_TRIGGER_HZ: f64 = 40e3;

/// Most triggers of a continuous sweep: "the number of triggers … is <= 100001" (same page).
pub const MAX_TRIGGERS: usize = 100_001;

/// Go to a wavelength: `[:SOURce[n]]:WAVelength <value>NM`.
pub fn set_wavelength(nm: f64) -> String {
    format!(":SOUR0:WAV {nm:.6}NM")
}

/// Read the wavelength back (reply in metres).
pub const WAVELENGTH_QUERY: &str = ":SOUR0:WAV?";

/// The commands of a one-way continuous sweep with lambda logging, in order. The guide's
/// prerequisites for lambda logging (`WAVelength:SWEep:LLOGging`): sweep mode CONTinuous, trigger
/// output STFinished (a trigger at every step), amplitude modulation off (`:AM:STATe OFF`); and a
/// continuous sweep starts only with "the start wavelength less than the stop wavelength"
/// (`:WAV:SWE:REPeat ONEWay` sweeps start → stop once; TWOWay would sweep back too).
pub fn configure_sweep(from_nm: f64, to_nm: f64, rate_nm_per_s: f64, step_nm: f64) -> Vec<String> {
    vec![
        ":SOUR0:WAV:SWE:MODE CONT".into(),
        ":SOUR0:WAV:SWE:REP ONEW".into(),
        format!(":SOUR0:WAV:SWE:STAR {from_nm:.6}NM"),
        format!(":SOUR0:WAV:SWE:STOP {to_nm:.6}NM"),
        format!(":SOUR0:WAV:SWE:SPE {rate_nm_per_s:.6}NM/S"),
        format!(":SOUR0:WAV:SWE:STEP {step_nm:.6}NM"),
        ":SOUR0:WAV:SWE:CYCL 1".into(),
        ":SOUR0:AM:STAT OFF".into(),
        ":TRIG0:OUTP STF".into(),
        ":SOUR0:WAV:SWE:LLOG 1".into(),
    ]
}

/// What the sweep's settings read back as: (query, value in nm or nm/s it must equal within the
/// tolerance). Replies are in metres and m/s.
pub fn readback(from_nm: f64, to_nm: f64, step_nm: f64) -> [(&'static str, f64); 3] {
    [(":SOUR0:WAV:SWE:STAR?", from_nm), (":SOUR0:WAV:SWE:STOP?", to_nm), (":SOUR0:WAV:SWE:STEP?", step_nm)]
}

/// The speed the laser accepted (reply in m/s).
pub const SPEED_QUERY: &str = ":SOUR0:WAV:SWE:SPE?";

/// The speed range of the module: `:WAV:SWE:SPE? MIN` and `MAX` (replies in m/s).
pub const SPEED_LIMITS: [&str; 2] = [":SOUR0:WAV:SWE:SPE? MIN", ":SOUR0:WAV:SWE:SPE? MAX"];

/// Settings read back as words: (query, what the reply must be).
pub const STATE_READBACK: [(&str, &str); 4] = [
    (":SOUR0:WAV:SWE:MODE?", "CONT"),
    (":SOUR0:AM:STAT?", "0"),
    (":TRIG0:OUTP?", "STF"),
    (":SOUR0:WAV:SWE:LLOG?", "1"),
];

/// `[:SOURce]:WAVelength:SWEep:CHECkparams?`: "0,OK" when the sweep settings are consistent,
/// else a code and the reason.
pub const CHECK_PARAMS: &str = ":SOUR0:WAV:SWE:CHEC?";

/// Start, stop and state of the sweep (`[:SOURce]:WAVelength:SWEep[:STATe]`: +0 stopped, +1
/// running).
pub const START: &str = ":SOUR0:WAV:SWE 1";
/// Stop the sweep.
pub const STOP: &str = ":SOUR0:WAV:SWE 0";
/// The sweep's state.
pub const STATE: &str = ":SOUR0:WAV:SWE?";

/// `[:SOURce]:WAVelength:SWEep:FLAG?`: "an even number when logging data may be read" (2 after a
/// sweep whose trigger input does not start cycles); 0 "at start/end of sweep".
pub const FLAG: &str = ":SOUR0:WAV:SWE:FLAG?";

/// Number of logged points, and the log (`[:SOURce]:READout:POINts? LLOGging`, `:DATA? LLOGging`:
/// "each binary block is an 8-byte long double in Intel byte order").
pub const LOG_POINTS: &str = ":SOUR0:READ:POIN? LLOG";
/// The log's data.
pub const LOG_DATA: &str = ":SOUR0:READ:DATA? LLOG";

/// Output power in mW.
pub fn power(mw: f64) -> Vec<String> {
    vec![format!(":SOUR0:POW {mw}MW")]
}
