//! The [`Relight`] trait: cubemap lighting in, image out, with the time a
//! frame took. Two types implement it: [`Relighter`](crate::Relighter), the
//! non-linear wavelet lighting of a compressed `.ltm` file (Ng et al. 2003,
//! Cheslack-Postava et al. 2007), and [`BasisRelighter`](crate::BasisRelighter),
//! the linear PCA and spherical-harmonics bases the codec is compared with.
//! A viewer holds either as `Box<dyn Relight + Send + Sync>` and reuses one
//! [`Frame`] per thread, frame after frame.

use crate::error::{RelightError, Result};
use crate::image_io::Image;
use crate::relighter::WaveletScratch;
use crate::select::Weighting;
use std::time::Duration;

/// What a frame asks for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Request {
    /// How much of the lighting to use: wavelet lights (the `terms` of
    /// highest priority; values above [`Relight::max_terms`] use them all),
    /// principal components (the first `terms`) or spherical-harmonics
    /// orders (bands `l < terms`, `terms²` coefficients). Linear bases
    /// refuse `terms` above [`Relight::max_terms`]: they were not fitted
    /// that far.
    pub terms: usize,
    /// The priority rule for choosing wavelet lights; linear bases ignore it.
    pub weighting: Weighting,
}

/// Relighting: lighting in, image out, with stats. Object-safe.
pub trait Relight {
    /// Cubemap texels the lighting must have: `6·n²`, the matrix's columns.
    fn lights(&self) -> usize;
    /// Width and height of the relit image.
    fn size(&self) -> (usize, usize);
    /// The largest useful [`Request::terms`].
    fn max_terms(&self) -> usize;
    /// Bytes of decoded data this relighter holds in memory (its arena,
    /// basis or coefficients), for reports.
    fn held_bytes(&self) -> usize;
    /// Decodes now whatever later frames would decode on first use (the
    /// wavelet relighter decodes each column the first time a frame needs
    /// it), so that frames after it only relight: for timing frames alone,
    /// or for a viewer warming up in the background. The linear bases hold
    /// everything from the start.
    fn preload(&self) -> Result<()> {
        Ok(())
    }
    /// A frame holding every buffer this relighter needs, so that
    /// [`Relight::relight`] allocates nothing. Any frame works (buffers of
    /// the wrong size are replaced on first use).
    fn frame(&self) -> Frame;
    /// Relights under `light`, the mean radiance of each cubemap texel
    /// ([`Relight::lights`] finite RGB values, e.g. from
    /// [`EnvMap::to_cubemap`](crate::EnvMap::to_cubemap)); the image lands
    /// in `frame.image`.
    fn relight(
        &self,
        light: &[[f32; 3]],
        request: &Request,
        frame: &mut Frame,
    ) -> Result<FrameStats>;
}

/// Reusable per-thread frame state: the last image and the scratch buffers
/// of the relighters that filled it. [`Relight::frame`] makes one of the
/// right sizes; `Frame::default()` is empty and grows on first use.
pub struct Frame {
    /// The last frame's image.
    pub image: Image,
    /// Buffers of the wavelet relighter.
    pub(crate) wavelet: Option<WaveletScratch>,
    /// The lighting projected on a linear basis (RGB per basis function).
    pub(crate) projected: Vec<[f64; 3]>,
    /// The projected lighting in f32, one plane per colour channel.
    pub(crate) planar: Vec<f32>,
}

impl Default for Frame {
    fn default() -> Frame {
        Frame {
            image: Image::new(0, 0),
            wavelet: None,
            projected: Vec::new(),
            planar: Vec::new(),
        }
    }
}

impl Frame {
    /// Makes the next frame transform its lighting even if it is the same
    /// as the last frame's (a frame under unchanged lighting otherwise reuses
    /// the transform); for timing a new light.
    pub fn forget_light(&mut self) {
        if let Some(s) = &mut self.wavelet {
            s.forget_light();
        }
    }

    /// Makes `image` a `width × height` image, reallocating only when its
    /// size differs.
    pub(crate) fn fit_image(&mut self, width: usize, height: usize) {
        let i = &self.image;
        if (i.width, i.height, i.data.len()) != (width, height, width * height) {
            self.image = Image::new(width, height);
        }
    }
}

/// Where a frame's time went, and how much work it did.
#[derive(Clone, Copy, Debug, Default)]
pub struct FrameStats {
    /// Transforming the lighting: the row wavelet transform, or the
    /// projection on a linear basis.
    pub light_transform: Duration,
    /// Choosing the wavelet lights (zero for linear bases).
    pub selection: Duration,
    /// The multiply-add of coefficients and lighting.
    pub multiply: Duration,
    /// Inverse column steps and the albedo (zero for linear bases).
    pub inverse: Duration,
    /// Decoding the columns this frame was the first to need (wavelet
    /// relighter; zero once every column it uses is decoded).
    pub decode: Duration,
    /// Columns this frame decoded.
    pub columns_decoded: usize,
    /// Lighting terms used: wavelet lights (≤ N), principal components (N)
    /// or spherical-harmonics coefficients (N²).
    pub lights: usize,
    /// Coefficients multiply-added.
    pub nonzeros: u64,
}

impl FrameStats {
    /// The whole frame's time.
    pub fn total(&self) -> Duration {
        self.light_transform + self.selection + self.decode + self.multiply + self.inverse
    }
}

/// Checks cubemap lighting: `lights` texels (`6·n²` at face resolution
/// `face_res`), all finite.
pub(crate) fn check_light(light: &[[f32; 3]], lights: usize, face_res: u32) -> Result<()> {
    if light.len() != lights {
        return Err(RelightError::OutOfRange {
            what: "cubemap lighting texels",
            value: light.len().to_string(),
            valid: format!("{lights} (6·{face_res}² for this matrix)"),
        });
    }
    if let Some(j) = light.iter().position(|c| c.iter().any(|v| !v.is_finite())) {
        return Err(RelightError::Invalid(format!(
            "cubemap lighting texel {j} is NaN or infinite"
        )));
    }
    Ok(())
}
