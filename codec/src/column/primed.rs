//! Encoding 6 (format version 9; what the writer chooses where it codes a
//! column smaller than encoding 5): encoding 5 with every context starting
//! in the file's priors, chunk PRIO ([`crate::entropy::Priors`],
//! [`ValueCoding::Primed`]). The writer codes it once every column is
//! known (`LtmWriter::finish`), since the priors come from them all.

use super::compact::check_compact_entry;
use super::ranged::decode_range_coded;
use super::{Codec, ColumnEntry, SparseColumn};
use crate::entropy::{ColumnShape, Priors, ValueCoding};
use crate::error::Result;

/// Encoding 6.
pub(crate) struct Primed;

impl Codec for Primed {
    fn name(&self) -> &'static str {
        "primed"
    }

    fn since_version(&self) -> u32 {
        9
    }

    fn value_coding(&self) -> Option<ValueCoding> {
        Some(ValueCoding::Primed)
    }

    /// `None`: a column alone has no priors (the writer codes encoding 6
    /// from the whole file's).
    fn encode(&self, _: &SparseColumn, _: &ColumnShape, _: i32) -> Option<(Vec<u8>, u32)> {
        None
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
        priors: Option<&Priors>,
    ) -> Result<SparseColumn> {
        decode_range_coded(j, stored, e, shape, ValueCoding::Primed, priors)
    }
}
