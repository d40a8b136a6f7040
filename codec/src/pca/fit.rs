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

use crate::error::Result;
use crate::limits::Limits;
use crate::progress::{Progress, Stage};
use crate::raw::RawStore;
use crate::rsvd::{
    power_iterations, rayleigh_ritz, sketch, Ritz, Rows, OVERSAMPLING, POWER_ITERATIONS,
};
use faer::Mat;
use rayon::prelude::*;

/// The salt of this fit's Gaussian sketch rows ([`crate::rsvd::gaussian_row`]).
const SKETCH_SALT: u64 = 0xBB67_AE85_84CA_A73B;

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

/// Fits `rank` eigen-transports (`1..=min(P, N)`), reading blocks of about
/// `block_values` values. Buffers sized by the store are checked against
/// `limits`.
pub(crate) fn fit(
    raw: &RawStore,
    rank: usize,
    seed: u64,
    block_values: usize,
    limits: &Limits,
    progress: Progress<'_>,
) -> Result<CentredFit> {
    let dims = raw.dims();
    let (p, n) = (dims.pixels(), dims.row_len());
    let l = (rank + OVERSAMPLING).min(p.min(n));
    let _sketch = limits.check_alloc("PCA sketch", (n * l) as u64, 8)?;
    let _coefficients = limits.check_alloc("PCA row coefficients", (p * l) as u64, 4)?;
    let passes = 3 + POWER_ITERATIONS as u64;
    progress.report(Stage::Fit, 0, passes);
    let (mean, norm2) = mean_pass(raw, block_values)?;
    progress.report(Stage::Fit, 1, passes);
    let a = Rows::centred(raw, block_values, &mean);
    let z = sketch(&a, l, (seed, SKETCH_SALT), false, |_| {})?;
    progress.report(Stage::Fit, 2, passes);
    let q = power_iterations(&a, &z, norm2, |i| {
        progress.report(Stage::Fit, 3 + i as u64, passes)
    })?;
    let ritz = rayleigh_ritz(&a, &q, rank, Some(p))?;
    progress.report(Stage::Fit, passes, passes);
    let (err2, coefficients) = errors_and_coefficients(&ritz, p, rank);
    Ok(CentredFit {
        mean,
        basis: ritz.basis,
        coefficients,
        norm2,
        err2,
    })
}

/// `μ` and `‖T‖²` in f64, verifying every block.
fn mean_pass(raw: &RawStore, block_values: usize) -> Result<(Vec<f64>, f64)> {
    let (p, n) = (raw.dims().pixels(), raw.dims().row_len());
    let mut sum = vec![0.0f64; n];
    let mut norm2 = 0.0f64;
    raw.for_each_row_block(block_values, true, |_, rows| {
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

/// The fit's error at every rank, `err2[k] = ‖A‖² − Σ_{a<k} w_aᵀ·H·w_a`,
/// and every row's coefficients `F = C·W` (`P × k`, f32).
fn errors_and_coefficients(ritz: &Ritz, p: usize, k: usize) -> (Vec<f64>, Vec<f32>) {
    let (w, c_all) = (&ritz.w, &ritz.c);
    let l = w.nrows();
    let mut err2 = vec![ritz.norm2];
    let mut left = ritz.norm2;
    for c in &ritz.captured {
        left -= c;
        err2.push(left.max(0.0));
    }
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
    (err2, coefficients)
}
