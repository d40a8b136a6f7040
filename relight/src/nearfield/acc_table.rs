//! The memory-based approach of §5.3.2: the 1D couplings tabulated over
//! quantized `(s, o)` and looked up, instead of evaluated per point.
//!
//! Haar is self-similar: source `i ≥ 1` of level `l` and offset `t` is
//! `2^{l/2}·ψ(2^l·u − t)`, so `D_ik(s, o) = 2^{l/2}·D_1k(2^l·s, 2^l·o − t)`
//! with `ψ = Φ_1` the mother wavelet. The table therefore holds the
//! couplings of two sources, the scaling function and `ψ`, to every target
//! `k < order`.
//!
//! The grid is over `(s, o)` in the coordinates that set a coupling's
//! error: the source's width on the face, `w = 1/s`, and where it starts,
//! `b₀ = −o/s` (its breaks are `b₀`, `b₀ + w/2` and `b₀ + w`).
//! - `log₂ w` in `cells` steps an octave, over
//!   `[1/(4·order), MAX_WIDTH]`;
//! - `b₀` over `(−w, 1)`, where the source touches the face, in steps of
//!   `min(w, 1)/cells`: a break moves by at most a small share of the
//!   source's width and of the face.
//!
//! A lookup takes the node at the centre of the cell that holds `(w, b₀)`:
//! the couplings of a source whose breaks moved by up to half a cell, which
//! is the table's error (measured in the tests and in
//! docs/results/nearfield.md). Sources wider than `MAX_WIDTH` faces (a
//! point closer to the plane than `MAX_WIDTH/side` of the light's size)
//! or narrower than a quarter of a target texel are evaluated in closed
//! form ([`super::acc`]).

use super::acc::{couplings, couplings_where};
use crate::error::{RelightError, Result};
use ltm_codec::{Charge, Limits};
use rayon::prelude::*;

/// The widest source the table holds, in faces (`1/s`); wider ones are
/// evaluated in closed form.
pub const MAX_WIDTH: f64 = 2.0;

/// Couplings of the scaling function and the mother wavelet at the nodes of
/// a `(w, b₀)` grid (module docs).
#[derive(Debug)]
pub struct AccTable {
    order: usize,
    cells: usize,
    /// `log₂` of the narrowest width held, and width rows an octave.
    min_log_width: f64,
    per_octave: usize,
    /// Per width row, its first node; one more at the end.
    rows: Vec<usize>,
    /// Per width row, its geometry.
    geometry: Vec<Row>,
    /// Per node and source (`node·2 + source`), the start of its entries;
    /// one more at the end.
    starts: Vec<u32>,
    targets: Vec<u16>,
    values: Vec<f32>,
    _charge: Charge,
}

/// One width row: its centre width, the upper edge of its widths, the step
/// of `b₀` and the number of nodes.
#[derive(Clone, Copy, Debug)]
struct Row {
    width: f64,
    widest: f64,
    step: f64,
    nodes: usize,
}

impl AccTable {
    /// The table for targets `k < order` (a power of two in 1..=1024) with
    /// `cells` (8..=512) steps of `b₀` a source width (or face width, the
    /// smaller), built in parallel. Its size is computed before it is built
    /// and charged to `limits`.
    pub fn new(order: usize, cells: usize, limits: &Limits) -> Result<AccTable> {
        if !order.is_power_of_two() || order > 1024 {
            let valid = "a power of two in 1..=1024";
            return Err(RelightError::range("coupling table order", order, valid));
        }
        if !(8..=512).contains(&cells) {
            let valid = "8..=512 a width";
            return Err(RelightError::range("coupling table cells", cells, valid));
        }
        let min_log_width = -((4 * order) as f64).log2();
        let per_octave = cells;
        let octaves = MAX_WIDTH.log2() - min_log_width;
        let count = (octaves * per_octave as f64).ceil() as usize;
        let geometry: Vec<Row> = (0..count)
            .map(|q| row(min_log_width, per_octave, cells, q))
            .collect();
        let mut rows = Vec::with_capacity(count + 1);
        let mut nodes = 0usize;
        for g in &geometry {
            rows.push(nodes);
            nodes += g.nodes;
        }
        rows.push(nodes);
        let levels = order.trailing_zeros() as usize;
        // At most 1 + 3·levels targets per source, 6 bytes each, and a
        // start per node and source; the starts are u32.
        let entries = nodes as u64 * 2 * (1 + 3 * levels) as u64;
        if entries > u64::from(u32::MAX) {
            return Err(RelightError::Invalid(format!(
                "a coupling table of order {order} and {cells} cells would hold up to {entries} couplings, more than {}: use fewer cells",
                u32::MAX
            )));
        }
        let most = entries * 6 + 8 * nodes as u64;
        let charge = limits.check_alloc("coupling table", most, 1)?;
        let built: Vec<(Vec<u32>, Vec<u16>, Vec<f32>)> = (0..count)
            .into_par_iter()
            .map(|q| node_row(order, geometry[q]))
            .collect();
        let mut starts = Vec::with_capacity(nodes * 2 + 1);
        let (mut targets, mut values) = (Vec::new(), Vec::new());
        for (lengths, k, d) in built {
            let mut at = targets.len() as u32;
            for length in lengths {
                starts.push(at);
                at += length;
            }
            targets.extend(k);
            values.extend(d);
        }
        starts.push(targets.len() as u32);
        Ok(AccTable {
            order,
            cells,
            min_log_width,
            per_octave,
            rows,
            geometry,
            starts,
            targets,
            values,
            _charge: charge,
        })
    }
}

/// Width row `q` of a grid.
fn row(min_log_width: f64, per_octave: usize, cells: usize, q: usize) -> Row {
    let log = |x: f64| (min_log_width + x / per_octave as f64).exp2();
    let (width, widest) = (log(q as f64 + 0.5), log(q as f64 + 1.0));
    let step = width.min(1.0) / cells as f64;
    Row {
        width,
        widest,
        step,
        nodes: ((1.0 + widest) / step).ceil() as usize,
    }
}

/// One width row's nodes: each node's two entry counts (scaling function,
/// mother wavelet), then their targets and values. Node `r` starts at
/// `b₀ = −widest + (r + ½)·step`.
fn node_row(order: usize, row: Row) -> (Vec<u32>, Vec<u16>, Vec<f32>) {
    let mut lengths = Vec::with_capacity(2 * row.nodes);
    let (mut targets, mut values) = (Vec::new(), Vec::new());
    let mut list = Vec::new();
    let s = 1.0 / row.width;
    for r in 0..row.nodes {
        let b0 = -row.widest + (r as f64 + 0.5) * row.step;
        for source in 0..2 {
            list.clear();
            couplings(source, order, s, -b0 * s, &mut list);
            lengths.push(list.len() as u32);
            targets.extend(list.iter().map(|&(k, _)| k as u16));
            values.extend(list.iter().map(|&(_, d)| d as f32));
        }
    }
    (lengths, targets, values)
}

impl AccTable {
    /// The targets' order.
    pub fn order(&self) -> usize {
        self.order
    }

    /// Steps of `b₀` a width.
    pub fn cells(&self) -> usize {
        self.cells
    }

    /// The nodes of the grid.
    pub fn nodes(&self) -> usize {
        self.rows.last().copied().unwrap_or(0)
    }

    /// Stored couplings (both sources, every node).
    pub fn entries(&self) -> usize {
        self.targets.len()
    }

    /// Bytes held: two bytes of target and four of value an entry, four of
    /// start a node and source, 40 a width row.
    pub fn bytes(&self) -> usize {
        6 * self.targets.len() + 4 * self.starts.len() + 40 * self.rows.len()
    }

    /// The node that holds `(s, o)`: `None` when the source's width is
    /// outside the grid, `Some(None)` when it misses `[0, 1)` (every
    /// coupling is 0).
    fn cell(&self, s: f64, o: f64) -> Option<Option<usize>> {
        let width = 1.0 / s;
        let u = (width.log2() - self.min_log_width) * self.per_octave as f64;
        let q = u as usize;
        if !(u >= 0.0 && q + 1 < self.rows.len()) {
            return None;
        }
        let b0 = -o / s;
        if !(b0 < 1.0 && b0 + width > 0.0) {
            return Some(None);
        }
        let geometry = self.geometry[q];
        let r = (((b0 + geometry.widest) / geometry.step) as usize).min(geometry.nodes - 1);
        Some(Some(self.rows[q] + r))
    }

    /// Appends the couplings `(k, D_ik(s, o))` of source `i` to the targets
    /// where `wanted(k)` holds, in increasing `k`: looked up at the nearest
    /// node, or evaluated exactly where the source's width is outside the
    /// grid. `s > 0`
    /// and `o` finite (the caller checks).
    pub fn couplings_where(
        &self,
        i: usize,
        s: f64,
        o: f64,
        wanted: impl Fn(usize) -> bool,
        out: &mut Vec<(u32, f64)>,
    ) {
        let (source, amplitude, s1, o1) = if i == 0 {
            (0, 1.0, s, o)
        } else {
            let level = usize::BITS - 1 - i.leading_zeros();
            let scale = (1u64 << level) as f64;
            let offset = (i - (1usize << level)) as f64;
            (
                1,
                (0.5 * f64::from(level)).exp2(),
                scale * s,
                scale * o - offset,
            )
        };
        match self.cell(s1, o1) {
            None => couplings_where(i, self.order, s, o, wanted, out),
            Some(None) => {}
            Some(Some(node)) => {
                let at = node * 2 + source;
                let (a, b) = (self.starts[at] as usize, self.starts[at + 1] as usize);
                for (&k, &d) in self.targets[a..b].iter().zip(&self.values[a..b]) {
                    if wanted(k as usize) {
                        out.push((u32::from(k), amplitude * f64::from(d)));
                    }
                }
            }
        }
    }
}
