//! The identification from every start the data allow: the bootstrap from absolute gaps at
//! lateral poses, and the minima of the sign-free start fit ([`crate::identify::start`]). Owns the
//! passes (analyse the traces with a model, estimate, analyse again) and the choice of branch.
//!
//! The fringe analysis needs a model: its motion hint gives each trace's direction (intensity is
//! unchanged when the phase runs backwards), so a wrong start can analyse every trace into
//! observations that a wrong estimate then fits. Each start is therefore carried through a whole
//! pass, and the branch whose estimate explains its own observations best wins; branches whose
//! χ² tie are reported, not silently dropped.

use crate::identify::joint::{self, JointEstimate, JointOptions};
use crate::identify::measurements::{
    observations_from_seeded, observations_from_traces, sweep_seeds, ExtractOptions, Extracted,
};
use crate::identify::start::{found_before, same_branch, start_branches, travels};
use crate::identify::verdict::{BranchSummary, TIE_DELTA_CHI2};
use crate::identify::{paper, Observation, ObservationKind};
use crate::model::extrinsics::Extrinsics;
use crate::model::phase::PhaseModel;
use crate::trace::Trace;
use std::borrow::Borrow;

/// Which identifier.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Mode {
    /// The paper's steps A, B, C on strategies 1 and 2.
    Paper,
    /// Every parameter from every measurement at once, with tilt scans and absolute gaps.
    Joint,
}

/// A start of the identification.
#[derive(Debug, Clone)]
pub struct Start {
    /// Where it comes from ("absolute gaps", "fringe travel 1", …).
    pub name: String,
    /// The extrinsics to analyse the traces with first.
    pub extrinsics: Extrinsics,
}

/// Start-fit minima carried into a pass: at most this many, and only those whose cost is within
/// [`START_KEEP_FACTOR`] of the best (plus [`START_KEEP_MARGIN`]).
const MAX_TRAVEL_STARTS: usize = 6;
const START_KEEP_FACTOR: f64 = 3.0;
const START_KEEP_MARGIN: f64 = 30.0;

/// The starts the data allow, without duplicates: the bootstrap from at least three absolute
/// gaps (the lamella normal from gap differences between poses, and the gap), then the minima
/// of the sign-free start fit.
pub fn starting_points<T: Borrow<Trace>>(nominal: &PhaseModel, motions: &[T], gaps: &[Observation]) -> Vec<Start> {
    let mut starts: Vec<Start> = Vec::new();
    if gaps.len() >= 3 {
        let boot = JointOptions { free: [true, true, false, false, false, false, true, false], ..Default::default() };
        let est = joint::estimate(nominal, gaps, &nominal.extrinsics, &boot);
        if est.converged {
            starts.push(Start { name: "absolute gaps".into(), extrinsics: est.extrinsics });
        }
    }
    let wavelength_nm = motions.iter().find_map(|t| t.borrow().wavelength_nm.first().copied()).unwrap_or(1560.0);
    let branches = start_branches(nominal, &travels(motions, nominal.n_air), gaps, wavelength_nm);
    if let Some(best) = branches.first().map(|b| b.chi2) {
        let keep = START_KEEP_FACTOR * best + START_KEEP_MARGIN;
        for b in branches.iter().filter(|b| b.chi2 <= keep).take(MAX_TRAVEL_STARTS) {
            if !starts.iter().any(|s| same_branch(&s.extrinsics, &b.extrinsics)) {
                let name = format!("fringe travel {}", starts.len() + 1);
                starts.push(Start { name, extrinsics: b.extrinsics });
            }
        }
    }
    if starts.is_empty() {
        starts.push(Start { name: "nominal design".into(), extrinsics: nominal.extrinsics });
    }
    starts
}

/// What one branch of [`identify`] found.
#[derive(Debug, Clone)]
pub struct Identification {
    /// The estimate with its Jacobian and residuals.
    pub estimate: JointEstimate,
    /// The observations it used.
    pub observations: Vec<Observation>,
    /// Paper mode: step A's details.
    pub step_a: Option<paper::StepA>,
    /// Traces that gave no observation (label, why).
    pub skipped: Vec<(String, String)>,
    /// Tracked motions whose travel departs from their fringe count (label, why): their
    /// tracking followed the motion hint of these extrinsics, not the fringes.
    pub hint_led: Vec<(String, String)>,
    /// Every branch run, best first (the chosen one first).
    pub branches: Vec<BranchSummary>,
    /// The branches whose χ² ties with the chosen one's (indices into `branches`, never 0).
    pub tied: Vec<usize>,
    /// Traces whose observations were weighted down as outliers, with the factor their σ were
    /// multiplied by ([`downweight_outliers`]).
    pub downweighted: Vec<(String, f64)>,
}

impl Identification {
    /// The normalised residuals with every observation's σ as the analysis gave it (before any
    /// outlier was weighted down): what the verdict on the fit reads.
    pub fn raw_normalised_residuals(&self) -> Vec<f64> {
        self.observations
            .iter()
            .zip(&self.estimate.residuals)
            .map(|(o, r)| {
                let f = self.downweighted.iter().find(|d| d.0 == o.label).map_or(1.0, |d| d.1);
                r / (o.sigma / f)
            })
            .collect()
    }
}

impl Identification {
    /// The branch's cost ([`BranchSummary::cost`]).
    fn cost(&self) -> f64 {
        self.summary("").cost()
    }

    fn summary(&self, start: &str) -> BranchSummary {
        let n = self.estimate.normalised_residuals.len().max(1);
        let chi2: f64 = self.estimate.normalised_residuals.iter().map(|r| r * r).sum();
        BranchSummary {
            start: start.to_string(),
            extrinsics: self.estimate.extrinsics,
            chi2,
            rms_sigma: (chi2 / n as f64).sqrt(),
            skipped_traces: self.skipped.len(),
            hint_led_traces: self.hint_led.len(),
        }
    }
}

/// Fringe amplitudes kept per rotation: a ±4° tilt scan has about 30.
const AMPLITUDES_PER_TRACE: usize = 40;

/// How the identification reads traces: every rotation is also a tilt scan (its fringe
/// amplitudes, from three extrema in a row, locate where the lamella faces the fiber), whatever
/// its label says: a recording from elsewhere names its motions as it likes.
pub fn extract_options() -> ExtractOptions {
    ExtractOptions {
        amplitudes_from_rotations: true,
        amplitude_neighbours: true,
        max_amplitudes_per_trace: Some(AMPLITUDES_PER_TRACE),
        ..ExtractOptions::default()
    }
}

/// A trace whose observations' residual rms exceeds this (σ) is an outlier: its tracking
/// slipped or its motion is one the model cannot follow.
pub const OUTLIER_TRACE_SIGMA: f64 = 1.5;

/// The estimate again with each outlier trace's σ multiplied by its residual rms, so that one
/// trace the analysis got wrong (a fringe slipped at a turning point, a motion in the dark)
/// cannot drag the parameters while claiming its nominal σ. The verdict still reads the
/// residuals at the analysis's σ ([`Identification::raw_normalised_residuals`]).
fn downweight_outliers(nominal: &PhaseModel, id: Identification) -> Identification {
    let labels: Vec<String> = id.observations.iter().map(|o| o.label.clone()).collect();
    let per_trace = crate::identify::verdict::worst_traces(&labels, &id.estimate.normalised_residuals, usize::MAX);
    let downweighted: Vec<(String, f64)> =
        per_trace.into_iter().filter(|t| t.rms_sigma > OUTLIER_TRACE_SIGMA).map(|t| (t.label, t.rms_sigma)).collect();
    if downweighted.is_empty() {
        return id;
    }
    let mut observations = id.observations.clone();
    for o in &mut observations {
        if let Some(d) = downweighted.iter().find(|d| d.0 == o.label) {
            o.sigma *= d.1;
        }
    }
    let estimate = joint::estimate(nominal, &observations, &id.estimate.extrinsics, &JointOptions::default());
    Identification { estimate, observations, downweighted, ..id }
}

/// `base` with extrinsics `e`.
pub(crate) fn model_with(base: &PhaseModel, e: Extrinsics) -> PhaseModel {
    PhaseModel { extrinsics: e, ..base.clone() }
}

/// Identify from recorded traces. `nominal` is the model before calibration (design
/// extrinsics); it also supplies the robot, optics and air. Every start of
/// [`starting_points`] is carried through a first pass; in joint mode every distinct branch
/// gets a second pass with its own estimate, outlier traces downweighted. The branch with the
/// lowest χ² is returned, the others are kept in [`Identification::branches`], those that tie
/// with it listed in [`Identification::tied`].
pub fn identify(traces: &[Trace], nominal: &PhaseModel, mode: Mode) -> Result<Identification, String> {
    use rayon::prelude::*;
    let t0 = std::time::Instant::now();
    let phase_done = |what: &str| tracing::debug!(elapsed_s = t0.elapsed().as_secs_f64(), "identification: {what}");
    let (sweeps, motions): (Vec<&Trace>, Vec<&Trace>) = traces.iter().partition(|t| crate::trace::is_sweep(t));
    // A sweep's two-beam fit does not depend on the extrinsics: fitted once, reused by every pass.
    let seeds = sweep_seeds(&sweeps, nominal);
    let swept = observations_from_seeded(&sweeps, &seeds, nominal, &extract_options());
    if motions.is_empty() && swept.observations.is_empty() {
        return Err("no trace could be analysed: nothing to identify from".into());
    }
    phase_done("sweeps fitted");
    let starts = starting_points(nominal, &motions, &swept.observations);
    phase_done("starts found");
    // The first pass reads the sweeps as the nominal model analyses them: a sweep's gap depends
    // on the tilt the model puts the lamella at in its pose (up to 0.3 µm between a square
    // model and Table II's 1.1°), so there they count with that much uncertainty.
    let loose = loosen(&swept, FIRST_PASS_GAP_SIGMA_UM);
    let mut runs: Vec<(String, Identification)> = starts
        .par_iter()
        .map(|s| (s.name.clone(), one_pass(mode, nominal, &loose, &motions, s.extrinsics, FIRST_PASS)))
        .collect();
    runs.sort_by(|a, b| a.1.cost().total_cmp(&b.1.cost()));
    phase_done("first passes");
    if mode == Mode::Joint {
        runs = second_passes(runs, |e| {
            let swept = observations_from_seeded(&sweeps, &seeds, &model_with(nominal, e), &extract_options());
            // Outlier traces downweighted in every branch, so that one trace its model
            // tracked badly does not decide between branches.
            downweight_outliers(nominal, one_pass(mode, nominal, &swept, &motions, e, FINAL_PASS))
        });
        phase_done("second passes");
    }
    let (best_name, mut best) = runs.remove(0);
    let best_cost = best.cost();
    let mut branches = vec![best.summary(&best_name)];
    let mut tied = Vec::new();
    // A tie: a distinct branch that refitted to the chosen branch's data fits them as well; in
    // joint mode also one whose own analysis fits as well (Δχ² < 9), every branch having had
    // its full second pass. The paper's steps read only the translations, each branch with
    // its own model: there two χ² of different branches are not comparable on their own.
    // A branch found from several starts counts once.
    let listed: Vec<Extrinsics> =
        std::iter::once(&best).chain(runs.iter().map(|r| &r.1)).map(|id| id.estimate.extrinsics).collect();
    let repeat: Vec<bool> = (1..listed.len()).map(|k| found_before(&listed, k).is_some()).collect();
    let rivals: Vec<Option<BranchSummary>> = runs
        .par_iter()
        .zip(repeat)
        .map(|((name, run), repeat)| {
            let own = run.summary(name);
            if repeat {
                return None;
            }
            let close = run.cost() - best_cost < TIE_DELTA_CHI2;
            if mode == Mode::Joint && close && !same_branch(&own.extrinsics, &best.estimate.extrinsics) {
                return Some(own);
            }
            if mode == Mode::Paper && !close {
                return None;
            }
            rival_on_the_same_data(nominal, &best, name, &run.estimate.extrinsics)
        })
        .collect();
    for ((name, run), rival) in runs.iter().zip(rivals) {
        match rival {
            Some(r) => {
                tied.push(branches.len());
                branches.push(r);
            }
            None => branches.push(run.summary(name)),
        }
    }
    best.branches = branches;
    best.tied = tied;
    phase_done("branches compared");
    Ok(best)
}

/// Joint mode's second passes over `runs` (first passes, best first), sorted again: every
/// distinct branch analysed and estimated again by `pass` from its first estimate (a start's
/// first analysis can go astray and leave the right branch at 16σ, as on a pool plan of 12
/// motions where the mirrored lamella then won). A start whose first pass ended in a branch
/// already found takes that branch's second pass: its own first pass read other data (the
/// nominal model's analysis, loosened gaps), so neither its χ² nor its place within the basin
/// compares with a second pass (on the designed plan through TCP it stayed 0.04-0.05° from
/// its branch's final estimate, a tie or not depending on the host's timing).
fn second_passes<F>(runs: Vec<(String, Identification)>, pass: F) -> Vec<(String, Identification)>
where
    F: Fn(Extrinsics) -> Identification + Sync,
{
    use rayon::prelude::*;
    let firsts: Vec<Extrinsics> = runs.iter().map(|r| r.1.estimate.extrinsics).collect();
    let mut twin: Vec<Option<usize>> = Vec::with_capacity(runs.len());
    for k in 0..runs.len() {
        twin.push(found_before(&firsts, k).map(|j| twin[j].unwrap_or(j)));
    }
    let finals: Vec<Option<Identification>> = runs
        .par_iter()
        .zip(&twin)
        .map(|((_, first), twin)| twin.is_none().then(|| pass(first.estimate.extrinsics)))
        .collect();
    let mut out: Vec<(String, Identification)> = runs
        .into_iter()
        .enumerate()
        .map(|(k, (name, first))| (name, finals[twin[k].unwrap_or(k)].clone().unwrap_or(first)))
        .collect();
    out.sort_by(|a, b| a.1.cost().total_cmp(&b.1.cost()));
    out
}

/// The branch started at `other` refitted to the chosen branch's own observations, when it ends
/// at a distinct minimum within [`TIE_DELTA_CHI2`] of the chosen one: a tie. Each branch
/// analyses the traces with its own model, so two χ² of different branches are of different
/// data; and a branch whose own analysis went astray (a tracking that failed with its model)
/// may still fit the chosen branch's data as well as the chosen estimate does: on a pool plan
/// of 12 motions and one sweep, the mirrored lamella (β_et −0.744°) fitted at 1.24σ rms while
/// the truth's own pass ended at 16σ.
fn rival_on_the_same_data(
    nominal: &PhaseModel,
    best: &Identification,
    name: &str,
    other: &Extrinsics,
) -> Option<BranchSummary> {
    if same_branch(other, &best.estimate.extrinsics) {
        return None;
    }
    let chi2 = |r: &[f64]| -> f64 { r.iter().map(|v| v * v).sum() };
    let own = chi2(&best.estimate.normalised_residuals);
    let ties = |e: &joint::JointEstimate| {
        chi2(&e.normalised_residuals) - own < TIE_DELTA_CHI2 && !same_branch(&e.extrinsics, &best.estimate.extrinsics)
    };
    let short = JointOptions { patience: FIRST_PASS.patience, ..JointOptions::default() };
    let mut refit = joint::estimate(nominal, &best.observations, other, &short);
    if !ties(&refit) {
        return None;
    }
    // A tie needs a minimum of its own: a short refit can stop on its way into the chosen one.
    refit = joint::estimate(nominal, &best.observations, &refit.extrinsics, &JointOptions::default());
    let cross = chi2(&refit.normalised_residuals);
    (ties(&refit) && refit.converged).then(|| BranchSummary {
        start: format!("{name}, refitted to the chosen branch's data"),
        extrinsics: refit.extrinsics,
        chi2: cross,
        rms_sigma: (cross / refit.normalised_residuals.len().max(1) as f64).sqrt(),
        skipped_traces: best.skipped.len(),
        hint_led_traces: best.hint_led.len(),
    })
}

/// How far one pass goes: the fringe amplitudes kept over all traces (each costs the fit three
/// windowed power models per evaluation: a plan of rotations only gives hundreds, and a few
/// dozen evenly spread along each rotation locate the tilt as well) and the solver's patience
/// (evaluations per parameter).
#[derive(Debug, Clone, Copy)]
struct Pass {
    amplitudes: usize,
    patience: usize,
    /// Motions tracked with the model's fringe shape at the pass's start
    /// ([`ExtractOptions::shaped`]).
    shaped: bool,
}

/// The first pass only has to reach a branch's basin: a start that has not settled within 15
/// evaluations per parameter is far from any minimum (one such start ran 3,600 evaluations,
/// 200 s, on a plan of rotations only, and lost). The final pass keeps what sixteen ±4° scans
/// give (the shipped joint plans have about 540 amplitudes: thinned to 320, σ(β_wf) grew from
/// 0.0006° to 0.0009°).
const FIRST_PASS: Pass = Pass { amplitudes: 120, patience: 15, shaped: false };
const FINAL_PASS: Pass = Pass { amplitudes: 640, patience: 200, shaped: true };

/// The observations with at most `budget` fringe amplitudes, shared evenly between the gain
/// groups (each rotation's own) and evenly spread within each; the other kinds all kept.
fn within_amplitude_budget(obs: Vec<Observation>, budget: usize) -> Vec<Observation> {
    let group_of = |o: &Observation| match o.kind {
        ObservationKind::FringeAmplitude { group, .. } => Some(group),
        _ => None,
    };
    let mut counts = std::collections::BTreeMap::<usize, usize>::new();
    for g in obs.iter().filter_map(group_of) {
        *counts.entry(g).or_default() += 1;
    }
    let total: usize = counts.values().sum();
    if total <= budget {
        return obs;
    }
    let per_group = (budget / counts.len().max(1)).max(MIN_AMPLITUDES_PER_GROUP);
    let mut seen = std::collections::BTreeMap::<usize, usize>::new();
    obs.into_iter()
        .filter(|o| {
            let Some(g) = group_of(o) else { return true };
            let (n, k) = (counts[&g], seen.entry(g).or_default());
            let index = *k;
            *k += 1;
            // Keep the indices nearest an even spread of `per_group` over 0..n (first and last kept).
            n <= per_group || (0..per_group).any(|j| j * (n - 1) / (per_group - 1).max(1) == index)
        })
        .collect()
}

/// A gain group keeps at least this many amplitudes: its gain takes one of them.
const MIN_AMPLITUDES_PER_GROUP: usize = 6;

/// σ floor of the absolute gaps in the first pass (µm): what the nominal model's tilt can move
/// a sweep's analysis by.
const FIRST_PASS_GAP_SIGMA_UM: f64 = 0.5;

/// The observations with each absolute gap's σ raised to at least `floor_um`.
fn loosen(swept: &Extracted, floor_um: f64) -> Extracted {
    let mut out = swept.clone();
    for o in &mut out.observations {
        if matches!(o.kind, ObservationKind::AbsoluteGap { .. }) {
            o.sigma = o.sigma.hypot(floor_um);
        }
    }
    out
}

/// One pass from `current`: the motions analysed with its model, then the mode's estimate from
/// the sweeps' and the motions' observations.
fn one_pass(
    mode: Mode,
    nominal: &PhaseModel,
    swept: &Extracted,
    motions: &[&Trace],
    current: Extrinsics,
    pass: Pass,
) -> Identification {
    let model = model_with(nominal, current);
    let options = ExtractOptions { shaped: pass.shaped, ..extract_options() };
    let mut extracted = observations_from_traces(motions, &model, &options);
    extracted.skipped.extend(swept.skipped.iter().cloned());
    let mut obs = swept.observations.clone();
    obs.append(&mut extracted.observations);
    let obs = within_amplitude_budget(obs, pass.amplitudes);
    let (estimate, step_a, observations) = match mode {
        Mode::Joint => {
            let options = JointOptions { patience: pass.patience, ..JointOptions::default() };
            (joint::estimate(nominal, &obs, &current, &options), None, obs)
        }
        Mode::Paper => {
            let (est, a, translations) = paper_estimate(nominal, &obs, &current);
            (est, Some(a), translations)
        }
    };
    Identification {
        estimate,
        observations,
        step_a,
        skipped: extracted.skipped,
        hint_led: extracted.hint_led,
        branches: vec![],
        tied: vec![],
        downweighted: vec![],
    }
}

/// The paper's steps A and B on the translations and rotations of `obs`, with the joint
/// machinery's uncertainties evaluated at the result on step A's data.
fn paper_estimate(
    nominal: &PhaseModel,
    obs: &[Observation],
    current: &Extrinsics,
) -> (JointEstimate, paper::StepA, Vec<Observation>) {
    let translations: Vec<Observation> = obs.iter().filter(|o| is_translation(o)).cloned().collect();
    let rotations: Vec<Observation> = obs.iter().filter(|o| is_rotation(o)).cloned().collect();
    let a = paper::step_a_with(&nominal.chain, &translations, current, true);
    let b = paper::step_b(&nominal.chain, &rotations, a.angles_deg);
    let e = Extrinsics {
        beta_et_deg: a.angles_deg[0],
        theta_et_deg: a.angles_deg[1],
        beta_wf_deg: a.angles_deg[2],
        theta_wf_deg: a.angles_deg[3],
        z_et_um: b.origins_um[0],
        x_wf_um: b.origins_um[1],
        y_wf_um: b.origins_um[2],
        z_wf_um: b.origins_um[3],
    };
    // Step A's data only: step B reads the fringes as the change of L along the beam where
    // they measure the perpendicular distance (a bias of |L|·(1 − cos γ), µm over the 4°
    // rotations), so its residuals say nothing about the noise, and the origins stay
    // undetermined by the data the method can trust. Evaluated with the start's origins
    // (translations barely depend on them), then the step B origins put back for the report.
    let at = Extrinsics {
        z_et_um: current.z_et_um,
        x_wf_um: current.x_wf_um,
        y_wf_um: current.y_wf_um,
        z_wf_um: current.z_wf_um,
        ..e
    };
    let mut est = joint::evaluate(nominal, &translations, &at, &JointOptions::default());
    est.extrinsics = e;
    est.converged = a.converged;
    est.termination = format!("step A: {}", if a.converged { "converged" } else { "did not converge" });
    (est, a, translations)
}

fn joints_changed(o: &Observation) -> Option<[bool; 6]> {
    match o.kind {
        ObservationKind::GapChange { from_display, to_display, .. } => {
            Some(std::array::from_fn(|i| (from_display[i] - to_display[i]).abs() > 1e-9))
        }
        _ => None,
    }
}

/// A gap change over a translation: only prismatic joints moved.
pub fn is_translation(o: &Observation) -> bool {
    joints_changed(o).is_some_and(|c| c[..3].iter().any(|&x| x) && !c[3..].iter().any(|&x| x))
}

/// A gap change over a rotation: only revolute joints moved.
pub fn is_rotation(o: &Observation) -> bool {
    joints_changed(o).is_some_and(|c| c[3..].iter().any(|&x| x) && !c[..3].iter().any(|&x| x))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn amplitude(group: usize, index: usize) -> Observation {
        Observation {
            label: format!("motion {group}"),
            kind: ObservationKind::FringeAmplitude {
                at_display: [index as f64, 0.0, 0.0, 0.0, 0.0, 0.0],
                amplitude_mw: 1.0,
                group,
                neighbours: None,
            },
            sigma: 0.01,
            wavelength_nm: 1550.0,
            time_s: [0.0; 2],
            approach: [[0; 6]; 2],
        }
    }

    fn gap() -> Observation {
        Observation {
            kind: ObservationKind::AbsoluteGap { at_display: [0.0; 6], gap_um: 100.0, sweep_nm_per_s: 0.0 },
            ..amplitude(0, 0)
        }
    }

    /// Kept per group: the budget shared evenly, the ends of each kept, the other kinds kept.
    #[test]
    fn the_amplitude_budget_is_shared_evenly_and_keeps_the_ends() {
        let mut obs = vec![gap()];
        obs.extend((0..40).map(|i| amplitude(0, i)));
        obs.extend((0..10).map(|i| amplitude(1, i)));
        obs.extend((0..100).map(|i| amplitude(2, i)));
        obs.push(gap());
        let kept = within_amplitude_budget(obs.clone(), 45);
        let of = |g: usize| -> Vec<f64> {
            kept.iter()
                .filter_map(|o| match o.kind {
                    ObservationKind::FringeAmplitude { group, at_display, .. } if group == g => Some(at_display[0]),
                    _ => None,
                })
                .collect()
        };
        assert_eq!(kept.iter().filter(|o| matches!(o.kind, ObservationKind::AbsoluteGap { .. })).count(), 2);
        assert_eq!(of(0).len(), 15);
        assert_eq!(of(1).len(), 10, "a group under its share keeps all");
        assert_eq!(of(2).len(), 15);
        assert_eq!((of(2)[0], of(2)[14]), (0.0, 99.0));
        assert_eq!(within_amplitude_budget(obs.clone(), 150).len(), obs.len(), "within budget: all kept");
        let tiny = within_amplitude_budget(obs, 3);
        assert_eq!(tiny.len(), 2 + 3 * MIN_AMPLITUDES_PER_GROUP, "each gain keeps its minimum");
    }

    /// A branch's pass result at `e` with χ² `chi2` (one residual), for the branch logic alone.
    fn pass_result(e: Extrinsics, chi2: f64) -> Identification {
        let estimate = JointEstimate {
            extrinsics: e,
            gains: vec![],
            converged: true,
            termination: String::new(),
            evaluations: 0,
            residuals: vec![chi2.sqrt()],
            normalised_residuals: vec![chi2.sqrt()],
            weighted_jacobian: nalgebra::DMatrix::zeros(1, 8),
            column_names: vec![],
            column_parameter: vec![],
        };
        Identification {
            estimate,
            observations: vec![],
            step_a: None,
            skipped: vec![],
            hint_led: vec![],
            branches: vec![],
            tied: vec![],
            downweighted: vec![],
        }
    }

    /// A start whose first pass ended 0.03° from an earlier one's (one branch) takes that
    /// branch's second pass, however far the second pass moved: its own first pass, left as it
    /// was, lay 0.07° from the final estimate, a distinct branch tying with it. A distinct start
    /// gets its own pass; each pass runs once.
    #[test]
    fn a_start_in_a_branch_already_found_takes_that_branchs_second_pass() {
        let truth = Extrinsics::nominal_design();
        let with_theta = |d: f64| Extrinsics { theta_et_deg: truth.theta_et_deg + d, ..truth };
        let mirrored = Extrinsics { beta_et_deg: -truth.beta_et_deg - 1.0, ..truth };
        let runs = vec![
            ("fringe travel 2".to_string(), pass_result(with_theta(-0.04), 2.3)),
            ("absolute gaps".to_string(), pass_result(with_theta(-0.07), 2.4)),
            ("fringe travel 3".to_string(), pass_result(mirrored, 40.0)),
            ("fringe travel 4".to_string(), pass_result(with_theta(-0.10), 2.5)),
        ];
        assert!(same_branch(&runs[0].1.estimate.extrinsics, &runs[1].1.estimate.extrinsics));
        assert!(!same_branch(&runs[1].1.estimate.extrinsics, &truth), "left as it was, a distinct branch");
        let calls = std::sync::atomic::AtomicUsize::new(0);
        let out = second_passes(runs, |e| {
            calls.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            // The second pass lands on the truth from anywhere in its basin, χ² 2.1.
            if same_branch(&e, &with_theta(-0.05)) {
                pass_result(truth, 2.1)
            } else {
                pass_result(e, 30.0)
            }
        });
        assert_eq!(calls.into_inner(), 2, "one pass per distinct branch");
        let names: Vec<&str> = out.iter().map(|r| r.0.as_str()).collect();
        assert_eq!(names, ["fringe travel 2", "absolute gaps", "fringe travel 4", "fringe travel 3"]);
        for (name, run) in &out[..3] {
            assert_eq!(run.estimate.extrinsics, truth, "{name}: its branch's second pass");
            assert!((run.cost() - 2.1).abs() < 1e-12, "{name}");
        }
        assert_eq!(out[3].1.estimate.extrinsics, mirrored);
        assert!((out[3].1.cost() - 30.0).abs() < 1e-12, "the distinct start's own second pass");
    }
}
