//! `ltm relight`.

use crate::area_light::AreaArgs;
use crate::common::{claim_files, describe_terms, Ctx, ImageOutput, TermsArgs};
use crate::render_glossy::{Glossy, GlossyArgs};
use anyhow::{bail, Context, Result};
use clap::Args;
use glam::DVec3;
use ltm_codec::{Charge, ImageCamera, LtmFile, RowLayout, SurfacePoint};
use ltm_relight::rotation::Brdf;
use ltm_relight::{
    relative_l2, EnvMap, Frame, FrameStats, Image, Lookup, PcaRelighter, PointLight, Relight,
    Request, Rotation,
};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Arguments of `ltm relight`.
#[derive(Args)]
pub struct RelightArgs {
    /// A compressed matrix from `ltm compress`.
    pub file: PathBuf,
    /// Environment map: lat-long (width = 2·height) EXR or Radiance .hdr.
    /// May be left out when point lights are given: the image is then
    /// theirs alone.
    #[arg(long, required_unless_present_any = ["point", "area_light"])]
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
    #[arg(long, value_name = "X,Y,Z", value_parser = crate::common::ranges::point, allow_hyphen_values = true)]
    pub point: Vec<[f64; 3]>,
    /// Radiant intensity of the matching --point, W/sr: I, or R,G,B; finite
    /// and >= 0 (as Mitsuba's point emitter `intensity`).
    #[arg(long, value_name = "I", value_parser = crate::common::ranges::intensity, allow_hyphen_values = true)]
    pub intensity: Vec<[f32; 3]>,
    /// How a point light's direction picks cubemap texels: `nearest` (the
    /// texel it falls in) or `bilinear` (the four nearest texel centres).
    #[arg(long, default_value = "bilinear")]
    pub point_lookup: Lookup,
    #[command(flatten)]
    pub area: AreaArgs,
    #[command(flatten)]
    pub glossy: GlossyArgs,
    /// With --brdf: the camera position the file's pixels were seen from
    /// [default: recovered from the file's surface records, which lie on
    /// the rays through the pixel centres; refused when they cannot fix it,
    /// e.g. a view of one plane].
    #[arg(long, value_name = "X,Y,Z", value_parser = crate::common::ranges::point, allow_hyphen_values = true, requires = "brdf")]
    pub eye: Option<[f64; 3]>,
    #[command(flatten)]
    pub terms: TermsArgs,
    /// Rotate the lighting: yaw,pitch,roll in degrees.
    #[arg(long, default_value = "0,0,0", allow_hyphen_values = true)]
    pub rotate: Rotation,
    #[command(flatten)]
    pub out: ImageOutput,
    /// Frames to time (the image is the same each frame; reports the median
    /// wall time from lighting to finished image, each frame transforming
    /// its lighting anew; `--json` also gives the median of as many frames
    /// that reuse the transform, as when only the number of terms changes;
    /// each part of a frame, e.g. the multiply-add, is its median over the
    /// timed frames). The first frame also decodes the columns it uses
    /// (`--json`: `first_frame_ms`, `decode_ms`), unless `--preload`.
    #[arg(long, default_value_t = 1, value_parser = crate::common::ranges::frames)]
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
fn open_for_points(file: &LtmFile, path: &Path, ctx: &Ctx) -> Result<PcaRelighter> {
    if file.pca().is_none() {
        bail!(
            "--point needs a pca file (ltm compress --mode pca): {} is a {} file, and the wavelet modes (2d, 4d, adaptive) do not support point lights",
            path.display(),
            file.meta().mode.name()
        );
    }
    Ok(PcaRelighter::new(file, ctx.limits())?)
}

/// The opened file: a pca relighter, which also lights points, or a
/// relighter of any mode.
enum Opened {
    Points(Box<PcaRelighter>),
    Any(AnyRelighter),
}

impl Opened {
    /// The relighter of `file` (`a.file`, opened): for point lights when
    /// there are any, else of any mode, decoded whole with `--preload`.
    fn open(a: &RelightArgs, file: LtmFile, points: bool, ctx: &Ctx) -> Result<Opened> {
        let open = || -> Result<Opened> {
            Ok(if points {
                Opened::Points(Box::new(open_for_points(&file, &a.file, ctx)?))
            } else {
                Opened::Any(ltm_relight::open_file(file, ctx.limits())?)
            })
        };
        let opened = open().with_context(|| format!("opening {}", a.file.display()))?;
        if a.preload {
            opened
                .relighter()
                .preload()
                .with_context(|| format!("decoding {}", a.file.display()))?;
        }
        Ok(opened)
    }

    fn relighter(&self) -> &dyn Relight {
        match self {
            Opened::Points(p) => p.as_ref(),
            Opened::Any(o) => o.as_ref(),
        }
    }

    fn pca(&self) -> Option<&PcaRelighter> {
        match self {
            Opened::Points(p) => Some(p.as_ref()),
            Opened::Any(_) => None,
        }
    }
}

/// One frame's work: the environment's image (if any) plus the point
/// lights'.
struct Scene<'a> {
    opened: &'a Opened,
    light: Option<Vec<[f32; 3]>>,
    points: &'a [PointLight],
    lookup: Lookup,
    request: Request,
}

impl Scene<'_> {
    /// Relights one frame into `bufs`; with `reuse`, the lighting's
    /// transform of the last frame is kept, as when only N changes.
    fn frame(&self, bufs: &mut Frame, reuse: bool) -> Result<FrameStats> {
        let relighter = self.opened.relighter();
        let mut stats = Default::default();
        match &self.light {
            Some(l) => {
                if !reuse {
                    bufs.forget_light();
                }
                stats = relighter.relight(l, &self.request, bufs)?;
            }
            None => {
                let (w, h) = relighter.size();
                bufs.image = Image::new(w, h);
            }
        }
        if let Some(p) = self.opened.pca() {
            let lit = p.relight_points(self.points, self.lookup, self.request.terms)?;
            for (o, v) in bufs.image.data.iter_mut().zip(&lit.data) {
                for (oc, vc) in o.iter_mut().zip(v) {
                    *oc += vc;
                }
            }
        }
        Ok(stats)
    }
}

/// The timed frames: medians and the first frame.
struct Timing {
    /// Each part of a frame: its median over the timed frames.
    stats: FrameStats,
    first: FrameStats,
    first_time: Duration,
    median: Duration,
    median_reuse: Duration,
}

/// Times `frames` frames that each transform their lighting anew, then as
/// many that reuse it.
fn time_frames(scene: &Scene, bufs: &mut Frame, frames: usize) -> Result<Timing> {
    let mut times = Vec::with_capacity(frames);
    let mut all_stats = Vec::with_capacity(frames);
    for _ in 0..frames {
        let t = Instant::now();
        all_stats.push(scene.frame(bufs, false)?);
        times.push(t.elapsed());
    }
    let part = |f: fn(&FrameStats) -> Duration| {
        let mut v: Vec<_> = all_stats.iter().map(f).collect();
        v.sort();
        v.get(v.len() / 2).copied().unwrap_or_default()
    };
    let stats = FrameStats {
        light_transform: part(|s| s.light_transform),
        selection: part(|s| s.selection),
        multiply: part(|s| s.multiply),
        inverse: part(|s| s.inverse),
        ..all_stats.last().copied().unwrap_or_default()
    };
    let mut reuse = Vec::with_capacity(frames);
    for _ in 0..frames {
        let t = Instant::now();
        scene.frame(bufs, true)?;
        reuse.push(t.elapsed());
    }
    let first_time = times.first().copied().unwrap_or_default();
    times.sort();
    reuse.sort();
    Ok(Timing {
        stats,
        first: all_stats.first().copied().unwrap_or_default(),
        first_time,
        median: times[times.len() / 2],
        median_reuse: reuse[reuse.len() / 2],
    })
}

/// The image of the `--area-light`s, if any, and its time.
fn area_image(a: &RelightArgs, ctx: &Ctx) -> Result<Option<(Vec<[f32; 3]>, Duration)>> {
    if !a.area.any() {
        return Ok(None);
    }
    let method = a.area.method()?;
    let lights = a.area.lights(ctx.limits())?;
    let (image, time) = crate::area_light::render(&a.file, &lights, method, ctx.limits())?;
    Ok(Some((image, time)))
}

/// Refuses flags that `--brdf` cannot go with: it reflects the map, so it
/// needs one, and `--reference` is the transport's exact image, not the
/// glossy one.
fn check_glossy_flags(a: &RelightArgs) -> Result<()> {
    if a.env.is_none() {
        bail!("--brdf reflects the environment map: give it with --env (point and area lights are not reflected by the glossy part)");
    }
    if a.reference.is_some() {
        bail!("--reference compares with the transport's exact image, which has no --brdf material: leave one of them out");
    }
    Ok(())
}

/// The eye that image rows were seen from: `--eye`, or recovered from the
/// rows' surface records.
fn image_eye(a: &RelightArgs, file: &LtmFile) -> Result<DVec3> {
    let path = a.file.display();
    let surface = file.surface().with_context(|| {
        format!("--brdf shades each pixel from its surface point, and {path} stores none (files compressed from bakes of this version do)")
    })?;
    let width = match file.meta().dims.rows {
        RowLayout::Image { width, .. } => width as usize,
        _ => bail!(
            "{path} holds texture rows, whose glossy look depends on the view: draw them with ltm render --brdf (or ltm view --brdf)"
        ),
    };
    if let Some(eye) = a.eye {
        return Ok(DVec3::from_array(eye));
    }
    let camera = ImageCamera::recover(surface, width)
        .with_context(|| format!("{path}: give the camera position with --eye X,Y,Z"))?;
    let e = camera.eye();
    eprintln!(
        "eye recovered from {} surface points: {:.6}, {:.6}, {:.6} (largest miss {:.1e} px; --eye sets it)",
        camera.points(),
        e[0],
        e[1],
        e[2],
        camera.max_residual_px()
    );
    Ok(DVec3::from_array(e))
}

/// What `--brdf` shades, read before any work: the file's surface points
/// (charged to the budget while they live) and the eye.
struct GlossySurface {
    points: Vec<SurfacePoint>,
    _charge: Charge,
    eye: DVec3,
}

impl GlossySurface {
    fn read(a: &RelightArgs, file: &LtmFile, ctx: &Ctx) -> Result<GlossySurface> {
        let eye = image_eye(a, file)?;
        let points = file.surface().map_or(&[][..], |s| s.points());
        let size = std::mem::size_of::<SurfacePoint>() as u64;
        let charge = ctx
            .limits()
            .check_alloc("surface points", points.len() as u64, size)?;
        Ok(GlossySurface {
            points: points.to_vec(),
            _charge: charge,
            eye,
        })
    }

    /// The relit `image` plus (or replaced by, with `--shading glossy`)
    /// the `--brdf` material's reflection of `env`, each pixel shaded from
    /// the eye.
    fn shade(
        self,
        a: &RelightArgs,
        brdf: Brdf,
        env: &EnvMap,
        image: &Image,
        ctx: &Ctx,
    ) -> Result<Image> {
        let glossy = Glossy::prepare(&a.glossy, brdf, self.points, env, &a.rotate, ctx.limits())?;
        let start = Instant::now();
        let out = glossy.texture(image, self.eye)?;
        eprintln!(
            "{}; every pixel shaded (step 2) in {:.1} ms",
            glossy.describe(),
            start.elapsed().as_secs_f64() * 1e3
        );
        Ok(out)
    }
}

/// The relit image's relative L2 error against `--reference`, if given.
fn reference_error(image: &Image, reference: Option<&Path>) -> Result<Option<f64>> {
    let Some(path) = reference else {
        return Ok(None);
    };
    let exact = Image::read_exr(path).with_context(|| format!("reading {}", path.display()))?;
    Ok(Some(relative_l2(image, &exact).with_context(|| {
        format!("comparing with {}", path.display())
    })?))
}

pub fn run(a: RelightArgs, ctx: &Ctx) -> Result<()> {
    let points = point_lights(&a)?;
    let brdf = a.glossy.material(ctx.limits())?;
    if brdf.is_some() {
        check_glossy_flags(&a)?;
    }
    let mut inputs = vec![("input", a.file.as_path())];
    if let Some(env) = &a.env {
        inputs.push(("--env", env.as_path()));
    }
    if let Some(r) = &a.reference {
        inputs.push(("--reference", r.as_path()));
    }
    inputs.extend(a.area.inputs());
    inputs.extend(a.glossy.measured_file().map(|m| ("--brdf", m)));
    let _claim = claim_files(&inputs, &a.out.roles())?;
    // One read of the file: its surface for --brdf, then its relighter.
    let opened_at = Instant::now();
    let file = LtmFile::open_with_limits(&a.file, ctx.limits())
        .with_context(|| format!("opening {}", a.file.display()))?;
    let read_time = opened_at.elapsed();
    let glossy = match brdf {
        Some(b) => Some((b, GlossySurface::read(&a, &file, ctx)?)),
        None => None,
    };
    let near = area_image(&a, ctx)?;
    let opened_at = Instant::now();
    let opened = Opened::open(&a, file, !points.is_empty(), ctx)?;
    let relighter = opened.relighter();
    let open_time = read_time + opened_at.elapsed();
    let env = match &a.env {
        Some(path) => {
            Some(EnvMap::load(path).with_context(|| format!("loading {}", path.display()))?)
        }
        None => None,
    };
    let light = env
        .as_ref()
        .map(|env| env.to_cubemap(relighter.face_res(), &a.rotate));
    let scene = Scene {
        opened: &opened,
        light,
        points: &points,
        lookup: a.point_lookup,
        request: Request {
            terms: a.terms.resolve(relighter),
            weighting: a.terms.weighting,
        },
    };
    let mut bufs = relighter.frame()?;
    let timing = time_frames(&scene, &mut bufs, a.frames)?;
    if let Some((lit, time)) = &near {
        for (o, v) in bufs.image.data.iter_mut().zip(lit) {
            for (oc, vc) in o.iter_mut().zip(v) {
                *oc += vc;
            }
        }
        eprintln!(
            "{} area light(s): {} rows shaded in {:.1} ms ({})",
            a.area.area_light.len(),
            lit.len(),
            time.as_secs_f64() * 1e3,
            crate::area_light::method_name(a.area.method()?),
        );
    }
    if let (Some((brdf, surface)), Some(env)) = (glossy, &env) {
        bufs.image = surface.shade(&a, brdf, env, &bufs.image, ctx)?;
    }
    a.out.write(&bufs.image)?;
    let error = reference_error(&bufs.image, a.reference.as_deref())?;
    report(&a, &scene, &timing, open_time, error);
    Ok(())
}

/// Prints the `--json` line and the summary on stderr.
fn report(
    a: &RelightArgs,
    scene: &Scene,
    timing: &Timing,
    open_time: Duration,
    error: Option<f64>,
) {
    let relighter = scene.opened.relighter();
    let (stats, first) = (&timing.stats, &timing.first);
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    if a.json {
        let line = serde_json::json!({
            "file": a.file,
            "terms": scene.request.terms.min(relighter.lights()),
            "weighting": a.terms.weighting.name(),
            "lights": stats.lights,
            "nonzeros": stats.nonzeros,
            "frame_ms": ms(timing.median),
            "same_light_frame_ms": ms(timing.median_reuse),
            "open_ms": ms(open_time),
            "first_frame_ms": ms(timing.first_time),
            "decode_ms": ms(first.decode),
            "columns_decoded": first.columns_decoded,
            "arena_bytes": relighter.held_bytes(),
            "light_transform_ms": ms(stats.light_transform),
            "selection_ms": ms(stats.selection),
            "multiply_ms": ms(stats.multiply),
            "inverse_ms": ms(stats.inverse),
            "relative_error": error,
            "point_lights": scene.points.len(),
        });
        println!("{line}");
    }
    if let Some(e) = error {
        eprintln!("relative L2 error against the reference: {e:.6}");
    }
    let points = match scene.points.len() {
        0 => String::new(),
        1 => " and 1 point light".into(),
        n => format!(" and {n} point lights"),
    };
    if scene.light.is_none() && scene.points.is_empty() {
        eprintln!("wrote {}: the area lights alone", a.out.output.display());
        return;
    }
    eprintln!(
        "wrote {}: {}{points}, {} nonzeros, frame {:.3} ms (median of {}; light transform {:.3}, selection {:.3}, multiply {:.3}, inverse {:.3} ms)",
        a.out.output.display(),
        describe_terms(relighter, stats.lights),
        stats.nonzeros,
        ms(timing.median),
        a.frames,
        ms(stats.light_transform),
        ms(stats.selection),
        ms(stats.multiply),
        ms(stats.inverse),
    );
    if first.columns_decoded > 0 {
        eprintln!(
            "the first frame decoded the {} columns it used in {:.1} ms (open {:.1} ms; --preload decodes every column at open)",
            first.columns_decoded,
            ms(first.decode),
            ms(open_time),
        );
    }
}
