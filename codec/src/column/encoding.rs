//! [`Encoding`], the list of column encodings, and the dispatch to their
//! codecs: decoding a stored payload ([`read_column`]) and checking a
//! column-table entry. Each encoding is one file of this module that
//! implements [`Codec`], and one line of [`encodings!`].

use super::{classed, compact, empty, plain, primed, ranged, zstd};
use super::{ColumnEntry, SparseColumn};
use crate::entropy::{ColumnShape, Priors, ValueCoding};
use crate::error::{Error, Result};

/// What a column encoding provides: one implementation per file.
pub(crate) trait Codec: Sync {
    /// The encoding's name in messages (`plain`, `range-coded`).
    fn name(&self) -> &'static str;

    /// The first `.ltm` version whose files may hold it.
    fn since_version(&self) -> u32;

    /// How a range-coded payload codes its values; `None` for the others.
    fn value_coding(&self) -> Option<ValueCoding> {
        None
    }

    /// The stored bytes of `col` and its payload length after decoding the
    /// storage (`raw_len`), or `None` when this encoding does not store it
    /// (or not smaller than the payload, for a compressing one).
    fn encode(
        &self,
        col: &SparseColumn,
        shape: &ColumnShape,
        zstd_level: i32,
    ) -> Option<(Vec<u8>, u32)>;

    /// Checks the counts and lengths of a table entry of this encoding
    /// (its depth and nonzero count are already within range): the
    /// problem, if any.
    fn check_entry(&self, e: &ColumnEntry, shape: &ColumnShape) -> std::result::Result<(), String>;

    /// Decodes column `j`'s stored payload (CRC checked) and checks every
    /// position and value; encoding 6 needs the file's `priors`.
    fn decode(
        &self,
        j: usize,
        stored: &[u8],
        e: &ColumnEntry,
        shape: &ColumnShape,
        priors: Option<&Priors>,
    ) -> Result<SparseColumn>;
}

/// Declares [`Encoding`], one line per encoding: its doc, its name, its
/// code in the column table and its codec.
macro_rules! encodings {
    ($($(#[$doc:meta])* $name:ident = $code:literal => $codec:expr,)*) => {
        /// How a column payload is stored.
        #[derive(Clone, Copy, Debug, PartialEq, Eq)]
        #[non_exhaustive]
        pub enum Encoding {
            $($(#[$doc])* $name = $code,)*
        }

        impl Encoding {
            /// Every encoding, by code.
            pub const ALL: &[Encoding] = &[$(Encoding::$name),*];

            /// The encoding's codec.
            pub(crate) fn codec(self) -> &'static dyn Codec {
                match self {
                    $(Encoding::$name => &$codec,)*
                }
            }
        }
    };
}

encodings! {
    /// No nonzero coefficient: no payload.
    Empty = 0 => empty::Empty,
    /// Payload bytes as they are.
    Plain = 1 => plain::Plain,
    /// Payload compressed with zstd.
    Zstd = 2 => zstd::Zstd,
    /// Scale codes, then the coefficients range-coded with context
    /// modelling (version 3; `crate::entropy`).
    Ranged = 3 => ranged::Ranged,
    /// Scale codes, then the coefficients range-coded with magnitude
    /// classes and raw low bits (version 4; `crate::entropy`).
    Classed = 4 => classed::Classed,
    /// Encoding 4's coefficients with the scale codes in the streams and a
    /// varint stream length (version 8; `crate::entropy`).
    Compact = 5 => compact::Compact,
    /// Encoding 5 with every context starting in the file's priors (chunk
    /// PRIO; version 9; `crate::entropy`).
    Primed = 6 => primed::Primed,
}

impl Encoding {
    /// The encoding's name in messages and reports (`plain`, `compact`).
    pub fn name(self) -> &'static str {
        self.codec().name()
    }

    /// How a range-coded payload codes its values; `None` for the others.
    pub fn value_coding(self) -> Option<ValueCoding> {
        self.codec().value_coding()
    }

    /// Whether the payload is range-coded (encodings 3, 4 and 5).
    pub fn is_range_coded(self) -> bool {
        self.value_coding().is_some()
    }

    /// The encoding of table code `code` in a file of `version`, or the
    /// problem: the codes that version may hold.
    pub(crate) fn from_code(code: u8, version: u32) -> std::result::Result<Encoding, String> {
        let known = Encoding::ALL
            .iter()
            .copied()
            .filter(|e| e.codec().since_version() <= version);
        if let Some(e) = known.clone().find(|&e| e as u8 == code) {
            return Ok(e);
        }
        let valid: Vec<String> = known
            .map(|e| format!("{} {}", e as u8, e.codec().name()))
            .collect();
        Err(format!(
            "encoding {code} in a file of version {version} (valid: {})",
            valid.join(", ")
        ))
    }
}

/// Reads and checks column `j`'s payload (entry `e`) from the DATA chunk.
pub(crate) fn read_column(
    data: &[u8],
    shape: &ColumnShape,
    priors: Option<&Priors>,
    j: usize,
    e: &ColumnEntry,
) -> Result<SparseColumn> {
    let stored = &data[e.offset as usize..(e.offset + e.stored_len as u64) as usize];
    if e.encoding != Encoding::Empty {
        check_column_crc(j, e, stored)?;
    }
    e.encoding.codec().decode(j, stored, e, shape, priors)
}

/// Column `j`'s stored payload against the CRC of its table entry.
pub(crate) fn check_column_crc(j: usize, e: &ColumnEntry, stored: &[u8]) -> Result<()> {
    let crc = crc32fast::hash(stored);
    if crc != e.crc {
        return Err(Error::Crc {
            chunk: format!("column {j}"),
            stored: e.crc,
            computed: crc,
        });
    }
    Ok(())
}
