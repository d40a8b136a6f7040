//! Texture-space bakes: rows are texels of a texture over one mesh, laid
//! out by the mesh's own UVs or by a spherical parameterization.

use crate::common;

use common::{build, err, scene_toml, CAMERA, LIGHTING};
use ltm_bake::{bake, row_surface, BakeOptions, Scene};
use ltm_codec::{Parameterization, RawStore, RowLayout};
use std::fmt::Write as _;

/// An icosphere of radius `r` at `c` (closed, genus 0), `level`
/// subdivisions, as OBJ text.
pub fn icosphere(level: usize, r: f64, c: [f64; 3]) -> String {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let mut v: Vec<[f64; 3]> = vec![
        [-1.0, t, 0.0],
        [1.0, t, 0.0],
        [-1.0, -t, 0.0],
        [1.0, -t, 0.0],
        [0.0, -1.0, t],
        [0.0, 1.0, t],
        [0.0, -1.0, -t],
        [0.0, 1.0, -t],
        [t, 0.0, -1.0],
        [t, 0.0, 1.0],
        [-t, 0.0, -1.0],
        [-t, 0.0, 1.0],
    ];
    let mut f: Vec<[usize; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..level {
        let mut mid = std::collections::HashMap::new();
        let mut nf = Vec::new();
        for tri in &f {
            let mut m = [0usize; 3];
            for k in 0..3 {
                let (a, b) = (tri[k].min(tri[(k + 1) % 3]), tri[k].max(tri[(k + 1) % 3]));
                m[k] = *mid.entry((a, b)).or_insert_with(|| {
                    v.push([0, 1, 2].map(|i| (v[a][i] + v[b][i]) / 2.0));
                    v.len() - 1
                });
            }
            nf.extend([
                [tri[0], m[0], m[2]],
                [tri[1], m[1], m[0]],
                [tri[2], m[2], m[1]],
                m,
            ]);
        }
        f = nf;
    }
    let mut s = String::new();
    for p in &v {
        let l = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        writeln!(
            s,
            "v {} {} {}",
            c[0] + r * p[0] / l,
            c[1] + r * p[1] / l,
            c[2] + r * p[2] / l
        )
        .unwrap();
    }
    for t in &f {
        writeln!(s, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1).unwrap();
    }
    s
}

/// A unit square in y = 0 facing +Y, with UVs (u, v) = (x + ½, ½ − z),
/// split into `n × n` cells.
fn plane_obj(n: usize) -> String {
    let mut s = String::new();
    for j in 0..=n {
        for i in 0..=n {
            let (u, v) = (i as f64 / n as f64, j as f64 / n as f64);
            writeln!(s, "v {} 0 {}", u - 0.5, 0.5 - v).unwrap();
            writeln!(s, "vt {u} {v}").unwrap();
        }
    }
    for j in 0..n {
        for i in 0..n {
            let a = j * (n + 1) + i + 1;
            let (b, c, d) = (a + 1, a + n + 1, a + n + 2);
            writeln!(s, "f {a}/{a} {b}/{b} {d}/{d}").unwrap();
            writeln!(s, "f {a}/{a} {d}/{d} {c}/{c}").unwrap();
        }
    }
    s
}

fn texture_scene(mesh: &str, extra: &str) -> String {
    scene_toml(
        CAMERA,
        LIGHTING,
        &format!("[[meshes]]\npath = \"{mesh}\"\nmaterial = \"grey\"\n\n{extra}"),
    )
}

fn baked(toml: &str, files: &[(&str, &[u8])]) -> (Scene, RawStore, tempfile::TempDir) {
    let (dir, scene) = build(toml, files);
    let scene = scene.unwrap();
    let out = dir.path().join("t.raw");
    bake(
        &scene,
        &out,
        &BakeOptions::default(),
        ltm_codec::Progress::NONE,
    )
    .unwrap();
    let store = RawStore::open(&out).unwrap();
    (scene, store, dir)
}

/// A plane under an unoccluded sky: every texel's grey transport sums to
/// ∫ cos/π dω = 1, its albedo is the material's, and the surface data
/// places each texel at its UV's point.
#[test]
fn uv_plane_texels_see_the_whole_sky() {
    let toml = texture_scene(
        "plane.obj",
        "[texture]\nmesh = 0\nsize = 8\nparameterization = \"uv\"\nspp = 4\n",
    );
    let (scene, store, _dir) = baked(&toml, &[("plane.obj", plane_obj(3).as_bytes())]);
    let dims = store.dims();
    assert_eq!(
        dims.rows,
        RowLayout::Texture {
            size: 8,
            parameterization: Parameterization::Uv
        }
    );
    let surface = store.surface().expect("surface data");
    assert_eq!(surface.valid_count(), 64);
    let albedo = store.albedo().expect("grey transport with albedo");
    for k in 0..64 {
        let sum: f64 = store.read_row(k).unwrap().iter().map(|&v| v as f64).sum();
        assert!((sum - 1.0).abs() < 0.02, "texel {k}: {sum}");
        assert_eq!(albedo[3 * k], 0.5);
        let p = surface.points()[k];
        let (u, v) = (
            ((k % 8) as f32 + 0.5) / 8.0,
            1.0 - ((k / 8) as f32 + 0.5) / 8.0,
        );
        let want = [u - 0.5, 0.0, 0.5 - v];
        assert!(
            (0..3).all(|i| (p.position[i] - want[i]).abs() < 1e-5),
            "{k}: {:?}",
            p.position
        );
        assert_eq!(p.normal, [0.0, 1.0, 0.0]);
    }
    assert_eq!(scene.texel_map().unwrap().stats().valid_texels, 64);
    assert_eq!(row_surface(&scene).unwrap(), *surface);
}

/// A sphere parameterization of a convex closed mesh: no texel is
/// shadowed, so every row sums to 1; with a ground quad under it, texels
/// on the underside see less of the sky and sum to less.
#[test]
fn sphere_texels_of_a_convex_mesh_see_a_hemisphere() {
    let ico = icosphere(2, 0.5, [0.0, 0.6, 0.0]);
    let t = "[texture]\nmesh = 0\nsize = 16\nparameterization = \"sphere\"\nspp = 1\n";
    let (scene, store, _dir) = baked(&texture_scene("ico.obj", t), &[("ico.obj", ico.as_bytes())]);
    let st = scene.texel_map().unwrap().stats().clone();
    assert_eq!(st.valid_texels, 256);
    assert_eq!(st.flipped_triangles, 0);
    let (mean, max) = (st.stretch_mean.unwrap(), st.stretch_max.unwrap());
    assert!(
        (1.0..1.2).contains(&mean) && max < 2.0,
        "stretch {mean} {max}"
    );
    let surface = store.surface().unwrap();
    for k in 0..256 {
        let sum: f64 = store.read_row(k).unwrap().iter().map(|&v| v as f64).sum();
        // Flat facets: the quadrature's cos over texels is approximate.
        assert!((sum - 1.0).abs() < 0.03, "texel {k}: {sum}");
        let p = surface.points()[k];
        let r =
            (p.position[0].powi(2) + (p.position[1] - 0.6).powi(2) + p.position[2].powi(2)).sqrt();
        assert!(
            r > 0.5 * 0.79 && r <= 0.5 + 1e-5,
            "texel {k} off the mesh: r = {r}"
        );
    }
    let quad = "[[quads]]\ncenter = [0.0, 0.0, 0.0]\nsize = [8.0, 8.0]\nmaterial = \"grey\"\n";
    let (_s, shadowed, _d) = baked(
        &texture_scene("ico.obj", &format!("{quad}\n{t}")),
        &[("ico.obj", ico.as_bytes())],
    );
    let low = (0..256)
        .filter(|&k| shadowed.surface().unwrap().points()[k].normal[1] < -0.5)
        .map(|k| {
            shadowed
                .read_row(k)
                .unwrap()
                .iter()
                .map(|&v| v as f64)
                .sum::<f64>()
        })
        .fold(f64::INFINITY, f64::min);
    assert!(low < 0.2, "underside texel sums {low}");
}

#[test]
fn bad_texture_inputs_are_clear_errors() {
    let ico = icosphere(1, 0.5, [0.0, 0.6, 0.0]);
    let plane = plane_obj(2);
    let files: &[(&str, &[u8])] = &[("ico.obj", ico.as_bytes()), ("plane.obj", plane.as_bytes())];
    let case = |mesh: &str, t: &str| {
        let (_d, r) = build(&texture_scene(mesh, &format!("[texture]\n{t}\n")), files);
        err(r).1
    };
    let e = case("ico.obj", "mesh = 0\nsize = 8\nparameterization = \"uv\"");
    assert!(e.contains("no texture coordinates"), "{e}");
    let e = case(
        "plane.obj",
        "mesh = 0\nsize = 8\nparameterization = \"sphere\"",
    );
    assert!(e.contains("open") && e.contains("boundary edges"), "{e}");
    let e = case(
        "ico.obj",
        "mesh = 1\nsize = 8\nparameterization = \"sphere\"",
    );
    assert!(e.contains("texture.mesh") && e.contains("0..1"), "{e}");
    for size in ["0", "4097"] {
        let e = case(
            "ico.obj",
            &format!("mesh = 0\nsize = {size}\nparameterization = \"sphere\""),
        );
        assert!(e.contains("texture.size") && e.contains("4096"), "{e}");
    }
    let e = case("ico.obj", "mesh = 0\nsize = 8\nparameterization = \"cube\"");
    assert!(e.contains("unknown parameterization"), "{e}");
    // A glossy receiver needs diffuse_only.
    let glossy = "[materials.shiny]\ntype = \"glossy\"\nalbedo = [0.5, 0.5, 0.5]\nspecular = [0.04, 0.04, 0.04]\nroughness = 0.2\n";
    let toml = scene_toml(
        CAMERA,
        LIGHTING,
        &format!("{glossy}\n[[meshes]]\npath = \"ico.obj\"\nmaterial = \"shiny\"\n\n[texture]\nmesh = 0\nsize = 8\nparameterization = \"sphere\"\n"),
    );
    let (_d, r) = build(&toml, files);
    let e = err(r).1;
    assert!(e.contains("glossy") && e.contains("diffuse_only"), "{e}");
    let (_d, r) = build(
        &toml.replace(
            "parameterization = \"sphere\"",
            "parameterization = \"sphere\"\ndiffuse_only = true",
        ),
        files,
    );
    assert_eq!(r.unwrap().channels(), 1);
}

/// A torus (genus 1) and two spheres (two components) are refused with
/// their Euler characteristic.
#[test]
fn non_genus_zero_meshes_are_refused() {
    let (n, m) = (12, 8);
    let mut s = String::new();
    for i in 0..n {
        for j in 0..m {
            let (a, b) = (
                i as f64 / n as f64 * std::f64::consts::TAU,
                j as f64 / m as f64 * std::f64::consts::TAU,
            );
            let r = 1.0 + 0.3 * b.cos();
            writeln!(
                s,
                "v {} {} {}",
                r * a.cos(),
                0.3 * b.sin() + 1.0,
                r * a.sin()
            )
            .unwrap();
        }
    }
    for i in 0..n {
        for j in 0..m {
            let id = |i: usize, j: usize| (i % n) * m + (j % m) + 1;
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i, j + 1), id(i + 1, j + 1));
            writeln!(s, "f {a} {c} {d}\nf {a} {d} {b}").unwrap();
        }
    }
    let t = "[texture]\nmesh = 0\nsize = 8\nparameterization = \"sphere\"\n";
    let (_d, r) = build(
        &texture_scene("torus.obj", t),
        &[("torus.obj", s.as_bytes())],
    );
    let e = err(r).1;
    assert!(
        e.contains("Euler characteristic") && e.contains("= 0") && e.contains("genus 1"),
        "{e}"
    );
    let two = icosphere(1, 0.3, [0.0, 0.5, 0.0])
        + &icosphere(1, 0.3, [1.0, 0.5, 0.0])
            .lines()
            .map(|l| {
                if let Some(rest) = l.strip_prefix("f ") {
                    let ids: Vec<usize> = rest
                        .split(' ')
                        .map(|x| x.parse::<usize>().unwrap() + 42)
                        .collect();
                    format!("f {} {} {}\n", ids[0], ids[1], ids[2])
                } else {
                    format!("{l}\n")
                }
            })
            .collect::<String>();
    let (_d, r) = build(&texture_scene("two.obj", t), &[("two.obj", two.as_bytes())]);
    let e = err(r).1;
    assert!(e.contains("2 connected component"), "{e}");
}

/// The shipped texture-space scene parses and names a sphere layout.
#[test]
fn shipped_texture_scene_parses() {
    let path = common::assets().join("scenes/bunny_texture.toml");
    let desc = ltm_bake::SceneDesc::load(&path).unwrap();
    let t = desc.texture.as_ref().unwrap();
    assert_eq!((t.mesh, t.size), (ltm_bake::Receivers::Mesh(0), 256));
    assert_eq!(t.parameterization, Parameterization::Sphere);
}

/// A closed genus-0 body with two thin limbs (a sphere of radius 0.3
/// pushed out to 0.3·(1 + 2.5·exp(−(θ/0.25)²)) about ±X): the sphere
/// layout folds nothing and gives the limbs a fair share of the texels.
#[test]
fn thin_limbs_keep_their_texels() {
    let limb = |p: [f64; 3]| {
        let l = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        let c = (p[0] / l).abs().clamp(-1.0, 1.0);
        0.3 * (1.0 + 2.5 * (-(c.acos() / 0.25).powi(2)).exp()) / l
    };
    let obj: String = icosphere(4, 1.0, [0.0, 0.0, 0.0])
        .lines()
        .map(|line| match line.strip_prefix("v ") {
            Some(rest) => {
                let v: Vec<f64> = rest.split(' ').map(|x| x.parse().unwrap()).collect();
                let s = limb([v[0], v[1], v[2]]);
                format!("v {} {} {}\n", v[0] * s, v[1] * s + 0.5, v[2] * s)
            }
            None => format!("{line}\n"),
        })
        .collect();
    let t = "[texture]\nmesh = 0\nsize = 64\nparameterization = \"sphere\"\nspp = 1\n";
    let (scene, store, _dir) = baked(
        &texture_scene("limbs.obj", t),
        &[("limbs.obj", obj.as_bytes())],
    );
    let st = scene.texel_map().unwrap().stats().clone();
    assert_eq!(st.flipped_triangles, 0);
    let (mean, max) = (st.stretch_mean.unwrap(), st.stretch_max.unwrap());
    // Texels on the limbs (|x| > 0.45) against their share of the area:
    // the conformal start alone gives them about a third of their share
    // (12.5 % of the texels for 35 % of the area); the density-equalizing
    // flow brings it near 1.
    let on_limbs = store
        .surface()
        .unwrap()
        .points()
        .iter()
        .filter(|p| p.position[0].abs() > 0.45)
        .count() as f64
        / 4096.0;
    let area = |pts: &[[f64; 3]; 3]| {
        let (a, b, c) = (
            glam::DVec3::from(pts[0]),
            glam::DVec3::from(pts[1]),
            glam::DVec3::from(pts[2]),
        );
        0.5 * (b - a).cross(c - a).length()
    };
    let verts: Vec<[f64; 3]> = obj
        .lines()
        .filter_map(|l| l.strip_prefix("v "))
        .map(|r| {
            let v: Vec<f64> = r.split(' ').map(|x| x.parse().unwrap()).collect();
            [v[0], v[1], v[2]]
        })
        .collect();
    let (mut limb_area, mut total) = (0.0, 0.0);
    for l in obj.lines().filter_map(|l| l.strip_prefix("f ")) {
        let i: Vec<usize> = l
            .split(' ')
            .map(|x| x.parse::<usize>().unwrap() - 1)
            .collect();
        let tri = [verts[i[0]], verts[i[1]], verts[i[2]]];
        let a = area(&tri);
        total += a;
        if tri.iter().all(|p| p[0].abs() > 0.45) {
            limb_area += a;
        }
    }
    let share = on_limbs / (limb_area / total);
    assert!(mean < 3.0 && max < 20.0, "stretch mean {mean} max {max}");
    assert!(
        share > 0.5,
        "limbs get {share} of their fair share of texels"
    );
}

/// A real scan (the small Stanford bunny in assets/): the conformal start
/// squeezes the ears (L2 stretch mean about 400, max 6000); density
/// equalization and one-ring relaxation alone leave mean 3.5, max 23. The
/// Sobolev descent of the stretch brings both well below that, with no
/// triangle flipped.
#[test]
fn scanned_bunny_parameterizes_with_low_stretch() {
    let bytes = std::fs::read(common::assets().join("meshes/bunny_small.obj")).unwrap();
    let t = "[texture]\nmesh = 0\nsize = 32\nparameterization = \"sphere\"\nspp = 1\n";
    let (_d, scene) = build(&texture_scene("bunny.obj", t), &[("bunny.obj", &bytes)]);
    let st = scene.unwrap().texel_map().unwrap().stats().clone();
    assert_eq!(st.flipped_triangles, 0);
    let (mean, max) = (st.stretch_mean.unwrap(), st.stretch_max.unwrap());
    // 1.49 / 4.92 with the converged descent (1.60 / 5.9 after 150 steps;
    // 3.52 / 22.8 without it).
    assert!(mean < 2.0 && max < 8.0, "stretch mean {mean} max {max}");
}
