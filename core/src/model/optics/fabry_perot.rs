//! The multi-beam Fabry-Perot evaluator: the model precomputed at one wavelength and medium
//! index, its field, power and two-beam fringe.

use std::f64::consts::PI;

use super::params::{check, OpticalParams, OpticsError};
use crate::model::kinematics::sin_cos;
use nalgebra::Complex;
use serde::{Deserialize, Serialize};

/// Two-beam (first-order) description of the fringe at one gap and tilt:
/// P(L) ≈ `offset_mw` + `amplitude_mw`·cos(`phase_rad`).
///
/// Uses the fiber face and the first lamella reflection only (no higher beams, no back
/// face); the multi-beam signal differs by the harmonics (a few %). This is the scale to
/// normalise detector noise against ("σ_I = 1e-3 of the fringe amplitude").
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TwoBeamFringe {
    /// Mean reflected power over a fringe, mW.
    pub offset_mw: f64,
    /// Half peak-to-peak of the fringe, mW.
    pub amplitude_mw: f64,
    /// amplitude / offset (dimensionless).
    pub visibility: f64,
    /// Fringe phase, rad (see [`FabryPerot::fringe_phase_rad`]).
    pub phase_rad: f64,
}

/// One cavity of the multi-beam sum: the fiber face and one reflector of the lamella.
#[derive(Debug, Clone, Copy)]
pub(super) struct Cavity {
    /// Effective amplitude reflectance of the lamella reflector (signed).
    pub(super) r: f64,
    /// Reduced distance added to |L| for diffraction and tilt, µm.
    pub(super) extra_reduced_um: f64,
    /// Round-trip phase added to 2k|L|, rad.
    pub(super) extra_phase_rad: f64,
    /// d(extra_phase_rad)/dk along a wavelength change (k the wavenumber in the medium), µm.
    pub(super) extra_phase_per_k_um: f64,
}

/// Below this bound on |term| the remaining beams cannot change the field (relative 1e-17).
pub(super) const NEGLIGIBLE_AMPLITUDE: f64 = 1e-17;

/// The signal model evaluated at one wavelength and medium index, constants precomputed.
///
/// Construction validates the parameters; evaluation allocates nothing and costs two
/// sin/cos (the fast [`sin_cos`], within an ulp of the standard library's), one exp and a few
/// complex products per beam.
#[derive(Debug, Clone)]
pub struct FabryPerot {
    wavelength_nm: f64,
    medium_index: f64,
    /// Wavenumber in the medium, rad/µm.
    pub(super) k_per_um: f64,
    pub(super) rayleigh_um: f64,
    /// (k·w0)²/2: ε = this·θ².
    pub(super) half_kw0_sq: f64,
    pub(super) r1: f64,
    /// r1 scaled by the cleave-angle coupling.
    pub(super) r1_direct: f64,
    /// 1 - r1².
    pub(super) t1_sq: f64,
    /// (n_fiber·w0·θc/n)²: r1_direct = r1·exp(-this·k²/2).
    pub(super) cleave_per_k_sq: f64,
    pub(super) front: Cavity,
    pub(super) back: Option<Cavity>,
    pub(super) beams: u32,
    /// Scale of the Gouy phase: 1 with it, 0 without, anything else with a Gouy-phase error.
    pub(super) gouy_scale: f64,
    input_power_mw: f64,
}

impl FabryPerot {
    /// Precomputes the model for vacuum wavelength `wavelength_nm` (100-20000 nm) and the
    /// index `medium_index` of the cavity medium (1-3; air: see `model::air`).
    pub fn new(params: &OpticalParams, wavelength_nm: f64, medium_index: f64) -> Result<Self, OpticsError> {
        params.validate()?;
        check("wavelength_nm", wavelength_nm, 100.0, 20_000.0, "nm")?;
        check("medium_index", medium_index, 1.0, 3.0, "")?;

        let k0 = 2.0 * PI / (wavelength_nm * 1e-3); // vacuum, rad/µm
        let k = k0 * medium_index;
        let w0 = params.mode_field_radius_um;
        let r1 = (params.fiber_index - medium_index) / (params.fiber_index + medium_index);
        let cleave = (k0 * params.fiber_index * w0 * params.cleave_angle_deg.to_radians()).powi(2);
        let r2 = -params.lamella_reflectance.sqrt();
        let back = params.back_face.map(|b| {
            let k_ref = 2.0 * PI / (b.reference_wavelength_nm * 1e-3);
            let kn_t = k_ref * b.phase_index + b.group_index * (k0 - k_ref);
            Cavity {
                r: (1.0 - r2 * r2) * b.reflectance.sqrt() * if b.inverted { -1.0 } else { 1.0 },
                extra_reduced_um: b.thickness_um * medium_index / b.phase_index,
                extra_phase_rad: 2.0 * kn_t * b.thickness_um,
                extra_phase_per_k_um: 2.0 * b.group_index * b.thickness_um / medium_index,
            }
        });
        Ok(Self {
            wavelength_nm,
            medium_index,
            k_per_um: k,
            rayleigh_um: 0.5 * k * w0 * w0,
            half_kw0_sq: 0.5 * (k * w0).powi(2),
            r1,
            r1_direct: r1 * (-0.5 * cleave).exp(),
            t1_sq: 1.0 - r1 * r1,
            cleave_per_k_sq: (params.fiber_index * w0 * params.cleave_angle_deg.to_radians() / medium_index).powi(2),
            front: Cavity { r: r2, extra_reduced_um: 0.0, extra_phase_rad: 0.0, extra_phase_per_k_um: 0.0 },
            back,
            beams: params.beams as u32,
            gouy_scale: f64::from(u8::from(params.gouy_phase)) + params.gouy_scale_error,
            input_power_mw: params.input_power_mw,
        })
    }

    /// Vacuum wavelength, nm.
    pub fn wavelength_nm(&self) -> f64 {
        self.wavelength_nm
    }

    /// Index of the cavity medium.
    pub fn medium_index(&self) -> f64 {
        self.medium_index
    }

    /// Rayleigh range of the fiber mode in the cavity medium, µm.
    pub fn rayleigh_range_um(&self) -> f64 {
        self.rayleigh_um
    }

    /// Gap change for one fringe far from z_R, λ/(2n), µm.
    pub fn fringe_period_um(&self) -> f64 {
        PI / self.k_per_um
    }

    /// Amplitude reflectance of the fiber face from inside the fiber (before the cleave factor).
    pub fn fiber_amplitude_reflectance(&self) -> f64 {
        self.r1
    }

    /// Wavenumber k = 2π·n/λ in the cavity medium, rad/µm.
    pub fn wavenumber_per_um(&self) -> f64 {
        self.k_per_um
    }

    /// Power launched towards the cavity, mW ([`FabryPerot::power`] is this times |E_r/E_in|²).
    pub fn input_power_mw(&self) -> f64 {
        self.input_power_mw
    }

    /// Field reflected into the fiber mode, E_r/E_in (dimensionless), at signed gap `gap_um`
    /// and tilt `tilt_rad` between lamella normal and fiber axis. Even in both arguments.
    /// Finite inputs give finite outputs (a huge tilt just extinguishes the cavity).
    pub fn field(&self, gap_um: f64, tilt_rad: f64) -> Complex<f64> {
        self.field_sums::<1, false>(&[gap_um], &[tilt_rad]).0[0]
    }

    /// [`FabryPerot::field`] (the same bits) and its derivative along the signed gap, per µm,
    /// from the same sums: what a fit of the gap needs, at a fraction of two more fields.
    pub fn field_and_gap_slope(&self, gap_um: f64, tilt_rad: f64) -> (Complex<f64>, Complex<f64>) {
        let (e, slope) = self.field_sums::<1, true>(&[gap_um], &[tilt_rad]);
        (e[0], slope[0] * gap_um.signum())
    }

    /// The fields at `K` gaps and tilts and, with `SLOPE`, their derivatives along |L|.
    fn field_sums<const K: usize, const SLOPE: bool>(
        &self,
        gaps_um: &[f64; K],
        tilts_rad: &[f64; K],
    ) -> ([Complex<f64>; K], [Complex<f64>; K]) {
        let gaps = gaps_um.map(f64::abs);
        let (front, mut slope) = self.cavity_fields::<K, SLOPE>(&self.front, &gaps, tilts_rad);
        let mut e = front.map(|f| Complex::new(self.r1_direct, 0.0) + f);
        if let Some(back) = &self.back {
            let (field, d) = self.cavity_fields::<K, SLOPE>(back, &gaps, tilts_rad);
            for k in 0..K {
                e[k] += field[k];
                slope[k] += d[k];
            }
        }
        (e, slope)
    }

    /// Reflected power reaching the detector side of the circulator, mW (the reflectance
    /// times `input_power_mw`).
    pub fn power(&self, gap_um: f64, tilt_rad: f64) -> f64 {
        self.powers(&[gap_um], &[tilt_rad])[0]
    }

    /// [`FabryPerot::power`] at `K` gaps and tilts, the same bits: the beams of every point
    /// summed side by side, so that the processor overlaps their chains of products.
    pub fn powers<const K: usize>(&self, gaps_um: &[f64; K], tilts_rad: &[f64; K]) -> [f64; K] {
        self.field_sums::<K, false>(gaps_um, tilts_rad).0.map(|e| self.input_power_mw * e.norm_sqr())
    }

    /// Unwrapped two-beam fringe phase, rad:
    /// 2k|L| - arctan(|L|/z_R) [if Gouy] - k·θ²·|L| + π, with k = 2π·n/λ.
    ///
    /// The π is the reflection phase of the lamella (r2 < 0), so that the two-beam signal is
    /// exactly offset + amplitude·cos(phase) ([`FabryPerot::two_beam`]). The k·θ²·|L| term
    /// makes the round trip 2|L|·cos θ: the fringes measure the distance from the fiber to
    /// the lamella plane along the lamella normal, not along the fiber axis (at Table II's
    /// θ = 19.46 mrad, 189 ppm less: 170 nm at 899 µm).
    ///
    /// With more than one beam, the fundamental of the full signal is pulled by the higher
    /// beams: at most 0.030 rad (3.7 nm of gap) for LiNbO3 and 0.008 rad (1.0 nm) for glass,
    /// both near |L| ≈ 70 µm, square lamella.
    pub fn fringe_phase_rad(&self, gap_um: f64, tilt_rad: f64) -> f64 {
        let gap = gap_um.abs();
        let gouy = self.gouy_scale * (gap / self.rayleigh_um).atan();
        2.0 * self.k_per_um * gap - gouy - self.k_per_um * tilt_rad * tilt_rad * gap + PI
    }

    /// Two-beam offset, amplitude, visibility and phase at one gap and tilt.
    pub fn two_beam(&self, gap_um: f64, tilt_rad: f64) -> TwoBeamFringe {
        let ell = gap_um / self.rayleigh_um;
        let a = self.r1_direct;
        let b = self.t1_sq * self.front.r.abs() * (-self.half_kw0_sq * tilt_rad * tilt_rad).exp()
            / (1.0 + ell * ell).sqrt();
        let offset = a * a + b * b;
        let amplitude = 2.0 * a * b;
        TwoBeamFringe {
            offset_mw: self.input_power_mw * offset,
            amplitude_mw: self.input_power_mw * amplitude,
            visibility: if offset > 0.0 { amplitude / offset } else { 0.0 },
            phase_rad: self.fringe_phase_rad(gap_um, tilt_rad),
        }
    }

    /// Σ_m (1 - r1²)·r^m·(-r1)^(m-1)·c_m·T_m·exp(-i·m·Φ) for one cavity at `K` gaps |L| and
    /// tilts, with every power built by recurrence (a_{m+1} - a_m = m² + m + 1,
    /// (m+1)² - m² = 2m + 1); with `SLOPE` also its derivative along |L| (each term's: -2k·m
    /// from Φ, k·θ²·a_m from its tilt phase, d ln c_m/d|L| from the Gouy factor), else zero.
    /// Each point stops at its first negligible beam, as it would alone.
    fn cavity_fields<const K: usize, const SLOPE: bool>(
        &self,
        cav: &Cavity,
        gaps_um: &[f64; K],
        tilts_rad: &[f64; K],
    ) -> ([Complex<f64>; K], [Complex<f64>; K]) {
        let zero = Complex::new(0.0, 0.0);
        let (mut sum, mut slope) = ([zero; K], [zero; K]);
        if cav.r == 0.0 {
            return (sum, slope);
        }
        let mut lanes: [Beams; K] = std::array::from_fn(|k| self.first_beam(cav, gaps_um[k], tilts_rad[k]));
        let mut coef = self.t1_sq * cav.r; // (1 - r1²)·r^m·(-r1)^(m-1)
        let coef_step = -self.r1 * cav.r;
        for m in 1..=self.beams {
            let mf = f64::from(m);
            let mut any = false;
            for ((b, sum), slope) in lanes.iter_mut().zip(&mut sum).zip(&mut slope) {
                if !b.active {
                    continue;
                }
                let x = mf * b.ell;
                let inv = 1.0 / (1.0 + x * x);
                let c_m = if self.gouy_scale == 1.0 {
                    Complex::new(inv, x * inv)
                } else if self.gouy_scale == 0.0 {
                    Complex::new(inv.sqrt(), 0.0)
                } else {
                    Complex::from_polar(inv.sqrt(), self.gouy_scale * x.atan())
                };
                let weight = coef * b.q_m;
                let term = c_m * b.phase * weight;
                *sum += term;
                if SLOPE {
                    let a_m = mf * (mf * mf + 2.0) / 3.0;
                    let d_ln_c = Complex::new(-x, self.gouy_scale) * inv; // d ln c_m / dx
                    *slope += term
                        * (Complex::new(0.0, b.k_tilt * a_m - 2.0 * self.k_per_um * mf)
                            + d_ln_c * (mf / self.rayleigh_um));
                }
                if weight.abs() < NEGLIGIBLE_AMPLITUDE {
                    b.active = false;
                    continue;
                }
                any = true;
                b.q_m *= b.q_step;
                b.q_step *= b.q2;
                b.phase *= b.base * b.z_step;
                b.z_step *= b.z_grow;
                b.z_grow *= b.z2;
            }
            if !any {
                break;
            }
            coef *= coef_step;
        }
        (sum, slope)
    }

    /// The recurrence of [`FabryPerot::cavity_fields`] at its first beam, at gap |L| `gap_um`
    /// and tilt `tilt_rad`; inactive when the tilt extinguishes the cavity.
    #[inline]
    fn first_beam(&self, cav: &Cavity, gap_um: f64, tilt_rad: f64) -> Beams {
        let q = (-self.half_kw0_sq * tilt_rad * tilt_rad).exp(); // |T_1|
        let dist = gap_um + cav.extra_reduced_um;
        let (s, c) = sin_cos(2.0 * self.k_per_um * gap_um + cav.extra_phase_rad);
        let base = Complex::new(c, -s); // exp(-iΦ)
        let (zs, zc) = sin_cos(self.k_per_um * tilt_rad * tilt_rad * dist);
        let z = Complex::new(zc, zs); // exp(+i·k·θ²·dist)
        let z2 = z * z;
        Beams {
            active: q != 0.0,
            ell: dist / self.rayleigh_um,
            k_tilt: self.k_per_um * tilt_rad * tilt_rad,
            q_m: q,            // q^(m²)
            q_step: q * q * q, // q^(2m+1)
            q2: q * q,
            base,
            phase: base * z, // base^m · z^(a_m)
            z_step: z2 * z,  // z^(m²+m+1)
            z_grow: z2 * z2, // z^(2m+2)
            z2,
        }
    }
}

/// One point's state in the beam recurrence of [`FabryPerot::cavity_fields`], at beam m.
#[derive(Clone, Copy)]
struct Beams {
    /// Summing: no beam so far was negligible.
    active: bool,
    /// (|L| + the cavity's extra distance) / z_R.
    ell: f64,
    /// k·θ², rad/µm.
    k_tilt: f64,
    q_m: f64,
    q_step: f64,
    q2: f64,
    base: Complex<f64>,
    phase: Complex<f64>,
    z_step: Complex<f64>,
    z_grow: Complex<f64>,
    z2: Complex<f64>,
}

/// Reflected power, mW, at one gap, tilt, vacuum wavelength and medium index (builds a
/// [`FabryPerot`]; in loops, build it once and call [`FabryPerot::power`]).
pub fn reflected_power(
    params: &OpticalParams,
    gap_um: f64,
    tilt_rad: f64,
    wavelength_nm: f64,
    medium_index: f64,
) -> Result<f64, OpticsError> {
    Ok(FabryPerot::new(params, wavelength_nm, medium_index)?.power(gap_um, tilt_rad))
}

/// Two-beam fringe phase, rad (see [`FabryPerot::fringe_phase_rad`]).
pub fn fringe_phase_rad(
    params: &OpticalParams,
    gap_um: f64,
    tilt_rad: f64,
    wavelength_nm: f64,
    medium_index: f64,
) -> Result<f64, OpticsError> {
    Ok(FabryPerot::new(params, wavelength_nm, medium_index)?.fringe_phase_rad(gap_um, tilt_rad))
}

/// Two-beam fringe offset, amplitude, visibility and phase (see [`FabryPerot::two_beam`]).
pub fn two_beam_fringe(
    params: &OpticalParams,
    gap_um: f64,
    tilt_rad: f64,
    wavelength_nm: f64,
    medium_index: f64,
) -> Result<TwoBeamFringe, OpticsError> {
    Ok(FabryPerot::new(params, wavelength_nm, medium_index)?.two_beam(gap_um, tilt_rad))
}
