//! The report's pages: `index.md`, `results.json` and the SVG plots, all
//! derived from [`Results`].

use super::plot::{write_svg, Axis, Chart, Series, Style};
use super::{Coding, RelightPoint, Results};
use crate::common::write_atomic;
use anyhow::Result;
use ltm_codec::Mode;
use ltm_relight::Weighting;
use std::fmt::Write as _;
use std::path::Path;

/// The modes in the order of the tables and plots.
const MODES: [Mode; 4] = [Mode::TwoD, Mode::FourD, Mode::Adaptive, Mode::Pca];
/// The weightings in the order of the tables and plots.
const WEIGHTINGS: [Weighting; 3] = [Weighting::Unweighted, Weighting::Transport, Weighting::Area];
/// The peers of `tools/validate/peers.py`, in the order of the tables.
const PEERS: [&str; 3] = ["sz3", "zfp", "sperr"];

/// The relit-frame numbers of one (setting, weighting, N), averaged over maps.
#[derive(Clone, Copy, Debug, Default)]
struct Frame {
    n: usize,
    lights: usize,
    frame_ms: f64,
    relit_error: f64,
    dynamic_compression: f64,
    nonzeros: f64,
}

/// Mean over maps of each N's points with `weighting`, in N order.
fn frames(points: &[RelightPoint], weighting: Weighting) -> Vec<Frame> {
    let mut ns: Vec<usize> = points.iter().map(|p| p.n).collect();
    ns.sort_unstable();
    ns.dedup();
    ns.into_iter()
        .filter_map(|n| {
            let sel: Vec<&RelightPoint> = points
                .iter()
                .filter(|p| p.n == n && p.weighting == weighting)
                .collect();
            let k = sel.len() as f64;
            (!sel.is_empty()).then(|| Frame {
                n,
                lights: sel[0].lights,
                frame_ms: sel.iter().map(|p| p.frame_ms).sum::<f64>() / k,
                relit_error: sel.iter().map(|p| p.relit_error).sum::<f64>() / k,
                dynamic_compression: sel.iter().map(|p| p.dynamic_compression).sum::<f64>() / k,
                nonzeros: sel.iter().map(|p| p.nonzeros as f64).sum::<f64>() / k,
            })
        })
        .collect()
}

/// Points that no other point beats in both coordinates (smaller is
/// better), sorted by x.
fn pareto(mut pts: Vec<(f64, f64)>) -> Vec<(f64, f64)> {
    pts.retain(|p| p.0.is_finite() && p.1.is_finite());
    pts.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
    let mut front: Vec<(f64, f64)> = Vec::new();
    for p in pts {
        if front.last().is_none_or(|l| p.1 < l.1) {
            front.push(p);
        }
    }
    front
}

/// Bytes a mode needs for matrix error `e`: log-log interpolation on its
/// size/error front; None outside the front's range.
fn size_at_error(codings: &[Coding], mode: Mode, e: f64) -> Option<f64> {
    let front = pareto(
        codings
            .iter()
            .filter(|c| c.mode == mode && c.matrix_error > 0.0)
            .map(|c| (c.matrix_error, c.file_bytes as f64))
            .collect(),
    );
    front.windows(2).find_map(|w| {
        let ((e0, b0), (e1, b1)) = (w[0], w[1]);
        (e0 <= e && e <= e1).then(|| {
            let t = (e.ln() - e0.ln()) / (e1.ln() - e0.ln()).max(f64::MIN_POSITIVE);
            (b0.ln() + t * (b1.ln() - b0.ln())).exp()
        })
    })
}

/// The smallest file of `mode` coded for target error `target` that met it.
fn coded_at(r: &Results, mode: Mode, target: f64) -> Option<&Coding> {
    r.codings
        .iter()
        .filter(|c| c.mode == mode && c.target_met && (c.target_error - target).abs() < 1e-9)
        .min_by_key(|c| c.file_bytes)
}

/// The peers beside ltm at each of their target errors, and what
/// relighting from each costs.
fn peers_table(md: &mut String, r: &Results) -> Result<()> {
    if r.peers.is_empty() {
        return Ok(());
    }
    let raw = r.scene.raw_bytes as f64;
    let mut targets: Vec<f64> = r.peers.iter().map(|p| p.target).collect();
    targets.sort_by(f64::total_cmp);
    targets.dedup();
    writeln!(
        md,
        "### Peers: SZ3, ZFP and SPERR at equal matrix error
"
    )?;
    writeln!(md, "Each cell: file size, ratio against the raw f32 matrix, measured matrix error. ltm: the smallest file over the swept bits coded for that target; SZ3, ZFP and SPERR (`tools/validate/peers.py`): the error parameter (SZ3's absolute bound, ZFP's tolerance, SPERR's quantization step) bisected to the target, the smallest over the layouts (P, M·C), (H, W, M·C), (P, 6, n, n·C) and (M·C, H, W) (kept layout in brackets). Last column: adaptive's size over the smallest peer's.\n")?;
    writeln!(
        md,
        "| target | ltm 2d | ltm adaptive | SZ3 | ZFP | SPERR | adaptive / best peer |\n|---|---|---|---|---|---|---|"
    )?;
    let cell = |bytes: u64, err: f64| {
        format!(
            "{} MB ({:.1}×, {})",
            mb(bytes as f64),
            raw / bytes as f64,
            pct(err)
        )
    };
    for &t in &targets {
        let ours = |mode: Mode| coded_at(r, mode, t);
        let peer = |m: &str| r.peers.iter().find(|p| p.method == m && p.target == t);
        let ltm_cell =
            |c: Option<&Coding>| c.map_or("–".into(), |c| cell(c.file_bytes, c.matrix_error));
        let peer_cell = |m: &str| {
            peer(m).map_or("–".into(), |p| {
                format!("{} [{}]", cell(p.bytes, p.matrix_error), p.shape)
            })
        };
        let best = PEERS.iter().filter_map(|m| peer(m)).map(|p| p.bytes).min();
        let ratio = match (ours(Mode::Adaptive), best) {
            (Some(a), Some(p)) => format!("{:.2}", a.file_bytes as f64 / p as f64),
            _ => "–".into(),
        };
        writeln!(
            md,
            "| {} | {} | {} | {} | {} | {} | {} |",
            pct(t),
            ltm_cell(ours(Mode::TwoD)),
            ltm_cell(ours(Mode::Adaptive)),
            peer_cell("sz3"),
            peer_cell("zfp"),
            peer_cell("sperr"),
            ratio
        )?;
    }
    writeln!(md, "\nRelighting from a peer means decompressing the whole matrix once and a dense `T·L` per frame (numpy, median of 5); an `.ltm` file is relit from its compressed columns:\n")?;
    writeln!(
        md,
        "| peer | target | compress s | decompress s | dense frame ms |\n|---|---|---|---|---|"
    )?;
    for p in &r.peers {
        writeln!(
            md,
            "| {} | {} | {:.2} | {:.2} | {:.1} |",
            peer_name(&p.method),
            pct(p.target),
            p.compress_s,
            p.decompress_s,
            1e3 * p.frame_s
        )?;
    }
    writeln!(md)?;
    Ok(())
}

fn peer_name(method: &str) -> &str {
    super::peers::name(method)
}

fn pair(r: &Results, mode: Mode) -> Option<&Coding> {
    r.codings.iter().find(|c| c.quality_pair && c.mode == mode)
}

fn mb(bytes: f64) -> String {
    format!("{:.3}", bytes / 1e6)
}

fn pct(e: f64) -> String {
    format!("{:.3} %", 100.0 * e)
}

fn svg(dir: &Path, name: &str, chart: Chart) -> Result<String> {
    write_svg(&dir.join(name), &chart)?;
    Ok(format!("![{}]({name})\n", chart.title))
}

fn series(name: impl Into<String>, points: Vec<(f64, f64)>, style: Style) -> Series {
    Series {
        name: name.into(),
        points,
        style,
        color: None,
    }
}

fn chart(title: &str, x: &str, y: &str, axes: (Axis, Axis), series: Vec<Series>) -> Chart {
    Chart {
        title: title.into(),
        x_label: x.into(),
        y_label: y.into(),
        x_axis: axes.0,
        y_axis: axes.1,
        series,
    }
}

const LOG: (Axis, Axis) = (Axis::Log, Axis::Log);

/// Writes `results.json`, the plots and `index.md` into `dir`.
pub fn write(dir: &Path, r: &Results) -> Result<()> {
    write_atomic(
        &dir.join("results.json"),
        serde_json::to_string_pretty(r)?.as_bytes(),
    )?;
    let mut md = String::new();
    let s = &r.settings;
    let sc = &r.scene;
    writeln!(md, "# ltm report\n")?;
    writeln!(
        md,
        "- **Date:** {}\n- **Machine:** {}, {} threads, {:.1} GiB RAM, {}\n- **Matrix:** {}; {}×{} pixels, 6·{}² = {} lights, {} channel(s){}; raw {} MB{}\n- **Maps:** {}\n- **Settings:** row filter {}, column filter {}; bits {:?}; target errors {:?}; N {:?}; median of {} frames; equal-quality pair at {} matrix error and {} bits\n- **Command:** `{}`\n",
        r.date,
        r.machine.cpu,
        r.machine.threads,
        r.machine.memory_gib,
        r.machine.os,
        sc.source,
        sc.width,
        sc.height,
        sc.face_res,
        sc.lights,
        sc.channels,
        if sc.has_albedo { " + albedo" } else { "" },
        mb(sc.raw_bytes as f64),
        if r.out_of_core { " (transposed out of core)" } else { "" },
        r.envs.join(", "),
        s.row_filter,
        s.col_filter,
        s.bits,
        s.errors,
        s.terms,
        s.frames,
        pct(s.quality),
        s.quality_bits,
        r.command,
    )?;
    if s.quick {
        writeln!(md, "> A `--quick` run: a tiny matrix and few settings. It checks that every section is produced; its figures are not meaningful.\n")?;
    }
    writeln!(md, "Errors are relative L2 (Frobenius) norms: the *matrix error* of a decoded file against the raw matrix; the *relit error* of a relit image against the exact product `T·L` of the raw matrix (`ltm reference`). Frame times are medians; relit numbers are means over the maps.\n")?;

    headline(&mut md, r)?;
    peers_table(&mut md, r)?;
    size_error(&mut md, dir, r)?;
    relit_error(&mut md, dir, r)?;
    frame_time(&mut md, dir, r)?;
    depth_by_level(&mut md, dir, r)?;
    speed_error(&mut md, dir, r)?;
    geometry(&mut md, r)?;

    let t = &r.timings;
    writeln!(md, "## Run time\n")?;
    writeln!(md, "| bake or open | exact images | row transform + transpose | coding + relighting | baselines | total |\n|---|---|---|---|---|---|")?;
    let coding: f64 = r.codings.iter().map(|c| c.code_s).sum();
    writeln!(
        md,
        "| {:.1} s | {:.1} s | {:.1} s | {:.1} s (coding {:.1} s) | {:.1} s | {:.1} s |",
        t.bake_or_open_s,
        t.references_s,
        t.transpose_s,
        t.total_s - t.bake_or_open_s - t.references_s - t.transpose_s - t.baselines_s,
        coding,
        t.baselines_s,
        t.total_s
    )?;
    write_atomic(&dir.join("index.md"), md.as_bytes())
}

fn headline(md: &mut String, r: &Results) -> Result<()> {
    let s = &r.settings;
    writeln!(md, "## Headline\n")?;
    let raw = r.scene.raw_bytes as f64;
    if let Some(a) = pair(r, Mode::Adaptive) {
        writeln!(
            md,
            "Adaptive at `--bits {} --max-error {}`: {} MB, **{:.1}× smaller than the raw matrix** ({} MB), matrix error {}.\n",
            a.bits,
            s.quality,
            mb(a.file_bytes as f64),
            raw / a.file_bytes as f64,
            mb(raw),
            pct(a.matrix_error)
        )?;
    }
    writeln!(md, "Size at equal matrix error (log-log interpolation on each mode's size/error front over all bit depths):\n")?;
    writeln!(
        md,
        "| matrix error | 2d MB | 4d MB | adaptive MB | pca MB | 2d / adaptive | 4d / adaptive | pca / adaptive |\n|---|---|---|---|---|---|---|---|"
    )?;
    let mut errors = s.errors.clone();
    errors.push(s.quality);
    errors.sort_by(f64::total_cmp);
    errors.dedup();
    for e in errors {
        let sz: Vec<Option<f64>> = MODES
            .iter()
            .map(|&m| size_at_error(&r.codings, m, e))
            .collect();
        if sz.iter().all(Option::is_none) {
            // No mode reached this error: a row of dashes says nothing.
            continue;
        }
        let cell = |v: Option<f64>| v.map_or("–".into(), mb);
        let ratio = |a: Option<f64>, b: Option<f64>| match (a, b) {
            (Some(a), Some(b)) => format!("{:.2}×", a / b),
            _ => "–".into(),
        };
        writeln!(
            md,
            "| {} | {} | {} | {} | {} | {} | {} | {} |",
            pct(e),
            cell(sz[0]),
            cell(sz[1]),
            cell(sz[2]),
            cell(sz[3]),
            ratio(sz[0], sz[2]),
            ratio(sz[1], sz[2]),
            ratio(sz[3], sz[2])
        )?;
    }
    writeln!(
        md,
        "\n\"–\": the error lies outside the errors that mode reached in this sweep.\n"
    )?;
    best_at_relit_error(md, r, 0.01)?;
    if let (Some(a), Some(d)) = (pair(r, Mode::Adaptive), pair(r, Mode::TwoD)) {
        writeln!(
            md,
            "Relighting the equal-quality pair (both at {} target matrix error, {} bits; transport-weighted wavelet lights):\n",
            pct(s.quality),
            s.quality_bits
        )?;
        writeln!(md, "| N | 2d frames/s | adaptive frames/s | adaptive vs 2d | relit error 2d | relit error adaptive |\n|---|---|---|---|---|---|")?;
        let (fa, fd) = (
            frames(&a.relight, Weighting::Transport),
            frames(&d.relight, Weighting::Transport),
        );
        for (x, y) in fd.iter().zip(&fa) {
            writeln!(
                md,
                "| {} | {:.0} | {:.0} | {:.2}× | {} | {} |",
                x.n,
                1e3 / x.frame_ms,
                1e3 / y.frame_ms,
                x.frame_ms / y.frame_ms,
                pct(x.relit_error),
                pct(y.relit_error)
            )?;
        }
        writeln!(md)?;
    }
    Ok(())
}

/// Each mode's Pareto front of (median frame time, relit error) over every
/// coded setting and N (transport weighting, means over maps).
fn speed_fronts(r: &Results) -> Vec<(Mode, Vec<(f64, f64)>)> {
    MODES
        .into_iter()
        .map(|mode| {
            let pts = r
                .codings
                .iter()
                .filter(|c| c.mode == mode)
                .flat_map(|c| frames(&c.relight, Weighting::Transport))
                .map(|f| (f.frame_ms, f.relit_error))
                .collect();
            (mode, pareto(pts))
        })
        .collect()
}

/// The headline's choice: which mode reaches relit error `e` within each
/// frame-time budget, and the fastest of all.
fn best_at_relit_error(md: &mut String, r: &Results, e: f64) -> Result<()> {
    let fronts = speed_fronts(r);
    let fastest: Vec<(&str, f64)> = fronts
        .iter()
        .filter_map(|(m, f)| f.iter().find(|p| p.1 <= e).map(|p| (m.name(), p.0)))
        .collect();
    let Some(best) = fastest.iter().min_by(|a, b| a.1.total_cmp(&b.1)) else {
        writeln!(
            md,
            "No mode reached {} relit error in this sweep.\n",
            pct(e)
        )?;
        return Ok(());
    };
    let others: Vec<String> = fastest
        .iter()
        .filter(|m| m.0 != best.0)
        .map(|(m, ms)| format!("{m} {ms:.3} ms"))
        .collect();
    writeln!(
        md,
        "**At ≤ {} relit error, {} is the fastest mode: {:.3} ms a frame** (others: {}). With a frame-time budget below {:.3} ms no mode reaches {}; above it, {} does.\n",
        pct(e),
        best.0,
        best.1,
        if others.is_empty() { "none reached it".into() } else { others.join(", ") },
        best.1,
        pct(e),
        best.0
    )?;
    Ok(())
}

fn size_error(md: &mut String, dir: &Path, r: &Results) -> Result<()> {
    writeln!(md, "## 1. Size against matrix error\n")?;
    md.push_str(&svg(
        dir,
        "size-error.svg",
        chart(
            "Size against matrix error",
            "relative L2 matrix error",
            "file size (MB)",
            LOG,
            size_series(r),
        ),
    )?);
    codings_table(md, r)?;
    baselines_table(md, r)
}

/// The size/error plot's series: each mode per bit depth, the baselines,
/// the peers, and the lossless and raw sizes across the errors shown.
fn size_series(r: &Results) -> Vec<Series> {
    let mut ser = Vec::new();
    for mode in MODES {
        // pca files choose their bits: one series over all of them.
        let bit_sets: Vec<Option<u32>> = if mode == Mode::Pca {
            vec![None]
        } else {
            r.settings.bits.iter().map(|&b| Some(b)).collect()
        };
        for b in bit_sets {
            let mut pts: Vec<(f64, f64)> = r
                .codings
                .iter()
                .filter(|c| c.mode == mode && b.is_none_or(|b| c.bits == b))
                .map(|c| (c.matrix_error, c.file_bytes as f64 / 1e6))
                .collect();
            pts.sort_by(|a, b| a.0.total_cmp(&b.0));
            let name = match b {
                Some(b) => format!("{} {b} bits", mode.name()),
                None => format!("{} (Eigentransport)", mode.name()),
            };
            ser.push(series(name, pts, Style::LinePoints));
        }
    }
    let mut x_range = r
        .codings
        .iter()
        .map(|c| c.matrix_error)
        .filter(|e| *e > 0.0)
        .fold((f64::INFINITY, 0.0f64), |(lo, hi), e| {
            (lo.min(e), hi.max(e))
        });
    for method in ["pca", "sh"] {
        let mut pts: Vec<(f64, f64)> = r
            .baselines
            .iter()
            .filter(|b| b.method == method)
            .map(|b| (b.matrix_error, b.bytes as f64 / 1e6))
            .collect();
        pts.sort_by(|a, b| a.0.total_cmp(&b.0));
        for p in &pts {
            if p.0 > 0.0 {
                x_range = (x_range.0.min(p.0), x_range.1.max(p.0));
            }
        }
        let name = if method == "pca" {
            "PCA (rank k)"
        } else {
            "spherical harmonics (order L)"
        };
        ser.push(series(name, pts, Style::LinePoints));
    }
    for method in PEERS {
        let mut pts: Vec<(f64, f64)> = r
            .peers
            .iter()
            .filter(|p| p.method == method && p.matrix_error > 0.0)
            .map(|p| (p.matrix_error, p.bytes as f64 / 1e6))
            .collect();
        if pts.is_empty() {
            continue;
        }
        pts.sort_by(|a, b| a.0.total_cmp(&b.0));
        for p in &pts {
            x_range = (x_range.0.min(p.0), x_range.1.max(p.0));
        }
        ser.push(series(peer_name(method), pts, Style::LinePoints));
    }
    if x_range.0.is_finite() {
        let flat = |y: f64| vec![(x_range.0, y), (x_range.1, y)];
        if let Some(z) = r.baselines.iter().find(|b| b.method == "zstd-raw") {
            ser.push(series(
                "zstd of the raw matrix (lossless)",
                flat(z.bytes as f64 / 1e6),
                Style::Dashed,
            ));
        }
        ser.push(series(
            "raw matrix",
            flat(r.scene.raw_bytes as f64 / 1e6),
            Style::Dashed,
        ));
    }
    ser
}

/// Every coded setting, one row each.
fn codings_table(md: &mut String, r: &Results) -> Result<()> {
    writeln!(md, "\nEvery coded setting (`ltm compress --mode M --bits B --max-error E`, coded from one transposed matrix):\n")?;
    writeln!(md, "| mode | bits | target | MB | ratio vs raw | matrix error | target met | nonzeros | coding s |\n|---|---|---|---|---|---|---|---|---|")?;
    for c in &r.codings {
        writeln!(
            md,
            "| {} | {} | {} | {} | {:.1}× | {} | {} | {} | {:.1} |",
            c.mode.name(),
            c.bits,
            pct(c.target_error),
            mb(c.file_bytes as f64),
            r.scene.raw_bytes as f64 / c.file_bytes as f64,
            pct(c.matrix_error),
            if c.target_met { "yes" } else { "no" },
            c.nonzeros,
            c.code_s
        )?;
    }
    Ok(())
}

/// The baselines on the same matrix, one row each.
fn baselines_table(md: &mut String, r: &Results) -> Result<()> {
    writeln!(md, "\nBaselines on the same matrix: lossless zstd (level {}) of the raw f32 rows; PCA over rows (rank-k randomized SVD, f32 factors, error measured in f64); spherical-harmonics projection of each row (order L, L² f32 coefficients per pixel and channel):\n", r.settings.zstd_raw_level)?;
    writeln!(
        md,
        "| method | k or L | MB | ratio vs raw | matrix error |\n|---|---|---|---|---|"
    )?;
    for b in &r.baselines {
        writeln!(
            md,
            "| {} | {} | {} | {:.1}× | {} |",
            b.method,
            b.param,
            mb(b.bytes as f64),
            r.scene.raw_bytes as f64 / b.bytes as f64,
            pct(b.matrix_error)
        )?;
    }
    writeln!(md)?;
    Ok(())
}

fn relit_error(md: &mut String, dir: &Path, r: &Results) -> Result<()> {
    writeln!(
        md,
        "## 2. Relit error against the number of wavelet lights\n"
    )?;
    let Some(a) = pair(r, Mode::Adaptive) else {
        return Ok(());
    };
    writeln!(md, "The adaptive file of the equal-quality pair, with each rule for choosing the N wavelet lights (Ng et al. 2003): unweighted (largest |L|), transport-weighted (|L| × column norm) and area-weighted (|L| × support area). The pca file at the same target matrix error relit with its first N eigen-transports, and spherical harmonics with L² coefficients, are on the same axes.\n")?;
    for env in &r.envs {
        md.push_str(&svg(
            dir,
            &format!("relit-error-{env}.svg"),
            chart(
                &format!("Relit error under {env}"),
                "lighting terms N",
                "relative L2 error vs T·L",
                LOG,
                relit_series(r, a, env),
            ),
        )?);
    }
    relit_tables(md, r, a)
}

/// The relit-error plot's series under one map: the adaptive file with
/// each weighting, the pca file and spherical harmonics.
fn relit_series(r: &Results, a: &Coding, env: &str) -> Vec<Series> {
    let under = |c: &Coding| -> Vec<RelightPoint> {
        c.relight.iter().filter(|p| p.env == env).cloned().collect()
    };
    let pts = under(a);
    let mut ser: Vec<Series> = WEIGHTINGS
        .iter()
        .map(|&w| {
            let f = frames(&pts, w);
            series(
                format!("adaptive, {}", w.name()),
                f.iter().map(|f| (f.lights as f64, f.relit_error)).collect(),
                Style::LinePoints,
            )
        })
        .collect();
    if let Some(p) = pair(r, Mode::Pca) {
        ser.push(series(
            "pca (first N eigen-transports)",
            frames(&under(p), Weighting::Transport)
                .iter()
                .map(|f| (f.lights as f64, f.relit_error))
                .collect(),
            Style::LinePoints,
        ));
    }
    ser.push(series(
        "spherical harmonics (L² terms)",
        r.sh_relight
            .iter()
            .filter(|p| p.env == env)
            .map(|p| (p.coefficients as f64, p.relit_error))
            .collect(),
        Style::LinePoints,
    ));
    ser
}

/// The relit errors' means over maps: the adaptive file per weighting, and
/// spherical harmonics per order.
fn relit_tables(md: &mut String, r: &Results, a: &Coding) -> Result<()> {
    writeln!(md, "\nMean over maps:\n")?;
    writeln!(
        md,
        "| N | unweighted | transport | area |\n|---|---|---|---|"
    )?;
    let f: Vec<Vec<Frame>> = WEIGHTINGS.iter().map(|&w| frames(&a.relight, w)).collect();
    for ((u, t), a) in f[0].iter().zip(&f[1]).zip(&f[2]) {
        writeln!(
            md,
            "| {} | {} | {} | {} |",
            u.n,
            pct(u.relit_error),
            pct(t.relit_error),
            pct(a.relit_error)
        )?;
    }
    writeln!(
        md,
        "\n| SH order L | terms | mean relit error |\n|---|---|---|"
    )?;
    for &order in &r.settings.sh_orders {
        let e: Vec<f64> = r
            .sh_relight
            .iter()
            .filter(|p| p.order == order)
            .map(|p| p.relit_error)
            .collect();
        writeln!(
            md,
            "| {order} | {} | {} |",
            order * order,
            pct(e.iter().sum::<f64>() / e.len().max(1) as f64)
        )?;
    }
    writeln!(md)?;
    Ok(())
}

fn frame_time(md: &mut String, dir: &Path, r: &Results) -> Result<()> {
    writeln!(md, "## 3. Frame time and dynamic compression against N\n")?;
    let pairs: Vec<&Coding> = [Mode::TwoD, Mode::Adaptive, Mode::Pca]
        .into_iter()
        .filter_map(|m| pair(r, m))
        .collect();
    if pairs.is_empty() {
        return Ok(());
    }
    writeln!(md, "The equal-quality pair (Fig. 9), transport weighting. The dynamic compression rate is the dense size of the N columns used (N × pixels × channels) over the coefficients multiply-added. G coef./s is the coefficients multiply-added per second of the whole frame (light transform, selection, multiply-add and inverse steps); each coefficient carries all stored channels.\n")?;
    let f: Vec<Vec<Frame>> = pairs
        .iter()
        .map(|c| frames(&c.relight, Weighting::Transport))
        .collect();
    let ser = |g: fn(&Frame) -> f64| -> Vec<Series> {
        pairs
            .iter()
            .zip(&f)
            .map(|(c, f)| {
                series(
                    format!("{} ({} MB)", c.mode.name(), mb(c.file_bytes as f64)),
                    f.iter().map(|x| (x.lights as f64, g(x))).collect(),
                    Style::LinePoints,
                )
            })
            .collect()
    };
    md.push_str(&svg(
        dir,
        "frame-time.svg",
        chart(
            "Frame time",
            "lighting terms N",
            "median frame time (ms)",
            LOG,
            ser(|x| x.frame_ms),
        ),
    )?);
    md.push_str(&svg(
        dir,
        "dynamic-compression.svg",
        chart(
            "Dynamic compression rate",
            "lighting terms N",
            "dense entries / coefficients used",
            LOG,
            ser(|x| x.dynamic_compression),
        ),
    )?);
    write!(md, "\n| N |")?;
    for c in &pairs {
        write!(
            md,
            " {m} ms | {m} frames/s | {m} dyn. compression | {m} G coef./s |",
            m = c.mode.name()
        )?;
    }
    writeln!(md, "\n|---|{}", "---|".repeat(4 * pairs.len()))?;
    // Rows of N that every file was relit at (a results.json edited by hand
    // may hold fewer points for one of them).
    let rows = f.iter().map(Vec::len).min().unwrap_or(0);
    for i in 0..rows {
        write!(md, "| {} |", f[0][i].n)?;
        for fr in &f {
            let x = fr[i];
            write!(
                md,
                " {:.3} | {:.0} | {:.1}× | {:.2} |",
                x.frame_ms,
                1e3 / x.frame_ms,
                x.dynamic_compression,
                x.nonzeros / x.frame_ms * 1e-6
            )?;
        }
        writeln!(md)?;
    }
    writeln!(md)?;
    Ok(())
}

fn depth_by_level(md: &mut String, dir: &Path, r: &Results) -> Result<()> {
    writeln!(md, "## 4. Average column depth by row-wavelet level\n")?;
    writeln!(md, "Adaptive files (Fig. 8). Level 0 is each face's scaling function; higher levels are finer wavelet lights.\n")?;
    let adaptive: Vec<&Coding> = r
        .codings
        .iter()
        .filter(|c| c.mode == Mode::Adaptive)
        .collect();
    let ser = adaptive
        .iter()
        .map(|c| {
            series(
                format!("{} bits, {}", c.bits, pct(c.target_error)),
                c.depth_by_row_level
                    .iter()
                    .enumerate()
                    .map(|(l, d)| (l as f64, *d))
                    .collect(),
                Style::LinePoints,
            )
        })
        .collect();
    md.push_str(&svg(
        dir,
        "depth-by-level.svg",
        chart(
            "Average column depth by row level",
            "row-wavelet level",
            "average column transform depth",
            (Axis::Linear, Axis::Linear),
            ser,
        ),
    )?);
    let levels = adaptive.first().map_or(0, |c| c.depth_by_row_level.len());
    write!(md, "\n| bits | target |")?;
    for l in 0..levels {
        write!(md, " level {l} |")?;
    }
    writeln!(md, "\n|---|---|{}", "---|".repeat(levels))?;
    for c in &adaptive {
        write!(md, "| {} | {} |", c.bits, pct(c.target_error))?;
        for d in &c.depth_by_row_level {
            write!(md, " {d:.2} |")?;
        }
        writeln!(md)?;
    }
    writeln!(md)?;
    Ok(())
}

/// Texture-space matrices: the relit texture and two views of the mesh.
fn geometry(md: &mut String, r: &Results) -> Result<()> {
    let Some(t) = &r.texture else {
        return Ok(());
    };
    writeln!(md, "## 6. Geometry relighting\n")?;
    writeln!(
        md,
        "The rows are the texels of a {s}×{s} geometry image, so one relight gives a texture that the mesh ({} triangles) is drawn with from any camera. `{}` relit under {} with N = {} transport-weighted wavelet lights: **{:.2} ms** per relight (median, {:.0} frames/s); relight plus one {v}×{v} view: **{:.2} ms** ({:.0} frames/s). Views: front and back of an orbit, drawn from the same relit texture.\n",
        t.triangles,
        t.file,
        t.env,
        t.terms,
        t.relight_ms,
        1e3 / t.relight_ms,
        t.relight_view_ms,
        1e3 / t.relight_view_ms,
        s = t.texture_side,
        v = super::texture::VIEW_SIDE,
    )?;
    for image in &t.images {
        write!(md, "![{image}]({image}) ")?;
    }
    writeln!(md, "\n")?;
    Ok(())
}

fn speed_error(md: &mut String, dir: &Path, r: &Results) -> Result<()> {
    writeln!(md, "## 5. Speed against error\n")?;
    writeln!(md, "Every (coded setting, N) as one point: median frame time against relit error (transport weighting, means over maps), with each mode's Pareto front.\n")?;
    let mut ser = Vec::new();
    let mut fronts = Vec::new();
    for (i, mode) in MODES.into_iter().enumerate() {
        let pts: Vec<(f64, f64)> = r
            .codings
            .iter()
            .filter(|c| c.mode == mode)
            .flat_map(|c| frames(&c.relight, Weighting::Transport))
            .map(|f| (f.frame_ms, f.relit_error))
            .collect();
        let front = pareto(pts.clone());
        for (name, pts, style) in [
            ("settings", pts, Style::Points),
            ("front", front.clone(), Style::Line),
        ] {
            ser.push(Series {
                color: Some(i),
                ..series(format!("{} {name}", mode.name()), pts, style)
            });
        }
        fronts.push((mode, front));
    }
    md.push_str(&svg(
        dir,
        "speed-error.svg",
        chart(
            "Speed against error",
            "median frame time (ms)",
            "relit error vs T·L",
            LOG,
            ser,
        ),
    )?);
    writeln!(md, "\nFastest frame time reaching each relit error:\n")?;
    write!(md, "| relit error |")?;
    for (mode, _) in &fronts {
        write!(md, " {} ms |", mode.name())?;
    }
    writeln!(md, "\n|---|{}", "---|".repeat(fronts.len()))?;
    for e in [0.1, 0.05, 0.02, 0.01, 0.005, 0.002] {
        write!(md, "| ≤ {} |", pct(e))?;
        for (_, front) in &fronts {
            match front.iter().find(|p| p.1 <= e) {
                Some(p) => write!(md, " {:.3} |", p.0)?,
                None => write!(md, " – |")?,
            }
        }
        writeln!(md)?;
    }
    writeln!(md)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pareto_keeps_only_undominated_points() {
        let f = pareto(vec![
            (3.0, 1.0),
            (1.0, 5.0),
            (2.0, 2.0),
            (2.5, 3.0),
            (f64::NAN, 0.0),
        ]);
        assert_eq!(f, vec![(1.0, 5.0), (2.0, 2.0), (3.0, 1.0)]);
    }
}
