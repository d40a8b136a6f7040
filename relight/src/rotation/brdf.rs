//! BRDFs and their view slices (Wang et al. 2006, §3, "Precomputing
//! BRDFs"): for each view direction `ω_o` at the centre of a texel of a
//! hemi-octahedral view grid, the target-resolution map of
//! `∫_texel f_r(ω, ω_o) cos θ dω` (sub-sampled, exact Jacobian), Haar
//! transformed, keeping its scaling coefficient and its largest detail terms
//! (by `|r| + |g| + |b|`).
//!
//! Local frames have the normal on `+z`; `ω` and `ω_o` point away from the
//! surface.

use super::maps::{hemi_encode, square_bilinear, texel_of};
use super::merl::MeasuredBrdf;
use super::spatial::{self, Square, SubSamples};
use super::{check_pow2, haar};
use crate::error::{RelightError, Result};
use glam::DVec3;
use ltm_codec::{Charge, Limits};
use rayon::prelude::*;
use std::f64::consts::PI;
use std::path::Path;
use std::sync::Arc;

/// A reflectance model, isotropic, in the local frame.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum Brdf {
    /// A measured table in the MERL database's layout ([`MeasuredBrdf`]),
    /// shared.
    Measured(Arc<MeasuredBrdf>),
    /// Lambertian: `albedo / π`.
    Lambert {
        /// Albedo per channel, in `[0, 1]`.
        albedo: [f32; 3],
    },
    /// GGX microfacet conductor (Walter et al. 2007): GGX distribution of
    /// roughness `alpha`, separable Smith masking `G1(ω)·G1(ω_o)`, Schlick
    /// Fresnel from `f0` at the half vector.
    Ggx {
        /// GGX roughness α, in `[0.01, 1]`.
        alpha: f32,
        /// Reflectance at normal incidence per channel, in `[0, 1]`.
        f0: [f32; 3],
    },
    /// Normalized modified Phong (Lafortune and Willems 1994):
    /// `specular · (e + 2)/(2π) · max(0, ω·r)^e`, `r` the mirror of `ω_o`.
    Phong {
        /// Exponent `e`, in `[1, 100000]`.
        exponent: f32,
        /// Specular reflectance per channel, in `[0, 1]`.
        specular: [f32; 3],
    },
    /// Plastic: a GGX dielectric coat (the exact unpolarized Fresnel
    /// reflectance of the index of refraction, at the half vector) over a
    /// Lambertian base weighted by the coat's transmission both ways,
    /// `(1 − F(ω))(1 − F(ω_o))·albedo/π`. The slices are precomputed, so
    /// the exact Fresnel costs nothing at run time; Schlick's approximation
    /// is 5.4 % off it at IOR 1.5 and put the coat 10–15 % off Mitsuba's
    /// `roughplastic` (docs/results/glossy.md).
    Plastic {
        /// Base albedo per channel, in `[0, 1]`.
        albedo: [f32; 3],
        /// Coat roughness α, in `[0.01, 1]`.
        alpha: f32,
        /// Coat index of refraction, in `(1, 3]`.
        ior: f32,
    },
}

/// The `n·α` that [`Brdf::lighting_side`] asks of a lobe: where the
/// error against Mitsuba 3 falls under 2 %.
pub const LOBE_TEXELS: f64 = 25.0;

fn check_rgb(what: &'static str, c: [f32; 3]) -> Result<()> {
    match c.iter().find(|v| !(0.0..=1.0).contains(*v)) {
        Some(v) => Err(RelightError::range(what, v, "0..=1 per channel")),
        None => Ok(()),
    }
}

fn check_alpha(alpha: f32) -> Result<()> {
    if !(0.01..=1.0).contains(&alpha) {
        return Err(RelightError::range(
            "GGX roughness alpha",
            alpha,
            "0.01..=1",
        ));
    }
    Ok(())
}

fn schlick(f0: f64, cos: f64) -> f64 {
    f0 + (1.0 - f0) * (1.0 - cos.clamp(0.0, 1.0)).powi(5)
}

/// The unpolarized Fresnel reflectance of a dielectric of relative index
/// `eta > 1`, light arriving from outside at `cos` to the normal (the
/// mean of the s and p reflectances, written with `g = √(η² − 1 + c²)`).
pub(crate) fn fresnel_dielectric(eta: f64, cos: f64) -> f64 {
    let c = cos.clamp(0.0, 1.0);
    let g = (eta * eta - 1.0 + c * c).sqrt();
    let (a, b) = (g - c, g + c);
    let p = (c * b - 1.0) / (c * a + 1.0);
    0.5 * (a / b).powi(2) * (1.0 + p * p)
}

/// GGX `D · G1(ω) · G1(ω_o) / (4 cos θ cos θ_o)` and `ω·h`.
fn ggx_lobe(alpha: f64, wi: DVec3, wo: DVec3) -> (f64, f64) {
    let h = (wi + wo).normalize();
    let a2 = alpha * alpha;
    let c = h.z * h.z;
    let d = a2 / (PI * (c * (a2 - 1.0) + 1.0).powi(2));
    let g1 = |cos: f64| 2.0 * cos / (cos + (a2 + (1.0 - a2) * cos * cos).sqrt());
    (d * g1(wi.z) * g1(wo.z) / (4.0 * wi.z * wo.z), wi.dot(h))
}

impl Brdf {
    /// Checks the parameters (errors name the value and its valid range).
    pub fn validate(&self) -> Result<()> {
        match *self {
            Brdf::Measured(_) => Ok(()),
            Brdf::Lambert { albedo } => check_rgb("Lambert albedo", albedo),
            Brdf::Ggx { alpha, f0 } => {
                check_alpha(alpha)?;
                check_rgb("GGX F0", f0)
            }
            Brdf::Phong { exponent, specular } => {
                if !(1.0..=1e5).contains(&exponent) {
                    return Err(RelightError::range(
                        "Phong exponent",
                        exponent,
                        "1..=100000",
                    ));
                }
                check_rgb("Phong specular", specular)
            }
            Brdf::Plastic { albedo, alpha, ior } => {
                check_alpha(alpha)?;
                if !(ior > 1.0 && ior <= 3.0) {
                    return Err(RelightError::range("plastic ior", ior, "(1, 3]"));
                }
                check_rgb("plastic albedo", albedo)
            }
        }
    }

    /// The lighting map side `n` this BRDF needs, for
    /// [`RotationConfig::n`](super::RotationConfig::n) when the caller
    /// names none: the smaller of 64 and 128 at which `n·α` reaches
    /// [`LOBE_TEXELS`]. Against Mitsuba 3 (docs/results/glossy.md) the error
    /// of a sphere follows `n·α`: 25 % at 3.2, 9–10 % at 6.4, 3–4 % at 12.8,
    /// 3 % at 16, 1.6 % at 25.6 and 1.2 % at 32. Lambert needs 64 (2–4 % at
    /// 32, 1 % at 64). Phong's lobe counts as GGX's α = √(2/(e + 2)), and a
    /// measured table, whose sharpness is unknown, takes 128. Lobes
    /// sharper than α = 25/128 ≈ 0.2 get 128, the largest the CLI builds.
    pub fn lighting_side(&self) -> usize {
        let alpha = match *self {
            Brdf::Lambert { .. } => return 64,
            Brdf::Measured(_) => return 128,
            Brdf::Ggx { alpha, .. } | Brdf::Plastic { alpha, .. } => alpha as f64,
            Brdf::Phong { exponent, .. } => (2.0 / (exponent as f64 + 2.0)).sqrt(),
        };
        if 64.0 * alpha >= LOBE_TEXELS {
            64
        } else {
            128
        }
    }

    /// The fractions of terms step 2 keeps by default, for
    /// [`SliceConfig::keep`] and [`Shader::set_local_keep`](super::Shader::set_local_keep):
    /// at a lighting side `n`: 0.03 and 0.03 where `n ≥ 128` and the BRDF
    /// is an analytic lobe that [`Brdf::lighting_side`] gives 128, else 0.1
    /// and 0.1. At n = 128 a sharp lobe's error against Mitsuba 3 is the
    /// same at 0.03 as at 0.1 (to 0.01 %, under a sun and small lamps;
    /// 1.35 % against 1.2 % under a smooth sky), and step 2 is 2.9× faster.
    /// What counts is the number of terms, about 100 of `(n/2)²`: at n = 32
    /// the same lobe is 23 % off at 0.03 against 10 % at 0.1. Broad lobes
    /// and Lambert lose at 0.03 under a smooth sky (Lambert 1.2 → 2.6 %,
    /// α = 0.5 0.7 → 2.3 %), and measured tables may be broad.
    pub fn kept_fractions(&self, n: usize) -> (f64, f64) {
        match self {
            Brdf::Measured(_) => (0.1, 0.1),
            _ if n >= 128 && self.lighting_side() == 128 => (0.03, 0.03),
            _ => (0.1, 0.1),
        }
    }

    /// `f_r(ω, ω_o)` per channel; zero where either direction is at or
    /// below the horizon.
    pub fn eval(&self, wi: DVec3, wo: DVec3) -> [f64; 3] {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return [0.0; 3];
        }
        match *self {
            Brdf::Measured(ref table) => table.eval(wi, wo),
            Brdf::Lambert { albedo } => albedo.map(|a| f64::from(a) / PI),
            Brdf::Ggx { alpha, f0 } => {
                let (lobe, cos_h) = ggx_lobe(f64::from(alpha), wi, wo);
                f0.map(|f| lobe * schlick(f64::from(f), cos_h))
            }
            Brdf::Phong { exponent, specular } => {
                let e = f64::from(exponent);
                let r = DVec3::new(-wo.x, -wo.y, wo.z);
                let lobe = (e + 2.0) / (2.0 * PI) * wi.dot(r).max(0.0).powf(e);
                specular.map(|s| f64::from(s) * lobe)
            }
            Brdf::Plastic { albedo, alpha, ior } => {
                let eta = f64::from(ior);
                let (lobe, cos_h) = ggx_lobe(f64::from(alpha), wi, wo);
                let coat = lobe * fresnel_dielectric(eta, cos_h);
                let base = (1.0 - fresnel_dielectric(eta, wi.z))
                    * (1.0 - fresnel_dielectric(eta, wo.z))
                    / PI;
                albedo.map(|a| coat + base * f64::from(a))
            }
        }
    }
}

/// Parses a grey value `v` or an RGB triple `r/g/b`.
fn parse_rgb(what: &'static str, s: &str) -> Result<[f32; 3]> {
    let bad = || RelightError::Invalid(format!("{what} '{s}' is not a number or r/g/b"));
    let v: Vec<f32> = s
        .split('/')
        .map(|t| t.trim().parse::<f32>().map_err(|_| bad()))
        .collect::<Result<_>>()?;
    match v[..] {
        [g] => Ok([g; 3]),
        [r, g, b] => Ok([r, g, b]),
        _ => Err(bad()),
    }
}

fn parse_scalar(what: &'static str, s: &str) -> Result<f32> {
    s.trim()
        .parse::<f32>()
        .map_err(|_| RelightError::Invalid(format!("{what} '{s}' is not a number")))
}

/// The spellings `Brdf`'s [`FromStr`](std::str::FromStr) accepts.
pub const BRDF_SYNTAX: &str = "lambert[:ALBEDO] | ggx:ALPHA[,f0=F0] | phong:EXPONENT[,specular=S] | plastic:ALPHA[,albedo=A][,ior=IOR] (colours grey or r/g/b) | merl:PATH (a measured BRDF file)";

impl std::str::FromStr for Brdf {
    type Err = RelightError;

    /// `lambert[:ALBEDO]` (albedo 0.8 by default), `ggx:ALPHA[,f0=F0]`
    /// (F0 0.9), `phong:EXPONENT[,specular=S]` (S 1) or
    /// `plastic:ALPHA[,albedo=A][,ior=IOR]` (A 0.5, IOR 1.5); colours are a
    /// grey value or `r/g/b`; names and keys are case-insensitive. The
    /// result is validated. `merl:PATH` reads a measured table
    /// ([`MeasuredBrdf::read`]) charged to the default budget; see
    /// [`Brdf::from_spec`] to pass one.
    fn from_str(spec: &str) -> Result<Brdf> {
        Brdf::from_spec(spec, &Limits::default())
    }
}

impl Brdf {
    /// `Brdf`'s [`FromStr`](std::str::FromStr), with a `merl:PATH` table
    /// charged to `limits`.
    pub fn from_spec(spec: &str, limits: &Limits) -> Result<Brdf> {
        if let Some(path) = spec.strip_prefix("merl:") {
            let table = MeasuredBrdf::read(Path::new(path), limits)?;
            return Ok(Brdf::Measured(Arc::new(table)));
        }
        let (kind, rest) = spec.split_once(':').unwrap_or((spec, ""));
        let mut parts = rest.split(',').map(str::trim).filter(|p| !p.is_empty());
        let first = parts.next();
        let mut keys = Vec::new();
        for p in parts {
            let (k, v) = p.split_once('=').ok_or_else(|| {
                RelightError::Invalid(format!("'{p}' in BRDF '{spec}' is not key=value"))
            })?;
            keys.push((k.trim().to_ascii_lowercase(), v));
        }
        let need = |what: &'static str| {
            first.ok_or_else(|| {
                RelightError::Invalid(format!("BRDF '{spec}' needs its {what}: {BRDF_SYNTAX}"))
            })
        };
        let mut brdf = match kind.trim().to_ascii_lowercase().as_str() {
            "lambert" => Brdf::Lambert {
                albedo: first.map_or(Ok([0.8; 3]), |a| parse_rgb("albedo", a))?,
            },
            "ggx" => Brdf::Ggx {
                alpha: parse_scalar("GGX roughness", need("roughness")?)?,
                f0: [0.9; 3],
            },
            "phong" => Brdf::Phong {
                exponent: parse_scalar("Phong exponent", need("exponent")?)?,
                specular: [1.0; 3],
            },
            "plastic" => Brdf::Plastic {
                albedo: [0.5; 3],
                alpha: parse_scalar("plastic roughness", need("roughness")?)?,
                ior: 1.5,
            },
            other => {
                return Err(RelightError::Invalid(format!(
                    "unknown BRDF '{other}' (valid: {BRDF_SYNTAX})"
                )))
            }
        };
        for (k, v) in keys {
            brdf.set_key(&k, v, spec)?;
        }
        brdf.validate()?;
        Ok(brdf)
    }
}

impl Brdf {
    /// Sets the optional parameter `key` of a parsed spec.
    fn set_key(&mut self, key: &str, value: &str, spec: &str) -> Result<()> {
        match (self, key) {
            (Brdf::Ggx { f0, .. }, "f0") => *f0 = parse_rgb("GGX F0", value)?,
            (Brdf::Phong { specular, .. }, "specular") => {
                *specular = parse_rgb("Phong specular", value)?
            }
            (Brdf::Plastic { albedo, .. }, "albedo") => {
                *albedo = parse_rgb("plastic albedo", value)?
            }
            (Brdf::Plastic { ior, .. }, "ior") => *ior = parse_scalar("plastic ior", value)?,
            _ => {
                return Err(RelightError::Invalid(format!(
                    "BRDF '{spec}' has no parameter '{key}' (valid: {BRDF_SYNTAX})"
                )))
            }
        }
        Ok(())
    }
}

fn rgb_spec(c: [f32; 3]) -> String {
    if c[0] == c[1] && c[1] == c[2] {
        c[0].to_string()
    } else {
        format!("{}/{}/{}", c[0], c[1], c[2])
    }
}

impl std::fmt::Display for Brdf {
    /// The spec that parses back to the same BRDF.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match *self {
            Brdf::Measured(ref table) => write!(f, "merl:{}", table.name()),
            Brdf::Lambert { albedo } => write!(f, "lambert:{}", rgb_spec(albedo)),
            Brdf::Ggx { alpha, f0 } => write!(f, "ggx:{alpha},f0={}", rgb_spec(f0)),
            Brdf::Phong { exponent, specular } => {
                write!(f, "phong:{exponent},specular={}", rgb_spec(specular))
            }
            Brdf::Plastic { albedo, alpha, ior } => {
                write!(f, "plastic:{alpha},albedo={},ior={ior}", rgb_spec(albedo))
            }
        }
    }
}

/// How [`BrdfSlices`] are built.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SliceConfig {
    /// Target hemi-octahedral side `m` (a power of two, 2..=128): the
    /// rotation set's `n/2`.
    pub m: usize,
    /// Side of the hemi-octahedral grid of view directions (1..=256).
    pub views: usize,
    /// Sub-samples per target texel and side (1..=16).
    pub supersample: usize,
    /// Fraction of the `m²` Haar terms kept per slice, in `(0, 1]`.
    pub keep: f64,
    /// Whether each view also stores its dense residual (`views² · m²`
    /// RGB values: 50 MB at the defaults of `ltm render`), which
    /// [`Shader`](super::Shader) dots with each grid normal's largest
    /// local-lighting terms.
    pub residuals: bool,
}

impl Default for SliceConfig {
    fn default() -> SliceConfig {
        SliceConfig {
            m: 32,
            views: 64,
            supersample: 4,
            keep: 0.03,
            residuals: true,
        }
    }
}

impl SliceConfig {
    /// Checks every field.
    pub fn validate(&self) -> Result<()> {
        check_pow2("BRDF slice side m", self.m, 2, 128)?;
        if !(1..=256).contains(&self.views) {
            return Err(RelightError::range("view grid side", self.views, "1..=256"));
        }
        if !(1..=16).contains(&self.supersample) {
            return Err(RelightError::range(
                "slice supersample",
                self.supersample,
                "1..=16",
            ));
        }
        if !(self.keep > 0.0 && self.keep <= 1.0) {
            return Err(RelightError::range(
                "kept BRDF fraction",
                self.keep,
                "(0, 1]",
            ));
        }
        Ok(())
    }

    /// Terms kept per slice: `ceil(keep · m²)`.
    pub fn terms(&self) -> usize {
        ((self.keep * (self.m * self.m) as f64).ceil() as usize).clamp(1, self.m * self.m)
    }
}

/// One kept term of a slice: target coefficient and RGB value.
type Term = (u32, [f32; 3]);

/// A slice split into its kept terms and its dense residual.
pub(super) type SplitSlice = (Vec<Term>, Vec<[f32; 3]>);

/// One sparse Haar slice per view direction.
#[derive(Debug)]
pub struct BrdfSlices {
    cfg: SliceConfig,
    brdf: Brdf,
    /// Per view `v`, its terms are `offsets[v]..offsets[v + 1]`.
    offsets: Vec<u32>,
    index: Vec<u32>,
    value: Vec<[f32; 3]>,
    /// Per view, its `m²` coefficients with the kept terms zeroed (what
    /// [`BrdfSlices::residual_dot`] adds where the lighting is large).
    residual: Vec<[f32; 3]>,
    _charge: Charge,
}

/// Haar transform of a spatial slice, split in two: the kept terms (its
/// scaling coefficient, the slice's mean: without it, a constant lighting
/// would reflect nothing where a narrow lobe's detail terms outweigh it;
/// and its `terms − 1` largest detail coefficients) and the dense residual
/// (every coefficient, the kept ones zeroed).
fn split_slice(spatial: &[[f64; 3]], m: usize, terms: usize) -> Result<SplitSlice> {
    let mut planes = [0, 1, 2].map(|c| spatial.iter().map(|p| p[c] as f32).collect::<Vec<_>>());
    for p in planes.iter_mut() {
        haar::forward(p, m)?;
    }
    let mags: Vec<f32> = (0..m * m)
        .map(|i| planes.iter().map(|p| p[i].abs()).sum::<f32>())
        .collect();
    let mag = |i: u32| mags[i as usize];
    // The `terms − 1` largest details, ties to the lower index.
    let mut order: Vec<u32> = (1..(m * m) as u32).collect();
    let details = terms.saturating_sub(1);
    if details < order.len() {
        order.select_nth_unstable_by(details, |&a, &b| mag(b).total_cmp(&mag(a)).then(a.cmp(&b)));
        order.truncate(details);
    }
    let mut kept: Vec<u32> = std::iter::once(0)
        .chain(order)
        .filter(|&i| mag(i) > 0.0)
        .collect();
    kept.sort_unstable();
    let terms = kept
        .iter()
        .map(|&i| (i, [0, 1, 2].map(|c| planes[c][i as usize])))
        .collect();
    let mut residual: Vec<[f32; 3]> = (0..m * m)
        .map(|i| [0, 1, 2].map(|c| planes[c][i]))
        .collect();
    for &i in &kept {
        residual[i as usize] = [0.0; 3];
    }
    Ok((terms, residual))
}

/// Every view's split slice, in view order: one spatial slice per orbit
/// of views under `symmetries` (which must leave `brdf` unchanged), moved
/// onto the orbit's other views, in parallel over orbits.
pub(super) fn split_slices(
    brdf: &Brdf,
    cfg: &SliceConfig,
    symmetries: &[Square],
) -> Result<Vec<SplitSlice>> {
    let (m, terms) = (cfg.m, cfg.terms());
    let samples = SubSamples::new(cfg);
    let per_orbit: Vec<Vec<(usize, Result<SplitSlice>)>> = spatial::orbits(cfg.views, symmetries)
        .into_par_iter()
        .map(|(first, members)| {
            let base = samples.slice(brdf, spatial::view_direction(cfg.views, first));
            members
                .into_iter()
                .map(|(v, g)| (v, split_slice(&spatial::moved(&base, m, g), m, terms)))
                .collect()
        })
        .collect();
    let mut slices: Vec<Option<SplitSlice>> = (0..cfg.views * cfg.views).map(|_| None).collect();
    for (v, slice) in per_orbit.into_iter().flatten() {
        slices[v] = Some(slice?);
    }
    slices
        .into_iter()
        .map(|s| s.ok_or_else(|| RelightError::Invalid("a view has no BRDF slice".into())))
        .collect()
}

impl BrdfSlices {
    /// Builds every view's slice, in parallel; the terms are charged to
    /// `limits` before they are stored. Views that a symmetry of the view
    /// grid maps onto each other (a quarter turn about the normal, or a
    /// mirror through it: up to 8 views) share one computed slice, moved
    /// texel by texel: every analytic BRDF is isotropic, and a measured
    /// table is unchanged by the quarter turns.
    pub fn build(brdf: Brdf, cfg: SliceConfig, limits: &Limits) -> Result<BrdfSlices> {
        brdf.validate()?;
        cfg.validate()?;
        let views = cfg.views * cfg.views;
        let terms = cfg.terms();
        let m2 = cfg.m * cfg.m;
        let charge = limits
            .check_alloc("BRDF slices", (views * terms) as u64, 16)?
            .join(limits.check_alloc(
                "BRDF slice residuals",
                (views * m2 * usize::from(cfg.residuals)) as u64,
                12,
            )?);
        let slices = split_slices(&brdf, &cfg, &Square::of(&brdf))?;
        let mut offsets = Vec::with_capacity(views + 1);
        let (mut index, mut value) = (Vec::new(), Vec::new());
        let mut residual = Vec::with_capacity(views * m2 * usize::from(cfg.residuals));
        offsets.push(0u32);
        for (kept, rest) in slices {
            for (i, v) in kept {
                index.push(i);
                value.push(v);
            }
            offsets.push(index.len() as u32);
            if cfg.residuals {
                residual.extend(rest);
            }
        }
        Ok(BrdfSlices {
            cfg,
            brdf,
            offsets,
            index,
            value,
            residual,
            _charge: charge,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &SliceConfig {
        &self.cfg
    }

    /// The BRDF.
    pub fn brdf(&self) -> &Brdf {
        &self.brdf
    }

    /// The view texel nearest local view direction `wo` (moved onto the
    /// horizon if below it).
    pub fn view_index(&self, wo: DVec3) -> usize {
        let (u, v) = hemi_encode(wo);
        texel_of(self.cfg.views, u, v)
    }

    /// The four view texels around local view direction `wo` (moved onto
    /// the horizon if below it) and their bilinear weights.
    pub fn view_bilinear(&self, wo: DVec3) -> [(usize, f64); 4] {
        let (u, v) = hemi_encode(wo);
        square_bilinear(self.cfg.views, u, v)
    }

    /// The terms of view `v`: `(target coefficient, RGB value)`.
    pub fn slice(&self, v: usize) -> impl Iterator<Item = (usize, [f32; 3])> + '_ {
        let range = self.offsets[v] as usize..self.offsets[v + 1] as usize;
        self.index[range.clone()]
            .iter()
            .map(|&i| i as usize)
            .zip(self.value[range].iter().copied())
    }

    /// Slice of view `v` dotted with a local lighting (`m²` RGB Haar
    /// coefficients), per channel.
    pub fn dot(&self, v: usize, local: &[[f32; 3]]) -> [f32; 3] {
        let mut acc = [0.0f32; 3];
        for (i, f) in self.slice(v) {
            let l = local[i];
            for c in 0..3 {
                acc[c] += f[c] * l[c];
            }
        }
        acc
    }

    /// The residual of view `v` (the coefficients its kept terms lack)
    /// dotted with a local lighting at its coefficients `at` only, per
    /// channel: with [`BrdfSlices::dot`], a term is dropped only where both
    /// the slice and the lighting are small.
    pub fn residual_dot(&self, v: usize, local: &[[f32; 3]], at: &[u32]) -> [f32; 3] {
        let m2 = self.cfg.m * self.cfg.m;
        let Some(rest) = self.residual.get(v * m2..(v + 1) * m2) else {
            return [0.0; 3];
        };
        let mut acc = [0.0f32; 3];
        for &i in at {
            let (f, l) = (rest[i as usize], local[i as usize]);
            for c in 0..3 {
                acc[c] += f[c] * l[c];
            }
        }
        acc
    }

    /// Bytes of the stored terms and residuals.
    pub fn bytes(&self) -> usize {
        4 * self.offsets.len() + 16 * self.index.len() + 12 * self.residual.len()
    }
}
