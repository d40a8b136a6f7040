//! Hostile input, one section per class of the reliability review: stale
//! partial files, rays leaking through shared edges, the camera-inside check
//! on open and closed geometry, degenerate geometry, and camera messages.

use crate::common;

use common::*;
use glam::{DMat3, DVec3};
use ltm_bake::{bake, raw_header, BakeError, BakeOptions, BlockBaker, Overrides, Scene, SceneDesc};
use ltm_codec::raw::{RestartReason, ResumeState};
use ltm_codec::{Progress, RawHeader, RawWriter, Stage, Step};
use std::path::Path;

// ---------------------------------------------------------------------------
// Meshes built in the tests.

/// Vertices (exact `f32`) and counter-clockwise triangles.
#[derive(Clone)]
struct Mesh {
    v: Vec<[f32; 3]>,
    t: Vec<[u32; 3]>,
}

impl Mesh {
    fn pos(&self, i: u32) -> DVec3 {
        DVec3::from(self.v[i as usize].map(f64::from))
    }

    /// Orients every triangle of a mesh that is convex around `c` so that
    /// its front (counter-clockwise) side faces away from `c`, or towards it
    /// when `inward`.
    fn orient(mut self, c: DVec3, inward: bool) -> Mesh {
        for i in 0..self.t.len() {
            let [a, b, d] = self.t[i].map(|k| self.pos(k));
            let out = (b - a).cross(d - a).dot((a + b + d) / 3.0 - c) > 0.0;
            if out == inward {
                self.t[i].swap(1, 2);
            }
        }
        self
    }

    /// `rot·p + shift` for every vertex, rounded to `f32` once.
    fn moved(&self, rot: DMat3, shift: DVec3) -> Mesh {
        let v = self
            .v
            .iter()
            .map(|p| {
                (rot * DVec3::from(p.map(f64::from)) + shift)
                    .as_vec3()
                    .to_array()
            })
            .collect();
        Mesh {
            v,
            t: self.t.clone(),
        }
    }

    /// OBJ text; `f32` Display is the shortest string that reads back
    /// exactly, so the baker sees exactly these vertices.
    fn obj(&self) -> String {
        let mut s = String::new();
        for p in &self.v {
            s += &format!("v {} {} {}\n", p[0], p[1], p[2]);
        }
        for t in &self.t {
            s += &format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1);
        }
        s
    }

    /// Every edge once, as vertex index pairs.
    fn edges(&self) -> Vec<(u32, u32)> {
        let mut e: Vec<(u32, u32)> = self
            .t
            .iter()
            .flat_map(|t| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])])
            .map(|(a, b)| (a.min(b), a.max(b)))
            .collect();
        e.sort_unstable();
        e.dedup();
        e
    }
}

/// The cube `[-1, 1]³`, each face split along a diagonal.
fn cube() -> Mesh {
    let v: Vec<[f32; 3]> = (0..8)
        .map(|i| [0, 1, 2].map(|k| if i >> k & 1 == 1 { 1.0 } else { -1.0 }))
        .collect();
    let mut t = Vec::new();
    for axis in 0..3 {
        for side in 0..2u32 {
            let (a, b) = ((axis + 1) % 3, (axis + 2) % 3);
            let corner = |u: u32, w: u32| side << axis | u << a | w << b;
            let q = [corner(0, 0), corner(1, 0), corner(1, 1), corner(0, 1)];
            t.push([q[0], q[1], q[2]]);
            t.push([q[0], q[2], q[3]]);
        }
    }
    Mesh { v, t }.orient(DVec3::ZERO, false)
}

/// The unit icosphere: an icosahedron subdivided `levels` times, midpoints
/// shared between neighbouring triangles.
fn icosphere(levels: u32) -> Mesh {
    let phi = (1.0 + 5f64.sqrt()) / 2.0;
    let mut pts: Vec<DVec3> = Vec::new();
    for (a, b) in [(1.0, phi), (-1.0, phi), (1.0, -phi), (-1.0, -phi)] {
        pts.extend([
            DVec3::new(0.0, a, b),
            DVec3::new(a, b, 0.0),
            DVec3::new(b, 0.0, a),
        ]);
    }
    let mut tris: Vec<[u32; 3]> = Vec::new();
    let n = pts.len() as u32;
    let edge = |i: u32, j: u32| (pts[i as usize] - pts[j as usize]).length() < 2.01;
    for i in 0..n {
        for j in i + 1..n {
            for k in j + 1..n {
                if edge(i, j) && edge(j, k) && edge(i, k) {
                    tris.push([i, j, k]);
                }
            }
        }
    }
    for _ in 0..levels {
        let mut mid = std::collections::HashMap::new();
        let mut next = Vec::new();
        for t in &tris {
            let mut m = [0u32; 3];
            for e in 0..3 {
                let (a, b) = (t[e].min(t[(e + 1) % 3]), t[e].max(t[(e + 1) % 3]));
                m[e] = *mid.entry((a, b)).or_insert_with(|| {
                    pts.push((pts[a as usize] + pts[b as usize]) / 2.0);
                    pts.len() as u32 - 1
                });
            }
            next.extend([
                [t[0], m[0], m[2]],
                [t[1], m[1], m[0]],
                [t[2], m[2], m[1]],
                [m[0], m[1], m[2]],
            ]);
        }
        tris = next;
    }
    let v = pts
        .iter()
        .map(|p| p.normalize().as_vec3().to_array())
        .collect();
    Mesh { v, t: tris }.orient(DVec3::ZERO, false)
}

/// Spherical Fibonacci directions.
fn sphere_dirs(n: usize) -> Vec<DVec3> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - (2 * i + 1) as f64 / n as f64;
            let r = (1.0 - z * z).sqrt();
            let a = golden * i as f64;
            DVec3::new(r * a.cos(), r * a.sin(), z)
        })
        .collect()
}

/// `Rz·Ry·Rx`, the scene file's Euler convention.
fn euler(deg: [f64; 3]) -> DMat3 {
    DMat3::from_rotation_z(deg[2].to_radians())
        * DMat3::from_rotation_y(deg[1].to_radians())
        * DMat3::from_rotation_x(deg[0].to_radians())
}

const ORIENTATIONS: [[f64; 3]; 4] = [
    [0.0, 0.0, 0.0],
    [17.3, 41.9, -63.1],
    [90.0, 45.0, 0.0],
    [-33.0, 0.0, 45.0],
];

fn mesh_toml(camera: &str, extra: &str) -> String {
    scene_toml(
        camera,
        LIGHTING,
        &format!("[[meshes]]\npath = \"m.obj\"\nmaterial = \"grey\"\nsmooth = false\n{extra}"),
    )
}

const FAR_CAMERA: &str =
    "eye = [0.3, 0.2, 40.0]\ntarget = [0.0, 0.0, 0.0]\nfov = 10.0\nwidth = 4\nheight = 4";

// ---------------------------------------------------------------------------
// Class 2: watertight intersection.

/// Points on a closed mesh that rays are aimed at: every vertex, points on
/// every edge (its midpoint and two others), every triangle's centroid.
fn targets(m: &Mesh) -> Vec<DVec3> {
    let mut out: Vec<DVec3> = (0..m.v.len() as u32).map(|i| m.pos(i)).collect();
    for (a, b) in m.edges() {
        let (a, b) = (m.pos(a), m.pos(b));
        for s in [0.5, 0.25, 1.0 / 3.0] {
            out.push(a + (b - a) * s);
        }
    }
    for t in &m.t {
        out.push(t.iter().map(|&i| m.pos(i)).sum::<DVec3>() / 3.0);
    }
    out
}

/// Traces rays through the closed, convex `m` (centred at `c`, in world
/// space as the scene holds it) and returns the ones that escape: from
/// points inside towards every target and many other directions (closest
/// hit and shadow query), and from outside straight at every target.
fn escapes(scene: &Scene, m: &Mesh, c: DVec3) -> Vec<String> {
    let mut bad = Vec::new();
    let r = (m.pos(0) - c).length();
    let insides = [
        c,
        c + DVec3::new(0.11, -0.07, 0.05) * r,
        c + DVec3::new(-0.3, 0.2, 0.1) * r,
    ];
    let goals = targets(m);
    for &o in &insides {
        let dirs = goals
            .iter()
            .map(|&t| (t - o).normalize())
            .chain(sphere_dirs(400));
        for d in dirs {
            if scene.intersect(o, d).is_none() {
                bad.push(format!("closest hit from {o} along {d}"));
            }
            if !scene.occluded(o, d) {
                bad.push(format!("shadow ray from {o} along {d}"));
            }
        }
    }
    // From just inside the surface, near edges and corners (where shadow
    // rays of a closed room start), towards the rest of the surface.
    for &near in goals.iter().step_by(5) {
        let o = c + (near - c) * (1.0 - 1e-4);
        for d in goals
            .iter()
            .step_by(3)
            .map(|&t| (t - o).normalize())
            .chain(sphere_dirs(64))
        {
            if !d.is_finite() {
                continue;
            }
            if !scene.occluded(o, d) || scene.intersect(o, d).is_none() {
                bad.push(format!("from near the surface at {o} along {d}"));
            }
        }
    }
    for &t in &goals {
        let n = (t - c).normalize();
        let o = t + 3.0 * r * n;
        if scene.intersect(o, -n).is_none() || !scene.occluded(o, -n) {
            bad.push(format!("from outside at {t}"));
        }
    }
    // The bake traces its rays as packets: the same answers, ray by ray.
    for o in insides.into_iter().chain(goals.iter().step_by(7).copied()) {
        let dirs: Vec<DVec3> = goals
            .iter()
            .map(|&t| (t - o).normalize())
            .filter(|d| d.is_finite())
            .chain(sphere_dirs(200))
            .collect();
        bad.extend(packet_disagreements(scene, o, &dirs));
    }
    bad
}

/// The rays from `o` along `dirs` whose packet answer
/// (`Scene::occluded_packet`, in packets of 1, 7 and all of them) differs
/// from the single ray's.
fn packet_disagreements(scene: &Scene, o: DVec3, dirs: &[DVec3]) -> Vec<String> {
    let single: Vec<bool> = dirs.iter().map(|&d| scene.occluded(o, d)).collect();
    let mut bad = Vec::new();
    for size in [1, 7, dirs.len().max(1)] {
        for (k, chunk) in dirs.chunks(size).enumerate() {
            let mut out = vec![!single[k * size]; chunk.len()];
            scene.occluded_packet(o, chunk, &mut out);
            for (i, (&got, &want)) in out.iter().zip(&single[k * size..]).enumerate() {
                if got != want {
                    bad.push(format!(
                        "packet of {size} from {o} along {}: {got}, one ray {want}",
                        chunk[i]
                    ));
                }
            }
        }
    }
    bad
}

fn closed_meshes() -> Vec<(&'static str, Mesh)> {
    vec![("cube", cube()), ("icosphere", icosphere(2))]
}

#[test]
fn rays_never_escape_closed_meshes() {
    let shift = DVec3::new(0.37, -1.3, 2.9);
    for (name, base) in closed_meshes() {
        for inward in [false, true] {
            let base = base.clone().orient(DVec3::ZERO, inward);
            for deg in ORIENTATIONS {
                // The vertices are placed in the file, so the rays aim at
                // exactly the positions the baker traces.
                let m = base.moved(euler(deg), shift);
                let (_d, r) = build(&mesh_toml(FAR_CAMERA, ""), &[("m.obj", m.obj().as_bytes())]);
                let scene = r.expect("closed mesh scene");
                let bad = escapes(&scene, &m, shift);
                assert!(
                    bad.is_empty(),
                    "{name} (inward {inward}, rotation {deg:?}): {} rays escape, e.g. {:?}",
                    bad.len(),
                    &bad[..bad.len().min(4)]
                );
            }
        }
    }
}

#[test]
fn rays_never_escape_meshes_moved_by_the_scene() {
    // The same through the scene's own transform (rotation, scale and
    // translation applied by the baker in double precision).
    for (name, base) in closed_meshes() {
        for deg in ORIENTATIONS {
            let extra = format!(
                "rotation = [{}, {}, {}]\nscale = 2.5\ntranslation = [-0.7, 0.3, 1.1]\n",
                deg[0], deg[1], deg[2]
            );
            let (_d, r) = build(
                &mesh_toml(FAR_CAMERA, &extra),
                &[("m.obj", base.obj().as_bytes())],
            );
            let scene = r.expect("closed mesh scene");
            let shift = DVec3::new(-0.7, 0.3, 1.1);
            let m = base.moved(euler(deg) * 2.5, shift);
            let bad = escapes(&scene, &m, shift);
            assert!(
                bad.is_empty(),
                "{name} rotated {deg:?}: {} rays escape, e.g. {:?}",
                bad.len(),
                &bad[..bad.len().min(4)]
            );
        }
    }
}

#[test]
fn quad_seen_from_behind_has_no_crack() {
    // Rays from under a quad, across its shared diagonal, all hit its back
    // side (a dense grid, some exactly on the diagonal).
    let toml = scene_toml(
        CAMERA,
        LIGHTING,
        "[[quads]]\ncenter = [0.0, 0.0, 0.0]\nsize = [4.0, 4.0]\nrotation = [0.0, 30.0, 0.0]\nmaterial = \"grey\"\n",
    );
    let (_d, r) = build(&toml, &[]);
    let scene = r.expect("quad scene");
    let eye = DVec3::new(0.0, -2.0, 0.0);
    let mut missed = Vec::new();
    for i in 0..=200 {
        for j in 0..=20 {
            let s = i as f64 / 100.0 - 1.0;
            let (a, b) = (
                euler([0.0, 30.0, 0.0]) * DVec3::new(s, 0.0, s),
                DVec3::new(0.0, 0.0, j as f64 * 1e-9),
            );
            let d = (a + b - eye).normalize();
            match scene.intersect(eye, d) {
                Some(h) => assert!(h.back),
                None => missed.push(d),
            }
        }
    }
    assert!(
        missed.is_empty(),
        "{} rays missed, e.g. {:?}",
        missed.len(),
        &missed[..missed.len().min(3)]
    );
}

/// A camera at the centre of a closed, outward-facing cube, whatever it
/// looks at (a face centre on the diagonal, an edge, a corner) and however
/// small its image, is inside geometry.
#[test]
fn camera_inside_a_closed_cube_is_detected() {
    for deg in ORIENTATIONS {
        let m = cube().moved(euler(deg), DVec3::new(0.2, 0.1, -0.3));
        let c = DVec3::new(0.2, 0.1, -0.3);
        let looks = [
            (m.pos(0) + m.pos(3)) / 2.0, // a face centre: on a diagonal
            (m.pos(0) + m.pos(1)) / 2.0, // an edge midpoint
            m.pos(7),                    // a corner
        ];
        for target in looks {
            for size in [1, 2, 3] {
                let camera = format!(
                    "eye = [{}, {}, {}]\ntarget = [{}, {}, {}]\nfov = 20.0\nwidth = {size}\nheight = {size}",
                    c.x, c.y, c.z, target.x, target.y, target.z
                );
                let (_d, r) = build(&mesh_toml(&camera, ""), &[("m.obj", m.obj().as_bytes())]);
                let (e, msg) = err(r);
                assert!(
                    matches!(e, BakeError::CameraInsideGeometry { .. }),
                    "rotation {deg:?}, looking at {target}, {size}×{size}: {msg}"
                );
            }
        }
    }
}

/// The same cube in a tiny and in a huge scene.
#[test]
fn camera_inside_is_detected_at_any_scale() {
    for scale in [1e-29, 1e-4, 1e-2, 1e3, 1e6] {
        let m = cube().moved(euler([10.0, 20.0, 30.0]) * scale, DVec3::ZERO);
        let camera = format!(
            "eye = [{}, 0.0, 0.0]\ntarget = [0.0, 0.0, {}]\nfov = 40.0\nwidth = 4\nheight = 4",
            0.1 * scale,
            -scale
        );
        let (_d, r) = build(&mesh_toml(&camera, ""), &[("m.obj", m.obj().as_bytes())]);
        let (e, msg) = err(r);
        assert!(
            matches!(e, BakeError::CameraInsideGeometry { .. }),
            "scale {scale}: {msg}"
        );
    }
    // Below single precision's range: a clear error, not a wrong bake.
    let m = cube().moved(DMat3::IDENTITY * 1e-40, DVec3::ZERO);
    let camera =
        "eye = [1e-41, 0.0, 0.0]\ntarget = [0.0, 0.0, -1e-40]\nfov = 40.0\nwidth = 4\nheight = 4";
    let (_d, r) = build(&mesh_toml(camera, ""), &[("m.obj", m.obj().as_bytes())]);
    let (e, msg) = err(r);
    assert!(matches!(e, BakeError::Geometry(_)), "{msg}");
    assert!(
        msg.contains("out of range") && msg.contains("1e-30"),
        "{msg}"
    );
}

// ---------------------------------------------------------------------------
// Class 3: the camera-inside check and open surfaces.

/// The cube without the faces whose outward normal is along `open`.
fn open_box(open: &[DVec3]) -> Mesh {
    let mut m = cube();
    let keep: Vec<[u32; 3]> =
        m.t.iter()
            .copied()
            .filter(|t| {
                let [a, b, c] = t.map(|i| m.pos(i));
                let n = (b - a).cross(c - a).normalize();
                !open.iter().any(|o| n.dot(*o) > 0.99)
            })
            .collect();
    m.t = keep;
    m
}

#[test]
fn open_surfaces_seen_from_behind_are_not_inside() {
    // Under an open plane, looking up at its back side.
    let toml = scene_toml(
        "eye = [0.0, -1.0, 0.0]\ntarget = [0.3, 0.0, 0.2]\nup = [0.0, 0.0, 1.0]\nfov = 60.0\nwidth = 8\nheight = 8",
        LIGHTING,
        "[[quads]]\ncenter = [0.0, 0.0, 0.0]\nsize = [50.0, 50.0]\nmaterial = \"grey\"\n",
    );
    let (_d, r) = build(&toml, &[]);
    r.expect("a camera under an open plane is not inside geometry");

    // Inside an outward-facing box missing one face, looking at the back
    // faces of the others (the opening behind, beside or in front).
    for open in [DVec3::Z, DVec3::X, -DVec3::Z, DVec3::Y] {
        let m = open_box(&[open]);
        let camera =
            "eye = [0.1, -0.2, 0.5]\ntarget = [0.0, 0.0, -1.0]\nfov = 90.0\nwidth = 8\nheight = 8";
        let (_d, r) = build(&mesh_toml(camera, ""), &[("m.obj", m.obj().as_bytes())]);
        r.unwrap_or_else(|e| panic!("box open towards {open}: {e}"));
    }

    // A closed box is inside, from anywhere within it, whatever it looks at.
    let m = cube();
    for eye in ["[0.1, -0.2, 0.5]", "[0.9, 0.9, 0.9]", "[-0.5, 0.0, 0.0]"] {
        let camera =
            format!("eye = {eye}\ntarget = [0.0, 0.0, -1.0]\nfov = 90.0\nwidth = 8\nheight = 8");
        let (_d, r) = build(&mesh_toml(&camera, ""), &[("m.obj", m.obj().as_bytes())]);
        let (e, msg) = err(r);
        assert!(
            matches!(e, BakeError::CameraInsideGeometry { .. }),
            "{eye}: {msg}"
        );
    }
}

#[test]
fn a_closed_room_facing_the_camera_is_not_inside() {
    // Walls wound towards the room (an interior scene) are seen from the
    // front: documented as valid.
    let m = cube().orient(DVec3::ZERO, true);
    let camera =
        "eye = [0.1, -0.2, 0.5]\ntarget = [0.0, 0.0, -1.0]\nfov = 90.0\nwidth = 8\nheight = 8";
    let (_d, r) = build(&mesh_toml(camera, ""), &[("m.obj", m.obj().as_bytes())]);
    r.expect("a room seen from inside");
}

// ---------------------------------------------------------------------------
// Class 4: degenerate geometry.

/// Degenerate distributions of triangles over a ground quad: the scene
/// builds and bakes, and the lit ground reflects its albedo.
#[test]
fn degenerate_geometry_bakes() {
    let tri = |a: [f64; 3], b: [f64; 3], c: [f64; 3]| [a, b, c];
    type Gen = Box<dyn Fn(usize) -> [[f64; 3]; 3]>;
    let cases: Vec<(&str, usize, Gen)> = vec![
        (
            "coincident",
            600,
            Box::new(move |_| tri([-1.0, 0.5, -1.0], [-1.0, 0.5, 1.0], [1.0, 0.5, 0.0])),
        ),
        (
            "coincident",
            3000,
            Box::new(move |_| tri([-1.0, 0.5, -1.0], [-1.0, 0.5, 1.0], [1.0, 0.5, 0.0])),
        ),
        (
            "jittered",
            600,
            Box::new(move |i| {
                let j = (i as f64 * 0.618).fract() * 1e-6;
                tri([-1.0 + j, 0.5, -1.0], [-1.0, 0.5, 1.0], [1.0, 0.5, j])
            }),
        ),
        (
            "nested",
            600,
            Box::new(move |i| {
                let s = 1.0 + i as f64 * 1e-3;
                tri([-s, 0.5, -s], [-s, 0.5, s], [s, 0.5, 0.0])
            }),
        ),
        (
            "exponential",
            200,
            Box::new(move |i| {
                let x = 2f64.powi(-(i as i32) / 4) * 3.0;
                tri([x, 0.5, 0.0], [x, 0.5, 0.01], [x + 0.01, 0.5, 0.0])
            }),
        ),
    ];
    let bake_rows = |obj: &str| -> (Vec<f32>, usize) {
        let toml = scene_toml(
            "eye = [0.0, 3.0, 4.0]\ntarget = [0.0, 0.0, 0.0]\nfov = 40.0\nwidth = 6\nheight = 6",
            "face_res = 4\ntexel_samples = 2",
            "[[meshes]]\npath = \"m.obj\"\nmaterial = \"grey\"\n\
             [[quads]]\ncenter = [0.0, -0.2, 0.0]\nsize = [40.0, 40.0]\nmaterial = \"grey\"\n",
        );
        let (dir, r) = build(&toml, &[("m.obj", obj.as_bytes())]);
        let scene = r.unwrap_or_else(|e| panic!("{e}"));
        let out = dir.path().join("d.raw");
        bake(
            &scene,
            &out,
            &BakeOptions::default(),
            ltm_codec::Progress::NONE,
        )
        .unwrap();
        let store = ltm_codec::RawStore::open(&out).unwrap();
        let mut rows = Vec::new();
        store
            .read_rows(0..store.dims().pixels(), &mut rows)
            .unwrap();
        (rows, scene.stats().meshes[0].triangles)
    };
    let obj_of = |n: usize, f: &Gen| {
        let mut obj = String::new();
        for i in 0..n {
            for p in f(i) {
                obj += &format!("v {} {} {}\n", p[0], p[1], p[2]);
            }
            obj += &format!("f {} {} {}\n", 3 * i + 1, 3 * i + 2, 3 * i + 3);
        }
        obj
    };
    let (single, _) = bake_rows(&obj_of(1, &cases[0].2));
    for (name, n, f) in &cases {
        let (rows, kept) = bake_rows(&obj_of(*n, f));
        assert_eq!(kept, *n, "{name}");
        let row_len = rows.len() / 36;
        for (p, row) in rows.chunks(row_len).enumerate() {
            let sum: f64 = row.iter().map(|&v| v as f64).sum();
            assert!(row.iter().all(|v| v.is_finite() && *v >= 0.0), "{name}");
            assert!(sum <= 1.05, "{name}: pixel {p} row sum {sum}");
        }
        // The bottom-left pixel sees the lit ground.
        let sum: f64 = rows[30 * row_len..31 * row_len]
            .iter()
            .map(|&v| v as f64)
            .sum();
        assert!(sum > 0.3, "{name}: row sum {sum}");
        if *name == "coincident" {
            assert!(rows == single, "{name} × {n}: differs from one copy");
        }
    }
}

/// Packets of rays answer as the rays one at a time in degenerate and
/// thin geometry: a comb of slivers a thousandth wide, coincident and
/// nested triangles, from origins inside, on and outside the scene's box,
/// along directions with zero and negative-zero components and nearly
/// parallel ones.
#[test]
fn packets_answer_as_single_rays() {
    let mut obj = String::new();
    let face = |obj: &mut String, p: [[f64; 3]; 3]| {
        for v in p {
            *obj += &format!("v {} {} {}\n", v[0], v[1], v[2]);
        }
        let k = obj.lines().filter(|l| l.starts_with('v')).count();
        *obj += &format!("f {} {} {}\n", k - 2, k - 1, k);
    };
    for i in 0..40 {
        let x = -1.0 + i as f64 * 0.05;
        face(
            &mut obj,
            [[x, 0.0, -1.0], [x + 1e-3, 0.0, -1.0], [x, 1.5, 1.0]],
        );
    }
    for i in 0..50 {
        let s = 0.3 + (i % 5) as f64 * 1e-3;
        face(&mut obj, [[-s, 0.8, -s], [-s, 0.8, s], [s, 0.8, 0.0]]);
    }
    let toml = scene_toml(
        FAR_CAMERA,
        LIGHTING,
        "[[meshes]]\npath = \"m.obj\"\nmaterial = \"grey\"\n\
         [[quads]]\ncenter = [0.0, -0.2, 0.0]\nsize = [4.0, 4.0]\nmaterial = \"grey\"\n",
    );
    let (_d, r) = build(&toml, &[("m.obj", obj.as_bytes())]);
    let scene = r.expect("comb scene");
    let mut dirs = sphere_dirs(500);
    for axis in [DVec3::X, DVec3::Y, DVec3::Z] {
        for s in [1.0, -1.0] {
            dirs.push(axis * s);
            // Negative zeros in the other components.
            dirs.push(axis * s + DVec3::splat(-0.0));
        }
    }
    let up = DVec3::new(0.01, 1.0, 0.02).normalize();
    dirs.extend(
        (0..64).map(|i| (up + DVec3::new(i as f64 * 1e-4, 0.0, -(i as f64) * 1e-4)).normalize()),
    );
    let origins = [
        DVec3::new(0.0, -0.19, 0.0),
        DVec3::new(0.01, 0.5, 0.0),
        DVec3::new(0.0, 0.8, 0.0),
        DVec3::new(-0.95, 0.0, -1.0),
        DVec3::new(3.0, 2.0, 5.0),
        DVec3::new(0.0, 40.0, 0.0),
    ];
    let mut bad = Vec::new();
    let mut occluded = 0;
    for o in origins {
        occluded += dirs.iter().filter(|&&d| scene.occluded(o, d)).count();
        bad.extend(packet_disagreements(&scene, o, &dirs));
    }
    assert!(
        bad.is_empty(),
        "{} disagree, e.g. {:?}",
        bad.len(),
        &bad[..bad.len().min(4)]
    );
    let total = origins.len() * dirs.len();
    assert!(
        occluded > total / 10 && occluded < total * 9 / 10,
        "{occluded} of {total}"
    );
}

// ---------------------------------------------------------------------------
// Class 5: camera messages.

#[test]
fn camera_messages_name_the_real_problem() {
    let obj: &[(&str, &[u8])] = &[("t.obj", TRIANGLE_OBJ.as_bytes())];
    let mesh = "[[meshes]]\npath = \"t.obj\"\nmaterial = \"grey\"\n";
    let cam = |eye: &str, target: &str, up: &str| {
        format!("eye = {eye}\ntarget = {target}\nup = {up}\nfov = 40.0\nwidth = 9\nheight = 9")
    };
    let y = "[0.0, 1.0, 0.0]";
    let cases = [
        // (camera, expected fragments, forbidden fragment)
        (
            cam("[1e30, 0.0, 0.0]", "[0.0, 0.0, 0.0]", y),
            vec!["camera.eye", "1e30", "at most 1e9"],
            "parallel",
        ),
        (
            cam("[1e200, 1e200, 0.0]", "[0.0, 0.0, 0.0]", y),
            vec!["camera.eye", "1e200", "at most 1e9"],
            "parallel",
        ),
        (
            cam("[0.0, 3.0, 4.0]", "[0.0, 0.0, -2e12]", y),
            vec!["camera.target", "-2000000000000.0", "at most 1e9"],
            "parallel",
        ),
        (
            cam("[0.0, 1e30, 0.0]", "[0.0, 0.0, 0.0]", y),
            vec!["camera.eye", "1e30"],
            "parallel",
        ),
        (
            cam("[1.0, 2.0, 3.0]", "[1.0, 2.0, 3.0]", y),
            vec!["camera.target", "equals camera.eye", "[1.0, 2.0, 3.0]"],
            "parallel",
        ),
        (
            cam("[1.0, 2.0, 3.0]", "[1.0, 2.0, 3.0000000000000004]", y),
            vec!["camera.target", "camera.eye", "distance"],
            "parallel",
        ),
        (
            cam("[0.0, 3.0, 4.0]", "[0.0, 0.0, 0.0]", "[0.0, -3.0, -4.0]"),
            vec![
                "camera.up",
                "[0.0, -3.0, -4.0]",
                "parallel to the viewing direction",
            ],
            "equals",
        ),
        (
            cam("[0.0, 3.0, 4.0]", "[0.0, 0.0, 0.0]", "[0.0, 0.0, 0.0]"),
            vec!["camera.up", "zero"],
            "parallel",
        ),
    ];
    for (camera, want, not) in cases {
        let (_d, r) = build(&scene_toml(&camera, LIGHTING, mesh), obj);
        let (e, msg) = err(r);
        assert!(
            matches!(
                e,
                BakeError::OutOfRange { .. } | BakeError::InvalidScene { .. }
            ),
            "{msg}"
        );
        for w in want {
            assert!(msg.contains(w), "expected {w:?} in: {msg}");
        }
        assert!(!msg.contains(not), "unexpected {not:?} in: {msg}");
    }
    // Extreme but meaningful values still build.
    for (eye, up) in [
        ("[0.0, 3.0, 4.0]", "[0.0, 1e-200, 0.0]"),
        ("[0.0, 3.0, 4.0]", "[0.0, 1e300, 1e300]"),
        ("[0.0, 3e8, 4e8]", y),
    ] {
        let (_d, r) = build(
            &scene_toml(&cam(eye, "[0.0, 0.0, 0.0]", up), LIGHTING, mesh),
            obj,
        );
        r.unwrap_or_else(|e| panic!("eye {eye}, up {up}: {e}"));
    }
}

// ---------------------------------------------------------------------------
// Class 1: resuming only from the same inputs.

const RESUME_OBJ: &str = "v -1 0.2 -1\nv -1 0.2 1\nv 1 0.8 0\nf 1 2 3\n";

/// A scene directory: scene.toml (a glossy triangle over a Lambertian
/// ground) and its mesh.
fn resume_dir() -> tempfile::TempDir {
    let toml = "[camera]\neye = [0.0, 3.0, 4.0]\ntarget = [0.0, 0.0, 0.0]\nfov = 40.0\nwidth = 12\nheight = 10\n\n\
[lighting]\nface_res = 4\ntexel_samples = 2\n\n\
[materials.ground]\ntype = \"lambert\"\nalbedo = [0.5, 0.5, 0.5]\n\n\
[materials.shiny]\ntype = \"glossy\"\nalbedo = [0.3, 0.2, 0.1]\nspecular = [0.04, 0.04, 0.04]\nroughness = 0.3\n\n\
[[meshes]]\npath = \"m.obj\"\nmaterial = \"shiny\"\n\n\
[[quads]]\ncenter = [0.0, 0.0, 0.0]\nsize = [6.0, 6.0]\nmaterial = \"ground\"\n";
    dir_with(&[
        ("scene.toml", toml.as_bytes()),
        ("m.obj", RESUME_OBJ.as_bytes()),
    ])
}

fn load(dir: &Path, o: &Overrides) -> Scene {
    let mut desc = SceneDesc::load(&dir.join("scene.toml")).unwrap();
    desc.apply(o).unwrap();
    Scene::build(&desc).unwrap()
}

const BLOCK: BakeOptions = BakeOptions {
    block_bytes: 4 << 10,
};

/// Leaves `out.partial` as an interrupted bake of `scene` would: three
/// blocks of the lower, lit half of the image complete.
fn interrupt(scene: &Scene, out: &Path) {
    let header = raw_header(scene, BLOCK.block_bytes);
    assert!(header.block_count() >= 5);
    let surface = ltm_bake::row_surface(scene).unwrap();
    let mut w = RawWriter::create_with_surface(out, header, Some(&surface)).unwrap();
    let baker = BlockBaker::new(scene, header).unwrap();
    let (mut rows, mut albedo) = (Vec::new(), Vec::new());
    let n = header.block_count();
    for b in [n / 2, n / 2 + 2, n - 1] {
        baker.compute(b, &mut rows, &mut albedo, &|_| {});
        w.write_block(b, &rows, (scene.channels() == 1).then_some(&albedo[..]))
            .unwrap();
    }
}

fn edit(dir: &Path, file: &str, from: &str, to: &str) {
    let path = dir.join(file);
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.contains(from), "{from}");
    std::fs::write(&path, text.replacen(from, to, 1)).unwrap();
}

/// Interrupts a bake, changes one input, bakes again to the same output:
/// the result is the fresh bake of the new inputs, never a splice, and the
/// report says why the partial file was not used.
#[test]
fn stale_partial_is_never_resumed() {
    type Change = Box<dyn Fn(&Path) -> Overrides>;
    let none = Overrides::default();
    let changes: Vec<(&str, Change)> = vec![
        (
            "camera eye",
            Box::new(move |d| {
                edit(
                    d,
                    "scene.toml",
                    "eye = [0.0, 3.0, 4.0]",
                    "eye = [0.1, 3.0, 4.0]",
                );
                none
            }),
        ),
        (
            "camera up",
            Box::new(move |d| {
                edit(
                    d,
                    "scene.toml",
                    "fov = 40.0",
                    "up = [0.1, 1.0, 0.0]\nfov = 40.0",
                );
                none
            }),
        ),
        (
            "--texel-samples",
            Box::new(|_| Overrides {
                texel_samples: Some(3),
                ..Default::default()
            }),
        ),
        (
            "--spp",
            Box::new(|_| Overrides {
                spp: Some(2),
                ..Default::default()
            }),
        ),
        (
            "mesh bytes",
            Box::new(move |d| {
                edit(d, "m.obj", "v 1 0.8 0", "v 1 0.9 0");
                none
            }),
        ),
        (
            "mesh bytes, same length",
            Box::new(move |d| {
                edit(d, "m.obj", "v 1 0.8 0", "v 1 0.7 0");
                none
            }),
        ),
        (
            "glossy albedo",
            Box::new(move |d| {
                edit(
                    d,
                    "scene.toml",
                    "albedo = [0.3, 0.2, 0.1]",
                    "albedo = [0.3, 0.2, 0.2]",
                );
                none
            }),
        ),
        (
            "roughness",
            Box::new(move |d| {
                edit(d, "scene.toml", "roughness = 0.3", "roughness = 0.31");
                none
            }),
        ),
        (
            "ground albedo",
            Box::new(move |d| {
                edit(
                    d,
                    "scene.toml",
                    "albedo = [0.5, 0.5, 0.5]",
                    "albedo = [0.5, 0.5, 0.6]",
                );
                none
            }),
        ),
        (
            "mesh transform",
            Box::new(move |d| {
                edit(
                    d,
                    "scene.toml",
                    "material = \"shiny\"",
                    "material = \"shiny\"\ntranslation = [0.0, 0.01, 0.0]",
                );
                none
            }),
        ),
        (
            "flat normals",
            Box::new(move |d| {
                edit(
                    d,
                    "scene.toml",
                    "material = \"shiny\"",
                    "material = \"shiny\"\nsmooth = false",
                );
                none
            }),
        ),
    ];
    for (what, change) in changes {
        let dir = resume_dir();
        let out = dir.path().join("out.raw");
        let before = load(dir.path(), &none);
        interrupt(&before, &out);
        let o = change(dir.path());
        let after = load(dir.path(), &o);
        let fresh = dir.path().join("fresh.raw");
        bake(&after, &fresh, &BLOCK, ltm_codec::Progress::NONE).unwrap();
        let report = bake(&after, &out, &BLOCK, ltm_codec::Progress::NONE).unwrap();
        assert!(
            std::fs::read(&out).unwrap() == std::fs::read(&fresh).unwrap(),
            "{what}: rows of the old scene were spliced in"
        );
        assert_eq!(report.blocks_resumed, 0, "{what}");
        assert_eq!(
            report.resume,
            ResumeState::Restarted(RestartReason::DifferentInputs),
            "{what}"
        );
        assert!(
            report.resume.to_string().contains("different inputs"),
            "{what}: {}",
            report.resume
        );
    }
}

#[test]
fn partial_from_the_same_inputs_resumes() {
    let dir = resume_dir();
    let out = dir.path().join("out.raw");
    let scene = load(dir.path(), &Overrides::default());
    interrupt(&scene, &out);
    // Re-loading the same files gives the same identity.
    let again = load(dir.path(), &Overrides::default());
    let seen = std::sync::Mutex::new(None);
    let report = bake(
        &again,
        &out,
        &BLOCK,
        Progress::new(&|s: Step| {
            if let Stage::Bake { resume } = s.stage {
                *seen.lock().unwrap() = Some(resume);
            }
        }),
    )
    .unwrap();
    assert_eq!(report.blocks_resumed, 3);
    assert!(
        matches!(report.resume, ResumeState::Resumed { kept: 3, .. }),
        "{}",
        report.resume
    );
    assert_eq!(
        *seen.lock().unwrap(),
        Some(report.resume),
        "progress carries it"
    );
    let fresh = dir.path().join("fresh.raw");
    let r = bake(&again, &fresh, &BLOCK, ltm_codec::Progress::NONE).unwrap();
    assert_eq!(r.resume, ResumeState::New);
    assert!(std::fs::read(&out).unwrap() == std::fs::read(&fresh).unwrap());
}

#[test]
fn partial_without_identity_is_started_over() {
    // A version-1 store (as ltm import or an older ltm writes it) cannot
    // prove where its rows came from.
    let dir = resume_dir();
    let out = dir.path().join("out.raw");
    let scene = load(dir.path(), &Overrides::default());
    let header = raw_header(&scene, BLOCK.block_bytes);
    let anonymous = RawHeader {
        input_id: None,
        has_surface: false,
        ..header
    };
    {
        let mut w = RawWriter::create(&out, anonymous).unwrap();
        let row = vec![7.0f32; header.block_range(0).len() * scene.dims().row_len()];
        w.write_block(0, &row, None).unwrap();
    }
    let report = bake(&scene, &out, &BLOCK, ltm_codec::Progress::NONE).unwrap();
    assert_eq!(
        report.resume,
        ResumeState::Restarted(RestartReason::NoIdentity)
    );
    assert_eq!(report.blocks_resumed, 0);
    let store = ltm_codec::RawStore::open(&out).unwrap();
    assert!(store.read_row(0).unwrap().iter().all(|&v| v != 7.0));
    // And a writer without an identity never resumes anything.
    {
        let mut w = RawWriter::create(&out, anonymous).unwrap();
        w.write_block(
            0,
            &vec![0.0; header.block_range(0).len() * scene.dims().row_len()],
            None,
        )
        .unwrap();
    }
    let w = RawWriter::create(&out, anonymous).unwrap();
    assert_eq!(
        w.resume_state(),
        ResumeState::Restarted(RestartReason::NoIdentity)
    );
    assert_eq!(w.pending_blocks().len(), header.block_count());
}

/// Packets with a reach per ray (`Scene::occluded_packet_until`, the light
/// plane's shadow rays) answer as single rays (`Scene::occluded_until`),
/// and a short reach ignores what lies beyond it.
#[test]
fn packets_with_a_reach_answer_as_single_rays() {
    let toml = scene_toml(
        FAR_CAMERA,
        LIGHTING,
        "[[quads]]\ncenter = [0.0, 1.0, 0.0]\nsize = [2.0, 2.0]\nmaterial = \"grey\"\n\
         [[quads]]\ncenter = [0.0, -0.2, 0.0]\nsize = [4.0, 4.0]\nmaterial = \"grey\"\n",
    );
    let (_d, r) = build(&toml, &[]);
    let scene = r.expect("two quads");
    let dirs = sphere_dirs(400);
    let mut bad = Vec::new();
    let (mut far, mut near) = (0, 0);
    for o in [
        DVec3::new(0.1, 0.0, 0.2),
        DVec3::new(0.0, 3.0, 0.0),
        DVec3::new(0.5, 0.99, 0.0),
    ] {
        // Reaches that end before, at and beyond the quads, and none.
        for reach in [1e-7, 0.5, 0.999, 1.0, 1.5, 10.0, f64::INFINITY] {
            let single: Vec<bool> = dirs
                .iter()
                .map(|&d| scene.occluded_until(o, d, reach))
                .collect();
            let mut out = vec![false; dirs.len()];
            scene.occluded_packet_until(o, &dirs, |_| reach, &mut out);
            for (k, (&got, &want)) in out.iter().zip(&single).enumerate() {
                if got != want {
                    bad.push(format!(
                        "from {o} along {} within {reach}: {got}, one ray {want}",
                        dirs[k]
                    ));
                }
            }
            let count = single.iter().filter(|&&h| h).count();
            match reach {
                r if r.is_infinite() => far += count,
                r if r < 1e-6 => near += count,
                _ => {}
            }
        }
        // A reach per direction: the distance to the plane y = 1.
        let plane = |d: DVec3| {
            if d.y > 0.0 {
                (1.0 - o.y) / d.y
            } else {
                f64::INFINITY
            }
        };
        let mut out = vec![false; dirs.len()];
        scene.occluded_packet_until(o, &dirs, plane, &mut out);
        for (k, &d) in dirs.iter().enumerate() {
            if out[k] != scene.occluded_until(o, d, plane(d)) {
                bad.push(format!("from {o} along {d} to the plane: {}", out[k]));
            }
        }
    }
    assert!(
        bad.is_empty(),
        "{} disagreements: {:?}",
        bad.len(),
        &bad[..bad.len().min(5)]
    );
    assert!(
        far > 300 && near == 0,
        "{far} occluded without a reach, {near} within 1e-7"
    );
}
