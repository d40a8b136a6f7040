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
/// Largest texture side S of a texture-space bake.
pub const MAX_TEXTURE_SIZE: u32 = 4096;
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
    /// One row per texel of a `size × size` texture over a mesh (a texture-
    /// space bake): row `k` = texel `(k mod size, k div size)`, v down. The
    /// texel's surface point and normal are in the file's surface data
    /// ([`crate::Surface`]); texels outside the mesh are invalid rows.
    Texture {
        /// Texture side S in texels.
        size: u32,
        /// How the mesh was laid out over the square.
        parameterization: Parameterization,
    },
}

/// How a mesh is laid out over a texture's square (docs/FORMAT.md codes).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum Parameterization {
    /// The mesh's own texture coordinates (charts), code 1.
    Uv,
    /// A spherical parameterization of a closed genus-0 mesh unfolded
    /// through the octahedron (a geometry image, Praun & Hoppe 2003), code 2.
    Sphere,
    /// An automatic chart atlas of the receiving meshes (xatlas: charts
    /// grown over the surface, flattened and packed with padding), code 3.
    Atlas,
}

impl Parameterization {
    /// The code stored in files: 1 = uv, 2 = sphere, 3 = atlas.
    pub fn code(self) -> u32 {
        match self {
            Parameterization::Uv => 1,
            Parameterization::Sphere => 2,
            Parameterization::Atlas => 3,
        }
    }

    /// The parameterization of a stored code, if known.
    pub fn from_code(c: u32) -> Option<Parameterization> {
        [
            Parameterization::Uv,
            Parameterization::Sphere,
            Parameterization::Atlas,
        ]
        .into_iter()
        .find(|p| p.code() == c)
    }

    /// Its name in scene files and reports: `uv`, `sphere` or `atlas`.
    pub fn name(self) -> &'static str {
        match self {
            Parameterization::Uv => "uv",
            Parameterization::Sphere => "sphere",
            Parameterization::Atlas => "atlas",
        }
    }
}

impl std::str::FromStr for Parameterization {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Parameterization, String> {
        match s {
            "uv" => Ok(Parameterization::Uv),
            "sphere" => Ok(Parameterization::Sphere),
            "atlas" => Ok(Parameterization::Atlas),
            _ => Err(format!(
                "unknown parameterization '{s}' (expected atlas, uv or sphere)"
            )),
        }
    }
}

impl RowLayout {
    /// Width of the row grid.
    pub fn width(&self) -> u32 {
        match *self {
            RowLayout::Image { width, .. } => width,
            RowLayout::Texture { size, .. } => size,
        }
    }

    /// Height of the row grid.
    pub fn height(&self) -> u32 {
        match *self {
            RowLayout::Image { height, .. } => height,
            RowLayout::Texture { size, .. } => size,
        }
    }

    /// Number of rows P.
    pub fn rows(&self) -> usize {
        self.width() as usize * self.height() as usize
    }

    /// True for the texels of a texture ([`RowLayout::Texture`]).
    pub fn is_texture(&self) -> bool {
        matches!(self, RowLayout::Texture { .. })
    }

    /// The code stored in files: 0 = image, 1 = texture.
    pub(crate) fn code(&self) -> u32 {
        match self {
            RowLayout::Image { .. } => 0,
            RowLayout::Texture { .. } => 1,
        }
    }

    /// The layout of stored codes over a `width × height` grid, checked:
    /// a texture is square and names a known parameterization; an image
    /// has parameterization code 0.
    pub(crate) fn from_codes(
        layout: u32,
        parameterization: u32,
        width: u32,
        height: u32,
    ) -> Result<RowLayout> {
        match (layout, parameterization) {
            (0, 0) => Ok(RowLayout::Image { width, height }),
            (0, p) => Err(Error::range("parameterization of image rows", p, "0")),
            (1, p) => {
                let parameterization = Parameterization::from_code(p)
                    .ok_or_else(|| Error::range("parameterization", p, "1 (uv) or 2 (sphere)"))?;
                if width != height {
                    return Err(Error::range(
                        "texture height",
                        height,
                        format!("equal to its width {width}"),
                    ));
                }
                Ok(RowLayout::Texture {
                    size: width,
                    parameterization,
                })
            }
            (l, _) => Err(Error::range("row layout", l, "0 (image) or 1 (texture)")),
        }
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

    /// The dimensions of an `size × size` texture over a mesh laid out by
    /// `parameterization`, lit by a cubemap of face resolution `face_res`.
    pub fn texture(
        size: u32,
        parameterization: Parameterization,
        face_res: u32,
        channels: u32,
    ) -> Dims {
        Dims {
            rows: RowLayout::Texture {
                size,
                parameterization,
            },
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
        if let RowLayout::Texture { size, .. } = self.rows {
            if size > MAX_TEXTURE_SIZE {
                return Err(Error::range(
                    "texture size",
                    size,
                    format!("1..={MAX_TEXTURE_SIZE}"),
                ));
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
    fn texture_layout_codes_round_trip() {
        let d = Dims::texture(8, Parameterization::Sphere, 4, 1);
        assert_eq!((d.width(), d.height(), d.pixels()), (8, 8, 64));
        assert!(d.rows.is_texture() && d.validate().is_ok());
        let back = RowLayout::from_codes(d.rows.code(), 2, 8, 8).unwrap();
        assert_eq!(back, d.rows);
        assert_eq!(
            RowLayout::from_codes(1, 3, 8, 8).unwrap(),
            Dims::texture(8, Parameterization::Atlas, 4, 1).rows
        );
        assert_eq!(
            RowLayout::from_codes(0, 0, 5, 3).unwrap(),
            RowLayout::Image {
                width: 5,
                height: 3
            }
        );
        for (l, p, w, h) in [
            (1, 2, 8, 4),
            (1, 0, 8, 8),
            (1, 4, 8, 8),
            (0, 1, 8, 8),
            (2, 0, 8, 8),
        ] {
            assert!(
                RowLayout::from_codes(l, p, w, h).is_err(),
                "{l} {p} {w} {h}"
            );
        }
        assert_eq!("uv".parse::<Parameterization>(), Ok(Parameterization::Uv));
        assert!("cube".parse::<Parameterization>().is_err());
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
