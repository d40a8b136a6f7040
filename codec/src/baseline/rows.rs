//! What the linear fits share beside the dense blocks of (pixel, channel)
//! rows they stream ([`crate::rsvd::for_each_block`]): the block size, the
//! relative error, and their tests' helpers.

/// Values (rows × lights) of one block of rows converted to a dense matrix.
pub(crate) const CHUNK_VALUES: usize = 1 << 23;

/// `√(err2 / norm2)`, or 0 for an all-zero matrix.
pub(crate) fn relative(err2: f64, norm2: f64) -> f64 {
    if norm2 > 0.0 {
        (err2.max(0.0) / norm2).sqrt()
    } else {
        0.0
    }
}

/// Helpers shared by the fits' tests.
#[cfg(test)]
pub(crate) mod testing {
    use crate::dims::Dims;
    use crate::raw::{RawHeader, RawStore, RawWriter};
    use faer::{Mat, MatRef};
    use std::path::{Path, PathBuf};

    /// Writes a raw store of `t` (P·M·C values) in blocks of `block_pixels`
    /// rows, with an albedo image when given.
    pub fn write_raw(
        dir: &Path,
        name: &str,
        dims: Dims,
        t: &[f32],
        albedo: Option<&[f32]>,
        block_pixels: usize,
    ) -> PathBuf {
        let header = RawHeader::new(
            dims,
            albedo.is_some(),
            (block_pixels * dims.row_len() * 4) as u64,
        );
        RawWriter::write_dense(&dir.join(name), header, t, albedo).unwrap()
    }

    pub fn dims(width: u32, height: u32, face_res: u32, channels: u32) -> Dims {
        Dims::image(width, height, face_res, channels)
    }

    /// The store as a dense matrix, rows (pixel, channel), f64.
    pub fn dense(raw: &RawStore) -> Mat<f64> {
        let d = raw.dims();
        let c = d.channels as usize;
        let mut t = Vec::new();
        raw.read_rows(0..d.pixels(), &mut t).unwrap();
        Mat::from_fn(d.pixels() * c, d.lights(), |r, j| {
            t[(r / c) * d.row_len() + j * c + r % c] as f64
        })
    }

    pub fn frobenius2(a: MatRef<'_, f64>) -> f64 {
        let mut s = 0.0;
        for j in 0..a.ncols() {
            for i in 0..a.nrows() {
                s += a[(i, j)] * a[(i, j)];
            }
        }
        s
    }
}
