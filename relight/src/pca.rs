//! Relighting `pca` files (Eigentransport, Nowrouzezahrai et al. 2007):
//! `T̂[p] = μ + Σ_a F[p][a]·B[a]`, so a frame projects the lighting once on
//! the mean row and the first `k` eigen-transports (`l_a[c] = Σ_j
//! B[a][j, c]·L[j][c]`, a `k × 3` table) and each pixel is one `k`-term dot
//! product of its coefficients per colour channel. Grey files (`C = 1`)
//! project each light channel on the same basis, then multiply the albedo.
//!
//! The coefficients are held in component blocks of pixel tiles
//! ([`crate::pca_blocks`]), so a frame with the first `k` components streams
//! just those, 24 pixels at a time with fused vector multiply-adds;
//! [`PcaRelighter::relight_scalar`] is the plain f64 loop it is tested
//! against.

use crate::error::{RelightError, Result};
use crate::frame::{check_light, Frame, FrameStats, Relight, Request, TermBasis};
use crate::image_io::Image;
use crate::open::Source;
use crate::pca_blocks::{Blocks, Path as DotPath};
use crate::point::{point_light_taps, Lookup, PointLight, SurfaceSample, Taps};
use ltm_codec::{Charge, Dims, LightBasis, Limits, LtmFile};
use rayon::prelude::*;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::OnceLock;
use std::time::Instant;

/// A `pca` file ready to relight: the [`Relight`] implementation for
/// Eigentransport. [`Request::terms`] is the number of eigen-transports
/// used (the first `terms`, at most the rank stored); the weighting is
/// ignored. Immutable and `Sync`.
pub struct PcaRelighter {
    dims: Dims,
    rank: usize,
    /// `μ`, `N = M·C` values.
    mean: Vec<f32>,
    /// `K × N` decoded eigen-transports.
    basis: Vec<f32>,
    /// The decoded coefficients in component blocks.
    coefficients: Blocks,
    /// The compiled dot-product loop this CPU runs.
    path: DotPath,
    albedo: Option<Vec<f32>>,
    /// Rows that decode to exactly 0 (chunk EMPT): black pixels.
    empty: Option<ltm_codec::EmptyRows>,
    /// Per-row surface samples (chunk SURF), for point lights.
    surface: Option<Vec<SurfaceSample>>,
    /// `N × K` the basis transposed (column `i` of `B` contiguous), made
    /// by the first point light (the same size as `basis`).
    basis_t: OnceLock<Vec<f32>>,
    /// The budget the file, these buffers and every frame are charged to.
    limits: Limits,
    /// The buffers' bytes, charged to `limits`.
    _charge: Charge,
}

/// The scratch a [`PcaRelighter`] keeps in a [`Frame`].
struct PcaScratch {
    /// The lighting projected on the mean and the components (RGB each).
    projected: Vec<[f64; 3]>,
    /// The projected lighting in f32, one plane per colour channel.
    planar: Vec<f32>,
}

impl PcaRelighter {
    /// Opens a `pca` file, from a path or from bytes in memory, charging
    /// it and the relighter's buffers to `limits`.
    pub fn open(source: impl Into<Source>, limits: &Limits) -> Result<PcaRelighter> {
        PcaRelighter::new(&source.into().open(limits)?, limits)
    }

    /// [`PcaRelighter::open`] of a path.
    pub fn open_with_limits(path: &Path, limits: &Limits) -> Result<PcaRelighter> {
        PcaRelighter::open(path, limits)
    }

    /// Prepares a relighter for an opened `pca` file: copies what it needs
    /// (the file may be dropped after), charging the decoded coefficients
    /// and basis to `limits`, whose clone it keeps for its frames.
    pub fn new(file: &LtmFile, limits: &Limits) -> Result<PcaRelighter> {
        let Some(model) = file.pca() else {
            return Err(RelightError::Invalid(format!(
                "a {} file has no PCA basis: open it with ltm_relight::open (or Relighter)",
                file.meta().mode.name()
            )));
        };
        let dims = model.dims();
        let rank = model.rank();
        let padded = Blocks::padded_len(dims.pixels(), rank);
        let coefficients = limits.check_alloc("PCA coefficients", padded as u64, 2)?;
        // The basis, and its transpose for point lights where they can be
        // used (a file with surface data).
        let copies = 1 + u64::from(file.surface().is_some());
        let basis = limits.check_alloc("PCA basis", (dims.row_len() * rank) as u64, 4 * copies)?;
        let per_row = 12
            + file
                .surface()
                .map_or(0, |_| std::mem::size_of::<SurfaceSample>());
        let rows = limits.check_alloc(
            "PCA mean, albedo and surface",
            dims.pixels() as u64,
            per_row as u64,
        )?;
        Ok(PcaRelighter {
            limits: limits.clone(),
            _charge: coefficients.join(basis).join(rows),
            dims,
            rank,
            mean: model.mean().to_vec(),
            basis: model.basis().dequantize(),
            basis_t: OnceLock::new(),
            empty: model.empty_rows().cloned(),
            coefficients: blocks(model),
            path: DotPath::detect(),
            albedo: file.albedo().map(<[f32]>::to_vec),
            surface: file
                .surface()
                .map(|s| s.points().iter().map(|&p| p.into()).collect()),
        })
    }

    /// The rank `K` stored.
    pub fn rank(&self) -> usize {
        self.rank
    }

    /// A frame's buffers (of the rank's size: a few hundred bytes).
    fn scratch(&self) -> PcaScratch {
        PcaScratch {
            projected: Vec::with_capacity(self.rank + 1),
            planar: Vec::with_capacity(3 * self.rank),
        }
    }

    fn check_terms(&self, terms: usize) -> Result<usize> {
        if terms > self.rank {
            return Err(RelightError::range(
                "eigen-transports",
                terms,
                format!("0..={} (the rank stored)", self.rank),
            ));
        }
        Ok(terms)
    }

    /// `row · L` per light channel for one `N`-value row, in f64 with four
    /// partial sums per channel (texels `j mod 4`) added at the end.
    fn project_row(&self, row: &[f32], light: &[[f32; 3]]) -> [f64; 3] {
        let c = self.dims.channels as usize;
        let mut acc = [[0.0f64; 3]; 4];
        let add = |a: &mut [f64; 3], v: &[f32], l: &[f32; 3]| {
            for ch in 0..3 {
                a[ch] += v[ch.min(c - 1)] as f64 * l[ch] as f64;
            }
        };
        let lights = light.chunks_exact(4);
        let tail = lights.remainder();
        for (l4, v4) in lights.zip(row.chunks_exact(4 * c)) {
            for (t, a) in acc.iter_mut().enumerate() {
                add(a, &v4[t * c..t * c + c], &l4[t]);
            }
        }
        let rest = &row[(light.len() - tail.len()) * c..];
        for ((a, l), v) in acc.iter_mut().zip(tail).zip(rest.chunks_exact(c)) {
            add(a, v, l);
        }
        [0, 1, 2].map(|ch| (acc[0][ch] + acc[1][ch]) + (acc[2][ch] + acc[3][ch]))
    }

    /// The mean's and the first `k` components' projections: entry 0 is the
    /// mean, entry `1 + a` component `a`.
    fn project(&self, light: &[[f32; 3]], k: usize, out: &mut Vec<[f64; 3]>) {
        let n = self.dims.row_len();
        out.resize(k + 1, [0.0; 3]);
        out.par_iter_mut().enumerate().for_each(|(i, o)| {
            *o = if i == 0 {
                self.project_row(&self.mean, light)
            } else {
                self.project_row(&self.basis[(i - 1) * n..i * n], light)
            };
        });
    }

    /// The pixel's value times its albedo; 0 for an empty row.
    #[inline]
    fn albedo_times(&self, p: usize, mut v: [f64; 3]) -> [f32; 3] {
        if self.empty.as_ref().is_some_and(|e| e.is_empty_row(p)) {
            return [0.0; 3];
        }
        if let Some(a) = &self.albedo {
            for (c, x) in v.iter_mut().enumerate() {
                *x *= a[3 * p + c] as f64;
            }
        }
        v.map(|x| x as f32)
    }

    /// The reference: the same frame with plain f64 loops.
    pub fn relight_scalar(&self, light: &[[f32; 3]], terms: usize) -> Result<Image> {
        check_light(light, self.lights(), self.dims.face_res())?;
        let k = self.check_terms(terms)?;
        let mut projected = Vec::new();
        self.project(light, k, &mut projected);
        let (w, h) = self.size();
        let mut image = Image::new(w, h);
        let mut f = Vec::with_capacity(k);
        for (p, px) in image.data.iter_mut().enumerate() {
            self.coefficients.row(p, k, &mut f);
            let mut v = projected[0];
            for (a, &fa) in f.iter().enumerate() {
                for (vc, lc) in v.iter_mut().zip(projected[1 + a]) {
                    *vc += fa as f64 * lc;
                }
            }
            *px = self.albedo_times(p, v);
        }
        Ok(image)
    }

    /// The image under a local point light (Eigentransport §4.2.1): each
    /// row evaluated with its first `terms` components at the texels its
    /// surface sample sees the light through ([`point_light_taps`]), times
    /// the light's intensity (and the albedo). `samples` has one entry per
    /// pixel.
    pub fn relight_point(
        &self,
        samples: &[SurfaceSample],
        light: &PointLight,
        lookup: Lookup,
        terms: usize,
    ) -> Result<Image> {
        self.relight_points_at(samples, std::slice::from_ref(light), lookup, terms)
    }

    /// The image under several point lights (their sum), at the surface
    /// data stored in the file (chunk `SURF`, copied from the raw store by
    /// `compress --mode pca`). Refuses a file without surface data, and
    /// every light [`point_light_taps`] refuses, naming the light.
    pub fn relight_points(
        &self,
        lights: &[PointLight],
        lookup: Lookup,
        terms: usize,
    ) -> Result<Image> {
        let Some(samples) = &self.surface else {
            return Err(RelightError::Invalid(
                "this pca file has no per-row surface data (chunk SURF), which point lights need: bake the scene with this version of ltm (image and texture bakes store each row's surface point) and compress it again with --mode pca".into(),
            ));
        };
        self.relight_points_at(samples, lights, lookup, terms)
    }

    /// The per-row surface samples stored in the file, if any.
    pub fn surface(&self) -> Option<&[SurfaceSample]> {
        self.surface.as_deref()
    }

    fn relight_points_at(
        &self,
        samples: &[SurfaceSample],
        lights: &[PointLight],
        lookup: Lookup,
        terms: usize,
    ) -> Result<Image> {
        let k = self.check_terms(terms)?;
        if samples.len() != self.dims.pixels() {
            return Err(RelightError::range(
                "surface samples",
                samples.len(),
                format!("{} (one per pixel)", self.dims.pixels()),
            ));
        }
        let (w, h) = self.size();
        let mut image = Image::new(w, h);
        for (i, light) in lights.iter().enumerate() {
            let taps = point_light_taps(samples, light, self.dims.face_res() as usize, lookup)
                .map_err(|e| RelightError::Invalid(format!("point light {}: {e}", i + 1)))?;
            self.add_point(&taps, light, k, &mut image);
        }
        if let Some((x, y)) = image.first_non_finite() {
            return Err(RelightError::Invalid(format!(
                "relit pixel ({x}, {y}) is not finite (exceeds the f32 range)"
            )));
        }
        Ok(image)
    }

    /// Adds one point light's rows (first `k` components at `taps`) to
    /// `image`: per tap, the row's value at that texel is `μ[i] + F[p]·B[·][i]`,
    /// a `k`-term dot product with column `i` of the basis (held
    /// texel-major for this, `basis_t`), once per stored channel.
    fn add_point(&self, taps: &[Taps], light: &PointLight, k: usize, image: &mut Image) {
        let c = self.dims.channels as usize;
        let basis_t = self
            .basis_t
            .get_or_init(|| transpose(&self.basis, self.rank, self.dims.row_len()));
        image
            .data
            .par_iter_mut()
            .enumerate()
            .for_each_init(Vec::new, |f, (p, px)| {
                self.coefficients.row(p, k, f);
                let mut v = [0.0f64; 3];
                for &(j, wt) in taps[p].iter().filter(|t| t.1 != 0.0) {
                    let mut t = [0.0f64; 3];
                    for (ch, tc) in t.iter_mut().enumerate().take(c) {
                        let i = j as usize * c + ch;
                        let col = &basis_t[i * self.rank..i * self.rank + k];
                        let dot: f32 = f.iter().zip(col).map(|(a, b)| a * b).sum();
                        *tc = self.mean[i] as f64 + dot as f64;
                    }
                    for (ch, o) in v.iter_mut().enumerate() {
                        *o += t[ch.min(c - 1)] * wt as f64 * light.intensity[ch] as f64;
                    }
                }
                for (o, v) in px.iter_mut().zip(self.albedo_times(p, v)) {
                    *o += v;
                }
            });
    }

    /// Every pixel's dot product of its first `k` coefficients with the
    /// planar projected lighting ([`Blocks::scaled_light`]), plus the mean's
    /// projection `base`.
    /// Returns whether every pixel is finite.
    fn dot_rows(&self, planar: &[f32], k: usize, base: [f64; 3], image: &mut Image) -> bool {
        let finite = AtomicBool::new(true);
        self.coefficients
            .dot_rows(self.path, planar, k, &mut image.data, |p0, pixels| {
                if !self.finish_rows(p0, pixels, base) {
                    finite.store(false, Ordering::Relaxed);
                }
            });
        finite.into_inner()
    }

    /// Pixels `p0 ..` from their dot products: plus `base`, times the
    /// albedo (in f64, rounded once, as [`PcaRelighter::albedo_times`]), 0
    /// in empty rows. Returns whether all are finite. Written as straight
    /// loops over slices, which the compiler vectorizes.
    fn finish_rows(&self, p0: usize, pixels: &mut [[f32; 3]], base: [f64; 3]) -> bool {
        let plus = |v: &[f32; 3]| [0, 1, 2].map(|c| base[c] + v[c] as f64);
        match &self.albedo {
            Some(a) => {
                let a = &a[3 * p0..3 * (p0 + pixels.len())];
                for (v, a) in pixels.iter_mut().zip(a.chunks_exact(3)) {
                    let x = plus(v);
                    *v = [0, 1, 2].map(|c| (x[c] * a[c] as f64) as f32);
                }
            }
            None => pixels
                .iter_mut()
                .for_each(|v| *v = plus(v).map(|x| x as f32)),
        }
        if let Some(e) = &self.empty {
            for (p, v) in (p0..).zip(pixels.iter_mut()) {
                if e.is_empty_row(p) {
                    *v = [0.0; 3];
                }
            }
        }
        pixels.iter().flatten().all(|x| x.is_finite())
    }

    /// Bytes of coefficients a frame with `terms` components reads.
    pub fn coefficient_bytes(&self, terms: usize) -> usize {
        self.coefficients.bytes_read(terms)
    }
}

impl Relight for PcaRelighter {
    fn light_basis(&self) -> LightBasis {
        self.dims.lights
    }

    /// Principal components (eigen-transports).
    fn term_basis(&self) -> TermBasis {
        TermBasis::Linear
    }

    fn size(&self) -> (usize, usize) {
        (self.dims.width() as usize, self.dims.height() as usize)
    }

    /// The rank stored.
    fn max_terms(&self) -> usize {
        self.rank
    }
    fn held_bytes(&self) -> usize {
        4 * (self.mean.len() + self.basis.len() + self.basis_t.get().map_or(0, Vec::len))
            + self.coefficients.held_bytes()
            + self.albedo.as_ref().map_or(0, |a| 4 * a.len())
            + self
                .surface
                .as_ref()
                .map_or(0, |s| s.len() * std::mem::size_of::<SurfaceSample>())
    }

    fn frame(&self) -> Result<Frame> {
        let (w, h) = self.size();
        let mut frame = Frame::default();
        frame.fit_image(w, h, &self.limits)?;
        frame.scratch(|_: &PcaScratch| false, || Ok(self.scratch()))?;
        Ok(frame)
    }

    /// `T̂·L` with the first `request.terms` eigen-transports.
    fn relight(
        &self,
        light: &[[f32; 3]],
        request: &Request,
        frame: &mut Frame,
    ) -> Result<FrameStats> {
        check_light(light, self.lights(), self.dims.face_res())?;
        let k = self.check_terms(request.terms)?;
        let (w, h) = self.size();
        frame.fit_image(w, h, &self.limits)?;
        let (s, image) = frame.scratch(|_: &PcaScratch| true, || Ok(self.scratch()))?;
        let t0 = Instant::now();
        self.project(light, k, &mut s.projected);
        self.coefficients
            .scaled_light(&s.projected[1..], k, &mut s.planar);
        let t1 = Instant::now();
        let finite = self.dot_rows(&s.planar, k, s.projected[0], image);
        let bad = if finite {
            None
        } else {
            frame.image.first_non_finite()
        };
        if let Some((x, y)) = bad {
            return Err(RelightError::Invalid(format!(
                "relit pixel ({x}, {y}) is not finite (exceeds the f32 range)"
            )));
        }
        Ok(FrameStats {
            light_transform: t1 - t0,
            multiply: t1.elapsed(),
            lights: k,
            nonzeros: (self.dims.pixels() * k) as u64,
            ..FrameStats::default()
        })
    }
}

/// The model's quantized coefficients in component blocks.
fn blocks(model: &ltm_codec::PcaModel) -> Blocks {
    let coefficients = model.coefficients();
    let q_max = ltm_codec::pca::q_max(coefficients.bits);
    Blocks::new(
        model.dims().pixels(),
        &coefficients.q,
        &coefficients.scales,
        q_max,
    )
}

/// `rows × cols` row-major values transposed.
fn transpose(m: &[f32], rows: usize, cols: usize) -> Vec<f32> {
    let mut t = vec![0.0; m.len()];
    for (r, row) in m.chunks_exact(cols).enumerate() {
        for (c, &v) in row.iter().enumerate() {
            t[c * rows + r] = v;
        }
    }
    t
}
