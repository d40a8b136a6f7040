//! Wavelet rotation's two steps (`ltm_relight::rotation`, Wang et al. 2006
//! §3) at the CLI's settings, n = 64 (N = 64²) and n = 128, 32² normals,
//! GGX α = 0.2, BRDF keep 0.1, local keep 0.1:
//!
//! - group `rotation_lighting` (a lighting change): the cubemap projected
//!   onto the octahedral map (16 × 16 samples per texel, as `ltm render`
//!   does), then step 1 (`R(n)·L` for every grid normal, with the largest
//!   local terms listed), in lighting changes per second;
//! - group `rotation_view` (a view change): step 2 for 256² texels on a
//!   sphere, in texels per second, at the default keeps and at fewer BRDF
//!   and local-lighting terms; each three ways: `direct` (no pair table:
//!   every (grid normal, view texel) pair computed where it is used),
//!   `new_view` (a new, empty pair table before each view: a view with
//!   nothing to reuse) and `orbit` (a view 1° about the vertical from the
//!   one before, whose pairs the table keeps: a step of a viewer's drag);
//!   and each with both view filters (`Nearest`: one view texel per grid
//!   normal; `Bilinear`, the default: four).
//!
//! The goals are 10 lighting changes per second at N = 64² and a
//! view change at 60 frames/s (3.9 M texels/s) for 256² texels.

use criterion::measurement::WallTime;
use criterion::{
    criterion_group, criterion_main, BenchmarkGroup, BenchmarkId, Criterion, Throughput,
};
use ltm::codec::SurfacePoint;
use ltm::relight::rotation::{
    Brdf, BrdfSlices, OctMap, RotationConfig, RotationSet, Shader, SliceConfig, ViewFilter,
};
use ltm::Limits;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// (BRDF keep, local keep) pairs of step 2: the defaults, and fewer terms.
const KEEPS: [(f64, f64); 3] = [(0.1, 0.1), (0.03, 0.1), (0.03, 0.03)];

/// Texture side: 256² texels.
const SIDE: usize = 256;

/// A sky with a sun and two lamps, on a cubemap of face resolution `n`.
fn cubemap(n: usize) -> Vec<[f32; 3]> {
    let sun = glam::Vec3::new(0.4, 0.8, 0.3).normalize();
    let lamp = glam::Vec3::new(-0.7, 0.2, -0.6).normalize();
    (0..6 * n * n)
        .map(|j| {
            let d = ltm::codec::cubemap::texel_direction(n, j);
            let sky = 0.3 + 0.2 * d.y.max(0.0);
            let s = if d.dot(sun) > 0.9994 { 5e3 } else { 0.0 };
            let l = if d.dot(lamp) > 0.99 { 60.0 } else { 0.0 };
            [sky + s + l, sky + 0.9 * s + l, sky + 0.8 * s + 0.7 * l]
        })
        .collect()
}

/// `SIDE²` points of a unit sphere (a latitude–longitude grid).
fn sphere() -> Vec<SurfacePoint> {
    (0..SIDE * SIDE)
        .map(|k| {
            let theta = std::f32::consts::PI * ((k / SIDE) as f32 + 0.5) / SIDE as f32;
            let phi = std::f32::consts::TAU * ((k % SIDE) as f32 + 0.5) / SIDE as f32;
            let p = [
                theta.sin() * phi.cos(),
                theta.cos(),
                theta.sin() * phi.sin(),
            ];
            SurfacePoint::new(p, p)
        })
        .collect()
}

/// `eye` turned by 1° about the vertical axis: an orbit's next view.
fn orbit(eye: glam::DVec3) -> glam::DVec3 {
    glam::DQuat::from_rotation_y(1f64.to_radians()) * eye
}

fn bench(c: &mut Criterion) {
    let limits = Limits::default();
    let brdf = Brdf::Ggx {
        alpha: 0.2,
        f0: [0.9; 3],
    };
    let points = sphere();
    let eye = glam::DVec3::new(0.4, 1.0, 3.0);
    for n in [64usize, 128] {
        let cfg = RotationConfig {
            n,
            ..RotationConfig::default()
        };
        let set = Arc::new(RotationSet::build(cfg, &limits).unwrap());
        let sc = SliceConfig {
            m: n / 2,
            keep: 0.1,
            ..SliceConfig::default()
        };
        let slices = Arc::new(BrdfSlices::build(brdf.clone(), sc, &limits).unwrap());
        let mut shader = Shader::new(set, slices, &limits).unwrap();
        shader.set_local_keep(0.1, &limits).unwrap();
        let cube = cubemap(n);
        let mut group = c.benchmark_group("rotation_lighting");
        group.sample_size(10);
        group.throughput(Throughput::Elements(1));
        group.bench_function(BenchmarkId::new("project_and_step1", n), |b| {
            b.iter(|| {
                let map = OctMap::from_cubemap(n, 16, n, &cube).unwrap();
                shader.light(&map, None).unwrap();
            })
        });
        let map = OctMap::from_cubemap(n, 16, n, &cube).unwrap();
        group.bench_function(BenchmarkId::new("step1", n), |b| {
            b.iter(|| shader.light(&map, None).unwrap())
        });
        group.finish();
        let mut group = c.benchmark_group("rotation_view");
        group.sample_size(10);
        group.throughput(Throughput::Elements(points.len() as u64));
        for (keep, local) in KEEPS {
            let sc = SliceConfig { keep, ..sc };
            let slices = Arc::new(BrdfSlices::build(brdf.clone(), sc, &limits).unwrap());
            shader.set_brdf(slices).unwrap();
            shader.set_local_keep(local, &limits).unwrap();
            shader.light(&map, None).unwrap();
            for filter in [ViewFilter::Nearest, ViewFilter::Bilinear] {
                shader.set_view_filter(filter);
                view_change(
                    &mut group,
                    &mut shader,
                    (n, keep, local, filter),
                    (&points, eye),
                );
            }
        }
        group.finish();
    }
}

/// Step 2 for `points` from `eye` three ways (see the module doc).
fn view_change(
    group: &mut BenchmarkGroup<'_, WallTime>,
    shader: &mut Shader,
    (n, keep, local, filter): (usize, f64, f64, ViewFilter),
    (points, eye): (&[SurfacePoint], glam::DVec3),
) {
    let mut out = vec![[0.0f32; 3]; points.len()];
    let id = |how: &str| format!("step2_256x256_keep{keep}_local{local}_{filter:?}_{how}");
    shader.set_pair_table(false);
    group.bench_function(BenchmarkId::new(id("direct"), n), |b| {
        b.iter(|| shader.shade_points(points, eye, &mut out).unwrap())
    });
    group.bench_function(BenchmarkId::new(id("new_view"), n), |b| {
        b.iter_custom(|iters| {
            let mut total = Duration::ZERO;
            for _ in 0..iters {
                assert!(shader.set_pair_table(true));
                let start = Instant::now();
                shader.shade_points(points, eye, &mut out).unwrap();
                total += start.elapsed();
            }
            total
        })
    });
    group.bench_function(BenchmarkId::new(id("orbit"), n), |b| {
        b.iter_custom(|iters| {
            let mut total = Duration::ZERO;
            for _ in 0..iters {
                assert!(shader.set_pair_table(true));
                shader.shade_points(points, eye, &mut out).unwrap();
                let start = Instant::now();
                shader.shade_points(points, orbit(eye), &mut out).unwrap();
                total += start.elapsed();
            }
            total
        })
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
