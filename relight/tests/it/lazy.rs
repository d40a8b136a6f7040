//! Columns decoded on first use: frames equal those of a relighter whose
//! columns were all decoded up front, bit for bit; a frame decodes only the
//! columns it uses, each once; a file without stored norms (version 4)
//! ranks lights by the norms of its decoded columns; a stored norm that
//! disagrees with its column, or a damaged payload, is refused at open.

use ltm_codec::compress::{compress, CompressOptions};
use ltm_codec::{Dims, Limits, LtmFile, RawHeader, RawStore, RawWriter};
use ltm_relight::{relative_l2, Frame, Relight, Relighter, Request, Weighting};
use std::path::{Path, PathBuf};

/// A compressed 16 × 12 RGB matrix with n = 4 (96 lights), whose columns
/// differ in density, and the path of the file.
fn file(dir: &Path) -> PathBuf {
    let dims = Dims::image(16, 12, 4, 3);
    let mut writer =
        RawWriter::create(&dir.join("t.raw"), RawHeader::new(dims, false, 1 << 20)).unwrap();
    let m = dims.lights();
    let rows: Vec<f32> = (0..dims.pixels() * m * 3)
        .map(|i| {
            let (p, j) = (i / (3 * m), i / 3 % m);
            let lit = (p * 5 + j * 3) % 11 < 4 + j % 5;
            if lit {
                ((i % 89) as f32 * 0.07).sin().abs() * 1e-2 + 1e-3
            } else {
                0.0
            }
        })
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
    ltm
}

/// Lighting number `k`: a different bright texel and colour each time.
fn lighting(lights: usize, k: usize) -> Vec<[f32; 3]> {
    (0..lights)
        .map(|j| {
            let peak = if j == (k * 37) % lights { 50.0 } else { 0.0 };
            [
                0.2 + peak + (j % 7) as f32 * 0.1,
                0.5 + (j * k % 5) as f32 * 0.2,
                (j % 3) as f32,
            ]
        })
        .collect()
}

fn frame(
    r: &Relighter,
    light: &[[f32; 3]],
    request: &Request,
    f: &mut Frame,
) -> (Vec<[f32; 3]>, usize, usize) {
    let stats = r.relight(light, request, f).unwrap();
    (f.image.data.clone(), stats.columns_decoded, stats.lights)
}

#[test]
fn frames_on_demand_equal_preloaded_frames_and_decode_each_column_once() {
    let dir = tempfile::tempdir().unwrap();
    let path = file(dir.path());
    let lazy = Relighter::open(&path).unwrap();
    let eager = Relighter::open(&path).unwrap();
    assert_eq!(lazy.arena_bytes(), 0, "open decodes nothing");
    eager.decode_all().unwrap();
    let full = eager.arena_bytes();
    assert!(full > 0);
    assert_eq!(lazy.nonzeros(), eager.nonzeros());
    let (mut fl, mut fe) = (lazy.frame().unwrap(), eager.frame().unwrap());
    let mut decoded = 0;
    for k in 0..4 {
        let light = lighting(lazy.lights(), k);
        for weighting in [Weighting::Transport, Weighting::Unweighted, Weighting::Area] {
            for terms in [1, 7, 30, usize::MAX] {
                let request = Request { terms, weighting };
                let (a, new, used) = frame(&lazy, &light, &request, &mut fl);
                let (b, none, _) = frame(&eager, &light, &request, &mut fe);
                assert_eq!(a, b, "lighting {k} {weighting:?} N = {terms}");
                assert!(new <= used, "{new} decoded for {used} lights");
                assert_eq!(none, 0);
                decoded += new;
                // The same frame again decodes nothing.
                let (again, zero, _) = frame(&lazy, &light, &request, &mut fl);
                assert_eq!((again, zero), (a, 0));
                let naive = lazy.relight_naive(&light, &request).unwrap();
                assert!(relative_l2(&fl.image, &naive).unwrap() <= 2e-6);
            }
        }
    }
    // Each column decoded once, and then the arena is the preloaded one
    // (both hold the norms their transport-weighted frames computed).
    assert_eq!(decoded, lazy.lights());
    assert_eq!(lazy.arena_bytes(), eager.arena_bytes());
    assert_eq!(eager.arena_bytes(), full + 4 * lazy.lights());
    lazy.decode_all().unwrap();
    assert_eq!(lazy.arena_bytes(), eager.arena_bytes());
}

/// A few lights decode a few columns, and frames on two threads that share
/// one relighter both see every column they need.
#[test]
fn a_frame_decodes_only_its_columns_even_on_two_threads() {
    let dir = tempfile::tempdir().unwrap();
    let path = file(dir.path());
    let r = Relighter::open(&path).unwrap();
    let light = lighting(r.lights(), 1);
    let request = Request {
        terms: 5,
        weighting: Weighting::Transport,
    };
    let (_, decoded, used) = frame(&r, &light, &request, &mut r.frame().unwrap());
    assert_eq!((decoded, used), (5, 5));
    let preloaded = Relighter::open(&path).unwrap();
    preloaded.decode_all().unwrap();
    assert!(r.arena_bytes() < preloaded.arena_bytes() / 4);
    let all = Request {
        terms: usize::MAX,
        weighting: Weighting::Transport,
    };
    let want = frame(&preloaded, &light, &all, &mut preloaded.frame().unwrap()).0;
    std::thread::scope(|s| {
        let a = s.spawn(|| frame(&r, &light, &all, &mut r.frame().unwrap()).0);
        let b = s.spawn(|| frame(&r, &light, &all, &mut r.frame().unwrap()).0);
        assert_eq!(a.join().unwrap(), want);
        assert_eq!(b.join().unwrap(), want);
    });
}

/// A version-4 file (as a version-8 one) stores no column norms: transport
/// weighting decodes every column once on its first frame for their
/// norms, keeps only the norms and the columns the frame uses, and ranks
/// by them as the naive sum does.
#[test]
fn version_4_files_rank_lights_by_their_decoded_norms() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../codec/tests/fixtures/golden-v4.ltm");
    let r = Relighter::open(&path).unwrap();
    assert!(r.file().column_norms().is_none());
    let light = lighting(r.lights(), 2);
    let request = Request {
        terms: 9,
        weighting: Weighting::Transport,
    };
    let (image, decoded, used) = frame(&r, &light, &request, &mut r.frame().unwrap());
    assert_eq!(used, 9);
    assert!(decoded <= 9);
    let preloaded = Relighter::open(&path).unwrap();
    preloaded.decode_all().unwrap();
    assert_eq!(
        image,
        frame(
            &preloaded,
            &light,
            &request,
            &mut preloaded.frame().unwrap()
        )
        .0
    );
    // The norms pass kept no column beyond the frame's.
    assert!(r.arena_bytes() < preloaded.arena_bytes() / 4);
    let mut f = r.frame().unwrap();
    f.image = r.relight_naive(&light, &request).unwrap();
    let mut g = r.frame().unwrap();
    g.image.data = image;
    g.image.width = f.image.width;
    g.image.height = f.image.height;
    assert!(relative_l2(&g.image, &f.image).unwrap() <= 2e-6);
}

/// The offset and length of chunk `tag` in a file's bytes.
fn chunk(bytes: &[u8], tag: &[u8; 4]) -> (usize, usize) {
    let count = u32::from_le_bytes(bytes[16..20].try_into().unwrap()) as usize;
    let at = |e: usize| u64::from_le_bytes(bytes[e..e + 8].try_into().unwrap()) as usize;
    (0..count)
        .map(|k| 24 + 32 * k)
        .find(|&e| &bytes[e..e + 4] == tag)
        .map(|e| (at(e + 8), at(e + 16)))
        .unwrap()
}

/// A NORM entry understated or overstated (checksums repaired) is refused
/// before the first transport-weighted frame ranks a light, with the
/// column, the stored and the decoded norm: an understated norm would push
/// its light out of a transport-weighted top N, where no frame decodes (and
/// so checks) its column. Frames that do not read the norms still work.
#[test]
fn a_stored_norm_that_disagrees_with_its_column_is_refused_before_ranking() {
    // Version 8 stores no norms: a version-5 file does.
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../codec/tests/fixtures/golden-v5.ltm");
    let good = std::fs::read(&path).unwrap();
    let limits = Limits::default();
    let file = LtmFile::open(&path).unwrap();
    let j = file.columns().iter().rposition(|c| c.nnz > 0).unwrap();
    let (at, _) = chunk(&good, b"NORM");
    let o = at + 4 * j;
    let norm = f32::from_le_bytes(good[o..o + 4].try_into().unwrap());
    let request = |weighting| Request {
        terms: 1,
        weighting,
    };
    for factor in [0.5f32, 2.0, 1.0 + f32::EPSILON] {
        let mut bytes = good.clone();
        let wrong = norm * factor;
        bytes[o..o + 4].copy_from_slice(&wrong.to_le_bytes());
        ltm_codec::container::repair_checksums(&mut bytes);
        // The container alone accepts it (a norm is a finite value ≥ 0) ...
        let file = LtmFile::from_bytes(bytes.clone(), &limits).unwrap();
        let r = Relighter::new(file, &limits).unwrap();
        let light = lighting(r.lights(), 1);
        let mut f = r.frame().unwrap();
        r.relight(&light, &request(Weighting::Unweighted), &mut f)
            .unwrap();
        // ... a transport-weighted frame does not rank by it.
        let err = r.relight(&light, &request(Weighting::Transport), &mut f);
        let err = err.err().unwrap().to_string();
        assert!(
            err.contains("NORM")
                && err.contains(&format!("column {j}:"))
                && err.contains(&format!("{wrong:e}"))
                && err.contains(&format!("{norm:e}")),
            "{err}"
        );
    }
    // The file as written relights by transport.
    let r = Relighter::new(LtmFile::from_bytes(good, &limits).unwrap(), &limits).unwrap();
    let light = lighting(r.lights(), 1);
    r.relight(
        &light,
        &request(Weighting::Transport),
        &mut r.frame().unwrap(),
    )
    .unwrap();
}

/// A payload byte flipped (its CRC not repaired) is refused at open, before
/// any column is decoded.
#[test]
fn a_damaged_payload_is_refused_at_open() {
    let dir = tempfile::tempdir().unwrap();
    let path = file(dir.path());
    let mut bytes = std::fs::read(&path).unwrap();
    let (data, len) = chunk(&bytes, b"DATA");
    bytes[data + len / 2] ^= 0x10;
    let limits = Limits::default();
    let file = LtmFile::from_bytes(bytes, &limits).unwrap();
    let err = Relighter::new(file, &limits).err().unwrap().to_string();
    assert!(err.contains("CRC") && err.contains("column"), "{err}");
}

/// Lighting near the `f32` limit (a map of 3e38) relights to a finite
/// image, the image of the same lighting divided by a power of two times
/// that power (the relighter scales the lighting down and the image back
/// up, exactly); an image beyond the `f32` range is an error naming a
/// pixel, never a NaN.
#[test]
fn lighting_near_the_f32_limit_gives_a_finite_image_or_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let r = Relighter::open(&file(dir.path())).unwrap();
    let mut f = r.frame().unwrap();
    let request = Request {
        terms: usize::MAX,
        weighting: Weighting::Transport,
    };
    let two_127 = 2f32.powi(127);
    for light in [vec![[1.7632415f32; 3]; r.lights()], lighting(r.lights(), 2)] {
        let small = frame(&r, &light, &request, &mut f).0;
        let big: Vec<[f32; 3]> = light
            .iter()
            .map(|l| l.map(|v| v * (two_127 / 64.0)))
            .collect();
        let (image, _, _) = frame(&r, &big, &request, &mut f);
        assert!(image.iter().flatten().all(|v| v.is_finite()));
        let want: Vec<[f32; 3]> = small
            .iter()
            .map(|p| p.map(|v| v * (two_127 / 64.0)))
            .collect();
        assert_eq!(image, want);
    }
    // 3e38 in every texel: T·L beyond f32 in some pixel is an error.
    let huge = vec![[3e38f32; 3]; r.lights()];
    match r.relight(&huge, &request, &mut f) {
        Ok(_) => assert!(f.image.first_non_finite().is_none()),
        Err(e) => assert!(e.to_string().contains("exceeds the f32 range"), "{e}"),
    }
}
