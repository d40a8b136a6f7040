//! `ltm.open` and the `File` it returns.

use crate::arrays::to_numpy;
use crate::errors::{self, value};
use crate::relighter::Relighter;
use ltm_codec::{Dims, Limits, LtmFile};
use ltm_relight::Source;
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyTuple};
use std::path::PathBuf;
use std::sync::Arc;

/// A memory budget in bytes: an int, or a size as `ltm --max-memory`
/// takes it (a number with an optional K, M, G or T suffix, binary units).
pub fn limits(max_memory: Option<&Bound<'_, PyAny>>) -> PyResult<Limits> {
    let Some(m) = max_memory else {
        return Ok(Limits::for_machine());
    };
    let bytes = match m.extract::<u64>() {
        Ok(b) => b,
        Err(_) => parse_size(&m.extract::<String>().map_err(|_| {
            value("max_memory: expected a number of bytes or a size such as '512M'")
        })?)?,
    };
    if bytes < 1 << 20 {
        return Err(value(format!(
            "max_memory = {bytes} bytes is out of range (valid: at least 1M)"
        )));
    }
    Ok(Limits::with_max_alloc(bytes))
}

/// Parses `512M`, `1.5G`, `4096`.
fn parse_size(s: &str) -> PyResult<u64> {
    let t = s.trim();
    let (num, shift) = match t.char_indices().last() {
        Some((i, c)) if c.is_ascii_alphabetic() => {
            let shift = match c.to_ascii_uppercase() {
                'K' => 10,
                'M' => 20,
                'G' => 30,
                'T' => 40,
                _ => return Err(value(format!("max_memory '{s}': unknown suffix {c}"))),
            };
            (&t[..i], shift)
        }
        _ => (t, 0),
    };
    match num.parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 && v * f64::powi(2.0, shift) < 1.8e19 => {
            Ok((v * f64::powi(2.0, shift)) as u64)
        }
        _ => Err(value(format!(
            "max_memory '{s}' is not a size (e.g. 512M, 1.5G)"
        ))),
    }
}

/// Where a file comes from: a path (`str` or `os.PathLike`) or its bytes.
fn source(obj: &Bound<'_, PyAny>) -> PyResult<Source> {
    if let Ok(b) = obj.cast::<PyBytes>() {
        return Ok(Source::Bytes(Arc::from(b.as_bytes())));
    }
    match obj.extract::<PathBuf>() {
        Ok(p) => Ok(Source::Path(p)),
        Err(_) => Err(value(
            "open: expected a path (str or os.PathLike) or the file's bytes",
        )),
    }
}

/// A compressed transport matrix (`.ltm`), opened and validated.
#[pyclass(module = "ltm", name = "File", frozen)]
pub struct File {
    source: Source,
    file: LtmFile,
    limits: Limits,
}

/// Opens an `.ltm` file from a path or from bytes (see `ltm.pyi`).
#[pyfunction]
#[pyo3(signature = (source, max_memory = None))]
pub fn open(
    py: Python<'_>,
    source: &Bound<'_, PyAny>,
    max_memory: Option<&Bound<'_, PyAny>>,
) -> PyResult<File> {
    let source = self::source(source)?;
    let limits = limits(max_memory)?;
    let file = py
        .detach(|| source.clone().open(&limits))
        .map_err(errors::relight)?;
    Ok(File {
        source,
        file,
        limits,
    })
}

/// The shape of the dense matrix: `(P, M)` or `(P, M, C)`.
pub fn matrix_shape(dims: Dims) -> Vec<usize> {
    let mut shape = vec![dims.pixels(), dims.lights()];
    if dims.channels != 1 {
        shape.push(dims.channels as usize);
    }
    shape
}

/// The matrix's dimensions as a dict.
pub fn dims_dict<'py>(py: Python<'py>, dims: Dims) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("width", dims.width())?;
    d.set_item("height", dims.height())?;
    d.set_item("rows", dims.pixels())?;
    d.set_item("face_res", dims.face_res())?;
    d.set_item("lights", dims.lights())?;
    d.set_item("channels", dims.channels)?;
    let layout = if dims.rows.is_texture() {
        "texture"
    } else {
        "image"
    };
    d.set_item("layout", layout)?;
    Ok(d)
}

#[pymethods]
impl File {
    /// The matrix's dimensions: width, height, rows, face_res, lights,
    /// channels and layout ("image" or "texture").
    #[getter]
    fn dims<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        dims_dict(py, self.file.meta().dims)
    }

    /// The mode: "2d", "4d", "adaptive" or "pca".
    #[getter]
    fn mode(&self) -> &'static str {
        self.file.meta().mode.name()
    }

    /// The measured relative L2 error of the whole decoded matrix.
    #[getter]
    fn error(&self) -> f32 {
        self.file.meta().achieved_error
    }

    /// The file's size in bytes.
    #[getter]
    fn size(&self) -> u64 {
        self.file.file_bytes()
    }

    /// The shape `export()` returns: `(P, M)` or `(P, M, C)`.
    #[getter]
    fn shape<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyTuple>> {
        PyTuple::new(py, matrix_shape(self.file.meta().dims))
    }

    /// Everything the header says (`ltm inspect`'s fields) as a dict.
    #[getter]
    fn meta<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let m = self.file.meta();
        let d = PyDict::new(py);
        d.set_item("mode", m.mode.name())?;
        d.set_item("row_filter", m.row_filter.name())?;
        d.set_item("col_filter", m.col_filter.name())?;
        d.set_item("bits", m.bits)?;
        d.set_item("seed", m.seed)?;
        d.set_item("target_error", m.target_error)?;
        d.set_item("achieved_error", m.achieved_error)?;
        d.set_item("keep", m.terms)?;
        d.set_item("file_bytes", self.file.file_bytes())?;
        d.set_item("raw_bytes", m.dims.raw_bytes())?;
        d.set_item("has_albedo", self.file.albedo().is_some())?;
        d.set_item("pca_rank", self.file.pca().map_or(0, |p| p.rank()))?;
        d.set_item("surface_rows", self.file.surface().map(|s| s.valid_count()))?;
        d.set_item("dims", dims_dict(py, m.dims)?)?;
        Ok(d)
    }

    /// The decoded matrix as float32, the layout of `ltm export`: shape
    /// `(P, M)` or `(P, M, C)`, the pixel lighting basis. The dense matrix
    /// is charged to the file's memory budget (MemoryError beyond it).
    fn export<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        let data = py
            .detach(|| ltm_codec::npy::decode_matrix(&self.file, &self.limits))
            .map_err(errors::codec)?;
        to_numpy(py, data, &matrix_shape(self.file.meta().dims))
    }

    /// A relighter for this file, charged to the same memory budget; with
    /// `preload`, every column is decoded now instead of when a frame first
    /// needs it.
    #[pyo3(signature = (preload = false))]
    fn relighter(&self, py: Python<'_>, preload: bool) -> PyResult<Relighter> {
        Relighter::open(py, self.source.clone(), &self.file, &self.limits, preload)
    }

    fn __repr__(&self) -> String {
        let dims = self.file.meta().dims;
        format!(
            "<ltm.File {} {}x{} rows, {} lights, {} channel(s), {} bytes, error {:.5}>",
            self.file.meta().mode.name(),
            dims.width(),
            dims.height(),
            dims.lights(),
            dims.channels,
            self.file.file_bytes(),
            self.file.meta().achieved_error
        )
    }
}
