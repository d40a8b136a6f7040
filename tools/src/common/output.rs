//! Output files: written whole or not at all, under unique temporary names
//! ([`ltm_codec::AtomicFile`]).

use anyhow::{Context, Result};
use ltm_codec::AtomicFile;
use std::io::Write as _;
use std::path::Path;

/// Writes `bytes` to `path` atomically: a unique temporary file beside it,
/// synced, then renamed over it (removed again on failure).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let write = || -> Result<()> {
        let mut f = AtomicFile::create(path)?;
        f.file().write_all(bytes)?;
        f.commit()?;
        Ok(())
    };
    write().with_context(|| format!("writing {}", path.display()))
}
