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

mod bytes;
pub mod compress;
pub mod container;
pub mod cubemap;
mod decode;
mod error;
mod mmap;
pub mod npy;
pub mod pca;
pub mod quant;
pub mod raw;
mod rows;
pub mod sh;
pub mod wavelet;

pub use bytes::MAX_ALLOC_BYTES;
pub use compress::{compress, CompressOptions, CompressStats, Stage, Target, Transposed};
pub use container::{LtmFile, LtmWriter, Meta, Mode, SparseColumn};
pub use decode::ColumnDecoder;
pub use error::{Error, Result};
pub use pca::PcaBasis;
pub use raw::{Dims, RawHeader, RawStore, RawWriter};
pub use sh::{ShProjection, MAX_SH_ORDER};
pub use wavelet::Filter;
