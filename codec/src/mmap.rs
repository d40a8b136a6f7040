//! The crate's only `unsafe`: memory-mapping files (memmap2).

#![allow(unsafe_code)]

use memmap2::{Mmap, MmapMut, MmapOptions, UncheckedAdvice};
use std::fs::File;
use std::io;

/// Maps a whole file read-only.
pub(crate) fn map_read(file: &File) -> io::Result<Mmap> {
    // SAFETY: the mapping is only read through `&[u8]`. Every reader
    // validates what it reads (sizes, offsets, CRCs), so a file changed by
    // another process while mapped gives wrong values or an error, never
    // undefined behaviour in this crate's logic. ltm never truncates a file
    // it has mapped; outputs are written to a temporary file and renamed.
    unsafe { Mmap::map(file) }
}

/// Maps `len` bytes of a file at `offset` for writing.
pub(crate) fn map_write(file: &File, offset: u64, len: usize) -> io::Result<MmapMut> {
    // SAFETY: the file is a private temporary file of this process, opened
    // for writing and already sized to cover `offset + len`; the mapping is
    // dropped before the file is renamed into place.
    unsafe { MmapOptions::new().offset(offset).len(len).map_mut(file) }
}

/// Tells the kernel it may drop the pages of `map[offset..offset + len]`
/// from this process's memory; later reads fetch them from the file again.
pub(crate) fn release(map: &Mmap, offset: usize, len: usize) {
    // SAFETY: a shared, read-only, file-backed mapping: MADV_DONTNEED only
    // drops clean page-cache references, and later accesses re-read the
    // same file contents. No Rust reference into the range is invalidated.
    let _ = unsafe { map.unchecked_advise_range(UncheckedAdvice::DontNeed, offset, len) };
}
