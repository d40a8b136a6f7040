//! `ltm import`, `ltm compress`, `ltm inspect`, `ltm export`.

use crate::common::{claim_files, progress, Ctx};
use anyhow::{bail, Context, Result};
use clap::Args;
use ltm_codec::compress::{
    compress, CodeOptions, CompressOptions, Target, TransposeOptions, DEFAULT_MAX_ERROR,
};
use ltm_codec::compress::{Entropy, Mode, Quantizer};
use ltm_codec::container::LtmFile;
use ltm_codec::default_mem_budget;
use ltm_codec::npy::{export_npy, import_npy};
use ltm_codec::wavelet::row_level;
use ltm_codec::{compress_pca, Filter, PcaOptions, Progress, RawStore, Stage};
use serde::Serialize;
use std::path::PathBuf;

/// Arguments of `ltm import`.
#[derive(Args)]
pub struct ImportArgs {
    /// NumPy matrix: float32 or float64, C order, shape (P, M) or (P, M, C),
    /// with P = width·height pixels (row-major) and M = 6·n² cubemap texels
    /// in the column order of docs/FORMAT.md.
    pub npy: PathBuf,
    /// Image width in pixels.
    #[arg(long)]
    pub width: u32,
    /// Image height in pixels.
    #[arg(long)]
    pub height: u32,
    /// Output raw store.
    #[arg(short, long)]
    pub output: PathBuf,
}

pub fn import(a: ImportArgs, _ctx: &Ctx) -> Result<()> {
    let _claim = claim_files(&[("input", &a.npy)], &[("-o", &a.output)])?;
    let bar = progress::bar(0, "import", progress::Unit::BLOCKS);
    let dims = import_npy(
        &a.npy,
        a.width,
        a.height,
        &a.output,
        Progress::new(&|s| {
            bar.set_length(s.total);
            bar.set_position(s.done);
        }),
    )
    .with_context(|| format!("importing {}", a.npy.display()))?;
    bar.finish_and_clear();
    eprintln!(
        "wrote {}: {}x{} pixels, n = {} ({} lights), {} channel(s)",
        a.output.display(),
        dims.width(),
        dims.height(),
        dims.face_res(),
        dims.lights(),
        dims.channels
    );
    Ok(())
}

/// Arguments of `ltm compress`.
#[derive(Args)]
pub struct CompressArgs {
    /// Raw transport store (from `ltm bake` or `ltm import`).
    pub raw: PathBuf,
    /// Output .ltm file (written atomically).
    #[arg(short, long)]
    pub output: PathBuf,
    /// 2d: rows only (Ng et al. 2003); 4d: every column image to full depth;
    /// adaptive: each column to the depth that codes it best; pca: mean row
    /// plus the top K eigen-transports and K coefficients per pixel
    /// (Eigentransport), K from --rank or the smallest meeting --max-error.
    #[arg(long, default_value = "adaptive")]
    pub mode: Mode,
    /// pca: store exactly K eigen-transports (1..=min(pixels, lights·channels)).
    #[arg(long, value_name = "K", conflicts_with_all = ["max_error", "keep"])]
    pub rank: Option<usize>,
    /// pca: the largest rank --max-error may choose (the fit's sketch size).
    /// Without it the fit starts at rank 256 (or the matrix's full rank
    /// min(pixels, lights·channels) when smaller) and is redone at twice the
    /// rank, up to the full rank, while no rank meets --max-error (as --bits
    /// is raised); given, it is a hard limit.
    #[arg(long, value_name = "K")]
    pub max_rank: Option<usize>,
    /// Row filter over each cube face: haar, d4, d6 or d8.
    #[arg(long, default_value = "haar")]
    pub row_filter: Filter,
    /// Column image filter: legall53, cdf97, haar, d4, d6 or d8.
    #[arg(long, default_value = "legall53")]
    pub col_filter: Filter,
    /// Quantization bits per coefficient (2..=16): the levels of each
    /// band's largest value [default: 16 with the uniform quantizer, whose
    /// steps do not depend on them; 10 with `peak` (pca: 12), raised by 2 at
    /// a time (up to 16) while a --max-error target is missed].
    #[arg(long, value_parser = clap::value_parser!(u32).range(2..=16))]
    pub bits: Option<u32>,
    /// How a --max-error run quantizes the kept coefficients: `uniform`
    /// (one step for the whole matrix, tied to the threshold, values
    /// rounded: the smallest files) or `peak` (each band's step from its
    /// largest value and --bits, dithered: what ltm wrote before; 1.2–2.0×
    /// larger files at the same error, but 1–2.6× fewer nonzeros, so a
    /// smaller relighter arena and a faster whole-file decode). Either
    /// decodes with the same reader. A --keep run quantizes with `peak`.
    #[arg(long, default_value = "uniform")]
    pub quantizer: Quantizer,
    /// Keep the N largest coefficients of each column (the paper's N-term
    /// rule).
    #[arg(long, value_name = "N", conflicts_with = "max_error")]
    pub keep: Option<usize>,
    /// The old name of --keep, refused with a message: `ltm relight --terms`
    /// counts wavelet lights per frame, not coefficients per column.
    #[arg(
        long = "terms",
        hide = true,
        value_name = "N",
        num_args = 0..=1,
        default_missing_value = "",
        value_parser = renamed_terms
    )]
    pub old_terms: Option<usize>,
    /// Target relative L2 error of the whole decoded matrix [default: 0.01].
    #[arg(long)]
    pub max_error: Option<f64>,
    /// Target relative L2 error of the near-field rows (a store baked with
    /// a `[light_plane]`, for `ltm relight --area-light`): their Haar
    /// coefficients rounded to one step, the largest that meets it, and
    /// those that round to 0 dropped. 0 stores them losslessly
    /// [default: --max-error's target; 0 with --keep].
    #[arg(long, value_name = "E")]
    pub near_error: Option<f64>,
    /// Memory for the transpose: a size as for --max-memory, e.g. 512M or
    /// 1.5G [default: a quarter of RAM, at most 8G].
    #[arg(long, value_name = "SIZE", value_parser = crate::common::size::size)]
    pub mem_budget: Option<u64>,
    /// Dither seed.
    #[arg(long, default_value_t = 0x6c74_6d00)]
    pub seed: u64,
    /// Column payloads: `range` (context-modelled range coding, column
    /// encodings 5 and 6, the latter starting from priors measured on the
    /// file's own columns: the smallest files) or `zstd` (about 1.5× larger files
    /// whose columns decode about 3× faster; what format versions 1 and 2
    /// wrote). The relighter decodes a column when a frame first needs it,
    /// so either opens without decoding. Wavelet modes only [default: range].
    #[arg(long)]
    pub entropy: Option<Entropy>,
    /// Sharded compression, stage 1: analyze this shard's columns (with the
    /// coding options given here) into the analysis part -o (JSON); then
    /// `ltm plan`. See `ltm plan --help`.
    #[arg(long, conflicts_with = "plan")]
    pub analyze: bool,
    /// Sharded compression, stage 3: code this shard's columns with the
    /// plan of `ltm plan` into the coded part -o; the coding options come
    /// from the plan. See `ltm plan --help`.
    #[arg(
        long,
        value_name = "PLAN",
        conflicts_with_all = ["mode", "rank", "max_rank", "col_filter", "row_filter", "bits", "quantizer", "keep", "max_error", "seed", "entropy", "near_error"]
    )]
    pub plan: Option<PathBuf>,
    /// With --analyze or --plan: shard I (0-based) of N contiguous column
    /// ranges; `auto` or `auto/N` takes them from a Slurm job array
    /// (SLURM_ARRAY_TASK_ID) or a Kubernetes Indexed Job
    /// (JOB_COMPLETION_INDEX, with N from `auto/N` or LTM_SHARD_COUNT)
    /// [default: 0/1].
    #[arg(long, value_name = "I/N|auto")]
    pub shard: Option<String>,
}

/// Refuses `ltm compress --terms`, renamed to `--keep`.
fn renamed_terms(_: &str) -> std::result::Result<usize, String> {
    Err(
        "`ltm compress --terms` is now `--keep N` (coefficients kept per column); \
         `--terms` is `ltm relight`'s count of wavelet lights per frame"
            .into(),
    )
}

/// The coding options of `ltm compress`'s arguments (wavelet modes).
pub fn code_options(a: &CompressArgs) -> CodeOptions {
    let target = match (a.keep, a.max_error) {
        (Some(n), _) => Target::Keep(n),
        (None, Some(e)) => Target::MaxError(e),
        (None, None) => Target::MaxError(DEFAULT_MAX_ERROR),
    };
    CodeOptions {
        mode: a.mode,
        col_filter: a.col_filter,
        quantizer: a.quantizer,
        bits: a.bits.unwrap_or(a.quantizer.default_bits()),
        raise_bits: a.bits.is_none(),
        target,
        seed: a.seed,
        entropy: a.entropy.unwrap_or_default(),
        near_error: a.near_error,
        ..Default::default()
    }
}

pub fn compress_cmd(a: CompressArgs, ctx: &Ctx) -> Result<()> {
    if a.analyze || a.plan.is_some() {
        if a.near_error.is_some() {
            bail!("--near-error applies to a one-machine `ltm compress`: sharded compression refuses stores with near-field rows");
        }
        if a.mode == Mode::Pca || a.rank.is_some() || a.max_rank.is_some() {
            bail!("sharded compression (--analyze, --plan) codes the wavelet modes 2d, 4d and adaptive, not pca");
        }
        return crate::shard_cmds::compress_shard(&a, ctx);
    }
    if a.shard.is_some() {
        bail!("--shard needs --analyze (stage 1) or --plan PLAN (stage 3) of a sharded compression; see `ltm plan --help`");
    }
    let _claim = claim_files(&[("input", &a.raw)], &[("-o", &a.output)])?;
    let raw = RawStore::open_with_limits(&a.raw, ctx.limits())
        .with_context(|| format!("opening {}", a.raw.display()))?;
    if a.mode == Mode::Pca {
        if a.near_error.is_some() {
            bail!("--near-error applies to the wavelet modes (2d, 4d, adaptive), whose files hold near-field rows; pca files do not");
        }
        return compress_pca_cmd(&a, &raw);
    }
    if a.rank.is_some() {
        bail!(
            "--rank applies to --mode pca only (this is --mode {})",
            a.mode.name()
        );
    }
    let mem_budget = a.mem_budget.unwrap_or_else(default_mem_budget);
    let opts = CompressOptions {
        transpose: TransposeOptions {
            row_filter: a.row_filter,
            mem_budget,
            temp_dir: None,
        },
        code: code_options(&a),
    };
    let dims = raw.dims();
    let bar = progress::bar(0, "transpose", progress::Unit::of(Stage::Rows, dims));
    let start = std::time::Instant::now();
    let stats = compress(
        &raw,
        &a.output,
        &opts,
        Progress::new(&|s| progress::show(&bar, s, dims)),
    )
    .with_context(|| format!("compressing {}", a.raw.display()))?;
    bar.finish_and_clear();
    let secs = start.elapsed().as_secs_f64();
    // The ratio is the matrix's: near-field rows are stored beside it.
    let matrix_bytes = stats
        .file_bytes
        .saturating_sub(stats.near_field_bytes)
        .max(1);
    eprintln!(
        "wrote {}: {} bytes ({}{:.1}x smaller than {} raw), {} bits, {} nonzeros, relative L2 error {:.5}, {} coding pass{}, {:.1} s ({:.1} MB/s of raw matrix){}",
        a.output.display(),
        stats.file_bytes,
        if stats.near_field_bytes > 0 { "the matrix " } else { "" },
        stats.raw_bytes as f64 / matrix_bytes as f64,
        stats.raw_bytes,
        stats.bits,
        stats.nonzeros,
        stats.achieved_error,
        stats.codings,
        if stats.codings == 1 { "" } else { "es" },
        secs,
        stats.raw_bytes as f64 / 1e6 / secs,
        if stats.out_of_core { ", out of core" } else { "" }
    );
    if let Some(q) = stats.near_field.filter(|_| stats.near_field_bytes > 0) {
        let how = if q.step > 0.0 {
            format!(
                "{} of {} Haar coefficients kept at one step of {:.3e}, relative L2 error {:.5} (--near-error)",
                q.kept, q.before, q.step, q.error
            )
        } else {
            format!("{} Haar coefficients, stored losslessly", q.before)
        };
        eprintln!(
            "of which {} bytes are the near-field rows (the scene's [light_plane]): {how}",
            stats.near_field_bytes
        );
    }
    if stats.codings > 1 {
        if let Target::MaxError(e) = opts.code.target {
            eprintln!(
                "(a coding pass quantizes and entropy-codes every column at one threshold; the first missed the window [{:.5}, {e}] around the target, so the columns were coded again at a threshold calibrated from its error; see docs/GLOSSARY.md)",
                ltm_codec::compress::TARGET_LOW * e
            );
        }
    }
    if opts.code.raise_bits && stats.bits > opts.code.bits {
        eprintln!(
            "coded at {} bits: {} miss the target (too coarse a quantization)",
            stats.bits,
            (opts.code.bits..stats.bits)
                .step_by(2)
                .map(|b| b.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    if !stats.target_met {
        if stats.bits < 16 {
            eprintln!("warning: the target error was not reached: {} bits quantize too coarsely for it; try more --bits", stats.bits);
        } else {
            eprintln!("warning: the target error was not reached: it is below the quantization floor of 16 bits");
        }
    }
    Ok(())
}

/// `ltm compress --mode pca`.
fn compress_pca_cmd(a: &CompressArgs, raw: &RawStore) -> Result<()> {
    if a.keep.is_some() {
        bail!("--keep counts wavelet coefficients per column; --mode pca takes --rank K or --max-error E");
    }
    if a.entropy.is_some() {
        bail!("--entropy chooses how wavelet columns are stored; --mode pca stores its basis and coefficients with zstd");
    }
    let mem_budget = a.mem_budget.unwrap_or_else(default_mem_budget);
    let opts = PcaOptions {
        rank: a.rank,
        max_error: a.max_error.unwrap_or(DEFAULT_MAX_ERROR),
        max_rank: a.max_rank.unwrap_or_else(|| {
            let d = raw.dims();
            ltm_codec::compress::DEFAULT_MAX_RANK.min(d.pixels().min(d.row_len()))
        }),
        raise_rank: a.max_rank.is_none(),
        bits: a.bits.unwrap_or(ltm_codec::compress::DEFAULT_PCA_BITS),
        raise_bits: a.bits.is_none(),
        seed: a.seed,
        mem_budget,
        ..PcaOptions::default()
    };
    let dims = raw.dims();
    let bar = progress::bar(0, "pca fit", progress::Unit::of(Stage::Fit, dims));
    let start = std::time::Instant::now();
    let stats = compress_pca(
        raw,
        &a.output,
        &opts,
        Progress::new(&|s| progress::show(&bar, s, dims)),
    )
    .with_context(|| format!("compressing {}", a.raw.display()))?;
    bar.finish_and_clear();
    let secs = start.elapsed().as_secs_f64();
    eprintln!(
        "wrote {}: {} bytes ({:.1}x smaller than {} raw), pca rank {}, {} bits, relative L2 error {:.5} (rank alone {:.5}), {:.1} s",
        a.output.display(),
        stats.file_bytes,
        stats.raw_bytes as f64 / stats.file_bytes as f64,
        stats.raw_bytes,
        stats.rank,
        stats.bits,
        stats.achieved_error,
        stats.predicted_error,
        secs
    );
    if !stats.target_met {
        eprintln!("warning: the target error was not reached at rank {} and {} bits; raise --max-rank or --bits", stats.rank, stats.bits);
    }
    Ok(())
}

/// Arguments of `ltm inspect`.
#[derive(Args)]
pub struct InspectArgs {
    /// An .ltm file.
    pub file: PathBuf,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

/// What `ltm inspect` reports.
#[derive(Serialize)]
pub struct Inspection {
    /// Rows are the texels of a texture atlas (else an image's pixels).
    pub texture: bool,
    pub width: u32,
    pub height: u32,
    pub face_res: u32,
    pub channels: u32,
    pub mode: String,
    pub row_filter: String,
    pub col_filter: String,
    pub bits: u32,
    pub file_bytes: u64,
    pub raw_bytes: u64,
    pub compression_ratio: f64,
    pub bits_per_element: f64,
    pub nonzeros: u64,
    pub target_error: f32,
    pub terms: u32,
    pub achieved_error: f32,
    pub has_albedo: bool,
    /// Columns per transform depth (index = depth).
    pub depth_histogram: Vec<u64>,
    /// Columns per column encoding, by the encoding's number and name
    /// (`"5 compact"`, `"6 primed"`: docs/FORMAT.md).
    pub columns_by_encoding: std::collections::BTreeMap<String, u64>,
    /// Average column depth per row-wavelet level (index = level, 0 = scaling
    /// functions): the paper's Fig. 8.
    pub average_depth_by_row_level: Vec<f64>,
    /// pca files: the eigen-transports stored (0 otherwise).
    pub pca_rank: usize,
    /// Rows with a surface point in the file's surface data (chunk SURF;
    /// `None` without it). pca files need it for point lights.
    pub surface_rows: Option<usize>,
    /// Near-field rows (chunk NEAR, a scene's `[light_plane]`): the face's
    /// order and side and the coefficients stored (`None` without).
    pub near_field: Option<NearFieldInfo>,
}

/// What `ltm inspect` reports of a file's near-field rows.
#[derive(Serialize)]
pub struct NearFieldInfo {
    pub order: u32,
    pub side: f64,
    pub origin: [f64; 3],
    pub x_axis: [f64; 3],
    pub y_axis: [f64; 3],
    pub nonzeros: usize,
}

pub fn inspect(file: &LtmFile) -> Inspection {
    let meta = file.meta();
    let dims = meta.dims;
    let n = dims.face_res() as usize;
    let mut hist = vec![0u64; meta.max_depth() as usize + 1];
    let levels = row_level(n, n * n - 1) as usize + 1;
    let mut by_level = vec![(0.0f64, 0u64); levels];
    let mut nnz = 0;
    let mut encodings = std::collections::BTreeMap::new();
    for (j, c) in file.columns().iter().enumerate() {
        hist[c.depth as usize] += 1;
        let e = format!("{} {}", c.encoding as u8, c.encoding.name());
        *encodings.entry(e).or_insert(0) += 1;
        let l = &mut by_level[row_level(n, j) as usize];
        l.0 += c.depth as f64;
        l.1 += 1;
        nnz += c.nnz as u64;
    }
    let raw_bytes = dims.raw_bytes();
    let elements = raw_bytes / 4;
    Inspection {
        texture: dims.rows.is_texture(),
        width: dims.width(),
        height: dims.height(),
        face_res: dims.face_res(),
        channels: dims.channels,
        mode: meta.mode.name().into(),
        row_filter: meta.row_filter.name().into(),
        col_filter: meta.col_filter.name().into(),
        bits: meta.bits,
        file_bytes: file.file_bytes(),
        raw_bytes,
        compression_ratio: raw_bytes as f64 / file.file_bytes() as f64,
        bits_per_element: file.file_bytes() as f64 * 8.0 / elements as f64,
        nonzeros: match file.pca() {
            Some(m) => (m.rank() * (dims.pixels() + dims.row_len())) as u64,
            None => nnz,
        },
        target_error: meta.target_error,
        terms: meta.terms,
        achieved_error: meta.achieved_error,
        has_albedo: file.albedo().is_some(),
        depth_histogram: hist,
        columns_by_encoding: encodings,
        average_depth_by_row_level: by_level
            .iter()
            .map(|(s, c)| if *c > 0 { s / *c as f64 } else { 0.0 })
            .collect(),
        pca_rank: file.pca().map_or(0, |m| m.rank()),
        surface_rows: file.surface().map(|s| s.valid_count()),
        near_field: file.near_field().map(|r| {
            let b = r.basis();
            NearFieldInfo {
                order: b.order,
                side: b.side,
                origin: b.origin,
                x_axis: b.x_axis,
                y_axis: b.y_axis,
                nonzeros: r.nonzeros(),
            }
        }),
    }
}

pub fn inspect_cmd(a: InspectArgs, ctx: &Ctx) -> Result<()> {
    let file = LtmFile::open_with_limits(&a.file, ctx.limits())
        .with_context(|| format!("opening {}", a.file.display()))?;
    let i = inspect(&file);
    if a.json {
        println!("{}", serde_json::to_string_pretty(&i)?);
        return Ok(());
    }
    println!("{}", a.file.display());
    let (rows, unit) = match i.texture {
        true => ("texture", "texels"),
        false => ("image", "pixels"),
    };
    println!(
        "  {rows:<14} {} x {} {unit}, {} channel(s){}",
        i.width,
        i.height,
        i.channels,
        if i.has_albedo { " + albedo" } else { "" }
    );
    println!(
        "  lighting       6 x {} x {} cubemap ({} lights)",
        i.face_res,
        i.face_res,
        6 * i.face_res * i.face_res
    );
    if i.pca_rank > 0 {
        println!(
            "  mode           pca, rank {} (mean row + {} eigen-transports, {} coefficients per {}), {} bits",
            i.pca_rank,
            i.pca_rank,
            i.pca_rank,
            unit.trim_end_matches('s'),
            i.bits
        );
    } else {
        println!(
            "  mode           {} (rows {}, columns {}), {} bits",
            i.mode, i.row_filter, i.col_filter, i.bits
        );
    }
    println!(
        "  size           {} bytes, raw {} bytes, ratio {:.1}x, {:.3} bits/element",
        i.file_bytes, i.raw_bytes, i.compression_ratio, i.bits_per_element
    );
    println!("  nonzeros       {}", i.nonzeros);
    if let Some(n) = &i.near_field {
        println!(
            "  near field     {0} x {0} face of side {1} on the plane at {2:?} (x {3:?}, y {4:?}), {5} coefficients (relight --area-light works)",
            n.order, n.side, n.origin, n.x_axis, n.y_axis, n.nonzeros
        );
    }
    match (i.surface_rows, i.pca_rank > 0) {
        (Some(v), true) => {
            println!("  surface data   {v} rows with a surface point (relight --point works)")
        }
        (Some(v), false) => println!("  surface data   {v} rows with a surface point"),
        (None, true) => println!("  surface data   none (relight --point needs it)"),
        (None, false) => {}
    }
    if i.pca_rank > 0 {
        if i.target_error > 0.0 {
            println!("  target error   {}", i.target_error);
        } else {
            println!("  target         rank {}", i.pca_rank);
        }
    } else if i.terms > 0 {
        println!("  target         {} coefficients kept per column", i.terms);
    } else {
        println!("  target error   {}", i.target_error);
    }
    println!(
        "  measured error {:.6} (relative L2 of the decoded matrix)",
        i.achieved_error
    );
    if i.pca_rank > 0 {
        return Ok(());
    }
    println!(
        "  columns by depth {:?} (columns whose image is transformed to column-wavelet depth 0, 1, ...; 2d keeps every column at 0)",
        i.depth_histogram
    );
    let by_encoding: Vec<String> = i
        .columns_by_encoding
        .iter()
        .map(|(e, n)| format!("{e} {n}"))
        .collect();
    println!(
        "  columns by encoding {} (docs/FORMAT.md; 6 primed: coded from the file's priors)",
        by_encoding.join(", ")
    );
    let avg: Vec<String> = i
        .average_depth_by_row_level
        .iter()
        .map(|d| format!("{d:.2}"))
        .collect();
    println!("  average depth by row-wavelet level [{}]", avg.join(", "));
    Ok(())
}

/// Arguments of `ltm export`.
#[derive(Args)]
pub struct ExportArgs {
    /// An .ltm file.
    pub file: PathBuf,
    /// Output .npy: float32, shape (P, M) or (P, M, C), pixel lighting basis.
    #[arg(short, long)]
    pub output: PathBuf,
}

pub fn export(a: ExportArgs, ctx: &Ctx) -> Result<()> {
    let _claim = claim_files(&[("input", &a.file)], &[("-o", &a.output)])?;
    let file = LtmFile::open_with_limits(&a.file, ctx.limits())
        .with_context(|| format!("opening {}", a.file.display()))?;
    let dims = file.meta().dims;
    let npy_bytes = dims.raw_bytes().saturating_add(256);
    ltm_codec::output::check_space(&a.output, npy_bytes)?;
    export_npy(&file, &a.output, ctx.limits())
        .with_context(|| format!("exporting to {}", a.output.display()))?;
    eprintln!("wrote {}", a.output.display());
    Ok(())
}
