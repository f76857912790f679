//! Cross-validation of a fitted model, one recorded trace left out at a time: what the other
//! traces predict for its gap changes and absolute gap. Owns the held-out χ² the workflow asks of
//! every named effect.
//!
//! Linearised about the fit (exact for a linear model, as the identifier's jackknife): with the
//! whitened residuals r and Jacobian J of the fit, leaving out the observations f of one trace
//! moves the parameters by δ = A⁺·(Jᵀr − J_fᵀr_f), A = JᵀJ − J_fᵀJ_f, and the trace's predicted
//! residual is r_f − J_f·δ. Directions that the left-out trace alone determines stay at the fit's
//! values (the pseudo-inverse drops those in which the other traces hold under [`MIN_SHARE`] of
//! the whole fit's information): such a direction is not cross-validated, and the comparison of
//! two models treats it alike in both. An effect the other traces contradict (one trace's
//! tracking error fitted) predicts them worse.
//!
//! The fringe amplitudes are never left out: they carry the fiber's angles, which gap changes
//! see only at second order, and each trace's detector gain. Left out with a tilt scan, the
//! angles would swing along their weakly determined directions and the scan's gap changes with
//! them, whatever the model: on femto-lab (seed 5) every candidate then came out 556 worse.

use crate::diagnose::fit::Fit;
use crate::identify::{Observation, ObservationKind};
use nalgebra::{DMatrix, DVector};

/// The sum over traces of the squared whitened residuals of each trace's gap changes and absolute
/// gaps, predicted by the model fitted to the others (`obs` are the fit's observations, in its
/// order; a trace is a label).
pub fn leave_one_trace_out_chi2(fit: &Fit, obs: &[Observation]) -> f64 {
    let (j, r) = (&fit.jacobian, &fit.residuals);
    if j.nrows() != obs.len() || j.ncols() == 0 {
        return r.norm_squared();
    }
    let jtj = j.transpose() * j;
    let jtr = j.transpose() * r;
    let whiten = Whitening::of(&jtj);
    let held = |o: &Observation| !matches!(o.kind, ObservationKind::FringeAmplitude { .. });
    let mut labels: Vec<&str> = Vec::new();
    for o in obs.iter().filter(|o| held(o)) {
        if !labels.contains(&o.label.as_str()) {
            labels.push(&o.label);
        }
    }
    labels
        .iter()
        .map(|label| {
            let rows: Vec<usize> = (0..obs.len()).filter(|&i| obs[i].label == *label && held(&obs[i])).collect();
            let jf = j.select_rows(rows.iter());
            let rf = DVector::from_iterator(rows.len(), rows.iter().map(|&i| r[i]));
            let a = &jtj - jf.transpose() * &jf;
            let b = &jtr - jf.transpose() * &rf;
            let delta = whiten.solve_kept(&a, &b);
            (rf - jf * delta).norm_squared()
        })
        .sum()
}

/// The whole fit's information `F = JᵀJ` on its correlation form (unit diagonal), whitened:
/// `W` with `Wᵀ·D·F·D·W = I` over the directions the fit determines.
struct Whitening {
    /// `1/√F_ii` (0 for a column nothing determines).
    d: Vec<f64>,
    /// The whitening, one column per determined direction.
    w: DMatrix<f64>,
}

impl Whitening {
    fn of(f: &DMatrix<f64>) -> Self {
        let d: Vec<f64> = (0..f.nrows()).map(|i| if f[(i, i)] > 0.0 { 1.0 / f[(i, i)].sqrt() } else { 0.0 }).collect();
        let scaled = DMatrix::from_fn(f.nrows(), f.ncols(), |i, j| f[(i, j)] * d[i] * d[j]);
        let eig = scaled.symmetric_eigen();
        let top = eig.eigenvalues.iter().fold(0.0f64, |m, v| m.max(*v));
        let kept: Vec<usize> =
            (0..eig.eigenvalues.len()).filter(|&k| eig.eigenvalues[k] > UNDETERMINED * top).collect();
        let w = DMatrix::from_fn(f.nrows(), kept.len(), |i, c| {
            eig.eigenvectors[(i, kept[c])] / eig.eigenvalues[kept[c]].sqrt()
        });
        Whitening { d, w }
    }

    /// The other traces' information `a` in the whole fit's whitened directions: its eigenvalues
    /// are the share of each direction's information the other traces hold (0 to 1).
    fn share(&self, a: &DMatrix<f64>) -> DMatrix<f64> {
        let d = &self.d;
        let scaled = DMatrix::from_fn(a.nrows(), a.ncols(), |i, j| a[(i, j)] * d[i] * d[j]);
        self.w.transpose() * scaled * &self.w
    }

    /// `a⁻¹·b` over the directions in which the other traces (information `a`) hold at least
    /// [`MIN_SHARE`] of the whole fit's information; along the others the parameters stay where
    /// the whole fit put them, rather than swing by the other traces' noise over what little they
    /// know of them.
    fn solve_kept(&self, a: &DMatrix<f64>, b: &DVector<f64>) -> DVector<f64> {
        let eig = self.share(a).symmetric_eigen();
        let rhs = self.w.transpose() * DVector::from_fn(b.len(), |i, _| b[i] * self.d[i]);
        let mut z = DVector::zeros(rhs.len());
        for (k, &mu) in eig.eigenvalues.iter().enumerate() {
            if mu >= MIN_SHARE {
                let u = eig.eigenvectors.column(k);
                z += u * (u.dot(&rhs) / mu);
            }
        }
        let y = &self.w * z;
        DVector::from_fn(b.len(), |i, _| y[i] * self.d[i])
    }
}

/// Relative eigenvalue of the whole fit's correlation form below which a direction counts as
/// undetermined by the fit itself (numerically null: a gain no amplitude sees).
const UNDETERMINED: f64 = 1e-12;

/// Least share of a direction's information the other traces must hold for the left-out trace's
/// prediction to move along it: below it, the left-out trace alone determines the direction (its
/// σ from the others would exceed √10 times the whole fit's) and it is not cross-validated.
/// A q4 rotation at q3 = 150 µm, designed to separate a q3 axis tilt from a q4 zero offset,
/// holds all but 0.07 % of one combination of the two: left out, the others' noise swings it by
/// 70σ, and the tilt (0.60 mrad hidden, 0.60 ± 0.08 mrad estimated) would go as predicting worse.
/// The directions the other traces do determine hold 80 % of their information or more there.
pub const MIN_SHARE: f64 = 0.1;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::fit::ModelState;
    use crate::model::extrinsics::Extrinsics;

    fn obs(label: &str) -> Observation {
        Observation {
            label: label.into(),
            kind: ObservationKind::GapChange { from_display: [0.0; 6], to_display: [0.0; 6], dl_nm: 0.0 },
            sigma: 1.0,
            wavelength_nm: 1560.0,
            time_s: [0.0; 2],
            approach: Default::default(),
        }
    }

    /// Oracle: a straight line y = a + b·x fitted to points, three per trace; each trace's
    /// cross-validated residuals from the line refitted without it, by brute force.
    #[test]
    fn it_matches_refitting_without_each_trace() {
        let x: Vec<f64> = (0..12).map(|i| i as f64 * 0.7 - 3.0).collect();
        let y: Vec<f64> =
            x.iter().enumerate().map(|(i, x)| 1.5 - 0.8 * x + [0.3, -0.2, 0.1][i % 3] * (i as f64).sin()).collect();
        let labels: Vec<String> = (0..12).map(|i| format!("trace {}", i / 3)).collect();
        let fit_line = |keep: &[usize]| {
            let a = DMatrix::from_fn(keep.len(), 2, |r, c| if c == 0 { 1.0 } else { x[keep[r]] });
            let b = DVector::from_iterator(keep.len(), keep.iter().map(|&i| y[i]));
            a.clone().svd(true, true).solve(&b, 1e-12).unwrap()
        };
        let all: Vec<usize> = (0..12).collect();
        let p = fit_line(&all);
        let residuals = DVector::from_iterator(12, (0..12).map(|i| y[i] - p[0] - p[1] * x[i]));
        let jacobian = DMatrix::from_fn(12, 2, |r, c| if c == 0 { 1.0 } else { x[r] });
        let fit = Fit {
            state: ModelState { extrinsics: Extrinsics::table2(), effects: vec![], gains: vec![] },
            residuals,
            jacobian,
            column_names: vec!["a".into(), "b".into()],
            effect_sigma: vec![],
            iterations: 1,
        };
        let observations: Vec<Observation> = labels.iter().map(|l| obs(l)).collect();
        let mut brute = 0.0;
        for t in 0..4 {
            let keep: Vec<usize> = (0..12).filter(|i| i / 3 != t).collect();
            let q = fit_line(&keep);
            brute += (0..12).filter(|i| i / 3 == t).map(|i| (y[i] - q[0] - q[1] * x[i]).powi(2)).sum::<f64>();
        }
        let cv = leave_one_trace_out_chi2(&fit, &observations);
        assert!((cv - brute).abs() < 1e-9 * brute.max(1.0), "{cv} vs {brute}");
        assert!(cv > fit.residuals.norm_squared(), "out of sample is worse than in sample");
        // The parameters' units do not decide which directions count as determined: the slope
        // in units 10⁸ times larger (its column 10⁻⁸) cross-validates alike.
        let mut rescaled = fit.clone();
        rescaled.jacobian.column_mut(1).scale_mut(1e-8);
        let cv_rescaled = leave_one_trace_out_chi2(&rescaled, &observations);
        assert!((cv_rescaled - cv).abs() < 1e-6 * cv, "{cv_rescaled} vs {cv}");

        // A third parameter that trace 3 alone determines (its column 1 there, 10⁻⁴ elsewhere):
        // refitted without trace 3, brute force swings it by the others' noise over their
        // vanishing information; here it stays at the whole fit's value and trace 3 is predicted
        // by the line the others determine.
        let z = |i: usize| if i / 3 == 3 { 1.0 } else { 1e-4 * (7.0 * i as f64).sin() };
        let fit3 = |keep: &[usize]| {
            let a = DMatrix::from_fn(keep.len(), 3, |r, c| [1.0, x[keep[r]], z(keep[r])][c]);
            let b = DVector::from_iterator(keep.len(), keep.iter().map(|&i| y[i]));
            a.clone().svd(true, true).solve(&b, 1e-15).unwrap()
        };
        let p3 = fit3(&all);
        let predicted = |q: &DVector<f64>, i: usize| q[0] + q[1] * x[i] + q[2] * z(i);
        let with_c = Fit {
            residuals: DVector::from_iterator(12, (0..12).map(|i| y[i] - predicted(&p3, i))),
            jacobian: DMatrix::from_fn(12, 3, |r, c| [1.0, x[r], z(r)][c]),
            column_names: vec!["a".into(), "b".into(), "c".into()],
            ..fit.clone()
        };
        let keep: Vec<usize> = (0..12).filter(|i| i / 3 != 3).collect();
        let q = fit3(&keep);
        let brute3: f64 = (9..12).map(|i| (y[i] - predicted(&q, i)).powi(2)).sum();
        let cv3 = leave_one_trace_out_chi2(&with_c, &observations);
        assert!(brute3 > 100.0 * cv, "brute force swings: {brute3} vs {cv}");
        assert!(cv3 < 2.0 * cv, "not cross-validated, not swung: {cv3} vs {cv} without c");
    }
}
