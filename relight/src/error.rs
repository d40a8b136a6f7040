//! The relighting crate's error type.

use std::io;
use std::path::PathBuf;

/// Every failure of `ltm-relight`. Messages name the offending value and,
/// where there is one, its valid range.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RelightError {
    /// A failure reported by the codec (opening or reading a raw store or an
    /// `.ltm` file).
    #[error(transparent)]
    Codec(#[from] ltm_codec::Error),
    /// Reading or writing a file failed at the operating-system level.
    #[error("{path}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What the system said.
        #[source]
        error: io::Error,
    },
    /// An image file could not be decoded or encoded.
    #[error("{path}: {detail}")]
    Image {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        detail: String,
    },
    /// An environment map that cannot be used as lighting: NaN or infinite
    /// pixels, a wrong shape.
    #[error("invalid environment map: {0}")]
    InvalidEnvMap(String),
    /// A parameter outside its valid range.
    #[error("{what} = {value} is out of range (valid: {valid})")]
    OutOfRange {
        /// The parameter.
        what: &'static str,
        /// Its value.
        value: String,
        /// The valid range.
        valid: String,
    },
    /// A rotation cache file that cannot be read: wrong magic, CRC,
    /// truncated, or a field out of its range.
    #[error("invalid rotation cache: {0}")]
    InvalidRotationCache(String),
    /// Any other unusable input.
    #[error("invalid input: {0}")]
    Invalid(String),
}

/// `Result` with [`RelightError`].
pub type Result<T> = std::result::Result<T, RelightError>;

impl RelightError {
    pub(crate) fn range(what: &'static str, value: impl ToString, valid: impl ToString) -> Self {
        RelightError::OutOfRange {
            what,
            value: value.to_string(),
            valid: valid.to_string(),
        }
    }

    #[cfg(any(feature = "exr", feature = "png", feature = "hdr"))]
    pub(crate) fn io(path: impl Into<PathBuf>, error: io::Error) -> Self {
        RelightError::Io {
            path: path.into(),
            error,
        }
    }

    #[cfg(any(feature = "exr", feature = "png", feature = "hdr"))]
    pub(crate) fn image(path: impl Into<PathBuf>, detail: impl ToString) -> Self {
        RelightError::Image {
            path: path.into(),
            detail: detail.to_string(),
        }
    }
}
