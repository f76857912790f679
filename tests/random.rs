//! Random plans through the path users run: `photorobot simulate` writes a plan's traces to a
//! folder, `photorobot calibrate --traces` identifies from that folder, and the outcome is scored
//! against the bench's hidden truth (every determined parameter within 3σ, or the report says
//! the fit failed), with the validation motions planned with the result run on the true bench.

use photorobot_app::cli::run;
use photorobot_core::bench::{BenchPreset, VirtualBench};
use photorobot_core::model::extrinsics::{Extrinsics, PARAMETER_NAMES};
use photorobot_core::model::phase::PhaseModel;
use photorobot_core::plan::random::{random_plan, Family};
use photorobot_core::validate::{run_validation, waypoints, ValidationMotion};
use serde_json::Value;

/// How a random plan's calibration came out.
#[derive(Debug, Clone)]
pub struct PlanOutcome {
    /// Bench preset, plan family and seed, bench seed.
    pub bench: String,
    pub family: Family,
    pub plan_seed: u64,
    pub bench_seed: u64,
    /// The report's verdict (`fits`, `does_not_fit`, `ambiguous`), or `error: …` when no report
    /// was written.
    pub verdict: String,
    /// Whether `calibrate` exited with success.
    pub succeeded: bool,
    /// Residual rms (σ) and observations.
    pub rms_sigma: f64,
    pub observations: usize,
    /// Per parameter: (name, error in σ) when determined.
    pub errors_sigma: Vec<(String, f64)>,
    /// Determined parameters more than 3σ from the truth.
    pub wrong: Vec<String>,
    /// Per validation motion planned with the result and run on the true bench (when asked for
    /// and the fit was accepted): (motion, the figure the fringes give, the true gap's peak to
    /// peak along the planned joints, nm). The second is what the calibration leaves; the first
    /// adds the stage noise and the tracking's floor.
    pub validation_nm: Vec<(String, f64, f64)>,
    /// The report's validation forecast: (motion, 95 % bound on the true gap's peak to peak,
    /// target, nm).
    pub forecast_nm: Vec<(String, f64, f64)>,
}

impl PlanOutcome {
    /// Validation motions whose true gap went beyond the target although the forecast said the
    /// extrinsics were good enough for it: a validation promised and not kept.
    pub fn validation_wrongly_promised(&self) -> Vec<String> {
        self.validation_nm
            .iter()
            .filter(|(m, _, true_nm)| {
                let f = self.forecast_nm.iter().find(|f| &f.0 == m);
                f.is_some_and(|f| *true_nm > f.2 && f.1 <= f.2) || (f.is_none() && true_nm.is_finite())
            })
            .map(|(m, _, t)| format!("{m}: true gap {t:.1} nm"))
            .collect()
    }

    /// Confidently wrong: a parameter reported determined lies beyond 3σ of the truth.
    pub fn confidently_wrong(&self) -> bool {
        !self.wrong.is_empty()
    }
}

fn cli(args: &[String]) -> (bool, String) {
    let mut out = Vec::new();
    let ok = run(args.iter().cloned(), &mut out).is_ok();
    (ok, String::from_utf8_lossy(&out).into_owned())
}

/// A bench preset by name: an embedded one, or `femto-lab-clean`, femto-lab with its hidden
/// effects switched off (its noise, drift-free air and detector kept). On femto-lab itself the
/// hidden intrinsic errors move the extrinsics that explain the data away from its truth (a
/// q5 zero offset of 0.02° is a θ_et of 0.02° on these motions), so only a verdict can be
/// scored there, not the values.
pub fn preset(name: &str) -> BenchPreset {
    match name {
        "femto-lab-clean" => {
            let mut p = BenchPreset::resolve("femto-lab").expect("the embedded femto-lab");
            p.effects.clear();
            p.name = name.to_string();
            p
        }
        other => BenchPreset::resolve(other).expect("an embedded bench preset"),
    }
}

/// Simulate random plan `plan_seed` of `family` on `bench` ([`preset`], seed `bench_seed`),
/// calibrate from the traces folder, score the report; with `validate`, run the validation
/// motions planned with the result on the true bench.
pub fn run_random_plan(bench: &str, family: Family, plan_seed: u64, bench_seed: u64, validate: bool) -> PlanOutcome {
    let preset = preset(bench);
    let plan = random_plan(family, plan_seed);
    let dir = tempfile::tempdir().expect("a temporary folder");
    let plan_file = dir.path().join("plan.ron");
    plan.save(&plan_file).expect("the plan saved");
    let preset_file = dir.path().join("bench.ron");
    photorobot_core::files::save_ron(&preset_file, &preset).expect("the preset saved");
    let bench_arg = preset_file.display().to_string();
    let bench = bench_arg.as_str();
    let traces = dir.path().join("traces");
    let session = dir.path().join("session");
    let s = |v: &str| v.to_string();
    let p = |v: &std::path::Path| v.display().to_string();
    let simulate = [s("photorobot"), s("simulate"), s("--bench"), s(bench), s("--plan"), p(&plan_file)];
    let (ok, text) = cli(&[&simulate[..], &[s("--seed"), bench_seed.to_string(), s("--out"), p(&traces)]].concat());
    assert!(ok, "simulate failed: {text}");
    let calibrate = [s("photorobot"), s("calibrate"), s("--bench"), s(bench), s("--traces"), p(&traces)];
    let (succeeded, text) = cli(&[&calibrate[..], &[s("--out"), p(&session), s("--json")]].concat());
    let mut outcome = PlanOutcome {
        bench: preset.name.clone(),
        family,
        plan_seed,
        bench_seed,
        verdict: String::new(),
        succeeded,
        rms_sigma: f64::NAN,
        observations: 0,
        errors_sigma: vec![],
        wrong: vec![],
        validation_nm: vec![],
        forecast_nm: vec![],
    };
    let Ok(doc) = serde_json::from_str::<Value>(&text) else {
        outcome.verdict = format!("error: {}", text.lines().last().unwrap_or("no output"));
        return outcome;
    };
    outcome.verdict = doc["fit"]["verdict"].as_str().unwrap_or("missing").to_string();
    outcome.rms_sigma = doc["residual_rms_sigma"].as_f64().unwrap_or(f64::NAN);
    for f in doc["validation_forecast"].as_array().into_iter().flatten() {
        let nm = |k: &str| f[k].as_f64().unwrap_or(f64::NAN);
        outcome.forecast_nm.push((f["motion"].as_str().unwrap_or("?").to_string(), nm("expected_nm"), nm("target_nm")));
    }
    outcome.observations = doc["observations"].as_u64().unwrap_or(0) as usize;
    let truth = preset.truth.to_array();
    for (i, (name, _)) in PARAMETER_NAMES.iter().enumerate() {
        let row = doc["parameters"].as_array().and_then(|a| a.iter().find(|r| r["name"] == *name));
        let Some(row) = row else { continue };
        if row["determined"] != true {
            continue;
        }
        let (value, sigma) = (row["value"].as_f64().unwrap_or(f64::NAN), row["sigma"].as_f64().unwrap_or(f64::NAN));
        let e = (value - truth[i]) / sigma;
        outcome.errors_sigma.push((name.to_string(), e));
        // A NaN error (σ missing) counts as wrong too.
        if e.abs() <= 3.0 {
            continue;
        }
        outcome.wrong.push(format!("{name} {value:.5} ± {sigma:.5} (truth {:.5}, {e:+.1}σ)", truth[i]));
    }
    if validate && outcome.verdict == "fits" {
        let identified: Extrinsics = serde_json::from_value(doc["extrinsics"].clone()).expect("the extrinsics");
        let nominal = PhaseModel::of_preset(&preset, Extrinsics::nominal_design()).expect("the nominal model");
        let mut bench = VirtualBench::new(&preset, Some(bench_seed + 1000)).expect("the true bench");
        let analysis = PhaseModel { extrinsics: identified, ..nominal };
        let truth = PhaseModel::of_preset(&preset, preset.truth).expect("the true model");
        for m in ValidationMotion::ALL {
            let figure =
                run_validation(&mut bench, &analysis, &identified, m, [0.0; 6]).map_or(f64::NAN, |f| f.peak_to_peak_nm);
            let true_nm = true_peak_to_peak_nm(&truth, &analysis, &identified, m);
            outcome.validation_nm.push((m.name().to_string(), figure, true_nm));
        }
    }
    outcome
}

/// Peak to peak (nm) of the true cavity length along validation motion `m` as planned with
/// `identified` (its waypoints, and 8 points on each straight joint segment between them): what
/// the calibration leaves on a robot without stage noise, which the fringe figure adds.
fn true_peak_to_peak_nm(
    truth: &PhaseModel,
    planning: &PhaseModel,
    identified: &Extrinsics,
    m: ValidationMotion,
) -> f64 {
    let Ok(w) = waypoints(planning, identified, m, [0.0; 6], m.waypoint_count()) else { return f64::NAN };
    let mut lengths_um = Vec::new();
    for pair in w.windows(2) {
        for k in 0..8 {
            let f = k as f64 / 8.0;
            let q: [f64; 6] = std::array::from_fn(|j| pair[0][j] + f * (pair[1][j] - pair[0][j]));
            lengths_um.push(truth.gap_and_tilt(&q).map_or(f64::NAN, |g| g.0));
        }
    }
    lengths_um.extend(w.last().and_then(|q| truth.gap_and_tilt(q)).map(|g| g.0));
    let (lo, hi) = lengths_um.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| (l.min(*v), h.max(*v)));
    (hi - lo) * 1e3
}

/// One line of a table of outcomes.
pub fn outcome_line(o: &PlanOutcome) -> String {
    let worst = o.errors_sigma.iter().map(|e| e.1.abs()).fold(0.0, f64::max);
    let forecast = |m: &str| o.forecast_nm.iter().find(|f| f.0 == m).map_or(f64::NAN, |f| f.1);
    let validation: Vec<String> = o
        .validation_nm
        .iter()
        .map(|(m, v, t)| format!("{m} {v:.1} (true gap {t:.1}, forecast ≤ {:.1})", forecast(m)))
        .collect();
    format!(
        "{:<12} {:<16} plan {:>3} bench {:>3}  {:<13} {:>7.2}σ  {} determined, worst {:.1}σ{}{}",
        o.bench,
        o.family.name(),
        o.plan_seed,
        o.bench_seed,
        o.verdict,
        o.rms_sigma,
        o.errors_sigma.len(),
        worst,
        if o.wrong.is_empty() { String::new() } else { format!("  WRONG: {}", o.wrong.join("; ")) },
        if validation.is_empty() { String::new() } else { format!("  validation nm: {}", validation.join(", ")) }
    )
}
