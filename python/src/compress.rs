//! `ltm.compress`: a numpy matrix (validated as `ltm import` validates a
//! `.npy`) or a raw store, compressed to bytes or to a file.

use crate::errors::{self, value};
use crate::progress::Callback;
use ltm_codec::compress::{
    CodeOptions, CompressOptions, Quantizer, Target, TransposeOptions, DEFAULT_MAX_ERROR,
    DEFAULT_MAX_RANK, DEFAULT_PCA_BITS,
};
use ltm_codec::{default_mem_budget, Dims, Entropy, Filter, Mode, PcaOptions, Progress, RawStore};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};
use std::path::{Path, PathBuf};

mod store;

/// The coding settings of `ltm compress`, as Python passes them.
pub struct Settings {
    mode: Mode,
    max_error: Option<f64>,
    bits: Option<u32>,
    quantizer: Quantizer,
    keep: Option<usize>,
    rank: Option<usize>,
    max_rank: Option<usize>,
    row_filter: Filter,
    col_filter: Filter,
    entropy: Option<Entropy>,
    near_error: Option<f64>,
    seed: u64,
    mem_budget: u64,
}

/// A setting parsed from its name, or a ValueError.
fn parse<T: std::str::FromStr>(what: &str, s: &str) -> PyResult<T>
where
    T::Err: std::fmt::Display,
{
    s.parse().map_err(|e| value(format!("{what} '{s}': {e}")))
}

impl Settings {
    /// Checks the combination as `ltm compress` does.
    fn check(&self) -> PyResult<()> {
        if let Some(b) = self.bits {
            if !(2..=16).contains(&b) {
                return Err(value(format!("bits = {b} is out of range (valid: 2..=16)")));
            }
        }
        let pca = self.mode == Mode::Pca;
        if self.keep.is_some() && (pca || self.max_error.is_some()) {
            return Err(value(
                "keep counts wavelet coefficients per column: not with max_error, nor mode='pca'",
            ));
        }
        if self.rank.is_some() && (!pca || self.max_error.is_some()) {
            return Err(value(
                "rank applies to mode='pca' only, and not with max_error",
            ));
        }
        if pca && self.near_error.is_some() {
            return Err(value(
                "near_error applies to the wavelet modes, whose files hold near-field rows; mode='pca' files do not",
            ));
        }
        if pca && self.entropy.is_some() {
            return Err(value(
                "entropy chooses how wavelet columns are stored; mode='pca' stores its basis with zstd",
            ));
        }
        Ok(())
    }

    fn wavelet(&self) -> CompressOptions {
        let target = match (self.keep, self.max_error) {
            (Some(n), _) => Target::Keep(n),
            (None, e) => Target::MaxError(e.unwrap_or(DEFAULT_MAX_ERROR)),
        };
        CompressOptions {
            transpose: TransposeOptions {
                row_filter: self.row_filter,
                mem_budget: self.mem_budget,
                temp_dir: None,
            },
            code: CodeOptions {
                mode: self.mode,
                col_filter: self.col_filter,
                quantizer: self.quantizer,
                bits: self.bits.unwrap_or(self.quantizer.default_bits()),
                raise_bits: self.bits.is_none(),
                target,
                seed: self.seed,
                entropy: self.entropy.unwrap_or_default(),
                near_error: self.near_error,
                ..Default::default()
            },
        }
    }

    fn pca(&self, dims: Dims) -> PcaOptions {
        PcaOptions {
            rank: self.rank,
            max_error: self.max_error.unwrap_or(DEFAULT_MAX_ERROR),
            max_rank: self
                .max_rank
                .unwrap_or_else(|| DEFAULT_MAX_RANK.min(dims.pixels().min(dims.row_len()))),
            raise_rank: self.max_rank.is_none(),
            bits: self.bits.unwrap_or(DEFAULT_PCA_BITS),
            raise_bits: self.bits.is_none(),
            seed: self.seed,
            mem_budget: self.mem_budget,
            ..PcaOptions::default()
        }
    }

    /// Compresses the raw store at `raw` to `out`; the stats as
    /// (name, value) pairs.
    fn run(&self, raw: &Path, out: &Path, progress: Progress<'_>) -> PyResult<Vec<Stat>> {
        let store = RawStore::open(raw).map_err(errors::codec)?;
        let dims = store.dims();
        if self.mode == Mode::Pca {
            let s = ltm_codec::compress_pca(&store, out, &self.pca(dims), progress)
                .map_err(errors::codec)?;
            return Ok(vec![
                ("file_bytes", s.file_bytes as f64),
                ("raw_bytes", s.raw_bytes as f64),
                ("achieved_error", s.achieved_error),
                ("bits", s.bits as f64),
                ("rank", s.rank as f64),
                ("predicted_error", s.predicted_error),
                ("target_met", s.target_met as u8 as f64),
            ]);
        }
        let s =
            ltm_codec::compress(&store, out, &self.wavelet(), progress).map_err(errors::codec)?;
        Ok(vec![
            ("file_bytes", s.file_bytes as f64),
            ("raw_bytes", s.raw_bytes as f64),
            ("achieved_error", s.achieved_error),
            ("bits", s.bits as f64),
            ("nonzeros", s.nonzeros as f64),
            ("codings", s.codings as f64),
            ("target_met", s.target_met as u8 as f64),
            ("near_field_bytes", s.near_field_bytes as f64),
            ("near_field_error", s.near_field.map_or(0.0, |q| q.error)),
        ])
    }
}

/// One figure of a compression's stats.
type Stat = (&'static str, f64);

/// The stats as a dict: counts as ints, flags as bools, errors as floats.
fn stats_dict<'py>(py: Python<'py>, stats: &[Stat]) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    for &(k, v) in stats {
        match k {
            "achieved_error" | "predicted_error" | "near_field_error" => d.set_item(k, v)?,
            "target_met" => d.set_item(k, v != 0.0)?,
            _ => d.set_item(k, v as u64)?,
        }
    }
    Ok(d)
}

/// Compresses a matrix (see `ltm.pyi`).
#[pyfunction]
#[pyo3(signature = (matrix, out = None, *, width = None, height = None, albedo = None,
    mode = "adaptive", max_error = None, bits = None, quantizer = "uniform", keep = None, rank = None,
    max_rank = None, row_filter = "haar", col_filter = "legall53", entropy = None,
    near_error = None, seed = 0x6c74_6d00, mem_budget = None, progress = None))]
#[allow(clippy::too_many_arguments)]
pub fn compress<'py>(
    py: Python<'py>,
    matrix: &Bound<'py, PyAny>,
    out: Option<PathBuf>,
    width: Option<u32>,
    height: Option<u32>,
    albedo: Option<&Bound<'py, PyAny>>,
    mode: &str,
    max_error: Option<f64>,
    bits: Option<u32>,
    quantizer: &str,
    keep: Option<usize>,
    rank: Option<usize>,
    max_rank: Option<usize>,
    row_filter: &str,
    col_filter: &str,
    entropy: Option<&str>,
    near_error: Option<f64>,
    seed: u64,
    mem_budget: Option<u64>,
    progress: Option<Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyAny>> {
    let settings = Settings {
        mode: parse("mode", mode)?,
        max_error,
        bits,
        quantizer: parse("quantizer", quantizer)?,
        keep,
        rank,
        max_rank,
        row_filter: parse("row_filter", row_filter)?,
        col_filter: parse("col_filter", col_filter)?,
        entropy: entropy.map(|e| parse("entropy", e)).transpose()?,
        near_error,
        seed,
        mem_budget: mem_budget.unwrap_or_else(default_mem_budget),
    };
    settings.check()?;
    let dir =
        tempfile::tempdir().map_err(|e| pyo3::exceptions::PyOSError::new_err(e.to_string()))?;
    let callback = Callback::new(progress);
    let report = |s| callback.report(s);
    let progress = Progress::new(&report);
    let raw = match matrix.extract::<PathBuf>() {
        Ok(_) if albedo.is_some() || width.is_some() || height.is_some() => {
            return Err(value(
                "width, height and albedo describe an array; a raw store carries its own",
            ))
        }
        Ok(path) => path,
        Err(_) => store::write(py, matrix, albedo, (width, height), dir.path(), progress)?,
    };
    let target = out.clone().unwrap_or_else(|| dir.path().join("out.ltm"));
    let stats = py.detach(|| settings.run(&raw, &target, progress))?;
    callback.finish()?;
    match out {
        Some(_) => Ok(stats_dict(py, &stats)?.into_any()),
        None => {
            let bytes = std::fs::read(&target).map_err(|e| {
                pyo3::exceptions::PyOSError::new_err(format!("{}: {e}", target.display()))
            })?;
            Ok(PyBytes::new(py, &bytes).into_any())
        }
    }
}
