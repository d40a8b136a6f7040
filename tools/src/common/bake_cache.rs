//! Bakes cached between runs of `ltm demo` and `ltm report`.

use super::progress;
use anyhow::Result;
use ltm_bake::{bake, BakeOptions, Scene, SceneDesc};
use ltm_codec::Progress;
use std::hash::{Hash, Hasher};
use std::path::{Path, PathBuf};

/// Bakes `desc` into `dir/{label}-{key}.raw` unless a complete store is
/// already there, and returns its path. The key hashes the whole description
/// (meshes, materials, camera, sizes), so an edited or different scene is
/// baked anew; delete the file to bake again after editing a mesh file.
pub fn bake_cached(desc: &SceneDesc, dir: &Path, label: &str) -> Result<PathBuf> {
    let key = {
        let mut h = std::hash::DefaultHasher::new();
        format!("{desc:?}").hash(&mut h);
        h.finish()
    };
    let raw_path = dir.join(format!("{label}-{key:016x}.raw"));
    if raw_path.exists() {
        eprintln!("using the cached bake {}", raw_path.display());
        return Ok(raw_path);
    }
    let scene = Scene::build(desc)?;
    let bar = progress::bar(0, "bake", progress::Unit::rows(scene.dims()));
    let report = bake(
        &scene,
        &raw_path,
        &BakeOptions::default(),
        Progress::new(&|s| {
            bar.set_length(s.total);
            bar.set_position(s.done);
        }),
    )?;
    bar.finish_and_clear();
    eprintln!(
        "baked {} rows in {:.1} s",
        report.rows_baked,
        report.elapsed.as_secs_f64()
    );
    Ok(raw_path)
}
