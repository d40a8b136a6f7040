//! Principal components of the transport rows: the light basis of
//! Eigentransport (Nowrouzezahrai, Simari, Kalogerakis and Fiume 2007,
//! "Eigentransport for efficient and accurate all-frequency relighting"),
//! in which the principal components of the transport functions form an
//! orthonormal light basis shared by every pixel, a frame projects the
//! lighting on it once and each pixel is a short dot product.
//!
//! The fit is the best rank-`K` factorisation `T ≈ T·V·Vᵀ` of the matrix
//! itself (an uncentered PCA: Eigentransport's eq. 2 also subtracts the
//! mean transport row, which this fit does not). Rows are (pixel, channel)
//! pairs, so one light basis `V` (`M × K`) serves all channels. `V` comes
//! from the randomized SVD of Halko, Martinsson and Tropp 2011 ("Finding
//! structure with randomness", SIAM Review 53(2)): a Gaussian sketch of the
//! row space, power iterations with re-orthonormalisation and a
//! Rayleigh–Ritz step, each a pass over the raw store in blocks of rows
//! (never whole in memory); the last pass is in f64.

use super::rows::{relative, CHUNK_VALUES};
use crate::dims::Dims;
use crate::error::{Error, Result};
use crate::raw::RawStore;
use crate::rsvd::{block_norm2, for_each_block};
use crate::rsvd::{power_iterations, rayleigh_ritz, sketch, Rows, OVERSAMPLING};
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatRef, Par};

/// The salt of this fit's Gaussian sketch rows ([`crate::rsvd::gaussian_row`]).
const SKETCH_SALT: u64 = 0x6A09_E667_F3BC_C909;

/// The first `K` principal light vectors of a transport matrix (rows =
/// (pixel, channel) pairs, uncentered) and the error of every rank up to
/// `K`. See the module documentation of `baseline::pca`.
#[derive(Clone, Debug)]
pub struct PcaBasis {
    dims: Dims,
    rank: usize,
    /// Vector `i` is `vectors[i·M .. (i+1)·M]`.
    vectors: Vec<f64>,
    rank_errors: Vec<f64>,
}

impl PcaBasis {
    /// Fits the first `rank` principal light vectors of `raw` (clamped to
    /// `min(P·C, M)`) by a randomized SVD with a Gaussian sketch of width
    /// `rank + 10` drawn from `seed`, two power iterations and a
    /// Rayleigh–Ritz step: four passes over the store, whose block
    /// checksums are verified on the first. Rows flagged all zero are
    /// skipped. The same store, rank and seed give the same basis.
    pub fn fit(raw: &RawStore, rank: usize, seed: u64) -> Result<PcaBasis> {
        fit_with(raw, rank, seed, CHUNK_VALUES)
    }

    /// The dimensions of the matrix fitted.
    pub fn dims(&self) -> Dims {
        self.dims
    }

    /// `K`, the number of basis vectors.
    pub fn rank(&self) -> usize {
        self.rank
    }

    /// The orthonormal light vectors `v_i` by decreasing captured energy,
    /// `K × M` row-major: vector `i` is `vectors()[i·M .. (i+1)·M]`.
    pub fn vectors(&self) -> &[f64] {
        &self.vectors
    }

    /// The rank–error curve: entry `k` (`0 ≤ k ≤ K`) is the relative
    /// Frobenius error `‖T − T·V_k·V_kᵀ‖_F / ‖T‖_F` of the first `k`
    /// vectors, computed in f64 over the raw rows (0 for an all-zero
    /// matrix). Entry 0 is 1 and the curve does not increase.
    pub fn rank_errors(&self) -> &[f64] {
        &self.rank_errors
    }

    /// The coefficients `c_r = t_r·V` of every row `r = p·C + c` of `raw`
    /// (a store of the fitted dimensions) on the `K` vectors, `P·C × K`
    /// row-major, computed in f64 in one pass (checksums verified); rows
    /// flagged all zero get zero coefficients. `T ≈ C·Vᵀ`.
    pub fn coefficients(&self, raw: &RawStore) -> Result<Vec<f64>> {
        let dims = raw.dims();
        if dims != self.dims {
            return Err(Error::Invalid(format!(
                "PCA basis fitted to a {:?} matrix cannot project a {:?} store",
                self.dims, dims
            )));
        }
        let (m, k) = (dims.lights(), self.rank);
        let mut out = vec![0.0f64; dims.pixels() * dims.channels as usize * k];
        if k == 0 {
            return Ok(out);
        }
        let v = MatRef::from_column_major_slice(&self.vectors, m, k);
        let mut buf: Vec<f64> = Vec::new();
        for_each_block(raw, CHUNK_VALUES, true, &mut buf, |blk| {
            let mut c = Mat::<f64>::zeros(blk.rows.len(), k);
            matmul(c.as_mut(), Accum::Replace, blk.a(), v, 1.0, Par::rayon(0));
            for (i, &row) in blk.rows.iter().enumerate() {
                for (a, o) in out[row * k..(row + 1) * k].iter_mut().enumerate() {
                    *o = c[(i, a)];
                }
            }
            Ok(())
        })?;
        Ok(out)
    }
}

/// [`PcaBasis::fit`] with blocks of about `chunk_values` values: the
/// randomized SVD ([`crate::rsvd`]) of the uncentred rows.
fn fit_with(raw: &RawStore, rank: usize, seed: u64, chunk_values: usize) -> Result<PcaBasis> {
    let dims = raw.dims();
    let m = dims.lights();
    let full = (dims.pixels() * dims.channels as usize).min(m);
    let rank = rank.min(full);
    let l = (rank + OVERSAMPLING).min(full);
    let a = Rows::uncentred(raw, chunk_values);
    // The first pass verifies the store's checksums and sums `‖A‖²`.
    let mut norm2 = 0.0f64;
    let z = sketch(&a, l, (seed, SKETCH_SALT), true, |data| {
        norm2 += block_norm2(data)
    })?;
    if norm2 == 0.0 || l == 0 {
        return Ok(PcaBasis {
            dims,
            rank,
            vectors: vec![0.0; rank * m],
            rank_errors: vec![0.0; rank + 1],
        });
    }
    let q = power_iterations(&a, &z, norm2, |_| {})?;
    let ritz = rayleigh_ritz(&a, &q, rank, None)?;
    let norm2 = ritz.norm2;
    let mut kept = 0.0f64;
    let mut rank_errors = vec![relative(norm2, norm2)];
    for c in &ritz.captured {
        kept += c;
        rank_errors.push(relative(norm2 - kept, norm2));
    }
    // Column-major M × K is vector after vector.
    let vectors = (0..rank)
        .flat_map(|i| (0..m).map(move |j| (j, i)))
        .map(|ij| ritz.basis[ij])
        .collect();
    Ok(PcaBasis {
        dims,
        rank,
        vectors,
        rank_errors,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::baseline::rows::testing::{dense, dims, frobenius2, write_raw};
    use crate::rsvd::SplitMix64;

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
        let basis = fit_with(&raw, 16, 1234, 2000).unwrap();
        let a = dense(&raw);
        let norm2 = frobenius2(a.as_ref());
        let sv = a.as_ref().singular_values().unwrap();
        let noise_rel = noise / norm2.sqrt();
        let mut prev = f64::INFINITY;
        assert_eq!((basis.rank(), basis.rank_errors().len()), (16, 17));
        let ranks = [1, 2, 3, 4, 5, 6, 8, 16];
        for &k in &ranks {
            let error = basis.rank_errors()[k];
            let exact = (sv[k..].iter().map(|s| s * s).sum::<f64>() / norm2).sqrt();
            println!("rank {k}: {error} (exact {exact})");
            assert!(error < prev, "error must decrease with the rank");
            prev = error;
            assert!(
                error >= exact * (1.0 - 1e-9) && error <= exact * 1.03,
                "rank {k}: {error} vs optimal {exact}"
            );
            if k >= 5 {
                assert!(error < 1.5 * noise_rel, "rank {k}: {error}");
            } else {
                assert!(error > 10.0 * noise_rel, "rank {k}: {error}");
            }
        }

        // The shortcut equals the error of the explicit reconstruction
        // A·V_k·V_kᵀ, and V is orthonormal.
        let m = d.lights();
        let v = MatRef::from_column_major_slice(basis.vectors(), m, 16);
        let mut vtv = Mat::<f64>::zeros(16, 16);
        matmul(
            vtv.as_mut(),
            Accum::Replace,
            v.transpose(),
            v,
            1.0,
            Par::Seq,
        );
        for i in 0..16 {
            for j in 0..16 {
                let want = if i == j { 1.0 } else { 0.0 };
                assert!((vtv[(i, j)] - want).abs() < 1e-12);
            }
        }
        for &k in &ranks {
            let vk = v.subcols(0, k);
            let mut c = Mat::<f64>::zeros(a.nrows(), k);
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
            let error = basis.rank_errors()[k];
            assert!(
                (error - explicit).abs() <= 1e-6 * explicit,
                "rank {k}: shortcut {error} vs explicit {explicit}"
            );
        }

        // The coefficients are A·V, row by row (zero rows included).
        let coefficients = basis.coefficients(&raw).unwrap();
        let mut c = Mat::<f64>::zeros(a.nrows(), 16);
        matmul(c.as_mut(), Accum::Replace, a.as_ref(), v, 1.0, Par::Seq);
        assert_eq!(coefficients.len(), a.nrows() * 16);
        for (i, got) in coefficients.iter().enumerate() {
            let want = c[(i / 16, i % 16)];
            assert!((got - want).abs() <= 1e-12, "{i}: {got} vs {want}");
        }
    }

    #[test]
    fn rank_clamped_and_full_rank_exact() {
        let dir = tempfile::tempdir().unwrap();
        let d = dims(4, 3, 2, 1); // 12 rows, 24 lights
        let t = low_rank_matrix(d, 1.0);
        let raw = RawStore::open(&write_raw(dir.path(), "t.raw", d, &t, None, 5)).unwrap();
        let basis = PcaBasis::fit(&raw, 300, 7).unwrap();
        assert_eq!(basis.rank(), 12);
        assert_eq!(basis.vectors().len(), 12 * 24);
        assert!((basis.rank_errors()[0] - 1.0).abs() < 1e-12);
        assert!(basis.rank_errors()[12] < 1e-6);
        assert!(basis.rank_errors().windows(2).all(|w| w[1] <= w[0]));
        let empty = PcaBasis::fit(&raw, 0, 7).unwrap();
        assert_eq!((empty.rank(), empty.rank_errors()), (0, &[1.0][..]));
        assert_eq!(empty.coefficients(&raw).unwrap(), vec![0.0; 0]);

        // An all-zero store, and a store of other dimensions.
        let zero = vec![0.0f32; t.len()];
        let raw0 = RawStore::open(&write_raw(dir.path(), "z.raw", d, &zero, None, 5)).unwrap();
        let basis0 = PcaBasis::fit(&raw0, 4, 7).unwrap();
        assert!(basis0.rank_errors().iter().all(|&e| e == 0.0));
        let d2 = dims(3, 3, 2, 1);
        let raw2 =
            RawStore::open(&write_raw(dir.path(), "o.raw", d2, &t[..9 * 24], None, 5)).unwrap();
        assert!(basis.coefficients(&raw2).is_err());
    }
}
