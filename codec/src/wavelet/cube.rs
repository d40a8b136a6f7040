//! The row transform over cube faces (Ng et al. 2003 §4; Cheslack-Postava et
//! al. 2007 §4.2): each of a row's six `n × n` faces gets a full-depth 2D
//! wavelet transform. The compressor applies it to every row of the matrix
//! and the relighter to every lighting, so both work in the same basis.

use super::{forward, inverse, max_levels, Filter};
use crate::error::Result;

/// Full-depth row transform of one channel-plane of a row (6 faces of n×n).
pub fn row_forward(filter: Filter, n: usize, row: &mut [f32], work: &mut [f32]) -> Result<()> {
    let levels = max_levels(n, n);
    for face in row.chunks_mut(n * n) {
        forward(filter, face, n, n, levels, work)?;
    }
    Ok(())
}

/// The inverse of [`row_forward`].
pub fn row_inverse(filter: Filter, n: usize, row: &mut [f32], work: &mut [f32]) -> Result<()> {
    let levels = max_levels(n, n);
    for face in row.chunks_mut(n * n) {
        inverse(filter, face, n, n, levels, work)?;
    }
    Ok(())
}

/// Row-wavelet level of column `j` (0 = a face's scaling function, then
/// 1, 2, … from coarse to fine detail): the x axis of the paper's Fig. 8.
pub fn row_level(n: usize, j: usize) -> u32 {
    let i = j % (n * n);
    let (y, x) = (i / n, i % n);
    let m = x.max(y);
    if m == 0 {
        0
    } else {
        usize::BITS - m.leading_zeros()
    }
}
