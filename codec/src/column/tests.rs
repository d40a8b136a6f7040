//! Round trips of every encoding through its codec, and the checks of the
//! column table's entries.

use super::{read_column, ColumnEntry, EncodedColumn, Encoding, SparseColumn};
use crate::compress::Entropy;
use crate::entropy::{encode_primed, ColumnShape, PriorTally};

const SHAPE: ColumnShape = ColumnShape {
    width: 16,
    height: 8,
    channels: 3,
    bits: 10,
};

/// A depth-1 column with a few kept positions.
fn column() -> SparseColumn {
    let indices: Vec<u32> = vec![0, 3, 17, 40, 41, 90, 127];
    let values = (0..indices.len() * SHAPE.channels)
        .map(|i| (i as i32 * 37 % 401) - 200)
        .collect();
    SparseColumn {
        depth: 1,
        scale_codes: (0..2 * SHAPE.channels as u16).map(|g| 300 + g).collect(),
        indices,
        values,
    }
}

/// The entry of `bytes` stored in `encoding` (offset 0).
fn entry(col: &SparseColumn, encoding: Encoding, bytes: &[u8], raw_len: u32) -> ColumnEntry {
    ColumnEntry {
        offset: 0,
        stored_len: bytes.len() as u32,
        raw_len,
        nnz: col.indices.len() as u32,
        crc: crc32fast::hash(bytes),
        depth: col.depth as u8,
        encoding,
    }
}

#[test]
fn every_encoding_round_trips() {
    let col = column();
    for &encoding in Encoding::ALL {
        let codec = encoding.codec();
        let source = if encoding == Encoding::Empty {
            SparseColumn {
                depth: 1,
                ..Default::default()
            }
        } else {
            col.clone()
        };
        // zstd stores only what it shrinks: a repetitive column.
        let source = if encoding == Encoding::Zstd {
            SparseColumn {
                indices: (0..100).collect(),
                values: vec![5; 300],
                ..source
            }
        } else {
            source
        };
        // Encoding 6 needs a file's priors: the writer codes it.
        let priors = PriorTally::default().priors();
        let coded = match encoding {
            Encoding::Primed => {
                assert!(codec.encode(&source, &SHAPE, 3).is_none());
                encode_primed(&source, &SHAPE, &priors).map(|b| (b.len() as u32, b))
            }
            _ => codec.encode(&source, &SHAPE, 3).map(|(b, n)| (n, b)),
        };
        let (raw_len, bytes) = coded.unwrap_or_else(|| panic!("{encoding:?} stores the column"));
        let e = entry(&source, encoding, &bytes, raw_len);
        codec.check_entry(&e, &SHAPE).unwrap();
        let back = read_column(&bytes, &SHAPE, Some(&priors), 0, &e).unwrap();
        if encoding == Encoding::Empty {
            assert_eq!((back.depth, back.indices.len()), (1, 0));
        } else {
            assert_eq!(back, source, "{encoding:?}");
        }
    }
}

#[test]
fn a_damaged_payload_fails_its_crc() {
    let col = column();
    let coded = EncodedColumn::coded(&col, &SHAPE, Entropy::Range, 3);
    assert_eq!(coded.entry.encoding, Encoding::Compact);
    let mut bytes = coded.bytes.clone();
    bytes[0] ^= 1;
    let err = read_column(&bytes, &SHAPE, None, 7, &coded.entry).unwrap_err();
    assert!(err.to_string().contains("column 7"), "{err}");
}

#[test]
fn the_writer_chooses_by_size() {
    let col = column();
    let range = EncodedColumn::coded(&col, &SHAPE, Entropy::Range, 3);
    let plain = EncodedColumn::coded(&col, &SHAPE, Entropy::Zstd, 3);
    assert_eq!(range.entry.encoding, Encoding::Compact);
    assert!(matches!(
        plain.entry.encoding,
        Encoding::Plain | Encoding::Zstd
    ));
    assert!(range.bytes.len() <= col.to_payload(SHAPE.channels).len());
    let empty = EncodedColumn::coded(&SparseColumn::default(), &SHAPE, Entropy::Range, 3);
    assert_eq!(
        (
            empty.entry.encoding,
            empty.entry.stored_len,
            empty.entry.crc
        ),
        (Encoding::Empty, 0, 0)
    );
}

#[test]
fn codes_by_version() {
    assert_eq!(Encoding::from_code(4, 5), Ok(Encoding::Classed));
    assert_eq!(Encoding::from_code(3, 3), Ok(Encoding::Ranged));
    assert_eq!(
        Encoding::from_code(3, 2).unwrap_err(),
        "encoding 3 in a file of version 2 (valid: 0 empty, 1 plain, 2 zstd)"
    );
    assert_eq!(
        Encoding::from_code(4, 3).unwrap_err(),
        "encoding 4 in a file of version 3 (valid: 0 empty, 1 plain, 2 zstd, 3 range-coded)"
    );
    assert_eq!(
        Encoding::from_code(9, 5).unwrap_err(),
        "encoding 9 in a file of version 5 (valid: 0 empty, 1 plain, 2 zstd, 3 range-coded, 4 classed)"
    );
    assert_eq!(Encoding::from_code(5, 8), Ok(Encoding::Compact));
    assert_eq!(
        Encoding::from_code(5, 7).unwrap_err(),
        "encoding 5 in a file of version 7 (valid: 0 empty, 1 plain, 2 zstd, 3 range-coded, 4 classed)"
    );
    for (k, &e) in Encoding::ALL.iter().enumerate() {
        assert_eq!(e as usize, k);
    }
}

#[test]
fn entry_lengths_are_checked() {
    let col = column();
    let (bytes, raw_len) = Encoding::Plain.codec().encode(&col, &SHAPE, 3).unwrap();
    let mut e = entry(&col, Encoding::Plain, &bytes, raw_len);
    e.stored_len += 1;
    let problem = Encoding::Plain.codec().check_entry(&e, &SHAPE).unwrap_err();
    assert!(problem.starts_with("stored length"), "{problem}");
    let mut e = entry(&col, Encoding::Classed, &bytes, raw_len);
    e.nnz = 0;
    let problem = Encoding::Classed
        .codec()
        .check_entry(&e, &SHAPE)
        .unwrap_err();
    assert!(problem.contains("valid: k ≥ 1"), "{problem}");
    let mut e = entry(&col, Encoding::Empty, &[], 0);
    assert!(Encoding::Empty.codec().check_entry(&e, &SHAPE).is_err());
    e.nnz = 0;
    Encoding::Empty.codec().check_entry(&e, &SHAPE).unwrap();
}
