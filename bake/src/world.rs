//! The built scene: world-space triangles in a BVH, shading data, materials
//! and the camera.
//!
//! Surfaces are two-sided: at a hit, the geometric normal is flipped to face
//! the viewer and the shading normal is flipped into the same hemisphere.
//! A triangle's front side is the counter-clockwise one (OBJ and PLY
//! convention); it matters only for the camera-inside-geometry check
//! ([`crate::inside`]).
//!
//! Tracing is watertight: rays cannot slip between triangles that share an
//! edge or a vertex, from either side. The triangle test is Woop, Benthin,
//! Wald 2013 ([`crate::intersect`]) on the vertices exactly as the
//! triangles share them; the BVH ([`crate::bvh`]) has conservative boxes.
//! Geometry is traced in single precision in a copy of world space scaled
//! by a power of two (exact) so that the scene spans about 2¹²: obvhs's
//! fixed ray/box tolerances then cannot drop small scenes. A ray that
//! starts outside the scene's (padded) bounding box starts tracing where it
//! enters it, so that a distant camera loses no precision.
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
use crate::intersect::{Tri, WtRay};
use crate::material::Material;
use crate::mesh::{self, RawMesh};
use crate::packet::{Packet, PACKET};
use crate::plane::LightPlane;
use crate::rows::RowSource;
use crate::scene::{CameraDesc, Receivers, SceneDesc};
use crate::texture::{SurfaceMesh, TexelMap};
use glam::{DMat3, DVec2, DVec3, Vec3A};
use ltm_codec::Parameterization;
use obvhs::cwbvh::CwBvh;
use obvhs::ray::{Ray, RayHit};
use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Arc;

/// Largest and smallest scene extent traced (the larger of the bounding
/// box's diagonal and its largest coordinate magnitude): single precision
/// must hold it, scaled to trace space, with room to spare.
const MAX_EXTENT: f64 = 1e30;
const MIN_EXTENT: f64 = 1e-30;
/// The scene's extent in trace space is about 2^TRACE_EXPONENT.
const TRACE_EXPONENT: i32 = 12;
/// Box padding, relative to the scene's extent.
const PAD: f64 = 1.0 / 16384.0;

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
    /// The mesh file, resolved against the scene file's directory.
    pub path: PathBuf,
    /// Triangles kept (after triangulating polygons).
    pub triangles: usize,
    /// Triangles skipped because they have (almost) no area.
    pub degenerate_skipped: usize,
}

/// Pinhole camera; see [`crate::scene::CameraDesc`]. World space, Y up;
/// `forward`, `right` and `up` form a right-handed orthonormal basis
/// (`right = forward × up`).
#[derive(Clone, Copy, Debug)]
pub struct Camera {
    /// The pinhole, world units.
    pub eye: DVec3,
    /// Unit viewing direction (through the image centre).
    pub forward: DVec3,
    /// Unit vector towards the image's right edge.
    pub right: DVec3,
    /// Unit vector towards the image's top edge.
    pub up: DVec3,
    /// tan(fov/2), fov the vertical field of view.
    pub tan_half: f64,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
}

impl Camera {
    /// The camera of a validated description.
    pub fn new(c: &CameraDesc) -> Camera {
        let eye = DVec3::from(c.eye);
        let forward = unit(DVec3::from(c.target) - eye);
        let right = forward.cross(unit(DVec3::from(c.up))).normalize();
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

/// `v / |v|` without overflow or underflow for any finite non-zero `v`.
fn unit(v: DVec3) -> DVec3 {
    (v / v.abs().max_element()).normalize()
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
    /// The hit point, world units.
    pub point: DVec3,
    /// Unit geometric normal, facing the viewer.
    pub ng: DVec3,
    /// Unit shading normal, in the hemisphere of `ng`.
    pub ns: DVec3,
    /// True when the ray hit the triangle's back (clockwise) side.
    pub back: bool,
    /// Index of the hit surface's material (scene materials in name order).
    pub material: usize,
}

/// Triangles and their shading data as loaded, in world space.
#[derive(Default)]
struct Geometry {
    tris: Vec<Tri>,
    shade: Vec<Shade>,
    stats: SceneStats,
    /// Per mesh: the SHA-256 of its file and its format.
    files: Vec<([u8; 32], &'static str)>,
    /// The receiver of a texture-space bake, as placed.
    receiver: Option<SurfaceMesh>,
    /// The names of the receiver's parts (mesh paths, `quads[i]`).
    receiver_parts: Vec<String>,
}

/// A ray ready for the BVH: in trace space, starting where the world ray
/// enters the scene's box, `skip` world units from its origin.
struct Traced {
    ray: Ray,
    wt: WtRay,
    skip: f64,
}

/// A scene ready to trace.
pub struct Scene {
    pub(crate) rows: RowSource,
    pub(crate) face_res: u32,
    pub(crate) texel_samples: u32,
    pub(crate) materials: Vec<Material>,
    pub(crate) channels: u32,
    /// Triangles in trace space (world × `scale`), in BVH order.
    tris: Vec<Tri>,
    shade: Vec<Shade>,
    bvh: CwBvh,
    /// Trace space = world space × scale, a power of two.
    scale: f64,
    /// The padded bounding box of the geometry, world units.
    bounds: [DVec3; 2],
    /// The geometry's bounding box, world units (unpadded).
    geometry_bounds: [DVec3; 2],
    /// Shadow-ray origin offset along the geometric normal, world units.
    pub(crate) epsilon: f64,
    stats: SceneStats,
    input_id: [u8; 32],
    /// The light plane every row is also baked over, as the codec stores
    /// its face.
    light_plane: Option<(LightPlane, ltm_codec::PlaneBasis)>,
}

impl Scene {
    /// Loads the meshes, builds the BVH and checks the camera placement.
    pub fn build(desc: &SceneDesc) -> Result<Scene> {
        desc.validate()?;
        let geometry = load_geometry(desc)?;
        let files: Vec<([u8; 32], &str)> = geometry.files.iter().map(|(d, f)| (*d, *f)).collect();
        let input_id = crate::identity::scene_identity(desc, &files);
        let scene = Scene::assemble(desc, geometry, input_id)?;
        if scene.camera().is_some() {
            scene.check_camera()?;
        }
        Ok(scene)
    }

    /// Scales the geometry into trace space and builds the BVH.
    fn assemble(desc: &SceneDesc, g: Geometry, input_id: [u8; 32]) -> Result<Scene> {
        let (lo, hi) = g.tris.iter().flat_map(|t| t.vertices()).fold(
            (Vec3A::splat(f32::MAX), Vec3A::splat(f32::MIN)),
            |(lo, hi), v| (lo.min(v), hi.max(v)),
        );
        let (lo, hi) = (lo.as_dvec3(), hi.as_dvec3());
        let extent = (hi - lo).length().max(lo.abs().max(hi.abs()).max_element());
        if !(MIN_EXTENT..=MAX_EXTENT).contains(&extent) {
            return Err(BakeError::Geometry(format!(
                "the scene's bounding box [{lo}, {hi}] (extent {extent:e}) is out of range for single-precision ray tracing (valid: an extent, the larger of its diagonal and its largest coordinate, from {MIN_EXTENT:e} to {MAX_EXTENT:e})"
            )));
        }
        let scale = 2f64.powi(TRACE_EXPONENT - extent.log2().ceil() as i32);
        let s = scale as f32;
        let traced: Vec<Tri> = g
            .tris
            .iter()
            .map(|t| Tri::new(t.vertices().map(|v| v * s)))
            .collect();
        let pad = PAD * extent;
        let (bvh, depth) = crate::bvh::build(&traced, (pad * scale) as f32);
        if depth > crate::bvh::MAX_DEPTH {
            return Err(BakeError::Geometry(format!(
                "the BVH is {depth} levels deep (valid: at most {}); the scene has too many triangles",
                crate::bvh::MAX_DEPTH
            )));
        }
        let order = &bvh.primitive_indices;
        let tris = order.iter().map(|&i| traced[i as usize]).collect();
        let shade = order.iter().map(|&i| g.shade[i as usize]).collect();
        let mut stats = g.stats;
        stats.triangles = g.tris.len();
        let rows = match (&desc.texture, g.receiver) {
            (Some(t), Some(receiver)) => {
                let path = match t.mesh {
                    Receivers::Mesh(m) => desc.resolve(&desc.meshes[m].path),
                    _ => PathBuf::from(&desc.origin),
                };
                let map = match t.parameterization {
                    Parameterization::Uv => TexelMap::from_uv(receiver, t.size, t.dilate()),
                    Parameterization::Sphere => TexelMap::from_sphere(receiver, t.size),
                    Parameterization::Atlas => TexelMap::from_atlas(
                        receiver,
                        &crate::atlas::AtlasRequest {
                            size: t.size,
                            texels_per_unit: t.texels_per_unit,
                            padding: t.padding,
                            dilate: t.dilate(),
                        },
                        g.receiver_parts,
                    ),
                    p => Err(format!(
                        "the {} parameterization is not supported",
                        p.name()
                    )),
                }
                .map_err(|message| BakeError::Parameterization {
                    path,
                    parameterization: t.parameterization.name(),
                    message,
                })?;
                RowSource::Texture {
                    map: Arc::new(map),
                    spp: t.spp,
                }
            }
            _ => RowSource::Camera {
                camera: Camera::new(&desc.camera),
                spp: desc.camera.spp,
            },
        };
        let light_plane = match &desc.light_plane {
            Some(p) => Some((p.plane()?, p.basis()?)),
            None => None,
        };
        Ok(Scene {
            light_plane,
            rows,
            face_res: desc.lighting.face_res,
            texel_samples: desc.lighting.texel_samples,
            channels: if desc.needs_color_transport() { 3 } else { 1 },
            materials: desc.materials.values().map(Material::new).collect(),
            tris,
            shade,
            bvh,
            scale,
            bounds: [lo - 2.0 * pad, hi + 2.0 * pad],
            geometry_bounds: [lo, hi],
            epsilon: 1e-5 * extent.max(1e-3),
            stats,
            input_id,
        })
    }

    /// Load statistics (triangle counts, skipped degenerate triangles).
    pub fn stats(&self) -> &SceneStats {
        &self.stats
    }

    /// The input identity of this scene: a SHA-256 of everything that
    /// determines its rows ([`crate::identity`]), stored in the raw store's
    /// header so that only a bake of the same inputs is resumed.
    pub fn input_id(&self) -> [u8; 32] {
        self.input_id
    }

    /// The face of the scene's `[light_plane]`, which every row is also
    /// baked over (`None` without one).
    pub fn light_plane(&self) -> Option<(&LightPlane, &ltm_codec::PlaneBasis)> {
        self.light_plane.as_ref().map(|(p, b)| (p, b))
    }

    /// What the rows are.
    pub fn rows(&self) -> &RowSource {
        &self.rows
    }

    /// The camera whose pixels are the rows (`None` for texture rows).
    pub fn camera(&self) -> Option<&Camera> {
        match &self.rows {
            RowSource::Camera { camera, .. } => Some(camera),
            RowSource::Texture { .. } => None,
        }
    }

    /// The texture-space layout of the rows (`None` for camera rows).
    pub fn texel_map(&self) -> Option<&TexelMap> {
        match &self.rows {
            RowSource::Texture { map, .. } => Some(map),
            RowSource::Camera { .. } => None,
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

    /// The ray from `origin` along unit `dir` in trace space, clipped to the
    /// scene's box; `None` when it misses the box.
    #[inline(always)]
    fn traced(&self, origin: DVec3, dir: DVec3) -> Option<Traced> {
        let (start, d, skip) = self.clipped(origin, dir)?;
        Some(Traced {
            ray: Ray::new_inf(start, d),
            wt: WtRay::new(start, d),
            skip,
        })
    }

    /// Whether `origin` is finite and strictly inside the scene's box.
    #[inline(always)]
    fn strictly_inside(&self, origin: DVec3) -> bool {
        let [lo, hi] = self.bounds;
        origin.is_finite() && origin.cmpgt(lo).all() && origin.cmplt(hi).all()
    }

    /// [`Scene::clipped`] for an `origin` strictly inside the scene's box,
    /// without the slab test: every axis then puts the box's near face
    /// strictly behind the origin, so the entry distance is exactly `+0.0`
    /// and the ray never misses the box.
    #[inline(always)]
    fn clipped_inside(&self, origin: DVec3, dir: DVec3) -> Option<(Vec3A, Vec3A, f64)> {
        if !dir.is_finite() || dir == DVec3::ZERO {
            return None;
        }
        let near = 0.0;
        let start = ((origin + dir * near) * self.scale).as_vec3a();
        Some((start, dir.as_vec3a() + Vec3A::ZERO, near))
    }

    /// Where the ray from `origin` along unit `dir` enters the scene's box,
    /// in trace space, its direction there, and the world distance to the
    /// entry; `None` when it misses the box.
    #[inline(always)]
    fn clipped(&self, origin: DVec3, dir: DVec3) -> Option<(Vec3A, Vec3A, f64)> {
        if !origin.is_finite() || !dir.is_finite() || dir == DVec3::ZERO {
            return None;
        }
        let [lo, hi] = self.bounds;
        let (mut near, mut far) = (0.0f64, f64::INFINITY);
        let inv = dir.recip();
        for k in 0..3 {
            if dir[k] == 0.0 {
                if origin[k] < lo[k] || origin[k] > hi[k] {
                    return None;
                }
                continue;
            }
            let (a, b) = ((lo[k] - origin[k]) * inv[k], (hi[k] - origin[k]) * inv[k]);
            near = near.max(a.min(b));
            far = far.min(a.max(b));
        }
        if near > far {
            return None;
        }
        let start = ((origin + dir * near) * self.scale).as_vec3a();
        // Negative zeros become positive: obvhs 0.4's CWBVH traversal misses
        // everything along a direction with a `-0.0` component (its octant
        // comes from the sign bit).
        Some((start, dir.as_vec3a() + Vec3A::ZERO, near))
    }

    /// Closest hit along a ray from `origin` in unit direction `dir`.
    pub fn intersect(&self, origin: DVec3, dir: DVec3) -> Option<Hit> {
        let t = self.traced(origin, dir)?;
        let mut hit = RayHit::none();
        let found = self.bvh.ray_traverse(t.ray, &mut hit, |r, id| {
            t.wt.hit(&self.tris[id], r.tmin, r.tmax)
        });
        if !found {
            return None;
        }
        let dist = t.skip + hit.t as f64 / self.scale;
        Some(self.shade_hit(hit.primitive_id as usize, origin + dir * dist, dir))
    }

    /// The hit on triangle `id` at `point`, seen along `dir`.
    fn shade_hit(&self, id: usize, point: DVec3, dir: DVec3) -> Hit {
        let [v0, v1, v2] = self.tris[id].vertices().map(|v| v.as_dvec3() / self.scale);
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
        Hit {
            point,
            ng,
            ns,
            back,
            material: s.material as usize,
        }
    }

    /// The bounding box of the scene's triangles, world units: the lowest
    /// and the highest corner (what a user needs to place a camera).
    pub fn bounding_box(&self) -> [[f64; 3]; 2] {
        self.geometry_bounds.map(|c| c.to_array())
    }

    /// The triangles traced, in world units (three vertices each): the
    /// geometry another ray tracer is measured on.
    pub fn world_triangles(&self) -> Vec<[[f32; 3]; 3]> {
        self.tris
            .iter()
            .map(|t| {
                t.vertices()
                    .map(|v| (v.as_dvec3() / self.scale).as_vec3().to_array())
            })
            .collect()
    }

    /// [`Scene::occluded`] for rays from one `origin` along `dirs`, traced
    /// together in packets of up to 64 (masked packet traversal): `out[i]`
    /// for `dirs[i]`, the same answers, faster when the directions are
    /// close.
    pub fn occluded_packet(&self, origin: DVec3, dirs: &[DVec3], out: &mut [bool]) {
        self.occluded_within(&mut Packet::default(), origin, dirs, |_| f64::INFINITY, out);
    }

    /// [`Scene::occluded_packet`] counting only hits closer than
    /// `reach(dir)` (a world distance; infinite for no limit), as
    /// [`Scene::occluded_until`] answers each ray.
    pub fn occluded_packet_until(
        &self,
        origin: DVec3,
        dirs: &[DVec3],
        reach: impl Fn(DVec3) -> f64,
        out: &mut [bool],
    ) {
        self.occluded_within(&mut Packet::default(), origin, dirs, reach, out);
    }

    /// [`Scene::occluded_packet_until`] with the packet's storage passed
    /// in.
    pub(crate) fn occluded_within(
        &self,
        packet: &mut Packet,
        origin: DVec3,
        dirs: &[DVec3],
        reach: impl Fn(DVec3) -> f64,
        out: &mut [bool],
    ) {
        assert_eq!(dirs.len(), out.len(), "one answer per direction");
        out.fill(false);
        let inside = self.strictly_inside(origin);
        for (start, chunk) in dirs.chunks(PACKET).enumerate() {
            packet.clear();
            for (i, &d) in chunk.iter().enumerate() {
                let clipped = if inside {
                    self.clipped_inside(origin, d)
                } else {
                    self.clipped(origin, d)
                };
                debug_assert_eq!(bits(clipped), bits(self.clipped(origin, d)));
                let Some((start, dir, near)) = clipped else {
                    continue;
                };
                match self.trace_limit(reach(d), near) {
                    Some(tmax) => packet.push_until(i, start, dir, tmax),
                    None => packet.push(i, start, dir),
                }
            }
            let hit = packet.trace(&self.bvh, &self.tris);
            for (k, &i) in packet.index().iter().enumerate() {
                out[start * PACKET + i as usize] = hit >> k & 1 == 1;
            }
        }
    }

    /// The trace-space limit of a ray whose hits count up to world
    /// distance `reach` and that enters the scene's box at world distance
    /// `near`; `None` for no limit. A reach that ends before the box gives
    /// a negative limit: nothing counts.
    fn trace_limit(&self, reach: f64, near: f64) -> Option<f32> {
        reach
            .is_finite()
            .then(|| ((reach - near) * self.scale).min(f64::from(f32::MAX)) as f32)
    }

    /// [`Scene::occluded`] counting only hits closer than world distance
    /// `reach` (one ray at a time: the reference of the packets).
    pub fn occluded_until(&self, origin: DVec3, dir: DVec3, reach: f64) -> bool {
        let Some(t) = self.traced(origin, dir) else {
            return false;
        };
        let tmax = self.trace_limit(reach, t.skip).unwrap_or(f32::INFINITY);
        if tmax.is_nan() || tmax < 0.0 {
            return false;
        }
        let ray = Ray::new(t.ray.origin, t.ray.direction, t.ray.tmin, tmax);
        !self
            .bvh
            .ray_traverse_miss(ray, |r, id| t.wt.hit(&self.tris[id], r.tmin, r.tmax))
    }

    /// True when a ray from `origin` in unit direction `dir` hits anything
    /// (any hit: the shadow query).
    pub fn occluded(&self, origin: DVec3, dir: DVec3) -> bool {
        let Some(t) = self.traced(origin, dir) else {
            return false;
        };
        !self
            .bvh
            .ray_traverse_miss(t.ray, |r, id| t.wt.hit(&self.tris[id], r.tmin, r.tmax))
    }
}

/// A clipped ray's start, direction and entry distance as bits (so that
/// `-0.0` and `+0.0` differ).
fn bits(c: Option<(Vec3A, Vec3A, f64)>) -> Option<([u32; 3], [u32; 3], u64)> {
    c.map(|(s, d, near)| {
        (
            s.to_array().map(f32::to_bits),
            d.to_array().map(f32::to_bits),
            near.to_bits(),
        )
    })
}

/// Loads every mesh and quad of `desc` into world-space triangles.
fn load_geometry(desc: &SceneDesc) -> Result<Geometry> {
    let names: Vec<&String> = desc.materials.keys().collect();
    let mat_index = |name: &String| names.iter().position(|n| *n == name).unwrap_or(0) as u32;
    let mut g = Geometry::default();
    for (i, m) in desc.meshes.iter().enumerate() {
        let path = desc.resolve(&m.path);
        let loaded = mesh::load(&path).map_err(|e| match e {
            BakeError::Io { path, error } => BakeError::MeshIo {
                origin: desc.origin.clone(),
                field: format!("meshes[{i}].path"),
                path,
                error,
            },
            e => e,
        })?;
        let lin = rotation(m.rotation) * DMat3::from_diagonal(DVec3::from(m.scale.0));
        let placed = Placement {
            lin,
            translation: DVec3::from(m.translation),
            smooth: m.smooth,
            material: mat_index(&m.material),
        };
        let (kept, skipped) =
            placed
                .add(&loaded.mesh, &mut g)
                .map_err(|message| BakeError::MalformedMesh {
                    path: path.clone(),
                    format: loaded.format,
                    message,
                })?;
        if desc.texture.as_ref().is_some_and(|t| t.mesh.has_mesh(i)) {
            let surface = placed.surface_mesh(&loaded.mesh)?;
            let volume = surface.closed_volume();
            if let Some(v) = volume.filter(|&v| v < 0.0) {
                return Err(BakeError::MalformedMesh {
                    path,
                    format: loaded.format,
                    message: format!("its faces point inwards (a closed surface of signed volume {v:.4e}): its texels would see the inside of the surface and bake black; reverse the triangles' winding"),
                });
            }
            // An open surface is seen from both sides: in an atlas each
            // side gets texels of its own.
            let atlas = desc
                .texture
                .as_ref()
                .is_some_and(|t| t.parameterization == Parameterization::Atlas);
            let surface = if atlas && volume.is_none() {
                surface.with_back_faces()
            } else {
                surface
            };
            g.add_receiver(surface, path.display().to_string());
        }
        g.files.push((loaded.digest, loaded.format));
        g.stats.meshes.push(MeshStats {
            path,
            triangles: kept,
            degenerate_skipped: skipped,
        });
    }
    for (i, q) in desc.quads.iter().enumerate() {
        let placed = Placement {
            lin: rotation(q.rotation),
            translation: DVec3::from(q.center),
            smooth: false,
            material: mat_index(&q.material),
        };
        placed
            .add(&quad_mesh(q.size), &mut g)
            .map_err(|m| BakeError::invalid(&desc.origin, format!("quads[{i}]"), m))?;
        if desc
            .texture
            .as_ref()
            .is_some_and(|t| t.mesh == Receivers::All)
        {
            g.add_receiver(
                placed.surface_mesh(&quad_mesh(q.size))?,
                format!("quads[{i}]"),
            );
        }
    }
    Ok(g)
}

impl Geometry {
    /// Joins one more receiving part (a mesh or a quad, named for reports)
    /// to the receiver.
    fn add_receiver(&mut self, part: SurfaceMesh, name: String) {
        let index = self.receiver_parts.len() as u32;
        self.receiver_parts.push(name);
        let mut part = part;
        part.parts.fill(index);
        match &mut self.receiver {
            Some(r) => r.append(part),
            None => self.receiver = Some(part),
        }
    }
}

/// A `size[0] × size[1]` rectangle in the XZ plane, centred, facing +Y.
fn quad_mesh(size: [f64; 2]) -> RawMesh {
    let (hx, hz) = ((0.5 * size[0]) as f32, (0.5 * size[1]) as f32);
    RawMesh {
        positions: vec![
            [-hx, 0.0, -hz],
            [-hx, 0.0, hz],
            [hx, 0.0, hz],
            [hx, 0.0, -hz],
        ],
        normals: None,
        uvs: None,
        triangles: vec![[0, 1, 2], [0, 2, 3]],
    }
}

/// `Rz·Ry·Rx` for Euler angles `[rx, ry, rz]` in degrees.
pub(crate) fn rotation(deg: [f64; 3]) -> DMat3 {
    DMat3::from_rotation_z(deg[2].to_radians())
        * DMat3::from_rotation_y(deg[1].to_radians())
        * DMat3::from_rotation_x(deg[0].to_radians())
}

/// Where a mesh goes: its transform, normals mode and material.
struct Placement {
    lin: DMat3,
    translation: DVec3,
    smooth: bool,
    material: u32,
}

impl Placement {
    /// Appends the transformed mesh to `g`; returns (triangles kept,
    /// degenerate skipped) or a message when nothing usable remains.
    fn add(&self, raw: &RawMesh, g: &mut Geometry) -> std::result::Result<(usize, usize), String> {
        let world = self.world_positions(raw)?;
        // A mirroring transform flips the winding; swap two corners to keep
        // counter-clockwise fronts.
        let flip = self.lin.determinant() < 0.0;
        let tris: Vec<[u32; 3]> = raw
            .triangles
            .iter()
            .map(|t| if flip { [t[0], t[2], t[1]] } else { *t })
            .collect();
        let normals = self.vertex_normals(raw, &world, &tris);
        let (mut kept, mut skipped) = (0, 0);
        for t in &tris {
            let Some(ng) = face_normal(&world, t) else {
                skipped += 1;
                continue;
            };
            g.tris.push(Tri::new(t.map(|i| world[i as usize])));
            let corner = |i: u32| match &normals {
                Some(vn) if vn[i as usize] != DVec3::ZERO && vn[i as usize].is_finite() => {
                    vn[i as usize].as_vec3a()
                }
                _ => ng.as_vec3a(),
            };
            g.shade.push(Shade {
                normals: t.map(corner),
                material: self.material,
            });
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

    /// The mesh as a texture-space bake's receiver: world positions, shading
    /// normals, the triangles [`Placement::add`] keeps, texture coordinates.
    fn surface_mesh(&self, raw: &RawMesh) -> Result<SurfaceMesh> {
        let world = self
            .world_positions(raw)
            .map_err(|e| BakeError::Geometry(format!("texture receiver: {e}")))?;
        let flip = self.lin.determinant() < 0.0;
        let tris: Vec<[u32; 3]> = raw
            .triangles
            .iter()
            .map(|t| if flip { [t[0], t[2], t[1]] } else { *t })
            .collect();
        let normals = self
            .vertex_normals(raw, &world, &tris)
            .unwrap_or_else(|| vec![DVec3::ZERO; world.len()]);
        let kept: Vec<[u32; 3]> = tris
            .iter()
            .filter(|t| face_normal(&world, t).is_some())
            .copied()
            .collect();
        let kept_count = kept.len();
        let degenerate_triangles: Vec<[u32; 3]> = tris
            .iter()
            .filter(|t| face_normal(&world, t).is_none())
            .copied()
            .collect();
        Ok(SurfaceMesh {
            degenerate_triangles,
            positions: world.iter().map(|p| p.as_dvec3()).collect(),
            normals: normals
                .into_iter()
                .map(|n| if n.is_finite() { n } else { DVec3::ZERO })
                .collect(),
            degenerate: tris.len() - kept.len(),
            triangles: kept,
            uvs: raw.uvs.as_ref().map(|uv| {
                uv.iter()
                    .map(|t| DVec2::new(t[0] as f64, t[1] as f64))
                    .collect()
            }),
            materials: vec![self.material; kept_count],
            parts: vec![0; kept_count],
        })
    }

    /// Vertex positions in world space, rounded to single precision once
    /// per vertex (so that triangles sharing a vertex share its bits).
    fn world_positions(&self, raw: &RawMesh) -> std::result::Result<Vec<Vec3A>, String> {
        let world: Vec<Vec3A> = raw
            .positions
            .iter()
            .map(|p| (self.lin * DVec3::from(p.map(f64::from)) + self.translation).as_vec3a())
            .collect();
        match world.iter().position(|p| !p.is_finite()) {
            Some(i) => Err(format!(
                "vertex {i} leaves the single-precision range after the transform"
            )),
            None => Ok(world),
        }
    }

    /// Per-vertex shading normals when smooth: the file's, transformed, or
    /// area-weighted face normals welded by position; `None` when flat.
    fn vertex_normals(
        &self,
        raw: &RawMesh,
        world: &[Vec3A],
        tris: &[[u32; 3]],
    ) -> Option<Vec<DVec3>> {
        if !self.smooth {
            return None;
        }
        let Some(ns) = &raw.normals else {
            return Some(welded_normals(raw, world, tris));
        };
        let normal_matrix = self.lin.inverse().transpose();
        Some(
            ns.iter()
                .map(|n| (normal_matrix * DVec3::from(n.map(f64::from))).normalize_or_zero())
                .collect(),
        )
    }
}

/// The unit normal of triangle `t`, or `None` when it is degenerate.
fn face_normal(world: &[Vec3A], t: &[u32; 3]) -> Option<DVec3> {
    let [a, b, c] = t.map(|i| world[i as usize].as_dvec3());
    let (e1, e2, e3) = (b - a, c - a, c - b);
    let n = e1.cross(e2);
    let longest = e1
        .length_squared()
        .max(e2.length_squared())
        .max(e3.length_squared());
    let len = n.length();
    (len.is_finite() && len > 1e-10 * longest).then(|| n / len)
}

/// Area-weighted face normals summed over vertices welded by model-space
/// position.
fn welded_normals(raw: &RawMesh, world: &[Vec3A], tris: &[[u32; 3]]) -> Vec<DVec3> {
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
    for t in tris {
        if face_normal(world, t).is_none() {
            continue;
        }
        let [a, b, c] = t.map(|i| world[i as usize].as_dvec3());
        let n = (b - a).cross(c - a);
        for i in t {
            acc[keys[*i as usize]] += n;
        }
    }
    keys.iter().map(|&k| acc[k].normalize_or_zero()).collect()
}
