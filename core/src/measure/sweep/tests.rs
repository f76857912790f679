//! Tests of the sweep analyses: accuracy and honest σ against the Cramér-Rao bounds, the FFT
//! seed's bias, the Gouy phase, bad sweeps; and the sign of a move from two sweeps.

use super::*;
use rand::rngs::StdRng;
use rand::SeedableRng;

const N_AIR: f64 = 1.000_268;
const CENTER: f64 = 1560.0;
const SPAN: f64 = 40.0;
const W0: f64 = 5200.0;
const B: f64 = 0.2;

fn wavelengths(n: usize) -> Vec<f64> {
    (0..n).map(|i| CENTER - 0.5 * SPAN + SPAN * i as f64 / (n - 1) as f64).collect()
}

fn sweep(gap_nm: f64, noise_rel: f64, phase: f64, seed: u64) -> (Vec<f64>, Vec<f64>) {
    let wl = wavelengths(4000);
    let sig = TwoBeamSweep {
        gap_nm,
        n_air: N_AIR,
        offset: 1.0,
        offset_slope_per_nm: 0.05 / SPAN,
        center_nm: CENTER,
        amplitude: B,
        phase_rad: phase,
        gouy_waist_nm: Some(W0),
        noise_sigma: noise_rel * B,
    };
    let mut rng = StdRng::seed_from_u64(seed);
    let y = sig.render(&wl, &mut rng).unwrap();
    (wl, y)
}

fn cfg() -> SweepConfig {
    SweepConfig { n_air: N_AIR, gouy_waist_nm: Some(W0) }
}

#[test]
fn crlb_matches_a_worked_example() {
    // A worked example: 40 nm sweep, N = 4000, η = 1000 → 8.4 nm (frequency), 62 pm (phase)
    let f = crlb_frequency_nm(40.0, 1560.0, 1000.0, 4000, 1.0);
    let p = crlb_phase_nm(1560.0, 1000.0, 4000, 1.0);
    assert!((f - 8.38).abs() < 0.05, "{f}");
    assert!((p - 0.062).abs() < 0.001, "{p}");
}

#[test]
fn fit_recovers_the_gap_within_20nm_with_honest_sigma() {
    // 900 µm: ~30 fringes; 100 µm: 3.3 fringes; 50 µm: 1.6 fringes across 40 nm
    for gap_um in [900.0, 100.0, 50.0] {
        let mut worst = 0f64;
        let mut worst_z = 0f64;
        for seed in 0..6u64 {
            let (wl, y) = sweep(gap_um * 1e3, 1e-3, 0.4 + 1.1 * seed as f64, seed);
            let fit = fit_gap(&wl, &y, &cfg()).unwrap();
            let err_nm = (fit.estimate.gap_um - gap_um) * 1e3;
            let sigma_nm = fit.estimate.sigma_um * 1e3;
            worst = worst.max(err_nm.abs());
            worst_z = worst_z.max(err_nm.abs() / sigma_nm);
            assert!(err_nm.abs() < 20.0, "{gap_um} µm seed {seed}: err {err_nm} nm");
            assert!(err_nm.abs() < 3.0 * sigma_nm, "{gap_um} µm seed {seed}: err {err_nm} σ {sigma_nm}");
            assert_eq!(fit.estimate.method, GapMethod::ModelFit);
        }
        let crlb = crlb_frequency_nm(SPAN, CENTER, 1.0 / (2.0 * 1e-6), 4000, N_AIR);
        eprintln!("{gap_um} µm: worst |err| {worst:.3} nm, worst |err|/σ {worst_z:.2}, CRLB {crlb:.3} nm");
    }
}

#[test]
fn reported_sigma_is_of_the_order_of_the_crlb_and_of_the_scatter() {
    // η = B²/(2σ²) = 1000 as in the worked example: CRLB 8.4 nm
    let noise_rel = (1.0f64 / 2000.0).sqrt();
    let crlb = crlb_frequency_nm(SPAN, CENTER, 1000.0, 4000, N_AIR);
    let mut errs = Vec::new();
    let mut sigmas = Vec::new();
    for seed in 0..24u64 {
        let (wl, y) = sweep(900e3, noise_rel, 0.3 * seed as f64, 1000 + seed);
        let fit = fit_gap(&wl, &y, &cfg()).unwrap();
        errs.push((fit.estimate.gap_um - 900.0) * 1e3);
        sigmas.push(fit.estimate.sigma_um * 1e3);
    }
    let rms = (errs.iter().map(|e| e * e).sum::<f64>() / errs.len() as f64).sqrt();
    let mean_sigma = sigmas.iter().sum::<f64>() / sigmas.len() as f64;
    eprintln!("η=1000: CRLB {crlb:.2} nm, mean σ {mean_sigma:.2} nm, rms error {rms:.2} nm");
    assert!(mean_sigma > 0.9 * crlb && mean_sigma < 2.0 * crlb, "σ {mean_sigma} vs CRLB {crlb}");
    assert!(rms > 0.5 * mean_sigma && rms < 1.6 * mean_sigma, "rms {rms} vs σ {mean_sigma}");
}

/// A weak fringe on a strong offset (a tilted lamella: amplitude 0.4 % of the offset, as at the
/// start of a validation rotation): the gap's σ is still the scatter's, not zero. The gap's
/// column is the amplitude times 2nk, ten thousand times smaller than the offset's, and once
/// decorrelated from the phase its eigenvalue fell under a threshold set on the unscaled JᵀJ.
#[test]
fn a_weak_fringe_on_a_strong_offset_keeps_an_honest_sigma() {
    let wl: Vec<f64> = (0..2000).map(|i| CENTER - 10.0 + 20.0 * i as f64 / 1999.0).collect();
    let (mut errs, mut sigmas) = (Vec::new(), Vec::new());
    for seed in 0..24u64 {
        let sig = TwoBeamSweep {
            gap_nm: 897.4e3,
            n_air: N_AIR,
            offset: 1.0,
            offset_slope_per_nm: 0.0,
            center_nm: CENTER,
            amplitude: 0.004,
            phase_rad: 0.3 * seed as f64,
            gouy_waist_nm: Some(W0),
            noise_sigma: 1.7e-5,
        };
        let y = sig.render(&wl, &mut StdRng::seed_from_u64(2000 + seed)).unwrap();
        let fit = fit_gap(&wl, &y, &cfg()).unwrap();
        errs.push((fit.estimate.gap_um - 897.4) * 1e3);
        sigmas.push(fit.estimate.sigma_um * 1e3);
    }
    let rms = (errs.iter().map(|e| e * e).sum::<f64>() / errs.len() as f64).sqrt();
    let mean_sigma = sigmas.iter().sum::<f64>() / sigmas.len() as f64;
    eprintln!("amplitude 0.4 %: mean σ {mean_sigma:.2} nm, rms error {rms:.2} nm");
    assert!(rms > 0.5 * mean_sigma && rms < 1.6 * mean_sigma, "rms {rms} nm vs σ {mean_sigma} nm");
}

#[test]
fn fft_seed_is_biased_with_few_fringes_and_the_fit_removes_the_bias() {
    let (wl, y) = sweep(50e3, 1e-3, 1.0, 7);
    let seed = fft_gap(&wl, &y, N_AIR).unwrap();
    let fit = fit_gap(&wl, &y, &cfg()).unwrap();
    let seed_err = (seed.gap_um - 50.0) * 1e3;
    let fit_err = (fit.estimate.gap_um - 50.0) * 1e3;
    eprintln!(
        "50 µm ({:.2} fringes): FFT err {seed_err:.0} nm, fit err {fit_err:.2} nm",
        fit.estimate.fringes_across_sweep
    );
    assert!(fit.estimate.fringes_across_sweep < 2.0);
    assert!(seed_err.abs() > 500.0, "the seed should be visibly biased: {seed_err}");
    assert!(fit_err.abs() < 20.0);
}

#[test]
fn peak_fsr_method_is_much_worse_than_the_fit_at_100um() {
    let mut worst_ratio = f64::INFINITY;
    for seed in 0..4u64 {
        let (wl, y) = sweep(100e3, 1e-3, 0.5 + seed as f64, 40 + seed);
        let fsr = peak_fsr_gap(&wl, &y, N_AIR).unwrap();
        let fit = fit_gap(&wl, &y, &cfg()).unwrap();
        let fsr_err = (fsr.gap_um - 100.0) * 1e3;
        let fit_err = (fit.estimate.gap_um - 100.0) * 1e3;
        eprintln!(
            "100 µm seed {seed}: FSR err {fsr_err:.1} nm (σ {:.1}), fit err {fit_err:.2} nm (σ {:.2})",
            fsr.sigma_um * 1e3,
            fit.estimate.sigma_um * 1e3
        );
        assert_eq!(fsr.method, GapMethod::PeakFsr);
        // worse in error, or at least reported with a larger σ
        let worse = fsr_err.abs() > 5.0 * fit_err.abs().max(1.0) || fsr.sigma_um > 3.0 * fit.estimate.sigma_um;
        assert!(worse, "seed {seed}");
        worst_ratio = worst_ratio.min(fsr_err.abs() / fit_err.abs().max(1e-3));
    }
    eprintln!("smallest FSR/fit error ratio {worst_ratio:.1}");
}

#[test]
fn ignoring_the_gouy_phase_biases_short_gaps() {
    let (wl, y) = sweep(100e3, 1e-3, 0.9, 3);
    let with = fit_gap(&wl, &y, &cfg()).unwrap();
    let without = fit_gap(&wl, &y, &SweepConfig { gouy_waist_nm: None, ..cfg() }).unwrap();
    let e_with = (with.estimate.gap_um - 100.0) * 1e3;
    let e_without = (without.estimate.gap_um - 100.0) * 1e3;
    eprintln!("100 µm: err with Gouy {e_with:.2} nm, without {e_without:.1} nm");
    assert!(e_without.abs() > 20.0 && e_without.abs() > 10.0 * e_with.abs());
}

#[test]
fn the_gouy_series_is_the_arctangent_within_its_tolerance() {
    // sweeps from 0.1 nm to 300 nm wide around 1560 nm, gaps from 1 µm to 3 mm, waists 2-20 µm
    let mut rng = StdRng::seed_from_u64(3);
    let mut used = 0;
    for _ in 0..300 {
        let span_nm = 10f64.powf(rng.random_range(-1.0..2.5));
        let (l, w0) = (10f64.powf(rng.random_range(3.0..6.5)), rng.random_range(2000.0..20_000.0));
        let (k_lo, k_hi) = (TAU / (CENTER + 0.5 * span_nm), TAU / (CENTER - 0.5 * span_nm));
        let (k0, half) = (0.5 * (k_lo + k_hi), 0.5 * (k_hi - k_lo));
        let theta = FringePhase::new(k0, half, l, N_AIR, Some(w0));
        used += usize::from(theta.degree > 0);
        for i in 0..=100 {
            let k = k_lo + (k_hi - k_lo) * i as f64 / 100.0;
            let exact = gouy_phase(k, l, w0) - gouy_phase(k0, l, w0);
            let err = (theta.gouy_change(k) - exact).abs();
            assert!(
                err < 2e-12,
                "span {span_nm} nm, L {l} nm, w0 {w0} nm, degree {}: off by {err:e} rad",
                theta.degree
            );
        }
    }
    assert!(used > 250, "the series was used on {used} of 300 sweeps");
    // 500 nm wide, ±16 % of k0: within the series' degrees at a long gap (|k0 + i·a| ≫ k0), not
    // at a short one
    let (k_lo, k_hi) = (TAU / (CENTER + 250.0), TAU / (CENTER - 250.0));
    let wide = |l: f64| FringePhase::new(0.5 * (k_lo + k_hi), 0.5 * (k_hi - k_lo), l, N_AIR, Some(W0)).degree;
    assert!(wide(3e6) > 0 && wide(1e3) == 0, "degrees {} and {}", wide(3e6), wide(1e3));
}

/// A dense sweep (200 k samples, 20 nm) at `gap_nm`, σ of the noise 10 % of B.
fn dense_sweep(gap_nm: f64, seed: u64) -> (Vec<f64>, Vec<f64>) {
    let n = 200_001;
    let wl: Vec<f64> = (0..n).map(|i| 1550.0 + 20.0 * i as f64 / (n - 1) as f64).collect();
    let sig = TwoBeamSweep {
        gap_nm,
        n_air: N_AIR,
        offset: 1.0,
        offset_slope_per_nm: 0.001,
        center_nm: 1560.0,
        amplitude: B,
        phase_rad: seed as f64,
        gouy_waist_nm: Some(W0),
        noise_sigma: 0.1 * B,
    };
    let y = sig.render(&wl, &mut StdRng::seed_from_u64(seed)).unwrap();
    (wl, y)
}

#[test]
fn the_fit_on_block_means_is_the_fit_on_every_sample() {
    // Oracle: the same fit with blocks of one sample.
    for (seed, gap_nm) in [(1u64, 120_000.0), (2, 900_000.0), (3, 2_400_000.0)] {
        let (wl, y) = dense_sweep(gap_nm, seed);
        let sp = validate(&wl, &y).unwrap();
        let blocks = super::fit::fit_spectrum(&sp, &cfg(), 0.01).unwrap().estimate;
        let every = super::fit::fit_spectrum(&sp, &cfg(), 0.0).unwrap().estimate;
        let sigma_nm = every.sigma_um * 1e3;
        let moved_nm = (blocks.gap_um - every.gap_um) * 1e3;
        assert!(moved_nm.abs() < 0.03 * sigma_nm, "gap {gap_nm} nm: moved {moved_nm} nm, σ {sigma_nm} nm");
        assert!((blocks.sigma_um / every.sigma_um - 1.0).abs() < 1e-3, "{blocks:?} vs {every:?}");
        assert!((blocks.fit_rms / every.fit_rms - 1.0).abs() < 1e-3, "{blocks:?} vs {every:?}");
        assert!((blocks.gap_um * 1e3 - gap_nm).abs() < 4.0 * sigma_nm, "{blocks:?} against {gap_nm} nm");
    }
}

#[test]
fn the_fft_seed_finds_fringes_too_fast_for_its_block_means() {
    // 150 fringes fit the averaged series (16,666 means of 12 samples); 600 are above the
    // sixteenth of its Nyquist frequency it trusts, 12,000 alias above it, and 16,766 alias
    // onto 100 but the averaging took nearly all their power: those are looked for again in
    // every sample.
    for fringes in [150.0, 600.0, 12_000.0, 16_766.0] {
        let span_k = TAU / 1550.0 - TAU / 1570.0;
        let gap_nm = fringes * PI / (N_AIR * span_k);
        let (wl, y) = dense_sweep(gap_nm, 4);
        let seed = fft_gap(&wl, &y, N_AIR).unwrap();
        assert!((seed.fringes_across_sweep - fringes).abs() < 0.5, "{fringes} fringes: seed {seed:?}");
    }
}

#[test]
fn decreasing_wavelengths_give_the_same_gap() {
    let (mut wl, mut y) = sweep(300e3, 1e-3, 0.2, 11);
    let up = fit_gap(&wl, &y, &cfg()).unwrap();
    wl.reverse();
    y.reverse();
    let down = fit_gap(&wl, &y, &cfg()).unwrap();
    assert!((up.estimate.gap_um - down.estimate.gap_um).abs() < 1e-9);
}

#[test]
fn bad_sweeps_are_errors_not_panics() {
    let c = cfg();
    assert_eq!(fit_gap(&[], &[], &c).unwrap_err(), SweepError::EmptySweep);
    assert!(matches!(fit_gap(&[1.0, 2.0], &[1.0], &c), Err(SweepError::LengthMismatch { .. })));
    assert!(matches!(fit_gap(&[1.0, 2.0], &[1.0, 2.0], &c), Err(SweepError::TooFewSamples { .. })));
    let (wl, mut y) = sweep(100e3, 1e-3, 0.0, 1);
    y[17] = f64::NAN;
    assert!(matches!(fit_gap(&wl, &y, &c), Err(SweepError::NonFinite { index: 17, .. })));
    let (mut wl, y) = sweep(100e3, 1e-3, 0.0, 1);
    wl[100] = wl[99];
    assert!(matches!(fit_gap(&wl, &y, &c), Err(SweepError::NonMonotonicWavelength { index: 100, .. })));
    // 5 µm gap: 0.16 fringe across the sweep
    let (wl, y) = sweep(5e3, 1e-3, 0.0, 1);
    assert!(matches!(
        fit_gap(&wl, &y, &c),
        Err(SweepError::TooFewFringes { .. }) | Err(SweepError::NoFringeContrast { .. })
    ));
    // no fringes at all
    let wl = wavelengths(4000);
    let mut rng = StdRng::seed_from_u64(2);
    let noise = Normal::new(0.0, 1e-3).unwrap();
    let y: Vec<f64> = wl.iter().map(|_| 1.0 + noise.sample(&mut rng)).collect();
    assert!(fit_gap(&wl, &y, &c).is_err());
    assert!(matches!(peak_fsr_gap(&wl, &y, N_AIR), Err(SweepError::TooFewPeaks { .. })));
    assert!(matches!(fit_gap(&wl, &y, &SweepConfig { n_air: 0.5, ..c }), Err(SweepError::InvalidParameter { .. })));
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]
    #[test]
    fn arbitrary_sweeps_never_panic(
        ys in proptest::collection::vec(-10.0f64..10.0, 0..64),
        start in 1000.0f64..2000.0,
        step in -1.0f64..1.0,
        n_air in 0.9f64..1.1,
    ) {
        let wl: Vec<f64> = (0..ys.len()).map(|i| start + step * i as f64).collect();
        let _ = fit_gap(&wl, &ys, &SweepConfig { n_air, gouy_waist_nm: Some(W0) });
        let _ = fft_gap(&wl, &ys, n_air);
        let _ = peak_fsr_gap(&wl, &ys, n_air);
    }
}

#[test]
fn sign_from_sweeps_is_significant_only_beyond_k_sigma() {
    let g = |gap_um: f64, sigma_um: f64| GapEstimate {
        method: GapMethod::ModelFit,
        gap_um,
        sigma_um,
        fringes_across_sweep: 10.0,
        fit_rms: 0.0,
    };
    let s = sign_from_sweeps(&g(900.0, 0.01), &g(900.2, 0.01), 3.0).unwrap();
    assert_eq!(s.sign, 1);
    assert!(s.significant);
    assert!((s.gap_change_nm - 200.0).abs() < 1e-6);
    let s = sign_from_sweeps(&g(900.0, 0.01), &g(899.98, 0.01), 3.0).unwrap();
    assert_eq!(s.sign, -1);
    assert!(!s.significant);
    assert!(sign_from_sweeps(&g(f64::NAN, 0.01), &g(1.0, 0.01), 3.0).is_err());
    assert!(sign_from_sweeps(&g(1.0, -0.01), &g(1.0, 0.01), 3.0).is_err());
}
