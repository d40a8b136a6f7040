//! Local point lights from a distant-lighting matrix (Eigentransport §4.2.1):
//! a point light at `X` with intensity `I` lights row `p`, whose surface
//! point is `x_p`, from the single direction `ω = (X − x_p)/d`, `d = |X −
//! x_p|`, with irradiance `I/d²`. In the matrix's basis that is a lighting
//! vector with one nonzero texel per row: `L_p[j] = I/(d²·Ω_j)` at the texel
//! `j` that `ω` falls in (the matrix's entries already include `Ω_j`), or
//! four texels weighted bilinearly between the texel centres of `ω`'s face.
//! Visibility is that of the distant direction `ω` (exact for lights far
//! outside the scene; wrong for a light between objects).
//!
//! # Units
//!
//! `I` is radiant intensity in W/sr per colour channel (Mitsuba 3's `point`
//! emitter `intensity`; PBRT's `I` times its `scale`), in the units of the
//! environment maps' radiance: a row then gets `f_r·V·cos θ·I/d²`, the
//! radiance a renderer computes for direct light from that point light.
//! Positions are in the scene's world units (the bake's TOML).
//!
//! # Refused lights
//!
//! - a non-finite position, a NaN, infinite or negative intensity;
//! - a light within `1e-6 · s` of a valid row's surface point, where `s` is
//!   the largest coordinate magnitude of the light and the surface points
//!   (at least 1): the direction is undefined there;
//! - a light *behind every row*: on the back side (`n·(X − x_p) ≤ 0`) of
//!   every valid row's surface, as a light inside a closed object seen
//!   from outside is. Such a light lights nothing. A light inside an
//!   object whose inside no row sees, but in front of another surface (a
//!   light inside the bunny, above the ground), is not detected: it is
//!   lit as if the object were not around it, shadowed by the distant
//!   visibility of each row's direction.
//!
//! [`point_light_taps`] computes every row's taps from its surface sample;
//! [`PcaRelighter::relight_point`](crate::PcaRelighter::relight_point)
//! evaluates the rows of a `pca` file at them.

use crate::error::{RelightError, Result};
use glam::DVec3;
use ltm_codec::cubemap::{direction_face_point, texel_index, texel_solid_angle};

/// Where a row's surface is: its first-hit point and shading normal in world
/// space. `valid` is false for a row that sees no surface (background): it
/// gets no light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceSample {
    /// World-space position of the row's surface point.
    pub position: [f32; 3],
    /// Unit shading normal, on the side the row is seen from (used only to
    /// refuse a light behind every row).
    pub normal: [f32; 3],
    /// The row sees a surface.
    pub valid: bool,
}

impl From<ltm_codec::SurfacePoint> for SurfaceSample {
    fn from(p: ltm_codec::SurfacePoint) -> SurfaceSample {
        SurfaceSample {
            position: p.position,
            normal: p.normal,
            valid: p.valid,
        }
    }
}

/// An isotropic point light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointLight {
    /// World-space position.
    pub position: [f64; 3],
    /// Radiant intensity per colour channel (W/sr), finite and ≥ 0.
    pub intensity: [f32; 3],
}

/// How a direction picks texels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum Lookup {
    /// The texel the direction falls in (k = 1).
    Nearest,
    /// The four texel centres around it on its face, bilinear weights
    /// (k = 4), clamped at the face's edges.
    Bilinear,
}

impl Lookup {
    /// The name `FromStr` reads: `nearest` or `bilinear`.
    pub fn name(self) -> &'static str {
        match self {
            Lookup::Nearest => "nearest",
            Lookup::Bilinear => "bilinear",
        }
    }
}

impl std::str::FromStr for Lookup {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Lookup, String> {
        match s {
            "nearest" => Ok(Lookup::Nearest),
            "bilinear" => Ok(Lookup::Bilinear),
            _ => Err(format!(
                "texel lookup '{s}' is not one of: nearest, bilinear"
            )),
        }
    }
}

/// One row's lighting: up to four `(texel, I/(d²·Ω_j)·weight)` pairs (weight
/// 0 for unused slots). Multiply by the light's RGB intensity.
pub type Taps = [(u32, f32); 4];

/// The closest a light may come to a surface point, relative to the
/// scene's size (the largest coordinate magnitude, at least 1).
const MIN_DISTANCE: f64 = 1e-6;

/// Every row's taps for `light` on a matrix of face resolution `n`.
/// Refuses a NaN, infinite or negative intensity, a non-finite position,
/// a light at (within 1e-6 of the scene's scale of) a valid surface
/// point, naming the row, and a light behind every valid row's surface
/// (see the module's "Refused lights").
pub fn point_light_taps(
    samples: &[SurfaceSample],
    light: &PointLight,
    n: usize,
    lookup: Lookup,
) -> Result<Vec<Taps>> {
    if let Some(c) = light
        .intensity
        .iter()
        .position(|v| !(v.is_finite() && *v >= 0.0))
    {
        return Err(RelightError::range(
            "point light intensity",
            light.intensity[c],
            "finite and >= 0 (each channel)",
        ));
    }
    let x = DVec3::from_array(light.position);
    if !x.is_finite() {
        return Err(RelightError::Invalid(format!(
            "point light position {x} is not finite"
        )));
    }
    let scale = samples
        .iter()
        .filter(|s| s.valid)
        .flat_map(|s| s.position)
        .fold(x.abs().max_element().max(1.0), |m, v| m.max(v.abs() as f64));
    let all = samples
        .iter()
        .enumerate()
        .map(|(p, s)| {
            if !s.valid {
                return Ok([(0, 0.0); 4]);
            }
            let to = x - DVec3::from_array(s.position.map(f64::from));
            let d2 = to.length_squared();
            if !(to.is_finite() && d2.sqrt() > MIN_DISTANCE * scale) {
                return Err(RelightError::Invalid(format!(
                    "point light at {x} lies on the surface point of row {p} ({:?}): distance {:.3e}, at least {:.3e} needed",
                    s.position, d2.sqrt(), MIN_DISTANCE * scale
                )));
            }
            Ok(taps(to, d2, n, lookup))
        })
        .collect::<Result<Vec<Taps>>>()?;
    check_in_front(samples, x)?;
    Ok(all)
}

/// Refuses a light on the back side of every valid row's surface.
fn check_in_front(samples: &[SurfaceSample], x: DVec3) -> Result<()> {
    let mut valid = samples.iter().filter(|s| s.valid).peekable();
    if valid.peek().is_none() {
        return Ok(());
    }
    let in_front = |s: &SurfaceSample| {
        let to = x - DVec3::from_array(s.position.map(f64::from));
        to.dot(DVec3::from_array(s.normal.map(f64::from))) > 0.0
    };
    if !valid.any(in_front) {
        return Err(RelightError::Invalid(format!(
            "point light at {x} is behind the surface of every row (n·(X − x) ≤ 0 at all {} surface points): inside or behind the geometry the rows see, it lights nothing",
            samples.iter().filter(|s| s.valid).count()
        )));
    }
    Ok(())
}

/// The taps of direction `to` (unnormalised) at squared distance `d2`.
fn taps(to: DVec3, d2: f64, n: usize, lookup: Lookup) -> Taps {
    let (face, s, t) = direction_face_point(to);
    let nf = n as f64;
    let tap = |row: usize, col: usize, w: f64| {
        let j = texel_index(n, face, row, col);
        (j as u32, (w / (d2 * texel_solid_angle(n, j))) as f32)
    };
    match lookup {
        Lookup::Nearest => {
            let col = ((s * nf) as usize).min(n - 1);
            let row = ((t * nf) as usize).min(n - 1);
            [tap(row, col, 1.0), (0, 0.0), (0, 0.0), (0, 0.0)]
        }
        Lookup::Bilinear => {
            // Texel centres at (i + 0.5)/n: the two on each side, clamped.
            let axis = |u: f64| {
                let f = (u * nf - 0.5).clamp(0.0, nf - 1.0);
                let i0 = (f.floor() as usize).min(n - 1);
                let i1 = (i0 + 1).min(n - 1);
                (i0, i1, f - i0 as f64)
            };
            let (c0, c1, fs) = axis(s);
            let (r0, r1, ft) = axis(t);
            [
                tap(r0, c0, (1.0 - fs) * (1.0 - ft)),
                tap(r0, c1, fs * (1.0 - ft)),
                tap(r1, c0, (1.0 - fs) * ft),
                tap(r1, c1, fs * ft),
            ]
        }
    }
}
