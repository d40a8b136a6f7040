//! Checks on the files a command names, made before any work starts: an
//! output must not be an input or another output (compared by canonical
//! path and by file identity, which also catches hard links and symbolic
//! links), and must be a writable file path in an existing folder.

use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};

/// Where a path leads: the file's identity when it exists, else the
/// canonical path it would be created at.
#[derive(PartialEq, Eq, Debug)]
enum Target {
    /// Device and inode (on unix; elsewhere the canonical path).
    File(u64, u64, PathBuf),
    New(PathBuf),
}

fn target(path: &Path) -> Result<Target> {
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
                .with_context(|| format!("{}: not a file path", path.display()))?;
            let dir = parent.canonicalize().with_context(|| {
                format!(
                    "{}: the folder {} does not exist",
                    path.display(),
                    parent.display()
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

fn parent_of(path: &Path) -> &Path {
    path.parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."))
}

/// Checks a command's files before it does any work: every output is a
/// file path (not a folder) in an existing, writable folder, names no input
/// and no other output. `inputs` and `outputs` are (role, path) pairs, the
/// role as the command line names it (e.g. "--env", "-o").
pub fn check_files(inputs: &[(&str, &Path)], outputs: &[(&str, &Path)]) -> Result<()> {
    let ins: Vec<Target> = inputs
        .iter()
        .map(|(_, p)| target(p))
        .collect::<Result<_>>()?;
    let mut outs: Vec<Target> = Vec::with_capacity(outputs.len());
    for (role, path) in outputs {
        check_writable(role, path)?;
        let t = target(path)?;
        if let Some(k) = ins.iter().position(|i| same(i, &t)) {
            bail!(
                "{role} {} is the input {} {}: refusing to overwrite an input",
                path.display(),
                inputs[k].0,
                inputs[k].1.display()
            );
        }
        if let Some(k) = outs.iter().position(|o| same(o, &t)) {
            bail!(
                "{role} {} and {} {} name the same file: give each output its own path",
                path.display(),
                outputs[k].0,
                outputs[k].1.display()
            );
        }
        outs.push(t);
    }
    Ok(())
}

/// The temporary name a raw store is written under before it is complete
/// (`PATH.partial`, see docs/FORMAT.md).
pub fn partial(path: &Path) -> PathBuf {
    let mut s = path.as_os_str().to_owned();
    s.push(".partial");
    PathBuf::from(s)
}

/// An output must be a file path (not a folder) in an existing folder where
/// a file can be created.
fn check_writable(role: &str, path: &Path) -> Result<()> {
    if path.is_dir() {
        bail!("{role} {} is a folder: give a file path", path.display());
    }
    let dir = parent_of(path);
    if !dir.is_dir() {
        bail!(
            "{role} {}: the folder {} does not exist",
            path.display(),
            dir.display()
        );
    }
    tempfile::Builder::new()
        .prefix(".ltm-write-check")
        .tempfile_in(dir)
        .with_context(|| {
            format!(
                "{role} {}: cannot create files in {}",
                path.display(),
                dir.display()
            )
        })?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

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
        let ok = |o: &[(&str, &Path)]| check_files(&[("input", &a)], o);
        assert!(ok(&[("-o", &new)]).is_ok());
        for bad in [&a, &link, &dotted] {
            let e = ok(&[("-o", bad)]).unwrap_err().to_string();
            assert!(e.contains("refusing to overwrite an input"), "{e}");
        }
        #[cfg(unix)]
        {
            let sym = dir.path().join("sym.raw");
            std::os::unix::fs::symlink(&a, &sym).unwrap();
            assert!(ok(&[("-o", &sym)]).is_err());
        }
        let e = ok(&[("-o", &new), ("--png", &sub.join("../new.ltm"))])
            .unwrap_err()
            .to_string();
        assert!(e.contains("name the same file"), "{e}");
        let e = ok(&[("-o", &sub)]).unwrap_err().to_string();
        assert!(e.contains("is a folder"), "{e}");
        let e = ok(&[("-o", &dir.path().join("missing/x.ltm"))])
            .unwrap_err()
            .to_string();
        assert!(e.contains("does not exist"), "{e}");
    }
}
