//! The header and the chunk directory: magic, version, feature flags and
//! the directory's entries, written and checked (known unique tags, in
//! range, sorted, non-overlapping) before any chunk is read.

use crate::bytes::{Reader, Writer};
use crate::error::{Error, Result};
use crate::limits::{Charge, Limits};
use std::borrow::Cow;

/// File magic: `\x89LTM\r\n\x1a\n`.
pub const MAGIC: [u8; 8] = *b"\x89LTM\r\n\x1a\n";
/// Format version this build writes. It reads versions 1 to 8; version 2
/// adds the empty-row mask ([`FEATURE_EMPTY_ROWS`]) and the row layout with
/// per-row surface data ([`FEATURE_SURFACE`]). A version-1 file has neither.
/// Version 3 adds column encoding 3 ([`Encoding::Ranged`](crate::column::Encoding::Ranged)), version 4 column
/// encoding 4 ([`Encoding::Classed`](crate::column::Encoding::Classed)), version 5 the column norms
/// ([`FEATURE_COLUMN_NORMS`]), version 6 the receiver mesh
/// ([`FEATURE_RECEIVER_MESH`]), version 7 zstd-packed side chunks (a
/// directory entry's unpacked length), version 8 the planar packing of
/// SURF and COLS (chunk packing 2) and column encoding 5
/// ([`Encoding::Compact`](crate::column::Encoding::Compact)), version 9
/// the per-file priors ([`FEATURE_PRIORS`]) and column encoding 6
/// ([`Encoding::Primed`](crate::column::Encoding::Primed)), version 10 the
/// near-field rows ([`FEATURE_NEAR_FIELD`]).
pub const VERSION: u32 = 10;
/// The oldest format version this build reads.
pub const MIN_VERSION: u32 = 1;
/// Feature flag: an RGB albedo image is stored (chunk ALBD).
pub const FEATURE_ALBEDO: u32 = 1;
/// Feature flag (version 2): the mask of all-zero rows is stored (chunk
/// EMPT); decoders output exactly 0 in those rows.
pub const FEATURE_EMPTY_ROWS: u32 = 2;
/// Feature flag (version 2): the row layout and per-row surface data are
/// stored (chunk SURF).
pub const FEATURE_SURFACE: u32 = 4;
/// Feature flag (version 5): every column's priority norm is stored (chunk
/// NORM; wavelet modes only), [`ColumnDecoder::weighted_norm`] of the
/// decoded column.
///
/// [`ColumnDecoder::weighted_norm`]: crate::ColumnDecoder::weighted_norm
pub const FEATURE_COLUMN_NORMS: u32 = 8;
/// Feature flag (version 6): the receiving mesh of a texture-space file is
/// stored (chunk MESH, [`ReceiverMesh`](crate::ReceiverMesh)); only with
/// [`FEATURE_SURFACE`] and texture rows.
pub const FEATURE_RECEIVER_MESH: u32 = 16;
/// Feature flag (version 9): the starting states of column encoding 6's
/// contexts are stored (chunk PRIO, [`Priors`](crate::entropy::Priors));
/// wavelet modes only.
pub const FEATURE_PRIORS: u32 = 32;
/// Feature flag (version 10): every row's transport over a light plane's
/// face is stored (chunk NEAR, [`PlaneRows`](crate::PlaneRows)); wavelet
/// modes only, with [`FEATURE_SURFACE`].
pub const FEATURE_NEAR_FIELD: u32 = 64;
/// Each feature flag and the first version that knows it.
const FEATURE_SINCE: [(u32, u32); 7] = [
    (FEATURE_ALBEDO, 1),
    (FEATURE_EMPTY_ROWS, 2),
    (FEATURE_SURFACE, 2),
    (FEATURE_COLUMN_NORMS, 5),
    (FEATURE_RECEIVER_MESH, 6),
    (FEATURE_PRIORS, 9),
    (FEATURE_NEAR_FIELD, 10),
];

/// The feature flags a reader of `version` knows.
const fn known_features(version: u32) -> u32 {
    let mut known = 0;
    let mut k = 0;
    while k < FEATURE_SINCE.len() {
        if FEATURE_SINCE[k].1 <= version {
            known |= FEATURE_SINCE[k].0;
        }
        k += 1;
    }
    known
}
/// The chunks a file of version 7 or later may store zstd-packed: the side data known
/// when the file is started, the column table and the priors (which ltm
/// writes after DATA, once every column is known).
pub(super) const PACKABLE: [&[u8; 4]; 7] = [
    b"ALBD", b"EMPT", b"SURF", b"MESH", b"NEAR", b"COLS", b"PRIO",
];
/// The chunks a version-8 file may store in planes ([`Packing::Planes`]):
/// those made of 28-byte records.
pub(super) const PLANAR: [&[u8; 4]; 2] = [b"SURF", b"COLS"];

/// How a chunk's bytes are stored (the directory entry's encoding, version
/// 7 and later).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(super) enum Packing {
    /// As they are (encoding 0).
    #[default]
    Stored,
    /// One zstd frame of the `unpacked` bytes (encoding 1, version 7).
    Zstd { unpacked: u32 },
    /// One zstd frame of the planar form of the `unpacked` bytes (encoding
    /// 2, version 8; [`planes`](super::planes)).
    Planes { unpacked: u32 },
}

impl Packing {
    /// The directory's encoding code and unpacked length.
    fn fields(self) -> (u32, u32) {
        match self {
            Packing::Stored => (0, 0),
            Packing::Zstd { unpacked } => (1, unpacked),
            Packing::Planes { unpacked } => (2, unpacked),
        }
    }
}
/// The most chunks a file of any version holds: 4 required (a `pca`
/// file's) plus one per feature bit.
pub const MAX_CHUNKS: usize = 4 + known_features(VERSION).count_ones() as usize;
pub(super) const HEADER_LEN: usize = 24;
pub(super) const DIR_ENTRY_LEN: usize = 32;

#[derive(Clone, Copy, Debug)]
pub(super) struct DirEntry {
    pub tag: [u8; 4],
    pub offset: u64,
    /// Stored bytes.
    pub len: u64,
    /// CRC-32 of the stored bytes.
    pub crc: u32,
    /// How the chunk is stored (as is in versions 1 to 6).
    pub packing: Packing,
}

/// Reads and checks the header and the chunk directory: magic, version,
/// known feature flags, the directory CRC, and chunks with known unique
/// tags, in range, sorted and non-overlapping. Returns the feature flags
/// and the directory.
pub(super) fn read_directory(bytes: &[u8]) -> Result<(u32, u32, Vec<DirEntry>)> {
    let mut r = Reader::new(bytes, ".ltm header");
    if r.take(8)? != MAGIC {
        return Err(Error::corrupt(".ltm header", "bad magic bytes"));
    }
    let version = r.u32()?;
    if !(MIN_VERSION..=VERSION).contains(&version) {
        return Err(Error::Version {
            what: ".ltm",
            found: version,
            supported: VERSION,
        });
    }
    let features = r.u32()?;
    let known = known_features(version);
    if features & !known != 0 {
        return Err(Error::range(
            "feature flags",
            format!("{features:#x}"),
            format!("a subset of {known:#x} in version {version}"),
        ));
    }
    let count = r.u32()? as usize;
    // Required chunks: 3 (META, COLS, DATA), 4 in a version-2 pca file
    // (META, PCAM, PCAB, PCAC); plus one per feature bit.
    let most = 3 + usize::from(version >= 2) + known.count_ones() as usize;
    if !(3..=most).contains(&count) {
        return Err(Error::range("chunk count", count, format!("3..={most}")));
    }
    r.u32()?;
    let mut dir = Vec::with_capacity(count);
    for _ in 0..count {
        let tag: [u8; 4] = r.take(4)?.try_into().expect("4 bytes");
        let encoding = r.u32()?;
        let (offset, len, crc) = (r.u64()?, r.u64()?, r.u32()?);
        let unpacked = r.u32()?;
        let packing = if version >= 7 {
            check_packing(&tag, encoding, unpacked, version)?
        } else {
            Packing::Stored
        };
        dir.push(DirEntry {
            tag,
            offset,
            len,
            crc,
            packing,
        });
    }
    let dir_end = r.pos();
    let stored = r.u32()?;
    let computed = crc32fast::hash(&bytes[..dir_end]);
    if stored != computed {
        return Err(Error::Crc {
            chunk: "chunk directory".into(),
            stored,
            computed,
        });
    }
    check_directory(&dir, r.pos() as u64, bytes.len())?;
    Ok((version, features, dir))
}

/// A version-7 or later entry's encoding (0 stored, 1 zstd, 2 planes from
/// version 8; only [`PACKABLE`] chunks are packed, only [`PLANAR`] ones
/// in planes) and unpacked length (0 when stored, else at least 1).
fn check_packing(tag: &[u8; 4], encoding: u32, unpacked: u32, version: u32) -> Result<Packing> {
    let name = String::from_utf8_lossy(tag);
    match (encoding, unpacked) {
        (0, 0) => Ok(Packing::Stored),
        (1, n) if n > 0 && PACKABLE.contains(&tag) => Ok(Packing::Zstd { unpacked: n }),
        (2, n) if n > 0 && version >= 8 && PLANAR.contains(&tag) => {
            Ok(Packing::Planes { unpacked: n })
        }
        _ => Err(Error::corrupt(
            "chunk directory",
            format!(
                "chunk {name}: encoding {encoding} with unpacked length {unpacked} in a version-{version} file (valid: 0 with 0; 1 (zstd) with a length >= 1 for ALBD, EMPT, SURF, MESH, NEAR, COLS or PRIO; from version 8, 2 (planes) with a length >= 1 for SURF or COLS)"
            ),
        )),
    }
}

/// Directory entries: known unique tags, in range, sorted, non-overlapping,
/// starting at or after `start` in a file of `file_len` bytes.
fn check_directory(dir: &[DirEntry], start: u64, file_len: usize) -> Result<()> {
    let mut end = start;
    for d in dir {
        let tag = String::from_utf8_lossy(&d.tag);
        if !matches!(
            &d.tag,
            b"META"
                | b"ALBD"
                | b"EMPT"
                | b"SURF"
                | b"MESH"
                | b"NEAR"
                | b"NORM"
                | b"PRIO"
                | b"COLS"
                | b"DATA"
                | b"PCAM"
                | b"PCAB"
                | b"PCAC"
        ) {
            return Err(Error::corrupt(
                "chunk directory",
                format!("unknown chunk tag {tag:?}"),
            ));
        }
        if dir.iter().filter(|o| o.tag == d.tag).count() != 1 {
            return Err(Error::corrupt(
                "chunk directory",
                format!("chunk {tag} appears more than once"),
            ));
        }
        let stop = d
            .offset
            .checked_add(d.len)
            .filter(|&s| s <= file_len as u64);
        match stop {
            Some(stop) if d.offset >= end => end = stop,
            _ => {
                return Err(Error::corrupt("chunk directory", format!(
                    "chunk {tag} at {}+{} is out of order, overlapping or past the end of the {file_len}-byte file",
                    d.offset, d.len)))
            }
        }
    }
    Ok(())
}

/// The stored bytes of chunk `tag`, CRC-checked (DATA has per-column CRCs
/// instead), and its directory entry, or `None` when the directory has no
/// such chunk. The directory has been checked against the file's length.
/// Only [`PACKABLE`] chunks can be packed; read them with [`chunk`].
pub(super) fn stored_chunk<'a>(
    bytes: &'a [u8],
    dir: &[DirEntry],
    tag: &[u8; 4],
) -> Result<Option<(&'a [u8], DirEntry)>> {
    let Some(d) = dir.iter().find(|d| &d.tag == tag) else {
        return Ok(None);
    };
    let s = &bytes[d.offset as usize..(d.offset + d.len) as usize];
    if tag != b"DATA" {
        let computed = crc32fast::hash(s);
        if computed != d.crc {
            return Err(Error::Crc {
                chunk: String::from_utf8_lossy(tag).into_owned(),
                stored: d.crc,
                computed,
            });
        }
    }
    Ok(Some((s, *d)))
}

/// A chunk's bytes as [`chunk`] reads them: the stored bytes, or the
/// unpacked copy with its charge to the limits, held as long as the copy.
#[derive(Debug)]
pub(super) struct ChunkBytes<'a> {
    bytes: Cow<'a, [u8]>,
    /// The unpacked copy's bytes, charged (empty for stored bytes).
    _charge: Charge,
}

impl std::ops::Deref for ChunkBytes<'_> {
    type Target = [u8];
    fn deref(&self) -> &[u8] {
        &self.bytes
    }
}

/// The bytes of chunk `tag` as [`stored_chunk`] reads them, unpacked when
/// packed: the unpacked length is charged to `limits` first (and stays
/// charged while the copy lives), and must be exactly what the zstd frame
/// holds. A chunk in planes charges a second copy while it is joined.
pub(super) fn chunk<'a>(
    bytes: &'a [u8],
    dir: &[DirEntry],
    tag: &[u8; 4],
    limits: &Limits,
) -> Result<Option<ChunkBytes<'a>>> {
    let Some((s, d)) = stored_chunk(bytes, dir, tag)? else {
        return Ok(None);
    };
    let (unpacked, planar) = match d.packing {
        Packing::Stored => {
            return Ok(Some(ChunkBytes {
                bytes: Cow::Borrowed(s),
                _charge: Charge::default(),
            }))
        }
        Packing::Zstd { unpacked } => (unpacked as usize, false),
        Packing::Planes { unpacked } => (unpacked as usize, true),
    };
    let name = String::from_utf8_lossy(tag);
    let charge = limits.check_alloc("packed chunk", unpacked as u64, 1)?;
    let frame = zstd::bulk::decompress(s, unpacked).map_err(|e| {
        Error::corrupt(
            "chunk",
            format!("{name}: is not a zstd frame of {unpacked} bytes ({e})"),
        )
    })?;
    if frame.len() != unpacked {
        return Err(Error::corrupt(
            "chunk",
            format!(
                "{name}: unpacks to {} bytes, the directory says {unpacked}",
                frame.len()
            ),
        ));
    }
    let bytes = if planar {
        let _joining = limits.check_alloc("chunk in planes", unpacked as u64, 1)?;
        super::planes::join(&frame)
    } else {
        frame
    };
    Ok(Some(ChunkBytes {
        bytes: Cow::Owned(bytes),
        _charge: charge,
    }))
}

/// `raw` as packable chunk `tag` is stored: the smallest of the bytes as
/// they are, one zstd frame of them (version 7) and, for a [`PLANAR`]
/// chunk, one zstd frame of their planes (version 8).
pub(super) fn pack(raw: Vec<u8>, tag: &[u8; 4]) -> (Vec<u8>, Packing) {
    let unpacked = match u32::try_from(raw.len()) {
        Ok(n) if n > 0 => n,
        _ => return (raw, Packing::Stored),
    };
    let mut best: Option<(Vec<u8>, Packing)> = None;
    let mut consider = |bytes: &[u8], packing: Packing| {
        let smallest = best.as_ref().map_or(raw.len(), |b| b.0.len());
        match zstd::bulk::compress(bytes, PACK_LEVEL) {
            Ok(z) if z.len() < smallest => best = Some((z, packing)),
            _ => {}
        }
    };
    consider(&raw, Packing::Zstd { unpacked });
    if PLANAR.contains(&tag) {
        consider(&super::planes::split(&raw), Packing::Planes { unpacked });
    }
    best.unwrap_or((raw, Packing::Stored))
}

/// zstd level of packed side chunks.
const PACK_LEVEL: i32 = 9;

/// The header and chunk directory with its CRC.
pub(super) fn encode_head(features: u32, dir: &[DirEntry]) -> Vec<u8> {
    let mut head = Writer::default();
    head.bytes.extend_from_slice(&MAGIC);
    head.u32(VERSION);
    head.u32(features);
    head.u32(dir.len() as u32);
    head.u32(0);
    for d in dir {
        head.bytes.extend_from_slice(&d.tag);
        let (encoding, unpacked) = d.packing.fields();
        head.u32(encoding);
        head.u64(d.offset);
        head.u64(d.len);
        head.u32(d.crc);
        head.u32(unpacked);
    }
    let crc = crc32fast::hash(&head.bytes);
    head.u32(crc);
    head.bytes
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entry(tag: &[u8; 4], offset: u64, len: u64) -> DirEntry {
        DirEntry {
            tag: *tag,
            offset,
            len,
            crc: 0,
            packing: Packing::Stored,
        }
    }

    /// A file of a META, a SURF chunk holding `stored` packed as
    /// `packing`, and an empty DATA.
    fn packed_file(stored: &[u8], packing: Packing) -> (Vec<u8>, Vec<DirEntry>) {
        let start = (HEADER_LEN + DIR_ENTRY_LEN * 3 + 4) as u64;
        let surf = DirEntry {
            crc: crc32fast::hash(stored),
            packing,
            ..entry(b"SURF", start + 64, stored.len() as u64)
        };
        let meta = DirEntry {
            crc: crc32fast::hash(&[0; 64]),
            ..entry(b"META", start, 64)
        };
        let data = entry(b"DATA", surf.offset + surf.len, 0);
        let dir = vec![meta, surf, data];
        let mut file = encode_head(FEATURE_SURFACE, &dir);
        file.extend_from_slice(&[0; 64]);
        file.extend_from_slice(stored);
        (file, dir)
    }

    /// 16 head bytes and 300 surface-like records: slowly moving words.
    fn records() -> Vec<u8> {
        let mut raw = vec![3u8; 16];
        for i in 0..300u32 {
            for w in 0..7u32 {
                let v = 0x3F00_0000u32 + i * 37 + w * 1000 + (i * w) % 5;
                raw.extend_from_slice(&v.to_le_bytes());
            }
        }
        raw
    }

    #[test]
    fn packed_chunks_unpack_and_bad_packing_is_an_error() {
        let raw = records();
        let (stored, packing) = pack(raw.clone(), b"SURF");
        // Planes pack these records smaller than plain zstd does.
        let unpacked = match packing {
            Packing::Planes { unpacked } => unpacked,
            other => panic!("{other:?}"),
        };
        let (zstd_only, _) = pack(raw.clone(), b"ALBD");
        assert!(unpacked as usize == raw.len() && stored.len() < zstd_only.len());
        let limits = Limits::default();
        for (bytes, packing) in [
            (&stored, packing),
            (&zstd_only, Packing::Zstd { unpacked }),
            (&raw, Packing::Stored),
        ] {
            let (file, _) = packed_file(bytes, packing);
            let (_, _, dir) = read_directory(&file).unwrap();
            let unpacked_chunk = chunk(&file, &dir, b"SURF", &limits).unwrap().unwrap();
            assert_eq!(*unpacked_chunk, raw[..]);
            // The unpacked copy stays charged while it lives.
            let held = if packing == Packing::Stored {
                0
            } else {
                raw.len()
            };
            assert_eq!(limits.used_bytes(), held as u64);
            drop(unpacked_chunk);
            assert_eq!(limits.used_bytes(), 0);
        }
        // A wrong unpacked length, a frame that unpacks to more than the
        // budget allows, and bytes that are no zstd frame.
        for (bytes, claimed, expect) in [
            (&stored[..], unpacked - 1, "is not a zstd frame of"),
            (&stored[..], unpacked + 1, "unpacks to"),
            (&raw[..], 100, "is not a zstd frame of"),
        ] {
            let (file, _) = packed_file(bytes, Packing::Planes { unpacked: claimed });
            let (_, _, dir) = read_directory(&file).unwrap();
            let e = chunk(&file, &dir, b"SURF", &limits)
                .unwrap_err()
                .to_string();
            assert!(e.contains(expect), "{e}");
        }
        let (file, _) = packed_file(&stored, Packing::Zstd { unpacked: u32::MAX });
        let (_, _, dir) = read_directory(&file).unwrap();
        let small = Limits::with_max_alloc(1 << 20);
        assert!(matches!(
            chunk(&file, &dir, b"SURF", &small),
            Err(Error::Limit { .. })
        ));
        // Packing is known for side chunks only, planes for SURF and COLS
        // only, and no other encoding.
        for (which, packing) in [
            (0, Packing::Zstd { unpacked: 7 }),
            (0, Packing::Planes { unpacked: 7 }),
        ] {
            let (mut file, mut dir) = packed_file(&stored, packing);
            dir[which].packing = packing;
            let head = encode_head(FEATURE_SURFACE, &dir);
            file[..head.len()].copy_from_slice(&head);
            let e = read_directory(&file).unwrap_err().to_string();
            assert!(e.contains("valid: 0 with 0"), "{e}");
        }
        let (mut file, _) = packed_file(&stored, packing);
        file[HEADER_LEN + DIR_ENTRY_LEN + 4] = 3;
        let crc = crc32fast::hash(&file[..HEADER_LEN + 3 * DIR_ENTRY_LEN]);
        file[HEADER_LEN + 3 * DIR_ENTRY_LEN..][..4].copy_from_slice(&crc.to_le_bytes());
        let e = read_directory(&file).unwrap_err().to_string();
        assert!(e.contains("encoding 3"), "{e}");
        // Planes are new in version 8: a version-7 file may not hold them.
        let (mut file, _) = packed_file(&stored, packing);
        file[8..12].copy_from_slice(&7u32.to_le_bytes());
        let crc = crc32fast::hash(&file[..HEADER_LEN + 3 * DIR_ENTRY_LEN]);
        file[HEADER_LEN + 3 * DIR_ENTRY_LEN..][..4].copy_from_slice(&crc.to_le_bytes());
        let e = read_directory(&file).unwrap_err().to_string();
        assert!(
            e.contains("encoding 2 with") && e.contains("version-7"),
            "{e}"
        );
    }

    #[test]
    fn a_written_directory_reads_back() {
        let dir = [
            entry(b"META", 124, 64),
            entry(b"COLS", 188, 28),
            entry(b"DATA", 216, 0),
        ];
        let mut file = encode_head(0, &dir);
        assert_eq!(file.len(), HEADER_LEN + DIR_ENTRY_LEN * dir.len() + 4);
        file.resize(216, 0);
        let (version, features, back) = read_directory(&file).unwrap();
        assert_eq!((version, features), (VERSION, 0));
        assert_eq!(
            back.iter()
                .map(|d| (d.tag, d.offset, d.len))
                .collect::<Vec<_>>(),
            dir.iter()
                .map(|d| (d.tag, d.offset, d.len))
                .collect::<Vec<_>>()
        );
        file[HEADER_LEN + 9] ^= 1;
        assert!(matches!(read_directory(&file), Err(Error::Crc { .. })));
    }

    #[test]
    fn directory_entries_are_checked() {
        let ok = [entry(b"META", 100, 64), entry(b"COLS", 164, 8)];
        check_directory(&ok, 100, 172).unwrap();
        let cases: [(&[DirEntry], &str); 4] = [
            (&[entry(b"XXXX", 100, 1)], "unknown chunk tag"),
            (
                &[entry(b"META", 100, 1), entry(b"META", 101, 1)],
                "more than once",
            ),
            (
                &[entry(b"COLS", 120, 8), entry(b"META", 100, 64)],
                "out of order",
            ),
            (&[entry(b"META", 100, 100)], "past the end"),
        ];
        for (dir, says) in cases {
            let err = check_directory(dir, 100, 172).unwrap_err().to_string();
            assert!(err.contains(says), "{err}");
        }
        assert!(check_directory(&ok, 101, 172).is_err());
    }
}
