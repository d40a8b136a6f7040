//! Context-modelled entropy coding of column payloads (column encodings 3,
//! 4 and 5, `.ltm` versions 3, 4 and 8): an adaptive range coder ([`range`]),
//! encoding 4's raw bit stream (`bits.rs`) and the column model that drives
//! them ([`column`]).

mod bits;
mod column;
pub mod range;

pub use column::{decode, encode, ColumnShape, ValueCoding};
