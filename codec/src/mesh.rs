//! The receiving mesh of a texture-space matrix: the triangles a relit
//! texture is drawn on (geometry relighting, Cheslack-Postava et al. 2007
//! §4.1).
//!
//! A texture-space bake of an atlas or `uv` layout stores the receiver
//! itself beside the per-texel surface records: world-space vertex
//! positions and shading normals, texture coordinates in texel units (the
//! texel map's convention: `x` from 0 to S rightwards, `y` from 0 to S
//! downwards, texel `(x, y)` covering `[x, x+1] × [y, y+1]`) and
//! counter-clockwise triangles. Renderers rasterize these triangles with a
//! perspective-correct lookup of the relit texture, so that the picture
//! shows the mesh's own shape, not a grid of texels.

use crate::error::{Error, Result};

/// Largest vertex or triangle count of a stored mesh.
pub const MAX_MESH_ELEMENTS: usize = 1 << 26;

/// The receiving surface as an indexed triangle mesh with texture
/// coordinates.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ReceiverMesh {
    /// World-space vertex positions.
    pub positions: Vec<[f32; 3]>,
    /// Unit shading normals per vertex (zero: use the face normal).
    pub normals: Vec<[f32; 3]>,
    /// Texture coordinates per vertex, in texel units of an S × S texture
    /// (`x` rightwards, `y` downwards, both in `[0, S]`).
    pub uvs: Vec<[f32; 2]>,
    /// Counter-clockwise triangles (front face), as vertex indices.
    pub triangles: Vec<[u32; 3]>,
}

impl ReceiverMesh {
    /// Bytes of its arrays in memory.
    pub fn heap_bytes(&self) -> usize {
        std::mem::size_of_val(self.positions.as_slice())
            + std::mem::size_of_val(self.normals.as_slice())
            + std::mem::size_of_val(self.uvs.as_slice())
            + std::mem::size_of_val(self.triangles.as_slice())
    }

    /// Number of vertices.
    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    /// Checks the mesh against a texture of side `size`: equal array
    /// lengths, counts within [`MAX_MESH_ELEMENTS`], at least one triangle,
    /// finite positions, unit or zero normals, texture coordinates in
    /// `[0, size]` and vertex indices in range.
    pub fn validate(&self, size: u32) -> Result<()> {
        let v = self.positions.len();
        let bad = |detail: String| Err(Error::corrupt("receiver mesh", detail));
        if self.normals.len() != v || self.uvs.len() != v {
            return bad(format!(
                "{v} positions, {} normals and {} texture coordinates (valid: one of each per vertex)",
                self.normals.len(),
                self.uvs.len()
            ));
        }
        if v > MAX_MESH_ELEMENTS || self.triangles.len() > MAX_MESH_ELEMENTS {
            return Err(Error::range(
                "receiver mesh vertex or triangle count",
                v.max(self.triangles.len()),
                format!("at most {MAX_MESH_ELEMENTS}"),
            ));
        }
        if self.triangles.is_empty() {
            return bad("no triangles (valid: at least one)".into());
        }
        for (i, p) in self.positions.iter().enumerate() {
            if p.iter().any(|c| !c.is_finite()) {
                return bad(format!("vertex {i}: position {p:?} is not finite"));
            }
        }
        for (i, n) in self.normals.iter().enumerate() {
            let len = n.iter().map(|c| c * c).sum::<f32>().sqrt();
            if !(len == 0.0 || (len - 1.0).abs() <= 1e-3) {
                return bad(format!(
                    "vertex {i}: normal {n:?} has length {len} (valid: 0, or 1 within 1e-3)"
                ));
            }
        }
        let s = size as f32;
        for (i, uv) in self.uvs.iter().enumerate() {
            if !uv.iter().all(|c| (0.0..=s).contains(c)) {
                return bad(format!(
                    "vertex {i}: texture coordinate {uv:?} is outside [0, {size}]"
                ));
            }
        }
        for (t, tri) in self.triangles.iter().enumerate() {
            if tri.iter().any(|&k| k as usize >= v) {
                return bad(format!(
                    "triangle {t}: vertex indices {tri:?} (valid: below {v})"
                ));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quad() -> ReceiverMesh {
        ReceiverMesh {
            positions: vec![[0.0; 3], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]],
            normals: vec![[0.0, 0.0, 1.0]; 4],
            uvs: vec![[0.0, 4.0], [4.0, 4.0], [4.0, 0.0], [0.0, 0.0]],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
        }
    }

    #[test]
    fn a_valid_mesh_passes_and_each_defect_is_named() {
        quad().validate(4).unwrap();
        let cases: Vec<(Box<dyn Fn(&mut ReceiverMesh)>, &str)> = vec![
            (
                Box::new(|m| m.normals.pop().map(drop).unwrap_or(())),
                "normals",
            ),
            (Box::new(|m| m.positions[1][2] = f32::NAN), "not finite"),
            (Box::new(|m| m.normals[0] = [0.0, 0.0, 2.0]), "length"),
            (Box::new(|m| m.uvs[2] = [4.5, 0.0]), "outside [0, 4]"),
            (Box::new(|m| m.triangles[1] = [0, 2, 4]), "below 4"),
            (Box::new(|m| m.triangles.clear()), "no triangles"),
        ];
        for (break_it, want) in cases {
            let mut m = quad();
            break_it(&mut m);
            let e = m.validate(4).unwrap_err().to_string();
            assert!(e.contains(want), "{e}");
        }
    }
}
