//! Chunk packing 2 (version 8): a chunk of fixed-size records of
//! little-endian 32-bit words, each word delta-coded against the same word
//! of the record before and written byte plane by byte plane, before zstd.
//! The surface records (`f32` positions and normals of neighbouring rows)
//! and the column table (offsets, lengths, counts) change slowly from one
//! record to the next, so the deltas' high bytes are mostly equal and the
//! planes pack 1.2–1.5× smaller than the plain records. docs/FORMAT.md
//! ("Packed chunks") is the specification.

/// Words per record: 7 (28 bytes), the record of both chunks packed this
/// way (SURF's surface record, COLS's column entry).
pub(super) const RECORD_WORDS: usize = 7;
const RECORD: usize = 4 * RECORD_WORDS;

/// The head's length: the bytes before the first record, `len mod 28`.
fn head_len(len: usize) -> usize {
    len % RECORD
}

/// The planar form of `raw`: its head as is, then for each word `w` of a
/// record and each byte `b` of a word, byte `b` of every record's
/// `word_w − previous record's word_w` (mod 2^32; 0 before the first).
pub(super) fn split(raw: &[u8]) -> Vec<u8> {
    let head = head_len(raw.len());
    let records = &raw[head..];
    let n = records.len() / RECORD;
    let mut out = Vec::with_capacity(raw.len());
    out.extend_from_slice(&raw[..head]);
    let mut deltas = vec![0u32; n];
    for w in 0..RECORD_WORDS {
        let mut prev = 0u32;
        for (r, d) in records.chunks_exact(RECORD).zip(&mut deltas) {
            let word = u32::from_le_bytes(r[4 * w..4 * w + 4].try_into().expect("4 bytes"));
            *d = word.wrapping_sub(prev);
            prev = word;
        }
        for b in 0..4 {
            out.extend(deltas.iter().map(|d| d.to_le_bytes()[b]));
        }
    }
    out
}

/// Undoes [`split`]: the records of `planar`, of the same length.
pub(super) fn join(planar: &[u8]) -> Vec<u8> {
    let head = head_len(planar.len());
    let n = (planar.len() - head) / RECORD;
    let mut out = vec![0u8; planar.len()];
    out[..head].copy_from_slice(&planar[..head]);
    let records = &mut out[head..];
    for w in 0..RECORD_WORDS {
        let plane = |b: usize| &planar[head + (4 * w + b) * n..head + (4 * w + b + 1) * n];
        let (p0, p1, p2, p3) = (plane(0), plane(1), plane(2), plane(3));
        let mut word = 0u32;
        for (r, rec) in records.chunks_exact_mut(RECORD).enumerate() {
            word = word.wrapping_add(u32::from_le_bytes([p0[r], p1[r], p2[r], p3[r]]));
            rec[4 * w..4 * w + 4].copy_from_slice(&word.to_le_bytes());
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn join_undoes_split(raw in prop::collection::vec(any::<u8>(), 0..400)) {
            let planar = split(&raw);
            prop_assert_eq!(planar.len(), raw.len());
            prop_assert_eq!(join(&planar), raw);
        }
    }

    #[test]
    fn planes_hold_the_deltas_byte_by_byte() {
        // A 3-byte head, then two records whose word 0 goes 5 → 0x0100_0004.
        let mut raw = vec![9, 8, 7];
        let mut rec = [0u8; RECORD];
        rec[..4].copy_from_slice(&5u32.to_le_bytes());
        raw.extend_from_slice(&rec);
        rec[..4].copy_from_slice(&0x0100_0004u32.to_le_bytes());
        raw.extend_from_slice(&rec);
        let planar = split(&raw);
        assert_eq!(&planar[..3], &[9, 8, 7]);
        // Word 0's four planes: the deltas 5 and 0x00FF_FFFF.
        assert_eq!(&planar[3..11], &[5, 0xFF, 0, 0xFF, 0, 0xFF, 0, 0]);
        assert!(planar[11..].iter().all(|&b| b == 0));
    }
}
