//! The baker's error type.

use std::io;
use std::path::PathBuf;

/// Every failure of `ltm-bake`. Messages name the file (or the command line),
/// the offending field or value, and the valid range.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum BakeError {
    /// Reading a scene file failed (missing, unreadable).
    #[error("{path}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What the system said.
        #[source]
        error: io::Error,
    },
    /// Reading a mesh file failed (missing, unreadable); `field` names the
    /// scene entry, e.g. `meshes[0].path`.
    #[error("{origin}: {field}: cannot read {path}")]
    MeshIo {
        /// The scene file (or "command line").
        origin: String,
        /// The scene entry naming the mesh.
        field: String,
        /// The mesh file, resolved against the scene file's directory.
        path: PathBuf,
        /// What the system said.
        #[source]
        error: io::Error,
    },
    /// The scene file is not valid TOML, or does not have the scene's
    /// structure (unknown or missing field, wrong type).
    #[error("{path}: {message}")]
    SceneSyntax {
        /// The scene file.
        path: PathBuf,
        /// What is wrong, with line and column.
        message: String,
    },
    /// A scene setting outside its valid range. `origin` is the scene file,
    /// or "command line" for an override.
    #[error("{origin}: {field} = {value} is out of range (valid: {valid})")]
    OutOfRange {
        /// The scene file, or "command line".
        origin: String,
        /// The setting, e.g. `camera.fov` or `--face-res`.
        field: String,
        /// Its value as given.
        value: String,
        /// The valid range.
        valid: String,
    },
    /// A scene setting that is in range but inconsistent (an unknown
    /// material name, a camera looking along its up vector, ...).
    #[error("{origin}: {field}: {message}")]
    InvalidScene {
        /// The scene file, or "command line".
        origin: String,
        /// The setting, e.g. `camera.up`.
        field: String,
        /// What is wrong, with the values involved and what is valid.
        message: String,
    },
    /// A mesh file that cannot be parsed, or whose contents are unusable
    /// (non-finite vertices, indices out of range, no triangle with area).
    #[error("{path}: malformed {format} mesh: {message}")]
    MalformedMesh {
        /// The mesh file.
        path: PathBuf,
        /// "OBJ", "PLY" or "unknown".
        format: &'static str,
        /// What is wrong, naming the first offending vertex, face or line.
        message: String,
    },
    /// The camera is enclosed by geometry seen from behind, as inside a
    /// closed object: probe rays from the eye in every direction all hit a
    /// surface, most of them its back side ([`crate::inside`]).
    #[error(
        "the camera at eye = [{}, {}, {}] appears to be inside geometry: probe rays in every direction \
         all hit a surface and {:.0} % of them its back side (limit {:.0} %); move the eye out of the object",
        eye[0], eye[1], eye[2], 100.0 * back_fraction, 100.0 * limit
    )]
    CameraInsideGeometry {
        /// The camera's eye, world units.
        eye: [f64; 3],
        /// Fraction of the probe rays that hit a back face.
        back_fraction: f64,
        /// The fraction above which the camera counts as inside.
        limit: f64,
    },
    /// The scene's geometry cannot be traced safely.
    #[error("scene geometry: {0}")]
    Geometry(String),
    /// The receiver of a texture-space bake cannot be parameterized.
    #[error("{path}: {parameterization} parameterization: {message}")]
    Parameterization {
        /// The receiver's mesh file.
        path: PathBuf,
        /// `uv` or `sphere`.
        parameterization: &'static str,
        /// What is wrong.
        message: String,
    },
    /// Writing the raw store failed.
    #[error(transparent)]
    Store(#[from] ltm_codec::Error),
}

/// `Result` with [`BakeError`].
pub type Result<T> = std::result::Result<T, BakeError>;

impl BakeError {
    pub(crate) fn io(path: impl Into<PathBuf>, error: io::Error) -> BakeError {
        BakeError::Io {
            path: path.into(),
            error,
        }
    }

    pub(crate) fn range(
        origin: impl ToString,
        field: impl ToString,
        value: impl ToString,
        valid: impl ToString,
    ) -> BakeError {
        BakeError::OutOfRange {
            origin: origin.to_string(),
            field: field.to_string(),
            value: value.to_string(),
            valid: valid.to_string(),
        }
    }

    pub(crate) fn invalid(
        origin: impl ToString,
        field: impl ToString,
        message: impl ToString,
    ) -> BakeError {
        BakeError::InvalidScene {
            origin: origin.to_string(),
            field: field.to_string(),
            message: message.to_string(),
        }
    }
}
