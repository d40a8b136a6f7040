//! Direction conventions: cubemap texels (the columns of T) and lat-long
//! environment maps. World space is Y-up.
//!
//! Cubemap: OpenGL's face order and orientation (the `(sc, tc, ma)` table of
//! the OpenGL specification, "Cube Map Texture Selection"). Column index
//! `j = face·n² + row·n + col`, faces `+X, −X, +Y, −Y, +Z, −Z`, and texel
//! `(row, col)` is centred at `s = (col + 0.5)/n`, `t = (row + 0.5)/n`.
//!
//! Lat-long: `u = atan2(x, −z) / 2π mod 1`, `v = acos(y) / π`, with `u`
//! growing to the right and `v = 0` at the top row (the convention of
//! Mitsuba 3's `envmap` emitter with an identity transform).

use glam::{DVec3, Vec3};
use std::f64::consts::PI;

/// Face names in index order.
pub const FACE_NAMES: [&str; 6] = ["+X", "-X", "+Y", "-Y", "+Z", "-Z"];

/// Number of cubemap texels (matrix columns) at face resolution `n`.
pub fn texel_count(n: usize) -> usize {
    6 * n * n
}

/// Unit direction through the point `(s, t) ∈ [0, 1]²` of `face`.
pub fn face_point_direction(face: usize, s: f64, t: f64) -> DVec3 {
    let sc = 2.0 * s - 1.0;
    let tc = 2.0 * t - 1.0;
    let d = match face {
        0 => DVec3::new(1.0, -tc, -sc),
        1 => DVec3::new(-1.0, -tc, sc),
        2 => DVec3::new(sc, 1.0, tc),
        3 => DVec3::new(sc, -1.0, -tc),
        4 => DVec3::new(sc, -tc, 1.0),
        _ => DVec3::new(-sc, -tc, -1.0),
    };
    d.normalize()
}

/// The face a direction hits and its face coordinates `(s, t) ∈ [0, 1]²`.
/// Any finite non-zero vector works; the zero vector (or a non-finite one)
/// maps to the centre of `+Z`.
pub fn direction_face_point(d: DVec3) -> (usize, f64, f64) {
    let a = d.abs();
    let (face, sc, tc, ma) = if a.x >= a.y && a.x >= a.z {
        if d.x >= 0.0 {
            (0, -d.z, -d.y, a.x)
        } else {
            (1, d.z, -d.y, a.x)
        }
    } else if a.y >= a.z {
        if d.y >= 0.0 {
            (2, d.x, d.z, a.y)
        } else {
            (3, d.x, -d.z, a.y)
        }
    } else if d.z >= 0.0 {
        (4, d.x, -d.y, a.z)
    } else {
        (5, -d.x, -d.y, a.z)
    };
    if ma == 0.0 || !ma.is_finite() {
        return (4, 0.5, 0.5);
    }
    (face, 0.5 * (sc / ma + 1.0), 0.5 * (tc / ma + 1.0))
}

/// Column index of the texel `(face, row, col)`.
pub fn texel_index(n: usize, face: usize, row: usize, col: usize) -> usize {
    (face * n + row) * n + col
}

/// `(face, row, col)` of column `j`.
pub fn texel_coords(n: usize, j: usize) -> (usize, usize, usize) {
    (j / (n * n), (j / n) % n, j % n)
}

/// Unit direction through the centre of texel `j`.
pub fn texel_direction(n: usize, j: usize) -> Vec3 {
    let (face, row, col) = texel_coords(n, j);
    let nf = n as f64;
    face_point_direction(face, (col as f64 + 0.5) / nf, (row as f64 + 0.5) / nf).as_vec3()
}

/// The texel (column index) a direction falls in.
pub fn direction_texel(n: usize, d: Vec3) -> usize {
    let (face, s, t) = direction_face_point(d.as_dvec3());
    let col = ((s * n as f64) as usize).min(n - 1);
    let row = ((t * n as f64) as usize).min(n - 1);
    texel_index(n, face, row, col)
}

/// Solid angle of the face region `[s0, s1] × [t0, t1]` (face coordinates),
/// exact: the cube's area element integrated in closed form.
pub fn face_rect_solid_angle(s0: f64, s1: f64, t0: f64, t1: f64) -> f64 {
    let f = |a: f64, b: f64| (a * b).atan2((a * a + b * b + 1.0).sqrt());
    let (a0, a1, b0, b1) = (
        2.0 * s0 - 1.0,
        2.0 * s1 - 1.0,
        2.0 * t0 - 1.0,
        2.0 * t1 - 1.0,
    );
    f(a1, b1) - f(a0, b1) - f(a1, b0) + f(a0, b0)
}

/// Solid angle of texel `j` in steradians (the 6·n² texels sum to 4π).
pub fn texel_solid_angle(n: usize, j: usize) -> f64 {
    let (_, row, col) = texel_coords(n, j);
    let nf = n as f64;
    face_rect_solid_angle(
        col as f64 / nf,
        (col + 1) as f64 / nf,
        row as f64 / nf,
        (row + 1) as f64 / nf,
    )
}

/// Lat-long coordinates `(u, v) ∈ [0, 1)×[0, 1]` of a unit direction.
pub fn latlong_uv(d: DVec3) -> (f64, f64) {
    let u = (d.x.atan2(-d.z) / (2.0 * PI)).rem_euclid(1.0);
    let v = d.y.clamp(-1.0, 1.0).acos() / PI;
    (u, v)
}

/// Unit direction of lat-long coordinates `(u, v)`.
pub fn latlong_direction(u: f64, v: f64) -> DVec3 {
    let (phi, theta) = (2.0 * PI * u, PI * v);
    DVec3::new(
        phi.sin() * theta.sin(),
        theta.cos(),
        -phi.cos() * theta.sin(),
    )
}
