//! The checks of the workflow, driven alone on recorded traces: a re-analysis with a motion hint
//! the data contradict must not replace the analysis it was meant to improve, and the held-out
//! allowance at the noise floor and far above it.

use super::*;
use crate::bench::{run_plan, BenchPreset, RunControl, VirtualBench};
use crate::diagnose::fit::StopCheck;
use crate::plan::Plan;

/// The designed plan recorded on `table2-ideal` (no hidden effect), diagnosed from its traces
/// up to the baseline fit.
fn baseline_of_recorded_traces() -> Diagnosis {
    let preset = BenchPreset::resolve("table2-ideal").unwrap();
    let mut bench = VirtualBench::new(&preset, Some(7)).unwrap();
    let cancel = std::sync::atomic::AtomicBool::new(false);
    let mut control = RunControl { cancel: &cancel, on_samples: &mut |_, _| {}, on_progress: &mut |_| {} };
    let run = run_plan(&mut bench, &Plan::optimised(), &mut control);
    run.outcome.unwrap();
    let base = PhaseModel::of_preset(&preset, Extrinsics::table2()).unwrap();
    let (mut d, skipped) =
        Diagnosis::from_traces(&base, &run.traces, Extrinsics::table2(), StopCheck::default()).unwrap();
    assert!(skipped.is_empty(), "{skipped:?}");
    d.step(None).unwrap();
    assert!(matches!(d.steps.last(), Some(Step::Baseline { .. })), "{:?}", d.steps.last().map(Step::title));
    d
}

/// The fit of `d` with `name` added at `value` to its motion hint (not refitted).
fn with_hint(d: &Diagnosis, name: &str, value: f64) -> Fit {
    let mut f = d.fit.clone().unwrap();
    let c = d.candidates.iter().find(|c| c.name == name).unwrap_or_else(|| panic!("no candidate {name}"));
    f.state.effects.push((c.clone(), value));
    f
}

#[test]
fn a_reanalysis_with_a_wrong_motion_hint_is_refused_and_the_earlier_analysis_kept() {
    let mut d = baseline_of_recorded_traces();
    let before = d.fit.as_ref().unwrap().rms();
    assert!(before < NOISE_FLOOR_FACTOR, "clean traces fit at {before:.2}σ");
    let observations = d.observations.clone();
    let held_out = d.held_out.clone();
    // A rotary-stage zero offset of 10°, 200 times its typical size: the rotations are
    // tracked from a gap path they did not follow (the refit reached 627σ where the earlier
    // analysis fits at 0.12σ; a 3° hint is still absorbed, at 0.21σ).
    d.fit = Some(with_hint(&d, "joint zero offset q5", 10.0));
    d.reanalyse(None).unwrap();
    let Some(Step::ReanalysisRefused { rms_sigma }) = d.steps.last() else {
        panic!("not refused: {:?}", d.steps.last().map(Step::title));
    };
    assert!(rms_sigma[1] > rms_sigma[0].max(NOISE_FLOOR_FACTOR), "{rms_sigma:?}");
    assert_eq!(d.observations, observations, "the earlier analysis is kept");
    assert_eq!(d.held_out, held_out);
}

#[test]
fn a_reanalysis_with_the_right_motion_hint_is_taken() {
    let mut d = baseline_of_recorded_traces();
    let n_steps = d.steps.len();
    d.reanalyse(None).unwrap();
    assert_eq!(d.steps.len(), n_steps, "no refusal: {:?}", d.steps.last().map(Step::title));
    let after = d.fit.as_ref().unwrap().rms();
    assert!(after < NOISE_FLOOR_FACTOR, "re-analysed clean traces fit at {after:.2}σ");
}

/// The held-out check at the noise floor and far above it. A held-out motion can miss far
/// beyond its σ where the fitted ones do not: recordings of rotations alone with a hidden 20 µm
/// q4 pivot had their 4 held-out observations at 52.8σ (the fit at 0.76σ), and the true pivot
/// took them to 71.9σ (59.2σ → 76.9σ with the traces analysed again with it in the hint). An
/// allowance in proportion to the held-out rms (not its square) refused it and named a drift
/// instead.
#[test]
fn held_out_motions_far_above_noise_allow_a_growth_in_proportion_to_their_square() {
    let mut d = baseline_of_recorded_traces();
    d.held_out = (0..20).map(|k| k % 5 == 4).collect();
    assert!(d.held_out_allows([52.8, 71.9]));
    assert!(!d.held_out_allows([52.8, 95.0]));
    // At the noise floor, the 3σ spread of a χ² of 4 observations: 1 → 1.76.
    assert!(d.held_out_allows([1.0, 1.75]));
    assert!(!d.held_out_allows([1.0, 1.77]));
}
