//! The raw transport store: the uncompressed matrix T, row-major, as `ltm
//! bake` and `ltm import` write it and `ltm compress` reads it.
//!
//! One little-endian file (layout in docs/FORMAT.md). Version 2 adds the
//! input identity, version 3 the row layout and per-row surface data
//! ([`Surface`](crate::Surface)), version 4 the receiving mesh of a texture layout
//! ([`ReceiverMesh`](crate::ReceiverMesh)); version 5 is one part of a sharded bake
//! ([`RawHeader::with_part`], joined by [`merge_parts`]); version 6 adds every row's
//! transport over a light plane's face ([`RawHeader::with_plane`]). A header is `hlen` = 64
//! bytes in version 1, 96 in version 2, 112 in version 3, 128 in version 4, 144 in version
//! 5 and 240 in version 6:
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 8 | magic `LTMRAW\0\x01` |
//! | 8 | 4 | version (1 to 6) |
//! | 12 | 4 | flags: bit 0 = an albedo image is stored, bit 1 = surface data (exactly in versions 3 to 6), bit 2 = receiver mesh (exactly in version 4, optional in 5 and 6), bit 3 = a part (exactly in version 5), bit 4 = near-field rows (exactly in version 6) |
//! | 16 | 4·5 | width, height, face_res, channels, block_rows |
//! | 36 | 4 | block_count = ceil(width·height / block_rows) |
//! | 40 | 8 | data_offset (multiple of 4096) |
//! | 48 | 8 | albedo_offset (0 when absent) |
//! | 56 | 4 | reserved, 0 (a reader refuses any other value) |
//! | 60 | 32 | versions 2 to 4: input identity ([`RawHeader::input_id`]; all zero in versions 3 and 4 = none) |
//! | 92 | 8 | versions 3 and 4: surface_offset |
//! | 100 | 4·2 | versions 3 and 4: row layout (0 image, 1 texture; 1 in version 4), parameterization (0 none, 1 uv, 2 sphere, 3 atlas) |
//! | 108 | 8 | version 4: mesh_offset |
//! | 116 | 8 | version 4: mesh_len, bytes of the encoded mesh |
//! | 124 | 8·2 | version 5: first row and row count of the part (mesh fields 0 without bit 2); version 6: 0 |
//! | 140 | 8 | version 6: plane_offset |
//! | 148 | 88 | version 6: the light plane ([`PlaneBasis`](crate::PlaneBasis)) |
//! | hlen − 4 | 4 | CRC-32 of bytes 0..hlen−4 |
//! | hlen | 8·block_count | block table: state (0 = pending, 1 = complete), CRC-32 of the block |
//! | flags_offset | P | one byte per row: 1 = the row is all zero, else 0 |
//! | albedo_offset | 12·P | RGB albedo per pixel, f32 (optional) |
//! | surface_offset | 28·P + 4 | versions 3 and 4: surface record per row, then the CRC-32 of the records |
//! | mesh_offset | mesh_len + 4 | version 4: the encoded mesh ([`ReceiverMesh::encode`](crate::ReceiverMesh::encode)), then its CRC-32 |
//! | data_offset | 4·P·M·C | T\[p\]\[j\]\[c\], f32 |
//! | plane_offset | 4·P·order²·C | version 6: N\[p\]\[j\]\[c\], f32, each row over the plane's face |
//!
//! A block is `block_rows` consecutive rows (the last may be shorter); its
//! CRC covers its row flags, then its albedo values, then its data, then
//! (version 6) its near-field rows. In a
//! version-5 part the block table, flags, albedo and data cover only the
//! part's rows (P is then the part's row count), the surface records and
//! mesh the whole matrix; see docs/FORMAT.md, "Parts of a sharded bake".
//!
//! Writing goes to `PATH.partial`, one block at a time with plain positioned
//! writes (so that a full disk is an error, not a signal), and the file is
//! renamed to `PATH` when every block is complete. A header with an input
//! identity is written as version 2, one without as version 1.
//! Re-opening an interrupted `.partial` resumes it only when it proves to
//! come from the same inputs: both it and the new header carry an input
//! identity, the identities are equal, and the layout and length match. Its
//! blocks marked complete whose CRC verifies are then kept, the others are
//! pending. Otherwise the file is started over, and
//! [`RawWriter::resume_state`] says why.
//!
//! Reading ([`RawStore`]) trusts nothing: a file with the magic but shorter
//! than its header implies is reported as truncated with both sizes; the
//! reserved field must be 0, every block state 1 (0 = never completed, any
//! other value is refused), every row flag 0 or 1 and every albedo value
//! finite. Row data is read with positioned reads ([`RawStore::read_rows`])
//! and trusted only once its block is verified: its CRC, finite values, and
//! every row flagged zero really zero ([`BlockVerifier`]).

mod blocks;
mod header;
mod merge;
mod store;
#[cfg(test)]
mod tests;
mod verify;
mod writer;

pub use blocks::RowBlocks;
pub(crate) use header::MAGIC as RAW_MAGIC;
pub use header::{RawHeader, RowSpan, INPUT_ID_LEN};
pub use merge::{merge_parts, MergeReport};
pub use store::RawStore;
pub use verify::BlockVerifier;
pub use writer::{RawWriter, RestartReason, ResumeState};
