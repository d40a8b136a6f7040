#!/usr/bin/env python3
"""The codec's own hard corpus: matrices from meshes and scenes that are not
in assets/, baked with ltm and compressed at 0.3, 1 and 3 % matrix error
with `2d`, `adaptive --quantizer peak` and `adaptive` (the uniform
quantizer), beside the peers of `peers.json` files when they exist.

The corpus (every scene written here, every mesh made here):
- limbs: a closed body with six thin limbs on a floor, grey with an albedo
  image, 96x72, n = 16, 4 samples per texel (noisy);
- limbs-smooth: the same with 64 samples per texel;
- limbs-n32: the same at 128x128, n = 32;
- limbs-tex: its texture-space rows (128x128 sphere geometry image);
- torus-rgb: a glossy torus (genus 1) on a floor, RGB, 128x96, n = 16;
- torus-grey: the torus, Lambertian (grey with albedo), 96x72, n = 32;
- default: assets/scenes/default.toml at 96x72, n = 16 (RGB).

Usage:
  cargo build --release -p ltm-tools
  pip install numpy
  python3 tools/validate/codec_corpus.py --out /tmp/corpus [--only limbs torus-rgb]
  # peers (optional, slow): for each NAME,
  python3 tools/validate/peers.py /tmp/corpus/NAME.raw -o /tmp/corpus/peers-NAME.json
  python3 tools/validate/codec_corpus.py --out /tmp/corpus --table-only

Writes OUT/corpus.json (every file: bytes, side bytes, bits, nonzeros,
error, coding passes, seconds) and prints a markdown table; a peer column
shows the smallest stream of that compressor at an error at most the
target. `--variants adaptive` recodes only those variants, keeping the
others' results.

The peers store the matrix T alone. An .ltm file also stores side data a
relighter needs and the peers do not: the albedo image (ALBD), the surface
records (SURF) and the receiving mesh (MESH). "side bytes" are those
chunks' stored lengths; the table gives adaptive's ratio for the whole
file and for T alone (the file less its side bytes), and both against the
best peer.
"""

import argparse
import json
import os
import re
import subprocess
import sys
import time

import struct

import numpy as np

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
sys.path.insert(0, os.path.dirname(__file__))

TARGETS = [0.003, 0.01, 0.03]
VARIANTS = {
    "2d": ["--mode", "2d"],
    "adaptive peak": ["--mode", "adaptive", "--quantizer", "peak"],
    "adaptive": ["--mode", "adaptive"],
}

LIMBS = """[camera]
eye = [1.6, 1.3, 2.2]
target = [0.0, 0.35, 0.0]
fov = 42.0
width = {w}
height = {h}
spp = 4

[lighting]
face_res = {n}
texel_samples = {samples}

[materials.skin]
type = "lambert"
albedo = [0.75, 0.55, 0.45]

[materials.floor]
type = "lambert"
albedo = [0.35, 0.4, 0.3]

[[meshes]]
path = "limbs.obj"
material = "skin"
translation = [0.0, 0.25, 0.0]

[[quads]]
center = [0.0, 0.0, 0.0]
size = [{floor}, {floor}]
material = "floor"
{texture}"""

TORUS = """[camera]
eye = [1.2, 1.0, 1.5]
target = [0.0, 0.1, 0.0]
fov = 40.0
width = {w}
height = {h}
spp = 4

[lighting]
face_res = {n}
texel_samples = 4

[materials.copper]
{material}

[materials.floor]
type = "lambert"
albedo = [0.3, 0.35, 0.5]

[[meshes]]
path = "torus.obj"
material = "copper"
rotation = [60.0, 20.0, 0.0]
translation = [0.0, 0.3, 0.0]

[[quads]]
center = [0.0, 0.0, 0.0]
size = [6.0, 6.0]
material = "floor"
"""

GLOSSY = 'type = "glossy"\nalbedo = [0.6, 0.3, 0.15]\nspecular = [0.5, 0.3, 0.2]\nroughness = 0.2'
LAMBERT = 'type = "lambert"\nalbedo = [0.6, 0.3, 0.15]'
TEXTURE = '\n[texture]\nmesh = 0\nsize = 128\nspp = 4\nparameterization = "sphere"\n'


def scenes():
    """name -> (scene file text or None for the default scene, extra bake args)."""
    limbs = dict(w=96, h=72, n=16, samples=4, floor=8.0, texture="")
    return {
        "limbs": (LIMBS.format(**limbs), []),
        "limbs-smooth": (LIMBS.format(**{**limbs, "samples": 64}), []),
        "limbs-n32": (LIMBS.format(**{**limbs, "w": 128, "h": 128, "n": 32}), []),
        "limbs-tex": (LIMBS.format(**{**limbs, "floor": 1.6, "texture": TEXTURE}), []),
        "torus-rgb": (TORUS.format(w=128, h=96, n=16, material=GLOSSY), []),
        "torus-grey": (TORUS.format(w=96, h=72, n=32, material=LAMBERT), []),
        "default": (None, ["--size", "96x72", "--face-res", "16"]),
    }


def torus_mesh(big=0.45, small=0.16, nu=96, nv=48):
    """A closed torus (genus 1): vertices (N, 3) and triangles (F, 3)."""
    u = np.linspace(0, 2 * np.pi, nu, endpoint=False)
    v = np.linspace(0, 2 * np.pi, nv, endpoint=False)
    uu, vv = np.meshgrid(u, v, indexing="ij")
    ring = big + small * np.cos(vv)
    verts = np.stack([ring * np.cos(uu), small * np.sin(vv), ring * np.sin(uu)], -1)
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    a, b = i * nv + j, ((i + 1) % nu) * nv + j
    c, d = ((i + 1) % nu) * nv + (j + 1) % nv, i * nv + (j + 1) % nv
    faces = np.concatenate([np.stack([a, c, b], -1), np.stack([a, d, c], -1)], 0)
    return verts.reshape(-1, 3), faces.reshape(-1, 3)


def bake(ltm, out, name, text, extra):
    raw = os.path.join(out, f"{name}.raw")
    if os.path.exists(raw):
        return raw
    if text is None:
        scene = os.path.join(ROOT, "assets/scenes/default.toml")
    else:
        scene = os.path.join(out, f"{name}.toml")
        with open(scene, "w") as f:
            f.write(text)
    subprocess.run([ltm, "bake", scene, "-o", raw, *extra], check=True)
    return raw


def compress(ltm, raw, target, args):
    out = raw[:-4] + ".tmp.ltm"
    t0 = time.monotonic()
    run = subprocess.run([ltm, "compress", raw, "-o", out, "--max-error", str(target), *args],
                         check=True, capture_output=True, text=True)
    seconds = time.monotonic() - t0
    line = next(l for l in run.stdout.splitlines() + run.stderr.splitlines() if l.startswith("wrote"))
    m = re.search(r": (\d+) bytes .*?, (\d+) bits, (\d+) nonzeros, relative L2 error ([0-9.]+), "
                  r"(\d+) coding pass", line)
    side = side_bytes(out)
    os.remove(out)
    return {"bytes": int(m[1]), "side_bytes": side, "bits": int(m[2]), "nonzeros": int(m[3]),
            "error": float(m[4]), "codings": int(m[5]), "seconds": seconds}


def side_bytes(path):
    """Stored bytes of the chunks ALBD, SURF and MESH (docs/FORMAT.md's chunk
    directory: 32-byte entries from byte 24, the count at byte 16)."""
    with open(path, "rb") as f:
        head = f.read(24 + 32 * 16)
    count, = struct.unpack_from("<I", head, 16)
    total = 0
    for e in range(count):
        tag = head[24 + 32 * e:28 + 32 * e]
        length, = struct.unpack_from("<Q", head, 24 + 32 * e + 16)
        if tag in (b"ALBD", b"SURF", b"MESH"):
            total += length
    return total


def peers(out, name):
    """The smallest stream per peer and target from OUT/peers-NAME.json."""
    path = os.path.join(out, f"peers-{name}.json")
    if not os.path.exists(path):
        return {}
    best = {}
    for p in json.load(open(path))["points"]:
        key = (p["method"], p["target"])
        if p.get("bytes") and p["matrix_error"] <= p["target"] and p["bytes"] < best.get(key, 1e30):
            best[key] = p["bytes"]
    return best


def table(out, results):
    names = list(results)
    raw_bytes = {n: os.path.getsize(os.path.join(out, f"{n}.raw")) for n in names}
    cols = list(VARIANTS) + ["adaptive, T alone", "sz3", "zfp", "sperr"]
    print("| matrix | target | " + " | ".join(cols) + " | adaptive / best peer | T alone / best peer |")
    print("|" + "---|" * (len(cols) + 4))
    for n in names:
        best = peers(out, n)
        for e in TARGETS:
            row, sizes = [], {}
            for v in VARIANTS:
                r = results[n].get(v, {}).get(str(e))
                sizes[v] = r and r["bytes"]
                row.append(f"{raw_bytes[n] / r['bytes']:.1f}×" if r else "")
            r = results[n].get("adaptive", {}).get(str(e))
            alone = r and "side_bytes" in r and r["bytes"] - r["side_bytes"]
            row.append(f"{raw_bytes[n] / alone:.1f}×" if alone else "")
            for p in ["sz3", "zfp", "sperr"]:
                b = best.get((p, e))
                sizes[p] = b
                row.append(f"{raw_bytes[n] / b:.1f}×" if b else "")
            peer = [sizes[p] for p in ["sz3", "zfp", "sperr"] if sizes[p]]
            ratio = f"{sizes['adaptive'] / min(peer):.2f}" if peer and sizes["adaptive"] else ""
            ratio_alone = f"{alone / min(peer):.2f}" if peer and alone else ""
            print(f"| {n} | {e * 100:g} % | " + " | ".join(row) + f" | {ratio} | {ratio_alone} |")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True)
    ap.add_argument("--ltm", default=os.path.join(ROOT, "target/release/ltm"))
    ap.add_argument("--only", nargs="*", help="matrix names (default: all)")
    ap.add_argument("--table-only", action="store_true", help="print the table of OUT/corpus.json")
    ap.add_argument("--variants", nargs="*", choices=list(VARIANTS),
                    help="variants to (re)code (default: all); the others' results are kept")
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    path = os.path.join(a.out, "corpus.json")
    results = json.load(open(path)) if os.path.exists(path) else {}
    if not a.table_only:
        from mitsuba_texture import limbs_mesh, write_obj
        write_obj(os.path.join(a.out, "limbs.obj"), *limbs_mesh())
        write_obj(os.path.join(a.out, "torus.obj"), *torus_mesh())
        for name, (text, extra) in scenes().items():
            if a.only and name not in a.only:
                continue
            raw = bake(a.ltm, a.out, name, text, extra)
            kept = results.get(name, {})
            for v, args in VARIANTS.items():
                if not a.variants or v in a.variants:
                    kept[v] = {str(e): compress(a.ltm, raw, e, args) for e in TARGETS}
            results[name] = kept
            with open(path, "w") as f:
                json.dump(results, f, indent=1)
    table(a.out, results)


if __name__ == "__main__":
    main()
