//! The Santec TSL-570 SCPI commands (TSL-570 command reference, "SCPI commands"): wavelengths in
//! nm, speeds in nm/s, the wavelength log read with `:READout:POINts?` / `:READout:DATa?` as a
//! binary block of 4-byte little-endian unsigned integers in units of 0.1 pm (the manual's
//! example: 4520000 = 452.0000 nm).

use super::{scpi, Dialect};

/// The Santec command set.
pub(crate) static DIALECT: Dialect = Dialect {
    set_wavelength: |nm| format!(":WAV {nm:.4}"),
    configure_sweep: |from, to, rate, step| {
        vec![
            ":WAV:SWE:MODE 1".into(),
            format!(":WAV:SWE:STAR {from:.4}"),
            format!(":WAV:SWE:STOP {to:.4}"),
            format!(":WAV:SWE:SPE {rate}"),
            ":TRIG:OUTP 3".into(),
            format!(":TRIG:OUTP:STEP {step:.4}"),
        ]
    },
    start_sweep: ":WAV:SWE 1",
    stop_sweep: ":WAV:SWE 0",
    sweep_state: ":WAV:SWE?",
    log_points: ":READout:POINts?",
    log_data: ":READout:DATa?",
    decode_log: |data| Ok(scpi::decode_u32_le(data)?.into_iter().map(|v| v as f64 * 1e-4).collect()),
    wavelength_query: ":WAV?",
    nm_per_unit: 1.0,
    power: |mw| vec![":POW:UNIT 1".into(), format!(":POW {mw}")],
    vendors: &["santec"],
};
