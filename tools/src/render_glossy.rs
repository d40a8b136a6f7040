//! `ltm render --brdf`: a glossy material drawn by wavelet rotation (Wang
//! et al. 2006; `ltm_relight::rotation`) on top of, or instead of, the
//! file's relit transport. The rotation matrices depend only on the
//! lighting map's side, the normal grid and the truncation, so they are
//! built once (or read from `--rotation-cache`) and serve every BRDF; the
//! lighting is projected once per run (step 1) and every view shades every
//! texel from its own eye direction (step 2).

use anyhow::{bail, Context, Result};
use clap::{Args, ValueEnum};
use glam::DVec3;
use ltm_codec::{Limits, SurfacePoint};
use ltm_relight::rotation::{
    Brdf, BrdfSlices, CacheUse, OctMap, RotationConfig, RotationSet, Shader, SliceConfig,
    ViewFilter,
};
use ltm_relight::{EnvMap, Image, Rotation};
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

/// Octahedral sub-samples per lighting texel and side when the map is
/// projected from the cubemap.
pub(crate) const LIGHT_SUPERSAMPLE: usize = 16;

/// What a view draws when `--brdf` is given.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Shading {
    /// The file's relit transport (its baked material, with all-frequency
    /// shadows and interreflections as baked) plus the glossy BRDF's
    /// reflection of the distant lighting (unshadowed), as a clear coat.
    Sum,
    /// The glossy BRDF's reflection alone (unshadowed): the file supplies
    /// only the surface (positions and normals).
    Glossy,
}

/// `--view-filter`: how step 2 reads the BRDF slices between view texels.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum ViewFilterArg {
    /// The four view texels around each view direction, blended.
    Bilinear,
    /// The view texel each direction falls in.
    Nearest,
}

impl From<ViewFilterArg> for ViewFilter {
    fn from(f: ViewFilterArg) -> ViewFilter {
        match f {
            ViewFilterArg::Bilinear => ViewFilter::Bilinear,
            ViewFilterArg::Nearest => ViewFilter::Nearest,
        }
    }
}

/// The glossy material's flags of `ltm render`.
#[derive(Args)]
pub struct GlossyArgs {
    /// Add a glossy material, shaded per view by wavelet rotation (Wang et
    /// al. 2006), so highlights move with the camera. SPEC:
    /// `lambert[:ALBEDO]` | `ggx:ALPHA[,f0=F0]` | `phong:EXPONENT[,specular=S]`
    /// | `plastic:ALPHA[,albedo=A][,ior=IOR]`; colours are grey or r/g/b, e.g.
    /// ggx:0.2,f0=0.95/0.64/0.54 (gold-like). Defaults: albedo 0.8, F0 0.9,
    /// S 1, plastic albedo 0.5 and IOR 1.5. Or merl:PATH, a measured BRDF
    /// file in the MERL database's binary layout (90×90×180 bins).
    #[arg(long, value_name = "SPEC")]
    pub brdf: Option<String>,
    /// With --brdf: `sum` draws the relit transport plus the glossy
    /// reflection; `glossy` draws the glossy reflection alone.
    #[arg(long, value_enum, default_value = "sum", requires = "brdf")]
    pub shading: Shading,
    /// Side n of the octahedral lighting map the rotation works on: a power
    /// of two, 8 to 128 [default: what the BRDF needs: 64 for Lambert and
    /// lobes of α ≥ 0.4, else 128]. The error against Mitsuba 3 follows
    /// n·α (1.2 % at 32, 1.6 % at 25.6, 3–4 % at 12.8, 9 % at 6.4), and
    /// time and memory grow about 4× per doubling: n = 64 takes 0.3 GB of
    /// rotation matrices built in about 6 s on 2 cores, n = 128 1.4 GB in
    /// about 28 s (--rotation-cache keeps them), and step 1 and step 2
    /// (at the same --brdf-keep and --local-keep) about 4× longer
    /// (docs/results/glossy.md).
    #[arg(long, value_name = "N", requires = "brdf")]
    pub glossy_n: Option<usize>,
    /// Side of the octahedral grid of normals with a rotation matrix each
    /// (1 to 256); shading blends the four around each normal.
    #[arg(long, default_value_t = 32, value_name = "SIDE", requires = "brdf")]
    pub normals: usize,
    /// Fraction of each BRDF view slice's Haar terms kept, in (0, 1]
    /// [default: 0.03 for lobes of α < 0.4 at n = 128, else 0.1].
    /// With --local-keep, a sharp lobe at n = 128 is as close to Mitsuba 3
    /// at 0.03 as at 0.1 and shades 2.9× faster; broad lobes and Lambert
    /// need 0.1 under a smooth sky (docs/results/glossy.md).
    #[arg(long, value_name = "FRACTION", requires = "brdf")]
    pub brdf_keep: Option<f64>,
    /// Fraction of each grid normal's local-lighting Haar terms, the
    /// largest, that shading also dots with what the BRDF slice did not
    /// keep, in [0, 1] [default: as --brdf-keep]: a term is then dropped
    /// only where both the slice and the lighting are small, which keeps a
    /// sun or a small lamp exact. 0 uses the slice's kept terms alone.
    #[arg(long, value_name = "FRACTION", requires = "brdf")]
    pub local_keep: Option<f64>,
    /// Side of the hemi-octahedral grid of view directions with a BRDF
    /// slice each (1 to 256).
    #[arg(long, default_value_t = 64, value_name = "SIDE", requires = "brdf")]
    pub brdf_views: usize,
    /// How step 2 reads the BRDF slices for a view direction between the
    /// view grid's texels: `bilinear` blends the four around it; `nearest`
    /// takes the one it falls in, which is faster but steps where the
    /// direction crosses a texel's edge. A sharp lobe shows the steps: a
    /// conductor of α = 0.1 on a sphere is 6.0 % from Mitsuba 3 with
    /// `nearest`, 2.7 % with `bilinear` (docs/results/glossy.md).
    #[arg(long, value_enum, default_value = "bilinear", requires = "brdf")]
    pub view_filter: ViewFilterArg,
    /// Largest Haar terms of the lighting kept in step 1 [default: all].
    #[arg(long, value_name = "N", requires = "brdf")]
    pub glossy_terms: Option<usize>,
    /// Rotation cache: read when it holds the matrices of these settings,
    /// else built and written there (a file of other settings is replaced;
    /// a file that is not a rotation cache is refused). An existing folder
    /// keeps one file per setting in it (rotation-n64-normals32-ss16-t1.bin
    /// and so on), so materials that need different sides each keep
    /// theirs. Without it the matrices are built in memory on every run.
    #[arg(long, value_name = "PATH", requires = "brdf")]
    pub rotation_cache: Option<PathBuf>,
}

/// The glossy part of a render, lit and ready to shade views.
pub struct Glossy {
    shader: Shader,
    points: Vec<SurfacePoint>,
    shading: Shading,
    brdf: Brdf,
    /// Set-up times in ms: rotation matrices (built or read), BRDF slices,
    /// step 1.
    pub setup_ms: [f64; 3],
    /// Where the rotation matrices came from.
    pub source: &'static str,
    /// Whether n was chosen for the BRDF (no `--glossy-n`).
    n_chosen: bool,
}

fn ms(start: Instant) -> f64 {
    start.elapsed().as_secs_f64() * 1e3
}

impl GlossyArgs {
    /// The `--brdf` material, if any (a `merl:` table read and charged to
    /// `limits`), after every glossy setting is checked: called before any
    /// work, so that a bad value fails at once.
    pub fn material(&self, limits: &Limits) -> Result<Option<Brdf>> {
        let Some(spec) = &self.brdf else {
            return Ok(None);
        };
        let brdf = Brdf::from_spec(spec, limits).with_context(|| format!("--brdf {spec}"))?;
        self.check(&brdf)?;
        Ok(Some(brdf))
    }

    /// Checks the rotation and slice settings (messages name the flag's
    /// value and its valid range).
    fn check(&self, brdf: &Brdf) -> Result<()> {
        let cfg = self.rotation_config(brdf);
        if !cfg.n.is_power_of_two() || cfg.n < 8 || cfg.n > 128 {
            bail!(
                "--glossy-n {} is out of range (valid: a power of two, 8..=128)",
                cfg.n
            );
        }
        cfg.validate()?;
        self.slice_config(cfg.n, brdf).validate()?;
        Ok(())
    }

    /// The kept fractions of slice and local-lighting terms: the flags',
    /// or what `brdf` needs.
    pub(crate) fn kept(&self, brdf: &Brdf) -> (f64, f64) {
        let (keep, local) = brdf.kept_fractions(self.rotation_config(brdf).n);
        (
            self.brdf_keep.unwrap_or(keep),
            self.local_keep.unwrap_or(local),
        )
    }

    pub(crate) fn slice_config(&self, n: usize, brdf: &Brdf) -> SliceConfig {
        let (keep, local) = self.kept(brdf);
        SliceConfig {
            m: n / 2,
            keep,
            views: self.brdf_views,
            residuals: local > 0.0,
            ..SliceConfig::default()
        }
    }

    /// The measured BRDF file `--brdf merl:PATH` names.
    pub fn measured_file(&self) -> Option<&std::path::Path> {
        let spec = self.brdf.as_deref()?;
        spec.strip_prefix("merl:").map(std::path::Path::new)
    }

    /// The rotation settings: `--glossy-n`, or the side `brdf` needs.
    fn rotation_config(&self, brdf: &Brdf) -> RotationConfig {
        RotationConfig {
            n: self.glossy_n.unwrap_or_else(|| brdf.lighting_side()),
            normals: self.normals,
            ..RotationConfig::default()
        }
    }

    /// The rotation cache file for `brdf`, if `--rotation-cache` is given:
    /// the path itself, or, where it is a folder, one file in it per
    /// setting, so that BRDFs that need different sides each keep theirs.
    pub fn cache_path(&self, brdf: &Brdf) -> Option<PathBuf> {
        let path = self.rotation_cache.as_deref()?;
        if !path.is_dir() {
            return Some(path.to_path_buf());
        }
        let cfg = self.rotation_config(brdf);
        Some(path.join(format!(
            "rotation-n{}-normals{}-ss{}-t{}.bin",
            cfg.n, cfg.normals, cfg.supersample, cfg.threshold
        )))
    }

    pub(crate) fn rotations(
        &self,
        brdf: &Brdf,
        limits: &Limits,
    ) -> Result<(RotationSet, &'static str)> {
        let cfg = self.rotation_config(brdf);
        let Some(path) = &self.cache_path(brdf) else {
            return Ok((RotationSet::build(cfg, limits)?, "built"));
        };
        let (set, used) = RotationSet::cached(cfg, path, limits)
            .with_context(|| format!("rotation cache {}", path.display()))?;
        let source = match used {
            CacheUse::Read => "read from the cache",
            CacheUse::Replaced => "built (replacing a cache of other settings or a damaged one)",
            _ => "built and cached",
        };
        Ok((set, source))
    }
}

impl Glossy {
    /// Builds (or reads) the rotations, builds the BRDF's slices and lights
    /// every grid normal with `env` under `rotate`.
    pub fn prepare(
        a: &GlossyArgs,
        brdf: Brdf,
        points: Vec<SurfacePoint>,
        env: &EnvMap,
        rotate: &Rotation,
        limits: &Limits,
    ) -> Result<Glossy> {
        let start = Instant::now();
        let (rotations, source) = a.rotations(&brdf, limits)?;
        let rotations_ms = ms(start);
        let n = rotations.config().n;
        let start = Instant::now();
        let slice_cfg = a.slice_config(n, &brdf);
        let slices = BrdfSlices::build(brdf.clone(), slice_cfg, limits)?;
        let slices_ms = ms(start);
        let start = Instant::now();
        // The lighting the transport sees (same rotation and cube
        // convention), at a face resolution of n.
        let cube = env.to_cubemap(n, rotate);
        let map = OctMap::from_cubemap(n, LIGHT_SUPERSAMPLE, n, &cube)?;
        let mut shader = Shader::new(Arc::new(rotations), Arc::new(slices), limits)?;
        shader
            .set_local_keep(a.kept(&brdf).1, limits)
            .context("--local-keep")?;
        shader.set_view_filter(a.view_filter.into());
        shader.light(&map, a.glossy_terms)?;
        Ok(Glossy {
            shader,
            points,
            shading: a.shading,
            brdf,
            setup_ms: [rotations_ms, slices_ms, ms(start)],
            source,
            n_chosen: a.glossy_n.is_none(),
        })
    }

    /// The texture a view from `eye` draws: the relit `base` plus (or
    /// replaced by) every texel's glossy reflection toward `eye`.
    pub fn texture(&self, base: &Image, eye: DVec3) -> Result<Image> {
        let mut out = Image::new(base.width, base.height);
        self.shader.shade_points(&self.points, eye, &mut out.data)?;
        if self.shading == Shading::Sum {
            for (o, b) in out.data.iter_mut().zip(&base.data) {
                (0..3).for_each(|c| o[c] += b[c]);
            }
        }
        Ok(out)
    }

    /// One line for the run's summary.
    pub fn describe(&self) -> String {
        let [rot, slices, light] = self.setup_ms;
        let cfg = self.shader_config();
        let chosen = match self.n_chosen {
            true => " (the side this BRDF needs; --glossy-n sets it)",
            false => "",
        };
        format!(
            "glossy {} ({:?}, n = {}{chosen}, {}² normals): rotation matrices {} in {:.0} ms, BRDF slices {slices:.0} ms, lighting (step 1) {light:.1} ms",
            self.brdf, self.shading, cfg.n, cfg.normals, self.source, rot
        )
    }

    fn shader_config(&self) -> RotationConfig {
        *self.shader.rotations().config()
    }

    /// The BRDF.
    pub fn brdf(&self) -> &Brdf {
        &self.brdf
    }
}
