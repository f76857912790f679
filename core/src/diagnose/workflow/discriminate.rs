//! The discriminating motions: what the pool can show of the candidates, the motions chosen
//! for them ([`super::evidence`]), and running them.

use super::evidence::{PoolEvidence, Target};
use super::{Diagnosis, Stage};
use crate::diagnose::fit;
use crate::diagnose::motions::{self, DesignedMotion, MotionRunner};
use crate::diagnose::result::DiagnoseError;
use crate::diagnose::scoring;
use crate::diagnose::settings::{DETECTABLE_SCORE, EQUIVALENT_SHARE, MAX_DESIGN_ROUNDS, MAX_MOTIONS};
use crate::diagnose::step::Step;
use crate::diagnose::validation;
use crate::identify::Observation;
use crate::model::phase::PhaseModel;

/// Pool motions the design leaves out, and why (labels).
#[derive(Debug, Default)]
struct LeftOut {
    /// The observations hold them already.
    recorded: Vec<String>,
    /// The gap turns inside them.
    turns: Vec<String>,
    /// The gap travels under [`motions::MIN_FRINGES`] fringes in them.
    short: Vec<String>,
}

impl Diagnosis {
    /// The pool and what it can show of each target (a candidate, and the candidates it must be
    /// told apart from): the Jacobian and the targets' signatures at the current state over the
    /// data and every pool motion's templates.
    fn pool_evidence(
        &self,
        targets: &[(usize, Vec<usize>)],
    ) -> Result<(Vec<DesignedMotion>, PoolEvidence), DiagnoseError> {
        let f = self.fit.as_ref().ok_or_else(|| DiagnoseError::Model("design before the baseline".into()))?;
        let obs = self.fit_set();
        let t_end = self.observations.iter().map(|o| o.time_s[1]).fold(0.0, f64::max);
        let pool = motions::pool();
        let templates = motions::templates(&pool, t_end + 10.0);
        let all: Vec<Observation> = obs.iter().chain(&templates).cloned().collect();
        let j = fit::jacobian_of(&self.predictor, &f.state, &all)?;
        let signatures = scoring::signatures(&self.predictor, &f.state, &self.candidates, &all)?;
        let motion_rows = pool
            .iter()
            .map(|m| (0..templates.len()).filter(|&k| templates[k].label == m.label).map(|k| obs.len() + k).collect())
            .collect();
        let targets = targets
            .iter()
            .map(|(c, others)| Target {
                signature: signatures[*c].clone(),
                others: others.iter().map(|&o| signatures[o].clone()).collect(),
                typical: self.candidates[*c].typical,
            })
            .collect();
        Ok((pool, PoolEvidence { j, n_data: obs.len(), motion_rows, targets }))
    }

    /// The pool motions the design may choose (true) and those it leaves out: those already
    /// recorded (a label the observations have: run again, they would add nothing the data lack),
    /// and, when the observations come from tracked fringes, those whose fringes cannot be
    /// analysed as the current model predicts them: the gap turns inside them
    /// ([`motions::gap_turns`]), or it travels under [`motions::MIN_FRINGES`] fringes
    /// ([`motions::too_short`]: a q6 turn of ±20° at a lateral offset moves the gap by 0.3 µm,
    /// under one fringe, and its trace is skipped when analysed).
    fn leave_out(&self, pool: &[DesignedMotion], tracked: bool) -> Result<(Vec<bool>, LeftOut), DiagnoseError> {
        let f = self.fit.as_ref().ok_or_else(|| DiagnoseError::Model("design before the baseline".into()))?;
        let mut out = LeftOut::default();
        let per: Vec<Vec<Observation>> =
            pool.iter().map(|m| if tracked { motions::turn_templates(m) } else { vec![] }).collect();
        // Every move's points in one prediction (the model is built once).
        let all: Vec<Observation> = per.iter().flatten().cloned().collect();
        let dl = if all.is_empty() {
            vec![]
        } else {
            self.predictor.predict(&f.state.extrinsics, &f.state.library_effects(), &f.state.gains, &all)?
        };
        let mut at = 0;
        let mut allowed = vec![true; pool.len()];
        for ((m, allow), t) in pool.iter().zip(allowed.iter_mut()).zip(&per) {
            let (from, to) = (at, at + t.len());
            at = to;
            let list = if self.recorded(m) {
                &mut out.recorded
            } else if !t.is_empty() && motions::gap_turns(&dl[from..to]) {
                &mut out.turns
            } else if !t.is_empty() && motions::too_short(&dl[from..to]) {
                &mut out.short
            } else {
                continue;
            };
            *allow = false;
            list.push(m.label.clone());
        }
        Ok((allowed, out))
    }

    /// Whether the observations hold motion `m` already (recorded with the session, added
    /// later, or run by this diagnosis).
    fn recorded(&self, m: &DesignedMotion) -> bool {
        self.observations.iter().any(|o| o.label == m.label)
    }

    /// Run motions on the runner, add their observations (all fitted), refit the current state, rescore.
    fn run_motions<'r>(
        &mut self,
        runner: &mut (dyn MotionRunner + 'r),
        motions: &[DesignedMotion],
    ) -> Result<usize, DiagnoseError> {
        // Analysed as the recorded traces are once effects are named (`reanalyse`): the motion
        // hint and the fringe's shape follow the named effects, and the fringes are tracked with
        // that shape. With the base model and the data's shape, a q6 turn run after the Gouy
        // phase was named missed by tens of σ and the residual rose from 0.86σ to 25σ.
        let analysis = match &self.fit {
            Some(f) => {
                validation::extended_model(self.predictor.base(), f.state.extrinsics, &f.state.library_effects())
                    .map_err(|e| DiagnoseError::Model(e.to_string()))?
            }
            None => PhaseModel { extrinsics: self.start, ..self.predictor.base().clone() },
        };
        let shaped = !self.added.is_empty();
        let new = runner.run(motions, &analysis, shaped).map_err(DiagnoseError::Bench)?;
        let added = new.len();
        self.predictor.extend(&new).map_err(DiagnoseError::Model)?;
        self.held_out.extend(std::iter::repeat_n(false, new.len()));
        self.observations.extend(new);
        self.ran = true;
        self.designed.extend(motions.iter().cloned());
        let start = self.fit.as_ref().map(|f| f.state.clone()).ok_or_else(|| DiagnoseError::Model("no fit".into()))?;
        let f = self.refit(&start)?;
        self.fit = Some(f);
        self.rescore()?;
        // Motions can tell apart branches the session could not.
        self.try_other_branches(Some(runner))?;
        Ok(added)
    }

    /// Stage 4, once what the data show is named: for candidates the data cannot see at their
    /// typical size, pool motions whose projected signature is large, run when a bench is given
    /// (otherwise proposed, when they would make one detectable).
    pub(super) fn design_discriminating_motions<'r>(
        &mut self,
        runner: Option<&mut (dyn MotionRunner + 'r)>,
    ) -> Result<(), DiagnoseError> {
        self.design_done = true;
        let needy: Vec<usize> = (0..self.candidates.len())
            .filter(|&c| self.scores[c].detectability_at_typical < DETECTABLE_SCORE && !self.scores[c].significant)
            .collect();
        let targets: Vec<(usize, Vec<usize>)> = (0..self.candidates.len()).map(|c| (c, vec![])).collect();
        let (pool, evidence) = self.pool_evidence(&targets)?;
        let absorbed = evidence.absorbed();
        let (allowed, left_out) = self.leave_out(&pool, runner.as_deref().is_none_or(|r| r.tracks_fringes()))?;
        // An effect the model holds is named, not equivalent: on the branch its naming led to,
        // the Gouy phase's signature is absorbed by the extrinsics on the data and the pool.
        let in_model = |c: usize| {
            self.fit.as_ref().is_some_and(|f| f.state.effects.iter().any(|(e, _)| e.name == self.candidates[c].name))
        };
        self.equivalent = (0..self.candidates.len())
            .filter(|&c| absorbed[c] >= EQUIVALENT_SHARE && !in_model(c))
            .map(|c| self.candidates[c].name.clone())
            .collect();
        let (chosen, seen) = evidence.only(&needy).choose(&allowed, scoring::naming_threshold(self.candidates.len()));
        // Reported as needing motions: neither equivalent to an extrinsic change nor unseeable.
        let reportable = |c: usize| {
            !self.equivalent.contains(&self.candidates[c].name) && !self.not_seen.contains(&self.candidates[c].name)
        };
        let needy_names: Vec<String> =
            needy.iter().filter(|&&c| reportable(c)).map(|&c| self.candidates[c].name.clone()).collect();
        // Of those, the ones the chosen motions would make detectable at typical size.
        let seen_with_motions: Vec<String> = needy
            .iter()
            .enumerate()
            .filter(|&(t, &c)| reportable(c) && seen[t] >= DETECTABLE_SCORE)
            .map(|(_, &c)| self.candidates[c].name.clone())
            .collect();
        // A plan is proposed only when it would make some candidate detectable: one that adds a
        // little evidence for candidates it leaves undetectable teaches the technician nothing,
        // and the loop would not end (on the other simulator's clean recordings a third pass
        // proposed one q3 reversal for the q4-q6 reversals and lateral tilts no motion shows).
        let motions: Vec<DesignedMotion> = if runner.is_some() || !seen_with_motions.is_empty() {
            chosen.iter().map(|&m| pool[m].clone()).collect()
        } else {
            vec![]
        };
        // Settled: no motion of the pool not yet recorded would show a candidate the data
        // cannot, or a bench runs every one that would (the design was not cut short).
        self.settled = motions.is_empty() || (runner.is_some() && motions.len() < MAX_MOTIONS);
        let labels: Vec<String> = motions.iter().map(|m| m.label.clone()).collect();
        let mut added = 0;
        let mut ran_on = None;
        match (runner, motions.is_empty()) {
            (Some(r), false) => {
                added = self.run_motions(r, &motions)?;
                ran_on = Some(r.name());
            }
            (None, false) => {
                self.need_motions = seen_with_motions;
                self.designed = motions.clone();
            }
            _ => {}
        }
        self.steps.push(Step::Designed {
            needy: needy_names,
            motions: labels,
            ran_on,
            added_observations: added,
            rms_sigma: self.fit.as_ref().map_or(f64::NAN, |f| f.rms()),
            avoided: left_out.turns,
            short: left_out.short,
            recorded: left_out.recorded,
        });
        // On a bench, design again on what the motions showed while they showed nothing to name
        // (see [`MAX_DESIGN_ROUNDS`]); a significant candidate is named first.
        if added > 0 {
            self.design_rounds += 1;
        }
        let nothing_to_name = !self.scores.iter().any(|s| s.significant);
        let again = added > 0 && nothing_to_name && self.design_rounds < MAX_DESIGN_ROUNDS;
        self.stage = if again { Stage::Design } else { Stage::Name };
        Ok(())
    }

    /// When the best candidate cannot be told apart from others, motions that separate them
    /// (each pair's projected signature large), run once per candidate. True when motions ran.
    pub(super) fn separate<'r>(
        &mut self,
        best: usize,
        ambiguous: &[usize],
        runner: &mut (dyn MotionRunner + 'r),
    ) -> Result<bool, DiagnoseError> {
        let name = self.candidates[best].name.clone();
        if ambiguous.is_empty() || self.separated.contains(&name) {
            return Ok(false);
        }
        self.separated.push(name.clone());
        let targets: Vec<(usize, Vec<usize>)> =
            ambiguous.iter().flat_map(|&o| [(best, vec![o]), (o, vec![best])]).collect();
        let needy = std::iter::once(name).chain(ambiguous.iter().map(|&o| self.candidates[o].name.clone())).collect();
        Ok(self.run_separating(needy, &targets, runner)?.is_some())
    }

    /// Run the pool motions not yet designed that tell apart the candidates of each target (a
    /// candidate and those it must be told from), for the candidates `needy`, and say so in a
    /// step. The observations they added, or `None` when the pool has none to run.
    fn run_separating<'r>(
        &mut self,
        needy: Vec<String>,
        targets: &[(usize, Vec<usize>)],
        runner: &mut (dyn MotionRunner + 'r),
    ) -> Result<Option<usize>, DiagnoseError> {
        let (pool, evidence) = self.pool_evidence(targets)?;
        let (allowed, left_out) = self.leave_out(&pool, runner.tracks_fringes())?;
        let motions: Vec<DesignedMotion> = evidence
            .choose(&allowed, scoring::naming_threshold(self.candidates.len()))
            .0
            .into_iter()
            .map(|m| pool[m].clone())
            .filter(|m| !self.designed.contains(m))
            .collect();
        if motions.is_empty() {
            return Ok(None);
        }
        let added = self.run_motions(runner, &motions)?;
        self.steps.push(Step::Designed {
            needy,
            motions: motions.iter().map(|m| m.label.clone()).collect(),
            ran_on: Some(runner.name()),
            added_observations: added,
            rms_sigma: self.fit.as_ref().map_or(f64::NAN, |f| f.rms()),
            avoided: left_out.turns,
            short: left_out.short,
            recorded: left_out.recorded,
        });
        Ok(Some(added))
    }

    /// Once nothing is left to name, on a bench: motions that tell apart each pair of candidates
    /// whose signatures cancel on the data (two effects of opposite sign can leave the residual
    /// at the floor), once per pair. True when they ran: the naming goes on. From recordings
    /// alone the pairs stay listed: proposed, such motions left the pairs' signatures as
    /// collinear over all the data on table2-ideal's designed plan.
    pub(super) fn separate_pairs<'r>(&mut self, runner: &mut (dyn MotionRunner + 'r)) -> Result<bool, DiagnoseError> {
        let f = self.fit.as_ref().ok_or_else(|| DiagnoseError::Model("no fit".into()))?;
        let not_detectable = self.not_detectable(&f.state);
        let pairs: Vec<[String; 2]> =
            self.cancelling_pairs(&not_detectable).into_iter().filter(|p| !self.separated_pairs.contains(p)).collect();
        if pairs.is_empty() {
            return Ok(false);
        }
        self.separated_pairs.extend(pairs.iter().cloned());
        let index = |n: &String| self.candidates.iter().position(|c| &c.name == n);
        let targets: Vec<(usize, Vec<usize>)> = pairs
            .iter()
            .filter_map(|[a, b]| Some((index(a)?, index(b)?)))
            .flat_map(|(a, b)| [(a, vec![b]), (b, vec![a])])
            .collect();
        let needy = pairs.iter().flatten().cloned().collect();
        Ok(self.run_separating(needy, &targets, runner)?.is_some_and(|added| added > 0))
    }
}
