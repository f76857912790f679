//! The tunable laser of a bench on controllers, and a fixed one for a bench whose laser the
//! software cannot drive (the emulated one is [`crate::hardware::emulator::EmulatedLaser`]).

use crate::hardware::HwError;

/// A tunable laser.
pub trait Laser: Send {
    /// The wavelength when not sweeping (nm).
    fn nominal_nm(&self) -> f64;
    /// Go to a fixed wavelength (nm).
    fn set_wavelength(&mut self, nm: f64) -> Result<(), HwError>;
    /// Start a linear sweep (returns at once).
    fn start_sweep(&mut self, from_nm: f64, to_nm: f64, rate_nm_per_s: f64) -> Result<(), HwError>;
    /// A name for messages ("Keysight laser").
    fn name(&self) -> String {
        "laser".into()
    }
    /// Configure a sweep over the span of `from_nm` → `to_nm` at about `rate_nm_per_s` without
    /// starting it, and say what the laser will do: its start and stop (a laser that sweeps one way
    /// only sweeps the span that way), the speed it accepted and the log step, as read back from it.
    /// [`Laser::start_sweep`] with the setup's values then only has to start it. The default sweeps
    /// as asked and keeps no log.
    fn prepare_sweep(&mut self, from_nm: f64, to_nm: f64, rate_nm_per_s: f64) -> Result<SweepSetup, HwError> {
        Ok(SweepSetup { from_nm, to_nm, rate_nm_per_s, step_nm: 0.0 })
    }
    /// True while a started sweep runs. The default (a laser without a state query) says no: the
    /// sweep is taken as done when the segment's time is up.
    fn sweep_running(&mut self) -> Result<bool, HwError> {
        Ok(false)
    }
    /// The wavelengths the laser logged during its last sweep, or `None` when it keeps no log.
    fn lambda_log(&mut self) -> Result<Option<LambdaLog>, HwError> {
        Ok(None)
    }
    /// Stop a running sweep where it is. The default does nothing.
    fn stop_sweep(&mut self) -> Result<(), HwError> {
        Ok(())
    }
    /// Open the link again after a fault. The default does nothing.
    fn reconnect(&mut self) -> Result<(), HwError> {
        Ok(())
    }
    /// The wavelength the laser reports now (nm), `None` for a laser without a query.
    fn wavelength_now_nm(&mut self) -> Result<Option<f64>, HwError> {
        Ok(None)
    }
    /// The laser sweeps its wavelength (true for every driven laser).
    fn tunable(&self) -> bool {
        true
    }
    /// The traffic on the laser's link so far, for the log's summaries (`None`: no link).
    fn traffic(&self) -> Option<crate::hardware::Traffic> {
        None
    }
}

/// A sweep as the laser will run it (read back from it): start, stop (nm), speed (nm/s) and the
/// distance between logged points (nm; 0 for a laser without a log).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SweepSetup {
    /// Start (nm).
    pub from_nm: f64,
    /// Stop (nm).
    pub to_nm: f64,
    /// Speed (nm/s, positive).
    pub rate_nm_per_s: f64,
    /// Log step (nm, positive; 0 without a log).
    pub step_nm: f64,
}

impl SweepSetup {
    /// Bench time the sweep takes at its speed, start to stop (s).
    pub fn duration_s(&self) -> f64 {
        (self.to_nm - self.from_nm).abs() / self.rate_nm_per_s.max(f64::MIN_POSITIVE)
    }
}

/// The wavelengths a laser logged during a continuous sweep: one point per trigger, every `step_nm`
/// of the sweep from `from_nm`, so point `k` was logged `k·|step_nm| / rate_nm_per_s` seconds after
/// the first one while the laser sweeps at constant speed. The log has no time stamps: its time
/// base is the trigger output or a wavelength monitor on the recorder.
#[derive(Debug, Clone, PartialEq)]
pub struct LambdaLog {
    /// Start of the sweep (nm).
    pub from_nm: f64,
    /// End of the sweep (nm).
    pub to_nm: f64,
    /// Distance between logged points (nm, positive).
    pub step_nm: f64,
    /// Sweep speed (nm/s, positive).
    pub rate_nm_per_s: f64,
    /// The logged wavelengths (nm).
    pub wavelengths_nm: Vec<f64>,
}

impl LambdaLog {
    /// Number of points a complete sweep logs.
    pub fn expected_points(&self) -> usize {
        ((self.to_nm - self.from_nm).abs() / self.step_nm + 1e-6).floor() as usize + 1
    }

    /// The wavelength `t_s` seconds after the first logged point: linear between the logged
    /// points (taken at their trigger times), the first or last point outside them; `None` for an
    /// empty log.
    pub fn wavelength_at(&self, t_s: f64) -> Option<f64> {
        self.at_index(t_s * self.rate_nm_per_s / self.step_nm)
    }

    /// The logged wavelength at fractional point index `x` (linear between points, clamped).
    pub fn at_index(&self, x: f64) -> Option<f64> {
        let w = &self.wavelengths_nm;
        let last = w.len().checked_sub(1)?;
        let x = x.clamp(0.0, last as f64);
        let k = (x.floor() as usize).min(last);
        let f = x - k as f64;
        Some(if k == last { w[last] } else { w[k] + f * (w[k + 1] - w[k]) })
    }

    /// Bench time from the first logged point to the last (s).
    pub fn duration_s(&self) -> f64 {
        self.wavelengths_nm.len().saturating_sub(1) as f64 * self.step_nm / self.rate_nm_per_s
    }
}

/// A laser the software cannot drive (no laser driver yet): it stays at its nominal wavelength, and a
/// plan that sweeps is refused with a message saying so.
pub struct FixedLaser {
    nominal_nm: f64,
}

impl FixedLaser {
    /// A laser resting at `nominal_nm`.
    pub fn new(nominal_nm: f64) -> Self {
        FixedLaser { nominal_nm }
    }
}

impl Laser for FixedLaser {
    fn nominal_nm(&self) -> f64 {
        self.nominal_nm
    }
    fn set_wavelength(&mut self, nm: f64) -> Result<(), HwError> {
        if (nm - self.nominal_nm).abs() < 1e-9 {
            Ok(())
        } else {
            Err(self.refuse())
        }
    }
    fn start_sweep(&mut self, _from_nm: f64, _to_nm: f64, _rate_nm_per_s: f64) -> Result<(), HwError> {
        Err(self.refuse())
    }
    fn tunable(&self) -> bool {
        false
    }
}

impl FixedLaser {
    fn refuse(&self) -> HwError {
        HwError::Usage {
            controller: "laser".into(),
            problem: format!(
                "no tunable-laser driver on this bench (fixed at {} nm): wavelength sweeps cannot run",
                self.nominal_nm
            ),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_lambda_log_is_read_at_its_trigger_times() {
        // Three points 0.5 nm apart at 10 nm/s: logged at 0, 50 and 100 ms; the laser ran 2 pm slow
        // in the middle.
        let log = LambdaLog {
            from_nm: 1550.0,
            to_nm: 1551.0,
            step_nm: 0.5,
            rate_nm_per_s: 10.0,
            wavelengths_nm: vec![1550.0, 1550.498, 1551.0],
        };
        assert_eq!(log.expected_points(), 3);
        let at = |t: f64| log.wavelength_at(t).unwrap();
        assert!((at(0.05) - 1550.498).abs() < 1e-9);
        assert!((at(0.025) - 1550.249).abs() < 1e-9);
        assert!((at(0.075) - 1550.749).abs() < 1e-9);
        assert_eq!((at(-1.0), at(1.0)), (1550.0, 1551.0), "clamped outside the sweep");
        assert_eq!(LambdaLog { wavelengths_nm: vec![], ..log }.wavelength_at(0.0), None);
    }
}
