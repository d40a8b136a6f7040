//! A small test scene: a camera over a ground quad and one mesh.

/// A scene description (TOML) of `width`×`height` pixels and face
/// resolution `face_res`: one Lambertian mesh from the OBJ file `mesh`
/// (relative to the scene file), raised 0.6 above a 4×4 ground quad.
pub fn scene_toml(mesh: &str, width: u32, height: u32, face_res: u32) -> String {
    SCENE
        .replace("MESH", mesh)
        .replace("WIDTH", &width.to_string())
        .replace("HEIGHT", &height.to_string())
        .replace("FACE_RES", &face_res.to_string())
}

/// A `[texture]` section: a 16² sphere parameterization of mesh 0.
pub const TEXTURE_SPHERE_16: &str =
    "\n[texture]\nmesh = 0\nsize = 16\nparameterization = \"sphere\"\nspp = 1\n";

const SCENE: &str = r#"
[camera]
eye = [0.0, 1.0, 3.0]
target = [0.0, 0.5, 0.0]
fov = 30.0
width = WIDTH
height = HEIGHT

[lighting]
face_res = FACE_RES
texel_samples = 1

[materials.clay]
type = "lambert"
albedo = [0.7, 0.6, 0.5]

[[meshes]]
path = "MESH"
material = "clay"
translation = [0.0, 0.6, 0.0]

[[quads]]
center = [0.0, 0.0, 0.0]
size = [4.0, 4.0]
material = "clay"
"#;
