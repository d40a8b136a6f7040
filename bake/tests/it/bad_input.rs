//! Bad scene and mesh input: each case is a clear error, never a panic.

use crate::common;

use common::*;
use ltm_bake::{BakeError, Overrides, SceneDesc};

fn mesh_scene(file: &str) -> String {
    scene_toml(
        CAMERA,
        LIGHTING,
        &format!("[[meshes]]\npath = \"{file}\"\nmaterial = \"grey\"\n"),
    )
}

#[test]
fn missing_mesh_names_the_file() {
    let (_d, r) = build(&mesh_scene("nowhere.obj"), &[]);
    let (e, msg) = err(r);
    assert!(matches!(e, BakeError::MeshIo { .. }), "{msg}");
    assert!(
        msg.contains("nowhere.obj") && msg.contains("meshes[0].path"),
        "{msg}"
    );
}

#[test]
fn unreadable_mesh_is_an_io_error() {
    // A directory named like a mesh cannot be read as a file.
    let d = dir_with(&[]);
    std::fs::create_dir(d.path().join("dir.obj")).unwrap();
    let path = d.path().join("scene.toml");
    std::fs::write(&path, mesh_scene("dir.obj")).unwrap();
    let r = SceneDesc::load(&path).and_then(|s| ltm_bake::Scene::build(&s));
    let (e, msg) = err(r);
    assert!(matches!(e, BakeError::MeshIo { .. }), "{msg}");
    assert!(msg.contains("dir.obj"), "{msg}");
}

#[test]
fn unsupported_extension() {
    let (_d, r) = build(&mesh_scene("m.stl"), &[("m.stl", b"solid x")]);
    let (_, msg) = err(r);
    assert!(msg.contains("m.stl") && msg.contains(".obj, .ply"), "{msg}");
}

#[test]
fn malformed_obj() {
    for (text, what) in [
        ("v 1 2\nv 0 0 0\nv 1 1 1\nf 1 2 3\n", "position"),
        ("v 0 0 0\nv 1 0 0\nv 0 0 1\nf 1 2 9\n", "out of"),
        ("v 0 0 0\nv 1 0 0\nv 0 0 1\nf 1 x 3\n", "face"),
        ("v 0 0 0\nv 1 0 0\n", "no faces"),
    ] {
        let (_d, r) = build(&mesh_scene("m.obj"), &[("m.obj", text.as_bytes())]);
        let (e, msg) = err(r);
        assert!(
            matches!(e, BakeError::MalformedMesh { .. }),
            "{text:?}: {msg}"
        );
        assert!(msg.contains("m.obj") && msg.contains("OBJ"), "{msg}");
        assert!(msg.to_lowercase().contains(what), "{text:?}: {msg}");
    }
}

fn ply_ascii(body: &str, nv: usize, nf: usize) -> String {
    format!(
        "ply\nformat ascii 1.0\ncomment test\nelement vertex {nv}\nproperty float x\nproperty float y\nproperty float z\nelement face {nf}\nproperty list uchar int vertex_indices\nend_header\n{body}"
    )
}

#[test]
fn malformed_ply() {
    let good = "0 0 0\n1 0 0\n0 0 1\n3 0 1 2\n";
    let cases: Vec<(String, &str)> = vec![
        (good.to_string(), ""), // replaced below by the header variants
        (
            ply_ascii("0 0 0\n1 0 0\n0 0 1\n3 0 1 5\n", 3, 1),
            "out of range",
        ),
        (ply_ascii("0 0 0\n1 0 0\n", 3, 1), "truncated"),
        (
            ply_ascii("0 0 0\n1 0 0\n0 0 1\n3 0 1", 3, 1),
            "end of file in face 0",
        ),
        (
            ply_ascii("0 0 0\n1 0 zz\n0 0 1\n3 0 1 2\n", 3, 1),
            "not a number",
        ),
        (
            ply_ascii("0 0 0\n1 0 0\n0 0 1\n2 0 1\n", 3, 1),
            "at least 3",
        ),
        (format!("plyx\n{}", &ply_ascii(good, 3, 1)[4..]), "\"ply\""),
        (
            ply_ascii(good, 3, 1).replace("format ascii 1.0", "format ascii 2.0"),
            "unknown format",
        ),
        (
            ply_ascii(good, 3, 1).replace("format ascii 1.0", "format binary_big_endian 1.0"),
            "big_endian",
        ),
        (
            ply_ascii(good, 3, 1).replace("element vertex 3", "element vertex three"),
            "element count",
        ),
        (
            ply_ascii(good, 3, 1).replace("property float y", "property quad y"),
            "header line 6",
        ),
        (
            ply_ascii(good, 3, 1).replace("end_header\n", ""),
            "end_header",
        ),
        (
            ply_ascii(good, 3, 1).replace("property float z\n", ""),
            "lacks",
        ),
        (
            ply_ascii(good, 3, 1).replace("format ascii 1.0\n", ""),
            "no format",
        ),
        (
            ply_ascii(good, 3, 1).replace("element vertex 3", "element vertex 99999999999"),
            "truncated",
        ),
    ];
    for (text, what) in cases.into_iter().skip(1) {
        let (_d, r) = build(&mesh_scene("m.ply"), &[("m.ply", text.as_bytes())]);
        let (e, msg) = err(r);
        assert!(
            matches!(e, BakeError::MalformedMesh { .. }),
            "{text:?}: {msg}"
        );
        assert!(msg.contains("m.ply") && msg.contains("PLY"), "{msg}");
        assert!(msg.contains(what), "expected {what:?} in: {msg}");
    }
}

#[test]
fn truncated_binary_ply() {
    let bunny = std::fs::read(assets().join("meshes/bunny.ply")).unwrap();
    for cut in [bunny.len() / 2, bunny.len() - 1, 400] {
        let (_d, r) = build(&mesh_scene("b.ply"), &[("b.ply", &bunny[..cut])]);
        let (e, msg) = err(r);
        assert!(matches!(e, BakeError::MalformedMesh { .. }), "{msg}");
        assert!(msg.contains("truncated"), "{msg}");
    }
}

#[test]
fn binary_ply_with_polygons_and_extra_elements_loads() {
    let mut b = b"ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nelement face 1\nproperty list uchar uint vertex_indices\nproperty float quality\nelement edge 1\nproperty int a\nproperty list ushort short b\nend_header\n".to_vec();
    for v in [
        [-1.0f32, 0.0, -1.0],
        [-1.0, 0.0, 1.0],
        [1.0, 0.0, 1.0],
        [1.0, 0.0, -1.0],
    ] {
        for c in v {
            b.extend_from_slice(&c.to_le_bytes());
        }
        b.push(200);
    }
    b.push(4);
    for i in [0u32, 1, 2, 3] {
        b.extend_from_slice(&i.to_le_bytes());
    }
    b.extend_from_slice(&0.5f32.to_le_bytes());
    b.extend_from_slice(&7i32.to_le_bytes());
    b.extend_from_slice(&2u16.to_le_bytes());
    b.extend_from_slice(&(-1i16).to_le_bytes());
    b.extend_from_slice(&3i16.to_le_bytes());
    let (_d, r) = build(&mesh_scene("q.ply"), &[("q.ply", &b)]);
    let scene = r.expect("valid binary PLY");
    assert_eq!(scene.stats().meshes[0].triangles, 2);
    // A truncated copy (the edge element cut short) fails cleanly.
    let (_d, r) = build(&mesh_scene("q.ply"), &[("q.ply", &b[..b.len() - 3])]);
    let (_, msg) = err(r);
    assert!(msg.contains("truncated"), "{msg}");
}

#[test]
fn nan_vertices() {
    let obj = "v 0 0 0\nv nan 0 0\nv 0 0 1\nf 1 2 3\n";
    let (_d, r) = build(&mesh_scene("m.obj"), &[("m.obj", obj.as_bytes())]);
    let (_, msg) = err(r);
    assert!(
        msg.contains("vertex 1") && msg.contains("non-finite"),
        "{msg}"
    );

    let ply = ply_ascii("0 0 0\n1 NaN 0\n0 0 1\n3 0 1 2\n", 3, 1);
    let (_d, r) = build(&mesh_scene("m.ply"), &[("m.ply", ply.as_bytes())]);
    let (_, msg) = err(r);
    assert!(
        msg.contains("vertex 1") && msg.contains("non-finite"),
        "{msg}"
    );

    let ply = ply_ascii("0 0 0\n1 0 0\ninf 0 1\n3 0 1 2\n", 3, 1);
    let (_d, r) = build(&mesh_scene("m.ply"), &[("m.ply", ply.as_bytes())]);
    let (_, msg) = err(r);
    assert!(msg.contains("vertex 2"), "{msg}");
}

#[test]
fn degenerate_triangles_are_skipped_and_counted() {
    // One good triangle, one with a repeated vertex, one with collinear
    // vertices.
    let obj = "v -1 0 -1\nv -1 0 1\nv 1 0 0\nv 2 0 0\nv 3 0 0\nf 1 2 3\nf 1 1 2\nf 3 4 5\n";
    let (_d, r) = build(&mesh_scene("m.obj"), &[("m.obj", obj.as_bytes())]);
    let scene = r.expect("a mesh with some degenerate triangles builds");
    let m = &scene.stats().meshes[0];
    assert_eq!((m.triangles, m.degenerate_skipped), (1, 2));

    let obj = "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\nf 1 1 1\n";
    let (_d, r) = build(&mesh_scene("m.obj"), &[("m.obj", obj.as_bytes())]);
    let (_, msg) = err(r);
    assert!(msg.contains("degenerate"), "{msg}");
}

const CUBE_OBJ: &str =
    "v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\nv -1 -1 1\nv 1 -1 1\nv 1 1 1\nv -1 1 1\n\
f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 4 8 7 3\nf 1 5 8 4\nf 2 3 7 6\n";

#[test]
fn camera_inside_geometry() {
    let toml = scene_toml(
        "eye = [0.2, 0.1, 0.3]\ntarget = [0.0, 0.0, -1.0]\nfov = 60.0\nwidth = 16\nheight = 16",
        LIGHTING,
        "[[meshes]]\npath = \"cube.obj\"\nmaterial = \"grey\"\n",
    );
    let (_d, r) = build(&toml, &[("cube.obj", CUBE_OBJ.as_bytes())]);
    let (e, msg) = err(r);
    assert!(matches!(e, BakeError::CameraInsideGeometry { .. }), "{msg}");
    assert!(
        msg.contains("inside geometry") && msg.contains("100 %"),
        "{msg}"
    );

    // The same cube seen from outside is fine.
    let toml = scene_toml(
        "eye = [0.5, 1.0, 6.0]\ntarget = [0.0, 0.0, 0.0]\nfov = 30.0\nwidth = 16\nheight = 16",
        LIGHTING,
        "[[meshes]]\npath = \"cube.obj\"\nmaterial = \"grey\"\n",
    );
    let (_d, r) = build(&toml, &[("cube.obj", CUBE_OBJ.as_bytes())]);
    r.expect("camera outside the cube");
}

#[test]
fn bad_settings_name_field_value_and_range() {
    let obj: &[(&str, &[u8])] = &[("t.obj", TRIANGLE_OBJ.as_bytes())];
    let mesh = "[[meshes]]\npath = \"t.obj\"\nmaterial = \"grey\"\n";
    let cases = [
        (CAMERA.replace("width = 9", "width = 0"), LIGHTING.to_string(), mesh.to_string(), "camera.width = 0"),
        (CAMERA.replace("height = 9", "height = 0"), LIGHTING.to_string(), mesh.to_string(), "camera.height = 0"),
        (CAMERA.to_string(), LIGHTING.replace("face_res = 8", "face_res = 12"), mesh.to_string(), "lighting.face_res = 12"),
        (CAMERA.to_string(), LIGHTING.replace("face_res = 8", "face_res = 0"), mesh.to_string(), "power of two"),
        (CAMERA.to_string(), LIGHTING.replace("texel_samples = 4", "texel_samples = 0"), mesh.to_string(), "lighting.texel_samples = 0"),
        (CAMERA.replace("fov = 40.0", "fov = 180.0"), LIGHTING.to_string(), mesh.to_string(), "camera.fov = 180"),
        (CAMERA.replace("target = [0.0, 0.0, 0.0]", "target = [0.0, 3.0, 4.0]"), LIGHTING.to_string(), mesh.to_string(), "camera.target"),
        (format!("{CAMERA}\nup = [0.0, -3.0, -4.0]"), LIGHTING.to_string(), mesh.to_string(), "camera.up"),
        (CAMERA.to_string(), LIGHTING.to_string(), mesh.replace("grey", "gold"), "unknown material \"gold\" (defined: grey)"),
        (CAMERA.to_string(), LIGHTING.to_string(), format!("{mesh}scale = [1.0, 0.0, 1.0]\n"), "meshes[0].scale[1] = 0"),
        (CAMERA.to_string(), LIGHTING.to_string(), "[materials.m]\ntype = \"glossy\"\nalbedo = [0.5, 0.5, 0.5]\nspecular = [0.04, 0.04, 0.04]\nroughness = 0.0\n".to_string(), "materials.m.roughness = 0"),
        (CAMERA.to_string(), LIGHTING.to_string(), "[materials.m]\ntype = \"lambert\"\nalbedo = [1.5, 0.5, 0.5]\n".to_string(), "materials.m.albedo"),
        (CAMERA.to_string(), LIGHTING.to_string(), String::new(), "no geometry"),
        (CAMERA.to_string(), LIGHTING.to_string(), "[[quads]]\ncenter = [0.0, 0.0, 0.0]\nsize = [1.0, -1.0]\nmaterial = \"grey\"\n".to_string(), "quads[0].size[1] = -1"),
    ];
    for (camera, lighting, body, want) in cases {
        let (_d, r) = build(&scene_toml(&camera, &lighting, &body), obj);
        let (e, msg) = err(r);
        assert!(
            matches!(
                e,
                BakeError::OutOfRange { .. } | BakeError::InvalidScene { .. }
            ),
            "{msg}"
        );
        assert!(msg.contains(want), "expected {want:?} in: {msg}");
        assert!(msg.contains("scene.toml"), "{msg}");
    }
}

#[test]
fn syntax_errors_name_line_and_field() {
    let obj: &[(&str, &[u8])] = &[("t.obj", TRIANGLE_OBJ.as_bytes())];
    let cases = [
        (
            scene_toml(&format!("{CAMERA}\nfocus = 2.0"), LIGHTING, ""),
            "line 7",
            "focus",
        ),
        (
            scene_toml(CAMERA, LIGHTING, "[materials.m]\ntype = \"metal\"\n"),
            "line",
            "metal",
        ),
        (
            scene_toml(
                CAMERA,
                LIGHTING,
                "[materials.m]\ntype = \"lambert\"\nalbedo = [0.5, 0.5, 0.5]\nroughness = 0.5\n",
            ),
            "line",
            "roughness",
        ),
        (
            scene_toml(&CAMERA.replace("width = 9", "width = -9"), LIGHTING, ""),
            "line",
            "width",
        ),
        (
            scene_toml(
                CAMERA,
                LIGHTING,
                "[[meshes]]\npath = \"t.obj\"\nmaterial = \"grey\"\nscale = [1.0, 2.0]\n",
            ),
            "line",
            "3 numbers",
        ),
        ("[camera\n".to_string(), "line 1", ""),
        (scene_toml(CAMERA, "", ""), "line", "face_res"),
    ];
    for (toml, line, what) in cases {
        let (_d, r) = build(&toml, obj);
        let (e, msg) = err(r);
        assert!(matches!(e, BakeError::SceneSyntax { .. }), "{msg}");
        assert!(
            msg.contains(line) && msg.contains(what),
            "expected {line:?}, {what:?} in: {msg}"
        );
        assert!(!msg.contains('\n'), "one line: {msg}");
    }
}

#[test]
fn overrides_are_checked() {
    let mut desc = SceneDesc::default_scene(&assets()).unwrap();
    for (o, want) in [
        (
            Overrides {
                width: Some(0),
                ..Default::default()
            },
            "command line: --width = 0",
        ),
        (
            Overrides {
                face_res: Some(12),
                ..Default::default()
            },
            "--face-res = 12 is out of range (valid: a power of two",
        ),
        (
            Overrides {
                spp: Some(0),
                ..Default::default()
            },
            "--spp = 0",
        ),
        (
            Overrides {
                texel_samples: Some(0),
                ..Default::default()
            },
            "--texel-samples = 0",
        ),
    ] {
        let msg = desc.apply(&o).unwrap_err().to_string();
        assert!(msg.contains(want), "expected {want:?} in: {msg}");
    }
    desc.apply(&Overrides {
        width: Some(8),
        height: Some(4),
        face_res: Some(2),
        ..Default::default()
    })
    .unwrap();
    assert_eq!(
        (
            desc.camera.width,
            desc.camera.height,
            desc.lighting.face_res
        ),
        (8, 4, 2)
    );
}
