//! Baselines for the size/error report: what the wavelet codec is measured
//! against on the same matrix `T` (rows = pixels, columns = cubemap texels).
//! PCA (Eigentransport) is no longer a baseline here: it is a coded mode,
//! `ltm compress --mode pca`, swept with the others.
//!
//! - `zstd-raw`: the raw f32 matrix compressed losslessly with zstd (a pure
//!   measurement, here).
//! - `sh`: the linear spherical-harmonics approximation of each row,
//!   [`ltm_codec::ShProjection`], relit by [`ltm_relight::BasisRelighter`].
//!
//! Sizes count the stored factors as uncompressed f32 values; errors are the
//! relative Frobenius error `‖T − T̂‖_F / ‖T‖_F` of the matrix, computed in
//! f64 by the fits. None of the sizes includes the albedo image of a grey
//! store.

use anyhow::{anyhow, Result};
use ltm_codec::{RawStore, ShProjection};
use rayon::prelude::*;
use std::io::Write;

/// Bytes of raw rows per zstd frame (frames are compressed in parallel).
const ZSTD_FRAME_BYTES: usize = 32 << 20;

/// One baseline point: size in bytes against relative L2 (Frobenius) error
/// of the matrix.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct BaselinePoint {
    /// `"zstd-raw"` or `"sh"` (`"pca"` in reports made before PCA was a mode).
    pub method: String,
    /// 0 for zstd, the rank `k` for PCA, the order `L` for SH (`L²`
    /// coefficients, bands `l < L`).
    pub param: usize,
    /// Size of the representation in bytes.
    pub bytes: u64,
    /// `‖T − T̂‖_F / ‖T‖_F` (0 for an all-zero matrix).
    pub matrix_error: f64,
}

/// Sorted, deduplicated `params`, clamped to `max`.
fn sorted(params: &[usize], max: usize) -> Vec<usize> {
    let mut v: Vec<usize> = params.iter().map(|&k| k.min(max)).collect();
    v.sort_unstable();
    v.dedup();
    v
}

/// Entry `i` of a fit's error curve.
fn curve_point(curve: &[f64], i: usize, what: &str) -> Result<f64> {
    curve.get(i).copied().ok_or_else(|| {
        anyhow!(
            "{what} {i} was not fitted (at most {})",
            curve.len().saturating_sub(1)
        )
    })
}

// ---------------------------------------------------------------------------
// zstd

/// Lossless zstd (at `level`) of the raw f32 matrix rows, as stored
/// (`T[p][j][c]`, little-endian), streamed block by block; error 0.
pub fn zstd_raw(raw: &RawStore, level: i32) -> Result<BaselinePoint> {
    let bytes = zstd_raw_to(raw, level, ZSTD_FRAME_BYTES, &mut std::io::sink())?;
    Ok(BaselinePoint {
        method: "zstd-raw".into(),
        param: 0,
        bytes,
        matrix_error: 0.0,
    })
}

/// Writes the zstd stream of the raw rows to `out` (consecutive frames of
/// about `frame_bytes` of rows each, compressed in parallel) and returns its
/// length in bytes.
fn zstd_raw_to(raw: &RawStore, level: i32, frame_bytes: usize, out: &mut dyn Write) -> Result<u64> {
    let dims = raw.dims();
    let header = *raw.header();
    let pixels = dims.pixels();
    let frame_pixels = (frame_bytes / (dims.row_len() * 4)).max(1);
    let frames: Vec<std::ops::Range<usize>> = (0..pixels)
        .step_by(frame_pixels)
        .map(|s| s..(s + frame_pixels).min(pixels))
        .collect();
    let batch = 2 * rayon::current_num_threads().max(1);
    let mut next_block = 0;
    let mut total = 0u64;
    for group in frames.chunks(batch) {
        let end = group.last().map_or(0, |r| r.end);
        while next_block < header.block_count() && header.block_range(next_block).start < end {
            raw.verify_block(next_block)?;
            next_block += 1;
        }
        let compressed: Vec<Vec<u8>> = group
            .par_iter()
            .map(|r| {
                // Positioned reads: a store truncated meanwhile is an error.
                let mut values = Vec::new();
                raw.read_rows(r.clone(), &mut values)?;
                let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
                Ok(zstd::bulk::compress(&bytes, level)?)
            })
            .collect::<Result<_>>()?;
        for frame in compressed {
            out.write_all(&frame)?;
            total += frame.len() as u64;
        }
    }
    raw.check_unchanged()?;
    Ok(total)
}

// ---------------------------------------------------------------------------
// Spherical harmonics

/// Spherical-harmonics projection of each row at each order of `orders`
/// (sorted and deduplicated; at most [`ltm_codec::MAX_SH_ORDER`]), from one
/// [`ShProjection`] of the largest order, which is returned for relighting.
/// The size of order `L` is `L²·P·C·4` bytes.
pub fn sh(raw: &RawStore, orders: &[usize]) -> Result<(Vec<BaselinePoint>, ShProjection)> {
    let dims = raw.dims();
    let n_rows = dims.pixels() * dims.channels as usize;
    let orders = sorted(orders, usize::MAX);
    let projection = ShProjection::fit(raw, orders.last().copied().unwrap_or(0))?;
    let points = orders
        .iter()
        .map(|&order| {
            Ok(BaselinePoint {
                method: "sh".into(),
                param: order,
                bytes: (order * order) as u64 * n_rows as u64 * 4,
                matrix_error: curve_point(projection.order_errors(), order, "SH order")?,
            })
        })
        .collect::<Result<_>>()?;
    Ok((points, projection))
}

#[cfg(test)]
mod tests {
    use super::*;
    use ltm_codec::Dims;
    use ltm_testkit::{block_bytes, write_raw};

    fn dims(width: u32, height: u32, face_res: u32, channels: u32) -> Dims {
        Dims::image(width, height, face_res, channels)
    }

    /// A deterministic matrix of full rank with every third pixel zero.
    fn matrix(d: Dims) -> Vec<f32> {
        let row = d.row_len();
        (0..d.pixels() * row)
            .map(|i| {
                if (i / row) % 3 == 1 {
                    0.0
                } else {
                    ((i as f32 * 0.37).sin() + 1.2) * 1e-2
                }
            })
            .collect()
    }

    #[test]
    fn sh_orders_sorted_with_sizes_from_the_error_curve() {
        let dir = tempfile::tempdir().unwrap();
        let d = dims(6, 5, 4, 3);
        let raw = RawStore::open(&write_raw(
            &dir.path().join("t.raw"),
            d,
            &matrix(d),
            None,
            block_bytes(d, 4),
        ))
        .unwrap();
        let (points, projection) = sh(&raw, &[6, 1, 2, 3, 5, 2, 4]).unwrap();
        assert_eq!(
            points.iter().map(|p| p.param).collect::<Vec<_>>(),
            vec![1, 2, 3, 4, 5, 6]
        );
        for p in &points {
            assert_eq!(p.method, "sh");
            assert_eq!(p.bytes, (p.param * p.param * d.pixels() * 3 * 4) as u64);
            assert_eq!(p.matrix_error, projection.order_errors()[p.param]);
        }
        assert!(sh(&raw, &[65]).is_err());
    }

    #[test]
    fn zstd_round_trip_and_size() {
        let dir = tempfile::tempdir().unwrap();
        let d = dims(7, 5, 4, 3);
        let t: Vec<f32> = (0..d.pixels() * d.row_len())
            .map(|i| ((i % 113) as f32 * 0.05).sin() * 1e-3)
            .collect();
        let raw = RawStore::open(&write_raw(
            &dir.path().join("t.raw"),
            d,
            &t,
            None,
            block_bytes(d, 4),
        ))
        .unwrap();
        let mut rows = Vec::new();
        raw.read_rows(0..d.pixels(), &mut rows).unwrap();
        let want: Vec<u8> = rows.iter().flat_map(|v| v.to_le_bytes()).collect();
        // Frames of 3 rows: several frames, concatenated.
        for frame_bytes in [3 * d.row_len() * 4, ZSTD_FRAME_BYTES] {
            let mut out = Vec::new();
            let n = zstd_raw_to(&raw, 3, frame_bytes, &mut out).unwrap();
            assert_eq!(n, out.len() as u64);
            assert_eq!(zstd::decode_all(&out[..]).unwrap(), want);
        }
        let mut out = Vec::new();
        zstd_raw_to(&raw, 3, ZSTD_FRAME_BYTES, &mut out).unwrap();
        let point = zstd_raw(&raw, 3).unwrap();
        assert_eq!(point.bytes, out.len() as u64);
        assert_eq!(
            (point.method.as_str(), point.param, point.matrix_error),
            ("zstd-raw", 0, 0.0)
        );
        assert!(point.bytes < want.len() as u64);
    }
}
