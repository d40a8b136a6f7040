//! The codec end to end on constructed matrices: round trips in every mode,
//! measured error against the dense original, hard numerical cases,
//! out-of-core transposition and hostile files.

use ltm_codec::compress::{
    compress, CodeOptions, Coder, Coding, CompressOptions, Feedback, Next, Plan, QuantSpec, Target,
    TransposeOptions,
};
use ltm_codec::compress::{Entropy, Mode, Quantizer};
use ltm_codec::container::LtmFile;
use ltm_codec::cubemap::{texel_direction, texel_solid_angle};
use ltm_codec::npy::decode_matrix;
use ltm_codec::{Dims, Error, Filter, Limits, LtmWriter, RawStore, Transposed};
use ltm_testkit::write_raw;
use std::path::{Path, PathBuf};

/// A plausible transport matrix: a curved surface with a shadowing ridge,
/// cosine-weighted, zero background pixels.
fn scene(dims: Dims) -> Vec<f32> {
    let (w, h, n, c) = (
        dims.width() as usize,
        dims.height() as usize,
        dims.face_res() as usize,
        dims.channels as usize,
    );
    let m = dims.lights();
    let mut t = vec![0.0f32; w * h * m * c];
    for y in 0..h {
        for x in 0..w {
            let (u, v) = (
                (x as f32 + 0.5) / w as f32 - 0.5,
                (y as f32 + 0.5) / h as f32 - 0.5,
            );
            if u * u + v * v > 0.22 {
                continue; // background
            }
            let normal = glam::Vec3::new(u, 1.0, v).normalize();
            let ridge = 0.3 * (6.0 * u).sin();
            for j in 0..m {
                let d = texel_direction(n, j);
                let cos = normal.dot(d).max(0.0);
                let lit = if d.y > ridge * (1.0 - d.x.abs()) {
                    1.0
                } else {
                    0.0
                };
                let val = cos * lit * texel_solid_angle(n, j) as f32 / std::f32::consts::PI;
                for ch in 0..c {
                    t[((y * w + x) * m + j) * c + ch] = val * [0.8, 0.5, 0.3][ch];
                }
            }
        }
    }
    t
}

fn rel_error(a: &[f32], b: &[f32]) -> f64 {
    let num: f64 = a.iter().zip(b).map(|(x, y)| ((x - y) as f64).powi(2)).sum();
    let den: f64 = b.iter().map(|y| (*y as f64).powi(2)).sum();
    if den == 0.0 {
        num.sqrt()
    } else {
        (num / den).sqrt()
    }
}

fn run(
    dir: &Path,
    raw: &Path,
    opts: &CompressOptions,
    name: &str,
) -> (PathBuf, ltm_codec::CompressStats) {
    let out = dir.join(name);
    let store = RawStore::open(raw).unwrap();
    let stats = compress(&store, &out, opts, ltm_codec::Progress::NONE).unwrap();
    (out, stats)
}

#[test]
fn every_mode_meets_its_target_and_reports_the_measured_error() {
    let dir = tempfile::tempdir().unwrap();
    let dims = Dims::image(24, 20, 4, 1);
    let t = scene(dims);
    let raw = write_raw(&dir.path().join("m.raw"), dims, &t, None, 64 << 10);
    for mode in [Mode::TwoD, Mode::FourD, Mode::Adaptive] {
        for (bits, target) in [(16, 0.001), (9, 0.02), (12, 0.05)] {
            let opts: CompressOptions = CodeOptions {
                mode,
                bits,
                target: Target::MaxError(target),
                ..Default::default()
            }
            .into();
            let (out, stats) = run(dir.path(), &raw, &opts, "m.ltm");
            let file = LtmFile::open(&out).unwrap();
            let dense = decode_matrix(&file, &Limits::default()).unwrap();
            let err = rel_error(&dense, &t);
            assert!(dense.iter().all(|v| v.is_finite()));
            assert!(
                (err - stats.achieved_error).abs() <= 1e-4 + 1e-3 * err,
                "{mode:?} bits {bits}: measured {err} vs reported {}",
                stats.achieved_error
            );
            // A target below the quantization floor of `bits` is reported as
            // missed; 16 bits reach every target here.
            assert_eq!(
                stats.target_met,
                err <= target * 1.0001,
                "{mode:?} bits {bits}: {err} reported {}",
                stats.achieved_error
            );
            assert!(
                stats.target_met || bits < 16,
                "{mode:?} bits {bits} target {target}: error {err}"
            );
            assert!(
                stats.file_bytes < stats.raw_bytes,
                "{mode:?}: {} bytes vs raw {}",
                stats.file_bytes,
                stats.raw_bytes
            );
            let depths: Vec<u8> = file.columns().iter().map(|c| c.depth).collect();
            match mode {
                Mode::TwoD => assert!(depths.iter().all(|&d| d == 0)),
                Mode::FourD => assert!(depths.iter().all(|&d| d as u32 == file.meta().max_depth())),
                Mode::Adaptive => {}
                other => panic!("mode {other:?} is not tested here"),
            }
        }
    }
}

/// Rows that are all zero (the background of `scene`, open sky) decode to
/// exactly 0 in every mode, through every decoder: the file stores them
/// (chunk EMPT) and the encoder's measured error is the decoded file's.
#[test]
fn empty_rows_decode_to_exactly_zero_in_every_mode() {
    let dir = tempfile::tempdir().unwrap();
    for dims in [Dims::image(24, 20, 4, 1), Dims::image(23, 17, 2, 3)] {
        let t = scene(dims);
        let m = dims.lights() * dims.channels as usize;
        let background: Vec<usize> = (0..dims.pixels())
            .filter(|&p| t[p * m..(p + 1) * m].iter().all(|&v| v == 0.0))
            .collect();
        assert!(background.len() > dims.pixels() / 10);
        let raw = write_raw(&dir.path().join("e.raw"), dims, &t, None, 64 << 10);
        for mode in [Mode::TwoD, Mode::FourD, Mode::Adaptive] {
            for target in [Target::MaxError(0.03), Target::Keep(9)] {
                let opts: CompressOptions = CodeOptions {
                    mode,
                    target,
                    ..Default::default()
                }
                .into();
                let (out, stats) = run(dir.path(), &raw, &opts, "e.ltm");
                let file = LtmFile::open(&out).unwrap();
                let mask = file.empty_rows().expect("an EMPT chunk");
                assert_eq!(mask.count(), background.len());
                assert!(background.iter().all(|&p| mask.is_empty_row(p)));
                let dense = decode_matrix(&file, &Limits::default()).unwrap();
                for &p in &background {
                    assert!(
                        dense[p * m..(p + 1) * m].iter().all(|&v| v == 0.0),
                        "{mode:?} {target:?}: row {p} is not 0"
                    );
                }
                let err = rel_error(&dense, &t);
                assert!(
                    (err - stats.achieved_error).abs() <= 1e-4 + 1e-3 * err,
                    "{mode:?}: measured {err} vs reported {}",
                    stats.achieved_error
                );
            }
        }
    }
}

/// A matrix without empty rows stores no mask, and the written file is
/// of the current version either way.
#[test]
fn files_without_empty_rows_have_no_mask() {
    let dir = tempfile::tempdir().unwrap();
    let dims = Dims::image(6, 5, 2, 1);
    let t: Vec<f32> = (0..dims.pixels() * dims.lights())
        .map(|i| 1.0 + (i % 7) as f32)
        .collect();
    let raw = write_raw(&dir.path().join("f.raw"), dims, &t, None, 64 << 10);
    let (out, _) = run(dir.path(), &raw, &CompressOptions::default(), "f.ltm");
    let bytes = std::fs::read(&out).unwrap();
    assert_eq!(
        u32::from_le_bytes(bytes[8..12].try_into().unwrap()),
        ltm_codec::container::VERSION
    );
    assert!(LtmFile::open(&out).unwrap().empty_rows().is_none());
}

/// Opens the committed fixture `tests/fixtures/NAME` (the golden matrix
/// below at the default options, written by an older ltm), checks its
/// version, and checks that it decodes to the error it recorded. Returns
/// the file and the CRC-32 of its bytes.
fn old_fixture_decodes(name: &str, version: u32) -> (LtmFile, u32) {
    let path = fixture(name);
    let bytes = std::fs::read(&path).unwrap();
    assert_eq!(
        u32::from_le_bytes(bytes[8..12].try_into().unwrap()),
        version
    );
    let file = LtmFile::open(&path).unwrap();
    let dense = decode_matrix(&file, &Limits::default()).unwrap();
    let err = rel_error(&dense, &golden_matrix(file.meta().dims));
    assert!(
        (err - file.meta().achieved_error as f64).abs() <= 1e-4 + 1e-3 * err,
        "{name}: decoded error {err} vs recorded {}",
        file.meta().achieved_error
    );
    (file, crc32fast::hash(&bytes))
}

/// A version-1 file (before the empty-row mask) still opens and decodes,
/// with no row known to be empty.
#[test]
fn version_1_files_still_decode() {
    let (file, crc) = old_fixture_decodes("golden-v1.ltm", 1);
    assert_eq!(crc, GOLDEN_LTM_V1);
    assert!(file.empty_rows().is_none());
}

/// A version-2 file (before column encoding 3) still opens and decodes to
/// the error it recorded.
#[test]
fn version_2_files_still_decode() {
    let (file, _) = old_fixture_decodes("golden-v2.ltm", 2);
    assert!(file.columns().iter().all(|c| !c.encoding.is_range_coded()));
}

/// A version-3 file (column encoding 3, before encoding 4) still opens and
/// decodes to the error it recorded.
#[test]
fn version_3_files_still_decode() {
    let (file, crc) = old_fixture_decodes("golden-v3.ltm", 3);
    assert_eq!(crc, GOLDEN_LTM_V3);
    let encodings: Vec<_> = file.columns().iter().map(|c| c.encoding).collect();
    assert!(encodings.contains(&ltm_codec::column::Encoding::Ranged));
    assert!(!encodings.contains(&ltm_codec::column::Encoding::Classed));
}

/// A version-4 file (column encoding 4, before the stored column norms)
/// still opens and decodes to the error it recorded, with no norms.
#[test]
fn version_4_files_still_decode() {
    let (file, crc) = old_fixture_decodes("golden-v4.ltm", 4);
    assert_eq!(crc, GOLDEN_LTM_V4);
    assert!(file.column_norms().is_none());
    let encodings: Vec<_> = file.columns().iter().map(|c| c.encoding).collect();
    assert!(encodings.contains(&ltm_codec::column::Encoding::Classed));
}

/// A version-5 file (column norms, before the receiver mesh) still opens
/// and decodes to the error it recorded, with its norms and no mesh.
#[test]
fn version_5_files_still_decode() {
    let (file, crc) = old_fixture_decodes("golden-v5.ltm", 5);
    assert_eq!(crc, GOLDEN_LTM_V5);
    assert!(file.column_norms().is_some());
    assert!(file.mesh().is_none());
}

/// A version-6 file (the receiver mesh, before packed side chunks), a
/// version-7 file (column encoding 4, the column norms, no planes), and
/// version-8 and 9 files (before the priors and before NEAR) still open
/// and decode, and to exactly the matrix the current version's file
/// of the same options decodes to: packing the side chunks, encoding 5 and
/// dropping the norms changed no value.
#[test]
fn version_6_and_7_files_still_decode_to_the_current_files_matrix() {
    for (name, version, golden) in [
        ("golden-v6.ltm", 6, GOLDEN_LTM_V5),
        ("golden-v7.ltm", 7, GOLDEN_LTM_V7),
        ("golden-v8.ltm", 8, GOLDEN_LTM_V8),
        // Version 9 (before NEAR): the same bytes as a version-10 file but
        // the version field, which a whole-file CRC does not see (the
        // directory's CRC follows it), so its hash is the current one.
        ("golden-v9.ltm", 9, GOLDEN_LTM),
    ] {
        let (old, crc) = old_fixture_decodes(name, version);
        assert_eq!(crc, golden);
        if version == 7 {
            assert!(old.column_norms().is_some());
            let encodings: Vec<_> = old.columns().iter().map(|c| c.encoding).collect();
            assert!(encodings.contains(&ltm_codec::column::Encoding::Classed));
        }
        same_matrix_as_a_new_file(&old, version);
    }
}

/// `old` (of format `version`) decodes to the matrix of the current
/// version's file of the golden matrix at [`fixture_options`], bit for bit,
/// with the same empty rows.
fn same_matrix_as_a_new_file(old: &LtmFile, version: u32) {
    let dir = tempfile::tempdir().unwrap();
    let out = golden_file(dir.path(), &fixture_options());
    let new = LtmFile::open(&out).unwrap();
    let limits = Limits::default();
    let (a, b) = (
        decode_matrix(old, &limits).unwrap(),
        decode_matrix(&new, &limits).unwrap(),
    );
    assert!(a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits()) && a.len() == b.len());
    assert_eq!(old.empty_rows(), new.empty_rows());
    let encodings: Vec<_> = new.columns().iter().map(|c| c.encoding).collect();
    assert!(encodings.contains(&ltm_codec::column::Encoding::Primed));
    assert!(new.column_norms().is_none() && new.priors().is_some());
    // Versions before 9 lacked the priors; a version-9 file is the same
    // bytes but for its version field.
    match version {
        9 => assert_eq!(new.file_bytes(), old.file_bytes()),
        _ => assert!(new.file_bytes() < old.file_bytes()),
    }
}

/// A PRIO chunk that disagrees with its feature flag or the file's
/// version, holds a state no context reaches, or is missing where a column
/// has encoding 6, is refused with a message naming it, even with every
/// checksum repaired.
#[test]
fn bad_priors_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let dims = Dims::image(24, 20, 4, 3);
    let out = golden_file(dir.path(), &fixture_options());
    let good = ltm_codec::container::unpack_chunks(&std::fs::read(&out).unwrap()).unwrap();
    let parse = parse_repaired;
    assert_eq!(parse(&good, &|_| {}), "");
    let (_, prio_at, prio_len) = chunk_entry(&good, b"PRIO");
    assert_eq!(prio_len, ltm_codec::entropy::PRIO_LEN);
    let err = parse(&good, &|b| b[12] &= !32);
    assert!(err.contains("PRIO"), "{err}");
    let err = parse(&good, &|b| b[8] = 8);
    assert!(
        err.contains("feature flags") && err.contains("version 8"),
        "{err}"
    );
    // Binary context 0 at p = 0; symbol context 0 with a[1] > a[2].
    let err = parse(&good, &|b| b[prio_at + 4..prio_at + 6].fill(0));
    assert!(err.contains("binary context 0"), "{err}");
    let class0 = prio_at + 4 + 4 * ltm_codec::entropy::PRIOR_BINARY;
    let err = parse(&good, &|b| {
        b[class0..class0 + 2].copy_from_slice(&u16::MAX.to_le_bytes())
    });
    assert!(err.contains("class context 0"), "{err}");
    // An encoding-6 column in a version-9 file without priors.
    let old =
        ltm_codec::container::unpack_chunks(&std::fs::read(fixture("golden-v8.ltm")).unwrap())
            .unwrap();
    let (_, cols_at, _) = chunk_entry(&old, b"COLS");
    let j = (0..dims.lights())
        .find(|j| old[cols_at + 28 * j + 25] == 5)
        .unwrap();
    let err = parse(&old, &|b| {
        b[8] = 9;
        b[cols_at + 28 * j + 25] = 6;
    });
    assert!(err.contains(&format!("column {j} has encoding 6")), "{err}");
    // In a version-8 file, encoding 6 is unknown.
    let err = parse(&old, &|b| b[cols_at + 28 * j + 25] = 6);
    assert!(err.contains("encoding 6"), "{err}");
}

/// Version 7 packs the column table (chunk COLS, written after DATA) when
/// its zstd frame is smaller, version 8 in planes when those are smaller
/// still (packing 1 or 2), and the file decodes exactly as the same file
/// with its chunks stored as is.
#[test]
fn the_column_table_is_packed_when_smaller_and_decodes_identically() {
    let dir = tempfile::tempdir().unwrap();
    let dims = Dims::image(24, 20, 4, 3);
    let out = golden_file(dir.path(), &CompressOptions::default());
    let packed = std::fs::read(&out).unwrap();
    let u32_at = |b: &[u8], at: usize| u32::from_le_bytes(b[at..at + 4].try_into().unwrap());
    let table = 28 * dims.lights();
    let (entry, at, len) = chunk_entry(&packed, b"COLS");
    assert!([1, 2].contains(&u32_at(&packed, entry + 4)));
    assert_eq!(u32_at(&packed, entry + 28), table as u32);
    assert!(len < table, "{len} stored bytes for a {table}-byte table");
    // DATA, the priors (version 9; the golden matrix's pay for theirs),
    // then COLS, which ends the file.
    let (_, data_at, data_len) = chunk_entry(&packed, b"DATA");
    let (_, prio_at, prio_len) = chunk_entry(&packed, b"PRIO");
    assert_eq!(prio_at, data_at + data_len);
    assert_eq!((at, at + len), (prio_at + prio_len, packed.len()));
    let stored = ltm_codec::container::unpack_chunks(&packed).unwrap();
    let (entry, _, len) = chunk_entry(&stored, b"COLS");
    assert_eq!((u32_at(&stored, entry + 4), len), (0, table));
    let limits = Limits::default();
    let a = LtmFile::from_bytes(packed, &limits).unwrap();
    let b = LtmFile::from_bytes(stored, &limits).unwrap();
    assert_eq!(a.columns(), b.columns());
    for j in 0..a.columns().len() {
        assert_eq!(a.column(j).unwrap(), b.column(j).unwrap(), "column {j}");
    }
    let (x, y) = (
        decode_matrix(&a, &limits).unwrap(),
        decode_matrix(&b, &limits).unwrap(),
    );
    assert!(x.len() == y.len() && x.iter().zip(&y).all(|(p, q)| p.to_bits() == q.to_bits()));
}

/// A version-8 file stores no column norms (chunk NORM); the decoder's
/// norms are those of the columns as it reads them, bit for bit, and a
/// version-5 file's stored norms are exactly those: in every wavelet mode,
/// with either entropy coder, grey and RGB, with zero columns.
#[test]
fn column_norms_are_those_of_the_decoded_columns() {
    let dir = tempfile::tempdir().unwrap();
    for (dims, entropy, mode) in [
        (Dims::image(40, 28, 4, 3), Entropy::Range, Mode::Adaptive),
        (Dims::image(40, 28, 4, 3), Entropy::Zstd, Mode::TwoD),
        (Dims::image(9, 31, 2, 1), Entropy::Range, Mode::FourD),
    ] {
        let mut t = scene(dims);
        // Face 0 dark: its n² wavelet lights (the row transform works per
        // face) have all-zero columns.
        let (m, c) = (dims.lights(), dims.channels as usize);
        let face = m / 6;
        for (i, v) in t.iter_mut().enumerate() {
            if i / c % m < face {
                *v = 0.0;
            }
        }
        let raw = write_raw(&dir.path().join("n.raw"), dims, &t, None, 64 << 10);
        let opts: CompressOptions = CodeOptions {
            entropy,
            mode,
            target: Target::MaxError(0.01),
            ..Default::default()
        }
        .into();
        let (out, _) = run(dir.path(), &raw, &opts, "n.ltm");
        let file = LtmFile::open(&out).unwrap();
        assert!(file.column_norms().is_none());
        let decoder = ltm_codec::ColumnDecoder::for_file(&file, &Limits::default()).unwrap();
        let norms = decoder.column_norms(&file).unwrap();
        assert_eq!(norms.len(), m);
        for (j, &n) in norms.iter().enumerate() {
            let col = file.column(j).unwrap();
            assert_eq!(n, decoder.weighted_norm(&col) as f32, "{mode:?} column {j}");
            if j < face {
                assert_eq!(n, 0.0);
            }
        }
        let zero = file.columns().iter().filter(|c| c.nnz == 0).count();
        assert!(zero >= face, "{zero} empty columns");
        assert_eq!(norms.iter().filter(|&&n| n == 0.0).count(), zero);
    }
    let v5 = LtmFile::open(&fixture("golden-v5.ltm")).unwrap();
    let decoder = ltm_codec::ColumnDecoder::for_file(&v5, &Limits::default()).unwrap();
    let stored = v5.column_norms().expect("a NORM chunk");
    assert_eq!(stored, &decoder.column_norms(&v5).unwrap()[..]);
    decoder.check_stored_norms(&v5).unwrap();
}

/// The path of the committed fixture `tests/fixtures/NAME`.
fn fixture(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

/// `Entropy::Zstd` stores no range-coded column (the faster-opening
/// files), meets the same target, and decodes to the error it records;
/// the default range-coded file of the same matrix is smaller.
#[test]
fn zstd_entropy_writes_no_range_coded_columns() {
    let dir = tempfile::tempdir().unwrap();
    let dims = Dims::image(40, 28, 4, 3);
    let raw = write_raw(
        &dir.path().join("z.raw"),
        dims,
        &scene(dims),
        None,
        64 << 10,
    );
    let mut sizes = Vec::new();
    for entropy in [Entropy::Zstd, Entropy::Range] {
        let opts: CompressOptions = CodeOptions {
            entropy,
            target: Target::MaxError(0.01),
            bits: 12,
            ..Default::default()
        }
        .into();
        let (out, stats) = run(dir.path(), &raw, &opts, "z.ltm");
        let file = LtmFile::open(&out).unwrap();
        let ranged = file
            .columns()
            .iter()
            .filter(|c| c.encoding.is_range_coded())
            .count();
        assert_eq!(
            ranged == 0,
            entropy == Entropy::Zstd,
            "{entropy:?}: {ranged} ranged"
        );
        assert!(
            stats.target_met && stats.achieved_error <= 0.01,
            "{entropy:?}"
        );
        let dense = decode_matrix(&file, &Limits::default()).unwrap();
        let err = rel_error(&dense, &scene(dims));
        assert!(
            (err - stats.achieved_error).abs() <= 1e-4,
            "{err} vs {}",
            stats.achieved_error
        );
        sizes.push(stats.file_bytes);
    }
    assert!(
        sizes[1] < sizes[0],
        "range {} vs zstd {}",
        sizes[1],
        sizes[0]
    );
}

/// With `raise_bits`, bits whose quantization floor misses the target are
/// skipped or re-coded with 2 more bits, and the file is the one coded
/// at the final bits directly.
#[test]
fn raised_bits_give_the_file_of_the_final_bits() {
    let dir = tempfile::tempdir().unwrap();
    let dims = Dims::image(31, 17, 4, 3);
    let raw = write_raw(
        &dir.path().join("r.raw"),
        dims,
        &scene(dims),
        None,
        64 << 10,
    );
    let options = |bits, raise_bits| -> CompressOptions {
        CodeOptions {
            bits,
            raise_bits,
            target: Target::MaxError(0.002),
            ..Default::default()
        }
        .into()
    };
    let (_, raised) = run(dir.path(), &raw, &options(4, true), "a.ltm");
    assert!(raised.bits > 4 && raised.target_met, "{raised:?}");
    assert!(raised.achieved_error <= 0.002, "{raised:?}");
    let (_, direct) = run(dir.path(), &raw, &options(raised.bits, false), "b.ltm");
    assert_eq!(
        (raised.file_bytes, raised.achieved_error),
        (direct.file_bytes, direct.achieved_error)
    );
    let (a, b) = (
        std::fs::read(dir.path().join("a.ltm")).unwrap(),
        std::fs::read(dir.path().join("b.ltm")).unwrap(),
    );
    assert!(a == b, "the raised file differs from the direct one");
}

/// A file asked for E lands in [0.97·E, E] measured, in every mode, with
/// both quantizers, on odd sizes and both channel counts (2 or 3 codings
/// here but for one case of 5). The smallest matrix has 96 lights: at 24,
/// one coefficient crossing the uniform quantizer's threshold moved the
/// error by 4 % of the target at 0.3 %, more than the window.
#[test]
fn target_errors_land_within_three_percent_below_the_target() {
    let dir = tempfile::tempdir().unwrap();
    let mut failures = Vec::new();
    for dims in [
        Dims::image(24, 20, 4, 1),
        Dims::image(31, 17, 4, 3),
        Dims::image(45, 33, 4, 1),
    ] {
        let t = scene(dims);
        let raw = write_raw(&dir.path().join("x.raw"), dims, &t, None, 64 << 10);
        let modes = [Mode::TwoD, Mode::FourD, Mode::Adaptive];
        let cases = modes
            .into_iter()
            .flat_map(|m| [Quantizer::Uniform, Quantizer::Peak].map(|q| (m, q)));
        for (mode, quantizer) in cases {
            for target in [0.003, 0.01, 0.03] {
                let opts: CompressOptions = CodeOptions {
                    mode,
                    quantizer,
                    bits: 14,
                    target: Target::MaxError(target),
                    ..Default::default()
                }
                .into();
                let (out, stats) = run(dir.path(), &raw, &opts, "x.ltm");
                let dense =
                    decode_matrix(&LtmFile::open(&out).unwrap(), &Limits::default()).unwrap();
                let err = rel_error(&dense, &t);
                let what = format!(
                    "{}x{}x{} {mode:?} {quantizer:?} target {target}: error {:.4} of it, {} codings",
                    dims.width(),
                    dims.height(),
                    dims.channels,
                    err / target,
                    stats.codings
                );
                if !(0.97 * target..=target * 1.00005).contains(&err) || stats.codings > 8 {
                    failures.push(what);
                }
            }
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// Targets just above the quantization floor `F` of few bits (measured by
/// keeping every coefficient at the same bits), where the floor's model
/// can be off by a few times: a 512² 2d file asked for 1 % landed at
/// 0.66 % before the re-coding calibrated the quantization model apart
/// from the dropped energy. 2d files land in [0.97·E, E]; 4d and adaptive
/// ones, whose depths and scale groups move with the threshold, never
/// above E and not below 0.8·E (measured 0.81–1.0 here; before the change
/// 29 of the 48 cases missed 0.97·E, now 18, none of them 2d).
#[test]
fn targets_near_the_quantization_floor_land_close_below_them() {
    let dir = tempfile::tempdir().unwrap();
    let mut failures = Vec::new();
    for dims in [Dims::image(31, 17, 4, 3), Dims::image(24, 20, 4, 1)] {
        let t = scene(dims);
        let raw = write_raw(&dir.path().join("f.raw"), dims, &t, None, 64 << 10);
        for mode in [Mode::TwoD, Mode::FourD, Mode::Adaptive] {
            for bits in [6, 8] {
                let options = |target| -> CompressOptions {
                    CodeOptions {
                        mode,
                        bits,
                        target,
                        ..Default::default()
                    }
                    .into()
                };
                let (_, all) = run(
                    dir.path(),
                    &raw,
                    &options(Target::Keep(dims.pixels())),
                    "f.ltm",
                );
                let floor = all.achieved_error;
                for factor in [1.1, 1.3, 1.7, 2.5] {
                    let target = floor * factor;
                    let (_, stats) = run(
                        dir.path(),
                        &raw,
                        &options(Target::MaxError(target)),
                        "f.ltm",
                    );
                    let err = stats.achieved_error;
                    let low = if mode == Mode::TwoD { 0.97 } else { 0.8 };
                    if !(low * target..=target * 1.00005).contains(&err) || stats.codings > 8 {
                        failures.push(format!(
                            "{}x{}x{} {mode:?} {bits} bits, floor {floor:.5}, target {factor}·floor: error {:.4} of it, {} codings",
                            dims.width(),
                            dims.height(),
                            dims.channels,
                            err / target,
                            stats.codings
                        ));
                    }
                }
            }
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

#[test]
fn near_lossless_at_16_bits() {
    let dir = tempfile::tempdir().unwrap();
    let dims = Dims::image(16, 12, 4, 3);
    let t = scene(dims);
    let raw = write_raw(&dir.path().join("c.raw"), dims, &t, None, 64 << 10);
    for col_filter in Filter::ALL {
        let opts: CompressOptions = CodeOptions {
            bits: 16,
            target: Target::MaxError(0.001),
            col_filter,
            ..Default::default()
        }
        .into();
        let (out, _) = run(dir.path(), &raw, &opts, "c.ltm");
        let dense = decode_matrix(&LtmFile::open(&out).unwrap(), &Limits::default()).unwrap();
        let err = rel_error(&dense, &t);
        assert!(err <= 0.001, "{col_filter}: {err}");
    }
}

#[test]
fn keep_mode_keeps_at_most_n_per_column_and_adaptive_is_no_worse_than_2d() {
    let dir = tempfile::tempdir().unwrap();
    let dims = Dims::image(32, 32, 4, 1);
    let t = scene(dims);
    let raw = write_raw(&dir.path().join("t.raw"), dims, &t, None, 64 << 10);
    let mut errors = Vec::new();
    for mode in [Mode::TwoD, Mode::Adaptive] {
        let opts: CompressOptions = CodeOptions {
            mode,
            bits: 16,
            target: Target::Keep(40),
            ..Default::default()
        }
        .into();
        let (out, _) = run(dir.path(), &raw, &opts, "t.ltm");
        let file = LtmFile::open(&out).unwrap();
        assert!(file.columns().iter().all(|c| c.nnz <= 40));
        errors.push(rel_error(
            &decode_matrix(&file, &Limits::default()).unwrap(),
            &t,
        ));
    }
    assert!(
        errors[1] <= errors[0] * 1.0001,
        "adaptive {} vs 2d {}",
        errors[1],
        errors[0]
    );
}

#[test]
fn monochrome_rgb_is_stored_as_one_channel() {
    let dir = tempfile::tempdir().unwrap();
    let dims = Dims::image(8, 8, 2, 3);
    let grey = scene(Dims {
        channels: 1,
        ..dims
    });
    let t: Vec<f32> = grey.iter().flat_map(|&v| [v, v, v]).collect();
    let raw = write_raw(&dir.path().join("g.raw"), dims, &t, None, 64 << 10);
    let (out, stats) = run(dir.path(), &raw, &CompressOptions::default(), "g.ltm");
    assert_eq!(stats.channels, 1);
    assert_eq!(LtmFile::open(&out).unwrap().meta().dims.channels, 1);
}

#[test]
fn hard_numerical_cases_never_produce_nan() {
    let dir = tempfile::tempdir().unwrap();
    type Entry = Box<dyn Fn(usize, usize) -> f32>;
    let cases: Vec<(&str, Dims, Entry)> = vec![
        ("zero", Dims::image(5, 3, 2, 1), Box::new(|_, _| 0.0)),
        (
            "impulse",
            Dims::image(7, 9, 2, 1),
            Box::new(|p, j| if p == 31 && j == 5 { 3.5 } else { 0.0 }),
        ),
        ("constant", Dims::image(6, 5, 2, 1), Box::new(|_, _| 0.25)),
        (
            "1x1",
            Dims::image(1, 1, 4, 1),
            Box::new(|_, j| j as f32 * 0.01),
        ),
        (
            "97x61",
            Dims::image(97, 61, 1, 1),
            Box::new(|p, j| ((p * 7 + j * 3) % 11) as f32),
        ),
        (
            "range",
            Dims::image(12, 10, 2, 1),
            Box::new(|p, j| 10f32.powi(((p + j) % 11) as i32 - 6)),
        ),
    ];
    for (name, dims, f) in cases {
        let m = dims.lights();
        let t: Vec<f32> = (0..dims.pixels() * m).map(|i| f(i / m, i % m)).collect();
        let raw = write_raw(&dir.path().join("h.raw"), dims, &t, None, 64 << 10);
        for bits in [4, 6, 8, 9, 10, 12, 16] {
            for mode in [Mode::TwoD, Mode::FourD, Mode::Adaptive] {
                let opts: CompressOptions = CodeOptions {
                    mode,
                    bits,
                    target: Target::MaxError(0.05),
                    ..Default::default()
                }
                .into();
                let (out, stats) = run(dir.path(), &raw, &opts, "h.ltm");
                let dense =
                    decode_matrix(&LtmFile::open(&out).unwrap(), &Limits::default()).unwrap();
                assert!(
                    dense.iter().all(|v| v.is_finite()),
                    "{name} bits {bits} {mode:?}: NaN"
                );
                assert!(stats.achieved_error.is_finite());
                if bits >= 12 {
                    let err = rel_error(&dense, &t);
                    assert!(err <= 0.0525, "{name} bits {bits} {mode:?}: error {err}");
                }
            }
        }
    }
}

#[test]
fn out_of_core_transpose_gives_the_same_file() {
    let dir = tempfile::tempdir().unwrap();
    let dims = Dims::image(64, 48, 8, 1);
    let t = scene(dims);
    let raw = write_raw(&dir.path().join("big.raw"), dims, &t, None, 64 << 10);
    assert!(dims.raw_bytes() > 3 << 20);
    let mut opts = CompressOptions::default();
    let (a, sa) = run(dir.path(), &raw, &opts, "a.ltm");
    opts.transpose.mem_budget = 1 << 20;
    let (b, sb) = run(dir.path(), &raw, &opts, "b.ltm");
    assert!(!sa.out_of_core && sb.out_of_core);
    assert_eq!(std::fs::read(a).unwrap(), std::fs::read(b).unwrap());
}

/// One transposed matrix coded with several settings (as `ltm report`
/// does) gives the files `compress` writes for each setting alone, in core
/// and out of core. The row filter is the transpose's: a filter it cannot
/// use is refused, and every file coded from it records its filter.
#[test]
fn one_transpose_codes_every_setting_like_compress() {
    let dir = tempfile::tempdir().unwrap();
    let dims = Dims::image(64, 48, 4, 3);
    let raw_path = write_raw(
        &dir.path().join("m.raw"),
        dims,
        &scene(dims),
        None,
        64 << 10,
    );
    let raw = RawStore::open(&raw_path).unwrap();
    for budget in [1u64 << 30, 1 << 20] {
        let transpose = TransposeOptions {
            mem_budget: budget,
            temp_dir: Some(dir.path().into()),
            ..Default::default()
        };
        let shared = Transposed::new(&raw, &transpose, ltm_codec::Progress::NONE).unwrap();
        assert_eq!(shared.out_of_core(), budget == 1 << 20);
        for (mode, bits, target) in [
            (Mode::Adaptive, 12, Target::MaxError(0.01)),
            (Mode::TwoD, 8, Target::MaxError(0.05)),
            (Mode::FourD, 10, Target::Keep(7)),
        ] {
            let code = CodeOptions {
                mode,
                bits,
                target,
                ..Default::default()
            };
            let opts = CompressOptions {
                transpose: transpose.clone(),
                code: code.clone(),
            };
            let a = dir.path().join("shared.ltm");
            let b = dir.path().join("alone.ltm");
            let sa = shared.code(&a, &code, ltm_codec::Progress::NONE).unwrap();
            let sb = compress(&raw, &b, &opts, ltm_codec::Progress::NONE).unwrap();
            assert_eq!(sa.file_bytes, sb.file_bytes);
            assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
        }
        let other = TransposeOptions {
            row_filter: Filter::LeGall53,
            ..transpose.clone()
        };
        let err = Transposed::new(&raw, &other, ltm_codec::Progress::NONE)
            .err()
            .unwrap();
        assert!(err.to_string().contains("row filter"), "{err}");
        let d4 = TransposeOptions {
            row_filter: Filter::D4,
            ..transpose
        };
        let a = dir.path().join("d4.ltm");
        let code = CodeOptions::default();
        let stats = Transposed::new(&raw, &d4, ltm_codec::Progress::NONE)
            .unwrap()
            .code(&a, &code, ltm_codec::Progress::NONE)
            .unwrap();
        assert_eq!(LtmFile::open(&a).unwrap().meta().row_filter, Filter::D4);
        let b = dir.path().join("d4-alone.ltm");
        let opts = CompressOptions {
            transpose: d4,
            code,
        };
        assert_eq!(
            compress(&raw, &b, &opts, ltm_codec::Progress::NONE)
                .unwrap()
                .file_bytes,
            stats.file_bytes
        );
        assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
    }
}

/// Too few bits for the target: missed at fixed bits, met when the coder
/// may raise them; the file records the bits it was coded with.
#[test]
fn raise_bits_meets_a_target_that_fixed_bits_miss() {
    let dir = tempfile::tempdir().unwrap();
    let dims = Dims::image(32, 24, 4, 1);
    let t = scene(dims);
    let raw = write_raw(&dir.path().join("m.raw"), dims, &t, None, 64 << 10);
    let mut opts: CompressOptions = CodeOptions {
        bits: 4,
        target: Target::MaxError(0.002),
        ..Default::default()
    }
    .into();
    let (_, fixed) = run(dir.path(), &raw, &opts, "fixed.ltm");
    assert!(!fixed.target_met && fixed.bits == 4, "{fixed:?}");
    opts.code.raise_bits = true;
    let (path, raised) = run(dir.path(), &raw, &opts, "raised.ltm");
    assert!(
        raised.target_met && raised.achieved_error <= 0.002,
        "{raised:?}"
    );
    assert!(raised.bits > 4 && raised.bits <= 16 && raised.bits % 2 == 0);
    let file = LtmFile::open(&path).unwrap();
    assert_eq!(file.meta().bits, raised.bits);
    let decoded = decode_matrix(&file, &Limits::default()).unwrap();
    assert!(rel_error(&decoded, &t) <= 0.002 * 1.0001);
}

/// The stages run apart, as a sharded compressor runs them: each shard
/// keeps only its columns (`Transposed::with_columns`), analyses of the
/// shards merge into the analysis of the whole, the shared error-feedback
/// loop (`Feedback`) plans every coding from what the shards measured, and
/// the shards' columns written in order give the file `Transposed::code`
/// writes (this setting lands on its target after two or three codings).
#[test]
fn stages_run_per_column_range_give_the_same_file() {
    let dir = tempfile::tempdir().unwrap();
    let dims = Dims::image(32, 24, 4, 3);
    let raw = RawStore::open(&write_raw(
        &dir.path().join("m.raw"),
        dims,
        &scene(dims),
        None,
        64 << 10,
    ))
    .unwrap();
    let transpose = TransposeOptions {
        mem_budget: 1 << 20,
        temp_dir: Some(dir.path().into()),
        ..Default::default()
    };
    let t = Transposed::new(&raw, &transpose, ltm_codec::Progress::NONE).unwrap();
    let code = CodeOptions {
        bits: 12,
        target: Target::MaxError(0.02),
        ..Default::default()
    };
    let (m, k) = (dims.lights(), 37);
    let shards: Vec<Transposed> = [0..k, k..m]
        .into_iter()
        .map(|r| Transposed::with_columns(&raw, &transpose, r, ltm_codec::Progress::NONE).unwrap())
        .collect();
    let coders: Vec<Coder> = shards
        .iter()
        .map(|s| Coder::new(s, &code).unwrap())
        .collect();
    assert!(coders[0]
        .analyze(0..k + 1, ltm_codec::Progress::NONE)
        .is_err());
    let whole = Coder::new(&t, &code)
        .unwrap()
        .analyze(0..m, ltm_codec::Progress::NONE)
        .unwrap();
    let first = coders[0].analyze(0..k, ltm_codec::Progress::NONE).unwrap();
    let second = coders[1].analyze(k..m, ltm_codec::Progress::NONE).unwrap();
    assert_eq!(first.clone().merge(second.clone()).unwrap(), whole);
    assert!(second.merge(first).is_err());
    let budget = coders[0].budget();
    let feedback = Feedback::new(&code, budget, Some(&whole)).unwrap();
    let mut step = feedback.first().unwrap();
    let (achieved, codings) = loop {
        assert_eq!(step.bits, code.bits);
        let mut writer = LtmWriter::create_with(
            &dir.path().join("staged.ltm"),
            coders[0].meta().clone(),
            None,
            ltm_codec::container::OptionalChunks {
                surface: None,
                mesh: None,
                empty_rows: Some(t.empty_rows()),
                near_field: None,
                column_norms: false,
                priors: true,
            },
        )
        .unwrap();
        let mut measured = Coding::default();
        for (coder, range) in coders.iter().zip([0..k, k..m]) {
            let coded = coder.code_columns(range, &step.plan).unwrap();
            coded.measure_into(&mut measured);
            writer.push_columns(coded.first, coded.columns).unwrap();
        }
        match feedback.next(&step, &measured).unwrap() {
            Next::Code(next) => step = next,
            Next::Keep { target_met } => {
                assert!(target_met);
                let achieved = (measured.err.sqrt() / t.norm()) as f32;
                writer.finish(achieved).unwrap();
                break (achieved, step.coding);
            }
            other => panic!("{other:?}"),
        }
    };
    let stats = t
        .code(
            &dir.path().join("driver.ltm"),
            &code,
            ltm_codec::Progress::NONE,
        )
        .unwrap();
    assert!(codings >= 2);
    assert_eq!(stats.codings, codings);
    assert_eq!(stats.achieved_error as f32, achieved);
    assert_eq!(
        std::fs::read(dir.path().join("staged.ltm")).unwrap(),
        std::fs::read(dir.path().join("driver.ltm")).unwrap()
    );
}

/// Plans are checked against the coder, and columns against the plan and
/// the matrix; the writer takes column ranges only in order.
#[test]
fn mismatched_plans_and_column_ranges_are_typed_errors() {
    let dir = tempfile::tempdir().unwrap();
    let dims = Dims::image(8, 6, 2, 1);
    let raw = RawStore::open(&write_raw(
        &dir.path().join("m.raw"),
        dims,
        &scene(dims),
        None,
        64 << 10,
    ))
    .unwrap();
    let t = Transposed::new(
        &raw,
        &TransposeOptions::default(),
        ltm_codec::Progress::NONE,
    )
    .unwrap();
    let m = dims.lights();
    let code = CodeOptions::default();
    let coder = Coder::new(&t, &code).unwrap();
    let analysis = coder.analyze(0..m, ltm_codec::Progress::NONE).unwrap();
    let spec = QuantSpec {
        quantizer: code.quantizer,
        bits: code.bits,
    };
    let other_bits = QuantSpec {
        bits: code.bits - 2,
        ..spec
    };
    let other_bits = Plan::new(&analysis, other_bits, coder.budget()).unwrap();
    let err = coder.code_columns(0..m, &other_bits).err().unwrap();
    assert!(
        matches!(err, Error::SettingsDiffer { field: "bits", .. }),
        "{err}"
    );
    let peak = Plan::new(&analysis, QuantSpec::peak(code.bits), coder.budget()).unwrap();
    let err = coder.code_columns(0..m, &peak).err().unwrap();
    assert!(
        matches!(
            err,
            Error::SettingsDiffer {
                field: "quantizer",
                ..
            }
        ),
        "{err}"
    );
    let err = coder.code_columns(0..m, &Plan::keep(3)).err().unwrap();
    assert!(
        matches!(
            err,
            Error::SettingsDiffer {
                field: "target",
                ..
            }
        ),
        "{err}"
    );
    let part = Plan::new(&analysis.for_columns(0..4).unwrap(), spec, coder.budget()).unwrap();
    assert!(coder.code_columns(0..4, &part).is_ok());
    assert!(coder.code_columns(2..6, &part).is_err());
    let plan = Plan::new(&analysis, spec, coder.budget()).unwrap();
    assert!(coder.code_columns(0..m + 1, &plan).is_err());
    let fourd = Coder::new(
        &t,
        &CodeOptions {
            mode: Mode::FourD,
            ..code.clone()
        },
    )
    .unwrap();
    let err = fourd.code_columns(0..m, &plan).err().unwrap();
    assert!(
        matches!(err, Error::SettingsDiffer { field: "mode", .. }),
        "{err}"
    );
    assert!(coder.analyze(0..m + 1, ltm_codec::Progress::NONE).is_err());
    let keep = Coder::new(
        &t,
        &CodeOptions {
            target: Target::Keep(3),
            ..code
        },
    )
    .unwrap();
    assert!(keep.analyze(0..m, ltm_codec::Progress::NONE).is_err());

    // The writer: a gap, an overlap and a range past the last column.
    let coded = coder.code_columns(0..m, &plan).unwrap();
    let mut cols = coded.columns.into_iter();
    let mut writer =
        LtmWriter::create(&dir.path().join("w.ltm"), coder.meta().clone(), None).unwrap();
    writer
        .push_columns(0, cols.by_ref().take(5).collect())
        .unwrap();
    for (first, len) in [(6, 1), (4, 1), (5, m)] {
        let batch = coder.code_columns(0..len, &plan).unwrap().columns;
        match writer.push_columns(first, batch).unwrap_err() {
            Error::ColumnRange {
                start,
                expected,
                total,
                ..
            } => {
                assert_eq!((start, expected, total), (first, 5, m))
            }
            e => panic!("{e}"),
        }
    }
    writer.push_columns(5, cols.collect()).unwrap();
    let extra = coder.code_columns(0..1, &plan).unwrap().columns;
    let err = writer.push_columns(m, extra).unwrap_err();
    assert!(
        err.to_string().contains(&format!("ending at most at {m}")),
        "{err}"
    );
    writer.finish(0.0).unwrap();

    // A restarted writer drops what it wrote and writes the same file as a
    // new one; it keeps its dimensions.
    let all = || coder.code_columns(0..m, &plan).unwrap().columns;
    let fresh = dir.path().join("fresh.ltm");
    let mut writer = LtmWriter::create(&fresh, coder.meta().clone(), None).unwrap();
    writer.push_columns(0, all()).unwrap();
    writer.finish(0.0).unwrap();
    let again = dir.path().join("again.ltm");
    let mut writer = LtmWriter::create(&again, coder.meta().clone(), None).unwrap();
    writer
        .push_columns(0, all().into_iter().take(3).collect())
        .unwrap();
    let mut writer = writer.restart(&again, coder.meta().clone()).unwrap();
    writer.push_columns(0, all()).unwrap();
    writer.finish(0.0).unwrap();
    assert_eq!(
        std::fs::read(&fresh).unwrap(),
        std::fs::read(&again).unwrap()
    );
    let mut other = coder.meta().clone();
    other.dims = Dims::image(4, 6, 2, 3);
    let writer = LtmWriter::create(&again, coder.meta().clone(), None).unwrap();
    let err = writer.restart(&again, other).err().unwrap().to_string();
    assert!(err.contains("keeps its dimensions"), "{err}");
    let leftovers = std::fs::read_dir(dir.path())
        .unwrap()
        .filter(|e| {
            e.as_ref()
                .unwrap()
                .file_name()
                .to_string_lossy()
                .contains(".tmp")
        })
        .count();
    assert_eq!(leftovers, 0, "temporary files left behind");
}

/// Mutated and truncated files must give errors, never panics.
#[test]
fn hostile_files_error_and_never_panic() {
    let dir = tempfile::tempdir().unwrap();
    let dims = Dims::image(8, 6, 2, 3);
    let t = scene(dims);
    let raw = write_raw(&dir.path().join("x.raw"), dims, &t, None, 64 << 10);
    let (out, _) = run(dir.path(), &raw, &CompressOptions::default(), "x.ltm");
    let packed = std::fs::read(&out).unwrap();
    // Mutated as written (a packed column table) and with every chunk
    // stored as is, whose column CRCs `repair_checksums` can rewrite.
    let unpacked = ltm_codec::container::unpack_chunks(&packed).unwrap();
    let check = |bytes: &[u8]| {
        let _ = ltm_codec::container::validate_bytes(bytes, &ltm_codec::Limits::default());
        // Also past the checksums, to reach the structural checks.
        let mut repaired = bytes.to_vec();
        ltm_codec::container::repair_checksums(&mut repaired);
        let _ = ltm_codec::container::validate_bytes(&repaired, &ltm_codec::Limits::default());
        let path = dir.path().join("mut.ltm");
        std::fs::write(&path, bytes).unwrap();
        if let Ok(f) = LtmFile::open(&path) {
            for j in 0..f.columns().len() {
                let _ = f.column(j);
            }
        }
    };
    let mut s = 0x1234_5678_9abc_def0u64;
    for good in [&packed, &unpacked] {
        for len in 0..good.len() {
            check(&good[..len]);
        }
        for _ in 0..3000 {
            let mut bytes = good.clone();
            for _ in 0..1 + (s % 4) {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                let i = (s % bytes.len() as u64) as usize;
                bytes[i] ^= 1 << (s >> 60 & 7);
            }
            check(&bytes);
        }
    }
    // A header that claims a newer version is refused with a clear message.
    let mut newer = packed.clone();
    let next = ltm_codec::container::VERSION + 1;
    newer[8..12].copy_from_slice(&next.to_le_bytes());
    let err = LtmFile::parse(&newer, &ltm_codec::Limits::default())
        .unwrap_err()
        .to_string();
    assert!(err.contains(&format!("version {next}")), "{err}");
}

/// The message `LtmFile::parse` gives for `good` mutated by `mutate`, with
/// every checksum repaired ("" when it parses).
fn parse_repaired(good: &[u8], mutate: &dyn Fn(&mut Vec<u8>)) -> String {
    let mut b = good.to_vec();
    mutate(&mut b);
    ltm_codec::container::repair_checksums(&mut b);
    LtmFile::parse(&b, &Limits::default())
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default()
}

/// The directory entry of chunk `tag`: (entry offset, chunk offset, length).
fn chunk_entry(bytes: &[u8], tag: &[u8; 4]) -> (usize, usize, usize) {
    let count = u32::from_le_bytes(bytes[16..20].try_into().unwrap()) as usize;
    let at = |k: usize, o: usize| u64::from_le_bytes(bytes[k + o..k + o + 8].try_into().unwrap());
    (0..count)
        .map(|k| 24 + 32 * k)
        .find(|&e| &bytes[e..e + 4] == tag)
        .map(|e| (e, at(e, 8) as usize, at(e, 16) as usize))
        .expect("the chunk")
}

/// A NORM chunk (of a version-5 file: version 8 writes none) that is not
/// one finite norm ≥ 0 per column, or that disagrees with its feature flag
/// or the file's version, is refused with a message naming it, even with
/// every checksum repaired; the relighter refuses a column whose stored
/// norm differs from its decoded one (see relight/tests/it/lazy.rs).
#[test]
fn bad_column_norms_are_refused() {
    let good = std::fs::read(fixture("golden-v5.ltm")).unwrap();
    let dims = LtmFile::open(&fixture("golden-v5.ltm"))
        .unwrap()
        .meta()
        .dims;
    let (_, norm_at, norm_len) = chunk_entry(&good, b"NORM");
    assert_eq!(norm_len, 4 * dims.lights());
    let parse = |mutate: &dyn Fn(&mut Vec<u8>)| parse_repaired(&good, mutate);
    for bad in [f32::NAN, f32::INFINITY, -1.0, -f32::MIN_POSITIVE] {
        let err = parse(&|b| b[norm_at + 12..norm_at + 16].copy_from_slice(&bad.to_le_bytes()));
        assert!(
            err.contains("column norm") && err.contains("column 3"),
            "{bad}: {err}"
        );
    }
    // The flag cleared with the chunk still there.
    let err = parse(&|b| b[12] &= !8);
    assert!(err.contains("NORM"), "{err}");
    // A version-4 header knows no feature 8.
    let err = parse(&|b| b[8] = 4);
    assert!(
        err.contains("feature flags") && err.contains("version 4"),
        "{err}"
    );
    // One column short.
    let err = parse(&|b| {
        let (entry, _, _) = chunk_entry(b, b"NORM");
        b[entry + 16..entry + 24].copy_from_slice(&(norm_len as u64 - 4).to_le_bytes());
    });
    assert!(err.contains("NORM chunk"), "{err}");
    assert_eq!(parse(&|_| {}), "");
}

#[test]
fn hostile_raw_stores_error() {
    let dir = tempfile::tempdir().unwrap();
    let dims = Dims::image(4, 4, 2, 1);
    let raw = write_raw(
        &dir.path().join("r.raw"),
        dims,
        &scene(dims),
        None,
        64 << 10,
    );
    let good = std::fs::read(&raw).unwrap();
    let path = dir.path().join("bad.raw");
    for len in [0, 7, 63, 64, 100, good.len() - 1] {
        std::fs::write(&path, &good[..len]).unwrap();
        assert!(RawStore::open(&path).is_err(), "truncated to {len}");
    }
    let mut flipped = good.clone();
    let last = flipped.len() - 1;
    flipped[last] ^= 0x40;
    std::fs::write(&path, &flipped).unwrap();
    let store = RawStore::open(&path).unwrap();
    assert!((0..store.header().block_count()).any(|b| store.verify_block(b).is_err()));
}

/// Inputs the fuzzers once found, kept as regression tests. Files named
/// `*.crc-fixed.ltm` are run as the `ltm_decode_crc_fixed` target runs them,
/// after `repair_checksums`.
#[test]
fn fuzz_regressions_are_errors() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fuzz/regressions");
    let mut n = 0;
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        if name.ends_with(".ltm") {
            let mut bytes = std::fs::read(&path).unwrap();
            if name.ends_with(".crc-fixed.ltm") {
                ltm_codec::container::repair_checksums(&mut bytes);
            }
            assert!(
                ltm_codec::container::validate_bytes(&bytes, &ltm_codec::Limits::default())
                    .is_err(),
                "{name}"
            );
            n += 1;
        }
    }
    assert!(n >= 4);
}

/// The raw store and the codec's output are deterministic: the same input
/// and options give the same bytes on every machine and thread count. A
/// change to these hashes is a change of the formats or of the encoder's
/// decisions and must be deliberate.
#[test]
fn golden_hashes_of_deterministic_outputs() {
    let dir = tempfile::tempdir().unwrap();
    let dims = Dims::image(24, 20, 4, 3);
    // Arithmetic only (no libm), so the input is bit-identical everywhere.
    let t = golden_matrix(dims);
    let raw = write_raw(&dir.path().join("g.raw"), dims, &t, None, 64 << 10);
    let raw_crc = crc32fast::hash(&std::fs::read(&raw).unwrap());
    let (out, _) = run(dir.path(), &raw, &fixture_options(), "g.ltm");
    let ltm_crc = crc32fast::hash(&std::fs::read(&out).unwrap());
    assert_eq!(raw_crc, GOLDEN_RAW);
    assert_eq!(ltm_crc, GOLDEN_LTM);
    let (out, _) = run(dir.path(), &raw, &CompressOptions::default(), "u.ltm");
    let uniform_crc = crc32fast::hash(&std::fs::read(&out).unwrap());
    assert_eq!(uniform_crc, GOLDEN_LTM_UNIFORM, "{uniform_crc:#x}");
}

/// The options the golden fixtures were written with: the defaults before
/// the uniform quantizer (the peak quantizer at 10 bits).
fn fixture_options() -> CompressOptions {
    CodeOptions {
        quantizer: Quantizer::Peak,
        bits: 10,
        raise_bits: false,
        ..Default::default()
    }
    .into()
}

/// The golden matrix's raw store and its `.ltm` file at `opts`, in `dir`.
fn golden_file(dir: &Path, opts: &CompressOptions) -> PathBuf {
    let dims = Dims::image(24, 20, 4, 3);
    let raw = write_raw(
        &dir.join("g.raw"),
        dims,
        &golden_matrix(dims),
        None,
        64 << 10,
    );
    run(dir, &raw, opts, "g.ltm").0
}

/// The matrix of the golden hashes (24 × 20 pixels, n = 4, RGB).
fn golden_matrix(dims: Dims) -> Vec<f32> {
    let m = dims.lights();
    (0..dims.pixels() * m * 3)
        .map(|i| {
            let (p, j, c) = (i / (3 * m), i / 3 % m, i % 3);
            if (p % 24) * (p / 24) % 7 == 3 {
                0.0
            } else {
                ((p * 7 + j * 13 + c) % 23) as f32 / 23.0 * (1 + p % 5) as f32 / (1 + j % 3) as f32
            }
        })
        .collect()
}

/// The committed version-1 fixture `tests/fixtures/golden-v1.ltm`.
const GOLDEN_LTM_V1: u32 = 0x5832_3993;

const GOLDEN_RAW: u32 = 0xf20f_83f3;
/// [`fixture_options`]: adaptive, the peak quantizer at 10 bits, 1 %
/// target (version 9: encoding 6 from the file's priors, the column table
/// in planes, no NORM).
const GOLDEN_LTM: u32 = 0xdec3_6952;
/// The committed version-8 fixture `tests/fixtures/golden-v8.ltm`: the
/// same options, written before version 9 (encoding 5, no priors).
const GOLDEN_LTM_V8: u32 = 0x871f_e682;
/// The committed version-7 fixture `tests/fixtures/golden-v7.ltm`: the
/// same options, written before version 8 (encoding 5, planes, no norms).
const GOLDEN_LTM_V7: u32 = 0xce3f_8a13;
/// The default options: adaptive, the uniform quantizer at 16 bits, 1 %.
const GOLDEN_LTM_UNIFORM: u32 = 0xb608_e547;
/// The committed version-5 fixture `tests/fixtures/golden-v5.ltm`: the
/// same options, written before version 6 (the receiver mesh). A file
/// without a mesh differs from version 6 only in its version field and
/// directory CRC, which leave the CRC of the whole file unchanged (the
/// CRC-32 of any bytes followed by their own CRC-32 is a constant): the
/// version check of `old_fixture_decodes` tells the two apart.
const GOLDEN_LTM_V5: u32 = 0xe48a_2fdb;
/// The committed version-4 fixture `tests/fixtures/golden-v4.ltm`: the
/// same options, written before version 5 (the column norms).
const GOLDEN_LTM_V4: u32 = 0xd11d_24af;
/// The committed version-3 fixture `tests/fixtures/golden-v3.ltm`: the
/// same options, written before version 4 (column encoding 3).
const GOLDEN_LTM_V3: u32 = 0x0c2f_934d;

/// An `.ltm` file is read whole at open, charged to the budget: truncated
/// or rewritten after open, it decodes as it was opened (no memory map, so
/// no SIGBUS); one truncated before open is refused; one larger than the
/// budget is refused with its size and the budget.
#[test]
fn a_file_truncated_after_open_decodes_as_opened() {
    let dir = tempfile::tempdir().unwrap();
    let dims = Dims::image(16, 12, 4, 3);
    let raw = write_raw(&dir.path().join("t.raw"), dims, &scene(dims), None, 1 << 16);
    let (path, _) = run(dir.path(), &raw, &CompressOptions::default(), "t.ltm");
    let len = std::fs::metadata(&path).unwrap().len();
    let limits = Limits::with_max_alloc(1 << 30);
    let file = LtmFile::open_with_limits(&path, &limits).unwrap();
    assert!(limits.used_bytes() >= len, "the file's bytes are charged");
    let want = decode_matrix(&file, &limits).unwrap();
    let f = std::fs::OpenOptions::new().write(true).open(&path).unwrap();
    f.set_len(len / 3).unwrap();
    assert_eq!(decode_matrix(&file, &limits).unwrap(), want);
    f.set_len(0).unwrap();
    f.set_len(len).unwrap(); // all zero now
    assert_eq!(decode_matrix(&file, &limits).unwrap(), want);
    drop(file);
    assert_eq!(limits.used_bytes(), 0);
    let e = LtmFile::open(&path).err().unwrap().to_string();
    assert!(e.contains("not an .ltm file"), "{e}");
    let (cut, _) = run(dir.path(), &raw, &CompressOptions::default(), "cut.ltm");
    std::fs::OpenOptions::new()
        .write(true)
        .open(&cut)
        .unwrap()
        .set_len(len / 2)
        .unwrap();
    assert!(LtmFile::open(&cut).is_err());
    let (whole, _) = run(dir.path(), &raw, &CompressOptions::default(), "whole.ltm");
    let small = Limits::with_max_alloc(len / 2);
    let e = LtmFile::open_with_limits(&whole, &small).err().unwrap();
    assert!(
        matches!(e, Error::Limit { needed, .. } if needed == len),
        "{e}"
    );
}

/// The default transpose memory is a budget `TransposeOptions` accepts,
/// within its documented bounds.
#[test]
fn the_default_transpose_budget_is_valid() {
    let b = ltm_codec::default_mem_budget();
    assert!(((1 << 20)..=(8 << 30)).contains(&b), "{b}");
    let options = TransposeOptions {
        mem_budget: b,
        ..TransposeOptions::default()
    };
    assert!(options.validate().is_ok());
}

/// The uniform quantizer (one step for the matrix, tied to the threshold)
/// spends fewer bytes than the peak quantizer (each band's step from its
/// largest value) for the same target, grey and RGB, at 1 % and 3 %: the
/// reason it is the default.
#[test]
fn uniform_quantizer_codes_the_same_target_in_fewer_bytes() {
    let dir = tempfile::tempdir().unwrap();
    for dims in [Dims::image(40, 30, 4, 1), Dims::image(40, 30, 4, 3)] {
        let t = scene(dims);
        let raw = write_raw(&dir.path().join("q.raw"), dims, &t, None, 64 << 10);
        for target in [0.01, 0.03] {
            let size = |quantizer: Quantizer| {
                let opts: CompressOptions = CodeOptions {
                    quantizer,
                    bits: quantizer.default_bits(),
                    target: Target::MaxError(target),
                    ..Default::default()
                }
                .into();
                let (out, stats) = run(dir.path(), &raw, &opts, "q.ltm");
                assert!(stats.target_met, "{quantizer:?} {stats:?}");
                std::fs::metadata(out).unwrap().len() as f64
            };
            let (uniform, peak) = (size(Quantizer::Uniform), size(Quantizer::Peak));
            assert!(
                uniform < 0.95 * peak,
                "{} channels at {target}: uniform {uniform} B, peak {peak} B",
                dims.channels
            );
        }
    }
}
