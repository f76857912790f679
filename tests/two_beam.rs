//! A second optics model, deliberately unlike the core's: two beams instead of many, a fiber mode
//! that is elliptical with a wide pedestal (not a circular Gaussian), the round-trip coupling from
//! the exact paraxial overlap of that mode (another law for tilt and defocus), the Gouy phase on or
//! off, a weak beam from a wedged back face, all written from the physics alone.
//!
//! # The model
//!
//! The field coupled back into the fiber mode M is
//!
//! ```text
//! E/E_in = r1 + (1 − r1²)·r2·C(|L|, θ)·e^{−i·2k|L|} + (1 − r1²)(1 − r2²)·r_b·C(|L| + t/n, θ_b)·e^{−i·2(k|L| + k0·n·t)}
//! ```
//!
//! with k = 2π·n_air/λ, k0 = 2π/λ. `C` is the overlap ⟨M | P·K·P | M⟩ / ⟨M|M⟩ of the mode with
//! itself propagated (P, Fresnel) over |L| to the lamella, kicked there by the lamella's tilt (K, a
//! phase e^{−ikα·x} with α twice the tilt, per transverse axis) and propagated back. The mode is a sum
//! of elliptical Gaussians `Σ a_j·exp(−u²/w_uj² − v²/w_vj²)` on axes (u, v) turned by
//! `mode_angle_deg` from the fiber frame's X and Z axes; each pair of components overlaps in closed
//! form per axis (a complex Gaussian integral, [`axis_overlap`]). So the tilt loss depends on the
//! direction of the tilt, and falls off more slowly than one Gaussian where the pedestal carries it.
//! With `gouy: false` the coupling keeps only its magnitude and the path along the lamella normal,
//! 2|L|·cos θ: a world without the Gouy phase, which the core's model always has.
//!
//! The back face of a lamella of thickness t and index n is wedged by `wedge_deg`: its reflection
//! leaves the lamella turned by about 2·n·wedge, so it couples as a mirror tilted by n·wedge more
//! than the front face, toward `wedge_direction_deg` in the lamella plane; it diffracts over
//! |L| + t/n. Bounces inside the lamella and between lamella and fiber are left out (two beams).

use nalgebra::{Complex, Vector3};
use std::f64::consts::PI;

use crate::independent::Geometry;

/// One Gaussian component of the fiber mode: amplitude and 1/e field radii along the mode's axes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModeComponent {
    /// Relative field amplitude at the centre.
    pub amplitude: f64,
    /// 1/e field radius along the mode's u axis (µm).
    pub w_u_um: f64,
    /// 1/e field radius along the mode's v axis (µm).
    pub w_v_um: f64,
}

/// A wedged, weakly reflecting back face of the lamella.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WedgedBackFace {
    /// Lamella thickness (µm).
    pub thickness_um: f64,
    /// Lamella index (phase and group alike: no dispersion in this model).
    pub index: f64,
    /// Power reflectance of the back face from inside (an AR coating's residual).
    pub reflectance: f64,
    /// Angle between the two faces (°).
    pub wedge_deg: f64,
    /// Direction of the wedge in the lamella plane, from the tool frame's X axis toward its Y (°).
    pub wedge_direction_deg: f64,
}

/// The second optics model; see the module documentation.
#[derive(Debug, Clone, PartialEq)]
pub struct TwoBeamOptics {
    /// Fiber core index (the fiber face's Fresnel reflection).
    pub fiber_index: f64,
    /// Power reflectance of the lamella's front face.
    pub lamella_reflectance: f64,
    /// Index of the air in the cavity.
    pub air_index: f64,
    /// The fiber mode as a sum of elliptical Gaussians.
    pub mode: Vec<ModeComponent>,
    /// Angle of the mode's u axis from the fiber frame's X axis toward its Z axis (°).
    pub mode_angle_deg: f64,
    /// The coupling's own phase (Gouy and tilt) kept, or only its magnitude with the path 2|L|·cos θ.
    pub gouy: bool,
    /// A wedged back face, if any.
    pub back_face: Option<WedgedBackFace>,
}

impl Default for TwoBeamOptics {
    /// An SMF-28 whose mode is 2 % elliptical with a pedestal of 1 % of its field at twice the
    /// radius (its tilt loss 1-7 % off a Gaussian's at 1-3°, 14 % at 4°), an LiNbO3 lamella
    /// 300 µm thick wedged by 1.5° with a 0.05 % back face, Gouy phase on.
    fn default() -> Self {
        Self {
            fiber_index: 1.4682,
            lamella_reflectance: 0.142,
            air_index: 1.0002681,
            mode: vec![
                ModeComponent { amplitude: 1.0, w_u_um: 5.15, w_v_um: 5.25 },
                ModeComponent { amplitude: 0.01, w_u_um: 10.0, w_v_um: 10.2 },
            ],
            mode_angle_deg: 30.0,
            gouy: true,
            back_face: Some(WedgedBackFace {
                thickness_um: 300.0,
                index: 2.14,
                reflectance: 0.0005,
                wedge_deg: 1.5,
                wedge_direction_deg: 40.0,
            }),
        }
    }
}

/// The overlap along one axis of a launched Gaussian `exp(−x²/w_l²)` propagated over `2·d_um`
/// with a tilt kick `α` at `d_um`, with a received Gaussian `exp(−x²/w_r²)`; `k` the wavenumber
/// (rad/µm). Paraxial, propagation e^{−ikz}: a kick e^{−ikαx} propagated over d shifts the beam
/// by α·d and adds the phase kα²d/2 (the shift theorem of the Fresnel integral), so the launched
/// field at the end is `√(q0/q)·exp(−ik(x − α·d)²/(2q) − ikα·x + ikα²d/2)`, q0 = i·k·w_l²/2,
/// q = 2d + q0; the integral of `exp(−a·x² − b·x − c)` is `√(π/a)·exp(b²/(4a) − c)`.
pub fn axis_overlap(w_l_um: f64, w_r_um: f64, d_um: f64, alpha_rad: f64, k: f64) -> Complex<f64> {
    let i = Complex::new(0.0, 1.0);
    let q0 = i * (k * w_l_um * w_l_um / 2.0);
    let q = q0 + 2.0 * d_um;
    let a = Complex::new(1.0 / (w_r_um * w_r_um), 0.0) + i * k / (q * 2.0);
    let b = i * k * alpha_rad * (Complex::new(1.0, 0.0) - d_um / q);
    let c = i * k * alpha_rad * alpha_rad * d_um * d_um / (q * 2.0) - i * (k * alpha_rad * alpha_rad * d_um / 2.0);
    (q0 / q).sqrt() * (Complex::new(PI, 0.0) / a).sqrt() * (b * b / (a * 4.0) - c).exp()
}

impl TwoBeamOptics {
    /// The complex round-trip coupling `C` of the module documentation over a distance `d_um` to a
    /// mirror whose normal makes angles `(θ_u, θ_v)` (rad) with the fiber axis along the mode's axes.
    pub fn coupling(&self, d_um: f64, tilt_uv_rad: [f64; 2], wavelength_nm: f64) -> Complex<f64> {
        let k = 2.0 * PI * self.air_index / (wavelength_nm * 1e-3);
        let (mut overlap, mut norm) = (Complex::new(0.0, 0.0), 0.0);
        for launched in &self.mode {
            for received in &self.mode {
                let u = axis_overlap(launched.w_u_um, received.w_u_um, d_um, 2.0 * tilt_uv_rad[0], k);
                let v = axis_overlap(launched.w_v_um, received.w_v_um, d_um, 2.0 * tilt_uv_rad[1], k);
                let weight = launched.amplitude * received.amplitude;
                overlap += u * v * weight;
                let self_overlap = |a: f64, b: f64| (PI / (1.0 / (a * a) + 1.0 / (b * b))).sqrt();
                norm += weight
                    * self_overlap(launched.w_u_um, received.w_u_um)
                    * self_overlap(launched.w_v_um, received.w_v_um);
            }
        }
        overlap / norm
    }

    /// The mirror tilt of a reflector of normal `normal` along the mode's axes (rad).
    fn tilt_uv(&self, g: &Geometry, normal: &Vector3<f64>) -> [f64; 2] {
        let facing = if normal.dot(&g.n_f) < 0.0 { -normal } else { *normal };
        let (s, c) = self.mode_angle_deg.to_radians().sin_cos();
        let u = g.fiber_x * c + g.fiber_z * s;
        let v = g.fiber_z * c - g.fiber_x * s;
        let along = facing.dot(&g.n_f);
        [facing.dot(&u).atan2(along), facing.dot(&v).atan2(along)]
    }

    /// One returning beam: the coupling over `d_um` at the tilt of `normal`, with the path phase.
    fn beam(
        &self,
        g: &Geometry,
        normal: &Vector3<f64>,
        d_um: f64,
        extra_phase: f64,
        wavelength_nm: f64,
    ) -> Complex<f64> {
        let k = 2.0 * PI * self.air_index / (wavelength_nm * 1e-3);
        let tilt = self.tilt_uv(g, normal);
        let c = self.coupling(d_um, tilt, wavelength_nm);
        let gap = g.l_um.abs();
        let phase = if self.gouy {
            c.arg() - 2.0 * k * gap
        } else {
            let cos_theta = normal.dot(&g.n_f).abs().min(1.0);
            -2.0 * k * gap * cos_theta
        };
        Complex::from_polar(c.norm(), phase - extra_phase)
    }

    /// Reflected power as a fraction of the input for the cavity `g` at `wavelength_nm`.
    pub fn reflectance(&self, g: &Geometry, wavelength_nm: f64) -> f64 {
        let r1 = (self.fiber_index - self.air_index) / (self.fiber_index + self.air_index);
        // Fresnel, air to the denser lamella: a π phase on reflection.
        let r2 = -self.lamella_reflectance.sqrt();
        let gap = g.l_um.abs();
        let mut field = Complex::new(r1, 0.0) + self.beam(g, &g.n_t, gap, 0.0, wavelength_nm) * ((1.0 - r1 * r1) * r2);
        if let Some(b) = &self.back_face {
            let k0 = 2.0 * PI / (wavelength_nm * 1e-3);
            let (s, c) = b.wedge_direction_deg.to_radians().sin_cos();
            let deviation = (g.tool_x * c + g.tool_y * s) * (b.index * b.wedge_deg.to_radians());
            let normal = (g.n_t + deviation).normalize();
            let amplitude = (1.0 - r1 * r1) * (1.0 - r2 * r2) * b.reflectance.sqrt();
            let d = gap + b.thickness_um / b.index;
            field += self.beam(g, &normal, d, 2.0 * k0 * b.index * b.thickness_um, wavelength_nm) * amplitude;
        }
        field.norm_sqr()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn circular(w: f64) -> TwoBeamOptics {
        TwoBeamOptics {
            mode: vec![ModeComponent { amplitude: 1.0, w_u_um: w, w_v_um: w }],
            back_face: None,
            ..TwoBeamOptics::default()
        }
    }

    /// A circular Gaussian mode gives SPEC section 5's closed forms: power coupling
    /// exp(−(2π·w0·θ/λ)²)/(1 + (L/z_R)²) whatever the gap, and the Gouy phase arctan(L/z_R).
    #[test]
    fn a_circular_gaussian_gives_the_spec_coupling() {
        let o = TwoBeamOptics { air_index: 1.0, ..circular(5.2) };
        let lambda_um = 1.56;
        let z_r = PI * 5.2 * 5.2 / lambda_um;
        for gap in [0.0, 20.0, 54.0, 200.0, 900.0] {
            for deg in [0.0f64, 1.0, 2.0, 3.0] {
                let t = deg.to_radians();
                let c = o.coupling(gap, [t * 0.6, t * 0.8], 1560.0);
                let want = (-(2.0 * PI * 5.2 * t / lambda_um).powi(2)).exp() / (1.0 + (gap / z_r).powi(2));
                assert!((c.norm_sqr() / want - 1.0).abs() < 1e-9, "L {gap}, {deg}°: {} vs {want}", c.norm_sqr());
                if deg == 0.0 {
                    assert!((c.arg() - (gap / z_r).atan()).abs() < 1e-9, "Gouy phase at {gap}: {}", c.arg());
                }
            }
        }
    }

    /// The tilt shortens the round trip to the path along the lamella normal, 2|L|·cos θ: for one
    /// Gaussian the coupling's phase grows by k·|L|·θ² exactly (paraxial, as SPEC section 5's
    /// image geometry gives); the default mode's pedestal moves it by a few per cent near the fiber.
    #[test]
    fn a_tilt_shortens_the_path_to_the_one_along_the_normal() {
        let k = 2.0 * PI * TwoBeamOptics::default().air_index / 1.56;
        for (o, tolerance) in [(circular(5.2), 1e-9), (TwoBeamOptics::default(), 0.05)] {
            for (gap, deg) in [(900.0, 1.0), (900.0, 3.0), (300.0, 2.0)] {
                let t = f64::to_radians(deg);
                let (c0, c) = (o.coupling(gap, [0.0, 0.0], 1560.0), o.coupling(gap, [t * 0.6, t * 0.8], 1560.0));
                let want = k * gap * t * t;
                let grown = want + ((c / c0).arg() - want + PI).rem_euclid(2.0 * PI) - PI;
                assert!((grown / want - 1.0).abs() < tolerance, "L {gap}, {deg}°: phase {grown}, path {want}");
            }
        }
    }

    /// Brute force: the closed-form overlap along one axis against the Fresnel integrals computed
    /// by quadrature (propagate to the mirror, kick, propagate back, overlap), for unequal widths.
    #[test]
    fn the_axis_overlap_matches_numerical_fresnel_propagation() {
        let (w_l, w_r, d, alpha, k) = (5.0, 7.0, 60.0, 0.03, 2.0 * PI / 1.56);
        let fresnel = |field: &[(f64, Complex<f64>)], at: &[f64], z: f64| -> Vec<Complex<f64>> {
            let i = Complex::new(0.0, 1.0);
            // The kernel of propagation e^{−ikz}: √(i·k/(2πz))·e^{−ik(x−x')²/(2z)}.
            let pre = (i * (k / (2.0 * PI * z))).sqrt();
            let dx = field[1].0 - field[0].0;
            at.iter()
                .map(|&x| {
                    field.iter().map(|&(xp, u)| u * (-i * k * (x - xp).powi(2) / (2.0 * z)).exp()).sum::<Complex<f64>>()
                        * pre
                        * dx
                })
                .collect()
        };
        let grid: Vec<f64> = (0..2400).map(|j| -120.0 + 240.0 * j as f64 / 2400.0).collect();
        let launched: Vec<(f64, Complex<f64>)> =
            grid.iter().map(|&x| (x, Complex::new((-(x / w_l).powi(2)).exp(), 0.0))).collect();
        let at_mirror = fresnel(&launched, &grid, d);
        let kicked: Vec<(f64, Complex<f64>)> =
            grid.iter().zip(at_mirror).map(|(&x, u)| (x, u * Complex::new(0.0, -k * alpha * x).exp())).collect();
        let near: Vec<f64> = (0..400).map(|j| -25.0 + 50.0 * j as f64 / 400.0).collect();
        let back = fresnel(&kicked, &near, d);
        let numeric: Complex<f64> =
            near.iter().zip(back).map(|(&x, u)| u * (-(x / w_r).powi(2)).exp()).sum::<Complex<f64>>() * (50.0 / 400.0);
        let closed = axis_overlap(w_l, w_r, d, alpha, k);
        assert!((numeric - closed).norm() < 2e-3 * closed.norm(), "numeric {numeric}, closed form {closed}");
    }

    /// The default mode: the tilt loss depends on the direction of the tilt, and the pedestal
    /// makes it fall otherwise than the core's Gaussian law at large tilt.
    #[test]
    fn the_default_mode_couples_unlike_a_circular_gaussian() {
        let o = TwoBeamOptics::default();
        let t = 2f64.to_radians();
        let along_u = o.coupling(900.0, [t, 0.0], 1560.0).norm_sqr();
        let along_v = o.coupling(900.0, [0.0, t], 1560.0).norm_sqr();
        let square = o.coupling(900.0, [0.0, 0.0], 1560.0).norm_sqr();
        assert!((along_u / along_v - 1.0).abs() > 0.02, "u {along_u}, v {along_v}");
        let gaussian_5_2 = (-(2.0 * PI * 5.2 * 4f64.to_radians() / 1.56).powi(2)).exp();
        let at_4 = o.coupling(900.0, [4f64.to_radians(), 0.0], 1560.0).norm_sqr() / square;
        assert!((at_4 / gaussian_5_2 - 1.0).abs() > 0.05, "loss at 4°: {at_4} against a Gaussian's {gaussian_5_2}");
    }
}
