//! Encoding 5 (format version 8; what the writer chooses): encoding 4's
//! coefficients, with the scale codes coded in the streams (a code equal to
//! the one before costs one modelled bit) and the range-coded stream's
//! length as a varint ([`crate::entropy`], [`ValueCoding::Compact`]). On a
//! grey 96×72 matrix at 3 %, encoding 4's fixed 2·(d + 1)·C + 4 bytes (16
//! at depth 5) were an eighth of a column's 124 bytes.

use super::ranged::{decode_range_coded, encode_range_coded};
use super::{Codec, ColumnEntry, SparseColumn};
use crate::entropy::{ColumnShape, Priors, ValueCoding};
use crate::error::Result;

/// Encoding 5.
pub(crate) struct Compact;

/// The shortest encoding-5 or 6 payload: a 1-byte varint and the first
/// nonzero scale code's 16 raw bits.
const LEAST: u32 = 3;

/// The lengths of an encoding-5 or 6 entry: at least one nonzero, equal
/// stored and payload lengths of at least [`LEAST`].
pub(super) fn check_compact_entry(e: &ColumnEntry) -> std::result::Result<(), String> {
    let (nnz, raw_len, stored_len) = (e.nnz, e.raw_len, e.stored_len);
    if nnz == 0 || raw_len != stored_len || stored_len < LEAST {
        return Err(format!(
            "{nnz} nonzeros with encoding {}, stored length {stored_len} and payload length {raw_len} (valid: k ≥ 1, equal lengths ≥ {LEAST})",
            e.encoding as u8
        ));
    }
    Ok(())
}

impl Codec for Compact {
    fn name(&self) -> &'static str {
        "compact"
    }

    fn since_version(&self) -> u32 {
        8
    }

    fn value_coding(&self) -> Option<ValueCoding> {
        Some(ValueCoding::Compact)
    }

    fn encode(&self, col: &SparseColumn, shape: &ColumnShape, _: i32) -> Option<(Vec<u8>, u32)> {
        encode_range_coded(col, shape, ValueCoding::Compact)
    }

    fn check_entry(&self, e: &ColumnEntry, _: &ColumnShape) -> std::result::Result<(), String> {
        check_compact_entry(e)
    }

    fn decode(
        &self,
        j: usize,
        stored: &[u8],
        e: &ColumnEntry,
        shape: &ColumnShape,
        _: Option<&Priors>,
    ) -> Result<SparseColumn> {
        decode_range_coded(j, stored, e, shape, ValueCoding::Compact, None)
    }
}
