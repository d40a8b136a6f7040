//! The repository's assets (meshes, scenes and environment maps) as the
//! commands find and load them.

use anyhow::{bail, Context, Result};
use ltm_relight::EnvMap;
use std::path::{Path, PathBuf};

/// The assets directory: `given`, else ./assets, else the one this binary
/// was built from; it must hold meshes/ and envmaps/.
pub fn assets_dir(given: Option<PathBuf>) -> Result<PathBuf> {
    let candidates = match given {
        Some(p) => vec![p],
        None => vec![
            PathBuf::from("assets"),
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets"),
        ],
    };
    candidates
        .into_iter()
        .find(|p| p.join("meshes").is_dir() && p.join("envmaps").is_dir())
        .context("no assets directory with meshes/ and envmaps/ found: run from the repository root or pass --assets")
}

/// The environment maps (.exr, .hdr in either case) in `dir`, sorted.
pub fn map_files(dir: &Path) -> std::io::Result<Vec<PathBuf>> {
    let mut maps: Vec<PathBuf> = std::fs::read_dir(dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.extension()
                .is_some_and(|x| x.eq_ignore_ascii_case("exr") || x.eq_ignore_ascii_case("hdr"))
        })
        .collect();
    maps.sort();
    Ok(maps)
}

/// The environment maps in `assets/envmaps`, sorted; an error when there
/// are none.
pub fn env_maps(assets: &Path) -> Result<Vec<PathBuf>> {
    let dir = assets.join("envmaps");
    let maps = map_files(&dir).with_context(|| format!("reading {}", dir.display()))?;
    if maps.is_empty() {
        bail!("no environment maps (.exr, .hdr) in {}", dir.display());
    }
    Ok(maps)
}

/// Loads every map, named by its file stem (names must be distinct: they
/// name the outputs). Run before any long work, so that a bad map fails
/// first.
pub fn load_maps(paths: &[PathBuf]) -> Result<Vec<(String, EnvMap)>> {
    let mut maps: Vec<(String, EnvMap)> = Vec::with_capacity(paths.len());
    for path in paths {
        let name = path
            .file_stem()
            .map_or("map".into(), |s| s.to_string_lossy().into_owned());
        if maps.iter().any(|(n, _)| *n == name) {
            bail!("two environment maps are named {name}: give maps distinct file names");
        }
        let map = EnvMap::load(path).with_context(|| format!("loading {}", path.display()))?;
        maps.push((name, map));
    }
    Ok(maps)
}
