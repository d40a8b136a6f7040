//! A file's near-field rows laid out for the wavelet method's shading
//! (`B = Σ_k L_k·T_k`, eq. 30): per row, its coefficients' increasing
//! indices with one value each, and where each band `k_y` starts, so that
//! only the bands the incident light reaches are read. An RGB file's three
//! channel rows are merged into one list with an RGB value per index (0
//! where a channel has no coefficient): one 4-wide multiply-add a
//! coefficient for the three channels.

use super::propagate::{band_starts, Propagator};
use crate::error::{RelightError, Result};
use ltm_codec::{Charge, Limits, PlaneRows};
use rayon::prelude::*;

/// The values of [`ShadingRows`]: one per coefficient of a grey row, or a
/// channel a lane of an RGB row.
#[derive(Debug)]
enum RowValues {
    Grey(Vec<f32>),
    Rgb(Vec<[f32; 3]>),
}

/// Near-field rows for the wavelet method's shading (module docs).
#[derive(Debug)]
pub(super) struct ShadingRows {
    order: usize,
    /// Per row, its first coefficient; one more at the end.
    starts: Vec<usize>,
    indices: Vec<u16>,
    values: RowValues,
    /// Per row, where each band `k_y` starts in it (`order` each).
    bands: Vec<u32>,
    _charge: Charge,
}

impl ShadingRows {
    /// The layout of `rows`, charged to `limits` before it is built: 6 bytes
    /// a coefficient of a grey row, 14 an index of an RGB row's merged
    /// list, and `4·order` a row for its bands.
    pub(super) fn new(rows: &PlaneRows, limits: &Limits) -> Result<ShadingRows> {
        let order = rows.basis().order as usize;
        let (count, channels) = (rows.rows(), rows.channels());
        let lengths: Vec<usize> = (0..count)
            .into_par_iter()
            .map(|p| match channels {
                1 => rows.row(p, 0).0.len(),
                _ => merged_len([0, 1, 2].map(|c| rows.row(p, c).0)),
            })
            .collect();
        let total: usize = lengths.iter().sum();
        let value_bytes = if channels == 1 { 4 } else { 12 };
        let bytes = total as u64 * (2 + value_bytes) + (count as u64) * (8 + 4 * order as u64);
        let charge = limits.check_alloc("near-field shading rows", bytes, 1)?;
        let mut starts = Vec::with_capacity(count + 1);
        starts.push(0);
        for &n in &lengths {
            starts.push(starts[starts.len() - 1] + n);
        }
        let mut indices = Vec::with_capacity(total);
        let values = match channels {
            1 => {
                let mut values = Vec::with_capacity(total);
                for p in 0..count {
                    let (k, v) = rows.row(p, 0);
                    indices.extend_from_slice(k);
                    values.extend_from_slice(v);
                }
                RowValues::Grey(values)
            }
            3 => {
                let mut values = Vec::with_capacity(total);
                for p in 0..count {
                    merge(rows, p, &mut indices, &mut values);
                }
                RowValues::Rgb(values)
            }
            _ => {
                let valid = "1 or 3";
                return Err(RelightError::range("near-field channels", channels, valid));
            }
        };
        let mut bands = vec![0u32; count * order];
        bands
            .par_chunks_mut(order.max(1))
            .enumerate()
            .for_each(|(p, out)| band_starts(&indices[starts[p]..starts[p + 1]], order, out));
        Ok(ShadingRows {
            order,
            starts,
            indices,
            values,
            bands,
            _charge: charge,
        })
    }

    /// Row `p`'s RGB radiance under the light `propagator` prepared for its
    /// point: a grey row under each channel of the light, an RGB row's
    /// channel under that channel; 0 for a row past the end.
    pub(super) fn shade(&self, propagator: &Propagator, p: usize) -> [f64; 3] {
        let (Some(&a), Some(&b)) = (self.starts.get(p), self.starts.get(p + 1)) else {
            return [0.0; 3];
        };
        let indices = &self.indices[a..b];
        let bands = self
            .bands
            .get(p * self.order..(p + 1) * self.order)
            .unwrap_or(&[]);
        match &self.values {
            RowValues::Grey(values) => propagator.shade_bands(indices, &values[a..b], bands),
            RowValues::Rgb(values) => propagator.shade_rgb_bands(indices, &values[a..b], bands),
        }
    }
}

/// The number of distinct indices of three increasing lists.
fn merged_len(lists: [&[u16]; 3]) -> usize {
    let mut at = [0usize; 3];
    let mut count = 0;
    while let Some(k) = next_index(&lists, &at) {
        for (i, list) in lists.iter().enumerate() {
            if list.get(at[i]) == Some(&k) {
                at[i] += 1;
            }
        }
        count += 1;
    }
    count
}

/// The smallest index not yet taken from the lists.
fn next_index(lists: &[&[u16]; 3], at: &[usize; 3]) -> Option<u16> {
    (0..3).filter_map(|i| lists[i].get(at[i]).copied()).min()
}

/// Appends row `p`'s three channel lists merged: each distinct index once,
/// with the channels' values (0 where a channel lacks it).
fn merge(rows: &PlaneRows, p: usize, indices: &mut Vec<u16>, values: &mut Vec<[f32; 3]>) {
    let channel = [0, 1, 2].map(|c| rows.row(p, c));
    let lists = channel.map(|(k, _)| k);
    let mut at = [0usize; 3];
    while let Some(k) = next_index(&lists, &at) {
        let mut value = [0.0f32; 3];
        for (c, (list, v)) in channel.iter().enumerate() {
            if list.get(at[c]) == Some(&k) {
                value[c] = v[at[c]];
                at[c] += 1;
            }
        }
        indices.push(k);
        values.push(value);
    }
}
