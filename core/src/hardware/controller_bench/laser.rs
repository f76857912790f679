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
