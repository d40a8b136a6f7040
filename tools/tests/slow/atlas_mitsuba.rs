//! Geometry relighting with the atlas layout against Mitsuba 3 (issue 30),
//! without Python: each folder of `tools/tests/fixtures/atlas_mitsuba/`
//! holds a scene (`scene.toml`, its mesh), the lighting (`env.exr`, a
//! lat-long map that is constant over each cubemap texel), Mitsuba's
//! `direct` render of one camera (`mitsuba.npy`), the receiver's pixel
//! coverage (`coverage.npy`) and `meta.json` (the camera, Mitsuba's noise).
//! `tools/validate/mitsuba_atlas.py --fixtures` made them; the folder's
//! README.md gives the command.
//!
//! The test bakes the scene with `parameterization = "atlas"`, compresses
//! it near-losslessly, draws the camera with `ltm render --terms all` and
//! checks the two measures of the script:
//! - shading: relative L2 over the pixels more than 1 px from a silhouette,
//!   Mitsuba's noise removed in quadrature, ≤ 3 % (issue 30), or the
//!   fixture's `shading_limit` where `meta.json` gives one with a
//!   `shading_limit_note` saying why;
//! - shape: pixels at least 2 px inside Mitsuba's object mask that ltm
//!   leaves empty, and ltm's pixels at least 2 px inside its own mask that
//!   Mitsuba's lacks, each ≤ 0.5 % of Mitsuba's eroded mask.

use ltm_relight::Image;
use std::path::{Path, PathBuf};

fn ltm(args: &[&str]) {
    let run = ltm_testkit::run(env!("CARGO_BIN_EXE_ltm"), args);
    assert!(run.ok, "{args:?}: {}", run.stderr);
}

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/atlas_mitsuba")
}

/// Pixels whose (2r+1)² neighbourhood lies wholly in `mask` (w × h).
fn erode(mask: &[bool], w: usize, h: usize, r: usize) -> Vec<bool> {
    (0..w * h)
        .map(|i| {
            let (x, y) = (i % w, i / w);
            x >= r
                && y >= r
                && x + r < w
                && y + r < h
                && (y - r..=y + r).all(|yy| (x - r..=x + r).all(|xx| mask[yy * w + xx]))
        })
        .collect()
}

fn meta(case: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(case.join("meta.json")).unwrap()).unwrap()
}

/// The figures of one fixture: (shading error with Mitsuba's noise
/// removed, raw shading error, missing, extra, IoU).
fn measure(case: &Path, out: &Path) -> (f64, f64, f64, f64, f64) {
    let meta = meta(case);
    let p = |n: &str| out.join(n).to_str().unwrap().to_string();
    let scene = case.join("scene.toml");
    ltm(&["bake", scene.to_str().unwrap(), "-o", &p("t.raw")]);
    ltm(&[
        "compress",
        &p("t.raw"),
        "-o",
        &p("t.ltm"),
        "--bits",
        "16",
        "--max-error",
        "0.001",
    ]);
    let cam = &meta["camera"];
    let v3 = |k: &str| {
        cam[k]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap().to_string())
            .collect::<Vec<_>>()
            .join(",")
    };
    let width = meta["width"].as_u64().unwrap() as usize;
    ltm(&[
        "render",
        &p("t.ltm"),
        "--env",
        case.join("env.exr").to_str().unwrap(),
        "--terms",
        "all",
        "--camera",
        &v3("eye"),
        "--target",
        &v3("target"),
        "--fov",
        &cam["fov"].as_f64().unwrap().to_string(),
        "--size",
        &format!("{width}x{width}"),
        "--supersample",
        "8",
        "-o",
        &p("view.exr"),
    ]);
    let ours = Image::read_exr(Path::new(&p("view.exr"))).unwrap();
    let (shape, reference) = ltm_testkit::read_npy_f32(&case.join("mitsuba.npy"));
    assert_eq!(shape, [width, width, 3]);
    let (shape, cov) = ltm_testkit::read_npy_f32(&case.join("coverage.npy"));
    assert_eq!(shape, [width, width]);
    assert_eq!((ours.width, ours.height), (width, width));
    // Shading over Mitsuba's wholly covered pixels whose 8 neighbours are too.
    let full: Vec<bool> = cov.iter().map(|&c| c >= 1.0).collect();
    let interior = erode(&full, width, width, 1);
    let (mut num, mut den) = (0.0f64, 0.0f64);
    for (i, _) in interior.iter().enumerate().filter(|(_, &m)| m) {
        for c in 0..3 {
            let r = reference[i * 3 + c] as f64;
            num += (ours.data[i][c] as f64 - r).powi(2);
            den += r * r;
        }
    }
    assert!(den > 0.0, "{}: no interior pixels", case.display());
    let e = (num / den).sqrt();
    let noise = meta["mitsuba_noise"].as_f64().unwrap();
    let e0 = (e * e - noise * noise).max(0.0).sqrt();
    // Shape: masks of any coverage (ltm's background is 0).
    let theirs: Vec<bool> = cov.iter().map(|&c| c > 0.0).collect();
    let mine: Vec<bool> = ours
        .data
        .iter()
        .map(|p| p.iter().sum::<f32>() > 0.0)
        .collect();
    let inner = erode(&theirs, width, width, 2);
    let n = inner.iter().filter(|&&m| m).count().max(1) as f64;
    let missing = inner.iter().zip(&mine).filter(|(&i, &m)| i && !m).count() as f64 / n;
    let mine_inner = erode(&mine, width, width, 2);
    let extra = mine_inner
        .iter()
        .zip(&theirs)
        .filter(|(&m, &t)| m && !t)
        .count() as f64
        / n;
    let both = theirs.iter().zip(&mine).filter(|(&t, &m)| t && m).count() as f64;
    let either = theirs.iter().zip(&mine).filter(|(&t, &m)| t || m).count() as f64;
    (e0, e, missing, extra, both / either.max(1.0))
}

#[test]
fn atlas_bakes_match_mitsuba_in_shading_and_shape() {
    let mut cases: Vec<PathBuf> = std::fs::read_dir(fixtures())
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.join("meta.json").is_file())
        .collect();
    cases.sort();
    assert!(!cases.is_empty(), "no fixtures in {}", fixtures().display());
    let mut failures = Vec::new();
    for case in &cases {
        let dir = tempfile::tempdir().unwrap();
        let (e0, e, missing, extra, iou) = measure(case, dir.path());
        let name = case.file_name().unwrap().to_string_lossy();
        println!(
            "{name}: shading {:.2} % ({:.2} % with Mitsuba's noise), missing {:.3} %, extra {:.3} %, IoU {iou:.4}",
            100.0 * e0,
            100.0 * e,
            100.0 * missing,
            100.0 * extra
        );
        let limit = meta(case)["shading_limit"].as_f64().unwrap_or(0.03);
        if e0 > limit || missing > 0.005 || extra > 0.005 {
            failures.push(format!(
                "{name}: shading {e0:.4} (limit {limit}), missing {missing:.4}, extra {extra:.4}"
            ));
        }
    }
    assert!(failures.is_empty(), "{failures:?}");
}
