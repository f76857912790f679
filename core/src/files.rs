//! Reading and writing the project's data files (RON descriptions, presets, plans).
//! Owns the file-level error type that names the file, the line and what was expected, and atomic saves.

use serde::{de::DeserializeOwned, Serialize};
use std::fmt;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use thiserror::Error;

/// An error reading or writing a data file: always names the file, and where possible the
/// line, column or field and what was expected.
#[derive(Debug, Error)]
pub enum FileError {
    /// The file could not be read or written at all.
    #[error("{file}: {action}: {source}")]
    Io {
        /// The file.
        file: PathBuf,
        /// What was being done ("cannot read", "cannot write").
        action: &'static str,
        /// The operating-system error.
        source: std::io::Error,
    },
    /// The text does not parse as the expected kind of document.
    #[error("{file}:{line}:{column}: {message} (expected {expected})")]
    Parse {
        /// The file.
        file: PathBuf,
        /// 1-based line of the error.
        line: usize,
        /// 1-based column of the error.
        column: usize,
        /// The parser's message.
        message: String,
        /// What kind of document was expected.
        expected: String,
    },
    /// The document parses but a field has a value that is not allowed.
    #[error("{file}: field `{field}`: {problem}")]
    Invalid {
        /// The file.
        file: PathBuf,
        /// Path of the field, e.g. `links[3].limits`.
        field: String,
        /// What is wrong and what was expected.
        problem: String,
    },
    /// The file is larger than the limit for its kind; it was refused from its size, unread.
    #[error(
        "{file}: {size_bytes} bytes, above the limit of {limit_bytes} bytes for {what}; refusing to read it ({advice})"
    )]
    TooLarge {
        /// The file.
        file: PathBuf,
        /// Its size (bytes).
        size_bytes: u64,
        /// The limit (bytes).
        limit_bytes: u64,
        /// What kind of file was expected, e.g. "a session file".
        what: &'static str,
        /// What to do about it.
        advice: &'static str,
    },
    /// The value could not be serialised (a bug, reported rather than panicking).
    #[error("{file}: cannot serialise: {message}")]
    Serialise {
        /// The file.
        file: PathBuf,
        /// The serialiser's message.
        message: String,
    },
}

/// A problem found by a validation pass: the field path and what is wrong. Turned into a
/// [`FileError::Invalid`] once the file name is known.
#[derive(Debug, Clone, PartialEq)]
pub struct FieldError {
    /// Path of the field, e.g. `links[3].limits`.
    pub field: String,
    /// What is wrong and what was expected.
    pub problem: String,
}

impl FieldError {
    /// A field error.
    pub fn new(field: impl Into<String>, problem: impl Into<String>) -> Self {
        Self { field: field.into(), problem: problem.into() }
    }

    /// Attach the file name.
    pub fn in_file(self, file: impl Into<PathBuf>) -> FileError {
        FileError::Invalid { file: file.into(), field: self.field, problem: self.problem }
    }
}

impl fmt::Display for FieldError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "field `{}`: {}", self.field, self.problem)
    }
}

/// Parse RON text; `origin` names the file (or the embedded asset) in errors.
pub fn parse_ron<T: DeserializeOwned>(text: &str, origin: &Path, expected: &str) -> Result<T, FileError> {
    ron::from_str(text).map_err(|e| FileError::Parse {
        file: origin.to_path_buf(),
        line: e.span.start.line,
        column: e.span.start.col,
        message: e.code.to_string(),
        expected: expected.to_string(),
    })
}

/// Read a text file; the error names the file.
pub fn read_text(path: &Path) -> Result<String, FileError> {
    std::fs::read_to_string(path).map_err(|source| FileError::Io {
        file: path.to_path_buf(),
        action: "cannot read",
        source,
    })
}

/// Refuse a file larger than `limit_bytes` from its size alone, before reading any of it.
pub fn check_size(path: &Path, limit_bytes: u64, what: &'static str, advice: &'static str) -> Result<u64, FileError> {
    let size_bytes = std::fs::metadata(path)
        .map_err(|source| FileError::Io { file: path.to_path_buf(), action: "cannot open", source })?
        .len();
    if size_bytes > limit_bytes {
        return Err(FileError::TooLarge { file: path.to_path_buf(), size_bytes, limit_bytes, what, advice });
    }
    Ok(size_bytes)
}

/// Read a text file of at most `limit_bytes` (checked from its size first, so a huge file is
/// never read into memory); the error names the file.
pub fn read_text_limited(
    path: &Path,
    limit_bytes: u64,
    what: &'static str,
    advice: &'static str,
) -> Result<String, FileError> {
    check_size(path, limit_bytes, what, advice)?;
    let mut text = String::new();
    std::fs::File::open(path)
        .and_then(|f| f.take(limit_bytes).read_to_string(&mut text))
        .map_err(|source| FileError::Io { file: path.to_path_buf(), action: "cannot read", source })?;
    Ok(text)
}

/// Read and parse a RON file.
pub fn load_ron<T: DeserializeOwned>(path: &Path, expected: &str) -> Result<T, FileError> {
    parse_ron(&read_text(path)?, path, expected)
}

/// Serialise to pretty RON.
pub fn to_ron_string<T: Serialize>(value: &T, origin: &Path) -> Result<String, FileError> {
    ron::ser::to_string_pretty(value, ron::ser::PrettyConfig::default())
        .map_err(|e| FileError::Serialise { file: origin.to_path_buf(), message: e.to_string() })
}

/// Write bytes atomically: into a temporary file of a unique name beside the target (so two
/// saves at once never share one), flushed to disk, renamed over the target, then the folder
/// itself flushed so the rename survives a power cut. A crash leaves either the old file or the
/// new one, never half of one.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), FileError> {
    write_atomic_on(path, bytes, &mut SystemDisk)
}

/// The two steps of an atomic save that a full or failing disk refuses: writing the temporary
/// file's bytes, and flushing them to the device. [`SystemDisk`] does them; a stand-in that fails as
/// a disk does shows what a full disk does to a save ([`write_atomic_on`]).
pub trait Medium {
    /// Write all of `bytes` to `file`.
    fn write(&mut self, file: &mut std::fs::File, bytes: &[u8]) -> std::io::Result<()>;
    /// Flush `file`'s content to the device.
    fn sync(&mut self, file: &std::fs::File) -> std::io::Result<()>;
}

/// The disk itself, through the operating system.
#[derive(Debug, Default, Clone, Copy)]
pub struct SystemDisk;

impl Medium for SystemDisk {
    fn write(&mut self, file: &mut std::fs::File, bytes: &[u8]) -> std::io::Result<()> {
        file.write_all(bytes)
    }
    fn sync(&mut self, file: &std::fs::File) -> std::io::Result<()> {
        file.sync_all()
    }
}

/// [`write_atomic`] through `medium`. A write or a flush that fails leaves the target as it was
/// and removes the temporary.
pub fn write_atomic_on(path: &Path, bytes: &[u8], medium: &mut dyn Medium) -> Result<(), FileError> {
    let tmp = Temporary::with_bytes_on(path, bytes, medium)?;
    persist(tmp.0, path)?;
    sync_dir(&parent_dir(path))
}

/// How many files [`write_atomic_with`] writes and flushes at once.
pub const WRITE_AT_ONCE: usize = 16;

/// [`write_atomic`] for many files at once, each file's temporary made by `make` from its
/// target and item (several at a time, on threads of their own), which also gives what the
/// caller keeps of each file, returned in order. Every temporary is written and flushed, then
/// renamed over its target in order, then each folder flushed once (waiting for the disk one
/// file after the other is most of the time of many small saves). Each file is atomic as with
/// [`write_atomic`]; on an error, the files renamed before it stay written. Every temporary
/// stays open until all are made: many files are written a group of [`WRITE_AT_ONCE`] at a time.
pub fn write_atomic_with<T, X, E>(
    files: &[(PathBuf, T)],
    make: impl Fn(&Path, &T) -> Result<(Temporary, X), E> + Sync,
) -> Result<Vec<X>, E>
where
    T: Sync,
    X: Send,
    E: From<FileError> + Send,
{
    let per_thread = files.len().div_ceil(WRITE_AT_ONCE).max(1);
    let made: Vec<(Temporary, X)> = if files.len() <= 1 {
        files.iter().map(|(path, item)| make(path, item)).collect::<Result<_, _>>()?
    } else {
        // Threads of their own rather than the compute pool's: they mostly wait for the disk.
        std::thread::scope(|scope| {
            let make = &make;
            let writers: Vec<_> = files
                .chunks(per_thread)
                .map(|chunk| scope.spawn(move || chunk.iter().map(|(path, item)| make(path, item)).collect::<Vec<_>>()))
                .collect();
            writers
                .into_iter()
                .flat_map(|w| w.join().unwrap_or_else(|panic| std::panic::resume_unwind(panic)))
                .collect::<Result<_, _>>()
        })?
    };
    let mut dirs: Vec<PathBuf> = Vec::new();
    let mut kept = Vec::with_capacity(made.len());
    for ((tmp, x), (path, _)) in made.into_iter().zip(files) {
        persist(tmp.0, path)?;
        let dir = parent_dir(path);
        if !dirs.contains(&dir) {
            dirs.push(dir);
        }
        kept.push(x);
    }
    dirs.iter().try_for_each(|d| sync_dir(d))?;
    Ok(kept)
}

/// The folder a file is in (`.` for a bare name).
fn parent_dir(path: &Path) -> PathBuf {
    match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// A temporary file of a unique name beside its target (so two saves at once never share
/// one), its content flushed to disk, for [`write_atomic_with`] to rename over the target.
/// Dropping it removes it.
pub struct Temporary(tempfile::NamedTempFile);

impl Temporary {
    /// A temporary beside `path`, empty.
    fn beside(path: &Path) -> Result<tempfile::NamedTempFile, FileError> {
        let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| "file".into());
        tempfile::Builder::new().prefix(&format!(".{name}.")).suffix(".tmp").tempfile_in(parent_dir(path)).map_err(
            |source| FileError::Io { file: path.to_path_buf(), action: "cannot create temporary file", source },
        )
    }

    /// A temporary beside `path` holding `bytes`.
    pub fn with_bytes(path: &Path, bytes: &[u8]) -> Result<Self, FileError> {
        Self::with_bytes_on(path, bytes, &mut SystemDisk)
    }

    /// [`Temporary::with_bytes`] through `medium`.
    fn with_bytes_on(path: &Path, bytes: &[u8], medium: &mut dyn Medium) -> Result<Self, FileError> {
        let io = |action: &'static str| move |source| FileError::Io { file: path.to_path_buf(), action, source };
        let mut tmp = Self::beside(path)?;
        medium.write(tmp.as_file_mut(), bytes).map_err(io("cannot write"))?;
        medium.sync(tmp.as_file()).map_err(io("cannot flush to disk"))?;
        Ok(Self(tmp))
    }

    /// A temporary beside `path` holding a copy of the file `source`, when the copy is
    /// `size_bytes` long with the CRC-32 `crc32`; `None` when it is not (the source changed
    /// since it was read, or cannot be read). The kernel copies the file (several times less
    /// CPU than reading and writing it here); the copy is read back for the check.
    pub fn copy_of(path: &Path, source: &Path, crc32: u32, size_bytes: u64) -> Result<Option<Self>, FileError> {
        let io = |action: &'static str| move |source| FileError::Io { file: path.to_path_buf(), action, source };
        let mut tmp = Self::beside(path)?;
        let copied = std::fs::File::open(source).and_then(|mut from| std::io::copy(&mut from, tmp.as_file_mut()));
        if copied.ok() != Some(size_bytes) {
            return Ok(None);
        }
        tmp.as_file().sync_all().map_err(io("cannot flush to disk"))?;
        let mut back = tmp.reopen().map_err(io("cannot read back"))?;
        let (mut hasher, mut buf) = (crc32fast::Hasher::new(), vec![0u8; 256 * 1024]);
        let mut read = 0u64;
        loop {
            match back.read(&mut buf).map_err(io("cannot read back"))? {
                0 => break,
                n => {
                    hasher.update(&buf[..n]);
                    read += n as u64;
                }
            }
        }
        Ok((read == size_bytes && hasher.finalize() == crc32).then_some(Self(tmp)))
    }
}

/// Rename a flushed temporary file over `path`.
fn persist(tmp: tempfile::NamedTempFile, path: &Path) -> Result<(), FileError> {
    tmp.persist(path).map(|_| ()).map_err(|e| FileError::Io {
        file: path.to_path_buf(),
        action: "cannot replace",
        source: e.error,
    })
}

/// Flush a folder's entries (a rename or a removal in it) to disk.
pub fn sync_dir(dir: &Path) -> Result<(), FileError> {
    // Only Unix can open a folder to flush it; elsewhere the rename is as durable as it gets.
    #[cfg(unix)]
    std::fs::File::open(dir).and_then(|d| d.sync_all()).map_err(|source| FileError::Io {
        file: dir.to_path_buf(),
        action: "cannot flush the folder to disk",
        source,
    })?;
    Ok(())
}

/// Serialise to RON and save atomically.
pub fn save_ron<T: Serialize>(path: &Path, value: &T) -> Result<(), FileError> {
    let text = to_ron_string(value, path)?;
    write_atomic(path, text.as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(serde::Deserialize, serde::Serialize, Debug, PartialEq)]
    struct Doc {
        a_um: f64,
    }

    #[test]
    fn parse_error_names_file_line_and_expectation() {
        let err = parse_ron::<Doc>("(\n  a_um: \"x\",\n)", Path::new("x.ron"), "a Doc").unwrap_err();
        let msg = err.to_string();
        assert!(msg.starts_with("x.ron:2:"), "{msg}");
        assert!(msg.contains("expected a Doc"), "{msg}");
    }

    #[test]
    fn atomic_save_round_trips_and_leaves_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("doc.ron");
        save_ron(&p, &Doc { a_um: 1.5 }).unwrap();
        save_ron(&p, &Doc { a_um: 2.5 }).unwrap();
        let back: Doc = load_ron(&p, "a Doc").unwrap();
        assert_eq!(back, Doc { a_um: 2.5 });
        let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(names.len(), 1);
    }

    #[test]
    fn concurrent_atomic_saves_of_one_file_never_mix() {
        // One temporary name per process made two saves at once write into the same file.
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("doc.txt");
        let writers: Vec<_> = (0..8u8)
            .map(|k| {
                let p = p.clone();
                std::thread::spawn(move || {
                    let body = vec![b'a' + k; 200_000];
                    for _ in 0..5 {
                        write_atomic(&p, &body).unwrap();
                    }
                })
            })
            .collect();
        for w in writers {
            w.join().unwrap();
        }
        let back = std::fs::read(&p).unwrap();
        assert_eq!(back.len(), 200_000);
        assert!(back.iter().all(|b| *b == back[0]), "the file mixes two saves");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1, "a temporary file was left");
    }

    /// Bytes written as a batch of atomic saves.
    fn write_all(files: &[(PathBuf, Vec<u8>)]) -> Result<(), FileError> {
        write_atomic_with(files, |path, bytes| Ok::<_, FileError>((Temporary::with_bytes(path, bytes)?, ())))
            .map(|_| ())
    }

    #[test]
    fn a_batch_of_atomic_saves_writes_every_file_and_leaves_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let sub = dir.path().join("sub");
        std::fs::create_dir(&sub).unwrap();
        std::fs::write(dir.path().join("0.txt"), b"old").unwrap();
        let files: Vec<(PathBuf, Vec<u8>)> = (0..12u8)
            .map(|k| {
                let folder = if k % 2 == 0 { dir.path() } else { sub.as_path() };
                (folder.join(format!("{k}.txt")), vec![b'a' + k; 1000 * k as usize])
            })
            .collect();
        write_all(&files).unwrap();
        for (path, bytes) in &files {
            assert_eq!(&std::fs::read(path).unwrap(), bytes, "{path:?}");
        }
        // 6 files and the sub-folder; 6 files in it: no temporary left in either
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 7);
        assert_eq!(std::fs::read_dir(&sub).unwrap().count(), 6);
    }

    #[test]
    fn a_batch_with_an_unwritable_file_names_it_and_renames_none() {
        let dir = tempfile::tempdir().unwrap();
        let good = dir.path().join("good.txt");
        let bad = dir.path().join("no-such-folder").join("bad.txt");
        let err = write_all(&[(good.clone(), b"x".to_vec()), (bad.clone(), b"y".to_vec())]).unwrap_err();
        assert!(err.to_string().contains("bad.txt"), "{err}");
        assert!(!good.exists(), "a file was renamed into place although the batch failed first");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0, "a temporary file was left");
    }

    /// A copy is kept only when it holds the bytes that were read (size and CRC-32): a source
    /// changed in place to as many other bytes, or gone, gives none and leaves no temporary.
    #[test]
    fn a_copy_is_kept_only_when_it_holds_the_bytes_read() {
        let dir = tempfile::tempdir().unwrap();
        let (source, target) = (dir.path().join("source.csv"), dir.path().join("out").join("000.csv"));
        std::fs::create_dir(target.parent().unwrap()).unwrap();
        let bytes: Vec<u8> = (0..700_000u32).map(|k| (k % 251) as u8).collect();
        std::fs::write(&source, &bytes).unwrap();
        let (crc, size) = (crc32fast::hash(&bytes), bytes.len() as u64);
        let copy = Temporary::copy_of(&target, &source, crc, size).unwrap().expect("the source is as read");
        assert_eq!(std::fs::read(copy.0.path()).unwrap(), bytes);
        drop(copy);
        let mut changed = bytes.clone();
        changed[400_000] ^= 1;
        std::fs::write(&source, &changed).unwrap();
        assert!(Temporary::copy_of(&target, &source, crc, size).unwrap().is_none(), "one bit changed");
        std::fs::remove_file(&source).unwrap();
        assert!(Temporary::copy_of(&target, &source, crc, size).unwrap().is_none(), "the source is gone");
        assert_eq!(std::fs::read_dir(target.parent().unwrap()).unwrap().count(), 0, "a temporary file was left");
    }

    #[test]
    fn missing_file_is_named() {
        let err = load_ron::<Doc>(Path::new("/no/such/file.ron"), "a Doc").unwrap_err();
        assert!(err.to_string().contains("/no/such/file.ron"));
    }
}
