//! Drawing a relit texture on its mesh from any camera (geometry
//! relighting, Cheslack-Postava et al. 2007 §4.1).
//!
//! A texture-space `.ltm` file carries its geometry image: each texel's
//! surface point, normal and valid bit ([`ltm_codec::Surface`]). The grid
//! of valid texels *is* the mesh drawn here ([`TexturedMesh`]): every grid
//! cell whose four texels are valid becomes two triangles (split along the
//! shorter diagonal in 3D), a cell with three valid texels one. A relit
//! texture is view-independent for Lambertian surfaces, so one relight
//! serves every view.
//!
//! [`TexturedMesh::render`] rasterizes the triangles in a pinhole camera
//! ([`ViewCamera`], the bake's camera model) with a depth buffer and
//! `ss × ss` regular samples per pixel (box-filtered: antialiased
//! silhouettes); each sample takes the perspective-correct texture
//! coordinate of its triangle and a bilinear lookup of the relit texture
//! over the valid texels among the four nearest (weights renormalized,
//! so empty texels never bleed in). Pixels that see no surface are black.
//!
//! Cells of a `uv` layout that join two charts (neighbouring in the
//! texture, far apart on the surface) must not be drawn: a triangle with
//! an edge longer than [`SEAM_FACTOR`] times the median grid edge is left
//! out. The `sphere` layout's square is also joined along its border,
//! where the octahedral unfolding folds it: texel `(x, 0)` meets
//! `(S−1−x, 0)`, and likewise on the other three sides.

use crate::error::{RelightError, Result};
use crate::image_io::Image;
use glam::{DVec2, DVec3};
use ltm_codec::{LtmFile, Parameterization, RowLayout, Surface};
use rayon::prelude::*;

/// Triangles with an edge longer than this times the median grid edge are
/// seams between charts and are not drawn.
pub const SEAM_FACTOR: f64 = 16.0;
/// Largest side of a rendered view.
pub const MAX_VIEW_SIDE: u32 = 16384;
/// Largest supersampling factor per pixel side.
pub const MAX_SUPERSAMPLE: u32 = 8;

/// A pinhole camera looking from `eye` at `target`: the bake's camera model
/// (`ltm_bake::Camera`), so that a view and an image-space bake of the same
/// camera line up pixel for pixel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewCamera {
    /// The pinhole.
    pub eye: DVec3,
    /// The point at the image centre.
    pub target: DVec3,
    /// World direction towards the image's top.
    pub up: DVec3,
    /// Vertical field of view, degrees, in (0, 180).
    pub fov: f64,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
}

/// A camera's orthonormal frame.
struct Frame {
    eye: DVec3,
    forward: DVec3,
    right: DVec3,
    up: DVec3,
    tan_half: f64,
}

impl ViewCamera {
    /// Checks every field: finite eye and target apart from each other, an
    /// up direction not parallel to the view, fov in (0, 180), sides in
    /// `1..=MAX_VIEW_SIDE`.
    pub fn validate(&self) -> Result<()> {
        for (what, v) in [
            ("camera eye", self.eye),
            ("camera target", self.target),
            ("camera up", self.up),
        ] {
            if !v.is_finite() {
                return Err(RelightError::range(
                    what,
                    format!("{v}"),
                    "finite coordinates",
                ));
            }
        }
        let d = self.target - self.eye;
        if d.length()
            <= 1e-9
                * self
                    .eye
                    .abs()
                    .max(self.target.abs())
                    .max_element()
                    .max(1e-300)
        {
            return Err(RelightError::Invalid(format!(
                "camera eye {} and target {} coincide",
                self.eye, self.target
            )));
        }
        if d.normalize().cross(self.up.normalize_or_zero()).length() < 1e-9 {
            return Err(RelightError::Invalid(format!(
                "camera up {} is parallel to the view direction {}",
                self.up, d
            )));
        }
        if !(self.fov > 0.0 && self.fov < 180.0) {
            return Err(RelightError::range(
                "camera fov",
                self.fov,
                "0 < fov < 180 degrees",
            ));
        }
        for (what, v) in [("view width", self.width), ("view height", self.height)] {
            if v == 0 || v > MAX_VIEW_SIDE {
                return Err(RelightError::range(what, v, format!("1..={MAX_VIEW_SIDE}")));
            }
        }
        Ok(())
    }

    /// View `k` of an orbit of `count`: the eye turned by `k·360°/count`
    /// about the axis through `target` along `up`.
    pub fn orbit(&self, k: usize, count: usize) -> ViewCamera {
        let axis = self.up.normalize();
        let angle = std::f64::consts::TAU * k as f64 / count.max(1) as f64;
        let rot = glam::DQuat::from_axis_angle(axis, angle);
        ViewCamera {
            eye: self.target + rot * (self.eye - self.target),
            ..*self
        }
    }

    fn frame(&self) -> Frame {
        let forward = (self.target - self.eye).normalize();
        let right = forward.cross(self.up.normalize()).normalize();
        Frame {
            eye: self.eye,
            forward,
            right,
            up: right.cross(forward),
            tan_half: (self.fov.to_radians() * 0.5).tan(),
        }
    }
}

/// The mesh of a geometry image, ready to draw.
#[derive(Clone, Debug)]
pub struct TexturedMesh {
    size: usize,
    positions: Vec<DVec3>,
    normals: Vec<DVec3>,
    valid: Vec<bool>,
    /// Triangles as texel indices.
    triangles: Vec<[u32; 3]>,
}

impl TexturedMesh {
    /// The mesh of a texture-space file; an image-space file is an error.
    pub fn from_file(file: &LtmFile) -> Result<TexturedMesh> {
        let dims = file.meta().dims;
        let RowLayout::Texture {
            size,
            parameterization,
        } = dims.rows
        else {
            return Err(RelightError::Invalid(
                "this is an image-space file (its rows are the pixels of a fixed camera); drawing a view needs a texture-space file, baked with a [texture] section".into(),
            ));
        };
        let surface = file.surface().ok_or_else(|| {
            RelightError::Invalid("the texture-space file has no surface data".into())
        })?;
        TexturedMesh::new(size, parameterization, surface)
    }

    /// The mesh of an `size × size` geometry image.
    pub fn new(
        size: u32,
        parameterization: Parameterization,
        surface: &Surface,
    ) -> Result<TexturedMesh> {
        let s = size as usize;
        if surface.len() != s * s {
            return Err(RelightError::Invalid(format!(
                "{} surface points for a {size}×{size} texture",
                surface.len()
            )));
        }
        let p = surface.points();
        let positions: Vec<DVec3> = p
            .iter()
            .map(|q| DVec3::from(q.position.map(f64::from)))
            .collect();
        let normals: Vec<DVec3> = p
            .iter()
            .map(|q| DVec3::from(q.normal.map(f64::from)))
            .collect();
        let valid: Vec<bool> = p.iter().map(|q| q.valid).collect();
        let mut mesh = TexturedMesh {
            size: s,
            positions,
            normals,
            valid,
            triangles: Vec::new(),
        };
        mesh.triangulate(parameterization == Parameterization::Sphere);
        if mesh.triangles.is_empty() {
            return Err(RelightError::Invalid(
                "the geometry image has no cell of valid texels to draw".into(),
            ));
        }
        Ok(mesh)
    }

    /// Texture side S.
    pub fn size(&self) -> usize {
        self.size
    }

    /// Number of triangles drawn.
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    fn triangulate(&mut self, fold_border: bool) {
        let s = self.size;
        let id = |x: usize, y: usize| (y * s + x) as u32;
        let mut quads = Vec::new();
        for y in 0..s.saturating_sub(1) {
            for x in 0..s - 1 {
                quads.push([id(x, y), id(x + 1, y), id(x, y + 1), id(x + 1, y + 1)]);
            }
        }
        if fold_border && s >= 4 {
            // The octahedral square folds onto itself along each side.
            for x in 0..s / 2 - 1 {
                let (a, b, ma, mb) = (x, x + 1, s - 1 - x, s - 2 - x);
                quads.push([id(a, 0), id(b, 0), id(ma, 0), id(mb, 0)]);
                quads.push([id(a, s - 1), id(b, s - 1), id(ma, s - 1), id(mb, s - 1)]);
                quads.push([id(0, a), id(0, b), id(0, ma), id(0, mb)]);
                quads.push([id(s - 1, a), id(s - 1, b), id(s - 1, ma), id(s - 1, mb)]);
            }
        }
        let limit = SEAM_FACTOR * self.median_edge();
        let ok = |t: &[u32; 3], m: &TexturedMesh| {
            (0..3).all(|k| {
                let (a, b) = (t[k] as usize, t[(k + 1) % 3] as usize);
                m.valid[a] && m.valid[b] && (m.positions[a] - m.positions[b]).length() <= limit
            })
        };
        let mut tris = Vec::with_capacity(2 * quads.len());
        for [a, b, c, d] in quads {
            let p = |i: u32| self.positions[i as usize];
            // Split along the shorter diagonal (a–d or b–c).
            let pair = if (p(a) - p(d)).length_squared() <= (p(b) - p(c)).length_squared() {
                [[a, b, d], [a, d, c]]
            } else {
                [[a, b, c], [b, d, c]]
            };
            let all = [a, b, c, d].iter().all(|&i| self.valid[i as usize]);
            if all {
                tris.extend(pair.into_iter().filter(|t| ok(t, self)));
            } else {
                // Three valid corners make one triangle.
                let v: Vec<u32> = [a, b, d, c]
                    .into_iter()
                    .filter(|&i| self.valid[i as usize])
                    .collect();
                if v.len() == 3 && ok(&[v[0], v[1], v[2]], self) {
                    tris.push([v[0], v[1], v[2]]);
                }
            }
        }
        self.triangles = tris;
    }

    /// Median length of the edges between valid neighbouring texels.
    fn median_edge(&self) -> f64 {
        let s = self.size;
        let mut e = Vec::new();
        for y in 0..s {
            for x in 0..s {
                let k = y * s + x;
                for n in [(x + 1 < s).then(|| k + 1), (y + 1 < s).then(|| k + s)]
                    .into_iter()
                    .flatten()
                {
                    if self.valid[k] && self.valid[n] {
                        e.push((self.positions[k] - self.positions[n]).length());
                    }
                }
            }
        }
        if e.is_empty() {
            return f64::INFINITY;
        }
        let mid = e.len() / 2;
        *e.select_nth_unstable_by(mid, f64::total_cmp).1
    }

    /// An error when `eye` is inside the mesh: most of 26 probe rays from it
    /// that hit the mesh hit the inside of a surface (whose normals face
    /// away from the eye).
    pub fn check_outside(&self, eye: DVec3) -> Result<()> {
        let mut dirs = Vec::new();
        for x in -1..=1 {
            for y in -1..=1 {
                for z in -1..=1 {
                    if (x, y, z) != (0, 0, 0) {
                        dirs.push(DVec3::new(x as f64, y as f64, z as f64 + 0.013).normalize());
                    }
                }
            }
        }
        let results: Vec<Option<bool>> = dirs.par_iter().map(|&d| self.probe(eye, d)).collect();
        let hits = results.iter().flatten().count();
        let inside = results.iter().flatten().filter(|&&back| back).count();
        if hits > 0 && 3 * inside > 2 * dirs.len() {
            return Err(RelightError::Invalid(format!(
                "the camera eye {eye} is inside the mesh ({inside} of {} probe rays from it hit the inside of the surface); place it outside",
                dirs.len()
            )));
        }
        Ok(())
    }

    /// The nearest hit along a ray: `Some(true)` when it hits a back face.
    fn probe(&self, o: DVec3, d: DVec3) -> Option<bool> {
        let mut best: Option<(f64, usize)> = None;
        for (i, t) in self.triangles.iter().enumerate() {
            let [a, b, c] = t.map(|k| self.positions[k as usize]);
            if let Some(dist) = ray_triangle(o, d, a, b, c) {
                if best.is_none_or(|(bd, _)| dist < bd) {
                    best = Some((dist, i));
                }
            }
        }
        let (_, i) = best?;
        let n: DVec3 = self.triangles[i]
            .iter()
            .map(|&k| self.normals[k as usize])
            .sum();
        Some(n.dot(d) > 0.0)
    }

    /// Draws the mesh textured with `texture` (the relit texture, S × S)
    /// from `camera`, with `ss × ss` samples per pixel.
    pub fn render(&self, texture: &Image, camera: &ViewCamera, ss: u32) -> Result<Image> {
        camera.validate()?;
        if !(1..=MAX_SUPERSAMPLE).contains(&ss) {
            return Err(RelightError::range(
                "supersampling",
                ss,
                format!("1..={MAX_SUPERSAMPLE}"),
            ));
        }
        if texture.width != self.size || texture.height != self.size {
            return Err(RelightError::Invalid(format!(
                "the texture is {}×{}, the geometry image {}×{}",
                texture.width, texture.height, self.size, self.size
            )));
        }
        let f = camera.frame();
        let (w, h) = (camera.width as usize, camera.height as usize);
        let ssz = ss as usize;
        let projected = self.project(&f, w as f64 * ss as f64, h as f64 * ss as f64);
        let mut out = Image::new(w, h);
        const BAND: usize = 8;
        out.data
            .par_chunks_mut(w * BAND)
            .enumerate()
            .for_each(|(band, pixels)| {
                let rows = pixels.len() / w;
                let y0 = band * BAND * ssz;
                let (sw, sh) = (w * ssz, rows * ssz);
                let mut depth = vec![f64::INFINITY; sw * sh];
                let mut uv = vec![DVec2::NAN; sw * sh];
                for t in &projected {
                    raster(t, y0, sw, sh, &mut depth, &mut uv);
                }
                let norm = 1.0 / (ssz * ssz) as f32;
                for (i, px) in pixels.iter_mut().enumerate() {
                    let (x, y) = (i % w, i / w);
                    let mut acc = [0.0f32; 3];
                    for sy in 0..ssz {
                        for sx in 0..ssz {
                            let q = uv[(y * ssz + sy) * sw + x * ssz + sx];
                            if q.is_finite() {
                                let c = self.lookup(texture, q);
                                for ch in 0..3 {
                                    acc[ch] += c[ch];
                                }
                            }
                        }
                    }
                    *px = acc.map(|v| v * norm);
                }
            });
        Ok(out)
    }

    /// Triangles in supersampled screen space (`sw × sh`), with 1/z and
    /// texel coordinates over z; triangles not wholly in front of the
    /// camera are left out.
    fn project(&self, f: &Frame, sw: f64, sh: f64) -> Vec<Projected> {
        let near = 1e-9 * (1.0 + f.eye.abs().max_element());
        let s = self.size;
        let vert = |k: u32| {
            let r = self.positions[k as usize] - f.eye;
            let z = r.dot(f.forward);
            let sx = r.dot(f.right) / (z * f.tan_half * (sw / sh));
            let sy = r.dot(f.up) / (z * f.tan_half);
            let uv = DVec2::new((k as usize % s) as f64 + 0.5, (k as usize / s) as f64 + 0.5);
            (
                DVec2::new((sx + 1.0) * 0.5 * sw, (1.0 - sy) * 0.5 * sh),
                z,
                uv,
            )
        };
        self.triangles
            .par_iter()
            .filter_map(|t| {
                let v = t.map(vert);
                if v.iter().any(|(_, z, _)| {
                    !matches!(z.partial_cmp(&near), Some(std::cmp::Ordering::Greater))
                }) {
                    return None;
                }
                Some(Projected {
                    p: v.map(|x| x.0),
                    inv_z: v.map(|x| 1.0 / x.1),
                    uv_z: v.map(|x| x.2 / x.1),
                })
            })
            .collect()
    }

    /// Bilinear lookup at texel coordinates `q` over the valid texels.
    fn lookup(&self, tex: &Image, q: DVec2) -> [f32; 3] {
        let s = self.size as isize;
        let g = q - DVec2::splat(0.5);
        let (x0, y0) = (g.x.floor() as isize, g.y.floor() as isize);
        let (fx, fy) = (g.x - x0 as f64, g.y - y0 as f64);
        let mut acc = [0.0f64; 3];
        let mut wsum = 0.0;
        for (dx, dy, w) in [
            (0, 0, (1.0 - fx) * (1.0 - fy)),
            (1, 0, fx * (1.0 - fy)),
            (0, 1, (1.0 - fx) * fy),
            (1, 1, fx * fy),
        ] {
            let (x, y) = (
                (x0 + dx).clamp(0, s - 1) as usize,
                (y0 + dy).clamp(0, s - 1) as usize,
            );
            let k = y * self.size + x;
            if w > 0.0 && self.valid[k] {
                let c = tex.data[k];
                for ch in 0..3 {
                    acc[ch] += w * c[ch] as f64;
                }
                wsum += w;
            }
        }
        if wsum <= 0.0 {
            let k = (q.y.floor().clamp(0.0, (s - 1) as f64) as usize) * self.size
                + q.x.floor().clamp(0.0, (s - 1) as f64) as usize;
            return tex.data[k];
        }
        acc.map(|v| (v / wsum) as f32)
    }
}

/// A triangle in supersampled screen space.
struct Projected {
    p: [DVec2; 3],
    inv_z: [f64; 3],
    uv_z: [DVec2; 3],
}

/// Rasterizes `t` into the band of sample rows `y0 .. y0 + sh` (sample
/// centres at half-integers), keeping the nearest surface per sample.
fn raster(t: &Projected, y0: usize, sw: usize, sh: usize, depth: &mut [f64], uv: &mut [DVec2]) {
    let [a, b, c] = t.p;
    let area = (b - a).perp_dot(c - a);
    if area == 0.0 || !area.is_finite() {
        return;
    }
    let lo = a.min(b).min(c);
    let hi = a.max(b).max(c);
    let x_lo = (lo.x - 0.5).ceil().max(0.0) as usize;
    let x_hi = ((hi.x - 0.5).floor().min(sw as f64 - 1.0)).max(-1.0);
    let y_lo = (lo.y - 0.5).ceil().max(y0 as f64) as usize;
    let y_hi = ((hi.y - 0.5).floor().min((y0 + sh) as f64 - 1.0)).max(-1.0);
    if x_hi < 0.0 || y_hi < 0.0 {
        return;
    }
    let (x_hi, y_hi) = (x_hi as usize, y_hi as usize);
    for y in y_lo..=y_hi {
        for x in x_lo..=x_hi {
            let q = DVec2::new(x as f64 + 0.5, y as f64 + 0.5);
            let w1 = (q - a).perp_dot(c - a) / area;
            let w2 = (b - a).perp_dot(q - a) / area;
            let w0 = 1.0 - w1 - w2;
            if w0 < 0.0 || w1 < 0.0 || w2 < 0.0 {
                continue;
            }
            let iz = w0 * t.inv_z[0] + w1 * t.inv_z[1] + w2 * t.inv_z[2];
            let z = 1.0 / iz;
            let i = (y - y0) * sw + x;
            if z < depth[i] {
                depth[i] = z;
                uv[i] = (w0 * t.uv_z[0] + w1 * t.uv_z[1] + w2 * t.uv_z[2]) * z;
            }
        }
    }
}

/// Distance along unit `d` from `o` to triangle `abc`, if hit (either
/// side; Möller–Trumbore).
fn ray_triangle(o: DVec3, d: DVec3, a: DVec3, b: DVec3, c: DVec3) -> Option<f64> {
    let (e1, e2) = (b - a, c - a);
    let p = d.cross(e2);
    let det = e1.dot(p);
    if det.abs() < 1e-300 {
        return None;
    }
    let inv = 1.0 / det;
    let s = o - a;
    let u = s.dot(p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(e1);
    let v = d.dot(q) * inv;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let t = e2.dot(q) * inv;
    (t > 0.0).then_some(t)
}
