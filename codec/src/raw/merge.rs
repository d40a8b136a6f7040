//! Joining the parts of a sharded bake into one raw store (`ltm merge`).
//!
//! Each part (version 5, [`RawHeader::with_part`]) holds a contiguous range
//! of rows of the same matrix. The parts are checked before anything is
//! written: every one opens as a part, all come from the same inputs (equal
//! input identity, header, surface data and mesh), and sorted by their first
//! row they cover every row exactly once (no gap, overlap or duplicate).
//! The rows are then streamed in order into a [`RawWriter`] for the whole
//! header, one output block at a time, while every part block's CRC, values
//! and row flags are verified as its rows go by ([`RawStore::row_blocks`]).
//! The writer computes the row flags and block CRCs exactly as the bake's
//! does, so the merged file equals a one-machine bake byte for byte. Any
//! problem is an [`Error::Part`] naming the part; the output's partial file
//! is then removed.

use super::header::{RawHeader, RowSpan};
use super::store::RawStore;
use super::writer::RawWriter;
use crate::error::{Error, Result};
use crate::limits::Limits;
use std::path::{Path, PathBuf};

/// What [`merge_parts`] did.
#[derive(Clone, Debug)]
pub struct MergeReport {
    /// The whole raw store written.
    pub path: PathBuf,
    /// Its header.
    pub header: RawHeader,
    /// The parts, sorted by their first row, with their rows.
    pub parts: Vec<(PathBuf, RowSpan)>,
}

/// The error for `part`: `problem`, with the sources of an underlying error.
fn part_error(part: &Path, problem: impl std::fmt::Display) -> Error {
    Error::Part {
        part: part.into(),
        problem: problem.to_string(),
    }
}

/// `e` in words with its sources (an I/O error's cause included).
fn chain(e: &Error) -> String {
    let mut text = e.to_string();
    let mut source = std::error::Error::source(e);
    while let Some(s) = source {
        text.push_str(": ");
        text.push_str(&s.to_string());
        source = s.source();
    }
    text
}

/// Opens `path` as a part, naming it in any error.
fn open(path: &Path, limits: &Limits) -> Result<RawStore> {
    RawStore::open_part(path, limits).map_err(|e| part_error(path, chain(&e)))
}

/// Joins the parts `paths` of a sharded bake into the whole raw store
/// `out` (through `out.partial`, renamed when complete). See the module
/// docs for the checks; buffers are charged to `limits`.
pub fn merge_parts(paths: &[PathBuf], out: &Path, limits: &Limits) -> Result<MergeReport> {
    let Some(first_path) = paths.first() else {
        return Err(Error::Invalid("ltm merge: no part given".into()));
    };
    let first = open(first_path, limits)?;
    let mut parts = vec![(first_path.clone(), *first.header())];
    for path in &paths[1..] {
        let store = open(path, limits)?;
        check_same_scene(&first, &store)?;
        parts.push((path.clone(), *store.header()));
    }
    parts.sort_by_key(|(_, h)| h.first_row());
    check_cover(&parts)?;
    let header = first.header().whole();
    let mut writer = RawWriter::create_with_geometry(out, header, first.surface(), first.mesh())?;
    writer.discard_on_drop();
    drop(first);
    let mut sink = BlockSink::new(header, limits)?;
    for (path, want) in &parts {
        copy_part(path, want, limits, &mut sink, &mut writer)?;
    }
    Ok(MergeReport {
        path: writer.finish()?,
        header,
        parts: parts
            .into_iter()
            .map(|(p, h)| (p, h.part.unwrap_or(RowSpan { start: 0, end: 0 })))
            .collect(),
    })
}

/// `other` comes from the same inputs as `first`: input identity, header
/// (but for its rows), surface data and receiving mesh.
fn check_same_scene(first: &RawStore, other: &RawStore) -> Result<()> {
    let (a, b) = (first.header(), other.header());
    let f = first.path().display();
    let problem = if a.input_id.is_none() || b.input_id.is_none() {
        Some(format!(
            "records no input identity, so it cannot be proven to come from the same scene as {f}"
        ))
    } else if a.input_id != b.input_id {
        Some(format!(
            "another scene: its input identity differs from that of {f}"
        ))
    } else if a.whole() != b.whole() {
        Some(format!(
            "another layout than {f} (dimensions, albedo image, block size or mesh)"
        ))
    } else if first.surface() != other.surface() || first.mesh() != other.mesh() {
        Some(format!("other surface data or receiver mesh than {f}"))
    } else {
        None
    };
    problem.map_or(Ok(()), |p| Err(part_error(other.path(), p)))
}

/// The parts, sorted by first row, cover every row of the matrix exactly
/// once.
fn check_cover(parts: &[(PathBuf, RawHeader)]) -> Result<()> {
    let span = |h: &RawHeader| h.part.unwrap_or(RowSpan { start: 0, end: 0 });
    let rows = parts[0].1.dims.pixels() as u64;
    let mut next = 0u64;
    for (k, (path, h)) in parts.iter().enumerate() {
        let s = span(h);
        let prev = k.checked_sub(1).map(|j| (&parts[j].0, span(&parts[j].1)));
        match prev {
            Some((p, ps)) if ps == s => {
                return Err(part_error(
                    path,
                    format!("duplicate: holds {s}, as {} does", p.display()),
                ))
            }
            Some((p, ps)) if s.start < ps.end => {
                return Err(part_error(
                    path,
                    format!("overlap: its {s} overlap the {ps} of {}", p.display()),
                ))
            }
            _ => {}
        }
        if s.start > next {
            let after = prev.map_or("the start of the matrix".to_string(), |(p, _)| {
                p.display().to_string()
            });
            return Err(part_error(
                path,
                format!(
                    "gap: it starts at row {}, but rows {next}..{} are in no part (after {after})",
                    s.start, s.start
                ),
            ));
        }
        next = s.end;
    }
    if next < rows {
        let (last, _) = &parts[parts.len() - 1];
        return Err(part_error(
            last,
            format!("gap: the last part ends at row {next}, but the matrix has {rows} rows: rows {next}..{rows} are in no part"),
        ));
    }
    Ok(())
}

/// Rows gathered into the whole store's blocks, each written when full.
struct BlockSink {
    header: RawHeader,
    block: usize,
    rows: Vec<f32>,
    albedo: Vec<f32>,
    _charge: crate::limits::Charge,
}

impl BlockSink {
    fn new(header: RawHeader, limits: &Limits) -> Result<BlockSink> {
        // One output block, and the reader's buffer of at most as many rows.
        let values = header.block_rows as u64 * header.dims.row_len() as u64;
        let charge = limits.check_alloc("merge row blocks", values.saturating_mul(2), 4)?;
        Ok(BlockSink {
            header,
            block: 0,
            rows: Vec::new(),
            albedo: Vec::new(),
            _charge: charge,
        })
    }

    /// Rows still wanted by the current block.
    fn wanted(&self) -> usize {
        let r = self.header.block_range(self.block);
        r.len() - self.rows.len() / self.header.dims.row_len().max(1)
    }

    /// Appends rows (and their albedo values), writing the block when full.
    fn push(&mut self, rows: &[f32], albedo: Option<&[f32]>, w: &mut RawWriter) -> Result<()> {
        self.rows.extend_from_slice(rows);
        self.albedo.extend_from_slice(albedo.unwrap_or(&[]));
        if self.wanted() == 0 {
            let a = self.header.has_albedo.then_some(self.albedo.as_slice());
            w.write_block(self.block, &self.rows, a)?;
            self.block += 1;
            self.rows.clear();
            self.albedo.clear();
        }
        Ok(())
    }
}

/// Streams the rows of the part at `path` (checked to still have the
/// header `want`) into `sink`, verifying its blocks as they go by.
fn copy_part(
    path: &Path,
    want: &RawHeader,
    limits: &Limits,
    sink: &mut BlockSink,
    writer: &mut RawWriter,
) -> Result<()> {
    let store = open(path, limits)?;
    if store.header() != want {
        return Err(part_error(path, "changed while the parts were merged"));
    }
    let named = |e: Error| part_error(path, chain(&e));
    let mut blocks = store.row_blocks(true);
    while let Some((range, rows)) = blocks.next_rows(sink.wanted()).map_err(named)? {
        let albedo = store.albedo().map(|a| &a[3 * range.start..3 * range.end]);
        sink.push(rows, albedo, writer)?;
    }
    blocks.finish().map_err(named)
}
