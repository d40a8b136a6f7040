//! Step 2's radiance per (grid normal, view texel) pair, kept once
//! computed.
//!
//! Step 2 ([`super::Shader::shade`]) blends, for each surface point, the
//! radiance of four grid normals, each seen from one texel of the slices'
//! view grid. That radiance is a pure function of the pair (grid normal,
//! view texel) for a given lighting, BRDF and local-lighting keep, and
//! neighbouring surface points share most of their pairs: a grid normal is
//! blended into every point of the cells around it, and their views fall
//! into a few view texels. So each pair is computed once, on first use, and
//! read back until the lighting, the BRDF or the keep changes.
//!
//! The table is filled concurrently by step 2's threads without locks: a
//! pair's three values are stored, then its bit is set with release
//! ordering, and a reader that sees the bit (acquire) sees the values. Two
//! threads that miss the same pair at once both compute it and store the
//! same bits, so the result never depends on the schedule.

use ltm_codec::{Charge, Limits};
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};

/// The largest table kept, in bytes (`normals² · views² · 12`); larger
/// grids shade without one. 32² normals and 128² views take 201 MB.
pub const MAX_PAIR_TABLE_BYTES: u64 = 256 << 20;

/// Bytes per pair: three `f32` values plus one bit.
const PAIR_BYTES: u64 = 12;

/// The radiance of every (grid normal, view texel) pair computed since the
/// last [`PairTable::clear`].
#[derive(Debug)]
pub(crate) struct PairTable {
    views: usize,
    done: Vec<AtomicU64>,
    value: Vec<[AtomicU32; 3]>,
    _charge: Charge,
}

impl PairTable {
    /// An empty table for `normals` grid normals and `views` view texels,
    /// charged to `limits`; `None` where it would exceed
    /// [`MAX_PAIR_TABLE_BYTES`] or the limits (step 2 then computes every
    /// pair where it is used, with the same result).
    pub(crate) fn new(normals: usize, views: usize, limits: &Limits) -> Option<PairTable> {
        let pairs = normals.checked_mul(views)?;
        if pairs as u64 * PAIR_BYTES > MAX_PAIR_TABLE_BYTES {
            return None;
        }
        let words = pairs.div_ceil(64);
        let charge = limits
            .check_alloc("step-2 pair table", pairs as u64, PAIR_BYTES)
            .ok()?
            .join(
                limits
                    .check_alloc("step-2 pair bits", words as u64, 8)
                    .ok()?,
            );
        Some(PairTable {
            views,
            done: (0..words).map(|_| AtomicU64::new(0)).collect(),
            value: (0..pairs).map(|_| Default::default()).collect(),
            _charge: charge,
        })
    }

    /// Forgets every pair (after a change of lighting, BRDF or keep).
    pub(crate) fn clear(&mut self) {
        for w in &mut self.done {
            *w.get_mut() = 0;
        }
    }

    /// The radiance of grid normal `normal` seen from view texel `view`:
    /// read back if computed, else `compute()`d and kept.
    pub(crate) fn get(
        &self,
        normal: usize,
        view: usize,
        compute: impl FnOnce() -> [f32; 3],
    ) -> [f32; 3] {
        let key = normal * self.views + view;
        let (word, bit) = (&self.done[key / 64], 1u64 << (key % 64));
        let slot = &self.value[key];
        if word.load(Ordering::Acquire) & bit != 0 {
            return slot
                .each_ref()
                .map(|a| f32::from_bits(a.load(Ordering::Relaxed)));
        }
        let value = compute();
        for (a, v) in slot.iter().zip(value) {
            a.store(v.to_bits(), Ordering::Relaxed);
        }
        word.fetch_or(bit, Ordering::Release);
        value
    }

    /// How many pairs are kept.
    #[cfg(test)]
    pub(crate) fn kept(&self) -> u32 {
        self.done
            .iter()
            .map(|w| w.load(Ordering::Relaxed).count_ones())
            .sum()
    }
}
