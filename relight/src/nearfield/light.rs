//! A planar, textured area light and its Haar coefficients with source-level
//! truncation (§5.3.3).

use crate::error::{RelightError, Result};

/// The largest light texture side accepted, in pixels.
pub const MAX_TEXTURE_SIDE: usize = 16384;

/// An RGB radiance texture over the light's rectangle: `width × height`
/// pixels, row-major, row 0 at the light's `−y` edge and column 0 at its
/// `−x` edge (texture coordinates `u = (x, y) ∈ [0, 1)²`). Radiance is
/// uniform over outgoing angle, as in §5.2.2.
#[derive(Clone, Debug)]
pub struct LightTexture {
    width: usize,
    height: usize,
    texels: Vec<[f32; 3]>,
}

impl LightTexture {
    /// A texture from its pixels; refuses empty or oversized shapes and
    /// negative, NaN or infinite radiance.
    pub fn new(width: usize, height: usize, texels: Vec<[f32; 3]>) -> Result<LightTexture> {
        let valid = format!("1..={MAX_TEXTURE_SIDE}");
        if width == 0 || width > MAX_TEXTURE_SIDE {
            return Err(RelightError::range("light texture width", width, &valid));
        }
        if height == 0 || height > MAX_TEXTURE_SIDE {
            return Err(RelightError::range("light texture height", height, &valid));
        }
        if texels.len() != width * height {
            return Err(RelightError::Invalid(format!(
                "light texture of {width}x{height} has {} texels",
                texels.len()
            )));
        }
        if let Some(bad) = texels
            .iter()
            .flatten()
            .find(|v| !v.is_finite() || **v < 0.0)
        {
            return Err(RelightError::range(
                "light texture radiance",
                bad,
                "finite and >= 0",
            ));
        }
        Ok(LightTexture {
            width,
            height,
            texels,
        })
    }

    /// A texture of one radiance.
    pub fn constant(rgb: [f32; 3]) -> Result<LightTexture> {
        LightTexture::new(1, 1, vec![rgb])
    }

    /// Texels along x.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Texels along y.
    pub fn height(&self) -> usize {
        self.height
    }

    /// The texel in column `x` (from the `−x` edge) and row `y` (from the
    /// `−y` edge); `x < width`, `y < height`.
    pub fn texel(&self, x: usize, y: usize) -> [f32; 3] {
        self.texels[y * self.width + x]
    }

    /// The area average of the texture over each texel of an
    /// `order × order` grid (row-major, `y` major): the exact projection onto
    /// the grid's box functions.
    pub fn box_average(&self, order: usize) -> Vec<[f64; 3]> {
        self.resampled(order, order)
    }

    /// The area average of the texture over each texel of a
    /// `width × height` grid (row-major, `y` major; both >= 1).
    pub fn resampled(&self, width: usize, height: usize) -> Vec<[f64; 3]> {
        let wx = box_weights(self.width, width);
        let wy = box_weights(self.height, height);
        // One texture row at a time (resampled along x), added into the
        // output rows it overlaps: memory O(width·height) whatever the
        // texture's size.
        let mut row = vec![[0.0f64; 3]; width];
        let mut row_of = usize::MAX;
        let mut out = vec![[0.0f64; 3]; width * height];
        for &(j, p, w) in &wy {
            if p != row_of {
                row.fill([0.0; 3]);
                let src = &self.texels[p * self.width..(p + 1) * self.width];
                for &(x, q, wq) in &wx {
                    for c in 0..3 {
                        row[x][c] += wq * f64::from(src[q][c]);
                    }
                }
                row_of = p;
            }
            for (dst, src) in out[j * width..(j + 1) * width].iter_mut().zip(&row) {
                for c in 0..3 {
                    dst[c] += w * src[c];
                }
            }
        }
        out
    }
}

/// Sub-samples per side of each texel of [`LightTexture::rotated`].
pub const ROTATION_SAMPLES: usize = 4;

impl LightTexture {
    /// The texture of a light of `size` (plane units) turned by `degrees`
    /// about its centre, counter-clockwise seen from the lit side (a
    /// texel at `p` from the centre moves to `R(degrees)·p`), as a texture
    /// over the turned light's bounding rectangle with its size: each new
    /// texel is the mean of [`ROTATION_SAMPLES`]² point samples of the old
    /// texture, dark outside the light. The new texels are as large as the
    /// old ones' smaller side, at most [`super::MAX_TABLE_SIDE`] per side.
    pub fn rotated(&self, size: [f64; 2], degrees: f64) -> Result<(LightTexture, [f64; 2])> {
        if !(degrees.is_finite() && size.iter().all(|s| s.is_finite() && *s > 0.0)) {
            return Err(RelightError::Invalid(format!(
                "turning a light of size {size:?} by {degrees} degrees: both must be finite, the size > 0"
            )));
        }
        let (sin, cos) = degrees.to_radians().sin_cos();
        let [w, h] = size;
        let bound = [w * cos.abs() + h * sin.abs(), w * sin.abs() + h * cos.abs()];
        let texel = (w / self.width as f64).min(h / self.height as f64);
        // Rounding of sin/cos must not add a sliver texel.
        let count = |len: f64| {
            ((len / texel * (1.0 - 1e-9)).ceil() as usize).clamp(1, super::MAX_TABLE_SIDE)
        };
        let (nw, nh) = (count(bound[0]), count(bound[1]));
        let n = ROTATION_SAMPLES;
        let mut texels = Vec::with_capacity(nw * nh);
        for j in 0..nh {
            for i in 0..nw {
                let mut sum = [0.0f64; 3];
                for (si, sj) in (0..n * n).map(|k| (k % n, k / n)) {
                    let x =
                        ((i as f64 + (si as f64 + 0.5) / n as f64) / nw as f64 - 0.5) * bound[0];
                    let y =
                        ((j as f64 + (sj as f64 + 0.5) / n as f64) / nh as f64 - 0.5) * bound[1];
                    // Back to the light's own frame: R(−degrees).
                    let (u, v) = ((cos * x + sin * y) / w + 0.5, (cos * y - sin * x) / h + 0.5);
                    if (0.0..1.0).contains(&u) && (0.0..1.0).contains(&v) {
                        let t = self.texel(
                            ((u * self.width as f64) as usize).min(self.width - 1),
                            ((v * self.height as f64) as usize).min(self.height - 1),
                        );
                        (0..3).for_each(|c| sum[c] += f64::from(t[c]));
                    }
                }
                texels.push(sum.map(|v| (v / (n * n) as f64) as f32));
            }
        }
        Ok((LightTexture::new(nw, nh, texels)?, bound))
    }
}

/// `(target, source, weight)` triples: source pixel `p` of `from` covers
/// `[p/from, (p+1)/from)`, target texel `j` of `to` covers `[j/to, (j+1)/to)`,
/// and the weight is their overlap over the target's width.
fn box_weights(from: usize, to: usize) -> Vec<(usize, usize, f64)> {
    let mut out = Vec::with_capacity(from + to);
    let (mut p, mut j) = (0usize, 0usize);
    // Integer breakpoints on a common grid of from·to cells.
    while p < from && j < to {
        let end = ((p + 1) * to).min((j + 1) * from);
        let start = (p * to).max(j * from);
        out.push((j, p, (end - start) as f64 / from as f64));
        if (p + 1) * to == end {
            p += 1;
        }
        if (j + 1) * from == end {
            j += 1;
        }
    }
    out
}

/// Where a light sits in its plane: the centre of its rectangle and its
/// side lengths in plane units, and a radiance scale.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Placement {
    /// Centre `(x, y)` of the rectangle in the light plane.
    pub center: [f64; 2],
    /// Side lengths `(x, y)`, both > 0.
    pub size: [f64; 2],
    /// Radiance scale, finite and >= 0.
    pub intensity: f64,
}

impl Placement {
    /// Refuses NaN or infinite fields, sides that are not > 0 and a negative
    /// intensity.
    pub fn check(&self) -> Result<()> {
        for (what, v) in [
            ("light centre x", self.center[0]),
            ("light centre y", self.center[1]),
        ] {
            if !v.is_finite() {
                return Err(RelightError::range(what, v, "finite"));
            }
        }
        for (what, v) in [
            ("light width", self.size[0]),
            ("light height", self.size[1]),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(RelightError::range(what, v, "finite and > 0"));
            }
        }
        if !(self.intensity.is_finite() && self.intensity >= 0.0) {
            let v = self.intensity;
            return Err(RelightError::range("light intensity", v, "finite and >= 0"));
        }
        Ok(())
    }
}

/// The source-level lighting: the light texture's largest Haar coefficients
/// at `order × order` (standard 2D decomposition, intensity applied), with
/// the distinct indices of each axis gathered for the separable propagation
/// (§5.3.1).
#[derive(Clone, Debug)]
pub struct SourceCoefficients {
    pub(super) order: usize,
    /// Distinct `i₁` (axis x) and `i₂` (axis y) indices, increasing.
    pub(super) axis: [Vec<u32>; 2],
    /// `(position in axis[0], position in axis[1], rgb)` per kept term.
    pub(super) terms: Vec<(u32, u32, [f64; 3])>,
    /// The kept terms' axis-x source functions as steps, merged: each
    /// distinct break `u` in `[0, 1]`, increasing, with the range of its
    /// weights in `weights`.
    pub(super) breaks: Vec<(f64, std::ops::Range<usize>)>,
    /// Per break, `(position in axis[1], Σ rgb·jump)` over the terms whose
    /// axis-x function jumps there, nonzero.
    pub(super) weights: Vec<(u32, [f32; 4])>,
    /// Per break `p` and axis-y position (`p·axis[1].len() + i_y`), the
    /// value at 0 of the kept terms' axis-x functions once the face starts
    /// past `p`: `Σ rgb·(jumps at breaks up to p)`, summed term by term, so
    /// that a function wholly before the face adds exactly 0.
    pub(super) before: Vec<[f32; 4]>,
    /// The squared norm of all coefficients and of the kept ones.
    energy: (f64, f64),
    /// A power of two: every coefficient above (and so the sums of steps 1
    /// and 2, in `f32`) is the light's divided by it, its largest about
    /// 2⁶⁴, so that no light within `f64` overflows or underflows `f32`.
    /// The propagator's results are multiplied back, exactly.
    pub(super) scale: f64,
}

impl SourceCoefficients {
    /// Transforms `texture` at `order` (a power of two, 1..=1024) and keeps
    /// its `keep` largest coefficients by summed magnitude (`keep >= 1`;
    /// more than `order²` keeps all).
    pub fn new(
        texture: &LightTexture,
        placement: &Placement,
        order: usize,
        keep: usize,
    ) -> Result<SourceCoefficients> {
        placement.check()?;
        if !order.is_power_of_two() || order > 1024 {
            return Err(RelightError::range(
                "near-field order",
                order,
                "a power of two in 1..=1024",
            ));
        }
        if keep == 0 {
            return Err(RelightError::range("source terms", keep, ">= 1"));
        }
        let averages = texture.box_average(order);
        let intensity = placement.intensity;
        let scale = power_of_two_scale(averages.iter().flatten().map(|a| a * intensity));
        // Transformed in f32 (as the rows were) on the light divided by
        // `scale`: exactly the unscaled transform's values over `scale`
        // wherever those are within f32.
        let coefficients = haar_2d(&averages, order, intensity / scale)?;
        if coefficients.iter().flatten().any(|v| !v.is_finite()) {
            return Err(RelightError::range(
                "light intensity",
                intensity,
                "small enough that intensity × radiance stays within f64",
            ));
        }
        let mut ranked: Vec<(usize, f64)> = coefficients
            .iter()
            .enumerate()
            .map(|(i, c)| (i, c.iter().map(|v| v.abs()).sum()))
            .filter(|&(_, m)| m > 0.0)
            .collect();
        ranked.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
        ranked.truncate(keep);
        ranked.sort_by_key(|&(i, _)| i);
        let energy_of = |c: &[f64; 3]| c.iter().map(|v| v * v).sum::<f64>();
        let total = coefficients.iter().map(energy_of).sum();
        let kept = ranked
            .iter()
            .map(|&(i, _)| energy_of(&coefficients[i]))
            .sum();
        let mut axis = [Vec::new(), Vec::new()];
        for &(i, _) in &ranked {
            axis[0].push((i % order) as u32);
            axis[1].push((i / order) as u32);
        }
        for a in &mut axis {
            a.sort_unstable();
            a.dedup();
        }
        let position = |a: &[u32], v: usize| a.binary_search(&(v as u32)).unwrap_or(0) as u32;
        let terms: Vec<(u32, u32, [f64; 3])> = ranked
            .iter()
            .map(|&(i, _)| {
                let (x, y) = (i % order, i / order);
                (
                    position(&axis[0], x),
                    position(&axis[1], y),
                    coefficients[i],
                )
            })
            .collect();
        let (breaks, weights, before) = axis_steps(&axis[0], &axis[1], &terms, order);
        Ok(SourceCoefficients {
            order,
            axis,
            terms,
            breaks,
            weights,
            before,
            energy: (total, kept),
            scale,
        })
    }

    /// The number of kept terms.
    pub fn terms(&self) -> usize {
        self.terms.len()
    }

    /// The share of the light's energy (squared L2 norm) the kept terms hold.
    pub fn kept_energy(&self) -> f64 {
        if self.energy.0 > 0.0 {
            self.energy.1 / self.energy.0
        } else {
            1.0
        }
    }
}

/// The power of two `2^e` that brings the largest of `values`' magnitudes
/// into `[2⁶⁴, 2⁶⁵)` (1 for none, all zero or one not finite; `e` within
/// ±1000, so that dividing by it is exact for every normal value).
fn power_of_two_scale(values: impl Iterator<Item = f64>) -> f64 {
    let most = values.fold(0.0f64, |m, v| m.max(v.abs()));
    if !(most > 0.0 && most.is_finite()) {
        return 1.0;
    }
    let e = (most.log2().floor() as i32 - 64).clamp(-1000, 1000);
    2f64.powi(e)
}

/// Breaks, weights and values before the face of [`SourceCoefficients`]:
/// source `i` is the step function `Σ_b jump·[u ≥ b]` with breaks on the
/// grid `m/(2·order)` (the scaling function +1 at 0 and −1 at 1; a wavelet
/// of level `l` and offset `t`, `±2^{l/2}`, +1, −2, +1 at `t/2^l`,
/// `(t + ½)/2^l` and `(t + 1)/2^l`), so the terms' weights add up per grid
/// point and axis-y position.
#[allow(clippy::type_complexity)]
fn axis_steps(
    xs: &[u32],
    ys: &[u32],
    terms: &[(u32, u32, [f64; 3])],
    order: usize,
) -> (
    Vec<(f64, std::ops::Range<usize>)>,
    Vec<(u32, [f32; 4])>,
    Vec<[f32; 4]>,
) {
    let grid = 2 * order;
    let steps = |i: usize| -> Vec<(usize, f64)> {
        if i == 0 {
            return vec![(0, 1.0), (grid, -1.0)];
        }
        let level = (usize::BITS - 1 - i.leading_zeros()) as usize;
        let (width, t) = (grid >> level, i - (1 << level));
        let a = super::acc::amplitude(level);
        vec![
            (t * width, a),
            (t * width + width / 2, -2.0 * a),
            ((t + 1) * width, a),
        ]
    };
    let mut sums = std::collections::BTreeMap::<(usize, u32), [f64; 3]>::new();
    for &(ix, iy, f) in terms {
        for (m, jump) in steps(xs[ix as usize] as usize) {
            let sum = sums.entry((m, iy)).or_insert([0.0; 3]);
            (0..3).for_each(|c| sum[c] += f[c] * jump);
        }
    }
    let (mut breaks, mut weights) = (Vec::<(f64, std::ops::Range<usize>)>::new(), Vec::new());
    let mut grid_points = Vec::new();
    for ((m, iy), w) in sums {
        if w.iter().all(|&v| v == 0.0) {
            continue;
        }
        let u = m as f64 / grid as f64;
        match breaks.last_mut() {
            Some((at, range)) if *at == u => range.end += 1,
            _ => {
                breaks.push((u, weights.len()..weights.len() + 1));
                grid_points.push(m);
            }
        }
        weights.push((iy, [w[0] as f32, w[1] as f32, w[2] as f32, 0.0]));
    }
    // A term's jumps up to a break add up exactly (multiples of 2^{l/2}),
    // to 0 before its first and from its last on: only the breaks between
    // are visited.
    let mut before = vec![[0.0f64; 3]; breaks.len() * ys.len()];
    for &(ix, iy, f) in terms {
        let term_steps = steps(xs[ix as usize] as usize);
        let (first, last) = (term_steps[0].0, term_steps[term_steps.len() - 1].0);
        let from = grid_points.partition_point(|&m| m < first);
        let to = grid_points.partition_point(|&m| m < last);
        for (p, &m) in grid_points.iter().enumerate().take(to).skip(from) {
            let jumps: f64 = term_steps.iter().filter(|s| s.0 <= m).map(|s| s.1).sum();
            let sum = &mut before[p * ys.len() + iy as usize];
            (0..3).for_each(|c| sum[c] += f[c] * jumps);
        }
    }
    let before = before
        .iter()
        .map(|b| [b[0] as f32, b[1] as f32, b[2] as f32, 0.0])
        .collect();
    (breaks, weights, before)
}

/// The standard 2D orthonormal Haar transform (every row fully, then every
/// column fully) of the pixel-basis coefficients of an `order × order`
/// grid of averages: a texel average `a` is `a/order` in the pixel basis
/// (`order` per axis, `1/√order` each). The result is scaled by `scale`.
pub fn haar_2d(averages: &[[f64; 3]], order: usize, scale: f64) -> Result<Vec<[f64; 3]>> {
    let mut out = vec![[0.0f64; 3]; order * order];
    let mut plane = vec![0.0f32; order * order];
    for c in 0..3 {
        for (p, a) in plane.iter_mut().zip(averages) {
            *p = (a[c] * scale / order as f64) as f32;
        }
        ltm_codec::nearfield::standard_haar_2d(&mut plane, order)?;
        for (o, v) in out.iter_mut().zip(&plane) {
            o[c] = f64::from(*v);
        }
    }
    Ok(out)
}
