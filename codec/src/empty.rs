//! The empty-row mask: which rows of `T` are all zero (pixels that see only
//! the background, such as open sky). A column transform spreads its
//! quantization error over neighbouring pixels, so without the mask a
//! decoded empty pixel would hold a small "ghost" of its neighbours; every
//! decoder sets the masked rows to exactly 0 instead (chunk `EMPT`,
//! docs/FORMAT.md). The encoder measures its error after the same zeroing.

use crate::error::{Error, Result};

/// One bit per row: bit `p % 8` (least significant first) of byte `p / 8`
/// is 1 when row `p` is all zero.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct EmptyRows {
    rows: usize,
    bits: Vec<u8>,
    count: usize,
}

impl EmptyRows {
    /// A mask of `rows` rows, none empty.
    pub fn none(rows: usize) -> EmptyRows {
        EmptyRows {
            rows,
            bits: vec![0; rows.div_ceil(8)],
            count: 0,
        }
    }

    /// The mask of the rows for which `empty(p)` is true.
    pub fn from_fn(rows: usize, empty: impl Fn(usize) -> bool) -> EmptyRows {
        let mut mask = EmptyRows::none(rows);
        for p in (0..rows).filter(|&p| empty(p)) {
            mask.set(p);
        }
        mask
    }

    /// Marks row `p` empty (ignored outside the mask).
    pub fn set(&mut self, p: usize) {
        if p < self.rows && !self.is_empty_row(p) {
            self.bits[p / 8] |= 1 << (p % 8);
            self.count += 1;
        }
    }

    /// Whether row `p` is all zero (false outside the mask).
    #[inline]
    pub fn is_empty_row(&self, p: usize) -> bool {
        p < self.rows && self.bits[p / 8] >> (p % 8) & 1 == 1
    }

    /// Rows covered.
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// Empty rows.
    pub fn count(&self) -> usize {
        self.count
    }

    /// The stored bytes (`ceil(rows / 8)`).
    pub fn as_bytes(&self) -> &[u8] {
        &self.bits
    }

    /// Parses a stored mask of `rows` rows: exactly `ceil(rows / 8)` bytes,
    /// the bits past the last row 0.
    pub fn from_bytes(bytes: &[u8], rows: usize) -> Result<EmptyRows> {
        let need = rows.div_ceil(8);
        if bytes.len() != need {
            return Err(Error::corrupt(
                "EMPT chunk",
                format!("{} bytes for {rows} rows (needs {need})", bytes.len()),
            ));
        }
        if !rows.is_multiple_of(8) && bytes[need - 1] >> (rows % 8) != 0 {
            return Err(Error::corrupt(
                "EMPT chunk",
                format!("bits set past row {rows} in the last byte"),
            ));
        }
        let count = bytes.iter().map(|b| b.count_ones() as usize).sum();
        Ok(EmptyRows {
            rows,
            bits: bytes.to_vec(),
            count,
        })
    }

    /// Sets the empty rows of `plane` (one value per row) to 0.
    pub fn zero(&self, plane: &mut [f32]) {
        if self.count == 0 {
            return;
        }
        for (p, v) in plane.iter_mut().enumerate().take(self.rows) {
            if self.is_empty_row(p) {
                *v = 0.0;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn masks_round_trip_and_zero_exactly_their_rows() {
        for rows in [1, 7, 8, 9, 100] {
            let mask = EmptyRows::from_fn(rows, |p| p % 3 == 0);
            assert_eq!(mask.count(), rows.div_ceil(3));
            let back = EmptyRows::from_bytes(mask.as_bytes(), rows).unwrap();
            assert_eq!(back, mask);
            let mut plane = vec![1.5f32; rows];
            mask.zero(&mut plane);
            for (p, v) in plane.iter().enumerate() {
                assert_eq!(*v, if p % 3 == 0 { 0.0 } else { 1.5 }, "row {p}");
            }
        }
        assert!(!EmptyRows::none(4).is_empty_row(9));
    }

    #[test]
    fn bad_masks_are_refused() {
        assert!(EmptyRows::from_bytes(&[0, 0], 7).is_err());
        assert!(EmptyRows::from_bytes(&[0x80], 7).is_err());
        assert!(EmptyRows::from_bytes(&[0x7f], 7).is_ok());
    }
}
