//! A run's files, declared before any work: [`RunFiles`] checks them and
//! [`RunFiles::claim`] locks the outputs.

use super::lock::OutputLock;
use super::parent_of;
use crate::error::{Error, Result};
use std::path::{Path, PathBuf};

/// Where a path leads: the file's identity when it exists, else the
/// canonical path it would be created at.
#[derive(PartialEq, Eq, Debug)]
enum Target {
    /// Device and inode (on unix; elsewhere zero), and the canonical path.
    File(u64, u64, PathBuf),
    New(PathBuf),
}

fn target(role: &str, path: &Path) -> Result<Target> {
    match std::fs::metadata(path) {
        Ok(meta) => {
            let canonical = path.canonicalize().unwrap_or_else(|_| path.to_path_buf());
            #[cfg(unix)]
            let id = {
                use std::os::unix::fs::MetadataExt;
                (meta.dev(), meta.ino())
            };
            #[cfg(not(unix))]
            let id = {
                let _ = meta;
                (0, 0)
            };
            Ok(Target::File(id.0, id.1, canonical))
        }
        Err(_) => {
            let parent = parent_of(path);
            let name = path
                .file_name()
                .ok_or_else(|| refused(role, path, "is not a file path"))?;
            let dir = parent.canonicalize().map_err(|_| {
                refused(
                    role,
                    path,
                    &format!("the folder {} does not exist", parent.display()),
                )
            })?;
            Ok(Target::New(dir.join(name)))
        }
    }
}

fn same(a: &Target, b: &Target) -> bool {
    match (a, b) {
        (Target::File(d1, i1, p1), Target::File(d2, i2, p2)) => {
            (cfg!(unix) && (d1, i1) == (d2, i2)) || p1 == p2
        }
        (Target::New(p1), Target::New(p2)) => p1 == p2,
        _ => false,
    }
}

fn refused(role: &str, path: &Path, reason: &str) -> Error {
    Error::Output {
        role: role.into(),
        path: path.into(),
        reason: reason.into(),
    }
}

/// One declared output.
#[derive(Clone, Debug)]
struct Output {
    role: String,
    path: PathBuf,
    /// The final size when known in advance, for the free-space check.
    size: Option<u64>,
    /// A folder the run writes its files into (created when missing).
    folder: bool,
    /// Taken by a lock for the run ([`OutputLock`]); a cache is not.
    locked: bool,
}

/// The inputs and outputs of one run, checked together before any work
/// (see [`RunFiles::claim`]).
#[derive(Clone, Debug, Default)]
pub struct RunFiles {
    inputs: Vec<(String, PathBuf)>,
    outputs: Vec<Output>,
}

/// The claimed outputs of a run: their locks, held until dropped.
#[derive(Debug)]
pub struct Claim {
    _locks: Vec<OutputLock>,
}

impl RunFiles {
    /// An empty plan.
    pub fn new() -> RunFiles {
        RunFiles::default()
    }

    /// Declares an input; `role` is how the command line names it.
    pub fn input(mut self, role: &str, path: &Path) -> RunFiles {
        self.inputs.push((role.into(), path.into()));
        self
    }

    /// Declares an output of unknown size.
    pub fn output(mut self, role: &str, path: &Path) -> RunFiles {
        self.outputs.push(Output {
            role: role.into(),
            path: path.into(),
            size: None,
            folder: false,
            locked: true,
        });
        self
    }

    /// Declares a folder the run writes files into (`ltm report -o DIR`):
    /// it must be a folder or not exist yet; it is locked like a file
    /// output (`DIR.lock`), so that two runs never mix their files in it.
    pub fn output_folder(mut self, role: &str, path: &Path) -> RunFiles {
        self.outputs.push(Output {
            role: role.into(),
            path: path.into(),
            size: None,
            folder: true,
            locked: true,
        });
        self
    }

    /// Declares a cache: a file that runs of the same settings read, and
    /// write when it is missing or stale. It is checked like an output but
    /// not locked, so that concurrent runs can share it: each writes it
    /// whole under a unique temporary name and renames it, so a reader
    /// sees one complete file, and a run checks what it reads.
    pub fn cache(mut self, role: &str, path: &Path) -> RunFiles {
        self.outputs.push(Output {
            role: role.into(),
            path: path.into(),
            size: None,
            folder: false,
            locked: false,
        });
        self
    }

    /// Declares an output whose final size is `bytes`.
    pub fn output_sized(mut self, role: &str, path: &Path, bytes: u64) -> RunFiles {
        self.outputs.push(Output {
            role: role.into(),
            path: path.into(),
            size: Some(bytes),
            folder: false,
            locked: true,
        });
        self
    }

    /// Checks every output, then locks them all:
    /// - it is a file path in an existing folder where files can be created;
    /// - it is not an input nor another output (by canonical path and by
    ///   device and inode, so hard and symbolic links count);
    /// - an existing output is a regular file, not a folder, device, FIFO
    ///   or socket;
    /// - its filesystem has room for its known size;
    /// - no other run holds its lock ([`OutputLock`]); caches take none.
    pub fn claim(self) -> Result<Claim> {
        let ins: Vec<Target> = self
            .inputs
            .iter()
            .map(|(role, p)| target(role, p))
            .collect::<Result<_>>()?;
        let mut outs: Vec<Target> = Vec::with_capacity(self.outputs.len());
        for o in &self.outputs {
            if o.folder {
                check_folder(&o.role, &o.path)?;
                continue;
            }
            check_kind(&o.role, &o.path)?;
            check_writable(&o.role, &o.path)?;
            let t = target(&o.role, &o.path)?;
            if let Some(k) = ins.iter().position(|i| same(i, &t)) {
                let (role, input) = &self.inputs[k];
                let why = format!(
                    "is the input {role} {}: refusing to overwrite an input",
                    input.display()
                );
                return Err(refused(&o.role, &o.path, &why));
            }
            if let Some(k) = outs.iter().position(|x| same(x, &t)) {
                let other = &self.outputs[k];
                let why = format!(
                    "and {} {} name the same file: give each output its own path",
                    other.role,
                    other.path.display()
                );
                return Err(refused(&o.role, &o.path, &why));
            }
            if let Some(bytes) = o.size {
                check_space(&o.path, bytes)?;
            }
            outs.push(t);
        }
        let locks = self
            .outputs
            .iter()
            .filter(|o| o.locked)
            .map(|o| OutputLock::acquire(&o.path))
            .collect::<Result<_>>()?;
        Ok(Claim { _locks: locks })
    }
}

/// An existing output must be a regular file (or a link to one, which is
/// replaced, its target untouched); a folder, device, FIFO or socket is
/// refused: outputs are written to a temporary file and renamed, which
/// would replace the device node instead of writing to it.
pub(crate) fn check_kind(role: &str, path: &Path) -> Result<()> {
    let Ok(meta) = std::fs::metadata(path) else {
        return Ok(());
    };
    let kind = if meta.is_file() {
        return Ok(());
    } else if meta.is_dir() {
        "is a folder: give a file path"
    } else {
        special_kind(&meta)
    };
    Err(refused(role, path, kind))
}

#[cfg(unix)]
fn special_kind(meta: &std::fs::Metadata) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    let t = meta.file_type();
    if t.is_fifo() {
        "is a FIFO or pipe: ltm writes regular files only (write to a file, then copy it)"
    } else if t.is_socket() {
        "is a socket: ltm writes regular files only"
    } else {
        "is a device: ltm writes regular files only (write to a file, then copy it)"
    }
}

#[cfg(not(unix))]
fn special_kind(_meta: &std::fs::Metadata) -> &'static str {
    "is not a regular file: ltm writes regular files only"
}

/// An output folder must be a folder, or not exist yet in a folder that
/// does.
fn check_folder(role: &str, path: &Path) -> Result<()> {
    match std::fs::metadata(path) {
        Ok(m) if m.is_dir() => Ok(()),
        Ok(_) => Err(refused(
            role,
            path,
            "is not a folder: give a folder path (it is created when missing)",
        )),
        Err(_) => check_writable(role, path),
    }
}

/// An output must be in an existing folder where a file can be created.
fn check_writable(role: &str, path: &Path) -> Result<()> {
    let dir = parent_of(path);
    if !dir.is_dir() {
        let why = format!("the folder {} does not exist", dir.display());
        return Err(refused(role, path, &why));
    }
    tempfile::Builder::new()
        .prefix(".ltm-write-check")
        .tempfile_in(dir)
        .map_err(|e| {
            refused(
                role,
                path,
                &format!("cannot create files in {}: {e}", dir.display()),
            )
        })?;
    Ok(())
}

/// Fails when the filesystem of `path` has less than `bytes` free, less
/// what an existing `PATH.partial` already holds (it is written in place).
pub fn check_space(path: &Path, bytes: u64) -> Result<()> {
    let partial = super::partial_path(path);
    let have = std::fs::symlink_metadata(&partial).map_or(0, |m| allocated(&m));
    let need = bytes.saturating_sub(have);
    match free_bytes(parent_of(path)) {
        Some(free) if free < need => Err(Error::NoSpace {
            path: path.into(),
            need,
            free,
        }),
        _ => Ok(()),
    }
}

#[cfg(unix)]
fn allocated(m: &std::fs::Metadata) -> u64 {
    use std::os::unix::fs::MetadataExt;
    m.blocks().saturating_mul(512)
}

#[cfg(not(unix))]
fn allocated(m: &std::fs::Metadata) -> u64 {
    m.len()
}

/// Bytes available to this user on `dir`'s filesystem (`statvfs`), when
/// the system says.
#[cfg(unix)]
fn free_bytes(dir: &Path) -> Option<u64> {
    let s = rustix::fs::statvfs(dir).ok()?;
    Some(s.f_bavail.saturating_mul(s.f_frsize))
}

#[cfg(not(unix))]
fn free_bytes(_dir: &Path) -> Option<u64> {
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    fn claim(inputs: &[&Path], outputs: &[(&str, &Path)]) -> Result<Claim> {
        let mut plan = RunFiles::new();
        for i in inputs {
            plan = plan.input("input", i);
        }
        for (role, o) in outputs {
            plan = plan.output(role, o);
        }
        plan.claim()
    }

    #[test]
    fn outputs_that_name_inputs_or_each_other_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let a = dir.path().join("a.raw");
        std::fs::write(&a, b"x").unwrap();
        let link = dir.path().join("hard.raw");
        std::fs::hard_link(&a, &link).unwrap();
        let sub = dir.path().join("sub");
        std::fs::create_dir(&sub).unwrap();
        let dotted = sub.join("../a.raw");
        let new = dir.path().join("new.ltm");
        assert!(claim(&[&a], &[("-o", &new)]).is_ok());
        for bad in [&a, &link, &dotted] {
            let e = claim(&[&a], &[("-o", bad)]).unwrap_err().to_string();
            assert!(e.contains("refusing to overwrite an input"), "{e}");
        }
        #[cfg(unix)]
        {
            let sym = dir.path().join("sym.raw");
            std::os::unix::fs::symlink(&a, &sym).unwrap();
            assert!(claim(&[&a], &[("-o", &sym)]).is_err());
        }
        let twice = sub.join("../new.ltm");
        let e = claim(&[&a], &[("-o", &new), ("--png", &twice)])
            .unwrap_err()
            .to_string();
        assert!(e.contains("name the same file"), "{e}");
        let e = claim(&[&a], &[("-o", &sub)]).unwrap_err().to_string();
        assert!(e.contains("is a folder"), "{e}");
        let missing = dir.path().join("missing/x.ltm");
        let e = claim(&[&a], &[("-o", &missing)]).unwrap_err().to_string();
        assert!(e.contains("does not exist"), "{e}");
    }

    #[cfg(unix)]
    #[test]
    fn devices_fifos_and_pipes_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let dev = dir.path().join("null");
        std::os::unix::fs::symlink("/dev/null", &dev).unwrap();
        let fifo = dir.path().join("fifo");
        rustix::fs::mknodat(
            rustix::fs::CWD,
            &fifo,
            rustix::fs::FileType::Fifo,
            rustix::fs::Mode::from_raw_mode(0o600),
            0,
        )
        .unwrap();
        for (out, word) in [(&dev, "device"), (&fifo, "FIFO")] {
            let e = claim(&[], &[("-o", out)]).unwrap_err().to_string();
            assert!(e.contains(word), "{e}");
        }
        assert!(std::fs::symlink_metadata(&dev)
            .unwrap()
            .file_type()
            .is_symlink());
    }

    #[test]
    fn a_second_claim_of_an_output_is_busy_until_the_first_ends() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("o.raw");
        let first = claim(&[], &[("-o", &out)]).unwrap();
        let lock = super::super::lock::lock_path(&out);
        let other = std::fs::File::open(&lock).unwrap();
        #[cfg(unix)]
        assert!(
            rustix::fs::flock(&other, rustix::fs::FlockOperation::NonBlockingLockExclusive)
                .is_err()
        );
        drop(other);
        drop(first);
        assert!(!lock.exists());
    }

    /// A cache is shared by concurrent runs (no lock), but it is still
    /// never an input, another output or a folder.
    #[test]
    fn a_cache_is_shared_but_checked_like_an_output() {
        let dir = tempfile::tempdir().unwrap();
        let (input, cache) = (dir.path().join("in.ltm"), dir.path().join("rot.bin"));
        std::fs::write(&input, b"x").unwrap();
        let run = || {
            RunFiles::new()
                .input("input", &input)
                .cache("--cache", &cache)
        };
        let (first, second) = (run().claim().unwrap(), run().claim().unwrap());
        assert!(!super::super::lock::lock_path(&cache).exists());
        drop((first, second));
        let on_input = RunFiles::new()
            .input("input", &input)
            .cache("--cache", &input);
        let e = on_input.claim().unwrap_err().to_string();
        assert!(e.contains("refusing to overwrite an input"), "{e}");
        let e = RunFiles::new()
            .output("-o", &cache)
            .cache("--cache", &cache)
            .claim()
            .unwrap_err()
            .to_string();
        assert!(e.contains("name the same file"), "{e}");
        let e = RunFiles::new()
            .cache("--cache", dir.path())
            .claim()
            .unwrap_err()
            .to_string();
        assert!(e.contains("is a folder"), "{e}");
    }

    #[test]
    fn an_output_larger_than_the_free_space_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("huge.raw");
        let e = RunFiles::new()
            .output_sized("-o", &out, u64::MAX / 2)
            .claim()
            .unwrap_err();
        assert!(matches!(e, Error::NoSpace { .. }), "{e}");
        assert!(RunFiles::new().output_sized("-o", &out, 1).claim().is_ok());
    }
}
