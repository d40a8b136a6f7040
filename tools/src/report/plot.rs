//! SVG line and scatter plots for the report (plotters, no system fonts).
//!
//! Plotters is built without its `ttf` feature, so text is laid out with its
//! built-in size estimate and written as SVG `<text>` elements that the
//! viewer renders with its own sans-serif font.
//!
//! Both axes are drawn on linear plotters coordinates; a logarithmic axis
//! plots `log10` of the data and labels its ticks with the original values.
//! Tick positions are chosen here (1–2–5 steps on linear axes, decades, or
//! 1–2–5 / 1–9 multiples of them when the data spans less than a decade,
//! on log axes), so labels read as `1e-3, 0.01, 0.1, 1, 10, 100, 1e3`.

use anyhow::Result;
use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint};
use plotters::prelude::*;
use std::ops::Range;
use std::path::Path;

/// Chart size in pixels.
const SIZE: (u32, u32) = (800, 520);
/// Space below the plot for tick labels and the x-axis description.
const X_LABEL_AREA: u32 = 50;
/// Space left of the plot for tick labels and the y-axis description.
const Y_LABEL_AREA: u32 = 75;
const MARGIN: u32 = 15;
const CAPTION_SIZE: u32 = 22;
const LABEL_SIZE: u32 = 15;
const LEGEND_SIZE: u32 = 15;
/// Radius of a point marker.
const MARKER: u32 = 3;

/// Series colours (Tableau 10), cycled beyond ten series.
const PALETTE: [RGBColor; 10] = [
    RGBColor(0x1f, 0x77, 0xb4),
    RGBColor(0xff, 0x7f, 0x0e),
    RGBColor(0x2c, 0xa0, 0x2c),
    RGBColor(0xd6, 0x27, 0x28),
    RGBColor(0x94, 0x67, 0xbd),
    RGBColor(0x8c, 0x56, 0x4b),
    RGBColor(0xe3, 0x77, 0xc2),
    RGBColor(0x7f, 0x7f, 0x7f),
    RGBColor(0xbc, 0xbd, 0x22),
    RGBColor(0x17, 0xbe, 0xcf),
];

/// Scale of an axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Axis {
    Linear,
    /// Base-10 logarithmic; non-positive values are not drawn.
    Log,
}

/// How a series is drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Style {
    /// Solid line through the points in the given order.
    Line,
    /// Markers only.
    Points,
    /// Solid line with a marker at every point.
    LinePoints,
    /// Dashed line through the points in the given order.
    Dashed,
}

impl Style {
    fn has_line(self) -> bool {
        !matches!(self, Style::Points)
    }
}

/// One named data series.
#[derive(Clone, Debug)]
pub struct Series {
    pub name: String,
    /// `(x, y)` points; line styles connect them in this order (sort by x
    /// first where that is wanted).
    pub points: Vec<(f64, f64)>,
    pub style: Style,
    /// Palette index (cycled); `None` takes the series' position, so that
    /// related series (points and their front) can share a colour.
    pub color: Option<usize>,
}

/// A 2D chart of one or more series; the legend lists them in order.
#[derive(Clone, Debug)]
pub struct Chart {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub x_axis: Axis,
    pub y_axis: Axis,
    pub series: Vec<Series>,
}

/// One axis after looking at the data: the plotted (possibly `log10`) range
/// and its ticks, in plotted units. It is the plotters coordinate of the
/// axis, so the ticks are exactly these.
#[derive(Clone)]
struct Scale {
    axis: Axis,
    lo: f64,
    hi: f64,
    ticks: Vec<f64>,
    minor: Vec<f64>,
}

impl Scale {
    /// The plotted coordinate of a data value, `None` when it cannot be
    /// drawn on this axis.
    fn map(axis: Axis, v: f64) -> Option<f64> {
        match axis {
            Axis::Linear => v.is_finite().then_some(v),
            Axis::Log => (v.is_finite() && v > 0.0).then(|| v.log10()),
        }
    }

    /// Range and ticks for plotted values `vals` (finite; may be empty).
    fn new(axis: Axis, vals: impl Iterator<Item = f64>) -> Scale {
        let (mut lo, mut hi) = vals.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
        if lo > hi {
            // No data: a unit range (0..1, or 1..10 on a log axis).
            (lo, hi) = (0.0, 1.0);
        } else {
            match axis {
                Axis::Linear => {
                    // 5 % of the span each side; ±10 % of a single value
                    // (±1 for zero). Near ±f64::MAX the padded ends may not
                    // exist: pad one side only, or not at all.
                    let m = lo.abs().max(hi.abs());
                    let pad = if hi > lo {
                        0.05 * (hi - lo)
                    } else if m > 0.0 {
                        0.1 * m
                    } else {
                        1.0
                    };
                    let (a, b) = (lo - pad, hi + pad);
                    (lo, hi) = [(a, b), (a, hi), (lo, b), (lo, hi), (0.0, 1.0)]
                        .into_iter()
                        .find(|&(a, b)| a.is_finite() && b.is_finite() && b > a)
                        .unwrap_or((0.0, 1.0));
                }
                Axis::Log => {
                    // Decades; pad by a twentieth of the span (at least a
                    // tenth of a decade) so points stay off the frame.
                    let pad = (0.05 * (hi - lo)).max(0.1);
                    (lo, hi) = (lo - pad, hi + pad);
                }
            }
        }
        let (ticks, minor) = match axis {
            Axis::Linear => linear_ticks(lo, hi),
            Axis::Log => log_ticks(lo, hi),
        };
        Scale {
            axis,
            lo,
            hi,
            ticks,
            minor,
        }
    }

    /// The tick label of a plotted value.
    fn label(&self, v: f64) -> String {
        match self.axis {
            Axis::Linear => linear_label(v, self.step()),
            Axis::Log => log_label(v),
        }
    }

    /// The linear tick step (the span when there is at most one tick).
    fn step(&self) -> f64 {
        match self.ticks.as_slice() {
            [a, b, ..] => b - a,
            _ => self.hi - self.lo,
        }
    }

    /// The position of a plotted value in the range, 0 at `lo`, 1 at `hi`.
    fn unit(&self, v: f64) -> f64 {
        // Halved, so that spans beyond f64::MAX do not overflow.
        (0.5 * v - 0.5 * self.lo) / (0.5 * self.hi - 0.5 * self.lo)
    }
}

impl Ranged for Scale {
    type FormatOption = DefaultFormatting;
    type ValueType = f64;

    fn map(&self, v: &f64, limit: (i32, i32)) -> i32 {
        let t = self.unit(*v).clamp(-10.0, 10.0);
        let t = if t.is_finite() { t } else { 0.5 };
        limit.0 + ((limit.1 - limit.0) as f64 * t).round() as i32
    }

    fn key_points<Hint: KeyPointHint>(&self, hint: Hint) -> Vec<f64> {
        if hint.weight().allow_light_points() {
            self.minor.clone()
        } else {
            self.ticks.clone()
        }
    }

    fn range(&self) -> Range<f64> {
        self.lo..self.hi
    }
}

/// Ticks at multiples of a 1–2–5 step giving about six intervals, minor
/// ticks at a fifth (or half) of it.
fn linear_ticks(lo: f64, hi: f64) -> (Vec<f64>, Vec<f64>) {
    // A sixth of the span, without overflowing near ±f64::MAX.
    let raw = hi / 6.0 - lo / 6.0;
    if !(raw.is_finite() && raw > 0.0) {
        return (vec![lo, hi], Vec::new());
    }
    let mag = 10f64.powf(raw.log10().floor());
    let norm = raw / mag;
    let (m, minor_div) = if norm < 1.5 {
        (1.0, 5.0)
    } else if norm < 3.0 {
        (2.0, 4.0)
    } else if norm < 7.0 {
        (5.0, 5.0)
    } else {
        (10.0, 5.0)
    };
    let step = m * mag;
    let multiples = |step: f64| -> Vec<f64> {
        let (k0, k1) = ((lo / step).ceil(), (hi / step).floor());
        if !(k0.is_finite() && k1.is_finite()) || k1 - k0 > 1000.0 {
            return Vec::new();
        }
        let mut out = Vec::new();
        let mut k = k0;
        while k <= k1 {
            // Snap rounding residue around zero.
            let v = k * step;
            out.push(if v.abs() < step * 1e-9 { 0.0 } else { v });
            k += 1.0;
        }
        out
    };
    let ticks = multiples(step);
    if ticks.is_empty() {
        return (vec![lo, hi], Vec::new());
    }
    let minor = multiples(step / minor_div);
    (ticks, minor)
}

/// Ticks of a log axis in `log10` units: every decade (every k-th when more
/// than ten fit); 1–2–5 or 1…9 multiples when fewer than two decades fall in
/// the range. Minor ticks at 2…9 multiples while there are few decades.
fn log_ticks(lo: f64, hi: f64) -> (Vec<f64>, Vec<f64>) {
    let (e0, e1) = (lo.floor(), hi.ceil());
    if !(e0.is_finite() && e1.is_finite()) || e1 - e0 > 700.0 {
        return (vec![lo, hi], Vec::new());
    }
    let in_range = |v: &f64| *v >= lo - 1e-12 && *v <= hi + 1e-12;
    let with = |mults: &[f64]| -> Vec<f64> {
        let mut out = Vec::new();
        let mut e = e0;
        while e <= e1 {
            out.extend(mults.iter().map(|m| e + m.log10()).filter(in_range));
            e += 1.0;
        }
        out
    };
    let decades = with(&[1.0]);
    if decades.len() >= 2 {
        let every = decades.len().div_ceil(10);
        let ticks: Vec<f64> = decades
            .iter()
            .copied()
            .filter(|e| (*e as i64).rem_euclid(every as i64) == 0)
            .collect();
        let minor = if every == 1 && decades.len() <= 8 {
            with(&[2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0])
        } else {
            decades
        };
        return (ticks, minor);
    }
    let all: Vec<f64> = (1..=9).map(f64::from).collect();
    let ticks = with(&[1.0, 2.0, 5.0]);
    if ticks.len() >= 3 {
        return (ticks, with(&all));
    }
    let ticks = with(&all);
    if ticks.len() >= 2 {
        return (ticks, Vec::new());
    }
    (vec![lo, hi], Vec::new())
}

/// A linear tick label with as many decimals as the step needs; scientific
/// for very large or small magnitudes.
fn linear_label(v: f64, step: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    let step = step.abs();
    let step_exp = if step > 0.0 && step.is_finite() {
        step.log10().floor() as i32
    } else {
        v.abs().log10().floor() as i32 - 3
    };
    let v_exp = v.abs().log10().floor() as i32;
    if v_exp >= 6 || v_exp <= -4 || step_exp <= -5 {
        let digits = (v_exp - step_exp).clamp(0, 6) as usize;
        sci(v, digits)
    } else {
        let decimals = (-step_exp).clamp(0, 12) as usize;
        format!("{v:.decimals$}")
    }
}

/// `v` as `1.5e-4`: `digits` digits after the point, trailing zeros dropped.
fn sci(v: f64, digits: usize) -> String {
    let s = format!("{v:.digits$e}");
    match s.split_once('e') {
        Some((m, e)) if m.contains('.') => {
            let m = m.trim_end_matches('0').trim_end_matches('.');
            format!("{m}e{e}")
        }
        _ => s,
    }
}

/// The label of a log-axis tick at `log10` value `v`: `0.01 … 100` written
/// out, `1e-3`, `2e5` etc. beyond.
fn log_label(v: f64) -> String {
    let e = (v + 1e-9).floor();
    let m = 10f64.powf(v - e);
    let m_round = m.round();
    if (m - m_round).abs() > 1e-6 * m || !(1.0..10.0).contains(&m_round) {
        // Not a 1…9 multiple (a range-end fallback tick).
        return sci(10f64.powf(v), 2);
    }
    let (m, e) = (m_round as i64, e as i64);
    match e {
        -2..=-1 => format!("{:.*}", (-e) as usize, m as f64 * 10f64.powi(e as i32)),
        0..=2 => format!("{}", m * 10i64.pow(e as u32)),
        _ => format!("{m}e{e}"),
    }
}

/// The drawable points of a series in plotted units, split into runs at
/// points that cannot be drawn, so lines do not bridge gaps in the data.
fn runs(s: &Series, x: Axis, y: Axis) -> Vec<Vec<(f64, f64)>> {
    let mut out = vec![Vec::new()];
    for &(px, py) in &s.points {
        match (Scale::map(x, px), Scale::map(y, py)) {
            (Some(a), Some(b)) => out.last_mut().unwrap().push((a, b)),
            _ => {
                if !out.last().unwrap().is_empty() {
                    out.push(Vec::new());
                }
            }
        }
    }
    out.retain(|r| !r.is_empty());
    out
}

/// The corner where the legend covers the least data: points and samples
/// along line segments are counted in a box of the legend's approximate
/// size in each corner.
fn legend_corner(
    chart: &Chart,
    data: &[Vec<Vec<(f64, f64)>>],
    x: &Scale,
    y: &Scale,
) -> (SeriesLabelPosition, usize, f64) {
    let plot_w = (SIZE.0 - Y_LABEL_AREA - 2 * MARGIN) as f64;
    let plot_h = (SIZE.1 - X_LABEL_AREA - 2 * MARGIN - 2 * CAPTION_SIZE) as f64;
    let w = (legend_width(chart) as f64 / plot_w).min(1.0);
    let h = ((chart.series.len() as f64 * (LEGEND_SIZE as f64 + 5.0) + 30.0) / plot_h).min(1.0);
    let mut samples = Vec::new();
    for (s, runs) in chart.series.iter().zip(data) {
        for run in runs {
            for (k, &(px, py)) in run.iter().enumerate() {
                let (u, v) = (x.unit(px), y.unit(py));
                samples.push((u, v));
                if s.style.has_line() && k > 0 {
                    let (u0, v0) = (x.unit(run[k - 1].0), y.unit(run[k - 1].1));
                    for t in 1..8 {
                        let t = t as f64 / 8.0;
                        samples.push((u0 + (u - u0) * t, v0 + (v - v0) * t));
                    }
                }
            }
        }
    }
    // Preference order on ties: upper right, upper left, lower right, lower left.
    [
        (SeriesLabelPosition::UpperRight, 1.0 - w, 1.0 - h),
        (SeriesLabelPosition::UpperLeft, 0.0, 1.0 - h),
        (SeriesLabelPosition::LowerRight, 1.0 - w, 0.0),
        (SeriesLabelPosition::LowerLeft, 0.0, 0.0),
    ]
    .into_iter()
    .map(|(pos, u0, v0)| {
        let n = samples
            .iter()
            .filter(|&&(u, v)| u >= u0 && u <= u0 + w && v >= v0 && v <= v0 + h)
            .count();
        (n, pos)
    })
    .min_by_key(|(n, _)| *n)
    .map_or((SeriesLabelPosition::UpperRight, 0, h), |(n, pos)| {
        (pos, n, h)
    })
}

/// Width in pixels of the legend box (the naive font estimate: 0.7 em per
/// character).
fn legend_width(chart: &Chart) -> u32 {
    let longest = chart
        .series
        .iter()
        .map(|s| s.name.chars().count())
        .max()
        .unwrap_or(0);
    (longest as f64 * LEGEND_SIZE as f64 * 0.7 / 1.24 / 1.24 + 60.0).ceil() as u32
}

/// Renders the chart as SVG text.
pub fn render_svg(chart: &Chart) -> Result<String> {
    let data: Vec<Vec<Vec<(f64, f64)>>> = chart
        .series
        .iter()
        .map(|s| runs(s, chart.x_axis, chart.y_axis))
        .collect();
    let all = || data.iter().flatten().flatten();
    let x = Scale::new(chart.x_axis, all().map(|p| p.0));
    let y = Scale::new(chart.y_axis, all().map(|p| p.1));
    let empty = all().next().is_none();
    let (corner, covered, _) = legend_corner(chart, &data, &x, &y);
    // When every corner of the plot covers data, the legend goes to the
    // right of the plot, in a wider image.
    let outside = (covered > 0).then(|| legend_width(chart));
    let size = (SIZE.0 + outside.unwrap_or(0), SIZE.1);

    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
        root.fill(&WHITE)?;
        let mut ctx = ChartBuilder::on(&root)
            .caption(&chart.title, ("sans-serif", CAPTION_SIZE))
            .margin(MARGIN)
            .margin_right(MARGIN + outside.unwrap_or(0))
            .x_label_area_size(X_LABEL_AREA)
            .y_label_area_size(Y_LABEL_AREA)
            .build_cartesian_2d(x.clone(), y.clone())?;
        let x_fmt = |v: &f64| x.label(*v);
        let y_fmt = |v: &f64| y.label(*v);
        ctx.configure_mesh()
            .x_desc(&chart.x_label)
            .y_desc(&chart.y_label)
            .x_label_formatter(&x_fmt)
            .y_label_formatter(&y_fmt)
            .label_style(("sans-serif", LABEL_SIZE))
            .axis_desc_style(("sans-serif", LABEL_SIZE))
            .bold_line_style(BLACK.mix(0.15))
            .light_line_style(BLACK.mix(0.05))
            .draw()?;

        draw_series(&mut ctx, chart, &data)?;
        if outside.is_some() {
            draw_legend_outside(&root, chart)?;
        } else if !chart.series.is_empty() {
            ctx.configure_series_labels()
                .position(corner)
                .label_font(("sans-serif", LEGEND_SIZE))
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK.mix(0.4))
                .draw()?;
        }
        if empty {
            draw_no_data(&ctx)?;
        }
        root.present()?;
    }
    Ok(svg)
}

/// The chart's coordinates on an SVG.
type SvgChart<'a, 'b> = ChartContext<'a, SVGBackend<'b>, Cartesian2d<Scale, Scale>>;

/// Draws every series' runs and its legend entry.
fn draw_series<'a, 'b: 'a>(
    ctx: &mut SvgChart<'a, 'b>,
    chart: &Chart,
    data: &[Vec<Vec<(f64, f64)>>],
) -> Result<()> {
    for (n, (s, runs)) in chart.series.iter().zip(data).enumerate() {
        let color = PALETTE[s.color.unwrap_or(n) % PALETTE.len()];
        let line = color.stroke_width(2);
        for run in runs {
            match s.style {
                Style::Points => {}
                Style::Dashed => {
                    ctx.draw_series(DashedLineSeries::new(run.iter().copied(), 8, 5, line))?;
                }
                Style::Line | Style::LinePoints => {
                    ctx.draw_series(LineSeries::new(run.iter().copied(), line))?;
                }
            }
            // A lone point of a line has no line to show: mark it.
            if matches!(s.style, Style::Points | Style::LinePoints) || run.len() == 1 {
                ctx.draw_series(run.iter().map(|&p| Circle::new(p, MARKER, color.filled())))?;
            }
        }
        // The legend entry: an empty series carrying the label, so a
        // series split into runs (or with nothing drawable) gets one entry.
        let anno = ctx.draw_series(std::iter::empty::<Circle<(f64, f64), u32>>())?;
        let glyph = Glyph::of(s.style);
        let [piece0, piece1] = glyph.pieces;
        // Transparent parts are not written to the SVG.
        let line_style = if glyph.line { line } else { TRANSPARENT.into() };
        let marker_style = if glyph.marker {
            color.filled()
        } else {
            TRANSPARENT.into()
        };
        // The closure must return a concrete element: plotters' dynamic
        // elements would need a 'static backend.
        anno.label(s.name.as_str()).legend(move |at| {
            EmptyElement::at(at)
                + PathElement::new(piece0.to_vec(), line_style)
                + PathElement::new(piece1.to_vec(), line_style)
                + Circle::new((10, 0), MARKER, marker_style)
        });
    }
    Ok(())
}

/// The legend to the right of the plot, drawn in pixels.
fn draw_legend_outside(
    root: &DrawingArea<SVGBackend, plotters::coord::Shift>,
    chart: &Chart,
) -> Result<()> {
    let x0 = (SIZE.0 - MARGIN + 10) as i32;
    for (i, s) in chart.series.iter().enumerate() {
        let color = PALETTE[s.color.unwrap_or(i) % PALETTE.len()];
        let y = (MARGIN + 2 * CAPTION_SIZE) as i32 + i as i32 * (LEGEND_SIZE as i32 + 7);
        let glyph = Glyph::of(s.style);
        if glyph.line {
            for piece in glyph.pieces {
                let pts: Vec<(i32, i32)> =
                    piece.iter().map(|&(px, py)| (x0 + px, y + py)).collect();
                root.draw(&PathElement::new(pts, color.stroke_width(2)))?;
            }
        }
        if glyph.marker {
            root.draw(&Circle::new((x0 + 10, y), MARKER, color.filled()))?;
        }
        let style = ("sans-serif", LEGEND_SIZE).into_text_style(root).pos(
            plotters::style::text_anchor::Pos::new(
                plotters::style::text_anchor::HPos::Left,
                plotters::style::text_anchor::VPos::Center,
            ),
        );
        root.draw(&Text::new(s.name.as_str(), (x0 + 28, y), style))?;
    }
    Ok(())
}

/// "no data" in the middle of an empty plot.
fn draw_no_data(ctx: &SvgChart) -> Result<()> {
    let area = ctx.plotting_area();
    let (w, h) = area.dim_in_pixel();
    let grey = BLACK.mix(0.6);
    let style = ("sans-serif", LABEL_SIZE + 3)
        .into_text_style(area)
        .color(&grey)
        .pos(plotters::style::text_anchor::Pos::new(
            plotters::style::text_anchor::HPos::Center,
            plotters::style::text_anchor::VPos::Center,
        ));
    area.strip_coord_spec().draw(&Text::new(
        "no data",
        ((w / 2) as i32, (h / 2) as i32),
        style,
    ))?;
    Ok(())
}

/// The legend sample of a series, relative to its anchor.
struct Glyph {
    /// Two line pieces: one 20-pixel line in two halves, or a dash and a gap
    /// then a dash.
    pieces: [[(i32, i32); 2]; 2],
    line: bool,
    /// A marker in the middle.
    marker: bool,
}

impl Glyph {
    fn of(style: Style) -> Glyph {
        let solid = [[(0, 0), (10, 0)], [(10, 0), (20, 0)]];
        let (pieces, line, marker) = match style {
            Style::Line => (solid, true, false),
            Style::Points => (solid, false, true),
            Style::LinePoints => (solid, true, true),
            Style::Dashed => ([[(0, 0), (8, 0)], [(13, 0), (21, 0)]], true, false),
        };
        Glyph {
            pieces,
            line,
            marker,
        }
    }
}

/// Writes it atomically (temporary file in the same directory, then rename).
pub fn write_svg(path: &Path, chart: &Chart) -> Result<()> {
    crate::common::write_atomic(path, render_svg(chart)?.as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::fs;

    fn series(name: &str, style: Style, points: Vec<(f64, f64)>) -> Series {
        Series {
            name: name.into(),
            points,
            style,
            color: None,
        }
    }

    fn chart(x_axis: Axis, y_axis: Axis, series: Vec<Series>) -> Chart {
        Chart {
            title: "Error against size".into(),
            x_label: "bits per coefficient".into(),
            y_label: "relative L2 error".into(),
            x_axis,
            y_axis,
            series,
        }
    }

    /// Text contents of every `<text>` element.
    fn texts(svg: &str) -> Vec<String> {
        svg.split("<text")
            .skip(1)
            .filter_map(|t| {
                let body = &t[t.find('>')? + 1..];
                Some(body[..body.find("</text>")?].trim().to_string())
            })
            .collect()
    }

    fn count(svg: &str, tag: &str) -> usize {
        svg.matches(&format!("<{tag} ")).count()
    }

    fn assert_labelled(svg: &str, c: &Chart) {
        assert!(svg.starts_with("<svg"), "{}", &svg[..100.min(svg.len())]);
        // 800 wide, wider when the legend moves to the right of the plot.
        let width: u32 = svg["<svg width=\"".len()..]
            .split('"')
            .next()
            .unwrap()
            .parse()
            .unwrap();
        assert!(width >= 800 && svg.contains(r#"height="520""#));
        assert!(svg.trim_end().ends_with("</svg>"));
        let t = texts(svg);
        for want in [&c.title, &c.x_label, &c.y_label] {
            assert!(t.contains(want), "{want:?} not among {t:?}");
        }
        for s in &c.series {
            assert!(t.contains(&s.name), "{:?} not among {t:?}", s.name);
        }
    }

    #[test]
    fn linear_chart_has_labels_lines_and_points() {
        let xs: Vec<f64> = (0..20).map(|i| i as f64 * 0.5).collect();
        let c = chart(
            Axis::Linear,
            Axis::Linear,
            vec![
                series(
                    "line",
                    Style::Line,
                    xs.iter().map(|&x| (x, x * x)).collect(),
                ),
                series(
                    "points",
                    Style::Points,
                    xs.iter().map(|&x| (x, 3.0 * x)).collect(),
                ),
                series(
                    "both",
                    Style::LinePoints,
                    xs.iter().map(|&x| (x, 40.0 - x)).collect(),
                ),
                series(
                    "dashed",
                    Style::Dashed,
                    xs.iter().map(|&x| (x, 10.0)).collect(),
                ),
            ],
        );
        let svg = render_svg(&c).unwrap();
        assert_labelled(&svg, &c);
        // One polyline per line series plus legend glyphs and many dashes;
        // 20 + 20 data markers plus the legend markers.
        assert!(count(&svg, "polyline") >= 3 + 3);
        assert!(count(&svg, "circle") >= 40 + 2, "{}", count(&svg, "circle"));
        let t = texts(&svg);
        // Tick labels at 1–2–5 steps.
        for tick in ["0", "2", "4", "8", "20", "40", "80"] {
            assert!(t.iter().any(|s| s == tick), "tick {tick} not among {t:?}");
        }
        assert!(!t.iter().any(|s| s == "no data"));
    }

    #[test]
    fn log_log_chart_labels_decades() {
        let c = chart(
            Axis::Log,
            Axis::Log,
            vec![
                series(
                    "adaptive",
                    Style::LinePoints,
                    (0..12)
                        .map(|i| (0.02 * 2f64.powi(i), 0.5 * 0.5f64.powi(i)))
                        .collect(),
                ),
                series(
                    "2d",
                    Style::Line,
                    (0..12)
                        .map(|i| (0.02 * 2f64.powi(i), 0.9 * 0.6f64.powi(i)))
                        .collect(),
                ),
                series("targets", Style::Points, vec![(1.0, 1e-3), (10.0, 1e-2)]),
            ],
        );
        let svg = render_svg(&c).unwrap();
        assert_labelled(&svg, &c);
        let t = texts(&svg);
        for tick in ["1e-3", "0.01", "0.1", "1", "10"] {
            assert!(t.iter().any(|s| s == tick), "tick {tick} not among {t:?}");
        }
        assert!(count(&svg, "polyline") >= 2);
        assert!(count(&svg, "circle") >= 12 + 2);
    }

    #[test]
    fn log_labels_read_well() {
        let l = |v: f64| log_label(v.log10());
        assert_eq!(l(1e-3), "1e-3");
        assert_eq!(l(0.01), "0.01");
        assert_eq!(l(0.05), "0.05");
        assert_eq!(l(0.1), "0.1");
        assert_eq!(l(1.0), "1");
        assert_eq!(l(2.0), "2");
        assert_eq!(l(10.0), "10");
        assert_eq!(l(500.0), "500");
        assert_eq!(l(1e3), "1e3");
        assert_eq!(l(2e-5), "2e-5");
        assert_eq!(linear_label(0.30000000000000004, 0.1), "0.3");
        assert_eq!(linear_label(2e7, 1e6), "2e7");
        assert_eq!(linear_label(2.5e-5, 5e-6), "2.5e-5");
        assert_eq!(linear_label(-4.0, 2.0), "-4");
    }

    #[test]
    fn narrow_log_range_gets_sub_decade_ticks() {
        let s = Scale::new(Axis::Log, [2f64.log10(), 8f64.log10()].into_iter());
        let labels: Vec<String> = s.ticks.iter().map(|&v| s.label(v)).collect();
        assert!(labels.len() >= 2, "{labels:?}");
        assert!(labels.contains(&"5".to_string()), "{labels:?}");
        let s = Scale::new(Axis::Log, [1e-9f64.log10(), 1e9f64.log10()].into_iter());
        assert!(s.ticks.len() <= 11 && s.ticks.len() >= 5, "{:?}", s.ticks);
    }

    #[test]
    fn degenerate_data_does_not_panic() {
        let nasty = vec![
            (f64::NAN, 1.0),
            (1.0, f64::INFINITY),
            (0.0, 0.0),
            (-1.0, -5.0),
            (f64::NEG_INFINITY, f64::NAN),
        ];
        for (x, y) in [
            (Axis::Linear, Axis::Linear),
            (Axis::Log, Axis::Log),
            (Axis::Linear, Axis::Log),
            (Axis::Log, Axis::Linear),
        ] {
            // No series at all.
            let svg = render_svg(&chart(x, y, vec![])).unwrap();
            assert!(texts(&svg).contains(&"no data".to_string()));
            // Series with nothing drawable keep their legend entry.
            let only_bad = chart(
                x,
                y,
                vec![
                    series("empty", Style::Line, vec![]),
                    series("bad", Style::Points, vec![(f64::NAN, f64::NAN)]),
                ],
            );
            let svg = render_svg(&only_bad).unwrap();
            assert_labelled(&svg, &only_bad);
            // A single point, all-equal values, zeros, negatives and NaN mixed
            // with good points, unsorted x, huge magnitudes.
            for style in [Style::Line, Style::Points, Style::LinePoints, Style::Dashed] {
                let mut mixed = nasty.clone();
                mixed.extend([(3.0, 2.0), (2.0, 2.0), (5.0, 2.0)]);
                let c = chart(
                    x,
                    y,
                    vec![
                        series("single", style, vec![(1.0, 1.0)]),
                        series("mixed", style, mixed),
                        series("zero", style, vec![(0.0, 0.0), (0.0, 0.0)]),
                        series(
                            "huge",
                            style,
                            vec![(f64::MAX, -f64::MAX), (-f64::MAX, f64::MAX)],
                        ),
                        series(
                            "tiny",
                            style,
                            vec![(f64::MIN_POSITIVE, 1e-300), (1e-310, 1e-320)],
                        ),
                    ],
                );
                let svg = render_svg(&c).unwrap();
                assert_labelled(&svg, &c);
                for one in &c.series {
                    let c1 = chart(x, y, vec![one.clone()]);
                    render_svg(&c1).unwrap();
                }
            }
        }
    }

    #[test]
    fn single_point_and_equal_values_give_a_range() {
        for axis in [Axis::Linear, Axis::Log] {
            for v in [0.0, 1.0, 1e-3, -7.0, 123.0] {
                let Some(p) = Scale::map(axis, v) else {
                    continue;
                };
                let s = Scale::new(axis, [p, p, p].into_iter());
                assert!(s.hi > s.lo && s.lo <= p && p <= s.hi, "{axis:?} {v}");
                assert!(!s.ticks.is_empty());
            }
        }
        for vals in [vec![-f64::MAX, f64::MAX], vec![f64::MAX], vec![-f64::MAX]] {
            let s = Scale::new(Axis::Linear, vals.iter().copied());
            assert!(
                s.lo.is_finite() && s.hi.is_finite() && s.hi > s.lo,
                "{vals:?}"
            );
            assert!(s.ticks.len() >= 2, "{vals:?}: {:?}", s.ticks);
            assert!(s.ticks.iter().all(|t| t.is_finite()));
            for v in vals {
                assert!((0.0..=1.0).contains(&s.unit(v)));
            }
        }
    }

    #[test]
    fn palette_cycles_beyond_its_colours() {
        let many: Vec<Series> = (0..13)
            .map(|i| {
                series(
                    &format!("s{i}"),
                    Style::Line,
                    vec![(0.0, i as f64), (1.0, i as f64 + 1.0)],
                )
            })
            .collect();
        let svg = render_svg(&chart(Axis::Linear, Axis::Linear, many.clone())).unwrap();
        let c = chart(Axis::Linear, Axis::Linear, many);
        assert_labelled(&svg, &c);
        // Legend order follows series order.
        let t = texts(&svg);
        let pos: Vec<usize> = (0..13)
            .map(|i| t.iter().position(|s| *s == format!("s{i}")).unwrap())
            .collect();
        assert!(pos.windows(2).all(|w| w[0] < w[1]), "{pos:?}");
        assert!(PALETTE.len() >= 8);
        for (i, a) in PALETTE.iter().enumerate() {
            for b in &PALETTE[i + 1..] {
                assert_ne!(a, b);
            }
        }
    }

    #[test]
    fn write_svg_is_atomic_and_matches_render() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("error.svg");
        let c = chart(
            Axis::Linear,
            Axis::Log,
            vec![series("a", Style::Line, vec![(1.0, 0.1), (2.0, 0.01)])],
        );
        fs::write(&path, "old").unwrap();
        write_svg(&path, &c).unwrap();
        assert_eq!(fs::read_to_string(&path).unwrap(), render_svg(&c).unwrap());
        let names: Vec<_> = fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from("error.svg")]);
        // A missing directory is an error and leaves nothing behind.
        assert!(write_svg(&dir.path().join("missing/x.svg"), &c).is_err());
        assert!(write_svg(Path::new("/"), &c).is_err());
    }
}
