//! Near-field light propagation and shading per receiving point
//! (`ltm_relight::nearfield`, Sun and Ramamoorthi 2009 §5.3), in points per
//! second: a 256² textured light at order 32 (the paper's wavelet order),
//! 4096 points at depths 0.1 to 3 light sizes, each with a transport row of
//! 30 % nonzero Haar coefficients, at the paper's operating point (1 % of
//! source and 20 % of target terms), at 5 % and 30 %, and at every term.
//!
//! Group `nearfield_rows` renders the same points as stored rows
//! ([`NearField::render`], every thread) by the exact method and by the
//! wavelet method at 1 % / 20 %, with the light 1 × 1 and 3 × 3 (it then
//! covers most of each point's face), in rows per second.
//!
//! Group `couplings_order32` lists every source's couplings at 4096 random
//! scales and offsets, in closed form and from the memory-based table
//! ([`AccTable`], 64 cells a width), in sources per second.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use ltm::relight::nearfield::{
    acc, transport_coefficients, AccTable, AreaLight, LightTexture, NearField, NearFieldMethod,
    NearFieldTerms, Placement, PlaneFace, Propagator, Receiver, SourceCoefficients, Targets,
};

const ORDER: usize = 32;
const POINTS: usize = 4096;

struct Xorshift(u64);

impl Xorshift {
    fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// A softbox: a bright disc with a soft edge and a darker grid over it.
fn texture() -> LightTexture {
    let side = 256;
    let texels = (0..side * side)
        .map(|j| {
            let (x, y) = (
                (j % side) as f32 / 256.0 - 0.5,
                (j / side) as f32 / 256.0 - 0.5,
            );
            let disc = (1.0 - (x * x + y * y).sqrt() * 2.2).clamp(0.0, 0.2) * 5.0;
            let grid = if (j % side) % 32 < 3 || (j / side) % 32 < 3 {
                0.2
            } else {
                1.0
            };
            let v = disc * grid;
            [v * 10.0, v * 9.0, v * 7.0]
        })
        .collect();
    LightTexture::new(side, side, texels).unwrap()
}

fn bench(c: &mut Criterion) {
    let mut rng = Xorshift(0x9e37_79b9_7f4a_7c15);
    let light = texture();
    let placement = Placement {
        center: [0.0; 2],
        size: [1.0; 2],
        intensity: 1.0,
    };
    let face = PlaneFace {
        order: ORDER,
        side: 4.0,
    };
    let points: Vec<Receiver> = (0..POINTS)
        .map(|_| Receiver {
            depth: 0.1 + 2.9 * rng.uniform(),
            position: [rng.uniform() * 4.0 - 2.0, rng.uniform() * 4.0 - 2.0],
        })
        .collect();
    let rows: Vec<Vec<(u32, f32)>> = (0..POINTS)
        .map(|_| {
            let t: Vec<f32> = (0..ORDER * ORDER).map(|_| rng.uniform() as f32).collect();
            let mut coefficients = transport_coefficients(&t, ORDER).unwrap();
            coefficients.sort_by(|a, b| b.1.abs().total_cmp(&a.1.abs()));
            coefficients.truncate(ORDER * ORDER * 3 / 10);
            coefficients.sort_by_key(|e| e.0);
            coefficients
        })
        .collect();
    let mut group = c.benchmark_group("nearfield_order32");
    group.throughput(Throughput::Elements(POINTS as u64));
    for (source, target) in [(0.01, 0.2), (0.05, 0.3), (1.0, 1.0)] {
        let keep = ((source * (ORDER * ORDER) as f64).ceil() as usize).max(1);
        let coefficients = SourceCoefficients::new(&light, &placement, ORDER, keep).unwrap();
        let targets = if target < 1.0 {
            Targets::Share(target)
        } else {
            Targets::All
        };
        let mut propagator = Propagator::new(face).unwrap();
        let name = format!(
            "source {:.0}%, target {:.0}%",
            source * 100.0,
            target * 100.0
        );
        group.bench_function(BenchmarkId::new("propagate_and_shade", name), |b| {
            b.iter(|| {
                let mut sum = 0.0;
                for (p, row) in points.iter().zip(&rows) {
                    propagator
                        .prepare(&coefficients, &placement, p, targets)
                        .unwrap();
                    sum += propagator.shade(row)[0];
                }
                sum
            })
        });
    }
    group.finish();
    stored_rows(c, &light, &points);
    couplings(c, &mut rng);
}

/// Every source's couplings at random `(s, o)`, both ways.
fn couplings(c: &mut Criterion, rng: &mut Xorshift) {
    let cases: Vec<(f64, f64)> = (0..POINTS)
        .map(|_| {
            let s = 10f64.powf(rng.uniform() * 2.0 - 0.5);
            (s, rng.uniform() * 1.4 - 0.2 - 0.5 * s)
        })
        .collect();
    let table = AccTable::new(ORDER, 64, &ltm::Limits::default()).unwrap();
    let mut group = c.benchmark_group("couplings_order32");
    group.throughput(Throughput::Elements((POINTS * ORDER) as u64));
    let mut out = Vec::new();
    group.bench_function("closed form", |b| {
        b.iter(|| {
            out.clear();
            for &(s, o) in &cases {
                (0..ORDER).for_each(|i| acc::couplings(i, ORDER, s, o, &mut out));
            }
            out.len()
        })
    });
    group.bench_function("table, 64 cells", |b| {
        b.iter(|| {
            out.clear();
            for &(s, o) in &cases {
                (0..ORDER).for_each(|i| table.couplings_where(i, s, o, |_| true, &mut out));
            }
            out.len()
        })
    });
    group.finish();
}

/// The stored-row path, both methods.
fn stored_rows(c: &mut Criterion, light: &LightTexture, points: &[Receiver]) {
    let mut rng = Xorshift(0x5151_2e2e_7a7a_0303);
    let basis = ltm::codec::PlaneBasis {
        origin: [0.0; 3],
        x_axis: [1.0, 0.0, 0.0],
        y_axis: [0.0, 0.0, 1.0],
        order: ORDER as u32,
        side: 4.0,
    };
    let mut rows = ltm::codec::PlaneRows::new(basis, 1).unwrap();
    for _ in points {
        let t: Vec<f32> = (0..ORDER * ORDER).map(|_| rng.uniform() as f32).collect();
        rows.push_texels(&t).unwrap();
    }
    let receivers = points.iter().copied().map(Some).collect();
    let near = NearField::new(rows, receivers, None, &ltm::Limits::default()).unwrap();
    let mut group = c.benchmark_group("nearfield_rows");
    group.throughput(Throughput::Elements(points.len() as u64));
    let wavelet = NearFieldMethod::Wavelet(NearFieldTerms {
        source: 0.01,
        targets: Targets::Share(0.2),
    });
    for side in [1.0, 3.0] {
        let lights = [AreaLight {
            texture: light.clone(),
            placement: Placement {
                center: [0.0; 2],
                size: [side; 2],
                intensity: 1.0,
            },
        }];
        for (name, method) in [
            ("exact", NearFieldMethod::Exact),
            ("wavelet 1%/20%", wavelet),
        ] {
            let id = BenchmarkId::new(format!("light {side}x{side}"), name);
            group.bench_function(id, |b| b.iter(|| near.render(&lights, method).unwrap()));
        }
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
