//! A numpy matrix written as a raw store, checked as `ltm import` checks a
//! `.npy`: float32 or float64, shape `(P, M)` or `(P, M, C)` with
//! `P = width·height`, `M = 6·n²` (n a power of two), `C` 1 or 3, every
//! value finite as a float32.

use crate::arrays::float_shape;
use crate::errors::{self, value};
use ltm_codec::{Dims, Progress, RawHeader, RawWriter, Stage};
use numpy::ndarray::{ArrayViewD, Axis, Slice};
use numpy::{PyArrayDyn, PyArrayMethods};
use pyo3::prelude::*;
use std::path::{Path, PathBuf};

/// Bytes of rows per block of the store (as `ltm import`).
const BLOCK_BYTES: u64 = 16 << 20;

/// The matrix's dims from its shape and the image size; width and height
/// default to the square root of P.
fn dims(shape: &[usize], size: (Option<u32>, Option<u32>)) -> PyResult<Dims> {
    let (rows, cols, channels) = match shape[..] {
        [p, m] => (p, m, 1),
        [p, m, c] => (p, m, c),
        _ => {
            return Err(value(format!(
                "matrix shape {shape:?}: expected (P, M) or (P, M, C)"
            )))
        }
    };
    let side = (rows as f64).sqrt().round() as u32;
    let (width, height) = match size {
        (Some(w), Some(h)) => (w, h),
        (None, None) if side as usize * side as usize == rows => (side, side),
        (Some(w), None) if w > 0 && rows % w as usize == 0 => (w, (rows / w as usize) as u32),
        (None, Some(h)) if h > 0 && rows % h as usize == 0 => ((rows / h as usize) as u32, h),
        _ => {
            return Err(value(format!(
                "matrix has {rows} rows: give width and height with width·height = {rows}"
            )))
        }
    };
    if rows as u64 != width as u64 * height as u64 {
        return Err(value(format!(
            "matrix has {rows} rows but width {width} × height {height} = {}",
            width as u64 * height as u64
        )));
    }
    let n = ((cols / 6) as f64).sqrt().round() as u32;
    if cols == 0 || 6 * (n as usize) * (n as usize) != cols {
        return Err(value(format!(
            "matrix has {cols} columns: expected 6·n² cubemap texels (n a power of two)"
        )));
    }
    if channels != 1 && channels != 3 {
        return Err(value(format!(
            "matrix channels (third dimension) = {channels} is out of range (valid: 1 or 3)"
        )));
    }
    let dims = Dims::image(width, height, n, channels as u32);
    dims.validate().map_err(errors::codec)?;
    Ok(dims)
}

/// The rows `range` of `view` as float32, checked finite (the error names
/// the element as `(p, j, c)`).
fn block<T: Copy + Into<f64>>(
    view: &ArrayViewD<'_, T>,
    range: std::ops::Range<usize>,
    dims: Dims,
) -> PyResult<Vec<f32>> {
    let rows = view.slice_axis(Axis(0), Slice::from(range.clone()));
    let values: Vec<f32> = rows.iter().map(|&v| v.into() as f32).collect();
    if let Some(k) = values.iter().position(|v| !v.is_finite()) {
        let (row, c) = (dims.row_len(), dims.channels as usize);
        let e = range.start * row + k;
        return Err(value(format!(
            "matrix element ({}, {}, {}) is {} (NaN, infinite, or beyond float32)",
            e / row,
            e % row / c,
            e % c,
            values[k]
        )));
    }
    Ok(values)
}

/// The albedo image as `3·P` finite values: shape `(P, 3)` or `(H, W, 3)`.
fn albedo(obj: &Bound<'_, PyAny>, dims: Dims) -> PyResult<Vec<f32>> {
    let shape = float_shape(obj, "albedo")?;
    let (p, w, h) = (dims.pixels(), dims.width() as usize, dims.height() as usize);
    if shape != [p, 3] && shape != [h, w, 3] {
        return Err(value(format!(
            "albedo shape {shape:?}: expected ({p}, 3) or ({h}, {w}, 3)"
        )));
    }
    if dims.channels != 1 {
        return Err(value(
            "albedo goes with a grey (P, M) matrix; an RGB matrix carries its colour",
        ));
    }
    let values = crate::arrays::floats(obj, "albedo")?;
    if let Some((k, v)) = crate::arrays::first_non_finite(&values) {
        return Err(value(format!("albedo value {k} is {v}; it must be finite")));
    }
    Ok(values)
}

/// Writes the store block by block from `view`.
fn write_blocks<T: Copy + Into<f64>>(
    view: &ArrayViewD<'_, T>,
    header: RawHeader,
    albedo: Option<&[f32]>,
    path: &Path,
    progress: Progress<'_>,
) -> PyResult<PathBuf> {
    let mut writer = RawWriter::create(path, header).map_err(errors::codec)?;
    writer.discard_on_drop();
    let blocks = header.block_count();
    for b in 0..blocks {
        let range = header.block_range(b);
        let values = block(view, range.clone(), header.dims)?;
        let a = albedo.map(|a| &a[3 * range.start..3 * range.end]);
        writer.write_block(b, &values, a).map_err(errors::codec)?;
        progress.report(Stage::Import, (b + 1) as u64, blocks as u64);
    }
    writer.finish().map_err(errors::codec)
}

/// Writes `matrix` (and its albedo) as `DIR/matrix.raw`, with the
/// interpreter released while blocks are written.
pub fn write(
    py: Python<'_>,
    matrix: &Bound<'_, PyAny>,
    albedo_obj: Option<&Bound<'_, PyAny>>,
    size: (Option<u32>, Option<u32>),
    dir: &Path,
    progress: Progress<'_>,
) -> PyResult<PathBuf> {
    let shape = float_shape(matrix, "matrix")?;
    let dims = dims(&shape, size)?;
    let albedo = albedo_obj.map(|a| albedo(a, dims)).transpose()?;
    let header = RawHeader::new(dims, albedo.is_some(), BLOCK_BYTES);
    let path = dir.join("matrix.raw");
    let a = albedo.as_deref();
    if let Ok(m) = matrix.cast::<PyArrayDyn<f32>>() {
        let ro = m.try_readonly()?;
        let view = ro.as_array();
        return py.detach(|| write_blocks(&view, header, a, &path, progress));
    }
    let m = matrix.cast::<PyArrayDyn<f64>>()?;
    let ro = m.try_readonly()?;
    let view = ro.as_array();
    py.detach(|| write_blocks(&view, header, a, &path, progress))
}
