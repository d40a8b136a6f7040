//! Per-band weighting and dithered scalar quantization of column
//! coefficients (Cheslack-Postava et al. 2007 §4.3).
//!
//! Each coefficient is multiplied by the pixel-domain L2 norm of its band's
//! synthesis function before it is thresholded and quantized, so that one
//! quantization step costs the same pixel-domain error in every band. For the
//! lifting filters this weight grows as `2^level` — the paper's non-linear
//! per-level scaling — and for the orthonormal filters it is 1.
//!
//! Quantization to `bits` maps a weighted value `u` whose column's largest
//! kept weighted magnitude in its scale group ([`scale_groups`]), rounded up
//! to a stored scale ([`encode_scale`]), is `s` to `q = floor(u/s·Q + d)` with
//! `Q = 2^(bits−1) − 1` and a dither `d ∈ [0, 1)` drawn from a hash of
//! (seed, column, index, channel). The dither makes the quantizer unbiased
//! (`E[q] = u/s·Q`), so small kept coefficients survive on average instead of
//! all rounding the same way; zero stays zero. Decoding is `u = q·s/Q`.
//!
//! That peak quantizer spends many bits on every kept value. The uniform
//! quantizer of target-error runs instead takes one step `Δ` for the whole
//! matrix, tied to the threshold, stores `s = Δ·Q` (or the peak, if larger)
//! and rounds `u/Δ` to the nearest integer: the same decoder reads both.

use crate::bands::{band_count, band_level, band_map, band_rect};
use crate::column::SparseColumn;
use crate::error::{Error, Result};
use crate::limits::{Charge, Limits};
use crate::wavelet::{self, Filter};

/// `count` copies of `value`, allocated fallibly (the bytes are charged by
/// the caller): memory the system refuses is an error naming `what`.
pub(crate) fn try_vec<T: Clone>(
    count: usize,
    value: T,
    what: &'static str,
    limits: &Limits,
) -> Result<Vec<T>> {
    let mut v = Vec::new();
    v.try_reserve_exact(count).map_err(|_| Error::OutOfMemory {
        what: what.to_string(),
        needed: (count as u64).saturating_mul(std::mem::size_of::<T>() as u64),
        limit: limits.max_alloc_bytes(),
    })?;
    v.resize(count, value);
    Ok(v)
}

/// Quantization levels on each side of zero for `bits` (2..=16).
pub fn levels(bits: u32) -> f32 {
    ((1u32 << (bits - 1)) - 1) as f32
}

/// A deterministic dither value in `[0, 1)`.
#[inline]
pub fn dither(seed: u64, column: u32, index: u32, channel: u32) -> f32 {
    let mut z = seed
        ^ ((column as u64) << 32 | index as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ ((channel as u64) << 61);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> 40) as f32 / (1u64 << 24) as f32
}

/// Which dither stream a column is quantized with: [`dither`]'s `seed`
/// and `column`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Dither {
    /// The compressor's seed.
    pub seed: u64,
    /// The column's index.
    pub column: u32,
}

/// Scale group of every position of a `width` × `height` column image at
/// `depth`: 0 in the low band (the whole image at depth 0), `k` in the detail
/// bands of level `k` (1 = finest). Each group has its own quantizer scale, so
/// large coarse coefficients do not coarsen the steps of small fine ones.
pub fn scale_groups(width: usize, height: usize, depth: u32) -> Vec<u8> {
    let mut map = band_map(width, height, depth);
    map.iter_mut()
        .for_each(|b| *b = band_level(*b as usize) as u8);
    map
}

/// A quantizer scale as stored: `s = 2^((e − 32768)/256)`, `e = 0` for 0.
pub fn decode_scale(e: u16) -> f32 {
    if e == 0 {
        0.0
    } else {
        ((e as f64 - 32768.0) / 256.0).exp2() as f32
    }
}

/// The smallest code whose scale is at least `s` (`s` finite, ≥ 0).
pub fn encode_scale(s: f32) -> u16 {
    if s <= 0.0 || !s.is_finite() {
        return 0;
    }
    let mut e = ((s as f64).log2() * 256.0 + 32768.0)
        .ceil()
        .clamp(1.0, 65535.0) as u16;
    while e < u16::MAX && decode_scale(e) < s {
        e += 1;
    }
    e
}

/// How [`quantize`] quantizes one column: the bits (levels `Q =
/// 2^(bits−1) − 1` of a scale group's largest value), and either a uniform
/// step or a dither.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Quantization {
    /// Quantization bits, 2..=16.
    pub bits: u32,
    /// The uniform quantizer's weighted step per channel (rounding to the
    /// nearest step); `None` for the peak quantizer's dithered steps.
    pub step: Option<f32>,
    /// The dither stream of the peak quantizer.
    pub dither: Dither,
}

/// The coder's quantizer: stores the sorted positions `kept` of one column's
/// weighted coefficients `coefs` (`channels` planes of equal length, in the
/// column transform's layout at `depth`). Each scale group (`groups`, from
/// [`scale_groups`]) and channel gets one log-coded scale `s`; values become
/// integers `q` that decode as `q·s/Q` with `Q = levels(bits)`.
/// - The peak quantizer (no `step`): `s` is the group's largest kept
///   magnitude and `q = floor(u/s·Q + d)`, `d` the dither of (the
///   [`Dither`]'s `seed` and `column`, position, channel). Positions whose
///   every channel is below half a step are dropped (dithering them costs
///   more error than dropping them).
/// - The uniform quantizer: `s` is the larger of `step·Q` and the group's
///   largest kept magnitude (so that no value needs more than `Q` steps),
///   and `q` is `u/s·Q` rounded to the nearest integer (halves away from
///   zero).
///
/// Positions whose every channel quantizes to zero are dropped.
pub fn quantize(
    coefs: &[f32],
    channels: usize,
    kept: &[u32],
    groups: &[u8],
    depth: u32,
    how: Quantization,
) -> SparseColumn {
    let p = coefs.len() / channels.max(1);
    let c_n = channels;
    let q = levels(how.bits);
    let mut peak = vec![0.0f32; (depth as usize + 1) * c_n];
    for &i in kept {
        let g = groups[i as usize] as usize;
        for c in 0..c_n {
            peak[g * c_n + c] = peak[g * c_n + c].max(coefs[c * p + i as usize].abs());
        }
    }
    if let Some(step) = how.step {
        let floor = step * q;
        peak.iter_mut()
            .filter(|s| **s > 0.0)
            .for_each(|s| *s = s.max(floor));
    }
    let scale_codes: Vec<u16> = peak.iter().map(|&s| encode_scale(s)).collect();
    let scales: Vec<f32> = scale_codes.iter().map(|&e| decode_scale(e)).collect();
    let mut col = SparseColumn {
        depth,
        scale_codes,
        ..Default::default()
    };
    let Dither { seed, column } = how.dither;
    let dithered = how.step.is_none();
    let mut vals = [0i32; 3];
    for &i in kept {
        let g = groups[i as usize] as usize;
        let half_step = |c: usize| 0.5 * scales[g * c_n + c] / q;
        if dithered && (0..c_n).all(|c| coefs[c * p + i as usize].abs() < half_step(c)) {
            continue;
        }
        let mut any = false;
        for (c, v) in vals.iter_mut().enumerate().take(c_n) {
            let s = scales[g * c_n + c];
            *v = if s > 0.0 {
                let x = coefs[c * p + i as usize] / s * q;
                let x = if dithered {
                    (x + dither(seed, column, i, c as u32)).floor()
                } else {
                    x.round()
                };
                x.clamp(-q, q) as i32
            } else {
                0
            };
            any |= *v != 0;
        }
        if any {
            col.indices.push(i);
            col.values.extend_from_slice(&vals[..c_n]);
        }
    }
    col
}

/// Synthesis-norm weight of every coefficient position of a `width` ×
/// `height` column image, for each transform depth `0..=max_depth`.
pub struct BandWeights {
    maps: Vec<Vec<f32>>,
    /// The maps' bytes, charged to the limits they were made under.
    _charge: Charge,
}

impl BandWeights {
    /// Computes the weights by inverse-transforming one impulse per band.
    /// The maps (and two work planes while they are made) are charged to
    /// `limits`.
    pub fn new(
        filter: Filter,
        width: usize,
        height: usize,
        max_depth: u32,
        limits: &Limits,
    ) -> Result<BandWeights> {
        let n = width.saturating_mul(height);
        let depths = max_depth as usize + 1;
        let charge = limits.check_alloc("band weights", n as u64, 4 * depths as u64)?;
        let (mut probe, _probe) = limits.vec("band weight probe", n, 0.0f32)?;
        let (mut work, _work) = limits.vec("band weight work plane", n, 0.0f32)?;
        // norm of an impulse at (x, y) after inverse-transforming `depth` levels.
        let mut norm = |x: usize, y: usize, depth: u32| -> f32 {
            probe.fill(0.0);
            probe[y * width + x] = 1.0;
            if wavelet::inverse(filter, &mut probe, width, height, depth, &mut work).is_err() {
                return 1.0;
            }
            probe.iter().map(|v| v * v).sum::<f32>().sqrt().max(1e-6)
        };
        let mut maps = Vec::with_capacity(depths);
        for depth in 0..=max_depth {
            let mut map = try_vec(n, 1.0f32, "band weights", limits)?;
            if depth > 0 {
                for band in 0..band_count(depth) {
                    let (xs, ys) = band_rect(width, height, depth, band);
                    if xs.is_empty() || ys.is_empty() {
                        continue;
                    }
                    let w = norm((xs.start + xs.end) / 2, (ys.start + ys.end) / 2, depth);
                    for y in ys {
                        map[y * width + xs.start..y * width + xs.end].fill(w);
                    }
                }
            }
            maps.push(map);
        }
        Ok(BandWeights {
            maps,
            _charge: charge,
        })
    }

    /// The weight map for columns transformed to `depth`.
    pub fn map(&self, depth: u32) -> &[f32] {
        &self.maps[depth as usize]
    }

    /// Deepest depth covered.
    pub fn max_depth(&self) -> u32 {
        self.maps.len() as u32 - 1
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The uniform quantizer rounds every kept value to the nearest
    /// multiple of its group's step (the given step, or the group's
    /// peak/Q where that is larger), stores the step as `s/Q`, and drops
    /// positions whose every channel rounds to zero.
    #[test]
    fn uniform_quantizer_rounds_to_one_step_per_group() {
        let (p, c_n, bits) = (6usize, 2usize, 4u32);
        let q = levels(bits); // 7
                              // Group 0: positions 0..3, group 1: 3..6 with a peak of 100 (more
                              // than 7 steps of 1 in channel 0: its step there grows to about
                              // 100/7; channel 1 keeps the step 1).
        let groups = [0u8, 0, 0, 1, 1, 1];
        let coefs = [
            0.4f32, 2.6, -1.49, 100.0, 3.0, 0.2, // channel 0
            0.3, 0.0, 0.51, -7.0, 0.0, 0.1, // channel 1
        ];
        let how = Quantization {
            bits,
            step: Some(1.0),
            dither: Dither { seed: 0, column: 0 },
        };
        let col = quantize(&coefs, c_n, &[0, 1, 2, 3, 4, 5], &groups, 1, how);
        let step = |g: usize, c: usize| decode_scale(col.scale_codes[g * c_n + c]) / q;
        assert!((step(0, 0) - 1.0).abs() < 3e-3 && (step(0, 1) - 1.0).abs() < 3e-3);
        assert!(step(1, 0) >= 100.0 / q && step(1, 0) < 1.003 * 100.0 / q);
        // Position 0 rounds to 0 in both channels and is dropped; so are
        // 5 and 4 (3.0 is under half of group 1's step of 100/7).
        assert_eq!(col.indices, vec![1, 2, 3]);
        let value = |k: usize, c: usize| col.values[k * c_n + c];
        assert_eq!((value(0, 0), value(0, 1)), (3, 0));
        assert_eq!((value(1, 0), value(1, 1)), (-1, 1));
        assert_eq!((value(2, 0), value(2, 1)), (7, -7));
        for (k, &i) in col.indices.iter().enumerate() {
            for c in 0..c_n {
                let g = groups[i as usize] as usize;
                let back = value(k, c) as f32 * step(g, c);
                let err = (back - coefs[c * p + i as usize]).abs();
                assert!(err <= 0.5 * step(g, c) + 1e-4, "position {i} channel {c}");
            }
        }
    }

    /// Every stored scale is a finite positive f32 (subnormal at the bottom,
    /// below `f32::MAX` at the top), and any positive f32 up to the largest
    /// scale gets a code whose scale covers it.
    #[test]
    fn scales_never_overflow_or_underflow() {
        for e in 1..=u16::MAX {
            let s = decode_scale(e);
            assert!(s.is_finite() && s > 0.0, "code {e}: {s}");
            // The code of a stored scale covers it, one step up at most
            // (decoding rounds to the nearest f32).
            let back = encode_scale(s);
            assert!(back >= e && back - e <= 1 && decode_scale(back) >= s, "{e}");
        }
        assert_eq!(encode_scale(0.0), 0);
        for s in [
            f32::from_bits(1),
            f32::MIN_POSITIVE,
            1e-30,
            1.0,
            1e30,
            decode_scale(u16::MAX),
        ] {
            let e = encode_scale(s);
            assert!(e >= 1 && decode_scale(e) >= s, "{s}: code {e}");
        }
    }
}
