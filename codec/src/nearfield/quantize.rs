//! Lossy near-field rows: every kept Haar coefficient of a [`PlaneRows`]
//! rounded to the nearest multiple of one step `Δ` for the whole chunk,
//! and those that round to 0 dropped. As for the matrix's uniform
//! quantizer, one step for every coefficient gives the least squared error
//! for the count of values kept; the step is the largest that keeps the
//! rows' relative L2 error at most the target. The Haar transform is
//! orthonormal, so the error of the coefficients is the error of the
//! per-texel integrals. The chunk's layout does not change (docs/FORMAT.md,
//! "Near-field rows"): a reader takes the stored coefficients as they are.

use super::PlaneRows;
use crate::error::{Error, Result};
use rayon::prelude::*;

/// What [`PlaneRows::quantize`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct NearQuantization {
    /// The step `Δ` (0: nothing was changed).
    pub step: f64,
    /// The rows' relative L2 error after quantization.
    pub error: f64,
    /// Coefficients before.
    pub before: usize,
    /// Coefficients kept.
    pub kept: usize,
}

/// The search stops once the error is at least this share of the target.
const WINDOW_LOW: f64 = 0.97;
/// Bisection steps at most (each halves `log Δ`'s interval).
const MAX_STEPS: usize = 64;

/// `v` rounded to the nearest multiple of `step` (ties away from 0), as
/// stored: 0 when it rounds to 0 (dropped), and within f32's range.
#[inline]
fn rounded(v: f32, step: f64) -> f32 {
    let most = f64::from(f32::MAX);
    let x = f64::from(v) / step;
    // |x| ≤ 2^62 for every step the search tries (at least peak·2^−60),
    // so the integer conversion is exact rounding, and faster than
    // `f64::round` on every x86-64.
    let q = ((x.abs() + 0.5) as i64 as f64).copysign(x);
    (q * step).clamp(-most, most) as f32
}

/// `Σ (v − rounded(v))²` over `values`, summed in a fixed order (chunks
/// of 2^16 values, then their sums in turn), so that the step, and the
/// file, do not depend on the thread count.
fn squared_error(values: &[f32], step: f64) -> f64 {
    let sums: Vec<f64> = values
        .par_chunks(1 << 16)
        .map(|c| {
            c.iter()
                .map(|&v| (f64::from(v) - f64::from(rounded(v, step))).powi(2))
                .sum::<f64>()
        })
        .collect();
    sums.iter().sum()
}

impl PlaneRows {
    /// Quantizes the coefficients in place so that their relative L2
    /// error is at most `max_error` and, where a step can give it, at
    /// least 0.97 of it: the largest step found by bisection over `log Δ`.
    /// `max_error = 0` keeps every coefficient as it is (lossless); at 1 or
    /// more every coefficient is dropped. Refuses a negative or NaN target.
    pub fn quantize(&mut self, max_error: f64) -> Result<NearQuantization> {
        if max_error.is_nan() || max_error < 0.0 {
            return Err(Error::range("near-field error", max_error, "0 <= E"));
        }
        let before = self.values.len();
        let norm2: f64 = self.values.iter().map(|&v| f64::from(v).powi(2)).sum();
        let peak = self
            .values
            .iter()
            .fold(0.0f64, |m, &v| m.max(f64::from(v).abs()));
        let mut out = NearQuantization {
            before,
            kept: before,
            ..Default::default()
        };
        if max_error == 0.0 || norm2 == 0.0 {
            return Ok(out);
        }
        let Some((step, squared)) = search_step(&self.values, peak, norm2, max_error) else {
            // Even the finest step misses a target below f32's own rounding.
            return Ok(out);
        };
        out.step = step;
        out.error = (squared / norm2).sqrt();
        self.keep_rounded(step);
        out.kept = self.values.len();
        Ok(out)
    }

    /// Rounds every value to `step`'s multiples and drops the zeros,
    /// keeping each row and channel's entries in order.
    fn keep_rounded(&mut self, step: f64) {
        let mut w = 0usize;
        let mut start = 0u64;
        for i in 1..self.starts.len() {
            let end = self.starts[i];
            for k in start as usize..end as usize {
                let v = rounded(self.values[k], step);
                if v != 0.0 {
                    self.values[w] = v;
                    self.indices[w] = self.indices[k];
                    w += 1;
                }
            }
            start = end;
            self.starts[i] = w as u64;
        }
        self.values.truncate(w);
        self.indices.truncate(w);
        self.values.shrink_to_fit();
        self.indices.shrink_to_fit();
    }
}

/// The largest step (within the bisection's resolution) whose relative
/// error is at most `max_error`, stopping early inside
/// `[WINDOW_LOW·E, E]`, with its squared error; `None` when even
/// `peak·2^−60` misses it.
fn search_step(values: &[f32], peak: f64, norm2: f64, max_error: f64) -> Option<(f64, f64)> {
    let budget = (max_error * max_error) * norm2;
    let low_budget = (WINDOW_LOW * max_error).powi(2) * norm2;
    // At 4·peak every value rounds to 0: the error is the whole norm.
    let (mut lo, mut hi) = ((peak * 2f64.powi(-60)).max(f64::MIN_POSITIVE), 4.0 * peak);
    let all = squared_error(values, hi);
    if all <= budget {
        return Some((hi, all));
    }
    let mut lo_error = squared_error(values, lo);
    if lo_error > budget {
        return None;
    }
    for _ in 0..MAX_STEPS {
        let mid = (lo * hi).sqrt();
        let e = squared_error(values, mid);
        if e <= budget {
            (lo, lo_error) = (mid, e);
            if e >= low_budget {
                break;
            }
        } else {
            hi = mid;
        }
        if hi / lo < 1.0 + 1e-9 {
            break;
        }
    }
    Some((lo, lo_error))
}

#[cfg(test)]
mod tests {
    use super::super::tests::basis;
    use super::*;
    use crate::limits::Limits;

    /// Rows of `order²·channels` texels: HDR values from 1e-6 to 1e5
    /// (log-uniform, a xorshift from `seed`), a row of zeros, a constant
    /// row and a row with one lit texel.
    fn hdr_rows(order: u32, channels: usize, rows: usize, seed: u64) -> (PlaneRows, Vec<Vec<f32>>) {
        let n = (order * order) as usize * channels;
        let mut x = seed | 1;
        let mut next = move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut out = PlaneRows::new(basis(order), channels).unwrap();
        let mut all = Vec::new();
        for p in 0..rows {
            let row: Vec<f32> = match p % 7 {
                0 => vec![0.0; n],
                1 => vec![0.25; n],
                2 => (0..n).map(|i| if i == n / 3 { 1e4 } else { 0.0 }).collect(),
                _ => (0..n)
                    .map(|_| 10f64.powf(-6.0 + 11.0 * next()) as f32)
                    .collect(),
            };
            out.push_texels(&row).unwrap();
            all.push(row);
        }
        (out, all)
    }

    /// Relative L2 difference of every row's per-texel integrals.
    fn texel_error(rows: &PlaneRows, original: &[Vec<f32>]) -> f64 {
        let (c, n) = (rows.channels(), rows.basis().texels());
        let (mut diff, mut norm) = (0.0f64, 0.0f64);
        let mut t = vec![0.0f32; n];
        for (p, row) in original.iter().enumerate() {
            for ch in 0..c {
                rows.texels(p, ch, &mut t).unwrap();
                for (a, b) in row.iter().skip(ch).step_by(c).zip(&t) {
                    diff += (f64::from(*a) - f64::from(*b)).powi(2);
                    norm += f64::from(*a).powi(2);
                }
            }
        }
        (diff / norm).sqrt()
    }

    #[test]
    fn quantized_rows_meet_the_target_with_fewer_coefficients() {
        for (order, channels) in [(16, 1), (8, 3), (1, 1)] {
            let (rows, original) = hdr_rows(order, channels, 30, u64::from(order));
            for target in [0.001, 0.01, 0.1, 0.5] {
                let mut q = rows.clone();
                let r = q.quantize(target).unwrap();
                assert!(r.step > 0.0 && r.error <= target, "{r:?} at {target}");
                assert!(r.error >= 0.5 * target || r.kept == r.before, "{r:?}");
                assert_eq!((r.before, r.kept), (rows.nonzeros(), q.nonzeros()));
                // Orthonormal: the texels' error is the coefficients'.
                let seen = texel_error(&q, &original);
                let lossless = texel_error(&rows, &original);
                assert!(seen <= target * 1.001 + lossless, "{seen} at {target}");
                // What is stored decodes, with every value nonzero.
                let back = PlaneRows::decode(&q.encode(), 30, channels, &Limits::default());
                assert_eq!(back.unwrap().nonzeros(), q.nonzeros());
            }
            let mut q = rows.clone();
            let r = q.quantize(0.01).unwrap();
            assert!(r.kept < r.before, "{r:?} order {order}");
        }
    }

    #[test]
    fn lossless_total_and_bad_targets() {
        let (rows, _) = hdr_rows(8, 1, 10, 7);
        let mut same = rows.clone();
        let r = same.quantize(0.0).unwrap();
        assert_eq!((r.step, r.error, r.kept), (0.0, 0.0, rows.nonzeros()));
        assert_eq!(same.encode(), rows.encode());
        let mut none = rows.clone();
        let r = none.quantize(1.0).unwrap();
        assert_eq!((none.nonzeros(), r.error), (0, 1.0));
        assert_eq!(none.rows(), 10);
        for bad in [-0.01, f64::NAN] {
            let err = rows.clone().quantize(bad).unwrap_err().to_string();
            assert!(err.contains("near-field error"), "{err}");
        }
        // Rows with nothing to quantize stay as they are.
        let mut zeros = PlaneRows::new(basis(4), 3).unwrap();
        zeros.push_texels(&[0.0; 48]).unwrap();
        assert_eq!(zeros.quantize(0.01).unwrap().step, 0.0);
    }

    #[test]
    fn extreme_scales_quantize_without_overflow() {
        for scale in [1e-38f32, 1e-30, 1e30, 1e37] {
            let mut rows = PlaneRows::new(basis(4), 1).unwrap();
            let row: Vec<f32> = (0..16).map(|i| scale * (1.0 + i as f32) / 16.0).collect();
            rows.push_texels(&row).unwrap();
            let r = rows.quantize(0.01).unwrap();
            assert!(r.error <= 0.01 && r.error.is_finite(), "{scale}: {r:?}");
            let (_, values) = rows.row(0, 0);
            assert!(values.iter().all(|v| v.is_finite() && *v != 0.0), "{scale}");
        }
    }

    #[test]
    fn the_step_does_not_depend_on_the_thread_count() {
        let (rows, _) = hdr_rows(64, 1, 64, 3);
        assert!(rows.nonzeros() > 1 << 17, "{}", rows.nonzeros());
        let quantized = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                let mut q = rows.clone();
                q.quantize(0.02).unwrap();
                q.encode()
            })
        };
        assert_eq!(quantized(1), quantized(3));
    }
}
