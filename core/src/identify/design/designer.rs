//! [`design`]: the candidate pool run on the pilot bench, the selection against the targets,
//! the plan it writes and the σ predicted for it (and for reference plans).

use super::assemble::assemble;
use super::error::DesignError;
use super::pilot::{pilot, plans_information, PilotResult};
use super::pool::{candidate_pool, Candidate, CandidateKind};
use super::selection::{select, Criterion, Selection, SelectionProblem};
use super::targets::{weak_prior, Target, BOOTSTRAP_FREE};
use crate::bench::BenchPreset;
use crate::model::extrinsics::Extrinsics;
use crate::model::robot::RobotDescription;
use crate::plan::{Plan, Segment, TimedSegment};
use serde::{Deserialize, Serialize};

/// Options of [`design`].
#[derive(Debug, Clone, PartialEq)]
pub struct DesignOptions {
    /// The required σ.
    pub targets: Vec<Target>,
    /// The design aims at `margin × max_sigma` (0 < margin ≤ 1; default 0.8).
    pub margin: f64,
    /// Extrinsics at which the model is linearised and which the pilot bench takes as truth.
    pub prior: Extrinsics,
    /// Seed of the pilot bench.
    pub seed: u64,
}

impl Default for DesignOptions {
    fn default() -> Self {
        Self { targets: Target::acceptance_targets(), margin: 0.8, prior: Extrinsics::nominal_design(), seed: 1 }
    }
}

/// A chosen motion in a design.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChosenMotion {
    /// Label of the recorded segment.
    pub label: String,
    /// What it is.
    pub kind: CandidateKind,
    /// Bench time of its setup move in the plan's order (s).
    pub setup_s: f64,
    /// Bench time of the recorded segment (s).
    pub duration_s: f64,
    /// Observations it gave on the pilot bench.
    pub observations: usize,
}

/// A target with the σ predicted for the design (and for a reference plan).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TargetResult {
    /// Target name.
    pub name: String,
    /// Unit.
    pub unit: String,
    /// Required σ.
    pub required_sigma: f64,
    /// The σ the design aimed at (required × margin).
    pub design_sigma: f64,
    /// Predicted σ of the designed plan.
    pub predicted_sigma: f64,
    /// Predicted σ of the reference plan (the default joint plans), if computed.
    pub reference_sigma: Option<f64>,
}

/// A design: the plan, its bench time and its predicted uncertainties.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Design {
    /// The plan (run it with `photorobot calibrate --plan`).
    pub plan: Plan,
    /// Its total bench time from q = 0 (s), from the plan's timing model.
    pub total_s: f64,
    /// The chosen motions in plan order.
    pub chosen: Vec<ChosenMotion>,
    /// Targets and predicted σ.
    pub targets: Vec<TargetResult>,
    /// Candidates in the pool, and how many gave no observation on the pilot bench.
    pub pool_size: usize,
    /// Candidates that gave nothing on the pilot bench (label, why).
    pub pool_failures: Vec<(String, String)>,
    /// log det of the information (prior included) of the design, internal units (D-criterion).
    pub log_det_information: f64,
    /// The reference plans' names and total bench time (s), if computed.
    pub reference: Option<(Vec<String>, f64)>,
    /// The prior the design is linearised at.
    pub prior: Extrinsics,
    /// The margin used.
    pub margin: f64,
    /// Reduced χ² of each observation kind ([`KIND_NAMES`]) on the pilot bench at its truth:
    /// σ of a kind above 1 were scaled up by its square root.
    pub pilot_reduced_chi2: [Option<f64>; 3],
}

/// The selection criteria of the targets: each aims at `margin ×` its σ; a bootstrap target counts
/// only the sweeps and frees only [`BOOTSTRAP_FREE`].
fn criteria(targets: &[Target], margin: f64, candidates: &[Candidate]) -> Vec<Criterion> {
    let sweeps: Vec<bool> = candidates.iter().map(|c| c.kind == CandidateKind::Sweep).collect();
    targets
        .iter()
        .map(|t| Criterion {
            c: t.internal(),
            tau: t.max_sigma * margin,
            free: t.bootstrap.then(|| BOOTSTRAP_FREE.to_vec()),
            members: t.bootstrap.then(|| sweeps.clone()),
        })
        .collect()
}

/// Design a plan on `preset`'s noise model (see the module documentation); `reference`: plans
/// whose predicted σ are reported beside the design's (e.g. the default joint plans).
pub fn design(preset: &BenchPreset, options: &DesignOptions, reference: &[Plan]) -> Result<Design, DesignError> {
    check_options(options)?;
    let robot = preset.robot_description().map_err(|e| DesignError::Pilot(e.to_string()))?;
    let pool = candidate_pool(&robot, &preset.motion);
    let (pilot, reduced_chi2) = pilot(preset, &options.prior, &pool, options.seed)?;
    let problem = SelectionProblem {
        information: pilot.iter().map(|p| p.information.clone()).collect(),
        cost: pool.iter().map(Candidate::cost_s).collect(),
        prior: weak_prior(),
        criteria: criteria(&options.targets, options.margin, &pool),
        scatter: Some(pilot.iter().map(|p| (p.expected_chi2, p.observations as f64, p.nuisance as f64)).collect()),
    };
    let sel = select(&problem).map_err(|e| match e {
        DesignError::Unreachable(why) => DesignError::Unreachable(format!(
            "{why}; targets in order: {}",
            options.targets.iter().map(|t| t.name.as_str()).collect::<Vec<_>>().join(", ")
        )),
        other => other,
    })?;
    let chosen: Vec<&Candidate> = sel.chosen.iter().map(|&k| &pool[k]).collect();
    let plan = assemble(&chosen, &robot, &preset.motion)?;
    let segs = plan.expand(&robot, [0.0; 6], &preset.motion)?;
    let total_s = crate::plan::total_duration_s(&segs);
    let motions = chosen_motions(&segs, &chosen, &sel, &pool, &pilot);
    let log_det_information = log_det_information(&pilot, &sel);
    let reference_sigmas = if reference.is_empty() {
        None
    } else {
        Some(reference_prediction(preset, options, reference, &robot, &reduced_chi2)?)
    };
    let targets = options
        .targets
        .iter()
        .enumerate()
        .map(|(t, target)| {
            // Back to display units: σ of cᵀp is the internal σ (c' already carries the scales).
            TargetResult {
                name: target.name.clone(),
                unit: target.unit.clone(),
                required_sigma: target.max_sigma,
                design_sigma: target.max_sigma * options.margin,
                predicted_sigma: sel.sigma[t],
                reference_sigma: reference_sigmas.as_ref().map(|r| r.0[t]),
            }
        })
        .collect();
    Ok(Design {
        plan,
        total_s,
        chosen: motions,
        targets,
        pool_size: pool.len(),
        pool_failures: pool
            .iter()
            .zip(&pilot)
            .filter_map(|(c, p)| p.failure.as_ref().map(|f| (c.label.clone(), f.clone())))
            .collect(),
        log_det_information,
        reference: reference_sigmas.map(|(_, names, total)| (names, total)),
        prior: options.prior,
        margin: options.margin,
        pilot_reduced_chi2: reduced_chi2,
    })
}

/// A margin in (0, 1] and at least one target, each with a positive σ and a non-zero combination.
fn check_options(options: &DesignOptions) -> Result<(), DesignError> {
    if !(options.margin.is_finite() && options.margin > 0.0 && options.margin <= 1.0) {
        return Err(DesignError::Input(format!("margin: expected a number in (0, 1], found {}", options.margin)));
    }
    if options.targets.is_empty() {
        return Err(DesignError::Input("targets: expected at least one".into()));
    }
    for t in &options.targets {
        if !(t.max_sigma.is_finite() && t.max_sigma > 0.0) || t.combination.iter().all(|c| *c == 0.0) {
            return Err(DesignError::Input(format!(
                "target {}: expected a positive σ and a non-zero combination",
                t.name
            )));
        }
    }
    Ok(())
}

/// Per chosen motion, in plan order: its setup move's time in that order and its segment.
fn chosen_motions(
    segs: &[TimedSegment],
    chosen: &[&Candidate],
    sel: &Selection,
    pool: &[Candidate],
    pilot: &[PilotResult],
) -> Vec<ChosenMotion> {
    let mut motions = Vec::new();
    for (k, s) in segs.iter().enumerate() {
        if s.record {
            let c = chosen.iter().position(|c| c.label == s.label).map(|i| sel.chosen[i]);
            motions.push(ChosenMotion {
                label: s.label.clone(),
                kind: c.map_or(CandidateKind::Translation, |c| pool[c].kind),
                setup_s: if k > 0 && !segs[k - 1].record { segs[k - 1].duration_s } else { 0.0 },
                duration_s: s.duration_s,
                observations: c.map_or(0, |c| pilot[c].observations),
            });
        }
    }
    motions
}

/// log det of the information of the selection, the weak prior included (D-criterion).
fn log_det_information(pilot: &[PilotResult], sel: &Selection) -> f64 {
    let mut info = weak_prior();
    for &k in &sel.chosen {
        info += &pilot[k].information;
    }
    info.clone().cholesky().map_or(f64::NEG_INFINITY, |c| 2.0 * c.l().diagonal().map(f64::ln).sum())
}

/// The σ the reference plans reach on each target (bootstrap targets on their sweeps alone),
/// their names and their total bench time run one after the other from q = 0 (s).
fn reference_prediction(
    preset: &BenchPreset,
    options: &DesignOptions,
    reference: &[Plan],
    robot: &RobotDescription,
    reduced_chi2: &[Option<f64>; 3],
) -> Result<(Vec<f64>, Vec<String>, f64), DesignError> {
    let f = plans_information(preset, &options.prior, reference, options.seed, reduced_chi2)?;
    // The reference plan's sweeps alone, for the bootstrap targets.
    let sweeps: Vec<Plan> = reference
        .iter()
        .map(|p| Plan {
            segments: p
                .segments
                .iter()
                .filter(|s| !s.is_recorded() || matches!(s, Segment::Sweep { .. }))
                .cloned()
                .collect(),
            ..p.clone()
        })
        .collect();
    let f_sweeps = plans_information(preset, &options.prior, &sweeps, options.seed, reduced_chi2)?;
    let p = SelectionProblem {
        information: vec![f.0, f_sweeps.0],
        cost: vec![1.0, 1.0],
        prior: weak_prior(),
        scatter: Some(vec![f.1, (0.0, 0.0, 0.0)]),
        criteria: options
            .targets
            .iter()
            .map(|t| Criterion {
                c: t.internal(),
                tau: t.max_sigma,
                free: t.bootstrap.then(|| BOOTSTRAP_FREE.to_vec()),
                members: Some(vec![!t.bootstrap, t.bootstrap]),
            })
            .collect(),
    };
    p.check()?;
    let mut total = 0.0;
    let mut start = [0.0; 6];
    for r in reference {
        let segs = r.expand(robot, start, &preset.motion)?;
        total += crate::plan::total_duration_s(&segs);
        start = segs.last().map_or(start, |s| s.to_display);
    }
    Ok((p.sigmas(&[true, true]), reference.iter().map(|r| r.name.clone()).collect::<Vec<_>>(), total))
}
