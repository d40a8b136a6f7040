//! A dense matrix quantized with one scale per row and entropy coded: the
//! payload of the `PCAB` (basis) and `PCAC` (coefficients) chunks
//! (docs/FORMAT.md, "PCA files").
//!
//! Row `a` holds `cols` values `v` quantized to `q = round(v / s_a · Q)`,
//! `Q = 2^(B−1) − 1`, `s_a = max |v|` over the row. Each `q` is predicted by
//! the value `stride` places before it in its row (0 for the first
//! `stride`), and the residuals are zigzag LEB128 varints in one zstd frame.
//! [`QuantizedMatrix::dequantize`] is the one reconstruction the encoder
//! measures and every decoder uses.

use crate::bytes::{Reader, Writer};
use crate::error::{Error, Result};
use crate::limits::Limits;

/// Bytes before the scales: rows, cols, stride, decompressed length.
const HEAD_LEN: usize = 16;
/// The largest scale a file may hold (the codec's matrix norm bound).
pub const MAX_SCALE: f32 = 1.2676506e30; // 2^100

/// A quantized matrix: `rows × cols` integers with one scale per row.
#[derive(Clone, Debug, PartialEq)]
pub struct QuantizedMatrix {
    /// Rows of the matrix.
    pub rows: usize,
    /// Values per row.
    pub cols: usize,
    /// Prediction distance within a row (1..=cols).
    pub stride: usize,
    /// Quantization bits `B` (2..=16).
    pub bits: u32,
    /// One scale per row: the largest magnitude of the row.
    pub scales: Vec<f32>,
    /// `rows · cols` quantized values, row-major, each within `±Q`.
    pub q: Vec<i32>,
}

/// `Q = 2^(B−1) − 1` for `bits` = B.
pub fn q_max(bits: u32) -> i32 {
    (1i32 << (bits - 1)) - 1
}

impl QuantizedMatrix {
    /// Quantizes `values` (`rows × cols`, row-major, finite) to `bits`.
    pub fn quantize(values: &[f32], rows: usize, cols: usize, stride: usize, bits: u32) -> Self {
        debug_assert_eq!(values.len(), rows * cols);
        let qm = q_max(bits) as f64;
        let mut scales = Vec::with_capacity(rows);
        let mut q = Vec::with_capacity(rows * cols);
        for row in values.chunks_exact(cols.max(1)).take(rows) {
            let s = row
                .iter()
                .fold(0.0f32, |m, v| m.max(v.abs()))
                .min(MAX_SCALE);
            scales.push(s);
            let inv = if s > 0.0 { qm / s as f64 } else { 0.0 };
            q.extend(
                row.iter()
                    .map(|&v| ((v as f64 * inv).round().clamp(-qm, qm)) as i32),
            );
        }
        QuantizedMatrix {
            rows,
            cols,
            stride,
            bits,
            scales,
            q,
        }
    }

    /// The decoded value of entry `(row, col)`: `q · s_row / Q` in f32.
    #[inline]
    pub fn value(&self, row: usize, col: usize) -> f32 {
        dequantize(self.q[row * self.cols + col], self.scales[row], self.bits)
    }

    /// The decoded matrix, row-major.
    pub fn dequantize(&self) -> Vec<f32> {
        let mut out = Vec::with_capacity(self.q.len());
        for (row, qs) in self.q.chunks_exact(self.cols.max(1)).enumerate() {
            let s = self.scales[row];
            out.extend(qs.iter().map(|&q| dequantize(q, s, self.bits)));
        }
        out
    }

    /// The chunk bytes (zstd at `level`).
    pub fn encode(&self, level: i32) -> Result<Vec<u8>> {
        let mut stream = Vec::with_capacity(self.q.len() * 2);
        for row in self.q.chunks_exact(self.cols.max(1)) {
            for (i, &v) in row.iter().enumerate() {
                let pred = if i >= self.stride {
                    row[i - self.stride]
                } else {
                    0
                };
                let r = v - pred;
                put_varint(&mut stream, ((r << 1) ^ (r >> 31)) as u32);
            }
        }
        let packed = zstd::bulk::compress(&stream, level)
            .map_err(|e| Error::Invalid(format!("zstd failed on a PCA chunk: {e}")))?;
        let mut w = Writer::default();
        w.u32(self.rows as u32);
        w.u32(self.cols as u32);
        w.u32(self.stride as u32);
        w.u32(stream.len() as u32);
        for &s in &self.scales {
            w.f32(s);
        }
        w.bytes.extend_from_slice(&packed);
        Ok(w.bytes)
    }

    /// Parses chunk `what` that must hold `rows × cols` values with
    /// prediction distance `stride`, checking every size against `limits`
    /// before allocating and every value against the bits' range.
    pub fn decode(
        bytes: &[u8],
        what: &'static str,
        shape: (usize, usize, usize),
        bits: u32,
        limits: &Limits,
    ) -> Result<QuantizedMatrix> {
        let (rows, cols, stride) = shape;
        let mut r = Reader::new(bytes, what);
        let (fr, fc, fs, raw_len) = (r.u32()?, r.u32()?, r.u32()?, r.u32()? as usize);
        if (fr as usize, fc as usize, fs as usize) != (rows, cols, stride) {
            return Err(Error::corrupt(
                what,
                format!("shape {fr}×{fc} with stride {fs}, the header implies {rows}×{cols} with stride {stride}"),
            ));
        }
        let count = rows as u64 * cols as u64;
        if (raw_len as u64) < count || raw_len as u64 > 5 * count {
            return Err(Error::corrupt(
                what,
                format!(
                    "{raw_len} varint bytes for {count} values (valid: {count}..={})",
                    5 * count
                ),
            ));
        }
        let _values = limits.check_alloc(what, count, 4)?;
        let _stream = limits.check_alloc(what, raw_len as u64, 1)?;
        if r.remaining() < 4 * rows {
            return Err(Error::corrupt(
                what,
                format!("{} bytes cannot hold {rows} scales", r.remaining()),
            ));
        }
        let mut scales = Vec::with_capacity(rows);
        for a in 0..rows {
            let s = r.f32()?;
            if !(0.0..=MAX_SCALE).contains(&s) {
                return Err(Error::corrupt(
                    what,
                    format!("scale {a} is {s} (valid: 0..=2^100)"),
                ));
            }
            scales.push(s);
        }
        let packed = &bytes[HEAD_LEN + 4 * rows..];
        let stream = zstd::bulk::decompress(packed, raw_len)
            .map_err(|e| Error::corrupt(what, format!("zstd: {e}")))?;
        if stream.len() != raw_len {
            return Err(Error::corrupt(
                what,
                format!(
                    "{} bytes after decompression, header says {raw_len}",
                    stream.len()
                ),
            ));
        }
        let q = decode_values(&stream, what, rows, cols, stride, bits)?;
        Ok(QuantizedMatrix {
            rows,
            cols,
            stride,
            bits,
            scales,
            q,
        })
    }
}

/// `q · s / Q`: the one dequantization of PCA files.
#[inline]
pub fn dequantize(q: i32, scale: f32, bits: u32) -> f32 {
    ((q as f64 * scale as f64) / q_max(bits) as f64) as f32
}

/// The residual varints of `rows × cols` values, undone and checked.
fn decode_values(
    stream: &[u8],
    what: &'static str,
    rows: usize,
    cols: usize,
    stride: usize,
    bits: u32,
) -> Result<Vec<i32>> {
    let qm = q_max(bits) as i64;
    let mut q = Vec::with_capacity(rows * cols);
    let mut pos = 0usize;
    for _ in 0..rows {
        let start = q.len();
        for i in 0..cols {
            let z = get_varint(stream, &mut pos).ok_or_else(|| {
                Error::corrupt(
                    what,
                    format!("varint stream ends or overflows at byte {pos}"),
                )
            })?;
            let r = ((z >> 1) as i64) ^ -((z & 1) as i64);
            let pred = if i >= stride {
                q[start + i - stride] as i64
            } else {
                0
            };
            let v = pred + r;
            if v.abs() > qm {
                return Err(Error::corrupt(
                    what,
                    format!("quantized value {v} outside ±{qm} for {bits} bits"),
                ));
            }
            q.push(v as i32);
        }
    }
    if pos != stream.len() {
        return Err(Error::corrupt(
            what,
            format!("{} trailing bytes", stream.len() - pos),
        ));
    }
    Ok(q)
}

fn put_varint(out: &mut Vec<u8>, mut v: u32) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

/// A LEB128 varint of at most 5 bytes that fits `u32`.
fn get_varint(s: &[u8], pos: &mut usize) -> Option<u32> {
    let mut v = 0u64;
    for shift in (0..35).step_by(7) {
        let b = *s.get(*pos)?;
        *pos += 1;
        v |= ((b & 0x7f) as u64) << shift;
        if b & 0x80 == 0 {
            return u32::try_from(v).ok();
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_every_bit_depth_and_hostile_values() {
        let rows = 3;
        let cols = 37;
        let values: Vec<f32> = (0..rows * cols)
            .map(|i| match i / cols {
                0 => ((i as f32) * 0.37).sin() * 1e-6,
                1 => 0.0,
                _ => ((i as f32) * 1.3).cos() * 3e4,
            })
            .collect();
        for bits in 2..=16 {
            for stride in [1, 3] {
                let qm = QuantizedMatrix::quantize(&values, rows, cols, stride, bits);
                let bytes = qm.encode(3).unwrap();
                let back = QuantizedMatrix::decode(
                    &bytes,
                    "PCAB chunk",
                    (rows, cols, stride),
                    bits,
                    &Limits::default(),
                )
                .unwrap();
                assert_eq!(back, qm);
                let dq = back.dequantize();
                for (a, (v, d)) in values.iter().zip(&dq).enumerate() {
                    let s = qm.scales[a / cols];
                    // Rounding to nearest: at most half a step, plus f32 rounding.
                    assert!(
                        (v - d).abs() <= 0.5 * s / q_max(bits) as f32 * 1.0001 + s * 1e-6,
                        "{bits} bits: {v} vs {d}"
                    );
                    assert!(d.is_finite());
                }
            }
        }
    }

    #[test]
    fn corrupted_chunks_are_errors() {
        let values: Vec<f32> = (0..40).map(|i| i as f32 - 20.0).collect();
        let qm = QuantizedMatrix::quantize(&values, 4, 10, 1, 8);
        let bytes = qm.encode(3).unwrap();
        let lim = Limits::default();
        let dec = |b: &[u8], shape| QuantizedMatrix::decode(b, "PCAC chunk", shape, 8, &lim);
        assert!(dec(&bytes, (4, 10, 1)).is_ok());
        assert!(dec(&bytes, (4, 11, 1)).is_err(), "shape differs");
        assert!(dec(&bytes, (4, 10, 1)).is_ok());
        assert!(
            QuantizedMatrix::decode(&bytes, "PCAC chunk", (4, 10, 1), 4, &lim).is_err(),
            "values beyond 4 bits"
        );
        for cut in 0..bytes.len() {
            assert!(
                dec(&bytes[..cut], (4, 10, 1)).is_err(),
                "truncated at {cut}"
            );
        }
        let mut nan = bytes.clone();
        nan[HEAD_LEN..HEAD_LEN + 4].copy_from_slice(&f32::NAN.to_le_bytes());
        assert!(dec(&nan, (4, 10, 1))
            .unwrap_err()
            .to_string()
            .contains("scale 0"));
        let mut huge = bytes.clone();
        huge[12..16].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(dec(&huge, (4, 10, 1)).is_err());
        let small = Limits::with_max_alloc(100);
        assert!(QuantizedMatrix::decode(&bytes, "PCAC chunk", (4, 10, 1), 8, &small).is_err());
    }
}
