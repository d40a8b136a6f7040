//! [`PcaModel`], a decoded `pca` file: the one reconstruction of its rows.

use super::QuantizedMatrix;
use crate::dims::Dims;
use crate::empty::EmptyRows;
use crate::error::{Error, Result};
use crate::raw::RawStore;
use faer::linalg::matmul::matmul;
use faer::{Accum, MatMut, MatRef, Par};

/// A decoded PCA file: mean row, quantized basis and coefficients.
#[derive(Clone, Debug)]
pub struct PcaModel {
    dims: Dims,
    mean: Vec<f32>,
    /// `K × N`, prediction stride `C`.
    basis: QuantizedMatrix,
    /// `K × P` (component-major), prediction stride 1.
    coefficients: QuantizedMatrix,
    /// The decoded basis, `K × N`, row-major.
    basis_values: Vec<f64>,
    /// Rows the raw store flagged all zero (chunk EMPT): decoded as 0.
    empty_rows: Option<EmptyRows>,
}

impl PcaModel {
    /// Assembles a model, checking the parts' shapes against `dims`.
    pub fn new(
        dims: Dims,
        mean: Vec<f32>,
        basis: QuantizedMatrix,
        coefficients: QuantizedMatrix,
    ) -> Result<PcaModel> {
        let (p, n) = (dims.pixels(), dims.row_len());
        let k = basis.rows;
        let ok = mean.len() == n
            && (basis.cols, basis.stride) == (n, dims.channels as usize)
            && (coefficients.rows, coefficients.cols, coefficients.stride) == (k, p, 1)
            && basis.bits == coefficients.bits
            && (1..=p.min(n)).contains(&k);
        if !ok {
            return Err(Error::Invalid(format!(
                "PCA parts do not fit a {p}-pixel matrix of {n} values per row: mean {}, basis {}×{}, coefficients {}×{}",
                mean.len(), basis.rows, basis.cols, coefficients.rows, coefficients.cols
            )));
        }
        let basis_values = basis.dequantize().iter().map(|&v| v as f64).collect();
        Ok(PcaModel {
            dims,
            mean,
            basis,
            coefficients,
            basis_values,
            empty_rows: None,
        })
    }

    /// The model with the mask of rows that decode to exactly 0 (chunk
    /// EMPT); a mask with no row set is dropped.
    pub fn with_empty_rows(mut self, empty: Option<EmptyRows>) -> Result<PcaModel> {
        if let Some(e) = &empty {
            if e.rows() != self.dims.pixels() {
                return Err(Error::BufferTooSmall {
                    what: "empty-row mask",
                    len: e.rows(),
                    need: self.dims.pixels(),
                });
            }
        }
        self.empty_rows = empty.filter(|e| e.count() > 0);
        Ok(self)
    }

    /// Bytes of its buffers in memory (mean, basis in both forms,
    /// coefficients).
    pub fn heap_bytes(&self) -> usize {
        let quantized = |m: &QuantizedMatrix| 4 * (m.q.len() + m.scales.len());
        4 * self.mean.len()
            + quantized(&self.basis)
            + quantized(&self.coefficients)
            + 8 * self.basis_values.len()
    }

    /// The rows that decode to exactly 0, if any are marked.
    pub fn empty_rows(&self) -> Option<&EmptyRows> {
        self.empty_rows.as_ref()
    }

    /// The matrix's dimensions.
    pub fn dims(&self) -> Dims {
        self.dims
    }

    /// `K`, the number of eigen-transports.
    pub fn rank(&self) -> usize {
        self.basis.rows
    }

    /// Quantization bits.
    pub fn bits(&self) -> u32 {
        self.basis.bits
    }

    /// The mean row `μ` (`N = M·C` values, channel-interleaved as a raw row).
    pub fn mean(&self) -> &[f32] {
        &self.mean
    }

    /// The quantized basis (`K × N`).
    pub fn basis(&self) -> &QuantizedMatrix {
        &self.basis
    }

    /// The quantized coefficients (`K × P`, component-major).
    pub fn coefficients(&self) -> &QuantizedMatrix {
        &self.coefficients
    }

    /// Rows `first..first + count` of the decoded matrix, `μ + F·B` in f64
    /// (0 in the rows of the empty-row mask), into `out` (`count × N`,
    /// row-major): the reconstruction of every decoder and of the encoder's
    /// error measurement. Rows past the matrix's last are an error.
    pub fn reconstruct_rows(&self, first: usize, count: usize, out: &mut Vec<f64>) -> Result<()> {
        let pixels = self.dims.pixels();
        if first.checked_add(count).is_none_or(|end| end > pixels) {
            return Err(Error::range(
                "rows to reconstruct",
                format!("{first}..{}", first.saturating_add(count)),
                format!("within 0..{pixels}"),
            ));
        }
        let (n, k) = (self.dims.row_len(), self.rank());
        let f: Vec<f64> = (first..first + count)
            .flat_map(|px| (0..k).map(move |a| (px, a)))
            .map(|(px, a)| self.coefficients.value(a, px) as f64)
            .collect();
        out.clear();
        out.resize(count * n, 0.0);
        for row in out.chunks_exact_mut(n) {
            row.iter_mut()
                .zip(&self.mean)
                .for_each(|(o, &m)| *o = m as f64);
        }
        let dst = MatMut::from_row_major_slice_mut(out, count, n);
        let fm = MatRef::from_row_major_slice(&f, count, k);
        let bm = MatRef::from_row_major_slice(&self.basis_values, k, n);
        matmul(dst, Accum::Add, fm, bm, 1.0, Par::rayon(0));
        if let Some(e) = &self.empty_rows {
            for (r, row) in out.chunks_exact_mut(n).enumerate() {
                if e.is_empty_row(first + r) {
                    row.fill(0.0);
                }
            }
        }
        Ok(())
    }

    /// `‖T − T̂‖²_F` against the store (f64, `T̂` rounded to f32 as decoders
    /// return it), in blocks of about
    /// `block_values` values.
    pub(crate) fn error2(&self, raw: &RawStore, block_values: usize) -> Result<f64> {
        let n = self.dims.row_len();
        let mut err2 = 0.0;
        let mut recon = Vec::new();
        raw.for_each_row_block(block_values, false, |start, rows| {
            self.reconstruct_rows(start, rows.len() / n, &mut recon)?;
            // Decoders round to f32: so does the measurement.
            err2 += rows
                .iter()
                .zip(&recon)
                .map(|(&t, &r)| (t as f64 - r as f32 as f64).powi(2))
                .sum::<f64>();
            Ok(())
        })?;
        Ok(err2)
    }
}

/// Checks a rank against the matrix: `1..=min(P, N)`.
pub fn check_rank(rank: usize, dims: Dims) -> Result<()> {
    let full = dims.pixels().min(dims.row_len());
    if !(1..=full).contains(&rank) {
        return Err(Error::range(
            "PCA rank",
            rank,
            format!(
                "1..={full} (at most min(pixels, lights·channels) = min({}, {}))",
                dims.pixels(),
                dims.row_len()
            ),
        ));
    }
    Ok(())
}
