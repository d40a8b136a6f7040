//! The raw store opened for reading.

#[cfg(target_endian = "big")]
compile_error!("ltm's file formats are little-endian and are read into native values directly; big-endian targets are not supported");

use super::header::{Layout, RawHeader, CRC_CHUNK, HEADER_LEN_MAX};
use super::verify::BlockVerifier;
use super::writer::non_finite_albedo;
use crate::dims::Dims;
use crate::error::{Error, Result};
use crate::fileio::{check_regular, read_at, Stamp};
use crate::limits::{Charge, Limits};
use crate::mesh::ReceiverMesh;
use crate::surface::{Surface, SURFACE_RECORD_LEN};
use std::fs::File;
use std::ops::Range;
use std::path::{Path, PathBuf};

/// A raw store opened for reading.
///
/// Opening validates the header and reads the block table, the row flags
/// and the albedo image into memory with positioned reads, checking every
/// field: block states 0 or 1 (and every block complete), row flags 0 or 1,
/// finite albedo values. Row data is read on demand with positioned reads
/// ([`RawStore::read_rows`], [`RawStore::row_blocks`]): a file truncated
/// meanwhile is an error, never a signal. Data is trusted only once its
/// block is verified ([`RawStore::verify_block`], [`BlockVerifier`])
/// against the block table read at open.
pub struct RawStore {
    pub(super) file: File,
    pub(super) header: RawHeader,
    pub(super) layout: Layout,
    pub(super) path: PathBuf,
    /// CRC of every block, from the block table.
    pub(super) block_crcs: Vec<u32>,
    /// The header's bytes as read.
    pub(super) head: Vec<u8>,
    /// One byte per row: 1 = flagged all zero.
    pub(super) flags: Vec<u8>,
    pub(super) albedo: Option<Vec<f32>>,
    pub(super) surface: Option<Surface>,
    pub(super) mesh: Option<ReceiverMesh>,
    pub(super) stamp: Stamp,
    /// The tables' bytes, charged to the limits it was opened with.
    pub(super) _charge: Charge,
    /// Those limits: what is made from the store (a compression's buffers,
    /// its near-field rows) is charged to them too.
    pub(super) limits: Limits,
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

    /// [`RawStore::open`] with the given limits. A part of a sharded bake
    /// (version 5) is refused: it holds only some rows; `ltm merge`
    /// ([`RawStore::open_part`]) joins the parts into a whole store.
    pub fn open_with_limits(path: &Path, limits: &Limits) -> Result<RawStore> {
        let store = Self::open_any(path, limits)?;
        match store.header.part {
            Some(span) => Err(Error::Invalid(format!(
                "{}: is one part ({span}) of a sharded bake, not a whole raw store; join the parts with `ltm merge`",
                path.display()
            ))),
            None => Ok(store),
        }
    }

    /// Opens a part of a sharded bake (version 5) as [`RawStore::open_with_limits`]
    /// opens a whole store; a whole store is refused. Its stored rows are
    /// numbered from 0 ([`RawStore::read_rows`], [`RawStore::verify_block`],
    /// the row flags and albedo values): stored row `i` is row
    /// `header().first_row() + i` of the matrix. Its surface data and mesh
    /// are the whole matrix's.
    pub fn open_part(path: &Path, limits: &Limits) -> Result<RawStore> {
        let store = Self::open_any(path, limits)?;
        if store.header.part.is_none() {
            return Err(Error::Invalid(format!(
                "{}: is a whole raw store, not a part of a sharded bake (`ltm bake --shard`)",
                path.display()
            )));
        }
        Ok(store)
    }

    fn open_any(path: &Path, limits: &Limits) -> Result<RawStore> {
        let file = File::open(path).map_err(|e| Error::io(path, e))?;
        check_regular(&file, path)?;
        let stamp = Stamp::of(&file, path)?;
        let mut head = vec![0u8; stamp.len.min(HEADER_LEN_MAX) as usize];
        read_at(&file, path, &mut head, 0)?;
        let (header, layout) = RawHeader::decode(&head, stamp.len, path)?;
        check_length(stamp.len, layout.file_len, path)?;
        let block_crcs = read_block_table(&file, path, &layout, limits)?;
        let flags = read_flags(&file, path, &header, &layout, limits)?;
        let albedo = read_albedo(&file, path, &header, &layout, limits)?;
        let surface = read_surface(&file, path, &header, &layout, limits)?;
        let mesh = read_mesh(&file, path, &header, &layout, limits)?;
        // A file truncated or grown while its tables were read.
        stamp.check_unchanged(&file, path)?;
        let held = 4 * block_crcs.len() + flags.len() + 4 * albedo.as_ref().map_or(0, Vec::len);
        let held = held
            + surface.as_ref().map_or(0, Surface::heap_bytes)
            + mesh.as_ref().map_or(0, ReceiverMesh::heap_bytes);
        let charge = limits.check_alloc("raw store tables", held as u64, 1)?;
        Ok(RawStore {
            _charge: charge,
            limits: limits.clone(),
            file,
            header,
            layout,
            path: path.into(),
            block_crcs,
            head,
            flags,
            albedo,
            surface,
            mesh,
            stamp,
        })
    }

    /// The limits the store was opened with, which buffers made from it
    /// are charged to.
    pub fn limits(&self) -> &Limits {
        &self.limits
    }

    /// The header.
    pub fn header(&self) -> &RawHeader {
        &self.header
    }

    /// The matrix dimensions.
    pub fn dims(&self) -> Dims {
        self.header.dims
    }

    /// The file's length in bytes, when it was opened.
    pub fn file_len(&self) -> u64 {
        self.stamp.len
    }

    /// A 64-bit checksum of the store's content, from what opening read:
    /// the header, the block table (the CRC of every block of rows), the
    /// row flags and the albedo image. Two stores with equal ids hold the
    /// same matrix (sharded compression checks it).
    pub fn content_id(&self) -> u64 {
        let mut a = crc32fast::Hasher::new();
        let mut b = crc32fast::Hasher::new_with_initial(0x6c74_6d21);
        let parts: [&[u8]; 4] = [
            &self.head,
            bytemuck::cast_slice(&self.block_crcs),
            &self.flags,
            bytemuck::cast_slice(self.albedo.as_deref().unwrap_or(&[])),
        ];
        for p in parts {
            a.update(p);
            b.update(p);
        }
        (a.finalize() as u64) << 32 | b.finalize() as u64
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
        let p = self.header.stored_rows();
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

    /// The near-field rows `range` (`order²·C` values each, channel-
    /// interleaved; [`RawHeader::plane_row_len`]) into `out` (resized), with
    /// positioned reads. Like row data, they are trusted only once their
    /// block is verified (the block CRC covers them; [`BlockVerifier`]
    /// checks them when a block ends). An error without a light plane.
    pub fn read_plane_rows(&self, range: Range<usize>, out: &mut Vec<f32>) -> Result<()> {
        let (p, len) = (self.header.stored_rows(), self.header.plane_row_len());
        if self.header.plane.is_none() {
            return Err(Error::Invalid(format!(
                "{}: holds no near-field rows (its scene has no [light_plane])",
                self.path.display()
            )));
        }
        if range.start > range.end || range.end > p {
            return Err(Error::range(
                "raw store near-field rows",
                format!("{}..{}", range.start, range.end),
                format!("a range within 0..{p}"),
            ));
        }
        out.truncate(range.len() * len);
        out.resize(range.len() * len, 0.0);
        let offset = self.layout.plane_offset + (range.start * len) as u64 * 4;
        read_at(
            &self.file,
            &self.path,
            bytemuck::cast_slice_mut(out),
            offset,
        )
    }

    /// Row `p` (`M·C` values, channel-interleaved) as stored, read with a
    /// positioned read ([`RawStore::read_rows`]).
    pub fn read_row(&self, p: usize) -> Result<Vec<f32>> {
        let mut row = Vec::new();
        self.read_rows(p..p.saturating_add(1), &mut row)?;
        Ok(row)
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

    /// The receiving mesh of a texture layout (version 4), if stored:
    /// CRC-checked, decoded within the limits and validated for the
    /// texture.
    pub fn mesh(&self) -> Option<&ReceiverMesh> {
        self.mesh.as_ref()
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
        self.stamp.check_unchanged(&self.file, &self.path)
    }

    /// The first problem of row `p`'s values: a non-finite value, or a value
    /// other than 0 in a row flagged zero.
    pub(super) fn check_row(&self, p: usize, row: &[f32]) -> Result<()> {
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
pub(super) fn check_length(len: u64, expected: u64, path: &Path) -> Result<()> {
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
pub(super) fn read_block_table(
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
pub(super) fn read_flags(
    file: &File,
    path: &Path,
    header: &RawHeader,
    layout: &Layout,
    limits: &Limits,
) -> Result<Vec<u8>> {
    let (mut flags, _held) = limits.vec("raw store row flags", header.stored_rows(), 0u8)?;
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
pub(super) fn read_surface(
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

/// The receiving mesh, if stored (version 4): its bytes charged to the
/// limits before they are read, its CRC, then the mesh decoded and
/// validated for the texture's side.
pub(super) fn read_mesh(
    file: &File,
    path: &Path,
    header: &RawHeader,
    layout: &Layout,
    limits: &Limits,
) -> Result<Option<ReceiverMesh>> {
    let (Some(len), crate::RowLayout::Texture { size, .. }) = (header.mesh_len, header.dims.rows)
    else {
        return Ok(None);
    };
    let len = usize::try_from(len).unwrap_or(usize::MAX - 4);
    let (mut bytes, _held) = limits.vec("raw store receiver mesh", len + 4, 0u8)?;
    read_at(file, path, &mut bytes, layout.mesh_offset)?;
    let stored = u32::from_le_bytes(bytes[len..].try_into().expect("4 bytes"));
    let computed = crc32fast::hash(&bytes[..len]);
    if stored != computed {
        return Err(Error::Crc {
            chunk: "raw store receiver mesh".into(),
            stored,
            computed,
        });
    }
    ReceiverMesh::decode(&bytes[..len], size, limits).map(Some)
}

/// The albedo image, if stored: every value finite.
pub(super) fn read_albedo(
    file: &File,
    path: &Path,
    header: &RawHeader,
    layout: &Layout,
    limits: &Limits,
) -> Result<Option<Vec<f32>>> {
    if !header.has_albedo {
        return Ok(None);
    }
    let count = header.stored_rows().saturating_mul(3);
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
