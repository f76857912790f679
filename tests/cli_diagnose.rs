//! End to end: a session recorded on the virtual bench with a hidden pivot offset
//! (assets/benches/hidden-pivot.ron), then `photorobot diagnose <session> --json`: the workflow runs
//! its discriminating motions on that bench and names the hidden effect from the traces.

use photorobot_core::bench::{run_plan, BenchPreset, RunControl, VirtualBench};
use photorobot_core::files::save_ron;
use photorobot_core::plan::{JointTarget, Plan, Segment};
use std::sync::atomic::AtomicBool;

fn mv(to: [f64; 6], record: bool, label: &str) -> Segment {
    Segment::Move { to: JointTarget::all(to), record, label: label.into() }
}

/// A short calibration-like session: absolute gaps at three poses, X and Z translations, q4 and
/// q5 rotations of ±4° (the paper's kinds of motion, on which the pivot offset is absorbed).
fn session_plan() -> Plan {
    let mut s = Vec::new();
    for (k, at) in [[0.0; 6], [0.0, -100.0, 0.0, 0.0, 0.0, 0.0], [120.0, 0.0, -120.0, 0.0, 0.0, 0.0]].iter().enumerate()
    {
        s.push(mv(*at, false, "setup"));
        s.push(Segment::Sweep { from_nm: 1540.0, to_nm: 1580.0, rate_nm_per_s: 10.0, label: format!("sweep {k}") });
    }
    for lateral in [-100.0, 100.0] {
        s.push(mv([lateral, 0.0, -150.0, 0.0, 0.0, 0.0], false, "setup"));
        s.push(mv([lateral, 0.0, 150.0, 0.0, 0.0, 0.0], true, &format!("X at q1 = {lateral}")));
        s.push(mv([-150.0, 0.0, lateral, 0.0, 0.0, 0.0], false, "setup"));
        s.push(mv([150.0, 0.0, lateral, 0.0, 0.0, 0.0], true, &format!("Z at q3 = {lateral}")));
    }
    for other in [-2.0, 0.0, 2.0] {
        s.push(mv([0.0, 0.0, 0.0, -4.0, other, 0.0], false, "setup"));
        s.push(mv([0.0, 0.0, 0.0, 4.0, other, 0.0], true, &format!("q4 at q5 = {other}")));
        s.push(mv([0.0, 0.0, 0.0, other, -4.0, 0.0], false, "setup"));
        s.push(mv([0.0, 0.0, 0.0, other, 4.0, 0.0], true, &format!("q5 at q4 = {other}")));
    }
    Plan { name: "diagnose e2e".into(), description: String::new(), segments: s }
}

#[test]
fn diagnose_names_the_hidden_pivot_from_virtual_bench_traces() {
    let t0 = std::time::Instant::now();
    let preset = BenchPreset::resolve("hidden-pivot").unwrap();
    let mut bench = VirtualBench::new(&preset, Some(5)).unwrap();
    let cancel = AtomicBool::new(false);
    let mut control = RunControl { cancel: &cancel, on_samples: &mut |_, _| {}, on_progress: &mut |_| {} };
    let run = run_plan(&mut bench, &session_plan(), &mut control);
    run.outcome.unwrap();
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir_all(dir.path().join("traces")).unwrap();
    for (i, t) in run.traces.iter().enumerate() {
        t.write_csv(&dir.path().join("traces").join(format!("{i:03}.csv"))).unwrap();
    }
    // The calibrated extrinsics: the truth (the workflow refits them in its baseline).
    save_ron(&dir.path().join("extrinsics.ron"), &preset.truth).unwrap();
    let mut out = Vec::new();
    let args = ["photorobot", "diagnose", dir.path().to_str().unwrap(), "--json"];
    photorobot_app::cli::run(args, &mut out).unwrap();
    let v: serde_json::Value = serde_json::from_slice(&out).unwrap();
    if let Ok(p) = std::env::var("DIAGNOSE_DUMP") {
        std::fs::write(p, &out).unwrap();
    }
    eprintln!(
        "verdict {}, rms {} → {} nm ({} → {} σ), {:.1} s",
        v["verdict"],
        v["residual_rms_before_nm"],
        v["residual_rms_after_nm"],
        v["residual_rms_before_sigma"],
        v["residual_rms_after_sigma"],
        t0.elapsed().as_secs_f64()
    );
    assert_eq!(v["discriminating_motions_ran"], true);
    // The first effect added: the joint-4 pivot along Z_w or one of its equivalents (a pivot of
    // joint 6 along Z_w or X_w, or of joint 5 along X_w, with the beam shifted), of its size.
    let added: Vec<&serde_json::Value> = v["steps"].as_array().unwrap().iter().filter_map(|s| s.get("Added")).collect();
    let first = &added.first().expect("an effect added")["effect"];
    let name = first["name"].as_str().unwrap();
    let class = [
        "pivot offset q4 along Z_w",
        "pivot offset q6 along Z_w",
        "pivot offset q5 along X_w",
        "pivot offset q6 along X_w",
    ];
    assert!(class.contains(&name), "{name}");
    let est = first["estimate"].as_f64().unwrap();
    assert!((est.abs() - 20.0).abs() < 5.0, "{name} = {est} µm");
    // The residual falls by more than a factor of 5 (the verdict itself is not asserted: the
    // absolute gaps of the virtual bench's sweeps keep a few-σ residual that the model lacks;
    // see the report of issue 6).
    let (before, after) = (v["residual_rms_before_nm"].as_f64().unwrap(), v["residual_rms_after_nm"].as_f64().unwrap());
    assert!(after * 5.0 < before, "{before} → {after} nm");
    // The extended model in use: the validation motions planned through the IGM with the effect
    // leave the cavity nearly unchanged where the model without it does not (the hidden pivot
    // moves P_r along the beam by about 20 µm × 3° in the 6° rotations).
    let rows = v["validation"].as_array().expect("validation rows");
    assert_eq!(rows.len(), 4, "{rows:?}");
    for r in rows {
        let (without, with) = (r["without_effect_nm"].as_f64().unwrap(), r["with_effect_nm"].as_f64().unwrap());
        eprintln!("{}: {without:.1} nm without the effect, {with:.1} nm with it", r["motion"]);
        if r["motion"].as_str().unwrap().starts_with("rotation 6°") {
            // Measured (seed 5, 2026-11-24): with the hidden q4 pivot named, 3036 → 19.9 nm about
            // X_f and 3694 → 26.2 nm about Z_f; with its equivalent, the q6 pivot along Z_w,
            // 2830 → 18.1 and 3642 → 32.2 nm. More than 50× either way, a few tens of nm left.
            assert!(with * 50.0 < without && with < 40.0, "{}: {without} → {with} nm", r["motion"]);
        } else {
            assert!(with <= without.max(50.0), "{}: {without} → {with} nm", r["motion"]);
        }
    }
}

#[test]
fn diagnose_on_a_folder_without_traces_says_what_it_expected() {
    let dir = tempfile::tempdir().unwrap();
    let mut out = Vec::new();
    let err = photorobot_app::cli::run(["photorobot", "diagnose", dir.path().to_str().unwrap()], &mut out).unwrap_err();
    let msg = err.to_string();
    assert!(msg.contains("traces") && msg.contains("photorobot calibrate"), "{msg}");
}
