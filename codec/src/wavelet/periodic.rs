//! Orthonormal filters with periodic extension (PyWavelets mode
//! `periodization`): `low[o] = Σ_j lo[j] · x[(2o + F/2 − j) mod n]` and the
//! same with the high-pass taps `hi[j] = (−1)^(j+1) · lo[F−1−j]`.
//!
//! An odd length `2q + 1` transforms its first `2q` samples with period `2q`
//! and appends the last sample to the low band unchanged.

use super::dwt2::{for_each_row, Rows, RowsRef};
use std::f64::consts::FRAC_1_SQRT_2;

/// Haar analysis low-pass taps (PyWavelets `haar.dec_lo`).
pub(crate) static HAAR: [f64; 2] = [FRAC_1_SQRT_2, FRAC_1_SQRT_2];
/// Daubechies, 2 vanishing moments (PyWavelets `db2.dec_lo`).
pub(crate) static DB2: [f64; 4] = [
    -0.129_409_522_550_921_45,
    0.224_143_868_041_857_35,
    0.836_516_303_737_469,
    0.482_962_913_144_690_25,
];
/// Daubechies, 3 vanishing moments (PyWavelets `db3.dec_lo`).
pub(crate) static DB3: [f64; 6] = [
    0.035_226_291_882_100_656,
    -0.085_441_273_882_241_49,
    -0.135_011_020_010_390_84,
    0.459_877_502_119_331_3,
    0.806_891_509_313_338_8,
    0.332_670_552_950_956_9,
];
/// Daubechies, 4 vanishing moments (PyWavelets `db4.dec_lo`).
pub(crate) static DB4: [f64; 8] = [
    -0.010_597_401_784_997_278,
    0.032_883_011_666_982_945,
    0.030_841_381_835_986_965,
    -0.187_034_811_718_881_14,
    -0.027_983_769_416_983_85,
    0.630_880_767_929_590_4,
    0.714_846_570_552_541_5,
    0.230_377_813_308_855_23,
];

/// Low- and high-pass taps in f32 (at most 8 of each).
struct Taps {
    lo: [f32; 8],
    hi: [f32; 8],
    len: usize,
}

impl Taps {
    fn new(dec_lo: &[f64]) -> Taps {
        let len = dec_lo.len();
        let mut t = Taps {
            lo: [0.0; 8],
            hi: [0.0; 8],
            len,
        };
        for j in 0..len {
            t.lo[j] = dec_lo[j] as f32;
            let sign = if j % 2 == 0 { -1.0 } else { 1.0 };
            t.hi[j] = (sign * dec_lo[len - 1 - j]) as f32;
        }
        t
    }

    /// Index into the periodic signal of period `m` read by output `o`, tap `j`.
    #[inline]
    fn src(&self, o: usize, j: usize, m: usize) -> usize {
        (2 * o + self.len / 2 + m * self.len - j) % m
    }

    /// For signal sample `k` and tap `j`, the band index `o` that reads it,
    /// if any.
    #[inline]
    fn band(&self, k: usize, j: usize, m: usize) -> Option<usize> {
        let t = (k + j + m * self.len - self.len / 2) % m;
        t.is_multiple_of(2).then_some(t / 2)
    }
}

/// Outputs `o` whose taps `2o + F/2 − j` (j in 0..F) all lie in `0..m`:
/// they need no wrap-around.
fn interior(taps: &Taps, m: usize) -> std::ops::Range<usize> {
    let half = taps.len / 2;
    let start = (taps.len - 1).saturating_sub(half).div_ceil(2);
    let end = if m > half { (m - half).div_ceil(2) } else { 0 };
    start..end.max(start)
}

/// One analysis step of `x` (length >= 2) into `out` as `[low | high]`.
pub(crate) fn forward_1d(dec_lo: &[f64], x: &[f32], out: &mut [f32]) {
    let taps = Taps::new(dec_lo);
    let n = x.len();
    let m = n & !1;
    let q = m / 2;
    let ns = n.div_ceil(2);
    let inner = interior(&taps, m);
    let half = taps.len / 2;
    for o in 0..q {
        let (mut a, mut d) = (0.0f32, 0.0f32);
        if inner.contains(&o) {
            let base = 2 * o + half;
            for j in 0..taps.len {
                let v = x[base - j];
                a += taps.lo[j] * v;
                d += taps.hi[j] * v;
            }
        } else {
            for j in 0..taps.len {
                let v = x[taps.src(o, j, m)];
                a += taps.lo[j] * v;
                d += taps.hi[j] * v;
            }
        }
        out[o] = a;
        out[ns + o] = d;
    }
    if n % 2 == 1 {
        out[q] = x[n - 1];
    }
}

/// One synthesis step from `bands` (`[low | high]`) into the signal `out`:
/// the transpose of the analysis, scattered.
pub(crate) fn inverse_1d(dec_lo: &[f64], bands: &[f32], out: &mut [f32]) {
    let taps = Taps::new(dec_lo);
    let n = bands.len();
    let m = n & !1;
    let ns = n.div_ceil(2);
    let inner = interior(&taps, m);
    let half = taps.len / 2;
    out[..m].fill(0.0);
    for o in 0..m / 2 {
        let (a, d) = (bands[o], bands[ns + o]);
        if inner.contains(&o) {
            let base = 2 * o + half;
            for j in 0..taps.len {
                out[base - j] += taps.lo[j] * a + taps.hi[j] * d;
            }
        } else {
            for j in 0..taps.len {
                out[taps.src(o, j, m)] += taps.lo[j] * a + taps.hi[j] * d;
            }
        }
    }
    if n % 2 == 1 {
        out[n - 1] = bands[m / 2];
    }
}

/// [`inverse_1d`] on `L` interleaved signals at once: each lane gets the
/// same f32 operations in the same order, so the same bits.
pub(crate) fn inverse_1d_lanes<const L: usize>(
    dec_lo: &[f64],
    bands: &[[f32; L]],
    out: &mut [[f32; L]],
) {
    let taps = Taps::new(dec_lo);
    let n = bands.len();
    let m = n & !1;
    let ns = n.div_ceil(2);
    let inner = interior(&taps, m);
    let half = taps.len / 2;
    out[..m].fill([0.0; L]);
    for o in 0..m / 2 {
        let (a, d) = (bands[o], bands[ns + o]);
        for j in 0..taps.len {
            let k = if inner.contains(&o) {
                2 * o + half - j
            } else {
                taps.src(o, j, m)
            };
            let (cl, ch) = (taps.lo[j], taps.hi[j]);
            for ((x, a), d) in out[k].iter_mut().zip(a).zip(d) {
                *x += cl * a + ch * d;
            }
        }
    }
    if n % 2 == 1 {
        out[n - 1] = bands[m / 2];
    }
}

/// Vertical analysis: `src` holds `h` compact rows of `w`; the bands are
/// written to `dst` (rows of `stride`), low rows first.
pub(crate) fn forward_rows(
    dec_lo: &[f64],
    src: &[f32],
    dst: &mut [f32],
    stride: usize,
    w: usize,
    h: usize,
    parallel: bool,
) {
    let taps = Taps::new(dec_lo);
    let m = h & !1;
    let q = m / 2;
    let ns = h.div_ceil(2);
    let src_row = |r: usize| &src[r * w..][..w];
    let mut rows = Rows::new(dst, stride, w, h);
    for_each_row(&mut rows, parallel, |r, row| {
        let (o, t) = if r < q {
            (r, &taps.lo)
        } else if r >= ns {
            (r - ns, &taps.hi)
        } else {
            row.copy_from_slice(src_row(h - 1));
            return;
        };
        row.fill(0.0);
        for (j, &c) in t.iter().enumerate().take(taps.len) {
            for (d, s) in row.iter_mut().zip(src_row(taps.src(o, j, m))) {
                *d += c * s;
            }
        }
    });
}

/// Vertical synthesis: `src` holds the bands in rows of `stride` (low rows
/// first); the `h` reconstructed rows of `w` are written compactly to `work`
/// in signal order.
pub(crate) fn inverse_rows(
    dec_lo: &[f64],
    src: &[f32],
    stride: usize,
    work: &mut [f32],
    w: usize,
    h: usize,
    parallel: bool,
) {
    let taps = Taps::new(dec_lo);
    let m = h & !1;
    let ns = h.div_ceil(2);
    let src_row = |r: usize| &src[r * stride..][..w];
    let mut rows = Rows::new(work, w, w, h);
    for_each_row(&mut rows, parallel, |k, row| {
        if k >= m {
            row.copy_from_slice(src_row(m / 2));
            return;
        }
        row.fill(0.0);
        for j in 0..taps.len {
            if let Some(o) = taps.band(k, j, m) {
                let (cl, ch) = (taps.lo[j], taps.hi[j]);
                for ((d, a), b) in row.iter_mut().zip(src_row(o)).zip(src_row(ns + o)) {
                    *d += cl * a + ch * b;
                }
            }
        }
    });
}

/// [`inverse_rows`] skipping zero rows: `bands` holds the `h` band rows
/// (low rows first), and the `h` signal rows of `w` go compactly to `work`.
/// On entry `live[i]` says whether band row `i` may be nonzero (a row
/// marked `false` is all zero); on return it says whether signal row `k` of
/// `work` was written (a row none of whose taps reads a nonzero band row is
/// zero and is not written).
pub(crate) fn inverse_rows_sparse(
    dec_lo: &[f64],
    bands: RowsRef<'_>,
    work: &mut [f32],
    parallel: bool,
    live: &mut [bool],
) {
    let (src, stride, w, h) = (bands.data, bands.stride, bands.w, bands.rows);
    let taps = Taps::new(dec_lo);
    let m = h & !1;
    let ns = h.div_ceil(2);
    let rows_in = live[..h].to_vec();
    for (k, flag) in live[..h].iter_mut().enumerate() {
        *flag = if k >= m {
            rows_in[m / 2]
        } else {
            (0..taps.len).any(|j| {
                taps.band(k, j, m)
                    .is_some_and(|o| rows_in[o] || rows_in[ns + o])
            })
        };
    }
    let written: &[bool] = live;
    let src_row = |r: usize| &src[r * stride..][..w];
    let mut rows = Rows::new(work, w, w, h);
    for_each_row(&mut rows, parallel, |k, row| {
        if !written[k] {
            return;
        }
        if k >= m {
            row.copy_from_slice(src_row(m / 2));
            return;
        }
        row.fill(0.0);
        for j in 0..taps.len {
            if let Some(o) = taps.band(k, j, m) {
                let (cl, ch) = (taps.lo[j], taps.hi[j]);
                for ((d, a), b) in row.iter_mut().zip(src_row(o)).zip(src_row(ns + o)) {
                    *d += cl * a + ch * b;
                }
            }
        }
    });
}
