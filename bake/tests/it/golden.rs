//! Golden hashes of baked values: every row (and albedo) of small bakes,
//! hashed bit for bit, with the count of shadow rays. A change to any baked
//! value (the tracer, the quadrature, the sampling) changes a hash; a
//! change that must not move values, such as a faster tracer, must leave
//! them all as they are. Cases: the default scene (RGB, glossy) at 1, 4,
//! 9 and 64 samples per texel; a grey scene of a torus
//! (genus 1) and a comb of thin slivers on a ground quad, image rows and
//! atlas texels.

use crate::common;

use common::*;
use ltm_bake::{Overrides, Scene, SceneDesc};

/// FNV-1a, 64 bits.
fn fnv(hash: &mut u64, bytes: &[u8]) {
    for &b in bytes {
        *hash ^= u64::from(b);
        *hash = hash.wrapping_mul(0x0000_0100_0000_01b3);
    }
}

/// The hash of every row and albedo of `scene`, and its shadow rays.
fn baked(scene: &Scene) -> (u64, u64) {
    let dims = scene.dims();
    let mut row = vec![0.0f32; dims.row_len()];
    let (mut hash, mut rays) = (0xcbf2_9ce4_8422_2325u64, 0);
    for p in 0..dims.pixels() {
        let mut albedo = [0.0f32; 3];
        rays += scene.transport_row(p, &mut row, &mut albedo).shadow_rays;
        for v in row.iter().chain(&albedo) {
            fnv(&mut hash, &v.to_bits().to_le_bytes());
        }
    }
    (hash, rays)
}

fn default_scene(width: u32, height: u32, face_res: u32, samples: u32) -> Scene {
    let mut desc = SceneDesc::default_scene(&assets()).expect("default scene");
    desc.apply(&Overrides {
        width: Some(width),
        height: Some(height),
        face_res: Some(face_res),
        texel_samples: Some(samples),
        ..Default::default()
    })
    .unwrap();
    Scene::build(&desc).expect("default scene builds")
}

/// A torus about the y axis at height `y`, outward-wound.
fn torus(big: f64, small: f64, y: f64, nu: usize, nv: usize) -> String {
    let mut obj = String::new();
    for i in 0..nu {
        for j in 0..nv {
            let (u, v) = (
                i as f64 * std::f64::consts::TAU / nu as f64,
                j as f64 * std::f64::consts::TAU / nv as f64,
            );
            let r = big + small * v.cos();
            obj += &format!(
                "v {} {} {}\n",
                r * u.cos(),
                y + small * v.sin(),
                r * u.sin()
            );
        }
    }
    for i in 0..nu {
        for j in 0..nv {
            let at = |a: usize, b: usize| (a % nu) * nv + b % nv + 1;
            let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
            obj += &format!("f {a} {c} {b}\nf {a} {d} {c}\n");
        }
    }
    obj
}

/// Thin upright slivers, a hundredth wide, in a row.
fn comb() -> String {
    let mut obj = String::new();
    for i in 0..12 {
        let x = -0.6 + i as f64 * 0.1;
        obj += &format!("v {x} 0 0.8\nv {} 0 0.8\nv {x} 0.9 0.7\n", x + 0.01);
        obj += &format!("f {} {} {}\n", 3 * i + 1, 3 * i + 2, 3 * i + 3);
    }
    obj
}

fn grey_scene(texture: bool) -> Scene {
    let mut body = String::from(
        "[[meshes]]\npath = \"torus.obj\"\nmaterial = \"grey\"\n\n\
         [[meshes]]\npath = \"comb.obj\"\nmaterial = \"grey\"\n\n\
         [[quads]]\ncenter = [0.0, 0.0, 0.0]\nsize = [3.0, 3.0]\nmaterial = \"grey\"\n\n",
    );
    if texture {
        body += "[texture]\nmesh = 0\nsize = 32\nspp = 1\n";
    }
    let camera =
        "eye = [0.0, 2.5, 3.5]\ntarget = [0.0, 0.3, 0.0]\nfov = 40.0\nwidth = 20\nheight = 15";
    let toml = scene_toml(camera, "face_res = 8\ntexel_samples = 4", &body);
    let torus = torus(0.6, 0.2, 0.25, 24, 12);
    let comb = comb();
    let (_dir, scene) = build(
        &toml,
        &[
            ("torus.obj", torus.as_bytes()),
            ("comb.obj", comb.as_bytes()),
        ],
    );
    scene.expect("grey scene builds")
}

#[test]
fn baked_values_match_their_golden_hashes() {
    let cases: [(&str, Scene, u64, u64); 6] = [
        (
            "default, S = 4",
            default_scene(24, 18, 8, 4),
            0xb033_01a2_5799_9b0a,
            191190,
        ),
        (
            "default, S = 1",
            default_scene(16, 12, 8, 1),
            0x2093_5c22_47b9_0656,
            21576,
        ),
        (
            "default, S = 9, n = 2",
            default_scene(16, 12, 2, 9),
            0x5ffd_be06_564f_d195,
            12121,
        ),
        (
            "default, S = 64, n = 4",
            default_scene(12, 9, 4, 64),
            0x2798_6964_fb24_c106,
            189473,
        ),
        (
            "grey image rows",
            grey_scene(false),
            0x5117_38c9_b484_bdcb,
            121822,
        ),
        (
            "grey atlas texels",
            grey_scene(true),
            0x1719_5384_6fe5_cadf,
            398944,
        ),
    ];
    let mut wrong = Vec::new();
    for (name, scene, hash, rays) in &cases {
        let got = baked(scene);
        if got != (*hash, *rays) {
            wrong.push(format!("{name}: ({:#018x}, {})", got.0, got.1));
        }
    }
    assert!(wrong.is_empty(), "hashes changed:\n{}", wrong.join("\n"));
}
