//! The receiving mesh of a texture-space matrix through the raw store
//! (version 4) and the `.ltm` container (version 6, chunk MESH): carried
//! bit for bit by both compressors, resumed only when equal, and every
//! invalid chunk an error, never a panic.

use ltm_codec::compress::{compress, compress_pca, CompressOptions, PcaOptions};
use ltm_codec::container::{validate_bytes, LtmFile};
use ltm_codec::raw::{RestartReason, ResumeState};
use ltm_codec::{
    Dims, Error, Limits, Parameterization, RawHeader, RawStore, RawWriter, ReceiverMesh, Surface,
    SurfacePoint,
};
use std::path::{Path, PathBuf};

const S: u32 = 8;

fn dims() -> Dims {
    Dims::texture(S, Parameterization::Atlas, 2, 1)
}

/// Every texel valid, on the plane z = 0.
fn surface(dims: Dims) -> Surface {
    let w = dims.width() as usize;
    Surface::new(
        (0..dims.pixels())
            .map(|p| SurfacePoint::new([(p % w) as f32, (p / w) as f32, 0.0], [0.0, 0.0, 1.0]))
            .collect(),
    )
    .unwrap()
}

/// A fan of `n` triangles around the texture's centre (at least 1).
fn mesh(n: usize) -> ReceiverMesh {
    let s = S as f32;
    let ring = |k: usize| {
        let a = k as f32 / n as f32 * std::f32::consts::TAU;
        [s / 2.0 + 3.9 * a.cos(), s / 2.0 + 3.9 * a.sin()]
    };
    let mut uvs = vec![[s / 2.0; 2]];
    uvs.extend((0..n).map(ring));
    ReceiverMesh {
        positions: uvs.iter().map(|uv| [uv[0], -uv[1], 0.25]).collect(),
        normals: (0..=n)
            .map(|k| if k == 1 { [0.0; 3] } else { [0.0, 0.0, 1.0] })
            .collect(),
        uvs,
        triangles: (0..n as u32)
            .map(|k| [0, 1 + k, 1 + (k + 1) % n as u32])
            .collect(),
    }
}

fn matrix(dims: Dims) -> Vec<f32> {
    let m = dims.lights();
    (0..dims.pixels() * m)
        .map(|i| 0.1 + ((i / m * 3 + i % m * 7) % 11) as f32 * 0.05)
        .collect()
}

/// A texture raw store with `mesh` (version 4), or without (version 3).
fn raw(dir: &Path, name: &str, mesh: Option<&ReceiverMesh>) -> PathBuf {
    let d = dims();
    let mut header = RawHeader::new(d, false, 1 << 12).with_input_id([5; 32]);
    if let Some(m) = mesh {
        header = header.with_mesh(m);
    }
    assert_eq!(header.version(), if mesh.is_some() { 4 } else { 3 });
    RawWriter::write_dense_with_geometry(
        &dir.join(name),
        header,
        &matrix(d),
        None,
        Some(&surface(d)),
        mesh,
    )
    .unwrap()
}

fn compressed(dir: &Path, mesh: Option<&ReceiverMesh>, pca: bool) -> PathBuf {
    let store = RawStore::open(&raw(dir, "t.raw", mesh)).unwrap();
    let out = dir.join(if pca { "p.ltm" } else { "w.ltm" });
    if pca {
        let opts = PcaOptions {
            rank: Some(3),
            ..Default::default()
        };
        compress_pca(&store, &out, &opts, ltm_codec::Progress::NONE).unwrap();
    } else {
        let opts = CompressOptions::default();
        compress(&store, &out, &opts, ltm_codec::Progress::NONE).unwrap();
    }
    out
}

/// The directory of an `.ltm` image: (tag, offset, length) per chunk.
fn directory(b: &[u8]) -> Vec<([u8; 4], usize, usize)> {
    let k = u32::from_le_bytes(b[16..20].try_into().unwrap()) as usize;
    (0..k)
        .map(|e| {
            let at = 24 + 32 * e;
            let word = |o: usize| u64::from_le_bytes(b[at + o..at + o + 8].try_into().unwrap());
            (
                b[at..at + 4].try_into().unwrap(),
                word(8) as usize,
                word(16) as usize,
            )
        })
        .collect()
}

/// Chunk `e` of the directory, unpacked when it is stored as a zstd frame
/// (version 7: the entry's first reserved word is 1, its last the length)
/// or a zstd frame of planes (version 8: 2).
fn unpacked(b: &[u8], e: usize, (off, len): (usize, usize)) -> Vec<u8> {
    let at = 24 + 32 * e;
    let word = |o: usize| u32::from_le_bytes(b[at + o..at + o + 4].try_into().unwrap());
    let stored = &b[off..off + len];
    match word(4) {
        0 => stored.to_vec(),
        1 => zstd::bulk::decompress(stored, word(28) as usize).unwrap(),
        2 => unplane(&zstd::bulk::decompress(stored, word(28) as usize).unwrap()),
        e => panic!("encoding {e}"),
    }
}

/// docs/FORMAT.md "Planes", undone: a head of `len mod 28` bytes, then per
/// word of the 28-byte records and per byte, a plane of the words' deltas.
fn unplane(p: &[u8]) -> Vec<u8> {
    let (h, n) = (p.len() % 28, p.len() / 28);
    let mut out = p[..h].to_vec();
    out.resize(p.len(), 0);
    for w in 0..7 {
        let mut word = 0u32;
        for r in 0..n {
            let delta = (0..4).fold(0u32, |d, b| {
                d | (p[h + (4 * w + b) * n + r] as u32) << (8 * b)
            });
            word = word.wrapping_add(delta);
            out[h + 28 * r + 4 * w..][..4].copy_from_slice(&word.to_le_bytes());
        }
    }
    out
}

/// Chunk `tag`, unpacked.
fn chunk(b: &[u8], tag: &[u8; 4]) -> Option<Vec<u8>> {
    let (e, (_, off, len)) = directory(b)
        .into_iter()
        .enumerate()
        .find(|c| &c.1 .0 == tag)?;
    Some(unpacked(b, e, (off, len)))
}

/// Rebuilds an `.ltm` image with the chunks `edit` gives (in order, every
/// chunk stored as is) and feature flags `features`, every offset and CRC
/// recomputed. DATA (whose columns are addressed from its start) moves as
/// a whole.
fn rebuild(b: &[u8], features: u32, edit: impl FnOnce(&mut Vec<([u8; 4], Vec<u8>)>)) -> Vec<u8> {
    let mut chunks: Vec<([u8; 4], Vec<u8>)> = directory(b)
        .into_iter()
        .enumerate()
        .map(|(e, (t, off, len))| (t, unpacked(b, e, (off, len))))
        .collect();
    edit(&mut chunks);
    let head = 24 + 32 * chunks.len() + 4;
    let mut out = b[..8].to_vec();
    for v in [
        u32::from_le_bytes(b[8..12].try_into().unwrap()),
        features,
        chunks.len() as u32,
        0,
    ] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    let mut offset = head as u64;
    for (tag, bytes) in &chunks {
        out.extend_from_slice(tag);
        out.extend_from_slice(&0u32.to_le_bytes());
        out.extend_from_slice(&offset.to_le_bytes());
        out.extend_from_slice(&(bytes.len() as u64).to_le_bytes());
        let crc = if tag == b"DATA" {
            0
        } else {
            crc32fast::hash(bytes)
        };
        out.extend_from_slice(&crc.to_le_bytes());
        out.extend_from_slice(&0u32.to_le_bytes());
        offset += bytes.len() as u64;
    }
    let crc = crc32fast::hash(&out);
    out.extend_from_slice(&crc.to_le_bytes());
    for (_, bytes) in &chunks {
        out.extend_from_slice(bytes);
    }
    out
}

fn features(b: &[u8]) -> u32 {
    u32::from_le_bytes(b[12..16].try_into().unwrap())
}

/// The MESH chunk replaced by `f` applied to it.
fn with_mesh_chunk(b: &[u8], f: impl FnOnce(&mut Vec<u8>)) -> Vec<u8> {
    rebuild(b, features(b), |chunks| {
        let c = chunks.iter_mut().find(|c| &c.0 == b"MESH").unwrap();
        f(&mut c.1);
    })
}

/// Raw store → `ltm compress` (wavelet and pca) → `.ltm` keeps the mesh bit
/// for bit; without a mesh, the raw store stays version 3 and the `.ltm`
/// has no MESH chunk.
#[test]
fn the_mesh_carries_through_both_compressors_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let m = mesh(7);
    let store = RawStore::open(&raw(dir.path(), "r.raw", Some(&m))).unwrap();
    assert_eq!(store.header().version(), 4);
    assert_eq!(store.mesh(), Some(&m));
    for pca in [false, true] {
        let out = compressed(dir.path(), Some(&m), pca);
        let bytes = std::fs::read(&out).unwrap();
        assert_eq!(
            u32::from_le_bytes(bytes[8..12].try_into().unwrap()),
            ltm_codec::container::VERSION
        );
        assert_eq!(features(&bytes) & 16, 16);
        assert_eq!(chunk(&bytes, b"MESH"), Some(m.encode()));
        let tags: Vec<_> = directory(&bytes).into_iter().map(|c| c.0).collect();
        let at = |t: &[u8; 4]| tags.iter().position(|x| x == t).unwrap();
        assert_eq!(at(b"MESH"), at(b"SURF") + 1, "MESH right after SURF");
        let f = LtmFile::open(&out).unwrap();
        assert_eq!(f.mesh(), Some(&m), "pca {pca}");
        assert_eq!(f.mesh().unwrap().encode(), m.encode());
        assert_eq!(f.surface(), Some(&surface(dims())));
        // The mesh is charged while the file is open.
        let limits = Limits::with_max_alloc(1 << 30);
        let held = LtmFile::open_with_limits(&out, &limits).unwrap();
        let with = limits.used_bytes();
        drop(held);
        let plain = compressed(dir.path(), None, pca);
        let f = LtmFile::open_with_limits(&plain, &limits).unwrap();
        assert!(f.mesh().is_none());
        let without = limits.used_bytes()
            + (bytes.len() - std::fs::metadata(&plain).unwrap().len() as usize) as u64;
        assert!(
            with >= without + m.heap_bytes() as u64,
            "{with} vs {without}"
        );
        let plain = std::fs::read(&plain).unwrap();
        assert_eq!(features(&plain) & 16, 0);
        assert!(chunk(&plain, b"MESH").is_none());
    }
}

/// A partial raw store is resumed only with the same mesh: another mesh
/// of the same length, one of another length, or none restarts it with
/// `DifferentMesh`.
#[test]
fn resume_needs_the_same_mesh() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.raw");
    let d = dims();
    let header = |m: Option<&ReceiverMesh>| {
        let h = RawHeader::new(d, false, 1 << 10).with_input_id([3; 32]);
        m.map_or(h, |m| h.with_mesh(m))
    };
    let s = surface(d);
    let a = mesh(5);
    let mut b = a.clone();
    b.positions[2][1] += 0.5;
    let longer = mesh(6);
    let t = matrix(d);
    let open = |m: Option<&ReceiverMesh>| {
        let mut w = RawWriter::create_with_geometry(&path, header(m), Some(&s), m).unwrap();
        let state = w.resume_state();
        let r = w.header().block_range(0);
        w.write_block(0, &t[r.start * d.row_len()..r.end * d.row_len()], None)
            .unwrap();
        state
    };
    let restarted = ResumeState::Restarted(RestartReason::DifferentMesh);
    let total = header(None).block_count();
    assert_eq!(open(Some(&a)), ResumeState::New);
    assert_eq!(open(Some(&a)), ResumeState::Resumed { kept: 1, total });
    assert_eq!(open(Some(&b)), restarted);
    assert_eq!(open(Some(&b)), ResumeState::Resumed { kept: 1, total });
    assert_eq!(open(Some(&longer)), restarted);
    assert_eq!(open(None), restarted);
    assert_eq!(open(Some(&a)), restarted);
    assert!(restarted.to_string().contains("receiver mesh"));
    // Whatever was resumed, the finished store holds the last mesh.
    let mut w =
        RawWriter::create_with_geometry(&path, header(Some(&a)), Some(&s), Some(&a)).unwrap();
    for blk in w.pending_blocks() {
        let r = w.header().block_range(blk);
        w.write_block(blk, &t[r.start * d.row_len()..r.end * d.row_len()], None)
            .unwrap();
    }
    let done = w.finish().unwrap();
    assert_eq!(RawStore::open(&done).unwrap().mesh(), Some(&a));
}

/// The writers refuse a mesh they cannot store: without room in the
/// header, of another length, invalid for the texture, for image rows.
#[test]
fn writers_refuse_a_mesh_they_cannot_store() {
    let dir = tempfile::tempdir().unwrap();
    let d = dims();
    let s = surface(d);
    let m = mesh(4);
    let plain = RawHeader::new(d, false, 1 << 12);
    let p = dir.path().join("x.raw");
    let err = |r: ltm_codec::Result<RawWriter>| r.err().unwrap().to_string();
    let e = err(RawWriter::create_with_geometry(
        &p,
        plain,
        Some(&s),
        Some(&m),
    ));
    assert!(e.contains("with_mesh"), "{e}");
    let e = err(RawWriter::create_with_geometry(
        &p,
        plain.with_mesh(&m),
        Some(&s),
        None,
    ));
    assert!(e.contains("none was given"), "{e}");
    let e = err(RawWriter::create_with_geometry(
        &p,
        plain.with_mesh(&mesh(5)),
        Some(&s),
        Some(&m),
    ));
    assert!(e.contains("receiver mesh"), "{e}");
    let mut bad = m.clone();
    bad.uvs[0] = [S as f32 + 1.0, 0.0];
    let e = err(RawWriter::create_with_geometry(
        &p,
        plain.with_mesh(&bad),
        Some(&s),
        Some(&bad),
    ));
    assert!(e.contains("outside [0, 8]"), "{e}");
    let image = RawHeader::new(Dims::image(8, 8, 2, 1), false, 1 << 12).with_surface();
    let e = err(RawWriter::create_with_geometry(
        &p,
        image.with_mesh(&m),
        Some(&s),
        Some(&m),
    ));
    assert!(e.contains("texture-space"), "{e}");
}

/// Rewrites the raw store header's CRC (over bytes `0..124`).
fn fix_raw_header(b: &mut [u8]) {
    let crc = crc32fast::hash(&b[..124]);
    b[124..128].copy_from_slice(&crc.to_le_bytes());
}

/// Every damaged version-4 header or mesh section is an error naming it.
#[test]
fn invalid_raw_mesh_sections_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let m = mesh(6);
    let good = std::fs::read(raw(dir.path(), "g.raw", Some(&m))).unwrap();
    let mesh_at = u64::from_le_bytes(good[108..116].try_into().unwrap()) as usize;
    assert_eq!(mesh_at % 64, 0);
    assert_eq!(
        u64::from_le_bytes(good[116..124].try_into().unwrap()),
        m.encoded_len() as u64
    );
    assert_eq!(&good[mesh_at..mesh_at + m.encoded_len()], &m.encode()[..]);
    let mut cases: Vec<(Vec<u8>, &str)> = Vec::new();
    let mut flip = good.clone();
    flip[mesh_at + 20] ^= 1;
    cases.push((flip, "receiver mesh"));
    let mut patch = |at: usize, v: &[u8], want: &'static str| {
        let mut b = good.clone();
        b[at..at + v.len()].copy_from_slice(v);
        fix_raw_header(&mut b);
        cases.push((b, want));
    };
    patch(
        116,
        &(m.encoded_len() as u64 + 4096).to_le_bytes(),
        "data_offset",
    );
    patch(116, &u64::MAX.to_le_bytes(), "mesh_len");
    patch(116, &3u64.to_le_bytes(), "mesh_len");
    patch(108, &(mesh_at as u64 + 64).to_le_bytes(), "mesh_offset");
    patch(12, &2u32.to_le_bytes(), "flags");
    patch(12, &14u32.to_le_bytes(), "flags");
    patch(100, &[0, 0, 0, 0, 0, 0, 0, 0], "row layout");
    for (i, (bytes, want)) in cases.into_iter().enumerate() {
        let p = dir.path().join(format!("bad{i}.raw"));
        std::fs::write(&p, &bytes).unwrap();
        let e = RawStore::open(&p).err().unwrap().to_string();
        assert!(e.contains(want), "case {i} ({want}): {e}");
    }
    // A mesh within the file but beyond the budget: refused, not allocated.
    let big = mesh(20_000);
    let p = raw(dir.path(), "big.raw", Some(&big));
    assert_eq!(RawStore::open(&p).unwrap().mesh(), Some(&big));
    let e = RawStore::open_with_limits(&p, &Limits::with_max_alloc(100_000))
        .err()
        .unwrap();
    assert!(
        matches!(&e, Error::Limit { what, .. } if what.contains("receiver mesh")),
        "{e}"
    );
}

/// An image-space file (with SURF) of the same size.
fn image_file(dir: &Path) -> Vec<u8> {
    let d = Dims::image(S, S, 2, 1);
    let h = RawHeader::new(d, false, 1 << 12).with_surface();
    let r = RawWriter::write_dense_with_surface(
        &dir.join("i.raw"),
        h,
        &matrix(d),
        None,
        Some(&surface(d)),
    )
    .unwrap();
    let out = dir.join("i.ltm");
    let store = RawStore::open(&r).unwrap();
    let opts = CompressOptions::default();
    compress(&store, &out, &opts, ltm_codec::Progress::NONE).unwrap();
    std::fs::read(out).unwrap()
}

/// `good` with its MESH chunk (of mesh `m`) broken, every CRC valid, and
/// what the error must say.
fn broken_mesh_chunks(good: &[u8], m: &ReceiverMesh) -> Vec<(Vec<u8>, &'static str)> {
    let v = m.vertex_count();
    let (nrm, uv, tri) = (16 + 12 * v, 16 + 24 * v, 16 + 32 * v);
    let put =
        |at: usize, x: u32| move |c: &mut Vec<u8>| c[at..at + 4].copy_from_slice(&x.to_le_bytes());
    let nan = f32::NAN.to_bits();
    vec![
        (
            with_mesh_chunk(good, |c| c.truncate(10)),
            "shorter than its 16-byte header",
        ),
        (
            with_mesh_chunk(good, |c| c.truncate(c.len() - 4)),
            "needs exactly",
        ),
        (with_mesh_chunk(good, |c| c.push(0)), "needs exactly"),
        (with_mesh_chunk(good, put(0, 1 << 27)), "at most 67108864"),
        (with_mesh_chunk(good, put(4, u32::MAX)), "at most 67108864"),
        (with_mesh_chunk(good, put(0, 1 << 20)), "needs exactly"),
        (with_mesh_chunk(good, put(8, 1)), "reserved"),
        (
            with_mesh_chunk(good, put(tri + 4, v as u32)),
            "valid: below",
        ),
        (with_mesh_chunk(good, put(16 + 8, nan)), "not finite"),
        (
            with_mesh_chunk(good, put(16, f32::INFINITY.to_bits())),
            "not finite",
        ),
        (with_mesh_chunk(good, put(nrm, 2.0f32.to_bits())), "length"),
        (with_mesh_chunk(good, put(nrm + 4, nan)), "length"),
        (with_mesh_chunk(good, put(uv + 4, nan)), "outside [0, 8]"),
        (
            with_mesh_chunk(good, put(uv, 8.5f32.to_bits())),
            "outside [0, 8]",
        ),
        (
            with_mesh_chunk(good, put(uv + 12, (-0.5f32).to_bits())),
            "outside [0, 8]",
        ),
        (
            with_mesh_chunk(good, |c| {
                c[4..8].copy_from_slice(&0u32.to_le_bytes());
                c.truncate(tri);
            }),
            "no triangles",
        ),
    ]
}

/// The invalid-input suite of the MESH chunk: each must be an error, never
/// a panic.
#[test]
fn invalid_mesh_chunks_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let m = mesh(5);
    let good = std::fs::read(compressed(dir.path(), Some(&m), false)).unwrap();
    validate_bytes(&good, &Limits::default()).unwrap();
    let image = image_file(dir.path());
    validate_bytes(&image, &Limits::default()).unwrap();
    let in_image = rebuild(&image, features(&image) | 16, |c| {
        let at = c.iter().position(|c| &c.0 == b"SURF").unwrap() + 1;
        c.insert(at, (*b"MESH", m.encode()));
    });
    let mut version5 = good.clone();
    version5[8..12].copy_from_slice(&5u32.to_le_bytes());
    let disagree = "MESH chunk and receiver-mesh feature flag disagree";
    let mut cases = broken_mesh_chunks(&good, &m);
    cases.extend([
        (
            rebuild(&good, features(&good), |c| c.retain(|c| &c.0 != b"MESH")),
            disagree,
        ),
        (rebuild(&good, features(&good) & !16, |_| {}), disagree),
        (in_image, "image-space"),
        (rebuild(&version5, features(&good), |_| {}), "feature flags"),
        (
            rebuild(&good, features(&good), |c| {
                let at = c.iter().position(|c| &c.0 == b"MESH").unwrap();
                let mesh = c.remove(at);
                c.push(mesh.clone());
                c.push(mesh);
            }),
            "more than once",
        ),
    ]);
    for (i, (bytes, want)) in cases.iter().enumerate() {
        let e = validate_bytes(bytes, &Limits::default())
            .err()
            .unwrap_or_else(|| panic!("case {i} ({want}) was accepted"))
            .to_string();
        assert!(e.contains(want), "case {i} ({want}): {e}");
    }
    // The mesh removed with its flag: a texture file without a mesh.
    let none = rebuild(&good, features(&good) & !16, |c| {
        c.retain(|c| &c.0 != b"MESH")
    });
    let f = LtmFile::from_bytes(none, &Limits::default()).unwrap();
    assert!(f.mesh().is_none());
}

/// Counts too large for the budget: a large mesh in a file opened with a
/// small budget is refused before its arrays are made.
#[test]
fn a_mesh_beyond_the_budget_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let good = std::fs::read(compressed(dir.path(), Some(&mesh(5)), false)).unwrap();
    let big = mesh(20_000);
    let large = with_mesh_chunk(&good, |c| *c = big.encode());
    let f = LtmFile::from_bytes(large.clone(), &Limits::default()).unwrap();
    assert_eq!(f.mesh(), Some(&big));
    validate_bytes(&good, &Limits::with_max_alloc(300_000)).unwrap();
    let e = validate_bytes(&large, &Limits::with_max_alloc(300_000)).unwrap_err();
    assert!(
        matches!(&e, Error::Limit { what, .. } if what.contains("receiver mesh")),
        "{e}"
    );
}

/// The independent reader (tools/validate/ltm_reader.py, written from
/// docs/FORMAT.md) decodes the MESH chunk and the version-4 raw store's
/// mesh to the same values, bit for bit, and the matrix of the `.ltm`
/// file. Runs with the Python that `LTM_PYTHON` names (CI sets it to its
/// venv, which has numpy); without it the test says so and passes.
#[test]
fn the_independent_reader_decodes_the_mesh() {
    let Some(python) = std::env::var_os("LTM_PYTHON") else {
        eprintln!("LTM_PYTHON is not set: the independent reader is not run");
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let m = mesh(9);
    let reader = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tools/validate/ltm_reader.py");
    let ltm = compressed(dir.path(), Some(&m), false);
    let raw = dir.path().join("t.raw");
    let bits = |a: &[[f32; 3]]| -> Vec<u32> { a.iter().flatten().map(|v| v.to_bits()).collect() };
    let want = serde_json_like(
        S,
        &bits(&m.positions),
        &bits(&m.normals),
        &m.uvs
            .iter()
            .flatten()
            .map(|v| v.to_bits())
            .collect::<Vec<_>>(),
        &m.triangles.iter().flatten().copied().collect::<Vec<_>>(),
    );
    for file in [&ltm, &raw] {
        let json = dir.path().join("mesh.json");
        let out = std::process::Command::new(&python)
            .arg(&reader)
            .arg(file)
            .arg("--mesh-json")
            .arg(&json)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}: {}{}",
            file.display(),
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        let got: String = std::fs::read_to_string(&json)
            .unwrap()
            .chars()
            .filter(|c| !c.is_whitespace())
            .collect();
        assert_eq!(got, want, "{}", file.display());
    }
}

/// The JSON `ltm_reader.py --mesh-json` writes (Python's `json.dump`,
/// whitespace removed), built by hand.
fn serde_json_like(size: u32, p: &[u32], n: &[u32], uv: &[u32], t: &[u32]) -> String {
    let rows = |v: &[u32], k: usize| {
        let r: Vec<String> = v
            .chunks(k)
            .map(|c| {
                let c: Vec<String> = c.iter().map(u32::to_string).collect();
                format!("[{}]", c.join(","))
            })
            .collect();
        format!("[{}]", r.join(","))
    };
    format!(
        "{{\"size\":{size},\"positions\":{},\"normals\":{},\"uvs\":{},\"triangles\":{}}}",
        rows(p, 3),
        rows(n, 3),
        rows(uv, 2),
        rows(t, 3)
    )
}
