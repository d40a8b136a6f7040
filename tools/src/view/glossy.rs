//! Glossy materials in `ltm view` (`--brdf`, repeatable): the page's
//! material menu for texture-space files (and image-space ones, each pixel
//! seen from the eye its surface records fix). A frame asked for with
//! `brdf=K` (K ≥ 1) and `eye=x,y,z` is what `ltm render --brdf SPEC
//! --shading sum` draws from that eye: the relit texture plus every
//! texel's glossy reflection toward the eye, by wavelet rotation (Wang et
//! al. 2006, [`ltm_relight::rotation`]).
//!
//! One rotation set serves every material (built, or read from
//! `--rotation-cache`, on the first glossy frame). Each material's BRDF
//! slices are built on its first use and kept. Each file keeps one shader:
//! step 1 runs again only when the file's lighting changes (the local
//! lightings do not depend on the BRDF: a new material takes its slices
//! and its largest local terms), and step 2 on every frame, its pair table
//! keeping the pairs of earlier views, so orbiting the mesh costs step 2
//! alone.

use super::state::lock;
use crate::render_glossy::{self, GlossyArgs, Shading, ViewFilterArg};
use anyhow::{Context, Result};
use glam::DVec3;
use ltm_codec::{Limits, SurfacePoint};
use ltm_relight::rotation::{Brdf, BrdfSlices, OctMap, RotationSet, Shader};
use ltm_relight::Image;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// One entry of the menu.
struct Material {
    /// The spec as given (`ggx:0.2`).
    spec: String,
    brdf: Brdf,
    /// The flags `ltm render` would take for it.
    args: GlossyArgs,
    /// Built on first use.
    slices: Mutex<Option<Arc<BrdfSlices>>>,
}

/// A file's shader and what it was lit with.
struct FileShader {
    shader: Shader,
    /// The lighting of step 1 (none yet: `None`).
    lit: Option<LightingKey>,
    /// The material shaded (none yet: `None`).
    material: Option<usize>,
}

/// A lighting: map index, the rotation's bits, and whether the cubemap is
/// the draft resampling.
pub type LightingKey = (usize, [u64; 3], bool);

/// The glossy materials and the state that serves them.
pub struct Materials {
    entries: Vec<Material>,
    /// The lighting map's side n, shared by every material.
    n: usize,
    rotations: Mutex<Option<Arc<RotationSet>>>,
    /// Per file.
    shaders: Vec<Mutex<Option<FileShader>>>,
    limits: Limits,
}

/// What a glossy frame cost.
pub struct GlossyTimes {
    /// Building or reading the rotations, building the material's slices
    /// and switching the file's shader to the material, where this frame
    /// did (else zero).
    pub setup: Duration,
    /// Step 1 (zero when the file's lighting was kept).
    pub step1: Duration,
    /// Step 2.
    pub step2: Duration,
    /// Whether the lighting was the draft resampling (the frame is then a
    /// draft, refined once the page's settings rest).
    pub draft: bool,
}

impl Materials {
    /// The menu of `specs` (each checked as `ltm render --brdf` checks it),
    /// for `files` files, at lighting side `n` (default: the largest that
    /// the materials need, as `ltm render` chooses for each).
    pub fn new(
        specs: &[String],
        n: Option<usize>,
        cache: Option<PathBuf>,
        files: usize,
        limits: &Limits,
    ) -> Result<Materials> {
        let mut entries = Vec::new();
        for spec in specs {
            let brdf = Brdf::from_spec(spec, limits).with_context(|| format!("--brdf {spec}"))?;
            entries.push((spec.clone(), brdf));
        }
        let n = n.unwrap_or_else(|| {
            let sides = entries.iter().map(|(_, b)| b.lighting_side());
            sides.max().unwrap_or(64)
        });
        let entries = entries
            .into_iter()
            .map(|(spec, brdf)| {
                let args = GlossyArgs {
                    brdf: Some(spec.clone()),
                    shading: Shading::Sum,
                    glossy_n: Some(n),
                    normals: 32,
                    brdf_keep: None,
                    local_keep: None,
                    brdf_views: 64,
                    view_filter: ViewFilterArg::Bilinear,
                    glossy_terms: None,
                    rotation_cache: cache.clone(),
                };
                args.material(limits)?;
                Ok(Material {
                    spec,
                    brdf,
                    args,
                    slices: Mutex::new(None),
                })
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Materials {
            entries,
            n,
            rotations: Mutex::new(None),
            shaders: (0..files).map(|_| Mutex::new(None)).collect(),
            limits: limits.clone(),
        })
    }

    /// The menu's specs (entry K of the API is `names()[K − 1]`).
    pub fn names(&self) -> Vec<&str> {
        self.entries.iter().map(|m| m.spec.as_str()).collect()
    }

    /// The lighting map's side.
    pub fn side(&self) -> usize {
        self.n
    }

    /// The rotation cache file the materials use, if `--rotation-cache`
    /// was given.
    pub fn cache_path(&self) -> Option<PathBuf> {
        let m = self.entries.first()?;
        m.args.cache_path(&m.brdf)
    }

    /// The measured BRDF files the menu reads (`merl:PATH`).
    pub fn measured_files(&self) -> Vec<&std::path::Path> {
        let files = self.entries.iter().filter_map(|m| m.args.measured_file());
        files.collect()
    }

    /// How many materials the menu holds (besides the baked one).
    pub fn count(&self) -> usize {
        self.entries.len()
    }

    /// The rotation set, built or read on first use.
    fn rotations(&self, m: &Material) -> Result<(Arc<RotationSet>, Duration)> {
        let mut kept = lock(&self.rotations);
        if let Some(r) = kept.as_ref() {
            return Ok((r.clone(), Duration::ZERO));
        }
        let t = Instant::now();
        let (set, _) = m.args.rotations(&m.brdf, &self.limits)?;
        let set = Arc::new(set);
        *kept = Some(set.clone());
        Ok((set, t.elapsed()))
    }

    /// Material `m`'s slices, built on first use.
    fn slices(&self, m: &Material) -> Result<(Arc<BrdfSlices>, Duration)> {
        let mut kept = lock(&m.slices);
        if let Some(s) = kept.as_ref() {
            return Ok((s.clone(), Duration::ZERO));
        }
        let t = Instant::now();
        let cfg = m.args.slice_config(self.n, &m.brdf);
        let s = Arc::new(BrdfSlices::build(m.brdf.clone(), cfg, &self.limits)?);
        *kept = Some(s.clone());
        Ok((s, t.elapsed()))
    }

    /// Adds material `k` (1-based) to `texture`, file `file`'s relit
    /// texture of surface `points`, seen from `eye`; `cubemap` is the
    /// lighting `lit` at face resolution [`Materials::side`] (the one the
    /// transport sees).
    pub fn add(
        &self,
        (file, points): (usize, &[SurfacePoint]),
        k: usize,
        (lit, cubemap): (LightingKey, &[[f32; 3]]),
        eye: DVec3,
        texture: &mut Image,
    ) -> Result<GlossyTimes> {
        let m = k.checked_sub(1).and_then(|i| self.entries.get(i));
        let m = m.with_context(|| format!("no material {k} (valid: 1..={})", self.count()))?;
        let mut state = lock(&self.shaders[file]);
        let mut setup = Duration::ZERO;
        let (slices, took) = self.slices(m)?;
        setup += took;
        if state.is_none() {
            let (rotations, took) = self.rotations(m)?;
            setup += took;
            let shader = Shader::new(rotations, slices.clone(), &self.limits)?;
            *state = Some(FileShader {
                shader,
                lit: None,
                material: None,
            });
        }
        let fs = state.as_mut().context("no shader")?;
        if fs.material != Some(k) {
            // The local lightings do not depend on the BRDF: a new material
            // takes its slices and its own largest local terms only.
            let t = Instant::now();
            fs.shader.set_brdf(slices)?;
            fs.shader
                .set_local_keep(m.args.kept(&m.brdf).1, &self.limits)?;
            fs.material = Some(k);
            setup += t.elapsed();
        }
        let mut step1 = Duration::ZERO;
        if fs.lit != Some(lit) {
            let t = Instant::now();
            let supersample = render_glossy::LIGHT_SUPERSAMPLE;
            let map = OctMap::from_cubemap(self.n, supersample, self.n, cubemap)?;
            fs.shader.light(&map, None)?;
            fs.lit = Some(lit);
            step1 = t.elapsed();
        }
        let t = Instant::now();
        let mut glossy = vec![[0.0f32; 3]; points.len()];
        fs.shader.shade_points(points, eye, &mut glossy)?;
        for (o, g) in texture.data.iter_mut().zip(&glossy) {
            (0..3).for_each(|c| o[c] += g[c]);
        }
        Ok(GlossyTimes {
            setup,
            step1,
            step2: t.elapsed(),
            draft: lit.2,
        })
    }
}
