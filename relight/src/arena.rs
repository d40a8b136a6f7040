//! The compact arena: every column of a file decoded once at open into the
//! form the multiply-add streams, 8 bytes per RGB coefficient and 4 per grey
//! one (Cheslack-Postava et al. 2007 §4.5 keeps the matrix in memory in its
//! compressed form; this is the decoded form closest to it).
//!
//! A coefficient is stored as its quantized value `q` (an `i16`: the coder
//! writes `|q| ≤ 2^(bits−1) − 1 ≤ 32767`) per channel, then one `u16`
//! *code*: the coefficient's band (high bits) and its position within its
//! pixel block (low bits). A band is the low band (0) or one orientation of
//! one level's detail bands (`1 + 3·(level − 1) + orientation`, orientation 0
//! = right of the low band, 1 = below, 2 = diagonal). Every coefficient of a
//! band shares its scale group's quantizer step and its band weight, so the
//! value the old `f32` arena held, `q·s/Q / w`, is `q · f_band` with one
//! factor per (column, band, channel) kept beside the column. A frame
//! multiplies the factors by the light once per column and band
//! ([`Arena::light_tables`]); the kernels then do one multiply-add per
//! coefficient and channel.
//!
//! Columns are cut into pixel blocks (at least [`MIN_BLOCKS`], each at most
//! `2^offset_bits` pixels so that the position fits beside the band), with
//! the offset of every block boundary kept, so that a frame can split the
//! multiply-add into pixel ranges of equal work without searching.

use crate::error::{RelightError, Result};
use ltm_codec::container::{LtmFile, Meta, SparseColumn};
use ltm_codec::wavelet::band_size;
use ltm_codec::BandWeights;
use ltm_codec::ColumnDecoder;
use rayon::prelude::*;

/// The fewest pixel blocks a column is cut into.
pub(crate) const MIN_BLOCKS: usize = 64;

/// Bands of a column transformed to `depth`: the low band and three
/// orientations per level.
pub(crate) fn bands(depth: u32) -> usize {
    3 * depth as usize + 1
}

/// Band of every position of a `width` × `height` column image at `depth`
/// (numbered as in the module docs).
pub(crate) fn band_map(width: usize, height: usize, depth: u32) -> Vec<u8> {
    let mut map = vec![0u8; width * height];
    for k in 1..=depth {
        let (pw, ph) = band_size(width, height, k - 1);
        let (lw, lh) = band_size(width, height, k);
        for y in 0..ph {
            for x in 0..pw {
                let o = match (x >= lw, y >= lh) {
                    (false, false) => continue,
                    (true, false) => 0,
                    (false, true) => 1,
                    (true, true) => 2,
                };
                map[y * width + x] = (1 + 3 * (k - 1) + o) as u8;
            }
        }
    }
    map
}

/// The scale group of band `b` ([`ltm_codec::quant::scale_groups`]).
fn band_group(b: usize) -> usize {
    if b == 0 {
        0
    } else {
        (b - 1) / 3 + 1
    }
}

/// How codes split into band and in-block position.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct CodeLayout {
    /// The position's bits: `code & mask`; the band is `code >> shift`.
    pub shift: u32,
    /// Pixels per block (the last block may be shorter).
    pub block_pixels: usize,
    /// Number of blocks.
    pub blocks: usize,
}

impl CodeLayout {
    /// The layout for `pixels` pixels and columns of depth up to `max_depth`.
    pub fn new(pixels: usize, max_depth: u32) -> CodeLayout {
        let band_bits = usize::BITS - (bands(max_depth) - 1).leading_zeros();
        let shift = 16 - band_bits.max(1);
        let blocks = MIN_BLOCKS.max(pixels.div_ceil(1 << shift));
        CodeLayout {
            shift,
            block_pixels: pixels.div_ceil(blocks).max(1),
            blocks,
        }
    }

    /// The in-block position mask.
    #[cfg(test)]
    pub fn mask(&self) -> u16 {
        ((1u32 << self.shift) - 1) as u16
    }
}

/// Band maps and band weights of every depth, for building the arena.
struct Bands {
    maps: Vec<Vec<u8>>,
    /// Per depth, per band: the band's weight (1 for an empty band).
    weights: Vec<Vec<f64>>,
}

impl Bands {
    fn new(meta: &Meta) -> Bands {
        let (w, h) = (meta.dims.width() as usize, meta.dims.height() as usize);
        let bw = BandWeights::new(meta.col_filter, w, h, meta.max_depth());
        let maps: Vec<Vec<u8>> = (0..=meta.max_depth()).map(|d| band_map(w, h, d)).collect();
        let weights = maps
            .iter()
            .enumerate()
            .map(|(d, map)| {
                let mut out = vec![1.0f64; bands(d as u32)];
                let mut seen = vec![false; out.len()];
                for (&b, &wt) in map.iter().zip(bw.map(d as u32)) {
                    if !seen[b as usize] {
                        (seen[b as usize], out[b as usize]) = (true, wt as f64);
                    }
                }
                out
            })
            .collect();
        Bands { maps, weights }
    }
}

/// One column in arena form, before it is appended.
struct ArenaColumn {
    /// `channels + 1` values per coefficient: `q` per channel, then the code.
    entries: Vec<i16>,
    /// Offsets of the block boundaries within the column's coefficients.
    block_index: Vec<u32>,
    /// Per band: the channel factors (grey: the one factor three times),
    /// lane 3 zero.
    factors: Vec<[f32; 4]>,
    depth: u8,
    /// L2 norm of the column's weighted values (the transport priority).
    norm: f32,
}

/// Every column of a file in compact form.
pub(crate) struct Arena {
    /// 1 (grey) or 3 (RGB).
    pub channels: usize,
    pub layout: CodeLayout,
    /// `channels + 1` `i16` per coefficient.
    pub entries: Vec<i16>,
    /// Column `j`'s coefficients are `starts[j]..starts[j + 1]`.
    pub starts: Vec<usize>,
    /// Column `j`'s entries in block `b` are `starts[j] + block_index[j·(blocks
    /// + 1) + b] ..` up to the next boundary's offset.
    pub block_index: Vec<u32>,
    /// Column `j`'s band factors are `factors[factor_starts[j]..]`, one per
    /// band of its depth.
    pub factors: Vec<[f32; 4]>,
    pub factor_starts: Vec<usize>,
    pub depths: Vec<u8>,
    pub norms: Vec<f32>,
}

impl Arena {
    /// Bytes per coefficient for `channels` channels.
    pub fn entry_bytes(channels: usize) -> usize {
        2 * (channels + 1)
    }

    /// Decodes every column of `file` (in parallel).
    pub fn build(file: &LtmFile, decoder: &ColumnDecoder) -> Result<Arena> {
        let meta = file.meta();
        let dims = meta.dims;
        let channels = dims.channels as usize;
        let layout = CodeLayout::new(dims.pixels(), meta.max_depth());
        let bands = Bands::new(meta);
        let columns: Vec<ArenaColumn> = (0..dims.lights())
            .into_par_iter()
            .map(|j| {
                let col = file.column(j)?;
                arena_column(&col, j, meta, &layout, &bands, decoder)
            })
            .collect::<Result<_>>()?;
        let total: usize = columns.iter().map(|c| c.entries.len()).sum();
        let total_factors: usize = columns.iter().map(|c| c.factors.len()).sum();
        let mut arena = Arena {
            channels,
            layout,
            entries: Vec::with_capacity(total),
            starts: Vec::with_capacity(columns.len() + 1),
            block_index: Vec::with_capacity(columns.len() * (layout.blocks + 1)),
            factors: Vec::with_capacity(total_factors),
            factor_starts: Vec::with_capacity(columns.len() + 1),
            depths: Vec::with_capacity(columns.len()),
            norms: Vec::with_capacity(columns.len()),
        };
        arena.starts.push(0);
        arena.factor_starts.push(0);
        for c in columns {
            arena.entries.extend_from_slice(&c.entries);
            arena.starts.push(arena.entries.len() / (channels + 1));
            arena.block_index.extend_from_slice(&c.block_index);
            arena.factors.extend_from_slice(&c.factors);
            arena.factor_starts.push(arena.factors.len());
            arena.depths.push(c.depth);
            arena.norms.push(c.norm);
        }
        Ok(arena)
    }

    /// Coefficients held.
    pub fn nonzeros(&self) -> usize {
        self.entries.len() / (self.channels + 1)
    }

    /// Column `j`'s block boundaries.
    pub fn offsets(&self, j: usize) -> &[u32] {
        &self.block_index[j * (self.layout.blocks + 1)..][..self.layout.blocks + 1]
    }

    /// Column `j`'s entries from block `b0` up to block `b1`.
    pub fn entries(&self, j: usize, b0: usize, b1: usize) -> &[i16] {
        let (s, o) = (self.starts[j], self.offsets(j));
        let e = self.channels + 1;
        &self.entries[e * (s + o[b0] as usize)..e * (s + o[b1] as usize)]
    }

    /// Column `j`'s band factors.
    pub fn factors(&self, j: usize) -> &[[f32; 4]] {
        &self.factors[self.factor_starts[j]..self.factor_starts[j + 1]]
    }

    /// The light tables of `group`'s columns, appended to `out`: per column,
    /// per band, the light's channels times the band factors (lane 3 zero).
    /// `starts[k]` is column `group[k]`'s first table.
    pub fn light_tables(
        &self,
        group: &[u32],
        light: &[[f32; 3]],
        out: &mut Vec<[f32; 4]>,
        starts: &mut Vec<usize>,
    ) {
        out.clear();
        starts.clear();
        for &j in group {
            starts.push(out.len());
            let l = light[j as usize];
            out.extend(
                self.factors(j as usize)
                    .iter()
                    .map(|f| [l[0] * f[0], l[1] * f[1], l[2] * f[2], 0.0]),
            );
        }
    }

    /// The value the multiply-add gives coefficient `k` of column `j` in
    /// channel `c` (for tests): `q · f_band`.
    #[cfg(test)]
    pub fn value(&self, j: usize, k: usize, c: usize) -> f32 {
        let e = self.channels + 1;
        let entry = &self.entries[e * (self.starts[j] + k)..][..e];
        let band = (entry[self.channels] as u16 >> self.layout.shift) as usize;
        let q = entry[if self.channels == 1 { 0 } else { c }] as f32;
        self.factors(j)[band][c] * q
    }
}

/// Column `j` in arena form, with its priority norm.
fn arena_column(
    col: &SparseColumn,
    j: usize,
    meta: &Meta,
    layout: &CodeLayout,
    bands: &Bands,
    decoder: &ColumnDecoder,
) -> Result<ArenaColumn> {
    let channels = meta.dims.channels as usize;
    let depth = col.depth as usize;
    let (map, weights) = (&bands.maps[depth], &bands.weights[depth]);
    let q = (1u64 << (meta.bits - 1)) as f64 - 1.0;
    let mut factors = Vec::with_capacity(weights.len());
    for (b, w) in weights.iter().enumerate() {
        let mut f = [0.0f32; 4];
        for (c, fc) in f.iter_mut().take(3).enumerate() {
            let v = decoder.step(col, band_group(b), if channels == 1 { 0 } else { c }) / w;
            *fc = v as f32;
            if !fc.is_finite() || (*fc as f64 * q).abs() > ColumnDecoder::MAX_DECODED as f64 {
                return Err(RelightError::Invalid(format!(
                    "column {j}: band {b} decodes to {v:.3e} per step, beyond {:.3e}",
                    ColumnDecoder::MAX_DECODED
                )));
            }
        }
        factors.push(f);
    }
    let mut entries = Vec::with_capacity(col.indices.len() * (channels + 1));
    for (k, &i) in col.indices.iter().enumerate() {
        for c in 0..channels {
            let v = col.values[k * channels + c];
            let q = i16::try_from(v).map_err(|_| {
                RelightError::Invalid(format!(
                    "column {j}: quantized value {v} outside the i16 range of a {}-bit file",
                    meta.bits
                ))
            })?;
            entries.push(q);
        }
        let i = i as usize;
        let offset = i % layout.block_pixels;
        let band = map[i] as usize;
        entries.push(((band << layout.shift) | offset) as u16 as i16);
    }
    // Positions are sorted (the container stores them as gaps).
    let block_index = (0..=layout.blocks)
        .map(|b| {
            col.indices
                .partition_point(|&i| (i as usize) < b * layout.block_pixels) as u32
        })
        .collect();
    Ok(ArenaColumn {
        entries,
        block_index,
        factors,
        depth: col.depth as u8,
        norm: decoder.weighted_norm(col) as f32,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use ltm_codec::{Dims, Meta};

    /// Band maps agree with the codec's scale groups, at odd sizes and every
    /// depth, and code layouts always fit the position and band.
    #[test]
    fn band_maps_refine_scale_groups_and_codes_fit() {
        for (w, h) in [(1, 1), (1, 7), (5, 3), (16, 16), (33, 17), (256, 256)] {
            let max = ltm_codec::wavelet::max_levels(w, h);
            let meta = Meta {
                dims: Dims::image(w as u32, h as u32, 1, 1),
                mode: ltm_codec::Mode::Adaptive,
                row_filter: ltm_codec::Filter::Haar,
                col_filter: ltm_codec::Filter::LeGall53,
                bits: 12,
                seed: 0,
                target_error: 0.0,
                achieved_error: 0.0,
                terms: 0,
                norm: 1.0,
            };
            let decoder = ColumnDecoder::new(&meta);
            for d in 0..=max {
                let map = band_map(w, h, d);
                for (i, b) in map.iter().enumerate() {
                    assert!((*b as usize) < bands(d));
                    let g = decoder.scale_group(d, i);
                    assert_eq!(band_group(*b as usize), g as usize, "{w}x{h} depth {d}");
                }
            }
            let l = CodeLayout::new(w * h, max);
            assert!(l.block_pixels <= 1 << l.shift && l.blocks * l.block_pixels >= w * h);
            assert!(bands(max) <= 1 << (16 - l.shift));
        }
        for (p, d) in [(1 << 20, 10), (1 << 24, 12), (7, 15)] {
            let l = CodeLayout::new(p, d);
            assert!(l.block_pixels <= 1 << l.shift && l.blocks * l.block_pixels >= p);
            assert!(bands(d) <= 1 << (16 - l.shift), "{p} {d}");
        }
    }
}

/// The arena against the codec's own dequantization on compressed files of
/// hard cases.
#[cfg(test)]
mod file_tests {
    use super::*;
    use ltm_codec::compress::{compress, CodeOptions, Target};
    use ltm_codec::{Dims, Filter, Mode, RawHeader, RawStore, RawWriter};

    /// A raw store of `w × h` pixels, face resolution 2, with zero columns,
    /// constant columns and values spread over `scale·(1e-6..1e5)`.
    fn store(dir: &std::path::Path, w: u32, h: u32, channels: u32, scale: f32) -> RawStore {
        let dims = Dims::image(w, h, 2, channels);
        let mut writer =
            RawWriter::create(&dir.join("t.raw"), RawHeader::new(dims, false, 1 << 24)).unwrap();
        let (p, m, c) = (dims.pixels(), dims.lights(), channels as usize);
        let rows: Vec<f32> = (0..p * m * c)
            .map(|k| {
                let (i, j) = (k / (m * c), (k / c) % m);
                match j % 4 {
                    0 => 0.0,
                    1 => scale,
                    _ => {
                        let e = ((i * 7 + j * 13 + k) % 12) as f32 - 6.0;
                        scale * 10f32.powf(e) * if (i + j) % 3 == 0 { 1.0 } else { 0.5 }
                    }
                }
            })
            .collect();
        writer.write_block(0, &rows, None).unwrap();
        RawStore::open(&writer.finish().unwrap()).unwrap()
    }

    /// Every arena value `q·f_band` is the codec's `q·s/Q / w` within 4 ulp
    /// (the factor is rounded once, the old value twice), for every bit
    /// depth, grey and RGB, odd sizes, both filter kinds and every mode;
    /// every code addresses its coefficient's own block, offset and band.
    #[test]
    fn arena_values_match_the_codec_dequantization() {
        let dir = tempfile::tempdir().unwrap();
        for (w, h, channels, scale) in [(5, 3, 1, 1e-6f32), (9, 7, 3, 1e5), (16, 16, 3, 1.0)] {
            let raw = store(dir.path(), w, h, channels, scale);
            for bits in 2..=16 {
                let (mode, filter) = match bits % 3 {
                    0 => (Mode::Adaptive, Filter::LeGall53),
                    1 => (Mode::FourD, Filter::Cdf97),
                    _ => (Mode::TwoD, Filter::D4),
                };
                let out = dir.path().join("t.ltm");
                let opts = CodeOptions {
                    mode,
                    col_filter: filter,
                    bits,
                    target: Target::MaxError(1e-3),
                    ..Default::default()
                };
                compress(&raw, &out, &opts.into(), &|_, _, _| {}).unwrap();
                let file = LtmFile::open(&out).unwrap();
                let meta = file.meta().clone();
                let decoder = ColumnDecoder::new(&meta);
                let arena = Arena::build(&file, &decoder).unwrap();
                let weights =
                    BandWeights::new(meta.col_filter, w as usize, h as usize, meta.max_depth());
                let l = arena.layout;
                for j in 0..meta.dims.lights() {
                    let col = file.column(j).unwrap();
                    let map = band_map(w as usize, h as usize, col.depth);
                    assert_eq!(arena.starts[j + 1] - arena.starts[j], col.indices.len());
                    // The norm, from scales decoded once per group, is the
                    // per-value dequantization's, exactly.
                    let per_value: f64 = (0..col.indices.len())
                        .flat_map(|k| (0..channels as usize).map(move |c| (k, c)))
                        .map(|(k, c)| (decoder.dequantize(&col, k, c) as f64).powi(2))
                        .sum();
                    assert_eq!(arena.norms[j], per_value.sqrt() as f32);
                    for (k, &i) in col.indices.iter().enumerate() {
                        let i = i as usize;
                        let e = &arena.entries[(channels as usize + 1) * (arena.starts[j] + k)..];
                        let code = e[channels as usize] as u16;
                        assert_eq!((code >> l.shift) as u8, map[i]);
                        assert_eq!((code & l.mask()) as usize, i % l.block_pixels);
                        let block = i / l.block_pixels;
                        let o = arena.offsets(j);
                        assert!(o[block] as usize <= k && k < o[block + 1] as usize);
                        for c in 0..3 {
                            let fc = if channels == 1 { 0 } else { c };
                            let old = decoder.dequantize(&col, k, fc) / weights.map(col.depth)[i];
                            let new = arena.value(j, k, c);
                            assert!(
                                (new - old).abs() <= 4.0 * f32::EPSILON * old.abs(),
                                "{w}x{h}x{channels} {bits} bits col {j} pos {i}: {new} vs {old}"
                            );
                        }
                    }
                }
                // The whole frame: level-recursive sum against eq. 3, with
                // the fast kernel and the interleaved inverse steps.
                let relighter = crate::Relighter::open(&out).unwrap();
                let light: Vec<[f32; 3]> = (0..meta.dims.lights())
                    .map(|j| [1.0 + j as f32, 0.5, (j % 3) as f32 * 1e3])
                    .collect();
                for terms in [1, 5, usize::MAX] {
                    let request = crate::Request {
                        terms,
                        weighting: crate::Weighting::Transport,
                    };
                    let mut frame = crate::Relight::frame(&relighter);
                    crate::Relight::relight(&relighter, &light, &request, &mut frame).unwrap();
                    let naive = relighter.relight_naive(&light, &request).unwrap();
                    assert!(frame.image.first_non_finite().is_none());
                    let diff = crate::relative_l2(&frame.image, &naive).unwrap();
                    assert!(
                        diff <= 2e-6,
                        "{w}x{h}x{channels} {bits} bits N={terms}: {diff}"
                    );
                }
            }
        }
    }
}
