//! `ltm render`: relight a texture-space file once and draw the relit mesh
//! from one camera or an orbit of cameras, optionally with a glossy
//! material shaded per view (`--brdf`, [`crate::render_glossy`]).

use crate::area_light::AreaArgs;
use crate::common::{
    claim_files_and_cache, commit_all, describe_terms, Ctx, ImageOutput, TermsArgs,
};
use crate::render_glossy::{Glossy, GlossyArgs};
use anyhow::{bail, Context, Result};
use clap::Args;
use glam::DVec3;
use ltm_codec::{Charge, LtmFile, SurfacePoint};
use ltm_relight::nearfield::NearField;
use ltm_relight::{EnvMap, Relight, Request, Rotation, TexturedMesh, ViewCamera, MAX_SUPERSAMPLE};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Most views `--views` may draw.
pub const MAX_VIEWS: usize = 3600;

/// Arguments of `ltm render`.
#[derive(Args)]
pub struct RenderArgs {
    /// A compressed texture-space matrix (baked with a `[texture]` section),
    /// of any mode (wavelet or pca).
    pub file: PathBuf,
    /// Environment map: lat-long (width = 2·height) EXR or Radiance .hdr.
    #[arg(long)]
    pub env: PathBuf,
    #[command(flatten)]
    pub terms: TermsArgs,
    /// Rotate the lighting: yaw,pitch,roll in degrees.
    #[arg(long, default_value = "0,0,0", allow_hyphen_values = true)]
    pub rotate: Rotation,
    /// Camera position x,y,z (world units of the bake).
    #[arg(long, allow_hyphen_values = true, value_parser = vec3)]
    pub camera: DVec3,
    /// Point at the image centre x,y,z.
    #[arg(long, allow_hyphen_values = true, value_parser = vec3)]
    pub target: DVec3,
    /// Direction towards the image's top x,y,z.
    #[arg(long, default_value = "0,1,0", allow_hyphen_values = true, value_parser = vec3)]
    pub up: DVec3,
    /// Vertical field of view in degrees, in (0, 180).
    #[arg(long, default_value_t = 35.0)]
    pub fov: f64,
    /// View size in pixels: WxH, or N for N×N.
    #[arg(long, default_value = "512x512", value_parser = size)]
    pub size: (u32, u32),
    /// Samples per pixel side (antialiased edges): 1 to 8.
    #[arg(long, default_value_t = 3)]
    pub supersample: u32,
    /// Draw an orbit of this many views about the target (around the up
    /// axis) from one relight. One view is written to the names -o and
    /// --png give; K > 1 views are numbered, the same way for both:
    /// `-o view.exr --png view.png --views 3` writes view-000.exr,
    /// view-001.exr, view-002.exr and view-000.png, view-001.png,
    /// view-002.png.
    #[arg(long, default_value_t = 1, value_parser = views)]
    pub views: usize,
    #[command(flatten)]
    pub out: ImageOutput,
    /// Also write the relit texture (EXR): the transport's, without the
    /// view-dependent glossy part.
    #[arg(long)]
    pub texture: Option<PathBuf>,
    #[command(flatten)]
    pub glossy: GlossyArgs,
    /// Area lights (files baked with a `[light_plane]`), added to the
    /// map's relit texture before the views are drawn, as `ltm relight
    /// --area-light` adds them.
    #[command(flatten)]
    pub area: AreaArgs,
    /// Print one JSON line with the settings and timings.
    #[arg(long)]
    pub json: bool,
}

/// Parses `x,y,z` with finite components.
fn vec3(s: &str) -> std::result::Result<DVec3, String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|t| t.trim().parse::<f64>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| format!("'{s}' is not x,y,z"))?;
    match v[..] {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok(DVec3::new(x, y, z)),
        [_, _, _] => Err(format!("'{s}' has a component that is not finite")),
        _ => Err(format!("'{s}' is not x,y,z (three numbers)")),
    }
}

/// `--size`: WxH or N, sides 1..=[`ltm_relight::MAX_VIEW_SIDE`].
fn size(s: &str) -> std::result::Result<(u32, u32), String> {
    crate::common::ranges::image_size(s, ltm_relight::MAX_VIEW_SIDE)
}

fn views(s: &str) -> std::result::Result<usize, String> {
    match s.parse::<usize>() {
        Ok(n) if (1..=MAX_VIEWS).contains(&n) => Ok(n),
        _ => Err(format!("'{s}' is out of range (valid: 1..={MAX_VIEWS})")),
    }
}

/// The name of view `k` of `count`: `PATH` for one view, `PATH` with
/// `-NNN` before the extension for several (the rule for -o and --png).
fn numbered(path: &Path, k: usize, count: usize) -> PathBuf {
    if count == 1 {
        return path.to_path_buf();
    }
    let stem = path.file_stem().unwrap_or_default().to_string_lossy();
    let name = match path.extension() {
        Some(e) => format!("{stem}-{k:03}.{}", e.to_string_lossy()),
        None => format!("{stem}-{k:03}"),
    };
    path.with_file_name(name)
}

/// What `ltm render` draws from: the relighter of a texture-space file of
/// any mode (wavelet or `pca`), the mesh of its geometry, and its surface
/// points when `--brdf` shades them.
struct Opened {
    relighter: Box<dyn Relight + Send + Sync>,
    mesh: TexturedMesh,
    points: Vec<SurfacePoint>,
    /// The points' bytes, charged to the run's budget while they live.
    points_charge: Charge,
    /// The file's near-field rows, when area lights are given.
    near: Option<NearField>,
}

fn open(path: &Path, with_points: bool, with_near: bool, ctx: &Ctx) -> Result<Opened> {
    let context = || format!("opening {}", path.display());
    let mut file = LtmFile::open_with_limits(path, ctx.limits()).with_context(context)?;
    let near = match with_near {
        true => Some(NearField::take(&mut file, ctx.limits()).with_context(context)?),
        false => None,
    };
    let mesh = TexturedMesh::from_file(&file, ctx.limits()).with_context(context)?;
    let (mut points, mut points_charge) = (Vec::new(), Charge::default());
    if let Some(surface) = file.surface().filter(|_| with_points) {
        let bytes = std::mem::size_of::<SurfacePoint>() as u64;
        points_charge = ctx
            .limits()
            .check_alloc("surface points", surface.len() as u64, bytes)?;
        points = surface.points().to_vec();
    }
    let relighter = ltm_relight::open_file(file, ctx.limits()).with_context(context)?;
    Ok(Opened {
        relighter,
        mesh,
        points,
        points_charge,
        near,
    })
}

pub fn run(a: RenderArgs, ctx: &Ctx) -> Result<()> {
    if !(1..=MAX_SUPERSAMPLE).contains(&a.supersample) {
        bail!(
            "--supersample {} is out of range (valid: 1..={MAX_SUPERSAMPLE})",
            a.supersample
        );
    }
    let camera = ViewCamera {
        eye: a.camera,
        target: a.target,
        up: a.up,
        fov: a.fov,
        width: a.size.0,
        height: a.size.1,
    };
    camera.validate()?;
    let mut names: Vec<(&str, PathBuf)> = (0..a.views)
        .map(|k| ("-o", numbered(&a.out.output, k, a.views)))
        .collect();
    if let Some(png) = &a.out.png {
        names.extend((0..a.views).map(|k| ("--png", numbered(png, k, a.views))));
    }
    names.extend(a.texture.clone().map(|t| ("--texture", t)));
    // The cache file depends on the side the BRDF needs; concurrent runs
    // share it.
    let material = a.glossy.material(ctx.limits())?;
    let cache = material.as_ref().and_then(|b| a.glossy.cache_path(b));
    let outputs: Vec<(&str, &Path)> = names.iter().map(|(r, p)| (*r, p.as_path())).collect();
    let mut inputs = vec![("input", a.file.as_path()), ("--env", a.env.as_path())];
    inputs.extend(a.glossy.measured_file().map(|m| ("--brdf", m)));
    inputs.extend(a.area.inputs());
    let cache = cache.as_deref().map(|c| ("--rotation-cache", c));
    let _claim = claim_files_and_cache(&inputs, &outputs, cache)?;
    let area = match a.area.any() {
        true => Some((a.area.lights(ctx.limits())?, a.area.method()?)),
        false => None,
    };
    let Opened {
        relighter,
        mesh,
        points,
        points_charge: _points_charge,
        near,
    } = open(&a.file, material.is_some(), area.is_some(), ctx)?;
    let mut frame = relighter.frame()?;
    let env = EnvMap::load(&a.env).with_context(|| format!("loading {}", a.env.display()))?;
    let light = env.to_cubemap(relighter.face_res(), &a.rotate);
    let request = Request {
        terms: a.terms.resolve(relighter.as_ref()),
        weighting: a.terms.weighting,
    };
    let stats = relighter.relight(&light, &request, &mut frame)?;
    if let (Some(near), Some((lights, method))) = (&near, &area) {
        let start = Instant::now();
        let lit = near.render(lights, *method)?;
        for (o, v) in frame.image.data.iter_mut().zip(&lit) {
            (0..3).for_each(|c| o[c] += v[c]);
        }
        eprintln!(
            "{} area light(s) added to the texture in {:.1} ms ({})",
            lights.len(),
            start.elapsed().as_secs_f64() * 1e3,
            crate::area_light::method_name(*method)
        );
    }
    let glossy = match material {
        Some(brdf) => Some(Glossy::prepare(
            &a.glossy,
            brdf,
            points,
            &env,
            &a.rotate,
            ctx.limits(),
        )?),
        None => None,
    };
    // Every file of the run appears together at the end, or none does.
    let mut staged = Vec::new();
    if let Some(t) = &a.texture {
        let file = frame.image.stage_exr(t);
        staged.push(file.with_context(|| format!("writing {}", t.display()))?);
    }
    let views = draw_views(
        &a,
        &mesh,
        &frame.image,
        glossy.as_ref(),
        &camera,
        &mut staged,
    )?;
    commit_all(staged)?;
    let median = median_ms(views.render_ms);
    let relight_ms = stats.total().as_secs_f64() * 1e3;
    if a.json {
        let line = serde_json::json!({
            "file": a.file,
            "terms": request.terms.min(relighter.lights()),
            "views": a.views,
            "width": a.size.0,
            "height": a.size.1,
            "triangles": mesh.triangle_count(),
            "relight_ms": relight_ms,
            "render_ms_median": median,
            "brdf": glossy.as_ref().map(|g| g.brdf().to_string()),
            "glossy_setup_ms": glossy.as_ref().map(|g| g.setup_ms),
            "glossy_shade_ms_median": glossy.as_ref().map(|_| median_ms(views.shade_ms.clone())),
        });
        println!("{line}");
    }
    if let Some(g) = &glossy {
        eprintln!(
            "{}; shading (step 2) {:.1} ms per view (median)",
            g.describe(),
            median_ms(views.shade_ms)
        );
    }
    eprintln!(
        "relit the {}² texture in {relight_ms:.3} ms ({}); drew {} view(s) of {} triangles, {median:.3} ms each (median); wrote {}",
        mesh.size(),
        describe_terms(relighter.as_ref(), stats.lights),
        a.views,
        mesh.triangle_count(),
        written(&a.out.output, a.views),
    );
    if let Some(png) = &a.out.png {
        eprintln!("wrote {}", written(png, a.views));
    }
    a.out.print_exposure(views.ev);
    Ok(())
}

/// The median of some timings (0 for none).
fn median_ms(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(0.0)
}

/// What [`draw_views`] measured.
struct Drawn {
    /// The PNGs' exposure (one for the orbit, the first view's).
    ev: f32,
    /// Each view's drawing time in ms.
    render_ms: Vec<f64>,
    /// Each view's glossy shading time in ms (empty without `--brdf`).
    shade_ms: Vec<f64>,
}

/// Draws every view of the orbit of the relit `texture` (with the glossy
/// part of each view's eye, if any) and stages its files in `staged`.
fn draw_views(
    a: &RenderArgs,
    mesh: &TexturedMesh,
    texture: &ltm_relight::Image,
    glossy: Option<&Glossy>,
    camera: &ViewCamera,
    staged: &mut Vec<ltm_codec::AtomicFile>,
) -> Result<Drawn> {
    let mut drawn = Drawn {
        ev: 0.0,
        render_ms: Vec::with_capacity(a.views),
        shade_ms: Vec::new(),
    };
    let mut ev = None;
    for k in 0..a.views {
        let view = camera.orbit(k, a.views);
        mesh.check_outside(view.eye)?;
        let start = Instant::now();
        let shaded = match glossy {
            Some(g) => Some(g.texture(texture, view.eye)?),
            None => None,
        };
        if shaded.is_some() {
            drawn.shade_ms.push(start.elapsed().as_secs_f64() * 1e3);
        }
        let start = Instant::now();
        let image = mesh.render(shaded.as_ref().unwrap_or(texture), &view, a.supersample)?;
        drawn.render_ms.push(start.elapsed().as_secs_f64() * 1e3);
        let view_ev = *ev.get_or_insert_with(|| a.out.ev(&image));
        let exr = numbered(&a.out.output, k, a.views);
        let png = a.out.png.as_ref().map(|p| numbered(p, k, a.views));
        staged.extend(a.out.stage(&image, &exr, png.as_deref(), view_ev)?);
    }
    drawn.ev = ev.unwrap_or(0.0);
    Ok(drawn)
}

/// The files [`numbered`] names for `count` views: `PATH`, or the first
/// and last numbered ones.
fn written(path: &Path, count: usize) -> String {
    match count {
        1 => path.display().to_string(),
        _ => format!(
            "{} ... {}",
            numbered(path, 0, count).display(),
            numbered(path, count - 1, count).display()
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_are_parsed_and_checked() {
        assert_eq!(vec3("1,-2.5, 3").unwrap(), DVec3::new(1.0, -2.5, 3.0));
        for bad in ["1,2", "1,2,3,4", "nan,0,0", "1,x,2", "inf,0,0"] {
            assert!(vec3(bad).is_err(), "{bad}");
        }
        assert_eq!(size("640x480"), Ok((640, 480)));
        assert_eq!(size("64"), Ok((64, 64)));
        for bad in ["0x10", "10x", "99999x2"] {
            assert!(size(bad).is_err(), "{bad}");
        }
        assert_eq!(
            numbered(Path::new("a/v.exr"), 3, 8),
            Path::new("a/v-003.exr")
        );
        assert_eq!(numbered(Path::new("v.exr"), 0, 1), Path::new("v.exr"));
        assert!(views("0").is_err() && views("3601").is_err() && views("4").is_ok());
    }
}
