//! Encoding 4 (format version 4; what the writer chooses): scale codes,
//! the range-coded stream's length, the stream (magnitude classes, signs
//! and the two modelled bits below the leading one), then the raw low bits
//! ([`crate::entropy`], [`ValueCoding::Classes`]).

use super::ranged::{check_range_coded, decode_range_coded, encode_range_coded};
use super::{Codec, ColumnEntry, SparseColumn};
use crate::entropy::{ColumnShape, Priors, ValueCoding};
use crate::error::Result;

/// Encoding 4.
pub(crate) struct Classed;

impl Codec for Classed {
    fn name(&self) -> &'static str {
        "classed"
    }

    fn since_version(&self) -> u32 {
        4
    }

    fn value_coding(&self) -> Option<ValueCoding> {
        Some(ValueCoding::Classes)
    }

    fn encode(&self, col: &SparseColumn, shape: &ColumnShape, _: i32) -> Option<(Vec<u8>, u32)> {
        encode_range_coded(col, shape, ValueCoding::Classes)
    }

    /// As encoding 3, with 4 more bytes: the range-coded stream's length.
    fn check_entry(&self, e: &ColumnEntry, shape: &ColumnShape) -> std::result::Result<(), String> {
        check_range_coded(e, shape, 4)
    }

    fn decode(
        &self,
        j: usize,
        stored: &[u8],
        e: &ColumnEntry,
        shape: &ColumnShape,
        _: Option<&Priors>,
    ) -> Result<SparseColumn> {
        decode_range_coded(j, stored, e, shape, ValueCoding::Classes, None)
    }
}
