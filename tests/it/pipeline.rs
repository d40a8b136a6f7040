//! The whole pipeline on the embedded default scene (bunny and glossy teapot
//! from assets/, small settings): bake → compress (every mode) → relight,
//! checked against the exact dense product T·L and against eq. 3.

use ltm::bake::{bake, BakeOptions, Overrides, Scene, SceneDesc};
use ltm::codec::compress::Mode;
use ltm::codec::compress::{compress, CodeOptions, CompressOptions, Target, TransposeOptions};
use ltm::codec::{Filter, RawStore};
use ltm::relight::{
    reference, relative_l2, EnvMap, Relight, Relighter, Request, Rotation, Weighting,
};
use std::path::{Path, PathBuf};

fn assets() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("assets")
}

/// Bakes the default scene at 40×32 pixels, n = 8, into `dir`.
fn bake_default(dir: &Path) -> PathBuf {
    let mut desc = SceneDesc::default_scene(&assets()).unwrap();
    desc.apply(&Overrides {
        width: Some(40),
        height: Some(32),
        face_res: Some(8),
        texel_samples: Some(4),
        spp: Some(1),
        ..Default::default()
    })
    .unwrap();
    let scene = Scene::build(&desc).unwrap();
    let raw = dir.join("scene.raw");
    bake(
        &scene,
        &raw,
        &BakeOptions::default(),
        ltm_codec::Progress::NONE,
    )
    .unwrap();
    raw
}

fn req(terms: usize, weighting: Weighting) -> Request {
    Request { terms, weighting }
}

fn light(n: usize, name: &str) -> Vec<[f32; 3]> {
    EnvMap::load(&assets().join("envmaps").join(name))
        .unwrap()
        .to_cubemap(n, &Rotation::IDENTITY)
}

#[test]
fn relighting_matches_the_dense_reference_and_eq3() {
    let dir = tempfile::tempdir().unwrap();
    let raw_path = bake_default(dir.path());
    let raw = RawStore::open(&raw_path).unwrap();
    let n = raw.dims().face_res() as usize;
    for env in ["interior.exr", "sunset.exr"] {
        let l = light(n, env);
        let exact = reference(&raw, &l).unwrap();
        for (mode, col_filter, row_filter) in [
            (Mode::TwoD, Filter::LeGall53, Filter::Haar),
            (Mode::FourD, Filter::Cdf97, Filter::D4),
            (Mode::Adaptive, Filter::LeGall53, Filter::Haar),
            (Mode::Adaptive, Filter::D6, Filter::D8),
        ] {
            let out = dir.path().join("scene.ltm");
            let opts = CompressOptions {
                transpose: TransposeOptions {
                    row_filter,
                    ..Default::default()
                },
                code: CodeOptions {
                    mode,
                    col_filter,
                    bits: 16,
                    target: Target::MaxError(2e-5),
                    ..Default::default()
                },
            };
            compress(&raw, &out, &opts, ltm_codec::Progress::NONE).unwrap();
            let relighter = Relighter::open(&out).unwrap();
            let mut bufs = relighter.frame().unwrap();
            relighter
                .relight(&l, &req(usize::MAX, Weighting::Unweighted), &mut bufs)
                .unwrap();
            let err = relative_l2(&bufs.image, &exact).unwrap();
            assert!(
                err <= 1e-4,
                "{env} {mode:?} {col_filter}/{row_filter}: relit error {err} against T·L"
            );
            assert!(bufs.image.first_non_finite().is_none());
            // The level-recursive sum equals eq. 3 (every column decoded alone).
            for (terms, weighting) in [
                (10, Weighting::Unweighted),
                (50, Weighting::Transport),
                (usize::MAX, Weighting::Area),
            ] {
                relighter
                    .relight(&l, &req(terms, weighting), &mut bufs)
                    .unwrap();
                let naive = relighter.relight_naive(&l, &req(terms, weighting)).unwrap();
                let diff = relative_l2(&bufs.image, &naive).unwrap();
                assert!(
                    diff <= 2e-6,
                    "{env} {mode:?} N={terms}: level-recursive vs eq. 3 differ by {diff}"
                );
            }
        }
    }
}

#[test]
fn more_terms_give_less_error_and_threads_agree() {
    let dir = tempfile::tempdir().unwrap();
    let raw_path = bake_default(dir.path());
    let raw = RawStore::open(&raw_path).unwrap();
    let l = light(raw.dims().face_res() as usize, "studio.exr");
    let exact = reference(&raw, &l).unwrap();
    let out = dir.path().join("scene.ltm");
    compress(
        &raw,
        &out,
        &CodeOptions {
            bits: 12,
            target: Target::MaxError(0.005),
            ..Default::default()
        }
        .into(),
        ltm_codec::Progress::NONE,
    )
    .unwrap();
    let relighter = Relighter::open(&out).unwrap();
    let mut bufs = relighter.frame().unwrap();
    let mut errors = Vec::new();
    for terms in [5, 50, 384] {
        relighter
            .relight(&l, &req(terms, Weighting::Transport), &mut bufs)
            .unwrap();
        errors.push(relative_l2(&bufs.image, &exact).unwrap());
    }
    assert!(
        errors[0] > errors[1] && errors[1] > errors[2],
        "errors by N: {errors:?}"
    );
    assert!(errors[2] < 0.01, "all terms: {}", errors[2]);
    // Two threads sharing one relighter give the same image.
    let images: Vec<_> = std::thread::scope(|s| {
        let hs: Vec<_> = (0..2)
            .map(|_| {
                s.spawn(|| {
                    let mut b = relighter.frame().unwrap();
                    relighter
                        .relight(&l, &req(50, Weighting::Unweighted), &mut b)
                        .unwrap();
                    b.image
                })
            })
            .collect();
        hs.into_iter().map(|h| h.join().unwrap()).collect()
    });
    assert_eq!(images[0], images[1]);
    // The multiply-add's split into pixel ranges follows the pool's thread
    // count; every pixel is still summed in the same order.
    let frame = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let mut b = relighter.frame().unwrap();
            relighter
                .relight(&l, &req(384, Weighting::Transport), &mut b)
                .unwrap();
            b.image
        })
    };
    assert_eq!(frame(1), frame(3));
}

#[test]
fn bad_lighting_is_an_error_and_large_n_is_clamped() {
    let dir = tempfile::tempdir().unwrap();
    let raw_path = bake_default(dir.path());
    let raw = RawStore::open(&raw_path).unwrap();
    let out = dir.path().join("scene.ltm");
    compress(
        &raw,
        &out,
        &CompressOptions::default(),
        ltm_codec::Progress::NONE,
    )
    .unwrap();
    let relighter = Relighter::open(&out).unwrap();
    let mut bufs = relighter.frame().unwrap();
    let m = relighter.lights();
    assert!(relighter
        .relight(
            &vec![[1.0; 3]; m - 1],
            &req(10, Weighting::Unweighted),
            &mut bufs
        )
        .is_err());
    let mut nan = vec![[1.0; 3]; m];
    nan[3] = [f32::NAN, 0.0, 0.0];
    assert!(relighter
        .relight(&nan, &req(10, Weighting::Unweighted), &mut bufs)
        .is_err());
    let l = vec![[0.5; 3]; m];
    let a = relighter
        .relight(&l, &req(m, Weighting::Unweighted), &mut bufs)
        .unwrap();
    let img = bufs.image.clone();
    let b = relighter
        .relight(&l, &req(10 * m, Weighting::Unweighted), &mut bufs)
        .unwrap();
    assert_eq!(img, bufs.image);
    assert_eq!(a.lights, b.lights);
}
