//! Writing outputs safely; every command's outputs pass through here.
//!
//! - [`RunFiles`]: a run declares its inputs and outputs before any work, and
//!   [`RunFiles::claim`] checks them (not an input, not another output, a
//!   regular file in a writable folder, room on the disk) and locks them.
//! - [`OutputLock`]: one advisory lock per output, `PATH.lock`, so that two
//!   runs never write one output at once.
//! - [`AtomicFile`]: an output written whole or not at all, under a unique
//!   temporary name created with `O_EXCL`, renamed into place on commit.
//!
//! The raw store's resumable `PATH.partial` ([`crate::RawWriter`]) takes
//! the same lock, is never opened through a symbolic link, and must be a
//! regular file.

mod atomic;
mod lock;
mod plan;

pub use atomic::AtomicFile;
pub use lock::{lock_path, OutputLock};
pub(crate) use plan::check_kind;
pub use plan::{check_space, Claim, RunFiles};

use std::path::{Path, PathBuf};

/// The folder a path is in (`.` for a bare file name).
pub(crate) fn parent_of(path: &Path) -> &Path {
    path.parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."))
}

/// The name a resumable output is written under until complete:
/// `PATH.partial` (see docs/FORMAT.md).
pub fn partial_path(path: &Path) -> PathBuf {
    let mut s = path.as_os_str().to_owned();
    s.push(".partial");
    PathBuf::from(s)
}
