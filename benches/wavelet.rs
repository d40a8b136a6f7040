//! Wavelet filter bank: 2D forward and inverse, full depth and one step, on
//! a 512×512 image, in pixels per second.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use ltm::codec::wavelet::{self, max_levels};
use ltm::codec::Filter;

const SIDE: usize = 512;

fn image(seed: u64) -> Vec<f32> {
    let mut s = seed | 1;
    (0..SIDE * SIDE)
        .map(|_| {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 40) as f32 / (1u64 << 24) as f32
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let x = image(42);
    let mut work = vec![0.0; x.len()];
    let levels = max_levels(SIDE, SIDE);
    let mut group = c.benchmark_group("wavelet_512x512");
    group.throughput(Throughput::Elements((SIDE * SIDE) as u64));
    for filter in Filter::ALL {
        let mut data = x.clone();
        group.bench_function(BenchmarkId::new("forward_full", filter), |b| {
            b.iter(|| {
                data.copy_from_slice(&x);
                wavelet::forward(filter, &mut data, SIDE, SIDE, levels, &mut work).unwrap()
            })
        });
        group.bench_function(BenchmarkId::new("inverse_full", filter), |b| {
            b.iter(|| {
                data.copy_from_slice(&x);
                wavelet::inverse(filter, &mut data, SIDE, SIDE, levels, &mut work).unwrap()
            })
        });
        group.bench_function(BenchmarkId::new("forward_step", filter), |b| {
            b.iter(|| {
                wavelet::forward_step(filter, &mut data, SIDE, SIDE, SIDE, &mut work).unwrap()
            })
        });
        group.bench_function(BenchmarkId::new("inverse_step", filter), |b| {
            b.iter(|| {
                wavelet::inverse_step(filter, &mut data, SIDE, SIDE, SIDE, &mut work).unwrap()
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
