//! `photorobot calibrate` with sweeps measured but whose analysis is refused: the report lists
//! what losing them costs (the parameters they would determine, the signs they would fix), those
//! parameters are not reported as determined, and the run is refused as an incomplete
//! calibration (exit 1), not printed as one that fits.

use serde_json::Value;
use std::process::Command;

#[test]
fn lost_sweeps_leave_an_incomplete_calibration_not_one_that_fits() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("session");
    let plan = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/optimised-two-sweeps-lost.ron");
    let run = Command::new(env!("CARGO_BIN_EXE_photorobot"))
        .args([
            "calibrate",
            "--bench",
            "table2-ideal",
            "--seed",
            "7",
            "--plan",
            plan,
            "--no-validation",
            "--json",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr);
    let report: Value = serde_json::from_slice(&run.stdout).unwrap_or_else(|e| panic!("{e}: {stderr}"));
    let cost = &report["sweep_cost"];
    let lost: Vec<&str> = cost["lost"].as_array().unwrap().iter().map(|l| l["label"].as_str().unwrap()).collect();
    assert_eq!(lost.len(), 2, "both short sweeps are lost: {lost:?}");
    assert!(lost.iter().all(|l| l.starts_with("too short a sweep")), "{lost:?}");
    let undetermined: Vec<&str> =
        cost["undetermined"].as_array().unwrap().iter().map(|p| p["name"].as_str().unwrap()).collect();
    eprintln!("lost sweeps cost: {}\n{stderr}", cost);
    assert!(
        !undetermined.is_empty() || !cost["unsigned"].as_array().unwrap().is_empty(),
        "losing them costs something: {cost}"
    );
    for name in &undetermined {
        let p = report["parameters"].as_array().unwrap().iter().find(|p| p["name"] == *name).unwrap();
        assert_eq!(p["determined"], false, "{name} is not reported as determined");
        assert!(p["reason"].as_str().unwrap().contains("its sweeps were lost"), "{p}");
    }
    assert_eq!(run.status.code(), Some(1), "refused as a calibration:\n{stderr}");
    assert!(
        stderr.contains("the calibration is incomplete") && stderr.contains("measured but not analysed"),
        "{stderr}"
    );
}
