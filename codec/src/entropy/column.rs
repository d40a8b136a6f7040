//! Column encodings 3 to 6: a column's sparse coefficients range-coded
//! with context modelling. The bands of the column image are visited coarse
//! to fine, each in 4 × 4 blocks: a block flag says whether the block holds
//! a kept coefficient, then each of its pixels a significance bit, then
//! each kept pixel its channels' values. Encoding 3 codes a value as a zero
//! flag, a sign and an exp-Golomb magnitude, every bit modelled; encoding 4
//! as one 17-symbol magnitude class, a sign, the two bits below the leading
//! one modelled and the rest raw, in a bit stream of their own: about a
//! third of the range coder's steps per value, for a payload about as
//! small. Contexts come from
//! the band's level, the already coded neighbours and the parent in the
//! next coarser band. Encoding 5 codes encoding 4's values, with the scale
//! codes and the stream's length coded compactly; encoding 6 codes encoding
//! 5 with the contexts starting in the file's priors (`priors.rs`).
//! docs/FORMAT.md ("Encoding 3" to "Encoding 6") is the specification.

use super::bits::{BitReader, BitWriter};
use super::priors::Priors;
use super::range::{Cdf, Context, Decoder, Encoder};
use crate::column::SparseColumn;
use crate::error::{Error, Result};
use crate::wavelet::{band_size, max_levels};

/// Side of the square blocks a band is scanned in.
const BLOCK: usize = 4;
/// Level classes: 0 for the low band, `min(k, 7)` for detail level `k`.
const CLASSES: usize = 8;
/// Most channels a column has.
const MAX_CHANNELS: usize = 3;
/// Magnitude classes kept per pixel (its bit length, capped).
const MAX_MAG: u8 = 15;

/// What the coder needs to know of a file: the column image's size, the
/// channels per pixel and the quantizer's bits.
#[derive(Clone, Copy, Debug)]
pub struct ColumnShape {
    /// Column image width.
    pub width: usize,
    /// Column image height.
    pub height: usize,
    /// Values per position (1 or 3).
    pub channels: usize,
    /// Quantization bits (2..=16): magnitudes are below `2^(bits − 1)`.
    pub bits: u32,
}

/// A rectangle of the column image.
#[derive(Clone, Copy, Debug)]
struct Rect {
    x0: usize,
    y0: usize,
    w: usize,
    h: usize,
}

/// One band: its rectangle, level class, parent band and the shift from
/// its coordinates to the parent's.
#[derive(Clone, Copy, Debug)]
struct Band {
    rect: Rect,
    /// Scale group: 0 for the low band, `k` for detail level `k`.
    group: usize,
    class: usize,
    parent: Option<(Rect, u32)>,
}

/// The bands of a column image at `depth`, in coding order: the low band,
/// then for `k = depth, …, 1` the bands right of (HL), below (LH) and
/// diagonal to (HH) the level-`k` low band.
fn bands(width: usize, height: usize, depth: u32) -> Vec<Band> {
    let (lw, lh) = band_size(width, height, depth);
    let low = Rect {
        x0: 0,
        y0: 0,
        w: lw,
        h: lh,
    };
    let mut out = vec![Band {
        rect: low,
        group: 0,
        class: 0,
        parent: None,
    }];
    let mut parents = [low; 3];
    for k in (1..=depth).rev() {
        let (pw, ph) = band_size(width, height, k - 1);
        let (lw, lh) = band_size(width, height, k);
        let rects = [
            Rect {
                x0: lw,
                y0: 0,
                w: pw - lw,
                h: lh,
            },
            Rect {
                x0: 0,
                y0: lh,
                w: lw,
                h: ph - lh,
            },
            Rect {
                x0: lw,
                y0: lh,
                w: pw - lw,
                h: ph - lh,
            },
        ];
        let shift = u32::from(k != depth);
        for (o, &rect) in rects.iter().enumerate() {
            out.push(Band {
                rect,
                group: k as usize,
                class: (k as usize).min(CLASSES - 1),
                parent: Some((parents[o], shift)),
            });
        }
        parents = rects;
    }
    out
}

/// Bit length of a magnitude: 0 for 0, `⌊log2 m⌋ + 1` else.
#[inline]
fn bit_length(m: u32) -> u32 {
    32 - m.leading_zeros()
}

/// How a column's values are coded: the column encodings 3 and 4.
#[non_exhaustive]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ValueCoding {
    /// Encoding 3: zero flag, sign, exp-Golomb magnitude, every bit
    /// modelled.
    ExpGolomb,
    /// Encoding 4: a 17-symbol magnitude class, a sign, two modelled bits
    /// below the leading one and the rest raw.
    Classes,
    /// Encoding 5: encoding 4's values, with the scale codes coded in the
    /// streams (a repeated code in 1 modelled bit) and the range-coded
    /// stream's length as a varint: about 4 bytes a column where encoding 4
    /// spends `2·(d + 1)·C + 4`.
    Compact,
    /// Encoding 6: encoding 5 with every context starting in the file's
    /// [`Priors`] rather than at p = 1/2.
    Primed,
}

impl ValueCoding {
    /// Encodings 5 and 6: scale codes in the streams, a varint length.
    fn compact(self) -> bool {
        matches!(self, ValueCoding::Compact | ValueCoding::Primed)
    }
}

/// Reads or writes symbols: the encoder codes the symbol given, the
/// decoder returns the symbol decoded.
trait BitIo {
    /// True for the encoder (which knows the bits).
    const ENCODES: bool;
    fn bit(&mut self, ctx: &mut Context, bit: bool) -> bool;
    /// A symbol of 0..=16.
    fn symbol(&mut self, cdf: &mut Cdf, s: usize) -> usize;
    /// `n` raw bits (the low `n` bits of `value` when encoding).
    fn raw(&mut self, n: u32, value: u32) -> u32;
    /// Whether the decoder read past a stream's end (it then stops).
    fn overrun(&self) -> bool {
        false
    }
}

/// The encoder's two streams.
#[derive(Default)]
struct Writer {
    range: Encoder,
    raw: BitWriter,
}

impl BitIo for Writer {
    const ENCODES: bool = true;
    #[inline(always)]
    fn bit(&mut self, ctx: &mut Context, bit: bool) -> bool {
        self.range.bit(ctx, bit);
        bit
    }
    #[inline(always)]
    fn symbol(&mut self, cdf: &mut Cdf, s: usize) -> usize {
        self.range.symbol(cdf, s);
        s
    }
    #[inline(always)]
    fn raw(&mut self, n: u32, value: u32) -> u32 {
        self.raw.put(n, value);
        value
    }
}

/// The decoder's two streams.
struct Reader<'a> {
    range: Decoder<'a>,
    raw: BitReader<'a>,
}

impl BitIo for Reader<'_> {
    const ENCODES: bool = false;
    #[inline(always)]
    fn bit(&mut self, ctx: &mut Context, _bit: bool) -> bool {
        self.range.bit(ctx)
    }
    #[inline(always)]
    fn symbol(&mut self, cdf: &mut Cdf, _s: usize) -> usize {
        self.range.symbol(cdf)
    }
    #[inline(always)]
    fn raw(&mut self, n: u32, _value: u32) -> u32 {
        self.raw.get(n)
    }
    fn overrun(&self) -> bool {
        self.range.overrun() || self.raw.overrun()
    }
}

/// The adaptive contexts of one column: all starting at p = 1/2, or
/// (encoding 6) in the file's [`Priors`].
pub(super) struct Model {
    /// Encoding 5's scale codes: "the same as the last nonzero code",
    /// "zero".
    scale: [Context; 2],
    /// Block flags: class × (left + up block flags, 0..=2) × parent.
    block: [Context; CLASSES * 3 * 2],
    /// Significance: class × (left + up, 0..=2) × (up-left + up-right,
    /// 0..=2) × parent.
    sig: [Context; CLASSES * 3 * 3 * 2],
    /// Zero flag: 1 for channel 0, 2 for channel 1 (prediction 0 or
    /// not), 4 for channel 2 (prediction 0, channel 1's residual 0).
    zero: [Context; 7],
    /// Sign: 1 for channel 0, 3 per later channel (prediction 0, +, −).
    sign: [Context; 7],
    /// Exp-Golomb prefix: magnitude context × prefix position (capped 15).
    prefix: [[Context; 16]; MAG_CONTEXTS],
    /// Exp-Golomb suffix: prefix length × bit position.
    suffix: [[Context; 16]; 16],
    /// Encoding 4's magnitude classes: the prefix contexts' 64, then 16
    /// more for channel 2 after a zero residual of channel 1.
    class: [Cdf; CLASS_CONTEXTS],
    /// Encoding 4's bit below the leading one, by bit length (2..=16).
    top: [Context; 17],
    /// Encoding 4's second bit below the leading one, by bit length and
    /// the first.
    second: [[Context; 2]; 17],
}

/// Encoding 4's magnitude-class contexts.
pub(super) const CLASS_CONTEXTS: usize = MAG_CONTEXTS + 16;

/// Scale groups a column has at most (depth ≤ 15).
const MAX_GROUPS: usize = 16;

/// Magnitude contexts: class × neighbour bucket for channel 0, then 16
/// per later channel by its prediction's bit length.
const MAG_CONTEXTS: usize = CLASSES * 4 + 2 * 16;

impl Model {
    /// The contexts encodings 5 and 6 use, in the order of the PRIO
    /// chunk: the scale codes', block flags, significance, signs, the bits
    /// below the leading one; then the magnitude classes.
    pub(super) fn compact(&mut self) -> (impl Iterator<Item = &mut Context>, &mut [Cdf]) {
        let binary = self
            .scale
            .iter_mut()
            .chain(self.block.iter_mut())
            .chain(self.sig.iter_mut())
            .chain(self.sign.iter_mut())
            .chain(self.top.iter_mut())
            .chain(self.second.iter_mut().flatten());
        (binary, &mut self.class[..])
    }

    pub(super) fn new() -> Box<Model> {
        let c = Context::default();
        Box::new(Model {
            scale: [c; 2],
            block: [c; CLASSES * 3 * 2],
            sig: [c; CLASSES * 3 * 3 * 2],
            zero: [c; 7],
            sign: [c; 7],
            prefix: [[c; 16]; MAG_CONTEXTS],
            suffix: [[c; 16]; 16],
            class: [Cdf::default(); CLASS_CONTEXTS],
            top: [c; 17],
            second: [[c; 2]; 17],
        })
    }
}

/// The walk over a column's bands shared by the encoder and the decoder.
/// `truth` gives the encoder's values at a pixel (`None` where not kept);
/// `found` receives every kept pixel and its values in coding order.
struct Walk<'a, IO, T, F>
where
    IO: BitIo,
    T: Fn(usize) -> Option<[i32; MAX_CHANNELS]>,
    F: FnMut(usize, [i32; MAX_CHANNELS]),
{
    io: &'a mut IO,
    truth: T,
    shape: ColumnShape,
    coding: ValueCoding,
    model: Box<Model>,
    /// Per pixel: 0 if not kept, else the largest channel bit length
    /// (capped at 15).
    mag: Vec<u8>,
    /// Block flags of the current band.
    blocks: Vec<bool>,
    /// Kept pixels still to find.
    left: usize,
    /// Per scale group: Σ q0² and Σ q_c·q0 (c = 1, 2) over the kept
    /// positions coded so far.
    sxx: [i64; MAX_GROUPS],
    sxy: [[i64; 2]; MAX_GROUPS],
    /// Encoding 4: per scale group, the ratios `Sxy/Sxx` in units of
    /// 2^−16 as of the last position (see [`ratio`]).
    ratio: [[i64; 2]; MAX_GROUPS],
    found: F,
}

impl<IO, T, F> Walk<'_, IO, T, F>
where
    IO: BitIo,
    T: Fn(usize) -> Option<[i32; MAX_CHANNELS]>,
    F: FnMut(usize, [i32; MAX_CHANNELS]),
{
    fn run(&mut self, depth: u32) -> Result<()> {
        for band in bands(self.shape.width, self.shape.height, depth) {
            if self.left == 0 {
                break;
            }
            self.band(&band)?;
        }
        Ok(())
    }

    #[inline]
    fn mag_at(&self, r: &Rect, u: usize, v: usize) -> u8 {
        self.mag[(r.y0 + v) * self.shape.width + r.x0 + u]
    }

    /// The parent's magnitude class of local pixel `(u, v)`.
    #[inline]
    fn parent_mag(&self, band: &Band, u: usize, v: usize) -> u8 {
        match band.parent {
            Some((p, s)) if p.w > 0 && p.h > 0 => {
                self.mag_at(&p, (u >> s).min(p.w - 1), (v >> s).min(p.h - 1))
            }
            _ => 0,
        }
    }

    fn band(&mut self, band: &Band) -> Result<()> {
        let r = band.rect;
        let (bw, bh) = (r.w.div_ceil(BLOCK), r.h.div_ceil(BLOCK));
        self.blocks.clear();
        self.blocks.resize(bw * bh, false);
        for by in 0..bh {
            for bx in 0..bw {
                if self.left == 0 {
                    return Ok(());
                }
                if self.io.overrun() {
                    return Err(Error::corrupt(
                        "column payload",
                        "range-coded stream ends early",
                    ));
                }
                let (u0, v0) = (bx * BLOCK, by * BLOCK);
                let (u1, v1) = ((u0 + BLOCK).min(r.w), (v0 + BLOCK).min(r.h));
                let any = self.block_truth(&r, u0, v0, u1, v1);
                let near = usize::from(bx > 0 && self.blocks[by * bw + bx - 1])
                    + usize::from(by > 0 && self.blocks[(by - 1) * bw + bx]);
                let parent = [(u0, v0), (u1 - 1, v0), (u0, v1 - 1), (u1 - 1, v1 - 1)]
                    .iter()
                    .any(|&(u, v)| self.parent_mag(band, u, v) > 0);
                let ctx = (band.class * 3 + near) * 2 + usize::from(parent);
                let flag = self.io.bit(&mut self.model.block[ctx], any);
                self.blocks[by * bw + bx] = flag;
                if flag {
                    self.block(band, u0, v0, u1, v1)?;
                }
            }
        }
        Ok(())
    }

    /// Whether the encoder's block holds a kept pixel (false when decoding).
    fn block_truth(&self, r: &Rect, u0: usize, v0: usize, u1: usize, v1: usize) -> bool {
        IO::ENCODES
            && (v0..v1).any(|v| {
                (u0..u1).any(|u| (self.truth)((r.y0 + v) * self.shape.width + r.x0 + u).is_some())
            })
    }

    fn block(&mut self, band: &Band, u0: usize, v0: usize, u1: usize, v1: usize) -> Result<()> {
        let r = band.rect;
        let mut seen = false;
        for v in v0..v1 {
            for u in u0..u1 {
                if self.left == 0 {
                    return Ok(());
                }
                let pixel = (r.y0 + v) * self.shape.width + r.x0 + u;
                let truth = (self.truth)(pixel);
                let last = v == v1 - 1 && u == u1 - 1;
                let kept = if last && !seen {
                    true
                } else {
                    let ctx = self.sig_context(band, u, v);
                    self.io.bit(&mut self.model.sig[ctx], truth.is_some())
                };
                if kept {
                    seen = true;
                    let values = self.values(band, u, v, truth.unwrap_or_default())?;
                    self.left -= 1;
                    (self.found)(pixel, values);
                }
            }
        }
        Ok(())
    }

    fn sig_context(&self, band: &Band, u: usize, v: usize) -> usize {
        let r = &band.rect;
        let w = self.shape.width;
        let at = (r.y0 + v) * w + r.x0 + u;
        let on = |i: usize| usize::from(self.mag[i] > 0);
        let (left, right) = (u > 0, u + 1 < r.w);
        let mut near = if left { on(at - 1) } else { 0 };
        let mut diag = 0;
        if v > 0 {
            let above = at - w;
            near += on(above);
            diag = if left { on(above - 1) } else { 0 } + if right { on(above + 1) } else { 0 };
        }
        let parent = usize::from(self.parent_mag(band, u, v) > 0);
        ((band.class * 3 + near) * 3 + diag) * 2 + parent
    }

    /// Codes the values of a kept pixel; returns them. Channel 0 is coded
    /// as it is; a later channel as its residual from the prediction
    /// [`Walk::predict`] makes from channel 0.
    fn values(
        &mut self,
        band: &Band,
        u: usize,
        v: usize,
        truth: [i32; MAX_CHANNELS],
    ) -> Result<[i32; MAX_CHANNELS]> {
        let r = &band.rect;
        let left = if u > 0 { self.mag_at(r, u - 1, v) } else { 0 };
        let up = if v > 0 { self.mag_at(r, u, v - 1) } else { 0 };
        let bucket = match left as u32 + up as u32 {
            0 => 0,
            1..=3 => 1,
            4..=7 => 2,
            _ => 3,
        };
        let max = (1i32 << (self.shape.bits - 1)) - 1;
        let mut out = [0i32; MAX_CHANNELS];
        let ctx0 = band.class * 4 + bucket;
        let q0 = match self.coding {
            ValueCoding::ExpGolomb => self.value(0, 0, ctx0, self.shape.bits - 2, truth[0])?,
            _ => self.classed(ctx0, 0, self.shape.bits - 1, truth[0])?,
        };
        out[0] = q0;
        let mut widest = bit_length(q0.unsigned_abs());
        let mut prev_zero = false;
        for c in 1..self.shape.channels {
            let pred = match self.coding {
                ValueCoding::ExpGolomb => self.predict(band.group, c, q0, max),
                _ => ((q0 as i64 * self.ratio[band.group][c - 1] + (1 << 15)) >> 16)
                    .clamp(-max as i64, max as i64) as i32,
            };
            let zero_ctx = if c == 1 {
                1 + usize::from(pred == 0)
            } else {
                3 + 2 * usize::from(pred == 0) + usize::from(prev_zero)
            };
            let sign_ctx = 1 + (c - 1) * 3 + pred.signum().rem_euclid(3) as usize;
            let len = bit_length(pred.unsigned_abs()).min(15) as usize;
            let mag_ctx = CLASSES * 4 + (c - 1) * 16 + len;
            let res = match self.coding {
                ValueCoding::ExpGolomb => self.value(
                    zero_ctx,
                    sign_ctx,
                    mag_ctx,
                    self.shape.bits - 1,
                    truth[c] - pred,
                )?,
                _ => {
                    let class_ctx = mag_ctx + if c == 2 && prev_zero { 16 } else { 0 };
                    self.classed(class_ctx, sign_ctx, self.shape.bits, truth[c] - pred)?
                }
            };
            let q = pred + res;
            if q.abs() > max {
                return Err(Error::corrupt(
                    "column payload",
                    format!("quantized value {q} outside ±{max}"),
                ));
            }
            out[c] = q;
            prev_zero = res == 0;
            widest = widest.max(bit_length(q.unsigned_abs()));
            let g = band.group;
            self.sxy[g][c - 1] += q as i64 * q0 as i64;
        }
        let g = band.group;
        self.sxx[g] += q0 as i64 * q0 as i64;
        if self.coding != ValueCoding::ExpGolomb {
            for c in 1..self.shape.channels {
                self.ratio[g][c - 1] = ratio(self.sxy[g][c - 1], self.sxx[g]);
            }
        }
        let pixel = (r.y0 + v) * self.shape.width + r.x0 + u;
        self.mag[pixel] = (widest as u8).clamp(1, MAX_MAG);
        Ok(out)
    }

    /// The prediction of channel `c` from channel 0's value `q0` at a
    /// position of scale group `g`: `q0` times the least-squares ratio of
    /// the group's positions coded so far, rounded half up, within `±max`.
    fn predict(&self, g: usize, c: usize, q0: i32, max: i32) -> i32 {
        let (sxx, sxy) = (self.sxx[g], self.sxy[g][c - 1]);
        if sxx == 0 {
            return 0;
        }
        // i64 when it cannot overflow (the usual case), else i128: the
        // same exact value.
        let fits = sxy.unsigned_abs() < 1 << 46 && sxx < 1 << 60;
        let p = if fits {
            (2 * sxy * q0 as i64 + sxx).div_euclid(2 * sxx) as i128
        } else {
            (2 * sxy as i128 * q0 as i128 + sxx as i128).div_euclid(2 * sxx as i128)
        };
        p.clamp(-max as i128, max as i128) as i32
    }

    /// Codes a value: a zero flag, then the sign and the magnitude (at
    /// most `max_n + 1` bits long) of a nonzero one.
    fn value(
        &mut self,
        zero_ctx: usize,
        sign_ctx: usize,
        mag_ctx: usize,
        max_n: u32,
        want: i32,
    ) -> Result<i32> {
        if !self.io.bit(&mut self.model.zero[zero_ctx], want != 0) {
            return Ok(0);
        }
        let negative = self.io.bit(&mut self.model.sign[sign_ctx], want < 0);
        let m = self.magnitude(mag_ctx, max_n, want.unsigned_abs())? as i32;
        Ok(if negative { -m } else { m })
    }

    /// Codes a value as encoding 4 does: its magnitude class (bit length,
    /// at most `max_len`), the sign of a nonzero one, the two bits below
    /// the leading one modelled, then the lower bits raw.
    fn classed(
        &mut self,
        class_ctx: usize,
        sign_ctx: usize,
        max_len: u32,
        want: i32,
    ) -> Result<i32> {
        let want_m = want.unsigned_abs();
        let len = self.io.symbol(
            &mut self.model.class[class_ctx],
            bit_length(want_m) as usize,
        ) as u32;
        if len == 0 {
            return Ok(0);
        }
        if len > max_len {
            return Err(Error::corrupt(
                "column payload",
                format!("magnitude class {len} (valid: 0..={max_len})"),
            ));
        }
        let negative = self.io.bit(&mut self.model.sign[sign_ctx], want < 0);
        let mut m = 1u32;
        if len >= 2 {
            let top = self.io.bit(
                &mut self.model.top[len as usize],
                want_m >> (len - 2) & 1 == 1,
            );
            m = 2 | u32::from(top);
            if len >= 3 {
                let second = self.io.bit(
                    &mut self.model.second[len as usize][top as usize],
                    want_m >> (len - 3) & 1 == 1,
                );
                m = m << 1 | u32::from(second);
                let low = len - 3;
                m = m << low | self.io.raw(low, want_m & ((1 << low) - 1));
            }
        }
        Ok(if negative { -(m as i32) } else { m as i32 })
    }

    /// Codes a magnitude `m ≥ 1` below `2^(max_n + 1)`: its bit length
    /// minus one `n` in unary (no terminator at `n = max_n`), then its `n`
    /// bits below the leading one, most significant first.
    fn magnitude(&mut self, ctx: usize, max_n: u32, want: u32) -> Result<u32> {
        let want_n = bit_length(want).saturating_sub(1);
        let mut n = 0u32;
        while n < max_n {
            let more = self
                .io
                .bit(&mut self.model.prefix[ctx][n.min(15) as usize], want_n > n);
            if !more {
                break;
            }
            n += 1;
        }
        let mut m = 1u32;
        for j in (0..n).rev() {
            let b = self.io.bit(
                &mut self.model.suffix[n as usize][j as usize],
                want >> j & 1 == 1,
            );
            m = m << 1 | u32::from(b);
        }
        Ok(m)
    }
}

/// Encoding 4's prediction ratio `⌊(2^17·sxy + sxx) / (2·sxx)⌋` (`sxy/sxx`
/// rounded, in units of 2^−16; 0 for `sxx = 0`) within `±2^20`. It is
/// computed once a position is done, so that the next position's
/// prediction is a product: the division is off the decoder's path.
fn ratio(sxy: i64, sxx: i64) -> i64 {
    if sxx == 0 {
        return 0;
    }
    // i64 when it cannot overflow (the usual case), else i128: the same
    // exact value.
    const LIMIT: i64 = 1 << 20;
    if sxy.unsigned_abs() < 1 << 45 && sxx < 1 << 60 {
        ((sxy << 17) + sxx).div_euclid(2 * sxx).clamp(-LIMIT, LIMIT)
    } else {
        let r = (((sxy as i128) << 17) + sxx as i128).div_euclid(2 * sxx as i128);
        r.clamp(-LIMIT as i128, LIMIT as i128) as i64
    }
}

/// Checks that the coder can represent `col`: at most 3 channels, every
/// magnitude below `2^(bits − 1)`, positions inside the image, a depth
/// the image has.
fn representable(col: &SparseColumn, shape: &ColumnShape) -> bool {
    let c = shape.channels;
    let max = (1u32 << (shape.bits - 1)) - 1;
    (1..=MAX_CHANNELS).contains(&c)
        && (2..=16).contains(&shape.bits)
        && col.values.len() == col.indices.len() * c
        && col
            .indices
            .iter()
            .all(|&i| (i as usize) < shape.width * shape.height)
        && (col.depth as usize) < MAX_GROUPS
        && col.depth <= max_levels(shape.width, shape.height)
        && col.values.iter().all(|&x| x.unsigned_abs() <= max)
}

/// Encodes a column: its scale codes (2 bytes each, little-endian), then
/// the range-coded stream (encoding 3), or the range-coded stream's length
/// (`u32`, little-endian), the stream and the raw bit stream (encoding 4).
/// `None` when the column cannot be represented (see `representable`);
/// the caller then stores it otherwise.
///
/// Encoding 6 ([`ValueCoding::Primed`]) needs the file's priors: see
/// [`encode_primed`]; `encode` refuses it.
pub fn encode(col: &SparseColumn, shape: &ColumnShape, coding: ValueCoding) -> Option<Vec<u8>> {
    if coding == ValueCoding::Primed {
        return None;
    }
    encode_from(col, shape, coding, Model::new()).map(|(bytes, _)| bytes)
}

/// Encodes a column in encoding 6: encoding 5 with the contexts starting
/// in `priors`.
pub fn encode_primed(col: &SparseColumn, shape: &ColumnShape, priors: &Priors) -> Option<Vec<u8>> {
    encode_from(col, shape, ValueCoding::Primed, priors.model()).map(|(bytes, _)| bytes)
}

/// [`encode`] with the contexts starting in `model`'s states; also returns
/// their states at the end.
pub(super) fn encode_from(
    col: &SparseColumn,
    shape: &ColumnShape,
    coding: ValueCoding,
    mut model: Box<Model>,
) -> Option<(Vec<u8>, Box<Model>)> {
    if !representable(col, shape) {
        return None;
    }
    let c = shape.channels;
    let mut dense = vec![u32::MAX; shape.width * shape.height];
    for (k, &i) in col.indices.iter().enumerate() {
        dense[i as usize] = k as u32;
    }
    let truth = |pixel: usize| {
        let k = dense[pixel];
        (k != u32::MAX).then(|| {
            let mut v = [0i32; MAX_CHANNELS];
            v[..c].copy_from_slice(&col.values[k as usize * c..(k as usize + 1) * c]);
            v
        })
    };
    let mut enc = Writer::default();
    if coding.compact() {
        let mut codes = col.scale_codes.clone();
        if codes.len() != (col.depth as usize + 1) * c {
            return None;
        }
        scale_codes(&mut enc, &mut codes, &mut model.scale);
    }
    let mut walk = Walk {
        io: &mut enc,
        truth,
        shape: *shape,
        coding,
        model,
        mag: vec![0; shape.width * shape.height],
        blocks: Vec::new(),
        left: col.indices.len(),
        sxx: [0; MAX_GROUPS],
        sxy: [[0; 2]; MAX_GROUPS],
        ratio: [[0; 2]; MAX_GROUPS],
        found: |_, _| {},
    };
    walk.run(col.depth).ok()?;
    if walk.left != 0 {
        return None;
    }
    let model = walk.model;
    let range = enc.range.finish();
    if coding.compact() {
        let mut out = Vec::with_capacity(range.len() + 8);
        put_varint(&mut out, u32::try_from(range.len()).ok()?);
        out.extend_from_slice(&range);
        out.extend_from_slice(&enc.raw.finish());
        return Some((out, model));
    }
    let mut out = Vec::with_capacity(2 * col.scale_codes.len());
    for e in &col.scale_codes {
        out.extend_from_slice(&e.to_le_bytes());
    }
    if coding == ValueCoding::ExpGolomb {
        out.extend_from_slice(&range);
    } else {
        out.extend_from_slice(&u32::try_from(range.len()).ok()?.to_le_bytes());
        out.extend_from_slice(&range);
        out.extend_from_slice(&enc.raw.finish());
    }
    Some((out, model))
}

/// Decodes a column of `nnz` kept positions at `depth` from `bytes`.
/// Encoding 6 ([`ValueCoding::Primed`]) needs the file's `priors`; the
/// others ignore them.
pub fn decode(
    bytes: &[u8],
    nnz: usize,
    shape: &ColumnShape,
    depth: u32,
    coding: ValueCoding,
    priors: Option<&Priors>,
) -> Result<SparseColumn> {
    let model = match (coding, priors) {
        (ValueCoding::Primed, Some(p)) => p.model(),
        (ValueCoding::Primed, None) => {
            return Err(Error::corrupt(
                "column payload",
                "encoding 6 in a file without priors (chunk PRIO)",
            ))
        }
        _ => Model::new(),
    };
    decode_from(bytes, nnz, shape, depth, coding, model).map(|(col, _)| col)
}

/// [`decode`] with the contexts starting in `model`'s states; also returns
/// their states at the end.
pub(super) fn decode_from(
    bytes: &[u8],
    nnz: usize,
    shape: &ColumnShape,
    depth: u32,
    coding: ValueCoding,
    mut model: Box<Model>,
) -> Result<(SparseColumn, Box<Model>)> {
    let c = shape.channels;
    if !(1..=MAX_CHANNELS).contains(&c) || !(2..=16).contains(&shape.bits) {
        return Err(Error::range("channels", c, "1..=3"));
    }
    let pixels = shape.width * shape.height;
    if nnz > pixels {
        return Err(Error::corrupt(
            "column payload",
            format!("{nnz} nonzeros (valid: 0..={pixels})"),
        ));
    }
    if depth > max_levels(shape.width, shape.height) || depth as usize >= MAX_GROUPS {
        return Err(Error::range(
            "column depth",
            depth,
            format!("0..={}", max_levels(shape.width, shape.height)),
        ));
    }
    let groups = (depth as usize + 1) * c;
    let (mut dec, scale_codes) = if coding.compact() {
        let (range, raw) = split_compact(bytes)?;
        let mut dec = Reader {
            range: Decoder::new(range)?,
            raw: BitReader::new(raw),
        };
        let mut codes = vec![0u16; groups];
        scale_codes(&mut dec, &mut codes, &mut model.scale);
        (dec, codes)
    } else {
        fixed_streams(bytes, groups, coding)?
    };
    // Values in coding order, and each kept pixel's place among them.
    let mut order: Vec<[i32; MAX_CHANNELS]> = Vec::with_capacity(nnz);
    let mut slot = vec![0u32; pixels];
    let mut walk = Walk {
        io: &mut dec,
        truth: |_| None,
        shape: *shape,
        coding,
        model,
        mag: vec![0; pixels.next_multiple_of(8)],
        blocks: Vec::new(),
        left: nnz,
        sxx: [0; MAX_GROUPS],
        sxy: [[0; 2]; MAX_GROUPS],
        ratio: [[0; 2]; MAX_GROUPS],
        found: |pixel: usize, v| {
            slot[pixel] = order.len() as u32;
            order.push(v);
        },
    };
    walk.run(depth)?;
    let Walk {
        left, mag, model, ..
    } = walk;
    if left != 0 {
        return Err(Error::corrupt(
            "column payload",
            format!("{} of {nnz} nonzeros found", nnz - left),
        ));
    }
    dec.range.finish()?;
    dec.raw.finish()?;
    let mut col = SparseColumn {
        depth,
        scale_codes,
        indices: Vec::with_capacity(nnz),
        values: Vec::with_capacity(nnz * c),
    };
    // Kept pixels are those with a magnitude class: gather them in raster
    // order, skipping 8 empty pixels at a time.
    for (w, word) in mag.chunks_exact(8).enumerate() {
        // `mag` is padded to whole words.
        if u64::from_ne_bytes(word.try_into().unwrap_or_default()) == 0 {
            continue;
        }
        for (k, &m) in word.iter().enumerate() {
            if m != 0 {
                let pixel = w * 8 + k;
                col.indices.push(pixel as u32);
                col.values
                    .extend_from_slice(&order[slot[pixel] as usize][..c]);
            }
        }
    }
    Ok((col, model))
}

/// The scale codes (2 bytes each) and the streams of encodings 3 and 4,
/// with the decoder over the streams.
fn fixed_streams(
    bytes: &[u8],
    groups: usize,
    coding: ValueCoding,
) -> Result<(Reader<'_>, Vec<u16>)> {
    if bytes.len() < 2 * groups {
        return Err(Error::corrupt(
            "column payload",
            format!("{} bytes, fewer than the {groups} scale codes", bytes.len()),
        ));
    }
    let (scales, stream) = bytes.split_at(2 * groups);
    let scale_codes = scales
        .chunks_exact(2)
        .map(|b| u16::from_le_bytes([b[0], b[1]]))
        .collect();
    let (range, raw) = match coding {
        ValueCoding::ExpGolomb => (stream, &[][..]),
        _ => split_streams(stream)?,
    };
    let dec = Reader {
        range: Decoder::new(range)?,
        raw: BitReader::new(raw),
    };
    Ok((dec, scale_codes))
}

/// Codes a column's scale codes (encoding 5), in place: after a nonzero
/// code, a modelled bit "the same as the last nonzero code"; else a
/// modelled bit "zero"; else 16 raw bits.
fn scale_codes<IO: BitIo>(io: &mut IO, codes: &mut [u16], contexts: &mut [Context; 2]) {
    let [same, zero] = contexts;
    let mut last = None;
    for code in codes.iter_mut() {
        *code = match last {
            Some(l) if io.bit(same, *code == l) => l,
            _ if io.bit(zero, *code == 0) => 0,
            _ => io.raw(16, u32::from(*code)) as u16,
        };
        if *code != 0 {
            last = Some(*code);
        }
    }
}

/// Appends `v` as an unsigned LEB128 varint.
fn put_varint(out: &mut Vec<u8>, mut v: u32) {
    while v >= 0x80 {
        out.push(v as u8 | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

/// Encoding 5's range-coded and raw streams: a varint (unsigned LEB128,
/// at most 5 bytes, no redundant last byte) gives the range-coded
/// stream's length.
fn split_compact(bytes: &[u8]) -> Result<(&[u8], &[u8])> {
    let bad = |why: String| Error::corrupt("column payload", why);
    let mut len = 0u64;
    let mut at = 0;
    loop {
        let Some(&b) = bytes.get(at) else {
            return Err(bad(format!(
                "stream length varint runs past the {}-byte payload",
                bytes.len()
            )));
        };
        len |= u64::from(b & 0x7F) << (7 * at);
        at += 1;
        if b & 0x80 == 0 {
            if at > 1 && b == 0 {
                return Err(bad(
                    "stream length varint ends in a redundant zero byte".into()
                ));
            }
            break;
        }
        if at == 5 {
            return Err(bad("stream length varint longer than 5 bytes".into()));
        }
    }
    let rest = &bytes[at..];
    if len > rest.len() as u64 {
        return Err(bad(format!(
            "range-coded stream of {len} bytes (valid: 0..={})",
            rest.len()
        )));
    }
    Ok(rest.split_at(len as usize))
}

/// Encoding 4's range-coded and raw streams, after the scale codes.
fn split_streams(stream: &[u8]) -> Result<(&[u8], &[u8])> {
    let Some((len, rest)) = stream.split_first_chunk::<4>() else {
        return Err(Error::corrupt(
            "column payload",
            format!("{} bytes after the scale codes (valid: ≥ 4)", stream.len()),
        ));
    };
    let len = u32::from_le_bytes(*len) as usize;
    if len > rest.len() {
        return Err(Error::corrupt(
            "column payload",
            format!(
                "range-coded stream of {len} bytes (valid: 0..={})",
                rest.len()
            ),
        ));
    }
    Ok(rest.split_at(len))
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A random column: shape, depth, and about `density` of its positions
    /// kept with values whose bit lengths follow `spread`.
    pub(in crate::entropy) fn column(
        (w, h, channels, bits): (usize, usize, usize, u32),
        depth_pick: u32,
        density: f64,
        seed: u64,
    ) -> (SparseColumn, ColumnShape) {
        let shape = ColumnShape {
            width: w,
            height: h,
            channels,
            bits,
        };
        let depth = depth_pick % (max_levels(w, h) + 1);
        let mut s = seed | 1;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s
        };
        let max = (1i64 << (bits - 1)) - 1;
        let mut col = SparseColumn {
            depth,
            // Random, zero or repeated codes (encoding 5 codes each kind
            // its own way).
            scale_codes: (0..(depth as usize + 1) * channels)
                .map(|_| match next() % 3 {
                    0 => next() as u16,
                    1 => 0,
                    _ => 33_000,
                })
                .collect(),
            ..Default::default()
        };
        for i in 0..w * h {
            if (next() % 10_000) as f64 >= density * 10_000.0 {
                continue;
            }
            let mut vals = [0i32; MAX_CHANNELS];
            while vals[..channels].iter().all(|&v| v == 0) {
                for v in vals.iter_mut().take(channels) {
                    let len = next() % bits as u64;
                    let m = (next() % (1 << len)) as i64;
                    let m = m.min(max);
                    *v = if next() % 2 == 0 { m as i32 } else { -m as i32 };
                }
            }
            col.indices.push(i as u32);
            col.values.extend_from_slice(&vals[..channels]);
        }
        (col, shape)
    }

    fn codings() -> impl Strategy<Value = ValueCoding> {
        prop::sample::select(vec![
            ValueCoding::ExpGolomb,
            ValueCoding::Classes,
            ValueCoding::Compact,
        ])
    }

    fn shapes() -> impl Strategy<Value = (usize, usize, usize, u32)> {
        (
            1usize..40,
            1usize..40,
            prop::sample::select(vec![1usize, 3]),
            2u32..=16,
        )
    }

    proptest! {
        #[test]
        fn columns_round_trip(shape in shapes(), d in 0u32..8, density in 0.0f64..1.0, seed in any::<u64>(), coding in codings()) {
            let (col, shape) = column(shape, d, density, seed);
            let bytes = encode(&col, &shape, coding).unwrap();
            let back = decode(&bytes, col.indices.len(), &shape, col.depth, coding, None).unwrap();
            prop_assert_eq!(back, col);
        }

        #[test]
        fn truncated_or_altered_payloads_fail_cleanly(shape in shapes(), d in 0u32..8, density in 0.01f64..0.5, seed in any::<u64>(), cut in any::<prop::sample::Index>(), flip in any::<prop::sample::Index>(), coding in codings()) {
            let (col, shape) = column(shape, d, density, seed);
            let bytes = encode(&col, &shape, coding).unwrap();
            let n = col.indices.len();
            let _ = decode(&bytes[..cut.index(bytes.len() + 1)], n, &shape, col.depth, coding, None);
            let mut altered = bytes.clone();
            if !altered.is_empty() {
                let k = flip.index(altered.len());
                altered[k] ^= 0x5A;
            }
            if let Ok(back) = decode(&altered, n, &shape, col.depth, coding, None) {
                // Whatever decodes is a valid column of the shape.
                prop_assert_eq!(back.indices.len(), n);
                prop_assert!(back.indices.windows(2).all(|p| p[0] < p[1]));
                prop_assert!(back.indices.iter().all(|&i| (i as usize) < shape.width * shape.height));
                let max = (1i32 << (shape.bits - 1)) - 1;
                prop_assert!(back.values.iter().all(|v| v.abs() <= max));
            }
        }

        #[test]
        fn random_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..200), shape in shapes(), d in 0u32..8, nnz in 0usize..2000, coding in codings()) {
            let depth = d % (max_levels(shape.0, shape.1) + 1);
            let shape = ColumnShape { width: shape.0, height: shape.1, channels: shape.2, bits: shape.3 };
            let _ = decode(&bytes, nnz, &shape, depth, coding, None);
        }
    }

    #[test]
    fn a_wrong_count_is_an_error() {
        let (col, shape) = column((32, 24, 3, 12), 3, 0.1, 7);
        for coding in [
            ValueCoding::ExpGolomb,
            ValueCoding::Classes,
            ValueCoding::Compact,
        ] {
            let bytes = encode(&col, &shape, coding).unwrap();
            let n = col.indices.len();
            assert!(decode(&bytes, n + 1, &shape, 3, coding, None).is_err());
            assert!(decode(
                &bytes,
                shape.width * shape.height + 1,
                &shape,
                3,
                coding,
                None
            )
            .is_err());
            // Shorter than its scale codes; far too short for its nonzeros.
            assert!(decode(&bytes[..4 * 3 * 2 - 1], n, &shape, 3, coding, None).is_err());
            assert!(decode(&bytes[..4 * 3 * 2 + 2], n, &shape, 3, coding, None).is_err());
        }
    }

    /// Encoding 4 codes the same column in fewer range-coded symbols than
    /// encoding 3, at about its size, and refuses a stream length that
    /// does not fit the payload.
    #[test]
    fn classes_code_the_same_column_about_as_small() {
        let (col, shape) = column((64, 48, 3, 12), 4, 0.2, 11);
        let v3 = encode(&col, &shape, ValueCoding::ExpGolomb).unwrap();
        let v4 = encode(&col, &shape, ValueCoding::Classes).unwrap();
        let ratio = v4.len() as f64 / v3.len() as f64;
        assert!(
            (0.9..1.05).contains(&ratio),
            "{} vs {} bytes",
            v4.len(),
            v3.len()
        );
        let scales = 5 * 3 * 2;
        let mut bad = v4.clone();
        let len = u32::from_le_bytes(bad[scales..scales + 4].try_into().unwrap());
        bad[scales..scales + 4].copy_from_slice(&(len + (v4.len() - scales) as u32).to_le_bytes());
        let n = col.indices.len();
        assert!(decode(&bad, n, &shape, 4, ValueCoding::Classes, None).is_err());
        // A payload of one encoding read as the other fails or decodes
        // something else; it never panics.
        let _ = decode(&v3, n, &shape, 4, ValueCoding::Classes, None);
        let _ = decode(&v4, n, &shape, 4, ValueCoding::ExpGolomb, None);
    }

    /// Encoding 5 is encoding 4 less the scale codes' and the length's
    /// fixed bytes, plus a few bits; its varint is checked.
    #[test]
    fn compact_framing_saves_the_fixed_bytes() {
        let (mut col, shape) = column((96, 72, 1, 16), 5, 0.01, 5);
        col.scale_codes = vec![33_000, 33_000, 0, 33_000, 33_000, 33_000];
        let v4 = encode(&col, &shape, ValueCoding::Classes).unwrap();
        let v5 = encode(&col, &shape, ValueCoding::Compact).unwrap();
        // 12 bytes of codes and a 4-byte length against a 1- or 2-byte
        // varint, 16 raw bits and a few modelled ones.
        let saved = v4.len() as i64 - v5.len() as i64;
        assert!(
            (11..=14).contains(&saved),
            "{} vs {} bytes",
            v5.len(),
            v4.len()
        );
        let n = col.indices.len();
        assert_eq!(
            decode(&v5, n, &shape, 5, ValueCoding::Compact, None).unwrap(),
            col
        );
        let rest = |v: &[u8]| -> Vec<u8> {
            let at = v.iter().position(|&b| b < 0x80).unwrap() + 1;
            v[at..].to_vec()
        };
        let r = rest(&v5);
        let len = v5.len() - r.len();
        let mut too_long = Vec::new();
        put_varint(&mut too_long, r.len() as u32 + 1);
        for (varint, says) in [
            (vec![0x80 | r.len() as u8, 0x00], "redundant zero"),
            (vec![0xFF; 5], "longer than 5"),
            (vec![0x80], "runs past"),
            (too_long, "valid: 0..="),
        ] {
            let mut bad = varint.clone();
            if !says.contains("runs past") {
                bad.extend_from_slice(&r);
            }
            let e = decode(&bad, n, &shape, 5, ValueCoding::Compact, None).unwrap_err();
            assert!(e.to_string().contains(says), "{len}: {e}");
        }
    }

    #[test]
    fn all_zero_positions_round_trip() {
        let shape = ColumnShape {
            width: 4,
            height: 4,
            channels: 1,
            bits: 8,
        };
        let col = SparseColumn {
            depth: 0,
            scale_codes: vec![1],
            indices: vec![3],
            values: vec![0],
        };
        for coding in [
            ValueCoding::ExpGolomb,
            ValueCoding::Classes,
            ValueCoding::Compact,
        ] {
            let bytes = encode(&col, &shape, coding).unwrap();
            assert_eq!(decode(&bytes, 1, &shape, 0, coding, None).unwrap(), col);
        }
    }

    /// The ratio's 64-bit path gives the exact value at the edges where it
    /// hands over to the 128-bit one.
    #[test]
    fn ratio_is_exact_at_the_edges_of_its_fast_path() {
        let exact = |sxy: i64, sxx: i64| -> i64 {
            if sxx == 0 {
                return 0;
            }
            let num = sxy as i128 * (1 << 17) + sxx as i128;
            num.div_euclid(2 * sxx as i128).clamp(-(1 << 20), 1 << 20) as i64
        };
        let edges = [
            0,
            1,
            7,
            12_345,
            (1 << 45) - 1,
            1 << 45,
            1 << 50,
            i64::MAX >> 2,
        ];
        for &a in &edges {
            for sxy in [a, -a] {
                for sxx in [1, 2, 3, 1000, 1 << 31, (1 << 60) - 1, 1 << 60, 1 << 61] {
                    assert_eq!(ratio(sxy, sxx), exact(sxy, sxx), "{sxy} / {sxx}");
                }
            }
        }
        assert_eq!(ratio(3, 4), 49_152);
        assert_eq!(ratio(-1, 3), -21_845);
    }

    #[test]
    fn bands_tile_the_image() {
        for (w, h) in [(1, 1), (5, 3), (16, 16), (33, 7), (96, 72)] {
            for depth in 0..=max_levels(w, h) {
                let mut hits = vec![0u8; w * h];
                for b in bands(w, h, depth) {
                    for y in b.rect.y0..b.rect.y0 + b.rect.h {
                        for x in b.rect.x0..b.rect.x0 + b.rect.w {
                            hits[y * w + x] += 1;
                        }
                    }
                }
                assert!(hits.iter().all(|&c| c == 1), "{w}×{h} at depth {depth}");
            }
        }
    }
}
