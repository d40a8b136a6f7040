//! `ltm demo`: the whole product on the embedded default scene and the
//! environment maps in assets/: bake (cached), compress adaptively and in 2d
//! at the same file size, relight under every map, and write images and a
//! summary with sizes, errors against the exact `T·L` and frame rates.

use crate::common::{
    assets_dir, bake_cached, claim_folder, env_maps, load_maps, progress, write_atomic, Ctx,
    Exposure,
};
use anyhow::{Context, Result};
use clap::Args;
use ltm_bake::{Overrides, SceneDesc};
use ltm_codec::compress::{compress, CodeOptions, CompressStats, Mode, Target};
use ltm_codec::{Dims, Progress, RawStore, Stage};
use ltm_relight::{
    reference, relative_l2, EnvMap, Image, Relight, Relighter, Request, Rotation, Weighting,
};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Arguments of `ltm demo`.
#[derive(Args)]
pub struct DemoArgs {
    /// Output directory (created; the bake is cached there between runs).
    #[arg(short, long, default_value = "ltm-demo")]
    pub output: PathBuf,
    /// The repository's assets directory [default: ./assets, else the one
    /// this binary was built from].
    #[arg(long)]
    pub assets: Option<PathBuf>,
    /// Image size in pixels: N for N×N, or WxH (as `ltm bake --size` and
    /// `ltm render --size`).
    #[arg(long, default_value = "128", value_parser = demo_size)]
    pub size: (u32, u32),
    /// Cubemap face resolution n (6·n² lights).
    #[arg(long, default_value_t = 16)]
    pub face_res: u32,
    /// Target relative L2 error of the adaptive file.
    #[arg(long, default_value_t = 0.01)]
    pub max_error: f64,
    /// Quantization bits.
    #[arg(long, default_value_t = 12)]
    pub bits: u32,
    /// Exposure of the PNGs and the contact sheet: `auto` (per map, the
    /// 99th-percentile luminance of the exact image to 0.8; every image of
    /// a map shares it) or a number of stops EV in -64..=64.
    #[arg(
        long,
        value_name = "auto|EV",
        default_value = "auto",
        allow_hyphen_values = true
    )]
    pub exposure: Exposure,
}

/// `--size`: N or WxH, sides 1..=[`ltm_codec::MAX_SIDE`].
fn demo_size(s: &str) -> std::result::Result<(u32, u32), String> {
    crate::common::ranges::image_size(s, ltm_codec::MAX_SIDE)
}

/// Compresses `raw` in 2d mode to about `bytes` bytes (within 3 %) by a
/// secant search on the target error in log-log space.
fn compress_2d_to_size(raw: &RawStore, out: &Path, bits: u32, bytes: u64) -> Result<(u64, f64)> {
    let run = |e: f64| -> Result<(u64, f64)> {
        let opts = CodeOptions {
            mode: Mode::TwoD,
            bits,
            target: Target::MaxError(e),
            ..Default::default()
        };
        let s = compress(raw, out, &opts.into(), ltm_codec::Progress::NONE)?;
        Ok((s.file_bytes, s.achieved_error))
    };
    let (mut e0, mut e1) = (0.05, 0.01);
    let (mut s0, mut s1) = (run(e0)?.0 as f64, run(e1)?.0 as f64);
    let want = (bytes as f64).ln();
    for _ in 0..8 {
        if ((s1.ln() - want).abs()) < 0.03 || (s1 - s0).abs() < 1.0 {
            break;
        }
        let slope = (s1.ln() - s0.ln()) / (e1.ln() - e0.ln());
        let e2 = (e1.ln() + (want - s1.ln()) / slope).exp().clamp(1e-5, 0.9);
        (e0, s0) = (e1, s1);
        e1 = e2;
        s1 = run(e1)?.0 as f64;
    }
    run(e1)
}

/// The numbers of wavelet lights the demo times.
const N_VALUES: [usize; 3] = [50, 200, 1000];
/// The N whose images are written and put on the contact sheet.
const SHEET_N: usize = 200;

pub fn run(a: DemoArgs, ctx: &Ctx) -> Result<()> {
    let assets = assets_dir(a.assets.clone())?;
    // Everything that can fail is checked before the bake.
    let opts = CodeOptions {
        bits: a.bits,
        target: Target::MaxError(a.max_error),
        ..Default::default()
    };
    opts.validate()?;
    let maps = load_maps(&env_maps(&assets)?)?;
    let _claim = claim_folder(&[], "-o", &a.output)?;
    std::fs::create_dir_all(&a.output)
        .with_context(|| format!("creating {}", a.output.display()))?;
    let start = Instant::now();

    // 1. Bake (cached: a complete raw store of the same settings is reused).
    let mut desc = SceneDesc::default_scene(&assets)?;
    desc.apply(&Overrides {
        width: Some(a.size.0),
        height: Some(a.size.1),
        face_res: Some(a.face_res),
        ..Default::default()
    })?;
    let raw_path = bake_cached(
        &desc,
        &a.output,
        &match a.size {
            (w, h) if w == h => format!("scene-{w}px-n{}", a.face_res),
            (w, h) => format!("scene-{w}x{h}px-n{}", a.face_res),
        },
    )?;
    let raw = RawStore::open_with_limits(&raw_path, ctx.limits())?;

    // 2. Compress: adaptive at the target error, 2d at the same size.
    let files = compress_pair(&raw, &a, opts)?;

    // 3. Relight under every map.
    let open = |name: &str| Relighter::open_with_limits(&a.output.join(name), ctx.limits());
    let relighters = [
        ("adaptive", open("scene-adaptive.ltm")?),
        ("2d", open("scene-2d.ltm")?),
    ];
    // The timed frames below are of frames alone, with every column decoded.
    for (_, r) in &relighters {
        r.decode_all()?;
    }
    let table = relight_maps(&raw, &maps, &relighters, &a.output, a.exposure)?;

    // 4. Summary.
    let md = summary(&a, raw.dims(), &files, &table, start)?;
    write_atomic(&a.output.join("summary.md"), md.as_bytes())?;
    println!("{md}");
    eprintln!("wrote {}", a.output.display());
    Ok(())
}

/// The two files the demo compares.
struct Files {
    adaptive: CompressStats,
    twod_bytes: u64,
    twod_error: f64,
}

/// Compresses the adaptive file at the target error and the 2d file at
/// the same size.
fn compress_pair(raw: &RawStore, a: &DemoArgs, opts: CodeOptions) -> Result<Files> {
    let bar = progress::bar(0, "compress", progress::Unit::of(Stage::Rows, raw.dims()));
    let t = Instant::now();
    let adaptive_path = a.output.join("scene-adaptive.ltm");
    let adaptive = compress(
        raw,
        &adaptive_path,
        &opts.into(),
        Progress::new(&|s| progress::show(&bar, s, raw.dims())),
    )?;
    bar.finish_and_clear();
    let compress_s = t.elapsed().as_secs_f64();
    eprintln!(
        "adaptive: {} bytes, error {:.4}, {compress_s:.1} s",
        adaptive.file_bytes, adaptive.achieved_error
    );
    let twod_path = a.output.join("scene-2d.ltm");
    let (twod_bytes, twod_error) =
        compress_2d_to_size(raw, &twod_path, a.bits, adaptive.file_bytes)?;
    eprintln!("2d at the same size: {twod_bytes} bytes, error {twod_error:.4}");
    Ok(Files {
        adaptive,
        twod_bytes,
        twod_error,
    })
}

/// Relights both files under every map at every N, writes the images and
/// the contact sheet, and returns the table rows.
fn relight_maps(
    raw: &RawStore,
    maps: &[(String, EnvMap)],
    relighters: &[(&str, Relighter)],
    dir: &Path,
    exposure: Exposure,
) -> Result<String> {
    let out = |name: &str| dir.join(name);
    let dims = raw.dims();
    let mut table = String::new();
    let (w, h) = (dims.width() as usize, dims.height() as usize);
    let mut sheet = Image::new(3 * w, maps.len() * h);
    for (row, (name, map)) in maps.iter().enumerate() {
        let light = map.to_cubemap(dims.face_res() as usize, &Rotation::IDENTITY);
        let exact = reference(raw, &light)?;
        let ev = exposure.resolve(&exact);
        exact.write_exr(&out(&format!("{name}-reference.exr")))?;
        exact.write_png(&out(&format!("{name}-reference.png")), ev)?;
        let mut tiles = vec![exact];
        for (mode, relighter) in relighters {
            let mut bufs = relighter.frame()?;
            for &n in &N_VALUES {
                let (ms, stats) = time_frame(relighter, &light, n, &mut bufs)?;
                let err = relative_l2(&bufs.image, &tiles[0])?;
                writeln!(
                    table,
                    "| {name} | {mode} | {n} | {} | {:.3} | {:.0} | {:.2} % |",
                    stats.nonzeros,
                    ms,
                    1e3 / ms,
                    100.0 * err
                )?;
                if n == SHEET_N {
                    bufs.image
                        .write_png(&out(&format!("{name}-{mode}-N{n}.png")), ev)?;
                    bufs.image
                        .write_exr(&out(&format!("{name}-{mode}-N{n}.exr")))?;
                    tiles.push(bufs.image.clone());
                }
            }
        }
        for (col, tile) in tiles.iter().enumerate() {
            let scale = 2f32.powf(ev);
            for y in 0..h {
                for x in 0..w {
                    sheet.data[(row * h + y) * 3 * w + col * w + x] =
                        tile.data[y * w + x].map(|v| v * scale);
                }
            }
        }
        eprintln!("relit under {name}: PNGs at {}", exposure.describe(ev));
    }
    sheet.write_png(&out("contact-sheet.png"), 0.0)?;
    Ok(table)
}

/// Relights 15 frames with `n` transport-weighted wavelet lights: the
/// median frame time in ms and the last frame's statistics.
fn time_frame(
    relighter: &Relighter,
    light: &[[f32; 3]],
    n: usize,
    bufs: &mut ltm_relight::Frame,
) -> Result<(f64, ltm_relight::FrameStats)> {
    let mut times = Vec::new();
    let mut stats = Default::default();
    for _ in 0..15 {
        let request = Request {
            terms: n,
            weighting: Weighting::Transport,
        };
        stats = relighter.relight(light, &request, bufs)?;
        times.push(stats.total().as_secs_f64());
    }
    times.sort_by(f64::total_cmp);
    Ok((times[times.len() / 2] * 1e3, stats))
}

/// The demo's summary.md.
fn summary(a: &DemoArgs, dims: Dims, files: &Files, table: &str, start: Instant) -> Result<String> {
    let adaptive = &files.adaptive;
    let mut md = String::new();
    writeln!(md, "# ltm demo\n")?;
    writeln!(md, "Default scene (bunny and glossy teapot), {}×{} pixels, 6·{}² lights, {} channel(s); {} raw bytes.", dims.width(), dims.height(), dims.face_res(), dims.channels, dims.raw_bytes())?;
    writeln!(
        md,
        "Machine: {} CPU threads. Total demo time {:.0} s.\n",
        rayon::current_num_threads(),
        start.elapsed().as_secs_f64()
    )?;
    writeln!(
        md,
        "| file | bytes | ratio | matrix error |\n|---|---|---|---|"
    )?;
    writeln!(
        md,
        "| adaptive (`--bits {} --max-error {}`) | {} | {:.1}× | {:.3} % |",
        a.bits,
        a.max_error,
        adaptive.file_bytes,
        dims.raw_bytes() as f64 / adaptive.file_bytes as f64,
        100.0 * adaptive.achieved_error
    )?;
    writeln!(
        md,
        "| 2d at the same size | {} | {:.1}× | {:.3} % |\n",
        files.twod_bytes,
        dims.raw_bytes() as f64 / files.twod_bytes as f64,
        100.0 * files.twod_error
    )?;
    writeln!(md, "Relighting (transport-weighted wavelet lights, median of 15 frames); error is the relative L2 error against the exact `T·L`:\n")?;
    writeln!(md, "| map | file | N | nonzeros | frame ms | frames/s | relit error |\n|---|---|---|---|---|---|---|")?;
    md.push_str(table);
    writeln!(md, "\n`contact-sheet.png`: one row per map; columns: exact `T·L`, adaptive N = 200, 2d (same file size) N = 200.")?;
    Ok(md)
}
