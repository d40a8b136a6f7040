//! Environment lighting: lat-long maps, their rotation, and their exact
//! area-weighted resampling to the transport matrix's cubemap.
//!
//! # Resampling
//!
//! [`EnvMap::to_cubemap`] gives every cubemap texel the mean radiance of the
//! map over the texel's solid angle, `L[j] = (1/Ω_j) Σ_i A(i ∩ j)·L_i`, where
//! `A(i ∩ j)` is the solid angle shared by map pixel `i` and texel `j`. The
//! overlaps are exact (up to floating-point rounding), not estimated by
//! sampling, so that
//!
//! - a constant map gives the same constant in every texel, and
//! - power is conserved: `Σ_j L[j]·Ω_j = Σ_i L_i·ΔΩ_i`, so a sun smaller than
//!   a texel keeps all of its energy.
//!
//! The overlaps come from Green's theorem in the equal-area coordinates
//! `(φ, z = cos θ)`, in which `dω = dφ·dz` and every map pixel is a
//! rectangle: the area of a region is `−∮ z dφ` around its boundary, so each
//! overlap is a sum of line integrals along the pieces of the two grids'
//! edges (the conservative remapping of Jones 1999, "First- and second-order
//! conservative remapping schemes for grids in spherical coordinates").
//! Pixel edges along meridians contribute nothing, pixel edges along the
//! parallel `z` contribute `z·Δφ`, and a texel edge, an arc of the great
//! circle with unit normal `m`, contributes `∫ z dφ = atan(q_1/m_y) −
//! atan(q_0/m_y)` between its points `d_0`, `d_1`, with `q = (m × d)_y`.
//! Every texel edge is cut where it crosses the map's meridians and
//! parallels, and every parallel where texel edges cross it; each piece
//! then lies in one pixel and borders known texels.
//!
//! The poles are the parametrization's singular points: there the parallel
//! `z = ±1` has length 0 on the sphere but `2π` in the plane. Its pieces
//! belong to the texel holding the pole, or, when the pole lies on texel
//! edges, to the sectors between those edges. A pole closer than 1e-6 texel
//! widths to an edge or corner is taken to lie on it, so that every edge
//! either passes through the pole or stays clear of it (the area moved is
//! below 1e-6 of a texel's).
//!
//! Cost: proportional to the map's pixels plus the texel edges' crossings
//! with the map's grid; about 10 ms for a 1024×512 map at `n = 32` and 25 ms
//! at `n = 64` on one core, parallel over texel edges and parallels.

use crate::error::{RelightError, Result};
#[cfg(feature = "exr")]
use crate::image_io::read_exr_rgb;
use glam::{DMat3, DVec3};
#[cfg(feature = "hdr")]
use image::ImageDecoder;
use ltm_codec::cubemap::{
    direction_face_point, face_point_direction, texel_index, texel_solid_angle,
};
use rayon::prelude::*;
use std::f64::consts::{PI, TAU};
use std::fmt;
#[cfg(any(feature = "exr", feature = "hdr"))]
use std::path::Path;
use std::str::FromStr;

/// The map files this build reads, for [`EnvMap::load`]'s message.
#[cfg(all(feature = "exr", feature = "hdr"))]
const READABLE_FORMATS: &str = ".exr or .hdr file";
#[cfg(all(feature = "exr", not(feature = "hdr")))]
const READABLE_FORMATS: &str = ".exr file (this build reads no .hdr: feature `hdr`)";
#[cfg(all(feature = "hdr", not(feature = "exr")))]
const READABLE_FORMATS: &str = ".hdr file (this build reads no .exr: feature `exr`)";

/// Largest environment map height (the width is twice the height): a
/// `16384 × 8192` map.
pub const MAX_ENV_HEIGHT: usize = 8192;

/// A rotation of the lighting, in degrees.
///
/// The matrix is `R = Rz(roll)·Rx(pitch)·Ry(yaw)` acting on world-space
/// column vectors (Y up): yaw first, then pitch, then roll, each about a
/// fixed world axis and each right-handed:
///
/// - `yaw` about +Y: positive yaw turns the lighting counter-clockwise seen
///   from above; at `yaw = 90` a light at +Z moves to +X;
/// - `pitch` about +X: at `pitch = 90` the zenith (+Y) moves to +Z;
/// - `roll` about +Z: at `roll = 90` a light at +X moves to +Y.
///
/// The map's light from direction `d` arrives from `R·d` after rotation: the
/// rotated lighting is `L'(ω) = L(R⁻¹·ω)`. Angles are taken modulo 360, and
/// multiples of 90 degrees are exact, so `yaw = 360` is the identity. A
/// non-finite angle counts as 0 (parsing refuses them).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Rotation {
    /// Degrees about +Y.
    pub yaw: f64,
    /// Degrees about +X.
    pub pitch: f64,
    /// Degrees about +Z.
    pub roll: f64,
}

impl Rotation {
    /// No rotation.
    pub const IDENTITY: Rotation = Rotation {
        yaw: 0.0,
        pitch: 0.0,
        roll: 0.0,
    };

    /// A rotation from its three angles in degrees.
    pub fn new(yaw: f64, pitch: f64, roll: f64) -> Rotation {
        Rotation { yaw, pitch, roll }
    }

    /// A rotation about +Y only.
    pub fn yaw(yaw: f64) -> Rotation {
        Rotation::new(yaw, 0.0, 0.0)
    }

    /// The matrix `R` (see the type's documentation).
    pub fn matrix(&self) -> DMat3 {
        let (sy, cy) = sin_cos_degrees(self.yaw);
        let (sp, cp) = sin_cos_degrees(self.pitch);
        let (sr, cr) = sin_cos_degrees(self.roll);
        let ry = DMat3::from_cols(DVec3::new(cy, 0.0, -sy), DVec3::Y, DVec3::new(sy, 0.0, cy));
        let rx = DMat3::from_cols(DVec3::X, DVec3::new(0.0, cp, sp), DVec3::new(0.0, -sp, cp));
        let rz = DMat3::from_cols(DVec3::new(cr, sr, 0.0), DVec3::new(-sr, cr, 0.0), DVec3::Z);
        rz * rx * ry
    }

    /// Where the light of the map's direction `d` arrives from after the
    /// rotation: `R·d`.
    pub fn apply(&self, d: DVec3) -> DVec3 {
        self.matrix() * d
    }
}

/// `sin` and `cos` of an angle in degrees, exact at multiples of 90; a
/// non-finite angle counts as 0.
fn sin_cos_degrees(deg: f64) -> (f64, f64) {
    let r = deg.rem_euclid(360.0);
    if r == 0.0 || !r.is_finite() {
        (0.0, 1.0)
    } else if r == 90.0 {
        (1.0, 0.0)
    } else if r == 180.0 {
        (0.0, -1.0)
    } else if r == 270.0 {
        (-1.0, 0.0)
    } else {
        r.to_radians().sin_cos()
    }
}

impl FromStr for Rotation {
    type Err = RelightError;

    /// Parses `YAW,PITCH,ROLL` in degrees; `YAW` or `YAW,PITCH` leave the
    /// missing angles at 0.
    fn from_str(s: &str) -> Result<Rotation> {
        let parts: Vec<&str> = s.split(',').map(str::trim).collect();
        if parts.len() > 3 {
            return Err(RelightError::Invalid(format!(
                "rotation '{s}' has {} values; expected YAW,PITCH,ROLL in degrees",
                parts.len()
            )));
        }
        let mut angles = [0.0f64; 3];
        for (i, part) in parts.iter().enumerate() {
            let v: f64 = part.parse().map_err(|_| {
                RelightError::Invalid(format!(
                    "rotation '{s}': '{part}' is not a number; expected YAW,PITCH,ROLL in degrees"
                ))
            })?;
            if !v.is_finite() {
                return Err(RelightError::range(
                    ["yaw", "pitch", "roll"][i],
                    v,
                    "a finite angle in degrees",
                ));
            }
            angles[i] = v;
        }
        Ok(Rotation::new(angles[0], angles[1], angles[2]))
    }
}

impl fmt::Display for Rotation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{},{},{}", self.yaw, self.pitch, self.roll)
    }
}

/// A lat-long (equirectangular) environment map of linear RGB radiance.
///
/// Pixel `(x, y)` is `data[y·width + x]` and covers
/// `u ∈ [x/W, (x+1)/W]`, `v ∈ [y/H, (y+1)/H]` in the convention of
/// `ltm_codec::cubemap` (docs/FORMAT.md): `u = atan2(d.x, −d.z)/2π`,
/// `v = acos(d.y)/π`, so the top row looks up (+Y), `u = 0` looks down −Z
/// and `u = 0.25` down +X.
///
/// Invariants, checked by every constructor: `width = 2·height`,
/// `2 ≤ height ≤` [`MAX_ENV_HEIGHT`], every value finite and `≥ 0`
/// (negative values, such as lossy compression leaves, are clamped to 0).
///
/// ```
/// use ltm_relight::{EnvMap, Rotation};
///
/// // A sky of radiance 1 with a sun of 1000 in one pixel.
/// let env = EnvMap::from_fn(256, 128, |x, y| {
///     if (x, y) == (40, 30) { [1000.0; 3] } else { [1.0; 3] }
/// })?;
/// // Mean radiance per texel of a 6·8² cubemap, lighting turned 90° about +Y.
/// let light = env.to_cubemap(8, &Rotation::yaw(90.0));
/// assert_eq!(light.len(), 6 * 8 * 8);
/// // Power is conserved: Σ L[j]·Ω_j equals the map's integral.
/// let power: f64 = light
///     .iter()
///     .enumerate()
///     .map(|(j, l)| l[0] as f64 * ltm_codec::cubemap::texel_solid_angle(8, j))
///     .sum();
/// assert!((power / env.power()[0] - 1.0).abs() < 1e-6);
/// # Ok::<(), ltm_relight::RelightError>(())
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct EnvMap {
    width: usize,
    height: usize,
    data: Vec<[f32; 3]>,
}

impl EnvMap {
    /// A map from its pixels (row-major, top row first). Fails on a wrong
    /// shape or a NaN or infinite value (naming the pixel); clamps negative
    /// values to 0.
    pub fn new(width: usize, height: usize, mut data: Vec<[f32; 3]>) -> Result<EnvMap> {
        check_shape(width, height)?;
        if data.len() != width * height {
            return Err(RelightError::InvalidEnvMap(format!(
                "{width}×{height} map holds {} pixels (needs {})",
                data.len(),
                width * height
            )));
        }
        for (i, p) in data.iter_mut().enumerate() {
            for (c, v) in p.iter_mut().enumerate() {
                if !v.is_finite() {
                    return Err(RelightError::InvalidEnvMap(format!(
                        "pixel (x = {}, y = {}) channel {} is {}; radiance must be finite",
                        i % width,
                        i / width,
                        ["R", "G", "B"][c],
                        v
                    )));
                }
                // `max` also turns −0 into +0.
                *v = v.max(0.0) + 0.0;
            }
        }
        Ok(EnvMap {
            width,
            height,
            data,
        })
    }

    /// A map whose pixel `(x, y)` is `f(x, y)`.
    pub fn from_fn(
        width: usize,
        height: usize,
        mut f: impl FnMut(usize, usize) -> [f32; 3],
    ) -> Result<EnvMap> {
        check_shape(width, height)?;
        let data = (0..width * height)
            .map(|i| f(i % width, i / width))
            .collect();
        EnvMap::new(width, height, data)
    }

    /// A map of constant radiance.
    pub fn constant(width: usize, height: usize, rgb: [f32; 3]) -> Result<EnvMap> {
        EnvMap::from_fn(width, height, |_, _| rgb)
    }

    /// Loads a lat-long map: OpenEXR (`.exr`: the first layer with R, G and
    /// B channels, any sample type and compression) or Radiance HDR (`.hdr`,
    /// `.pic`). The shape must be `width = 2·height` with `height ≥ 2`.
    /// Negative values are clamped to 0; NaN or infinite values are an
    /// error naming the pixel. Each format needs its feature (`exr`, `hdr`;
    /// both on by default).
    #[cfg(any(feature = "exr", feature = "hdr"))]
    pub fn load(path: &Path) -> Result<EnvMap> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase)
            .unwrap_or_default();
        let (width, height, data) = match ext.as_str() {
            #[cfg(feature = "exr")]
            "exr" => read_exr_rgb(path)?,
            #[cfg(feature = "hdr")]
            "hdr" | "pic" => read_hdr(path)?,
            _ => {
                return Err(RelightError::Invalid(format!(
                    "{}: unsupported environment map format (expected a lat-long {})",
                    path.display(),
                    READABLE_FORMATS
                )))
            }
        };
        EnvMap::new(width, height, data).map_err(|e| match e {
            RelightError::InvalidEnvMap(m) => {
                RelightError::InvalidEnvMap(format!("{}: {m}", path.display()))
            }
            other => other,
        })
    }

    /// Width in pixels (`2·height`).
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> usize {
        self.height
    }

    /// The pixels, row-major from the top.
    pub fn data(&self) -> &[[f32; 3]] {
        &self.data
    }

    /// Pixel `(x, y)`, or `None` outside the map.
    pub fn pixel(&self, x: usize, y: usize) -> Option<[f32; 3]> {
        (x < self.width && y < self.height).then(|| self.data[y * self.width + x])
    }

    /// Exact solid angle of a pixel of row `y`:
    /// `Δφ·(cos θ_y − cos θ_(y+1))` with `Δφ = 2π/W`, `θ_y = π·y/H`.
    pub fn pixel_solid_angle(&self, y: usize) -> f64 {
        let z = |k: usize| parallel_z(k, self.height);
        TAU / self.width as f64 * (z(y) - z(y + 1))
    }

    /// The direction through the centre of pixel `(x, y)`.
    pub fn pixel_direction(&self, x: usize, y: usize) -> DVec3 {
        ltm_codec::cubemap::latlong_direction(
            (x as f64 + 0.5) / self.width as f64,
            (y as f64 + 0.5) / self.height as f64,
        )
    }

    /// The integral of the radiance over the sphere, `Σ_pixels L·ΔΩ`, per
    /// channel (the irradiance-weighted "power" that resampling conserves).
    pub fn power(&self) -> [f64; 3] {
        let mut total = [0.0f64; 3];
        for y in 0..self.height {
            let omega = self.pixel_solid_angle(y);
            let mut row = [0.0f64; 3];
            for p in &self.data[y * self.width..(y + 1) * self.width] {
                for c in 0..3 {
                    row[c] += p[c] as f64;
                }
            }
            for c in 0..3 {
                total[c] += row[c] * omega;
            }
        }
        total
    }

    /// The mean radiance over every texel of a cubemap of face resolution
    /// `n` (`6·n²` values in the column order of docs/FORMAT.md), with the
    /// lighting rotated by `rotation`. Exact area-weighted integration (see
    /// the module documentation); parallel over rayon's pool.
    ///
    /// `n` is the face resolution of a transport matrix (1..=1024); `n = 0`
    /// gives an empty vector.
    pub fn to_cubemap(&self, n: usize, rotation: &Rotation) -> Vec<[f32; 3]> {
        if n == 0 {
            return Vec::new();
        }
        let energy = Remap::new(self, n, rotation).energy();
        energy
            .iter()
            .enumerate()
            .map(|(j, e)| {
                let omega = texel_solid_angle(n, j);
                e.map(|v| (v.max(0.0) / omega) as f32)
            })
            .collect()
    }
}

fn check_shape(width: usize, height: usize) -> Result<()> {
    if height < 2 || width != 2 * height || height > MAX_ENV_HEIGHT {
        let why = if height < 2 {
            "the height must be at least 2".to_string()
        } else if height > MAX_ENV_HEIGHT {
            format!("the height must be at most {MAX_ENV_HEIGHT}")
        } else {
            format!(
                "the aspect ratio is {:.3}:1, not 2:1 (cube crosses and other layouts are not supported)",
                width as f64 / height as f64
            )
        };
        return Err(RelightError::InvalidEnvMap(format!(
            "{width}×{height} pixels: a lat-long map needs width = 2·height and 2 ≤ height ≤ {MAX_ENV_HEIGHT} (e.g. 1024×512); {why}"
        )));
    }
    Ok(())
}

/// Reads a Radiance HDR file as RGB f32, checking its size before
/// allocating.
#[cfg(feature = "hdr")]
fn read_hdr(path: &Path) -> Result<(usize, usize, Vec<[f32; 3]>)> {
    let file = std::fs::File::open(path).map_err(|e| RelightError::io(path, e))?;
    let decoder = image::codecs::hdr::HdrDecoder::new(std::io::BufReader::new(file))
        .map_err(|e| RelightError::image(path, format!("Radiance HDR: {e}")))?;
    let (w, h) = decoder.dimensions();
    let (width, height) = (w as usize, h as usize);
    check_shape(width, height)
        .map_err(|e| RelightError::InvalidEnvMap(format!("{}: {e}", path.display())))?;
    let mut bytes = vec![0u8; width * height * 12];
    if decoder.total_bytes() != bytes.len() as u64 {
        return Err(RelightError::image(
            path,
            "Radiance HDR: unexpected pixel format".to_string(),
        ));
    }
    decoder
        .read_image(&mut bytes)
        .map_err(|e| RelightError::image(path, format!("Radiance HDR: {e}")))?;
    let f = |b: &[u8]| f32::from_ne_bytes([b[0], b[1], b[2], b[3]]);
    let data = bytes
        .chunks_exact(12)
        .map(|p| [f(&p[0..4]), f(&p[4..8]), f(&p[8..12])])
        .collect();
    Ok((width, height, data))
}

/// `z = cos θ` of parallel `k` (the top edge of pixel row `k`), exact at the
/// poles.
fn parallel_z(k: usize, height: usize) -> f64 {
    if k == 0 {
        1.0
    } else if k >= height {
        -1.0
    } else {
        (PI * k as f64 / height as f64).cos()
    }
}

/// `φ = 2π·u ∈ [0, 2π]` of a direction.
fn phi_of(d: DVec3) -> f64 {
    let p = d.x.atan2(-d.z);
    if p < 0.0 {
        (p + TAU).min(TAU)
    } else {
        p
    }
}

/// `atan2(y, x)`, by its series when `|y| ≤ x/16` (the line integral of a
/// short piece of arc), to full double precision.
fn atan2_short(y: f64, x: f64) -> f64 {
    if x > 0.0 && y.abs() <= 0.0625 * x {
        // atan r = r − r³/3 + r⁵/5 − …; with |r| ≤ 1/16 the terms past r¹⁷
        // are below 2⁻⁶⁴ of the sum.
        let r = y / x;
        let r2 = r * r;
        let mut s = 1.0 / 17.0;
        for k in (0..8).rev() {
            let c = 1.0 / (2 * k + 1) as f64;
            s = c - r2 * s;
        }
        r * s
    } else {
        y.atan2(x)
    }
}

/// `acos(z)` within 1e-4 (Abramowitz & Stegun 4.4.45), clamped to `[−1, 1]`.
fn acos_approx(z: f64) -> f64 {
    let a = z.abs().min(1.0);
    let f =
        (1.0 - a).sqrt() * (1.570_728_8 + a * (-0.212_114_4 + a * (0.074_261 - a * 0.018_729_3)));
    if z < 0.0 {
        PI - f
    } else {
        f
    }
}

/// A pole closer than this (in texel widths) to a line of texel edges is
/// moved onto it, and onto a texel corner likewise: every edge then either
/// passes exactly through the pole or stays well away from it, so that the
/// pole's texels are decided consistently. The area moved is below 1e-12 sr.
const SNAP: f64 = 1e-6;
/// An edge passes through a (snapped) pole when the pole lies within this
/// of its great circle and of its extent (rounding only: any other edge is
/// at least `SNAP` texel widths away).
const THROUGH_TOL: f64 = 1e-12;
/// Slack on the arc parameter of crossings found just outside an arc's ends.
const CROSS_KEY_TOL: f64 = 5e-13;

/// A pole `e` (map frame) moved onto the line of texel edges or the texel
/// corner it lies within `SNAP` texel widths of, or `None` when it lies
/// well inside a texel.
fn snapped_pole(n: usize, rot: DMat3, e: DVec3) -> Option<DVec3> {
    let (face, s, t) = direction_face_point(rot * e);
    let nf = n as f64;
    let snap = |x: f64| {
        let r = (x * nf).round();
        ((x * nf - r).abs() < SNAP).then_some(r / nf)
    };
    let (ss, ts) = (snap(s), snap(t));
    if ss.is_none() && ts.is_none() {
        return None;
    }
    let world = face_point_direction(face, ss.unwrap_or(s), ts.unwrap_or(t));
    Some((rot.transpose() * world).normalize())
}

/// A texel edge meeting a pole: its direction away from the pole, as `φ`,
/// and the texel on its side of increasing `φ`.
#[derive(Clone, Copy)]
struct Ray {
    pole: u8,
    phi: f64,
    texel_after: u32,
}

/// A point where an arc is cut: its parameter `key = tan(t/2)` (increasing
/// along the arc), its direction and its `φ`.
#[derive(Clone, Copy)]
struct Cut {
    key: f64,
    d: DVec3,
    phi: f64,
}

/// Per-thread accumulators and scratch space.
struct Acc {
    energy: Vec<[f64; 3]>,
    crossings: Vec<(u32, f64)>,
    rays: Vec<Ray>,
    cuts: Vec<Cut>,
    line: Vec<(DVec3, f64)>,
    beside: Vec<DVec3>,
}

impl Acc {
    fn new(texels: usize) -> Acc {
        Acc {
            energy: vec![[0.0; 3]; texels],
            crossings: Vec::new(),
            rays: Vec::new(),
            cuts: Vec::new(),
            line: Vec::new(),
            beside: Vec::new(),
        }
    }

    fn add(&mut self, texel: u32, w: f64, l: [f64; 3]) {
        let e = &mut self.energy[texel as usize];
        for c in 0..3 {
            e[c] += w * l[c];
        }
    }
}

/// One texel edge: the great-circle arc from `p` to `q` (map frame, with
/// their `φ`) between texels `ta` and `tb`, `side_a` telling whether `ta`
/// lies on the side of `p × q`.
struct Arc {
    p: DVec3,
    q: DVec3,
    phi_p: f64,
    phi_q: f64,
    ta: u32,
    tb: u32,
    side_a: bool,
}

/// The great circle of an arc: its unit normal `m`, and `u = m × p`, so
/// that the arc's points are `p·cos t + u·sin t`, `t ∈ [0, α]`, ordered by
/// `key = tan(t/2)` from 0 to `key_end`.
struct ArcFrame {
    p: DVec3,
    m: DVec3,
    u: DVec3,
    key_end: f64,
}

impl ArcFrame {
    /// `None` for a degenerate arc (zero length, or antipodal ends).
    fn new(arc: &Arc) -> Option<ArcFrame> {
        let (p, q) = (arc.p, arc.q);
        let cross = p.cross(q);
        let sin_a = cross.length();
        if sin_a.is_nan() || sin_a <= 0.0 || p.dot(q) <= -1.0 + 1e-12 {
            return None;
        }
        let m = cross / sin_a;
        let mut g = ArcFrame {
            p,
            m,
            u: m.cross(p),
            key_end: 0.0,
        };
        g.key_end = g.key(q);
        Some(g)
    }

    /// The position of `d` along the arc's great circle.
    fn key(&self, d: DVec3) -> f64 {
        d.dot(self.u) / (1.0 + d.dot(self.p))
    }

    /// Whether a key lies on the arc.
    fn inside(&self, k: f64) -> bool {
        (0.0..=self.key_end).contains(&k)
    }
}

/// One resampling: the map, the cubemap resolution and the rotation.
struct Remap<'a> {
    env: &'a EnvMap,
    n: usize,
    /// Map frame → world (where the light arrives from).
    rot: DMat3,
    /// World → map frame.
    inv: DMat3,
    /// `z` of parallels `0..=H`.
    z: Vec<f64>,
    /// `sin θ` of parallels `0..=H`.
    r: Vec<f64>,
    /// `(cos φ, sin φ)` of meridians `0..W`.
    meridians: Vec<(f64, f64)>,
    /// North and south pole (map frame), moved onto the texel edge or
    /// corner they lie within `SNAP` of; `None` for a pole inside a texel.
    poles: [Option<DVec3>; 2],
}

impl<'a> Remap<'a> {
    fn new(env: &'a EnvMap, n: usize, rotation: &Rotation) -> Remap<'a> {
        let rot = rotation.matrix();
        let (w, h) = (env.width, env.height);
        Remap {
            env,
            n,
            rot,
            inv: rot.transpose(),
            z: (0..=h).map(|k| parallel_z(k, h)).collect(),
            r: (0..=h)
                .map(|k| {
                    if k == 0 || k == h {
                        0.0
                    } else {
                        (PI * k as f64 / h as f64).sin()
                    }
                })
                .collect(),
            poles: [DVec3::Y, DVec3::NEG_Y].map(|e| snapped_pole(n, rot, e)),
            meridians: (0..w)
                .map(|x| {
                    let (s, c) = sin_cos_degrees(360.0 * x as f64 / w as f64);
                    (c, s)
                })
                .collect(),
        }
    }

    fn texels(&self) -> usize {
        6 * self.n * self.n
    }

    /// Radiance of pixel `(x, y)` in f64.
    fn radiance(&self, x: usize, y: usize) -> [f64; 3] {
        self.env.data[y * self.env.width + x].map(f64::from)
    }

    /// The pixel row whose band `[z_(y+1), z_y]` holds `z`.
    fn row_of(&self, z: f64) -> usize {
        let h = self.env.height;
        let mut y = ((acos_approx(z) / PI * h as f64) as usize).min(h - 1);
        while y > 0 && z > self.z[y] {
            y -= 1;
        }
        while y + 1 < h && z < self.z[y + 1] {
            y += 1;
        }
        y
    }

    /// The texel a world direction falls in.
    fn world_texel(&self, w: DVec3) -> u32 {
        let n = self.n;
        let (face, s, t) = direction_face_point(w);
        let col = ((s * n as f64) as usize).min(n - 1);
        let row = ((t * n as f64) as usize).min(n - 1);
        texel_index(n, face, row, col) as u32
    }

    /// The texel a map-frame direction falls in after rotation.
    fn env_texel(&self, d: DVec3) -> u32 {
        self.world_texel(self.rot * d)
    }

    /// Map-frame direction of face point `(s, t)`.
    fn env_point(&self, face: usize, s: f64, t: f64) -> DVec3 {
        (self.inv * face_point_direction(face, s, t)).normalize()
    }

    /// The energy `Σ_i A(i ∩ j)·L_i` of every texel.
    fn energy(&self) -> Vec<[f64; 3]> {
        let texels = self.texels();
        let h = self.env.height;
        // One accumulator per thread (at most 1 GiB of them); work is
        // interleaved for balance.
        let budget = (1usize << 30) / (texels * 24).max(1);
        let chunks = rayon::current_num_threads().clamp(1, budget.clamp(1, 64));

        // Texel edges: 6 faces × 2 directions × (n + 1) lines of n arcs.
        let lines = 6 * 2 * (self.n + 1);
        let mut accs: Vec<Acc> = (0..chunks)
            .into_par_iter()
            .map(|c| {
                let mut acc = Acc::new(texels);
                for line in (c..lines).step_by(chunks) {
                    self.edge_line(line, &mut acc);
                }
                acc
            })
            .collect();

        // The crossings of each parallel, grouped by parallel.
        let mut starts = vec![0usize; h + 2];
        for acc in &accs {
            for &(k, _) in &acc.crossings {
                starts[k as usize + 1] += 1;
            }
        }
        for k in 0..=h {
            starts[k + 1] += starts[k];
        }
        let mut phis = vec![0.0f64; starts[h + 1]];
        let mut next = starts.clone();
        let mut rays: Vec<Ray> = Vec::new();
        for acc in &mut accs {
            for &(k, phi) in &acc.crossings {
                phis[next[k as usize]] = phi;
                next[k as usize] += 1;
            }
            acc.crossings = Vec::new();
            rays.append(&mut acc.rays);
        }
        rays.sort_unstable_by(|a, b| a.phi.total_cmp(&b.phi));

        // Parallels 0..=H, each split at its crossings and the meridians.
        let mut slices: Vec<&mut [f64]> = Vec::with_capacity(h + 1);
        let mut rest = phis.as_mut_slice();
        for k in 0..=h {
            let (head, tail) = rest.split_at_mut(starts[k + 1] - starts[k]);
            slices.push(head);
            rest = tail;
        }
        let mut groups: Vec<Vec<(usize, &mut [f64])>> = (0..chunks).map(|_| Vec::new()).collect();
        for (k, phis) in slices.into_iter().enumerate() {
            groups[k % chunks].push((k, phis));
        }
        accs.par_iter_mut().zip(groups).for_each(|(acc, group)| {
            for (k, phis) in group {
                phis.sort_unstable_by(f64::total_cmp);
                self.parallel(k, phis, &rays, acc);
            }
        });

        let mut total = vec![[0.0f64; 3]; texels];
        for acc in &accs {
            for (t, e) in total.iter_mut().zip(&acc.energy) {
                for c in 0..3 {
                    t[c] += e[c];
                }
            }
        }
        total
    }

    /// Processes the arcs of one line of texel edges: `line` indexes
    /// (face, direction, line) with lines `t = i/n` (direction 0) and
    /// `s = i/n` (direction 1). Edges on a face boundary are processed by
    /// the face whose texel has the lower index.
    fn edge_line(&self, line: usize, acc: &mut Acc) {
        let n = self.n;
        let nf = n as f64;
        let face = line / (2 * (n + 1));
        let dir = (line / (n + 1)) % 2;
        let i = line % (n + 1);
        // (s, t) of the point at coordinate `b` along line `a`.
        let st = |b: f64, a: f64| if dir == 0 { (b, a) } else { (a, b) };
        let texel_at = |i: usize, seg: usize| {
            (if dir == 0 {
                texel_index(n, face, i, seg)
            } else {
                texel_index(n, face, seg, i)
            }) as u32
        };
        // The corners on this line, and on the next line inside the face
        // (corners of the texels on one side, off this line).
        let beside = if i > 0 { i - 1 } else { 1 };
        acc.line.clear();
        acc.beside.clear();
        for c in 0..=n {
            let (s, t) = st(c as f64 / nf, i as f64 / nf);
            let d = self.env_point(face, s, t);
            acc.line.push((d, phi_of(d)));
            let (s, t) = st(c as f64 / nf, beside as f64 / nf);
            acc.beside.push(self.env_point(face, s, t));
        }
        let outside = 0.25 / nf;
        for seg in 0..n {
            let bm = (seg as f64 + 0.5) / nf;
            // The texels before (line i − 1 side) and after the line.
            let (ta, tb) = if i == 0 || i == n {
                let (s, t) = st(bm, if i == 0 { -outside } else { 1.0 + outside });
                let other = self.world_texel(face_point_direction(face, s, t));
                let own = texel_at(if i == 0 { 0 } else { n - 1 }, seg);
                if own > other {
                    continue;
                }
                if i == 0 {
                    (other, own)
                } else {
                    (own, other)
                }
            } else {
                (texel_at(i - 1, seg), texel_at(i, seg))
            };
            let ((p, phi_p), (q, phi_q)) = (acc.line[seg], acc.line[seg + 1]);
            // `beside[seg]` is a corner of texel `ta` (i > 0) or `tb`.
            let side = p.cross(q).dot(acc.beside[seg]) > 0.0;
            let side_a = if i > 0 { side } else { !side };
            let arc = Arc {
                p,
                q,
                phi_p,
                phi_q,
                ta,
                tb,
                side_a,
            };
            self.arc(&arc, acc);
        }
    }

    /// Adds one texel edge's line integrals, records where it crosses the
    /// parallels, and where it meets a pole.
    fn arc(&self, arc: &Arc, acc: &mut Acc) {
        let Some(g) = ArcFrame::new(arc) else {
            return;
        };
        let touches = self.pole_rays(arc, &g, acc);
        acc.cuts.clear();
        acc.cuts.push(Cut {
            key: 0.0,
            d: arc.p,
            phi: arc.phi_p,
        });
        acc.cuts.push(Cut {
            key: g.key_end,
            d: arc.q,
            phi: arc.phi_q,
        });
        self.parallel_crossings(arc, &g, touches, acc);
        if touches {
            return;
        }
        self.meridian_cuts(arc, &g, acc);
        self.integrate_cuts(arc, &g, acc);
    }

    /// An edge through a pole has no line integral (in the (φ, z) plane it
    /// runs along meridians); the pole's parallel is split where it leaves,
    /// with a ray recorded for each side. Returns whether the edge touches
    /// a pole.
    fn pole_rays(&self, arc: &Arc, g: &ArcFrame, acc: &mut Acc) -> bool {
        let mut touches = false;
        for (pole, ps) in self.poles.iter().enumerate() {
            let Some(ps) = *ps else { continue };
            if g.m.dot(ps).abs() > THROUGH_TOL || 1.0 + ps.dot(arc.p) < 1e-12 {
                continue;
            }
            let k = g.key(ps);
            if !(-THROUGH_TOL..=g.key_end + THROUGH_TOL).contains(&k) {
                continue;
            }
            touches = true;
            // The rays take the φ of the arc's ends, the same values as the
            // edges meeting there, so that the (φ, z) plane closes up
            // exactly around the pole.
            let mut push = |phi: f64| {
                let after = DVec3::new(phi.cos(), 0.0, phi.sin());
                let texel_after = if (g.m.dot(after) > 0.0) == arc.side_a {
                    arc.ta
                } else {
                    arc.tb
                };
                acc.rays.push(Ray {
                    pole: pole as u8,
                    phi,
                    texel_after,
                });
            };
            if k < g.key_end - THROUGH_TOL {
                push(arc.phi_q);
            }
            if k > THROUGH_TOL {
                push(arc.phi_p);
            }
        }
        touches
    }

    /// Crossings with the parallels 1..H−1: the great circle meets the
    /// plane y = z at d0 ± s·l. Every crossing is recorded for the
    /// parallel; those inside the arc also cut it, unless it touches a pole.
    fn parallel_crossings(&self, arc: &Arc, g: &ArcFrame, touches: bool, acc: &mut Acc) {
        let (m, p, q) = (g.m, arc.p, arc.q);
        let rr2 = m.x * m.x + m.z * m.z;
        if rr2 <= 0.0 {
            return;
        }
        let h = self.env.height;
        let rr = rr2.sqrt();
        let top = (DVec3::Y - m * m.y) / rr;
        let on_arc = |d: DVec3| 1.0 + d.dot(p) > 1e-12 && g.inside(g.key(d));
        let zmax = if on_arc(top) { rr } else { p.y.max(q.y) };
        let zmin = if on_arc(-top) { -rr } else { p.y.min(q.y) };
        let hf = h as f64;
        let k_lo = ((zmax.clamp(-1.0, 1.0).acos() / PI * hf).floor() as usize)
            .saturating_sub(1)
            .max(1);
        let k_hi = ((zmin.clamp(-1.0, 1.0).acos() / PI * hf).ceil() as usize + 1).min(h - 1);
        let l = m.cross(DVec3::Y) / rr;
        for k in k_lo..=k_hi {
            let z = self.z[k];
            let s2 = 1.0 - z * z / rr2;
            if s2 < 0.0 {
                continue;
            }
            let d0 = top * (z / rr);
            let s = s2.sqrt();
            for d in [d0 + l * s, d0 - l * s] {
                if 1.0 + d.dot(p) <= 1e-12 {
                    continue;
                }
                let kd = g.key(d);
                if (-CROSS_KEY_TOL..=g.key_end + CROSS_KEY_TOL).contains(&kd) {
                    let phi = phi_of(d);
                    acc.crossings.push((k as u32, phi));
                    if !touches && g.inside(kd) {
                        acc.cuts.push(Cut { key: kd, d, phi });
                    }
                }
                if s == 0.0 {
                    break;
                }
            }
        }
    }

    /// Crossings with the meridians: φ is monotonic along the arc,
    /// decreasing when m.y > 0.
    fn meridian_cuts(&self, arc: &Arc, g: &ArcFrame, acc: &mut Acc) {
        let w = self.env.width;
        let m = g.m;
        let decreasing = m.y > 0.0;
        let (phi_p, phi_q) = (arc.phi_p, arc.phi_q);
        let mut sweep = if decreasing {
            (phi_p - phi_q).rem_euclid(TAU)
        } else {
            (phi_q - phi_p).rem_euclid(TAU)
        };
        if sweep > 1.5 * PI {
            // A rounding of a sweep of 0 in the other direction.
            sweep = 0.0;
        }
        let scale = w as f64 / TAU;
        let (lo, hi) = if decreasing {
            (phi_p - sweep, phi_p)
        } else {
            (phi_p, phi_p + sweep)
        };
        let (x_lo, x_hi) = ((lo * scale).ceil() as i64, (hi * scale).floor() as i64);
        for xi in x_lo..=x_hi {
            let x = xi.rem_euclid(w as i64) as usize;
            let (c, s) = self.meridians[x];
            // The meridian's plane has normal (cos φ, 0, sin φ); its half
            // at φ points along (sin φ, 0, −cos φ).
            let dir = m.cross(DVec3::new(c, 0.0, s));
            let len = dir.length();
            if len.is_nan() || len <= 0.0 {
                continue;
            }
            let mut d = dir / len;
            if d.x * s - d.z * c < 0.0 {
                d = -d;
            }
            if 1.0 + d.dot(arc.p) <= 1e-12 {
                continue;
            }
            let kd = g.key(d);
            if g.inside(kd) {
                acc.cuts.push(Cut {
                    key: kd,
                    d,
                    phi: TAU * x as f64 / w as f64,
                });
            }
        }
    }

    /// Each piece between cuts lies in one pixel: adds its line integral
    /// ∫ z dφ = atan(q1/m_y) − atan(q0/m_y), q = (m × d)_y, to the texels
    /// on either side.
    fn integrate_cuts(&self, arc: &Arc, g: &ArcFrame, acc: &mut Acc) {
        let w = self.env.width;
        let m = g.m;
        let scale = w as f64 / TAU;
        // In the (φ, z) plane, whose orientation is the reverse of the
        // sphere's seen from outside, the texel on the −m side lies on the
        // left of the arc's direction.
        let (left, right) = if arc.side_a {
            (arc.tb, arc.ta)
        } else {
            (arc.ta, arc.tb)
        };
        acc.cuts.sort_unstable_by(|a, b| a.key.total_cmp(&b.key));
        let q_of = |d: DVec3| m.z * d.x - m.x * d.z;
        for i in 1..acc.cuts.len() {
            let (a, b) = (acc.cuts[i - 1], acc.cuts[i]);
            if b.key <= a.key {
                continue;
            }
            let dq = m.z * (b.d.x - a.d.x) - m.x * (b.d.z - a.d.z);
            let integral = atan2_short(m.y * dq, m.y * m.y + q_of(a.d) * q_of(b.d));
            if integral == 0.0 {
                continue;
            }
            // φ is monotonic along the piece and stays in one column; z
            // may have an extremum inside it, so take the arc's midpoint.
            let mut phi = 0.5 * (a.phi + b.phi);
            if (a.phi - b.phi).abs() > PI {
                phi = (phi + PI).rem_euclid(TAU);
            }
            let x = ((phi * scale) as usize).min(w - 1);
            let y = self.row_of((a.d + b.d).normalize().y);
            let l = self.radiance(x, y);
            acc.add(left, -integral, l);
            acc.add(right, integral, l);
        }
    }

    /// Parallel `k` (the top edge of pixel row `k`, the bottom edge of row
    /// `k − 1`), split at `crossings` (sorted `φ` where texel edges cross it)
    /// and at the meridians.
    fn parallel(&self, k: usize, crossings: &[f64], rays: &[Ray], acc: &mut Acc) {
        let (w, h) = (self.env.width, self.env.height);
        let (z, r) = (self.z[k], self.r[k]);
        // Split points and the texel of each interval between them.
        let mut cuts: Vec<f64> = Vec::new();
        let mut texels: Vec<u32> = Vec::new();
        if k == 0 || k == h {
            let pole = u8::from(k == h);
            let rays: Vec<&Ray> = rays.iter().filter(|r| r.pole == pole).collect();
            if let Some(last) = rays.last() {
                texels.push(last.texel_after);
                for ray in &rays {
                    cuts.push(ray.phi);
                    texels.push(ray.texel_after);
                }
            } else {
                texels.push(self.env_texel(DVec3::new(0.0, z, 0.0)));
            }
        } else {
            cuts.extend_from_slice(crossings);
            let mut prev = 0.0;
            for &c in cuts.iter().chain(std::iter::once(&TAU)) {
                let phi = 0.5 * (prev + c);
                let (s, co) = phi.sin_cos();
                texels.push(self.env_texel(DVec3::new(s * r, z, -co * r)));
                prev = c;
            }
        }
        let dphi = TAU / w as f64;
        let mut ci = 0;
        for x in 0..w {
            let (a, b) = (
                x as f64 * dphi,
                if x + 1 == w {
                    TAU
                } else {
                    (x + 1) as f64 * dphi
                },
            );
            // z·(L below the parallel − L above it), per unit of φ.
            let mut l = [0.0f64; 3];
            if k < h {
                let below = self.radiance(x, k);
                for c in 0..3 {
                    l[c] += z * below[c];
                }
            }
            if k > 0 {
                let above = self.radiance(x, k - 1);
                for c in 0..3 {
                    l[c] -= z * above[c];
                }
            }
            let mut cur = a;
            while ci < cuts.len() && cuts[ci] < b {
                let c = cuts[ci].max(cur);
                if c > cur {
                    acc.add(texels[ci], c - cur, l);
                }
                cur = c;
                ci += 1;
            }
            acc.add(texels[ci], b - cur, l);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn short_atan2_matches_the_library() {
        for i in 0..2000 {
            let x = 0.5 + i as f64 * 1e-3;
            for f in [0.0, 1e-9, 0.01, -0.03, 0.0625, -0.0625, 0.07, -0.5, 3.0] {
                let y = f * x;
                let (a, b) = (atan2_short(y, x), y.atan2(x));
                assert!(
                    (a - b).abs() <= 2.0 * f64::EPSILON * b.abs(),
                    "{y} {x}: {a} {b}"
                );
            }
        }
        assert_eq!(atan2_short(1.0, -1.0), 1.0f64.atan2(-1.0));
    }

    #[test]
    fn approximate_acos_is_within_a_row_of_the_exact_one() {
        for i in 0..=20000 {
            let z = -1.0 + i as f64 * 1e-4;
            assert!(
                (acos_approx(z) - z.clamp(-1.0, 1.0).acos()).abs() < 1e-4,
                "{z}"
            );
        }
    }
}
