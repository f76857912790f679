//! The equivalents a named effect cannot be told from on these data, by refitting: another
//! candidate in its place, with the other named effects, fits within [`EQUIVALENT_CHI2`] of it.

use super::Diagnosis;
use crate::diagnose::fit::Fit;
use crate::diagnose::result::DiagnoseError;
use crate::diagnose::scoring;
use crate::diagnose::settings::REMOVE_BELOW_SIGMA;

/// Another candidate in a named effect's place that fits within this χ² of it is one the data
/// cannot tell from it (3σ for one parameter).
pub const EQUIVALENT_CHI2: f64 = 9.0;

/// Only candidates whose signature, beside the other effects and the extrinsics, is this close
/// in direction to the named effect's are refitted in its place (|cos| above it).
const NEAR_COSINE: f64 = 0.8;

impl Diagnosis {
    /// For each named effect of the final fit `f`, list beside it the candidates that, refitted
    /// in its place with the other effects, fit within [`EQUIVALENT_CHI2`] of `f` and keep a
    /// size beyond [`REMOVE_BELOW_SIGMA`]: the data do not tell which of the two is there.
    pub(super) fn list_refitted_equivalents(&mut self, f: &Fit) -> Result<(), DiagnoseError> {
        let obs = self.fit_set();
        for k in 0..f.state.effects.len() {
            let own = f.state.effects[k].0.name.clone();
            let Some(i) = self.added.iter().position(|e| e.name == own) else { continue };
            let Some(c_own) = self.candidates.iter().position(|c| c.name == own) else { continue };
            let mut without = f.state.clone();
            without.effects.remove(k);
            let nf = self.refit(&without)?;
            let signatures = scoring::signatures(&self.predictor, &nf.state, &self.candidates, &obs)?;
            let (scores, projected) = scoring::score(&self.candidates, &signatures, &nf.jacobian, &nf.residuals);
            for c in scoring::near_in_direction(c_own, &projected, NEAR_COSINE) {
                let name = &self.candidates[c].name;
                if self.added[i].ambiguous_with.contains(name) || f.state.effects.iter().any(|(e, _)| &e.name == name) {
                    continue;
                }
                let mut start = nf.state.clone();
                start.effects.insert(k, (self.candidates[c].clone(), scores[c].estimate));
                let sf = self.refit(&start)?;
                if sf.chi2() - f.chi2() < EQUIVALENT_CHI2 && sf.effect_z(k) >= REMOVE_BELOW_SIGMA {
                    self.added[i].ambiguous_with.push(name.clone());
                }
            }
        }
        Ok(())
    }
}
