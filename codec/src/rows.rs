//! Dense blocks of transport rows streamed from a raw store, for the linear
//! fits ([`crate::pca`], [`crate::sh`]): the store is never whole in memory,
//! block checksums are verified on request and rows flagged all zero are
//! skipped. A row here is one (pixel, channel) pair of `M` values.

use crate::error::Result;
use crate::raw::RawStore;
use faer::MatRef;
use rayon::prelude::*;

/// Values (rows × lights) of one block of rows converted to a dense matrix.
pub(crate) const CHUNK_VALUES: usize = 1 << 23;

/// A block of nonzero matrix rows as a dense matrix.
pub(crate) struct Block<'a, T> {
    /// Matrix row index `p·C + c` of each row of the block.
    pub rows: &'a [usize],
    /// Row `i` is `data[i·M .. (i+1)·M]`.
    pub data: &'a [T],
    lights: usize,
}

impl<'a, T> Block<'a, T> {
    /// The block transposed, `M × R`, column-major.
    pub fn at(&self) -> MatRef<'a, T> {
        MatRef::from_column_major_slice(self.data, self.lights, self.rows.len())
    }

    /// The block, `R × M`.
    pub fn a(&self) -> MatRef<'a, T> {
        self.at().transpose()
    }

    /// Row `i` of the block (`M` values).
    pub fn row(&self, i: usize) -> &'a [T] {
        &self.data[i * self.lights..(i + 1) * self.lights]
    }
}

/// Calls `f` on consecutive blocks of the nonzero rows of `raw` (rows are
/// (pixel, channel) pairs, `M` values each), each of about `chunk_values`
/// values, converted to `T`. With `verify`, the checksum of every store
/// block is checked before its rows are used.
pub(crate) fn for_each_block<T, F>(
    raw: &RawStore,
    chunk_values: usize,
    verify: bool,
    buf: &mut Vec<T>,
    mut f: F,
) -> Result<()>
where
    T: Copy + Default + From<f32> + Send + Sync,
    F: FnMut(Block<'_, T>) -> Result<()>,
{
    let dims = raw.dims();
    let header = *raw.header();
    let (pixels, m, c) = (dims.pixels(), dims.lights(), dims.channels as usize);
    let chunk_pixels = (chunk_values / (m * c)).max(1);
    let mut rows = Vec::new();
    let mut next_block = 0;
    let mut start = 0;
    while start < pixels {
        let end = (start + chunk_pixels).min(pixels);
        if verify {
            while next_block < header.block_count() && header.block_range(next_block).start < end {
                raw.verify_block(next_block)?;
                next_block += 1;
            }
        }
        rows.clear();
        for p in (start..end).filter(|&p| !raw.is_zero_row(p)) {
            rows.extend((0..c).map(|ch| p * c + ch));
        }
        if !rows.is_empty() {
            buf.clear();
            buf.resize(rows.len() * m, T::default());
            buf.par_chunks_mut(m)
                .zip(rows.par_iter())
                .for_each(|(dst, &r)| {
                    let src = raw.row(r / c);
                    for (d, s) in dst.iter_mut().zip(src.iter().skip(r % c).step_by(c)) {
                        *d = T::from(*s);
                    }
                });
            f(Block {
                rows: &rows,
                data: buf,
                lights: m,
            })?;
        }
        raw.release_rows(start..end);
        start = end;
    }
    Ok(())
}

/// `‖row‖²` summed over the rows of a block, in f64.
pub(crate) fn block_norm2<T: Copy + Into<f64> + Sync>(data: &[T]) -> f64 {
    data.par_chunks(1 << 16)
        .map(|c| c.iter().map(|&v| v.into() * v.into()).sum::<f64>())
        .sum()
}

/// `√(err2 / norm2)`, or 0 for an all-zero matrix.
pub(crate) fn relative(err2: f64, norm2: f64) -> f64 {
    if norm2 > 0.0 {
        (err2.max(0.0) / norm2).sqrt()
    } else {
        0.0
    }
}

/// splitmix64 (Steele, Lea and Flood 2014): the generator of the PCA sketch
/// and of the fits' test matrices.
pub(crate) struct SplitMix64(pub u64);

impl SplitMix64 {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        mix64(self.0)
    }

    /// Uniform in the open interval (0, 1).
    pub fn uniform(&mut self) -> f64 {
        ((self.next_u64() >> 11) as f64 + 0.5) * (1.0 / (1u64 << 53) as f64)
    }

    /// Two independent standard normal numbers (Box–Muller).
    pub fn gaussian_pair(&mut self) -> [f64; 2] {
        let r = (-2.0 * self.uniform().ln()).sqrt();
        let (s, c) = (2.0 * std::f64::consts::PI * self.uniform()).sin_cos();
        [r * c, r * s]
    }
}

pub(crate) fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
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
        Mat::from_fn(d.pixels() * c, d.lights(), |r, j| {
            raw.row(r / c)[j * c + r % c] as f64
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
