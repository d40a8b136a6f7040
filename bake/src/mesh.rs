//! Mesh files: OBJ (through `tobj`) and PLY (ASCII or binary little-endian,
//! [`crate::ply`]), chosen by the file extension.
//!
//! A loaded mesh is checked before use: every vertex (and normal, when the
//! file has them) must be finite, every face index must name an existing
//! vertex, and the file must hold at least one face. Violations are errors
//! naming the file and the first offending vertex or face.

use crate::error::{BakeError, Result};
use sha2::{Digest, Sha256};
use std::io::Cursor;
use std::path::Path;

/// A triangle mesh as read from a file, in model space.
#[derive(Clone, Debug, Default)]
pub(crate) struct RawMesh {
    pub positions: Vec<[f32; 3]>,
    /// Per-vertex normals, when the file has them.
    pub normals: Option<Vec<[f32; 3]>>,
    /// Per-vertex texture coordinates `(u, v)`, `v` up, when the file has
    /// them (OBJ `vt`, PLY `s,t` or `u,v`).
    pub uvs: Option<Vec<[f32; 2]>>,
    pub triangles: Vec<[u32; 3]>,
}

/// A mesh file as loaded.
pub(crate) struct Loaded {
    pub mesh: RawMesh,
    /// "OBJ" or "PLY".
    pub format: &'static str,
    /// SHA-256 of the bytes parsed (for the input identity).
    pub digest: [u8; 32],
}

/// Reads and checks a mesh file.
pub(crate) fn load(path: &Path) -> Result<Loaded> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let format = match ext.as_deref() {
        Some("obj") => "OBJ",
        Some("ply") => "PLY",
        _ => {
            return Err(BakeError::MalformedMesh {
                path: path.to_path_buf(),
                format: "unknown",
                message: "unsupported file extension (valid: .obj, .ply)".into(),
            })
        }
    };
    let bytes = std::fs::read(path).map_err(|e| BakeError::io(path, e))?;
    let bad = |message: String| BakeError::MalformedMesh {
        path: path.to_path_buf(),
        format,
        message,
    };
    let mesh = if format == "OBJ" {
        parse_obj(&bytes).map_err(bad)?
    } else {
        crate::ply::parse(&bytes).map_err(bad)?
    };
    check(&mesh).map_err(bad)?;
    let mut sha = Sha256::new();
    sha.update(&bytes);
    Ok(Loaded {
        mesh,
        format,
        digest: sha.finalize().into(),
    })
}

fn parse_obj(bytes: &[u8]) -> std::result::Result<RawMesh, String> {
    // tobj's optional features add fields to LoadOptions; keep the default
    // for them.
    #[allow(clippy::needless_update)]
    let opts = tobj::LoadOptions {
        single_index: true,
        triangulate: true,
        ignore_points: true,
        ignore_lines: true,
        ..Default::default()
    };
    let (models, _materials) = tobj::load_obj_buf(&mut Cursor::new(bytes), &opts, |_| {
        // Materials come from the scene file; `mtllib` lines are ignored.
        Err(tobj::LoadError::GenericFailure)
    })
    .map_err(|e| format!("{e}"))?;
    let mut out = RawMesh::default();
    let mut normals: Vec<[f32; 3]> = Vec::new();
    let mut all_have_normals = true;
    let mut uvs: Vec<[f32; 2]> = Vec::new();
    let mut all_have_uvs = true;
    for model in &models {
        let m = &model.mesh;
        let base = out.positions.len();
        if m.positions.len() % 3 != 0 || m.indices.len() % 3 != 0 {
            return Err(format!(
                "object \"{}\" has a position or index count that is not a multiple of 3",
                model.name
            ));
        }
        let count = m.positions.len() / 3;
        out.positions
            .extend(m.positions.chunks_exact(3).map(|p| [p[0], p[1], p[2]]));
        if m.normals.len() == m.positions.len() {
            normals.extend(m.normals.chunks_exact(3).map(|n| [n[0], n[1], n[2]]));
        } else {
            all_have_normals = false;
        }
        if m.texcoords.len() == 2 * count {
            uvs.extend(m.texcoords.chunks_exact(2).map(|t| [t[0], t[1]]));
        } else {
            all_have_uvs = false;
        }
        for t in m.indices.chunks_exact(3) {
            let mut tri = [0u32; 3];
            for (slot, &i) in tri.iter_mut().zip(t) {
                if i as usize >= count {
                    return Err(format!(
                        "object \"{}\": face vertex index {} is out of range (the object has {count} vertices)",
                        model.name,
                        i as u64 + 1
                    ));
                }
                *slot = (base + i as usize) as u32;
            }
            out.triangles.push(tri);
        }
    }
    if all_have_normals && !normals.is_empty() {
        out.normals = Some(normals);
    }
    if all_have_uvs && !uvs.is_empty() {
        out.uvs = Some(uvs);
    }
    Ok(out)
}

fn check(m: &RawMesh) -> std::result::Result<(), String> {
    if let Some(i) = m
        .positions
        .iter()
        .position(|p| !p.iter().all(|v| v.is_finite()))
    {
        return Err(format!(
            "vertex {i} has a non-finite coordinate {:?}",
            m.positions[i]
        ));
    }
    if let Some(ns) = &m.normals {
        if let Some(i) = ns.iter().position(|p| !p.iter().all(|v| v.is_finite())) {
            return Err(format!(
                "the normal of vertex {i} is not finite {:?}",
                ns[i]
            ));
        }
    }
    let n = m.positions.len();
    if let Some(f) = m
        .triangles
        .iter()
        .position(|t| t.iter().any(|&i| i as usize >= n))
    {
        return Err(format!(
            "triangle {f} has vertex indices {:?}, out of range (the file has {n} vertices, indices from 0)",
            m.triangles[f]
        ));
    }
    if let Some(uv) = &m.uvs {
        if uv.len() != n {
            return Err(format!("{} texture coordinates for {n} vertices", uv.len()));
        }
        if let Some(i) = uv.iter().position(|t| !t.iter().all(|v| v.is_finite())) {
            return Err(format!(
                "the texture coordinates of vertex {i} are not finite {:?}",
                uv[i]
            ));
        }
    }
    if m.triangles.is_empty() {
        return Err("the file holds no faces".into());
    }
    Ok(())
}
