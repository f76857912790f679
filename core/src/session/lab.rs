//! The lab record of a session: when the measurement started (UTC, RFC 3339), who ran it, the
//! ambient conditions read in the lab (each optional) and the controllers' identification replies.
//! The air index of the model comes from the bench preset's ambient conditions, not from these: the
//! report shows both side by side.

use crate::files::FieldError;
use serde::{Deserialize, Serialize};
use std::ops::RangeInclusive;

/// Temperatures accepted in a lab record (°C).
pub const TEMPERATURE_RANGE_C: RangeInclusive<f64> = -40.0..=60.0;
/// Pressures accepted in a lab record (hPa): sea level to high-altitude labs, with margin.
pub const PRESSURE_RANGE_HPA: RangeInclusive<f64> = 500.0..=1100.0;
/// Relative humidities accepted in a lab record (%).
pub const HUMIDITY_RANGE_PERCENT: RangeInclusive<f64> = 0.0..=100.0;

/// Who, when and in what air a session was measured, and which controllers answered.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct LabRecord {
    /// When recording started, UTC, RFC 3339 (`2026-11-27T16:49:50Z`).
    #[serde(default)]
    pub measured_at_utc: Option<String>,
    /// Who ran the measurement.
    #[serde(default)]
    pub operator: Option<String>,
    /// Ambient air temperature in the lab (°C).
    #[serde(default)]
    pub ambient_temperature_c: Option<f64>,
    /// Ambient air pressure in the lab (hPa).
    #[serde(default)]
    pub pressure_hpa: Option<f64>,
    /// Relative humidity in the lab (%).
    #[serde(default)]
    pub relative_humidity_percent: Option<f64>,
    /// Each controller's name and its identification reply (`*IDN?`), or the virtual bench's own.
    #[serde(default)]
    pub controllers: Vec<ControllerIdentity>,
}

/// A controller's name (as in the hardware configuration) and what it answered when asked who it is.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ControllerIdentity {
    /// The controller's name.
    pub name: String,
    /// Its identification reply.
    pub identification: String,
}

/// The current time, UTC, RFC 3339 to the second.
pub fn now_utc_rfc3339() -> String {
    humantime::format_rfc3339_seconds(std::time::SystemTime::now()).to_string()
}

/// `value` within `range`, or why not (names the quantity, the range and the unit).
pub fn check_range(what: &str, value: f64, range: &RangeInclusive<f64>, unit: &str) -> Result<f64, String> {
    if range.contains(&value) {
        Ok(value)
    } else {
        Err(format!("{what} {value} {unit} is outside {} to {} {unit}", range.start(), range.end()))
    }
}

impl LabRecord {
    /// Set the start of the measurement to now unless it is set already.
    pub fn stamp_start(&mut self) {
        if self.measured_at_utc.is_none() {
            self.measured_at_utc = Some(now_utc_rfc3339());
        }
    }

    /// Every field in range, the time an RFC 3339 UTC time; the error names the field (under `lab.`).
    pub fn validate(&self) -> Result<(), FieldError> {
        if let Some(t) = &self.measured_at_utc {
            humantime::parse_rfc3339(t).map_err(|e| {
                FieldError::new("lab.measured_at_utc", format!("`{t}` is not a UTC RFC 3339 time ({e})"))
            })?;
        }
        let checks = [
            ("ambient_temperature_c", "temperature", self.ambient_temperature_c, &TEMPERATURE_RANGE_C, "°C"),
            ("pressure_hpa", "pressure", self.pressure_hpa, &PRESSURE_RANGE_HPA, "hPa"),
            (
                "relative_humidity_percent",
                "relative humidity",
                self.relative_humidity_percent,
                &HUMIDITY_RANGE_PERCENT,
                "%",
            ),
        ];
        for (field, what, value, range, unit) in checks {
            if let Some(v) = value {
                check_range(what, v, range, unit).map_err(|e| FieldError::new(format!("lab.{field}"), e))?;
            }
        }
        Ok(())
    }

    /// True when nothing is recorded.
    pub fn is_empty(&self) -> bool {
        *self == LabRecord::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::session::tests::sample_session;
    use crate::session::{session_path, Session};

    fn recorded() -> LabRecord {
        LabRecord {
            measured_at_utc: Some("2026-11-27T16:49:50Z".into()),
            operator: Some("Ada Lovelace".into()),
            ambient_temperature_c: Some(21.3),
            pressure_hpa: Some(1002.5),
            relative_humidity_percent: Some(38.0),
            controllers: vec![ControllerIdentity { name: "pi".into(), identification: "E-712, 0, 1.0.0".into() }],
        }
    }

    #[test]
    fn a_lab_record_round_trips_through_save_and_load() {
        let dir = tempfile::tempdir().unwrap();
        let mut s = sample_session(dir.path());
        s.lab = recorded();
        s.save(dir.path()).unwrap();
        assert_eq!(Session::load(dir.path()).unwrap().lab, recorded());
    }

    #[test]
    fn a_session_file_without_a_lab_record_loads_with_an_empty_one() {
        let dir = tempfile::tempdir().unwrap();
        let s = sample_session(dir.path());
        s.save(dir.path()).unwrap();
        let path = session_path(dir.path());
        let text = std::fs::read_to_string(&path).unwrap();
        // A file written before the lab record existed: no `lab` field at all.
        let start = text.find("\n    lab: ").expect("the field is written");
        let old = format!("{}\n)\n", text[..start].trim_end());
        assert!(!old.contains("lab:") && !old.contains("measured_at_utc"), "{old}");
        std::fs::write(&path, old).unwrap();
        let back = Session::load(dir.path()).unwrap();
        assert!(back.lab.is_empty());
        assert_eq!(back.notes, s.notes);
    }

    #[test]
    fn out_of_range_or_malformed_values_name_the_field() {
        for (lab, field, says) in [
            (
                LabRecord { relative_humidity_percent: Some(140.0), ..recorded() },
                "lab.relative_humidity_percent",
                "0 to 100 %",
            ),
            (LabRecord { pressure_hpa: Some(f64::NAN), ..recorded() }, "lab.pressure_hpa", "500 to 1100 hPa"),
            (
                LabRecord { ambient_temperature_c: Some(-80.0), ..recorded() },
                "lab.ambient_temperature_c",
                "-40 to 60 °C",
            ),
            (LabRecord { measured_at_utc: Some("yesterday".into()), ..recorded() }, "lab.measured_at_utc", "RFC 3339"),
        ] {
            let e = lab.validate().unwrap_err();
            assert_eq!(e.field, field);
            assert!(e.problem.contains(says), "{}", e.problem);
        }
        assert!(recorded().validate().is_ok());
        let mut stamped = LabRecord::default();
        stamped.stamp_start();
        assert!(stamped.validate().is_ok(), "{:?}", stamped.measured_at_utc);
    }
}
