//! Step 4, coding (Cheslack-Postava et al. 2007 §4.2–4.3): each column image
//! is transformed to a depth, weighted by its bands' synthesis norms,
//! thresholded by the [`Plan`] and dither-quantized, then stored sparse
//! (zstd). Each candidate depth of a column is coded and decoded with
//! [`ColumnDecoder`] — the relighter's code — and the one with the lowest
//! measured cost is kept: coded bytes (at 2 bytes per coefficient) plus
//! measured error over τ² for a target error; less error (on ties, fewer
//! nonzeros) for a term count. The measured errors add up to the file's
//! error.

use super::analysis::{candidate_depths, AnalysisSettings};
use super::feedback::{budget_for, Coding};
use super::plan::{quantization_error, rounded_grid, rounding_error, ErrorCurve, Plan, Rule};
use super::{CodeOptions, Target, Transposed};
use crate::column::{EncodedColumn, SparseColumn};
use crate::container::Meta;
use crate::decode::ColumnDecoder;
use crate::dims::Dims;
use crate::entropy::ColumnShape;
use crate::error::{Error, Result};
use crate::quant::{
    decode_scale, levels, quantize, scale_groups, BandWeights, Dither, Quantization,
};
use crate::wavelet::{self, max_levels};
use rayon::prelude::*;
use std::ops::Range;

/// Stored bytes of a typical coefficient (about 2.1 with range coding on
/// the default scene at 1 %, 3.3 with zstd before): the exchange rate between a
/// candidate depth's coded size and the analysis's unit (one coefficient).
/// Deeper transforms keep fewer coefficients but larger values, so the
/// depth choice counts coded bytes, not coefficients.
const BYTES_PER_COEFFICIENT: f64 = 2.0;

/// One coding setting applied to a [`Transposed`] matrix: the state the
/// analysis and coding stages share (band weights, scale groups, the
/// decoder, the file's [`Meta`]).
pub struct Coder<'t> {
    transposed: &'t Transposed<'t>,
    opts: CodeOptions,
    dims: Dims,
    depths: Vec<u32>,
    weights: BandWeights,
    /// Scale group of every position, per depth.
    groups: Vec<Vec<u8>>,
    decoder: ColumnDecoder,
    meta: Meta,
}

/// Coded columns `first..first + columns.len()` and their measured squared
/// errors (pixel domain, summed over channels), ready for
/// [`LtmWriter::push_columns`](crate::LtmWriter::push_columns).
pub struct CodedColumns {
    /// The first column's index.
    pub first: usize,
    /// The coded columns, in order.
    pub columns: Vec<EncodedColumn>,
    /// The measured squared error of each column.
    pub errors: Vec<f64>,
    /// How each column's error would change with the threshold (`Some` for
    /// threshold plans with τ > 0 only). Merged in column order, they give
    /// the same sums however the columns were split into ranges.
    pub curves: Vec<Option<ErrorCurve>>,
}

impl CodedColumns {
    /// Adds what the columns measured to `coding`, column by column.
    pub fn measure_into(&self, coding: &mut Coding) {
        for ((col, err), curve) in self.columns.iter().zip(&self.errors).zip(&self.curves) {
            coding.push_column(*err, col.entry.depth as u32, curve.as_ref());
        }
    }
}

/// Buffers of one worker: weighted coefficients, a decoded plane, scratch.
struct Buffers {
    coefs: Vec<f32>,
    /// The weighted coefficients of the best depth so far.
    best: Vec<f32>,
    plane: Vec<f32>,
    work: Vec<f32>,
}

/// A coded candidate depth of a column.
struct Candidate {
    col: SparseColumn,
    /// Encoded when the cost needed its size.
    encoded: Option<EncodedColumn>,
    err: f64,
    cost: f64,
}

impl<'t> Coder<'t> {
    /// Checks `opts` and prepares the coding of `transposed` with them.
    pub fn new(transposed: &'t Transposed<'t>, opts: &CodeOptions) -> Result<Coder<'t>> {
        opts.validate()?;
        let dims = transposed.dims();
        let (w, h) = (dims.width() as usize, dims.height() as usize);
        let max_depth = max_levels(w, h);
        let meta = Meta {
            dims,
            mode: opts.mode,
            row_filter: transposed.row_filter(),
            col_filter: opts.col_filter,
            bits: opts.bits,
            seed: opts.seed,
            target_error: match opts.target {
                Target::MaxError(e) => e as f32,
                Target::Keep(_) => 0.0,
            },
            achieved_error: 0.0,
            terms: match opts.target {
                Target::MaxError(_) => 0,
                Target::Keep(n) => n as u32,
            },
            norm: transposed.norm(),
        };
        // Buffers of the image's size, charged to the store's budget (the
        // matrix itself is far larger and already in memory).
        let limits = transposed.raw().limits();
        Ok(Coder {
            transposed,
            opts: opts.clone(),
            dims,
            depths: candidate_depths(opts.mode, max_depth),
            weights: BandWeights::new(opts.col_filter, w, h, max_depth, limits)?,
            groups: (0..=max_depth).map(|d| scale_groups(w, h, d)).collect(),
            decoder: ColumnDecoder::new(&meta, limits)?
                .with_empty_rows(Some(transposed.empty_rows().clone())),
            meta,
        })
    }

    /// The shape the column coder sees: image size, channels, bits.
    fn shape(&self) -> ColumnShape {
        ColumnShape::of(&self.meta)
    }

    /// The coding options.
    pub fn options(&self) -> &CodeOptions {
        &self.opts
    }

    /// The matrix coded.
    pub fn transposed(&self) -> &'t Transposed<'t> {
        self.transposed
    }

    /// The file's metadata (its achieved error is set when it is finished).
    pub fn meta(&self) -> &Meta {
        &self.meta
    }

    /// The candidate depths of every column.
    pub fn depths(&self) -> &[u32] {
        &self.depths
    }

    /// The squared error budget of the target: `(E·‖T‖)²` for a target
    /// relative error `E`, 0 for a term count.
    pub fn budget(&self) -> f64 {
        budget_for(self.opts.target, self.transposed.norm())
    }

    /// The settings of this coder's analyses (a target error only).
    pub fn analysis_settings(&self) -> Result<AnalysisSettings> {
        if let Target::Keep(_) = self.opts.target {
            return Err(Error::Invalid(
                "the analysis is for a target error; a term count needs none".into(),
            ));
        }
        Ok(AnalysisSettings {
            width: self.dims.width(),
            height: self.dims.height(),
            channels: self.dims.channels,
            lights: self.dims.lights(),
            mode: self.opts.mode,
            col_filter: self.opts.col_filter,
            tau0_sq: self.transposed.first_threshold(self.budget()),
        })
    }

    pub(super) fn channels(&self) -> usize {
        self.dims.channels as usize
    }

    pub(super) fn scale_groups(&self, depth: u32) -> &[u8] {
        &self.groups[depth as usize]
    }

    /// Transforms `planes` (channels × P, pixel domain) into `out` at
    /// `depth`, weighted.
    pub(super) fn weighted(
        &self,
        planes: &[f32],
        depth: u32,
        out: &mut [f32],
        work: &mut [f32],
    ) -> Result<()> {
        let (w, h) = (self.dims.width() as usize, self.dims.height() as usize);
        out.copy_from_slice(planes);
        let map = self.weights.map(depth);
        for plane in out.chunks_mut(w * h) {
            wavelet::forward(self.opts.col_filter, plane, w, h, depth, work)?;
            plane.iter_mut().zip(map).for_each(|(v, m)| *v *= m);
        }
        Ok(())
    }

    /// Squared magnitude of position `i` over channels.
    pub(super) fn energy(&self, coefs: &[f32], i: usize) -> f64 {
        let p = self.dims.pixels();
        (0..self.channels())
            .map(|c| (coefs[c * p + i] as f64).powi(2))
            .sum()
    }

    /// Codes `columns` with `plan` (made for this coder's options: a
    /// threshold plan from an analysis with this coder's settings and bits
    /// that covers `columns`, or [`Plan::keep`] of its term count).
    pub fn code_columns(&self, columns: Range<usize>, plan: &Plan) -> Result<CodedColumns> {
        self.transposed.check_columns(&columns)?;
        self.check_plan(plan, &columns)?;
        let (channels, p) = (self.channels(), self.dims.pixels());
        let mut out = CodedColumns {
            first: columns.start,
            columns: Vec::with_capacity(columns.len()),
            errors: Vec::with_capacity(columns.len()),
            curves: Vec::with_capacity(columns.len()),
        };
        for batch in self.transposed.batches(columns) {
            let data = self.transposed.read_columns(batch.clone())?;
            let coded: Vec<(EncodedColumn, f64, Option<ErrorCurve>)> = data
                .par_chunks(channels * p)
                .enumerate()
                .map_init(
                    || Buffers {
                        coefs: vec![0.0; channels * p],
                        best: vec![0.0; channels * p],
                        plane: vec![0.0; p],
                        work: vec![0.0; p],
                    },
                    |bufs, (l, planes)| self.code_column(batch.start + l, planes, plan, bufs),
                )
                .collect::<Result<_>>()?;
            for (col, err, curve) in coded {
                out.columns.push(col);
                out.errors.push(err);
                out.curves.push(curve);
            }
        }
        Ok(out)
    }

    /// `plan` was made for this coder and covers `columns`.
    fn check_plan(&self, plan: &Plan, columns: &Range<usize>) -> Result<()> {
        let differ = |found: String, expected: String| Error::SettingsDiffer {
            what: "plan",
            field: "target",
            found,
            expected,
        };
        match (plan.rule(), self.opts.target) {
            (Rule::Largest(n), Target::Keep(k)) if n == k => Ok(()),
            (Rule::Above(_), Target::MaxError(_)) => {
                let (settings, spec) = plan
                    .made_for()
                    .ok_or_else(|| differ("none".into(), "an analysis".into()))?;
                self.analysis_settings()?.check_same(settings, "plan")?;
                if spec.bits != self.opts.bits {
                    return Err(Error::SettingsDiffer {
                        what: "plan",
                        field: "bits",
                        found: spec.bits.to_string(),
                        expected: self.opts.bits.to_string(),
                    });
                }
                if spec.quantizer != self.opts.quantizer {
                    return Err(Error::SettingsDiffer {
                        what: "plan",
                        field: "quantizer",
                        found: spec.quantizer.name().into(),
                        expected: self.opts.quantizer.name().into(),
                    });
                }
                let all = plan.columns();
                if columns.start < all.start || columns.end > all.end {
                    return Err(Error::range(
                        "columns",
                        format!("{}..{}", columns.start, columns.end),
                        format!("a range within the plan's {}..{}", all.start, all.end),
                    ));
                }
                Ok(())
            }
            (rule, target) => Err(differ(format!("{rule:?}"), format!("{target:?}"))),
        }
    }

    /// Codes column `j` (`planes`: C × P pixel-domain values) at each depth
    /// the plan tries and keeps the cheapest: its coded bytes and measured
    /// squared error.
    fn code_column(
        &self,
        j: usize,
        planes: &[f32],
        plan: &Plan,
        bufs: &mut Buffers,
    ) -> Result<(EncodedColumn, f64, Option<ErrorCurve>)> {
        let mut best: Option<Candidate> = None;
        for d in self.tries(j, plan) {
            self.weighted(planes, d, &mut bufs.coefs, &mut bufs.work)?;
            let col = self.quantize_column(j, &bufs.coefs, d, plan.rule());
            let err = self.measured_error(&col, planes, &mut bufs.plane, &mut bufs.work)?;
            let candidate = self.candidate(col, err, plan.tau_sq());
            if best
                .as_ref()
                .is_none_or(|b| self.better(&candidate, b, plan.tau_sq()))
            {
                best = Some(candidate);
                std::mem::swap(&mut bufs.coefs, &mut bufs.best);
            }
        }
        let best = best.ok_or_else(|| Error::Invalid(format!("column {j}: no depth to try")))?;
        let curve = match plan.rule() {
            Rule::Above(tau_sq) if tau_sq > 0.0 => {
                Some(self.error_curve(&best.col, &bufs.best, tau_sq))
            }
            _ => None,
        };
        let encoded = best.encoded.unwrap_or_else(|| {
            EncodedColumn::coded(
                &best.col,
                &self.shape(),
                self.opts.entropy,
                self.opts.zstd_level,
            )
        });
        // The norm of the column as the decoder will read it (chunk NORM).
        let norm = self.decoder.weighted_norm(&best.col) as f32;
        Ok((encoded.with_norm(norm), best.err, curve))
    }

    /// The [`ErrorCurve`] of a coded column around `tau_sq`: `coefs` are its
    /// weighted coefficients at its depth, `col` what was stored of them.
    fn error_curve(&self, col: &SparseColumn, coefs: &[f32], tau_sq: f64) -> ErrorCurve {
        let (channels, p) = (self.channels(), self.dims.pixels());
        let groups = &self.groups[col.depth as usize];
        let q = levels(self.opts.bits) as f64;
        let mut curve = ErrorCurve::new(tau_sq);
        let uniform = self.step(Rule::Above(tau_sq));
        let grid = uniform.map(|step| rounded_grid(tau_sq, step));
        let mut u = [0.0f64; 3];
        let mut next = 0;
        for i in 0..p {
            let e = self.energy(coefs, i);
            if e <= 0.0 {
                continue;
            }
            if let Some(grid) = &grid {
                (0..channels).for_each(|c| u[c] = (coefs[c * p + i] as f64).abs());
                curve.add_rounded(e, &u[..channels], grid);
            }
            let stored = col.indices.get(next) == Some(&(i as u32));
            if stored {
                let k = next;
                next += 1;
                let coded: f64 = (0..channels)
                    .map(|c| {
                        let d = self.decoder.dequantize(col, k, c) as f64;
                        (coefs[c * p + i] as f64 - d).powi(2)
                    })
                    .sum();
                curve.add_kept(e, coded);
            } else if e < tau_sq {
                let g = groups[i] as usize;
                let coded: f64 = (0..channels)
                    .map(|c| {
                        let u = (coefs[c * p + i] as f64).abs();
                        let code = col.scale_codes.get(g * channels + c).copied().unwrap_or(0);
                        let step = decode_scale(code) as f64 / q;
                        let kept = match uniform {
                            // A group with nothing kept stored no scale.
                            Some(s) => rounding_error(u, step.max(s)),
                            None if step > 0.0 => quantization_error(u, step),
                            None => None,
                        };
                        kept.unwrap_or(u * u)
                    })
                    .sum();
                curve.add_dropped(e, coded);
            } else {
                curve.add_quantized_away(e);
            }
        }
        curve
    }

    /// The depths column `j` tries: for a threshold plan, the two best by
    /// estimate and both extremes (rows only, full depth), which the
    /// estimate ranks least reliably; every candidate depth for a term count.
    fn tries(&self, j: usize, plan: &Plan) -> Vec<u32> {
        match plan.choice(j) {
            Some(choice) if plan.fixed_depths() => vec![choice[0]],
            Some(choice) => {
                let mut t = choice.to_vec();
                t.extend([self.depths[0], self.depths[self.depths.len() - 1]]);
                t.sort_unstable();
                t.dedup();
                t
            }
            None => self.depths.clone(),
        }
    }

    /// A coded depth and its cost: for a target error (τ² > 0), coded bytes
    /// over [`BYTES_PER_COEFFICIENT`] plus error over τ²; else the error.
    fn candidate(&self, col: SparseColumn, err: f64, tau_sq: f64) -> Candidate {
        if tau_sq > 0.0 {
            let encoded =
                EncodedColumn::coded(&col, &self.shape(), self.opts.entropy, self.opts.zstd_level);
            let cost = encoded.bytes.len() as f64 / BYTES_PER_COEFFICIENT + err / tau_sq;
            Candidate {
                col,
                encoded: Some(encoded),
                err,
                cost,
            }
        } else {
            Candidate {
                col,
                encoded: None,
                err,
                cost: err,
            }
        }
    }

    /// `c` beats `best`: lower cost; without a threshold (the paper's rule),
    /// on equal errors the one with fewer nonzeros.
    fn better(&self, c: &Candidate, best: &Candidate, tau_sq: f64) -> bool {
        let m = self.dims.lights() as f64;
        let tie = (c.err - best.err).abs() <= 1e-12 * (c.err + best.err)
            || (tau_sq == 0.0 && c.err.max(best.err) <= 1e-14 * self.transposed.norm_sq() / m);
        if tau_sq == 0.0 && tie {
            c.col.indices.len() < best.col.indices.len()
        } else {
            c.cost < best.cost
        }
    }

    /// Keeps the positions `rule` keeps of column `j`'s weighted
    /// coefficients at `depth` and quantizes them.
    fn quantize_column(&self, j: usize, coefs: &[f32], depth: u32, rule: Rule) -> SparseColumn {
        let p = self.dims.pixels();
        let mut kept: Vec<u32> = match rule {
            Rule::Above(tau_sq) => (0..p)
                .filter(|&i| self.energy(coefs, i) >= tau_sq && self.energy(coefs, i) > 0.0)
                .map(|i| i as u32)
                .collect(),
            Rule::Largest(n) => {
                let mut order: Vec<(f64, u32)> = (0..p)
                    .map(|i| (self.energy(coefs, i), i as u32))
                    .filter(|e| e.0 > 0.0)
                    .collect();
                if order.len() > n {
                    order.select_nth_unstable_by(n, |a, b| b.0.total_cmp(&a.0));
                    order.truncate(n);
                }
                order.into_iter().map(|e| e.1).collect()
            }
        };
        kept.sort_unstable();
        quantize(
            coefs,
            self.channels(),
            &kept,
            &self.groups[depth as usize],
            depth,
            Quantization {
                bits: self.opts.bits,
                step: self.step(rule).map(|s| s as f32),
                dither: Dither {
                    seed: self.opts.seed,
                    column: j as u32,
                },
            },
        )
    }

    /// The uniform quantizer's step under `rule` (a threshold plan with
    /// τ > 0); `None` quantizes with the peak quantizer.
    fn step(&self, rule: Rule) -> Option<f64> {
        match rule {
            Rule::Above(tau_sq) => self.opts.quantizer.step(tau_sq, self.channels()),
            Rule::Largest(_) => None,
        }
    }

    /// Squared pixel-domain error of `col` against `planes`, decoded with the
    /// relighter's decoder.
    fn measured_error(
        &self,
        col: &SparseColumn,
        planes: &[f32],
        plane: &mut [f32],
        work: &mut [f32],
    ) -> Result<f64> {
        let p = self.dims.pixels();
        let mut err = 0.0;
        for c in 0..self.channels() {
            self.decoder.decode(col, c, plane, work)?;
            err += plane
                .iter()
                .zip(&planes[c * p..(c + 1) * p])
                .map(|(a, b)| ((a - b) as f64).powi(2))
                .sum::<f64>();
        }
        Ok(err)
    }
}
