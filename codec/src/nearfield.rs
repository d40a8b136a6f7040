//! Near-field rows: every row's transport over the expanded top face of a
//! light plane, the lighting basis of planar area lights (Sun and
//! Ramamoorthi 2009, §5.2.1). Layouts in docs/FORMAT.md ("Near-field
//! rows").
//!
//! [`PlaneBasis`] names the face: a plane (origin and two orthonormal
//! axes, lit side `x × y`), its resolution `order` and its side in tangent
//! units. The raw store holds each row's per-texel integrals over the face
//! as they are baked (`order²·C` values); the `.ltm` file holds their
//! standard 2D Haar coefficients ([`plane_coefficients`]), sparse, in
//! [`PlaneRows`] (chunk `NEAR`): every nonzero one (lossless), or rounded
//! to one step for a target error by [`PlaneRows::quantize`]
//! (`quantize.rs`).

use crate::bytes::{Reader, Writer};
use crate::error::{Error, Result};
use crate::limits::{Charge, Limits};
use crate::raw::RawStore;
use crate::wavelet::{self, Filter};

mod quantize;
pub use quantize::NearQuantization;

/// The largest face resolution stored (so that a coefficient's index fits
/// 16 bits).
pub const MAX_PLANE_ORDER: u32 = 256;
/// Bytes of an encoded [`PlaneBasis`].
pub const PLANE_BASIS_LEN: usize = 88;
/// How far from unit length and from orthogonal the stored axes may be.
const AXIS_TOLERANCE: f64 = 1e-9;

/// The expanded top face of a light plane: `order × order` texels over
/// tangent coordinates `v ∈ [−side/2, side/2]²`. A point at depth
/// `z = (x × y)·(point − origin) > 0` sees along texel `j = r·order + c`
/// (`c` along `x`, `r` along `y`) the plane position `(point − origin)`
/// projected onto the axes plus `z·v`.
#[derive(Clone, Copy, Debug)]
pub struct PlaneBasis {
    /// A point of the plane.
    pub origin: [f64; 3],
    /// The plane's unit `x` axis.
    pub x_axis: [f64; 3],
    /// The plane's unit `y` axis, orthogonal to `x_axis`.
    pub y_axis: [f64; 3],
    /// Texels per side: a power of two in `1..=`[`MAX_PLANE_ORDER`].
    pub order: u32,
    /// The face's side in tangent units, finite and in `(0, 1000]`.
    pub side: f64,
}

/// Bit-exact equality (so that a header holding a basis is `Eq`).
impl PartialEq for PlaneBasis {
    fn eq(&self, other: &PlaneBasis) -> bool {
        self.to_bytes() == other.to_bytes()
    }
}

impl Eq for PlaneBasis {}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

impl PlaneBasis {
    /// Texels of the face, `order²`.
    pub fn texels(&self) -> usize {
        (self.order as usize).pow(2)
    }

    /// The unit normal towards the lit side, `x × y`.
    pub fn normal(&self) -> [f64; 3] {
        let (x, y) = (self.x_axis, self.y_axis);
        [
            x[1] * y[2] - x[2] * y[1],
            x[2] * y[0] - x[0] * y[2],
            x[0] * y[1] - x[1] * y[0],
        ]
    }

    /// The depth of `point` in front of the plane (> 0 on the lit side)
    /// and its in-plane position `(x, y)`.
    pub fn locate(&self, point: [f64; 3]) -> (f64, [f64; 2]) {
        let d = [0, 1, 2].map(|k| point[k] - self.origin[k]);
        (
            dot(d, self.normal()),
            [dot(d, self.x_axis), dot(d, self.y_axis)],
        )
    }

    /// Refuses non-finite fields, axes that are not unit length or not
    /// orthogonal (within 1e-9), an order that is not a power of two in
    /// `1..=256` and a side outside `(0, 1000]`.
    pub fn validate(&self) -> Result<()> {
        let fields = [self.origin, self.x_axis, self.y_axis];
        if !fields.iter().flatten().all(|v| v.is_finite()) {
            return Err(Error::range("light plane", format!("{self:?}"), "finite"));
        }
        let unit = |a: [f64; 3]| (dot(a, a) - 1.0).abs() <= AXIS_TOLERANCE;
        if !unit(self.x_axis)
            || !unit(self.y_axis)
            || dot(self.x_axis, self.y_axis).abs() > AXIS_TOLERANCE
        {
            return Err(Error::range(
                "light plane axes",
                format!("{:?}, {:?}", self.x_axis, self.y_axis),
                "two orthogonal unit vectors (within 1e-9)",
            ));
        }
        if !self.order.is_power_of_two() || self.order > MAX_PLANE_ORDER {
            return Err(Error::range(
                "light plane order",
                self.order,
                format!("a power of two in 1..={MAX_PLANE_ORDER}"),
            ));
        }
        if !(self.side.is_finite() && self.side > 0.0 && self.side <= 1000.0) {
            return Err(Error::range(
                "light plane face side",
                self.side,
                "(0, 1000]",
            ));
        }
        Ok(())
    }

    /// The [`PLANE_BASIS_LEN`] bytes: order (`u32`), 0 (`u32`), side, then
    /// origin, x axis and y axis (`f64` each), little-endian.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut w = Writer::default();
        self.write(&mut w);
        w.bytes
    }

    pub(crate) fn write(&self, w: &mut Writer) {
        w.u32(self.order);
        w.u32(0);
        w.u64(self.side.to_bits());
        for v in [self.origin, self.x_axis, self.y_axis].iter().flatten() {
            w.u64(v.to_bits());
        }
    }

    /// Reads and validates a basis.
    pub(crate) fn read(r: &mut Reader<'_>) -> Result<PlaneBasis> {
        let order = r.u32()?;
        let reserved = r.u32()?;
        if reserved != 0 {
            return Err(Error::range("light plane reserved field", reserved, "0"));
        }
        let side = f64::from_bits(r.u64()?);
        let mut v = [0.0f64; 9];
        for x in &mut v {
            *x = f64::from_bits(r.u64()?);
        }
        let basis = PlaneBasis {
            origin: [v[0], v[1], v[2]],
            x_axis: [v[3], v[4], v[5]],
            y_axis: [v[6], v[7], v[8]],
            order,
            side,
        };
        basis.validate()?;
        Ok(basis)
    }
}

/// The standard 2D orthonormal Haar coefficients (every row fully, then
/// every column fully; Mallat layout, index `k = r·order + c`) of a row's
/// per-texel integrals over the face (`order²` values, `y` major): the
/// integral `t` of a texel is the function `t·order²` over it, `t·order`
/// in the pixel basis, computed as `f32((f64(t)·order²)/order)`. Zeros are
/// dropped; the rest are appended to `out` in increasing `k`.
pub fn plane_coefficients(
    per_texel: &[f32],
    order: usize,
    out: &mut Vec<(u32, f32)>,
) -> Result<()> {
    if !order.is_power_of_two() || per_texel.len() != order * order {
        return Err(Error::range(
            "near-field row",
            format!("{} texels for order {order}", per_texel.len()),
            "order² texels, order a power of two",
        ));
    }
    let scale = (order * order) as f64;
    let mut plane: Vec<f32> = per_texel
        .iter()
        .map(|&t| (f64::from(t) * scale / order as f64) as f32)
        .collect();
    standard_haar_2d(&mut plane, order)?;
    out.extend(
        plane
            .iter()
            .enumerate()
            .filter(|(_, &c)| c != 0.0)
            .map(|(k, &c)| (k as u32, c)),
    );
    Ok(())
}

/// The standard 2D orthonormal Haar transform of an `order × order` grid
/// (row-major), in place: every row fully, then every column fully
/// ([`wavelet::forward_1d`] with the Haar filter, `log₂ order` levels).
pub fn standard_haar_2d(plane: &mut [f32], order: usize) -> Result<()> {
    standard_haar(plane, order, false)
}

/// The inverse of [`standard_haar_2d`], in place: every column, then every
/// row ([`wavelet::inverse_1d`]).
pub fn inverse_standard_haar_2d(plane: &mut [f32], order: usize) -> Result<()> {
    standard_haar(plane, order, true)
}

fn standard_haar(plane: &mut [f32], order: usize, inverse: bool) -> Result<()> {
    if !order.is_power_of_two() || plane.len() != order * order {
        return Err(Error::range(
            "standard Haar grid",
            format!("{} values for order {order}", plane.len()),
            "order² values, order a power of two",
        ));
    }
    let levels = order.trailing_zeros();
    let mut work = vec![0.0f32; order];
    let mut column = vec![0.0f32; order];
    let step = |data: &mut [f32], work: &mut [f32]| match inverse {
        false => wavelet::forward_1d(Filter::Haar, data, levels, work),
        true => wavelet::inverse_1d(Filter::Haar, data, levels, work),
    };
    let rows = |plane: &mut [f32], work: &mut [f32]| -> Result<()> {
        for row in plane.chunks_exact_mut(order) {
            step(row, work)?;
        }
        Ok(())
    };
    if !inverse {
        rows(plane, &mut work)?;
    }
    for x in 0..order {
        for y in 0..order {
            column[y] = plane[y * order + x];
        }
        step(&mut column, &mut work)?;
        for y in 0..order {
            plane[y * order + x] = column[y];
        }
    }
    if inverse {
        rows(plane, &mut work)?;
    }
    Ok(())
}

/// Every row's near-field transport as sparse Haar coefficients, per row
/// and channel ([`plane_coefficients`]).
#[derive(Clone, Debug)]
pub struct PlaneRows {
    basis: PlaneBasis,
    channels: usize,
    /// Entry ranges: `starts[p·C + c]..starts[p·C + c + 1]`.
    starts: Vec<u64>,
    indices: Vec<u16>,
    values: Vec<f32>,
    _charge: Charge,
}

impl PlaneRows {
    /// An empty set of rows for `basis` with `channels` (1 or 3) per row.
    pub fn new(basis: PlaneBasis, channels: usize) -> Result<PlaneRows> {
        basis.validate()?;
        if channels != 1 && channels != 3 {
            return Err(Error::range("near-field channels", channels, "1 or 3"));
        }
        Ok(PlaneRows {
            basis,
            channels,
            starts: vec![0],
            indices: Vec::new(),
            values: Vec::new(),
            _charge: Charge::default(),
        })
    }

    /// Appends the next row from its per-texel integrals (`order²·C` values,
    /// channel-interleaved, as the raw store holds them). Refuses
    /// non-finite values.
    pub fn push_texels(&mut self, texels: &[f32]) -> Result<()> {
        let (n, c) = (self.basis.texels(), self.channels);
        if texels.len() != n * c {
            return Err(Error::BufferTooSmall {
                what: "near-field row",
                len: texels.len(),
                need: n * c,
            });
        }
        if let Some(v) = texels.iter().find(|v| !v.is_finite()) {
            return Err(Error::range("near-field value", v, "finite"));
        }
        let mut channel = vec![0.0f32; n];
        let mut entries = Vec::new();
        for ch in 0..c {
            for (d, s) in channel.iter_mut().zip(texels.iter().skip(ch).step_by(c)) {
                *d = *s;
            }
            entries.clear();
            plane_coefficients(&channel, self.basis.order as usize, &mut entries)?;
            for &(k, v) in &entries {
                self.indices.push(k as u16);
                self.values.push(v);
            }
            self.starts.push(self.values.len() as u64);
        }
        Ok(())
    }

    /// The basis.
    pub fn basis(&self) -> &PlaneBasis {
        &self.basis
    }

    /// Channels per row (1 or 3).
    pub fn channels(&self) -> usize {
        self.channels
    }

    /// Rows held.
    pub fn rows(&self) -> usize {
        (self.starts.len() - 1) / self.channels
    }

    /// Nonzero coefficients held.
    pub fn nonzeros(&self) -> usize {
        self.values.len()
    }

    /// Bytes held on the heap.
    pub fn heap_bytes(&self) -> usize {
        8 * self.starts.len() + 2 * self.indices.len() + 4 * self.values.len()
    }

    /// Row `p`'s coefficients of channel `c`: indices and values.
    pub fn row(&self, p: usize, c: usize) -> (&[u16], &[f32]) {
        let i = p * self.channels + c;
        let (a, b) = (self.starts[i] as usize, self.starts[i + 1] as usize);
        (&self.indices[a..b], &self.values[a..b])
    }

    /// Row `p`'s per-texel integrals of channel `c` (`order²`, `y` major),
    /// the inverse of [`plane_coefficients`]: the coefficients scattered,
    /// [`inverse_standard_haar_2d`], divided by `order`. `out` holds
    /// `order²` values.
    pub fn texels(&self, p: usize, c: usize, out: &mut [f32]) -> Result<()> {
        let order = self.basis.order as usize;
        if out.len() != order * order {
            return Err(Error::BufferTooSmall {
                what: "near-field texels",
                len: out.len(),
                need: order * order,
            });
        }
        out.fill(0.0);
        let (index, value) = self.row(p, c);
        for (&k, &v) in index.iter().zip(value) {
            // Indices were checked against order² when decoded or pushed.
            out[usize::from(k)] = v;
        }
        inverse_standard_haar_2d(out, order)?;
        let scale = 1.0 / order as f32;
        out.iter_mut().for_each(|t| *t *= scale);
        Ok(())
    }

    /// The chunk's bytes (see docs/FORMAT.md, "Near-field rows").
    pub fn encode(&self) -> Vec<u8> {
        let mut w = Writer::default();
        w.u32(self.channels as u32);
        w.u32(0);
        self.basis.write(&mut w);
        for pair in self.starts.windows(2) {
            w.u32((pair[1] - pair[0]) as u32);
        }
        for &k in &self.indices {
            w.u16(k);
        }
        w.pad_to(w.bytes.len().next_multiple_of(4));
        for &v in &self.values {
            w.f32(v);
        }
        w.bytes
    }

    /// Decodes the chunk of a file of `rows` rows and `channels` channels,
    /// charging what it holds to `limits` first: counts of at most `order²`
    /// per row and channel, indices increasing within each and below
    /// `order²`, values finite and nonzero, and nothing left over.
    pub fn decode(
        bytes: &[u8],
        rows: usize,
        channels: usize,
        limits: &Limits,
    ) -> Result<PlaneRows> {
        let mut r = Reader::new(bytes, "NEAR chunk");
        let c = r.u32()? as usize;
        if c != channels || r.u32()? != 0 {
            return Err(Error::range(
                "NEAR channels and reserved field",
                c,
                format!("{channels} (the file's channels), then 0"),
            ));
        }
        let basis = PlaneBasis::read(&mut r)?;
        let lists = rows * channels;
        // The row table (counts as read, then starts) is charged before
        // it is read, the entries once their count is known.
        let charge = limits.check_alloc("NEAR chunk row table", lists as u64 + 1, 12)?;
        let counts: Vec<u32> = r
            .take(lists.saturating_mul(4))?
            .chunks_exact(4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        let texels = basis.texels() as u64;
        if let Some(i) = counts.iter().position(|&n| u64::from(n) > texels) {
            let what = format!(
                "{} (row {}, channel {})",
                counts[i],
                i / channels,
                i % channels
            );
            return Err(Error::range(
                "NEAR entry count",
                what,
                format!("0..={texels}"),
            ));
        }
        let total: u64 = counts.iter().map(|&n| u64::from(n)).sum();
        let charge = charge.join(limits.check_alloc("NEAR chunk entries", total, 6)?);
        let indices: Vec<u16> = r
            .take(2 * total as usize)?
            .chunks_exact(2)
            .map(|b| u16::from_le_bytes([b[0], b[1]]))
            .collect();
        r.take(r.pos().next_multiple_of(4) - r.pos())?;
        let values: Vec<f32> = r
            .take(4 * total as usize)?
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        if r.remaining() != 0 {
            return Err(Error::corrupt(
                "NEAR chunk",
                format!("{} bytes left over", r.remaining()),
            ));
        }
        let mut starts = Vec::with_capacity(lists + 1);
        starts.push(0u64);
        for &n in &counts {
            starts.push(starts[starts.len() - 1] + u64::from(n));
        }
        let rows = PlaneRows {
            basis,
            channels,
            starts,
            indices,
            values,
            _charge: charge,
        };
        rows.check_entries()?;
        Ok(rows)
    }

    /// Indices increasing within each list and below `order²`; values
    /// finite and nonzero.
    fn check_entries(&self) -> Result<()> {
        let texels = self.basis.texels();
        for (i, pair) in self.starts.windows(2).enumerate() {
            let (a, b) = (pair[0] as usize, pair[1] as usize);
            let index = &self.indices[a..b];
            let bad_index = index.windows(2).any(|w| w[0] >= w[1])
                || index.last().is_some_and(|&k| k as usize >= texels);
            let bad_value = self.values[a..b]
                .iter()
                .any(|v| !v.is_finite() || *v == 0.0);
            if bad_index || bad_value {
                return Err(Error::corrupt(
                    "NEAR chunk",
                    format!(
                        "row {}, channel {}: indices must increase below {texels} and values be finite and nonzero",
                        i / self.channels,
                        i % self.channels
                    ),
                ));
            }
        }
        Ok(())
    }
}

/// Refuses a raw store with near-field rows in a command (`what`) that
/// would drop them.
pub(crate) fn refuse_plane_rows(raw: &RawStore, what: &str) -> Result<()> {
    match raw.header().plane {
        Some(_) => Err(Error::Invalid(format!(
            "{}: holds near-field rows (its scene has a [light_plane]), which {what} does not keep; compress it on one machine in a wavelet mode (2d, 4d or adaptive)",
            raw.path().display()
        ))),
        None => Ok(()),
    }
}

/// The near-field rows of a raw store as [`PlaneRows`] with `channels`
/// per row (`None` when it has no light plane), read block by block and
/// charged to `limits` as they grow. A 3-channel store may give 1 channel
/// only when its three channels are equal in every row (a grey matrix
/// stored as one channel). Values are trusted as the caller's verification
/// of the store's blocks (which covers them) trusts them.
pub fn plane_rows_of(
    raw: &RawStore,
    channels: usize,
    limits: &Limits,
) -> Result<Option<PlaneRows>> {
    let header = raw.header();
    let Some(basis) = header.plane else {
        return Ok(None);
    };
    let stored = header.dims.channels as usize;
    if channels != stored && !(channels == 1 && stored == 3) {
        return Err(Error::range(
            "near-field channels",
            channels,
            format!("{stored}"),
        ));
    }
    let mut rows = PlaneRows::new(basis, channels)?;
    let (mut buf, texels) = (Vec::new(), basis.texels());
    for b in 0..header.block_count() {
        let range = header.block_range(b);
        raw.read_plane_rows(range.clone(), &mut buf)?;
        let before = rows.heap_bytes();
        for (i, row) in buf.chunks_exact(texels * stored).enumerate() {
            if channels == stored {
                rows.push_texels(row)?;
                continue;
            }
            if row.chunks_exact(3).any(|t| t[0] != t[1] || t[0] != t[2]) {
                return Err(Error::Invalid(format!(
                    "near-field row {} differs between channels, but the matrix is stored as grey",
                    range.start + i
                )));
            }
            let grey: Vec<f32> = row.iter().step_by(3).copied().collect();
            rows.push_texels(&grey)?;
        }
        let grown =
            limits.check_alloc("near-field rows", (rows.heap_bytes() - before) as u64, 1)?;
        rows._charge = std::mem::take(&mut rows._charge).join(grown);
    }
    Ok(Some(rows))
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) fn basis(order: u32) -> PlaneBasis {
        PlaneBasis {
            origin: [0.0, 1.5, 0.0],
            x_axis: [1.0, 0.0, 0.0],
            y_axis: [0.0, 0.0, 1.0],
            order,
            side: 4.0,
        }
    }

    #[test]
    fn rows_round_trip_and_bad_chunks_error() {
        let b = basis(4);
        assert_eq!(b.normal(), [0.0, -1.0, 0.0]);
        let mut rows = PlaneRows::new(b, 3).unwrap();
        let texels: Vec<f32> = (0..48).map(|i| ((i * 7) % 5) as f32 * 0.25).collect();
        rows.push_texels(&texels).unwrap();
        rows.push_texels(&[0.0; 48]).unwrap();
        let bytes = rows.encode();
        let back = PlaneRows::decode(&bytes, 2, 3, &Limits::default()).unwrap();
        assert_eq!(back.basis(), &b);
        for p in 0..2 {
            for c in 0..3 {
                assert_eq!(back.row(p, c), rows.row(p, c));
            }
        }
        assert!(back.row(1, 2).0.is_empty());
        // The 2D Haar keeps the energy: Σ coefficient² = Σ (t·order)².
        let (_, v) = rows.row(0, 1);
        let energy: f64 = v.iter().map(|&x| f64::from(x).powi(2)).sum();
        let want: f64 = texels
            .iter()
            .skip(1)
            .step_by(3)
            .map(|&t| f64::from(t * 4.0).powi(2))
            .sum();
        assert!((energy - want).abs() < 1e-4 * want, "{energy} {want}");
        let limits = Limits::default();
        assert!(PlaneRows::decode(&bytes, 3, 3, &limits).is_err());
        assert!(PlaneRows::decode(&bytes, 2, 1, &limits).is_err());
        assert!(PlaneRows::decode(&bytes[..bytes.len() - 1], 2, 3, &limits).is_err());
        let mut extra = bytes.clone();
        extra.push(0);
        assert!(PlaneRows::decode(&extra, 2, 3, &limits).is_err());
        let mut bad_order = bytes.clone();
        bad_order[8] = 3;
        assert!(PlaneRows::decode(&bad_order, 2, 3, &limits).is_err());
        let tiny = Limits::with_max_alloc(16);
        assert!(PlaneRows::decode(&bytes, 2, 3, &tiny).is_err());
    }

    #[test]
    fn texels_invert_the_coefficients() {
        for order in [1usize, 2, 8, 32] {
            let mut rows = PlaneRows::new(basis(order as u32), 1).unwrap();
            let n = order * order;
            let texels: Vec<f32> = (0..n)
                .map(|i| ((i * 37 % 11) as f32 - 3.0) * 1e-3 + if i % 5 == 0 { 0.0 } else { 2.5 })
                .collect();
            rows.push_texels(&texels).unwrap();
            let mut back = vec![7.0f32; n];
            rows.texels(0, 0, &mut back).unwrap();
            // f32 rounding through 2·log₂(order) steps, relative to the
            // largest texel.
            let largest = texels.iter().fold(0.0f32, |m, t| m.max(t.abs()));
            for (a, b) in texels.iter().zip(&back) {
                assert!((a - b).abs() <= 1e-6 * largest, "order {order}: {a} {b}");
            }
        }
        let mut plane: Vec<f32> = (0..64).map(|i| i as f32).collect();
        let original = plane.clone();
        standard_haar_2d(&mut plane, 8).unwrap();
        assert_ne!(plane, original);
        inverse_standard_haar_2d(&mut plane, 8).unwrap();
        for (a, b) in original.iter().zip(&plane) {
            assert!((a - b).abs() < 1e-4, "{a} {b}");
        }
        assert!(inverse_standard_haar_2d(&mut plane[..63], 8).is_err());
        let rows = PlaneRows::new(basis(8), 1).unwrap();
        assert!(rows.texels(0, 0, &mut [0.0; 63]).is_err());
    }

    #[test]
    fn bases_are_checked() {
        assert!(basis(256).validate().is_ok());
        for bad in [
            PlaneBasis {
                order: 512,
                ..basis(4)
            },
            PlaneBasis {
                order: 3,
                ..basis(4)
            },
            PlaneBasis {
                side: 0.0,
                ..basis(4)
            },
            PlaneBasis {
                side: f64::NAN,
                ..basis(4)
            },
            PlaneBasis {
                x_axis: [1.0, 0.0, 0.1],
                ..basis(4)
            },
            PlaneBasis {
                y_axis: [1.0, 0.0, 0.0],
                ..basis(4)
            },
            PlaneBasis {
                origin: [f64::INFINITY, 0.0, 0.0],
                ..basis(4)
            },
        ] {
            let err = bad.validate().unwrap_err().to_string();
            assert!(err.contains("light plane"), "{err}");
        }
        let (depth, at) = basis(4).locate([0.5, 0.5, -0.25]);
        assert_eq!((depth, at), (1.0, [0.5, -0.25]));
    }
}
