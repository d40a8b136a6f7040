//! Kernels of the pipeline on the default scene (64×64 pixels, n = 16,
//! baked once into a temporary directory): a relighting frame at several N
//! (throughput: coefficients multiply-added), decoding one column (pixels),
//! resampling an environment map to the cubemap (map pixels) and the row
//! transform of the lighting (lights).

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use ltm::bake::{bake, BakeOptions, Overrides, Scene, SceneDesc};
use ltm::codec::compress::{compress, row_forward, CompressOptions, Target};
use ltm::codec::container::Mode;
use ltm::codec::{ColumnDecoder, Filter, RawStore};
use ltm::relight::{EnvMap, Relighter, Rotation, Weighting};
use std::path::Path;

fn bench(c: &mut Criterion) {
    let dir = tempfile::tempdir().unwrap();
    let assets = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets");
    let mut desc = SceneDesc::default_scene(&assets).unwrap();
    desc.apply(&Overrides {
        width: Some(64),
        height: Some(64),
        face_res: Some(16),
        ..Default::default()
    })
    .unwrap();
    let raw_path = dir.path().join("scene.raw");
    bake(
        &Scene::build(&desc).unwrap(),
        &raw_path,
        &BakeOptions::default(),
        &|_| {},
    )
    .unwrap();
    let raw = RawStore::open(&raw_path).unwrap();
    let env = EnvMap::load(&assets.join("envmaps/interior.exr")).unwrap();
    let light = env.to_cubemap(16, &Rotation::IDENTITY);

    let relighters: Vec<(Mode, Relighter)> = [Mode::Adaptive, Mode::TwoD]
        .into_iter()
        .map(|mode| {
            let path = dir.path().join(format!("{}.ltm", mode.name()));
            let opts = CompressOptions {
                mode,
                bits: 12,
                target: Target::MaxError(0.01),
                ..Default::default()
            };
            compress(&raw, &path, &opts, &|_, _, _| {}).unwrap();
            (mode, Relighter::open(&path).unwrap())
        })
        .collect();

    let mut group = c.benchmark_group("relight_frame");
    for (mode, relighter) in &relighters {
        let mut bufs = relighter.buffers();
        for n in [50, 200, 1000] {
            let nnz = relighter
                .relight(&light, n, Weighting::Transport, &mut bufs)
                .unwrap()
                .nonzeros;
            group.throughput(Throughput::Elements(nnz));
            group.bench_function(BenchmarkId::new(mode.name(), n), |b| {
                b.iter(|| {
                    relighter
                        .relight(&light, n, Weighting::Transport, &mut bufs)
                        .unwrap()
                })
            });
        }
    }
    group.finish();

    let file = relighters[0].1.file();
    let decoder = ColumnDecoder::new(file.meta());
    let j = (0..file.columns().len())
        .max_by_key(|&j| file.columns()[j].nnz)
        .unwrap();
    let col = file.column(j).unwrap();
    let (mut plane, mut work) = (vec![0.0; 64 * 64], vec![0.0; 64 * 64]);
    let mut g = c.benchmark_group("decode_column");
    g.throughput(Throughput::Elements(64 * 64));
    g.bench_function(
        format!("depth{}_nnz{}", col.depth, col.indices.len()),
        |b| b.iter(|| decoder.decode(&col, 0, &mut plane, &mut work).unwrap()),
    );
    g.finish();

    let mut g = c.benchmark_group("light");
    g.throughput(Throughput::Elements((env.width() * env.height()) as u64));
    g.bench_function("resample_1024x512_to_n16", |b| {
        b.iter(|| env.to_cubemap(16, &Rotation::new(30.0, 10.0, 0.0)))
    });
    let plane: Vec<f32> = light.iter().map(|l| l[1]).collect();
    let (mut x, mut work) = (plane.clone(), vec![0.0; 256]);
    g.throughput(Throughput::Elements(plane.len() as u64));
    g.bench_function("row_transform_haar_n16", |b| {
        b.iter(|| {
            x.copy_from_slice(&plane);
            row_forward(Filter::Haar, 16, &mut x, &mut work).unwrap()
        })
    });
    g.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20);
    targets = bench
}
criterion_main!(benches);
