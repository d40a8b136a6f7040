//! Positioned reads and writes (`pread`/`pwrite`) on every platform
//! (`FileExt` on unix, seek + read/write elsewhere), and what every reader
//! of an input file shares: the regular-file check, reads that call a
//! truncated file truncated, and the length-and-time [`Stamp`] that tells
//! whether an input changed while it was read.

use crate::error::{Error, Result};
use std::fs::File;
use std::io;
use std::path::Path;
use std::time::SystemTime;

/// Reads and writes at an offset without a shared cursor (on unix; other
/// platforms seek, so concurrent use of one `File` must be serialized).
pub(crate) trait PositionedIo {
    /// Reads exactly `buf.len()` bytes at `offset`.
    fn read_exact_at(&self, buf: &mut [u8], offset: u64) -> io::Result<()>;
    /// Writes all of `buf` at `offset`.
    fn write_all_at(&self, buf: &[u8], offset: u64) -> io::Result<()>;
}

impl PositionedIo for File {
    #[cfg(unix)]
    fn read_exact_at(&self, buf: &mut [u8], offset: u64) -> io::Result<()> {
        std::os::unix::fs::FileExt::read_exact_at(self, buf, offset)
    }

    #[cfg(unix)]
    fn write_all_at(&self, buf: &[u8], offset: u64) -> io::Result<()> {
        std::os::unix::fs::FileExt::write_all_at(self, buf, offset)
    }

    #[cfg(not(unix))]
    fn read_exact_at(&self, buf: &mut [u8], offset: u64) -> io::Result<()> {
        use std::io::{Read, Seek, SeekFrom};
        let mut f = self;
        f.seek(SeekFrom::Start(offset))?;
        f.read_exact(buf)
    }

    #[cfg(not(unix))]
    fn write_all_at(&self, buf: &[u8], offset: u64) -> io::Result<()> {
        use std::io::{Seek, SeekFrom, Write};
        let mut f = self;
        f.seek(SeekFrom::Start(offset))?;
        f.write_all(buf)
    }
}

/// An input must be a regular file: a folder or a device is an error that
/// says so.
pub(crate) fn check_regular(file: &File, path: &Path) -> Result<()> {
    let meta = file.metadata().map_err(|e| Error::io(path, e))?;
    if !meta.is_file() {
        return Err(Error::io(
            path,
            io::Error::new(
                io::ErrorKind::InvalidInput,
                "not a regular file (a folder or a device)",
            ),
        ));
    }
    Ok(())
}

/// Reads `buf.len()` bytes at `offset` of `file`; a file that ends too early
/// (truncated since it was opened) is an error that says so, never a signal.
pub(crate) fn read_at(file: &File, path: &Path, buf: &mut [u8], offset: u64) -> Result<()> {
    file.read_exact_at(buf, offset).map_err(|e| {
        if e.kind() != io::ErrorKind::UnexpectedEof {
            return Error::io(path, e);
        }
        let now = file
            .metadata()
            .map_or_else(|_| "unknown".into(), |m| m.len().to_string());
        let end = offset + buf.len() as u64;
        Error::io(
            path,
            io::Error::new(
                e.kind(),
                format!("bytes {offset}..{end} lie past the end of the file (now {now} bytes): it was truncated while being read"),
            ),
        )
    })
}

/// A file's length and modification time, taken at open and compared after
/// a pass over it ([`Stamp::check_unchanged`]) to detect a change of the
/// input while it was read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Stamp {
    pub(crate) len: u64,
    pub(crate) modified: Option<SystemTime>,
}

impl Stamp {
    /// The length and modification time of `file` now.
    pub(crate) fn of(file: &File, path: &Path) -> Result<Stamp> {
        let m = file.metadata().map_err(|e| Error::io(path, e))?;
        Ok(Stamp {
            len: m.len(),
            modified: m.modified().ok(),
        })
    }

    /// Checks that `file` still has this length and modification time: a
    /// run that read it fails rather than use an input that changed
    /// meanwhile.
    pub(crate) fn check_unchanged(&self, file: &File, path: &Path) -> Result<()> {
        let now = Stamp::of(file, path)?;
        if now == *self {
            return Ok(());
        }
        let detail = if now.len != self.len {
            format!("its length went from {} to {} bytes", self.len, now.len)
        } else {
            "its modification time changed".into()
        };
        Err(Error::io(
            path,
            io::Error::other(format!(
                "the file changed while it was read ({detail}); no output is written from a changed input"
            )),
        ))
    }
}
