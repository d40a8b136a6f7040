//! A small disk that fills up: a 1 MiB tmpfs mounted for a test's lifetime.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// A 1 MiB tmpfs mounted at [`SmallDisk::path`] until dropped.
pub struct SmallDisk {
    path: PathBuf,
    _dir: tempfile::TempDir,
}

impl SmallDisk {
    /// Mounts the filesystem, or returns `None` where mounting is not
    /// allowed (not root). CI runs as root, so there a failed mount fails
    /// the test instead of skipping it.
    pub fn mount() -> Option<SmallDisk> {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("small");
        std::fs::create_dir(&path).unwrap();
        let ok = Command::new("mount")
            .args(["-t", "tmpfs", "-o", "size=1m", "tmpfs"])
            .arg(&path)
            .status()
            .is_ok_and(|s| s.success());
        if !ok {
            assert!(
                std::env::var_os("CI").is_none(),
                "CI must be able to mount a small tmpfs for the disk-full tests"
            );
            eprintln!("skipped: cannot mount a tmpfs here (not root)");
            return None;
        }
        Some(SmallDisk { path, _dir: dir })
    }

    /// The mount point.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Fills the disk to its last byte with one file, `filler`.
    pub fn fill(&self) {
        use std::io::Write as _;
        let mut f = std::fs::File::create(self.path.join("filler")).unwrap();
        let chunk = vec![1u8; 4096];
        while f.write_all(&chunk).is_ok() {}
        while f.write_all(&chunk[..1]).is_ok() {}
    }

    /// The names in the disk's root folder, sorted.
    pub fn files(&self) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(&self.path)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }
}

impl Drop for SmallDisk {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg(&self.path).status();
    }
}

/// Checks that a run failed with a message that names the full disk (the
/// system's, or the free-space check's), by an exit code rather than a
/// signal.
pub fn assert_disk_full_error(out: &Output, what: &str) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.code() == Some(1),
        "{what}: expected exit code 1, got {:?} (a signal?): {stderr}",
        out.status
    );
    assert!(
        stderr.contains("No space left on device") || stderr.contains("bytes free"),
        "{what}: the message does not name the full disk: {stderr}"
    );
}
