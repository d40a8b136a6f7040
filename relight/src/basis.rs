//! Relighting from a linear light basis fitted to the raw store: principal
//! components (Eigentransport, [`ltm_codec::PcaBasis`]) or spherical
//! harmonics ([`ltm_codec::ShProjection`]), the baselines the wavelet codec
//! is measured against.
//!
//! Both approximate the matrix as `T̂ = F·B`: `K` coefficients `f_r` per row
//! `r` (a (pixel, channel) pair) and `K` reconstruction functions `b_a` over
//! the cubemap texels (PCA: the light vectors `v_a`; SH: `Y_a(ω_j)·dω_j`).
//! A frame projects the lighting once, `l_a = Σ_j b_a[j]·L_j` (RGB), and
//! each pixel is a dot product `B̂[r] = Σ_{a<k} f_r[a]·l_a`, which equals
//! `T̂_k·L`. Grey stores multiply each light channel, then the albedo image
//! if there is one. Everything is accumulated in f64.

use crate::error::{RelightError, Result};
use crate::frame::{check_light, Frame, FrameStats, Relight, Request, TermBasis};
use crate::image_io::Image;
use ltm_codec::{Dims, LightBasis, Limits, PcaBasis, RawStore, ShProjection};
use rayon::prelude::*;
use std::time::Instant;

/// A transport matrix approximated on a linear light basis, ready to
/// relight: the [`Relight`] implementation for PCA and spherical harmonics.
/// [`Request::terms`] is the number of principal components, or the
/// spherical-harmonics order (`terms²` coefficients); the weighting is
/// ignored. Immutable and `Sync`.
pub struct BasisRelighter {
    fit: Fit,
    dims: Dims,
    albedo: Option<Vec<f32>>,
    /// The budget its frames are charged to: the one the raw store was
    /// opened with.
    limits: Limits,
}

/// The scratch a [`BasisRelighter`] keeps in a [`Frame`]: the lighting
/// projected on the basis (RGB per basis function).
struct Projected(Vec<[f64; 3]>);

/// The fitted coefficients and basis.
enum Fit {
    Pca {
        rank: usize,
        /// `P·C × K`.
        coefficients: Vec<f64>,
        /// `K × M`.
        vectors: Vec<f64>,
    },
    Sh(ShProjection),
}

impl BasisRelighter {
    /// The first [`PcaBasis::rank`] principal components of `raw`, the
    /// store `basis` was fitted to: computes every row's coefficients (one
    /// pass over the store).
    pub fn pca(basis: &PcaBasis, raw: &RawStore) -> Result<BasisRelighter> {
        let fit = Fit::Pca {
            rank: basis.rank(),
            coefficients: basis.coefficients(raw)?,
            vectors: basis.vectors().to_vec(),
        };
        BasisRelighter::new(fit, basis.dims(), raw)
    }

    /// The spherical-harmonics projection of `raw` up to
    /// [`ShProjection::max_order`].
    pub fn sh(projection: ShProjection, raw: &RawStore) -> Result<BasisRelighter> {
        let dims = projection.dims();
        BasisRelighter::new(Fit::Sh(projection), dims, raw)
    }

    fn new(fit: Fit, dims: Dims, raw: &RawStore) -> Result<BasisRelighter> {
        if raw.dims() != dims {
            return Err(RelightError::Invalid(format!(
                "a basis fitted to a {dims:?} matrix cannot relight a {:?} store",
                raw.dims()
            )));
        }
        Ok(BasisRelighter {
            fit,
            dims,
            albedo: raw.albedo().map(<[f32]>::to_vec),
            // Frames are charged to the budget the store was opened with.
            limits: raw.limits().clone(),
        })
    }

    /// `(coefficients, basis, K)`: row `r`'s coefficients are
    /// `coefficients[r·K ..]`, basis function `a` is `basis[a·M ..]`.
    fn parts(&self) -> (&[f64], &[f64], usize) {
        match &self.fit {
            Fit::Pca {
                rank,
                coefficients,
                vectors,
            } => (coefficients, vectors, *rank),
            Fit::Sh(p) => (p.coefficients(), p.weighted_basis(), p.max_order().pow(2)),
        }
    }

    /// The coefficients a request uses: `terms` components, or `terms²`
    /// spherical-harmonics coefficients.
    fn coefficients_used(&self, terms: usize) -> Result<usize> {
        let (what, valid) = match self.fit {
            Fit::Pca { .. } => ("principal components", "the rank fitted"),
            Fit::Sh(_) => ("spherical-harmonics order", "the order fitted"),
        };
        if terms > self.max_terms() {
            let range = format!("0..={} ({valid})", self.max_terms());
            return Err(RelightError::range(what, terms, range));
        }
        Ok(match self.fit {
            Fit::Pca { .. } => terms,
            Fit::Sh(_) => terms * terms,
        })
    }

    /// `l_a = Σ_j b_a[j]·L_j` for the first `k` basis functions.
    fn project(&self, light: &[[f32; 3]], k: usize, out: &mut Vec<[f64; 3]>) {
        let (_, basis, _) = self.parts();
        let m = self.dims.lights();
        out.resize(k, [0.0; 3]);
        out.par_iter_mut().enumerate().for_each(|(a, acc)| {
            *acc = [0.0; 3];
            for (w, l) in basis[a * m..(a + 1) * m].iter().zip(light) {
                for c in 0..3 {
                    acc[c] += w * l[c] as f64;
                }
            }
        });
    }

    /// Every pixel's dot product of its first `k` coefficients with the
    /// projected lighting, times the albedo.
    fn dot_rows(&self, projected: &[[f64; 3]], image: &mut Image) {
        let (coefficients, _, stride) = self.parts();
        let channels = self.dims.channels as usize;
        let k = projected.len();
        image.data.par_iter_mut().enumerate().for_each(|(p, px)| {
            let mut out = [0.0f64; 3];
            for (c, o) in out.iter_mut().enumerate() {
                let row = if channels == 3 { 3 * p + c } else { p };
                let f = &coefficients[row * stride..row * stride + k];
                *o = f.iter().zip(projected).map(|(f, l)| f * l[c]).sum();
            }
            if let Some(a) = &self.albedo {
                for c in 0..3 {
                    out[c] *= a[3 * p + c] as f64;
                }
            }
            *px = out.map(|v| v as f32);
        });
    }
}

impl Relight for BasisRelighter {
    fn light_basis(&self) -> LightBasis {
        self.dims.lights
    }

    /// Principal components or spherical-harmonics orders.
    fn term_basis(&self) -> TermBasis {
        TermBasis::Linear
    }

    fn size(&self) -> (usize, usize) {
        (self.dims.width() as usize, self.dims.height() as usize)
    }

    /// The rank, or the spherical-harmonics order, fitted.
    fn max_terms(&self) -> usize {
        match &self.fit {
            Fit::Pca { rank, .. } => *rank,
            Fit::Sh(p) => p.max_order(),
        }
    }
    fn held_bytes(&self) -> usize {
        let fit = match &self.fit {
            Fit::Pca {
                coefficients,
                vectors,
                ..
            } => 8 * (coefficients.len() + vectors.len()),
            Fit::Sh(sh) => 8 * (sh.coefficients().len() + sh.weighted_basis().len()),
        };
        fit + self.albedo.as_ref().map_or(0, |a| 4 * a.len())
    }

    fn frame(&self) -> Result<Frame> {
        let (w, h) = self.size();
        let mut frame = Frame::default();
        frame.fit_image(w, h, &self.limits)?;
        let k = self.parts().2;
        frame.scratch(
            |_: &Projected| false,
            || Ok(Projected(Vec::with_capacity(k))),
        )?;
        Ok(frame)
    }

    /// `T̂·L` with the first `request.terms` components or orders.
    fn relight(
        &self,
        light: &[[f32; 3]],
        request: &Request,
        frame: &mut Frame,
    ) -> Result<FrameStats> {
        check_light(light, self.lights(), self.dims.face_res())?;
        let k = self.coefficients_used(request.terms)?;
        let (w, h) = self.size();
        frame.fit_image(w, h, &self.limits)?;
        let (s, image) = frame.scratch(|_: &Projected| true, || Ok(Projected(Vec::new())))?;
        let t0 = Instant::now();
        self.project(light, k, &mut s.0);
        let t1 = Instant::now();
        self.dot_rows(&s.0, image);
        if let Some((x, y)) = frame.image.first_non_finite() {
            return Err(RelightError::Invalid(format!(
                "relit pixel ({x}, {y}) is not finite (exceeds the f32 range)"
            )));
        }
        let rows = self.dims.pixels() * self.dims.channels as usize;
        Ok(FrameStats {
            light_transform: t1 - t0,
            multiply: t1.elapsed(),
            lights: k,
            nonzeros: (rows * k) as u64,
            ..FrameStats::default()
        })
    }
}
