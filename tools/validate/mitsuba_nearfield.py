#!/usr/bin/env python3
"""Check near-field area lights (Sun and Ramamoorthi 2009) against Mitsuba 3.

The scene `tools/validate/point/scene.toml` (the small bunny, flat-shaded
and Lambertian, on a ground quad before a wall) is lit by one planar,
textured area light above it, parallel to the ground and facing down.
`--scene glossy` takes `tools/validate/point/glossy.toml` instead: the
same scene with the bunny (GGX alpha 0.25) and the ground (alpha 0.4) made
Fresnel-1 conductors, Mitsuba's `roughconductor` with material "none".

  * ltm: `cargo run --release --example nearfield`, which bakes every pixel
    over the light plane's expanded top face (`Scene::plane_row`, order 32,
    side 4) and propagates the light's Haar coefficients to it
    (`ltm::relight::nearfield`);
  * Mitsuba: a `rectangle` shape with an `area` emitter whose radiance is a
    `bitmap` texture (nearest, raw), `direct` integrator, traced along each
    pixel's centre ray (ltm's rows are the pixel centres' first hits). The
    `llvm_ad_rgb` variant takes the rays in wavefronts
    (`mitsuba_compare.centre_render`).
    Before 2026-12-02 the reference was rendered at 5 times ltm's
    resolution with the centre sub-pixel of each 5 x 5 block kept; its
    1/5-pixel box straddles the small bunny's sub-pixel facets, which cost
    the near light's check 2-3 points of error that were the reference's.

Two placements: `near` (the light 0.75 above the bunny's top, about half the
scene's size) and `far` (2.5 higher and 3 times larger). Each is measured at
every source and target term and at the paper's 1 % / 20 %. Each is also
rendered by Mitsuba under a distant map of the same light as seen from the
camera's target (the paper's Fig. 8c), to show what the near field changes.

Conventions: the light's texture row 0 lies at its -y edge and column 0 at
its -x edge, with the plane's x axis = world +X and y axis = world +Z (lit
side x × y = -Y). Mitsuba's rectangle maps its local [-1, 1]^2 to uv
[0, 1]^2 and its bitmap's row 0 to v = 0, so the same texture is passed to
both. Pixels whose light arrives from outside the face (more than
atan(side/2) = 63 degrees off the plane's normal) are darker in ltm by
design: the summary reports the error over all pixels and over pixels that
see the whole light rectangle inside the face and lie more than 1 px from
a silhouette (kept from the box-filtered reference of before, whose box
saw two surfaces there; the summary also gives the error without that
exclusion).

With --write-fixtures the light texture and Mitsuba's images (float32
.npy, H x W x 3) are written to tests/fixtures/ for tests/nearfield.rs:
`nearfield_mitsuba_{near,far}.npy` for the diffuse scene,
`nearfield_mitsuba_glossy_{near,far}.npy` for the glossy one.

Usage (needs LLVM 16 or newer for Mitsuba's llvm_ad_rgb variant, e.g.
`apt-get install libllvm19`; see `mitsuba_compare.use_new_llvm`):
  python3 tools/validate/mitsuba_nearfield.py [--scene diffuse|glossy] [--spp 1024]
      [--out DIR] [--write-fixtures]
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
sys.path.insert(0, HERE)
import mitsuba_compare  # noqa: E402  (the shared scene builder)

SCENES = {"diffuse": os.path.join(HERE, "point", "scene.toml"),
          "glossy": os.path.join(HERE, "point", "glossy.toml")}
SCENE = SCENES["diffuse"]
FIXTURES = os.path.join(ROOT, "tests", "fixtures")
SIDE = 4.0
ORDER = 32
# name: (plane height, centre (x, z), size (x, z), intensity). Keep in step
# with tests/nearfield.rs.
PLACEMENTS = {
    "near": (1.5, (0.15, 0.25), (0.8, 0.6), 4.0),
    "far": (4.0, (0.3, 0.5), (2.4, 1.8), 4.0),
}


def light_texture(w=64, h=48):
    """A softbox: warm left half, cool right half, dark bars, a bright spot."""
    y, x = np.mgrid[0:h, 0:w] + 0.5
    u, v = x / w, y / h
    tex = np.zeros((h, w, 3), np.float32)
    tex[..., 0] = np.where(u < 0.5, 1.6, 0.5)
    tex[..., 1] = 0.9
    tex[..., 2] = np.where(u < 0.5, 0.4, 1.5)
    bars = (np.floor(v * 6) % 2 == 1) & (u > 0.2) & (u < 0.8)
    tex[bars] *= 0.15
    spot = (u - 0.8) ** 2 + (v - 0.2) ** 2 < 0.01
    tex[spot] = [6.0, 6.0, 5.0]
    return tex


def mitsuba_image(mi, scene, tex_path, height, center, size, spp, seed):
    """Mitsuba's image along ltm's pixel centres; `tex_path` holds the
    radiance with the intensity applied."""
    d = mitsuba_compare.mitsuba_scene(mi, scene, os.path.dirname(SCENE),
                                      np.zeros((8, 16, 3)), spp)
    del d["env"]
    T = mi.ScalarTransform4f
    # local x -> +X·w/2, local y -> +Z·h/2, local z (emitting side) -> -Y.
    cx, cz = center
    sx, sz = size
    to_world = T([[sx / 2, 0, 0, cx], [0, 0, -1, height], [0, sz / 2, 0, cz], [0, 0, 0, 1]])
    d["light"] = {"type": "rectangle", "to_world": to_world,
                  "emitter": {"type": "area", "radiance": {
                      "type": "bitmap", "filename": tex_path, "raw": True,
                      "filter_type": "nearest"}}}
    return mitsuba_compare.centre_render(mi, d, spp, seed)


def silhouettes(points, eye, jump=0.01):
    """Pixels within 1 px of a silhouette: a miss, or a distance to the eye
    that bends by more than `jump` (relative) between a pixel and its two
    neighbours along a row or a column (a plane seen in perspective stays
    nearly straight)."""
    dist = np.linalg.norm(points - np.asarray(eye), axis=-1)
    edge = ~np.isfinite(dist)
    d = np.where(edge, 0.0, dist)
    bend = np.zeros_like(edge)
    bend[1:-1] |= np.abs(d[:-2] + d[2:] - 2 * d[1:-1]) > jump * d[1:-1]
    bend[:, 1:-1] |= np.abs(d[:, :-2] + d[:, 2:] - 2 * d[:, 1:-1]) > jump * d[:, 1:-1]
    edge |= bend
    grown = edge.copy()
    grown[1:] |= edge[:-1]
    grown[:-1] |= edge[1:]
    grown[:, 1:] |= edge[:, :-1]
    grown[:, :-1] |= edge[:, 1:]
    return grown


def distant_env(tex, height, center, size, origin, w=2048):
    """The light as a distant environment seen from `origin`: a lat-long map
    in Mitsuba's envmap convention (mitsuba_compare.env_lookup), each texel
    the light's radiance along its direction (the paper's Fig. 8c)."""
    h = w // 2
    v = np.arange(h) / (h - 1)
    u = (np.arange(w) + 0.5) / w
    theta, phi = np.meshgrid(np.pi * v, 2 * np.pi * u, indexing="ij")
    d = np.stack([np.sin(theta) * np.sin(phi), np.cos(theta),
                  -np.sin(theta) * np.cos(phi)], -1)
    env = np.zeros((h, w, 3), np.float32)
    up = d[..., 1] > 1e-9
    t = np.where(up, (height - origin[1]) / np.where(up, d[..., 1], 1.0), 0.0)
    qx = origin[0] + t * d[..., 0]
    qz = origin[2] + t * d[..., 2]
    tu = (qx - center[0]) / size[0] + 0.5
    tv = (qz - center[1]) / size[1] + 0.5
    hit = up & (tu >= 0) & (tu < 1) & (tv >= 0) & (tv < 1)
    th, tw = tex.shape[:2]
    iy = np.clip((tv * th).astype(int), 0, th - 1)
    ix = np.clip((tu * tw).astype(int), 0, tw - 1)
    env[hit] = tex[iy[hit], ix[hit]]
    return env


def rel_l2(a, b, mask=None):
    if mask is not None:
        a, b = a[mask], b[mask]
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def run_ltm(scene_path, tex_file, tex, height, center, size, intensity, out, source, target):
    """Runs the example; returns its seconds and its summary line."""
    h, w = tex.shape[:2]
    cmd = ["cargo", "run", "--release", "--quiet", "--example", "nearfield", "--", scene_path,
           "--plane", f"0,{height},0,1,0,0,0,0,1", "--texture", f"{w},{h},{tex_file}",
           "--center", f"{center[0]},{center[1]}", "--size", f"{size[0]},{size[1]}",
           "--intensity", str(intensity), "--order", str(ORDER), "--side", str(SIDE),
           "--source-share", str(source), "--target-share", str(target), "-o", out,
           "--coverage", out + ".coverage", "--points", out + ".points"]
    t0 = time.time()
    log = subprocess.run(cmd, check=True, cwd=ROOT, capture_output=True, text=True).stdout
    return time.time() - t0, log.strip()


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--spp", type=int, default=256, help="Mitsuba samples per sub-pixel")
    ap.add_argument("--texel-samples", type=int, default=16)
    ap.add_argument("--order", type=int, default=32, help="face texels per side")
    ap.add_argument("--only", default=None, help="one placement: near or far")
    ap.add_argument("--scene", choices=sorted(SCENES), default="diffuse",
                    help="diffuse (scene.toml) or glossy (glossy.toml) receivers")
    ap.add_argument("--write-fixtures", action="store_true",
                    help="write the light and Mitsuba's images to tests/fixtures/ "
                         "(read by tests/nearfield.rs)")
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    global ORDER, SCENE
    ORDER = args.order
    SCENE = SCENES[args.scene]
    prefix = "" if args.scene == "diffuse" else args.scene + "_"
    mitsuba_compare.use_new_llvm()
    import mitsuba as mi
    mi.set_variant("llvm_ad_rgb")
    out = args.out or tempfile.mkdtemp(prefix="ltm-nearfield-")
    os.makedirs(out, exist_ok=True)
    with open(SCENE, "rb") as f:
        scene = tomllib.load(f)
    # The same scene with more direction samples per texel, beside the
    # original so its relative mesh path still holds, under a name of its
    # own so that runs side by side do not share it.
    text = open(SCENE).read().replace("texel_samples = 4", f"texel_samples = {args.texel_samples}")
    with tempfile.NamedTemporaryFile("w", dir=os.path.dirname(SCENE), prefix=".nearfield-",
                                     suffix=".toml", delete=False) as f:
        f.write(text)
        scene_path = f.name
    tex = light_texture()
    tex_f32 = os.path.join(out, "light.f32")
    tex.astype("<f4").tofile(tex_f32)
    if args.write_fixtures:
        os.makedirs(FIXTURES, exist_ok=True)
        np.save(os.path.join(FIXTURES, "nearfield_light.npy"), tex.astype(np.float32))
    cam = scene["camera"]
    H, W = cam["height"], cam["width"]
    results = {}
    try:
        for name, (height, center, size, inten) in PLACEMENTS.items():
            if args.only and name != args.only:
                continue
            tex_exr = os.path.join(out, f"light-{name}.exr")
            mi.Bitmap(tex * np.float32(inten)).write(tex_exr)
            t0 = time.time()
            ref = mitsuba_image(mi, scene, tex_exr, height, center, size, args.spp, 1)
            render_s = time.time() - t0
            ref2 = mitsuba_image(mi, scene, tex_exr, height, center, size, args.spp, 2)
            noise = rel_l2(ref2, ref) / math.sqrt(2)
            np.save(os.path.join(out, f"{name}_mitsuba.npy"), ref.astype(np.float32))
            np.save(os.path.join(out, f"{name}_mitsuba_seed2.npy"), ref2.astype(np.float32))
            if args.write_fixtures:
                np.save(os.path.join(FIXTURES, f"nearfield_mitsuba_{prefix}{name}.npy"),
                        ref.astype(np.float32))
            # What a distant map of the same light would give (Mitsuba on
            # both sides): the light as seen from the scene's centre.
            env = distant_env(tex * np.float32(inten), height, center, size, cam["target"])
            d = mitsuba_compare.mitsuba_scene(mi, scene, os.path.dirname(SCENE), env, args.spp)
            distant = mitsuba_compare.centre_render(mi, d, args.spp, 1)
            r = dict(height=height, center=center, size=size, intensity=inten,
                     mitsuba_render_s=render_s, mitsuba_noise=noise,
                     distant_map_against_near_field=rel_l2(distant, ref), runs=[])
            mitsuba_compare.save_png(os.path.join(out, f"{name}_distant.png"),
                                     distant / np.percentile(ref, 99.5))
            for source, target in [(1.0, 1.0), (0.05, 0.3), (0.01, 0.2)]:
                img_path = os.path.join(out, f"{name}-{source}-{target}.f32")
                secs, log = run_ltm(scene_path, tex_f32, tex, height, center, size, inten,
                                    img_path, source, target)
                ours = np.fromfile(img_path, dtype="<f4").reshape(H, W, 3).astype(np.float64)
                cov = np.fromfile(img_path + ".coverage", dtype=np.uint8).reshape(H, W)
                pts = np.fromfile(img_path + ".points", dtype="<f4").reshape(H, W, 3)
                inside = (cov == 2) & ~silhouettes(pts.astype(np.float64), cam["eye"])
                e, e_in = rel_l2(ours, ref), rel_l2(ours, ref, inside)
                noise_in = rel_l2(ref2, ref, inside) / math.sqrt(2)
                r["runs"].append(dict(
                    source=source, target=target, rel_l2=e,
                    rel_l2_noise_removed=math.sqrt(max(e * e - noise * noise, 0)),
                    inside_share=float(inside.mean()), rel_l2_inside=e_in,
                    # Over every pixel that sees the whole light, silhouettes
                    # included.
                    rel_l2_covered=rel_l2(ours, ref, cov == 2),
                    mitsuba_noise_inside=noise_in,
                    rel_l2_inside_noise_removed=math.sqrt(max(e_in ** 2 - noise_in ** 2, 0)),
                    # The share of the image's light, and of the light of
                    # the pixels the face does not fully cover, left out.
                    image_energy_left_out=float((ref[cov == 1].sum() - ours[cov == 1].sum())
                                                / ref.sum()),
                    partial_energy_left_out=(
                        float(1 - ours[cov == 1].sum() / ref[cov == 1].sum())
                        if (cov == 1).any() else None),
                    ltm_s=secs, log=log))
                if source == 1.0:
                    peak = np.percentile(ref, 99.5)
                    mitsuba_compare.save_png(os.path.join(out, f"{name}_ltm.png"), ours / peak)
                    mitsuba_compare.save_png(os.path.join(out, f"{name}_mitsuba.png"), ref / peak)
            results[name] = r
            print(json.dumps({name: r}, indent=1), flush=True)
    finally:
        os.remove(scene_path)
    summary = dict(mitsuba_version=mi.__version__, spp=args.spp, rays="pixel centres",
                   scene_kind=args.scene,
                   scene=os.path.relpath(SCENE, ROOT), side=SIDE, order=ORDER,
                   texel_samples=args.texel_samples, results=results)
    with open(os.path.join(out, "summary.json"), "w") as f:
        json.dump(summary, f, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
