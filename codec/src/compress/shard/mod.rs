//! Sharded compression: the stages of [`Transposed::code`] run apart, on
//! as many machines as there are shards, with files between them
//! (docs/FORMAT.md, "Sharded compression"):
//!
//! 1. [`analyze_shard`] → an [`AnalysisPart`] (JSON) per column range;
//! 2. [`plan_first`] → a [`PlanFile`] (JSON) from every analysis part;
//! 3. [`code_shard`] → a coded part (binary, `coded.rs`) per column range;
//! 4. [`plan_next`]: from the analyses and the coded parts, the next
//!    [`PlanFile`] when the error-feedback loop ([`Feedback`]) codes
//!    again, else `None`, and then
//! 5. [`assemble`] → the `.ltm` file.
//!
//! Every shard transforms every row (the row transform needs whole rows),
//! so that the norm and the statistics of the matrix are the whole
//! matrix's, and keeps only its columns ([`Transposed::with_columns`]).
//! Each column's measured error and error curve travel with it and are
//! summed in column order, and the loop's decisions are [`Feedback`]'s:
//! the file equals the one [`Transposed::code`] writes, byte for byte, for
//! any shard count.
//!
//! Every file names the run it belongs to ([`RunIdentity`]: the raw
//! store's length and content checksum, the options, the matrix's norm),
//! and coded parts name their plan; each stage refuses files of another
//! run, plan or shard count, and column ranges with gaps, overlaps or
//! duplicates, naming the file and the problem.

mod coded;

pub use coded::{read_coded_header, CodedPartHeader, CODED_PART_MAGIC};

use super::feedback::{budget_for, Feedback, Next, Step};
use super::{Analysis, CodeOptions, Coder, CompressStats, Target, TransposeOptions, Transposed};
use crate::error::{Error, Result};
use crate::limits::Limits;
use crate::progress::Progress;
use crate::raw::RawStore;
use crate::wavelet::Filter;
use serde::{Deserialize, Serialize};
use std::ops::Range;
use std::path::{Path, PathBuf};

/// Version of the sharded-compression files (analysis parts, plans and
/// coded parts).
pub const SHARD_FILES_VERSION: u32 = 2;

/// The `kind` of an analysis part.
pub const ANALYSIS_PART_KIND: &str = "ltm analysis part";
/// The `kind` of a plan.
pub const PLAN_KIND: &str = "ltm plan";

/// The largest JSON file (analysis part or plan) read, before the memory
/// limits: 1 GiB.
const MAX_JSON_BYTES: u64 = 1 << 30;

/// What every file of one sharded run shares: the raw store, the options
/// and what the row pass measured of the whole matrix.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunIdentity {
    /// The raw store's path as the analysis was given it, made absolute
    /// (shared storage: the same path on every machine).
    pub raw_path: PathBuf,
    /// Its length in bytes.
    pub raw_len: u64,
    /// Its content checksum ([`RawStore::content_id`]), hex.
    pub raw_id: String,
    /// The row filter.
    pub row_filter: Filter,
    /// The coding options (their bits are the first coding's).
    pub options: CodeOptions,
    /// The matrix's squared Frobenius norm, after the row pass.
    pub norm_sq: f64,
    /// Columns of the matrix.
    pub lights: usize,
    /// Shards of the run.
    pub shards: u64,
}

impl RunIdentity {
    /// The identity of a run over `t` with `options` in `shards` shards.
    fn of(t: &Transposed, options: &CodeOptions, shards: u64) -> Result<RunIdentity> {
        let raw = t.raw();
        let raw_path = std::path::absolute(raw.path()).map_err(|e| Error::io(raw.path(), e))?;
        Ok(RunIdentity {
            raw_path,
            raw_len: raw.file_len(),
            raw_id: format!("{:016x}", raw.content_id()),
            row_filter: t.row_filter(),
            options: options.clone(),
            norm_sq: t.norm_sq(),
            lights: t.dims().lights(),
            shards,
        })
    }

    /// Every field in range (a file's identity is untrusted): the options
    /// valid, `1 <= shards <= lights`, the norm finite.
    fn validate(&self, file: &Path) -> Result<()> {
        self.options
            .validate()
            .map_err(|e| Error::Invalid(format!("{}: {e}", file.display())))?;
        let problem = if self.lights == 0 || self.shards == 0 || self.shards > self.lights as u64 {
            Some(format!(
                "{} shards of {} columns (valid: 1 <= shards <= columns)",
                self.shards, self.lights
            ))
        } else if !(self.norm_sq.is_finite() && self.norm_sq >= 0.0) {
            Some(format!(
                "matrix norm² {} (valid: finite and >= 0)",
                self.norm_sq
            ))
        } else {
            None
        };
        match problem {
            Some(p) => Err(Error::Invalid(format!("{}: {p}", file.display()))),
            None => Ok(()),
        }
    }

    /// Equal identities, or an error naming `file` and the first field that
    /// differs from the run's.
    fn check_same(&self, other: &RunIdentity, file: &Path) -> Result<()> {
        let fields = [
            (
                "raw store length",
                self.raw_len.to_string(),
                other.raw_len.to_string(),
            ),
            (
                "raw store checksum",
                self.raw_id.clone(),
                other.raw_id.clone(),
            ),
            (
                "row filter",
                self.row_filter.to_string(),
                other.row_filter.to_string(),
            ),
            (
                "coding options",
                format!("{:?}", self.options),
                format!("{:?}", other.options),
            ),
            (
                "matrix norm²",
                format!("{:e}", self.norm_sq),
                format!("{:e}", other.norm_sq),
            ),
            ("columns", self.lights.to_string(), other.lights.to_string()),
            (
                "shard count",
                self.shards.to_string(),
                other.shards.to_string(),
            ),
        ];
        match fields.into_iter().find(|f| f.1 != f.2) {
            Some((field, run, found)) => Err(Error::Invalid(format!(
                "{}: belongs to another run: its {field} is {found}, the run's is {run}",
                file.display()
            ))),
            None => Ok(()),
        }
    }

    /// The raw store named by the identity is that raw store: same length
    /// and content checksum.
    fn check_raw(&self, raw: &RawStore, file: &Path) -> Result<()> {
        let id = format!("{:016x}", raw.content_id());
        if raw.file_len() != self.raw_len || id != self.raw_id {
            return Err(Error::Invalid(format!(
                "{}: was made from another raw store ({} bytes, checksum {}), not {} ({} bytes, checksum {id})",
                file.display(),
                self.raw_len,
                self.raw_id,
                raw.path().display(),
                raw.file_len()
            )));
        }
        Ok(())
    }

    /// The squared-error budget of the run's target.
    fn budget(&self) -> f64 {
        budget_for(self.options.target, self.norm_sq.sqrt())
    }
}

/// Shard `index` of `count` of `total` columns: contiguous ranges, as even
/// as possible (the first `total mod count` shards hold one column more).
pub fn shard_columns(total: usize, index: u64, count: u64) -> Result<Range<usize>> {
    if count == 0 || index >= count || count > total as u64 {
        return Err(Error::range(
            "shard",
            format!("{index}/{count}"),
            format!("0 <= I < N <= {total} (the matrix's columns)"),
        ));
    }
    let (index, count) = (index as usize, count as usize);
    let (base, extra) = (total / count, total % count);
    let start = index * base + index.min(extra);
    Ok(start..start + base + usize::from(index < extra))
}

/// One shard's analysis: the first stage of a sharded compression.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AnalysisPart {
    /// [`ANALYSIS_PART_KIND`].
    pub kind: String,
    /// [`SHARD_FILES_VERSION`].
    pub version: u32,
    /// The run.
    pub run: RunIdentity,
    /// This shard's index (0-based).
    pub shard: u64,
    /// Its columns.
    pub columns: Range<usize>,
    /// Their analysis (`None` for a term-count target, which needs none).
    pub analysis: Option<Analysis>,
}

/// The plan of one coding of a sharded run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PlanFile {
    /// [`PLAN_KIND`].
    pub kind: String,
    /// [`SHARD_FILES_VERSION`].
    pub version: u32,
    /// The run.
    pub run: RunIdentity,
    /// The coding: bits, number and plan.
    pub step: Step,
}

impl PlanFile {
    /// The plan's identifier, which coded parts record: a checksum of its
    /// JSON form, hex.
    pub fn id(&self) -> Result<String> {
        Ok(format!("{:016x}", checksum64(&to_json(self)?)))
    }
}

/// A 64-bit checksum: two CRC-32s with different seeds.
fn checksum64(bytes: &[u8]) -> u64 {
    let crc = |seed: u32| {
        let mut h = crc32fast::Hasher::new_with_initial(seed);
        h.update(bytes);
        h.finalize() as u64
    };
    crc(0) << 32 | crc(0x6c74_6d21)
}

/// `value` as JSON bytes.
pub fn to_json<T: Serialize>(value: &T) -> Result<Vec<u8>> {
    serde_json::to_vec(value).map_err(|e| Error::Invalid(format!("JSON encoding: {e}")))
}

/// Reads a JSON file of `kind` (its length charged to `limits`): the
/// analysis part or plan it holds, its kind and version checked.
pub fn read_json<T: for<'de> Deserialize<'de> + Kinded>(path: &Path, limits: &Limits) -> Result<T> {
    let len = std::fs::metadata(path)
        .map_err(|e| Error::io(path, e))?
        .len();
    if len > MAX_JSON_BYTES {
        return Err(Error::range(
            "JSON file size",
            format!("{len} bytes ({})", path.display()),
            format!("at most {MAX_JSON_BYTES}"),
        ));
    }
    let _charge = limits.check_alloc("JSON file", len, 4)?;
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let value: T = serde_json::from_slice(&bytes).map_err(|e| {
        Error::corrupt(
            T::KIND,
            format!("{}: not a valid {}: {e}", path.display(), T::KIND),
        )
    })?;
    value.check_kind(path)?;
    Ok(value)
}

/// A sharded-run JSON file: its kind and version are checked on reading.
pub trait Kinded {
    /// The expected `kind`.
    const KIND: &'static str;
    /// The file's own kind and version.
    fn kind_version(&self) -> (&str, u32);
    /// The kind and version are the expected ones.
    fn check_kind(&self, path: &Path) -> Result<()> {
        let (kind, version) = self.kind_version();
        if kind != Self::KIND || version != SHARD_FILES_VERSION {
            return Err(Error::Invalid(format!(
                "{}: is a {kind:?} file of version {version}, not a {:?} file of version {SHARD_FILES_VERSION}",
                path.display(),
                Self::KIND
            )));
        }
        Ok(())
    }
}

impl Kinded for AnalysisPart {
    const KIND: &'static str = ANALYSIS_PART_KIND;
    fn kind_version(&self) -> (&str, u32) {
        (&self.kind, self.version)
    }
}

impl Kinded for PlanFile {
    const KIND: &'static str = PLAN_KIND;
    fn kind_version(&self) -> (&str, u32) {
        (&self.kind, self.version)
    }
}

/// Stage 1: transforms every row of `raw`, keeps shard `index` of `count`
/// column ranges and analyzes them with `opts`.
pub fn analyze_shard(
    raw: &RawStore,
    transpose: &TransposeOptions,
    opts: &CodeOptions,
    (index, count): (u64, u64),
    progress: Progress<'_>,
) -> Result<AnalysisPart> {
    opts.validate()?;
    crate::nearfield::refuse_plane_rows(raw, "sharded compression")?;
    let columns = shard_columns(raw.dims().lights(), index, count)?;
    let t = Transposed::with_columns(raw, transpose, columns.clone(), progress)?;
    let coder = Coder::new(&t, opts)?;
    let analysis = match opts.target {
        Target::MaxError(_) => Some(coder.analyze(columns.clone(), progress)?),
        Target::Keep(_) => None,
    };
    raw.check_unchanged()?;
    Ok(AnalysisPart {
        kind: ANALYSIS_PART_KIND.into(),
        version: SHARD_FILES_VERSION,
        run: RunIdentity::of(&t, opts, count)?,
        shard: index,
        columns,
        analysis,
    })
}

/// The analysis parts of one run, checked: one per shard, the same run,
/// their column ranges tiling the matrix. Returns the run and the merged
/// analysis (`None` for a term count).
pub fn merge_analyses(
    parts: Vec<(PathBuf, AnalysisPart)>,
) -> Result<(RunIdentity, Option<Analysis>)> {
    let mut parts = parts;
    let run = match parts.first() {
        Some((_, first)) => first.run.clone(),
        None => return Err(Error::Invalid("no analysis parts".into())),
    };
    for (path, part) in &parts {
        part.run.validate(path)?;
        run.check_same(&part.run, path)?;
        let expected = shard_columns(run.lights, part.shard, run.shards)?;
        if part.columns != expected
            || part
                .analysis
                .as_ref()
                .is_some_and(|a| a.columns() != expected)
        {
            return Err(Error::Invalid(format!(
                "{}: shard {}/{} holds columns {:?}, expected {expected:?}",
                path.display(),
                part.shard,
                run.shards,
                part.columns
            )));
        }
    }
    parts.sort_by_key(|(_, p)| p.shard);
    check_tiling(
        parts.iter().map(|(path, p)| (path.as_path(), p.shard)),
        run.shards,
        "analysis part",
    )?;
    let mut merged: Option<Analysis> = None;
    for (_, part) in parts {
        merged = match (merged, part.analysis) {
            (None, a) => a,
            (Some(m), Some(a)) => Some(m.merge(a)?),
            (Some(_), None) => {
                return Err(Error::Invalid("analysis parts of mixed targets".into()))
            }
        };
    }
    Ok((run, merged))
}

/// Every shard `0..count` exactly once among `shards` (sorted by shard),
/// or an error naming the file and the problem.
fn check_tiling<'p>(
    shards: impl Iterator<Item = (&'p Path, u64)>,
    count: u64,
    what: &str,
) -> Result<()> {
    let mut next = 0u64;
    let mut previous: Option<&Path> = None;
    for (path, shard) in shards {
        if shard < next {
            return Err(Error::Invalid(format!(
                "{}: shard {shard}/{count} is also in {} (a duplicate {what})",
                path.display(),
                previous.map_or("another file".into(), |p| p.display().to_string())
            )));
        }
        if shard > next {
            return Err(Error::Invalid(format!(
                "{}: shard {shard}/{count} follows shard {}: the {what} of shard {next} is missing",
                path.display(),
                next.wrapping_sub(1)
            )));
        }
        next += 1;
        previous = Some(path);
    }
    if next != count {
        return Err(Error::Invalid(format!(
            "{next} {what}s of {count}: the {what}s of shards {next}..{count} are missing"
        )));
    }
    Ok(())
}

/// Stage 2: the plan of the first coding.
pub fn plan_first(run: &RunIdentity, analysis: Option<&Analysis>) -> Result<PlanFile> {
    let feedback = Feedback::new(&run.options, run.budget(), analysis)?;
    Ok(PlanFile {
        kind: PLAN_KIND.into(),
        version: SHARD_FILES_VERSION,
        run: run.clone(),
        step: feedback.first()?,
    })
}

/// Stage 4: after the coding whose parts are `coded` (their headers and
/// per-column measures), the plan of the next coding,
/// or `None` when the parts are the file.
pub fn plan_next(
    run: &RunIdentity,
    analysis: Option<&Analysis>,
    coded: &[PathBuf],
    limits: &Limits,
) -> Result<Option<PlanFile>> {
    let (step, coding) = coded::measured(run, coded, limits)?;
    let feedback = Feedback::new(&run.options, run.budget(), analysis)?;
    Ok(match feedback.next(&step, &coding)? {
        Next::Code(step) => Some(PlanFile {
            kind: PLAN_KIND.into(),
            version: SHARD_FILES_VERSION,
            run: run.clone(),
            step,
        }),
        Next::Keep { .. } => None,
    })
}

/// What a coding shard wrote.
#[derive(Clone, Debug)]
pub struct CodedShard {
    /// Its columns.
    pub columns: Range<usize>,
    /// Bytes of the part file.
    pub part_bytes: u64,
    /// The columns' measured squared error.
    pub err: f64,
}

/// Stage 3: codes shard `index` of the run's columns with `plan` into the
/// part file `out` (written atomically).
pub fn code_shard(
    raw: &RawStore,
    transpose: &TransposeOptions,
    plan: &PlanFile,
    index: u64,
    out: &Path,
    progress: Progress<'_>,
) -> Result<CodedShard> {
    let run = &plan.run;
    run.validate(out)?;
    run.check_raw(raw, out)?;
    crate::nearfield::refuse_plane_rows(raw, "sharded compression")?;
    let columns = shard_columns(run.lights, index, run.shards)?;
    let transpose = TransposeOptions {
        row_filter: run.row_filter,
        ..transpose.clone()
    };
    let t = Transposed::with_columns(raw, &transpose, columns.clone(), progress)?;
    run.check_same(&RunIdentity::of(&t, &run.options, run.shards)?, raw.path())?;
    let coder = Coder::new(&t, &run.options.with_bits(plan.step.bits))?;
    let header = CodedPartHeader::new(plan, index, columns.clone())?;
    coded::write(&coder, &header, &plan.step, out, progress)
}

/// Stage 5: the coded parts of the last coding, checked (one run, one
/// plan, every shard once, every checksum), written in column order into
/// the `.ltm` file `out` (atomically). The raw store named by the run
/// gives the albedo image, the surface data and the mesh, as
/// [`Transposed::code`] takes them from it.
pub fn assemble(parts: &[PathBuf], out: &Path, limits: &Limits) -> Result<CompressStats> {
    coded::assemble(parts, out, limits)
}
