//! `ltm-codec`: the leaf crate of ltm. It owns the wavelet filter bank, the
//! cubemap convention, the raw transport store and the `.ltm` container.
//!
//! The codec follows Cheslack-Postava et al. 2007, "4D Compression and
//! Relighting with High-Resolution Light Transport Matrices": rows are
//! wavelet-transformed over each cube face (Ng et al. 2003), columns are
//! transformed as images to an adaptively chosen depth. The linear fits the
//! codec is measured against, PCA ([`PcaBasis`], Eigentransport) and
//! spherical harmonics ([`ShProjection`]), stream the raw store the same way.

#![deny(unsafe_code)]
#![warn(missing_docs)]

mod bytes;
pub mod compress;
pub mod container;
pub mod cubemap;
mod decode;
mod dims;
pub mod eigen;
mod empty;
pub mod entropy;
mod error;
mod fileio;
mod limits;
mod mmap;
pub mod npy;
mod output;
pub mod pca;
/// The quantizer's internals: public only with the `benchmarks` feature.
#[cfg(feature = "benchmarks")]
pub mod quant;
#[cfg(not(feature = "benchmarks"))]
mod quant;
pub mod raw;
mod rows;
pub mod sh;
mod surface;
pub mod wavelet;

pub use compress::{
    compress, Analysis, CodeOptions, Coder, CompressOptions, CompressStats, Plan, Stage, Target,
    TransposeOptions, Transposed,
};
pub use container::{Entropy, LtmFile, LtmWriter, Meta, Mode, OptionalChunks, SparseColumn};
pub use decode::ColumnDecoder;
pub use dims::{
    Dims, LightBasis, Parameterization, RowLayout, MAX_FACE_RES, MAX_PIXELS, MAX_SIDE,
    MAX_TEXTURE_SIZE,
};
pub use eigen::{compress_pca, PcaModel, PcaOptions, PcaStats};
pub use empty::EmptyRows;
pub use error::{Error, Result};
pub use limits::{Charge, Limits};
pub use output::AtomicFile;
pub use pca::PcaBasis;
pub use quant::BandWeights;
pub use raw::{RawHeader, RawStore, RawWriter};
pub use sh::{ShProjection, MAX_SH_ORDER};
pub use surface::{Surface, SurfacePoint, SURFACE_RECORD_LEN};
pub use wavelet::Filter;
