//! The relighter: environment lighting → image from a compressed matrix
//! (Cheslack-Postava et al. 2007 §4.5, eq. 6–8, Fig. 6).
//!
//! At open, every column is decoded once to an in-memory arena of
//! `(position, value)` pairs whose values already carry the quantizer scale
//! and the inverse band weight, so a frame is a stream of multiply-adds.
//! Per frame:
//! 1. the cubemap lighting gets the file's row transform;
//! 2. the N lights of highest priority are chosen ([`select`]);
//! 3. they are grouped by their column's depth, deepest first; each group is
//!    multiply-added into the image planes, then one inverse column step
//!    brings the planes one level up, until depth 0 (eq. 8);
//! 4. a factored monochrome file multiplies in its albedo image.

use crate::error::{RelightError, Result};
use crate::frame::{check_light, Frame, FrameStats, Relight, Request};
use crate::image_io::Image;
use crate::select::{select, support_area, Weighting};
use ltm_codec::container::{LtmFile, Meta};
use ltm_codec::wavelet::row_forward;
use ltm_codec::BandWeights;
use ltm_codec::{ColumnDecoder, Limits};
use rayon::prelude::*;
use std::path::Path;
use std::time::Instant;

/// Pixel blocks of the block index: each column records where its entries
/// cross every block boundary, so a frame can split the multiply-add into
/// pixel ranges of equal work (deep columns crowd into the first blocks,
/// where the coarse bands are) without searching.
const BLOCKS: usize = 64;
/// Parallel tasks per thread of the multiply-add.
const TASKS_PER_THREAD: usize = 4;

/// A compressed matrix ready to relight with N wavelet lights (the
/// [`Relight`] implementation for `.ltm` files). Immutable and `Sync`:
/// threads share one and each keeps its own [`Frame`].
pub struct Relighter {
    file: LtmFile,
    decoder: ColumnDecoder,
    /// Column `j`'s coefficients are `starts[j]..starts[j + 1]`.
    starts: Vec<usize>,
    positions: Vec<u32>,
    /// `channels` values per coefficient, ready to multiply by the light.
    values: Vec<f32>,
    /// Pixels per block of the block index (the last block may be shorter).
    block_pixels: usize,
    /// Column `j`'s entries in block `b` are `starts[j] + block_index[j·(BLOCKS
    /// + 1) + b] ..` up to the next boundary's offset.
    block_index: Vec<u32>,
    depths: Vec<u8>,
    /// Per light: the transport-weighted and area-weighted priority scales.
    norms: Vec<f32>,
    areas: Vec<f32>,
    ones: Vec<f32>,
}

/// The wavelet relighter's part of a [`Frame`]: sized for one file.
pub(crate) struct WaveletScratch {
    light: Vec<[f32; 3]>,
    plane: Vec<f32>,
    work: Vec<f32>,
    planes: [Vec<f32>; 3],
    selected: Vec<u32>,
    order: Vec<(f32, u32)>,
}

impl Relighter {
    /// Opens an `.ltm` file (memory-mapped) and decodes its columns, with
    /// the default [`Limits`].
    pub fn open(path: &Path) -> Result<Relighter> {
        Relighter::open_with_limits(path, &Limits::default())
    }

    /// [`Relighter::open`] with the given limits.
    pub fn open_with_limits(path: &Path, limits: &Limits) -> Result<Relighter> {
        Relighter::new(LtmFile::open_with_limits(path, limits)?, limits)
    }

    /// Prepares a relighter for an opened file. The arena of decoded
    /// coefficients, sized by the file's column table, is checked against
    /// `limits` before anything is decoded.
    pub fn new(file: LtmFile, limits: &Limits) -> Result<Relighter> {
        if file.pca().is_some() {
            return Err(RelightError::Invalid(
                "a pca file has no wavelet columns: open it with PcaRelighter (or open_relighter)"
                    .into(),
            ));
        }
        let meta = file.meta().clone();
        let dims = meta.dims;
        let nonzeros: u64 = file.columns().iter().map(|c| c.nnz as u64).sum();
        // Positions and values, held twice while the columns are gathered.
        let entry_bytes = 2 * (4 + 4 * dims.channels as u64);
        limits.check_alloc("relighting arena", nonzeros, entry_bytes)?;
        limits.check_alloc("frame image planes", dims.pixels() as u64, 4 * 6)?;
        let (w, h) = (dims.width() as usize, dims.height() as usize);
        let channels = dims.channels as usize;
        let n = dims.face_res() as usize;
        let weights = BandWeights::new(meta.col_filter, w, h, meta.max_depth());
        let decoder = ColumnDecoder::new(&meta);
        let decoded: Vec<(Vec<u32>, Vec<f32>, u8, f32)> = (0..dims.lights())
            .into_par_iter()
            .map(|j| -> Result<_> {
                let col = file.column(j)?;
                let map = weights.map(col.depth);
                let mut values = Vec::with_capacity(col.values.len());
                let mut norm_sq = 0.0f64;
                for (k, &i) in col.indices.iter().enumerate() {
                    for c in 0..channels {
                        let weighted = decoder.dequantize(&col, k, c);
                        norm_sq += (weighted as f64).powi(2);
                        values.push(weighted / map[i as usize]);
                    }
                }
                Ok((col.indices, values, col.depth as u8, norm_sq.sqrt() as f32))
            })
            .collect::<Result<_>>()?;
        let total: usize = decoded.iter().map(|d| d.0.len()).sum();
        let block_pixels = dims.pixels().div_ceil(BLOCKS).max(1);
        let mut r = Relighter {
            block_pixels,
            block_index: Vec::with_capacity(decoded.len() * (BLOCKS + 1)),
            decoder,
            starts: Vec::with_capacity(decoded.len() + 1),
            positions: Vec::with_capacity(total),
            values: Vec::with_capacity(total * channels),
            depths: Vec::with_capacity(decoded.len()),
            norms: Vec::with_capacity(decoded.len()),
            areas: (0..dims.lights()).map(|j| support_area(n, j)).collect(),
            ones: vec![1.0; dims.lights()],
            file,
        };
        r.starts.push(0);
        for (pos, val, depth, norm) in decoded {
            // Positions are sorted (the container stores them as gaps).
            r.block_index.extend(
                (0..=BLOCKS)
                    .map(|b| pos.partition_point(|&i| (i as usize) < b * block_pixels) as u32),
            );
            r.positions.extend_from_slice(&pos);
            r.values.extend_from_slice(&val);
            r.starts.push(r.positions.len());
            r.depths.push(depth);
            r.norms.push(norm);
        }
        Ok(r)
    }

    /// The file's metadata.
    pub fn meta(&self) -> &Meta {
        self.file.meta()
    }

    /// The underlying file.
    pub fn file(&self) -> &LtmFile {
        &self.file
    }

    /// Coefficients held in memory.
    pub fn nonzeros(&self) -> usize {
        self.positions.len()
    }

    /// Buffers for one frame of this file.
    fn scratch(&self) -> WaveletScratch {
        let dims = self.meta().dims;
        let p = dims.pixels();
        let n = dims.face_res() as usize;
        WaveletScratch {
            light: vec![[0.0; 3]; dims.lights()],
            plane: vec![0.0; dims.lights()],
            work: vec![0.0; p.max(n * n)],
            planes: [vec![0.0; p], vec![0.0; p], vec![0.0; p]],
            selected: Vec::with_capacity(dims.lights()),
            order: Vec::with_capacity(dims.lights()),
        }
    }

    /// Whether `s` was made by [`Relighter::scratch`] for a file of this
    /// size.
    fn fits(&self, s: &WaveletScratch) -> bool {
        let dims = self.meta().dims;
        let (p, n) = (dims.pixels(), dims.face_res() as usize);
        s.light.len() == dims.lights()
            && s.plane.len() == dims.lights()
            && s.work.len() == p.max(n * n)
            && s.planes.iter().all(|plane| plane.len() == p)
    }

    /// Row transform of the cubemap lighting into `s.light`.
    fn transform_light(&self, light: &[[f32; 3]], s: &mut WaveletScratch) -> Result<()> {
        let meta = self.meta();
        let n = meta.dims.face_res() as usize;
        for c in 0..3 {
            for (v, l) in s.plane.iter_mut().zip(light) {
                *v = l[c];
            }
            row_forward(meta.row_filter, n, &mut s.plane, &mut s.work)?;
            for (l, v) in s.light.iter_mut().zip(&s.plane) {
                l[c] = *v;
            }
        }
        Ok(())
    }

    fn priority_scale(&self, weighting: Weighting) -> &[f32] {
        match weighting {
            Weighting::Unweighted => &self.ones,
            Weighting::Transport => &self.norms,
            Weighting::Area => &self.areas,
        }
    }

    /// Checks the lighting and row-transforms it into `s.light`.
    fn prepare_light(&self, light: &[[f32; 3]], s: &mut WaveletScratch) -> Result<()> {
        check_light(light, self.lights(), self.meta().dims.face_res())?;
        self.transform_light(light, s)
    }

    /// Selects the requested lights from `s.light` into `s.selected`.
    fn select_lights(&self, request: &Request, s: &mut WaveletScratch) {
        select(
            &s.light,
            self.priority_scale(request.weighting),
            request.terms,
            &mut s.order,
            &mut s.selected,
        );
    }

    /// Eq. 8 on the selected lights (sorted deepest first): each depth
    /// group is multiply-added into the planes, then one inverse column step
    /// brings the planes a level up, to depth 0.
    fn multiply_levels(&self, s: &mut WaveletScratch, stats: &mut FrameStats) -> Result<()> {
        let channels = self.meta().dims.channels as usize;
        for p in s.planes.iter_mut() {
            p.fill(0.0);
        }
        let top = s.selected.first().map_or(0, |&j| self.depths[j as usize]);
        let mut next = 0;
        for depth in (0..=top).rev() {
            let tm = Instant::now();
            let start = next;
            while next < s.selected.len() && self.depths[s.selected[next] as usize] == depth {
                next += 1;
            }
            let group = &s.selected[start..next];
            if !group.is_empty() {
                stats.nonzeros += self.multiply_add(group, &s.light, channels, &mut s.planes);
            }
            let ti = Instant::now();
            stats.multiply += ti - tm;
            if depth > 0 {
                for plane in s.planes.iter_mut() {
                    self.decoder
                        .inverse_step(depth as u32, plane, &mut s.work)?;
                }
            }
            stats.inverse += ti.elapsed();
        }
        Ok(())
    }

    /// Multiply-adds the columns of `group` into the planes, in parallel over
    /// pixel ranges of about equal work (from the block index; each pixel is
    /// summed by one task in group order, so the image does not depend on
    /// the split). Returns the coefficients used.
    fn multiply_add(
        &self,
        group: &[u32],
        light: &[[f32; 3]],
        channels: usize,
        planes: &mut [Vec<f32>; 3],
    ) -> u64 {
        let offsets = |j: u32| &self.block_index[j as usize * (BLOCKS + 1)..][..BLOCKS + 1];
        let mut work = [0u64; BLOCKS];
        for &j in group {
            for (w, o) in work.iter_mut().zip(offsets(j).windows(2)) {
                *w += u64::from(o[1] - o[0]);
            }
        }
        let used: u64 = work.iter().sum();
        // Consecutive blocks grouped into ranges of about equal work.
        let tasks = TASKS_PER_THREAD * rayon::current_num_threads();
        let target = (used / tasks as u64).max(1);
        let mut ranges = Vec::with_capacity(tasks + 1);
        let (mut first, mut acc) = (0, 0);
        for (b, w) in work.iter().enumerate() {
            acc += w;
            if acc >= target {
                ranges.push(first..b + 1);
                (first, acc) = (b + 1, 0);
            }
        }
        if first < BLOCKS {
            ranges.push(first..BLOCKS);
        }
        // Disjoint plane slices, one set per range.
        let p = planes[0].len();
        let [r, g, b] = planes;
        let (mut r, mut g, mut b) = (&mut r[..], &mut g[..], &mut b[..]);
        let mut parts = Vec::with_capacity(ranges.len());
        let mut lo = 0;
        for range in ranges {
            let hi = (range.end * self.block_pixels).min(p).max(lo);
            let (r0, r1) = r.split_at_mut(hi - lo);
            let (g0, g1) = g.split_at_mut(hi - lo);
            let (b0, b1) = b.split_at_mut(hi - lo);
            parts.push((range, lo as u32, r0, g0, b0));
            (r, g, b, lo) = (r1, g1, b1, hi);
        }
        parts.into_par_iter().for_each(|(range, lo, r, g, b)| {
            for &j in group {
                let (s, o) = (self.starts[j as usize], offsets(j));
                let (a, z) = (s + o[range.start] as usize, s + o[range.end] as usize);
                let pos = &self.positions[a..z];
                let l = light[j as usize];
                if channels == 1 {
                    multiply_add_grey(pos, &self.values[a..z], lo, l, r, g, b);
                } else {
                    multiply_add_rgb(pos, &self.values[3 * a..3 * z], lo, l, r, g, b);
                }
            }
        });
        used
    }

    fn finish_image(&self, planes: &[Vec<f32>; 3], image: &mut Image) {
        let albedo = self.file.albedo();
        for (p, px) in image.data.iter_mut().enumerate() {
            *px = [planes[0][p], planes[1][p], planes[2][p]];
            if let Some(a) = albedo {
                for (c, v) in px.iter_mut().enumerate() {
                    *v *= a[3 * p + c];
                }
            }
        }
    }

    /// The same image by eq. 3: every chosen column fully decoded with the
    /// codec's column decoder and summed — the slow reference the
    /// level-recursive path is tested against.
    pub fn relight_naive(&self, light: &[[f32; 3]], request: &Request) -> Result<Image> {
        let mut s = self.scratch();
        self.prepare_light(light, &mut s)?;
        self.select_lights(request, &mut s);
        let channels = self.meta().dims.channels as usize;
        let p = self.meta().dims.pixels();
        let mut plane = vec![0.0f32; p];
        let mut acc = [vec![0.0f64; p], vec![0.0f64; p], vec![0.0f64; p]];
        for &j in &s.selected {
            let col = self.file.column(j as usize)?;
            for fc in 0..channels {
                self.decoder.decode(&col, fc, &mut plane, &mut s.work)?;
                for (c, plane_acc) in acc.iter_mut().enumerate() {
                    if channels == 1 || c == fc {
                        let l = s.light[j as usize][c] as f64;
                        for (a, v) in plane_acc.iter_mut().zip(&plane) {
                            *a += l * *v as f64;
                        }
                    }
                }
            }
        }
        let planes = acc.map(|a| a.into_iter().map(|v| v as f32).collect::<Vec<f32>>());
        let (w, h) = self.size();
        let mut image = Image::new(w, h);
        self.finish_image(&planes, &mut image);
        Ok(image)
    }
}

impl Relight for Relighter {
    /// The file's cubemap texels (its columns).
    fn lights(&self) -> usize {
        self.depths.len()
    }

    fn size(&self) -> (usize, usize) {
        let dims = self.meta().dims;
        (dims.width() as usize, dims.height() as usize)
    }

    /// Every light: larger requests are clamped to it.
    fn max_terms(&self) -> usize {
        self.lights()
    }

    fn frame(&self) -> Frame {
        let (w, h) = self.size();
        Frame {
            image: Image::new(w, h),
            wavelet: Some(self.scratch()),
            ..Frame::default()
        }
    }

    /// Relights with the `request.terms` most important wavelet lights under
    /// `request.weighting` (all of them when `terms` ≥ the number of
    /// lights), by eq. 8 of Cheslack-Postava et al. 2007.
    fn relight(
        &self,
        light: &[[f32; 3]],
        request: &Request,
        frame: &mut Frame,
    ) -> Result<FrameStats> {
        let (w, h) = self.size();
        frame.fit_image(w, h);
        let s = match frame.wavelet.take() {
            Some(s) if self.fits(&s) => frame.wavelet.insert(s),
            _ => frame.wavelet.insert(self.scratch()),
        };
        let mut stats = FrameStats::default();
        let t0 = Instant::now();
        self.prepare_light(light, s)?;
        let t1 = Instant::now();
        self.select_lights(request, s);
        // Deepest columns first (eq. 8).
        let depths = &self.depths;
        s.selected
            .sort_unstable_by_key(|&j| (std::cmp::Reverse(depths[j as usize]), j));
        stats.lights = s.selected.len();
        let t2 = Instant::now();
        stats.light_transform = t1 - t0;
        stats.selection = t2 - t1;
        self.multiply_levels(s, &mut stats)?;
        let ti = Instant::now();
        self.finish_image(&s.planes, &mut frame.image);
        stats.inverse += ti.elapsed();
        Ok(stats)
    }
}

/// `plane_c[pos − lo] += light_c · value` for a grey column: the scalar
/// reference kernel of the multiply-add.
#[inline]
fn multiply_add_grey(
    pos: &[u32],
    val: &[f32],
    lo: u32,
    l: [f32; 3],
    r: &mut [f32],
    g: &mut [f32],
    b: &mut [f32],
) {
    for (&i, &v) in pos.iter().zip(val) {
        let i = (i - lo) as usize;
        r[i] += l[0] * v;
        g[i] += l[1] * v;
        b[i] += l[2] * v;
    }
}

/// The same for an RGB column (3 values per coefficient).
#[inline]
fn multiply_add_rgb(
    pos: &[u32],
    val: &[f32],
    lo: u32,
    l: [f32; 3],
    r: &mut [f32],
    g: &mut [f32],
    b: &mut [f32],
) {
    for (&i, v) in pos.iter().zip(val.chunks_exact(3)) {
        let i = (i - lo) as usize;
        r[i] += l[0] * v[0];
        g[i] += l[1] * v[1];
        b[i] += l[2] * v[2];
    }
}
