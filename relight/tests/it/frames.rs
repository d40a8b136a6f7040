//! Frame reuse: a frame under unchanged lighting reuses the light's row
//! transform, and any change of the lighting (one texel, one bit) is seen.

use ltm_codec::compress::{compress, CodeOptions, CompressOptions, Target};
use ltm_codec::{Dims, Filter, Mode, RawHeader, RawStore, RawWriter};
use ltm_relight::{relative_l2, Frame, Relight, Relighter, Request, Weighting};

fn relighter(dir: &std::path::Path) -> Relighter {
    let dims = Dims::image(12, 9, 4, 3);
    let mut writer =
        RawWriter::create(&dir.join("t.raw"), RawHeader::new(dims, false, 1 << 20)).unwrap();
    let rows: Vec<f32> = (0..dims.pixels() * dims.lights() * 3)
        .map(|i| ((i % 89) as f32 * 0.07).sin().abs() * 1e-2)
        .collect();
    writer.write_block(0, &rows, None).unwrap();
    let raw = RawStore::open(&writer.finish().unwrap()).unwrap();
    let ltm = dir.join("t.ltm");
    compress(
        &raw,
        &ltm,
        &CompressOptions::default(),
        ltm_codec::Progress::NONE,
    )
    .unwrap();
    Relighter::open(&ltm).unwrap()
}

fn image(r: &Relighter, light: &[[f32; 3]], terms: usize, frame: &mut Frame) -> Vec<[f32; 3]> {
    let request = Request {
        terms,
        weighting: Weighting::Transport,
    };
    r.relight(light, &request, frame).unwrap();
    frame.image.data.clone()
}

#[test]
fn reused_light_transform_matches_a_fresh_frame_and_changes_are_seen() {
    let dir = tempfile::tempdir().unwrap();
    let r = relighter(dir.path());
    let a: Vec<[f32; 3]> = (0..r.lights())
        .map(|j| [1.0 + j as f32 * 0.1, 0.5, (j % 5) as f32])
        .collect();
    let mut frame = r.frame().unwrap();
    // Only N changes: each image equals a fresh frame's.
    for terms in [3, 40, 7, usize::MAX] {
        let reused = image(&r, &a, terms, &mut frame);
        assert_eq!(
            reused,
            image(&r, &a, terms, &mut r.frame().unwrap()),
            "N = {terms}"
        );
    }
    // A brighter light after a reused frame: a different image, the fresh one.
    let twice: Vec<[f32; 3]> = a.iter().map(|l| l.map(|v| 2.0 * v)).collect();
    let bright = image(&r, &twice, 40, &mut frame);
    assert_ne!(bright, image(&r, &a, 40, &mut r.frame().unwrap()));
    assert_eq!(bright, image(&r, &twice, 40, &mut r.frame().unwrap()));
    // One texel changed by one bit, then the sign of a zero: both seen.
    let mut b = a.clone();
    b[17][1] = f32::from_bits(b[17][1].to_bits() + 1);
    assert_eq!(
        image(&r, &b, 40, &mut frame),
        image(&r, &b, 40, &mut r.frame().unwrap())
    );
    let mut c = a.clone();
    c[3] = [0.0, 0.0, 0.0];
    let mut d = c.clone();
    d[3] = [-0.0, 0.0, 0.0];
    image(&r, &c, 40, &mut frame);
    assert_eq!(
        image(&r, &d, 40, &mut frame),
        image(&r, &d, 40, &mut r.frame().unwrap())
    );
    // Bad lighting after a reused frame is still an error, and the next
    // good frame is right.
    let mut bad = a.clone();
    bad[0][0] = f32::NAN;
    let request = Request {
        terms: 40,
        weighting: Weighting::Transport,
    };
    assert!(r.relight(&bad, &request, &mut frame).is_err());
    assert!(r.relight(&a[1..], &request, &mut frame).is_err());
    assert_eq!(
        image(&r, &a, 40, &mut frame),
        image(&r, &a, 40, &mut r.frame().unwrap())
    );
    // forget_light gives the same image.
    frame.forget_light();
    assert_eq!(
        image(&r, &a, 40, &mut frame),
        image(&r, &a, 40, &mut r.frame().unwrap())
    );
}

/// A file whose image has runs of rows that are zero under every light
/// (rows 0..3, 9..15 and the last two), so that the inverse steps skip rows,
/// at an odd size transformed to full depth: one frame reused over N up and
/// down gives a fresh frame's image bit for bit and stays within 2e-6 of
/// eq. 3 (`relight_naive`), for 2d, 4d and adaptive files.
#[test]
fn zero_rows_are_skipped_without_changing_the_image() {
    let dir = tempfile::tempdir().unwrap();
    let dims = Dims::image(37, 23, 4, 3);
    let mut writer = RawWriter::create(
        &dir.path().join("z.raw"),
        RawHeader::new(dims, false, 1 << 20),
    )
    .unwrap();
    let (m, w) = (dims.lights(), 37);
    let rows: Vec<f32> = (0..dims.pixels() * m * 3)
        .map(|i| {
            let y = i / (m * 3) / w;
            let zero = y < 3 || (9..15).contains(&y) || y >= 21;
            if zero {
                0.0
            } else {
                ((i % 97) as f32 * 0.11).sin().abs() * 1e-2
            }
        })
        .collect();
    writer.write_block(0, &rows, None).unwrap();
    let raw = RawStore::open(&writer.finish().unwrap()).unwrap();
    let light: Vec<[f32; 3]> = (0..m)
        .map(|j| [1.0 + j as f32 * 0.1, 0.5, (j % 5) as f32])
        .collect();
    for (mode, filter) in [
        (Mode::TwoD, Filter::D4),
        (Mode::FourD, Filter::Cdf97),
        (Mode::Adaptive, Filter::LeGall53),
    ] {
        let ltm = dir.path().join("z.ltm");
        let opts = CodeOptions {
            mode,
            col_filter: filter,
            bits: 14,
            target: Target::MaxError(1e-3),
            ..Default::default()
        };
        compress(&raw, &ltm, &opts.into(), ltm_codec::Progress::NONE).unwrap();
        let r = Relighter::open(&ltm).unwrap();
        let mut frame = r.frame().unwrap();
        for terms in [1, 5, 60, 7, usize::MAX, 2] {
            let reused = image(&r, &light, terms, &mut frame);
            let fresh = image(&r, &light, terms, &mut r.frame().unwrap());
            assert_eq!(reused, fresh, "{mode:?} N = {terms}");
            let request = Request {
                terms,
                weighting: Weighting::Transport,
            };
            let naive = r.relight_naive(&light, &request).unwrap();
            let diff = relative_l2(&frame.image, &naive).unwrap();
            assert!(diff <= 2e-6, "{mode:?} N = {terms}: {diff}");
        }
    }
}

/// Mutated files (CRCs repaired, so the mutations reach the structure and
/// the column payloads) are refused at open or relight to finite images:
/// the arena's band factors and `i16` values never panic or give NaN.
#[test]
fn mutated_files_never_panic_or_give_nan() {
    let dir = tempfile::tempdir().unwrap();
    let r = relighter(dir.path());
    // Every chunk stored as is, so that `repair_checksums` also repairs
    // the columns' CRCs (it cannot in a packed column table).
    let good =
        ltm_codec::container::unpack_chunks(&std::fs::read(dir.path().join("t.ltm")).unwrap())
            .unwrap();
    let light: Vec<[f32; 3]> = (0..r.lights()).map(|j| [1.0, j as f32, 0.5]).collect();
    let request = Request {
        terms: usize::MAX,
        weighting: Weighting::Transport,
    };
    let limits = ltm_codec::Limits::default();
    let mut seed = 0x2545_f491_4f6c_dd1du64;
    let (mut opened, mut relit) = (0, 0);
    for _ in 0..400 {
        let mut bytes = good.clone();
        for _ in 0..1 + seed % 3 {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            let at = (seed >> 8) as usize % bytes.len();
            bytes[at] = match seed % 4 {
                0 => 0xff,
                1 => 0,
                _ => bytes[at] ^ (1 << ((seed >> 40) % 8)),
            };
        }
        ltm_codec::container::repair_checksums(&mut bytes);
        let Ok(file) = ltm_codec::LtmFile::from_bytes(bytes, &limits) else {
            continue;
        };
        opened += 1;
        let Ok(r) = Relighter::new(file, &limits) else {
            continue;
        };
        let mut frame = r.frame().unwrap();
        if r.relight(&light, &request, &mut frame).is_ok() {
            relit += 1;
            assert!(frame.image.first_non_finite().is_none());
        }
    }
    assert!(opened > 0 && relit > 0, "{opened} opened, {relit} relit");
}

/// Every multiply-add kernel the CPU runs relights within 2e-6 of eq. 3
/// (`relight_naive`); an unknown kernel name is an error naming the valid
/// ones.
#[test]
fn every_kernel_relights_like_the_naive_sum() {
    let dir = tempfile::tempdir().unwrap();
    let mut r = relighter(dir.path());
    let light: Vec<[f32; 3]> = (0..r.lights())
        .map(|j| [1.0 + j as f32 * 0.1, 0.5, (j % 5) as f32])
        .collect();
    let kernels = Relighter::kernels();
    assert_eq!(kernels[0], "scalar");
    // The default: SSE4.1 where the CPU has it (bit-identical to scalar).
    let expect = if kernels.contains(&"sse4.1") {
        "sse4.1"
    } else {
        kernels.last().unwrap()
    };
    assert_eq!(r.kernel(), expect);
    for kernel in kernels {
        r.set_kernel(kernel).unwrap();
        assert_eq!(r.kernel(), kernel);
        for terms in [1, 40, usize::MAX] {
            let got = image(&r, &light, terms, &mut r.frame().unwrap());
            let request = Request {
                terms,
                weighting: Weighting::Transport,
            };
            let naive = r.relight_naive(&light, &request).unwrap();
            let mut frame = r.frame().unwrap();
            frame.image.data = got;
            let diff = relative_l2(&frame.image, &naive).unwrap();
            assert!(diff <= 2e-6, "{kernel} N = {terms}: {diff}");
        }
    }
    let err = r.set_kernel("avx9").unwrap_err().to_string();
    assert!(err.contains("avx9") && err.contains("scalar"), "{err}");
}
