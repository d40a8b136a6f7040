//! The input identity of a bake: a digest of everything that determines its
//! rows, stored in the raw store's header ([`ltm_codec::RawHeader::input_id`])
//! so that an interrupted bake is resumed only from a `.partial` file baked
//! from the same inputs.
//!
//! The identity is the SHA-256 (FIPS 180-4) of this sequence, each
//! string as a little-endian `u64` byte count and its UTF-8 bytes, each
//! number little-endian (`f64` by its IEEE-754 bits), each `bool` one byte:
//!
//! 1. the string `"ltm-bake input identity"`, [`ROWS_VERSION`] (`u32`) and
//!    the crate version string;
//! 2. the camera: eye, target, up (3 `f64` each), fov (`f64`), width,
//!    height, spp (`u32` each);
//! 3. the lighting: face_res, texel_samples (`u32`);
//! 4. the material count (`u64`), then per material in name order: name,
//!    type (`"lambert"` or `"glossy"`), albedo (3 `f64`), and for glossy
//!    specular (3 `f64`) and roughness (`f64`);
//! 5. the mesh count (`u64`), then per mesh: material name, smooth, scale,
//!    rotation, translation (3 `f64` each), the file format (`"OBJ"` or
//!    `"PLY"`) and the SHA-256 of the file's bytes (32 bytes) — the bytes
//!    that were parsed, so an edited mesh changes the identity even at the
//!    same size and modification time;
//! 6. the quad count (`u64`), then per quad: center (3 `f64`), size (2
//!    `f64`), rotation (3 `f64`), material name.
//!
//! The description is the one the scene was built from, after command-line
//! overrides. Mesh paths and the scene file's location are not part of it:
//! moving a scene directory keeps its identity.

use crate::scene::{MaterialDesc, SceneDesc};
use sha2::{Digest, Sha256};

/// Version of the row computation, part of the identity. It changes
/// whenever ltm-bake computes different rows from the same inputs, so that
/// a `.partial` file of an older computation is not resumed. 2: watertight
/// ray/triangle intersection.
pub const ROWS_VERSION: u32 = 2;

/// A SHA-256 fed with typed values.
struct Feed(Sha256);

impl Feed {
    fn str(&mut self, s: &str) {
        self.0.update((s.len() as u64).to_le_bytes());
        self.0.update(s.as_bytes());
    }
    fn u32(&mut self, v: u32) {
        self.0.update(v.to_le_bytes());
    }
    fn count(&mut self, n: usize) {
        self.0.update((n as u64).to_le_bytes());
    }
    fn f64s(&mut self, v: &[f64]) {
        for x in v {
            self.0.update(x.to_bits().to_le_bytes());
        }
    }
    fn bool(&mut self, b: bool) {
        self.0.update([u8::from(b)]);
    }
}

/// The identity of a bake of `desc` whose mesh files (in `desc.meshes`
/// order) have the SHA-256 digests `meshes`, with their formats.
pub(crate) fn scene_identity(desc: &SceneDesc, meshes: &[([u8; 32], &str)]) -> [u8; 32] {
    let mut f = Feed(Sha256::new());
    f.str("ltm-bake input identity");
    f.u32(ROWS_VERSION);
    f.str(env!("CARGO_PKG_VERSION"));
    let c = &desc.camera;
    f.f64s(&[c.eye, c.target, c.up].concat());
    f.f64s(&[c.fov]);
    for v in [c.width, c.height, c.spp] {
        f.u32(v);
    }
    f.u32(desc.lighting.face_res);
    f.u32(desc.lighting.texel_samples);
    f.count(desc.materials.len());
    for (name, m) in &desc.materials {
        f.str(name);
        material(&mut f, m);
    }
    f.count(desc.meshes.len());
    for (m, (digest, format)) in desc.meshes.iter().zip(meshes) {
        f.str(&m.material);
        f.bool(m.smooth);
        f.f64s(&[m.scale.0, m.rotation, m.translation].concat());
        f.str(format);
        f.0.update(digest);
    }
    f.count(desc.quads.len());
    for q in &desc.quads {
        f.f64s(&q.center);
        f.f64s(&q.size);
        f.f64s(&q.rotation);
        f.str(&q.material);
    }
    if let Some(t) = &desc.texture {
        // Absent for image bakes, whose identities are unchanged.
        f.str("texture");
        match t.mesh {
            crate::scene::Receivers::Mesh(m) => f.count(m),
            _ => f.str("all"),
        }
        f.u32(t.size);
        f.str(t.parameterization.name());
        f.u32(t.spp);
        f.u32(t.dilate());
        f.bool(t.diffuse_only);
        if t.parameterization == ltm_codec::Parameterization::Atlas {
            // The atlas is xatlas's output: its version is an input.
            f.str(ltm_xatlas::XATLAS_VERSION);
            f.u32(t.padding);
            f.f64s(&[t.texels_per_unit.unwrap_or(0.0)]);
        }
    }
    if let Some(p) = &desc.light_plane {
        // Absent without a light plane, whose identities are unchanged.
        f.str("light_plane");
        f.f64s(&[p.origin, p.x_axis, p.y_axis].concat());
        f.u32(p.order);
        f.f64s(&[p.side]);
    }
    f.0.finalize().into()
}

fn material(f: &mut Feed, m: &MaterialDesc) {
    match m {
        MaterialDesc::Lambert { albedo } => {
            f.str("lambert");
            f.f64s(albedo);
        }
        MaterialDesc::Glossy {
            albedo,
            specular,
            roughness,
        } => {
            f.str("glossy");
            f.f64s(albedo);
            f.f64s(specular);
            f.f64s(&[*roughness]);
        }
    }
}
