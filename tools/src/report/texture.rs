//! Geometry relighting in the report (Cheslack-Postava et al. 2007 §4.2):
//! for a texture-space matrix, the adaptive file of the equal-quality pair
//! is relit into its texture under the first map, and the relit mesh is
//! drawn from two sides (front and back of an orbit) from that one relight.
//! The figures are the paper's Fig. 10 pair: frame time of the relight
//! alone, and of the relight plus one view.

use crate::common::Ctx;
use anyhow::{Context, Result};
use glam::DVec3;
use ltm_relight::{Relight, Relighter, Request, TexturedMesh, ViewCamera, Weighting};
use serde::{Deserialize, Serialize};
use std::path::Path;
use std::time::Instant;

/// Side of the views drawn and timed.
pub const VIEW_SIDE: u32 = 512;
/// Supersampling of the views (per axis).
const SUPERSAMPLE: u32 = 2;
/// Wavelet lights of the timed relight (the paper's Fig. 10 uses 256).
pub const TERMS: usize = 256;

/// What the report measured on a texture-space file.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TexturePoint {
    /// The file relit (relative to the report).
    pub file: String,
    /// The map it was relit under.
    pub env: String,
    /// Wavelet lights used.
    pub terms: usize,
    /// Texture side S.
    pub texture_side: u32,
    /// Triangles of the geometry-image mesh.
    pub triangles: usize,
    /// Median relight of the texture, ms.
    pub relight_ms: f64,
    /// Median relight plus one `VIEW_SIDE`² view, ms.
    pub relight_view_ms: f64,
    /// The relit texture and the views, PNG, relative to the report.
    pub images: Vec<String>,
}

/// Relights `file` (a texture-space `.ltm` in `dir/files`) under `light`,
/// times `frames` relights alone and with one view, and writes
/// `texture.png`, `view-front.png` and `view-back.png` into `dir`.
pub fn measure(
    dir: &Path,
    file: &Path,
    (env, light): (&str, &[[f32; 3]]),
    frames: usize,
    ctx: &Ctx,
) -> Result<TexturePoint> {
    let relighter = Relighter::open_with_limits(file, ctx.limits())
        .with_context(|| format!("opening {}", file.display()))?;
    // Frame times below are of frames alone, with every column decoded.
    relighter.decode_all()?;
    let mesh = TexturedMesh::from_file(relighter.file(), ctx.limits())?;
    let camera = framing_camera(&mesh)?;
    let request = Request {
        terms: TERMS.min(relighter.lights()),
        weighting: Weighting::Transport,
    };
    let mut frame = relighter.frame()?;
    let (mut alone, mut with_view) = (Vec::new(), Vec::new());
    for _ in 0..frames.max(1) {
        let t = Instant::now();
        relighter.relight(light, &request, &mut frame)?;
        alone.push(t.elapsed().as_secs_f64() * 1e3);
        let t = Instant::now();
        relighter.relight(light, &request, &mut frame)?;
        mesh.render(&frame.image, &camera, SUPERSAMPLE)?;
        with_view.push(t.elapsed().as_secs_f64() * 1e3);
    }
    let mut images = vec!["texture.png".to_string()];
    frame.image.write_png(&dir.join(&images[0]), 0.0)?;
    for (k, name) in ["view-front.png", "view-back.png"].into_iter().enumerate() {
        let view = camera.orbit(k, 2);
        mesh.check_outside(view.eye)?;
        let image = mesh.render(&frame.image, &view, SUPERSAMPLE)?;
        image.write_png(&dir.join(name), 0.0)?;
        images.push(name.to_string());
    }
    Ok(TexturePoint {
        file: format!(
            "files/{}",
            file.file_name().unwrap_or_default().to_string_lossy()
        ),
        env: env.to_string(),
        terms: request.terms,
        texture_side: mesh.size() as u32,
        triangles: mesh.triangle_count(),
        relight_ms: super::median(alone),
        relight_view_ms: super::median(with_view),
        images,
    })
}

/// A camera that frames the mesh: looking at its bounding box's centre from
/// the front (+z), a little above, far enough that the box's bounding
/// sphere fits a 30° view.
fn framing_camera(mesh: &TexturedMesh) -> Result<ViewCamera> {
    let (lo, hi) = mesh
        .bounds()
        .context("the geometry image has no valid texel to draw")?;
    let (centre, radius) = ((lo + hi) * 0.5, ((hi - lo) * 0.5).length().max(1e-6));
    let fov: f64 = 30.0;
    let distance = 1.1 * radius / (fov.to_radians() * 0.5).sin();
    let camera = ViewCamera {
        eye: centre + DVec3::new(0.0, 0.35, 1.0).normalize() * distance,
        target: centre,
        up: DVec3::Y,
        fov,
        width: VIEW_SIDE,
        height: VIEW_SIDE,
    };
    camera.validate()?;
    Ok(camera)
}
