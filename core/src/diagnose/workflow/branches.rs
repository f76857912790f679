//! The calibration's other branches: extrinsics that fitted the session's traces nearly as well
//! as the chosen ones. A model that lacks an effect can choose the wrong branch (on table2-ideal
//! with the Gouy phase hidden, the mirrored lamella, θ_et +0.595° for −0.594°, won by a χ² of 56).
//! Once an effect is named, or motions that tell the branches apart have run, every branch is
//! tried again with the current effects, its traces analysed with its own motion hint.

use super::{held_out_mask, not_held_out, Diagnosis};
use crate::diagnose::fit::{self, Fit, ModelState};
use crate::diagnose::motions::MotionRunner;
use crate::diagnose::result::DiagnoseError;
use crate::diagnose::settings::BRANCH_MARGIN_CHI2;
use crate::diagnose::step::Step;
use crate::identify::start::same_branch;
use crate::identify::{Observation, N_EXTRINSICS};
use crate::model::extrinsics::Extrinsics;

impl Diagnosis {
    /// Extrinsics of the calibration's other branches, tried again whenever the model or the
    /// data change: one of each branch ([`same_branch`]; several starts of a calibration end in
    /// the same one), not the start's.
    pub fn set_branches(&mut self, branches: &[Extrinsics]) {
        self.branches.clear();
        for b in branches {
            if !same_branch(b, &self.start) && !self.branches.iter().any(|o| same_branch(o, b)) {
                self.branches.push(*b);
            }
        }
    }

    /// Try every other branch with the current effects: the traces analysed with its model, the
    /// extrinsics fitted from it. When one fits its data better than the current fit does its
    /// own, by more than [`BRANCH_MARGIN_CHI2`] (χ² scaled to the current number of fitted
    /// observations), it becomes the fit (the branch left joins the others) and a step says so.
    /// Returns whether the branch changed.
    pub(super) fn try_other_branches<'r>(
        &mut self,
        mut runner: Option<&mut (dyn MotionRunner + 'r)>,
    ) -> Result<bool, DiagnoseError> {
        let Some(f) = self.fit.clone() else { return Ok(false) };
        let n_now = self.held_out.iter().filter(|h| !**h).count().max(1) as f64;
        let mut best: Option<(usize, Fit, Vec<Observation>, f64)> = None;
        for k in 0..self.branches.len() {
            let state = ModelState { extrinsics: self.branches[k], ..f.state.clone() };
            let obs = self.analysed_with(runner.as_deref_mut(), &state)?.unwrap_or_else(|| self.observations.clone());
            let fitted = not_held_out(&obs, &held_out_mask(&obs));
            let Ok(nf) = fit::fit(&self.predictor, &fitted, &state, &[true; N_EXTRINSICS]) else { continue };
            let chi2 = nf.chi2() * n_now / fitted.len().max(1) as f64;
            let lowest = best.as_ref().map_or(f.chi2() - BRANCH_MARGIN_CHI2, |b| b.3);
            if chi2 < lowest {
                best = Some((k, nf, obs, chi2));
            }
        }
        let Some((k, nf, obs, chi2)) = best else { return Ok(false) };
        self.branches[k] = f.state.extrinsics;
        self.steps.push(Step::Branch {
            from: f.state.extrinsics,
            to: nf.state.extrinsics,
            chi2: [f.chi2(), chi2],
            rms_sigma: [f.rms(), nf.rms()],
        });
        self.held_out = held_out_mask(&obs);
        self.observations = obs;
        self.fit = Some(nf);
        self.rescore()?;
        Ok(true)
    }
}
