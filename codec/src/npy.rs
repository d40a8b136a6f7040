//! NumPy `.npy` import into the raw store, and dense export of a decoded
//! `.ltm` file, so that anyone can check the codec with numpy.

use crate::container::LtmFile;
use crate::decode::ColumnDecoder;
use crate::dims::Dims;
use crate::error::{Error, Result};
use crate::fileio::Stamp;
use crate::limits::{Charge, Limits};
use crate::output::AtomicFile;
use crate::progress::{Progress, Stage};
use crate::raw::{RawHeader, RawWriter};
use crate::wavelet::row_inverse;
use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Write};
use std::path::Path;

const NPY_MAGIC: &[u8; 6] = b"\x93NUMPY";

/// Element type of an `.npy` array.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum NpyDtype {
    /// Little-endian float32 (`<f4`).
    F32,
    /// Little-endian float64 (`<f8`).
    F64,
}

/// The header of an `.npy` file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NpyHeader {
    /// Element type.
    pub dtype: NpyDtype,
    /// Array shape, C order.
    pub shape: Vec<usize>,
    /// Bytes before the data.
    pub data_offset: usize,
}

/// Parses an `.npy` header (format versions 1–3). The header dictionary is
/// parsed strictly ([`parse_header_dict`]): what numpy writes is accepted,
/// anything else is an error.
pub fn read_npy_header(r: &mut impl Read) -> Result<NpyHeader> {
    let bad = |d: String| Error::Invalid(format!("not a readable .npy file: {d}"));
    let short = |part: &str, e: std::io::Error| {
        if e.kind() == std::io::ErrorKind::UnexpectedEof {
            bad(format!("the file ends inside its {part} (truncated)"))
        } else {
            bad(e.to_string())
        }
    };
    let mut pre = [0u8; 8];
    r.read_exact(&mut pre)
        .map_err(|e| short("8-byte preamble", e))?;
    if &pre[..6] != NPY_MAGIC {
        return Err(bad("missing \\x93NUMPY magic".into()));
    }
    let (len, prefix) = match pre[6] {
        1 => {
            let mut b = [0u8; 2];
            r.read_exact(&mut b)
                .map_err(|e| short("header length", e))?;
            (u16::from_le_bytes(b) as usize, 10)
        }
        2 | 3 => {
            let mut b = [0u8; 4];
            r.read_exact(&mut b)
                .map_err(|e| short("header length", e))?;
            (u32::from_le_bytes(b) as usize, 12)
        }
        v => return Err(bad(format!("format version {v} (supported: 1, 2, 3)"))),
    };
    if len > 1 << 16 {
        return Err(bad(format!("header length {len} (valid: at most 65536)")));
    }
    let mut text = vec![0u8; len];
    r.read_exact(&mut text)
        .map_err(|e| short(&format!("{len}-byte header"), e))?;
    let dict = std::str::from_utf8(&text)
        .map_err(|_| bad("the header dictionary is not UTF-8 text".into()))?;
    let (dtype, shape) = parse_header_dict(dict)?;
    Ok(NpyHeader {
        dtype,
        shape,
        data_offset: prefix + len,
    })
}

/// Parses the header dictionary numpy writes, e.g.
/// `{'descr': '<f4', 'fortran_order': False, 'shape': (4, 24), }`: exactly
/// the keys `descr`, `fortran_order` and `shape`, each once, in any order,
/// with single- or double-quoted strings, then spaces and a newline.
pub fn parse_header_dict(dict: &str) -> Result<(NpyDtype, Vec<usize>)> {
    let mut p = DictParser {
        s: dict.as_bytes(),
        at: 0,
    };
    let (mut descr, mut fortran, mut shape) = (None, None, None);
    p.expect(b'{')?;
    loop {
        if p.eat(b'}') {
            break;
        }
        let key = p.string()?;
        p.expect(b':')?;
        let dup = match key.as_str() {
            "descr" => descr.replace(p.string()?).is_some(),
            "fortran_order" => fortran.replace(p.boolean()?).is_some(),
            "shape" => shape.replace(p.tuple()?).is_some(),
            _ => {
                return Err(p.error(&format!(
                    "unknown key '{key}' (valid: descr, fortran_order, shape)"
                )))
            }
        };
        if dup {
            return Err(p.error(&format!("key '{key}' appears more than once")));
        }
        if !p.eat(b',') {
            p.expect(b'}')?;
            break;
        }
    }
    p.skip_space();
    if p.at != p.s.len() {
        return Err(p.error("text after the dictionary"));
    }
    let missing = |k: &str| Error::Invalid(format!(".npy header has no '{k}' field: {dict}"));
    let descr = descr.ok_or_else(|| missing("descr"))?;
    let dtype = match descr.as_str() {
        "<f4" => NpyDtype::F32,
        "<f8" => NpyDtype::F64,
        other => {
            return Err(Error::Invalid(format!(
                "unsupported .npy dtype '{other}' (supported: float32 '<f4', float64 '<f8')"
            )))
        }
    };
    if fortran.ok_or_else(|| missing("fortran_order"))? {
        return Err(Error::Invalid(
            "Fortran-ordered .npy arrays are not supported: save with C order".into(),
        ));
    }
    Ok((dtype, shape.ok_or_else(|| missing("shape"))?))
}

/// A cursor over a header dictionary's bytes.
struct DictParser<'a> {
    s: &'a [u8],
    at: usize,
}

impl DictParser<'_> {
    fn error(&self, what: &str) -> Error {
        Error::Invalid(format!(
            "malformed .npy header at byte {}: {what} (header: {})",
            self.at,
            String::from_utf8_lossy(self.s).trim_end()
        ))
    }

    fn skip_space(&mut self) {
        while self
            .s
            .get(self.at)
            .is_some_and(|c| matches!(c, b' ' | b'\t' | b'\n' | b'\r'))
        {
            self.at += 1;
        }
    }

    /// Skips spaces, then consumes `c` if it is next.
    fn eat(&mut self, c: u8) -> bool {
        self.skip_space();
        let found = self.s.get(self.at) == Some(&c);
        self.at += found as usize;
        found
    }

    fn expect(&mut self, c: u8) -> Result<()> {
        if self.eat(c) {
            Ok(())
        } else {
            Err(self.error(&format!("expected '{}'", c as char)))
        }
    }

    /// A string in single or double quotes, without escapes.
    fn string(&mut self) -> Result<String> {
        self.skip_space();
        let quote = match self.s.get(self.at) {
            Some(&q @ (b'\'' | b'"')) => q,
            _ => return Err(self.error("expected a quoted string")),
        };
        let start = self.at + 1;
        let len = self.s[start..]
            .iter()
            .position(|&c| c == quote)
            .ok_or_else(|| self.error("unterminated string"))?;
        let text = &self.s[start..start + len];
        if text.contains(&b'\\') {
            return Err(self.error("escapes in strings are not supported"));
        }
        self.at = start + len + 1;
        Ok(String::from_utf8_lossy(text).into_owned())
    }

    fn boolean(&mut self) -> Result<bool> {
        self.skip_space();
        for (word, value) in [(&b"True"[..], true), (&b"False"[..], false)] {
            if self.s[self.at..].starts_with(word) {
                self.at += word.len();
                return Ok(value);
            }
        }
        Err(self.error("expected True or False"))
    }

    /// A tuple of non-negative integers: `()`, `(5,)`, `(3, 4)`, `(3, 4, 2)`.
    fn tuple(&mut self) -> Result<Vec<usize>> {
        self.expect(b'(')?;
        let mut dims = Vec::new();
        loop {
            if self.eat(b')') {
                break;
            }
            dims.push(self.integer()?);
            if !self.eat(b',') {
                self.expect(b')')?;
                if dims.len() == 1 {
                    return Err(self.error("a one-element shape needs a trailing comma"));
                }
                break;
            }
        }
        Ok(dims)
    }

    fn integer(&mut self) -> Result<usize> {
        self.skip_space();
        let digits = self.s[self.at..]
            .iter()
            .take_while(|c| c.is_ascii_digit())
            .count();
        if digits == 0 {
            return Err(self.error("expected a non-negative integer"));
        }
        let text = std::str::from_utf8(&self.s[self.at..self.at + digits]).unwrap_or("");
        let value = text
            .parse::<usize>()
            .map_err(|_| self.error(&format!("dimension {text} is too large")))?;
        self.at += digits;
        Ok(value)
    }
}

/// Imports a `(P, M)` or `(P, M, C)` `.npy` matrix as a raw store,
/// reporting ([`Stage::Import`], blocks written, blocks).
/// On failure nothing is left behind.
pub fn import_npy(
    npy: &Path,
    width: u32,
    height: u32,
    out: &Path,
    progress: Progress<'_>,
) -> Result<Dims> {
    import_npy_inner(npy, width, height, out, progress)
}

fn import_npy_inner(
    npy: &Path,
    width: u32,
    height: u32,
    out: &Path,
    progress: Progress<'_>,
) -> Result<Dims> {
    let file = File::open(npy).map_err(|e| Error::io(npy, e))?;
    // Checked again before the output is finished: an array rewritten
    // during the import is an error, not a mix of two arrays.
    let stamp = Stamp::of(&file, npy)?;
    let file_len = stamp.len;
    let mut r = BufReader::with_capacity(1 << 20, file);
    let header = read_npy_header(&mut r)?;
    let (rows, cols, channels) = match header.shape[..] {
        [p, m] => (p, m, 1),
        [p, m, c] => (p, m, c),
        _ => {
            return Err(Error::Invalid(format!(
                "array shape {:?}: expected (P, M) or (P, M, C)",
                header.shape
            )))
        }
    };
    if rows as u64 != width as u64 * height as u64 {
        return Err(Error::Invalid(format!(
            "array has {rows} rows but --width {width} × --height {height} = {}",
            width as u64 * height as u64
        )));
    }
    let n = ((cols / 6) as f64).sqrt().round() as u32;
    if cols == 0 || 6 * (n as usize) * (n as usize) != cols {
        return Err(Error::Invalid(format!(
            "array has {cols} columns: expected 6·n² cubemap texels (n a power of two)"
        )));
    }
    if channels != 1 && channels != 3 {
        return Err(Error::range(
            "array channels (third dimension)",
            channels,
            "1 or 3",
        ));
    }
    let dims = Dims::image(width, height, n, channels as u32);
    dims.validate()?;
    let item = if header.dtype == NpyDtype::F32 { 4 } else { 8 };
    let need = header.data_offset as u64 + dims.raw_bytes() / 4 * item;
    if file_len != need {
        return Err(Error::Invalid(format!(
            "{}: file is {file_len} bytes, shape {:?} needs {need}",
            npy.display(),
            header.shape
        )));
    }
    let raw = RawHeader::new(dims, false, 16 << 20);
    let mut writer = RawWriter::create(out, raw)?;
    // An import is never resumed: a failed one leaves nothing.
    writer.discard_on_drop();
    let row_len = dims.row_len();
    let mut bytes = Vec::new();
    let blocks = raw.block_count();
    for b in 0..blocks {
        let range = raw.block_range(b);
        bytes.resize(range.len() * row_len * item as usize, 0);
        r.read_exact(&mut bytes).map_err(|e| {
            if e.kind() != std::io::ErrorKind::UnexpectedEof {
                return Error::io(npy, e);
            }
            let why = format!("the file ends before the {need} bytes its header implies: it was truncated while being read");
            Error::io(npy, std::io::Error::new(e.kind(), why))
        })?;
        let values: Vec<f32> = if item == 4 {
            bytes
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes")))
                .collect()
        } else {
            bytes
                .chunks_exact(8)
                .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")) as f32)
                .collect()
        };
        if let Some(k) = values.iter().position(|v| !v.is_finite()) {
            let e = range.start * row_len + k;
            return Err(Error::Invalid(format!(
                "{}: element ({}, {}, {}) is {} (NaN, infinite, or beyond float32)",
                npy.display(),
                e / row_len,
                e % row_len / channels,
                e % channels,
                values[k]
            )));
        }
        writer.write_block(b, &values, None)?;
        progress.report(Stage::Import, (b + 1) as u64, blocks as u64);
    }
    stamp.check_unchanged(r.get_ref(), npy)?;
    writer.finish()?;
    Ok(dims)
}

/// Decodes a whole `.ltm` file to the pixel lighting basis: `P × M × C`
/// values, C order. The dense matrix must fit `limits`.
pub fn decode_matrix(file: &LtmFile, limits: &Limits) -> Result<Vec<f32>> {
    decode_matrix_charged(file, limits).map(|(dense, _charge)| dense)
}

/// [`decode_matrix`], with the dense matrix's charge to `limits`.
fn decode_matrix_charged(file: &LtmFile, limits: &Limits) -> Result<(Vec<f32>, Charge)> {
    let meta = file.meta();
    let dims = meta.dims;
    let values = usize::try_from(dims.raw_bytes() / 4).unwrap_or(usize::MAX);
    if let Some(model) = file.pca() {
        // Reconstructed in f64 in blocks of rows, rounded to f32.
        let n = dims.row_len();
        let (mut dense, charge) = limits.vec("dense decoded matrix", values, 0.0f32)?;
        dense.clear();
        let mut block = Vec::new();
        let step = ((1usize << 22) / n).max(1);
        for first in (0..dims.pixels()).step_by(step) {
            let count = step.min(dims.pixels() - first);
            model.reconstruct_rows(first, count, &mut block)?;
            dense.extend(block.iter().map(|&v| v as f32));
        }
        if let Some(i) = dense.iter().position(|v| !v.is_finite()) {
            return Err(Error::corrupt(
                "PCA file",
                format!("decoded value {i} exceeds the f32 range"),
            ));
        }
        return Ok((dense, charge));
    }
    let (p, m, c) = (dims.pixels(), dims.lights(), dims.channels as usize);
    let n = dims.face_res() as usize;
    let decoder = ColumnDecoder::for_file(file, limits)?;
    let (mut dense, charge) = limits.vec("dense decoded matrix", values, 0.0f32)?;
    let (mut plane, _plane) = limits.vec("export column plane", p, 0.0f32)?;
    let (mut work, _work) = limits.vec("export work plane", p.max(n * n), 0.0f32)?;
    for j in 0..m {
        let col = file.column(j)?;
        for ch in 0..c {
            decoder.decode(&col, ch, &mut plane, &mut work)?;
            for (pi, v) in plane.iter().enumerate() {
                dense[(pi * m + j) * c + ch] = *v;
            }
        }
    }
    let mut row = vec![0.0f32; m];
    for pi in 0..p {
        for ch in 0..c {
            for j in 0..m {
                row[j] = dense[(pi * m + j) * c + ch];
            }
            row_inverse(meta.row_filter, n, &mut row, &mut work)?;
            for j in 0..m {
                dense[(pi * m + j) * c + ch] = row[j];
            }
        }
    }
    Ok((dense, charge))
}

/// Writes the decoded matrix as a float32 `.npy` of shape `(P, M)` or
/// `(P, M, C)`, atomically. The dense matrix must fit `limits`.
pub fn export_npy(file: &LtmFile, out: &Path, limits: &Limits) -> Result<()> {
    let dims = file.meta().dims;
    let (dense, _charge) = decode_matrix_charged(file, limits)?;
    let shape = if dims.channels == 1 {
        format!("({}, {})", dims.pixels(), dims.lights())
    } else {
        format!("({}, {}, {})", dims.pixels(), dims.lights(), dims.channels)
    };
    let mut dict = format!("{{'descr': '<f4', 'fortran_order': False, 'shape': {shape}, }}");
    while (10 + dict.len() + 1) % 64 != 0 {
        dict.push(' ');
    }
    dict.push('\n');
    let file = AtomicFile::create(out)?;
    let tmp = file.tmp_path().to_path_buf();
    let io = |e| Error::io(&tmp, e);
    let mut w = BufWriter::new(file);
    w.write_all(NPY_MAGIC).map_err(io)?;
    w.write_all(&[1, 0]).map_err(io)?;
    w.write_all(&(dict.len() as u16).to_le_bytes())
        .map_err(io)?;
    w.write_all(dict.as_bytes()).map_err(io)?;
    w.write_all(bytemuck::cast_slice(&dense)).map_err(io)?;
    w.into_inner()
        .map_err(|e| Error::io(&tmp, e.into_error()))?
        .commit()
}
