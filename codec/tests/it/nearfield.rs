//! Near-field rows (a scene's light plane): raw store version 6 and the
//! `.ltm` file's NEAR chunk (version 10). Round trips through the writer,
//! the reader, resuming and `compress`; every damaged or inconsistent file
//! is an error, never a panic or a wrong row.

use ltm_codec::compress::{compress, CompressOptions};
use ltm_codec::nearfield::plane_coefficients;
use ltm_codec::raw::ResumeState;
use ltm_codec::{
    Dims, Limits, LtmFile, PlaneBasis, PlaneRows, Progress, RawHeader, RawStore, RawWriter,
    Surface, SurfacePoint,
};
use std::path::{Path, PathBuf};

fn basis(order: u32) -> PlaneBasis {
    PlaneBasis {
        origin: [0.0, 2.0, 0.0],
        x_axis: [1.0, 0.0, 0.0],
        y_axis: [0.0, 0.0, 1.0],
        order,
        side: 4.0,
    }
}

fn surface(rows: usize) -> Surface {
    let point = |p: usize| SurfacePoint::new([p as f32 * 0.1, 0.0, 0.0], [0.0, 1.0, 0.0]);
    Surface::new((0..rows).map(point).collect()).unwrap()
}

/// A 6×5 grey store at n = 2 with near-field rows of order 4, blocks of
/// about `block_bytes`.
fn header(block_bytes: u64) -> RawHeader {
    RawHeader::new(Dims::image(6, 5, 2, 1), true, block_bytes)
        .with_input_id([3; 32])
        .with_surface()
        .with_plane(basis(4))
}

/// Row `p`'s transport (`value` scaled) and near-field row.
fn rows(p: usize, h: &RawHeader) -> (Vec<f32>, Vec<f32>) {
    let t = (0..h.dims.row_len())
        .map(|j| ((p * 7 + j) % 5) as f32 * 0.01)
        .collect();
    let plane = (0..h.plane_row_len())
        .map(|j| {
            if (p + j).is_multiple_of(3) {
                0.0
            } else {
                (p + j) as f32 * 1e-3
            }
        })
        .collect();
    (t, plane)
}

fn write_blocks(w: &mut RawWriter, blocks: &[usize]) {
    let h = *w.header();
    for &b in blocks {
        let (mut t, mut plane) = (Vec::new(), Vec::new());
        for p in h.block_range(b) {
            let (a, c) = rows(p, &h);
            t.extend(a);
            plane.extend(c);
        }
        let albedo = vec![0.5; 3 * h.block_range(b).len()];
        w.write_block_with_plane(b, &t, Some(&albedo), Some(&plane))
            .unwrap();
    }
}

fn write_store(path: &Path, h: RawHeader) -> PathBuf {
    let mut w = RawWriter::create_with_surface(path, h, Some(&surface(30))).unwrap();
    write_blocks(&mut w, &(0..h.block_count()).collect::<Vec<_>>());
    w.finish().unwrap()
}

#[test]
fn stores_with_a_light_plane_round_trip_and_resume() {
    let dir = tempfile::tempdir().unwrap();
    let h = header(100);
    assert_eq!(h.version(), 6);
    let path = write_store(&dir.path().join("s.raw"), h);
    let store = RawStore::open(&path).unwrap();
    assert_eq!(*store.header(), h);
    for b in 0..h.block_count() {
        store.verify_block(b).unwrap();
    }
    let mut plane = Vec::new();
    store.read_plane_rows(3..5, &mut plane).unwrap();
    assert_eq!(plane.len(), 2 * 16);
    assert_eq!(plane[..16], rows(3, &h).1[..]);
    assert!(store.read_plane_rows(29..31, &mut plane).is_err());
    // A partial file of the same inputs resumes with its blocks.
    let partial = dir.path().join("r.raw");
    let mut w = RawWriter::create_with_surface(&partial, h, Some(&surface(30))).unwrap();
    write_blocks(&mut w, &[0, 1]);
    drop(w);
    let w = RawWriter::create_with_surface(&partial, h, Some(&surface(30))).unwrap();
    assert!(matches!(
        w.resume_state(),
        ResumeState::Resumed { kept: 2, .. }
    ));
    // Another light plane starts it over.
    let other = header(100).with_plane(PlaneBasis {
        side: 3.0,
        ..basis(4)
    });
    drop(w);
    let w = RawWriter::create_with_surface(&partial, other, Some(&surface(30))).unwrap();
    assert!(matches!(w.resume_state(), ResumeState::Restarted(_)));
}

#[test]
fn near_field_rows_are_given_exactly_when_the_store_has_a_plane() {
    let dir = tempfile::tempdir().unwrap();
    let h = header(1 << 20);
    let mut w =
        RawWriter::create_with_surface(&dir.path().join("a.raw"), h, Some(&surface(30))).unwrap();
    let t = vec![0.0f32; 30 * h.dims.row_len()];
    let albedo = vec![0.5f32; 90];
    assert!(w.write_block(0, &t, Some(&albedo)).is_err());
    let short = vec![0.0f32; 30 * 16 - 1];
    assert!(w
        .write_block_with_plane(0, &t, Some(&albedo), Some(&short))
        .is_err());
    let mut nan = vec![0.0f32; 30 * 16];
    nan[7] = f32::NAN;
    assert!(w
        .write_block_with_plane(0, &t, Some(&albedo), Some(&nan))
        .is_err());
    let plain = RawHeader::new(Dims::image(6, 5, 2, 1), true, 1 << 20);
    let mut w = RawWriter::create(&dir.path().join("b.raw"), plain).unwrap();
    let zeros = vec![0.0f32; 30 * 16];
    assert!(w
        .write_block_with_plane(0, &t, Some(&albedo), Some(&zeros))
        .is_err());
    // A part of a sharded bake holds no near-field rows.
    let part = h.with_part(ltm_codec::RowSpan { start: 0, end: 10 });
    let err = RawWriter::create_with_surface(&dir.path().join("c.raw"), part, Some(&surface(30)));
    assert!(err.err().unwrap().to_string().contains("near-field"));
}

/// Flips one byte of a copy of `bytes` at `at` (or sets a field) and
/// checks that opening and verifying it fails.
fn damaged(dir: &Path, bytes: &[u8], at: usize, value: &[u8]) -> bool {
    let mut b = bytes.to_vec();
    b[at..at + value.len()].copy_from_slice(value);
    let path = dir.join(format!("d{at}.raw"));
    std::fs::write(&path, &b).unwrap();
    match RawStore::open(&path) {
        Err(_) => true,
        Ok(s) => (0..s.header().block_count()).any(|k| s.verify_block(k).is_err()),
    }
}

/// Rewrites the header CRC of a version-6 header (240 bytes) after an
/// edit, so that the field checks themselves are reached.
fn with_crc(mut b: Vec<u8>) -> Vec<u8> {
    let crc = crc32fast::hash(&b[..236]);
    b[236..240].copy_from_slice(&crc.to_le_bytes());
    b
}

#[test]
fn damaged_version_6_stores_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let h = header(100);
    let path = write_store(&dir.path().join("s.raw"), h);
    let bytes = std::fs::read(&path).unwrap();
    let len = bytes.len();
    // A flipped value of the near-field section: its block's CRC.
    let last = bytes[len - 3];
    assert!(damaged(dir.path(), &bytes, len - 3, &[last ^ 0x10]));
    // Header fields, each with a valid CRC.
    let edits: [(usize, Vec<u8>); 6] = [
        (12, 3u32.to_le_bytes().to_vec()),  // flags without the plane bit
        (124, 1u64.to_le_bytes().to_vec()), // part fields set
        (140, 4096u64.to_le_bytes().to_vec()), // plane_offset
        (148, 3u32.to_le_bytes().to_vec()), // order 3
        (156, f64::NAN.to_bits().to_le_bytes().to_vec()), // side NaN
        (188, 2.0f64.to_bits().to_le_bytes().to_vec()), // x axis not unit
    ];
    for (at, value) in edits {
        let mut b = bytes.clone();
        b[at..at + value.len()].copy_from_slice(&value);
        let b = with_crc(b);
        let p = dir.path().join(format!("e{at}.raw"));
        std::fs::write(&p, &b).unwrap();
        assert!(RawStore::open(&p).is_err(), "edit at {at} accepted");
    }
    // Truncated into the near-field section.
    let cut = dir.path().join("cut.raw");
    std::fs::write(&cut, &bytes[..len - 8]).unwrap();
    let err = RawStore::open(&cut).err().unwrap().to_string();
    assert!(err.contains("truncated"), "{err}");
}

#[test]
fn compress_stores_the_near_field_rows_losslessly() {
    let dir = tempfile::tempdir().unwrap();
    let h = header(100);
    let raw = RawStore::open(&write_store(&dir.path().join("s.raw"), h)).unwrap();
    let out = dir.path().join("s.ltm");
    let lossless = CompressOptions::from(ltm_codec::CodeOptions {
        near_error: Some(0.0),
        ..Default::default()
    });
    let stats = compress(&raw, &out, &lossless, Progress::NONE).unwrap();
    assert!(stats.near_field_bytes > 0);
    let q = stats.near_field.unwrap();
    assert_eq!((q.step, q.kept), (0.0, q.before));
    let file = LtmFile::open(&out).unwrap();
    let near = file.near_field().expect("NEAR chunk");
    assert_eq!(
        (near.rows(), near.channels(), *near.basis()),
        (30, 1, basis(4))
    );
    let mut want = Vec::new();
    for p in 0..30 {
        want.clear();
        plane_coefficients(&rows(p, &h).1, 4, &mut want).unwrap();
        let (index, value) = near.row(p, 0);
        let got: Vec<(u32, f32)> = index
            .iter()
            .map(|&k| u32::from(k))
            .zip(value.iter().copied())
            .collect();
        assert_eq!(got, want, "row {p}");
    }
    // At the default target (the matrix's 1 %), every stored value is a
    // multiple of the step, and the rows' error is within the target.
    let lossy = dir.path().join("q.ltm");
    let stats = compress(&raw, &lossy, &CompressOptions::default(), Progress::NONE).unwrap();
    let q = stats.near_field.unwrap();
    assert!(
        q.step > 0.0 && q.error <= 0.01 && q.kept < q.before,
        "{q:?}"
    );
    let file = LtmFile::open(&lossy).unwrap();
    let rounded = file.near_field().expect("NEAR chunk");
    assert_eq!(rounded.nonzeros(), q.kept);
    let (mut diff, mut norm) = (0.0f64, 0.0f64);
    for p in 0..30 {
        want.clear();
        plane_coefficients(&rows(p, &h).1, 4, &mut want).unwrap();
        let (index, value) = rounded.row(p, 0);
        for &(k, v) in &want {
            let stored = index
                .iter()
                .position(|&i| u32::from(i) == k)
                .map_or(0.0, |at| f64::from(value[at]));
            let steps = stored / q.step;
            assert!((steps - steps.round()).abs() < 1e-4, "{stored} {}", q.step);
            diff += (stored - f64::from(v)).powi(2);
            norm += f64::from(v).powi(2);
        }
    }
    let error = (diff / norm).sqrt();
    assert!(
        (error - q.error).abs() < 1e-6 * q.error.max(1e-3),
        "{error} {q:?}"
    );
    // Modes that would drop the rows refuse the store.
    let pca = ltm_codec::compress_pca(
        &raw,
        &dir.path().join("p.ltm"),
        &ltm_codec::PcaOptions::default(),
        Progress::NONE,
    );
    assert!(pca.err().unwrap().to_string().contains("near-field"));
}

#[test]
fn near_chunks_decode_only_when_consistent() {
    let mut rows = PlaneRows::new(basis(2), 3).unwrap();
    rows.push_texels(&[1.0, 0.5, 0.25, 0.0, 0.0, 0.0, 2.0, 2.0, 2.0, 0.1, 0.2, 0.3])
        .unwrap();
    assert!(rows.push_texels(&[f32::INFINITY; 12]).is_err());
    assert!(rows.push_texels(&[0.0; 11]).is_err());
    let bytes = rows.encode();
    let limits = Limits::default();
    let back = PlaneRows::decode(&bytes, 1, 3, &limits).unwrap();
    assert_eq!(back.nonzeros(), rows.nonzeros());
    // An entry count past order², a repeated index, a zero value.
    let counts = 8 + 88;
    let mut b = bytes.clone();
    b[counts..counts + 4].copy_from_slice(&5u32.to_le_bytes());
    assert!(PlaneRows::decode(&b, 1, 3, &limits).is_err());
    let first_index = counts + 12;
    let mut b = bytes.clone();
    b.copy_within(first_index..first_index + 2, first_index + 2);
    assert!(PlaneRows::decode(&b, 1, 3, &limits).is_err());
    let values = bytes.len() - 4 * rows.nonzeros();
    let mut b = bytes.clone();
    b[values..values + 4].copy_from_slice(&0f32.to_le_bytes());
    assert!(PlaneRows::decode(&b, 1, 3, &limits).is_err());
    // Every truncation.
    for cut in 0..bytes.len() {
        assert!(
            PlaneRows::decode(&bytes[..cut], 1, 3, &limits).is_err(),
            "cut {cut}"
        );
    }
}

/// What `compress` makes from a store (the coder's buffers, the
/// near-field rows) is charged to the limits the store was opened with,
/// not to the machine's: growing the budget from what the store's own
/// tables take, compression is refused, naming what did not fit (the
/// near-field rows among them), until it succeeds.
#[test]
fn compress_charges_the_stores_limits() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_store(&dir.path().join("s.raw"), header(100));
    let tables = RawStore::open_with_limits(&path, &Limits::with_max_alloc(1 << 30))
        .unwrap()
        .limits()
        .used_bytes();
    let mut refused = Vec::new();
    for extra in (0..400).map(|k| 256 * k) {
        let limits = Limits::with_max_alloc(tables + extra);
        let raw = RawStore::open_with_limits(&path, &limits).unwrap();
        let out = dir.path().join("s.ltm");
        match compress(&raw, &out, &CompressOptions::default(), Progress::NONE) {
            Ok(_) => break,
            Err(e) => refused.push(e.to_string()),
        }
    }
    assert!(!refused.is_empty() && refused.len() < 400, "{refused:?}");
    assert!(
        refused.iter().any(|e| e.contains("near-field rows")),
        "{refused:?}"
    );
}

/// The independent reader (tools/validate/ltm_reader.py, written from
/// docs/FORMAT.md) decodes the NEAR chunk to the same plane and the same
/// coefficients, bit for bit, and reads the version-6 raw store's header.
/// Runs with the Python that `LTM_PYTHON` names (CI sets it); without it
/// the test says so and passes.
#[test]
fn the_independent_reader_decodes_the_near_field_rows() {
    let Some(python) = std::env::var_os("LTM_PYTHON") else {
        eprintln!("LTM_PYTHON is not set: the independent reader is not run");
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let raw = write_store(&dir.path().join("s.raw"), header(100));
    let out = dir.path().join("s.ltm");
    let store = RawStore::open(&raw).unwrap();
    compress(&store, &out, &CompressOptions::default(), Progress::NONE).unwrap();
    let reader = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tools/validate/ltm_reader.py");
    let json = dir.path().join("near.json");
    let run = |args: &[&std::ffi::OsStr]| {
        let o = std::process::Command::new(&python)
            .arg(&reader)
            .args(args)
            .output()
            .unwrap();
        let text = format!(
            "{}{}",
            String::from_utf8_lossy(&o.stdout),
            String::from_utf8_lossy(&o.stderr)
        );
        assert!(o.status.success(), "{text}");
        text
    };
    let text = run(&[out.as_os_str(), "--near-json".as_ref(), json.as_os_str()]);
    let file = LtmFile::open(&out).unwrap();
    let near = file.near_field().unwrap();
    assert!(
        text.contains(&format!("{} coefficients", near.nonzeros())),
        "{text}"
    );
    let b = near.basis();
    let bits = |v: &[f64]| -> String {
        let s: Vec<String> = v.iter().map(|x| x.to_bits().to_string()).collect();
        format!("[{}]", s.join(","))
    };
    let rows: Vec<String> = (0..30)
        .map(|p| {
            let (k, v) = near.row(p, 0);
            let k: Vec<String> = k.iter().map(u16::to_string).collect();
            let v: Vec<String> = v.iter().map(|x| x.to_bits().to_string()).collect();
            format!("[[{}],[{}]]", k.join(","), v.join(","))
        })
        .collect();
    let want = format!(
        "{{\"order\":{},\"side\":{},\"origin\":{},\"x\":{},\"y\":{},\"rows\":[{}]}}",
        b.order,
        b.side.to_bits(),
        bits(&b.origin),
        bits(&b.x_axis),
        bits(&b.y_axis),
        rows.join(",")
    );
    let got: String = std::fs::read_to_string(&json)
        .unwrap()
        .chars()
        .filter(|c| !c.is_whitespace())
        .collect();
    assert_eq!(got, want);
    let text = run(&[raw.as_os_str()]);
    assert!(text.contains("raw store version 6"), "{text}");
}
