//! Resource limits for decoding untrusted files, passed in by the caller as
//! image-png's `Limits` and jxl-oxide's `AllocTracker` are: every decoder
//! checks each allocation it sizes from file contents against them before
//! allocating.

use crate::error::{Error, Result};

/// Limits on what a decoder may allocate for sizes it reads from a file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Limits {
    /// Largest single buffer, in bytes, that a decoder sizes from file
    /// contents: a column table, a relighter's arena, a dense export.
    pub max_alloc_bytes: u64,
}

impl Limits {
    /// The default of [`Limits::max_alloc_bytes`]: 4 GiB.
    pub const DEFAULT_MAX_ALLOC_BYTES: u64 = 4 << 30;

    /// Limits with a largest buffer of `max_alloc_bytes`.
    pub fn with_max_alloc(max_alloc_bytes: u64) -> Limits {
        Limits { max_alloc_bytes }
    }

    /// Checks that `count` elements of `elem` bytes, sized by a file field,
    /// fit the limits, and returns the byte count.
    pub fn check_alloc(&self, what: &'static str, count: u64, elem: u64) -> Result<usize> {
        let bytes = count.checked_mul(elem);
        match bytes {
            Some(b) if b <= self.max_alloc_bytes => usize::try_from(b).map_err(|_| {
                Error::range(what, format!("{b} bytes"), "addressable on this machine")
            }),
            _ => Err(Error::Limit {
                what: what.to_string(),
                needed: bytes.unwrap_or(u64::MAX),
                limit: self.max_alloc_bytes,
            }),
        }
    }
}

impl Default for Limits {
    fn default() -> Limits {
        Limits::with_max_alloc(Limits::DEFAULT_MAX_ALLOC_BYTES)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn allocations_are_checked_against_the_limit() {
        let l = Limits::with_max_alloc(1000);
        assert_eq!(l.check_alloc("table", 10, 100).unwrap(), 1000);
        let e = l.check_alloc("table", 11, 100).unwrap_err().to_string();
        assert!(
            e.contains("table") && e.contains("1100") && e.contains("1000"),
            "{e}"
        );
        assert!(l.check_alloc("table", u64::MAX, 2).is_err());
        assert_eq!(Limits::default().max_alloc_bytes, 4 << 30);
    }
}
