//! The Keysight 816x / N777x tunable-laser commands (8163A/B, 8164A/B & 8166A/B Mainframes
//! Programming Guide, chapter "Measurement Operations & Settings", the SOURce subsystem):
//! wavelengths in metres, speeds in m/s, the lambda log as IEEE 488.2 binary blocks of
//! little-endian f64 metres.

use super::{scpi, Dialect};

/// The Keysight command set.
pub(crate) static DIALECT: Dialect = Dialect {
    set_wavelength: |nm| format!(":SOUR0:WAV {:e}", nm * 1e-9),
    configure_sweep: |from, to, rate, step| {
        vec![
            ":SOUR0:WAV:SWE:MODE CONT".into(),
            format!(":SOUR0:WAV:SWE:STAR {:e}", from * 1e-9),
            format!(":SOUR0:WAV:SWE:STOP {:e}", to * 1e-9),
            format!(":SOUR0:WAV:SWE:SPE {:e}", rate * 1e-9),
            format!(":SOUR0:WAV:SWE:STEP {:e}", step * 1e-9),
            ":SOUR0:WAV:SWE:CYCL 1".into(),
            ":TRIG0:OUTP STF".into(),
            ":SOUR0:WAV:SWE:LLOG 1".into(),
        ]
    },
    start_sweep: ":SOUR0:WAV:SWE 1",
    stop_sweep: ":SOUR0:WAV:SWE 0",
    sweep_state: ":SOUR0:WAV:SWE?",
    log_points: ":SOUR0:READ:POIN? LLOG",
    log_data: ":SOUR0:READ:DATA? LLOG",
    decode_log: |data| Ok(scpi::decode_f64_le(data)?.into_iter().map(|m| m * 1e9).collect()),
    wavelength_query: ":SOUR0:WAV?",
    nm_per_unit: 1e9,
    power: |mw| vec![format!(":SOUR0:POW {mw}MW")],
    vendors: &["keysight", "agilent", "hewlett-packard"],
};
