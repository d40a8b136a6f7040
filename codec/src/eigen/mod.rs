//! The PCA mode (`Mode::Pca`): Eigentransport (Nowrouzezahrai, Simari,
//! Kalogerakis and Fiume, "Eigentransport for efficient and accurate
//! all-frequency relighting", 2007) as a file mode. The matrix is stored as
//! its mean row `μ`, its top `K` eigen-transports `B` (`K × N`, `N = M·C`)
//! and every pixel's `K` coefficients `F` (`P × K`):
//! `T̂[p] = μ + Σ_a F[p][a]·B[a]`. A frame projects the lighting on `μ` and
//! `B` once and each pixel is a `K`-term dot product.
//!
//! [`compress_pca`] fits the basis by a randomized SVD streamed over the raw
//! store ([`fit`]), quantizes `B` and `F` with one scale per component
//! ([`QuantizedMatrix`]) and measures the error of exactly what a decoder
//! reconstructs ([`PcaModel::reconstruct_rows`]).

mod fit;
mod quantized;

pub use quantized::{dequantize, q_max, QuantizedMatrix, MAX_SCALE};

use crate::container::{write_pca_file, Meta, Mode};
use crate::dims::Dims;
use crate::empty::EmptyRows;
use crate::error::{Error, Result};
use crate::limits::Limits;
use crate::raw::RawStore;
use crate::wavelet::Filter;
use faer::linalg::matmul::matmul;
use faer::{Accum, MatMut, MatRef, Par};
use std::path::Path;

/// Default quantization bits of PCA files (raised while a target is missed).
pub const DEFAULT_PCA_BITS: u32 = 12;
/// Default largest rank `--max-error` may choose.
pub const DEFAULT_MAX_RANK: usize = 256;

/// Settings of [`compress_pca`].
#[derive(Clone, Debug)]
pub struct PcaOptions {
    /// A fixed rank `K` (`1..=min(P, N)`), or `None` to choose the smallest
    /// rank whose measured error meets `max_error`.
    pub rank: Option<usize>,
    /// Target relative L2 error of the decoded matrix (without `rank`).
    pub max_error: f64,
    /// The largest rank a `max_error` target may choose.
    pub max_rank: usize,
    /// Quantization bits of basis and coefficients (2..=16).
    pub bits: u32,
    /// Raise `bits` by 2 (up to 16) while quantization misses the target.
    pub raise_bits: bool,
    /// Seed of the randomized sketch.
    pub seed: u64,
    /// zstd level of the chunks.
    pub zstd_level: i32,
    /// Memory the fit may use for one buffer (the sketch, the coefficients).
    pub mem_budget: u64,
}

impl Default for PcaOptions {
    fn default() -> PcaOptions {
        PcaOptions {
            rank: None,
            max_error: 0.01,
            max_rank: DEFAULT_MAX_RANK,
            bits: DEFAULT_PCA_BITS,
            raise_bits: true,
            seed: 0x6c74_6d00,
            zstd_level: 9,
            mem_budget: 4 << 30,
        }
    }
}

/// What [`compress_pca`] did.
#[derive(Clone, Debug)]
pub struct PcaStats {
    /// Size of the written file.
    pub file_bytes: u64,
    /// Size of the dense f32 matrix.
    pub raw_bytes: u64,
    /// The rank stored.
    pub rank: usize,
    /// Quantization bits.
    pub bits: u32,
    /// Measured relative L2 error of the decoded matrix.
    pub achieved_error: f64,
    /// The error the fit predicts for the rank before quantization.
    pub predicted_error: f64,
    /// The measured error meets the target (always true for a fixed rank).
    pub target_met: bool,
    /// The fit's error at every rank `0..=K_fitted` (relative L2).
    pub rank_errors: Vec<f64>,
}

/// A decoded PCA file: mean row, quantized basis and coefficients.
#[derive(Clone, Debug)]
pub struct PcaModel {
    dims: Dims,
    mean: Vec<f32>,
    /// `K × N`, prediction stride `C`.
    basis: QuantizedMatrix,
    /// `K × P` (component-major), prediction stride 1.
    coefficients: QuantizedMatrix,
    /// The decoded basis, `K × N`, row-major.
    basis_values: Vec<f64>,
    /// Rows the raw store flagged all zero (chunk EMPT): decoded as 0.
    empty_rows: Option<EmptyRows>,
}

impl PcaModel {
    /// Assembles a model, checking the parts' shapes against `dims`.
    pub fn new(
        dims: Dims,
        mean: Vec<f32>,
        basis: QuantizedMatrix,
        coefficients: QuantizedMatrix,
    ) -> Result<PcaModel> {
        let (p, n) = (dims.pixels(), dims.row_len());
        let k = basis.rows;
        let ok = mean.len() == n
            && (basis.cols, basis.stride) == (n, dims.channels as usize)
            && (coefficients.rows, coefficients.cols, coefficients.stride) == (k, p, 1)
            && basis.bits == coefficients.bits
            && (1..=p.min(n)).contains(&k);
        if !ok {
            return Err(Error::Invalid(format!(
                "PCA parts do not fit a {p}-pixel matrix of {n} values per row: mean {}, basis {}×{}, coefficients {}×{}",
                mean.len(), basis.rows, basis.cols, coefficients.rows, coefficients.cols
            )));
        }
        let basis_values = basis.dequantize().iter().map(|&v| v as f64).collect();
        Ok(PcaModel {
            dims,
            mean,
            basis,
            coefficients,
            basis_values,
            empty_rows: None,
        })
    }

    /// The model with the mask of rows that decode to exactly 0 (chunk
    /// EMPT); a mask with no row set is dropped.
    pub fn with_empty_rows(mut self, empty: Option<EmptyRows>) -> Result<PcaModel> {
        if let Some(e) = &empty {
            if e.rows() != self.dims.pixels() {
                return Err(Error::BufferTooSmall {
                    what: "empty-row mask",
                    len: e.rows(),
                    need: self.dims.pixels(),
                });
            }
        }
        self.empty_rows = empty.filter(|e| e.count() > 0);
        Ok(self)
    }

    /// Bytes of its buffers in memory (mean, basis in both forms,
    /// coefficients).
    pub fn heap_bytes(&self) -> usize {
        let quantized = |m: &QuantizedMatrix| 4 * (m.q.len() + m.scales.len());
        4 * self.mean.len()
            + quantized(&self.basis)
            + quantized(&self.coefficients)
            + 8 * self.basis_values.len()
    }

    /// The rows that decode to exactly 0, if any are marked.
    pub fn empty_rows(&self) -> Option<&EmptyRows> {
        self.empty_rows.as_ref()
    }

    /// The matrix's dimensions.
    pub fn dims(&self) -> Dims {
        self.dims
    }

    /// `K`, the number of eigen-transports.
    pub fn rank(&self) -> usize {
        self.basis.rows
    }

    /// Quantization bits.
    pub fn bits(&self) -> u32 {
        self.basis.bits
    }

    /// The mean row `μ` (`N = M·C` values, channel-interleaved as a raw row).
    pub fn mean(&self) -> &[f32] {
        &self.mean
    }

    /// The quantized basis (`K × N`).
    pub fn basis(&self) -> &QuantizedMatrix {
        &self.basis
    }

    /// The quantized coefficients (`K × P`, component-major).
    pub fn coefficients(&self) -> &QuantizedMatrix {
        &self.coefficients
    }

    /// Rows `first..first + count` of the decoded matrix, `μ + F·B` in f64
    /// (0 in the rows of the empty-row mask), into `out` (`count × N`,
    /// row-major): the reconstruction of every decoder and of the encoder's
    /// error measurement.
    pub fn reconstruct_rows(&self, first: usize, count: usize, out: &mut Vec<f64>) {
        let (n, k) = (self.dims.row_len(), self.rank());
        let f: Vec<f64> = (first..first + count)
            .flat_map(|px| (0..k).map(move |a| (px, a)))
            .map(|(px, a)| self.coefficients.value(a, px) as f64)
            .collect();
        out.clear();
        out.resize(count * n, 0.0);
        for row in out.chunks_exact_mut(n) {
            row.iter_mut()
                .zip(&self.mean)
                .for_each(|(o, &m)| *o = m as f64);
        }
        let dst = MatMut::from_row_major_slice_mut(out, count, n);
        let fm = MatRef::from_row_major_slice(&f, count, k);
        let bm = MatRef::from_row_major_slice(&self.basis_values, k, n);
        matmul(dst, Accum::Add, fm, bm, 1.0, Par::rayon(0));
        if let Some(e) = &self.empty_rows {
            for (r, row) in out.chunks_exact_mut(n).enumerate() {
                if e.is_empty_row(first + r) {
                    row.fill(0.0);
                }
            }
        }
    }

    /// `‖T − T̂‖²_F` against the store (f64, `T̂` rounded to f32 as decoders
    /// return it), in blocks of about
    /// `block_values` values.
    fn error2(&self, raw: &RawStore, block_values: usize) -> Result<f64> {
        let n = self.dims.row_len();
        let mut err2 = 0.0;
        let mut recon = Vec::new();
        fit::for_each_rows(raw, block_values, false, |start, rows| {
            self.reconstruct_rows(start, rows.len() / n, &mut recon);
            // Decoders round to f32: so does the measurement.
            err2 += rows
                .iter()
                .zip(&recon)
                .map(|(&t, &r)| (t as f64 - r as f32 as f64).powi(2))
                .sum::<f64>();
            Ok(())
        })?;
        Ok(err2)
    }
}

/// Checks a rank against the matrix: `1..=min(P, N)`.
pub fn check_rank(rank: usize, dims: Dims) -> Result<()> {
    let full = dims.pixels().min(dims.row_len());
    if !(1..=full).contains(&rank) {
        return Err(Error::range(
            "PCA rank",
            rank,
            format!(
                "1..={full} (at most min(pixels, lights·channels) = min({}, {}))",
                dims.pixels(),
                dims.row_len()
            ),
        ));
    }
    Ok(())
}

/// Compresses `raw` into a PCA file at `out` (written atomically).
/// `progress` gets (done, total) passes over the store.
pub fn compress_pca(
    raw: &RawStore,
    out: &Path,
    opts: &PcaOptions,
    progress: &dyn Fn(usize, usize),
) -> Result<PcaStats> {
    let dims = raw.dims();
    let full = dims.pixels().min(dims.row_len());
    if !(2..=16).contains(&opts.bits) {
        return Err(Error::range("bits", opts.bits, "2..=16"));
    }
    let fitted = match opts.rank {
        Some(k) => {
            check_rank(k, dims)?;
            k
        }
        None => {
            if !(opts.max_error.is_finite() && opts.max_error > 0.0 && opts.max_error < 1.0) {
                return Err(Error::range(
                    "PCA target error",
                    opts.max_error,
                    "0 < e < 1",
                ));
            }
            check_rank(opts.max_rank, dims).map_err(|_| {
                Error::range(
                    "PCA largest rank (--max-rank)",
                    opts.max_rank,
                    format!("1..={full}"),
                )
            })?;
            opts.max_rank
        }
    };
    let limits = Limits::with_max_alloc(opts.mem_budget);
    let block_values = ((opts.mem_budget / 64) as usize).clamp(dims.row_len(), 1 << 23);
    let f = fit::fit(raw, fitted, opts.seed, block_values, &limits, progress)?;
    let rel = |e2: f64| {
        if f.norm2 > 0.0 {
            (e2.max(0.0) / f.norm2).sqrt()
        } else {
            0.0
        }
    };
    let rank_errors: Vec<f64> = f.err2.iter().map(|&e| rel(e)).collect();
    let (mut k, mut bits) = match opts.rank {
        Some(k) => (k, opts.bits),
        None => {
            let goal = 0.95 * opts.max_error;
            let Some(k) = (1..=fitted).find(|&k| rank_errors[k] <= goal) else {
                return Err(Error::range(
                    "PCA target error",
                    opts.max_error,
                    format!("at least {:.4e}: rank {fitted} (--max-rank) leaves {:.4e}; raise --max-rank or the target", rank_errors[fitted] / 0.95, rank_errors[fitted]),
                ));
            };
            (k, opts.bits)
        }
    };
    // Rows the store flags all zero (checked by the fit's verified pass).
    let empty = EmptyRows::from_fn(dims.pixels(), |r| raw.is_zero_row(r));
    let mut tries = 0;
    loop {
        let model = quantize(&f, dims, k, bits)?.with_empty_rows(Some(empty.clone()))?;
        let achieved = rel(model.error2(raw, block_values)?);
        let met = opts.rank.is_some() || achieved <= opts.max_error;
        let can_more_bits = opts.raise_bits && bits < 16;
        tries += 1;
        if met || tries >= 12 || (k == fitted && !can_more_bits) {
            let meta = pca_meta(dims, &model, opts, achieved, f.norm2.sqrt());
            let file_bytes = write_pca_file(
                out,
                meta,
                raw.albedo(),
                raw.surface(),
                model.empty_rows(),
                &model,
                opts.zstd_level,
            )?;
            raw.check_unchanged()?;
            return Ok(PcaStats {
                file_bytes,
                raw_bytes: dims.raw_bytes(),
                rank: k,
                bits,
                achieved_error: achieved,
                predicted_error: rank_errors[k],
                target_met: met,
                rank_errors,
            });
        }
        // The quantization's share of the error decides what to raise.
        let quant2 = achieved.powi(2) - rank_errors[k].powi(2);
        if can_more_bits && (quant2 > 0.3 * opts.max_error.powi(2) || k == fitted) {
            bits += 2;
        } else {
            k = (k + (k / 8).max(1)).min(fitted);
        }
    }
}

/// The file's metadata: mode `pca`, `terms` = K, filters unused (0).
fn pca_meta(dims: Dims, model: &PcaModel, opts: &PcaOptions, achieved: f64, norm: f64) -> Meta {
    Meta {
        dims,
        mode: Mode::Pca,
        row_filter: Filter::Haar,
        col_filter: Filter::Haar,
        bits: model.bits(),
        seed: opts.seed,
        target_error: if opts.rank.is_some() {
            0.0
        } else {
            opts.max_error as f32
        },
        achieved_error: achieved as f32,
        terms: model.rank() as u32,
        norm,
    }
}

/// The first `k` components of a fit quantized to `bits`.
fn quantize(f: &fit::CentredFit, dims: Dims, k: usize, bits: u32) -> Result<PcaModel> {
    let (p, n) = (dims.pixels(), dims.row_len());
    let kf = f.basis.ncols();
    let b: Vec<f32> = (0..k)
        .flat_map(|a| (0..n).map(move |i| (i, a)))
        .map(|(i, a)| f.basis[(i, a)] as f32)
        .collect();
    let c: Vec<f32> = (0..k)
        .flat_map(|a| (0..p).map(move |px| px * kf + a))
        .map(|i| f.coefficients[i])
        .collect();
    let mean = f.mean.iter().map(|&m| m as f32).collect();
    PcaModel::new(
        dims,
        mean,
        QuantizedMatrix::quantize(&b, k, n, dims.channels as usize, bits),
        QuantizedMatrix::quantize(&c, k, p, 1, bits),
    )
}
