//! The shape of the multi-beam fringe relative to its fundamental: the pulling of its phase
//! and its 2nd and 3rd harmonics.

use std::f64::consts::PI;

use super::fabry_perot::FabryPerot;
use super::fringe_expansion::{tilt_phasors, FringeExpansion};
use crate::model::kinematics::sin_cos;
use nalgebra::Complex;

/// The shape of the multi-beam fringe at one gap and tilt, relative to its fundamental:
/// `P = P0 + P1·[cos φ + Re(h2·e^{2iφ}) + Re(h3·e^{3iφ})] + ...`, φ the fundamental's phase.
///
/// With P = |Σ_m D_m·u^m|², D_m = B_m·w^(e_m) ([`FringeExpansion`]), the harmonic k of the
/// power is 2·Re(G_k·u^k), G_k = Σ_n D_{n+k}·conj(D_n): φ = Φ - arg G1 and
/// h_k = |G_k|/|G_1|·exp(i·(k·arg G_1 - arg G_k)). On a rotation the tilt phase ψ moves
/// beam m by e_m·ψ, so the 2nd harmonic turns by -2ψ against the fundamental (as fast as
/// the fringes themselves when the motion is all tilt): a harmonic that is a fixed function
/// of φ cannot describe it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FringeShape {
    /// φ - [`FabryPerot::fringe_phase_rad`], wrapped to (-π, π]: how far the higher beams pull
    /// the fundamental away from the first beam's phase, rad.
    pub pulling_rad: f64,
    /// P0 / input power (G0 = Σ|D_m|², dimensionless).
    pub offset: f64,
    /// P1 / input power (2|G1|, dimensionless).
    pub fundamental: f64,
    /// h2.
    pub second: Complex<f64>,
    /// h3.
    pub third: Complex<f64>,
}

impl FabryPerot {
    /// Unwrapped phase of the fringe's fundamental, rad: [`FabryPerot::fringe_phase_rad`] plus
    /// the pulling of the higher beams ([`FringeShape::pulling_rad`]). This is what a phase
    /// tracker measures; over a ±4° rotation at 900 µm the pulling moves by up to 0.9 nm of
    /// gap (LiNbO3).
    /// It runs per sample (motion hints) and per prediction (identifier): the expansion's
    /// buffers are kept per thread.
    pub fn fundamental_phase_rad(&self, gap_um: f64, tilt_rad: f64) -> f64 {
        thread_local! {
            static SCRATCH: std::cell::RefCell<FringeExpansion> = std::cell::RefCell::new(FringeExpansion::default());
        }
        let two_beam = self.fringe_phase_rad(gap_um, tilt_rad);
        two_beam + SCRATCH.with(|ex| self.pulling_rad(gap_um, tilt_rad, two_beam, &mut ex.borrow_mut()))
    }

    /// [`FringeShape::pulling_rad`] alone: the fundamental G₁ without the harmonics, from the
    /// expansion's coefficients without their derivatives (the same sums, the same bits);
    /// `two_beam` is [`FabryPerot::fringe_phase_rad`] at the same gap and tilt.
    fn pulling_rad(&self, gap_um: f64, tilt_rad: f64, two_beam: f64, scratch: &mut FringeExpansion) -> f64 {
        let t = tilt_rad * tilt_rad;
        self.expansion_coefficients(gap_um, t, scratch);
        let (phi, psi) = self.expansion_phases_rad(gap_um, t);
        let (ws, wc) = sin_cos(psi);
        let w = Complex::new(wc, ws);
        let mut g1 = Complex::new(0.0, 0.0);
        let mut prev = g1;
        for (b, wp) in scratch.coefficients.iter().zip(tilt_phasors(w)) {
            let d = b * wp;
            g1 += d * prev.conj();
            prev = d;
        }
        wrap_pi(phi - g1.arg() - two_beam)
    }

    /// The fringe's shape at gap `gap_um` and tilt `tilt_rad` ([`FringeShape`]); `scratch`
    /// is reused between calls.
    pub fn fringe_shape(&self, gap_um: f64, tilt_rad: f64, scratch: &mut FringeExpansion) -> FringeShape {
        let t = tilt_rad * tilt_rad;
        self.expansion_coefficients(gap_um, t, scratch);
        let (phi, psi) = self.expansion_phases_rad(gap_um, t);
        let (ws, wc) = sin_cos(psi);
        let w = Complex::new(wc, ws);
        let zero = Complex::new(0.0, 0.0);
        let mut g = [zero; 4];
        let mut g0 = 0.0;
        // prev[k - 1] = D_{m-k}: the three beams before m (zero before the first)
        let mut prev = [zero; 3];
        for (b, wp) in scratch.coefficients.iter().zip(tilt_phasors(w)) {
            let d = b * wp;
            g0 += d.norm_sqr();
            for (gk, p) in g[1..].iter_mut().zip(&prev) {
                *gk += d * p.conj();
            }
            prev = [d, prev[0], prev[1]];
        }
        let a1 = g[1].arg();
        let rel = |k: usize| {
            if g[1].norm() > 0.0 {
                let chi = k as f64 * a1 - g[k].arg();
                Complex::from_polar(g[k].norm() / g[1].norm(), chi)
            } else {
                zero
            }
        };
        FringeShape {
            pulling_rad: wrap_pi(phi - a1 - self.fringe_phase_rad(gap_um, tilt_rad)),
            offset: g0,
            fundamental: 2.0 * g[1].norm(),
            second: rel(2),
            third: rel(3),
        }
    }
}

/// `a` wrapped to [−π, π).
fn wrap_pi(a: f64) -> f64 {
    a - 2.0 * PI * ((a + PI) / (2.0 * PI)).floor()
}
