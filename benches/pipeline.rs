//! Kernels of the pipeline on the default scene (64×64 pixels, n = 16,
//! baked once into a temporary directory): a relighting frame at several N
//! (throughput: coefficients multiply-added), decoding one column (pixels),
//! resampling an environment map to the cubemap (map pixels) and the row
//! transform of the lighting (lights).
//!
//! The `quantize` group times the column quantizer on its own, on a
//! synthetic 256×256 single-channel column image (smooth shading with a hard
//! shadow edge plus noise), LeGall 5/3–transformed to depth 4 and
//! band-weighted as the coder does, at 12 bits with the largest 10 % of the
//! coefficients kept:
//! - `code_column`: threshold, per-scale-group peaks and stored scales, then
//!   dither-quantize the kept coefficients with the coder's quantizer
//!   (`quant::quantize`; throughput: image coefficients);
//! - `encode_payload`: varint serialization and zstd of the quantized column
//!   (`EncodedColumn::new`, default level; throughput: kept coefficients);
//! - `parse_payload`: `SparseColumn::from_payload` on the plain payload
//!   (kept coefficients);
//! - `range_encode/encodingE`, `range_decode/encodingE`: the range-coded
//!   column payloads of encodings 3 and 4 (`entropy::encode`/`decode`;
//!   kept coefficients);
//! - `dequantize_unweight`: `ColumnDecoder::accumulate` into a cleared plane
//!   then `unweight`, i.e. decoding without the inverse transform (image
//!   coefficients);
//! - `decode_column`: the same plus the four inverse steps (image
//!   coefficients), for comparison.

mod common;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use ltm::codec::column::EncodedColumn;
use ltm::codec::compress::Mode;
use ltm::codec::compress::{compress, CodeOptions, Target};
use ltm::codec::entropy::{self, ColumnShape, ValueCoding};
use ltm::codec::quant::{self, scale_groups, BandWeights};
use ltm::codec::wavelet::{self, row_forward};
use ltm::codec::{ColumnDecoder, Dims, Filter, Limits, Meta, RawStore, SparseColumn};
use ltm::relight::{EnvMap, PrefilteredMap, Relight, Relighter, Request, Rotation, Weighting};
use std::time::Duration;

fn bench(c: &mut Criterion) {
    let dir = tempfile::tempdir().unwrap();
    let raw = RawStore::open(&common::small_scene(dir.path())).unwrap();
    let env = EnvMap::load(&common::assets().join("envmaps/interior.exr")).unwrap();
    let light = env.to_cubemap(16, &Rotation::IDENTITY);

    let relighters: Vec<(Mode, Relighter)> = [Mode::Adaptive, Mode::TwoD]
        .into_iter()
        .map(|mode| {
            let path = dir.path().join(format!("{}.ltm", mode.name()));
            let opts = CodeOptions {
                mode,
                bits: 12,
                target: Target::MaxError(0.01),
                ..Default::default()
            };
            compress(&raw, &path, &opts.into(), ltm_codec::Progress::NONE).unwrap();
            let relighter = Relighter::open(&path).unwrap();
            relighter.decode_all().unwrap();
            (mode, relighter)
        })
        .collect();

    let mut group = c.benchmark_group("relight_frame");
    for (mode, relighter) in &relighters {
        let mut bufs = relighter.frame().unwrap();
        for n in [50, 200, 1000] {
            let request = Request {
                terms: n,
                weighting: Weighting::Transport,
            };
            let nnz = relighter
                .relight(&light, &request, &mut bufs)
                .unwrap()
                .nonzeros;
            group.throughput(Throughput::Elements(nnz));
            group.bench_function(BenchmarkId::new(mode.name(), n), |b| {
                b.iter(|| relighter.relight(&light, &request, &mut bufs).unwrap())
            });
        }
    }
    group.finish();

    let file = relighters[0].1.file();
    let decoder = ColumnDecoder::new(file.meta(), &Limits::default()).unwrap();
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
    // The viewer's drag: exact against draft resampling at n = 32.
    g.bench_function("resample_1024x512_to_n32", |b| {
        b.iter(|| env.to_cubemap(32, &Rotation::new(30.0, 10.0, 0.0)))
    });
    let prefiltered = PrefilteredMap::new(&env, 32);
    g.bench_function("draft_resample_1024x512_to_n32", |b| {
        b.iter(|| prefiltered.to_cubemap(&Rotation::new(30.0, 10.0, 0.0)))
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

/// A `w` × `h` column image: smooth shading, a hard shadow edge and a
/// highlight, plus uniform noise of ±1 %.
fn column_image(w: usize, h: usize, seed: u64) -> Vec<f32> {
    let mut s = seed | 1;
    (0..w * h)
        .map(|k| {
            let (x, y) = ((k % w) as f32 / w as f32, (k / w) as f32 / h as f32);
            let shade = 0.6 + 0.3 * (6.0 * x).sin() * (4.0 * y).cos();
            let shadow = if x + 0.3 * y > 0.6 { 1.0 } else { 0.35 };
            let highlight = 0.8 * (-((x - 0.3).powi(2) + (y - 0.6).powi(2)) / 0.01).exp();
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            let noise = ((s >> 40) as f32 / (1u64 << 24) as f32 - 0.5) * 0.02;
            shade * shadow + highlight + noise
        })
        .collect()
}

/// Keeps positions with `u² ≥ tau_sq` of one channel of weighted
/// coefficients and quantizes them with the coder's default quantizer (the
/// uniform one, its step tied to τ).
fn code_column(
    coefs: &[f32],
    groups: &[u8],
    depth: u32,
    tau_sq: f64,
    bits: u32,
    seed: u64,
    j: u32,
) -> SparseColumn {
    let kept: Vec<u32> = (0..coefs.len() as u32)
        .filter(|&i| {
            let e = (coefs[i as usize] as f64).powi(2);
            e >= tau_sq && e > 0.0
        })
        .collect();
    let how = quant::Quantization {
        bits,
        step: CodeOptions::default()
            .quantizer
            .step(tau_sq, 1)
            .map(|s| s as f32),
        dither: quant::Dither { seed, column: j },
    };
    quant::quantize(coefs, 1, &kept, groups, depth, how)
}

fn quantize(c: &mut Criterion) {
    const W: usize = 256;
    const H: usize = 256;
    const DEPTH: u32 = 4;
    const BITS: u32 = 12;
    const P: usize = W * H;
    let opts = CodeOptions::default();
    let filter = Filter::LeGall53;
    let image = column_image(W, H, 0x5eed);
    let weights = BandWeights::new(filter, W, H, DEPTH, &Limits::default()).unwrap();
    let mut coefs = image.clone();
    let mut work = vec![0.0f32; P];
    wavelet::forward(filter, &mut coefs, W, H, DEPTH, &mut work).unwrap();
    for (v, m) in coefs.iter_mut().zip(weights.map(DEPTH)) {
        *v *= m;
    }
    let groups = scale_groups(W, H, DEPTH);
    // τ² keeping the largest 10 % of the coefficients.
    let mut energy: Vec<f64> = coefs.iter().map(|&v| (v as f64).powi(2)).collect();
    let keep = P / 10;
    let tau_sq = *energy.select_nth_unstable_by(P - keep, f64::total_cmp).1;
    let col = code_column(&coefs, &groups, DEPTH, tau_sq, BITS, opts.seed, 0);
    let nnz = col.indices.len();

    let meta = Meta {
        dims: Dims::image(W as u32, H as u32, 16, 1),
        mode: Mode::Adaptive,
        row_filter: Filter::Haar,
        col_filter: filter,
        bits: BITS,
        seed: opts.seed,
        target_error: 0.01,
        achieved_error: 0.0,
        terms: 0,
        norm: 1.0,
    };
    let decoder = ColumnDecoder::new(&meta, &Limits::default()).unwrap();
    let mut plane = vec![0.0f32; P];
    decoder.decode(&col, 0, &mut plane, &mut work).unwrap();
    let err = plane
        .iter()
        .zip(&image)
        .map(|(a, b)| ((a - b) as f64).powi(2))
        .sum::<f64>()
        .sqrt()
        / image
            .iter()
            .map(|&v| (v as f64).powi(2))
            .sum::<f64>()
            .sqrt();
    assert!(err < 0.05, "relative error {err}");
    let payload = col.to_payload(1);
    let encoded = EncodedColumn::new(&col, 1, opts.zstd_level);
    println!(
        "quantize: {W}x{H} depth {DEPTH}, {BITS} bits: {nnz} of {P} coefficients kept, \
         relative L2 error {err:.4}, payload {} B, stored {} B ({:?})",
        payload.len(),
        encoded.bytes.len(),
        encoded.entry.encoding
    );

    let mut g = c.benchmark_group("quantize");
    // Microsecond kernels: short windows are plenty.
    g.warm_up_time(Duration::from_secs(1));
    g.measurement_time(Duration::from_secs(2));
    g.throughput(Throughput::Elements(P as u64));
    g.bench_function(format!("code_column/{W}x{H}_d{DEPTH}_b{BITS}"), |b| {
        b.iter(|| code_column(&coefs, &groups, DEPTH, tau_sq, BITS, opts.seed, 0))
    });
    g.throughput(Throughput::Elements(nnz as u64));
    g.bench_function(format!("encode_payload/nnz{nnz}"), |b| {
        b.iter(|| EncodedColumn::new(&col, 1, opts.zstd_level))
    });
    g.bench_function(format!("parse_payload/nnz{nnz}"), |b| {
        b.iter(|| SparseColumn::from_payload(&payload, nnz, 1, P, BITS, DEPTH).unwrap())
    });
    let shape = ColumnShape {
        width: W,
        height: H,
        channels: 1,
        bits: BITS,
    };
    for (encoding, coding) in [(3, ValueCoding::ExpGolomb), (4, ValueCoding::Classes)] {
        let bytes = entropy::encode(&col, &shape, coding).unwrap();
        g.bench_function(format!("range_encode/encoding{encoding}/nnz{nnz}"), |b| {
            b.iter(|| entropy::encode(&col, &shape, coding).unwrap())
        });
        let id = format!("range_decode/encoding{encoding}/nnz{nnz}_{}B", bytes.len());
        g.bench_function(id, |b| {
            b.iter(|| entropy::decode(&bytes, nnz, &shape, DEPTH, coding, None).unwrap())
        });
    }
    g.throughput(Throughput::Elements(P as u64));
    g.bench_function(format!("dequantize_unweight/nnz{nnz}"), |b| {
        b.iter(|| {
            plane.fill(0.0);
            decoder.accumulate(&col, 0, 1.0, &mut plane);
            decoder.unweight(col.depth, &mut plane);
        })
    });
    g.bench_function(format!("decode_column/nnz{nnz}"), |b| {
        b.iter(|| decoder.decode(&col, 0, &mut plane, &mut work).unwrap())
    });
    g.finish();
}

/// The multiply-add against the machine's streaming bound, in one run:
/// - `multiply_add/MODE-KERNEL/N`: the multiply-add part of relighting frames of
///   `LTM_BENCH_LTM` (a `.ltm` file, e.g. the default scene at 256²; without
///   it, 2d and adaptive files of the 64×64 scene made here), timed from the
///   frames' own split; throughput in bytes of arena entries streamed (8 per
///   RGB coefficient, 4 per grey one), so bytes ÷ 8 is coefficients; once
///   per kernel the CPU runs (`scalar`, `sse4.1`, `avx2+fma`);
/// - `multiply_add/stream_probe`: a parallel read of a 256 MiB buffer of
///   `u64` (summed), the streaming bound those bytes are compared with.
fn multiply_add(c: &mut Criterion) {
    let dir = tempfile::tempdir().unwrap();
    let files: Vec<(String, std::path::PathBuf)> = match std::env::var_os("LTM_BENCH_LTM") {
        Some(path) => vec![("file".into(), path.into())],
        None => {
            let raw = RawStore::open(&common::small_scene(dir.path())).unwrap();
            [Mode::TwoD, Mode::Adaptive]
                .into_iter()
                .map(|mode| {
                    let path = dir.path().join(format!("{}.ltm", mode.name()));
                    let opts = CodeOptions {
                        mode,
                        bits: 12,
                        target: Target::MaxError(0.01),
                        ..Default::default()
                    };
                    compress(&raw, &path, &opts.into(), ltm_codec::Progress::NONE).unwrap();
                    (mode.name().to_string(), path)
                })
                .collect()
        }
    };
    let env = EnvMap::load(&common::assets().join("envmaps/interior.exr")).unwrap();
    let mut group = c.benchmark_group("multiply_add");
    for (name, path) in &files {
        let mut relighter = Relighter::open(path).unwrap();
        relighter.decode_all().unwrap();
        let light = env.to_cubemap(
            relighter.meta().dims.face_res() as usize,
            &Rotation::IDENTITY,
        );
        let entry_bytes = 2 * (relighter.meta().dims.channels as u64 + 1);
        let mut frame = relighter.frame().unwrap();
        for n in [200, 1000, 5000] {
            let request = Request {
                terms: n,
                weighting: Weighting::Transport,
            };
            let nnz = relighter
                .relight(&light, &request, &mut frame)
                .unwrap()
                .nonzeros;
            group.throughput(Throughput::Bytes(nnz * entry_bytes));
            for kernel in Relighter::kernels() {
                relighter.set_kernel(kernel).unwrap();
                let id = BenchmarkId::new(format!("{name}-{kernel}"), n);
                common::bench_multiply(&mut group, id, &relighter, &light, &request, &mut frame);
            }
        }
    }
    common::stream_probe(&mut group);
    group.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20);
    targets = bench, quantize, multiply_add
}
criterion_main!(benches);
