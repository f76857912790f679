//! Tunable lasers over a raw SCPI socket (terminated commands and replies, binary blocks for the
//! wavelength log): the Keysight 816x / N777x and the Santec TSL-570 command sets, behind the
//! bench's [`Laser`] trait. Owns the connection sequence, the `:SYST:ERR?` check after every set
//! command (as the PI driver checks `ERR?`), the sweep's set-up read back from the laser, and the
//! lambda log. The sweep's rules (speeds, steps, direction) are in [`sweep`]; each family's
//! commands in [`keysight`] and [`santec`].
//!
//! Every wavelength crossing the trait is in nm; the Keysight set is sent with units and answers in
//! metres, the Santec Legacy set speaks nm.

pub mod keysight;
pub mod santec;
pub mod scpi;
mod sweep;

use super::controller_bench::{FixedLaser, HardwareConfig, LambdaLog, Laser, LaserFamily, SweepSetup};
use super::{parse_f64, parse_i64, HwError, LineEnd, Link, Traffic};
use std::time::{Duration, Instant};

pub use sweep::LOG_POINTS_MAX;

/// A tunable laser on a raw SCPI socket.
pub struct ScpiLaser {
    name: String,
    family: LaserFamily,
    link: Link,
    nominal_nm: f64,
    idn: String,
    /// The module's sweep speed range (nm/s), read once (Keysight `:WAV:SWE:SPE? MIN|MAX`).
    speed_range: Option<(f64, f64)>,
    prepared: Option<SweepSetup>,
    started: Option<SweepSetup>,
}

impl ScpiLaser {
    /// Connect to a laser of `family` at `address`, read `*IDN?` (refusing another vendor's), empty
    /// its error queue, and select the command set this driver speaks (Santec: Legacy, read back).
    /// `nominal_nm` is its resting wavelength.
    pub fn connect(family: LaserFamily, address: &str, timeout_s: f64, nominal_nm: f64) -> Result<Self, HwError> {
        let name = format!("{family:?} laser");
        let line_end = match family {
            LaserFamily::Keysight => LineEnd::Lf,
            LaserFamily::Santec => LineEnd::Cr,
            LaserFamily::None => {
                return Err(HwError::Usage { controller: name, problem: "family None has no driver".into() })
            }
        };
        let link = Link::connect_with(&name, address, timeout_s, line_end)?;
        let mut laser = ScpiLaser {
            name,
            family,
            link,
            nominal_nm,
            idn: String::new(),
            speed_range: None,
            prepared: None,
            started: None,
        };
        laser.init()?;
        Ok(laser)
    }

    fn keysight(&self) -> bool {
        self.family == LaserFamily::Keysight
    }

    fn init(&mut self) -> Result<(), HwError> {
        self.idn = self.query("*IDN?")?;
        let vendors = if self.keysight() { keysight::VENDORS } else { santec::VENDORS };
        let lower = self.idn.to_ascii_lowercase();
        if !vendors.iter().any(|v| lower.contains(v)) {
            let idn = self.idn.clone();
            return Err(HwError::bad_reply(
                &self.name,
                "*IDN?",
                &idn,
                &format!("an identification naming {} (is this the configured laser family?)", vendors.join(" or ")),
            ));
        }
        // Errors left from before this connection are not ours.
        for _ in 0..64 {
            if self.error()?.0 == 0 {
                break;
            }
        }
        if !self.keysight() {
            self.command(santec::LEGACY)?;
            let set = self.query(santec::COMMAND_SET)?;
            if !same_word(&set, "0") {
                return Err(HwError::bad_reply(&self.name, santec::COMMAND_SET, &set, "0 (Legacy, just set)"));
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

    /// A numeric reply (a leading `+` allowed).
    fn query_f64(&mut self, command: &str) -> Result<f64, HwError> {
        let reply = self.query(command)?;
        let v = reply.trim();
        parse_f64(&self.name, command, &reply, v.strip_prefix('+').unwrap_or(v))
    }

    fn query_int(&mut self, command: &str) -> Result<i64, HwError> {
        let reply = self.query(command)?;
        let v = reply.trim();
        parse_i64(&self.name, command, &reply, v.strip_prefix('+').unwrap_or(v))
    }

    /// Send a set command, then `:SYST:ERR?`; a non-zero code is an error naming the command and
    /// the laser's message.
    pub fn command(&mut self, command: &str) -> Result<(), HwError> {
        tracing::debug!(controller = %self.name, "{command}");
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

    /// nm per unit of the family's replies (Keysight: metres).
    fn nm_per_reply_unit(&self) -> f64 {
        if self.keysight() {
            1e9
        } else {
            1.0
        }
    }

    /// The laser's wavelength now (nm), read back.
    pub fn wavelength_nm(&mut self) -> Result<f64, HwError> {
        let q = if self.keysight() { keysight::WAVELENGTH_QUERY } else { santec::WAVELENGTH_QUERY };
        Ok(self.query_f64(q)? * self.nm_per_reply_unit())
    }

    /// Set the output power (mW).
    pub fn set_power_mw(&mut self, mw: f64) -> Result<(), HwError> {
        let commands = if self.keysight() { keysight::power(mw) } else { santec::power(mw) };
        for c in commands {
            self.command(&c)?;
        }
        Ok(())
    }

    /// The log step of a sweep over `span_nm`: at most [`LOG_POINTS_MAX`] points, in whole 0.1 pm.
    pub fn log_step_nm(span_nm: f64) -> f64 {
        sweep::log_step_nm(span_nm, 0.0, f64::INFINITY)
    }

    /// After a sweep, the Keysight's lambda log is ready when `FLAG?` is even and at least 2
    /// ("an even number when logging data may be read"); wait for it.
    fn wait_for_log(&mut self) -> Result<(), HwError> {
        if !self.keysight() {
            return Ok(());
        }
        let deadline = Instant::now() + Duration::from_secs_f64(5.0 * self.link.timeout_s());
        loop {
            let flag = self.query_int(keysight::FLAG)?;
            if flag >= 2 && flag % 2 == 0 {
                return Ok(());
            }
            if Instant::now() > deadline {
                return Err(HwError::Usage {
                    controller: self.name.clone(),
                    problem: format!(
                        "the lambda log never became ready after the sweep (`{}` stays {flag})",
                        keysight::FLAG
                    ),
                });
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }
}

/// A word reply equals `want` (case, a leading `+`, and ON/OFF for 1/0 aside).
fn same_word(reply: &str, want: &str) -> bool {
    let r = reply.trim().trim_start_matches('+').to_ascii_uppercase();
    let w = want.to_ascii_uppercase();
    r == w || (w == "0" && r == "OFF") || (w == "1" && r == "ON") || (w.len() >= 3 && r.starts_with(&w))
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
        let c = if self.keysight() { keysight::set_wavelength(nm) } else { santec::set_wavelength(nm) };
        self.command(&c)
    }

    fn prepare_sweep(&mut self, from_nm: f64, to_nm: f64, rate_nm_per_s: f64) -> Result<SweepSetup, HwError> {
        self.prepared = None;
        let setup = self.configure_sweep(from_nm, to_nm, rate_nm_per_s)?;
        self.prepared = Some(setup);
        Ok(setup)
    }

    fn start_sweep(&mut self, from_nm: f64, to_nm: f64, rate_nm_per_s: f64) -> Result<(), HwError> {
        let same = |p: &SweepSetup| p.from_nm == from_nm && p.to_nm == to_nm && p.rate_nm_per_s == rate_nm_per_s;
        if !self.prepared.as_ref().is_some_and(same) {
            self.prepare_sweep(from_nm, to_nm, rate_nm_per_s)?;
        }
        self.started = self.prepared;
        self.command(if self.keysight() { keysight::START } else { santec::START })
    }

    fn sweep_running(&mut self) -> Result<bool, HwError> {
        Ok(self.query_int(if self.keysight() { keysight::STATE } else { santec::STATE })? != 0)
    }

    fn lambda_log(&mut self) -> Result<Option<LambdaLog>, HwError> {
        let Some(setup) = self.started else { return Ok(None) };
        self.wait_for_log()?;
        let (q, d) = if self.keysight() {
            (keysight::LOG_POINTS, keysight::LOG_DATA)
        } else {
            (santec::LOG_POINTS, santec::LOG_DATA)
        };
        let points = self.query_int(q)?;
        let points = usize::try_from(points)
            .map_err(|_| HwError::bad_reply(&self.name, q, &points.to_string(), "a count ≥ 0"))?;
        self.link.send(d)?;
        let data = scpi::read_block(&mut self.link, d)?;
        let wavelengths_nm = scpi::decode_log(&data, points)
            .map_err(|e| HwError::bad_reply(&self.name, d, &format!("{} bytes", data.len()), &e))?;
        Ok(Some(LambdaLog {
            from_nm: setup.from_nm,
            to_nm: setup.to_nm,
            step_nm: setup.step_nm,
            rate_nm_per_s: setup.rate_nm_per_s,
            wavelengths_nm,
        }))
    }

    fn stop_sweep(&mut self) -> Result<(), HwError> {
        self.command(if self.keysight() { keysight::STOP } else { santec::STOP })
    }

    fn reconnect(&mut self) -> Result<(), HwError> {
        self.prepared = None;
        self.link.reconnect()?;
        self.init()
    }

    fn traffic(&self) -> Option<Traffic> {
        Some(self.link.traffic())
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
