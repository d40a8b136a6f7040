//! Context-modelled entropy coding of column payloads (column encodings 3,
//! 4, 5 and 6, `.ltm` versions 3, 4, 8 and 9): an adaptive range coder
//! ([`range`]), encoding 4's raw bit stream (`bits.rs`), the column model
//! that drives them (`column.rs`) and encoding 6's per-file starting states
//! (`priors.rs`).

mod bits;
mod column;
mod priors;
pub mod range;

pub use column::{decode, encode, encode_primed, ColumnShape, ValueCoding};
pub use priors::{PriorTally, Priors, PRIOR_BINARY, PRIOR_CLASSES, PRIO_LEN};
