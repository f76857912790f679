//! The fringe expansion against the field, and the fringe shape against the harmonics of the power.

use super::*;

/// The optics variants the expansion is checked on: Gouy on, off and scaled, a cleave, a back
/// face, a high-finesse cavity.
fn optics_variants() -> [OpticalParams; 5] {
    [
        OpticalParams::default(),
        OpticalParams { gouy_phase: false, cleave_angle_deg: 0.7, beams: 6, ..OpticalParams::default() },
        OpticalParams { gouy_scale_error: -0.4, beams: 5, ..OpticalParams::default() },
        OpticalParams { back_face: Some(BackFace::default()), cleave_angle_deg: 0.3, ..OpticalParams::default() },
        OpticalParams { beams: 1000, lamella_reflectance: 0.306, ..OpticalParams::default() },
    ]
}

/// The fringe expansion sums to the field, and its derivatives match finite differences
/// (the wavenumber derivative against a model rebuilt at a shifted wavelength).
#[test]
fn fringe_expansion_equals_the_field_and_its_derivatives_are_exact() {
    let cases = optics_variants();
    assert_eq!((1..6).map(tilt_phase_order).collect::<Vec<_>>(), [0, 2, 8, 20, 40]);
    let mut e = FringeExpansion::default();
    let mut ep = FringeExpansion::default();
    let mut em = FringeExpansion::default();
    for params in cases {
        let fp = bench(&params);
        for gap in [0.0, 3.0, 54.0, 333.3, -898.83] {
            for tilt in [0.0, 0.004, -0.0195, 0.07] {
                let t2 = tilt * tilt;
                fp.expansion(gap, t2, &mut e);
                let (phi, psi) = fp.expansion_phases_rad(gap, t2);
                let field = e.field(Complex::new(phi.cos(), -phi.sin()), Complex::new(psi.cos(), psi.sin()));
                let exact = fp.field(gap, tilt);
                // Both round Φ ≈ 7.3e3 rad at 899 µm to its ulp (9e-13 rad).
                assert!((field - exact).norm() < 1e-13, "{params:?} gap {gap} tilt {tilt}: {field} vs {exact}");
                let check = |name: &str, d: &[Complex<f64>], p: &FringeExpansion, m: &FringeExpansion, h: f64| {
                    for (j, dj) in d.iter().enumerate() {
                        let fd = (p.coefficients[j] - m.coefficients[j]) / (2.0 * h);
                        let scale = e.coefficients[1].norm().max(1e-300);
                        assert!(
                            (fd - dj).norm() * h < 1e-9 * scale + 1e-20,
                            "{name} m = {j}, gap {gap}, tilt {tilt}: {dj} vs {fd}"
                        );
                    }
                };
                let h = 1e-3;
                fp.expansion(gap.abs() + h, t2, &mut ep);
                fp.expansion(gap.abs() - h, t2, &mut em);
                if gap.abs() > h {
                    check("d/dgap", &e.d_gap, &ep, &em, h);
                }
                let h = 1e-7;
                fp.expansion(gap, t2 + h, &mut ep);
                fp.expansion(gap, t2 - h, &mut em);
                check("d/dtilt²", &e.d_tilt_sq, &ep, &em, h);
                for j in 0..e.d2_tilt_sq.len() {
                    let fd = (ep.d_tilt_sq[j] - em.d_tilt_sq[j]) / (2.0 * h);
                    let tol = 1e-4 * (e.d2_tilt_sq[j].norm() + e.coefficients[1].norm() * 1e3);
                    assert!((fd - e.d2_tilt_sq[j]).norm() < tol, "d²/dtilt²² m = {j}: {} vs {fd}", e.d2_tilt_sq[j]);
                }
                let dl = 1e-3; // nm
                let (fpp, fpm) = (
                    FabryPerot::new(&params, WL + dl, N_AIR).unwrap(),
                    FabryPerot::new(&params, WL - dl, N_AIR).unwrap(),
                );
                fpp.expansion(gap, t2, &mut ep);
                fpm.expansion(gap, t2, &mut em);
                let dk = 0.5 * (fpp.wavenumber_per_um() - fpm.wavenumber_per_um());
                check("d/dk", &e.d_wavenumber, &ep, &em, dk);
            }
        }
    }
}

/// Oracle for [`FabryPerot::fringe_shape`]: the power of the expansion at fixed B_m and w,
/// sampled over one period of u, projected on its harmonics by brute force.
#[test]
fn fringe_shape_matches_the_harmonics_of_the_power() {
    let linbo3 = OpticalParams { lamella_reflectance: 0.142, beams: 4, ..OpticalParams::default() };
    for params in [linbo3, glass()] {
        let fp = bench(&params);
        let mut ex = FringeExpansion::default();
        for (gap, tilt) in [(900.0, 0.0), (900.0, 0.05), (100.0, 0.03), (70.0, 0.0), (450.0, 0.08)] {
            let shape = fp.fringe_shape(gap, tilt, &mut ex);
            let (phi, psi) = fp.expansion_phases_rad(gap, tilt * tilt);
            let w = Complex::new(psi.cos(), psi.sin());
            let n = 64;
            let mut c = [Complex::new(0.0, 0.0); 4];
            for j in 0..n {
                let big_phi = 2.0 * PI * j as f64 / n as f64;
                let p = ex.field(Complex::new(big_phi.cos(), -big_phi.sin()), w).norm_sqr();
                for (k, ck) in c.iter_mut().enumerate() {
                    // coefficient of e^{-ikΦ}: 2·G_k for k ≥ 1
                    *ck += p * Complex::new(0.0, k as f64 * big_phi).exp() / n as f64;
                }
            }
            // fundamental phase φ = Φ - arg G1, relative to the first beam's phase
            let pulling = wrap(phi - c[1].arg() - fp.fringe_phase_rad(gap, tilt));
            assert!((pulling - shape.pulling_rad).abs() < 1e-9, "pulling {pulling} vs {}", shape.pulling_rad);
            assert!((2.0 * c[1].norm() - shape.fundamental).abs() < 1e-12);
            assert!((c[0].re - shape.offset).abs() < 1e-12);
            for (k, h) in [(2, shape.second), (3, shape.third)] {
                let expect = Complex::from_polar(c[k].norm() / c[1].norm(), k as f64 * c[1].arg() - c[k].arg());
                assert!((expect - h).norm() < 1e-9 * (1.0 + h.norm()), "h{k} {h} vs {expect} at {gap} µm, {tilt} rad");
            }
        }
    }
}

/// The shape rebuilds the real power over one fringe: P0 + P1·f(φ) with φ the first beam's
/// phase plus the pulling (what the tracker sees), within the 4th-harmonic and the slow
/// change of B_m over one fringe.
#[test]
fn fringe_shape_rebuilds_the_power_over_one_fringe() {
    let params = OpticalParams { lamella_reflectance: 0.142, beams: 4, ..OpticalParams::default() };
    let fp = bench(&params);
    let mut ex = FringeExpansion::default();
    for (gap, tilt) in [(900.0, 0.02), (900.0, 0.07), (300.0, 0.04)] {
        let s = fp.fringe_shape(gap, tilt, &mut ex);
        let period = fp.fringe_period_um();
        let n = 200;
        let (mut worst, mut p0) = (0f64, 0.0);
        let model: Vec<(f64, f64)> = (0..n)
            .map(|j| {
                let g = gap + period * j as f64 / n as f64;
                let phi = fp.fringe_phase_rad(g, tilt) + s.pulling_rad;
                let f = phi.cos()
                    + (s.second * Complex::new(0.0, 2.0 * phi).exp()).re
                    + (s.third * Complex::new(0.0, 3.0 * phi).exp()).re;
                (fp.power(g, tilt) / fp.input_power_mw(), f)
            })
            .collect();
        for &(p, f) in &model {
            p0 += (p - s.fundamental * f) / n as f64;
        }
        for &(p, f) in &model {
            worst = worst.max((p - p0 - s.fundamental * f).abs());
        }
        assert!(worst < 2e-3 * s.fundamental, "misfit {worst:e} of {:e} at {gap} µm, {tilt} rad", s.fundamental);
    }
}

/// The coefficients-only expansion and the fundamental's phase built on it are the full
/// expansion's and the fringe shape's, bit for bit.
#[test]
fn the_coefficients_alone_and_the_fundamental_phase_are_the_full_computations() {
    let cases = [
        OpticalParams::default(),
        OpticalParams { gouy_scale_error: -0.4, beams: 5, ..OpticalParams::default() },
        OpticalParams { back_face: Some(BackFace::default()), cleave_angle_deg: 0.3, ..OpticalParams::default() },
    ];
    let (mut full, mut alone) = (FringeExpansion::default(), FringeExpansion::default());
    for params in cases {
        let fp = bench(&params);
        for gap in [0.0, 3.0, 54.0, 333.3, -898.83] {
            for tilt in [0.0, 0.004, -0.0195, 0.07] {
                fp.expansion(gap, tilt * tilt, &mut full);
                fp.expansion_coefficients(gap, tilt * tilt, &mut alone);
                assert_eq!(full.coefficients, alone.coefficients, "{params:?} gap {gap} tilt {tilt}");
                assert!(alone.d_gap.is_empty() && alone.d_wavenumber.is_empty());
                let shape = fp.fringe_shape(gap, tilt, &mut full);
                let phase = fp.fringe_phase_rad(gap, tilt) + shape.pulling_rad;
                assert_eq!(fp.fundamental_phase_rad(gap, tilt).to_bits(), phase.to_bits(), "gap {gap} tilt {tilt}");
            }
        }
    }
}

/// The tilt phasors by recurrence are the powers w^(e_m), to rounding, for as many beams as
/// a high-finesse cavity keeps and at tilt phases from zero to many turns.
#[test]
fn tilt_phasors_are_the_powers_of_the_tilt_phasor() {
    use crate::model::optics::fringe_expansion::tilt_phasors;
    for psi in [0.0, 1e-6, 0.0123, -0.7, 2.9, 31.4] {
        let w = Complex::new(f64::cos(psi), f64::sin(psi));
        for (m, p) in tilt_phasors(w).take(60).enumerate() {
            let e = tilt_phase_order(m) as i32;
            let power = w.powi(e);
            // Both drift by a few ulps per product; e_59 = 68 440 products deep by powers.
            assert!((p - power).norm() < 1e-11, "ψ {psi}, m {m}: {p} vs {power}");
        }
    }
}

/// The field's slope along the gap is the derivative of the field (Richardson-extrapolated
/// central differences), and the field beside it is `field`'s to the bit, on both sides of the
/// fiber and for every optics variant (Gouy on, off and scaled, a back face, a cleave, a
/// high-finesse cavity).
#[test]
fn the_field_slope_along_the_gap_is_its_derivative() {
    let cases = optics_variants();
    for params in cases {
        let fp = bench(&params);
        for gap in [3.0, 54.0, 333.3, -898.83] {
            for tilt in [0.0, 0.004, -0.0195, 0.07] {
                let (field, slope) = fp.field_and_gap_slope(gap, tilt);
                assert_eq!(field, fp.field(gap, tilt), "{params:?} gap {gap} tilt {tilt}");
                let diff = |h: f64| (fp.field(gap + h, tilt) - fp.field(gap - h, tilt)) / (2.0 * h);
                let h = 2e-4;
                let numeric = (diff(h / 2.0) * 4.0 - diff(h)) / 3.0;
                assert!(
                    (slope - numeric).norm() < 1e-7 * (1.0 + slope.norm()),
                    "{params:?} gap {gap} tilt {tilt}: {slope} vs {numeric}"
                );
            }
        }
    }
}

/// Powers at many points at once are each point's power to the bit, whatever the other points
/// are: tilts that stop the beams' sums at different orders, a tilt that extinguishes the
/// cavity, both sides of the fiber, every optics variant.
#[test]
fn powers_side_by_side_are_each_points_power() {
    const K: usize = 17;
    for params in optics_variants() {
        let fp = bench(&params);
        let gaps: [f64; K] = std::array::from_fn(|k| -898.83 + 113.7 * k as f64);
        let tilts: [f64; K] = std::array::from_fn(|k| [0.0, 0.004, -0.0195, 0.07, 0.31, 2.0][k % 6]);
        let together = fp.powers(&gaps, &tilts);
        for k in 0..K {
            assert_eq!(together[k].to_bits(), fp.power(gaps[k], tilts[k]).to_bits(), "{params:?} point {k}");
        }
        assert_eq!(together[5], fp.power(1e9, 2.0), "an extinguished cavity: the fiber face alone");
    }
}
