//! RGB float images: the relit frame, OpenEXR and PNG output (features
//! `exr` and `png`), and the error measure used to compare a relit image
//! with the reference.

use crate::error::{RelightError, Result};
#[cfg(feature = "exr")]
use exr::prelude::{
    Encoding, Image as ExrImage, Layer, LayerAttributes, ReadChannels, ReadLayers,
    SpecificChannels, Vec2, WritableImage,
};
#[cfg(feature = "png")]
use image::{ExtendedColorType, ImageEncoder};
#[cfg(any(feature = "exr", feature = "png"))]
use ltm_codec::AtomicFile;
#[cfg(any(feature = "exr", feature = "png"))]
use std::io::BufWriter;
#[cfg(feature = "png")]
use std::io::Write;
#[cfg(any(feature = "exr", feature = "png"))]
use std::path::Path;

/// Largest pixel count read from an image file (`16384 × 8192`); a larger
/// header is refused before anything is allocated.
pub const MAX_READ_PIXELS: usize = 1 << 27;

/// A linear RGB image, row-major with `y = 0` the top row: pixel `(x, y)` is
/// `data[y·width + x]`, the same order as the rows of the transport matrix.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// `width·height` linear RGB pixels, row-major from the top.
    pub data: Vec<[f32; 3]>,
}

impl Image {
    /// A black image.
    pub fn new(width: usize, height: usize) -> Image {
        Image {
            width,
            height,
            data: vec![[0.0; 3]; width * height],
        }
    }

    /// An image from its pixels; `data.len()` must be `width·height`.
    pub fn from_data(width: usize, height: usize, data: Vec<[f32; 3]>) -> Result<Image> {
        let image = Image {
            width,
            height,
            data,
        };
        image.check_len()?;
        Ok(image)
    }

    /// Pixel `(x, y)`, or `None` outside the image.
    pub fn pixel(&self, x: usize, y: usize) -> Option<[f32; 3]> {
        if x >= self.width {
            return None;
        }
        self.data
            .get(y.checked_mul(self.width)?.checked_add(x)?)
            .copied()
    }

    /// The first pixel `(x, y)` holding a NaN or infinite value, if any.
    pub fn first_non_finite(&self) -> Option<(usize, usize)> {
        let i = self
            .data
            .iter()
            .position(|p| p.iter().any(|v| !v.is_finite()))?;
        Some((i % self.width.max(1), i / self.width.max(1)))
    }

    /// Checks that `data` holds `width·height` pixels.
    pub(crate) fn check_len(&self) -> Result<()> {
        match self.width.checked_mul(self.height) {
            Some(p) if p == self.data.len() => Ok(()),
            _ => Err(RelightError::Invalid(format!(
                "image of {}×{} pixels holds {} values (needs width·height)",
                self.width,
                self.height,
                self.data.len()
            ))),
        }
    }

    /// Checks what a writer needs: a non-empty image whose pixel count
    /// matches its size and whose values are all finite.
    #[cfg(any(feature = "exr", feature = "png"))]
    fn check_writable(&self, path: &Path) -> Result<()> {
        self.check_len()?;
        if self.width == 0 || self.height == 0 {
            return Err(RelightError::image(
                path,
                format!("cannot write an empty {}×{} image", self.width, self.height),
            ));
        }
        if let Some((x, y)) = self.first_non_finite() {
            return Err(RelightError::Invalid(format!(
                "pixel ({x}, {y}) of the image to write to {} is NaN or infinite",
                path.display()
            )));
        }
        Ok(())
    }

    /// Writes a 32-bit float RGB OpenEXR file (ZIP compression, lossless).
    /// The file is written under a unique temporary name and renamed to
    /// `PATH` when complete ([`ltm_codec::AtomicFile`]). Refuses images
    /// holding NaN or infinite values.
    #[cfg(feature = "exr")]
    pub fn write_exr(&self, path: &Path) -> Result<()> {
        Ok(self.stage_exr(path)?.commit()?)
    }

    /// [`Image::write_exr`] up to, not including, the commit: the file is
    /// complete under its temporary name, and appears at `path` only when
    /// the returned file is committed (dropped, it vanishes). Outputs that
    /// must appear together (the views of an orbit) are staged first and
    /// committed last.
    #[cfg(feature = "exr")]
    pub fn stage_exr(&self, path: &Path) -> Result<AtomicFile> {
        self.check_writable(path)?;
        let mut out = AtomicFile::create(path)?;
        let tmp = out.tmp_path().to_path_buf();
        let width = self.width;
        let channels = SpecificChannels::rgb(|pos: Vec2<usize>| {
            let p = self.data[pos.y() * width + pos.x()];
            (p[0], p[1], p[2])
        });
        let layer = Layer::new(
            (self.width, self.height),
            LayerAttributes::default(),
            Encoding::SMALL_LOSSLESS,
            channels,
        );
        ExrImage::from_layer(layer)
            .write()
            .to_buffered(BufWriter::new(&mut out))
            .map_err(|e| exr_error(&tmp, e))?;
        Ok(out)
    }

    /// Writes an 8-bit sRGB PNG: each value is multiplied by `2^exposure_ev`,
    /// clamped to `[0, 1]` and encoded with the sRGB transfer function. The
    /// file is written under a unique temporary name and renamed to `PATH`
    /// when complete.
    #[cfg(feature = "png")]
    pub fn write_png(&self, path: &Path, exposure_ev: f32) -> Result<()> {
        Ok(self.stage_png(path, exposure_ev)?.commit()?)
    }

    /// [`Image::write_png`] up to, not including, the commit (see
    /// [`Image::stage_exr`]).
    #[cfg(feature = "png")]
    pub fn stage_png(&self, path: &Path, exposure_ev: f32) -> Result<AtomicFile> {
        if !exposure_ev.is_finite() || exposure_ev.abs() > 64.0 {
            return Err(RelightError::range(
                "exposure (EV)",
                exposure_ev,
                "a finite value in -64..=64",
            ));
        }
        self.check_writable(path)?;
        let (Ok(w), Ok(h)) = (u32::try_from(self.width), u32::try_from(self.height)) else {
            return Err(RelightError::image(
                path,
                format!("{}×{} is too large for PNG", self.width, self.height),
            ));
        };
        let scale = 2f32.powf(exposure_ev);
        let bytes: Vec<u8> = self
            .data
            .iter()
            .flat_map(|p| p.map(|v| srgb_8bit(v * scale)))
            .collect();
        let mut file = AtomicFile::create(path)?;
        let tmp = file.tmp_path().to_path_buf();
        let mut out = BufWriter::new(&mut file);
        image::codecs::png::PngEncoder::new(&mut out)
            .write_image(&bytes, w, h, ExtendedColorType::Rgb8)
            .map_err(|e| RelightError::image(&tmp, e))?;
        out.flush().map_err(|e| RelightError::io(&tmp, e))?;
        drop(out);
        Ok(file)
    }

    /// Reads the first layer with R, G and B channels of an OpenEXR file,
    /// any sample type, as 32-bit floats. Values are returned as stored
    /// (NaN, infinite and negative values included).
    #[cfg(feature = "exr")]
    pub fn read_exr(path: &Path) -> Result<Image> {
        let (width, height, data) = read_exr_rgb(path)?;
        Ok(Image {
            width,
            height,
            data,
        })
    }
}

/// Relative L2 error `‖a − reference‖ / ‖reference‖` over all pixels and
/// channels, accumulated in f64. Both images must have the same size and
/// hold only finite values (a NaN or infinite pixel is an error naming it),
/// and the reference must not be all zero (the relative error is then
/// undefined: an error that says so), so the result is always finite.
pub fn relative_l2(a: &Image, reference: &Image) -> Result<f64> {
    a.check_len()?;
    reference.check_len()?;
    if (a.width, a.height) != (reference.width, reference.height) {
        return Err(RelightError::Invalid(format!(
            "cannot compare a {}×{} image with a {}×{} reference",
            a.width, a.height, reference.width, reference.height
        )));
    }
    for (what, image) in [("reference", reference), ("relit image", a)] {
        if let Some((x, y)) = image.first_non_finite() {
            return Err(RelightError::Invalid(format!(
                "{what} pixel ({x}, {y}) is {:?}: the relative error needs finite values",
                image.data[y * image.width + x]
            )));
        }
    }
    let (mut diff, mut norm) = (0.0f64, 0.0f64);
    for (p, q) in a.data.iter().zip(&reference.data) {
        for c in 0..3 {
            let d = p[c] as f64 - q[c] as f64;
            diff += d * d;
            norm += q[c] as f64 * q[c] as f64;
        }
    }
    if norm == 0.0 {
        return Err(RelightError::Invalid(format!(
            "the {}×{} reference is all zero: the relative error is undefined (relight under the same map, or compare with a reference that is lit)",
            reference.width, reference.height
        )));
    }
    Ok((diff / norm).sqrt())
}

/// The sRGB encoding of a linear value, clamped to `[0, 1]`, as 8 bits.
#[cfg(feature = "png")]
fn srgb_8bit(v: f32) -> u8 {
    // NaN stays NaN here and becomes 0 in the saturating cast below.
    let v = v.clamp(0.0, 1.0);
    let e = if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    };
    (e * 255.0 + 0.5) as u8
}

/// Maps an exr error to ours: operating-system failures keep their
/// `io::Error`, everything else is a decode/encode failure.
#[cfg(feature = "exr")]
fn exr_error(path: &Path, e: exr::error::Error) -> RelightError {
    use std::io::ErrorKind::{IsADirectory, NotFound, PermissionDenied};
    match e {
        exr::error::Error::Io(io)
            if matches!(io.kind(), NotFound | PermissionDenied | IsADirectory) =>
        {
            RelightError::io(path, io)
        }
        // Any other failure while reading is the file's fault (offsets or
        // sizes that point outside it), whatever the system called it.
        exr::error::Error::Io(io) => {
            RelightError::image(path, format!("OpenEXR: corrupt or truncated file ({io})"))
        }
        other => RelightError::image(path, format!("OpenEXR: {other}")),
    }
}

/// The data window (`xMin, yMin, xMax, yMax`) of an OpenEXR file's first
/// header, if its first 64 KiB hold one (a header is a list of attributes:
/// name, type, size, value, ended by an empty name).
#[cfg(feature = "exr")]
fn exr_data_window(path: &Path) -> Option<[i32; 4]> {
    use std::io::Read;
    let mut head = Vec::new();
    std::fs::File::open(path)
        .ok()?
        .take(1 << 16)
        .read_to_end(&mut head)
        .ok()?;
    let mut rest = head.get(8..)?;
    let cstr = |rest: &mut &[u8]| -> Option<Vec<u8>> {
        let end = rest.iter().position(|&b| b == 0)?;
        let s = rest[..end].to_vec();
        *rest = &rest[end + 1..];
        Some(s)
    };
    loop {
        let name = cstr(&mut rest)?;
        if name.is_empty() {
            return None;
        }
        let kind = cstr(&mut rest)?;
        let size = u32::from_le_bytes(rest.get(..4)?.try_into().ok()?) as usize;
        let value = rest.get(4..4 + size)?;
        if name == b"dataWindow" && kind == b"box2i" && size == 16 {
            let v =
                |k: usize| i32::from_le_bytes(value[4 * k..4 * k + 4].try_into().unwrap_or([0; 4]));
            return Some([v(0), v(1), v(2), v(3)]);
        }
        rest = &rest[4 + size..];
    }
}

/// Refuses an OpenEXR file whose first header's data window holds more than
/// [`MAX_READ_PIXELS`] pixels, naming its size and the limit, before the
/// OpenEXR reader sees it (which calls such a file corrupt).
#[cfg(feature = "exr")]
fn check_exr_data_window(path: &Path) -> Result<()> {
    let Some([x0, y0, x1, y1]) = exr_data_window(path) else {
        return Ok(());
    };
    let (w, h) = (
        i64::from(x1) - i64::from(x0) + 1,
        i64::from(y1) - i64::from(y0) + 1,
    );
    if w >= 1 && h >= 1 && (w as u128) * (h as u128) <= MAX_READ_PIXELS as u128 {
        return Ok(());
    }
    Err(RelightError::image(
        path,
        format!(
            "OpenEXR data window ({x0}, {y0})..=({x1}, {y1}) is {w}×{h} pixels (valid: 1 to {MAX_READ_PIXELS} pixels, e.g. 16384×8192)"
        ),
    ))
}

/// Reads the first layer with R, G, B channels of an OpenEXR file:
/// `(width, height, pixels)`, row-major from the top. The layer's size is
/// checked against [`MAX_READ_PIXELS`] before its pixels are allocated.
#[cfg(feature = "exr")]
pub(crate) fn read_exr_rgb(path: &Path) -> Result<(usize, usize, Vec<[f32; 3]>)> {
    check_exr_data_window(path)?;
    let meta = exr::meta::MetaData::read_from_file(path, false).map_err(|e| exr_error(path, e))?;
    let header = meta
        .headers
        .iter()
        .find(|h| {
            !h.deep
                && ["R", "G", "B"]
                    .iter()
                    .all(|c| h.channels.list.iter().any(|d| d.name.eq(c)))
        })
        .ok_or_else(|| {
            RelightError::image(
                path,
                "OpenEXR file has no layer with R, G and B channels".to_string(),
            )
        })?;
    let size = header.layer_size;
    let area = size.width().checked_mul(size.height());
    if !matches!(area, Some(a) if a <= MAX_READ_PIXELS) {
        return Err(RelightError::image(
            path,
            format!(
                "OpenEXR layer of {}×{} pixels is too large (at most {MAX_READ_PIXELS} pixels)",
                size.width(),
                size.height()
            ),
        ));
    }
    // The pixel storage re-checks the size, so a layer other than the one
    // checked above cannot make it allocate without bound.
    struct Pixels {
        width: usize,
        height: usize,
        data: Vec<[f32; 3]>,
    }
    let image = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .rgb_channels(
            |res: Vec2<usize>, _| {
                let (width, height) = (res.width(), res.height());
                let ok = matches!(width.checked_mul(height), Some(a) if a <= MAX_READ_PIXELS);
                Pixels {
                    width,
                    height,
                    data: if ok {
                        vec![[0.0; 3]; width * height]
                    } else {
                        Vec::new()
                    },
                }
            },
            |px: &mut Pixels, pos: Vec2<usize>, (r, g, b): (f32, f32, f32)| {
                let i = pos
                    .y()
                    .checked_mul(px.width)
                    .and_then(|i| i.checked_add(pos.x()));
                if let (true, Some(slot)) = (pos.x() < px.width, i.and_then(|i| px.data.get_mut(i)))
                {
                    *slot = [r, g, b];
                }
            },
        )
        .first_valid_layer()
        .all_attributes()
        .from_file(path)
        .map_err(|e| exr_error(path, e))?;
    let px = image.layer_data.channel_data.pixels;
    if px.data.is_empty() || Some(px.data.len()) != px.width.checked_mul(px.height) {
        return Err(RelightError::image(
            path,
            format!(
                "OpenEXR layer of {}×{} pixels is empty or too large (at most {MAX_READ_PIXELS} pixels)",
                px.width, px.height
            ),
        ));
    }
    Ok((px.width, px.height, px.data))
}
