//! Null diagnoses through the path users run: `photorobot calibrate` on a bench that hides
//! nothing (table2-ideal, and femto-lab with its hidden effects switched off but its noise,
//! air and detector kept), then `photorobot diagnose <session> --json`. On every seed
//! the verdict is `none`, nothing is named, and the residual before and after is one figure (the
//! same analysis of the same traces). The calibration runs the experiment design's plan
//! (`--plan optimised`, 26 s of bench time) so that eight seeds stay within the suite's budget.

use photorobot_app::cli::{run, CliError};
use photorobot_core::bench::BenchPreset;
use photorobot_core::files::save_ron;
use serde_json::Value;

/// `calibrate --bench BENCH --seed SEED --plan optimised --out DIR`, then
/// `diagnose DIR [--bench BENCH] --json` (a bench file is named again: the traces name the preset).
fn calibrate_then_diagnose(bench: &str, seed: u64, bench_file: bool) -> Value {
    let t0 = std::time::Instant::now();
    let dir = tempfile::tempdir().unwrap();
    let session = dir.path().join("session");
    let seed = seed.to_string();
    let argv = [
        "photorobot",
        "calibrate",
        "--bench",
        bench,
        "--seed",
        &seed,
        "--plan",
        "optimised",
        "--json",
        "--out",
        session.to_str().unwrap(),
    ];
    let mut out = Vec::new();
    // A validation beyond its targets refuses the calibration but writes its session, which is
    // where a diagnosis starts (femto-lab's noise alone puts its circle at 30-40 nm).
    if let Err(e) = run(argv, &mut out) {
        let refused_by_validation = matches!(&e, CliError::NotACalibration { problem, .. }
            if problem.starts_with("its validation does not prove it"));
        assert!(refused_by_validation, "calibrate {bench} seed {seed}: {e}");
    }
    let mut out = Vec::new();
    let mut argv = vec!["photorobot", "diagnose", session.to_str().unwrap(), "--json"];
    if bench_file {
        argv.extend(["--bench", bench]);
    }
    run(argv, &mut out).unwrap_or_else(|e| panic!("diagnose {bench} seed {seed}: {e}"));
    let v: Value = serde_json::from_slice(&out).unwrap();
    eprintln!(
        "{bench} seed {seed}: verdict {}, residual {} → {} σ, effects {}, {:.1} s",
        v["verdict"],
        v["residual_rms_before_sigma"],
        v["residual_rms_after_sigma"],
        v["effects"],
        t0.elapsed().as_secs_f64()
    );
    v
}

fn assert_null(v: &Value, what: &str) {
    assert_eq!(v["verdict"], "none", "{what}: {}", v["steps"]);
    assert_eq!(v["effects"].as_array().map(Vec::len), Some(0), "{what}: {}", v["effects"]);
    assert_eq!(v["residual_rms_before_nm"], v["residual_rms_after_nm"], "{what}");
}

fn table2(seed: u64) {
    let v = calibrate_then_diagnose("table2-ideal", seed, false);
    assert_null(&v, &format!("table2-ideal seed {seed}"));
}

/// femto-lab with `effects: []`, saved as the bench file both commands read.
fn femto_lab_without_effects(seed: u64) {
    let mut preset = BenchPreset::resolve("femto-lab").unwrap();
    preset.name = "femto-lab without hidden effects".into();
    preset.effects.clear();
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("femto-lab-null.ron");
    save_ron(&file, &preset).unwrap();
    let v = calibrate_then_diagnose(file.to_str().unwrap(), seed, true);
    assert_null(&v, &format!("femto-lab without effects, seed {seed}"));
}

#[test]
fn table2_ideal_seed_1_names_nothing() {
    table2(1);
}

#[test]
fn table2_ideal_seed_2_names_nothing() {
    table2(2);
}

#[test]
fn table2_ideal_seed_3_names_nothing() {
    table2(3);
}

#[test]
fn table2_ideal_seed_4_names_nothing() {
    table2(4);
}

#[test]
fn table2_ideal_seed_5_names_nothing() {
    table2(5);
}

#[test]
fn femto_lab_without_effects_seed_1_names_nothing() {
    femto_lab_without_effects(1);
}

#[test]
fn femto_lab_without_effects_seed_2_names_nothing() {
    femto_lab_without_effects(2);
}

#[test]
fn femto_lab_without_effects_seed_3_names_nothing() {
    femto_lab_without_effects(3);
}
