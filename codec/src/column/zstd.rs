//! Encoding 2: the plain payload ([`super::plain`]) in one zstd frame.

use super::plain::{check_payload_len, decode_payload};
use super::{Codec, ColumnEntry, SparseColumn};
use crate::entropy::{ColumnShape, Priors};
use crate::error::{Error, Result};

/// Encoding 2.
pub(crate) struct Zstd;

impl Codec for Zstd {
    fn name(&self) -> &'static str {
        "zstd"
    }

    fn since_version(&self) -> u32 {
        1
    }

    /// The compressed payload, when it is smaller than the payload.
    fn encode(
        &self,
        col: &SparseColumn,
        shape: &ColumnShape,
        zstd_level: i32,
    ) -> Option<(Vec<u8>, u32)> {
        let payload = col.to_payload(shape.channels);
        match ::zstd::bulk::compress(&payload, zstd_level) {
            Ok(packed) if packed.len() < payload.len() => Some((packed, payload.len() as u32)),
            _ => None,
        }
    }

    fn check_entry(&self, e: &ColumnEntry, shape: &ColumnShape) -> std::result::Result<(), String> {
        check_payload_len(e, shape, false)
    }

    fn decode(
        &self,
        j: usize,
        stored: &[u8],
        e: &ColumnEntry,
        shape: &ColumnShape,
        _: Option<&Priors>,
    ) -> Result<SparseColumn> {
        let payload = ::zstd::bulk::decompress(stored, e.raw_len as usize)
            .map_err(|err| Error::corrupt("column payload", format!("column {j}: zstd: {err}")))?;
        if payload.len() != e.raw_len as usize {
            return Err(Error::corrupt(
                "column payload",
                format!(
                    "column {j}: {} bytes after decompression, table says {}",
                    payload.len(),
                    e.raw_len
                ),
            ));
        }
        decode_payload(&payload, e, shape)
    }
}
