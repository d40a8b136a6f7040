//! Checksum repair for fuzzing and tests (the `fuzzing` feature).

use crate::column::COLUMN_ENTRY_LEN;

/// Rewrites every checksum an `.ltm` image claims — each column's, each
/// chunk's and the directory's — from the bytes it covers, as far as the
/// (unchecked) directory and column table can be followed. For fuzzing and
/// tests: it lets mutated files reach the structural checks behind the CRCs.
/// The columns' CRCs are rewritten only in a column table stored as is, not
/// in a packed one (version 7): start from [`unpack_chunks`]'s image to
/// have them rewritten. Only with the `fuzzing` feature.
pub fn repair_checksums(b: &mut [u8]) {
    let u32_at = |b: &[u8], at: usize| {
        b.get(at..at + 4)
            .map(|s| u32::from_le_bytes(s.try_into().expect("4 bytes")))
    };
    let u64_at = |b: &[u8], at: usize| {
        b.get(at..at + 8)
            .map(|s| u64::from_le_bytes(s.try_into().expect("8 bytes")))
    };
    let span = |len: usize, offset: u64, size: u64| {
        offset
            .checked_add(size)
            .filter(|&e| e <= len as u64)
            .map(|e| offset as usize..e as usize)
    };
    let Some(count) = u32_at(b, 16).map(|c| (c as usize).min(super::MAX_CHUNKS)) else {
        return;
    };
    let mut chunks = Vec::new();
    for k in 0..count {
        let e = 24 + 32 * k;
        if let (Some(tag), Some(offset), Some(len)) =
            (b.get(e..e + 4), u64_at(b, e + 8), u64_at(b, e + 16))
        {
            chunks.push((tag.to_vec(), offset, len, e + 24));
        }
    }
    let find = |tag: &[u8]| {
        chunks
            .iter()
            .find(|c| c.0 == tag)
            .and_then(|c| span(b.len(), c.1, c.2))
    };
    if let (Some(data), Some(cols)) = (find(b"DATA"), find(b"COLS")) {
        let mut entry = cols.start;
        while entry + COLUMN_ENTRY_LEN <= cols.end {
            if let (Some(off), Some(len)) = (u64_at(b, entry), u32_at(b, entry + 8)) {
                if let Some(r) = span(data.len(), off, len as u64) {
                    let crc = crc32fast::hash(&b[data.start + r.start..data.start + r.end]);
                    b[entry + 20..entry + 24].copy_from_slice(&crc.to_le_bytes());
                }
            }
            entry += COLUMN_ENTRY_LEN;
        }
    }
    for (tag, offset, len, crc_at) in &chunks {
        if let (false, Some(r)) = (tag == b"DATA", span(b.len(), *offset, *len)) {
            let crc = crc32fast::hash(&b[r]);
            if let Some(dst) = b.get_mut(*crc_at..*crc_at + 4) {
                dst.copy_from_slice(&crc.to_le_bytes());
            }
        }
    }
    let dir_end = 24 + 32 * count;
    if b.len() >= dir_end + 4 {
        let crc = crc32fast::hash(&b[..dir_end]);
        b[dir_end..dir_end + 4].copy_from_slice(&crc.to_le_bytes());
    }
}

/// A valid `.ltm` image with every packed chunk (version 7) stored as is,
/// offsets, lengths and checksums rewritten: the same file in the layout
/// that tests and fuzzers can edit byte by byte. Only with the `fuzzing`
/// feature.
pub fn unpack_chunks(b: &[u8]) -> crate::Result<Vec<u8>> {
    use super::directory::DIR_ENTRY_LEN;
    use super::directory::{chunk, encode_head, read_directory, DirEntry, Packing, HEADER_LEN};
    let (_, features, dir) = read_directory(b)?;
    let limits = crate::Limits::default();
    let mut bodies = Vec::with_capacity(dir.len());
    for d in &dir {
        bodies.push(
            chunk(b, &dir, &d.tag, &limits)?
                .map(|c| c.to_vec())
                .unwrap_or_default(),
        );
    }
    let mut offset = (HEADER_LEN + DIR_ENTRY_LEN * dir.len() + 4) as u64;
    let mut out_dir = Vec::with_capacity(dir.len());
    for (d, body) in dir.iter().zip(&bodies) {
        let crc = if &d.tag == b"DATA" {
            0
        } else {
            crc32fast::hash(body)
        };
        out_dir.push(DirEntry {
            offset,
            len: body.len() as u64,
            crc,
            packing: Packing::Stored,
            ..*d
        });
        offset += body.len() as u64;
    }
    let mut out = encode_head(features, &out_dir);
    bodies.iter().for_each(|body| out.extend_from_slice(body));
    Ok(out)
}
