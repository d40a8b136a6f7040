//! The libraries' errors as Python exceptions, each carrying the Rust
//! message (with its causes, as the CLI prints them): `MemoryError` for a
//! memory budget, `OSError` (or its `FileNotFoundError` and
//! `PermissionError` subclasses) for I/O, `ValueError` for bad input.

use ltm_bake::BakeError;
use ltm_codec::Error as CodecError;
use ltm_relight::RelightError;
use pyo3::exceptions::{
    PyFileNotFoundError, PyMemoryError, PyOSError, PyPermissionError, PyRuntimeError, PyValueError,
};
use pyo3::PyErr;
use std::error::Error;
use std::io::ErrorKind;

/// The error's message followed by each of its sources.
fn message(e: &(dyn Error + 'static)) -> String {
    let mut text = e.to_string();
    let mut source = e.source();
    while let Some(s) = source {
        let part = s.to_string();
        if !text.ends_with(&part) {
            text.push_str(": ");
            text.push_str(&part);
        }
        source = s.source();
    }
    text
}

/// An `OSError` of the kind of the first `io::Error` in `e`'s chain.
fn os_error(e: &(dyn Error + 'static)) -> PyErr {
    let msg = message(e);
    let mut source: Option<&(dyn Error + 'static)> = Some(e);
    while let Some(s) = source {
        if let Some(io) = s.downcast_ref::<std::io::Error>() {
            return match io.kind() {
                ErrorKind::NotFound => PyFileNotFoundError::new_err(msg),
                ErrorKind::PermissionDenied => PyPermissionError::new_err(msg),
                ErrorKind::OutOfMemory => PyMemoryError::new_err(msg),
                _ => PyOSError::new_err(msg),
            };
        }
        source = s.source();
    }
    PyOSError::new_err(msg)
}

/// A codec error as its Python exception.
pub fn codec(e: CodecError) -> PyErr {
    match e {
        CodecError::Limit { .. } | CodecError::OutOfMemory { .. } => {
            PyMemoryError::new_err(message(&e))
        }
        CodecError::Io { .. }
        | CodecError::Output { .. }
        | CodecError::OutputBusy { .. }
        | CodecError::NoSpace { .. } => os_error(&e),
        CodecError::Numerical { .. } => PyRuntimeError::new_err(message(&e)),
        _ => PyValueError::new_err(message(&e)),
    }
}

/// A relighting error as its Python exception.
pub fn relight(e: RelightError) -> PyErr {
    match e {
        RelightError::Codec(c) => codec(c),
        RelightError::Io { .. } => os_error(&e),
        _ => PyValueError::new_err(message(&e)),
    }
}

/// A bake error as its Python exception.
pub fn bake(e: BakeError) -> PyErr {
    match e {
        BakeError::Store(c) => codec(c),
        BakeError::Io { .. } | BakeError::MeshIo { .. } => os_error(&e),
        _ => PyValueError::new_err(message(&e)),
    }
}

/// A `ValueError` with this message.
pub fn value(msg: impl Into<String>) -> PyErr {
    PyValueError::new_err(msg.into())
}
