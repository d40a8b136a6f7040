//! Where a matrix's rows come from: a row index becomes the surface samples
//! whose reflected light the row holds. Rows are the pixels of a pinhole
//! camera ([`RowSource::Camera`]) or the texels of a texture over a mesh
//! ([`RowSource::Texture`], [`crate::texture`]); the transport integral of
//! [`crate::transport`] is the same for both.

use crate::sampling::{mix64, rotation, wrap};
use crate::texture::TexelMap;
use crate::world::{Camera, Hit, Scene};
use glam::{DVec2, DVec3};
use ltm_codec::{RowLayout, SurfacePoint};
use std::sync::Arc;

/// Key of a row's pixel-sample rotation (decorrelates rows).
const PIXEL_KEY: u64 = 0x5049_5845_4c00_0000;

/// What the rows of a bake are.
#[derive(Clone, Debug)]
#[non_exhaustive]
pub enum RowSource {
    /// One row per pixel of `camera`, `p = y·width + x` with `y` from the
    /// top. Each row averages `spp` sub-samples spread over the pixel's area
    /// (a box filter): the pixel centre when `spp = 1`, else rotated
    /// Hammersley points.
    Camera {
        /// The camera.
        camera: Camera,
        /// Sub-samples per pixel.
        spp: u32,
    },
    /// One row per texel of a `S × S` texture over a mesh, `k = y·S + x`
    /// with `y` from the top (v down). Each row averages `spp` sub-samples
    /// spread over the texel's square, mapped onto the surface: its
    /// footprint. Invalid texels (off the mesh) are zero rows.
    Texture {
        /// Texture point → surface point.
        map: Arc<TexelMap>,
        /// Sub-samples per texel.
        spp: u32,
    },
}

/// One surface sample of a row: what a sub-sample sees, and the direction
/// from the surface back towards the viewer.
#[derive(Clone, Copy, Debug)]
pub struct RowSample {
    /// The surface point, its normals and material.
    pub hit: Hit,
    /// Unit direction from the hit towards the viewer (`ω_o`).
    pub wo: DVec3,
}

impl RowSource {
    /// The grid the rows lie on.
    pub fn layout(&self) -> RowLayout {
        match self {
            RowSource::Camera { camera, .. } => RowLayout::Image {
                width: camera.width,
                height: camera.height,
            },
            RowSource::Texture { map, .. } => RowLayout::Texture {
                size: map.size(),
                parameterization: map.parameterization(),
            },
        }
    }

    /// Sub-samples averaged into each row (K in the transport's definition).
    pub fn samples_per_row(&self) -> u32 {
        match self {
            RowSource::Camera { spp, .. } | RowSource::Texture { spp, .. } => *spp,
        }
    }

    /// Where row `p` lies, for the surface data of the raw store: for a
    /// camera pixel, the first hit of the ray through its centre (its point
    /// and shading normal, facing the camera), invalid when that ray
    /// escapes.
    pub(crate) fn surface_point(&self, scene: &Scene, p: usize) -> SurfacePoint {
        match self {
            RowSource::Camera { camera, .. } => {
                let w = camera.width as usize;
                let (x, y) = ((p % w) as f64 + 0.5, (p / w) as f64 + 0.5);
                match scene.intersect(camera.eye, camera.direction(x, y)) {
                    Some(hit) => SurfacePoint::new(
                        hit.point.as_vec3().to_array(),
                        hit.ns.as_vec3().to_array(),
                    ),
                    None => SurfacePoint::INVALID,
                }
            }
            RowSource::Texture { map, .. } => {
                let s = map.size() as usize;
                let q = DVec2::new((p % s) as f64 + 0.5, (p / s) as f64 + 0.5);
                match map.locate(q).filter(|_| map.is_valid(p)) {
                    Some(h) => {
                        SurfacePoint::new(h.point.as_vec3().to_array(), h.ns.as_vec3().to_array())
                    }
                    None => SurfacePoint::INVALID,
                }
            }
        }
    }

    /// Per-row state of [`RowSource::sample`]: the rotation of the pixel
    /// sample pattern of row `p`.
    pub(crate) fn row_rotation(&self, p: usize) -> [f64; 2] {
        rotation(mix64(p as u64 ^ PIXEL_KEY))
    }

    /// Sub-sample `k` of row `p`, or `None` when it sees no surface.
    /// `pattern` holds the unrotated sample points (one per sub-sample) and
    /// `rot` the row's rotation from [`RowSource::row_rotation`].
    pub(crate) fn sample(
        &self,
        scene: &Scene,
        p: usize,
        k: usize,
        pattern: &[[f64; 2]],
        rot: [f64; 2],
    ) -> Option<RowSample> {
        match self {
            RowSource::Camera { camera, spp } => {
                let w = camera.width as usize;
                let (x, y) = ((p % w) as f64, (p / w) as f64);
                let (dx, dy) = if *spp == 1 {
                    (0.5, 0.5)
                } else {
                    let [u, v] = pattern[k];
                    (wrap(u, rot[0]), wrap(v, rot[1]))
                };
                let dir = camera.direction(x + dx, y + dy);
                let hit = scene.intersect(camera.eye, dir)?;
                Some(RowSample { hit, wo: -dir })
            }
            RowSource::Texture { map, spp } => {
                if !map.is_valid(p) {
                    return None;
                }
                let s = map.size() as usize;
                let (dx, dy) = if *spp == 1 {
                    (0.5, 0.5)
                } else {
                    let [u, v] = pattern[k];
                    (wrap(u, rot[0]), wrap(v, rot[1]))
                };
                let q = DVec2::new((p % s) as f64 + dx, (p / s) as f64 + dy);
                let h = map.locate(q)?;
                let hit = Hit {
                    point: h.point,
                    ng: h.ng,
                    ns: h.ns,
                    back: false,
                    material: h.material,
                };
                Some(RowSample { hit, wo: h.ns })
            }
        }
    }
}
