//! Recordings from a simulator that shares no code with the core (`independent.rs`: its own
//! kinematics, optics, motions, detector and clock), calibrated through the path users run:
//! `photorobot calibrate --bench table2-ideal --traces DIR --json`. The truth is Table II.

use photorobot_app::cli::run;
use photorobot_core::bench::BenchPreset;
use photorobot_core::model::extrinsics::Extrinsics;
use photorobot_core::model::phase::PhaseModel;
use photorobot_core::validate::{waypoints, ValidationMotion};
use photorobot_e2e::independent::{cavity, lab_records, Profile, Recorder, TABLE2};
use serde_json::Value;

/// Calibrate `recorder`'s recordings of the lab motions; returns the JSON report.
fn calibrate(recorder: &Recorder) -> Value {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let traces = dir.path().join("traces");
    let (samples, _) = recorder.write_folder(&lab_records(), &traces).expect("the traces written");
    assert!(samples > 100_000, "{samples} samples");
    let args = ["photorobot", "calibrate", "--bench", "table2-ideal", "--traces"].map(String::from);
    let rest =
        [traces.display().to_string(), "--out".into(), dir.path().join("s").display().to_string(), "--json".into()];
    let mut out = Vec::new();
    let result = run(args.into_iter().chain(rest), &mut out);
    let text = String::from_utf8_lossy(&out).into_owned();
    assert!(result.is_ok(), "calibrate failed: {text}");
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{e}: {text}"))
}

/// Every determined parameter within 2.5σ of Table II (the docs state 2.3σ at worst), the fit
/// accepted with a residual of 0.05-0.2σ rms (stated: 0.09-0.14σ); returns the names of the
/// determined parameters.
fn assert_right(doc: &Value, seed: u64) -> Vec<String> {
    let verdict = doc["fit"]["verdict"].as_str().unwrap_or("missing");
    let rms = doc["residual_rms_sigma"].as_f64().unwrap_or(f64::NAN);
    eprintln!("seed {seed}: verdict {verdict}, residual {rms:.2}σ");
    let (mut determined, mut wrong) = (Vec::new(), Vec::new());
    for (name, truth) in TABLE2.report_order() {
        let row = doc["parameters"].as_array().and_then(|a| a.iter().find(|r| r["name"] == name)).expect("a row");
        let (value, sigma) = (row["value"].as_f64().unwrap_or(f64::NAN), row["sigma"].as_f64().unwrap_or(f64::NAN));
        let e = (value - truth) / sigma;
        eprintln!("  {name}: {value:.5} ± {sigma:.5} (truth {truth}, {e:+.2}σ) determined {}", row["determined"]);
        if row["determined"] != true {
            continue;
        }
        determined.push(name.to_string());
        if e.abs() > 2.5 {
            wrong.push(format!("{name} {value} ± {sigma} ({e:+.1}σ from {truth})"));
        }
    }
    assert!(wrong.is_empty(), "seed {seed}: determined and wrong: {wrong:?}");
    assert_eq!(verdict, "fits", "seed {seed}");
    assert!((0.05..=0.2).contains(&rms), "seed {seed}: residual {rms}σ, the docs state 0.09-0.14σ");
    determined
}

/// The validation motions planned with the report's extrinsics (through the product's inverse
/// model), run on the independent simulator's geometry: the true gap's peak to peak (nm) along
/// the waypoints and 8 points on each straight joint segment between them, with the report's
/// forecast and target for it.
fn validation_on_the_truth(doc: &Value) -> Vec<(String, f64, f64, f64)> {
    let identified: Extrinsics = serde_json::from_value(doc["extrinsics"].clone()).expect("the extrinsics");
    let preset = BenchPreset::resolve("table2-ideal").expect("the preset");
    let planning = PhaseModel::of_preset(&preset, identified).expect("the planning model");
    let mut rows = Vec::new();
    for m in ValidationMotion::ALL {
        let w = waypoints(&planning, &identified, m, [0.0; 6], m.waypoint_count()).expect("the motion planned");
        let mut gaps_um: Vec<f64> = w
            .windows(2)
            .flat_map(|p| (0..8).map(move |k| std::array::from_fn(|j| p[0][j] + k as f64 / 8.0 * (p[1][j] - p[0][j]))))
            .map(|q| cavity(&TABLE2, q).0)
            .collect();
        gaps_um.push(cavity(&TABLE2, *w.last().expect("waypoints")).0);
        let (lo, hi) = gaps_um.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| (l.min(*v), h.max(*v)));
        let forecast = doc["validation_forecast"].as_array().and_then(|a| a.iter().find(|f| f["motion"] == m.name()));
        let nm = |k: &str| forecast.and_then(|f| f[k].as_f64()).unwrap_or(f64::NAN);
        rows.push((m.name().to_string(), (hi - lo) * 1e3, nm("expected_nm"), nm("target_nm")));
    }
    rows
}

/// Three seeds of the lab motions: one as recorded, one with a dark offset on the photodiode and
/// twice the noise, one with smooth (raised-cosine) starts and stops. Table II recovered within
/// 2.5σ in every parameter the data determine, the lamella normal and the beam's hit point among
/// them; the validation motions planned with the result keep the true gap within their targets
/// (10 nm circle, 20 nm rotations), as the report forecasts, and within twice what the docs
/// state (0.11 nm on the circle, 2.2 nm on the rotations).
#[test]
fn independent_recordings_calibrate_to_table_two() {
    let mut offset = Recorder::new(12);
    offset.offset_v = 0.3;
    offset.noise_rel_fringe = 2e-3;
    let mut smooth = Recorder::new(13);
    smooth.profile = Profile::RaisedCosine;
    for (seed, recorder) in [(11, Recorder::new(11)), (12, offset), (13, smooth)] {
        let doc = calibrate(&recorder);
        let determined = assert_right(&doc, seed);
        for name in ["beta_et", "theta_et", "x_wf", "z_wf"] {
            let found = determined.iter().any(|d| d == name);
            assert!(found, "seed {seed}: {name} not determined: {determined:?}");
        }
        for (motion, true_nm, forecast_nm, target_nm) in validation_on_the_truth(&doc) {
            eprintln!("  {motion}: true gap {true_nm:.2} nm, forecast ≤ {forecast_nm:.1} nm, target {target_nm} nm");
            assert!(forecast_nm <= target_nm, "seed {seed}: {motion} not promised: {forecast_nm} nm");
            assert!(true_nm <= target_nm, "seed {seed}: {motion} moves the true gap by {true_nm} nm");
            let stated = if motion.starts_with("circle") { 0.11 } else { 2.2 };
            assert!(true_nm <= 2.0 * stated, "seed {seed}: {motion}: true gap {true_nm} nm, the docs state ≤ {stated}");
        }
    }
}
