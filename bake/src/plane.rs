//! Transport over the expanded top face of a light plane, the lighting
//! basis of near-field area lights (Sun and Ramamoorthi 2009, §5.2.1).
//!
//! A [`LightPlane`] is an origin and two orthonormal axes; its normal
//! `x × y` points to the lit side. A surface point at depth
//! `z = normal·(point − origin) > 0` sees the plane through one face of
//! `order × order` texels over tangent coordinates
//! `v ∈ [−side/2, side/2]²`: direction `normalize(v_x·x + v_y·y − normal)`,
//! which meets the plane at in-plane position `position + z·v`
//! ([`LightPlane::locate`]). Texel `j = r·order + c` has `c` along `x` and
//! `r` along `y`.
//!
//! [`Scene::plane_row`] integrates `V·f_r·cos` over each texel exactly as a
//! cubemap row does over its texels ([`crate::transport`]: the same
//! quadrature, the same grey and RGB conventions, the texels' exact solid
//! angles), so `B = Σ_j T[j]·L̄[j]` with `L̄[j]` the mean radiance of
//! texel `j` seen from the point.

use crate::error::{BakeError, Result};
use crate::transport::{Grid, RowStats, Scratch, Tables};
use crate::world::Scene;
use glam::DVec3;

/// A plane with orthonormal in-plane axes; the lit side is `x × y`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LightPlane {
    origin: DVec3,
    x_axis: DVec3,
    y_axis: DVec3,
}

fn plane_error(field: &'static str, value: impl std::fmt::Debug, valid: &str) -> BakeError {
    BakeError::OutOfRange {
        origin: "light plane".into(),
        field: field.into(),
        value: format!("{value:?}"),
        valid: valid.into(),
    }
}

impl LightPlane {
    /// A plane through `origin` whose `x` axis is `x_axis` (normalized) and
    /// whose `y` axis is `y_axis` made orthogonal to it (Gram–Schmidt).
    /// Refuses non-finite input and parallel or zero axes.
    pub fn new(origin: DVec3, x_axis: DVec3, y_axis: DVec3) -> Result<LightPlane> {
        for (field, v) in [("origin", origin), ("x axis", x_axis), ("y axis", y_axis)] {
            if !v.is_finite() {
                return Err(plane_error(field, v, "finite"));
            }
        }
        let x = x_axis.normalize_or_zero();
        let y = (y_axis - y_axis.dot(x) * x).normalize_or_zero();
        if x == DVec3::ZERO || y == DVec3::ZERO {
            return Err(plane_error(
                "axes",
                (x_axis, y_axis),
                "two non-parallel, nonzero axes",
            ));
        }
        Ok(LightPlane {
            origin,
            x_axis: x,
            y_axis: y,
        })
    }

    /// The unit x axis.
    pub fn x_axis(&self) -> DVec3 {
        self.x_axis
    }

    /// The unit y axis, orthogonal to x.
    pub fn y_axis(&self) -> DVec3 {
        self.y_axis
    }

    /// The plane as the face the codec stores (`order`, `side`
    /// unchecked here; [`ltm_codec::PlaneBasis::validate`] checks them).
    pub fn basis(&self, order: u32, side: f64) -> ltm_codec::PlaneBasis {
        ltm_codec::PlaneBasis {
            origin: self.origin.to_array(),
            x_axis: self.x_axis.to_array(),
            y_axis: self.y_axis.to_array(),
            order,
            side,
        }
    }

    /// The unit normal towards the lit side, `x × y`.
    pub fn normal(&self) -> DVec3 {
        self.x_axis.cross(self.y_axis)
    }

    /// The world point at in-plane position `(x, y)`.
    pub fn point(&self, position: [f64; 2]) -> DVec3 {
        self.origin + position[0] * self.x_axis + position[1] * self.y_axis
    }

    /// The depth of `point` in front of the plane and its in-plane position
    /// `(x, y)`.
    pub fn locate(&self, point: DVec3) -> (f64, [f64; 2]) {
        let d = point - self.origin;
        (
            self.normal().dot(d),
            [self.x_axis.dot(d), self.y_axis.dot(d)],
        )
    }
}

impl LightPlane {
    /// The distance from `origin` along unit `dir` to the plane, where a
    /// shadow ray towards a light in it ends; infinite when `origin` is
    /// not in front of the plane or `dir` does not head towards it.
    pub fn reach(&self, origin: DVec3, dir: DVec3) -> f64 {
        let (depth, _) = self.locate(origin);
        let towards = -self.normal().dot(dir);
        match depth > 0.0 && towards > 0.0 {
            true => depth / towards,
            false => f64::INFINITY,
        }
    }
}

/// What [`Scene::plane_row`] found besides the row.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PlaneRow {
    /// Rays traced.
    pub stats: RowStats,
    /// The mean surface point of the row's sub-samples that hit, where the
    /// near-field light is propagated to; `None` when all missed.
    pub point: Option<DVec3>,
}

impl Scene {
    /// Row `p` over the light plane's face of `order × order` texels
    /// (`order²·C` values, channel-interleaved) and, for grey transport, the
    /// row's RGB albedo. Sub-samples behind the plane are integrated too:
    /// the caller decides from [`PlaneRow::point`] whether the row is lit.
    pub fn plane_row(
        &self,
        p: usize,
        plane: &LightPlane,
        order: usize,
        side: f64,
        row: &mut [f32],
        albedo: &mut [f32; 3],
    ) -> Result<PlaneRow> {
        if !(1..=1024).contains(&order) {
            return Err(plane_error("order", order, "1..=1024"));
        }
        if !(side.is_finite() && side > 0.0) {
            return Err(plane_error("face side", side, "finite and > 0"));
        }
        let texels = order * order;
        if row.len() != texels * self.channels as usize {
            let valid = format!("{} values", texels * self.channels as usize);
            return Err(plane_error("row length", row.len(), &valid));
        }
        let tables = Tables::new(self);
        let grid = Grid::face(order, side, plane.x_axis, plane.y_axis, -plane.normal());
        let mut scratch = Scratch::with_texels(self, texels);
        let stats = self.row_on(&tables, &grid, Some(plane), &mut scratch, p, row, albedo);
        Ok(PlaneRow {
            stats,
            point: self.mean_point(&tables, p),
        })
    }

    /// The mean hit point of row `p`'s sub-samples.
    fn mean_point(&self, tables: &Tables, p: usize) -> Option<DVec3> {
        let rot = self.rows.row_rotation(p);
        let (mut sum, mut hits) = (DVec3::ZERO, 0usize);
        for k in 0..self.rows.samples_per_row() as usize {
            if let Some(s) = self.rows.sample(self, p, k, tables.pixel_points(), rot) {
                sum += s.hit.point;
                hits += 1;
            }
        }
        (hits > 0).then(|| sum / hits as f64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn planes_locate_points_and_refuse_bad_axes() {
        let plane = LightPlane::new(
            DVec3::new(0.0, 2.0, 0.0),
            DVec3::X * 3.0,
            DVec3::new(0.5, 0.0, 1.0),
        )
        .unwrap();
        assert!((plane.normal() - DVec3::NEG_Y).length() < 1e-12);
        let p = DVec3::new(0.3, 0.5, -0.7);
        let (depth, position) = plane.locate(p);
        assert!((depth - 1.5).abs() < 1e-12);
        assert!((plane.point(position) + depth * plane.normal() - p).length() < 1e-12);
        for (x, y) in [
            (DVec3::X, DVec3::X * 2.0),
            (DVec3::ZERO, DVec3::Z),
            (DVec3::new(f64::NAN, 0.0, 0.0), DVec3::Z),
            (DVec3::X, DVec3::new(0.0, f64::INFINITY, 0.0)),
        ] {
            let err = LightPlane::new(DVec3::ZERO, x, y).unwrap_err().to_string();
            assert!(
                err.contains("light plane") && err.contains("valid"),
                "{err}"
            );
        }
        assert!(LightPlane::new(DVec3::splat(f64::NAN), DVec3::X, DVec3::Z).is_err());
    }
}
