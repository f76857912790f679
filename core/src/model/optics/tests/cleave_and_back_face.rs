//! The cleave angle of the fiber face and the back face of a transparent lamella.

use super::*;
use rustfft::FftPlanner;

#[test]
fn cleave_angle_scales_the_fiber_reflectance() {
    // A 0.5 rad tilt extinguishes the cavity (ε ≈ 55): only the fiber face remains.
    let square = reflected_power(&OpticalParams::default(), 100.0, 0.5, WL, N_AIR).unwrap();
    let r1 = (1.4682 - N_AIR) / (1.4682 + N_AIR);
    assert!((square - r1 * r1).abs() < 1e-15);
    for deg in [0.25, 0.5, 1.0, 2.0] {
        let params = OpticalParams { cleave_angle_deg: deg, ..OpticalParams::default() };
        let cleaved = reflected_power(&params, 100.0, 0.5, WL, N_AIR).unwrap();
        let spec = (-(2.0 * PI * 1.4682 * 5.2 * f64::to_radians(deg) / (WL * 1e-3)).powi(2)).exp();
        assert!((cleaved / square - spec).abs() < 1e-12, "{deg}°: {} vs {spec}", cleaved / square);
    }
}

/// Lamella with an AR-coated front (R2 = 0) and a reflecting back face: one beam is a
/// two-beam signal at reduced distance |L| + t/n_p and phase 2(k|L| + k0·n_p·t).
#[test]
fn back_face_alone_is_a_cavity_at_the_optical_thickness() {
    let back = BackFace {
        thickness_um: 150.0,
        phase_index: 1.444,
        group_index: 1.463,
        reference_wavelength_nm: WL,
        reflectance: 0.035,
        inverted: false,
    };
    let params = OpticalParams {
        lamella_reflectance: 0.0,
        back_face: Some(back),
        beams: 1,
        gouy_phase: false,
        ..OpticalParams::default()
    };
    let fp = bench(&params);
    let r1 = (params.fiber_index - N_AIR) / (params.fiber_index + N_AIR);
    let k0 = 2.0 * PI / (WL * 1e-3);
    let z_r = PI * 5.2 * 5.2 / (WL / N_AIR * 1e-3);
    for gap in [0.0, 10.0, 77.7, 400.0] {
        let reduced = gap + back.thickness_um * N_AIR / back.phase_index;
        let c = 1.0 / (1.0 + (reduced / z_r).powi(2)).sqrt();
        let phase = 2.0 * (k0 * N_AIR * gap + k0 * back.phase_index * back.thickness_um);
        let oracle = (Complex::new(r1, 0.0)
            + (1.0 - r1 * r1) * back.reflectance.sqrt() * c * Complex::new(0.0, -phase).exp())
        .norm_sqr();
        assert!((fp.power(gap, 0.0) - oracle).abs() < 1e-13, "gap {gap}");
    }
}

/// In a wavelength sweep the back-face cavity appears at optical path 2(n_air·L + n_g·t).
#[test]
fn wavelength_sweep_shows_back_face_at_group_optical_thickness() {
    let (gap, t, n_g) = (300.0, 200.0, 2.2634);
    let params = OpticalParams {
        back_face: Some(BackFace { thickness_um: t, group_index: n_g, ..BackFace::default() }),
        ..OpticalParams::default()
    };
    // Uniform in vacuum wavenumber σ = 1/λ over 1520-1600 nm.
    let n = 1024;
    let (s0, s1) = (1.0 / 1.600, 1.0 / 1.520); // µm⁻¹
    let mut buf: Vec<Complex<f64>> = (0..n)
        .map(|j| {
            let sigma = s0 + (s1 - s0) * j as f64 / n as f64;
            Complex::new(reflected_power(&params, gap, 0.0, 1e3 / sigma, N_AIR).unwrap(), 0.0)
        })
        .collect();
    let mean = buf.iter().map(|v| v.re).sum::<f64>() / n as f64;
    buf.iter_mut().for_each(|v| v.re -= mean);
    FftPlanner::new().plan_fft_forward(n).process(&mut buf);
    // Bin b ↔ optical path difference b/Δσ.
    let opd_per_bin = 1.0 / (s1 - s0);
    let peak_near = |opd: f64| {
        let centre = (opd / opd_per_bin).round() as usize;
        (centre - 3..=centre + 3).max_by(|&a, &b| buf[a].norm().total_cmp(&buf[b].norm())).unwrap()
    };
    for opd in [2.0 * N_AIR * gap, 2.0 * (N_AIR * gap + n_g * t)] {
        let bin = peak_near(opd);
        assert!(
            (bin as f64 * opd_per_bin - opd).abs() <= opd_per_bin,
            "peak at {} µm, expected {opd} µm",
            bin as f64 * opd_per_bin
        );
        // A real peak: well above the floor between the two.
        let floor = buf[((2.0 * N_AIR * gap + n_g * t) / opd_per_bin) as usize].norm();
        assert!(buf[bin].norm() > 5.0 * floor);
    }
}
