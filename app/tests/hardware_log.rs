//! The log of a bench on the stage-controller emulators: every command sent and reply received
//! at debug level, with its controller, and a lost connection as a warning, written through the
//! app's rotating log file as `photorobot.log` in a session folder.

use photorobot_app::log::{RotatingFile, LOG_FILE};
use photorobot_core::bench::{run_plan, BenchPreset, RunControl};
use photorobot_core::hardware::emulator::local::LocalEmulators;
use photorobot_core::hardware::{ControllerBench, HardwareConfig};
use photorobot_core::plan::{JointTarget, Plan, Segment};
use std::sync::atomic::AtomicBool;
use std::sync::Mutex;

#[test]
fn the_log_has_the_controllers_transcript_and_their_failures() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(LOG_FILE);
    let file = RotatingFile::open(&path, 10 << 20, 3).unwrap();
    let subscriber = tracing_subscriber::fmt()
        .with_max_level(tracing::Level::DEBUG)
        .with_ansi(false)
        .with_writer(Mutex::new(file))
        .finish();
    tracing::subscriber::with_default(subscriber, || {
        let preset = BenchPreset::resolve("table2-ideal").unwrap();
        let robot = preset.robot_description().unwrap();
        let config = HardwareConfig::femto();
        let emu = LocalEmulators::start(&preset, 7, &robot, &config, 0, 0).unwrap();
        let addresses = emu.addresses();
        let config = config.with_addresses(&[
            (addresses[0].0.as_str(), addresses[0].1.clone()),
            (addresses[1].0.as_str(), addresses[1].1.clone()),
        ]);
        let mut bench =
            ControllerBench::connect(robot, config, preset.motion, preset.ambient, emu.laser(), emu.clock()).unwrap();
        let plan = Plan {
            name: "jog".into(),
            description: String::new(),
            segments: vec![Segment::Move {
                to: JointTarget::all([10.0, 0.0, 0.0, 0.0, 0.0, 0.5]),
                record: true,
                label: "jog".into(),
            }],
        };
        let cancel = AtomicBool::new(false);
        let mut control = RunControl { cancel: &cancel, on_samples: &mut |_, _| {}, on_progress: &mut |_| {} };
        run_plan(&mut bench, &plan, &mut control).outcome.unwrap();
        // The emulators stop: the next poll finds the connections lost.
        drop(emu);
        let _ = bench.axis_status();
    });
    let log = std::fs::read_to_string(&path).unwrap();
    let lines = |needle: &str| log.lines().filter(|l| l.contains(needle)).count();
    assert!(lines("DEBUG") > 20, "a command and reply per line at debug level:\n{log}");
    assert!(log.contains("PI E-712") && log.contains("SmarAct MCS"), "each line names its controller");
    assert!(lines("> POS?") > 0 && lines("< ") > 0, "commands sent and replies received:\n{log}");
    assert!(lines("> *IDN?") > 0, "the PI identification query");
    assert!(log.contains("connected"), "the connection itself");
    assert!(
        log.lines().any(|l| l.contains("WARN") && (l.contains("no reply") || l.contains("send failed"))),
        "a lost connection is a warning:\n{}",
        log.lines().rev().take(10).collect::<Vec<_>>().join("\n")
    );
}
