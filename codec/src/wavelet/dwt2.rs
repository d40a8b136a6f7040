//! Separable 2D steps in the Mallat layout, and the multi-level transforms
//! built on them.

use super::{lifting, periodic, Filter, Kind};
use crate::error::{Error, Result};
use rayon::prelude::*;

/// Images with at least this many samples in the transformed region are
/// processed in parallel (rows or row groups across rayon's pool).
const PARALLEL_MIN: usize = 1 << 16;
/// Samples per parallel task.
const PARALLEL_GRAIN: usize = 1 << 13;

/// `rows` rows of `w` used values each, `stride` apart, in `data`.
pub(crate) struct Rows<'a> {
    data: &'a mut [f32],
    pub stride: usize,
    pub w: usize,
    pub rows: usize,
}

/// A read-only view of [`Rows`].
pub(crate) struct RowsRef<'a> {
    data: &'a [f32],
    stride: usize,
    w: usize,
}

impl<'a> Rows<'a> {
    pub fn new(data: &'a mut [f32], stride: usize, w: usize, rows: usize) -> Rows<'a> {
        Rows {
            data,
            stride,
            w,
            rows,
        }
    }

    pub fn view(&self) -> RowsRef<'_> {
        RowsRef {
            data: self.data,
            stride: self.stride,
            w: self.w,
        }
    }
}

impl RowsRef<'_> {
    #[inline]
    pub fn row(&self, i: usize) -> &[f32] {
        &self.data[i * self.stride..][..self.w]
    }
}

/// Calls `f(i, row)` for each row, in parallel when asked.
pub(crate) fn for_each_row<F>(rows: &mut Rows, parallel: bool, f: F)
where
    F: Fn(usize, &mut [f32]) + Sync + Send,
{
    let (w, n) = (rows.w, rows.rows);
    if n == 0 {
        return;
    }
    let data = &mut rows.data[..(n - 1) * rows.stride + w];
    if parallel {
        let grain = (PARALLEL_GRAIN / w.max(1)).max(1);
        data.par_chunks_mut(rows.stride)
            .with_min_len(grain)
            .enumerate()
            .for_each(|(i, row)| f(i, &mut row[..w]));
    } else {
        data.chunks_mut(rows.stride)
            .enumerate()
            .for_each(|(i, row)| f(i, &mut row[..w]));
    }
}

/// Size of the low band after `level` steps on a `width` × `height` image.
pub fn band_size(width: usize, height: usize, level: u32) -> (usize, usize) {
    let (mut w, mut h) = (width, height);
    for _ in 0..level {
        w = w.div_ceil(2);
        h = h.div_ceil(2);
    }
    (w, h)
}

/// Number of steps after which the low band is 1 × 1:
/// `ceil(log2(max(width, height)))`.
pub fn max_levels(width: usize, height: usize) -> u32 {
    let n = width.max(height).max(1);
    usize::BITS - (n - 1).leading_zeros()
}

fn check_region(data: &[f32], stride: usize, w: usize, h: usize, work: &[f32]) -> Result<()> {
    if w == 0 || h == 0 {
        return Err(Error::range(
            "wavelet region size",
            format!("{w}x{h}"),
            "at least 1x1",
        ));
    }
    if stride < w {
        return Err(Error::range(
            "wavelet row stride",
            stride,
            format!(">= width {w}"),
        ));
    }
    let need = (h - 1) * stride + w;
    if data.len() < need {
        return Err(Error::BufferTooSmall {
            what: "wavelet data",
            len: data.len(),
            need,
        });
    }
    if work.len() < w * h {
        return Err(Error::BufferTooSmall {
            what: "wavelet scratch",
            len: work.len(),
            need: w * h,
        });
    }
    Ok(())
}

fn forward_row(filter: Filter, x: &[f32], out: &mut [f32]) {
    match filter.kind() {
        Kind::Periodic(t) => periodic::forward_1d(t, x, out),
        Kind::Lifting(s) => lifting::forward_1d(s, x, out),
    }
}

fn inverse_row(filter: Filter, bands: &[f32], out: &mut [f32]) {
    match filter.kind() {
        Kind::Periodic(t) => periodic::inverse_1d(t, bands, out),
        Kind::Lifting(s) => lifting::inverse_1d(s, bands, out),
    }
}

fn inverse_row_lanes<const L: usize>(filter: Filter, bands: &[[f32; L]], out: &mut [[f32; L]]) {
    match filter.kind() {
        Kind::Periodic(t) => periodic::inverse_1d_lanes(t, bands, out),
        Kind::Lifting(s) => lifting::inverse_1d_lanes(s, bands, out),
    }
}

/// One forward step on the top-left `w` × `h` region of `data` (rows
/// `stride` apart): rows are split into low | high halves (if `w >= 2`),
/// then columns (if `h >= 2`). `work` needs `w · h` values.
pub fn forward_step(
    filter: Filter,
    data: &mut [f32],
    stride: usize,
    w: usize,
    h: usize,
    work: &mut [f32],
) -> Result<()> {
    check_region(data, stride, w, h, work)?;
    let parallel = w * h >= PARALLEL_MIN;
    let work = &mut work[..w * h];
    // Horizontal: data rows -> work rows.
    {
        let src = Rows::new(data, stride, w, h);
        let src = src.view();
        let mut dst = Rows::new(work, w, w, h);
        for_each_row(&mut dst, parallel, |r, out| {
            if w >= 2 {
                forward_row(filter, src.row(r), out)
            } else {
                out.copy_from_slice(src.row(r))
            }
        });
    }
    // Vertical: work rows -> data rows.
    if h >= 2 {
        match filter.kind() {
            Kind::Periodic(t) => periodic::forward_rows(t, work, data, stride, w, h, parallel),
            Kind::Lifting(s) => lifting::forward_rows(s, work, data, stride, w, h, parallel),
        }
    } else {
        data[..w].copy_from_slice(&work[..w]);
    }
    Ok(())
}

/// One inverse step: the exact inverse of [`forward_step`] on the same region.
pub fn inverse_step(
    filter: Filter,
    data: &mut [f32],
    stride: usize,
    w: usize,
    h: usize,
    work: &mut [f32],
) -> Result<()> {
    inverse_step_lanes(filter, data, stride, w, h, 1, work)
}

/// [`inverse_step`] on `lanes` interleaved images at once: pixel `(x, y)` of
/// image `c` is `data[(y·stride + x)·lanes + c]` (`stride` and `w` count
/// pixels). Every image gets exactly the arithmetic [`inverse_step`] would
/// give it alone, so the results are bit-identical; the vertical pass runs
/// once over all lanes, the horizontal one per row and lane. `work` needs
/// `w · h · lanes` values.
pub fn inverse_step_lanes(
    filter: Filter,
    data: &mut [f32],
    stride: usize,
    w: usize,
    h: usize,
    lanes: usize,
    work: &mut [f32],
) -> Result<()> {
    if lanes == 0 {
        return Err(Error::range("interleaved lanes", lanes, "at least 1"));
    }
    check_region(data, stride * lanes, w * lanes, h, work)?;
    let parallel = w * h >= PARALLEL_MIN / lanes;
    let (wl, sl) = (w * lanes, stride * lanes);
    let work = &mut work[..wl * h];
    // Vertical: data rows -> work rows. Each sample of a row is filtered on
    // its own, so the lanes need no special care. Lifting leaves the rows in
    // band order (low rows, then high rows); `signal_row` maps back.
    let mut band_order = false;
    if h >= 2 {
        match filter.kind() {
            Kind::Periodic(t) => periodic::inverse_rows(t, data, sl, work, wl, h, parallel),
            Kind::Lifting(s) => {
                lifting::inverse_rows(s, data, sl, work, wl, h, parallel);
                band_order = true;
            }
        }
    } else {
        work[..wl].copy_from_slice(&data[..wl]);
    }
    // Horizontal: work rows -> data rows, lane by lane.
    let src = Rows::new(work, wl, wl, h);
    let src = src.view();
    let mut dst = Rows::new(data, sl, wl, h);
    for_each_row(&mut dst, parallel, |k, out| {
        synthesize_row(filter, w, lanes, src.row(signal_row(k, h, band_order)), out)
    });
    Ok(())
}

/// Signal row `k` of a vertical synthesis's output in `work`: lifting
/// leaves the rows in band order (low rows, then high rows).
fn signal_row(k: usize, h: usize, band_order: bool) -> usize {
    if band_order && k % 2 == 1 {
        h.div_ceil(2) + k / 2
    } else if band_order {
        k / 2
    } else {
        k
    }
}

/// The horizontal synthesis of one row of `lanes` interleaved images
/// (`w` pixels) from its bands.
fn synthesize_row(filter: Filter, w: usize, lanes: usize, bands: &[f32], out: &mut [f32]) {
    if w < 2 {
        out.copy_from_slice(bands)
    } else if lanes == 1 {
        inverse_row(filter, bands, out)
    } else if lanes == 4 {
        inverse_row_lanes::<4>(filter, bands.as_chunks().0, out.as_chunks_mut().0)
    } else if lanes == 3 {
        inverse_row_lanes::<3>(filter, bands.as_chunks().0, out.as_chunks_mut().0)
    } else {
        LANE_ROWS.with_borrow_mut(|buf| {
            buf.resize(2 * w, 0.0);
            let (lane, done) = buf.split_at_mut(w);
            for c in 0..lanes {
                for (l, b) in lane.iter_mut().zip(bands[c..].iter().step_by(lanes)) {
                    *l = *b;
                }
                inverse_row(filter, lane, done);
                for (o, d) in out[c..].iter_mut().step_by(lanes).zip(done.iter()) {
                    *o = *d;
                }
            }
        })
    }
}

/// [`inverse_step_lanes`] that skips rows known to be zero.
///
/// `nonzero[y]` (at least `h` flags) says whether image row `y` (all
/// `stride` pixels of it) may hold a nonzero value; a row marked `false`
/// must be all zero. Rows that are zero in both of their band rows' inputs
/// are neither filtered nor read, and come out zero. On return the first
/// `h` flags describe the rows after the step the same way (a flag may be
/// `true` for a row that happens to be zero, never the reverse).
///
/// The output equals [`inverse_step_lanes`]'s as f32 values: computed rows
/// get the same arithmetic bit for bit; a skipped row is `+0.0` where the
/// full step may give `−0.0`.
#[allow(clippy::too_many_arguments)]
pub fn inverse_step_lanes_sparse(
    filter: Filter,
    data: &mut [f32],
    stride: usize,
    w: usize,
    h: usize,
    lanes: usize,
    work: &mut [f32],
    nonzero: &mut [bool],
) -> Result<()> {
    if lanes == 0 {
        return Err(Error::range("interleaved lanes", lanes, "at least 1"));
    }
    check_region(data, stride * lanes, w * lanes, h, work)?;
    if nonzero.len() < h {
        return Err(Error::BufferTooSmall {
            what: "nonzero row flags",
            len: nonzero.len(),
            need: h,
        });
    }
    let parallel = w * h >= PARALLEL_MIN / lanes;
    let (wl, sl) = (w * lanes, stride * lanes);
    let work = &mut work[..wl * h];
    let rows_in = nonzero[..h].to_vec();
    // Vertical: data rows -> work rows; `live[r]` says whether work row `r`
    // was written (rows not written hold stale values and are not read).
    let mut live = rows_in.clone();
    match (filter.kind(), h >= 2) {
        (Kind::Lifting(scheme), true) => {
            // Lifting: vertical and horizontal together, strip by strip.
            let region = Region {
                filter,
                scheme,
                w,
                h,
                lanes,
                stride: sl,
            };
            live = region.synthesize_strips(data, work, &rows_in, parallel, false);
            region.write_back(data, work, &rows_in, &live, parallel);
        }
        (Kind::Periodic(t), true) => {
            periodic::inverse_rows_sparse(t, data, sl, work, wl, h, parallel, &mut live);
            synthesize_live_rows(
                filter, data, sl, work, w, h, lanes, &rows_in, &live, parallel,
            );
        }
        (_, false) => {
            if live[0] {
                work[..wl].copy_from_slice(&data[..wl]);
            }
            synthesize_live_rows(
                filter, data, sl, work, w, h, lanes, &rows_in, &live, parallel,
            );
        }
    }
    // A row's pixels right of the region (finer detail bands) are untouched.
    for (k, flag) in nonzero[..h].iter_mut().enumerate() {
        *flag = live[k] || (rows_in[k] && w < stride);
    }
    Ok(())
}

/// The horizontal pass of [`inverse_step_lanes_sparse`]: live work rows
/// (signal order) -> data rows; dead rows are zeroed (or left alone when
/// they already are).
#[allow(clippy::too_many_arguments)]
fn synthesize_live_rows(
    filter: Filter,
    data: &mut [f32],
    stride: usize,
    work: &[f32],
    w: usize,
    h: usize,
    lanes: usize,
    rows_in: &[bool],
    live: &[bool],
    parallel: bool,
) {
    let wl = w * lanes;
    let mut dst = Rows::new(data, stride, wl, h);
    for_each_row(&mut dst, parallel, |k, out| {
        if live[k] {
            synthesize_row(filter, w, lanes, &work[k * wl..][..wl], out)
        } else if rows_in[k] {
            out.fill(0.0)
        }
    });
}

/// [`inverse_step_lanes_sparse`] of a whole image (`w` pixels per row, no
/// stride) into `out` instead of in place: `out` gets every row of the
/// result (zero where `nonzero` comes back `false`), and `data` is left as
/// scratch (its values afterwards are unspecified). For a lifting filter
/// this is one pass, where the in-place step also copies its result back.
/// `out` needs `w · h · lanes` values; the result equals the in-place
/// step's as f32 values.
#[allow(clippy::too_many_arguments)]
pub fn inverse_step_lanes_sparse_into(
    filter: Filter,
    data: &mut [f32],
    w: usize,
    h: usize,
    lanes: usize,
    out: &mut [f32],
    nonzero: &mut [bool],
) -> Result<()> {
    if lanes == 0 {
        return Err(Error::range("interleaved lanes", lanes, "at least 1"));
    }
    let wl = w * lanes;
    check_region(data, wl, wl, h, out)?;
    if nonzero.len() < h {
        return Err(Error::BufferTooSmall {
            what: "nonzero row flags",
            len: nonzero.len(),
            need: h,
        });
    }
    let (data, out) = (&mut data[..wl * h], &mut out[..wl * h]);
    if let (Kind::Lifting(scheme), true) = (filter.kind(), h >= 2) {
        let region = Region {
            filter,
            scheme,
            w,
            h,
            lanes,
            stride: wl,
        };
        let parallel = w * h >= PARALLEL_MIN / lanes;
        let live = region.synthesize_strips(data, out, &nonzero[..h], parallel, true);
        nonzero[..h].copy_from_slice(&live);
        return Ok(());
    }
    out.copy_from_slice(data);
    inverse_step_lanes_sparse(filter, out, w, w, h, lanes, data, nonzero)
}

/// Samples of a strip's window, at most (256 KiB: a core's L2 holds it).
const STRIP_SAMPLES: usize = 1 << 16;

/// A lifting region of [`inverse_step_lanes_sparse`], synthesized in
/// horizontal strips: each strip's rows are lifted vertically in a window
/// of their own (a few rows wider, [`lifting::inverse_rows_window`]) and
/// synthesized horizontally while the window is in cache, into `work`; then
/// `work` is copied back. Two passes over the region, each one parallel
/// task set, where the row-by-row path makes one per lifting step.
struct Region<'a> {
    filter: Filter,
    scheme: &'a lifting::Scheme,
    w: usize,
    h: usize,
    lanes: usize,
    /// Samples between rows of `data`.
    stride: usize,
}

impl Region<'_> {
    /// Rows per strip: a window within [`STRIP_SAMPLES`], and at least two
    /// strips per thread when the region has the rows.
    fn strip_rows(&self) -> usize {
        let wl = self.w * self.lanes;
        let fits = (STRIP_SAMPLES / wl).saturating_sub(2 * self.scheme.steps.len());
        let spread = self.h.div_ceil(2 * rayon::current_num_threads());
        fits.min(spread).max(8)
    }

    /// Every strip into `work` (compact rows of `w · lanes`, signal order);
    /// returns which output rows may be nonzero (the others are zeroed with
    /// `zero_dead`, else not written).
    fn synthesize_strips(
        &self,
        data: &[f32],
        work: &mut [f32],
        rows_in: &[bool],
        parallel: bool,
        zero_dead: bool,
    ) -> Vec<bool> {
        let (wl, h) = (self.w * self.lanes, self.h);
        let strip = self.strip_rows();
        let mut live = vec![false; h];
        let task = |(i, (out, live)): (usize, (&mut [f32], &mut [bool]))| {
            WINDOW.with_borrow_mut(|(buf, flags)| {
                let a = i * strip;
                let rows = a..a + live.len();
                let w0 = lifting::inverse_rows_window(
                    self.scheme,
                    data,
                    self.stride,
                    wl,
                    h,
                    rows_in,
                    rows,
                    buf,
                    flags,
                );
                for (k, (o, l)) in out.chunks_exact_mut(wl).zip(live.iter_mut()).enumerate() {
                    let r = a + k - w0;
                    *l = flags[r];
                    if *l {
                        synthesize_row(self.filter, self.w, self.lanes, &buf[r * wl..][..wl], o);
                    } else if zero_dead {
                        o.fill(0.0);
                    }
                }
            })
        };
        let strips = work[..wl * h]
            .chunks_mut(strip * wl)
            .zip(live.chunks_mut(strip));
        if parallel {
            let strips: Vec<_> = strips.collect();
            strips.into_par_iter().enumerate().for_each(task);
        } else {
            strips.enumerate().for_each(task);
        }
        live
    }

    /// The synthesized rows from `work` into `data`; rows not live are
    /// zeroed where they held values.
    fn write_back(
        &self,
        data: &mut [f32],
        work: &[f32],
        rows_in: &[bool],
        live: &[bool],
        parallel: bool,
    ) {
        let wl = self.w * self.lanes;
        let mut dst = Rows::new(data, self.stride, wl, self.h);
        for_each_row(&mut dst, parallel, |k, out| {
            if live[k] {
                lifting::copy_scaled(out, &work[k * wl..][..wl], 1.0)
            } else if rows_in[k] {
                out.fill(0.0)
            }
        });
    }
}

thread_local! {
    /// A strip's window rows and flags, per thread, for [`Region`].
    #[allow(clippy::type_complexity)]
    static WINDOW: std::cell::RefCell<(Vec<f32>, Vec<bool>)> =
        const { std::cell::RefCell::new((Vec::new(), Vec::new())) };
    /// One lane's row and its synthesis, per thread, for [`inverse_step_lanes`].
    static LANE_ROWS: std::cell::RefCell<Vec<f32>> = const { std::cell::RefCell::new(Vec::new()) };
}

fn check_levels(width: usize, height: usize, levels: u32) -> Result<()> {
    let max = max_levels(width, height);
    if levels > max {
        return Err(Error::range(
            "wavelet levels",
            levels,
            format!("0..={max} for a {width}x{height} image"),
        ));
    }
    Ok(())
}

/// `levels` forward steps of a `width` × `height` image in the Mallat layout.
/// `work` needs `width · height` values.
pub fn forward(
    filter: Filter,
    data: &mut [f32],
    width: usize,
    height: usize,
    levels: u32,
    work: &mut [f32],
) -> Result<()> {
    check_levels(width, height, levels)?;
    for level in 0..levels {
        let (w, h) = band_size(width, height, level);
        forward_step(filter, data, width, w, h, work)?;
    }
    Ok(())
}

/// The inverse of [`forward`] with the same `levels`.
pub fn inverse(
    filter: Filter,
    data: &mut [f32],
    width: usize,
    height: usize,
    levels: u32,
    work: &mut [f32],
) -> Result<()> {
    check_levels(width, height, levels)?;
    for level in (0..levels).rev() {
        let (w, h) = band_size(width, height, level);
        inverse_step(filter, data, width, w, h, work)?;
    }
    Ok(())
}

/// Multi-level 1D forward transform of a signal (a 1-row image).
pub fn forward_1d(filter: Filter, data: &mut [f32], levels: u32, work: &mut [f32]) -> Result<()> {
    forward(filter, data, data.len(), 1, levels, work)
}

/// The inverse of [`forward_1d`].
pub fn inverse_1d(filter: Filter, data: &mut [f32], levels: u32, work: &mut [f32]) -> Result<()> {
    inverse(filter, data, data.len(), 1, levels, work)
}
