//! Wavelet filter bank: 2D forward and inverse, full depth and one step, on
//! a 512×512 image, in pixels per second. `rgb_inverse_256`: a relighting
//! frame's inverse column steps (every level of a 256×256 RGB image, LeGall
//! 5/3 and D4) as three single-plane steps per level against one step of
//! the interleaved `[r, g, b, 0]` pixels (a four-lane `PlaneMut`), and as a
//! frame runs them (`frame_steps`: the row-skipping steps, every row live,
//! the last into a second buffer).

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use ltm::codec::wavelet::{self, max_levels, PlaneMut, RowMode};
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
                let plane = PlaneMut::image(&mut data, SIDE, SIDE, 1).unwrap();
                wavelet::forward_step(filter, plane, &mut work).unwrap()
            })
        });
        group.bench_function(BenchmarkId::new("inverse_step", filter), |b| {
            b.iter(|| {
                let plane = PlaneMut::image(&mut data, SIDE, SIDE, 1).unwrap();
                wavelet::inverse_step(filter, plane, &mut work, RowMode::Dense).unwrap()
            })
        });
    }
    group.finish();
}

fn rgb_inverse(c: &mut Criterion) {
    const S: usize = 256;
    let levels = max_levels(S, S);
    let planes: Vec<Vec<f32>> = (0..3).map(|k| image(7 + k)[..S * S].to_vec()).collect();
    let pixels: Vec<f32> = (0..S * S * 4)
        .map(|i| {
            if i % 4 == 3 {
                0.0
            } else {
                planes[i % 4][i / 4]
            }
        })
        .collect();
    let mut work = vec![0.0; 4 * S * S];
    let mut group = c.benchmark_group("rgb_inverse_256");
    group.throughput(Throughput::Elements((S * S) as u64));
    for filter in [Filter::LeGall53, Filter::D4] {
        let mut data = planes.clone();
        group.bench_function(BenchmarkId::new("three_planes", filter), |b| {
            b.iter(|| {
                for (d, p) in data.iter_mut().zip(&planes) {
                    d.copy_from_slice(p);
                    for level in (0..levels).rev() {
                        let (w, h) = wavelet::band_size(S, S, level);
                        let plane = PlaneMut::new(d, S, w, h, 1).unwrap();
                        wavelet::inverse_step(filter, plane, &mut work, RowMode::Dense).unwrap();
                    }
                }
            })
        });
        let mut inter = pixels.clone();
        group.bench_function(BenchmarkId::new("interleaved", filter), |b| {
            b.iter(|| {
                inter.copy_from_slice(&pixels);
                for level in (0..levels).rev() {
                    let (w, h) = wavelet::band_size(S, S, level);
                    let plane = PlaneMut::new(&mut inter, S, w, h, 4).unwrap();
                    wavelet::inverse_step(filter, plane, &mut work, RowMode::Dense).unwrap();
                }
            })
        });
        // As a relighting frame runs them: the row-skipping steps (every row
        // live here; lifting filters in strips, the last step into a second
        // buffer).
        let mut flags = vec![true; S];
        let mut out = pixels.clone();
        group.bench_function(BenchmarkId::new("frame_steps", filter), |b| {
            b.iter(|| {
                inter.copy_from_slice(&pixels);
                flags.fill(true);
                for level in (1..levels).rev() {
                    let (w, h) = wavelet::band_size(S, S, level);
                    let plane = PlaneMut::new(&mut inter, S, w, h, 4).unwrap();
                    let rows = RowMode::sparse(&mut flags);
                    wavelet::inverse_step(filter, plane, &mut work, rows).unwrap();
                }
                let plane = PlaneMut::image(&mut inter, S, S, 4).unwrap();
                if filter.is_lifting() {
                    let rows = RowMode::sparse_into(&mut flags, &mut out);
                    wavelet::inverse_step(filter, plane, &mut [], rows).unwrap();
                } else {
                    let rows = RowMode::sparse(&mut flags);
                    wavelet::inverse_step(filter, plane, &mut work, rows).unwrap();
                }
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench, rgb_inverse);
criterion_main!(benches);
