//! What a diagnosis says of the candidates it did not name and no other list holds: pairs whose
//! signatures cancel on its data, and for every other one the size its data rule out. A result
//! "none" then says how large each unnamed effect could still be, not that it is absent.

use super::Diagnosis;
use crate::diagnose::fit::ModelState;
use crate::diagnose::result::Bound;
use crate::diagnose::scoring;
use crate::diagnose::settings::DETECTABLE_SCORE;

/// Multiples of σ above |estimate| that bound an unnamed candidate.
const BOUND_SIGMAS: f64 = 3.0;

impl Diagnosis {
    /// The candidates the data cannot see at their typical size that no other list holds: not
    /// equivalent to an extrinsic change, not needing the proposed motions, seen, not in the
    /// model `state`, and not what a named effect cannot be told from (the named one took its
    /// signature, it is not invisible).
    pub(super) fn not_detectable(&self, state: &ModelState) -> Vec<String> {
        self.scores
            .iter()
            .filter(|s| {
                s.detectability_at_typical < DETECTABLE_SCORE
                    && !self.equivalent.contains(&s.name)
                    && !self.need_motions.contains(&s.name)
                    && !self.not_seen.contains(&s.name)
                    && !state.effects.iter().any(|(c, _)| c.name == s.name)
                    && !self.added.iter().any(|e| e.ambiguous_with.contains(&s.name))
            })
            .map(|s| s.name.clone())
            .collect()
    }

    /// Whether candidate `k` is reported in no other list: not excluded from naming, not in the
    /// model, not equivalent to an extrinsic change, seen, detectable, and not in a named
    /// effect's ambiguity set.
    fn unreported(&self, k: usize, not_detectable: &[String]) -> bool {
        let name = &self.candidates[k].name;
        !self.excluded.contains(&k)
            && !self.equivalent.contains(name)
            && !self.not_seen.contains(name)
            && !self.need_motions.contains(name)
            && !not_detectable.contains(name)
            && !self.fit.as_ref().is_some_and(|f| f.state.effects.iter().any(|(c, _)| &c.name == name))
            && !self.added.iter().any(|e| e.ambiguous_with.contains(name))
    }

    /// Pairs of candidates, each detectable alone and reported nowhere else, whose projected
    /// signatures on the last scoring are nearly collinear: they can cancel each other.
    pub(super) fn cancelling_pairs(&self, not_detectable: &[String]) -> Vec<[String; 2]> {
        let n = self.projected.len().min(self.candidates.len());
        let open = |k: usize| self.unreported(k, not_detectable);
        let mut pairs = Vec::new();
        for a in (0..n).filter(|&a| open(a)) {
            for b in scoring::ambiguity_set(a, &self.projected).into_iter().filter(|&b| b > a && b < n && open(b)) {
                pairs.push([self.candidates[a].name.clone(), self.candidates[b].name.clone()]);
            }
        }
        pairs
    }

    /// Every candidate reported nowhere else, not in a cancelling pair, with the size its last
    /// scoring rules out: |estimate| + 3σ. A typical-size effect the data would see is not
    /// claimed absent at any size: one at half its typical size may stand below the naming
    /// threshold and still lie under this bound.
    pub(super) fn bounds(&self, not_detectable: &[String], pairs: &[[String; 2]]) -> Vec<Bound> {
        let n = self.scores.len().min(self.candidates.len());
        (0..n)
            .filter(|&k| self.unreported(k, not_detectable))
            .filter(|&k| !pairs.iter().any(|p| p.contains(&self.candidates[k].name)))
            .map(|k| &self.scores[k])
            .filter(|s| s.sigma.is_finite() && s.estimate.is_finite())
            .map(|s| Bound {
                name: s.name.clone(),
                unit: s.unit.clone(),
                estimate: s.estimate,
                sigma: s.sigma,
                below: s.estimate.abs() + BOUND_SIGMAS * s.sigma,
            })
            .collect()
    }
}
