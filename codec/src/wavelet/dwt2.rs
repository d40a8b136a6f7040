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
    let mut band_order = false;
    if h >= 2 {
        match filter.kind() {
            Kind::Periodic(t) => {
                periodic::inverse_rows_sparse(t, data, sl, work, wl, h, parallel, &mut live)
            }
            Kind::Lifting(s) => {
                lifting::inverse_rows_sparse(s, data, sl, work, wl, h, parallel, &mut live);
                band_order = true;
            }
        }
    } else if live[0] {
        work[..wl].copy_from_slice(&data[..wl]);
    }
    // Horizontal: live work rows -> data rows; dead rows are zeroed (or left
    // alone when they already are).
    let src = Rows::new(work, wl, wl, h);
    let src = src.view();
    let mut dst = Rows::new(data, sl, wl, h);
    for_each_row(&mut dst, parallel, |k, out| {
        let r = signal_row(k, h, band_order);
        if live[r] {
            synthesize_row(filter, w, lanes, src.row(r), out)
        } else if rows_in[k] {
            out.fill(0.0)
        }
    });
    // A row's pixels right of the region (finer detail bands) are untouched.
    for (k, flag) in nonzero[..h].iter_mut().enumerate() {
        *flag = live[signal_row(k, h, band_order)] || (rows_in[k] && w < stride);
    }
    Ok(())
}

thread_local! {
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
