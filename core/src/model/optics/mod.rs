//! Fabry-Perot signal model: the power the fiber/lamella cavity reflects back into the fiber.
//! Owns the optical parameters, the Gaussian-beam couplings (defocus, tilt, Gouy phase) and the multi-beam sum.
//!
//! Units: lengths in µm, wavelengths in nm (vacuum unless a name says otherwise), angles in
//! rad (degrees only where a field name says `_deg`), powers in mW.
//!
//! # The model
//!
//! The fiber end face (amplitude reflectance r1 = (n_fiber - n)/(n_fiber + n), n the index
//! of the cavity medium, normally air) and the lamella face (r2 = -√R2: air to a denser
//! dielectric, a π phase shift) form a low-finesse cavity of gap |L|. The field coupled back
//! into the fiber mode is
//!
//! ```text
//! E_r/E_in = r1·g_c + (1 - r1²) · Σ_{m=1..beams} r2^m · (-r1)^(m-1) · c_m · T_m · exp(-i·2m·k·|L|)
//! ```
//!
//! with k = 2π·n/λ the wavenumber in the medium and z_R = k·w0²/2 its Rayleigh range:
//! - `c_m = 1/(1 - i·m·|L|/z_R)`: overlap of the fiber mode with itself after 2m·|L| of free
//!   propagation (defocus); |c_1|² = 1/(1 + (L/z_R)²), and arg c_m = arctan(m·|L|/z_R) is the
//!   Gouy phase. With `gouy_phase = false`, |c_m| is used instead (the Gouy phase only).
//! - `T_m = exp(-m²·ε) · exp(i·a_m·k·θ²·|L|)`, ε = (k·w0·θ)²/2, a_m = m(m² + 2)/3: the tilt
//!   factor of a lamella whose normal makes an angle θ with the fiber axis. Beam m has been
//!   reflected m times by the lamella, so it returns tilted by 2mθ and walked off laterally by
//!   2θ·m²·|L|. Treating each lamella reflection as a phase kick exp(-2ikθx) between Gaussian
//!   propagations gives this closed form exactly (paraxial): the walk-off does not change
//!   the magnitude, which is the overlap of two Gaussians at an angle 2mθ, and the phase
//!   a_m·k·θ²·|L| is the path shortening of the tilted beams (for m = 1, the round trip is
//!   2·|L|·cos θ: the gap measured along the lamella normal). For m = 1, |T_1|² is the usual
//!   tilt loss exp(-(2π·w0·θ/λ)²): its θ is the angle between the normals, and the
//!   doubling of the angle on reflection is inside the formula. The test
//!   `round_trip_coupling_matches_paraxial_angular_spectrum` checks c_m·T_m against a
//!   numerical angular-spectrum propagation.
//! - `g_c = exp(-(k0·n_fiber·w0·θc)²/2)`, k0 = 2π/λ: the cleave angle θc tilts the fiber face,
//!   so its own reflection returns tilted by 2θc inside the glass (power factor
//!   exp(-(2π·n_fiber·w0·θc/λ)²)). Approximation: the cleave angle only scales this
//!   direct reflection; the refraction of the outgoing beam, (n_fiber - 1)·θc, and the kicks of
//!   the intracavity reflections on the tilted face are neglected (θ is measured from the
//!   fiber axis).
//!
//! Sign conventions: the phase uses the physical gap |L| (the signed L of the measurement
//! equation is about -899 µm at Table II values; the signal is even in L). The time
//! convention is exp(+iωt), so propagation is exp(-ikz) and the Gouy phase enters with +.
//!
//! Optional back face ([`BackFace`]): a transparent lamella of thickness t adds a second cavity
//! fiber ↔ back face, summed with the same formula with amplitude reflectance
//! (1 - R2)·√R_back, phase 2·(k·|L| + k0·n(λ)·t) with n(λ)·k0 linearised about the reference
//! wavelength (phase index n_p there, slope the group index n_g: a wavelength sweep sees the
//! optical thickness n_g·t), and Gaussian propagation over the reduced distance |L| + t·n/n_p
//! (a slab of index n_p diffracts like t/n_p of vacuum; the back face is parallel to the
//! front one, so the tilt is the same θ). Approximation: paths that reflect on both faces
//! of the lamella and bounces inside the lamella are neglected; they are smaller than the
//! back-face beams by a factor r1·|r2| or |r2|·√R_back (≤ 7 % for LiNbO3 on both faces).
//!
//! For dense sampling (the virtual bench), [`FringeExpansion`] rewrites the sum as a
//! polynomial in two exact phasors, the first beam's round-trip phase and the tilt phase, with
//! slowly varying coefficients and their analytic derivatives.
//!
//! # The fringe's visibility and harmonics
//!
//! - Two-beam visibility at |L| ≈ 900 µm: 0.23 for LiNbO3 (R2 = 0.142), 0.22 for R2 = 0.132,
//!   0.12 for glass (R2 = 0.04): the often quoted "≈ 0.2" holds for LiNbO3 (0.2 exactly needs R2 ≈ 0.11).
//! - Second harmonic of the fringe, H2/H1 ≈ r1·√R2·|c_2/c_1|·e^{-3ε}: it is twice as large at
//!   small gaps (|c_2/c_1| → 1) as at |L| ≫ z_R (|c_2/c_1| → 1/2). Glass: 3.6 % at 2 µm,
//!   3.2 % at 20 µm, 1.9 % at 900 µm; LiNbO3: 7.0 % at 2 µm, 6.2 % at 20 µm, 3.6 % at 900 µm.
//!   So the often quoted "2 % for glass" is the large-gap value and "up to 7 % for LiNbO3" the
//!   small-gap one; a tilt lowers both by e^{-3ε} (0.82 at 1°).

mod fabry_perot;
mod fringe_expansion;
mod fringe_shape;
mod gaussian_coupling;
mod params;

pub use fabry_perot::{fringe_phase_rad, reflected_power, two_beam_fringe, FabryPerot, TwoBeamFringe};
pub use fringe_expansion::{tilt_phase_order, FringeExpansion};
pub use fringe_shape::FringeShape;
pub use gaussian_coupling::{divergence_rad, power_coupling, rayleigh_range_um, round_trip_coupling, tilt_coupling};
pub use params::{BackFace, OpticalParams, OpticsError};

#[cfg(test)]
mod tests;
