//! Mesh loading: the shipped assets, PLY variants, normals.

use crate::common;

use common::*;
use glam::DVec3;

fn mesh_scene(file: &str, smooth: bool) -> String {
    scene_toml(
        CAMERA,
        LIGHTING,
        &format!("[[meshes]]\npath = \"{file}\"\nmaterial = \"grey\"\nsmooth = {smooth}\n"),
    )
}

#[test]
fn shipped_meshes_load() {
    let dir = assets().join("meshes");
    for (file, tris) in [
        ("bunny.ply", 75_408),
        ("bunny_small.obj", 3_674),
        ("teapot.obj", 992),
        ("fandisk.ply", 12_946),
    ] {
        let path = dir.join(file).display().to_string();
        let far = CAMERA.replace("eye = [0.0, 3.0, 4.0]", "eye = [0.0, 60.0, 80.0]");
        let toml = mesh_scene(&path, true).replace(CAMERA, &far);
        let (_d, r) = build(&toml, &[]);
        let scene = r.unwrap_or_else(|e| panic!("{file}: {e}"));
        let m = &scene.stats().meshes[0];
        assert_eq!((m.triangles, m.degenerate_skipped), (tris, 0), "{file}");
    }
}

#[test]
fn ascii_ply_polygons_normals_and_comments() {
    // A quad (fanned into 2 triangles) whose file normals all lean towards +X.
    let ply = "ply\nformat ascii 1.0\ncomment made by hand\nobj_info nothing\nelement vertex 4\n\
property double x\nproperty double y\nproperty double z\nproperty float nx\nproperty float ny\nproperty float nz\n\
element face 1\nproperty list uchar uint vertex_indices\nend_header\n\
-1 0 -1 0.6 0.8 0\n-1 0 1 0.6 0.8 0\n1 0 1 0.6 0.8 0\n1 0 -1 0.6 0.8 0\n4 0 1 2 3\n";
    for (smooth, want) in [(true, DVec3::new(0.6, 0.8, 0.0)), (false, DVec3::Y)] {
        let (_d, r) = build(&mesh_scene("q.ply", smooth), &[("q.ply", ply.as_bytes())]);
        let scene = r.unwrap();
        assert_eq!(scene.stats().meshes[0].triangles, 2);
        let hit = scene
            .intersect(DVec3::new(0.2, 1.0, 0.3), -DVec3::Y)
            .expect("the quad is under the ray");
        assert!((hit.point - DVec3::new(0.2, 0.0, 0.3)).length() < 1e-6);
        assert!(
            (hit.ns - want).length() < 1e-5,
            "smooth {smooth}: {:?}",
            hit.ns
        );
        assert!(!hit.back);
    }
}

#[test]
fn obj_normals_and_several_objects() {
    let obj = "o a\nv -1 0 -1\nv -1 0 1\nv 1 0 1\nvn 0 1 0\nf 1//1 2//1 3//1\n\
o b\nv 5 0 -1\nv 5 0 1\nv 7 0 1\nvn 0.6 0.8 0\nf 4//2 5//2 6//2\n";
    let (_d, r) = build(&mesh_scene("m.obj", true), &[("m.obj", obj.as_bytes())]);
    let scene = r.unwrap();
    assert_eq!(scene.stats().meshes[0].triangles, 2);
    let hit = scene
        .intersect(DVec3::new(5.5, 1.0, 0.5), -DVec3::Y)
        .unwrap();
    assert!(
        (hit.ns - DVec3::new(0.6, 0.8, 0.0)).length() < 1e-5,
        "{:?}",
        hit.ns
    );
}

#[test]
fn smooth_normals_weld_coincident_vertices() {
    // A ridge along Z made of two triangles that do not share vertex
    // indices, only positions (like the teapot's seams).
    let obj = "v -1 0 -1\nv 0 1 1\nv 0 1 -1\nv 0 1 -1\nv 0 1 1\nv 1 0 -1\nf 1 2 3\nf 4 5 6\n";
    let (_d, r) = build(&mesh_scene("r.obj", true), &[("r.obj", obj.as_bytes())]);
    let scene = r.unwrap();
    // Just left of the ridge line x = 0 on the left face.
    let hit = scene
        .intersect(DVec3::new(-0.001, 5.0, -0.5), -DVec3::Y)
        .expect("ridge below");
    let left = DVec3::new(-1.0, 1.0, 0.0).normalize();
    // Welded: the ridge vertices carry the average normal, +Y.
    assert!(hit.ns.dot(DVec3::Y) > 0.999, "{:?}", hit.ns);
    let (_d, r) = build(&mesh_scene("r.obj", false), &[("r.obj", obj.as_bytes())]);
    let hit = r
        .unwrap()
        .intersect(DVec3::new(-0.001, 5.0, -0.5), -DVec3::Y)
        .unwrap();
    assert!((hit.ns - left).length() < 1e-6, "flat: {:?}", hit.ns);
}

#[test]
fn mirroring_scale_keeps_the_front_side() {
    // Counter-clockwise seen from +Y; mirrored in X it must still face +Y.
    let (_d, r) = build(
        &mesh_scene("t.obj", false)
            .replace("smooth = false", "smooth = false\nscale = [-1.0, 1.0, 1.0]"),
        &[("t.obj", TRIANGLE_OBJ.as_bytes())],
    );
    let hit = r
        .unwrap()
        .intersect(DVec3::new(0.0, 1.0, 0.0), -DVec3::Y)
        .unwrap();
    assert!(!hit.back, "front side up after mirroring");
}
