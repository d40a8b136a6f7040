#!/usr/bin/env python3
"""SZ3, ZFP and SPERR, the error-bounded scientific float compressors, on a
raw transport store: the peers `ltm report --peers FILE` shows beside ltm.

For each compressor, each target relative L2 (Frobenius) error E of the
whole matrix and each layout the matrix can be given in,

  (P, M*C)         rows = pixels, one row of all lights and channels,
  (H, W, M*C)      the image grid, lights and channels innermost,
  (P, 6, n, n*C)   each row as its cubemap (channels innermost),
  (M*C, H, W)      one image per light and channel (a transposed copy),

the compressor's error parameter (SZ3: the ABS error bound; ZFP: the
fixed-accuracy tolerance; SPERR: the quantization step of its "q" mode,
which bounds the L2 error; SPERR codes 3D arrays, and the 4D layout as 3D
slices) is bisected (secant steps on log bound vs log error) until the
measured error lies in [0.97 E, E]; the smallest compressed size with an
error of at most E over all shapes is kept. The cost of relighting from
the peer is recorded too: one decompression of the kept stream, and the
dense product B = T.L per frame (numpy, median of 5 frames, L a random
positive lighting of the matrix's M columns).

Output: JSON with one point per (method, target):
  {"method": "sz3"|"zfp", "param": 0, "bytes": ..., "matrix_error": ...,
   "target": E, "shape": "(H, W, M·C)", "bound": ..., "compress_s": ...,
   "decompress_s": ..., "frame_s": ..., "tries": [...every shape's best...]}

Usage (what the committed results were made with):
  pip install pysz "zfpy==1.0.1" numcodecs-wasm-sperr numpy
  (numcodecs, which the SPERR codec imports, cannot parse zfpy's version
  "1.0.1.post0")
  python3 tools/validate/peers.py scene.raw -o peers.json --targets 0.003 0.01 0.03
  ltm report --raw scene.raw --peers peers.json -o report/
"""

import argparse
import json
import math
import struct
import sys
import time

import numpy as np

RAW_MAGIC = b"LTMRAW\x00\x01"


def open_raw(path):
    """The matrix of a raw store as (P, M, C) float32 (memory-mapped) and
    its dimensions (docs/FORMAT.md, "Raw transport store")."""
    with open(path, "rb") as f:
        hdr = f.read(64)
    if hdr[:8] != RAW_MAGIC:
        sys.exit(f"{path}: not an ltm raw store")
    w, h, n, c = struct.unpack_from("<4I", hdr, 16)
    (data_offset,) = struct.unpack_from("<Q", hdr, 40)
    p, m = w * h, 6 * n * n
    t = np.memmap(path, dtype="<f4", mode="r", offset=data_offset, shape=(p, m, c))
    return np.ascontiguousarray(t), dict(width=w, height=h, face_res=n, channels=c)


def layouts(d):
    """Per layout label: (to the layout from (P, M, C), back to (P, M, C))."""
    w, h, n, c = d["width"], d["height"], d["face_res"], d["channels"]
    p, m = w * h, 6 * n * n

    def reshaped(shape):
        return (lambda t: t.reshape(shape), lambda u: u.reshape(p, m, c))

    return {
        "(P, M·C)": reshaped((p, m * c)),
        "(H, W, M·C)": reshaped((h, w, m * c)),
        "(P, 6, n, n·C)": reshaped((p, 6, n, n * c)),
        "(M·C, H, W)": (
            lambda t: np.ascontiguousarray(t.reshape(h, w, m * c).transpose(2, 0, 1)),
            lambda u: u.transpose(1, 2, 0).reshape(p, m, c),
        ),
    }


def rel_error(t, u, norm):
    """||t - u||_F / norm in float64, in slabs."""
    acc = 0.0
    a, b = t.reshape(-1), u.reshape(-1)
    step = 1 << 24
    for i in range(0, a.size, step):
        d = a[i : i + step].astype(np.float64) - b[i : i + step]
        acc += float(np.dot(d, d))
    return math.sqrt(acc) / norm if norm > 0 else math.sqrt(acc)


class Sz3:
    name = "sz3"

    def __init__(self):
        from pysz import sz, szConfig, szErrorBoundMode

        self.sz, self.cfg, self.mode = sz, szConfig, szErrorBoundMode

    def compress(self, a, bound):
        conf = self.cfg(a.shape)
        conf.errorBoundMode = self.mode.ABS
        conf.absErrorBound = bound
        packed, _ = self.sz.compress(a, conf)
        return packed

    def decompress(self, packed, shape):
        out, _ = self.sz.decompress(packed, np.float32, shape)
        return out.reshape(shape)


class Zfp:
    name = "zfp"

    def __init__(self):
        import zfpy

        self.zfpy = zfpy

    def compress(self, a, bound):
        return self.zfpy.compress_numpy(a, tolerance=bound)

    def decompress(self, packed, shape):
        return self.zfpy.decompress_numpy(packed).reshape(shape)


class Sperr:
    name = "sperr"

    def __init__(self):
        from numcodecs_wasm_sperr import Sperr as codec

        self.codec = codec

    def compress(self, a, bound):
        return self.codec(mode="q", q=bound).encode(a)

    def decompress(self, packed, shape):
        return np.asarray(self.codec(mode="q", q=1.0).decode(packed)).reshape(shape)


def bisect(codec, t, norm, layout, target, evals):
    """The smallest stream of `codec` on `t` in `layout` (to, back) with a
    relative error of at most `target` found in `evals` codings: secant
    steps on (log bound, log error), aiming at 0.985 target, stopping once
    the error lies in [0.97 target, target]."""
    to, back = layout
    a = to(t)
    shape = a.shape
    rms = math.sqrt(float(np.dot(t.reshape(-1).astype(np.float64), t.reshape(-1))) / t.size)
    aim = math.log(0.985 * target)
    bound = max(target * rms, 1e-30)
    seen, best = [], None
    for _ in range(evals):
        t0 = time.perf_counter()
        packed = codec.compress(a, bound)
        ct = time.perf_counter() - t0
        err = rel_error(t, back(codec.decompress(packed, shape)), norm)
        seen.append((math.log(bound), math.log(max(err, 1e-30))))
        size = len(bytes(packed)) if not isinstance(packed, bytes) else len(packed)
        if err <= target and (best is None or size < best["bytes"]):
            best = dict(bytes=size, matrix_error=err, bound=bound, compress_s=ct)
        if 0.97 * target <= err <= target:
            break
        if len(seen) >= 2:
            (x0, y0), (x1, y1) = sorted(seen[-2:], key=lambda s: s[0])
            slope = (y1 - y0) / (x1 - x0) if x1 != x0 else 1.0
            slope = slope if slope > 0.05 else 1.0
        else:
            slope = 1.0
        x, y = seen[-1]
        step = max(min((aim - y) / slope, 4.0), -4.0)
        bound = math.exp(x + step)
    return best


def relight_cost(codec, t, best_packed, layout, repeats=5):
    """Seconds to decompress the kept stream (back to (P, M, C)), and the
    median seconds of a dense frame B = T.L."""
    to, back = layout
    shape = to(t).shape
    t0 = time.perf_counter()
    dense = np.ascontiguousarray(back(codec.decompress(best_packed, shape)))
    decompress_s = time.perf_counter() - t0
    p, m, c = t.shape
    rng = np.random.default_rng(1)
    light = rng.random((m, 3), dtype=np.float32)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        if c == 1:
            img = dense[:, :, 0] @ light
        else:
            img = np.einsum("pjc,jc->pc", dense, light)
        times.append(time.perf_counter() - t0)
    assert np.all(np.isfinite(img))
    return decompress_s, float(np.median(times))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("raw", help="raw transport store (ltm bake / ltm import)")
    ap.add_argument("-o", "--output", required=True, help="JSON to write")
    ap.add_argument("--targets", type=float, nargs="+", default=[0.003, 0.01, 0.03])
    ap.add_argument("--evals", type=int, default=8, help="codings per bisection")
    ap.add_argument("--methods", nargs="+", default=["sz3", "zfp", "sperr"])
    args = ap.parse_args()
    t, d = open_raw(args.raw)
    norm = math.sqrt(float(np.dot(t.reshape(-1).astype(np.float64), t.reshape(-1))))
    codecs = {"sz3": Sz3, "zfp": Zfp, "sperr": Sperr}
    points = []
    for name in args.methods:
        codec = codecs[name]()
        for target in args.targets:
            tries = []
            for label, layout in layouts(d).items():
                try:
                    best = bisect(codec, t, norm, layout, target, args.evals)
                except RuntimeError as e:
                    # zfpy's header cannot hold some 4D shapes (a side
                    # above its field width): that shape is skipped.
                    print(f"{name} {target} {label}: refused ({e})", file=sys.stderr)
                    continue
                if best is not None:
                    tries.append(dict(best, shape=label))
                print(f"{name} {target} {label}: {best}", file=sys.stderr)
            if not tries:
                continue
            kept = min(tries, key=lambda b: b["bytes"])
            layout = layouts(d)[kept["shape"]]
            packed = codec.compress(layout[0](t), kept["bound"])
            dec_s, frame_s = relight_cost(codec, t, packed, layout)
            points.append(
                dict(
                    method=name,
                    param=0,
                    bytes=kept["bytes"],
                    matrix_error=kept["matrix_error"],
                    target=target,
                    shape=kept["shape"],
                    bound=kept["bound"],
                    compress_s=kept["compress_s"],
                    decompress_s=dec_s,
                    frame_s=frame_s,
                    tries=tries,
                )
            )
    out = dict(
        source=args.raw,
        dims=d,
        raw_bytes=int(t.nbytes),
        tools={
            "pysz": version("pysz"),
            "zfpy": version("zfpy"),
            "numcodecs-wasm-sperr": version("numcodecs-wasm-sperr"),
            "numpy": np.__version__,
        },
        points=points,
    )
    with open(args.output + ".tmp", "w") as f:
        json.dump(out, f, indent=1)
    import os

    os.replace(args.output + ".tmp", args.output)


def version(pkg):
    try:
        from importlib.metadata import version as v

        return v(pkg)
    except Exception:
        return None


if __name__ == "__main__":
    main()
