//! The camera that image rows were seen from, recovered from their surface
//! records.
//!
//! A `.ltm` file of image rows stores, per pixel, the first hit of the ray
//! through the pixel's centre (docs/FORMAT.md, "Row layout and surface
//! data"), but not the camera. The camera is still determined: every valid
//! record `X` projects to its pixel centre `x` through one pinhole, so a
//! projective camera `P` (3 × 4) with `x ~ P·X` fits them all, and its
//! centre, the eye, is `P`'s null vector. View-dependent shading (a glossy
//! material, `ltm relight --brdf`) needs that eye.
//!
//! The fit is the normalized direct linear transform (Hartley and
//! Zisserman, *Multiple View Geometry*, §4.4 and §7.1): points and pixels
//! are centred and scaled, `P` is the eigenvector of the smallest
//! eigenvalue of the 12 × 12 normal matrix, and the eye solves
//! `M·C = −p₄`. A fit is refused when the points are (nearly) coplanar,
//! which leaves the eye undetermined, and when any point misses its pixel
//! centre by more than [`MAX_RESIDUAL_PX`].

use crate::error::{Error, Result};
use crate::surface::Surface;
use faer::{Mat, Side};
use glam::{DMat3, DVec3};

/// The largest distance, in pixels, between a valid record's projection
/// and its pixel centre that a recovered camera allows. Records are `f32`
/// points on exact rays, so a true fit stays far below it (about 10⁻⁴ px).
pub const MAX_RESIDUAL_PX: f64 = 0.05;
/// Fewest valid records a fit takes (the camera has 11 degrees of freedom,
/// each record gives 2 equations).
pub const MIN_CAMERA_POINTS: usize = 6;
/// The largest share of valid records whose normal may face away from the
/// recovered eye.
pub const MAX_FACING_AWAY: f64 = 0.1;
/// The largest relative uncertainty of the fit, `√(λ₀/λ₁)` of the normal
/// matrix's two smallest eigenvalues (f64 rounding counts as 10⁻¹⁶ of the
/// largest), before the points count as coplanar.
const MAX_UNCERTAINTY: f64 = 1e-3;

/// The pinhole camera of a file's image rows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImageCamera {
    eye: [f64; 3],
    max_residual_px: f64,
    points: usize,
}

/// Centre and scale that take points to mean distance `√D` from the
/// origin.
struct Normalization<const D: usize> {
    centre: [f64; D],
    scale: f64,
}

impl<const D: usize> Normalization<D> {
    /// Of the points `points` yields (two passes).
    fn of(points: impl Iterator<Item = [f64; D]> + Clone) -> Normalization<D> {
        let (mut centre, mut n) = ([0.0; D], 0.0);
        for p in points.clone() {
            (0..D).for_each(|k| centre[k] += p[k]);
            n += 1.0;
        }
        centre = centre.map(|c| c / n);
        let distance = |p: [f64; D]| (0..D).map(|k| (p[k] - centre[k]).powi(2)).sum::<f64>();
        let mean = points.map(|p| distance(p).sqrt()).sum::<f64>() / n;
        let scale = if mean > 0.0 {
            (D as f64).sqrt() / mean
        } else {
            1.0
        };
        Normalization { centre, scale }
    }

    fn apply(&self, p: &[f64; D]) -> [f64; D] {
        std::array::from_fn(|k| (p[k] - self.centre[k]) * self.scale)
    }
}

/// The valid records of image rows `width` pixels wide: each one's pixel
/// centre and point. Read in passes, never copied.
fn records(
    surface: &Surface,
    width: usize,
) -> impl Iterator<Item = ([f64; 2], [f64; 3])> + Clone + '_ {
    surface
        .points()
        .iter()
        .enumerate()
        .filter(|(_, p)| p.valid)
        .map(move |(k, p)| {
            let pixel = [(k % width) as f64 + 0.5, (k / width) as f64 + 0.5];
            (pixel, p.position.map(f64::from))
        })
}

/// The normalizations of the pixels and the points.
type Normalized = (Normalization<2>, Normalization<3>);

/// The records normalized.
fn normalized<'a>(
    records: impl Iterator<Item = ([f64; 2], [f64; 3])> + Clone + 'a,
    (n2, n3): &'a Normalized,
) -> impl Iterator<Item = ([f64; 2], [f64; 3])> + Clone + 'a {
    records.map(move |(x, p)| (n2.apply(&x), n3.apply(&p)))
}

/// The normal matrix `AᵀA` of the direct linear transform of `x ~ P·X`
/// over the (normalized) records: two rows of `A` per record.
fn normal_matrix(records: impl Iterator<Item = ([f64; 2], [f64; 3])>) -> Mat<f64> {
    let mut g = [[0.0f64; 12]; 12];
    for (x, p) in records {
        let h = [p[0], p[1], p[2], 1.0];
        let mut rows = [[0.0f64; 12]; 2];
        for k in 0..4 {
            rows[0][k] = h[k];
            rows[0][8 + k] = -x[0] * h[k];
            rows[1][4 + k] = h[k];
            rows[1][8 + k] = -x[1] * h[k];
        }
        for r in &rows {
            for i in 0..12 {
                if r[i] != 0.0 {
                    for j in 0..=i {
                        g[i][j] += r[i] * r[j];
                    }
                }
            }
        }
    }
    Mat::from_fn(12, 12, |i, j| g[i.max(j)][i.min(j)])
}

fn numerical(detail: String) -> Error {
    Error::Numerical {
        what: "recovering the camera of image rows",
        detail,
    }
}

impl ImageCamera {
    /// Fits the pinhole camera of the image rows whose records `surface`
    /// holds, `width` pixels to a row (row `k` is pixel `(k mod width,
    /// ⌊k / width⌋)`). Errors: fewer than [`MIN_CAMERA_POINTS`] valid
    /// records, records that do not fix the eye (coplanar), or records that
    /// no single pinhole explains.
    pub fn recover(surface: &Surface, width: usize) -> Result<ImageCamera> {
        if width == 0 || !surface.len().is_multiple_of(width) {
            return Err(Error::range(
                "image width",
                width,
                format!("a divisor of the {} rows", surface.len()),
            ));
        }
        let count = surface.valid_count();
        if count < MIN_CAMERA_POINTS {
            return Err(numerical(format!(
                "{count} valid surface records (valid: at least {MIN_CAMERA_POINTS})"
            )));
        }
        let all = records(surface, width);
        let norms = (
            Normalization::of(all.clone().map(|r| r.0)),
            Normalization::of(all.clone().map(|r| r.1)),
        );
        let (p, uncertainty) = Self::solve(&normal_matrix(normalized(all.clone(), &norms)))?;
        let residual = Self::residual(&p, normalized(all, &norms))? / norms.0.scale;
        if residual.is_nan() || residual > MAX_RESIDUAL_PX {
            return Err(numerical(format!(
                "the surface records fit no single pinhole camera: a record lies {residual:.3e} px from its pixel centre (valid: at most {MAX_RESIDUAL_PX})"
            )));
        }
        if uncertainty.is_nan() || uncertainty > MAX_UNCERTAINTY {
            return Err(numerical(format!(
                "the valid surface records leave the eye undetermined: they lie (nearly) on one plane, or on rays that (nearly) never meet (fit uncertainty {uncertainty:.1e}, valid: at most {MAX_UNCERTAINTY:e})"
            )));
        }
        let eye = Self::centre(&p, &norms.1)?;
        Self::check_facing(surface, eye)?;
        Ok(ImageCamera {
            eye,
            max_residual_px: residual,
            points: count,
        })
    }

    /// The camera matrix (row-major, normalized coordinates), the
    /// eigenvector of the smallest eigenvalue, and how far the next
    /// eigenvalue leaves it undetermined (`√(λ₀/λ₁)`).
    fn solve(g: &Mat<f64>) -> Result<([f64; 12], f64)> {
        let evd = g
            .as_ref()
            .self_adjoint_eigen(Side::Lower)
            .map_err(|e| numerical(format!("eigendecomposition failed: {e:?}")))?;
        let s = evd.S().column_vector();
        let (l0, l1, top) = (s[0].max(0.0), s[1], s[11]);
        let uncertainty = ((l0 + 1e-16 * top) / l1).sqrt();
        let u = evd.U();
        Ok((std::array::from_fn(|i| u[(i, 0)]), uncertainty))
    }

    /// The camera's centre in world units: the null vector of `p`, in the
    /// coordinates `n3` normalized.
    fn centre(p: &[f64; 12], n3: &Normalization<3>) -> Result<[f64; 3]> {
        let m = DMat3::from_cols_array(&[p[0], p[4], p[8], p[1], p[5], p[9], p[2], p[6], p[10]]);
        let det = m.determinant();
        let size = m.to_cols_array().iter().map(|v| v * v).sum::<f64>();
        if det.is_nan() || det.abs() <= 1e-12 * size.powf(1.5) {
            return Err(numerical(format!(
                "the fitted camera has no centre (determinant {det:e}): the rows look orthographic"
            )));
        }
        let centre = -(m.inverse() * DVec3::new(p[3], p[7], p[11]));
        let eye: [f64; 3] = std::array::from_fn(|k| centre[k] / n3.scale + n3.centre[k]);
        match eye.iter().all(|v| v.is_finite()) {
            true => Ok(eye),
            false => Err(numerical(format!("the fitted eye {eye:?} is not finite"))),
        }
    }

    /// The largest distance between a (normalized) record's projection and
    /// its pixel (normalized units); an error when records lie on both
    /// sides of the camera.
    fn residual(p: &[f64; 12], records: impl Iterator<Item = ([f64; 2], [f64; 3])>) -> Result<f64> {
        let mut worst = 0.0f64;
        let mut sides = [false; 2];
        for (x, q) in records {
            let h = [q[0], q[1], q[2], 1.0];
            let row = |r: usize| (0..4).map(|k| p[4 * r + k] * h[k]).sum::<f64>();
            let w = row(2);
            sides[usize::from(w > 0.0)] = true;
            let d = (row(0) / w - x[0]).hypot(row(1) / w - x[1]);
            worst = if d.is_nan() {
                f64::INFINITY
            } else {
                worst.max(d)
            };
        }
        if sides[0] && sides[1] {
            return Err(numerical(
                "the surface records fit no single pinhole camera: they lie on both sides of the best fit's centre"
                    .into(),
            ));
        }
        Ok(worst)
    }

    /// Checks that the valid records' normals face `eye`, as image rows'
    /// shading normals are turned to the camera's side of their triangle:
    /// all but [`MAX_FACING_AWAY`] of them (interpolated normals lean past
    /// the silhouette). This also settles which side a far, nearly
    /// orthographic camera is on.
    fn check_facing(surface: &Surface, eye: [f64; 3]) -> Result<()> {
        let eye = DVec3::from_array(eye);
        let (mut valid, mut away) = (0usize, 0usize);
        for p in surface.points().iter().filter(|p| p.valid) {
            let to_eye = eye - DVec3::from_array(p.position.map(f64::from));
            valid += 1;
            let facing = DVec3::from_array(p.normal.map(f64::from)).dot(to_eye);
            away += usize::from(facing.is_nan() || facing < 0.0);
        }
        let share = away as f64 / valid as f64;
        match share <= MAX_FACING_AWAY {
            true => Ok(()),
            false => Err(numerical(format!(
                "the fitted eye {eye:?} is behind the surface of {:.1} % of the records (valid: at most {} %, as image rows' normals face their camera): the rows are not a pinhole camera's",
                100.0 * share,
                100.0 * MAX_FACING_AWAY
            ))),
        }
    }

    /// The eye: the camera's centre, in world units.
    pub fn eye(&self) -> [f64; 3] {
        self.eye
    }

    /// The largest distance, in pixels, between a record's projection and
    /// its pixel centre.
    pub fn max_residual_px(&self) -> f64 {
        self.max_residual_px
    }

    /// The valid records the fit used.
    pub fn points(&self) -> usize {
        self.points
    }
}

#[cfg(test)]
mod tests;
