//! The `pca` mode's frame against the machine's streaming bound, in one run:
//! - `pca_dot/K`: the dot-product part of a frame with the first `K`
//!   eigen-transports of `LTM_BENCH_PCA` (a `pca` `.ltm` file, e.g. the
//!   default scene at 256² with `--rank 256`; without it, a rank-64 file of
//!   the 64×64 scene made here), timed from the frames' own split;
//!   throughput in coefficient bytes read (2 per pixel and component used);
//! - `pca_dot/stream_probe`: a parallel read of a 256 MiB buffer, the bound
//!   those bytes are compared with.

mod common;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use ltm::codec::{compress_pca, Limits, PcaOptions, RawStore};
use ltm::relight::{EnvMap, PcaRelighter, Relight, Request, Rotation, Weighting};

fn pca_dot(c: &mut Criterion) {
    let dir = tempfile::tempdir().unwrap();
    let path = match std::env::var_os("LTM_BENCH_PCA") {
        Some(path) => path.into(),
        None => {
            let raw = RawStore::open(&common::small_scene(dir.path())).unwrap();
            let path = dir.path().join("scene.ltm");
            let opts = PcaOptions {
                rank: Some(64),
                ..Default::default()
            };
            compress_pca(&raw, &path, &opts, ltm_codec::Progress::NONE).unwrap();
            path
        }
    };
    let relighter = PcaRelighter::open_with_limits(&path, &Limits::default()).unwrap();
    let env = EnvMap::load(&common::assets().join("envmaps/interior.exr")).unwrap();
    let n = (relighter.lights() as f64 / 6.0).sqrt() as usize;
    let light = env.to_cubemap(n, &Rotation::IDENTITY);
    let mut frame = relighter.frame().unwrap();
    let mut group = c.benchmark_group("pca_dot");
    for k in [16, 48, 128, 256] {
        if k > relighter.rank() {
            continue;
        }
        let request = Request {
            terms: k,
            weighting: Weighting::Transport,
        };
        group.throughput(Throughput::Bytes(relighter.coefficient_bytes(k) as u64));
        let id = BenchmarkId::from_parameter(k);
        common::bench_multiply(&mut group, id, &relighter, &light, &request, &mut frame);
    }
    common::stream_probe(&mut group);
    group.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20);
    targets = pca_dot
}
criterion_main!(benches);
