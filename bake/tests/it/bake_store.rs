//! Baking into the raw store: the default scene, resuming, output hygiene.

use crate::common;

use common::*;
use ltm_bake::{bake, raw_header, BakeOptions, BlockBaker, Overrides, Scene, SceneDesc};
use ltm_codec::{Progress, RawStore, RawWriter, Stage, Step};
use std::sync::atomic::{AtomicU64, Ordering};

fn small_default(width: u32, height: u32, face_res: u32) -> Scene {
    let mut desc = SceneDesc::default_scene(&assets()).expect("default scene");
    desc.apply(&Overrides {
        width: Some(width),
        height: Some(height),
        face_res: Some(face_res),
        ..Default::default()
    })
    .unwrap();
    Scene::build(&desc).expect("default scene builds")
}

#[test]
fn default_scene_bakes_into_a_valid_store() {
    let scene = small_default(64, 64, 8);
    assert_eq!(scene.channels(), 3, "the teapot is glossy");
    let stats = scene.stats();
    assert_eq!(stats.meshes.len(), 2);
    assert_eq!(stats.meshes[0].triangles, 75_408, "bunny.ply");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("default.raw");
    let calls = AtomicU64::new(0);
    let report = bake(
        &scene,
        &out,
        &BakeOptions {
            block_bytes: 1 << 20,
        },
        Progress::new(&|s: Step| {
            calls.fetch_add(1, Ordering::Relaxed);
            assert!(s.done <= s.total && s.total == 64 * 64);
            assert!(matches!(s.stage, Stage::Bake { .. }));
        }),
    )
    .unwrap();
    assert_eq!(calls.load(Ordering::Relaxed), 64 * 64);
    assert_eq!(report.rows_baked, 64 * 64);
    assert_eq!(report.blocks_resumed, 0);
    assert!(report.rays.shadow_rays > 0);
    assert!(!dir.path().join("default.raw.partial").exists());

    let store = RawStore::open(&out).unwrap();
    let d = store.dims();
    assert_eq!(
        (d.width(), d.height(), d.face_res(), d.channels),
        (64, 64, 8, 3)
    );
    assert!(store.albedo().is_none());
    for b in 0..store.header().block_count() {
        store.verify_block(b).unwrap();
    }
    // The top rows see the sky behind the scene: zero rows, flagged.
    assert!(store.is_zero_row(0) && store.read_row(0).unwrap().iter().all(|&v| v == 0.0));
    // The bottom rows see the lit ground.
    let p = 63 * 64 + 32;
    assert!(!store.is_zero_row(p));
    let row = store.read_row(p).unwrap();
    assert!(row.iter().all(|v| v.is_finite() && *v >= 0.0));
    let rgb: Vec<f64> = (0..3)
        .map(|c| row.iter().skip(c).step_by(3).map(|&v| v as f64).sum())
        .collect();
    // The ground's albedo is (0.55, 0.55, 0.52); under white light it
    // reflects at most that.
    assert!(rgb[0] > 0.3 && rgb[0] <= 0.56, "{rgb:?}");
    assert!(rgb[2] < rgb[0]);
}

#[test]
fn resumed_bake_is_byte_identical() {
    let scene = small_default(24, 20, 4);
    let options = BakeOptions {
        block_bytes: 16 << 10,
    };
    let header = raw_header(&scene, options.block_bytes);
    assert!(header.block_count() >= 4, "{}", header.block_count());
    let dir = tempfile::tempdir().unwrap();
    let whole = dir.path().join("whole.raw");
    bake(&scene, &whole, &options, ltm_codec::Progress::NONE).unwrap();

    // Interrupt: write blocks 0, 1 and 3, then drop the writer.
    let resumed = dir.path().join("resumed.raw");
    let partial = dir.path().join("resumed.raw.partial");
    {
        let surface = ltm_bake::row_surface(&scene).unwrap();
        let mut w = RawWriter::create_with_surface(&resumed, header, Some(&surface)).unwrap();
        let baker = BlockBaker::new(&scene, header).unwrap();
        let (mut rows, mut albedo) = (Vec::new(), Vec::new());
        for b in [0, 1, 3] {
            baker.compute(b, &mut rows, &mut albedo, &|_| {});
            w.write_block(b, &rows, None).unwrap();
        }
    }
    assert!(partial.exists() && !resumed.exists());
    // Damage block 1's data as a crash mid-write would: it must be redone.
    let bytes = std::fs::read(&whole).unwrap();
    let mut part = std::fs::read(&partial).unwrap();
    let row_bytes = scene.dims().row_len() * 4;
    let data_start = part.len() - scene.dims().pixels() * row_bytes;
    let at = data_start + header.block_range(1).start * row_bytes + 100;
    part[at] ^= 0x55;
    std::fs::write(&partial, &part).unwrap();

    let report = bake(&scene, &resumed, &options, ltm_codec::Progress::NONE).unwrap();
    assert_eq!(report.blocks_resumed, 2, "blocks 0 and 3 kept, 1 redone");
    assert_eq!(
        report.rows_baked as usize,
        scene.dims().pixels() - header.block_range(0).len() - header.block_range(3).len()
    );
    assert!(
        std::fs::read(&resumed).unwrap() == bytes,
        "resumed file differs"
    );
    assert!(!partial.exists());
}

#[test]
fn grey_scene_stores_the_albedo_image() {
    let toml = scene_toml(
        CAMERA,
        LIGHTING,
        "[[quads]]\ncenter = [0.0, 0.0, 0.0]\nsize = [2.0, 2.0]\nmaterial = \"grey\"\n",
    );
    let (dir, r) = build(&toml, &[]);
    let scene = r.unwrap();
    let out = dir.path().join("grey.raw");
    bake(
        &scene,
        &out,
        &BakeOptions::default(),
        ltm_codec::Progress::NONE,
    )
    .unwrap();
    let store = RawStore::open(&out).unwrap();
    assert_eq!(store.dims().channels, 1);
    let albedo = store.albedo().expect("albedo image");
    // Centre pixel: on the quad; corner pixel (0, 0): beyond it.
    assert_eq!(&albedo[3 * 40..3 * 41], &[0.5, 0.5, 0.5]);
    assert_eq!(&albedo[..3], &[0.0, 0.0, 0.0]);
    assert!(store.is_zero_row(0));
}

#[test]
fn failed_bake_leaves_no_complete_output() {
    let scene = small_default(8, 8, 2);
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("missing-dir").join("x.raw");
    let err = bake(
        &scene,
        &out,
        &BakeOptions::default(),
        ltm_codec::Progress::NONE,
    )
    .unwrap_err();
    assert!(err.to_string().contains("missing-dir"), "{err}");
    assert!(!out.exists());
}

#[test]
fn sharded_bake_with_small_blocks_merges_to_the_whole() {
    // Blocks of a few rows, so that parts end inside blocks of the whole
    // store and one output block gathers rows of several parts.
    let scene = small_default(24, 20, 4);
    let options = BakeOptions {
        block_bytes: 16 << 10,
    };
    let dir = tempfile::tempdir().unwrap();
    let whole = dir.path().join("whole.raw");
    bake(&scene, &whole, &options, Progress::NONE).unwrap();
    let want = std::fs::read(&whole).unwrap();
    let rows = scene.dims().pixels() as u64;
    for n in [3u64, 7, 40] {
        let parts: Vec<std::path::PathBuf> = (0..n)
            .map(|i| {
                let path = dir.path().join(format!("part-{i}.raw"));
                let span = ltm_codec::RowSpan::shard(rows, i, n);
                let r = ltm_bake::bake_part(&scene, &path, &options, Some(span), Progress::NONE)
                    .unwrap();
                assert_eq!(r.rows_baked, span.len());
                path
            })
            .collect();
        let out = dir.path().join(format!("merged-{n}.raw"));
        let limits = ltm_codec::Limits::default();
        ltm_codec::raw::merge_parts(&parts, &out, &limits).unwrap();
        assert!(std::fs::read(&out).unwrap() == want, "{n} parts");
        assert_eq!(limits.used_bytes(), 0, "every charge given back");
    }
}
