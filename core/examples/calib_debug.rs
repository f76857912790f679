//! Debug harness for the calibration: simulate (cached under /tmp), identify, compare with the truth.
//! `cargo run --release -p photorobot-core --example calib_debug -- <preset> <joint|paper> [seed]`
//!
//! Environment switches pick one diagnostic instead of the full identification:
//! TRACE_IDX (one trace sample by sample, window FROM..TO), PER_TRACE (every trace's
//! tracking error, HINT_NOMINAL to analyse with the design model), TRUTH_RESID (residuals at the
//! truth, SHOW_AMP for the amplitudes), STEP_A (the paper's step A), TIME_EXTRACT (timings).
use photorobot_core::bench::{BenchPreset, VirtualBench};
use photorobot_core::calibration::{self, Mode};
use photorobot_core::identify::joint;
use photorobot_core::identify::{Observation, ObservationKind};
use photorobot_core::model::extrinsics::{Extrinsics, PARAMETER_NAMES};
use photorobot_core::model::phase::PhaseModel;
use photorobot_core::trace::Trace;
use std::path::PathBuf;
use std::time::Instant;

/// Command-line choices: which preset, which calibration mode, which noise seed.
struct Args {
    preset_name: String,
    mode: Mode,
    seed: u64,
}

fn parse_args() -> Args {
    let args: Vec<String> = std::env::args().collect();
    let preset_name = args.get(1).map(String::as_str).unwrap_or("table2-ideal").to_string();
    let mode = if args.get(2).map(String::as_str) == Some("paper") { Mode::Paper } else { Mode::Joint };
    let seed: u64 = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(1);
    Args { preset_name, mode, seed }
}

/// The calibration traces: read from the /tmp cache when present, otherwise measured on the
/// virtual bench and written there, so repeated runs skip the slow simulation.
fn load_or_measure_traces(args: &Args, preset: &BenchPreset) -> Vec<Trace> {
    let Args { preset_name, mode, seed } = args;
    let dir = PathBuf::from(format!("/tmp/calib-{preset_name}-{mode:?}-{seed}"));
    if dir.exists() {
        let mut files: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().path()).collect();
        files.sort();
        files.iter().map(|p| Trace::read_csv(p).unwrap()).collect()
    } else {
        let mut bench = VirtualBench::new(preset, Some(*seed)).unwrap();
        let (traces, dur) = calibration::measure(&mut bench, &calibration::plans(*mode)).unwrap();
        println!("measured {} traces, bench time {:.0} s", traces.len(), dur);
        std::fs::create_dir_all(&dir).unwrap();
        for (i, t) in traces.iter().enumerate() {
            t.write_csv(&dir.join(format!("{i:03}.csv"))).unwrap();
        }
        traces
    }
}

/// The phase model with the design extrinsics: the starting point of the identification.
fn nominal_model(preset: &BenchPreset) -> PhaseModel {
    PhaseModel::new(
        preset.robot_description().unwrap(),
        Extrinsics::nominal_design(),
        preset.optics,
        &preset.ambient,
        preset.laser.wavelength_nm,
    )
    .unwrap()
}

/// The nominal model with the true extrinsics put in: what the bench really does.
fn truth_model(nominal: &PhaseModel, preset: &BenchPreset) -> PhaseModel {
    let mut m2 = nominal.clone();
    m2.extrinsics = preset.truth;
    m2
}

/// TRACE_IDX: 41 samples of one trace (between fractions FROM and TO) with the tracked and the
/// true path difference.
fn print_trace_samples(traces: &[Trace], idx: &str, nominal: &PhaseModel, preset: &BenchPreset) {
    let t = &traces[idx.parse::<usize>().unwrap()];
    let m2 = truth_model(nominal, preset);
    let truth = m2.hint_nm(t, 1560.0).unwrap();
    if let Ok(photorobot_core::measure::Measurement::Motion(mm)) = photorobot_core::measure::analyse(t, &m2) {
        let n = t.len();
        let from: f64 = std::env::var("FROM").ok().and_then(|v| v.parse().ok()).unwrap_or(0.0);
        for k in 0..=40 {
            let to: f64 = std::env::var("TO").ok().and_then(|v| v.parse().ok()).unwrap_or(1.0);
            let i = ((from + (to - from) * k as f64 / 40.0) * (n - 1) as f64) as usize;
            println!(
                "{i:6} t {:.3} I {:.5} dl {:10.2} truth {:10.2} err {:7.2} σ {:.2}",
                t.t_s[i],
                t.irradiance[i],
                mm.track.dl_nm[i],
                truth[i],
                mm.track.dl_nm[i] - truth[i],
                mm.track.sigma_dl_nm[i]
            );
        }
        println!("warnings {:?}", mm.track.warnings);
    }
}

/// PER_TRACE: one line per trace with the tracking error at the quarters and the error budget.
fn print_per_trace_errors(traces: &[Trace], nominal: &PhaseModel, preset: &BenchPreset) {
    let m2 = truth_model(nominal, preset);
    for (i, t) in traces.iter().enumerate() {
        // HINT_NOMINAL=1: analyse with the design extrinsics (hint and model wrong), compare
        // with the truth all the same.
        let (name, m) = if std::env::var("HINT_NOMINAL").is_ok() { ("nominal", nominal) } else { ("truth", &m2) };
        match photorobot_core::measure::analyse(t, m) {
            Ok(photorobot_core::measure::Measurement::Motion(mm)) => {
                let truth = m2.hint_nm(t, 1560.0).unwrap();
                let n = t.len();
                let errs: Vec<f64> = (1..=4)
                    .map(|p| {
                        let i = p * (n - 1) / 4;
                        mm.track.dl_nm[i] - truth[i]
                    })
                    .collect();
                println!(
                    "{i:3} {name:8} {:42} dL {:10.2} err {:6.2} {:6.2} {:6.2} {:6.2} σ {:.2} fit {:.2} harm {:.2} chi2 {:.2} noise {:.2e} h {:?}",
                    t.meta.label,
                    mm.track.dl_nm.last().unwrap(),
                    errs[0], errs[1], errs[2], errs[3],
                    mm.track.sigma_total_nm, mm.track.sigma_fit_nm, mm.track.sigma_harmonic_nm,
                    mm.track.normalized_chi2, mm.track.noise_sigma, mm.track.harmonic
                )
            }
            Ok(_) => {}
            Err(e) => println!("{i:3} {name:8} {:50} ERROR {e}", t.meta.label),
        }
    }
}

/// TRUTH_RESID: residuals of the observations (extracted with the true model) at the true
/// extrinsics, grouped by label and by unit; labels worse than 1.5σ rms are listed.
fn print_residuals_at_truth(traces: &[Trace], nominal: &PhaseModel, preset: &BenchPreset) {
    let m2 = truth_model(nominal, preset);
    let ex = photorobot_core::identify::measurements::observations_from_traces(traces, &m2, &Default::default());
    let obs = ex.observations;
    let at_truth = joint::evaluate(nominal, &obs, &preset.truth, &Default::default());
    let mut by: std::collections::BTreeMap<String, (f64, usize)> = Default::default();
    for (o, r) in obs.iter().zip(&at_truth.normalised_residuals) {
        let k = format!("{} [{}]", o.label, o.unit());
        let e = by.entry(k).or_default();
        e.0 += r * r;
        e.1 += 1;
    }
    for ((o, r), n) in obs.iter().zip(&at_truth.residuals).zip(&at_truth.normalised_residuals) {
        if let ObservationKind::FringeAmplitude { at_display, amplitude_mw, .. } = o.kind {
            if std::env::var("SHOW_AMP").is_ok() {
                println!(
                    "{:40} q4 {:7.3} q5 {:7.3} amp {:.6} res {:+.3e} σ {:.2e} ({:+.1}σ)",
                    o.label, at_display[3], at_display[4], amplitude_mw, r, o.sigma, n
                );
            }
        }
    }
    let mut kinds: std::collections::BTreeMap<&str, (f64, usize)> = Default::default();
    for (o, r) in obs.iter().zip(&at_truth.normalised_residuals) {
        let e = kinds.entry(o.unit()).or_default();
        e.0 += r * r;
        e.1 += 1;
    }
    for (k, (s, n)) in &by {
        let r = (s / *n as f64).sqrt();
        if r > 1.5 {
            println!("{k:60} n {n:3} rms {r:.2}σ");
        }
    }
    for (k, (s, n)) in &kinds {
        println!("{k:4} n {n:4} rms {:.2}σ", (s / *n as f64).sqrt());
    }
    let n = at_truth.normalised_residuals.len() as f64;
    println!("all: rms {:.2}σ", (at_truth.normalised_residuals.iter().map(|r| r * r).sum::<f64>() / n).sqrt());
}

/// STEP_A: the absolute gaps against their true values, the bootstrap fit on the sweeps, and
/// the paper's step A from the truth and from the design, with and without holding.
fn print_step_a(traces: &[Trace], nominal: &PhaseModel, preset: &BenchPreset) {
    let m2 = truth_model(nominal, preset);
    let ex = photorobot_core::identify::measurements::observations_from_traces(traces, &m2, &Default::default());
    // Gap changes that move only the first three axes: step A's input.
    let tr: Vec<_> = ex
        .observations
        .iter()
        .filter(|o| match o.kind {
            ObservationKind::GapChange { from_display, to_display, .. } => {
                (3..6).all(|i| from_display[i] == to_display[i])
            }
            _ => false,
        })
        .cloned()
        .collect();
    let sweeps: Vec<Trace> = traces.iter().filter(|t| photorobot_core::trace::is_sweep(t)).cloned().collect();
    let g = photorobot_core::identify::measurements::observations_from_traces(&sweeps, nominal, &Default::default());
    for o in &g.observations {
        if let ObservationKind::AbsoluteGap { at_display, gap_um, sweep_nm_per_s } = o.kind {
            let mut o2 = o.clone();
            o2.kind = ObservationKind::AbsoluteGap { at_display, gap_um: 0.0, sweep_nm_per_s };
            let fp = photorobot_core::model::optics::FabryPerot::new(&preset.optics, 1560.0, nominal.n_air).unwrap();
            let p = photorobot_core::identify::predict(&m2, &fp, &preset.truth, &o2, 1.0);
            println!("gap {:?} {:.4} truth {:.4} σ {:.4} {}", at_display, gap_um, p, o.sigma, o.label);
        }
    }
    let boot = joint::estimate(
        nominal,
        &g.observations,
        &nominal.extrinsics,
        &joint::JointOptions { free: [true, true, false, false, false, false, true, false], ..Default::default() },
    );
    println!("boot {:?} {}", boot.extrinsics, boot.termination);
    for (start, name) in [(preset.truth, "truth"), (Extrinsics::nominal_design(), "nominal")] {
        for hold in [false, true] {
            let a = photorobot_core::identify::paper::step_a_with(&nominal.chain, &tr, &start, hold);
            println!("start {name} hold {hold}: {:?} rms {:.2}", a.angles_deg, a.residual_rms_sigma);
        }
    }
}

/// TIME_EXTRACT: how long extraction takes (traces slower than 0.3 s are named) and how long
/// one joint estimate from the truth takes. `t1` is when the diagnostics phase started.
fn print_extraction_timing(traces: &[Trace], nominal: &PhaseModel, preset: &BenchPreset, t1: Instant) {
    let ex = photorobot_core::identify::measurements::observations_from_traces(traces, nominal, &Default::default());
    for t in traces {
        let t3 = Instant::now();
        let _ = photorobot_core::measure::analyse(t, nominal);
        let dt = t3.elapsed().as_secs_f64();
        if dt > 0.3 {
            println!("  {:.2} s {} ({} samples)", dt, t.meta.label, t.len());
        }
    }
    println!("extract with nominal: {:.1} s, {} obs", t1.elapsed().as_secs_f64(), ex.observations.len());
    let t2 = Instant::now();
    let est = joint::estimate(nominal, &ex.observations, &preset.truth, &Default::default());
    println!("estimate {:.3} s, {} evaluations", t2.elapsed().as_secs_f64(), est.evaluations);
}

/// Each identified parameter with its σ and its error against the truth.
fn print_parameter_errors(est: &joint::JointEstimate, preset: &BenchPreset) {
    let report = photorobot_core::identify::joint::analyse_estimate(est);
    let rows = calibration::parameter_rows(&est.extrinsics, &report);
    let truth = preset.truth.to_array();
    for (i, r) in rows.iter().enumerate() {
        let err = r.value - truth[i];
        println!(
            "{:>9} {:>12.5} {:3} σ {:>10} err {:>10.5} ({:>6.1}σ) {}",
            r.name,
            r.value,
            r.unit,
            r.sigma.map_or("-".into(), |s| format!("{s:.5}")),
            err,
            r.sigma.map_or(f64::NAN, |s| err / s),
            if r.determined { "" } else { "NOT DETERMINED" }
        );
    }
}

/// Normalised residuals of the estimate: rms and max per observation kind, then the 12 worst.
fn print_estimate_residuals(est: &joint::JointEstimate, obs: &[Observation]) {
    let mut by_kind: std::collections::BTreeMap<&str, (f64, usize, f64)> = Default::default();
    for (o, r) in obs.iter().zip(&est.normalised_residuals) {
        let k = match o.kind {
            ObservationKind::GapChange { .. } => "gap change",
            ObservationKind::AbsoluteGap { .. } => "absolute gap",
            ObservationKind::FringeAmplitude { .. } => "amplitude",
        };
        let e = by_kind.entry(k).or_default();
        e.0 += r * r;
        e.1 += 1;
        e.2 = e.2.max(r.abs());
    }
    for (k, (s, n, m)) in by_kind {
        println!("{k:>14}: n {n:4} rms {:.2}σ max {:.1}σ", (s / n as f64).sqrt(), m);
    }
    let mut idx: Vec<usize> = (0..obs.len()).collect();
    idx.sort_by(|a, b| est.normalised_residuals[*b].abs().total_cmp(&est.normalised_residuals[*a].abs()));
    for &i in idx.iter().take(12) {
        println!(
            "  {:>8.1}σ  {:>10.4} {} (σ {:.4}) {}",
            est.normalised_residuals[i],
            est.residuals[i],
            obs[i].unit(),
            obs[i].sigma,
            obs[i].label
        );
    }
}

/// Truth check: the normalised rms at the true extrinsics next to the one at the estimate.
fn print_rms_truth_vs_estimate(
    est: &joint::JointEstimate,
    obs: &[Observation],
    nominal: &PhaseModel,
    preset: &BenchPreset,
) {
    let at_truth = joint::evaluate(nominal, obs, &preset.truth, &Default::default());
    let rms = (at_truth.normalised_residuals.iter().map(|r| r * r).sum::<f64>()
        / at_truth.normalised_residuals.len() as f64)
        .sqrt();
    println!("normalised rms at the truth: {rms:.2}; at the estimate: {:.2}", {
        (est.normalised_residuals.iter().map(|r| r * r).sum::<f64>() / est.normalised_residuals.len() as f64).sqrt()
    });
}

/// The full identification in `mode`, then its parameters and residuals against the truth.
/// `t1` is when the diagnostics phase started.
fn identify_and_compare(traces: &[Trace], nominal: &PhaseModel, preset: &BenchPreset, mode: Mode, t1: Instant) {
    let id = calibration::identify(traces, nominal, mode).unwrap();
    let (est, obs) = (id.estimate, id.observations);
    for (l, w) in &id.skipped {
        println!("skipped {l}: {w}");
    }
    println!("identify {:.1} s, converged {}, {}", t1.elapsed().as_secs_f64(), est.converged, est.termination);
    print_parameter_errors(&est, preset);
    let _ = PARAMETER_NAMES;
    print_estimate_residuals(&est, &obs);
    print_rms_truth_vs_estimate(&est, &obs, nominal, preset);
}

fn main() {
    let args = parse_args();
    let preset = BenchPreset::resolve(&args.preset_name).unwrap();
    let t0 = Instant::now();
    let traces = load_or_measure_traces(&args, &preset);
    println!("traces ready in {:.1} s", t0.elapsed().as_secs_f64());
    let nominal = nominal_model(&preset);
    if let Ok(i) = std::env::var("TRACE_IDX") {
        print_trace_samples(&traces, &i, &nominal, &preset);
        return;
    }
    if std::env::var("PER_TRACE").is_ok() {
        print_per_trace_errors(&traces, &nominal, &preset);
        return;
    }
    if std::env::var("TRUTH_RESID").is_ok() {
        print_residuals_at_truth(&traces, &nominal, &preset);
        return;
    }
    let t1 = Instant::now();
    if std::env::var("STEP_A").is_ok() {
        print_step_a(&traces, &nominal, &preset);
        return;
    }
    if std::env::var("TIME_EXTRACT").is_ok() {
        print_extraction_timing(&traces, &nominal, &preset, t1);
        return;
    }
    identify_and_compare(&traces, &nominal, &preset, args.mode, t1);
}
