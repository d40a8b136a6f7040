//! The PCA mode (Eigentransport) end to end through the public API: the
//! error a file records is the error of what `decode_matrix` returns,
//! against an exact dense SVD; ranks and targets outside the valid range;
//! corrupted payloads; version-1 files still open.

use ltm_codec::compress::{compress, CompressOptions};
use ltm_codec::compress::{compress_pca, PcaOptions};
use ltm_codec::npy::decode_matrix;
use ltm_codec::{Dims, Limits, LtmFile, Mode, RawStore};
use ltm_testkit::{block_bytes, write_raw, Rng};

/// A matrix with a large mean row, a decaying spectrum of 8 smooth
/// components and a little noise; every ninth pixel is zero.
pub fn matrix(d: Dims, seed: u64) -> Vec<f32> {
    let (p, n) = (d.pixels(), d.row_len());
    let mut rng = Rng(seed);
    let mean: Vec<f64> = (0..n)
        .map(|i| 1.0 + 0.5 * (i as f64 * 0.01).sin())
        .collect();
    let comps: Vec<(Vec<f64>, Vec<f64>)> = (0..8)
        .map(|a| {
            let s = 0.6f64.powi(a);
            let u = (0..p).map(|_| s * (rng.uniform() - 0.5)).collect();
            let v = (0..n)
                .map(|i| ((i as f64 + 1.0) * 0.07 * (a + 1) as f64).cos())
                .collect();
            (u, v)
        })
        .collect();
    let mut t = vec![0.0f32; p * n];
    for px in (0..p).filter(|px| px % 9 != 4) {
        for i in 0..n {
            let x: f64 = mean[i] + comps.iter().map(|(u, v)| u[px] * v[i]).sum::<f64>();
            t[px * n + i] = (x + 1e-4 * (rng.uniform() - 0.5)) as f32;
        }
    }
    t
}

fn rel(a: &[f32], b: &[f32]) -> f64 {
    let num: f64 = a
        .iter()
        .zip(b)
        .map(|(x, y)| (*x as f64 - *y as f64).powi(2))
        .sum();
    let den: f64 = b.iter().map(|y| (*y as f64).powi(2)).sum();
    (num / den).sqrt()
}

/// Singular values of the centred dense matrix (exact, faer's SVD).
fn centred_singular_values(t: &[f32], p: usize, n: usize) -> Vec<f64> {
    let mut mean = vec![0.0f64; n];
    for row in t.chunks_exact(n) {
        mean.iter_mut()
            .zip(row)
            .for_each(|(m, &v)| *m += v as f64 / p as f64);
    }
    let a = faer::Mat::<f64>::from_fn(p, n, |r, i| t[r * n + i] as f64 - mean[i]);
    a.as_ref().singular_values().unwrap()
}

#[test]
fn recorded_error_is_the_decoded_error_and_near_optimal() {
    let dir = tempfile::tempdir().unwrap();
    for (d, albedo) in [
        (Dims::image(13, 11, 2, 3), false),
        (Dims::image(16, 9, 4, 1), true),
    ] {
        let t = matrix(d, 5);
        let a: Vec<f32> = (0..3 * d.pixels())
            .map(|i| 0.2 + (i % 7) as f32 * 0.1)
            .collect();
        let raw_path = write_raw(
            &dir.path().join("t.raw"),
            d,
            &t,
            albedo.then_some(&a[..]),
            block_bytes(d, 5),
        );
        let raw = RawStore::open(&raw_path).unwrap();
        let norm2: f64 = t.iter().map(|&v| v as f64 * v as f64).sum();
        let sv = centred_singular_values(&t, d.pixels(), d.row_len());
        for k in [1, 3, 6, 9] {
            for bits in [8, 12, 16] {
                let out = dir.path().join("t.ltm");
                let opts = PcaOptions {
                    rank: Some(k),
                    bits,
                    raise_bits: false,
                    ..Default::default()
                };
                let stats = compress_pca(&raw, &out, &opts, ltm_codec::Progress::NONE).unwrap();
                let file = LtmFile::open(&out).unwrap();
                assert_eq!(file.meta().mode, Mode::Pca);
                assert_eq!(file.pca().unwrap().rank(), k);
                assert_eq!(file.albedo().is_some(), albedo);
                let decoded = decode_matrix(&file, &Limits::default()).unwrap();
                let measured = rel(&decoded, &t);
                // The file records the error of exactly what decoders return.
                assert!(
                    (measured - stats.achieved_error).abs() <= 1e-6 * measured.max(1e-9),
                    "{measured} vs {}",
                    stats.achieved_error
                );
                assert!(
                    (file.meta().achieved_error as f64 - measured).abs()
                        <= 1e-6 * measured.max(1e-6) + 1e-9
                );
                // Rank alone: the optimal rank-k error of the centred matrix.
                let optimal = (sv[k..].iter().map(|s| s * s).sum::<f64>() / norm2).sqrt();
                assert!(
                    stats.predicted_error >= optimal * (1.0 - 1e-6)
                        && stats.predicted_error <= optimal * 1.02 + 1e-7,
                    "rank {k}: {} vs optimal {optimal}",
                    stats.predicted_error
                );
                if bits == 16 {
                    assert!(
                        measured <= stats.predicted_error * 1.05 + 2e-5,
                        "{bits} bits rank {k}: {measured} vs {}",
                        stats.predicted_error
                    );
                }
            }
        }
    }
}

#[test]
fn max_error_picks_a_rank_that_meets_it() {
    let dir = tempfile::tempdir().unwrap();
    let d = Dims::image(12, 12, 2, 3);
    let t = matrix(d, 9);
    let raw = RawStore::open(&write_raw(
        &dir.path().join("t.raw"),
        d,
        &t,
        None,
        block_bytes(d, 5),
    ))
    .unwrap();
    let mut last_rank = usize::MAX;
    for target in [0.001, 0.01, 0.05] {
        let out = dir.path().join("e.ltm");
        let opts = PcaOptions {
            max_error: target,
            max_rank: 20,
            ..Default::default()
        };
        let stats = compress_pca(&raw, &out, &opts, ltm_codec::Progress::NONE).unwrap();
        assert!(
            stats.target_met && stats.achieved_error <= target,
            "{target}: {stats:?}"
        );
        let decoded = decode_matrix(&LtmFile::open(&out).unwrap(), &Limits::default()).unwrap();
        assert!(rel(&decoded, &t) <= target);
        // A rank one lower would not have met it before quantization.
        assert!(
            stats.rank == 1
                || stats.rank_errors[stats.rank - 1] > 0.95 * target * 0.999
                || stats.bits > 12
        );
        assert!(stats.rank <= last_rank);
        last_rank = stats.rank;
    }
}

#[test]
fn bad_ranks_and_unreachable_targets_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = Dims::image(4, 3, 1, 1); // 12 pixels, 6 values per row
    let t = matrix(d, 3);
    let raw = RawStore::open(&write_raw(
        &dir.path().join("t.raw"),
        d,
        &t,
        None,
        block_bytes(d, 5),
    ))
    .unwrap();
    let out = dir.path().join("x.ltm");
    for k in [0, 7, 1000] {
        let opts = PcaOptions {
            rank: Some(k),
            ..Default::default()
        };
        let e = compress_pca(&raw, &out, &opts, ltm_codec::Progress::NONE)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("PCA rank") && e.contains(&k.to_string()) && e.contains("1..=6"),
            "{e}"
        );
    }
    assert!(compress_pca(
        &raw,
        &out,
        &PcaOptions {
            rank: Some(6),
            ..Default::default()
        },
        ltm_codec::Progress::NONE
    )
    .is_ok());
    // Rank 1 of a noisy matrix cannot reach 1e-6.
    let d2 = Dims::image(10, 10, 2, 3);
    let raw2 = RawStore::open(&write_raw(
        &dir.path().join("u.raw"),
        d2,
        &matrix(d2, 4),
        None,
        block_bytes(d2, 5),
    ))
    .unwrap();
    let opts = PcaOptions {
        max_error: 1e-6,
        max_rank: 2,
        ..Default::default()
    };
    let e = compress_pca(&raw2, &out, &opts, ltm_codec::Progress::NONE)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("target error") && e.contains("--max-rank"),
        "{e}"
    );
    for bad in [0.0, 1.0, f64::NAN, -0.1] {
        let opts = PcaOptions {
            max_error: bad,
            ..Default::default()
        };
        assert!(compress_pca(&raw2, &out, &opts, ltm_codec::Progress::NONE).is_err());
    }
    std::fs::remove_file(&out).unwrap();
    let opts = PcaOptions {
        max_error: 1e-6,
        max_rank: 2,
        ..Default::default()
    };
    assert!(compress_pca(&raw2, &out, &opts, ltm_codec::Progress::NONE).is_err());
    assert!(!out.exists(), "a refused target writes nothing");
}

#[test]
fn zero_and_constant_matrices() {
    let dir = tempfile::tempdir().unwrap();
    let d = Dims::image(5, 4, 2, 3);
    for (name, v) in [("zero", 0.0f32), ("constant", 3.5)] {
        let t = vec![v; d.pixels() * d.row_len()];
        let raw = RawStore::open(&write_raw(
            &dir.path().join(name),
            d,
            &t,
            None,
            block_bytes(d, 5),
        ))
        .unwrap();
        let out = dir.path().join(format!("{name}.ltm"));
        let stats = compress_pca(
            &raw,
            &out,
            &PcaOptions {
                rank: Some(2),
                ..Default::default()
            },
            ltm_codec::Progress::NONE,
        )
        .unwrap();
        let decoded = decode_matrix(&LtmFile::open(&out).unwrap(), &Limits::default()).unwrap();
        assert!(decoded.iter().all(|x| x.is_finite()));
        // Rows past the last are refused, not a panic.
        let file = LtmFile::open(&out).unwrap();
        let model = file.pca().unwrap();
        let mut rows = Vec::new();
        model.reconstruct_rows(19, 1, &mut rows).unwrap();
        for (first, count) in [(19, 2), (21, 0), (usize::MAX, 2)] {
            let err = model.reconstruct_rows(first, count, &mut rows).unwrap_err();
            assert!(err.to_string().contains("within 0..20"), "{err}");
        }
        assert!(
            stats.achieved_error < 1e-6,
            "{name}: {}",
            stats.achieved_error
        );
        assert!(decoded
            .iter()
            .zip(&t)
            .all(|(a, b)| (a - b).abs() <= 1e-6 * (1.0 + b.abs())));
    }
}

/// Rewrites the CRC of the chunk that holds byte `at` and the directory's.
fn fix_crcs(b: &mut [u8]) {
    let count = u32::from_le_bytes(b[16..20].try_into().unwrap()) as usize;
    for k in 0..count {
        let e = 24 + 32 * k;
        let off = u64::from_le_bytes(b[e + 8..e + 16].try_into().unwrap()) as usize;
        let len = u64::from_le_bytes(b[e + 16..e + 24].try_into().unwrap()) as usize;
        if off + len <= b.len() && &b[e..e + 4] != b"DATA" {
            let crc = crc32fast::hash(&b[off..off + len]);
            b[e + 24..e + 28].copy_from_slice(&crc.to_le_bytes());
        }
    }
    let end = 24 + 32 * count;
    let crc = crc32fast::hash(&b[..end]);
    b[end..end + 4].copy_from_slice(&crc.to_le_bytes());
}

/// Where chunk `tag` lies.
fn chunk_range(b: &[u8], tag: &[u8; 4]) -> std::ops::Range<usize> {
    let count = u32::from_le_bytes(b[16..20].try_into().unwrap()) as usize;
    (0..count)
        .map(|k| 24 + 32 * k)
        .find(|&e| &b[e..e + 4] == tag)
        .map(|e| {
            let off = u64::from_le_bytes(b[e + 8..e + 16].try_into().unwrap()) as usize;
            let len = u64::from_le_bytes(b[e + 16..e + 24].try_into().unwrap()) as usize;
            off..off + len
        })
        .unwrap()
}

#[test]
fn corrupted_pca_files_are_errors_never_panics() {
    let dir = tempfile::tempdir().unwrap();
    let d = Dims::image(6, 5, 2, 3);
    let raw = RawStore::open(&write_raw(
        &dir.path().join("t.raw"),
        d,
        &matrix(d, 1),
        None,
        block_bytes(d, 5),
    ))
    .unwrap();
    let out = dir.path().join("t.ltm");
    compress_pca(
        &raw,
        &out,
        &PcaOptions {
            rank: Some(3),
            ..Default::default()
        },
        ltm_codec::Progress::NONE,
    )
    .unwrap();
    let good = std::fs::read(&out).unwrap();
    let lim = Limits::default();
    assert!(LtmFile::from_bytes(good.clone(), &lim).is_ok());
    let meta = chunk_range(&good, b"META");
    // Rank (META terms) 0, above min(P, N), and mode codes.
    for (at, v) in [
        (meta.start + 36, 0u32),
        (meta.start + 36, 31),
        (meta.start + 36, u32::MAX),
    ] {
        let mut b = good.clone();
        b[at..at + 4].copy_from_slice(&v.to_le_bytes());
        fix_crcs(&mut b);
        let e = LtmFile::from_bytes(b, &lim)
            .err()
            .expect("refused")
            .to_string();
        assert!(e.contains("PCA rank"), "{e}");
    }
    let mut b = good.clone();
    b[meta.start + 16] = 2; // adaptive, but PCA chunks
    fix_crcs(&mut b);
    assert!(LtmFile::from_bytes(b, &lim).is_err());
    // Every byte of every PCA chunk flipped, CRCs repaired: an error or a
    // valid file whose decoded values are finite.
    for tag in [b"PCAM", b"PCAB", b"PCAC"] {
        let r = chunk_range(&good, tag);
        for at in r.clone() {
            for flip in [0x01u8, 0x80, 0xff] {
                let mut b = good.clone();
                b[at] ^= flip;
                fix_crcs(&mut b);
                if let Ok(f) = LtmFile::from_bytes(b, &lim) {
                    if let Ok(m) = decode_matrix(&f, &lim) {
                        assert!(m.iter().all(|v| v.is_finite()));
                    }
                }
            }
        }
        // Without repaired CRCs every flip is caught by the chunk CRC.
        let mut b = good.clone();
        b[r.start] ^= 1;
        assert!(LtmFile::from_bytes(b, &lim)
            .err()
            .unwrap()
            .to_string()
            .contains("CRC"));
    }
    // Limits are checked before the coefficients are allocated.
    let small = Limits::with_max_alloc(200);
    let e = LtmFile::from_bytes(good.clone(), &small)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("PCA") || e.contains("limit"), "{e}");
}

#[test]
fn version_1_wavelet_files_still_open_and_pca_needs_version_2() {
    let dir = tempfile::tempdir().unwrap();
    let d = Dims::image(8, 8, 2, 1);
    let t = matrix(d, 2);
    let raw = RawStore::open(&write_raw(
        &dir.path().join("t.raw"),
        d,
        &t,
        None,
        block_bytes(d, 5),
    ))
    .unwrap();
    let w = dir.path().join("w.ltm");
    compress(
        &raw,
        &w,
        &CompressOptions::default(),
        ltm_codec::Progress::NONE,
    )
    .unwrap();
    let mut b = std::fs::read(&w).unwrap();
    assert_eq!(
        u32::from_le_bytes(b[8..12].try_into().unwrap()),
        ltm_codec::container::VERSION
    );
    // A version-1 file is a version-6 wavelet file with version 1 when it
    // has no feature of a later version (an empty-row mask, surface data,
    // column norms) and no range-coded column (versions 3 and 4).
    let features = u32::from_le_bytes(b[12..16].try_into().unwrap());
    let ranged = LtmFile::open(&w)
        .unwrap()
        .columns()
        .iter()
        .any(|c| c.encoding.is_range_coded());
    b[8..12].copy_from_slice(&1u32.to_le_bytes());
    fix_crcs(&mut b);
    let v1 = LtmFile::from_bytes(b.clone(), &Limits::default());
    if features & !1 == 0 && !ranged {
        let v2 = LtmFile::open(&w).unwrap();
        assert_eq!(
            decode_matrix(&v1.unwrap(), &Limits::default()).unwrap(),
            decode_matrix(&v2, &Limits::default()).unwrap()
        );
    } else {
        let e = v1.err().unwrap().to_string();
        assert!(e.contains("version 1"), "{e}");
    }
    // A version-8 file's planes or encoding 5 are refused in a file that
    // claims version 7, column norms (feature 8, a version-5 file's) in one
    // that claims version 4, and encoding 4 in a version-4 file that
    // claims version 3.
    b[8..12].copy_from_slice(&7u32.to_le_bytes());
    fix_crcs(&mut b);
    let e = LtmFile::from_bytes(b.clone(), &Limits::default())
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("version-7") || e.contains("version 7"), "{e}");
    let fixtures = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures");
    let mut v5 = std::fs::read(fixtures.join("golden-v5.ltm")).unwrap();
    v5[8..12].copy_from_slice(&4u32.to_le_bytes());
    fix_crcs(&mut v5);
    let e = LtmFile::from_bytes(v5, &Limits::default())
        .err()
        .unwrap()
        .to_string();
    assert!(
        e.contains("feature flags") && e.contains("version 4"),
        "{e}"
    );
    let mut v4 = std::fs::read(fixtures.join("golden-v4.ltm")).unwrap();
    let classed = LtmFile::from_bytes(v4.clone(), &Limits::default())
        .unwrap()
        .columns()
        .iter()
        .any(|c| c.encoding == ltm_codec::column::Encoding::Classed);
    assert!(classed);
    v4[8..12].copy_from_slice(&3u32.to_le_bytes());
    fix_crcs(&mut v4);
    let e = LtmFile::from_bytes(v4, &Limits::default())
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("encoding 4") && e.contains("version 3"), "{e}");
    b[8..12].copy_from_slice(&(ltm_codec::container::VERSION + 1).to_le_bytes());
    fix_crcs(&mut b);
    assert!(LtmFile::from_bytes(b, &Limits::default())
        .err()
        .unwrap()
        .to_string()
        .contains("version"));
    let p = dir.path().join("p.ltm");
    compress_pca(
        &raw,
        &p,
        &PcaOptions {
            rank: Some(2),
            ..Default::default()
        },
        ltm_codec::Progress::NONE,
    )
    .unwrap();
    let mut b = std::fs::read(&p).unwrap();
    b[8..12].copy_from_slice(&1u32.to_le_bytes());
    fix_crcs(&mut b);
    assert!(LtmFile::from_bytes(b, &Limits::default())
        .err()
        .unwrap()
        .to_string()
        .contains("version"));
}
