//! The `pca` mode's chunks: `PCAM` (the mean row, f32), `PCAB` (the
//! quantized basis) and `PCAC` (the quantized coefficients), written
//! and read here; the container places them (docs/FORMAT.md).

use super::{PcaModel, QuantizedMatrix, MAX_SCALE};
use crate::dims::Dims;
use crate::error::{Error, Result};
use crate::limits::Limits;

/// The chunks of `model`: `PCAM`, `PCAB`, `PCAC`, in that order.
pub(crate) fn write_chunks(model: &PcaModel, zstd_level: i32) -> Result<Vec<([u8; 4], Vec<u8>)>> {
    let mean: Vec<u8> = model.mean().iter().flat_map(|v| v.to_le_bytes()).collect();
    Ok(vec![
        (*b"PCAM", mean),
        (*b"PCAB", model.basis().encode(zstd_level)?),
        (*b"PCAC", model.coefficients().encode(zstd_level)?),
    ])
}

/// Decodes and checks the PCA chunks (each found by `get`) against a
/// matrix of `dims` with `k` components (already checked against the
/// dimensions) quantized to `bits`, and `limits`.
pub(crate) fn read_chunks<'a>(
    get: impl Fn(&[u8; 4]) -> Result<&'a [u8]>,
    dims: Dims,
    k: usize,
    bits: u32,
    limits: &Limits,
) -> Result<PcaModel> {
    let (p, n) = (dims.pixels(), dims.row_len());
    let mean_bytes = get(b"PCAM")?;
    if mean_bytes.len() != 4 * n {
        return Err(Error::corrupt(
            "PCAM chunk",
            format!(
                "{} bytes, the mean row needs {} ({n} values)",
                mean_bytes.len(),
                4 * n
            ),
        ));
    }
    let _mean = limits.check_alloc("PCA mean row", n as u64, 4)?;
    let mean: Vec<f32> = mean_bytes
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes")))
        .collect();
    if let Some(i) = mean
        .iter()
        .position(|v| !v.is_finite() || v.abs() > MAX_SCALE)
    {
        return Err(Error::corrupt(
            "PCAM chunk",
            format!(
                "mean value {i} is {} (valid: finite, at most 2^100)",
                mean[i]
            ),
        ));
    }
    // The model also keeps the basis in f64.
    let _basis = limits.check_alloc("PCA basis", (k * n) as u64, 8)?;
    let basis = QuantizedMatrix::decode(
        get(b"PCAB")?,
        "PCAB chunk",
        (k, n, dims.channels as usize),
        bits,
        limits,
    )?;
    let coefficients =
        QuantizedMatrix::decode(get(b"PCAC")?, "PCAC chunk", (k, p, 1), bits, limits)?;
    PcaModel::new(dims, mean, basis, coefficients)
}
