//! The error-feedback loop of a target-error coding, as steps: which
//! bits and plan the next coding uses, given what the last one measured.
//! One machine ([`Transposed::code`](super::Transposed::code)) and a
//! sharded run (`ltm plan` between the coding shards) take their decisions
//! here, so both code the same columns the same way and write the same
//! file.
//!
//! The first coding follows the plan for [`TARGET_AIM`]·E; when its
//! measured error lands outside [[`TARGET_LOW`]·E, E], the plan's estimate
//! is calibrated by the measured error (their ratio) and the columns are
//! planned again, with a threshold interpolated between histogram bins,
//! and coded once more. Only when that still misses E (rare: the
//! calibration holds between nearby thresholds) does the budget shrink by
//! the miss, up to [`MAX_CODINGS`] codings; bits that are too few for the
//! target give a floor no threshold can pass, hence the limit. When the
//! kept coding misses the target and [`CodeOptions::raise_bits`] is set,
//! the loop starts again at 2 more bits (up to 16), skipping bits whose
//! estimated quantization floor alone misses the target.

use super::analysis::Analysis;
use super::plan::{Calibration, ErrorCurve, Plan, QuantSpec};
use super::{CodeOptions, Quantizer, Target, MAX_CODINGS, TARGET_AIM, TARGET_LOW};
use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};

/// One coding of the loop: its quantization bits, its number among the
/// codings at those bits (from 1), and its plan.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Step {
    /// Quantization bits.
    pub bits: u32,
    /// 1 for the first coding at `bits`.
    pub coding: u32,
    /// What the coding keeps of each column, and at which depths.
    pub plan: Plan,
}

/// What a coding measured: the total squared error, each column's depth
/// and the columns' [`ErrorCurve`] (threshold plans), accumulated column
/// by column in column order, so that codings split into batches or
/// shards measure the same sums bit for bit.
#[derive(Clone, Debug, Default)]
pub struct Coding {
    /// The total squared error.
    pub err: f64,
    /// Each column's depth, in column order.
    pub depths: Vec<u32>,
    /// The columns' error curves merged (threshold plans with τ > 0).
    pub curve: Option<ErrorCurve>,
}

impl Coding {
    /// Adds the next column: its measured squared error, depth and curve.
    pub fn push_column(&mut self, err: f64, depth: u32, curve: Option<&ErrorCurve>) {
        self.err += err;
        self.depths.push(depth);
        if let Some(c) = curve {
            match &mut self.curve {
                Some(total) => total.merge(c),
                None => self.curve = Some(c.clone()),
            }
        }
    }
}

/// What follows a coding.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum Next {
    /// Code again with this step.
    Code(Step),
    /// Keep the coding: it is the file. `target_met` says whether its
    /// measured error meets the target (always for a term count).
    Keep {
        /// The measured error is at most the target.
        target_met: bool,
    },
}

/// The squared-error budget of `target` for a matrix of Frobenius norm
/// `norm`: `(E·norm)²` for a relative error E, 0 for a term count.
pub fn budget_for(target: Target, norm: f64) -> f64 {
    match target {
        Target::MaxError(e) => (e * norm).powi(2),
        Target::Keep(_) => 0.0,
    }
}

/// The loop's decisions for one matrix, its options and its analysis.
pub struct Feedback<'a> {
    opts: &'a CodeOptions,
    budget: f64,
    analysis: Option<&'a Analysis>,
}

impl<'a> Feedback<'a> {
    /// The loop for `opts` with the squared-error `budget` ([`budget_for`]);
    /// a target error needs the `analysis` of every column.
    pub fn new(
        opts: &'a CodeOptions,
        budget: f64,
        analysis: Option<&'a Analysis>,
    ) -> Result<Feedback<'a>> {
        if matches!(opts.target, Target::MaxError(_)) && analysis.is_none() {
            return Err(Error::Invalid("a target error needs an analysis".into()));
        }
        Ok(Feedback {
            opts,
            budget,
            analysis,
        })
    }

    /// The first coding.
    pub fn first(&self) -> Result<Step> {
        self.first_at(self.opts.bits)
    }

    /// The first coding at `bits` or, while their estimated floor misses
    /// the target and more bits are allowed, at 2 more.
    fn first_at(&self, mut bits: u32) -> Result<Step> {
        loop {
            let can_raise = self.opts.raise_bits && bits < 16;
            let hopeless = match (self.analysis, can_raise) {
                (Some(a), true) => below_floor(a, self.spec(bits), self.budget)?,
                _ => false,
            };
            if !hopeless {
                let aim = self.budget * TARGET_AIM.powi(2);
                let plan = match (self.analysis, self.opts.target) {
                    (_, Target::Keep(n)) => Plan::keep(n),
                    (Some(a), Target::MaxError(_)) => Plan::new(a, self.spec(bits), aim)?,
                    (None, Target::MaxError(_)) => {
                        return Err(Error::Invalid("a target error needs an analysis".into()))
                    }
                };
                return Ok(Step {
                    bits,
                    coding: 1,
                    plan,
                });
            }
            bits = (bits + 2).min(16);
        }
    }

    /// The quantizer of a coding at `bits`.
    fn spec(&self, bits: u32) -> QuantSpec {
        QuantSpec {
            quantizer: self.opts.quantizer,
            bits,
        }
    }

    /// What follows the coding `step` that measured `coded`.
    pub fn next(&self, step: &Step, coded: &Coding) -> Result<Next> {
        let (aim, low) = (
            self.budget * TARGET_AIM.powi(2),
            self.budget * TARGET_LOW.powi(2),
        );
        let missed = coded.err > self.budget * 1.0001;
        if let Some(a) = self.analysis {
            if step.coding < MAX_CODINGS && (missed || coded.err < low) {
                let next = replan(
                    a,
                    &step.plan,
                    coded,
                    self.spec(step.bits),
                    aim,
                    step.coding,
                    missed,
                )?;
                if let Some(plan) = next {
                    return Ok(Next::Code(Step {
                        bits: step.bits,
                        coding: step.coding + 1,
                        plan,
                    }));
                }
            }
        }
        let target_met = self.analysis.is_none() || !missed;
        if target_met || !(self.opts.raise_bits && step.bits < 16) {
            return Ok(Next::Keep { target_met });
        }
        self.first_at((step.bits + 2).min(16)).map(Next::Code)
    }
}

/// Whether even keeping every coefficient at `bits` is estimated to miss
/// the squared-error `budget` (the quantization floor of `bits`): the
/// analysis's plan at τ = 0 exceeds the budget by more than the plan's
/// usual estimation error.
fn below_floor(analysis: &Analysis, spec: QuantSpec, budget: f64) -> Result<bool> {
    let plan = Plan::new(analysis, spec, budget)?;
    Ok(plan.tau_sq() == 0.0 && plan.estimated_error() > FLOOR_MARGIN * budget)
}

/// How far the estimated floor must exceed the budget before [`below_floor`]
/// skips the bits without trying them.
const FLOOR_MARGIN: f64 = 1.5;

/// The next plan after a coding with `plan` measured the squared error
/// `err` outside the target range, or `None` to keep the coding. The
/// second coding moves τ to where the first coding's [`ErrorCurve`] puts
/// the error at `aim`; beyond the curve's range (or without one) the plan's
/// estimate is calibrated by `err` ([`calibration`]). The third coding
/// follows the second coding's own curve; later ones (after a miss of the
/// budget) follow the curve when it lowers τ, else shrink the estimate's
/// budget by the miss and lower τ. An error below the range is kept after
/// the third coding (the fourth with the uniform quantizer), and whenever
/// the plan's estimate is 0.
fn replan(
    a: &Analysis,
    plan: &Plan,
    coded: &Coding,
    spec: QuantSpec,
    aim: f64,
    coding: u32,
    missed: bool,
) -> Result<Option<Plan>> {
    let (estimate, err) = (plan.estimated_error(), coded.err);
    if coding == 1 {
        let curve = coded.curve.as_ref();
        if let Some(tau_sq) = curve.and_then(|c| c.threshold_for(err, aim - err, spec.quantizer)) {
            return Plan::at_threshold(a, spec, tau_sq, &coded.depths).map(Some);
        }
        if estimate > 0.0 && err > 0.0 {
            return Plan::calibrated(a, spec, aim, calibration(plan, err)).map(Some);
        }
        return Ok(None);
    }
    if plan.fixed_depths() && missed && coding >= 5 {
        // The first coding's depths cannot meet the target (a quantization
        // floor): back to the analysis's conservative plans, free depths.
        return Plan::new(a, spec, 0.5 * aim).map(Some);
    }
    // A uniform coding's error moves with its step as well as its
    // threshold: an error still below the range after the third coding
    // gets one more try along the curve.
    let low_again = spec.quantizer == Quantizer::Uniform && coding == 3;
    if plan.tau_sq() > 0.0 && err > 0.0 && (coding == 2 || missed || low_again) {
        // The curve of the re-coding itself, measured near the target,
        // at its depths: a third coding, and later ones only while the
        // error exceeds the target.
        let next = coded
            .curve
            .as_ref()
            .and_then(|c| c.threshold_for(err, aim - err, spec.quantizer));
        let tau_sq = match next {
            Some(t) if !missed || t < plan.tau_sq() => Some(t),
            _ if plan.fixed_depths() => Some(plan.tau_sq() * 0.9 * aim / err),
            _ => None,
        };
        if let Some(tau_sq) = tau_sq {
            return Plan::at_threshold(a, spec, tau_sq, &coded.depths).map(Some);
        }
    }
    if !missed || plan.tau_sq() <= 0.0 || err <= 0.0 {
        return Ok(None);
    }
    if estimate <= 0.0 {
        return Ok(None);
    }
    let shrink = 0.9 * aim / err;
    Plan::below(a, spec, estimate * shrink, plan.tau_sq() * shrink).map(Some)
}

/// How a coding with `plan` that measured the squared error `err` (> 0)
/// calibrates the plan's estimate (> 0). The dropped energy is counted
/// from the analysis, while the quantization error is a model (which can
/// be off by a factor of a few where few bits meet a wide range of values):
/// when the plan's estimate is mostly quantization error, the measured
/// error less the dropped energy calibrates the model alone; otherwise
/// (or when that leaves too little) both parts scale by `err / estimate`.
fn calibration(plan: &Plan, err: f64) -> Calibration {
    let (estimate, quant) = (plan.estimated_error(), plan.estimated_quantization());
    let dropped = estimate - quant;
    let whole = err / estimate;
    if quant > 0.5 * estimate && err > 2.0 * dropped {
        Calibration {
            dropped: 1.0,
            quantization: ((err - dropped) / quant).clamp(0.1 * whole, 10.0 * whole),
        }
    } else {
        Calibration {
            dropped: whole,
            quantization: whole,
        }
    }
}
