//! What a transport matrix's rows and columns are.
//!
//! A matrix `T` has one row per receiver sample and one column per lighting
//! basis function, with `channels` values per entry. [`RowLayout`] says what
//! the rows are (the pixels of a fixed camera today; the texels of a
//! texture-space bake next), [`LightBasis`] what the columns are (the texels
//! of a cubemap of distant lighting). Both are stored in the raw store and
//! `.ltm` headers as the four numbers `width, height, face_res, channels`
//! (docs/FORMAT.md).

use crate::error::{Error, Result};

/// Largest side of the row grid.
pub const MAX_SIDE: u32 = 1 << 15;
/// Largest row count P.
pub const MAX_PIXELS: u64 = 1 << 26;
/// Largest cubemap face resolution n.
pub const MAX_FACE_RES: u32 = 1024;

/// What the rows of a transport matrix are. Rows always lie on a
/// `width × height` grid in row-major order: the column transform treats
/// each column as an image over that grid.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum RowLayout {
    /// One row per pixel of a fixed camera's `width × height` image, row `p`
    /// = pixel `(p mod width, p div width)`, y down.
    Image {
        /// Image width in pixels.
        width: u32,
        /// Image height in pixels.
        height: u32,
    },
}

impl RowLayout {
    /// Width of the row grid.
    pub fn width(&self) -> u32 {
        match *self {
            RowLayout::Image { width, .. } => width,
        }
    }

    /// Height of the row grid.
    pub fn height(&self) -> u32 {
        match *self {
            RowLayout::Image { height, .. } => height,
        }
    }

    /// Number of rows P.
    pub fn rows(&self) -> usize {
        self.width() as usize * self.height() as usize
    }
}

/// What the columns of a transport matrix are.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum LightBasis {
    /// One column per texel of a cubemap of six `n × n` faces of distant
    /// lighting, in the face order and texel convention of docs/FORMAT.md:
    /// column `j = (face·n + y)·n + x`.
    Cubemap {
        /// Face resolution (a power of two).
        n: u32,
    },
}

impl LightBasis {
    /// Cubemap face resolution n.
    pub fn face_res(&self) -> u32 {
        match *self {
            LightBasis::Cubemap { n } => n,
        }
    }

    /// Number of columns M (6·n² for a cubemap).
    pub fn columns(&self) -> usize {
        match *self {
            LightBasis::Cubemap { n } => 6 * n as usize * n as usize,
        }
    }
}

/// Dimensions of a transport matrix: P rows of [`RowLayout`], M columns of
/// [`LightBasis`], `channels` values per entry.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Dims {
    /// What the rows are.
    pub rows: RowLayout,
    /// What the columns are.
    pub lights: LightBasis,
    /// Values per entry: 1 (grey) or 3 (RGB).
    pub channels: u32,
}

impl Dims {
    /// The dimensions of a fixed camera's `width × height` image lit by a
    /// cubemap of face resolution `face_res`.
    pub fn image(width: u32, height: u32, face_res: u32, channels: u32) -> Dims {
        Dims {
            rows: RowLayout::Image { width, height },
            lights: LightBasis::Cubemap { n: face_res },
            channels,
        }
    }

    /// Width of the row grid.
    pub fn width(&self) -> u32 {
        self.rows.width()
    }

    /// Height of the row grid.
    pub fn height(&self) -> u32 {
        self.rows.height()
    }

    /// Cubemap face resolution n of the lighting.
    pub fn face_res(&self) -> u32 {
        self.lights.face_res()
    }

    /// Checks every field against its valid range.
    pub fn validate(&self) -> Result<()> {
        for (what, v) in [("width", self.width()), ("height", self.height())] {
            if v == 0 || v > MAX_SIDE {
                return Err(Error::range(what, v, format!("1..={MAX_SIDE}")));
            }
        }
        if self.pixels() as u64 > MAX_PIXELS {
            return Err(Error::range(
                "width·height",
                self.pixels(),
                format!("at most {MAX_PIXELS}"),
            ));
        }
        let n = self.face_res();
        if !n.is_power_of_two() || n > MAX_FACE_RES {
            return Err(Error::range(
                "face_res",
                n,
                format!("a power of two in 1..={MAX_FACE_RES}"),
            ));
        }
        if self.channels != 1 && self.channels != 3 {
            return Err(Error::range("channels", self.channels, "1 or 3"));
        }
        Ok(())
    }

    /// Number of rows P (pixels).
    pub fn pixels(&self) -> usize {
        self.rows.rows()
    }

    /// Number of columns M = 6·n² (lighting directions).
    pub fn lights(&self) -> usize {
        self.lights.columns()
    }

    /// Values per row: M·C.
    pub fn row_len(&self) -> usize {
        self.lights() * self.channels as usize
    }

    /// Bytes of the dense f32 matrix, P·M·C·4.
    pub fn raw_bytes(&self) -> u64 {
        self.pixels() as u64 * self.row_len() as u64 * 4
    }

    /// The four header fields `width, height, face_res, channels` (docs/FORMAT.md).
    pub(crate) fn to_fields(self) -> [u32; 4] {
        [self.width(), self.height(), self.face_res(), self.channels]
    }

    /// Reads the four header fields written by [`Dims::to_fields`].
    pub(crate) fn read_fields(r: &mut crate::bytes::Reader<'_>) -> Result<Dims> {
        Ok(Dims::image(r.u32()?, r.u32()?, r.u32()?, r.u32()?))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn image_dims_name_rows_and_columns() {
        let d = Dims::image(5, 3, 4, 3);
        assert_eq!(
            d.rows,
            RowLayout::Image {
                width: 5,
                height: 3
            }
        );
        assert_eq!(d.lights, LightBasis::Cubemap { n: 4 });
        assert_eq!((d.width(), d.height(), d.face_res()), (5, 3, 4));
        assert_eq!((d.pixels(), d.lights(), d.row_len()), (15, 96, 288));
        assert_eq!(d.raw_bytes(), 15 * 288 * 4);
        assert_eq!(d.to_fields(), [5, 3, 4, 3]);
    }

    #[test]
    fn invalid_dims_error() {
        for d in [
            Dims::image(0, 3, 4, 1),
            Dims::image(3, MAX_SIDE + 1, 4, 1),
            Dims::image(1 << 14, 1 << 14, 4, 1),
            Dims::image(3, 3, 3, 1),
            Dims::image(3, 3, 2 * MAX_FACE_RES, 1),
            Dims::image(3, 3, 4, 2),
        ] {
            assert!(d.validate().is_err(), "{d:?}");
        }
    }
}
