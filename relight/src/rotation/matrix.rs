//! Wavelet rotation matrices (Wang et al. 2006, §2–3): for a normal `n`,
//! `R(n) = H_m · W(n) · H_nᵀ`, where `H` is the orthonormal Haar transform
//! of a map and `W(n)` resamples the global octahedral map (piecewise
//! constant over its texels) into the local hemi-octahedral map of the
//! frame of `n` (each target texel the solid-angle-weighted mean of `s × s`
//! sub-samples). Column `j` is source wavelet `j` resampled in the local
//! frame and transformed back to Haar; row `r` is computed directly as the
//! Haar transform of `W(n)ᵀ` applied to target wavelet `r`, so rows come
//! out in the order they are stored.

use super::haar;
use super::maps::{hemi_decode, oct_encode, subsample, texel_of, Frame};
use super::RotationConfig;
use glam::DVec3;

/// Largest magnitude of a quantized entry.
pub const QMAX: f64 = 32767.0;

/// What the builder shares between normals: the Haar expansions of both
/// maps.
pub(crate) struct Bases {
    /// Source (`n × n`) impulse expansions, per texel.
    src_delta: Vec<Vec<(u32, f64)>>,
    /// Target (`m × m`) basis functions, per coefficient.
    dst_basis: Vec<Vec<(u32, f64)>>,
}

impl Bases {
    pub(crate) fn new(n: usize) -> Bases {
        let (src_delta, _) = haar::basis_functions(n);
        let (_, dst_basis) = haar::basis_functions(n / 2);
        Bases {
            src_delta,
            dst_basis,
        }
    }
}

/// The resampling `W(n)`: per target texel, `(source texel, weight)` with
/// weights summing to 1.
pub(crate) fn resampling(cfg: &RotationConfig, normal: DVec3) -> Vec<Vec<(u32, f64)>> {
    let (n, m, s) = (cfg.n, cfg.n / 2, cfg.supersample);
    let frame = Frame::new(normal);
    (0..m * m)
        .map(|t| {
            let mut taps: Vec<(u32, f64)> = Vec::with_capacity(s * s);
            for j in 0..s {
                for i in 0..s {
                    let (u, v) = subsample(m, t, s, i, j);
                    let (d, jac) = hemi_decode(u, v);
                    let (gu, gv) = oct_encode(frame.to_global(d));
                    taps.push((texel_of(n, gu, gv) as u32, jac));
                }
            }
            taps.sort_unstable_by_key(|p| p.0);
            let total: f64 = taps.iter().map(|p| p.1).sum();
            let mut merged: Vec<(u32, f64)> = Vec::new();
            for (k, w) in taps {
                match merged.last_mut() {
                    Some(last) if last.0 == k => last.1 += w / total,
                    _ => merged.push((k, w / total)),
                }
            }
            merged
        })
        .collect()
}

/// The exact (f64) rows of `R(n)`: per target coefficient, its nonzero
/// `(source coefficient, value)` in column order.
pub(crate) fn exact_rows(
    cfg: &RotationConfig,
    bases: &Bases,
    normal: DVec3,
) -> Vec<Vec<(u32, f64)>> {
    let w = resampling(cfg, normal);
    let big = cfg.n * cfg.n;
    let (mut img, mut coef) = (vec![0.0f64; big], vec![0.0f64; big]);
    let (mut img_seen, mut coef_seen) = (vec![false; big], vec![false; big]);
    let (mut touched_img, mut touched_coef) = (Vec::new(), Vec::new());
    let mut rows = Vec::with_capacity(bases.dst_basis.len());
    for basis in &bases.dst_basis {
        for &(t, phi) in basis {
            for &(k, wk) in &w[t as usize] {
                let k = k as usize;
                if !img_seen[k] {
                    img_seen[k] = true;
                    touched_img.push(k);
                }
                img[k] += phi * wk;
            }
        }
        for &k in &touched_img {
            for &(j, h) in &bases.src_delta[k] {
                let j = j as usize;
                if !coef_seen[j] {
                    coef_seen[j] = true;
                    touched_coef.push(j);
                }
                coef[j] += img[k] * h;
            }
            img[k] = 0.0;
            img_seen[k] = false;
        }
        touched_img.clear();
        touched_coef.sort_unstable();
        let mut row = Vec::with_capacity(touched_coef.len());
        for &j in &touched_coef {
            // Exact cancellations leave rounding residue far below any
            // quantization step.
            if coef[j].abs() > 1e-12 {
                row.push((j as u32, coef[j]));
            }
            coef[j] = 0.0;
            coef_seen[j] = false;
        }
        touched_coef.clear();
        rows.push(row);
    }
    rows
}

/// Column indices of a matrix: 16 bits where the source has at most 2¹⁶
/// coefficients (every `n` ≤ 256 the configuration allows), else 32.
#[derive(Clone, Debug)]
pub enum Columns {
    /// 16-bit indices.
    U16(Vec<u16>),
    /// 32-bit indices.
    U32(Vec<u32>),
}

impl Columns {
    fn len(&self) -> usize {
        match self {
            Columns::U16(c) => c.len(),
            Columns::U32(c) => c.len(),
        }
    }

    fn index_bytes(&self) -> usize {
        match self {
            Columns::U16(_) => 2,
            Columns::U32(_) => 4,
        }
    }
}

/// One quantized sparse rotation matrix `R(n)`, `M × N`, row-major: entry
/// `(r, cols[k])` for `k ∈ row_ptr[r]..row_ptr[r + 1]` is `values[k]·scale`.
/// `scale = max |R_ij| / 32767` per matrix; an entry is kept when its
/// quantized magnitude is at least the truncation threshold (and nonzero).
#[derive(Clone, Debug)]
pub struct RotationMatrix {
    pub(crate) row_ptr: Vec<u32>,
    pub(crate) cols: Columns,
    pub(crate) values: Vec<i16>,
    pub(crate) scale: f32,
}

impl RotationMatrix {
    /// The matrix of one (unit) normal, any normal, not only a grid one.
    pub fn build(cfg: &RotationConfig, normal: DVec3) -> crate::error::Result<RotationMatrix> {
        cfg.validate()?;
        let rows = exact_rows(cfg, &Bases::new(cfg.n), normal.normalize());
        Ok(RotationMatrix::quantize(
            &rows,
            cfg.threshold,
            cfg.n * cfg.n > 1 << 16,
        ))
    }

    /// Quantizes exact rows (see the type's documentation).
    pub(crate) fn quantize(rows: &[Vec<(u32, f64)>], threshold: u16, wide: bool) -> RotationMatrix {
        let max = rows
            .iter()
            .flatten()
            .fold(0.0f64, |a, &(_, v)| a.max(v.abs()));
        let scale = if max > 0.0 { max / QMAX } else { 1.0 };
        let keep = f64::from(threshold.max(1));
        let mut row_ptr = Vec::with_capacity(rows.len() + 1);
        let (mut c16, mut c32, mut values) = (Vec::new(), Vec::new(), Vec::new());
        row_ptr.push(0u32);
        for row in rows {
            for &(j, v) in row {
                let q = (v / scale).round().clamp(-QMAX, QMAX);
                if q.abs() >= keep {
                    if wide {
                        c32.push(j);
                    } else {
                        c16.push(j as u16);
                    }
                    values.push(q as i16);
                }
            }
            row_ptr.push(values.len() as u32);
        }
        let cols = if wide {
            Columns::U32(c32)
        } else {
            Columns::U16(c16)
        };
        RotationMatrix {
            row_ptr,
            cols,
            values,
            scale: scale as f32,
        }
    }

    /// Rows (target coefficients).
    pub fn rows(&self) -> usize {
        self.row_ptr.len() - 1
    }

    /// Stored entries.
    pub fn nonzeros(&self) -> usize {
        self.values.len()
    }

    /// The quantization step: an entry is `value · scale`.
    pub fn scale(&self) -> f32 {
        self.scale
    }

    /// Bytes of the stored form: row offsets (u32), column indices, values
    /// (i16) and the scale.
    pub fn bytes(&self) -> usize {
        4 * self.row_ptr.len() + (self.cols.index_bytes() + 2) * self.cols.len() + 4
    }

    /// Row `r` as `(column, quantized value)`.
    pub fn row(&self, r: usize) -> impl Iterator<Item = (usize, i16)> + '_ {
        let range = self.row_ptr[r] as usize..self.row_ptr[r + 1] as usize;
        let vals = &self.values[range.clone()];
        let cols: Box<dyn Iterator<Item = usize>> = match &self.cols {
            Columns::U16(c) => Box::new(c[range].iter().map(|&j| j as usize)),
            Columns::U32(c) => Box::new(c[range].iter().map(|&j| j as usize)),
        };
        cols.zip(vals.iter().copied())
    }

    /// `out = R · light` for RGB coefficient vectors (`light` has `N`
    /// entries, `out` `M`).
    pub fn apply(&self, light: &[[f32; 3]], out: &mut [[f32; 3]]) {
        match &self.cols {
            Columns::U16(c) => self.apply_with(c, light, out),
            Columns::U32(c) => self.apply_with(c, light, out),
        }
    }

    fn apply_with<T: Copy + Into<u64>>(
        &self,
        cols: &[T],
        light: &[[f32; 3]],
        out: &mut [[f32; 3]],
    ) {
        for (r, o) in out.iter_mut().enumerate() {
            let (a, b) = (self.row_ptr[r] as usize, self.row_ptr[r + 1] as usize);
            let mut acc = [0.0f32; 3];
            for (&j, &q) in cols[a..b].iter().zip(&self.values[a..b]) {
                let l = light[j.into() as usize];
                let q = f32::from(q);
                acc[0] += q * l[0];
                acc[1] += q * l[1];
                acc[2] += q * l[2];
            }
            *o = acc.map(|v| v * self.scale);
        }
    }
}
