//! The orthonormal 2D Haar transform of a square map, non-standard
//! decomposition (each level splits both axes of the low band; Mallat
//! layout), as in Ng et al. 2003 and Wang et al. 2006. The dense transform
//! is the codec's ([`ltm_codec::wavelet::forward`] with [`Filter::Haar`]);
//! [`delta`] expands one texel into its `3·log₂ n + 1` coefficients in the
//! same convention (low `(a + b)/√2`, high `(a − b)/√2`), which the
//! rotation matrices are built from.

use crate::error::Result;
use ltm_codec::wavelet;
use ltm_codec::Filter;
use std::f64::consts::FRAC_1_SQRT_2;

/// `log₂ n` for a power of two.
pub fn levels(n: usize) -> u32 {
    n.trailing_zeros()
}

/// Forward transform of an `n × n` map in place (`n` a power of two).
pub fn forward(data: &mut [f32], n: usize) -> Result<()> {
    let mut work = vec![0.0f32; n * n];
    wavelet::forward(Filter::Haar, data, n, n, levels(n), &mut work)?;
    Ok(())
}

/// Inverse of [`forward`].
pub fn inverse(data: &mut [f32], n: usize) -> Result<()> {
    let mut work = vec![0.0f32; n * n];
    wavelet::inverse(Filter::Haar, data, n, n, levels(n), &mut work)?;
    Ok(())
}

/// Sparse `(index, value)` lists, one per texel or coefficient.
pub type SparseLists = Vec<Vec<(u32, f64)>>;

/// The Haar coefficients `(index, value)` of a unit impulse at texel `t` of
/// an `n × n` map: row `t` of the transform's matrix read as column.
pub fn delta(n: usize, t: usize) -> Vec<(u32, f64)> {
    let mut out = Vec::with_capacity(3 * levels(n) as usize + 1);
    let (mut x, mut y, mut v, mut size) = (t % n, t / n, 1.0f64, n);
    while size > 1 {
        let half = size / 2;
        let hx = if x % 2 == 0 {
            FRAC_1_SQRT_2
        } else {
            -FRAC_1_SQRT_2
        };
        let hy = if y % 2 == 0 {
            FRAC_1_SQRT_2
        } else {
            -FRAC_1_SQRT_2
        };
        let (lx, ly) = (x / 2, y / 2);
        let at = |cx: usize, cy: usize| (cy * n + cx) as u32;
        out.push((at(half + lx, ly), v * hx * FRAC_1_SQRT_2));
        out.push((at(lx, half + ly), v * FRAC_1_SQRT_2 * hy));
        out.push((at(half + lx, half + ly), v * hx * hy));
        v *= 0.5;
        (x, y, size) = (lx, ly, half);
    }
    out.push((0, v));
    out
}

/// [`delta`] of every texel, and its transpose: for each coefficient, the
/// texels `(texel, value)` of its basis function (the inverse transform of a
/// unit coefficient).
pub fn basis_functions(n: usize) -> (SparseLists, SparseLists) {
    let deltas: Vec<_> = (0..n * n).map(|t| delta(n, t)).collect();
    let mut basis = vec![Vec::new(); n * n];
    for (t, d) in deltas.iter().enumerate() {
        for &(c, v) in d {
            basis[c as usize].push((t as u32, v));
        }
    }
    (deltas, basis)
}
