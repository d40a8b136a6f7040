//! Where a matrix's rows come from: a row index becomes the surface samples
//! whose reflected light the row holds. Today rows are the pixels of a
//! pinhole camera ([`RowSource::Camera`]); a texture-space bake adds the
//! texels of a mesh's parameterization as another source, and the
//! transport integral of [`crate::transport`] is the same for both.

use crate::sampling::{mix64, rotation, wrap};
use crate::world::{Camera, Hit, Scene};
use glam::DVec3;
use ltm_codec::RowLayout;

/// Key of a row's pixel-sample rotation (decorrelates rows).
const PIXEL_KEY: u64 = 0x5049_5845_4c00_0000;

/// What the rows of a bake are.
#[derive(Clone, Copy, Debug)]
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
        }
    }

    /// Sub-samples averaged into each row (K in the transport's definition).
    pub fn samples_per_row(&self) -> u32 {
        match self {
            RowSource::Camera { spp, .. } => *spp,
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
        }
    }
}
