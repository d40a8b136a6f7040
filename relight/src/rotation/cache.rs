//! The rotation cache: a [`RotationSet`] as a file, reused across runs and
//! models (docs/FORMAT.md, "Rotation cache"). Little-endian throughout:
//!
//! ```text
//! magic "LTMROT\0\0", version u32 (1), n u32, normals u32,
//! supersample u32, threshold u32, index bytes u32 (2 or 4),
//! then per grid normal: scale f32, nonzeros u32, row offsets u32 × (M + 1),
//!   column indices (u16 or u32) × nonzeros, values i16 × nonzeros,
//! then CRC-32 (IEEE) u32 of every byte before it.
//! ```
//!
//! The reader checks the length and the CRC before anything else, then every
//! field against its valid range, and charges every buffer to the budget
//! before it is made: bad input is an error, never a panic.

use super::matrix::{Columns, RotationMatrix, QMAX};
use super::{RotationConfig, RotationSet};
use crate::error::{RelightError, Result};
use ltm_codec::{AtomicFile, Charge, Limits};
use std::io::{Read, Write};
use std::path::Path;

/// The file's first eight bytes.
pub const MAGIC: [u8; 8] = *b"LTMROT\0\0";
/// The version this build writes and reads.
pub const VERSION: u32 = 1;
/// Bytes of the header (magic to index bytes).
const HEADER: usize = 8 + 6 * 4;

fn bad(detail: impl Into<String>) -> RelightError {
    RelightError::InvalidRotationCache(detail.into())
}

/// How [`RotationSet::cached`] got its set.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum CacheUse {
    /// Read from the cache.
    Read,
    /// Built and written to a new cache file.
    Built,
    /// Built and written over a cache of other settings, or a damaged one.
    Replaced,
}

impl RotationSet {
    /// The set in the cache format.
    pub fn to_bytes(&self) -> Vec<u8> {
        let cfg = self.config();
        let wide = matches!(self.matrix(0).cols, Columns::U32(_));
        let mut out = MAGIC.to_vec();
        let head = [
            VERSION,
            cfg.n as u32,
            cfg.normals as u32,
            cfg.supersample as u32,
        ];
        for v in head
            .into_iter()
            .chain([u32::from(cfg.threshold), if wide { 4 } else { 2 }])
        {
            out.extend_from_slice(&v.to_le_bytes());
        }
        for mat in self.matrices() {
            out.extend_from_slice(&mat.scale.to_le_bytes());
            out.extend_from_slice(&(mat.values.len() as u32).to_le_bytes());
            mat.row_ptr
                .iter()
                .for_each(|r| out.extend_from_slice(&r.to_le_bytes()));
            match &mat.cols {
                Columns::U16(c) => c
                    .iter()
                    .for_each(|j| out.extend_from_slice(&j.to_le_bytes())),
                Columns::U32(c) => c
                    .iter()
                    .for_each(|j| out.extend_from_slice(&j.to_le_bytes())),
            }
            mat.values
                .iter()
                .for_each(|v| out.extend_from_slice(&v.to_le_bytes()));
        }
        let crc = crc32fast::hash(&out);
        out.extend_from_slice(&crc.to_le_bytes());
        out
    }

    /// Writes the cache file atomically (a temporary file renamed when
    /// complete).
    pub fn write(&self, path: &Path) -> Result<()> {
        // A cache: runs of the same settings share it (no lock).
        let mut file = AtomicFile::create_shared(path)?;
        let io = |e| RelightError::Io {
            path: path.to_path_buf(),
            error: e,
        };
        file.file().write_all(&self.to_bytes()).map_err(io)?;
        file.commit()?;
        Ok(())
    }

    /// Reads a cache file, its bytes charged to `limits` before they are
    /// read.
    pub fn read(path: &Path, limits: &Limits) -> Result<RotationSet> {
        let io = |e| RelightError::Io {
            path: path.to_path_buf(),
            error: e,
        };
        let file = std::fs::File::open(path).map_err(io)?;
        let len = file.metadata().map_err(io)?.len();
        let _charge = limits.check_alloc("rotation cache file", len, 1)?;
        let mut bytes = Vec::new();
        bytes
            .try_reserve_exact(len as usize)
            .map_err(|_| bad(format!("{len} bytes cannot be allocated")))?;
        file.take(len).read_to_end(&mut bytes).map_err(io)?;
        RotationSet::from_bytes(&bytes, limits)
    }

    /// The set of `cfg` through the cache file at `path`: read when the
    /// file holds that configuration, else built (in parallel) and written
    /// there atomically, replacing a cache of other settings or a damaged
    /// one. A file at `path` that is not a rotation cache (its first bytes
    /// are not the magic) is never replaced: that is an error.
    pub fn cached(
        cfg: RotationConfig,
        path: &Path,
        limits: &Limits,
    ) -> Result<(RotationSet, CacheUse)> {
        let outcome = match std::fs::File::open(path) {
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => CacheUse::Built,
            Err(error) => {
                return Err(RelightError::Io {
                    path: path.to_path_buf(),
                    error,
                })
            }
            Ok(mut file) => {
                let mut head = [0u8; 8];
                if file.read_exact(&mut head).is_err() || head != MAGIC {
                    return Err(RelightError::Invalid(format!(
                        "{} is not a rotation cache (its first bytes are not the magic); refusing to replace it",
                        path.display()
                    )));
                }
                match RotationSet::read(path, limits) {
                    Ok(set) if *set.config() == cfg => return Ok((set, CacheUse::Read)),
                    Ok(_) | Err(RelightError::InvalidRotationCache(_)) => CacheUse::Replaced,
                    Err(e) => return Err(e),
                }
            }
        };
        let set = RotationSet::build(cfg, limits)?;
        set.write(path)?;
        Ok((set, outcome))
    }

    /// Parses the cache format (see the module documentation).
    pub fn from_bytes(bytes: &[u8], limits: &Limits) -> Result<RotationSet> {
        if bytes.len() < HEADER + 4 {
            return Err(bad(format!(
                "{} bytes is shorter than the header",
                bytes.len()
            )));
        }
        if bytes[..8] != MAGIC {
            return Err(bad("not a rotation cache (wrong magic)"));
        }
        let (body, tail) = bytes.split_at(bytes.len() - 4);
        let stored = u32::from_le_bytes([tail[0], tail[1], tail[2], tail[3]]);
        if crc32fast::hash(body) != stored {
            return Err(bad("CRC mismatch"));
        }
        let mut r = Reader { bytes: body, at: 8 };
        let version = r.u32()?;
        if version != VERSION {
            return Err(RelightError::range(
                "rotation cache version",
                version,
                VERSION,
            ));
        }
        let cfg = RotationConfig {
            n: r.u32()? as usize,
            normals: r.u32()? as usize,
            supersample: r.u32()? as usize,
            threshold: u16::try_from(r.u32()?).map_err(|_| bad("threshold past 65535"))?,
        };
        cfg.validate()?;
        let wide = cfg.n * cfg.n > 1 << 16;
        let index = r.u32()?;
        if index != if wide { 4 } else { 2 } {
            return Err(RelightError::range(
                "rotation cache index bytes",
                index,
                if wide { 4 } else { 2 },
            ));
        }
        let mut matrices = Vec::new();
        let mut charge = Charge::default();
        for _ in 0..cfg.normals * cfg.normals {
            let (mat, c) = read_matrix(&mut r, &cfg, wide, limits)?;
            matrices.push(mat);
            charge = charge.join(c);
        }
        if r.at != body.len() {
            return Err(bad(format!(
                "{} bytes after the last matrix",
                body.len() - r.at
            )));
        }
        Ok(RotationSet::from_parts(cfg, matrices, charge))
    }
}

/// A bounds-checked little-endian cursor.
struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn take(&mut self, len: usize) -> Result<&[u8]> {
        let end = self.at.checked_add(len).filter(|&e| e <= self.bytes.len());
        let end =
            end.ok_or_else(|| bad(format!("truncated at byte {} (need {len} more)", self.at)))?;
        let s = &self.bytes[self.at..end];
        self.at = end;
        Ok(s)
    }

    fn u32(&mut self) -> Result<u32> {
        let b = self.take(4)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }
}

fn read_matrix(
    r: &mut Reader<'_>,
    cfg: &RotationConfig,
    wide: bool,
    limits: &Limits,
) -> Result<(RotationMatrix, Charge)> {
    let (rows, cols) = (cfg.m() * cfg.m(), cfg.n * cfg.n);
    let scale = f32::from_bits(r.u32()?);
    if !(scale.is_finite() && scale > 0.0) {
        return Err(RelightError::range(
            "rotation matrix scale",
            scale,
            "finite and > 0",
        ));
    }
    let nnz = r.u32()? as usize;
    if nnz > rows * cols {
        return Err(RelightError::range(
            "rotation matrix nonzeros",
            nnz,
            format!("0..={}", rows * cols),
        ));
    }
    let ib = if wide { 4 } else { 2 };
    // Every byte is in the (CRC-checked) input, so the sizes are bounded by
    // its length; the buffers are still charged before they are made.
    let need = 4 * (rows + 1) + (ib + 2) * nnz;
    let charge = limits.check_alloc("rotation matrix", need as u64, 1)?;
    let raw = r.take(4 * (rows + 1))?;
    let row_ptr: Vec<u32> = raw
        .chunks_exact(4)
        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    if row_ptr[0] != 0 || row_ptr[rows] as usize != nnz || row_ptr.windows(2).any(|w| w[0] > w[1]) {
        return Err(bad(
            "row offsets are not 0, increasing, ending at the nonzero count",
        ));
    }
    let raw = r.take(ib * nnz)?;
    let index: Vec<u32> = if wide {
        raw.chunks_exact(4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect()
    } else {
        raw.chunks_exact(2)
            .map(|b| u32::from(u16::from_le_bytes([b[0], b[1]])))
            .collect()
    };
    if let Some(j) = index.iter().find(|&&j| j as usize >= cols) {
        return Err(RelightError::range(
            "rotation matrix column",
            j,
            format!("0..{cols}"),
        ));
    }
    let unordered = row_ptr.windows(2).any(|w| {
        index[w[0] as usize..w[1] as usize]
            .windows(2)
            .any(|p| p[0] >= p[1])
    });
    if unordered {
        return Err(bad("column indices not increasing within a row"));
    }
    let raw = r.take(2 * nnz)?;
    let values: Vec<i16> = raw
        .chunks_exact(2)
        .map(|b| i16::from_le_bytes([b[0], b[1]]))
        .collect();
    if let Some(v) = values
        .iter()
        .find(|v| f64::from(v.unsigned_abs()) > QMAX || **v == 0)
    {
        return Err(RelightError::range(
            "rotation matrix value",
            v,
            "±1..=±32767",
        ));
    }
    let cols = if wide {
        Columns::U32(index)
    } else {
        Columns::U16(index.into_iter().map(|j| j as u16).collect())
    };
    Ok((
        RotationMatrix {
            row_ptr,
            cols,
            values,
            scale,
        },
        charge,
    ))
}
