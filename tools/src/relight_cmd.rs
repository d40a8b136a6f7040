//! `ltm relight`.

use anyhow::{bail, Context, Result};
use clap::Args;
use ltm_codec::LtmFile;
use ltm_relight::{
    relative_l2, EnvMap, Image, Lookup, PcaRelighter, PointLight, Relight, Request, Rotation,
    TermBasis, Weighting,
};
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
    /// May be left out when point lights are given: the image is then
    /// theirs alone.
    #[arg(long, required_unless_present = "point")]
    pub env: Option<PathBuf>,
    /// A point light at world position X,Y,Z (the scene's units), added to
    /// the environment's image; repeatable, paired in order with
    /// --intensity. pca files only (they keep a basis that can be
    /// evaluated at any single direction; the wavelet modes 2d, 4d and
    /// adaptive cannot), and the file must carry per-row surface data (any
    /// image or texture bake compressed by this version). Each row is lit
    /// from the light's direction as seen from its surface point, scaled by
    /// I/d², with the visibility of that direction at infinity
    /// (Eigentransport §4.2.1): exact for lights outside the scene's
    /// bounding sphere, wrong for a light between objects. Refused: a
    /// non-finite position, a light within 1e-6·(scene scale) of a row's
    /// surface point, or behind every row's surface (inside geometry).
    #[arg(long, value_name = "X,Y,Z", value_parser = crate::ranges::point, allow_hyphen_values = true)]
    pub point: Vec<[f64; 3]>,
    /// Radiant intensity of the matching --point, W/sr: I, or R,G,B; finite
    /// and >= 0 (as Mitsuba's point emitter `intensity`).
    #[arg(long, value_name = "I", value_parser = crate::ranges::intensity, allow_hyphen_values = true)]
    pub intensity: Vec<[f32; 3]>,
    /// How a point light's direction picks cubemap texels: `nearest` (the
    /// texel it falls in) or `bilinear` (the four nearest texel centres).
    #[arg(long, default_value = "bilinear")]
    pub point_lookup: Lookup,
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
    /// that reuse the transform, as when only the number of terms changes;
    /// each part of a frame, e.g. the multiply-add, is its median over the
    /// timed frames). The first frame also decodes the columns it uses
    /// (`--json`: `first_frame_ms`, `decode_ms`), unless `--preload`.
    #[arg(long, default_value_t = 1, value_parser = crate::ranges::frames)]
    pub frames: usize,
    /// Decode every column of a wavelet file at open (counted in the open
    /// time) instead of each when a frame first needs it: frames then
    /// never decode.
    #[arg(long)]
    pub preload: bool,
    /// An exact image from `ltm reference` (same map and rotation): print the
    /// relit image's relative L2 error against it.
    #[arg(long)]
    pub reference: Option<PathBuf>,
    /// Print one JSON line with the settings, timings and error.
    #[arg(long)]
    pub json: bool,
}

/// A relighter of any mode.
type AnyRelighter = Box<dyn Relight + Send + Sync>;

/// The point lights of the command line: `--point` and `--intensity` in
/// pairs.
fn point_lights(a: &RelightArgs) -> Result<Vec<PointLight>> {
    if a.point.len() != a.intensity.len() {
        bail!(
            "{} --point and {} --intensity given: each point light needs one of each, paired in order",
            a.point.len(),
            a.intensity.len()
        );
    }
    Ok(a.point
        .iter()
        .zip(&a.intensity)
        .map(|(&position, &intensity)| PointLight {
            position,
            intensity,
        })
        .collect())
}

/// Opens a file for point lights: a pca file, or an error naming the mode.
fn open_for_points(path: &std::path::Path) -> Result<PcaRelighter> {
    let file = LtmFile::open_with_limits(path, crate::limits())?;
    if file.pca().is_none() {
        bail!(
            "--point needs a pca file (ltm compress --mode pca): {} is a {} file, and the wavelet modes (2d, 4d, adaptive) do not support point lights",
            path.display(),
            file.meta().mode.name()
        );
    }
    Ok(PcaRelighter::new(&file, crate::limits())?)
}

pub fn run(a: RelightArgs) -> Result<()> {
    let points = point_lights(&a)?;
    let mut inputs = vec![("input", a.file.as_path())];
    if let Some(env) = &a.env {
        inputs.push(("--env", env.as_path()));
    }
    if let Some(r) = &a.reference {
        inputs.push(("--reference", r.as_path()));
    }
    let mut outputs = vec![("-o", a.output.as_path())];
    if let Some(png) = &a.png {
        outputs.push(("--png", png.as_path()));
    }
    crate::paths::check_files(&inputs, &outputs)?;
    let opened = std::time::Instant::now();
    let open = || -> Result<(Option<PcaRelighter>, Option<AnyRelighter>)> {
        Ok(if points.is_empty() {
            (None, Some(ltm_relight::open(&a.file, crate::limits())?))
        } else {
            (Some(open_for_points(&a.file)?), None)
        })
    };
    let (pca, other) = open().with_context(|| format!("opening {}", a.file.display()))?;
    let relighter: &dyn Relight = match (&pca, &other) {
        (Some(p), _) => p,
        (None, Some(o)) => o.as_ref(),
        (None, None) => unreachable!("one of the two is opened"),
    };
    if a.preload {
        relighter
            .preload()
            .with_context(|| format!("decoding {}", a.file.display()))?;
    }
    let open_time = opened.elapsed();
    let light = match &a.env {
        Some(path) => {
            let env = EnvMap::load(path).with_context(|| format!("loading {}", path.display()))?;
            Some(env.to_cubemap(relighter.face_res(), &a.rotate))
        }
        None => None,
    };
    // A pca file (linear basis) refuses more terms than it stores; `all`
    // and the default mean all of them there.
    let linear = relighter.term_basis() == TermBasis::Linear;
    let terms = match a.terms {
        Some(Terms(usize::MAX)) => relighter.max_terms(),
        Some(Terms(t)) => t,
        None if linear => relighter.max_terms(),
        None => 200,
    };
    let mut bufs = relighter.frame()?;
    let request = Request {
        terms,
        weighting: a.weighting,
    };
    let (w, h) = relighter.size();
    // Every timed frame transforms its lighting, as a new light would;
    // then the same number of frames reuse it, as when only N changes.
    let mut frame = |reuse: bool| -> Result<ltm_relight::FrameStats> {
        let mut stats = Default::default();
        match &light {
            Some(l) => {
                if !reuse {
                    bufs.forget_light();
                }
                stats = relighter.relight(l, &request, &mut bufs)?;
            }
            None => bufs.image = Image::new(w, h),
        }
        if let Some(p) = &pca {
            let lit = p.relight_points(&points, a.point_lookup, terms)?;
            for (o, v) in bufs.image.data.iter_mut().zip(&lit.data) {
                for (oc, vc) in o.iter_mut().zip(v) {
                    *oc += vc;
                }
            }
        }
        Ok(stats)
    };
    let mut times = Vec::with_capacity(a.frames);
    let mut all_stats = Vec::with_capacity(a.frames);
    for _ in 0..a.frames {
        let t = std::time::Instant::now();
        all_stats.push(frame(false)?);
        times.push(t.elapsed());
    }
    // Each part of a frame: its median over the timed frames.
    let part = |f: fn(&ltm_relight::FrameStats) -> std::time::Duration| {
        let mut v: Vec<_> = all_stats.iter().map(f).collect();
        v.sort();
        v.get(v.len() / 2).copied().unwrap_or_default()
    };
    let first = all_stats.first().copied().unwrap_or_default();
    let first_time = times.first().copied().unwrap_or_default();
    let stats = ltm_relight::FrameStats {
        light_transform: part(|s| s.light_transform),
        selection: part(|s| s.selection),
        multiply: part(|s| s.multiply),
        inverse: part(|s| s.inverse),
        ..all_stats.last().copied().unwrap_or_default()
    };
    let mut reuse = Vec::with_capacity(a.frames);
    for _ in 0..a.frames {
        let t = std::time::Instant::now();
        frame(true)?;
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
            "first_frame_ms": ms(first_time),
            "decode_ms": ms(first.decode),
            "columns_decoded": first.columns_decoded,
            "arena_bytes": relighter.held_bytes(),
            "light_transform_ms": ms(stats.light_transform),
            "selection_ms": ms(stats.selection),
            "multiply_ms": ms(stats.multiply),
            "inverse_ms": ms(stats.inverse),
            "relative_error": error,
            "point_lights": points.len(),
        });
        println!("{line}");
    }
    if let Some(e) = error {
        eprintln!("relative L2 error against the reference: {e:.6}");
    }
    eprintln!(
        "wrote {}: {} point light(s), {} lights, {} nonzeros, frame {:.3} ms (median of {}; light transform {:.3}, selection {:.3}, multiply {:.3}, inverse {:.3} ms)",
        a.output.display(),
        points.len(),
        stats.lights,
        stats.nonzeros,
        median.as_secs_f64() * 1e3,
        a.frames,
        stats.light_transform.as_secs_f64() * 1e3,
        stats.selection.as_secs_f64() * 1e3,
        stats.multiply.as_secs_f64() * 1e3,
        stats.inverse.as_secs_f64() * 1e3,
    );
    if first.columns_decoded > 0 {
        eprintln!(
            "the first frame decoded the {} columns it used in {:.1} ms (open {:.1} ms; --preload decodes every column at open)",
            first.columns_decoded,
            first.decode.as_secs_f64() * 1e3,
            open_time.as_secs_f64() * 1e3,
        );
    }
    Ok(())
}
