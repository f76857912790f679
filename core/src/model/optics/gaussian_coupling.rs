//! Gaussian-beam couplings of the fiber mode: Rayleigh range, divergence, tilt and defocus
//! losses, and the complex coupling of one beam after m round trips.

use std::f64::consts::PI;

use nalgebra::Complex;

/// Rayleigh range z_R = π·w0²/λ of a Gaussian beam of waist radius w0, µm.
///
/// `wavelength_nm` is the wavelength in the medium (λ_vac/n_air in air; the difference,
/// 268 ppm, is usually negligible). SMF-28 at 1560 nm: 54 µm.
pub fn rayleigh_range_um(mode_field_radius_um: f64, wavelength_nm: f64) -> f64 {
    PI * mode_field_radius_um * mode_field_radius_um / (wavelength_nm * 1e-3)
}

/// Far-field divergence half-angle λ/(π·w0) of the fiber mode, rad (SMF-28: 95 mrad).
pub fn divergence_rad(mode_field_radius_um: f64, wavelength_nm: f64) -> f64 {
    wavelength_nm * 1e-3 / (PI * mode_field_radius_um)
}

/// Power coupling loss from a lamella tilt, exp(-(2π·w0·θ/λ)²).
///
/// `tilt_rad` is the angle θ between the lamella normal n_t and the fiber axis n_f (not the
/// angle of the returning beam, which is 2θ: the doubling is inside the formula). It does
/// not depend on the gap. SMF-28 at 1560 nm: 1° → 0.875, 2° → 0.586, 3° → 0.300,
/// 5° → 0.035. `wavelength_nm` as in [`rayleigh_range_um`].
pub fn tilt_coupling(mode_field_radius_um: f64, tilt_rad: f64, wavelength_nm: f64) -> f64 {
    let x = 2.0 * PI * mode_field_radius_um * tilt_rad / (wavelength_nm * 1e-3);
    (-x * x).exp()
}

/// First-pass power coupling η(L, θ) = tilt_coupling / (1 + (L/z_R)²) of the beam reflected
/// once by the lamella back into the fiber mode (SMF-28 at 900 µm, square: 0.0036).
pub fn power_coupling(mode_field_radius_um: f64, gap_um: f64, tilt_rad: f64, wavelength_nm: f64) -> f64 {
    let l = gap_um / rayleigh_range_um(mode_field_radius_um, wavelength_nm);
    tilt_coupling(mode_field_radius_um, tilt_rad, wavelength_nm) / (1.0 + l * l)
}

/// Complex amplitude coupling c_m·T_m of the beam that made `round_trips` = m round trips
/// in the cavity, Gouy phase included, without the propagation phase exp(-2imk|L|).
///
/// c_m = 1/(1 - i·m·|L|/z_R), T_m = exp(-m²·ε + i·m(m²+2)/3·k·θ²·|L|), ε = (k·w0·θ)²/2
/// (see the module documentation). |result|² for m = 1 is [`power_coupling`].
/// `wavelength_nm` is the wavelength in the medium.
pub fn round_trip_coupling(
    mode_field_radius_um: f64,
    gap_um: f64,
    tilt_rad: f64,
    wavelength_nm: f64,
    round_trips: u32,
) -> Complex<f64> {
    let k = 2.0 * PI / (wavelength_nm * 1e-3);
    let z_r = rayleigh_range_um(mode_field_radius_um, wavelength_nm);
    let m = f64::from(round_trips);
    let gap = gap_um.abs();
    let c_m = Complex::new(1.0, 0.0) / Complex::new(1.0, -m * gap / z_r);
    let half_kw = 0.5 * (k * mode_field_radius_um * tilt_rad).powi(2);
    let tilt = Complex::new(-m * m * half_kw, m * (m * m + 2.0) / 3.0 * k * tilt_rad * tilt_rad * gap).exp();
    c_m * tilt
}
