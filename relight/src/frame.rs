//! The [`Relight`] trait: cubemap lighting in, image out, with the time a
//! frame took. The crate's types implement it:
//! [`Relighter`](crate::Relighter), the non-linear wavelet lighting of a
//! compressed `.ltm` file (Ng et al. 2003, Cheslack-Postava et al. 2007),
//! [`PcaRelighter`](crate::PcaRelighter) for `pca` files, and
//! [`BasisRelighter`](crate::BasisRelighter), the linear PCA and
//! spherical-harmonics bases the codec is compared with;
//! [`open`](crate::open) opens any `.ltm` file as the right one. A viewer
//! holds one as `Box<dyn Relight + Send + Sync>` and reuses one [`Frame`]
//! per thread, frame after frame; each relighter keeps its own buffers in
//! the frame as an opaque scratch ([`Frame::scratch`]), so a relighter
//! defined outside this crate (GPU, wasm, Python) can keep its own too.

use crate::error::{RelightError, Result};
use crate::image_io::Image;
use crate::select::Weighting;
use ltm_codec::{Charge, LightBasis, Limits};
use std::any::Any;
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

/// What a relighter's terms ([`Request::terms`]) count.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TermBasis {
    /// Wavelet lights of the cubemap, the most important chosen anew for
    /// each lighting (non-linear): any number up to every light, larger
    /// requests using them all.
    Wavelet,
    /// A linear basis fitted once (principal components, spherical-harmonics
    /// orders): at most [`Relight::max_terms`], the default being all.
    Linear,
}

/// Relighting: lighting in, image out, with stats. Object-safe.
pub trait Relight {
    /// The lighting this relighter takes: the matrix's columns (a cubemap
    /// of `6·n²` texels).
    fn light_basis(&self) -> LightBasis;
    /// What [`Request::terms`] counts: wavelet lights or a linear basis's
    /// terms.
    fn term_basis(&self) -> TermBasis;
    /// Cubemap texels the lighting must have: `6·n²`, the matrix's columns.
    fn lights(&self) -> usize {
        self.light_basis().columns()
    }
    /// The cubemap's face resolution `n` (lighting of `6·n²` texels, e.g.
    /// for [`EnvMap::to_cubemap`](crate::EnvMap::to_cubemap)).
    fn face_res(&self) -> usize {
        self.light_basis().face_res() as usize
    }
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
    /// [`Relight::relight`] allocates nothing, charged to the relighter's
    /// memory budget (an error when they do not fit it). Any frame works
    /// (buffers of the wrong size are replaced on first use); the default
    /// is an empty one.
    fn frame(&self) -> Result<Frame> {
        Ok(Frame::default())
    }
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
/// of the relighter that filled it. [`Relight::frame`] makes one of the
/// right sizes; `Frame::default()` is empty and grows on first use.
pub struct Frame {
    /// The last frame's image.
    pub image: Image,
    /// The image's bytes, charged to the budget of the relighter that
    /// sized it ([`Frame::fit_image`]).
    image_charge: Charge,
    /// The buffers of the relighter that last used this frame: its own
    /// type, found again by downcasting ([`Frame::scratch`]).
    scratch: Option<Box<dyn Any + Send>>,
    /// Whether [`Frame::forget_light`] was called since the relighter last
    /// looked ([`Frame::take_forget_light`]).
    forget_light: bool,
}

impl Default for Frame {
    fn default() -> Frame {
        Frame {
            image: Image::new(0, 0),
            image_charge: Charge::default(),
            scratch: None,
            forget_light: false,
        }
    }
}

impl Frame {
    /// Makes the next frame transform its lighting even if it is the same
    /// as the last frame's (a frame under unchanged lighting otherwise reuses
    /// the transform); for timing a new light.
    pub fn forget_light(&mut self) {
        self.forget_light = true;
    }

    /// Whether [`Frame::forget_light`] was called since the last call of
    /// this: a relighter that reuses a transformed light drops it then.
    pub fn take_forget_light(&mut self) -> bool {
        std::mem::take(&mut self.forget_light)
    }

    /// Makes `image` a black `width × height` image charged to `limits`,
    /// reallocating only when its size differs (an error naming the budget
    /// when it does not fit).
    pub fn fit_image(&mut self, width: usize, height: usize, limits: &Limits) -> Result<()> {
        let i = &self.image;
        if (i.width, i.height, i.data.len()) != (width, height, width * height) {
            self.image = Image::new(0, 0);
            self.image_charge = Charge::default();
            let count = width.saturating_mul(height);
            let (data, charge) = limits.vec("relit image", count, [0.0f32; 3])?;
            self.image = Image {
                width,
                height,
                data,
            };
            self.image_charge = charge;
        }
        Ok(())
    }

    /// The relighter's scratch of type `S` kept in this frame, if `fits`
    /// accepts it, or else the one `make` builds (replacing whatever
    /// scratch the frame held), beside the frame's image. One downcast per
    /// call: a relighter calls this once per frame.
    pub fn scratch<S: Any + Send>(
        &mut self,
        fits: impl FnOnce(&S) -> bool,
        make: impl FnOnce() -> Result<S>,
    ) -> Result<(&mut S, &mut Image)> {
        let kept = self
            .scratch
            .as_deref()
            .and_then(|s| s.downcast_ref::<S>())
            .is_some_and(fits);
        if !kept {
            // The old scratch goes first, so that its bytes are given back
            // before the new one is charged.
            self.scratch = None;
            self.scratch = Some(Box::new(make()?));
        }
        let s = self
            .scratch
            .as_deref_mut()
            .and_then(|s| s.downcast_mut::<S>())
            .expect("the scratch was just checked or made as an S");
        Ok((s, &mut self.image))
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
