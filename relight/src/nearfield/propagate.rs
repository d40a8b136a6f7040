//! Light propagation per receiving point (eq. 30), separable in two steps
//! (§5.3.1), with target-level selection from a constant-light prediction
//! (eq. 32), and the per-row shading `B = Σ_k L_k·T_k`.

use super::acc::{amplitude, couplings_where, inverse_power_of_two};
use super::acc_table::AccTable;
use super::light::{Placement, SourceCoefficients};
use crate::error::{RelightError, Result};
use std::sync::Arc;

/// The default side of the expanded top face in tangent units (§5.2.1: a
/// standard cube face is 2; 3 or 4 suffice).
pub const DEFAULT_FACE_SIDE: f64 = 4.0;

/// Scales below this are raised to it: a point this close to the light
/// plane sees one texel of the light over the whole face.
pub const MIN_SCALE: f64 = 1e-9;

/// The expanded top face: `order × order` texels over tangent coordinates
/// `v ∈ [−side/2, side/2]²`, aligned with the light plane (axis x of the
/// face along the plane's x). Direction `v` is `(v_x, v_y, 1)` in the
/// plane's frame, `1` along the normal from the point towards the plane.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlaneFace {
    /// Texels per side, a power of two in 1..=1024.
    pub order: usize,
    /// Side in tangent units, finite and > 0.
    pub side: f64,
}

impl PlaneFace {
    /// Refuses an order that is not a power of two in 1..=1024 and a side
    /// that is not finite and > 0.
    pub fn check(&self) -> Result<()> {
        if !self.order.is_power_of_two() || self.order > 1024 {
            let valid = "a power of two in 1..=1024";
            return Err(RelightError::range("near-field order", self.order, valid));
        }
        if !(self.side.is_finite() && self.side > 0.0) {
            return Err(RelightError::range(
                "face side",
                self.side,
                "finite and > 0",
            ));
        }
        Ok(())
    }
}

/// A receiving point in the light plane's frame: its distance in front of
/// the plane along the normal (> 0 to be lit) and its position in the
/// plane's coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Receiver {
    /// Distance to the plane; 0 or less means behind it: no light.
    pub depth: f64,
    /// `(x, y)` in the plane.
    pub position: [f64; 2],
}

/// Which target coefficients `L_k` are computed.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub enum Targets {
    /// Every coefficient.
    All,
    /// This share (0..=1) of the `order²` coefficients, the largest under a
    /// constant light of the same rectangle (eq. 32).
    Share(f64),
}

/// The affine map of one face axis onto the light's texture axis:
/// `u = scale·w + offset` for face coordinate `w ∈ [0, 1)` (eq. 29).
pub fn affine(face: &PlaneFace, placement: &Placement, receiver: &Receiver) -> [(f64, f64); 2] {
    std::array::from_fn(|a| {
        let size = placement.size[a];
        let scale = (receiver.depth * face.side / size).max(MIN_SCALE);
        let offset = (receiver.position[a] - placement.center[a]) / size + 0.5 - 0.5 * scale;
        (scale, offset)
    })
}

/// Per-point propagation state, reused point after point.
#[derive(Debug)]
pub struct Propagator {
    face: PlaneFace,
    /// Couplings looked up here (§5.3.2's memory-based approach) instead of
    /// evaluated in closed form.
    table: Option<Arc<AccTable>>,
    /// Step 1's `Z[i_y][k_x]`, RGB and a zero lane (one 4-wide vector),
    /// `i_y` major: `axis[1].len() × order`.
    partial: Vec<Rgb4>,
    /// Per axis, whether any coupling reached target `k` (step 1's `k_x`,
    /// the axis-y lists' `k_y`): the other targets are zero.
    touched: [Vec<bool>; 2],
    /// Per axis, the targets that can be selected: all, or under
    /// [`Targets::Share`] those whose prediction times the other axis's
    /// largest reaches the threshold. Couplings to others are not computed.
    wanted: [Vec<bool>; 2],
    /// Per axis, the scaling function's couplings `D_{0 k}` to every
    /// target: the prediction's, and source 0's in both steps.
    scaling: [Vec<(u32, f64)>; 2],
    /// Whether `scaling` holds this point's lists (computed only when the
    /// selection can prune).
    scaling_ready: bool,
    /// The constant light's `|D_{0 k}|` per axis, `order` each, and their
    /// nonzero values.
    prediction: [Vec<f64>; 2],
    nonzero: [Vec<f64>; 2],
    /// Targets whose predicted product is below this are skipped; 0 keeps
    /// all.
    threshold: f64,
    /// The point's incident coefficients `L_k`, dense (`order²`): zero
    /// outside the box of `candidates`, which the next point clears.
    incident: Vec<Rgb4>,
    /// Per axis, the targets reached by a coupling, increasing.
    candidates: [Vec<u32>; 2],
    products: Vec<f64>,
    list: Vec<(u32, f64)>,
    starts: Vec<usize>,
    /// The last source's [`SourceCoefficients::scale`]: `incident` holds the
    /// light's coefficients divided by it.
    scale: f64,
}

impl Propagator {
    /// A propagator for `face`.
    pub fn new(face: PlaneFace) -> Result<Propagator> {
        face.check()?;
        let order = face.order;
        Ok(Propagator {
            face,
            table: None,
            partial: Vec::new(),
            touched: [vec![false; order], vec![false; order]],
            wanted: [vec![true; order], vec![true; order]],
            scaling: [Vec::new(), Vec::new()],
            scaling_ready: false,
            prediction: [vec![0.0; order], vec![0.0; order]],
            nonzero: [Vec::new(), Vec::new()],
            threshold: 0.0,
            incident: vec![[0.0; 4]; order * order],
            candidates: [Vec::new(), Vec::new()],
            products: Vec::new(),
            list: Vec::new(),
            starts: Vec::new(),
            scale: 1.0,
        })
    }

    /// A propagator for `face` that looks its couplings up in `table`
    /// (nearest node; see [`AccTable`]): refuses a table of another order.
    pub fn with_table(face: PlaneFace, table: Arc<AccTable>) -> Result<Propagator> {
        if table.order() != face.order {
            let valid = format!("{}, the face's order", face.order);
            return Err(RelightError::range(
                "coupling table order",
                table.order(),
                valid,
            ));
        }
        let mut propagator = Propagator::new(face)?;
        propagator.table = Some(table);
        Ok(propagator)
    }

    /// Propagates `source` to `receiver` (steps 1 and 2's couplings) and
    /// selects the targets. Returns false, and shades to zero, when the
    /// point is not in front of the plane. The light's centre and size are
    /// read from `placement`, so a moved or resized light needs no new
    /// source; its intensity is the one `source` was made with.
    pub fn prepare(
        &mut self,
        source: &SourceCoefficients,
        placement: &Placement,
        receiver: &Receiver,
        targets: Targets,
    ) -> Result<bool> {
        self.clear_incident();
        placement.check()?;
        let order = self.face.order;
        if source.order != order {
            let valid = format!("{order}, the face's order");
            return Err(RelightError::range("source order", source.order, valid));
        }
        if !(receiver.depth.is_finite() && receiver.position.iter().all(|v| v.is_finite())) {
            return Err(RelightError::Invalid(format!(
                "receiver at depth {} and position {:?} is not finite",
                receiver.depth, receiver.position
            )));
        }
        if receiver.depth <= 0.0 {
            return Ok(false);
        }
        let [(sx, ox), (sy, oy)] = affine(&self.face, placement, receiver);
        self.scale = source.scale;
        self.select(targets, [(sx, ox), (sy, oy)]);
        self.step_one(source, (sx, ox));
        self.axis_couplings(1, &source.axis[1], (sy, oy));
        self.step_two();
        Ok(true)
    }

    /// Zeroes the previous point's incident coefficients (the box of its
    /// candidates) and forgets its candidates.
    fn clear_incident(&mut self) {
        let order = self.face.order;
        let [xs, ys] = &mut self.candidates;
        for &ky in ys.iter() {
            let row = &mut self.incident[ky as usize * order..][..order];
            xs.iter().for_each(|&kx| row[kx as usize] = [0.0; 4]);
        }
        xs.clear();
        ys.clear();
    }

    /// The couplings of each of `sources` on `axis` to its wanted targets,
    /// concatenated in `list` (source `j`'s at `starts[j]..starts[j + 1]`),
    /// and the targets reached marked in `touched`.
    fn axis_couplings(&mut self, axis: usize, sources: &[u32], (s, o): (f64, f64)) {
        let order = self.face.order;
        self.list.clear();
        self.starts.clear();
        let (table, wanted) = (self.table.as_deref(), &self.wanted[axis]);
        for &i in sources {
            self.starts.push(self.list.len());
            if i == 0 && self.scaling_ready {
                let scaling = self.scaling[axis].iter();
                self.list
                    .extend(scaling.filter(|&&(k, _)| wanted[k as usize]));
                continue;
            }
            couple(
                table,
                (i as usize, order),
                (s, o),
                |k| wanted[k],
                &mut self.list,
            );
        }
        self.starts.push(self.list.len());
        self.touched[axis].fill(false);
        for &(k, _) in &self.list {
            self.touched[axis][k as usize] = true;
        }
    }

    /// Step 1: `Z[i_y][k_x] = Σ_{i_x} F[i_x, i_y]·D_{i_x k_x}(s_x, o_x)`.
    /// In closed form it is a sum over the merged breaks of the kept terms'
    /// axis-x functions ([`SourceCoefficients`]): by
    /// [`couplings_where`]'s step form, a break at `b` with weight `w` adds
    /// `w·E_k(b)` to the one target a level whose support holds it, and
    /// `w·(1 − b)` to the scaling target (`w` when `b ≤ 0`). Through a
    /// coupling table, or for sources narrower than half a finest texel,
    /// it is summed coupling list by coupling list.
    fn step_one(&mut self, source: &SourceCoefficients, (s, o): (f64, f64)) {
        let order = self.face.order;
        self.partial.clear();
        self.partial.resize(source.axis[1].len() * order, [0.0; 4]);
        if self.table.is_some() || s > 2.0 * order as f64 {
            return self.step_one_by_lists(source, (s, o));
        }
        self.touched[0].fill(false);
        let inverse = 1.0 / s;
        let levels = order.trailing_zeros() as usize;
        let ys = source.axis[1].len();
        // The breaks before the face set the value at 0.
        let first = source
            .breaks
            .partition_point(|(u, _)| (u - o) * inverse <= 0.0);
        if first > 0 && self.wanted[0][0] {
            let before = &source.before[(first - 1) * ys..][..ys];
            for (iy, v) in before.iter().enumerate() {
                if v.iter().any(|&v| v != 0.0) {
                    self.touched[0][0] = true;
                    let z = &mut self.partial[iy * order];
                    (0..4).for_each(|c| z[c] += v[c]);
                }
            }
        }
        for (u, range) in &source.breaks[first..] {
            let b = (u - o) * inverse;
            if b >= 1.0 {
                // Breaks are increasing: the rest are past the face too.
                break;
            }
            let weights = &source.weights[range.clone()];
            self.add_break(weights, 0, 1.0 - b);
            let finest = ((b * order as f64) as usize).min(order - 1);
            for level in 0..levels {
                let t = finest >> (levels - level);
                let width = inverse_power_of_two(level);
                let x0 = t as f64 * width;
                let (left, right) = (b - x0, x0 + width - b);
                let e = -amplitude(level) * if left < right { left } else { right };
                self.add_break(weights, (1 << level) + t, e);
            }
        }
    }

    /// Adds `e·w` to `Z[i_y][k]` for each `(i_y, w)` of a break's weights,
    /// and marks `k` reached, unless `e` is 0 or `k` is not wanted.
    #[inline]
    fn add_break(&mut self, weights: &[(u32, Rgb4)], k: usize, e: f64) {
        if e == 0.0 || !self.wanted[0][k] {
            return;
        }
        self.touched[0][k] = true;
        let order = self.face.order;
        let e = e as f32;
        for &(iy, w) in weights {
            let z = &mut self.partial[iy as usize * order + k];
            for c in 0..4 {
                z[c] += w[c] * e;
            }
        }
    }

    /// [`Propagator::step_one`] from each axis-x source's coupling list.
    fn step_one_by_lists(&mut self, source: &SourceCoefficients, (s, o): (f64, f64)) {
        let order = self.face.order;
        self.axis_couplings(0, &source.axis[0], (s, o));
        let starts = &self.starts;
        for &(ix, iy, f) in &source.terms {
            let ix = ix as usize;
            let iy = iy as usize;
            let f = [f[0] as f32, f[1] as f32, f[2] as f32, 0.0];
            for &(k, d) in &self.list[starts[ix]..starts[ix + 1]] {
                let z = &mut self.partial[iy * order + k as usize];
                let d = d as f32;
                for c in 0..4 {
                    z[c] += f[c] * d;
                }
            }
        }
    }

    /// The selection of [`Targets::Share`]: `k` is computed when the
    /// constant light's `|D_{0 k_x}·D_{0 k_y}|` reaches the threshold. At
    /// most `(1 + 2·log₂ order)²` products are nonzero (the scaling
    /// function has two breaks), so only those are ranked; a share past
    /// their bound, or past their number, keeps every target.
    fn select(&mut self, targets: Targets, axes: [(f64, f64); 2]) {
        let order = self.face.order;
        self.threshold = 0.0;
        self.scaling_ready = false;
        self.wanted.iter_mut().for_each(|w| w.fill(true));
        let share = match targets {
            Targets::Share(share) if share < 1.0 => share.max(0.0),
            _ => return,
        };
        let count = ((share * (order * order) as f64).ceil() as usize).clamp(1, order * order);
        // The scaling function's two breaks reach at most one target a
        // level and break, and the scaling target.
        let reach = 1 + 2 * order.trailing_zeros() as usize;
        if count > reach * reach {
            return;
        }
        for (scaling, axis) in self.scaling.iter_mut().zip(axes) {
            scaling.clear();
            couple(self.table.as_deref(), (0, order), axis, |_| true, scaling);
        }
        self.scaling_ready = true;
        for a in 0..2 {
            self.prediction[a].fill(0.0);
            self.nonzero[a].clear();
            for &(k, d) in &self.scaling[a] {
                self.prediction[a][k as usize] = d.abs();
                self.nonzero[a].push(d.abs());
            }
        }
        let [xs, ys] = &self.nonzero;
        if count > xs.len() * ys.len() {
            return;
        }
        self.products.clear();
        self.products
            .extend(ys.iter().flat_map(|y| xs.iter().map(move |x| x * y)));
        let (_, nth, _) = self
            .products
            .select_nth_unstable_by(count - 1, |a, b| b.total_cmp(a));
        self.threshold = *nth;
        for a in 0..2 {
            let most = self.nonzero[1 - a].iter().copied().fold(0.0, f64::max);
            for (w, &p) in self.wanted[a].iter_mut().zip(&self.prediction[a]) {
                *w = p * most >= self.threshold;
            }
        }
    }

    /// Step 2 for the selected targets: `L_k = Σ_{i_y} Z[i_y][k_x]·D_{i_y k_y}`
    /// over the box of the `k_x` and `k_y` reached by a coupling (other
    /// targets are zero), summed coupling by coupling of the axis-y list
    /// (`list`, source `i_y`'s at `starts`); then, under
    /// [`Targets::Share`], the targets whose constant-light product is below
    /// the threshold are zeroed.
    fn step_two(&mut self) {
        let order = self.face.order;
        for (candidates, touched) in self.candidates.iter_mut().zip(&self.touched) {
            candidates.extend((0..order as u32).filter(|&k| touched[k as usize]));
        }
        let xs = &self.candidates[0];
        for (iy, range) in self.starts.windows(2).enumerate() {
            let z = &self.partial[iy * order..][..order];
            for &(ky, d) in &self.list[range[0]..range[1]] {
                let d = d as f32;
                let row = &mut self.incident[ky as usize * order..][..order];
                for &kx in xs {
                    let (l, z) = (&mut row[kx as usize], z[kx as usize]);
                    for c in 0..4 {
                        l[c] += z[c] * d;
                    }
                }
            }
        }
        let threshold = self.threshold;
        if threshold > 0.0 {
            // A target was reached only if it was wanted (`select`), so
            // under a threshold its prediction is nonzero.
            for &ky in &self.candidates[1] {
                let py = self.prediction[1][ky as usize];
                let row = &mut self.incident[ky as usize * order..][..order];
                for &kx in xs {
                    if self.prediction[0][kx as usize] * py < threshold {
                        row[kx as usize] = [0.0; 4];
                    }
                }
            }
        }
    }

    /// Whether the last point's selection pruned targets (a threshold
    /// above 0).
    #[cfg(test)]
    pub(super) fn pruned(&self) -> bool {
        self.threshold > 0.0
    }

    /// The incident lighting's coefficient `L_k` (`k = k_y·order + k_x`),
    /// zero when not selected or not lit.
    pub fn coefficient(&self, k: usize) -> [f64; 3] {
        let l = self.incident.get(k).copied().unwrap_or([0.0; 4]);
        std::array::from_fn(|c| f64::from(l[c]) * self.scale)
    }

    /// Every coefficient of the incident lighting, `order²` (dense; for tests
    /// and figures).
    pub fn incident(&self) -> Vec<[f64; 3]> {
        let order = self.face.order;
        (0..order * order).map(|k| self.coefficient(k)).collect()
    }

    /// `B = Σ_k L_k·T_k` over a transport row's nonzero Haar coefficients
    /// `(k, T_k)` (see [`transport_coefficients`]).
    pub fn shade(&self, transport: &[(u32, f32)]) -> [f64; 3] {
        self.shade_terms(transport.iter().map(|&(k, t)| (k as usize, t)))
    }

    /// [`Propagator::shade`] of a row held as parallel lists of indices and
    /// values (as [`ltm_codec::PlaneRows::row`] gives them).
    pub fn shade_indexed(&self, indices: &[u16], values: &[f32]) -> [f64; 3] {
        let b = four_sums(indices, values, &self.incident);
        std::array::from_fn(|c| f64::from(b[c]) * self.scale)
    }

    /// [`Propagator::shade_indexed`] of a row whose band `k_y` (the
    /// indices `k_y·order..(k_y + 1)·order`) starts at `bands[k_y]`
    /// ([`band_starts`]): only the bands that the incident light reaches are
    /// read, about two fifths of a 256² frame's stored coefficients.
    /// Starts past the row read nothing.
    pub fn shade_bands(&self, indices: &[u16], values: &[f32], bands: &[u32]) -> [f64; 3] {
        self.banded(indices, values, bands, |t| [t; 4])
    }

    /// [`Propagator::shade_bands`] of an RGB row held as one list: each
    /// index with its three channels' values; channel `c` of the result is
    /// the row's channel `c` under the light's.
    pub fn shade_rgb_bands(&self, indices: &[u16], values: &[[f32; 3]], bands: &[u32]) -> [f64; 3] {
        self.banded(indices, values, bands, |v| [v[0], v[1], v[2], 0.0])
    }

    fn banded<V: Copy>(
        &self,
        indices: &[u16],
        values: &[V],
        bands: &[u32],
        lanes_of: impl Fn(V) -> Rgb4 + Copy,
    ) -> [f64; 3] {
        let n = indices.len().min(values.len());
        let start = |ky: usize| bands.get(ky).map_or(n, |&s| (s as usize).min(n));
        let mut lanes = [[0.0f32; 4]; 4];
        // The light is nonzero only in the box of step 2's candidates; runs
        // of consecutive candidate bands are one range of the row.
        let ys = &self.candidates[1];
        let mut r = 0;
        while r < ys.len() {
            let first = ys[r] as usize;
            let mut last = first;
            while r + 1 < ys.len() && ys[r + 1] as usize == last + 1 {
                last += 1;
                r += 1;
            }
            r += 1;
            let (a, b) = (start(first), start(last + 1));
            if a < b {
                let (k, v) = (&indices[a..b], &values[a..b]);
                add_four_sums(k, v, &self.incident, &mut lanes, lanes_of);
            }
        }
        std::array::from_fn(|c| {
            f64::from((lanes[0][c] + lanes[1][c]) + (lanes[2][c] + lanes[3][c])) * self.scale
        })
    }

    fn shade_terms(&self, terms: impl Iterator<Item = (usize, f32)>) -> [f64; 3] {
        let mut sum = [0.0f64; 3];
        for (k, t) in terms {
            let l = self.coefficient(k);
            for c in 0..3 {
                sum[c] += l[c] * f64::from(t);
            }
        }
        sum
    }
}

/// Where each band `k_y` of a row's increasing indices starts (indices
/// `k_y·order..(k_y + 1)·order`), into `out` (`order` starts, for
/// [`Propagator::shade_bands`]).
pub fn band_starts(indices: &[u16], order: usize, out: &mut [u32]) {
    let mut at = 0;
    for (ky, start) in out.iter_mut().enumerate() {
        let first = ky * order;
        at += indices[at..].partition_point(|&k| usize::from(k) < first);
        *start = at as u32;
    }
}

/// An RGB value and a zero lane: one 4-wide vector.
pub(super) type Rgb4 = [f32; 4];

/// `Σ light[k]·t` over a row's parallel lists of indices `k` and values `t`,
/// in four running sums, so that the additions do not wait on each other.
/// An index past `light` adds nothing.
/// The sums are f32, one 4-wide vector a term, about 1.1 times faster than
/// f64 sums on the 256² frames; `shade_indexed` is tested against the f64
/// [`Propagator::shade`] relative to the terms' magnitudes.
fn four_sums(indices: &[u16], values: &[f32], light: &[Rgb4]) -> Rgb4 {
    let mut lanes = [[0.0f32; 4]; 4];
    add_four_sums(indices, values, light, &mut lanes, |t| [t; 4]);
    std::array::from_fn(|c| (lanes[0][c] + lanes[1][c]) + (lanes[2][c] + lanes[3][c]))
}

/// [`four_sums`] added to running `lanes`, of values whose lanes multiply
/// the light's (`lanes_of`: a grey value in every lane, an RGB one as is).
#[inline]
fn add_four_sums<V: Copy>(
    indices: &[u16],
    values: &[V],
    light: &[Rgb4],
    lanes: &mut [Rgb4; 4],
    lanes_of: impl Fn(V) -> Rgb4,
) {
    let n = indices.len().min(values.len());
    let (k4, v4) = (indices[..n].chunks_exact(4), values[..n].chunks_exact(4));
    let (k_rest, v_rest) = (k4.remainder(), v4.remainder());
    let at = |k: u16| light.get(k as usize).copied().unwrap_or([0.0; 4]);
    for (k, v) in k4.zip(v4) {
        for (lane, (&k, &t)) in lanes.iter_mut().zip(k.iter().zip(v)) {
            let (l, t) = (at(k), lanes_of(t));
            for c in 0..4 {
                lane[c] += l[c] * t[c];
            }
        }
    }
    for (lane, (&k, &t)) in lanes.iter_mut().zip(k_rest.iter().zip(v_rest)) {
        let (l, t) = (at(k), lanes_of(t));
        for c in 0..4 {
            lane[c] += l[c] * t[c];
        }
    }
}

/// The couplings of source `i` to the wanted targets `k < order`, from
/// `table` or in closed form.
#[inline]
fn couple(
    table: Option<&AccTable>,
    (i, order): (usize, usize),
    (s, o): (f64, f64),
    wanted: impl Fn(usize) -> bool,
    out: &mut Vec<(u32, f64)>,
) {
    match table {
        Some(table) => table.couplings_where(i, s, o, wanted, out),
        None => couplings_where(i, order, s, o, wanted, out),
    }
}

/// The Haar coefficients of a transport row over the face from its
/// per-texel integrals (`∫ V·ρ·cos dω` over each texel, `order²`,
/// row-major, `y` major): the per-texel integral `t` is the function
/// `t·order²` on the texel, `t·order` in the pixel basis; then the standard
/// 2D Haar. Zeros are dropped.
pub fn transport_coefficients(per_texel: &[f32], order: usize) -> Result<Vec<(u32, f32)>> {
    if per_texel.len() != order * order {
        return Err(RelightError::Invalid(format!(
            "transport row of {} texels for a face of {order}x{order}",
            per_texel.len()
        )));
    }
    let mut out = Vec::new();
    ltm_codec::nearfield::plane_coefficients(per_texel, order, &mut out)?;
    Ok(out)
}
