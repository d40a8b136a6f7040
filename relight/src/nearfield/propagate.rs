//! Light propagation per receiving point (eq. 30), separable in two steps
//! (§5.3.1), with target-level selection from a constant-light prediction
//! (eq. 32), and the per-row shading `B = Σ_k L_k·T_k`.

use super::acc::couplings;
use super::light::{Placement, SourceCoefficients};
use crate::error::{RelightError, Result};

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
    lit: bool,
    /// Axis-y couplings `D_{i_y k_y}`, dense, `k_y` major: `order × axis[1].len()`.
    columns: Vec<f64>,
    /// Step 1's `Z[i_y][k_x]`, RGB, `k_x` major: `order × axis[1].len()`.
    partial: Vec<[f64; 3]>,
    /// The constant light's `|D_{0 k}|` per axis, `order` each, and their
    /// nonzero values.
    prediction: [Vec<f64>; 2],
    nonzero: [Vec<f64>; 2],
    /// Targets whose predicted product is below this are skipped; 0 keeps
    /// all.
    threshold: f64,
    products: Vec<f64>,
    list: Vec<(u32, f64)>,
    starts: Vec<usize>,
}

impl Propagator {
    /// A propagator for `face`.
    pub fn new(face: PlaneFace) -> Result<Propagator> {
        face.check()?;
        Ok(Propagator {
            face,
            lit: false,
            columns: Vec::new(),
            partial: Vec::new(),
            prediction: [vec![0.0; face.order], vec![0.0; face.order]],
            nonzero: [Vec::new(), Vec::new()],
            threshold: 0.0,
            products: Vec::new(),
            list: Vec::new(),
            starts: Vec::new(),
        })
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
        self.lit = receiver.depth > 0.0;
        if !self.lit {
            return Ok(false);
        }
        let [(sx, ox), (sy, oy)] = affine(&self.face, placement, receiver);
        self.step_one(source, (sx, ox));
        let ys = source.axis[1].len();
        self.columns.clear();
        self.columns.resize(ys * order, 0.0);
        for (j, &i) in source.axis[1].iter().enumerate() {
            self.list.clear();
            couplings(i as usize, order, sy, oy, &mut self.list);
            for &(k, d) in &self.list {
                self.columns[k as usize * ys + j] = d;
            }
        }
        self.select(targets, [(sx, ox), (sy, oy)]);
        Ok(true)
    }

    /// Step 1: `Z[i_y][k_x] = Σ_{i_x} F[i_x, i_y]·D_{i_x k_x}(s_x, o_x)`.
    fn step_one(&mut self, source: &SourceCoefficients, (s, o): (f64, f64)) {
        let order = self.face.order;
        let ys = source.axis[1].len();
        self.partial.clear();
        self.partial.resize(ys * order, [0.0; 3]);
        // Couplings of each distinct x index, concatenated.
        self.list.clear();
        self.starts.clear();
        for &i in &source.axis[0] {
            self.starts.push(self.list.len());
            couplings(i as usize, order, s, o, &mut self.list);
        }
        self.starts.push(self.list.len());
        let starts = &self.starts;
        for &(ix, iy, f) in &source.terms {
            let ix = ix as usize;
            let iy = iy as usize;
            for &(k, d) in &self.list[starts[ix]..starts[ix + 1]] {
                let z = &mut self.partial[k as usize * ys + iy];
                for c in 0..3 {
                    z[c] += f[c] * d;
                }
            }
        }
    }

    /// The selection of [`Targets::Share`]: `k` is computed when the
    /// constant light's `|D_{0 k_x}·D_{0 k_y}|` reaches the threshold. At
    /// most `(1 + 3·log₂ order)²` products are nonzero, so only those are
    /// ranked; a share past them keeps every target.
    fn select(&mut self, targets: Targets, axes: [(f64, f64); 2]) {
        let order = self.face.order;
        self.threshold = 0.0;
        let share = match targets {
            Targets::Share(share) if share < 1.0 => share.max(0.0),
            _ => return,
        };
        for (a, (prediction, (s, o))) in self.prediction.iter_mut().zip(axes).enumerate() {
            prediction.fill(0.0);
            self.list.clear();
            couplings(0, order, s, o, &mut self.list);
            self.nonzero[a].clear();
            for &(k, d) in &self.list {
                prediction[k as usize] = d.abs();
                self.nonzero[a].push(d.abs());
            }
        }
        let count = ((share * (order * order) as f64).ceil() as usize).clamp(1, order * order);
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
    }

    /// The incident lighting's coefficient `L_k` (`k = k_y·order + k_x`),
    /// zero when not selected or not lit.
    pub fn coefficient(&self, k: usize) -> [f64; 3] {
        let order = self.face.order;
        if !self.lit || k >= order * order {
            return [0.0; 3];
        }
        let (kx, ky) = (k % order, k / order);
        if self.threshold > 0.0 && self.prediction[0][kx] * self.prediction[1][ky] < self.threshold
        {
            return [0.0; 3];
        }
        let mut sum = [0.0f64; 3];
        let ys = self.partial.len() / order;
        let partial = &self.partial[kx * ys..][..ys];
        for (z, d) in partial.iter().zip(&self.columns[ky * ys..][..ys]) {
            for c in 0..3 {
                sum[c] += z[c] * d;
            }
        }
        sum
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
        self.shade_terms(indices.iter().zip(values).map(|(&k, &t)| (k as usize, t)))
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
