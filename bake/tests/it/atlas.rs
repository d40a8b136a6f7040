//! Atlas layouts (`parameterization = "atlas"`) on meshes a single chart
//! cannot hold: a figure with thin limbs and fingers, a torus knot (genus
//! 1), an open half-pipe, and all of them on a floor as one atlas.

use crate::common;

use common::{build, err, scene_toml, CAMERA, LIGHTING};
use glam::DVec3;
use ltm_bake::{row_surface, Scene};
use ltm_codec::Parameterization;
use std::f64::consts::TAU;
use std::fmt::Write as _;

type Mesh = (Vec<[f64; 3]>, Vec<[usize; 3]>);

/// A closed tube of radius `r` along the polyline `spine` (capped when
/// `open_ends`, a loop otherwise), `m` vertices around.
fn tube(spine: &[DVec3], r: f64, m: usize, closed_loop: bool) -> Mesh {
    let n = spine.len();
    let (mut v, mut f) = (Vec::new(), Vec::new());
    for i in 0..n {
        let (a, b) = if closed_loop {
            (spine[(i + n - 1) % n], spine[(i + 1) % n])
        } else {
            (spine[i.saturating_sub(1)], spine[(i + 1).min(n - 1)])
        };
        let t = (b - a).normalize();
        let side = if t.y.abs() < 0.9 { DVec3::Y } else { DVec3::X };
        let nrm = t.cross(side).normalize();
        let bin = t.cross(nrm);
        for j in 0..m {
            let s = TAU * j as f64 / m as f64;
            v.push((spine[i] + r * (s.cos() * nrm + s.sin() * bin)).to_array());
        }
    }
    let rings = if closed_loop { n } else { n - 1 };
    for i in 0..rings {
        for j in 0..m {
            let id = |i: usize, j: usize| (i % n) * m + j % m;
            f.push([id(i, j), id(i + 1, j + 1), id(i + 1, j)]);
            f.push([id(i, j), id(i, j + 1), id(i + 1, j + 1)]);
        }
    }
    if !closed_loop {
        for (ring, tip) in [(0, spine[0]), (n - 1, spine[n - 1])] {
            let c = v.len();
            v.push(tip.to_array());
            for j in 0..m {
                let (a, b) = (ring * m + j, ring * m + (j + 1) % m);
                f.push(if ring == 0 { [c, b, a] } else { [c, a, b] });
            }
        }
    }
    (v, f)
}

fn join(parts: Vec<Mesh>) -> Mesh {
    let (mut v, mut f) = (Vec::new(), Vec::new());
    for (pv, pf) in parts {
        let base = v.len();
        v.extend(pv);
        f.extend(pf.into_iter().map(|t| t.map(|i| i + base)));
    }
    (v, f)
}

fn line(a: DVec3, b: DVec3, k: usize) -> Vec<DVec3> {
    (0..=k).map(|i| a.lerp(b, i as f64 / k as f64)).collect()
}

/// A body with two arms, two legs and five fingers on each hand, every
/// part a capped tube: fingers are 0.02 thick on a 1.5-tall figure.
fn figure() -> Mesh {
    let p = DVec3::new;
    let mut parts = vec![
        tube(
            &line(p(0.0, 0.7, 0.0), p(0.0, 1.3, 0.0), 8),
            0.16,
            16,
            false,
        ),
        tube(
            &line(p(-0.08, 0.7, 0.0), p(-0.12, 0.0, 0.0), 10),
            0.05,
            10,
            false,
        ),
        tube(
            &line(p(0.08, 0.7, 0.0), p(0.12, 0.0, 0.0), 10),
            0.05,
            10,
            false,
        ),
    ];
    for side in [-1.0, 1.0] {
        let hand = p(side * 0.75, 1.2, 0.0);
        parts.push(tube(
            &line(p(side * 0.14, 1.2, 0.0), hand, 10),
            0.04,
            10,
            false,
        ));
        for k in 0..5 {
            let dz = 0.025 * (k as f64 - 2.0);
            let tip = hand + p(side * 0.12, -0.02 * (k as f64 - 2.0).abs(), dz * 2.0);
            parts.push(tube(&line(hand + p(0.0, 0.0, dz), tip, 4), 0.01, 6, false));
        }
    }
    join(parts)
}

/// A (2, 3) torus knot tube: genus 1.
fn torus_knot() -> Mesh {
    let spine: Vec<DVec3> = (0..240)
        .map(|i| {
            let t = TAU * i as f64 / 240.0;
            let r = 0.5 + 0.18 * (3.0 * t).cos();
            DVec3::new(
                r * (2.0 * t).cos(),
                0.6 + 0.18 * (3.0 * t).sin(),
                r * (2.0 * t).sin(),
            )
        })
        .collect();
    tube(&spine, 0.08, 12, true)
}

/// An open half-pipe (half a cylinder, no caps), facing up.
fn half_pipe() -> Mesh {
    let (n, m) = (24, 16);
    let mut v = Vec::new();
    for i in 0..=n {
        for j in 0..=m {
            let a = std::f64::consts::PI * j as f64 / m as f64;
            v.push([
                0.5 * a.cos(),
                0.55 - 0.5 * a.sin(),
                -0.8 + 1.6 * i as f64 / n as f64,
            ]);
        }
    }
    let id = |i: usize, j: usize| i * (m + 1) + j;
    let mut f = Vec::new();
    for i in 0..n {
        for j in 0..m {
            f.push([id(i, j), id(i, j + 1), id(i + 1, j + 1)]);
            f.push([id(i, j), id(i + 1, j + 1), id(i + 1, j)]);
        }
    }
    (v, f)
}

/// The signed volume of a closed mesh (every directed edge met once by
/// its reverse), `None` when open.
fn closed_volume((v, f): &Mesh) -> Option<f64> {
    let mut edges = std::collections::HashMap::new();
    for t in f {
        for k in 0..3 {
            *edges.entry((t[k], t[(k + 1) % 3])).or_insert(0) += 1;
        }
    }
    let closed = edges
        .iter()
        .all(|(&(a, b), &n)| n == 1 && edges.get(&(b, a)) == Some(&1));
    closed.then(|| {
        f.iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| DVec3::from(v[i]));
                a.dot(b.cross(c)) / 6.0
            })
            .sum()
    })
}

/// The corpus's closed parts are closed and wound outwards (else their
/// texels would see their insides).
#[test]
fn the_corpus_is_wound_outwards() {
    let p = DVec3::new;
    let capped = tube(&line(p(0.0, 0.0, 0.0), p(0.0, 1.0, 0.0), 4), 0.2, 8, false);
    for (name, m) in [("capped tube", capped), ("torus knot", torus_knot())] {
        let v = closed_volume(&m).unwrap_or_else(|| panic!("{name} is not closed"));
        assert!(v > 0.0, "{name}: volume {v}");
    }
    assert!(closed_volume(&half_pipe()).is_none());
}

fn obj((v, f): &Mesh) -> String {
    let mut s = String::new();
    for p in v {
        writeln!(s, "v {} {} {}", p[0], p[1], p[2]).unwrap();
    }
    for t in f {
        writeln!(s, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1).unwrap();
    }
    s
}

fn atlas_scene(meshes: &[&str], texture: &str, quad: bool) -> String {
    let mut body = String::new();
    for m in meshes {
        writeln!(body, "[[meshes]]\npath = \"{m}\"\nmaterial = \"grey\"\n").unwrap();
    }
    if quad {
        body.push_str(
            "[[quads]]\ncenter = [0.0, 0.0, 0.0]\nsize = [3.0, 3.0]\nmaterial = \"grey\"\n\n",
        );
    }
    scene_toml(CAMERA, LIGHTING, &format!("{body}[texture]\n{texture}"))
}

fn built(toml: &str, files: &[(&str, String)]) -> Scene {
    let files: Vec<(&str, &[u8])> = files.iter().map(|(n, s)| (*n, s.as_bytes())).collect();
    let (_dir, scene) = build(toml, &files);
    scene.unwrap()
}

/// Every valid texel's surface point lies on the receiver's triangles
/// (within a texel of dilation), and the stored mesh checks out.
fn assert_texels_on_mesh(scene: &Scene) {
    let map = scene.texel_map().unwrap();
    assert_eq!(map.parameterization(), Parameterization::Atlas);
    let mesh = map.receiver_mesh().unwrap();
    mesh.validate(map.size()).unwrap();
    let st = map.stats();
    assert_eq!(st.flipped_triangles, 0);
    assert!(st.stretch_mean.unwrap() < 1.5, "{st:?}");
    let surface = row_surface(scene).unwrap();
    let valid = surface.points().iter().filter(|p| p.valid).count();
    assert_eq!(valid, st.valid_texels);
    assert!(
        valid as f64 > 0.3 * (map.size() as f64).powi(2),
        "{valid} valid texels"
    );
}

#[test]
fn a_figure_with_fingers_gets_texels_in_proportion_to_area() {
    let fig = figure();
    let toml = atlas_scene(&["figure.obj"], "mesh = 0\nsize = 128\nspp = 1\n", false);
    let scene = built(&toml, &[("figure.obj", obj(&fig))]);
    assert_texels_on_mesh(&scene);
    // Texture area per unit surface area on the fingers (|x| > 0.76:
    // beyond the hands) against the whole figure's: one density for all.
    let map = scene.texel_map().unwrap();
    let mesh = map.receiver_mesh().unwrap();
    let (mut fingers, mut all) = ([0.0; 2], [0.0; 2]);
    for t in &mesh.triangles {
        let p = t.map(|i| DVec3::from(mesh.positions[i as usize].map(f64::from)));
        let q = t.map(|i| glam::DVec2::from(mesh.uvs[i as usize].map(f64::from)));
        let a = [
            0.5 * (q[1] - q[0]).perp_dot(q[2] - q[0]).abs(),
            0.5 * (p[1] - p[0]).cross(p[2] - p[0]).length(),
        ];
        for k in 0..2 {
            all[k] += a[k];
            if p.iter().all(|v| v.x.abs() > 0.76) {
                fingers[k] += a[k];
            }
        }
    }
    let ratio = (fingers[0] / fingers[1]) / (all[0] / all[1]);
    // xatlas keeps every chart a few texels wide, so thin parts get
    // more than their share, never less.
    assert!(
        fingers[1] > 0.0 && (0.8..3.0).contains(&ratio),
        "fingers get {ratio} of the figure's texel density"
    );
    // Each of the ten fingers (tips at |x| ≈ 0.87) has texels of its own.
    let surface = row_surface(&scene).unwrap();
    let tips = surface
        .points()
        .iter()
        .filter(|p| p.valid && p.position[0].abs() > 0.84)
        .count();
    assert!(tips >= 10, "{tips} texels on the finger tips");
}

#[test]
fn genus_one_open_and_several_parts_share_one_atlas() {
    let files = [
        ("knot.obj", obj(&torus_knot())),
        ("pipe.obj", obj(&half_pipe())),
        ("figure.obj", obj(&figure())),
    ];
    let toml = atlas_scene(
        &["knot.obj", "pipe.obj", "figure.obj"],
        "mesh = \"all\"\nsize = 128\nspp = 1\n",
        true,
    );
    let scene = built(&toml, &files);
    assert_texels_on_mesh(&scene);
    let atlas = scene.texel_map().unwrap().stats().atlas.clone().unwrap();
    // Four parts (three meshes and the floor).
    assert_eq!(atlas.part_density.len(), 4);
    let d: Vec<f64> = atlas.part_density.iter().map(|p| p.1).collect();
    // No part gets less than the floor's density; the figure (whose
    // fingers' charts are a few texels wide at least) gets more.
    let floor = d[3];
    assert!(
        d.iter().all(|&x| x >= 0.9 * floor && x <= 2.0 * floor),
        "densities {d:?}"
    );
    // The same inputs give the same atlas, bit for bit.
    let again = built(&toml, &files);
    let (a, b) = (scene.texel_map().unwrap(), again.texel_map().unwrap());
    assert_eq!(a.receiver_mesh(), b.receiver_mesh());
    assert_eq!(scene.input_id(), again.input_id());
}

#[test]
fn a_texel_density_sizes_the_texture() {
    let files = [("knot.obj", obj(&torus_knot()))];
    let sized = |t: &str| {
        let s = built(&atlas_scene(&["knot.obj"], t, false), &files);
        s.texel_map().unwrap().size()
    };
    let (low, high) = (
        sized("mesh = 0\ntexels_per_unit = 20.0\n"),
        sized("mesh = 0\ntexels_per_unit = 40.0\n"),
    );
    let ratio = high as f64 / low as f64;
    assert!((1.6..2.5).contains(&ratio), "{low} → {high}");
}

#[test]
fn atlas_settings_that_cannot_work_are_clear_errors() {
    let files: Vec<(&str, &[u8])> = vec![];
    let knot = obj(&torus_knot());
    let with = |t: &str| {
        let toml = atlas_scene(&["knot.obj"], t, false);
        err(build(&toml, &[("knot.obj", knot.as_bytes())]).1).1
    };
    let _ = files;
    for (t, want) in [
        (
            "mesh = \"all\"\nsize = 64\nparameterization = \"sphere\"\n",
            "needs parameterization = \"atlas\"",
        ),
        (
            "mesh = 0\nsize = 64\nparameterization = \"uv\"\ntexels_per_unit = 10.0\n",
            "only an atlas",
        ),
        ("mesh = 0\ntexels_per_unit = -1.0\n", "texels_per_unit"),
        ("mesh = 0\n", "absent with texels_per_unit"),
        (
            "mesh = \"every\"\nsize = 64\n",
            "mesh \"every\" (valid: an index into [[meshes]], or \"all\")",
        ),
        ("mesh = -2\nsize = 64\n", "mesh index -2"),
        ("mesh = 0\nsize = 16\ntexels_per_unit = 500.0\n", "16×16"),
        (
            "mesh = 0\ntexels_per_unit = 900000.0\n",
            "lower the texel density",
        ),
        ("mesh = 0\nsize = 64\npadding = 40\n", "texture.padding"),
    ] {
        let e = with(t);
        assert!(e.contains(want), "{t}: {e}");
    }
}

/// An open surface is seen from both sides: each side of the half-pipe
/// has texels of its own, whose normals face that side.
#[test]
fn an_open_surface_gets_texels_on_both_sides() {
    let toml = atlas_scene(&["pipe.obj"], "mesh = 0\nsize = 64\nspp = 1\n", false);
    let scene = built(&toml, &[("pipe.obj", obj(&half_pipe()))]);
    assert_texels_on_mesh(&scene);
    let surface = row_surface(&scene).unwrap();
    // Texels on the pipe's bottom (|x| < 0.1): inner side faces up, outer down.
    let bottom: Vec<f32> = surface
        .points()
        .iter()
        .filter(|p| p.valid && p.position[0].abs() < 0.1)
        .map(|p| p.normal[1])
        .collect();
    let up = bottom.iter().filter(|&&y| y > 0.9).count();
    let down = bottom.iter().filter(|&&y| y < -0.9).count();
    assert!(
        up > 20 && down > 20 && (up as f64 / down as f64 - 1.0).abs() < 0.3,
        "{up} up, {down} down"
    );
}

/// Input a chart atlas must survive: three triangles on one edge (a fin),
/// two cubes touching at a vertex (a bowtie), a duplicated face, a
/// zero-area sliver and a face whose winding disagrees with its
/// neighbours'. The atlas covers every non-degenerate triangle and each
/// texel still lies on the mesh.
#[test]
fn non_manifold_and_degenerate_input_is_handled() {
    let mut s = String::from(
        "v 0 0 0\nv 1 0 0\nv 0.5 1 0\nv 0.5 0 1\nv 0.5 0 -1\nv 0.5 -1 0\n\
         f 1 2 3\nf 2 1 4\nf 1 2 5\nf 1 2 6\nf 1 2 3\nv 2 0 0\nf 1 2 7\n",
    );
    // Two unit cubes touching at the point (1, 1, 1).
    for (k, o) in [(8, 0.0), (16, 1.0)] {
        for c in 0..8 {
            let p = [c & 1, (c >> 1) & 1, (c >> 2) & 1].map(|b| o + 2.0 + b as f64);
            writeln!(s, "v {} {} {}", p[0], p[1], p[2]).unwrap();
        }
        for q in [
            [0, 1, 3, 2],
            [4, 6, 7, 5],
            [0, 4, 5, 1],
            [2, 3, 7, 6],
            [0, 2, 6, 4],
            [1, 5, 7, 3],
        ] {
            let v = q.map(|i| i + k);
            writeln!(
                s,
                "f {} {} {}\nf {} {} {}",
                v[0], v[1], v[2], v[0], v[3], v[2]
            )
            .unwrap();
        }
    }
    let toml = atlas_scene(&["bad.obj"], "mesh = 0\nsize = 64\nspp = 1\n", false);
    let scene = built(&toml, &[("bad.obj", s)]);
    let map = scene.texel_map().unwrap();
    let mesh = map.receiver_mesh().unwrap();
    mesh.validate(64).unwrap();
    // The sliver (f 1 2 7) is left out as zero-area; every other face is
    // drawn, from both sides (the fin makes the surface open).
    assert_eq!(mesh.triangles.len(), 2 * (5 + 24));
    assert_eq!(map.stats().skipped_triangles, 1);
    let surface = row_surface(&scene).unwrap();
    assert!(surface.points().iter().filter(|p| p.valid).count() > 500);
}

#[test]
fn shipped_atlas_scene_parses() {
    let path = common::assets().join("scenes/atlas.toml");
    let desc = ltm_bake::SceneDesc::load(&path).unwrap();
    let t = desc.texture.as_ref().unwrap();
    assert_eq!((t.mesh, t.size), (ltm_bake::Receivers::All, 256));
    assert_eq!(t.parameterization, Parameterization::Atlas);
    assert_eq!((t.padding, t.dilate()), (2, 1));
}

/// A closed receiver whose faces point inwards would bake black: it is an
/// error naming the mesh and the fix; the same mesh wound outwards bakes.
#[test]
fn an_inside_out_receiver_is_an_error() {
    let (v, f) = torus_knot();
    let inward: Mesh = (v.clone(), f.iter().map(|t| [t[0], t[2], t[1]]).collect());
    let toml = atlas_scene(&["knot.obj"], "mesh = 0\nsize = 32\n", false);
    let (_, e) = err(build(&toml, &[("knot.obj", obj(&inward).as_bytes())]).1);
    assert!(
        e.contains("knot.obj") && e.contains("point inwards") && e.contains("winding"),
        "{e}"
    );
    let (_, ok) = build(&toml, &[("knot.obj", obj(&(v, f)).as_bytes())]);
    ok.unwrap();
}
