//! `ltm report`: sweeps of codec settings on one matrix, each measured
//! against the exact product `T·L`, written as `index.md`, `results.json`
//! and SVG plots. The sections follow Cheslack-Postava et al. 2007
//! (Figs. 7, 8, 9) and the error graphs of Ng et al. 2003.
//!
//! The matrix is row-transformed and transposed once
//! ([`ltm_codec::Transposed`]); every setting is coded from it.

pub mod baselines;
mod page;
pub mod peers;
pub mod plot;
pub mod texture;

use crate::common::{assets_dir, bake_cached, claim_folder, env_maps, load_maps, progress, Ctx};
use anyhow::{bail, Context, Result};
use clap::Args;
use ltm_bake::{Overrides, SceneDesc};
use ltm_codec::default_mem_budget;
use ltm_codec::wavelet::row_level;
use ltm_codec::{
    compress_pca, CodeOptions, Mode, PcaOptions, Progress, RawStore, Target, TransposeOptions,
    Transposed,
};
use ltm_relight::{
    reference, relative_l2, BasisRelighter, EnvMap, Frame, Image, PcaRelighter, Relight, Relighter,
    Request, Rotation, Weighting,
};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Arguments of `ltm report`.
#[derive(Args)]
#[command(
    long_about = "Measure size, speed and error over a sweep of settings on one matrix.

The matrix (a baked scene or --raw) is row-transformed and transposed once; every wavelet mode (2d, 4d, adaptive) × --bits × --errors is coded from it, relit under every --env at every --terms N, and compared with the exact product T·L. The pca mode (Eigentransport) is coded at every --errors target and relit with the first N of its components for N in --pca-ranks. Baselines on the same matrix: lossless zstd of the raw matrix and spherical harmonics (order L).

Writes OUTPUT/index.md (machine, date, settings, headline table and five sections: size against matrix error, relit error against N for the three light weightings and SH, frame time and dynamic compression against N, average column depth by row level, speed against error with Pareto fronts; for a texture-space matrix a sixth, geometry relighting: the relit texture and the mesh from two sides, OUTPUT/texture.png and OUTPUT/view-{front,back}.png, with relight and relight-plus-view times), the SVG plots, and OUTPUT/results.json with every measured point. OUTPUT/files/ keeps the 2d and adaptive files compared at equal quality.

A full run on the default 128² scene takes about a minute on 2 cores; --quick takes seconds."
)]
pub struct ReportArgs {
    /// Scene to bake (cached in the output directory under a name that
    /// covers the scene description and sizes; delete it to bake again)
    /// [default: the default scene in assets/].
    #[arg(long, conflicts_with = "raw")]
    pub scene: Option<PathBuf>,
    /// An existing raw store to report on instead of baking a scene.
    #[arg(long)]
    pub raw: Option<PathBuf>,
    /// Environment map (.exr, .hdr); repeat for several
    /// [default: every map in assets/envmaps].
    #[arg(long = "env")]
    pub envs: Vec<PathBuf>,
    /// Output directory.
    #[arg(short, long, default_value = "ltm-report")]
    pub output: PathBuf,
    /// A small, fast run (32² pixels, n = 8, few settings) that checks the
    /// whole report end to end; its timings mean little.
    #[arg(long)]
    pub quick: bool,
    /// The repository's assets directory [default: ./assets].
    #[arg(long)]
    pub assets: Option<PathBuf>,
    /// Image side when baking a scene [default: 128; quick: 32].
    #[arg(long, conflicts_with = "raw")]
    pub size: Option<u32>,
    /// Cubemap face resolution when baking a scene [default: 16; quick: 8].
    #[arg(long, conflicts_with = "raw")]
    pub face_res: Option<u32>,
    /// Quantization bits swept, comma-separated [default: 10,12,14; quick: 12].
    #[arg(long, value_delimiter = ',')]
    pub bits: Vec<u32>,
    /// Target matrix errors swept [default: 0.003,0.01,0.03,0.1; quick: 0.01,0.05].
    #[arg(long, value_delimiter = ',')]
    pub errors: Vec<f64>,
    /// Numbers of wavelet lights N relit with every setting
    /// [default: 10,20,50,100,200,500,1000,2000,5000; quick: 10,50,200].
    /// Values above the number of lights are clamped.
    #[arg(long, value_delimiter = ',')]
    pub terms: Vec<usize>,
    /// Matrix error of the 2d and adaptive pair compared at equal quality.
    #[arg(long, default_value_t = 0.01)]
    pub quality: f64,
    /// Bits of that pair.
    #[arg(long, default_value_t = 12)]
    pub quality_bits: u32,
    /// Frames timed per (setting, N, map); the median is reported
    /// [default: 11; quick: 3].
    #[arg(long)]
    pub frames: Option<usize>,
    /// pca files: numbers of eigen-transports N relit (at most the rank
    /// each file stores, which is also relit); the largest is the largest
    /// rank a target may choose [default: 1,2,4,…,512; quick: 1,4,16,64,256].
    #[arg(long, value_delimiter = ',')]
    pub pca_ranks: Vec<usize>,
    /// Spherical-harmonics orders L (L² coefficients)
    /// [default: 2..=20; quick: 2,4,8].
    #[arg(long, value_delimiter = ',')]
    pub sh_orders: Vec<usize>,
    /// Memory for the transpose: a size as for --max-memory, e.g. 512M or
    /// 1.5G [default: a quarter of RAM, at most 8 GiB].
    #[arg(long, value_name = "SIZE", value_parser = crate::common::size::size)]
    pub mem_budget: Option<u64>,
    /// Keep every coded .ltm file (by default only the equal-quality pair).
    #[arg(long)]
    pub keep_files: bool,
    /// Measure nothing: rewrite index.md and the plots of the output
    /// directory from its results.json.
    #[arg(long)]
    pub replot: bool,
    /// SZ3, ZFP and SPERR measured on the same raw store, as written by
    /// `python3 tools/validate/peers.py RAW -o FILE` (pip: pysz, zfpy,
    /// numcodecs-wasm-sperr):
    /// shown in the headline, the tables and the size/error plot. With
    /// --replot, replaces the peers of results.json.
    #[arg(long)]
    pub peers: Option<PathBuf>,
}

/// The settings a run used, after defaults.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Settings {
    pub quick: bool,
    pub bits: Vec<u32>,
    pub errors: Vec<f64>,
    pub terms: Vec<usize>,
    pub quality: f64,
    pub quality_bits: u32,
    pub frames: usize,
    pub pca_ranks: Vec<usize>,
    pub sh_orders: Vec<usize>,
    pub row_filter: String,
    pub col_filter: String,
    pub zstd_raw_level: i32,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Machine {
    pub cpu: String,
    pub threads: usize,
    pub memory_gib: f64,
    pub os: String,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SceneInfo {
    /// The scene file or raw store reported on.
    pub source: String,
    pub width: u32,
    pub height: u32,
    pub face_res: u32,
    pub lights: usize,
    /// Channels of the raw store.
    pub channels: u32,
    pub raw_bytes: u64,
    pub has_albedo: bool,
}

/// One relit frame setting, measured.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct RelightPoint {
    pub env: String,
    /// The rule that chose the lights (serialized by its name).
    #[serde(with = "weighting_name")]
    pub weighting: Weighting,
    /// Requested wavelet lights.
    pub n: usize,
    /// Lights used (≤ n).
    pub lights: usize,
    /// Median frame time.
    pub frame_ms: f64,
    /// Stored coefficients multiply-added.
    pub nonzeros: u64,
    /// Dense entries of the used columns (lights × pixels × stored channels)
    /// over `nonzeros`: the dynamic compression rate of Fig. 9a.
    pub dynamic_compression: f64,
    /// Relative L2 error against the exact `T·L`.
    pub relit_error: f64,
}

/// One coded setting.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Coding {
    /// Serialized by its name (`2d`, `4d`, `adaptive`, `pca`).
    pub mode: Mode,
    pub bits: u32,
    pub target_error: f64,
    pub file_bytes: u64,
    pub matrix_error: f64,
    pub target_met: bool,
    pub nonzeros: u64,
    pub code_s: f64,
    /// Columns per column-transform depth.
    pub depth_histogram: Vec<u64>,
    /// Average column depth per row-wavelet level (0 = the faces' scaling
    /// functions), Fig. 8.
    pub depth_by_row_level: Vec<f64>,
    /// The equal-quality pair member (also relit with every weighting).
    pub quality_pair: bool,
    pub relight: Vec<RelightPoint>,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ShRelightPoint {
    pub env: String,
    pub order: usize,
    pub coefficients: usize,
    pub relit_error: f64,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Timings {
    pub bake_or_open_s: f64,
    pub references_s: f64,
    pub transpose_s: f64,
    pub baselines_s: f64,
    pub total_s: f64,
}

/// Everything a report measured: `results.json`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Results {
    pub date: String,
    pub command: String,
    pub machine: Machine,
    pub scene: SceneInfo,
    pub envs: Vec<String>,
    pub settings: Settings,
    pub out_of_core: bool,
    pub matrix_norm: f64,
    pub codings: Vec<Coding>,
    pub baselines: Vec<baselines::BaselinePoint>,
    /// SZ3 and ZFP (`--peers`), empty without.
    #[serde(default)]
    pub peers: Vec<peers::PeerPoint>,
    pub sh_relight: Vec<ShRelightPoint>,
    /// Texture-space matrices: the relit texture and two views.
    #[serde(default)]
    pub texture: Option<texture::TexturePoint>,
    pub timings: Timings,
}

/// [`Weighting`] in `results.json`: its name.
mod weighting_name {
    use ltm_relight::Weighting;
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(w: &Weighting, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(w.name())
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Weighting, D::Error> {
        let name = String::deserialize(d)?;
        name.parse().map_err(serde::de::Error::custom)
    }
}

fn or_default<T: Clone>(given: &[T], full: &[T], quick: &[T], is_quick: bool) -> Vec<T> {
    if !given.is_empty() {
        given.to_vec()
    } else if is_quick {
        quick.to_vec()
    } else {
        full.to_vec()
    }
}

fn settings(a: &ReportArgs) -> Result<Settings> {
    let q = a.quick;
    let s = Settings {
        quick: q,
        bits: or_default(&a.bits, &[10, 12, 14], &[12], q),
        errors: or_default(&a.errors, &[0.003, 0.01, 0.03, 0.1], &[0.01, 0.05], q),
        terms: or_default(
            &a.terms,
            &[10, 20, 50, 100, 200, 500, 1000, 2000, 5000],
            &[10, 50, 200],
            q,
        ),
        quality: a.quality,
        quality_bits: a.quality_bits,
        frames: a.frames.unwrap_or(if q { 3 } else { 11 }),
        pca_ranks: or_default(
            &a.pca_ranks,
            &[1, 2, 4, 8, 16, 32, 64, 128, 256, 512],
            &[1, 4, 16, 64, 256],
            q,
        ),
        sh_orders: or_default(&a.sh_orders, &(2..=20).collect::<Vec<_>>(), &[2, 4, 8], q),
        row_filter: TransposeOptions::default().row_filter.to_string(),
        col_filter: CodeOptions::default().col_filter.to_string(),
        zstd_raw_level: 3,
    };
    if let Some(b) = s
        .bits
        .iter()
        .chain([&s.quality_bits])
        .find(|b| !(2..=16).contains(*b))
    {
        bail!("--bits {b} is out of range: 2..=16");
    }
    if let Some(e) = s
        .errors
        .iter()
        .chain([&s.quality])
        .find(|e| !(**e > 0.0 && **e < 1.0))
    {
        bail!("target error {e} is out of range: 0 < E < 1");
    }
    if s.terms.contains(&0) {
        bail!("--terms values must be at least 1");
    }
    if s.frames == 0 {
        bail!("--frames must be at least 1");
    }
    if s.pca_ranks.contains(&0) || s.sh_orders.contains(&0) {
        bail!("PCA ranks and SH orders must be at least 1");
    }
    if let Some(o) = s.sh_orders.iter().find(|&&o| o > ltm_codec::MAX_SH_ORDER) {
        bail!(
            "--sh-orders {o} is out of range (valid: 1..={})",
            ltm_codec::MAX_SH_ORDER
        );
    }
    Ok(s)
}

/// A map's name and its cubemap lighting and exact image.
struct Env {
    name: String,
    light: Vec<[f32; 3]>,
    exact: Image,
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Relights `frames` times; the median time, the last frame's statistics
/// and its error.
fn measure(
    relighter: &dyn Relight,
    channels: u32,
    bufs: &mut Frame,
    env: &Env,
    n: usize,
    weighting: Weighting,
    frames: usize,
) -> Result<RelightPoint> {
    let mut times = Vec::with_capacity(frames);
    let mut stats = Default::default();
    let request = Request {
        terms: n,
        weighting,
    };
    for _ in 0..frames {
        stats = relighter.relight(&env.light, &request, bufs)?;
        times.push(stats.total().as_secs_f64());
    }
    let stats: ltm_relight::FrameStats = stats;
    let (w, h) = relighter.size();
    let dense = stats.lights as f64 * (w * h) as f64 * channels as f64;
    Ok(RelightPoint {
        env: env.name.clone(),
        weighting,
        n,
        lights: stats.lights,
        frame_ms: median(times) * 1e3,
        nonzeros: stats.nonzeros,
        dynamic_compression: if stats.nonzeros > 0 {
            dense / stats.nonzeros as f64
        } else {
            0.0
        },
        relit_error: relative_l2(&bufs.image, &env.exact)?,
    })
}

fn depth_by_row_level(relighter: &Relighter) -> Vec<f64> {
    let n = relighter.meta().dims.face_res() as usize;
    let levels = row_level(n, n * n - 1) as usize + 1;
    let mut sum = vec![(0.0, 0usize); levels];
    for (j, c) in relighter.file().columns().iter().enumerate() {
        let s = &mut sum[row_level(n, j) as usize];
        s.0 += c.depth as f64;
        s.1 += 1;
    }
    sum.iter().map(|(d, k)| d / (*k).max(1) as f64).collect()
}

fn machine() -> Machine {
    let cpuinfo = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let cpu = cpuinfo
        .lines()
        .find_map(|l| l.strip_prefix("model name"))
        .and_then(|l| l.split(':').nth(1))
        .map_or_else(
            || std::env::consts::ARCH.to_string(),
            |s| s.trim().to_string(),
        );
    let memory_gib = std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|m| {
            m.lines()
                .find_map(|l| l.strip_prefix("MemTotal:"))
                .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<f64>().ok())
        })
        .map_or(0.0, |kb| kb / (1024.0 * 1024.0));
    Machine {
        cpu,
        threads: rayon::current_num_threads(),
        memory_gib,
        os: std::env::consts::OS.to_string(),
    }
}

/// Today's UTC date and time, `YYYY-MM-DD HH:MM UTC`.
fn utc_now() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let (days, rem) = ((secs / 86_400) as i64, secs % 86_400);
    // Civil date from days since 1970-01-01 (proleptic Gregorian).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!(
        "{y:04}-{m:02}-{d:02} {:02}:{:02} UTC",
        rem / 3600,
        rem % 3600 / 60
    )
}

fn file_name(mode: Mode, bits: u32, err: f64) -> String {
    format!("{}-{bits}b-e{err}.ltm", mode.name())
}

pub fn run(a: ReportArgs, ctx: &Ctx) -> Result<()> {
    if a.replot {
        return replot(&a.output, a.peers.as_deref());
    }
    let start = Instant::now();
    let s = settings(&a)?;
    // The maps are loaded before the bake, so that a bad one fails first.
    let env_paths = if a.envs.is_empty() {
        env_maps(&assets_dir(a.assets.clone())?)?
    } else {
        a.envs.clone()
    };
    let maps = load_maps(&env_paths)?;
    let mut inputs: Vec<(&str, &Path)> = env_paths.iter().map(|p| ("--env", p.as_path())).collect();
    inputs.extend(a.raw.iter().map(|p| ("--raw", p.as_path())));
    inputs.extend(a.scene.iter().map(|p| ("--scene", p.as_path())));
    inputs.extend(a.peers.iter().map(|p| ("--peers", p.as_path())));
    let _claim = claim_folder(&inputs, "-o", &a.output)?;
    let files_dir = a.output.join("files");
    std::fs::create_dir_all(&files_dir)
        .with_context(|| format!("creating {}", files_dir.display()))?;

    // 1. The matrix: a raw store, or a scene baked once into the output.
    let t = Instant::now();
    let (raw_path, source) = matrix_source(&a)?;
    let raw = RawStore::open_with_limits(&raw_path, ctx.limits())?;
    let bake_or_open_s = t.elapsed().as_secs_f64();
    let scene = scene_info(&raw, source);
    let peers = match &a.peers {
        Some(path) => peers::load(path, &scene)?,
        None => Vec::new(),
    };

    // 2. Lighting and the exact images.
    let t = Instant::now();
    let envs = exact_images(&raw, maps)?;
    let references_s = t.elapsed().as_secs_f64();
    eprintln!("{} exact images in {references_s:.1} s", envs.len());

    // 3. and 4. The sweep, coded from one transposed matrix, and pca.
    let sweep = code_sweep(&a, &s, &raw, &envs, ctx)?;

    // Texture-space matrices: the relit texture and two views of the
    // equal-quality adaptive file.
    let texture = match (raw.dims().rows.is_texture(), envs.first()) {
        (true, Some(env)) => {
            let file = files_dir.join(file_name(Mode::Adaptive, s.quality_bits, s.quality));
            let map = (env.name.as_str(), env.light.as_slice());
            Some(texture::measure(&a.output, &file, map, s.frames, ctx)?)
        }
        _ => None,
    };

    // 5. Baselines on the same matrix.
    let t = Instant::now();
    eprintln!("baselines: zstd of the raw matrix, spherical harmonics");
    let (baselines, sh_relight) = measure_baselines(&raw, &s, &envs)?;
    let baselines_s = t.elapsed().as_secs_f64();

    let results = Results {
        date: utc_now(),
        command: std::env::args().collect::<Vec<_>>().join(" "),
        machine: machine(),
        scene,
        envs: envs.iter().map(|e| e.name.clone()).collect(),
        settings: s,
        out_of_core: sweep.out_of_core,
        matrix_norm: sweep.matrix_norm,
        codings: sweep.codings,
        baselines,
        peers,
        sh_relight,
        texture,
        timings: Timings {
            bake_or_open_s,
            references_s,
            transpose_s: sweep.transpose_s,
            baselines_s,
            total_s: start.elapsed().as_secs_f64(),
        },
    };
    page::write(&a.output, &results)?;
    eprintln!(
        "wrote {} in {:.0} s",
        a.output.join("index.md").display(),
        start.elapsed().as_secs_f64()
    );
    Ok(())
}

/// What the report says of the matrix.
fn scene_info(raw: &RawStore, source: String) -> SceneInfo {
    let dims = raw.dims();
    SceneInfo {
        source,
        width: dims.width(),
        height: dims.height(),
        face_res: dims.face_res(),
        lights: dims.lights(),
        channels: dims.channels,
        raw_bytes: dims.raw_bytes(),
        has_albedo: raw.albedo().is_some(),
    }
}

/// Every map's cubemap lighting and exact image `T·L`.
fn exact_images(raw: &RawStore, maps: Vec<(String, EnvMap)>) -> Result<Vec<Env>> {
    let n = raw.dims().face_res() as usize;
    let mut envs = Vec::with_capacity(maps.len());
    for (name, map) in maps {
        let light = map.to_cubemap(n, &Rotation::IDENTITY);
        let exact = reference(raw, &light)?;
        envs.push(Env { name, light, exact });
    }
    Ok(envs)
}

/// Every coded setting of a run, and what the transpose found.
struct Sweep {
    codings: Vec<Coding>,
    out_of_core: bool,
    matrix_norm: f64,
    transpose_s: f64,
}

/// Row-transforms and transposes the matrix once, codes and relights every
/// wavelet setting of the sweep from it, then the pca mode at every target
/// error.
fn code_sweep(
    a: &ReportArgs,
    s: &Settings,
    raw: &RawStore,
    envs: &[Env],
    ctx: &Ctx,
) -> Result<Sweep> {
    let files_dir = a.output.join("files");
    let transpose = TransposeOptions {
        mem_budget: a.mem_budget.unwrap_or_else(default_mem_budget),
        temp_dir: Some(files_dir.clone()),
        ..Default::default()
    };
    let t = Instant::now();
    let unit = progress::Unit::of(ltm_codec::Stage::Rows, raw.dims());
    let bar = progress::bar(0, "transpose", unit);
    let transposed = Transposed::new(
        raw,
        &transpose,
        Progress::new(&|s| progress::show(&bar, s, raw.dims())),
    )?;
    bar.finish_and_clear();
    let transpose_s = t.elapsed().as_secs_f64();
    eprintln!("row transform and transpose in {transpose_s:.1} s");

    // The sweep: every mode × bits × target error, plus the pair.
    let plan = sweep(s);
    let mut codings = Vec::new();
    let files = Files {
        dir: &files_dir,
        keep: a.keep_files,
        ctx,
    };
    for (i, &setting) in plan.iter().enumerate() {
        let label = format!("[{}/{}]", i + 1, plan.len());
        codings.push(code_and_relight(
            &transposed,
            setting,
            &label,
            s,
            envs,
            &files,
        )?);
    }
    let (out_of_core, matrix_norm) = (transposed.out_of_core(), transposed.norm());
    drop(transposed);
    let mut pca_errors = s.errors.clone();
    if !pca_errors.contains(&s.quality) {
        pca_errors.push(s.quality);
    }
    for (i, &err) in pca_errors.iter().enumerate() {
        let label = format!("[pca {}/{}]", i + 1, pca_errors.len());
        codings.extend(code_and_relight_pca(raw, err, &label, s, envs, &files)?);
    }
    Ok(Sweep {
        codings,
        out_of_core,
        matrix_norm,
        transpose_s,
    })
}

/// Where coded files go, whether they are kept, and the run's limits to
/// open them with.
struct Files<'a> {
    dir: &'a Path,
    keep: bool,
    ctx: &'a Ctx,
}

/// `--replot`: redraws the pages from a report's `results.json`.
fn replot(output: &Path, peers: Option<&Path>) -> Result<()> {
    let path = output.join("results.json");
    let text =
        std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    let mut results: Results = serde_json::from_str(&text)
        .with_context(|| format!("{} is not a report's results.json", path.display()))?;
    if let Some(p) = peers {
        results.peers = peers::load(p, &results.scene)?;
    }
    page::write(output, &results)?;
    eprintln!("rewrote {}", output.join("index.md").display());
    Ok(())
}

/// The raw store to measure and how it was made: `--raw`, or the scene
/// (`--scene` or the default) baked once into the output folder.
fn matrix_source(a: &ReportArgs) -> Result<(PathBuf, String)> {
    if let Some(p) = &a.raw {
        return Ok((p.clone(), p.display().to_string()));
    }
    let size = a.size.unwrap_or(if a.quick { 32 } else { 128 });
    let face_res = a.face_res.unwrap_or(if a.quick { 8 } else { 16 });
    let (mut desc, source) = match &a.scene {
        Some(p) => (SceneDesc::load(p)?, p.display().to_string()),
        None => (
            SceneDesc::default_scene(&assets_dir(a.assets.clone())?)?,
            "assets/scenes/default.toml".to_string(),
        ),
    };
    desc.apply(&Overrides {
        width: Some(size),
        height: Some(size),
        face_res: Some(face_res),
        ..Default::default()
    })?;
    let path = bake_cached(&desc, &a.output, &format!("scene-{size}px-n{face_res}"))?;
    Ok((path, format!("{source} at {size}×{size}, n = {face_res}")))
}

/// Every (mode, bits, target error) of the sweep, then the equal-quality
/// pair (2d and adaptive at `--quality`) if the sweep lacks it.
fn sweep(s: &Settings) -> Vec<(Mode, u32, f64)> {
    let mut plan: Vec<(Mode, u32, f64)> = Vec::new();
    for mode in [Mode::TwoD, Mode::FourD, Mode::Adaptive] {
        for &b in &s.bits {
            for &e in &s.errors {
                plan.push((mode, b, e));
            }
        }
    }
    for mode in [Mode::TwoD, Mode::Adaptive] {
        if !plan.contains(&(mode, s.quality_bits, s.quality)) {
            plan.push((mode, s.quality_bits, s.quality));
        }
    }
    plan
}

/// Codes one setting from the transposed matrix, relights the file under
/// every map at every N, and removes it unless it is kept.
fn code_and_relight(
    transposed: &Transposed,
    (mode, bits, err): (Mode, u32, f64),
    counter: &str,
    s: &Settings,
    envs: &[Env],
    files: &Files,
) -> Result<Coding> {
    let opts = CodeOptions {
        mode,
        bits,
        target: Target::MaxError(err),
        ..Default::default()
    };
    let path = files.dir.join(file_name(mode, bits, err));
    let label = format!("{counter} {} {bits} bits {err}", mode.name());
    let unit = progress::Unit::of(ltm_codec::Stage::Coding, transposed.dims());
    let bar = progress::bar(0, &label, unit);
    let t = Instant::now();
    let stats = transposed.code(
        &path,
        &opts,
        Progress::new(&|s| {
            bar.set_length(s.total);
            bar.set_position(s.done);
        }),
    )?;
    bar.finish_and_clear();
    let code_s = t.elapsed().as_secs_f64();
    let quality_pair = bits == s.quality_bits && err == s.quality && mode != Mode::FourD;
    let relighter = Relighter::open_with_limits(&path, files.ctx.limits())?;
    // Frame times below are of frames alone, with every column decoded.
    relighter.decode_all()?;
    let mut terms: Vec<usize> = s.terms.iter().map(|&n| n.min(relighter.lights())).collect();
    terms.sort_unstable();
    terms.dedup();
    let weightings: &[Weighting] = if quality_pair {
        &[Weighting::Transport, Weighting::Unweighted, Weighting::Area]
    } else {
        &[Weighting::Transport]
    };
    let mut bufs = relighter.frame()?;
    let mut relight = Vec::new();
    for env in envs {
        for &weighting in weightings {
            for &n in &terms {
                let c = relighter.meta().dims.channels;
                relight.push(measure(
                    &relighter, c, &mut bufs, env, n, weighting, s.frames,
                )?);
            }
        }
    }
    let coding = Coding {
        mode,
        bits,
        target_error: err,
        // The matrix's bytes: near-field rows (a [light_plane]) are not
        // what the report compares.
        file_bytes: stats.file_bytes - stats.near_field_bytes,
        matrix_error: stats.achieved_error,
        target_met: stats.target_met,
        nonzeros: stats.nonzeros,
        code_s,
        depth_histogram: stats.depth_histogram.clone(),
        depth_by_row_level: depth_by_row_level(&relighter),
        quality_pair,
        relight,
    };
    drop(relighter);
    if !(quality_pair || files.keep) {
        std::fs::remove_file(&path).with_context(|| format!("removing {}", path.display()))?;
    }
    eprintln!(
        "{label}: {:.2} MB, matrix error {:.3} %, {code_s:.1} s",
        coding.file_bytes as f64 / 1e6,
        100.0 * coding.matrix_error
    );
    Ok(coding)
}

/// Codes the pca mode at target error `err` from the raw store, relights
/// the file under every map with the first N components for every N of
/// `--pca-ranks` up to its rank (and the rank), and removes it unless it
/// is the equal-quality one or files are kept.
fn code_and_relight_pca(
    raw: &RawStore,
    err: f64,
    label: &str,
    s: &Settings,
    envs: &[Env],
    files: &Files,
) -> Result<Option<Coding>> {
    if raw.header().plane.is_some() {
        eprintln!("{label} pca {err}: left out: the store has near-field rows (a [light_plane]), which pca files do not hold");
        return Ok(None);
    }
    let dims = raw.dims();
    let full = dims.pixels().min(dims.row_len());
    let max_rank = s.pca_ranks.iter().copied().max().unwrap_or(256).min(full);
    let opts = PcaOptions {
        max_error: err,
        max_rank,
        ..Default::default()
    };
    let path = files.dir.join(format!("pca-e{err}.ltm"));
    let t = Instant::now();
    let stats = match compress_pca(raw, &path, &opts, ltm_codec::Progress::NONE) {
        Ok(stats) => stats,
        // A target no rank up to the largest reaches: left out of the
        // sweep, and said so.
        Err(
            e @ ltm_codec::Error::OutOfRange {
                what: "PCA target error",
                ..
            },
        ) => {
            eprintln!("{label} pca {err}: left out: {e}");
            return Ok(None);
        }
        Err(e) => return Err(e.into()),
    };
    let code_s = t.elapsed().as_secs_f64();
    let relighter = PcaRelighter::open_with_limits(&path, files.ctx.limits())?;
    let mut terms: Vec<usize> = s.pca_ranks.iter().map(|&n| n.min(stats.rank)).collect();
    terms.push(stats.rank);
    terms.sort_unstable();
    terms.dedup();
    let mut bufs = relighter.frame()?;
    let mut relight = Vec::new();
    for env in envs {
        for &n in &terms {
            let w = Weighting::Transport;
            relight.push(measure(
                &relighter,
                dims.channels,
                &mut bufs,
                env,
                n,
                w,
                s.frames,
            )?);
        }
    }
    drop(relighter);
    let quality_pair = err == s.quality;
    if !(quality_pair || files.keep) {
        std::fs::remove_file(&path).with_context(|| format!("removing {}", path.display()))?;
    }
    eprintln!(
        "{label} pca {err}: rank {}, {} bits, {:.2} MB, matrix error {:.3} %, {code_s:.1} s",
        stats.rank,
        stats.bits,
        stats.file_bytes as f64 / 1e6,
        100.0 * stats.achieved_error
    );
    Ok(Some(Coding {
        mode: Mode::Pca,
        bits: stats.bits,
        target_error: err,
        file_bytes: stats.file_bytes,
        matrix_error: stats.achieved_error,
        target_met: stats.target_met,
        nonzeros: (stats.rank * (dims.pixels() + dims.row_len())) as u64,
        code_s,
        depth_histogram: Vec::new(),
        depth_by_row_level: Vec::new(),
        quality_pair,
        relight,
    }))
}

/// The zstd and SH points on the same matrix, and the images relit
/// from the SH projection under every map.
fn measure_baselines(
    raw: &RawStore,
    s: &Settings,
    envs: &[Env],
) -> Result<(Vec<baselines::BaselinePoint>, Vec<ShRelightPoint>)> {
    let mut points = vec![baselines::zstd_raw(raw, s.zstd_raw_level)?];
    let (sh_points, sh) = baselines::sh(raw, &s.sh_orders)?;
    points.extend(sh_points);
    let sh = BasisRelighter::sh(sh, raw)?;
    let mut frame = sh.frame()?;
    let mut sh_relight = Vec::new();
    for env in envs {
        for &order in &s.sh_orders {
            let request = Request {
                terms: order,
                weighting: Weighting::Transport,
            };
            sh.relight(&env.light, &request, &mut frame)?;
            sh_relight.push(ShRelightPoint {
                env: env.name.clone(),
                order,
                coefficients: order * order,
                relit_error: relative_l2(&frame.image, &env.exact)?,
            });
        }
    }
    Ok((points, sh_relight))
}
