//! Any byte string given to the range-coded column decoder (encodings 3,
//! 4 and 5) must give a valid column or an error, never a panic. The first 8
//! bytes pick the shape (width, height 1..=64, channels 1 or 3, bits
//! 2..=16, depth, nonzero count) and the encoding; the rest is the payload.
#![no_main]

use libfuzzer_sys::fuzz_target;
use ltm_codec::entropy::{decode, ColumnShape, ValueCoding};
use ltm_codec::wavelet::max_levels;

fuzz_target!(|data: &[u8]| {
    if data.len() < 8 {
        return;
    }
    let (head, payload) = data.split_at(8);
    let shape = ColumnShape {
        width: 1 + head[0] as usize % 64,
        height: 1 + head[1] as usize % 64,
        channels: if head[2] & 1 == 0 { 1 } else { 3 },
        bits: 2 + head[3] as u32 % 15,
    };
    let depth = head[4] as u32 % (max_levels(shape.width, shape.height) + 2);
    let nnz = u16::from_le_bytes([head[5], head[6]]) as usize;
    let coding = match head[7] % 3 {
        0 => ValueCoding::ExpGolomb,
        1 => ValueCoding::Classes,
        _ => ValueCoding::Compact,
    };
    if let Ok(col) = decode(payload, nnz, &shape, depth, coding) {
        let pixels = shape.width * shape.height;
        let max = (1i32 << (shape.bits - 1)) - 1;
        assert_eq!(col.indices.len(), nnz);
        assert_eq!(col.values.len(), nnz * shape.channels);
        assert!(col.indices.windows(2).all(|w| w[0] < w[1]));
        assert!(col.indices.iter().all(|&i| (i as usize) < pixels));
        assert!(col.values.iter().all(|v| v.abs() <= max));
    }
});
