//! A file's near-field rows laid out for the wavelet method's shading
//! (`B = Σ_k L_k·T_k`, eq. 30): per row, its coefficients' increasing
//! indices with one value each, and where each band `k_y` starts, so that
//! only the bands the incident light reaches are read. An RGB file's three
//! channel rows are merged into one list with an RGB value per index (0
//! where a channel has no coefficient): one 4-wide multiply-add a
//! coefficient for the three channels. Where the three are the same list
//! (a grey surface), the row is held once, as a grey file's.

use super::propagate::{band_starts, Propagator};
use crate::error::{RelightError, Result};
use ltm_codec::{Charge, Limits, PlaneRows};
use rayon::prelude::*;

/// Near-field rows for the wavelet method's shading (module docs).
#[derive(Debug)]
pub(super) struct ShadingRows {
    order: usize,
    /// Per row, its first coefficient; one more at the end.
    starts: Vec<usize>,
    indices: Vec<u16>,
    /// Per row, whether it is held in RGB, and where its values start: in
    /// `grey` (a grey file's rows, and an RGB file's rows whose three
    /// channels are the same list) or in `rgb`.
    values_at: Vec<(bool, usize)>,
    grey: Vec<f32>,
    rgb: Vec<[f32; 3]>,
    /// Per row, where each band `k_y` starts in it (`order` each).
    bands: Vec<u32>,
    _charge: Charge,
}

impl ShadingRows {
    /// The layout of `rows`, charged to `limits` before it is built: 6 bytes
    /// a coefficient of a grey row, 14 an index of an RGB row's merged
    /// list, and `4·order + 24` a row for its bands and offsets.
    pub(super) fn new(rows: &PlaneRows, limits: &Limits) -> Result<ShadingRows> {
        let order = rows.basis().order as usize;
        let (count, channels) = (rows.rows(), rows.channels());
        if channels != 1 && channels != 3 {
            return Err(RelightError::range(
                "near-field channels",
                channels,
                "1 or 3",
            ));
        }
        // Per row: coefficients, and whether it needs RGB values.
        let shapes: Vec<(usize, bool)> = (0..count)
            .into_par_iter()
            .map(|p| match channels {
                1 => (rows.row(p, 0).0.len(), false),
                _ if same_channels(rows, p) => (rows.row(p, 0).0.len(), false),
                _ => (merged_len([0, 1, 2].map(|c| rows.row(p, c).0)), true),
            })
            .collect();
        let total: usize = shapes.iter().map(|s| s.0).sum();
        let colour: usize = shapes.iter().filter(|s| s.1).map(|s| s.0).sum();
        let bytes = (total * 6 + colour * 8) as u64 + count as u64 * (24 + 4 * order as u64);
        let charge = limits.check_alloc("near-field shading rows", bytes, 1)?;
        let mut starts = Vec::with_capacity(count + 1);
        let mut values_at = Vec::with_capacity(count);
        let mut indices = Vec::with_capacity(total);
        let (mut grey, mut rgb) = (
            Vec::with_capacity(total - colour),
            Vec::with_capacity(colour),
        );
        for (p, &(_, in_rgb)) in shapes.iter().enumerate() {
            starts.push(indices.len());
            if in_rgb {
                values_at.push((true, rgb.len()));
                merge(rows, p, &mut indices, &mut rgb);
            } else {
                values_at.push((false, grey.len()));
                let (k, v) = rows.row(p, 0);
                indices.extend_from_slice(k);
                grey.extend_from_slice(v);
            }
        }
        starts.push(indices.len());
        let mut bands = vec![0u32; count * order];
        bands
            .par_chunks_mut(order.max(1))
            .enumerate()
            .for_each(|(p, out)| band_starts(&indices[starts[p]..starts[p + 1]], order, out));
        Ok(ShadingRows {
            order,
            starts,
            indices,
            values_at,
            grey,
            rgb,
            bands,
            _charge: charge,
        })
    }

    /// Row `p`'s RGB radiance under the light `propagator` prepared for its
    /// point: a grey row under each channel of the light, an RGB row's
    /// channel under that channel; 0 for a row past the end.
    pub(super) fn shade(&self, propagator: &Propagator, p: usize) -> [f64; 3] {
        let (Some(&a), Some(&b), Some(&(in_rgb, v))) = (
            self.starts.get(p),
            self.starts.get(p + 1),
            self.values_at.get(p),
        ) else {
            return [0.0; 3];
        };
        let indices = &self.indices[a..b];
        let bands = self
            .bands
            .get(p * self.order..(p + 1) * self.order)
            .unwrap_or(&[]);
        let n = b - a;
        match in_rgb {
            false => propagator.shade_bands(indices, self.grey.get(v..v + n).unwrap_or(&[]), bands),
            true => {
                propagator.shade_rgb_bands(indices, self.rgb.get(v..v + n).unwrap_or(&[]), bands)
            }
        }
    }
}

/// Whether row `p`'s three channels are the same list (a grey surface of
/// an RGB file: its colour is in the light alone).
fn same_channels(rows: &PlaneRows, p: usize) -> bool {
    let first = rows.row(p, 0);
    (1..3).all(|c| rows.row(p, c) == first)
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
