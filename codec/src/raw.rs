//! The raw transport store: the uncompressed matrix T, row-major, as `ltm
//! bake` and `ltm import` write it and `ltm compress` reads it.
//!
//! One little-endian file (layout in docs/FORMAT.md):
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 8 | magic `LTMRAW\0\x01` |
//! | 8 | 4 | version (1) |
//! | 12 | 4 | flags: bit 0 = an albedo image is stored |
//! | 16 | 4·5 | width, height, face_res, channels, block_rows |
//! | 36 | 4 | block_count = ceil(width·height / block_rows) |
//! | 40 | 8 | data_offset (multiple of 4096) |
//! | 48 | 8 | albedo_offset (0 when absent) |
//! | 56 | 4 | reserved (0) |
//! | 60 | 4 | CRC-32 of bytes 0..60 |
//! | 64 | 8·block_count | block table: state (1 = complete), CRC-32 of the block |
//! | flags_offset | P | one byte per row: 1 = the row is all zero |
//! | albedo_offset | 12·P | RGB albedo per pixel, f32 (optional) |
//! | data_offset | 4·P·M·C | T\[p\]\[j\]\[c\], f32 |
//!
//! A block is `block_rows` consecutive rows (the last may be shorter); its
//! CRC covers its row flags, then its albedo values, then its data.
//!
//! Writing goes to `PATH.partial`, one block at a time with plain positioned
//! writes (so that a full disk is an error, not a signal), and the
//! file is renamed to `PATH` when every block is complete. Re-opening an
//! interrupted `.partial` with the same header resumes: blocks marked
//! complete whose CRC verifies are kept, the others are pending.

#[cfg(target_endian = "big")]
compile_error!("ltm's file formats are little-endian and are mapped directly; big-endian targets are not supported");

use crate::bytes::{Reader, Writer};
use crate::dims::Dims;
use crate::error::{Error, Result};
use crate::fileio::PositionedIo as _;
use crate::limits::Limits;
use crate::mmap;
use memmap2::Mmap;
use std::fs::{File, OpenOptions};
use std::path::{Path, PathBuf};

const MAGIC: [u8; 8] = *b"LTMRAW\0\x01";
const VERSION: u32 = 1;
const HEADER_LEN: u64 = 64;
const FLAG_ALBEDO: u32 = 1;
const DATA_ALIGN: u64 = 4096;
/// Bytes read at a time when a resumed block's CRC is checked.
const CRC_CHUNK: u64 = 8 << 20;

/// Header of a raw store.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RawHeader {
    /// The matrix's dimensions.
    pub dims: Dims,
    /// Rows per block (the unit of writing, resuming and checksumming).
    pub block_rows: u32,
    /// An RGB albedo image is stored (monochrome transport factored as
    /// albedo × grey transport).
    pub has_albedo: bool,
}

#[derive(Clone, Copy)]
struct Layout {
    block_count: u64,
    flags_offset: u64,
    albedo_offset: u64,
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
        let p = self.dims.pixels() as u64;
        if self.block_rows == 0 || self.block_rows as u64 > p {
            return Err(Error::range(
                "block_rows",
                self.block_rows,
                format!("1..={p}"),
            ));
        }
        let block_count = p.div_ceil(self.block_rows as u64);
        let flags_offset = HEADER_LEN + 8 * block_count;
        let albedo_offset = (flags_offset + p).next_multiple_of(64);
        let albedo_end = albedo_offset + if self.has_albedo { 12 * p } else { 0 };
        let data_offset = albedo_end.next_multiple_of(DATA_ALIGN);
        let file_len = data_offset
            .checked_add(self.dims.raw_bytes())
            .ok_or_else(|| {
                Error::range("raw store size", self.dims.raw_bytes(), "below 2^64 bytes")
            })?;
        Ok(Layout {
            block_count,
            flags_offset,
            albedo_offset: if self.has_albedo { albedo_offset } else { 0 },
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
        w.u32(VERSION);
        w.u32(if self.has_albedo { FLAG_ALBEDO } else { 0 });
        for v in self.dims.to_fields() {
            w.u32(v);
        }
        w.u32(self.block_rows);
        w.u32(layout.block_count as u32);
        w.u64(layout.data_offset);
        w.u64(layout.albedo_offset);
        w.u32(0);
        let crc = crc32fast::hash(&w.bytes);
        w.u32(crc);
        w.bytes
    }

    fn decode(bytes: &[u8], path: &Path) -> Result<(RawHeader, Layout)> {
        if bytes.len() < HEADER_LEN as usize || bytes[..8] != MAGIC {
            return Err(Error::BadMagic {
                path: path.into(),
                expected: "an ltm raw transport store",
                found: bytes[..bytes.len().min(8)].to_vec(),
            });
        }
        let mut r = Reader::new(&bytes[..HEADER_LEN as usize], "raw store header");
        r.take(8)?;
        let version = r.u32()?;
        if version != VERSION {
            return Err(Error::Version {
                what: "raw store",
                found: version,
                supported: VERSION,
            });
        }
        let flags = r.u32()?;
        let stored_crc = u32::from_le_bytes(bytes[60..64].try_into().expect("4 bytes"));
        let crc = crc32fast::hash(&bytes[..60]);
        if crc != stored_crc {
            return Err(Error::Crc {
                chunk: "raw store header".into(),
                stored: stored_crc,
                computed: crc,
            });
        }
        if flags & !FLAG_ALBEDO != 0 {
            return Err(Error::range(
                "raw store flags",
                format!("{flags:#x}"),
                "bit 0 only",
            ));
        }
        let dims = Dims::read_fields(&mut r)?;
        let header = RawHeader {
            dims,
            block_rows: r.u32()?,
            has_albedo: flags & FLAG_ALBEDO != 0,
        };
        let layout = header.layout()?;
        let (block_count, data_offset, albedo_offset) = (r.u32()?, r.u64()?, r.u64()?);
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
}

impl RawWriter {
    /// Opens `PATH.partial` for writing: resumes it when its header matches
    /// `header`, else starts a new one.
    pub fn create(path: &Path, header: RawHeader) -> Result<RawWriter> {
        let layout = header.layout()?;
        let partial = partial_path(path);
        let io = |e| Error::io(&partial, e);
        let head = header.encode(&layout);
        let mut done = vec![false; layout.block_count as usize];
        let resumable = match File::open(&partial) {
            Ok(f) => {
                let mut existing = vec![0u8; HEADER_LEN as usize];
                f.read_exact_at(&mut existing, 0).is_ok()
                    && existing == head
                    && f.metadata().map(|m| m.len()).ok() == Some(layout.file_len)
            }
            Err(_) => false,
        };
        let file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(!resumable)
            .open(&partial)
            .map_err(io)?;
        let mut writer = RawWriter {
            file,
            header,
            path: path.into(),
            partial: partial.clone(),
            layout,
            done: Vec::new(),
        };
        if resumable {
            let mut table = vec![0u8; 8 * done.len()];
            writer
                .file
                .read_exact_at(&mut table, HEADER_LEN)
                .map_err(io)?;
            for (b, entry) in table.chunks_exact(8).enumerate() {
                if entry[..4] == 1u32.to_le_bytes() {
                    let stored = u32::from_le_bytes(entry[4..8].try_into().expect("4 bytes"));
                    done[b] = writer.block_crc(b)? == stored;
                }
            }
        } else {
            writer.file.set_len(layout.file_len).map_err(io)?;
            writer.file.write_all_at(&head, 0).map_err(io)?;
        }
        writer.done = done;
        Ok(writer)
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
            .write_all_at(&entry, HEADER_LEN + 8 * b as u64)
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
        let mut w = RawWriter::create(path, header)?;
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

/// A raw store opened for reading (memory-mapped).
pub struct RawStore {
    map: Mmap,
    header: RawHeader,
    layout: Layout,
    path: PathBuf,
}

impl RawStore {
    /// Opens and validates a raw store: header CRC, dimensions, file length
    /// and completeness of every block. Block CRCs are checked by
    /// [`RawStore::verify_block`]. Uses the default [`Limits`].
    pub fn open(path: &Path) -> Result<RawStore> {
        Self::open_with_limits(path, &Limits::default())
    }

    /// [`RawStore::open`] with the given limits.
    pub fn open_with_limits(path: &Path, limits: &Limits) -> Result<RawStore> {
        let file = File::open(path).map_err(|e| Error::io(path, e))?;
        let map = mmap::map_read(&file).map_err(|e| Error::io(path, e))?;
        let (header, layout) = RawHeader::decode(&map, path)?;
        if map.len() as u64 != layout.file_len {
            return Err(Error::corrupt(
                "raw store",
                format!(
                    "{}: file is {} bytes, the header implies {}",
                    path.display(),
                    map.len(),
                    layout.file_len
                ),
            ));
        }
        limits.check_alloc("raw store block table", layout.block_count, 8)?;
        let table = &map[HEADER_LEN as usize..layout.flags_offset as usize];
        if let Some(b) = table
            .chunks_exact(8)
            .position(|e| e[..4] != 1u32.to_le_bytes())
        {
            return Err(Error::corrupt(
                "raw store",
                format!("{}: block {b} was never completed", path.display()),
            ));
        }
        Ok(RawStore {
            map,
            header,
            layout,
            path: path.into(),
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

    /// Rows `range` as one slice of `range.len() · M · C` values.
    pub fn rows(&self, range: std::ops::Range<usize>) -> &[f32] {
        let row_bytes = self.header.dims.row_len() * 4;
        let start = self.layout.data_offset as usize + range.start * row_bytes;
        bytemuck::cast_slice(&self.map[start..start + range.len() * row_bytes])
    }

    /// Row `p`: M·C values, channel-interleaved.
    pub fn row(&self, p: usize) -> &[f32] {
        self.rows(p..p + 1)
    }

    /// True when row `p` is flagged all zero (e.g. a background pixel).
    pub fn is_zero_row(&self, p: usize) -> bool {
        self.map[self.layout.flags_offset as usize + p] == 1
    }

    /// The RGB albedo image (3 values per pixel), if stored.
    pub fn albedo(&self) -> Option<&[f32]> {
        self.header.has_albedo.then(|| {
            let start = self.layout.albedo_offset as usize;
            bytemuck::cast_slice(&self.map[start..start + 12 * self.header.dims.pixels()])
        })
    }

    /// Recomputes block `b`'s CRC and checks it against the block table, and
    /// that its values are finite.
    pub fn verify_block(&self, b: usize) -> Result<()> {
        let range = self.header.block_range(b);
        let mut h = crc32fast::Hasher::new();
        let f0 = self.layout.flags_offset as usize;
        h.update(&self.map[f0 + range.start..f0 + range.end]);
        if self.header.has_albedo {
            let a0 = self.layout.albedo_offset as usize;
            h.update(&self.map[a0 + 12 * range.start..a0 + 12 * range.end]);
        }
        let data = self.rows(range.clone());
        h.update(bytemuck::cast_slice(data));
        let entry = &self.map[HEADER_LEN as usize + 8 * b..][..8];
        let stored = u32::from_le_bytes(entry[4..8].try_into().expect("4 bytes"));
        let computed = h.finalize();
        if stored != computed {
            return Err(Error::Crc {
                chunk: format!("raw store block {b} (rows {}..{})", range.start, range.end),
                stored,
                computed,
            });
        }
        if data.iter().any(|v| !v.is_finite()) {
            return Err(Error::Invalid(format!(
                "raw store block {b} holds NaN or infinite values"
            )));
        }
        Ok(())
    }

    /// Lets the kernel drop the mapped pages of rows `range` from this
    /// process (they stay readable), bounding resident memory on long scans.
    pub fn release_rows(&self, range: std::ops::Range<usize>) {
        let row_bytes = self.header.dims.row_len() * 4;
        let start = self.layout.data_offset as usize + range.start * row_bytes;
        mmap::release(&self.map, start, range.len() * row_bytes);
    }
}
