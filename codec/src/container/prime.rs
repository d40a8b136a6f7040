//! The writer's last pass over DATA (format version 9): measure the file's
//! priors from its encoding-5 columns, then code each of them again in
//! encoding 6 where that is smaller ([`crate::entropy::Priors`]). Columns
//! are read back in batches and rewritten in place: a column's new bytes
//! are never longer than its old ones, so its new offset is never past its
//! old one and a write never reaches a column not yet read.

use super::directory::{pack, Packing, DIR_ENTRY_LEN};
use crate::column::{ColumnEntry, Encoding};
use crate::entropy::{encode_primed, ColumnShape, PriorTally, Priors};
use crate::error::{Error, Result};
use crate::fileio::read_at;
use rayon::prelude::*;
use std::fs::File;
use std::os::unix::fs::FileExt;
use std::path::Path;

/// Stored bytes of DATA read back at a time.
pub(super) const BATCH_BYTES: u64 = 16 << 20;
/// Recoded bytes held before the saving has paid for the PRIO chunk; past
/// this the file keeps encoding 5.
const MAX_HELD: usize = 64 << 20;

/// The DATA chunk of a file being written: where it starts in `file` and
/// its columns.
pub(super) struct Data<'a> {
    pub file: &'a File,
    pub path: &'a Path,
    pub start: u64,
    pub entries: &'a mut [ColumnEntry],
    pub shape: ColumnShape,
    /// Stored bytes read back at a time ([`BATCH_BYTES`]; tests use less).
    pub batch_bytes: u64,
}

/// A file whose columns were primed.
pub(super) struct Primed {
    /// The PRIO chunk as stored, and how.
    pub prio: (Vec<u8>, Packing),
    /// The new length of DATA.
    pub data_len: u64,
}

/// Primes the file's encoding-5 columns when the columns recoded in
/// encoding 6 save more than the PRIO chunk and its directory entry cost;
/// `None` (and nothing written) otherwise.
pub(super) fn prime(data: &mut Data<'_>) -> Result<Option<Primed>> {
    if !data.entries.iter().any(|e| e.encoding == Encoding::Compact) {
        return Ok(None);
    }
    let priors = tally(data)?.priors();
    let prio = pack(priors.to_bytes(), b"PRIO");
    let cost = (prio.0.len() + DIR_ENTRY_LEN) as u64;
    Ok(recode(data, &priors, cost)?.map(|data_len| Primed { prio, data_len }))
}

/// The batches of columns read back at a time: index ranges of at most
/// `max` stored bytes (or one column).
fn batches(entries: &[ColumnEntry], max: u64) -> Vec<std::ops::Range<usize>> {
    let mut out = Vec::new();
    let mut start = 0;
    let mut bytes = 0u64;
    for (j, e) in entries.iter().enumerate() {
        if j > start && bytes + e.stored_len as u64 > max {
            out.push(start..j);
            start = j;
            bytes = 0;
        }
        bytes += e.stored_len as u64;
    }
    if start < entries.len() {
        out.push(start..entries.len());
    }
    out
}

/// The stored bytes of columns `r` (contiguous in DATA) and the offset of
/// the first.
fn read_batch(data: &Data<'_>, r: &std::ops::Range<usize>) -> Result<(Vec<u8>, u64)> {
    let first = data.entries[r.start].offset;
    let last = &data.entries[r.end - 1];
    let mut buf = vec![0u8; (last.offset + last.stored_len as u64 - first) as usize];
    read_at(data.file, data.path, &mut buf, data.start + first)?;
    Ok((buf, first))
}

/// Column `e`'s stored bytes within a batch read from `first`.
fn slice<'b>(buf: &'b [u8], first: u64, e: &ColumnEntry) -> &'b [u8] {
    let at = (e.offset - first) as usize;
    &buf[at..at + e.stored_len as usize]
}

/// The final context states of every encoding-5 column, summed.
fn tally(data: &Data<'_>) -> Result<PriorTally> {
    let mut total = PriorTally::default();
    for r in batches(data.entries, data.batch_bytes) {
        let (buf, first) = read_batch(data, &r)?;
        let part = data.entries[r]
            .par_iter()
            .filter(|e| e.encoding == Encoding::Compact)
            .try_fold(PriorTally::default, |mut t, e| {
                let bytes = slice(&buf, first, e);
                t.add_column(bytes, e.nnz as usize, &data.shape, e.depth as u32)
                    .map(|()| t)
            })
            .try_reduce(PriorTally::default, |a, b| Ok(a.merge(b)))?;
        total = total.merge(part);
    }
    Ok(total)
}

/// A batch recoded: its columns' new bytes, one after another, and each
/// column's new entry (offset from the batch's start).
struct Recoded {
    bytes: Vec<u8>,
    entries: Vec<ColumnEntry>,
    saved: u64,
}

/// Recodes batch `r`: each encoding-5 column in encoding 6 where that is
/// smaller.
fn recode_batch(data: &Data<'_>, r: std::ops::Range<usize>, priors: &Priors) -> Result<Recoded> {
    let (buf, first) = read_batch(data, &r)?;
    let shape = data.shape;
    let primed: Vec<Option<Vec<u8>>> = data.entries[r.clone()]
        .par_iter()
        .map(|e| {
            if e.encoding != Encoding::Compact {
                return Ok(None);
            }
            let old = slice(&buf, first, e);
            let col = crate::entropy::decode(
                old,
                e.nnz as usize,
                &shape,
                e.depth as u32,
                crate::entropy::ValueCoding::Compact,
                None,
            )?;
            Ok(encode_primed(&col, &shape, priors).filter(|b| b.len() < old.len()))
        })
        .collect::<Result<_>>()?;
    let mut out = Recoded {
        bytes: Vec::with_capacity(buf.len()),
        entries: Vec::with_capacity(r.len()),
        saved: 0,
    };
    for (e, p) in data.entries[r].iter().zip(primed) {
        let mut e = *e;
        let old = slice(&buf, first, &e);
        e.offset = out.bytes.len() as u64;
        if let Some(p) = p {
            out.saved += (old.len() - p.len()) as u64;
            (e.encoding, e.crc) = (Encoding::Primed, crc32fast::hash(&p));
            (e.stored_len, e.raw_len) = (p.len() as u32, p.len() as u32);
            out.bytes.extend_from_slice(&p);
        } else {
            out.bytes.extend_from_slice(old);
        }
        out.entries.push(e);
    }
    Ok(out)
}

/// Recodes every batch; once the saving exceeds `cost`, writes the held
/// batches and then each batch as it is recoded. The new DATA length, or
/// `None` (nothing written) when the saving never pays for the chunk.
fn recode(data: &mut Data<'_>, priors: &Priors, cost: u64) -> Result<Option<u64>> {
    let (mut held, mut held_bytes) = (Vec::new(), 0usize);
    let (mut saved, mut end) = (0u64, 0u64);
    let mut written = 0;
    for r in batches(data.entries, data.batch_bytes) {
        let batch = recode_batch(data, r.clone(), priors)?;
        saved += batch.saved;
        held_bytes += batch.bytes.len();
        held.push((r, batch));
        if saved <= cost {
            if held_bytes > MAX_HELD {
                return Ok(None);
            }
            continue;
        }
        for (r, b) in held.drain(..) {
            data.file
                .write_all_at(&b.bytes, data.start + end)
                .map_err(|e| Error::io(data.path, e))?;
            for (slot, mut e) in data.entries[r].iter_mut().zip(b.entries) {
                e.offset += end;
                *slot = e;
            }
            end += b.bytes.len() as u64;
            written += 1;
        }
        held_bytes = 0;
    }
    Ok((written > 0 && held.is_empty()).then_some(end))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::column::{read_column, EncodedColumn, SparseColumn};
    use crate::compress::Entropy;
    use std::io::Write;

    const SHAPE: ColumnShape = ColumnShape {
        width: 32,
        height: 24,
        channels: 1,
        bits: 12,
    };

    /// Column `j`: about 80 positions, values of a few bits.
    fn column(j: u64) -> SparseColumn {
        let mut s = j.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s
        };
        let indices: Vec<u32> = (0..768).filter(|_| next() % 10 == 0).collect();
        let values = indices
            .iter()
            .map(|_| (1 + next() % 40) as i32 * if next() % 2 == 0 { 1 } else { -1 })
            .collect();
        SparseColumn {
            depth: 2,
            scale_codes: vec![15_000; 3],
            indices,
            values,
        }
    }

    /// DATA recoded in place, in batches of any size, holds every column
    /// as it was (read back through the new entries and the priors), in
    /// fewer bytes, and the bytes before DATA are untouched.
    #[test]
    fn recoding_in_batches_keeps_every_column() {
        let cols: Vec<SparseColumn> = (0..300).map(column).collect();
        let coded: Vec<EncodedColumn> = cols
            .iter()
            .map(|c| EncodedColumn::coded(c, &SHAPE, Entropy::Range, 3))
            .collect();
        let start = 100u64;
        for batch_bytes in [1, 700, 1 << 20] {
            let mut file = tempfile::tempfile().unwrap();
            file.write_all(&[0xA5; 100]).unwrap();
            let mut entries = Vec::new();
            let mut offset = 0;
            for c in &coded {
                file.write_all(&c.bytes).unwrap();
                entries.push(ColumnEntry { offset, ..c.entry });
                offset += c.bytes.len() as u64;
            }
            let path = Path::new("test DATA");
            let mut data = Data {
                file: &file,
                path,
                start,
                entries: &mut entries,
                shape: SHAPE,
                batch_bytes,
            };
            let primed = prime(&mut data)
                .unwrap()
                .expect("300 alike columns pay for priors");
            assert!(primed.data_len < offset, "{} vs {offset}", primed.data_len);
            let raw = match primed.prio.1 {
                Packing::Zstd { unpacked } => {
                    zstd::bulk::decompress(&primed.prio.0, unpacked as usize).unwrap()
                }
                _ => primed.prio.0.clone(),
            };
            let priors = Priors::from_bytes(&raw).unwrap();
            let mut bytes = vec![0u8; (start + primed.data_len) as usize];
            read_at(&file, path, &mut bytes, 0).unwrap();
            assert!(bytes[..100].iter().all(|&b| b == 0xA5));
            let body = &bytes[100..];
            assert!(entries.iter().any(|e| e.encoding == Encoding::Primed));
            for (j, (e, c)) in entries.iter().zip(&cols).enumerate() {
                let back = read_column(body, &SHAPE, Some(&priors), j, e).unwrap();
                assert_eq!(&back, c, "column {j} in batches of {batch_bytes} bytes");
            }
        }
    }
}
