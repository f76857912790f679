//! The log of a bench on the stage-controller emulators, written through the app's rotating log
//! file as `photorobot.log` in a session folder: at debug level the commands that change a
//! controller's state and one summary per recording (its rows, reads, bytes and timing), not the
//! recorder's rows; every command and reply only at trace level; a lost connection as a warning.

use photorobot_app::log::{RotatingFile, LOG_FILE};
use photorobot_core::bench::{run_plan, BenchPreset, RunControl};
use photorobot_core::hardware::emulator::local::LocalEmulators;
use photorobot_core::hardware::{ControllerBench, HardwareConfig};
use photorobot_core::plan::{JointTarget, Plan, Segment};
use std::sync::atomic::AtomicBool;
use std::sync::Mutex;

/// Run a short recorded jog on the emulators with the log at `level`, then lose the connection;
/// the log's text.
fn jog_log(level: tracing::Level) -> String {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(LOG_FILE);
    let file = RotatingFile::open(&path, 10 << 20, 3).unwrap();
    let subscriber =
        tracing_subscriber::fmt().with_max_level(level).with_ansi(false).with_writer(Mutex::new(file)).finish();
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
                through: false,
            }],
        };
        let cancel = AtomicBool::new(false);
        let mut control = RunControl { cancel: &cancel, on_samples: &mut |_, _| {}, on_progress: &mut |_| {} };
        run_plan(&mut bench, &plan, &mut control).outcome.unwrap();
        // The emulators stop: the next poll finds the connections lost.
        drop(emu);
        let _ = bench.axis_status();
    });
    std::fs::read_to_string(&path).unwrap()
}

#[test]
fn the_log_summarises_each_recording_and_keeps_the_rows_for_trace_level() {
    let log = jog_log(tracing::Level::DEBUG);
    let lines = |needle: &str| log.lines().filter(|l| l.contains(needle)).count();
    assert!(log.contains("PI E-712") && log.contains("SmarAct MCS"), "each line names its controller");
    assert!(lines("MOV ") > 0 && lines("VCO ") > 0 && lines(":MAA") > 0, "the commands that change state:\n{log}");
    let summary: Vec<&str> = log.lines().filter(|l| l.contains("recording:")).collect();
    assert_eq!(summary.len(), 1, "one summary for the one recording:\n{log}");
    for want in ["label=jog", "rows=", "recorder_reads=", "PI E-712:", "commands", "B in", "polls_kept="] {
        assert!(summary[0].contains(want), "`{want}` in {}", summary[0]);
    }
    assert_eq!(lines("< "), 0, "no reply rows at debug level:\n{log}");
    assert_eq!(lines("END_HEADER"), 0, "no recorder rows at debug level");
    assert!(log.len() < 20_000, "a short jog's debug log is short: {} bytes", log.len());
    assert!(log.contains("connected"), "the connection itself");
    assert!(
        log.lines().any(|l| l.contains("WARN") && (l.contains("no reply") || l.contains("send failed"))),
        "a lost connection is a warning:\n{}",
        log.lines().rev().take(10).collect::<Vec<_>>().join("\n")
    );
    // At trace level every command and reply is there, the recorder's rows with them.
    let trace = jog_log(tracing::Level::TRACE);
    assert!(trace.lines().filter(|l| l.contains("> POS?")).count() > 0, "commands at trace level");
    assert!(trace.lines().filter(|l| l.contains("< # END_HEADER")).count() > 0, "recorder rows at trace level");
    assert!(trace.len() > 10 * log.len(), "{} vs {} bytes", trace.len(), log.len());
}
