//! A column's entry in the column table, and a column ready to append
//! with the writer's choice of encoding.

use super::{Encoding, SparseColumn};
use crate::compress::Entropy;
use crate::entropy::ColumnShape;

/// One column's entry in the column table.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ColumnEntry {
    /// Offset of the payload from the start of the DATA chunk.
    pub offset: u64,
    /// Stored payload bytes.
    pub stored_len: u32,
    /// Payload bytes after decompression.
    pub raw_len: u32,
    /// Nonzero coefficients.
    pub nnz: u32,
    /// CRC-32 of the stored payload.
    pub crc: u32,
    /// Column transform depth.
    pub depth: u8,
    /// How the payload is stored.
    pub encoding: Encoding,
}

/// Bytes of one column-table entry.
pub const COLUMN_ENTRY_LEN: usize = 28;

/// A column ready to append: its stored bytes and table entry (offset not
/// yet set). Encoding is independent per column, so it runs in parallel.
pub struct EncodedColumn {
    /// The payload as stored (plain or zstd).
    pub bytes: Vec<u8>,
    /// Its column-table entry.
    pub entry: ColumnEntry,
    /// The column's priority norm ([`ColumnDecoder::weighted_norm`] of the
    /// column as decoded), for a writer that stores them
    /// ([`OptionalChunks::column_norms`](crate::container::OptionalChunks::column_norms)); `None` until
    /// [`EncodedColumn::with_norm`] sets it.
    ///
    /// [`ColumnDecoder::weighted_norm`]: crate::ColumnDecoder::weighted_norm
    pub norm: Option<f32>,
}

impl EncodedColumn {
    /// Encodes a column of a `width` × `height` column image quantized to
    /// `bits` bits: with [`Entropy::Range`], range-coded (encoding 5) when
    /// that is no larger than the plain payload (zstd is then not tried: on
    /// these payloads it gains less than range coding), else (and always
    /// with [`Entropy::Zstd`]) as [`EncodedColumn::new`]. This is the
    /// writer's one choice of encoding per column; `LtmWriter::finish`
    /// may then recode encoding-5 columns in encoding 6, from the file's
    /// priors.
    pub fn coded(
        col: &SparseColumn,
        shape: &ColumnShape,
        entropy: Entropy,
        zstd_level: i32,
    ) -> EncodedColumn {
        if !col.indices.is_empty() && entropy == Entropy::Range {
            let compact = Encoding::Compact.codec().encode(col, shape, zstd_level);
            if let Some((bytes, raw_len)) = compact {
                if bytes.len() <= col.to_payload(shape.channels).len() {
                    return EncodedColumn::stored(col, Encoding::Compact, bytes, raw_len);
                }
            }
        }
        EncodedColumn::new(col, shape.channels, zstd_level)
    }

    /// Serializes and compresses a column (zstd when that is smaller),
    /// without range coding.
    pub fn new(col: &SparseColumn, channels: usize, zstd_level: i32) -> EncodedColumn {
        // Only the channel count matters to the varint payloads.
        let shape = ColumnShape {
            width: 0,
            height: 0,
            channels,
            bits: 0,
        };
        [Encoding::Empty, Encoding::Zstd, Encoding::Plain]
            .into_iter()
            .find_map(|e| {
                let (bytes, raw_len) = e.codec().encode(col, &shape, zstd_level)?;
                Some(EncodedColumn::stored(col, e, bytes, raw_len))
            })
            .expect("the plain payload stores every column")
    }

    /// The column stored as `bytes` in `encoding`, `raw_len` bytes once
    /// decompressed; its CRC is 0 when it has no payload.
    fn stored(
        col: &SparseColumn,
        encoding: Encoding,
        bytes: Vec<u8>,
        raw_len: u32,
    ) -> EncodedColumn {
        let entry = ColumnEntry {
            offset: 0,
            stored_len: bytes.len() as u32,
            raw_len,
            nnz: col.indices.len() as u32,
            crc: if encoding == Encoding::Empty {
                0
            } else {
                crc32fast::hash(&bytes)
            },
            depth: col.depth as u8,
            encoding,
        };
        EncodedColumn {
            bytes,
            entry,
            norm: None,
        }
    }

    /// The column with its priority norm set (see [`EncodedColumn::norm`]).
    pub fn with_norm(self, norm: f32) -> EncodedColumn {
        EncodedColumn {
            norm: Some(norm),
            ..self
        }
    }
}
