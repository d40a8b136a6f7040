//! The `.ltm` writers: [`LtmWriter`] streams a wavelet file's columns,
//! [`write_pca_file`] writes a `pca` file at once.

use super::directory::{
    encode_head, pack, DirEntry, Packing, DIR_ENTRY_LEN, FEATURE_ALBEDO, FEATURE_COLUMN_NORMS,
    FEATURE_EMPTY_ROWS, FEATURE_NEAR_FIELD, FEATURE_PRIORS, FEATURE_RECEIVER_MESH, FEATURE_SURFACE,
    HEADER_LEN,
};
use super::meta::{Meta, META_LEN};
use super::prime::{prime, Data, BATCH_BYTES};
use crate::bytes::Writer;
use crate::column::{ColumnEntry, EncodedColumn};
use crate::empty::EmptyRows;
use crate::entropy::ColumnShape;
use crate::error::{Error, Result};
use crate::mesh::ReceiverMesh;
use crate::nearfield::PlaneRows;
use crate::output::AtomicFile;
use crate::pca::PcaModel;
use crate::surface::Surface;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

/// The optional chunks of a new `.ltm` file beside its albedo image.
#[derive(Clone, Copy, Debug, Default)]
pub struct OptionalChunks<'a> {
    /// Per-row surface data (chunk SURF); required for a texture layout.
    pub surface: Option<&'a Surface>,
    /// The receiving mesh (chunk MESH); only for a texture layout, with
    /// `surface`. It must pass [`ReceiverMesh::validate`] for the texture.
    pub mesh: Option<&'a ReceiverMesh>,
    /// The mask of all-zero rows (chunk EMPT); stored when it has any.
    pub empty_rows: Option<&'a EmptyRows>,
    /// Every row's transport over a light plane's face (chunk NEAR); only
    /// with `surface`, one row per matrix row, the matrix's channels.
    pub near_field: Option<&'a PlaneRows>,
    /// Store every column's priority norm (chunk NORM): each pushed
    /// column must then carry one ([`EncodedColumn::with_norm`]).
    pub column_norms: bool,
    /// Once every column is written, measure the file's priors (chunk
    /// PRIO) from its encoding-5 columns and code each again in encoding 6
    /// where that is smaller; kept only when the saving exceeds the chunk.
    pub priors: bool,
}

/// A chunk as stored and how ([`pack`]).
type Stored = (Vec<u8>, Packing);

/// Streams a `.ltm` file to a unique temporary file beside `PATH`, then
/// renames it into place ([`AtomicFile`]).
pub struct LtmWriter {
    file: BufWriter<AtomicFile>,
    tmp: PathBuf,
    meta: Meta,
    /// The side chunks known at the start, as stored (packed when smaller)
    /// and how.
    albedo: Option<Stored>,
    surface: Option<Stored>,
    mesh: Option<Stored>,
    near: Option<Stored>,
    empty_rows: Option<Stored>,
    entries: Vec<ColumnEntry>,
    /// The columns' norms, when the file stores them.
    norms: Option<Vec<f32>>,
    /// Whether [`OptionalChunks::priors`] was asked for.
    priors: bool,
    data_start: u64,
    data_len: u64,
}

/// What a writer knows before its first column: the side chunks as stored,
/// which optional tables it keeps, and where DATA starts.
struct SideChunks {
    albedo: Option<Stored>,
    surface: Option<Stored>,
    mesh: Option<Stored>,
    near: Option<Stored>,
    empty_rows: Option<Stored>,
    norms: bool,
    priors: bool,
    data_start: u64,
}

impl LtmWriter {
    /// Starts a file for `meta`, with an optional albedo image (3 values per
    /// pixel).
    pub fn create(path: &Path, meta: Meta, albedo: Option<&[f32]>) -> Result<LtmWriter> {
        LtmWriter::create_with(path, meta, albedo, OptionalChunks::default())
    }

    /// [`LtmWriter::create`] with the optional chunks: per-row surface data
    /// (chunk SURF, which also records the row layout of `meta.dims`; a
    /// texture layout needs it) and the mask of all-zero rows (chunk EMPT,
    /// stored when it has any).
    pub fn create_with(
        path: &Path,
        meta: Meta,
        albedo: Option<&[f32]>,
        extra: OptionalChunks<'_>,
    ) -> Result<LtmWriter> {
        meta.dims.validate()?;
        if !meta.mode.is_wavelet() {
            return Err(Error::Invalid(format!(
                "the column writer writes wavelet modes, not {} (see ltm_codec::compress_pca)",
                meta.mode.name()
            )));
        }
        if let Some(s) = extra.surface {
            s.check_rows(&meta.dims)?;
        } else if meta.dims.rows.is_texture() {
            return Err(Error::Invalid(
                "a texture-space .ltm file needs its surface data".into(),
            ));
        }
        let surface = extra.surface.map(|s| s.encode_chunk(&meta.dims.rows));
        let mesh = mesh_chunk(&extra, &meta)?;
        let near = near_chunk(&extra, &meta)?;
        let empty_rows = match extra.empty_rows {
            Some(e) if e.rows() != meta.dims.pixels() => {
                return Err(Error::BufferTooSmall {
                    what: "empty-row mask",
                    len: e.rows(),
                    need: meta.dims.pixels(),
                })
            }
            Some(e) if e.count() > 0 => Some(e.as_bytes().to_vec()),
            _ => None,
        };
        let albedo = match albedo {
            Some(a) if a.len() == 3 * meta.dims.pixels() => {
                Some(bytemuck::cast_slice::<f32, u8>(a).to_vec())
            }
            Some(a) => {
                return Err(Error::BufferTooSmall {
                    what: "albedo image",
                    len: a.len(),
                    need: 3 * meta.dims.pixels(),
                })
            }
            None => None,
        };
        let [albedo, empty_rows, surface, mesh, near] = [
            (albedo, b"ALBD"),
            (empty_rows, b"EMPT"),
            (surface, b"SURF"),
            (mesh, b"MESH"),
            (near, b"NEAR"),
        ]
        .map(|(c, tag)| c.map(|c| pack(c, tag)));
        let chunks = 3
            + albedo.is_some() as u64
            + empty_rows.is_some() as u64
            + surface.is_some() as u64
            + mesh.is_some() as u64
            + near.is_some() as u64
            + extra.column_norms as u64
            + extra.priors as u64;
        let head_len = HEADER_LEN as u64 + DIR_ENTRY_LEN as u64 * chunks + 4;
        let norms_len = 4 * meta.dims.lights() as u64 * extra.column_norms as u64;
        let optional = |c: &Option<Stored>| c.as_ref().map_or(0, |a| a.0.len() as u64);
        let data_start = head_len
            + META_LEN as u64
            + optional(&albedo)
            + optional(&empty_rows)
            + optional(&surface)
            + optional(&mesh)
            + optional(&near)
            + norms_len;
        let side = SideChunks {
            albedo,
            surface,
            mesh,
            near,
            empty_rows,
            norms: extra.column_norms,
            priors: extra.priors,
            data_start,
        };
        LtmWriter::start(path, meta, side)
    }

    /// Opens the temporary file with room for the side chunks before DATA.
    fn start(path: &Path, meta: Meta, side: SideChunks) -> Result<LtmWriter> {
        let (file, tmp) = open_at(path, side.data_start)?;
        Ok(LtmWriter {
            file,
            tmp,
            meta,
            albedo: side.albedo,
            surface: side.surface,
            mesh: side.mesh,
            near: side.near,
            empty_rows: side.empty_rows,
            entries: Vec::new(),
            norms: side.norms.then(Vec::new),
            priors: side.priors,
            data_start: side.data_start,
            data_len: 0,
        })
    }

    /// Bytes of the NEAR chunk as stored (0 without near-field rows).
    pub fn near_field_bytes(&self) -> u64 {
        self.near.as_ref().map_or(0, |c| c.0.len() as u64)
    }

    /// Appends the next column (columns are written in order `0..M`).
    pub fn push_column(&mut self, col: EncodedColumn) -> Result<()> {
        let next = self.entries.len();
        self.check_range(next, next + 1)?;
        if let Some(norms) = &mut self.norms {
            match col.norm {
                Some(n) if n.is_finite() && n >= 0.0 => norms.push(n),
                other => {
                    return Err(Error::Invalid(format!(
                        "column {next}: priority norm {other:?}, the writer stores a finite norm ≥ 0 per column"
                    )))
                }
            }
        }
        let mut entry = col.entry;
        entry.offset = self.data_len;
        self.file
            .write_all(&col.bytes)
            .map_err(|e| Error::io(&self.tmp, e))?;
        self.data_len += col.bytes.len() as u64;
        self.entries.push(entry);
        Ok(())
    }

    /// Appends columns `first..first + cols.len()`: `first` must be the
    /// number of columns written so far, so that ranges coded apart (in
    /// batches or shards) are written in order, each exactly once.
    pub fn push_columns(&mut self, first: usize, cols: Vec<EncodedColumn>) -> Result<()> {
        self.check_range(first, first.saturating_add(cols.len()))?;
        cols.into_iter().try_for_each(|c| self.push_column(c))
    }

    /// Columns `start..end` continue the columns written so far and end
    /// within the matrix.
    fn check_range(&self, start: usize, end: usize) -> Result<()> {
        let (expected, total) = (self.entries.len(), self.meta.dims.lights());
        if start != expected || end > total {
            return Err(Error::ColumnRange {
                what: "ltm writer",
                start,
                end,
                expected,
                total,
            });
        }
        Ok(())
    }

    /// Drops the partial file (as dropping the writer does).
    pub fn abandon(self) {}

    /// Drops the partial file and starts `path` again, in a new temporary
    /// file, for `meta` (of the same dimensions) with the same side chunks
    /// as they were packed: a coding pass that is not kept costs no
    /// packing of them again.
    pub fn restart(self, path: &Path, meta: Meta) -> Result<LtmWriter> {
        if meta.dims != self.meta.dims {
            return Err(Error::Invalid(format!(
                "a restarted .ltm writer keeps its dimensions ({:?}), not {:?}",
                self.meta.dims, meta.dims
            )));
        }
        let LtmWriter {
            file,
            albedo,
            surface,
            mesh,
            near,
            empty_rows,
            norms,
            priors,
            data_start,
            ..
        } = self;
        drop(file);
        let side = SideChunks {
            albedo,
            surface,
            mesh,
            near,
            empty_rows,
            norms: norms.is_some(),
            priors,
            data_start,
        };
        LtmWriter::start(path, meta, side)
    }

    /// Writes the tables, syncs and renames the file into place. Returns the
    /// file size.
    pub fn finish(mut self, achieved_error: f32) -> Result<u64> {
        let lights = self.meta.dims.lights();
        if self.entries.len() != lights {
            return Err(Error::Invalid(format!(
                "{} columns written, the matrix has {lights}",
                self.entries.len()
            )));
        }
        self.meta.achieved_error = achieved_error;
        let prio = self.prime()?;
        let (chunks, mut features) = self.side_chunks();
        // The column table (and the priors) follow DATA: they are known
        // only now, and packed when smaller.
        let (cols, cols_packing) = pack(column_table(&self.entries), b"COLS");
        // A PRIO entry is reserved when priors are asked for: without the
        // chunk, its 32 bytes stay unused (zero) before the first chunk.
        let head_len = HEADER_LEN + DIR_ENTRY_LEN * (chunks.len() + 2 + self.priors as usize) + 4;
        let mut dir = Vec::new();
        let mut offset = head_len as u64;
        for (tag, (bytes, packing)) in &chunks {
            dir.push(DirEntry {
                tag: **tag,
                offset,
                len: bytes.len() as u64,
                crc: crc32fast::hash(bytes),
                packing: *packing,
            });
            offset += bytes.len() as u64;
        }
        debug_assert_eq!(offset, self.data_start);
        dir.push(DirEntry {
            tag: *b"DATA",
            offset,
            len: self.data_len,
            crc: 0,
            packing: Packing::Stored,
        });
        let mut cols_offset = offset + self.data_len;
        if let Some((bytes, packing)) = &prio {
            dir.push(DirEntry {
                tag: *b"PRIO",
                offset: cols_offset,
                len: bytes.len() as u64,
                crc: crc32fast::hash(bytes),
                packing: *packing,
            });
            cols_offset += bytes.len() as u64;
            features |= FEATURE_PRIORS;
        }
        dir.push(DirEntry {
            tag: *b"COLS",
            offset: cols_offset,
            len: cols.len() as u64,
            crc: crc32fast::hash(&cols),
            packing: cols_packing,
        });
        let mut head = encode_head(features, &dir);
        head.resize(head_len, 0);
        let io = |e| Error::io(&self.tmp, e);
        let end = cols_offset + cols.len() as u64;
        self.file
            .seek(SeekFrom::Start(offset + self.data_len))
            .map_err(io)?;
        if let Some((bytes, _)) = &prio {
            self.file.write_all(bytes).map_err(io)?;
        }
        self.file.write_all(&cols).map_err(io)?;
        self.file.seek(SeekFrom::Start(0)).map_err(io)?;
        self.file.write_all(&head).map_err(io)?;
        for (_, (bytes, _)) in &chunks {
            self.file.write_all(bytes).map_err(io)?;
        }
        let file = self
            .file
            .into_inner()
            .map_err(|e| Error::io(&self.tmp, e.into_error()))?;
        // Priming shortened DATA: drop what is left of the old columns.
        let mut file = file;
        file.file()
            .set_len(end)
            .map_err(|e| Error::io(&self.tmp, e))?;
        file.commit()?;
        Ok(end)
    }

    /// Moves the side chunks written before DATA out of the writer, META
    /// first, with their feature flags.
    fn side_chunks(&mut self) -> (Vec<(&'static [u8; 4], Stored)>, u32) {
        let meta = self.meta.encode();
        let mut chunks: Vec<(&[u8; 4], Stored)> = vec![(b"META", (meta, Packing::Stored))];
        let mut features = 0;
        if let Some(a) = self.albedo.take() {
            chunks.push((b"ALBD", a));
            features |= FEATURE_ALBEDO;
        }
        if let Some(e) = self.empty_rows.take() {
            chunks.push((b"EMPT", e));
            features |= FEATURE_EMPTY_ROWS;
        }
        if let Some(s) = self.surface.take() {
            chunks.push((b"SURF", s));
            features |= FEATURE_SURFACE;
        }
        if let Some(m) = self.mesh.take() {
            chunks.push((b"MESH", m));
            features |= FEATURE_RECEIVER_MESH;
        }
        if let Some(n) = self.near.take() {
            chunks.push((b"NEAR", n));
            features |= FEATURE_NEAR_FIELD;
        }
        if let Some(n) = self.norms.take() {
            chunks.push((
                b"NORM",
                (
                    bytemuck::cast_slice::<f32, u8>(&n).to_vec(),
                    Packing::Stored,
                ),
            ));
            features |= FEATURE_COLUMN_NORMS;
        }
        (chunks, features)
    }

    /// Primes the file's columns when asked ([`OptionalChunks::priors`]):
    /// the PRIO chunk as stored when the file keeps it (DATA and the
    /// column table then hold the recoded columns).
    fn prime(&mut self) -> Result<Option<Stored>> {
        if !self.priors {
            return Ok(None);
        }
        self.file.flush().map_err(|e| Error::io(&self.tmp, e))?;
        let mut data = Data {
            file: self.file.get_mut().file(),
            path: &self.tmp,
            start: self.data_start,
            entries: &mut self.entries,
            shape: ColumnShape::of(&self.meta),
            batch_bytes: BATCH_BYTES,
        };
        Ok(prime(&mut data)?.map(|p| {
            self.data_len = p.data_len;
            p.prio
        }))
    }
}

/// The column table's bytes (chunk COLS, unpacked).
fn column_table(entries: &[ColumnEntry]) -> Vec<u8> {
    let mut cols = Writer::default();
    for e in entries {
        cols.u64(e.offset);
        cols.u32(e.stored_len);
        cols.u32(e.raw_len);
        cols.u32(e.nnz);
        cols.u32(e.crc);
        cols.u8(e.depth);
        cols.u8(e.encoding as u8);
        cols.u16(0);
    }
    cols.bytes
}

/// The MESH chunk of a file with `meta`, if `extra` has a mesh: only
/// for texture rows with surface data, and valid for the texture's side.
fn mesh_chunk(extra: &OptionalChunks<'_>, meta: &Meta) -> Result<Option<Vec<u8>>> {
    let Some(mesh) = extra.mesh else {
        return Ok(None);
    };
    match meta.dims.rows {
        crate::RowLayout::Texture { size, .. } if extra.surface.is_some() => {
            mesh.validate(size)
                .map_err(|e| Error::Invalid(e.to_string()))?;
            Ok(Some(mesh.encode()))
        }
        _ => Err(Error::Invalid(
            "a receiver mesh is stored only in a texture-space .ltm file, with its surface data"
                .into(),
        )),
    }
}

/// The NEAR chunk of a file with `meta`, if `extra` has near-field rows:
/// only beside surface data, one row per matrix row, the matrix's channels.
/// A new temporary file for `path`, buffered and placed at `data_start`,
/// where the columns begin; and its path, for messages.
fn open_at(path: &Path, data_start: u64) -> Result<(BufWriter<AtomicFile>, PathBuf)> {
    let file = AtomicFile::create(path)?;
    let tmp = file.tmp_path().to_path_buf();
    let mut file = BufWriter::with_capacity(1 << 20, file);
    file.seek(SeekFrom::Start(data_start))
        .map_err(|e| Error::io(&tmp, e))?;
    Ok((file, tmp))
}

fn near_chunk(extra: &OptionalChunks<'_>, meta: &Meta) -> Result<Option<Vec<u8>>> {
    let Some(near) = extra.near_field else {
        return Ok(None);
    };
    if extra.surface.is_none() {
        return Err(Error::Invalid(
            "near-field rows are stored only with their rows' surface data".into(),
        ));
    }
    let (rows, channels) = (meta.dims.pixels(), meta.dims.channels as usize);
    if near.rows() != rows || near.channels() != channels {
        return Err(Error::Invalid(format!(
            "near-field rows: {} rows of {} channels, the matrix has {rows} of {channels}",
            near.rows(),
            near.channels()
        )));
    }
    Ok(Some(near.encode()))
}

/// Writes a `pca` file: META, ALBD, EMPT (when it has a row), SURF, MESH
/// (each when given), PCAM, PCAB, PCAC, atomically. `extra` may not ask
/// for column norms. Returns the file size.
pub(crate) fn write_pca_file(
    path: &Path,
    meta: Meta,
    albedo: Option<&[f32]>,
    extra: OptionalChunks<'_>,
    model: &PcaModel,
    zstd_level: i32,
) -> Result<u64> {
    let (surface, empty_rows) = (extra.surface, extra.empty_rows);
    if extra.column_norms {
        return Err(Error::Invalid("a pca file stores no column norms".into()));
    }
    if extra.near_field.is_some() {
        return Err(Error::Invalid(
            "a pca file stores no near-field rows (compress the store in a wavelet mode)".into(),
        ));
    }
    let mut chunks: Vec<([u8; 4], Vec<u8>)> = vec![(*b"META", meta.encode())];
    let mut features = 0;
    if let Some(a) = albedo {
        chunks.push((*b"ALBD", bytemuck::cast_slice::<f32, u8>(a).to_vec()));
        features |= FEATURE_ALBEDO;
    }
    if let Some(e) = empty_rows.filter(|e| e.count() > 0) {
        if e.rows() != meta.dims.pixels() {
            return Err(Error::BufferTooSmall {
                what: "empty-row mask",
                len: e.rows(),
                need: meta.dims.pixels(),
            });
        }
        chunks.push((*b"EMPT", e.as_bytes().to_vec()));
        features |= FEATURE_EMPTY_ROWS;
    }
    if let Some(s) = surface {
        s.check_rows(&meta.dims)?;
        chunks.push((*b"SURF", s.encode_chunk(&meta.dims.rows)));
        features |= FEATURE_SURFACE;
    } else if meta.dims.rows.is_texture() {
        return Err(Error::Invalid(
            "a texture-space .ltm file needs its surface data".into(),
        ));
    }
    if let Some(m) = mesh_chunk(&extra, &meta)? {
        chunks.push((*b"MESH", m));
        features |= FEATURE_RECEIVER_MESH;
    }
    chunks.extend(crate::pca::write_chunks(model, zstd_level)?);
    let head_len = HEADER_LEN + DIR_ENTRY_LEN * chunks.len() + 4;
    let mut dir = Vec::new();
    let mut offset = head_len as u64;
    for (tag, bytes) in &chunks {
        dir.push(DirEntry {
            tag: *tag,
            offset,
            len: bytes.len() as u64,
            crc: crc32fast::hash(bytes),
            packing: Packing::Stored,
        });
        offset += bytes.len() as u64;
    }
    let head = encode_head(features, &dir);
    let file = AtomicFile::create(path)?;
    let tmp = file.tmp_path().to_path_buf();
    let mut w = BufWriter::with_capacity(1 << 20, file);
    let io = |e| Error::io(&tmp, e);
    w.write_all(&head).map_err(io)?;
    for (_, bytes) in &chunks {
        w.write_all(bytes).map_err(io)?;
    }
    w.into_inner()
        .map_err(|e| Error::io(&tmp, e.into_error()))?
        .commit()?;
    Ok(offset)
}
