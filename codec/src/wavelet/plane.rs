//! The plane view the 2D steps work on, and how an inverse step treats its
//! rows.

use crate::error::{Error, Result};

/// A mutable view of the top-left `width` × `height` region of a plane of
/// `lanes` interleaved images: pixel `(x, y)` of image `c` is
/// `data[(y·stride + x)·lanes + c]` (`stride`, `width` and `height` count
/// pixels). One lane is a plain image.
///
/// [`PlaneMut::new`] checks the geometry once (a region of at least 1×1, at
/// least one lane, `stride >= width`, and `data` long enough for the
/// region), so the steps that take a view check only their scratch.
#[derive(Debug)]
pub struct PlaneMut<'a> {
    pub(super) data: &'a mut [f32],
    pub(super) stride: usize,
    pub(super) width: usize,
    pub(super) height: usize,
    pub(super) lanes: usize,
}

impl<'a> PlaneMut<'a> {
    /// The `width` × `height` region of `data` (rows `stride` pixels apart,
    /// `lanes` interleaved images). Errors name the value and its valid
    /// range: an empty region, no lanes, a stride below the width, sizes
    /// whose product overflows, or `data` shorter than the region.
    pub fn new(
        data: &'a mut [f32],
        stride: usize,
        width: usize,
        height: usize,
        lanes: usize,
    ) -> Result<PlaneMut<'a>> {
        if width == 0 || height == 0 {
            return Err(Error::range(
                "wavelet region size",
                format!("{width}x{height}"),
                "at least 1x1",
            ));
        }
        if lanes == 0 {
            return Err(Error::range("interleaved lanes", lanes, "at least 1"));
        }
        if stride < width {
            return Err(Error::range(
                "wavelet row stride",
                stride,
                format!(">= width {width}"),
            ));
        }
        let need = (height - 1)
            .checked_mul(stride)
            .and_then(|n| n.checked_add(width))
            .and_then(|n| n.checked_mul(lanes))
            .ok_or_else(|| {
                Error::range(
                    "wavelet plane size",
                    format!("{height} rows of stride {stride} x {lanes} lanes"),
                    format!("at most {} samples", usize::MAX),
                )
            })?;
        if data.len() < need {
            return Err(Error::BufferTooSmall {
                what: "wavelet data",
                len: data.len(),
                need,
            });
        }
        Ok(PlaneMut {
            data,
            stride,
            width,
            height,
            lanes,
        })
    }

    /// A whole `width` × `height` image of `lanes` interleaved images (rows
    /// `width` pixels apart): [`PlaneMut::new`] with `stride = width`.
    pub fn image(
        data: &'a mut [f32],
        width: usize,
        height: usize,
        lanes: usize,
    ) -> Result<PlaneMut<'a>> {
        PlaneMut::new(data, width, width, height, lanes)
    }

    /// Pixels between the starts of two rows.
    pub fn stride(&self) -> usize {
        self.stride
    }

    /// Width of the region, in pixels.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height of the region, in rows.
    pub fn height(&self) -> usize {
        self.height
    }

    /// Interleaved images.
    pub fn lanes(&self) -> usize {
        self.lanes
    }

    /// Samples in the region (`width · height · lanes`): the scratch a step
    /// of it needs.
    pub fn samples(&self) -> usize {
        self.width * self.height * self.lanes
    }

    /// Samples between the starts of two rows (`stride · lanes`).
    pub(super) fn row_stride(&self) -> usize {
        self.stride * self.lanes
    }

    /// Samples of a row of the region (`width · lanes`).
    pub(super) fn row_len(&self) -> usize {
        self.width * self.lanes
    }

    /// Errors unless `work` holds at least [`PlaneMut::samples`] values.
    pub(super) fn check_scratch(&self, what: &'static str, work: &[f32]) -> Result<()> {
        let need = self.samples();
        if work.len() < need {
            return Err(Error::BufferTooSmall {
                what,
                len: work.len(),
                need,
            });
        }
        Ok(())
    }
}

/// How an inverse step ([`super::inverse_step`]) treats the rows of its
/// plane.
#[derive(Debug)]
pub enum RowMode<'a> {
    /// Every row of the region is filtered, in place.
    Dense,
    /// Rows known to be zero are skipped.
    ///
    /// `nonzero[y]` (at least `height` flags) says whether image row `y`
    /// (all `stride` pixels of it) may hold a nonzero value; a row marked
    /// `false` must be all zero. Rows that are zero in both of their band
    /// rows' inputs are neither filtered nor read, and come out zero. On
    /// return the first `height` flags describe the rows after the step the
    /// same way (a flag may be `true` for a row that happens to be zero,
    /// never the reverse).
    ///
    /// The output equals the dense step's as f32 values: computed rows get
    /// the same arithmetic bit for bit; a skipped row is `+0.0` where the
    /// dense step may give `−0.0`.
    Sparse {
        /// One flag per image row, updated by the step.
        nonzero: &'a mut [bool],
        /// `None`: the step runs in place. `Some(out)`: the plane must be a
        /// whole image (`stride = width`); `out` (at least `width · height
        /// · lanes` values) gets every row of the result (zero where
        /// `nonzero` comes back `false`), the plane's data is left as
        /// scratch (its values afterwards are unspecified), and the step's
        /// `work` is not used (it may be empty). For a lifting filter this
        /// is one pass, where the in-place step also copies its result
        /// back.
        out: Option<&'a mut [f32]>,
    },
}

impl<'a> RowMode<'a> {
    /// [`RowMode::Sparse`] in place.
    pub fn sparse(nonzero: &'a mut [bool]) -> RowMode<'a> {
        RowMode::Sparse { nonzero, out: None }
    }

    /// [`RowMode::Sparse`] into `out`.
    pub fn sparse_into(nonzero: &'a mut [bool], out: &'a mut [f32]) -> RowMode<'a> {
        RowMode::Sparse {
            nonzero,
            out: Some(out),
        }
    }
}
