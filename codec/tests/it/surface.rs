//! Per-row surface data and the row layout through the raw store (version
//! 3) and the `.ltm` container (version 2, chunk SURF), and version-1
//! `.ltm` files still read.

use ltm_codec::compress::{compress, CompressOptions};
use ltm_codec::container::{validate_bytes, LtmFile};
use ltm_codec::{
    Dims, Limits, Parameterization, RawHeader, RawWriter, RowLayout, Surface, SurfacePoint,
};
use std::path::{Path, PathBuf};

/// A smooth matrix over the grid, zero on invalid rows.
fn matrix(dims: Dims, surface: &Surface) -> Vec<f32> {
    let m = dims.lights();
    let mut t = vec![0.0f32; dims.pixels() * m];
    for (p, s) in surface.points().iter().enumerate() {
        if s.valid {
            for j in 0..m {
                t[p * m + j] = 0.2 + 0.1 * ((p + 3 * j) % 7) as f32 + (j % 5) as f32 * 0.01;
            }
        }
    }
    t
}

fn surface(dims: Dims) -> Surface {
    let w = dims.width() as usize;
    Surface::new(
        (0..dims.pixels())
            .map(|p| {
                let (x, y) = ((p % w) as f32, (p / w) as f32);
                if (x - 4.0).powi(2) + (y - 4.0).powi(2) > 12.0 {
                    SurfacePoint::INVALID
                } else {
                    SurfacePoint::new([x, y, 1.0], [x - 4.0, y - 4.0, 3.0])
                }
            })
            .collect(),
    )
    .unwrap()
}

fn compressed(dir: &Path, dims: Dims, with_surface: bool) -> (PathBuf, Surface) {
    let s = surface(dims);
    let t = matrix(dims, &s);
    let mut header = RawHeader::new(dims, false, 1 << 12);
    if with_surface {
        header = header.with_surface();
    }
    let raw = RawWriter::write_dense_with_surface(
        &dir.join("t.raw"),
        header,
        &t,
        None,
        with_surface.then_some(&s),
    )
    .unwrap();
    let out = dir.join("t.ltm");
    let store = ltm_codec::RawStore::open(&raw).unwrap();
    compress(
        &store,
        &out,
        &CompressOptions::default(),
        ltm_codec::Progress::NONE,
    )
    .unwrap();
    (out, s)
}

#[test]
fn texture_rows_and_surface_carry_through_compress() {
    let dir = tempfile::tempdir().unwrap();
    for dims in [
        Dims::texture(8, Parameterization::Sphere, 2, 1),
        Dims::texture(8, Parameterization::Uv, 2, 1),
        Dims::image(8, 8, 2, 1),
    ] {
        let (out, s) = compressed(dir.path(), dims, true);
        let f = LtmFile::open(&out).unwrap();
        assert_eq!(f.meta().dims, dims);
        assert_eq!(f.surface(), Some(&s));
        let bytes = std::fs::read(&out).unwrap();
        assert_eq!(
            u32::from_le_bytes(bytes[8..12].try_into().unwrap()),
            ltm_codec::container::VERSION
        );
        let features = u32::from_le_bytes(bytes[12..16].try_into().unwrap());
        assert_eq!(features & 4, 4, "feature flags {features:#x}");
    }
    let (out, _) = compressed(dir.path(), Dims::image(8, 8, 2, 1), false);
    let f = LtmFile::open(&out).unwrap();
    assert!(f.surface().is_none());
    assert!(matches!(f.meta().dims.rows, RowLayout::Image { .. }));
}

/// Rewrites the header's version field and the directory CRC.
fn set_version(bytes: &mut [u8], version: u32) {
    bytes[8..12].copy_from_slice(&version.to_le_bytes());
    let count = u32::from_le_bytes(bytes[16..20].try_into().unwrap()) as usize;
    let end = 24 + 32 * count;
    let crc = crc32fast::hash(&bytes[..end]);
    bytes[end..end + 4].copy_from_slice(&crc.to_le_bytes());
}

/// Version 1 is the version-2 layout without feature 4: a file written
/// without surface data and marked version 1 is read; a version-1 file
/// that claims feature 4 is refused, as is an unknown version.
#[test]
fn version_1_files_are_still_read() {
    let dir = tempfile::tempdir().unwrap();
    // A file written by the version-1 writer (committed fixture).
    let fixture =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/golden-v1.ltm");
    let f = LtmFile::open(&fixture).unwrap();
    assert!(f.surface().is_none());
    assert!(matches!(f.meta().dims.rows, RowLayout::Image { .. }));
    for j in 0..f.meta().dims.lights() {
        f.column(j).unwrap();
    }
    let (out, _) = compressed(
        dir.path(),
        Dims::texture(8, Parameterization::Uv, 2, 1),
        true,
    );
    let mut b = std::fs::read(&out).unwrap();
    set_version(&mut b, 1);
    let e = validate_bytes(&b, &Limits::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("feature flags"), "{e}");
    set_version(&mut b, ltm_codec::container::VERSION + 1);
    assert!(validate_bytes(&b, &Limits::default()).is_err());
}

/// Where the SURF chunk lies: (offset, len, directory entry index).
fn surf_chunk(bytes: &[u8]) -> (usize, usize, usize) {
    let count = u32::from_le_bytes(bytes[16..20].try_into().unwrap()) as usize;
    for i in 0..count {
        let e = &bytes[24 + 32 * i..24 + 32 * (i + 1)];
        if &e[..4] == b"SURF" {
            let off = u64::from_le_bytes(e[8..16].try_into().unwrap()) as usize;
            let len = u64::from_le_bytes(e[16..24].try_into().unwrap()) as usize;
            return (off, len, i);
        }
    }
    panic!("no SURF chunk");
}

#[test]
fn hostile_surface_chunks_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let (out, _) = compressed(
        dir.path(),
        Dims::texture(8, Parameterization::Sphere, 2, 1),
        true,
    );
    // Stored as is, so that its bytes can be edited in place.
    let good = ltm_codec::container::unpack_chunks(&std::fs::read(&out).unwrap()).unwrap();
    let limits = Limits::default();
    let (off, len, _) = surf_chunk(&good);
    assert_eq!(len, 16 + 28 * 64);
    // A flipped bit: the chunk CRC.
    let mut b = good.clone();
    b[off + 20] ^= 0x10;
    let e = validate_bytes(&b, &limits).unwrap_err().to_string();
    assert!(e.contains("SURF"), "{e}");
    // Bad fields with their CRC repaired: each refused with a message.
    for (at, v, why) in [
        (0usize, 9u32, "row layout"),
        (4, 0, "parameterization"),
        (8, 63, "row count"),
        (12, 1, "reserved"),
        (16 + 24, 2, "flags"),
        (16 + 12, f32::NAN.to_bits(), "must have zero"),
        // Row 36 (texel (4, 4)) is valid.
        (16 + 36 * 28 + 12, f32::NAN.to_bits(), "not finite"),
        (16 + 36 * 28 + 16, 0.5f32.to_bits(), "length"),
    ] {
        let mut b = good.clone();
        b[off + at..off + at + 4].copy_from_slice(&v.to_le_bytes());
        ltm_codec::container::repair_checksums(&mut b);
        let e = validate_bytes(&b, &limits).unwrap_err().to_string();
        assert!(e.contains(why), "{why}: {e}");
    }
    // The feature flag without the chunk, and the reverse.
    let mut b = good.clone();
    b[12..16].copy_from_slice(&0u32.to_le_bytes());
    ltm_codec::container::repair_checksums(&mut b);
    let e = validate_bytes(&b, &limits).unwrap_err().to_string();
    assert!(
        e.contains("SURF chunk and surface feature flag disagree"),
        "{e}"
    );
    // A limit below the surface data's size is refused before allocating.
    let e = LtmFile::from_bytes(good.clone(), &Limits::with_max_alloc(1000))
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("surface data") || e.contains("limit"), "{e}");
    // Every truncation is an error, never a panic.
    for cut in (0..good.len()).step_by(97) {
        assert!(validate_bytes(&good[..cut], &limits).is_err());
    }
}
