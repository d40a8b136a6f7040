//! Baselines for the size/error report: what the wavelet codec is measured
//! against on the same matrix `T` (rows = pixels, columns = cubemap texels).
//!
//! - `zstd-raw`: the raw f32 matrix compressed losslessly with zstd.
//! - `pca`: the best low-rank factorisation `T ≈ U_k·S_k·V_kᵀ`, the idea of
//!   Eigentransport (Nowrouzezahrai et al. 2007, "Eigentransport for
//!   efficient and accurate all-frequency relighting": principal components
//!   of the transport give a light basis shared by all pixels). The rows are
//!   (pixel, channel) pairs, so one light basis `V` serves all channels. It
//!   is computed with the randomized SVD of Halko, Martinsson and Tropp 2011
//!   ("Finding structure with randomness", SIAM Review 53(2)): a Gaussian
//!   sketch of the row space, power iterations with re-orthonormalisation
//!   and a Rayleigh–Ritz step, all streamed over the rows.
//! - `sh`: the linear spherical-harmonics approximation of each row, the
//!   basis of precomputed radiance transfer (Sloan, Kautz and Snyder 2002,
//!   "Precomputed radiance transfer for real-time rendering in dynamic,
//!   low-frequency lighting environments"), the comparison made by Ng,
//!   Ramamoorthi and Hanrahan 2003 ("All-frequency shadows using non-linear
//!   wavelet lighting approximation").
//!
//! Sizes count the stored factors as uncompressed f32 values; errors are the
//! relative Frobenius error `‖T − T̂‖_F / ‖T‖_F` of the matrix, computed in
//! f64. None of the sizes includes the albedo image of a grey store. The raw
//! store is read block by block (never whole in memory), its block checksums
//! are verified on the first pass, and rows flagged all zero are skipped.

use anyhow::{anyhow, ensure, Result};
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatRef, Par, Side};
use ltm_codec::cubemap;
use ltm_codec::{Dims, RawStore};
use ltm_relight::Image;
use rayon::prelude::*;
use std::f64::consts::PI;
use std::io::Write;

/// Values (rows × lights) of one block of rows converted to a dense matrix.
const CHUNK_VALUES: usize = 1 << 23;
/// Bytes of raw rows per zstd frame (frames are compressed in parallel).
const ZSTD_FRAME_BYTES: usize = 32 << 20;
/// Extra columns of the randomized sketch beyond the largest rank.
const OVERSAMPLING: usize = 10;
/// Power iterations of the randomized SVD.
const POWER_ITERATIONS: usize = 2;
/// Largest spherical-harmonics order accepted by [`sh`].
pub const MAX_SH_ORDER: usize = 64;

/// One baseline point: size in bytes against relative L2 (Frobenius) error
/// of the matrix.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct BaselinePoint {
    /// `"zstd-raw"`, `"pca"` or `"sh"`.
    pub method: String,
    /// 0 for zstd, the rank `k` for PCA, the order `L` for SH (`L²`
    /// coefficients, bands `l < L`).
    pub param: usize,
    /// Size of the representation in bytes.
    pub bytes: u64,
    /// `‖T − T̂‖_F / ‖T‖_F` (0 for an all-zero matrix).
    pub matrix_error: f64,
}

// ---------------------------------------------------------------------------
// Streaming the rows

/// A block of nonzero matrix rows as a dense matrix.
struct Block<'a, T> {
    /// Matrix row index `p·C + c` of each row of the block.
    rows: &'a [usize],
    /// Row `i` is `data[i·M .. (i+1)·M]`.
    data: &'a [T],
    lights: usize,
}

impl<'a, T> Block<'a, T> {
    /// The block transposed, `M × R`, column-major.
    fn at(&self) -> MatRef<'a, T> {
        MatRef::from_column_major_slice(self.data, self.lights, self.rows.len())
    }

    /// The block, `R × M`.
    fn a(&self) -> MatRef<'a, T> {
        self.at().transpose()
    }

    fn row(&self, i: usize) -> &'a [T] {
        &self.data[i * self.lights..(i + 1) * self.lights]
    }
}

/// Calls `f` on consecutive blocks of the nonzero rows of `raw` (rows are
/// (pixel, channel) pairs, `M` values each), each of about `chunk_values`
/// values, converted to `T`. With `verify`, the checksum of every store
/// block is checked before its rows are used.
fn for_each_block<T, F>(
    raw: &RawStore,
    chunk_values: usize,
    verify: bool,
    buf: &mut Vec<T>,
    mut f: F,
) -> Result<()>
where
    T: Copy + Default + From<f32> + Send + Sync,
    F: FnMut(Block<'_, T>) -> Result<()>,
{
    let dims = raw.dims();
    let header = *raw.header();
    let (pixels, m, c) = (dims.pixels(), dims.lights(), dims.channels as usize);
    let chunk_pixels = (chunk_values / (m * c)).max(1);
    let mut rows = Vec::new();
    let mut next_block = 0;
    let mut start = 0;
    while start < pixels {
        let end = (start + chunk_pixels).min(pixels);
        if verify {
            while next_block < header.block_count() && header.block_range(next_block).start < end {
                raw.verify_block(next_block)?;
                next_block += 1;
            }
        }
        rows.clear();
        for p in (start..end).filter(|&p| !raw.is_zero_row(p)) {
            rows.extend((0..c).map(|ch| p * c + ch));
        }
        if !rows.is_empty() {
            buf.clear();
            buf.resize(rows.len() * m, T::default());
            buf.par_chunks_mut(m)
                .zip(rows.par_iter())
                .for_each(|(dst, &r)| {
                    let src = raw.row(r / c);
                    for (d, s) in dst.iter_mut().zip(src.iter().skip(r % c).step_by(c)) {
                        *d = T::from(*s);
                    }
                });
            f(Block {
                rows: &rows,
                data: buf,
                lights: m,
            })?;
        }
        raw.release_rows(start..end);
        start = end;
    }
    Ok(())
}

/// `‖row‖²` summed over the rows of a block, in f64.
fn block_norm2<T: Copy + Into<f64> + Sync>(data: &[T]) -> f64 {
    data.par_chunks(1 << 16)
        .map(|c| c.iter().map(|&v| v.into() * v.into()).sum::<f64>())
        .sum()
}

fn relative(err2: f64, norm2: f64) -> f64 {
    if norm2 > 0.0 {
        (err2.max(0.0) / norm2).sqrt()
    } else {
        0.0
    }
}

// ---------------------------------------------------------------------------
// zstd

/// Lossless zstd (at `level`) of the raw f32 matrix rows, as stored
/// (`T[p][j][c]`, little-endian), streamed block by block; error 0.
pub fn zstd_raw(raw: &RawStore, level: i32) -> Result<BaselinePoint> {
    let bytes = zstd_raw_to(raw, level, ZSTD_FRAME_BYTES, &mut std::io::sink())?;
    Ok(BaselinePoint {
        method: "zstd-raw".into(),
        param: 0,
        bytes,
        matrix_error: 0.0,
    })
}

/// Writes the zstd stream of the raw rows to `out` (consecutive frames of
/// about `frame_bytes` of rows each, compressed in parallel) and returns its
/// length in bytes.
fn zstd_raw_to(raw: &RawStore, level: i32, frame_bytes: usize, out: &mut dyn Write) -> Result<u64> {
    let dims = raw.dims();
    let header = *raw.header();
    let pixels = dims.pixels();
    let frame_pixels = (frame_bytes / (dims.row_len() * 4)).max(1);
    let frames: Vec<std::ops::Range<usize>> = (0..pixels)
        .step_by(frame_pixels)
        .map(|s| s..(s + frame_pixels).min(pixels))
        .collect();
    let batch = 2 * rayon::current_num_threads().max(1);
    let mut next_block = 0;
    let mut total = 0u64;
    for group in frames.chunks(batch) {
        let end = group.last().map_or(0, |r| r.end);
        while next_block < header.block_count() && header.block_range(next_block).start < end {
            raw.verify_block(next_block)?;
            next_block += 1;
        }
        let compressed: Vec<Vec<u8>> = group
            .par_iter()
            .map(|r| {
                let values = raw.rows(r.clone());
                let mut bytes = Vec::with_capacity(values.len() * 4);
                for v in values {
                    bytes.extend_from_slice(&v.to_le_bytes());
                }
                let frame = zstd::bulk::compress(&bytes, level)?;
                raw.release_rows(r.clone());
                Ok(frame)
            })
            .collect::<std::io::Result<_>>()?;
        for frame in compressed {
            out.write_all(&frame)?;
            total += frame.len() as u64;
        }
    }
    Ok(total)
}

// ---------------------------------------------------------------------------
// PCA

/// PCA over rows (Eigentransport-style low-rank basis): `T ≈ U_k·S_k·V_kᵀ`
/// by a randomized SVD (Halko et al. 2011) with a Gaussian sketch of width
/// `max(ranks) + 10` drawn from `seed`, two power iterations and a
/// Rayleigh–Ritz step. Rows are (pixel, channel) pairs, so the light basis
/// `V` (`M × k`) is shared by the channels. The size of rank `k` is
/// `k·(P·C + M)·4` bytes (f32 factors). The error of each rank is that of
/// the orthogonal projection of every row onto the first `k` basis vectors,
/// `Σ_r ‖t_r − Σ_{i<k} (t_r·v_i) v_i‖²`, accumulated in f64 over the raw
/// rows. Ranks are sorted, clamped to `min(P·C, M)` and deduplicated.
pub fn pca(raw: &RawStore, ranks: &[usize], seed: u64) -> Result<Vec<BaselinePoint>> {
    let (points, _basis) = pca_fit(raw, ranks, seed, CHUNK_VALUES)?;
    Ok(points)
}

/// The points of [`pca`] and the light basis `V` (`M × k_max`, orthonormal
/// columns by decreasing captured energy).
type PcaFit = (Vec<BaselinePoint>, Mat<f64>);

fn pca_fit(raw: &RawStore, ranks: &[usize], seed: u64, chunk_values: usize) -> Result<PcaFit> {
    let dims = raw.dims();
    let m = dims.lights();
    let n_rows = dims.pixels() * dims.channels as usize;
    let full = n_rows.min(m);
    let mut ranks: Vec<usize> = ranks.iter().map(|&k| k.min(full)).collect();
    ranks.sort_unstable();
    ranks.dedup();
    let k_max = ranks.last().copied().unwrap_or(0);
    let l = (k_max + OVERSAMPLING).min(full);
    let par = Par::rayon(0);
    if ranks.is_empty() {
        return Ok((Vec::new(), Mat::zeros(m, 0)));
    }
    let point = |k: usize, matrix_error: f64| BaselinePoint {
        method: "pca".into(),
        param: k,
        bytes: k as u64 * (n_rows + m) as u64 * 4,
        matrix_error,
    };

    // Sketch of the row space: Z = Aᵀ·G, G Gaussian (rows × l), one pass.
    let mut z = Mat::<f32>::zeros(m, l);
    let mut norm2 = 0.0f64;
    let mut buf32: Vec<f32> = Vec::new();
    let mut gauss: Vec<f32> = Vec::new();
    for_each_block(raw, chunk_values, true, &mut buf32, |blk| {
        norm2 += block_norm2(blk.data);
        gauss.resize(blk.rows.len() * l, 0.0);
        gauss
            .par_chunks_mut(l.max(1))
            .zip(blk.rows.par_iter())
            .for_each(|(dst, &r)| gaussian_row(seed, r, dst));
        let g = MatRef::from_row_major_slice(&gauss, blk.rows.len(), l);
        matmul(z.as_mut(), Accum::Add, blk.at(), g, 1.0f32, par);
        Ok(())
    })?;
    if norm2 == 0.0 || l == 0 {
        let points = ranks.iter().map(|&k| point(k, 0.0)).collect();
        return Ok((points, Mat::zeros(m, k_max)));
    }
    let mut q = orthonormal_columns(&z);

    // Power iterations Z = Aᵀ·A·Q in f32, with A scaled by a power of two
    // near 1/‖A‖ so that the squared magnitudes stay in range.
    let scale = 2f32.powi(-(0.5 * norm2.log2()).round().clamp(-120.0, 120.0) as i32);
    for _ in 0..POWER_ITERATIONS {
        let q32 = Mat::<f32>::from_fn(m, l, |i, j| q[(i, j)] as f32);
        let mut z = Mat::<f32>::zeros(m, l);
        for_each_block(raw, chunk_values, false, &mut buf32, |blk| {
            let mut x = Mat::<f32>::zeros(blk.rows.len(), l);
            matmul(
                x.as_mut(),
                Accum::Replace,
                blk.a(),
                q32.as_ref(),
                scale,
                par,
            );
            matmul(z.as_mut(), Accum::Add, blk.at(), x.as_ref(), scale, par);
            Ok(())
        })?;
        q = orthonormal_columns(&z);
    }
    drop(buf32);

    // Rayleigh–Ritz in f64: C = A·Q (coefficients on the orthonormal Q),
    // H = CᵀC; its eigenvectors W give V = Q·W, and the energy row r keeps
    // on v_i is (c_r·w_i)², so Σ_r ‖t_r − Σ_{i<k}(t_r·v_i)v_i‖² equals
    // ‖A‖² − Σ_{i<k} w_iᵀ·H·w_i.
    let mut h = Mat::<f64>::zeros(l, l);
    let mut norm2 = 0.0f64;
    let mut buf64: Vec<f64> = Vec::new();
    for_each_block(raw, chunk_values, false, &mut buf64, |blk| {
        norm2 += block_norm2(blk.data);
        let mut c = Mat::<f64>::zeros(blk.rows.len(), l);
        matmul(c.as_mut(), Accum::Replace, blk.a(), q.as_ref(), 1.0, par);
        matmul(h.as_mut(), Accum::Add, c.transpose(), c.as_ref(), 1.0, par);
        Ok(())
    })?;
    let evd = h
        .as_ref()
        .self_adjoint_eigen(Side::Lower)
        .map_err(|e| anyhow!("PCA: eigendecomposition of the {l}×{l} Gram matrix failed: {e:?}"))?;
    // Eigenvalues come in nondecreasing order: take them from the end.
    let u = evd.U();
    let w = Mat::<f64>::from_fn(l, k_max, |i, j| u[(i, l - 1 - j)]);
    let mut hw = Mat::<f64>::zeros(l, k_max);
    matmul(
        hw.as_mut(),
        Accum::Replace,
        h.as_ref(),
        w.as_ref(),
        1.0,
        par,
    );
    let captured: Vec<f64> = (0..k_max)
        .map(|j| (0..l).map(|i| w[(i, j)] * hw[(i, j)]).sum())
        .collect();
    let mut basis = Mat::<f64>::zeros(m, k_max);
    matmul(
        basis.as_mut(),
        Accum::Replace,
        q.as_ref(),
        w.as_ref(),
        1.0,
        par,
    );
    let points = ranks
        .iter()
        .map(|&k| {
            let kept: f64 = captured[..k].iter().sum();
            point(k, relative(norm2 - kept, norm2))
        })
        .collect();
    Ok((points, basis))
}

/// An orthonormal basis (f64) of the column space of `z` by Householder QR.
fn orthonormal_columns(z: &Mat<f32>) -> Mat<f64> {
    let z64 = Mat::<f64>::from_fn(z.nrows(), z.ncols(), |i, j| z[(i, j)] as f64);
    z64.as_ref().qr().compute_thin_Q()
}

/// splitmix64 (Steele, Lea and Flood 2014).
struct SplitMix64(u64);

impl SplitMix64 {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        mix64(self.0)
    }

    /// Uniform in the open interval (0, 1).
    fn uniform(&mut self) -> f64 {
        ((self.next_u64() >> 11) as f64 + 0.5) * (1.0 / (1u64 << 53) as f64)
    }

    /// Two independent standard normal numbers (Box–Muller).
    fn gaussian_pair(&mut self) -> [f64; 2] {
        let r = (-2.0 * self.uniform().ln()).sqrt();
        let (s, c) = (2.0 * PI * self.uniform()).sin_cos();
        [r * c, r * s]
    }
}

fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Row `row` of the Gaussian sketch matrix: a function of `(seed, row)`
/// only, so the sketch does not depend on how rows are split into blocks.
fn gaussian_row(seed: u64, row: usize, out: &mut [f32]) {
    let mut rng = SplitMix64(mix64(seed ^ mix64(row as u64 ^ 0x6A09_E667_F3BC_C909)));
    for pair in out.chunks_mut(2) {
        let g = rng.gaussian_pair();
        for (o, v) in pair.iter_mut().zip(g) {
            *o = v as f32;
        }
    }
}

// ---------------------------------------------------------------------------
// Spherical harmonics

/// Real orthonormal spherical harmonics of bands `l < order` at the unit
/// direction `d = (x, y, z)`, polar axis `z`, into `out[l² + l + m]`
/// (`order²` values):
/// `Y_l0 = N_l0·P_l^0(z)`, `Y_lm = √2·N_lm·P_l^m(z)·cos(mφ)` and
/// `Y_l,−m = √2·N_lm·P_l^m(z)·sin(mφ)` for `m > 0`, with
/// `N_lm = √((2l+1)/(4π)·(l−m)!/(l+m)!)` and no Condon–Shortley phase
/// (so `Y_11 = √(3/4π)·x`).
///
/// Evaluated with the stable recurrences of the normalised associated
/// Legendre functions, divided by `sin^m θ` (polynomials in `z`), times
/// `(x + iy)^m = sin^m θ·e^{imφ}`: exact at the poles, stable to high order.
fn sh_eval(order: usize, d: [f64; 3], out: &mut [f64]) {
    let [x, y, z] = d;
    let sqrt2 = std::f64::consts::SQRT_2;
    // Q_m^m = N_mm·P_m^m / sin^m θ, and (cm, sm) = (x + iy)^m.
    let mut qmm = (0.25 / PI).sqrt();
    let (mut cm, mut sm) = (1.0f64, 0.0f64);
    for m in 0..order {
        if m > 0 {
            let mf = m as f64;
            qmm *= ((2.0 * mf + 1.0) / (2.0 * mf)).sqrt();
            (cm, sm) = (cm * x - sm * y, cm * y + sm * x);
        }
        let mut store = |l: usize, q: f64| {
            let i = l * l + l;
            if m == 0 {
                out[i] = q;
            } else {
                out[i + m] = sqrt2 * q * cm;
                out[i - m] = sqrt2 * q * sm;
            }
        };
        store(m, qmm);
        if m + 1 < order {
            let mut prev2 = qmm;
            let mut prev = z * (2.0 * m as f64 + 3.0).sqrt() * qmm;
            store(m + 1, prev);
            let m2 = (m * m) as f64;
            for l in m + 2..order {
                let lf = l as f64;
                let a = ((4.0 * lf * lf - 1.0) / (lf * lf - m2)).sqrt();
                let b =
                    (((lf - 1.0) * (lf - 1.0) - m2) / (4.0 * (lf - 1.0) * (lf - 1.0) - 1.0)).sqrt();
                let q = a * (z * prev - b * prev2);
                store(l, q);
                (prev2, prev) = (prev, q);
            }
        }
    }
}

/// Direction of the centre of texel `j` (f64).
fn texel_centre(n: usize, j: usize) -> [f64; 3] {
    let (face, row, col) = cubemap::texel_coords(n, j);
    let nf = n as f64;
    let d = cubemap::face_point_direction(face, (col as f64 + 0.5) / nf, (row as f64 + 0.5) / nf);
    [d.x, d.y, d.z]
}

/// The SH basis at the texel centres, `Y[j, a]` (`M × order²`), and the
/// texel solid angles `dω_j`.
fn sh_basis(n: usize, order: usize) -> (Mat<f64>, Vec<f64>) {
    let m = cubemap::texel_count(n);
    let k = order * order;
    let mut rows = vec![0.0f64; m * k];
    if k > 0 {
        rows.par_chunks_mut(k)
            .enumerate()
            .for_each(|(j, out)| sh_eval(order, texel_centre(n, j), out));
    }
    let y = Mat::from_fn(m, k, |j, a| rows[j * k + a]);
    let dw = (0..m).map(|j| cubemap::texel_solid_angle(n, j)).collect();
    (y, dw)
}

/// The spherical-harmonics projection of every row of a raw store, up to
/// the largest order asked for: what [`ShProjection::points`] reports and
/// [`ShProjection::relight`] relights with.
pub struct ShProjection {
    dims: Dims,
    max_order: usize,
    /// `f_lm` of each row (pixel, channel), `max_order²` per row.
    coefficients: Vec<f64>,
    /// `Y_a(ω_j)·dω_j`, `M` values per coefficient `a`.
    weighted_basis: Vec<f64>,
    albedo: Option<Vec<f32>>,
    points: Vec<BaselinePoint>,
}

/// Spherical-harmonics projection of each row (Sloan et al. 2002, as
/// compared in Ng et al. 2003). Per texel `j`, `T[p, j] = f_p(ω_j)·dω_j`, so
/// `f_lm = Σ_j T[p, j]·Y_lm(ω_j)` and the reconstruction is
/// `T̂[p, j] = Σ_{l<L, m} f_lm·Y_lm(ω_j)·dω_j`, `ω_j` the texel centre and
/// `dω_j` the exact texel solid angle. The size of order `L` is
/// `L²·P·C·4` bytes; its error `‖T − T̂_L‖_F / ‖T‖_F` is exact in f64, from
/// `F = T·Y` and `G = T·W·Y` (`W = diag(dω)`):
/// `‖t − t̂‖² = ‖t‖² − 2·f·g + fᵀ·(YᵀW²Y)·f` over the first `L²` coefficients.
/// Orders are sorted and deduplicated; at most [`MAX_SH_ORDER`].
pub fn sh(raw: &RawStore, orders: &[usize]) -> Result<ShProjection> {
    sh_with(raw, orders, CHUNK_VALUES)
}

fn sh_with(raw: &RawStore, orders: &[usize], chunk_values: usize) -> Result<ShProjection> {
    let dims = raw.dims();
    let mut orders = orders.to_vec();
    orders.sort_unstable();
    orders.dedup();
    let max_order = orders.last().copied().unwrap_or(0);
    ensure!(
        max_order <= MAX_SH_ORDER,
        "spherical-harmonics order {max_order} is too large (at most {MAX_SH_ORDER})"
    );
    let (n, m) = (dims.face_res() as usize, dims.lights());
    let channels = dims.channels as usize;
    let n_rows = dims.pixels() * channels;
    let k = max_order * max_order;
    let par = Par::rayon(0);

    let (y, dw) = sh_basis(n, max_order);
    // [Y | W·Y], M × 2K.
    let yw = Mat::<f64>::from_fn(m, 2 * k, |j, a| {
        if a < k {
            y[(j, a)]
        } else {
            dw[j] * y[(j, a - k)]
        }
    });
    // S = (WY)ᵀ(WY); its strictly lower part gives z_a = Σ_{b<a} S_ab f_b.
    let mut s = Mat::<f64>::zeros(k, k);
    let wy = yw.as_ref().subcols(k, k);
    matmul(s.as_mut(), Accum::Replace, wy.transpose(), wy, 1.0, par);
    let s_lower = Mat::<f64>::from_fn(k, k, |a, b| if b < a { s[(a, b)] } else { 0.0 });
    let s_diag: Vec<f64> = (0..k).map(|a| s[(a, a)]).collect();

    let mut coefficients = vec![0.0f64; n_rows * k];
    // err2[o] for each order, then ‖T‖².
    let mut sums = vec![0.0f64; orders.len() + 1];
    let mut buf: Vec<f64> = Vec::new();
    for_each_block(raw, chunk_values, true, &mut buf, |blk| {
        let r = blk.rows.len();
        // (F | G)ᵀ = [Y | WY]ᵀ·Aᵀ (2K × R): row i's f and g are contiguous.
        let mut fgt = Mat::<f64>::zeros(2 * k, r);
        let mut zt = Mat::<f64>::zeros(k, r);
        if k > 0 {
            matmul(
                fgt.as_mut(),
                Accum::Replace,
                yw.transpose(),
                blk.at(),
                1.0,
                par,
            );
            matmul(
                zt.as_mut(),
                Accum::Replace,
                s_lower.as_ref(),
                fgt.as_ref().subrows(0, k),
                1.0,
                par,
            );
        }
        let block_sums = (0..r)
            .into_par_iter()
            .fold(
                || vec![0.0f64; orders.len() + 1],
                |mut acc, i| {
                    let t = blk.row(i);
                    let tn: f64 = t.iter().map(|v| v * v).sum();
                    let fg = fgt
                        .col(i)
                        .try_as_col_major()
                        .expect("column-major")
                        .as_slice();
                    let zc = zt
                        .col(i)
                        .try_as_col_major()
                        .expect("column-major")
                        .as_slice();
                    let (f, g) = fg.split_at(k);
                    let (mut quad, mut dot, mut a) = (0.0f64, 0.0f64, 0usize);
                    for (o, &order) in orders.iter().enumerate() {
                        while a < order * order {
                            quad += f[a] * (2.0 * zc[a] + s_diag[a] * f[a]);
                            dot += f[a] * g[a];
                            a += 1;
                        }
                        acc[o] += tn - 2.0 * dot + quad;
                    }
                    acc[orders.len()] += tn;
                    acc
                },
            )
            .reduce(
                || vec![0.0f64; orders.len() + 1],
                |mut a, b| {
                    a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
                    a
                },
            );
        sums.iter_mut().zip(block_sums).for_each(|(x, y)| *x += y);
        if k > 0 {
            for (i, &row) in blk.rows.iter().enumerate() {
                let f = &fgt
                    .col(i)
                    .try_as_col_major()
                    .expect("column-major")
                    .as_slice()[..k];
                coefficients[row * k..(row + 1) * k].copy_from_slice(f);
            }
        }
        Ok(())
    })?;

    let norm2 = sums[orders.len()];
    let points = orders
        .iter()
        .zip(&sums)
        .map(|(&order, &err2)| BaselinePoint {
            method: "sh".into(),
            param: order,
            bytes: (order * order) as u64 * n_rows as u64 * 4,
            matrix_error: relative(err2, norm2),
        })
        .collect();
    let mut weighted_basis = vec![0.0f64; k * m];
    for a in 0..k {
        for j in 0..m {
            weighted_basis[a * m + j] = y[(j, a)] * dw[j];
        }
    }
    Ok(ShProjection {
        dims,
        max_order,
        coefficients,
        weighted_basis,
        albedo: raw.albedo().map(<[f32]>::to_vec),
        points,
    })
}

impl ShProjection {
    /// One point per order asked for, in increasing order.
    pub fn points(&self) -> Vec<BaselinePoint> {
        self.points.clone()
    }

    /// The largest order asked for (coefficients are kept up to it).
    pub fn max_order(&self) -> usize {
        self.max_order
    }

    /// The relit image of order `order` (at most [`Self::max_order`]) under
    /// cubemap lighting `light` (`6·n²` entries, mean radiance per texel, as
    /// for `ltm_relight::reference`): `B̂ = Σ_lm f_lm·L_lm` with
    /// `L_lm = Σ_j L_j·Y_lm(ω_j)·dω_j`, which equals `T̂·L`. Grey stores
    /// multiply each light channel, then the albedo image if there is one.
    /// Accumulated in f64.
    pub fn relight(&self, light: &[[f32; 3]], order: usize) -> Result<Image> {
        let dims = self.dims;
        let m = dims.lights();
        ensure!(
            order <= self.max_order(),
            "spherical-harmonics order {order} was not computed (at most {})",
            self.max_order()
        );
        ensure!(
            light.len() == m,
            "lighting has {} texels; the store needs 6·n² = {m} (n = {})",
            light.len(),
            dims.face_res()
        );
        if let Some(j) = light.iter().position(|l| l.iter().any(|v| !v.is_finite())) {
            return Err(anyhow!(
                "lighting texel {j} is {:?}; values must be finite",
                light[j]
            ));
        }
        let k = order * order;
        let kk = self.max_order * self.max_order;
        let lighting: Vec<[f64; 3]> = (0..k)
            .into_par_iter()
            .map(|a| {
                let wb = &self.weighted_basis[a * m..(a + 1) * m];
                let mut acc = [0.0f64; 3];
                for (w, l) in wb.iter().zip(light) {
                    for c in 0..3 {
                        acc[c] += w * l[c] as f64;
                    }
                }
                acc
            })
            .collect();
        let channels = dims.channels as usize;
        let data: Vec<[f32; 3]> = (0..dims.pixels())
            .into_par_iter()
            .map(|p| {
                let mut out = [0.0f64; 3];
                for (c, o) in out.iter_mut().enumerate() {
                    let row = if channels == 3 { 3 * p + c } else { p };
                    let f = &self.coefficients[row * kk..row * kk + k];
                    *o = f.iter().zip(&lighting).map(|(f, l)| f * l[c]).sum();
                }
                if let Some(a) = &self.albedo {
                    for c in 0..3 {
                        out[c] *= a[3 * p + c] as f64;
                    }
                }
                out.map(|v| v as f32)
            })
            .collect();
        let image = Image::from_data(dims.width() as usize, dims.height() as usize, data)?;
        if let Some((x, y)) = image.first_non_finite() {
            return Err(anyhow!(
                "SH relit pixel ({x}, {y}) is not finite (exceeds the f32 range)"
            ));
        }
        Ok(image)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ltm_codec::{RawHeader, RawWriter};
    use std::path::{Path, PathBuf};

    /// Writes a raw store of `t` (P·M·C values) in blocks of `block_pixels`
    /// rows, with an albedo image when given.
    fn write_raw(
        dir: &Path,
        name: &str,
        dims: Dims,
        t: &[f32],
        albedo: Option<&[f32]>,
        block_pixels: usize,
    ) -> PathBuf {
        let header = RawHeader::new(
            dims,
            albedo.is_some(),
            (block_pixels * dims.row_len() * 4) as u64,
        );
        RawWriter::write_dense(&dir.join(name), header, t, albedo).unwrap()
    }

    fn dims(width: u32, height: u32, face_res: u32, channels: u32) -> Dims {
        Dims::image(width, height, face_res, channels)
    }

    /// The store as a dense matrix, rows (pixel, channel), f64.
    fn dense(raw: &RawStore) -> Mat<f64> {
        let d = raw.dims();
        let c = d.channels as usize;
        Mat::from_fn(d.pixels() * c, d.lights(), |r, j| {
            raw.row(r / c)[j * c + r % c] as f64
        })
    }

    fn frobenius2(a: MatRef<'_, f64>) -> f64 {
        let mut s = 0.0;
        for j in 0..a.ncols() {
            for i in 0..a.nrows() {
                s += a[(i, j)] * a[(i, j)];
            }
        }
        s
    }

    fn normalize(d: [f64; 3]) -> [f64; 3] {
        let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        d.map(|v| v / n)
    }

    fn test_directions() -> Vec<[f64; 3]> {
        vec![
            normalize([0.3, -0.5, 0.81]),
            normalize([-0.7, 0.2, -0.1]),
            normalize([0.0, 0.0, 1.0]),
            normalize([0.0, 0.0, -1.0]),
            normalize([1.0, 1.0, 1.0]),
            normalize([0.12, 0.95, -0.4]),
        ]
    }

    #[test]
    fn sh_closed_form_bands_0_to_2() {
        let c0 = 0.5 / PI.sqrt();
        let c1 = (3.0 / (4.0 * PI)).sqrt();
        let c2 = 0.5 * (15.0 / PI).sqrt();
        let c20 = 0.25 * (5.0 / PI).sqrt();
        let c22 = 0.25 * (15.0 / PI).sqrt();
        for d in test_directions() {
            let [x, y, z] = d;
            let want = [
                c0,
                c1 * y,
                c1 * z,
                c1 * x,
                c2 * x * y,
                c2 * y * z,
                c20 * (3.0 * z * z - 1.0),
                c2 * x * z,
                c22 * (x * x - y * y),
            ];
            let mut got = [0.0; 9];
            sh_eval(3, d, &mut got);
            for (a, (g, w)) in got.iter().zip(want).enumerate() {
                assert!((g - w).abs() < 1e-14, "Y[{a}] at {d:?}: {g} vs {w}");
            }
        }
    }

    /// `P_l^m(x)` without the Condon–Shortley phase, from the explicit sum
    /// for `P_l` differentiated `m` times.
    fn legendre_explicit(l: usize, m: usize, x: f64) -> f64 {
        let fact = |n: usize| (1..=n).map(|v| v as f64).product::<f64>();
        let binom = |n: usize, k: usize| fact(n) / (fact(k) * fact(n - k));
        let mut sum = 0.0;
        for k in 0..=l / 2 {
            let power = l - 2 * k;
            if power < m {
                continue;
            }
            let coef = binom(l, k) * binom(2 * l - 2 * k, l) * fact(power) / fact(power - m);
            let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
            sum += sign * coef * x.powi((power - m) as i32);
        }
        sum / 2f64.powi(l as i32) * (1.0 - x * x).powf(m as f64 / 2.0)
    }

    #[test]
    fn sh_matches_explicit_legendre_formula_to_order_13() {
        let order = 13;
        let fact = |n: usize| (1..=n).map(|v| v as f64).product::<f64>();
        for d in test_directions() {
            let mut got = vec![0.0; order * order];
            sh_eval(order, d, &mut got);
            let phi = d[1].atan2(d[0]);
            for l in 0..order {
                for m in 0..=l {
                    let norm = ((2 * l + 1) as f64 / (4.0 * PI) * fact(l - m) / fact(l + m)).sqrt();
                    let p = norm * legendre_explicit(l, m, d[2]);
                    let i = l * l + l;
                    let (want_c, want_s) = if m == 0 {
                        (p, 0.0)
                    } else {
                        let s2 = std::f64::consts::SQRT_2;
                        (
                            s2 * p * (m as f64 * phi).cos(),
                            s2 * p * (m as f64 * phi).sin(),
                        )
                    };
                    assert!(
                        (got[i + m] - want_c).abs() < 1e-9,
                        "l={l} m={m} at {d:?}: {} vs {want_c}",
                        got[i + m]
                    );
                    if m > 0 {
                        assert!(
                            (got[i - m] - want_s).abs() < 1e-9,
                            "l={l} m=-{m} at {d:?}: {} vs {want_s}",
                            got[i - m]
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn sh_basis_orthonormal_on_fine_cubemap() {
        let (y, dw) = sh_basis(64, 8);
        assert!((dw.iter().sum::<f64>() - 4.0 * PI).abs() < 1e-9);
        let k = y.ncols();
        let mut worst = 0.0f64;
        for a in 0..k {
            for b in 0..k {
                let g: f64 = (0..y.nrows()).map(|j| y[(j, a)] * y[(j, b)] * dw[j]).sum();
                let want = if a == b { 1.0 } else { 0.0 };
                worst = worst.max((g - want).abs());
            }
        }
        println!("largest deviation of the discrete Gram matrix from I: {worst:.2e}");
        assert!(worst < 1e-3, "largest deviation from the identity {worst}");
        // High orders stay finite and bounded (|Y_lm| ≤ √((2l+1)/4π)).
        let (y, _) = sh_basis(8, 40);
        for a in 0..y.ncols() {
            let l = (a as f64).sqrt().floor();
            let bound = ((2.0 * l + 1.0) / (4.0 * PI)).sqrt() * std::f64::consts::SQRT_2 + 1e-9;
            for j in 0..y.nrows() {
                assert!(
                    y[(j, a)].abs() <= bound,
                    "Y[{a}] = {} at texel {j}",
                    y[(j, a)]
                );
            }
        }
    }

    #[test]
    fn sh_row_of_order_4_projects_exactly_at_order_4() {
        let dir = tempfile::tempdir().unwrap();
        let d = dims(2, 1, 32, 1);
        let m = d.lights();
        let mut rng = SplitMix64(11);
        let coef: Vec<f64> = (0..16).map(|_| rng.gaussian_pair()[0]).collect();
        let mut t = vec![0.0f32; 2 * m];
        let mut yv = vec![0.0; 16];
        for (j, v) in t[..m].iter_mut().enumerate() {
            sh_eval(4, texel_centre(32, j), &mut yv);
            let f: f64 = coef.iter().zip(&yv).map(|(c, y)| c * y).sum();
            *v = (f * cubemap::texel_solid_angle(32, j)) as f32;
        }
        // Pixel 1 stays zero.
        let raw = RawStore::open(&write_raw(dir.path(), "t.raw", d, &t, None, 1)).unwrap();
        let proj = sh(&raw, &[6, 1, 2, 3, 4, 5]).unwrap();
        let e: Vec<f64> = proj.points().iter().map(|p| p.matrix_error).collect();
        println!("errors by order 1..=6: {e:?}");
        assert_eq!(
            proj.points().iter().map(|p| p.param).collect::<Vec<_>>(),
            vec![1, 2, 3, 4, 5, 6]
        );
        for (o, &err) in e.iter().enumerate() {
            if o + 1 >= 4 {
                assert!(err < 1e-3, "order {}: error {err}", o + 1);
            } else {
                assert!(err > 0.1, "order {}: error {err}", o + 1);
            }
        }
    }

    /// A deterministic random matrix with every third pixel zero.
    fn random_matrix(d: Dims, seed: u64) -> Vec<f32> {
        let mut rng = SplitMix64(seed);
        let row = d.row_len();
        let mut t = vec![0.0f32; d.pixels() * row];
        for p in (0..d.pixels()).filter(|p| p % 3 != 1) {
            for v in &mut t[p * row..(p + 1) * row] {
                *v = (rng.uniform() * 1e-2 + 1e-3 * rng.gaussian_pair()[0]) as f32;
            }
        }
        t
    }

    /// The coefficients `F = T·Y` and the reconstruction `T̂_L` of a dense
    /// matrix, computed directly.
    fn dense_sh(a: &Mat<f64>, n: usize, order: usize, max_order: usize) -> (Mat<f64>, Mat<f64>) {
        let m = a.ncols();
        let k = max_order * max_order;
        let mut y = Mat::<f64>::zeros(m, k);
        let mut v = vec![0.0; k];
        for j in 0..m {
            sh_eval(max_order, texel_centre(n, j), &mut v);
            for b in 0..k {
                y[(j, b)] = v[b];
            }
        }
        let f = Mat::from_fn(a.nrows(), k, |r, b| {
            (0..m).map(|j| a[(r, j)] * y[(j, b)]).sum()
        });
        let kl = order * order;
        let recon = Mat::from_fn(a.nrows(), m, |r, j| {
            (0..kl).map(|b| f[(r, b)] * y[(j, b)]).sum::<f64>() * cubemap::texel_solid_angle(n, j)
        });
        (f, recon)
    }

    #[test]
    fn sh_error_matches_explicit_reconstruction() {
        let dir = tempfile::tempdir().unwrap();
        let d = dims(6, 5, 4, 3);
        let t = random_matrix(d, 3);
        let raw = RawStore::open(&write_raw(dir.path(), "t.raw", d, &t, None, 4)).unwrap();
        let orders = [0, 1, 2, 3, 5];
        // Small chunks: several blocks of rows per pass.
        let proj = sh_with(&raw, &orders, 1000).unwrap();
        let a = dense(&raw);
        let norm2 = frobenius2(a.as_ref());
        for (point, &order) in proj.points().iter().zip(&orders) {
            let (_, recon) = dense_sh(&a, 4, order, 5);
            let diff = Mat::from_fn(a.nrows(), a.ncols(), |i, j| a[(i, j)] - recon[(i, j)]);
            let want = (frobenius2(diff.as_ref()) / norm2).sqrt();
            assert_eq!(point.method, "sh");
            assert_eq!(point.param, order);
            assert_eq!(point.bytes, (order * order * d.pixels() * 3 * 4) as u64);
            assert!(
                (point.matrix_error - want).abs() <= 1e-9 * want.max(1e-3),
                "order {order}: {} vs explicit {want}",
                point.matrix_error
            );
        }
        assert!((proj.points()[0].matrix_error - 1.0).abs() < 1e-12);
        assert!(proj.points()[4].matrix_error < proj.points()[1].matrix_error);
    }

    /// Relights at every order up to 4 and compares with `T̂_L·L` formed
    /// densely.
    fn check_relight(d: Dims, albedo: Option<Vec<f32>>) {
        let dir = tempfile::tempdir().unwrap();
        let t = random_matrix(d, 5);
        let raw =
            RawStore::open(&write_raw(dir.path(), "t.raw", d, &t, albedo.as_deref(), 3)).unwrap();
        let proj = sh_with(&raw, &[2, 4], 700).unwrap();
        let n = d.face_res() as usize;
        let c = d.channels as usize;
        let mut rng = SplitMix64(9);
        let light: Vec<[f32; 3]> = (0..d.lights())
            .map(|_| [0, 1, 2].map(|_| (rng.uniform() * 3.0) as f32))
            .collect();
        let a = dense(&raw);
        for order in 0..=4 {
            let (_, recon) = dense_sh(&a, n, order, 4);
            let img = proj.relight(&light, order).unwrap();
            let mut scale = 0.0f64;
            let mut want = vec![[0.0f64; 3]; d.pixels()];
            for (p, w) in want.iter_mut().enumerate() {
                for (ch, v) in w.iter_mut().enumerate() {
                    let r = if c == 3 { 3 * p + ch } else { p };
                    *v = (0..d.lights())
                        .map(|j| recon[(r, j)] * light[j][ch] as f64)
                        .sum();
                    if let Some(al) = &albedo {
                        *v *= al[3 * p + ch] as f64;
                    }
                    scale = scale.max(v.abs());
                }
            }
            assert!(order == 0 || scale > 0.0);
            for (p, (got, w)) in img.data.iter().zip(&want).enumerate() {
                for ch in 0..3 {
                    assert!(
                        (got[ch] as f64 - w[ch]).abs() <= 1e-6 * scale + 1e-30,
                        "order {order} pixel {p} channel {ch}: {} vs {}",
                        got[ch],
                        w[ch]
                    );
                }
            }
        }
        assert!(proj.relight(&light, 5).is_err());
        assert!(proj.relight(&light[1..], 2).is_err());
    }

    #[test]
    fn sh_relight_matches_dense_product_rgb() {
        check_relight(dims(5, 4, 4, 3), None);
    }

    #[test]
    fn sh_relight_matches_dense_product_grey_albedo() {
        let d = dims(5, 4, 4, 1);
        let albedo: Vec<f32> = (0..3 * d.pixels())
            .map(|i| 0.2 + 0.03 * (i % 17) as f32)
            .collect();
        check_relight(d, Some(albedo));
    }

    /// A rank-5 matrix with decaying singular values, plus Gaussian noise of
    /// Frobenius norm about `noise`; every seventh pixel is zero.
    fn low_rank_matrix(d: Dims, noise: f64) -> Vec<f32> {
        let (p, m, c) = (d.pixels(), d.lights(), d.channels as usize);
        let n = p * c;
        let mut rng = SplitMix64(21);
        let s = [1.0, 0.5, 0.25, 0.12, 0.06];
        let u: Vec<Vec<f64>> = s
            .iter()
            .map(|_| {
                (0..n)
                    .map(|_| rng.gaussian_pair()[0] / (n as f64).sqrt())
                    .collect()
            })
            .collect();
        let v: Vec<Vec<f64>> = s
            .iter()
            .map(|_| {
                (0..m)
                    .map(|_| rng.gaussian_pair()[0] / (m as f64).sqrt())
                    .collect()
            })
            .collect();
        let mut t = vec![0.0f32; p * m * c];
        let sigma = noise / ((n * m) as f64).sqrt();
        for px in (0..p).filter(|px| px % 7 != 3) {
            for ch in 0..c {
                let r = px * c + ch;
                for j in 0..m {
                    let x: f64 = (0..5).map(|i| s[i] * u[i][r] * v[i][j]).sum();
                    t[(px * m + j) * c + ch] = (x + sigma * rng.gaussian_pair()[0]) as f32;
                }
            }
        }
        t
    }

    #[test]
    fn pca_matches_exact_svd_on_low_rank_matrix() {
        let dir = tempfile::tempdir().unwrap();
        let d = dims(16, 12, 4, 3);
        let noise = 1e-3;
        let t = low_rank_matrix(d, noise);
        let raw = RawStore::open(&write_raw(dir.path(), "t.raw", d, &t, None, 10)).unwrap();
        let ranks = [8, 1, 2, 3, 4, 5, 6, 16];
        let (points, basis) = pca_fit(&raw, &ranks, 1234, 2000).unwrap();
        let a = dense(&raw);
        let norm2 = frobenius2(a.as_ref());
        let sv = a.as_ref().singular_values().unwrap();
        let noise_rel = noise / norm2.sqrt();
        let mut prev = f64::INFINITY;
        let n_rows = d.pixels() * 3;
        for p in &points {
            let k = p.param;
            let exact = (sv[k..].iter().map(|s| s * s).sum::<f64>() / norm2).sqrt();
            println!("rank {k}: {} (exact {exact})", p.matrix_error);
            assert_eq!(p.method, "pca");
            assert_eq!(p.bytes, (k * (n_rows + d.lights()) * 4) as u64);
            assert!(p.matrix_error < prev, "error must decrease with the rank");
            prev = p.matrix_error;
            assert!(
                p.matrix_error >= exact * (1.0 - 1e-9) && p.matrix_error <= exact * 1.03,
                "rank {k}: {} vs optimal {exact}",
                p.matrix_error
            );
            if k >= 5 {
                assert!(
                    p.matrix_error < 1.5 * noise_rel,
                    "rank {k}: {}",
                    p.matrix_error
                );
            } else {
                assert!(
                    p.matrix_error > 10.0 * noise_rel,
                    "rank {k}: {}",
                    p.matrix_error
                );
            }
        }
        assert_eq!(
            points.iter().map(|p| p.param).collect::<Vec<_>>(),
            vec![1, 2, 3, 4, 5, 6, 8, 16]
        );

        // The shortcut equals the error of the explicit reconstruction
        // A·V_k·V_kᵀ, and V is orthonormal.
        let v = &basis;
        assert_eq!((v.nrows(), v.ncols()), (d.lights(), 16));
        let mut vtv = Mat::<f64>::zeros(16, 16);
        matmul(
            vtv.as_mut(),
            Accum::Replace,
            v.transpose(),
            v.as_ref(),
            1.0,
            Par::Seq,
        );
        for i in 0..16 {
            for j in 0..16 {
                let want = if i == j { 1.0 } else { 0.0 };
                assert!((vtv[(i, j)] - want).abs() < 1e-12);
            }
        }
        for p in &points {
            let vk = v.as_ref().subcols(0, p.param);
            let mut c = Mat::<f64>::zeros(a.nrows(), p.param);
            matmul(c.as_mut(), Accum::Replace, a.as_ref(), vk, 1.0, Par::Seq);
            let mut diff = a.clone();
            matmul(
                diff.as_mut(),
                Accum::Add,
                c.as_ref(),
                vk.transpose(),
                -1.0,
                Par::Seq,
            );
            let explicit = (frobenius2(diff.as_ref()) / norm2).sqrt();
            assert!(
                (p.matrix_error - explicit).abs() <= 1e-6 * explicit,
                "rank {}: shortcut {} vs explicit {explicit}",
                p.param,
                p.matrix_error
            );
        }
    }

    #[test]
    fn pca_ranks_sorted_clamped_and_full_rank_exact() {
        let dir = tempfile::tempdir().unwrap();
        let d = dims(4, 3, 2, 1); // 12 rows, 24 lights
        let t = random_matrix(d, 8);
        let raw = RawStore::open(&write_raw(dir.path(), "t.raw", d, &t, None, 5)).unwrap();
        let points = pca(&raw, &[300, 2, 1, 2, 0], 7).unwrap();
        let params: Vec<usize> = points.iter().map(|p| p.param).collect();
        assert_eq!(params, vec![0, 1, 2, 12]);
        assert!((points[0].matrix_error - 1.0).abs() < 1e-12);
        assert!(points[3].matrix_error < 1e-6, "{}", points[3].matrix_error);
        assert!(pca(&raw, &[], 7).unwrap().is_empty());

        // An all-zero store.
        let zero = vec![0.0f32; t.len()];
        let raw0 = RawStore::open(&write_raw(dir.path(), "z.raw", d, &zero, None, 5)).unwrap();
        let points = pca(&raw0, &[1, 4], 7).unwrap();
        assert!(points.iter().all(|p| p.matrix_error == 0.0));
    }

    #[test]
    fn zstd_round_trip_and_size() {
        let dir = tempfile::tempdir().unwrap();
        let d = dims(7, 5, 4, 3);
        let t: Vec<f32> = (0..d.pixels() * d.row_len())
            .map(|i| ((i % 113) as f32 * 0.05).sin() * 1e-3)
            .collect();
        let raw = RawStore::open(&write_raw(dir.path(), "t.raw", d, &t, None, 4)).unwrap();
        let want: Vec<u8> = raw
            .rows(0..d.pixels())
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        // Frames of 3 rows: several frames, concatenated.
        for frame_bytes in [3 * d.row_len() * 4, ZSTD_FRAME_BYTES] {
            let mut out = Vec::new();
            let n = zstd_raw_to(&raw, 3, frame_bytes, &mut out).unwrap();
            assert_eq!(n, out.len() as u64);
            assert_eq!(zstd::decode_all(&out[..]).unwrap(), want);
        }
        let mut out = Vec::new();
        zstd_raw_to(&raw, 3, ZSTD_FRAME_BYTES, &mut out).unwrap();
        let point = zstd_raw(&raw, 3).unwrap();
        assert_eq!(point.bytes, out.len() as u64);
        assert_eq!(
            (point.method.as_str(), point.param, point.matrix_error),
            ("zstd-raw", 0, 0.0)
        );
        assert!(point.bytes < want.len() as u64);
    }

    /// Timing on a real store (`LTM_BASELINE_RAW`, default
    /// /tmp/e2e/default128.raw): `cargo test --release -p ltm-tools --bin ltm
    /// report::baselines -- --ignored --nocapture`.
    #[test]
    #[ignore]
    fn timing_on_store() {
        let path = std::env::var("LTM_BASELINE_RAW").unwrap_or("/tmp/e2e/default128.raw".into());
        let raw = RawStore::open(Path::new(&path)).unwrap();
        println!(
            "{path}: {:?}, {} threads",
            raw.dims(),
            rayon::current_num_threads()
        );
        let t0 = std::time::Instant::now();
        let z = zstd_raw(&raw, 3).unwrap();
        println!(
            "zstd-raw level 3: {:.2} s, {z:?}",
            t0.elapsed().as_secs_f64()
        );
        let t0 = std::time::Instant::now();
        let points = pca(&raw, &[1, 2, 4, 8, 16, 32, 64, 128, 256], 1).unwrap();
        println!("pca: {:.2} s", t0.elapsed().as_secs_f64());
        for p in &points {
            println!("  {p:?}");
        }
        let t0 = std::time::Instant::now();
        let proj = sh(&raw, &(2..=20).collect::<Vec<_>>()).unwrap();
        println!("sh: {:.2} s", t0.elapsed().as_secs_f64());
        for p in proj.points() {
            println!("  {p:?}");
        }
        let light = vec![[1.0f32; 3]; raw.dims().lights()];
        let t0 = std::time::Instant::now();
        let img = proj.relight(&light, 20).unwrap();
        let seconds = t0.elapsed().as_secs_f64();
        let reference = ltm_relight::reference(&raw, &light).unwrap();
        println!(
            "sh relight order 20: {seconds:.3} s, image error under uniform light {:.4}",
            ltm_relight::relative_l2(&img, &reference).unwrap()
        );
    }

    /// The randomized PCA errors against the exact ones (eigenvalues of the
    /// dense Gram matrix AᵀA) on a real store with few lights
    /// (`LTM_BASELINE_RAW`, default /tmp/e2e/default128.raw).
    #[test]
    #[ignore]
    fn pca_against_exact_on_store() {
        let path = std::env::var("LTM_BASELINE_RAW").unwrap_or("/tmp/e2e/default128.raw".into());
        let raw = RawStore::open(Path::new(&path)).unwrap();
        let m = raw.dims().lights();
        assert!(m <= 6144, "the dense Gram matrix needs few lights");
        let mut gram = Mat::<f64>::zeros(m, m);
        let mut norm2 = 0.0;
        let mut buf: Vec<f64> = Vec::new();
        for_each_block(&raw, CHUNK_VALUES, false, &mut buf, |blk| {
            norm2 += block_norm2(blk.data);
            matmul(
                gram.as_mut(),
                Accum::Add,
                blk.at(),
                blk.a(),
                1.0,
                Par::rayon(0),
            );
            Ok(())
        })
        .unwrap();
        let mut eig = gram.as_ref().self_adjoint_eigenvalues(Side::Lower).unwrap();
        eig.reverse();
        let ranks = [1, 2, 4, 8, 16, 32, 64, 128, 256];
        let points = pca(&raw, &ranks, 1).unwrap();
        for p in &points {
            let exact = (eig[p.param..].iter().sum::<f64>().max(0.0) / norm2).sqrt();
            println!(
                "rank {:4}: randomized {:.6}, exact {exact:.6}, ratio {:.5}",
                p.param,
                p.matrix_error,
                p.matrix_error / exact
            );
            assert!(p.matrix_error >= exact * (1.0 - 1e-6));
            assert!(p.matrix_error <= exact * 1.05);
        }
    }
}
