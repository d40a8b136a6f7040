#!/usr/bin/env python3
"""Writes an analytic light-transport matrix for `ltm import`: a diffuse
sphere resting on a diffuse ground plane, seen from above at an angle,
shadowed by exact ray-sphere tests, in the conventions of docs/FORMAT.md
(texel-centre directions, exact texel solid angles).

    python3 tools/validate/sphere_matrix.py OUT.npy --width 96 --height 64 --face-res 16
    ltm import OUT.npy --width 96 --height 64 -o sphere.raw

It is independent of ltm's own renderer and serves as a second test matrix.
Needs numpy only.
"""
import argparse
import numpy as np


def face_dirs(n):
    """Unit texel-centre directions and solid angles, column order of FORMAT.md."""
    s = (np.arange(n) + 0.5) / n
    sc, tc = np.meshgrid(2 * s - 1, 2 * s - 1)  # tc varies by row, sc by column
    one = np.ones_like(sc)
    faces = [
        (one, -tc, -sc), (-one, -tc, sc), (sc, one, tc),
        (sc, -one, -tc), (sc, -tc, one), (-sc, -tc, -one),
    ]
    d = np.concatenate([np.stack(f, -1).reshape(-1, 3) for f in faces])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    e = np.arange(n + 1) / n * 2 - 1
    F = lambda a, b: np.arctan2(a * b, np.sqrt(a * a + b * b + 1))
    a0, a1 = np.meshgrid(e[:-1], e[1:])[0], np.meshgrid(e[1:], e[1:])[0]
    b0, b1 = np.meshgrid(e[:-1], e[:-1])[1], np.meshgrid(e[1:], e[1:])[1]
    omega = (F(a1, b1) - F(a0, b1) - F(a1, b0) + F(a0, b0)).reshape(-1)
    return d, np.tile(omega, 6)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out")
    ap.add_argument("--width", type=int, default=96)
    ap.add_argument("--height", type=int, default=64)
    ap.add_argument("--face-res", type=int, default=16)
    a = ap.parse_args()
    W, H, n = a.width, a.height, a.face_res
    dirs, omega = face_dirs(n)
    centre, radius = np.array([0.0, 1.0, 0.0]), 1.0
    # Camera: orthographic, looking down and forward.
    fwd = np.array([0.0, -0.8, -0.6]); fwd /= np.linalg.norm(fwd)
    right = np.array([1.0, 0.0, 0.0]); up = np.cross(right, fwd)
    xs = (np.arange(W) + 0.5) / W * 2 - 1
    ys = (np.arange(H) + 0.5) / H * 2 - 1
    X, Y = np.meshgrid(xs * 3.0 * W / H, -ys * 3.0)
    origin = np.array([0.0, 1.0, 0.0]) - 6 * fwd + X[..., None] * right + Y[..., None] * up
    o = origin.reshape(-1, 3)

    def hit_sphere(o, d):
        oc = o - centre
        b = np.sum(oc * d, -1)
        c = np.sum(oc * oc, -1) - radius ** 2
        disc = b * b - c
        t = -b - np.sqrt(np.maximum(disc, 0))
        return np.where((disc > 0) & (t > 1e-4), t, np.inf)

    t_s = hit_sphere(o, np.broadcast_to(fwd, o.shape))
    t_p = np.where(fwd[1] < 0, -o[:, 1] / fwd[1], np.inf)
    t_p = np.where(np.abs(o[:, 0] + t_p * fwd[0]) < 4, t_p, np.inf)
    t = np.minimum(t_s, t_p)
    hit = np.isfinite(t)
    x = o + t[:, None] * fwd
    normal = np.where((t_s <= t_p)[:, None], (x - centre) / radius, np.array([0.0, 1.0, 0.0]))
    albedo = np.where(t_s <= t_p, 0.7, 0.5)
    T = np.zeros((W * H, len(dirs)), np.float32)
    for p in np.nonzero(hit)[0]:
        cos = dirs @ normal[p]
        vis = ~np.isfinite(hit_sphere(np.broadcast_to(x[p] + 1e-4 * normal[p], dirs.shape), dirs))
        T[p] = albedo[p] / np.pi * np.maximum(cos, 0) * vis * omega
    np.save(a.out, T)
    print(f"wrote {a.out}: shape {T.shape}, {hit.sum()} lit pixels, sum {T.sum():.4f}")


if __name__ == "__main__":
    main()
