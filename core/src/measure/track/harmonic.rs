//! The fringe's harmonic distortion: one set of coefficients, and their profile along the
//! path travelled by the hint.

use std::f64::consts::PI;

/// Harmonic distortion of the fringe, relative to B:
/// `f(φ) = cos φ + cos_rel·cos 2φ + sin_rel·sin 2φ + cos3_rel·cos 3φ + sin3_rel·sin 3φ`.
///
/// The multi-beam Airy signal of a fiber facing a reflective lamella has a 2nd harmonic of a
/// few % and a 3rd of about 0.1 % (LiNbO3 at 900 µm). Both are modelled: an unmodelled 3rd
/// harmonic of 0.1 % biased tracked gap changes by up to 10 nm on slow motions, because the
/// envelope and phase knots (one per fringe) fold it into a fringe-periodic envelope swing.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Harmonic {
    /// Coefficient of cos 2φ.
    pub cos_rel: f64,
    /// Coefficient of sin 2φ.
    pub sin_rel: f64,
    /// Coefficient of cos 3φ.
    pub cos3_rel: f64,
    /// Coefficient of sin 3φ.
    pub sin3_rel: f64,
}

impl Harmonic {
    /// A pure second harmonic.
    pub fn second(cos_rel: f64, sin_rel: f64) -> Self {
        Self { cos_rel, sin_rel, cos3_rel: 0.0, sin3_rel: 0.0 }
    }

    /// From the phasors of `f(φ) = cos φ + Re(h2·e^{2iφ}) + Re(h3·e^{3iφ})` (the convention
    /// of `model::optics::FringeShape`).
    pub fn from_phasors(h2: nalgebra::Complex<f64>, h3: nalgebra::Complex<f64>) -> Self {
        Self { cos_rel: h2.re, sin_rel: -h2.im, cos3_rel: h3.re, sin3_rel: -h3.im }
    }

    #[inline(always)]
    pub(super) fn f_and_slope(&self, s: f64, c: f64) -> (f64, f64) {
        let c2 = 2.0 * c * c - 1.0;
        let s2 = 2.0 * s * c;
        let c3 = c * c2 - s * s2;
        let s3 = s * c2 + c * s2;
        (
            c + self.cos_rel * c2 + self.sin_rel * s2 + self.cos3_rel * c3 + self.sin3_rel * s3,
            -s - 2.0 * self.cos_rel * s2 + 2.0 * self.sin_rel * c2 - 3.0 * self.cos3_rel * s3
                + 3.0 * self.sin3_rel * c3,
        )
    }

    /// The four coefficients (cos 2φ, sin 2φ, cos 3φ, sin 3φ).
    pub(super) fn coefficients(&self) -> [f64; 4] {
        [self.cos_rel, self.sin_rel, self.cos3_rel, self.sin3_rel]
    }

    /// The extremum of B(φ)·f(φ) near `start` when d ln B/dφ = `beta`: the root of
    /// f'(φ) + β·f(φ) (Newton, a few steps), rad.
    pub(super) fn extremum_near(&self, start: f64, beta: f64) -> f64 {
        let mut p = start;
        for _ in 0..6 {
            let (s, c) = p.sin_cos();
            let (f, d1) = self.f_and_slope(s, c);
            let (s2, c2) = (2.0 * p).sin_cos();
            let (s3, c3) = (3.0 * p).sin_cos();
            let d2 = -c
                - 4.0 * self.cos_rel * c2
                - 4.0 * self.sin_rel * s2
                - 9.0 * self.cos3_rel * c3
                - 9.0 * self.sin3_rel * s3;
            let (g, dg) = (d1 + beta * f, d2 + beta * d1);
            if dg.abs() > 1e-12 {
                p -= (g / dg).clamp(-0.3, 0.3);
            }
        }
        if (p - start).abs() < 0.5 {
            p
        } else {
            start
        }
    }

    /// (max, min) of f(φ) over a period (Newton from 0 and π).
    pub(super) fn extremes(&self) -> (f64, f64) {
        let newton = |mut p: f64| {
            for _ in 0..8 {
                let (s, c) = p.sin_cos();
                let (s2, c2) = (2.0 * p).sin_cos();
                let (s3, c3) = (3.0 * p).sin_cos();
                let d1 = -s - 2.0 * self.cos_rel * s2 + 2.0 * self.sin_rel * c2 - 3.0 * self.cos3_rel * s3
                    + 3.0 * self.sin3_rel * c3;
                let d2 = -c
                    - 4.0 * self.cos_rel * c2
                    - 4.0 * self.sin_rel * s2
                    - 9.0 * self.cos3_rel * c3
                    - 9.0 * self.sin3_rel * s3;
                if d2.abs() > 1e-12 {
                    p -= (d1 / d2).clamp(-0.5, 0.5);
                }
            }
            let (s, c) = p.sin_cos();
            self.f_and_slope(s, c).0
        };
        (newton(0.0), newton(PI))
    }
}

/// The fringe harmonics as a function of the path travelled by the hint (nm): local
/// estimates at window centres, interpolated linearly, constant beyond the end windows.
///
/// On rotations the higher beams' coupling and tilt phase change along the motion, so the
/// harmonics do too (the 2nd harmonic of a ±4° goniometer scan turns by radians); one
/// global value left several nm of cyclic error there.
#[derive(Debug, Clone, Default)]
pub(super) struct HarmonicProfile {
    /// (path position nm, harmonic), sorted by position; empty = no distortion.
    knots: Vec<(f64, Harmonic)>,
    /// (max, min) of f at each knot ([`Harmonic::extremes`]), interpolated like the knots.
    extremes: Vec<(f64, f64)>,
}

impl HarmonicProfile {
    pub(super) fn new(knots: Vec<(f64, Harmonic)>) -> Self {
        let extremes = knots.iter().map(|(_, h)| h.extremes()).collect();
        Self { knots, extremes }
    }

    pub(super) fn constant(h: Harmonic) -> Self {
        Self::new(vec![(0.0, h)])
    }

    /// (max, min) of f at path position `s`: the knots' values interpolated linearly (exact
    /// at the knots; between them the error is second order in the harmonics' change).
    pub(super) fn extremes_at(&self, s: f64, cursor: &mut usize) -> (f64, f64) {
        let k = &self.knots;
        let e = &self.extremes;
        match k.len() {
            0 => (1.0, -1.0),
            1 => e[0],
            m => {
                if s <= k[0].0 {
                    return e[0];
                }
                if s >= k[m - 1].0 {
                    return e[m - 1];
                }
                if *cursor + 1 >= m || k[*cursor].0 > s {
                    *cursor = 0;
                }
                while *cursor + 2 < m && k[*cursor + 1].0 <= s {
                    *cursor += 1;
                }
                let i = *cursor;
                let t = ((s - k[i].0) / (k[i + 1].0 - k[i].0)).clamp(0.0, 1.0);
                (e[i].0 + t * (e[i + 1].0 - e[i].0), e[i].1 + t * (e[i + 1].1 - e[i].1))
            }
        }
    }

    /// The harmonic at path position `s`; `cursor` speeds up monotone queries.
    pub(super) fn at(&self, s: f64, cursor: &mut usize) -> Harmonic {
        let k = &self.knots;
        match k.len() {
            0 => Harmonic::default(),
            1 => k[0].1,
            m => {
                if s <= k[0].0 {
                    return k[0].1;
                }
                if s >= k[m - 1].0 {
                    return k[m - 1].1;
                }
                if *cursor + 1 >= m || k[*cursor].0 > s {
                    *cursor = 0;
                }
                while *cursor + 2 < m && k[*cursor + 1].0 <= s {
                    *cursor += 1;
                }
                let (s0, h0) = k[*cursor];
                let (s1, h1) = k[*cursor + 1];
                let t = ((s - s0) / (s1 - s0)).clamp(0.0, 1.0);
                let (c0, c1) = (h0.coefficients(), h1.coefficients());
                let l = |i: usize| c0[i] + t * (c1[i] - c0[i]);
                Harmonic { cos_rel: l(0), sin_rel: l(1), cos3_rel: l(2), sin3_rel: l(3) }
            }
        }
    }

    /// Mean of the knots (the summary reported in [`super::PhaseTrack::harmonic`]).
    pub(super) fn mean(&self) -> Harmonic {
        let m = self.knots.len().max(1) as f64;
        let mean = |i: usize| self.knots.iter().map(|(_, h)| h.coefficients()[i]).sum::<f64>() / m;
        Harmonic { cos_rel: mean(0), sin_rel: mean(1), cos3_rel: mean(2), sin3_rel: mean(3) }
    }
}
