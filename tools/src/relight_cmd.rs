//! `ltm relight`.

use anyhow::{bail, Context, Result};
use clap::Args;
use ltm_relight::{open_relighter, relative_l2, EnvMap, Image, Request, Rotation, Weighting};
use std::path::PathBuf;
use std::str::FromStr;

/// How many wavelet lights to use.
#[derive(Clone, Copy, Debug)]
pub struct Terms(pub usize);

impl FromStr for Terms {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Terms, String> {
        if s == "all" {
            return Ok(Terms(usize::MAX));
        }
        match s.parse::<usize>() {
            Ok(0) | Err(_) => Err(format!("terms '{s}' must be a positive integer or 'all'")),
            Ok(n) => Ok(Terms(n)),
        }
    }
}

/// Arguments of `ltm relight`.
#[derive(Args)]
pub struct RelightArgs {
    /// A compressed matrix from `ltm compress`.
    pub file: PathBuf,
    /// Environment map: lat-long (width = 2·height) EXR or Radiance .hdr.
    #[arg(long)]
    pub env: PathBuf,
    /// Wavelet lights per frame (non-linear approximation), or `all`.
    /// Values above the number of lights use them all. For a pca file: the
    /// first N eigen-transports (at most the rank stored). [default: 200
    /// wavelet lights; every eigen-transport of a pca file]
    #[arg(long)]
    pub terms: Option<Terms>,
    /// Priority of wavelet lights: unweighted |c|, transport |c|·‖T_j‖, or
    /// area |c|·support area (Ng et al. 2003).
    #[arg(long, default_value = "unweighted")]
    pub weighting: Weighting,
    /// Rotate the lighting: yaw,pitch,roll in degrees.
    #[arg(long, default_value = "0,0,0", allow_hyphen_values = true)]
    pub rotate: Rotation,
    /// Output image, linear RGB EXR.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Also write a tone-mapped sRGB PNG.
    #[arg(long)]
    pub png: Option<PathBuf>,
    /// Exposure for the PNG, in stops.
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true, value_parser = crate::ranges::exposure)]
    pub exposure: f32,
    /// Frames to time (the image is the same each frame; reports the median
    /// wall time from lighting to finished image, each frame transforming
    /// its lighting anew; `--json` also gives the median of as many frames
    /// that reuse the transform, as when only the number of terms changes).
    #[arg(long, default_value_t = 1, value_parser = crate::ranges::frames)]
    pub frames: usize,
    /// An exact image from `ltm reference` (same map and rotation): print the
    /// relit image's relative L2 error against it.
    #[arg(long)]
    pub reference: Option<PathBuf>,
    /// Print one JSON line with the settings, timings and error.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: RelightArgs) -> Result<()> {
    let mut inputs = vec![("input", a.file.as_path()), ("--env", a.env.as_path())];
    if let Some(r) = &a.reference {
        inputs.push(("--reference", r.as_path()));
    }
    let mut outputs = vec![("-o", a.output.as_path())];
    if let Some(png) = &a.png {
        outputs.push(("--png", png.as_path()));
    }
    crate::paths::check_files(&inputs, &outputs)?;
    let opened = std::time::Instant::now();
    let relighter = open_relighter(&a.file, crate::limits())
        .with_context(|| format!("opening {}", a.file.display()))?;
    let open_time = opened.elapsed();
    let env = EnvMap::load(&a.env).with_context(|| format!("loading {}", a.env.display()))?;
    let n = ((relighter.lights() / 6) as f64).sqrt().round() as usize;
    // A pca file (linear basis) refuses more terms than it stores; `all`
    // and the default mean all of them there.
    let linear = relighter.max_terms() < relighter.lights();
    let terms = match a.terms {
        Some(Terms(usize::MAX)) => relighter.max_terms(),
        Some(Terms(t)) => t,
        None if linear => relighter.max_terms(),
        None => 200,
    };
    let light = env.to_cubemap(n, &a.rotate);
    if a.frames == 0 {
        bail!("--frames must be at least 1");
    }
    let mut bufs = relighter.frame();
    let request = Request {
        terms,
        weighting: a.weighting,
    };
    // Every timed frame transforms its lighting, as a new light would;
    // then the same number of frames reuse it, as when only N changes.
    let mut times = Vec::with_capacity(a.frames);
    let mut stats = Default::default();
    for _ in 0..a.frames {
        bufs.forget_light();
        let t = std::time::Instant::now();
        stats = relighter.relight(&light, &request, &mut bufs)?;
        times.push(t.elapsed());
    }
    let mut reuse = Vec::with_capacity(a.frames);
    for _ in 0..a.frames {
        let t = std::time::Instant::now();
        relighter.relight(&light, &request, &mut bufs)?;
        reuse.push(t.elapsed());
    }
    times.sort();
    reuse.sort();
    let median = times[times.len() / 2];
    let median_reuse = reuse[reuse.len() / 2];
    bufs.image
        .write_exr(&a.output)
        .with_context(|| format!("writing {}", a.output.display()))?;
    if let Some(png) = &a.png {
        bufs.image
            .write_png(png, a.exposure)
            .with_context(|| format!("writing {}", png.display()))?;
    }
    let error = match &a.reference {
        Some(path) => {
            let exact =
                Image::read_exr(path).with_context(|| format!("reading {}", path.display()))?;
            Some(
                relative_l2(&bufs.image, &exact)
                    .with_context(|| format!("comparing with {}", path.display()))?,
            )
        }
        None => None,
    };
    if a.json {
        let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3;
        let line = serde_json::json!({
            "file": a.file,
            "terms": terms.min(relighter.lights()),
            "weighting": a.weighting.name(),
            "lights": stats.lights,
            "nonzeros": stats.nonzeros,
            "frame_ms": ms(median),
            "same_light_frame_ms": ms(median_reuse),
            "open_ms": ms(open_time),
            "arena_bytes": relighter.held_bytes(),
            "light_transform_ms": ms(stats.light_transform),
            "selection_ms": ms(stats.selection),
            "multiply_ms": ms(stats.multiply),
            "inverse_ms": ms(stats.inverse),
            "relative_error": error,
        });
        println!("{line}");
    }
    if let Some(e) = error {
        eprintln!("relative L2 error against the reference: {e:.6}");
    }
    eprintln!(
        "wrote {}: {} lights, {} nonzeros, frame {:.3} ms (median of {}; light transform {:.3}, selection {:.3}, multiply {:.3}, inverse {:.3} ms)",
        a.output.display(),
        stats.lights,
        stats.nonzeros,
        median.as_secs_f64() * 1e3,
        a.frames,
        stats.light_transform.as_secs_f64() * 1e3,
        stats.selection.as_secs_f64() * 1e3,
        stats.multiply.as_secs_f64() * 1e3,
        stats.inverse.as_secs_f64() * 1e3,
    );
    Ok(())
}
