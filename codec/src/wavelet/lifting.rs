//! Biorthogonal filters by lifting (Daubechies & Sweldens 1998), with the
//! whole-sample symmetric extension of JPEG 2000 (ISO/IEC 15444-1 Annex F):
//! `x[-1] = x[1]`, `x[n] = x[n-2]`.
//!
//! A scheme is a list of predict steps (`high[i] += c·(low[i] + low[i+1])`)
//! and update steps (`low[i] += c·(high[i-1] + high[i])`), then a scaling of
//! each band. Low band = even samples, high band = odd samples.

use super::dwt2::{for_each_row, Rows, RowsRef};

#[derive(Clone, Copy)]
pub(crate) enum Step {
    Predict(f32),
    Update(f32),
}

pub(crate) struct Scheme {
    pub steps: &'static [Step],
    pub low_scale: f32,
    pub high_scale: f32,
}

impl Scheme {
    /// `(predict, update)` coefficients of a scheme of one predict step, one
    /// update step and unit scales (LeGall 5/3), which has one-pass inverses.
    pub(crate) fn two_step(&self) -> Option<(f32, f32)> {
        match self.steps {
            [Step::Predict(cp), Step::Update(cu)]
                if self.low_scale == 1.0 && self.high_scale == 1.0 =>
            {
                Some((*cp, *cu))
            }
            _ => None,
        }
    }
}

/// LeGall 5/3: DC gain 1, Nyquist gain 2.
pub(crate) static LEGALL53: Scheme = Scheme {
    steps: &[Step::Predict(-0.5), Step::Update(0.25)],
    low_scale: 1.0,
    high_scale: 1.0,
};

const CDF97_K: f64 = 1.230_174_104_914_001;
const CDF97_ALPHA: f64 = -1.586_134_342_059_924;
const CDF97_BETA: f64 = -0.052_980_118_572_961;
const CDF97_GAMMA: f64 = 0.882_911_075_530_934;
const CDF97_DELTA: f64 = 0.443_506_852_043_971;

/// CDF 9/7 with JPEG 2000's lifting constants; scaled by `1/K` (low) and `K`
/// (high), which gives DC gain 1 and Nyquist gain 2 like the 5/3.
pub(crate) static CDF97: Scheme = Scheme {
    steps: &[
        Step::Predict(CDF97_ALPHA as f32),
        Step::Update(CDF97_BETA as f32),
        Step::Predict(CDF97_GAMMA as f32),
        Step::Update(CDF97_DELTA as f32),
    ],
    low_scale: (1.0 / CDF97_K) as f32,
    high_scale: CDF97_K as f32,
};

// ---- 1D, one sample per element: the scalar reference path ----

fn predict(low: &[f32], high: &mut [f32], c: f32) {
    let ns = low.len();
    for (i, h) in high.iter_mut().enumerate() {
        *h += c * (low[i] + low[(i + 1).min(ns - 1)]);
    }
}

fn update(low: &mut [f32], high: &[f32], c: f32) {
    let nd = high.len();
    for (i, l) in low.iter_mut().enumerate() {
        *l += c * (high[i.saturating_sub(1)] + high[i.min(nd - 1)]);
    }
}

fn scale(x: &mut [f32], s: f32) {
    if s != 1.0 {
        x.iter_mut().for_each(|v| *v *= s);
    }
}

/// One analysis step of `x` (length >= 2) into `out` as `[low | high]`.
pub(crate) fn forward_1d(scheme: &Scheme, x: &[f32], out: &mut [f32]) {
    let n = x.len();
    let ns = n.div_ceil(2);
    let (low, high) = out[..n].split_at_mut(ns);
    for (i, l) in low.iter_mut().enumerate() {
        *l = x[2 * i];
    }
    for (i, h) in high.iter_mut().enumerate() {
        *h = x[2 * i + 1];
    }
    for step in scheme.steps {
        match *step {
            Step::Predict(c) => predict(low, high, c),
            Step::Update(c) => update(low, high, c),
        }
    }
    scale(low, scheme.low_scale);
    scale(high, scheme.high_scale);
}

/// One synthesis step from `bands` (`[low | high]`) into the signal `out`.
/// The lifting is undone in place on the interleaved signal.
pub(crate) fn inverse_1d(scheme: &Scheme, bands: &[f32], out: &mut [f32]) {
    let n = bands.len();
    let ns = n.div_ceil(2);
    let (low, high) = bands.split_at(ns);
    // Division by a scale of 1 is the identity: skipped (same bits).
    let unscale = |v: f32, s: f32| if s == 1.0 { v } else { v / s };
    for (i, l) in low.iter().enumerate() {
        out[2 * i] = unscale(*l, scheme.low_scale);
    }
    for (i, h) in high.iter().enumerate() {
        out[2 * i + 1] = unscale(*h, scheme.high_scale);
    }
    let last_even = 2 * (ns - 1);
    let last_odd = 2 * (n / 2) - 1;
    for step in scheme.steps.iter().rev() {
        match *step {
            Step::Predict(c) => {
                for k in (1..n).step_by(2) {
                    out[k] -= c * (out[k - 1] + out[(k + 1).min(last_even)]);
                }
            }
            Step::Update(c) => {
                for k in (0..n).step_by(2) {
                    let left = if k == 0 { 1 } else { k - 1 };
                    out[k] -= c * (out[left] + out[(k + 1).min(last_odd)]);
                }
            }
        }
    }
}

/// [`inverse_1d`] on `L` interleaved signals at once: each lane gets the
/// same f32 operations in the same order, so the same bits.
pub(crate) fn inverse_1d_lanes<const L: usize>(
    scheme: &Scheme,
    bands: &[[f32; L]],
    out: &mut [[f32; L]],
) {
    if let Some((cp, cu)) = scheme.two_step() {
        return two_step_1d_lanes(cp, cu, bands, out);
    }
    let n = bands.len();
    let ns = n.div_ceil(2);
    let (low, high) = bands.split_at(ns);
    // Division by a scale of 1 is the identity: skipped (same bits).
    if scheme.low_scale == 1.0 && scheme.high_scale == 1.0 {
        for (o, (l, h)) in out.chunks_exact_mut(2).zip(low.iter().zip(high)) {
            o[0] = *l;
            o[1] = *h;
        }
        if n % 2 == 1 {
            out[n - 1] = low[ns - 1];
        }
    } else {
        for (i, l) in low.iter().enumerate() {
            out[2 * i] = l.map(|v| v / scheme.low_scale);
        }
        for (i, h) in high.iter().enumerate() {
            out[2 * i + 1] = h.map(|v| v / scheme.high_scale);
        }
    }
    let last_even = 2 * (ns - 1);
    let last_odd = 2 * (n / 2) - 1;
    let lift = |x: &mut [f32; L], c: f32, a: [f32; L], b: [f32; L]| {
        for ((x, a), b) in x.iter_mut().zip(a).zip(b) {
            *x -= c * (a + b);
        }
    };
    for step in scheme.steps.iter().rev() {
        match *step {
            Step::Predict(c) => {
                for k in (1..n).step_by(2) {
                    let (a, b) = (out[k - 1], out[(k + 1).min(last_even)]);
                    lift(&mut out[k], c, a, b);
                }
            }
            Step::Update(c) => {
                for k in (0..n).step_by(2) {
                    let left = if k == 0 { 1 } else { k - 1 };
                    let (a, b) = (out[left], out[(k + 1).min(last_odd)]);
                    lift(&mut out[k], c, a, b);
                }
            }
        }
    }
}

/// [`inverse_1d_lanes`] of a [`Scheme::two_step`] scheme in one sweep: each
/// even sample `e_i = low_i − cu·(high_{i−1} + high_i)` is made once and
/// kept for the odd sample `high_i − cp·(e_i + e_{i+1})` (mirrored at both
/// ends as in [`inverse_1d`]): the same operations on the same values.
fn two_step_1d_lanes<const L: usize>(cp: f32, cu: f32, bands: &[[f32; L]], out: &mut [[f32; L]]) {
    let n = bands.len();
    let ns = n.div_ceil(2);
    let nd = n - ns;
    let (low, high) = bands.split_at(ns);
    let lift = |x: [f32; L], c: f32, a: [f32; L], b: [f32; L]| {
        let mut x = x;
        for ((x, a), b) in x.iter_mut().zip(a).zip(b) {
            *x -= c * (a + b);
        }
        x
    };
    let even = |i: usize| lift(low[i], cu, high[i.saturating_sub(1)], high[i.min(nd - 1)]);
    let mut e = even(0);
    for (i, pair) in out[..2 * nd].chunks_exact_mut(2).enumerate() {
        let next = if i + 1 < ns { even(i + 1) } else { e };
        pair[0] = e;
        pair[1] = lift(high[i], cp, e, next);
        e = next;
    }
    if ns > nd {
        out[n - 1] = e;
    }
}

// ---- Vertical: one sample per image row, applied to whole rows ----

/// `dst += c·(a + b)`. Not inlined: as a call its slices are known not to
/// overlap, which lets it vectorize wherever it is used.
#[inline(never)]
fn axpy2(dst: &mut [f32], c: f32, a: &[f32], b: &[f32]) {
    for ((d, a), b) in dst.iter_mut().zip(a).zip(b) {
        *d += c * (a + b);
    }
}

fn lift_rows(low: &mut Rows, high: &mut Rows, step: Step, parallel: bool) {
    let (ns, nd) = (low.rows, high.rows);
    match step {
        Step::Predict(c) => {
            let src = low.view();
            for_each_row(high, parallel, |i, row| {
                axpy2(row, c, src.row(i), src.row((i + 1).min(ns - 1)))
            });
        }
        Step::Update(c) => {
            let src = high.view();
            for_each_row(low, parallel, |i, row| {
                axpy2(row, c, src.row(i.saturating_sub(1)), src.row(i.min(nd - 1)))
            });
        }
    }
}

fn scale_rows(rows: &mut Rows, s: f32, parallel: bool) {
    if s != 1.0 {
        for_each_row(rows, parallel, |_, row| {
            row.iter_mut().for_each(|v| *v *= s)
        });
    }
}

/// Vertical analysis: `src` holds `h` compact rows of `w`; the bands are
/// written to `dst` (rows of `stride`), low rows first.
pub(crate) fn forward_rows(
    scheme: &Scheme,
    src: &[f32],
    dst: &mut [f32],
    stride: usize,
    w: usize,
    h: usize,
    parallel: bool,
) {
    let ns = h.div_ceil(2);
    let (low, high) = dst.split_at_mut(ns * stride);
    let mut low = Rows::new(low, stride, w, ns);
    let mut high = Rows::new(high, stride, w, h - ns);
    for_each_row(&mut low, parallel, |i, row| {
        row.copy_from_slice(&src[2 * i * w..][..w])
    });
    for_each_row(&mut high, parallel, |i, row| {
        row.copy_from_slice(&src[(2 * i + 1) * w..][..w])
    });
    for step in scheme.steps {
        lift_rows(&mut low, &mut high, *step, parallel);
    }
    scale_rows(&mut low, scheme.low_scale, parallel);
    scale_rows(&mut high, scheme.high_scale, parallel);
}

/// Vertical synthesis: `src` holds the bands in rows of `stride` (low rows
/// first); the `h` reconstructed rows of `w` are written compactly to `work`.
pub(crate) fn inverse_rows(
    scheme: &Scheme,
    src: &[f32],
    stride: usize,
    work: &mut [f32],
    w: usize,
    h: usize,
    parallel: bool,
) {
    let ns = h.div_ceil(2);
    // Bands into `work` (compact), lifting undone there, then interleaved by
    // the caller's horizontal pass through `interleaved_row`.
    for (i, row) in work[..h * w].chunks_mut(w).enumerate() {
        row.copy_from_slice(&src[i * stride..][..w]);
    }
    let (low, high) = work[..h * w].split_at_mut(ns * w);
    let mut low = Rows::new(low, w, w, ns);
    let mut high = Rows::new(high, w, w, h - ns);
    scale_rows(&mut low, 1.0 / scheme.low_scale, parallel);
    scale_rows(&mut high, 1.0 / scheme.high_scale, parallel);
    for step in scheme.steps.iter().rev() {
        let inverse = match *step {
            Step::Predict(c) => Step::Predict(-c),
            Step::Update(c) => Step::Update(-c),
        };
        lift_rows(&mut low, &mut high, inverse, parallel);
    }
}

/// A window of signal rows of a vertical synthesis and their flags
/// ([`inverse_rows_window`]), kept per thread between calls.
pub(crate) struct Window {
    /// The window's rows (and scratch past them), in signal order.
    pub buf: Vec<f32>,
    /// Whether each of the window's rows may be nonzero.
    pub flags: Vec<bool>,
}

impl Window {
    pub const fn new() -> Window {
        Window {
            buf: Vec::new(),
            flags: Vec::new(),
        }
    }
}

/// The signal rows `rows` of a vertical synthesis ([`inverse_rows`]),
/// computed in a window of rows alone: `bands` holds the `h` band rows
/// (`stride` apart, `w` used, low rows first) and `live_in` their flags (a
/// row marked `false` is all zero and is not read). The window `[w0, w1)`
/// (returned as `w0`) widens `rows` by one row per lifting step; `win.buf`
/// gets its rows in signal order and `win.flags` whether each may be nonzero. A
/// lifting step whose two sources are zero is skipped (it would add `±0`);
/// every other row gets exactly the arithmetic of [`inverse_rows`] (and of
/// [`inverse_1d`] down the columns), so splitting a region into windows
/// changes no bit.
pub(crate) fn inverse_rows_window(
    scheme: &Scheme,
    bands: RowsRef<'_>,
    live_in: &[bool],
    rows: std::ops::Range<usize>,
    win: &mut Window,
) -> usize {
    if let Some((cp, cu)) = scheme.two_step() {
        return two_step_window((cp, cu), bands, live_in, rows, win);
    }
    let (w, h) = (bands.w, bands.rows);
    let steps = scheme.steps.len();
    let ns = h.div_ceil(2);
    let (w0, w1) = (rows.start.saturating_sub(steps), (rows.end + steps).min(h));
    gather_window(scheme, bands, live_in, w0..w1, win);
    let Window { buf, flags } = win;
    let (last_even, last_odd) = (2 * (ns - 1), 2 * (h / 2) - 1);
    for (t, step) in scheme.steps.iter().rev().enumerate() {
        // Rows still needed after this step: `rows` widened by the steps left.
        let margin = steps - 1 - t;
        let (lo, hi) = (
            rows.start.saturating_sub(margin),
            (rows.end + margin).min(h),
        );
        let (parity, c) = match *step {
            Step::Predict(c) => (1, -c),
            Step::Update(c) => (0, -c),
        };
        for k in (lo + usize::from(lo % 2 != parity)..hi).step_by(2) {
            let (x, y) = match parity {
                1 => (k - 1, (k + 1).min(last_even)),
                _ => (if k == 0 { 1 } else { k - 1 }, (k + 1).min(last_odd)),
            };
            if flags[x - w0] || flags[y - w0] {
                let (row, a, b) = row_and_sources(buf, w, k - w0, x - w0, y - w0);
                axpy2(row, c, a, b);
                flags[k - w0] = true;
            }
        }
    }
    w0
}

/// The band rows of the signal rows `window` into `win.buf` (signal
/// order), unscaled; rows not live are written as zeros.
fn gather_window(
    scheme: &Scheme,
    bands: RowsRef<'_>,
    live_in: &[bool],
    window: std::ops::Range<usize>,
    win: &mut Window,
) {
    let (src, stride, w) = (bands.data, bands.stride, bands.w);
    let ns = bands.rows.div_ceil(2);
    let Window { buf, flags } = win;
    let inverse = [1.0 / scheme.low_scale, 1.0 / scheme.high_scale];
    buf.resize(window.len() * w, 0.0);
    flags.clear();
    for (k, row) in window.zip(buf.chunks_exact_mut(w)) {
        let band = if k % 2 == 0 { k / 2 } else { ns + k / 2 };
        flags.push(live_in[band]);
        if !live_in[band] {
            row.fill(0.0);
            continue;
        }
        let from = &src[band * stride..][..w];
        copy_scaled(row, from, inverse[k % 2]);
    }
}

/// Row `k` of `buf` (rows of `w`) mutably, with rows `x` and `y` (both not
/// `k`) to read.
fn row_and_sources(
    buf: &mut [f32],
    w: usize,
    k: usize,
    x: usize,
    y: usize,
) -> (&mut [f32], &[f32], &[f32]) {
    let (before, rest) = buf.split_at_mut(k * w);
    let (row, after) = rest.split_at_mut(w);
    let (before, after) = (&*before, &*after);
    let pick = |i: usize| {
        if i < k {
            &before[i * w..][..w]
        } else {
            &after[(i - k - 1) * w..][..w]
        }
    };
    (row, pick(x), pick(y))
}

/// `dst = src·s` (bit-exact copies for `s = 1`). The factor is opaque to
/// the optimizer, so that the loop stays a vector loop instead of becoming
/// a `memmove` call: glibc's `rep movsb` path runs these row copies
/// between page-aligned buffers several times slower on the AMD CPUs we
/// measured.
pub(crate) fn copy_scaled(dst: &mut [f32], src: &[f32], s: f32) {
    let s = std::hint::black_box(s);
    dst.iter_mut().zip(src).for_each(|(d, v)| *d = v * s);
}

/// [`inverse_rows_window`] for a [`Scheme::two_step`] scheme: each window
/// row is written once, straight from the band rows (no gather): the even
/// rows of `[start − 1, end + 1)` by the update, then the odd rows of
/// `rows` by the predict. The same arithmetic as the general path: a row
/// is `own + (−c)·(a + b)`, with rows that are not live read as `+0.0`, and
/// left as it is when both sources are not live. `(cp, cu)` are the
/// scheme's predict and update coefficients.
fn two_step_window(
    (cp, cu): (f32, f32),
    bands: RowsRef<'_>,
    live_in: &[bool],
    rows: std::ops::Range<usize>,
    win: &mut Window,
) -> usize {
    let (src, stride, w, h) = (bands.data, bands.stride, bands.w, bands.rows);
    let Window { buf, flags } = win;
    let ns = h.div_ceil(2);
    let (last_even, last_odd) = (2 * (ns - 1), 2 * (h / 2) - 1);
    let (w0, w1) = (rows.start.saturating_sub(2), (rows.end + 2).min(h));
    // The window's rows, then one row of zeros (read for rows not live).
    buf.resize((w1 - w0 + 1) * w, 0.0);
    let (buf, zeros) = buf.split_at_mut((w1 - w0) * w);
    zeros.fill(0.0);
    let zeros = &*zeros;
    flags.clear();
    flags.resize(w1 - w0, false);
    let band = |k: usize| {
        if k.is_multiple_of(2) {
            k / 2
        } else {
            ns + k / 2
        }
    };
    let input = |k: usize| {
        let b = band(k);
        live_in[b].then(|| &src[b * stride..][..w])
    };
    // Update: even rows from the band rows.
    let (lo, hi) = (rows.start.saturating_sub(1), (rows.end + 1).min(h));
    for k in (lo + lo % 2..hi).step_by(2) {
        let (x, y) = (if k == 0 { 1 } else { k - 1 }, (k + 1).min(last_odd));
        let dst = &mut buf[(k - w0) * w..][..w];
        let own = input(k);
        flags[k - w0] = match (input(x), input(y)) {
            (None, None) => {
                copy_scaled(dst, own.unwrap_or(zeros), 1.0);
                own.is_some()
            }
            (a, b) => {
                lift_into(
                    dst,
                    own.unwrap_or(zeros),
                    -cu,
                    a.unwrap_or(zeros),
                    b.unwrap_or(zeros),
                );
                true
            }
        };
    }
    // Predict: odd rows of `rows` from the even rows just made.
    for k in (rows.start + (1 - rows.start % 2)..rows.end).step_by(2) {
        let (x, y) = (k - 1, (k + 1).min(last_even));
        let own = input(k);
        let (row, a, b) = row_and_sources(buf, w, k - w0, x - w0, y - w0);
        flags[k - w0] = if flags[x - w0] || flags[y - w0] {
            lift_into(row, own.unwrap_or(zeros), -cp, a, b);
            true
        } else {
            copy_scaled(row, own.unwrap_or(zeros), 1.0);
            own.is_some()
        };
    }
    w0
}

/// `dst = own + c·(a + b)`. Not inlined, so that it vectorizes (see
/// [`axpy2`]).
#[inline(never)]
fn lift_into(dst: &mut [f32], own: &[f32], c: f32, a: &[f32], b: &[f32]) {
    for (((d, o), a), b) in dst.iter_mut().zip(own).zip(a).zip(b) {
        *d = o + c * (a + b);
    }
}
