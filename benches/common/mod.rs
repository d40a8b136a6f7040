//! Set-up shared by the benches: the small default scene and the streaming
//! probe that kernels are compared with.

use criterion::measurement::WallTime;
use criterion::{BenchmarkGroup, BenchmarkId, Throughput};
use ltm::bake::{bake, BakeOptions, Overrides, Scene, SceneDesc};
use ltm::relight::{Frame, Relight, Request};
use rayon::prelude::*;
use std::path::{Path, PathBuf};

/// The repository's `assets/` folder.
pub fn assets() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("assets")
}

/// Bakes the default scene at 64×64 pixels, n = 16, into `dir/scene.raw`.
pub fn small_scene(dir: &Path) -> PathBuf {
    let mut desc = SceneDesc::default_scene(&assets()).unwrap();
    desc.apply(&Overrides {
        width: Some(64),
        height: Some(64),
        face_res: Some(16),
        ..Default::default()
    })
    .unwrap();
    let raw_path = dir.join("scene.raw");
    let scene = Scene::build(&desc).unwrap();
    bake(
        &scene,
        &raw_path,
        &BakeOptions::default(),
        ltm_codec::Progress::NONE,
    )
    .unwrap();
    raw_path
}

/// `stream_probe`: a parallel read of a 256 MiB buffer of `u64` (summed),
/// the streaming bound a kernel's bytes are compared with in the same run.
pub fn stream_probe(group: &mut BenchmarkGroup<'_, WallTime>) {
    let probe: Vec<u64> = (0..(256u64 << 20) / 8).collect();
    group.throughput(Throughput::Bytes(8 * probe.len() as u64));
    group.bench_function("stream_probe", |b| {
        b.iter(|| {
            probe
                .par_chunks(1 << 16)
                .map(|c| c.iter().fold(0u64, |a, &v| a.wrapping_add(v)))
                .reduce(|| 0, u64::wrapping_add)
        })
    });
}

/// Benchmarks the multiply part of `relighter`'s frames under `light` (the
/// frames' own split of their time, summed over the iterations).
pub fn bench_multiply(
    group: &mut BenchmarkGroup<'_, WallTime>,
    id: BenchmarkId,
    relighter: &dyn Relight,
    light: &[[f32; 3]],
    request: &Request,
    frame: &mut Frame,
) {
    group.bench_function(id, |b| {
        b.iter_custom(|iters| {
            (0..iters)
                .map(|_| relighter.relight(light, request, frame).unwrap().multiply)
                .sum()
        })
    });
}
