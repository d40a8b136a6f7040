//! The multiply-add kernels: one column's arena entries in one pixel block,
//! added into interleaved pixels `[r, g, b, 0]` (16 bytes, one aligned
//! vector per pixel):
//! `pixel[offset] += table[band] · q` for every entry (see [`crate::arena`]).
//!
//! The scalar kernels are the reference. On x86-64 two SIMD versions are
//! found at run time:
//! - SSE4.1 converts an entry's four `i16` at once and adds one vector per
//!   pixel; it multiplies and adds separately (no fused multiply-add), so it
//!   gives the scalar kernels' bits exactly;
//! - AVX2 with FMA does two entries (two pixels) per 256-bit vector with a
//!   fused multiply-add, one rounding instead of two: each pixel lane is
//!   within `(2k + 2)·2⁻²⁴·(|p₀| + Σ|t·q|)` of the scalar result, for `k`
//!   entries adding into it from the start value `p₀` (both are within
//!   their own rounding bound of the exact sum).
//!
//! The tests check both. With `pca_blocks`, this is the crate's `unsafe`
//! code.

#![allow(unsafe_code)]

/// Which kernel a frame runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Kernel {
    /// The portable reference.
    Scalar,
    /// SSE4.1 (x86-64 only).
    #[cfg(target_arch = "x86_64")]
    Sse41,
    /// AVX2 and FMA (x86-64 only).
    #[cfg(target_arch = "x86_64")]
    Avx2Fma,
}

impl Kernel {
    /// The kernel a relighter starts with: SSE4.1 where the CPU has it,
    /// else the scalar reference. SSE4.1 is bit-identical to the scalar
    /// kernel, and on the 2-core AMD EPYC we measure on it streamed 3–25 %
    /// faster than AVX2+FMA in every idle benchmark (docs/results/
    /// relight-arena.md, round 3); AVX2+FMA stays available by name.
    pub fn detect() -> Kernel {
        let all = Kernel::available();
        #[cfg(target_arch = "x86_64")]
        if all.contains(&Kernel::Sse41) {
            return Kernel::Sse41;
        }
        *all.last().unwrap_or(&Kernel::Scalar)
    }

    /// Every kernel this CPU runs, the scalar reference first.
    pub fn available() -> Vec<Kernel> {
        #[allow(unused_mut)]
        let mut out = vec![Kernel::Scalar];
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("sse4.1") {
                out.push(Kernel::Sse41);
            }
            if std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma")
            {
                out.push(Kernel::Avx2Fma);
            }
        }
        out
    }

    /// The kernel's name: `scalar`, `sse4.1` or `avx2+fma`.
    pub fn name(self) -> &'static str {
        match self {
            Kernel::Scalar => "scalar",
            #[cfg(target_arch = "x86_64")]
            Kernel::Sse41 => "sse4.1",
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx2Fma => "avx2+fma",
        }
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
            // SAFETY: `Kernel::Sse41` is only made by `available` when the
            // CPU has SSE4.1.
            (Kernel::Sse41, 1) => unsafe { x86::grey_sse41(entries, tables, shift, pixels) },
            #[cfg(target_arch = "x86_64")]
            // SAFETY: as above.
            (Kernel::Sse41, _) => unsafe { x86::rgb_sse41(entries, tables, shift, pixels) },
            #[cfg(target_arch = "x86_64")]
            // SAFETY: `Kernel::Avx2Fma` is only made by `available` when the
            // CPU has AVX2 and FMA.
            (Kernel::Avx2Fma, 1) => unsafe { x86::grey_avx2(entries, tables, shift, pixels) },
            #[cfg(target_arch = "x86_64")]
            // SAFETY: as above.
            (Kernel::Avx2Fma, _) => unsafe { x86::rgb_avx2(entries, tables, shift, pixels) },
        }
    }
}

/// Bytes of a column's entries that [`prefetch`] asks for.
const PREFETCH_BYTES: usize = 512;

/// Asks the CPU to start loading the first [`PREFETCH_BYTES`] of `entries`
/// into the cache (a hint: no effect on results; nothing on other CPUs).
#[inline]
pub fn prefetch(entries: &[i16]) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        let bytes = std::mem::size_of_val(entries).min(PREFETCH_BYTES);
        let base = entries.as_ptr() as *const i8;
        for offset in (0..bytes).step_by(64) {
            // SAFETY: `offset` is within `entries` (a prefetch of any
            // address is safe anyway: it never faults); SSE is part of the
            // x86-64 baseline.
            unsafe { _mm_prefetch::<_MM_HINT_T0>(base.add(offset)) };
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = entries;
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

    /// Pixel `i` of `pixels` as a raw pointer, bounds-checked.
    #[inline(always)]
    fn pixel_ptr(pixels: &mut [[f32; 4]], i: usize) -> *mut f32 {
        pixels[i].as_mut_ptr()
    }

    /// AVX2 + FMA version of [`super::rgb_scalar`]: two entries (16 bytes)
    /// convert at once and meet their two bands' tables and two pixels in
    /// one 256-bit fused multiply-add. Two entries for the same pixel are
    /// done one after the other.
    ///
    /// # Safety
    /// The CPU must support AVX2 and FMA.
    #[target_feature(enable = "avx2,fma")]
    pub unsafe fn rgb_avx2(
        entries: &[i16],
        tables: &[[f32; 4]],
        shift: u32,
        pixels: &mut [[f32; 4]],
    ) {
        let mut pairs = entries.chunks_exact(8);
        for e in &mut pairs {
            let (b0, i0) = split(e[3], shift);
            let (b1, i1) = split(e[7], shift);
            let (t0, t1) = (&tables[b0], &tables[b1]);
            if i0 == i1 {
                // SAFETY: AVX2 and FMA are enabled for this function.
                unsafe {
                    rgb_one_fma(&e[..4], t0, &mut pixels[i0]);
                    rgb_one_fma(&e[4..], t1, &mut pixels[i1]);
                }
                continue;
            }
            let (p0, p1) = (pixel_ptr(pixels, i0), pixel_ptr(pixels, i1));
            // SAFETY: `e` holds 8 `i16` (16 bytes, read unaligned); `t0`,
            // `t1` are 16-byte tables; `p0` and `p1` point at two distinct
            // in-bounds pixels of 16 bytes (checked above); AVX2 and FMA are
            // enabled for this function.
            unsafe {
                let q = _mm256_cvtepi32_ps(_mm256_cvtepi16_epi32(_mm_loadu_si128(
                    e.as_ptr() as *const __m128i
                )));
                let t = _mm256_loadu2_m128(t1.as_ptr(), t0.as_ptr());
                let sum = _mm256_fmadd_ps(t, q, _mm256_loadu2_m128(p1, p0));
                _mm256_storeu2_m128(p1, p0, sum);
            }
        }
        for e in pairs.remainder().chunks_exact(4) {
            let (band, i) = split(e[3], shift);
            // SAFETY: AVX2 and FMA are enabled for this function.
            unsafe { rgb_one_fma(e, &tables[band], &mut pixels[i]) };
        }
    }

    /// One RGB entry by a 128-bit fused multiply-add.
    ///
    /// # Safety
    /// The CPU must support AVX2 and FMA; `e` holds 4 values.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    unsafe fn rgb_one_fma(e: &[i16], t: &[f32; 4], p: &mut [f32; 4]) {
        assert!(e.len() >= 4);
        // SAFETY: `e` holds 4 `i16` (8 bytes, read unaligned), `t` and `p`
        // 16 bytes each; AVX2 and FMA are enabled.
        unsafe {
            let q = _mm_cvtepi32_ps(_mm_cvtepi16_epi32(_mm_loadl_epi64(
                e.as_ptr() as *const __m128i
            )));
            let sum = _mm_fmadd_ps(_mm_loadu_ps(t.as_ptr()), q, _mm_loadu_ps(p.as_ptr()));
            _mm_storeu_ps(p.as_mut_ptr(), sum);
        }
    }

    /// AVX2 + FMA version of [`super::grey_scalar`]: two entries per
    /// 256-bit fused multiply-add, as [`rgb_avx2`].
    ///
    /// # Safety
    /// The CPU must support AVX2 and FMA.
    #[target_feature(enable = "avx2,fma")]
    pub unsafe fn grey_avx2(
        entries: &[i16],
        tables: &[[f32; 4]],
        shift: u32,
        pixels: &mut [[f32; 4]],
    ) {
        let one = |e: &[i16], pixels: &mut [[f32; 4]]| {
            let (band, i) = split(e[1], shift);
            let (t, p) = (&tables[band], &mut pixels[i]);
            // SAFETY: `t` and `p` are 16 bytes each; AVX2 and FMA are
            // enabled for this function.
            unsafe {
                let q = _mm_set1_ps(e[0] as f32);
                let sum = _mm_fmadd_ps(_mm_loadu_ps(t.as_ptr()), q, _mm_loadu_ps(p.as_ptr()));
                _mm_storeu_ps(p.as_mut_ptr(), sum);
            }
        };
        let mut pairs = entries.chunks_exact(4);
        for e in &mut pairs {
            let (b0, i0) = split(e[1], shift);
            let (b1, i1) = split(e[3], shift);
            if i0 == i1 {
                one(&e[..2], pixels);
                one(&e[2..], pixels);
                continue;
            }
            let (t0, t1) = (&tables[b0], &tables[b1]);
            let (p0, p1) = (pixel_ptr(pixels, i0), pixel_ptr(pixels, i1));
            // SAFETY: `t0`, `t1` are 16-byte tables; `p0` and `p1` point at
            // two distinct in-bounds pixels of 16 bytes; AVX2 and FMA are
            // enabled for this function.
            unsafe {
                let q = _mm256_set_m128(_mm_set1_ps(e[2] as f32), _mm_set1_ps(e[0] as f32));
                let t = _mm256_loadu2_m128(t1.as_ptr(), t0.as_ptr());
                let sum = _mm256_fmadd_ps(t, q, _mm256_loadu2_m128(p1, p0));
                _mm256_storeu2_m128(p1, p0, sum);
            }
        }
        for e in pairs.remainder().chunks_exact(2) {
            one(e, pixels);
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

    /// Every available kernel against the scalar reference, grey and RGB,
    /// for every code split, repeated offsets, odd counts (a pair's
    /// remainder) and empty inputs: SSE4.1 bit for bit, AVX2 + FMA within
    /// the module's bound `(2k + 2)·2⁻²⁴·(|p₀| + Σ|t·q|)` per pixel lane.
    #[test]
    fn every_available_kernel_agrees_with_the_scalar_reference() {
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let u = f32::EPSILON as f64 / 2.0;
        for fast in Kernel::available() {
            for channels in [1, 3] {
                for shift in [1, 5, 10, 11, 15] {
                    for n in [0, 1, 2, 7, 1000] {
                        let (entries, tables) = case(channels, n, shift, &mut seed);
                        let start: Vec<[f32; 4]> = (0..1usize << shift)
                            .map(|i| [i as f32 * 0.5, -(i as f32), 1e-7, 0.0])
                            .collect();
                        // Per pixel lane: entries added, and |p0| + Σ|t·q|.
                        let mut hits = vec![0usize; start.len()];
                        let mut mass: Vec<[f64; 3]> = start
                            .iter()
                            .map(|p| [0, 1, 2].map(|c| (p[c] as f64).abs()))
                            .collect();
                        for e in entries.chunks_exact(channels + 1) {
                            let (band, i) = split(e[channels], shift);
                            hits[i] += 1;
                            for (c, m) in mass[i].iter_mut().enumerate() {
                                let q = e[if channels == 1 { 0 } else { c }] as f64;
                                *m += (tables[band][c] as f64 * q).abs();
                            }
                        }
                        let (mut a, mut b) = (start.clone(), start);
                        Kernel::Scalar.run(channels, &entries, &tables, shift, &mut a);
                        fast.run(channels, &entries, &tables, shift, &mut b);
                        for (i, (x, y)) in a.iter().zip(&b).enumerate() {
                            for c in 0..3 {
                                let what = format!(
                                    "{} {channels} ch, shift {shift}, n {n}, pixel {i} lane {c}",
                                    fast.name()
                                );
                                let bound = (2 * hits[i] + 2) as f64 * u * mass[i][c];
                                let exact = fast.name() != "avx2+fma";
                                if exact {
                                    assert_eq!(x[c].to_bits(), y[c].to_bits(), "{what}");
                                } else {
                                    let d = (x[c] as f64 - y[c] as f64).abs();
                                    assert!(d <= bound, "{what}: {} vs {}", x[c], y[c]);
                                }
                            }
                            assert_eq!(y[3], 0.0);
                            assert!(y.iter().all(|v| v.is_finite()));
                        }
                    }
                }
            }
        }
    }

    /// The scalar reference is always available; x86-64 CPUs with SSE4.1
    /// start with the SSE4.1 kernel, others with the last available one.
    #[test]
    fn detection_picks_the_sse41_kernel_where_there_is_one() {
        let all = Kernel::available();
        assert_eq!(all[0], Kernel::Scalar);
        assert!(all.contains(&Kernel::detect()));
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("sse4.1") {
            assert_eq!(Kernel::detect(), Kernel::Sse41);
            return;
        }
        assert_eq!(Kernel::detect(), *all.last().unwrap());
    }
}
