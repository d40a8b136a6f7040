//! Glossy materials by wavelet rotation (`ltm render --brdf`) against
//! Mitsuba 3 (issue 31), without Python. `tools/tests/fixtures/glossy_mitsuba/`
//! holds a sphere (`scene.toml`, `sphere.obj` with exact vertex normals),
//! the lighting (`env.exr`: a sky with a sun 10⁴ times brighter, made by
//! the script, constant over each texel of an n = 32 cubemap), Mitsuba's
//! `direct` render of the analytic sphere for each material
//! (`mitsuba_*.npy`), the pixels more than 1 px from its silhouette
//! (`interior.npy`) and `meta.json` (camera, Mitsuba's noise, the limit per
//! material). `tools/validate/mitsuba_glossy.py --fixture` made them; the
//! folder's README.md gives the command.
//!
//! The test bakes the sphere, draws each material with `ltm render --brdf
//! SPEC --shading glossy --glossy-n 32` and checks the relative L2 error
//! over the interior, Mitsuba's noise removed in quadrature, against the
//! limit (1.5 × the error measured when the fixture was made).

use ltm_relight::Image;
use std::path::{Path, PathBuf};

fn ltm(args: &[&str]) -> String {
    let run = ltm_testkit::run(env!("CARGO_BIN_EXE_ltm"), args);
    assert!(run.ok, "{args:?}: {}", run.stderr);
    run.stderr
}

fn fixture() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/glossy_mitsuba")
}

/// `[x, y, z]` of `meta.json` as the CLI's `x,y,z`.
fn vec3(v: &serde_json::Value) -> String {
    let xs: Vec<String> = v
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap().to_string())
        .collect();
    xs.join(",")
}

/// Relative L2 of `ours` against `reference` over `mask`.
fn masked_rel_l2(ours: &Image, reference: &[f32], mask: &[bool]) -> f64 {
    let (mut num, mut den) = (0.0f64, 0.0f64);
    for (i, _) in mask.iter().enumerate().filter(|(_, &m)| m) {
        for c in 0..3 {
            let r = f64::from(reference[i * 3 + c]);
            num += (f64::from(ours.data[i][c]) - r).powi(2);
            den += r * r;
        }
    }
    assert!(den > 0.0, "Mitsuba's reference is black over the interior");
    (num / den).sqrt()
}

#[test]
fn glossy_renders_match_mitsuba_on_a_sphere_under_a_sun() {
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n).to_str().unwrap().to_string();
    let fx = fixture();
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(fx.join("meta.json")).unwrap()).unwrap();
    ltm(&[
        "bake",
        fx.join("scene.toml").to_str().unwrap(),
        "-o",
        &p("t.raw"),
    ]);
    ltm(&["compress", &p("t.raw"), "-o", &p("t.ltm")]);
    let width = meta["width"].as_u64().unwrap() as usize;
    let (shape, interior) = ltm_testkit::read_npy_f32(&fx.join("interior.npy"));
    assert_eq!(shape, [width, width]);
    let mask: Vec<bool> = interior.iter().map(|&m| m > 0.5).collect();
    assert!(mask.iter().filter(|&&m| m).count() > width * width / 10);
    let cam = &meta["camera"];
    let (size, n) = (
        format!("{width}x{width}"),
        meta["glossy_n"].as_u64().unwrap().to_string(),
    );
    let (eye, target, fov) = (
        vec3(&cam["eye"]),
        vec3(&cam["target"]),
        cam["fov"].as_f64().unwrap().to_string(),
    );
    let env = fx.join("env.exr");
    let mut failures = Vec::new();
    for case in meta["cases"].as_array().unwrap() {
        let name = case["name"].as_str().unwrap();
        let spec = case["spec"].as_str().unwrap();
        let out = p(&format!("{name}.exr"));
        ltm(&[
            "render",
            &p("t.ltm"),
            "--env",
            env.to_str().unwrap(),
            "--brdf",
            spec,
            "--shading",
            "glossy",
            "--glossy-n",
            &n,
            "--rotation-cache",
            &p("rotations.bin"),
            "--camera",
            &eye,
            "--target",
            &target,
            "--fov",
            &fov,
            "--size",
            &size,
            "--supersample",
            "4",
            "-o",
            &out,
        ]);
        let ours = Image::read_exr(Path::new(&out)).unwrap();
        assert_eq!((ours.width, ours.height), (width, width));
        let (shape, reference) = ltm_testkit::read_npy_f32(&fx.join(format!("mitsuba_{name}.npy")));
        assert_eq!(shape, [width, width, 3]);
        let e = masked_rel_l2(&ours, &reference, &mask);
        let noise = case["mitsuba_noise"].as_f64().unwrap();
        let e0 = (e * e - noise * noise).max(0.0).sqrt();
        let limit = case["limit"].as_f64().unwrap();
        println!(
            "{name} ({spec}): {:.2} % ({:.2} % with Mitsuba's noise), limit {:.1} %",
            100.0 * e0,
            100.0 * e,
            100.0 * limit
        );
        if e0 > limit {
            failures.push(format!("{name}: {e0:.4} > {limit}"));
        }
    }
    assert!(failures.is_empty(), "{failures:?}");
}
