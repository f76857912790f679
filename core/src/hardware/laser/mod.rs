//! Tunable lasers over a raw SCPI socket (newline-terminated commands and replies, binary blocks
//! for the wavelength log): the Keysight 816x / N777x and the Santec TSL-570 command sets, behind
//! the bench's [`Laser`] trait. Owns the command sequences, the `:SYST:ERR?` check after every set
//! command (as the PI driver checks `ERR?`), and the decoding of the lambda log.
//!
//! Every wavelength crossing the trait is in nm; the Keysight set speaks metres (and m/s), the
//! Santec set nm (and nm/s). The family's commands are in [`keysight`] and [`santec`].

pub mod keysight;
pub mod santec;
pub mod scpi;

use super::controller_bench::{FixedLaser, HardwareConfig, LambdaLog, Laser, LaserFamily};
use super::{parse_i64, HwError, Link};

/// Most points a sweep logs: the step is the sweep's span over this less one (at least 0.1 pm).
pub const LOG_POINTS_MAX: usize = 10_001;

/// The commands of one family.
pub(crate) struct Dialect {
    /// Go to a fixed wavelength (nm).
    pub set_wavelength: fn(f64) -> String,
    /// Configure (not start) a continuous one-way sweep with lambda logging: from, to (nm), speed
    /// (nm/s), log step (nm).
    pub configure_sweep: fn(f64, f64, f64, f64) -> Vec<String>,
    pub start_sweep: &'static str,
    pub stop_sweep: &'static str,
    pub sweep_state: &'static str,
    pub log_points: &'static str,
    pub log_data: &'static str,
    /// The log's block data → wavelengths (nm).
    pub decode_log: fn(&[u8]) -> Result<Vec<f64>, String>,
    /// Read the wavelength back, and the unit of its reply (nm per reply unit).
    pub wavelength_query: &'static str,
    pub nm_per_unit: f64,
    /// Set the output power (mW).
    pub power: fn(f64) -> Vec<String>,
    /// What an identification of this family contains (lower case, any of).
    pub vendors: &'static [&'static str],
}

fn dialect(family: LaserFamily) -> Option<&'static Dialect> {
    match family {
        LaserFamily::Keysight => Some(&keysight::DIALECT),
        LaserFamily::Santec => Some(&santec::DIALECT),
        LaserFamily::None => None,
    }
}

/// A sweep as configured: from, to (nm), speed (nm/s), log step (nm).
type SweepSetup = (f64, f64, f64, f64);

/// A tunable laser on a raw SCPI socket.
pub struct ScpiLaser {
    name: String,
    dialect: &'static Dialect,
    link: Link,
    nominal_nm: f64,
    idn: String,
    prepared: Option<SweepSetup>,
    started: Option<SweepSetup>,
}

impl ScpiLaser {
    /// Connect to a laser of `family` at `address`, read `*IDN?` (refusing another vendor's), and
    /// empty its error queue. `nominal_nm` is its resting wavelength.
    pub fn connect(family: LaserFamily, address: &str, timeout_s: f64, nominal_nm: f64) -> Result<Self, HwError> {
        let name = format!("{family:?} laser");
        let dialect = dialect(family)
            .ok_or_else(|| HwError::Usage { controller: name.clone(), problem: "family None has no driver".into() })?;
        let link = Link::connect(&name, address, timeout_s)?;
        let mut laser =
            ScpiLaser { name, dialect, link, nominal_nm, idn: String::new(), prepared: None, started: None };
        laser.init()?;
        Ok(laser)
    }

    fn init(&mut self) -> Result<(), HwError> {
        self.idn = self.query("*IDN?")?;
        let lower = self.idn.to_ascii_lowercase();
        if !self.dialect.vendors.iter().any(|v| lower.contains(v)) {
            let idn = self.idn.clone();
            return Err(HwError::bad_reply(
                &self.name,
                "*IDN?",
                &idn,
                &format!(
                    "an identification naming {} (is this the configured laser family?)",
                    self.dialect.vendors.join(" or ")
                ),
            ));
        }
        // Errors left from before this connection are not ours.
        for _ in 0..64 {
            if self.error()?.0 == 0 {
                break;
            }
        }
        Ok(())
    }

    /// The identification string (`*IDN?`).
    pub fn idn(&self) -> &str {
        &self.idn
    }

    /// Record every command and reply.
    pub fn set_transcript(&mut self, t: Option<super::Transcript>) {
        self.link.set_transcript(t);
    }

    /// `:SYST:ERR?`: the oldest error of the queue (code 0: none), removing it.
    pub fn error(&mut self) -> Result<(i64, String), HwError> {
        let reply = self.query_raw(":SYST:ERR?")?;
        scpi::parse_error_reply(&reply).map_err(|e| HwError::bad_reply(&self.name, ":SYST:ERR?", &reply, &e))
    }

    fn query_raw(&mut self, command: &str) -> Result<String, HwError> {
        self.link.send(command)?;
        self.link.read_line(command)
    }

    /// Send a query and return its reply line. A silent query with an error pending (asked on a
    /// fresh connection) is that error, not a timeout.
    pub fn query(&mut self, command: &str) -> Result<String, HwError> {
        match self.query_raw(command) {
            Err(HwError::Timeout { timeout_s, .. }) => {
                let timeout = HwError::Timeout { controller: self.name.clone(), command: command.into(), timeout_s };
                if self.link.reconnect().is_ok() {
                    if let Ok((code, message)) = self.error() {
                        if code != 0 {
                            return Err(self.refused(command, code, &message));
                        }
                    }
                }
                self.link.close();
                Err(timeout)
            }
            other => other,
        }
    }

    /// Send a set command, then `:SYST:ERR?`; a non-zero code is an error naming the command and
    /// the laser's message.
    pub fn command(&mut self, command: &str) -> Result<(), HwError> {
        self.link.send(command)?;
        let (code, message) = self.error()?;
        if code != 0 {
            return Err(self.refused(command, code, &message));
        }
        Ok(())
    }

    fn refused(&self, command: &str, code: i64, message: &str) -> HwError {
        HwError::Usage {
            controller: self.name.clone(),
            problem: format!("`{command}` failed: laser error {code}, \"{message}\""),
        }
    }

    /// The laser's wavelength now (nm), read back.
    pub fn wavelength_nm(&mut self) -> Result<f64, HwError> {
        let q = self.dialect.wavelength_query;
        let reply = self.query(q)?;
        Ok(super::parse_f64(&self.name, q, &reply, &reply)? * self.dialect.nm_per_unit)
    }

    /// Set the output power (mW).
    pub fn set_power_mw(&mut self, mw: f64) -> Result<(), HwError> {
        for c in (self.dialect.power)(mw) {
            self.command(&c)?;
        }
        Ok(())
    }

    /// The log step of a sweep over `span_nm`: at most [`LOG_POINTS_MAX`] points, in whole 0.1 pm.
    pub fn log_step_nm(span_nm: f64) -> f64 {
        let step = span_nm.abs() / (LOG_POINTS_MAX - 1) as f64;
        ((step / 1e-4).ceil() * 1e-4).max(1e-4)
    }
}

impl Laser for ScpiLaser {
    fn nominal_nm(&self) -> f64 {
        self.nominal_nm
    }

    fn wavelength_now_nm(&mut self) -> Result<Option<f64>, HwError> {
        self.wavelength_nm().map(Some)
    }

    fn name(&self) -> String {
        self.name.clone()
    }

    fn set_wavelength(&mut self, nm: f64) -> Result<(), HwError> {
        self.command(&(self.dialect.set_wavelength)(nm))
    }

    fn prepare_sweep(&mut self, from_nm: f64, to_nm: f64, rate_nm_per_s: f64) -> Result<(), HwError> {
        if !(from_nm.is_finite() && to_nm.is_finite() && rate_nm_per_s.is_finite() && rate_nm_per_s > 0.0) {
            return Err(HwError::Usage {
                controller: self.name.clone(),
                problem: format!("cannot sweep {from_nm} → {to_nm} nm at {rate_nm_per_s} nm/s"),
            });
        }
        self.prepared = None;
        let step = Self::log_step_nm(to_nm - from_nm);
        for c in (self.dialect.configure_sweep)(from_nm, to_nm, rate_nm_per_s, step) {
            self.command(&c)?;
        }
        self.prepared = Some((from_nm, to_nm, rate_nm_per_s, step));
        Ok(())
    }

    fn start_sweep(&mut self, from_nm: f64, to_nm: f64, rate_nm_per_s: f64) -> Result<(), HwError> {
        let same = |p: &SweepSetup| p.0 == from_nm && p.1 == to_nm && p.2 == rate_nm_per_s;
        if !self.prepared.as_ref().is_some_and(same) {
            self.prepare_sweep(from_nm, to_nm, rate_nm_per_s)?;
        }
        self.started = self.prepared;
        self.command(self.dialect.start_sweep)
    }

    fn sweep_running(&mut self) -> Result<bool, HwError> {
        let q = self.dialect.sweep_state;
        let reply = self.query(q)?;
        let v = reply.trim();
        Ok(parse_i64(&self.name, q, &reply, v.strip_prefix('+').unwrap_or(v))? != 0)
    }

    fn lambda_log(&mut self) -> Result<Option<LambdaLog>, HwError> {
        let Some((from_nm, to_nm, rate_nm_per_s, step_nm)) = self.started else { return Ok(None) };
        let q = self.dialect.log_points;
        let reply = self.query(q)?;
        let v = reply.trim();
        let points = parse_i64(&self.name, q, &reply, v.strip_prefix('+').unwrap_or(v))?;
        let d = self.dialect.log_data;
        self.link.send(d)?;
        let data = scpi::read_block(&mut self.link, d)?;
        let wavelengths_nm = (self.dialect.decode_log)(&data)
            .map_err(|e| HwError::bad_reply(&self.name, d, &format!("{} bytes", data.len()), &e))?;
        if wavelengths_nm.len() as i64 != points {
            return Err(HwError::bad_reply(
                &self.name,
                d,
                &format!("{} points", wavelengths_nm.len()),
                &format!("the {points} points `{q}` announced"),
            ));
        }
        Ok(Some(LambdaLog { from_nm, to_nm, step_nm, rate_nm_per_s, wavelengths_nm }))
    }

    fn stop_sweep(&mut self) -> Result<(), HwError> {
        self.command(self.dialect.stop_sweep)
    }

    fn reconnect(&mut self) -> Result<(), HwError> {
        self.prepared = None;
        self.link.reconnect()?;
        self.init()
    }
}

/// The laser of a bench: a driver for the configured family at its address, or a [`FixedLaser`]
/// at `nominal_nm` when the configuration has none (sweeps are then refused).
pub fn connect_laser(config: &HardwareConfig, nominal_nm: f64) -> Result<Box<dyn Laser>, HwError> {
    match &config.laser {
        Some(l) if l.family != LaserFamily::None => {
            Ok(Box::new(ScpiLaser::connect(l.family, &l.address, l.timeout_s, nominal_nm)?))
        }
        _ => Ok(Box::new(FixedLaser::new(nominal_nm))),
    }
}
