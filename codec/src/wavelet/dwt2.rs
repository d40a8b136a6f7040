//! Separable 2D steps in the Mallat layout, and the multi-level transforms
//! built on them.

use super::plane::{PlaneMut, RowMode};
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

/// `rows` rows of `w` used values each, `stride` apart, in `data`, to read.
#[derive(Clone, Copy)]
pub(crate) struct RowsRef<'a> {
    pub data: &'a [f32],
    pub stride: usize,
    pub w: usize,
    pub rows: usize,
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
            rows: self.rows,
        }
    }
}

impl<'a> RowsRef<'a> {
    pub fn new(data: &'a [f32], stride: usize, w: usize, rows: usize) -> RowsRef<'a> {
        RowsRef {
            data,
            stride,
            w,
            rows,
        }
    }

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

/// One forward step on the region of `plane` (one lane): rows are split
/// into low | high halves (if `width >= 2`), then columns (if
/// `height >= 2`). `work` needs `width · height` values.
pub fn forward_step(filter: Filter, plane: PlaneMut<'_>, work: &mut [f32]) -> Result<()> {
    if plane.lanes != 1 {
        return Err(Error::range(
            "forward step lanes",
            plane.lanes,
            "1 (interleaved images are transformed one at a time)",
        ));
    }
    plane.check_scratch("wavelet scratch", work)?;
    let (stride, w, h) = (plane.stride, plane.width, plane.height);
    let data = plane.data;
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

/// One inverse step: the exact inverse of [`forward_step`] on the region of
/// `plane`, on every lane of it (each interleaved image gets exactly the
/// arithmetic it would get alone, so the results are bit-identical to
/// stepping the images one by one; the vertical pass runs once over all
/// lanes, the horizontal one per row and lane).
///
/// `rows` says which rows are filtered: all of them ([`RowMode::Dense`]),
/// or only those that may be nonzero ([`RowMode::Sparse`], in place or
/// into a second buffer). `work` is scratch of [`PlaneMut::samples`]
/// values (unused, and may be empty, for a sparse step into a second
/// buffer).
pub fn inverse_step(
    filter: Filter,
    plane: PlaneMut<'_>,
    work: &mut [f32],
    rows: RowMode<'_>,
) -> Result<()> {
    let RowMode::Sparse { nonzero, out } = rows else {
        plane.check_scratch("wavelet scratch", work)?;
        dense_step(filter, plane, work);
        return Ok(());
    };
    if nonzero.len() < plane.height {
        return Err(Error::BufferTooSmall {
            what: "nonzero row flags",
            len: nonzero.len(),
            need: plane.height,
        });
    }
    let nonzero = &mut nonzero[..plane.height];
    match out {
        None => {
            plane.check_scratch("wavelet scratch", work)?;
            sparse_step(filter, plane, work, nonzero);
        }
        Some(out) => {
            if plane.stride != plane.width {
                return Err(Error::range(
                    "row stride of a step into a second buffer",
                    plane.stride,
                    format!("{} (the width: a whole image)", plane.width),
                ));
            }
            plane.check_scratch("wavelet output", out)?;
            sparse_step_into(filter, plane, out, nonzero);
        }
    }
    Ok(())
}

/// [`RowMode::Dense`]: every row, in place (`work` checked).
fn dense_step(filter: Filter, plane: PlaneMut<'_>, work: &mut [f32]) {
    let (w, h, lanes) = (plane.width, plane.height, plane.lanes);
    let parallel = w * h >= PARALLEL_MIN / lanes;
    let (wl, sl) = (plane.row_len(), plane.row_stride());
    let data = plane.data;
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

/// [`RowMode::Sparse`] in place (`work` and `nonzero`, `height` flags,
/// checked).
fn sparse_step(filter: Filter, mut plane: PlaneMut<'_>, work: &mut [f32], nonzero: &mut [bool]) {
    let (w, h, lanes) = (plane.width, plane.height, plane.lanes);
    let parallel = w * h >= PARALLEL_MIN / lanes;
    let wl = plane.row_len();
    let work = &mut work[..wl * h];
    let rows_in = nonzero.to_vec();
    // Vertical: data rows -> work rows; `live[r]` says whether work row `r`
    // was written (rows not written hold stale values and are not read).
    let mut live = rows_in.clone();
    match (filter.kind(), h >= 2) {
        (Kind::Lifting(scheme), true) => {
            // Lifting: vertical and horizontal together, strip by strip.
            let region = Region::new(filter, scheme, &plane);
            live = region.synthesize_strips(plane.data, work, &rows_in, parallel, false);
            region.write_back(plane.data, work, &rows_in, &live, parallel);
        }
        (Kind::Periodic(t), true) => {
            let src = RowsRef::new(plane.data, plane.row_stride(), wl, h);
            periodic::inverse_rows_sparse(t, src, work, parallel, &mut live);
            synthesize_live_rows(filter, &mut plane, work, &rows_in, &live, parallel);
        }
        (_, false) => {
            if live[0] {
                work[..wl].copy_from_slice(&plane.data[..wl]);
            }
            synthesize_live_rows(filter, &mut plane, work, &rows_in, &live, parallel);
        }
    }
    // A row's pixels right of the region (finer detail bands) are untouched.
    for (k, flag) in nonzero.iter_mut().enumerate() {
        *flag = live[k] || (rows_in[k] && w < plane.stride);
    }
}

/// The horizontal pass of [`sparse_step`]: live work rows (signal order)
/// -> the plane's rows; dead rows are zeroed (or left alone when they
/// already are).
fn synthesize_live_rows(
    filter: Filter,
    plane: &mut PlaneMut<'_>,
    work: &[f32],
    rows_in: &[bool],
    live: &[bool],
    parallel: bool,
) {
    let (w, h, lanes) = (plane.width, plane.height, plane.lanes);
    let wl = w * lanes;
    let mut dst = Rows::new(plane.data, plane.row_stride(), wl, h);
    for_each_row(&mut dst, parallel, |k, out| {
        if live[k] {
            synthesize_row(filter, w, lanes, &work[k * wl..][..wl], out)
        } else if rows_in[k] {
            out.fill(0.0)
        }
    });
}

/// [`RowMode::Sparse`] into `out` (a whole image: `stride = width`; `out`
/// and `nonzero`, `height` flags, checked). For a lifting filter one pass
/// into `out`; otherwise `out` gets a copy of the plane, stepped in place
/// with the plane's data as scratch.
fn sparse_step_into(filter: Filter, plane: PlaneMut<'_>, out: &mut [f32], nonzero: &mut [bool]) {
    let (w, h, lanes) = (plane.width, plane.height, plane.lanes);
    let n = plane.samples();
    if let (Kind::Lifting(scheme), true) = (filter.kind(), h >= 2) {
        let region = Region::new(filter, scheme, &plane);
        let parallel = w * h >= PARALLEL_MIN / lanes;
        let (data, out) = (&plane.data[..n], &mut out[..n]);
        let live = region.synthesize_strips(data, out, nonzero, parallel, true);
        nonzero.copy_from_slice(&live);
        return;
    }
    let (data, out) = (&mut plane.data[..n], &mut out[..n]);
    out.copy_from_slice(data);
    let plane = PlaneMut {
        data: out,
        stride: w,
        width: w,
        height: h,
        lanes,
    };
    sparse_step(filter, plane, data, nonzero)
}

/// Samples of a strip's window, at most (256 KiB: a core's L2 holds it).
const STRIP_SAMPLES: usize = 1 << 16;

/// A lifting region of a [`RowMode::Sparse`] step, synthesized in
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

impl<'a> Region<'a> {
    fn new(filter: Filter, scheme: &'a lifting::Scheme, plane: &PlaneMut<'_>) -> Region<'a> {
        Region {
            filter,
            scheme,
            w: plane.width,
            h: plane.height,
            lanes: plane.lanes,
            stride: plane.row_stride(),
        }
    }

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
        let bands = RowsRef::new(data, self.stride, wl, h);
        let task = |(i, (out, live)): (usize, (&mut [f32], &mut [bool]))| {
            WINDOW.with_borrow_mut(|win| {
                let a = i * strip;
                let rows = a..a + live.len();
                let w0 = lifting::inverse_rows_window(self.scheme, bands, rows_in, rows, win);
                let (buf, flags) = (&win.buf, &win.flags);
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
    static WINDOW: std::cell::RefCell<lifting::Window> =
        const { std::cell::RefCell::new(lifting::Window::new()) };
    /// One lane's row and its synthesis, per thread, for [`synthesize_row`].
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
        forward_step(filter, PlaneMut::new(data, width, w, h, 1)?, work)?;
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
        let plane = PlaneMut::new(data, width, w, h, 1)?;
        inverse_step(filter, plane, work, RowMode::Dense)?;
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
