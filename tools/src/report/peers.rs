//! The peers: SZ3, ZFP and SPERR, error-bounded scientific float
//! compressors, measured on the same raw store by `tools/validate/peers.py`
//! (pip's `pysz`, `zfpy` and `numcodecs-wasm-sperr`) and read here from its
//! JSON (`ltm report --peers FILE`).
//! Each point is the smallest stream over four layouts of the matrix whose
//! relative L2 matrix error is at most its target, with the cost of
//! relighting from it: one decompression, then a dense `T·L` per frame.

use super::SceneInfo;
use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// One peer at one target error.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct PeerPoint {
    /// `"sz3"`, `"zfp"` or `"sperr"`.
    pub method: String,
    /// The target relative L2 matrix error it was bisected to.
    pub target: f64,
    /// Compressed bytes.
    pub bytes: u64,
    /// Measured `‖T − T̂‖_F / ‖T‖_F`.
    pub matrix_error: f64,
    /// The shape the matrix was given in, e.g. `(H, W, M·C)`.
    pub shape: String,
    /// The compressor's absolute error bound.
    pub bound: f64,
    /// Seconds to compress.
    pub compress_s: f64,
    /// Seconds to decompress (once, before relighting).
    pub decompress_s: f64,
    /// Seconds of one dense frame `T·L` (numpy).
    pub frame_s: f64,
}

/// What `peers.py` writes.
#[derive(Deserialize)]
struct PeersFile {
    dims: PeerDims,
    points: Vec<PeerPoint>,
}

#[derive(Deserialize)]
struct PeerDims {
    width: u32,
    height: u32,
    face_res: u32,
    channels: u32,
}

/// Reads the peers' JSON and checks that it was measured on a matrix of the
/// scene's dimensions.
pub fn load(path: &Path, scene: &SceneInfo) -> Result<Vec<PeerPoint>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let file: PeersFile = serde_json::from_str(&text).with_context(|| {
        format!(
            "{} is not the JSON of tools/validate/peers.py",
            path.display()
        )
    })?;
    let d = &file.dims;
    let ours = (scene.width, scene.height, scene.face_res, scene.channels);
    if (d.width, d.height, d.face_res, d.channels) != ours {
        bail!(
            "{}: measured on a {}×{} matrix with n = {} and {} channels, the report's is {}×{} with n = {} and {} channels",
            path.display(), d.width, d.height, d.face_res, d.channels, ours.0, ours.1, ours.2, ours.3
        );
    }
    for p in &file.points {
        let ok = p.target > 0.0
            && p.matrix_error.is_finite()
            && p.matrix_error >= 0.0
            && p.bytes > 0
            && [p.compress_s, p.decompress_s, p.frame_s]
                .iter()
                .all(|t| t.is_finite() && *t >= 0.0);
        if !ok {
            bail!("{}: invalid point {p:?}", path.display());
        }
    }
    Ok(file.points)
}

/// The peers' display name.
pub fn name(method: &str) -> &str {
    match method {
        "sz3" => "SZ3",
        "zfp" => "ZFP",
        "sperr" => "SPERR",
        other => other,
    }
}
