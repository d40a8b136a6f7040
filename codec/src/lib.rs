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

pub mod bands;
pub mod baseline;
mod bytes;
mod camera;
pub mod column;
pub mod compress;
pub mod container;
pub mod cubemap;
mod decode;
mod dims;
mod empty;
pub mod entropy;
mod error;
mod fileio;
mod limits;
mod mesh;
pub mod nearfield;
pub mod npy;
pub mod output;
pub mod pca;
mod progress;
/// The quantizer's internals: public only with the `benchmarks` feature.
#[cfg(feature = "benchmarks")]
pub mod quant;
#[cfg(not(feature = "benchmarks"))]
mod quant;
pub mod raw;
mod rsvd;
mod surface;
pub mod wavelet;

pub use baseline::{PcaBasis, ShProjection, MAX_SH_ORDER};
pub use camera::{ImageCamera, MAX_FACING_AWAY, MAX_RESIDUAL_PX, MIN_CAMERA_POINTS};
pub use column::SparseColumn;
pub use compress::{
    compress, compress_pca, default_mem_budget, Analysis, CodeOptions, Coder, CompressOptions,
    CompressStats, Entropy, Mode, PcaOptions, PcaStats, Plan, Quantizer, Target, TransposeOptions,
    Transposed,
};
pub use container::{LtmFile, LtmWriter, Meta, OptionalChunks};
pub use decode::ColumnDecoder;
pub use dims::{
    Dims, LightBasis, Parameterization, RowLayout, MAX_FACE_RES, MAX_PIXELS, MAX_SIDE,
    MAX_TEXTURE_SIZE,
};
pub use empty::EmptyRows;
pub use error::{Error, Result};
pub use limits::{Charge, Limits};
pub use mesh::{
    ReceiverMesh, MAX_MESH_ELEMENTS, MESH_HEADER_LEN, MESH_TRIANGLE_LEN, MESH_VERTEX_LEN,
};
pub use nearfield::{NearQuantization, PlaneBasis, PlaneRows};
pub use output::{AtomicFile, Claim, OutputLock, RunFiles};
pub use pca::PcaModel;
pub use progress::{Progress, Stage, Step};
pub use quant::BandWeights;
pub use raw::{RawHeader, RawStore, RawWriter, RowSpan};
pub use surface::{Surface, SurfacePoint, SURFACE_RECORD_LEN};
pub use wavelet::Filter;
