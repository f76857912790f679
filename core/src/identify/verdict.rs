//! The verdict on a fit as a whole: does the model explain these data, and is the minimum found
//! the only one that does? Owns the residual threshold and the branch comparison.
//!
//! The threshold comes from the χ² distribution of the observation count: with N observations at
//! the noise floor, N·rms² follows χ²(N − p). Its 99.9 % quantile bounds what noise alone gives.
//! The σ of the fringe analysis are estimates (floors for what tracking cannot see), good to
//! within a factor of about two on the benches we can check, so the threshold allows
//! [`MODEL_ALLOWANCE`] times that bound: `rms ≤ MODEL_ALLOWANCE · √(χ²₀.₉₉₉(N − p) / N)`. Above
//! it the model does not fit these data, whatever the solver says, and no parameter is
//! determined. For 240 observations and 12 unknowns the threshold is 2.80σ.

use crate::model::extrinsics::{Extrinsics, PARAMETER_NAMES};
use serde::{Deserialize, Serialize};

/// How far above the noise-only bound the residual may lie before the fit is refused: the
/// factor by which the analysis's σ may understate the real scatter.
pub const MODEL_ALLOWANCE: f64 = 2.5;

/// Two branches whose χ² differ by less than this tie: the data cannot tell them apart
/// (a difference of 3σ along one direction).
pub const TIE_DELTA_CHI2: f64 = 9.0;

/// The upper `p = 0.999` quantile of χ²(k), by the Wilson-Hilferty cube approximation
/// (within 0.5 % for k ≥ 10).
pub fn chi2_quantile_999(k: usize) -> f64 {
    const Z: f64 = 3.090_232_306; // standard normal 99.9 % quantile
    let k = k.max(1) as f64;
    let a = 2.0 / (9.0 * k);
    k * (1.0 - a + Z * a.sqrt()).powi(3)
}

/// The largest residual rms (σ units) of a fit that still explains its data: see the module
/// documentation. `observations` rows, `unknowns` fitted parameters.
pub fn rms_threshold(observations: usize, unknowns: usize) -> f64 {
    let n = observations.max(1);
    MODEL_ALLOWANCE * (chi2_quantile_999(n.saturating_sub(unknowns).max(1)) / n as f64).sqrt()
}

/// The verdict's word.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// The residual is within the threshold and no other branch fits as well.
    Fits,
    /// The residual is above the threshold: not a calibration.
    DoesNotFit,
    /// Two branches fit equally well: what differs between them is not determined.
    Ambiguous,
}

/// A branch the identification ran, for the report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BranchSummary {
    /// Where the branch started: the start's name ("sweeps", "fringe travel 1", …).
    pub start: String,
    /// The estimate it ended at.
    pub extrinsics: Extrinsics,
    /// Its χ² (sum of squared normalised residuals).
    pub chi2: f64,
    /// Its residual rms (σ).
    pub rms_sigma: f64,
    /// Traces it could not analyse.
    pub skipped_traces: usize,
    /// Tracked motions whose tracking followed its extrinsics' motion hint rather than the
    /// fringes ([`crate::measure::hint_led`]).
    #[serde(default)]
    pub hint_led_traces: usize,
}

/// Cost added per trace a branch cannot analyse (the beam misses the lamella in its model): a
/// branch must not win by dropping the data it cannot explain.
pub const SKIPPED_TRACE_COST: f64 = 100.0;

/// Cost added per tracked motion whose tracking followed the branch's motion hint rather than
/// its fringes ([`crate::measure::hint_led`]): such a tracking reports the gap change the
/// branch predicts, so its residuals agree with the branch whatever the bench did.
pub const HINT_LED_TRACE_COST: f64 = 100.0;

impl BranchSummary {
    /// What the identification ranks branches by: χ², with [`SKIPPED_TRACE_COST`] per trace the
    /// branch could not analyse and [`HINT_LED_TRACE_COST`] per motion its hint led.
    pub fn cost(&self) -> f64 {
        self.chi2 + SKIPPED_TRACE_COST * self.skipped_traces as f64 + HINT_LED_TRACE_COST * self.hint_led_traces as f64
    }
}

/// One trace's share of the residual.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TraceResidual {
    /// The trace's label.
    pub label: String,
    /// Rms of its normalised residuals (σ).
    pub rms_sigma: f64,
    /// Its observations.
    pub observations: usize,
}

/// The verdict on the fit as a whole.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FitCheck {
    /// Fits, does not fit, or ambiguous.
    pub verdict: Verdict,
    /// Residual rms (σ).
    pub rms_sigma: f64,
    /// The threshold it is held to (σ).
    pub threshold_sigma: f64,
    /// The traces with the largest residual, worst first (at most [`WORST_TRACES`]).
    pub worst_traces: Vec<TraceResidual>,
    /// Every branch the identification ran, best first.
    pub branches: Vec<BranchSummary>,
    /// The branches that tie with the chosen one (indices into `branches`, never 0).
    #[serde(default)]
    pub tied_branches: Vec<usize>,
    /// Parameters that differ between tied branches (names).
    pub ambiguous_parameters: Vec<String>,
    /// One sentence for the user.
    pub summary: String,
}

/// How a listed branch stands against the chosen one.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Standing {
    /// The branch the identification keeps.
    Chosen,
    /// It ties with the chosen one.
    Tied,
    /// A branch listed before it, found again from another start.
    SameBranch,
    /// A distinct branch that fits worse.
    Worse,
}

impl Standing {
    /// The word the report lists the branch with.
    pub fn word(self) -> &'static str {
        match self {
            Standing::Chosen => "chosen",
            Standing::Tied => "TIED",
            Standing::SameBranch => "same branch",
            Standing::Worse => "worse",
        }
    }
}

impl FitCheck {
    /// How branch `k` of [`FitCheck::branches`] stands.
    pub fn standing(&self, k: usize) -> Standing {
        let listed: Vec<Extrinsics> = self.branches.iter().map(|b| b.extrinsics).collect();
        if k == 0 {
            Standing::Chosen
        } else if self.tied_branches.contains(&k) {
            Standing::Tied
        } else if crate::identify::start::found_before(&listed, k).is_some() {
            Standing::SameBranch
        } else {
            Standing::Worse
        }
    }
}

/// Traces listed in [`FitCheck::worst_traces`].
pub const WORST_TRACES: usize = 5;

/// The residual per trace (grouped by label), worst first, at most `keep`.
pub fn worst_traces(labels: &[String], normalised: &[f64], keep: usize) -> Vec<TraceResidual> {
    let mut by: Vec<(String, f64, usize)> = Vec::new();
    for (l, r) in labels.iter().zip(normalised) {
        match by.iter_mut().find(|(k, _, _)| k == l) {
            Some(e) => {
                e.1 += r * r;
                e.2 += 1;
            }
            None => by.push((l.clone(), r * r, 1)),
        }
    }
    let mut out: Vec<TraceResidual> = by
        .into_iter()
        .map(|(label, ss, n)| TraceResidual { label, rms_sigma: (ss / n as f64).sqrt(), observations: n })
        .collect();
    out.sort_by(|a, b| b.rms_sigma.total_cmp(&a.rms_sigma));
    out.truncate(keep);
    out
}

/// The parameters on which two estimates differ by more than `k` of their σ (`sigma` in the
/// order of [`PARAMETER_NAMES`], `None` where unknown: then any difference beyond the branch
/// tolerance counts).
pub fn differing_parameters(a: &Extrinsics, b: &Extrinsics, sigma: &[Option<f64>], k: f64) -> Vec<String> {
    let (a, b) = (a.to_array(), b.to_array());
    (0..PARAMETER_NAMES.len())
        .filter(|&i| {
            let d = (a[i] - b[i]).abs();
            let floor = if PARAMETER_NAMES[i].1 == "°" { 1e-4 } else { 0.01 };
            match sigma.get(i).copied().flatten() {
                Some(s) => d > (k * s).max(floor),
                None => d > floor,
            }
        })
        .map(|i| PARAMETER_NAMES[i].0.to_string())
        .collect()
}

/// Fewest traces for [`jackknife_sigma`].
pub const MIN_JACKKNIFE_TRACES: usize = 12;

/// The jackknife σ of each column of a fit, leaving out one trace at a time (linearised): the
/// spread of the estimate over the traces, which the formal σ misses when a trace's error is
/// systematic (a tracking slip shared by all of its observations) rather than the independent
/// noise the analysis assumes. `jacobian` is the weighted Jacobian (rows: observations, then
/// priors), `residuals` the normalised residuals of the observations, `labels` their traces.
/// Leaving trace k out moves the estimate by `(JᵀJ − J_kᵀJ_k)⁺ J_kᵀ r_k`; the variance is
/// `(n − 1)/n · Σ (δ_k − δ̄)²` over the n traces. `None` with fewer than
/// [`MIN_JACKKNIFE_TRACES`]: in a short plan each trace carries directions no other sees (a
/// designed plan of five motions and four sweeps), and leaving it out measures that, not how
/// far the traces disagree.
pub fn jackknife_sigma(jacobian: &nalgebra::DMatrix<f64>, residuals: &[f64], labels: &[String]) -> Option<Vec<f64>> {
    let mut traces: Vec<&String> = Vec::new();
    for l in labels {
        if !traces.contains(&l) {
            traces.push(l);
        }
    }
    let n = traces.len();
    let p = jacobian.ncols();
    if n < MIN_JACKKNIFE_TRACES || p == 0 {
        return None;
    }
    let normal = jacobian.transpose() * jacobian;
    let deltas: Vec<nalgebra::DVector<f64>> = traces
        .iter()
        .map(|t| {
            let rows: Vec<usize> = (0..labels.len()).filter(|&k| labels[k] == **t).collect();
            let jk = jacobian.select_rows(rows.iter());
            let rk = nalgebra::DVector::from_iterator(rows.len(), rows.iter().map(|&k| residuals[k]));
            let h = &normal - jk.transpose() * &jk;
            let tolerance = 1e-12 * h.norm();
            match h.pseudo_inverse(tolerance) {
                Ok(inv) => inv * (jk.transpose() * rk),
                Err(_) => nalgebra::DVector::zeros(p),
            }
        })
        .collect();
    let mean = deltas.iter().fold(nalgebra::DVector::zeros(p), |a, d| a + d) / n as f64;
    let var = deltas.iter().fold(nalgebra::DVector::zeros(p), |a, d| a + (d - &mean).map(|v| v * v));
    Some(var.iter().map(|v| (v * (n - 1) as f64 / n as f64).sqrt()).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The quantile against values from tables of χ² (Abramowitz & Stegun 26.8): χ²₀.₉₉₉(10) =
    /// 29.588, χ²₀.₉₉₉(100) = 149.449.
    #[test]
    fn chi2_quantile_matches_the_tables() {
        assert!((chi2_quantile_999(10) / 29.588 - 1.0).abs() < 0.01, "{}", chi2_quantile_999(10));
        assert!((chi2_quantile_999(100) / 149.449 - 1.0).abs() < 0.002, "{}", chi2_quantile_999(100));
    }

    /// Brute force: the share of χ²(k) draws above the quantile is 0.1 %.
    #[test]
    fn chi2_quantile_leaves_a_thousandth_above_it() {
        use rand::{rngs::StdRng, SeedableRng};
        use rand_distr::{Distribution, StandardNormal};
        let mut rng = StdRng::seed_from_u64(1);
        let (k, draws) = (50, 200_000);
        let q = chi2_quantile_999(k);
        let above = (0..draws)
            .filter(|_| (0..k).map(|_| StandardNormal.sample(&mut rng)).map(|x: f64| x * x).sum::<f64>() > q)
            .count();
        let share = above as f64 / draws as f64;
        assert!((share - 1e-3).abs() < 3e-4, "{share}");
    }

    #[test]
    fn the_threshold_for_a_typical_calibration() {
        let t = rms_threshold(240, 12);
        assert!((2.6..3.0).contains(&t), "{t}");
        // Many observations: the bound tends to the allowance.
        assert!((rms_threshold(100_000, 12) - MODEL_ALLOWANCE).abs() < 0.05);
    }

    /// Brute force: on a straight-line fit whose traces each carry their own offset (an error
    /// shared by a trace's points), the linearised jackknife equals the spread of the refits
    /// leaving one trace out, and exceeds the formal σ.
    #[test]
    fn jackknife_matches_leaving_each_trace_out() {
        use nalgebra::{DMatrix, DVector};
        let (traces, per) = (12, 5);
        let offsets = [0.8, -1.1, 0.3, 1.7, -0.6, -1.4, 0.2, 0.9, -0.4, 1.2, -0.9, 0.5];
        let mut x = Vec::new();
        let mut y = Vec::new();
        let mut labels = Vec::new();
        for (t, offset) in offsets.iter().enumerate() {
            for k in 0..per {
                let xi = t as f64 + 0.1 * k as f64;
                x.push(xi);
                y.push(2.0 + 0.5 * xi + offset + 0.01 * ((k * 7 + t) % 3) as f64);
                labels.push(format!("trace {t}"));
            }
        }
        let fit = |rows: &[usize]| {
            let a = DMatrix::from_fn(rows.len(), 2, |i, c| if c == 0 { 1.0 } else { x[rows[i]] });
            let b = DVector::from_iterator(rows.len(), rows.iter().map(|&i| y[i]));
            (a.transpose() * &a).try_inverse().unwrap() * a.transpose() * b
        };
        let all: Vec<usize> = (0..x.len()).collect();
        let theta = fit(&all);
        // Residuals r = y − model, Jacobian ∂r/∂θ = −[1, x].
        let j = DMatrix::from_fn(x.len(), 2, |i, c| if c == 0 { -1.0 } else { -x[i] });
        let r: Vec<f64> = (0..x.len()).map(|i| y[i] - theta[0] - theta[1] * x[i]).collect();
        let jack = jackknife_sigma(&j, &r, &labels).unwrap();
        let refits: Vec<DVector<f64>> =
            (0..traces).map(|t| fit(&all.iter().copied().filter(|&i| i / per != t).collect::<Vec<_>>())).collect();
        let mean = refits.iter().fold(DVector::zeros(2), |a, d| a + d) / traces as f64;
        for c in 0..2 {
            let v: f64 =
                refits.iter().map(|d| (d[c] - mean[c]).powi(2)).sum::<f64>() * (traces - 1) as f64 / traces as f64;
            assert!((jack[c] / v.sqrt() - 1.0).abs() < 1e-6, "column {c}: {} vs {}", jack[c], v.sqrt());
        }
        let formal = ((j.transpose() * &j).try_inverse().unwrap()[(1, 1)] * 1e-4).sqrt();
        assert!(jack[1] > 10.0 * formal, "jackknife {} vs formal {formal}", jack[1]);
    }

    /// The chosen branch, a tie, the chosen branch found again from another start, a distinct
    /// worse branch and that one found again.
    #[test]
    fn each_listed_branch_says_how_it_stands() {
        let e = Extrinsics::nominal_design();
        let branch = |start: &str, extrinsics: Extrinsics, chi2: f64| BranchSummary {
            start: start.into(),
            extrinsics,
            chi2,
            rms_sigma: 0.1,
            skipped_traces: 0,
            hint_led_traces: 0,
        };
        let mirrored = Extrinsics { beta_et_deg: -e.beta_et_deg, ..e };
        let far = Extrinsics { theta_et_deg: e.theta_et_deg + 1.0, ..e };
        let fit = FitCheck {
            verdict: Verdict::Ambiguous,
            rms_sigma: 0.1,
            threshold_sigma: 2.8,
            worst_traces: vec![],
            branches: vec![
                branch("absolute gaps", e, 2.1),
                branch("fringe travel 1", mirrored, 4.0),
                branch("fringe travel 2", e, 2.1),
                branch("fringe travel 3", far, 90.0),
                branch("fringe travel 4", far, 90.0),
            ],
            tied_branches: vec![1],
            ambiguous_parameters: vec![],
            summary: String::new(),
        };
        let standings: Vec<Standing> = (0..5).map(|k| fit.standing(k)).collect();
        use Standing::*;
        assert_eq!(standings, [Chosen, Tied, SameBranch, Worse, SameBranch]);
        let words: Vec<&str> = standings.iter().map(|s| s.word()).collect();
        assert_eq!(words, ["chosen", "TIED", "same branch", "worse", "same branch"]);
    }

    #[test]
    fn worst_traces_group_by_label() {
        let labels: Vec<String> = ["a", "b", "a", "c"].iter().map(|s| s.to_string()).collect();
        let w = worst_traces(&labels, &[1.0, 5.0, 1.0, 0.5], WORST_TRACES);
        assert_eq!(w[0].label, "b");
        assert_eq!(w[1].label, "a");
        assert_eq!(w[1].observations, 2);
        assert!((w[1].rms_sigma - 1.0).abs() < 1e-12);
    }
}
