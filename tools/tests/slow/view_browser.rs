//! `ltm view` in a real browser: headless Chromium is driven through the
//! page's own controls (map, rotation fields, drags on the image and on the
//! map preview, the N slider and field, exposure, the split view, the
//! heatmap, the probe, reset), and what it displays is checked against
//! `ltm relight` at the same settings, each file's error readout against
//! `ltm relight --reference`; a stopped server shows as offline.
//!
//! Chromium is found as `$LTM_CHROMIUM`, else `chromium`,
//! `chromium-browser` or `google-chrome` on the PATH. Without it the test
//! fails when `CI` is set (CI installs it: `.ci/run`) and is skipped with a
//! message otherwise.

use crate::view_support;

use headless_chrome::protocol::cdp::{Input, Page};
use headless_chrome::{Browser, LaunchOptions, Tab};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};
use view_support::*;

/// Longest wait for any one thing the page does.
const TIMEOUT: Duration = Duration::from_secs(60);

fn chromium() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("LTM_CHROMIUM") {
        return Some(PathBuf::from(p));
    }
    let path = std::env::var_os("PATH")?;
    for dir in std::env::split_paths(&path) {
        for name in ["chromium", "chromium-browser", "google-chrome"] {
            let p = dir.join(name);
            if p.is_file() {
                return Some(p);
            }
        }
    }
    None
}

/// Starts headless Chromium, or says why the test cannot run.
fn browser() -> Option<Browser> {
    let Some(path) = chromium() else {
        let msg = "Chromium not found (install Debian's `chromium` package or set LTM_CHROMIUM)";
        if std::env::var_os("CI").is_some() {
            panic!("{msg}; CI must run the browser test");
        }
        eprintln!("SKIPPED view_browser: {msg}");
        return None;
    };
    let options = LaunchOptions::default_builder()
        .path(Some(path.clone()))
        .headless(true)
        // The test runs as root in CI containers, where the sandbox cannot start.
        .sandbox(false)
        .window_size(Some((1300, 900)))
        // WebGL on a machine without a GPU runs on SwiftShader, which
        // Chromium no longer falls back to unasked (since about version 137).
        .args(vec![std::ffi::OsStr::new("--enable-unsafe-swiftshader")])
        .idle_browser_timeout(Duration::from_secs(300))
        .build()
        .expect("launch options");
    match Browser::new(options) {
        Ok(b) => Some(b),
        Err(e) => panic!("Chromium at {} could not start: {e:#}", path.display()),
    }
}

fn eval(tab: &Tab, js: &str) -> Value {
    tab.evaluate(js, false)
        .unwrap_or_else(|e| panic!("evaluating {js}: {e}"))
        .value
        .unwrap_or(Value::Null)
}

/// Sets a control's value and fires the event its listeners wait for, as
/// typing into it or moving it would.
fn set(tab: &Tab, id: &str, value: &str, event: &str) {
    tab.find_element(&format!("#{id}"))
        .unwrap()
        .call_js_fn(
            "function(v, ev) { this.value = v; this.dispatchEvent(new Event(ev, { bubbles: true })); }",
            vec![json!(value), json!(event)],
            false,
        )
        .unwrap_or_else(|e| panic!("setting #{id}: {e}"));
}

/// Waits until the canvas `id` shows the frame of `query`.
fn wait_shown(tab: &Tab, id: &str, query: &str) {
    let sel = format!("#{id}[data-shown=\"{query}\"]");
    if let Err(e) = tab.wait_for_element_with_custom_timeout(&sel, TIMEOUT) {
        let shown = eval(
            tab,
            &format!("document.getElementById('{id}').dataset.shown || ''"),
        );
        let msg = eval(tab, "document.getElementById('message').textContent");
        panic!(
            "{id} did not show {query} within {TIMEOUT:?} ({e}); it shows {shown}; page says {msg}"
        );
    }
}

/// The displayed 8-bit RGB pixels of a canvas.
fn pixels(tab: &Tab, id: &str) -> Vec<u8> {
    let js = format!(
        "(() => {{ const c = document.getElementById('{id}'); \
         return Array.from(c.getContext('2d').getImageData(0, 0, c.width, c.height).data).join(','); }})()"
    );
    let s = eval(tab, &js);
    let rgba: Vec<u8> = s
        .as_str()
        .unwrap()
        .split(',')
        .map(|v| v.parse().unwrap())
        .collect();
    rgba.chunks_exact(4)
        .flat_map(|p| [p[0], p[1], p[2]])
        .collect()
}

/// sRGB 8-bit of a linear value after `exposure` stops, as `ltm relight --png`.
fn srgb8(v: f32, exposure: f32) -> u8 {
    let v = (v * 2f32.powf(exposure)).clamp(0.0, 1.0);
    let e = if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    };
    (e * 255.0 + 0.5) as u8
}

/// Settings of a frame, as the page's controls set them.
struct Settings<'a> {
    map: &'a str,
    rotate: &'a str,
    n: usize,
    weighting: &'a str,
}

/// The displayed pixels against `ltm relight` at the same settings: within
/// one level (the frame travels as half floats, which can move a value
/// across a rounding boundary of the 8-bit encoding).
fn check_pixels(tab: &Tab, file: usize, at: &Settings, exposure: f32) {
    let s = scene();
    check_pixels_of(tab, file, [&s.ltm, &s.ltm2][file], at, exposure);
}

/// [`check_pixels`] for panel `file` showing the file at `path`.
fn check_pixels_of(tab: &Tab, file: usize, path: &Path, at: &Settings, exposure: f32) {
    let (want, _) = relight(path, &map(at.map), at.rotate, at.n, at.weighting, None);
    let got = pixels(tab, &format!("view{file}"));
    assert_eq!(got.len(), want.len(), "displayed pixels");
    let mut lit = 0;
    for (i, (g, w)) in got.iter().zip(&want).enumerate() {
        let w8 = srgb8(*w, exposure);
        assert!(
            g.abs_diff(w8) <= 1,
            "file {file}, value {i} at rotate {}, N {}, exposure {exposure}: shown {g}, ltm relight {w8}",
            at.rotate,
            at.n
        );
        lit += usize::from(w8 > 0);
    }
    assert!(
        lit > got.len() / 10,
        "the frame is nearly black: nothing was compared"
    );
}

fn drag(tab: &Tab, id: &str, dx: f64) {
    drag_with(tab, id, (dx, 0.0), None);
}

/// A drag by `(dx, dy)` pixels on element `id`, with the keyboard
/// `modifiers` of CDP (8: shift) held.
fn drag_with(tab: &Tab, id: &str, (dx, dy): (f64, f64), modifiers: Option<u32>) {
    let p = tab
        .find_element(&format!("#{id}"))
        .unwrap()
        .get_midpoint()
        .unwrap();
    let event = |kind, x: f64, y: f64, buttons| Input::DispatchMouseEvent {
        Type: kind,
        x,
        y,
        modifiers,
        timestamp: None,
        button: Some(Input::MouseButton::Left),
        buttons: Some(buttons),
        click_count: Some(1),
        force: None,
        tangential_pressure: None,
        tilt_x: None,
        tilt_y: None,
        twist: None,
        delta_x: None,
        delta_y: None,
        pointer_Type: None,
    };
    use Input::DispatchMouseEventTypeOption as T;
    tab.call_method(event(T::MousePressed, p.x, p.y, 1))
        .unwrap();
    tab.call_method(event(T::MouseMoved, p.x + dx, p.y + dy, 1))
        .unwrap();
    tab.call_method(event(T::MouseReleased, p.x + dx, p.y + dy, 0))
        .unwrap();
}

/// Waits until the page's expression `js` is true.
fn wait_until(tab: &Tab, js: &str, what: &str) {
    let t = Instant::now();
    while eval(tab, js) != json!(true) {
        let msg = eval(tab, "document.getElementById('message').textContent");
        assert!(
            t.elapsed() < TIMEOUT,
            "{what} within {TIMEOUT:?}; page says {msg}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn text(tab: &Tab, js: &str) -> String {
    eval(tab, js).as_str().unwrap_or_default().to_string()
}

/// The exposure `ltm demo` chooses: the 99th percentile of the positive
/// luminances shows at 0.8.
fn auto_ev(rgb: &[f32]) -> f64 {
    let mut lum: Vec<f64> = rgb
        .chunks_exact(3)
        .map(|p| 0.2126 * f64::from(p[0]) + 0.7152 * f64::from(p[1]) + 0.0722 * f64::from(p[2]))
        .filter(|v| *v > 0.0)
        .collect();
    lum.sort_by(f64::total_cmp);
    let k = (lum.len() * 99 / 100).min(lum.len() - 1);
    (0.8 / lum[k]).log2()
}

fn lum(p: &[f32]) -> f64 {
    0.2126 * f64::from(p[0]) + 0.7152 * f64::from(p[1]) + 0.0722 * f64::from(p[2])
}

/// A new tab on the server's page, once `ready` (a selector) is there.
fn open_page(browser: &Browser, srv: &Server, ready: &str) -> std::sync::Arc<Tab> {
    let tab = browser.new_tab().expect("open a tab");
    tab.set_default_timeout(TIMEOUT);
    tab.navigate_to(&srv.url())
        .unwrap()
        .wait_until_navigated()
        .unwrap();
    tab.wait_for_element_with_custom_timeout(ready, TIMEOUT)
        .unwrap_or_else(|e| panic!("{ready}: {e}"));
    tab
}

#[test]
fn page_controls_show_what_ltm_relight_computes() {
    let Some(browser) = browser() else { return };
    let s = scene();
    let srv = Server::start(&[
        s.ltm.to_str().unwrap(),
        s.ltm2.to_str().unwrap(),
        "--env",
        map("interior.exr").to_str().unwrap(),
        "--env",
        map("sunset.exr").to_str().unwrap(),
        "--reference",
        s.raw.to_str().unwrap(),
    ]);
    let tab = open_page(&browser, &srv, "#view0[data-shown]");
    opens_at_the_readme_settings(&tab);
    fast_srgb_is_the_exact_encoding(&tab);
    let n = controls_relight_as_ltm_relight(&tab);
    let at = Settings {
        map: "sunset.exr",
        rotate: "50,-15,0",
        n,
        weighting: "unweighted",
    };
    error_readouts_match_ltm_relight_reference(&tab, &at);
    probe_and_heatmap_show_the_error(&tab, &at);
    split_preview_and_reset(&tab);
    let png = tab
        .capture_screenshot(Page::CaptureScreenshotFormatOption::Png, None, None, true)
        .unwrap();
    let out = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("view-browser.png");
    std::fs::write(&out, png).unwrap();
    eprintln!("screenshot: {}", out.display());
    // A stopped server: the panels say so.
    drop(srv);
    set(&tab, "yaw", "10", "change");
    wait_until(
        &tab,
        "document.getElementById('state0').textContent.includes('offline')",
        "the offline state",
    );
    assert!(text(&tab, "document.getElementById('message').textContent").contains("still running"));
}

/// Files of different light counts (6·4² and 6·2²) get an N control each,
/// and each panel relights at its own N as `ltm relight` does.
#[test]
fn files_with_different_light_counts_get_their_own_n() {
    let Some(browser) = browser() else { return };
    let s = scene();
    let coarse = s.dir.join("coarse.ltm");
    let raw = s.dir.join("coarse.raw");
    let scene_file = assets().join("scenes/default.toml");
    let p = |p: &Path| p.to_str().unwrap().to_string();
    ltm(&[
        "bake",
        &p(&scene_file),
        "-o",
        &p(&raw),
        "--size",
        "24x20",
        "--face-res",
        "2",
        "--texel-samples",
        "1",
    ]);
    ltm(&[
        "compress",
        &p(&raw),
        "-o",
        &p(&coarse),
        "--max-error",
        "0.05",
    ]);
    let srv = Server::start(&[&p(&s.ltm), &p(&coarse), "--env", &p(&map("interior.exr"))]);
    let tab = open_page(&browser, &srv, "#view1[data-shown]");
    assert_eq!(
        text(&tab, "document.getElementById('n-number').value"),
        "96"
    );
    assert_eq!(
        text(&tab, "document.getElementById('n-number-1').max"),
        "24"
    );
    assert_eq!(
        text(&tab, "document.getElementById('n-number-1').value"),
        "24"
    );
    set(&tab, "weighting", "unweighted", "change");
    set(&tab, "yaw", "25", "change");
    set(&tab, "n-number-1", "7", "change");
    let q = "map=0&yaw=25&pitch=0&roll=0";
    wait_shown(
        &tab,
        "view0",
        &format!("file=0&{q}&n=96&weighting=unweighted"),
    );
    wait_shown(
        &tab,
        "view1",
        &format!("file=1&{q}&n=7&weighting=unweighted"),
    );
    let ev = eval(&tab, "ev()").as_f64().unwrap() as f32;
    let at = |n| Settings {
        map: "interior.exr",
        rotate: "25,0,0",
        n,
        weighting: "unweighted",
    };
    check_pixels_of(&tab, 0, &s.ltm, &at(96), ev);
    check_pixels_of(&tab, 1, &coarse, &at(7), ev);
}

/// The page's table-driven sRGB encoding (for whole frames) stores the
/// codes of its per-value one (NaN stores 0 in both), on a fine grid, at random values, and on either
/// side of every code's threshold.
fn fast_srgb_is_the_exact_encoding(tab: &Tab) {
    let js = "(() => { let bad = []; const check = (v) => { if (Uint8ClampedArray.of(srgb8Fast(v))[0] !== Uint8ClampedArray.of(srgb8(v))[0]) bad.push(v); }; \
        for (let i = -10; i <= 2000010; i++) check(i / 2000000); \
        for (let i = 0; i < 200000; i++) check(Math.fround(Math.random() ** 4)); \
        for (let k = 1; k < 256; k++) { const t = SRGB_AT[k]; check(t); check(t * (1 - 1e-15)); check(t * (1 + 1e-15)); } \
        [0, -0, 1, 1.5, 1e30, NaN, -1].forEach(check); return JSON.stringify(bad.slice(0, 5)); })()";
    assert_eq!(text(tab, js), "[]", "values where the encodings differ");
}

/// Transport weighting, N = min(200, lights), auto exposure (the pixels at
/// the exposure ltm demo would choose) and the exact view, untouched.
fn opens_at_the_readme_settings(tab: &Tab) {
    let q = "file=0&map=0&yaw=0&pitch=0&roll=0&n=96&weighting=transport";
    wait_shown(tab, "view0", q);
    let groups = "document.querySelectorAll('#n-controls input[type=number]').length";
    assert_eq!(
        eval(tab, groups),
        json!(1),
        "both files have 96 lights: one N"
    );
    let at = Settings {
        map: "interior.exr",
        rotate: "0,0,0",
        n: 96,
        weighting: "transport",
    };
    let (want, _) = relight(
        &scene().ltm,
        &map(at.map),
        at.rotate,
        at.n,
        at.weighting,
        None,
    );
    let ev: f64 = text(tab, "document.getElementById('exposure-value').dataset.ev")
        .parse()
        .unwrap();
    let want_ev = auto_ev(&want);
    assert!(
        (ev - want_ev).abs() < 0.02,
        "auto exposure {ev} EV, from ltm relight's image {want_ev} EV"
    );
    check_pixels(tab, 0, &at, ev as f32);
    wait_shown(tab, "exact", q);
}

/// Map, weighting, rotation fields, the N slider and field, exposure and a
/// drag, through the controls; returns N.
fn controls_relight_as_ltm_relight(tab: &Tab) -> usize {
    set(tab, "map", "1", "change");
    set(tab, "weighting", "unweighted", "change");
    set(tab, "yaw", "30", "change");
    set(tab, "pitch", "-15", "change");
    set(tab, "n", "700", "input");
    set(tab, "exposure", "1", "input");
    assert_eq!(
        eval(tab, "document.getElementById('auto-exposure').checked"),
        json!(false),
        "moving the exposure turns auto off"
    );
    let n_field = "document.getElementById('n-number').value";
    assert_eq!(text(tab, n_field), "24", "slider 700 of 1..96: 96^0.7");
    let mut at = Settings {
        map: "sunset.exr",
        rotate: "30,-15,0",
        n: 24,
        weighting: "unweighted",
    };
    let q = "file=0&map=1&yaw=30&pitch=-15&roll=0&n=24&weighting=unweighted";
    wait_shown(tab, "view0", q);
    wait_shown(tab, "view1", &q.replace("file=0", "file=1"));
    check_pixels(tab, 0, &at, 1.0);
    check_pixels(tab, 1, &at, 1.0);

    // Exposure is applied in the page: no new frame.
    let frames = eval(tab, "window.ltmView.frames");
    set(tab, "exposure", "-1.5", "input");
    check_pixels(tab, 0, &at, -1.5);
    assert_eq!(eval(tab, "window.ltmView.frames"), frames);

    // A drag of 40 px to the right turns the yaw by 20 degrees; N typed.
    drag(tab, "view0", 40.0);
    assert_eq!(
        eval(tab, "document.getElementById('yaw').value"),
        json!("50")
    );
    set(tab, "n-number", "37", "change");
    assert_eq!(
        text(tab, "document.getElementById('n').value"),
        "791",
        "1000 · ln 37 / ln 96"
    );
    at.rotate = "50,-15,0";
    at.n = 37;
    wait_shown(
        tab,
        "view0",
        "file=0&map=1&yaw=50&pitch=-15&roll=0&n=37&weighting=unweighted",
    );
    check_pixels(tab, 0, &at, -1.5);
    37
}

/// Each file's error readout (in %) against `ltm relight --reference`.
fn error_readouts_match_ltm_relight_reference(tab: &Tab, at: &Settings) {
    let s = scene();
    let exr = reference(&map(at.map), at.rotate);
    for (i, path) in [&s.ltm, &s.ltm2].into_iter().enumerate() {
        wait_until(
            tab,
            &format!("panels[{i}].shown === query({i}) && !!panels[{i}].readout.error"),
            "an error readout",
        );
        let shown = text(
            tab,
            &format!("document.getElementById('error{i}').textContent"),
        );
        let pct: f64 = shown
            .strip_prefix("error against exact T·L: ")
            .and_then(|t| t.strip_suffix(" %"))
            .unwrap_or_else(|| panic!("error readout {shown}"))
            .parse()
            .unwrap();
        let (_, json) = relight(
            path,
            &map(at.map),
            at.rotate,
            at.n,
            at.weighting,
            Some(&exr),
        );
        let want = 100.0 * json["relative_error"].as_f64().unwrap();
        assert!(
            (pct - want).abs() <= 5e-4 + 1e-4 * want,
            "file {i}: readout {pct} %, ltm relight --reference {want} %"
        );
    }
}

/// Moves the pointer (no button) over the middle of element `id`.
fn hover(tab: &Tab, id: &str) {
    let p = tab
        .find_element(&format!("#{id}"))
        .unwrap()
        .get_midpoint()
        .unwrap();
    tab.move_mouse_to_point(p).unwrap();
}

/// The probe shows file 0's values under the pointer (those of `ltm
/// relight`, to the 4 digits shown); the heatmap is darkest where relit and
/// exact agree and brighter where they differ most.
fn probe_and_heatmap_show_the_error(tab: &Tab, at: &Settings) {
    let s = scene();
    let (relit, _) = relight(&s.ltm, &map(at.map), at.rotate, at.n, at.weighting, None);
    let exact = ltm_relight::Image::read_exr(&reference(&map(at.map), at.rotate)).unwrap();
    let exact: Vec<f32> = exact.data.iter().flatten().copied().collect();
    hover(tab, "view0");
    let x: usize = text(tab, "document.getElementById('probe').dataset.x")
        .parse()
        .unwrap();
    let y: usize = text(tab, "document.getElementById('probe').dataset.y")
        .parse()
        .unwrap();
    let probe = text(tab, "document.getElementById('probe').textContent");
    let line = probe
        .lines()
        .find_map(|l| l.strip_prefix("t.ltm: "))
        .unwrap_or_else(|| panic!("probe {probe}"));
    let width = 24;
    for (c, v) in line.split(' ').take(3).enumerate() {
        let got: f32 = v.parse().unwrap();
        let want = relit[3 * (y * width + x) + c];
        assert!(
            (got - want).abs() <= 1.5e-3 * want.abs() + 1e-7,
            "probe at ({x}, {y}) channel {c}: {got}, ltm relight {want}"
        );
    }

    set(tab, "display", "heat", "change");
    wait_until(
        tab,
        "document.getElementById('view0').dataset.display === 'heat'",
        "the heatmap",
    );
    assert_eq!(
        eval(tab, "document.getElementById('legend').hidden"),
        json!(false)
    );
    let shown = pixels(tab, "view0");
    let mut order: Vec<(f64, u32)> = relit
        .chunks_exact(3)
        .zip(exact.chunks_exact(3))
        .zip(shown.chunks_exact(3))
        .map(|((r, e), px)| {
            let d = [
                (r[0] - e[0]).abs(),
                (r[1] - e[1]).abs(),
                (r[2] - e[2]).abs(),
            ];
            (lum(&d), px.iter().map(|&v| u32::from(v)).sum())
        })
        .collect();
    order.sort_by(|a, b| a.0.total_cmp(&b.0));
    let tenth = order.len() / 10;
    let mean = |v: &[(f64, u32)]| v.iter().map(|p| f64::from(p.1)).sum::<f64>() / v.len() as f64;
    let (low, high) = (mean(&order[..tenth]), mean(&order[order.len() - tenth..]));
    assert!(
        high > low + 60.0,
        "heatmap: the tenth of pixels that differ most average {high}, the tenth that differ least {low}"
    );
    set(tab, "display", "image", "change");
}

/// The split view (divider, labels), the map preview (drawn rotated, dragged
/// to turn the yaw), the rotation fields' ranges and reset.
fn split_preview_and_reset(tab: &Tab) {
    set(tab, "layout", "split", "change");
    let wrap = "getComputedStyle(document.getElementById('split-wrap')).display";
    assert_eq!(eval(tab, wrap), json!("block"));
    assert_eq!(eval(tab, "panels[0].figure.hidden"), json!(true));
    set(tab, "split", "0.25", "input");
    assert_eq!(
        eval(tab, "document.getElementById('split-divider').style.left"),
        json!("25%")
    );
    assert!(text(tab, "document.getElementById('view1').style.clipPath").contains("25%"));
    assert!(text(tab, "document.getElementById('split-left').textContent").contains("t.ltm"));
    set(tab, "layout", "side", "change");
    assert_eq!(eval(tab, "panels[0].figure.hidden"), json!(false));

    wait_until(
        tab,
        "document.getElementById('map-preview').dataset.shown === rotationQuery()",
        "the map preview",
    );
    preview_is_the_servers(tab);
    // 30 px of the 300 px preview: 36 degrees, the map following the pointer.
    drag(tab, "map-preview", 30.0);
    assert_eq!(
        eval(tab, "document.getElementById('yaw').value"),
        json!("14")
    );
    set(tab, "yaw", "99999", "change");
    assert_eq!(
        eval(tab, "document.getElementById('yaw').value"),
        json!("-81")
    );
    set(tab, "pitch", "-100", "change");
    assert_eq!(
        eval(tab, "document.getElementById('pitch').value"),
        json!("-90")
    );

    tab.find_element("#reset").unwrap().click().unwrap();
    for (js, want) in [
        ("document.getElementById('yaw').value", "0"),
        ("document.getElementById('pitch').value", "0"),
        ("document.getElementById('weighting').value", "transport"),
        ("document.getElementById('n-number').value", "96"),
        (
            "String(document.getElementById('auto-exposure').checked)",
            "true",
        ),
    ] {
        assert_eq!(text(tab, js), want, "{js} after reset");
    }
}

/// The page rotates the map preview itself: at rotations off the quarter
/// turns, its canvas shows the server's `/api/map` of the same rotation,
/// tone-mapped at the preview's exposure, pixel for pixel (outside the
/// cross; a pixel whose nearest source differs by one ulp of a libm call
/// may differ, at most 0.1 % of them).
fn preview_is_the_servers(tab: &Tab) {
    let field = |id: &str| text(tab, &format!("document.getElementById('{id}').value"));
    let before = ["yaw", "pitch", "roll"].map(field);
    for (yaw, pitch, roll) in [
        (37.5, -20.0, 10.0),
        (90.0, 0.0, 0.0),
        (-123.25, 45.0, -170.0),
    ] {
        set(tab, "yaw", &yaw.to_string(), "change");
        set(tab, "pitch", &pitch.to_string(), "change");
        set(tab, "roll", &roll.to_string(), "change");
        wait_until(
            tab,
            "document.getElementById('map-preview').dataset.shown === rotationQuery()",
            "the rotated map preview",
        );
        let js = "(async () => { \
            const r = await fetch('/api/map?' + rotationQuery()); \
            const f = decodeFrame(await r.arrayBuffer()), w = f.width, h = f.height, floats = halvesToFloats(f.halves); \
            const got = document.getElementById('map-preview').getContext('2d').getImageData(0, 0, w, h).data; \
            const [cu, cv] = latlongUv(...rotationColumns()[2]), cx = cu * w, cy = cv * h; \
            const scale = Math.pow(2, preview.ev); let compared = 0, differ = 0; \
            for (let y = 0; y < h; y++) for (let x = 0; x < w; x++) { \
              if (Math.abs(x + 0.5 - cx) < 11 && Math.abs(y + 0.5 - cy) < 11) continue; \
              compared++; const p = y * w + x; \
              for (let k = 0; k < 3; k++) if (got[4 * p + k] !== srgb8Fast(floats[3 * p + k] * scale)) { differ++; break; } } \
            return JSON.stringify([compared, differ]); })()";
        let v = tab.evaluate(js, true).unwrap().value.unwrap();
        let (compared, differ): (u64, u64) = serde_json::from_str(v.as_str().unwrap()).unwrap();
        assert!(compared > 30_000, "{compared} pixels compared");
        assert!(
            differ * 1000 <= compared,
            "yaw {yaw}, pitch {pitch}, roll {roll}: {differ} of {compared} preview pixels differ from /api/map"
        );
    }
    for (id, v) in ["yaw", "pitch", "roll"].iter().zip(&before) {
        set(tab, id, v, "change");
    }
}

/// A texture-space file of the sphere layout (drawn as the grid of its
/// geometry image, with the square's folds): a 32² texture over a closed
/// procedural blob, baked with 6·2² lights.
fn sphere_texture_file(dir: &std::path::Path) -> PathBuf {
    let texture = ltm_testkit::TEXTURE_SPHERE_16.replace("size = 16", "size = 32");
    texture_file(dir, &texture)
}

/// The blob and its ground as one 48² atlas: several charts, their seams
/// across the view.
fn atlas_texture_file(dir: &std::path::Path) -> PathBuf {
    texture_file(dir, "\n[texture]\nmesh = \"all\"\nsize = 48\nspp = 1\n")
}

/// The page's WebGL view of texture-space file `file` (lit by `env`),
/// after a drag that orbits its camera, against `ltm render` of the same
/// camera, relight and exposure: the same triangles, and every pixel within
/// 3 levels (8-bit sRGB) except where an edge of the silhouette passes
/// (the two rasterizers may disagree on a sample lying on an edge).
///
/// With `glossy` (`ltm view` and `ltm render` flags), the page's material
/// menu picks the glossy material, and each orbit is compared once the
/// frame shaded from its eye has come.
fn mesh_view_matches_ltm_render(
    browser: &Browser,
    file: &std::path::Path,
    env: &std::path::Path,
    glossy: &[&str],
) {
    let mut args = vec![file.to_str().unwrap(), "--env", env.to_str().unwrap()];
    args.extend(glossy);
    let srv = Server::start(&args);
    let tab = browser.new_tab().expect("open a tab");
    tab.set_default_timeout(TIMEOUT);
    tab.navigate_to(&srv.url())
        .unwrap()
        .wait_until_navigated()
        .unwrap();
    tab.wait_for_element_with_custom_timeout("#gl0[data-camera]", TIMEOUT)
        .unwrap_or_else(|e| {
            let msg = eval(&tab, "document.getElementById('message').textContent");
            panic!("no WebGL view ({e}); page says {msg}")
        });
    set(&tab, "exposure", "0.5", "input");
    if !glossy.is_empty() {
        set(&tab, "brdf", "1", "change");
    }
    let q = eval(&tab, "query(0)");
    wait_shown(&tab, "view0", q.as_str().unwrap());
    // Two orbits: a quarter turn and then half a turn further round
    // (0.01 rad per pixel), so that both sides (the sphere layout's folds
    // lie on one) are compared.
    for dx in [70.0, 314.0] {
        compare_mesh_view(&tab, (file, env), dx, glossy);
    }
}

/// Drags the WebGL view `dx` pixels and compares it with `ltm render`
/// (given the `glossy` flags too).
fn compare_mesh_view(
    tab: &Tab,
    (file, env): (&std::path::Path, &std::path::Path),
    dx: f64,
    glossy: &[&str],
) {
    let before = eval(tab, "document.getElementById('gl0').dataset.camera");
    drag(tab, "gl0", dx);
    let after = eval(tab, "document.getElementById('gl0').dataset.camera");
    assert_ne!(after, before, "the drag orbits the camera");
    if !glossy.is_empty() {
        // A glossy material is shaded from the eye: the page asks for the
        // frame of the new eye (query(0) holds it).
        let q = eval(tab, "query(0)");
        assert!(q.as_str().unwrap().contains("&brdf=1&eye="), "{q}");
        wait_shown(tab, "view0", q.as_str().unwrap());
    }
    let camera: Value = serde_json::from_str(after.as_str().unwrap()).unwrap();
    let js = "Array.from(panels[0].gl.pixels()).join(',')";
    let got: Vec<u8> = eval(tab, js)
        .as_str()
        .unwrap()
        .split(',')
        .map(|v| v.parse().unwrap())
        .collect();
    let n = eval(tab, "terms(0)").as_u64().unwrap().to_string();
    let weighting = eval(tab, "document.getElementById('weighting').value");
    let triangles = eval(tab, "document.getElementById('gl0').dataset.triangles");
    let v3 = |v: &Value| {
        let a: Vec<String> = v
            .as_array()
            .unwrap()
            .iter()
            .map(|c| c.to_string())
            .collect();
        a.join(",")
    };
    // One name per test and drag: the tests run at once.
    let out = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!(
        "view-mesh-{}-{dx}{}.exr",
        file.file_stem().unwrap().to_string_lossy(),
        if glossy.is_empty() { "" } else { "-glossy" }
    ));
    let fov = camera["fov"].to_string();
    let (eye, target) = (v3(&camera["eye"]), v3(&camera["target"]));
    let mut args = vec![
        "render",
        file.to_str().unwrap(),
        "--env",
        env.to_str().unwrap(),
        "--terms",
        &n,
        "--weighting",
        weighting.as_str().unwrap(),
        "--camera",
        &eye,
        "--target",
        &target,
        "--up",
        "0,1,0",
        "--fov",
        &fov,
        "--size",
        "512x512",
        "--supersample",
        "1",
        "-o",
        out.to_str().unwrap(),
        "--json",
    ];
    args.extend(glossy);
    let line = ltm(&args);
    let json: Value = serde_json::from_str(line.trim()).unwrap();
    assert_eq!(
        json["triangles"].to_string(),
        triangles.as_str().unwrap(),
        "the page draws ltm render's triangles"
    );
    let want: Vec<u8> = ltm_relight::Image::read_exr(&out)
        .unwrap()
        .data
        .iter()
        .flatten()
        .map(|&v| srgb8(v, 0.5))
        .collect();
    assert_eq!(got.len(), want.len(), "512×512 RGB");
    compare_pixels(
        &format!("{} (drag {dx})", file.display()),
        &camera,
        &got,
        &want,
    );
}

/// Every pixel of `got` within 3 levels of `want`, but for a few on a
/// silhouette: next to the background in either view, or where `want`
/// jumps by more than 24 levels to a neighbour (an object's edge over
/// another surface, where the two rasterizers may pick different
/// triangles for a sample on the edge). Chart seams are not jumps in
/// `want`: a seam drawn wrong by the page fails.
fn compare_pixels(label: &str, camera: &Value, got: &[u8], want: &[u8]) {
    let w = 512usize;
    if let Ok(dir) = std::env::var("LTM_VIEW_DUMP") {
        // For a look at a failure: both views as binary PPM.
        for (name, img) in [("page", got), ("render", want)] {
            let mut ppm = format!("P6 {w} {w} 255\n").into_bytes();
            ppm.extend_from_slice(img);
            std::fs::write(format!("{dir}/{name}.ppm"), ppm).unwrap();
        }
    }
    let px = |img: &[u8], x: usize, y: usize| -> [u8; 3] {
        img[3 * (y * w + x)..][..3].try_into().unwrap()
    };
    let black = |img: &[u8], x: usize, y: usize| px(img, x, y) == [0, 0, 0];
    let jump = |x: usize, y: usize, xx: usize, yy: usize| {
        let (a, b) = (px(want, x, y), px(want, xx, yy));
        (0..3).any(|c| a[c].abs_diff(b[c]) > 24)
    };
    let edge = |x: usize, y: usize| {
        (y.saturating_sub(1)..=(y + 1).min(w - 1)).any(|yy| {
            (x.saturating_sub(1)..=(x + 1).min(w - 1))
                .any(|xx| black(got, xx, yy) || black(want, xx, yy) || jump(x, y, xx, yy))
        })
    };
    let (mut object, mut worst, mut at_edges) = (0, 0, 0);
    // Interior pixels off by more than 3 levels: a few where single and
    // double precision pick different texels (the nearest-texel fallback
    // switches discontinuously), never more than 32 levels.
    let mut stray = Vec::new();
    for y in 0..w {
        for x in 0..w {
            let i = 3 * (y * w + x);
            let d = (0..3)
                .map(|c| got[i + c].abs_diff(want[i + c]))
                .max()
                .unwrap();
            object += usize::from(!black(want, x, y));
            if d <= 3 {
                worst = worst.max(d);
            } else if edge(x, y) {
                at_edges += 1;
            } else {
                assert!(
                    d <= 32,
                    "{label}: pixel ({x}, {y}) shows {:?}, ltm render {:?} (camera {camera})",
                    &got[i..i + 3],
                    &want[i..i + 3]
                );
                stray.push((x, y, d));
            }
        }
    }
    assert!(object > w * w / 20, "the object covers {object} pixels");
    assert!(
        at_edges * 100 < object,
        "{at_edges} silhouette pixels differ of {object}"
    );
    assert!(
        stray.len() * 1000 <= object,
        "{label}: {} interior pixels differ by more than 3 levels (of {object}): {:?}",
        stray.len(),
        &stray[..stray.len().min(8)]
    );
    eprintln!(
        "{label}: {object} object pixels, within {worst} levels; {at_edges} silhouette pixels and {} interior pixels (at most 32 levels) differ",
        stray.len()
    );
}

/// The WebGL view of a texture-space file matches `ltm render`: the sphere
/// layout's grid (its folds included), and an atlas of a blob and its
/// ground (the stored mesh, its chart seams across the view).
#[test]
fn mesh_views_show_what_ltm_render_draws() {
    let Some(browser) = browser() else { return };
    let dir = tempfile::tempdir().unwrap();
    let sphere = sphere_texture_file(dir.path());
    mesh_view_matches_ltm_render(&browser, &sphere, &map("interior.exr"), &[]);
    let dir = tempfile::tempdir().unwrap();
    let atlas = atlas_texture_file(dir.path());
    mesh_view_matches_ltm_render(&browser, &atlas, &map("interior.exr"), &[]);
}

/// A glossy material from the page's menu (`ltm view --brdf`) is what
/// `ltm render --brdf` draws from the orbit camera's eye: the highlights
/// follow the eye, frame by frame, on the sphere layout and on an atlas.
#[test]
fn glossy_materials_show_what_ltm_render_brdf_draws() {
    let Some(browser) = browser() else { return };
    let glossy = ["--brdf", "ggx:0.3,f0=0.9/0.7/0.4", "--glossy-n", "16"];
    let dir = tempfile::tempdir().unwrap();
    let sphere = sphere_texture_file(dir.path());
    mesh_view_matches_ltm_render(&browser, &sphere, &map("interior.exr"), &glossy);
    let dir = tempfile::tempdir().unwrap();
    let atlas = atlas_texture_file(dir.path());
    mesh_view_matches_ltm_render(&browser, &atlas, &map("interior.exr"), &glossy);
}

/// A glossy material on an image-space file, chosen in the page's menu, is
/// what `ltm relight --brdf` draws: every pixel seen from the eye the
/// file's surface records fix (the scene file's camera), within one 8-bit
/// level.
#[test]
fn glossy_materials_on_image_rows_show_what_ltm_relight_brdf_draws() {
    let Some(browser) = browser() else { return };
    let (s, env) = (scene(), map("interior.exr"));
    let (file, env_s) = (s.ltm.to_str().unwrap(), env.to_str().unwrap());
    let glossy = ["--brdf", "ggx:0.25,f0=0.9/0.7/0.4", "--glossy-n", "16"];
    let srv = Server::start(&[&[file, "--env", env_s][..], &glossy].concat());
    let tab = open_page(&browser, &srv, "#view0[data-shown]");
    set(&tab, "weighting", "unweighted", "change");
    set(&tab, "n-number", "40", "change");
    set(&tab, "exposure", "0.5", "input");
    set(&tab, "brdf", "1", "change");
    let q = eval(&tab, "query(0)");
    let q = q.as_str().unwrap();
    assert!(q.contains("&n=40&") && q.contains("&brdf=1&eye="), "{q}");
    let eye: Vec<f64> = q
        .rsplit("eye=")
        .next()
        .unwrap()
        .split(',')
        .map(|c| c.parse().unwrap())
        .collect();
    let camera = [0.2, 1.45, 5.0];
    assert!(
        eye.iter().zip(camera).all(|(a, b)| (a - b).abs() < 1e-5),
        "{q}"
    );
    wait_shown(&tab, "view0", q);
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("g.exr");
    let relight = [
        "relight",
        file,
        "--env",
        env_s,
        "--terms",
        "40",
        "--weighting",
        "unweighted",
    ];
    ltm(&[&relight[..], &glossy, &["-o", out.to_str().unwrap()]].concat());
    let want = ltm_relight::Image::read_exr(&out).unwrap();
    let got = pixels(&tab, "view0");
    let want8: Vec<u8> = want.data.iter().flatten().map(|&v| srgb8(v, 0.5)).collect();
    assert_eq!(got.len(), want8.len());
    let worst = got.iter().zip(&want8).map(|(g, w)| g.abs_diff(*w)).max();
    assert!(worst <= Some(1), "largest difference {worst:?} levels");
    // The material changed the picture.
    set(&tab, "brdf", "0", "change");
    wait_shown(&tab, "view0", q.split("&brdf").next().unwrap());
    let baked = pixels(&tab, "view0");
    let changed = baked
        .iter()
        .zip(&got)
        .filter(|(a, b)| a.abs_diff(**b) > 8)
        .count();
    assert!(
        changed > got.len() / 20,
        "{changed} of {} values changed",
        got.len()
    );
}

/// Interaction latency of a sustained drag (benchmark mode, not a test of
/// correctness): both files of `LTM_VIEW_BENCH` open side by side, and the
/// page's yaw turns by 1.5° every 16.7 ms (60 input events a second, as a
/// drag's pointer moves fire them) for `LTM_VIEW_BENCH_SECONDS` (default
/// 10), once the server has decoded every column (`preloaded`; the wait is
/// `preload_wait_s`). Latency is `performance.now()` from the oldest input a frame
/// answers to the `requestAnimationFrame` after it is drawn. Also measures
/// the draft light's relit error against the exact light's at 8 rotations.
/// For docs/results/viewer.md; run by hand:
///
/// `LTM_VIEW_BENCH=a.ltm,b.ltm LTM_VIEW_BENCH_ENV=map.exr LTM_VIEW_BENCH_OUT=out.json
/// cargo test --release -p ltm-tools --test view_browser measure_latency -- --ignored --nocapture`
#[test]
#[ignore = "measurement, run by hand (see docs/results/viewer.md)"]
fn measure_latency() {
    let var = |k: &str| std::env::var(k).unwrap_or_else(|_| panic!("set {k}"));
    let (files, env, out) = (
        var("LTM_VIEW_BENCH"),
        var("LTM_VIEW_BENCH_ENV"),
        var("LTM_VIEW_BENCH_OUT"),
    );
    let seconds: f64 = std::env::var("LTM_VIEW_BENCH_SECONDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(10.0);
    let mut args: Vec<&str> = files.split(',').collect();
    args.extend(["--env", &env]);
    let srv = Server::start(&args);
    let browser = browser().expect("Chromium");
    let tab = open_page(&browser, &srv, "#view0[data-shown]");
    let panels = eval(&tab, "panels.length").as_u64().unwrap();
    for i in 0..panels {
        let q = eval(&tab, &format!("query({i})"));
        wait_shown(&tab, &format!("view{i}"), q.as_str().unwrap());
    }
    // The steady state: every column decoded (the server's background
    // preload), so that no frame of the drag decodes; the wait is reported.
    let opened = Instant::now();
    let preloaded = "fetch('/api/info').then((r) => r.json()).then((i) => i.preloaded)";
    while tab.evaluate(preloaded, true).unwrap().value != Some(json!(true)) {
        assert!(
            opened.elapsed().as_secs() < 600,
            "the preload did not end in 10 minutes"
        );
        std::thread::sleep(std::time::Duration::from_millis(200));
    }
    let preload_wait = opened.elapsed().as_secs_f64();
    let first = eval(&tab, "window.ltmView.latencies.length")
        .as_u64()
        .unwrap();
    let drag = format!(
        "new Promise((done) => {{ let k = 0; const t = setInterval(() => {{ \
           const y = document.getElementById('yaw'); y.value = (++k * 1.5).toFixed(2); \
           y.dispatchEvent(new Event('input', {{ bubbles: true }})); \
           if (k >= {}) {{ clearInterval(t); done(k); }} }}, 1000 / 60); }})",
        (seconds * 60.0).round()
    );
    let started = Instant::now();
    let events = tab
        .evaluate(&drag, true)
        .unwrap()
        .value
        .unwrap_or(Value::Null);
    let wall = started.elapsed().as_secs_f64();
    for i in 0..panels {
        let q = eval(&tab, &format!("query({i})"));
        wait_shown(&tab, &format!("view{i}"), q.as_str().unwrap());
    }
    let samples = eval(
        &tab,
        &format!("JSON.stringify(window.ltmView.latencies.slice({first}))"),
    );
    let samples: Vec<Value> = serde_json::from_str(samples.as_str().unwrap()).unwrap();
    let mut r = latency_stats(&samples, panels as usize, wall);
    r["events"] = events;
    r["samples"] = json!(samples);
    r["preload_wait_s"] = json!(preload_wait);
    r["files"] = json!(files);
    r["query"] = eval(&tab, "query(0)");
    r["draft_relit_error"] = draft_errors(&srv, &eval(&tab, "query(0)"));
    eprintln!("{r:#}");
    std::fs::write(out, serde_json::to_string_pretty(&r).unwrap()).unwrap();
}

/// Median and 95th percentile of each figure of the drag's frames, per file
/// and light (draft frames during the drag, exact ones when it rests).
fn latency_stats(samples: &[Value], files: usize, wall: f64) -> Value {
    let mut out = serde_json::Map::new();
    for file in 0..files {
        for light in ["draft", "exact"] {
            let s: Vec<&Value> = samples
                .iter()
                .filter(|s| s["file"] == json!(file) && s["light"] == light)
                .collect();
            if s.is_empty() {
                continue;
            }
            let stat = |key: &str| {
                let mut v: Vec<f64> = s.iter().filter_map(|x| x[key].as_f64()).collect();
                if v.is_empty() {
                    return Value::Null;
                }
                v.sort_by(f64::total_cmp);
                let q = |p: f64| v[((v.len() - 1) as f64 * p).round() as usize];
                json!({ "median": q(0.5), "p95": q(0.95) })
            };
            out.insert(
                format!("file{file}_{light}"),
                json!({
                    "frames": s.len(),
                    "frames_per_s": s.len() as f64 / wall,
                    "latency_ms": stat("latency_ms"),
                    "round_trip_ms": stat("round_trip_ms"),
                    "server_frame_ms": stat("server_ms"),
                    "resample_ms": stat("resample_ms"),
                    "fetch_and_decode_ms": stat("fetch_ms"),
                    "draw_ms": stat("draw_ms"),
                    "display_wait_ms": stat("display_wait_ms"),
                    // The fetch's parts (the browser's resource timing).
                    "request_queue_ms": stat("queue_ms"),
                    "first_byte_wait_ms": stat("wait_ms"),
                    "body_ms": stat("body_ms"),
                    "after_body_ms": stat("after_body_ms"),
                }),
            );
        }
    }
    out.insert("drag_s".into(), json!(wall));
    Value::Object(out)
}

/// Relative L2 error of draft frames against exact ones, file 0, at 8 new
/// rotations (`query` gives the file, map and N).
fn draft_errors(srv: &Server, query: &Value) -> Value {
    let base: Vec<&str> = query
        .as_str()
        .unwrap()
        .split('&')
        .filter(|kv| !kv.starts_with("yaw=") && !kv.starts_with("pitch="))
        .collect();
    let mut errors: Vec<f64> = (0..8)
        .map(|k| {
            let q = format!(
                "/api/frame?{}&yaw={}&pitch={}",
                base.join("&"),
                11.0 + 43.0 * f64::from(k),
                5 * k - 20
            );
            let (_, _, a) = srv.get(&format!("{q}&light=draft")).frame();
            let (_, _, b) = srv.get(&q).frame();
            frame_distance(&a, &b)
        })
        .collect();
    errors.sort_by(f64::total_cmp);
    json!({ "median": errors[4], "max": errors[7], "all": errors })
}

/// The README's screenshot: `LTM_VIEW_SHOT_ARGS` (the arguments of `ltm
/// view`, separated by spaces) with the exact view on, saved to
/// `LTM_VIEW_SHOT`; `LTM_VIEW_SHOT_SET` (`id=value,…`) sets more controls
/// first (docs/view-split.png: `layout=split,display=heat`). Run by hand
/// like `measure_latency`.
#[test]
#[ignore = "makes docs/view.png, run by hand"]
fn screenshot_for_readme() {
    let args = std::env::var("LTM_VIEW_SHOT_ARGS").expect("LTM_VIEW_SHOT_ARGS");
    let out = std::env::var("LTM_VIEW_SHOT").expect("LTM_VIEW_SHOT=out.png");
    let args: Vec<&str> = args.split(' ').collect();
    let browser = browser().expect("Chromium");
    let srv = Server::start(&args);
    let tab = open_page(&browser, &srv, "#view0[data-shown]");
    set(&tab, "yaw", "40", "change");
    set(&tab, "n", "720", "input");
    for kv in std::env::var("LTM_VIEW_SHOT_SET")
        .unwrap_or_default()
        .split(',')
    {
        if let Some((id, value)) = kv.split_once('=') {
            set(&tab, id, value, "change");
        }
    }
    let q = eval(&tab, "query(0)");
    wait_shown(&tab, "view0", q.as_str().unwrap());
    if eval(&tab, "!!info.reference") == json!(true) {
        wait_until(
            &tab,
            "lightingOf(document.getElementById('exact').dataset.shown || '') === lightingOf(query(0))",
            "the exact view",
        );
    }
    let png = tab
        .capture_screenshot(Page::CaptureScreenshotFormatOption::Png, None, None, true)
        .unwrap();
    std::fs::write(out, png).unwrap();
}

/// A file baked with a `[light_plane]` gets the page's area-light fields;
/// with the light on, the panel shows what `ltm relight --env
/// --area-light` computes at the same settings (within a level), a
/// shift-drag moves the light (not the map), and the readout gives the
/// light's time.
#[test]
fn area_light_in_the_page_matches_ltm_relight() {
    let Some(browser) = browser() else { return };
    let dir = tempfile::tempdir().unwrap();
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let (raw, file) = (dir.path().join("a.raw"), dir.path().join("a.ltm"));
    let scene = assets().join("scenes/area_light.toml");
    ltm(&[
        "bake",
        &s(&scene),
        "-o",
        &s(&raw),
        "--width",
        "32",
        "--height",
        "24",
        "--face-res",
        "4",
    ]);
    ltm(&["compress", &s(&raw), "-o", &s(&file)]);
    let env = map("interior.exr");
    let srv = Server::start(&[&s(&file), "--env", &s(&env)]);
    let tab = open_page(&browser, &srv, "#view0[data-shown]");
    assert_eq!(
        eval(&tab, "document.getElementById('area-row').hidden"),
        json!(false)
    );
    set(&tab, "exposure", "0", "input");
    for (id, v) in [
        ("area-x", "0.15"),
        ("area-y", "0.25"),
        ("area-w", "0.8"),
        ("area-h", "0.6"),
        ("area-i", "4"),
    ] {
        set(&tab, id, v, "change");
    }
    eval(&tab, "(() => { const a = document.getElementById('area'); a.checked = true; a.dispatchEvent(new Event('change')); return true; })()");
    let n = text(&tab, "document.getElementById('n-number').value");
    let area = |x: &str, y: &str| format!("&ax={x}&ay={y}&aw=0.8&ah=0.6&ai=4&ad=0&at=0");
    let q = format!(
        "file=0&map=0&yaw=0&pitch=0&roll=0&n={n}&weighting=transport{}",
        area("0.15", "0.25")
    );
    wait_shown(&tab, "view0", &q);
    let compare = |center: &str, angle: &str| {
        let out = dir.path().join("want.exr");
        ltm(&[
            "relight",
            &s(&file),
            "--env",
            &s(&env),
            "--terms",
            &n,
            "--weighting",
            "transport",
            "--area-light",
            "uniform",
            "--area-center",
            center,
            "--area-size",
            "0.8,0.6",
            "--area-intensity",
            "4",
            "--area-angle",
            angle,
            "-o",
            &s(&out),
        ]);
        let want = ltm_relight::Image::read_exr(&out).unwrap();
        let got = pixels(&tab, "view0");
        let mut lit = 0;
        for (i, (g, w)) in got.iter().zip(want.data.iter().flatten()).enumerate() {
            let w8 = srgb8(*w, 0.0);
            assert!(
                g.abs_diff(w8) <= 1,
                "value {i}: shown {g}, ltm relight {w8} (centre {center})"
            );
            lit += usize::from(w8 > 0);
        }
        assert!(lit > got.len() / 10, "nearly black");
        want
    };
    let before = compare("0.15,0.25", "0");
    assert!(text(&tab, "document.getElementById('readouts').textContent").contains("area light"));
    // A shift-drag of 20 px right and 10 px down moves the light by
    // (0.2, 0.1) in the plane and leaves the map where it was.
    drag_with(&tab, "view0", (20.0, 10.0), Some(8));
    assert_eq!(
        eval(&tab, "document.getElementById('yaw').value"),
        json!("0")
    );
    let q = q.replace(&area("0.15", "0.25"), &area("0.35", "0.35"));
    wait_shown(&tab, "view0", &q);
    let after = compare("0.35,0.35", "0");
    let moved = ltm_relight::relative_l2(&after, &before).unwrap();
    assert!(moved > 0.01, "moving the light changes the image: {moved}");
    // Any angle, as `--area-angle` turns it.
    set(&tab, "area-angle", "30", "change");
    wait_shown(&tab, "view0", &q.replace("&ad=0&", "&ad=30&"));
    let turned = compare("0.35,0.35", "30");
    let e = ltm_relight::relative_l2(&turned, &after).unwrap();
    assert!(e > 1e-3, "turning the light changes the image: {e}");
    let png = tab
        .capture_screenshot(Page::CaptureScreenshotFormatOption::Png, None, None, true)
        .unwrap();
    let out = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("view-area.png");
    std::fs::write(&out, png).unwrap();
    eprintln!("screenshot: {}", out.display());
}

/// Screenshots of an area light moved and resized in the page (for
/// docs/, not a test of correctness): `LTM_VIEW_AREA_FILE` (a file with
/// near-field rows) lit by `LTM_VIEW_AREA_ENV`, with a uniform light of
/// intensity 60 and 0.3 × 0.3 at (−0.5, 0.1), then moved to (0.5, 0.6) and
/// grown to 1.5 × 1.2, written to `LTM_VIEW_AREA_OUT`-1.png and -2.png.
///
/// `LTM_VIEW_AREA_FILE=s128.ltm LTM_VIEW_AREA_ENV=map.exr LTM_VIEW_AREA_OUT=docs/view-area
/// cargo test --release -p ltm-tools --test view_browser area_light_screenshots -- --ignored`
#[test]
#[ignore = "writes screenshots for docs/; run by hand"]
fn area_light_screenshots() {
    let Some(browser) = browser() else { return };
    let var = |k: &str| std::env::var(k).unwrap_or_else(|_| panic!("{k} is not set"));
    let (file, env, out) = (
        var("LTM_VIEW_AREA_FILE"),
        var("LTM_VIEW_AREA_ENV"),
        var("LTM_VIEW_AREA_OUT"),
    );
    let srv = Server::start(&[&file, "--env", &env]);
    let tab = open_page(&browser, &srv, "#view0[data-shown]");
    let n = text(&tab, "document.getElementById('n-number').value");
    let shots = [("-0.5", "0.1", "0.3", "0.3"), ("0.5", "0.6", "1.5", "1.2")];
    for (k, (x, y, w, h)) in shots.into_iter().enumerate() {
        for (id, v) in [
            ("area-x", x),
            ("area-y", y),
            ("area-w", w),
            ("area-h", h),
            ("area-i", "60"),
        ] {
            set(&tab, id, v, "change");
        }
        eval(&tab, "(() => { const a = document.getElementById('area'); a.checked = true; a.dispatchEvent(new Event('change')); return true; })()");
        let q = format!(
            "file=0&map=0&yaw=0&pitch=0&roll=0&n={n}&weighting=transport&ax={x}&ay={y}&aw={w}&ah={h}&ai=60&ad=0&at=0"
        );
        wait_shown(&tab, "view0", &q);
        let png = tab
            .capture_screenshot(Page::CaptureScreenshotFormatOption::Png, None, None, true)
            .unwrap();
        std::fs::write(format!("{out}-{}.png", k + 1), png).unwrap();
    }
}

/// Screenshots of glossy materials for docs/ (run by hand, see
/// docs/results/glossy.md): the texture-space file `LTM_VIEW_GLOSSY_FILE`
/// under the two maps of `LTM_VIEW_GLOSSY_ENVS` (comma-separated) with the
/// two materials of `LTM_VIEW_GLOSSY_BRDFS` (`;`-separated), from two
/// orbit positions (the second 120 px of drag round), written to
/// `LTM_VIEW_GLOSSY_OUT-{map}-{material}-{view}.png`;
/// `LTM_VIEW_GLOSSY_CACHE` is the rotation cache.
#[test]
#[ignore = "writes screenshots for docs/; run by hand"]
fn glossy_screenshots() {
    let Some(browser) = browser() else { return };
    let var = |k: &str| std::env::var(k).unwrap_or_else(|_| panic!("{k} is not set"));
    let (file, envs, brdfs) = (
        var("LTM_VIEW_GLOSSY_FILE"),
        var("LTM_VIEW_GLOSSY_ENVS"),
        var("LTM_VIEW_GLOSSY_BRDFS"),
    );
    let (cache, out) = (var("LTM_VIEW_GLOSSY_CACHE"), var("LTM_VIEW_GLOSSY_OUT"));
    let mut args = vec![file.as_str(), "--rotation-cache", &cache];
    for env in envs.split(',') {
        args.extend(["--env", env]);
    }
    for b in brdfs.split(';') {
        args.extend(["--brdf", b]);
    }
    let srv = Server::start(&args);
    let tab = open_page(&browser, &srv, "#gl0[data-camera]");
    for view in 0..2 {
        if view == 1 {
            drag(&tab, "gl0", 120.0);
        }
        for map in 0..2 {
            set(&tab, "map", &map.to_string(), "change");
            for material in 1..=2 {
                set(&tab, "brdf", &material.to_string(), "change");
                let q = eval(&tab, "query(0)");
                wait_shown(&tab, "view0", q.as_str().unwrap());
                let png = tab
                    .capture_screenshot(Page::CaptureScreenshotFormatOption::Png, None, None, true)
                    .unwrap();
                std::fs::write(format!("{out}-{map}-{material}-{view}.png"), png).unwrap();
            }
        }
    }
}
