//! Encoding 1: the plain payload, positions as varint gaps, then values as
//! zigzag varints (also the payload encoding 2 compresses).

use super::{Codec, ColumnEntry, SparseColumn};
use crate::bytes::Reader;
use crate::entropy::{ColumnShape, Priors};
use crate::error::{Error, Result};

fn put_varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

fn get_varint(r: &mut Reader) -> Result<u64> {
    let mut v = 0u64;
    for shift in (0..64).step_by(7) {
        let b = r.u8()?;
        v |= ((b & 0x7f) as u64) << shift;
        if b & 0x80 == 0 {
            return Ok(v);
        }
    }
    Err(Error::corrupt(
        "column payload",
        "varint longer than 10 bytes",
    ))
}

impl SparseColumn {
    /// Payload bytes: positions as varint gaps, then values as zigzag
    /// varints, channel-interleaved.
    pub fn to_payload(&self, channels: usize) -> Vec<u8> {
        let mut out =
            Vec::with_capacity(2 * self.scale_codes.len() + self.indices.len() * (2 + channels));
        for e in &self.scale_codes {
            out.extend_from_slice(&e.to_le_bytes());
        }
        let mut prev: i64 = -1;
        for &i in &self.indices {
            put_varint(&mut out, (i as i64 - prev - 1) as u64);
            prev = i as i64;
        }
        for &v in &self.values[..self.indices.len() * channels] {
            put_varint(&mut out, ((v << 1) ^ (v >> 31)) as u32 as u64);
        }
        out
    }

    /// Parses a payload of a column at `depth`, checking every position
    /// against `pixels` and every value against the quantizer's range.
    pub fn from_payload(
        bytes: &[u8],
        nnz: usize,
        channels: usize,
        pixels: usize,
        bits: u32,
        depth: u32,
    ) -> Result<SparseColumn> {
        let mut r = Reader::new(bytes, "column payload");
        let groups = (depth as usize + 1) * channels;
        let mut col = SparseColumn {
            depth,
            scale_codes: Vec::with_capacity(groups),
            indices: Vec::with_capacity(nnz),
            values: Vec::with_capacity(nnz * channels),
        };
        for _ in 0..groups {
            col.scale_codes.push(r.u16()?);
        }
        let mut next = 0u64;
        for _ in 0..nnz {
            let i = next.saturating_add(get_varint(&mut r)?);
            if i >= pixels as u64 {
                return Err(Error::corrupt(
                    "column payload",
                    format!("position {i} outside the {pixels}-pixel image"),
                ));
            }
            col.indices.push(i as u32);
            next = i + 1;
        }
        let max = (1i64 << (bits - 1)) - 1;
        for _ in 0..nnz * channels {
            let z = get_varint(&mut r)?;
            if z > u32::MAX as u64 {
                return Err(Error::corrupt(
                    "column payload",
                    "value out of 32-bit range",
                ));
            }
            let v = ((z >> 1) as i64) ^ -((z & 1) as i64);
            if v.abs() > max {
                return Err(Error::corrupt(
                    "column payload",
                    format!("quantized value {v} outside ±{max} for {bits} bits"),
                ));
            }
            col.values.push(v as i32);
        }
        if r.remaining() != 0 {
            return Err(Error::corrupt(
                "column payload",
                format!("{} trailing bytes", r.remaining()),
            ));
        }
        Ok(col)
    }
}

/// Encoding 1.
pub(crate) struct Plain;

impl Codec for Plain {
    fn name(&self) -> &'static str {
        "plain"
    }

    fn since_version(&self) -> u32 {
        1
    }

    fn encode(&self, col: &SparseColumn, shape: &ColumnShape, _: i32) -> Option<(Vec<u8>, u32)> {
        let payload = col.to_payload(shape.channels);
        let len = payload.len() as u32;
        Some((payload, len))
    }

    fn check_entry(&self, e: &ColumnEntry, shape: &ColumnShape) -> std::result::Result<(), String> {
        check_payload_len(e, shape, false)?;
        if e.stored_len != e.raw_len {
            return Err(stored_len_problem(e));
        }
        Ok(())
    }

    fn decode(
        &self,
        _: usize,
        stored: &[u8],
        e: &ColumnEntry,
        shape: &ColumnShape,
        _: Option<&Priors>,
    ) -> Result<SparseColumn> {
        decode_payload(stored, e, shape)
    }
}

/// Parses the payload of entry `e` ([`SparseColumn::from_payload`]).
pub(super) fn decode_payload(
    payload: &[u8],
    e: &ColumnEntry,
    shape: &ColumnShape,
) -> Result<SparseColumn> {
    SparseColumn::from_payload(
        payload,
        e.nnz as usize,
        shape.channels,
        shape.width * shape.height,
        shape.bits,
        e.depth as u32,
    )
}

/// The payload length of a varint entry (encodings 0 to 2): 2 bytes per
/// scale, then 1 to 5 bytes per position and per value; no nonzero exactly
/// when `empty`.
pub(super) fn check_payload_len(
    e: &ColumnEntry,
    shape: &ColumnShape,
    empty: bool,
) -> std::result::Result<(), String> {
    let (nnz, raw_len) = (e.nnz, e.raw_len);
    let channels = shape.channels as u64;
    let scale_bytes = 2 * (e.depth as u64 + 1) * channels;
    let (min_raw, max_raw) = (
        scale_bytes + nnz as u64 * (1 + channels),
        scale_bytes + nnz as u64 * 5 * (1 + channels),
    );
    if empty != (nnz == 0) || (nnz > 0 && !(min_raw..=max_raw).contains(&(raw_len as u64))) {
        return Err(format!(
            "{nnz} nonzeros with encoding {} and {raw_len} payload bytes (valid: {min_raw}..={max_raw})",
            e.encoding as u8
        ));
    }
    Ok(())
}

/// The problem of a stored length that the encoding does not allow.
pub(super) fn stored_len_problem(e: &ColumnEntry) -> String {
    format!(
        "stored length {} for encoding {} and payload length {}",
        e.stored_len, e.encoding as u8, e.raw_len
    )
}
