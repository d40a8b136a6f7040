//! The header and the chunk directory: magic, version, feature flags and
//! the directory's entries, written and checked (known unique tags, in
//! range, sorted, non-overlapping) before any chunk is read.

use crate::bytes::{Reader, Writer};
use crate::error::{Error, Result};
use crate::limits::{Charge, Limits};
use std::borrow::Cow;

/// File magic: `\x89LTM\r\n\x1a\n`.
pub const MAGIC: [u8; 8] = *b"\x89LTM\r\n\x1a\n";
/// Format version this build writes. It reads versions 1 to 6; version 2
/// adds the empty-row mask ([`FEATURE_EMPTY_ROWS`]) and the row layout with
/// per-row surface data ([`FEATURE_SURFACE`]). A version-1 file has neither.
/// Version 3 adds column encoding 3 ([`Encoding::Ranged`](crate::column::Encoding::Ranged)), version 4 column
/// encoding 4 ([`Encoding::Classed`](crate::column::Encoding::Classed)), version 5 the column norms
/// ([`FEATURE_COLUMN_NORMS`]), version 6 the receiver mesh
/// ([`FEATURE_RECEIVER_MESH`]), version 7 zstd-packed side chunks (a
/// directory entry's unpacked length).
pub const VERSION: u32 = 7;
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
/// The feature flags a reader of each version knows, by version − 1.
const KNOWN_FEATURES: [u32; VERSION as usize] = [
    FEATURE_ALBEDO,
    FEATURE_ALBEDO | FEATURE_EMPTY_ROWS | FEATURE_SURFACE,
    FEATURE_ALBEDO | FEATURE_EMPTY_ROWS | FEATURE_SURFACE,
    FEATURE_ALBEDO | FEATURE_EMPTY_ROWS | FEATURE_SURFACE,
    FEATURE_ALBEDO | FEATURE_EMPTY_ROWS | FEATURE_SURFACE | FEATURE_COLUMN_NORMS,
    FEATURE_ALBEDO
        | FEATURE_EMPTY_ROWS
        | FEATURE_SURFACE
        | FEATURE_COLUMN_NORMS
        | FEATURE_RECEIVER_MESH,
    FEATURE_ALBEDO
        | FEATURE_EMPTY_ROWS
        | FEATURE_SURFACE
        | FEATURE_COLUMN_NORMS
        | FEATURE_RECEIVER_MESH,
];
/// The chunks a version-7 file may store zstd-packed: the side data known
/// when the file is started, and the column table (which ltm writes after
/// DATA, once every column is known).
pub(super) const PACKABLE: [&[u8; 4]; 5] = [b"ALBD", b"EMPT", b"SURF", b"MESH", b"COLS"];
/// The most chunks a file of any version holds: 4 required (a `pca`
/// file's) plus one per feature bit.
pub const MAX_CHUNKS: usize = 4 + KNOWN_FEATURES[VERSION as usize - 1].count_ones() as usize;
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
    /// Version 7: the chunk's length once unpacked when it is stored as one
    /// zstd frame (encoding 1), else 0 (stored as is, encoding 0).
    pub unpacked: u32,
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
    let known = KNOWN_FEATURES[version as usize - 1];
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
        let unpacked = if version >= 7 {
            check_packing(&tag, encoding, unpacked)?
        } else {
            0
        };
        dir.push(DirEntry {
            tag,
            offset,
            len,
            crc,
            unpacked,
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

/// A version-7 entry's encoding (0 stored, 1 zstd; only [`PACKABLE`]
/// chunks are packed) and unpacked length (0 when stored, else at least
/// 1): the unpacked length, 0 for a stored chunk.
fn check_packing(tag: &[u8; 4], encoding: u32, unpacked: u32) -> Result<u32> {
    let name = String::from_utf8_lossy(tag);
    match (encoding, unpacked) {
        (0, 0) => Ok(0),
        (1, n) if n > 0 && PACKABLE.contains(&tag) => Ok(n),
        _ => Err(Error::corrupt(
            "chunk directory",
            format!(
                "chunk {name}: encoding {encoding} with unpacked length {unpacked} (valid: 0 with 0, or 1 (zstd) with a length >= 1 for ALBD, EMPT, SURF, MESH or COLS)"
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
                | b"NORM"
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
/// holds.
pub(super) fn chunk<'a>(
    bytes: &'a [u8],
    dir: &[DirEntry],
    tag: &[u8; 4],
    limits: &Limits,
) -> Result<Option<ChunkBytes<'a>>> {
    let Some((s, d)) = stored_chunk(bytes, dir, tag)? else {
        return Ok(None);
    };
    if d.unpacked == 0 {
        return Ok(Some(ChunkBytes {
            bytes: Cow::Borrowed(s),
            _charge: Charge::default(),
        }));
    }
    let name = String::from_utf8_lossy(tag);
    let charge = limits.check_alloc("packed chunk", d.unpacked as u64, 1)?;
    let unpacked = zstd::bulk::decompress(s, d.unpacked as usize).map_err(|e| {
        Error::corrupt(
            "chunk",
            format!("{name}: is not a zstd frame of {} bytes ({e})", d.unpacked),
        )
    })?;
    if unpacked.len() != d.unpacked as usize {
        return Err(Error::corrupt(
            "chunk",
            format!(
                "{name}: unpacks to {} bytes, the directory says {}",
                unpacked.len(),
                d.unpacked
            ),
        ));
    }
    Ok(Some(ChunkBytes {
        bytes: Cow::Owned(unpacked),
        _charge: charge,
    }))
}

/// `raw` as a packable chunk is stored: one zstd frame when that is smaller
/// (version 7), else as is. Returns the stored bytes and the unpacked
/// length (0 when stored as is).
pub(super) fn pack(raw: Vec<u8>) -> (Vec<u8>, u32) {
    let Ok(len) = u32::try_from(raw.len()) else {
        return (raw, 0);
    };
    match zstd::bulk::compress(&raw, PACK_LEVEL) {
        Ok(z) if len > 0 && z.len() < raw.len() => (z, len),
        _ => (raw, 0),
    }
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
        head.u32(u32::from(d.unpacked > 0));
        head.u64(d.offset);
        head.u64(d.len);
        head.u32(d.crc);
        head.u32(d.unpacked);
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
            unpacked: 0,
        }
    }

    /// A file of a META, a SURF chunk holding `stored` with the directory's
    /// unpacked length `unpacked`, and an empty DATA.
    fn packed_file(stored: &[u8], unpacked: u32) -> (Vec<u8>, Vec<DirEntry>) {
        let start = (HEADER_LEN + DIR_ENTRY_LEN * 3 + 4) as u64;
        let surf = DirEntry {
            crc: crc32fast::hash(stored),
            unpacked,
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

    #[test]
    fn packed_chunks_unpack_and_bad_packing_is_an_error() {
        let raw: Vec<u8> = (0..5000u32).flat_map(|i| (i / 100).to_le_bytes()).collect();
        let (stored, unpacked) = pack(raw.clone());
        assert!(unpacked as usize == raw.len() && stored.len() < raw.len() / 4);
        let limits = Limits::default();
        let (file, _) = packed_file(&stored, unpacked);
        let (_, _, dir) = read_directory(&file).unwrap();
        let unpacked_chunk = chunk(&file, &dir, b"SURF", &limits).unwrap().unwrap();
        assert_eq!(*unpacked_chunk, raw[..]);
        // The unpacked copy stays charged while it lives.
        assert_eq!(limits.used_bytes(), raw.len() as u64);
        drop(unpacked_chunk);
        assert_eq!(limits.used_bytes(), 0);
        // The stored bytes of a chunk stored as is come back as they are.
        let (file, _) = packed_file(&raw, 0);
        let (_, _, dir) = read_directory(&file).unwrap();
        assert_eq!(
            *chunk(&file, &dir, b"SURF", &limits).unwrap().unwrap(),
            raw[..]
        );
        // A wrong unpacked length, a frame that unpacks to more than the
        // budget allows, and bytes that are no zstd frame.
        for (bytes, claimed, expect) in [
            (&stored[..], unpacked - 1, "is not a zstd frame of"),
            (&stored[..], unpacked + 1, "unpacks to"),
            (&raw[..], 100, "is not a zstd frame of"),
        ] {
            let (file, _) = packed_file(bytes, claimed);
            let (_, _, dir) = read_directory(&file).unwrap();
            let e = chunk(&file, &dir, b"SURF", &limits)
                .unwrap_err()
                .to_string();
            assert!(e.contains(expect), "{e}");
        }
        let (file, _) = packed_file(&stored, u32::MAX);
        let (_, _, dir) = read_directory(&file).unwrap();
        let small = Limits::with_max_alloc(1 << 20);
        assert!(matches!(
            chunk(&file, &dir, b"SURF", &small),
            Err(Error::Limit { .. })
        ));
        // Packing is known for side chunks only, and as encoding 1 only.
        let (mut file, dir) = packed_file(&stored, unpacked);
        let packed_meta = DirEntry {
            unpacked: 7,
            ..dir[0]
        };
        let head = encode_head(FEATURE_SURFACE, &[packed_meta, dir[1], dir[2]]);
        file[..head.len()].copy_from_slice(&head);
        assert!(read_directory(&file)
            .unwrap_err()
            .to_string()
            .contains("META"));
        let (mut file, _) = packed_file(&stored, unpacked);
        let at = HEADER_LEN + DIR_ENTRY_LEN + 4;
        file[at] = 2;
        let end = HEADER_LEN + DIR_ENTRY_LEN * 3;
        let crc = crc32fast::hash(&file[..end]);
        file[end..end + 4].copy_from_slice(&crc.to_le_bytes());
        assert!(read_directory(&file)
            .unwrap_err()
            .to_string()
            .contains("encoding 2"));
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
