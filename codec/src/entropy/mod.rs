//! Context-modelled entropy coding of column payloads (column encoding 3,
//! `.ltm` version 3): an adaptive binary range coder ([`range`]) and the
//! column model that drives it ([`column`]).

mod column;
pub mod range;

pub use column::{decode, encode, ColumnShape};

use crate::container::Meta;

impl ColumnShape {
    /// The column shape of a file's metadata.
    pub fn of(meta: &Meta) -> ColumnShape {
        ColumnShape {
            width: meta.dims.width() as usize,
            height: meta.dims.height() as usize,
            channels: meta.dims.channels as usize,
            bits: meta.bits,
        }
    }
}
