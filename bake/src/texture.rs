//! Texture-space rows: texel `k = y·S + x` of an `S × S` texture laid over
//! one mesh (the *receiver*), for geometry relighting (Cheslack-Postava et
//! al. 2007, §4.1: the matrix columns are then images over the texture, and
//! the same 4D codec applies).
//!
//! A [`TexelMap`] turns a point of the texture square into a point of the
//! receiver's surface. Texture coordinates are in texel units here: `x`
//! from 0 to S rightwards, `y` from 0 to S downwards, so that texel
//! `(x, y)` covers `[x, x+1] × [y, y+1]` and the mesh's `(u, v)` (v up) is
//! at `(u·S, (1 − v)·S)`.
//!
//! Two layouts exist ([`ltm_codec::Parameterization`]):
//!
//! - `uv`: the mesh's own texture coordinates. Triangles are located in a
//!   grid of per-texel candidate lists. A point outside every chart maps
//!   to the nearest chart point (dilation): a texel is valid when its
//!   centre lies within `dilate + ½` texels of a chart, so that filtered
//!   lookups near a chart's edge read surface values, not zeros. Charts
//!   that overlap (a point strictly inside two triangles) are an error, as
//!   are coordinates outside `[0, 1]`; triangles of zero texture area are
//!   skipped (they cover no texel) and counted.
//! - `sphere`: a spherical parameterization of a closed genus-0 mesh
//!   (the `sphere` module), unfolded to the square through the octahedron
//!   (Praun & Hoppe 2003); every texel is valid.
//!
//! A texel's surface samples are spread over its square (rotated
//! Hammersley points, the same pattern as camera pixels), so the texel
//! averages the transport over its footprint on the surface.

use glam::{DVec2, DVec3};

/// The receiving mesh in world space, as the bake places it: vertex
/// positions, per-vertex shading normals (zero where the face normal is
/// used), counter-clockwise non-degenerate triangles, and the texture
/// coordinates of the file, if any.
#[derive(Clone, Debug, Default)]
pub(crate) struct SurfaceMesh {
    pub positions: Vec<DVec3>,
    pub normals: Vec<DVec3>,
    pub triangles: Vec<[u32; 3]>,
    pub uvs: Option<Vec<DVec2>>,
    /// Material index of each triangle.
    pub materials: Vec<u32>,
    /// Index of the scene part (mesh or quad of the receiver) each
    /// triangle comes from.
    pub parts: Vec<u32>,
    /// Triangles of zero area left out when the mesh was placed.
    pub degenerate: usize,
    /// Those triangles (they still join the surface's topology).
    pub degenerate_triangles: Vec<[u32; 3]>,
}

impl SurfaceMesh {
    /// The mesh with vertices at identical positions welded into one (the
    /// surface's topology, for the sphere parameterization), every
    /// triangle kept (zero-area ones too), normals averaged.
    pub fn welded(&self) -> SurfaceMesh {
        let mut id: std::collections::HashMap<[u64; 3], u32> = std::collections::HashMap::new();
        let mut positions = Vec::new();
        let mut normals: Vec<DVec3> = Vec::new();
        let map: Vec<u32> = self
            .positions
            .iter()
            .zip(&self.normals)
            .map(|(p, n)| {
                let key = p.to_array().map(|v| if v == 0.0 { 0 } else { v.to_bits() });
                let next = positions.len() as u32;
                let i = *id.entry(key).or_insert(next);
                if i == next {
                    positions.push(*p);
                    normals.push(DVec3::ZERO);
                }
                normals[i as usize] += *n;
                i
            })
            .collect();
        let triangles = self
            .triangles
            .iter()
            .chain(&self.degenerate_triangles)
            .map(|t| t.map(|i| map[i as usize]))
            .collect();
        SurfaceMesh {
            positions,
            normals: normals.into_iter().map(|n| n.normalize_or_zero()).collect(),
            triangles,
            uvs: None,
            materials: self
                .materials
                .iter()
                .copied()
                .chain(std::iter::repeat_n(
                    self.materials.first().copied().unwrap_or(0),
                    self.degenerate_triangles.len(),
                ))
                .collect(),
            parts: vec![0; self.triangles.len() + self.degenerate_triangles.len()],
            degenerate: self.degenerate,
            degenerate_triangles: Vec::new(),
        }
    }

    /// Appends `other`, its vertex indices shifted past this mesh's.
    pub fn append(&mut self, other: SurfaceMesh) {
        let base = self.positions.len() as u32;
        let shift = |t: [u32; 3]| t.map(|i| i + base);
        self.uvs = match (self.uvs.take(), other.uvs) {
            (Some(mut a), Some(b)) => {
                a.extend(b);
                Some(a)
            }
            _ => None,
        };
        self.positions.extend(other.positions);
        self.normals.extend(other.normals);
        self.triangles
            .extend(other.triangles.into_iter().map(shift));
        self.materials.extend(other.materials);
        self.parts.extend(other.parts);
        self.degenerate += other.degenerate;
        self.degenerate_triangles
            .extend(other.degenerate_triangles.into_iter().map(shift));
    }

    /// The mesh with each triangle's back as a triangle of its own (new
    /// vertices, reversed winding, negated normals; texture coordinates
    /// dropped): an open surface's two sides, each with its own texels in
    /// an atlas.
    pub fn with_back_faces(mut self) -> SurfaceMesh {
        let back = SurfaceMesh {
            positions: self.positions.clone(),
            normals: self.normals.iter().map(|n| -*n).collect(),
            triangles: self.triangles.iter().map(|t| [t[0], t[2], t[1]]).collect(),
            uvs: None,
            materials: self.materials.clone(),
            parts: self.parts.clone(),
            degenerate: 0,
            degenerate_triangles: Vec::new(),
        };
        self.uvs = None;
        self.append(back);
        self
    }

    /// The signed volume enclosed by the surface when it is closed (every
    /// edge, once identical positions are welded, met by exactly one
    /// triangle in each direction), `None` when it is open. Negative: the
    /// faces point inwards.
    pub fn closed_volume(&self) -> Option<f64> {
        let w = self.welded();
        let mut edges: std::collections::HashMap<(u32, u32), i32> = Default::default();
        for t in &w.triangles {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                if a == b {
                    continue;
                }
                *edges.entry((a, b)).or_default() += 1;
            }
        }
        let closed = edges
            .iter()
            .all(|(&(a, b), &n)| n == 1 && edges.get(&(b, a)) == Some(&1));
        closed.then(|| {
            w.triangles
                .iter()
                .map(|t| {
                    let [a, b, c] = t.map(|i| w.positions[i as usize]);
                    a.dot(b.cross(c)) / 6.0
                })
                .sum()
        })
    }

    /// The unit face normal of triangle `t` (counter-clockwise front).
    pub fn face_normal(&self, t: usize) -> DVec3 {
        let [a, b, c] = self.triangles[t].map(|i| self.positions[i as usize]);
        (b - a).cross(c - a).normalize_or_zero()
    }

    /// Total surface area.
    pub fn area(&self) -> f64 {
        (0..self.triangles.len())
            .map(|t| {
                let [a, b, c] = self.triangles[t].map(|i| self.positions[i as usize]);
                0.5 * (b - a).cross(c - a).length()
            })
            .sum()
    }

    /// The point and normals at barycentric `w` of triangle `t`: the point,
    /// the face normal, and the interpolated shading normal turned into the
    /// face normal's hemisphere.
    pub fn at(&self, t: usize, w: [f64; 3]) -> (DVec3, DVec3, DVec3) {
        let idx = self.triangles[t].map(|i| i as usize);
        let p = (0..3).map(|k| w[k] * self.positions[idx[k]]).sum::<DVec3>();
        let ng = self.face_normal(t);
        let smooth = (0..3)
            .map(|k| w[k] * self.normals[idx[k]])
            .sum::<DVec3>()
            .normalize_or_zero();
        // A zero-area triangle has no face normal: use the smooth one.
        let ng = if ng == DVec3::ZERO {
            if smooth == DVec3::ZERO {
                DVec3::Y
            } else {
                smooth
            }
        } else {
            ng
        };
        let ns = (0..3)
            .map(|k| w[k] * self.normals[idx[k]])
            .sum::<DVec3>()
            .normalize_or_zero();
        let ns = if ns == DVec3::ZERO || !ns.is_finite() {
            ng
        } else if ns.dot(ng) < 0.0 {
            -ns
        } else {
            ns
        };
        (p, ng, ns)
    }
}

/// A surface point found for a texture point.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SurfaceSample {
    pub point: DVec3,
    pub ng: DVec3,
    pub ns: DVec3,
    /// Material index of the surface there.
    pub material: usize,
}

/// Quality figures of a parameterization, for reports.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TexelStats {
    /// Texture side S.
    pub size: u32,
    /// Texels that lie on the surface (valid rows).
    pub valid_texels: usize,
    /// Valid texels per unit of surface area (world units²).
    pub texels_per_area: f64,
    /// Receiver triangles of zero area (3D or texture) that cover no texel.
    pub skipped_triangles: usize,
    /// L2 stretch of the map from texture to surface (Sander et al. 2001),
    /// area-weighted mean over triangles, normalized so that 1 is a map of
    /// uniform scale; `None` where not measured.
    pub stretch_mean: Option<f64>,
    /// Largest per-triangle L2 stretch (same normalization).
    pub stretch_max: Option<f64>,
    /// Triangles whose orientation flips in the parameterization (must be 0).
    pub flipped_triangles: usize,
    /// Seconds spent computing the parameterization.
    pub seconds: f64,
    /// The atlas's figures (`atlas` layouts only).
    pub atlas: Option<crate::atlas::AtlasQuality>,
}

/// Texture point → surface point, for one receiver and layout.
pub struct TexelMap {
    size: u32,
    layout: ltm_codec::Parameterization,
    mesh: SurfaceMesh,
    domain: Domain,
    valid: Vec<bool>,
    stats: TexelStats,
}

impl std::fmt::Debug for TexelMap {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TexelMap")
            .field("size", &self.size)
            .field("stats", &self.stats)
            .finish_non_exhaustive()
    }
}

enum Domain {
    /// Triangles in texel units, located through per-texel candidates.
    Charts(ChartGrid),
    /// A spherical parameterization.
    Sphere(crate::sphere::SphereMap),
}

impl TexelMap {
    /// The map of the mesh's own texture coordinates over an `size²`
    /// texture, charts grown by `dilate` texels. Errors (a message for the
    /// caller to name the mesh) when the mesh has no texture coordinates,
    /// when they leave `[0, 1]`, or when charts overlap.
    pub(crate) fn from_uv(mesh: SurfaceMesh, size: u32, dilate: u32) -> Result<TexelMap, String> {
        let start = std::time::Instant::now();
        let grid = ChartGrid::build(&mesh, size, dilate)?;
        let s = size as usize;
        let valid: Vec<bool> = (0..s * s)
            .map(|k| {
                let c = DVec2::new((k % s) as f64 + 0.5, (k / s) as f64 + 0.5);
                // Strictly within: `dilate` whole rings of texels.
                grid.nearest(c, dilate as f64 + 0.5 - 1e-9).is_some()
            })
            .collect();
        let stats = TexelStats {
            size,
            skipped_triangles: grid.skipped + mesh.degenerate,
            ..Default::default()
        };
        TexelMap::finish(mesh, size, Domain::Charts(grid), valid, stats, start)
    }

    /// An automatic chart atlas of the receiver (see [`crate::atlas`]),
    /// its parts named by `parts` for the density figures.
    pub(crate) fn from_atlas(
        mesh: SurfaceMesh,
        req: &crate::atlas::AtlasRequest,
        parts: Vec<String>,
    ) -> Result<TexelMap, String> {
        let start = std::time::Instant::now();
        let (laid, size, quality) = crate::atlas::lay_out(&mesh, req, parts)?;
        let (mean, max, flipped) = crate::atlas::stretch(&laid, &quality.triangle_charts);
        let mut map = TexelMap::from_uv(laid, size, req.dilate)?;
        map.layout = ltm_codec::Parameterization::Atlas;
        map.stats.stretch_mean = Some(mean);
        map.stats.stretch_max = Some(max);
        map.stats.flipped_triangles = flipped;
        map.stats.atlas = Some(quality);
        map.stats.seconds = start.elapsed().as_secs_f64();
        Ok(map)
    }

    /// The spherical parameterization of a closed genus-0 mesh over an
    /// `size²` geometry image (see [`crate::sphere`]).
    pub(crate) fn from_sphere(mesh: SurfaceMesh, size: u32) -> Result<TexelMap, String> {
        let start = std::time::Instant::now();
        let mesh = mesh.welded();
        let (map, quality) = crate::sphere::SphereMap::build(&mesh)?;
        let s = size as usize;
        let valid = vec![true; s * s];
        let stats = TexelStats {
            size,
            skipped_triangles: mesh.degenerate,
            stretch_mean: Some(quality.stretch_mean),
            stretch_max: Some(quality.stretch_max),
            flipped_triangles: quality.flipped,
            ..Default::default()
        };
        TexelMap::finish(mesh, size, Domain::Sphere(map), valid, stats, start)
    }

    fn finish(
        mesh: SurfaceMesh,
        size: u32,
        domain: Domain,
        valid: Vec<bool>,
        mut stats: TexelStats,
        start: std::time::Instant,
    ) -> Result<TexelMap, String> {
        stats.valid_texels = valid.iter().filter(|&&v| v).count();
        if stats.valid_texels == 0 {
            return Err(format!(
                "no texel of the {size}×{size} texture lies on the mesh (its charts are smaller than a texel)"
            ));
        }
        stats.texels_per_area = stats.valid_texels as f64 / mesh.area();
        stats.seconds = start.elapsed().as_secs_f64();
        let layout = match domain {
            Domain::Charts(_) => ltm_codec::Parameterization::Uv,
            Domain::Sphere(_) => ltm_codec::Parameterization::Sphere,
        };
        Ok(TexelMap {
            size,
            layout,
            mesh,
            domain,
            valid,
            stats,
        })
    }

    /// Texture side S.
    pub fn size(&self) -> u32 {
        self.size
    }

    /// The layout.
    pub fn parameterization(&self) -> ltm_codec::Parameterization {
        self.layout
    }

    /// The receiver as drawn: its triangles with texture coordinates in
    /// texel units, for `uv` and `atlas` layouts (`None` for `sphere`,
    /// whose geometry image is drawn as its grid of texels).
    pub fn receiver_mesh(&self) -> Option<ltm_codec::ReceiverMesh> {
        if !matches!(self.domain, Domain::Charts(_)) {
            return None;
        }
        let uvs = self.mesh.uvs.as_ref()?;
        let s = self.size as f32;
        let unit = |n: &DVec3| {
            let n = n.normalize_or_zero();
            if n.is_finite() {
                n.as_vec3().to_array()
            } else {
                [0.0; 3]
            }
        };
        Some(ltm_codec::ReceiverMesh {
            positions: self
                .mesh
                .positions
                .iter()
                .map(|p| p.as_vec3().to_array())
                .collect(),
            normals: self.mesh.normals.iter().map(unit).collect(),
            uvs: uvs
                .iter()
                .map(|uv| {
                    [
                        (uv.x as f32 * s).clamp(0.0, s),
                        ((1.0 - uv.y as f32) * s).clamp(0.0, s),
                    ]
                })
                .collect(),
            triangles: self.mesh.triangles.clone(),
        })
    }

    /// Quality figures.
    pub fn stats(&self) -> &TexelStats {
        &self.stats
    }

    /// True when texel `k` lies on the surface.
    pub fn is_valid(&self, k: usize) -> bool {
        self.valid[k]
    }

    /// The surface point at texture point `q` (texel units) of a valid
    /// texel, or `None` outside the surface.
    pub(crate) fn locate(&self, q: DVec2) -> Option<SurfaceSample> {
        let (t, w) = match &self.domain {
            Domain::Charts(g) => g.nearest(q, g.reach)?,
            Domain::Sphere(m) => m.locate(q, self.size)?,
        };
        let (point, ng, ns) = self.mesh.at(t, w);
        let material = self.mesh.materials.get(t).map_or(0, |&m| m as usize);
        Some(SurfaceSample {
            point,
            ng,
            ns,
            material,
        })
    }
}

/// Triangles in texel units with per-texel candidate lists.
struct ChartGrid {
    size: usize,
    /// Per chart triangle: its corners in texel units and its mesh index.
    tris: Vec<([DVec2; 3], usize)>,
    /// CSR lists: texel `k`'s candidates are `items[start[k]..start[k+1]]`.
    start: Vec<u32>,
    items: Vec<u32>,
    /// Largest distance (texels) at which a point still maps to a chart.
    reach: f64,
    /// Triangles of zero texture area.
    skipped: usize,
}

impl ChartGrid {
    fn build(mesh: &SurfaceMesh, size: u32, dilate: u32) -> Result<ChartGrid, String> {
        let uvs = mesh.uvs.as_ref().ok_or(
            "the mesh has no texture coordinates (OBJ vt, PLY s,t or u,v); use parameterization = \"sphere\" for a closed mesh, or add texture coordinates",
        )?;
        let sz = size as f64;
        if let Some((i, uv)) = uvs.iter().enumerate().find(|(_, uv)| {
            !(-1e-6..=1.0 + 1e-6).contains(&uv.x) || !(-1e-6..=1.0 + 1e-6).contains(&uv.y)
        }) {
            return Err(format!(
                "vertex {i} has texture coordinates ({}, {}) outside [0, 1] (tiled or wrapped UVs cannot give one texel per surface point)",
                uv.x, uv.y
            ));
        }
        let to_texel = |uv: DVec2| DVec2::new(uv.x * sz, (1.0 - uv.y) * sz);
        let mut tris = Vec::with_capacity(mesh.triangles.len());
        let mut skipped = 0;
        for (t, idx) in mesh.triangles.iter().enumerate() {
            let c = idx.map(|i| to_texel(uvs[i as usize]));
            let area2 = (c[1] - c[0]).perp_dot(c[2] - c[0]);
            if area2.abs() <= 1e-12 * sz * sz {
                skipped += 1;
                continue;
            }
            tris.push((c, t));
        }
        let reach = dilate as f64 + 1.5;
        let s = size as usize;
        let (start, items) = candidate_lists(&tris, s, reach);
        let grid = ChartGrid {
            size: s,
            tris,
            start,
            items,
            reach,
            skipped,
        };
        grid.check_overlap()?;
        Ok(grid)
    }

    fn candidates(&self, x: usize, y: usize) -> &[u32] {
        let k = y * self.size + x;
        &self.items[self.start[k] as usize..self.start[k + 1] as usize]
    }

    /// Two triangles both strictly containing a sample point (a 2×2 grid
    /// per texel) means overlapping charts.
    fn check_overlap(&self) -> Result<(), String> {
        for y in 0..self.size {
            for x in 0..self.size {
                let cands = self.candidates(x, y);
                if cands.len() < 2 {
                    continue;
                }
                for (sx, sy) in [(0.25, 0.25), (0.75, 0.25), (0.25, 0.75), (0.75, 0.75)] {
                    let q = DVec2::new(x as f64 + sx, y as f64 + sy);
                    let mut inside = cands
                        .iter()
                        .filter(|&&i| strictly_inside(&self.tris[i as usize].0, q));
                    if let (Some(&a), Some(&b)) = (inside.next(), inside.next()) {
                        let (ta, tb) = (self.tris[a as usize].1, self.tris[b as usize].1);
                        return Err(format!(
                            "overlapping texture charts: triangles {ta} and {tb} both cover texture point ({:.4}, {:.4}); uv needs a one-to-one layout (or use parameterization = \"sphere\")",
                            q.x / self.size as f64,
                            1.0 - q.y / self.size as f64
                        ));
                    }
                }
            }
        }
        Ok(())
    }

    /// The chart point nearest to `q` within `max_dist` texels: (mesh
    /// triangle, barycentric weights).
    fn nearest(&self, q: DVec2, max_dist: f64) -> Option<(usize, [f64; 3])> {
        let clamp = |v: f64| (v.floor().max(0.0) as usize).min(self.size - 1);
        let mut best: Option<(f64, usize, [f64; 3])> = None;
        for &i in self.candidates(clamp(q.x), clamp(q.y)) {
            let (c, t) = &self.tris[i as usize];
            let (d2, w) = closest_on_triangle(c, q);
            if best.is_none_or(|b| d2 < b.0) {
                best = Some((d2, *t, w));
            }
        }
        best.filter(|b| b.0 <= max_dist * max_dist)
            .map(|(_, t, w)| (t, w))
    }
}

/// Per-texel lists of the triangles whose box, grown by `reach`, touches
/// the texel.
fn candidate_lists(tris: &[([DVec2; 3], usize)], s: usize, reach: f64) -> (Vec<u32>, Vec<u32>) {
    let span = |lo: f64, hi: f64| {
        let a = (lo - reach).floor().max(0.0) as usize;
        let b = ((hi + reach).floor().max(0.0) as usize).min(s - 1);
        a..=b
    };
    let boxes: Vec<_> = tris
        .iter()
        .map(|(c, _)| {
            let lo = c[0].min(c[1]).min(c[2]);
            let hi = c[0].max(c[1]).max(c[2]);
            (span(lo.x, hi.x), span(lo.y, hi.y))
        })
        .collect();
    let mut count = vec![0u32; s * s + 1];
    for (xs, ys) in &boxes {
        for y in ys.clone() {
            for x in xs.clone() {
                count[y * s + x + 1] += 1;
            }
        }
    }
    for k in 1..count.len() {
        count[k] += count[k - 1];
    }
    let mut fill = count.clone();
    let mut items = vec![0u32; count[s * s] as usize];
    for (i, (xs, ys)) in boxes.iter().enumerate() {
        for y in ys.clone() {
            for x in xs.clone() {
                let k = y * s + x;
                items[fill[k] as usize] = i as u32;
                fill[k] += 1;
            }
        }
    }
    (count, items)
}

/// Barycentric weights of `q` in triangle `c` (non-degenerate).
fn barycentric(c: &[DVec2; 3], q: DVec2) -> [f64; 3] {
    let area = (c[1] - c[0]).perp_dot(c[2] - c[0]);
    let w1 = (q - c[0]).perp_dot(c[2] - c[0]) / area;
    let w2 = (c[1] - c[0]).perp_dot(q - c[0]) / area;
    [1.0 - w1 - w2, w1, w2]
}

fn strictly_inside(c: &[DVec2; 3], q: DVec2) -> bool {
    barycentric(c, q).iter().all(|&w| w > 1e-6)
}

/// Squared distance from `q` to triangle `c` and the barycentric weights
/// of the closest point.
fn closest_on_triangle(c: &[DVec2; 3], q: DVec2) -> (f64, [f64; 3]) {
    let w = barycentric(c, q);
    if w.iter().all(|&v| v >= 0.0) {
        return (0.0, w);
    }
    let mut best = (f64::INFINITY, [0.0; 3]);
    for (a, b) in [(0, 1), (1, 2), (2, 0)] {
        let e = c[b] - c[a];
        let t = ((q - c[a]).dot(e) / e.length_squared()).clamp(0.0, 1.0);
        let d2 = (c[a] + t * e - q).length_squared();
        if d2 < best.0 {
            let mut w = [0.0; 3];
            w[a] = 1.0 - t;
            w[b] = t;
            best = (d2, w);
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two triangles making the unit square in the XZ plane, uv = (x, z).
    fn square(uv_scale: f64) -> SurfaceMesh {
        let p = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 0.0, 1.0],
            [0.0, 0.0, 1.0],
        ];
        SurfaceMesh {
            positions: p.iter().map(|&v| DVec3::from(v)).collect(),
            normals: vec![DVec3::Y; 4],
            triangles: vec![[0, 2, 1], [0, 3, 2]],
            uvs: Some(
                p.iter()
                    .map(|v| DVec2::new(v[0], v[2]) * uv_scale)
                    .collect(),
            ),
            materials: vec![0; 2],
            parts: vec![0; 2],
            degenerate: 0,
            degenerate_triangles: Vec::new(),
        }
    }

    /// Near-zero-area slivers (a needle, a triangle of three collinear
    /// points, one of a single repeated point) and smooth normals that
    /// cancel: every point's normals stay finite unit vectors.
    #[test]
    fn sliver_normals_are_never_nan() {
        let p = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.5, 1e-300, 0.0],
            [2.0, 0.0, 0.0],
            [0.5, 1e-13, 1e-13],
        ];
        for normals in [
            vec![DVec3::ZERO; 5],
            vec![DVec3::Y, -DVec3::Y, DVec3::Y, -DVec3::Y, DVec3::Z],
        ] {
            let mesh = SurfaceMesh {
                positions: p.iter().map(|&v| DVec3::from(v)).collect(),
                normals,
                triangles: vec![[0, 1, 2], [0, 1, 3], [0, 0, 0], [0, 1, 4]],
                ..Default::default()
            };
            for t in 0..4 {
                for w in [[1.0 / 3.0; 3], [0.5, 0.5, 0.0], [1.0, 0.0, 0.0]] {
                    let (point, ng, ns) = mesh.at(t, w);
                    assert!(point.is_finite(), "triangle {t}: point {point}");
                    for n in [ng, ns] {
                        assert!(
                            (n.length() - 1.0).abs() < 1e-9,
                            "triangle {t} at {w:?}: {n}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn uv_square_maps_texels_to_points() {
        let m = TexelMap::from_uv(square(1.0), 8, 2).unwrap();
        assert_eq!(m.stats().valid_texels, 64);
        // Texel (x = 2, y = 5) centre: u = 2.5/8, v = 1 − 5.5/8.
        let s = m.locate(DVec2::new(2.5, 5.5)).unwrap();
        assert!((s.point - DVec3::new(2.5 / 8.0, 0.0, 1.0 - 5.5 / 8.0)).length() < 1e-12);
        assert!((s.ns - DVec3::Y).length() < 1e-12);
        assert!((m.stats().texels_per_area - 64.0).abs() < 1e-9);
    }

    #[test]
    fn half_square_dilates_and_leaves_the_rest_empty() {
        let m = TexelMap::from_uv(square(0.5), 8, 1).unwrap();
        // The chart covers texels x < 4, y ≥ 4; one more ring is dilation.
        assert_eq!(m.stats().valid_texels, 25);
        assert!(m.is_valid(3 * 8 + 4) && !m.is_valid(2 * 8 + 5));
        // A dilated texel maps to the nearest chart point, on its edge.
        let s = m.locate(DVec2::new(4.5, 4.5)).unwrap();
        assert!(
            (s.point - DVec3::new(1.0, 0.0, 0.875)).length() < 1e-12,
            "{}",
            s.point
        );
        assert!(m.locate(DVec2::new(7.5, 0.5)).is_none());
        let m0 = TexelMap::from_uv(square(0.5), 8, 0).unwrap();
        assert_eq!(m0.stats().valid_texels, 16);
    }

    #[test]
    fn bad_uv_layouts_are_errors() {
        let mut m = square(1.0);
        m.uvs = None;
        assert!(TexelMap::from_uv(m, 8, 2)
            .unwrap_err()
            .contains("no texture coordinates"));
        assert!(TexelMap::from_uv(square(1.5), 8, 2)
            .unwrap_err()
            .contains("outside [0, 1]"));
        // Both triangles over the same chart: an overlap.
        let mut m = square(1.0);
        m.uvs.as_mut().unwrap()[3] = DVec2::new(1.0, 0.0);
        let e = TexelMap::from_uv(m, 8, 2).unwrap_err();
        assert!(e.contains("overlapping"), "{e}");
        // Zero texture area everywhere: nothing to bake.
        let mut m = square(1.0);
        m.uvs = Some(vec![DVec2::splat(0.5); 4]);
        let e = TexelMap::from_uv(m, 8, 2).unwrap_err();
        assert!(e.contains("no texel"), "{e}");
    }

    #[test]
    fn closest_point_is_on_the_nearest_edge() {
        let c = [DVec2::ZERO, DVec2::X, DVec2::Y];
        let (d2, w) = closest_on_triangle(&c, DVec2::new(2.0, 0.5));
        assert!(
            (d2 - 1.25).abs() < 1e-12 && w == [0.0, 1.0, 0.0],
            "{d2} {w:?}"
        );
        let (d2, w) = closest_on_triangle(&c, DVec2::new(0.25, 0.25));
        assert!(d2 == 0.0 && (w[0] - 0.5).abs() < 1e-12);
    }
}
