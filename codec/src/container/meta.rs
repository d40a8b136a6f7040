//! [`Meta`], the file's metadata (chunk META), and the column shape it
//! implies.

use crate::bytes::{Reader, Writer};
use crate::compress::Mode;
use crate::dims::Dims;
use crate::entropy::ColumnShape;
use crate::error::{Error, Result};
use crate::wavelet::{max_levels, Filter};

/// Bytes of the META chunk.
pub(super) const META_LEN: usize = 64;

/// Everything about a file except its columns.
#[derive(Clone, Debug, PartialEq)]
pub struct Meta {
    /// What the rows and columns are, and the stored channels.
    pub dims: Dims,
    /// How the columns were transformed.
    pub mode: Mode,
    /// The row transform over each cube face (orthonormal).
    pub row_filter: Filter,
    /// The column image transform.
    pub col_filter: Filter,
    /// Quantization bits (2..=16).
    pub bits: u32,
    /// Dither seed.
    pub seed: u64,
    /// Requested relative L2 error of the decoded matrix (0 when the file was
    /// made with a term count).
    pub target_error: f32,
    /// Measured relative L2 error of the decoded matrix.
    pub achieved_error: f32,
    /// Terms per column requested (0 when made with a target error).
    pub terms: u32,
    /// Frobenius norm of the original matrix.
    pub norm: f64,
}

impl Meta {
    /// Deepest column transform possible for the image size.
    pub fn max_depth(&self) -> u32 {
        max_levels(self.dims.width() as usize, self.dims.height() as usize)
    }

    pub(crate) fn encode(&self) -> Vec<u8> {
        let mut w = Writer::default();
        for v in self.dims.to_fields() {
            w.u32(v);
        }
        w.u8(self.mode.code());
        w.u8(self.row_filter.code());
        w.u8(self.col_filter.code());
        w.u8(self.bits as u8);
        w.u64(self.seed);
        w.f32(self.target_error);
        w.f32(self.achieved_error);
        w.u32(self.terms);
        w.bytes.extend_from_slice(&self.norm.to_le_bytes());
        w.pad_to(META_LEN);
        w.bytes
    }

    pub(crate) fn decode(bytes: &[u8]) -> Result<Meta> {
        let mut r = Reader::new(bytes, "META chunk");
        let dims = Dims::read_fields(&mut r)?;
        dims.validate()?;
        let mode = r.u8()?;
        let mode = Mode::from_code(mode)
            .ok_or_else(|| Error::range("mode", mode, "0 (2d), 1 (4d), 2 (adaptive) or 3 (pca)"))?;
        let filter =
            |c: u8| Filter::from_code(c).ok_or_else(|| Error::range("filter code", c, "0..=5"));
        let row_filter = filter(r.u8()?)?;
        let col_filter = filter(r.u8()?)?;
        if !row_filter.is_orthonormal() {
            return Err(Error::range(
                "row filter",
                row_filter,
                "an orthonormal filter (haar, d4, d6, d8)",
            ));
        }
        let bits = r.u8()? as u32;
        if !(2..=16).contains(&bits) {
            return Err(Error::range("bits", bits, "2..=16"));
        }
        let seed = r.u64()?;
        let target_error = r.f32()?;
        let achieved_error = r.f32()?;
        let terms = r.u32()?;
        if mode == Mode::Pca {
            if (row_filter, col_filter) != (Filter::Haar, Filter::Haar) {
                return Err(Error::corrupt(
                    "META chunk",
                    "filter codes of a pca file must be 0",
                ));
            }
            crate::pca::check_rank(terms as usize, dims)?;
        }
        let norm = f64::from_le_bytes(r.take(8)?.try_into().expect("8 bytes"));
        if !norm.is_finite() || norm < 0.0 {
            return Err(Error::range("matrix norm", norm, "finite and >= 0"));
        }
        Ok(Meta {
            dims,
            mode,
            row_filter,
            col_filter,
            bits,
            seed,
            target_error,
            achieved_error,
            terms,
            norm,
        })
    }
}

impl ColumnShape {
    /// The column shape of a file's metadata.
    pub fn of(meta: &Meta) -> ColumnShape {
        ColumnShape {
            width: meta.dims.width() as usize,
            height: meta.dims.height() as usize,
            channels: meta.dims.channels as usize,
            bits: meta.bits,
        }
    }
}
