//! The mean-centred principal components of the transport rows, streamed
//! over the raw store (Eigentransport §3, eq. 2): rows are pixels of
//! `N = M·C` values (lights × channels, as stored), `μ` is the mean row and
//! the eigen-transports are the top right singular vectors of the centred
//! matrix `A = T − 1·μᵀ`.
//!
//! The randomized SVD of Halko, Martinsson and Tropp 2011 ("Finding
//! structure with randomness"): a Gaussian sketch `Aᵀ·G`, power iterations
//! `AᵀA·Q` with re-orthonormalisation (in f32, scaled by a power of two),
//! and a Rayleigh–Ritz pass in f64 that also keeps `A·Q`, from which every
//! row's coefficients follow without another pass. Every pass reads blocks
//! of rows with positioned reads; the first verifies every raw block, and
//! the store must not change during the fit.

use crate::error::{Error, Result};
use crate::limits::Limits;
use crate::raw::RawStore;
use crate::rows::{mix64, SplitMix64};
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatRef, Par, Side};
use rayon::prelude::*;

/// Extra columns of the randomized sketch beyond the rank.
const OVERSAMPLING: usize = 10;
/// Power iterations of the randomized SVD.
const POWER_ITERATIONS: usize = 2;

/// The fit: mean row, eigen-transports and every row's coefficients.
pub(crate) struct CentredFit {
    /// `μ`, `N` values.
    pub mean: Vec<f64>,
    /// `V`: `N × K`, column `a` the `a`-th eigen-transport.
    pub basis: Mat<f64>,
    /// `F = A·V`, `P × K` (f32 is far below any quantizer's step).
    pub coefficients: Vec<f32>,
    /// `‖T‖²_F` in f64.
    pub norm2: f64,
    /// `err2[k] = ‖A − A·V_k·V_kᵀ‖²_F`, `k = 0..=K`.
    pub err2: Vec<f64>,
}

/// Reads the store in blocks of about `block_values` values, calling `f`
/// with the first pixel of each block and its rows (`rows × N`, f32).
pub(crate) fn for_each_rows(
    raw: &RawStore,
    block_values: usize,
    verify: bool,
    mut f: impl FnMut(usize, &[f32]) -> Result<()>,
) -> Result<()> {
    let (p, n) = (raw.dims().pixels(), raw.dims().row_len());
    let step = (block_values / n).max(1);
    let mut verifier = verify.then(|| raw.verifier());
    let mut buf = Vec::new();
    for start in (0..p).step_by(step) {
        let range = start..(start + step).min(p);
        raw.read_rows(range.clone(), &mut buf)?;
        if let Some(v) = verifier.as_mut() {
            v.feed(start, &buf)?;
        }
        f(start, &buf)?;
    }
    if let Some(v) = verifier {
        v.finish()?;
    }
    raw.check_unchanged()
}

/// Fits `rank` eigen-transports (`1..=min(P, N)`), reading blocks of about
/// `block_values` values. Buffers sized by the store are checked against
/// `limits`.
pub(crate) fn fit(
    raw: &RawStore,
    rank: usize,
    seed: u64,
    block_values: usize,
    limits: &Limits,
    progress: &dyn Fn(usize, usize),
) -> Result<CentredFit> {
    let dims = raw.dims();
    let (p, n) = (dims.pixels(), dims.row_len());
    let l = (rank + OVERSAMPLING).min(p.min(n));
    let _sketch = limits.check_alloc("PCA sketch", (n * l) as u64, 8)?;
    let _coefficients = limits.check_alloc("PCA row coefficients", (p * l) as u64, 4)?;
    let passes = 3 + POWER_ITERATIONS;
    progress(0, passes);
    let (mean, norm2) = mean_pass(raw, block_values)?;
    progress(1, passes);
    let mean32: Vec<f32> = mean.iter().map(|&v| v as f32).collect();
    let mut q = orthonormal_columns(&sketch(raw, &mean32, l, seed, block_values)?);
    progress(2, passes);
    // Scaled by a power of two near 1/‖T‖ so that squares stay in f32's range.
    let scale = 2f32.powi(
        -(0.5 * norm2.max(1e-300).log2())
            .round()
            .clamp(-120.0, 120.0) as i32,
    );
    for i in 0..POWER_ITERATIONS {
        q = orthonormal_columns(&power_step(raw, &mean32, &q, scale, block_values)?);
        progress(3 + i, passes);
    }
    let fit = rayleigh_ritz(raw, &mean, &q, rank, block_values)?;
    progress(passes, passes);
    Ok(CentredFit { mean, norm2, ..fit })
}

/// `μ` and `‖T‖²` in f64, verifying every block.
fn mean_pass(raw: &RawStore, block_values: usize) -> Result<(Vec<f64>, f64)> {
    let (p, n) = (raw.dims().pixels(), raw.dims().row_len());
    let mut sum = vec![0.0f64; n];
    let mut norm2 = 0.0f64;
    for_each_rows(raw, block_values, true, |_, rows| {
        for row in rows.chunks_exact(n) {
            for (s, &v) in sum.iter_mut().zip(row) {
                *s += v as f64;
            }
        }
        norm2 += rows
            .par_chunks(1 << 16)
            .map(|c| c.iter().map(|&v| v as f64 * v as f64).sum::<f64>())
            .sum::<f64>();
        Ok(())
    })?;
    sum.iter_mut().for_each(|s| *s /= p as f64);
    Ok((sum, norm2))
}

/// `rows − μ` in place.
fn centre(rows: &mut [f32], mean: &[f32]) {
    rows.par_chunks_mut(mean.len())
        .for_each(|r| r.iter_mut().zip(mean).for_each(|(v, m)| *v -= m));
}

/// `Z = Aᵀ·G`, `G` Gaussian (`P × l`, row `p` a function of `(seed, p)`).
fn sketch(
    raw: &RawStore,
    mean: &[f32],
    l: usize,
    seed: u64,
    block_values: usize,
) -> Result<Mat<f32>> {
    let n = mean.len();
    let mut z = Mat::<f32>::zeros(n, l);
    let mut gauss = Vec::new();
    let mut a = Vec::new();
    for_each_rows(raw, block_values, false, |start, rows| {
        let r = rows.len() / n;
        a.clear();
        a.extend_from_slice(rows);
        centre(&mut a, mean);
        gauss.resize(r * l, 0.0f32);
        gauss
            .par_chunks_mut(l)
            .enumerate()
            .for_each(|(i, dst)| gaussian_row(seed, start + i, dst));
        let at = MatRef::from_column_major_slice(&a, n, r);
        let g = MatRef::from_row_major_slice(&gauss, r, l);
        matmul(z.as_mut(), Accum::Add, at, g, 1.0f32, Par::rayon(0));
        Ok(())
    })?;
    Ok(z)
}

/// One power iteration `Z = (sA)ᵀ·(sA)·Q` in f32.
fn power_step(
    raw: &RawStore,
    mean: &[f32],
    q: &Mat<f64>,
    scale: f32,
    block_values: usize,
) -> Result<Mat<f32>> {
    let (n, l) = (q.nrows(), q.ncols());
    let par = Par::rayon(0);
    let q32 = Mat::<f32>::from_fn(n, l, |i, j| q[(i, j)] as f32);
    let mut z = Mat::<f32>::zeros(n, l);
    let mut a = Vec::new();
    for_each_rows(raw, block_values, false, |_, rows| {
        let r = rows.len() / n;
        a.clear();
        a.extend_from_slice(rows);
        centre(&mut a, mean);
        let at = MatRef::from_column_major_slice(&a, n, r);
        let mut x = Mat::<f32>::zeros(r, l);
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

/// Rayleigh–Ritz in f64: `C = A·Q` (kept), `H = CᵀC`, its top `k`
/// eigenvectors `W`; `V = Q·W`, `F = C·W`, and the energy left by the
/// first `k` vectors is `‖A‖² − Σ_{a<k} w_aᵀ·H·w_a`.
fn rayleigh_ritz(
    raw: &RawStore,
    mean: &[f64],
    q: &Mat<f64>,
    k: usize,
    block_values: usize,
) -> Result<CentredFit> {
    let (n, l) = (q.nrows(), q.ncols());
    let p = raw.dims().pixels();
    let par = Par::rayon(0);
    let mut h = Mat::<f64>::zeros(l, l);
    let mut c_all = vec![0.0f32; p * l];
    let mut a_norm2 = 0.0f64;
    let mut a = Vec::new();
    for_each_rows(raw, block_values, false, |start, rows| {
        let r = rows.len() / n;
        a.clear();
        a.extend(
            rows.iter()
                .enumerate()
                .map(|(i, &v)| v as f64 - mean[i % n]),
        );
        a_norm2 += a
            .par_chunks(1 << 16)
            .map(|c| c.iter().map(|v| v * v).sum::<f64>())
            .sum::<f64>();
        let at = MatRef::from_column_major_slice(&a, n, r);
        let mut c = Mat::<f64>::zeros(r, l);
        matmul(
            c.as_mut(),
            Accum::Replace,
            at.transpose(),
            q.as_ref(),
            1.0,
            par,
        );
        matmul(h.as_mut(), Accum::Add, c.transpose(), c.as_ref(), 1.0, par);
        for i in 0..r {
            for j in 0..l {
                c_all[(start + i) * l + j] = c[(i, j)] as f32;
            }
        }
        Ok(())
    })?;
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
        par,
    );
    let mut err2 = vec![a_norm2];
    let mut left = a_norm2;
    for j in 0..k {
        left -= (0..l).map(|i| w[(i, j)] * hw[(i, j)]).sum::<f64>();
        err2.push(left.max(0.0));
    }
    let mut basis = Mat::<f64>::zeros(n, k);
    matmul(
        basis.as_mut(),
        Accum::Replace,
        q.as_ref(),
        w.as_ref(),
        1.0,
        par,
    );
    let w32: Vec<f32> = (0..l * k).map(|i| w[(i / k, i % k)] as f32).collect();
    let mut coefficients = vec![0.0f32; p * k];
    coefficients
        .par_chunks_mut(k.max(1))
        .zip(c_all.par_chunks(l.max(1)))
        .for_each(|(f, c)| {
            for (i, &ci) in c.iter().enumerate() {
                for (fa, wa) in f.iter_mut().zip(&w32[i * k..(i + 1) * k]) {
                    *fa += ci * wa;
                }
            }
        });
    Ok(CentredFit {
        mean: Vec::new(),
        basis,
        coefficients,
        norm2: 0.0,
        err2,
    })
}

/// An orthonormal basis (f64) of the column space of `z` by Householder QR.
fn orthonormal_columns(z: &Mat<f32>) -> Mat<f64> {
    let z64 = Mat::<f64>::from_fn(z.nrows(), z.ncols(), |i, j| z[(i, j)] as f64);
    z64.as_ref().qr().compute_thin_Q()
}

/// Row `row` of the Gaussian sketch: a function of `(seed, row)` only, so
/// the sketch does not depend on how rows are split into blocks.
fn gaussian_row(seed: u64, row: usize, out: &mut [f32]) {
    let mut rng = SplitMix64(mix64(seed ^ mix64(row as u64 ^ 0xBB67_AE85_84CA_A73B)));
    for pair in out.chunks_mut(2) {
        let g = rng.gaussian_pair();
        for (o, v) in pair.iter_mut().zip(g) {
            *o = v as f32;
        }
    }
}
