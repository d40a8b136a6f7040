//! Reflectance models. Directions point away from the surface; `n` is the
//! unit shading normal; `f_r` is returned per RGB channel in 1/sr.
//!
//! **Lambert**: `f_r = albedo/π`.
//!
//! **Glossy**: a GGX microfacet specular lobe over a Lambertian base,
//! `f_r = f_s + f_d` with
//!
//! - `f_s(ω_i, ω_o) = F(ω_i·h) · D(h) · G1(ω_i) · G1(ω_o) / (4 (n·ω_i)(n·ω_o))`,
//!   `h = normalize(ω_i + ω_o)`;
//! - GGX distribution `D(h) = α² / (π ((n·h)²(α² − 1) + 1)²)`, with
//!   `α = roughness`;
//! - separable Smith masking, `G1(v) = 2(n·v) / ((n·v) + √(α² + (1 − α²)(n·v)²))`;
//! - Schlick's Fresnel `F(c) = F0 + (1 − F0)(1 − c)⁵`, `F0 = specular`;
//! - the base `f_d = albedo/π · (1 − E_s(μ_i)) (1 − E_s(μ_o)) / (1 − E_avg)`
//!   (Kelemen and Szirmay-Kalos 2001), where `E_s(μ) = ∫ f_s cos θ_i dω_i`
//!   is the specular lobe's directional albedo at `μ = n·ω_o` and
//!   `E_avg = 2 ∫₀¹ E_s(μ) μ dμ`. The base receives exactly the energy the
//!   lobe does not reflect: `∫ f_r cos θ_i dω_i = E_s(μ_o) + albedo·(1 −
//!   E_s(μ_o)) ≤ 1`, and `f_r` is symmetric in `ω_i, ω_o` (reciprocal).
//!
//! `E_s` is tabulated per material when the scene is built: because Schlick's
//! F is affine in F0, `E_s = F0·(E_1 − E_w) + E_w` with `E_1` the lobe's
//! albedo for F = 1 and `E_w` that for F = (1 − ω_o·h)⁵; both are integrated
//! numerically (GGX importance sampling on a 96×96 midpoint grid) at 65
//! values of μ and interpolated linearly. `E_avg` is integrated exactly from
//! the interpolant.

use crate::scene::MaterialDesc;
use glam::DVec3;
use std::f64::consts::{FRAC_1_PI, PI};

const TABLE_LEN: usize = 65;
const TABLE_GRID: usize = 96;

/// A material ready to evaluate.
#[derive(Clone, Debug)]
#[non_exhaustive]
pub enum Material {
    /// Lambertian: `f_r = albedo/π`.
    Lambert {
        /// Reflectance per RGB channel, in `[0, 1]`.
        albedo: [f64; 3],
    },
    /// A Lambertian base plus a GGX specular lobe.
    Glossy(Box<Glossy>),
}

/// The glossy model; see the module docs.
#[derive(Clone, Debug)]
pub struct Glossy {
    /// Reflectance of the Lambertian base per RGB channel, in `[0, 1]`.
    pub albedo: [f64; 3],
    /// Schlick's F0 per RGB channel: the specular reflectance at normal
    /// incidence, in `[0, 1]`.
    pub f0: [f64; 3],
    /// GGX alpha, the width of the microfacet slope distribution, in
    /// `[0.01, 1]`.
    pub alpha: f64,
    /// Directional albedo of the lobe for F = 1, at μ = i/(TABLE_LEN − 1).
    e_one: [f64; TABLE_LEN],
    /// Same for F = (1 − ω_o·h)⁵.
    e_w: [f64; TABLE_LEN],
    /// `albedo/π / (1 − E_avg)` per channel (0 where the lobe reflects all).
    base_scale: [f64; 3],
}

impl Material {
    /// Builds a material from its description.
    pub fn new(desc: &MaterialDesc) -> Material {
        match *desc {
            MaterialDesc::Lambert { albedo } => Material::Lambert { albedo },
            MaterialDesc::Glossy {
                albedo,
                specular,
                roughness,
            } => Material::Glossy(Box::new(Glossy::new(albedo, specular, roughness))),
        }
    }

    /// The diffuse albedo (the RGB factor stored in the albedo image when
    /// the transport is grey).
    pub fn albedo(&self) -> [f64; 3] {
        match self {
            Material::Lambert { albedo } => *albedo,
            Material::Glossy(g) => g.albedo,
        }
    }

    /// `f_r(ω_i, ω_o)` per channel; zero when `ω_i` is below the shading
    /// hemisphere. A view direction below it (possible at silhouettes with
    /// interpolated normals) is treated as grazing: `n·ω_o` is clamped to
    /// 10⁻⁴.
    pub fn eval(&self, n: DVec3, wi: DVec3, wo: DVec3) -> [f64; 3] {
        let (ci, co) = (n.dot(wi), n.dot(wo).max(1e-4));
        if ci <= 0.0 {
            return [0.0; 3];
        }
        match self {
            Material::Lambert { albedo } => albedo.map(|a| a * FRAC_1_PI),
            Material::Glossy(g) => g.eval_cos(ci, co, wi, wo, n),
        }
    }
}

impl Glossy {
    /// Tabulates the lobe's directional albedo for these parameters.
    pub fn new(albedo: [f64; 3], f0: [f64; 3], alpha: f64) -> Glossy {
        let mut e_one = [0.0; TABLE_LEN];
        let mut e_w = [0.0; TABLE_LEN];
        for i in 0..TABLE_LEN {
            let mu = i as f64 / (TABLE_LEN - 1) as f64;
            (e_one[i], e_w[i]) = lobe_albedo(alpha, mu);
        }
        let mut g = Glossy {
            albedo,
            f0,
            alpha,
            e_one,
            e_w,
            base_scale: [0.0; 3],
        };
        for (c, &a) in albedo.iter().enumerate() {
            // E_avg = 2∫E(μ)μ dμ, exact for the piecewise-linear E: Simpson's
            // rule is exact for the quadratic E(μ)μ on each segment.
            let h = 1.0 / (TABLE_LEN - 1) as f64;
            let mut avg = 0.0;
            for i in 0..TABLE_LEN - 1 {
                let (m0, m1) = (i as f64 * h, (i + 1) as f64 * h);
                let (e0, e1) = (g.table(c, i), g.table(c, i + 1));
                let mid = 0.5 * (e0 + e1) * 0.5 * (m0 + m1);
                avg += h / 6.0 * (e0 * m0 + 4.0 * mid + e1 * m1);
            }
            let avg = 2.0 * avg;
            g.base_scale[c] = if 1.0 - avg > 1e-9 {
                a * FRAC_1_PI / (1.0 - avg)
            } else {
                0.0
            };
        }
        g
    }

    fn table(&self, c: usize, i: usize) -> f64 {
        self.f0[c] * (self.e_one[i] - self.e_w[i]) + self.e_w[i]
    }

    /// The lobe's directional albedo `E_s(μ)` for channel `c`.
    pub fn lobe_albedo(&self, c: usize, mu: f64) -> f64 {
        let x = mu.clamp(0.0, 1.0) * (TABLE_LEN - 1) as f64;
        let i = (x as usize).min(TABLE_LEN - 2);
        let t = x - i as f64;
        (1.0 - t) * self.table(c, i) + t * self.table(c, i + 1)
    }

    /// The specular lobe alone, per channel.
    pub fn specular(&self, ci: f64, co: f64, wi: DVec3, wo: DVec3, n: DVec3) -> [f64; 3] {
        let h = (wi + wo).normalize_or_zero();
        if h == DVec3::ZERO {
            return [0.0; 3];
        }
        let nh = n.dot(h).max(0.0);
        let a2 = self.alpha * self.alpha;
        let d = nh * nh * (a2 - 1.0) + 1.0;
        let dist = a2 / (PI * d * d);
        // G1(v)/(n·v) = 2/((n·v) + √(α² + (1 − α²)(n·v)²)).
        let g_over = |c: f64| 2.0 / (c + (a2 + (1.0 - a2) * c * c).sqrt());
        let common = dist * g_over(ci) * g_over(co) / 4.0;
        let w = (1.0 - wi.dot(h).clamp(0.0, 1.0)).powi(5);
        self.f0.map(|f0| (f0 + (1.0 - f0) * w) * common)
    }

    fn eval_cos(&self, ci: f64, co: f64, wi: DVec3, wo: DVec3, n: DVec3) -> [f64; 3] {
        let s = self.specular(ci, co, wi, wo, n);
        let mut out = [0.0; 3];
        for c in 0..3 {
            let base = if self.base_scale[c] > 0.0 {
                self.base_scale[c]
                    * (1.0 - self.lobe_albedo(c, ci))
                    * (1.0 - self.lobe_albedo(c, co))
            } else {
                0.0
            };
            out[c] = s[c] + base;
        }
        out
    }
}

/// `(E_1, E_w)` at `μ = n·ω_o`: the GGX lobe's directional albedo for F = 1
/// and for F = (1 − ω_o·h)⁵, by importance sampling the half vector with
/// density `D(h)(n·h)` on a midpoint grid.
fn lobe_albedo(alpha: f64, mu: f64) -> (f64, f64) {
    let a2 = alpha * alpha;
    let mu = mu.max(1e-6);
    let wo = DVec3::new((1.0 - mu * mu).max(0.0).sqrt(), 0.0, mu);
    let g1 = |c: f64| 2.0 * c / (c + (a2 + (1.0 - a2) * c * c).sqrt());
    let (mut e1, mut ew) = (0.0, 0.0);
    let g = TABLE_GRID as f64;
    for a in 0..TABLE_GRID {
        let u1 = (a as f64 + 0.5) / g;
        // tan²θ_h = α² u/(1 − u) inverts the GGX slope CDF.
        let t2 = a2 * u1 / (1.0 - u1);
        let cos_h = 1.0 / (1.0 + t2).sqrt();
        let sin_h = (1.0 - cos_h * cos_h).max(0.0).sqrt();
        for b in 0..TABLE_GRID {
            let phi = 2.0 * PI * (b as f64 + 0.5) / g;
            let h = DVec3::new(sin_h * phi.cos(), sin_h * phi.sin(), cos_h);
            let oh = wo.dot(h);
            if oh <= 0.0 {
                continue;
            }
            let wi = 2.0 * oh * h - wo;
            if wi.z <= 0.0 {
                continue;
            }
            // f_s cos_i / pdf(ω_i) with pdf(ω_i) = D(h)(n·h)/(4 ω_o·h).
            let v = g1(wi.z) * g1(mu) * oh / (mu * cos_h);
            e1 += v;
            ew += v * (1.0 - oh).powi(5);
        }
    }
    let n = g * g;
    (e1 / n, ew / n)
}
