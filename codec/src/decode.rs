//! Column decoding, shared by the encoder's error measurements, export and
//! relighting: dequantize into a column image in the Mallat layout of the
//! column's depth, undo the band weights, then inverse steps, then the
//! file's empty rows set to 0.

use crate::column::SparseColumn;
use crate::container::{LtmFile, Meta};
use crate::empty::EmptyRows;
use crate::error::{Error, Result};
use crate::limits::{Charge, Limits};
use crate::quant::{decode_scale, levels, scale_groups, BandWeights};
use crate::wavelet::{self, band_size, PlaneMut, RowMode};
use rayon::prelude::*;

/// Scales above this are dequantized in f64: `q·s` in f32 could overflow
/// (`|q| < 2^15`). The encoder never writes one (its matrices have norms of
/// at most 2^100), so its files decode with the f32 product.
const F64_SCALE: f32 = (1u128 << 100) as f32;

/// A quantized value `q` times its scale `s`, over the levels `q_levels`.
#[inline]
fn scaled(q: i32, s: f32, q_levels: f32) -> f32 {
    if s <= F64_SCALE {
        q as f32 * s / q_levels
    } else {
        (q as f64 * s as f64 / q_levels as f64) as f32
    }
}

/// Decoding state for one file's column filter and image size.
pub struct ColumnDecoder {
    meta: Meta,
    /// The band weights of every depth.
    weights: BandWeights,
    /// `1 / weight` per position, per depth.
    inv_weights: Vec<Vec<f32>>,
    /// Scale group per position, per depth.
    groups: Vec<Vec<u8>>,
    /// Rows decoded as exactly 0.
    empty_rows: Option<EmptyRows>,
    /// The inverse weights' and groups' bytes, charged to the limits.
    _charge: Charge,
}

impl ColumnDecoder {
    /// The largest decoded column value [`ColumnDecoder::decode`] returns,
    /// 2^112 ≈ 5.2e33: a file the encoder writes holds a matrix of norm at
    /// most 2^100 ([`MAX_NORM`](crate::compress::MAX_NORM)), and no value
    /// of a column exceeds the norm, so larger values come only from a
    /// crafted file. Below this bound the inverse row transform of any
    /// decoded row stays finite.
    pub const MAX_DECODED: f32 = (1u128 << 112) as f32;

    /// Precomputes the band weights and scale groups of `meta`'s column
    /// filter and image size at every depth, charged to `limits`.
    pub fn new(meta: &Meta, limits: &Limits) -> Result<ColumnDecoder> {
        ColumnDecoder::to_depth(meta, meta.max_depth(), limits)
    }

    /// [`ColumnDecoder::new`] for columns of depth `0..=deepest` only.
    fn to_depth(meta: &Meta, deepest: u32, limits: &Limits) -> Result<ColumnDecoder> {
        let (w, h) = (meta.dims.width() as usize, meta.dims.height() as usize);
        let deepest = deepest.min(meta.max_depth());
        let depths = u64::from(deepest) + 1;
        let charge = limits.check_alloc("column decoder tables", (w * h) as u64, 5 * depths)?;
        let weights = BandWeights::new(meta.col_filter, w, h, deepest, limits)?;
        let inv_weights = (0..=deepest)
            .map(|d| weights.map(d).iter().map(|x| 1.0 / x).collect())
            .collect();
        let groups = (0..=deepest).map(|d| scale_groups(w, h, d)).collect();
        Ok(ColumnDecoder {
            meta: meta.clone(),
            weights,
            inv_weights,
            groups,
            empty_rows: None,
            _charge: charge,
        })
    }

    /// The band weights of every depth (computed once, by
    /// [`ColumnDecoder::new`]).
    pub fn band_weights(&self) -> &BandWeights {
        &self.weights
    }

    /// The decoder of an opened file: [`ColumnDecoder::new`] up to the
    /// depth of the file's deepest column (the tables of deeper ones would
    /// never be used), with the file's empty-row mask.
    pub fn for_file(file: &LtmFile, limits: &Limits) -> Result<ColumnDecoder> {
        let deepest = file.columns().iter().map(|c| u32::from(c.depth)).max();
        let decoder = ColumnDecoder::to_depth(file.meta(), deepest.unwrap_or(0), limits)?;
        Ok(decoder.with_empty_rows(file.empty_rows().cloned()))
    }

    /// Sets the rows [`ColumnDecoder::decode`] outputs as exactly 0 (a mask
    /// of another size than the file's rows is ignored).
    pub fn with_empty_rows(mut self, empty_rows: Option<EmptyRows>) -> ColumnDecoder {
        self.empty_rows = empty_rows.filter(|e| e.rows() == self.meta.dims.pixels());
        self
    }

    /// The rows decoded as exactly 0, if any mask is set.
    pub fn empty_rows(&self) -> Option<&EmptyRows> {
        self.empty_rows.as_ref()
    }

    /// Adds `gain ×` channel `channel` of `col`, dequantized (still weighted),
    /// into `plane` (one column image of `width·height` values).
    ///
    /// # Panics
    /// If `channel` or a position of `col` is out of range, or `col` holds
    /// too few values: the hot path trusts columns that a reader parsed.
    /// [`ColumnDecoder::decode`] checks all three first.
    pub fn accumulate(&self, col: &SparseColumn, channel: usize, gain: f32, plane: &mut [f32]) {
        for k in 0..col.indices.len() {
            plane[col.indices[k] as usize] += gain * self.dequantize(col, k, channel);
        }
    }

    /// The weighted value of coefficient `k` of `col`, channel `channel`.
    #[inline]
    pub fn dequantize(&self, col: &SparseColumn, k: usize, channel: usize) -> f32 {
        let channels = self.meta.dims.channels as usize;
        let group = self.groups[col.depth as usize][col.indices[k] as usize] as usize;
        let code = col
            .scale_codes
            .get(group * channels + channel)
            .copied()
            .unwrap_or(0);
        scaled(
            col.values[k * channels + channel],
            decode_scale(code),
            levels(self.meta.bits),
        )
    }

    /// The L2 norm of `col`'s weighted values: the root of the sum of the
    /// squared [`ColumnDecoder::dequantize`] values, in f64, with each
    /// scale decoded once.
    pub fn weighted_norm(&self, col: &SparseColumn) -> f64 {
        let channels = self.meta.dims.channels as usize;
        let (q_levels, groups) = (levels(self.meta.bits), &self.groups[col.depth as usize]);
        let scales: Vec<f32> = col.scale_codes.iter().map(|&e| decode_scale(e)).collect();
        let mut sum = 0.0f64;
        for (k, &i) in col.indices.iter().enumerate() {
            let group = groups[i as usize] as usize;
            for c in 0..channels {
                let s = scales.get(group * channels + c).copied().unwrap_or(0.0);
                let v = scaled(col.values[k * channels + c], s, q_levels);
                sum += (v as f64).powi(2);
            }
        }
        sum.sqrt()
    }

    /// Checks column `j`'s stored priority norm against the norm of the
    /// decoded column, `decoded` ([`ColumnDecoder::weighted_norm`] rounded
    /// to `f32`): the NORM chunk promises them equal, bit for bit
    /// (docs/FORMAT.md).
    pub fn check_norm(j: usize, stored: f32, decoded: f32) -> Result<()> {
        if decoded.to_bits() == stored.to_bits() {
            return Ok(());
        }
        Err(Error::corrupt(
            "NORM chunk",
            format!(
                "column {j}: the file stores priority norm {stored:e}, the column decodes to {decoded:e} (they must be equal bit for bit)"
            ),
        ))
    }

    /// Checks every norm `file` stores (chunk NORM) against its column:
    /// each column is decoded once, in parallel, and
    /// [`ColumnDecoder::check_norm`]ed; the first column (in column order)
    /// whose norm disagrees is the error. So no light is ranked by a norm
    /// that was not checked. A file without NORM passes.
    pub fn check_stored_norms(&self, file: &LtmFile) -> Result<()> {
        let Some(norms) = file.column_norms() else {
            return Ok(());
        };
        let decoded = self.column_norms(file)?;
        let problem =
            (0..norms.len()).find_map(|j| ColumnDecoder::check_norm(j, norms[j], decoded[j]).err());
        problem.map_or(Ok(()), Err)
    }

    /// Every column's priority norm, [`ColumnDecoder::weighted_norm`] of
    /// the decoded column rounded to `f32`: each column is decoded once, in
    /// parallel, and not kept. A column that fails to decode is the error
    /// (which one, when several fail, is not specified).
    pub fn column_norms(&self, file: &LtmFile) -> Result<Vec<f32>> {
        (0..file.meta().dims.lights())
            .into_par_iter()
            .map(|j| Ok(self.weighted_norm(&file.column(j)?) as f32))
            .collect()
    }

    /// The dequantization step `s/Q` of scale group `group`, channel
    /// `channel` of `col` (0 for a group the column does has no scale for),
    /// in f64: [`ColumnDecoder::dequantize`] is `q · step / weight` up to
    /// rounding.
    pub fn step(&self, col: &SparseColumn, group: usize, channel: usize) -> f64 {
        let channels = self.meta.dims.channels as usize;
        let code = col
            .scale_codes
            .get(group * channels + channel)
            .copied()
            .unwrap_or(0);
        decode_scale(code) as f64 / levels(self.meta.bits) as f64
    }

    /// The scale group (the quantizer's `scale_groups`: 0 the low band,
    /// `k` the detail bands of level `k`) of `position` in a column at
    /// `depth` (0 for a depth or position out of range).
    pub fn scale_group(&self, depth: u32, position: usize) -> u8 {
        self.groups
            .get(depth as usize)
            .and_then(|g| g.get(position))
            .copied()
            .unwrap_or(0)
    }

    /// Undoes the band weights of depth `depth` on a plane of weighted
    /// coefficients.
    pub fn unweight(&self, depth: u32, plane: &mut [f32]) {
        for (v, w) in plane.iter_mut().zip(&self.inv_weights[depth as usize]) {
            *v *= w;
        }
    }

    /// The image width and the band that the inverse step from depth
    /// `level` rebuilds, with `level` checked against `1..=max_depth`.
    fn step_band(&self, level: u32) -> Result<(usize, usize, usize)> {
        let max = self.meta.max_depth();
        if level == 0 || level > max {
            return Err(Error::range(
                "inverse step level",
                level,
                format!("1..={max}"),
            ));
        }
        let (w, h) = (
            self.meta.dims.width() as usize,
            self.meta.dims.height() as usize,
        );
        let (bw, bh) = band_size(w, h, level - 1);
        Ok((w, bw, bh))
    }

    /// One inverse column step from depth `level` to `level − 1` of `lanes`
    /// interleaved planes (bit-identical to stepping each alone), with the
    /// rows filtered as `rows` says ([`wavelet::inverse_step`]); `work`
    /// needs `lanes · width · height` values.
    pub fn inverse_step(
        &self,
        level: u32,
        planes: &mut [f32],
        lanes: usize,
        work: &mut [f32],
        rows: RowMode<'_>,
    ) -> Result<()> {
        let (w, bw, bh) = self.step_band(level)?;
        let plane = PlaneMut::new(planes, w, bw, bh, lanes)?;
        wavelet::inverse_step(self.meta.col_filter, plane, work, rows)
    }

    /// The last inverse step (from depth 1, whose region is the whole
    /// image), skipping zero rows as [`RowMode::Sparse`] says of
    /// `nonzero`. With a lifting column filter the result goes to `out` in
    /// one pass and `planes` is left as scratch; with the others the step
    /// runs in place in `planes`, with `out` as its scratch. Returns
    /// whether the result is in `out`.
    pub fn last_inverse_step_lanes_sparse(
        &self,
        planes: &mut [f32],
        lanes: usize,
        out: &mut [f32],
        nonzero: &mut [bool],
    ) -> Result<bool> {
        let into = self.meta.col_filter.is_lifting();
        let (work, rows) = if into {
            (&mut [][..], RowMode::sparse_into(nonzero, out))
        } else {
            (out, RowMode::sparse(nonzero))
        };
        self.inverse_step(1, planes, lanes, work, rows)?;
        Ok(into)
    }

    /// Checks what [`ColumnDecoder::accumulate`] indexes by: `channel`, the
    /// column's positions and its count of values.
    fn check_column(&self, col: &SparseColumn, channel: usize) -> Result<()> {
        let channels = self.meta.dims.channels as usize;
        if channel >= channels {
            return Err(Error::range("channel", channel, format!("0..{channels}")));
        }
        let need = col.indices.len() * channels;
        if col.values.len() != need {
            return Err(Error::BufferTooSmall {
                what: "column values (channels per position)",
                len: col.values.len(),
                need,
            });
        }
        let p = self.meta.dims.pixels();
        match col.indices.iter().find(|&&i| i as usize >= p) {
            Some(&i) => Err(Error::range("column position", i, format!("0..{p}"))),
            None => Ok(()),
        }
    }

    /// Decodes channel `channel` of a column into `plane` (overwritten), in
    /// the row-wavelet lighting basis, with the empty rows exactly 0. `work` needs `width·height` values.
    /// A column that decodes to a value beyond [`ColumnDecoder::MAX_DECODED`] (or not a
    /// number) is an error: only a crafted file holds one.
    pub fn decode(
        &self,
        col: &SparseColumn,
        channel: usize,
        plane: &mut [f32],
        work: &mut [f32],
    ) -> Result<()> {
        let p = self.meta.dims.pixels();
        if plane.len() != p || work.len() < p {
            return Err(Error::BufferTooSmall {
                what: "column decode plane and work",
                len: plane.len().min(work.len()),
                need: p,
            });
        }
        if col.depth > self.meta.max_depth() {
            return Err(Error::range(
                "column depth",
                col.depth,
                format!("0..={}", self.meta.max_depth()),
            ));
        }
        self.check_column(col, channel)?;
        plane.fill(0.0);
        self.accumulate(col, channel, 1.0, plane);
        self.unweight(col.depth, plane);
        for level in (1..=col.depth).rev() {
            self.inverse_step(level, plane, 1, work, RowMode::Dense)?;
        }
        if let Some(e) = &self.empty_rows {
            e.zero(plane);
        }
        match plane
            .iter()
            .find(|v| v.is_nan() || v.abs() > Self::MAX_DECODED)
        {
            Some(v) => Err(Error::range(
                "decoded column value",
                format!("{v:.3e} (depth {}, channel {channel})", col.depth),
                format!("at most {:.3e} = 2^112 in magnitude: files of matrices within the codec's range stay below 2^100", Self::MAX_DECODED),
            )),
            None => Ok(()),
        }
    }
}
