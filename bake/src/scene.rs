//! The scene description: a TOML file, parsed and validated.
//!
//! ```toml
//! [camera]
//! eye = [0.0, 1.2, 3.5]     # world position of the pinhole
//! target = [0.0, 0.4, 0.0]  # point at the image centre
//! up = [0.0, 1.0, 0.0]      # optional, default +Y
//! fov = 35.0                # vertical field of view, degrees, in (0, 180)
//! width = 256               # pixels
//! height = 256
//! spp = 4                   # optional, pixel sub-samples (box filter), default 1
//!
//! [lighting]
//! face_res = 32             # cubemap face resolution n, a power of two: M = 6·n² lights
//! texel_samples = 4         # optional, directions per cubemap texel S, default 4
//!
//! [materials.clay]
//! type = "lambert"
//! albedo = [0.8, 0.6, 0.5]
//!
//! [materials.porcelain]
//! type = "glossy"
//! albedo = [0.1, 0.2, 0.5]  # Lambertian base
//! specular = [0.04, 0.04, 0.04]  # Schlick F0
//! roughness = 0.2           # GGX alpha
//!
//! [[meshes]]
//! path = "../meshes/bunny.ply"   # .obj or .ply, relative to this file
//! material = "clay"
//! smooth = true             # optional, interpolated vertex normals (default) or flat
//! scale = 1.0               # optional, uniform or [x, y, z], default 1
//! rotation = [0.0, 30.0, 0.0]    # optional, Euler angles in degrees, default 0
//! translation = [0.0, 0.5, 0.0]  # optional, default 0
//!
//! [[quads]]                 # a rectangle in the local XZ plane, facing +Y
//! center = [0.0, 0.0, 0.0]
//! size = [8.0, 8.0]         # extent along local X and Z
//! rotation = [0.0, 0.0, 0.0]  # optional, Euler angles in degrees
//! material = "clay"
//!
//! [texture]                 # optional: bake texels of surfaces, not camera pixels
//! mesh = 0                  # index into [[meshes]] of the receiver, or "all" (atlas)
//! size = 256                # texture side S, 1..=4096: S² rows
//! parameterization = "atlas"  # optional: "atlas" (automatic charts, the default),
//!                           # "uv" (the mesh's own texture coordinates) or "sphere"
//! texels_per_unit = 40.0    # optional (atlas): texel density; size then optional
//! padding = 2               # optional (atlas): empty texels between charts, 0..=16
//! spp = 4                   # optional, sub-samples per texel over its footprint, default 4
//! dilate = 1                # optional, texels charts are grown by, 0..=8 (uv: 2, atlas: 1)
//! diffuse_only = false      # optional: bake a glossy receiver's Lambertian base
//!
//! [light_plane]             # optional: also bake every row over a light plane's face
//! origin = [0.0, 1.5, 0.0]  # a point of the plane
//! x_axis = [1.0, 0.0, 0.0]  # the plane's axes (normalized; y made orthogonal to x);
//! y_axis = [0.0, 0.0, 1.0]  # area lights shine from the side x × y (here −Y, down)
//! order = 32                # optional, face texels per side, a power of two in 1..=256
//! side = 4.0                # optional, face side in tangent units, (0, 1000], default 4
//! ```
//!
//! With `[texture]`, row `k` is texel `k` of an `S × S` texture over the
//! mesh (see `ltm_codec::RowLayout::Texture`); the camera is then only the
//! default view and is not baked. The receiver must be Lambertian (a
//! texture is view-independent) unless `diffuse_only = true`; every other
//! mesh and quad still casts shadows.
//!
//! Transforms map a model point `p` to `translation + R·(scale ⊙ p)` with
//! `R = Rz(rz)·Ry(ry)·Rx(rx)` for `rotation = [rx, ry, rz]`: the rotation
//! about X is applied first, then Y, then Z, each counter-clockwise when
//! looking down the axis towards the origin (right-handed).
//!
//! Unknown fields are errors, so that a misspelt setting is never silently
//! ignored.

use crate::error::{BakeError, Result};
use glam::DVec3;
use ltm_codec::{Parameterization, MAX_FACE_RES, MAX_PIXELS, MAX_SIDE, MAX_TEXTURE_SIZE};
use serde::de::{self, Deserializer, SeqAccess, Visitor};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};

/// The default scene (`assets/scenes/default.toml`), embedded; its mesh
/// paths are relative to `assets/scenes/`.
pub const DEFAULT_SCENE_TOML: &str = include_str!("../../assets/scenes/default.toml");

/// Largest pixel supersampling.
pub const MAX_SPP: u32 = 4096;
/// Largest number of direction samples per cubemap texel.
pub const MAX_TEXEL_SAMPLES: u32 = 65536;
/// Smallest GGX roughness (alpha).
pub const MIN_ROUGHNESS: f64 = 0.01;
/// Largest magnitude of a camera eye or target coordinate: rays are traced
/// in single precision, whose spacing at 10⁹ is already 64 units.
pub const MAX_CAMERA_COORD: f64 = 1e9;
/// Smallest distance between camera eye and target, relative to their
/// largest coordinate: below it the viewing direction is lost to rounding.
pub const MIN_VIEW_DISTANCE: f64 = 1e-9;
/// Smallest angle (radians) between camera up and the viewing direction.
pub const MIN_UP_ANGLE: f64 = 1e-9;

/// A parsed, validated scene description.
#[derive(Clone, Debug)]
pub struct SceneDesc {
    /// `[camera]`: the pinhole camera whose pixels are the rows.
    pub camera: CameraDesc,
    /// `[lighting]`: the cubemap whose texels are the columns.
    pub lighting: LightingDesc,
    /// `[materials.NAME]`, by name (sorted; a hit's material index counts
    /// in this order).
    pub materials: BTreeMap<String, MaterialDesc>,
    /// `[[meshes]]`, in file order.
    pub meshes: Vec<MeshDesc>,
    /// `[[quads]]`, in file order.
    pub quads: Vec<QuadDesc>,
    /// `[texture]`: bake the texels of a mesh instead of the camera's
    /// pixels.
    pub texture: Option<TextureDesc>,
    /// `[light_plane]`: also bake every row over the face of a plane that
    /// near-field area lights lie in.
    pub light_plane: Option<LightPlaneDesc>,
    /// Directory that relative mesh paths are resolved against.
    pub base_dir: PathBuf,
    /// Where the description came from, for messages.
    pub origin: String,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SceneFile {
    camera: CameraDesc,
    lighting: LightingDesc,
    #[serde(default)]
    materials: BTreeMap<String, MaterialDesc>,
    #[serde(default)]
    meshes: Vec<MeshDesc>,
    #[serde(default)]
    quads: Vec<QuadDesc>,
    texture: Option<TextureDesc>,
    light_plane: Option<LightPlaneDesc>,
}

/// The plane near-field area lights lie in (Sun and Ramamoorthi 2009,
/// §5.2.1): every row is also baked over its expanded top face.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LightPlaneDesc {
    /// A point of the plane.
    pub origin: [f64; 3],
    /// The plane's x axis (normalized when baked).
    pub x_axis: [f64; 3],
    /// The plane's y axis (made orthogonal to x and normalized); lights
    /// shine from the side `x × y`.
    pub y_axis: [f64; 3],
    /// Face texels per side, a power of two in 1..=256.
    #[serde(default = "default_plane_order")]
    pub order: u32,
    /// Face side in tangent units, (0, 1000].
    #[serde(default = "default_plane_side")]
    pub side: f64,
}

fn default_plane_order() -> u32 {
    32
}

fn default_plane_side() -> f64 {
    4.0
}

impl LightPlaneDesc {
    /// The plane, its axes orthonormalized: finite, axes nonzero and not
    /// parallel.
    pub fn plane(&self) -> Result<crate::plane::LightPlane> {
        let v = DVec3::from_array;
        crate::plane::LightPlane::new(v(self.origin), v(self.x_axis), v(self.y_axis))
    }

    /// The face as stored (the axes of [`LightPlaneDesc::plane`]), checked:
    /// order and side in range.
    pub fn basis(&self) -> Result<ltm_codec::PlaneBasis> {
        let basis = self.plane()?.basis(self.order, self.side);
        basis.validate().map_err(BakeError::Store)?;
        Ok(basis)
    }
}

/// A texture-space bake: the rows are the texels of a texture over the
/// receiving surfaces.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TextureDesc {
    /// The receiving surfaces: one mesh of `[[meshes]]`, or `"all"`.
    pub mesh: Receivers,
    /// Texture side S (1..=[`ltm_codec::MAX_TEXTURE_SIZE`]); 0 or absent
    /// with `texels_per_unit`: as large as the atlas needs.
    #[serde(default)]
    pub size: u32,
    /// How the surfaces are laid out over the square: `"atlas"` (the
    /// default), `"uv"` or `"sphere"`.
    #[serde(default = "default_parameterization")]
    #[serde(deserialize_with = "parameterization")]
    pub parameterization: Parameterization,
    /// Texels per world unit of length (`atlas` only): every part gets
    /// texels in proportion to its area. Without it the atlas fills `size`.
    #[serde(default)]
    pub texels_per_unit: Option<f64>,
    /// Empty texels between an atlas's charts (`atlas` only).
    #[serde(default = "default_padding")]
    pub padding: u32,
    /// Sub-samples per texel, spread over its footprint on the surface.
    #[serde(default = "default_texel_spp")]
    pub spp: u32,
    /// Texels that charts are grown by (`uv` and `atlas`), so that filtered
    /// lookups near a chart's edge do not read empty texels; default 2 for
    /// `uv`, 1 for `atlas` (half its default padding).
    #[serde(default)]
    pub dilate: Option<u32>,
    /// Bake only the Lambertian base of a glossy receiver.
    #[serde(default)]
    pub diffuse_only: bool,
}

/// The receiving surfaces of a texture-space bake.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum Receivers {
    /// One mesh: an index into `[[meshes]]`.
    Mesh(usize),
    /// Every mesh and quad of the scene (`mesh = "all"`, `atlas` only).
    All,
}

impl<'de> Deserialize<'de> for Receivers {
    fn deserialize<D: Deserializer<'de>>(d: D) -> std::result::Result<Receivers, D::Error> {
        struct V;
        impl de::Visitor<'_> for V {
            type Value = Receivers;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("an index into [[meshes]] (0, 1, …) or \"all\"")
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> std::result::Result<Receivers, E> {
                usize::try_from(v).map(Receivers::Mesh).map_err(|_| {
                    E::custom(format!(
                        "mesh index {v} (valid: an index into [[meshes]], 0 or more, or \"all\")"
                    ))
                })
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> std::result::Result<Receivers, E> {
                self.visit_i64(i64::try_from(v).unwrap_or(-1))
            }
            fn visit_str<E: de::Error>(self, v: &str) -> std::result::Result<Receivers, E> {
                if v == "all" {
                    Ok(Receivers::All)
                } else {
                    Err(E::custom(format!(
                        "mesh \"{v}\" (valid: an index into [[meshes]], or \"all\")"
                    )))
                }
            }
        }
        d.deserialize_any(V)
    }
}

impl std::str::FromStr for Receivers {
    type Err = String;
    /// A mesh index (`0`, `1`, …) or `all`, as `texture.mesh` and
    /// `--texture` take it.
    fn from_str(s: &str) -> std::result::Result<Receivers, String> {
        match s.trim() {
            "all" => Ok(Receivers::All),
            t => t.parse().map(Receivers::Mesh).map_err(|_| {
                format!("mesh '{s}' (valid: an index into [[meshes]], 0 or more, or all)")
            }),
        }
    }
}

impl Receivers {
    /// True when mesh `i` of `[[meshes]]` receives.
    pub fn has_mesh(self, i: usize) -> bool {
        match self {
            Receivers::Mesh(m) => m == i,
            Receivers::All => true,
        }
    }
}

impl TextureDesc {
    /// A `[texture]` section with only its receivers given: size 0 (to be
    /// set, or sized by a density) and every other key at its default.
    pub fn new(mesh: Receivers) -> TextureDesc {
        TextureDesc {
            mesh,
            size: 0,
            parameterization: default_parameterization(),
            texels_per_unit: None,
            padding: default_padding(),
            spp: default_texel_spp(),
            dilate: None,
            diffuse_only: false,
        }
    }

    /// Texels that charts are grown by: `dilate`, or the layout's default.
    pub fn dilate(&self) -> u32 {
        self.dilate.unwrap_or(match self.parameterization {
            Parameterization::Atlas => 1,
            _ => 2,
        })
    }
}

/// Largest chart dilation in texels.
pub const MAX_DILATE: u32 = 8;
/// Largest atlas padding in texels.
pub const MAX_PADDING: u32 = 16;
/// Largest texel density, texels per world unit.
pub const MAX_TEXELS_PER_UNIT: f64 = 1e6;

fn parameterization<'de, D: Deserializer<'de>>(
    d: D,
) -> std::result::Result<Parameterization, D::Error> {
    let s = String::deserialize(d)?;
    s.parse().map_err(de::Error::custom)
}

fn default_parameterization() -> Parameterization {
    Parameterization::Atlas
}
fn default_padding() -> u32 {
    2
}
fn default_texel_spp() -> u32 {
    4
}

/// Pinhole camera. Pixel `(x, y)` (row `y` counted from the top) is row
/// `p = y·width + x` of the matrix.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraDesc {
    /// World position of the pinhole; each coordinate finite, of magnitude
    /// at most [`MAX_CAMERA_COORD`].
    pub eye: [f64; 3],
    /// World point at the image centre; as `eye`, and apart from it.
    pub target: [f64; 3],
    /// World direction towards the image's top (any length; default +Y);
    /// not parallel to `target − eye`.
    #[serde(default = "default_up")]
    pub up: [f64; 3],
    /// Vertical field of view in degrees, in (0, 180).
    pub fov: f64,
    /// Image width in pixels, 1..=32768.
    pub width: u32,
    /// Image height in pixels, 1..=32768 (width·height ≤ 2²⁶).
    pub height: u32,
    /// Pixel sub-samples averaged into each row (a box pixel filter).
    #[serde(default = "default_spp")]
    pub spp: u32,
}

/// Lighting resolution.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LightingDesc {
    /// Cubemap face resolution n (a power of two); M = 6·n² columns.
    pub face_res: u32,
    /// Direction samples S per cubemap texel.
    #[serde(default = "default_texel_samples")]
    pub texel_samples: u32,
}

/// A material; `type = "lambert"` or `type = "glossy"`.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
#[non_exhaustive]
pub enum MaterialDesc {
    /// Lambertian: f_r = albedo/π.
    Lambert {
        /// Reflectance per RGB channel, each in `[0, 1]`.
        albedo: [f64; 3],
    },
    /// A Lambertian base plus a GGX specular lobe (see [`crate::material`]).
    Glossy {
        /// Reflectance of the Lambertian base per RGB channel, in `[0, 1]`.
        albedo: [f64; 3],
        /// Schlick's F0, the specular reflectance at normal incidence.
        specular: [f64; 3],
        /// GGX alpha (the width of the microfacet slope distribution).
        roughness: f64,
    },
}

/// A triangle mesh from an OBJ or PLY file.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MeshDesc {
    /// OBJ or PLY file, relative to the scene file.
    pub path: PathBuf,
    /// Name of a `[materials.NAME]` table.
    pub material: String,
    /// Interpolated vertex normals (true) or flat triangle normals.
    #[serde(default = "default_true")]
    pub smooth: bool,
    /// Scale applied first, in model units (finite, non-zero; negative
    /// mirrors).
    #[serde(default = "default_scale")]
    pub scale: Scale,
    /// Euler angles in degrees `[rx, ry, rz]`, applied X, then Y, then Z.
    #[serde(default)]
    pub rotation: [f64; 3],
    /// World offset applied last.
    #[serde(default)]
    pub translation: [f64; 3],
}

/// A rectangle: local `[-size/2, size/2]` in X and Z, facing +Y, rotated
/// then moved to `center`.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct QuadDesc {
    /// World position of the rectangle's centre.
    pub center: [f64; 3],
    /// Extent along local X and Z, world units, each > 0.
    pub size: [f64; 2],
    /// Euler angles in degrees `[rx, ry, rz]`, applied X, then Y, then Z.
    #[serde(default)]
    pub rotation: [f64; 3],
    /// Name of a `[materials.NAME]` table.
    pub material: String,
}

/// A uniform (`scale = 2.0`) or per-axis (`scale = [1, 2, 1]`) scale: the
/// factors along X, Y and Z.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Scale(pub [f64; 3]);

impl<'de> Deserialize<'de> for Scale {
    fn deserialize<D: Deserializer<'de>>(d: D) -> std::result::Result<Scale, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = Scale;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a number or an array of 3 numbers")
            }
            fn visit_f64<E: de::Error>(self, v: f64) -> std::result::Result<Scale, E> {
                Ok(Scale([v; 3]))
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> std::result::Result<Scale, E> {
                Ok(Scale([v as f64; 3]))
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> std::result::Result<Scale, E> {
                Ok(Scale([v as f64; 3]))
            }
            fn visit_seq<A: SeqAccess<'de>>(
                self,
                mut seq: A,
            ) -> std::result::Result<Scale, A::Error> {
                let mut s = [0.0; 3];
                for (i, v) in s.iter_mut().enumerate() {
                    *v = seq
                        .next_element()?
                        .ok_or_else(|| de::Error::invalid_length(i, &self))?;
                }
                if seq.next_element::<f64>()?.is_some() {
                    return Err(de::Error::invalid_length(4, &self));
                }
                Ok(Scale(s))
            }
        }
        d.deserialize_any(V)
    }
}

fn default_up() -> [f64; 3] {
    [0.0, 1.0, 0.0]
}
fn default_spp() -> u32 {
    1
}
fn default_texel_samples() -> u32 {
    4
}
fn default_true() -> bool {
    true
}
fn default_scale() -> Scale {
    Scale([1.0; 3])
}

/// Settings that override the scene file (e.g. from the command line).
#[derive(Clone, Copy, Debug, Default)]
pub struct Overrides {
    /// `camera.width` (`--width`).
    pub width: Option<u32>,
    /// `camera.height` (`--height`).
    pub height: Option<u32>,
    /// `lighting.face_res` (`--face-res`).
    pub face_res: Option<u32>,
    /// `lighting.texel_samples` (`--texel-samples`).
    pub texel_samples: Option<u32>,
    /// `camera.spp` (`--spp`).
    pub spp: Option<u32>,
    /// `texture.size` (`--texture-size`).
    pub texture_size: Option<u32>,
    /// `texture.texels_per_unit` (`--texels-per-unit`).
    pub texels_per_unit: Option<f64>,
    /// `texture.mesh` (`--texture`): a scene without a `[texture]` section
    /// gets one, its other keys at their defaults.
    pub texture: Option<Receivers>,
    /// `texture.parameterization` (`--parameterization`).
    pub parameterization: Option<Parameterization>,
}

impl SceneDesc {
    /// Reads and validates a scene file; mesh paths resolve against its
    /// directory. Meshes are not opened until [`crate::Scene::build`].
    pub fn load(path: &Path) -> Result<SceneDesc> {
        let text = std::fs::read_to_string(path).map_err(|e| BakeError::io(path, e))?;
        let base = path.parent().unwrap_or(Path::new("")).to_path_buf();
        SceneDesc::parse(&text, &base, path)
    }

    /// Parses and validates scene TOML; `name` is used in messages.
    pub fn parse(text: &str, base_dir: &Path, name: &Path) -> Result<SceneDesc> {
        let file: SceneFile = toml::from_str(text).map_err(|e| BakeError::SceneSyntax {
            path: name.to_path_buf(),
            message: toml_message(text, &e),
        })?;
        let desc = SceneDesc {
            camera: file.camera,
            lighting: file.lighting,
            materials: file.materials,
            meshes: file.meshes,
            quads: file.quads,
            texture: file.texture,
            light_plane: file.light_plane,
            base_dir: base_dir.to_path_buf(),
            origin: name.display().to_string(),
        };
        desc.validate()?;
        Ok(desc)
    }

    /// The embedded default scene (the bunny and a glossy teapot on a ground
    /// quad), with mesh paths resolved against `assets_dir` (the repository's
    /// `assets/` directory, which holds `meshes/`).
    pub fn default_scene(assets_dir: &Path) -> Result<SceneDesc> {
        SceneDesc::parse(
            DEFAULT_SCENE_TOML,
            &assets_dir.join("scenes"),
            &assets_dir.join("scenes").join("default.toml"),
        )
    }

    /// Applies overrides and re-validates; a bad override is reported as
    /// coming from the command line.
    pub fn apply(&mut self, o: &Overrides) -> Result<()> {
        let cl = "command line";
        for (flag, v) in [
            ("--width", o.width),
            ("--height", o.height),
            ("--spp", o.spp),
            ("--face-res", o.face_res),
            ("--texel-samples", o.texel_samples),
        ] {
            if let Some(v) = v {
                let (lo, hi) = match flag {
                    "--width" | "--height" => (1, MAX_SIDE),
                    "--spp" => (1, MAX_SPP),
                    "--face-res" => (1, MAX_FACE_RES),
                    _ => (1, MAX_TEXEL_SAMPLES),
                };
                if v < lo || v > hi {
                    return Err(BakeError::range(cl, flag, v, format!("{lo}..={hi}")));
                }
                if flag == "--face-res" && !v.is_power_of_two() {
                    return Err(BakeError::range(
                        cl,
                        flag,
                        v,
                        format!("a power of two in 1..={MAX_FACE_RES}"),
                    ));
                }
            }
        }
        let c = &mut self.camera;
        c.width = o.width.unwrap_or(c.width);
        c.height = o.height.unwrap_or(c.height);
        c.spp = o.spp.unwrap_or(c.spp);
        let l = &mut self.lighting;
        l.face_res = o.face_res.unwrap_or(l.face_res);
        l.texel_samples = o.texel_samples.unwrap_or(l.texel_samples);
        self.apply_texture(o)?;
        self.validate()
    }

    /// The texture flags of [`SceneDesc::apply`]: `--texture` adds or
    /// retargets the `[texture]` section; the others need one.
    fn apply_texture(&mut self, o: &Overrides) -> Result<()> {
        let cl = "command line";
        if let Some(mesh) = o.texture {
            match &mut self.texture {
                Some(t) => t.mesh = mesh,
                None if o.texture_size.is_none() && o.texels_per_unit.is_none() => {
                    return Err(BakeError::invalid(
                        cl,
                        "--texture",
                        "the scene has no [texture] section: give the texture's side with --texture-size S (or a density with --texels-per-unit D)".to_string(),
                    ))
                }
                None => self.texture = Some(TextureDesc::new(mesh)),
            }
        }
        let flags = [
            ("--texture-size", o.texture_size.is_some()),
            ("--texels-per-unit", o.texels_per_unit.is_some()),
            ("--parameterization", o.parameterization.is_some()),
        ];
        let Some((flag, _)) = flags.iter().find(|(_, given)| *given) else {
            return Ok(());
        };
        let Some(t) = &mut self.texture else {
            return Err(BakeError::invalid(
                cl,
                flag,
                "the scene has no [texture] section (it bakes camera pixels); add --texture MESH (an index into [[meshes]], or all)".to_string(),
            ));
        };
        if let Some(d) = o.texels_per_unit {
            t.texels_per_unit = Some(d);
            // A density alone sizes the texture to the atlas.
            t.size = o.texture_size.unwrap_or(0);
        }
        t.size = o.texture_size.unwrap_or(t.size);
        t.parameterization = o.parameterization.unwrap_or(t.parameterization);
        Ok(())
    }

    /// Checks every field against its valid range and cross-references
    /// (material names).
    pub fn validate(&self) -> Result<()> {
        let o = &self.origin;
        let c = &self.camera;
        validate_camera(o, c)?;
        if !(c.fov > 0.0 && c.fov < 180.0) {
            return Err(BakeError::range(
                o,
                "camera.fov",
                c.fov,
                "0 < fov < 180 degrees",
            ));
        }
        for (f, v) in [("camera.width", c.width), ("camera.height", c.height)] {
            if v == 0 || v > MAX_SIDE {
                return Err(BakeError::range(o, f, v, format!("1..={MAX_SIDE}")));
            }
        }
        let pixels = c.width as u64 * c.height as u64;
        if pixels > MAX_PIXELS {
            return Err(BakeError::range(
                o,
                "camera.width·camera.height",
                pixels,
                format!("at most {MAX_PIXELS}"),
            ));
        }
        if c.spp == 0 || c.spp > MAX_SPP {
            return Err(BakeError::range(
                o,
                "camera.spp",
                c.spp,
                format!("1..={MAX_SPP}"),
            ));
        }
        self.validate_lighting()?;
        self.validate_materials()?;
        self.validate_geometry()?;
        self.validate_texture()?;
        if let Some(p) = &self.light_plane {
            p.basis()
                .map_err(|e| BakeError::invalid(o, "light_plane", format!("{e}")))?;
        }
        Ok(())
    }

    fn validate_lighting(&self) -> Result<()> {
        let o = &self.origin;
        let l = &self.lighting;
        if !l.face_res.is_power_of_two() || l.face_res > MAX_FACE_RES {
            return Err(BakeError::range(
                o,
                "lighting.face_res",
                l.face_res,
                format!("a power of two in 1..={MAX_FACE_RES}"),
            ));
        }
        if l.texel_samples == 0 || l.texel_samples > MAX_TEXEL_SAMPLES {
            return Err(BakeError::range(
                o,
                "lighting.texel_samples",
                l.texel_samples,
                format!("1..={MAX_TEXEL_SAMPLES}"),
            ));
        }
        Ok(())
    }

    fn validate_materials(&self) -> Result<()> {
        let o = &self.origin;
        for (name, m) in &self.materials {
            let f = |k: &str| format!("materials.{name}.{k}");
            let (albedo, spec, rough) = match m {
                MaterialDesc::Lambert { albedo } => (albedo, None, None),
                MaterialDesc::Glossy {
                    albedo,
                    specular,
                    roughness,
                } => (albedo, Some(specular), Some(*roughness)),
            };
            unit3(o, &f("albedo"), *albedo)?;
            if let Some(s) = spec {
                unit3(o, &f("specular"), *s)?;
            }
            if let Some(r) = rough {
                if !(MIN_ROUGHNESS..=1.0).contains(&r) {
                    return Err(BakeError::range(
                        o,
                        f("roughness"),
                        r,
                        format!("{MIN_ROUGHNESS}..=1 (GGX alpha)"),
                    ));
                }
            }
        }
        Ok(())
    }

    fn validate_geometry(&self) -> Result<()> {
        let o = &self.origin;
        if self.meshes.is_empty() && self.quads.is_empty() {
            return Err(BakeError::invalid(
                o,
                "meshes, quads",
                "the scene has no geometry; add a [[meshes]] or [[quads]] entry",
            ));
        }
        for (i, m) in self.meshes.iter().enumerate() {
            let f = |k: &str| format!("meshes[{i}].{k}");
            self.known_material(&f("material"), &m.material)?;
            for (k, v) in m.scale.0.iter().enumerate() {
                if !v.is_finite() || *v == 0.0 {
                    return Err(BakeError::range(
                        o,
                        format!("{}[{k}]", f("scale")),
                        v,
                        "finite and non-zero",
                    ));
                }
            }
            finite3(o, &f("rotation"), m.rotation)?;
            finite3(o, &f("translation"), m.translation)?;
        }
        for (i, q) in self.quads.iter().enumerate() {
            let f = |k: &str| format!("quads[{i}].{k}");
            self.known_material(&f("material"), &q.material)?;
            finite3(o, &f("center"), q.center)?;
            finite3(o, &f("rotation"), q.rotation)?;
            for (k, v) in q.size.iter().enumerate() {
                if !(v.is_finite() && *v > 0.0) {
                    return Err(BakeError::range(
                        o,
                        format!("{}[{k}]", f("size")),
                        v,
                        "finite and > 0",
                    ));
                }
            }
        }
        Ok(())
    }

    fn validate_texture(&self) -> Result<()> {
        let Some(t) = &self.texture else {
            return Ok(());
        };
        let o = &self.origin;
        let atlas = t.parameterization == Parameterization::Atlas;
        match t.mesh {
            Receivers::Mesh(m) if m >= self.meshes.len() => {
                return Err(BakeError::range(
                    o,
                    "texture.mesh",
                    m,
                    format!("an index into [[meshes]], 0..{}", self.meshes.len()),
                ))
            }
            Receivers::All if !atlas => {
                return Err(BakeError::invalid(
                    o,
                    "texture.mesh",
                    format!("\"all\" needs parameterization = \"atlas\" (one layout over every mesh and quad), not \"{}\"", t.parameterization.name()),
                ))
            }
            _ => {}
        }
        self.validate_texture_size(t)?;
        for (field, value, max) in [
            ("texture.spp", t.spp, MAX_SPP),
            ("texture.dilate", t.dilate(), MAX_DILATE),
            ("texture.padding", t.padding, MAX_PADDING),
        ] {
            if value > max || (field == "texture.spp" && value == 0) {
                let lo = u32::from(field == "texture.spp");
                return Err(BakeError::range(o, field, value, format!("{lo}..={max}")));
            }
        }
        self.validate_receiver_materials(t)
    }

    /// `size` and `texels_per_unit`: a size in range, or a density (atlas
    /// only) with an optional size.
    fn validate_texture_size(&self, t: &TextureDesc) -> Result<()> {
        let o = &self.origin;
        if let Some(d) = t.texels_per_unit {
            if t.parameterization != Parameterization::Atlas {
                return Err(BakeError::invalid(
                    o,
                    "texture.texels_per_unit",
                    format!(
                        "only an atlas takes a texel density, not parameterization = \"{}\"",
                        t.parameterization.name()
                    ),
                ));
            }
            if !(d.is_finite() && d > 0.0 && d <= MAX_TEXELS_PER_UNIT) {
                return Err(BakeError::range(
                    o,
                    "texture.texels_per_unit",
                    d,
                    format!("above 0, at most {MAX_TEXELS_PER_UNIT:e}"),
                ));
            }
        }
        let size_ok = t.size <= MAX_TEXTURE_SIZE && (t.size > 0 || t.texels_per_unit.is_some());
        if !size_ok {
            return Err(BakeError::range(
                o,
                "texture.size",
                t.size,
                format!("1..={MAX_TEXTURE_SIZE} (or absent with texels_per_unit)"),
            ));
        }
        Ok(())
    }

    /// Every receiving surface's material holds Lambertian reflection.
    fn validate_receiver_materials(&self, t: &TextureDesc) -> Result<()> {
        let meshes = self
            .meshes
            .iter()
            .enumerate()
            .filter(|(i, _)| t.mesh.has_mesh(*i))
            .map(|(_, m)| &m.material);
        let quads = self
            .quads
            .iter()
            .filter(|_| t.mesh == Receivers::All)
            .map(|q| &q.material);
        for material in meshes.chain(quads) {
            if matches!(
                self.materials.get(material),
                Some(MaterialDesc::Glossy { .. })
            ) && !t.diffuse_only
            {
                return Err(BakeError::invalid(
                    &self.origin,
                    "texture.mesh",
                    format!("the receiver's material \"{material}\" is glossy, but a texture is view-independent and holds only Lambertian reflection; use a lambert material, or set texture.diffuse_only = true to bake its Lambertian base"),
                ));
            }
        }
        Ok(())
    }

    fn known_material(&self, field: &str, name: &str) -> Result<()> {
        if self.materials.contains_key(name) {
            return Ok(());
        }
        let known: Vec<&str> = self.materials.keys().map(String::as_str).collect();
        Err(BakeError::invalid(
            &self.origin,
            field,
            format!(
                "unknown material \"{name}\" (defined: {})",
                if known.is_empty() {
                    "none; add a [materials.NAME] table".to_string()
                } else {
                    known.join(", ")
                }
            ),
        ))
    }

    /// Resolves a mesh path against the scene's directory.
    pub fn resolve(&self, path: &Path) -> PathBuf {
        if path.is_absolute() {
            path.to_path_buf()
        } else {
            self.base_dir.join(path)
        }
    }

    /// The transport's size in bytes (rows × 6·n² lights × channels × 4),
    /// known before the scene is built: for checking the free space before
    /// any work.
    pub fn transport_bytes(&self) -> u64 {
        let rows = match &self.texture {
            // An atlas sized by its texel density: known once it is made.
            Some(t) => t.size as u64 * t.size as u64,
            None => self.camera.width as u64 * self.camera.height as u64,
        };
        let n = self.lighting.face_res as u64;
        let channels = if self.needs_color_transport() { 3 } else { 1 };
        rows.saturating_mul(6 * n * n).saturating_mul(channels * 4)
    }

    /// True when some mesh or quad uses a glossy material, so that the
    /// transport needs 3 channels.
    pub fn needs_color_transport(&self) -> bool {
        if self.texture.is_some() {
            return false; // the receiver's Lambertian albedo; others only shadow
        }
        let used = self
            .meshes
            .iter()
            .map(|m| &m.material)
            .chain(self.quads.iter().map(|q| &q.material));
        used.into_iter()
            .any(|name| matches!(self.materials.get(name), Some(MaterialDesc::Glossy { .. })))
    }
}

/// A one-line message with line and column from a TOML error.
fn toml_message(text: &str, e: &toml::de::Error) -> String {
    let msg = e.message().trim().replace('\n', "; ");
    match e.span() {
        Some(span) => {
            let before = &text[..span.start.min(text.len())];
            let line = before.matches('\n').count() + 1;
            let line_start = before.rfind('\n').map_or(0, |i| i + 1);
            let col = before.len() - line_start + 1;
            let src = text[line_start..].lines().next().unwrap_or("").trim();
            format!("line {line}, column {col} (`{src}`): {msg}")
        }
        None => msg,
    }
}

/// Checks the camera's placement: finite coordinates of a magnitude single
/// precision can trace, a target apart from the eye, an up vector across
/// the viewing direction. Each message names what is actually wrong.
fn validate_camera(o: &str, c: &CameraDesc) -> Result<()> {
    for (field, v) in [("camera.eye", c.eye), ("camera.target", c.target)] {
        if !v
            .iter()
            .all(|x| x.is_finite() && x.abs() <= MAX_CAMERA_COORD)
        {
            return Err(BakeError::range(
                o,
                field,
                format!("{v:?}"),
                format!("finite coordinates of magnitude at most {MAX_CAMERA_COORD:e}, which single-precision ray tracing resolves"),
            ));
        }
    }
    finite3(o, "camera.up", c.up)?;
    let (eye, target, up) = (DVec3::from(c.eye), DVec3::from(c.target), DVec3::from(c.up));
    let view = target - eye;
    if view == DVec3::ZERO {
        return Err(BakeError::invalid(o, "camera.target", format!(
            "{:?} equals camera.eye; the camera needs a viewing direction (valid: a target apart from the eye)",
            c.target
        )));
    }
    let size = eye.abs().max(target.abs()).max_element();
    if view.length() < MIN_VIEW_DISTANCE * size {
        return Err(BakeError::invalid(o, "camera.target", format!(
            "{:?} is at a distance of {:e} from camera.eye = {:?}, too close to define a viewing direction (valid: a distance of at least {:e}, {MIN_VIEW_DISTANCE:e} × the largest coordinate)",
            c.target, view.length(), c.eye, MIN_VIEW_DISTANCE * size
        )));
    }
    if up == DVec3::ZERO {
        return Err(BakeError::invalid(
            o,
            "camera.up",
            format!(
                "{:?} is zero (valid: a non-zero vector across the viewing direction target − eye)",
                c.up
            ),
        ));
    }
    let sin = unit(view).cross(unit(up)).length();
    if sin < MIN_UP_ANGLE {
        return Err(BakeError::invalid(o, "camera.up", format!(
            "{:?} is parallel to the viewing direction target − eye = {:?} (angle {:e} rad; valid: at least {MIN_UP_ANGLE:e} rad)",
            c.up, view.to_array(), sin.asin()
        )));
    }
    Ok(())
}

/// `v / |v|` without overflow or underflow for a finite non-zero `v`.
fn unit(v: DVec3) -> DVec3 {
    (v / v.abs().max_element()).normalize()
}

fn finite3(o: &str, field: &str, v: [f64; 3]) -> Result<()> {
    if v.iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(BakeError::range(
            o,
            field,
            format!("{v:?}"),
            "finite numbers",
        ))
    }
}

fn unit3(o: &str, field: &str, v: [f64; 3]) -> Result<()> {
    if v.iter().all(|x| (0.0..=1.0).contains(x)) {
        Ok(())
    } else {
        Err(BakeError::range(
            o,
            field,
            format!("{v:?}"),
            "each component in 0..=1",
        ))
    }
}
