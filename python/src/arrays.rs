//! numpy arrays in and out: float arrays read as `f32` (float64 rounded,
//! as `ltm import` reads it), images and matrices handed to numpy without a
//! copy.

use crate::errors::value;
use ltm_relight::Image;
use numpy::ndarray::{ArrayD, IxDyn};
use numpy::{PyArrayDyn, PyArrayMethods, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::prelude::*;

/// The array's shape, failing with a `ValueError` that names `what` when
/// `obj` is not a float32 or float64 numpy array.
pub fn float_shape(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<Vec<usize>> {
    let arr = obj.cast::<PyUntypedArray>().map_err(|_| {
        let kind = obj.get_type().name().map_or("?".into(), |n| n.to_string());
        value(format!("{what}: expected a numpy array, got {kind}"))
    })?;
    if obj.cast::<PyArrayDyn<f32>>().is_err() && obj.cast::<PyArrayDyn<f64>>().is_err() {
        let dtype = arr.dtype().str().map_or("?".into(), |s| s.to_string());
        return Err(value(format!(
            "{what}: dtype {dtype}, expected float32 or float64"
        )));
    }
    Ok(arr.shape().to_vec())
}

/// The values of a float32 or float64 array (checked by [`float_shape`])
/// in C order, as `f32`.
pub fn floats(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<Vec<f32>> {
    float_shape(obj, what)?;
    if let Ok(a) = obj.cast::<PyArrayDyn<f32>>() {
        let ro = a.try_readonly()?;
        // `as_slice` also takes a Fortran-ordered array, in memory order:
        // only a C-ordered one is copied whole.
        return Ok(match ro.as_slice() {
            Ok(s) if a.is_c_contiguous() => s.to_vec(),
            _ => ro.as_array().iter().copied().collect(),
        });
    }
    let a = obj.cast::<PyArrayDyn<f64>>()?;
    let ro = a.try_readonly()?;
    Ok(ro.as_array().iter().map(|&v| v as f32).collect())
}

/// The first value that is not finite as an `f32`: its flat index and
/// value.
pub fn first_non_finite(values: &[f32]) -> Option<(usize, f32)> {
    // A branch-free pass first (vectorized), the search only on failure.
    if values.iter().fold(true, |ok, v| ok & v.is_finite()) {
        return None;
    }
    values
        .iter()
        .position(|v| !v.is_finite())
        .map(|k| (k, values[k]))
}

/// RGB triples as a flat vector, moved (no copy).
pub fn flatten(data: Vec<[f32; 3]>) -> Vec<f32> {
    bytemuck::allocation::cast_vec(data)
}

/// A flat vector as a numpy array of `shape`, without copying it (one
/// array object, made in its shape).
pub fn to_numpy<'py>(
    py: Python<'py>,
    data: Vec<f32>,
    shape: &[usize],
) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    let array = ArrayD::from_shape_vec(IxDyn(shape), data).map_err(|e| value(e.to_string()))?;
    Ok(PyArrayDyn::from_owned_array(py, array))
}

/// An image as an `(H, W, 3)` float32 array, without copying it.
pub fn image<'py>(py: Python<'py>, image: Image) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    let shape = [image.height, image.width, 3];
    to_numpy(py, flatten(image.data), &shape)
}
