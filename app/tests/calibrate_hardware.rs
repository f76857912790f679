//! `photorobot calibrate --bench <hardware bench file>` end to end: the stage-controller and laser
//! emulators served in this process on free loopback ports, a hardware bench file pointing at them,
//! and the built binary measuring a short plan (a laser sweep and three small moves) on them,
//! identifying, validating and writing a session that loads.

use photorobot_core::bench::BenchPreset;
use photorobot_core::hardware::controller_bench::{LaserConfig, LaserFamily};
use photorobot_core::hardware::emulator::{LaserEmulator, LaserEmulatorConfig, LocalEmulators};
use photorobot_core::hardware::HardwareConfig;
use photorobot_core::session::Session;
use std::process::Command;

#[test]
fn calibrate_runs_a_plan_on_the_controllers_and_the_laser_of_a_hardware_bench_file() {
    let preset = BenchPreset::resolve("table2-ideal").unwrap();
    let robot = preset.robot_description().unwrap();
    let config = HardwareConfig::femto();
    let emus = LocalEmulators::start(&preset, 5, &robot, &config, 0, 0).unwrap();
    let laser = LaserEmulator::start_on(0, emus.emu_laser(), LaserEmulatorConfig::new(LaserFamily::Keysight)).unwrap();
    let a = emus.addresses();
    let mut config = config.with_addresses(&[(a[0].0.as_str(), a[0].1.clone()), (a[1].0.as_str(), a[1].1.clone())]);
    config.laser =
        Some(LaserConfig { family: LaserFamily::Keysight, address: laser.addr().to_string(), timeout_s: 2.0 });
    let dir = tempfile::tempdir().unwrap();
    let bench_file = dir.path().join("bench.ron");
    std::fs::write(&bench_file, ron::ser::to_string_pretty(&config, Default::default()).unwrap()).unwrap();
    let out = dir.path().join("session");
    let plan = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/short-hardware-plan.ron");
    let run = Command::new(env!("CARGO_BIN_EXE_photorobot"))
        .args(["calibrate", "--bench"])
        .arg(&bench_file)
        .args(["--model", "table2-ideal", "--plan", plan, "--out"])
        .arg(&out)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&run.stdout);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "calibrate failed:\n{stdout}\n{stderr}");
    assert!(stdout.contains("validation (FP cavity variation"), "the validation motions ran on the bench:\n{stdout}");

    let session = Session::load(&out).unwrap();
    assert!(session.bench.name.starts_with("femto-hardware (PI E-712 at 127.0.0.1:"), "{}", session.bench.name);
    let ids: Vec<&str> = session.lab.controllers.iter().map(|c| c.identification.as_str()).collect();
    assert!(ids.iter().any(|i| i.contains("E-712 (emulated)")), "{ids:?}");
    assert!(ids.iter().any(|i| i.contains("8164B (emulated)")), "the laser's *IDN? is in the lab record: {ids:?}");
    let traces = session.load_traces(&out).unwrap();
    assert_eq!(traces.len(), 4, "the sweep and the three recorded moves");
    assert!(session.calibration.is_some(), "the calibration is in the session");
    // The sweep's wavelengths come from the laser the driver swept: 1550 -> 1551 nm.
    let sweep = &traces[0];
    let (lo, hi) =
        sweep.wavelength_nm.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |m, &w| (m.0.min(w), m.1.max(w)));
    assert!((lo - 1550.0).abs() < 0.05 && (hi - 1551.0).abs() < 0.05, "sweep {lo}..{hi} nm");
    // The moves' wavelength is the resting one.
    assert!(traces[1].wavelength_nm.iter().all(|w| (w - preset.laser.wavelength_nm).abs() < 1e-6));
}
