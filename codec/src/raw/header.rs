//! The raw store's header: fields, block layout, encoding and checks.

use crate::bytes::{Reader, Writer};
use crate::dims::Dims;
use crate::error::{Error, Result};
use crate::mesh::{
    ReceiverMesh, MAX_MESH_ELEMENTS, MESH_HEADER_LEN, MESH_TRIANGLE_LEN, MESH_VERTEX_LEN,
};
use crate::nearfield::{PlaneBasis, PLANE_BASIS_LEN};
use crate::surface::SURFACE_RECORD_LEN;
use std::path::Path;

pub(crate) const MAGIC: [u8; 8] = *b"LTMRAW\0\x01";
/// The newest version; every version from 1 is still read and written
/// (the version of a header is the oldest that holds what it stores;
/// version 5 is a part of a sharded bake, version 6 adds near-field rows).
pub(super) const VERSION: u32 = 6;
/// Header bytes of versions 1 to 6.
pub(super) const HEADER_LEN_V1: u64 = 64;
pub(super) const HEADER_LEN_V2: u64 = 96;
pub(super) const HEADER_LEN_V3: u64 = 112;
pub(super) const HEADER_LEN_V4: u64 = 128;
pub(super) const HEADER_LEN_V5: u64 = 144;
pub(super) const HEADER_LEN_V6: u64 = 240;
/// The longest header: the bytes a reader reads before decoding.
pub(super) const HEADER_LEN_MAX: u64 = HEADER_LEN_V6;
/// Bytes of an input identity.
pub const INPUT_ID_LEN: usize = 32;
pub(super) const FLAG_ALBEDO: u32 = 1;
pub(super) const FLAG_SURFACE: u32 = 2;
pub(super) const FLAG_MESH: u32 = 4;
pub(super) const FLAG_PART: u32 = 8;
pub(super) const FLAG_PLANE: u32 = 16;
pub(super) const DATA_ALIGN: u64 = 4096;
/// Bytes read at a time when a block's CRC is checked.
pub(super) const CRC_CHUNK: u64 = 8 << 20;

/// Header of a raw store.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RawHeader {
    /// Matrix dimensions: rows (pixels), lights (cubemap texels), channels.
    pub dims: Dims,
    /// Rows per block (the unit of writing, resuming and checksumming).
    pub block_rows: u32,
    /// An RGB albedo image is stored (monochrome transport factored as
    /// albedo × grey transport).
    pub has_albedo: bool,
    /// A digest of everything that determines the rows, defined by the
    /// writer (`ltm bake`: a SHA-256 of the resolved scene description,
    /// every mesh file's bytes and the settings), or `None` when the writer
    /// cannot tell (`ltm import`). A `.partial` file is resumed only when
    /// its identity equals the writer's. Stored in version-2 files; a
    /// header without one is written as version 1.
    pub input_id: Option<[u8; INPUT_ID_LEN]>,
    /// Per-row surface data ([`Surface`](crate::Surface)) is stored (version 3). Texture
    /// rows ([`crate::RowLayout::Texture`]) always have it.
    pub has_surface: bool,
    /// Bytes of the stored receiving mesh ([`ReceiverMesh::encoded_len`]),
    /// when one is stored (version 4; texture rows only); see
    /// [`RawHeader::with_mesh`].
    pub mesh_len: Option<u64>,
    /// The rows this file holds when it is one part of a sharded bake
    /// (version 5; see [`RawHeader::with_part`]); `None` for a whole store.
    pub part: Option<RowSpan>,
    /// The face of near-field rows, when each row's transport over a light
    /// plane is stored too (version 6; see [`RawHeader::with_plane`]).
    pub plane: Option<PlaneBasis>,
}

/// A range of rows `start..end` of the whole matrix: the rows one part of a
/// sharded bake holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RowSpan {
    /// First row.
    pub start: u64,
    /// One past the last row.
    pub end: u64,
}

impl RowSpan {
    /// Rows in the span.
    pub fn len(&self) -> u64 {
        self.end.saturating_sub(self.start)
    }

    /// Whether the span holds no row.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Part `index` (0-based) of `count` contiguous parts of `rows` rows, as
    /// even as possible: the first `rows mod count` parts hold one row more.
    pub fn shard(rows: u64, index: u64, count: u64) -> RowSpan {
        let count = count.max(1);
        let (base, extra) = (rows / count, rows % count);
        let start = index * base + index.min(extra);
        RowSpan {
            start,
            end: start + base + u64::from(index < extra),
        }
    }
}

impl std::fmt::Display for RowSpan {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "rows {}..{}", self.start, self.end)
    }
}

#[derive(Clone, Copy)]
pub(super) struct Layout {
    /// Start of the block table: the header length.
    pub(super) table_offset: u64,
    pub(super) block_count: u64,
    pub(super) flags_offset: u64,
    pub(super) albedo_offset: u64,
    /// Start of the surface records (0 when absent).
    pub(super) surface_offset: u64,
    /// Start of the receiving mesh (0 when absent).
    pub(super) mesh_offset: u64,
    /// Start of the near-field rows (0 when absent).
    pub(super) plane_offset: u64,
    pub(super) data_offset: u64,
    pub(super) file_len: u64,
}

impl RawHeader {
    /// A header with a block size of about `block_bytes` of row data.
    pub fn new(dims: Dims, has_albedo: bool, block_bytes: u64) -> RawHeader {
        let row_bytes = (dims.row_len() as u64 * 4).max(1);
        let block_rows = (block_bytes / row_bytes).clamp(1, dims.pixels().max(1) as u64) as u32;
        RawHeader {
            dims,
            block_rows,
            has_albedo,
            input_id: None,
            has_surface: dims.rows.is_texture(),
            mesh_len: None,
            part: None,
            plane: None,
        }
    }

    /// The same header for one part of a sharded bake holding the rows
    /// `span` of the whole matrix (written as version 5, which always has
    /// surface data). Its block table, row flags, albedo values and row
    /// data cover those rows only, in blocks of `block_rows` from
    /// `span.start`; its surface records and mesh are the whole matrix's.
    pub fn with_part(self, span: RowSpan) -> RawHeader {
        RawHeader {
            has_surface: true,
            part: Some(span),
            ..self
        }
    }

    /// The same header as a whole store (no part range).
    pub fn whole(self) -> RawHeader {
        RawHeader { part: None, ..self }
    }

    /// Rows stored in the file: the part's rows, or every row.
    pub fn stored_rows(&self) -> usize {
        self.part.map_or(self.dims.pixels(), |s| s.len() as usize)
    }

    /// The first row stored in the file (0 but in a part): stored row `i`
    /// is row `first_row() + i` of the matrix.
    pub fn first_row(&self) -> usize {
        self.part.map_or(0, |s| s.start as usize)
    }

    /// The same header with room for `mesh`, the receiving mesh of a
    /// texture layout (written as version 4; the writer is then given this
    /// mesh, [`RawWriter::create_with_geometry`](crate::RawWriter::create_with_geometry)).
    pub fn with_mesh(self, mesh: &ReceiverMesh) -> RawHeader {
        RawHeader {
            has_surface: true,
            mesh_len: Some(mesh.encoded_len() as u64),
            ..self
        }
    }

    /// The same header with near-field rows over `plane`'s face (written as
    /// version 6, which always has surface data): each row's `order²·C`
    /// per-texel values, after the matrix ([`RawWriter::write_block_with_plane`](crate::RawWriter::write_block_with_plane)).
    pub fn with_plane(self, plane: PlaneBasis) -> RawHeader {
        RawHeader {
            has_surface: true,
            plane: Some(plane),
            ..self
        }
    }

    /// Values of one row's near-field transport (`order²·C`; 0 without).
    pub fn plane_row_len(&self) -> usize {
        self.plane.map_or(0, |b| {
            b.texels().saturating_mul(self.dims.channels as usize)
        })
    }

    /// The same header with per-row surface data (written as version 3).
    pub fn with_surface(self) -> RawHeader {
        RawHeader {
            has_surface: true,
            ..self
        }
    }

    /// The same header with an input identity (written as version 2).
    pub fn with_input_id(self, id: [u8; INPUT_ID_LEN]) -> RawHeader {
        RawHeader {
            input_id: Some(id),
            ..self
        }
    }

    /// The format version this header is written as: 6 with near-field
    /// rows, else 5 for a part of a sharded bake, else 4 with a receiving
    /// mesh, else 3 with surface data, else 2 with an input identity, else 1.
    pub fn version(&self) -> u32 {
        if self.plane.is_some() {
            6
        } else if self.part.is_some() {
            5
        } else if self.mesh_len.is_some() {
            4
        } else if self.has_surface {
            3
        } else if self.input_id.is_some() {
            2
        } else {
            1
        }
    }

    pub(super) fn header_len(&self) -> u64 {
        match self.version() {
            6 => HEADER_LEN_V6,
            5 => HEADER_LEN_V5,
            4 => HEADER_LEN_V4,
            3 => HEADER_LEN_V3,
            2 => HEADER_LEN_V2,
            _ => HEADER_LEN_V1,
        }
    }

    pub(super) fn layout(&self) -> Result<Layout> {
        self.dims.validate()?;
        if self.has_albedo && self.dims.channels != 1 {
            return Err(Error::range(
                "channels with an albedo image",
                self.dims.channels,
                "1",
            ));
        }
        if self.dims.rows.is_texture() && !self.has_surface {
            return Err(Error::Invalid(
                "a texture-space raw store must carry surface data".into(),
            ));
        }
        let mesh_len = self.checked_mesh_len()?;
        if let Some(basis) = &self.plane {
            basis.validate()?;
        }
        let all = self.dims.pixels() as u64;
        self.check_part(all)?;
        let p = self.stored_rows() as u64;
        if self.block_rows == 0 || self.block_rows as u64 > all {
            return Err(Error::range(
                "block_rows",
                self.block_rows,
                format!("1..={all}"),
            ));
        }
        let block_count = p.div_ceil(self.block_rows as u64);
        let table_offset = self.header_len();
        let flags_offset = table_offset + 8 * block_count;
        let albedo_offset = (flags_offset + p).next_multiple_of(64);
        let albedo_end = albedo_offset + if self.has_albedo { 12 * p } else { 0 };
        let surface_offset = albedo_end.next_multiple_of(64);
        let surface_end = surface_offset
            + if self.has_surface {
                SURFACE_RECORD_LEN as u64 * all + 4
            } else {
                0
            };
        let mesh_offset = surface_end.next_multiple_of(64);
        let mesh_end = mesh_len.map_or(surface_end, |len| mesh_offset + len + 4);
        let data_offset = mesh_end.next_multiple_of(DATA_ALIGN);
        let data_len = (self.dims.row_len() as u64 * 4).saturating_mul(p);
        let plane_len = (self.plane_row_len() as u64 * 4).saturating_mul(p);
        let too_large = || Error::range("raw store size", data_len, "below 2^64 bytes");
        let data_end = data_offset.checked_add(data_len).ok_or_else(too_large)?;
        let plane_offset = data_end.next_multiple_of(DATA_ALIGN);
        let file_len = match self.plane {
            Some(_) => plane_offset.checked_add(plane_len).ok_or_else(too_large)?,
            None => data_end,
        };
        Ok(Layout {
            table_offset,
            block_count,
            flags_offset,
            albedo_offset: if self.has_albedo { albedo_offset } else { 0 },
            surface_offset: if self.has_surface { surface_offset } else { 0 },
            mesh_offset: if mesh_len.is_some() { mesh_offset } else { 0 },
            plane_offset: if self.plane.is_some() {
                plane_offset
            } else {
                0
            },
            data_offset,
            file_len,
        })
    }

    /// A part's rows: at least one, within the matrix's `all` rows, and
    /// surface data stored.
    fn check_part(&self, all: u64) -> Result<()> {
        let Some(span) = self.part else {
            return Ok(());
        };
        if span.is_empty() || span.end > all {
            return Err(Error::range(
                "raw store part rows",
                span,
                format!("a non-empty range within rows 0..{all}"),
            ));
        }
        if !self.has_surface {
            return Err(Error::Invalid(
                "a part of a sharded bake must carry surface data".into(),
            ));
        }
        if self.plane.is_some() {
            return Err(Error::Invalid(
                "a part of a sharded bake holds no near-field rows: bake a scene with a light plane on one machine".into(),
            ));
        }
        Ok(())
    }

    /// The mesh length, checked: texture rows only, within the bytes of a
    /// mesh of at most [`MAX_MESH_ELEMENTS`] vertices and triangles.
    fn checked_mesh_len(&self) -> Result<Option<u64>> {
        let Some(len) = self.mesh_len else {
            return Ok(None);
        };
        if !self.dims.rows.is_texture() || !self.has_surface {
            return Err(Error::Invalid(
                "a receiver mesh is stored only in a texture-space raw store".into(),
            ));
        }
        let most =
            (MESH_HEADER_LEN + (MESH_VERTEX_LEN + MESH_TRIANGLE_LEN) * MAX_MESH_ELEMENTS) as u64;
        if !(MESH_HEADER_LEN as u64..=most).contains(&len) {
            return Err(Error::range(
                "raw store mesh_len",
                len,
                format!("{MESH_HEADER_LEN}..={most}"),
            ));
        }
        Ok(Some(len))
    }

    /// Number of blocks.
    pub fn block_count(&self) -> usize {
        self.stored_rows().div_ceil(self.block_rows as usize)
    }

    /// Stored rows of block `b` (in a part, counted from its first row:
    /// add [`RawHeader::first_row`] for the rows of the matrix).
    pub fn block_range(&self, b: usize) -> std::ops::Range<usize> {
        let start = b * self.block_rows as usize;
        start..(start + self.block_rows as usize).min(self.stored_rows())
    }

    pub(super) fn encode(&self, layout: &Layout) -> Vec<u8> {
        let mut w = Writer::default();
        w.bytes.extend_from_slice(&MAGIC);
        w.u32(self.version());
        w.u32(
            if self.has_albedo { FLAG_ALBEDO } else { 0 }
                | if self.has_surface { FLAG_SURFACE } else { 0 }
                | if self.mesh_len.is_some() {
                    FLAG_MESH
                } else {
                    0
                }
                | if self.part.is_some() { FLAG_PART } else { 0 }
                | if self.plane.is_some() { FLAG_PLANE } else { 0 },
        );
        for v in self.dims.to_fields() {
            w.u32(v);
        }
        w.u32(self.block_rows);
        w.u32(layout.block_count as u32);
        w.u64(layout.data_offset);
        w.u64(layout.albedo_offset);
        w.u32(0);
        if let Some(id) = &self.input_id {
            w.bytes.extend_from_slice(id);
        } else if self.has_surface {
            w.bytes.extend_from_slice(&[0; INPUT_ID_LEN]);
        }
        if self.has_surface {
            w.u64(layout.surface_offset);
            w.u32(self.dims.rows.code());
            w.u32(match self.dims.rows {
                crate::RowLayout::Texture {
                    parameterization, ..
                } => parameterization.code(),
                _ => 0,
            });
        }
        if self.mesh_len.is_some() || self.part.is_some() || self.plane.is_some() {
            w.u64(layout.mesh_offset);
            w.u64(self.mesh_len.unwrap_or(0));
        }
        if let Some(span) = self.part {
            w.u64(span.start);
            w.u64(span.len());
        }
        if let Some(basis) = &self.plane {
            w.u64(0);
            w.u64(0);
            w.u64(layout.plane_offset);
            basis.write(&mut w);
        }
        let crc = crc32fast::hash(&w.bytes);
        w.u32(crc);
        w.bytes
    }

    /// Decodes and checks a header from the first bytes of a file of
    /// `file_len` bytes (`bytes` holds `min(file_len, HEADER_LEN_MAX)` of
    /// them).
    pub(super) fn decode(bytes: &[u8], file_len: u64, path: &Path) -> Result<(RawHeader, Layout)> {
        check_magic(bytes, file_len, path)?;
        let version = u32::from_le_bytes(bytes[8..12].try_into().expect("4 bytes"));
        let len = match version {
            1 => HEADER_LEN_V1,
            2 => HEADER_LEN_V2,
            3 => HEADER_LEN_V3,
            4 => HEADER_LEN_V4,
            5 => HEADER_LEN_V5,
            6 => HEADER_LEN_V6,
            _ => {
                return Err(Error::Version {
                    what: "raw store",
                    found: version,
                    supported: VERSION,
                })
            }
        } as usize;
        if bytes.len() < len {
            return Err(Error::corrupt(
                "raw store",
                format!(
                    "{}: truncated: the file is {file_len} bytes, shorter than its {len}-byte version-{version} header",
                    path.display()
                ),
            ));
        }
        let mut r = Reader::new(&bytes[..len], "raw store header");
        r.take(12)?;
        let flags = r.u32()?;
        check_fixed_fields(bytes, len, version, flags)?;
        let mut dims = Dims::read_fields(&mut r)?;
        let word = |at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().expect("4 bytes"));
        let long = |at: usize| u64::from_le_bytes(bytes[at..at + 8].try_into().expect("8 bytes"));
        if version >= 3 {
            dims.rows =
                crate::RowLayout::from_codes(word(100), word(104), dims.width(), dims.height())?;
        }
        let id: [u8; INPUT_ID_LEN] = bytes[60..60 + INPUT_ID_LEN.min(len - 60)]
            .iter()
            .copied()
            .chain(std::iter::repeat(0))
            .take(INPUT_ID_LEN)
            .collect::<Vec<u8>>()
            .try_into()
            .expect("32 bytes");
        let header = RawHeader {
            dims,
            block_rows: r.u32()?,
            has_albedo: flags & FLAG_ALBEDO != 0,
            input_id: (version == 2 || (version >= 3 && id != [0; INPUT_ID_LEN])).then_some(id),
            has_surface: version >= 3,
            mesh_len: (flags & FLAG_MESH != 0).then(|| long(116)),
            part: (version == 5).then(|| RowSpan {
                start: long(124),
                end: long(124).saturating_add(long(132)),
            }),
            plane: if version == 6 {
                let mut r =
                    Reader::new(&bytes[148..148 + PLANE_BASIS_LEN], "raw store light plane");
                Some(PlaneBasis::read(&mut r)?)
            } else {
                None
            },
        };
        if version >= 5 && flags & FLAG_MESH == 0 && long(116) != 0 {
            return Err(Error::range(
                "raw store mesh_len (header offset 116) without a mesh",
                long(116),
                "0",
            ));
        }
        if version == 4 && !dims.rows.is_texture() {
            return Err(Error::range(
                "raw store row layout",
                "0 (image) in a version-4 header",
                "1 (texture): a receiver mesh belongs to texture rows",
            ));
        }
        let layout = header.layout()?;
        let offsets = (r.u32()?, r.u64()?, r.u64()?);
        let surface_offset = if version >= 3 { long(92) } else { 0 };
        let mesh_offset = if version >= 4 { long(108) } else { 0 };
        check_offsets(&layout, offsets, (surface_offset, mesh_offset))?;
        if version == 6 {
            check_plane_fields(&long, &layout)?;
        }
        Ok((header, layout))
    }
}

/// A version-6 header's bytes 124..140 (a version-5 part's fields) are 0
/// and its `plane_offset` (offset 140) is the layout's.
fn check_plane_fields(long: &dyn Fn(usize) -> u64, layout: &Layout) -> Result<()> {
    if long(124) != 0 || long(132) != 0 {
        return Err(Error::range(
            "raw store header bytes 124..140 (part fields) in version 6",
            format!("{}, {}", long(124), long(132)),
            "0, 0",
        ));
    }
    if long(140) != layout.plane_offset {
        return Err(Error::corrupt(
            "raw store header",
            format!(
                "plane_offset {} disagrees with the dimensions (expected {})",
                long(140),
                layout.plane_offset
            ),
        ));
    }
    Ok(())
}

/// The header's CRC (over its first `len − 4` bytes), its flags (bit 0,
/// bit 1 exactly in `version` 3 to 5, bit 2 exactly in version 4 and
/// optional in version 5, bit 3 exactly in version 5) and its reserved
/// field (0).
pub(super) fn check_fixed_fields(bytes: &[u8], len: usize, version: u32, flags: u32) -> Result<()> {
    let stored_crc = u32::from_le_bytes(bytes[len - 4..len].try_into().expect("4 bytes"));
    let crc = crc32fast::hash(&bytes[..len - 4]);
    if crc != stored_crc {
        return Err(Error::Crc {
            chunk: "raw store header".into(),
            stored: stored_crc,
            computed: crc,
        });
    }
    let allowed = FLAG_ALBEDO | FLAG_SURFACE | FLAG_MESH | FLAG_PART | FLAG_PLANE;
    let mesh_ok = match version {
        4 => flags & FLAG_MESH != 0,
        5 | 6 => true,
        _ => flags & FLAG_MESH == 0,
    };
    if flags & !allowed != 0
        || (version >= 3) != (flags & FLAG_SURFACE != 0)
        || !mesh_ok
        || (version == 5) != (flags & FLAG_PART != 0)
        || (version == 6) != (flags & FLAG_PLANE != 0)
    {
        return Err(Error::range(
            "raw store flags",
            format!("{flags:#x} (version {version})"),
            "bit 0, bit 1 exactly in versions 3 to 6, bit 2 exactly in version 4 (optional in 5 and 6), bit 3 exactly in version 5, bit 4 exactly in version 6",
        ));
    }
    let reserved = u32::from_le_bytes(bytes[56..60].try_into().expect("4 bytes"));
    if reserved != 0 {
        return Err(Error::range(
            "raw store reserved field (header offset 56)",
            format!("{reserved:#x}"),
            "0",
        ));
    }
    Ok(())
}

/// The offsets a header stores (block count, data, albedo; surface, mesh)
/// against the layout its dimensions imply.
pub(super) fn check_offsets(
    layout: &Layout,
    (block_count, data_offset, albedo_offset): (u32, u64, u64),
    (surface_offset, mesh_offset): (u64, u64),
) -> Result<()> {
    if mesh_offset != layout.mesh_offset {
        return Err(Error::corrupt(
            "raw store header",
            format!(
                "mesh_offset {mesh_offset} disagrees with the dimensions (expected {})",
                layout.mesh_offset
            ),
        ));
    }
    if surface_offset != layout.surface_offset {
        return Err(Error::corrupt(
            "raw store header",
            format!(
                "surface_offset {surface_offset} disagrees with the dimensions (expected {})",
                layout.surface_offset
            ),
        ));
    }
    if block_count as u64 != layout.block_count
        || data_offset != layout.data_offset
        || albedo_offset != layout.albedo_offset
    {
        return Err(Error::corrupt("raw store header", format!(
                "block_count {block_count}, data_offset {data_offset}, albedo_offset {albedo_offset} disagree with the dimensions (expected {}, {}, {})",
                layout.block_count, layout.data_offset, layout.albedo_offset)));
    }
    Ok(())
}

/// The file starts with the magic and holds a whole header: a file whose
/// bytes are the magic (or a prefix of it) but shorter than the header is
/// reported as truncated, not as another kind of file.
pub(super) fn check_magic(bytes: &[u8], file_len: u64, path: &Path) -> Result<()> {
    let n = bytes.len().min(8);
    if file_len == 0 {
        return Err(Error::corrupt(
            "raw store",
            format!("{}: the file is empty (0 bytes)", path.display()),
        ));
    }
    if bytes[..n] == crate::container::MAGIC[..n] && n == 8 {
        return Err(Error::ltm_not_raw(path));
    }
    if bytes[..n] != MAGIC[..n] {
        return Err(Error::BadMagic {
            path: path.into(),
            expected: "an ltm raw transport store",
            found: bytes[..n].to_vec(),
        });
    }
    if file_len < HEADER_LEN_V1 {
        return Err(Error::corrupt(
            "raw store",
            format!(
                "{}: truncated: the file is {file_len} bytes, shorter than the {HEADER_LEN_V1}-byte header",
                path.display()
            ),
        ));
    }
    Ok(())
}
