//! Progress bars on a terminal (indicatif); silent when stderr is not one.
//! Each bar counts in a named unit (rows, columns, passes) and shows its
//! rate in that unit, the matching MB/s of the raw matrix, and the time
//! left: `coding [=====>    ] 812/4096 columns, 1.52k columns/s, 31.4 MB/s, ETA 2s`.

use indicatif::{ProgressBar, ProgressState, ProgressStyle};
use ltm_codec::{Dims, Stage, Step};
use std::fmt::Write as _;

/// What a bar counts: a unit's name and the raw-matrix bytes one unit
/// stands for (0: no MB/s).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Unit {
    /// The unit's name, plural ("rows").
    pub name: &'static str,
    /// Raw-matrix bytes per unit.
    pub bytes: u64,
}

impl Unit {
    /// Blocks of a file being read, of no fixed size.
    pub const BLOCKS: Unit = Unit {
        name: "blocks",
        bytes: 0,
    };

    /// Rows of `dims`'s raw matrix (pixels or texels).
    pub fn rows(dims: Dims) -> Unit {
        Unit {
            name: "rows",
            bytes: dims.row_len() as u64 * 4,
        }
    }

    /// The unit a stage of a long operation counts in, for a matrix of
    /// `dims`.
    pub fn of(stage: Stage, dims: Dims) -> Unit {
        match stage {
            Stage::Bake { .. } | Stage::Rows | Stage::Reference => Unit::rows(dims),
            Stage::Analysis | Stage::Coding => Unit {
                name: "columns",
                bytes: dims.raw_bytes() / dims.lights().max(1) as u64,
            },
            Stage::Fit => Unit {
                name: "passes",
                bytes: dims.raw_bytes(),
            },
            _ => Unit::BLOCKS,
        }
    }
}

/// A rate with three significant digits and a k, M or G suffix:
/// `812`, `1.52k`, `64.2M`.
pub fn compact(v: f64) -> String {
    if !v.is_finite() || v < 0.0 {
        return "-".into();
    }
    let (v, suffix) = match v {
        v if v >= 1e9 => (v / 1e9, "G"),
        v if v >= 1e6 => (v / 1e6, "M"),
        v if v >= 1e3 => (v / 1e3, "k"),
        v => (v, ""),
    };
    let digits = match v {
        v if v >= 100.0 => 0,
        v if v >= 10.0 => 1,
        _ => 2,
    };
    format!("{v:.digits$}{suffix}")
}

/// The rate shown for `per_sec` units of `unit` a second.
pub fn rate(per_sec: f64, unit: Unit) -> String {
    let mut s = format!("{} {}/s", compact(per_sec), unit.name);
    if unit.bytes > 0 {
        let mb = per_sec * unit.bytes as f64 / 1e6;
        let _ = write!(s, ", {} MB/s", compact(mb));
    }
    s
}

/// The bar's look for `unit`.
fn style(unit: Unit) -> ProgressStyle {
    let template = format!(
        "{{msg:>12}} [{{bar:40}}] {{pos}}/{{len}} {}, {{rate}}, ETA {{eta}}",
        unit.name
    );
    ProgressStyle::with_template(&template)
        .expect("static template")
        .with_key(
            "rate",
            move |s: &ProgressState, w: &mut dyn std::fmt::Write| {
                let _ = w.write_str(&rate(s.per_sec(), unit));
            },
        )
        .progress_chars("=> ")
}

/// A bar of `total` units of `unit`, labelled `what`, hidden off a
/// terminal.
pub fn bar(total: u64, what: &str, unit: Unit) -> ProgressBar {
    let bar = ProgressBar::new(total);
    bar.set_style(style(unit));
    bar.set_message(what.to_string());
    bar
}

/// Shows `step` of an operation on a matrix of `dims` on `bar`: a new
/// stage restarts the bar, labelled and counted in the stage's unit.
pub fn show(bar: &ProgressBar, step: Step, dims: Dims) {
    let unit = Unit::of(step.stage, dims);
    let label = stage_label(step.stage);
    if bar.message() != label {
        bar.reset();
        bar.set_style(style(unit));
        bar.set_message(label);
    }
    bar.set_length(step.total);
    bar.set_position(step.done);
}

/// A stage as a bar labels it.
fn stage_label(stage: Stage) -> &'static str {
    match stage {
        Stage::Bake { .. } => "bake",
        Stage::Import => "import",
        Stage::Rows => "transpose",
        Stage::Analysis => "analysis",
        Stage::Coding => "coding",
        Stage::Fit => "pca fit",
        Stage::Reference => "reference",
        _ => "working",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rates_are_short_and_name_their_unit() {
        assert_eq!(compact(812.0), "812");
        assert_eq!(compact(1523.0), "1.52k");
        assert_eq!(compact(64_191_839.703), "64.2M");
        assert_eq!(compact(0.5), "0.50");
        assert_eq!(compact(f64::NAN), "-");
        let dims = Dims::image(4, 4, 2, 3);
        let rows = Unit::of(Stage::Rows, dims);
        assert_eq!(rows, Unit::rows(dims));
        // A row: 6·2² lights × 3 channels × 4 bytes = 288 bytes.
        assert_eq!(rate(1e4, rows), "10.0k rows/s, 2.88 MB/s");
        assert_eq!(Unit::of(Stage::Coding, dims).bytes, 16 * 3 * 4);
        let blocks = Unit::of(Stage::Import, dims);
        assert_eq!(rate(3.0, blocks), "3.00 blocks/s");
    }
}
