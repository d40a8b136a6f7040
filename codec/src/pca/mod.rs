//! The PCA mode (`Mode::Pca`): Eigentransport (Nowrouzezahrai, Simari,
//! Kalogerakis and Fiume, "Eigentransport for efficient and accurate
//! all-frequency relighting", 2007) as a file mode. The matrix is stored as
//! its mean row `μ`, its top `K` eigen-transports `B` (`K × N`, `N = M·C`)
//! and every pixel's `K` coefficients `F` (`P × K`):
//! `T̂[p] = μ + Σ_a F[p][a]·B[a]`. A frame projects the lighting on `μ` and
//! `B` once and each pixel is a `K`-term dot product.
//!
//! [`compress_pca`](crate::compress_pca) fits the basis by a randomized SVD streamed over the raw
//! store (`fit.rs`), quantizes `B` and `F` with one scale per component
//! ([`QuantizedMatrix`]) and measures the error of exactly what a decoder
//! reconstructs ([`PcaModel::reconstruct_rows`]).

mod chunks;
pub(crate) mod fit;
mod model;
mod quantized;

pub(crate) use chunks::{read_chunks, write_chunks};
pub use model::{check_rank, PcaModel};
pub use quantized::{dequantize, q_max, QuantizedMatrix, MAX_SCALE};
