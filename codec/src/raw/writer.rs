//! The raw store's writer: block by block, resumable from `PATH.partial`.

use super::header::{Layout, RawHeader, CRC_CHUNK, HEADER_LEN_MAX};
use crate::error::{Error, Result};
use crate::fileio::PositionedIo as _;
use crate::mesh::ReceiverMesh;
use crate::output::{partial_path, OutputLock};
use crate::surface::Surface;
use std::fs::{File, OpenOptions};
use std::path::{Path, PathBuf};

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
    /// Same inputs, but its per-row surface data differs from this run's
    /// (a parameterization that changed): its rows belong to other texels.
    DifferentSurface,
    /// Same inputs, but its receiving mesh differs from this run's (or one
    /// of the two has none).
    DifferentMesh,
    /// Same inputs, but it holds other rows: a part of a sharded bake for
    /// another shard, or a whole store where a part is written (or the
    /// reverse).
    DifferentRows,
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
            RestartReason::DifferentSurface => {
                "its surface data (the point each row stands for) differs from this run's"
            }
            RestartReason::DifferentMesh => {
                "its receiver mesh differs from this run's (or only one of the two has one)"
            }
            RestartReason::DifferentRows => {
                "it holds other rows (a part of a sharded bake for another shard, or a whole store where a part is baked, or the reverse)"
            }
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

/// `Ok` when the open partial file can be resumed by a writer of `header`
/// with the stored `surface` and `mesh` regions, else the state to report:
/// no file, or why it is started over.
fn probe_partial(
    file: &File,
    header: &RawHeader,
    layout: &Layout,
    (surface, mesh): (Option<&[u8]>, Option<&[u8]>),
) -> std::result::Result<(), ResumeState> {
    let restart = |why| Err(ResumeState::Restarted(why));
    let len = file.metadata().map(|m| m.len()).unwrap_or(0);
    if len == 0 {
        return Err(ResumeState::New);
    }
    let mut bytes = vec![0u8; len.min(HEADER_LEN_MAX) as usize];
    if file.read_exact_at(&mut bytes, 0).is_err() {
        return restart(RestartReason::Unreadable);
    }
    let Ok((old, old_layout)) = RawHeader::decode(&bytes, len, Path::new("")) else {
        return restart(RestartReason::Unreadable);
    };
    match (old.input_id, header.input_id) {
        (Some(a), Some(b)) if a != b => restart(RestartReason::DifferentInputs),
        (Some(_), Some(_)) if old.part != header.part => restart(RestartReason::DifferentRows),
        (Some(_), Some(_)) if old.mesh_len.is_some() != header.mesh_len.is_some() => {
            restart(RestartReason::DifferentMesh)
        }
        (Some(_), Some(_)) if !same_but_mesh(&old, header) => {
            restart(RestartReason::DifferentLayout)
        }
        (Some(_), Some(_)) if old.mesh_len != header.mesh_len => {
            restart(RestartReason::DifferentMesh)
        }
        (Some(_), Some(_)) if len != layout.file_len || len != old_layout.file_len => {
            restart(RestartReason::WrongLength)
        }
        (Some(_), Some(_)) if !same_region(file, layout.surface_offset, surface) => {
            restart(RestartReason::DifferentSurface)
        }
        (Some(_), Some(_)) if !same_region(file, layout.mesh_offset, mesh) => {
            restart(RestartReason::DifferentMesh)
        }
        (Some(_), Some(_)) => Ok(()),
        _ => restart(RestartReason::NoIdentity),
    }
}

/// Whether two headers are equal but for their mesh length.
fn same_but_mesh(old: &RawHeader, new: &RawHeader) -> bool {
    RawHeader {
        mesh_len: new.mesh_len,
        ..*old
    } == *new
}

/// Whether the file's bytes at `offset` equal `want` (true when there are
/// none to compare: a region the header does not have).
fn same_region(file: &File, offset: u64, want: Option<&[u8]>) -> bool {
    let Some(want) = want else {
        return true;
    };
    let mut have = vec![0u8; want.len()];
    file.read_exact_at(&mut have, offset).is_ok() && have == want
}

/// Opens `PATH.partial` for reading and writing, creating it: never
/// through a symbolic link, and only when it is (or will be) a regular
/// file.
fn open_partial(partial: &Path) -> Result<File> {
    let refuse = |reason: &str| Error::Output {
        role: "partial file".into(),
        path: partial.into(),
        reason: reason.into(),
    };
    if let Ok(m) = std::fs::symlink_metadata(partial) {
        if m.file_type().is_symlink() {
            return Err(refuse(
                "is a symbolic link: refusing to write through it; remove it",
            ));
        }
        if !m.is_file() {
            return Err(refuse("is not a regular file; remove it"));
        }
    }
    let mut options = OpenOptions::new();
    options.read(true).write(true).create(true).truncate(false);
    #[cfg(unix)]
    std::os::unix::fs::OpenOptionsExt::custom_flags(
        &mut options,
        rustix::fs::OFlags::NOFOLLOW.bits() as i32,
    );
    options.open(partial).map_err(|e| Error::io(partial, e))
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
    /// Remove the partial file when dropped unfinished (outputs that cannot
    /// be resumed, see [`RawWriter::discard_on_drop`]).
    discard: bool,
    finished: bool,
    _lock: OutputLock,
}

impl RawWriter {
    /// Opens `PATH.partial` for writing: resumes it when it comes from the
    /// same inputs as `header` (see the module docs), else starts it over.
    /// [`RawWriter::resume_state`] tells which, and why.
    pub fn create(path: &Path, header: RawHeader) -> Result<RawWriter> {
        Self::create_with_geometry(path, header, None, None)
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
        Self::create_with_geometry(path, header, surface, None)
    }

    /// [`RawWriter::create_with_surface`] with the receiving mesh of a
    /// texture layout: `mesh` must be given exactly when
    /// [`RawHeader::mesh_len`] is set, with that encoded length (make the
    /// header with [`RawHeader::with_mesh`]), and valid for the texture
    /// ([`ReceiverMesh::validate`]). It is written at once, like the
    /// surface; a partial file is resumed only when its stored mesh is the
    /// same, byte for byte ([`RestartReason::DifferentMesh`]).
    pub fn create_with_geometry(
        path: &Path,
        header: RawHeader,
        surface: Option<&Surface>,
        mesh: Option<&ReceiverMesh>,
    ) -> Result<RawWriter> {
        let layout = header.layout()?;
        let mesh_bytes = check_mesh(&header, mesh)?;
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
        crate::output::check_kind("output", path)?;
        let lock = OutputLock::acquire(path)?;
        let partial = partial_path(path);
        let io = |e| Error::io(&partial, e);
        crate::output::check_space(path, layout.file_len)?;
        let file = open_partial(&partial)?;
        let records = surface.map(surface_bytes);
        let probe = probe_partial(
            &file,
            &header,
            &layout,
            (records.as_deref(), mesh_bytes.as_deref()),
        );
        let total = layout.block_count as usize;
        let mut writer = RawWriter {
            file,
            header,
            path: path.into(),
            partial: partial.clone(),
            layout,
            done: vec![false; total],
            resume: ResumeState::New,
            discard: false,
            finished: false,
            _lock: lock,
        };
        match probe {
            Ok(()) => {
                writer.done = writer.verified_blocks()?;
                let kept = writer.done.iter().filter(|&&d| d).count();
                writer.resume = ResumeState::Resumed { kept, total };
            }
            Err(state) => {
                writer.file.set_len(0).map_err(io)?;
                writer.file.set_len(layout.file_len).map_err(io)?;
                writer
                    .file
                    .write_all_at(&header.encode(&layout), 0)
                    .map_err(io)?;
                writer.resume = state;
            }
        }
        if let Some(bytes) = records {
            writer
                .file
                .write_all_at(&bytes, layout.surface_offset)
                .map_err(io)?;
        }
        if let Some(bytes) = mesh_bytes {
            writer
                .file
                .write_all_at(&bytes, layout.mesh_offset)
                .map_err(io)?;
        }
        Ok(writer)
    }

    /// Removes the partial file if the writer is dropped before
    /// [`RawWriter::finish`]: for outputs that can never be resumed
    /// (`ltm import`), so that a failed run leaves nothing behind.
    pub fn discard_on_drop(&mut self) {
        self.discard = true;
    }

    /// What was done with an existing `PATH.partial`: started anew, resumed
    /// (with the blocks kept), or started over (and why).
    pub fn resume_state(&self) -> ResumeState {
        self.resume
    }

    /// The blocks of a resumed file marked complete whose CRC verifies.
    pub(super) fn verified_blocks(&self) -> Result<Vec<bool>> {
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

    pub(super) fn block_crc(&self, b: usize) -> Result<u32> {
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
        let plane_bytes = self.header.plane_row_len() as u64 * 4;
        let plane = (
            self.layout.plane_offset + rows.start as u64 * plane_bytes,
            self.layout.plane_offset + rows.end as u64 * plane_bytes,
        );
        for (start, end) in [(start, end), plane] {
            buf.resize((end - start).min(CRC_CHUNK) as usize, 0);
            let mut at = start;
            while at < end {
                let len = (end - at).min(CRC_CHUNK) as usize;
                self.file.read_exact_at(&mut buf[..len], at).map_err(io)?;
                h.update(&buf[..len]);
                at += len as u64;
            }
        }
        Ok(h.finalize())
    }

    /// Writes block `b`: `rows` holds its rows (M·C values each) and
    /// `albedo` its RGB albedo values when the store has an albedo image.
    /// A store with near-field rows takes [`RawWriter::write_block_with_plane`].
    pub fn write_block(&mut self, b: usize, rows: &[f32], albedo: Option<&[f32]>) -> Result<()> {
        self.write_block_with_plane(b, rows, albedo, None)
    }

    /// [`RawWriter::write_block`] with the block's near-field rows
    /// (`order²·C` values each, [`RawHeader::plane_row_len`]), given exactly
    /// when the header has a light plane; they are covered by the block's
    /// CRC after its data.
    pub fn write_block_with_plane(
        &mut self,
        b: usize,
        rows: &[f32],
        albedo: Option<&[f32]>,
        plane: Option<&[f32]>,
    ) -> Result<()> {
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
        if rows
            .iter()
            .chain(plane.into_iter().flatten())
            .any(|v| !v.is_finite())
        {
            return Err(Error::Invalid(format!(
                "block {b} holds NaN or infinite values"
            )));
        }
        let plane_len = range.len() * self.header.plane_row_len();
        if plane.map(<[f32]>::len) != self.header.plane.map(|_| plane_len) {
            return Err(Error::Invalid(format!(
                "near-field rows for block {b} must be given exactly when the store has a light plane, {plane_len} values (given {:?})",
                plane.map(<[f32]>::len)
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
        if let Some(plane) = plane {
            let bytes: &[u8] = bytemuck::cast_slice(plane);
            let at =
                self.layout.plane_offset + (range.start * self.header.plane_row_len()) as u64 * 4;
            self.file.write_all_at(bytes, at).map_err(io)?;
            h.update(bytes);
        }
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
        Self::write_dense_with_geometry(path, header, t, albedo, None, None)
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
        Self::write_dense_with_geometry(path, header, t, albedo, surface, None)
    }

    /// [`RawWriter::write_dense`] with per-row surface data and the
    /// receiving mesh (see [`RawWriter::create_with_geometry`]).
    pub fn write_dense_with_geometry(
        path: &Path,
        header: RawHeader,
        t: &[f32],
        albedo: Option<&[f32]>,
        surface: Option<&Surface>,
        mesh: Option<&ReceiverMesh>,
    ) -> Result<PathBuf> {
        let (p, row) = (header.stored_rows(), header.dims.row_len());
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
        let mut w = RawWriter::create_with_geometry(path, header, surface, mesh)?;
        for b in 0..header.block_count() {
            let r = header.block_range(b);
            let a = albedo.map(|a| &a[3 * r.start..3 * r.end]);
            w.write_block(b, &t[r.start * row..r.end * row], a)?;
        }
        w.finish()
    }

    /// Checks that every block is complete, syncs, and renames the file into
    /// place.
    pub fn finish(mut self) -> Result<PathBuf> {
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
        self.finished = true;
        Ok(self.path.clone())
    }
}

impl Drop for RawWriter {
    fn drop(&mut self) {
        if self.discard && !self.finished {
            let _ = std::fs::remove_file(&self.partial);
        }
    }
}

/// The mesh region as stored — the encoded mesh, then its CRC-32 — when
/// the header has one: `mesh` given exactly then, of the header's length
/// and valid for the texture.
fn check_mesh(header: &RawHeader, mesh: Option<&ReceiverMesh>) -> Result<Option<Vec<u8>>> {
    let (len, mesh) =
        match (header.mesh_len, mesh, header.dims.rows) {
            (None, None, _) => return Ok(None),
            (Some(len), Some(m), crate::RowLayout::Texture { size, .. }) => {
                m.validate(size)
                    .map_err(|e| Error::Invalid(e.to_string()))?;
                (len, m)
            }
            (Some(_), None, _) => {
                return Err(Error::Invalid(
                    "the raw store header has a receiver mesh but none was given".into(),
                ))
            }
            _ => return Err(Error::Invalid(
                "receiver mesh given for a raw store header without one (see RawHeader::with_mesh)"
                    .into(),
            )),
        };
    let mut bytes = mesh.encode();
    if bytes.len() as u64 != len {
        return Err(Error::BufferTooSmall {
            what: "receiver mesh",
            len: bytes.len(),
            need: len as usize,
        });
    }
    let crc = crc32fast::hash(&bytes);
    bytes.extend_from_slice(&crc.to_le_bytes());
    Ok(Some(bytes))
}

/// The surface records as stored: the records, then their CRC-32.
fn surface_bytes(s: &Surface) -> Vec<u8> {
    let mut bytes = s.encode_records();
    let crc = crc32fast::hash(&bytes);
    bytes.extend_from_slice(&crc.to_le_bytes());
    bytes
}

/// The error for a non-finite albedo value of pixel `p`, channel `c`.
pub(super) fn non_finite_albedo(p: usize, c: usize, v: f32) -> Error {
    Error::range(
        "raw store albedo value",
        format!("{v} (pixel {p}, channel {c})"),
        "finite",
    )
}
