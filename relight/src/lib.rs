//! `ltm-relight`: relighting from light-transport matrices behind one
//! [`Relight`] trait: non-linear wavelet lighting (Ng et al. 2003) and the
//! level-recursive sparse multiply of Cheslack-Postava et al. 2007
//! ([`Relighter`]), and the linear PCA and spherical-harmonics bases
//! ([`BasisRelighter`]). Environment lighting (lat-long EXR or HDR maps,
//! rotated and resampled exactly to the matrix's cubemap), RGB image output,
//! and the exact dense reference `T·L` that relit images are measured
//! against.
//!
//! A texture-space file (rows = texels of a mesh's texture) relights into
//! its relit texture, which [`TexturedMesh::render`] then draws on the mesh
//! from any [`ViewCamera`], with no new relight per view.
//!
//! [`rotation`] shades glossy surfaces under live lighting, view and BRDF
//! by wavelet rotation (Wang et al. 2006): precomputed sparse Haar rotation
//! matrices per normal and view-dependent BRDF slices.
//!
//! [`nearfield`] lights points from planar, textured area lights at a
//! finite distance (Sun and Ramamoorthi 2009): the light's Haar
//! coefficients propagated to each point by affine wavelet couplings.
//!
//! Features (all on by default): `exr` (OpenEXR maps and images), `png`
//! (PNG output), `hdr` (Radiance HDR maps). Without them the relighting core
//! builds alone: [`EnvMap::from_fn`] and [`EnvMap::new`] take lighting from
//! memory.
//!
//! ```
//! use ltm_codec::compress::{compress, CompressOptions};
//! use ltm_codec::{Dims, RawHeader, RawStore, RawWriter};
//! use ltm_relight::{reference, relative_l2, EnvMap, Relight, Relighter, Request, Rotation, Weighting};
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let dir = tempfile::tempdir()?;
//! // A small transport matrix: 16×16 pixels, 6·4² lights, one channel.
//! let dims = Dims::image(16, 16, 4, 1);
//! let header = RawHeader::new(dims, false, 1 << 20);
//! let mut writer = RawWriter::create(&dir.path().join("t.raw"), header)?;
//! let rows: Vec<f32> = (0..dims.pixels() * dims.lights())
//!     .map(|i| ((i % 97) as f32 * 0.01).sin().abs() * 1e-2)
//!     .collect();
//! writer.write_block(0, &rows, None)?;
//! let raw = RawStore::open(&writer.finish()?)?;
//!
//! // Compress it, then relight under a sky that is brighter above.
//! let ltm = dir.path().join("t.ltm");
//! compress(&raw, &ltm, &CompressOptions::default(), ltm_codec::Progress::NONE)?;
//! let sky = EnvMap::from_fn(64, 32, |_, y| [1.0, 1.0, if y < 16 { 4.0 } else { 0.5 }])?;
//! let light = sky.to_cubemap(4, &Rotation::IDENTITY);
//!
//! let relighter = Relighter::open(&ltm)?;
//! let mut frame = relighter.frame()?; // reused frame after frame
//! let request = Request { terms: 50, weighting: Weighting::Transport };
//! let stats = relighter.relight(&light, &request, &mut frame)?;
//! let exact = reference(&raw, &light)?;
//! println!("{} lights, error {:.4}", stats.lights, relative_l2(&frame.image, &exact)?);
//! # Ok(())
//! # }
//! ```

#![deny(unsafe_code)]
#![warn(missing_docs)]

mod arena;
mod basis;
mod envmap;
mod error;
mod frame;
mod image_io;
mod kernel;
pub mod nearfield;
mod open;
mod pca;
mod pca_blocks;
mod point;
mod prefiltered;
mod reference;
mod relighter;
mod render;
pub mod rotation;
mod select;
mod slots;

pub use basis::BasisRelighter;
pub use envmap::{EnvMap, Rotation, MAX_ENV_HEIGHT};
pub use error::{RelightError, Result};
pub use frame::{Frame, FrameStats, Relight, Request, TermBasis};
pub use image_io::{relative_l2, Image, MAX_READ_PIXELS};
pub use open::{open, open_file, Source};
pub use pca::PcaRelighter;
pub use point::{point_light_taps, Lookup, PointLight, SurfaceSample, Taps};
pub use prefiltered::{PrefilteredMap, PREFILTER_SCALE, SAMPLES_PER_SIDE};
pub use reference::{reference, reference_with_progress};
pub use relighter::Relighter;
pub use render::{
    TexturedMesh, ViewCamera, CHART_REACH, MAX_SUPERSAMPLE, MAX_VIEW_SIDE, SEAM_FACTOR,
};
pub use select::{luminance, magnitude, select, support_area, Weighting};
