//! ltm: compressed precomputed light-transport matrices.
//!
//! A facade over the pipeline's crates: [`codec`] (wavelets, file formats, the
//! adaptive 4D codec of Cheslack-Postava et al. 2007), [`bake`](mod@bake) (ray-traced
//! transport rows) and [`relight`] (images from compressed matrices under
//! environment lighting). The types most programs need are re-exported here:
//!
//! - a matrix's shape: [`Dims`] = [`RowLayout`] × [`LightBasis`] × channels;
//! - files: [`RawStore`] / [`RawWriter`] (the uncompressed matrix),
//!   [`LtmFile`] (a compressed one, from a path or from bytes), both opened
//!   under [`Limits`], one memory budget that clones share;
//! - compression: [`compress()`](fn@compress) with [`CompressOptions`];
//! - relighting: [`open()`](fn@open) opens any `.ltm` file (a [`Source`]:
//!   path or bytes) as a `Box<dyn` [`Relight`]`>`, the trait implemented by
//!   the wavelet [`Relighter`], the [`PcaRelighter`] and the PCA/SH
//!   [`BasisRelighter`], which says its [`TermBasis`] and face resolution,
//!   is fed by an [`EnvMap`] and reuses a [`Frame`];
//! - baking: [`Scene`] and [`bake()`](fn@bake).
//!
//! Each crate has its own error type: [`CodecError`], [`BakeError`],
//! [`RelightError`].

#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub use ltm_bake as bake;
pub use ltm_codec as codec;
pub use ltm_relight as relight;

pub use ltm_bake::{bake, BakeError, BakeOptions, Scene, SceneDesc};
pub use ltm_codec::{
    compress, Charge, CompressOptions, Dims, Error as CodecError, LightBasis, Limits, LtmFile,
    Mode, RawStore, RawWriter, RowLayout,
};
pub use ltm_relight::{
    open, BasisRelighter, EnvMap, Frame, Image, PcaRelighter, Relight, RelightError, Relighter,
    Request, Rotation, Source, TermBasis, Weighting,
};
