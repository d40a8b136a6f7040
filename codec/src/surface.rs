//! Per-row surface data: where on the scene each row of a matrix lies.
//!
//! For every row the raw store (version 3, flag 2) and the `.ltm` file
//! (version 2, feature 4, chunk `SURF`) may carry one [`SurfacePoint`]: the
//! world-space point the row's light leaves from, its unit normal, and a
//! valid bit. Texture-space bakes (rows = texels of a geometry image) always
//! carry it, since the texels' points and normals *are* the mesh that a
//! relit texture is drawn on; image bakes carry each pixel's first hit, so
//! that lights placed in the scene (point lights) can be evaluated per row.
//! Records are 28 bytes, little-endian (docs/FORMAT.md, "Surface data").

use crate::dims::{Dims, RowLayout};
use crate::error::{Error, Result};
use crate::limits::Limits;

/// Bytes of one stored [`SurfacePoint`].
pub const SURFACE_RECORD_LEN: usize = 28;
/// Bytes of the `SURF` chunk's header before its records.
pub(crate) const SURF_HEADER_LEN: usize = 16;
/// Largest allowed deviation of a valid normal's length from 1.
const NORMAL_TOLERANCE: f32 = 1e-3;

/// Where one row lies on the scene's surfaces.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SurfacePoint {
    /// World-space position (finite when valid, zero otherwise).
    pub position: [f32; 3],
    /// Unit surface normal (shading normal, facing the row's viewer for
    /// image rows and outwards for texels; zero when invalid).
    pub normal: [f32; 3],
    /// The row sees a surface: an image pixel whose primary ray hits
    /// something, or a texel inside a chart of the mesh.
    pub valid: bool,
}

impl SurfacePoint {
    /// The record of a row that sees no surface.
    pub const INVALID: SurfacePoint = SurfacePoint {
        position: [0.0; 3],
        normal: [0.0; 3],
        valid: false,
    };

    /// A valid point; the normal is normalized.
    pub fn new(position: [f32; 3], normal: [f32; 3]) -> SurfacePoint {
        let len = normal.iter().map(|v| v * v).sum::<f32>().sqrt();
        SurfacePoint {
            position,
            normal: normal.map(|v| v / len),
            valid: true,
        }
    }

    fn check(&self, row: usize) -> Result<()> {
        let bad = |detail: String| {
            Err(Error::corrupt(
                "surface data",
                format!("row {row}: {detail}"),
            ))
        };
        if !self.valid {
            if self.position != [0.0; 3] || self.normal != [0.0; 3] {
                return bad("an invalid row must have zero position and normal".into());
            }
            return Ok(());
        }
        if self
            .position
            .iter()
            .chain(&self.normal)
            .any(|v| !v.is_finite())
        {
            return bad(format!(
                "position {:?} or normal {:?} is not finite",
                self.position, self.normal
            ));
        }
        let len = self.normal.iter().map(|v| v * v).sum::<f32>().sqrt();
        if (len - 1.0).abs() > NORMAL_TOLERANCE {
            return bad(format!(
                "normal {:?} has length {len} (valid: 1 ± {NORMAL_TOLERANCE})",
                self.normal
            ));
        }
        Ok(())
    }

    fn encode(&self, out: &mut Vec<u8>) {
        for v in self.position.iter().chain(&self.normal) {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out.extend_from_slice(&u32::from(self.valid).to_le_bytes());
    }

    fn decode(b: &[u8], row: usize) -> Result<SurfacePoint> {
        let f = |i: usize| f32::from_le_bytes(b[4 * i..4 * i + 4].try_into().expect("4 bytes"));
        let flags = u32::from_le_bytes(b[24..28].try_into().expect("4 bytes"));
        if flags > 1 {
            return Err(Error::corrupt(
                "surface data",
                format!("row {row}: flags {flags:#x} (valid: 0 or 1)"),
            ));
        }
        let p = SurfacePoint {
            position: [f(0), f(1), f(2)],
            normal: [f(3), f(4), f(5)],
            valid: flags == 1,
        };
        p.check(row)?;
        Ok(p)
    }
}

/// The surface data of every row of a matrix, in row order.
#[derive(Clone, Debug, PartialEq)]
pub struct Surface {
    points: Vec<SurfacePoint>,
}

impl Surface {
    /// Bytes of its points in memory.
    pub fn heap_bytes(&self) -> usize {
        std::mem::size_of_val(self.points.as_slice())
    }

    /// Surface data from one point per row, checked: a valid point has a
    /// finite position and a unit normal, an invalid one is all zero.
    pub fn new(points: Vec<SurfacePoint>) -> Result<Surface> {
        for (row, p) in points.iter().enumerate() {
            p.check(row).map_err(|e| Error::Invalid(e.to_string()))?;
        }
        Ok(Surface { points })
    }

    /// The points, one per row.
    pub fn points(&self) -> &[SurfacePoint] {
        &self.points
    }

    /// Number of rows.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// True when there are no rows.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// Number of valid rows.
    pub fn valid_count(&self) -> usize {
        self.points.iter().filter(|p| p.valid).count()
    }

    /// The records, 28 bytes per row.
    pub(crate) fn encode_records(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(SURFACE_RECORD_LEN * self.points.len());
        for p in &self.points {
            p.encode(&mut out);
        }
        out
    }

    /// Decodes exactly `rows` records from `bytes` (whose length the caller
    /// checked against `rows` and the limits).
    pub(crate) fn decode_records(bytes: &[u8], rows: usize) -> Result<Surface> {
        if bytes.len() != SURFACE_RECORD_LEN * rows {
            return Err(Error::corrupt(
                "surface data",
                format!(
                    "{} bytes for {rows} rows (needs {SURFACE_RECORD_LEN} per row)",
                    bytes.len()
                ),
            ));
        }
        let points = bytes
            .chunks_exact(SURFACE_RECORD_LEN)
            .enumerate()
            .map(|(row, b)| SurfacePoint::decode(b, row))
            .collect::<Result<Vec<_>>>()?;
        Ok(Surface { points })
    }

    /// Checks that there is one point per row of `dims`.
    pub(crate) fn check_rows(&self, dims: &Dims) -> Result<()> {
        if self.len() != dims.pixels() {
            return Err(Error::BufferTooSmall {
                what: "surface data",
                len: self.len(),
                need: dims.pixels(),
            });
        }
        Ok(())
    }

    /// The `SURF` chunk: row layout code, parameterization code, row count,
    /// a reserved 0, then the records.
    pub(crate) fn encode_chunk(&self, rows: &RowLayout) -> Vec<u8> {
        let param = match rows {
            RowLayout::Texture {
                parameterization, ..
            } => parameterization.code(),
            RowLayout::Image { .. } => 0,
        };
        let mut out = Vec::with_capacity(SURF_HEADER_LEN + SURFACE_RECORD_LEN * self.len());
        for v in [rows.code(), param, self.len() as u32, 0] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out.extend_from_slice(&self.encode_records());
        out
    }

    /// Reads a `SURF` chunk for a matrix whose META gave `dims` (image rows
    /// of its width and height): returns the row layout it records and the
    /// surface. Sizes are checked against `dims` and `limits` before any
    /// allocation.
    pub(crate) fn decode_chunk(
        bytes: &[u8],
        dims: &Dims,
        limits: &Limits,
    ) -> Result<(RowLayout, Surface)> {
        if bytes.len() < SURF_HEADER_LEN {
            return Err(Error::corrupt(
                "SURF chunk",
                format!(
                    "{} bytes, shorter than its {SURF_HEADER_LEN}-byte header",
                    bytes.len()
                ),
            ));
        }
        let word =
            |i: usize| u32::from_le_bytes(bytes[4 * i..4 * i + 4].try_into().expect("4 bytes"));
        let rows = RowLayout::from_codes(word(0), word(1), dims.width(), dims.height())?;
        let (count, reserved) = (word(2) as usize, word(3));
        if reserved != 0 {
            return Err(Error::range(
                "SURF reserved field",
                format!("{reserved:#x}"),
                "0",
            ));
        }
        if count != dims.pixels() {
            return Err(Error::range(
                "SURF row count",
                count,
                format!("{} (width·height)", dims.pixels()),
            ));
        }
        let _held = limits.check_alloc("surface data", count as u64, SURFACE_RECORD_LEN as u64)?;
        let surface = Surface::decode_records(&bytes[SURF_HEADER_LEN..], count)?;
        Ok((rows, surface))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dims::Parameterization;

    fn sample() -> Surface {
        Surface::new(vec![
            SurfacePoint::new([1.0, -2.0, 3.5], [0.0, 0.0, 2.0]),
            SurfacePoint::INVALID,
            SurfacePoint::new([0.0, 1e5, -1e-6], [0.6, 0.8, 0.0]),
            SurfacePoint::INVALID,
        ])
        .unwrap()
    }

    #[test]
    fn chunk_round_trips_with_its_layout() {
        let s = sample();
        assert_eq!((s.len(), s.valid_count()), (4, 2));
        assert_eq!(s.points()[0].normal, [0.0, 0.0, 1.0]);
        let dims = Dims::texture(2, Parameterization::Uv, 2, 1);
        let bytes = s.encode_chunk(&dims.rows);
        assert_eq!(bytes.len(), SURF_HEADER_LEN + 4 * SURFACE_RECORD_LEN);
        let image = Dims::image(2, 2, 2, 1);
        let (rows, back) = Surface::decode_chunk(&bytes, &image, &Limits::default()).unwrap();
        assert_eq!((rows, &back), (dims.rows, &s));
        let (rows, _) =
            Surface::decode_chunk(&s.encode_chunk(&image.rows), &image, &Limits::default())
                .unwrap();
        assert_eq!(rows, image.rows);
    }

    #[test]
    fn invalid_chunks_are_refused() {
        let s = sample();
        let dims = Dims::image(2, 2, 2, 1);
        let good = s.encode_chunk(&dims.rows);
        let limits = Limits::default();
        let mut cases: Vec<(Vec<u8>, &str)> = vec![
            (good[..10].to_vec(), "shorter"),
            (good[..good.len() - 1].to_vec(), "bytes for 4 rows"),
        ];
        let mut patch = |at: usize, v: u32, why: &'static str| {
            let mut b = good.clone();
            b[at..at + 4].copy_from_slice(&v.to_le_bytes());
            cases.push((b, why));
        };
        patch(0, 7, "row layout");
        patch(4, 1, "parameterization");
        patch(8, 5, "row count");
        patch(12, 1, "reserved");
        patch(16 + 24, 3, "flags");
        patch(16 + 12, f32::NAN.to_bits(), "not finite");
        patch(16 + 12, 0.5f32.to_bits(), "length");
        patch(16 + 28, 1.0f32.to_bits(), "zero position");
        for (bytes, why) in cases {
            let e = Surface::decode_chunk(&bytes, &dims, &limits)
                .unwrap_err()
                .to_string();
            assert!(e.contains(why), "{why}: {e}");
        }
        let e = Surface::decode_chunk(&good, &dims, &Limits::with_max_alloc(100))
            .unwrap_err()
            .to_string();
        assert!(e.contains("surface data"), "{e}");
        assert!(Surface::new(vec![SurfacePoint {
            position: [f32::INFINITY, 0.0, 0.0],
            normal: [1.0, 0.0, 0.0],
            valid: true
        }])
        .is_err());
    }
}
