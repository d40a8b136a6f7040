//! The files a command names, declared before any work starts
//! ([`ltm_codec::RunFiles`]): an output must not be an input or another
//! output, must be a regular file path in an existing writable folder, and
//! is locked for the run.

use anyhow::Result;
use ltm_codec::{Claim, RunFiles};
use std::path::Path;

/// Checks and claims a command's files before it does any work.
/// `inputs` and `outputs` are (role, path) pairs, the role as the command
/// line names it (e.g. "--env", "-o"). Hold the returned claim until the
/// outputs are written: it holds their locks.
pub fn claim_files(inputs: &[(&str, &Path)], outputs: &[(&str, &Path)]) -> Result<Claim> {
    claim_files_and_cache(inputs, outputs, None)
}

/// [`claim_files`] with a cache beside the outputs (`RunFiles::cache`):
/// checked like them, but shared with concurrent runs rather than locked.
pub fn claim_files_and_cache(
    inputs: &[(&str, &Path)],
    outputs: &[(&str, &Path)],
    cache: Option<(&str, &Path)>,
) -> Result<Claim> {
    let mut files = RunFiles::new();
    for (role, path) in inputs {
        files = files.input(role, path);
    }
    for (role, path) in outputs {
        files = files.output(role, path);
    }
    if let Some((role, path)) = cache {
        files = files.cache(role, path);
    }
    Ok(files.claim()?)
}

/// [`claim_files`] for a command that writes a folder of files (`-o DIR`).
pub fn claim_folder(inputs: &[(&str, &Path)], role: &str, dir: &Path) -> Result<Claim> {
    let mut files = RunFiles::new();
    for (r, path) in inputs {
        files = files.input(r, path);
    }
    Ok(files.output_folder(role, dir).claim()?)
}
