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
//! The first test bakes the sphere, draws each material with `ltm render
//! --brdf SPEC --shading glossy --glossy-n 32` and checks the relative L2
//! error over the interior, Mitsuba's noise removed in quadrature, against
//! the limit (1.5 × the error measured when the fixture was made). The
//! second bakes the same sphere as the camera's image rows (`image.toml`)
//! and shades them with `ltm relight --brdf`, whose eye comes from the
//! file's surface records, against the same renders (`image_limit`).

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

/// The fixture's `meta.json`.
fn meta() -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(fixture().join("meta.json")).unwrap()).unwrap()
}

/// The interior mask of a `width`² view.
fn interior(width: usize) -> Vec<bool> {
    let (shape, interior) = ltm_testkit::read_npy_f32(&fixture().join("interior.npy"));
    assert_eq!(shape, [width, width]);
    let mask: Vec<bool> = interior.iter().map(|&m| m > 0.5).collect();
    assert!(mask.iter().filter(|&&m| m).count() > width * width / 10);
    mask
}

/// The error of `ours` against case `name`'s Mitsuba render over `mask`,
/// Mitsuba's noise removed in quadrature.
fn case_error(ours: &Image, case: &serde_json::Value, mask: &[bool], width: usize) -> f64 {
    let name = case["name"].as_str().unwrap();
    let (shape, reference) =
        ltm_testkit::read_npy_f32(&fixture().join(format!("mitsuba_{name}.npy")));
    assert_eq!(shape, [width, width, 3]);
    assert_eq!((ours.width, ours.height), (width, width));
    let e = masked_rel_l2(ours, &reference, mask);
    let noise = case["mitsuba_noise"].as_f64().unwrap();
    (e * e - noise * noise).max(0.0).sqrt()
}

#[test]
fn glossy_image_rows_match_mitsuba_on_a_sphere_under_a_sun() {
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n).to_str().unwrap().to_string();
    let (fx, meta) = (fixture(), meta());
    ltm(&[
        "bake",
        fx.join("image.toml").to_str().unwrap(),
        "-o",
        &p("i.raw"),
    ]);
    ltm(&["compress", &p("i.raw"), "-o", &p("i.ltm")]);
    let width = meta["width"].as_u64().unwrap() as usize;
    let mask = interior(width);
    let n = meta["glossy_n"].as_u64().unwrap().to_string();
    let env = fx.join("env.exr");
    let (file, cache) = (p("i.ltm"), p("rotations.bin"));
    let relight = |spec: &str, out: &str, extra: &[&str]| {
        let mut args = vec![
            "relight",
            &file,
            "--env",
            env.to_str().unwrap(),
            "--brdf",
            spec,
            "--shading",
            "glossy",
            "--glossy-n",
            &n,
            "--rotation-cache",
            &cache,
            "-o",
            out,
        ];
        args.extend(extra);
        let said = ltm(&args);
        Image::read_exr(Path::new(out)).map(|i| (i, said)).unwrap()
    };
    let mut failures = Vec::new();
    for case in meta["cases"].as_array().unwrap() {
        let (name, spec) = (
            case["name"].as_str().unwrap(),
            case["spec"].as_str().unwrap(),
        );
        let (ours, said) = relight(spec, &p(&format!("{name}.exr")), &[]);
        assert!(said.contains("eye recovered from"), "{said}");
        let e0 = case_error(&ours, case, &mask, width);
        let limit = case["image_limit"].as_f64().unwrap();
        println!(
            "image rows, {name} ({spec}): {:.2} %, limit {:.1} %",
            100.0 * e0,
            100.0 * limit
        );
        if e0 > limit {
            failures.push(format!("{name}: {e0:.4} > {limit}"));
        }
    }
    assert!(failures.is_empty(), "{failures:?}");
    // The recovered eye shades as the scene's own camera does.
    let spec = meta["cases"][0]["spec"].as_str().unwrap();
    let (recovered, _) = relight(spec, &p("recovered.exr"), &[]);
    let eye = vec3(&meta["camera"]["eye"]);
    let (given, said) = relight(spec, &p("given.exr"), &["--eye", &eye]);
    assert!(!said.contains("eye recovered"), "{said}");
    let (mut num, mut den) = (0.0f64, 0.0f64);
    for (a, b) in recovered.data.iter().zip(&given.data) {
        for c in 0..3 {
            num += f64::from(a[c] - b[c]).powi(2);
            den += f64::from(b[c]).powi(2);
        }
    }
    assert!(
        den > 0.0 && (num / den).sqrt() < 1e-5,
        "{}",
        (num / den).sqrt()
    );
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
