//! The memory budget for decoding untrusted files, passed in by the caller
//! as image-png's `Limits` and jxl-oxide's `AllocTracker` are: one total of
//! bytes, shared by every clone of a [`Limits`], that each allocation sized
//! from a file or an argument is charged to before it is made
//! ([`Limits::check_alloc`]) and for as long as it lives (the [`Charge`] it
//! returns gives the bytes back when dropped, so an owner keeps it beside
//! its buffer). Allocations made through [`Limits::vec`] are fallible too:
//! memory the system refuses is an [`Error`], never an abort.
//!
//! The default budget follows the machine ([`Limits::machine_budget`]): a
//! share of the smaller of the memory available and the address-space
//! limit.

use crate::error::{Error, Result};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

/// A total memory budget for buffers sized from files or arguments. Clones
/// share one counter, so that every file a program opens with clones of one
/// `Limits` is charged to the same budget.
#[derive(Clone, Debug)]
pub struct Limits {
    /// The budget, in bytes.
    total: u64,
    /// Bytes charged and not yet given back, shared by every clone.
    used: Arc<AtomicU64>,
}

/// Bytes charged to a [`Limits`] budget, given back when dropped: kept
/// beside the buffer they pay for (e.g. a field of the owning struct).
#[must_use = "the bytes are given back to the budget when the charge is dropped"]
#[derive(Debug, Default)]
pub struct Charge {
    /// Per budget charged: its counter and the bytes charged to it.
    parts: Vec<(Arc<AtomicU64>, u64)>,
}

impl Charge {
    /// Bytes held by this charge.
    pub fn bytes(&self) -> u64 {
        self.parts.iter().map(|p| p.1).sum()
    }

    /// One charge holding `self`'s bytes and `other`'s, for an owner of
    /// several buffers.
    pub fn join(mut self, mut other: Charge) -> Charge {
        for (used, bytes) in other.parts.drain(..) {
            match self.parts.iter_mut().find(|p| Arc::ptr_eq(&p.0, &used)) {
                Some(p) => p.1 += bytes,
                None => self.parts.push((used, bytes)),
            }
        }
        self
    }
}

impl Clone for Charge {
    /// A charge for a copy of the buffers: the same bytes charged again
    /// (unchecked: the copy is already made).
    fn clone(&self) -> Charge {
        for (used, bytes) in &self.parts {
            used.fetch_add(*bytes, Ordering::AcqRel);
        }
        Charge {
            parts: self.parts.clone(),
        }
    }
}

impl Drop for Charge {
    fn drop(&mut self) {
        for (used, bytes) in &self.parts {
            used.fetch_sub(*bytes, Ordering::AcqRel);
        }
    }
}

impl Limits {
    /// The budget where the machine's memory is unknown: 4 GiB.
    pub const FALLBACK_BYTES: u64 = 4 << 30;
    /// The share of the machine's memory the default budget takes, in
    /// percent (the rest is headroom for buffers too small to charge).
    pub const MACHINE_SHARE_PERCENT: u64 = 75;

    /// A budget of `total` bytes in all, with a counter of its own.
    pub fn with_max_alloc(total: u64) -> Limits {
        Limits {
            total,
            used: Arc::new(AtomicU64::new(0)),
        }
    }

    /// The budget of [`Limits::machine_budget`].
    pub fn for_machine() -> Limits {
        Limits::with_max_alloc(Limits::machine_budget())
    }

    /// [`Limits::MACHINE_SHARE_PERCENT`] of the smaller of the memory
    /// available (`MemAvailable` of `/proc/meminfo`) and this process's
    /// address-space limit (`RLIMIT_AS`); [`Limits::FALLBACK_BYTES`] where
    /// neither is known.
    pub fn machine_budget() -> u64 {
        match (mem_available(), address_space_limit()) {
            (None, None) => Limits::FALLBACK_BYTES,
            (a, b) => {
                let least = a.unwrap_or(u64::MAX).min(b.unwrap_or(u64::MAX));
                least / 100 * Limits::MACHINE_SHARE_PERCENT
            }
        }
    }

    /// The budget, in bytes.
    pub fn max_alloc_bytes(&self) -> u64 {
        self.total
    }

    /// Bytes charged now (by every clone).
    pub fn used_bytes(&self) -> u64 {
        self.used.load(Ordering::Acquire)
    }

    /// Checks that `count` elements of `elem` bytes, sized by a file field
    /// or an argument, fit what is left of the budget, and charges them:
    /// the returned [`Charge`] gives them back when dropped.
    pub fn check_alloc(&self, what: &'static str, count: u64, elem: u64) -> Result<Charge> {
        let bytes = count.checked_mul(elem);
        let charged = bytes.filter(|&b| usize::try_from(b).is_ok()).and_then(|b| {
            self.used
                .fetch_update(Ordering::AcqRel, Ordering::Acquire, |u| {
                    u.checked_add(b).filter(|&n| n <= self.total)
                })
                .ok()
                .map(|_| b)
        });
        match charged {
            Some(b) => Ok(Charge {
                parts: vec![(self.used.clone(), b)],
            }),
            None => Err(Error::Limit {
                what: what.to_string(),
                needed: bytes.unwrap_or(u64::MAX),
                available: self.total.saturating_sub(self.used_bytes()),
                limit: self.total,
            }),
        }
    }

    /// `count` copies of `value`, charged to the budget and allocated
    /// fallibly: a vector the budget or the system refuses is an error
    /// naming `what`, never an abort.
    pub fn vec<T: Clone>(
        &self,
        what: &'static str,
        count: usize,
        value: T,
    ) -> Result<(Vec<T>, Charge)> {
        let charge = self.check_alloc(what, count as u64, std::mem::size_of::<T>() as u64)?;
        let mut v = Vec::new();
        v.try_reserve_exact(count).map_err(|_| Error::OutOfMemory {
            what: what.to_string(),
            needed: charge.bytes(),
            limit: self.total,
        })?;
        v.resize(count, value);
        Ok((v, charge))
    }
}

impl Default for Limits {
    /// The budget of [`Limits::for_machine`].
    fn default() -> Limits {
        Limits::for_machine()
    }
}

/// `MemAvailable` of `/proc/meminfo`, in bytes.
fn mem_available() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    kib.checked_mul(1024)
}

/// This process's soft address-space limit (`RLIMIT_AS`), in bytes, if any.
#[cfg(unix)]
fn address_space_limit() -> Option<u64> {
    rustix::process::getrlimit(rustix::process::Resource::As).current
}

/// No address-space limit is known off Unix.
#[cfg(not(unix))]
fn address_space_limit() -> Option<u64> {
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn allocations_are_checked_against_the_limit() {
        let l = Limits::with_max_alloc(1000);
        assert_eq!(l.check_alloc("table", 10, 100).unwrap().bytes(), 1000);
        let e = l.check_alloc("table", 11, 100).unwrap_err().to_string();
        assert!(
            e.contains("table") && e.contains("1100") && e.contains("1000"),
            "{e}"
        );
        assert!(l.check_alloc("table", u64::MAX, 2).is_err());
        let m = Limits::machine_budget();
        assert!(m > 0);
        assert!(
            m == Limits::FALLBACK_BYTES
                || mem_available().is_some()
                || address_space_limit().is_some()
        );
    }

    #[test]
    fn the_budget_is_a_total_shared_by_clones_and_given_back_on_drop() {
        let l = Limits::with_max_alloc(1000);
        let a = l.check_alloc("first", 600, 1).unwrap();
        let clone = l.clone();
        let e = clone.check_alloc("second", 600, 1).unwrap_err().to_string();
        assert!(
            e.contains("second") && e.contains("600") && e.contains("400"),
            "{e}"
        );
        let b = clone.check_alloc("second", 400, 1).unwrap();
        assert_eq!(l.used_bytes(), 1000);
        let both = a.join(b);
        assert_eq!(both.bytes(), 1000);
        drop(both);
        assert_eq!(l.used_bytes(), 0);
        // A budget of its own is not charged by another's clones.
        let other = Limits::with_max_alloc(1000);
        let _c = other.check_alloc("third", 1000, 1).unwrap();
        assert_eq!(l.used_bytes(), 0);
        let (v, charge) = l.vec("values", 100, 0u32).unwrap();
        assert_eq!((v.len(), charge.bytes(), l.used_bytes()), (100, 400, 400));
        assert!(l.vec("values", 1000, 0u8).is_err());
    }
}
