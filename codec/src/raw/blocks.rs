//! The one reader of a raw store's rows in order, a block of rows at a
//! time: every pass that streams the store (the transpose, the fits, the
//! error measurements) reads through [`RowBlocks`].

use super::{BlockVerifier, RawStore};
use crate::error::Result;
use std::ops::Range;

/// Reads a raw store's rows in order from row 0 with positioned reads (a
/// file truncated meanwhile is an error, not a signal), a block of rows at
/// a time. With verification, each raw block is checked by a
/// [`BlockVerifier`] as its last row goes by; [`RowBlocks::finish`] checks
/// that every row was read and that the file did not change.
pub struct RowBlocks<'a> {
    store: &'a RawStore,
    next: usize,
    buf: Vec<f32>,
    verifier: Option<BlockVerifier<'a>>,
}

impl<'a> RowBlocks<'a> {
    pub(super) fn new(store: &'a RawStore, verify: bool) -> RowBlocks<'a> {
        RowBlocks {
            store,
            next: 0,
            buf: Vec::new(),
            verifier: verify.then(|| store.verifier()),
        }
    }

    /// The next `count` rows (fewer at the end of the store; at least one),
    /// `M·C` values each, and their range; `None` once every row was read.
    pub fn next_rows(&mut self, count: usize) -> Result<Option<(Range<usize>, &[f32])>> {
        let p = self.store.header().stored_rows();
        if self.next >= p {
            return Ok(None);
        }
        let range = self.next..(self.next + count.max(1)).min(p);
        self.store.read_rows(range.clone(), &mut self.buf)?;
        if let Some(v) = self.verifier.as_mut() {
            v.feed(range.start, &self.buf)?;
        }
        self.next = range.end;
        Ok(Some((range, &self.buf)))
    }

    /// Checks that every row was verified (with verification) and that the
    /// file still has the length and modification time it had at open
    /// ([`RawStore::check_unchanged`]).
    pub fn finish(self) -> Result<()> {
        if let Some(v) = self.verifier {
            v.finish()?;
        }
        self.store.check_unchanged()
    }
}

impl RawStore {
    /// A [`RowBlocks`] reader from row 0, verifying every raw block when
    /// `verify` is set.
    pub fn row_blocks(&self, verify: bool) -> RowBlocks<'_> {
        RowBlocks::new(self, verify)
    }

    /// Calls `f` with the first row and the values (`rows × M·C`) of
    /// consecutive blocks of about `block_values` values (at least one row
    /// each) over the whole store, through [`RawStore::row_blocks`], then
    /// [`RowBlocks::finish`].
    pub(crate) fn for_each_row_block(
        &self,
        block_values: usize,
        verify: bool,
        mut f: impl FnMut(usize, &[f32]) -> Result<()>,
    ) -> Result<()> {
        let step = (block_values / self.dims().row_len()).max(1);
        let mut blocks = self.row_blocks(verify);
        while let Some((range, rows)) = blocks.next_rows(step)? {
            f(range.start, rows)?;
        }
        blocks.finish()
    }
}
