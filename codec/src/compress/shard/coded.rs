//! The coded part of a sharded compression (docs/FORMAT.md, "Coded
//! parts"): one shard's coded columns, what the coding measured of each,
//! and a JSON header naming the run, the plan and the columns.
//!
//! ```text
//! "LTMCPART"  u32 version  u32 0
//! payloads    the columns' stored payloads, in column order
//! measures    META, EMPT, then per column its table entry, priority norm,
//!             measured squared error and error curve
//! header      JSON (CodedPartHeader)
//! trailer     u64 payload_len  u64 measures_len  u64 header_len
//!             u32 payload_crc  u32 measures_crc  u32 header_crc
//!             u32 trailer_crc  "LTMCPART"
//! ```
//!
//! Payloads come first so that a shard streams them to the file as it
//! codes; readers find the sections from the trailer, with positioned
//! reads, and read the payloads only to assemble.

use super::{check_tiling, shard_columns, PlanFile, RunIdentity, SHARD_FILES_VERSION};
use crate::bytes::{Reader, Writer};
use crate::column::{ColumnEntry, EncodedColumn, Encoding};
use crate::compress::feedback::{budget_for, Coding, Step};
use crate::compress::plan::ErrorCurve;
use crate::compress::{relative_error, Coder, CompressStats, Target};
use crate::container::{LtmWriter, Meta, OptionalChunks, VERSION};
use crate::dims::Dims;
use crate::empty::EmptyRows;
use crate::error::{Error, Result};
use crate::fileio::{check_regular, read_at};
use crate::limits::Limits;
use crate::output::AtomicFile;
use crate::progress::{Progress, Stage};
use crate::raw::RawStore;
use serde::{Deserialize, Serialize};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::ops::Range;
use std::path::{Path, PathBuf};

/// First and last 8 bytes of a coded part.
pub const CODED_PART_MAGIC: &[u8; 8] = b"LTMCPART";

/// Bytes before the payloads: magic, version, reserved.
const LEAD_LEN: u64 = 16;
/// Bytes of the trailer.
const TRAILER_LEN: u64 = 48;
/// Bytes of a column's record in the measures, without its curve.
const RECORD_LEN: usize = 40;

/// The JSON header of a coded part.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CodedPartHeader {
    /// The run.
    pub run: RunIdentity,
    /// The identifier of the plan the columns were coded with
    /// ([`PlanFile::id`]).
    pub plan_id: String,
    /// That plan's coding (bits, number, plan), for the next plan.
    pub step: Step,
    /// The shard's index (0-based).
    pub shard: u64,
    /// Its columns.
    pub columns: Range<usize>,
}

impl CodedPartHeader {
    /// The header of shard `index` (`columns`) coded with `plan`.
    pub(super) fn new(plan: &PlanFile, index: u64, columns: Range<usize>) -> Result<Self> {
        Ok(CodedPartHeader {
            run: plan.run.clone(),
            plan_id: plan.id()?,
            step: plan.step.clone(),
            shard: index,
            columns,
        })
    }
}

/// One column's record: its table entry (offset unused), priority norm,
/// measured squared error and error curve.
struct Record {
    entry: ColumnEntry,
    norm: f32,
    err: f64,
    curve: Option<ErrorCurve>,
}

/// A coded part as read: its header and measures; the payloads stay in
/// the file.
struct Part {
    path: PathBuf,
    file: File,
    header: CodedPartHeader,
    meta: Vec<u8>,
    empty: Vec<u8>,
    records: Vec<Record>,
    payload_len: u64,
    payload_crc: u32,
}

/// Codes the header's columns with `coder` and `step.plan` into the part
/// file `out` (atomically), batch by batch.
pub(super) fn write(
    coder: &Coder,
    header: &CodedPartHeader,
    step: &Step,
    out: &Path,
    progress: Progress<'_>,
) -> Result<super::CodedShard> {
    let t = coder.transposed();
    let mut file = AtomicFile::create(out)?;
    let tmp = file.tmp_path().to_path_buf();
    let mut w = BufWriter::with_capacity(1 << 20, file.file());
    let io = |e| Error::io(&tmp, e);
    w.write_all(CODED_PART_MAGIC).map_err(io)?;
    w.write_all(&SHARD_FILES_VERSION.to_le_bytes())
        .map_err(io)?;
    w.write_all(&0u32.to_le_bytes()).map_err(io)?;
    let mut measures = Writer::default();
    put_block(&mut measures, &coder.meta().encode());
    put_block(&mut measures, t.empty_rows().as_bytes());
    let (mut payload_len, mut payload_crc) = (0u64, crc32fast::Hasher::new());
    let mut err = 0.0;
    let columns = header.columns.clone();
    for batch in t.batches(columns.clone()) {
        let coded = coder.code_columns(batch.clone(), &step.plan)?;
        for ((col, e), curve) in coded.columns.iter().zip(&coded.errors).zip(&coded.curves) {
            w.write_all(&col.bytes).map_err(io)?;
            payload_crc.update(&col.bytes);
            payload_len += col.bytes.len() as u64;
            put_record(&mut measures, col, *e, curve.as_ref())?;
            err += e;
        }
        progress.report(
            Stage::Coding,
            (batch.end - columns.start) as u64,
            columns.len() as u64,
        );
    }
    let json = super::to_json(header)?;
    w.write_all(&measures.bytes).map_err(io)?;
    w.write_all(&json).map_err(io)?;
    let trailer = trailer(
        [payload_len, measures.bytes.len() as u64, json.len() as u64],
        [
            payload_crc.finalize(),
            crc32fast::hash(&measures.bytes),
            crc32fast::hash(&json),
        ],
    );
    w.write_all(&trailer).map_err(io)?;
    w.flush().map_err(io)?;
    drop(w);
    t.raw().check_unchanged()?;
    let part_bytes =
        LEAD_LEN + payload_len + measures.bytes.len() as u64 + json.len() as u64 + TRAILER_LEN;
    file.commit()?;
    Ok(super::CodedShard {
        columns,
        part_bytes,
        err,
    })
}

/// Appends a u32 length and `bytes`.
fn put_block(w: &mut Writer, bytes: &[u8]) {
    w.u32(bytes.len() as u32);
    w.bytes.extend_from_slice(bytes);
}

/// Appends a column's record.
fn put_record(
    w: &mut Writer,
    col: &EncodedColumn,
    err: f64,
    curve: Option<&ErrorCurve>,
) -> Result<()> {
    let e = &col.entry;
    let norm = col
        .norm
        .ok_or_else(|| Error::Invalid("a coded column without its priority norm".into()))?;
    w.u32(e.stored_len);
    w.u32(e.raw_len);
    w.u32(e.nnz);
    w.u32(e.crc);
    w.u8(e.depth);
    w.u8(e.encoding as u8);
    w.u8(curve.is_some() as u8);
    w.u8(0);
    w.f32(norm);
    w.u64(err.to_bits());
    w.u64(0);
    if let Some(c) = curve {
        c.write(w);
    }
    Ok(())
}

/// The trailer of sections of `lens` (payloads, measures, header) with
/// checksums `crcs`.
fn trailer(lens: [u64; 3], crcs: [u32; 3]) -> Vec<u8> {
    let mut w = Writer::default();
    lens.iter().for_each(|&l| w.u64(l));
    crcs.iter().for_each(|&c| w.u32(c));
    let crc = crc32fast::hash(&w.bytes);
    w.u32(crc);
    w.bytes.extend_from_slice(CODED_PART_MAGIC);
    w.bytes
}

/// Reads a coded part's header only (for `ltm inspect`-like listings and
/// checks).
pub fn read_coded_header(path: &Path, limits: &Limits) -> Result<CodedPartHeader> {
    Ok(read_part(path, limits)?.header)
}

/// Reads a coded part's sections other than the payloads, every checksum
/// and length checked.
fn read_part(path: &Path, limits: &Limits) -> Result<Part> {
    let corrupt =
        |what: String| Error::corrupt("coded part", format!("{}: {what}", path.display()));
    let file = File::open(path).map_err(|e| Error::io(path, e))?;
    check_regular(&file, path)?;
    let len = file.metadata().map_err(|e| Error::io(path, e))?.len();
    if len < LEAD_LEN + TRAILER_LEN {
        return Err(corrupt(format!("{len} bytes, shorter than a coded part's {} bytes of framing (a truncated or unfinished part)", LEAD_LEN + TRAILER_LEN)));
    }
    let mut lead = [0u8; LEAD_LEN as usize];
    read_at(&file, path, &mut lead, 0)?;
    let mut tail = [0u8; TRAILER_LEN as usize];
    read_at(&file, path, &mut tail, len - TRAILER_LEN)?;
    if &lead[..8] != CODED_PART_MAGIC || &tail[40..] != CODED_PART_MAGIC {
        return Err(corrupt("no LTMCPART magic at its start and end: not a coded part (`ltm compress --plan --shard`), or an unfinished one".into()));
    }
    let version = u32::from_le_bytes(lead[8..12].try_into().expect("4 bytes"));
    if version != SHARD_FILES_VERSION {
        return Err(Error::range(
            "coded part version",
            version,
            SHARD_FILES_VERSION,
        ));
    }
    if lead[12..16] != [0; 4] {
        return Err(corrupt("reserved bytes 12..16 are not zero".into()));
    }
    let mut r = Reader::new(&tail, "coded part trailer");
    let lens = [r.u64()?, r.u64()?, r.u64()?];
    let crcs = [r.u32()?, r.u32()?, r.u32()?];
    if r.u32()? != crc32fast::hash(&tail[..36]) {
        return Err(corrupt("trailer checksum mismatch".into()));
    }
    let total = lens
        .iter()
        .try_fold(LEAD_LEN + TRAILER_LEN, |a, &l| a.checked_add(l));
    if total != Some(len) {
        return Err(corrupt(format!(
            "sections of {lens:?} bytes do not fill its {len} bytes"
        )));
    }
    let section = |offset: u64, n: u64, crc: u32, what: &'static str| -> Result<Vec<u8>> {
        let _charge = limits.check_alloc(what, n, 1)?;
        let mut buf = vec![0u8; n as usize];
        read_at(&file, path, &mut buf, offset)?;
        if crc32fast::hash(&buf) != crc {
            return Err(corrupt(format!("{what} checksum mismatch")));
        }
        Ok(buf)
    };
    let measures = section(LEAD_LEN + lens[0], lens[1], crcs[1], "coded part measures")?;
    let json = section(
        LEAD_LEN + lens[0] + lens[1],
        lens[2],
        crcs[2],
        "coded part header",
    )?;
    let header: CodedPartHeader = serde_json::from_slice(&json)
        .map_err(|e| corrupt(format!("its header is not valid: {e}")))?;
    let (meta, empty, records) =
        parse_measures(&measures, header.columns.len()).map_err(|e| corrupt(e.to_string()))?;
    Ok(Part {
        path: path.into(),
        file,
        header,
        meta,
        empty,
        records,
        payload_len: lens[0],
        payload_crc: crcs[0],
    })
}

/// The META and EMPT bytes and the column records of a part's measures.
fn parse_measures(bytes: &[u8], columns: usize) -> Result<(Vec<u8>, Vec<u8>, Vec<Record>)> {
    let mut r = Reader::new(bytes, "coded part measures");
    let meta_len = r.u32()? as usize;
    let meta = r.take(meta_len)?.to_vec();
    let empty_len = r.u32()? as usize;
    let empty = r.take(empty_len)?.to_vec();
    if columns > r.remaining() / RECORD_LEN {
        return Err(Error::corrupt(
            "coded part measures",
            format!("{columns} column records in {} bytes", r.remaining()),
        ));
    }
    let mut records = Vec::with_capacity(columns);
    for j in 0..columns {
        records.push(read_record(&mut r).map_err(|e| {
            Error::corrupt("coded part measures", format!("column record {j}: {e}"))
        })?);
    }
    if r.remaining() != 0 {
        return Err(Error::corrupt(
            "coded part measures",
            format!("{} bytes after the last column record", r.remaining()),
        ));
    }
    Ok((meta, empty, records))
}

/// One column's record.
fn read_record(r: &mut Reader) -> Result<Record> {
    let (stored_len, raw_len, nnz, crc) = (r.u32()?, r.u32()?, r.u32()?, r.u32()?);
    let (depth, code, has_curve, _) = (r.u8()?, r.u8()?, r.u8()?, r.u8()?);
    let norm = r.f32()?;
    let err = f64::from_bits(r.u64()?);
    r.u64()?;
    let encoding = Encoding::from_code(code, VERSION).map_err(Error::Invalid)?;
    let finite = norm.is_finite() && norm >= 0.0 && err.is_finite() && err >= 0.0;
    if !finite || has_curve > 1 {
        return Err(Error::Invalid(format!(
            "norm {norm}, error {err}, curve flag {has_curve}: out of range"
        )));
    }
    let curve = if has_curve == 1 {
        Some(ErrorCurve::read(r)?)
    } else {
        None
    };
    Ok(Record {
        entry: ColumnEntry {
            offset: 0,
            stored_len,
            raw_len,
            nnz,
            crc,
            depth,
            encoding,
        },
        norm,
        err,
        curve,
    })
}

/// Reads the parts of one coding of `run` (any run when `None`), checked:
/// the same run and plan, each shard's columns, every shard once. Sorted
/// by shard.
fn read_coding(run: Option<&RunIdentity>, paths: &[PathBuf], limits: &Limits) -> Result<Vec<Part>> {
    let mut parts = paths
        .iter()
        .map(|p| read_part(p, limits))
        .collect::<Result<Vec<_>>>()?;
    let Some(first) = parts.first() else {
        return Err(Error::Invalid("no coded parts".into()));
    };
    let (run, plan_id) = (
        run.unwrap_or(&first.header.run).clone(),
        first.header.plan_id.clone(),
    );
    for part in &parts {
        let h = &part.header;
        h.run.validate(&part.path)?;
        run.check_same(&h.run, &part.path)?;
        if h.plan_id != plan_id {
            return Err(Error::Invalid(format!(
                "{}: was coded with plan {} (coding {} at {} bits), {} with plan {plan_id}: parts of different codings",
                part.path.display(), h.plan_id, h.step.coding, h.step.bits, first.path.display()
            )));
        }
        let expected = shard_columns(run.lights, h.shard, run.shards)?;
        if h.columns != expected || part.meta != first.meta || part.empty != first.empty {
            return Err(Error::Invalid(format!(
                "{}: shard {}/{} holds columns {:?} (expected {expected:?}) or a header that differs from {}",
                part.path.display(), h.shard, run.shards, h.columns, first.path.display()
            )));
        }
    }
    parts.sort_by_key(|p| p.header.shard);
    check_tiling(
        parts.iter().map(|p| (p.path.as_path(), p.header.shard)),
        run.shards,
        "coded part",
    )?;
    Ok(parts)
}

/// The coding of the parts `paths` of `run`: its step and what it
/// measured, summed column by column in column order.
pub(super) fn measured(
    run: &RunIdentity,
    paths: &[PathBuf],
    limits: &Limits,
) -> Result<(Step, Coding)> {
    let parts = read_coding(Some(run), paths, limits)?;
    let mut coding = Coding::default();
    for r in parts.iter().flat_map(|p| &p.records) {
        coding.push_column(r.err, r.entry.depth as u32, r.curve.as_ref());
    }
    Ok((parts[0].header.step.clone(), coding))
}

/// Writes the parts `paths` (one coding, checked) into the `.ltm` file
/// `out`, verifying every payload's checksum.
pub(super) fn assemble(paths: &[PathBuf], out: &Path, limits: &Limits) -> Result<CompressStats> {
    let parts = read_coding(None, paths, limits)?;
    let run = parts[0].header.run.clone();
    let raw = RawStore::open_with_limits(&run.raw_path, limits)?;
    run.check_raw(&raw, &parts[0].path)?;
    let mut meta = Meta::decode(&parts[0].meta)?;
    // META records image dimensions; the row layout (a texture's) is the
    // raw store's, as the coder's was.
    let dims = Dims {
        channels: meta.dims.channels,
        ..raw.dims()
    };
    if dims.to_fields() != meta.dims.to_fields() {
        return Err(Error::corrupt(
            "coded part",
            format!(
                "{}: dimensions {:?} differ from the raw store's {:?}",
                parts[0].path.display(),
                meta.dims.to_fields(),
                dims.to_fields()
            ),
        ));
    }
    meta.dims = dims;
    let empty = EmptyRows::from_bytes(&parts[0].empty, meta.dims.pixels())?;
    let mut writer = LtmWriter::create_with(
        out,
        meta.clone(),
        raw.albedo(),
        OptionalChunks {
            surface: raw.surface(),
            mesh: raw.mesh(),
            empty_rows: Some(&empty),
            near_field: None,
            column_norms: false,
            // Encoding-5 columns coded again from the file's priors.
            priors: true,
        },
    )?;
    let mut stats = CompressStats {
        raw_bytes: raw.dims().raw_bytes(),
        channels: meta.dims.channels,
        depth_histogram: vec![0; meta.max_depth() as usize + 1],
        bits: meta.bits,
        codings: parts[0].header.step.coding,
        ..Default::default()
    };
    let mut coding = Coding::default();
    for part in &parts {
        push_part(&mut writer, &meta, part, &mut stats, &mut coding, limits)?;
    }
    stats.achieved_error = relative_error(coding.err, run.norm_sq.sqrt());
    stats.target_met = match run.options.target {
        Target::MaxError(_) => {
            coding.err <= budget_for(run.options.target, run.norm_sq.sqrt()) * 1.0001
        }
        _ => true,
    };
    raw.check_unchanged()?;
    stats.file_bytes = writer.finish(stats.achieved_error as f32)?;
    Ok(stats)
}

/// Pushes a part's columns into `writer`, each payload read and checked
/// against its entry's checksum, and the whole against the part's.
fn push_part(
    writer: &mut LtmWriter,
    meta: &Meta,
    part: &Part,
    stats: &mut CompressStats,
    coding: &mut Coding,
    limits: &Limits,
) -> Result<()> {
    let mut offset = LEAD_LEN;
    let mut crc = crc32fast::Hasher::new();
    for (k, r) in part.records.iter().enumerate() {
        let j = part.header.columns.start + k;
        let n = r.entry.stored_len as u64;
        // The checks of a reader of the finished file's column table.
        let code = (r.entry.encoding as u8, VERSION);
        crate::container::check_column_entry(j, r.entry, code, meta, n)
            .map_err(|e| Error::corrupt("coded part", format!("{}: {e}", part.path.display())))?;
        if offset - LEAD_LEN + n > part.payload_len {
            return Err(Error::corrupt(
                "coded part",
                format!(
                    "{}: column {j}'s payload runs past the payloads",
                    part.path.display()
                ),
            ));
        }
        let _charge = limits.check_alloc("column payload", n, 1)?;
        let mut bytes = vec![0u8; n as usize];
        read_at(&part.file, &part.path, &mut bytes, offset)?;
        if crc32fast::hash(&bytes) != r.entry.crc {
            return Err(Error::corrupt(
                "coded part",
                format!(
                    "{}: column {j}'s payload checksum mismatch",
                    part.path.display()
                ),
            ));
        }
        crc.update(&bytes);
        offset += n;
        stats.nonzeros += r.entry.nnz as u64;
        let depth = stats
            .depth_histogram
            .get_mut(r.entry.depth as usize)
            .ok_or_else(|| {
                Error::corrupt(
                    "coded part",
                    format!(
                        "{}: column {j} at depth {}",
                        part.path.display(),
                        r.entry.depth
                    ),
                )
            })?;
        *depth += 1;
        coding.push_column(r.err, r.entry.depth as u32, r.curve.as_ref());
        writer.push_column(EncodedColumn {
            bytes,
            entry: r.entry,
            norm: Some(r.norm),
        })?;
    }
    if offset - LEAD_LEN != part.payload_len || crc.finalize() != part.payload_crc {
        return Err(Error::corrupt(
            "coded part",
            format!(
                "{}: payloads do not match their length or checksum",
                part.path.display()
            ),
        ));
    }
    Ok(())
}
