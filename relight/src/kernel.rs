//! The multiply-add kernels: one column's arena entries in one pixel block,
//! added into interleaved pixels `[r, g, b, 0]` (16 bytes, one aligned
//! vector per pixel):
//! `pixel[offset] += table[band] · q` for every entry (see [`crate::arena`]).
//!
//! The scalar kernels are the reference. On x86-64 an SSE4.1 version (found
//! at run time) converts an entry's four `i16` at once and adds one vector
//! per pixel; it multiplies and adds separately (no fused multiply-add), so
//! it gives the scalar kernels' bits exactly, which the tests check. This is
//! the crate's only `unsafe` code.

#![allow(unsafe_code)]

/// Which kernel a frame runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Kernel {
    /// The portable reference.
    Scalar,
    /// SSE4.1 (x86-64 only).
    #[cfg(target_arch = "x86_64")]
    Sse41,
}

impl Kernel {
    /// The fastest kernel this CPU runs.
    pub fn detect() -> Kernel {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("sse4.1") {
            return Kernel::Sse41;
        }
        Kernel::Scalar
    }

    /// Multiply-adds `entries` (`channels + 1` values each: `q` per channel,
    /// then the code) into `pixels`, the block's pixels. `tables` holds the
    /// column's light-scaled band factors; codes split as `band = code >>
    /// shift`, `offset = code & mask`. Panics on a band or offset out of
    /// range (the arena never holds one).
    pub fn run(
        self,
        channels: usize,
        entries: &[i16],
        tables: &[[f32; 4]],
        shift: u32,
        pixels: &mut [[f32; 4]],
    ) {
        match (self, channels) {
            (Kernel::Scalar, 1) => grey_scalar(entries, tables, shift, pixels),
            (Kernel::Scalar, _) => rgb_scalar(entries, tables, shift, pixels),
            #[cfg(target_arch = "x86_64")]
            // SAFETY: `Kernel::Sse41` is only made by `detect` when the CPU
            // has SSE4.1 (or by tests that check the same).
            (Kernel::Sse41, 1) => unsafe { x86::grey_sse41(entries, tables, shift, pixels) },
            #[cfg(target_arch = "x86_64")]
            // SAFETY: as above.
            (Kernel::Sse41, _) => unsafe { x86::rgb_sse41(entries, tables, shift, pixels) },
        }
    }
}

/// Band and pixel of a code.
#[inline(always)]
fn split(code: i16, shift: u32) -> (usize, usize) {
    let code = code as u16;
    (
        (code >> shift) as usize,
        (code & ((1u32 << shift) - 1) as u16) as usize,
    )
}

/// Scalar reference, grey entries `[q, code]`.
fn grey_scalar(entries: &[i16], tables: &[[f32; 4]], shift: u32, pixels: &mut [[f32; 4]]) {
    for e in entries.chunks_exact(2) {
        let (band, i) = split(e[1], shift);
        let (t, p, q) = (&tables[band], &mut pixels[i], e[0] as f32);
        p[0] += t[0] * q;
        p[1] += t[1] * q;
        p[2] += t[2] * q;
    }
}

/// Scalar reference, RGB entries `[q_r, q_g, q_b, code]`.
fn rgb_scalar(entries: &[i16], tables: &[[f32; 4]], shift: u32, pixels: &mut [[f32; 4]]) {
    for e in entries.chunks_exact(4) {
        let (band, i) = split(e[3], shift);
        let (t, p) = (&tables[band], &mut pixels[i]);
        p[0] += t[0] * e[0] as f32;
        p[1] += t[1] * e[1] as f32;
        p[2] += t[2] * e[2] as f32;
    }
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    use super::split;
    use std::arch::x86_64::*;

    /// SSE4.1 version of [`super::grey_scalar`]; lane 3 of the pixels gets
    /// `0 · q` added, which leaves it zero.
    ///
    /// # Safety
    /// The CPU must support SSE4.1.
    #[target_feature(enable = "sse4.1")]
    pub unsafe fn grey_sse41(
        entries: &[i16],
        tables: &[[f32; 4]],
        shift: u32,
        pixels: &mut [[f32; 4]],
    ) {
        for e in entries.chunks_exact(2) {
            let (band, i) = split(e[1], shift);
            let (t, p) = (&tables[band], &mut pixels[i]);
            // SAFETY: `t` and `p` are references to 16 bytes each (unaligned
            // loads and stores); SSE4.1 is enabled for this function.
            unsafe {
                let q = _mm_set1_ps(e[0] as f32);
                let sum = _mm_add_ps(
                    _mm_loadu_ps(p.as_ptr()),
                    _mm_mul_ps(_mm_loadu_ps(t.as_ptr()), q),
                );
                _mm_storeu_ps(p.as_mut_ptr(), sum);
            }
        }
    }

    /// SSE4.1 version of [`super::rgb_scalar`]: the entry's four `i16`
    /// convert at once; lane 3 (the code) meets the table's zero.
    ///
    /// # Safety
    /// The CPU must support SSE4.1.
    #[target_feature(enable = "sse4.1")]
    pub unsafe fn rgb_sse41(
        entries: &[i16],
        tables: &[[f32; 4]],
        shift: u32,
        pixels: &mut [[f32; 4]],
    ) {
        for e in entries.chunks_exact(4) {
            let (band, i) = split(e[3], shift);
            let (t, p) = (&tables[band], &mut pixels[i]);
            // SAFETY: `e` holds 4 `i16` (8 bytes, read unaligned), `t` and
            // `p` 16 bytes each; SSE4.1 is enabled for this function.
            unsafe {
                let q = _mm_cvtepi32_ps(_mm_cvtepi16_epi32(_mm_loadl_epi64(
                    e.as_ptr() as *const __m128i
                )));
                let sum = _mm_add_ps(
                    _mm_loadu_ps(p.as_ptr()),
                    _mm_mul_ps(_mm_loadu_ps(t.as_ptr()), q),
                );
                _mm_storeu_ps(p.as_mut_ptr(), sum);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn xorshift(seed: &mut u64) -> u64 {
        *seed ^= *seed << 13;
        *seed ^= *seed >> 7;
        *seed ^= *seed << 17;
        *seed
    }

    /// Random entries over every band and offset, with extreme values
    /// (±32767, 0) and tables over 1e-6..1e5 (and zero).
    fn case(channels: usize, n: usize, shift: u32, seed: &mut u64) -> (Vec<i16>, Vec<[f32; 4]>) {
        let bands = 1usize << (16 - shift);
        let pixels = 1usize << shift;
        let tables = (0..bands)
            .map(|_| {
                let mut t = [0.0f32; 4];
                for v in t.iter_mut().take(3) {
                    let r = xorshift(seed);
                    let mag = 10f32.powf((r % 1100) as f32 / 100.0 - 6.0);
                    *v = match r % 9 {
                        0 => 0.0,
                        1 => -mag,
                        _ => mag,
                    };
                }
                t
            })
            .collect();
        let mut entries = Vec::new();
        for _ in 0..n {
            for _ in 0..channels {
                let r = xorshift(seed);
                entries.push(match r % 5 {
                    0 => 0,
                    1 => i16::MAX,
                    2 => -i16::MAX,
                    _ => (r >> 8) as i16,
                });
            }
            let r = xorshift(seed);
            let code = (((r as usize >> 3) % bands) << shift) | ((r as usize >> 20) % pixels);
            entries.push(code as u16 as i16);
        }
        (entries, tables)
    }

    /// The detected kernel gives the scalar reference's bits, grey and RGB,
    /// for every code split, repeated offsets and empty inputs.
    #[test]
    fn detected_kernel_matches_scalar_bit_for_bit() {
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let fast = Kernel::detect();
        for channels in [1, 3] {
            for shift in [1, 5, 10, 11, 15] {
                for n in [0, 1, 7, 1000] {
                    let (entries, tables) = case(channels, n, shift, &mut seed);
                    let start: Vec<[f32; 4]> = (0..1usize << shift)
                        .map(|i| [i as f32 * 0.5, -(i as f32), 1e-7, 0.0])
                        .collect();
                    let (mut a, mut b) = (start.clone(), start);
                    Kernel::Scalar.run(channels, &entries, &tables, shift, &mut a);
                    fast.run(channels, &entries, &tables, shift, &mut b);
                    for (i, (x, y)) in a.iter().zip(&b).enumerate() {
                        for c in 0..3 {
                            assert_eq!(
                                x[c].to_bits(),
                                y[c].to_bits(),
                                "{fast:?} {channels} ch, shift {shift}, pixel {i} lane {c}"
                            );
                        }
                        assert_eq!(y[3], 0.0);
                        assert!(y.iter().all(|v| v.is_finite()));
                    }
                }
            }
        }
    }
}
