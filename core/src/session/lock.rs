//! The lock that keeps a session folder to one photorobot at a time: an exclusive lock on
//! `session.lock` in the folder, held while a session is open in the workbench or measured into
//! by the command line. A second program refused the lock gets an error naming the folder and
//! the process that holds it. The operating system drops the lock when the holder exits, even
//! after a crash, so a stale lock file never blocks anyone. Whoever takes the lock removes the
//! temporary files an earlier holder left when it was killed in the middle of an atomic save.

use super::SessionError;
use crate::files::FileError;
use fs4::TryLockError;
use std::fs::{File, OpenOptions};
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

/// Name of the lock file in a session folder.
pub const LOCK_FILE: &str = "session.lock";

/// An exclusive hold on a session folder; released when dropped.
#[derive(Debug)]
pub struct FolderLock {
    dir: PathBuf,
    /// Holds the lock while it is open.
    _file: File,
}

impl FolderLock {
    /// Lock `dir` (created if needed) for this process, or say who holds it.
    pub fn acquire(dir: &Path) -> Result<Self, SessionError> {
        let io = |action: &'static str, file: &Path| {
            let file = file.to_path_buf();
            move |source| SessionError::File(FileError::Io { file, action, source })
        };
        std::fs::create_dir_all(dir).map_err(io("cannot create the folder", dir))?;
        let path = dir.join(LOCK_FILE);
        let mut file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .map_err(io("cannot open the lock file", &path))?;
        // fs4's lock is the operating system's (flock on Unix, LockFileEx on Windows), as std's
        // `File::try_lock` is from Rust 1.89, above this workspace's minimum Rust version.
        match fs4::FileExt::try_lock(&file) {
            Ok(()) => {}
            Err(TryLockError::WouldBlock) => {
                let mut holder = String::new();
                let _ = file.read_to_string(&mut holder);
                let pid = holder.trim().parse::<u32>().ok();
                return Err(SessionError::Locked { dir: dir.to_path_buf(), pid });
            }
            Err(TryLockError::Error(e)) => return Err(io("cannot lock", &path)(e)),
        }
        // Who holds it, for the message a second program shows.
        let pid = std::process::id().to_string();
        file.set_len(0)
            .and_then(|()| file.seek(SeekFrom::Start(0)))
            .and_then(|_| file.write_all(pid.as_bytes()))
            .map_err(io("cannot write", &path))?;
        remove_stray_temporaries(dir);
        remove_stray_temporaries(&dir.join(super::TRACES_DIR));
        Ok(Self { dir: dir.to_path_buf(), _file: file })
    }

    /// The folder held.
    pub fn dir(&self) -> &Path {
        &self.dir
    }
}

/// Remove the `.NAME.XXXXXX.tmp` files of interrupted atomic saves (`files::write_atomic`) from
/// `dir`. Only the lock holder writes there, so none of them belongs to a save in progress. Best
/// effort: a file that cannot be removed stays, and the session is unaffected by it.
fn remove_stray_temporaries(dir: &Path) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for entry in entries.flatten() {
        let name = entry.file_name();
        let name = name.to_string_lossy();
        let is_file = entry.file_type().is_ok_and(|t| t.is_file());
        if is_file && name.starts_with('.') && name.ends_with(".tmp") {
            match std::fs::remove_file(entry.path()) {
                Ok(()) => tracing::info!("removed {}, left by an interrupted save", entry.path().display()),
                Err(e) => tracing::warn!("cannot remove {}: {e}", entry.path().display()),
            }
        }
    }
}

/// The message of [`SessionError::Locked`].
pub(super) fn locked_message(dir: &Path, pid: Option<u32>) -> String {
    let by = pid.map_or_else(|| "another photorobot".to_string(), |p| format!("another photorobot (process {p})"));
    format!("{}: the session folder is open in {by}; close it there first, or choose another folder", dir.display())
}
