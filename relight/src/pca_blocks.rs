//! PCA coefficients in component blocks, and the frame's dot products over
//! them.
//!
//! The file quantizes each component `a` (a row of the `K × P` coefficient
//! matrix) to integers `q` within `±Q` with one scale `s_a`, so a value is
//! `q·s_a/Q`. They are held as those `i16` (half the bytes of `f32`), and a
//! frame folds `s_a/Q` into component `a`'s projected lighting once.
//!
//! A frame with the first `k` eigen-transports reads only the coefficients
//! it uses, each once, in long contiguous runs: block `b` holds components
//! `8b .. 8b + 8` of every pixel, in groups of 8 pixels, component-major
//! within a group, so value `((b·G + g)·8 + i)·8 + l` is component `8b + i`
//! of pixel `8g + l` (`G` groups; padding components and pixels are 0).
//! Eight pixels then take one lighting value per component and channel, so
//! the inner loop is a vertical multiply-add over 8 lanes with no
//! horizontal sums, which the compiler vectorizes; each pixel still sums its
//! components in order, in f32 ([`super::PcaRelighter::relight_scalar`] is
//! the f64 reference the tests hold it to).
//!
//! [`Blocks::dot_rows`] runs the same loop compiled for AVX2 when the CPU has
//! it (found at run time) and for the baseline otherwise. Both multiply and
//! add separately in the same order, so they give the same bits, which the
//! tests check.

#![allow(unsafe_code)]

use rayon::prelude::*;

/// Components per block and pixels per group.
pub(crate) const LANES: usize = 8;
/// Pixel groups per parallel task (16384 pixels, 192 KiB of accumulators,
/// which stay in L2): each task streams 256 KiB of each component block.
const GROUPS_PER_TASK: usize = 2048;

/// One group's accumulators: `[channel][pixel lane]`.
type Acc = [[f32; LANES]; 3];

/// The coefficients of every pixel in component blocks (module docs).
pub(crate) struct Blocks {
    data: Vec<i16>,
    /// `s_a/Q` per component (padding 0), in f64.
    steps: Vec<f64>,
    pixels: usize,
    groups: usize,
    blocks: usize,
}

/// Which compiled loop [`Blocks::dot_rows`] runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Path {
    /// The baseline target's vectors.
    Baseline,
    /// 256-bit AVX2 vectors (x86-64 only).
    #[cfg(target_arch = "x86_64")]
    Avx,
}

impl Path {
    /// The fastest path this CPU runs.
    pub fn detect() -> Path {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
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
        let (groups, blocks) = (pixels.div_ceil(LANES), rank.div_ceil(LANES));
        let mut data = vec![0i16; blocks * groups * LANES * LANES];
        for (a, row) in q.chunks_exact(pixels.max(1)).enumerate() {
            for (p, &v) in row.iter().enumerate() {
                data[Self::index(groups, p, a)] = v.clamp(-q_max, q_max) as i16;
            }
        }
        let mut steps: Vec<f64> = scales.iter().map(|&s| s as f64 / q_max as f64).collect();
        steps.resize(blocks * LANES, 0.0);
        Blocks {
            data,
            steps,
            pixels,
            groups,
            blocks,
        }
    }

    /// Values held, padding included (the size a limit is checked against).
    pub fn padded_len(pixels: usize, rank: usize) -> usize {
        pixels.div_ceil(LANES) * rank.div_ceil(LANES) * LANES * LANES
    }

    fn index(groups: usize, p: usize, a: usize) -> usize {
        ((a / LANES * groups + p / LANES) * LANES + a % LANES) * LANES + p % LANES
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
                .map(|a| (self.data[Self::index(self.groups, p, a)] as f64 * self.steps[a]) as f32),
        );
    }

    /// Bytes a frame with `k` components reads.
    pub fn bytes_read(&self, k: usize) -> usize {
        2 * k.div_ceil(LANES).min(self.blocks) * self.groups * LANES * LANES
    }

    /// The planar projected lighting of the first `k` components (`3 ×
    /// kp`), each value times its component's step `s_a/Q`, rounded to f32
    /// once: what [`Blocks::dot_rows`] multiplies the integers by.
    pub fn scaled_light(&self, projected: &[[f64; 3]], k: usize, planar: &mut Vec<f32>) {
        let kp = k.next_multiple_of(LANES);
        planar.clear();
        planar.resize(3 * kp, 0.0);
        for (a, l) in projected[..k].iter().enumerate() {
            for (c, lc) in l.iter().enumerate() {
                planar[c * kp + a] = (lc * self.steps[a]) as f32;
            }
        }
    }

    /// Every pixel's dot product of its first `k` integer components with
    /// the planar lighting from [`Blocks::scaled_light`] (`3 × kp` values,
    /// zero past `k`), in f32 and component order, handed to `finish(p, [r,
    /// g, b])` to store.
    pub fn dot_rows(
        &self,
        path: Path,
        planar: &[f32],
        k: usize,
        out: &mut [[f32; 3]],
        finish: impl Fn(usize, [f32; 3]) -> [f32; 3] + Sync,
    ) {
        let kb = k.div_ceil(LANES).min(self.blocks);
        let kp = planar.len() / 3;
        assert!(kp >= kb * LANES && out.len() == self.pixels);
        let task = GROUPS_PER_TASK * LANES;
        out.par_chunks_mut(task)
            .enumerate()
            .for_each(|(t, pixels)| {
                let mut acc = [[[0.0f32; LANES]; 3]; GROUPS_PER_TASK];
                let groups = pixels.len().div_ceil(LANES);
                let acc = &mut acc[..groups];
                for b in 0..kb {
                    let light = block_light(planar, kp, b);
                    let start = (b * self.groups + t * GROUPS_PER_TASK) * LANES * LANES;
                    let values = &self.data[start..start + groups * LANES * LANES];
                    run(path, acc, values, &light);
                }
                for (i, px) in pixels.iter_mut().enumerate() {
                    let a = &acc[i / LANES];
                    let v = [a[0][i % LANES], a[1][i % LANES], a[2][i % LANES]];
                    *px = finish(t * task + i, v);
                }
            });
    }
}

/// Block `b`'s lighting: `[channel][component within the block]`.
fn block_light(planar: &[f32], kp: usize, b: usize) -> Acc {
    let mut light = [[0.0f32; LANES]; 3];
    for (c, l) in light.iter_mut().enumerate() {
        l.copy_from_slice(&planar[c * kp + b * LANES..c * kp + (b + 1) * LANES]);
    }
    light
}

fn run(path: Path, acc: &mut [Acc], values: &[i16], light: &Acc) {
    match path {
        Path::Baseline => accumulate(acc, values, light),
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `Path::Avx` is only made by `Path::detect` when the CPU
        // has AVX2 (or by tests that check the same).
        Path::Avx => unsafe { accumulate_avx(acc, values, light) },
    }
}

/// [`accumulate`] compiled for AVX2.
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn accumulate_avx(acc: &mut [Acc], values: &[i16], light: &Acc) {
    accumulate(acc, values, light)
}

/// Adds one component block of consecutive pixel groups (`values`, 64 per
/// group) times the block's lighting into the groups' accumulators.
#[inline(always)]
fn accumulate(acc: &mut [Acc], values: &[i16], light: &Acc) {
    for (a, group) in acc.iter_mut().zip(values.chunks_exact(LANES * LANES)) {
        for (i, q) in group.chunks_exact(LANES).enumerate() {
            let q: &[i16; LANES] = q.try_into().expect("LANES values");
            let f = q.map(f32::from);
            for (ac, lc) in a.iter_mut().zip(light) {
                let w = lc[i];
                for (x, &v) in ac.iter_mut().zip(&f) {
                    *x += v * w;
                }
            }
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
                .map(|a| ltm_codec::eigen::dequantize(q[a * pixels + p], scales[a], 10))
                .collect();
            assert_eq!(row, want, "pixel {p}");
        }
    }

    /// Each path against a plain in-order f32 sum of `q · scaled light`, bit
    /// for bit, over odd pixel counts, partial blocks and more than one
    /// task.
    #[test]
    fn every_path_gives_the_in_order_sums_bit_for_bit() {
        let mut paths = vec![Path::Baseline];
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            paths.push(Path::Avx);
        }
        for (pixels, rank, k) in [
            (1usize, 1usize, 1usize),
            (37, 13, 13),
            (37, 13, 5),
            (17000, 24, 17),
        ] {
            let (q, scales) = matrix(pixels, rank);
            let blocks = Blocks::new(pixels, &q, &scales, 300);
            let projected: Vec<[f64; 3]> = (0..rank)
                .map(|a| [0.5, -1.25, 3.0].map(|x| x * (a as f64 + 1.0)))
                .collect();
            let mut planar = Vec::new();
            blocks.scaled_light(&projected, k, &mut planar);
            let kp = planar.len() / 3;
            let want: Vec<[f32; 3]> = (0..pixels)
                .map(|p| {
                    let mut v = [0.0f32; 3];
                    for a in 0..k {
                        for (c, x) in v.iter_mut().enumerate() {
                            *x += q[a * pixels + p] as f32 * planar[c * kp + a];
                        }
                    }
                    v.map(|x| x + p as f32)
                })
                .collect();
            for &path in &paths {
                let mut out = vec![[0.0f32; 3]; pixels];
                blocks.dot_rows(path, &planar, k, &mut out, |p, v| v.map(|x| x + p as f32));
                assert_eq!(out, want, "{path:?}, {pixels} pixels, rank {rank}, k {k}");
            }
        }
    }
}
