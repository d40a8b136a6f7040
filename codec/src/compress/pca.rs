//! [`compress_pca`], the `pca` mode's driver: the fit
//! ([`crate::pca`]), the choice of rank and bits, and the file.

use super::Mode;
use crate::container::{write_pca_file, Meta, OptionalChunks};
use crate::dims::Dims;
use crate::empty::EmptyRows;
use crate::error::{Error, Result};
use crate::limits::Limits;
use crate::pca::{check_rank, fit, PcaModel, QuantizedMatrix};
use crate::progress::Progress;
use crate::raw::RawStore;
use crate::wavelet::Filter;
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
    /// The largest rank a `max_error` target may choose (the rank of the
    /// first fit; see `raise_rank`).
    pub max_rank: usize,
    /// While no rank up to the fitted one meets `max_error`, fit again at
    /// twice the rank, up to the matrix's full rank `min(P, N)` (as
    /// `raise_bits` raises the bits). Off: `max_rank` is a hard limit.
    pub raise_rank: bool,
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
            raise_rank: false,
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

/// Compresses `raw` into a PCA file at `out` (written atomically).
/// `progress` gets ([`Stage::Fit`](crate::Stage::Fit), done, total) passes over the store.
pub fn compress_pca(
    raw: &RawStore,
    out: &Path,
    opts: &PcaOptions,
    progress: Progress<'_>,
) -> Result<PcaStats> {
    crate::nearfield::refuse_plane_rows(raw, "the pca mode")?;
    let dims = raw.dims();
    // At least one row, however long (`clamp` would panic when a row is
    // longer than the usual cap).
    let block_values = ((opts.mem_budget / 64) as usize)
        .min(1 << 23)
        .max(dims.row_len());
    let Fitted {
        fit: f,
        rank_errors,
        rank: mut k,
        fitted,
    } = fit_for_target(raw, opts, block_values, progress)?;
    let mut bits = opts.bits;
    let rel = |e2: f64| relative(e2, f.norm2);
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
                OptionalChunks {
                    surface: raw.surface(),
                    mesh: raw.mesh(),
                    empty_rows: model.empty_rows(),
                    near_field: None,
                    column_norms: false,
                    priors: false,
                },
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

/// `sqrt(e2 / norm2)`, 0 for a zero matrix.
fn relative(e2: f64, norm2: f64) -> f64 {
    if norm2 > 0.0 {
        (e2.max(0.0) / norm2).sqrt()
    } else {
        0.0
    }
}

/// A fit and the rank it starts from.
struct Fitted {
    fit: fit::CentredFit,
    /// The fit's relative L2 error at every rank `0..=fitted`.
    rank_errors: Vec<f64>,
    /// The fixed rank, or the smallest whose error is 0.95 of the target.
    rank: usize,
    /// The rank of the fit.
    fitted: usize,
}

/// Fits `raw` at the fixed rank, or for a target at `max_rank`, doubled
/// (up to the full rank) while no rank meets the target and
/// `opts.raise_rank` is set. A target no rank meets is refused with the
/// setting that limited the rank: `--max-rank`, the memory of the fit
/// (`--mem-budget`), or the matrix's full rank.
fn fit_for_target(
    raw: &RawStore,
    opts: &PcaOptions,
    block_values: usize,
    progress: Progress<'_>,
) -> Result<Fitted> {
    let dims = raw.dims();
    let full = dims.pixels().min(dims.row_len());
    let mut fitted = fitted_rank(opts, dims)?;
    let limits = Limits::with_max_alloc(opts.mem_budget);
    let goal = 0.95 * opts.max_error;
    loop {
        let f = match fit::fit(raw, fitted, opts.seed, block_values, &limits, progress) {
            Err(e @ Error::Limit { .. }) if fitted > opts.max_rank => {
                return Err(Error::range(
                    "PCA target error",
                    opts.max_error,
                    format!("reachable within the memory of the fit: no rank up to {} meets it, and the fit of rank {fitted} needs more than --mem-budget allows ({e}); raise --mem-budget or the target", fitted / 2),
                ))
            }
            r => r?,
        };
        let rank_errors: Vec<f64> = f.err2.iter().map(|&e| relative(e, f.norm2)).collect();
        let rank = match opts.rank {
            Some(k) => Some(k),
            None => (1..=fitted).find(|&k| rank_errors[k] <= goal),
        };
        if let Some(rank) = rank {
            return Ok(Fitted {
                fit: f,
                rank_errors,
                rank,
                fitted,
            });
        }
        let left = rank_errors[fitted];
        if !opts.raise_rank || fitted == full {
            let limit = if fitted == full {
                format!("the matrix's full rank min(pixels, lights·channels) = {full}")
            } else {
                format!("--max-rank {fitted} (the matrix's full rank is {full})")
            };
            return Err(Error::range(
                "PCA target error",
                opts.max_error,
                format!("at least {:.4e}: rank {fitted}, limited by {limit}, leaves {left:.4e}; raise that or the target", left / 0.95),
            ));
        }
        fitted = (fitted * 2).min(full);
    }
}

/// Checks the options against the matrix: the rank the fit computes (the
/// fixed rank, or the largest a target may choose).
fn fitted_rank(opts: &PcaOptions, dims: Dims) -> Result<usize> {
    let full = dims.pixels().min(dims.row_len());
    if !(2..=16).contains(&opts.bits) {
        return Err(Error::range("bits", opts.bits, "2..=16"));
    }
    Ok(match opts.rank {
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
    })
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
