//! `import ltm`: the codec and the relighter from Python, numpy arrays in
//! and out. The interpreter is released while files open, matrices
//! compress and frames relight; errors are `ValueError` (bad input),
//! `OSError` (I/O) and `MemoryError` (the memory budget), each with the
//! libraries' message. `ltm.pyi` documents the API.

mod arrays;
mod bake;
mod compress;
mod errors;
mod exr;
mod file;
mod light;
mod progress;
mod relighter;

use pyo3::prelude::*;

/// Compressed precomputed light-transport matrices: compress, open,
/// export and relight them from Python.
#[pymodule]
fn ltm(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("DEFAULT_WAVELET_TERMS", relighter::DEFAULT_WAVELET_TERMS)?;
    m.add_class::<file::File>()?;
    m.add_class::<relighter::Relighter>()?;
    m.add_function(wrap_pyfunction!(file::open, m)?)?;
    m.add_function(wrap_pyfunction!(compress::compress, m)?)?;
    m.add_function(wrap_pyfunction!(bake::bake, m)?)?;
    m.add_function(wrap_pyfunction!(bake::reference, m)?)?;
    m.add_function(wrap_pyfunction!(exr::read_exr, m)?)?;
    m.add_function(wrap_pyfunction!(exr::write_exr, m)?)?;
    Ok(())
}
