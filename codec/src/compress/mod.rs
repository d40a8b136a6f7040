//! The compression pipeline (Cheslack-Postava et al. 2007 §4.2–4.4), in
//! stages that each have their own type, so that they can run apart (per
//! setting, per batch of columns or per shard):
//!
//! 1. **Rows** and 2. **Transpose** ([`Transposed::new`], `transpose.rs`):
//!    each row's `6·n²` values (per channel) get a full-depth 2D wavelet
//!    transform over each cube face (the row filter, orthonormal, so errors
//!    in this basis equal errors in the pixel-lighting basis; Ng et al. 2003),
//!    and blocks of transformed rows are scattered into columns, in memory
//!    when the matrix fits `mem_budget`, else through a temporary file.
//! 3. **Analysis** ([`Coder::analyze`] → [`Analysis`], `analysis.rs`; target
//!    error only): for every column and candidate depth, a histogram of
//!    weighted squared coefficients around a first threshold guess.
//!    Analyses of adjacent column ranges merge.
//! 4. **Plan** ([`Plan::new`], `plan.rs`): one global threshold τ and each
//!    column's two best depths, minimising `nonzeros + error/τ²` (the
//!    Lagrangian of size under a total error budget) so that the whole
//!    decoded matrix meets the target by estimate.
//! 5. **Coding** ([`Coder::code_columns`], `code.rs`): each column is
//!    transformed to its depth, thresholded, weighted, dither-quantized and
//!    stored sparse (zstd). In adaptive mode the two best depths by estimate,
//!    depth 0 and the full depth are each coded and decoded with
//!    [`ColumnDecoder`](crate::ColumnDecoder) — the relighter's code — and
//!    the one with the lowest measured cost (zstd-coded bytes plus
//!    error/τ²) is kept; the measured errors give the file's error.
//!
//! [`Transposed::code`] drives stages 3–5: when the measured error lands
//! outside `[0.97·E, E]`, the columns are planned and coded again at the
//! threshold the measured error calls for (at most 8 codings);
//! when the bits are too few for the
//! target and [`CodeOptions::raise_bits`] is set, it codes again with 2 more
//! bits. [`compress`] runs the whole pipeline.

mod analysis;
mod code;
mod feedback;
mod options;
mod pca;
mod plan;
pub mod shard;
mod transpose;

pub use analysis::{Analysis, AnalysisSettings};
pub use code::{CodedColumns, Coder};
pub use feedback::{budget_for, Coding, Feedback, Next, Step};
pub use options::{Entropy, Mode, Quantizer, UNIFORM_STEP_PER_THRESHOLD};
pub use pca::{compress_pca, PcaOptions, PcaStats, DEFAULT_MAX_RANK, DEFAULT_PCA_BITS};
pub use plan::{Calibration, ErrorCurve, Plan, QuantSpec};
pub use transpose::{Transposed, MAX_NORM, MIN_NONZERO_RMS};

use crate::container::{LtmWriter, OptionalChunks};
use crate::error::{Error, Result};
use crate::nearfield::{NearQuantization, PlaneRows};
use crate::progress::{Progress, Stage};
use crate::raw::RawStore;
use crate::wavelet::Filter;
use std::path::{Path, PathBuf};

/// What the coder aims for.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[non_exhaustive]
pub enum Target {
    /// Relative L2 (Frobenius) error of the whole decoded matrix.
    MaxError(f64),
    /// Coefficients kept per column (the paper's N-term rule; `ltm compress
    /// --keep`).
    Keep(usize),
}

/// The default target: 1 % relative L2 error of the decoded matrix.
pub const DEFAULT_MAX_ERROR: f64 = 0.01;

/// The default quantization bits: the smallest files at 1–10 % target error
/// in the reports (docs/results); lower targets need 12–14 bits, which
/// [`CodeOptions::raise_bits`] finds.
pub const DEFAULT_BITS: u32 = 10;

/// Most codings of one file at one bit count: the first, the calibrated
/// one, then re-codings with a smaller budget while the measured error
/// still misses the target.
const MAX_CODINGS: u32 = 8;

/// A file asked for the relative error E lands in `[TARGET_LOW·E, E]`
/// (measured), unless the bits' quantization floor or the matrix itself
/// keeps the error below it.
pub const TARGET_LOW: f64 = 0.97;

/// The relative error a coding aims at, as a fraction of the target: the
/// middle of `[TARGET_LOW, 1]`.
pub const TARGET_AIM: f64 = 0.985;

/// Settings of the row transform and transpose ([`Transposed::new`]).
#[derive(Clone, Debug)]
pub struct TransposeOptions {
    /// Row filter over cube faces (orthonormal: haar, d4, d6, d8). Every
    /// file coded from the matrix records it.
    pub row_filter: Filter,
    /// Memory for the transpose and the batches of columns of the coding
    /// stages, in bytes (at least 1 MiB).
    pub mem_budget: u64,
    /// Directory of the temporary file used when the matrix does not fit
    /// `mem_budget`. `None`: beside the output file in [`compress`],
    /// [`std::env::temp_dir`] in [`Transposed::new`].
    pub temp_dir: Option<PathBuf>,
}

impl Default for TransposeOptions {
    fn default() -> Self {
        TransposeOptions {
            row_filter: Filter::Haar,
            mem_budget: 1 << 30,
            temp_dir: None,
        }
    }
}

/// The transpose's memory when the caller names none (`ltm compress`,
/// `ltm report`, Python's `ltm.compress`): a quarter of RAM as
/// `/proc/meminfo` gives it, at most 8 GiB; 1 GiB where RAM cannot be read.
pub fn default_mem_budget() -> u64 {
    let total = std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|m| {
            m.lines()
                .find(|l| l.starts_with("MemTotal:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse::<u64>().ok())
        })
        .map_or(4 << 30, |kb| kb.saturating_mul(1024));
    (total / 4).clamp(1 << 20, 8 << 30)
}

impl TransposeOptions {
    /// Checks every field against its valid range.
    pub fn validate(&self) -> Result<()> {
        if !self.row_filter.is_orthonormal() {
            return Err(Error::range(
                "row filter",
                self.row_filter,
                "haar, d4, d6 or d8 (orthonormal)",
            ));
        }
        if self.mem_budget < 1 << 20 {
            return Err(Error::range(
                "memory budget",
                self.mem_budget,
                "at least 1 MiB",
            ));
        }
        Ok(())
    }
}

/// Settings of the coding stages (analysis, plan, coding:
/// [`Transposed::code`]).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CodeOptions {
    /// How columns are transformed: rows only, full depth or adaptive.
    pub mode: Mode,
    /// Column image filter.
    pub col_filter: Filter,
    /// How kept values are quantized (target-error runs; a term count
    /// quantizes with [`Quantizer::Peak`]).
    #[serde(default = "Quantizer::before_uniform")]
    pub quantizer: Quantizer,
    /// Quantization bits, 2..=16: the levels `Q = 2^(bits−1) − 1` of a
    /// scale group's largest value (with [`Quantizer::Uniform`], the
    /// largest number of steps a value may take before its group's step
    /// grows).
    pub bits: u32,
    /// When a target error is missed because `bits` quantize too coarsely,
    /// code again with 2 more bits (up to 16) until it is met. The file
    /// records the bits it was coded with; [`CompressStats::bits`] reports
    /// them.
    pub raise_bits: bool,
    /// What the coder aims for.
    pub target: Target,
    /// Dither seed.
    pub seed: u64,
    /// How column payloads are stored: range-coded (smallest) or zstd
    /// (faster to open).
    pub entropy: Entropy,
    /// zstd level of column payloads.
    pub zstd_level: i32,
    /// Relative L2 error of the near-field rows (chunk NEAR) after
    /// [`PlaneRows::quantize`]: `Some(0.0)` keeps them losslessly; `None`
    /// takes the matrix's target error (lossless for a term count).
    #[serde(default)]
    pub near_error: Option<f64>,
}

impl Default for CodeOptions {
    fn default() -> Self {
        CodeOptions {
            mode: Mode::Adaptive,
            col_filter: Filter::LeGall53,
            quantizer: Quantizer::Uniform,
            bits: Quantizer::Uniform.default_bits(),
            raise_bits: false,
            target: Target::MaxError(DEFAULT_MAX_ERROR),
            seed: 0x6c74_6d00,
            entropy: Entropy::Range,
            zstd_level: 9,
            near_error: None,
        }
    }
}

impl CodeOptions {
    /// The near-field rows' target error: [`CodeOptions::near_error`], or
    /// the matrix's.
    pub fn near_target(&self) -> f64 {
        self.near_error.unwrap_or(match self.target {
            Target::MaxError(e) => e,
            Target::Keep(_) => 0.0,
        })
    }

    /// These options at `bits` quantization bits.
    pub fn with_bits(&self, bits: u32) -> CodeOptions {
        CodeOptions {
            bits,
            ..self.clone()
        }
    }

    /// Checks every field against its valid range.
    pub fn validate(&self) -> Result<()> {
        if !(2..=16).contains(&self.bits) {
            return Err(Error::range("bits", self.bits, "2..=16"));
        }
        if !self.mode.is_wavelet() {
            return Err(Error::range(
                "wavelet coding mode",
                self.mode.name(),
                "2d, 4d or adaptive (pca files come from ltm_codec::compress_pca)",
            ));
        }
        match self.target {
            Target::MaxError(e) if !(e > 0.0 && e < 1.0) => {
                return Err(Error::range("max error", e, "0 < E < 1"))
            }
            Target::Keep(n) if n == 0 || n > u32::MAX as usize => {
                return Err(Error::range("keep", n, format!("1..={}", u32::MAX)))
            }
            _ => {}
        }
        if let Some(e) = self.near_error.filter(|e| !(0.0..1.0).contains(e)) {
            return Err(Error::range("near-field error", e, "0 <= E < 1"));
        }
        let levels = zstd::compression_level_range();
        if !levels.contains(&self.zstd_level) {
            return Err(Error::range(
                "zstd level",
                self.zstd_level,
                format!("{}..={}", levels.start(), levels.end()),
            ));
        }
        Ok(())
    }
}

/// Settings of [`compress`]: both stages'.
#[derive(Clone, Debug, Default)]
pub struct CompressOptions {
    /// Row transform and transpose.
    pub transpose: TransposeOptions,
    /// Analysis, plan and coding.
    pub code: CodeOptions,
}

impl From<CodeOptions> for CompressOptions {
    /// The coding options `code` with the default transpose options.
    fn from(code: CodeOptions) -> Self {
        CompressOptions {
            transpose: TransposeOptions::default(),
            code,
        }
    }
}

/// What `compress` measured.
#[derive(Clone, Debug, Default)]
pub struct CompressStats {
    /// Size of the written file.
    pub file_bytes: u64,
    /// Of which the near-field rows (chunk NEAR; 0 without a light
    /// plane).
    pub near_field_bytes: u64,
    /// How the near-field rows were quantized (`None` without a light
    /// plane; a step of 0 when they are stored losslessly).
    pub near_field: Option<NearQuantization>,
    /// Size of the dense f32 matrix.
    pub raw_bytes: u64,
    /// Coefficients stored (positions, over all columns).
    pub nonzeros: u64,
    /// Measured relative L2 error of the decoded matrix.
    pub achieved_error: f64,
    /// Channels stored (3 → 1 when the matrix is monochrome).
    pub channels: u32,
    /// Columns per depth.
    pub depth_histogram: Vec<u64>,
    /// Quantization bits of the file (more than asked when
    /// [`CodeOptions::raise_bits`] raised them).
    pub bits: u32,
    /// Used a temporary file for the transpose.
    pub out_of_core: bool,
    /// Codings at the file's bits (1, or 2 when the first missed
    /// `[TARGET_LOW·E, E]`; more only when the calibrated one missed too).
    pub codings: u32,
    /// The measured error meets the target (always true for a term count).
    /// A miss means the quantization error of `bits` alone is near the
    /// target: more bits are needed.
    pub target_met: bool,
}

/// Compresses a raw store into `out` (written atomically). `progress` gets
/// a [`Step`](crate::Step) per batch of rows or columns.
///
/// The same as [`Transposed::new`] followed by [`Transposed::code`], with
/// the temporary file beside `out` unless `opts.transpose.temp_dir` says
/// otherwise; a sweep over coding settings builds the [`Transposed`] matrix
/// once instead.
pub fn compress(
    raw: &RawStore,
    out: &Path,
    opts: &CompressOptions,
    progress: Progress<'_>,
) -> Result<CompressStats> {
    opts.code.validate()?;
    let mut transpose = opts.transpose.clone();
    if transpose.temp_dir.is_none() {
        let dir = out.parent().filter(|d| !d.as_os_str().is_empty());
        transpose.temp_dir = Some(dir.unwrap_or(Path::new(".")).to_path_buf());
    }
    Transposed::new(raw, &transpose, progress)?.code(out, &opts.code, progress)
}

impl Transposed<'_> {
    /// Codes the matrix with `opts` into `out` (written atomically): the
    /// analysis (once, for a target error), then the codings of the
    /// error-feedback loop ([`Feedback`]: plan and coding at `opts.bits`,
    /// again while the measured error misses `[TARGET_LOW·E, E]`, and at 2
    /// more bits while the target is missed and `opts.raise_bits` is set).
    /// The file records [`Transposed::row_filter`].
    pub fn code(
        &self,
        out: &Path,
        opts: &CodeOptions,
        progress: Progress<'_>,
    ) -> Result<CompressStats> {
        let mut coder = Coder::new(self, opts)?;
        let m = self.dims().lights();
        let analysis = match opts.target {
            Target::MaxError(_) => Some(coder.analyze(0..m, progress)?),
            Target::Keep(_) => None,
        };
        let feedback = Feedback::new(opts, coder.budget(), analysis.as_ref())?;
        let channels = self.dims().channels as usize;
        let mut near = crate::nearfield::plane_rows_of(self.raw(), channels, self.raw().limits())?;
        let near_q = match near.as_mut() {
            Some(rows) => Some(rows.quantize(opts.near_target())?),
            None => None,
        };
        let mut step = feedback.first()?;
        if coder.options().bits != step.bits {
            coder = Coder::new(self, &opts.with_bits(step.bits))?;
        }
        // The side chunks are packed once (the NEAR chunk can take
        // seconds); a pass that is not kept starts the file again.
        let mut writer = new_writer(&coder, out, near.as_ref())?;
        loop {
            let (mut stats, coded) = write_columns(&coder, &mut writer, &step.plan, progress)?;
            match feedback.next(&step, &coded)? {
                Next::Code(next) => {
                    step = next;
                    if coder.options().bits != step.bits {
                        coder = Coder::new(self, &opts.with_bits(step.bits))?;
                    }
                    writer = writer.restart(out, coder.meta().clone())?;
                }
                Next::Keep { target_met } => {
                    stats.target_met = target_met;
                    stats.near_field = near_q;
                    stats.codings = step.coding;
                    if let Err(e) = self.raw().check_unchanged() {
                        writer.abandon();
                        return Err(e);
                    }
                    stats.file_bytes = writer.finish(stats.achieved_error as f32)?;
                    return Ok(stats);
                }
            }
        }
    }
}

/// The file `coder` writes to `out`, with the matrix's side chunks.
fn new_writer(coder: &Coder, out: &Path, near_field: Option<&PlaneRows>) -> Result<LtmWriter> {
    let t = coder.transposed();
    LtmWriter::create_with(
        out,
        coder.meta().clone(),
        t.raw().albedo(),
        OptionalChunks {
            surface: t.raw().surface(),
            mesh: t.raw().mesh(),
            empty_rows: Some(t.empty_rows()),
            near_field,
            column_norms: false,
            // Encoding-5 columns coded again from the file's priors.
            priors: true,
        },
    )
}

/// Codes every column with `plan` in batches, written as they come to the
/// unfinished file `writer`: its statistics and what the coding measured.
fn write_columns(
    coder: &Coder,
    writer: &mut LtmWriter,
    plan: &Plan,
    progress: Progress<'_>,
) -> Result<(CompressStats, Coding)> {
    let t = coder.transposed();
    let m = t.dims().lights();
    let mut stats = CompressStats {
        raw_bytes: t.raw().dims().raw_bytes(),
        channels: t.dims().channels,
        depth_histogram: vec![0; coder.meta().max_depth() as usize + 1],
        bits: coder.options().bits,
        out_of_core: t.out_of_core(),
        near_field_bytes: writer.near_field_bytes(),
        ..Default::default()
    };
    let mut coding = Coding::default();
    for batch in t.batches(0..m) {
        let coded = coder.code_columns(batch.clone(), plan)?;
        coded.measure_into(&mut coding);
        for col in &coded.columns {
            stats.nonzeros += col.entry.nnz as u64;
            stats.depth_histogram[col.entry.depth as usize] += 1;
        }
        writer.push_columns(coded.first, coded.columns)?;
        progress.report(Stage::Coding, batch.end as u64, m as u64);
    }
    stats.achieved_error = relative_error(coding.err, t.norm());
    Ok((stats, coding))
}

/// The relative error of a squared error `err` in a matrix of norm `norm`
/// (0 for a zero matrix).
pub(crate) fn relative_error(err: f64, norm: f64) -> f64 {
    if norm > 0.0 {
        err.sqrt() / norm
    } else {
        0.0
    }
}
