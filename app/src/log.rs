//! The program's log: warnings and errors on stderr (more with `-v` or `RUST_LOG`), and the log at
//! debug level in `photorobot.log` inside the session folder a command writes: milestones, the
//! commands that change an instrument's state and one summary per recording, so that a whole run
//! fits in it; every command and reply (the recorder's rows) at trace level, with `-vvv`. Owns the
//! subscriber set-up and the size-based rotation of the log file (`photorobot.log` →
//! `photorobot.log.1` … `.3`); what is logged is decided where it happens (`tracing` macros).

use std::fs::{File, OpenOptions};
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use tracing_subscriber::filter::{EnvFilter, LevelFilter, Targets};
use tracing_subscriber::fmt::MakeWriter;
use tracing_subscriber::prelude::*;

/// The log file's name in a session folder.
pub const LOG_FILE: &str = "photorobot.log";
/// The size at which the log file is rotated (bytes).
pub const ROTATE_BYTES: u64 = 10 * 1024 * 1024;
/// How many rotated files are kept (`photorobot.log.1` … `.3`).
pub const KEEP_ROTATED: usize = 3;

/// A log file rotated by size: when a write would take it past `max_bytes`, `name.N` becomes
/// `name.N+1` (the oldest beyond `keep` is deleted), the file becomes `name.1`, and a new file
/// starts. A single write larger than the limit still goes into one file, whole (the log's
/// formatter writes each event in one call, so events are never split across files).
pub struct RotatingFile {
    path: PathBuf,
    max_bytes: u64,
    keep: usize,
    file: File,
    size_bytes: u64,
}

impl RotatingFile {
    /// Open (append to) `path`, rotating at `max_bytes` and keeping `keep` old files.
    pub fn open(path: &Path, max_bytes: u64, keep: usize) -> io::Result<Self> {
        let file = OpenOptions::new().create(true).append(true).open(path)?;
        let size_bytes = file.metadata()?.len();
        Ok(RotatingFile { path: path.to_path_buf(), max_bytes, keep, file, size_bytes })
    }

    /// The path of the `k`-th rotated file (`photorobot.log.k`).
    pub fn rotated_path(path: &Path, k: usize) -> PathBuf {
        let mut name = path.as_os_str().to_os_string();
        name.push(format!(".{k}"));
        PathBuf::from(name)
    }

    fn rotate(&mut self) -> io::Result<()> {
        self.file.flush()?;
        if self.keep == 0 {
            self.file = File::create(&self.path)?;
        } else {
            let _ = std::fs::remove_file(Self::rotated_path(&self.path, self.keep));
            for k in (1..self.keep).rev() {
                let from = Self::rotated_path(&self.path, k);
                if from.exists() {
                    std::fs::rename(&from, Self::rotated_path(&self.path, k + 1))?;
                }
            }
            std::fs::rename(&self.path, Self::rotated_path(&self.path, 1))?;
            self.file = OpenOptions::new().create(true).append(true).open(&self.path)?;
        }
        self.size_bytes = 0;
        Ok(())
    }
}

impl Write for RotatingFile {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        if self.size_bytes > 0 && self.size_bytes + buf.len() as u64 > self.max_bytes {
            self.rotate()?;
        }
        self.file.write_all(buf)?;
        self.size_bytes += buf.len() as u64;
        Ok(buf.len())
    }

    fn flush(&mut self) -> io::Result<()> {
        self.file.flush()
    }
}

/// The session log in use, if a command opened one.
static SESSION_LOG: Mutex<Option<RotatingFile>> = Mutex::new(None);

/// Writes into the session log, or nowhere while none is open.
struct SessionLogWriter;

impl Write for SessionLogWriter {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        match SESSION_LOG.lock().ok().as_mut().and_then(|g| g.as_mut()) {
            Some(f) => f.write(buf),
            None => Ok(buf.len()),
        }
    }

    fn flush(&mut self) -> io::Result<()> {
        match SESSION_LOG.lock().ok().as_mut().and_then(|g| g.as_mut()) {
            Some(f) => f.flush(),
            None => Ok(()),
        }
    }
}

impl<'a> MakeWriter<'a> for SessionLogWriter {
    type Writer = SessionLogWriter;
    fn make_writer(&'a self) -> Self::Writer {
        SessionLogWriter
    }
}

/// Install the process's log: stderr at warn (`quiet`: errors only; `-v`: info, `-vv`: debug;
/// `RUST_LOG` overrides), and the session log at debug level (trace with `-vvv`: every command and
/// reply) once [`open_session_log`] is called. A second call does nothing.
pub fn init(verbose: u8, quiet: bool) {
    let stderr_filter = match std::env::var("RUST_LOG") {
        Ok(spec) if !spec.is_empty() => EnvFilter::new(spec),
        _ => EnvFilter::default().add_directive(
            match (quiet, verbose) {
                (true, _) => LevelFilter::ERROR,
                (false, 0) => LevelFilter::WARN,
                (false, 1) => LevelFilter::INFO,
                (false, 2) => LevelFilter::DEBUG,
                _ => LevelFilter::TRACE,
            }
            .into(),
        ),
    };
    let stderr = tracing_subscriber::fmt::layer()
        .with_writer(io::stderr)
        .with_target(false)
        .without_time()
        .with_ansi(std::io::IsTerminal::is_terminal(&io::stderr()))
        .with_filter(stderr_filter);
    // Our crates at debug (trace with -vvv); dependencies only when they warn.
    let ours = if verbose >= 3 { LevelFilter::TRACE } else { LevelFilter::DEBUG };
    let file_filter = Targets::new()
        .with_default(LevelFilter::WARN)
        .with_target("photorobot_core", ours)
        .with_target("photorobot_app", ours)
        .with_target("photorobot", ours);
    let file = tracing_subscriber::fmt::layer().with_writer(SessionLogWriter).with_ansi(false).with_filter(file_filter);
    let _ = tracing_subscriber::registry().with(stderr).with(file).try_init();
}

/// Log from now on into `photorobot.log` in `dir` (created if needed), appending to a log a
/// resumed session already has. Replaces any session log opened before.
pub fn open_session_log(dir: &Path) -> io::Result<PathBuf> {
    std::fs::create_dir_all(dir)?;
    let path = dir.join(LOG_FILE);
    let file = RotatingFile::open(&path, ROTATE_BYTES, KEEP_ROTATED)?;
    if let Ok(mut g) = SESSION_LOG.lock() {
        *g = Some(file);
    }
    Ok(path)
}

/// Flush and close the session log.
pub fn close_session_log() {
    if let Ok(mut g) = SESSION_LOG.lock() {
        if let Some(f) = g.as_mut() {
            let _ = f.flush();
        }
        *g = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_log_rotates_at_its_size_and_keeps_three_old_files() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(LOG_FILE);
        let mut f = RotatingFile::open(&path, 100, 3).unwrap();
        // 10 lines of 40 bytes: two per 100-byte file, so 5 files written, the oldest 1 dropped.
        for k in 0..10 {
            f.write_all(format!("{:<39}\n", format!("line {k}")).as_bytes()).unwrap();
        }
        f.flush().unwrap();
        let read = |p: PathBuf| std::fs::read_to_string(p).unwrap();
        assert!(read(path.clone()).starts_with("line 8"), "the newest lines in the file itself");
        assert!(read(RotatingFile::rotated_path(&path, 1)).starts_with("line 6"));
        assert!(read(RotatingFile::rotated_path(&path, 2)).starts_with("line 4"));
        assert!(read(RotatingFile::rotated_path(&path, 3)).starts_with("line 2"));
        assert!(!RotatingFile::rotated_path(&path, 4).exists(), "only three rotated files are kept");
        for k in 1..=3 {
            assert!(std::fs::metadata(RotatingFile::rotated_path(&path, k)).unwrap().len() <= 100);
        }
        // Reopening appends and counts what is there.
        drop(f);
        let mut f = RotatingFile::open(&path, 100, 3).unwrap();
        f.write_all(format!("{:<39}\n", "line 10").as_bytes()).unwrap();
        assert!(read(path.clone()).starts_with("line 10"), "80 + 40 bytes > 100: rotated on reopen too");
        assert!(read(RotatingFile::rotated_path(&path, 1)).starts_with("line 8"));
    }
}
