//! A small test scene (a camera over a ground quad and one mesh) and a
//! procedural closed mesh to put in it.

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

/// A closed genus-0 mesh of 2·6·k² triangles: a cube of k×k quads per
/// face, its vertices pushed toward a sphere (welded at the edges).
pub fn blob_obj(k: usize) -> String {
    use std::fmt::Write as _;
    let mut verts: Vec<[i64; 3]> = Vec::new();
    let mut index = std::collections::BTreeMap::new();
    let mut id = |v: [i64; 3], verts: &mut Vec<[i64; 3]>| {
        *index.entry(v).or_insert_with(|| {
            verts.push(v);
            verts.len()
        })
    };
    let k = k as i64;
    let mut faces = Vec::new();
    for axis in 0..3 {
        for side in [-k, k] {
            let at = |u: i64, v: i64| {
                let mut p = [0; 3];
                p[axis] = side;
                p[(axis + 1) % 3] = u;
                p[(axis + 2) % 3] = v;
                p
            };
            for u in (-k..k).step_by(2) {
                for v in (-k..k).step_by(2) {
                    let q = [at(u, v), at(u + 2, v), at(u + 2, v + 2), at(u, v + 2)];
                    let q = q.map(|p| id(p, &mut verts));
                    let (a, b) = if side > 0 {
                        ([q[0], q[1], q[2]], [q[0], q[2], q[3]])
                    } else {
                        ([q[0], q[2], q[1]], [q[0], q[3], q[2]])
                    };
                    faces.push(a);
                    faces.push(b);
                }
            }
        }
    }
    let mut s = String::new();
    for v in &verts {
        let p = v.map(|x| x as f64);
        let l = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        let r = 0.4 * (0.75 + 0.25 * p[0].abs().max(p[1].abs()).max(p[2].abs()) / k as f64);
        writeln!(s, "v {} {} {}", p[0] / l * r, p[1] / l * r, p[2] / l * r).unwrap();
    }
    for f in &faces {
        writeln!(s, "f {} {} {}", f[0], f[1], f[2]).unwrap();
    }
    s
}
