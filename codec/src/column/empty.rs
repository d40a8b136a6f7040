//! Encoding 0: a column with no nonzero coefficient, no payload.

use super::plain::{check_payload_len, stored_len_problem};
use super::{Codec, ColumnEntry, SparseColumn};
use crate::entropy::{ColumnShape, Priors};
use crate::error::Result;

/// Encoding 0.
pub(crate) struct Empty;

impl Codec for Empty {
    fn name(&self) -> &'static str {
        "empty"
    }

    fn since_version(&self) -> u32 {
        1
    }

    fn encode(&self, col: &SparseColumn, _: &ColumnShape, _: i32) -> Option<(Vec<u8>, u32)> {
        col.indices.is_empty().then(|| (Vec::new(), 0))
    }

    fn check_entry(&self, e: &ColumnEntry, shape: &ColumnShape) -> std::result::Result<(), String> {
        check_payload_len(e, shape, true)?;
        if e.stored_len != 0 {
            return Err(stored_len_problem(e));
        }
        Ok(())
    }

    fn decode(
        &self,
        _: usize,
        _: &[u8],
        e: &ColumnEntry,
        _: &ColumnShape,
        _: Option<&Priors>,
    ) -> Result<SparseColumn> {
        Ok(SparseColumn {
            depth: e.depth as u32,
            ..Default::default()
        })
    }
}
