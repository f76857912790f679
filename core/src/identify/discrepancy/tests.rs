//! The discrepancy term on linear problems whose answer is known: two families measuring one
//! quantity (closed forms), Monte Carlo without and with a family's bias.

use super::*;
use rand::{rngs::StdRng, Rng, SeedableRng};
use rand_distr::{Distribution, StandardNormal};

/// An observation of `family` (only its family, label and σ matter here).
fn obs(family: Family, label: &str) -> Observation {
    let q = [0.0; 6];
    let mut to = q;
    let kind = match family {
        Family::Translations => {
            to[0] = 10.0;
            ObservationKind::GapChange { from_display: q, to_display: to, dl_nm: 0.0 }
        }
        Family::Rotations => {
            to[3] = 1.0;
            ObservationKind::GapChange { from_display: q, to_display: to, dl_nm: 0.0 }
        }
        Family::AbsoluteGaps => ObservationKind::AbsoluteGap { at_display: q, gap_um: 0.0, sweep_nm_per_s: 0.0 },
        Family::FringeAmplitudes => {
            ObservationKind::FringeAmplitude { at_display: q, amplitude_mw: 0.0, group: 0, neighbours: None }
        }
    };
    Observation {
        label: label.into(),
        kind,
        sigma: 1.0,
        wavelength_nm: 1560.0,
        time_s: [0.0; 2],
        approach: [[0; 6]; 2],
    }
}

/// The least-squares residuals of `y` on `j` (unit σ): what an estimate leaves.
fn residuals(j: &DMatrix<f64>, y: &DVector<f64>) -> (DVector<f64>, DVector<f64>) {
    let theta = (j.transpose() * j).try_inverse().expect("full rank") * j.transpose() * y;
    (y - j * &theta, theta)
}

/// Two families measure one quantity: leaving either out moves the estimate by the two-sample
/// statistic χ² = (ȳ_A − ȳ_B)²/(1/n_A + 1/n_B), and the systematic variance is
/// max(a, b)²·(d² − (a + b))/(a + b)² with a = 1/n_A, b = 1/n_B, d = ȳ_A − ȳ_B.
#[test]
fn two_families_of_one_quantity_give_the_two_sample_closed_forms() {
    let (ya, yb) = ([1.0, 1.2, 0.9, 1.1], [3.0, 3.3, 2.8, 3.1, 2.9, 3.2]);
    let n = ya.len() + yb.len();
    let j = DMatrix::from_element(n, 1, 1.0);
    let y = DVector::from_iterator(n, ya.iter().chain(&yb).copied());
    let (r, _) = residuals(&j, &y);
    let observations: Vec<Observation> = (0..n)
        .map(|k| if k < ya.len() { obs(Family::Translations, "a") } else { obs(Family::AbsoluteGaps, "b") })
        .collect();
    let out = model_discrepancy(&j, r.as_slice(), &observations, &[Some(0)]);
    let (a, b) = (1.0 / ya.len() as f64, 1.0 / yb.len() as f64);
    let d = ya.iter().sum::<f64>() * a - yb.iter().sum::<f64>() * b;
    let chi2 = d * d / (a + b);
    for f in &out.families {
        assert!((f.shift_chi2 / chi2 - 1.0).abs() < 1e-9, "{:?}: {} vs {chi2}", f.family, f.shift_chi2);
        assert_eq!(f.shift_dof, 1);
        assert!(f.disagrees);
    }
    let want = a.max(b).powi(2) * (d * d - (a + b)) / (a + b).powi(2);
    let got = out.sigma_from_families[0].unwrap() / parameter_scale(0);
    assert!((got * got / want - 1.0).abs() < 1e-9, "{} vs {want}", got * got);
}

/// A random linear problem: 3 parameters seen by 4 families of 12 observations each.
fn problem(rng: &mut StdRng) -> (DMatrix<f64>, Vec<Observation>) {
    let rows = 48;
    let j = DMatrix::from_fn(rows, 3, |_, _| rng.random_range(-1.0..1.0));
    let observations = (0..rows).map(|k| obs(Family::ALL[k / 12], &format!("trace {}", k / 3))).collect();
    (j, observations)
}

/// Monte Carlo without a bias: each family is called in disagreement in about 1 % of draws, and
/// the systematic σ stays zero in nearly all of them.
#[test]
fn without_a_bias_families_rarely_disagree() {
    let mut rng = StdRng::seed_from_u64(5);
    let (draws, mut flagged, mut inflated) = (2000, 0, 0);
    for _ in 0..draws {
        let (j, observations) = problem(&mut rng);
        let y = DVector::from_fn(j.nrows(), |_, _| StandardNormal.sample(&mut rng));
        let (r, _) = residuals(&j, &y);
        let out = model_discrepancy(&j, r.as_slice(), &observations, &[Some(0), Some(1), Some(5)]);
        flagged += out.families.iter().filter(|f| f.disagrees).count();
        inflated += out.sigma_from_families.iter().flatten().any(|s| *s > 0.0) as usize;
        for f in &out.families {
            assert!((f.birge_ratio - 1.0).abs() < 1.2, "{f:?}");
        }
    }
    let rate = flagged as f64 / (4 * draws) as f64;
    assert!((0.003..0.02).contains(&rate), "a family disagrees in {rate} of draws");
    assert!((inflated as f64 / draws as f64) < 0.05, "{inflated} of {draws} inflated");
}

/// Monte Carlo with one family biased by 6 noise σ of the estimate in a random direction: the
/// noise σ alone leaves most errors beyond 3σ, the total σ covers at least 95 % of them.
#[test]
fn a_biased_family_is_covered_by_the_total_sigma() {
    let mut rng = StdRng::seed_from_u64(6);
    let (draws, mut beyond_noise, mut beyond_total, mut checked) = (400, 0, 0, 0);
    for draw in 0..draws {
        let (j, observations) = problem(&mut rng);
        let biased = Family::ALL[draw % 4];
        let c = (j.transpose() * &j).try_inverse().unwrap();
        let direction = DVector::from_fn(3, |_, _| StandardNormal.sample(&mut rng)).normalize();
        // The family's observations as if the parameters were 6 noise σ off along `direction`.
        let shift = direction.component_mul(&c.diagonal().map(f64::sqrt)) * 6.0 * 12f64.sqrt();
        let y = DVector::from_fn(j.nrows(), |k, _| {
            let noise: f64 = StandardNormal.sample(&mut rng);
            noise + if observations[k].kind == obs(biased, "").kind { (j.row(k) * &shift)[(0, 0)] } else { 0.0 }
        });
        let (r, theta) = residuals(&j, &y);
        let out = model_discrepancy(&j, r.as_slice(), &observations, &[Some(0), Some(1), Some(5)]);
        for (k, i) in [0usize, 1, 5].into_iter().enumerate() {
            let noise = c[(k, k)].sqrt();
            let sys = out.sigma_from_families[i].unwrap() / parameter_scale(i);
            let total = noise.hypot(sys);
            checked += 1;
            beyond_noise += (theta[k].abs() > 3.0 * noise) as usize;
            beyond_total += (theta[k].abs() > 3.0 * total) as usize;
        }
    }
    let (noise, total) = (beyond_noise as f64 / checked as f64, beyond_total as f64 / checked as f64);
    eprintln!("beyond 3σ: {noise:.3} with the noise σ, {total:.3} with the total σ");
    assert!(noise > 0.2, "the bias should show against the noise σ: {noise}");
    assert!(total <= 0.05, "total σ leaves {total} beyond 3σ");
}
