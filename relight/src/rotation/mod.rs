//! Wavelet rotation for glossy, view-dependent shading under distant
//! lighting: Wang, Ng, Luebke and Humphreys 2006, *Efficient Wavelet
//! Rotation for Environment Map Rendering* (EGSR 2006), §2–3.
//!
//! The global lighting is an `n × n` octahedral map ([`maps`]) of RGB
//! radiance, piecewise constant over texels, in the orthonormal 2D Haar
//! basis (non-standard decomposition, [`haar`]). For each normal of an
//! octahedral grid, a sparse [`RotationMatrix`] `R(n)` maps it to the local
//! lighting of the normal's frame on an `m × m` hemi-octahedral map,
//! `m = n/2`, also in Haar (eq. 5). A [`BrdfSlices`] table holds, for each
//! view direction of a hemi-octahedral grid, the Haar coefficients of
//! `f_r(ω, ω_o)·cos θ·Δω` over the target texels (the cosine and the
//! texels' solid angles are in the slice), keeping the largest terms; so a
//! slice dotted with a local lighting is the reflection integral (eq. 7)
//! for piecewise-constant local lighting.
//!
//! Rendering is the paper's two steps ([`Shader`]): [`Shader::light`]
//! (lighting change) computes `R(n)·L` for every grid normal, and
//! [`Shader::shade`] (view change) evaluates, for each of the four grid
//! normals around a surface normal, the slice of the view direction *in
//! that normal's frame* dotted with its local lighting, blended bilinearly.
//! Each (grid normal, view texel) pair's radiance is kept once computed
//! ([`Shader::set_pair_table`]), so a view change computes only the pairs
//! no earlier view used.
//! Rotation matrices depend only on `n`, the normal grid, the sub-sampling
//! and the threshold: switching BRDFs rebuilds no rotation.

pub mod brdf;
mod cache;
pub mod haar;
pub mod maps;
mod matrix;
mod merl;
mod pairs;
mod shade;
mod spatial;
#[cfg(test)]
mod tests;

pub use brdf::{Brdf, BrdfSlices, SliceConfig, BRDF_SYNTAX, LOBE_TEXELS};
pub use cache::{CacheUse, MAGIC as CACHE_MAGIC, VERSION as CACHE_VERSION};
pub use matrix::{Columns, RotationMatrix, QMAX};
pub use merl::{MeasuredBrdf, MERL_DIMS, MERL_FILE_BYTES};
pub use pairs::MAX_PAIR_TABLE_BYTES;
pub use shade::{resample_local, OctMap, Shader, ViewFilter, DEFAULT_LOCAL_KEEP};

use crate::error::{RelightError, Result};
use glam::DVec3;
use ltm_codec::{Charge, Limits};
use rayon::prelude::*;

/// Largest source map side.
pub const MAX_SOURCE_SIDE: usize = 256;
/// Largest side of the octahedral grid of normals.
pub const MAX_NORMAL_SIDE: usize = 256;
/// Largest sub-sampling per target texel and side.
pub const MAX_SUPERSAMPLE: usize = 16;

/// How a [`RotationSet`] is built.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RotationConfig {
    /// Source octahedral map side `n` (a power of two, 4..=256); the target
    /// hemi-octahedral side is `n/2`.
    pub n: usize,
    /// Side of the octahedral grid of normals (1..=256); 32 by default.
    pub normals: usize,
    /// Sub-samples per target texel and side when resampling (1..=16).
    pub supersample: usize,
    /// Truncation threshold on the 16-bit scale: entries whose quantized
    /// magnitude is below it are dropped (0 and 1 both keep every nonzero).
    pub threshold: u16,
}

impl Default for RotationConfig {
    fn default() -> RotationConfig {
        RotationConfig {
            n: 64,
            normals: 32,
            supersample: 16,
            threshold: 1,
        }
    }
}

/// Checks that `n` is a power of two within `lo..=hi`.
pub(crate) fn check_pow2(what: &'static str, n: usize, lo: usize, hi: usize) -> Result<()> {
    if !n.is_power_of_two() || n < lo || n > hi {
        return Err(RelightError::range(
            what,
            n,
            format!("a power of two in {lo}..={hi}"),
        ));
    }
    Ok(())
}

impl RotationConfig {
    /// Checks every field (errors name the value and its valid range).
    pub fn validate(&self) -> Result<()> {
        check_pow2("rotation source side n", self.n, 4, MAX_SOURCE_SIDE)?;
        if !(1..=MAX_NORMAL_SIDE).contains(&self.normals) {
            let valid = format!("1..={MAX_NORMAL_SIDE}");
            return Err(RelightError::range("normal grid side", self.normals, valid));
        }
        if !(1..=MAX_SUPERSAMPLE).contains(&self.supersample) {
            let valid = format!("1..={MAX_SUPERSAMPLE}");
            return Err(RelightError::range(
                "rotation supersample",
                self.supersample,
                valid,
            ));
        }
        if f64::from(self.threshold) > QMAX {
            let valid = format!("0..={QMAX}");
            return Err(RelightError::range(
                "truncation threshold",
                self.threshold,
                valid,
            ));
        }
        Ok(())
    }

    /// Target hemi-octahedral side `m = n/2`.
    pub fn m(&self) -> usize {
        self.n / 2
    }

    /// The grid normal of index `i` (texel centre of the normal grid).
    pub fn grid_normal(&self, i: usize) -> DVec3 {
        let (u, v) = maps::texel_center(self.normals, i);
        maps::oct_decode(u, v).0
    }
}

/// Size figures of a [`RotationSet`] (Table 2 of the paper).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RotationStats {
    /// Matrices (grid normals).
    pub matrices: usize,
    /// Stored entries over all matrices.
    pub nonzeros: usize,
    /// Mean stored entries per row.
    pub per_row: f64,
    /// Stored entries over `M·N·matrices`.
    pub density: f64,
    /// Bytes of the stored form.
    pub bytes: usize,
}

/// One rotation matrix per normal of an octahedral grid.
#[derive(Debug)]
pub struct RotationSet {
    cfg: RotationConfig,
    matrices: Vec<RotationMatrix>,
    _charge: Charge,
}

impl RotationSet {
    /// Builds every matrix, in parallel over normals (rayon); each matrix is
    /// charged to `limits` as it is made.
    pub fn build(cfg: RotationConfig, limits: &Limits) -> Result<RotationSet> {
        cfg.validate()?;
        let bases = matrix::Bases::new(cfg.n);
        let wide = cfg.n * cfg.n > 1 << 16;
        let built: Vec<Result<(RotationMatrix, Charge)>> = (0..cfg.normals * cfg.normals)
            .into_par_iter()
            .map(|i| {
                let rows = matrix::exact_rows(&cfg, &bases, cfg.grid_normal(i));
                let mat = RotationMatrix::quantize(&rows, cfg.threshold, wide);
                let charge = limits.check_alloc("rotation matrix", mat.bytes() as u64, 1)?;
                Ok((mat, charge))
            })
            .collect();
        let mut matrices = Vec::with_capacity(built.len());
        let mut charge = Charge::default();
        for b in built {
            let (mat, c) = b?;
            matrices.push(mat);
            charge = charge.join(c);
        }
        Ok(RotationSet {
            cfg,
            matrices,
            _charge: charge,
        })
    }

    pub(crate) fn from_parts(
        cfg: RotationConfig,
        matrices: Vec<RotationMatrix>,
        charge: Charge,
    ) -> RotationSet {
        RotationSet {
            cfg,
            matrices,
            _charge: charge,
        }
    }

    /// The configuration it was built with.
    pub fn config(&self) -> &RotationConfig {
        &self.cfg
    }

    /// The matrix of grid normal `i`.
    pub fn matrix(&self, i: usize) -> &RotationMatrix {
        &self.matrices[i]
    }

    /// The matrices, in grid order.
    pub fn matrices(&self) -> &[RotationMatrix] {
        &self.matrices
    }

    /// Size figures.
    pub fn stats(&self) -> RotationStats {
        let nonzeros: usize = self.matrices.iter().map(|m| m.nonzeros()).sum();
        let rows: usize = self.matrices.iter().map(|m| m.rows()).sum();
        let (n2, m2) = (self.cfg.n * self.cfg.n, self.cfg.m() * self.cfg.m());
        RotationStats {
            matrices: self.matrices.len(),
            nonzeros,
            per_row: nonzeros as f64 / rows.max(1) as f64,
            density: nonzeros as f64 / (n2 * m2 * self.matrices.len().max(1)) as f64,
            bytes: self.matrices.iter().map(|m| m.bytes()).sum(),
        }
    }
}
