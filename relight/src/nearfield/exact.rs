//! The exact near-field light of every face texel, without wavelets.
//!
//! By eq. 29 a face texel `[a, a+1)/order × [b, b+1)/order` of a receiving
//! point sees the light's texture over a rectangle of texture coordinates
//! (`u = s·w + o` per axis). The mean radiance over the texel is the
//! texture's integral over that rectangle divided by its area, and a
//! transport row stored as per-texel integrals `t` (the bake's values)
//! shades as `B = Σ t·mean` over the texels the light covers. This is what
//! the affine propagation of every source term to every target computes
//! (eq. 30 with nothing truncated), with the texture at its own resolution
//! instead of the face's.
//!
//! The integrals come from a summed-area table in `f64`
//! ([`LightTable`]). Where a face texel covers two or more texture texels
//! along both axes, they are bilinear differences of the table, with an
//! absolute error of a few ulps of the texture's total; where it covers
//! less (a point close to the light), the partly covered texels are
//! weighted directly, so a sliver of one texel keeps its relative
//! precision.

use super::light::LightTexture;
use crate::error::{RelightError, Result};

/// Textures wider or taller than this are box-averaged to it (exact area
/// averages) before their table is built: a face texel sees finer detail
/// only from closer than `size·order/(1024·side)` to the light.
pub const MAX_TABLE_SIDE: usize = 1024;

/// A light texture's summed-area table with its texels, radiance scaled
/// by the light's intensity, in texel units (a texel has area 1).
#[derive(Clone, Debug)]
pub struct LightTable {
    width: usize,
    height: usize,
    /// `(height + 1) × (width + 1)`, `y` major: `Σ` of the texels left of
    /// column `i` and below row `j` at `[j·(width + 1) + i]`.
    sat: Vec<[f64; 3]>,
    /// `height × width`, `y` major.
    texels: Vec<[f64; 3]>,
}

/// The texels one face texel covers along one axis, in texel units: the
/// first and last texel with the lengths covered, and every texel between
/// them whole.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Span {
    first: usize,
    first_len: f64,
    last: usize,
    last_len: f64,
}

impl Span {
    /// The span of `[x0, x1]` (`0 <= x0 <= x1 <= n`) over `n` texels.
    fn new(x0: f64, x1: f64, n: usize) -> Span {
        let ((i0, f0), (i1, f1)) = (cell(x0, n), cell(x1, n));
        if i0 == i1 {
            return Span {
                first: i0,
                first_len: f1 - f0,
                last: i0,
                last_len: 0.0,
            };
        }
        Span {
            first: i0,
            first_len: 1.0 - f0,
            last: i1,
            last_len: f1,
        }
    }

    /// `(texel, length)` for every texel of the span.
    fn texels(self) -> impl Iterator<Item = (usize, f64)> {
        (self.first..=self.last).map(move |i| match i {
            _ if i == self.first => (i, self.first_len),
            _ if i == self.last => (i, self.last_len),
            _ => (i, 1.0),
        })
    }

    /// Texels whole between the first and the last: `first + 1..last`.
    fn whole(self) -> (usize, usize) {
        (self.first + 1, self.last.max(self.first + 1))
    }
}

impl LightTable {
    /// The table of `texture` times `intensity` (finite and >= 0).
    pub fn new(texture: &LightTexture, intensity: f64) -> Result<LightTable> {
        if !(intensity.is_finite() && intensity >= 0.0) {
            return Err(RelightError::range(
                "light intensity",
                intensity,
                "finite and >= 0",
            ));
        }
        let (width, height) = (
            texture.width().min(MAX_TABLE_SIDE),
            texture.height().min(MAX_TABLE_SIDE),
        );
        let texels: Vec<[f64; 3]> = texture
            .resampled(width, height)
            .into_iter()
            .map(|t| t.map(|v| v * intensity))
            .collect();
        let row = width + 1;
        let mut sat = vec![[0.0f64; 3]; row * (height + 1)];
        for j in 0..height {
            let mut run = [0.0f64; 3];
            for i in 0..width {
                for c in 0..3 {
                    run[c] += texels[j * width + i][c];
                    sat[(j + 1) * row + i + 1][c] = sat[j * row + i + 1][c] + run[c];
                }
            }
        }
        if sat.last().is_some_and(|t| t.iter().any(|v| !v.is_finite())) {
            return Err(RelightError::range(
                "light intensity",
                intensity,
                "small enough that the texture's total stays finite",
            ));
        }
        Ok(LightTable {
            width,
            height,
            sat,
            texels,
        })
    }

    /// Texels along x and y.
    pub fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    fn s(&self, i: usize, j: usize) -> [f64; 3] {
        self.sat[j * (self.width + 1) + i]
    }

    fn m(&self, i: usize, j: usize) -> [f64; 3] {
        self.texels[j * self.width + i]
    }

    /// The table's bilinear values at `(x, y)` for every `x` of `cells`
    /// (each [`cell`] of an `x` in texel units) into `out`: the exact
    /// integrals over `[0, x] × [0, y]`.
    fn grid_row(&self, cells: &[(usize, f64)], y: f64, out: &mut Vec<[f64; 3]>) {
        let (j, g) = cell(y, self.height);
        let row = self.width + 1;
        let (low, high) = (
            &self.sat[j * row..][..row],
            &self.sat[(j + 1) * row..][..row],
        );
        out.clear();
        out.extend(cells.iter().map(|&(i, f)| {
            let (l0, l1, h0, h1) = (low[i], low[i + 1], high[i], high[i + 1]);
            let mut v = [0.0f64; 3];
            // Written out per channel: `std::array::from_fn` here was not
            // inlined, and a call per value took 40 % of a frame.
            for c in 0..3 {
                let l = l0[c] + f * (l1[c] - l0[c]);
                let h = h0[c] + f * (h1[c] - h0[c]);
                v[c] = l + g * (h - l);
            }
            v
        }));
    }

    /// `Σ` over whole texels `i0..i1` of row `j`, from the table.
    fn row_sum(&self, j: usize, (i0, i1): (usize, usize)) -> [f64; 3] {
        let (a, b, c, d) = (
            self.s(i1, j + 1),
            self.s(i1, j),
            self.s(i0, j + 1),
            self.s(i0, j),
        );
        std::array::from_fn(|k| (a[k] - b[k]) - (c[k] - d[k]))
    }

    /// `Σ` over whole texels `j0..j1` of column `i`, from the table.
    fn column_sum(&self, i: usize, (j0, j1): (usize, usize)) -> [f64; 3] {
        let (a, b, c, d) = (
            self.s(i + 1, j1),
            self.s(i, j1),
            self.s(i + 1, j0),
            self.s(i, j0),
        );
        std::array::from_fn(|k| (a[k] - b[k]) - (c[k] - d[k]))
    }

    /// The integral over `x × y`, two spans: the axis with fewer texels is
    /// walked texel by texel, the other summed from the table between its
    /// partly covered ends.
    fn span_mass(&self, x: Span, y: Span) -> [f64; 3] {
        let mut sum = [0.0f64; 3];
        let mut add = |w: f64, v: [f64; 3]| (0..3).for_each(|c| sum[c] += w * v[c]);
        if y.last - y.first <= x.last - x.first {
            for (j, wy) in y.texels() {
                let inner = self.row_sum(j, x.whole());
                add(wy, inner);
                add(wy * x.first_len, self.m(x.first, j));
                add(wy * x.last_len, self.m(x.last, j));
            }
        } else {
            for (i, wx) in x.texels() {
                let inner = self.column_sum(i, y.whole());
                add(wx, inner);
                add(wx * y.first_len, self.m(i, y.first));
                add(wx * y.last_len, self.m(i, y.last));
            }
        }
        sum
    }

    /// The integral of the texture over `[x0, x1] × [y0, y1]` in texture
    /// coordinates (`[0, 1]²` is the light; the rest is dark), in texel
    /// units.
    pub fn mass(&self, [x0, x1]: [f64; 2], [y0, y1]: [f64; 2]) -> [f64; 3] {
        let clamp = |v: f64, n: usize| (v.clamp(0.0, 1.0) * n as f64).min(n as f64);
        let (x0, x1) = (clamp(x0, self.width), clamp(x1, self.width));
        let (y0, y1) = (clamp(y0, self.height), clamp(y1, self.height));
        if !(x1 > x0 && y1 > y0) {
            return [0.0; 3];
        }
        let x = Span::new(x0, x1, self.width);
        let y = Span::new(y0, y1, self.height);
        self.span_mass(x, y)
    }
}

/// The face texels a light covers and their masses, reused row after row.
#[derive(Debug, Default)]
pub(crate) struct FaceMasses {
    /// Columns `a0..a1` of the face.
    pub columns: (usize, usize),
    /// Rows `b0..b1` of the face.
    pub rows: (usize, usize),
    /// At `(b − b0)·(a1 − a0) + (a − a0)`: each texel's integral of the
    /// texture, texel units.
    pub masses: Vec<[f64; 3]>,
    /// Texture coordinates of the grid lines, texel units, per axis.
    lines: [Vec<f64>; 2],
    /// The bilinear table values on the grid (one row of grid points).
    grid: [Vec<[f64; 3]>; 2],
    /// The texel and fraction of each x grid line.
    cells: Vec<(usize, f64)>,
    /// Each face texel's span per axis (`None`: empty).
    spans: [Vec<Option<Span>>; 2],
}

impl FaceMasses {
    /// Fills the masses of the face texels that the light covers for the
    /// affine maps `axes` (`(s, o)` per axis, `s > 0`). Returns false when
    /// the light covers none.
    pub fn compute(&mut self, table: &LightTable, axes: [(f64, f64); 2], order: usize) -> bool {
        let n = [table.width, table.height];
        for a in 0..2 {
            let (s, o) = axes[a];
            // Face lines w = k/order whose images bracket [0, 1].
            let lo = ((-o / s) * order as f64).floor().clamp(0.0, order as f64) as usize;
            let hi = (((1.0 - o) / s) * order as f64)
                .ceil()
                .clamp(0.0, order as f64) as usize;
            if hi <= lo {
                return false;
            }
            let line = &mut self.lines[a];
            line.clear();
            line.extend((lo..=hi).map(|k| {
                let u = s * (k as f64 / order as f64) + o;
                u.clamp(0.0, 1.0) * n[a] as f64
            }));
            if a == 0 {
                self.columns = (lo, hi);
            } else {
                self.rows = (lo, hi);
            }
        }
        let (nx, ny) = (self.lines[0].len() - 1, self.lines[1].len() - 1);
        self.masses.clear();
        // Two or more texels per face texel along both axes: differences
        // of the bilinear table on the grid; otherwise texel by texel.
        let wide = (0..2).all(|a| axes[a].0 * n[a] as f64 >= 2.0 * order as f64);
        if wide {
            self.grid_masses(table);
        } else {
            self.span_masses(table);
        }
        debug_assert_eq!(self.masses.len(), nx * ny);
        true
    }

    /// Texel by texel: each face texel's spans, with the common case of at
    /// most two texels per axis summed directly.
    fn span_masses(&mut self, table: &LightTable) {
        let n = [table.width, table.height];
        for (a, spans) in self.spans.iter_mut().enumerate() {
            spans.clear();
            let line = self.lines[a].windows(2);
            spans.extend(line.map(|x| (x[1] > x[0]).then(|| Span::new(x[0], x[1], n[a]))));
        }
        let [xs, ys] = &self.spans;
        for y in ys {
            for x in xs {
                let mass = match (x, y) {
                    (Some(x), Some(y)) if x.last <= x.first + 1 && y.last <= y.first + 1 => {
                        let mut sum = [0.0f64; 3];
                        for (j, wy) in [(y.first, y.first_len), (y.last, y.last_len)] {
                            for (i, wx) in [(x.first, x.first_len), (x.last, x.last_len)] {
                                let m = table.m(i, j);
                                (0..3).for_each(|c| sum[c] += wx * wy * m[c]);
                            }
                        }
                        sum
                    }
                    (Some(x), Some(y)) => table.span_mass(*x, *y),
                    _ => [0.0; 3],
                };
                self.masses.push(mass);
            }
        }
    }

    fn grid_masses(&mut self, table: &LightTable) {
        let [xs, ys] = &self.lines;
        let cells = &mut self.cells;
        cells.clear();
        cells.extend(xs.iter().map(|&x| cell(x, table.width)));
        let [below, above] = &mut self.grid;
        table.grid_row(cells, ys[0], below);
        for &y in &ys[1..] {
            table.grid_row(cells, y, above);
            for a in 0..xs.len() - 1 {
                let (p, q, r, s) = (below[a], below[a + 1], above[a], above[a + 1]);
                let mut mass = [0.0f64; 3];
                for c in 0..3 {
                    mass[c] = ((s[c] - r[c]) - (q[c] - p[c])).max(0.0);
                }
                self.masses.push(mass);
            }
            std::mem::swap(below, above);
        }
    }
}

/// The texel holding `x` (texel units, `0..=n`) and the fraction of it
/// left of `x`: the last texel for `x = n`.
fn cell(x: f64, n: usize) -> (usize, f64) {
    let i = (x as usize).min(n - 1);
    (i, x - i as f64)
}
