//! `ltm relight --area-light`: near-field textured area lights in the
//! file's light plane (the scene's `[light_plane]`), relit from the file's
//! near-field rows (`ltm_relight::nearfield::NearField`).

use anyhow::{bail, Context, Result};
use clap::Args;
use ltm_codec::{Limits, LtmFile};
use ltm_relight::nearfield::{
    AreaLight, LightTexture, NearField, NearFieldMethod, NearFieldTerms, Placement, Targets,
    MAX_TEXTURE_SIDE,
};
use ltm_relight::Image;
use std::path::Path;
use std::time::{Duration, Instant};

/// Area lights of `ltm relight`.
#[derive(Args, Clone, Debug)]
pub struct AreaArgs {
    /// A textured area light in the file's light plane (the `[light_plane]`
    /// of its scene; the file must come from such a bake): an EXR or PNG
    /// image of its radiance as seen from the lit side (top row at the
    /// plane's +y edge, left column at its −x edge; PNG is read as sRGB and
    /// made linear), or `uniform` for radiance 1. Repeatable: the lights
    /// add. Each is placed by --area-center, --area-size, --area-angle and
    /// --area-intensity, each given once for every light or once per light
    /// in order. Only the part of each row's view inside its light-plane
    /// face (`side` in the scene) is lit: light arriving at more than
    /// atan(side/2) from the plane's normal is left out.
    #[arg(long = "area-light", value_name = "TEXTURE")]
    pub area_light: Vec<String>,
    /// Centre of the light in the plane's coordinates (along its x and y
    /// axes from its origin), finite. Default 0,0.
    #[arg(long = "area-center", value_name = "X,Y", value_parser = crate::common::ranges::pair, allow_hyphen_values = true)]
    pub area_center: Vec<[f64; 2]>,
    /// Side lengths of the light along the plane's x and y axes (before
    /// --area-angle), finite and > 0. Default 1,1.
    #[arg(long = "area-size", value_name = "W,H", value_parser = crate::common::ranges::pair)]
    pub area_size: Vec<[f64; 2]>,
    /// Turns the light about its centre in the plane, counter-clockwise
    /// seen from the lit side, by any angle in degrees. Multiples of 90
    /// turn the texture exactly; other angles resample it onto the turned
    /// light's bounding rectangle (4 × 4 samples per texel, texels as
    /// large as the texture's). Default 0.
    #[arg(long = "area-angle", value_name = "DEG", allow_hyphen_values = true)]
    pub area_angle: Vec<f64>,
    /// Radiance scale of the light: I, or R,G,B; finite and >= 0. Default 1.
    #[arg(long = "area-intensity", value_name = "I", value_parser = crate::common::ranges::intensity)]
    pub area_intensity: Vec<[f32; 3]>,
    /// How each row's light is computed. `exact` (the default) integrates
    /// the light's texture over every face texel it covers: nothing is
    /// truncated, and the time grows with how much of the face the light
    /// covers. `wavelet` is the affine wavelet propagation of Sun and
    /// Ramamoorthi 2009 with the texture at the face's order and the terms
    /// of --area-source-terms and --area-target-terms.
    #[arg(long = "area-method", value_name = "METHOD", value_enum, default_value_t = AreaMethod::Exact)]
    pub area_method: AreaMethod,
    /// With --area-method wavelet: share (0, 1] of each light's Haar
    /// coefficients kept (its largest), the source-level truncation.
    /// Default 0.05 (5 %).
    #[arg(long = "area-source-terms", value_name = "SHARE", value_parser = crate::common::ranges::share)]
    pub area_source_terms: Option<f64>,
    /// With --area-method wavelet: share (0, 1] of each row's incident
    /// coefficients computed (those a constant light of the same rectangle
    /// predicts to be largest), the target-level selection. Default 0.3
    /// (30 %).
    #[arg(long = "area-target-terms", value_name = "SHARE", value_parser = crate::common::ranges::share)]
    pub area_target_terms: Option<f64>,
}

/// `--area-method`.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum AreaMethod {
    /// Exact integrals of the light over each face texel.
    Exact,
    /// The truncated affine wavelet propagation.
    Wavelet,
}

/// The `k`-th value of a repeatable setting: its only value, its `k`-th, or
/// `default` when not given.
fn nth<T: Copy>(values: &[T], k: usize, lights: usize, flag: &str, default: T) -> Result<T> {
    match values.len() {
        0 => Ok(default),
        1 => Ok(values[0]),
        n if n == lights => Ok(values[k]),
        n => {
            bail!("{n} {flag} given for {lights} --area-light: give one for all, or one per light")
        }
    }
}

impl AreaArgs {
    /// Whether any area light is given.
    pub fn any(&self) -> bool {
        !self.area_light.is_empty()
    }

    /// The texture files the lights read (inputs no output may replace).
    pub fn inputs(&self) -> Vec<(&'static str, &Path)> {
        self.area_light
            .iter()
            .filter(|s| s.as_str() != "uniform")
            .map(|s| ("--area-light", Path::new(s)))
            .collect()
    }

    /// The lights of the command line, placed.
    pub fn lights(&self, limits: &Limits) -> Result<Vec<AreaLight>> {
        let n = self.area_light.len();
        (0..n)
            .map(|k| {
                let spec = &self.area_light[k];
                let angle = nth(&self.area_angle, k, n, "--area-angle", 0.0)?;
                let rgb = nth(&self.area_intensity, k, n, "--area-intensity", [1.0; 3])?;
                let center = nth(&self.area_center, k, n, "--area-center", [0.0; 2])?;
                let size = nth(&self.area_size, k, n, "--area-size", [1.0; 2])?;
                let (texture, size) = turned(read_texture(spec, rgb, limits)?, size, angle)
                    .with_context(|| format!("--area-light {spec}"))?;
                let placement = Placement {
                    center,
                    size,
                    intensity: 1.0,
                };
                placement
                    .check()
                    .with_context(|| format!("--area-light {spec}"))?;
                Ok(AreaLight { texture, placement })
            })
            .collect()
    }

    /// The method of the command line: an error when terms are given for
    /// the exact method.
    pub fn method(&self) -> Result<NearFieldMethod> {
        if self.area_method == AreaMethod::Exact {
            if self.area_source_terms.is_some() || self.area_target_terms.is_some() {
                bail!("--area-source-terms and --area-target-terms apply to --area-method wavelet (the exact method truncates nothing)");
            }
            return Ok(NearFieldMethod::Exact);
        }
        let target = self.area_target_terms.unwrap_or(0.3);
        Ok(NearFieldMethod::Wavelet(NearFieldTerms {
            source: self.area_source_terms.unwrap_or(0.05),
            targets: if target >= 1.0 {
                Targets::All
            } else {
                Targets::Share(target)
            },
        }))
    }
}

/// How `method` is named in messages.
pub fn method_name(method: NearFieldMethod) -> String {
    match method {
        NearFieldMethod::Wavelet(t) => {
            let target = match t.targets {
                Targets::Share(s) => s,
                _ => 1.0,
            };
            format!(
                "wavelet: {:.0} % of the source terms, {:.0} % of the target terms",
                100.0 * t.source,
                100.0 * target
            )
        }
        _ => "exact".into(),
    }
}

/// The texture of `spec` (a path or `uniform`) as the light's texels (row
/// 0 at the plane's −y edge), each scaled by `rgb`.
pub fn read_texture(spec: &str, rgb: [f32; 3], limits: &Limits) -> Result<LightTexture> {
    if spec == "uniform" {
        return Ok(LightTexture::constant(rgb)?);
    }
    let path = Path::new(spec);
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default();
    let (width, height, rows) = match ext.as_str() {
        "exr" => {
            let image = Image::read_exr(path)?;
            (image.width, image.height, image.data)
        }
        "png" => {
            let image = image::open(path)
                .with_context(|| format!("reading {}", path.display()))?
                .to_rgb32f();
            let decode = |v: f32| {
                if v <= 0.04045 {
                    v / 12.92
                } else {
                    ((v + 0.055) / 1.055).powf(2.4)
                }
            };
            let (w, h) = (image.width() as usize, image.height() as usize);
            let data = image.pixels().map(|p| p.0.map(decode)).collect();
            (w, h, data)
        }
        _ => bail!(
            "{}: an area light's texture is read from .exr or .png (or give `uniform`)",
            path.display()
        ),
    };
    if width > MAX_TEXTURE_SIDE || height > MAX_TEXTURE_SIDE {
        bail!(
            "{}: {width}x{height} texels (valid: sides 1..={MAX_TEXTURE_SIDE})",
            path.display()
        );
    }
    let _charge = limits.check_alloc("area light texture", (width * height) as u64, 12)?;
    // Images list their top row first; the light's texels start at −y.
    let texels = rows
        .chunks_exact(width.max(1))
        .rev()
        .flatten()
        .map(|t| [0, 1, 2].map(|c| t[c] * rgb[c]))
        .collect();
    Ok(LightTexture::new(width, height, texels)?)
}

/// The texture and size of a light turned by `angle` degrees about its
/// centre: exactly for a multiple of 90°, else resampled onto the turned
/// light's bounding rectangle ([`LightTexture::rotated`]).
pub fn turned(
    texture: LightTexture,
    size: [f64; 2],
    angle: f64,
) -> Result<(LightTexture, [f64; 2])> {
    let quarter = angle / 90.0;
    if !quarter.is_finite() {
        bail!("--area-angle {angle} is not finite");
    }
    if quarter.fract() != 0.0 {
        return Ok(texture.rotated(size, angle)?);
    }
    let turns = quarter.rem_euclid(4.0) as usize;
    let (mut texture, mut size) = (texture, size);
    for _ in 0..turns {
        texture = quarter_turn(&texture)?;
        size = [size[1], size[0]];
    }
    Ok((texture, size))
}

/// The texture turned 90° counter-clockwise seen from the lit side: texel
/// `(i, j)` (column along x, row along y) of the new one is texel
/// `(j, H − 1 − i)` of the old.
fn quarter_turn(t: &LightTexture) -> Result<LightTexture> {
    let (w, h) = (t.width(), t.height());
    let texels = (0..w)
        .flat_map(|j| (0..h).map(move |i| t.texel(j, h - 1 - i)))
        .collect();
    Ok(LightTexture::new(h, w, texels)?)
}

/// The near-field image of `lights` from `path`'s near-field rows, and the
/// time it took (propagation and shading).
pub fn render(
    path: &Path,
    lights: &[AreaLight],
    method: NearFieldMethod,
    limits: &Limits,
) -> Result<(Vec<[f32; 3]>, Duration)> {
    let mut file = LtmFile::open_with_limits(path, limits)
        .with_context(|| format!("opening {}", path.display()))?;
    let near = NearField::take(&mut file, limits).with_context(|| format!("{}", path.display()))?;
    drop(file);
    let start = Instant::now();
    let image = near.render(lights, method)?;
    Ok((image, start.elapsed()))
}
