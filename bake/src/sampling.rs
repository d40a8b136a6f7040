//! Deterministic low-discrepancy point sets.
//!
//! Both the pixel sub-samples and the direction samples inside a cubemap
//! texel use the 2D Hammersley set of N points, `((k + ½)/N, φ₂(k))` for
//! `k < N` (φ₂ the base-2 radical inverse), shifted modulo 1 by a
//! Cranley–Patterson rotation: one per pixel for the pixel sub-samples, one
//! per (pixel, sub-sample, texel) for the direction samples. Independent
//! rotations keep the quadrature errors of different texels and pixels
//! uncorrelated, so they cancel in sums over many texels instead of adding
//! up. A rotation is a hash (SplitMix64) of the indices, so a bake is
//! reproducible bit for bit. With one pixel sub-sample, the pixel centre is
//! used.

/// The base-2 radical inverse of `k` (bit reversal), in [0, 1).
pub fn radical_inverse2(k: u32) -> f64 {
    k.reverse_bits() as f64 * (1.0 / 4_294_967_296.0)
}

/// The `n`-point 2D Hammersley set, `((k + ½)/n, φ₂(k))`.
pub fn hammersley(n: u32) -> Vec<[f64; 2]> {
    (0..n)
        .map(|k| [(k as f64 + 0.5) / n as f64, radical_inverse2(k)])
        .collect()
}

/// SplitMix64: a well-mixed 64-bit hash.
pub fn mix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A Cranley–Patterson shift in [0, 1)² from a key.
pub fn rotation(key: u64) -> [f64; 2] {
    let h = mix64(key);
    let scale = 1.0 / (1u64 << 32) as f64;
    [(h >> 32) as f64 * scale, (h & 0xFFFF_FFFF) as f64 * scale]
}

/// `x + shift` modulo 1.
#[inline]
pub fn wrap(x: f64, shift: f64) -> f64 {
    let y = x + shift;
    if y >= 1.0 {
        y - 1.0
    } else {
        y
    }
}
