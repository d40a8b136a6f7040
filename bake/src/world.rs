//! The built scene: world-space triangles in an obvhs BVH, shading data,
//! materials and the camera.
//!
//! Surfaces are two-sided: at a hit, the geometric normal is flipped to face
//! the viewer and the shading normal is flipped into the same hemisphere.
//! A triangle's front side is the counter-clockwise one (OBJ and PLY
//! convention); it matters only for the camera-inside-geometry check.
//!
//! Camera inside geometry: [`Scene::build`] traces up to 32×32 primary rays
//! through pixel centres spread over the image and fails when more than 90 %
//! of them ([`INSIDE_LIMIT`]) hit the back side of a triangle. That is what a
//! camera inside a closed, outward-wound mesh sees; the distant environment
//! could not light such a view anyway. (An interior scene whose walls face
//! the room is seen from the front and passes.)
//!
//! Degenerate triangles (after the transform, in single precision: a height
//! below 10⁻⁵ of the longest edge, i.e. |e₁ × e₂| ≤ 10⁻¹⁰·max edge²) are
//! skipped and counted in [`SceneStats`]; a mesh with no other triangle is an
//! error.
//!
//! Smooth normals come from the file when it has per-vertex normals, else
//! they are the area-weighted average of the face normals around each
//! vertex position (vertices at identical positions are welded for this, so
//! unwelded seams, as in the Utah teapot, shade smoothly).

use crate::error::{BakeError, Result};
use crate::material::Material;
use crate::mesh::{self, RawMesh};
use crate::rows::RowSource;
use crate::scene::{CameraDesc, SceneDesc};
use glam::{DMat3, DVec3, Vec3A};
use obvhs::cwbvh::builder::build_cwbvh_from_tris;
use obvhs::cwbvh::CwBvh;
use obvhs::ray::{Ray, RayHit};
use obvhs::rt_triangle::RtTriangle;
use obvhs::triangle::Triangle;
use obvhs::BvhBuildParams;
use std::collections::HashMap;
use std::path::PathBuf;
use std::time::Duration;

/// Fraction of probe rays hitting back faces above which the camera is
/// considered inside geometry.
pub const INSIDE_LIMIT: f64 = 0.9;
/// Deepest BVH accepted (obvhs traverses with a fixed 32-entry stack).
const MAX_BVH_DEPTH: u32 = 24;

/// What was loaded, for reports.
#[derive(Clone, Debug, Default)]
pub struct SceneStats {
    /// Triangles in the BVH.
    pub triangles: usize,
    /// Per mesh: file, triangles kept, degenerate triangles skipped.
    pub meshes: Vec<MeshStats>,
}

/// Per-mesh load statistics.
#[derive(Clone, Debug)]
pub struct MeshStats {
    pub path: PathBuf,
    pub triangles: usize,
    pub degenerate_skipped: usize,
}

/// Pinhole camera; see [`crate::scene::CameraDesc`].
#[derive(Clone, Copy, Debug)]
pub struct Camera {
    pub eye: DVec3,
    pub forward: DVec3,
    pub right: DVec3,
    pub up: DVec3,
    /// tan(fov/2).
    pub tan_half: f64,
    pub width: u32,
    pub height: u32,
}

impl Camera {
    /// The camera of a validated description.
    pub fn new(c: &CameraDesc) -> Camera {
        let eye = DVec3::from(c.eye);
        let forward = (DVec3::from(c.target) - eye).normalize();
        let right = forward.cross(DVec3::from(c.up)).normalize();
        let up = right.cross(forward);
        Camera {
            eye,
            forward,
            right,
            up,
            tan_half: (c.fov.to_radians() * 0.5).tan(),
            width: c.width,
            height: c.height,
        }
    }

    /// Unit direction through the image point `(x, y)`, in pixels from the
    /// top-left corner (`x` to the right, `y` down; pixel `(i, j)` covers
    /// `[i, i+1] × [j, j+1]`):
    /// `normalize(forward + (2x/W − 1)·tan(fov/2)·(W/H)·right + (1 − 2y/H)·tan(fov/2)·up)`.
    pub fn direction(&self, x: f64, y: f64) -> DVec3 {
        let (w, h) = (self.width as f64, self.height as f64);
        let sx = (2.0 * x / w - 1.0) * self.tan_half * (w / h);
        let sy = (1.0 - 2.0 * y / h) * self.tan_half;
        (self.forward + sx * self.right + sy * self.up).normalize()
    }
}

/// Per-triangle shading data, in BVH order.
#[derive(Clone, Copy)]
struct Shade {
    normals: [Vec3A; 3],
    material: u32,
}

/// A surface hit.
#[derive(Clone, Copy, Debug)]
pub struct Hit {
    pub point: DVec3,
    /// Unit geometric normal, facing the viewer.
    pub ng: DVec3,
    /// Unit shading normal, in the hemisphere of `ng`.
    pub ns: DVec3,
    /// True when the ray hit the triangle's back (clockwise) side.
    pub back: bool,
    pub material: usize,
}

/// A scene ready to trace.
pub struct Scene {
    pub(crate) rows: RowSource,
    pub(crate) face_res: u32,
    pub(crate) texel_samples: u32,
    pub(crate) materials: Vec<Material>,
    pub(crate) channels: u32,
    tris: Vec<RtTriangle>,
    shade: Vec<Shade>,
    bvh: CwBvh,
    /// Shadow-ray origin offset along the geometric normal.
    pub(crate) epsilon: f64,
    stats: SceneStats,
}

impl Scene {
    /// Loads the meshes, builds the BVH and checks the camera placement.
    pub fn build(desc: &SceneDesc) -> Result<Scene> {
        desc.validate()?;
        let names: Vec<&String> = desc.materials.keys().collect();
        let materials: Vec<Material> = desc.materials.values().map(Material::new).collect();
        let mat_index = |name: &String| names.iter().position(|n| *n == name).unwrap_or(0) as u32;
        let mut tris: Vec<Triangle> = Vec::new();
        let mut shade: Vec<Shade> = Vec::new();
        let mut stats = SceneStats::default();
        for (i, m) in desc.meshes.iter().enumerate() {
            let path = desc.resolve(&m.path);
            let raw = mesh::load(&path).map_err(|e| match e {
                BakeError::Io { path, error } => BakeError::MeshIo {
                    origin: desc.origin.clone(),
                    field: format!("meshes[{i}].path"),
                    path,
                    error,
                },
                e => e,
            })?;
            let lin = rotation(m.rotation) * DMat3::from_diagonal(DVec3::from(m.scale.0));
            let kept = add_mesh(
                &raw,
                lin,
                DVec3::from(m.translation),
                m.smooth,
                mat_index(&m.material),
                &mut tris,
                &mut shade,
            );
            let (kept, skipped) = kept.map_err(|message| BakeError::MalformedMesh {
                path: path.clone(),
                format: if path
                    .extension()
                    .is_some_and(|e| e.eq_ignore_ascii_case("ply"))
                {
                    "PLY"
                } else {
                    "OBJ"
                },
                message,
            })?;
            stats.meshes.push(MeshStats {
                path,
                triangles: kept,
                degenerate_skipped: skipped,
            });
        }
        for (i, q) in desc.quads.iter().enumerate() {
            let (hx, hz) = (0.5 * q.size[0], 0.5 * q.size[1]);
            let raw = RawMesh {
                positions: vec![
                    [-hx as f32, 0.0, -hz as f32],
                    [-hx as f32, 0.0, hz as f32],
                    [hx as f32, 0.0, hz as f32],
                    [hx as f32, 0.0, -hz as f32],
                ],
                normals: None,
                triangles: vec![[0, 1, 2], [0, 2, 3]],
            };
            add_mesh(
                &raw,
                rotation(q.rotation),
                DVec3::from(q.center),
                false,
                mat_index(&q.material),
                &mut tris,
                &mut shade,
            )
            .map_err(|m| BakeError::invalid(&desc.origin, format!("quads[{i}]"), m))?;
        }
        stats.triangles = tris.len();
        let (mut lo, mut hi) = (Vec3A::splat(f32::MAX), Vec3A::splat(f32::MIN));
        for t in &tris {
            for v in [t.v0, t.v1, t.v2] {
                lo = lo.min(v);
                hi = hi.max(v);
            }
        }
        let extent = ((hi - lo).length() as f64).max(lo.abs().max(hi.abs()).max_element() as f64);
        if !extent.is_finite() || extent > 1e30 {
            return Err(BakeError::Geometry(format!(
                "the scene's bounding box [{lo:?}, {hi:?}] is too large for single-precision ray tracing"
            )));
        }
        let bvh = build_cwbvh_from_tris(
            &tris,
            BvhBuildParams::medium_build(),
            &mut Duration::default(),
        );
        let depth = bvh_depth(&bvh);
        if depth > MAX_BVH_DEPTH {
            return Err(BakeError::Geometry(format!(
                "the BVH is {depth} levels deep (valid: at most {MAX_BVH_DEPTH}); the geometry is pathologically distributed"
            )));
        }
        let order = &bvh.primitive_indices;
        let rt: Vec<RtTriangle> = order
            .iter()
            .map(|&i| RtTriangle::from(&tris[i as usize]))
            .collect();
        let shade: Vec<Shade> = order.iter().map(|&i| shade[i as usize]).collect();
        let scene = Scene {
            rows: RowSource::Camera {
                camera: Camera::new(&desc.camera),
                spp: desc.camera.spp,
            },
            face_res: desc.lighting.face_res,
            texel_samples: desc.lighting.texel_samples,
            channels: if desc.needs_color_transport() { 3 } else { 1 },
            materials,
            tris: rt,
            shade,
            bvh,
            epsilon: 1e-5 * extent.max(1e-3),
            stats,
        };
        scene.check_camera()?;
        Ok(scene)
    }

    /// Load statistics (triangle counts, skipped degenerate triangles).
    pub fn stats(&self) -> &SceneStats {
        &self.stats
    }

    /// What the rows are.
    pub fn rows(&self) -> &RowSource {
        &self.rows
    }

    /// The camera whose pixels are the rows.
    pub fn camera(&self) -> Option<&Camera> {
        match &self.rows {
            RowSource::Camera { camera, .. } => Some(camera),
        }
    }

    /// Channels of the transport: 1 (grey transport with an albedo image)
    /// when every material used is Lambertian, else 3.
    pub fn channels(&self) -> u32 {
        self.channels
    }

    /// Matrix dimensions.
    pub fn dims(&self) -> ltm_codec::Dims {
        ltm_codec::Dims {
            rows: self.rows.layout(),
            lights: ltm_codec::LightBasis::Cubemap { n: self.face_res },
            channels: self.channels,
        }
    }

    /// Closest hit along a ray from `origin` in unit direction `dir`.
    pub fn intersect(&self, origin: DVec3, dir: DVec3) -> Option<Hit> {
        let ray = make_ray(origin, dir);
        let mut hit = RayHit::none();
        if !self
            .bvh
            .ray_traverse(ray, &mut hit, |r, id| self.tris[id].intersect(r))
        {
            return None;
        }
        let id = hit.primitive_id as usize;
        let tri = &self.tris[id];
        let v0 = tri.v0.as_dvec3();
        let v1 = v0 - tri.e1.as_dvec3();
        let v2 = v0 + tri.e2.as_dvec3();
        let point = origin + dir * hit.t as f64;
        let (e1, e2) = (v1 - v0, v2 - v0);
        let n = e1.cross(e2);
        let nn = n.length_squared();
        let nw = n / nn.sqrt();
        let q = point - v0;
        let b1 = (q.cross(e2).dot(n) / nn).clamp(0.0, 1.0);
        let b2 = (e1.cross(q).dot(n) / nn).clamp(0.0, 1.0 - b1);
        let b0 = 1.0 - b1 - b2;
        let back = nw.dot(dir) > 0.0;
        let ng = if back { -nw } else { nw };
        let s = &self.shade[id];
        let ns = (b0 * s.normals[0].as_dvec3()
            + b1 * s.normals[1].as_dvec3()
            + b2 * s.normals[2].as_dvec3())
        .normalize_or_zero();
        let ns = if ns == DVec3::ZERO || !ns.is_finite() {
            ng
        } else if ns.dot(ng) < 0.0 {
            -ns
        } else {
            ns
        };
        Some(Hit {
            point,
            ng,
            ns,
            back,
            material: s.material as usize,
        })
    }

    /// True when a ray from `origin` in direction `dir` hits anything.
    pub fn occluded(&self, origin: DVec3, dir: DVec3) -> bool {
        let ray = make_ray(origin, dir);
        !self
            .bvh
            .ray_traverse_miss(ray, |r, id| self.tris[id].intersect(r))
    }

    /// Probes the image with up to 32×32 pixel-centre rays and fails when
    /// more than [`INSIDE_LIMIT`] of them hit the back side of a triangle.
    fn check_camera(&self) -> Result<()> {
        let Some(c) = self.camera() else {
            return Ok(());
        };
        let (gx, gy) = (c.width.min(32), c.height.min(32));
        let mut back = 0usize;
        for j in 0..gy {
            for i in 0..gx {
                let x = (i as f64 + 0.5) * c.width as f64 / gx as f64;
                let y = (j as f64 + 0.5) * c.height as f64 / gy as f64;
                if self
                    .intersect(c.eye, c.direction(x, y))
                    .is_some_and(|h| h.back)
                {
                    back += 1;
                }
            }
        }
        let frac = back as f64 / (gx * gy) as f64;
        if frac > INSIDE_LIMIT {
            return Err(BakeError::CameraInsideGeometry {
                eye: c.eye.to_array(),
                back_fraction: frac,
                limit: INSIDE_LIMIT,
            });
        }
        Ok(())
    }
}

/// A single-precision ray. Negative zeros in the direction become positive:
/// obvhs 0.4's CWBVH traversal misses everything along a direction with a
/// `-0.0` component (its octant comes from the sign bit).
fn make_ray(origin: DVec3, dir: DVec3) -> Ray {
    Ray::new_inf(origin.as_vec3a(), dir.as_vec3a() + Vec3A::ZERO)
}

/// `Rz·Ry·Rx` for Euler angles `[rx, ry, rz]` in degrees.
pub(crate) fn rotation(deg: [f64; 3]) -> DMat3 {
    DMat3::from_rotation_z(deg[2].to_radians())
        * DMat3::from_rotation_y(deg[1].to_radians())
        * DMat3::from_rotation_x(deg[0].to_radians())
}

/// Appends a transformed mesh; returns (triangles kept, degenerate skipped)
/// or a message when nothing usable remains.
fn add_mesh(
    raw: &RawMesh,
    lin: DMat3,
    translation: DVec3,
    smooth: bool,
    material: u32,
    tris: &mut Vec<Triangle>,
    shade: &mut Vec<Shade>,
) -> std::result::Result<(usize, usize), String> {
    let world: Vec<Vec3A> = raw
        .positions
        .iter()
        .map(|p| (lin * DVec3::from(p.map(f64::from)) + translation).as_vec3a())
        .collect();
    if let Some(i) = world.iter().position(|p| !p.is_finite()) {
        return Err(format!(
            "vertex {i} leaves the single-precision range after the transform"
        ));
    }
    // A mirroring transform flips the winding; swap two corners to keep
    // counter-clockwise fronts.
    let flip = lin.determinant() < 0.0;
    let corners = |t: &[u32; 3]| {
        if flip {
            [t[0], t[2], t[1]]
        } else {
            *t
        }
    };
    let face_normal = |t: &[u32; 3]| -> Option<DVec3> {
        let [a, b, c] = t.map(|i| world[i as usize].as_dvec3());
        let (e1, e2, e3) = (b - a, c - a, c - b);
        let n = e1.cross(e2);
        let longest = e1
            .length_squared()
            .max(e2.length_squared())
            .max(e3.length_squared());
        let len = n.length();
        (len.is_finite() && len > 1e-10 * longest).then(|| n / len)
    };
    let normal_matrix = lin.inverse().transpose();
    let vertex_normals: Option<Vec<DVec3>> = if !smooth {
        None
    } else if let Some(ns) = &raw.normals {
        Some(
            ns.iter()
                .map(|n| (normal_matrix * DVec3::from(n.map(f64::from))).normalize_or_zero())
                .collect(),
        )
    } else {
        // Weld by model-space position, accumulate area-weighted normals.
        let mut key_of: HashMap<[u32; 3], usize> = HashMap::new();
        let keys: Vec<usize> = raw
            .positions
            .iter()
            .map(|p| {
                let k = p.map(|v| if v == 0.0 { 0 } else { v.to_bits() });
                let next = key_of.len();
                *key_of.entry(k).or_insert(next)
            })
            .collect();
        let mut acc = vec![DVec3::ZERO; key_of.len()];
        for t in &raw.triangles {
            let t = corners(t);
            if face_normal(&t).is_none() {
                continue;
            }
            let [a, b, c] = t.map(|i| world[i as usize].as_dvec3());
            let n = (b - a).cross(c - a);
            for i in t {
                acc[keys[i as usize]] += n;
            }
        }
        Some(keys.iter().map(|&k| acc[k].normalize_or_zero()).collect())
    };
    let (mut kept, mut skipped) = (0, 0);
    for t in &raw.triangles {
        let t = corners(t);
        let Some(ng) = face_normal(&t) else {
            skipped += 1;
            continue;
        };
        let [v0, v1, v2] = t.map(|i| world[i as usize]);
        tris.push(Triangle { v0, v1, v2 });
        let normals = match &vertex_normals {
            Some(vn) => t.map(|i| {
                let n = vn[i as usize];
                if n == DVec3::ZERO || !n.is_finite() {
                    ng.as_vec3a()
                } else {
                    n.as_vec3a()
                }
            }),
            None => [ng.as_vec3a(); 3],
        };
        shade.push(Shade { normals, material });
        kept += 1;
    }
    if kept == 0 {
        return Err(format!(
            "all {} triangles are degenerate (zero area)",
            raw.triangles.len()
        ));
    }
    Ok((kept, skipped))
}

/// Depth of a CWBVH (1 for a root-only tree).
fn bvh_depth(bvh: &CwBvh) -> u32 {
    if bvh.nodes.is_empty() {
        return 0;
    }
    let mut max = 0;
    let mut stack = vec![(0usize, 1u32)];
    while let Some((i, d)) = stack.pop() {
        max = max.max(d);
        let Some(node) = bvh.nodes.get(i) else {
            continue;
        };
        for c in 0..node.imask.count_ones() as usize {
            stack.push((node.child_base_idx as usize + c, d + 1));
        }
    }
    max
}
