//! Any byte string given to the range-coded column decoder (encodings 3,
//! 4, 5 and 6) must give a valid column or an error, never a panic. The
//! first 8 bytes pick the shape (width, height 1..=64, channels 1 or 3,
//! bits 2..=16, depth, nonzero count) and the encoding; the rest is the
//! payload. Encoding 6 starts from skewed priors (every state valid, many
//! far from p = 1/2).
#![no_main]

use libfuzzer_sys::fuzz_target;
use ltm_codec::entropy::{decode, ColumnShape, Priors, ValueCoding, PRIOR_BINARY, PRIOR_CLASSES};
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
    let coding = match head[7] % 4 {
        0 => ValueCoding::ExpGolomb,
        1 => ValueCoding::Classes,
        2 => ValueCoding::Compact,
        _ => ValueCoding::Primed,
    };
    let priors = skewed_priors(head[7]);
    if let Ok(col) = decode(payload, nnz, &shape, depth, coding, Some(&priors)) {
        let pixels = shape.width * shape.height;
        let max = (1i32 << (shape.bits - 1)) - 1;
        assert_eq!(col.indices.len(), nnz);
        assert_eq!(col.values.len(), nnz * shape.channels);
        assert!(col.indices.windows(2).all(|w| w[0] < w[1]));
        assert!(col.indices.iter().all(|&i| (i as usize) < pixels));
        assert!(col.values.iter().all(|v| v.abs() <= max));
    }
});

/// Valid priors far from p = 1/2, varied by `seed`.
fn skewed_priors(seed: u8) -> Priors {
    let mut b = Vec::new();
    let mut put = |v: u16| b.extend_from_slice(&v.to_le_bytes());
    put(PRIOR_BINARY as u16);
    put(PRIOR_CLASSES as u16);
    for k in 0..PRIOR_BINARY {
        let p = if (k + seed as usize) % 2 == 0 { 31 } else { 32737 };
        put(p);
        put((k % 33) as u16);
    }
    for k in 0..PRIOR_CLASSES {
        // Most of the mass on one symbol.
        let hot = (k + seed as usize) % 17;
        for i in 1..17 {
            put(if i <= hot { 0 } else { 32751 });
        }
        put((k % 33) as u16);
    }
    Priors::from_bytes(&b).expect("valid priors")
}
