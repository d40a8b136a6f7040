//! The spatial BRDF slices, `∫_texel f_r(ω, ω_o) cos θ dω` over the target
//! texels for each view texel, computed once per orbit of the square's
//! symmetries.
//!
//! The hemi-octahedral map ([`super::maps`]) turns each symmetry of its
//! square (the dihedral group of order 8: quarter turns and mirrors of the
//! texel grid) into an orthogonal map of directions that keeps `+z`: a
//! quarter turn about the normal or a mirror in a plane through it. It
//! maps texel centres and sub-samples to texel centres and sub-samples on
//! a grid of any side. An isotropic BRDF is unchanged by both kinds, so
//! the slice of view `g·v` is the slice of view `v` with its texels moved
//! by `g`. Each orbit of views (up to 8) then costs one slice; for the
//! analytic BRDFs the moved slices equal the ones computed per view to the
//! bit. A measured table is binned by the difference azimuth folded by
//! reciprocity alone (`φ_d` and `φ_d + π` share a bin, `φ_d` and `−φ_d`
//! do not), so only the quarter turns leave it unchanged; in-plane pairs
//! lie on its bin edges, where rounding picks the bin either way.

use super::brdf::{Brdf, SliceConfig};
use super::maps::{hemi_decode, subsample, texel_center};
use glam::DVec3;

/// A symmetry of the square grid: `(x, y)` swapped, then either flipped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Square {
    swap: bool,
    flip_x: bool,
    flip_y: bool,
}

impl Square {
    /// The four quarter turns (the identity first).
    const TURNS: [Square; 4] = [
        Square::new(false, false, false),
        Square::new(true, false, true),
        Square::new(false, true, true),
        Square::new(true, true, false),
    ];

    /// The four mirrors.
    const MIRRORS: [Square; 4] = [
        Square::new(false, false, true),
        Square::new(false, true, false),
        Square::new(true, false, false),
        Square::new(true, true, true),
    ];

    const fn new(swap: bool, flip_x: bool, flip_y: bool) -> Square {
        Square {
            swap,
            flip_x,
            flip_y,
        }
    }

    /// The symmetries that leave `brdf` unchanged.
    pub(crate) fn of(brdf: &Brdf) -> Vec<Square> {
        let mut all = Square::TURNS.to_vec();
        if !matches!(brdf, Brdf::Measured(_)) {
            all.extend(Square::MIRRORS);
        }
        all
    }

    /// Texel `t` of a side-`n` grid moved by the symmetry.
    pub(crate) fn apply(self, n: usize, t: usize) -> usize {
        let (x, y) = (t % n, t / n);
        let (a, b) = if self.swap { (y, x) } else { (x, y) };
        let a = if self.flip_x { n - 1 - a } else { a };
        let b = if self.flip_y { n - 1 - b } else { b };
        b * n + a
    }
}

/// Each target texel's sub-sample directions and Jacobians, the same for
/// every view.
pub(crate) struct SubSamples {
    m: usize,
    per_texel: usize,
    samples: Vec<(DVec3, f64)>,
}

impl SubSamples {
    pub(crate) fn new(cfg: &SliceConfig) -> SubSamples {
        let (m, s) = (cfg.m, cfg.supersample);
        let samples = (0..m * m)
            .flat_map(|t| {
                (0..s).flat_map(move |j| {
                    (0..s).map(move |i| {
                        let (u, v) = subsample(m, t, s, i, j);
                        hemi_decode(u, v)
                    })
                })
            })
            .collect();
        SubSamples {
            m,
            per_texel: s * s,
            samples,
        }
    }

    /// The spatial slice of view `wo`: per target texel, `∫ f cos dω`.
    pub(crate) fn slice(&self, brdf: &Brdf, wo: DVec3) -> Vec<[f64; 3]> {
        let area = 1.0 / (self.m * self.m * self.per_texel) as f64;
        self.samples
            .chunks_exact(self.per_texel)
            .map(|texel| {
                let mut acc = [0.0; 3];
                for &(wi, jac) in texel {
                    let f = brdf.eval(wi, wo);
                    for c in 0..3 {
                        acc[c] += f[c] * wi.z * jac * area;
                    }
                }
                acc
            })
            .collect()
    }
}

/// The views of a side-`views` grid grouped by orbit: per orbit, its first
/// view (the least index) and every view of it with the symmetry that
/// moves the first there.
pub(crate) fn orbits(views: usize, symmetries: &[Square]) -> Vec<(usize, Vec<(usize, Square)>)> {
    (0..views * views)
        .filter(|&v| symmetries.iter().all(|g| g.apply(views, v) >= v))
        .map(|first| {
            let mut members: Vec<(usize, Square)> = Vec::with_capacity(symmetries.len());
            for &g in symmetries {
                let v = g.apply(views, first);
                if members.iter().all(|&(w, _)| w != v) {
                    members.push((v, g));
                }
            }
            (first, members)
        })
        .collect()
}

/// The direction at the centre of view texel `v`.
pub(crate) fn view_direction(views: usize, v: usize) -> DVec3 {
    let (u, w) = texel_center(views, v);
    hemi_decode(u, w).0
}

/// `spatial`, the slice of some view, with its texels moved by `g` (the
/// slice of that view moved by `g`).
pub(crate) fn moved(spatial: &[[f64; 3]], m: usize, g: Square) -> Vec<[f64; 3]> {
    let mut out = vec![[0.0; 3]; spatial.len()];
    for (t, &value) in spatial.iter().enumerate() {
        out[g.apply(m, t)] = value;
    }
    out
}
