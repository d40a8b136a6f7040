//! Encoding 3 (format version 3): scale codes, then the coefficients
//! range-coded with context modelling, values as exp-Golomb bins
//! ([`crate::entropy`], [`ValueCoding::ExpGolomb`]). Still read; the
//! writer no longer chooses it.

use super::{Codec, ColumnEntry, SparseColumn};
use crate::entropy::{self, ColumnShape, Priors, ValueCoding};
use crate::error::{Error, Result};

/// Encoding 3.
pub(crate) struct Ranged;

impl Codec for Ranged {
    fn name(&self) -> &'static str {
        "range-coded"
    }

    fn since_version(&self) -> u32 {
        3
    }

    fn value_coding(&self) -> Option<ValueCoding> {
        Some(ValueCoding::ExpGolomb)
    }

    fn encode(&self, col: &SparseColumn, shape: &ColumnShape, _: i32) -> Option<(Vec<u8>, u32)> {
        encode_range_coded(col, shape, ValueCoding::ExpGolomb)
    }

    fn check_entry(&self, e: &ColumnEntry, shape: &ColumnShape) -> std::result::Result<(), String> {
        check_range_coded(e, shape, 0)
    }

    fn decode(
        &self,
        j: usize,
        stored: &[u8],
        e: &ColumnEntry,
        shape: &ColumnShape,
        _: Option<&Priors>,
    ) -> Result<SparseColumn> {
        decode_range_coded(j, stored, e, shape, ValueCoding::ExpGolomb, None)
    }
}

/// A range-coded payload of a nonempty column: stored as it decodes.
pub(super) fn encode_range_coded(
    col: &SparseColumn,
    shape: &ColumnShape,
    coding: ValueCoding,
) -> Option<(Vec<u8>, u32)> {
    if col.indices.is_empty() {
        return None;
    }
    let bytes = entropy::encode(col, shape, coding)?;
    let len = bytes.len() as u32;
    Some((bytes, len))
}

/// The lengths of a range-coded entry: at least one nonzero, equal stored
/// and payload lengths of at least the scale codes plus `extra` bytes.
pub(super) fn check_range_coded(
    e: &ColumnEntry,
    shape: &ColumnShape,
    extra: u64,
) -> std::result::Result<(), String> {
    let (nnz, raw_len, stored_len) = (e.nnz, e.raw_len, e.stored_len);
    let scale_bytes = 2 * (e.depth as u64 + 1) * shape.channels as u64;
    let least = scale_bytes + extra;
    if nnz == 0 || raw_len != stored_len || (stored_len as u64) < least {
        return Err(format!(
            "{nnz} nonzeros with encoding {}, stored length {stored_len} and payload length {raw_len} (valid: k ≥ 1, equal lengths ≥ {least})",
            e.encoding as u8
        ));
    }
    Ok(())
}

/// Decodes a range-coded payload; a corrupt one's message names column `j`.
pub(super) fn decode_range_coded(
    j: usize,
    stored: &[u8],
    e: &ColumnEntry,
    shape: &ColumnShape,
    coding: ValueCoding,
    priors: Option<&Priors>,
) -> Result<SparseColumn> {
    entropy::decode(
        stored,
        e.nnz as usize,
        shape,
        e.depth as u32,
        coding,
        priors,
    )
    .map_err(|err| match err {
        Error::Corrupt { what, detail } => Error::Corrupt {
            what,
            detail: format!("column {j}: {detail}"),
        },
        other => other,
    })
}
