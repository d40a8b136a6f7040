//! One row of the transport matrix: the light reflected towards the camera
//! through pixel `p` from each cubemap texel of a distant environment.
//!
//! # Definition
//!
//! Rows are pixels, `p = y·width + x` with `y` counted from the top row
//! (camera model: [`crate::Camera::direction`]). Columns are cubemap
//! texels `j = face·n² + row·n + col` ([`ltm_codec::cubemap`]: OpenGL face
//! order and orientation, world Y up). A row holds `M·C` values,
//! channel-interleaved: `T[p][j][c]` at index `j·C + c`.
//!
//! Let `L[j] = (1/Ω_j) ∫_{texel j} L(ω) dω` be the mean radiance of texel
//! `j` (Ω_j its solid angle). Then the pixel's radiance is
//!
//! `B[p][c] = Σ_j T[p][j][c] · L[j][c]`,
//!
//! `T[p][j][c] = (1/K) Σ_k ∫_{texel j} V(x_k, ω) · f_r,c(x_k, ω → ω_o,k) · max(0, n_k·ω) dω`,
//!
//! exactly when the environment is constant over each texel (otherwise it
//! is the texel-average approximation of `∫ V f_r cos L dω`). The sum runs
//! over the pixel's K sub-samples `k` (a box filter over the pixel's area):
//! `x_k` is the first hit of the primary ray through sub-sample `k`,
//! `ω_o,k` the direction back to the eye, `n_k` the shading normal, `f_r`
//! the material's reflectance ([`crate::material`]) and `V` the binary
//! visibility of the environment: 1 when a shadow ray from `x_k` towards
//! `ω` hits no triangle, 0 when it does or when `ω` is below the geometric
//! surface. Surfaces are two-sided (normals are flipped to face the eye).
//! Sub-samples that miss the scene contribute zero; a pixel that misses
//! everywhere has an all-zero row (flagged in the raw store). Emission and
//! interreflection are not modelled: the matrix is direct lighting from the
//! environment, in the same units as L.
//!
//! # Grey transport (1 channel)
//!
//! When every material used is Lambertian, `f_r = albedo/π` and
//! `T[p][j][c] = albedo_c · t[p][j]` with the grey transport
//! `t = ∫ V · max(0, n·ω)/π dω`. The store then holds `t` (C = 1) and the
//! RGB albedo image `a[p]`, and `B[p][c] = a[p][c] · Σ_j t[p][j] · L[j][c]`.
//! With K > 1 sub-samples of albedos `a_k` (zero for a miss), the stored
//! albedo is their mean `(1/K) Σ_k a_k` and `t = Σ_k Y(a_k) t_k / Σ_k Y(a_k)`
//! with `Y` the Rec. 709 luminance (0.2126, 0.7152, 0.0722): the product
//! is exact in luminance always, and in every channel when the sub-samples'
//! albedos are proportional (one material, or one material and the
//! background; at a boundary between materials of different hues the
//! pixel's colour is approximate).
//!
//! # Quadrature
//!
//! Texel `j = (face, row, col)` spans face coordinates
//! `s ∈ [col/n, (col+1)/n]`, `t ∈ [row/n, (row+1)/n]`. Its S direction
//! samples are the rotated Hammersley points `(u_i, v_i)` of
//! [`crate::sampling`], `s_i = (col + u_i)/n`, `t_i = (row + v_i)/n`,
//! `ω_i = face_point_direction(face, s_i, t_i)`. They are uniform in
//! `(s, t)`, whose solid-angle density is `dω = J ds dt` with
//! `J = 4/(1 + a² + b²)^{3/2}`, `a = 2s − 1`, `b = 2t − 1`. The estimate is
//!
//! `∫_{texel j} g dω ≈ Ω_j · Σ_i J_i g(ω_i) / Σ_i J_i`,
//!
//! with Ω_j the texel's exact solid angle
//! ([`ltm_codec::cubemap::texel_solid_angle`]): the weights follow the
//! solid-angle density and sum exactly to Ω_j, so an integrand that is
//! constant over the texel is integrated exactly. A texel whose four corners
//! all lie on or below the horizon of the shading or the geometric normal
//! is skipped without tracing: a texel is the spherical convex hull of its
//! corners, so it then lies wholly below and contributes nothing.
//!
//! Shadow rays start at `x + ε·n_g` with ε = 10⁻⁵ × max(bounding-box
//! diagonal, largest coordinate magnitude, 10⁻³) of the scene, and use the
//! BVH's any-hit query. The rays of a square tile of texels (at most 256)
//! are traced together as packets (`crate::packet`), with the answers each
//! would get alone; each texel's sum still runs over its samples in order,
//! so the values do not depend on the tiling.

use crate::material::Material;
use crate::packet::Packet;
use crate::plane::LightPlane;
use crate::rows::RowSample;
use crate::sampling::{hammersley, mix64, rotation, wrap};
use crate::world::Scene;
use glam::DVec3;
use ltm_codec::cubemap::{face_point_direction, face_rect_solid_angle};
use std::f64::consts::FRAC_1_PI;

/// Rec. 709 luminance weights.
pub const LUMINANCE: [f64; 3] = [0.2126, 0.7152, 0.0722];

/// Rays traced for one or more rows.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RowStats {
    /// Camera rays (one per pixel sub-sample).
    pub primary_rays: u64,
    /// Visibility rays towards the environment.
    pub shadow_rays: u64,
}

impl std::ops::AddAssign for RowStats {
    fn add_assign(&mut self, o: RowStats) {
        self.primary_rays += o.primary_rays;
        self.shadow_rays += o.shadow_rays;
    }
}

/// Tables shared by every row of a bake.
pub(crate) struct Tables {
    /// The cubemap's directions.
    grid: Grid,
    texel_pts: Vec<[f64; 2]>,
    pixel_pts: Vec<[f64; 2]>,
}

impl Tables {
    pub(crate) fn pixel_points(&self) -> &[[f64; 2]] {
        &self.pixel_pts
    }

    pub(crate) fn new(scene: &Scene) -> Tables {
        Tables {
            grid: Grid::cubemap(scene.face_res as usize),
            texel_pts: hammersley(scene.texel_samples),
            pixel_pts: hammersley(scene.rows.samples_per_row()),
        }
    }
}

/// How a face of a [`Grid`] maps face coordinates `(s, t) ∈ [0, 1]²` to
/// directions.
#[derive(Clone, Copy, Debug)]
enum GridFace {
    /// A cubemap face ([`face_point_direction`]).
    Cube(usize),
    /// `normalize(forward + a·right + b·up)` with tangent coordinates
    /// `a = h(2s − 1)`, `b = h(2t − 1)`.
    Axes {
        right: DVec3,
        up: DVec3,
        forward: DVec3,
    },
}

/// A grid of direction texels: faces of `n × n` texels over tangent
/// coordinates `[−h, h]²` (h = 1 for a cube face), with the texel corners'
/// directions and the texels' exact solid angles.
pub(crate) struct Grid {
    n: usize,
    half: f64,
    faces: Vec<GridFace>,
    /// Corner directions, `face·(n+1)² + r·(n+1) + c` for the grid point at
    /// `s = c/n`, `t = r/n`.
    corners: Vec<DVec3>,
    /// Solid angle of the face-local texel `row·n + col` (the same on every
    /// face).
    omega: Vec<f64>,
}

impl Grid {
    /// The six faces of a cubemap at face resolution `n`.
    pub(crate) fn cubemap(n: usize) -> Grid {
        Grid::new(n, 1.0, (0..6).map(GridFace::Cube).collect())
    }

    /// One face of `n × n` texels over tangent coordinates
    /// `[−side/2, side/2]²` around `forward`.
    pub(crate) fn face(n: usize, side: f64, right: DVec3, up: DVec3, forward: DVec3) -> Grid {
        Grid::new(n, 0.5 * side, vec![GridFace::Axes { right, up, forward }])
    }

    fn new(n: usize, half: f64, faces: Vec<GridFace>) -> Grid {
        let nf = n as f64;
        let mut grid = Grid {
            n,
            half,
            faces,
            corners: Vec::with_capacity(6 * (n + 1) * (n + 1)),
            omega: Vec::with_capacity(n * n),
        };
        for face in 0..grid.faces.len() {
            for r in 0..=n {
                for c in 0..=n {
                    let d = grid.direction(face, c as f64 / nf, r as f64 / nf);
                    grid.corners.push(d);
                }
            }
        }
        // ∫∫ da db / (1 + a² + b²)^{3/2} over a rectangle, in closed form.
        let f = |a: f64, b: f64| (a * b).atan2((a * a + b * b + 1.0).sqrt());
        let at = |i: usize| half * (2.0 * i as f64 / nf - 1.0);
        for r in 0..n {
            for c in 0..n {
                // A cube face (h = 1) through the codec's function, so that
                // cubemap rows stay bit for bit what they were.
                let omega = if half == 1.0 {
                    face_rect_solid_angle(
                        c as f64 / nf,
                        (c + 1) as f64 / nf,
                        r as f64 / nf,
                        (r + 1) as f64 / nf,
                    )
                } else {
                    let (a0, a1, b0, b1) = (at(c), at(c + 1), at(r), at(r + 1));
                    f(a1, b1) - f(a0, b1) - f(a1, b0) + f(a0, b0)
                };
                grid.omega.push(omega);
            }
        }
        grid
    }

    fn direction(&self, face: usize, s: f64, t: f64) -> DVec3 {
        match self.faces[face] {
            GridFace::Cube(f) => face_point_direction(f, s, t),
            GridFace::Axes { right, up, forward } => {
                let (a, b) = (self.half * (2.0 * s - 1.0), self.half * (2.0 * t - 1.0));
                (forward + a * right + b * up).normalize()
            }
        }
    }
}

/// Per-thread working memory.
pub(crate) struct Scratch {
    acc: Vec<f64>,
    tile: Tile,
    packet: Packet,
}

/// Rays a tile of texels aims at: the bake traces each tile's rays
/// together ([`Scene::occluded_packet`]), in packets of up to 64.
const TILE_RAYS: usize = 256;

/// Side, in texels, of the square tiles of a cubemap face whose rays are
/// traced together: the largest of 8, 4, 2, 1 whose tile holds at most
/// [`TILE_RAYS`] rays of `samples` each (8 for the default 4 samples).
fn tile_side(samples: usize) -> usize {
    [8, 4, 2, 1]
        .into_iter()
        .find(|&t| t * t * samples <= TILE_RAYS)
        .unwrap_or(1)
}

/// The rays of one tile of texels, gathered to be traced together.
#[derive(Default)]
struct Tile {
    /// Unit directions, texel by texel, each texel's in its sample order.
    dirs: Vec<DVec3>,
    /// Per ray: `jac · cos` and the BRDF term (the first C values).
    terms: Vec<(f64, [f64; 3])>,
    hits: Vec<bool>,
    /// Per texel with rays: its index, its rays' range in `dirs`, and
    /// `Ω_j / Σ jac`.
    texels: Vec<(usize, std::ops::Range<usize>, f64)>,
}

impl Tile {
    fn clear(&mut self) {
        self.dirs.clear();
        self.terms.clear();
        self.hits.clear();
        self.texels.clear();
    }

    /// Adds each texel's `Σ jac·cos·f` over its unoccluded rays, in sample
    /// order, times `Ω_j / Σ jac`, into `acc` (C values per texel).
    fn accumulate<const C: usize>(&self, acc: &mut [f64]) {
        for (j, range, scale) in &self.texels {
            let mut sum = [0.0f64; C];
            for k in range.clone() {
                if self.hits[k] {
                    continue;
                }
                let (w, fr) = self.terms[k];
                for ch in 0..C {
                    sum[ch] += w * fr[ch];
                }
            }
            for ch in 0..C {
                acc[j * C + ch] += sum[ch] * scale;
            }
        }
    }
}

impl Scratch {
    pub(crate) fn new(scene: &Scene) -> Scratch {
        let m = 6 * scene.face_res as usize * scene.face_res as usize;
        Scratch::with_texels(scene, m)
    }

    pub(crate) fn with_texels(scene: &Scene, texels: usize) -> Scratch {
        Scratch {
            acc: vec![0.0; texels * scene.channels as usize],
            tile: Tile::default(),
            packet: Packet::default(),
        }
    }
}

const DIR_KEY: u64 = 0x4449_5200_0000_0000;

impl Scene {
    /// Computes row `p` (M·C values, channel-interleaved) and, for grey
    /// transport, the pixel's RGB albedo (zero otherwise). See the module
    /// docs for the definition.
    pub fn transport_row(&self, p: usize, row: &mut [f32], albedo: &mut [f32; 3]) -> RowStats {
        let tables = Tables::new(self);
        let mut scratch = Scratch::new(self);
        self.row_into(&tables, &mut scratch, p, row, albedo)
    }

    pub(crate) fn row_into(
        &self,
        tables: &Tables,
        scratch: &mut Scratch,
        p: usize,
        row: &mut [f32],
        albedo_out: &mut [f32; 3],
    ) -> RowStats {
        self.row_on(tables, &tables.grid, None, scratch, p, row, albedo_out)
    }

    /// [`Scene::row_into`] over the texels of `grid`; with a light
    /// `plane`, shadow rays end at it ([`LightPlane::reach`]), so geometry
    /// beyond the plane casts no shadow from a light in it.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn row_on(
        &self,
        tables: &Tables,
        grid: &Grid,
        plane: Option<&LightPlane>,
        scratch: &mut Scratch,
        p: usize,
        row: &mut [f32],
        albedo_out: &mut [f32; 3],
    ) -> RowStats {
        let mut packet = std::mem::take(&mut scratch.packet);
        let mut occluded = |o, d: &[DVec3], out: &mut [bool]| {
            let reach = |dir| plane.map_or(f64::INFINITY, |l| l.reach(o, dir));
            self.occluded_within(&mut packet, o, d, reach, out)
        };
        let stats = self.row_traced(tables, grid, scratch, p, row, albedo_out, &mut occluded);
        scratch.packet = packet;
        stats
    }

    /// Every shadow ray row `p` traces, in the bake's order and in its
    /// packets, as world-space origin, unit directions and whether each
    /// was occluded: the rays a ray tracer is measured on
    /// (`examples/shadow_rays.rs`).
    pub fn shadow_rays(&self, p: usize, visit: &mut impl FnMut(DVec3, &[DVec3], &[bool])) {
        let tables = Tables::new(self);
        let mut scratch = Scratch::new(self);
        let mut row = vec![0.0; self.dims().row_len()];
        let mut trace = |o, d: &[DVec3], out: &mut [bool]| {
            self.occluded_packet(o, d, out);
            visit(o, d, out);
        };
        self.row_traced(
            &tables,
            &tables.grid,
            &mut scratch,
            p,
            &mut row,
            &mut [0.0; 3],
            &mut trace,
        );
    }

    /// [`Scene::row_into`] over the texels of `grid`, with the shadow
    /// query `occluded` (rays from one origin, one answer per direction).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn row_traced(
        &self,
        tables: &Tables,
        grid: &Grid,
        scratch: &mut Scratch,
        p: usize,
        row: &mut [f32],
        albedo_out: &mut [f32; 3],
        occluded: &mut impl FnMut(DVec3, &[DVec3], &mut [bool]),
    ) -> RowStats {
        let k_count = self.rows.samples_per_row() as usize;
        let (acc, tile) = (&mut scratch.acc, &mut scratch.tile);
        acc.iter_mut().for_each(|v| *v = 0.0);
        let mut stats = RowStats::default();
        let mut albedo_sum = [0.0f64; 3];
        let mut lum_sum = 0.0;
        let rot = self.rows.row_rotation(p);
        for k in 0..k_count {
            stats.primary_rays += 1;
            let Some(RowSample { hit, wo }) = self.rows.sample(self, p, k, &tables.pixel_pts, rot)
            else {
                continue;
            };
            let material = &self.materials[hit.material];
            let seed = mix64(((p as u64) << 12 ^ k as u64) ^ DIR_KEY);
            if self.channels == 1 {
                let a = material.albedo();
                let lum: f64 = (0..3).map(|c| LUMINANCE[c] * a[c]).sum();
                for c in 0..3 {
                    albedo_sum[c] += a[c];
                }
                if lum <= 0.0 {
                    continue;
                }
                lum_sum += lum;
                let f = |_: &Material, _| [lum * FRAC_1_PI; 1];
                stats.shadow_rays +=
                    self.integrate(tables, grid, &hit, seed, f, acc, tile, occluded);
            } else {
                let w = 1.0 / k_count as f64;
                stats.shadow_rays += self.integrate(
                    tables,
                    grid,
                    &hit,
                    seed,
                    |m: &Material, d| m.eval(hit.ns, d, wo).map(|v| v * w),
                    acc,
                    tile,
                    occluded,
                );
            }
        }
        if self.channels == 1 {
            let inv = if lum_sum > 0.0 { 1.0 / lum_sum } else { 0.0 };
            for (o, a) in row.iter_mut().zip(acc.iter()) {
                *o = (a * inv) as f32;
            }
            for c in 0..3 {
                albedo_out[c] = (albedo_sum[c] / k_count as f64) as f32;
            }
        } else {
            for (o, a) in row.iter_mut().zip(acc.iter()) {
                *o = *a as f32;
            }
            *albedo_out = [0.0; 3];
        }
        stats
    }

    /// Adds `∫_{texel j} V · f(ω) · max(0, n_s·ω) dω` for every texel into
    /// `acc` (C values per texel), with visibility V from `occluded`;
    /// returns the shadow rays traced. The rays of each square tile of
    /// texels ([`tile_side`]) are traced together; each texel's sum runs
    /// over its samples in order, as it would one ray at a time.
    #[allow(clippy::too_many_arguments)]
    fn integrate<const C: usize>(
        &self,
        tables: &Tables,
        grid: &Grid,
        hit: &crate::world::Hit,
        seed: u64,
        f: impl Fn(&Material, DVec3) -> [f64; C],
        acc: &mut [f64],
        tile: &mut Tile,
        occluded: &mut impl FnMut(DVec3, &[DVec3], &mut [bool]),
    ) -> u64 {
        let n = grid.n;
        let origin = hit.point + self.epsilon * hit.ng;
        let mut rays = 0;
        let side = tile_side(tables.texel_pts.len());
        for face in 0..grid.faces.len() {
            for r0 in (0..n).step_by(side) {
                for c0 in (0..n).step_by(side) {
                    tile.clear();
                    for r in r0..(r0 + side).min(n) {
                        for c in c0..(c0 + side).min(n) {
                            self.texel_rays(tables, grid, hit, seed, &f, [face, r, c], tile);
                        }
                    }
                    tile.hits.resize(tile.dirs.len(), false);
                    occluded(origin, &tile.dirs, &mut tile.hits);
                    rays += tile.dirs.len() as u64;
                    tile.accumulate::<C>(acc);
                }
            }
        }
        rays
    }

    /// Appends to `tile` the shadow rays of texel `(face, r, c)` of `grid`
    /// from `hit` (those below either normal, or of zero BRDF, skipped) and
    /// the texel's record; nothing for a texel wholly below either normal.
    #[allow(clippy::too_many_arguments)]
    fn texel_rays<const C: usize>(
        &self,
        tables: &Tables,
        grid: &Grid,
        hit: &crate::world::Hit,
        seed: u64,
        f: &impl Fn(&Material, DVec3) -> [f64; C],
        [face, r, c]: [usize; 3],
        tile: &mut Tile,
    ) {
        let n = grid.n;
        let nf = n as f64;
        let (ns, ng) = (hit.ns, hit.ng);
        let material = &self.materials[hit.material];
        let stride = n + 1;
        let i0 = face * stride * stride + r * stride + c;
        let quad = [
            grid.corners[i0],
            grid.corners[i0 + 1],
            grid.corners[i0 + stride],
            grid.corners[i0 + stride + 1],
        ];
        if quad.iter().all(|d| ns.dot(*d) <= 0.0) || quad.iter().all(|d| ng.dot(*d) <= 0.0) {
            return;
        }
        let j = (face * n + r) * n + c;
        let rot = rotation(seed ^ (j as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
        let first = tile.dirs.len();
        let mut sum_j = 0.0;
        for &[u, v] in &tables.texel_pts {
            let s = (c as f64 + wrap(u, rot[0])) / nf;
            let t = (r as f64 + wrap(v, rot[1])) / nf;
            let (a, b) = (2.0 * s - 1.0, 2.0 * t - 1.0);
            let (a, b) = (grid.half * a, grid.half * b);
            let q = 1.0 + a * a + b * b;
            let jac = 1.0 / (q * q.sqrt());
            sum_j += jac;
            let d = grid.direction(face, s, t);
            let cos = ns.dot(d);
            if cos <= 0.0 || ng.dot(d) <= 0.0 {
                continue;
            }
            let fr = f(material, d);
            if fr.iter().all(|&v| v == 0.0) {
                continue;
            }
            let mut term = [0.0; 3];
            term[..C].copy_from_slice(&fr);
            tile.dirs.push(d);
            tile.terms.push((jac * cos, term));
        }
        let scale = grid.omega[r * n + c] / sum_j;
        tile.texels.push((j, first..tile.dirs.len(), scale));
    }
}
