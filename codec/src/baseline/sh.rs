//! Spherical-harmonics projection of the transport rows: the linear basis
//! of precomputed radiance transfer (Sloan, Kautz and Snyder 2002,
//! "Precomputed radiance transfer for real-time rendering in dynamic,
//! low-frequency lighting environments"), the comparison made by Ng,
//! Ramamoorthi and Hanrahan 2003 ("All-frequency shadows using non-linear
//! wavelet lighting approximation").
//!
//! It lives in the codec next to [`crate::PcaBasis`] because both are fits of a
//! raw store: they stream the same dense blocks of rows and share the
//! linear algebra (faer), and a fit produces what a file would store. The
//! relighting crate only evaluates the fitted coefficients
//! (`ltm_relight::BasisRelighter`).

use super::rows::{relative, CHUNK_VALUES};
use crate::cubemap;
use crate::dims::Dims;
use crate::error::{Error, Result};
use crate::raw::RawStore;
use crate::rsvd::{for_each_block, Block};
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, Par};
use glam::DVec3;
use rayon::prelude::*;
use std::f64::consts::PI;

/// Largest spherical-harmonics order accepted by [`ShProjection::fit`].
pub const MAX_SH_ORDER: usize = 64;

/// Real orthonormal spherical harmonics of bands `l < order` at the unit
/// direction `d = (x, y, z)`, polar axis `z`, into `out[l² + l + m]`
/// (`order²` values; `out` must hold at least that many):
/// `Y_l0 = N_l0·P_l^0(z)`, `Y_lm = √2·N_lm·P_l^m(z)·cos(mφ)` and
/// `Y_l,−m = √2·N_lm·P_l^m(z)·sin(mφ)` for `m > 0`, with
/// `N_lm = √((2l+1)/(4π)·(l−m)!/(l+m)!)` and no Condon–Shortley phase
/// (so `Y_11 = √(3/4π)·x`).
///
/// Evaluated with the stable recurrences of the normalised associated
/// Legendre functions, divided by `sin^m θ` (polynomials in `z`), times
/// `(x + iy)^m = sin^m θ·e^{imφ}`: exact at the poles, stable to high order.
pub fn eval(order: usize, d: DVec3, out: &mut [f64]) -> Result<()> {
    let need = order * order;
    if out.len() < need {
        return Err(Error::BufferTooSmall {
            what: "spherical-harmonics values",
            len: out.len(),
            need,
        });
    }
    eval_unchecked(order, d, out);
    Ok(())
}

/// [`eval`] for an `out` of at least `order²` values.
fn eval_unchecked(order: usize, d: DVec3, out: &mut [f64]) {
    let DVec3 { x, y, z } = d;
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

/// Direction of the centre of texel `j` ([`cubemap::texel_direction`]),
/// renormalised in f64.
fn texel_centre(n: usize, j: usize) -> DVec3 {
    cubemap::texel_direction(n, j).as_dvec3().normalize()
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
            .for_each(|(j, out)| eval_unchecked(order, texel_centre(n, j), out));
    }
    let y = Mat::from_fn(m, k, |j, a| rows[j * k + a]);
    let dw = (0..m).map(|j| cubemap::texel_solid_angle(n, j)).collect();
    (y, dw)
}

/// The spherical-harmonics projection of every row of a raw store up to an
/// order `L`, and the error of every order up to it.
///
/// Per texel `j`, `T[p, j] = f_p(ω_j)·dω_j`, so
/// `f_lm = Σ_j T[p, j]·Y_lm(ω_j)` and the reconstruction is
/// `T̂[p, j] = Σ_{l<L, m} f_lm·Y_lm(ω_j)·dω_j`, `ω_j` the texel centre and
/// `dω_j` the exact texel solid angle.
#[derive(Clone, Debug)]
pub struct ShProjection {
    dims: Dims,
    max_order: usize,
    /// `f_lm` of each row (pixel, channel), `max_order²` per row.
    coefficients: Vec<f64>,
    /// `Y_a(ω_j)·dω_j`, `M` values per coefficient `a`.
    weighted_basis: Vec<f64>,
    order_errors: Vec<f64>,
}

impl ShProjection {
    /// Projects every row of `raw` on the real spherical harmonics of bands
    /// `l < max_order` (at most [`MAX_SH_ORDER`]) in one pass over the store
    /// (checksums verified, rows flagged all zero skipped). The error of
    /// every order is exact in f64, from `F = T·Y` and `G = T·W·Y`
    /// (`W = diag(dω)`): `‖t − t̂‖² = ‖t‖² − 2·f·g + fᵀ·(YᵀW²Y)·f` over the
    /// first `L²` coefficients.
    pub fn fit(raw: &RawStore, max_order: usize) -> Result<ShProjection> {
        fit_with(raw, max_order, CHUNK_VALUES)
    }

    /// The dimensions of the matrix projected.
    pub fn dims(&self) -> Dims {
        self.dims
    }

    /// `L`, the order fitted: coefficients of bands `l < L` are kept.
    pub fn max_order(&self) -> usize {
        self.max_order
    }

    /// The coefficients `f_lm` of every row `r = p·C + c`, `L²` per row at
    /// index `l² + l + m` ([`eval`]'s order): row `r` is
    /// `coefficients()[r·L² .. (r+1)·L²]`.
    pub fn coefficients(&self) -> &[f64] {
        &self.coefficients
    }

    /// The reconstruction basis `Y_a(ω_j)·dω_j`, `L² × M` row-major:
    /// `T̂[r, j] = Σ_a f[r, a]·weighted_basis()[a·M + j]`.
    pub fn weighted_basis(&self) -> &[f64] {
        &self.weighted_basis
    }

    /// The order–error curve: entry `o` (`0 ≤ o ≤ L`) is
    /// `‖T − T̂_o‖_F / ‖T‖_F` with bands `l < o` (0 for an all-zero matrix).
    pub fn order_errors(&self) -> &[f64] {
        &self.order_errors
    }
}

/// What a block's projection needs, built once per fit.
struct Projector {
    /// Coefficients per row, `order²`.
    k: usize,
    /// `[Y | W·Y]`, `M × 2K`.
    yw: Mat<f64>,
    /// `S = (WY)ᵀ(WY)` below its diagonal (`z_a = Σ_{b<a} S_ab f_b`), and
    /// its diagonal.
    s_lower: Mat<f64>,
    s_diag: Vec<f64>,
}

impl Projector {
    fn new(y: &Mat<f64>, dw: &[f64]) -> Projector {
        let (m, k) = (y.nrows(), y.ncols());
        let yw = Mat::<f64>::from_fn(m, 2 * k, |j, a| {
            if a < k {
                y[(j, a)]
            } else {
                dw[j] * y[(j, a - k)]
            }
        });
        let mut s = Mat::<f64>::zeros(k, k);
        let wy = yw.as_ref().subcols(k, k);
        matmul(
            s.as_mut(),
            Accum::Replace,
            wy.transpose(),
            wy,
            1.0,
            Par::rayon(0),
        );
        let s_lower = Mat::<f64>::from_fn(k, k, |a, b| if b < a { s[(a, b)] } else { 0.0 });
        let s_diag = (0..k).map(|a| s[(a, a)]).collect();
        Projector {
            k,
            yw,
            s_lower,
            s_diag,
        }
    }

    /// `(F | G)ᵀ = [Y | WY]ᵀ·Aᵀ` (`2K × R`: row `i`'s `f` and `g` are
    /// contiguous) and `Zᵀ = S_lower·Fᵀ` of a block.
    fn project(&self, blk: &Block<'_, f64>) -> (Mat<f64>, Mat<f64>) {
        let (k, r, par) = (self.k, blk.rows.len(), Par::rayon(0));
        let mut fgt = Mat::<f64>::zeros(2 * k, r);
        let mut zt = Mat::<f64>::zeros(k, r);
        if k > 0 {
            matmul(
                fgt.as_mut(),
                Accum::Replace,
                self.yw.transpose(),
                blk.at(),
                1.0,
                par,
            );
            let ft = fgt.as_ref().subrows(0, k);
            matmul(
                zt.as_mut(),
                Accum::Replace,
                self.s_lower.as_ref(),
                ft,
                1.0,
                par,
            );
        }
        (fgt, zt)
    }

    /// Adds each row's squared error at every order `0..=L` to `acc[o]` and
    /// `‖t‖²` to `acc[L + 1]`.
    fn errors(&self, t: &[f64], fg: &[f64], zc: &[f64], acc: &mut [f64]) {
        let max_order = acc.len() - 2;
        let tn: f64 = t.iter().map(|v| v * v).sum();
        let (f, g) = fg.split_at(self.k);
        let (mut quad, mut dot, mut a) = (0.0f64, 0.0f64, 0usize);
        for (order, e) in acc[..=max_order].iter_mut().enumerate() {
            while a < order * order {
                quad += f[a] * (2.0 * zc[a] + self.s_diag[a] * f[a]);
                dot += f[a] * g[a];
                a += 1;
            }
            *e += tn - 2.0 * dot + quad;
        }
        acc[max_order + 1] += tn;
    }
}

/// The contiguous column `i` of a column-major matrix.
fn column(m: &Mat<f64>, i: usize) -> &[f64] {
    m.col(i)
        .try_as_col_major()
        .expect("faer matrices are column-major")
        .as_slice()
}

/// [`ShProjection::fit`] with blocks of about `chunk_values` values.
fn fit_with(raw: &RawStore, max_order: usize, chunk_values: usize) -> Result<ShProjection> {
    if max_order > MAX_SH_ORDER {
        return Err(Error::range(
            "spherical-harmonics order",
            max_order,
            format!("0..={MAX_SH_ORDER}"),
        ));
    }
    let dims = raw.dims();
    let (n, m) = (dims.face_res() as usize, dims.lights());
    let n_rows = dims.pixels() * dims.channels as usize;
    let k = max_order * max_order;
    let (y, dw) = sh_basis(n, max_order);
    let proj = Projector::new(&y, &dw);
    let mut coefficients = vec![0.0f64; n_rows * k];
    // Squared errors of orders 0..=L, then ‖T‖².
    let mut sums = vec![0.0f64; max_order + 2];
    let mut buf: Vec<f64> = Vec::new();
    for_each_block(raw, chunk_values, true, &mut buf, |blk| {
        let (fgt, zt) = proj.project(&blk);
        let zero = || vec![0.0f64; max_order + 2];
        let block_sums = (0..blk.rows.len())
            .into_par_iter()
            .fold(zero, |mut acc, i| {
                proj.errors(blk.row(i), column(&fgt, i), column(&zt, i), &mut acc);
                acc
            })
            .reduce(zero, |mut a, b| {
                a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
                a
            });
        sums.iter_mut().zip(block_sums).for_each(|(x, y)| *x += y);
        for (i, &row) in blk.rows.iter().enumerate().filter(|_| k > 0) {
            coefficients[row * k..(row + 1) * k].copy_from_slice(&column(&fgt, i)[..k]);
        }
        Ok(())
    })?;
    let norm2 = sums[max_order + 1];
    let order_errors = sums[..=max_order]
        .iter()
        .map(|&e| relative(e, norm2))
        .collect();
    let weighted_basis = (0..k * m).map(|i| y[(i % m, i / m)] * dw[i % m]).collect();
    Ok(ShProjection {
        dims,
        max_order,
        coefficients,
        weighted_basis,
        order_errors,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::baseline::rows::testing::{dense, dims, frobenius2, write_raw};
    use crate::rsvd::SplitMix64;

    fn test_directions() -> Vec<DVec3> {
        vec![
            DVec3::new(0.3, -0.5, 0.81).normalize(),
            DVec3::new(-0.7, 0.2, -0.1).normalize(),
            DVec3::new(0.0, 0.0, 1.0),
            DVec3::new(0.0, 0.0, -1.0),
            DVec3::new(1.0, 1.0, 1.0).normalize(),
            DVec3::new(0.12, 0.95, -0.4).normalize(),
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
            let DVec3 { x, y, z } = d;
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
            eval(3, d, &mut got).unwrap();
            for (a, (g, w)) in got.iter().zip(want).enumerate() {
                assert!((g - w).abs() < 1e-14, "Y[{a}] at {d:?}: {g} vs {w}");
            }
        }
        assert!(eval(3, DVec3::Z, &mut [0.0; 8]).is_err());
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
            eval(order, d, &mut got).unwrap();
            let phi = d.y.atan2(d.x);
            for l in 0..order {
                for m in 0..=l {
                    let norm = ((2 * l + 1) as f64 / (4.0 * PI) * fact(l - m) / fact(l + m)).sqrt();
                    let p = norm * legendre_explicit(l, m, d.z);
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
    fn texel_centres_follow_the_cubemap_convention() {
        // The centre of texel (face, row, col) is the face point
        // ((col + 0.5)/n, (row + 0.5)/n), as `cubemap` defines it.
        let n = 5;
        for j in 0..cubemap::texel_count(n) {
            let (face, row, col) = cubemap::texel_coords(n, j);
            let s = (col as f64 + 0.5) / n as f64;
            let t = (row as f64 + 0.5) / n as f64;
            let want = cubemap::face_point_direction(face, s, t);
            assert!((texel_centre(n, j) - want).length() < 1e-7, "texel {j}");
            assert!((texel_centre(n, j).length() - 1.0).abs() < 1e-15);
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
            eval(4, texel_centre(32, j), &mut yv).unwrap();
            let f: f64 = coef.iter().zip(&yv).map(|(c, y)| c * y).sum();
            *v = (f * cubemap::texel_solid_angle(32, j)) as f32;
        }
        // Pixel 1 stays zero.
        let raw = RawStore::open(&write_raw(dir.path(), "t.raw", d, &t, None, 1)).unwrap();
        let proj = ShProjection::fit(&raw, 6).unwrap();
        let e = &proj.order_errors()[1..];
        println!("errors by order 1..=6: {e:?}");
        assert_eq!(proj.order_errors().len(), 7);
        for (o, &err) in e.iter().enumerate() {
            if o + 1 >= 4 {
                assert!(err < 1e-3, "order {}: error {err}", o + 1);
            } else {
                assert!(err > 0.1, "order {}: error {err}", o + 1);
            }
        }
        let e = ShProjection::fit(&raw, MAX_SH_ORDER + 1).unwrap_err();
        assert!(e.to_string().contains("65") && e.to_string().contains("0..=64"));
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
            eval(max_order, texel_centre(n, j), &mut v).unwrap();
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
        // Small chunks: several blocks of rows per pass.
        let proj = fit_with(&raw, 5, 1000).unwrap();
        let a = dense(&raw);
        let norm2 = frobenius2(a.as_ref());
        assert_eq!(proj.order_errors().len(), 6);
        for (order, &error) in proj.order_errors().iter().enumerate() {
            let (_, recon) = dense_sh(&a, 4, order, 5);
            let diff = Mat::from_fn(a.nrows(), a.ncols(), |i, j| a[(i, j)] - recon[(i, j)]);
            let want = (frobenius2(diff.as_ref()) / norm2).sqrt();
            assert!(
                (error - want).abs() <= 1e-9 * want.max(1e-3),
                "order {order}: {error} vs explicit {want}"
            );
        }
        assert!((proj.order_errors()[0] - 1.0).abs() < 1e-12);
        assert!(proj.order_errors()[5] < proj.order_errors()[1]);
        // The stored coefficients are F = T·Y, row by row, and the
        // reconstruction basis is Y·dω.
        let (f, _) = dense_sh(&a, 4, 5, 5);
        for (i, got) in proj.coefficients().iter().enumerate() {
            let want = f[(i / 25, i % 25)];
            assert!((got - want).abs() <= 1e-12 * (1.0 + want.abs()), "{i}");
        }
        let (y, dw) = sh_basis(4, 5);
        for (i, got) in proj.weighted_basis().iter().enumerate() {
            let (b, j) = (i / d.lights(), i % d.lights());
            assert_eq!(*got, y[(j, b)] * dw[j]);
        }
    }
}
