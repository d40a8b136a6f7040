//! The `.ltm` container: everything a relighter needs, with each column
//! reachable without decoding the others. Layout in docs/FORMAT.md.
//!
//! ```text
//! header (24 bytes) | chunk directory (32 bytes × count) | directory CRC
//! META | ALBD | EMPT | SURF | NORM (each optional) | COLS (column table) | DATA (column payloads)
//! ```
//!
//! Version 2 adds feature 4 and chunk `SURF`: the row layout (image pixels
//! or texture texels) and per-row surface data ([`Surface`]). Version-1
//! files (features 1 at most) are still read. Version 5 adds feature 8 and
//! chunk `NORM`: each column's priority norm, so that a relighter can rank
//! lights by transport without decoding every column first.
//!
//! Every chunk has a CRC-32 in the directory, except DATA whose columns
//! each have their own CRC in the column table. The directory is validated
//! (tags known and unique, offsets in range, sorted, non-overlapping) before
//! any chunk is read, and no allocation is sized by a field that has not
//! been checked against the dimensions.

use crate::bytes::{Reader, Writer};
use crate::dims::Dims;
use crate::eigen::{PcaModel, QuantizedMatrix};
use crate::empty::EmptyRows;
use crate::entropy::{self, ColumnShape, ValueCoding};
use crate::error::{Error, Result};
use crate::limits::{Charge, Limits};
use crate::mmap;
use crate::output::AtomicFile;
use crate::surface::Surface;
use crate::wavelet::{max_levels, Filter};
use memmap2::Mmap;
use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// File magic: `\x89LTM\r\n\x1a\n`.
pub const MAGIC: [u8; 8] = *b"\x89LTM\r\n\x1a\n";
/// Format version this build writes. It reads versions 1 to 5; version 2
/// adds the empty-row mask ([`FEATURE_EMPTY_ROWS`]) and the row layout with
/// per-row surface data ([`FEATURE_SURFACE`]). A version-1 file has neither.
/// Version 3 adds column encoding 3 ([`Encoding::Ranged`]), version 4 column
/// encoding 4 ([`Encoding::Classed`]), version 5 the column norms
/// ([`FEATURE_COLUMN_NORMS`]).
pub const VERSION: u32 = 5;
/// The oldest format version this build reads.
pub const MIN_VERSION: u32 = 1;
/// Feature flag: an RGB albedo image is stored (chunk ALBD).
pub const FEATURE_ALBEDO: u32 = 1;
/// Feature flag (version 2): the mask of all-zero rows is stored (chunk
/// EMPT); decoders output exactly 0 in those rows.
pub const FEATURE_EMPTY_ROWS: u32 = 2;
/// Feature flag (version 2): the row layout and per-row surface data are
/// stored (chunk SURF).
pub const FEATURE_SURFACE: u32 = 4;
/// Feature flag (version 5): every column's priority norm is stored (chunk
/// NORM; wavelet modes only), [`ColumnDecoder::weighted_norm`] of the
/// decoded column.
///
/// [`ColumnDecoder::weighted_norm`]: crate::ColumnDecoder::weighted_norm
pub const FEATURE_COLUMN_NORMS: u32 = 8;
/// The feature flags a reader of each version knows, by version − 1.
const KNOWN_FEATURES: [u32; VERSION as usize] = [
    FEATURE_ALBEDO,
    FEATURE_ALBEDO | FEATURE_EMPTY_ROWS | FEATURE_SURFACE,
    FEATURE_ALBEDO | FEATURE_EMPTY_ROWS | FEATURE_SURFACE,
    FEATURE_ALBEDO | FEATURE_EMPTY_ROWS | FEATURE_SURFACE,
    FEATURE_ALBEDO | FEATURE_EMPTY_ROWS | FEATURE_SURFACE | FEATURE_COLUMN_NORMS,
];
const HEADER_LEN: usize = 24;
const DIR_ENTRY_LEN: usize = 32;
const META_LEN: usize = 64;

/// How columns were transformed (serialized by its [`Mode::name`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[non_exhaustive]
pub enum Mode {
    /// Rows only (Ng et al. 2003): every column at depth 0.
    #[serde(rename = "2d")]
    TwoD,
    /// Every column to full depth.
    #[serde(rename = "4d")]
    FourD,
    /// Each column to the depth that codes it best (Cheslack-Postava et al. 2007).
    #[serde(rename = "adaptive")]
    Adaptive,
    /// Mean-centred principal components of the rows (Eigentransport):
    /// chunks `PCAM`, `PCAB`, `PCAC` instead of `COLS` and `DATA`
    /// (format version 2).
    #[serde(rename = "pca")]
    Pca,
}

impl Mode {
    /// The mode's name on the command line and in reports: `2d`, `4d` or
    /// `adaptive`.
    pub fn name(self) -> &'static str {
        match self {
            Mode::TwoD => "2d",
            Mode::FourD => "4d",
            Mode::Adaptive => "adaptive",
            Mode::Pca => "pca",
        }
    }
    fn code(self) -> u8 {
        match self {
            Mode::TwoD => 0,
            Mode::FourD => 1,
            Mode::Adaptive => 2,
            Mode::Pca => 3,
        }
    }
    /// True for the wavelet modes (columns in `COLS`/`DATA`).
    pub fn is_wavelet(self) -> bool {
        self != Mode::Pca
    }
    fn from_code(c: u8) -> Option<Mode> {
        [Mode::TwoD, Mode::FourD, Mode::Adaptive, Mode::Pca]
            .into_iter()
            .find(|m| m.code() == c)
    }
}

impl std::str::FromStr for Mode {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Mode, String> {
        match s {
            "2d" => Ok(Mode::TwoD),
            "4d" => Ok(Mode::FourD),
            "adaptive" => Ok(Mode::Adaptive),
            "pca" => Ok(Mode::Pca),
            _ => Err(format!(
                "unknown mode '{s}' (expected 2d, 4d, adaptive or pca)"
            )),
        }
    }
}

/// How the encoder stores column payloads.
#[non_exhaustive]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Entropy {
    /// Range-coded with context modelling (encoding 4) where that is no
    /// larger than the plain payload: the smallest files.
    #[default]
    Range,
    /// zstd frames (encoding 2), as format versions 1 and 2 wrote: larger
    /// files that decode, and so open, several times faster.
    Zstd,
}

impl std::str::FromStr for Entropy {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Entropy, String> {
        match s {
            "range" => Ok(Entropy::Range),
            "zstd" => Ok(Entropy::Zstd),
            _ => Err(format!(
                "unknown entropy coder '{s}' (expected range or zstd)"
            )),
        }
    }
}

/// Everything about a file except its columns.
#[derive(Clone, Debug, PartialEq)]
pub struct Meta {
    /// What the rows and columns are, and the stored channels.
    pub dims: Dims,
    /// How the columns were transformed.
    pub mode: Mode,
    /// The row transform over each cube face (orthonormal).
    pub row_filter: Filter,
    /// The column image transform.
    pub col_filter: Filter,
    /// Quantization bits (2..=16).
    pub bits: u32,
    /// Dither seed.
    pub seed: u64,
    /// Requested relative L2 error of the decoded matrix (0 when the file was
    /// made with a term count).
    pub target_error: f32,
    /// Measured relative L2 error of the decoded matrix.
    pub achieved_error: f32,
    /// Terms per column requested (0 when made with a target error).
    pub terms: u32,
    /// Frobenius norm of the original matrix.
    pub norm: f64,
}

impl Meta {
    /// Deepest column transform possible for the image size.
    pub fn max_depth(&self) -> u32 {
        max_levels(self.dims.width() as usize, self.dims.height() as usize)
    }

    fn encode(&self) -> Vec<u8> {
        let mut w = Writer::default();
        for v in self.dims.to_fields() {
            w.u32(v);
        }
        w.u8(self.mode.code());
        w.u8(self.row_filter.code());
        w.u8(self.col_filter.code());
        w.u8(self.bits as u8);
        w.u64(self.seed);
        w.f32(self.target_error);
        w.f32(self.achieved_error);
        w.u32(self.terms);
        w.bytes.extend_from_slice(&self.norm.to_le_bytes());
        w.pad_to(META_LEN);
        w.bytes
    }

    fn decode(bytes: &[u8]) -> Result<Meta> {
        let mut r = Reader::new(bytes, "META chunk");
        let dims = Dims::read_fields(&mut r)?;
        dims.validate()?;
        let mode = r.u8()?;
        let mode = Mode::from_code(mode)
            .ok_or_else(|| Error::range("mode", mode, "0 (2d), 1 (4d), 2 (adaptive) or 3 (pca)"))?;
        let filter =
            |c: u8| Filter::from_code(c).ok_or_else(|| Error::range("filter code", c, "0..=5"));
        let row_filter = filter(r.u8()?)?;
        let col_filter = filter(r.u8()?)?;
        if !row_filter.is_orthonormal() {
            return Err(Error::range(
                "row filter",
                row_filter,
                "an orthonormal filter (haar, d4, d6, d8)",
            ));
        }
        let bits = r.u8()? as u32;
        if !(2..=16).contains(&bits) {
            return Err(Error::range("bits", bits, "2..=16"));
        }
        let seed = r.u64()?;
        let target_error = r.f32()?;
        let achieved_error = r.f32()?;
        let terms = r.u32()?;
        if mode == Mode::Pca {
            if (row_filter, col_filter) != (Filter::Haar, Filter::Haar) {
                return Err(Error::corrupt(
                    "META chunk",
                    "filter codes of a pca file must be 0",
                ));
            }
            crate::eigen::check_rank(terms as usize, dims)?;
        }
        let norm = f64::from_le_bytes(r.take(8)?.try_into().expect("8 bytes"));
        if !norm.is_finite() || norm < 0.0 {
            return Err(Error::range("matrix norm", norm, "finite and >= 0"));
        }
        Ok(Meta {
            dims,
            mode,
            row_filter,
            col_filter,
            bits,
            seed,
            target_error,
            achieved_error,
            terms,
            norm,
        })
    }
}

/// How a column payload is stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum Encoding {
    /// No nonzero coefficient: no payload.
    Empty = 0,
    /// Payload bytes as they are.
    Plain = 1,
    /// Payload compressed with zstd.
    Zstd = 2,
    /// Scale codes, then the coefficients range-coded with context
    /// modelling (version 3; `crate::entropy`).
    Ranged = 3,
    /// Scale codes, then the coefficients range-coded with magnitude
    /// classes and raw low bits (version 4; `crate::entropy`).
    Classed = 4,
}

impl Encoding {
    /// How a range-coded payload codes its values; `None` for the others.
    pub fn value_coding(self) -> Option<ValueCoding> {
        match self {
            Encoding::Ranged => Some(ValueCoding::ExpGolomb),
            Encoding::Classed => Some(ValueCoding::Classes),
            _ => None,
        }
    }

    /// Whether the payload is range-coded (encodings 3 and 4).
    pub fn is_range_coded(self) -> bool {
        self.value_coding().is_some()
    }
}

/// One column's entry in the column table.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ColumnEntry {
    /// Offset of the payload from the start of the DATA chunk.
    pub offset: u64,
    /// Stored payload bytes.
    pub stored_len: u32,
    /// Payload bytes after decompression.
    pub raw_len: u32,
    /// Nonzero coefficients.
    pub nnz: u32,
    /// CRC-32 of the stored payload.
    pub crc: u32,
    /// Column transform depth.
    pub depth: u8,
    /// How the payload is stored.
    pub encoding: Encoding,
}

/// Bytes of one column-table entry.
pub const COLUMN_ENTRY_LEN: usize = 28;

/// A column as stored: sorted coefficient positions in the Mallat layout of
/// its depth, and quantized values (`channels` per position).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SparseColumn {
    /// Column transform depth (0 = rows only).
    pub depth: u32,
    /// Quantizer scale codes ([`crate::quant::decode_scale`]),
    /// `(depth + 1) · channels` of them, group-major: group 0 is the low band,
    /// group `k` the detail bands of level `k` ([`crate::quant::scale_groups`]).
    pub scale_codes: Vec<u16>,
    /// Sorted positions of the kept coefficients in the column image.
    pub indices: Vec<u32>,
    /// Quantized values, `channels` per position, position-major.
    pub values: Vec<i32>,
}

fn put_varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

fn get_varint(r: &mut Reader) -> Result<u64> {
    let mut v = 0u64;
    for shift in (0..64).step_by(7) {
        let b = r.u8()?;
        v |= ((b & 0x7f) as u64) << shift;
        if b & 0x80 == 0 {
            return Ok(v);
        }
    }
    Err(Error::corrupt(
        "column payload",
        "varint longer than 10 bytes",
    ))
}

impl SparseColumn {
    /// Payload bytes: positions as varint gaps, then values as zigzag
    /// varints, channel-interleaved.
    pub fn to_payload(&self, channels: usize) -> Vec<u8> {
        let mut out =
            Vec::with_capacity(2 * self.scale_codes.len() + self.indices.len() * (2 + channels));
        for e in &self.scale_codes {
            out.extend_from_slice(&e.to_le_bytes());
        }
        let mut prev: i64 = -1;
        for &i in &self.indices {
            put_varint(&mut out, (i as i64 - prev - 1) as u64);
            prev = i as i64;
        }
        for &v in &self.values[..self.indices.len() * channels] {
            put_varint(&mut out, ((v << 1) ^ (v >> 31)) as u32 as u64);
        }
        out
    }

    /// Parses a payload of a column at `depth`, checking every position
    /// against `pixels` and every value against the quantizer's range.
    pub fn from_payload(
        bytes: &[u8],
        nnz: usize,
        channels: usize,
        pixels: usize,
        bits: u32,
        depth: u32,
    ) -> Result<SparseColumn> {
        let mut r = Reader::new(bytes, "column payload");
        let groups = (depth as usize + 1) * channels;
        let mut col = SparseColumn {
            depth,
            scale_codes: Vec::with_capacity(groups),
            indices: Vec::with_capacity(nnz),
            values: Vec::with_capacity(nnz * channels),
        };
        for _ in 0..groups {
            col.scale_codes.push(r.u16()?);
        }
        let mut next = 0u64;
        for _ in 0..nnz {
            let i = next.saturating_add(get_varint(&mut r)?);
            if i >= pixels as u64 {
                return Err(Error::corrupt(
                    "column payload",
                    format!("position {i} outside the {pixels}-pixel image"),
                ));
            }
            col.indices.push(i as u32);
            next = i + 1;
        }
        let max = (1i64 << (bits - 1)) - 1;
        for _ in 0..nnz * channels {
            let z = get_varint(&mut r)?;
            if z > u32::MAX as u64 {
                return Err(Error::corrupt(
                    "column payload",
                    "value out of 32-bit range",
                ));
            }
            let v = ((z >> 1) as i64) ^ -((z & 1) as i64);
            if v.abs() > max {
                return Err(Error::corrupt(
                    "column payload",
                    format!("quantized value {v} outside ±{max} for {bits} bits"),
                ));
            }
            col.values.push(v as i32);
        }
        if r.remaining() != 0 {
            return Err(Error::corrupt(
                "column payload",
                format!("{} trailing bytes", r.remaining()),
            ));
        }
        Ok(col)
    }
}

#[derive(Clone, Copy, Debug)]
struct DirEntry {
    tag: [u8; 4],
    offset: u64,
    len: u64,
    crc: u32,
}

/// A column ready to append: its stored bytes and table entry (offset not
/// yet set). Encoding is independent per column, so it runs in parallel.
pub struct EncodedColumn {
    /// The payload as stored (plain or zstd).
    pub bytes: Vec<u8>,
    /// Its column-table entry.
    pub entry: ColumnEntry,
    /// The column's priority norm ([`ColumnDecoder::weighted_norm`] of the
    /// column as decoded), for a writer that stores them
    /// ([`OptionalChunks::column_norms`]); `None` until
    /// [`EncodedColumn::with_norm`] sets it.
    ///
    /// [`ColumnDecoder::weighted_norm`]: crate::ColumnDecoder::weighted_norm
    pub norm: Option<f32>,
}

impl EncodedColumn {
    /// Encodes a column of a `width` × `height` column image quantized to
    /// `bits` bits: with [`Entropy::Range`], range-coded (encoding 4) when
    /// that is no larger than the plain payload (zstd is then not tried: on
    /// these payloads it gains less than range coding), else (and always
    /// with [`Entropy::Zstd`]) as [`EncodedColumn::new`].
    pub fn coded(
        col: &SparseColumn,
        shape: &ColumnShape,
        entropy: Entropy,
        zstd_level: i32,
    ) -> EncodedColumn {
        let nnz = col.indices.len();
        if nnz > 0 && entropy == Entropy::Range {
            if let Some(bytes) = entropy::encode(col, shape, ValueCoding::Classes) {
                if bytes.len() <= col.to_payload(shape.channels).len() {
                    let entry = ColumnEntry {
                        offset: 0,
                        stored_len: bytes.len() as u32,
                        raw_len: bytes.len() as u32,
                        nnz: nnz as u32,
                        crc: crc32fast::hash(&bytes),
                        depth: col.depth as u8,
                        encoding: Encoding::Classed,
                    };
                    return EncodedColumn {
                        bytes,
                        entry,
                        norm: None,
                    };
                }
            }
        }
        EncodedColumn::new(col, shape.channels, zstd_level)
    }

    /// Serializes and compresses a column (zstd when that is smaller),
    /// without range coding.
    pub fn new(col: &SparseColumn, channels: usize, zstd_level: i32) -> EncodedColumn {
        let nnz = col.indices.len();
        let mut entry = ColumnEntry {
            offset: 0,
            stored_len: 0,
            raw_len: 0,
            nnz: nnz as u32,
            crc: 0,
            depth: col.depth as u8,
            encoding: Encoding::Empty,
        };
        if nnz == 0 {
            return EncodedColumn {
                bytes: Vec::new(),
                entry,
                norm: None,
            };
        }
        let payload = col.to_payload(channels);
        let bytes = match zstd::bulk::compress(&payload, zstd_level) {
            Ok(packed) if packed.len() < payload.len() => {
                entry.encoding = Encoding::Zstd;
                packed
            }
            _ => {
                entry.encoding = Encoding::Plain;
                payload.clone()
            }
        };
        entry.raw_len = payload.len() as u32;
        entry.stored_len = bytes.len() as u32;
        entry.crc = crc32fast::hash(&bytes);
        EncodedColumn {
            bytes,
            entry,
            norm: None,
        }
    }

    /// The column with its priority norm set (see [`EncodedColumn::norm`]).
    pub fn with_norm(self, norm: f32) -> EncodedColumn {
        EncodedColumn {
            norm: Some(norm),
            ..self
        }
    }
}

/// The optional chunks of a new `.ltm` file beside its albedo image.
#[derive(Clone, Copy, Debug, Default)]
pub struct OptionalChunks<'a> {
    /// Per-row surface data (chunk SURF); required for a texture layout.
    pub surface: Option<&'a Surface>,
    /// The mask of all-zero rows (chunk EMPT); stored when it has any.
    pub empty_rows: Option<&'a EmptyRows>,
    /// Store every column's priority norm (chunk NORM): each pushed
    /// column must then carry one ([`EncodedColumn::with_norm`]).
    pub column_norms: bool,
}

/// Streams a `.ltm` file to a unique temporary file beside `PATH`, then
/// renames it into place ([`AtomicFile`]).
pub struct LtmWriter {
    file: BufWriter<AtomicFile>,
    tmp: PathBuf,
    meta: Meta,
    albedo: Option<Vec<u8>>,
    surface: Option<Vec<u8>>,
    empty_rows: Option<Vec<u8>>,
    entries: Vec<ColumnEntry>,
    /// The columns' norms, when the file stores them.
    norms: Option<Vec<f32>>,
    data_start: u64,
    data_len: u64,
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
                "the column writer writes wavelet modes, not {} (see ltm_codec::eigen::compress_pca)",
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
        let file = AtomicFile::create(path)?;
        let tmp = file.tmp_path().to_path_buf();
        let chunks = 3
            + albedo.is_some() as u64
            + empty_rows.is_some() as u64
            + surface.is_some() as u64
            + extra.column_norms as u64;
        let head_len = HEADER_LEN as u64 + DIR_ENTRY_LEN as u64 * chunks + 4;
        let cols_len = (COLUMN_ENTRY_LEN * meta.dims.lights()) as u64;
        let norms_len = 4 * meta.dims.lights() as u64 * extra.column_norms as u64;
        let optional = |c: &Option<Vec<u8>>| c.as_ref().map_or(0, |a| a.len() as u64);
        let data_start = head_len
            + META_LEN as u64
            + optional(&albedo)
            + optional(&empty_rows)
            + optional(&surface)
            + norms_len
            + cols_len;
        let mut w = LtmWriter {
            file: BufWriter::with_capacity(1 << 20, file),
            tmp,
            meta,
            albedo,
            surface,
            empty_rows,
            entries: Vec::new(),
            norms: extra.column_norms.then(Vec::new),
            data_start,
            data_len: 0,
        };
        w.file
            .seek(SeekFrom::Start(data_start))
            .map_err(|e| Error::io(&w.tmp, e))?;
        Ok(w)
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
        let mut cols = Writer::default();
        for e in &self.entries {
            cols.u64(e.offset);
            cols.u32(e.stored_len);
            cols.u32(e.raw_len);
            cols.u32(e.nnz);
            cols.u32(e.crc);
            cols.u8(e.depth);
            cols.u8(e.encoding as u8);
            cols.u16(0);
        }
        let meta = self.meta.encode();
        let mut chunks: Vec<(&[u8; 4], Vec<u8>)> = vec![(b"META", meta)];
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
        if let Some(n) = self.norms.take() {
            chunks.push((b"NORM", bytemuck::cast_slice::<f32, u8>(&n).to_vec()));
            features |= FEATURE_COLUMN_NORMS;
        }
        chunks.push((b"COLS", cols.bytes));
        let head_len = HEADER_LEN + DIR_ENTRY_LEN * (chunks.len() + 1) + 4;
        let mut dir = Vec::new();
        let mut offset = head_len as u64;
        for (tag, bytes) in &chunks {
            dir.push(DirEntry {
                tag: **tag,
                offset,
                len: bytes.len() as u64,
                crc: crc32fast::hash(bytes),
            });
            offset += bytes.len() as u64;
        }
        debug_assert_eq!(offset, self.data_start);
        dir.push(DirEntry {
            tag: *b"DATA",
            offset,
            len: self.data_len,
            crc: 0,
        });
        let head = encode_head(features, &dir);
        let io = |e| Error::io(&self.tmp, e);
        self.file.seek(SeekFrom::Start(0)).map_err(io)?;
        self.file.write_all(&head).map_err(io)?;
        for (_, bytes) in &chunks {
            self.file.write_all(bytes).map_err(io)?;
        }
        let file = self
            .file
            .into_inner()
            .map_err(|e| Error::io(&self.tmp, e.into_error()))?;
        file.commit()?;
        Ok(self.data_start + self.data_len)
    }
}

/// The bytes of an opened file: a memory map, or a buffer the caller owns.
enum Bytes {
    Mapped(Mmap),
    Shared(Arc<[u8]>),
}

impl std::ops::Deref for Bytes {
    type Target = [u8];
    fn deref(&self) -> &[u8] {
        match self {
            Bytes::Mapped(m) => m,
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
    /// The mask of all-zero rows (chunk EMPT), if stored.
    pub empty_rows: Option<EmptyRows>,
    /// Every column's priority norm (chunk NORM), if stored.
    pub column_norms: Option<Vec<f32>>,
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
    surface: &Option<Surface>,
    norms: &Option<Vec<f32>>,
    columns: &[ColumnEntry],
    pca: Option<&PcaModel>,
) -> Result<Charge> {
    let bytes = 4 * (albedo.as_ref().map_or(0, Vec::len) + norms.as_ref().map_or(0, Vec::len))
        + surface.as_ref().map_or(0, Surface::heap_bytes)
        + std::mem::size_of_val(columns)
        + pca.map_or(0, PcaModel::heap_bytes);
    limits.check_alloc("decoded file index", bytes as u64, 1)
}

/// An opened, validated `.ltm` file (memory-mapped, or held in memory).
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

    /// [`LtmFile::open`] with the given limits.
    pub fn open_with_limits(path: &Path, limits: &Limits) -> Result<LtmFile> {
        let file = File::open(path).map_err(|e| Error::io(path, e))?;
        let map = mmap::map_read(&file).map_err(|e| Error::io(path, e))?;
        if map.len() < 8 || map[..8] != MAGIC {
            return Err(Error::BadMagic {
                path: path.into(),
                expected: "an .ltm file",
                found: map[..map.len().min(8)].to_vec(),
            });
        }
        let index = Self::parse(&map, limits)?;
        Ok(LtmFile {
            bytes: Bytes::Mapped(map),
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
        let mut meta = Meta::decode(chunk(bytes, &dir, b"META")?.ok_or_else(|| missing("META"))?)?;
        let albedo = read_albedo(
            chunk(bytes, &dir, b"ALBD")?,
            features & FEATURE_ALBEDO != 0,
            &meta.dims,
        )?;
        let surface = match (
            chunk(bytes, &dir, b"SURF")?,
            features & FEATURE_SURFACE != 0,
        ) {
            (Some(c), true) => {
                let (rows, surface) = Surface::decode_chunk(c, &meta.dims, limits)?;
                meta.dims.rows = rows;
                meta.dims.validate()?;
                Some(surface)
            }
            (None, false) => None,
            _ => {
                return Err(Error::corrupt(
                    "chunk directory",
                    "SURF chunk and surface feature flag disagree",
                ))
            }
        };
        let empty_rows = read_empty_rows(
            chunk(bytes, &dir, b"EMPT")?,
            features & FEATURE_EMPTY_ROWS != 0,
            &meta.dims,
        )?;
        check_mode_chunks(version, &meta, &dir)?;
        let column_norms = read_column_norms(
            chunk(bytes, &dir, b"NORM")?,
            features & FEATURE_COLUMN_NORMS != 0,
            &meta.dims,
            limits,
        )?;
        if meta.mode == Mode::Pca {
            let pca =
                read_pca_chunks(bytes, &dir, &meta, limits)?.with_empty_rows(empty_rows.clone())?;
            let charge = index_charge(limits, &albedo, &surface, &column_norms, &[], Some(&pca))?;
            return Ok(LtmIndex {
                _charge: charge,
                meta,
                columns: Vec::new(),
                albedo,
                surface,
                empty_rows,
                column_norms,
                data: 0..0,
                pca: Some(pca),
            });
        }
        let cols = chunk(bytes, &dir, b"COLS")?.ok_or_else(|| missing("COLS"))?;
        let data_dir = dir
            .iter()
            .find(|d| &d.tag == b"DATA")
            .ok_or_else(|| missing("DATA"))?;
        let data = data_dir.offset as usize..(data_dir.offset + data_dir.len) as usize;
        let columns = read_column_table(cols, &meta, version, data.len() as u64, limits)?;
        let charge = index_charge(limits, &albedo, &surface, &column_norms, &columns, None)?;
        Ok(LtmIndex {
            _charge: charge,
            meta,
            columns,
            albedo,
            surface,
            empty_rows,
            column_norms,
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

    /// Column `j` as stored (checked: CRC, positions, value range).
    pub fn column(&self, j: usize) -> Result<SparseColumn> {
        let Some(e) = self.index.columns.get(j) else {
            return Err(Error::range(
                "column",
                j,
                format!("0..{}", self.index.columns.len()),
            ));
        };
        read_column(&self.bytes[self.index.data.clone()], &self.index.meta, j, e)
    }
}

/// Reads and checks the header and the chunk directory: magic, version,
/// known feature flags, the directory CRC, and chunks with known unique
/// tags, in range, sorted and non-overlapping. Returns the feature flags
/// and the directory.
fn read_directory(bytes: &[u8]) -> Result<(u32, u32, Vec<DirEntry>)> {
    let mut r = Reader::new(bytes, ".ltm header");
    if r.take(8)? != MAGIC {
        return Err(Error::corrupt(".ltm header", "bad magic bytes"));
    }
    let version = r.u32()?;
    if !(MIN_VERSION..=VERSION).contains(&version) {
        return Err(Error::Version {
            what: ".ltm",
            found: version,
            supported: VERSION,
        });
    }
    let features = r.u32()?;
    let known = KNOWN_FEATURES[version as usize - 1];
    if features & !known != 0 {
        return Err(Error::range(
            "feature flags",
            format!("{features:#x}"),
            format!("a subset of {known:#x} in version {version}"),
        ));
    }
    let count = r.u32()? as usize;
    // Required chunks: 3 (META, COLS, DATA), 4 in a version-2 pca file
    // (META, PCAM, PCAB, PCAC); plus one per feature bit.
    let most = 3 + usize::from(version >= 2) + known.count_ones() as usize;
    if !(3..=most).contains(&count) {
        return Err(Error::range("chunk count", count, format!("3..={most}")));
    }
    r.u32()?;
    let mut dir = Vec::with_capacity(count);
    for _ in 0..count {
        let tag: [u8; 4] = r.take(4)?.try_into().expect("4 bytes");
        r.u32()?;
        let (offset, len, crc) = (r.u64()?, r.u64()?, r.u32()?);
        r.u32()?;
        dir.push(DirEntry {
            tag,
            offset,
            len,
            crc,
        });
    }
    let dir_end = r.pos();
    let stored = r.u32()?;
    let computed = crc32fast::hash(&bytes[..dir_end]);
    if stored != computed {
        return Err(Error::Crc {
            chunk: "chunk directory".into(),
            stored,
            computed,
        });
    }
    check_directory(&dir, r.pos() as u64, bytes.len())?;
    Ok((version, features, dir))
}

/// Directory entries: known unique tags, in range, sorted, non-overlapping,
/// starting at or after `start` in a file of `file_len` bytes.
fn check_directory(dir: &[DirEntry], start: u64, file_len: usize) -> Result<()> {
    let mut end = start;
    for d in dir {
        let tag = String::from_utf8_lossy(&d.tag);
        if !matches!(
            &d.tag,
            b"META"
                | b"ALBD"
                | b"EMPT"
                | b"SURF"
                | b"NORM"
                | b"COLS"
                | b"DATA"
                | b"PCAM"
                | b"PCAB"
                | b"PCAC"
        ) {
            return Err(Error::corrupt(
                "chunk directory",
                format!("unknown chunk tag {tag:?}"),
            ));
        }
        if dir.iter().filter(|o| o.tag == d.tag).count() != 1 {
            return Err(Error::corrupt(
                "chunk directory",
                format!("chunk {tag} appears more than once"),
            ));
        }
        let stop = d
            .offset
            .checked_add(d.len)
            .filter(|&s| s <= file_len as u64);
        match stop {
            Some(stop) if d.offset >= end => end = stop,
            _ => {
                return Err(Error::corrupt("chunk directory", format!(
                    "chunk {tag} at {}+{} is out of order, overlapping or past the end of the {file_len}-byte file",
                    d.offset, d.len)))
            }
        }
    }
    Ok(())
}

/// The bytes of chunk `tag`, CRC-checked (DATA has per-column CRCs
/// instead), or `None` when the directory has no such chunk. The directory
/// has been checked against the file's length.
fn chunk<'a>(bytes: &'a [u8], dir: &[DirEntry], tag: &[u8; 4]) -> Result<Option<&'a [u8]>> {
    let Some(d) = dir.iter().find(|d| &d.tag == tag) else {
        return Ok(None);
    };
    let s = &bytes[d.offset as usize..(d.offset + d.len) as usize];
    if tag != b"DATA" {
        let computed = crc32fast::hash(s);
        if computed != d.crc {
            return Err(Error::Crc {
                chunk: String::from_utf8_lossy(tag).into_owned(),
                stored: d.crc,
                computed,
            });
        }
    }
    Ok(Some(s))
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
fn check_column_entry(
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
    let (depth, nnz, raw_len, stored_len) = (e.depth, e.nnz, e.raw_len, e.stored_len);
    e.encoding = match enc {
        0 => Encoding::Empty,
        1 => Encoding::Plain,
        2 => Encoding::Zstd,
        3 if version >= 3 => Encoding::Ranged,
        4 if version >= 4 => Encoding::Classed,
        _ if version >= 3 => {
            let top = if version >= 4 { ", 4 classed" } else { "" };
            return bad(format!(
                "encoding {enc} in a file of version {version} (valid: 0 empty, 1 plain, 2 zstd, 3 range-coded{top})"
            ));
        }
        _ => {
            return bad(format!(
                "encoding {enc} in a file of version {version} (valid: 0 empty, 1 plain, 2 zstd)"
            ))
        }
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
    // A payload holds 2 bytes per scale, then 1 to 5 bytes per position and
    // per value; a range-coded one 2 bytes per scale, then its stream.
    let channels = meta.dims.channels as u64;
    let scale_bytes = 2 * (depth as u64 + 1) * channels;
    if e.encoding.is_range_coded() {
        // Encoding 4 adds the range-coded stream's length.
        let least = scale_bytes + 4 * u64::from(e.encoding == Encoding::Classed);
        if nnz == 0 || raw_len != stored_len || (stored_len as u64) < least {
            return bad(format!(
                "{nnz} nonzeros with encoding {enc}, stored length {stored_len} and payload length {raw_len} (valid: k ≥ 1, equal lengths ≥ {least})"
            ));
        }
        return check_payload_range(j, e, data_len);
    }
    let (min_raw, max_raw) = (
        scale_bytes + nnz as u64 * (1 + channels),
        scale_bytes + nnz as u64 * 5 * (1 + channels),
    );
    if (e.encoding == Encoding::Empty) != (nnz == 0)
        || (nnz > 0 && !(min_raw..=max_raw).contains(&(raw_len as u64)))
    {
        return bad(format!("{nnz} nonzeros with encoding {enc} and {raw_len} payload bytes (valid: {min_raw}..={max_raw})"));
    }
    if e.encoding == Encoding::Plain && stored_len != raw_len
        || e.encoding == Encoding::Empty && stored_len != 0
    {
        return bad(format!(
            "stored length {stored_len} for encoding {enc} and payload length {raw_len}"
        ));
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

/// Rewrites every checksum an `.ltm` image claims — each column's, each
/// chunk's and the directory's — from the bytes it covers, as far as the
/// (unchecked) directory and column table can be followed. For fuzzing and
/// tests: it lets mutated files reach the structural checks behind the CRCs.
/// Only with the `fuzzing` feature.
#[cfg(feature = "fuzzing")]
pub fn repair_checksums(b: &mut [u8]) {
    let u32_at = |b: &[u8], at: usize| {
        b.get(at..at + 4)
            .map(|s| u32::from_le_bytes(s.try_into().expect("4 bytes")))
    };
    let u64_at = |b: &[u8], at: usize| {
        b.get(at..at + 8)
            .map(|s| u64::from_le_bytes(s.try_into().expect("8 bytes")))
    };
    let span = |len: usize, offset: u64, size: u64| {
        offset
            .checked_add(size)
            .filter(|&e| e <= len as u64)
            .map(|e| offset as usize..e as usize)
    };
    let Some(count) = u32_at(b, 16).map(|c| (c as usize).min(8)) else {
        return;
    };
    let mut chunks = Vec::new();
    for k in 0..count {
        let e = 24 + 32 * k;
        if let (Some(tag), Some(offset), Some(len)) =
            (b.get(e..e + 4), u64_at(b, e + 8), u64_at(b, e + 16))
        {
            chunks.push((tag.to_vec(), offset, len, e + 24));
        }
    }
    let find = |tag: &[u8]| {
        chunks
            .iter()
            .find(|c| c.0 == tag)
            .and_then(|c| span(b.len(), c.1, c.2))
    };
    if let (Some(data), Some(cols)) = (find(b"DATA"), find(b"COLS")) {
        let mut entry = cols.start;
        while entry + COLUMN_ENTRY_LEN <= cols.end {
            if let (Some(off), Some(len)) = (u64_at(b, entry), u32_at(b, entry + 8)) {
                if let Some(r) = span(data.len(), off, len as u64) {
                    let crc = crc32fast::hash(&b[data.start + r.start..data.start + r.end]);
                    b[entry + 20..entry + 24].copy_from_slice(&crc.to_le_bytes());
                }
            }
            entry += COLUMN_ENTRY_LEN;
        }
    }
    for (tag, offset, len, crc_at) in &chunks {
        if let (false, Some(r)) = (tag == b"DATA", span(b.len(), *offset, *len)) {
            let crc = crc32fast::hash(&b[r]);
            if let Some(dst) = b.get_mut(*crc_at..*crc_at + 4) {
                dst.copy_from_slice(&crc.to_le_bytes());
            }
        }
    }
    let dir_end = 24 + 32 * count;
    if b.len() >= dir_end + 4 {
        let crc = crc32fast::hash(&b[..dir_end]);
        b[dir_end..dir_end + 4].copy_from_slice(&crc.to_le_bytes());
    }
}

/// Reads and checks one column payload from the DATA chunk.
pub(crate) fn read_column(
    data: &[u8],
    meta: &Meta,
    j: usize,
    e: &ColumnEntry,
) -> Result<SparseColumn> {
    let col = match e.encoding {
        Encoding::Empty => SparseColumn {
            depth: e.depth as u32,
            ..Default::default()
        },
        _ => {
            let stored = &data[e.offset as usize..(e.offset + e.stored_len as u64) as usize];
            check_column_crc(j, e, stored)?;
            if let Some(coding) = e.encoding.value_coding() {
                return entropy::decode(
                    stored,
                    e.nnz as usize,
                    &ColumnShape::of(meta),
                    e.depth as u32,
                    coding,
                )
                .map_err(|err| match err {
                    Error::Corrupt { what, detail } => Error::Corrupt {
                        what,
                        detail: format!("column {j}: {detail}"),
                    },
                    other => other,
                });
            }
            let payload;
            let bytes = if e.encoding == Encoding::Zstd {
                payload = zstd::bulk::decompress(stored, e.raw_len as usize).map_err(|err| {
                    Error::corrupt("column payload", format!("column {j}: zstd: {err}"))
                })?;
                if payload.len() != e.raw_len as usize {
                    return Err(Error::corrupt(
                        "column payload",
                        format!(
                            "column {j}: {} bytes after decompression, table says {}",
                            payload.len(),
                            e.raw_len
                        ),
                    ));
                }
                &payload[..]
            } else {
                stored
            };
            SparseColumn::from_payload(
                bytes,
                e.nnz as usize,
                meta.dims.channels as usize,
                meta.dims.pixels(),
                meta.bits,
                e.depth as u32,
            )?
        }
    };
    Ok(col)
}

/// Column `j`'s stored payload against the CRC of its table entry.
fn check_column_crc(j: usize, e: &ColumnEntry, stored: &[u8]) -> Result<()> {
    let crc = crc32fast::hash(stored);
    if crc != e.crc {
        return Err(Error::Crc {
            chunk: format!("column {j}"),
            stored: e.crc,
            computed: crc,
        });
    }
    Ok(())
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
        (&[b"PCAM", b"PCAB", b"PCAC"], &[b"COLS", b"DATA", b"NORM"])
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

/// Decodes and checks the PCA chunks against the metadata (`K` = `terms`,
/// already checked against the dimensions) and `limits`.
fn read_pca_chunks(
    bytes: &[u8],
    dir: &[DirEntry],
    meta: &Meta,
    limits: &Limits,
) -> Result<PcaModel> {
    let dims = meta.dims;
    let (p, n, k) = (dims.pixels(), dims.row_len(), meta.terms as usize);
    let get = |t: &[u8; 4]| -> Result<&[u8]> {
        chunk(bytes, dir, t)?
            .ok_or_else(|| Error::corrupt("chunk directory", "a PCA chunk is missing"))
    };
    let mean_bytes = get(b"PCAM")?;
    if mean_bytes.len() != 4 * n {
        return Err(Error::corrupt(
            "PCAM chunk",
            format!(
                "{} bytes, the mean row needs {} ({n} values)",
                mean_bytes.len(),
                4 * n
            ),
        ));
    }
    let _mean = limits.check_alloc("PCA mean row", n as u64, 4)?;
    let mean: Vec<f32> = mean_bytes
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes")))
        .collect();
    if let Some(i) = mean
        .iter()
        .position(|v| !v.is_finite() || v.abs() > crate::eigen::MAX_SCALE)
    {
        return Err(Error::corrupt(
            "PCAM chunk",
            format!(
                "mean value {i} is {} (valid: finite, at most 2^100)",
                mean[i]
            ),
        ));
    }
    // The model also keeps the basis in f64.
    let _basis = limits.check_alloc("PCA basis", (k * n) as u64, 8)?;
    let basis = QuantizedMatrix::decode(
        get(b"PCAB")?,
        "PCAB chunk",
        (k, n, dims.channels as usize),
        meta.bits,
        limits,
    )?;
    let coefficients =
        QuantizedMatrix::decode(get(b"PCAC")?, "PCAC chunk", (k, p, 1), meta.bits, limits)?;
    PcaModel::new(dims, mean, basis, coefficients)
}

/// Writes a `pca` file (version 2): META, ALBD, EMPT (when it has a row),
/// SURF (each when given), PCAM, PCAB, PCAC, atomically. Returns the file
/// size.
pub(crate) fn write_pca_file(
    path: &Path,
    meta: Meta,
    albedo: Option<&[f32]>,
    surface: Option<&Surface>,
    empty_rows: Option<&EmptyRows>,
    model: &PcaModel,
    zstd_level: i32,
) -> Result<u64> {
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
    let mean: Vec<u8> = model.mean().iter().flat_map(|v| v.to_le_bytes()).collect();
    chunks.push((*b"PCAM", mean));
    chunks.push((*b"PCAB", model.basis().encode(zstd_level)?));
    chunks.push((*b"PCAC", model.coefficients().encode(zstd_level)?));
    let head_len = HEADER_LEN + DIR_ENTRY_LEN * chunks.len() + 4;
    let mut dir = Vec::new();
    let mut offset = head_len as u64;
    for (tag, bytes) in &chunks {
        dir.push(DirEntry {
            tag: *tag,
            offset,
            len: bytes.len() as u64,
            crc: crc32fast::hash(bytes),
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

/// The header and chunk directory with its CRC.
fn encode_head(features: u32, dir: &[DirEntry]) -> Vec<u8> {
    let mut head = Writer::default();
    head.bytes.extend_from_slice(&MAGIC);
    head.u32(VERSION);
    head.u32(features);
    head.u32(dir.len() as u32);
    head.u32(0);
    for d in dir {
        head.bytes.extend_from_slice(&d.tag);
        head.u32(0);
        head.u64(d.offset);
        head.u64(d.len);
        head.u32(d.crc);
        head.u32(0);
    }
    let crc = crc32fast::hash(&head.bytes);
    head.u32(crc);
    head.bytes
}
