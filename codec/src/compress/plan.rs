//! Step 3b, the plan (Cheslack-Postava et al. 2007 §4.3–4.4): from an
//! [`Analysis`], one global threshold τ and each column's two best depths
//! minimising `nonzeros + error/τ²` — the Lagrangian of size under a total
//! error budget — with τ the largest threshold whose estimated total error
//! fits the budget. A term-count target needs no analysis: every column
//! keeps its N largest coefficients and tries every candidate depth.
//!
//! The error of a column at a depth is estimated from its histogram alone:
//! values in bins below τ are dropped (their energy is the error); a kept
//! value of magnitude `x` is dither-quantized with step `Δ`, which costs
//! `f(1 − f)·Δ²` on average for `f` the fractional part of `x/Δ`: `Δ²/6` for
//! `x ≥ Δ`, `x(Δ − x)` below. That is more than dropping it (`x²`) when
//! `x < Δ/2`, so those are dropped (as the quantizer does). The uniform
//! quantizer's step is tied to τ ([`Quantizer::step`]) and rounds: a kept
//! value costs `(x − Δ)²` up to `1.5·Δ` and `Δ²/12` beyond.

use super::analysis::{bin_threshold, Analysis, AnalysisSettings, BINS, BINS_PER_OCTAVE};
use super::Quantizer;
use crate::bytes::{Reader, Writer};
use crate::error::{Error, Result};
use crate::quant::levels;
use serde::{Deserialize, Serialize};
use std::ops::Range;

/// The quantizer a threshold plan is made for, at its bits.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct QuantSpec {
    /// Which quantizer.
    pub quantizer: Quantizer,
    /// Its bits, 2..=16.
    pub bits: u32,
}

impl QuantSpec {
    /// The peak quantizer at `bits`.
    pub fn peak(bits: u32) -> QuantSpec {
        QuantSpec {
            quantizer: Quantizer::Peak,
            bits,
        }
    }

    /// The uniform quantizer at `bits`.
    pub fn uniform(bits: u32) -> QuantSpec {
        QuantSpec {
            quantizer: Quantizer::Uniform,
            bits,
        }
    }

    /// How the estimate models a kept value's step at the threshold
    /// `tau_sq` of `channels` channels.
    fn model(self, tau_sq: f64, channels: usize) -> StepModel {
        match self.quantizer.step(tau_sq, channels) {
            Some(step) => StepModel::Rounded(step),
            None => StepModel::Dithered(levels(self.bits) as f64),
        }
    }
}

/// A kept value's step in the estimate.
#[derive(Clone, Copy, Debug)]
pub(super) enum StepModel {
    /// Dithered, with the column's RMS group peak over these levels.
    Dithered(f64),
    /// Rounded to this step.
    Rounded(f64),
}

/// How a plan keeps coefficients.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub(super) enum Rule {
    /// Positions whose squared weighted magnitude is at least τ².
    Above(f64),
    /// The N largest positions of each column.
    Largest(usize),
}

/// What the coder keeps of each column, and at which depths it tries them.
/// Deserializing validates every field, so that a plan read from a file
/// never indexes out of range.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "UncheckedPlan")]
pub struct Plan {
    rule: Rule,
    /// The analysis settings, bits and quantizer a threshold plan was made
    /// for.
    made_for: Option<(AnalysisSettings, QuantSpec)>,
    /// The columns of `choice`.
    columns: Range<usize>,
    /// Per column: the best and the runner-up depth by estimate.
    choice: Vec<[u32; 2]>,
    /// The estimated total squared error at τ (threshold plans; 0 for a
    /// term count).
    estimate: f64,
    /// The part of `estimate` that is quantization error of kept values
    /// (modelled; the rest is the energy of dropped values, counted).
    quantization: f64,
    /// Each column is coded at its best depth only (a re-coding that keeps
    /// the first coding's depths).
    fixed: bool,
}

/// A [`Plan`] as deserialized, before its fields are checked.
#[derive(Deserialize)]
struct UncheckedPlan {
    rule: Rule,
    made_for: Option<(AnalysisSettings, QuantSpec)>,
    columns: Range<usize>,
    choice: Vec<[u32; 2]>,
    estimate: f64,
    quantization: f64,
    fixed: bool,
}

impl TryFrom<UncheckedPlan> for Plan {
    type Error = Error;

    fn try_from(u: UncheckedPlan) -> Result<Plan> {
        for (what, v) in [
            ("plan estimate", u.estimate),
            ("plan quantization", u.quantization),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(Error::range(what, v, "finite and ≥ 0"));
            }
        }
        match (u.rule, &u.made_for) {
            (Rule::Largest(n), None) if n >= 1 && u.choice.is_empty() => {}
            (Rule::Above(tau_sq), Some((settings, spec))) => {
                check_threshold_plan(tau_sq, settings, spec.bits, &u.columns, &u.choice)?
            }
            (rule, _) => {
                return Err(Error::corrupt(
                    "plan",
                    format!("rule {rule:?} with the wrong analysis settings or depth choices"),
                ))
            }
        }
        Ok(Plan {
            rule: u.rule,
            made_for: u.made_for,
            columns: u.columns,
            choice: u.choice,
            estimate: u.estimate,
            quantization: u.quantization,
            fixed: u.fixed,
        })
    }
}

/// A threshold plan's fields are in range: τ² finite and ≥ 0, bits 2..=16,
/// a column range within the matrix, and one pair of candidate depths per
/// column.
fn check_threshold_plan(
    tau_sq: f64,
    settings: &AnalysisSettings,
    bits: u32,
    columns: &Range<usize>,
    choice: &[[u32; 2]],
) -> Result<()> {
    if !(tau_sq.is_finite() && tau_sq >= 0.0) {
        return Err(Error::range("plan threshold τ²", tau_sq, "finite and ≥ 0"));
    }
    if !(2..=16).contains(&bits) {
        return Err(Error::range("plan bits", bits, "2..=16"));
    }
    if settings.width == 0 || settings.height == 0 || settings.lights == 0 {
        return Err(Error::corrupt("plan", "empty image or light set"));
    }
    if columns.start > columns.end || columns.end > settings.lights {
        return Err(Error::range(
            "plan columns",
            format!("{}..{}", columns.start, columns.end),
            format!("a range within 0..{}", settings.lights),
        ));
    }
    let valid = settings.depths();
    if choice.len() != columns.len() || choice.iter().flatten().any(|d| !valid.contains(d)) {
        return Err(Error::corrupt(
            "plan",
            format!(
                "{} depth choices for {} columns, each one of {valid:?}",
                choice.len(),
                columns.len()
            ),
        ));
    }
    Ok(())
}

impl Plan {
    /// The plan of a target-error run: the largest threshold τ (a bin edge
    /// of the analysis) whose estimated total error over `analysis`'s columns
    /// is at most `budget` (a squared error, `(E·‖T‖)²` for a relative
    /// target `E`), and each column's best two depths at that τ, for the
    /// quantizer `spec`. When no threshold fits, τ = 0 and every column
    /// keeps every nonzero value.
    pub fn new(analysis: &Analysis, spec: QuantSpec, budget: f64) -> Result<Plan> {
        Plan::below(analysis, spec, budget, f64::INFINITY)
    }

    /// [`Plan::new`] with a threshold τ² below `max_tau_sq`: a re-coding
    /// after a miss lowers τ even where the estimate does not move it (the
    /// estimated error is flat over a gap in the histogram, while the
    /// coder's depth choices, which weigh error by 1/τ², depend on τ).
    pub(super) fn below(
        analysis: &Analysis,
        spec: QuantSpec,
        budget: f64,
        max_tau_sq: f64,
    ) -> Result<Plan> {
        check_plan_args(spec.bits, budget)?;
        let mut fallback = None;
        let tau0_sq = analysis.settings().tau0_sq;
        for b in (0..BINS).rev() {
            let tau_sq = bin_threshold(b, tau0_sq);
            if tau_sq >= max_tau_sq {
                continue;
            }
            let (err, choice) = choose(analysis, b, spec);
            if err[0] <= budget {
                return Ok(Plan::threshold(analysis, spec, tau_sq, choice, err));
            }
            fallback = Some((choice, err));
        }
        let (choice, err) = fallback.unwrap_or_else(|| {
            let (err, choice) = choose(analysis, 0, spec);
            (choice, err)
        });
        Ok(Plan::threshold(analysis, spec, 0.0, choice, err))
    }

    /// The plan whose estimated error, calibrated by a coding's measured
    /// error (`ratio`: the dropped energy and the quantization error are
    /// multiplied by their own factors), is `budget`: the threshold τ² is
    /// interpolated (linearly in `log τ²`) between the two bin edges whose
    /// calibrated estimates bracket the budget, so that a second coding
    /// lands on the target instead of on the safe bin edge below it.
    pub fn calibrated(
        analysis: &Analysis,
        spec: QuantSpec,
        budget: f64,
        ratio: Calibration,
    ) -> Result<Plan> {
        check_plan_args(spec.bits, budget)?;
        for r in [ratio.dropped, ratio.quantization] {
            if !(r > 0.0 && r.is_finite()) {
                return Err(Error::range("error calibration ratio", r, "finite and > 0"));
            }
        }
        let tau0_sq = analysis.settings().tau0_sq;
        let mut above: Option<([f64; 2], f64)> = None;
        for b in (0..BINS).rev() {
            let (err, choice) = choose(analysis, b, spec);
            let cal = ratio.apply(err);
            if cal <= budget {
                let edge = bin_threshold(b, tau0_sq);
                let (tau_sq, estimate) = match above {
                    Some((hi, cal_hi)) if cal_hi > cal => {
                        let t = ((budget - cal) / (cal_hi - cal)).clamp(0.0, 1.0);
                        let mix = |k: usize| err[k] + t * (hi[k] - err[k]);
                        (edge * 2f64.powf(t / BINS_PER_OCTAVE), [mix(0), mix(1)])
                    }
                    _ => (edge, err),
                };
                return Ok(Plan::threshold(analysis, spec, tau_sq, choice, estimate));
            }
            above = Some((err, cal));
        }
        let (err, choice) = choose(analysis, 0, spec);
        Ok(Plan::threshold(analysis, spec, 0.0, choice, err))
    }

    fn threshold(
        analysis: &Analysis,
        spec: QuantSpec,
        tau_sq: f64,
        choice: Vec<[u32; 2]>,
        [estimate, quantization]: [f64; 2],
    ) -> Plan {
        Plan {
            rule: Rule::Above(tau_sq),
            made_for: Some((analysis.settings().clone(), spec)),
            columns: analysis.columns(),
            choice,
            estimate,
            quantization,
            fixed: false,
        }
    }

    /// The threshold plan at `tau_sq` exactly (not a bin edge) that codes
    /// each column of the analysis at the one depth `depths` gives it (in
    /// the analysis's column order): the re-coding that an [`ErrorCurve`]
    /// of a first coding calls for, at that coding's depths, where the
    /// curve holds.
    pub fn at_threshold(
        analysis: &Analysis,
        spec: QuantSpec,
        tau_sq: f64,
        depths: &[u32],
    ) -> Result<Plan> {
        check_plan_args(spec.bits, 0.0)?;
        if !(tau_sq > 0.0 && tau_sq.is_finite()) {
            return Err(Error::range("threshold τ²", tau_sq, "finite and > 0"));
        }
        let columns = analysis.columns();
        let valid = analysis.settings().depths();
        if depths.len() != columns.len() || depths.iter().any(|d| !valid.contains(d)) {
            return Err(Error::Invalid(format!(
                "{} fixed depths for {} columns, each one of {valid:?}",
                depths.len(),
                columns.len()
            )));
        }
        let mut plan = Plan::threshold(
            analysis,
            spec,
            tau_sq,
            depths.iter().map(|&d| [d, d]).collect(),
            [0.0, 0.0],
        );
        plan.fixed = true;
        Ok(plan)
    }

    /// Whether each column is coded at its best depth only.
    pub fn fixed_depths(&self) -> bool {
        self.fixed
    }

    /// The estimated total squared error of a threshold plan (0 for a term
    /// count).
    pub fn estimated_error(&self) -> f64 {
        self.estimate
    }

    /// The part of [`Plan::estimated_error`] that is modelled quantization
    /// error of the kept values (the rest is dropped energy).
    pub fn estimated_quantization(&self) -> f64 {
        self.quantization
    }

    /// The plan of a term-count target: every column keeps its `n` largest
    /// coefficients and tries every candidate depth (the paper's rule: less
    /// error wins; on ties, fewer nonzeros).
    pub fn keep(n: usize) -> Plan {
        Plan {
            rule: Rule::Largest(n),
            made_for: None,
            columns: 0..usize::MAX,
            choice: Vec::new(),
            estimate: 0.0,
            quantization: 0.0,
            fixed: false,
        }
    }

    /// The global threshold τ² on weighted squared magnitudes (summed over
    /// channels); 0 for a term-count plan, or when no threshold met the
    /// budget.
    pub fn tau_sq(&self) -> f64 {
        match self.rule {
            Rule::Above(tau_sq) => tau_sq,
            Rule::Largest(_) => 0.0,
        }
    }

    /// The best and runner-up depth of column `j` by estimate (`None` for a
    /// term-count plan or a column outside the plan).
    pub fn choice(&self, j: usize) -> Option<[u32; 2]> {
        let k = j.checked_sub(self.columns.start)?;
        self.choice.get(k).copied()
    }

    /// The columns the plan covers.
    pub fn columns(&self) -> Range<usize> {
        self.columns.clone()
    }

    pub(super) fn rule(&self) -> Rule {
        self.rule
    }

    /// The analysis settings and quantizer of a threshold plan.
    pub(super) fn made_for(&self) -> Option<&(AnalysisSettings, QuantSpec)> {
        self.made_for.as_ref()
    }
}

/// Bins per octave of squared magnitude of an [`ErrorCurve`].
const CURVE_BINS_PER_OCTAVE: f64 = 16.0;
/// Bins on each side of the coded threshold: 3 octaves.
const CURVE_BINS: usize = 48;

/// How a coding's measured error would change with the threshold near the
/// τ² it was coded at, from the coded columns themselves (their chosen
/// depths): raising τ² past a kept coefficient of weighted squared
/// magnitude `e` adds `e` less its quantization error; lowering it past a
/// dropped one removes `e` less the quantization error it would get. Fine
/// bins (1/16 octave) over 3 octaves on each side let one re-coding land
/// on the target; the coarse analysis histogram cannot. The sums are in
/// the weighted coefficient domain. Quantization noise (dithered, white)
/// costs the same in pixels; dropped coefficients of the lifting filters,
/// whose synthesis functions are not orthogonal, do not, so the dropped
/// energies are scaled by the coding's measured dropped error (measured
/// error less quantization error) over the curve's dropped energy.
#[derive(Clone, Debug, PartialEq)]
pub struct ErrorCurve {
    tau_sq: f64,
    /// Quantization error of the kept coefficients.
    quantization: f64,
    /// Energy of the dropped coefficients.
    dropped: f64,
    /// Per bin above τ²: (energy, quantization error) of the kept
    /// coefficients a rise of τ² through it drops.
    up: Vec<(f64, f64)>,
    /// Per bin below τ²: (energy, expected quantization error) of the
    /// dropped coefficients a fall of τ² through it keeps.
    down: Vec<(f64, f64)>,
    /// The uniform quantizer's error at each point of [`rounded_grid`]:
    /// every coefficient from τ²/8 up re-quantized there (0 for the peak
    /// quantizer).
    rounded: Vec<f64>,
    /// The energy of the coefficients below the grid's lowest threshold,
    /// which every point drops.
    rounded_below: f64,
}

/// Points of the uniform quantizer's grid: every quarter octave of τ²
/// over 3 octaves on each side.
pub(super) const ROUNDED_POINTS: usize = 25;

/// Octaves of τ² of the grid point `g` (0 at the centre).
fn rounded_octaves(g: usize) -> f64 {
    (g as f64 - (ROUNDED_POINTS / 2) as f64) / 4.0
}

/// The uniform quantizer's grid around `tau_sq` with step `step` there: at
/// each point, its threshold τ'² and step (which grows with τ').
pub(super) fn rounded_grid(tau_sq: f64, step: f64) -> [(f64, f64); ROUNDED_POINTS] {
    std::array::from_fn(|g| {
        let o = rounded_octaves(g);
        (tau_sq * 2f64.powf(o), step * 2f64.powf(o / 2.0))
    })
}

impl ErrorCurve {
    /// An empty curve around the threshold `tau_sq` (> 0).
    pub fn new(tau_sq: f64) -> ErrorCurve {
        ErrorCurve {
            tau_sq,
            quantization: 0.0,
            dropped: 0.0,
            up: vec![(0.0, 0.0); CURVE_BINS],
            down: vec![(0.0, 0.0); CURVE_BINS],
            rounded: vec![0.0; ROUNDED_POINTS],
            rounded_below: 0.0,
        }
    }

    /// The threshold the curve was measured at.
    pub fn tau_sq(&self) -> f64 {
        self.tau_sq
    }

    /// Appends the curve as little-endian f64 values: τ², the quantization
    /// error, the dropped energy, then the (energy, error) pairs of the
    /// bins above and below τ² (a coded part's record).
    pub(crate) fn write(&self, w: &mut Writer) {
        let pairs = self.up.iter().chain(&self.down);
        let values = [self.tau_sq, self.quantization, self.dropped]
            .into_iter()
            .chain(pairs.flat_map(|&(e, q)| [e, q]))
            .chain([self.rounded_below])
            .chain(self.rounded.iter().copied());
        values.for_each(|v| w.u64(v.to_bits()));
    }

    /// Reads a curve [`ErrorCurve::write`] wrote: τ² finite and > 0, every
    /// other value finite and ≥ 0.
    pub(crate) fn read(r: &mut Reader) -> Result<ErrorCurve> {
        let mut next = || -> Result<f64> { Ok(f64::from_bits(r.u64()?)) };
        let tau_sq = next()?;
        if !(tau_sq.is_finite() && tau_sq > 0.0) {
            return Err(Error::range("error curve τ²", tau_sq, "finite and > 0"));
        }
        let count = 2 + 4 * CURVE_BINS + 1 + ROUNDED_POINTS;
        let mut values = Vec::with_capacity(count);
        for _ in 0..count {
            let v = next()?;
            if !(v.is_finite() && v >= 0.0) {
                return Err(Error::range("error curve value", v, "finite and ≥ 0"));
            }
            values.push(v);
        }
        let rounded = values.split_off(2 + 4 * CURVE_BINS);
        let pairs: Vec<(f64, f64)> = values[2..].chunks_exact(2).map(|p| (p[0], p[1])).collect();
        Ok(ErrorCurve {
            tau_sq,
            quantization: values[0],
            dropped: values[1],
            up: pairs[..CURVE_BINS].to_vec(),
            down: pairs[CURVE_BINS..].to_vec(),
            rounded_below: rounded[0],
            rounded: rounded[1..].to_vec(),
        })
    }

    /// Adds a kept coefficient of squared magnitude `e` (≥ τ²) coded with
    /// squared error `coded_err`.
    pub fn add_kept(&mut self, e: f64, coded_err: f64) {
        self.quantization += coded_err;
        let k = (e / self.tau_sq).log2() * CURVE_BINS_PER_OCTAVE;
        if k >= 0.0 && k < CURVE_BINS as f64 {
            let b = &mut self.up[k as usize];
            *b = (b.0 + e, b.1 + coded_err);
        }
    }

    /// Adds a dropped coefficient of squared magnitude `e` (< τ²) that would
    /// be coded with squared error `coded_err` if kept.
    pub fn add_dropped(&mut self, e: f64, coded_err: f64) {
        self.dropped += e;
        let k = (self.tau_sq / e).log2() * CURVE_BINS_PER_OCTAVE;
        if e > 0.0 && k >= 0.0 && k < CURVE_BINS as f64 {
            let b = &mut self.down[k as usize];
            *b = (b.0 + e, b.1 + coded_err.min(e));
        }
    }

    /// Adds, for a uniform coding, a coefficient of squared magnitude `e`
    /// (summed over channels) with per-channel magnitudes `u`, re-quantized
    /// at every point of `grid` (`rounded_grid` of this curve's τ²):
    /// dropped where `e` is below the point's threshold, else rounded to its
    /// step in each channel.
    pub(crate) fn add_rounded(&mut self, e: f64, u: &[f64], grid: &[(f64, f64); ROUNDED_POINTS]) {
        if e < grid[0].0 {
            self.rounded_below += e;
            return;
        }
        for (r, &(tau_sq, step)) in self.rounded.iter_mut().zip(grid) {
            *r += if e < tau_sq {
                e
            } else {
                u.iter()
                    .map(|&x| rounding_error(x, step).unwrap_or(x * x))
                    .sum()
            };
        }
    }

    /// Adds a coefficient of squared magnitude `e` that the quantizer
    /// dropped although it passed the threshold.
    pub fn add_quantized_away(&mut self, e: f64) {
        self.dropped += e;
    }

    /// Adds another curve of the same threshold (other columns).
    pub fn merge(&mut self, other: &ErrorCurve) {
        self.quantization += other.quantization;
        self.dropped += other.dropped;
        for (a, b) in self.up.iter_mut().zip(&other.up) {
            *a = (a.0 + b.0, a.1 + b.1);
        }
        for (a, b) in self.down.iter_mut().zip(&other.down) {
            *a = (a.0 + b.0, a.1 + b.1);
        }
        for (a, b) in self.rounded.iter_mut().zip(&other.rounded) {
            *a += b;
        }
        self.rounded_below += other.rounded_below;
    }

    /// The threshold τ² at which a coding whose measured squared error was
    /// `measured` changes it by `delta` (τ raised for `delta > 0`, lowered
    /// below), interpolated within a bin; `None` when the change lies
    /// beyond the curve's 3 octaves.
    ///
    /// With the uniform quantizer (`quantizer`), whose step follows τ, the
    /// error of every kept value changes with τ too: the threshold is then
    /// read off the coding's error re-quantized at 25 thresholds around τ².
    pub fn threshold_for(&self, measured: f64, delta: f64, quantizer: Quantizer) -> Option<f64> {
        let scale = if self.dropped > 0.0 {
            ((measured - self.quantization) / self.dropped).clamp(0.25, 4.0)
        } else {
            1.0
        };
        if quantizer == Quantizer::Uniform {
            return self.uniform_threshold(measured, delta);
        }
        let (bins, sign, need) = if delta >= 0.0 {
            (&self.up, 1.0, delta)
        } else {
            (&self.down, -1.0, -delta)
        };
        let mut acc = 0.0;
        for (k, &(e, q)) in bins.iter().enumerate() {
            let v = (scale * e - q).max(0.0);
            if v > 0.0 && acc + v >= need {
                let t = (need - acc) / v;
                return Some(
                    self.tau_sq * 2f64.powf(sign * (k as f64 + t) / CURVE_BINS_PER_OCTAVE),
                );
            }
            acc += v;
        }
        None
    }

    /// The threshold at which the uniform coding's error, re-quantized
    /// on the curve's grid ([`ErrorCurve::add_rounded`]) and scaled so that
    /// the grid's centre is the `measured` error, is `measured + delta`
    /// (linear in `log τ²` between grid points); `None` beyond the grid.
    fn uniform_threshold(&self, measured: f64, delta: f64) -> Option<f64> {
        let at = |g: usize| self.rounded[g] + self.rounded_below;
        let mid = ROUNDED_POINTS / 2;
        if at(mid) <= 0.0 {
            return None;
        }
        let ratio = measured / at(mid);
        let goal = measured + delta;
        let value = |g: usize| ratio * at(g);
        let pairs: Vec<(usize, usize)> = if delta >= 0.0 {
            (mid..ROUNDED_POINTS - 1).map(|g| (g, g + 1)).collect()
        } else {
            (1..=mid).rev().map(|g| (g, g - 1)).collect()
        };
        for (g, h) in pairs {
            let (a, b) = (value(g), value(h));
            let crosses = (a - goal) * (b - goal) <= 0.0 && a != b;
            if crosses {
                let t = (goal - a) / (b - a);
                let o = rounded_octaves(g) + t * (rounded_octaves(h) - rounded_octaves(g));
                return Some(self.tau_sq * 2f64.powf(o));
            }
        }
        None
    }
}

fn check_plan_args(bits: u32, budget: f64) -> Result<()> {
    if !(2..=16).contains(&bits) {
        return Err(Error::range("bits", bits, "2..=16"));
    }
    if !(budget >= 0.0 && budget.is_finite()) {
        return Err(Error::range("error budget", budget, "finite and ≥ 0"));
    }
    Ok(())
}

/// At the threshold of bin `b`: the estimated total error and each column's
/// (best, runner-up) depth by estimated cost `kept + error/τ²`.
fn choose(analysis: &Analysis, b: usize, spec: QuantSpec) -> ([f64; 2], Vec<[u32; 2]>) {
    let settings = analysis.settings();
    let (depths, channels) = (settings.depths(), settings.channels as usize);
    let tau_sq = bin_threshold(b, settings.tau0_sq);
    let model = spec.model(tau_sq, channels);
    let mut total = [0.0, 0.0];
    let choice = analysis
        .columns()
        .map(|j| {
            let mut costs: Vec<(f64, [f64; 2], usize)> = (0..depths.len())
                .map(|di| {
                    let (counts, energies, quant) = analysis.stats(j, di);
                    let (k, e, eq) = estimate_parts(counts, energies, quant, channels, model, b);
                    (k + e / tau_sq, [e, eq], di)
                })
                .collect();
            costs.sort_by(|a, b| a.0.total_cmp(&b.0));
            total[0] += costs[0].1[0];
            total[1] += costs[0].1[1];
            let second = costs.get(1).map_or(costs[0].2, |c| c.2);
            [depths[costs[0].2], depths[second]]
        })
        .collect();
    (total, choice)
}

/// How a coding's measured error calibrates a plan's estimate: factors for
/// the dropped energy and for the modelled quantization error.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Calibration {
    /// Factor on the energy of the dropped values.
    pub dropped: f64,
    /// Factor on the modelled quantization error of the kept values.
    pub quantization: f64,
}

impl Calibration {
    /// The calibrated total of an estimate `[total, quantization part]`.
    fn apply(&self, [total, quant]: [f64; 2]) -> f64 {
        (total - quant) * self.dropped + quant * self.quantization
    }
}

/// Estimated (kept values, squared error) of one column at one depth when
/// the bins below `b` are dropped: `counts` and `energies` its histogram,
/// `quant` its (Σ squared group peaks, nonzeros), `model` the quantizer's
/// step: the dithered step `Δ` is the RMS step of the column's scale groups
/// over the levels, the rounded one is given. `x` is a bin's RMS magnitude
/// per channel.
#[cfg(test)]
pub(super) fn estimate(
    counts: &[u32],
    energies: &[f64],
    quant: (f64, u32),
    channels: usize,
    model: StepModel,
    b: usize,
) -> (f64, f64) {
    let (kept, err, _) = estimate_parts(counts, energies, quant, channels, model, b);
    (kept, err)
}

/// [`estimate`] with the part of the error that is quantization error of
/// kept values: (kept values, squared error, its quantization part).
fn estimate_parts(
    counts: &[u32],
    energies: &[f64],
    quant: (f64, u32),
    channels: usize,
    model: StepModel,
    b: usize,
) -> (f64, f64, f64) {
    let mut dropped: f64 = energies[..b].iter().sum();
    let (qsum, nonzero) = quant;
    let (mut kept, mut quantization) = (0.0, 0.0);
    for (&count, &energy) in counts[b..].iter().zip(&energies[b..]).filter(|x| *x.0 > 0) {
        let x = (energy / count as f64 / channels as f64).sqrt();
        let cost = match model {
            StepModel::Dithered(q) => {
                quantization_error(x, (qsum / nonzero.max(1) as f64).sqrt() / q)
            }
            StepModel::Rounded(step) => expected_rounding_error(x, step),
        };
        match cost {
            None => dropped += energy,
            Some(per_value) => {
                kept += count as f64;
                let q = count as f64 * channels as f64 * per_value;
                dropped += q;
                quantization += q;
            }
        }
    }
    (kept, dropped, quantization)
}

/// The squared error, roughly expected over a bin of magnitudes around `x`,
/// of rounding `x` to the nearest multiple of `step`: `(x − Δ)²` up to
/// `1.5·Δ`, `Δ²/12` beyond (the fractional part uniform); `None` below
/// `Δ/2`, which rounds to zero.
pub(super) fn expected_rounding_error(x: f64, step: f64) -> Option<f64> {
    if x < step / 2.0 {
        None
    } else if x < 1.5 * step {
        Some((x - step).powi(2))
    } else {
        Some(step * step / 12.0)
    }
}

/// The squared error of rounding `x` (≥ 0) to the nearest multiple of
/// `step` (> 0) exactly, as the uniform quantizer does; `None` when it
/// rounds to zero.
pub(super) fn rounding_error(x: f64, step: f64) -> Option<f64> {
    let k = (x / step).round();
    (k >= 1.0).then(|| (x - k * step).powi(2))
}

/// The expected squared error of dither-quantizing a value of magnitude `x`
/// with step `step`: `Δ²/6` for `x ≥ Δ`, `x(Δ − x)` below; `None` (drop it)
/// when `x < Δ/2`, where dropping costs less.
pub(super) fn quantization_error(x: f64, step: f64) -> Option<f64> {
    if x < step / 2.0 {
        None
    } else if x >= step {
        Some(step * step / 6.0)
    } else {
        Some(x * (step - x))
    }
}

#[cfg(test)]
mod tests {
    use super::super::analysis::{depth_stats, tests::analysis};
    use super::*;
    use crate::column::SparseColumn;
    use crate::quant::{decode_scale, quantize, Dither, Quantization};

    /// One channel; one scale group of peak 4 over 4 values: Δ = 4/Q, and
    /// Q = 1 at 2 bits, so Δ = 4.
    const QUANT: (f64, u32) = (4.0 * 4.0 * 4.0, 4);

    /// Bins by hand: bin 0 one value of 1 (dropped, x < Δ/2), bin 1 one value
    /// of 3 (kept, 3·(4 − 3) = 3), bin 2 two values of 4 (kept, Δ²/6 each),
    /// bin 3 empty, bin 4 one value of 10 (Δ²/6).
    fn bins() -> (Vec<u32>, Vec<f64>) {
        let mut counts = vec![0u32; BINS];
        let mut energies = vec![0.0f64; BINS];
        for (b, n, x) in [(0, 1, 1.0f64), (1, 1, 3.0), (2, 2, 4.0), (4, 1, 10.0)] {
            counts[b] = n;
            energies[b] = n as f64 * x * x;
        }
        (counts, energies)
    }

    #[test]
    fn estimate_matches_hand_computed_errors() {
        let (counts, energies) = bins();
        let q = levels(2) as f64;
        assert_eq!(q, 1.0);
        let sixth = 16.0 / 6.0;
        let cases = [
            (0, 4.0, 1.0 + 3.0 + 3.0 * sixth),
            (1, 4.0, 1.0 + 3.0 + 3.0 * sixth),
            (2, 3.0, 1.0 + 9.0 + 3.0 * sixth),
            (3, 1.0, 1.0 + 9.0 + 32.0 + sixth),
            (5, 0.0, 1.0 + 9.0 + 32.0 + 100.0),
        ];
        for (b, kept, err) in cases {
            let (k, e) = estimate(&counts, &energies, QUANT, 1, StepModel::Dithered(q), b);
            assert_eq!(k, kept, "bin {b}");
            assert!((e - err).abs() < 1e-9, "bin {b}: {e} vs {err}");
        }
        // Three channels: a bin's x is its RMS per channel, and each kept
        // position costs its error once per channel.
        let mut e3 = energies.clone();
        e3.iter_mut().for_each(|e| *e *= 3.0);
        let (k, e) = estimate(&counts, &e3, QUANT, 3, StepModel::Dithered(q), 0);
        assert_eq!(k, 4.0);
        assert!((e - 3.0 * (1.0 + 3.0 + 3.0 * sixth)).abs() < 1e-9, "{e}");
        assert_eq!(quantization_error(1.99, 4.0), None);
        assert_eq!(quantization_error(2.0, 4.0), Some(4.0));
        assert_eq!(quantization_error(4.0, 4.0), Some(16.0 / 6.0));
    }

    /// Deterministic values in `[0, 1)`.
    fn lcg(s: &mut u64) -> f64 {
        *s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (*s >> 11) as f64 / (1u64 << 53) as f64
    }

    /// A column of `p` log-uniform magnitudes over 4 decades with random
    /// signs.
    fn log_uniform_column(p: usize, seed: u64) -> Vec<f32> {
        let mut s = seed;
        (0..p)
            .map(|_| {
                let mag = 10f64.powf(-4.0 * lcg(&mut s)) as f32;
                if lcg(&mut s) < 0.5 {
                    -mag
                } else {
                    mag
                }
            })
            .collect()
    }

    /// The squared error of `col` (one channel, one scale group) against
    /// `coefs`.
    fn measured(col: &SparseColumn, coefs: &[f32], bits: u32) -> f64 {
        let step = decode_scale(col.scale_codes[0]) / levels(bits);
        let mut decoded = vec![0.0f32; coefs.len()];
        for (&i, &v) in col.indices.iter().zip(&col.values) {
            decoded[i as usize] = v as f32 * step;
        }
        decoded
            .iter()
            .zip(coefs)
            .map(|(a, b)| ((a - b) as f64).powi(2))
            .sum()
    }

    /// A column of log-uniform magnitudes with random signs, histogrammed as
    /// the analysis does and quantized as the coder does: the estimate of
    /// dropped plus quantization error is within 10 % of the measured error
    /// at every threshold, for the peak quantizer at several bit counts and
    /// for the uniform one.
    #[test]
    fn estimate_matches_measured_error_on_a_constructed_column() {
        let (p, tau0_sq) = (8192usize, 1e-4);
        let coefs = log_uniform_column(p, 7);
        let groups = vec![0u8; p];
        let (mut counts, mut energies) = (vec![0u32; BINS], vec![0.0f64; BINS]);
        let energy = |i: usize| (coefs[i] as f64).powi(2);
        let quant = depth_stats(energy, &groups, 0, tau0_sq, &mut counts, &mut energies);
        let specs = [
            QuantSpec::peak(4),
            QuantSpec::peak(6),
            QuantSpec::peak(9),
            QuantSpec::uniform(16),
        ];
        for spec in specs {
            for b in [0, 32, 44, 52, 58] {
                let tau_sq = bin_threshold(b, tau0_sq);
                let kept: Vec<u32> = (0..p as u32)
                    .filter(|&i| energy(i as usize) >= tau_sq)
                    .collect();
                let how = Quantization {
                    bits: spec.bits,
                    step: spec.quantizer.step(tau_sq, 1).map(|s| s as f32),
                    dither: Dither { seed: 1, column: 0 },
                };
                let col = quantize(&coefs, 1, &kept, &groups, 0, how);
                let measured = measured(&col, &coefs, spec.bits);
                let model = spec.model(tau_sq, 1);
                let (_, est) = estimate(&counts, &energies, quant, 1, model, b);
                let ratio = est / measured;
                assert!(
                    (0.9..=1.1).contains(&ratio),
                    "{spec:?} bin {b}: estimate {est}, measured {measured}"
                );
            }
        }
    }

    /// The uniform quantizer's error curve predicts the error of a coding
    /// at another threshold, whose step moves with it: coded at τ, asked
    /// for ±30 % of the error, the threshold it gives lands within 5 %.
    #[test]
    fn uniform_curve_lands_a_recoding_on_the_asked_error() {
        let p = 8192usize;
        let coefs = log_uniform_column(p, 11);
        let groups = vec![0u8; p];
        let code = |tau_sq: f64| {
            let kept: Vec<u32> = (0..p as u32)
                .filter(|&i| (coefs[i as usize] as f64).powi(2) >= tau_sq)
                .collect();
            let step = Quantizer::Uniform.step(tau_sq, 1).map(|s| s as f32);
            let how = Quantization {
                bits: 16,
                step,
                dither: Dither { seed: 1, column: 0 },
            };
            let col = quantize(&coefs, 1, &kept, &groups, 0, how);
            measured(&col, &coefs, 16)
        };
        let tau_sq = 1e-5;
        let (step, err) = (Quantizer::Uniform.step(tau_sq, 1).unwrap(), code(tau_sq));
        let grid = rounded_grid(tau_sq, step);
        let mut curve = ErrorCurve::new(tau_sq);
        for &c in &coefs {
            let u = (c as f64).abs();
            curve.add_rounded(u * u, &[u], &grid);
        }
        for factor in [0.7, 1.3] {
            let goal = factor * err;
            let t = curve
                .threshold_for(err, goal - err, Quantizer::Uniform)
                .unwrap();
            let got = code(t);
            assert!(
                (got / goal - 1.0).abs() < 0.05,
                "asked {goal:e}, coded {got:e} at τ² {t:e} (from {tau_sq:e})"
            );
        }
        // Asked for no change, it keeps τ.
        let same = curve.threshold_for(err, 0.0, Quantizer::Uniform).unwrap();
        assert!((same / tau_sq - 1.0).abs() < 1e-9, "{same:e}");
    }

    #[test]
    fn plans_pick_the_largest_threshold_within_the_budget() {
        let a = analysis(0..6);
        let loose = Plan::new(&a, QuantSpec::peak(10), f64::MAX).unwrap();
        assert_eq!(
            loose.tau_sq(),
            bin_threshold(BINS - 1, a.settings().tau0_sq)
        );
        let tight = Plan::new(&a, QuantSpec::peak(10), 0.0).unwrap();
        assert_eq!(tight.tau_sq(), 0.0);
        assert_eq!(tight.columns(), 0..6);
        let depths = a.settings().depths();
        for j in 0..6 {
            let [best, second] = tight.choice(j).unwrap();
            assert!(depths.contains(&best) && depths.contains(&second));
        }
        assert_eq!(tight.choice(6), None);
        assert_eq!(Plan::keep(5).choice(0), None);
        assert!(Plan::new(&a, QuantSpec::peak(17), 1.0).is_err());
        assert!(Plan::new(&a, QuantSpec::peak(10), f64::NAN).is_err());
        assert!(Plan::new(&a, QuantSpec::peak(10), -1.0).is_err());
    }
}
