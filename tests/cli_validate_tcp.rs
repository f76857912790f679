//! `photorobot validate` through TCP on the emulated stage controllers and laser: its own test
//! binary, so that no other test loads the two cores while the emulators keep time.

use photorobot_core::bench::BenchPreset;
use photorobot_core::validate::ValidationMotion;
use photorobot_e2e::validation::{check_against_truth, motions, run_validate};

/// Through TCP, on the emulated stage controllers and laser serving table2-ideal's optics:
/// `photorobot validate --bench <hardware bench file>` with the true extrinsics and with β_wf 1°
/// off (the lamella placed by a wrong calibration): never a figure under 90 % of the true gap
/// change unless contradicted, and the wrong calibration refused (exit 1).
#[test]
fn wrong_extrinsics_are_caught_on_emulated_controllers() {
    use photorobot_core::hardware::emulator::EmulatedHardware;
    use photorobot_core::hardware::HardwareConfig;
    let dir = tempfile::tempdir().unwrap();
    let preset = BenchPreset::resolve("table2-ideal").unwrap();
    let emulated =
        EmulatedHardware::start(&preset, 17, HardwareConfig { time_scale: 2.0, ..HardwareConfig::femto() }).unwrap();
    let file = dir.path().join("bench.ron");
    photorobot_core::files::save_ron(&file, &emulated.config).unwrap();
    let bench = file.display().to_string();

    let (code, doc) = run_validate(&bench, &preset.truth, 17, &[], dir.path());
    assert_eq!(check_against_truth("truth over TCP", &preset.truth, &doc, false), Vec::<String>::new());
    // The circle and the rotation about the beam confirmed within target. The rotations about
    // X_f and Z_f track within 1-9 nm over TCP, their curve 0.7-1.0 nm about a smooth path in the
    // angle now that the wrist's polled joints are fitted ramps (interpolated between late polls
    // they left 3-5 nm and were contradicted in most runs). Their model-free reading sits at its
    // floor (77-80 nm under the tracked gap on the virtual bench, floor 84 nm), a few nm above it
    // in some runs over TCP: then contradicted, so they are not asserted here.
    let rows = motions(&doc);
    for m in [ValidationMotion::Circle, ValidationMotion::RotationOpticalAxis] {
        let row = rows.iter().find(|r| r.0 == m.name()).unwrap();
        assert!(row.3, "{} confirmed within target over TCP with the true extrinsics: {row:?}", m.name());
    }
    eprintln!("true extrinsics over TCP: exit {code}");

    let mut wrong = preset.truth.to_array();
    wrong[photorobot_e2e::validation::parameter("beta_wf")] += 1.0;
    let wrong = photorobot_core::model::extrinsics::Extrinsics::from_array(wrong);
    let (code, doc) = run_validate(&bench, &wrong, 17, &[], dir.path());
    assert_eq!(check_against_truth("beta_wf +1° over TCP", &wrong, &doc, false), Vec::<String>::new());
    assert_eq!(code, 1, "a wrong calibration passed over TCP: {doc}");
}
