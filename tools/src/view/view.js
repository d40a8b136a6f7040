// ltm view: asks the server for frames (binary RGB half floats, see the
// server's module docs), tone-maps them here and draws them. One request per
// file is in flight at a time; inputs that arrive meanwhile only update the
// pending state, so the newest settings are sent next (latest wins).
"use strict";

const $ = (id) => document.getElementById(id);
const client = Array.from(crypto.getRandomValues(new Uint8Array(8)), (b) => b.toString(16).padStart(2, "0")).join("");
let seq = 0;
let info = null;
const panels = []; // one per file: { canvas, halves, floats, width, height, inFlight, pending, ... }
let exactPanel = null;
const nGroups = []; // N controls: one for all files, or one per file when their light counts differ
const stats = { latencies: [], frames: 0 };
window.ltmView = stats;
const DEFAULT_N = 200;
let autoEv = null; // the auto exposure, once a first image has come
let autoEvDraft = false; // whether autoEv came from a draft frame
let offline = false;

// Half float → float, through a table of all 65536 values.
const HALF = new Float32Array(65536);
(function () {
  for (let h = 0; h < 65536; h++) {
    const s = h & 0x8000 ? -1 : 1, e = (h >> 10) & 0x1f, m = h & 0x3ff;
    HALF[h] = e === 0 ? s * m * 2 ** -24 : e === 31 ? (m ? NaN : s * Infinity) : s * (1 + m / 1024) * 2 ** (e - 15);
  }
})();

// A binary frame: its size and half floats. Drawing reads the halves
// (toRgba); the floats, which only the probe, the heatmap, the exposure
// and a mesh's texture need, are decoded on first use: a panel's `floats`
// getter (see `addPanel`) keeps them in `decoded` until the next frame.
function decodeFrame(buf) {
  const dv = new DataView(buf);
  const magic = String.fromCharCode(...new Uint8Array(buf, 0, 4));
  if (magic !== "LTMF" || dv.getUint32(12, true) !== 1) throw new Error("not an RGB f16 frame");
  const w = dv.getUint32(4, true), h = dv.getUint32(8, true);
  return { width: w, height: h, halves: new Uint16Array(buf, 16, w * h * 3), decoded: null };
}

function halvesToFloats(halves) {
  const f = new Float32Array(halves.length);
  for (let i = 0; i < f.length; i++) f[i] = HALF[halves[i]];
  return f;
}

// sRGB 8-bit encoding, as ltm's PNG writer does it.
function srgb8(v) {
  v = Math.min(Math.max(v, 0), 1);
  const e = v <= 0.0031308 ? 12.92 * v : 1.055 * Math.pow(v, 1 / 2.4) - 0.055;
  return Math.floor(e * 255 + 0.5);
}

// srgb8 without a power per value, for whole frames: a table on a 4096-step
// grid gives the code at the step's start, and the exact thresholds (the
// least value that encodes to each code, found by bisection) decide the one
// step the code can still rise within a grid step.
const SRGB_STEPS = 4096;
const SRGB_FROM = new Uint8Array(SRGB_STEPS + 1).map((_, i) => srgb8(i / SRGB_STEPS));
const SRGB_AT = Array.from({ length: 257 }, (_, k) => {
  if (k === 0) return -Infinity;
  if (k === 256) return Infinity;
  let lo = 0, hi = 1; // srgb8(lo) < k <= srgb8(hi)
  for (let i = 0; i < 80 && hi - lo > 0; i++) {
    const mid = 0.5 * (lo + hi);
    if (mid === lo || mid === hi) break;
    if (srgb8(mid) >= k) hi = mid; else lo = mid;
  }
  return hi;
});
function srgb8Fast(v) {
  if (!(v > 0)) return 0;
  if (v >= 1) return 255;
  const k = SRGB_FROM[Math.floor(v * SRGB_STEPS)];
  return v >= SRGB_AT[k + 1] ? k + 1 : k;
}

const lum = (f, i) => 0.2126 * f[i] + 0.7152 * f[i + 1] + 0.0722 * f[i + 2];

// The auto exposure of `ltm demo` (and `--exposure auto`): the 99th
// percentile of the positive luminances shows at 0.8.
function autoExposure(floats) {
  const all = new Float64Array(floats.length / 3);
  let n = 0;
  for (let i = 0; i < floats.length; i += 3) { const v = lum(floats, i); if (v > 0) all[n++] = v; }
  if (!n) return 0;
  const l = all.subarray(0, n).sort(); // typed arrays sort numerically
  const v = l[Math.min(Math.floor(l.length * 99 / 100), l.length - 1)];
  return Math.min(30, Math.max(-30, Math.log2(0.8 / v)));
}

function ev() { return $("auto-exposure").checked && autoEv !== null ? autoEv : Number($("exposure").value); }

function showEv() {
  const e = ev();
  $("exposure-value").textContent = e.toFixed(1);
  $("exposure-value").dataset.ev = e;
  if ($("auto-exposure").checked) $("exposure").value = e;
}

// A frame's tone-mapped pixels from its half floats, through a table of the
// 8-bit code of every half float (made once an exposure and tone map): each
// code as ltm's PNG writer makes it from the value.
let halfCodes = { key: null, table: null };
function toRgba(halves, w, h) {
  const scale = Math.pow(2, ev()), reinhard = $("tonemap").value === "reinhard", key = `${scale}:${reinhard}`;
  if (halfCodes.key !== key) {
    const table = new Uint8Array(65536);
    for (let i = 0; i < 65536; i++) {
      // Math.fround: the same f32 product as the PNG writer's.
      let v = Math.fround(HALF[i] * Math.fround(scale));
      if (reinhard) v = v / (1 + v);
      table[i] = srgb8Fast(v);
    }
    halfCodes = { key, table };
  }
  const t = halfCodes.table, out = new Uint8ClampedArray(w * h * 4);
  for (let p = 0; p < w * h; p++) {
    out[4 * p] = t[halves[3 * p]];
    out[4 * p + 1] = t[halves[3 * p + 1]];
    out[4 * p + 2] = t[halves[3 * p + 2]];
    out[4 * p + 3] = 255;
  }
  return out;
}

// --- error heatmap ---------------------------------------------------------

// A perceptually ordered dark-to-bright scale (black, purple, red, orange,
// pale yellow), linear between its stops.
const HEAT = [[0, 0, 4], [87, 16, 110], [188, 55, 84], [249, 142, 9], [252, 255, 164]];
function heatColor(t) {
  t = Math.min(Math.max(t, 0), 1) * (HEAT.length - 1);
  const i = Math.min(Math.floor(t), HEAT.length - 2), f = t - i;
  return HEAT[i].map((a, c) => Math.round(a + f * (HEAT[i + 1][c] - a)));
}

function meanLum(floats) {
  let s = 0;
  for (let i = 0; i < floats.length; i += 3) s += lum(floats, i);
  return s / Math.max(1, floats.length / 3);
}

// |relit − exact| per pixel (the luminance of the absolute difference), as a
// share of the exact image's mean luminance, over the chosen scale.
function heatRgba(floats, exact, w, h) {
  const mean = meanLum(exact) || 1, scale = Number($("heat-scale").value);
  const out = new Uint8ClampedArray(w * h * 4), d = [0, 0, 0];
  for (let p = 0; p < w * h; p++) {
    for (let c = 0; c < 3; c++) d[c] = Math.abs(floats[3 * p + c] - exact[3 * p + c]);
    const col = heatColor(lum(d, 0) / mean / scale);
    out.set(col, 4 * p);
    out[4 * p + 3] = 255;
  }
  return out;
}

function drawLegend(show) {
  $("legend").hidden = !show;
  $("legend-text").textContent = show
    ? `0 ${" ".repeat(26)}≥ ${(100 * Number($("heat-scale").value)).toFixed(0)} %\n|relit − exact| luminance, as a share\nof the exact image's mean luminance`
    : "";
  if (!show) return;
  const c = $("legend"), g = c.getContext("2d");
  for (let x = 0; x < c.width; x++) { g.fillStyle = `rgb(${heatColor(x / (c.width - 1)).join(",")})`; g.fillRect(x, 0, 1, c.height); }
}

// The exact image for a panel's lighting, when it has come.
function exactFor(p) {
  if (!exactPanel || !exactPanel.halves || !p.shown) return null;
  if (lightingOf(p.shown) !== lightingOf(exactPanel.shownQuery || "")) return null;
  return exactPanel.width === p.width && exactPanel.height === p.height ? exactPanel.floats : null;
}

// --- N, rotation, queries ----------------------------------------------------

function groupOf(fileIndex) { return nGroups.find((g) => g.files.includes(fileIndex)); }

function terms(fileIndex) {
  const g = groupOf(fileIndex), v = Math.round(Number(g.number.value));
  return Math.min(g.max, Math.max(1, Number.isFinite(v) ? v : g.max));
}

// Slider positions 0..1000 run logarithmically over 1..max.
const sliderOf = (n, max) => (max > 1 ? Math.round(1000 * Math.log(n) / Math.log(max)) : 1000);
const termsOf = (t, max) => Math.min(max, Math.max(1, Math.round(Math.exp(t / 1000 * Math.log(max)))));

function addNGroup(files, label) {
  const max = info.files[files[0]].max_terms, k = nGroups.length, suffix = k ? `-${k}` : "";
  const el = document.createElement("label");
  el.title = `terms per pixel: 1..${max}`;
  el.innerHTML = `${label} <input id="n${suffix}" type="range" min="0" max="1000"> ` +
    `<input id="n-number${suffix}" type="number" min="1" max="${max}" step="1"> <span class="num">of ${max}</span>`;
  $("n-controls").append(el);
  const g = { files, max, slider: el.querySelector(`#n${suffix}`), number: el.querySelector(`#n-number${suffix}`) };
  g.reset = () => { g.number.value = Math.min(DEFAULT_N, max); g.slider.value = sliderOf(Number(g.number.value), max); };
  g.slider.addEventListener("input", () => { g.number.value = termsOf(Number(g.slider.value), max); readouts(); requestFrames(); });
  g.number.addEventListener("change", () => { g.number.value = terms(files[0]); g.slider.value = sliderOf(terms(files[0]), max); readouts(); requestFrames(); });
  g.reset();
  nGroups.push(g);
}

function angle(id) {
  const v = Number($(id).value);
  return Number.isFinite(v) ? v : 0;
}

// Keeps the rotation fields in range: yaw and roll wrap into -180..180,
// pitch stays in -90..90.
function normalizeAngles() {
  const wrap = (a) => { const r = ((a + 180) % 360 + 360) % 360 - 180; return r === -180 ? 180 : r; };
  for (const id of ["yaw", "roll"]) { const a = angle(id), w = +wrap(a).toFixed(4); if (w !== a || $(id).value === "") $(id).value = w; }
  const p = angle("pitch"), c = Math.min(90, Math.max(-90, p));
  if (c !== p || $("pitch").value === "") $("pitch").value = c;
}

function rotationQuery() { return `map=${$("map").value}&yaw=${angle("yaw")}&pitch=${angle("pitch")}&roll=${angle("roll")}`; }

function query(fileIndex) {
  return `file=${fileIndex}&${rotationQuery()}&n=${terms(fileIndex)}&weighting=${$("weighting").value}${areaQuery(fileIndex)}${glossyQuery(fileIndex)}`;
}

// The glossy material's part of a file's query: the menu's material and
// the eye it is shaded from: a texture-space file's orbit camera, or the
// camera an image-space file's pixels were seen from.
function glossyQuery(fileIndex) {
  const k = Number($("brdf").value || 0), gl = panels[fileIndex]?.gl;
  const eye = gl ? gl.eye() : info.files[fileIndex]?.eye;
  if (!k || !eye) return "";
  return `&brdf=${k}&eye=${eye.map((c) => +c.toPrecision(9)).join(",")}`;
}

// The area light's part of a file's query: only when it is on and the file
// has near-field rows (a [light_plane] in its scene).
function areaQuery(fileIndex) {
  if (!$("area").checked || !info.files[fileIndex]?.near_field) return "";
  const v = (id) => Number($(id).value);
  return `&ax=${v("area-x")}&ay=${v("area-y")}&aw=${v("area-w")}&ah=${v("area-h")}&ai=${v("area-i")}` +
    `&ad=${v("area-angle")}&at=${$("area-texture").value}`;
}

// The lighting part of a query (map and rotation): what the exact image depends on.
function lightingOf(q) { return q.split("&").filter((kv) => /^(map|yaw|pitch|roll)=/.test(kv)).join("&"); }

function message(text) { $("message").textContent = text || ""; }

// --- drawing -------------------------------------------------------------

function draw(panel) {
  if (!panel.halves) return;
  const exact = panel !== exactPanel && $("display").value === "heat" ? exactFor(panel) : null;
  const rgba = exact ? heatRgba(panel.floats, exact, panel.width, panel.height)
    : toRgba(panel.halves, panel.width, panel.height);
  if (panel.gl) { panel.gl.setTexture(panel.floats, rgba, panel.width, panel.height); return; }
  const c = panel.canvas;
  if (c.width !== panel.width || c.height !== panel.height) { c.width = panel.width; c.height = panel.height; }
  c.getContext("2d").putImageData(new ImageData(rgba, panel.width, panel.height), 0, 0);
  c.dataset.display = exact ? "heat" : "image";
  layoutSplit();
}

function drawAll() {
  showEv();
  panels.forEach(draw);
  if (exactPanel) draw(exactPanel);
  drawLegend($("display").value === "heat");
  drawPreview();
}

// What each panel shows against what was asked: "updating" while a newer
// frame is on its way, "offline" while the server cannot be reached.
function showStates() {
  for (const p of [...panels, exactPanel].filter(Boolean)) {
    const s = p.state;
    const want = p === exactPanel ? lightingOf(query(0)) : query(p.index);
    const have = p === exactPanel ? lightingOf(p.shownQuery || "") : p.draft ? null : p.shown;
    s.className = offline ? "state offline" : "state";
    s.textContent = offline ? "offline: the server does not answer; this is the last frame"
      : p.halves && have !== want && (p.inFlight || p.pending) ? "updating…" : "";
  }
}

// --- requests --------------------------------------------------------------

function requestFrames() {
  normalizeAngles();
  const now = performance.now();
  for (const p of panels) {
    p.pending = { query: query(p.index), input: p.pending ? p.pending.input : now };
    if (!p.inFlight) send(p);
  }
  requestPreview();
  showStates();
}

function goneOffline(what, e) {
  if (!offline) { offline = true; setTimeout(() => { offline = false; requestFrames(); }, 2000); }
  message(`${what}: ${e} (is ltm view still running?)`);
  showStates();
}

// Auto exposure follows file 0's frames: set by the first, then moved when
// an exact frame's differs by more than 1/4 EV (or the current one came
// from a draft). Drafts do not move it: a drag shows them as fast as it
// moves, and they differ from the exact frame by a few per cent.
function followAutoExposure(p) {
  if (autoEv !== null && p.draft) return;
  const e = autoExposure(p.floats);
  if (autoEv === null || autoEvDraft || Math.abs(e - autoEv) > 0.25) {
    autoEv = e;
    autoEvDraft = p.draft;
  }
}

// A job asks for a draft light (fast, approximate: see `light=draft` in
// the server's API) unless it is the exact refinement of a draft frame.
const REFINE_MS = 100;

// The exact refinement of a draft frame, asked for once the settings have
// rested for REFINE_MS (so that it never holds up a drag's next frame).
function refineLater(p) {
  clearTimeout(p.refineTimer);
  p.refineTimer = setTimeout(() => {
    if (!p.draft || p.pending || p.inFlight || offline || p.shown !== query(p.index)) return;
    p.pending = { query: p.shown, input: performance.now(), exact: true };
    send(p);
  }, REFINE_MS);
}

// Where a frame's fetch spent its time, from the browser's resource timing
// (for the latency benchmark): waiting to be sent, waiting for the answer's
// first byte (the server's work), receiving the body, and from the last
// byte to the page having it. The browser keeps a few hundred entries;
// they are cleared every 64 frames, well before that.
let timings = 0;
function fetchTiming(url, sent, received) {
  const e = performance.getEntriesByName(new URL(url, location.href).href).pop();
  if (++timings % 64 === 0) performance.clearResourceTimings();
  if (!e) return {};
  return { queue_ms: e.requestStart - sent, wait_ms: e.responseStart - e.requestStart,
    body_ms: e.responseEnd - e.responseStart, after_body_ms: received - e.responseEnd };
}

// Once a frame arrives, the panel's next request goes out at once: its
// round trip overlaps the wait for the display frame and the drawing.
async function send(p) {
  const job = p.pending;
  p.pending = null;
  p.inFlight = true;
  let released = false;
  const release = () => {
    if (released) return;
    released = true;
    p.inFlight = false;
    if (p.pending && !offline) send(p);
    else if (p.index === 0) requestExact();
    if (preview.dirty) schedulePreview();
  };
  const sent = performance.now();
  try {
    // Each panel is its own stream for latest-request-wins.
    const light = job.exact ? "exact" : "draft";
    const url = `/api/frame?${job.query}&light=${light}&client=${client}${p.index}&seq=${++seq}`;
    const r = await fetch(url);
    if (r.status === 200) {
      const frame = decodeFrame(await r.arrayBuffer());
      const received = performance.now(), mine = (p.arrived = (p.arrived || 0) + 1);
      // The next request goes out at once; this frame is drawn in the next
      // display frame, together with whatever else arrived by then.
      release();
      await nextPaint();
      if (mine !== p.arrived) return; // a newer frame of this panel came first
      const painted = performance.now();
      Object.assign(p, frame);
      p.shown = job.query;
      const draft = (p.draft = r.headers.get("X-Light") === "draft");
      const evBefore = ev();
      if (p.index === 0) followAutoExposure(p);
      const readout = (p.readout = {
        serverMs: Number(r.headers.get("X-Frame-Ms")),
        resampleMs: Number(r.headers.get("X-Resample-Ms")),
        lights: r.headers.get("X-Lights"),
        nonzeros: r.headers.get("X-Nonzeros"),
        error: r.headers.get("X-Error"),
        areaMs: r.headers.has("X-Area-Ms") ? Number(r.headers.get("X-Area-Ms")) : null,
        step1Ms: r.headers.has("X-Step1-Ms") ? Number(r.headers.get("X-Step1-Ms")) : null,
        step2Ms: r.headers.has("X-Step2-Ms") ? Number(r.headers.get("X-Step2-Ms")) : null,
        glossySetupMs: r.headers.has("X-Glossy-Setup-Ms") ? Number(r.headers.get("X-Glossy-Setup-Ms")) : null,
      });
      // A new exposure redraws every panel; otherwise only this one changed.
      if (ev() !== evBefore || !p.drawnOnce) drawAll(); else draw(p);
      p.drawnOnce = true;
      // Drawn inside the display frame's callback: on screen with that frame.
      const shown = performance.now();
      if (wantsError(p)) askError(p);
      readout.latencyMs = shown - job.input;
      readout.roundTripMs = shown - sent;
      stats.frames++;
      stats.latencies.push({ file: p.index, query: job.query, light: draft ? "draft" : "exact",
        latency_ms: shown - job.input, round_trip_ms: shown - sent, server_ms: readout.serverMs,
        resample_ms: readout.resampleMs, fetch_ms: received - sent, draw_ms: shown - painted,
        display_wait_ms: painted - received, ...fetchTiming(url, sent, received) });
      p.canvas.dataset.shown = draft ? `${job.query}&light=draft` : job.query;
      if (draft) refineLater(p);
      message("");
    } else if (r.status === 503) {
      if (!p.pending) p.pending = job; // busy: retry with the newest settings
    } else if (r.status !== 204) {
      message(`frame: ${r.status} ${await r.text()}`);
    }
  } catch (e) {
    goneOffline("frame", e);
  }
  release();
  readouts();
  showStates();
}

async function requestExact() {
  if (!info.reference || !$("show-exact").checked) return;
  const q = query(0);
  // The exact image depends on the lighting only (N's errors come with the frames).
  if (exactPanel.inFlight || lightingOf(exactPanel.shownQuery || "") === lightingOf(q)) return;
  exactPanel.inFlight = true;
  $("error").textContent = "computing…";
  try {
    const r = await fetch(`/api/exact?${q}`);
    if (r.status === 200) {
      Object.assign(exactPanel, decodeFrame(await r.arrayBuffer()));
      exactPanel.shownQuery = q;
      exactPanel.canvas.dataset.shown = q;
      exactPanel.exactMs = r.headers.get("X-Exact-Ms");
      $("error").textContent = `computed in ${Number(exactPanel.exactMs).toFixed(1)} ms (0 when cached)`;
      // File 0's frame at this query: its error came with the exact image.
      if (panels[0].shown === q && !panels[0].draft && !areaQuery(0)) panels[0].readout.error = r.headers.get("X-Error");
      drawAll();
      for (const p of panels) if (wantsError(p)) askError(p);
    } else if (r.status !== 503) {
      message(`exact: ${r.status} ${await r.text()}`);
    }
  } catch (e) {
    goneOffline("exact", e);
  }
  exactPanel.inFlight = false;
  if (lightingOf(query(0)) !== lightingOf(exactPanel.shownQuery || "") && !panels[0].inFlight && !offline) requestExact();
  readouts();
  showStates();
}

// A frame that came without an error while the exact image of its lighting
// is shown (it was made before the exact image was cached): asked for once
// more, now with its error.
// (Not with an area light: the exact image is the map's alone.)
function wantsError(p) {
  return !!info.reference && !areaQuery(p.index) && !glossyQuery(p.index) && !!p.readout && !p.readout.error && !p.draft && p.shown === query(p.index) && p.retried !== p.shown &&
    !!exactPanel.shownQuery && lightingOf(exactPanel.shownQuery) === lightingOf(p.shown);
}

function askError(p) {
  p.retried = p.shown;
  if (!p.pending) p.pending = { query: p.shown, input: performance.now(), exact: true };
  if (!p.inFlight) send(p);
}

// --- map preview -------------------------------------------------------------

// The page fetches each map's unrotated preview once (`/api/map`, 256 × 128
// floats) and rotates it here, at most once a display frame: pixel ω shows
// the preview's pixel nearest R⁻¹·ω, as the server's /api/map draws it
// (src/view/preview.rs). Turning the map costs no request: a drag's inputs
// would otherwise each fetch and decode a preview beside the frames.
const preview = {
  inFlight: false, map: null, halves: null, decoded: null, width: 0, height: 0, ev: 0, texels: null, texelsEv: null, dirty: false, tiltKey: null, u: null, row: null,
  get floats() { return this.halves ? (this.decoded ??= halvesToFloats(this.halves)) : null; },
};

async function requestPreview() {
  const map = $("map").value;
  if (preview.map === map) return schedulePreview();
  if (preview.inFlight) return;
  preview.inFlight = true;
  try {
    const r = await fetch(`/api/map?map=${map}&yaw=0&pitch=0&roll=0`);
    if (r.status === 200) {
      Object.assign(preview, decodeFrame(await r.arrayBuffer()));
      // The rotation moves the pixels, not their values: one exposure a map.
      Object.assign(preview, { map, ev: autoExposure(preview.floats), texels: null, tiltKey: null });
    }
  } catch (e) {
    goneOffline("map preview", e);
  }
  preview.inFlight = false;
  if (preview.map !== $("map").value && !offline) requestPreview();
  else schedulePreview();
}

// The preview is drawn at most once a display frame. While a panel's frame
// is on its way, the preview waits and is drawn with that frame: one change
// to the page instead of two, and no display frame of its own. During a
// two-file drag this takes about 12 ms off the input-to-screen latency
// (docs/results/viewer.md).
function schedulePreview() {
  preview.dirty = true;
  if (!panels.some((p) => p.inFlight)) nextPaint();
}

// The next display frame's callback, shared: the panels' frames that have
// arrived since the last one and the preview, if it changed, are drawn in
// it, so that the page changes once a display frame.
let painting = null;
function nextPaint() {
  painting ??= new Promise((done) => requestAnimationFrame(() => {
    painting = null;
    if (preview.dirty) drawPreview();
    done();
  }));
  return painting;
}

// `sin` and `cos` of an angle in degrees as ltm_relight's sin_cos_degrees
// takes them: exact at multiples of 90, 0 for a non-finite angle.
function sinCosDegrees(deg) {
  let r = deg % 360;
  if (r < 0) r += 360;
  if (r === 0 || !Number.isFinite(r)) return [0, 1];
  if (r === 90) return [1, 0];
  if (r === 180) return [0, -1];
  if (r === 270) return [-1, 0];
  const x = r * (Math.PI / 180);
  return [Math.sin(x), Math.cos(x)];
}

// The rotation as ltm_relight::Rotation::matrix builds it (Rz·Rx·Ry,
// degrees), as its columns, with glam's order of operations.
function rotationColumns(yaw = angle("yaw"), pitch = angle("pitch"), roll = angle("roll")) {
  const [sy, cy] = sinCosDegrees(yaw), [sp, cp] = sinCosDegrees(pitch), [sr, cr] = sinCosDegrees(roll);
  const ry = [[cy, 0, -sy], [0, 1, 0], [sy, 0, cy]];
  const rx = [[1, 0, 0], [0, cp, sp], [0, -sp, cp]];
  const rz = [[cr, sr, 0], [-sr, cr, 0], [0, 0, 1]];
  const apply = (m, v) => [0, 1, 2].map((i) => m[0][i] * v[0] + m[1][i] * v[1] + m[2][i] * v[2]);
  const mul = (a, b) => b.map((col) => apply(a, col));
  return mul(mul(rz, rx), ry);
}

// The lat-long coordinates of a direction (ltm_codec::cubemap::latlong_uv).
function latlongUv(x, y, z) {
  let u = Math.atan2(x, -z) / (2 * Math.PI) % 1;
  if (u < 0) u += 1;
  return [u, Math.acos(Math.max(-1, Math.min(1, y))) / Math.PI];
}

// The preview's tone-mapped texels (once a map and exposure), and where
// each pixel looks before the yaw: R = Rz·Rx·Ry, so R⁻¹·ω = Ry⁻¹·(Rx⁻¹·Rz⁻¹·ω),
// and the last step, a turn about y, only moves u by +yaw/360. The table of
// Rx⁻¹·Rz⁻¹·ω's u and row is made once a pitch and roll, so that a yaw drag
// costs a lookup a pixel (the same pixels as /api/map's, but for ties at a
// pixel's edge: rounding differs from the server's one product).
function previewTables(pitch, roll) {
  const w = preview.width, h = preview.height;
  if (!preview.texels || preview.texelsEv !== preview.ev) {
    const scale = Math.pow(2, preview.ev), out = new Uint8ClampedArray(w * h * 4);
    for (let p = 0; p < w * h; p++) { for (let k = 0; k < 3; k++) out[4 * p + k] = srgb8Fast(preview.floats[3 * p + k] * scale); out[4 * p + 3] = 255; }
    preview.texels = new Uint32Array(out.buffer);
    preview.texelsEv = preview.ev;
  }
  const key = `${w}x${h}:${pitch},${roll}`;
  if (preview.tiltKey === key) return;
  const [[a0, a1, a2], [b0, b1, b2], [c0, c1, c2]] = rotationColumns(0, pitch, roll);
  preview.u = new Float64Array(w * h);
  preview.row = new Int32Array(w * h);
  for (let y = 0; y < h; y++) for (let x = 0; x < w; x++) {
    const phi = 2 * Math.PI * ((x + 0.5) / w), theta = Math.PI * ((y + 0.5) / h), p = y * w + x;
    const dx = Math.sin(phi) * Math.sin(theta), dy = Math.cos(theta), dz = -Math.cos(phi) * Math.sin(theta);
    // Each column of R (a row of its transpose) dotted with d.
    const [u, v] = latlongUv(a0 * dx + a1 * dy + a2 * dz, b0 * dx + b1 * dy + b2 * dz, c0 * dx + c1 * dy + c2 * dz);
    preview.u[p] = u;
    preview.row[p] = Math.min(Math.floor(v * h), h - 1) * w;
  }
  preview.tiltKey = key;
}

// The rotated map (as the frames are lit), with a cross where the map's
// centre (u = v = 0.5, straight ahead at no rotation) now lies.
function drawPreview() {
  preview.dirty = false;
  if (!preview.halves) return;
  const c = $("map-preview"), w = preview.width, h = preview.height;
  if (c.width !== w || c.height !== h) { c.width = w; c.height = h; }
  previewTables(angle("pitch"), angle("roll"));
  const m = rotationColumns(), out = new Uint32Array(w * h), texels = preview.texels, us = preview.u, rows = preview.row;
  const turn = angle("yaw") / 360;
  for (let p = 0; p < w * h; p++) {
    let u = us[p] + turn;
    u -= Math.floor(u);
    out[p] = texels[rows[p] + Math.min(Math.floor(u * w), w - 1)];
  }
  const g = c.getContext("2d");
  g.putImageData(new ImageData(new Uint8ClampedArray(out.buffer), w, h), 0, 0);
  // The map's centre pixel looks along +z (docs/FORMAT.md's lat-long map): R·(0, 0, 1) is R's last column.
  const [u, v] = latlongUv(...m[2]);
  const x = u * w, y = v * h;
  g.strokeStyle = "#fd8"; g.lineWidth = 1.5;
  g.beginPath(); g.moveTo(x - 8, y); g.lineTo(x + 8, y); g.moveTo(x, y - 8); g.lineTo(x, y + 8); g.stroke();
  c.dataset.shown = rotationQuery().replace(/^map=[^&]*/, `map=${preview.map}`);
  $("preview-caption").textContent = `${info.maps[Number($("map").value)].name}, yaw ${angle("yaw")}°, pitch ${angle("pitch")}°, roll ${angle("roll")}° (+: the map's centre)`;
}

function previewDrags() {
  const c = $("map-preview");
  let last = null;
  c.addEventListener("pointerdown", (e) => { last = e.clientX; c.setPointerCapture(e.pointerId); });
  c.addEventListener("pointermove", (e) => {
    if (last === null) return;
    // The content follows the pointer: a positive yaw moves it left.
    const dx = e.clientX - last;
    last = e.clientX;
    $("yaw").value = +(angle("yaw") - (dx / c.getBoundingClientRect().width) * 360).toFixed(2);
    requestFrames();
  });
  c.addEventListener("pointerup", () => { last = null; });
}

// --- readouts and probe ----------------------------------------------------------

function fmt(bytes) {
  return bytes > 1e6 ? `${(bytes / 1e6).toFixed(2)} MB` : `${(bytes / 1e3).toFixed(1)} kB`;
}

function pct(e) { return e === null || e === undefined || e === "" ? null : `${(100 * Number(e)).toFixed(3)} %`; }

function readouts() {
  const lines = panels.map((p) => {
    const f = info.files[p.index], r = p.readout || {};
    const err = pct(r.error);
    if (p.errorEl) p.errorEl.textContent = info.reference ? `error against exact T·L: ${err ?? "–"}` : "";
    if (p.errorEl) p.errorEl.dataset.value = r.error ?? "";
    return `${f.name}: ${fmt(f.bytes)} ${f.mode}, matrix error ${(100 * f.matrix_error).toFixed(3)} %, N = ${terms(p.index)} of ${f.max_terms}` +
      (err ? `, image error ${err}` : "") +
      `\n  server ${r.serverMs?.toFixed(2) ?? "-"} ms (+ resample ${r.resampleMs?.toFixed(2) ?? "-"} ms${p.draft ? ", draft light" : ""}), ` +
      `round trip ${r.roundTripMs?.toFixed(1) ?? "-"} ms, input→screen ${r.latencyMs?.toFixed(1) ?? "-"} ms, ` +
      `lights ${r.lights ?? "-"}, nonzeros ${r.nonzeros ?? "-"}` +
      (r.areaMs !== null && r.areaMs !== undefined ? `\n  area light ${r.areaMs.toFixed(1)} ms (exact; the error readouts are the map's)` : "") +
      (r.step2Ms !== null && r.step2Ms !== undefined ? `\n  glossy ${info.brdfs[Number($("brdf").value) - 1] ?? ""} (n = ${info.glossy_n}): step 1 ${r.step1Ms.toFixed(1)} ms (0: lighting kept), step 2 ${r.step2Ms.toFixed(1)} ms` +
        (r.glossySetupMs ? `, set-up ${r.glossySetupMs.toFixed(0)} ms` : "") : "");
  });
  $("readouts").textContent = lines.join("\n");
  layoutSplit();
}

// Values under the pointer: every file's, the exact image's and the error.
function probe(canvas, e) {
  const rect = canvas.getBoundingClientRect();
  const x = Math.floor(((e.clientX - rect.left) / rect.width) * canvas.width), y = Math.floor(((e.clientY - rect.top) / rect.height) * canvas.height);
  if (x < 0 || y < 0 || x >= canvas.width || y >= canvas.height) return;
  const at = (p) => (p && p.floats && x < p.width && y < p.height ? Array.from(p.floats.subarray(3 * (y * p.width + x), 3 * (y * p.width + x) + 3)) : null);
  const rgb = (v) => v.map((c) => c.toPrecision(4)).join(" ");
  const ex = at(exactPanel);
  const lines = [`pixel (${x}, ${y})`];
  for (const p of panels) {
    const v = at(p);
    if (!v) continue;
    const err = ex ? ` |Δ| ${Math.abs(lum(v, 0) - lum(ex, 0)).toPrecision(3)}` : "";
    lines.push(`${info.files[p.index].name}: ${rgb(v)}${err}`);
  }
  if (ex) lines.push(`exact: ${rgb(ex)}`);
  $("probe").textContent = lines.join("\n");
  $("probe").dataset.x = x; $("probe").dataset.y = y;
}

// --- controls ---------------------------------------------------------------

function resetAll() {
  for (const id of ["yaw", "pitch", "roll"]) $(id).value = 0;
  nGroups.forEach((g) => g.reset());
  $("auto-exposure").checked = true;
  $("tonemap").value = "clamp";
  $("display").value = "image";
  $("heat-label").hidden = true;
  if (info.weightings.includes("transport")) $("weighting").value = "transport";
  drawAll();
  requestFrames();
}

function wireControls() {
  for (const id of ["map", "weighting", "yaw", "pitch", "roll", "show-exact"]) $(id).addEventListener("change", requestFrames);
  for (const id of ["yaw", "pitch", "roll"]) $(id).addEventListener("input", requestFrames);
  for (const id of ["area", "area-texture", "area-angle", "brdf"]) $(id).addEventListener("change", requestFrames);
  for (const id of ["area-x", "area-y", "area-w", "area-h", "area-i"]) {
    $(id).addEventListener("input", requestFrames);
    $(id).addEventListener("change", requestFrames);
  }
  $("exposure").addEventListener("input", () => { $("auto-exposure").checked = false; drawAll(); });
  $("auto-exposure").addEventListener("change", drawAll);
  $("tonemap").addEventListener("change", drawAll);
  $("display").addEventListener("change", () => { $("heat-label").hidden = $("display").value !== "heat"; drawAll(); });
  $("heat-scale").addEventListener("change", drawAll);
  $("pixels").addEventListener("change", () => document.body.classList.toggle("exact-pixels", $("pixels").value === "exact"));
  $("show-exact").addEventListener("change", () => { exactPanel.figure.hidden = !$("show-exact").checked; });
  $("layout").addEventListener("change", layoutSplit);
  $("split").addEventListener("input", layoutSplit);
  $("reset").addEventListener("click", resetAll);
  previewDrags();
}

// Drag on an image rotates the lighting: x → yaw, y → pitch (0.5° a pixel).
function dragRotates(el) {
  let last = null;
  let moving = false;
  el.addEventListener("pointerdown", (e) => {
    moving = e.shiftKey && $("area").checked;
    if (!e.shiftKey || moving) { last = [e.clientX, e.clientY]; el.setPointerCapture(e.pointerId); }
  });
  el.addEventListener("pointermove", (e) => {
    probe(el, e);
    if (!last) return;
    const dx = e.clientX - last[0], dy = e.clientY - last[1];
    last = [e.clientX, e.clientY];
    if (moving) { // shift-drag: the area light along the plane's x and y, 0.01 a pixel
      $("area-x").value = +(Number($("area-x").value) + dx * 0.01).toFixed(3);
      $("area-y").value = +(Number($("area-y").value) + dy * 0.01).toFixed(3);
    } else {
      $("yaw").value = +(angle("yaw") + dx * 0.5).toFixed(2);
      $("pitch").value = +Math.max(-90, Math.min(90, angle("pitch") + dy * 0.5)).toFixed(2);
    }
    requestFrames();
  });
  el.addEventListener("pointerup", () => { last = null; });
}

// Split view: both files in one frame, file 0 left of the divider and file 1
// right of it; drag the divider (or use the slider) to move it.
function layoutSplit() {
  if (panels.length < 2 || !$("split-wrap")) return;
  const split = $("layout").value === "split";
  const wrap = $("split-wrap");
  wrap.style.display = split ? "block" : "none";
  $("split").hidden = !split;
  for (const p of panels.slice(0, 2)) {
    const home = p.gl ? p.figure.querySelector("canvas.gl") : p.canvas;
    if (split && home.parentNode !== wrap) wrap.append(home);
    if (!split && home.parentNode === wrap) p.figure.insertBefore(home, p.figure.firstChild);
    p.figure.hidden = split;
  }
  if (!split) { panels.forEach((p) => { (p.gl ? p.figure.querySelector("canvas.gl") : p.canvas).style.clipPath = ""; }); return; }
  const [a, b] = panels.slice(0, 2).map((p) => (p.gl ? p.figure.querySelector("canvas.gl") : p.canvas));
  const r = a.getBoundingClientRect();
  wrap.style.width = `${r.width}px`;
  wrap.style.height = `${r.height}px`;
  const s = Number($("split").value);
  b.style.clipPath = `inset(0 0 0 ${100 * s}%)`;
  $("split-divider").style.left = `${100 * s}%`;
  const label = (p) => `${info.files[p.index].name} (${info.files[p.index].mode})${pct(p.readout?.error) ? `: ${pct(p.readout.error)}` : ""}`;
  $("split-left").textContent = `◀ ${label(panels[0])}`;
  $("split-right").textContent = `${label(panels[1])} ▶`;
}

function makeSplit() {
  const wrap = document.createElement("div");
  wrap.id = "split-wrap";
  wrap.innerHTML = `<div id="split-divider" title="drag to move the split"></div><span id="split-left" class="split-label"></span><span id="split-right" class="split-label"></span>`;
  $("panels").prepend(wrap);
  $("split").hidden = true;
  const d = $("split-divider");
  let dragging = false;
  d.addEventListener("pointerdown", (e) => { dragging = true; d.setPointerCapture(e.pointerId); e.stopPropagation(); });
  d.addEventListener("pointermove", (e) => {
    if (!dragging) return;
    const r = wrap.getBoundingClientRect();
    $("split").value = Math.min(1, Math.max(0, (e.clientX - r.left) / r.width));
    layoutSplit();
  });
  d.addEventListener("pointerup", () => { dragging = false; });
}

function addPanel(title, index) {
  const fig = document.createElement("figure");
  const canvas = document.createElement("canvas");
  canvas.className = "view";
  canvas.id = index === "exact" ? "exact" : `view${index}`;
  const state = document.createElement("div");
  state.className = "state";
  state.id = index === "exact" ? "state-exact" : `state${index}`;
  const cap = document.createElement("figcaption");
  cap.textContent = title;
  const e = document.createElement("div");
  e.id = index === "exact" ? "error" : `error${index}`;
  e.className = "errval";
  cap.append(document.createElement("br"), e);
  fig.append(canvas, state, cap);
  $("panels").append(fig);
  dragRotates(canvas);
  return {
    index, canvas, state, figure: fig, errorEl: index === "exact" ? null : e, inFlight: false, pending: null, halves: null, decoded: null,
    get floats() { return this.halves ? (this.decoded ??= halvesToFloats(this.halves)) : null; },
  };
}

// --- texture-space files: the mesh in WebGL, with an orbit camera ------------
//
// The server sends what `ltm render` draws (`/api/mesh`: vertices, texture
// coordinates in texel units, triangles, each triangle's reach and fold
// flag) and the texels' surface records (`/api/surface`); the page
// triangulates nothing. The fragment shader does render's lookup: bilinear
// over the four nearest texels that are valid and whose record lies within
// the triangle's reach of the shaded point (never two charts), weights
// renormalized; with none, the valid texel of the 5 × 5 around whose record
// is nearest; fold triangles blend their corners' texels. Exposure, tone
// mapping and the sRGB encoding follow, as toRgba does for flat frames.

async function fetchBinary(url, magic) {
  const r = await fetch(url);
  if (r.status !== 200) throw new Error(`${url}: ${r.status} ${await r.text()}`);
  const buf = await r.arrayBuffer();
  if (String.fromCharCode(...new Uint8Array(buf, 0, 4)) !== magic) throw new Error(`${url}: not ${magic}`);
  const dv = new DataView(buf);
  return { buf, a: dv.getUint32(4, true), b: dv.getUint32(8, true), c: dv.getUint32(12, true) };
}

async function meshPanel(p) {
  const m = await fetchBinary(`/api/mesh?file=${p.index}`, "LTMG");
  const [nv, nt, cull] = [m.a, m.b, m.c === 2];
  let o = 16;
  const take = (Type, n) => { const a = new Type(m.buf.slice(o, o + n * Type.BYTES_PER_ELEMENT)); o += n * Type.BYTES_PER_ELEMENT; return a; };
  const mesh = { pos: take(Float32Array, 3 * nv), uv: take(Float32Array, 2 * nv), tri: take(Uint32Array, 3 * nt), reach: take(Float32Array, nt), folded: take(Uint8Array, nt), cull };
  const s = await fetchBinary(`/api/surface?file=${p.index}`, "LTMS");
  const side = s.a;
  const xyz = new Float32Array(s.buf.slice(16, 16 + side * side * 12));
  const valid = new Uint8Array(s.buf, 16 + side * side * 12, side * side);
  const records = new Float32Array(side * side * 4);
  for (let i = 0; i < side * side; i++) { records.set(xyz.subarray(3 * i, 3 * i + 3), 4 * i); records[4 * i + 3] = valid[i]; }
  const gl_canvas = document.createElement("canvas");
  gl_canvas.className = "gl";
  gl_canvas.id = `gl${p.index}`;
  gl_canvas.width = gl_canvas.height = 512;
  p.figure.insertBefore(gl_canvas, p.canvas);
  p.canvas.style.width = "128px";
  p.gl = makeGl(gl_canvas, side, mesh, records);
}

const MESH_VS = `#version 300 es
in vec3 p; in vec2 t; in vec3 b; in vec2 a0; in vec2 a1; in vec2 a2; in float r; in float fo;
uniform mat4 m;
out vec3 vp; out vec2 vt; out vec3 vb;
flat out vec2 c0; flat out vec2 c1; flat out vec2 c2; flat out float reach; flat out float folded;
void main() { vp = p; vt = t; vb = b; c0 = a0; c1 = a1; c2 = a2; reach = r; folded = fo; gl_Position = m * vec4(p, 1.0); }`;

const MESH_FS = `#version 300 es
precision highp float; precision highp int; precision highp sampler2D;
in vec3 vp; in vec2 vt; in vec3 vb;
flat in vec2 c0; flat in vec2 c1; flat in vec2 c2; flat in float reach; flat in float folded;
uniform sampler2D tex; uniform sampler2D rec; uniform int side; uniform float scale; uniform bool reinhard;
out vec4 o;
ivec2 texelAt(vec2 q) { return clamp(ivec2(floor(q)), ivec2(0), ivec2(side - 1)); }
vec3 texel(ivec2 k) { return texelFetch(tex, k, 0).rgb; }
float chartWeight(ivec2 k, vec3 p) {
  vec4 r = texelFetch(rec, k, 0);
  if (r.w < 0.5) return 0.0;
  if (reach < 0.0) return 1.0;
  return clamp((2.0 * reach - distance(r.xyz, p)) / reach, 0.0, 1.0);
}
vec3 fallback(vec2 q, vec3 p) {
  ivec2 c = texelAt(q), best = c;
  float bd = -1.0;
  for (int dy = -2; dy <= 2; dy++) for (int dx = -2; dx <= 2; dx++) {
    ivec2 k = c + ivec2(dx, dy);
    if (any(lessThan(k, ivec2(0))) || any(greaterThan(k, ivec2(side - 1)))) continue;
    vec4 r = texelFetch(rec, k, 0);
    vec3 d = r.xyz - p;
    float dd = dot(d, d);
    if (r.w > 0.5 && (bd < 0.0 || dd < bd)) { bd = dd; best = k; }
  }
  return texel(best);
}
vec3 lookup(vec2 q, vec3 p) {
  vec2 g = q - 0.5, g0 = floor(g), f = g - g0;
  ivec2 b = ivec2(g0);
  vec3 acc = vec3(0.0);
  float ws = 0.0;
  for (int i = 0; i < 4; i++) {
    ivec2 d = ivec2(i & 1, i >> 1);
    float w = (d.x == 1 ? f.x : 1.0 - f.x) * (d.y == 1 ? f.y : 1.0 - f.y);
    ivec2 k = clamp(b + d, ivec2(0), ivec2(side - 1));
    w *= chartWeight(k, p);
    if (w > 0.0) { acc += w * texel(k); ws += w; }
  }
  return ws > 0.0 ? acc / ws : fallback(q, p);
}
void main() {
  vec3 c = folded > 0.5 ? vb.x * texel(texelAt(c0)) + vb.y * texel(texelAt(c1)) + vb.z * texel(texelAt(c2)) : lookup(vt, vp);
  c *= scale;
  if (reinhard) c = c / (1.0 + c);
  c = clamp(c, 0.0, 1.0);
  o = vec4(mix(12.92 * c, 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055, step(vec3(0.0031308), c)), 1.0);
}`;

// Each triangle gets its own three vertices: the fold flag, the reach and
// the corners' texture coordinates are per triangle.
function triangleSoup(mesh) {
  const nt = mesh.reach.length, n = 3 * nt;
  const a = { p: new Float32Array(3 * n), t: new Float32Array(2 * n), b: new Float32Array(3 * n), a0: new Float32Array(2 * n),
    a1: new Float32Array(2 * n), a2: new Float32Array(2 * n), r: new Float32Array(n), fo: new Float32Array(n) };
  for (let i = 0; i < nt; i++) {
    const c = [mesh.tri[3 * i], mesh.tri[3 * i + 1], mesh.tri[3 * i + 2]];
    const reach = Number.isFinite(mesh.reach[i]) ? mesh.reach[i] : -1;
    for (let j = 0; j < 3; j++) {
      const v = 3 * i + j;
      a.p.set(mesh.pos.subarray(3 * c[j], 3 * c[j] + 3), 3 * v);
      a.t.set(mesh.uv.subarray(2 * c[j], 2 * c[j] + 2), 2 * v);
      a.b[3 * v + j] = 1;
      for (const [k, name] of ["a0", "a1", "a2"].entries()) a[name].set(mesh.uv.subarray(2 * c[k], 2 * c[k] + 2), 2 * v);
      a.r[v] = reach;
      a.fo[v] = mesh.folded[i];
    }
  }
  return a;
}

function makeGl(canvas, side, mesh, records) {
  // No multisampling: the pixels are render's (`--supersample 1`).
  const gl = canvas.getContext("webgl2", { antialias: false });
  if (!gl) throw new Error("WebGL 2 is needed for texture-space files");
  const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
  for (const k of mesh.tri) for (let c = 0; c < 3; c++) { lo[c] = Math.min(lo[c], mesh.pos[3 * k + c]); hi[c] = Math.max(hi[c], mesh.pos[3 * k + c]); }
  const center = lo.map((l, c) => (l + hi[c]) / 2);
  const radius = Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]) / 2 || 1;
  const prog = program(gl, MESH_VS, MESH_FS);
  const soup = triangleSoup(mesh);
  const sizes = { p: 3, t: 2, b: 3, a0: 2, a1: 2, a2: 2, r: 1, fo: 1 };
  for (const [name, n] of Object.entries(sizes)) {
    const b = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, b);
    gl.bufferData(gl.ARRAY_BUFFER, soup[name], gl.STATIC_DRAW);
    const l = gl.getAttribLocation(prog, name);
    gl.enableVertexAttribArray(l);
    gl.vertexAttribPointer(l, n, gl.FLOAT, false, 0, 0);
  }
  // Binds texture unit `unit` to `t` (a new texture when null) and fills it.
  const texture = (unit, t, w, h, data) => {
    t = t || gl.createTexture();
    gl.activeTexture(gl.TEXTURE0 + unit);
    gl.bindTexture(gl.TEXTURE_2D, t);
    for (const [k, v] of [[gl.TEXTURE_MIN_FILTER, gl.NEAREST], [gl.TEXTURE_MAG_FILTER, gl.NEAREST], [gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE], [gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE]]) gl.texParameteri(gl.TEXTURE_2D, k, v);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA32F, w, h, 0, gl.RGBA, gl.FLOAT, data);
    return t;
  };
  gl.pixelStorei(gl.UNPACK_ALIGNMENT, 1);
  texture(1, null, side, side, records);
  let tex = null;
  const u = (name) => gl.getUniformLocation(prog, name);
  gl.uniform1i(u("tex"), 0); gl.uniform1i(u("rec"), 1); gl.uniform1i(u("side"), side);
  gl.enable(gl.DEPTH_TEST);
  // As ltm render: a stored mesh's back faces are not drawn (fronts are
  // counter-clockwise, WebGL's default front face).
  if (mesh.cull) { gl.enable(gl.CULL_FACE); gl.cullFace(gl.BACK); }
  const count = soup.r.length;
  canvas.dataset.triangles = count / 3;
  const cam = { az: 0.6, el: 0.3, dist: 3 * radius, fovy: 0.6 };
  const eyeOf = () => [center[0] + cam.dist * Math.cos(cam.el) * Math.sin(cam.az), center[1] + cam.dist * Math.sin(cam.el), center[2] + cam.dist * Math.cos(cam.el) * Math.cos(cam.az)];
  const render = () => {
    const eye = eyeOf();
    // The camera, as `ltm render --camera --target --up 0,1,0 --fov` takes it.
    canvas.dataset.camera = JSON.stringify({ eye, target: center, fov: cam.fovy * 180 / Math.PI });
    gl.viewport(0, 0, canvas.width, canvas.height);
    gl.clearColor(0, 0, 0, 1);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    if (!tex) return;
    gl.uniformMatrix4fv(u("m"), false, mul(perspective(cam.fovy, canvas.width / canvas.height, radius * 0.05, cam.dist + 4 * radius), lookAt(eye, center)));
    gl.drawArrays(gl.TRIANGLES, 0, count);
  };
  let last = null;
  canvas.addEventListener("pointerdown", (e) => { last = [e.clientX, e.clientY]; canvas.setPointerCapture(e.pointerId); });
  canvas.addEventListener("pointermove", (e) => {
    if (!last) return;
    cam.az -= (e.clientX - last[0]) * 0.01;
    cam.el = Math.max(-1.5, Math.min(1.5, cam.el + (e.clientY - last[1]) * 0.01));
    last = [e.clientX, e.clientY];
    moved();
  });
  canvas.addEventListener("pointerup", () => { last = null; });
  canvas.addEventListener("wheel", (e) => { e.preventDefault(); cam.dist *= Math.exp(e.deltaY * 0.001); moved(); });
  // The baked material needs no new relight when the camera moves; a
  // glossy one is shaded from the eye, so it asks for a frame (step 2).
  const moved = () => { render(); if (Number($("brdf").value || 0)) requestFrames(); };
  render();
  return {
    eye: eyeOf,
    // floats: the relit texture (linear RGB), rgba: its tone-mapped pixels.
    setTexture(floats, rgba, w, h) {
      const data = new Float32Array(w * h * 4);
      for (let i = 0; i < w * h; i++) { data.set(floats.subarray(3 * i, 3 * i + 3), 4 * i); data[4 * i + 3] = 1; }
      tex = texture(0, tex, w, h, data);
      gl.uniform1f(u("scale"), Math.fround(Math.pow(2, ev())));
      gl.uniform1i(u("reinhard"), $("tonemap").value === "reinhard" ? 1 : 0);
      render();
      // Keep the flat texture too, small, beside the mesh.
      const c = canvas.nextSibling;
      if (c.width !== w) { c.width = w; c.height = h; }
      c.getContext("2d").putImageData(new ImageData(rgba, w, h), 0, 0);
    },
    // The drawn pixels, RGB, rows top to bottom (for tests).
    pixels() {
      render();
      const w = canvas.width, h = canvas.height, px = new Uint8Array(w * h * 4);
      gl.readPixels(0, 0, w, h, gl.RGBA, gl.UNSIGNED_BYTE, px);
      const out = new Uint8Array(w * h * 3);
      for (let y = 0; y < h; y++) for (let x = 0; x < w; x++) for (let c = 0; c < 3; c++) out[3 * (y * w + x) + c] = px[4 * ((h - 1 - y) * w + x) + c];
      return out;
    },
  };
}

function program(gl, vs, fs) {
  const p = gl.createProgram();
  for (const [type, src] of [[gl.VERTEX_SHADER, vs], [gl.FRAGMENT_SHADER, fs]]) {
    const s = gl.createShader(type);
    gl.shaderSource(s, src); gl.compileShader(s);
    if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
    gl.attachShader(p, s);
  }
  gl.linkProgram(p); gl.useProgram(p);
  return p;
}

function perspective(fovy, aspect, near, far) {
  const f = 1 / Math.tan(fovy / 2), nf = 1 / (near - far);
  return [f / aspect, 0, 0, 0, 0, f, 0, 0, 0, 0, (far + near) * nf, -1, 0, 0, 2 * far * near * nf, 0];
}

function lookAt(eye, at) {
  const sub = (a, b) => a.map((v, i) => v - b[i]);
  const norm = (a) => { const l = Math.hypot(...a) || 1; return a.map((v) => v / l); };
  const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  const z = norm(sub(eye, at)), x = norm(cross([0, 1, 0], z)), y = cross(z, x);
  return [x[0], y[0], z[0], 0, x[1], y[1], z[1], 0, x[2], y[2], z[2], 0, -dot(x, eye), -dot(y, eye), -dot(z, eye), 1];
}

function mul(a, b) { // column-major 4×4: a·b
  const o = new Array(16).fill(0);
  for (let c = 0; c < 4; c++) for (let r = 0; r < 4; r++) for (let k = 0; k < 4; k++) o[4 * c + r] += a[4 * k + r] * b[4 * c + k];
  return o;
}

// --- start ------------------------------------------------------------------

async function start() {
  info = await (await fetch("/api/info")).json();
  info.maps.forEach((m, i) => $("map").add(new Option(`${m.name} (${m.width}×${m.height})`, i)));
  info.weightings.forEach((w) => $("weighting").add(new Option(w, w)));
  // Transport weighting by default: half the error of unweighted at the same N.
  if (info.weightings.includes("transport")) $("weighting").value = "transport";
  const maxes = new Set(info.files.map((f) => f.max_terms));
  if (maxes.size === 1) addNGroup(info.files.map((_, i) => i), "N");
  else info.files.forEach((f, i) => addNGroup([i], `N (${f.name})`));
  for (const [i, f] of info.files.entries()) {
    const p = addPanel(`${f.name}: ${f.mode}, ${fmt(f.bytes)}, matrix error ${(100 * f.matrix_error).toFixed(3)} %, ${f.width}×${f.height} ${f.layout}`, i);
    panels.push(p);
    if (f.layout === "texture") await meshPanel(p).catch((e) => message(String(e)));
  }
  if (panels.length >= 2) {
    $("layout-label").hidden = false;
    makeSplit();
  }
  if (info.files.some((f) => f.near_field)) {
    $("area-row").hidden = false;
    info.area_textures.forEach((t, i) => $("area-texture").add(new Option(t, i)));
  }
  if (info.brdfs.length && info.files.some((f) => f.layout === "texture" || f.eye)) {
    $("brdf-label").hidden = false;
    $("brdf").add(new Option("baked", 0));
    info.brdfs.forEach((b, i) => $("brdf").add(new Option(b, i + 1)));
  }
  if (info.reference) {
    $("exact-label").hidden = false;
    $("display-label").hidden = false;
    exactPanel = addPanel(`exact T·L from ${info.reference}`, "exact");
  }
  wireControls();
  readouts();
  requestFrames();
}

start().catch((e) => message(`start: ${e}`));
