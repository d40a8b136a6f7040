//! The `.ltm` reader: [`LtmFile`] opens and validates a file (directory,
//! chunks, metadata, column table) before anything is used, and reads
//! columns on demand.

use super::directory::{
    chunk, read_directory, stored_chunk, DirEntry, FEATURE_ALBEDO, FEATURE_COLUMN_NORMS,
    FEATURE_EMPTY_ROWS, FEATURE_NEAR_FIELD, FEATURE_PRIORS, FEATURE_RECEIVER_MESH, FEATURE_SURFACE,
    MAGIC,
};
use super::Meta;
use crate::bytes::Reader;
use crate::column::{
    check_column_crc, read_column, ColumnEntry, Encoding, SparseColumn, COLUMN_ENTRY_LEN,
};
use crate::compress::Mode;
use crate::dims::Dims;
use crate::empty::EmptyRows;
use crate::entropy::{ColumnShape, Priors, PRIO_LEN};
use crate::error::{Error, Result};
use crate::fileio::{check_regular, read_at, Stamp};
use crate::limits::{Charge, Limits};
use crate::mesh::ReceiverMesh;
use crate::nearfield::PlaneRows;
use crate::pca::PcaModel;
use crate::surface::Surface;
use std::fs::File;
use std::path::Path;
use std::sync::Arc;

/// The bytes of an opened file: a copy read whole at open (charged to the
/// limits it was opened with), or a buffer the caller owns. Never a memory
/// map: a file truncated or replaced after open changes nothing.
enum Bytes {
    Read {
        bytes: Vec<u8>,
        /// The bytes, charged to the limits the file was opened with.
        _charge: Charge,
    },
    Shared(Arc<[u8]>),
}

impl std::ops::Deref for Bytes {
    type Target = [u8];
    fn deref(&self) -> &[u8] {
        match self {
            Bytes::Read { bytes, .. } => bytes,
            Bytes::Shared(b) => b,
        }
    }
}

/// What [`LtmFile::parse`] finds in a file: everything but the column
/// payloads, validated.
#[derive(Clone, Debug)]
pub struct LtmIndex {
    /// The metadata (chunk META).
    pub meta: Meta,
    /// The column table (chunk COLS), one entry per column.
    pub columns: Vec<ColumnEntry>,
    /// The RGB albedo image (chunk ALBD), if stored.
    pub albedo: Option<Vec<f32>>,
    /// The per-row surface data (chunk SURF), if stored; its row layout is
    /// in `meta.dims.rows`.
    pub surface: Option<Surface>,
    /// The receiving mesh of a texture-space file (chunk MESH), if stored.
    pub mesh: Option<ReceiverMesh>,
    /// Every row's transport over a light plane's face (chunk NEAR), if
    /// stored.
    pub near_field: Option<PlaneRows>,
    /// The mask of all-zero rows (chunk EMPT), if stored.
    pub empty_rows: Option<EmptyRows>,
    /// Every column's priority norm (chunk NORM), if stored.
    pub column_norms: Option<Vec<f32>>,
    /// The starting states of column encoding 6 (chunk PRIO), if stored.
    pub priors: Option<Priors>,
    /// Where the column payloads (chunk DATA) lie in the file (empty in
    /// PCA files).
    pub data: std::ops::Range<usize>,
    /// The decoded PCA model of a `pca` file (chunks PCAM, PCAB, PCAC).
    pub pca: Option<PcaModel>,
    /// The bytes of all the above, charged to the limits it was parsed with.
    _charge: Charge,
}

/// Charges the buffers of a parsed index to `limits`.
fn index_charge(
    limits: &Limits,
    albedo: &Option<Vec<f32>>,
    (surface, mesh): (&Option<Surface>, &Option<ReceiverMesh>),
    norms: &Option<Vec<f32>>,
    columns: &[ColumnEntry],
    pca: Option<&PcaModel>,
) -> Result<Charge> {
    // Room for a PRIO chunk's priors (about the chunk's size).
    let bytes = 4 * (albedo.as_ref().map_or(0, Vec::len) + norms.as_ref().map_or(0, Vec::len))
        + PRIO_LEN
        + surface.as_ref().map_or(0, Surface::heap_bytes)
        + mesh.as_ref().map_or(0, ReceiverMesh::heap_bytes)
        + std::mem::size_of_val(columns)
        + pca.map_or(0, PcaModel::heap_bytes);
    limits.check_alloc("decoded file index", bytes as u64, 1)
}

/// An opened, validated `.ltm` file, held in memory: read whole at open
/// ([`LtmFile::open`]) or given by the caller ([`LtmFile::from_bytes`]).
pub struct LtmFile {
    bytes: Bytes,
    index: LtmIndex,
}

impl LtmFile {
    /// Opens a file and validates its header, directory, chunk CRCs, metadata
    /// and column table, with the default [`Limits`]. Column payloads are
    /// checked when read.
    pub fn open(path: &Path) -> Result<LtmFile> {
        Self::open_with_limits(path, &Limits::default())
    }

    /// [`LtmFile::open`] with the given limits. The whole file is read into
    /// memory with positioned reads, its bytes charged to `limits` (a file
    /// larger than what is left of the budget is refused with its size and
    /// the budget), and its length and modification time are checked after
    /// the read: a file truncated or rewritten while it is read is an error,
    /// and one changed after open changes nothing (no memory map, no
    /// SIGBUS).
    pub fn open_with_limits(path: &Path, limits: &Limits) -> Result<LtmFile> {
        let file = File::open(path).map_err(|e| Error::io(path, e))?;
        check_regular(&file, path)?;
        let stamp = Stamp::of(&file, path)?;
        let len = usize::try_from(stamp.len).unwrap_or(usize::MAX);
        let mut head = [0u8; 8];
        let head = &mut head[..len.min(8)];
        read_at(&file, path, head, 0)?;
        if *head == crate::raw::RAW_MAGIC {
            return Err(Error::raw_not_ltm(path));
        }
        if *head != MAGIC {
            return Err(Error::not_ltm(path, head));
        }
        let (mut bytes, charge) = limits.vec("the .ltm file's bytes", len, 0u8)?;
        read_at(&file, path, &mut bytes, 0)?;
        stamp.check_unchanged(&file, path)?;
        let index = Self::parse(&bytes, limits)?;
        Ok(LtmFile {
            bytes: Bytes::Read {
                bytes,
                _charge: charge,
            },
            index,
        })
    }

    /// Opens a whole file held in memory (from a network, an archive, a
    /// wasm host), validated as [`LtmFile::open`] does.
    pub fn from_bytes(bytes: impl Into<Arc<[u8]>>, limits: &Limits) -> Result<LtmFile> {
        let bytes: Arc<[u8]> = bytes.into();
        let index = Self::parse(&bytes, limits)?;
        Ok(LtmFile {
            bytes: Bytes::Shared(bytes),
            index,
        })
    }

    /// Parses and validates a whole file held in memory: header, directory,
    /// chunk CRCs, metadata and column table (not the column payloads).
    pub fn parse(bytes: &[u8], limits: &Limits) -> Result<LtmIndex> {
        let (version, features, dir) = read_directory(bytes)?;
        let missing =
            |t: &str| Error::corrupt("chunk directory", format!("required chunk {t} is missing"));
        let mut meta = Meta::decode(stored(bytes, &dir, b"META")?.ok_or_else(|| missing("META"))?)?;
        let albedo = read_albedo(
            chunk(bytes, &dir, b"ALBD", limits)?.as_deref(),
            features & FEATURE_ALBEDO != 0,
            &meta.dims,
        )?;
        let surface = read_surface(
            chunk(bytes, &dir, b"SURF", limits)?.as_deref(),
            features & FEATURE_SURFACE != 0,
            &mut meta,
            limits,
        )?;
        let mesh = read_mesh(
            chunk(bytes, &dir, b"MESH", limits)?.as_deref(),
            features & FEATURE_RECEIVER_MESH != 0,
            &meta.dims,
            limits,
        )?;
        let empty_rows = read_empty_rows(
            chunk(bytes, &dir, b"EMPT", limits)?.as_deref(),
            features & FEATURE_EMPTY_ROWS != 0,
            &meta.dims,
        )?;
        check_mode_chunks(version, &meta, &dir)?;
        let column_norms = read_column_norms(
            stored(bytes, &dir, b"NORM")?,
            features & FEATURE_COLUMN_NORMS != 0,
            &meta.dims,
            limits,
        )?;
        if meta.mode == Mode::Pca {
            let pca =
                read_pca_chunks(bytes, &dir, &meta, limits)?.with_empty_rows(empty_rows.clone())?;
            let charge = index_charge(
                limits,
                &albedo,
                (&surface, &mesh),
                &column_norms,
                &[],
                Some(&pca),
            )?;
            return Ok(LtmIndex {
                _charge: charge,
                meta,
                columns: Vec::new(),
                albedo,
                surface,
                mesh,
                empty_rows,
                near_field: None,
                column_norms,
                priors: None,
                data: 0..0,
                pca: Some(pca),
            });
        }
        let near_field = read_near_field(
            chunk(bytes, &dir, b"NEAR", limits)?.as_deref(),
            features & FEATURE_NEAR_FIELD != 0,
            (&meta.dims, surface.is_some()),
            limits,
        )?;
        let cols = chunk(bytes, &dir, b"COLS", limits)?.ok_or_else(|| missing("COLS"))?;
        let data_dir = dir
            .iter()
            .find(|d| &d.tag == b"DATA")
            .ok_or_else(|| missing("DATA"))?;
        let data = data_dir.offset as usize..(data_dir.offset + data_dir.len) as usize;
        let columns = read_column_table(&cols, &meta, version, data.len() as u64, limits)?;
        let priors = read_priors(
            chunk(bytes, &dir, b"PRIO", limits)?.as_deref(),
            features & FEATURE_PRIORS != 0,
            &columns,
        )?;
        let charge = index_charge(
            limits,
            &albedo,
            (&surface, &mesh),
            &column_norms,
            &columns,
            None,
        )?;
        Ok(LtmIndex {
            _charge: charge,
            meta,
            columns,
            albedo,
            surface,
            mesh,
            empty_rows,
            near_field,
            column_norms,
            priors,
            data,
            pca: None,
        })
    }

    /// The metadata.
    pub fn meta(&self) -> &Meta {
        &self.index.meta
    }

    /// The PCA model of a `pca` file (decoded and checked at open), `None`
    /// for the wavelet modes.
    pub fn pca(&self) -> Option<&PcaModel> {
        self.index.pca.as_ref()
    }

    /// The column table (empty in a `pca` file).
    pub fn columns(&self) -> &[ColumnEntry] {
        &self.index.columns
    }

    /// The albedo image (3 values per pixel), if stored.
    pub fn albedo(&self) -> Option<&[f32]> {
        self.index.albedo.as_deref()
    }

    /// The per-row surface data (chunk SURF), if stored: for a
    /// texture-space file the geometry image (texel points, normals, valid
    /// mask), for an image-space one each pixel's first hit.
    pub fn surface(&self) -> Option<&Surface> {
        self.index.surface.as_ref()
    }

    /// Every row's transport over a light plane's face (chunk NEAR,
    /// version 10), if stored.
    pub fn near_field(&self) -> Option<&PlaneRows> {
        self.index.near_field.as_ref()
    }

    /// Moves the near-field rows out of the file (which then has none), so
    /// that a relighter of them and one of the matrix share one read.
    pub fn take_near_field(&mut self) -> Option<PlaneRows> {
        self.index.near_field.take()
    }

    /// The receiving mesh of a texture-space file (chunk MESH, version 6),
    /// if stored: the triangles a relit texture is drawn on, validated
    /// against the texture at open.
    pub fn mesh(&self) -> Option<&ReceiverMesh> {
        self.index.mesh.as_ref()
    }

    /// The mask of all-zero rows, if stored (a version-1 file has none).
    pub fn empty_rows(&self) -> Option<&EmptyRows> {
        self.index.empty_rows.as_ref()
    }

    /// Every column's priority norm ([`ColumnDecoder::weighted_norm`]), if
    /// stored (version 5 and later).
    ///
    /// [`ColumnDecoder::weighted_norm`]: crate::ColumnDecoder::weighted_norm
    pub fn column_norms(&self) -> Option<&[f32]> {
        self.index.column_norms.as_deref()
    }

    /// Checks the CRC of every column payload without decoding any (about
    /// a millisecond per 10 MB), so that a damaged file is refused before
    /// its columns are decoded on demand.
    pub fn check_column_crcs(&self) -> Result<()> {
        let data = &self.bytes[self.index.data.clone()];
        for (j, e) in self.index.columns.iter().enumerate() {
            if e.encoding == Encoding::Empty {
                continue;
            }
            let stored = &data[e.offset as usize..(e.offset + e.stored_len as u64) as usize];
            check_column_crc(j, e, stored)?;
        }
        Ok(())
    }

    /// File size in bytes.
    pub fn file_bytes(&self) -> u64 {
        self.bytes.len() as u64
    }

    /// The starting states of column encoding 6 (chunk PRIO), if stored.
    pub fn priors(&self) -> Option<&Priors> {
        self.index.priors.as_ref()
    }

    /// Column `j` as stored (checked: CRC, positions, value range).
    pub fn column(&self, j: usize) -> Result<SparseColumn> {
        let Some(e) = self.index.columns.get(j) else {
            return Err(Error::range(
                "column",
                j,
                format!("0..{}", self.index.columns.len()),
            ));
        };
        read_column(
            &self.bytes[self.index.data.clone()],
            &ColumnShape::of(&self.index.meta),
            self.index.priors.as_ref(),
            j,
            e,
        )
    }
}

/// The ALBD chunk's albedo image: present exactly when the feature flag
/// says so, 3 finite values per pixel, with grey transport.
fn read_albedo(chunk: Option<&[u8]>, flagged: bool, dims: &Dims) -> Result<Option<Vec<f32>>> {
    match (chunk, flagged) {
        (Some(a), true) => {
            if dims.channels != 1 || a.len() != 12 * dims.pixels() {
                return Err(Error::corrupt(
                    "ALBD chunk",
                    format!(
                        "{} bytes for {} pixels and {} channels (needs 12 per pixel, 1 channel)",
                        a.len(),
                        dims.pixels(),
                        dims.channels
                    ),
                ));
            }
            let v: Vec<f32> = a
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes")))
                .collect();
            if v.iter().any(|x| !x.is_finite()) {
                return Err(Error::corrupt(
                    "ALBD chunk",
                    "albedo holds NaN or infinite values",
                ));
            }
            Ok(Some(v))
        }
        (None, false) => Ok(None),
        _ => Err(Error::corrupt(
            "chunk directory",
            "ALBD chunk and albedo feature flag disagree",
        )),
    }
}

/// The MESH chunk's receiving mesh: present exactly when the feature flag
/// says so, only in a texture-space file (whose SURF chunk gave the
/// texture), decoded and validated for the texture's side.
fn read_mesh(
    chunk: Option<&[u8]>,
    flagged: bool,
    dims: &Dims,
    limits: &Limits,
) -> Result<Option<ReceiverMesh>> {
    match (chunk, flagged, dims.rows) {
        (Some(m), true, crate::RowLayout::Texture { size, .. }) => {
            ReceiverMesh::decode(m, size, limits).map(Some)
        }
        (Some(_), true, _) => Err(Error::corrupt(
            "MESH chunk",
            "a receiver mesh in an image-space file (valid: only with texture rows in SURF)",
        )),
        (None, false, _) => Ok(None),
        _ => Err(Error::corrupt(
            "chunk directory",
            "MESH chunk and receiver-mesh feature flag disagree",
        )),
    }
}

/// The SURF chunk's surface data, present exactly when the feature flag
/// says so; its row layout goes into `meta`.
fn read_surface(
    chunk: Option<&[u8]>,
    flagged: bool,
    meta: &mut Meta,
    limits: &Limits,
) -> Result<Option<Surface>> {
    match (chunk, flagged) {
        (Some(c), true) => {
            let (rows, surface) = Surface::decode_chunk(c, &meta.dims, limits)?;
            meta.dims.rows = rows;
            meta.dims.validate()?;
            Ok(Some(surface))
        }
        (None, false) => Ok(None),
        _ => Err(Error::corrupt(
            "chunk directory",
            "SURF chunk and surface feature flag disagree",
        )),
    }
}

/// The NEAR chunk's near-field rows: present exactly when the feature flag
/// says so, and only beside surface data (whose points the rows are lit
/// at).
fn read_near_field(
    chunk: Option<&[u8]>,
    flagged: bool,
    (dims, has_surface): (&Dims, bool),
    limits: &Limits,
) -> Result<Option<PlaneRows>> {
    match (chunk, flagged) {
        (Some(_), true) if !has_surface => Err(Error::corrupt(
            "NEAR chunk",
            "near-field rows without surface data (valid: only with chunk SURF)",
        )),
        (Some(c), true) => {
            PlaneRows::decode(c, dims.pixels(), dims.channels as usize, limits).map(Some)
        }
        (None, false) => Ok(None),
        _ => Err(Error::corrupt(
            "chunk directory",
            "NEAR chunk and near-field feature flag disagree",
        )),
    }
}

/// The EMPT chunk's mask of all-zero rows: present exactly when the feature
/// flag says so, one bit per row.
fn read_empty_rows(chunk: Option<&[u8]>, flagged: bool, dims: &Dims) -> Result<Option<EmptyRows>> {
    match (chunk, flagged) {
        (Some(e), true) => Ok(Some(EmptyRows::from_bytes(e, dims.pixels())?)),
        (None, false) => Ok(None),
        _ => Err(Error::corrupt(
            "chunk directory",
            "EMPT chunk and empty-row feature flag disagree",
        )),
    }
}

/// The PRIO chunk's priors: present exactly when the feature flag says so,
/// and when a column has encoding 6.
fn read_priors(
    chunk: Option<&[u8]>,
    flagged: bool,
    columns: &[ColumnEntry],
) -> Result<Option<Priors>> {
    let priors = match (chunk, flagged) {
        (Some(b), true) => Some(Priors::from_bytes(b)?),
        (None, false) => None,
        _ => {
            return Err(Error::corrupt(
                "chunk directory",
                "PRIO chunk and priors feature flag disagree",
            ))
        }
    };
    let primed = columns.iter().position(|e| e.encoding == Encoding::Primed);
    match (primed, &priors) {
        (Some(j), None) => Err(Error::corrupt(
            "column table",
            format!("column {j} has encoding 6 (primed) in a file without priors (chunk PRIO)"),
        )),
        _ => Ok(priors),
    }
}

/// The NORM chunk's column norms: present exactly when the feature flag
/// says so, one finite `f32` ≥ 0 per column.
fn read_column_norms(
    chunk: Option<&[u8]>,
    flagged: bool,
    dims: &Dims,
    limits: &Limits,
) -> Result<Option<Vec<f32>>> {
    let bytes = match (chunk, flagged) {
        (Some(b), true) => b,
        (None, false) => return Ok(None),
        _ => {
            return Err(Error::corrupt(
                "chunk directory",
                "NORM chunk and column-norm feature flag disagree",
            ))
        }
    };
    let lights = dims.lights();
    if bytes.len() != 4 * lights {
        return Err(Error::corrupt(
            "NORM chunk",
            format!("{} bytes, expected {lights} columns × 4", bytes.len()),
        ));
    }
    let _held = limits.check_alloc("column norms", lights as u64, 4)?;
    let norms: Vec<f32> = bytes
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    if let Some((j, n)) = norms
        .iter()
        .enumerate()
        .find(|(_, n)| !(n.is_finite() && **n >= 0.0))
    {
        return Err(Error::range(
            "column norm",
            format!("{n} (column {j})"),
            "finite and ≥ 0",
        ));
    }
    Ok(Some(norms))
}

/// Reads the COLS chunk: one checked entry per column, payloads within a
/// DATA chunk of `data_len` bytes.
fn read_column_table(
    cols: &[u8],
    meta: &Meta,
    version: u32,
    data_len: u64,
    limits: &Limits,
) -> Result<Vec<ColumnEntry>> {
    let lights = meta.dims.lights();
    if cols.len() != COLUMN_ENTRY_LEN * lights {
        return Err(Error::corrupt(
            "COLS chunk",
            format!(
                "{} bytes, expected {lights} columns × {COLUMN_ENTRY_LEN}",
                cols.len()
            ),
        ));
    }
    let _held = limits.check_alloc(
        "column table",
        lights as u64,
        std::mem::size_of::<ColumnEntry>() as u64,
    )?;
    let mut columns = Vec::with_capacity(lights);
    let mut r = Reader::new(cols, "COLS chunk");
    for j in 0..lights {
        let entry = ColumnEntry {
            offset: r.u64()?,
            stored_len: r.u32()?,
            raw_len: r.u32()?,
            nnz: r.u32()?,
            crc: r.u32()?,
            depth: r.u8()?,
            encoding: Encoding::Empty,
        };
        let enc = r.u8()?;
        r.u16()?;
        columns.push(check_column_entry(
            j,
            entry,
            (enc, version),
            meta,
            data_len,
        )?);
    }
    Ok(columns)
}

/// Checks column `j`'s table entry (its encoding code `enc` still raw, in
/// a file of `version`) against the metadata and the DATA chunk's length.
pub(crate) fn check_column_entry(
    j: usize,
    mut e: ColumnEntry,
    (enc, version): (u8, u32),
    meta: &Meta,
    data_len: u64,
) -> Result<ColumnEntry> {
    let bad = |detail: String| {
        Err(Error::corrupt(
            "COLS chunk",
            format!("column {j}: {detail}"),
        ))
    };
    let (depth, nnz) = (e.depth, e.nnz);
    e.encoding = match Encoding::from_code(enc, version) {
        Ok(encoding) => encoding,
        Err(problem) => return bad(problem),
    };
    let max_depth = meta.max_depth();
    if depth as u32 > max_depth {
        return bad(format!("depth {depth} (valid: 0..={max_depth})"));
    }
    if meta.mode == Mode::TwoD && depth != 0
        || meta.mode == Mode::FourD && depth as u32 != max_depth
    {
        return bad(format!("depth {depth} in a {} file", meta.mode.name()));
    }
    let pixels = meta.dims.pixels() as u64;
    if nnz as u64 > pixels {
        return bad(format!("{nnz} nonzeros (valid: 0..={pixels})"));
    }
    if let Err(problem) = e.encoding.codec().check_entry(&e, &ColumnShape::of(meta)) {
        return bad(problem);
    }
    check_payload_range(j, e, data_len)
}

/// Checks that column `j`'s payload lies inside the DATA chunk.
fn check_payload_range(j: usize, e: ColumnEntry, data_len: u64) -> Result<ColumnEntry> {
    if e.offset
        .checked_add(e.stored_len as u64)
        .is_none_or(|end| end > data_len)
    {
        return Err(Error::corrupt(
            "COLS chunk",
            format!(
                "column {j}: payload {}+{} outside the {data_len}-byte DATA chunk",
                e.offset, e.stored_len
            ),
        ));
    }
    Ok(e)
}

/// Opens a whole file held in memory and reads every column: the decoder's
/// full validation through its public entry points, as the fuzz target runs
/// it. Returns the nonzero count.
pub fn validate_bytes(bytes: &[u8], limits: &Limits) -> Result<u64> {
    let file = LtmFile::from_bytes(bytes, limits)?;
    if let Some(m) = file.pca() {
        return Ok((m.rank() * (m.dims().pixels() + m.dims().row_len())) as u64);
    }
    let mut nnz = 0;
    for j in 0..file.columns().len() {
        nnz += file.column(j)?.indices.len() as u64;
    }
    Ok(nnz)
}

/// The chunks a mode needs: wavelet files hold `COLS` and `DATA` and no PCA
/// chunk; `pca` files (version 2 and later) hold `PCAM`, `PCAB`, `PCAC` and
/// neither `COLS` nor `DATA`.
fn check_mode_chunks(version: u32, meta: &Meta, dir: &[DirEntry]) -> Result<()> {
    let has = |t: &[u8; 4]| dir.iter().any(|d| &d.tag == t);
    let pca = meta.mode == Mode::Pca;
    if pca && version < 2 {
        return Err(Error::corrupt(
            ".ltm header",
            format!("mode pca in a version-{version} file (pca needs version 2)"),
        ));
    }
    let (need, refuse): (&[&[u8; 4]], &[&[u8; 4]]) = if pca {
        (
            &[b"PCAM", b"PCAB", b"PCAC"],
            &[b"COLS", b"DATA", b"NORM", b"PRIO", b"NEAR"],
        )
    } else {
        (&[b"COLS", b"DATA"], &[b"PCAM", b"PCAB", b"PCAC"])
    };
    for t in need {
        if !has(t) {
            return Err(Error::corrupt(
                "chunk directory",
                format!(
                    "required chunk {} is missing in a {} file",
                    String::from_utf8_lossy(*t),
                    meta.mode.name()
                ),
            ));
        }
    }
    for t in refuse {
        if has(t) {
            return Err(Error::corrupt(
                "chunk directory",
                format!(
                    "chunk {} in a {} file",
                    String::from_utf8_lossy(*t),
                    meta.mode.name()
                ),
            ));
        }
    }
    Ok(())
}

/// The stored bytes of a chunk that is never packed (META, NORM, the PCA
/// chunks).
fn stored<'a>(bytes: &'a [u8], dir: &[DirEntry], tag: &[u8; 4]) -> Result<Option<&'a [u8]>> {
    Ok(stored_chunk(bytes, dir, tag)?.map(|(s, _)| s))
}

/// Decodes the PCA chunks ([`crate::pca::read_chunks`]) of a `pca` file.
fn read_pca_chunks(
    bytes: &[u8],
    dir: &[DirEntry],
    meta: &Meta,
    limits: &Limits,
) -> Result<PcaModel> {
    let get = |t: &[u8; 4]| -> Result<&[u8]> {
        stored(bytes, dir, t)?
            .ok_or_else(|| Error::corrupt("chunk directory", "a PCA chunk is missing"))
    };
    crate::pca::read_chunks(get, meta.dims, meta.terms as usize, meta.bits, limits)
}
