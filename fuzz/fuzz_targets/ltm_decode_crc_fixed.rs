//! Like `ltm_decode`, but first rewrites every CRC the input claims (the
//! directory's, each chunk's and each column's) so that mutations get past
//! the checksums and exercise the structural checks behind them.
#![no_main]

use libfuzzer_sys::fuzz_target;

fn u32_at(b: &[u8], at: usize) -> Option<u32> {
    Some(u32::from_le_bytes(b.get(at..at + 4)?.try_into().ok()?))
}

fn u64_at(b: &[u8], at: usize) -> Option<u64> {
    Some(u64::from_le_bytes(b.get(at..at + 8)?.try_into().ok()?))
}

fn put_u32(b: &mut [u8], at: usize, v: u32) {
    if let Some(s) = b.get_mut(at..at + 4) {
        s.copy_from_slice(&v.to_le_bytes());
    }
}

fn range(b: &[u8], offset: u64, len: u64) -> Option<std::ops::Range<usize>> {
    let end = offset.checked_add(len)?;
    (end <= b.len() as u64).then_some(offset as usize..end as usize)
}

/// Rewrites the CRCs of an `.ltm` image in place (layout in docs/FORMAT.md).
fn fix_crcs(b: &mut [u8]) -> Option<()> {
    let count = (u32_at(b, 16)? as usize).min(8);
    let mut chunks = Vec::new();
    for k in 0..count {
        let e = 24 + 32 * k;
        chunks.push((b.get(e..e + 4)?.to_vec(), u64_at(b, e + 8)?, u64_at(b, e + 16)?, e + 24));
    }
    // Column CRCs first (they live in COLS), then chunk CRCs, then the directory's.
    let data = chunks.iter().find(|c| c.0 == b"DATA").and_then(|c| range(b, c.1, c.2));
    let cols = chunks.iter().find(|c| c.0 == b"COLS").and_then(|c| range(b, c.1, c.2));
    if let (Some(data), Some(cols)) = (data, cols) {
        for entry in cols.clone().step_by(28) {
            if entry + 28 > cols.end {
                break;
            }
            let (off, len) = (u64_at(b, entry)?, u32_at(b, entry + 8)? as u64);
            if let Some(r) = range(&b[data.clone()], off, len) {
                let crc = crc32fast::hash(&b[data.start + r.start..data.start + r.end]);
                put_u32(b, entry + 20, crc);
            }
        }
    }
    for (tag, offset, len, crc_at) in &chunks {
        if tag != b"DATA" {
            if let Some(r) = range(b, *offset, *len) {
                let crc = crc32fast::hash(&b[r]);
                put_u32(b, *crc_at, crc);
            }
        }
    }
    let dir_end = 24 + 32 * count;
    let crc = crc32fast::hash(b.get(..dir_end)?);
    put_u32(b, dir_end, crc);
    Some(())
}

fuzz_target!(|data: &[u8]| {
    let mut bytes = data.to_vec();
    let _ = fix_crcs(&mut bytes);
    let _ = ltm_codec::container::validate_bytes(&bytes);
});
