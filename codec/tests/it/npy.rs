//! `.npy` import and export: round trip through the raw store and the codec,
//! and the bad inputs that must be refused with a clear message.

use ltm_codec::compress::{compress, CodeOptions, Target};
use ltm_codec::container::LtmFile;
use ltm_codec::npy::{decode_matrix, export_npy, import_npy, read_npy_header, NpyDtype};
use ltm_codec::Limits;
use ltm_codec::RawStore;
use std::path::Path;

fn write_npy(path: &Path, descr: &str, shape: &str, data: &[u8]) {
    let mut dict = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}");
    while (10 + dict.len() + 1) % 64 != 0 {
        dict.push(' ');
    }
    dict.push('\n');
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend_from_slice(&(dict.len() as u16).to_le_bytes());
    bytes.extend_from_slice(dict.as_bytes());
    bytes.extend_from_slice(data);
    std::fs::write(path, bytes).unwrap();
}

fn f32_bytes(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

#[test]
fn import_compress_export_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let (p, m) = (12usize, 24usize);
    let t: Vec<f32> = (0..p * m)
        .map(|i| ((i * 37 % 101) as f32 / 100.0).powi(2))
        .collect();
    let npy = dir.path().join("t.npy");
    write_npy(&npy, "<f4", &format!("({p}, {m})"), &f32_bytes(&t));
    let raw = dir.path().join("t.raw");
    let dims = import_npy(&npy, 4, 3, &raw, ltm_codec::Progress::NONE).unwrap();
    assert_eq!((dims.face_res(), dims.channels), (2, 1));
    let store = RawStore::open(&raw).unwrap();
    let mut rows = Vec::new();
    store.read_rows(0..p, &mut rows).unwrap();
    assert_eq!(rows, t);
    let ltm = dir.path().join("t.ltm");
    let opts = CodeOptions {
        bits: 16,
        target: Target::MaxError(0.0005),
        ..Default::default()
    };
    compress(&store, &ltm, &opts.into(), ltm_codec::Progress::NONE).unwrap();
    let out = dir.path().join("d.npy");
    let file = LtmFile::open(&ltm).unwrap();
    export_npy(&file, &out, &Limits::default()).unwrap();
    let mut r = std::io::BufReader::new(std::fs::File::open(&out).unwrap());
    let header = read_npy_header(&mut r).unwrap();
    assert_eq!(
        (header.dtype, header.shape.clone()),
        (NpyDtype::F32, vec![p, m])
    );
    let bytes = std::fs::read(&out).unwrap();
    let d: Vec<f32> = bytes[header.data_offset..]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
        .collect();
    assert_eq!(d, decode_matrix(&file, &Limits::default()).unwrap());
    let err: f64 = d
        .iter()
        .zip(&t)
        .map(|(a, b)| ((a - b) as f64).powi(2))
        .sum::<f64>()
        .sqrt()
        / t.iter().map(|v| (*v as f64).powi(2)).sum::<f64>().sqrt();
    assert!(err < 0.0005, "{err}");
}

#[test]
fn float64_and_three_channels_import() {
    let dir = tempfile::tempdir().unwrap();
    let v: Vec<f64> = (0..2 * 6 * 3).map(|i| i as f64 * 0.5).collect();
    let npy = dir.path().join("t.npy");
    write_npy(
        &npy,
        "<f8",
        "(2, 6, 3)",
        &v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<_>>(),
    );
    let raw = dir.path().join("t.raw");
    let dims = import_npy(&npy, 2, 1, &raw, ltm_codec::Progress::NONE).unwrap();
    assert_eq!((dims.face_res(), dims.channels), (1, 3));
    let store = RawStore::open(&raw).unwrap();
    let mut row = Vec::new();
    store.read_rows(1..2, &mut row).unwrap();
    assert_eq!(row[0], 9.0);
}

#[test]
fn bad_npy_files_are_refused_and_leave_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let raw = dir.path().join("x.raw");
    let good = f32_bytes(&[0.5; 4 * 6]);
    let cases: Vec<(&str, String, Vec<u8>, u32, &str)> = vec![
        ("<i4", "(4, 6)".into(), good.clone(), 4, "dtype"),
        ("<f4", "(4, 7)".into(), f32_bytes(&[0.5; 28]), 4, "columns"),
        ("<f4", "(4, 6)".into(), good.clone(), 5, "rows"),
        ("<f4", "(4, 6)".into(), good[..20].to_vec(), 4, "bytes"),
        ("<f4", "(4,)".into(), f32_bytes(&[1.0; 4]), 4, "shape"),
        (
            "<f4",
            "(4, 6)".into(),
            f32_bytes(&[0.5, f32::NAN].repeat(12)),
            4,
            "NaN",
        ),
        (
            "<f4",
            "(4, 6)".into(),
            f32_bytes(&[f32::INFINITY; 24]),
            4,
            "inf",
        ),
        ("<f4", "(4, 54)".into(), f32_bytes(&[1.0; 216]), 4, "6·n²"),
        // 2^32 + 3 channels: must not be read as 3.
        (
            "<f4",
            "(4, 6, 4294967299)".into(),
            good.clone(),
            4,
            "channels",
        ),
        (
            "<f4",
            "(4, 6, 2)".into(),
            f32_bytes(&[0.5; 48]),
            4,
            "channels",
        ),
    ];
    for (descr, shape, data, width, what) in cases {
        let npy = dir.path().join("bad.npy");
        write_npy(&npy, descr, &shape, &data);
        let err = import_npy(&npy, width, 1, &raw, ltm_codec::Progress::NONE).expect_err(what);
        assert!(!err.to_string().is_empty());
        if what == "channels" {
            assert!(err.to_string().contains("channels"), "{err}");
        }
        assert!(
            !raw.exists() && !dir.path().join("x.raw.partial").exists(),
            "{what}: output left behind ({err})"
        );
    }
    std::fs::write(dir.path().join("junk.npy"), b"not numpy at all").unwrap();
    assert!(import_npy(
        &dir.path().join("junk.npy"),
        1,
        1,
        &raw,
        ltm_codec::Progress::NONE
    )
    .is_err());
    assert!(import_npy(
        &dir.path().join("missing.npy"),
        1,
        1,
        &raw,
        ltm_codec::Progress::NONE
    )
    .is_err());
}

#[test]
fn header_dictionary_accepts_what_numpy_writes() {
    use ltm_codec::npy::parse_header_dict;
    for (dict, shape) in [
        (
            "{'descr': '<f4', 'fortran_order': False, 'shape': (3, 4), }",
            vec![3, 4],
        ),
        (
            "{\"descr\": \"<f4\", \"fortran_order\": False, \"shape\": (3, 4, 3)}",
            vec![3, 4, 3],
        ),
        (
            "{'shape': (5,), 'fortran_order': False, 'descr': '<f4'}   \n",
            vec![5],
        ),
        ("{'descr':'<f4','fortran_order':False,'shape':()}", vec![]),
    ] {
        let (dtype, s) = parse_header_dict(dict).unwrap_or_else(|e| panic!("{dict}: {e}"));
        assert_eq!((dtype, s), (NpyDtype::F32, shape), "{dict}");
    }
    let (dtype, s) =
        parse_header_dict("{'descr': '<f8', 'fortran_order': False, 'shape': (4294967297, 6), }")
            .unwrap();
    // A dimension above u32 is kept whole (not truncated to 32 bits).
    assert_eq!((dtype, s), (NpyDtype::F64, vec![4294967297, 6]));
}

#[test]
fn malformed_header_dictionaries_are_errors() {
    use ltm_codec::npy::parse_header_dict;
    for dict in [
        "",
        "{",
        "{'descr': '<f4', 'fortran_order': False, 'shape': )3, 4(, }",
        "{'descr': '<f4', 'fortran_order': False, 'shape': (3, 4}",
        "{'descr': '<f4', 'fortran_order': False, 'shape': (3 4), }",
        "{'descr': '<f4', 'fortran_order': False, 'shape': (3), }",
        "{'descr': '<f4', 'fortran_order': False, 'shape': (-3, 4), }",
        "{'descr': '<f4', 'fortran_order': False, 'shape': (99999999999999999999999, 4), }",
        "{'descr': '<f4', 'descr': '<f8', 'fortran_order': False, 'shape': (3, 4), }",
        "{'descr': '<f4', 'fortran_order': False, 'shape': (3, 4), 'shape': (6, 2), }",
        "{'descr': '<f4', 'fortran_order': False, 'shape': (3, 4), 'extra': 1}",
        "{'descr': '<f4', 'fortran_order': False}",
        "{'descr': '<f4', 'fortran_order': maybe, 'shape': (3, 4)}",
        "{'descr': '<f4', 'fortran_order': True, 'shape': (3, 4)}",
        "{'descr': '>f4', 'fortran_order': False, 'shape': (3, 4)}",
        "{'descr': '<i4', 'fortran_order': False, 'shape': (3, 4)}",
        "{'descr: '<f4', 'fortran_order': False, 'shape': (3, 4)}",
        "{'descr': '<f4', 'fortran_order': False, 'shape': (3, 4)} trailing",
        "{'descr': '<f\\4', 'fortran_order': False, 'shape': (3, 4)}",
    ] {
        assert!(parse_header_dict(dict).is_err(), "accepted: {dict}");
    }
}
