//! The codec's error type.

use std::io;
use std::path::PathBuf;

/// Every failure of `ltm-codec`. Messages name the offending value and the
/// valid range.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A parameter or header field outside its valid range.
    #[error("{what} = {value} is out of range (valid: {valid})")]
    OutOfRange {
        /// The parameter or field.
        what: &'static str,
        /// Its value.
        value: String,
        /// The valid range.
        valid: String,
    },
    /// A caller-provided buffer that is too short.
    #[error("{what}: buffer holds {len} values, needs {need}")]
    BufferTooSmall {
        /// The buffer.
        what: &'static str,
        /// Its length.
        len: usize,
        /// The length needed.
        need: usize,
    },
    /// Reading or writing a file failed.
    #[error("{path}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What the system said.
        #[source]
        error: io::Error,
    },
    /// A part of a sharded bake that cannot be merged: the part and the
    /// problem.
    #[error("{}: {problem}", part.display())]
    Part {
        /// The part's file.
        part: PathBuf,
        /// What is wrong with it.
        problem: String,
    },
    /// The file is not of the expected kind.
    #[error("{path}: not {expected} (magic bytes {found:02x?})")]
    BadMagic {
        /// The file.
        path: PathBuf,
        /// The kind of file expected.
        expected: &'static str,
        /// Its first bytes.
        found: Vec<u8>,
    },
    /// A file of the other kind: a raw store where an `.ltm` file is
    /// wanted, or an `.ltm` file where a raw store is wanted.
    #[error("{path}: {is}, not {wanted}: {hint}")]
    WrongKind {
        /// The file.
        path: PathBuf,
        /// What the file is.
        is: &'static str,
        /// The kind of file expected.
        wanted: &'static str,
        /// What to do instead.
        hint: String,
    },
    /// The file was written by a newer format version.
    #[error("{what} format version {found} is not supported (this build reads up to {supported})")]
    Version {
        /// The format.
        what: &'static str,
        /// The file's version.
        found: u32,
        /// The newest version this build reads.
        supported: u32,
    },
    /// Structural damage: truncation, bad offsets, inconsistent fields.
    #[error("corrupt {what}: {detail}")]
    Corrupt {
        /// The damaged structure.
        what: &'static str,
        /// What is wrong with it.
        detail: String,
    },
    /// A chunk whose checksum does not match its bytes.
    #[error("CRC mismatch in {chunk}: stored {stored:08x}, computed {computed:08x}")]
    Crc {
        /// The chunk or column.
        chunk: String,
        /// The checksum stored in the file.
        stored: u32,
        /// The checksum of the bytes.
        computed: u32,
    },
    /// An allocation sized by a file or argument that exceeds what is left
    /// of the memory budget ([`Limits`](crate::Limits)) passed in.
    #[error("{what} needs {needed} bytes, more than the {available} bytes left of the memory budget of {limit} bytes (raise the budget if the file is trusted)")]
    Limit {
        /// What would be allocated.
        what: String,
        /// Bytes needed.
        needed: u64,
        /// Bytes of the budget not charged yet.
        available: u64,
        /// The budget in force.
        limit: u64,
    },
    /// An allocation within the memory budget that the system refused.
    #[error("{what} needs {needed} bytes, which the system could not allocate (memory budget {limit} bytes: lower it to fit the memory available)")]
    OutOfMemory {
        /// What would be allocated.
        what: String,
        /// Bytes needed.
        needed: u64,
        /// The budget in force.
        limit: u64,
    },
    /// An output that cannot be written as named: it is an input, another
    /// output, a folder, a device or FIFO, or in a folder that does not
    /// exist or is not writable.
    #[error("{role} {path}: {reason}")]
    Output {
        /// How the command line names the output (e.g. `"-o"`).
        role: String,
        /// The output's path.
        path: PathBuf,
        /// Why it was refused and what to do instead.
        reason: String,
    },
    /// Another run holds the lock of this output (`PATH.lock`).
    #[error("{path}: another ltm run is writing this output (it holds the lock {lock}); wait for it to end or choose another output")]
    OutputBusy {
        /// The output.
        path: PathBuf,
        /// The lock file.
        lock: PathBuf,
    },
    /// The output's filesystem has less free space than the output needs.
    #[error("{path}: needs {need} bytes but its filesystem has {free} bytes free; free some space or choose another folder")]
    NoSpace {
        /// The output.
        path: PathBuf,
        /// Bytes the output still needs.
        need: u64,
        /// Bytes available to this user.
        free: u64,
    },
    /// Input data that cannot be encoded (NaN, infinity, wrong dtype, ...).
    #[error("invalid input: {0}")]
    Invalid(String),
    /// Columns given out of order: a range that does not start where the
    /// previous one ended, or that runs past the matrix's last column.
    #[error("{what}: columns {start}..{end} are out of order (valid: a range starting at column {expected} and ending at most at {total})")]
    ColumnRange {
        /// Who was given the columns.
        what: &'static str,
        /// The first column given.
        start: usize,
        /// One past the last column given.
        end: usize,
        /// The column the range had to start at.
        expected: usize,
        /// The matrix's columns.
        total: usize,
    },
    /// Parts that cannot be combined because they were made with different
    /// settings (analyses of other matrices or coding options, a plan for
    /// another analysis).
    #[error("{what}: {field} is {found}, expected {expected}")]
    SettingsDiffer {
        /// What was combined.
        what: &'static str,
        /// The first setting that differs.
        field: &'static str,
        /// Its value in the part given.
        found: String,
        /// Its value in the part it was combined with.
        expected: String,
    },
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

    /// A raw store given where an `.ltm` file is wanted: names the
    /// command that compresses it.
    pub(crate) fn raw_not_ltm(path: &std::path::Path) -> Error {
        Error::WrongKind {
            path: path.into(),
            is: "a raw transport store (from `ltm bake` or `ltm import`)",
            wanted: "an .ltm file",
            hint: format!(
                "compress it first: `ltm compress {} -o {}`",
                path.display(),
                path.with_extension("ltm").display()
            ),
        }
    }

    /// A file that is not an `.ltm` file: a scene file (TOML, by its name)
    /// gets the commands that make one from it, anything else its first
    /// bytes.
    pub(crate) fn not_ltm(path: &std::path::Path, head: &[u8]) -> Error {
        let ext = path.extension().map(|e| e.to_string_lossy().to_lowercase());
        if ext.as_deref() == Some("toml") {
            let raw = path.with_extension("raw");
            return Error::WrongKind {
                path: path.into(),
                is: "a scene file",
                wanted: "an .ltm file",
                hint: format!(
                    "bake and compress it first: `ltm bake {} -o {}`, then `ltm compress {} -o {}`",
                    path.display(),
                    raw.display(),
                    raw.display(),
                    path.with_extension("ltm").display()
                ),
            };
        }
        Error::BadMagic {
            path: path.into(),
            expected: "an .ltm file",
            found: head.to_vec(),
        }
    }

    /// An `.ltm` file given where a raw store is wanted.
    pub(crate) fn ltm_not_raw(path: &std::path::Path) -> Error {
        Error::WrongKind {
            path: path.into(),
            is: "an .ltm file (already compressed)",
            wanted: "an ltm raw transport store",
            hint: "this command reads the raw store from `ltm bake` or `ltm import`; \
                   relight, render, view, inspect and export take .ltm files"
                .into(),
        }
    }

    pub(crate) fn io(path: impl Into<PathBuf>, error: io::Error) -> Error {
        Error::Io {
            path: path.into(),
            error,
        }
    }
}
