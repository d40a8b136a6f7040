//! Lighting from Python: a lat-long map (numpy array or EXR/HDR path),
//! or a cubemap already in the matrix's column order.

use crate::arrays::{first_non_finite, float_shape, floats};
use crate::errors::{self, value};
use ltm_relight::{EnvMap, Rotation};
use numpy::PyUntypedArray;
use pyo3::prelude::*;
use std::path::PathBuf;

/// Lighting as given, read while the interpreter is held; turned into a
/// cubemap ([`Light::cubemap`]) without it.
pub enum Light {
    /// A lat-long map from an array (width = 2·height).
    Map(EnvMap),
    /// A lat-long map file (EXR or Radiance HDR), read when needed.
    Path(PathBuf),
    /// Cubemap texels in column order (`j = face·n² + row·n + col`).
    Cubemap(Vec<[f32; 3]>),
}

/// RGB triples from a flat vector of `3·k` values, moved (no copy) when
/// its capacity allows.
fn triples(v: Vec<f32>) -> Vec<[f32; 3]> {
    bytemuck::allocation::try_cast_vec(v)
        .unwrap_or_else(|(_, v)| v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
}

impl Light {
    /// Reads `obj`: a path (`str` or `os.PathLike`), an `(H, 2H, 3)`
    /// lat-long array, or a cubemap array `(6, n, n, 3)` or `(6·n², 3)`.
    pub fn extract(obj: &Bound<'_, PyAny>) -> PyResult<Light> {
        // An array is no path: not asking os.fspath spares a TypeError
        // per frame.
        if obj.cast::<PyUntypedArray>().is_err() {
            if let Ok(path) = obj.extract::<PathBuf>() {
                return Ok(Light::Path(path));
            }
        }
        let shape = float_shape(obj, "light")?;
        let values = floats(obj, "light")?;
        match shape[..] {
            [h, w, 3] => Ok(Light::Map(
                EnvMap::new(w, h, triples(values)).map_err(errors::relight)?,
            )),
            [6, n, m, 3] if n == m => Light::cube(values),
            [_, 3] => Light::cube(values),
            _ => Err(value(format!(
                "light: shape {shape:?}, expected a lat-long map (H, 2·H, 3) or a cubemap (6, n, n, 3) or (6·n², 3)"
            ))),
        }
    }

    fn cube(values: Vec<f32>) -> PyResult<Light> {
        if let Some((k, v)) = first_non_finite(&values) {
            return Err(value(format!(
                "light: cubemap texel {} channel {} is {v}; radiance must be finite",
                k / 3,
                k % 3
            )));
        }
        Ok(Light::Cubemap(triples(values)))
    }

    /// The lighting as `6·n²` cubemap texels, rotated; a cubemap given as
    /// texels takes no rotation (and is moved, not copied).
    pub fn cubemap(self, n: usize, rotation: &Rotation) -> PyResult<Vec<[f32; 3]>> {
        match self {
            Light::Map(env) => Ok(env.to_cubemap(n, rotation)),
            Light::Path(p) => Ok(EnvMap::load(&p)
                .map_err(errors::relight)?
                .to_cubemap(n, rotation)),
            Light::Cubemap(texels) => {
                if texels.len() != 6 * n * n {
                    return Err(value(format!(
                        "light: cubemap of {} texels, this matrix needs 6·{n}² = {}",
                        texels.len(),
                        6 * n * n
                    )));
                }
                if *rotation != Rotation::IDENTITY {
                    return Err(value(
                        "rotation applies to lat-long maps; rotate a cubemap before passing it",
                    ));
                }
                Ok(texels)
            }
        }
    }
}

/// A rotation of yaw, pitch and roll in degrees (`ltm relight --rotate`),
/// each finite.
pub fn rotation(r: Option<(f64, f64, f64)>) -> PyResult<Rotation> {
    match r {
        None => Ok(Rotation::IDENTITY),
        Some((y, p, r)) if [y, p, r].iter().all(|v| v.is_finite()) => Ok(Rotation::new(y, p, r)),
        Some(r) => Err(value(format!(
            "rotation {r:?}: yaw, pitch and roll must be finite degrees"
        ))),
    }
}
