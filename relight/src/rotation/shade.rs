//! The two rendering steps of Wang et al. 2006 (§3, "Environment Map
//! Rendering"), and the spatial-domain rotation they are checked against.

use super::maps::{hemi_decode, oct_bilinear, oct_decode, oct_encode, subsample, texel_of, Frame};
use super::pairs::PairTable;
use super::{check_pow2, haar, BrdfSlices, RotationSet, MAX_SOURCE_SIDE};
use crate::error::{RelightError, Result};
use glam::DVec3;
use ltm_codec::{Charge, Limits, SurfacePoint};
use rayon::prelude::*;
use std::sync::Arc;

/// The default of [`Shader::set_local_keep`]: each grid normal's largest
/// tenth of local-lighting terms.
pub const DEFAULT_LOCAL_KEEP: f64 = 0.1;

/// Global lighting: an `n × n` octahedral map of RGB radiance, texel
/// `y·n + x` (see [`super::maps`]).
#[derive(Clone, Debug, PartialEq)]
pub struct OctMap {
    n: usize,
    texels: Vec<[f32; 3]>,
}

impl OctMap {
    /// A map from its texels (`n` a power of two, 4..=256; `n²` finite
    /// texels).
    pub fn new(n: usize, texels: Vec<[f32; 3]>) -> Result<OctMap> {
        check_pow2("octahedral map side", n, 4, MAX_SOURCE_SIDE)?;
        if texels.len() != n * n {
            let valid = format!("{} (n = {n})", n * n);
            return Err(RelightError::range(
                "octahedral map texels",
                texels.len(),
                valid,
            ));
        }
        if texels.iter().flatten().any(|v| !v.is_finite()) {
            return Err(RelightError::InvalidEnvMap(
                "a texel is NaN or infinite".into(),
            ));
        }
        Ok(OctMap { n, texels })
    }

    /// A map with each texel the mean of `radiance` over `s × s` sub-samples
    /// of it, each weighted by its solid angle (so that a small bright
    /// source keeps its power wherever it falls in a texel; `s` is clamped
    /// to 1..=16).
    pub fn from_fn(n: usize, s: usize, radiance: impl Fn(DVec3) -> [f32; 3]) -> Result<OctMap> {
        check_pow2("octahedral map side", n, 4, MAX_SOURCE_SIDE)?;
        let s = s.clamp(1, 16);
        let texels = (0..n * n)
            .map(|t| {
                let (mut acc, mut total) = ([0.0f64; 3], 0.0);
                for j in 0..s {
                    for i in 0..s {
                        let (u, v) = subsample(n, t, s, i, j);
                        let (d, jac) = oct_decode(u, v);
                        let r = radiance(d);
                        (0..3).for_each(|c| acc[c] += jac * f64::from(r[c]));
                        total += jac;
                    }
                }
                acc.map(|a| (a / total) as f32)
            })
            .collect();
        OctMap::new(n, texels)
    }

    /// The octahedral map of a cubemap of face resolution `face_res` (the
    /// `6·face_res²` texels of a transport relighter's light, in the column
    /// order of docs/FORMAT.md): each texel the mean of the cube texels
    /// that its `s × s` sub-sample directions fall in, so the glossy and the
    /// transport parts of a render see one lighting, rotation included.
    pub fn from_cubemap(
        n: usize,
        s: usize,
        face_res: usize,
        cubemap: &[[f32; 3]],
    ) -> Result<OctMap> {
        let expected = ltm_codec::cubemap::texel_count(face_res);
        if face_res == 0 || cubemap.len() != expected {
            let valid =
                format!("6·face_res² = {expected} with face_res ≥ 1 (face_res = {face_res})");
            return Err(RelightError::range("cubemap texels", cubemap.len(), valid));
        }
        OctMap::from_fn(n, s, |d| {
            cubemap[ltm_codec::cubemap::direction_texel(face_res, d.as_vec3())]
        })
    }

    /// Side `n`.
    pub fn side(&self) -> usize {
        self.n
    }

    /// Texels.
    pub fn texels(&self) -> &[[f32; 3]] {
        &self.texels
    }

    /// Radiance of the texel containing direction `d`.
    pub fn lookup(&self, d: DVec3) -> [f32; 3] {
        let (u, v) = oct_encode(d);
        self.texels[texel_of(self.n, u, v)]
    }

    /// The RGB Haar coefficients (`n²`), optionally only the `terms`
    /// largest by `|r| + |g| + |b|` (the rest zero).
    pub fn haar(&self, terms: Option<usize>) -> Result<Vec<[f32; 3]>> {
        let n = self.n;
        let mut planes = [0, 1, 2].map(|c| self.texels.iter().map(|t| t[c]).collect::<Vec<_>>());
        for p in planes.iter_mut() {
            haar::forward(p, n)?;
        }
        let mut coef: Vec<[f32; 3]> = (0..n * n)
            .map(|i| [planes[0][i], planes[1][i], planes[2][i]])
            .collect();
        if let Some(k) = terms.filter(|&k| k < n * n) {
            let mag = |c: &[f32; 3]| c[0].abs() + c[1].abs() + c[2].abs();
            let mut order: Vec<usize> = (0..n * n).collect();
            order.select_nth_unstable_by(k, |&a, &b| mag(&coef[b]).total_cmp(&mag(&coef[a])));
            for &i in &order[k..] {
                coef[i] = [0.0; 3];
            }
        }
        Ok(coef)
    }
}

/// The spatial-domain rotation: the local hemi-octahedral map (`n/2`
/// side) of `normal`'s frame, each texel the solid-angle-weighted mean of
/// `map` over `s × s` sub-samples. `R(normal)·haar(map)` approximates its
/// Haar transform to quantization error when built with the same `s`.
pub fn resample_local(map: &OctMap, normal: DVec3, s: usize) -> Vec<[f32; 3]> {
    let (m, s) = (map.n / 2, s.clamp(1, 16));
    let frame = Frame::new(normal.normalize());
    (0..m * m)
        .map(|t| {
            let (mut acc, mut total) = ([0.0f64; 3], 0.0);
            for j in 0..s {
                for i in 0..s {
                    let (u, v) = subsample(m, t, s, i, j);
                    let (d, jac) = hemi_decode(u, v);
                    let r = map.lookup(frame.to_global(d));
                    (0..3).for_each(|c| acc[c] += jac * f64::from(r[c]));
                    total += jac;
                }
            }
            acc.map(|a| (a / total) as f32)
        })
        .collect()
}

/// Renders with a [`RotationSet`] and one BRDF's [`BrdfSlices`]: step 1
/// ([`Shader::light`]) on a lighting change, step 2 ([`Shader::shade`])
/// per surface point and view.
#[derive(Debug)]
pub struct Shader {
    rotations: Arc<RotationSet>,
    slices: Arc<BrdfSlices>,
    /// Per grid normal, its `m²` RGB local-lighting coefficients.
    local: Vec<[f32; 3]>,
    /// Per grid normal, the indices of its `local_terms` largest
    /// local-lighting coefficients (by `|r| + |g| + |b|`), ascending.
    top: Vec<u32>,
    /// How many of each normal's local-lighting terms step 2 dots with the
    /// slices' residuals.
    local_terms: usize,
    _top_charge: Charge,
    /// Per grid normal, its frame.
    frames: Vec<Frame>,
    /// Step 2's radiance per (grid normal, view texel), kept once computed
    /// (`None` where the table is too large: each pair is then computed
    /// where it is used).
    pairs: Option<PairTable>,
    /// The budget the pair table is charged to when the BRDF changes.
    limits: Limits,
    /// How step 2 reads the slices between view texels.
    view_filter: ViewFilter,
    _charge: Charge,
}

/// How step 2 takes a grid normal's slice for a view direction that falls
/// between the view grid's texels.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[non_exhaustive]
pub enum ViewFilter {
    /// The texel the direction falls in: one pair per grid normal. The
    /// shading then steps where the direction crosses a texel's edge,
    /// which a sharp lobe shows (6.0 % against Mitsuba 3 for a conductor
    /// of α = 0.1 on a sphere, 128² pixels, 64² views, n = 128).
    Nearest,
    /// The four texels around it, blended bilinearly: four pairs per grid
    /// normal, continuous across texel edges (2.7 % in the same case).
    #[default]
    Bilinear,
}

impl Shader {
    /// A shader with no lighting yet (black until [`Shader::light`]); the
    /// local-lighting buffer is charged to `limits`.
    pub fn new(
        rotations: Arc<RotationSet>,
        slices: Arc<BrdfSlices>,
        limits: &Limits,
    ) -> Result<Shader> {
        check_slices(&rotations, &slices)?;
        let cfg = rotations.config();
        let count = cfg.normals * cfg.normals * cfg.m() * cfg.m();
        let (local, charge) = limits.vec("local lightings", count, [0.0f32; 3])?;
        let normals = cfg.normals * cfg.normals;
        let frames_charge = limits.check_alloc("normal frames", normals as u64, 72)?;
        let frames = (0..normals)
            .map(|i| Frame::new(cfg.grid_normal(i)))
            .collect();
        let pairs = PairTable::new(normals, slices.config().views.pow(2), limits);
        let mut shader = Shader {
            rotations,
            slices,
            local,
            top: Vec::new(),
            local_terms: 0,
            _top_charge: Charge::default(),
            frames,
            pairs,
            limits: limits.clone(),
            view_filter: ViewFilter::default(),
            _charge: charge.join(frames_charge),
        };
        shader.set_local_keep(DEFAULT_LOCAL_KEEP, limits)?;
        Ok(shader)
    }

    /// Sets the fraction of each grid normal's `m²` local-lighting terms,
    /// the largest, that step 2 also dots with the BRDF slices' residuals
    /// (the terms a slice did not keep), in `[0, 1]`: a product term is
    /// then dropped only where both the slice and the lighting are small.
    /// 0 keeps the slice's terms alone (Wang et al.'s scheme); a sun or a
    /// small lamp needs the lighting's own terms. The index lists are
    /// charged to `limits`.
    pub fn set_local_keep(&mut self, fraction: f64, limits: &Limits) -> Result<()> {
        if !(0.0..=1.0).contains(&fraction) {
            return Err(RelightError::range(
                "local lighting fraction",
                fraction,
                "0..=1",
            ));
        }
        let cfg = *self.rotations.config();
        let m2 = cfg.m() * cfg.m();
        let terms = ((fraction * m2 as f64).round() as usize).min(m2);
        let count = cfg.normals * cfg.normals * terms;
        self._top_charge = Charge::default();
        self._top_charge = limits.check_alloc("local lighting terms", count as u64, 4)?;
        self.local_terms = terms;
        self.top = vec![0; count];
        self.select_top();
        self.forget_pairs();
        Ok(())
    }

    /// Empties the pair table after a change of lighting, BRDF or keep.
    fn forget_pairs(&mut self) {
        if let Some(p) = &mut self.pairs {
            p.clear();
        }
    }

    /// Refreshes every grid normal's list of largest local terms.
    fn select_top(&mut self) {
        let (k, m2) = (self.local_terms, self.rotations.config().m().pow(2));
        if k == 0 {
            return;
        }
        self.top
            .par_chunks_mut(k)
            .zip(self.local.par_chunks(m2))
            .for_each(|(top, local)| {
                let mag = |i: u32| local[i as usize].iter().map(|v| v.abs()).sum::<f32>();
                let mut order: Vec<u32> = (0..m2 as u32).collect();
                if k < m2 {
                    order.select_nth_unstable_by(k, |&a, &b| mag(b).total_cmp(&mag(a)));
                }
                order.truncate(k);
                order.sort_unstable();
                top.copy_from_slice(&order);
            });
    }

    /// The rotation matrices.
    pub fn rotations(&self) -> &RotationSet {
        &self.rotations
    }

    /// Switches the BRDF: no rotation or lighting is recomputed.
    pub fn set_brdf(&mut self, slices: Arc<BrdfSlices>) -> Result<()> {
        check_slices(&self.rotations, &slices)?;
        let resize = self.pairs.is_some() && slices.config().views != self.slices.config().views;
        self.slices = slices;
        self.forget_pairs();
        if resize {
            self.set_pair_table(true);
        }
        Ok(())
    }

    /// Step 1: `R(n)·L` for every grid normal, `L` the map's Haar
    /// coefficients, optionally only its `terms` largest.
    pub fn light(&mut self, map: &OctMap, terms: Option<usize>) -> Result<()> {
        let cfg = *self.rotations.config();
        if map.side() != cfg.n {
            let valid = format!("{} (the rotation set's n)", cfg.n);
            return Err(RelightError::range("lighting map side", map.side(), valid));
        }
        let light = map.haar(terms)?;
        let m2 = cfg.m() * cfg.m();
        self.local
            .par_chunks_mut(m2)
            .zip(self.rotations.matrices().par_iter())
            .for_each(|(out, mat)| mat.apply(&light, out));
        self.select_top();
        self.forget_pairs();
        Ok(())
    }

    /// The local lighting of grid normal `i` (`m²` RGB Haar coefficients).
    pub fn local(&self, i: usize) -> &[[f32; 3]] {
        let m2 = self.rotations.config().m().pow(2);
        &self.local[i * m2..(i + 1) * m2]
    }

    /// Sets how step 2 reads the slices between view texels (the pairs
    /// computed so far stay valid).
    pub fn set_view_filter(&mut self, filter: ViewFilter) {
        self.view_filter = filter;
    }

    /// The view filter.
    pub fn view_filter(&self) -> ViewFilter {
        self.view_filter
    }

    /// Step 2: outgoing radiance at a surface point of unit `normal` seen
    /// from unit direction `view` (towards the viewer), both global: for
    /// each of the four grid normals around `normal`, the slice of a view
    /// in that normal's frame (the view grid read as [`ViewFilter`] says)
    /// dotted with its local lighting, blended bilinearly.
    ///
    /// The view each grid normal `g` is shaded from is not `view` itself
    /// but the one that `g` mirrors into the same direction as `normal`
    /// mirrors `view`: `v' = 2(r·g)g − r`, `r = 2(v·n)n − v`. So all four
    /// put a glossy lobe's peak at the surface's own mirror direction, and
    /// blending moves no highlight (blending the plain view puts four
    /// copies of it up to twice the grid's spacing apart). At `g = normal`
    /// `v' = view`; a view-independent BRDF is unchanged.
    pub fn shade(&self, normal: DVec3, view: DVec3) -> [f32; 3] {
        let cfg = self.rotations.config();
        let mirror = 2.0 * view.dot(normal) * normal - view;
        let mut out = [0.0f32; 3];
        for (i, w) in oct_bilinear(cfg.normals, normal) {
            if w == 0.0 {
                continue;
            }
            // The mirror of `mirror` about the frame's normal (its +z).
            let r = self.frames[i].to_local(mirror);
            let wo = DVec3::new(-r.x, -r.y, r.z);
            let views = match self.view_filter {
                ViewFilter::Nearest => {
                    let v = self.slices.view_index(wo);
                    [(v, 1.0), (v, 0.0), (v, 0.0), (v, 0.0)]
                }
                ViewFilter::Bilinear => self.slices.view_bilinear(wo),
            };
            for (v, wv) in views {
                if wv == 0.0 {
                    continue;
                }
                let radiance = match &self.pairs {
                    Some(table) => table.get(i, v, || self.pair(i, v)),
                    None => self.pair(i, v),
                };
                let weight = (w * wv) as f32;
                (0..3).for_each(|c| out[c] += weight * radiance[c]);
            }
        }
        out
    }

    /// The radiance of grid normal `i` seen from view texel `v`: the
    /// slice's kept terms dotted with the local lighting, plus its residual
    /// at the lighting's largest terms.
    fn pair(&self, i: usize, v: usize) -> [f32; 3] {
        let k = self.local_terms;
        let b = self.slices.dot(v, self.local(i));
        let r = self
            .slices
            .residual_dot(v, self.local(i), &self.top[i * k..(i + 1) * k]);
        [0, 1, 2].map(|c| b[c] + r[c])
    }

    /// With `on`, a new, empty table of step 2's radiance per (grid normal,
    /// view texel) pair (a shader starts with one): each pair is computed
    /// on first use and read back until the lighting, the BRDF or the keep
    /// changes, so a view change costs only the pairs that earlier views
    /// did not use. Without it, step 2 computes every pair where it is
    /// used, with the same result. The table takes `normals² · views² ·
    /// 12` bytes, charged to the shader's limits; returns whether one is in
    /// use (not where it would exceed [`MAX_PAIR_TABLE_BYTES`] or the
    /// limits).
    ///
    /// [`MAX_PAIR_TABLE_BYTES`]: super::MAX_PAIR_TABLE_BYTES
    pub fn set_pair_table(&mut self, on: bool) -> bool {
        self.pairs = None;
        if on {
            let views = self.slices.config().views;
            self.pairs = PairTable::new(self.frames.len(), views * views, &self.limits);
        }
        self.pairs.is_some()
    }

    /// How many pairs the table keeps (`None` without one).
    #[cfg(test)]
    pub(crate) fn pairs_kept(&self) -> Option<u32> {
        self.pairs.as_ref().map(PairTable::kept)
    }
}

/// Step 2 at one surface point seen from `eye`: zero where the point is
/// not on the surface or its normal or view is degenerate. A point facing
/// away from the eye is shaded as seen from its horizon (the view moved
/// onto it), so that texels blended across a silhouette stay continuous.
fn shade_point(shader: &Shader, p: &SurfacePoint, eye: DVec3) -> [f32; 3] {
    let position = DVec3::from(p.position.map(f64::from));
    let normal = DVec3::from(p.normal.map(f64::from)).normalize_or_zero();
    let view = (eye - position).normalize_or_zero();
    if !p.valid || normal == DVec3::ZERO || view == DVec3::ZERO {
        return [0.0; 3];
    }
    // Truncated Haar terms can ring below zero; radiance cannot.
    shader.shade(normal, view).map(|v| v.max(0.0))
}

impl Shader {
    /// Step 2 for every point of a surface seen from `eye` (world space),
    /// in parallel, into `out` (one RGB radiance per point): the view
    /// direction is the point's own, so highlights follow a perspective
    /// camera. Points not on the surface get zero; points facing away from
    /// the eye are shaded as seen from their horizon; negative values (the
    /// ringing of truncated Haar terms) are clamped to zero.
    pub fn shade_points(
        &self,
        points: &[SurfacePoint],
        eye: DVec3,
        out: &mut [[f32; 3]],
    ) -> Result<()> {
        if out.len() != points.len() {
            let valid = format!("{} (one per surface point)", points.len());
            return Err(RelightError::range("shaded outputs", out.len(), valid));
        }
        if !eye.is_finite() {
            return Err(RelightError::Invalid(format!(
                "the eye {eye} is not finite"
            )));
        }
        out.par_iter_mut()
            .zip(points.par_iter())
            .for_each(|(o, p)| *o = shade_point(self, p, eye));
        Ok(())
    }
}

fn check_slices(rotations: &RotationSet, slices: &BrdfSlices) -> Result<()> {
    let m = rotations.config().m();
    if slices.config().m != m {
        let valid = format!("{m} (the rotation set's n/2)");
        return Err(RelightError::range(
            "BRDF slice side m",
            slices.config().m,
            valid,
        ));
    }
    Ok(())
}
