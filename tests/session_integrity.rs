//! A session folder survives the worst a bench PC does to it: the process killed (SIGKILL) at
//! random moments while it records, saves and redoes steps leaves a folder whose `session.ron`
//! and autosave load with every trace passing its CRC check; and a folder being written by one
//! photorobot is refused to a second one with the reason.

use photorobot_app::cli::run;
use photorobot_core::bench::{BenchPreset, RunControl, VirtualBench};
use photorobot_core::plan::Plan;
use photorobot_core::session::recording::record;
use photorobot_core::session::{autosave_path, session_path, BenchInfo, FolderLock, Session, SessionWriter};
use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

/// The folder the child process records into (set only for the child).
const CHILD_DIR: &str = "PHOTOROBOT_TEST_RECORDING_CHILD_DIR";

/// A new session of the short test plan.
fn new_session() -> Session {
    let preset = BenchPreset::resolve("table2-ideal").unwrap();
    let info = BenchInfo { name: "virtual bench".into(), preset: None, description: None, seed: Some(3) };
    let mut session = Session::new(info, preset.robot_description().unwrap());
    let plan = Plan::load(Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/fixtures/small-plan.ron"))).unwrap();
    session.plans = vec![plan];
    session
}

/// The child: open the folder as the workbench would (recover the autosave, else the saved
/// session, else a new one), then measure, save, and redo the whole plan, forever.
#[test]
#[ignore = "the child process of a_session_killed_at_random_moments_always_loads"]
fn child_records_saves_and_redoes_until_killed() {
    let Some(dir) = std::env::var_os(CHILD_DIR) else { return };
    let dir = Path::new(&dir);
    let _lock = FolderLock::acquire(dir).unwrap();
    let preset = BenchPreset::resolve("table2-ideal").unwrap();
    let mut bench = VirtualBench::new(&preset, Some(3)).unwrap();
    let session = if autosave_path(dir).exists() {
        Session::recover(dir).unwrap()
    } else if session_path(dir).exists() {
        Session::load(dir).unwrap()
    } else {
        new_session()
    };
    let mut writer = SessionWriter::new(dir, session);
    let cancel = AtomicBool::new(false);
    loop {
        let mut control = RunControl { cancel: &cancel, on_samples: &mut |_, _| {}, on_progress: &mut |_| {} };
        record(&mut bench, &mut writer, &mut control).unwrap().outcome.unwrap();
        writer.save().unwrap();
        // Redo: the plan measured again from the start, new traces in place of the saved ones.
        writer.session_mut().traces.clear();
        writer.session_mut().progress = None;
    }
}

/// Every trace `session` references passes its size, CRC-32 and length checks.
fn check_all_traces(session: &Session, dir: &Path) -> usize {
    for r in &session.traces {
        session.load_trace(dir, r).unwrap_or_else(|e| panic!("{e}"));
    }
    session.traces.len()
}

#[test]
fn a_session_killed_at_random_moments_always_loads() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("session");
    let exe = std::env::current_exe().unwrap();
    let (mut saved_seen, mut autosaved_seen) = (0, 0);
    for round in 0..8 {
        let delay = Duration::from_millis(rand::random_range(100..2500));
        let mut child = Command::new(&exe)
            .args(["child_records_saves_and_redoes_until_killed", "--exact", "--ignored", "--nocapture"])
            .env(CHILD_DIR, &dir)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let start = Instant::now();
        while start.elapsed() < delay {
            if let Some(status) = child.try_wait().unwrap() {
                let mut err = String::new();
                std::io::Read::read_to_string(child.stderr.as_mut().unwrap(), &mut err).unwrap();
                panic!("round {round}: the recording child ended by itself ({status}): {err}");
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        child.kill().unwrap(); // SIGKILL: no destructor, no flush runs
        child.wait().unwrap();
        // What a technician opens after the crash loads, every trace checked.
        if session_path(&dir).exists() {
            let saved = Session::load(&dir).unwrap_or_else(|e| panic!("round {round} ({delay:?}): {e}"));
            saved_seen += check_all_traces(&saved, &dir);
        }
        if autosave_path(&dir).exists() {
            let recovered = Session::recover(&dir).unwrap_or_else(|e| panic!("round {round} ({delay:?}): {e}"));
            autosaved_seen += check_all_traces(&recovered, &dir);
        }
    }
    assert!(saved_seen > 0 && autosaved_seen > 0, "saved {saved_seen}, autosaved {autosaved_seen} traces seen");
}

#[test]
fn a_folder_open_in_another_photorobot_is_refused_by_calibrate() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("busy");
    let _held = FolderLock::acquire(&dir).unwrap();
    let out = dir.display().to_string();
    let argv = ["photorobot", "calibrate", "--bench", "table2-ideal", "--mode", "paper", "--out", &out];
    let argv: Vec<String> = argv.iter().map(|s| s.to_string()).collect();
    let err = run(argv, &mut Vec::new()).unwrap_err().to_string();
    let expected = format!("{out}: the session folder is open in another photorobot (process {})", std::process::id());
    assert!(err.contains(&expected), "{err}");
    assert!(!session_path(&dir).exists() && !autosave_path(&dir).exists(), "nothing written into it");
}
