//! The linear fits the codec is measured against, streamed over the raw
//! store in dense blocks of (pixel, channel) rows (`rows.rs`): the
//! uncentred PCA light basis ([`PcaBasis`], `pca.rs`) and the spherical
//! harmonics projection ([`ShProjection`], `sh.rs`).

mod pca;
pub(crate) mod rows;
pub mod sh;

pub use pca::PcaBasis;
pub use sh::{ShProjection, MAX_SH_ORDER};
