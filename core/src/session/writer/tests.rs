use super::*;
use crate::bench::BenchPreset;
use crate::session::{BenchInfo, FolderLock};
use crate::trace::TraceMeta;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Arc;

fn trace(label: &str, n: usize, phase: f64) -> Trace {
    let mut t = Trace::new(TraceMeta { label: label.into(), ..TraceMeta::default() });
    for i in 0..n {
        let x = i as f64;
        t.push_sample(x * 1e-3, [x * 0.1, 0.0, -3.0, 0.0, 0.0, 0.0], 1560.0, 0.5 + 0.1 * (x * 0.3 + phase).sin());
    }
    t
}

fn empty_session() -> Session {
    let preset = BenchPreset::resolve("table2-ideal").unwrap();
    let bench = BenchInfo { name: "virtual bench".into(), preset: None, description: None, seed: Some(1) };
    let mut s = Session::new(bench, preset.robot_description().unwrap());
    s.plans = vec![crate::plan::Plan::strategy1()];
    s
}

/// Counts the files written; fails every write (as a full disk does) while `full` is set.
#[derive(Clone, Default)]
struct FaultyDisk {
    full: Arc<AtomicBool>,
    writes: Arc<AtomicUsize>,
}

impl Storage for FaultyDisk {
    fn write_atomic(&mut self, path: &Path, bytes: &[u8]) -> Result<(), FileError> {
        if self.full.load(Ordering::SeqCst) {
            let source = std::io::Error::other("No space left on device");
            return Err(FileError::Io { file: path.to_path_buf(), action: "cannot write", source });
        }
        self.writes.fetch_add(1, Ordering::SeqCst);
        Disk.write_atomic(path, bytes)
    }
}

fn labels(s: &Session, dir: &Path) -> Vec<String> {
    s.load_traces(dir).unwrap().into_iter().map(|t| t.meta.label).collect()
}

#[test]
fn a_step_redone_after_a_save_leaves_the_saved_session_intact() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let (a, b, c) = (trace("a", 30, 0.0), trace("b", 30, 1.0), trace("c: the redo", 30, 2.0));
    let mut w = SessionWriter::new(dir, empty_session());
    w.set_traces([(&a, Some((0, 1)), true), (&b, Some((0, 3)), true)]).unwrap();
    w.save().unwrap();
    let saved_b = std::fs::read(dir.join(&w.session().traces[1].file)).unwrap();
    // The second step is redone: new data in place of b, then the autosave.
    w.set_traces([(&a, Some((0, 1)), true), (&c, Some((0, 3)), true)]).unwrap();
    w.autosave().unwrap();
    let saved = Session::load(dir).unwrap();
    assert_eq!(labels(&saved, dir), ["a", "b"], "session.ron still loads, every CRC good");
    assert_eq!(std::fs::read(dir.join(&saved.traces[1].file)).unwrap(), saved_b);
    let recovered = Session::recover(dir).unwrap();
    assert_eq!(labels(&recovered, dir), ["a", "c: the redo"]);
    assert_eq!(recovered.traces[0].file, saved.traces[0].file, "a is referenced again, not rewritten");
    assert_ne!(recovered.traces[1].file, saved.traces[1].file, "the redo gets a new file");
    // Saving the redo removes the file no session references any more.
    w.save().unwrap();
    assert!(!dir.join(&saved.traces[1].file).exists());
    assert_eq!(std::fs::read_dir(dir.join(TRACES_DIR)).unwrap().count(), 2);
    assert_eq!(labels(&Session::load(dir).unwrap(), dir), ["a", "c: the redo"]);
}

#[test]
fn unchanged_traces_are_not_written_again() {
    let tmp = tempfile::tempdir().unwrap();
    let disk = FaultyDisk::default();
    let mut w = SessionWriter::new(tmp.path(), empty_session()).with_storage(Box::new(disk.clone()));
    let traces: Vec<Trace> = (0..5).map(|k| trace(&format!("t{k}"), 40, k as f64)).collect();
    let list = || traces.iter().enumerate().map(|(k, t)| (t, Some((0, k)), true));
    w.set_traces(list()).unwrap();
    w.autosave().unwrap();
    assert_eq!(disk.writes.load(Ordering::SeqCst), 6, "five traces, then the autosave");
    w.set_traces(list()).unwrap();
    w.autosave().unwrap();
    w.save().unwrap();
    assert_eq!(disk.writes.load(Ordering::SeqCst), 8, "only the autosave and session.ron again");
    // A writer of the reopened folder knows its files too.
    let reopened = Session::load(tmp.path()).unwrap();
    let mut w = SessionWriter::new(tmp.path(), reopened).with_storage(Box::new(disk.clone()));
    w.set_traces(list()).unwrap();
    w.save().unwrap();
    assert_eq!(disk.writes.load(Ordering::SeqCst), 9);
    // Two traces of the same content still get a file each (a file is referenced once).
    w.set_traces([(&traces[0], None, true), (&traces[0], None, true)]).unwrap();
    w.autosave().unwrap();
    assert_ne!(w.session().traces[0].file, w.session().traces[1].file);
    Session::recover(tmp.path()).unwrap();
}

#[test]
fn a_full_disk_reports_the_error_and_loses_nothing_recorded() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let disk = FaultyDisk::default();
    let mut w = SessionWriter::new(dir, empty_session()).with_storage(Box::new(disk.clone()));
    let (a, b) = (trace("a", 30, 0.0), trace("b", 30, 1.0));
    w.add_trace(&a, Some((0, 1)), true).unwrap();
    w.save().unwrap();
    disk.full.store(true, Ordering::SeqCst);
    let err = w.add_trace(&b, Some((0, 3)), true).unwrap_err().to_string();
    assert!(err.contains("No space left on device") && err.contains("traces/"), "{err}");
    assert_eq!(w.session().traces.len(), 1, "the session in memory is as before the failed write");
    let err = w.autosave().unwrap_err().to_string();
    assert!(err.contains("session.autosave.ron") && err.contains("No space left"), "{err}");
    let err = w.save().unwrap_err().to_string();
    assert!(err.contains("session.ron"), "{err}");
    // The earlier save is intact.
    assert_eq!(labels(&Session::load(dir).unwrap(), dir), ["a"]);
    // Space again: the trace still in the caller's hands is written.
    disk.full.store(false, Ordering::SeqCst);
    w.add_trace(&b, Some((0, 3)), true).unwrap();
    w.save().unwrap();
    assert_eq!(labels(&Session::load(dir).unwrap(), dir), ["a", "b"]);
}

#[test]
fn a_folder_that_cannot_be_written_fails_clearly_and_keeps_the_data() {
    let tmp = tempfile::tempdir().unwrap();
    let good = tmp.path().join("good");
    let mut w = SessionWriter::new(&good, empty_session());
    w.add_trace(&trace("a", 30, 0.0), Some((0, 1)), true).unwrap();
    w.save().unwrap();
    // A folder under a regular file cannot be created, even by root.
    std::fs::write(tmp.path().join("a-file"), "not a folder").unwrap();
    let bad = tmp.path().join("a-file").join("session");
    let mut elsewhere = SessionWriter::new(&bad, w.session().clone());
    let err = elsewhere.add_trace(&trace("b", 30, 1.0), Some((0, 3)), true).unwrap_err().to_string();
    assert!(err.contains("a-file/session") && err.contains("cannot create the folder"), "{err}");
    let err = elsewhere.save().unwrap_err().to_string();
    assert!(err.contains("a-file/session") && err.contains("cannot create the folder"), "{err}");
    assert_eq!(elsewhere.session().traces.len(), 1);
    assert_eq!(labels(&Session::load(&good).unwrap(), &good), ["a"]);
}

#[test]
fn a_second_program_is_refused_a_locked_folder_with_the_holder_named() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("session");
    let held = FolderLock::acquire(&dir).unwrap();
    let err = FolderLock::acquire(&dir).unwrap_err().to_string();
    let expected =
        format!("{}: the session folder is open in another photorobot (process {})", dir.display(), std::process::id());
    assert!(err.starts_with(&expected), "{err}");
    drop(held);
    FolderLock::acquire(&dir).expect("free again once the holder closed it");
}

#[test]
fn taking_the_lock_removes_the_temporaries_of_an_interrupted_save_and_nothing_else() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("session");
    let traces = dir.join(crate::session::TRACES_DIR);
    std::fs::create_dir_all(&traces).unwrap();
    // What `write_atomic` leaves when the process is killed between creating and renaming.
    let strays = [dir.join(".session.ron.a1B2c3.tmp"), traces.join(".004.csv.Xy9z8w.tmp")];
    let kept = [dir.join("session.ron"), dir.join("notes.tmp"), dir.join(".hidden"), traces.join("004.csv")];
    for f in strays.iter().chain(&kept) {
        std::fs::write(f, "x").unwrap();
    }
    let _held = FolderLock::acquire(&dir).unwrap();
    for f in &strays {
        assert!(!f.exists(), "{} removed", f.display());
    }
    for f in &kept {
        assert!(f.exists(), "{} kept", f.display());
    }
}

/// The traces a keeping writer hands back are those its folder holds: kept ones moved out of
/// memory, one referenced twice given twice, those of an earlier run read from their files,
/// incomplete ones left out.
#[test]
fn kept_traces_are_the_traces_the_folder_holds() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let (a, b, c) = (trace("a", 30, 0.0), trace("b", 40, 1.0), trace("c: partial", 10, 2.0));
    let mut earlier = SessionWriter::new(dir, empty_session());
    earlier.add_trace(&a, Some((0, 0)), true).unwrap();
    earlier.autosave().unwrap();
    let recovered = Session::recover(dir).unwrap();
    let mut w = SessionWriter::new(dir, recovered).keeping_traces();
    w.add_trace(&b, Some((0, 1)), true).unwrap();
    w.add_trace(&b, Some((0, 2)), true).unwrap();
    w.add_trace(&c, Some((0, 3)), false).unwrap();
    w.autosave().unwrap();
    let from_disk = Session::recover(dir).unwrap().load_traces(dir).unwrap();
    let taken = w.take_traces().unwrap();
    assert_eq!(taken.iter().map(|t| t.meta.label.as_str()).collect::<Vec<_>>(), ["a", "b", "b"]);
    assert_eq!(taken, from_disk);
}
