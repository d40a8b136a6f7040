//! Raw stores written from dense matrices.

use ltm_codec::{Dims, RawHeader, RawWriter};
use std::path::{Path, PathBuf};

/// Writes the dense matrix `t` (rows × lights × channels values, row-major)
/// and its albedo image, if any, as a raw store at `path` in blocks of
/// `block_bytes`, and returns the store's path. Panics on failure.
pub fn write_raw(
    path: &Path,
    dims: Dims,
    t: &[f32],
    albedo: Option<&[f32]>,
    block_bytes: u64,
) -> PathBuf {
    let header = RawHeader::new(dims, albedo.is_some(), block_bytes);
    RawWriter::write_dense(path, header, t, albedo).unwrap()
}

/// The bytes of `rows` rows of `dims`: a block size of that many rows.
pub fn block_bytes(dims: Dims, rows: usize) -> u64 {
    (rows * dims.row_len() * 4) as u64
}
