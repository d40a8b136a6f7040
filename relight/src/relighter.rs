//! The relighter: environment lighting → image from a compressed matrix
//! (Cheslack-Postava et al. 2007 §4.5, eq. 6–8, Fig. 6).
//!
//! Each column is decoded once, the first time a frame needs it, to the
//! compact arena ([`crate::arena`]: quantized `i16` values and a
//! band-and-offset code, 8 bytes per RGB coefficient, 4 per grey one, with
//! one factor per column, band and channel that carries the quantizer step
//! and the inverse band weight); opening checks the file, including every
//! stored column norm against its column (decoded for that and dropped),
//! and keeps no decoded column. Per frame:
//! 1. the cubemap lighting gets the file's row transform (kept in the frame:
//!    a frame under the same lighting, e.g. when only N changes, reuses it);
//! 2. the N lights of highest priority are chosen ([`select`]; the transport
//!    priority uses the column norms the file stores);
//! 3. their columns not yet in the arena are decoded (in parallel);
//! 4. they are grouped by their column's depth, deepest first; each group's
//!    band factors are multiplied by its lights, its coefficients
//!    multiply-added into one image of interleaved `[r, g, b, 0]` pixels
//!    ([`crate::kernel`]), then one inverse column step of all three
//!    channels at once brings the image one level up, until depth 0 (eq. 8);
//! 5. a factored monochrome file multiplies in its albedo image.

use crate::arena::{Arena, ArenaColumn};
use crate::error::{RelightError, Result};
use crate::frame::{check_light, Frame, FrameStats, Relight, Request, TermBasis};
use crate::image_io::Image;
use crate::kernel::{self, Kernel};
use crate::select::{select, support_area, Weighting};
use ltm_codec::container::{LtmFile, Meta};
use ltm_codec::wavelet::{row_forward, RowMode};
use ltm_codec::{Charge, ColumnDecoder, LightBasis, Limits};
use rayon::prelude::*;
use std::path::Path;
use std::time::Instant;

/// Parallel tasks per thread of the multiply-add.
const TASKS_PER_THREAD: usize = 4;
/// How many columns ahead a task prefetches the start of a column's
/// entries (the hardware prefetcher only picks a stream up after a few
/// misses, and each column's run of a task is a new stream).
const PREFETCH_COLUMNS: usize = 2;
/// Lanes of an interleaved pixel: red, green, blue and a zero.
const LANES: usize = 4;
/// Lighting whose largest magnitude exceeds this is divided by a power of
/// two before the row transform and the multiply-add, and the image
/// multiplied back (exact, unless a value leaves the normal range): sums
/// of `f32` values near `f32::MAX` would overflow to infinity, and then
/// NaN, where the image itself is finite.
const LIGHT_SCALE_ABOVE: f32 = (1u64 << 62) as f32;

/// The power of two the lighting `light` is divided by (1 for lighting up
/// to [`LIGHT_SCALE_ABOVE`]).
fn light_scale(light: &[[f32; 3]]) -> f32 {
    let max = light.iter().flatten().fold(0.0f32, |m, v| m.max(v.abs()));
    if max <= LIGHT_SCALE_ABOVE {
        return 1.0;
    }
    // The largest power of two at most `max` (finite: `max` is).
    f32::from_bits(max.to_bits() & 0x7f80_0000)
}

/// A compressed matrix ready to relight with N wavelet lights (the
/// [`Relight`] implementation for `.ltm` files). Immutable and `Sync`:
/// threads share one and each keeps its own [`Frame`].
pub struct Relighter {
    file: LtmFile,
    decoder: ColumnDecoder,
    /// Every column, decoded once on first use ([`crate::arena`]).
    arena: Arena,
    /// The multiply-add kernel this CPU runs best.
    kernel: Kernel,
    /// Per light: the area-weighted priority scales, and ones.
    areas: Vec<f32>,
    ones: Vec<f32>,
    /// The budget the file, the arena and every frame are charged to.
    limits: Limits,
    /// The arena's bytes (allocated whole at open), charged to `limits`.
    _charge: Charge,
}

/// The wavelet relighter's scratch in a [`Frame`]: sized for one file.
struct WaveletScratch {
    light: Vec<[f32; 3]>,
    plane: Vec<f32>,
    work: Vec<[f32; LANES]>,
    /// The image being summed, pixels interleaved `[r, g, b, 0]`.
    pixels: Vec<[f32; LANES]>,
    selected: Vec<u32>,
    order: Vec<(f32, u32)>,
    /// Light tables of the current depth group, and each column's first.
    tables: Vec<[f32; 4]>,
    table_starts: Vec<usize>,
    /// The cubemap lighting `light` was transformed from (empty when none):
    /// a frame under the same lighting reuses the transform.
    last_light: Vec<[f32; 3]>,
    /// What `light` was divided by ([`light_scale`]); the image is
    /// multiplied by it.
    light_scale: f32,
    /// Per image row: whether it may hold a nonzero pixel (a row marked
    /// `false` is all zero). The multiply-add marks the rows of the blocks
    /// it touches; the inverse steps skip rows that are still zero.
    rows: Vec<bool>,
    /// Whether `rows` describes `pixels` (false while a frame is under way,
    /// or after one failed): the next frame then clears only marked rows.
    rows_valid: bool,
    /// The buffers' bytes, charged to the relighter's limits.
    _charge: Charge,
}

impl Relighter {
    /// Opens an `.ltm` file (read into memory) with the default [`Limits`].
    /// Columns are decoded when a frame first needs them
    /// ([`Relighter::decode_all`] decodes the rest at once).
    pub fn open(path: &Path) -> Result<Relighter> {
        Relighter::open_with_limits(path, &Limits::default())
    }

    /// [`Relighter::open`] with the given limits.
    pub fn open_with_limits(path: &Path, limits: &Limits) -> Result<Relighter> {
        Relighter::new(LtmFile::open_with_limits(path, limits)?, limits)
    }

    /// Prepares a relighter for an opened file: checks every column's CRC
    /// (a damaged file is refused here, not in a later frame) and every
    /// stored column norm against its column (each column is decoded once,
    /// in parallel, and dropped: a norm that disagrees is refused here,
    /// before it can rank a light), and charges
    /// the decoder's tables and the arena of decoded coefficients, sized by
    /// the file's column table, to `limits` (whose clone it keeps for its
    /// frames). Keeps no decoded column. A `pca` file is refused: [`crate::open`]
    /// opens any file.
    pub fn new(file: LtmFile, limits: &Limits) -> Result<Relighter> {
        if file.pca().is_some() {
            return Err(RelightError::Invalid(
                "a pca file has no wavelet columns: open it with ltm_relight::open (or PcaRelighter)"
                    .into(),
            ));
        }
        let meta = file.meta().clone();
        let dims = meta.dims;
        let nonzeros: u64 = file.columns().iter().map(|c| c.nnz as u64).sum();
        // The arena is allocated whole at open (its pages are touched as
        // columns are decoded), beside one block index per column and the
        // band map of every depth.
        let entry_bytes = Arena::entry_bytes(dims.channels as usize) as u64;
        let arena = limits.check_alloc("relighting arena", nonzeros, entry_bytes)?;
        let blocks = crate::arena::CodeLayout::new(dims.pixels(), meta.max_depth()).blocks as u64;
        let index =
            limits.check_alloc("arena block index", dims.lights() as u64, 4 * (blocks + 1))?;
        let deepest = file.columns().iter().map(|c| c.depth).max().unwrap_or(0);
        let depths = u64::from(deepest) + 1;
        let maps = limits.check_alloc("arena band maps", dims.pixels() as u64, depths)?;
        let per_light = limits.check_alloc("per-light tables", dims.lights() as u64, 64)?;
        let n = dims.face_res() as usize;
        file.check_column_crcs()?;
        let decoder = ColumnDecoder::for_file(&file, limits)?;
        let arena_charge = arena.join(index).join(maps).join(per_light);
        let arena = Arena::new(&file, &decoder);
        Ok(Relighter {
            decoder,
            arena,
            kernel: Kernel::detect(),
            areas: (0..dims.lights()).map(|j| support_area(n, j)).collect(),
            ones: vec![1.0; dims.lights()],
            file,
            limits: limits.clone(),
            _charge: arena_charge,
        })
    }

    /// Names of the multiply-add kernels this CPU runs, the scalar
    /// reference first and the one [`Relighter::open`] picks last.
    pub fn kernels() -> Vec<&'static str> {
        Kernel::available().into_iter().map(Kernel::name).collect()
    }

    /// The multiply-add kernel in use.
    pub fn kernel(&self) -> &'static str {
        self.kernel.name()
    }

    /// Uses the named multiply-add kernel (one of
    /// [`Relighter::kernels`]), e.g. to compare them.
    pub fn set_kernel(&mut self, name: &str) -> Result<()> {
        self.kernel = Kernel::available()
            .into_iter()
            .find(|k| k.name() == name)
            .ok_or_else(|| RelightError::OutOfRange {
                what: "multiply-add kernel",
                value: name.to_string(),
                valid: Relighter::kernels().join(", "),
            })?;
        Ok(())
    }

    /// The file's metadata.
    pub fn meta(&self) -> &Meta {
        self.file.meta()
    }

    /// The underlying file.
    pub fn file(&self) -> &LtmFile {
        &self.file
    }

    /// Coefficients of the file's columns (held in memory once all are
    /// decoded).
    pub fn nonzeros(&self) -> usize {
        self.arena.nonzeros()
    }

    /// Bytes of the columns decoded so far (coefficients, block index, band
    /// factors).
    pub fn arena_bytes(&self) -> usize {
        self.arena.held_bytes()
    }

    /// Decodes every column not decoded yet (in parallel), so that no later
    /// frame decodes: for timings of frames alone, or a viewer warming up.
    pub fn decode_all(&self) -> Result<()> {
        self.arena.decode_all(&self.file, &self.decoder)
    }

    /// Buffers for one frame of this file, charged to its limits.
    fn scratch(&self) -> Result<WaveletScratch> {
        let dims = self.meta().dims;
        let (p, m) = (dims.pixels(), dims.lights());
        let n = dims.face_res() as usize;
        let l = &self.limits;
        let (light, c0) = l.vec("frame lighting", m, [0.0; 3])?;
        let (plane, c1) = l.vec("frame light plane", m, 0.0)?;
        let work_len = p.max((n * n).div_ceil(LANES));
        let (work, c2) = l.vec("frame work plane", work_len, [0.0; LANES])?;
        let (pixels, c3) = l.vec("frame pixel planes", p, [0.0; LANES])?;
        let (rows, c4) = l.vec("frame row flags", dims.height() as usize, true)?;
        // Selection (`selected`, `order`) and the remembered light.
        let c5 = l.check_alloc("frame light selection", m as u64, 24)?;
        Ok(WaveletScratch {
            light,
            plane,
            work,
            pixels,
            selected: Vec::with_capacity(m),
            order: Vec::with_capacity(m),
            tables: Vec::new(),
            table_starts: Vec::new(),
            last_light: Vec::new(),
            light_scale: 1.0,
            rows,
            rows_valid: false,
            _charge: c0.join(c1).join(c2).join(c3).join(c4).join(c5),
        })
    }

    /// Whether `s` was made by [`Relighter::scratch`] for a file of this
    /// size.
    fn fits(&self, s: &WaveletScratch) -> bool {
        let dims = self.meta().dims;
        let (p, n) = (dims.pixels(), dims.face_res() as usize);
        s.light.len() == dims.lights()
            && s.plane.len() == dims.lights()
            && s.work.len() == p.max((n * n).div_ceil(LANES))
            && s.pixels.len() == p
            && s.rows.len() == dims.height() as usize
    }

    /// Row transform of the cubemap lighting, divided by its
    /// [`light_scale`], into `s.light`.
    fn transform_light(&self, light: &[[f32; 3]], s: &mut WaveletScratch) -> Result<()> {
        let meta = self.meta();
        let n = meta.dims.face_res() as usize;
        s.light_scale = light_scale(light);
        let scale = s.light_scale;
        for c in 0..3 {
            for (v, l) in s.plane.iter_mut().zip(light) {
                *v = if scale == 1.0 { l[c] } else { l[c] / scale };
            }
            row_forward(meta.row_filter, n, &mut s.plane, s.work.as_flattened_mut())?;
            for (l, v) in s.light.iter_mut().zip(&s.plane) {
                l[c] = *v;
            }
        }
        Ok(())
    }

    /// The priority scales of `weighting`: the transport norms of a file
    /// that does not store them are those of its decoded columns (every
    /// column is decoded the first time).
    fn priority_scale(&self, weighting: Weighting) -> Result<&[f32]> {
        Ok(match weighting {
            Weighting::Unweighted => &self.ones,
            Weighting::Transport => self.arena.norms(&self.file, &self.decoder)?,
            Weighting::Area => &self.areas,
        })
    }

    /// Checks the lighting and row-transforms it into `s.light`, unless
    /// `s.light` already holds the transform of the same lighting (bit for
    /// bit): a viewer that changes only N reuses it.
    fn prepare_light(&self, light: &[[f32; 3]], s: &mut WaveletScratch) -> Result<()> {
        let same = s.last_light.len() == light.len()
            && s.last_light.iter().zip(light).all(|(a, b)| {
                a[0].to_bits() == b[0].to_bits()
                    && a[1].to_bits() == b[1].to_bits()
                    && a[2].to_bits() == b[2].to_bits()
            });
        if same {
            return Ok(());
        }
        s.last_light.clear();
        check_light(light, self.lights(), self.meta().dims.face_res())?;
        self.transform_light(light, s)?;
        s.last_light.extend_from_slice(light);
        Ok(())
    }

    /// Selects the requested lights from `s.light` into `s.selected`.
    fn select_lights(&self, request: &Request, s: &mut WaveletScratch) -> Result<()> {
        select(
            &s.light,
            self.priority_scale(request.weighting)?,
            request.terms,
            &mut s.order,
            &mut s.selected,
        );
        Ok(())
    }

    /// Eq. 8 on the selected lights (sorted deepest first; `columns[k]` is
    /// light `s.selected[k]`'s column): each depth group is multiply-added
    /// into the pixels, then one inverse column step of all three
    /// interleaved channels brings them a level up, to depth 0.
    fn multiply_levels(
        &self,
        s: &mut WaveletScratch,
        columns: &[ArenaColumn<'_>],
        stats: &mut FrameStats,
    ) -> Result<()> {
        self.clear_pixels(s);
        let depths = &self.arena.depths;
        let top = s.selected.first().map_or(0, |&j| depths[j as usize]);
        let mut next = 0;
        for depth in (0..=top).rev() {
            let tm = Instant::now();
            let start = next;
            while next < s.selected.len() && depths[s.selected[next] as usize] == depth {
                next += 1;
            }
            let group = &s.selected[start..next];
            if !group.is_empty() {
                let cols = &columns[start..next];
                Arena::light_tables(group, cols, &s.light, &mut s.tables, &mut s.table_starts);
                stats.nonzeros +=
                    self.multiply_add(cols, &s.tables, &s.table_starts, &mut s.pixels, &mut s.rows);
            }
            let ti = Instant::now();
            stats.multiply += ti - tm;
            if depth == 1 && s.work.len() == s.pixels.len() {
                // The whole image: with a lifting filter synthesized into
                // `work`, which becomes the pixels (no copy back).
                let into_work = self.decoder.last_inverse_step_lanes_sparse(
                    s.pixels.as_flattened_mut(),
                    LANES,
                    s.work.as_flattened_mut(),
                    &mut s.rows,
                )?;
                if into_work {
                    std::mem::swap(&mut s.pixels, &mut s.work);
                }
            } else if depth > 0 {
                self.decoder.inverse_step(
                    depth as u32,
                    s.pixels.as_flattened_mut(),
                    LANES,
                    s.work.as_flattened_mut(),
                    RowMode::sparse(&mut s.rows),
                )?;
            }
            stats.inverse += ti.elapsed();
        }
        s.rows_valid = true;
        Ok(())
    }

    /// Zeroes the pixels for a new frame: only the rows the last frame
    /// marked, when its marks are known to hold. Leaves every row marked
    /// zero and the marks invalid until the frame completes.
    fn clear_pixels(&self, s: &mut WaveletScratch) {
        let width = self.meta().dims.width() as usize;
        if s.rows_valid {
            for (row, _) in s
                .pixels
                .chunks_mut(width)
                .zip(&s.rows)
                .filter(|(_, &live)| live)
            {
                row.fill([0.0; LANES]);
            }
        } else {
            s.pixels.fill([0.0; LANES]);
        }
        s.rows.fill(false);
        s.rows_valid = false;
    }

    /// Marks the image rows of every pixel block with work (coefficients).
    fn mark_rows(&self, work: &[u64], rows: &mut [bool]) {
        let layout = self.arena.layout;
        let width = self.meta().dims.width() as usize;
        let p = self.meta().dims.pixels();
        for (b, _) in work.iter().enumerate().filter(|(_, &w)| w > 0) {
            let lo = b * layout.block_pixels;
            let hi = ((b + 1) * layout.block_pixels).min(p);
            if lo < hi {
                rows[lo / width..=(hi - 1) / width].fill(true);
            }
        }
    }

    /// Multiply-adds the columns of a group (with their light tables) into
    /// the pixels, in parallel over pixel ranges of about equal work (from
    /// the block index; each pixel is summed by one task in group order, so
    /// the image does not depend on the split), and marks the image rows it
    /// touches in `rows`. Returns the coefficients used.
    fn multiply_add(
        &self,
        group: &[ArenaColumn<'_>],
        tables: &[[f32; 4]],
        table_starts: &[usize],
        pixels: &mut [[f32; LANES]],
        rows: &mut [bool],
    ) -> u64 {
        let arena = &self.arena;
        let layout = arena.layout;
        let blocks = layout.blocks;
        let mut work = vec![0u64; blocks];
        for col in group {
            for (w, o) in work.iter_mut().zip(col.offsets().windows(2)) {
                *w += u64::from(o[1] - o[0]);
            }
        }
        let used: u64 = work.iter().sum();
        self.mark_rows(&work, rows);
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
        if first < blocks {
            ranges.push(first..blocks);
        }
        // Disjoint pixel slices, one per range.
        let p = pixels.len();
        let mut rest = pixels;
        let mut parts = Vec::with_capacity(ranges.len());
        let mut lo = 0;
        for range in ranges {
            let hi = (range.end * layout.block_pixels).min(p).max(lo);
            let (part, tail) = rest.split_at_mut(hi - lo);
            parts.push((range, part));
            (rest, lo) = (tail, hi);
        }
        let (channels, kernel) = (arena.channels, self.kernel);
        parts.into_par_iter().for_each(|(range, part)| {
            for (k, col) in group.iter().enumerate() {
                if let Some(next) = group.get(k + PREFETCH_COLUMNS) {
                    kernel::prefetch(next.entries(channels, range.start, range.end));
                }
                // The column's entries in this task's blocks, cut at the
                // block boundaries (most columns of a deep group have none
                // in most tasks).
                let all = col.entries(channels, range.start, range.end);
                if all.is_empty() {
                    continue;
                }
                let table = &tables[table_starts[k]..][..col.factors().len()];
                let bounds = &col.offsets()[range.start..=range.end];
                let e = channels + 1;
                for (b, w) in bounds.windows(2).enumerate() {
                    let (lo, hi) = ((w[0] - bounds[0]) as usize, (w[1] - bounds[0]) as usize);
                    if lo == hi {
                        continue;
                    }
                    let from = b * layout.block_pixels;
                    let to = (from + layout.block_pixels).min(part.len());
                    let block = &mut part[from..to];
                    kernel.run(channels, &all[e * lo..e * hi], table, layout.shift, block);
                }
            }
        });
        used
    }

    /// The image from the summed pixels: the lighting's scale and the
    /// albedo multiplied in, empty rows set to 0. A pixel that is not
    /// finite (the image exceeds the `f32` range) is an error naming it.
    fn finish_image(&self, pixels: &[[f32; LANES]], scale: f32, image: &mut Image) -> Result<()> {
        match self.file.albedo() {
            Some(albedo) => {
                for ((px, v), a) in image
                    .data
                    .iter_mut()
                    .zip(pixels)
                    .zip(albedo.chunks_exact(3))
                {
                    *px = [v[0] * a[0], v[1] * a[1], v[2] * a[2]];
                }
            }
            None => {
                for (px, v) in image.data.iter_mut().zip(pixels) {
                    *px = [v[0], v[1], v[2]];
                }
            }
        }
        if scale != 1.0 {
            for px in &mut image.data {
                *px = px.map(|v| v * scale);
            }
        }
        // Empty rows (open sky) are exactly 0, not the column transform's
        // spill from their neighbours.
        if let Some(e) = self.file.empty_rows() {
            for (p, px) in image.data.iter_mut().enumerate() {
                if e.is_empty_row(p) {
                    *px = [0.0; 3];
                }
            }
        }
        if let Some((x, y)) = image.first_non_finite() {
            return Err(RelightError::Invalid(format!(
                "relit pixel ({x}, {y}) is not finite: the image T·L exceeds the f32 range"
            )));
        }
        Ok(())
    }

    /// The same image by eq. 3: every chosen column fully decoded with the
    /// codec's column decoder and summed — the slow reference the
    /// level-recursive path is tested against.
    pub fn relight_naive(&self, light: &[[f32; 3]], request: &Request) -> Result<Image> {
        let mut s = self.scratch()?;
        self.prepare_light(light, &mut s)?;
        self.select_lights(request, &mut s)?;
        let channels = self.meta().dims.channels as usize;
        let p = self.meta().dims.pixels();
        let mut plane = vec![0.0f32; p];
        let mut acc = [vec![0.0f64; p], vec![0.0f64; p], vec![0.0f64; p]];
        for &j in &s.selected {
            let col = self.file.column(j as usize)?;
            for fc in 0..channels {
                self.decoder
                    .decode(&col, fc, &mut plane, s.work.as_flattened_mut())?;
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
        let pixels: Vec<[f32; LANES]> = (0..p)
            .map(|i| [acc[0][i] as f32, acc[1][i] as f32, acc[2][i] as f32, 0.0])
            .collect();
        let (w, h) = self.size();
        let mut image = Image::new(w, h);
        self.finish_image(&pixels, s.light_scale, &mut image)?;
        Ok(image)
    }
}

impl Relight for Relighter {
    /// The file's cubemap (its columns).
    fn light_basis(&self) -> LightBasis {
        self.meta().dims.lights
    }

    /// Wavelet lights.
    fn term_basis(&self) -> TermBasis {
        TermBasis::Wavelet
    }

    fn size(&self) -> (usize, usize) {
        let dims = self.meta().dims;
        (dims.width() as usize, dims.height() as usize)
    }

    /// Every light: larger requests are clamped to it.
    fn max_terms(&self) -> usize {
        self.lights()
    }
    fn held_bytes(&self) -> usize {
        self.arena_bytes()
    }

    fn preload(&self) -> Result<()> {
        self.decode_all()
    }

    fn frame(&self) -> Result<Frame> {
        let (w, h) = self.size();
        let mut frame = Frame::default();
        frame.fit_image(w, h, &self.limits)?;
        frame.scratch(|_: &WaveletScratch| false, || self.scratch())?;
        Ok(frame)
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
        frame.fit_image(w, h, &self.limits)?;
        let forget = frame.take_forget_light();
        let (s, image) = frame.scratch(|s| self.fits(s), || self.scratch())?;
        if forget {
            s.last_light.clear();
        }
        let mut stats = FrameStats::default();
        let t0 = Instant::now();
        self.prepare_light(light, s)?;
        let t1 = Instant::now();
        self.select_lights(request, s)?;
        // Deepest columns first (eq. 8).
        let depths = &self.arena.depths;
        s.selected
            .sort_unstable_by_key(|&j| (std::cmp::Reverse(depths[j as usize]), j));
        stats.lights = s.selected.len();
        let t2 = Instant::now();
        let mut columns = Vec::with_capacity(s.selected.len());
        stats.columns_decoded =
            self.arena
                .columns(&s.selected, &self.file, &self.decoder, &mut columns)?;
        let t3 = Instant::now();
        stats.light_transform = t1 - t0;
        stats.selection = t2 - t1;
        stats.decode = t3 - t2;
        self.multiply_levels(s, &columns, &mut stats)?;
        let ti = Instant::now();
        self.finish_image(&s.pixels, s.light_scale, image)?;
        stats.inverse += ti.elapsed();
        Ok(stats)
    }
}
