//! The codec's error type.

use std::io;
use std::path::PathBuf;

/// Every failure of `ltm-codec`. Messages name the offending value and the
/// valid range.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A parameter or header field outside its valid range.
    #[error("{what} = {value} is out of range (valid: {valid})")]
    OutOfRange {
        what: &'static str,
        value: String,
        valid: String,
    },
    /// A caller-provided buffer that is too short.
    #[error("{what}: buffer holds {len} values, needs {need}")]
    BufferTooSmall {
        what: &'static str,
        len: usize,
        need: usize,
    },
    /// Reading or writing a file failed.
    #[error("{path}: {error}")]
    Io { path: PathBuf, error: io::Error },
    /// The file is not of the expected kind.
    #[error("{path}: not {expected} (magic bytes {found:02x?})")]
    BadMagic {
        path: PathBuf,
        expected: &'static str,
        found: Vec<u8>,
    },
    /// The file was written by a newer format version.
    #[error("{what} format version {found} is not supported (this build reads up to {supported})")]
    Version {
        what: &'static str,
        found: u32,
        supported: u32,
    },
    /// Structural damage: truncation, bad offsets, inconsistent fields.
    #[error("corrupt {what}: {detail}")]
    Corrupt { what: &'static str, detail: String },
    /// A chunk whose checksum does not match its bytes.
    #[error("CRC mismatch in {chunk}: stored {stored:08x}, computed {computed:08x}")]
    Crc {
        chunk: String,
        stored: u32,
        computed: u32,
    },
    /// Input data that cannot be encoded (NaN, infinity, wrong dtype, ...).
    #[error("invalid input: {0}")]
    Invalid(String),
    /// A numerical method that failed on its input (a decomposition that
    /// did not converge).
    #[error("{what}: {detail}")]
    Numerical {
        /// The computation, e.g. `"PCA"`.
        what: &'static str,
        /// What failed, with the sizes involved.
        detail: String,
    },
}

/// `Result` with the codec's [`Error`].
pub type Result<T> = std::result::Result<T, Error>;

impl Error {
    pub(crate) fn range(what: &'static str, value: impl ToString, valid: impl ToString) -> Error {
        Error::OutOfRange {
            what,
            value: value.to_string(),
            valid: valid.to_string(),
        }
    }

    pub(crate) fn corrupt(what: &'static str, detail: impl ToString) -> Error {
        Error::Corrupt {
            what,
            detail: detail.to_string(),
        }
    }

    pub(crate) fn io(path: impl Into<PathBuf>, error: io::Error) -> Error {
        Error::Io {
            path: path.into(),
            error,
        }
    }
}
