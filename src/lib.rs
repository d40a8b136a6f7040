//! ltm: compressed precomputed light-transport matrices.
//!
//! A facade over the pipeline's crates: [`codec`] (wavelets, file formats, the
//! adaptive 4D codec), [`bake`] (ray-traced transport rows) and [`relight`]
//! (images from compressed matrices under environment lighting).

pub use ltm_bake as bake;
pub use ltm_codec as codec;
pub use ltm_relight as relight;
