//! What the validation tests share: the bench truth's cavity length along a validation motion,
//! `photorobot validate` run as a user runs it, and the extrinsics moved off the truth on purpose.

use photorobot_core::bench::BenchPreset;
use photorobot_core::model::extrinsics::{Extrinsics, PARAMETER_NAMES};
use photorobot_core::model::phase::PhaseModel;
use photorobot_core::validate::{waypoints, ValidationMotion};
use rand::{Rng, SeedableRng};
use serde_json::Value;
use std::path::Path;

/// Points per straight joint segment between two waypoints: the bench moves straight in joint
/// space between them.
const POINTS_PER_SEGMENT: usize = 16;

/// The peak to peak (nm) of the true |L| along `motion` planned with `planned` from q = 0 on
/// `preset` (its truth extrinsics, its robot): what the bench's cavity really did along the
/// joints it was commanded through (a bench without stage noise, play or drift records them).
pub fn true_peak_to_peak_nm(preset: &BenchPreset, planned: &Extrinsics, motion: ValidationMotion) -> f64 {
    let planning = PhaseModel::of_preset(preset, *planned).unwrap();
    let truth = PhaseModel::of_preset(preset, preset.truth).unwrap();
    let w = waypoints(&planning, planned, motion, [0.0; 6], motion.waypoint_count()).unwrap();
    let mut gaps = Vec::new();
    for pair in w.windows(2) {
        for k in 0..POINTS_PER_SEGMENT {
            let f = k as f64 / POINTS_PER_SEGMENT as f64;
            let q: [f64; 6] = std::array::from_fn(|j| pair[0][j] + f * (pair[1][j] - pair[0][j]));
            gaps.push(truth.gap_and_tilt(&q).unwrap().0 * 1e3);
        }
    }
    gaps.iter().copied().fold(f64::NEG_INFINITY, f64::max) - gaps.iter().copied().fold(f64::INFINITY, f64::min)
}

/// `photorobot validate --bench BENCH --extrinsics FILE --seed SEED --json [extra]` with
/// `extrinsics` written to a file in `dir`: its exit code and JSON document.
pub fn run_validate(bench: &str, extrinsics: &Extrinsics, seed: u64, extra: &[&str], dir: &Path) -> (u8, Value) {
    let file = dir.join(format!(
        "extrinsics-{seed}-{:x}.ron",
        extrinsics.to_array().iter().map(|v| v.to_bits()).fold(0u64, |a, b| a.rotate_left(7) ^ b)
    ));
    photorobot_core::files::save_ron(&file, extrinsics).unwrap();
    let seed = seed.to_string();
    let mut argv = vec!["photorobot", "validate", "--bench", bench, "--seed", &seed, "--json", "--extrinsics"];
    let file = file.display().to_string();
    argv.push(&file);
    argv.extend_from_slice(extra);
    let mut out = Vec::new();
    let code = photorobot_app::cli::run(argv, &mut out).map_or_else(|e| e.exit_code(), |_| 0);
    let doc = serde_json::from_slice(&out).unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(&out)));
    (code, doc)
}

/// Index of a parameter in [`PARAMETER_NAMES`].
pub fn parameter(name: &str) -> usize {
    PARAMETER_NAMES.iter().position(|p| p.0 == name).unwrap()
}

/// The acceptance's perturbations of Table II: β_et, θ_et, β_wf, θ_wf by 0.01°, 0.1° and 1°,
/// x_wf and z_wf by 1 µm and 10 µm (name, shift in the parameter's unit, the extrinsics).
pub fn perturbations(truth: &Extrinsics) -> Vec<(&'static str, f64, Extrinsics)> {
    let mut out = Vec::new();
    for (name, shifts) in [
        ("beta_et", &[0.01, 0.1, 1.0][..]),
        ("theta_et", &[0.01, 0.1, 1.0]),
        ("beta_wf", &[0.01, 0.1, 1.0]),
        ("theta_wf", &[0.01, 0.1, 1.0]),
        ("x_wf", &[1.0, 10.0]),
        ("z_wf", &[1.0, 10.0]),
    ] {
        for &d in shifts {
            let mut a = truth.to_array();
            a[parameter(name)] += d;
            out.push((name, d, Extrinsics::from_array(a)));
        }
    }
    out
}

/// Random extrinsics off the truth: every angle by up to ±0.5°, x_wf and z_wf by up to ±10 µm,
/// y_wf and Z_et by up to ±10 µm (log-uniform sizes from 0.001° and 0.1 µm, random signs).
pub fn random_perturbation(truth: &Extrinsics, seed: u64) -> Extrinsics {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let mut a = truth.to_array();
    for (i, (_, unit)) in PARAMETER_NAMES.iter().enumerate() {
        let (lo, hi): (f64, f64) = if *unit == "°" { (1e-3, 0.5) } else { (0.1, 10.0) };
        let size = (lo.ln() + rng.random::<f64>() * (hi.ln() - lo.ln())).exp();
        a[i] += if rng.random::<bool>() { size } else { -size };
    }
    Extrinsics::from_array(a)
}

/// One motion of a `validate` document: its name, the figure, the verdict and whether it is
/// within target.
pub fn motions(doc: &Value) -> Vec<(String, f64, String, bool)> {
    doc["validation"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| {
            (
                m["motion"].as_str().unwrap().to_string(),
                m["measured_nm"].as_f64().unwrap_or(f64::NAN),
                m["verdict"].as_str().unwrap_or("failed").to_string(),
                m["within_target"].as_bool().unwrap_or(false),
            )
        })
        .collect()
}

/// Each motion of `doc` against the truth along it (planned with `e` on table2-ideal), printed:
/// any figure at least 90 % of it (less 2 nm) unless contradicted; with `strict`, a confirmed
/// figure within 10 % (or 2 nm) of it; within target only when the truth is (with the same
/// slack). Returns what fails.
pub fn check_against_truth(name: &str, e: &Extrinsics, doc: &Value, strict: bool) -> Vec<String> {
    let preset = BenchPreset::resolve("table2-ideal").unwrap();
    let mut failures = Vec::new();
    for (m, (motion, measured, verdict, within)) in ValidationMotion::ALL.iter().zip(motions(doc)) {
        let truth = true_peak_to_peak_nm(&preset, e, *m);
        let slack = (0.1 * truth).max(2.0);
        let row = doc["validation"].as_array().and_then(|v| v.iter().find(|r| r["motion"] == motion.as_str()));
        let tilt = row.map_or(String::new(), |r| {
            let t = r["checks"].as_array().and_then(|c| c.iter().find(|c| c["name"] == "tilt term"));
            format!(" [tilt σ {} nm; {}]", r["tilt_sigma_nm"], t.map_or("-".into(), |t| t["detail"].to_string()))
        });
        let line = format!("{name}: {motion}: true {truth:.1} nm, reported {measured:.1} nm, {verdict}");
        let shape = row
            .and_then(|r| {
                r["checks"].as_array()?.iter().find(|c| c["name"] == "fringe shape").map(|c| c["detail"].to_string())
            })
            .unwrap_or_default();
        eprintln!("{line}{tilt} {shape}");
        assert_eq!(motion, m.name(), "the motions in order");
        let confirmed_off = strict && verdict == "confirmed" && (measured - truth).abs() > slack;
        let under = verdict != "contradicted" && measured < truth - slack;
        let wrongly_within = within && truth > m.target_nm() + slack;
        if confirmed_off || under || wrongly_within {
            failures.push(line);
        }
    }
    failures
}
