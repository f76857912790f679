//! The field as a polynomial in two exact phasors with slowly varying coefficients and their
//! analytic derivatives, for evaluators that sample the signal densely.

use super::fabry_perot::{Cavity, FabryPerot, NEGLIGIBLE_AMPLITUDE};
use nalgebra::Complex;

/// The field split into two exact phasors and slowly varying coefficients, for evaluators that
/// sample the signal densely (the virtual bench):
///
/// ```text
/// E_r/E_in = Σ_{m=0..M} B_m · u^m · w^(e_m),   u = exp(-i·Φ), Φ = k·|L|·(2 - θ²),
///                                               w = exp(+i·ψ), ψ = k·θ²·|L|,  e_m = m(m² - 1)/3
/// ```
///
/// Φ is the round-trip phase of the first beam (2k|L| less its tilt phase k·θ²·|L|) and
/// e_m·ψ = (a_m - m)·k·θ²·|L| the extra tilt phase of beam m (module documentation): both
/// move with the gap and the tilt much faster than the rest. B_0 = r1·g_c and, for m ≥ 1,
/// B_m = Σ_cavities (1 - r1²)·r^m·(-r1)^(m-1)·c_m(d)·exp(-m²·ε)·exp(i·(a_m·k·θ²·d_x - m·φ_x)),
/// with d = |L| + d_x, d_x and φ_x a cavity's extra reduced distance and round-trip phase
/// (zero for the front face, whose B_m are then real up to the Gouy phase). B_m changes with
/// |L| on the scale of z_R and with θ² on the scale of 1/(m·k·w0)². The partial derivatives are
/// analytic. Beams whose bound |(1 - r1²)·r^m·r1^(m-1)| is below 1e-17 are left out, as the
/// sum of [`FabryPerot::field`] leaves them.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FringeExpansion {
    /// B_m, m = 0..=M.
    pub coefficients: Vec<Complex<f64>>,
    /// ∂B_m/∂|L|, per µm.
    pub d_gap: Vec<Complex<f64>>,
    /// ∂B_m/∂(θ²), per rad².
    pub d_tilt_sq: Vec<Complex<f64>>,
    /// ∂²B_m/∂(θ²)², per rad⁴ (each beam is exp(linear in θ²) times a function of |L|).
    pub d2_tilt_sq: Vec<Complex<f64>>,
    /// ∂B_m/∂k, per (rad/µm), for a change of wavelength: k = 2π·n/λ the wavenumber in the
    /// medium, the fiber, lamella, back face and medium index fixed.
    pub d_wavenumber: Vec<Complex<f64>>,
}

impl FringeExpansion {
    /// E_r/E_in at the phasors u = exp(-iΦ) and w = exp(iψ) (Horner in u).
    pub fn field(&self, u: Complex<f64>, w: Complex<f64>) -> Complex<f64> {
        let mut acc = Complex::new(0.0, 0.0);
        for (m, b) in self.coefficients.iter().enumerate().rev() {
            acc = acc * u + b * w.powi(tilt_phase_order(m) as i32);
        }
        acc
    }
}

/// w^(e_m) for m = 0, 1, 2, ... ([`tilt_phase_order`]), by recurrence: three complex products
/// per beam where a power takes a dozen (e_m reaches hundreds). With s_m = w^(m(m+1)) and
/// g_m = w^(2(m+1)): w^(e_(m+1)) = w^(e_m)·s_m, s_(m+1) = s_m·g_m, g_(m+1) = g_m·w².
pub(crate) fn tilt_phasors(w: Complex<f64>) -> impl Iterator<Item = Complex<f64>> {
    let one = Complex::new(1.0, 0.0);
    let w2 = w * w;
    std::iter::successors(Some((one, one, w2)), move |&(p, s, g)| Some((p * s, s * g, g * w2))).map(|(p, _, _)| p)
}

/// e_m = m(m² - 1)/3 = a_m - m, the multiple of ψ = k·θ²·|L| in beam m's tilt phase
/// ([`FringeExpansion`]); e_{m+1} - e_m = m(m + 1).
pub fn tilt_phase_order(m: usize) -> u64 {
    let m = m as u64;
    m * (m * m).saturating_sub(1) / 3
}

impl FabryPerot {
    /// Highest beam order M kept by [`FabryPerot::expansion`].
    pub fn expansion_order(&self) -> usize {
        let order = |cav: &Cavity| -> usize {
            if cav.r == 0.0 {
                return 0;
            }
            let mut coef = self.t1_sq * cav.r;
            for m in 1..=self.beams {
                if coef.abs() < NEGLIGIBLE_AMPLITUDE {
                    return m as usize;
                }
                coef *= -self.r1 * cav.r;
            }
            self.beams as usize
        };
        order(&self.front).max(self.back.as_ref().map_or(0, order))
    }

    /// The fringe phase Φ = k·|L|·(2 - θ²) and the tilt phase ψ = k·θ²·|L| of
    /// [`FringeExpansion`], rad.
    #[inline]
    pub fn expansion_phases_rad(&self, gap_um: f64, tilt_sq_rad2: f64) -> (f64, f64) {
        let kg = self.k_per_um * gap_um.abs();
        (kg * (2.0 - tilt_sq_rad2), kg * tilt_sq_rad2)
    }

    /// The coefficients B_m of [`FringeExpansion`] and their partial derivatives at gap
    /// `gap_um` (its sign is ignored) and squared tilt `tilt_sq_rad2` = θ² (rad²), written into
    /// `out` (resized to M + 1): `field(gap, θ) = out.field(exp(-iΦ), exp(iψ))` with (Φ, ψ) from
    /// [`FabryPerot::expansion_phases_rad`].
    pub fn expansion(&self, gap_um: f64, tilt_sq_rad2: f64, out: &mut FringeExpansion) {
        self.expansion_with(gap_um, tilt_sq_rad2, out, true);
    }

    /// The coefficients B_m alone (the derivatives' vectors left empty): what the fringe's
    /// phase and shape need, at a fraction of [`FabryPerot::expansion`]'s cost.
    pub fn expansion_coefficients(&self, gap_um: f64, tilt_sq_rad2: f64, out: &mut FringeExpansion) {
        self.expansion_with(gap_um, tilt_sq_rad2, out, false);
    }

    fn expansion_with(&self, gap_um: f64, tilt_sq_rad2: f64, out: &mut FringeExpansion, derivatives: bool) {
        let n = self.expansion_order() + 1;
        let zero = Complex::new(0.0, 0.0);
        let len = if derivatives { n } else { 0 };
        out.coefficients.clear();
        out.coefficients.resize(n, zero);
        for v in [&mut out.d_gap, &mut out.d_tilt_sq, &mut out.d2_tilt_sq, &mut out.d_wavenumber] {
            v.clear();
            v.resize(len, zero);
        }
        let (k, t, g) = (self.k_per_um, tilt_sq_rad2, gap_um.abs());
        out.coefficients[0] = Complex::new(self.r1_direct, 0.0);
        if derivatives {
            out.d_wavenumber[0] = Complex::new(-self.r1_direct * self.cleave_per_k_sq * k, 0.0);
        }
        let i = Complex::new(0.0, 1.0);
        let q = (-self.half_kw0_sq * t).exp(); // exp(-ε)
        for cav in std::iter::once(&self.front).chain(self.back.as_ref()) {
            if cav.r == 0.0 || q == 0.0 {
                continue;
            }
            let dist = g + cav.extra_reduced_um;
            let mut coef = self.t1_sq * cav.r;
            let (mut decay, mut decay_step) = (q, q * q * q); // exp(-m²ε), exp(-(2m+1)ε)
            for m in 1..n {
                let mf = m as f64;
                let a_m = mf * (mf * mf + 2.0) / 3.0;
                let x = mf * dist / self.rayleigh_um;
                // c_m and d(ln c_m)/dx.
                let (c, dlnc) = if self.gouy_scale == 1.0 {
                    let c = Complex::new(1.0, x) / (1.0 + x * x);
                    (c, i * c)
                } else if self.gouy_scale == 0.0 {
                    (Complex::new((1.0 + x * x).sqrt().recip(), 0.0), Complex::new(-x / (1.0 + x * x), 0.0))
                } else {
                    // ln c = -ln(1 + x²)/2 + i·s·atan x.
                    let c = Complex::from_polar((1.0 + x * x).sqrt().recip(), self.gouy_scale * x.atan());
                    (c, Complex::new(-x, self.gouy_scale) / (1.0 + x * x))
                };
                let extra = a_m * k * t * cav.extra_reduced_um;
                let phase = extra - mf * cav.extra_phase_rad;
                let term = if phase == 0.0 {
                    c * (coef * decay)
                } else {
                    c * (coef * decay) * Complex::new(phase.cos(), phase.sin())
                };
                out.coefficients[m] += term;
                if derivatives {
                    let dln_tilt = i * (a_m * k * cav.extra_reduced_um) - mf * mf * self.half_kw0_sq;
                    out.d_gap[m] += term * dlnc * (mf / self.rayleigh_um);
                    out.d_tilt_sq[m] += term * dln_tilt;
                    out.d2_tilt_sq[m] += term * dln_tilt * dln_tilt;
                    out.d_wavenumber[m] += term
                        * (-dlnc * (x / k) + i * (extra / k - mf * cav.extra_phase_per_k_um)
                            - 2.0 * mf * mf * self.half_kw0_sq * t / k);
                }
                coef *= -self.r1 * cav.r;
                decay *= decay_step;
                decay_step *= q * q;
            }
        }
    }
}
