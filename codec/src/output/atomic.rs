//! Output files written whole or not at all: a unique temporary file beside
//! the final path (so that concurrent runs never share one, and the rename
//! stays on one filesystem), synced, then renamed into place. A file
//! dropped before [`AtomicFile::commit`] is removed, on success paths and
//! error paths alike. The output's lock ([`OutputLock`]) is held from
//! creation to commit or drop, except by a cache
//! ([`AtomicFile::create_shared`]).

use super::lock::OutputLock;
use crate::error::{Error, Result};
use std::fs::File;
use std::path::{Path, PathBuf};

/// An output being written; see the module docs.
pub struct AtomicFile {
    tmp: tempfile::NamedTempFile,
    path: PathBuf,
    _lock: Option<OutputLock>,
}

impl AtomicFile {
    /// Creates a temporary file for `path` in `path`'s folder, after
    /// checking that an existing `path` is a regular file and taking its
    /// lock.
    pub fn create(path: &Path) -> Result<AtomicFile> {
        AtomicFile::open(path, true)
    }

    /// [`AtomicFile::create`] for a cache that concurrent runs share
    /// (`RunFiles::cache`): no lock is taken, and of two writers the last
    /// rename wins, each file whole.
    pub fn create_shared(path: &Path) -> Result<AtomicFile> {
        AtomicFile::open(path, false)
    }

    fn open(path: &Path, locked: bool) -> Result<AtomicFile> {
        let name = path
            .file_name()
            .ok_or_else(|| Error::Invalid(format!("{}: not a file path", path.display())))?;
        super::check_kind("output", path)?;
        let lock = match locked {
            true => Some(OutputLock::acquire(path)?),
            false => None,
        };
        let dir = super::parent_of(path);
        let prefix = format!(".{}.", name.to_string_lossy());
        let mut builder = tempfile::Builder::new();
        builder.prefix(&prefix).suffix(".tmp");
        // Like `File::create`: readable by others unless the umask says no.
        #[cfg(unix)]
        builder.permissions(std::os::unix::fs::PermissionsExt::from_mode(0o666));
        let tmp = builder.tempfile_in(dir).map_err(|e| Error::io(path, e))?;
        Ok(AtomicFile {
            tmp,
            path: path.into(),
            _lock: lock,
        })
    }

    /// The open temporary file.
    pub fn file(&mut self) -> &mut File {
        self.tmp.as_file_mut()
    }

    /// The temporary file's path (for messages).
    pub fn tmp_path(&self) -> &Path {
        self.tmp.path()
    }

    /// The final path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Syncs the file and renames it to its final path.
    pub fn commit(self) -> Result<()> {
        self.tmp
            .as_file()
            .sync_all()
            .map_err(|e| Error::io(self.tmp.path(), e))?;
        let path = self.path;
        self.tmp
            .persist(&path)
            .map_err(|e| Error::io(&path, e.error))?;
        Ok(())
    }
}

impl std::io::Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.tmp.as_file_mut().write(buf)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.tmp.as_file_mut().flush()
    }
}

impl std::io::Seek for AtomicFile {
    fn seek(&mut self, pos: std::io::SeekFrom) -> std::io::Result<u64> {
        self.tmp.as_file_mut().seek(pos)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    #[test]
    fn committed_files_appear_whole_and_dropped_ones_vanish() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("a.bin");
        // Two writers of one process share the output's lock.
        let mut a = AtomicFile::create(&out).unwrap();
        let mut b = AtomicFile::create(&out).unwrap();
        assert_ne!(
            a.tmp_path(),
            b.tmp_path(),
            "two writers share a temporary name"
        );
        a.file().write_all(b"first").unwrap();
        b.file().write_all(b"second").unwrap();
        assert!(!out.exists());
        b.commit().unwrap();
        assert_eq!(std::fs::read(&out).unwrap(), b"second");
        drop(a);
        assert_eq!(std::fs::read(&out).unwrap(), b"second");
        let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(names.len(), 1, "a temporary or lock file was left behind");
    }
}
