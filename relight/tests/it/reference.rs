//! The exact reference image T·L from a raw store, and image output.

use ltm_codec::{Dims, RawHeader};
use ltm_relight::{reference, relative_l2, EnvMap, Image, RelightError, Rotation};
use ltm_testkit::{block_bytes, write_raw};
use std::path::{Path, PathBuf};

/// Writes a raw store of `t` (P·M·C values) with small blocks (several per
/// store), and an albedo image when given.
/// Writes a raw store in blocks of two rows, so that the matrix spans
/// several blocks.
fn write_blocks(dir: &Path, name: &str, dims: Dims, t: &[f32], albedo: Option<&[f32]>) -> PathBuf {
    let bytes = block_bytes(dims, 2);
    assert!(RawHeader::new(dims, albedo.is_some(), bytes).block_count() > 1);
    write_raw(&dir.join(name), dims, t, albedo, bytes)
}

/// A deterministic matrix with some all-zero rows (every third pixel) and
/// mixed-sign entries.
fn matrix(dims: Dims) -> Vec<f32> {
    let (p, m, c) = (dims.pixels(), dims.lights(), dims.channels as usize);
    let mut t = vec![0.0f32; p * m * c];
    for px in 0..p {
        if px % 3 == 1 {
            continue;
        }
        for j in 0..m {
            for ch in 0..c {
                let i = (px * m + j) * c + ch;
                let v = ((i * 2_654_435_761) % 1000) as f32 / 1000.0;
                t[i] = if (i % 7) == 0 { -0.1 * v } else { v };
            }
        }
    }
    t
}

fn light(m: usize) -> Vec<[f32; 3]> {
    (0..m)
        .map(|j| [1.0 + j as f32, 0.5 * (j % 5) as f32, 100.0 / (1 + j) as f32])
        .collect()
}

/// The product by hand, in f64.
fn expected(dims: Dims, t: &[f32], l: &[[f32; 3]], albedo: Option<&[f32]>) -> Vec<[f64; 3]> {
    let (p, m, c) = (dims.pixels(), dims.lights(), dims.channels as usize);
    (0..p)
        .map(|px| {
            let mut b = [0.0f64; 3];
            for j in 0..m {
                for ch in 0..3 {
                    let tv = t[(px * m + j) * c + if c == 3 { ch } else { 0 }] as f64;
                    b[ch] += tv * l[j][ch] as f64;
                }
            }
            if let Some(a) = albedo {
                for ch in 0..3 {
                    b[ch] *= a[3 * px + ch] as f64;
                }
            }
            b
        })
        .collect()
}

fn assert_matches(img: &Image, want: &[[f64; 3]]) {
    assert!(img.first_non_finite().is_none());
    assert_eq!(img.data.len(), want.len());
    for (px, (got, want)) in img.data.iter().zip(want).enumerate() {
        for c in 0..3 {
            let tol = 1e-6 * want[c].abs().max(1.0);
            assert!(
                (got[c] as f64 - want[c]).abs() <= tol,
                "pixel {px} channel {c}: {} vs {}",
                got[c],
                want[c]
            );
        }
        if px % 3 == 1 {
            assert_eq!(*got, [0.0; 3], "zero row {px}");
        }
    }
}

fn dims(width: u32, height: u32, face_res: u32, channels: u32) -> Dims {
    Dims::image(width, height, face_res, channels)
}

#[test]
fn rgb_transport_matches_the_hand_product() {
    let dir = tempfile::tempdir().unwrap();
    let d = dims(5, 3, 2, 3);
    let t = matrix(d);
    let path = write_blocks(dir.path(), "rgb.raw", d, &t, None);
    let raw = ltm_codec::RawStore::open(&path).unwrap();
    let l = light(d.lights());
    let img = reference(&raw, &l).unwrap();
    assert_eq!((img.width, img.height), (5, 3));
    assert_matches(&img, &expected(d, &t, &l, None));
}

#[test]
fn grey_transport_multiplies_rgb_light_and_albedo() {
    let dir = tempfile::tempdir().unwrap();
    let d = dims(4, 4, 1, 1);
    let t = matrix(d);
    let albedo: Vec<f32> = (0..3 * d.pixels())
        .map(|i| 0.1 + (i % 9) as f32 * 0.1)
        .collect();
    let l = light(d.lights());

    let path = write_blocks(dir.path(), "albedo.raw", d, &t, Some(&albedo));
    let raw = ltm_codec::RawStore::open(&path).unwrap();
    let img = reference(&raw, &l).unwrap();
    assert_matches(&img, &expected(d, &t, &l, Some(&albedo)));

    let path = write_blocks(dir.path(), "grey.raw", d, &t, None);
    let raw = ltm_codec::RawStore::open(&path).unwrap();
    let img = reference(&raw, &l).unwrap();
    assert_matches(&img, &expected(d, &t, &l, None));
    // Grey transport under grey light is grey.
    let grey: Vec<[f32; 3]> = l.iter().map(|v| [v[0]; 3]).collect();
    let img = reference(&raw, &grey).unwrap();
    assert!(img.data.iter().all(|p| p[0] == p[1] && p[1] == p[2]));
}

#[test]
fn constant_environment_gives_row_sums() {
    // Under a constant environment of radiance c, B[p] = c·Σ_j T[p, j].
    let dir = tempfile::tempdir().unwrap();
    let d = dims(3, 2, 4, 1);
    let t = matrix(d);
    let path = write_blocks(dir.path(), "env.raw", d, &t, None);
    let raw = ltm_codec::RawStore::open(&path).unwrap();
    let env = EnvMap::constant(64, 32, [2.0, 0.5, 0.0]).unwrap();
    let cube = env.to_cubemap(4, &Rotation::yaw(33.0));
    let img = reference(&raw, &cube).unwrap();
    let m = d.lights();
    for (px, got) in img.data.iter().enumerate() {
        let sum: f64 = t[px * m..(px + 1) * m].iter().map(|&v| v as f64).sum();
        for (c, k) in [2.0, 0.5, 0.0].iter().enumerate() {
            assert!((got[c] as f64 - k * sum).abs() <= 1e-5 * (k * sum).abs().max(1e-6));
        }
    }
}

#[test]
fn bad_lighting_and_damaged_stores_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let d = dims(3, 3, 1, 3);
    let t = matrix(d);
    let path = write_blocks(dir.path(), "s.raw", d, &t, None);
    let raw = ltm_codec::RawStore::open(&path).unwrap();
    let e = reference(&raw, &light(5)).unwrap_err();
    assert!(matches!(e, RelightError::OutOfRange { .. }), "{e}");
    assert!(e.to_string().contains("6·n² = 6"), "{e}");
    let mut l = light(6);
    l[4][1] = f32::NAN;
    let e = reference(&raw, &l).unwrap_err();
    assert!(e.to_string().contains("texel 4"), "{e}");
    // An overflowing product is an error, not an infinite pixel.
    let huge = vec![[f32::MAX; 3]; 6];
    assert!(reference(&raw, &huge).is_err());
    drop(raw);

    // Flip one byte of the matrix data: the block checksum catches it.
    let mut bytes = std::fs::read(&path).unwrap();
    let data_offset = u64::from_le_bytes(bytes[40..48].try_into().unwrap()) as usize;
    bytes[data_offset + 4 * 6 * 3 * 2 + 1] ^= 0x40;
    std::fs::write(&path, bytes).unwrap();
    let raw = ltm_codec::RawStore::open(&path).unwrap();
    let e = reference(&raw, &light(6)).unwrap_err();
    assert!(
        matches!(e, RelightError::Codec(ltm_codec::Error::Crc { .. })),
        "{e}"
    );
}

#[test]
#[cfg(all(feature = "exr", feature = "png"))]
fn exr_and_png_output() {
    let dir = tempfile::tempdir().unwrap();
    let d = dims(6, 4, 1, 3);
    let t = matrix(d);
    let path = write_blocks(dir.path(), "o.raw", d, &t, None);
    let raw = ltm_codec::RawStore::open(&path).unwrap();
    let img = reference(&raw, &light(6)).unwrap();

    let exr = dir.path().join("ref.exr");
    img.write_exr(&exr).unwrap();
    assert!(!dir.path().join("ref.exr.tmp").exists());
    let back = Image::read_exr(&exr).unwrap();
    assert_eq!(back, img);
    assert_eq!(relative_l2(&back, &img).unwrap(), 0.0);

    // Tone mapping: 2^EV, clamp, sRGB.
    let tones =
        Image::from_data(4, 1, vec![[0.0; 3], [0.25; 3], [0.5, 1.0, 2.0], [-1.0; 3]]).unwrap();
    let png = dir.path().join("tones.png");
    tones.write_png(&png, 1.0).unwrap();
    assert!(!dir.path().join("tones.png.tmp").exists());
    let decoded = image::open(&png).unwrap().to_rgb8();
    assert_eq!(decoded.dimensions(), (4, 1));
    assert_eq!(decoded.get_pixel(0, 0).0, [0, 0, 0]);
    assert_eq!(decoded.get_pixel(1, 0).0, [188, 188, 188]); // sRGB(0.5)
    assert_eq!(decoded.get_pixel(2, 0).0, [255, 255, 255]);
    assert_eq!(decoded.get_pixel(3, 0).0, [0, 0, 0]);
    img.write_png(&dir.path().join("ref.png"), 0.0).unwrap();
    assert!(tones.write_png(&png, f32::NAN).is_err());
}

#[test]
#[cfg(all(feature = "exr", feature = "png"))]
fn writers_refuse_non_finite_and_malformed_images() {
    let dir = tempfile::tempdir().unwrap();
    let mut img = Image::new(3, 2);
    img.data[4] = [0.0, f32::NAN, 0.0];
    assert_eq!(img.first_non_finite(), Some((1, 1)));
    let e = img.write_exr(&dir.path().join("nan.exr")).unwrap_err();
    assert!(e.to_string().contains("(1, 1)"), "{e}");
    assert!(img.write_png(&dir.path().join("nan.png"), 0.0).is_err());
    assert!(!dir.path().join("nan.exr").exists());
    let short = Image {
        width: 3,
        height: 2,
        data: vec![[0.0; 3]; 5],
    };
    assert!(short.write_exr(&dir.path().join("short.exr")).is_err());
    assert!(Image::from_data(3, 2, vec![[0.0; 3]; 5]).is_err());
    assert!(Image::new(0, 0)
        .write_png(&dir.path().join("empty.png"), 0.0)
        .is_err());
    // A directory that does not exist.
    let e = Image::new(2, 2)
        .write_exr(&dir.path().join("no/such/dir.exr"))
        .unwrap_err();
    assert!(e.to_string().contains("dir.exr"), "{e}");
    assert!(Image::read_exr(&dir.path().join("missing.exr")).is_err());
}

#[test]
fn relative_error_measure() {
    let a = Image::from_data(2, 1, vec![[1.0, 2.0, 2.0], [0.0; 3]]).unwrap();
    let b = Image::from_data(2, 1, vec![[1.0, 2.0, 2.0], [0.0, 0.0, 3.0]]).unwrap();
    // ‖a − b‖ = 3, ‖b‖ = √18.
    let e = relative_l2(&a, &b).unwrap();
    assert!((e - 3.0 / 18f64.sqrt()).abs() < 1e-15);
    assert_eq!(relative_l2(&b, &b).unwrap(), 0.0);
    // An all-zero reference leaves the relative error undefined; a NaN or
    // infinite pixel in either image is named.
    let zero = Image::new(2, 1);
    for x in [&zero, &a] {
        let e = relative_l2(x, &zero).unwrap_err().to_string();
        assert!(e.contains("all zero") && e.contains("undefined"), "{e}");
    }
    for bad in [f32::NAN, f32::INFINITY] {
        let mut c = b.clone();
        c.data[1][2] = bad;
        let e = relative_l2(&a, &c).unwrap_err().to_string();
        assert!(e.contains("reference pixel (1, 0)"), "{e}");
        let e = relative_l2(&c, &b).unwrap_err().to_string();
        assert!(e.contains("relit image pixel (1, 0)"), "{e}");
    }
    // Values near the f32 limit give a finite error.
    let big = Image::from_data(2, 1, vec![[3e38; 3], [-3e38; 3]]).unwrap();
    let e = relative_l2(&a, &big).unwrap();
    assert!(e.is_finite() && (e - 1.0).abs() < 1e-6, "{e}");
    assert!(relative_l2(&a, &Image::new(1, 2)).is_err());
}

/// An OpenEXR header whose data window claims 10⁹ × 10⁹ pixels is refused
/// with its size and the limit, not called corrupt, by the image and the
/// environment-map readers.
#[test]
fn a_huge_exr_data_window_is_refused_with_its_size() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("small.exr");
    Image::from_data(4, 2, vec![[0.5; 3]; 8])
        .unwrap()
        .write_exr(&path)
        .unwrap();
    let mut bytes = std::fs::read(&path).unwrap();
    let at = bytes
        .windows(17)
        .position(|w| w == b"dataWindow\0box2i\0")
        .expect("a data window")
        + 17
        + 4;
    for (k, v) in [0i32, 0, 999_999_999, 999_999_999].into_iter().enumerate() {
        bytes[at + 4 * k..at + 4 * k + 4].copy_from_slice(&v.to_le_bytes());
    }
    let huge = dir.path().join("huge.exr");
    std::fs::write(&huge, &bytes).unwrap();
    for e in [
        Image::read_exr(&huge).unwrap_err().to_string(),
        EnvMap::load(&huge).err().unwrap().to_string(),
    ] {
        assert!(
            e.contains("1000000000×1000000000")
                && e.contains(&ltm_relight::MAX_READ_PIXELS.to_string())
                && !e.contains("corrupt"),
            "{e}"
        );
    }
}
