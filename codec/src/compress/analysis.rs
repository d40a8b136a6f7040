//! Step 3a, the analysis of a target-error run (Cheslack-Postava et al.
//! 2007 §4.3–4.4): for every column and candidate depth, a histogram of the
//! weighted squared coefficient magnitudes (summed over channels) in
//! half-octave bins around a first threshold guess τ0, and the statistics of
//! the quantizer's steps. [`Plan::new`](super::Plan::new) turns them into a
//! global threshold and per-column depths without touching the columns again.
//!
//! An [`Analysis`] covers a range of columns and is serializable; analyses
//! of adjacent ranges [`merge`](Analysis::merge) into the analysis of their
//! union, so a sharded compressor can analyze each shard, merge, plan once
//! and code each shard.

use super::code::Coder;
use super::Mode;
use crate::error::{Error, Result};
use crate::progress::{Progress, Stage};
use crate::wavelet::{max_levels, Filter};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::ops::Range;

/// Squared-magnitude histogram window used by the analysis.
pub(super) const BINS: usize = 64;
/// Bins per octave of squared magnitude.
pub(super) const BINS_PER_OCTAVE: f64 = 2.0;

/// Histogram bin of a squared magnitude `e`: bin `BINS/2` starts at τ0²;
/// bin 0 also holds everything below the window, bin `BINS − 1` everything
/// above.
pub(super) fn bin_of(e: f64, tau0_sq: f64) -> usize {
    let b = ((e / tau0_sq).log2() * BINS_PER_OCTAVE).floor() + (BINS / 2) as f64;
    b.clamp(0.0, (BINS - 1) as f64) as usize
}

/// Lower edge (a squared magnitude) of bin `b`.
pub(super) fn bin_threshold(b: usize, tau0_sq: f64) -> f64 {
    tau0_sq * 2f64.powf((b as f64 - (BINS / 2) as f64) / BINS_PER_OCTAVE)
}

/// The depths a column may take in `mode`.
pub(super) fn candidate_depths(mode: Mode, max_depth: u32) -> Vec<u32> {
    match mode {
        Mode::TwoD => vec![0],
        Mode::FourD => vec![max_depth],
        // Refused by `CodeOptions::validate`.
        Mode::Adaptive | Mode::Pca => (0..=max_depth).collect(),
    }
}

/// What an [`Analysis`] depends on: analyses merge only when these are equal,
/// and a plan codes only a matrix and options with the same settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AnalysisSettings {
    /// Image width W (column image width).
    pub width: u32,
    /// Image height H.
    pub height: u32,
    /// Stored channels C.
    pub channels: u32,
    /// The matrix's columns M (all of them, not only the analyzed range).
    pub lights: usize,
    /// Transform mode: gives the candidate depths.
    pub mode: Mode,
    /// Column image filter: gives the band weights.
    pub col_filter: Filter,
    /// First threshold guess τ0² (from the whole matrix and the target
    /// error): places the histogram bins.
    pub tau0_sq: f64,
}

impl AnalysisSettings {
    /// The candidate depths of every column.
    pub fn depths(&self) -> Vec<u32> {
        let max_depth = max_levels(self.width as usize, self.height as usize);
        candidate_depths(self.mode, max_depth)
    }

    /// The number of candidate depths, `depths().len()`.
    pub fn depth_count(&self) -> usize {
        match self.mode {
            Mode::TwoD | Mode::FourD => 1,
            Mode::Adaptive | Mode::Pca => {
                max_levels(self.width as usize, self.height as usize) as usize + 1
            }
        }
    }

    /// Equal settings, or an error naming the first field that differs.
    pub(super) fn check_same(&self, other: &AnalysisSettings, what: &'static str) -> Result<()> {
        let fields: [(&'static str, String, String); 7] = [
            ("width", other.width.to_string(), self.width.to_string()),
            ("height", other.height.to_string(), self.height.to_string()),
            (
                "channels",
                other.channels.to_string(),
                self.channels.to_string(),
            ),
            ("lights", other.lights.to_string(), self.lights.to_string()),
            ("mode", other.mode.name().into(), self.mode.name().into()),
            (
                "column filter",
                other.col_filter.to_string(),
                self.col_filter.to_string(),
            ),
            (
                "tau0²",
                format!("{:e}", other.tau0_sq),
                format!("{:e}", self.tau0_sq),
            ),
        ];
        match fields.into_iter().find(|f| f.1 != f.2) {
            Some((field, found, expected)) => Err(Error::SettingsDiffer {
                what,
                field,
                found,
                expected,
            }),
            None => Ok(()),
        }
    }
}

/// The analysis of a range of columns: per column and candidate depth
/// (`D` of them, [`AnalysisSettings::depths`]), a `BINS`-bin histogram of
/// (count, energy) of weighted squared magnitudes and the quantizer
/// statistics. Made by [`Coder::analyze`]; deserializing validates every
/// length, so a plan never indexes out of range.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "Unchecked")]
pub struct Analysis {
    settings: AnalysisSettings,
    columns: Range<usize>,
    /// Count per bin, at `((j − start)·D + d)·BINS + b`.
    counts: Vec<u32>,
    /// Energy (sum of squared magnitudes) per bin, same layout, in f64: the
    /// squares of f32 values span 2^-298 to 2^256.
    energies: Vec<f64>,
    /// Per column and depth, `(j − start)·D + d`: Σ over nonzero positions
    /// of their scale group's squared peak magnitude.
    peak_sq: Vec<f64>,
    /// Per column and depth: nonzero positions.
    nonzeros: Vec<u32>,
}

/// An [`Analysis`] as deserialized, before its lengths are checked.
#[derive(Deserialize)]
struct Unchecked {
    settings: AnalysisSettings,
    columns: Range<usize>,
    counts: Vec<u32>,
    energies: Vec<f64>,
    peak_sq: Vec<f64>,
    nonzeros: Vec<u32>,
}

impl TryFrom<Unchecked> for Analysis {
    type Error = Error;

    fn try_from(u: Unchecked) -> Result<Analysis> {
        let s = &u.settings;
        if s.width == 0 || s.height == 0 || !(1..=3).contains(&s.channels) || s.lights == 0 {
            return Err(Error::corrupt(
                "analysis",
                "empty image, light set or channels",
            ));
        }
        if !(s.tau0_sq.is_finite() && s.tau0_sq > 0.0) {
            return Err(Error::range("analysis tau0²", s.tau0_sq, "finite and > 0"));
        }
        if u.columns.start > u.columns.end || u.columns.end > s.lights {
            return Err(Error::range(
                "analysis columns",
                format!("{}..{}", u.columns.start, u.columns.end),
                format!("a range within 0..{}", s.lights),
            ));
        }
        let stats = u.columns.len().checked_mul(s.depth_count());
        let bins = stats.and_then(|n| n.checked_mul(BINS));
        let lengths = [
            u.counts.len(),
            u.energies.len(),
            u.peak_sq.len(),
            u.nonzeros.len(),
        ];
        if [bins, bins, stats, stats] != lengths.map(Some) {
            return Err(Error::corrupt(
                "analysis",
                "statistics do not match the column range",
            ));
        }
        if let Some(v) = u
            .energies
            .iter()
            .chain(&u.peak_sq)
            .find(|v| !(**v >= 0.0 && v.is_finite()))
        {
            return Err(Error::range("analysis energy", v, "finite and ≥ 0"));
        }
        Ok(Analysis {
            settings: u.settings,
            columns: u.columns,
            counts: u.counts,
            energies: u.energies,
            peak_sq: u.peak_sq,
            nonzeros: u.nonzeros,
        })
    }
}

impl Analysis {
    /// An empty analysis of `start..start`, to extend with [`Analysis::push`].
    fn empty(settings: AnalysisSettings, start: usize) -> Analysis {
        Analysis {
            settings,
            columns: start..start,
            counts: Vec::new(),
            energies: Vec::new(),
            peak_sq: Vec::new(),
            nonzeros: Vec::new(),
        }
    }

    /// The settings the analysis was made with.
    pub fn settings(&self) -> &AnalysisSettings {
        &self.settings
    }

    /// The columns analyzed.
    pub fn columns(&self) -> Range<usize> {
        self.columns.clone()
    }

    /// The analysis of `self`'s columns followed by `next`'s: `next` must
    /// start where `self` ends and have the same settings.
    pub fn merge(mut self, next: Analysis) -> Result<Analysis> {
        self.settings.check_same(&next.settings, "analysis merge")?;
        if next.columns.start != self.columns.end {
            return Err(Error::ColumnRange {
                what: "analysis merge",
                start: next.columns.start,
                end: next.columns.end,
                expected: self.columns.end,
                total: self.settings.lights,
            });
        }
        self.columns.end = next.columns.end;
        self.counts.extend(next.counts);
        self.energies.extend(next.energies);
        self.peak_sq.extend(next.peak_sq);
        self.nonzeros.extend(next.nonzeros);
        Ok(self)
    }

    /// The analysis of the sub-range `columns` of `self`'s columns.
    pub fn for_columns(&self, columns: Range<usize>) -> Result<Analysis> {
        let all = &self.columns;
        if columns.start > columns.end || columns.start < all.start || columns.end > all.end {
            return Err(Error::range(
                "analysis columns",
                format!("{}..{}", columns.start, columns.end),
                format!("a range within {}..{}", all.start, all.end),
            ));
        }
        let nd = self.settings.depth_count();
        let stats = (columns.start - all.start) * nd..(columns.end - all.start) * nd;
        let bins = stats.start * BINS..stats.end * BINS;
        Ok(Analysis {
            settings: self.settings.clone(),
            columns,
            counts: self.counts[bins.clone()].to_vec(),
            energies: self.energies[bins].to_vec(),
            peak_sq: self.peak_sq[stats.clone()].to_vec(),
            nonzeros: self.nonzeros[stats].to_vec(),
        })
    }

    /// Appends the next column's statistics.
    fn push(&mut self, column: ColumnStats) {
        self.columns.end += 1;
        self.counts.extend(column.counts);
        self.energies.extend(column.energies);
        self.peak_sq.extend(column.peak_sq);
        self.nonzeros.extend(column.nonzeros);
    }

    /// Histogram (counts, energies) and quantizer statistics (Σ squared
    /// peaks, nonzeros) of column `j` at the candidate depth of index `di`.
    pub(super) fn stats(&self, j: usize, di: usize) -> (&[u32], &[f64], (f64, u32)) {
        let k = (j - self.columns.start) * self.settings.depth_count() + di;
        (
            &self.counts[k * BINS..(k + 1) * BINS],
            &self.energies[k * BINS..(k + 1) * BINS],
            (self.peak_sq[k], self.nonzeros[k]),
        )
    }
}

/// One column's statistics at every candidate depth.
struct ColumnStats {
    counts: Vec<u32>,
    energies: Vec<f64>,
    peak_sq: Vec<f64>,
    nonzeros: Vec<u32>,
}

impl Coder<'_> {
    /// Analyzes `columns` for this coder's target error: the input of
    /// [`Plan::new`](super::Plan::new). `progress` gets
    /// ([`Stage::Analysis`], columns done, columns in the range).
    pub fn analyze(&self, columns: Range<usize>, progress: Progress<'_>) -> Result<Analysis> {
        self.transposed().check_columns(&columns)?;
        let (channels, p) = (self.channels(), self.transposed().dims().pixels());
        let mut analysis = Analysis::empty(self.analysis_settings()?, columns.start);
        for batch in self.transposed().batches(columns.clone()) {
            let data = self.transposed().read_columns(batch.clone())?;
            let stats: Vec<ColumnStats> = data
                .par_chunks(channels * p)
                .map_init(
                    || (vec![0.0f32; channels * p], vec![0.0f32; p]),
                    |(coefs, work), planes| {
                        self.column_stats(planes, &analysis.settings, coefs, work)
                    },
                )
                .collect::<Result<_>>()?;
            stats.into_iter().for_each(|s| analysis.push(s));
            let done = batch.end - columns.start;
            progress.report(Stage::Analysis, done as u64, columns.len() as u64);
        }
        Ok(analysis)
    }

    /// The statistics of one column (`planes`: C × P pixel-domain values) at
    /// every candidate depth.
    fn column_stats(
        &self,
        planes: &[f32],
        settings: &AnalysisSettings,
        coefs: &mut [f32],
        work: &mut [f32],
    ) -> Result<ColumnStats> {
        let nd = self.depths().len();
        let mut s = ColumnStats {
            counts: vec![0; nd * BINS],
            energies: vec![0.0; nd * BINS],
            peak_sq: Vec::with_capacity(nd),
            nonzeros: Vec::with_capacity(nd),
        };
        for (di, &d) in self.depths().iter().enumerate() {
            self.weighted(planes, d, coefs, work)?;
            let bins = di * BINS..(di + 1) * BINS;
            let (peak_sq, nonzeros) = depth_stats(
                |i| self.energy(coefs, i),
                self.scale_groups(d),
                d,
                settings.tau0_sq,
                &mut s.counts[bins.clone()],
                &mut s.energies[bins],
            );
            s.peak_sq.push(peak_sq);
            s.nonzeros.push(nonzeros);
        }
        Ok(s)
    }
}

/// The histogram of one column at one depth (`energy(i)`: the squared
/// weighted magnitude of position `i`, summed over channels; `groups`: the
/// scale group of every position at `depth`) into `counts` and `energies`;
/// returns (Σ over nonzero positions of their scale group's squared peak,
/// nonzero positions). The quantizer's step in a group is its peak over `Q`.
pub(super) fn depth_stats(
    energy: impl Fn(usize) -> f64,
    groups: &[u8],
    depth: u32,
    tau0_sq: f64,
    counts: &mut [u32],
    energies: &mut [f64],
) -> (f64, u32) {
    let mut peak = vec![(0.0f64, 0u32); depth as usize + 1];
    for (i, &group) in groups.iter().enumerate() {
        let e = energy(i);
        if e > 0.0 {
            let bin = bin_of(e, tau0_sq);
            counts[bin] += 1;
            energies[bin] += e;
            let g = &mut peak[group as usize];
            g.0 = g.0.max(e);
            g.1 += 1;
        }
    }
    let qsum = peak.iter().map(|(e, n)| e * *n as f64).sum::<f64>();
    let nonzero = peak.iter().map(|(_, n)| n).sum::<u32>();
    (qsum, nonzero)
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;

    /// Settings of a one-channel 4×4 image, 24 lights, adaptive (3 depths).
    pub(in crate::compress) fn settings() -> AnalysisSettings {
        AnalysisSettings {
            width: 4,
            height: 4,
            channels: 1,
            lights: 24,
            mode: Mode::Adaptive,
            col_filter: Filter::LeGall53,
            tau0_sq: 0.25,
        }
    }

    /// A hand-made analysis of `columns` whose statistics encode the column
    /// index, so that ranges can be told apart.
    pub(in crate::compress) fn analysis(columns: Range<usize>) -> Analysis {
        let mut a = Analysis::empty(settings(), columns.start);
        for j in columns {
            let nd = a.settings.depth_count();
            a.push(ColumnStats {
                counts: (0..nd * BINS).map(|k| (j * 1000 + k) as u32).collect(),
                energies: (0..nd * BINS).map(|k| (j + k) as f64 * 0.5).collect(),
                peak_sq: (0..nd).map(|d| (j + d) as f64).collect(),
                nonzeros: (0..nd).map(|d| (j * 10 + d) as u32).collect(),
            });
        }
        a
    }

    #[test]
    fn bins_place_their_thresholds() {
        let tau0_sq = 0.25;
        assert_eq!(bin_of(tau0_sq, tau0_sq), BINS / 2);
        assert_eq!(bin_threshold(BINS / 2, tau0_sq), tau0_sq);
        for b in 1..BINS - 1 {
            let t = bin_threshold(b, tau0_sq);
            assert_eq!(bin_of(t * 1.0001, tau0_sq), b, "bin {b}");
            assert_eq!(bin_of(t * 0.9999, tau0_sq), b - 1, "bin {b}");
        }
        assert_eq!(bin_of(1e-300, tau0_sq), 0);
        assert_eq!(bin_of(1e300, tau0_sq), BINS - 1);
    }

    #[test]
    fn merged_halves_equal_the_whole_and_sub_ranges_round_trip() {
        let whole = analysis(3..20);
        let merged = analysis(3..11).merge(analysis(11..20)).unwrap();
        assert_eq!(merged, whole);
        assert_eq!(whole.for_columns(3..11).unwrap(), analysis(3..11));
        assert_eq!(whole.for_columns(11..20).unwrap(), analysis(11..20));
        assert_eq!(whole.for_columns(7..7).unwrap(), analysis(7..7));
        assert!(whole.for_columns(2..11).is_err());
        assert!(whole.for_columns(11..21).is_err());
    }

    #[test]
    fn bad_merges_are_typed_errors() {
        // A gap, an overlap and the wrong order.
        for (a, b) in [(0..5, 6..9), (0..5, 4..9), (5..9, 0..5)] {
            let err = analysis(a.clone()).merge(analysis(b.clone())).unwrap_err();
            match err {
                Error::ColumnRange {
                    start, expected, ..
                } => assert_eq!((start, expected), (b.start, a.end)),
                e => panic!("{e}"),
            }
        }
        let mut other = analysis(5..9);
        other.settings.mode = Mode::FourD;
        let err = analysis(0..5).merge(other).unwrap_err();
        assert!(
            matches!(err, Error::SettingsDiffer { field: "mode", .. }),
            "{err}"
        );
        assert!(err.to_string().contains("4d") && err.to_string().contains("adaptive"));
    }

    #[test]
    fn serde_round_trips_and_checks_lengths() {
        let a = analysis(2..6);
        let json = serde_json::to_string(&a).unwrap();
        let back: Analysis = serde_json::from_str(&json).unwrap();
        assert_eq!(back, a);
        let mut v: serde_json::Value = serde_json::from_str(&json).unwrap();
        v["columns"]["end"] = 7.into();
        assert!(serde_json::from_value::<Analysis>(v.clone()).is_err());
        v["columns"]["end"] = 99.into();
        assert!(serde_json::from_value::<Analysis>(v).is_err());
        let mut v: serde_json::Value = serde_json::from_str(&json).unwrap();
        v["peak_sq"].as_array_mut().unwrap().pop();
        assert!(serde_json::from_value::<Analysis>(v).is_err());
        let mut v: serde_json::Value = serde_json::from_str(&json).unwrap();
        v["settings"]["tau0_sq"] = 0.0.into();
        assert!(serde_json::from_value::<Analysis>(v).is_err());
        let mut v: serde_json::Value = serde_json::from_str(&json).unwrap();
        v["energies"][3] = (-1.0).into();
        let err = serde_json::from_value::<Analysis>(v)
            .unwrap_err()
            .to_string();
        assert!(err.contains("energy = -1"), "{err}");
        let mut v: serde_json::Value = serde_json::from_str(&json).unwrap();
        v["peak_sq"][0] = 1e300.into();
        v["energies"][0] = 1e300.into();
        assert!(
            serde_json::from_value::<Analysis>(v).is_ok(),
            "f64 holds any squared f32"
        );
    }
}
