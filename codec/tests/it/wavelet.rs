//! The wavelet filter bank against PyWavelets fixtures, perfect
//! reconstruction, energy, vanishing moments and random sizes.

use ltm_codec::wavelet::{self, band_size, max_levels, PlaneMut, RowMode};
use ltm_codec::Filter;
use proptest::prelude::*;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::Path;

#[derive(Deserialize)]
struct Band {
    shape: Vec<usize>,
    data: Vec<f64>,
}

#[derive(Deserialize)]
struct Fixture {
    wavelet: String,
    kind: String,
    shape: Vec<usize>,
    levels: u32,
    dec_lo: Vec<f64>,
    x: Vec<f64>,
    bands: BTreeMap<String, Band>,
}

fn filter_for(pywt_name: &str) -> Filter {
    match pywt_name {
        "haar" => Filter::Haar,
        "db2" => Filter::D4,
        "db3" => Filter::D6,
        "db4" => Filter::D8,
        "bior2.2" => Filter::LeGall53,
        "bior4.4" => Filter::Cdf97,
        other => panic!("fixture for unknown wavelet {other}"),
    }
}

fn fixtures() -> Vec<(String, Fixture)> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/pywt");
    let mut out = Vec::new();
    for entry in std::fs::read_dir(&dir).expect("fixture directory") {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "json") {
            let text = std::fs::read_to_string(&path).unwrap();
            let fx: Fixture = serde_json::from_str(&text).unwrap();
            out.push((path.file_name().unwrap().to_string_lossy().into_owned(), fx));
        }
    }
    out.sort_by(|a, b| a.0.cmp(&b.0));
    assert!(
        out.len() >= 50,
        "expected the committed PyWavelets fixtures"
    );
    out
}

/// PyWavelets' coefficient = factor × ours, per axis: orthonormal filters
/// match exactly; lifting filters have cA = √2·low and cD = −high/√2.
fn axis_factor(filter: Filter, detail: bool) -> f64 {
    match (filter.is_orthonormal(), detail) {
        (true, _) => 1.0,
        (false, false) => std::f64::consts::SQRT_2,
        (false, true) => -std::f64::consts::FRAC_1_SQRT_2,
    }
}

/// Band entries the boundary handling may change: the lifting filters use
/// symmetric extension, PyWavelets' `periodization` a periodic one.
fn boundary_margin(filter: Filter) -> usize {
    match filter {
        Filter::LeGall53 => 1,
        Filter::Cdf97 => 2,
        _ => 0,
    }
}

#[test]
fn orthonormal_taps_match_pywavelets() {
    for (name, fx) in fixtures() {
        let filter = filter_for(&fx.wavelet);
        if let Some(taps) = filter.orthonormal_taps() {
            assert_eq!(taps.len(), fx.dec_lo.len(), "{name}");
            for (a, b) in taps.iter().zip(&fx.dec_lo) {
                assert!((a - b).abs() < 1e-10, "{name}: tap {a} vs {b}");
            }
        }
    }
}

#[test]
fn conforms_to_pywavelets() {
    let mut checked = 0;
    for (name, fx) in fixtures() {
        let filter = filter_for(&fx.wavelet);
        let (height, width) = match fx.kind.as_str() {
            "dwt" => (1, fx.shape[0]),
            _ => (fx.shape[0], fx.shape[1]),
        };
        let mut data: Vec<f32> = fx.x.iter().map(|&v| v as f32).collect();
        let mut work = vec![0.0; data.len()];
        wavelet::forward(filter, &mut data, width, height, fx.levels, &mut work).unwrap();
        let margin = boundary_margin(filter);
        for (key, band) in &fx.bands {
            // Which Mallat region holds this band: (level step, axis-0 detail, axis-1 detail).
            let (step, d0, d1) = match (fx.kind.as_str(), key.as_str()) {
                ("dwt", "a") => (0, false, false),
                ("dwt", "d") => (0, false, true),
                ("dwt2", k) => (0, &k[0..1] == "d", &k[1..2] == "d"),
                ("wavedec2", "a") => (fx.levels - 1, false, false),
                ("wavedec2", k) => {
                    let coarse_rank: u32 = k[1..2].parse().unwrap();
                    (fx.levels - coarse_rank, &k[3..4] == "d", &k[4..5] == "d")
                }
                other => panic!("{name}: unexpected band {other:?}"),
            };
            let (w, h) = band_size(width, height, step);
            let (lw, lh) = (w.div_ceil(2), h.div_ceil(2));
            let (x0, y0) = (
                if d1 { lw } else { 0 },
                if d0 && height > 1 { lh } else { 0 },
            );
            let (bh, bw) = if band.shape.len() == 1 {
                (1, band.shape[0])
            } else {
                (band.shape[0], band.shape[1])
            };
            let factor = if height > 1 {
                axis_factor(filter, d0)
            } else {
                1.0
            } * axis_factor(filter, d1);
            let scale = band.data.iter().fold(1e-12f64, |m, v| m.max(v.abs()));
            for by in 0..bh {
                for bx in 0..bw {
                    let interior = |i: usize, n: usize| n == 1 || (i >= margin && i + margin < n);
                    if !interior(by, bh) || !interior(bx, bw) {
                        continue;
                    }
                    let ours = data[(y0 + by) * width + x0 + bx] as f64 * factor;
                    let theirs = band.data[by * bw + bx];
                    assert!(
                        (ours - theirs).abs() <= 1e-5 * scale,
                        "{name} band {key} at ({by},{bx}): ours {ours} pywt {theirs}"
                    );
                    checked += 1;
                }
            }
        }
    }
    assert!(checked > 10_000, "only {checked} coefficients compared");
}

fn noise(n: usize, seed: u64) -> Vec<f32> {
    let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    (0..n)
        .map(|_| {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
        })
        .collect()
}

fn roundtrip_error(filter: Filter, width: usize, height: usize, levels: u32, x: &[f32]) -> f32 {
    let mut data = x.to_vec();
    let mut work = vec![0.0; x.len()];
    wavelet::forward(filter, &mut data, width, height, levels, &mut work).unwrap();
    wavelet::inverse(filter, &mut data, width, height, levels, &mut work).unwrap();
    let peak = x.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    let err = data
        .iter()
        .zip(x)
        .fold(0.0f32, |m, (a, b)| m.max((a - b).abs()));
    err / peak.max(f32::MIN_POSITIVE)
}

const SIZES: [(usize, usize); 10] = [
    (640, 480),
    (97, 61),
    (1, 37),
    (37, 1),
    (1, 1),
    (2, 2),
    (3, 5),
    (64, 64),
    (512, 3),
    (1, 1024),
];

#[test]
fn perfect_reconstruction_every_filter_size_and_depth() {
    for filter in Filter::ALL {
        for (i, &(w, h)) in SIZES.iter().enumerate() {
            let x = noise(w * h, i as u64 + 1);
            let max = max_levels(w, h);
            for levels in [0, 1.min(max), max / 2, max] {
                let err = roundtrip_error(filter, w, h, levels, &x);
                assert!(
                    err <= 1e-5,
                    "{filter} {w}x{h} levels {levels}: relative error {err}"
                );
            }
        }
    }
}

#[test]
fn orthonormal_filters_preserve_energy() {
    for filter in Filter::ALL.into_iter().filter(|f| f.is_orthonormal()) {
        for (i, &(w, h)) in SIZES.iter().enumerate() {
            let mut x = noise(w * h, 100 + i as u64);
            let e0: f64 = x.iter().map(|&v| (v as f64).powi(2)).sum();
            let mut work = vec![0.0; x.len()];
            wavelet::forward(filter, &mut x, w, h, max_levels(w, h), &mut work).unwrap();
            let e1: f64 = x.iter().map(|&v| (v as f64).powi(2)).sum();
            assert!(
                (e1 - e0).abs() <= 1e-5 * e0,
                "{filter} {w}x{h}: energy {e0} -> {e1}"
            );
        }
    }
}

/// Detail coefficients of one step on a 1D polynomial of degree below the
/// filter's vanishing moments vanish away from the boundary.
#[test]
fn vanishing_moments() {
    let n = 64;
    for filter in Filter::ALL {
        for degree in 0..filter.vanishing_moments() as i32 {
            let x: Vec<f32> = (0..n)
                .map(|k| {
                    let t = k as f64 / n as f64 - 0.3;
                    (0.7 + (0..=degree).map(|d| t.powi(d)).sum::<f64>()) as f32
                })
                .collect();
            let mut data = x.clone();
            let mut work = vec![0.0; n];
            wavelet::forward(filter, &mut data, n, 1, 1, &mut work).unwrap();
            let high = &data[n / 2..];
            // Periodic filters wrap the first taps around; lifting filters
            // reflect at both ends.
            let taps = filter.orthonormal_taps().map_or(4, |t| t.len() / 2);
            for (i, d) in high.iter().enumerate().take(n / 2 - taps).skip(taps) {
                assert!(
                    d.abs() < 2e-5,
                    "{filter} degree {degree}: detail[{i}] = {d}"
                );
            }
        }
    }
}

/// The row-vector vertical pass agrees with the scalar 1D path applied to
/// gathered columns.
#[test]
fn separable_step_matches_scalar_rows_then_columns() {
    for filter in Filter::ALL {
        for &(w, h) in &[(97, 61), (640, 480), (2, 9), (8, 1), (1, 8)] {
            let x = noise(w * h, 7);
            let mut step = x.clone();
            let mut work = vec![0.0; w * h];
            let plane = PlaneMut::image(&mut step, w, h, 1).unwrap();
            wavelet::forward_step(filter, plane, &mut work).unwrap();

            let mut naive = x.clone();
            let mut tmp = vec![0.0; w.max(h)];
            if w >= 2 {
                for row in naive.chunks_mut(w) {
                    wavelet::forward_1d(filter, row, 1, &mut tmp).unwrap();
                }
            }
            if h >= 2 {
                let mut col = vec![0.0; h];
                for c in 0..w {
                    for r in 0..h {
                        col[r] = naive[r * w + c];
                    }
                    wavelet::forward_1d(filter, &mut col, 1, &mut tmp).unwrap();
                    for r in 0..h {
                        naive[r * w + c] = col[r];
                    }
                }
            }
            let err = step
                .iter()
                .zip(&naive)
                .fold(0.0f32, |m, (a, b)| m.max((a - b).abs()));
            assert!(
                err <= 1e-5,
                "{filter} {w}x{h}: 2D step vs 1D rows/columns differ by {err}"
            );
        }
    }
}

#[test]
fn single_steps_compose_to_full_transform_inside_a_larger_image() {
    // A step on a sub-region must leave the rest of the image untouched.
    let (w, h) = (33, 20);
    for filter in Filter::ALL {
        let x = noise(w * h, 9);
        let mut data = x.clone();
        let mut work = vec![0.0; w * h];
        let (rw, rh) = band_size(w, h, 1);
        let plane = PlaneMut::new(&mut data, w, rw, rh, 1).unwrap();
        wavelet::forward_step(filter, plane, &mut work).unwrap();
        for y in 0..h {
            for xx in 0..w {
                if y >= rh || xx >= rw {
                    assert_eq!(data[y * w + xx], x[y * w + xx]);
                }
            }
        }
        let plane = PlaneMut::new(&mut data, w, rw, rh, 1).unwrap();
        wavelet::inverse_step(filter, plane, &mut work, RowMode::Dense).unwrap();
        let err = data
            .iter()
            .zip(&x)
            .fold(0.0f32, |m, (a, b)| m.max((a - b).abs()));
        assert!(err < 1e-5, "{filter}: {err}");
    }
}

#[test]
fn bad_arguments_are_errors() {
    let mut data = vec![0.0; 16];
    let mut work = vec![0.0; 16];
    assert!(wavelet::forward(Filter::Haar, &mut data, 4, 4, 3, &mut work).is_err());
    assert!(wavelet::forward(Filter::Haar, &mut data, 4, 5, 1, &mut work).is_err());
    assert!(wavelet::forward(Filter::Haar, &mut data, 4, 4, 1, &mut work[..8]).is_err());
    assert!(PlaneMut::new(&mut data, 2, 4, 4, 1).is_err());
    assert!(PlaneMut::new(&mut data, 4, 0, 4, 1).is_err());
    assert!(PlaneMut::new(&mut data, 4, 4, 4, 0).is_err());
    assert!(PlaneMut::new(&mut data, 4, 4, 4, 2).is_err());
    assert!(PlaneMut::new(&mut data, usize::MAX / 2, 4, 4, 1).is_err());
    /// A step of the region `w` × 4 of a 4 × 4 image.
    fn step(
        data: &mut [f32],
        w: usize,
        work: &mut [f32],
        rows: RowMode<'_>,
    ) -> ltm_codec::Result<()> {
        let plane = PlaneMut::new(data, 4, w, 4, 1).unwrap();
        wavelet::inverse_step(Filter::Haar, plane, work, rows)
    }
    let (mut flags, mut out) = (vec![true; 4], vec![0.0; 16]);
    assert!(step(&mut data, 4, &mut work[..15], RowMode::Dense).is_err());
    assert!(step(&mut data, 4, &mut work, RowMode::sparse(&mut flags[..3])).is_err());
    let into = RowMode::sparse_into(&mut flags, &mut out[..15]);
    assert!(step(&mut data, 4, &mut [], into).is_err());
    let into = RowMode::sparse_into(&mut flags, &mut out);
    assert!(step(&mut data, 2, &mut [], into).is_err());
    let into = RowMode::sparse_into(&mut flags, &mut out);
    assert!(step(&mut data, 4, &mut [], into).is_ok());
    let plane = PlaneMut::new(&mut data, 2, 2, 2, 4).unwrap();
    assert!(wavelet::forward_step(Filter::Haar, plane, &mut work).is_err());
    assert_eq!(max_levels(1, 1), 0);
    assert_eq!(max_levels(640, 480), 10);
    assert_eq!(max_levels(97, 61), 7);
    assert_eq!(band_size(97, 61, 1), (49, 31));
}

#[test]
fn filter_names_and_codes_round_trip() {
    for f in Filter::ALL {
        assert_eq!(f.name().parse::<Filter>().unwrap(), f);
        assert_eq!(Filter::from_code(f.code()), Some(f));
    }
    assert!("db9".parse::<Filter>().is_err());
    assert_eq!(Filter::from_code(200), None);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]
    #[test]
    fn random_sizes_levels_and_filters_reconstruct(
        w in 1usize..70, h in 1usize..70, fi in 0usize..6, seed in any::<u64>(), lv in 0u32..16,
    ) {
        let filter = Filter::ALL[fi];
        let levels = lv.min(max_levels(w, h));
        let x = noise(w * h, seed);
        let err = roundtrip_error(filter, w, h, levels, &x);
        prop_assert!(err <= 1e-5, "{} {}x{} levels {}: {}", filter, w, h, levels, err);
    }
}

/// `inverse_step` on a plane of interleaved images gives every image exactly
/// the bits it gives the image alone: every filter, odd and even sizes,
/// 1 to 4 lanes, strides wider than the region, values over 1e-6..1e5, and
/// a region larger than the parallel threshold.
#[test]
fn interleaved_inverse_steps_match_single_images_bit_for_bit() {
    let mut seed = 0x1234_5678_9abc_def1u64;
    let mut next = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        seed
    };
    for filter in Filter::ALL {
        for (stride, w, h) in [
            (1, 1, 1),
            (7, 5, 3),
            (9, 9, 9),
            (16, 16, 1),
            (13, 1, 7),
            (300, 300, 257),
        ] {
            for lanes in 1..=4 {
                let images: Vec<Vec<f32>> = (0..lanes)
                    .map(|_| {
                        (0..stride * h)
                            .map(|_| {
                                let r = next();
                                let mag = 10f32.powf((r % 1100) as f32 / 100.0 - 6.0);
                                let v = if r % 7 == 0 { 0.0 } else { mag };
                                if r & (1 << 20) != 0 {
                                    -v
                                } else {
                                    v
                                }
                            })
                            .collect()
                    })
                    .collect();
                let mut inter: Vec<f32> = (0..stride * h * lanes)
                    .map(|i| images[i % lanes][i / lanes])
                    .collect();
                let mut work = vec![0.0; stride * h * lanes];
                let plane = PlaneMut::new(&mut inter, stride, w, h, lanes).unwrap();
                wavelet::inverse_step(filter, plane, &mut work, RowMode::Dense).unwrap();
                for (c, image) in images.iter().enumerate() {
                    let mut single = image.clone();
                    let plane = PlaneMut::new(&mut single, stride, w, h, 1).unwrap();
                    wavelet::inverse_step(filter, plane, &mut work, RowMode::Dense).unwrap();
                    for (i, v) in single.iter().enumerate() {
                        assert_eq!(
                            v.to_bits(),
                            inter[i * lanes + c].to_bits(),
                            "{filter} {w}x{h} stride {stride}, lane {c} of {lanes}, sample {i}"
                        );
                    }
                }
            }
        }
    }
}

/// The row-skipping inverse steps equal the dense ones as f32 values (`==`:
/// a skipped row may be `+0.0` where the dense step gives `−0.0`) through
/// every level of a full inverse, for every filter, odd and even sizes,
/// 1, 3 and 4 lanes, with runs of zero rows (none, some, all but one, all),
/// exact and conservative flags, and the scratch poisoned with NaN so that
/// a skipped row that was read would show. Flags stay conservative: a row
/// marked zero is zero. The last step is also run into a second buffer
/// (poisoned too) with [`RowMode::sparse_into`].
#[test]
fn row_skipping_inverse_steps_equal_the_dense_ones() {
    let mut seed = 0x0bad_cafe_1234_5678u64;
    let mut next = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        seed
    };
    for filter in Filter::ALL {
        for (w, h) in [
            (1, 1),
            (5, 3),
            (9, 9),
            (33, 17),
            (13, 1),
            (1, 7),
            (64, 64),
            (300, 257),
        ] {
            for lanes in [1, 3, 4] {
                for pattern in 0..5 {
                    let mut flags: Vec<bool> = match pattern {
                        0 => vec![true; h],
                        1 => vec![false; h],
                        2 => (0..h).map(|y| y == h / 2).collect(),
                        _ => (0..h).map(|y| (y / 3 + pattern) % 4 == 0).collect(),
                    };
                    let mut data: Vec<f32> = (0..w * h * lanes)
                        .map(|i| {
                            let r = next();
                            let mag = 10f32.powf((r % 1100) as f32 / 100.0 - 6.0);
                            let v = if r % 7 == 0 { 0.0 } else { mag };
                            let v = if r & (1 << 20) != 0 { -v } else { v };
                            if flags[i / (w * lanes)] {
                                v
                            } else if r % 2 == 0 {
                                -0.0
                            } else {
                                0.0
                            }
                        })
                        .collect();
                    if pattern == 4 {
                        // Conservative flags: zero rows marked live too.
                        flags.iter_mut().step_by(2).for_each(|f| *f = true);
                    }
                    let mut dense = data.clone();
                    let mut work = vec![0.0; w * h * lanes];
                    for level in (0..max_levels(w, h)).rev() {
                        let (bw, bh) = band_size(w, h, level);
                        let plane = PlaneMut::new(&mut dense, w, bw, bh, lanes).unwrap();
                        wavelet::inverse_step(filter, plane, &mut work, RowMode::Dense).unwrap();
                        work.fill(f32::NAN);
                        if level == 0 {
                            // The whole image, into a second buffer.
                            let mut into_flags = flags.clone();
                            let mut scratch = data.clone();
                            let mut out = vec![f32::NAN; data.len()];
                            let plane = PlaneMut::image(&mut scratch, w, h, lanes).unwrap();
                            let rows = RowMode::sparse_into(&mut into_flags, &mut out);
                            wavelet::inverse_step(filter, plane, &mut [], rows).unwrap();
                            // The messages are formatted only on failure (a
                            // string per sample made this test take 30 s).
                            for (i, (a, b)) in dense.iter().zip(&out).enumerate() {
                                let what = || {
                                    format!("into: {filter} {w}x{h} {lanes} lanes, pattern {pattern}, sample {i}")
                                };
                                assert!(a == b, "{}: dense {a} vs into {b}", what());
                                assert!(
                                    into_flags[i / (w * lanes)] || *b == 0.0,
                                    "{}: flagged zero",
                                    what()
                                );
                            }
                        }
                        let plane = PlaneMut::new(&mut data, w, bw, bh, lanes).unwrap();
                        let rows = RowMode::sparse(&mut flags);
                        wavelet::inverse_step(filter, plane, &mut work, rows).unwrap();
                        for (i, (a, b)) in dense.iter().zip(&data).enumerate() {
                            let what = || {
                                format!("{filter} {w}x{h} {lanes} lanes, pattern {pattern}, level {level}, sample {i}")
                            };
                            assert!(a == b, "{}: dense {a} vs skipping {b}", what());
                            assert!(
                                flags[i / (w * lanes)] || *b == 0.0,
                                "{}: flagged zero",
                                what()
                            );
                        }
                    }
                }
            }
        }
    }
}
