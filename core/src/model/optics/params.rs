//! Optical parameters of the bench (fiber, lamella, back face) and their validation.

use serde::{Deserialize, Serialize};
use thiserror::Error;

/// The back face of a transparent lamella (a second reflector behind the front face).
///
/// `Default` is a 500 µm lithium niobate wafer, ordinary index at 1560 nm (Sellmeier of
/// Zelmon et al., JOSA B 14, 3319 (1997)), with an uncoated back face.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct BackFace {
    /// Thickness of the lamella, µm.
    pub thickness_um: f64,
    /// Phase index of the lamella at `reference_wavelength_nm` (dimensionless).
    pub phase_index: f64,
    /// Group index of the lamella near `reference_wavelength_nm`, n_p - λ·dn/dλ
    /// (dimensionless): sets how the back-face fringes move in a wavelength sweep.
    pub group_index: f64,
    /// Vacuum wavelength at which `phase_index` is given, nm.
    pub reference_wavelength_nm: f64,
    /// Power reflectance of the back face seen from inside the lamella (dimensionless).
    pub reflectance: f64,
    /// The back face reflects with a π phase shift (a coating of higher index than the
    /// lamella); false for an uncoated face to air.
    pub inverted: bool,
}

impl Default for BackFace {
    fn default() -> Self {
        Self {
            thickness_um: 500.0,
            phase_index: 2.2108,
            group_index: 2.2634,
            reference_wavelength_nm: 1560.0,
            reflectance: 0.142,
            inverted: false,
        }
    }
}

/// Optical parameters of the bench (everything but the wavelength and the air index).
///
/// `Default` is the paper's bench: SMF-28 fiber, lithium niobate lamella (ordinary index),
/// square cleave, no back face, Gouy phase on, four round trips summed, 1 mW in.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct OpticalParams {
    /// Mode-field radius w0 of the fiber (1/e² intensity radius), µm. SMF-28: MFD
    /// 10.4 µm at 1550 nm, so 5.2 µm.
    pub mode_field_radius_um: f64,
    /// Effective index of the fiber mode (dimensionless). SMF-28 at 1550 nm: 1.4682.
    /// Sets the fiber-face reflectance r1 = (n_fiber - n)/(n_fiber + n), R1 ≈ 3.6 % in air.
    pub fiber_index: f64,
    /// Power reflectance R2 of the lamella's front face (dimensionless). LiNbO3: 0.142 (n_o)
    /// or 0.132 (n_e); glass: 0.040; silicon: 0.306.
    pub lamella_reflectance: f64,
    /// Cleave angle of the fiber end face from square, degrees.
    pub cleave_angle_deg: f64,
    /// Back face of a transparent lamella; `None` ignores it (thick, wedged or AR-coated).
    pub back_face: Option<BackFace>,
    /// Include the Gouy phase arctan(m·|L|/z_R) of each returning beam.
    pub gouy_phase: bool,
    /// Error of the Gouy phase, as a fraction of it (dimensionless, 0 for a Gaussian beam):
    /// each beam's Gouy phase is scaled by `gouy_phase as 0/1 + gouy_scale_error`. The effect
    /// library's "Gouy phase" sets it (−1 removes a Gouy phase the model has, +1 adds one it
    /// lacks); a bench never needs it otherwise.
    pub gouy_scale_error: f64,
    /// Number of cavity round trips summed (≥ 1; 1 gives the two-beam model).
    pub beams: usize,
    /// Power launched into the fiber towards the cavity, mW. Reflected powers are returned
    /// in mW; with 1.0 they equal the reflectance.
    pub input_power_mw: f64,
}

impl Default for OpticalParams {
    fn default() -> Self {
        Self {
            mode_field_radius_um: 5.2,
            fiber_index: 1.4682,
            lamella_reflectance: 0.142,
            cleave_angle_deg: 0.0,
            back_face: None,
            gouy_phase: true,
            gouy_scale_error: 0.0,
            beams: 4,
            input_power_mw: 1.0,
        }
    }
}

/// An optical parameter or an evaluation condition is out of its accepted range.
#[derive(Debug, Clone, PartialEq, Error)]
#[error("{quantity} = {value} {unit} is outside the accepted range {min}..{max} {unit}")]
pub struct OpticsError {
    /// Name of the offending field or argument.
    pub quantity: &'static str,
    /// The value given.
    pub value: f64,
    /// Lowest accepted value.
    pub min: f64,
    /// Highest accepted value.
    pub max: f64,
    /// Unit of `value`, `min` and `max` (empty when dimensionless).
    pub unit: &'static str,
}

pub(super) fn check(
    quantity: &'static str,
    value: f64,
    min: f64,
    max: f64,
    unit: &'static str,
) -> Result<(), OpticsError> {
    if (min..=max).contains(&value) {
        Ok(())
    } else {
        Err(OpticsError { quantity, value, min, max, unit })
    }
}

impl OpticalParams {
    /// Checks every field (NaN is rejected). Ranges are sanity limits, wide enough for the
    /// plane-wave limit (huge `mode_field_radius_um`) used in tests.
    pub fn validate(&self) -> Result<(), OpticsError> {
        check("mode_field_radius_um", self.mode_field_radius_um, 0.1, 1e9, "µm")?;
        check("fiber_index", self.fiber_index, 1.0, 5.0, "")?;
        check("lamella_reflectance", self.lamella_reflectance, 0.0, 1.0, "")?;
        check("cleave_angle_deg", self.cleave_angle_deg, -20.0, 20.0, "°")?;
        check("beams", self.beams as f64, 1.0, 10_000.0, "")?;
        check("input_power_mw", self.input_power_mw, 0.0, 1e6, "mW")?;
        check("gouy_scale_error", self.gouy_scale_error, -10.0, 10.0, "")?;
        if let Some(b) = &self.back_face {
            check("back_face.thickness_um", b.thickness_um, 0.0, 1e6, "µm")?;
            check("back_face.phase_index", b.phase_index, 1.0, 5.0, "")?;
            check("back_face.group_index", b.group_index, 1.0, 6.0, "")?;
            check("back_face.reference_wavelength_nm", b.reference_wavelength_nm, 100.0, 20_000.0, "nm")?;
            check("back_face.reflectance", b.reflectance, 0.0, 1.0, "")?;
        }
        Ok(())
    }
}
