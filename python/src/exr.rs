//! `ltm.read_exr` and `ltm.write_exr`: the RGB OpenEXR images the CLI
//! reads (environment maps) and writes (relit and exact images).

use crate::arrays::{self, float_shape, floats};
use crate::errors::{self, value};
use ltm_relight::Image;
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use std::path::PathBuf;

/// Reads an OpenEXR file's first RGB layer as an `(H, W, 3)` float32 array.
#[pyfunction]
pub fn read_exr<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    let image = py
        .detach(|| Image::read_exr(&path))
        .map_err(errors::relight)?;
    arrays::image(py, image)
}

/// Writes an `(H, W, 3)` array as a 32-bit float RGB OpenEXR file
/// (lossless, atomically).
#[pyfunction]
pub fn write_exr(py: Python<'_>, path: PathBuf, image: &Bound<'_, PyAny>) -> PyResult<()> {
    let shape = float_shape(image, "image")?;
    let [h, w, 3] = shape[..] else {
        return Err(value(format!("image shape {shape:?}: expected (H, W, 3)")));
    };
    let data = floats(image, "image")?;
    let data = data.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    let image = Image::from_data(w, h, data).map_err(errors::relight)?;
    py.detach(|| image.write_exr(&path))
        .map_err(errors::relight)
}
