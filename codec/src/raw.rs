//! The raw transport store: the uncompressed matrix T, row-major, as `ltm
//! bake` and `ltm import` write it and `ltm compress` reads it.
//!
//! One little-endian file (layout in docs/FORMAT.md). Version 2 adds the
//! input identity, version 3 the row layout and per-row surface data
//! ([`Surface`]); a header is `hlen` = 64 bytes in version 1, 96 in version
//! 2 and 112 in version 3:
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 8 | magic `LTMRAW\0\x01` |
//! | 8 | 4 | version (1, 2 or 3) |
//! | 12 | 4 | flags: bit 0 = an albedo image is stored, bit 1 = surface data (exactly in version 3) |
//! | 16 | 4·5 | width, height, face_res, channels, block_rows |
//! | 36 | 4 | block_count = ceil(width·height / block_rows) |
//! | 40 | 8 | data_offset (multiple of 4096) |
//! | 48 | 8 | albedo_offset (0 when absent) |
//! | 56 | 4 | reserved, 0 (a reader refuses any other value) |
//! | 60 | 32 | version 2 and 3: input identity ([`RawHeader::input_id`]; all zero in version 3 = none) |
//! | 92 | 8 | version 3: surface_offset |
//! | 100 | 4·2 | version 3: row layout (0 image, 1 texture), parameterization (0 none, 1 uv, 2 sphere) |
//! | hlen − 4 | 4 | CRC-32 of bytes 0..hlen−4 |
//! | hlen | 8·block_count | block table: state (0 = pending, 1 = complete), CRC-32 of the block |
//! | flags_offset | P | one byte per row: 1 = the row is all zero, else 0 |
//! | albedo_offset | 12·P | RGB albedo per pixel, f32 (optional) |
//! | surface_offset | 28·P + 4 | version 3: surface record per row, then the CRC-32 of the records |
//! | data_offset | 4·P·M·C | T\[p\]\[j\]\[c\], f32 |
//!
//! A block is `block_rows` consecutive rows (the last may be shorter); its
//! CRC covers its row flags, then its albedo values, then its data.
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

#[cfg(target_endian = "big")]
compile_error!("ltm's file formats are little-endian and are mapped directly; big-endian targets are not supported");

use crate::bytes::{Reader, Writer};
use crate::dims::Dims;
use crate::error::{Error, Result};
use crate::fileio::PositionedIo as _;
use crate::limits::{Charge, Limits};
use crate::mmap;
use crate::surface::{Surface, SURFACE_RECORD_LEN};
use memmap2::Mmap;
use std::fs::{File, OpenOptions};
use std::io;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::time::SystemTime;

const MAGIC: [u8; 8] = *b"LTMRAW\0\x01";
/// The newest version; version 1 (no input identity) is still read and
/// written.
const VERSION: u32 = 3;
/// Header bytes of versions 1, 2 and 3.
const HEADER_LEN_V1: u64 = 64;
const HEADER_LEN_V2: u64 = 96;
const HEADER_LEN_V3: u64 = 112;
/// Bytes of an input identity.
pub const INPUT_ID_LEN: usize = 32;
const FLAG_ALBEDO: u32 = 1;
const FLAG_SURFACE: u32 = 2;
const DATA_ALIGN: u64 = 4096;
/// Bytes read at a time when a block's CRC is checked.
const CRC_CHUNK: u64 = 8 << 20;

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
    /// Per-row surface data ([`Surface`]) is stored (version 3). Texture
    /// rows ([`crate::RowLayout::Texture`]) always have it.
    pub has_surface: bool,
}

#[derive(Clone, Copy)]
struct Layout {
    /// Start of the block table: the header length.
    table_offset: u64,
    block_count: u64,
    flags_offset: u64,
    albedo_offset: u64,
    /// Start of the surface records (0 when absent).
    surface_offset: u64,
    data_offset: u64,
    file_len: u64,
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
        }
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

    /// The format version this header is written as: 3 with surface data,
    /// else 2 with an input identity, else 1.
    pub fn version(&self) -> u32 {
        if self.has_surface {
            3
        } else if self.input_id.is_some() {
            2
        } else {
            1
        }
    }

    fn header_len(&self) -> u64 {
        match self.version() {
            3 => HEADER_LEN_V3,
            2 => HEADER_LEN_V2,
            _ => HEADER_LEN_V1,
        }
    }

    fn layout(&self) -> Result<Layout> {
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
        let p = self.dims.pixels() as u64;
        if self.block_rows == 0 || self.block_rows as u64 > p {
            return Err(Error::range(
                "block_rows",
                self.block_rows,
                format!("1..={p}"),
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
                SURFACE_RECORD_LEN as u64 * p + 4
            } else {
                0
            };
        let data_offset = surface_end.next_multiple_of(DATA_ALIGN);
        let file_len = data_offset
            .checked_add(self.dims.raw_bytes())
            .ok_or_else(|| {
                Error::range("raw store size", self.dims.raw_bytes(), "below 2^64 bytes")
            })?;
        Ok(Layout {
            table_offset,
            block_count,
            flags_offset,
            albedo_offset: if self.has_albedo { albedo_offset } else { 0 },
            surface_offset: if self.has_surface { surface_offset } else { 0 },
            data_offset,
            file_len,
        })
    }

    /// Number of blocks.
    pub fn block_count(&self) -> usize {
        (self.dims.pixels()).div_ceil(self.block_rows as usize)
    }

    /// Rows of block `b`.
    pub fn block_range(&self, b: usize) -> std::ops::Range<usize> {
        let start = b * self.block_rows as usize;
        start..(start + self.block_rows as usize).min(self.dims.pixels())
    }

    fn encode(&self, layout: &Layout) -> Vec<u8> {
        let mut w = Writer::default();
        w.bytes.extend_from_slice(&MAGIC);
        w.u32(self.version());
        w.u32(
            if self.has_albedo { FLAG_ALBEDO } else { 0 }
                | if self.has_surface { FLAG_SURFACE } else { 0 },
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
        let crc = crc32fast::hash(&w.bytes);
        w.u32(crc);
        w.bytes
    }

    /// Decodes and checks a header from the first bytes of a file of
    /// `file_len` bytes (`bytes` holds `min(file_len, HEADER_LEN_V3)` of
    /// them).
    fn decode(bytes: &[u8], file_len: u64, path: &Path) -> Result<(RawHeader, Layout)> {
        check_magic(bytes, file_len, path)?;
        let version = u32::from_le_bytes(bytes[8..12].try_into().expect("4 bytes"));
        let len = match version {
            1 => HEADER_LEN_V1,
            2 => HEADER_LEN_V2,
            3 => HEADER_LEN_V3,
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
        let stored_crc = u32::from_le_bytes(bytes[len - 4..len].try_into().expect("4 bytes"));
        let crc = crc32fast::hash(&bytes[..len - 4]);
        if crc != stored_crc {
            return Err(Error::Crc {
                chunk: "raw store header".into(),
                stored: stored_crc,
                computed: crc,
            });
        }
        let allowed = if version == 3 {
            FLAG_ALBEDO | FLAG_SURFACE
        } else {
            FLAG_ALBEDO
        };
        if flags & !allowed != 0 || (version == 3) != (flags & FLAG_SURFACE != 0) {
            return Err(Error::range(
                "raw store flags",
                format!("{flags:#x} (version {version})"),
                "bit 0, and bit 1 exactly in version 3",
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
        let mut dims = Dims::read_fields(&mut r)?;
        let word = |at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().expect("4 bytes"));
        if version == 3 {
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
            input_id: (version == 2 || (version == 3 && id != [0; INPUT_ID_LEN])).then_some(id),
            has_surface: version == 3,
        };
        let layout = header.layout()?;
        let (block_count, data_offset, albedo_offset) = (r.u32()?, r.u64()?, r.u64()?);
        let surface_offset = if version == 3 {
            u64::from_le_bytes(bytes[92..100].try_into().expect("8 bytes"))
        } else {
            0
        };
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
        Ok((header, layout))
    }
}

/// What [`RawWriter::create`] did with an existing `PATH.partial`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum ResumeState {
    /// There was no partial file: a new one was started.
    New,
    /// The partial file comes from the same inputs: its `kept` complete
    /// blocks (of `total`) whose CRC verifies were kept.
    Resumed {
        /// Blocks kept.
        kept: usize,
        /// Blocks in the store.
        total: usize,
    },
    /// A partial file was there but could not be resumed; it was started
    /// over.
    Restarted(RestartReason),
}

/// Why a partial file was started over.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum RestartReason {
    /// It cannot be read, or its header is not a valid raw store header.
    Unreadable,
    /// It or the new header has no input identity (a version-1 store, as
    /// `ltm import` and older versions of ltm write), so the two cannot be
    /// proven to come from the same inputs.
    NoIdentity,
    /// Its input identity differs: it was computed from other inputs.
    DifferentInputs,
    /// Same inputs, but another layout (dimensions, albedo image or block
    /// size).
    DifferentLayout,
    /// Its length is not the one its header implies (truncated).
    WrongLength,
}

impl std::fmt::Display for RestartReason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            RestartReason::Unreadable => "it cannot be read as a raw store",
            RestartReason::NoIdentity => {
                "it records no input identity (a version-1 store, from ltm import or an older ltm), so it cannot be proven to come from the same inputs"
            }
            RestartReason::DifferentInputs => {
                "it was computed from different inputs (its input identity differs: another scene description, mesh file, setting or program version)"
            }
            RestartReason::DifferentLayout => {
                "it has another layout (dimensions, albedo image or block size)"
            }
            RestartReason::WrongLength => "its length does not match its header (truncated)",
        })
    }
}

impl std::fmt::Display for ResumeState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ResumeState::New => f.write_str("no partial file; started a new one"),
            ResumeState::Resumed { kept, total } => {
                write!(f, "resumed the partial file: kept {kept} of {total} blocks")
            }
            ResumeState::Restarted(why) => {
                write!(f, "started the partial file over: {why}")
            }
        }
    }
}

/// `Ok` when the partial file at `partial` can be resumed by a writer of
/// `header`, else the state to report: no file, or why it is started over.
fn probe_partial(
    partial: &Path,
    header: &RawHeader,
    layout: &Layout,
) -> std::result::Result<(), ResumeState> {
    let restart = |why| Err(ResumeState::Restarted(why));
    let file = match File::open(partial) {
        Ok(f) => f,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Err(ResumeState::New),
        Err(_) => return restart(RestartReason::Unreadable),
    };
    let len = file.metadata().map(|m| m.len()).unwrap_or(0);
    let mut bytes = vec![0u8; len.min(HEADER_LEN_V3) as usize];
    if file.read_exact_at(&mut bytes, 0).is_err() {
        return restart(RestartReason::Unreadable);
    }
    let Ok((old, old_layout)) = RawHeader::decode(&bytes, len, partial) else {
        return restart(RestartReason::Unreadable);
    };
    match (old.input_id, header.input_id) {
        (Some(a), Some(b)) if a != b => restart(RestartReason::DifferentInputs),
        (Some(_), Some(_)) if old != *header => restart(RestartReason::DifferentLayout),
        (Some(_), Some(_)) if len != layout.file_len || len != old_layout.file_len => {
            restart(RestartReason::WrongLength)
        }
        (Some(_), Some(_)) => Ok(()),
        _ => restart(RestartReason::NoIdentity),
    }
}

/// The file starts with the magic and holds a whole header: a file whose
/// bytes are the magic (or a prefix of it) but shorter than the header is
/// reported as truncated, not as another kind of file.
fn check_magic(bytes: &[u8], file_len: u64, path: &Path) -> Result<()> {
    let n = bytes.len().min(8);
    if file_len == 0 {
        return Err(Error::corrupt(
            "raw store",
            format!("{}: the file is empty (0 bytes)", path.display()),
        ));
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

fn partial_path(path: &Path) -> PathBuf {
    let mut s = path.as_os_str().to_owned();
    s.push(".partial");
    PathBuf::from(s)
}

/// Writes a raw store block by block; see the module docs for resuming.
pub struct RawWriter {
    file: File,
    header: RawHeader,
    layout: Layout,
    path: PathBuf,
    partial: PathBuf,
    done: Vec<bool>,
    resume: ResumeState,
}

impl RawWriter {
    /// Opens `PATH.partial` for writing: resumes it when it comes from the
    /// same inputs as `header` (see the module docs), else starts it over.
    /// [`RawWriter::resume_state`] tells which, and why.
    pub fn create(path: &Path, header: RawHeader) -> Result<RawWriter> {
        Self::create_with_surface(path, header, None)
    }

    /// [`RawWriter::create`] for a header with surface data: `surface`
    /// (one point per row) must be given exactly when
    /// [`RawHeader::has_surface`]. It is written at once, on a resumed file
    /// too (it is a function of the same inputs).
    pub fn create_with_surface(
        path: &Path,
        header: RawHeader,
        surface: Option<&Surface>,
    ) -> Result<RawWriter> {
        let layout = header.layout()?;
        match surface {
            Some(s) => s.check_rows(&header.dims)?,
            None if header.has_surface => {
                return Err(Error::Invalid(
                    "the raw store header has surface data but none was given".into(),
                ))
            }
            None => {}
        }
        if surface.is_some() && !header.has_surface {
            return Err(Error::Invalid(
                "surface data given for a raw store header without it".into(),
            ));
        }
        let partial = partial_path(path);
        let io = |e| Error::io(&partial, e);
        let probe = probe_partial(&partial, &header, &layout);
        let file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(probe.is_err())
            .open(&partial)
            .map_err(io)?;
        let total = layout.block_count as usize;
        let mut writer = RawWriter {
            file,
            header,
            path: path.into(),
            partial: partial.clone(),
            layout,
            done: vec![false; total],
            resume: ResumeState::New,
        };
        match probe {
            Ok(()) => {
                writer.done = writer.verified_blocks()?;
                let kept = writer.done.iter().filter(|&&d| d).count();
                writer.resume = ResumeState::Resumed { kept, total };
            }
            Err(state) => {
                writer.file.set_len(layout.file_len).map_err(io)?;
                writer
                    .file
                    .write_all_at(&header.encode(&layout), 0)
                    .map_err(io)?;
                writer.resume = state;
            }
        }
        if let Some(s) = surface {
            let mut bytes = s.encode_records();
            let crc = crc32fast::hash(&bytes);
            bytes.extend_from_slice(&crc.to_le_bytes());
            writer
                .file
                .write_all_at(&bytes, layout.surface_offset)
                .map_err(io)?;
        }
        Ok(writer)
    }

    /// What was done with an existing `PATH.partial`: started anew, resumed
    /// (with the blocks kept), or started over (and why).
    pub fn resume_state(&self) -> ResumeState {
        self.resume
    }

    /// The blocks of a resumed file marked complete whose CRC verifies.
    fn verified_blocks(&self) -> Result<Vec<bool>> {
        let mut table = vec![0u8; 8 * self.layout.block_count as usize];
        self.file
            .read_exact_at(&mut table, self.layout.table_offset)
            .map_err(|e| Error::io(&self.partial, e))?;
        let mut done = Vec::with_capacity(table.len() / 8);
        for (b, entry) in table.chunks_exact(8).enumerate() {
            let stored = u32::from_le_bytes(entry[4..8].try_into().expect("4 bytes"));
            done.push(entry[..4] == 1u32.to_le_bytes() && self.block_crc(b)? == stored);
        }
        Ok(done)
    }

    /// The header being written.
    pub fn header(&self) -> &RawHeader {
        &self.header
    }

    /// Blocks not yet complete, in order.
    pub fn pending_blocks(&self) -> Vec<usize> {
        (0..self.done.len()).filter(|&b| !self.done[b]).collect()
    }

    fn block_crc(&self, b: usize) -> Result<u32> {
        let rows = self.header.block_range(b);
        let n = rows.len() as u64;
        let mut h = crc32fast::Hasher::new();
        let mut buf = vec![0u8; n as usize];
        let io = |e| Error::io(&self.partial, e);
        self.file
            .read_exact_at(&mut buf, self.layout.flags_offset + rows.start as u64)
            .map_err(io)?;
        h.update(&buf);
        if self.header.has_albedo {
            buf.resize(12 * n as usize, 0);
            self.file
                .read_exact_at(&mut buf, self.layout.albedo_offset + 12 * rows.start as u64)
                .map_err(io)?;
            h.update(&buf);
        }
        let row_bytes = self.header.dims.row_len() as u64 * 4;
        let (start, end) = (
            self.layout.data_offset + rows.start as u64 * row_bytes,
            self.layout.data_offset + rows.end as u64 * row_bytes,
        );
        buf.resize((end - start).min(CRC_CHUNK) as usize, 0);
        let mut at = start;
        while at < end {
            let len = (end - at).min(CRC_CHUNK) as usize;
            self.file.read_exact_at(&mut buf[..len], at).map_err(io)?;
            h.update(&buf[..len]);
            at += len as u64;
        }
        Ok(h.finalize())
    }

    /// Writes block `b`: `rows` holds its rows (M·C values each) and
    /// `albedo` its RGB albedo values when the store has an albedo image.
    pub fn write_block(&mut self, b: usize, rows: &[f32], albedo: Option<&[f32]>) -> Result<()> {
        if b >= self.done.len() {
            return Err(Error::range(
                "block index",
                b,
                format!("0..{}", self.done.len()),
            ));
        }
        let range = self.header.block_range(b);
        let row_len = self.header.dims.row_len();
        if rows.len() != range.len() * row_len {
            return Err(Error::BufferTooSmall {
                what: "raw block rows",
                len: rows.len(),
                need: range.len() * row_len,
            });
        }
        if rows.iter().any(|v| !v.is_finite()) {
            return Err(Error::Invalid(format!(
                "block {b} holds NaN or infinite values"
            )));
        }
        if let Some((i, v)) = albedo
            .into_iter()
            .flatten()
            .enumerate()
            .find(|(_, v)| !v.is_finite())
        {
            return Err(non_finite_albedo(range.start + i / 3, i % 3, *v));
        }
        let io = |e| Error::io(&self.partial, e);
        let mut h = crc32fast::Hasher::new();
        let flags: Vec<u8> = rows
            .chunks(row_len.max(1))
            .map(|r| u8::from(r.iter().all(|&v| v == 0.0)))
            .collect();
        self.file
            .write_all_at(&flags, self.layout.flags_offset + range.start as u64)
            .map_err(io)?;
        h.update(&flags);
        match (self.header.has_albedo, albedo) {
            (true, Some(a)) if a.len() == 3 * range.len() => {
                let bytes: &[u8] = bytemuck::cast_slice(a);
                self.file.write_all_at(bytes, self.layout.albedo_offset + 12 * range.start as u64).map_err(io)?;
                h.update(bytes);
            }
            (false, None) => {}
            _ => return Err(Error::Invalid(format!("albedo for block {b} must be given exactly when the store has an albedo image, 3 values per row"))),
        }
        // Plain positioned writes, not a memory map of the sparse file: a full
        // disk is then an ENOSPC error here rather than SIGBUS on a page.
        let bytes: &[u8] = bytemuck::cast_slice(rows);
        let row_bytes = row_len as u64 * 4;
        self.file
            .write_all_at(
                bytes,
                self.layout.data_offset + range.start as u64 * row_bytes,
            )
            .map_err(io)?;
        h.update(bytes);
        let mut entry = 1u32.to_le_bytes().to_vec();
        entry.extend_from_slice(&h.finalize().to_le_bytes());
        self.file
            .write_all_at(&entry, self.layout.table_offset + 8 * b as u64)
            .map_err(io)?;
        self.done[b] = true;
        Ok(())
    }

    /// Writes a whole matrix held in memory — `t` with P·M·C values, `albedo`
    /// with 3·P when the header has an albedo image — block by block, and
    /// finishes the store. Returns its path.
    pub fn write_dense(
        path: &Path,
        header: RawHeader,
        t: &[f32],
        albedo: Option<&[f32]>,
    ) -> Result<PathBuf> {
        Self::write_dense_with_surface(path, header, t, albedo, None)
    }

    /// [`RawWriter::write_dense`] with per-row surface data (see
    /// [`RawWriter::create_with_surface`]).
    pub fn write_dense_with_surface(
        path: &Path,
        header: RawHeader,
        t: &[f32],
        albedo: Option<&[f32]>,
        surface: Option<&Surface>,
    ) -> Result<PathBuf> {
        let (p, row) = (header.dims.pixels(), header.dims.row_len());
        if t.len() != p * row {
            return Err(Error::BufferTooSmall {
                what: "dense matrix",
                len: t.len(),
                need: p * row,
            });
        }
        if albedo.is_some_and(|a| a.len() != 3 * p) || albedo.is_some() != header.has_albedo {
            return Err(Error::BufferTooSmall {
                what: "albedo image",
                len: albedo.map_or(0, <[f32]>::len),
                need: if header.has_albedo { 3 * p } else { 0 },
            });
        }
        let mut w = RawWriter::create_with_surface(path, header, surface)?;
        for b in 0..header.block_count() {
            let r = header.block_range(b);
            let a = albedo.map(|a| &a[3 * r.start..3 * r.end]);
            w.write_block(b, &t[r.start * row..r.end * row], a)?;
        }
        w.finish()
    }

    /// Checks that every block is complete, syncs, and renames the file into
    /// place.
    pub fn finish(self) -> Result<PathBuf> {
        if let Some(b) = self.done.iter().position(|d| !d) {
            return Err(Error::Invalid(format!(
                "raw store incomplete: block {b} of {} not written",
                self.done.len()
            )));
        }
        self.file
            .sync_all()
            .map_err(|e| Error::io(&self.partial, e))?;
        std::fs::rename(&self.partial, &self.path).map_err(|e| Error::io(&self.path, e))?;
        Ok(self.path)
    }
}

/// The error for a non-finite albedo value of pixel `p`, channel `c`.
fn non_finite_albedo(p: usize, c: usize, v: f32) -> Error {
    Error::range(
        "raw store albedo value",
        format!("{v} (pixel {p}, channel {c})"),
        "finite",
    )
}

/// A file's length and modification time, taken at open and compared after
/// a run to detect a change of the input while it was read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Stamp {
    len: u64,
    modified: Option<SystemTime>,
}

impl Stamp {
    fn of(file: &File, path: &Path) -> Result<Stamp> {
        let m = file.metadata().map_err(|e| Error::io(path, e))?;
        Ok(Stamp {
            len: m.len(),
            modified: m.modified().ok(),
        })
    }
}

/// Reads `buf.len()` bytes at `offset` of `file`; a file that ends too early
/// (truncated since it was opened) is an error that says so.
fn read_at(file: &File, path: &Path, buf: &mut [u8], offset: u64) -> Result<()> {
    file.read_exact_at(buf, offset).map_err(|e| {
        if e.kind() != io::ErrorKind::UnexpectedEof {
            return Error::io(path, e);
        }
        let now = file
            .metadata()
            .map_or_else(|_| "unknown".into(), |m| m.len().to_string());
        let end = offset + buf.len() as u64;
        Error::io(
            path,
            io::Error::new(
                e.kind(),
                format!("bytes {offset}..{end} lie past the end of the file (now {now} bytes): it was truncated while being read"),
            ),
        )
    })
}

/// A raw store opened for reading.
///
/// Opening validates the header and reads the block table, the row flags
/// and the albedo image into memory with positioned reads, checking every
/// field: block states 0 or 1 (and every block complete), row flags 0 or 1,
/// finite albedo values. Row data is read on demand, either with
/// [`RawStore::read_rows`] (positioned reads: a file truncated meanwhile is
/// an error; what the compressor uses) or with [`RawStore::rows`] (a memory
/// map: no copy, but a file truncated while mapped raises SIGBUS). Data is
/// trusted only once its block is verified ([`RawStore::verify_block`],
/// [`BlockVerifier`]) against the block table read at open.
pub struct RawStore {
    file: File,
    map: Mmap,
    header: RawHeader,
    layout: Layout,
    path: PathBuf,
    /// CRC of every block, from the block table.
    block_crcs: Vec<u32>,
    /// One byte per row: 1 = flagged all zero.
    flags: Vec<u8>,
    albedo: Option<Vec<f32>>,
    surface: Option<Surface>,
    stamp: Stamp,
    /// The tables' bytes, charged to the limits it was opened with.
    _charge: Charge,
}

impl RawStore {
    /// Opens and validates a raw store: header CRC, reserved fields,
    /// dimensions, file length, block table (every block complete), row
    /// flags and albedo values. Block CRCs, finite values and rows flagged
    /// zero are checked by [`RawStore::verify_block`] or a
    /// [`BlockVerifier`]. Uses the default [`Limits`].
    pub fn open(path: &Path) -> Result<RawStore> {
        Self::open_with_limits(path, &Limits::default())
    }

    /// [`RawStore::open`] with the given limits.
    pub fn open_with_limits(path: &Path, limits: &Limits) -> Result<RawStore> {
        let file = File::open(path).map_err(|e| Error::io(path, e))?;
        mmap::check_regular(&file).map_err(|e| Error::io(path, e))?;
        let stamp = Stamp::of(&file, path)?;
        let mut head = vec![0u8; stamp.len.min(HEADER_LEN_V3) as usize];
        read_at(&file, path, &mut head, 0)?;
        let (header, layout) = RawHeader::decode(&head, stamp.len, path)?;
        check_length(stamp.len, layout.file_len, path)?;
        let block_crcs = read_block_table(&file, path, &layout, limits)?;
        let flags = read_flags(&file, path, &header, &layout, limits)?;
        let albedo = read_albedo(&file, path, &header, &layout, limits)?;
        let surface = read_surface(&file, path, &header, &layout, limits)?;
        let map = mmap::map_read(&file).map_err(|e| Error::io(path, e))?;
        check_length(map.len() as u64, layout.file_len, path)?;
        let held = 4 * block_crcs.len() + flags.len() + 4 * albedo.as_ref().map_or(0, Vec::len);
        let held = held + surface.as_ref().map_or(0, Surface::heap_bytes);
        let charge = limits.check_alloc("raw store tables", held as u64, 1)?;
        Ok(RawStore {
            _charge: charge,
            file,
            map,
            header,
            layout,
            path: path.into(),
            block_crcs,
            flags,
            albedo,
            surface,
            stamp,
        })
    }

    /// The header.
    pub fn header(&self) -> &RawHeader {
        &self.header
    }

    /// The matrix dimensions.
    pub fn dims(&self) -> Dims {
        self.header.dims
    }

    /// The file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Reads rows `range` into `out` (resized to `range.len() · M · C`
    /// values) with positioned reads: a file truncated since it was opened
    /// gives an [`Error::Io`] that says so, never a signal. The values are
    /// as stored; a [`BlockVerifier`] checks them.
    pub fn read_rows(&self, range: Range<usize>, out: &mut Vec<f32>) -> Result<()> {
        let p = self.header.dims.pixels();
        if range.start > range.end || range.end > p {
            return Err(Error::range(
                "raw store rows",
                format!("{}..{}", range.start, range.end),
                format!("a range within 0..{p}"),
            ));
        }
        let row_len = self.header.dims.row_len();
        self.read_values(range.start * row_len..range.end * row_len, out)
    }

    /// Reads the values `range` of the data (`p·M·C + j·C + c`), which must
    /// lie within it, into `out` (resized), with positioned reads.
    pub(crate) fn read_values(&self, range: Range<usize>, out: &mut Vec<f32>) -> Result<()> {
        out.truncate(range.len());
        out.resize(range.len(), 0.0);
        let offset = self.layout.data_offset + range.start as u64 * 4;
        read_at(
            &self.file,
            &self.path,
            bytemuck::cast_slice_mut(out),
            offset,
        )
    }

    /// Rows `range` as one slice of `range.len() · M · C` values, from the
    /// memory map. Truncating the file while it is mapped raises SIGBUS on
    /// access: [`RawStore::read_rows`] is the safe way to read.
    pub fn rows(&self, range: Range<usize>) -> &[f32] {
        let row_bytes = self.header.dims.row_len() * 4;
        let start = self.layout.data_offset as usize + range.start * row_bytes;
        bytemuck::cast_slice(&self.map[start..start + range.len() * row_bytes])
    }

    /// Row `p`: M·C values, channel-interleaved (memory-mapped, as
    /// [`RawStore::rows`]).
    pub fn row(&self, p: usize) -> &[f32] {
        self.rows(p..p + 1)
    }

    /// True when row `p` is flagged all zero (e.g. a background pixel). The
    /// flag is checked against the row's values when its block is verified
    /// ([`RawStore::verify_block`]): trust it only after that.
    pub fn is_zero_row(&self, p: usize) -> bool {
        self.flags.get(p) == Some(&1)
    }

    /// The RGB albedo image (3 finite values per pixel), if stored.
    pub fn albedo(&self) -> Option<&[f32]> {
        self.albedo.as_deref()
    }

    /// The per-row surface data (version 3), if stored: CRC-checked, one
    /// valid point (finite, unit normal) or all-zero record per row.
    pub fn surface(&self) -> Option<&Surface> {
        self.surface.as_ref()
    }

    /// Checks block `b`: its CRC against the block table, that its values
    /// are finite and that every row flagged zero is zero. Reads it with
    /// positioned reads, 8 MiB at a time.
    pub fn verify_block(&self, b: usize) -> Result<()> {
        if b >= self.block_crcs.len() {
            return Err(Error::range(
                "block index",
                b,
                format!("0..{}", self.block_crcs.len()),
            ));
        }
        let range = self.header.block_range(b);
        let step = (CRC_CHUNK as usize / (self.header.dims.row_len() * 4)).max(1);
        let mut verifier = BlockVerifier::new(self, range.start);
        let mut buf = Vec::new();
        for start in range.clone().step_by(step) {
            let rows = start..(start + step).min(range.end);
            self.read_rows(rows.clone(), &mut buf)?;
            verifier.feed(rows.start, &buf)?;
        }
        Ok(())
    }

    /// A [`BlockVerifier`] for reading every row in order from row 0.
    pub fn verifier(&self) -> BlockVerifier<'_> {
        BlockVerifier::new(self, 0)
    }

    /// Checks that the file still has the length and modification time it
    /// had when it was opened: a run that read it fails rather than write
    /// an output from an input that changed meanwhile.
    pub fn check_unchanged(&self) -> Result<()> {
        let now = Stamp::of(&self.file, &self.path)?;
        if now == self.stamp {
            return Ok(());
        }
        let detail = if now.len != self.stamp.len {
            format!(
                "its length went from {} to {} bytes",
                self.stamp.len, now.len
            )
        } else {
            "its modification time changed".into()
        };
        Err(Error::io(
            &self.path,
            io::Error::other(format!(
                "the file changed while it was read ({detail}); no output is written from a changed input"
            )),
        ))
    }

    /// Lets the kernel drop the mapped pages of rows `range` from this
    /// process (they stay readable), bounding resident memory on long scans
    /// through [`RawStore::rows`].
    pub fn release_rows(&self, range: Range<usize>) {
        let row_bytes = self.header.dims.row_len() * 4;
        let start = self.layout.data_offset as usize + range.start * row_bytes;
        mmap::release(&self.map, start, range.len() * row_bytes);
    }

    /// The first problem of row `p`'s values: a non-finite value, or a value
    /// other than 0 in a row flagged zero.
    fn check_row(&self, p: usize, row: &[f32]) -> Result<()> {
        let c = self.header.dims.channels as usize;
        if let Some(i) = row.iter().position(|v| !v.is_finite()) {
            return Err(Error::range(
                "raw store value",
                format!("{} (row {p}, column {}, channel {})", row[i], i / c, i % c),
                "finite",
            ));
        }
        if self.is_zero_row(p) {
            if let Some(i) = row.iter().position(|&v| v != 0.0) {
                return Err(Error::corrupt(
                    "raw store",
                    format!(
                        "{}: row {p} is flagged all zero but holds {} at column {}, channel {}",
                        self.path.display(),
                        row[i],
                        i / c,
                        i % c
                    ),
                ));
            }
        }
        Ok(())
    }
}

/// The file is exactly as long as the header implies.
fn check_length(len: u64, expected: u64, path: &Path) -> Result<()> {
    if len == expected {
        return Ok(());
    }
    let what = if len < expected { "truncated: " } else { "" };
    Err(Error::corrupt(
        "raw store",
        format!(
            "{}: {what}the file is {len} bytes, the header implies {expected}",
            path.display()
        ),
    ))
}

/// The block table: every state must be 1 (complete); returns the CRCs.
fn read_block_table(
    file: &File,
    path: &Path,
    layout: &Layout,
    limits: &Limits,
) -> Result<Vec<u32>> {
    let count = usize::try_from(layout.block_count).unwrap_or(usize::MAX / 8);
    let (mut table, _held) = limits.vec("raw store block table", count.saturating_mul(8), 0u8)?;
    read_at(file, path, &mut table, layout.table_offset)?;
    let entry =
        |e: &[u8], k: usize| u32::from_le_bytes(e[4 * k..4 * k + 4].try_into().expect("4 bytes"));
    table
        .chunks_exact(8)
        .enumerate()
        .map(|(b, e)| match entry(e, 0) {
            1 => Ok(entry(e, 1)),
            0 => Err(Error::corrupt(
                "raw store",
                format!(
                    "{}: block {b} was never completed (state 0)",
                    path.display()
                ),
            )),
            s => Err(Error::range(
                "raw store block state",
                format!("{s} (block {b})"),
                "0 (pending) or 1 (complete)",
            )),
        })
        .collect()
}

/// The row flags: every byte 0 or 1.
fn read_flags(
    file: &File,
    path: &Path,
    header: &RawHeader,
    layout: &Layout,
    limits: &Limits,
) -> Result<Vec<u8>> {
    let (mut flags, _held) = limits.vec("raw store row flags", header.dims.pixels(), 0u8)?;
    read_at(file, path, &mut flags, layout.flags_offset)?;
    if let Some(p) = flags.iter().position(|&f| f > 1) {
        return Err(Error::range(
            "raw store row flag",
            format!("{} (row {p})", flags[p]),
            "0 (not known to be zero) or 1 (all zero)",
        ));
    }
    Ok(flags)
}

/// The surface data, if stored: size checked against the limits, CRC and
/// every record checked.
fn read_surface(
    file: &File,
    path: &Path,
    header: &RawHeader,
    layout: &Layout,
    limits: &Limits,
) -> Result<Option<Surface>> {
    if !header.has_surface {
        return Ok(None);
    }
    let rows = header.dims.pixels();
    let len = rows.saturating_mul(SURFACE_RECORD_LEN);
    let (mut bytes, _held) = limits.vec("raw store surface data", len.saturating_add(4), 0u8)?;
    read_at(file, path, &mut bytes, layout.surface_offset)?;
    let stored = u32::from_le_bytes(bytes[len..].try_into().expect("4 bytes"));
    let computed = crc32fast::hash(&bytes[..len]);
    if stored != computed {
        return Err(Error::Crc {
            chunk: "raw store surface data".into(),
            stored,
            computed,
        });
    }
    Surface::decode_records(&bytes[..len], rows).map(Some)
}

/// The albedo image, if stored: every value finite.
fn read_albedo(
    file: &File,
    path: &Path,
    header: &RawHeader,
    layout: &Layout,
    limits: &Limits,
) -> Result<Option<Vec<f32>>> {
    if !header.has_albedo {
        return Ok(None);
    }
    let count = header.dims.pixels().saturating_mul(3);
    let (mut albedo, _held) = limits.vec("raw store albedo image", count, 0.0f32)?;
    read_at(
        file,
        path,
        bytemuck::cast_slice_mut(&mut albedo),
        layout.albedo_offset,
    )?;
    if let Some(i) = albedo.iter().position(|v| !v.is_finite()) {
        return Err(non_finite_albedo(i / 3, i % 3, albedo[i]));
    }
    Ok(Some(albedo))
}

/// Checks raw blocks as their rows are read in order: each block's CRC
/// against the block table read at open, that its values are finite and
/// that every row flagged zero is zero. A block is checked when its last
/// row is fed; the first problem of a block is reported after its CRC.
pub struct BlockVerifier<'a> {
    store: &'a RawStore,
    next_row: usize,
    hasher: crc32fast::Hasher,
    problem: Option<Error>,
}

impl<'a> BlockVerifier<'a> {
    fn new(store: &'a RawStore, first_row: usize) -> BlockVerifier<'a> {
        BlockVerifier {
            store,
            next_row: first_row,
            hasher: crc32fast::Hasher::new(),
            problem: None,
        }
    }

    /// Feeds whole rows from row `first` (`values`: M·C values per row),
    /// which must follow the rows fed so far, and checks every block whose
    /// last row is among them.
    pub fn feed(&mut self, first: usize, values: &[f32]) -> Result<()> {
        let (p, row_len) = (self.store.dims().pixels(), self.store.dims().row_len());
        let rows = values.len() / row_len;
        if first != self.next_row || !values.len().is_multiple_of(row_len) || first + rows > p {
            return Err(Error::Invalid(format!(
                "raw store verification: {} values from row {first} are not whole rows following row {} within 0..{p}",
                values.len(),
                self.next_row
            )));
        }
        for (k, row) in values.chunks_exact(row_len).enumerate() {
            self.row(first + k, row)?;
        }
        Ok(())
    }

    /// Checks that every row of the store has been fed.
    pub fn finish(self) -> Result<()> {
        let p = self.store.dims().pixels();
        if self.next_row != p {
            return Err(Error::Invalid(format!(
                "raw store verification stopped at row {} of {p}",
                self.next_row
            )));
        }
        Ok(())
    }

    fn row(&mut self, p: usize, row: &[f32]) -> Result<()> {
        let header = self.store.header();
        let b = p / header.block_rows as usize;
        let range = header.block_range(b);
        if p == range.start {
            self.start_block(range.clone());
        }
        self.hasher.update(bytemuck::cast_slice(row));
        if self.problem.is_none() {
            self.problem = self.store.check_row(p, row).err();
        }
        self.next_row = p + 1;
        if self.next_row == range.end {
            return self.end_block(b, range);
        }
        Ok(())
    }

    /// Starts block `rows`' CRC with its row flags and albedo values.
    fn start_block(&mut self, rows: Range<usize>) {
        self.hasher = crc32fast::Hasher::new();
        self.problem = None;
        self.hasher.update(&self.store.flags[rows.clone()]);
        if let Some(a) = &self.store.albedo {
            self.hasher
                .update(bytemuck::cast_slice(&a[3 * rows.start..3 * rows.end]));
        }
    }

    fn end_block(&mut self, b: usize, rows: Range<usize>) -> Result<()> {
        let computed = std::mem::replace(&mut self.hasher, crc32fast::Hasher::new()).finalize();
        let stored = self.store.block_crcs[b];
        if stored != computed {
            return Err(Error::Crc {
                chunk: format!("raw store block {b} (rows {}..{})", rows.start, rows.end),
                stored,
                computed,
            });
        }
        self.problem.take().map_or(Ok(()), Err)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn header(block_bytes: u64) -> RawHeader {
        RawHeader::new(Dims::image(6, 5, 2, 1), true, block_bytes)
    }

    fn fill(w: &mut RawWriter, blocks: &[usize], value: f32) {
        let h = *w.header();
        for &b in blocks {
            let n = h.block_range(b).len();
            w.write_block(
                b,
                &vec![value; n * h.dims.row_len()],
                Some(&vec![0.5; 3 * n]),
            )
            .unwrap();
        }
    }

    /// A version-2 store keeps its identity; a header without one is
    /// written as version 1, as before, and both open.
    #[test]
    fn identity_round_trips_and_version_1_stays() {
        let dir = tempfile::tempdir().unwrap();
        for (name, h) in [
            ("v1.raw", header(200)),
            ("v2.raw", header(200).with_input_id([7; 32])),
        ] {
            let path = dir.path().join(name);
            let mut w = RawWriter::create(&path, h).unwrap();
            fill(&mut w, &(0..h.block_count()).collect::<Vec<_>>(), 1.0);
            w.finish().unwrap();
            let bytes = std::fs::read(&path).unwrap();
            assert_eq!(
                u32::from_le_bytes(bytes[8..12].try_into().unwrap()),
                h.version()
            );
            let store = RawStore::open(&path).unwrap();
            assert_eq!(*store.header(), h);
            for b in 0..h.block_count() {
                store.verify_block(b).unwrap();
            }
            assert_eq!(store.row(29)[0], 1.0);
            // A truncated header is an error, not a panic.
            let cut = dir.path().join("cut.raw");
            std::fs::write(&cut, &bytes[..70]).unwrap();
            assert!(RawStore::open(&cut).is_err());
        }
    }

    fn surface(rows: usize) -> Surface {
        Surface::new(
            (0..rows)
                .map(|p| {
                    if p % 3 == 1 {
                        crate::SurfacePoint::INVALID
                    } else {
                        crate::SurfacePoint::new([p as f32, -1.0, 2.5], [0.0, 1.0, 0.0])
                    }
                })
                .collect(),
        )
        .unwrap()
    }

    /// Version 3 stores the row layout and the surface data, with or
    /// without an identity; a texture layout needs surface data.
    #[test]
    fn surface_and_row_layout_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let tex = Dims::texture(6, crate::Parameterization::Sphere, 2, 1);
        let plain = RawHeader::new(tex, true, 200);
        assert!(plain.has_surface && plain.version() == 3);
        for (name, h) in [
            ("tex.raw", plain),
            ("tex-id.raw", plain.with_input_id([9; 32])),
            ("img.raw", header(200).with_surface()),
        ] {
            let path = dir.path().join(name);
            let s = surface(h.dims.pixels());
            assert!(RawWriter::create(&path, h).is_err());
            let mut w = RawWriter::create_with_surface(&path, h, Some(&s)).unwrap();
            fill(&mut w, &(0..h.block_count()).collect::<Vec<_>>(), 2.0);
            w.finish().unwrap();
            let store = RawStore::open(&path).unwrap();
            assert_eq!(*store.header(), h, "{name}");
            assert_eq!(store.surface(), Some(&s));
            assert_eq!(store.row(7)[0], 2.0);
            // Any flipped bit of the surface section is caught by its CRC.
            let mut bytes = std::fs::read(&path).unwrap();
            let at = u64::from_le_bytes(bytes[92..100].try_into().unwrap()) as usize;
            bytes[at + 5] ^= 1;
            let bad = dir.path().join("bad.raw");
            std::fs::write(&bad, &bytes).unwrap();
            let e = RawStore::open(&bad).err().unwrap().to_string();
            assert!(e.contains("surface"), "{e}");
        }
        let wrong = surface(7);
        assert!(
            RawWriter::create_with_surface(&dir.path().join("w.raw"), plain, Some(&wrong)).is_err()
        );
        assert!(RawWriter::create_with_surface(
            &dir.path().join("w.raw"),
            header(200),
            Some(&surface(30))
        )
        .is_err());
        let no_surface = RawHeader {
            has_surface: false,
            ..plain
        };
        assert!(RawWriter::create(&dir.path().join("w.raw"), no_surface).is_err());
    }

    /// A partial file is resumed only with the same identity and layout;
    /// otherwise it is started over, and the writer says why.
    #[test]
    fn resume_needs_the_same_identity() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("s.raw");
        let partial = dir.path().join("s.raw.partial");
        let (a, b) = (
            header(200).with_input_id([1; 32]),
            header(200).with_input_id([2; 32]),
        );
        let w = RawWriter::create(&path, a).unwrap();
        assert_eq!(w.resume_state(), ResumeState::New);
        let mut w = w;
        fill(&mut w, &[0, 2], 3.0);
        drop(w);
        let state = |h: RawHeader| RawWriter::create(&path, h).unwrap().resume_state();
        let total = a.block_count();
        assert_eq!(state(a), ResumeState::Resumed { kept: 2, total });
        assert_eq!(
            RawWriter::create(&path, a).unwrap().pending_blocks().len(),
            total - 2
        );
        let restarted = |why| ResumeState::Restarted(why);
        assert_eq!(state(b), restarted(RestartReason::DifferentInputs));
        assert_eq!(state(a), restarted(RestartReason::DifferentInputs));
        // Started over: nothing of the old file is kept.
        assert_eq!(state(a), ResumeState::Resumed { kept: 0, total });
        let mut w = RawWriter::create(&path, a).unwrap();
        fill(&mut w, &[1], 3.0);
        drop(w);
        let other_blocks = RawHeader {
            block_rows: a.block_rows + 1,
            ..a
        };
        assert_eq!(
            state(other_blocks),
            restarted(RestartReason::DifferentLayout)
        );
        let mut w = RawWriter::create(&path, a).unwrap();
        fill(&mut w, &[1], 3.0);
        drop(w);
        assert_eq!(
            state(RawHeader {
                input_id: None,
                ..a
            }),
            restarted(RestartReason::NoIdentity)
        );
        // Now a version-1 partial: no identity to compare.
        assert_eq!(state(a), restarted(RestartReason::NoIdentity));
        let mut w = RawWriter::create(&path, a).unwrap();
        fill(&mut w, &[1], 3.0);
        drop(w);
        let len = std::fs::metadata(&partial).unwrap().len();
        std::fs::OpenOptions::new()
            .write(true)
            .open(&partial)
            .unwrap()
            .set_len(len - 1)
            .unwrap();
        assert_eq!(state(a), restarted(RestartReason::WrongLength));
        std::fs::write(&partial, b"not a raw store").unwrap();
        assert_eq!(state(a), restarted(RestartReason::Unreadable));
        assert!(state(a).to_string().contains("kept 0 of"));
    }
}
