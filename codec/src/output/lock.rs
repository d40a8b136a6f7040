//! One advisory lock per output: `PATH.lock`, held with `flock` for as long
//! as a run writes `PATH` (or its `PATH.partial`), removed when released.
//!
//! A second run that wants the same output fails at once with
//! [`Error::OutputBusy`] instead of writing beside the first. Within one
//! process the lock is re-entrant: the command's up-front
//! [`super::RunFiles::claim`] and the writer that later creates the file share
//! one lock, so libraries can take it themselves and commands can take it
//! before any work.
//!
//! Releasing removes the lock file before closing it; taking it checks,
//! after `flock` succeeds, that the path still names the locked file, and
//! retries otherwise, so that a run never holds a lock on a file that
//! another run has already removed.

use crate::error::{Error, Result};
use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, Weak};

/// The locks this process holds, by lock-file path, so that taking a lock
/// twice shares it instead of deadlocking against itself.
static HELD: Mutex<Vec<(PathBuf, Weak<Held>)>> = Mutex::new(Vec::new());

/// A locked `PATH.lock`; removed, then unlocked, when dropped.
#[derive(Debug)]
struct Held {
    lock: PathBuf,
    _file: File,
}

impl Drop for Held {
    fn drop(&mut self) {
        // Remove before the file closes (which unlocks it): a run waiting
        // on this file then sees that the path moved on and retries.
        let _ = std::fs::remove_file(&self.lock);
    }
}

/// The exclusive right to write one output; see the module docs.
#[derive(Clone, Debug)]
pub struct OutputLock(Arc<Held>);

/// The lock file of `path`: `PATH.lock` in the same folder.
pub fn lock_path(path: &Path) -> PathBuf {
    let mut s = path.as_os_str().to_owned();
    s.push(".lock");
    PathBuf::from(s)
}

impl OutputLock {
    /// Takes the lock of `path` (see the module docs), or shares it when
    /// this process holds it already.
    pub fn acquire(path: &Path) -> Result<OutputLock> {
        let lock = canonical_lock(path)?;
        let mut held = HELD.lock().unwrap_or_else(|p| p.into_inner());
        held.retain(|(_, w)| w.strong_count() > 0);
        if let Some(h) = held
            .iter()
            .find(|(p, _)| *p == lock)
            .and_then(|(_, w)| w.upgrade())
        {
            return Ok(OutputLock(h));
        }
        let file = take(&lock, path)?;
        let h = Arc::new(Held {
            lock: lock.clone(),
            _file: file,
        });
        held.push((lock, Arc::downgrade(&h)));
        Ok(OutputLock(h))
    }

    /// The lock file.
    pub fn path(&self) -> &Path {
        &self.0.lock
    }
}

/// `PATH.lock` with its folder made canonical, so that two spellings of
/// one output share one registry entry.
fn canonical_lock(path: &Path) -> Result<PathBuf> {
    let name = path
        .file_name()
        .ok_or_else(|| Error::Invalid(format!("{}: not a file path", path.display())))?;
    let dir = super::parent_of(path);
    let dir = dir.canonicalize().map_err(|e| Error::Output {
        role: "output".into(),
        path: path.into(),
        reason: format!("its folder {}: {e}", dir.display()),
    })?;
    Ok(lock_path(&dir.join(name)))
}

#[cfg(unix)]
fn take(lock: &Path, path: &Path) -> Result<File> {
    use rustix::fs::{flock, FlockOperation};
    use std::os::unix::fs::{MetadataExt, OpenOptionsExt};
    let io = |e| Error::io(lock, e);
    for _ in 0..16 {
        let file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .custom_flags(rustix::fs::OFlags::NOFOLLOW.bits() as i32)
            .open(lock)
            .map_err(|e| refuse_link(lock, e))?;
        if !file.metadata().map_err(io)?.is_file() {
            return Err(Error::Output {
                role: "lock".into(),
                path: lock.into(),
                reason: "is not a regular file; remove it".into(),
            });
        }
        match flock(&file, FlockOperation::NonBlockingLockExclusive) {
            Ok(()) => {}
            Err(rustix::io::Errno::WOULDBLOCK) => {
                return Err(Error::OutputBusy {
                    path: path.into(),
                    lock: lock.into(),
                })
            }
            Err(e) => return Err(io(e.into())),
        }
        let ours = file.metadata().map_err(io)?;
        // The holder before us may have removed the file after we opened
        // it: then the lock we hold is on a file no one else will see.
        if let Ok(now) = std::fs::symlink_metadata(lock) {
            if (now.dev(), now.ino()) == (ours.dev(), ours.ino()) {
                return Ok(file);
            }
        }
    }
    Err(Error::OutputBusy {
        path: path.into(),
        lock: lock.into(),
    })
}

/// `open` with `O_NOFOLLOW` on a symbolic link fails with `ELOOP`: say so.
#[cfg(unix)]
fn refuse_link(lock: &Path, e: std::io::Error) -> Error {
    if e.raw_os_error() == Some(rustix::io::Errno::LOOP.raw_os_error()) {
        return Error::Output {
            role: "lock".into(),
            path: lock.into(),
            reason: "is a symbolic link: refusing to write through it; remove it".into(),
        };
    }
    Error::io(lock, e)
}

#[cfg(not(unix))]
fn take(lock: &Path, _path: &Path) -> Result<File> {
    std::fs::OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(false)
        .open(lock)
        .map_err(|e| Error::io(lock, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_second_holder_is_refused_and_the_lock_file_goes_with_the_last() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("a.raw");
        let a = OutputLock::acquire(&out).unwrap();
        // Re-entrant within the process, also under another spelling.
        let b = OutputLock::acquire(&dir.path().join(".").join("a.raw")).unwrap();
        assert!(a.path().exists());
        // Another open file description on the same file cannot lock it.
        let other = File::open(a.path()).unwrap();
        let e = rustix::fs::flock(&other, rustix::fs::FlockOperation::NonBlockingLockExclusive);
        assert_eq!(e, Err(rustix::io::Errno::WOULDBLOCK));
        drop(other);
        drop(a);
        assert!(b.path().exists(), "released while still shared");
        let lock = b.path().to_path_buf();
        drop(b);
        assert!(!lock.exists(), "the lock file was left behind");
        let again = OutputLock::acquire(&out).unwrap();
        drop(again);
    }

    #[test]
    fn a_lock_path_that_is_a_symlink_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let victim = dir.path().join("victim");
        std::fs::write(&victim, b"keep").unwrap();
        let out = dir.path().join("b.raw");
        std::os::unix::fs::symlink(&victim, lock_path(&out)).unwrap();
        let e = OutputLock::acquire(&out).unwrap_err().to_string();
        assert!(e.contains("symbolic link"), "{e}");
        assert_eq!(std::fs::read(&victim).unwrap(), b"keep");
    }
}
