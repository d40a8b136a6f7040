//! Drawing a relit texture on its mesh from any camera (geometry
//! relighting, Cheslack-Postava et al. 2007 §4.1).
//!
//! A texture-space `.ltm` file carries its geometry image: each texel's
//! surface point, normal and valid bit ([`ltm_codec::Surface`]), and, for
//! the `atlas` and `uv` layouts, the receiving mesh itself
//! ([`ltm_codec::ReceiverMesh`]: positions, normals, texture coordinates in
//! texel units, counter-clockwise triangles). [`TexturedMesh`] is what is
//! drawn, shared by `ltm render`, the report and `ltm view` (which draws
//! the very same vertices, texture coordinates and triangles in WebGL):
//!
//! - **A stored mesh** ([`TexturedMesh::from_mesh`]) is drawn as its own
//!   triangles.
//! - **Without one** (the `sphere` layout; files without a mesh,
//!   [`TexturedMesh::new`]) the grid of valid texels is the mesh: one
//!   vertex per texel (its surface point, the texel's centre as texture
//!   coordinate), every grid cell whose four texels are valid two
//!   triangles (split along the shorter diagonal in 3D), a cell with three
//!   valid texels one.
//!
//! A relit texture is view-independent for Lambertian surfaces, so one
//! relight serves every view.
//!
//! [`TexturedMesh::render`] rasterizes the triangles in a pinhole camera
//! ([`ViewCamera`], the bake's camera model) with a depth buffer and
//! `ss × ss` regular samples per pixel (box-filtered: antialiased
//! silhouettes); each sample takes the perspective-correct texture
//! coordinate and surface point of its triangle and a bilinear lookup of
//! the relit texture that never mixes texels of two charts: of the four
//! nearest texels it reads only the valid ones whose surface record lies
//! near the shaded point: full weight within the triangle's reach
//! ([`CHART_REACH`] texel footprints, the footprint being the square root
//! of the triangle's 3D area over its texel area), falling linearly to
//! zero at twice the reach, weights renormalized. With none
//! readable it takes the valid texel of the 5 × 5 around whose record is
//! nearest to the point (or, with none valid, the texel holding the
//! coordinate). A stored mesh's back faces are culled (an open surface's
//! two sides are separate triangles with texels of their own; a closed
//! one's back faces are hidden anyway). The grid is one chart per cell: its reach is unlimited
//! (valid texels only). Pixels that see no surface are black.
//!
//! Grid cells of a `uv` layout that join two charts (neighbouring in the
//! texture, far apart on the surface) must not be drawn: a triangle with
//! an edge longer than [`SEAM_FACTOR`] times the median grid edge is left
//! out. The `sphere` layout is one chart, so none of its cells is a seam
//! (its long edges are stretched parts of the surface). The `sphere`
//! layout's square is also joined along its border, where the octahedral
//! unfolding folds it: texel `(x, 0)` meets `(S−1−x, 0)`, and likewise on
//! the other three sides. Those fold triangles' texture coordinates are
//! not contiguous, so they are shaded by blending their corners' texels
//! (the texel holding each corner's coordinate) with the barycentrics.

use crate::error::{RelightError, Result};
use crate::image_io::Image;
use glam::{DVec2, DVec3};
use ltm_codec::{Charge, Limits, LtmFile, Parameterization, ReceiverMesh, RowLayout, Surface};
use rayon::prelude::*;

/// Triangles with an edge longer than this times the median grid edge are
/// seams between charts and are not drawn.
pub const SEAM_FACTOR: f64 = 16.0;
/// How far, in texel footprints of its triangle, a texel's surface record
/// may lie from a shaded point of a stored mesh for the lookup to read the
/// texel: farther texels belong to another chart (neighbours in the
/// texture, apart on the surface) and are never mixed in.
pub const CHART_REACH: f64 = 2.0;
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

/// The larger coordinate magnitude of `a` and `b`, at least the smallest
/// positive normal `f64`: a scale that brings both within `[-1, 1]`.
fn magnitude(a: DVec3, b: DVec3) -> f64 {
    a.abs().max(b.abs()).max_element().max(f64::MIN_POSITIVE)
}

/// `v` at unit length, computed without overflow or underflow (a far
/// camera's `v` may have components whose squares overflow); `None` for the
/// zero vector or a non-finite one.
fn unit(v: DVec3) -> Option<DVec3> {
    let m = v.abs().max_element();
    (m > 0.0 && m.is_finite()).then(|| (v / m).normalize())
}

/// The unit direction from `eye` to `target`, defined however far apart
/// they are; `None` when they coincide (closer than 1e-9 of their
/// magnitude).
fn view_direction(eye: DVec3, target: DVec3) -> Option<DVec3> {
    let s = magnitude(eye, target);
    let d = target / s - eye / s;
    if d.length() <= 1e-9 {
        return None;
    }
    unit(d)
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
        let Some(forward) = view_direction(self.eye, self.target) else {
            return Err(RelightError::Invalid(format!(
                "camera eye {} and target {} coincide (closer than 1e-9 of their magnitude): a view needs a target apart from the eye",
                self.eye, self.target
            )));
        };
        let Some(up) = unit(self.up) else {
            return Err(RelightError::range(
                "camera up",
                format!("{}", self.up),
                "a nonzero direction",
            ));
        };
        if forward.cross(up).length() < 1e-9 {
            return Err(RelightError::Invalid(format!(
                "camera up {} is parallel to the view from eye {} to target {}: give an up direction across the view (--up)",
                self.up, self.eye, self.target
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
        let axis = unit(self.up).unwrap_or(DVec3::Y);
        let angle = std::f64::consts::TAU * k as f64 / count.max(1) as f64;
        let rot = glam::DQuat::from_axis_angle(axis, angle);
        // Scaled, so that a far eye does not overflow the difference.
        let s = magnitude(self.eye, self.target);
        ViewCamera {
            eye: (self.target / s + rot * (self.eye / s - self.target / s)) * s,
            ..*self
        }
    }

    fn frame(&self) -> Frame {
        let forward = view_direction(self.eye, self.target).unwrap_or(DVec3::NEG_Z);
        let up = unit(self.up).unwrap_or(DVec3::Y);
        let right = forward.cross(up).normalize();
        Frame {
            eye: self.eye,
            forward,
            right,
            up: right.cross(forward),
            tan_half: (self.fov.to_radians() * 0.5).tan(),
        }
    }
}

/// The mesh drawn for a texture-space file, ready to draw: vertices with a
/// texture coordinate each, triangles, and the texels' surface records that
/// the lookup checks samples against.
#[derive(Clone, Debug)]
pub struct TexturedMesh {
    size: usize,
    /// Drawn vertices (world space).
    positions: Vec<DVec3>,
    /// Their shading normals (zero: use the face normal).
    normals: Vec<DVec3>,
    /// Their texture coordinates, in texel units (`x` rightwards, `y`
    /// downwards, texel `(x, y)` covering `[x, x+1] × [y, y+1]`).
    uvs: Vec<DVec2>,
    /// Triangles as vertex indices.
    triangles: Vec<[u32; 3]>,
    /// Per triangle: how far (world units) a texel's surface record may lie
    /// from the shaded point for the lookup to read the texel (the chart
    /// rule); infinite for the grid of a geometry image (one chart).
    reach: Vec<f64>,
    /// Per triangle: true when it joins texels across a fold of the
    /// octahedral square (its texture coordinates are not contiguous, so
    /// it is shaded by blending its corners' texels instead).
    folded: Vec<bool>,
    /// Triangles facing away from the camera are not drawn: true for a
    /// stored mesh (counter-clockwise fronts; an open surface's two sides
    /// are separate triangles with texels of their own), false for the
    /// grid.
    cull_back: bool,
    /// Per texel: its surface record's position.
    records: Vec<DVec3>,
    /// Per texel: whether it lies on the surface.
    valid: Vec<bool>,
    /// The budget the mesh and every view's buffers are charged to.
    limits: Limits,
    /// The mesh's bytes, charged to `limits`.
    _charge: Charge,
}

/// A mesh stored in the file, if any.
fn stored_mesh(file: &LtmFile) -> Option<&ReceiverMesh> {
    file.mesh()
}

/// Bytes a grid mesh holds per texel: a vertex (position, normal, texture
/// coordinate), the texel's record and flag, and up to two triangles
/// (indices, reach, fold flag).
const GRID_BYTES_PER_TEXEL: u64 = 24 + 24 + 16 + 24 + 1 + 2 * (12 + 8 + 1);
/// Bytes a stored mesh holds per vertex and per triangle, beside the texels'
/// records (25 bytes each).
const MESH_BYTES_PER_VERTEX: u64 = 24 + 24 + 16;
const MESH_BYTES_PER_TRIANGLE: u64 = 12 + 8 + 1;

impl TexturedMesh {
    /// The mesh of a texture-space file, charged (with the buffers of each
    /// view it draws) to `limits`: its stored receiver mesh when it has one
    /// ([`TexturedMesh::from_mesh`]), else the grid of its geometry image
    /// ([`TexturedMesh::new`]). An image-space file is an error.
    pub fn from_file(file: &LtmFile, limits: &Limits) -> Result<TexturedMesh> {
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
        match stored_mesh(file) {
            Some(m) => TexturedMesh::from_mesh(size, parameterization, surface, m, limits),
            None => TexturedMesh::new(size, parameterization, surface, limits),
        }
    }

    /// An empty mesh over the records of an `size × size` surface, holding
    /// its `charge` to `limits`.
    fn over(size: u32, surface: &Surface, limits: &Limits, charge: Charge) -> Result<TexturedMesh> {
        let s = size as usize;
        if surface.len() != s * s {
            return Err(RelightError::Invalid(format!(
                "{} surface points for a {size}×{size} texture",
                surface.len()
            )));
        }
        let p = surface.points();
        Ok(TexturedMesh {
            size: s,
            positions: Vec::new(),
            normals: Vec::new(),
            uvs: Vec::new(),
            triangles: Vec::new(),
            reach: Vec::new(),
            folded: Vec::new(),
            cull_back: false,
            records: p
                .iter()
                .map(|q| DVec3::from(q.position.map(f64::from)))
                .collect(),
            valid: p.iter().map(|q| q.valid).collect(),
            limits: limits.clone(),
            _charge: charge,
        })
    }

    /// The grid mesh of an `size × size` geometry image: one vertex per
    /// texel (at its surface point, with the texel's centre as texture
    /// coordinate) and the cells of valid texels as triangles, charged
    /// (with the buffers of each view it draws) to `limits`.
    pub fn new(
        size: u32,
        parameterization: Parameterization,
        surface: &Surface,
        limits: &Limits,
    ) -> Result<TexturedMesh> {
        let charge = limits.check_alloc(
            "mesh of the geometry image",
            surface.len() as u64,
            GRID_BYTES_PER_TEXEL,
        )?;
        let mut mesh = TexturedMesh::over(size, surface, limits, charge)?;
        let s = mesh.size;
        mesh.positions = mesh.records.clone();
        mesh.normals = surface
            .points()
            .iter()
            .map(|q| DVec3::from(q.normal.map(f64::from)))
            .collect();
        mesh.uvs = (0..s * s)
            .map(|k| DVec2::new((k % s) as f64 + 0.5, (k / s) as f64 + 0.5))
            .collect();
        mesh.triangulate(parameterization == Parameterization::Sphere);
        mesh.reach = vec![f64::INFINITY; mesh.triangles.len()];
        if mesh.triangles.is_empty() {
            return Err(RelightError::Invalid(
                "the geometry image has no cell of valid texels to draw".into(),
            ));
        }
        Ok(mesh)
    }

    /// The receiver's own triangles over an `size × size` texture whose
    /// texels' records are `surface`, charged (with the buffers of each
    /// view it draws) to `limits`. Each triangle's reach (the chart rule
    /// of the lookup) is [`CHART_REACH`] texel footprints: the square root
    /// of its 3D area over its area in texels.
    pub fn from_mesh(
        size: u32,
        parameterization: Parameterization,
        surface: &Surface,
        mesh: &ReceiverMesh,
        limits: &Limits,
    ) -> Result<TexturedMesh> {
        let _ = parameterization; // every layout draws its stored mesh alike
        mesh.validate(size)?;
        let bytes = surface.len() as u64 * 25
            + mesh.vertex_count() as u64 * MESH_BYTES_PER_VERTEX
            + mesh.triangles.len() as u64 * MESH_BYTES_PER_TRIANGLE;
        let charge = limits.check_alloc("mesh of the receiver", bytes, 1)?;
        let mut out = TexturedMesh::over(size, surface, limits, charge)?;
        let v3 = |p: &[f32; 3]| DVec3::from(p.map(f64::from));
        out.positions = mesh.positions.iter().map(v3).collect();
        out.normals = mesh.normals.iter().map(v3).collect();
        out.uvs = mesh
            .uvs
            .iter()
            .map(|t| DVec2::new(t[0] as f64, t[1] as f64))
            .collect();
        out.triangles = mesh.triangles.clone();
        out.folded = vec![false; mesh.triangles.len()];
        out.cull_back = true;
        out.reach = out.triangles.iter().map(|t| out.reach_of(t)).collect();
        Ok(out)
    }

    /// [`CHART_REACH`] texel footprints of triangle `t` (twice its longest
    /// edge where its texture area is zero).
    fn reach_of(&self, t: &[u32; 3]) -> f64 {
        let [a, b, c] = t.map(|k| self.positions[k as usize]);
        let [ta, tb, tc] = t.map(|k| self.uvs[k as usize]);
        let area = (b - a).cross(c - a).length();
        let uv_area = (tb - ta).perp_dot(tc - ta).abs();
        let foot = (area / uv_area).sqrt();
        if uv_area > 0.0 && foot.is_finite() {
            CHART_REACH * foot
        } else {
            2.0 * (b - a).length().max((c - b).length()).max((a - c).length())
        }
    }

    /// Texture side S.
    pub fn size(&self) -> usize {
        self.size
    }

    /// Number of triangles drawn.
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    /// The drawn vertices' positions.
    pub fn positions(&self) -> &[DVec3] {
        &self.positions
    }

    /// The drawn vertices' shading normals (zero: the face normal).
    pub fn normals(&self) -> &[DVec3] {
        &self.normals
    }

    /// The drawn vertices' texture coordinates in texel units.
    pub fn uvs(&self) -> &[DVec2] {
        &self.uvs
    }

    /// The drawn triangles, as vertex indices.
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    /// True when back faces are not drawn (a stored mesh).
    pub fn culls_back_faces(&self) -> bool {
        self.cull_back
    }

    /// Per triangle: the chart rule's reach in world units (infinite: no
    /// limit).
    pub fn reach(&self) -> &[f64] {
        &self.reach
    }

    /// Per triangle: shaded by blending its corners' texels (a fold of the
    /// sphere layout's square) rather than by a lookup.
    pub fn folded(&self) -> &[bool] {
        &self.folded
    }

    /// Per texel: its surface record's position and whether it is valid.
    pub fn records(&self) -> (&[DVec3], &[bool]) {
        (&self.records, &self.valid)
    }

    /// The box around the drawn triangles' corners (lowest and highest
    /// corner), or `None` when there are none.
    pub fn bounds(&self) -> Option<(DVec3, DVec3)> {
        let mut corners = self
            .triangles
            .iter()
            .flatten()
            .map(|&k| self.positions[k as usize]);
        let first = corners.next()?;
        Some(corners.fold((first, first), |(lo, hi), p| (lo.min(p), hi.max(p))))
    }

    fn triangulate(&mut self, fold_border: bool) {
        let s = self.size;
        let id = |x: usize, y: usize| (y * s + x) as u32;
        let mut quads = Vec::new();
        for y in 0..s.saturating_sub(1) {
            for x in 0..s - 1 {
                quads.push((
                    [id(x, y), id(x + 1, y), id(x, y + 1), id(x + 1, y + 1)],
                    false,
                ));
            }
        }
        if fold_border && s >= 4 {
            // The octahedral square folds onto itself along each side.
            for x in 0..s / 2 - 1 {
                let (a, b, ma, mb) = (x, x + 1, s - 1 - x, s - 2 - x);
                for q in [
                    [id(a, 0), id(b, 0), id(ma, 0), id(mb, 0)],
                    [id(a, s - 1), id(b, s - 1), id(ma, s - 1), id(mb, s - 1)],
                    [id(0, a), id(0, b), id(0, ma), id(0, mb)],
                    [id(s - 1, a), id(s - 1, b), id(s - 1, ma), id(s - 1, mb)],
                ] {
                    quads.push((q, true));
                }
            }
        }
        // A sphere layout is one chart with no seams: its long edges are
        // stretched parts of the surface (ears, limbs) and must be drawn.
        let limit = if fold_border {
            f64::INFINITY
        } else {
            SEAM_FACTOR * self.median_edge()
        };
        let ok = |t: &[u32; 3], m: &TexturedMesh| {
            (0..3).all(|k| {
                let (a, b) = (t[k] as usize, t[(k + 1) % 3] as usize);
                m.valid[a] && m.valid[b] && (m.positions[a] - m.positions[b]).length() <= limit
            })
        };
        let mut tris = Vec::with_capacity(2 * quads.len());
        let mut folded = Vec::with_capacity(2 * quads.len());
        for ([a, b, c, d], fold) in quads {
            let p = |i: u32| self.positions[i as usize];
            // Split along the shorter diagonal (a–d or b–c).
            let pair = if (p(a) - p(d)).length_squared() <= (p(b) - p(c)).length_squared() {
                [[a, b, d], [a, d, c]]
            } else {
                [[a, b, c], [b, d, c]]
            };
            let all = [a, b, c, d].iter().all(|&i| self.valid[i as usize]);
            if all {
                for t in pair.into_iter().filter(|t| ok(t, self)) {
                    tris.push(t);
                    folded.push(fold);
                }
            } else {
                // Three valid corners make one triangle.
                let v: Vec<u32> = [a, b, d, c]
                    .into_iter()
                    .filter(|&i| self.valid[i as usize])
                    .collect();
                if v.len() == 3 && ok(&[v[0], v[1], v[2]], self) {
                    tris.push([v[0], v[1], v[2]]);
                    folded.push(fold);
                }
            }
        }
        self.triangles = tris;
        self.folded = folded;
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
        let t = self.triangles[i];
        let mut n: DVec3 = t.iter().map(|&k| self.normals[k as usize]).sum();
        if n.length_squared() < 1e-12 {
            // No shading normals: the counter-clockwise face's normal.
            let [a, b, c] = t.map(|k| self.positions[k as usize]);
            n = (b - a).cross(c - a);
        }
        Some(n.dot(d) > 0.0)
    }

    /// Draws the mesh textured with `texture` (the relit texture, S × S)
    /// from `camera`, with `ss × ss` samples per pixel.
    ///
    /// Triangles are binned by bands of pixel rows, each band is drawn
    /// (in parallel) into its own depth buffer of the nearest triangle and
    /// perspective-correct barycentrics per sample, and each sample is then
    /// shaded once.
    pub fn render(&self, texture: &Image, camera: &ViewCamera, ss: u32) -> Result<Image> {
        camera.validate()?;
        if !(1..=MAX_SUPERSAMPLE).contains(&ss) {
            return Err(RelightError::range(
                "supersampling",
                ss,
                format!("1..={MAX_SUPERSAMPLE}"),
            ));
        }
        texture.check_len()?;
        if texture.width != self.size || texture.height != self.size {
            return Err(RelightError::Invalid(format!(
                "the texture is {}×{}, the geometry image {}×{}",
                texture.width, texture.height, self.size, self.size
            )));
        }
        let f = camera.frame();
        let (w, h) = (camera.width as usize, camera.height as usize);
        let ssz = ss as usize;
        let (sw, sh) = (w * ssz, h * ssz);
        // The view, and one band of samples per thread.
        let _out = self
            .limits
            .check_alloc("rendered view", (w * h) as u64, 12)?;
        let band = (BAND * ssz * sw) as u64;
        let threads = rayon::current_num_threads() as u64;
        let _samples = self
            .limits
            .check_alloc("view sample buffers", band * threads, 32)?;
        let projected = self.project(&f, sw as f64, sh as f64);
        let bins = Bins::new(&projected, BAND * ssz, sh, &self.limits)?;
        let mut out = Image::new(w, h);
        out.data
            .par_chunks_mut(w * BAND)
            .enumerate()
            .for_each(|(band, pixels)| {
                let rows = pixels.len() / w;
                let mut buf = SampleBuffer::new(band * BAND * ssz, sw, rows * ssz);
                for &t in bins.band(band) {
                    buf.raster(&projected[t as usize], t);
                }
                let norm = 1.0 / (ssz * ssz) as f32;
                for (i, px) in pixels.iter_mut().enumerate() {
                    let (x, y) = (i % w, i / w);
                    let mut acc = [0.0f32; 3];
                    for sy in 0..ssz {
                        for sx in 0..ssz {
                            let (t, b) = buf.hit[(y * ssz + sy) * sw + x * ssz + sx];
                            if t != u32::MAX {
                                let c = self.shade(texture, projected[t as usize].tri as usize, b);
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

    /// Triangles in supersampled screen space (`sw × sh`) with 1/z;
    /// triangles not wholly in front of the camera, and back faces where
    /// they are culled, are left out.
    fn project(&self, f: &Frame, sw: f64, sh: f64) -> Vec<Projected> {
        let near = 1e-9 * (1.0 + f.eye.abs().max_element());
        let vert = |k: u32| {
            let r = self.positions[k as usize] - f.eye;
            let z = r.dot(f.forward);
            let sx = r.dot(f.right) / (z * f.tan_half * (sw / sh));
            let sy = r.dot(f.up) / (z * f.tan_half);
            (DVec2::new((sx + 1.0) * 0.5 * sw, (1.0 - sy) * 0.5 * sh), z)
        };
        self.triangles
            .par_iter()
            .enumerate()
            .filter_map(|(i, t)| {
                let v = t.map(vert);
                if v.iter().any(|(_, z)| {
                    !matches!(z.partial_cmp(&near), Some(std::cmp::Ordering::Greater))
                }) {
                    return None;
                }
                let p = v.map(|x| x.0);
                // Screen y points down: a front (counter-clockwise) face
                // has a negative signed area.
                if self.cull_back && (p[1] - p[0]).perp_dot(p[2] - p[0]) > 0.0 {
                    return None;
                }
                Some(Projected {
                    p,
                    inv_z: v.map(|x| 1.0 / x.1),
                    tri: i as u32,
                })
            })
            .collect()
    }

    /// The colour of a sample of triangle `t` at perspective-correct
    /// barycentrics `(b1, b2)`: a lookup at the interpolated texture
    /// coordinate and surface point, or, across a fold of the square (where
    /// the texture coordinates jump), the blend of the corners' texels.
    fn shade(&self, tex: &Image, t: usize, b: [f32; 2]) -> [f32; 3] {
        let w = [1.0 - b[0] as f64 - b[1] as f64, b[0] as f64, b[1] as f64];
        let corners = self.triangles[t].map(|k| k as usize);
        if self.folded[t] {
            let mut acc = [0.0f64; 3];
            for (&k, wk) in corners.iter().zip(w) {
                let c = tex.data[self.texel_at(self.uvs[k])];
                for ch in 0..3 {
                    acc[ch] += wk * c[ch] as f64;
                }
            }
            return acc.map(|v| v as f32);
        }
        let q: DVec2 = corners.iter().zip(w).map(|(&k, wk)| wk * self.uvs[k]).sum();
        let p: DVec3 = corners
            .iter()
            .zip(w)
            .map(|(&k, wk)| wk * self.positions[k])
            .sum();
        self.lookup(tex, q, p, self.reach[t])
    }

    /// The texel holding texel coordinates `q` (clamped into the texture).
    fn texel_at(&self, q: DVec2) -> usize {
        let last = (self.size - 1) as f64;
        let x = q.x.floor().clamp(0.0, last) as usize;
        let y = q.y.floor().clamp(0.0, last) as usize;
        y * self.size + x
    }

    /// The weight of texel `k` for surface point `p` under the chart rule:
    /// 0 when invalid; 1 when its record lies within `reach` of `p`, falling
    /// linearly to 0 at twice `reach` (continuous, so that renderers that
    /// round differently agree near the limit; another chart's texels lie
    /// much farther).
    fn chart_weight(&self, k: usize, p: DVec3, reach: f64) -> f64 {
        if !self.valid[k] {
            return 0.0;
        }
        if reach.is_infinite() {
            return 1.0;
        }
        ((2.0 * reach - self.records[k].distance(p)) / reach).clamp(0.0, 1.0)
    }

    /// Bilinear lookup at texel coordinates `q` of surface point `p`, over
    /// the four nearest texels that are readable (valid, and with their
    /// record within `reach` of `p`: texels of another chart are never
    /// mixed in), weights renormalized. With none readable: the valid texel
    /// nearest to `p` among the 5 × 5 around `q` ([`TexturedMesh::fallback`]).
    fn lookup(&self, tex: &Image, q: DVec2, p: DVec3, reach: f64) -> [f32; 3] {
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
            let w = w * self.chart_weight(k, p, reach);
            if w > 0.0 {
                let c = tex.data[k];
                for ch in 0..3 {
                    acc[ch] += w * c[ch] as f64;
                }
                wsum += w;
            }
        }
        if wsum <= 0.0 {
            return tex.data[self.fallback(q, p)];
        }
        acc.map(|v| (v / wsum) as f32)
    }

    /// The valid texel whose record is nearest to `p` among the 5 × 5
    /// texels around the one holding `q` (the first in row order on a tie),
    /// or the texel holding `q` when none of them is valid.
    fn fallback(&self, q: DVec2, p: DVec3) -> usize {
        let centre = self.texel_at(q);
        let (cx, cy) = ((centre % self.size) as isize, (centre / self.size) as isize);
        let s = self.size as isize;
        let mut best: Option<(f64, usize)> = None;
        for y in (cy - 2).max(0)..=(cy + 2).min(s - 1) {
            for x in (cx - 2).max(0)..=(cx + 2).min(s - 1) {
                let k = (y * s + x) as usize;
                let d = self.records[k].distance_squared(p);
                if self.valid[k] && best.is_none_or(|(bd, _)| d < bd) {
                    best = Some((d, k));
                }
            }
        }
        best.map_or(centre, |(_, k)| k)
    }
}

/// Pixel rows per band of the view drawn by one task.
const BAND: usize = 8;

/// A triangle in supersampled screen space.
struct Projected {
    p: [DVec2; 3],
    inv_z: [f64; 3],
    /// Its index in the mesh.
    tri: u32,
}

impl Projected {
    /// The sample rows `lo..=hi` its box covers (sample centres at
    /// half-integers), clipped to `0..sh`; `None` when empty.
    fn rows(&self, sh: usize) -> Option<(usize, usize)> {
        let [a, b, c] = self.p;
        let lo = (a.y.min(b.y).min(c.y) - 0.5).ceil().max(0.0);
        let hi = (a.y.max(b.y).max(c.y) - 0.5).floor().min(sh as f64 - 1.0);
        (lo.is_finite() && hi.is_finite() && lo <= hi).then_some((lo as usize, hi as usize))
    }
}

/// Triangles listed per band of `rows` sample rows (CSR).
struct Bins {
    start: Vec<usize>,
    items: Vec<u32>,
    /// `items`' bytes, charged.
    _charge: ltm_codec::Charge,
}

impl Bins {
    /// The bins of `tris`; their entries (one per triangle and band it
    /// spans, which a mesh of huge triangles makes many) are charged to
    /// `limits` before they are allocated.
    fn new(tris: &[Projected], rows: usize, sh: usize, limits: &Limits) -> Result<Bins> {
        let bands = sh.div_ceil(rows);
        let spans: Vec<Option<(usize, usize)>> = tris
            .iter()
            .map(|t| t.rows(sh).map(|(lo, hi)| (lo / rows, hi / rows)))
            .collect();
        let mut start = vec![0usize; bands + 1];
        for &(a, b) in spans.iter().flatten() {
            for band in a..=b {
                start[band + 1] += 1;
            }
        }
        for k in 1..start.len() {
            start[k] += start[k - 1];
        }
        let charge = limits.check_alloc("view triangle bins", start[bands] as u64, 4)?;
        let mut fill = start.clone();
        let mut items = vec![0u32; start[bands]];
        for (t, span) in spans.iter().enumerate() {
            if let Some((a, b)) = *span {
                for band in a..=b {
                    items[fill[band]] = t as u32;
                    fill[band] += 1;
                }
            }
        }
        Ok(Bins {
            start,
            items,
            _charge: charge,
        })
    }

    fn band(&self, k: usize) -> &[u32] {
        &self.items[self.start[k]..self.start[k + 1]]
    }
}

/// One band of samples: depth, and the nearest triangle with its
/// perspective-correct barycentrics (`u32::MAX`: no surface).
struct SampleBuffer {
    y0: usize,
    sw: usize,
    sh: usize,
    depth: Vec<f64>,
    hit: Vec<(u32, [f32; 2])>,
}

impl SampleBuffer {
    fn new(y0: usize, sw: usize, sh: usize) -> SampleBuffer {
        SampleBuffer {
            y0,
            sw,
            sh,
            depth: vec![f64::INFINITY; sw * sh],
            hit: vec![(u32::MAX, [0.0; 2]); sw * sh],
        }
    }

    /// Rasterizes triangle `id` into the band's sample rows `y0 .. y0 + sh`,
    /// keeping the nearest surface per sample.
    fn raster(&mut self, t: &Projected, id: u32) {
        let [a, b, c] = t.p;
        let area = (b - a).perp_dot(c - a);
        if area == 0.0 || !area.is_finite() {
            return;
        }
        let lo = a.min(b).min(c);
        let hi = a.max(b).max(c);
        let x_lo = (lo.x - 0.5).ceil().max(0.0) as usize;
        let x_hi = ((hi.x - 0.5).floor().min(self.sw as f64 - 1.0)).max(-1.0);
        let y_lo = (lo.y - 0.5).ceil().max(self.y0 as f64) as usize;
        let y_hi = ((hi.y - 0.5).floor().min((self.y0 + self.sh) as f64 - 1.0)).max(-1.0);
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
                let i = (y - self.y0) * self.sw + x;
                if z < self.depth[i] {
                    self.depth[i] = z;
                    let b1 = w1 * t.inv_z[1] * z;
                    let b2 = w2 * t.inv_z[2] * z;
                    self.hit[i] = (id, [b1 as f32, b2 as f32]);
                }
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

#[cfg(test)]
mod tests {
    use super::*;
    use ltm_codec::SurfacePoint;

    /// The (not equal-area) octahedral map of `[-1, 1]²` onto the unit
    /// sphere: its square's border folds as the sphere layout's does.
    fn octahedral(u: f64, v: f64) -> DVec3 {
        let z = 1.0 - u.abs() - v.abs();
        let (x, y) = if z >= 0.0 {
            (u, v)
        } else {
            ((1.0 - v.abs()).copysign(u), (1.0 - u.abs()).copysign(v))
        };
        DVec3::new(x, y, z).normalize()
    }

    /// A unit sphere as an `s × s` sphere-layout geometry image, and a
    /// texture holding a smooth function of the surface point.
    fn sphere(s: usize) -> (TexturedMesh, Image) {
        let mut pts = Vec::new();
        let mut tex = Image::new(s, s);
        for y in 0..s {
            for x in 0..s {
                let u = 2.0 * (x as f64 + 0.5) / s as f64 - 1.0;
                let v = 1.0 - 2.0 * (y as f64 + 0.5) / s as f64;
                let p = octahedral(u, v);
                pts.push(SurfacePoint::new(
                    p.as_vec3().to_array(),
                    p.as_vec3().to_array(),
                ));
                tex.data[y * s + x] = colour(p);
            }
        }
        let surface = Surface::new(pts).unwrap();
        let mesh = TexturedMesh::new(
            s as u32,
            Parameterization::Sphere,
            &surface,
            &Limits::default(),
        )
        .unwrap();
        (mesh, tex)
    }

    fn colour(p: DVec3) -> [f32; 3] {
        (p * 0.5 + DVec3::splat(0.5)).as_vec3().to_array()
    }

    fn camera(eye: DVec3) -> ViewCamera {
        ViewCamera {
            eye,
            target: DVec3::ZERO,
            up: DVec3::Y,
            fov: 40.0,
            width: 48,
            height: 40,
        }
    }

    /// Every pixel whose centre ray meets the sphere well inside its
    /// outline shows the texture's value at the point it meets, from the
    /// front and from behind, where the square's folded border runs
    /// through the view (a fold's texture coordinates are not contiguous:
    /// interpolating them would read texels from across the square).
    #[test]
    fn views_of_a_sphere_show_the_texture_at_the_point_seen() {
        let (mesh, tex) = sphere(64);
        for eye in [
            DVec3::new(0.0, 0.0, 3.5),
            DVec3::new(0.3, 0.2, -3.5),
            DVec3::new(0.0, 3.5, -0.4),
        ] {
            let cam = camera(eye);
            let img = mesh.render(&tex, &cam, 1).unwrap();
            let f = cam.frame();
            let (w, h) = (cam.width as f64, cam.height as f64);
            let mut checked = 0;
            for y in 0..cam.height as usize {
                for x in 0..cam.width as usize {
                    let sx = 2.0 * (x as f64 + 0.5) / w - 1.0;
                    let sy = 1.0 - 2.0 * (y as f64 + 0.5) / h;
                    let d =
                        (f.forward + f.right * sx * f.tan_half * w / h + f.up * sy * f.tan_half)
                            .normalize();
                    // Ray–unit sphere: |e + t d|² = 1.
                    let b = eye.dot(d);
                    let disc = b * b - (eye.length_squared() - 1.0);
                    let got = img.data[y * cam.width as usize + x];
                    if disc < 0.0 {
                        assert_eq!(got, [0.0; 3], "pixel ({x}, {y}) sees no surface");
                        continue;
                    }
                    // Closest approach at most 0.9 from the centre.
                    if disc < 1.0 - 0.81 {
                        continue;
                    }
                    let p = eye + (-b - disc.sqrt()) * d;
                    let want = colour(p);
                    for c in 0..3 {
                        assert!(
                            (got[c] - want[c]).abs() < 0.02,
                            "eye {eye}: pixel ({x}, {y}) {got:?}, want {want:?}"
                        );
                    }
                    checked += 1;
                }
            }
            assert!(checked > 300, "{checked}");
        }
    }

    /// Supersampling averages a constant texture to itself inside the
    /// outline and to a fraction of it at the silhouette.
    #[test]
    fn supersampled_edges_blend_towards_black() {
        let (mesh, mut tex) = sphere(32);
        tex.data.fill([0.5, 0.25, 1.0]);
        let img = mesh
            .render(&tex, &camera(DVec3::new(0.0, 0.0, 3.0)), 4)
            .unwrap();
        let centre = img.data[20 * 48 + 24];
        assert!((centre[0] - 0.5).abs() < 1e-6 && (centre[2] - 1.0).abs() < 1e-6);
        let partial = img
            .data
            .iter()
            .filter(|p| p[2] > 0.05 && p[2] < 0.95)
            .count();
        assert!(partial > 10, "{partial}");
        assert!(img.data.iter().all(|p| p[2] <= 1.0 + 1e-6));
    }

    #[test]
    fn bad_cameras_and_textures_are_errors() {
        let (mesh, tex) = sphere(16);
        let mut cam = camera(DVec3::new(0.0, 0.0, 3.0));
        cam.eye.x = f64::NAN;
        assert!(mesh.render(&tex, &cam, 1).is_err());
        let cam = camera(DVec3::new(0.0, 0.0, 3.0));
        assert!(mesh.render(&tex, &cam, 0).is_err());
        assert!(mesh.render(&Image::new(8, 8), &cam, 1).is_err());
        // A texture of the right size whose pixels were cut short.
        let mut short = tex.clone();
        short.data.truncate(10);
        let e = mesh.render(&short, &cam, 1).unwrap_err().to_string();
        assert!(e.contains("holds 10 values"), "{e}");
        assert!(mesh.check_outside(DVec3::new(0.1, 0.0, 0.0)).is_err());
        assert!(mesh.check_outside(DVec3::new(0.0, 0.0, 3.0)).is_ok());
        // A degenerate look-at names the eye and the target.
        let mut cam = camera(DVec3::new(0.0, 3.0, 0.0));
        let e = cam.validate().unwrap_err().to_string();
        assert!(
            e.contains("parallel") && e.contains("target") && e.contains("--up"),
            "{e}"
        );
        cam.target = cam.eye;
        let e = cam.validate().unwrap_err().to_string();
        assert!(e.contains("coincide"), "{e}");
    }

    /// A far camera is a valid camera: its view direction is defined even
    /// where the squares of its coordinates overflow, and it draws a finite
    /// image (the sphere smaller than a pixel: background), orbits included.
    #[test]
    fn far_cameras_draw_finite_images() {
        let (mesh, tex) = sphere(16);
        for eye in [
            DVec3::new(0.0, 0.0, 1e6),
            DVec3::new(0.3, 0.2, 1e200),
            DVec3::new(-1e300, 1e300, 1e307),
        ] {
            let cam = camera(eye);
            cam.validate().unwrap();
            let f = cam.frame();
            assert!(f.forward.is_finite() && f.right.is_finite() && f.up.is_finite());
            assert!((f.forward.length() - 1.0).abs() < 1e-12, "{eye}");
            for k in 0..3 {
                let view = cam.orbit(k, 3);
                assert!(view.eye.is_finite(), "{eye} {k}");
                let img = mesh.render(&tex, &view, 1).unwrap();
                assert!(img.first_non_finite().is_none(), "{eye}");
            }
        }
        // Near, the same camera sees the sphere.
        let img = mesh
            .render(&tex, &camera(DVec3::new(0.0, 0.0, 3.0)), 1)
            .unwrap();
        assert!(img.data.iter().any(|p| p[0] > 0.0));
    }

    /// A cube `[-1, 1]³` as a stored mesh of six charts (one per face,
    /// `n × n` quads each, counter-clockwise seen from outside), laid out in
    /// a 3 × 2 grid of 16-texel cells with 2 texels of padding in a 48²
    /// texture; the texels whose centres fall in a chart carry its surface
    /// point, the rest are invalid. Returns the mesh and the records.
    /// [`TexturedMesh::from_mesh`] of an atlas under the default limits.
    fn atlas_mesh(size: u32, surface: &Surface, m: &ReceiverMesh) -> Result<TexturedMesh> {
        TexturedMesh::from_mesh(
            size,
            Parameterization::Atlas,
            surface,
            m,
            &Limits::default(),
        )
    }

    fn cube(n: usize) -> (ReceiverMesh, Surface) {
        const S: usize = 48;
        let mut m = ReceiverMesh::default();
        let mut pts = vec![SurfacePoint::INVALID; S * S];
        for face in 0..6 {
            let (axis, sign) = (face / 2, if face % 2 == 0 { 1.0 } else { -1.0 });
            // Face frame: normal, and u, v with u × v = normal.
            let mut nrm = DVec3::ZERO;
            nrm[axis] = sign;
            let u = DVec3::from(match axis {
                0 => [0.0, 0.0, -sign],
                1 => [sign, 0.0, 0.0],
                _ => [sign, 0.0, 0.0],
            });
            let v = nrm.cross(u);
            let at = |a: f64, b: f64| nrm + u * a + v * b;
            // The chart: a 12-texel square inside its cell; texture y runs
            // down, so the face's +v is the chart's −y.
            let (cx, cy) = ((face % 3 * 16 + 2) as f64, (face / 3 * 16 + 2) as f64);
            let to_uv = |a: f64, b: f64| DVec2::new(cx + 6.0 * (a + 1.0), cy + 6.0 * (1.0 - b));
            let base = m.positions.len() as u32;
            for j in 0..=n {
                for i in 0..=n {
                    let (a, b) = (
                        2.0 * i as f64 / n as f64 - 1.0,
                        2.0 * j as f64 / n as f64 - 1.0,
                    );
                    m.positions.push(at(a, b).as_vec3().to_array());
                    m.normals.push(nrm.as_vec3().to_array());
                    m.uvs.push(to_uv(a, b).as_vec2().to_array());
                }
            }
            let id = |i: usize, j: usize| base + (j * (n + 1) + i) as u32;
            for j in 0..n {
                for i in 0..n {
                    let [a, b, c, d] = [id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)];
                    m.triangles.extend([[a, b, c], [a, c, d]]);
                }
            }
            for y in 0..12 {
                for x in 0..12 {
                    let (a, b) = ((x as f64 + 0.5) / 6.0 - 1.0, 1.0 - (y as f64 + 0.5) / 6.0);
                    let k = (cy as usize + y) * S + cx as usize + x;
                    pts[k] =
                        SurfacePoint::new(at(a, b).as_vec3().to_array(), nrm.as_vec3().to_array());
                }
            }
        }
        (m, Surface::new(pts).unwrap())
    }

    /// A texture holding `f` of each valid texel's record (black elsewhere).
    fn texture_of(surface: &Surface, f: impl Fn(DVec3) -> [f32; 3]) -> Image {
        let s = (surface.len() as f64).sqrt() as usize;
        let mut tex = Image::new(s, s);
        for (t, q) in tex.data.iter_mut().zip(surface.points()) {
            if q.valid {
                *t = f(DVec3::from(q.position.map(f64::from)));
            }
        }
        tex
    }

    /// The world ray through the centre of pixel `(x, y)`.
    fn pixel_ray(cam: &ViewCamera, x: usize, y: usize) -> DVec3 {
        let f = cam.frame();
        let (w, h) = (cam.width as f64, cam.height as f64);
        let sx = 2.0 * (x as f64 + 0.5) / w - 1.0;
        let sy = 1.0 - 2.0 * (y as f64 + 0.5) / h;
        (f.forward + f.right * sx * f.tan_half * w / h + f.up * sy * f.tan_half).normalize()
    }

    /// Where a ray from `o` along `d` enters the box `[-r, r]³`.
    fn box_hit(o: DVec3, d: DVec3, r: f64) -> Option<DVec3> {
        let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
        for a in 0..3 {
            let (lo, hi) = ((-r - o[a]) / d[a], (r - o[a]) / d[a]);
            t0 = t0.max(lo.min(hi));
            t1 = t1.min(lo.max(hi));
        }
        (t0 <= t1).then(|| o + t0 * d)
    }

    /// The stored mesh of a cube with six charts: every pixel whose ray
    /// meets the cube inside its outline shows the texture's value at the
    /// point seen, from cameras that look at edges and corners, where the
    /// view crosses chart seams (neighbouring pixels read different charts,
    /// whose borders are padding).
    #[test]
    fn views_of_a_charted_mesh_show_the_texture_at_the_point_seen() {
        let (m, surface) = cube(3);
        let mesh = atlas_mesh(48, &surface, &m).unwrap();
        assert_eq!(mesh.triangle_count(), 6 * 18);
        let (lo, hi) = mesh.bounds().unwrap();
        assert!((lo + DVec3::ONE).length() < 1e-6 && (hi - DVec3::ONE).length() < 1e-6);
        let f = |p: DVec3| (p * 0.25 + DVec3::splat(0.5)).as_vec3().to_array();
        let tex = texture_of(&surface, f);
        for eye in [
            DVec3::new(3.0, 2.5, 4.0),
            DVec3::new(-4.0, -3.0, 2.0),
            DVec3::new(0.5, 5.0, -3.0),
            DVec3::new(0.0, 0.0, 5.0),
        ] {
            mesh.check_outside(eye).unwrap();
            let cam = camera(eye);
            let img = mesh.render(&tex, &cam, 1).unwrap();
            let (mut checked, mut seams) = (0, 0);
            for y in 0..cam.height as usize {
                for x in 0..cam.width as usize {
                    let d = pixel_ray(&cam, x, y);
                    let got = img.data[y * cam.width as usize + x];
                    let Some(p) = box_hit(eye, d, 1.0) else {
                        assert_eq!(got, [0.0; 3], "eye {eye}: pixel ({x}, {y}) sees nothing");
                        continue;
                    };
                    // Well inside the outline: a smaller cube is hit too.
                    if box_hit(eye, d, 0.96).is_none() {
                        continue;
                    }
                    let want = f(p);
                    for c in 0..3 {
                        assert!(
                            (got[c] - want[c]).abs() < 0.03,
                            "eye {eye}: pixel ({x}, {y}) at {p}: {got:?}, want {want:?}"
                        );
                    }
                    checked += 1;
                    // Within a texel of an edge of the cube: a chart seam.
                    let near_edge = (0..3).filter(|&a| p[a].abs() > 1.0 - 1.0 / 6.0).count() >= 2;
                    seams += usize::from(near_edge);
                }
            }
            assert!(checked > 300, "eye {eye}: {checked}");
            if eye.x != 0.0 {
                assert!(seams > 20, "eye {eye}: {seams} pixels at seams");
            }
        }
        assert!(mesh.check_outside(DVec3::new(0.2, 0.1, 0.0)).is_err());
    }

    /// Two charts that are neighbours in the texture (no padding between
    /// them) but far apart on the surface: a view of one shows none of the
    /// other's colour, even along the texture edge they share (where a
    /// bilinear lookup without the chart rule would read the other's texels).
    #[test]
    fn charts_adjacent_in_the_texture_do_not_bleed() {
        const S: usize = 16;
        // Quad A at z = 0 takes texture columns 0..8, quad B (z = −20, far
        // off to the side) columns 8..16; both 2 × 2 world units.
        let quad = |x0: f32, z: f32, u0: f32| {
            let p = [
                [x0, -1.0, z],
                [x0 + 2.0, -1.0, z],
                [x0 + 2.0, 1.0, z],
                [x0, 1.0, z],
            ];
            let t = [[u0, 16.0], [u0 + 8.0, 16.0], [u0 + 8.0, 0.0], [u0, 0.0]];
            (p, t)
        };
        let mut m = ReceiverMesh::default();
        for (i, (p, t)) in [quad(-1.0, 0.0, 0.0), quad(30.0, -20.0, 8.0)]
            .into_iter()
            .enumerate()
        {
            m.positions.extend(p);
            m.uvs.extend(t);
            m.normals.extend([[0.0, 0.0, 1.0]; 4]);
            let b = 4 * i as u32;
            m.triangles.extend([[b, b + 1, b + 2], [b, b + 2, b + 3]]);
        }
        let mut pts = Vec::new();
        for y in 0..S {
            for x in 0..S {
                let (a, b) = ((x % 8) as f32 + 0.5, y as f32 + 0.5);
                let (x0, z) = if x < 8 { (-1.0, 0.0) } else { (30.0, -20.0) };
                let p = [x0 + a / 4.0, 1.0 - b / 8.0, z];
                pts.push(SurfacePoint::new(p, [0.0, 0.0, 1.0]));
            }
        }
        let surface = Surface::new(pts).unwrap();
        let mesh =
            TexturedMesh::from_mesh(16, Parameterization::Uv, &surface, &m, &Limits::default())
                .unwrap();
        let tex = texture_of(&surface, |p| {
            if p.z == 0.0 {
                [1.0, 0.0, 0.0]
            } else {
                [0.0, 0.0, 1.0]
            }
        });
        let cam = camera(DVec3::new(0.0, 0.0, 3.0));
        let img = mesh.render(&tex, &cam, 2).unwrap();
        let covered = img.data.iter().filter(|p| p[0] > 0.0).count();
        assert!(covered > 400, "{covered}");
        for (i, p) in img.data.iter().enumerate() {
            assert_eq!(p[2], 0.0, "pixel {i} mixes in the far chart: {p:?}");
        }
        // Interior pixels are fully red (nothing renormalized away).
        assert_eq!(img.data[20 * 48 + 24], [1.0, 0.0, 0.0]);
    }

    /// An open surface's two sides (the front counter-clockwise from +z on
    /// texture columns 0..8, its reversed copy on columns 8..16, at the
    /// same points): each camera sees only the side facing it.
    #[test]
    fn each_side_of_a_two_sided_sheet_shows_its_own_texels() {
        const S: usize = 16;
        let p = [
            [-1.0, -1.0, 0.0],
            [1.0, -1.0, 0.0],
            [1.0, 1.0, 0.0],
            [-1.0, 1.0, 0.0],
        ];
        let mut m = ReceiverMesh::default();
        for (side, u0) in [(1.0f32, 0.0f32), (-1.0, 8.0)] {
            let b = m.positions.len() as u32;
            m.positions.extend(p);
            m.normals.extend([[0.0, 0.0, side]; 4]);
            m.uvs
                .extend([[u0, 16.0], [u0 + 8.0, 16.0], [u0 + 8.0, 0.0], [u0, 0.0]]);
            m.triangles.extend(if side > 0.0 {
                [[b, b + 1, b + 2], [b, b + 2, b + 3]]
            } else {
                [[b, b + 2, b + 1], [b, b + 3, b + 2]]
            });
        }
        let mut pts = Vec::new();
        for y in 0..S {
            for x in 0..S {
                let (a, b) = ((x % 8) as f32 + 0.5, y as f32 + 0.5);
                let n = if x < 8 { 1.0 } else { -1.0 };
                pts.push(SurfacePoint::new(
                    [-1.0 + a / 4.0, 1.0 - b / 8.0, 0.0],
                    [0.0, 0.0, n],
                ));
            }
        }
        let surface = Surface::new(pts).unwrap();
        let mesh = atlas_mesh(16, &surface, &m).unwrap();
        assert!(mesh.culls_back_faces());
        let tex = Image {
            width: S,
            height: S,
            data: (0..S * S)
                .map(|k| {
                    if k % S < 8 {
                        [1.0, 0.0, 0.0]
                    } else {
                        [0.0, 0.0, 1.0]
                    }
                })
                .collect(),
        };
        for (z, want) in [(3.0, 0), (-3.0, 2)] {
            let img = mesh
                .render(&tex, &camera(DVec3::new(0.1, 0.2, z)), 1)
                .unwrap();
            let seen: Vec<_> = img
                .data
                .iter()
                .filter(|p| p.iter().any(|&c| c > 0.0))
                .collect();
            assert!(seen.len() > 300, "{}", seen.len());
            assert!(
                seen.iter().all(|p| p[want] == 1.0 && p[2 - want] == 0.0),
                "from z = {z}"
            );
        }
    }

    /// The fallback: a sample whose four nearest texels are all invalid or
    /// of another chart reads the nearest valid texel of its own chart, and
    /// a mesh whose surface is all invalid draws finite colours.
    #[test]
    fn lookups_fall_back_to_the_nearest_valid_texel_and_never_give_nan() {
        let (m, surface) = cube(2);
        let mesh = atlas_mesh(48, &surface, &m).unwrap();
        let tex = texture_of(&surface, |p| p.as_vec3().to_array());
        // Padding of chart 0 (texels 0..2): the nearest texel of the chart
        // is (2, 2), whose record is the surface point nearest (1, 1, 1).
        let p = DVec3::new(1.0, 1.0, 1.0);
        let got = mesh.lookup(&tex, DVec2::new(1.0, 1.0), p, 0.01);
        let want = tex.data[2 * 48 + 2];
        assert_eq!(got, want);
        // No valid texel at all: finite, and from the texel holding q.
        let empty = Surface::new(vec![SurfacePoint::INVALID; 48 * 48]).unwrap();
        let mesh = atlas_mesh(48, &empty, &m).unwrap();
        let img = mesh
            .render(&Image::new(48, 48), &camera(DVec3::new(3.0, 2.0, 4.0)), 2)
            .unwrap();
        assert!(img.first_non_finite().is_none());
        // A bad mesh or surface is an error.
        let mut bad = m.clone();
        bad.uvs[0] = [60.0, 0.0];
        assert!(atlas_mesh(48, &surface, &bad).is_err());
        assert!(atlas_mesh(32, &surface, &m).is_err());
    }

    /// Both constructors charge the caller's limits, not the machine's: a
    /// budget too small for the mesh refuses it, naming it, and one that
    /// holds it keeps the charge while the mesh lives.
    #[test]
    fn meshes_are_charged_to_the_callers_limits() {
        let (m, surface) = cube(1);
        let tiny = Limits::with_max_alloc(1024);
        let err = TexturedMesh::from_mesh(48, Parameterization::Atlas, &surface, &m, &tiny)
            .unwrap_err()
            .to_string();
        assert!(err.contains("mesh of the receiver"), "{err}");
        let (grid, _) = sphere(16);
        let records = grid.records.iter().map(|p| {
            let q = p.as_vec3().to_array();
            SurfacePoint::new(q, q)
        });
        let grid_surface = Surface::new(records.collect()).unwrap();
        let err = TexturedMesh::new(16, Parameterization::Sphere, &grid_surface, &tiny)
            .unwrap_err()
            .to_string();
        assert!(err.contains("mesh of the geometry image"), "{err}");
        let roomy = Limits::with_max_alloc(1 << 30);
        let mesh =
            TexturedMesh::from_mesh(48, Parameterization::Atlas, &surface, &m, &roomy).unwrap();
        assert!(roomy.used_bytes() > 0);
        drop(mesh);
        assert_eq!(roomy.used_bytes(), 0);
    }

    /// What is drawn is exposed as it is drawn: the sphere grid's vertices
    /// are its texels (texture coordinate at the centre), its folds flagged
    /// and without a chart limit; a stored mesh's are its own.
    #[test]
    fn the_drawn_mesh_is_exposed() {
        let (grid, _) = sphere(16);
        assert_eq!(grid.positions().len(), 256);
        assert_eq!(grid.uvs()[17], DVec2::new(1.5, 1.5));
        assert!(grid.folded().iter().any(|&f| f) && grid.reach().iter().all(|r| r.is_infinite()));
        assert_eq!(grid.triangles().len(), grid.folded().len());
        let (m, surface) = cube(1);
        let mesh = atlas_mesh(48, &surface, &m).unwrap();
        assert_eq!(mesh.positions().len(), m.positions.len());
        assert_eq!(mesh.uvs()[0], DVec2::new(2.0, 14.0));
        // A face is 2 × 2 world units over 12 × 12 texels.
        for r in mesh.reach() {
            assert!((r - CHART_REACH / 6.0).abs() < 1e-6, "{r}");
        }
        assert_eq!(mesh.records().0.len(), 48 * 48);
    }
}
