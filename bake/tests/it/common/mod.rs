//! Helpers shared by the integration tests.
#![allow(dead_code)]

use ltm_bake::{BakeError, Scene, SceneDesc};
use std::path::{Path, PathBuf};

/// The repository's `assets/` directory.
pub fn assets() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets")
}

/// Writes `files` (name, bytes) into a fresh temporary directory.
pub fn dir_with(files: &[(&str, &[u8])]) -> tempfile::TempDir {
    let dir = tempfile::tempdir().expect("temp dir");
    for (name, bytes) in files {
        std::fs::write(dir.path().join(name), bytes).expect("write test file");
    }
    dir
}

/// Writes `scene.toml` with `toml` next to `files` and loads and builds it.
pub fn build(toml: &str, files: &[(&str, &[u8])]) -> (tempfile::TempDir, Result<Scene, BakeError>) {
    let dir = dir_with(files);
    let path = dir.path().join("scene.toml");
    std::fs::write(&path, toml).expect("write scene");
    let scene = SceneDesc::load(&path).and_then(|d| Scene::build(&d));
    (dir, scene)
}

/// A scene file with the given camera/lighting settings, a grey Lambertian
/// material "grey", and `body` appended (meshes, quads, more materials).
pub fn scene_toml(camera: &str, lighting: &str, body: &str) -> String {
    format!(
        "[camera]\n{camera}\n\n[lighting]\n{lighting}\n\n[materials.grey]\ntype = \"lambert\"\nalbedo = [0.5, 0.5, 0.5]\n\n{body}\n"
    )
}

pub const CAMERA: &str =
    "eye = [0.0, 3.0, 4.0]\ntarget = [0.0, 0.0, 0.0]\nfov = 40.0\nwidth = 9\nheight = 9";
pub const LIGHTING: &str = "face_res = 8\ntexel_samples = 4";

/// An OBJ with one triangle in the plane y = 0 under the camera target.
pub const TRIANGLE_OBJ: &str = "v -1 0 -1\nv -1 0 1\nv 1 0 0\nf 1 2 3\n";

/// The error message of a failed build.
pub fn err(r: Result<Scene, BakeError>) -> (BakeError, String) {
    match r {
        Ok(_) => panic!("expected an error, the scene built"),
        Err(e) => {
            let msg = e.to_string();
            (e, msg)
        }
    }
}
