//! The camera-inside-geometry check: a camera enclosed by surfaces that it
//! sees from behind is inside an object, and a distant environment cannot
//! light anything it sees, so the bake would be all zero.
//!
//! [`Scene::build`] traces [`PROBES`] rays from the eye in directions spread
//! evenly over the whole sphere (a spherical Fibonacci set) and fails when
//! every one of them hits a surface and more than [`INSIDE_LIMIT`] of them
//! hit its back (clockwise) side. That is what a camera inside a closed,
//! outward-wound mesh sees: from inside a closed surface, the first surface
//! along any ray is a back face.
//!
//! Open surfaces never trigger it, since they are two-sided: under a plane
//! or inside a box that misses a face, probe rays escape through the
//! opening. (An opening narrower than the probes' spacing, about 3.6°, can
//! go unnoticed.) A room whose walls face the camera is seen from the front
//! and passes, as does an enclosure with mixed winding. The probes rely on
//! watertight tracing (Woop, Benthin, Wald 2013; see [`Scene`]): no probe
//! slips out through an edge of a closed mesh.

use crate::error::{BakeError, Result};
use crate::world::Scene;
use glam::DVec3;

/// Fraction of the probe rays that must hit a back face (all of them
/// hitting something) for the camera to count as inside geometry.
pub const INSIDE_LIMIT: f64 = 0.9;
/// Probe rays traced from the eye.
pub const PROBES: usize = 4096;

/// `n` unit directions spread evenly over the sphere: spherical Fibonacci
/// points, `z = 1 − (2i + 1)/n`, azimuth `i·π(3 − √5)`.
pub(crate) fn sphere_directions(n: usize) -> impl Iterator<Item = DVec3> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n).map(move |i| {
        let z = 1.0 - (2 * i + 1) as f64 / n as f64;
        let r = (1.0 - z * z).max(0.0).sqrt();
        let (s, c) = (golden * i as f64).sin_cos();
        DVec3::new(r * c, r * s, z)
    })
}

impl Scene {
    /// Fails with [`BakeError::CameraInsideGeometry`] when the eye is
    /// enclosed by surfaces seen from behind (see the module docs).
    pub(crate) fn check_camera(&self) -> Result<()> {
        let Some(eye) = self.camera().map(|c| c.eye) else {
            return Ok(());
        };
        let mut back = 0usize;
        for d in sphere_directions(PROBES) {
            match self.intersect(eye, d) {
                None => return Ok(()),
                Some(h) => back += usize::from(h.back),
            }
        }
        let frac = back as f64 / PROBES as f64;
        if frac > INSIDE_LIMIT {
            return Err(BakeError::CameraInsideGeometry {
                eye: eye.to_array(),
                back_fraction: frac,
                limit: INSIDE_LIMIT,
            });
        }
        Ok(())
    }
}
