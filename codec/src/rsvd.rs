//! The randomized SVD of Halko, Martinsson and Tropp 2011 ("Finding
//! structure with randomness", SIAM Review 53(2)), streamed over a raw
//! store in blocks of rows, shared by the uncentred PCA baseline
//! ([`crate::PcaBasis`]) and the `pca` mode's mean-centred fit
//! (`pca/fit.rs`): a Gaussian sketch `Aᵀ·G`, power iterations `AᵀA·Q`
//! with re-orthonormalisation (in f32, `A` scaled by a power of two), and a
//! Rayleigh–Ritz pass in f64. [`Rows`] says what the rows of `A` are: with
//! no centring, the (pixel, channel) rows of `M` values of the store, rows
//! flagged all zero skipped; centred, the pixel rows of `N = M·C` values
//! minus the mean row. [`for_each_block`] streams the uncentred rows as
//! dense blocks, for the baseline fits too.

use crate::error::{Error, Result};
use crate::raw::RawStore;
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatRef, Par, Side};
use rayon::prelude::*;

/// Extra columns of the randomized sketch beyond the rank.
pub(crate) const OVERSAMPLING: usize = 10;
/// Power iterations of the randomized SVD.
pub(crate) const POWER_ITERATIONS: usize = 2;

/// The matrix `A` a fit reads: a raw store's rows in blocks of about
/// `block_values` values, centred on a mean row or not.
pub(crate) struct Rows<'a> {
    raw: &'a RawStore,
    block_values: usize,
    /// The mean row in f64 and in f32 (centred rows), or `None`.
    mean: Option<(&'a [f64], Vec<f32>)>,
}

impl<'a> Rows<'a> {
    /// `A`: the store's (pixel, channel) rows of `M` values, uncentred;
    /// rows flagged all zero are skipped.
    pub fn uncentred(raw: &'a RawStore, block_values: usize) -> Rows<'a> {
        Rows {
            raw,
            block_values,
            mean: None,
        }
    }

    /// `A = T − 1·μᵀ`: the store's pixel rows of `N = M·C` values minus
    /// the mean row `mean` (f32 passes subtract it rounded to f32).
    pub fn centred(raw: &'a RawStore, block_values: usize, mean: &'a [f64]) -> Rows<'a> {
        let mean32 = mean.iter().map(|&v| v as f32).collect();
        Rows {
            raw,
            block_values,
            mean: Some((mean, mean32)),
        }
    }

    /// Columns of `A`.
    pub fn width(&self) -> usize {
        match self.mean {
            Some((m, _)) => m.len(),
            None => self.raw.dims().lights(),
        }
    }

    /// Calls `f` with the row indices of consecutive blocks of `A` and
    /// their values (`rows × width`, row after row) in f32. With `verify`,
    /// every raw block's checksum is checked as its rows go by.
    fn for_each_f32(
        &self,
        verify: bool,
        mut f: impl FnMut(&[usize], &[f32]) -> Result<()>,
    ) -> Result<()> {
        let Some((_, mean32)) = &self.mean else {
            let mut buf = Vec::new();
            return for_each_block(self.raw, self.block_values, verify, &mut buf, |blk| {
                f(blk.rows, blk.data)
            });
        };
        let n = mean32.len();
        let (mut ids, mut a) = (Vec::new(), Vec::new());
        self.raw
            .for_each_row_block(self.block_values, verify, |start, rows| {
                ids.clear();
                ids.extend(start..start + rows.len() / n);
                a.clear();
                a.extend_from_slice(rows);
                a.par_chunks_mut(n)
                    .for_each(|r| r.iter_mut().zip(mean32).for_each(|(v, m)| *v -= m));
                f(&ids, &a)
            })
    }

    /// [`Rows::for_each_f32`] in f64 (the centred rows subtract the f64
    /// mean), without verification.
    fn for_each_f64(&self, mut f: impl FnMut(&[usize], &[f64]) -> Result<()>) -> Result<()> {
        let Some((mean, _)) = self.mean else {
            let mut buf = Vec::new();
            return for_each_block(self.raw, self.block_values, false, &mut buf, |blk| {
                f(blk.rows, blk.data)
            });
        };
        let n = mean.len();
        let (mut ids, mut a) = (Vec::new(), Vec::new());
        self.raw
            .for_each_row_block(self.block_values, false, |start, rows| {
                ids.clear();
                ids.extend(start..start + rows.len() / n);
                a.clear();
                a.extend(
                    rows.iter()
                        .enumerate()
                        .map(|(i, &v)| v as f64 - mean[i % n]),
                );
                f(&ids, &a)
            })
    }
}

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
/// values, converted to `T`. The store is read through
/// [`RawStore::for_each_row_block`]: with `verify`, the checksum of every
/// store block is checked as its rows go by.
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
    let (m, c) = (dims.lights(), dims.channels as usize);
    let mut rows = Vec::new();
    raw.for_each_row_block(chunk_values, verify, |start, values| {
        let end = start + values.len() / (m * c);
        rows.clear();
        for p in (start..end).filter(|&p| !raw.is_zero_row(p)) {
            rows.extend((0..c).map(|ch| p * c + ch));
        }
        if rows.is_empty() {
            return Ok(());
        }
        buf.clear();
        buf.resize(rows.len() * m, T::default());
        buf.par_chunks_mut(m)
            .zip(rows.par_iter())
            .for_each(|(dst, &r)| {
                let src = &values[(r / c - start) * m * c..(r / c - start + 1) * m * c];
                for (d, s) in dst.iter_mut().zip(src.iter().skip(r % c).step_by(c)) {
                    *d = T::from(*s);
                }
            });
        f(Block {
            rows: &rows,
            data: buf,
            lights: m,
        })
    })
}

/// `‖row‖²` summed over the rows of a block, in f64.
pub(crate) fn block_norm2<T: Copy + Into<f64> + Sync>(data: &[T]) -> f64 {
    data.par_chunks(1 << 16)
        .map(|c| c.iter().map(|&v| v.into() * v.into()).sum::<f64>())
        .sum()
}

/// The Gaussian sketch `Z = Aᵀ·G` (`width × l`): row `r` of `G` is
/// [`gaussian_row`]`(seed, salt, r)`. `inspect` sees every block's values.
pub(crate) fn sketch(
    a: &Rows<'_>,
    l: usize,
    (seed, salt): (u64, u64),
    verify: bool,
    mut inspect: impl FnMut(&[f32]),
) -> Result<Mat<f32>> {
    let n = a.width();
    let mut z = Mat::<f32>::zeros(n, l);
    let mut gauss: Vec<f32> = Vec::new();
    a.for_each_f32(verify, |ids, data| {
        inspect(data);
        gauss.resize(ids.len() * l, 0.0);
        gauss
            .par_chunks_mut(l.max(1))
            .zip(ids.par_iter())
            .for_each(|(dst, &r)| gaussian_row(seed, salt, r, dst));
        let at = MatRef::from_column_major_slice(data, n, ids.len());
        let g = MatRef::from_row_major_slice(&gauss, ids.len(), l);
        matmul(z.as_mut(), Accum::Add, at, g, 1.0f32, Par::rayon(0));
        Ok(())
    })?;
    Ok(z)
}

/// The power iterations from the sketch `z`: `Q ← orth((sA)ᵀ·(sA)·Q)`,
/// `A` scaled by a power of two `s` near `1/‖T‖` (`norm2 = ‖T‖²`) so that
/// squares stay in f32's range. `done(i)` follows iteration `i`.
pub(crate) fn power_iterations(
    a: &Rows<'_>,
    z: &Mat<f32>,
    norm2: f64,
    mut done: impl FnMut(usize),
) -> Result<Mat<f64>> {
    let mut q = orthonormal_columns(z);
    let scale = 2f32.powi(
        -(0.5 * norm2.max(1e-300).log2())
            .round()
            .clamp(-120.0, 120.0) as i32,
    );
    for i in 0..POWER_ITERATIONS {
        q = orthonormal_columns(&power_step(a, &q, scale)?);
        done(i);
    }
    Ok(q)
}

/// One power iteration `Z = (sA)ᵀ·(sA)·Q` in f32.
fn power_step(a: &Rows<'_>, q: &Mat<f64>, scale: f32) -> Result<Mat<f32>> {
    let (n, l) = (q.nrows(), q.ncols());
    let par = Par::rayon(0);
    let q32 = Mat::<f32>::from_fn(n, l, |i, j| q[(i, j)] as f32);
    let mut z = Mat::<f32>::zeros(n, l);
    a.for_each_f32(false, |ids, data| {
        let at = MatRef::from_column_major_slice(data, n, ids.len());
        let mut x = Mat::<f32>::zeros(ids.len(), l);
        matmul(
            x.as_mut(),
            Accum::Replace,
            at.transpose(),
            q32.as_ref(),
            scale,
            par,
        );
        matmul(z.as_mut(), Accum::Add, at, x.as_ref(), scale, par);
        Ok(())
    })?;
    Ok(z)
}

/// What the Rayleigh–Ritz pass finds.
pub(crate) struct Ritz {
    /// `V = Q·W`, `width × k`: the top `k` right singular vectors.
    pub basis: Mat<f64>,
    /// `W`, `l × k`: the top eigenvectors of `H = CᵀC`.
    pub w: Mat<f64>,
    /// The energy each vector captures, `w_aᵀ·H·w_a`.
    pub captured: Vec<f64>,
    /// `‖A‖²_F`, in f64.
    pub norm2: f64,
    /// `C = A·Q` (`rows × l`, f32), when kept: indexed by row.
    pub c: Vec<f32>,
}

/// Rayleigh–Ritz in f64: `C = A·Q` (kept when `keep_rows` gives the
/// number of rows of `A`), `H = CᵀC`, its top `k` eigenvectors `W`;
/// `V = Q·W`, and the energy `A` keeps on `v_a` is `w_aᵀ·H·w_a`, so that
/// `‖A − A·V_k·V_kᵀ‖²_F = ‖A‖² − Σ_{a<k} w_aᵀ·H·w_a`.
pub(crate) fn rayleigh_ritz(
    a: &Rows<'_>,
    q: &Mat<f64>,
    k: usize,
    keep_rows: Option<usize>,
) -> Result<Ritz> {
    let l = q.ncols();
    let par = Par::rayon(0);
    let mut h = Mat::<f64>::zeros(l, l);
    let mut c_all = vec![0.0f32; keep_rows.unwrap_or(0) * l];
    let mut norm2 = 0.0f64;
    a.for_each_f64(|ids, data| {
        norm2 += block_norm2(data);
        let at = MatRef::from_column_major_slice(data, q.nrows(), ids.len());
        let mut c = Mat::<f64>::zeros(ids.len(), l);
        matmul(
            c.as_mut(),
            Accum::Replace,
            at.transpose(),
            q.as_ref(),
            1.0,
            par,
        );
        matmul(h.as_mut(), Accum::Add, c.transpose(), c.as_ref(), 1.0, par);
        if keep_rows.is_some() {
            for (i, &row) in ids.iter().enumerate() {
                for j in 0..l {
                    c_all[row * l + j] = c[(i, j)] as f32;
                }
            }
        }
        Ok(())
    })?;
    let (w, captured) = top_eigenvectors(&h, k)?;
    let mut basis = Mat::<f64>::zeros(q.nrows(), k);
    matmul(
        basis.as_mut(),
        Accum::Replace,
        q.as_ref(),
        w.as_ref(),
        1.0,
        par,
    );
    Ok(Ritz {
        basis,
        w,
        captured,
        norm2,
        c: c_all,
    })
}

/// The top `k` eigenvectors `W` (`l × k`) of the Gram matrix `h` and the
/// energy `w_aᵀ·H·w_a` of each.
fn top_eigenvectors(h: &Mat<f64>, k: usize) -> Result<(Mat<f64>, Vec<f64>)> {
    let l = h.nrows();
    let evd = h
        .as_ref()
        .self_adjoint_eigen(Side::Lower)
        .map_err(|e| Error::Numerical {
            what: "PCA",
            detail: format!("eigendecomposition of the {l}×{l} Gram matrix failed: {e:?}"),
        })?;
    // Eigenvalues come in nondecreasing order: take them from the end.
    let u = evd.U();
    let w = Mat::<f64>::from_fn(l, k, |i, j| u[(i, l - 1 - j)]);
    let mut hw = Mat::<f64>::zeros(l, k);
    matmul(
        hw.as_mut(),
        Accum::Replace,
        h.as_ref(),
        w.as_ref(),
        1.0,
        Par::rayon(0),
    );
    let captured = (0..k)
        .map(|j| (0..l).map(|i| w[(i, j)] * hw[(i, j)]).sum::<f64>())
        .collect();
    Ok((w, captured))
}

/// An orthonormal basis (f64) of the column space of `z` by Householder QR.
pub(crate) fn orthonormal_columns(z: &Mat<f32>) -> Mat<f64> {
    let z64 = Mat::<f64>::from_fn(z.nrows(), z.ncols(), |i, j| z[(i, j)] as f64);
    z64.as_ref().qr().compute_thin_Q()
}

/// Row `row` of the Gaussian sketch matrix: a function of `(seed, salt,
/// row)` only, so the sketch does not depend on how rows are split into
/// blocks. Each fit has its own salt.
pub(crate) fn gaussian_row(seed: u64, salt: u64, row: usize, out: &mut [f32]) {
    let mut rng = SplitMix64(mix64(seed ^ mix64(row as u64 ^ salt)));
    for pair in out.chunks_mut(2) {
        let g = rng.gaussian_pair();
        for (o, v) in pair.iter_mut().zip(g) {
            *o = v as f32;
        }
    }
}

/// splitmix64 (Steele, Lea and Flood 2014): the generator of the sketch
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

/// The splitmix64 finaliser.
pub(crate) fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}
