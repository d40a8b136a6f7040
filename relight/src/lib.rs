//! `ltm-relight`: relighting from light-transport matrices: non-linear
//! wavelet lighting (Ng et al. 2003) and the level-recursive sparse multiply
//! of Cheslack-Postava et al. 2007 ([`Relighter`]). Environment
//! lighting (lat-long EXR or HDR maps, rotated and resampled exactly to the
//! matrix's cubemap), RGB image output, and the exact dense reference
//! `T·L` that relit images are measured against.

#![forbid(unsafe_code)]

mod envmap;
mod error;
mod image_io;
mod reference;
mod relighter;
mod select;

pub use envmap::{EnvMap, Rotation, MAX_ENV_HEIGHT};
pub use error::{RelightError, Result};
pub use image_io::{relative_l2, Image, MAX_READ_PIXELS};
pub use reference::{reference, reference_with_progress};
pub use relighter::{FrameBuffers, FrameStats, Relighter};
pub use select::{luminance, magnitude, select, support_area, Weighting};
