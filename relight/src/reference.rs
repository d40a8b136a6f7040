//! The exact relit image: the dense product `B = T·L` over every light, read
//! from the raw transport store. Relit images from compressed files are
//! measured against it.

use crate::error::{RelightError, Result};
use crate::image_io::Image;
use ltm_codec::{Progress, RawStore, Stage};
use rayon::prelude::*;
use std::sync::atomic::{AtomicUsize, Ordering};

/// Bytes of rows read at a time (at least one row).
const READ_BYTES: usize = 8 << 20;

/// The exact image `B[p] = Σ_j T[p, j]·L[j]` under the cubemap lighting
/// `light` (mean radiance per texel, `6·n²` entries in column order, e.g.
/// from [`crate::EnvMap::to_cubemap`]).
///
/// Every product is accumulated in f64. With 3 channels each channel of `T`
/// multiplies the same channel of `L`; with 1 channel the grey transport
/// multiplies each channel of `L`, and the result is multiplied by the
/// pixel's albedo when the store has an albedo image. Rows flagged all zero
/// are skipped (their pixels are 0).
///
/// Each block's checksum is verified before its rows are used. Runs in
/// parallel over rows on rayon's pool.
pub fn reference(raw: &RawStore, light: &[[f32; 3]]) -> Result<Image> {
    reference_with_progress(raw, light, Progress::NONE)
}

/// [`reference()`], reporting ([`Stage::Reference`], rows done, rows) after
/// each block of rows (from several threads).
pub fn reference_with_progress(
    raw: &RawStore,
    light: &[[f32; 3]],
    progress: Progress<'_>,
) -> Result<Image> {
    let dims = raw.dims();
    let m = dims.lights();
    if light.len() != m {
        return Err(RelightError::range(
            "lighting texels",
            light.len(),
            format!("6·n² = {m} for the store's n = {}", dims.face_res()),
        ));
    }
    if let Some(j) = light.iter().position(|l| l.iter().any(|v| !v.is_finite())) {
        return Err(RelightError::Invalid(format!(
            "lighting texel {j} is {:?}; values must be finite",
            light[j]
        )));
    }
    let light: Vec<[f64; 3]> = light.iter().map(|l| l.map(f64::from)).collect();
    let channels = dims.channels as usize;
    let albedo = raw.albedo();
    let header = *raw.header();
    let total = dims.pixels();
    let done = AtomicUsize::new(0);
    let mut image = Image::new(dims.width() as usize, dims.height() as usize);
    image
        .data
        .par_chunks_mut(header.block_rows as usize)
        .enumerate()
        .try_for_each(|(b, pixels)| -> Result<()> {
            raw.verify_block(b)?;
            let rows = header.block_range(b);
            // Positioned reads (an input truncated meanwhile is an error,
            // not a signal), at most `READ_BYTES` of rows at a time: the
            // block's size is a file field.
            let row_len = dims.row_len();
            let step = (READ_BYTES / (4 * row_len)).max(1);
            let mut buf = Vec::new();
            for (k, part) in pixels.chunks_mut(step).enumerate() {
                let first = rows.start + k * step;
                raw.read_rows(first..first + part.len(), &mut buf)?;
                part.par_iter_mut().enumerate().for_each(|(i, out)| {
                    let p = first + i;
                    if raw.is_zero_row(p) {
                        return;
                    }
                    let row = &buf[i * row_len..(i + 1) * row_len];
                    let mut sum = if channels == 3 {
                        dot_rgb(row, &light)
                    } else {
                        dot_grey(row, &light)
                    };
                    if let Some(a) = albedo {
                        for c in 0..3 {
                            sum[c] *= a[3 * p + c] as f64;
                        }
                    }
                    *out = sum.map(|v| v as f32);
                });
            }
            let now = done.fetch_add(rows.len(), Ordering::Relaxed) + rows.len();
            progress.report(Stage::Reference, now as u64, total as u64);
            Ok(())
        })?;
    raw.check_unchanged()?;
    if let Some((x, y)) = image.first_non_finite() {
        return Err(RelightError::Invalid(format!(
            "reference pixel ({x}, {y}) is not finite: the product T·L (or the albedo) exceeds the f32 range"
        )));
    }
    Ok(image)
}

/// `Σ_j T[j]·L[j]` for a grey row.
fn dot_grey(row: &[f32], light: &[[f64; 3]]) -> [f64; 3] {
    // Two independent accumulators per channel shorten the dependency chain.
    let mut a = [[0.0f64; 3]; 2];
    let mut pairs = row.chunks_exact(2).zip(light.chunks_exact(2));
    for (t, l) in &mut pairs {
        for k in 0..2 {
            let tv = t[k] as f64;
            for c in 0..3 {
                a[k][c] += tv * l[k][c];
            }
        }
    }
    if row.len() % 2 == 1 {
        let (t, l) = (row[row.len() - 1] as f64, light[light.len() - 1]);
        for c in 0..3 {
            a[0][c] += t * l[c];
        }
    }
    [a[0][0] + a[1][0], a[0][1] + a[1][1], a[0][2] + a[1][2]]
}

/// `Σ_j T[j, c]·L[j, c]` for an RGB row (channel-interleaved).
fn dot_rgb(row: &[f32], light: &[[f64; 3]]) -> [f64; 3] {
    let mut a = [0.0f64; 3];
    for (t, l) in row.chunks_exact(3).zip(light) {
        for c in 0..3 {
            a[c] += t[c] as f64 * l[c];
        }
    }
    a
}
