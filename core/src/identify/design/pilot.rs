//! The Fisher information of candidates and plans, from a pilot virtual bench whose truth is
//! the prior: each trace goes through the calibration's extraction and the joint Jacobian.

use super::error::DesignError;
use super::pool::Candidate;
use crate::bench::{run_plan, BenchPreset, RunControl, VirtualBench};
use crate::identify::joint::{self, JointOptions};
use crate::identify::measurements::{observations_from_trace, observations_from_traces, ExtractOptions};
use crate::identify::N_EXTRINSICS;
use crate::model::extrinsics::Extrinsics;
use crate::model::phase::PhaseModel;
use crate::plan::{JointTarget, Plan, Segment};
use nalgebra::DMatrix;
use std::sync::atomic::AtomicBool;

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
            through: false,
        });
        segments.push(c.segment.clone());
    }
    segments.push(Segment::Move {
        to: JointTarget::all([0.0; 6]),
        record: false,
        label: "return to 0".into(),
        through: false,
    });
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
