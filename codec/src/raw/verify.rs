//! Checks raw blocks as their rows are read.

use super::header::CRC_CHUNK;
use super::store::RawStore;
use crate::error::{Error, Result};
use std::ops::Range;

/// Checks raw blocks as their rows are read in order: each block's CRC
/// against the block table read at open, that its values are finite and
/// that every row flagged zero is zero. A block is checked when its last
/// row is fed; the first problem of a block is reported after its CRC.
pub struct BlockVerifier<'a> {
    store: &'a RawStore,
    next_row: usize,
    hasher: crc32fast::Hasher,
    problem: Option<Error>,
}

impl<'a> BlockVerifier<'a> {
    pub(super) fn new(store: &'a RawStore, first_row: usize) -> BlockVerifier<'a> {
        BlockVerifier {
            store,
            next_row: first_row,
            hasher: crc32fast::Hasher::new(),
            problem: None,
        }
    }

    /// Feeds whole rows from row `first` (`values`: M·C values per row),
    /// which must follow the rows fed so far, and checks every block whose
    /// last row is among them.
    pub fn feed(&mut self, first: usize, values: &[f32]) -> Result<()> {
        let (p, row_len) = (
            self.store.header().stored_rows(),
            self.store.dims().row_len(),
        );
        let rows = values.len() / row_len;
        if first != self.next_row || !values.len().is_multiple_of(row_len) || first + rows > p {
            return Err(Error::Invalid(format!(
                "raw store verification: {} values from row {first} are not whole rows following row {} within 0..{p}",
                values.len(),
                self.next_row
            )));
        }
        for (k, row) in values.chunks_exact(row_len).enumerate() {
            self.row(first + k, row)?;
        }
        Ok(())
    }

    /// Checks that every row of the store has been fed.
    pub fn finish(self) -> Result<()> {
        let p = self.store.header().stored_rows();
        if self.next_row != p {
            return Err(Error::Invalid(format!(
                "raw store verification stopped at row {} of {p}",
                self.next_row
            )));
        }
        Ok(())
    }

    pub(super) fn row(&mut self, p: usize, row: &[f32]) -> Result<()> {
        let header = self.store.header();
        let b = p / header.block_rows as usize;
        let range = header.block_range(b);
        if p == range.start {
            self.start_block(range.clone());
        }
        self.hasher.update(bytemuck::cast_slice(row));
        if self.problem.is_none() {
            self.problem = self.store.check_row(p, row).err();
        }
        self.next_row = p + 1;
        if self.next_row == range.end {
            return self.end_block(b, range);
        }
        Ok(())
    }

    /// Starts block `rows`' CRC with its row flags and albedo values.
    pub(super) fn start_block(&mut self, rows: Range<usize>) {
        self.hasher = crc32fast::Hasher::new();
        self.problem = None;
        self.hasher.update(&self.store.flags[rows.clone()]);
        if let Some(a) = &self.store.albedo {
            self.hasher
                .update(bytemuck::cast_slice(&a[3 * rows.start..3 * rows.end]));
        }
    }

    pub(super) fn end_block(&mut self, b: usize, rows: Range<usize>) -> Result<()> {
        if self.store.header().plane.is_some() {
            self.feed_plane(rows.clone())?;
        }
        let computed = std::mem::replace(&mut self.hasher, crc32fast::Hasher::new()).finalize();
        let stored = self.store.block_crcs[b];
        if stored != computed {
            return Err(Error::Crc {
                chunk: format!("raw store block {b} (rows {}..{})", rows.start, rows.end),
                stored,
                computed,
            });
        }
        self.problem.take().map_or(Ok(()), Err)
    }

    /// Adds block `rows`' near-field rows to its CRC (read from the file,
    /// 8 MiB at a time) and notes the first non-finite value.
    fn feed_plane(&mut self, rows: Range<usize>) -> Result<()> {
        let len = self.store.header().plane_row_len().max(1);
        let step = (CRC_CHUNK as usize / (4 * len)).max(1);
        let mut buf = Vec::new();
        for start in rows.clone().step_by(step) {
            let part = start..(start + step).min(rows.end);
            self.store.read_plane_rows(part.clone(), &mut buf)?;
            self.hasher.update(bytemuck::cast_slice(&buf));
            if let (None, Some(i)) = (&self.problem, buf.iter().position(|v| !v.is_finite())) {
                self.problem = Some(Error::range(
                    "raw store near-field value",
                    format!("{} (row {})", buf[i], part.start + i / len),
                    "finite",
                ));
            }
        }
        Ok(())
    }
}
