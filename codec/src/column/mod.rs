//! Column payloads: a column as stored ([`SparseColumn`]), its table entry
//! ([`ColumnEntry`]), the writer's choice of encoding
//! ([`EncodedColumn::coded`]) and the encodings themselves, one file each
//! (`empty.rs`, `plain.rs`, `zstd.rs`, `ranged.rs`, `classed.rs`,
//! `compact.rs`, `primed.rs`), listed
//! once in [`Encoding`] (`encoding.rs`), which dispatches decoding and the
//! column table's checks to them. Layout in docs/FORMAT.md.

mod classed;
mod compact;
mod empty;
mod encoding;
mod entry;
mod plain;
mod primed;
mod ranged;
mod sparse;
#[cfg(test)]
mod tests;
mod zstd;

pub use encoding::Encoding;
pub(crate) use encoding::{check_column_crc, read_column, Codec};
pub use entry::{ColumnEntry, EncodedColumn, COLUMN_ENTRY_LEN};
pub use sparse::SparseColumn;
