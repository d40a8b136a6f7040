//! A hostile user's inputs: matrices at and beyond the ends of the f32
//! range, raw stores that change or shrink while they are read, and crafted
//! raw stores whose fields lie. Each must round-trip within its target or
//! fail with an error that names the problem, never panic, signal or write
//! an output.

use ltm_codec::compress::Mode;
use ltm_codec::compress::{
    compress, CodeOptions, CompressOptions, Target, MAX_NORM, MIN_NONZERO_RMS,
};
use ltm_codec::container::LtmFile;
use ltm_codec::npy::decode_matrix;
use ltm_codec::{
    ColumnDecoder, Dims, Error, Filter, Limits, Meta, Progress, RawHeader, RawStore, RawWriter,
    SparseColumn, Stage, Step,
};
use ltm_testkit::write_raw;
use proptest::prelude::*;
use std::path::{Path, PathBuf};

// ---------------------------------------------------------------------------
// Helpers

/// Deterministic values in `[0, 1)`.
fn lcg(s: &mut u64) -> f64 {
    *s = s
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    (*s >> 11) as f64 / (1u64 << 53) as f64
}

/// Matrix shapes that stress the transforms and the quantizer differently.
#[derive(Clone, Copy, Debug)]
enum Shape {
    /// Smooth positive rows, a zero background.
    Scene,
    /// One nonzero entry.
    Delta,
    /// Every entry equal.
    Constant,
    /// Alternating signs in every direction (all energy in the finest bands).
    Checker,
    /// Random signs, magnitudes log-uniform over 12 decades.
    Wide,
    /// Half the columns 10^20 times smaller than the others, zero columns.
    Mixed,
}

const SHAPES: [Shape; 6] = [
    Shape::Scene,
    Shape::Delta,
    Shape::Constant,
    Shape::Checker,
    Shape::Wide,
    Shape::Mixed,
];

/// `shape` for `dims`, in f64 (to be scaled before rounding to f32).
fn base(shape: Shape, dims: Dims) -> Vec<f64> {
    let (w, m, c) = (dims.width() as usize, dims.lights(), dims.channels as usize);
    let mut s = 0x5eed_u64;
    (0..dims.pixels() * m * c)
        .map(|i| {
            let (p, j, ch) = (i / (m * c), i / c % m, i % c);
            let (x, y) = (p % w, p / w);
            match shape {
                Shape::Scene if (x + 2 * y) % 7 == 3 => 0.0,
                Shape::Scene => {
                    (1.0 + (x as f64 * 0.3 + j as f64 * 0.2).sin()) * 0.01 * (1 + ch) as f64
                }
                Shape::Delta => f64::from(u8::from(p == 17 && j == 5)),
                Shape::Constant => 0.5,
                Shape::Checker => {
                    if (x + y + j + ch) % 2 == 0 {
                        1.0
                    } else {
                        -1.0
                    }
                }
                Shape::Wide => {
                    let mag = 10f64.powf(-12.0 * lcg(&mut s));
                    if lcg(&mut s) < 0.5 {
                        -mag
                    } else {
                        mag
                    }
                }
                Shape::Mixed if j % 5 == 4 => 0.0,
                Shape::Mixed if j % 2 == 1 => 1e-20 * (1 + p % 3) as f64,
                Shape::Mixed => (1 + (p + j) % 4) as f64,
            }
        })
        .collect()
}

/// `base · 10^exponent` rounded to f32, or `None` if a value overflows f32.
fn scaled(base: &[f64], exponent: i32) -> Option<Vec<f32>> {
    let s = 10f64.powi(exponent);
    let t: Vec<f32> = base.iter().map(|v| (v * s) as f32).collect();
    t.iter().all(|v| v.is_finite()).then_some(t)
}

/// Relative L2 error of `a` against the exact `b`, in f64.
fn rel_error(a: &[f32], b: &[f32]) -> f64 {
    let num: f64 = a
        .iter()
        .zip(b)
        .map(|(x, y)| (*x as f64 - *y as f64).powi(2))
        .sum();
    let den: f64 = b.iter().map(|y| (*y as f64).powi(2)).sum();
    if den == 0.0 {
        num.sqrt()
    } else {
        (num / den).sqrt()
    }
}

/// Whether the codec's range holds `t`: zero, or a norm of at most
/// `MAX_NORM` and a nonzero RMS of at least `MIN_NONZERO_RMS`.
fn in_range(t: &[f32]) -> bool {
    let nz: Vec<f64> = t.iter().filter(|v| **v != 0.0).map(|v| *v as f64).collect();
    let sum_sq: f64 = nz.iter().map(|v| v * v).sum();
    nz.is_empty()
        || (sum_sq.sqrt() <= MAX_NORM && (sum_sq / nz.len() as f64).sqrt() >= MIN_NONZERO_RMS)
}

/// Compresses `t` with `code` and checks the outcome: within the range, the
/// file meets the target measured against `t` in f64 and decodes to finite
/// values; outside, an out-of-range error naming the quantity and no file.
fn check_round_trip(dims: Dims, t: &[f32], code: CodeOptions, what: &str) {
    let dir = tempfile::tempdir().unwrap();
    let raw = RawStore::open(&write_raw(
        &dir.path().join("m.raw"),
        dims,
        t,
        None,
        4 << 10,
    ))
    .unwrap();
    let out = dir.path().join("m.ltm");
    let target = match code.target {
        Target::MaxError(e) => e,
        _ => unreachable!(),
    };
    match compress(&raw, &out, &code.into(), ltm_codec::Progress::NONE) {
        Ok(stats) => {
            assert!(in_range(t), "{what}: accepted outside the range");
            let file = LtmFile::open(&out).unwrap_or_else(|e| panic!("{what}: {e}"));
            let mut dense = decode_matrix(&file, &Limits::default()).unwrap();
            if file.meta().dims.channels < dims.channels {
                // Stored grey: every value stands for R, G and B.
                dense = dense.iter().flat_map(|&v| [v; 3]).collect();
            }
            assert_eq!(dense.len(), t.len(), "{what}");
            assert!(dense.iter().all(|v| v.is_finite()), "{what}: non-finite");
            let err = rel_error(&dense, t);
            assert!(stats.target_met, "{what}: target missed, {stats:?}");
            assert!(err <= target * 1.0001, "{what}: error {err} > {target}");
            assert!(
                (err - stats.achieved_error).abs() <= 1e-3 * target,
                "{what}: measured {err}, reported {}",
                stats.achieved_error
            );
        }
        Err(e) => {
            assert!(!in_range(t), "{what}: refused within the range: {e}");
            let msg = e.to_string();
            assert!(
                matches!(e, Error::OutOfRange { .. })
                    && (msg.contains("norm") && msg.contains("2^100")
                        || msg.contains("root mean square") && msg.contains("2^-120")),
                "{what}: {msg}"
            );
            assert!(!out.exists(), "{what}: wrote a file");
        }
    }
}

fn target_options(mode: Mode, col_filter: Filter, target: f64) -> CodeOptions {
    CodeOptions {
        mode,
        col_filter,
        raise_bits: true,
        target: Target::MaxError(target),
        ..Default::default()
    }
}

// ---------------------------------------------------------------------------
// 1. Extreme values

/// Every shape at every power of ten f32 can hold round-trips within its
/// target or is refused by the range check, never anything else.
#[test]
fn scaled_matrices_meet_the_target_or_are_refused() {
    let dims = Dims::image(12, 10, 2, 1);
    for shape in SHAPES {
        let b = base(shape, dims);
        for exponent in (-46..=39).step_by(2) {
            let Some(t) = scaled(&b, exponent) else {
                continue;
            };
            let what = format!("{shape:?} × 1e{exponent}");
            check_round_trip(
                dims,
                &t,
                target_options(Mode::Adaptive, Filter::LeGall53, 0.01),
                &what,
            );
        }
    }
}

/// The ends of the range themselves, with every column filter and mode:
/// a norm just below 2^100 and a nonzero RMS just above 2^-120.
#[test]
fn matrices_at_the_ends_of_the_range_round_trip() {
    let dims = Dims::image(9, 7, 2, 1);
    for shape in SHAPES {
        let b = base(shape, dims);
        let nz: Vec<f64> = b.iter().copied().filter(|v| *v != 0.0).collect();
        let sum_sq: f64 = nz.iter().map(|v| v * v).sum();
        let (norm, rms) = (sum_sq.sqrt(), (sum_sq / nz.len() as f64).sqrt());
        for scale in [MAX_NORM * 0.999 / norm, MIN_NONZERO_RMS * 1.001 / rms] {
            let t: Vec<f32> = b.iter().map(|v| (v * scale) as f32).collect();
            assert!(in_range(&t));
            for col_filter in Filter::ALL {
                for mode in [Mode::TwoD, Mode::FourD, Mode::Adaptive] {
                    let what = format!("{shape:?} × {scale:e}, {col_filter} {mode:?}");
                    check_round_trip(dims, &t, target_options(mode, col_filter, 0.01), &what);
                }
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 40, ..ProptestConfig::default() })]

    /// Any shape, scale exponent, filter, mode and target.
    #[test]
    fn any_scale_meets_its_target_or_is_refused(
        shape in 0..SHAPES.len(),
        exponent in -38i32..=38,
        filter in 0..Filter::ALL.len(),
        mode in 0..3usize,
        target in 0.002f64..0.2,
        three in any::<bool>(),
    ) {
        let dims = Dims::image(8, 6, 2, if three { 3 } else { 1 });
        if let Some(t) = scaled(&base(SHAPES[shape], dims), exponent) {
            let mode = [Mode::TwoD, Mode::FourD, Mode::Adaptive][mode];
            let what = format!("{:?} × 1e{exponent}", SHAPES[shape]);
            check_round_trip(dims, &t, target_options(mode, Filter::ALL[filter], target), &what);
        }
    }
}

/// A matrix scaled by 1e-23 used to lose every value (its squared
/// magnitudes underflowed f32) while the coder blamed the bits.
#[test]
fn tiny_matrices_keep_their_values() {
    let dims = Dims::image(12, 10, 2, 1);
    let t = scaled(&base(Shape::Scene, dims), -23).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let raw = RawStore::open(&write_raw(
        &dir.path().join("m.raw"),
        dims,
        &t,
        None,
        4 << 10,
    ))
    .unwrap();
    let out = dir.path().join("m.ltm");
    let stats = compress(
        &raw,
        &out,
        &CompressOptions::default(),
        ltm_codec::Progress::NONE,
    )
    .unwrap();
    assert!(stats.target_met && stats.nonzeros > 0, "{stats:?}");
    // Coded at the bits asked for: none were blamed.
    assert_eq!(stats.bits, CompressOptions::default().code.bits);
}

/// Columns 10^20 apart (the small ones far below the error budget) leave a
/// gap in the histogram over which the estimated error is flat: a re-coding
/// after a miss must still lower the threshold, or every re-coding repeats
/// the first (16 bits missed 1 % here).
#[test]
fn recoding_lowers_the_threshold_across_a_gap() {
    let dims = Dims::image(12, 10, 2, 1);
    let t = scaled(&base(Shape::Mixed, dims), 10).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let raw = RawStore::open(&write_raw(
        &dir.path().join("m.raw"),
        dims,
        &t,
        None,
        4 << 10,
    ))
    .unwrap();
    let out = dir.path().join("m.ltm");
    let code = CodeOptions {
        bits: 16,
        target: Target::MaxError(0.01),
        ..Default::default()
    };
    let stats = compress(&raw, &out, &code.into(), ltm_codec::Progress::NONE).unwrap();
    assert!(
        stats.target_met && stats.achieved_error <= 0.01,
        "{stats:?}"
    );
    let dense = decode_matrix(&LtmFile::open(&out).unwrap(), &Limits::default()).unwrap();
    assert!(rel_error(&dense, &t) <= 0.01);
}

/// A constant 3e38 matrix (its row transform overflows f32) and a matrix
/// scaled by 1e36 are refused before any output, naming the norm and the
/// valid range.
#[test]
fn huge_matrices_are_refused_up_front() {
    let dims = Dims::image(12, 10, 2, 1);
    let constant = vec![3e38f32; dims.pixels() * dims.lights()];
    let big = scaled(&base(Shape::Scene, dims), 36).unwrap();
    for t in [constant, big] {
        let dir = tempfile::tempdir().unwrap();
        let raw = RawStore::open(&write_raw(
            &dir.path().join("m.raw"),
            dims,
            &t,
            None,
            4 << 10,
        ))
        .unwrap();
        let out = dir.path().join("m.ltm");
        let err = compress(
            &raw,
            &out,
            &CompressOptions::default(),
            ltm_codec::Progress::NONE,
        )
        .unwrap_err();
        let msg = err.to_string();
        assert!(
            msg.contains("matrix norm") && msg.contains("2^100"),
            "{msg}"
        );
        assert!(!out.exists());
        assert_eq!(
            std::fs::read_dir(dir.path()).unwrap().count(),
            1,
            "only the raw store"
        );
    }
}

/// An albedo image with NaN or infinity is refused by the writer, and a
/// store whose albedo was patched to NaN (CRCs fixed) is refused at open.
#[test]
fn non_finite_albedo_is_refused() {
    let dims = Dims::image(4, 3, 2, 1);
    let t = vec![0.25f32; dims.pixels() * dims.lights()];
    let dir = tempfile::tempdir().unwrap();
    for bad in [f32::NAN, f32::INFINITY] {
        let mut albedo = vec![0.5f32; 3 * dims.pixels()];
        albedo[7] = bad;
        let header = RawHeader::new(dims, true, 1 << 10);
        let err = RawWriter::write_dense(&dir.path().join("a.raw"), header, &t, Some(&albedo))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("albedo") && err.contains("pixel 2, channel 1"),
            "{err}"
        );
    }
    let albedo = vec![0.5f32; 3 * dims.pixels()];
    let path = write_raw(&dir.path().join("m.raw"), dims, &t, Some(&albedo), 1 << 10);
    let mut bytes = std::fs::read(&path).unwrap();
    let f = Fields::of(&bytes);
    let at = f.albedo_offset + 4 * 7;
    bytes[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    f.fix_block_crc(&mut bytes, 7 / 3 / f.block_rows);
    std::fs::write(&path, &bytes).unwrap();
    let err = RawStore::open(&path).err().unwrap().to_string();
    assert!(
        err.contains("albedo value = NaN (pixel 2, channel 1)") && err.contains("finite"),
        "{err}"
    );
}

/// The header of a grey 8×8 image at face resolution 1, 4d mode.
fn grey_8x8_meta() -> Meta {
    Meta {
        dims: Dims::image(8, 8, 1, 1),
        mode: Mode::FourD,
        row_filter: Filter::Haar,
        col_filter: Filter::LeGall53,
        bits: 16,
        seed: 0,
        target_error: 0.01,
        achieved_error: 0.0,
        terms: 0,
        norm: 1.0,
    }
}

/// A crafted column with the largest scale code dequantizes to finite
/// values, and decoding it is an error rather than a plane of infinities.
#[test]
fn crafted_scale_codes_never_decode_to_infinity() {
    let meta = grey_8x8_meta();
    let decoder = ColumnDecoder::new(&meta, &Limits::default()).unwrap();
    let depth = meta.max_depth();
    let col = SparseColumn {
        depth,
        scale_codes: vec![u16::MAX; depth as usize + 1],
        indices: (0..64).collect(),
        values: vec![32767; 64],
    };
    for k in 0..64 {
        assert!(decoder.dequantize(&col, k, 0).is_finite());
    }
    let (mut plane, mut work) = (vec![0.0f32; 64], vec![0.0f32; 64]);
    let err = decoder
        .decode(&col, 0, &mut plane, &mut work)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("decoded column value") && err.contains("2^112"),
        "{err}"
    );
}

/// A column built by a caller, not a reader: a channel, a position or a
/// count of values out of range is an error naming it, not a panic.
#[test]
fn columns_out_of_range_are_errors() {
    let meta = grey_8x8_meta();
    let decoder = ColumnDecoder::new(&meta, &Limits::default()).unwrap();
    let good = SparseColumn {
        depth: 1,
        scale_codes: vec![0; 2],
        indices: vec![0, 63],
        values: vec![1, -1],
    };
    let (mut plane, mut work) = (vec![0.0f32; 64], vec![0.0f32; 64]);
    decoder.decode(&good, 0, &mut plane, &mut work).unwrap();
    let cases = [
        (good.clone(), 1, "channel = 1"),
        (
            SparseColumn {
                indices: vec![0, 64],
                ..good.clone()
            },
            0,
            "column position = 64",
        ),
        (
            SparseColumn {
                values: vec![1],
                ..good.clone()
            },
            0,
            "needs 2",
        ),
    ];
    for (col, channel, want) in cases {
        let err = decoder
            .decode(&col, channel, &mut plane, &mut work)
            .unwrap_err()
            .to_string();
        assert!(err.contains(want), "{err}");
    }
}

// ---------------------------------------------------------------------------
// 2. Inputs that change while they are read

/// A grey store of `dims` (so that the monochrome check of three channels
/// reads every row) with one block per 8 rows and a 1 MiB budget, so that
/// the row pass reads in several steps.
fn several_reads(dir: &Path, dims: Dims) -> (PathBuf, CompressOptions) {
    let grey = base(
        Shape::Scene,
        Dims {
            channels: 1,
            ..dims
        },
    );
    let c = dims.channels as usize;
    let t: Vec<f32> = grey.iter().flat_map(|v| vec![*v as f32; c]).collect();
    let path = write_raw(
        &dir.join("m.raw"),
        dims,
        &t,
        None,
        8 * dims.row_len() as u64 * 4,
    );
    let mut opts = CompressOptions::default();
    opts.transpose.mem_budget = 1 << 20;
    (path, opts)
}

/// No file but the raw store is left in `dir`.
fn only_the_input(dir: &Path) {
    let names: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names, ["m.raw"], "{names:?}");
}

/// The raw store is truncated to a quarter after the row pass's first read
/// (the next rows lie past its end): an I/O error that says so, not
/// SIGBUS, and no output.
#[test]
fn truncating_the_input_during_the_row_pass_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let dims = Dims::image(48, 40, 4, 1);
    let (path, opts) = several_reads(dir.path(), dims);
    let raw = RawStore::open(&path).unwrap();
    let out = dir.path().join("m.ltm");
    let truncate = |s: Step| {
        if s.stage == Stage::Rows && s.done < s.total {
            let f = std::fs::OpenOptions::new().write(true).open(&path).unwrap();
            f.set_len(std::fs::metadata(&path).unwrap().len() / 4)
                .unwrap();
        }
    };
    let err = compress(&raw, &out, &opts, Progress::new(&truncate)).unwrap_err();
    assert!(matches!(err, Error::Io { .. }), "{err}");
    assert!(chain(&err).contains("truncated while being read"), "{err}");
    only_the_input(dir.path());
}

/// Truncated to half between open and compress (three grey channels, so
/// the monochrome check reads every row first), and under `verify_block`
/// and `read_rows`.
#[test]
fn reading_a_truncated_input_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let dims = Dims::image(16, 12, 2, 3);
    let (path, opts) = several_reads(dir.path(), dims);
    let raw = RawStore::open(&path).unwrap();
    let len = std::fs::metadata(&path).unwrap().len();
    let f = std::fs::OpenOptions::new().write(true).open(&path).unwrap();
    f.set_len(len / 2).unwrap();
    let out = dir.path().join("m.ltm");
    let err = compress(&raw, &out, &opts, ltm_codec::Progress::NONE).unwrap_err();
    assert!(chain(&err).contains("truncated while being read"), "{err}");
    only_the_input(dir.path());
    let last = raw.header().block_count() - 1;
    assert!(raw.verify_block(last).is_err());
    let mut buf = Vec::new();
    assert!(raw.read_rows(0..dims.pixels(), &mut buf).is_err());
    assert!(raw.read_rows(0..1, &mut buf).is_ok());
}

/// Bytes rewritten in place during the row pass (same length) are caught
/// by the block CRCs read at open; a modification time changed during the
/// coding is caught before the output is written.
#[test]
fn changing_the_input_during_compress_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let dims = Dims::image(48, 40, 4, 1);
    let (path, opts) = several_reads(dir.path(), dims);
    let out = dir.path().join("m.ltm");
    let data_offset = Fields::of(&std::fs::read(&path).unwrap()).data_offset;
    let len = std::fs::metadata(&path).unwrap().len();
    let overwrite = |s: Step| {
        if s.stage == Stage::Rows && s.done < s.total {
            use std::os::unix::fs::FileExt;
            let f = std::fs::OpenOptions::new().write(true).open(&path).unwrap();
            let at = data_offset as u64 + (len - data_offset as u64) * 9 / 10;
            f.write_all_at(&1.5f32.to_le_bytes(), at).unwrap();
        }
    };
    let raw = RawStore::open(&path).unwrap();
    let err = compress(&raw, &out, &opts, Progress::new(&overwrite)).unwrap_err();
    assert!(matches!(err, Error::Crc { .. }), "{err}");
    only_the_input(dir.path());

    let (path, opts) = several_reads(dir.path(), dims);
    let raw = RawStore::open(&path).unwrap();
    let touch = |s: Step| {
        if s.stage == Stage::Coding {
            let f = std::fs::OpenOptions::new().write(true).open(&path).unwrap();
            f.set_modified(std::time::UNIX_EPOCH + std::time::Duration::from_secs(1000))
                .unwrap();
        }
    };
    let err = compress(&raw, &out, &opts, Progress::new(&touch)).unwrap_err();
    assert!(chain(&err).contains("changed while it was read"), "{err}");
    only_the_input(dir.path());
}

// ---------------------------------------------------------------------------
// 3. Crafted raw stores

/// Fields of a raw store's layout, read from its header.
struct Fields {
    block_rows: usize,
    block_count: usize,
    row_bytes: usize,
    flags_offset: usize,
    albedo_offset: usize,
    data_offset: usize,
}

impl Fields {
    fn of(bytes: &[u8]) -> Fields {
        let u32_at = |o: usize| u32::from_le_bytes(bytes[o..o + 4].try_into().unwrap()) as usize;
        let u64_at = |o: usize| u64::from_le_bytes(bytes[o..o + 8].try_into().unwrap()) as usize;
        let (n, c) = (u32_at(24), u32_at(28));
        let block_count = u32_at(36);
        Fields {
            block_rows: u32_at(32),
            block_count,
            row_bytes: 6 * n * n * c * 4,
            flags_offset: 64 + 8 * block_count,
            albedo_offset: u64_at(48),
            data_offset: u64_at(40),
        }
    }

    fn pixels(&self, bytes: &[u8]) -> usize {
        (bytes.len() - self.data_offset) / self.row_bytes
    }

    fn fix_header_crc(bytes: &mut [u8]) {
        let crc = crc32fast::hash(&bytes[..60]);
        bytes[60..64].copy_from_slice(&crc.to_le_bytes());
    }

    /// Rewrites block `b`'s CRC in the block table to match its bytes.
    fn fix_block_crc(&self, bytes: &mut [u8], b: usize) {
        let p = self.pixels(bytes);
        let rows = b * self.block_rows..((b + 1) * self.block_rows).min(p);
        let mut h = crc32fast::Hasher::new();
        h.update(&bytes[self.flags_offset + rows.start..self.flags_offset + rows.end]);
        if self.albedo_offset != 0 {
            h.update(
                &bytes[self.albedo_offset + 12 * rows.start..self.albedo_offset + 12 * rows.end],
            );
        }
        h.update(
            &bytes[self.data_offset + rows.start * self.row_bytes
                ..self.data_offset + rows.end * self.row_bytes],
        );
        let at = 64 + 8 * b + 4;
        bytes[at..at + 4].copy_from_slice(&h.finalize().to_le_bytes());
    }
}

/// A valid store (background rows are zero) to patch, its bytes and a path
/// for the patched copy.
fn crafted(dir: &Path) -> (Vec<u8>, PathBuf) {
    let dims = Dims::image(8, 6, 2, 1);
    let t: Vec<f32> = base(Shape::Scene, dims).iter().map(|v| *v as f32).collect();
    let good = std::fs::read(write_raw(
        &dir.join("m.raw"),
        dims,
        &t,
        None,
        4 * dims.row_len() as u64 * 4,
    ))
    .unwrap();
    assert!(Fields::of(&good).block_count > 1);
    (good, dir.join("bad.raw"))
}

fn open_err(path: &Path, bytes: &[u8]) -> String {
    std::fs::write(path, bytes).unwrap();
    RawStore::open(path)
        .err()
        .expect("must be refused")
        .to_string()
}

/// A file with the right magic but shorter than the header or than its
/// header implies is reported as truncated, with the sizes.
#[test]
fn short_files_with_the_magic_are_reported_as_truncated() {
    let dir = tempfile::tempdir().unwrap();
    let (good, path) = crafted(dir.path());
    for len in [5, 8, 40, 63] {
        let err = open_err(&path, &good[..len]);
        assert!(
            err.contains("truncated")
                && err.contains(&format!("{len} bytes"))
                && !err.contains("not an ltm"),
            "{len}: {err}"
        );
    }
    for len in [64, 100, good.len() - 1] {
        let err = open_err(&path, &good[..len]);
        assert!(
            err.contains("truncated")
                && err.contains(&format!("{len} bytes"))
                && err.contains(&good.len().to_string()),
            "{len}: {err}"
        );
    }
    assert!(open_err(&path, b"").contains("empty"));
    let err = open_err(
        &path,
        b"PK\x03\x04 not a raw store at all, but long enough to hold a header....",
    );
    assert!(err.contains("not an ltm raw transport store"), "{err}");
}

#[test]
fn a_non_zero_reserved_field_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (mut bytes, path) = crafted(dir.path());
    bytes[57] = 1;
    Fields::fix_header_crc(&mut bytes);
    let err = open_err(&path, &bytes);
    assert!(
        err.contains("reserved") && err.contains("offset 56") && err.contains("0x100"),
        "{err}"
    );
}

#[test]
fn block_states_other_than_0_and_1_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (good, path) = crafted(dir.path());
    for state in [2u32, 0x0101, u32::MAX] {
        let mut bytes = good.clone();
        bytes[64 + 8..64 + 12].copy_from_slice(&state.to_le_bytes());
        let err = open_err(&path, &bytes);
        assert!(
            err.contains(&format!("block state = {state} (block 1)"))
                && err.contains("0 (pending) or 1 (complete)"),
            "{err}"
        );
    }
    let mut pending = good.clone();
    pending[64 + 8] = 0;
    assert!(open_err(&path, &pending).contains("block 1 was never completed"));
}

#[test]
fn row_flags_other_than_0_and_1_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (mut bytes, path) = crafted(dir.path());
    let f = Fields::of(&bytes);
    bytes[f.flags_offset + 5] = 2;
    f.fix_block_crc(&mut bytes, 5 / f.block_rows);
    let err = open_err(&path, &bytes);
    assert!(
        err.contains("row flag = 2 (row 5)") && err.contains("0 (not known to be zero) or 1"),
        "{err}"
    );
}

/// A row flagged zero that holds values (its block's CRC fixed) fails the
/// block's verification and the compressor; a zero row not flagged is fine.
#[test]
fn a_zero_flag_is_verified_against_the_row() {
    let dir = tempfile::tempdir().unwrap();
    let (mut bytes, path) = crafted(dir.path());
    let f = Fields::of(&bytes);
    let zero = (0..f.pixels(&bytes))
        .find(|&p| bytes[f.flags_offset + p] == 1)
        .unwrap();
    let p = (0..f.pixels(&bytes))
        .find(|&p| bytes[f.flags_offset + p] == 0 && p / f.block_rows != zero / f.block_rows)
        .unwrap();
    bytes[f.flags_offset + p] = 1;
    bytes[f.flags_offset + zero] = 0;
    for b in [p / f.block_rows, zero / f.block_rows] {
        f.fix_block_crc(&mut bytes, b);
    }
    std::fs::write(&path, &bytes).unwrap();
    let raw = RawStore::open(&path).unwrap();
    assert!(raw.is_zero_row(p));
    raw.verify_block(zero / f.block_rows).unwrap();
    let err = raw.verify_block(p / f.block_rows).unwrap_err().to_string();
    assert!(
        err.contains(&format!("row {p} is flagged all zero but holds")),
        "{err}"
    );
    let out = dir.path().join("m.ltm");
    let err = compress(
        &raw,
        &out,
        &CompressOptions::default(),
        ltm_codec::Progress::NONE,
    )
    .unwrap_err();
    assert!(err.to_string().contains("flagged all zero"), "{err}");
    assert!(!out.exists());
}

/// Non-finite data (CRC fixed) names the value and where it is.
#[test]
fn non_finite_data_names_the_value() {
    let dir = tempfile::tempdir().unwrap();
    let (mut bytes, path) = crafted(dir.path());
    let f = Fields::of(&bytes);
    let row = 9;
    let at = f.data_offset + row * f.row_bytes + 4 * 3;
    bytes[at..at + 4].copy_from_slice(&f32::NEG_INFINITY.to_le_bytes());
    bytes[f.flags_offset + row] = 0;
    f.fix_block_crc(&mut bytes, row / f.block_rows);
    std::fs::write(&path, &bytes).unwrap();
    let raw = RawStore::open(&path).unwrap();
    let err = raw
        .verify_block(row / f.block_rows)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("value = -inf (row 9, column 3, channel 0)") && err.contains("finite"),
        "{err}"
    );
    let out = dir.path().join("m.ltm");
    let err = compress(
        &raw,
        &out,
        &CompressOptions::default(),
        ltm_codec::Progress::NONE,
    )
    .unwrap_err();
    assert!(err.to_string().contains("value = -inf (row 9"), "{err}");
    assert!(!out.exists());
}

/// An error and its sources, as `ltm` prints them (`a: b: c`).
fn chain(err: &dyn std::error::Error) -> String {
    let mut s = err.to_string();
    let mut e = err.source();
    while let Some(inner) = e {
        s.push_str(&format!(": {inner}"));
        e = inner.source();
    }
    s
}
