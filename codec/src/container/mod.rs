//! The `.ltm` container: everything a relighter needs, with each column
//! reachable without decoding the others. Layout in docs/FORMAT.md.
//!
//! ```text
//! header (24 bytes) | chunk directory (32 bytes × count) | directory CRC
//! META | ALBD | EMPT | SURF | MESH | NEAR | NORM (each optional) | DATA | PRIO (optional) | COLS
//! ```
//!
//! (Files of versions 1 to 6 hold COLS before DATA; readers find chunks by
//! tag.)
//!
//! Version 2 adds feature 4 and chunk `SURF`: the row layout (image pixels
//! or texture texels) and per-row surface data ([`Surface`](crate::Surface)). Version-1
//! files (features 1 at most) are still read. Version 5 adds feature 8 and
//! chunk `NORM`: each column's priority norm, so that a relighter can rank
//! lights by transport without decoding every column first. Version 6
//! adds feature 16 and chunk `MESH`: the receiving mesh of a texture-space
//! file ([`ReceiverMesh`](crate::ReceiverMesh)). Version 7 stores ALBD,
//! EMPT, SURF, MESH and COLS as zstd frames when that is smaller, and
//! writes COLS after DATA. Version 8 may store SURF and COLS in delta-coded
//! byte planes before zstd (`planes.rs`), and adds column encoding 5.
//! Version 9 adds the priors (PRIO) and column encoding 6; version 10
//! adds feature 64 and chunk `NEAR`: near-field rows
//! ([`PlaneRows`](crate::PlaneRows)), after MESH.
//!
//! Every chunk has a CRC-32 in the directory, except DATA whose columns
//! each have their own CRC in the column table. The directory is validated
//! (tags known and unique, offsets in range, sorted, non-overlapping) before
//! any chunk is read, and no allocation is sized by a field that has not
//! been checked against the dimensions.

mod directory;
mod meta;
mod planes;
mod prime;
mod read;
#[cfg(feature = "fuzzing")]
mod repair;
mod write;

pub use directory::{
    FEATURE_ALBEDO, FEATURE_COLUMN_NORMS, FEATURE_EMPTY_ROWS, FEATURE_NEAR_FIELD, FEATURE_PRIORS,
    FEATURE_RECEIVER_MESH, FEATURE_SURFACE, MAGIC, MAX_CHUNKS, MIN_VERSION, VERSION,
};
pub use meta::Meta;
pub(crate) use read::check_column_entry;
pub use read::{validate_bytes, LtmFile, LtmIndex};
#[cfg(feature = "fuzzing")]
pub use repair::{repair_checksums, unpack_chunks};
pub(crate) use write::write_pca_file;
pub use write::{LtmWriter, OptionalChunks};
