//! The square parameterizations of the sphere and of the upper hemisphere
//! (Praun and Hoppe 2003, as used by Wang et al. 2006, §3), the local frame
//! of a normal, and texel solid angles.
//!
//! Conventions: a map of side `n` has texel `(x, y)` at index `y·n + x`,
//! covering `u ∈ [x/n, (x+1)/n)`, `v ∈ [y/n, (y+1)/n)`; `p = 2·(u, v) − 1`.
//! - **Octahedral** (sphere): the upper half `|px| + |py| ≤ 1` is `z ≥ 0`,
//!   `d ∝ (px, py, 1 − |px| − |py|)`; the four outer triangles fold onto
//!   `z < 0`.
//! - **Hemi-octahedral** (the local frame's upper hemisphere, `+z` the
//!   normal): the square rotated by 45°, `(x', y') = ((px + py)/2,
//!   (px − py)/2)`, `d ∝ (x', y', 1 − |x'| − |y'|)`.
//!
//! On both maps the solid angle is `dω = J · du dv` with `J = 4 / |q|³` for
//! the octahedral map and `J = 2 / |q|³` for the hemi-octahedral one, where
//! `q` is the point on the octahedron `|x| + |y| + |z| = 1` (the fold and
//! the 45° rotation are affine with `|det|` 1 and ½), so the maps cover 4π
//! and 2π.

use glam::DVec3;

/// Direction of the point `(u, v)` of the octahedral map, and the Jacobian
/// `dω / (du dv)` there.
pub fn oct_decode(u: f64, v: f64) -> (DVec3, f64) {
    let (mut x, mut y) = (2.0 * u - 1.0, 2.0 * v - 1.0);
    let z = 1.0 - x.abs() - y.abs();
    if z < 0.0 {
        let (ax, ay) = (x.abs(), y.abs());
        x = (1.0 - ay).copysign(x);
        y = (1.0 - ax).copysign(y);
    }
    let q = DVec3::new(x, y, z);
    let len = q.length();
    (q / len, 4.0 / (len * len * len))
}

/// `(u, v) ∈ [0, 1]²` of a direction on the octahedral map (`d` need not be
/// unit length; it must not be zero).
pub fn oct_encode(d: DVec3) -> (f64, f64) {
    let q = d / (d.x.abs() + d.y.abs() + d.z.abs());
    let (mut x, mut y) = (q.x, q.y);
    if q.z < 0.0 {
        let (ax, ay) = (x.abs(), y.abs());
        x = (1.0 - ay).copysign(x);
        y = (1.0 - ax).copysign(y);
    }
    (0.5 * (x + 1.0), 0.5 * (y + 1.0))
}

/// Direction of the point `(u, v)` of the hemi-octahedral map, and the
/// Jacobian `dω / (du dv)` there.
pub fn hemi_decode(u: f64, v: f64) -> (DVec3, f64) {
    let (px, py) = (2.0 * u - 1.0, 2.0 * v - 1.0);
    let (x, y) = (0.5 * (px + py), 0.5 * (px - py));
    let q = DVec3::new(x, y, (1.0 - x.abs() - y.abs()).max(0.0));
    let len = q.length();
    (q / len, 2.0 / (len * len * len))
}

/// `(u, v) ∈ [0, 1]²` of a direction of the upper hemisphere on the
/// hemi-octahedral map; a direction below the horizon is first moved onto
/// it (`z` clamped to 0).
pub fn hemi_encode(d: DVec3) -> (f64, f64) {
    let d = DVec3::new(d.x, d.y, d.z.max(0.0));
    let s = d.x.abs() + d.y.abs() + d.z;
    let (x, y) = if s > 0.0 {
        (d.x / s, d.y / s)
    } else {
        (0.0, 0.0)
    };
    (0.5 * (x + y + 1.0), 0.5 * (x - y + 1.0))
}

/// The texel of side-`n` map containing `(u, v)` (clamped to the map).
pub fn texel_of(n: usize, u: f64, v: f64) -> usize {
    // `as usize` truncates towards zero and takes negatives and NaN to 0,
    // so it is `floor` clamped to 0 without a call to libm's `floor`
    // (step 2 takes five per surface point).
    let c = |t: f64| ((t * n as f64) as usize).min(n - 1);
    c(v) * n + c(u)
}

/// Bilinear interpolation on a side-`n` square grid (values at texel
/// centres, the square not folded: the hemi-octahedral map, whose border
/// is the horizon): the four texels around `(u, v)` and their weights,
/// clamped to the border texels past their centres.
pub fn square_bilinear(n: usize, u: f64, v: f64) -> [(usize, f64); 4] {
    let last = n as i64 - 1;
    let axis = |t: f64| {
        let f = (t * n as f64 - 0.5).clamp(0.0, last as f64);
        let i0 = floor(f).clamp(0, last);
        (i0 as usize, (i0 + 1).min(last) as usize, f - i0 as f64)
    };
    let ((x0, x1, ax), (y0, y1, ay)) = (axis(u), axis(v));
    [
        (y0 * n + x0, (1.0 - ax) * (1.0 - ay)),
        (y0 * n + x1, ax * (1.0 - ay)),
        (y1 * n + x0, (1.0 - ax) * ay),
        (y1 * n + x1, ax * ay),
    ]
}

/// `(u, v)` of the centre of texel `t` of a side-`n` map.
pub fn texel_center(n: usize, t: usize) -> (f64, f64) {
    let (x, y) = (t % n, t / n);
    ((x as f64 + 0.5) / n as f64, (y as f64 + 0.5) / n as f64)
}

/// `(u, v)` of sub-sample `(i, j)` of an `s × s` grid over texel `t`.
pub fn subsample(n: usize, t: usize, s: usize, i: usize, j: usize) -> (f64, f64) {
    let (x, y) = ((t % n) as f64, (t / n) as f64);
    let f = |c: f64, k: usize| (c + (k as f64 + 0.5) / s as f64) / n as f64;
    (f(x, i), f(y, j))
}

/// Solid angle of every texel of a side-`n` map whose Jacobian is `jac`,
/// by the `s × s` midpoint rule per texel.
pub fn solid_angles(n: usize, s: usize, jac: impl Fn(f64, f64) -> f64) -> Vec<f64> {
    let area = 1.0 / (n * n * s * s) as f64;
    (0..n * n)
        .map(|t| {
            let mut sum = 0.0;
            for j in 0..s {
                for i in 0..s {
                    let (u, v) = subsample(n, t, s, i, j);
                    sum += jac(u, v);
                }
            }
            sum * area
        })
        .collect()
}

/// The local frame of a normal: columns `(s, t, n)`, local `+z` the normal,
/// built without branches on the normal's direction except its sign
/// (Duff et al. 2017, "Building an orthonormal basis, revisited").
#[derive(Clone, Copy, Debug)]
pub struct Frame {
    /// First tangent.
    pub s: DVec3,
    /// Second tangent.
    pub t: DVec3,
    /// The normal.
    pub n: DVec3,
}

impl Frame {
    /// The frame of unit normal `n`.
    pub fn new(n: DVec3) -> Frame {
        let sign = 1.0f64.copysign(n.z);
        let a = -1.0 / (sign + n.z);
        let b = n.x * n.y * a;
        Frame {
            s: DVec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
            t: DVec3::new(b, sign + n.y * n.y * a, -n.y),
            n,
        }
    }

    /// A local direction in global coordinates.
    pub fn to_global(&self, d: DVec3) -> DVec3 {
        self.s * d.x + self.t * d.y + self.n * d.z
    }

    /// A global direction in local coordinates.
    pub fn to_local(&self, d: DVec3) -> DVec3 {
        DVec3::new(self.s.dot(d), self.t.dot(d), self.n.dot(d))
    }
}

/// `x.floor()` as an integer, exactly, for `|x| < 2⁶³`, without a call to
/// libm's `floor` (baseline x86-64 has no rounding instruction).
fn floor(x: f64) -> i64 {
    let t = x as i64;
    t - i64::from((t as f64) > x)
}

/// Bilinear interpolation on an octahedral grid of side `n` (values at
/// texel centres): the four texels around direction `d` and their weights.
/// Past the square's edges the octahedral fold is followed (column −1 of
/// row `y` is column 0 of row `n − 1 − y`, and likewise for rows).
pub fn oct_bilinear(n: usize, d: DVec3) -> [(usize, f64); 4] {
    let (u, v) = oct_encode(d);
    let (fx, fy) = (u * n as f64 - 0.5, v * n as f64 - 0.5);
    let (x0, y0) = (floor(fx), floor(fy));
    let (ax, ay) = (fx - x0 as f64, fy - y0 as f64);
    let at = |x: i64, y: i64| {
        let last = n as i64 - 1;
        let (mut x, mut y) = (x, y);
        if x < 0 || x > last {
            x = x.clamp(0, last);
            y = last - y;
        }
        if y < 0 || y > last {
            y = y.clamp(0, last);
            x = last - x;
        }
        (y * n as i64 + x) as usize
    };
    [
        (at(x0, y0), (1.0 - ax) * (1.0 - ay)),
        (at(x0 + 1, y0), ax * (1.0 - ay)),
        (at(x0, y0 + 1), (1.0 - ax) * ay),
        (at(x0 + 1, y0 + 1), ax * ay),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The integer floors equal libm's on integers, their neighbours,
    /// signed zeros, negatives, NaN and the map's edges.
    #[test]
    fn integer_floors_equal_libm() {
        let mut values = vec![0.0, -0.0, f64::NAN, 1e18, -1e18, 0.5, -0.5, -1.5];
        for k in -70..70 {
            let x = f64::from(k) * 0.5;
            values.extend([x, x.next_up(), x.next_down()]);
        }
        for x in values {
            if !x.is_nan() {
                assert_eq!(floor(x), x.floor() as i64, "{x}");
            }
            for n in [1, 2, 7, 64] {
                let libm = ((x * n as f64).floor().max(0.0) as usize).min(n - 1);
                let c = texel_of(n, x, 0.0) % n;
                assert_eq!(c, libm, "{x} at n = {n}");
            }
        }
    }
}
