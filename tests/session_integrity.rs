//! A session folder survives the worst a bench PC does to it, through the library the workbench
//! records with: the process killed (SIGKILL) at seeded random moments while it records, saves
//! and redoes steps leaves a folder whose `session.ron` and autosave load with every trace
//! passing its CRC check; and a disk that fills in the middle of a write, or fails a flush,
//! loses nothing recorded (the file layer's write and flush refuse as a full disk does). The
//! command line's own guarantee, on the binary, is `app/tests/cli_crash.rs`.

use photorobot_core::bench::{BenchPreset, RunControl, VirtualBench};
use photorobot_core::files::{self, FileError, Medium};
use photorobot_core::plan::Plan;
use photorobot_core::session::recording::record;
use photorobot_core::session::writer::Storage;
use photorobot_core::session::{autosave_path, session_path, BenchInfo, FolderLock, Session, SessionWriter};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use std::io::Write;
use std::path::{Path, PathBuf};
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

/// Measure the session's plans from where it stands on the virtual bench of seed 3.
fn record_all(writer: &mut SessionWriter) -> Result<(), String> {
    let mut bench = VirtualBench::from_preset_name("table2-ideal", Some(3)).unwrap();
    let cancel = AtomicBool::new(false);
    let mut control = RunControl { cancel: &cancel, on_samples: &mut |_, _| {}, on_progress: &mut |_| {} };
    let recorded = record(&mut bench, writer, &mut control).map_err(|e| e.to_string())?;
    recorded.outcome.map_err(|e| e.to_string())
}

/// The child: open the folder as the workbench would (recover the autosave, else the saved
/// session, else a new one), then measure, save, and redo the whole plan, forever.
#[test]
#[ignore = "the child process of a_session_killed_at_random_moments_always_loads"]
fn child_records_saves_and_redoes_until_killed() {
    let Some(dir) = std::env::var_os(CHILD_DIR) else { return };
    let dir = Path::new(&dir);
    let _lock = FolderLock::acquire(dir).unwrap();
    let session = if autosave_path(dir).exists() {
        Session::recover(dir).unwrap()
    } else if session_path(dir).exists() {
        Session::load(dir).unwrap()
    } else {
        new_session()
    };
    let mut writer = SessionWriter::new(dir, session);
    loop {
        record_all(&mut writer).unwrap();
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
    let mut rng = StdRng::seed_from_u64(49);
    let (mut saved_seen, mut autosaved_seen) = (0, 0);
    for round in 0..8 {
        let delay = Duration::from_millis(rng.random_range(100..2500));
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

/// Where the disk fails, counting the files the recording writes from 1 (the autosave at the
/// start, the one after the first segment, which records nothing, then a trace and its autosave
/// per recorded segment).
#[derive(Debug, Clone, Copy)]
enum Fault {
    /// The disk fills in the middle of the `n`-th file: half of it is written, then ENOSPC.
    FullInFile(usize),
    /// The flush of the `n`-th file fails with EIO.
    FlushFails(usize),
}

/// A disk that fails at `fault`, through the file layer's write and flush.
struct FaultyDisk {
    fault: Fault,
    files: usize,
}

impl Medium for FaultyDisk {
    fn write(&mut self, file: &mut std::fs::File, bytes: &[u8]) -> std::io::Result<()> {
        self.files += 1;
        if matches!(self.fault, Fault::FullInFile(n) if n == self.files) {
            file.write_all(&bytes[..bytes.len() / 2])?;
            return Err(std::io::Error::new(std::io::ErrorKind::StorageFull, "No space left on device"));
        }
        file.write_all(bytes)
    }

    fn sync(&mut self, file: &std::fs::File) -> std::io::Result<()> {
        if matches!(self.fault, Fault::FlushFails(n) if n == self.files) {
            return Err(std::io::Error::other("Input/output error"));
        }
        file.sync_all()
    }
}

/// The session writer's storage on the faulty disk; keeps the last autosave it wrote whole.
struct FaultyStorage {
    disk: FaultyDisk,
    last_autosave: std::sync::Arc<std::sync::Mutex<Option<Vec<u8>>>>,
}

impl Storage for FaultyStorage {
    fn write_atomic(&mut self, path: &Path, bytes: &[u8]) -> Result<(), FileError> {
        files::write_atomic_on(path, bytes, &mut self.disk)?;
        if path.file_name() == autosave_path(Path::new("")).file_name() {
            *self.last_autosave.lock().unwrap() = Some(bytes.to_vec());
        }
        Ok(())
    }
}

/// Every file under `dir` whose name ends with `.tmp`.
fn temporaries(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for d in [dir.to_path_buf(), dir.join("traces")] {
        for e in std::fs::read_dir(d).into_iter().flatten().flatten() {
            if e.file_name().to_string_lossy().ends_with(".tmp") {
                out.push(e.path());
            }
        }
    }
    out
}

/// The recording's fault: the error names a file of the folder and the disk's reason; the
/// folder's autosave is the last one written whole, every trace it references intact; no
/// temporary is left; the session in memory lost nothing it kept. Then, with a good disk,
/// the recording resumes to the end, every trace kept before the fault unchanged.
fn check_fault(fault: Fault, steps: usize) {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("session");
    let last_autosave = std::sync::Arc::new(std::sync::Mutex::new(None));
    let disk = FaultyDisk { fault, files: 0 };
    let storage = FaultyStorage { disk, last_autosave: last_autosave.clone() };
    let mut writer = SessionWriter::new(&dir, new_session()).with_storage(Box::new(storage));
    let err = record_all(&mut writer).expect_err("the disk fails within the recording");
    let reason = match fault {
        Fault::FullInFile(_) => "cannot write: No space left on device",
        Fault::FlushFails(_) => "cannot flush to disk: Input/output error",
    };
    assert!(err.contains(&*dir.to_string_lossy()) && err.contains(reason), "{fault:?}: {err}");
    assert!(temporaries(&dir).is_empty(), "{fault:?}: temporaries left: {:?}", temporaries(&dir));
    let last = last_autosave.lock().unwrap().clone().expect("an autosave before the fault");
    let on_disk = std::fs::read(autosave_path(&dir)).unwrap();
    assert!(on_disk == last, "{fault:?}: the autosave is not the last one written whole");
    let recovered = Session::recover(&dir).unwrap_or_else(|e| panic!("{fault:?}: {e}"));
    let in_memory = &writer.session().traces;
    assert!(recovered.traces.len() <= in_memory.len(), "{fault:?}");
    assert_eq!(recovered.traces[..], in_memory[..recovered.traces.len()], "{fault:?}: kept traces in memory");
    // Room again: the recording resumes from the autosave and finishes.
    let mut resumed = SessionWriter::new(&dir, recovered.clone());
    record_all(&mut resumed).unwrap_or_else(|e| panic!("{fault:?}: resume: {e}"));
    resumed.save().unwrap();
    let done = Session::load(&dir).unwrap();
    assert_eq!(check_all_traces(&done, &dir), steps, "{fault:?}: every recorded segment");
    assert_eq!(done.traces[..recovered.traces.len()], recovered.traces[..], "{fault:?}: kept traces unchanged");
}

#[test]
fn a_disk_that_fills_or_fails_a_flush_mid_recording_loses_nothing_recorded() {
    let steps = new_session().plans[0].segments.iter().filter(|s| s.is_recorded()).count();
    // Files 5 and 6: the second recorded segment's trace, then its autosave.
    for fault in [Fault::FullInFile(5), Fault::FullInFile(6), Fault::FlushFails(5), Fault::FlushFails(6)] {
        check_fault(fault, steps);
    }
}
