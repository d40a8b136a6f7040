//! Steps 1 and 2 of the pipeline (Cheslack-Postava et al. 2007 §4.2, §5):
//! every row gets the full-depth row transform over each cube face
//! ([`row_forward`], Ng et al. 2003 §4), and blocks of transformed rows are
//! scattered into column order, in memory when the matrix fits the memory
//! budget, else through an unlinked temporary file. Columns are stored one
//! after the other (`(j·C + c)·P + p`), so any range of columns is one
//! contiguous read; the coding stages read them in batches of `group`
//! columns, which fit half the budget.

use super::analysis::BINS_PER_OCTAVE;
use super::TransposeOptions;
use crate::dims::Dims;
use crate::empty::EmptyRows;
use crate::error::{Error, Result};
use crate::progress::{Progress, Stage};
use crate::raw::{RawStore, RowBlocks};
use crate::wavelet::{row_forward, Filter};
use rayon::prelude::*;
use std::fs::File;
use std::io;
use std::ops::Range;
use std::path::{Path, PathBuf};

/// Bins of the depth-0 histogram of squared values built with the rows
/// (half-octaves, bin 600 starting at 1): from 2^-300, below the square of
/// the smallest f32, to 2^211, above the square of [`MAX_NORM`].
const HIST0_BINS: usize = 1024;
const HIST0_OFFSET: f64 = 600.0;

/// Bytes read at a time by the monochrome check.
const MONO_READ_BYTES: usize = 4 << 20;

/// Bytes of raw rows read at a time by the row pass (at least one row).
const ROW_READ_BYTES: usize = 8 << 20;

/// The largest Frobenius norm of a matrix the codec stores, 2^100 ≈ 1.3e30.
/// No wavelet coefficient exceeds the norm by more than the column
/// filter's small gain, so every f32 value of the encoder and of the
/// decoders — the product `q·s` of dequantization at 16 bits included —
/// stays below 2^120, far from overflow.
pub const MAX_NORM: f64 = (1u128 << 100) as f64;

/// The smallest root mean square of a matrix's nonzero values the codec
/// stores, 2^-120 ≈ 7.5e-37. Below 2^-126, f32 numbers are subnormal and
/// rounded to multiples of 2^-149: from this root mean square on, the
/// rounding of the row and column transforms, which the coder cannot
/// measure, stays below f32's rounding of ordinary values (2^-24 of the
/// norm), so the measured error is the error of the file.
pub const MIN_NONZERO_RMS: f64 = f64::from_bits((1023 - 120) << 52);

/// Bin of the depth-0 histogram (clamped in f64: no integer overflow for
/// any `e`, infinity included).
fn hist0_bin(e: f64) -> usize {
    ((e.log2() * BINS_PER_OCTAVE).floor() + HIST0_OFFSET).clamp(0.0, HIST0_BINS as f64 - 1.0)
        as usize
}

/// A raw store after the row transform and the transpose (steps 1 and 2):
/// the input of every coding setting that shares its row filter.
pub struct Transposed<'a> {
    raw: &'a RawStore,
    /// The stored dimensions (1 channel when the store is monochrome RGB).
    dims: Dims,
    row_filter: Filter,
    store: Store,
    /// Columns per batch of the coding stages.
    group: usize,
    norm_sq: f64,
    /// Depth-0 histogram of squared row-transformed values: (count, energy).
    hist0: Vec<(u64, f64)>,
    out_of_core: bool,
    /// The rows whose values are all zero.
    empty_rows: EmptyRows,
    /// The columns stored: all of them, or one shard's range.
    kept: Range<usize>,
}

impl<'a> Transposed<'a> {
    /// Row-transforms every row of `raw` with `opts.row_filter` and
    /// transposes the result into columns: in memory when the matrix fits
    /// `opts.mem_budget` bytes, else in an unlinked temporary file in
    /// `opts.temp_dir` ([`std::env::temp_dir`] when `None`). Each raw block's
    /// checksum is verified before its rows are used.
    pub fn new(
        raw: &'a RawStore,
        opts: &TransposeOptions,
        progress: Progress<'_>,
    ) -> Result<Transposed<'a>> {
        Self::with_columns(raw, opts, 0..raw.dims().lights(), progress)
    }

    /// [`Transposed::new`] keeping only the columns `kept` (one shard of a
    /// sharded compression): every row is still read and transformed, so
    /// the norm, the histogram of values, the empty rows and the monochrome
    /// test are the whole matrix's, bit for bit, while the memory (or
    /// temporary file) holds only `kept`. The coding stages accept only
    /// column ranges within `kept`.
    pub fn with_columns(
        raw: &'a RawStore,
        opts: &TransposeOptions,
        kept: Range<usize>,
        progress: Progress<'_>,
    ) -> Result<Transposed<'a>> {
        opts.validate()?;
        let src = raw.dims();
        if kept.start >= kept.end || kept.end > src.lights() {
            return Err(Error::range(
                "kept columns",
                format!("{}..{}", kept.start, kept.end),
                format!("a non-empty range within 0..{}", src.lights()),
            ));
        }
        let channels = if is_monochrome(raw)? { 1 } else { src.channels };
        let dims = Dims { channels, ..src };
        let (p, m, c) = (dims.pixels(), dims.lights(), channels as usize);
        let mem = usize::try_from(opts.mem_budget / 4).unwrap_or(usize::MAX); // in f32 values
        let total = kept.len() * c * p;
        let out_of_core = total > mem;
        let store = if out_of_core {
            let dir = opts.temp_dir.clone().unwrap_or_else(std::env::temp_dir);
            Store::File(TempFile::create_in(&dir)?)
        } else {
            Store::Memory(vec![0.0; total])
        };
        let mut t = Transposed {
            raw,
            dims,
            row_filter: opts.row_filter,
            store,
            // Batches of G columns × C × P values within half the budget.
            group: (mem / 2 / (c * p)).clamp(1, m),
            norm_sq: 0.0,
            hist0: vec![(0, 0.0); HIST0_BINS],
            out_of_core,
            empty_rows: EmptyRows::none(p),
            kept,
        };
        // Blocks of rows within a quarter of the budget (raw rows are read
        // 8 MiB at a time).
        t.fill((mem / 4 / (m * c)).clamp(1, p), progress)?;
        Ok(t)
    }

    /// Reads the rows `block` at a time (positioned reads, each raw block
    /// verified as its rows go by), checks that the matrix lies within the
    /// codec's range, transforms the rows, accumulates the norm and the
    /// depth-0 histogram, and scatters them into the store. Fails if the
    /// raw store changed meanwhile.
    fn fill(&mut self, block: usize, progress: Progress<'_>) -> Result<()> {
        let p = self.dims.pixels();
        let mut tbuf = vec![0.0f32; block * self.dims.row_len()];
        let mut reader = RowReader {
            blocks: self.raw.row_blocks(true),
            range: RangeCheck::default(),
            empty: EmptyRows::none(p),
        };
        let mut p0 = 0;
        while p0 < p {
            let rows = p0..(p0 + block).min(p);
            let rbuf = self.read_transformed(rows.clone(), &mut reader)?;
            self.add_stats(&rbuf);
            self.scatter(&rbuf, rows.clone(), &mut tbuf)?;
            p0 = rows.end;
            progress.report(Stage::Rows, p0 as u64, p as u64);
        }
        reader.range.check()?;
        self.empty_rows = reader.empty;
        reader.blocks.finish()
    }

    /// Rows `rows`, row-transformed and channel-planar:
    /// `rbuf[(r·C + c)·M + j]`. They are read a few MiB at a time, and each
    /// piece is verified, range-checked and transformed while it is in the
    /// cache.
    fn read_transformed(&self, rows: Range<usize>, reader: &mut RowReader) -> Result<Vec<f32>> {
        let (p, out_len) = (self.dims.pixels(), self.dims.row_len());
        let src_len = self.raw.dims().row_len();
        let step = (ROW_READ_BYTES / (src_len * 4)).max(1);
        let mut rbuf = vec![0.0f32; rows.len() * out_len];
        for start in rows.clone().step_by(step) {
            let piece = start..(start + step).min(rows.end);
            let Some((read, src)) = reader.blocks.next_rows(piece.len())? else {
                break;
            };
            debug_assert_eq!(read, piece);
            reader.range.add(src, src_len);
            reader.range.check_norm(piece.end, p)?;
            for (r, row) in src.chunks_exact(src_len).enumerate() {
                if row.iter().all(|&v| v == 0.0) {
                    reader.empty.set(piece.start + r);
                }
            }
            let at = (piece.start - rows.start) * out_len;
            self.transform_rows(src, &mut rbuf[at..at + piece.len() * out_len])?;
        }
        Ok(rbuf)
    }

    /// Row-transforms the raw rows `src_rows` into `rbuf`, channel-planar:
    /// `rbuf[(r·C + c)·M + j]`.
    fn transform_rows(&self, src_rows: &[f32], rbuf: &mut [f32]) -> Result<()> {
        let (n, m) = (self.dims.face_res() as usize, self.dims.lights());
        let (channels, src_channels) = (
            self.dims.channels as usize,
            self.raw.dims().channels as usize,
        );
        rbuf.par_chunks_mut(channels * m)
            .enumerate()
            .try_for_each_init(
                || vec![0.0f32; n * n],
                |work, (r, out)| -> Result<()> {
                    let row = &src_rows[r * m * src_channels..(r + 1) * m * src_channels];
                    for c in 0..channels {
                        let plane = &mut out[c * m..(c + 1) * m];
                        for (j, v) in plane.iter_mut().enumerate() {
                            *v = row[j * src_channels + c];
                        }
                        row_forward(self.row_filter, n, plane, work)?;
                    }
                    Ok(())
                },
            )
    }

    /// Adds the rows' squared values to the norm and the depth-0 histogram:
    /// per row, then summed in row order, so the sums are the same whatever
    /// the thread count and block size.
    fn add_stats(&mut self, rbuf: &[f32]) {
        let row_len = self.dims.row_len();
        let partial: Vec<RowStats> = rbuf
            .par_chunks(row_len)
            .map_init(
                || vec![(0u64, 0.0f64); HIST0_BINS],
                |hist, chunk| row_stats(chunk, hist),
            )
            .collect();
        for (norm, bins) in partial {
            self.norm_sq += norm;
            for (b, count, energy) in bins {
                self.hist0[b].0 += count;
                self.hist0[b].1 += energy;
            }
        }
    }

    /// Transposes the kept columns of a block of transformed rows through
    /// `tbuf` (`tbuf[((j − kept.start)·C + c)·rows + r]`) and writes each
    /// run into its column.
    fn scatter(&mut self, rbuf: &[f32], rows: Range<usize>, tbuf: &mut [f32]) -> Result<()> {
        let (p, m, channels) = (
            self.dims.pixels(),
            self.dims.lights(),
            self.dims.channels as usize,
        );
        let (len, kept) = (rows.len(), self.kept.clone());
        tbuf[..len * kept.len() * channels]
            .par_chunks_mut(len)
            .enumerate()
            .for_each(|(jc, run)| {
                let (j, c) = (kept.start + jc / channels, jc % channels);
                for (r, v) in run.iter_mut().enumerate() {
                    *v = rbuf[(r * channels + c) * m + j];
                }
            });
        for jc in 0..kept.len() * channels {
            self.store
                .write(jc * p + rows.start, &tbuf[jc * len..(jc + 1) * len])?;
        }
        Ok(())
    }

    /// The stored dimensions (1 channel when every row is grey).
    pub fn dims(&self) -> Dims {
        self.dims
    }

    /// The row filter the rows were transformed with; every file coded
    /// from this matrix records it.
    pub fn row_filter(&self) -> Filter {
        self.row_filter
    }

    /// The Frobenius norm of the matrix.
    pub fn norm(&self) -> f64 {
        self.norm_sq.sqrt()
    }

    /// The rows whose values are all zero (e.g. pixels of open sky): every
    /// file coded from the matrix stores them, and decodes them as 0.
    pub fn empty_rows(&self) -> &EmptyRows {
        &self.empty_rows
    }

    /// Used a temporary file.
    pub fn out_of_core(&self) -> bool {
        self.out_of_core
    }

    /// The raw store the matrix came from.
    pub(super) fn raw(&self) -> &'a RawStore {
        self.raw
    }

    /// The squared Frobenius norm.
    pub(super) fn norm_sq(&self) -> f64 {
        self.norm_sq
    }

    /// The columns stored: `0..M`, or the range of
    /// [`Transposed::with_columns`].
    pub fn kept_columns(&self) -> Range<usize> {
        self.kept.clone()
    }

    /// Checks that `columns` lies within the stored columns.
    pub(super) fn check_columns(&self, columns: &Range<usize>) -> Result<()> {
        let kept = &self.kept;
        if columns.start > columns.end || columns.start < kept.start || columns.end > kept.end {
            return Err(Error::range(
                "columns",
                format!("{}..{}", columns.start, columns.end),
                format!("a range within the stored {}..{}", kept.start, kept.end),
            ));
        }
        Ok(())
    }

    /// `columns` cut into consecutive batches that fit the memory budget.
    pub(super) fn batches(&self, columns: Range<usize>) -> impl Iterator<Item = Range<usize>> {
        let group = self.group;
        columns
            .clone()
            .step_by(group)
            .map(move |j| j..(j + group).min(columns.end))
    }

    /// The values of `columns`: `C × P` per column, channel-planar.
    pub(super) fn read_columns(&self, columns: Range<usize>) -> Result<Vec<f32>> {
        let len = self.dims.channels as usize * self.dims.pixels();
        let mut data = vec![0.0f32; columns.len() * len];
        self.store
            .read((columns.start - self.kept.start) * len, &mut data)?;
        Ok(data)
    }

    /// The first guess τ0² of the analysis for a squared-error `budget`:
    /// the smallest values of the depth-0 histogram are dropped while their
    /// energy stays within half the budget.
    pub(super) fn first_threshold(&self, budget: f64) -> f64 {
        let mut acc = 0.0;
        for (b, &(_, e)) in self.hist0.iter().enumerate() {
            if acc + e > budget * 0.5 {
                return 2f64.powf((b as f64 - HIST0_OFFSET) / BINS_PER_OCTAVE);
            }
            acc += e;
        }
        f64::MIN_POSITIVE
    }
}

/// A row's squared norm and its nonzero bins of the depth-0 histogram as
/// (bin, count, energy).
type RowStats = (f64, Vec<(usize, u64, f64)>);

/// The [`RowStats`] of `row`, accumulated in `hist` (all zero before and
/// after).
fn row_stats(row: &[f32], hist: &mut [(u64, f64)]) -> RowStats {
    let mut norm = 0.0f64;
    let mut touched = Vec::new();
    for v in row {
        let e = (*v as f64).powi(2);
        norm += e;
        if e > 0.0 {
            let b = hist0_bin(e);
            if hist[b].0 == 0 {
                touched.push(b);
            }
            hist[b].0 += 1;
            hist[b].1 += e;
        }
    }
    let bins = touched
        .into_iter()
        .map(|b| {
            let (count, energy) = std::mem::take(&mut hist[b]);
            (b, count, energy)
        })
        .collect();
    (norm, bins)
}

/// The state of the row pass's reads: the block verifier, the range check
/// and the read buffer.
struct RowReader<'a> {
    blocks: RowBlocks<'a>,
    range: RangeCheck,
    /// The all-zero rows read so far.
    empty: EmptyRows,
}

/// True when every row has equal R, G and B values: the rows are read a
/// few MiB at a time with positioned reads, in parallel, until one that is
/// not grey.
fn is_monochrome(raw: &RawStore) -> Result<bool> {
    let dims = raw.dims();
    if dims.channels != 3 {
        return Ok(false);
    }
    let (len, step) = (dims.pixels() * dims.row_len(), MONO_READ_BYTES / 12 * 3);
    let found = (0..len.div_ceil(step))
        .into_par_iter()
        .map_init(Vec::<f32>::new, |buf, k| {
            let values = k * step..((k + 1) * step).min(len);
            match raw.read_values(values, buf) {
                Err(e) => Some(Err(e)),
                Ok(()) => {
                    let grey = buf.chunks_exact(3).all(|c| c[0] == c[1] && c[1] == c[2]);
                    (!grey).then_some(Ok(()))
                }
            }
        })
        .find_any(Option::is_some)
        .flatten();
    match found {
        Some(Err(e)) => Err(e),
        Some(Ok(())) => Ok(false),
        None => Ok(true),
    }
}

/// The checks of a matrix's range from its raw values: Σv² (in f64, exact
/// enough for any f32) and the count of nonzero values, summed per row and
/// then in row order.
#[derive(Default)]
struct RangeCheck {
    sum_sq: f64,
    nonzeros: u64,
}

impl RangeCheck {
    /// Adds whole rows of `row_len` values.
    fn add(&mut self, rows: &[f32], row_len: usize) {
        let per_row: Vec<(f64, u64)> = rows
            .par_chunks(row_len)
            .map(|row| {
                row.iter()
                    .filter(|v| **v != 0.0)
                    .fold((0.0, 0), |(s, n), &v| (s + (v as f64).powi(2), n + 1))
            })
            .collect();
        for (s, n) in per_row {
            self.sum_sq += s;
            self.nonzeros += n;
        }
    }

    /// The norm of the first `rows` rows of `total` is at most
    /// [`MAX_NORM`] (so that every row-transformed value is finite). An
    /// infinite or NaN value is the block verifier's to report, with its
    /// place, when its block ends.
    fn check_norm(&self, rows: usize, total: usize) -> Result<()> {
        let norm = self.sum_sq.sqrt();
        if norm.is_finite() && norm > MAX_NORM {
            let value = if rows < total {
                format!("{norm:.3e} or more (rows 0..{rows} of {total} alone)")
            } else {
                format!("{norm:.3e}")
            };
            return Err(Error::range(
                "matrix norm (Frobenius)",
                value,
                format!("at most {MAX_NORM:.3e} = 2^100, beyond which f32 wavelet coefficients overflow: scale the matrix down"),
            ));
        }
        Ok(())
    }

    /// A zero matrix, or a norm of at most [`MAX_NORM`] with a root mean
    /// square of the nonzero values of at least [`MIN_NONZERO_RMS`].
    fn check(&self) -> Result<()> {
        if self.nonzeros == 0 {
            return Ok(());
        }
        self.check_norm(1, 1)?;
        let rms = (self.sum_sq / self.nonzeros as f64).sqrt();
        if rms < MIN_NONZERO_RMS {
            return Err(Error::range(
                "root mean square of the nonzero matrix values",
                format!("{rms:.3e}"),
                format!("at least {MIN_NONZERO_RMS:.3e} = 2^-120, below which f32 arithmetic loses precision to subnormal numbers: scale the matrix up"),
            ));
        }
        Ok(())
    }
}

/// The transposed columns, in memory or in a temporary file, as `f32`
/// values at `(j·C + c)·P + p`.
enum Store {
    Memory(Vec<f32>),
    File(TempFile),
}

impl Store {
    fn write(&mut self, offset: usize, values: &[f32]) -> Result<()> {
        match self {
            Store::Memory(v) => {
                v[offset..offset + values.len()].copy_from_slice(values);
                Ok(())
            }
            Store::File(f) => f
                .write_all_at(bytemuck::cast_slice(values), offset as u64 * 4)
                .map_err(|e| Error::io("transpose file", e)),
        }
    }

    fn read(&self, offset: usize, out: &mut [f32]) -> Result<()> {
        match self {
            Store::Memory(v) => {
                out.copy_from_slice(&v[offset..offset + out.len()]);
                Ok(())
            }
            Store::File(f) => f
                .read_exact_at(bytemuck::cast_slice_mut(out), offset as u64 * 4)
                .map_err(|e| Error::io("transpose file", e)),
        }
    }
}

/// The temporary file of the transpose: positioned reads and writes.
#[cfg(unix)]
type TempFile = UnixFile;
#[cfg(not(unix))]
type TempFile = LockedFile;

/// Unix: positioned I/O without a lock ([`std::os::unix::fs::FileExt`]); the
/// file is unlinked as soon as it is created, so its space is freed however
/// the process ends.
#[cfg(unix)]
struct UnixFile(File);

#[cfg(unix)]
impl UnixFile {
    fn create_in(dir: &Path) -> Result<UnixFile> {
        let (file, path) = create_new_in(dir)?;
        let _ = std::fs::remove_file(&path);
        Ok(UnixFile(file))
    }

    fn write_all_at(&self, bytes: &[u8], offset: u64) -> io::Result<()> {
        std::os::unix::fs::FileExt::write_all_at(&self.0, bytes, offset)
    }

    fn read_exact_at(&self, bytes: &mut [u8], offset: u64) -> io::Result<()> {
        std::os::unix::fs::FileExt::read_exact_at(&self.0, bytes, offset)
    }
}

/// Other targets: seek, then read or write, under a lock. An open file may
/// not be removable there, so it is removed when dropped (after it is
/// closed: fields drop in declaration order).
#[cfg_attr(unix, allow(dead_code))]
struct LockedFile {
    file: std::sync::Mutex<File>,
    _path: RemovedOnDrop,
}

#[cfg_attr(unix, allow(dead_code))]
struct RemovedOnDrop(PathBuf);

impl Drop for RemovedOnDrop {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

#[cfg_attr(unix, allow(dead_code))]
impl LockedFile {
    fn create_in(dir: &Path) -> Result<LockedFile> {
        let (file, path) = create_new_in(dir)?;
        Ok(LockedFile {
            file: std::sync::Mutex::new(file),
            _path: RemovedOnDrop(path),
        })
    }

    fn locked(&self) -> io::Result<std::sync::MutexGuard<'_, File>> {
        self.file
            .lock()
            .map_err(|_| io::Error::other("a thread panicked while using the file"))
    }

    fn write_all_at(&self, bytes: &[u8], offset: u64) -> io::Result<()> {
        use io::{Seek, Write};
        let mut f = self.locked()?;
        f.seek(io::SeekFrom::Start(offset))?;
        f.write_all(bytes)
    }

    fn read_exact_at(&self, bytes: &mut [u8], offset: u64) -> io::Result<()> {
        use io::{Read, Seek};
        let mut f = self.locked()?;
        f.seek(io::SeekFrom::Start(offset))?;
        f.read_exact(bytes)
    }
}

/// Creates a new file `.ltm-transpose-PID-N.tmp` in `dir`.
fn create_new_in(dir: &Path) -> Result<(File, PathBuf)> {
    for attempt in 0..100u32 {
        let path = dir.join(format!(
            ".ltm-transpose-{}-{attempt}.tmp",
            std::process::id()
        ));
        match std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create_new(true)
            .open(&path)
        {
            Ok(f) => return Ok((f, path)),
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(Error::io(path, e)),
        }
    }
    Err(Error::Invalid(format!(
        "could not create a temporary file in {}",
        dir.display()
    )))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The portable fallback reads back what it wrote at any offset and
    /// removes its file when dropped; the Unix file leaves no name behind.
    #[test]
    fn temporary_files_read_back_and_leave_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let locked = LockedFile::create_in(dir.path()).unwrap();
        locked.write_all_at(&[1, 2, 3, 4], 8).unwrap();
        locked.write_all_at(&[9, 9], 2).unwrap();
        let mut back = [0u8; 12];
        locked.read_exact_at(&mut back, 0).unwrap();
        assert_eq!(back, [0, 0, 9, 9, 0, 0, 0, 0, 1, 2, 3, 4]);
        assert!(locked.read_exact_at(&mut back, 4).is_err());
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
        drop(locked);
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
        #[cfg(unix)]
        {
            let file = UnixFile::create_in(dir.path()).unwrap();
            file.write_all_at(&[5, 6], 3).unwrap();
            let mut back = [0u8; 5];
            file.read_exact_at(&mut back, 0).unwrap();
            assert_eq!(back, [0, 0, 0, 5, 6]);
            assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
        }
    }
}
