//! Experiment design: choose motions from a candidate pool so that the joint estimate reaches
//! required standard uncertainties in the least bench time. Owns the candidate pool, the Fisher
//! information of each candidate, the selection and the plan it writes.
//!
//! # Method
//!
//! 1. **Candidate pool** ([`candidate_pool`]): single recorded segments with the unrecorded setup
//!    move that brings the robot to their start — translations (X_w, Z_w 300 µm; Y_w 20 µm) at
//!    several held positions, absolute-gap sweeps (three sweep settings) at nine poses, q4 and q5
//!    rotations (±2.5° and ±4°) at several gaps and lateral offsets, read for fringe amplitudes
//!    as tilt scans, and q6 rotations of ±20°. Every candidate is checked against the joint
//!    limits and timed by the plan's own timing model ([`Plan::expand`]: synchronized
//!    trapezoidal moves, settling, sweep rates), so the bench time of a candidate is
//!    `setup_s + duration_s`, its setup move counted from q = 0.
//! 2. **Fisher information** ([`pilot`]): the pool is run once on a *pilot* virtual bench built
//!    from the bench preset (its detector, stages, sampling rate, optics, air) whose truth is the
//!    **prior** extrinsics (the nominal design by default, never the hidden truth) and which
//!    hides no effects. Each recorded trace goes through the same extraction as a calibration
//!    ([`observations_from_trace`]: gap changes, absolute gaps, fringe amplitudes, each with the
//!    σ the analysis assigns), and the same joint machinery evaluates the weighted Jacobian
//!    `J` at the prior ([`joint::evaluate`], internal units mrad and µm). The information of a
//!    candidate is `F = JᵀJ` with its detector-gain nuisance parameter (one per tilt scan)
//!    eliminated by the Schur complement `F_ee − F_eg F_gg⁻¹ F_ge`, so informations of
//!    different candidates add. The pilot's truth being the prior, its residuals at the prior
//!    are pure noise, and the pool's robust reduced χ² of each observation kind (median of r²;
//!    the fringe amplitudes scatter several times more than the σ the extraction gives them)
//!    predicts the residual variance of a design. The identifier's report scales every σ by
//!    `√max(1, χ²_red)` of the whole fit, so the predicted σ are scaled the same way:
//!    `σ_t(S) · √max(1, Σ_{k∈S} E[Σr²]_k / (m_S − 8 − gains_S))`. The design is *locally* optimal at
//!    the prior, like any design for a nonlinear model.
//! 3. **Targets** ([`Target`]): a required σ on a linear combination `cᵀp` of the parameters
//!    (display units), e.g. σ(β_et) ≤ 0.005° or σ(y_wf − Z_et) ≤ 0.0167 µm. The predicted σ is
//!    `√(c'ᵀ I⁻¹ c')` with `I = Λ₀ + Σ_{k∈S} F_k`. A target may count only some candidates and
//!    free only some parameters: the identifier's bootstrap uses the absolute gaps alone with
//!    (β_et, θ_et, y_wf) free, so the design requires that sub-problem to be determined too.
//! 4. **Unidentifiable directions.** The information matrix of any plan of these motions is
//!    singular or nearly so: the split of the gap between y_wf and Z_et is seen only at second
//!    order, and a small plan may not see the fiber direction at all. Its determinant is then
//!    zero and `I⁻¹` does not exist. The design adds a weak Gaussian prior
//!    `Λ₀ = diag(1/σ₀²)` with σ₀ = the identifiability report's useful bounds (1° for angles,
//!    10 µm for lengths): `I` is then positive definite, and since every target is far below
//!    its σ₀ (0.2 µm ≪ 10 µm), a target can only be met by information from the data, never by
//!    the prior (the prior changes a met σ by less than 0.1 %). The targets are on determined
//!    combinations (the gap, not y_wf and Z_et separately), so the criterion stays meaningful
//!    where a D-criterion over all eight parameters would be dominated by the undetermined
//!    split. The log-determinant of `I` (D-criterion) is reported for information only.
//! 5. **Selection** ([`select`]): a cost-weighted greedy on the targets followed by pruning and
//!    exchange. The deficiency `f(S) = Σ_t max(0, ln(σ_t²(S) / τ_t²))` (τ_t the target bound
//!    times the design margin) is zero exactly when every target is met; the greedy adds the
//!    candidate with the largest decrease of `f` per second of bench time until `f = 0`, then
//!    removes every candidate (most expensive first) that is not needed, then swaps a chosen
//!    candidate for a cheaper unchosen one while the targets stay met. [`select_exhaustive`]
//!    (pools of at most 20) is the brute-force oracle the tests compare it with.
//! 6. **Plan** ([`Design::plan`]): the chosen candidates ordered by nearest setup move from
//!    q = 0, each preceded by its setup move, ending back at q = 0; its total bench time is the
//!    plan's own ([`Plan::duration_s`]), usually a little less than the sum of the candidates'
//!    costs (setup moves between neighbours are shorter than from q = 0).
//!
//! A design is only as good as its model: run the plan ([`crate::identify::calibration`]) and
//! check the reported σ; the design margin (default 0.8) leaves room for the difference between
//! prior and truth and for the residual-variance scaling of the reported σ.

use crate::bench::{run_plan, BenchPreset, RunControl, VirtualBench};
use crate::identify::joint::{self, JointOptions};
use crate::identify::measurements::{observations_from_trace, observations_from_traces, ExtractOptions};
use crate::identify::observability::{DEFAULT_USEFUL_ANGLE_DEG, DEFAULT_USEFUL_LENGTH_UM};
use crate::identify::{parameter_scale, N_EXTRINSICS};
use crate::model::extrinsics::{Extrinsics, PARAMETER_NAMES};
use crate::model::phase::PhaseModel;
use crate::model::robot::RobotDescription;
use crate::plan::{JointTarget, MotionLimits, Plan, PlanError, Segment};
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};
use std::sync::atomic::AtomicBool;

/// What a candidate motion is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CandidateKind {
    /// A translation (q1, q2 or q3) with the orientation fixed.
    Translation,
    /// A wavelength sweep at a fixed pose (absolute gap).
    Sweep,
    /// A q4 or q5 rotation, read for gap changes and fringe amplitudes (label "tilt scan …").
    TiltScan,
    /// A q6 rotation (about the beam direction).
    AxisRotation,
}

/// One candidate motion: a recorded segment and the setup move to its start.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Candidate {
    /// The recorded segment's label (also the trace's).
    pub label: String,
    /// What it is.
    pub kind: CandidateKind,
    /// Joints at the start of the recorded segment (µm, °).
    pub start_display: [f64; 6],
    /// The recorded segment.
    pub segment: Segment,
    /// Bench time of the setup move from q = 0 to the start (s).
    pub setup_s: f64,
    /// Bench time of the recorded segment, settling included (s).
    pub duration_s: f64,
}

impl Candidate {
    /// Bench time charged to the candidate by the selection (s): setup from q = 0 plus the segment.
    pub fn cost_s(&self) -> f64 {
        self.setup_s + self.duration_s
    }
}

/// Why a design cannot be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DesignError {
    /// A candidate or the assembled plan does not fit the robot, limits or laser.
    #[error("plan: {0}")]
    Plan(#[from] PlanError),
    /// The pilot bench could not be built or run.
    #[error("pilot bench: {0}")]
    Pilot(String),
    /// Even the whole pool does not reach the targets.
    #[error("the candidate pool cannot reach the targets: {0}")]
    Unreachable(String),
    /// Bad input (targets, margin, sizes).
    #[error("{0}")]
    Input(String),
}

fn joints(q1: f64, q2: f64, q3: f64, q4: f64, q5: f64, q6: f64) -> [f64; 6] {
    [q1, q2, q3, q4, q5, q6]
}

fn pose_text(q: &[f64; 6]) -> String {
    let names = ["q1", "q2", "q3", "q4", "q5", "q6"];
    let units = ["µm", "µm", "µm", "°", "°", "°"];
    let parts: Vec<String> = (0..6)
        .filter(|&j| q[j] != 0.0)
        .map(|j| format!("{} = {}{}{}", names[j], if q[j] > 0.0 { "+" } else { "" }, q[j], units[j]))
        .collect();
    if parts.is_empty() {
        "q = 0".into()
    } else {
        parts.join(", ")
    }
}

/// The candidate pool (see the module documentation), timed with `limits` and checked against
/// the robot's joint limits and the default laser range. Candidates that do not fit are left out.
pub fn candidate_pool(robot: &RobotDescription, limits: &MotionLimits) -> Vec<Candidate> {
    let mut raw: Vec<(String, CandidateKind, [f64; 6], Segment)> = Vec::new();
    let mv = |to: JointTarget, label: &str| Segment::Move { to, record: true, label: label.to_string() };
    // Translations: X_w (q3) and Z_w (q1) over 300 µm, Y_w (q2) over 20 µm, at held positions.
    for held in [-150.0, 0.0, 150.0] {
        for q2 in [-100.0, 0.0, 100.0] {
            let start = joints(held, q2, -150.0, 0.0, 0.0, 0.0);
            let label =
                format!("translation X_w (q3) -150 -> +150 µm at {}", pose_text(&joints(held, q2, 0.0, 0.0, 0.0, 0.0)));
            raw.push((
                label.clone(),
                CandidateKind::Translation,
                start,
                mv(JointTarget::default().with(2, 150.0), &label),
            ));
            let start = joints(-150.0, q2, held, 0.0, 0.0, 0.0);
            let label =
                format!("translation Z_w (q1) -150 -> +150 µm at {}", pose_text(&joints(0.0, q2, held, 0.0, 0.0, 0.0)));
            raw.push((
                label.clone(),
                CandidateKind::Translation,
                start,
                mv(JointTarget::default().with(0, 150.0), &label),
            ));
        }
    }
    for (q1, q3) in [(0.0, 0.0), (150.0, 150.0), (-150.0, 150.0), (150.0, -150.0), (-150.0, -150.0)] {
        let start = joints(q1, -10.0, q3, 0.0, 0.0, 0.0);
        let label = format!("translation Y_w (q2) -10 -> +10 µm at {}", pose_text(&joints(q1, 0.0, q3, 0.0, 0.0, 0.0)));
        raw.push((label.clone(), CandidateKind::Translation, start, mv(JointTarget::default().with(1, 10.0), &label)));
    }
    // Absolute-gap sweeps at nine poses, three settings each.
    let sweep_poses = [
        joints(0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
        joints(0.0, -100.0, 0.0, 0.0, 0.0, 0.0),
        joints(0.0, 100.0, 0.0, 0.0, 0.0, 0.0),
        joints(120.0, 0.0, 120.0, 0.0, 0.0, 0.0),
        joints(120.0, 0.0, -120.0, 0.0, 0.0, 0.0),
        joints(-120.0, 0.0, 120.0, 0.0, 0.0, 0.0),
        joints(-120.0, 0.0, -120.0, 0.0, 0.0, 0.0),
        joints(0.0, 0.0, 0.0, 3.0, 0.0, 0.0),
        joints(0.0, 0.0, 0.0, 0.0, 3.0, 0.0),
    ];
    for q in sweep_poses {
        for (from_nm, to_nm, rate_nm_per_s) in [(1540.0, 1580.0, 10.0), (1520.0, 1600.0, 20.0), (1550.0, 1570.0, 1.0)] {
            let label = format!("sweep {from_nm}-{to_nm} nm at {rate_nm_per_s} nm/s at {}", pose_text(&q));
            raw.push((label.clone(), CandidateKind::Sweep, q, Segment::Sweep { from_nm, to_nm, rate_nm_per_s, label }));
        }
    }
    // q4 and q5 rotations (tilt scans), at several gaps (q2) and lateral offsets (q1, q3).
    let lateral = [(0.0, 0.0), (120.0, 120.0), (120.0, -120.0), (-120.0, 120.0), (-120.0, -120.0)];
    for q2 in [-100.0, 0.0, 150.0] {
        for (q1, q3) in lateral {
            for amplitude in [2.5, 4.0] {
                for (joint, name) in [(3usize, "q4"), (4usize, "q5")] {
                    let mut start = joints(q1, q2, q3, 0.0, 0.0, 0.0);
                    start[joint] = -amplitude;
                    let at = joints(q1, q2, q3, 0.0, 0.0, 0.0);
                    // The tilt scan, and the same rotation read for its fringe phase (gap
                    // changes) only.
                    for kind in ["tilt scan", "rotation"] {
                        let label = format!("{kind} {name} -{amplitude} -> +{amplitude}° at {}", pose_text(&at));
                        raw.push((
                            label.clone(),
                            CandidateKind::TiltScan,
                            start,
                            mv(JointTarget::default().with(joint, amplitude), &label),
                        ));
                    }
                }
            }
        }
    }
    // Strategy 2's cross rotations: q4 at q5 = ±4°, q5 at q4 = ±4°.
    for (joint, other, name) in [(3usize, 4usize, "q4"), (4, 3, "q5")] {
        for o in [-4.0, 4.0] {
            let mut start = [0.0; 6];
            start[joint] = -4.0;
            start[other] = o;
            let mut at = [0.0; 6];
            at[other] = o;
            let label = format!("tilt scan {name} -4 -> +4° at {}", pose_text(&at));
            raw.push((
                label.clone(),
                CandidateKind::TiltScan,
                start,
                mv(JointTarget::default().with(joint, 4.0), &label),
            ));
        }
    }
    // q6 rotations about the beam direction.
    for (q1, q3) in [(0.0, 0.0), (120.0, -120.0), (-120.0, -120.0)] {
        let start = joints(q1, 0.0, q3, 0.0, 0.0, -20.0);
        let label = format!("q6 -20 -> +20° at {}", pose_text(&joints(q1, 0.0, q3, 0.0, 0.0, 0.0)));
        raw.push((label.clone(), CandidateKind::AxisRotation, start, mv(JointTarget::default().with(5, 20.0), &label)));
    }
    raw.into_iter()
        .filter_map(|(label, kind, start, segment)| {
            let plan = Plan {
                name: "candidate".into(),
                description: String::new(),
                segments: vec![
                    Segment::Move { to: JointTarget::all(start), record: false, label: format!("setup: {label}") },
                    segment.clone(),
                ],
            };
            let segs = plan.expand(robot, [0.0; 6], limits).ok()?;
            Some(Candidate {
                label,
                kind,
                start_display: start,
                segment,
                setup_s: segs[0].duration_s,
                duration_s: segs[1].duration_s,
            })
        })
        .collect()
}

/// The Fisher information of the eight extrinsics (internal units: mrad, µm; order of
/// [`PARAMETER_NAMES`]) from a weighted Jacobian whose extra columns (`column_parameter` None)
/// are nuisance parameters, eliminated by the Schur complement.
pub fn extrinsic_information(weighted_jacobian: &DMatrix<f64>, column_parameter: &[Option<usize>]) -> DMatrix<f64> {
    let f = weighted_jacobian.transpose() * weighted_jacobian;
    let e: Vec<usize> = (0..column_parameter.len()).filter(|&c| column_parameter[c].is_some()).collect();
    let g: Vec<usize> = (0..column_parameter.len()).filter(|&c| column_parameter[c].is_none()).collect();
    let pick = |rows: &[usize], cols: &[usize]| DMatrix::from_fn(rows.len(), cols.len(), |i, j| f[(rows[i], cols[j])]);
    let mut fee = pick(&e, &e);
    if !g.is_empty() {
        let fgg = pick(&g, &g);
        let feg = pick(&e, &g);
        // Pseudo-inverse: a gain whose column is zero (no amplitude seen) carries nothing.
        if let Ok(inv) = fgg.clone().pseudo_inverse(1e-12 * fgg.norm().max(1e-300)) {
            fee -= &feg * inv * feg.transpose();
        }
    }
    let mut out = DMatrix::zeros(N_EXTRINSICS, N_EXTRINSICS);
    for (a, &ca) in e.iter().enumerate() {
        for (b, &cb) in e.iter().enumerate() {
            if let (Some(i), Some(j)) = (column_parameter[ca], column_parameter[cb]) {
                out[(i, j)] = fee[(a, b)];
            }
        }
    }
    // Symmetrise (rounding of the Schur complement).
    (&out + out.transpose()) * 0.5
}

/// What the pilot run found for one candidate.
#[derive(Debug, Clone)]
pub struct PilotResult {
    /// Fisher information (internal units, 8 × 8) from the σ the extraction assigns.
    pub information: DMatrix<f64>,
    /// Observations the extraction gave.
    pub observations: usize,
    /// Expected sum of squared normalised residuals of those observations: each counts the
    /// pool's reduced χ² of its kind ([`pilot`]).
    pub expected_chi2: f64,
    /// Nuisance parameters (detector gains) the candidate adds.
    pub nuisance: usize,
    /// Why the trace gave nothing, if it did not.
    pub failure: Option<String>,
}

/// Observation kinds, for the σ scaling of the pilot: gap change, absolute gap, amplitude.
fn kind_index(o: &crate::identify::Observation) -> usize {
    match o.kind {
        crate::identify::ObservationKind::GapChange { .. } => 0,
        crate::identify::ObservationKind::AbsoluteGap { .. } => 1,
        crate::identify::ObservationKind::FringeAmplitude { .. } => 2,
    }
}

/// Names of the observation kinds of [`kind_index`].
pub const KIND_NAMES: [&str; 3] = ["gap change", "absolute gap", "fringe amplitude"];

/// The pilot bench: the preset with the prior as truth and no hidden effects.
fn pilot_bench(preset: &BenchPreset, prior: &Extrinsics, seed: u64) -> Result<VirtualBench, DesignError> {
    let mut p = preset.clone();
    p.truth = *prior;
    p.effects.clear();
    VirtualBench::new(&p, Some(seed)).map_err(|e| DesignError::Pilot(e.to_string()))
}

fn model_for(preset: &BenchPreset, prior: &Extrinsics) -> Result<PhaseModel, DesignError> {
    PhaseModel::of_preset(preset, *prior).map_err(DesignError::Pilot)
}

/// Run plans on the pilot bench; every recorded trace.
fn run_pilot(bench: &mut VirtualBench, plans: &[Plan]) -> Result<Vec<crate::trace::Trace>, DesignError> {
    let cancel = AtomicBool::new(false);
    let mut traces = Vec::new();
    for p in plans {
        let mut control = RunControl { cancel: &cancel, on_samples: &mut |_, _| {}, on_progress: &mut |_| {} };
        let run = run_plan(bench, p, &mut control);
        traces.extend(run.traces);
        run.outcome.map_err(|e| DesignError::Pilot(format!("plan {}: {e}", p.name)))?;
    }
    Ok(traces)
}

/// Run every candidate once on the pilot bench (see the module documentation) and compute its
/// Fisher information at the prior. The pilot's truth is the prior, so its residuals at the
/// prior are pure noise: the σ the extraction assigns to each observation kind are checked
/// against that scatter over the whole pool, and a kind whose scatter exceeds its σ (robust
/// reduced χ², median of r² / 0.4549, above 1) has its σ scaled up by `√χ²` — the scaling the identifier's report applies too
/// (never down: the report floors χ² at 1). Also returns the reduced χ² per kind
/// ([`KIND_NAMES`]; `None` for a kind the pool never observed).
pub fn pilot(
    preset: &BenchPreset,
    prior: &Extrinsics,
    candidates: &[Candidate],
    seed: u64,
) -> Result<(Vec<PilotResult>, [Option<f64>; 3]), DesignError> {
    use rayon::prelude::*;
    let mut bench = pilot_bench(preset, prior, seed)?;
    let model = model_for(preset, prior)?;
    let mut segments = Vec::with_capacity(2 * candidates.len() + 1);
    for c in candidates {
        segments.push(Segment::Move {
            to: JointTarget::all(c.start_display),
            record: false,
            label: format!("setup: {}", c.label),
        });
        segments.push(c.segment.clone());
    }
    segments.push(Segment::Move { to: JointTarget::all([0.0; 6]), record: false, label: "return to 0".into() });
    let plan = Plan { name: "design pilot".into(), description: "every candidate once".into(), segments };
    let traces = run_pilot(&mut bench, &[plan])?;
    if traces.len() != candidates.len() {
        return Err(DesignError::Pilot(format!(
            "{} traces recorded for {} candidates",
            traces.len(),
            candidates.len()
        )));
    }
    let opts = ExtractOptions::default();
    // Per candidate: weighted Jacobian, its columns, normalised residuals and observation kinds.
    type Evaluated = Result<(DMatrix<f64>, Vec<Option<usize>>, Vec<f64>, Vec<usize>), String>;
    let evaluated: Vec<Evaluated> = traces
        .par_iter()
        .map(|t| {
            let obs: Vec<_> = observations_from_trace(t, &model, &opts, 0)
                .map_err(|e| e.to_string())?
                .into_iter()
                .filter(|o| o.value().is_finite() && o.sigma.is_finite() && o.sigma > 0.0)
                .collect();
            if obs.is_empty() {
                return Err("no usable observation".into());
            }
            let est = joint::evaluate(&model, &obs, prior, &JointOptions::default());
            if !est.weighted_jacobian.iter().all(|v| v.is_finite()) {
                return Err("non-finite Jacobian at the prior".into());
            }
            let kinds = obs.iter().map(kind_index).collect();
            Ok((est.weighted_jacobian, est.column_parameter, est.normalised_residuals, kinds))
        })
        .collect();
    // Robust reduced χ² per kind: median of r² over its median for unit-variance Gaussian
    // noise (0.4549), so a few outliers of the degenerate prior geometry do not set the scale.
    let mut r2: [Vec<f64>; 3] = Default::default();
    for (_, _, r, kinds) in evaluated.iter().flatten() {
        for (ri, &k) in r.iter().zip(kinds) {
            if ri.is_finite() {
                r2[k].push(ri * ri);
            }
        }
    }
    let reduced: [Option<f64>; 3] = std::array::from_fn(|k| {
        let mut v = r2[k].clone();
        v.sort_by(f64::total_cmp);
        (!v.is_empty()).then(|| v[v.len() / 2] / 0.4549)
    });
    let results = evaluated
        .into_iter()
        .map(|e| match e {
            Ok((j, cols, _, kinds)) => PilotResult {
                information: extrinsic_information(&j, &cols),
                observations: kinds.len(),
                expected_chi2: kinds.iter().map(|&k| reduced[k].unwrap_or(1.0)).sum(),
                nuisance: cols.iter().filter(|c| c.is_none()).count(),
                failure: None,
            },
            Err(why) => PilotResult {
                information: DMatrix::zeros(N_EXTRINSICS, N_EXTRINSICS),
                observations: 0,
                expected_chi2: 0.0,
                nuisance: 0,
                failure: Some(why),
            },
        })
        .collect();
    Ok((results, reduced))
}

/// Residual-variance data of a candidate or plan: expected Σr², observations, nuisance parameters.
pub type Scatter = (f64, f64, f64);

/// The Fisher information (internal units) of whole plans run one after the other, from the
/// same pilot bench and extraction (one gain per tilt-scan trace, eliminated), with the
/// expected Σr² (each observation counting its kind's reduced χ² from `reduced_chi2`, as
/// [`pilot`] gives), the number of observations and of nuisance parameters, for
/// [`SelectionProblem::scatter`].
pub fn plans_information(
    preset: &BenchPreset,
    prior: &Extrinsics,
    plans: &[Plan],
    seed: u64,
    reduced_chi2: &[Option<f64>; 3],
) -> Result<(DMatrix<f64>, Scatter), DesignError> {
    let mut bench = pilot_bench(preset, prior, seed)?;
    let model = model_for(preset, prior)?;
    let traces = run_pilot(&mut bench, plans)?;
    let obs = observations_from_traces(&traces, &model, &ExtractOptions::default()).observations;
    let est = joint::evaluate(&model, &obs, prior, &JointOptions::default());
    let chi2: f64 = obs.iter().map(|o| reduced_chi2[kind_index(o)].unwrap_or(1.0)).sum();
    let nuisance = est.column_parameter.iter().filter(|c| c.is_none()).count();
    Ok((
        extrinsic_information(&est.weighted_jacobian, &est.column_parameter),
        (chi2, obs.len() as f64, nuisance as f64),
    ))
}

/// A required standard uncertainty on a linear combination of the parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Target {
    /// Name, e.g. `beta_et` or `y_wf - Z_et`.
    pub name: String,
    /// Display unit of the combination (° or µm).
    pub unit: String,
    /// Coefficients over the eight parameters (order of [`PARAMETER_NAMES`], display units).
    pub combination: [f64; N_EXTRINSICS],
    /// Required standard uncertainty (display unit).
    pub max_sigma: f64,
    /// Count only sweeps and free only these parameters (the identifier's bootstrap); `None`:
    /// every candidate, every parameter.
    #[serde(default)]
    pub bootstrap: bool,
}

/// Parameters the identifier's bootstrap frees (calibration.rs): β_et, θ_et, y_wf.
pub const BOOTSTRAP_FREE: [bool; N_EXTRINSICS] = [true, true, false, false, false, false, true, false];

impl Target {
    /// A target on one parameter, by name (as in [`PARAMETER_NAMES`]).
    pub fn parameter(name: &str, max_sigma: f64) -> Self {
        let i = PARAMETER_NAMES.iter().position(|p| p.0 == name).expect("a known parameter name");
        let mut combination = [0.0; N_EXTRINSICS];
        combination[i] = 1.0;
        Self { name: name.into(), unit: PARAMETER_NAMES[i].1.into(), combination, max_sigma, bootstrap: false }
    }

    /// The acceptance targets on `table2-ideal` (joint mode): σ ≤ 0.005° for β_et, θ_et,
    /// ≤ 0.01° for β_wf, θ_wf, ≤ 0.2 µm for x_wf, z_wf, and the gap y_wf − Z_et within 0.05 µm,
    /// read as 3σ ≤ 0.05 µm; plus the bootstrap: the sweeps alone must fix the lamella normal to
    /// 0.05° (a rough start for the motion hints, [`Target::bootstrap`]).
    pub fn issue_targets() -> Vec<Self> {
        let mut gap = [0.0; N_EXTRINSICS];
        gap[6] = 1.0;
        gap[4] = -1.0;
        let mut out = vec![
            Self::parameter("beta_et", 0.005),
            Self::parameter("theta_et", 0.005),
            Self::parameter("beta_wf", 0.01),
            Self::parameter("theta_wf", 0.01),
            Self::parameter("x_wf", 0.2),
            Self::parameter("z_wf", 0.2),
            Self {
                name: "y_wf - Z_et".into(),
                unit: "µm".into(),
                combination: gap,
                max_sigma: 0.05 / 3.0,
                bootstrap: false,
            },
        ];
        for name in ["beta_et", "theta_et"] {
            let mut t = Self::parameter(name, 0.05);
            t.name = format!("{name} (bootstrap: sweeps alone)");
            t.bootstrap = true;
            out.push(t);
        }
        out
    }

    /// Coefficients in internal units (mrad, µm): `cᵀp = c'ᵀx` with `p_i = x_i · scale_i`.
    fn internal(&self) -> DVector<f64> {
        DVector::from_fn(N_EXTRINSICS, |i, _| self.combination[i] * parameter_scale(i))
    }
}

/// The prior information `Λ₀ = diag(1/σ₀²)` in internal units: σ₀ = 1° for angles, 10 µm for
/// lengths (the identifiability report's useful bounds).
pub fn weak_prior() -> DMatrix<f64> {
    DMatrix::from_fn(N_EXTRINSICS, N_EXTRINSICS, |i, j| {
        if i != j {
            0.0
        } else {
            let s0 = if PARAMETER_NAMES[i].1 == "°" { DEFAULT_USEFUL_ANGLE_DEG } else { DEFAULT_USEFUL_LENGTH_UM };
            (parameter_scale(i) / s0).powi(2)
        }
    })
}

/// A criterion of the generic selection: σ of `c` (internal units) with only the `free`
/// parameters estimated and only the candidates in `members` counted must be ≤ `tau`.
#[derive(Debug, Clone, PartialEq)]
pub struct Criterion {
    /// Coefficients (internal units).
    pub c: DVector<f64>,
    /// Bound on σ (internal units of the combination).
    pub tau: f64,
    /// Parameters estimated (others fixed); `None`: all.
    pub free: Option<Vec<bool>>,
    /// Candidates counted; `None`: all.
    pub members: Option<Vec<bool>>,
}

/// A generic selection problem: pick candidates (informations `F_k`, costs) so that every
/// criterion holds at least cost.
#[derive(Debug, Clone)]
pub struct SelectionProblem {
    /// Information of each candidate (n × n, symmetric positive semi-definite).
    pub information: Vec<DMatrix<f64>>,
    /// Cost of each candidate (s), positive.
    pub cost: Vec<f64>,
    /// Prior information (n × n, positive definite), added to every design.
    pub prior: DMatrix<f64>,
    /// The criteria.
    pub criteria: Vec<Criterion>,
    /// Residual-variance scaling as the identifier's report applies it, or `None` (σ from the
    /// noise model alone): per candidate (expected Σr², observations, nuisance parameters);
    /// the σ of a criterion counting every candidate is multiplied by
    /// `√max(1, Σ expected Σr² / (Σ observations − parameters − Σ nuisance))`.
    pub scatter: Option<Vec<Scatter>>,
}

/// A selection and what it reaches.
#[derive(Debug, Clone, PartialEq)]
pub struct Selection {
    /// Chosen candidates, ascending.
    pub chosen: Vec<usize>,
    /// Their total cost.
    pub cost: f64,
    /// Predicted σ per criterion (internal units).
    pub sigma: Vec<f64>,
}

impl SelectionProblem {
    fn check(&self) -> Result<usize, DesignError> {
        let n = self.prior.nrows();
        if self.prior.ncols() != n || self.information.len() != self.cost.len() {
            return Err(DesignError::Input("selection: sizes of prior, informations and costs disagree".into()));
        }
        for (k, (f, c)) in self.information.iter().zip(&self.cost).enumerate() {
            if f.shape() != (n, n) || !f.iter().all(|v| v.is_finite()) {
                return Err(DesignError::Input(format!("candidate {k}: information is not a finite {n}×{n} matrix")));
            }
            if !(c.is_finite() && *c > 0.0) {
                return Err(DesignError::Input(format!("candidate {k}: cost {c} s is not a finite positive number")));
            }
        }
        for (t, cr) in self.criteria.iter().enumerate() {
            let sizes_ok = cr.free.as_ref().is_none_or(|f| f.len() == n)
                && cr.members.as_ref().is_none_or(|m| m.len() == self.cost.len());
            if cr.c.len() != n || !(cr.tau.is_finite() && cr.tau > 0.0) || !sizes_ok {
                return Err(DesignError::Input(format!(
                    "criterion {t}: expected {n} coefficients, a positive bound and masks of the right sizes"
                )));
            }
        }
        Ok(n)
    }

    fn member(&self, criterion: usize, k: usize) -> bool {
        self.criteria[criterion].members.as_ref().is_none_or(|m| m[k])
    }

    /// Per criterion: the prior plus the information of the chosen candidates it counts.
    fn sums(&self, chosen: &[bool]) -> Vec<DMatrix<f64>> {
        (0..self.criteria.len())
            .map(|t| {
                let mut s = self.prior.clone();
                for (k, f) in self.information.iter().enumerate() {
                    if chosen[k] && self.member(t, k) {
                        s += f;
                    }
                }
                s
            })
            .collect()
    }

    /// The residual-variance factor of [`SelectionProblem::scatter`] for a set given as `sums`'
    /// chosen set (recomputed from `chosen`) with `add` and `remove`.
    fn scatter_factor(&self, chosen: &[bool], add: &[usize], remove: &[usize]) -> f64 {
        let Some(sc) = &self.scatter else { return 1.0 };
        let n = self.prior.nrows() as f64;
        let (mut chi2, mut m, mut nuisance) = (0.0, 0.0, 0.0);
        for k in 0..chosen.len() {
            let inside = (chosen[k] || add.contains(&k)) && !remove.contains(&k);
            if inside {
                chi2 += sc[k].0;
                m += sc[k].1;
                nuisance += sc[k].2;
            }
        }
        let dof = m - n - nuisance;
        if dof > 0.0 {
            (chi2 / dof).max(1.0)
        } else {
            1.0
        }
    }

    /// σ of every criterion for the set behind `sums` with `add` added and `remove` removed.
    fn sigmas_with(&self, chosen: &[bool], sums: &[DMatrix<f64>], add: &[usize], remove: &[usize]) -> Vec<f64> {
        self.sigmas_scaled(sums, add, remove, self.scatter_factor(chosen, add, remove))
    }

    fn sigmas_scaled(&self, sums: &[DMatrix<f64>], add: &[usize], remove: &[usize], factor: f64) -> Vec<f64> {
        let n = self.prior.nrows();
        self.criteria
            .iter()
            .enumerate()
            .map(|(t, cr)| {
                let mut info = sums[t].clone();
                for &k in add {
                    if self.member(t, k) {
                        info += &self.information[k];
                    }
                }
                for &k in remove {
                    if self.member(t, k) {
                        info -= &self.information[k];
                    }
                }
                let idx: Vec<usize> = (0..n).filter(|&i| cr.free.as_ref().is_none_or(|f| f[i])).collect();
                let sub = DMatrix::from_fn(idx.len(), idx.len(), |a, b| info[(idx[a], idx[b])]);
                let c = DVector::from_fn(idx.len(), |a, _| cr.c[idx[a]]);
                let f = if cr.members.is_none() { factor } else { 1.0 };
                match sub.cholesky() {
                    Some(ch) => (f * c.dot(&ch.solve(&c))).max(0.0).sqrt(),
                    None => f64::INFINITY,
                }
            })
            .collect()
    }

    /// Predicted σ of every criterion for a set of candidates (mask).
    pub fn sigmas(&self, chosen: &[bool]) -> Vec<f64> {
        self.sigmas_scaled(&self.sums(chosen), &[], &[], self.scatter_factor(chosen, &[], &[]))
    }

    fn deficiency_of(&self, sigmas: &[f64]) -> f64 {
        sigmas.iter().zip(&self.criteria).map(|(s, cr)| (2.0 * (s / cr.tau).ln()).max(0.0)).sum()
    }

    fn feasible_of(&self, sigmas: &[f64]) -> bool {
        sigmas.iter().zip(&self.criteria).all(|(s, cr)| *s <= cr.tau)
    }

    fn feasible(&self, chosen: &[bool]) -> bool {
        self.feasible_of(&self.sigmas(chosen))
    }

    fn cost_of(&self, chosen: &[bool]) -> f64 {
        (0..chosen.len()).filter(|&k| chosen[k]).map(|k| self.cost[k]).sum()
    }

    fn selection(&self, chosen: &[bool]) -> Selection {
        let idx: Vec<usize> = (0..chosen.len()).filter(|&k| chosen[k]).collect();
        Selection { cost: idx.iter().map(|&k| self.cost[k]).sum(), chosen: idx, sigma: self.sigmas(chosen) }
    }

    /// Greedy from `chosen`: add the candidate with the largest decrease of the deficiency per
    /// second until every criterion holds.
    fn greedy(&self, chosen: &mut [bool]) {
        let n = chosen.len();
        let mut sums = self.sums(chosen);
        let mut f = self.deficiency_of(&self.sigmas_with(chosen, &sums, &[], &[]));
        while f > 0.0 {
            let mut best: Option<(usize, f64, f64)> = None;
            for k in (0..n).filter(|&k| !chosen[k]) {
                let fk = self.deficiency_of(&self.sigmas_with(chosen, &sums, &[k], &[]));
                let score = (f - fk) / self.cost[k];
                if f - fk > 1e-12 && best.is_none_or(|b| score > b.1) {
                    best = Some((k, score, fk));
                }
            }
            // No single candidate lowers the deficiency (a target needing two candidates
            // together): add the cheapest remaining one.
            let k = match best {
                Some((k, _, _)) => k,
                None => match (0..n).filter(|&k| !chosen[k]).min_by(|&a, &b| self.cost[a].total_cmp(&self.cost[b])) {
                    Some(k) => k,
                    None => return,
                },
            };
            chosen[k] = true;
            sums = self.sums(chosen);
            f = self.deficiency_of(&self.sigmas_with(chosen, &sums, &[], &[]));
        }
    }

    /// Local search on a feasible set: drop what is not needed (most expensive first), then
    /// swap one chosen for one cheaper unchosen, or two chosen for one cheaper than both,
    /// while the criteria hold; repeat until nothing improves.
    fn improve(&self, chosen: &mut [bool]) {
        let n = chosen.len();
        for _ in 0..10 * n.max(1) {
            // Drop.
            let mut ins: Vec<usize> = (0..n).filter(|&k| chosen[k]).collect();
            ins.sort_by(|&a, &b| self.cost[b].total_cmp(&self.cost[a]));
            for &k in &ins {
                let sums = self.sums(chosen);
                if self.feasible_of(&self.sigmas_with(chosen, &sums, &[], &[k])) {
                    chosen[k] = false;
                }
            }
            let sums = self.sums(chosen);
            let ins: Vec<usize> = (0..n).filter(|&k| chosen[k]).collect();
            let outs: Vec<usize> = (0..n).filter(|&k| !chosen[k]).collect();
            // The best improving move of either kind.
            let mut best: Option<(f64, Vec<usize>, usize)> = None;
            for (a, &k) in ins.iter().enumerate() {
                for &j in &outs {
                    let gain = self.cost[k] - self.cost[j];
                    if gain > 1e-12
                        && best.as_ref().is_none_or(|b| gain > b.0)
                        && self.feasible_of(&self.sigmas_with(chosen, &sums, &[j], &[k]))
                    {
                        best = Some((gain, vec![k], j));
                    }
                }
                for &k2 in &ins[a + 1..] {
                    for &j in &outs {
                        let gain = self.cost[k] + self.cost[k2] - self.cost[j];
                        if gain > 1e-12
                            && best.as_ref().is_none_or(|b| gain > b.0)
                            && self.feasible_of(&self.sigmas_with(chosen, &sums, &[j], &[k, k2]))
                        {
                            best = Some((gain, vec![k, k2], j));
                        }
                    }
                }
            }
            match best {
                Some((_, removed, added)) => {
                    for k in removed {
                        chosen[k] = false;
                    }
                    chosen[added] = true;
                }
                None => return,
            }
        }
    }
}

/// Cost-weighted greedy selection followed by local search (drop, 1-for-1 and 2-for-1
/// exchanges), started from the empty set and from each of the best first picks; the cheapest
/// result wins (see the module documentation).
pub fn select(problem: &SelectionProblem) -> Result<Selection, DesignError> {
    problem.check()?;
    let n = problem.cost.len();
    let all = vec![true; n];
    let s_all = problem.sigmas(&all);
    if !problem.feasible_of(&s_all) {
        let missed: Vec<String> = s_all
            .iter()
            .zip(&problem.criteria)
            .enumerate()
            .filter(|(_, (s, cr))| **s > cr.tau)
            .map(|(t, (s, cr))| {
                format!("criterion {t}: σ {s:.3e} > {:.3e} (internal units) with every candidate", cr.tau)
            })
            .collect();
        return Err(DesignError::Unreachable(missed.join("; ")));
    }
    // Starts: the empty set, and each of the (at most 8) best first picks forced in.
    let empty = vec![false; n];
    let sums = problem.sums(&empty);
    let f0 = problem.deficiency_of(&problem.sigmas_with(&empty, &sums, &[], &[]));
    let mut firsts: Vec<(usize, f64)> = (0..n)
        .map(|k| (k, (f0 - problem.deficiency_of(&problem.sigmas_with(&empty, &sums, &[k], &[]))) / problem.cost[k]))
        .collect();
    firsts.sort_by(|a, b| b.1.total_cmp(&a.1));
    let mut best: Option<Vec<bool>> = None;
    for start in std::iter::once(None).chain(firsts.iter().take(8).map(|f| Some(f.0))) {
        let mut chosen = empty.clone();
        if let Some(k) = start {
            chosen[k] = true;
        }
        problem.greedy(&mut chosen);
        problem.improve(&mut chosen);
        if problem.feasible(&chosen)
            && best.as_ref().is_none_or(|b| problem.cost_of(&chosen) < problem.cost_of(b) - 1e-12)
        {
            best = Some(chosen);
        }
    }
    let chosen = best.ok_or_else(|| DesignError::Unreachable("no start reached the targets".into()))?;
    Ok(problem.selection(&chosen))
}

/// The cheapest feasible selection by enumerating every subset (pools of at most 20): the
/// oracle for [`select`]. `None` when no subset is feasible.
pub fn select_exhaustive(problem: &SelectionProblem) -> Result<Option<Selection>, DesignError> {
    problem.check()?;
    let n = problem.cost.len();
    if n > 20 {
        return Err(DesignError::Input(format!("exhaustive selection over {n} candidates (at most 20)")));
    }
    let mut best: Option<(f64, u32)> = None;
    for mask in 0u32..(1 << n) {
        let cost: f64 = (0..n).filter(|k| mask >> k & 1 == 1).map(|k| problem.cost[k]).sum();
        if best.is_some_and(|b| cost >= b.0) {
            continue;
        }
        let chosen: Vec<bool> = (0..n).map(|k| mask >> k & 1 == 1).collect();
        if problem.feasible(&chosen) {
            best = Some((cost, mask));
        }
    }
    Ok(best.map(|(_, mask)| problem.selection(&(0..n).map(|k| mask >> k & 1 == 1).collect::<Vec<_>>())))
}

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
        Self { targets: Target::issue_targets(), margin: 0.8, prior: Extrinsics::nominal_design(), seed: 1 }
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
    // Per chosen motion: its setup in plan order and its segment.
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
    let mut info = weak_prior();
    for &k in &sel.chosen {
        info += &pilot[k].information;
    }
    let log_det_information =
        info.clone().cholesky().map_or(f64::NEG_INFINITY, |c| 2.0 * c.l().diagonal().map(f64::ln).sum());
    let reference_sigmas = if reference.is_empty() {
        None
    } else {
        let f = plans_information(preset, &options.prior, reference, options.seed, &reduced_chi2)?;
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
        let f_sweeps = plans_information(preset, &options.prior, &sweeps, options.seed, &reduced_chi2)?;
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
            let segs = r.expand(&robot, start, &preset.motion)?;
            total += crate::plan::total_duration_s(&segs);
            start = segs.last().map_or(start, |s| s.to_display);
        }
        Some((p.sigmas(&[true, true]), reference.iter().map(|r| r.name.clone()).collect::<Vec<_>>(), total))
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

/// Longest joint move time between two poses (s), from the plan timing model.
fn move_s(robot: &RobotDescription, limits: &MotionLimits, from: [f64; 6], to: [f64; 6]) -> f64 {
    let p = Plan {
        name: "m".into(),
        description: String::new(),
        segments: vec![Segment::Move { to: JointTarget::all(to), record: false, label: String::new() }],
    };
    p.duration_s(robot, from, limits).unwrap_or(f64::INFINITY)
}

/// The plan of the chosen candidates: nearest setup move first from q = 0, each candidate's
/// setup move then its recorded segment, ending at q = 0.
pub fn assemble(chosen: &[&Candidate], robot: &RobotDescription, limits: &MotionLimits) -> Result<Plan, DesignError> {
    let mut left: Vec<&Candidate> = chosen.to_vec();
    let mut at = [0.0; 6];
    let mut segments = Vec::new();
    while !left.is_empty() {
        let (i, _) = left
            .iter()
            .enumerate()
            .map(|(i, c)| (i, move_s(robot, limits, at, c.start_display)))
            .min_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)))
            .expect("left is not empty");
        let c = left.remove(i);
        segments.push(Segment::Move {
            to: JointTarget::all(c.start_display),
            record: false,
            label: format!("setup: {}", c.label),
        });
        segments.push(c.segment.clone());
        let end = match &c.segment {
            Segment::Move { to, .. } => to.resolve(c.start_display),
            _ => c.start_display,
        };
        at = end;
    }
    segments.push(Segment::Move { to: JointTarget::all([0.0; 6]), record: false, label: "return to 0".into() });
    let plan = Plan {
        name: "optimised".into(),
        description: format!(
            "Experiment design (core/src/identify/design.rs): {} motions chosen from a candidate pool to reach the required σ of the joint estimate in the least bench time.",
            chosen.len()
        ),
        segments,
    };
    plan.expand(robot, [0.0; 6], limits)?;
    Ok(plan)
}

/// The plan as RON text with a header comment (each line prefixed with `// `).
pub fn plan_ron_with_header(plan: &Plan, header: &str) -> Result<String, DesignError> {
    let body = ron::ser::to_string_pretty(plan, ron::ser::PrettyConfig::default().struct_names(true).depth_limit(2))
        .map_err(|e| DesignError::Input(format!("plan to RON: {e}")))?;
    let mut out = String::new();
    for line in header.lines() {
        out.push_str("// ");
        out.push_str(line);
        out.push('\n');
    }
    out.push_str(&body);
    out.push('\n');
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A linear model y = θ₀ + θ₁·x + θ₂·x² measured at x with noise σ: information of one
    /// measurement `a aᵀ / σ²`, a = (1, x, x²).
    fn measurement(x: f64, sigma: f64) -> DMatrix<f64> {
        let a = DVector::from_vec(vec![1.0, x, x * x]);
        &a * a.transpose() / (sigma * sigma)
    }

    fn problem(points: &[(f64, f64, f64)], bounds: [f64; 3]) -> SelectionProblem {
        SelectionProblem {
            information: points.iter().map(|&(x, s, _)| measurement(x, s)).collect(),
            cost: points.iter().map(|p| p.2).collect(),
            prior: DMatrix::identity(3, 3) * 1e-6,
            scatter: None,
            criteria: (0..3)
                .map(|i| Criterion {
                    c: DVector::from_fn(3, |j, _| if i == j { 1.0 } else { 0.0 }),
                    tau: bounds[i],
                    free: None,
                    members: None,
                })
                .collect(),
        }
    }

    #[test]
    fn greedy_finds_the_brute_force_optimum_of_a_quadratic_fit() {
        // Points on [-1, 1]; the curvature and slope want the ends, the intercept the middle.
        let points: Vec<(f64, f64, f64)> = [-1.0, -0.75, -0.5, -0.25, 0.0, 0.25, 0.5, 0.75, 1.0]
            .iter()
            .enumerate()
            .map(|(k, &x)| (x, 0.1, 1.0 + 0.1 * k as f64))
            .collect();
        let p = problem(&points, [0.08, 0.1, 0.2]);
        let best = select_exhaustive(&p).unwrap().expect("feasible");
        let got = select(&p).unwrap();
        assert!(got.sigma.iter().zip(&p.criteria).all(|(s, c)| *s <= c.tau));
        assert!(
            (got.cost - best.cost).abs() < 1e-9,
            "greedy {:?} ({}) vs optimum {:?} ({})",
            got.chosen,
            got.cost,
            best.chosen,
            best.cost
        );
    }

    #[test]
    fn greedy_is_feasible_and_near_the_optimum_on_random_problems() {
        use rand::{rngs::StdRng, Rng, SeedableRng};
        let mut rng = StdRng::seed_from_u64(4);
        let (mut exact, mut feasible, mut worst) = (0, 0, 1.0f64);
        for _ in 0..40 {
            let points: Vec<(f64, f64, f64)> = (0..12)
                .map(|_| (rng.random_range(-1.0..1.0), rng.random_range(0.05..0.3), rng.random_range(1.0..5.0)))
                .collect();
            let p = problem(&points, [0.1, 0.15, 0.4]);
            let Some(best) = select_exhaustive(&p).unwrap() else {
                assert!(matches!(select(&p), Err(DesignError::Unreachable(_))));
                continue;
            };
            feasible += 1;
            let got = select(&p).unwrap();
            assert!(got.sigma.iter().zip(&p.criteria).all(|(s, c)| *s <= c.tau), "infeasible selection");
            assert!(got.cost >= best.cost - 1e-9);
            worst = worst.max(got.cost / best.cost);
            exact += usize::from((got.cost - best.cost).abs() < 1e-9);
        }
        eprintln!("greedy + exchange: optimum in {exact} of {feasible} feasible problems, worst ratio {worst:.3}");
        assert!(feasible >= 20, "only {feasible} feasible problems: the test is too easy");
        assert!(worst < 1.1, "worst cost ratio {worst}");
        assert!(exact * 10 >= feasible * 9, "optimum found in only {exact} of {feasible}");
    }

    #[test]
    fn an_unreachable_target_is_an_error_naming_it() {
        let p = problem(&[(0.0, 0.1, 1.0), (0.5, 0.1, 1.0)], [0.08, 0.1, 0.2]);
        let err = select(&p).unwrap_err().to_string();
        assert!(err.contains("criterion") && err.contains("cannot reach"), "{err}");
        let mut bad = problem(&[(0.0, 0.1, 1.0)], [0.1, 0.1, 0.1]);
        bad.cost[0] = 0.0;
        assert!(select(&bad).unwrap_err().to_string().contains("cost"));
    }

    #[test]
    fn the_schur_complement_removes_a_nuisance_gain() {
        // y_k = g·(1 + θ·x_k): with g free, θ's information is that of the centred x.
        let xs = [-1.0, 0.0, 2.0];
        let j = DMatrix::from_fn(3, 2, |r, c| if c == 0 { xs[r] } else { 1.0 });
        let cols = [Some(0usize), None];
        let f = extrinsic_information(&j, &cols);
        let mean = xs.iter().sum::<f64>() / 3.0;
        let want: f64 = xs.iter().map(|x| (x - mean).powi(2)).sum();
        assert!((f[(0, 0)] - want).abs() < 1e-12, "{} vs {want}", f[(0, 0)]);
    }

    #[test]
    fn the_shipped_optimised_plan_fits_in_ten_minutes() {
        let plan = Plan::optimised();
        let d = plan.duration_s(&RobotDescription::femto_6dof(), [0.0; 6], &MotionLimits::default()).unwrap();
        assert!(d <= 600.0, "{d} s");
        let sweeps = plan.segments.iter().filter(|s| matches!(s, Segment::Sweep { .. })).count();
        assert!(sweeps >= 3, "the identifier's bootstrap needs at least three sweeps, the plan has {sweeps}");
    }

    #[test]
    fn the_pool_fits_the_robot_and_is_timed_by_the_plan_model() {
        let robot = RobotDescription::femto_6dof();
        let limits = MotionLimits::default();
        let pool = candidate_pool(&robot, &limits);
        assert!(pool.len() > 100, "{} candidates", pool.len());
        for c in &pool {
            assert!(c.duration_s > 0.0 && c.setup_s >= 0.0, "{}", c.label);
        }
        let sweep = pool.iter().find(|c| c.label == "sweep 1540-1580 nm at 10 nm/s at q = 0").unwrap();
        assert!((sweep.duration_s - 4.0).abs() < 1e-9 && sweep.setup_s == 0.0);
        let refs: Vec<&Candidate> = pool.iter().take(5).collect();
        let plan = assemble(&refs, &robot, &limits).unwrap();
        let text = plan_ron_with_header(&plan, "generated by a test").unwrap();
        assert!(text.starts_with("// generated by a test\n"));
        let back = Plan::from_ron_str(&text, std::path::Path::new("optimised.ron")).unwrap();
        assert_eq!(back, plan);
        assert_eq!(
            back.recorded_moves() + back.segments.iter().filter(|s| matches!(s, Segment::Sweep { .. })).count(),
            5
        );
    }
}
