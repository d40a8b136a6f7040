//! Biorthogonal filters by lifting (Daubechies & Sweldens 1998), with the
//! whole-sample symmetric extension of JPEG 2000 (ISO/IEC 15444-1 Annex F):
//! `x[-1] = x[1]`, `x[n] = x[n-2]`.
//!
//! A scheme is a list of predict steps (`high[i] += c·(low[i] + low[i+1])`)
//! and update steps (`low[i] += c·(high[i-1] + high[i])`), then a scaling of
//! each band. Low band = even samples, high band = odd samples.

use super::dwt2::{for_each_row, Rows};

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

// ---- Vertical: one sample per image row, applied to whole rows ----

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

/// [`inverse_rows`] skipping zero rows. On entry `live[i]` says whether
/// band row `i` of `src` (low rows first) may be nonzero (a row marked
/// `false` is all zero); on return it says whether row `i` of `work` (band
/// order) was written. Rows of `work` not written hold stale values: they
/// are zero and are read as zero here. A lifting step on a row whose two
/// sources are both zero is skipped (it would add `±0`).
#[allow(clippy::too_many_arguments)]
pub(crate) fn inverse_rows_sparse(
    scheme: &Scheme,
    src: &[f32],
    stride: usize,
    work: &mut [f32],
    w: usize,
    h: usize,
    parallel: bool,
    live: &mut [bool],
) {
    let ns = h.div_ceil(2);
    let mut rows = Rows::new(&mut work[..h * w], w, w, h);
    let flags: &[bool] = live;
    for_each_row(&mut rows, parallel, |i, row| {
        if flags[i] {
            row.copy_from_slice(&src[i * stride..][..w]);
        }
    });
    let (low, high) = work[..h * w].split_at_mut(ns * w);
    let mut low = Rows::new(low, w, w, ns);
    let mut high = Rows::new(high, w, w, h - ns);
    let (live_low, live_high) = live[..h].split_at_mut(ns);
    scale_live_rows(&mut low, 1.0 / scheme.low_scale, parallel, live_low);
    scale_live_rows(&mut high, 1.0 / scheme.high_scale, parallel, live_high);
    let zeros = vec![0.0f32; w];
    for step in scheme.steps.iter().rev() {
        match *step {
            Step::Predict(c) => {
                let sources = |i: usize| [i, (i + 1).min(ns - 1)];
                lift_live_rows(
                    &mut high, &low, -c, parallel, live_high, live_low, &zeros, sources,
                )
            }
            Step::Update(c) => {
                let nd = h - ns;
                let sources = |i: usize| [i.saturating_sub(1), i.min(nd - 1)];
                lift_live_rows(
                    &mut low, &high, -c, parallel, live_low, live_high, &zeros, sources,
                )
            }
        }
    }
}

fn scale_live_rows(rows: &mut Rows, s: f32, parallel: bool, live: &[bool]) {
    if s != 1.0 {
        for_each_row(rows, parallel, |i, row| {
            if live[i] {
                row.iter_mut().for_each(|v| *v *= s)
            }
        });
    }
}

/// One lifting step `dst[i] += c·(src[a] + src[b])` with `[a, b] =
/// sources(i)`, on live rows only (dead sources read as `zeros`, a dead
/// destination is zeroed before it is written).
#[allow(clippy::too_many_arguments)]
fn lift_live_rows<F>(
    dst: &mut Rows,
    src: &Rows,
    c: f32,
    parallel: bool,
    live_dst: &mut [bool],
    live_src: &[bool],
    zeros: &[f32],
    sources: F,
) where
    F: Fn(usize) -> [usize; 2] + Sync + Send,
{
    let view = src.view();
    let pick = |i: usize| if live_src[i] { view.row(i) } else { zeros };
    let was: &[bool] = live_dst;
    for_each_row(dst, parallel, |i, row| {
        let [a, b] = sources(i);
        if live_src[a] || live_src[b] {
            if !was[i] {
                row.fill(0.0);
            }
            axpy2(row, c, pick(a), pick(b));
        }
    });
    for (i, flag) in live_dst.iter_mut().enumerate() {
        let [a, b] = sources(i);
        *flag |= live_src[a] || live_src[b];
    }
}
