#!/usr/bin/env python3
"""Check `ltm relight --point` (Eigentransport's local lights) against Mitsuba 3.

The scene `tools/validate/point/scene.toml` (Lambertian, flat-shaded: the
small bunny on a ground quad before a wall) is rendered by Mitsuba's
`direct` integrator lit only by one point light, and by ltm from a `pca`
file of the scene's bake: `ltm relight FILE --point X,Y,Z --intensity I`.
Two lights are checked:

  * `outside`: outside the scene's bounding sphere, where Eigentransport's
    approximation (each row sees the light with the visibility of its
    direction at infinity) is exact; the committed test
    `tools/tests/slow/point.rs` compares ltm with this image;
  * `between`: between the bunny and the wall, where the approximation
    breaks (rows on the wall are shadowed by the bunny *behind* the light).

Conventions (see tools/validate/README.md and mitsuba_compare.py, whose
scene builder this reuses):
  * camera, surfaces: as mitsuba_compare.py (look_at, fov_axis y, box
    filter, twosided diffuse, face_normals);
  * pixels: ltm's rows (spp = 1) are the pixel centres' first hits, and
    Mitsuba traces exactly those rays (`mitsuba_compare.centre_render`, the
    llvm_ad_rgb variant; it needs LLVM 16 or newer, e.g. `apt-get install
    libllvm19`). Before 2026-12-02 it rendered at 5 times the resolution
    and kept the centre sub-pixel of each 5 x 5 block, whose box straddles
    the bunny's sub-pixel facets;
  * units: Mitsuba's point emitter `intensity` is radiant intensity (W/sr),
    the `I` of ltm's `--intensity` (a row gets f_r cos I / d^2).

Mitsuba's images are written as float32 .npy (H x W x 3) fixtures:
  tools/tests/fixtures/point_mitsuba_outside.npy
  tools/tests/fixtures/point_mitsuba_between.npy
with `--write-fixtures`. With `--ltm` (default target/release/ltm) the
script also bakes, compresses (pca, `--rank`) and relights the scene and
prints the relative L2 errors and Mitsuba's own noise (two seeds).

Usage:
  cargo build --release -p ltm-tools
  python3 tools/validate/mitsuba_point.py [--write-fixtures] [--out DIR]
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

SCENE = os.path.join(HERE, "point", "scene.toml")
FIXTURES = os.path.join(ROOT, "tools", "tests", "fixtures")
# The lights: position (world units), intensity (W/sr). Keep in step with
# tools/tests/slow/point.rs.
LIGHTS = {
    "outside": ([3.0, 5.0, 4.0], 60.0),
    "between": ([0.5, 0.6, -0.7], 0.8),
}


def render(mi, scene, position, intensity, spp, seed):
    """Mitsuba's image at ltm's pixel centres (H x W x 3, float64)."""
    d = mitsuba_compare.mitsuba_scene(mi, scene, os.path.dirname(SCENE),
                                      np.zeros((8, 16, 3)), spp)
    del d["env"]
    d["light"] = {"type": "point", "position": position,
                  "intensity": {"type": "rgb", "value": [intensity] * 3}}
    return mitsuba_compare.centre_render(mi, d, spp, seed)


def rel_l2(a, b):
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def read_exr(mi, path):
    return np.array(mi.Bitmap(path), dtype=np.float64)[..., :3]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--ltm", default=os.path.join(ROOT, "target/release/ltm"))
    ap.add_argument("--no-ltm", action="store_true", help="only render with Mitsuba")
    ap.add_argument("--rank", default="1024", help="pca rank of the ltm file")
    ap.add_argument("--lookup", default="bilinear", help="ltm --point-lookup")
    ap.add_argument("--spp", type=int, default=64, help="Mitsuba samples per pixel")
    ap.add_argument("--out", default=None, help="directory for the bake, images and summary")
    ap.add_argument("--write-fixtures", action="store_true")
    args = ap.parse_args()

    mitsuba_compare.use_new_llvm()
    import mitsuba as mi
    mi.set_variant("llvm_ad_rgb")
    with open(SCENE, "rb") as f:
        scene = tomllib.load(f)
    out = args.out or tempfile.mkdtemp(prefix="ltm-point-")
    os.makedirs(out, exist_ok=True)
    results = {}
    images = {}
    for name, (pos, inten) in LIGHTS.items():
        t0 = time.time()
        ref = render(mi, scene, pos, inten, args.spp, seed=1)
        render_s = time.time() - t0
        ref2 = render(mi, scene, pos, inten, args.spp, seed=2)
        images[name] = ref
        results[name] = dict(position=pos, intensity=inten, render_s=render_s,
                             mitsuba_noise=rel_l2(ref2, ref) / math.sqrt(2))
        if args.write_fixtures:
            os.makedirs(FIXTURES, exist_ok=True)
            np.save(os.path.join(FIXTURES, f"point_mitsuba_{name}.npy"),
                    ref.astype(np.float32))
    if not args.no_ltm:
        raw, ltm_file = os.path.join(out, "scene.raw"), os.path.join(out, "scene.ltm")
        t0 = time.time()
        subprocess.run([args.ltm, "bake", SCENE, "-o", raw], check=True)
        bake_s = time.time() - t0
        t0 = time.time()
        subprocess.run([args.ltm, "compress", raw, "-o", ltm_file, "--mode", "pca",
                        "--rank", args.rank, "--bits", "16"], check=True)
        compress_s = time.time() - t0
        for name, (pos, inten) in LIGHTS.items():
            exr = os.path.join(out, f"{name}_ltm.exr")
            subprocess.run([args.ltm, "relight", ltm_file, "--point",
                            ",".join(map(str, pos)), "--intensity", str(inten),
                            "--point-lookup", args.lookup, "-o", exr], check=True)
            ours = read_exr(mi, exr)
            results[name]["rel_l2"] = rel_l2(ours, images[name])
            peak = np.percentile(images[name], 99.5)
            mitsuba_compare.save_png(os.path.join(out, f"{name}_ltm.png"), ours / peak)
            mitsuba_compare.save_png(os.path.join(out, f"{name}_mitsuba.png"),
                                     images[name] / peak)
            diff = np.abs(ours - images[name]).sum(-1) / peak
            mitsuba_compare.save_png(os.path.join(out, f"{name}_absdiff_x10.png"),
                                     np.repeat(np.clip(10 * diff, 0, 1)[..., None], 3, -1))
        results["ltm"] = dict(rank=args.rank, lookup=args.lookup, bake_s=bake_s,
                              compress_s=compress_s)
    summary = dict(mitsuba_version=mi.__version__, variant="llvm_ad_rgb", spp=args.spp,
                   rays="pixel centres", scene=os.path.relpath(SCENE, ROOT), results=results)
    with open(os.path.join(out, "summary.json"), "w") as f:
        json.dump(summary, f, indent=2)
    print(json.dumps(summary, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
