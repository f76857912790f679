//! Two effects named together: when nothing more can be named one at a time and the residual
//! stays above the floor, the pair of candidates that together explain it best. Two effects
//! that cancel on the session's motions and add on the discriminating ones look, one at a
//! time, like a third: a q5 pivot of −17 µm along X_w with a q5 zero offset of −0.06° first
//! scored as a q4 zero offset, and each of the two, added alone, was taken out again because the
//! traces were predicted no better with it.

use super::naming::named;
use super::Diagnosis;
use crate::diagnose::fit::Fit;
use crate::diagnose::motions::MotionRunner;
use crate::diagnose::result::DiagnoseError;
use crate::diagnose::scoring::{self, PLAUSIBLE_TYPICAL_MULTIPLE};
use crate::diagnose::settings::{NOISE_FLOOR_FACTOR, REMOVE_BELOW_SIGMA};
use crate::diagnose::step::Step;
use nalgebra::{Matrix2, Vector2};

/// How many pairs, best by their linearised joint fit, are refitted in full.
const PAIRS_REFITTED: usize = 4;
/// Pairs whose explained χ² is within this share of one another explain the same.
const EQUAL_CHI2_SHARE: f64 = 1e-3;

impl Diagnosis {
    /// Pairs of candidates not in the model, each with its linearised joint estimate, best first
    /// by the χ² the two explain together off the fitted parameters, one of each set of pairs
    /// that explain the same.
    fn pair_candidates(&self, f: &Fit) -> Vec<(usize, usize, [f64; 2])> {
        let in_model = |c: usize| f.state.effects.iter().any(|(e, _)| e.name == self.candidates[c].name);
        let open: Vec<usize> = (0..self.projected.len().min(self.candidates.len()))
            .filter(|&c| !in_model(c) && !self.not_seen.contains(&self.candidates[c].name))
            .filter(|&c| self.projected[c].norm_squared() > 1e-18)
            .collect();
        let r = &f.residuals;
        let mut pairs = Vec::new();
        for (i, &a) in open.iter().enumerate() {
            for &b in &open[i + 1..] {
                let (pa, pb) = (&self.projected[a], &self.projected[b]);
                let (aa, bb, ab) = (pa.norm_squared(), pb.norm_squared(), pa.dot(pb));
                // Nearly collinear: one of them stands for both (an ambiguity set, not a pair).
                if ab * ab > scoring::AMBIGUITY_COSINE.powi(2) * aa * bb {
                    continue;
                }
                let rhs = Vector2::new(pa.dot(r), pb.dot(r));
                let Some(x) = Matrix2::new(aa, ab, ab, bb).try_inverse().map(|m| m * rhs) else { continue };
                let plausible =
                    |c: usize, v: f64| v.abs() <= PLAUSIBLE_TYPICAL_MULTIPLE * self.candidates[c].typical.abs();
                if plausible(a, x[0]) && plausible(b, x[1]) {
                    pairs.push((a, b, [x[0], x[1]], x.dot(&rhs)));
                }
            }
        }
        // Exact equivalents explain the same χ² (a q6 axis tilt toward link x is a q5 zero
        // offset): of those, the pair that needs the least of the candidates' typical sizes.
        let size = |a: usize, b: usize, x: &[f64; 2]| {
            (x[0] / self.candidates[a].typical).abs() + (x[1] / self.candidates[b].typical).abs()
        };
        pairs.sort_by(|p, q| q.3.total_cmp(&p.3));
        // Groups of pairs within 0.1 % of the χ² the group's first explains; the smallest of each.
        let mut groups: Vec<(usize, usize, [f64; 2], f64)> = Vec::new();
        for p in pairs {
            match groups.last_mut() {
                Some(g) if p.3 >= g.3 * (1.0 - EQUAL_CHI2_SHARE) => {
                    if size(p.0, p.1, &p.2) < size(g.0, g.1, &g.2) {
                        *g = (p.0, p.1, p.2, g.3);
                    }
                }
                _ => groups.push(p),
            }
        }
        groups.into_iter().map(|(a, b, x, _)| (a, b, x)).collect()
    }

    /// Before the verdict, when the residual is above the floor: refit the best pairs in full and
    /// add the best one when it brings the residual to the floor, keeps both effects beyond
    /// [`REMOVE_BELOW_SIGMA`] and the held-out motions allow it. True when a pair was added.
    pub(super) fn add_best_pair<'r>(
        &mut self,
        runner: Option<&mut (dyn MotionRunner + 'r)>,
    ) -> Result<bool, DiagnoseError> {
        self.pair_tried = true;
        let f = self.fit.clone().ok_or_else(|| DiagnoseError::Model("no fit".into()))?;
        let mut best: Option<(usize, usize, Fit)> = None;
        for (a, b, x) in self.pair_candidates(&f).into_iter().take(PAIRS_REFITTED) {
            let mut start = f.state.clone();
            start.effects.push((self.candidates[a].clone(), x[0]));
            start.effects.push((self.candidates[b].clone(), x[1]));
            let Ok(nf) = self.refit(&start) else { continue };
            if best.as_ref().is_none_or(|(_, _, bf)| nf.chi2() < bf.chi2()) {
                best = Some((a, b, nf));
            }
        }
        let Some((a, b, nf)) = best else { return Ok(false) };
        let k = nf.state.effects.len();
        let kept = nf.effect_z(k - 2) >= REMOVE_BELOW_SIGMA && nf.effect_z(k - 1) >= REMOVE_BELOW_SIGMA;
        let held = [self.held_rms(&f.state)?, self.held_rms(&nf.state)?];
        if !(kept && nf.rms() <= NOISE_FLOOR_FACTOR && self.held_out_allows(held)) {
            return Ok(false);
        }
        self.excluded.retain(|&c| c != a && c != b);
        let ambiguous = |c: usize| -> Vec<String> {
            scoring::ambiguity_set(c, &self.projected).into_iter().map(|o| self.candidates[o].name.clone()).collect()
        };
        let first = named(self.candidates[a].name.clone(), &self.scores[a], &nf, k - 2, ambiguous(a));
        let second = named(self.candidates[b].name.clone(), &self.scores[b], &nf, k - 1, ambiguous(b));
        for effect in [&first, &second] {
            self.steps.push(Step::Added {
                effect: effect.clone(),
                rms_sigma: [f.rms(), nf.rms()],
                held_out_rms_sigma: held,
                confirmed: true,
            });
        }
        self.added.push(first);
        self.keep_added(second, nf, runner)?;
        self.refresh_added_estimates();
        Ok(true)
    }
}
