//! The crate's only `unsafe`: memory-mapping files (memmap2).

#![allow(unsafe_code)]

use memmap2::{Mmap, UncheckedAdvice};
use std::fs::File;
use std::io;

/// Maps a whole regular file read-only (a folder or a device is an error
/// that says so, not the system's "No such device").
pub(crate) fn map_read(file: &File) -> io::Result<Mmap> {
    check_regular(file)?;
    // SAFETY: this assumes that the file is not modified or truncated while
    // it is mapped, which Rust's aliasing rules for the `&[u8]` we hand out
    // require and nothing here can enforce: a change by another process is
    // undefined behaviour in principle, and truncation raises SIGBUS on
    // access. ltm itself never writes to or truncates a file it has mapped
    // for reading (outputs go to a temporary file that is renamed into
    // place), and docs/FORMAT.md tells users not to change inputs during a
    // run. Readers still validate what they read (sizes, offsets, CRCs), so
    // a file that was complete but wrong gives an error.
    unsafe { Mmap::map(file) }
}

/// An input must be a regular file: a folder or a device is an error that
/// says so.
pub(crate) fn check_regular(file: &File) -> io::Result<()> {
    if !file.metadata()?.is_file() {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            "not a regular file (a folder or a device)",
        ));
    }
    Ok(())
}

/// Tells the kernel it may drop the pages of `map[offset..offset + len]`
/// from this process's memory; later reads fetch them from the file again.
pub(crate) fn release(map: &Mmap, offset: usize, len: usize) {
    // SAFETY: a shared, read-only, file-backed mapping: MADV_DONTNEED only
    // drops clean page-cache references, and later accesses re-read the
    // same file contents. No Rust reference into the range is invalidated.
    let _ = unsafe { map.unchecked_advise_range(UncheckedAdvice::DontNeed, offset, len) };
}
