//! PCA coefficients in component blocks of pixel tiles, and the frame's
//! dot products over them.
//!
//! The file quantizes each component `a` (a row of the `K × P` coefficient
//! matrix) to integers `q` within `±Q` with one scale `s_a`, so a value is
//! `q·s_a/Q`. They are held as those `i16` (half the bytes of `f32`), and a
//! frame folds `s_a/Q` into component `a`'s projected lighting once.
//!
//! Components come in blocks of [`BLOCK`] = 16 and pixels in tiles of
//! [`TILE`] = 24. Block `b` holds its components of every pixel, tile after
//! tile, each tile component-major: value `((b·T + t)·16 + i)·24 + l` is
//! component `16b + i` of pixel `24t + l` (`T` tiles; padding components
//! and pixels are 0). A frame with the first `k` eigen-transports reads
//! only the blocks it uses, each once, in long contiguous runs. A parallel
//! task takes a chunk of [`CHUNK`] tiles: for each block in turn, each
//! tile's 72 sums (24 pixels × 3 channels) are loaded into registers, take
//! the block's components one vertical fused multiply-add of 24 pixels at
//! a time (one lighting value per channel, no horizontal sums), and go back
//! to the chunk's sums, which stay in L2. Each pixel sums its components in
//! order, in f32 ([`super::PcaRelighter::relight_scalar`] is the f64
//! reference the tests hold it to).
//!
//! [`Blocks::dot_rows`] runs the loop written with AVX2 and FMA intrinsics
//! when the CPU has both (found at run time), and the portable loop
//! otherwise. Both fuse each multiply-add (one rounding, `f32::mul_add`) in
//! the same order, so they give the same bits, which the tests check. (The
//! fused form halves the floating-point operations of the loop, whose
//! separate multiply and add kept it compute-bound.)

#![allow(unsafe_code)]

use rayon::prelude::*;

/// Pixels per tile: three 8-lane vectors, whose 9 sums, 3 lighting values
/// and a converted vector fit the 16 AVX registers with room to spare (a
/// fourth vector made the compiler spill a sum to the stack, in the
/// multiply-add chain).
pub(crate) const TILE: usize = 24;
/// Components per block.
pub(crate) const BLOCK: usize = 16;
/// Tiles per chunk, the unit of parallel work (4080 pixels): the chunk's
/// sums (48 KiB) stay in L2 while each block's 128 KiB run streams past.
const CHUNK: usize = 170;
/// How many tiles ahead of the one multiplied [`prefetch`] reads.
const PREFETCH_TILES: usize = 4;

/// One tile's sums: `[channel][pixel within the tile]`.
type Sums = [[f32; TILE]; 3];

/// The coefficients of every pixel in component blocks of tiles (module
/// docs).
pub(crate) struct Blocks {
    data: Vec<i16>,
    /// `s_a/Q` per component, in f64.
    steps: Vec<f64>,
    pixels: usize,
    tiles: usize,
    blocks: usize,
}

/// Which compiled loop [`Blocks::dot_rows`] runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Path {
    /// The portable loop, for the baseline target's vectors.
    Baseline,
    /// AVX2 and FMA intrinsics (x86-64 only).
    #[cfg(target_arch = "x86_64")]
    Avx,
}

impl Path {
    /// The fastest path this CPU runs.
    pub fn detect() -> Path {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
        {
            return Path::Avx;
        }
        Path::Baseline
    }
}

impl Blocks {
    /// Arranges the `K × P` quantized coefficients `q` (row-major, each
    /// within `±q_max` ≤ 32767), with component `a`'s value `q·scales[a] /
    /// q_max`.
    pub fn new(pixels: usize, q: &[i32], scales: &[f32], q_max: i32) -> Blocks {
        let rank = scales.len();
        assert!(q.len() == rank * pixels && (1..=i16::MAX as i32).contains(&q_max));
        let (tiles, blocks) = (pixels.div_ceil(TILE), rank.div_ceil(BLOCK));
        let mut data = vec![0i16; Self::padded_len(pixels, rank)];
        for (a, row) in q.chunks_exact(pixels.max(1)).enumerate() {
            for (p, &v) in row.iter().enumerate() {
                data[Self::index(tiles, p, a)] = v.clamp(-q_max, q_max) as i16;
            }
        }
        let mut steps: Vec<f64> = scales.iter().map(|&s| s as f64 / q_max as f64).collect();
        steps.resize(blocks * BLOCK, 0.0);
        Blocks {
            data,
            steps,
            pixels,
            tiles,
            blocks,
        }
    }

    /// Values held, padding included (the size a limit is checked against).
    pub fn padded_len(pixels: usize, rank: usize) -> usize {
        pixels.div_ceil(TILE) * TILE * rank.div_ceil(BLOCK) * BLOCK
    }

    fn index(tiles: usize, p: usize, a: usize) -> usize {
        ((a / BLOCK * tiles + p / TILE) * BLOCK + a % BLOCK) * TILE + p % TILE
    }

    /// Bytes held.
    pub fn held_bytes(&self) -> usize {
        2 * self.data.len() + 8 * self.steps.len()
    }

    /// The first `k` components of pixel `p` decoded as the codec decodes
    /// them (`q·s/Q` in f64, rounded once), into `out`.
    pub fn row(&self, p: usize, k: usize, out: &mut Vec<f32>) {
        out.clear();
        out.extend(
            (0..k)
                .map(|a| (self.data[Self::index(self.tiles, p, a)] as f64 * self.steps[a]) as f32),
        );
    }

    /// Bytes a frame with `k` components reads: whole blocks, but for the
    /// last one's unused components.
    pub fn bytes_read(&self, k: usize) -> usize {
        2 * k.min(self.blocks * BLOCK) * self.tiles * TILE
    }

    /// The planar projected lighting of the first `k` components (`3 × k`),
    /// each value times its component's step `s_a/Q`, rounded to f32 once:
    /// what [`Blocks::dot_rows`] multiplies the integers by.
    pub fn scaled_light(&self, projected: &[[f64; 3]], k: usize, planar: &mut Vec<f32>) {
        planar.clear();
        planar.resize(3 * k, 0.0);
        for (a, l) in projected[..k].iter().enumerate() {
            for (c, lc) in l.iter().enumerate() {
                planar[c * k + a] = (lc * self.steps[a]) as f32;
            }
        }
    }

    /// Every pixel's dot product of its first `k` integer components with
    /// the planar lighting from [`Blocks::scaled_light`] (`3 × k` values),
    /// in f32 and component order, stored in `out`; `finish(p0, pixels)`
    /// then finishes each parallel task's run of pixels, `p0` onwards, while
    /// they are in cache.
    pub fn dot_rows(
        &self,
        path: Path,
        planar: &[f32],
        k: usize,
        out: &mut [[f32; 3]],
        finish: impl Fn(usize, &mut [[f32; 3]]) + Sync,
    ) {
        assert!(k <= self.blocks * BLOCK && planar.len() == 3 * k && out.len() == self.pixels);
        let light = [&planar[..k], &planar[k..2 * k], &planar[2 * k..]];
        out.par_chunks_mut(CHUNK * TILE).enumerate().for_each_init(
            || vec![[[0.0f32; TILE]; 3]; CHUNK],
            |sums, (i, chunk)| {
                let t0 = i * CHUNK;
                let sums = &mut sums[..chunk.len().div_ceil(TILE)];
                self.chunk_sums(path, light, t0, sums);
                for (px, s) in chunk.chunks_mut(TILE).zip(sums.iter()) {
                    for (l, v) in px.iter_mut().enumerate() {
                        *v = [s[0][l], s[1][l], s[2][l]];
                    }
                }
                finish(t0 * TILE, chunk);
            },
        );
    }

    /// The sums of tiles `t0 .. t0 + sums.len()` over the components of
    /// `light`, block by block, into `sums`.
    fn chunk_sums(&self, path: Path, light: [&[f32]; 3], t0: usize, sums: &mut [Sums]) {
        sums.fill([[0.0; TILE]; 3]);
        let (k, n) = (light[0].len(), sums.len());
        for b in 0..k.div_ceil(BLOCK) {
            let (a0, a1) = (b * BLOCK, (b * BLOCK + BLOCK).min(k));
            let block_light = light.map(|l| &l[a0..a1]);
            let start = (b * self.tiles + t0) * BLOCK * TILE;
            let run = &self.data[start..start + n * BLOCK * TILE];
            // Tile `i`'s used values within the run, if it is in the chunk.
            let used = |i: usize| run.get(i * BLOCK * TILE..i * BLOCK * TILE + (a1 - a0) * TILE);
            for (i, s) in sums.iter_mut().enumerate() {
                if let Some(ahead) = used(i + PREFETCH_TILES) {
                    prefetch(path, ahead);
                }
                add_components(path, used(i).expect("a tile of the chunk"), block_light, s);
            }
        }
    }
}

/// Asks for `q`'s cache lines ahead of their use (AVX path only; the
/// hardware prefetcher alone left one core's stream at about two thirds of
/// a plain read's rate).
#[inline]
fn prefetch(path: Path, q: &[i16]) {
    #[cfg(target_arch = "x86_64")]
    if path == Path::Avx {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        for line in q.chunks(32) {
            // SAFETY: a prefetch only hints the cache and never faults; the
            // address is within `q`.
            unsafe { _mm_prefetch::<_MM_HINT_T0>(line.as_ptr().cast()) };
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (path, q);
}

fn add_components(path: Path, q: &[i16], light: [&[f32]; 3], sums: &mut Sums) {
    let m = light[0].len();
    assert!(q.len() == m * TILE && light.iter().all(|l| l.len() == m));
    match path {
        Path::Baseline => add_components_portable(q, light, sums),
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `Path::Avx` is only made by `Path::detect` when the CPU
        // has AVX2 and FMA (or by tests that check the same); the lengths
        // are asserted above.
        Path::Avx => unsafe { add_components_avx2(q, light, sums) },
    }
}

/// Adds a tile's `m = light[c].len()` components (`q`: `m × TILE` values)
/// times their lighting into its sums, in component order: the reference
/// loop.
fn add_components_portable(q: &[i16], light: [&[f32]; 3], sums: &mut Sums) {
    for (a, qa) in q.chunks_exact(TILE).enumerate() {
        let f: [f32; TILE] = std::array::from_fn(|l| f32::from(qa[l]));
        for (s, lc) in sums.iter_mut().zip(light) {
            let w = lc[a];
            for (x, &v) in s.iter_mut().zip(&f) {
                *x = v.mul_add(w, *x);
            }
        }
    }
}

/// [`add_components_portable`] with AVX2 and FMA intrinsics: the tile's
/// 72 sums in 9 registers (beside the 3 lighting values and the converted
/// integers), one 16-byte load of 8 integers per third of a tile and
/// component, read in order. The 9 independent chains of fused
/// multiply-adds hide their latency (4 cycles, against 4.5 for the 9 on
/// two FMA pipes).
///
/// # Safety
/// The CPU must support AVX2 and FMA; every `light[c]` has `m` values and
/// `q.len() == m·TILE`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn add_components_avx2(q: &[i16], light: [&[f32]; 3], sums: &mut Sums) {
    use std::arch::x86_64::*;
    const V: usize = TILE / 8;
    let m = light[0].len();
    let mut acc = [[_mm256_setzero_ps(); V]; 3];
    for (acc, s) in acc.iter_mut().zip(sums.iter()) {
        for (v, a) in acc.iter_mut().enumerate() {
            // SAFETY: a channel's sums hold `8·V` f32; the loads are
            // unaligned.
            *a = unsafe { _mm256_loadu_ps(s.as_ptr().add(8 * v)) };
        }
    }
    for a in 0..m {
        // SAFETY: `a < m`, the length of every `light[c]` (caller).
        let w = light.map(|l| _mm256_set1_ps(unsafe { *l.get_unchecked(a) }));
        for v in 0..V {
            // SAFETY: `a·TILE + 8v + 8 ≤ m·TILE = q.len()` (caller); the
            // load is unaligned.
            let x = unsafe { _mm_loadu_si128(q.as_ptr().add(a * TILE + 8 * v).cast()) };
            let x = _mm256_cvtepi32_ps(_mm256_cvtepi16_epi32(x));
            for (acc, w) in acc.iter_mut().zip(&w) {
                acc[v] = _mm256_fmadd_ps(x, *w, acc[v]);
            }
        }
    }
    for (acc, s) in acc.iter().zip(sums.iter_mut()) {
        for (v, a) in acc.iter().enumerate() {
            // SAFETY: as for the loads.
            unsafe { _mm256_storeu_ps(s.as_mut_ptr().add(8 * v), *a) };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A `rank × pixels` matrix of integers within ±300, and its scales.
    fn matrix(pixels: usize, rank: usize) -> (Vec<i32>, Vec<f32>) {
        let q = (0..rank * pixels)
            .map(|i| ((i * 7919) % 601) as i32 - 300)
            .collect();
        let scales = (0..rank).map(|a| 0.5 + a as f32 * 0.25).collect();
        (q, scales)
    }

    #[test]
    fn rows_decode_every_component_as_the_codec_does() {
        let (pixels, rank) = (37, 13);
        let (q, scales) = matrix(pixels, rank);
        let blocks = Blocks::new(pixels, &q, &scales, 511);
        assert_eq!(blocks.data.len(), Blocks::padded_len(pixels, rank));
        let mut row = Vec::new();
        for p in 0..pixels {
            blocks.row(p, rank, &mut row);
            let want: Vec<f32> = (0..rank)
                .map(|a| ltm_codec::pca::dequantize(q[a * pixels + p], scales[a], 10))
                .collect();
            assert_eq!(row, want, "pixel {p}");
        }
    }

    /// Each path against a plain in-order f32 fused sum of `q · scaled
    /// light`, bit for bit, over odd pixel counts, partial tiles and blocks,
    /// `k` below the rank, the `i16` range's ends and more than one task.
    #[test]
    fn every_path_gives_the_in_order_sums_bit_for_bit() {
        let mut paths = vec![Path::Baseline];
        #[cfg(target_arch = "x86_64")]
        if Path::detect() == Path::Avx {
            paths.push(Path::Avx);
        }
        for (pixels, rank, k, q_max) in [
            (1usize, 1usize, 1usize, 300),
            (37, 13, 13, 300),
            (37, 13, 5, 300),
            (37, 13, 0, 300),
            (37, 40, 33, 300),
            (17000, 24, 17, 300),
            (17000, 48, 48, 300),
            (5000, 9, 9, i16::MAX as i32),
        ] {
            let (mut q, scales) = matrix(pixels, rank);
            if q_max == i16::MAX as i32 {
                // The integer range's ends, where a wrong sign extension shows.
                for (i, v) in q.iter_mut().enumerate() {
                    *v = [-q_max, q_max, -1, 1, 0][i % 5];
                }
            }
            let blocks = Blocks::new(pixels, &q, &scales, q_max);
            let projected: Vec<[f64; 3]> = (0..rank)
                .map(|a| [0.5, -1.25, 3.0].map(|x| x * (a as f64 + 1.0)))
                .collect();
            let mut planar = Vec::new();
            blocks.scaled_light(&projected, k, &mut planar);
            let want: Vec<[f32; 3]> = (0..pixels)
                .map(|p| {
                    let mut v = [0.0f32; 3];
                    for a in 0..k {
                        for (c, x) in v.iter_mut().enumerate() {
                            *x = (q[a * pixels + p] as f32).mul_add(planar[c * k + a], *x);
                        }
                    }
                    v.map(|x| x + p as f32)
                })
                .collect();
            for &path in &paths {
                let mut out = vec![[0.0f32; 3]; pixels];
                blocks.dot_rows(path, &planar, k, &mut out, |p0, px| {
                    for (j, v) in px.iter_mut().enumerate() {
                        *v = v.map(|x| x + (p0 + j) as f32);
                    }
                });
                assert_eq!(out, want, "{path:?}, {pixels} pixels, rank {rank}, k {k}");
            }
        }
    }
}
