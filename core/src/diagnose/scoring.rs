//! Scoring candidate effects against the residual: each candidate's signature (the derivative of
//! the predictions with respect to its parameter, whitened), projected orthogonally to what the
//! fitted model already explains, then a one-parameter score test. Owns the statistics and the thresholds.
//!
//! With r the whitened residual of the current fit, J its whitened Jacobian and s a candidate's
//! whitened signature, s⊥ = (I − U·Uᵀ)·s (U spans J's determined columns):
//! - absorbed share: 1 − |s⊥|²/|s|², what the current parameters would soak up;
//! - estimate â = s⊥·r/|s⊥|², σ(â) = 1/|s⊥| (scaled by the residual rms when above 1);
//! - score T = (s⊥·r)²/|s⊥|², the drop of the residual sum of squares; F = T/max(σ̂², 1) with σ̂²
//!   the whitened residual variance after the candidate is added (an F(1, ν) test, robust to a
//!   σ stated too small; a σ stated too large, as the floors are, does not make structure
//!   below the noise significant);
//! - ΔBIC = n·ln(RSS/(RSS − T)) − ln n, positive when the candidate is worth its parameter.
//!
//! A candidate is significant when F exceeds the Bonferroni threshold for the family-wise
//! false-alarm rate [`FAMILY_FALSE_ALARM`] over all candidates, ΔBIC > 0, and its estimate is
//! plausible: at most [`PLAUSIBLE_TYPICAL_MULTIPLE`] times its typical size. A residual that a
//! candidate explains only at a thousand times any real bench's size (a stage scale error of
//! −1e6 ppm from uncalibrated extrinsics) is structure the candidate does not explain.

use crate::diagnose::candidates::Candidate;
use crate::diagnose::fit::{ModelState, PredictError, Predictor};
use crate::diagnose::projection::Projector;
use crate::identify::Observation;
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// Family-wise false-alarm probability of naming any candidate on data with no missing effect.
pub const FAMILY_FALSE_ALARM: f64 = 0.01;

/// Largest plausible estimate of a candidate, in multiples of its typical size (the
/// largest effects a bench shows are a few times the typical ones).
pub const PLAUSIBLE_TYPICAL_MULTIPLE: f64 = 20.0;

/// Whether `value` is a plausible size of candidate `c`: at most [`PLAUSIBLE_TYPICAL_MULTIPLE`]
/// times its typical size.
pub fn plausible_size(c: &Candidate, value: f64) -> bool {
    value.abs() <= PLAUSIBLE_TYPICAL_MULTIPLE * c.typical.abs()
}

/// Cosine between two candidates' projected signatures above which they cannot be told apart.
pub const AMBIGUITY_COSINE: f64 = 0.95;

/// Whitened signatures (derivative of each prediction per unit of the candidate's parameter,
/// divided by σ) of candidates at the state, by central differences of one step.
pub fn signatures(
    p: &Predictor,
    state: &ModelState,
    candidates: &[Candidate],
    obs: &[Observation],
) -> Result<Vec<DVector<f64>>, PredictError> {
    use rayon::prelude::*;
    candidates
        .par_iter()
        .map(|c| {
            let at = |v: f64| {
                let mut effects = state.library_effects();
                effects.push(c.effect(v));
                p.predict(&state.extrinsics, &effects, &state.gains, obs)
            };
            let (a, b) = (at(c.step)?, at(-c.step)?);
            Ok(DVector::from_iterator(
                obs.len(),
                obs.iter().enumerate().map(|(i, o)| {
                    let d = (a[i] - b[i]) / (2.0 * c.step) / o.sigma;
                    if d.is_finite() {
                        d
                    } else {
                        0.0
                    }
                }),
            ))
        })
        .collect()
}

/// One candidate's score against the residual.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CandidateScore {
    /// Candidate name.
    pub name: String,
    /// Unit of the estimate.
    pub unit: String,
    /// Linearised estimate of the parameter.
    pub estimate: f64,
    /// Its standard uncertainty (`unit`); infinite when the data cannot see the candidate.
    pub sigma: f64,
    /// F statistic of the one-parameter test.
    pub score: f64,
    /// Drop of the BIC when the candidate is added (positive: worth adding).
    pub delta_bic: f64,
    /// Share of the signature the current parameters absorb (0: none, 1: all).
    pub absorbed_share: f64,
    /// Expected score at the candidate's typical size, |s⊥|²·typical² (≥ 25 is a clear detection).
    pub detectability_at_typical: f64,
    /// The estimate is within [`PLAUSIBLE_TYPICAL_MULTIPLE`] typical sizes.
    #[serde(default = "plausible_default")]
    pub plausible: bool,
    /// Significant at the family-wise threshold, and plausible.
    pub significant: bool,
}

fn plausible_default() -> bool {
    true
}

/// Standard normal upper-tail probability Q(z), from the complementary error function
/// (Numerical Recipes' Chebyshev fit, relative error below 1.2e-7).
pub fn normal_upper_tail(z: f64) -> f64 {
    let x = z / std::f64::consts::SQRT_2;
    let ax = x.abs();
    let t = 1.0 / (1.0 + 0.5 * ax);
    let poly = -ax * ax - 1.26551223
        + t * (1.00002368
            + t * (0.37409196
                + t * (0.09678418
                    + t * (-0.18628806
                        + t * (0.27886807
                            + t * (-1.13520398 + t * (1.48851587 + t * (-0.82215223 + t * 0.17087277))))))));
    let erfc = t * poly.exp();
    0.5 * if x >= 0.0 { erfc } else { 2.0 - erfc }
}

/// The F (≈ χ²₁ for many observations) threshold for a two-sided per-test probability `alpha`.
pub fn chi2_1_threshold(alpha: f64) -> f64 {
    // Solve 2·Q(z) = alpha by bisection; the threshold is z².
    let (mut lo, mut hi) = (0.0f64, 40.0f64);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if 2.0 * normal_upper_tail(mid) > alpha {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let z = 0.5 * (lo + hi);
    z * z
}

/// The score a candidate must exceed to be significant among `n_candidates` (the Bonferroni
/// threshold for [`FAMILY_FALSE_ALARM`]).
pub fn naming_threshold(n_candidates: usize) -> f64 {
    chi2_1_threshold(FAMILY_FALSE_ALARM / n_candidates.max(1) as f64)
}

/// Score candidates, given their whitened signatures, against the fit's residual `r` and
/// Jacobian `j` (its columns: the parameters already free).
pub fn score(
    candidates: &[Candidate],
    signatures: &[DVector<f64>],
    j: &DMatrix<f64>,
    r: &DVector<f64>,
) -> (Vec<CandidateScore>, Vec<DVector<f64>>) {
    let proj = Projector::new(j);
    let n = r.len() as f64;
    let dof = (r.len() as f64 - j.ncols() as f64 - 1.0).max(1.0);
    let rss = r.norm_squared();
    let threshold = naming_threshold(candidates.len());
    let mut projected = Vec::new();
    let scores = candidates
        .iter()
        .zip(signatures)
        .map(|(c, s)| {
            let sp = proj.orthogonal(s);
            let (ns2, s2) = (sp.norm_squared(), s.norm_squared());
            let absorbed_share = if s2 > 0.0 { (1.0 - ns2 / s2).clamp(0.0, 1.0) } else { 1.0 };
            // A signature the data cannot see (below the solver's own resolution) scores nothing.
            let visible = ns2 > 1e-12 * s2.max(1e-300) && ns2 > 1e-18;
            let (estimate, t) = if visible { (sp.dot(r) / ns2, sp.dot(r).powi(2) / ns2) } else { (0.0, 0.0) };
            let resid_var = ((rss - t) / dof).max(1e-300);
            // The stated σ is the noise floor: a residual variance below it (σ floors above
            // what the tracker reaches) does not make sub-noise structure significant.
            let f = t / resid_var.max(1.0);
            let delta_bic = if rss > 0.0 && rss > t { n * (rss / (rss - t)).ln() - n.ln() } else { 0.0 };
            let sigma = if visible { resid_var.sqrt().max(1.0) / ns2.sqrt() } else { f64::INFINITY };
            let plausible = plausible_size(c, estimate);
            projected.push(sp);
            CandidateScore {
                name: c.name.clone(),
                unit: c.unit.clone(),
                estimate,
                sigma,
                score: f,
                delta_bic,
                absorbed_share,
                detectability_at_typical: ns2 * c.typical * c.typical,
                plausible,
                significant: visible && f > threshold && delta_bic > 0.0 && plausible,
            }
        })
        .collect();
    (scores, projected)
}

/// Candidates (indices) whose projected signature is nearly collinear with candidate `best`'s.
pub fn ambiguity_set(best: usize, projected: &[DVector<f64>]) -> Vec<usize> {
    near_in_direction(best, projected, AMBIGUITY_COSINE)
}

/// Candidates (indices) whose projected signature makes |cos| above `cosine` with candidate
/// `best`'s.
pub fn near_in_direction(best: usize, projected: &[DVector<f64>], cosine: f64) -> Vec<usize> {
    let b = &projected[best];
    let nb = b.norm();
    (0..projected.len())
        .filter(|&k| k != best)
        .filter(|&k| {
            let nk = projected[k].norm();
            nb > 0.0 && nk > 0.0 && (b.dot(&projected[k]) / (nb * nk)).abs() > cosine
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn threshold_matches_the_normal_quantiles() {
        // Two-sided 5 % → z = 1.959964; 1e-3 → z = 3.290527 (tables).
        assert!((chi2_1_threshold(0.05) - 1.959964f64.powi(2)).abs() < 1e-4);
        assert!((chi2_1_threshold(1e-3) - 3.290527f64.powi(2)).abs() < 1e-3);
    }

    #[test]
    fn projection_and_score_match_the_closed_form() {
        // J = first unit vector of R³; s = (1, 1, 0): s⊥ = (0, 1, 0), absorbed share ½.
        let j = DMatrix::from_column_slice(3, 1, &[2.0, 0.0, 0.0]);
        let s = DVector::from_vec(vec![1.0, 1.0, 0.0]);
        let r = DVector::from_vec(vec![5.0, 3.0, 0.5]);
        let c = crate::diagnose::candidates::library(&crate::model::robot::RobotDescription::femto_6dof())[0].clone();
        let (sc, proj) = score(&[c], &[s], &j, &r);
        assert!((&proj[0] - DVector::from_vec(vec![0.0, 1.0, 0.0])).norm() < 1e-12);
        assert!((sc[0].absorbed_share - 0.5).abs() < 1e-12);
        assert!((sc[0].estimate - 3.0).abs() < 1e-12);
        // T = 9; residual variance after = (25 + 9 + 0.25 − 9)/(3 − 1 − 1) = 25.25.
        assert!((sc[0].score - 9.0 / 25.25).abs() < 1e-12);
    }
}
