//! Does the fringe analysis see a hidden effect the way the model predicts it? Two virtual
//! benches that differ only by one library effect at its typical size (same seed, exact path,
//! so the same noise) run the short calibration-like session of `tests/cli_diagnose.rs` and
//! then the whole pool of discriminating motions; every observation is extracted with the
//! true extrinsics on both, and the measured change (with − without the effect) is set against
//! the model's (the predictor with − without it). A motion whose measured change misses the
//! model's by several σ is one the workflow cannot use for that effect.
//!
//!     cargo run --release -p photorobot-e2e --example effect_visibility [-- INDEX...] [--seed N] [--all] [--tracks] [--hinted] [--profile] [--noiseless] [--amplitudes]
//!
//! INDEX as in `diagnose_scan`; `--all` prints every gap change, not only those where the
//! effect or the mismatch exceeds 0.5σ. `--tracks` first prints, for every pool motion on the
//! bench without effects, the tracking on its own (`measure::analyse` with the true model):
//! its error against the truth at the quarter points and the end, the tracker's σ of the
//! end and its fitted hint scale (1 at the truth). Amplitudes are matched by their rank
//! within a motion: where the two runs find different numbers of extrema a line says "no
//! counterpart" and the amplitudes' sums mean little. `--hinted` extracts the bench with the
//! effect with a model that has it (as the diagnosis re-analyses its traces once the effect is
//! named) and, with `--tracks`, prints its tracking too. `EV_DETAIL=<part of a label>` prints
//! the tracking error along every tracked trace whose label contains it.

use photorobot_core::bench::{run_plan, BenchPreset, RunControl, VirtualBench};
use photorobot_core::diagnose::candidates::library;
use photorobot_core::diagnose::fit::Predictor;
use photorobot_core::diagnose::motions::{pool, BenchRunner, MotionRunner};
use photorobot_core::diagnose::validation::extended_model;
use photorobot_core::diagnose::EXTRACT_OPTIONS;
use photorobot_core::identify::measurements::observations_from_traces;
use photorobot_core::identify::{Observation, ObservationKind};
use photorobot_core::measure::{self, Measurement};
use photorobot_core::model::phase::PhaseModel;
use photorobot_e2e::{library_effects_at_typical_size, session_plan};
use std::sync::atomic::AtomicBool;

/// The session's and the pool's observations on a bench with `preset`'s effects.
/// With `EFFECT_VISIBILITY_DUMP=<prefix>`, every trace of the pool is written to
/// `<prefix>-<tag>-<index>.csv`.
fn observe(preset: &BenchPreset, model: &PhaseModel, seed: u64, tag: &str, tracks: bool) -> Vec<Observation> {
    let mut bench = VirtualBench::new(preset, Some(seed)).expect("bench");
    bench.set_exact(true);
    let cancel = AtomicBool::new(false);
    let mut control = RunControl { cancel: &cancel, on_samples: &mut |_, _| {}, on_progress: &mut |_| {} };
    let run = run_plan(&mut bench, &session_plan(), &mut control);
    run.outcome.expect("session runs");
    let mut obs = observations_from_traces(&run.traces, model, &EXTRACT_OPTIONS).observations;
    let mut runner = BenchRunner::new(&mut bench, 0.0);
    obs.extend(runner.run(&pool(), model, false).expect("pool runs"));
    for t in runner.traces.iter().filter(|_| tracks) {
        let Ok(Measurement::Motion(m)) = measure::analyse(t, model) else { continue };
        let truth = model.hint_nm(t, m.wavelength_nm).expect("hint");
        let n = t.len();
        let err = |i: usize| m.track.dl_nm[i] - truth[i];
        println!(
            "   {:<44} error {:+7.2} {:+7.2} {:+7.2} end {:+7.2} nm, σ end {:.2} nm, hint scale {:.5} ± {:.5}",
            t.meta.label,
            err(n / 4),
            err(n / 2),
            err(3 * n / 4),
            err(n - 1),
            m.track.sigma_total_nm,
            m.track.hint_scale,
            m.track.hint_scale_sigma
        );
        if std::env::var("EV_DETAIL").is_ok_and(|l| t.meta.label.contains(&l)) {
            let y = &t.irradiance;
            for i in (0..n).step_by((n / 200).max(1)) {
                println!(
                    "      {i:6} q {:?} truth {:9.2} err {:+7.2} y {:.5}",
                    t.joints_display(i).map(|v| (v * 1000.0).round() / 1000.0),
                    truth[i],
                    err(i),
                    y[i]
                );
            }
        }
    }
    if let Ok(prefix) = std::env::var("EFFECT_VISIBILITY_DUMP") {
        for (i, t) in runner.traces.iter().enumerate() {
            t.write_csv(std::path::Path::new(&format!("{prefix}-{tag}-{i:03}.csv"))).expect("trace");
        }
    }
    obs
}

fn kind_of(o: &Observation) -> usize {
    match o.kind {
        ObservationKind::GapChange { .. } => 0,
        ObservationKind::AbsoluteGap { .. } => 1,
        ObservationKind::FringeAmplitude { .. } => 2,
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (mut seed, mut picks, mut all_rows, mut tracks, mut profile, mut noiseless, mut amplitude_rows) =
        (5u64, Vec::new(), false, false, false, false, false);
    let mut hinted = false;
    let mut i = 0;
    while i < args.len() {
        match args[i].as_str() {
            "--seed" => {
                seed = args.get(i + 1).and_then(|s| s.parse().ok()).expect("--seed N");
                i += 1;
            }
            "--all" => all_rows = true,
            "--tracks" => tracks = true,
            "--profile" => profile = true,
            "--noiseless" => noiseless = true,
            "--amplitudes" => amplitude_rows = true,
            "--hinted" => hinted = true,
            a => picks.push(a.parse::<usize>().expect("an effect index")),
        }
        i += 1;
    }
    let all = library_effects_at_typical_size();
    if picks.is_empty() {
        picks = (1..all.len()).collect();
    }
    let mut base = BenchPreset::resolve("table2-ideal").expect("embedded preset");
    if noiseless {
        base = base.without_noise();
    }
    let model = PhaseModel::of_preset(&base, base.truth).expect("model");
    let without = observe(&base, &model, seed, "without", tracks);
    for k in picks {
        let (name, hidden, effects) = &all[k];
        let mut preset = base.clone();
        preset.effects = effects.clone();
        let analysis =
            if hinted { extended_model(&model, base.truth, effects).expect("effects") } else { model.clone() };
        let with = observe(&preset, &analysis, seed, &format!("with{k}"), tracks && hinted);
        let predictor = Predictor::new(&model, &with).expect("predictor");
        let gains = vec![1.0; 1000];
        let p1 = predictor.predict(&base.truth, effects, &gains, &with).expect("prediction");
        let p0 = predictor.predict(&base.truth, &[], &gains, &with).expect("prediction");
        let p_without = Predictor::new(&model, &without).expect("predictor");
        let q0 = p_without.predict(&base.truth, &[], &gains, &without).expect("prediction");
        println!("[{k}] {name} = {hidden}");
        // (kind, model change², mismatch², count) per kind.
        let mut sums = [[0.0f64; 3]; 3];
        for (n, o) in with.iter().enumerate() {
            let same = |p: &&Observation| p.label == o.label && kind_of(p) == kind_of(o);
            let rank = with[..n].iter().filter(|p| same(p)).count();
            let Some((m0, w0)) = without.iter().enumerate().filter(|(_, p)| same(p)).nth(rank) else {
                println!("   {} ({}): no counterpart without the effect", o.label, o.unit());
                continue;
            };
            let measured = o.value() - w0.value();
            let predicted = p1[n] - p0[n];
            let (zm, zp) = ((measured - predicted) / o.sigma, predicted / o.sigma);
            let s = &mut sums[kind_of(o)];
            s[0] += zp * zp;
            s[1] += zm * zm;
            s[2] += 1.0;
            if (noiseless || amplitude_rows) && kind_of(o) == 2 {
                println!(
                    "   {:<46} amplitude {:.9} model {:.9} mW  σ {:.9} miss {:+.2}σ relative miss {:+.5}",
                    o.label,
                    o.value(),
                    p1[n],
                    o.sigma,
                    (o.value() - p1[n]) / o.sigma,
                    o.value() / p1[n] - 1.0
                );
            }
            if kind_of(o) == 0 && (all_rows || zm.abs() > 0.5 || zp.abs() > 0.5) {
                println!(
                    "   {:<46} measured {measured:+9.3} model {predicted:+9.3} σ {:6.3} nm   miss {zm:+6.2}σ   residuals with {:+6.2}σ without {:+6.2}σ",
                    o.label,
                    o.sigma,
                    (o.value() - p1[n]) / o.sigma,
                    (w0.value() - q0[m0]) / w0.sigma
                );
            }
        }
        if profile {
            profile_chi2(&predictor, &base, effects, *hidden, &with);
        }
        for (kind, s) in ["gap changes", "absolute gaps", "amplitudes"].iter().zip(sums) {
            println!(
                "   {kind:<14} n {:4}  model Σ(Δ/σ)² {:10.1}  mismatch Σ(miss/σ)² {:10.1}",
                s[2] as usize, s[0], s[1]
            );
        }
    }
}

/// χ² of each kind of observation (amplitudes with each trace's gain at its best) at the truth,
/// with the one library parameter of `effects` at 0.99 to 1.01 × `hidden`, and the value each
/// kind alone puts the parameter at (parabola through the profile).
fn profile_chi2(
    predictor: &Predictor,
    base: &BenchPreset,
    effects: &[photorobot_core::model::effects::Effect],
    hidden: f64,
    obs: &[Observation],
) {
    let robot = base.robot_description().expect("robot");
    let Some(c) = library(&robot).into_iter().find(|c| effects.len() == 1 && c.effect(hidden) == effects[0]) else {
        println!("   profile: not one library parameter");
        return;
    };
    let factors = [0.99, 0.995, 1.0, 1.005, 1.01];
    let mut chi = Vec::new();
    for f in factors {
        let e = vec![c.effect(hidden * f)];
        let m = predictor.predict(&base.truth, &e, &vec![1.0; 1000], obs).expect("prediction");
        let mut k = [0.0f64; 3];
        let groups = photorobot_core::diagnose::fit::gain_groups(obs);
        let (mut ym, mut mm) = (vec![0.0; groups], vec![0.0; groups]);
        for (o, mi) in obs.iter().zip(&m) {
            match o.kind {
                ObservationKind::FringeAmplitude { group, .. } => {
                    ym[group] += o.value() * mi / (o.sigma * o.sigma);
                    mm[group] += mi * mi / (o.sigma * o.sigma);
                }
                _ => k[kind_of(o)] += ((o.value() - mi) / o.sigma).powi(2),
            }
        }
        for (o, mi) in obs.iter().zip(&m) {
            if let ObservationKind::FringeAmplitude { group, .. } = o.kind {
                let g = ym[group] / mm[group];
                k[2] += ((o.value() - g * mi) / o.sigma).powi(2);
            }
        }
        chi.push(k);
    }
    for (f, k) in factors.iter().zip(&chi) {
        println!(
            "   profile {} = {:.6} {}: χ² gap changes {:10.2} absolute {:8.2} amplitudes {:10.2}",
            c.name,
            hidden * f,
            c.unit,
            k[0],
            k[1],
            k[2]
        );
    }
    // Parabola through the points at 0.995, 1, 1.005 of each kind and of the sum.
    let h = 0.005 * hidden;
    let vertex = |a: f64, b: f64, d: f64| {
        let curv = (a - 2.0 * b + d) / (h * h);
        (hidden - (d - a) / (2.0 * h) / curv, (2.0 / curv).sqrt())
    };
    for (kind, i) in [("gap changes", 0), ("amplitudes", 2)] {
        let (v, s) = vertex(chi[1][i], chi[2][i], chi[3][i]);
        println!("   {kind} alone: {} = {v:.6} ± {s:.6} {}", c.name, c.unit);
    }
    let sum = |j: usize| chi[j].iter().sum::<f64>();
    let (v, s) = vertex(sum(1), sum(2), sum(3));
    println!("   all: {} = {v:.6} ± {s:.6} {}", c.name, c.unit);
}
