//! A small PLY reader: `format ascii 1.0` and `format binary_little_endian
//! 1.0`, all scalar types, list properties, any elements (those other than
//! `vertex` and `face` are read and skipped). It takes `vertex` properties
//! `x, y, z` (and `nx, ny, nz` when all three are present; texture
//! coordinates from the first pair present of `s, t`, `u, v`,
//! `texture_u, texture_v` and `texture_s, texture_t`) and the `face`
//! list `vertex_indices` (or `vertex_index`); polygons are fanned into
//! triangles.
//!
//! Errors are strings naming the header line or the element and index where
//! the file went wrong; the caller adds the path.

use crate::mesh::RawMesh;

#[derive(Clone, Copy, Debug, PartialEq)]
enum Ty {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Ty {
    fn parse(s: &str) -> Option<Ty> {
        Some(match s {
            "char" | "int8" => Ty::I8,
            "uchar" | "uint8" => Ty::U8,
            "short" | "int16" => Ty::I16,
            "ushort" | "uint16" => Ty::U16,
            "int" | "int32" => Ty::I32,
            "uint" | "uint32" => Ty::U32,
            "float" | "float32" => Ty::F32,
            "double" | "float64" => Ty::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Ty::I8 | Ty::U8 => 1,
            Ty::I16 | Ty::U16 => 2,
            Ty::I32 | Ty::U32 | Ty::F32 => 4,
            Ty::F64 => 8,
        }
    }

    fn is_int(self) -> bool {
        !matches!(self, Ty::F32 | Ty::F64)
    }
}

#[derive(Debug)]
enum Prop {
    Scalar { name: String, ty: Ty },
    List { name: String, count: Ty, item: Ty },
}

#[derive(Debug)]
struct Element {
    name: String,
    count: usize,
    props: Vec<Prop>,
}

impl Element {
    /// Smallest encoded size of one instance in binary (lists empty).
    fn min_binary_size(&self) -> usize {
        self.props
            .iter()
            .map(|p| match p {
                Prop::Scalar { ty, .. } => ty.size(),
                Prop::List { count, .. } => count.size(),
            })
            .sum()
    }
}

/// Longest header accepted, in bytes.
const MAX_HEADER: usize = 1 << 20;
/// Largest polygon accepted (vertices per face).
const MAX_POLYGON: usize = 1 << 16;

/// Parses a PLY file held in memory.
pub(crate) fn parse(bytes: &[u8]) -> Result<RawMesh, String> {
    let (elements, binary, body) = parse_header(bytes)?;
    let mut reader: Box<dyn Scalars> = if binary {
        Box::new(Binary {
            bytes: body,
            pos: 0,
        })
    } else {
        let text = std::str::from_utf8(body)
            .map_err(|e| format!("the ASCII body is not valid text ({e})"))?;
        Box::new(Ascii {
            tokens: text.split_ascii_whitespace(),
            remaining_bytes: body.len(),
        })
    };
    let mut mesh = RawMesh::default();
    let mut vertex_seen = false;
    let mut face_seen = false;
    for el in &elements {
        if el.props.is_empty() && el.name != "vertex" && el.name != "face" {
            continue;
        }
        check_count(el, binary, reader.as_ref())?;
        match el.name.as_str() {
            "vertex" => {
                vertex_seen = true;
                read_vertices(el, reader.as_mut(), &mut mesh)?;
            }
            "face" => {
                face_seen = true;
                read_faces(el, reader.as_mut(), &mut mesh)?;
            }
            _ => skip_element(el, reader.as_mut())?,
        }
    }
    if !vertex_seen {
        return Err("the header declares no vertex element".into());
    }
    if !face_seen {
        return Err("the header declares no face element (point clouds cannot be baked)".into());
    }
    Ok(mesh)
}

/// Refuses counts the remaining bytes cannot hold (truncation, or a header
/// lying about its size) before anything is allocated for them.
fn check_count(el: &Element, binary: bool, reader: &dyn Scalars) -> Result<(), String> {
    let min = if binary {
        el.min_binary_size().max(1)
    } else {
        (2 * el.props.len()).max(1)
    };
    if el.count > (reader.remaining() + 1) / min {
        return Err(format!(
            "truncated: the header declares {} {} elements, but only {} bytes follow",
            el.count,
            el.name,
            reader.remaining()
        ));
    }
    Ok(())
}

/// Reads a list's length and skips its items.
fn skip_list(
    reader: &mut dyn Scalars,
    count: Ty,
    item: Ty,
    at: &dyn Fn() -> String,
) -> Result<(), String> {
    let n = list_len(reader.scalar(count, at)?, at)?;
    for _ in 0..n {
        reader.scalar(item, at)?;
    }
    Ok(())
}

/// The `vertex` element: positions, and normals and texture coordinates
/// when the element has them.
fn read_vertices(el: &Element, reader: &mut dyn Scalars, mesh: &mut RawMesh) -> Result<(), String> {
    let idx = |n: &str| {
        el.props
            .iter()
            .position(|p| matches!(p, Prop::Scalar { name, .. } if name == n))
    };
    let (Some(ix), Some(iy), Some(iz)) = (idx("x"), idx("y"), idx("z")) else {
        return Err("element vertex lacks a scalar x, y or z property".into());
    };
    let normals = match (idx("nx"), idx("ny"), idx("nz")) {
        (Some(a), Some(b), Some(c)) => Some([a, b, c]),
        _ => None,
    };
    let uv = [
        ("s", "t"),
        ("u", "v"),
        ("texture_u", "texture_v"),
        ("texture_s", "texture_t"),
    ]
    .iter()
    .find_map(|(a, b)| Some([idx(a)?, idx(b)?]));
    let mut uvs = Vec::with_capacity(if uv.is_some() { el.count } else { 0 });
    mesh.positions.reserve(el.count);
    let mut vals = vec![0.0f64; el.props.len()];
    let mut ns = Vec::with_capacity(if normals.is_some() { el.count } else { 0 });
    for i in 0..el.count {
        for (k, p) in el.props.iter().enumerate() {
            let at = || format!("vertex {i} of {}", el.count);
            match p {
                Prop::Scalar { ty, .. } => vals[k] = reader.scalar(*ty, &at)?,
                Prop::List { count, item, .. } => skip_list(reader, *count, *item, &at)?,
            }
        }
        mesh.positions
            .push([vals[ix] as f32, vals[iy] as f32, vals[iz] as f32]);
        if let Some([a, b, c]) = normals {
            ns.push([vals[a] as f32, vals[b] as f32, vals[c] as f32]);
        }
        if let Some([a, b]) = uv {
            uvs.push([vals[a] as f32, vals[b] as f32]);
        }
    }
    if normals.is_some() {
        mesh.normals = Some(ns);
    }
    if uv.is_some() {
        mesh.uvs = Some(uvs);
    }
    Ok(())
}

/// The `face` element: each polygon of `vertex_indices` fanned into
/// triangles.
fn read_faces(el: &Element, reader: &mut dyn Scalars, mesh: &mut RawMesh) -> Result<(), String> {
    let Some(li) = el.props.iter().position(|p| {
        matches!(p, Prop::List { name, .. } if name == "vertex_indices" || name == "vertex_index")
    }) else {
        return Err("element face lacks a list property vertex_indices (or vertex_index)".into());
    };
    mesh.triangles.reserve(el.count);
    let mut polygon: Vec<f64> = Vec::new();
    for i in 0..el.count {
        let at = || format!("face {i} of {}", el.count);
        for (k, p) in el.props.iter().enumerate() {
            match p {
                Prop::Scalar { ty, .. } => {
                    reader.scalar(*ty, &at)?;
                }
                Prop::List { count, item, .. } if k != li => skip_list(reader, *count, *item, &at)?,
                Prop::List { count, item, .. } => {
                    read_polygon(reader, (*count, *item), &at, &mut polygon)?;
                    fan(&polygon, &at, &mut mesh.triangles)?;
                }
            }
        }
    }
    Ok(())
}

/// Reads one polygon's vertex indices (at least 3, stored as integers).
fn read_polygon(
    reader: &mut dyn Scalars,
    (count, item): (Ty, Ty),
    at: &dyn Fn() -> String,
    polygon: &mut Vec<f64>,
) -> Result<(), String> {
    let n = list_len(reader.scalar(count, at)?, at)?;
    if !item.is_int() {
        return Err(format!(
            "{}: vertex indices are stored as floating point",
            at()
        ));
    }
    if n < 3 {
        return Err(format!(
            "{}: a face has {n} vertices, at least 3 are needed",
            at()
        ));
    }
    polygon.clear();
    for _ in 0..n {
        polygon.push(reader.scalar(item, at)?);
    }
    Ok(())
}

/// Fans a polygon into triangles `(0, 1, 2), (0, 2, 3), …`.
fn fan(
    polygon: &[f64],
    at: &dyn Fn() -> String,
    triangles: &mut Vec<[u32; 3]>,
) -> Result<(), String> {
    let mut ids = [0u32; 3];
    for (slot, &v) in ids.iter_mut().zip(&polygon[..3]) {
        *slot = index(v, at)?;
    }
    triangles.push(ids);
    for &v in &polygon[3..] {
        ids[1] = ids[2];
        ids[2] = index(v, at)?;
        triangles.push(ids);
    }
    Ok(())
}

/// Reads and drops every instance of an element other than `vertex` and
/// `face`.
fn skip_element(el: &Element, reader: &mut dyn Scalars) -> Result<(), String> {
    for i in 0..el.count {
        let at = || format!("element {} {i} of {}", el.name, el.count);
        for p in &el.props {
            match p {
                Prop::Scalar { ty, .. } => {
                    reader.scalar(*ty, &at)?;
                }
                Prop::List { count, item, .. } => skip_list(reader, *count, *item, &at)?,
            }
        }
    }
    Ok(())
}

fn list_len(v: f64, at: &dyn Fn() -> String) -> Result<usize, String> {
    if v < 0.0 || v > MAX_POLYGON as f64 || v.fract() != 0.0 {
        return Err(format!(
            "{}: list length {v} is out of range (valid: 0..={MAX_POLYGON})",
            at()
        ));
    }
    Ok(v as usize)
}

fn index(v: f64, at: &dyn Fn() -> String) -> Result<u32, String> {
    if v < 0.0 || v >= u32::MAX as f64 || v.fract() != 0.0 {
        return Err(format!(
            "{}: vertex index {v} is negative or too large",
            at()
        ));
    }
    Ok(v as u32)
}

fn parse_header(bytes: &[u8]) -> Result<(Vec<Element>, bool, &[u8]), String> {
    let (lines, pos) = header_lines(bytes)?;
    let mut binary = None;
    let mut elements: Vec<Element> = Vec::new();
    for (i, line) in lines.iter().enumerate().skip(1) {
        let ln = i + 1;
        let w: Vec<&str> = line.split_whitespace().collect();
        match w.first().copied() {
            None | Some("comment") | Some("obj_info") => {}
            Some("format") => binary = Some(format_line(&w, ln, line)?),
            Some("element") => elements.push(element_line(&w, ln, line)?),
            Some("property") => {
                let Some(el) = elements.last_mut() else {
                    return Err(format!(
                        "header line {ln}: property before any element"
                    ));
                };
                el.props.push(property_line(&w, ln, line)?);
            }
            Some(other) => {
                return Err(format!(
                    "header line {ln}: unknown keyword \"{other}\" (valid: format, element, property, comment, obj_info, end_header)"
                ))
            }
        }
    }
    let Some(binary) = binary else {
        return Err("the header has no format line".into());
    };
    Ok((elements, binary, &bytes[pos..]))
}

/// The header's lines up to `end_header`, and the offset of the body.
fn header_lines(bytes: &[u8]) -> Result<(Vec<String>, usize), String> {
    if !bytes.starts_with(b"ply\n") && !bytes.starts_with(b"ply\r\n") {
        return Err("does not start with the line \"ply\"".into());
    }
    let mut pos = 0;
    let mut lines = Vec::new();
    loop {
        let Some(nl) = bytes[pos..].iter().position(|&b| b == b'\n') else {
            return Err("the header has no end_header line".into());
        };
        let line = &bytes[pos..pos + nl];
        pos += nl + 1;
        if pos > MAX_HEADER {
            return Err(format!(
                "the header is longer than {MAX_HEADER} bytes (no end_header line?)"
            ));
        }
        let line = std::str::from_utf8(line)
            .map_err(|_| format!("header line {} is not text", lines.len() + 1))?
            .trim_end_matches('\r');
        if line.trim() == "end_header" {
            return Ok((lines, pos));
        }
        lines.push(line.to_string());
    }
}

/// `format ascii 1.0` (false) or `format binary_little_endian 1.0` (true).
fn format_line(w: &[&str], ln: usize, line: &str) -> Result<bool, String> {
    match (w.get(1).copied(), w.get(2).copied()) {
        (Some("ascii"), Some("1.0")) => Ok(false),
        (Some("binary_little_endian"), Some("1.0")) => Ok(true),
        (Some("binary_big_endian"), _) => Err(
            "binary_big_endian PLY is not supported (valid: ascii 1.0, binary_little_endian 1.0)"
                .into(),
        ),
        _ => Err(format!(
            "header line {ln}: unknown format \"{line}\" (valid: ascii 1.0, binary_little_endian 1.0)"
        )),
    }
}

/// `element NAME COUNT`.
fn element_line(w: &[&str], ln: usize, line: &str) -> Result<Element, String> {
    let (Some(name), Some(count), None) = (w.get(1), w.get(2), w.get(3)) else {
        return Err(format!(
            "header line {ln}: expected \"element NAME COUNT\", found \"{line}\""
        ));
    };
    let count = count.parse::<usize>().map_err(|_| {
        format!("header line {ln}: element count \"{count}\" is not a non-negative integer")
    })?;
    Ok(Element {
        name: name.to_string(),
        count,
        props: Vec::new(),
    })
}

/// `property TYPE NAME` or `property list COUNT_TYPE ITEM_TYPE NAME`.
fn property_line(w: &[&str], ln: usize, line: &str) -> Result<Prop, String> {
    let bad = || {
        format!("header line {ln}: expected \"property TYPE NAME\" or \"property list COUNT_TYPE ITEM_TYPE NAME\" with types char, uchar, short, ushort, int, uint, float, double; found \"{line}\"")
    };
    if w.get(1) == Some(&"list") {
        let (Some(c), Some(t), Some(n), None) = (w.get(2), w.get(3), w.get(4), w.get(5)) else {
            return Err(bad());
        };
        let count = Ty::parse(c).ok_or_else(bad)?;
        if !count.is_int() {
            return Err(bad());
        }
        Ok(Prop::List {
            name: n.to_string(),
            count,
            item: Ty::parse(t).ok_or_else(bad)?,
        })
    } else {
        let (Some(t), Some(n), None) = (w.get(1), w.get(2), w.get(3)) else {
            return Err(bad());
        };
        Ok(Prop::Scalar {
            name: n.to_string(),
            ty: Ty::parse(t).ok_or_else(bad)?,
        })
    }
}

/// A source of scalar values (ASCII tokens or little-endian binary).
trait Scalars {
    fn scalar(&mut self, ty: Ty, at: &dyn Fn() -> String) -> Result<f64, String>;
    /// Bytes left, an upper bound on what can still be read.
    fn remaining(&self) -> usize;
}

struct Binary<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl Scalars for Binary<'_> {
    fn scalar(&mut self, ty: Ty, at: &dyn Fn() -> String) -> Result<f64, String> {
        let n = ty.size();
        let Some(b) = self.bytes.get(self.pos..self.pos + n) else {
            return Err(format!(
                "truncated: {} ends past the end of the file ({} bytes of data)",
                at(),
                self.bytes.len()
            ));
        };
        self.pos += n;
        let mut a = [0u8; 8];
        a[..n].copy_from_slice(b);
        Ok(match ty {
            Ty::I8 => a[0] as i8 as f64,
            Ty::U8 => a[0] as f64,
            Ty::I16 => i16::from_le_bytes([a[0], a[1]]) as f64,
            Ty::U16 => u16::from_le_bytes([a[0], a[1]]) as f64,
            Ty::I32 => i32::from_le_bytes([a[0], a[1], a[2], a[3]]) as f64,
            Ty::U32 => u32::from_le_bytes([a[0], a[1], a[2], a[3]]) as f64,
            Ty::F32 => f32::from_le_bytes([a[0], a[1], a[2], a[3]]) as f64,
            Ty::F64 => f64::from_le_bytes(a),
        })
    }

    fn remaining(&self) -> usize {
        self.bytes.len() - self.pos
    }
}

struct Ascii<'a> {
    tokens: std::str::SplitAsciiWhitespace<'a>,
    remaining_bytes: usize,
}

impl Scalars for Ascii<'_> {
    fn scalar(&mut self, ty: Ty, at: &dyn Fn() -> String) -> Result<f64, String> {
        let Some(tok) = self.tokens.next() else {
            return Err(format!("unexpected end of file in {}", at()));
        };
        self.remaining_bytes = self.remaining_bytes.saturating_sub(tok.len() + 1);
        let v: f64 = tok
            .parse()
            .map_err(|_| format!("{}: \"{tok}\" is not a number", at()))?;
        if ty.is_int() && (v.fract() != 0.0 || !v.is_finite()) {
            return Err(format!("{}: \"{tok}\" is not an integer", at()));
        }
        Ok(v)
    }

    fn remaining(&self) -> usize {
        self.remaining_bytes
    }
}
