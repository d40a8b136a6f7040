#!/usr/bin/env python3
"""Check `ltm bake` against Mitsuba 3, an independent renderer.

The scene (Lambertian materials only) is baked with `ltm bake`; the image
B = albedo * (T . L) is formed from the raw store, with L[j] the mean
radiance of cubemap texel j under the environment map; Mitsuba renders the
same scene with the `direct` integrator, lit by the same environment map.
The script prints the relative L2 error ||B_ltm - B_mitsuba|| / ||B_mitsuba||
over all pixels and channels, and Mitsuba's own noise level (from a second
render with another seed).

Conventions matched (and checked where possible):
  * environment map: Mitsuba's `envmap` with the identity transform reads
    direction d at u = atan2(d.x, -d.z) / 2pi, v = acos(d.y) / pi, ltm's
    lat-long convention. Mitsuba interpolates bilinearly with texel centres
    at u = (i + 1/2)/W (wrapping) and rows at v = i/(H - 1); L[j] integrates
    that same interpolant over each texel (checked against Mitsuba's
    `eval` at random directions). Negative pixels are clamped to 0.
  * camera: `perspective`, fov_axis "y", to_world = look_at(eye, target,
    up), box pixel filter (ltm averages its pixel sub-samples uniformly).
  * surfaces: `twosided` `diffuse` (ltm's surfaces are two-sided); meshes
    use `face_normals` when the scene asks for flat shading.
  * units: both are radiance for an environment of radiance L; the
    envmap's `scale` is 1.

Usage:
  cargo build --release -p ltm-tools
  pip install mitsuba numpy
  python3 tools/validate/mitsuba_compare.py [--env assets/envmaps/courtyard.exr ...]
"""

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
import tomllib

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.normpath(os.path.join(HERE, "..", ".."))


# ---------------------------------------------------------------- raw store

def read_raw(path):
    """Memory-maps an ltm raw store (layout: codec/src/raw.rs)."""
    head = np.fromfile(path, dtype=np.uint8, count=64)
    if bytes(head[:8]) != b"LTMRAW\0\x01":
        sys.exit(f"{path}: not an ltm raw store")
    u32 = head[8:40].view("<u4")
    version, flags, width, height, face_res, channels, block_rows, block_count = u32
    data_offset, albedo_offset = head[40:56].view("<u8")
    if version != 1:
        sys.exit(f"{path}: raw store version {version} is not supported")
    p, m = int(width) * int(height), 6 * int(face_res) ** 2
    t = np.memmap(path, dtype="<f4", mode="r", offset=int(data_offset),
                  shape=(p, m, int(channels)))
    albedo = None
    if flags & 1:
        albedo = np.memmap(path, dtype="<f4", mode="r", offset=int(albedo_offset),
                           shape=(p, 3))
    return dict(width=int(width), height=int(height), face_res=int(face_res),
                channels=int(channels), t=t, albedo=albedo)


def relight(raw, light):
    """B = T . L (times the albedo image for grey transport), as H x W x 3."""
    p = raw["width"] * raw["height"]
    out = np.zeros((p, 3))
    chunk = max(1, (256 << 20) // (raw["t"].shape[1] * raw["t"].shape[2] * 4))
    for s in range(0, p, chunk):
        t = np.asarray(raw["t"][s:s + chunk], dtype=np.float64)
        if raw["channels"] == 1:
            out[s:s + chunk] = (t[:, :, 0] @ light) * raw["albedo"][s:s + chunk]
        else:
            out[s:s + chunk] = np.einsum("pjc,jc->pc", t, light)
    return out.reshape(raw["height"], raw["width"], 3)


# ------------------------------------------------------------- environment

def face_point_direction(face, s, t):
    """ltm's cubemap convention (codec/src/cubemap.rs): OpenGL faces."""
    sc, tc = 2.0 * s - 1.0, 2.0 * t - 1.0
    one = np.ones_like(sc)
    d = {
        0: (one, -tc, -sc),
        1: (-one, -tc, sc),
        2: (sc, one, tc),
        3: (sc, -one, -tc),
        4: (sc, -tc, one),
        5: (-sc, -tc, -one),
    }[face]
    d = np.stack(d, axis=-1)
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def env_lookup(env, d):
    """Mitsuba 3's envmap interpolant at unit directions d (..., 3)."""
    h, w, _ = env.shape
    u = np.mod(np.arctan2(d[..., 0], -d[..., 2]) / (2 * np.pi), 1.0)
    v = np.arccos(np.clip(d[..., 1], -1.0, 1.0)) / np.pi
    x = u * w - 0.5
    y = v * (h - 1)
    x0 = np.floor(x).astype(np.int64)
    y0 = np.clip(np.floor(y).astype(np.int64), 0, h - 2)
    fx, fy = (x - x0)[..., None], (y - y0)[..., None]
    x0 %= w
    x1 = (x0 + 1) % w
    return ((1 - fx) * (1 - fy) * env[y0, x0] + fx * (1 - fy) * env[y0, x1]
            + (1 - fx) * fy * env[y0 + 1, x0] + fx * fy * env[y0 + 1, x1])


def texel_radiance(env, n, q):
    """Mean radiance of every cubemap texel: q x q points per texel, weighted
    by the solid-angle density 1/(1 + a^2 + b^2)^(3/2) of the face."""
    k = (np.arange(n * q) + 0.5) / (n * q)
    s, t = np.meshgrid(k, k, indexing="xy")  # t varies along rows
    a, b = 2 * s - 1, 2 * t - 1
    jac = (1 + a * a + b * b) ** -1.5
    out = np.zeros((6, n, n, 3))
    for face in range(6):
        rad = env_lookup(env, face_point_direction(face, s, t)) * jac[..., None]
        num = rad.reshape(n, q, n, q, 3).sum(axis=(1, 3))
        den = jac.reshape(n, q, n, q).sum(axis=(1, 3))
        out[face] = num / den[..., None]
    return out.reshape(6 * n * n, 3)


# ------------------------------------------------------------------ mitsuba

def euler(mi, t, rot):
    rx, ry, rz = rot
    return (t.rotate([0, 0, 1], rz).rotate([0, 1, 0], ry).rotate([1, 0, 0], rx))


def mitsuba_scene(mi, scene, base, env, spp):
    T = mi.ScalarTransform4f
    cam = scene["camera"]
    mats = scene.get("materials", {})

    def bsdf(name):
        m = mats[name]
        if m["type"] == "lambert":
            inner = {"type": "diffuse", "reflectance": {"type": "rgb", "value": m["albedo"]}}
        elif (m["type"] == "glossy" and all(a == 0 for a in m["albedo"])
              and all(f == 1 for f in m["specular"])):
            # ltm's glossy model with no base and F0 = 1 (Schlick's F is 1):
            # GGX D and separable Smith G1, as Mitsuba's roughconductor
            # with Fresnel 1.
            inner = {"type": "roughconductor", "distribution": "ggx",
                     "alpha": m["roughness"], "material": "none"}
        else:
            sys.exit(f"material {name}: only Lambertian materials and glossy ones with "
                     "albedo 0 and specular 1 (a Fresnel-1 conductor) can be compared")
        return {"type": "twosided", "material": inner}

    d = {
        "type": "scene",
        "integrator": {"type": "direct", "hide_emitters": True},
        "sensor": {
            "type": "perspective",
            "fov": cam["fov"],
            "fov_axis": "y",
            "to_world": T().look_at(origin=cam["eye"], target=cam["target"],
                                    up=cam.get("up", [0, 1, 0])),
            "film": {"type": "hdrfilm", "width": cam["width"], "height": cam["height"],
                     "rfilter": {"type": "box"}, "pixel_format": "rgb"},
            "sampler": {"type": "independent", "sample_count": spp},
        },
        "env": {"type": "envmap", "bitmap": mi.Bitmap(env.astype(np.float32))},
    }
    for i, m in enumerate(scene.get("meshes", [])):
        path = os.path.normpath(os.path.join(base, m["path"]))
        scale = m.get("scale", 1.0)
        scale = [scale] * 3 if isinstance(scale, (int, float)) else scale
        to_world = euler(mi, T().translate(m.get("translation", [0, 0, 0])),
                         m.get("rotation", [0, 0, 0])).scale(scale)
        d[f"mesh{i}"] = {"type": os.path.splitext(path)[1][1:].lower(),
                         "filename": path, "to_world": to_world,
                         "face_normals": not m.get("smooth", True),
                         "bsdf": bsdf(m["material"])}
    for i, q in enumerate(scene.get("quads", [])):
        sx, sz = q["size"]
        to_world = (euler(mi, T().translate(q["center"]), q.get("rotation", [0, 0, 0]))
                    .rotate([1, 0, 0], -90).scale([sx / 2, sz / 2, 1]))
        d[f"quad{i}"] = {"type": "rectangle", "to_world": to_world,
                         "bsdf": bsdf(q["material"])}
    return d


def use_new_llvm():
    """Points Dr.Jit at the newest libLLVM installed, unless
    DRJIT_LIBLLVM_PATH is set: Dr.Jit 1.5's kernels need LLVM 16 or newer
    (LLVM 14 and 15 fail to select `fmaximum`); Debian 12 has
    `apt-get install libllvm19`."""
    import glob
    import re
    if "DRJIT_LIBLLVM_PATH" in os.environ:
        return
    found = []
    for path in glob.glob("/usr/lib/*/libLLVM*.so*") + glob.glob("/usr/lib/llvm-*/lib/libLLVM*.so*"):
        m = re.search(r"libLLVM(?:-|\.so\.)(\d+)", path)
        if m and int(m.group(1)) >= 16:
            found.append((int(m.group(1)), path))
    if found:
        os.environ["DRJIT_LIBLLVM_PATH"] = max(found)[1]


def centre_render(mi, d, spp, seed, batch=64):
    """Mitsuba's `direct` integrator along each pixel's centre ray, `spp`
    samples each, as an H x W x 3 float64 image (row 0 at the top).

    ltm's rows are the pixel centres' first hits (camera spp = 1), so the
    reference takes exactly those rays rather than a pixel's box: where
    sub-pixel facets of a flat-shaded mesh meet inside a pixel, a box
    average and a centre ray differ by far more than either method's error.
    Needs a vectorized variant (llvm_ad_rgb); `batch` samples per pixel go
    in one wavefront."""
    import drjit as dr
    scene = mi.load_dict(d)
    sensor, integrator = scene.sensors()[0], scene.integrator()
    w, h = sensor.film().crop_size()
    total = np.zeros((h * w, 3))
    sampler = mi.load_dict({"type": "independent"})
    done = 0
    while done < spp:
        k = min(batch, spp - done)
        sampler.seed(seed * 100003 + done, w * h * k)
        pixel = dr.arange(mi.UInt32, w * h * k) // k
        x, y = mi.Float(pixel % w), mi.Float(pixel // w)
        centre = mi.Point2f((x + 0.5) / w, (y + 0.5) / h)
        ray, weight = sensor.sample_ray(0.0, 0.5, centre, mi.Point2f(0.5, 0.5))
        value, _, _ = integrator.sample(scene, sampler, ray)
        value = value * weight
        for c in range(3):
            total[:, c] += np.array(dr.block_sum(value[c], k), dtype=np.float64)
        done += k
    return (total / spp).reshape(h, w, 3)


def check_env_convention(mi, env):
    """Our numpy interpolant against Mitsuba's own envmap evaluation."""
    em = mi.load_dict({"type": "envmap", "bitmap": mi.Bitmap(env.astype(np.float32))})
    rng = np.random.default_rng(7)
    worst = 0.0
    for _ in range(500):
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        si = mi.SurfaceInteraction3f()
        si.wi = mi.Vector3f(*(-d))
        ref = np.array(em.eval(si))[:3]
        ours = env_lookup(env, d[None])[0]
        worst = max(worst, float(np.max(np.abs(ref - ours) / (np.abs(ref) + 1e-3))))
    return worst


# --------------------------------------------------------------------- main

def save_png(path, img):
    """8-bit sRGB-ish PNG (gamma 2.2) without extra dependencies."""
    import struct
    import zlib
    h, w, _ = img.shape
    px = (np.clip(img, 0, 1) ** (1 / 2.2) * 255 + 0.5).astype(np.uint8)
    raw = b"".join(b"\0" + px[y].tobytes() for y in range(h))

    def chunk(tag, data):
        return (struct.pack(">I", len(data)) + tag + data
                + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF))
    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
                + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default=os.path.join(HERE, "diffuse.toml"))
    ap.add_argument("--env", nargs="+",
                    default=[os.path.join(ROOT, "assets/envmaps/courtyard.exr")])
    ap.add_argument("--ltm", default=os.path.join(ROOT, "target/release/ltm"),
                    help="the ltm binary (cargo build --release -p ltm-tools)")
    ap.add_argument("--raw", help="use this baked raw store instead of baking")
    ap.add_argument("--spp", type=int, default=16384, help="Mitsuba samples per pixel")
    ap.add_argument("--texel-supersampling", type=int, default=16,
                    help="q: q x q environment lookups per cubemap texel")
    ap.add_argument("--out", default=None, help="directory for images and summary.json")
    ap.add_argument("--width", type=int, help="override camera.width (passed to ltm bake)")
    ap.add_argument("--height", type=int, help="override camera.height")
    ap.add_argument("--face-res", type=int, help="override lighting.face_res")
    ap.add_argument("--texel-samples", type=int, help="override lighting.texel_samples")
    ap.add_argument("--pixel-samples", type=int, help="override camera.spp")
    ap.add_argument("--variant", default="scalar_rgb")
    ap.add_argument("--limit", type=float, default=0.02, help="largest relative L2 error accepted")
    args = ap.parse_args()

    import mitsuba as mi
    mi.set_variant(args.variant)
    with open(args.scene, "rb") as f:
        scene = tomllib.load(f)
    base = os.path.dirname(os.path.abspath(args.scene))
    flags = []
    for key, table, field in [("width", "camera", "width"), ("height", "camera", "height"),
                              ("face_res", "lighting", "face_res"),
                              ("texel_samples", "lighting", "texel_samples"),
                              ("pixel_samples", "camera", "spp")]:
        value = getattr(args, key)
        if value is not None:
            scene[table][field] = value
            flag = "--spp" if key == "pixel_samples" else "--" + key.replace("_", "-")
            flags += [flag, str(value)]
    out = args.out or tempfile.mkdtemp(prefix="ltm-mitsuba-")
    os.makedirs(out, exist_ok=True)

    raw_path = args.raw
    bake_s = None
    if raw_path is None:
        raw_path = os.path.join(out, "scene.raw")
        t0 = time.time()
        subprocess.run([args.ltm, "bake", args.scene, "-o", raw_path] + flags, check=True)
        bake_s = time.time() - t0
    raw = read_raw(raw_path)
    cam = scene["camera"]
    if (raw["width"], raw["height"]) != (cam["width"], cam["height"]):
        sys.exit("the raw store's image size differs from the scene's camera")

    results = []
    for env_path in args.env:
        env = np.maximum(np.array(mi.Bitmap(env_path)), 0.0)[..., :3].astype(np.float64)
        conv = check_env_convention(mi, env)
        light = texel_radiance(env, raw["face_res"], args.texel_supersampling)
        ours = relight(raw, light)
        d = mitsuba_scene(mi, scene, base, env, args.spp)
        sc = mi.load_dict(d)
        t0 = time.time()
        ref = np.array(mi.render(sc, seed=1), dtype=np.float64)[..., :3]
        render_s = time.time() - t0
        ref2 = np.array(mi.render(sc, seed=2), dtype=np.float64)[..., :3]
        norm = np.linalg.norm(ref)
        err = float(np.linalg.norm(ours - ref) / norm)
        # Grey transport is exact in luminance at pixels mixing materials of
        # different hues (see ltm_bake::transport); report that error too.
        lum = np.array([0.2126, 0.7152, 0.0722])
        err_y = float(np.linalg.norm((ours - ref) @ lum) / np.linalg.norm(ref @ lum))
        noise = float(np.linalg.norm(ref2 - ref) / norm / math.sqrt(2))
        # The residual with Mitsuba's noise removed (independent errors add
        # in quadrature).
        name = os.path.splitext(os.path.basename(env_path))[0]
        res = dict(env=name, rel_l2=err, rel_l2_luminance=err_y, mitsuba_noise=noise,
                   rel_l2_noise_removed=math.sqrt(max(err * err - noise * noise, 0.0)),
                   env_convention_max_rel_diff=conv, mitsuba_render_s=render_s)
        results.append(res)
        print(json.dumps(res))
        np.save(os.path.join(out, f"{name}_ltm.npy"), ours.astype(np.float32))
        np.save(os.path.join(out, f"{name}_mitsuba.npy"), ref.astype(np.float32))
        peak = np.percentile(ref, 99.5)
        save_png(os.path.join(out, f"{name}_ltm.png"), ours / peak)
        save_png(os.path.join(out, f"{name}_mitsuba.png"), ref / peak)
        diff = np.abs(ours - ref).sum(-1) / peak
        save_png(os.path.join(out, f"{name}_absdiff_x10.png"),
                 np.repeat(np.clip(10 * diff, 0, 1)[..., None], 3, -1))
    summary = dict(mitsuba_version=mi.__version__, variant=args.variant, spp=args.spp,
                   scene=os.path.relpath(args.scene, ROOT), width=cam["width"],
                   height=cam["height"], face_res=raw["face_res"],
                   texel_samples=scene["lighting"].get("texel_samples", 4),
                   pixel_samples=cam.get("spp", 1),
                   texel_supersampling=args.texel_supersampling, bake_s=bake_s,
                   results=results)
    with open(os.path.join(out, "summary.json"), "w") as f:
        json.dump(summary, f, indent=2)
    print(f"images and summary.json in {out}")
    worst = max(r["rel_l2"] for r in results)
    if worst > args.limit:
        print(f"FAIL: relative L2 error {worst:.4f} > {args.limit}")
        return 1
    print(f"PASS: relative L2 error {worst:.4f} <= {args.limit}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
