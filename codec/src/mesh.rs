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
use crate::limits::Limits;

/// Largest vertex or triangle count of a stored mesh.
pub const MAX_MESH_ELEMENTS: usize = 1 << 26;
/// Bytes of a stored mesh's header: vertex count, triangle count and two
/// reserved words, `u32` each.
pub const MESH_HEADER_LEN: usize = 16;
/// Stored bytes per vertex: position and normal (`f32` × 3 each) and
/// texture coordinates (`f32` × 2).
pub const MESH_VERTEX_LEN: usize = 32;
/// Stored bytes per triangle: three `u32` vertex indices.
pub const MESH_TRIANGLE_LEN: usize = 12;

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

impl ReceiverMesh {
    /// Bytes of its stored encoding ([`ReceiverMesh::encode`]):
    /// `16 + 32·vertices + 12·triangles`.
    pub fn encoded_len(&self) -> usize {
        encoded_len(self.positions.len() as u64, self.triangles.len() as u64) as usize
    }

    /// The stored encoding (docs/FORMAT.md, "Receiver mesh"), little-endian:
    /// the vertex count `V`, the triangle count `T` and two reserved zero
    /// words (`u32` each); then the `V` positions (`f32` × 3), the `V`
    /// normals (`f32` × 3), the `V` texture coordinates (`f32` × 2) and the
    /// `T` triangles (`u32` × 3), each array whole before the next.
    /// Call [`ReceiverMesh::validate`] first: the lengths of the vertex
    /// arrays must agree.
    pub fn encode(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(self.encoded_len());
        for v in [
            self.positions.len() as u32,
            self.triangles.len() as u32,
            0,
            0,
        ] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        let floats = self.positions.iter().flatten();
        let floats = floats.chain(self.normals.iter().flatten());
        for v in floats.chain(self.uvs.iter().flatten()) {
            out.extend_from_slice(&v.to_le_bytes());
        }
        for i in self.triangles.iter().flatten() {
            out.extend_from_slice(&i.to_le_bytes());
        }
        out
    }

    /// Decodes and validates a stored mesh for a texture of side `size`:
    /// the header's counts (each at most [`MAX_MESH_ELEMENTS`]) and
    /// reserved words (0), the exact byte length they imply, the arrays
    /// charged to `limits` before they are allocated, then
    /// [`ReceiverMesh::validate`].
    pub fn decode(bytes: &[u8], size: u32, limits: &Limits) -> Result<ReceiverMesh> {
        if bytes.len() < MESH_HEADER_LEN {
            return Err(Error::corrupt(
                "receiver mesh",
                format!(
                    "{} bytes, shorter than its {MESH_HEADER_LEN}-byte header",
                    bytes.len()
                ),
            ));
        }
        let word = |i: usize| u32::from_le_bytes(bytes[4 * i..4 * i + 4].try_into().expect("4"));
        let (v, t) = (word(0) as u64, word(1) as u64);
        for (what, n) in [
            ("receiver mesh vertex count", v),
            ("receiver mesh triangle count", t),
        ] {
            if n > MAX_MESH_ELEMENTS as u64 {
                return Err(Error::range(
                    what,
                    n,
                    format!("at most {MAX_MESH_ELEMENTS}"),
                ));
            }
        }
        if let Some(r) = [word(2), word(3)].into_iter().find(|&r| r != 0) {
            return Err(Error::range(
                "receiver mesh reserved field",
                format!("{r:#x}"),
                "0",
            ));
        }
        let need = encoded_len(v, t);
        if bytes.len() as u64 != need {
            return Err(Error::corrupt(
                "receiver mesh",
                format!(
                    "{} bytes for {v} vertices and {t} triangles (needs exactly {need})",
                    bytes.len()
                ),
            ));
        }
        let _held = limits
            .check_alloc("receiver mesh vertices", v, MESH_VERTEX_LEN as u64)?
            .join(limits.check_alloc("receiver mesh triangles", t, MESH_TRIANGLE_LEN as u64)?);
        let (v, t) = (v as usize, t as usize);
        let f = |at: usize| f32::from_le_bytes(bytes[at..at + 4].try_into().expect("4 bytes"));
        let u = |at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().expect("4 bytes"));
        let (pos, nrm) = (MESH_HEADER_LEN, MESH_HEADER_LEN + 12 * v);
        let (uv, tri) = (nrm + 12 * v, nrm + 20 * v);
        let mesh = ReceiverMesh {
            positions: (0..v)
                .map(|i| [0, 1, 2].map(|c| f(pos + 12 * i + 4 * c)))
                .collect(),
            normals: (0..v)
                .map(|i| [0, 1, 2].map(|c| f(nrm + 12 * i + 4 * c)))
                .collect(),
            uvs: (0..v)
                .map(|i| [0, 1].map(|c| f(uv + 8 * i + 4 * c)))
                .collect(),
            triangles: (0..t)
                .map(|i| [0, 1, 2].map(|c| u(tri + 12 * i + 4 * c)))
                .collect(),
        };
        mesh.validate(size)?;
        Ok(mesh)
    }
}

/// Bytes of a stored mesh of `v` vertices and `t` triangles.
fn encoded_len(v: u64, t: u64) -> u64 {
    MESH_HEADER_LEN as u64 + MESH_VERTEX_LEN as u64 * v + MESH_TRIANGLE_LEN as u64 * t
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
        type Break = Box<dyn Fn(&mut ReceiverMesh)>;
        let cases: Vec<(Break, &str)> = vec![
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

    #[test]
    fn encoding_round_trips_bit_for_bit() {
        let mut m = quad();
        m.positions[2] = [-0.0, 1e-30, f32::MAX];
        m.normals[3] = [0.0; 3];
        let bytes = m.encode();
        assert_eq!(bytes.len(), m.encoded_len());
        assert_eq!(bytes.len(), 16 + 4 * 32 + 2 * 12);
        assert_eq!(&bytes[..8], &[4, 0, 0, 0, 2, 0, 0, 0]);
        let back = ReceiverMesh::decode(&bytes, 4, &Limits::default()).unwrap();
        assert_eq!(back.encode(), bytes);
        assert_eq!(back.positions[2][0].to_bits(), (-0.0f32).to_bits());
        assert_eq!(back, m);
    }

    #[test]
    fn invalid_encodings_are_refused_with_the_value_and_range() {
        let good = quad().encode();
        let limits = Limits::default();
        let patch = |at: usize, v: u32| {
            let mut b = good.clone();
            b[at..at + 4].copy_from_slice(&v.to_le_bytes());
            b
        };
        let (nrm, uv, tri) = (16 + 48, 16 + 96, 16 + 128);
        let cases: Vec<(Vec<u8>, &str)> = vec![
            (good[..15].to_vec(), "shorter than its 16-byte header"),
            (good[..good.len() - 1].to_vec(), "needs exactly 168"),
            ([good.clone(), vec![0]].concat(), "needs exactly 168"),
            (patch(0, 5), "5 vertices and 2 triangles"),
            (patch(4, 1 << 27), "at most 67108864"),
            (patch(0, u32::MAX), "at most 67108864"),
            (patch(8, 1), "reserved"),
            (patch(12, 7), "reserved"),
            (patch(16 + 4, f32::NAN.to_bits()), "not finite"),
            (patch(nrm, f32::NAN.to_bits()), "length"),
            (patch(uv + 8, 4.5f32.to_bits()), "outside [0, 4]"),
            (patch(uv, f32::NAN.to_bits()), "outside [0, 4]"),
            (patch(uv + 4, (-1.0f32).to_bits()), "outside [0, 4]"),
            (patch(tri + 20, 4), "below 4"),
            (patch(tri + 4, u32::MAX), "below 4"),
            ([patch(4, 0)[..16 + 128].to_vec()].concat(), "no triangles"),
        ];
        for (bytes, want) in cases {
            let e = ReceiverMesh::decode(&bytes, 4, &limits)
                .unwrap_err()
                .to_string();
            assert!(e.contains(want), "{want}: {e}");
        }
        let e = ReceiverMesh::decode(&good, 3, &limits).unwrap_err();
        assert!(e.to_string().contains("outside [0, 3]"), "{e}");
        let small = Limits::with_max_alloc(100);
        let e = ReceiverMesh::decode(&good, 4, &small).unwrap_err();
        assert!(
            matches!(&e, Error::Limit { what, .. } if what.contains("receiver mesh")),
            "{e}"
        );
        assert_eq!(small.used_bytes(), 0);
    }
}
