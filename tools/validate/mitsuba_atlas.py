#!/usr/bin/env python3
"""Geometry relighting of meshes that are hard for one chart, atlas and
sphere layouts, against Mitsuba 3 (issue 30's Checks).

For each case (a mesh made here, a mesh of assets/, or a scene of several
objects on a floor baked as one atlas with `mesh = "all"`) ltm bakes the
texture-space matrix with `parameterization = "atlas"` and with
`"sphere"` (which only takes one closed genus-0 mesh: its refusal is
reported as n/a with ltm's message), compresses it near-losslessly and
draws it with `ltm render --terms all` from three cameras. Mitsuba 3
renders the same scene with its `direct` integrator under the same
piecewise-constant cubemap lighting (mitsuba_texture.py holds the scene
and lighting code; this script imports it).

Per view:
- shading: relative L2 over Mitsuba's pixels more than 1 px from a
  silhouette (wholly covered, as are their 8 neighbours), and the same with
  Mitsuba's noise (two seeds) removed in quadrature;
- shape: the object masks are the pixels that any sample covers (Mitsuba:
  4x4 stratified rays against the receivers only; ltm: a non-zero pixel of
  `ltm render`, whose background is 0). "missing" is the share of the
  pixels at least 2 px inside Mitsuba's mask (5x5 erosion) that ltm leaves
  empty, "extra" the share of ltm's 2-px-eroded mask outside Mitsuba's,
  both as fractions of Mitsuba's eroded mask (target <= 0.5 % each);
  IoU of the two masks.

Cases: figure (body, head, four limbs, three fingers per hand: separate
interpenetrating closed parts), knot (a (2,3) torus-knot tube, genus 1),
halfpipe (an open surface), bunny, fandisk (assets/meshes), scene (figure,
knot, a sphere and a box on a 3x3 floor, mesh = "all").

`--fixtures DIR` also writes, for camera 0 of each case, what
tools/tests/slow/atlas_mitsuba.rs reads (see tools/tests/fixtures/atlas_mitsuba/
README.md for the command that made them).

Usage:
  cargo build --release -p ltm-tools
  pip install mitsuba numpy
  python3 tools/validate/mitsuba_atlas.py --out /tmp/ltm-atlas
"""

import argparse
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.normpath(os.path.join(HERE, "..", ".."))
sys.path.insert(0, HERE)
import mitsuba_compare as mc  # noqa: E402
import mitsuba_texture as mt  # noqa: E402

CASES = ["figure", "knot", "halfpipe", "bunny", "fandisk", "scene"]
LAYOUTS = ["atlas", "sphere"]
# Directions from the target to the three cameras (mitsuba_texture's).
CAMERA_DIRS = [np.array(c["eye"]) - np.array(c["target"]) for c in mt.DEFAULT_CAMERAS]


# ------------------------------------------------------------------ meshes

def ellipsoid(center, axis, half_length, radius, nu=24, nv=12):
    """A closed lat-long ellipsoid: `half_length` along `axis`, `radius`
    across, with a vertex at each pole."""
    axis = np.asarray(axis, float)
    axis /= np.linalg.norm(axis)
    other = np.array([1.0, 0, 0]) if abs(axis[0]) < 0.9 else np.array([0, 0, 1.0])
    e1 = np.cross(axis, other)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    v = [np.asarray(center) + half_length * axis, np.asarray(center) - half_length * axis]
    for i in range(1, nv):
        th = math.pi * i / nv
        for j in range(nu):
            ph = 2 * math.pi * j / nu
            v.append(np.asarray(center) + half_length * math.cos(th) * axis
                     + radius * math.sin(th) * (math.cos(ph) * e1 + math.sin(ph) * e2))
    ring = lambda i, j: 2 + (i - 1) * nu + j % nu  # noqa: E731
    f = []
    for j in range(nu):
        f.append([0, ring(1, j), ring(1, j + 1)])
        f.append([1, ring(nv - 1, j + 1), ring(nv - 1, j)])
    for i in range(1, nv - 1):
        for j in range(nu):
            a, b, c, d = ring(i, j), ring(i, j + 1), ring(i + 1, j), ring(i + 1, j + 1)
            f += [[a, c, b], [b, c, d]]
    return np.array(v), np.array(f)


def merge(parts):
    vs, fs, base = [], [], 0
    for v, f in parts:
        vs.append(v)
        fs.append(f + base)
        base += len(v)
    return np.concatenate(vs), np.concatenate(fs)


def figure_mesh():
    """A standing figure about 1.1 tall: body, head, two arms and two legs
    (thin ellipsoids), three fingers on each hand; separate closed parts
    that interpenetrate."""
    parts = [ellipsoid([0, 0.68, 0], [0, 1, 0], 0.24, 0.15),
             ellipsoid([0, 1.02, 0], [0, 1, 0], 0.1, 0.09)]
    for s in (-1, 1):
        parts.append(ellipsoid([s * 0.07, 0.25, 0], [s * 0.1, 1, 0], 0.26, 0.045))
        shoulder = np.array([s * 0.12, 0.85, 0.0])
        d = np.array([s * 1.0, -0.55, 0.15])
        d /= np.linalg.norm(d)
        parts.append(ellipsoid(shoulder + 0.2 * d, d, 0.21, 0.035))
        hand = shoulder + 0.41 * d
        for k, spread in enumerate((-0.5, 0.0, 0.5)):
            fd = d + np.array([0, spread, 0.3 * spread])
            fd /= np.linalg.norm(fd)
            parts.append(ellipsoid(hand + 0.06 * fd, fd, 0.065, 0.014, nu=10, nv=6))
    return merge(parts)


def torus_knot_mesh(p=2, q=3, n=240, m=14, scale=0.17, tube=0.055):
    """A (p, q) torus-knot tube standing in the x-y plane: closed, genus 1.
    The tube's frame is transported along the curve and its closing twist
    spread over the loop."""
    t = 2 * math.pi * np.arange(n) / n
    r = np.cos(q * t) + 2
    c = scale * np.stack([r * np.cos(p * t), r * np.sin(p * t), -np.sin(q * t)], -1)
    tan = np.roll(c, -1, 0) - np.roll(c, 1, 0)
    tan /= np.linalg.norm(tan, axis=1, keepdims=True)
    nrm = np.zeros_like(c)
    a = np.cross(tan[0], [0.0, 0.0, 1.0])
    nrm[0] = a / np.linalg.norm(a)
    for i in range(1, n):
        a = nrm[i - 1] - tan[i] * (nrm[i - 1] @ tan[i])
        nrm[i] = a / np.linalg.norm(a)
    # Closing twist between the transported frame and the first one.
    last = nrm[-1] - tan[0] * (nrm[-1] @ tan[0])
    last /= np.linalg.norm(last)
    twist = math.atan2(np.cross(last, nrm[0]) @ tan[0], last @ nrm[0])
    v = []
    for i in range(n):
        b = np.cross(tan[i], nrm[i])
        ang0 = twist * i / n
        for j in range(m):
            ang = ang0 + 2 * math.pi * j / m
            v.append(c[i] + tube * (math.cos(ang) * nrm[i] + math.sin(ang) * b))
    f = []
    for i in range(n):
        for j in range(m):
            a0, a1 = i * m + j, i * m + (j + 1) % m
            b0, b1 = ((i + 1) % n) * m + j, ((i + 1) % n) * m + (j + 1) % m
            f += [[a0, a1, b0], [a1, b1, b0]]  # outward
    return np.array(v), np.array(f)


def halfpipe_mesh(nu=40, nz=16, radius=0.45, half=0.5):
    """An open half-pipe (a U-shaped sheet), its lowest line just above y = 0."""
    v = []
    for i in range(nu + 1):
        th = math.pi * i / nu
        for k in range(nz + 1):
            z = -half + 2 * half * k / nz
            v.append([radius * math.cos(th), radius * (1 - math.sin(th)) + 0.02, z])
    f = []
    for i in range(nu):
        for k in range(nz):
            a, b = i * (nz + 1) + k, (i + 1) * (nz + 1) + k
            f += [[a, b, a + 1], [a + 1, b, b + 1]]
    return np.array(v, float), np.array(f)


def box_mesh(half):
    h = np.asarray(half, float)
    v = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float) * h
    f = [[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
         [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]]
    return v, np.array(f)


def placed(name, path, v, scale=1.0, at=(0.0, 0.0)):
    """An object dict (mitsuba_texture's) standing on y = 0 at x, z = at."""
    lo, hi = v.min(0) * scale, v.max(0) * scale
    tr = [at[0] - (lo[0] + hi[0]) / 2, -lo[1], at[1] - (lo[2] + hi[2]) / 2]
    return dict(name=name, path=path, scale=float(scale), translation=[float(x) for x in tr],
                lo=(lo + tr).tolist(), hi=(hi + tr).tolist())


def ply_vertices(mi, path):
    shape = mi.load_dict({"type": "ply", "filename": path})
    return np.array(shape.vertex_positions_buffer(), dtype=np.float64).reshape(-1, 3)


def case_setup(mi, name, out):
    """(objects, ground side, receiver: 0 or "all") of a case. Meshes made
    here are written as OBJ files to `out`."""
    def obj(stem, vf, **kw):
        path = os.path.join(out, f"{stem}.obj")
        mt.write_obj(path, *vf)
        return placed(stem, path, vf[0], **kw)
    if name == "figure":
        return [obj("figure", figure_mesh())], 8.0, 0
    if name == "knot":
        return [obj("knot", torus_knot_mesh())], 8.0, 0
    if name == "halfpipe":
        return [obj("halfpipe", halfpipe_mesh())], 8.0, 0
    if name in ("bunny", "fandisk"):
        path = os.path.join(ROOT, f"assets/meshes/{name}.ply")
        v = ply_vertices(mi, path)
        ext = v.max(0) - v.min(0)
        return [placed(name, path, v, scale=1.0 / ext.max())], 8.0, 0
    if name == "scene":
        objs = [obj("scene_figure", figure_mesh(), scale=0.7, at=(0.1, -0.55)),
                obj("scene_knot", torus_knot_mesh(), scale=0.7, at=(-0.65, 0.3)),
                obj("scene_sphere", mt.icosphere(3), scale=0.25, at=(0.65, 0.25)),
                obj("scene_box", box_mesh([0.18, 0.12, 0.22]), at=(0.0, 0.6))]
        return objs, 3.0, "all"
    sys.exit(f"unknown case {name}")


def cameras(objects, ground, receiver, fov=28.0):
    """Three cameras looking at the receivers' bounding box centre from
    mitsuba_texture's three directions, at a distance that frames it (the
    objects': a scene's floor runs past the frame)."""
    lo = np.min([o["lo"] for o in objects], 0)
    hi = np.max([o["hi"] for o in objects], 0)
    centre = (lo + hi) / 2
    radius = np.linalg.norm(hi - lo) / 2
    dist = 1.05 * radius / math.sin(math.radians(fov / 2))
    out = []
    for d in CAMERA_DIRS:
        eye = centre + dist * d / np.linalg.norm(d)
        out.append(dict(eye=[round(float(x), 4) for x in eye],
                        target=[round(float(x), 4) for x in centre], fov=fov))
    return out


# ----------------------------------------------------------------- metrics

def erode(mask, r):
    """Pixels whose (2r+1)^2 neighbourhood lies wholly in `mask`."""
    pad = np.pad(mask, r)
    out = mask.copy()
    h, w = mask.shape
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            out &= pad[r + dy:r + dy + h, r + dx:r + dx + w]
    return out


def shape_metrics(ours, cov):
    """missing, extra (fractions of Mitsuba's 2-px-eroded mask) and IoU."""
    ref_mask = cov > 0
    our_mask = ours.sum(-1) > 0
    inner = erode(ref_mask, 2)
    n = max(int(inner.sum()), 1)
    missing = float((inner & ~our_mask).sum() / n)
    extra = float((erode(our_mask, 2) & ~ref_mask).sum() / n)
    iou = float((ref_mask & our_mask).sum() / max((ref_mask | our_mask).sum(), 1))
    return missing, extra, iou


def mitsuba_noise(ref, ref2, mask, ratio):
    """The relative noise of `ref` from a second render `ref2` with another
    seed and spp(ref) / spp(ref2) = ratio: independent errors add in
    quadrature, |ref2 - ref|^2 = (1 + ratio) noise(ref)^2."""
    return mt.rel(ref2, ref, mask) / math.sqrt(1 + ratio)


def shading_metrics(ours, ref, ref2, cov, ratio):
    mask = mt.interior(cov)
    e = mt.rel(ours, ref, mask)
    noise = mitsuba_noise(ref, ref2, mask, ratio)
    return e, noise, math.sqrt(max(e * e - noise * noise, 0.0)), int(mask.sum())


# -------------------------------------------------------------------- main

def run(cmd):
    """(ok, seconds, stdout + stderr)."""
    t0 = time.time()
    p = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    return p.returncode == 0, time.time() - t0, p.stdout


def render_args(ltm, file, env, cam, width, out):
    return [ltm, "render", file, "--env", env, "--terms", "all",
            "--camera", ",".join(map(str, cam["eye"])),
            "--target", ",".join(map(str, cam["target"])),
            "--fov", str(cam["fov"]), "--size", f"{width}x{width}",
            "--supersample", "8", "-o", out]


def bake(args, objects, ground, receiver, cam, layout, out, n):
    """Bakes and compresses one layout: (ltm file or None, figures dict)."""
    texture = dict(size=args.size, parameterization=layout, spp=args.texel_spp,
                   mesh=receiver)
    toml = mt.scene_toml_objects(objects, cam, args.width, n, args.texel_samples, 1,
                                 True, texture, ground_size=ground)
    scene = os.path.join(out, f"{layout}.toml")
    with open(scene, "w") as f:
        f.write(toml)
    raw, ltm = os.path.join(out, f"{layout}.raw"), os.path.join(out, f"{layout}.ltm")
    ok, bake_s, log = run([args.ltm, "bake", scene, "-o", raw])
    with open(os.path.join(out, f"{layout}_bake.log"), "w") as f:
        f.write(log)
    if not ok:
        lines = [ln for ln in log.strip().splitlines() if ln.strip()]
        return None, dict(error=lines[-1] if lines else "bake failed", bake_s=bake_s)
    figures = [ln.strip() for ln in log.splitlines()
               if any(k in ln.lower() for k in ("atlas", "chart", "stretch", "texels per"))]
    ok, _, log = run([args.ltm, "compress", raw, "-o", ltm, "--bits", "16",
                      "--max-error", "0.001"])
    os.remove(raw)
    if not ok:
        return None, dict(error="compress: " + log.strip().splitlines()[-1], bake_s=bake_s)
    return ltm, dict(bake_s=bake_s, figures=figures, toml=scene)


def reference(mi, args, objects, ground, receiver, receivers, cam, env, stem):
    """Mitsuba's render at --spp, a second one at --spp2 (another seed: the
    noise), and the receivers' coverage; kept as STEM_*.npy and read back
    when a run with the same settings finds them."""
    key = json.dumps(dict(cam=cam, spp=args.spp, spp2=args.spp2, width=args.width,
                          env=args.env, n=args.face_res, h=args.env_height,
                          objects=[(o["path"], o["scale"], o["translation"]) for o in objects]))
    try:
        with open(stem + "_key.json") as f:
            if f.read() == key:
                return (np.load(stem + "_mitsuba.npy").astype(np.float64),
                        np.load(stem + "_mitsuba2.npy").astype(np.float64),
                        np.load(stem + "_coverage.npy").astype(np.float64))
    except OSError:
        pass
    sc = mi.load_dict(mt.mitsuba_dict_objects(mi, objects, cam, args.width, env, args.spp,
                                              True, ground))
    ref = np.array(mi.render(sc, seed=1, spp=args.spp), dtype=np.float64)[..., :3]
    ref2 = np.array(mi.render(sc, seed=2, spp=args.spp2), dtype=np.float64)[..., :3]
    cov = mt.coverage_render(mi, receivers, cam, args.width,
                             ground_size=ground if receiver == "all" else None)
    np.save(stem + "_mitsuba.npy", ref.astype(np.float32))
    np.save(stem + "_mitsuba2.npy", ref2.astype(np.float32))
    np.save(stem + "_coverage.npy", cov.astype(np.float32))
    with open(stem + "_key.json", "w") as f:
        f.write(key)
    peak = np.percentile(ref[cov > 0], 99.5)
    mc.save_png(stem + "_mitsuba.png", ref / peak)
    return ref, ref2, cov


def write_fixture(args, mi, dest, case, objects, ground, receiver, cam, ref, ref2, cov,
                  env_path, light, n, noise):
    """What tools/tests/slow/atlas_mitsuba.rs reads, for camera `cam`."""
    os.makedirs(dest, exist_ok=True)
    local = []
    for o in objects:
        if o["path"].startswith(ROOT + os.sep + "assets"):
            rel = os.path.relpath(o["path"], dest)
        else:
            rel = os.path.basename(o["path"])
            shutil.copy(o["path"], os.path.join(dest, rel))
        local.append(dict(o, path=rel))
    texture = dict(size=args.size, parameterization="atlas", spp=args.texel_spp,
                   mesh=receiver)
    with open(os.path.join(dest, "scene.toml"), "w") as f:
        f.write(mt.scene_toml_objects(local, cam, args.width, n, args.texel_samples, 1,
                                      True, texture, ground_size=ground))
    shutil.copy(env_path, os.path.join(dest, "env.exr"))
    np.save(os.path.join(dest, "light.npy"), light.astype(np.float32))
    np.save(os.path.join(dest, "mitsuba.npy"), ref.astype(np.float32))
    np.save(os.path.join(dest, "coverage.npy"), cov.astype(np.float32))
    meta = dict(case=case, camera=cam, width=args.width, mitsuba_spp=args.spp,
                mitsuba_version=mi.__version__, variant=args.variant, face_res=n,
                mitsuba_noise=noise, shading_limit=args.shading_limit)
    with open(os.path.join(dest, "meta.json"), "w") as f:
        json.dump(meta, f, indent=2)


def pct(x):
    return "–" if x is None else f"{100 * x:.2f} %"


def table(results):
    rows = ["| mesh | layout | camera | shading (noise removed) | Mitsuba noise | missing "
            "| extra | IoU | bake s | render s |",
            "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in results:
        if "error" in r:
            rows.append(f"| {r['case']} | {r['layout']} | – | n/a: {r['error']} | | | | | "
                        f"{r['bake_s']:.1f} | |")
            continue
        rows.append(
            f"| {r['case']} | {r['layout']} | {r['camera']} | {pct(r['rel_l2'])} "
            f"({pct(r['rel_l2_noise_removed'])}) | {pct(r['mitsuba_noise'])} | "
            f"{pct(r['missing'])} | {pct(r['extra'])} | {r['iou']:.4f} | "
            f"{r['bake_s']:.1f} | {r['render_s']:.2f} |")
    return "\n".join(rows) + "\n"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--layouts", default=",".join(LAYOUTS))
    ap.add_argument("--env", default=os.path.join(ROOT, "assets/envmaps/courtyard.exr"))
    ap.add_argument("--ltm", default=os.path.join(ROOT, "target/release/ltm"))
    ap.add_argument("--size", type=int, default=128, help="texture side S")
    ap.add_argument("--texel-spp", type=int, default=4)
    ap.add_argument("--face-res", type=int, default=8)
    ap.add_argument("--texel-samples", type=int, default=2)
    ap.add_argument("--width", type=int, default=128, help="view side in pixels")
    ap.add_argument("--cameras", type=int, default=3)
    ap.add_argument("--spp", type=int, default=2048, help="Mitsuba samples per pixel")
    ap.add_argument("--spp2", type=int, default=512,
                    help="samples per pixel of Mitsuba's second render (the noise estimate)")
    ap.add_argument("--references-only", action="store_true",
                    help="render (and keep) Mitsuba's images only")
    ap.add_argument("--env-height", type=int, default=1024)
    ap.add_argument("--variant", default="scalar_rgb")
    ap.add_argument("--out", default=None)
    ap.add_argument("--fixtures", default=None,
                    help="write camera 0 of each case as a test fixture under DIR/CASE")
    ap.add_argument("--shading-limit", type=float, default=0.03)
    ap.add_argument("--shape-limit", type=float, default=0.005)
    args = ap.parse_args()

    import mitsuba as mi
    mi.set_variant(args.variant)
    out = args.out or tempfile.mkdtemp(prefix="ltm-mitsuba-atlas-")
    os.makedirs(out, exist_ok=True)
    n = args.face_res
    mt.check_faces(n)
    src = np.maximum(np.array(mi.Bitmap(args.env)), 0.0)[..., :3].astype(np.float64)
    light = mc.texel_radiance(src, n, 16)
    env = mt.latlong_from_cubemap(light, n, args.env_height)
    env_path = os.path.join(out, "env.exr")
    mi.Bitmap(env.astype(np.float32)).write(env_path)
    env_diff = float(np.linalg.norm(mc.texel_radiance(env, n, 8) - light)
                     / np.linalg.norm(light))

    results = []
    for case in args.cases.split(","):
        cdir = os.path.join(out, case)
        os.makedirs(cdir, exist_ok=True)
        objects, ground, receiver = case_setup(mi, case, cdir)
        receivers = objects if receiver == "all" else [objects[receiver]]
        cams = cameras(receivers, ground, receiver)[:args.cameras]
        refs = []
        for c, cam in enumerate(cams):
            refs.append(reference(mi, args, objects, ground, receiver, receivers, cam, env,
                                  os.path.join(cdir, f"cam{c}")))
        if args.fixtures:
            ref, ref2, cov = refs[0]
            noise = mitsuba_noise(ref, ref2, mt.interior(cov), args.spp / args.spp2)
            write_fixture(args, mi, os.path.join(args.fixtures, case), case, objects, ground,
                          receiver, cams[0], ref, ref2, cov, env_path, light, n, noise)
        if args.references_only:
            continue
        for layout in args.layouts.split(","):
            ltm, info = bake(args, objects, ground, receiver, cams[0], layout,
                             cdir, n)
            if ltm is None:
                r = dict(case=case, layout=layout, **info)
                print(json.dumps(r), flush=True)
                results.append(r)
                continue
            for c, cam in enumerate(cams):
                ref, ref2, cov = refs[c]
                view = os.path.join(cdir, f"cam{c}_{layout}.exr")
                ok, render_s, log = run(render_args(args.ltm, ltm, env_path, cam, args.width,
                                                    view))
                if not ok:
                    sys.exit(f"ltm render failed: {log}")
                ours = mt.read_exr(mi, view)
                e, noise, e0, pixels = shading_metrics(ours, ref, ref2, cov, args.spp / args.spp2)
                missing, extra, iou = shape_metrics(ours, cov)
                r = dict(case=case, layout=layout, camera=c, eye=cam["eye"],
                         target=cam["target"], pixels=pixels, rel_l2=e, mitsuba_noise=noise,
                         rel_l2_noise_removed=e0, missing=missing, extra=extra, iou=iou,
                         bake_s=info["bake_s"], render_s=render_s,
                         atlas=info["figures"])
                print(json.dumps({k: v for k, v in r.items() if k != "atlas"}), flush=True)
                results.append(r)
                peak = np.percentile(ref[cov > 0], 99.5)
                mc.save_png(os.path.join(cdir, f"cam{c}_{layout}.png"), ours / peak)
                diff = np.abs(ours - ref).sum(-1) / peak * mt.interior(cov)
                mc.save_png(os.path.join(cdir, f"cam{c}_{layout}_absdiff_x10.png"),
                            np.repeat(np.clip(10 * diff, 0, 1)[..., None], 3, -1))

    summary = dict(mitsuba_version=mi.__version__, variant=args.variant, spp=args.spp,
                   size=args.size, texel_spp=args.texel_spp, face_res=n,
                   texel_samples=args.texel_samples, width=args.width,
                   env=os.path.relpath(args.env, ROOT), env_height=args.env_height,
                   env_texel_mean_rel_diff=env_diff, results=results)
    with open(os.path.join(out, "summary.json"), "w") as f:
        json.dump(summary, f, indent=2)
    md = table(results)
    with open(os.path.join(out, "table.md"), "w") as f:
        f.write(md)
    print(md)
    print(f"images, summary.json and table.md in {out}")
    atlas = [r for r in results if r["layout"] == "atlas" and "error" not in r]
    fails = [r for r in atlas if r["rel_l2_noise_removed"] > args.shading_limit
             or r["missing"] > args.shape_limit or r["extra"] > args.shape_limit]
    print(("PASS" if not fails and atlas else "FAIL")
          + f": {len(atlas) - len(fails)} of {len(atlas)} atlas views within "
          f"{args.shading_limit:.0%} shading and {args.shape_limit:.1%} shape")
    return 0 if atlas and not fails else 1


if __name__ == "__main__":
    sys.exit(main())
