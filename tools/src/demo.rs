//! `ltm demo`: the whole product on the embedded default scene and the
//! environment maps in assets/: bake (cached), compress adaptively and in 2d
//! at the same file size, relight under every map, and write images and a
//! summary with sizes, errors against the exact `T·L` and frame rates.

use crate::output::write_atomic;
use crate::progress;
use anyhow::{bail, Context, Result};
use clap::Args;
use ltm_bake::{bake, BakeOptions, Overrides, Scene, SceneDesc};
use ltm_codec::compress::{compress, CodeOptions, Target};
use ltm_codec::container::Mode;
use ltm_codec::RawStore;
use ltm_relight::{
    reference, relative_l2, EnvMap, Image, Relight, Relighter, Request, Rotation, Weighting,
};
use std::fmt::Write as _;
use std::hash::{Hash, Hasher};
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
    /// Image side in pixels.
    #[arg(long, default_value_t = 128)]
    pub size: u32,
    /// Cubemap face resolution n (6·n² lights).
    #[arg(long, default_value_t = 16)]
    pub face_res: u32,
    /// Target relative L2 error of the adaptive file.
    #[arg(long, default_value_t = 0.01)]
    pub max_error: f64,
    /// Quantization bits.
    #[arg(long, default_value_t = 12)]
    pub bits: u32,
}

pub(crate) fn assets_dir(given: Option<PathBuf>) -> Result<PathBuf> {
    let candidates = match given {
        Some(p) => vec![p],
        None => vec![
            PathBuf::from("assets"),
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets"),
        ],
    };
    candidates
        .into_iter()
        .find(|p| p.join("meshes").is_dir() && p.join("envmaps").is_dir())
        .context("no assets directory with meshes/ and envmaps/ found: run from the repository root or pass --assets")
}

/// Exposure (EV) that maps the 99th-percentile luminance of `image` to 0.8.
pub(crate) fn auto_exposure(image: &Image) -> f32 {
    let mut lum: Vec<f32> = image
        .data
        .iter()
        .map(|p| 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2])
        .filter(|v| *v > 0.0)
        .collect();
    if lum.is_empty() {
        return 0.0;
    }
    let k = (lum.len() * 99 / 100).min(lum.len() - 1);
    let (_, v, _) = lum.select_nth_unstable_by(k, |a, b| a.total_cmp(b));
    (0.8 / *v).log2().clamp(-30.0, 30.0)
}

/// The environment maps (.exr, .hdr) in `assets/envmaps`, sorted.
pub(crate) fn env_maps(assets: &Path) -> Result<Vec<PathBuf>> {
    let dir = assets.join("envmaps");
    let mut maps: Vec<PathBuf> = std::fs::read_dir(&dir)
        .with_context(|| format!("reading {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "exr" || x == "hdr"))
        .collect();
    maps.sort();
    if maps.is_empty() {
        bail!("no environment maps (.exr, .hdr) in {}", dir.display());
    }
    Ok(maps)
}

/// Loads every map, named by its file stem (names must be distinct: they
/// name the outputs). Run before any long work, so that a bad map fails
/// first.
pub(crate) fn load_maps(paths: &[PathBuf]) -> Result<Vec<(String, EnvMap)>> {
    let mut maps: Vec<(String, EnvMap)> = Vec::with_capacity(paths.len());
    for path in paths {
        let name = path
            .file_stem()
            .map_or("map".into(), |s| s.to_string_lossy().into_owned());
        if maps.iter().any(|(n, _)| *n == name) {
            bail!("two environment maps are named {name}: give maps distinct file names");
        }
        let map = EnvMap::load(path).with_context(|| format!("loading {}", path.display()))?;
        maps.push((name, map));
    }
    Ok(maps)
}

/// Bakes `desc` into `dir/{label}-{key}.raw` unless a complete store is
/// already there, and returns its path. The key hashes the whole description
/// (meshes, materials, camera, sizes), so an edited or different scene is
/// baked anew; delete the file to bake again after editing a mesh file.
pub(crate) fn bake_cached(desc: &SceneDesc, dir: &Path, label: &str) -> Result<PathBuf> {
    let key = {
        let mut h = std::hash::DefaultHasher::new();
        format!("{desc:?}").hash(&mut h);
        h.finish()
    };
    let raw_path = dir.join(format!("{label}-{key:016x}.raw"));
    if raw_path.exists() {
        eprintln!("using the cached bake {}", raw_path.display());
        return Ok(raw_path);
    }
    let scene = Scene::build(desc)?;
    let bar = progress::bar(0, "bake");
    let report = bake(&scene, &raw_path, &BakeOptions::default(), &|p| {
        bar.set_length(p.rows_total);
        bar.set_position(p.rows_done);
    })?;
    bar.finish_and_clear();
    eprintln!(
        "baked {} rows in {:.1} s",
        report.rows_baked,
        report.elapsed.as_secs_f64()
    );
    Ok(raw_path)
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
        let s = compress(raw, out, &opts.into(), &|_, _, _| {})?;
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

pub fn run(a: DemoArgs) -> Result<()> {
    let assets = assets_dir(a.assets)?;
    // Everything that can fail is checked before the bake.
    let opts = CodeOptions {
        bits: a.bits,
        target: Target::MaxError(a.max_error),
        ..Default::default()
    };
    opts.validate()?;
    let maps = load_maps(&env_maps(&assets)?)?;
    std::fs::create_dir_all(&a.output)
        .with_context(|| format!("creating {}", a.output.display()))?;
    let out = |name: &str| a.output.join(name);
    let start = Instant::now();

    // 1. Bake (cached: a complete raw store of the same settings is reused).
    let mut desc = SceneDesc::default_scene(&assets)?;
    desc.apply(&Overrides {
        width: Some(a.size),
        height: Some(a.size),
        face_res: Some(a.face_res),
        ..Default::default()
    })?;
    let raw_path = bake_cached(
        &desc,
        &a.output,
        &format!("scene-{}px-n{}", a.size, a.face_res),
    )?;
    let raw = RawStore::open(&raw_path)?;
    let dims = raw.dims();

    // 2. Compress: adaptive at the target error, 2d at the same size.
    let adaptive_path = out("scene-adaptive.ltm");
    let bar = progress::bar(0, "compress");
    let t = Instant::now();
    let adaptive = compress(&raw, &adaptive_path, &opts.into(), &|_, done, total| {
        bar.set_length(total);
        bar.set_position(done);
    })?;
    bar.finish_and_clear();
    let compress_s = t.elapsed().as_secs_f64();
    eprintln!(
        "adaptive: {} bytes, error {:.4}, {compress_s:.1} s",
        adaptive.file_bytes, adaptive.achieved_error
    );
    let twod_path = out("scene-2d.ltm");
    let (twod_bytes, twod_error) =
        compress_2d_to_size(&raw, &twod_path, a.bits, adaptive.file_bytes)?;
    eprintln!("2d at the same size: {twod_bytes} bytes, error {twod_error:.4}");

    // 3. Relight under every map.
    let relighters = [
        ("adaptive", Relighter::open(&adaptive_path)?),
        ("2d", Relighter::open(&twod_path)?),
    ];
    // The timed frames below are of frames alone, with every column decoded.
    for (_, r) in &relighters {
        r.decode_all()?;
    }
    let n_values = [50usize, 200, 1000];
    let mut table = String::new();
    let (w, h) = (dims.width() as usize, dims.height() as usize);
    let mut sheet = Image::new(3 * w, maps.len() * h);
    for (row, (name, map)) in maps.iter().enumerate() {
        let light = map.to_cubemap(dims.face_res() as usize, &Rotation::IDENTITY);
        let exact = reference(&raw, &light)?;
        let ev = auto_exposure(&exact);
        exact.write_exr(&out(&format!("{name}-reference.exr")))?;
        exact.write_png(&out(&format!("{name}-reference.png")), ev)?;
        let mut tiles = vec![exact];
        for (mode, relighter) in &relighters {
            let mut bufs = relighter.frame()?;
            for &n in &n_values {
                let mut times = Vec::new();
                let mut stats = Default::default();
                for _ in 0..15 {
                    let request = Request {
                        terms: n,
                        weighting: Weighting::Transport,
                    };
                    stats = relighter.relight(&light, &request, &mut bufs)?;
                    times.push(stats.total().as_secs_f64());
                }
                times.sort_by(f64::total_cmp);
                let ms = times[times.len() / 2] * 1e3;
                let err = relative_l2(&bufs.image, &tiles[0])?;
                writeln!(
                    table,
                    "| {name} | {mode} | {n} | {} | {:.3} | {:.0} | {:.2} % |",
                    stats.nonzeros,
                    ms,
                    1e3 / ms,
                    100.0 * err
                )?;
                if n == 200 {
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
        eprintln!("relit under {name}");
    }
    sheet.write_png(&out("contact-sheet.png"), 0.0)?;

    // 4. Summary.
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
        twod_bytes,
        dims.raw_bytes() as f64 / twod_bytes as f64,
        100.0 * twod_error
    )?;
    writeln!(md, "Relighting (transport-weighted wavelet lights, median of 15 frames); error is the relative L2 error against the exact `T·L`:\n")?;
    writeln!(md, "| map | file | N | nonzeros | frame ms | frames/s | relit error |\n|---|---|---|---|---|---|---|")?;
    md.push_str(&table);
    writeln!(md, "\n`contact-sheet.png`: one row per map; columns: exact `T·L`, adaptive N = 200, 2d (same file size) N = 200.")?;
    write_atomic(&out("summary.md"), md.as_bytes())?;
    println!("{md}");
    eprintln!("wrote {}", a.output.display());
    Ok(())
}
