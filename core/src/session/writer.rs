//! Writing a session folder incrementally: the one code path of the command line's recording and
//! the workbench's saves. A trace file, once written, is never written again: new data get a new
//! name (a free `traces/NNN.csv`), a trace already on disk is referenced again rather than
//! rewritten (recognised by its CRC-32 and size), and the session or autosave file that
//! references them is written last. A saved `session.ron` therefore stays valid whatever is
//! recorded, autosaved or interrupted after it.

use super::{autosave_path, session_path, Session, SessionError, TraceRef, TRACES_DIR};
use crate::files::{self, FileError};
use crate::trace::Trace;
use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

/// Where the writer puts bytes: the disk ([`Disk`]), or a stand-in that fails on demand to
/// show what a full disk or a failing drive does to a session.
pub trait Storage: Send {
    /// Write `bytes` to `path` atomically (all or nothing).
    fn write_atomic(&mut self, path: &Path, bytes: &[u8]) -> Result<(), FileError>;
}

/// The disk, through [`files::write_atomic`].
#[derive(Debug, Default, Clone, Copy)]
pub struct Disk;

impl Storage for Disk {
    fn write_atomic(&mut self, path: &Path, bytes: &[u8]) -> Result<(), FileError> {
        files::write_atomic(path, bytes)
    }
}

/// A session being written into its folder: the session in memory, and which trace files of
/// the folder hold which content.
pub struct SessionWriter {
    dir: PathBuf,
    session: Session,
    /// Trace files written or referenced in this folder, by (CRC-32, bytes) of their content.
    on_disk: HashMap<(u32, u64), Vec<String>>,
    /// The (CRC-32, bytes) of the CSV of traces seen before, by [`fingerprint`]: an unchanged
    /// trace is recognised without formatting its CSV again.
    seen: HashMap<u64, (u32, u64)>,
    /// Where to look for the next free trace name.
    next_name: usize,
    storage: Box<dyn Storage>,
    /// The traces written by this writer, by file, when it keeps them ([`SessionWriter::keeping_traces`]).
    kept: Option<HashMap<String, Trace>>,
}

impl std::fmt::Debug for SessionWriter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SessionWriter").field("dir", &self.dir).field("traces", &self.session.traces.len()).finish()
    }
}

impl SessionWriter {
    /// A writer of `session` into `dir`; the trace files the session references are taken as
    /// on disk already (a session loaded or recovered from `dir`).
    pub fn new(dir: &Path, session: Session) -> Self {
        let mut on_disk: HashMap<(u32, u64), Vec<String>> = HashMap::new();
        for r in &session.traces {
            on_disk.entry((r.crc32, r.bytes)).or_default().push(r.file.clone());
        }
        Self {
            dir: dir.to_path_buf(),
            session,
            on_disk,
            seen: HashMap::new(),
            next_name: 0,
            storage: Box::new(Disk),
            kept: None,
        }
    }

    /// Take the trace files `other` references as on disk too (the `session.ron` or autosave
    /// already in the folder), so that the same traces are referenced again, not rewritten.
    pub fn adopt_files(&mut self, other: &Session) {
        for r in &other.traces {
            let names = self.on_disk.entry((r.crc32, r.bytes)).or_default();
            if !names.contains(&r.file) {
                names.push(r.file.clone());
            }
        }
    }

    /// The same writer writing through `storage` (a failing one in tests).
    pub fn with_storage(mut self, storage: Box<dyn Storage>) -> Self {
        self.storage = storage;
        self
    }

    /// The same writer keeping in memory every trace it writes, so that
    /// [`SessionWriter::take_traces`] hands them back without reading their files again.
    pub fn keeping_traces(mut self) -> Self {
        self.kept = Some(HashMap::new());
        self
    }

    /// Every complete trace of the session, in order (as [`Session::load_traces`] reads them):
    /// those this writer kept moved out of memory, the others read from their files and checked.
    pub fn take_traces(&mut self) -> Result<Vec<Trace>, SessionError> {
        let mut kept = self.kept.take().unwrap_or_default();
        let complete: Vec<&TraceRef> = self.session.traces.iter().filter(|r| r.complete).collect();
        let mut traces = Vec::with_capacity(complete.len());
        for (k, reference) in complete.iter().enumerate() {
            // A file referenced twice is moved out on its last reference.
            let again = complete[k + 1..].iter().any(|r| r.file == reference.file);
            let trace = match kept.remove(&reference.file) {
                Some(t) if again => {
                    kept.insert(reference.file.clone(), t.clone());
                    t
                }
                Some(t) => t,
                None => self.session.load_trace(&self.dir, reference)?,
            };
            traces.push(trace);
        }
        Ok(traces)
    }

    /// The session folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The session as it stands in memory.
    pub fn session(&self) -> &Session {
        &self.session
    }

    /// The session, to change what is not a trace (plans, progress, results, notes).
    pub fn session_mut(&mut self) -> &mut Session {
        &mut self.session
    }

    /// The session, writer done.
    pub fn into_session(self) -> Session {
        self.session
    }

    /// Write `trace` as a new file (or reuse a file of the same content the session does not
    /// reference yet) and reference it. On error the session is unchanged.
    pub fn add_trace(
        &mut self,
        trace: &Trace,
        step: Option<(usize, usize)>,
        complete: bool,
    ) -> Result<&TraceRef, SessionError> {
        let mut used: HashSet<String> = self.session.traces.iter().map(|r| r.file.clone()).collect();
        let reference = self.store(trace, step, complete, &mut used)?;
        self.session.traces.push(reference);
        Ok(self.session.traces.last().expect("just pushed"))
    }

    /// Make the session's traces these, in order: traces already on disk are referenced as they
    /// are, new ones written to new files. On error the session's traces are unchanged.
    pub fn set_traces<'a>(
        &mut self,
        traces: impl IntoIterator<Item = (&'a Trace, Option<(usize, usize)>, bool)>,
    ) -> Result<(), SessionError> {
        let mut used = HashSet::new();
        let mut references = Vec::new();
        for (trace, step, complete) in traces {
            references.push(self.store(trace, step, complete, &mut used)?);
        }
        self.session.traces = references;
        Ok(())
    }

    /// Write the session to the autosave file (after its traces: they are on disk already).
    pub fn autosave(&mut self) -> Result<(), SessionError> {
        self.write_session(&autosave_path(&self.dir))
    }

    /// Write the session to `session.ron`, then remove the autosave and the trace files that
    /// `session.ron` no longer references (an earlier run of a step redone since).
    pub fn save(&mut self) -> Result<(), SessionError> {
        self.write_session(&session_path(&self.dir))?;
        let autosave = autosave_path(&self.dir);
        match std::fs::remove_file(&autosave) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                return Err(
                    FileError::Io { file: autosave, action: "cannot remove the autosave file", source: e }.into()
                );
            }
            _ => files::sync_dir(&self.dir)?,
        }
        self.remove_unreferenced();
        Ok(())
    }

    fn write_session(&mut self, path: &Path) -> Result<(), SessionError> {
        self.session.validate().map_err(|e| e.in_file(path))?;
        create_dir(&self.dir)?;
        let text = files::to_ron_string(&self.session, path)?;
        Ok(self.storage.write_atomic(path, text.as_bytes())?)
    }

    /// The reference of `trace`, its file written unless one of the same content not in `used`
    /// is on disk.
    fn store(
        &mut self,
        trace: &Trace,
        step: Option<(usize, usize)>,
        complete: bool,
        used: &mut HashSet<String>,
    ) -> Result<TraceRef, SessionError> {
        let print = fingerprint(trace);
        let seen = self.seen.get(&print).and_then(|key| Some((*key, self.free_file(key, used)?)));
        let (key, file) = match seen {
            Some((key, file)) => (key, file),
            None => {
                let bytes = trace.to_csv_bytes(&self.dir.join(TRACES_DIR))?;
                let key = (crc32fast::hash(&bytes), bytes.len() as u64);
                self.seen.insert(print, key);
                let file = match self.free_file(&key, used) {
                    Some(file) => file,
                    None => self.write_trace(key, &bytes, used)?,
                };
                (key, file)
            }
        };
        used.insert(file.clone());
        if let Some(kept) = self.kept.as_mut() {
            kept.entry(file.clone()).or_insert_with(|| trace.clone());
        }
        Ok(TraceRef {
            file,
            label: trace.meta.label.clone(),
            kind: trace.meta.kind,
            samples: trace.len(),
            bytes: key.1,
            crc32: key.0,
            step,
            complete,
        })
    }

    /// A file on disk holding the content `key` that `used` does not hold yet.
    fn free_file(&self, key: &(u32, u64), used: &HashSet<String>) -> Option<String> {
        let names = self.on_disk.get(key)?;
        names.iter().find(|n| !used.contains(n.as_str()) && self.dir.join(n.as_str()).is_file()).cloned()
    }

    /// Write a new trace file under a free name.
    fn write_trace(&mut self, key: (u32, u64), bytes: &[u8], used: &HashSet<String>) -> Result<String, SessionError> {
        let file = self.free_name(used);
        create_dir(&self.dir.join(TRACES_DIR))?;
        self.storage.write_atomic(&self.dir.join(&file), bytes)?;
        self.on_disk.entry(key).or_default().push(file.clone());
        Ok(file)
    }

    /// The first `traces/NNN.csv` from where the last search ended that is neither on disk nor
    /// known nor used.
    fn free_name(&mut self, used: &HashSet<String>) -> String {
        let known: HashSet<&String> = self.on_disk.values().flatten().collect();
        loop {
            let file = format!("{TRACES_DIR}/{:03}.csv", self.next_name);
            self.next_name += 1;
            if !used.contains(&file) && !known.contains(&file) && !self.dir.join(&file).exists() {
                return file;
            }
        }
    }

    /// Remove the trace files of the folder that `session.ron` does not reference, after a save
    /// (no autosave is left to reference them). Best effort: a file left behind costs only space.
    fn remove_unreferenced(&mut self) {
        let referenced: HashSet<&str> = self.session.traces.iter().map(|r| r.file.as_str()).collect();
        let Ok(entries) = std::fs::read_dir(self.dir.join(TRACES_DIR)) else { return };
        let mut removed = HashSet::new();
        for entry in entries.flatten() {
            let name = entry.file_name().to_string_lossy().into_owned();
            let file = format!("{TRACES_DIR}/{name}");
            let ours = name.ends_with(".csv") && name[..name.len() - 4].bytes().all(|b| b.is_ascii_digit());
            if ours && !referenced.contains(file.as_str()) && std::fs::remove_file(entry.path()).is_ok() {
                removed.insert(file);
            }
        }
        for names in self.on_disk.values_mut() {
            names.retain(|n| !removed.contains(n));
        }
        let _ = files::sync_dir(&self.dir.join(TRACES_DIR));
    }
}

/// A 64-bit hash of everything a trace's CSV is made of (its metadata and every value's bits):
/// equal for equal traces, and much cheaper than formatting the CSV.
fn fingerprint(trace: &Trace) -> u64 {
    use std::hash::{Hash, Hasher};
    let mut h = std::collections::hash_map::DefaultHasher::new();
    format!("{:?}", trace.meta).hash(&mut h);
    // The values' bytes in blocks: one hasher call per block, not per value.
    let mut block = [0u8; 8 * 512];
    for (name, values) in trace.columns() {
        name.hash(&mut h);
        values.len().hash(&mut h);
        for chunk in values.chunks(512) {
            for (bytes, v) in block.chunks_exact_mut(8).zip(chunk) {
                bytes.copy_from_slice(&v.to_bits().to_le_bytes());
            }
            h.write(&block[..8 * chunk.len()]);
        }
    }
    h.finish()
}

fn create_dir(dir: &Path) -> Result<(), FileError> {
    std::fs::create_dir_all(dir).map_err(|source| FileError::Io {
        file: dir.to_path_buf(),
        action: "cannot create the folder",
        source,
    })
}

#[cfg(test)]
mod tests;
