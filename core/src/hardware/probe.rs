//! "Who is at this address?": identify a stage controller without moving anything or changing its
//! settings, for the connection panel. Owns the identity record; the protocol work is the drivers'.

use super::controller_bench::ControllerKind;
use super::{AxisInfo, HwError, PiGcs, SmarActMcs, SmarActMcs2, StageController};

/// What a controller said about itself.
#[derive(Debug, Clone, PartialEq)]
pub struct Identity {
    /// The controller's name in the configuration ("PI E-712").
    pub controller: String,
    /// host:port asked.
    pub address: String,
    /// The identification: the `*IDN?` reply of a PI controller; for an MCS its system ID
    /// (`:GSI`, where the firmware answers it), channel count and each channel's sensor type; for an
    /// MCS2 its serial number and channels.
    pub reply: String,
    /// The axes or channels found, with their units.
    pub axes: Vec<AxisInfo>,
}

/// Connect to `address`, identify the controller of `kind` there and disconnect. PI: `*IDN?` and
/// `SAI?` (no `SVO`: the servo state is left alone). MCS: `:SCM0`, `:GNC`, each channel's sensor
/// type (`:GST`), acceleration control off (`:SCLA`) and `:GSI` (what connecting does; nothing
/// moves). MCS2: what connecting does (the error queue, `:DEV:SNUM?`, `:DEV:NOCH?`, each channel's
/// movement type, absolute move mode, acceleration control off). A
/// controller of another protocol is an error (a bad reply or no reply), not an identity.
pub fn identify(kind: ControllerKind, name: &str, address: &str, timeout_s: f64) -> Result<Identity, HwError> {
    let (reply, axes) = match kind {
        ControllerKind::PiGcs => PiGcs::identify(name, address, timeout_s)?,
        ControllerKind::SmarActMcs => {
            let mcs = SmarActMcs::connect(name, address, timeout_s, &[])?;
            let axes = mcs.axes().to_vec();
            let channels: Vec<String> = axes
                .iter()
                .zip(mcs.sensor_types())
                .map(|(a, s)| format!("{} {} sensor {s} ({})", a.id, kind_word(a), a.unit.symbol()))
                .collect();
            let id = mcs.system_id().map_or(String::new(), |id| format!(" system ID {id},"));
            (format!("SmarAct MCS,{id} {} channels: {}", axes.len(), channels.join(", ")), axes)
        }
        ControllerKind::SmarActMcs2 => {
            let mcs = SmarActMcs2::connect(name, address, timeout_s, &[])?;
            let axes = mcs.axes().to_vec();
            let channels: Vec<String> =
                axes.iter().map(|a| format!("{} {} ({})", a.id, kind_word(a), a.unit.symbol())).collect();
            (format!("SmarAct MCS2, serial {}, {} channels: {}", mcs.serial(), axes.len(), channels.join(", ")), axes)
        }
    };
    Ok(Identity { controller: name.to_string(), address: address.to_string(), reply, axes })
}

fn kind_word(a: &AxisInfo) -> &'static str {
    match a.unit {
        crate::bench::AxisUnit::Micrometre => "linear",
        crate::bench::AxisUnit::Degree => "rotary",
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hardware::emulator::{EmuClock, PiEmulator, PiEmulatorConfig, SmarActEmulator, SmarActEmulatorConfig};

    #[test]
    fn identify_names_both_controllers_and_refuses_the_wrong_protocol() {
        let clock = EmuClock::new(1.0);
        let pi = PiEmulator::start(clock.clone(), PiEmulatorConfig::default()).unwrap();
        let mcs = SmarActEmulator::start(clock, SmarActEmulatorConfig::default()).unwrap();
        let (pi_addr, mcs_addr) = (pi.addr().to_string(), mcs.addr().to_string());
        let id = identify(ControllerKind::PiGcs, "PI E-712", &pi_addr, 1.0).unwrap();
        assert!(id.reply.contains("E-712"), "{}", id.reply);
        assert_eq!(id.axes.iter().map(|a| a.id.as_str()).collect::<Vec<_>>(), ["1", "2", "3"]);
        let id = identify(ControllerKind::SmarActMcs, "SmarAct MCS", &mcs_addr, 1.0).unwrap();
        assert_eq!(
            id.reply,
            "SmarAct MCS, system ID 3118000001, 3 channels: 0 rotary sensor 16 (°), 1 rotary sensor 17 (°), 2 rotary sensor 26 (°)"
        );
        // A PI driver at the MCS port: the MCS answers `:E-1,1`, which is no identification.
        let err = identify(ControllerKind::PiGcs, "PI E-712", &mcs_addr, 1.0).unwrap_err().to_string();
        assert!(err.contains("is this a PI GCS controller?"), "{err}");
        // An MCS driver at the PI port: the E-712 ignores `:SCM0`.
        let err = identify(ControllerKind::SmarActMcs, "SmarAct MCS", &pi_addr, 0.3).unwrap_err();
        assert!(matches!(err, HwError::Timeout { .. }), "{err}");
        // Nothing listens: refused, naming the address.
        let closed = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().to_string();
        let err = identify(ControllerKind::PiGcs, "PI E-712", &closed, 1.0).unwrap_err().to_string();
        assert!(err.starts_with(&format!("PI E-712: cannot connect to {closed}: ")), "{err}");
    }
}
