//! The compact arena: every column of a file decoded once, the first time a
//! frame needs it, into the form the multiply-add streams, 8 bytes per RGB
//! coefficient and 4 per grey one (Cheslack-Postava et al. 2007 §4.5 keeps
//! the matrix in memory in its compressed form; this is the decoded form
//! closest to it). Columns are independent in the file, so a frame with N
//! lights needs only its N columns: opening keeps none (it decodes each
//! once only to check its stored norm), and a relight
//! with N = 200 of a 1536-light file decodes 13 % of its columns (about a
//! fifth of its coefficients: low-frequency lights have the densest
//! columns).
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
use crate::slots::Slots;
use ltm_codec::bands::{band_count, band_level, band_map};
use ltm_codec::column::SparseColumn;
use ltm_codec::container::{LtmFile, Meta};
use ltm_codec::BandWeights;
use ltm_codec::ColumnDecoder;
use rayon::prelude::*;
use std::sync::OnceLock;

/// The fewest pixel blocks a column is cut into.
pub(crate) const MIN_BLOCKS: usize = 64;

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
        let band_bits = usize::BITS - (band_count(max_depth) - 1).leading_zeros();
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
    fn new(meta: &Meta, bw: &BandWeights) -> Bands {
        let (w, h) = (meta.dims.width() as usize, meta.dims.height() as usize);
        let maps: Vec<Vec<u8>> = (0..=bw.max_depth()).map(|d| band_map(w, h, d)).collect();
        let weights = maps
            .iter()
            .enumerate()
            .map(|(d, map)| {
                let mut out = vec![1.0f64; band_count(d as u32)];
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

/// What a decoded column keeps beside its entries and block offsets.
struct ColumnInfo {
    /// Per band: the channel factors (grey: the one factor three times),
    /// lane 3 zero.
    factors: Vec<[f32; 4]>,
    /// L2 norm of the column's weighted values (the transport priority).
    norm: f32,
}

/// A decoded column, as a frame reads it.
#[derive(Clone, Copy)]
pub(crate) struct ArenaColumn<'a> {
    /// `channels + 1` values per coefficient: `q` per channel, then the code.
    entries: &'a [i16],
    /// Offsets of the block boundaries within the column's coefficients.
    offsets: &'a [u32],
    factors: &'a [[f32; 4]],
}

impl<'a> ArenaColumn<'a> {
    /// The block boundaries.
    pub fn offsets(&self) -> &'a [u32] {
        self.offsets
    }

    /// The entries from block `b0` up to block `b1` (`channels + 1` per
    /// coefficient).
    pub fn entries(&self, channels: usize, b0: usize, b1: usize) -> &'a [i16] {
        let (o, e) = (self.offsets, channels + 1);
        &self.entries[e * o[b0] as usize..e * o[b1] as usize]
    }

    /// The band factors.
    pub fn factors(&self) -> &'a [[f32; 4]] {
        self.factors
    }

    /// Bytes held.
    fn bytes(&self) -> usize {
        2 * self.entries.len() + 4 * self.offsets.len() + 16 * self.factors.len()
    }
}

/// Every column of a file in compact form, each decoded the first time a
/// frame needs it (or all at once by [`Arena::decode_all`]): a frame with N
/// lights decodes at most N columns, so a file opens without keeping any.
/// Columns lie end to end in column order in one buffer sized from the
/// column table ([`crate::slots`]), as a frame streams them fastest.
pub(crate) struct Arena {
    /// 1 (grey) or 3 (RGB).
    pub channels: usize,
    pub layout: CodeLayout,
    /// Per column: its transform depth (from the column table).
    pub depths: Vec<u8>,
    /// Coefficients of all columns (from the column table).
    nonzeros: usize,
    bands: Bands,
    /// Per column: its entries and block offsets.
    slots: Slots<i16, u32>,
    /// Per column: its factors and norm, set before its slots are
    /// published.
    info: Vec<OnceLock<ColumnInfo>>,
    /// The decoded columns' norms, once every column is decoded (for a file
    /// that does not store them).
    decoded_norms: OnceLock<Vec<f32>>,
    /// Set once every norm the file stores was checked against its column.
    norms_checked: OnceLock<()>,
}

impl Arena {
    /// Bytes per coefficient for `channels` channels.
    pub fn entry_bytes(channels: usize) -> usize {
        2 * (channels + 1)
    }

    /// The arena of `file` (whose decoder is `decoder`), with no column
    /// decoded yet. The caller has checked the entries' size against its
    /// limits.
    pub fn new(file: &LtmFile, decoder: &ColumnDecoder) -> Arena {
        let meta = file.meta();
        let dims = meta.dims;
        let channels = dims.channels as usize;
        let layout = CodeLayout::new(dims.pixels(), meta.max_depth());
        let columns = file.columns();
        Arena {
            channels,
            layout,
            depths: columns.iter().map(|c| c.depth).collect(),
            nonzeros: columns.iter().map(|c| c.nnz as usize).sum(),
            bands: Bands::new(meta, decoder.band_weights()),
            slots: Slots::new(
                columns.iter().map(|c| c.nnz as usize * (channels + 1)),
                layout.blocks + 1,
            ),
            info: (0..dims.lights()).map(|_| OnceLock::new()).collect(),
            decoded_norms: OnceLock::new(),
            norms_checked: OnceLock::new(),
        }
    }

    /// Column `j`, if decoded.
    pub fn column(&self, j: usize) -> Option<ArenaColumn<'_>> {
        let (entries, offsets) = self.slots.get(j)?;
        let info = self.info.get(j)?.get()?;
        Some(ArenaColumn {
            entries,
            offsets,
            factors: &info.factors,
        })
    }

    /// Decodes the columns of `group` that are not decoded yet (in
    /// parallel) and puts every column of `group`, in order, in `out`.
    /// Returns how many it decoded.
    pub fn columns<'a>(
        &'a self,
        group: &[u32],
        file: &LtmFile,
        decoder: &ColumnDecoder,
        out: &mut Vec<ArenaColumn<'a>>,
    ) -> Result<usize> {
        // Once the columns are decoded (every frame but the first few),
        // nothing is gathered.
        let mut missing = Vec::new();
        if !group.iter().all(|&j| self.slots.is_ready(j as usize)) {
            missing.extend(
                group
                    .iter()
                    .map(|&j| j as usize)
                    .filter(|&j| !self.slots.is_ready(j)),
            );
            self.decode(&missing, file, decoder)?;
        }
        out.clear();
        for &j in group {
            out.push(
                self.column(j as usize).ok_or_else(|| {
                    RelightError::Invalid(format!("column {j} is not in the arena"))
                })?,
            );
        }
        Ok(missing.len())
    }

    /// Decodes every column not decoded yet.
    pub fn decode_all(&self, file: &LtmFile, decoder: &ColumnDecoder) -> Result<()> {
        let missing: Vec<usize> = (0..self.depths.len())
            .filter(|&j| !self.slots.is_ready(j))
            .collect();
        self.decode(&missing, file, decoder)
    }

    /// Decodes columns `js` in parallel; a column another thread is
    /// decoding is waited for. A column whose norm differs from the one the
    /// file stores is refused (the file is damaged; the relighter's open has
    /// checked every stored norm already).
    fn decode(&self, js: &[usize], file: &LtmFile, decoder: &ColumnDecoder) -> Result<()> {
        let meta = file.meta();
        js.par_iter().try_for_each(|&j| {
            let Some(mut claim) = self.slots.claim(j) else {
                return Ok(()); // decoded meanwhile
            };
            let (entries, offsets) = claim.parts();
            let col = file.column(j)?;
            let info = arena_column(&col, j, meta, self, decoder, entries, offsets)?;
            if let Some(&stored) = file.column_norms().and_then(|n| n.get(j)) {
                // Checked for every column at open too (`Relighter::new`).
                ColumnDecoder::check_norm(j, stored, info.norm)?;
            }
            // Only this claim's holder sets it; a holder that failed set
            // nothing.
            let _ = self.info[j].set(info);
            claim.publish();
            Ok(())
        })
    }

    /// Every column's priority norm: the file's (chunk NORM, versions 5 to
    /// 7), each checked against its decoded column before the first use
    /// (so no light is ranked by an unchecked norm), else those of the
    /// decoded columns. Either way, the first time, each column not yet in
    /// the arena is decoded once for its norm and not kept; a column in the
    /// arena gives the norm it was decoded with (and checked against the
    /// file's, if any, when it was decoded).
    pub fn norms<'a>(&'a self, file: &'a LtmFile, decoder: &ColumnDecoder) -> Result<&'a [f32]> {
        if let Some(stored) = file.column_norms() {
            if self.norms_checked.get().is_none() {
                let decoded = self.column_norms(file, decoder)?;
                for (j, (&s, &d)) in stored.iter().zip(&decoded).enumerate() {
                    ColumnDecoder::check_norm(j, s, d)?;
                }
                let _ = self.norms_checked.set(());
            }
            return Ok(stored);
        }
        if let Some(n) = self.decoded_norms.get() {
            return Ok(n);
        }
        let norms = self.column_norms(file, decoder)?;
        Ok(self.decoded_norms.get_or_init(|| norms))
    }

    /// The norm of every column as decoded: from the arena where it holds
    /// the column, else decoded in parallel ([`ColumnDecoder::weighted_norm`]),
    /// not kept.
    fn column_norms(&self, file: &LtmFile, decoder: &ColumnDecoder) -> Result<Vec<f32>> {
        (0..self.depths.len())
            .into_par_iter()
            .map(|j| match self.info[j].get() {
                Some(info) => Ok(info.norm),
                None => Ok(decoder.weighted_norm(&file.column(j)?) as f32),
            })
            .collect()
    }

    /// Coefficients of all columns, decoded or not.
    pub fn nonzeros(&self) -> usize {
        self.nonzeros
    }

    /// Bytes of the columns decoded so far.
    pub fn held_bytes(&self) -> usize {
        let columns: usize = (0..self.depths.len())
            .filter_map(|j| self.column(j))
            .map(|c| c.bytes())
            .sum();
        columns + 4 * self.decoded_norms.get().map_or(0, Vec::len)
    }

    /// The light tables of `group`'s columns, appended to `out`: per column,
    /// per band, the light's channels times the band factors (lane 3 zero).
    /// `starts[k]` is column `group[k]`'s first table.
    pub fn light_tables(
        group: &[u32],
        columns: &[ArenaColumn<'_>],
        light: &[[f32; 3]],
        out: &mut Vec<[f32; 4]>,
        starts: &mut Vec<usize>,
    ) {
        out.clear();
        starts.clear();
        for (&j, col) in group.iter().zip(columns) {
            starts.push(out.len());
            let l = light[j as usize];
            out.extend(
                col.factors()
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
        let col = self.column(j).expect("decoded");
        let entry = &col.entries[e * k..][..e];
        let band = (entry[self.channels] as u16 >> self.layout.shift) as usize;
        let q = entry[if self.channels == 1 { 0 } else { c }] as f32;
        col.factors[band][c] * q
    }
}

/// Column `j` in arena form: its entries and block offsets written into
/// `entries` and `offsets` (sized from the column table), its factors and
/// priority norm returned.
fn arena_column(
    col: &SparseColumn,
    j: usize,
    meta: &Meta,
    arena: &Arena,
    decoder: &ColumnDecoder,
    entries: &mut [i16],
    offsets: &mut [u32],
) -> Result<ColumnInfo> {
    let (layout, channels) = (&arena.layout, arena.channels);
    let depth = col.depth as usize;
    let (map, weights) = (&arena.bands.maps[depth], &arena.bands.weights[depth]);
    let q = (1u64 << (meta.bits - 1)) as f64 - 1.0;
    let mut factors = Vec::with_capacity(weights.len());
    for (b, w) in weights.iter().enumerate() {
        let mut f = [0.0f32; 4];
        for (c, fc) in f.iter_mut().take(3).enumerate() {
            let v = decoder.step(col, band_level(b), if channels == 1 { 0 } else { c }) / w;
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
    if entries.len() != col.indices.len() * (channels + 1) || offsets.len() != layout.blocks + 1 {
        return Err(RelightError::Invalid(format!(
            "column {j}: decodes to {} coefficients, its table entry says {}",
            col.indices.len(),
            entries.len() / (channels + 1)
        )));
    }
    for ((&i, entry), values) in col
        .indices
        .iter()
        .zip(entries.chunks_exact_mut(channels + 1))
        .zip(col.values.chunks_exact(channels))
    {
        for (e, &v) in entry.iter_mut().zip(values) {
            *e = i16::try_from(v).map_err(|_| {
                RelightError::Invalid(format!(
                    "column {j}: quantized value {v} outside the i16 range of a {}-bit file",
                    meta.bits
                ))
            })?;
        }
        let i = i as usize;
        let offset = i % layout.block_pixels;
        let band = map[i] as usize;
        entry[channels] = ((band << layout.shift) | offset) as u16 as i16;
    }
    // Positions are sorted (the container stores them as gaps).
    for (b, o) in offsets.iter_mut().enumerate() {
        *o = col
            .indices
            .partition_point(|&i| (i as usize) < b * layout.block_pixels) as u32;
    }
    Ok(ColumnInfo {
        factors,
        norm: decoder.weighted_norm(col) as f32,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use ltm_codec::{Dims, Limits, Meta};

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
            let decoder = ColumnDecoder::new(&meta, &Limits::default()).unwrap();
            for d in 0..=max {
                let map = band_map(w, h, d);
                for (i, b) in map.iter().enumerate() {
                    assert!((*b as usize) < band_count(d));
                    let g = decoder.scale_group(d, i);
                    assert_eq!(band_level(*b as usize), g as usize, "{w}x{h} depth {d}");
                }
            }
            let l = CodeLayout::new(w * h, max);
            assert!(l.block_pixels <= 1 << l.shift && l.blocks * l.block_pixels >= w * h);
            assert!(band_count(max) <= 1 << (16 - l.shift));
        }
        for (p, d) in [(1 << 20, 10), (1 << 24, 12), (7, 15)] {
            let l = CodeLayout::new(p, d);
            assert!(l.block_pixels <= 1 << l.shift && l.blocks * l.block_pixels >= p);
            assert!(band_count(d) <= 1 << (16 - l.shift), "{p} {d}");
        }
    }
}

/// The arena against the codec's own dequantization on compressed files of
/// hard cases.
#[cfg(test)]
mod file_tests {
    use super::*;
    use ltm_codec::compress::{compress, CodeOptions, Target};
    use ltm_codec::{Dims, Filter, Limits, Mode, RawHeader, RawStore, RawWriter};

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
                compress(&raw, &out, &opts.into(), ltm_codec::Progress::NONE).unwrap();
                let file = LtmFile::open(&out).unwrap();
                let meta = file.meta().clone();
                let decoder = ColumnDecoder::new(&meta, &Limits::default()).unwrap();
                let arena = Arena::new(&file, &decoder);
                assert_eq!(arena.held_bytes(), 0);
                arena.decode_all(&file, &decoder).unwrap();
                let norms = arena.norms(&file, &decoder).unwrap();
                let (wu, hu) = (w as usize, h as usize);
                let weights = BandWeights::new(
                    meta.col_filter,
                    wu,
                    hu,
                    meta.max_depth(),
                    &Limits::default(),
                )
                .unwrap();
                let l = arena.layout;
                for (j, &norm) in norms.iter().enumerate() {
                    let col = file.column(j).unwrap();
                    let map = band_map(w as usize, h as usize, col.depth);
                    let ac = arena.column(j).unwrap();
                    assert_eq!(
                        ac.entries.len(),
                        col.indices.len() * (channels as usize + 1)
                    );
                    assert_eq!(ac.offsets.len(), l.blocks + 1);
                    // The norm, from scales decoded once per group, is the
                    // per-value dequantization's, exactly, and the one the
                    // relighter ranks by.
                    let per_value: f64 = (0..col.indices.len())
                        .flat_map(|k| (0..channels as usize).map(move |c| (k, c)))
                        .map(|(k, c)| (decoder.dequantize(&col, k, c) as f64).powi(2))
                        .sum();
                    let info_norm = arena.info[j].get().unwrap().norm;
                    assert_eq!(info_norm, per_value.sqrt() as f32);
                    assert_eq!(norm, info_norm);
                    for (k, &i) in col.indices.iter().enumerate() {
                        let i = i as usize;
                        let e = &ac.entries[(channels as usize + 1) * k..];
                        let code = e[channels as usize] as u16;
                        assert_eq!((code >> l.shift) as u8, map[i]);
                        assert_eq!((code & l.mask()) as usize, i % l.block_pixels);
                        let block = i / l.block_pixels;
                        let o = ac.offsets();
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
                    let mut frame = crate::Relight::frame(&relighter).unwrap();
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
