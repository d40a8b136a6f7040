//! Watertight ray/triangle intersection: Woop, Benthin, Wald 2013,
//! "Watertight Ray/Triangle Intersection", JCGT 2(1).
//!
//! The ray is moved to start at the origin and to run along +z: a
//! translation, a permutation of the axes that makes z the ray's largest
//! direction component (swapping x and y when it is negative, which keeps
//! the winding), and a shear. Every vertex is transformed on its own, so a
//! vertex shared by neighbouring triangles lands on exactly the same 2D
//! point in each of them. The edge function of an edge (the 2D cross
//! product of its end points, `q.x·p.y − q.y·p.x`) is then computed from the
//! same two points in both triangles that share it, in opposite order,
//! which gives exact negatives in floating point: a ray is on the same side
//! of a shared edge for both triangles, so a ray through an edge or a vertex
//! of a closed mesh hits at least one of the triangles around it. An edge
//! function that rounds to exactly 0 is recomputed in double precision
//! (the products of two `f32` are exact there), per edge, so that both
//! triangles of the edge take the same branch.
//!
//! Both windings are hit (no back-face culling); a hit counts when its
//! distance lies in the ray's `[tmin, tmax]`.

use glam::{Vec3A, Vec3Swizzles};

/// A triangle, stored by coordinate: `axes[k]` holds coordinate `k` of its
/// three vertices, bit-identical to the ones its neighbours share.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Tri {
    axes: [Vec3A; 3],
}

impl Tri {
    /// The triangle with vertices `v`.
    pub(crate) fn new(v: [Vec3A; 3]) -> Tri {
        Tri {
            axes: [0, 1, 2].map(|k| Vec3A::new(v[0][k], v[1][k], v[2][k])),
        }
    }

    /// Its three vertices.
    pub(crate) fn vertices(&self) -> [Vec3A; 3] {
        let [x, y, z] = self.axes;
        [0, 1, 2].map(|i| Vec3A::new(x[i], y[i], z[i]))
    }
}

/// A ray prepared for [`WtRay::hit`]: its origin (each coordinate splat)
/// and Woop et al.'s axis permutation `[kx, ky, kz]` and shear
/// `[Sx, Sy, Sz] = [d[kx]/d[kz], d[ky]/d[kz], 1/d[kz]]`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct WtRay {
    org: [Vec3A; 3],
    k: [usize; 3],
    shear: [f32; 3],
}

impl WtRay {
    /// The ray from `org` along `dir` (any non-zero length).
    pub(crate) fn new(org: Vec3A, dir: Vec3A) -> WtRay {
        let a = dir.abs();
        let kz = if a.x >= a.y && a.x >= a.z {
            0
        } else if a.y >= a.z {
            1
        } else {
            2
        };
        let (mut kx, mut ky) = ((kz + 1) % 3, (kz + 2) % 3);
        if dir[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        WtRay {
            org: [0, 1, 2].map(|k| Vec3A::splat(org[k])),
            k: [kx, ky, kz],
            shear: [dir[kx] / dir[kz], dir[ky] / dir[kz], 1.0 / dir[kz]],
        }
    }

    /// The distance along the ray (in units of its direction's length) to
    /// `tri`, or infinity when the ray misses it or the hit lies outside
    /// `[tmin, tmax]`. The three vertices are processed side by side: lane
    /// `i` of every vector belongs to vertex `i` (or to the edge opposite
    /// it), with the same operations, in the same order, as the paper's
    /// scalar code.
    #[inline(always)]
    pub(crate) fn hit(&self, tri: &Tri, tmin: f32, tmax: f32) -> f32 {
        let c = [0, 1, 2].map(|k| tri.axes[k] - self.org[k]);
        let ([kx, ky, kz], [sx, sy, sz]) = (self.k, self.shear);
        // Sheared 2D positions (x, y) and scaled depths (z) of A, B, C.
        let (x, y, z) = (c[kx] - sx * c[kz], c[ky] - sy * c[kz], sz * c[kz]);
        // (U, V, W) = edge functions of BC, CA, AB: q.x·p.y − q.y·p.x.
        let e = edges(x, y);
        if e.cmplt(Vec3A::ZERO).any() && e.cmpgt(Vec3A::ZERO).any() {
            return f32::INFINITY;
        }
        let det = e.x + e.y + e.z;
        if det == 0.0 || !det.is_finite() {
            return f32::INFINITY;
        }
        // t = T/det, compared as T·sign(det) against the range·|det|.
        let t_scaled = e.x * z.x + e.y * z.y + e.z * z.z;
        let (ts, d) = if det < 0.0 {
            (-t_scaled, -det)
        } else {
            (t_scaled, det)
        };
        if ts < tmin * d || ts > tmax * d {
            return f32::INFINITY;
        }
        t_scaled / det
    }
}

/// The edge functions `(U, V, W)` of the edges BC, CA, AB from the sheared
/// coordinates `x = (Ax, Bx, Cx)`, `y = (Ay, By, Cy)`:
/// `U = Cx·By − Cy·Bx`, `V = Ax·Cy − Ay·Cx`, `W = Bx·Ay − By·Ax`. A value
/// that rounds to 0 is recomputed in double precision (per edge, so that
/// both triangles sharing the edge take the same branch).
#[inline(always)]
fn edges(x: Vec3A, y: Vec3A) -> Vec3A {
    let e = x.zxy() * y.yzx() - y.zxy() * x.yzx();
    let zero = e.cmpeq(Vec3A::ZERO);
    if !zero.any() {
        return e;
    }
    let (xd, yd) = (x.as_dvec3(), y.as_dvec3());
    let exact = xd.zxy() * yd.yzx() - yd.zxy() * xd.yzx();
    Vec3A::select(zero, exact.as_vec3a(), e)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri(a: [f32; 3], b: [f32; 3], c: [f32; 3]) -> Tri {
        Tri::new([a.into(), b.into(), c.into()])
    }

    #[test]
    fn hits_both_windings_at_the_right_distance() {
        let front = tri([-1.0, 0.0, -1.0], [-1.0, 0.0, 1.0], [1.0, 0.0, 0.0]);
        let back = tri([-1.0, 0.0, -1.0], [1.0, 0.0, 0.0], [-1.0, 0.0, 1.0]);
        for (o, d) in [
            ([-0.2, 2.0, 0.1], [0.0, -1.0, 0.0]),
            ([-0.2, -3.0, 0.1], [0.0, 2.0, 0.0]),
        ] {
            let ray = WtRay::new(o.into(), d.into());
            for t in [front, back] {
                let expect = (o[1] / -d[1]).abs();
                assert!((ray.hit(&t, 0.0, f32::INFINITY) - expect).abs() < 1e-6);
                assert_eq!(ray.hit(&t, 0.0, expect * 0.5), f32::INFINITY, "beyond tmax");
                assert_eq!(ray.hit(&t, expect * 2.0, f32::INFINITY), f32::INFINITY);
            }
        }
        // Outside the triangle, and pointing away from it.
        let ray = WtRay::new([1.5, 2.0, 0.0].into(), [0.0, -1.0, 0.0].into());
        assert_eq!(ray.hit(&front, 0.0, f32::INFINITY), f32::INFINITY);
        let ray = WtRay::new([0.0, 2.0, 0.0].into(), [0.0, 1.0, 0.0].into());
        assert_eq!(ray.hit(&front, 0.0, f32::INFINITY), f32::INFINITY);
    }

    /// Rays through points on the shared edge of two triangles (a quad's
    /// diagonal, at an odd orientation) hit at least one of them.
    #[test]
    fn shared_edge_has_no_crack() {
        let q = [
            Vec3A::new(-1.3, 0.31, -0.7),
            Vec3A::new(0.2, 0.77, 1.9),
            Vec3A::new(1.1, -0.4, 0.6),
            Vec3A::new(-0.4, -0.9, -1.6),
        ];
        let (t0, t1) = (Tri::new([q[0], q[1], q[2]]), Tri::new([q[0], q[2], q[3]]));
        let o = Vec3A::new(0.3, 5.0, -0.2);
        // Interior points of the diagonal (its ends are corners of the quad,
        // where rounding may leave the ray just outside).
        for i in 1..10_000 {
            let s = i as f32 / 10_000.0;
            let p = q[0] + (q[2] - q[0]) * s;
            let ray = WtRay::new(o, p - o);
            let hit = ray
                .hit(&t0, 0.0, f32::INFINITY)
                .min(ray.hit(&t1, 0.0, f32::INFINITY));
            assert!(hit.is_finite(), "crack at s = {s}");
        }
    }
}
