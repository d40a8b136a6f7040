//! A column as stored: sorted positions in the Mallat layout of its depth
//! and quantized values.

/// A column as stored: sorted coefficient positions in the Mallat layout of
/// its depth, and quantized values (`channels` per position).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SparseColumn {
    /// Column transform depth (0 = rows only).
    pub depth: u32,
    /// Quantizer scale codes (`quant::decode_scale`),
    /// `(depth + 1) · channels` of them, group-major: group 0 is the low band,
    /// group `k` the detail bands of level `k` (`quant::scale_groups`).
    pub scale_codes: Vec<u16>,
    /// Sorted positions of the kept coefficients in the column image.
    pub indices: Vec<u32>,
    /// Quantized values, `channels` per position, position-major.
    pub values: Vec<i32>,
}
