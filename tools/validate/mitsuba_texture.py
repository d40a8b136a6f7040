#!/usr/bin/env python3
"""Check geometry relighting (texture-space bake + `ltm render`) against Mitsuba 3.

One closed mesh stands on a ground quad. ltm bakes it in texture space
(`[texture] parameterization = "sphere"`, or "uv"), compresses the matrix
near-losslessly, relights it with every wavelet light and draws it from two
or more cameras with `ltm render`. Mitsuba 3 renders the same scene (mesh
and quad) with its `direct` integrator from the same cameras. The script
reports the relative L2 error over the mesh's pixels that lie more than
1 px from a silhouette, Mitsuba's own noise (two seeds), and the same error
for the image-space bake of each camera (`ltm bake` without `[texture]`):
the difference between the two is what the geometry image's resampling
costs.

Lighting is identical on both sides: the cubemap radiance L (6 n^2 texels,
the mean of the source map over each texel) is written back as a lat-long
map E whose every pixel holds the L of the cubemap texel its centre lies in
(2048 x 1024 by default). Mitsuba reads E through its `envmap`; ltm reads E
and averages it over each cubemap texel (which returns L but for the
pixels straddling a texel edge; the script prints that difference).

Conventions (as in mitsuba_compare.py, checked there): Mitsuba's envmap
reads direction d at u = atan2(d.x, -d.z)/2pi, v = acos(d.y)/pi, ltm's
lat-long convention; cameras are `perspective` with fov_axis "y" and
`look_at(eye, target, up)`; surfaces are `twosided(diffuse)`, the mesh flat
shaded (`face_normals`, `smooth = false` for ltm) so that both renderers
shade with the same normals.

`--mesh` is a mesh file, `bunny` (assets/meshes/bunny.ply), `limbs` (a
star-shaped closed mesh with six thin limbs, made here, not in assets/) or
`sphere` (an icosphere). `--constant` lights with a white environment of
radiance 1 and drops the ground: every unoccluded convex point then has
radiance = albedo exactly, a check of units and conventions with a known
answer.

Usage:
  cargo build --release -p ltm-tools
  pip install mitsuba numpy
  python3 tools/validate/mitsuba_texture.py --mesh bunny --out /tmp/ltm-tex
"""

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.normpath(os.path.join(HERE, "..", ".."))
sys.path.insert(0, HERE)
import mitsuba_compare as mc  # noqa: E402  (env interpolant, cubemap faces, PNG)

ALBEDO = [0.78, 0.62, 0.52]
GROUND = [0.55, 0.55, 0.52]


# ------------------------------------------------------------------ meshes

def icosphere(level):
    t = (1 + 5 ** 0.5) / 2
    v = [[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
         [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]]
    f = [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9],
         [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2],
         [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10],
         [8, 6, 7], [9, 8, 1]]
    v = [list(np.array(p) / np.linalg.norm(p)) for p in v]
    for _ in range(level):
        mid = {}
        nf = []
        for tri in f:
            m = []
            for k in range(3):
                a, b = sorted((tri[k], tri[(k + 1) % 3]))
                if (a, b) not in mid:
                    p = np.array(v[a]) + np.array(v[b])
                    v.append(list(p / np.linalg.norm(p)))
                    mid[(a, b)] = len(v) - 1
                m.append(mid[(a, b)])
            nf += [[tri[0], m[0], m[2]], [tri[1], m[1], m[0]], [tri[2], m[2], m[1]], m]
        f = nf
    return np.array(v), np.array(f)


def limbs_mesh():
    """A closed, genus-0, star-shaped body with six thin limbs of different
    lengths and thicknesses (radius r(d) = 1 + sum_k h_k exp(-(angle to
    a_k)^2 / w_k^2)), from a finely subdivided icosphere."""
    v, f = icosphere(6)
    axes = np.array([[0, 1, 0], [1, 0.3, 0], [-1, 0.2, 0.3], [0.2, -0.2, 1],
                     [-0.3, 0.1, -1], [0.6, 0.8, 0.5]], dtype=float)
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    height = [1.6, 1.2, 1.4, 0.9, 1.3, 1.0]
    width = [0.10, 0.08, 0.12, 0.09, 0.07, 0.11]
    r = np.ones(len(v))
    for a, h, w in zip(axes, height, width):
        ang = np.arccos(np.clip(v @ a, -1, 1))
        r += h * np.exp(-(ang / w) ** 2)
    return v * r[:, None] * 0.25, f


def write_obj(path, v, f):
    with open(path, "w") as out:
        for p in v:
            out.write(f"v {p[0]:.9g} {p[1]:.9g} {p[2]:.9g}\n")
        for t in f:
            out.write(f"f {t[0] + 1} {t[1] + 1} {t[2] + 1}\n")


def mesh_setup(name, out):
    """(mesh path, scale, translation, lowest model y) for the chosen mesh."""
    if name == "bunny":
        # As in assets/scenes/default.toml (its lowest point at y = 0).
        return os.path.join(ROOT, "assets/meshes/bunny.ply"), 1.1, [0.0, 0.5435, 0.0]
    if name in ("limbs", "sphere"):
        v, f = limbs_mesh() if name == "limbs" else icosphere(4)
        if name == "sphere":
            v = v * 0.5
        path = os.path.join(out, f"{name}.obj")
        write_obj(path, v, f)
        lift = -v[:, 1].min() + (0.0 if name == "limbs" else 0.05)
        return path, 1.0, [0.0, float(lift), 0.0]
    return os.path.abspath(name), 1.0, [0.0, 0.0, 0.0]


# ------------------------------------------------------------- environment

def direction_texel(d, n):
    """Cubemap texel index of unit directions d (..., 3): the inverse of
    mitsuba_compare.face_point_direction (ltm's OpenGL faces)."""
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    ax, ay, az = np.abs(x), np.abs(y), np.abs(z)
    face = np.where((ax >= ay) & (ax >= az), np.where(x > 0, 0, 1),
                    np.where(ay >= az, np.where(y > 0, 2, 3), np.where(z > 0, 4, 5)))
    sc = np.select([face == 0, face == 1, face == 2, face == 3, face == 4, face == 5],
                   [-z / ax, z / ax, x / ay, x / ay, x / az, -x / az])
    tc = np.select([face == 0, face == 1, face == 2, face == 3, face == 4, face == 5],
                   [-y / ax, -y / ax, z / ay, -z / ay, -y / az, -y / az])
    col = np.clip(((sc + 1) / 2 * n).astype(np.int64), 0, n - 1)
    row = np.clip(((tc + 1) / 2 * n).astype(np.int64), 0, n - 1)
    return (face * n + row) * n + col


def latlong_from_cubemap(light, n, height):
    """A lat-long map whose pixels hold the cubemap texel at their centre."""
    w = 2 * height
    u = (np.arange(w) + 0.5) / w
    v = (np.arange(height) + 0.5) / height
    phi, theta = np.meshgrid(2 * np.pi * u, np.pi * v, indexing="xy")
    # u = atan2(d.x, -d.z) / 2pi, v = acos(d.y) / pi.
    d = np.stack([np.sin(theta) * np.sin(phi), np.cos(theta),
                  -np.sin(theta) * np.cos(phi)], axis=-1)
    return light[direction_texel(d, n)]


def check_faces(n):
    """direction_texel inverts face_point_direction at every texel centre."""
    k = (np.arange(n) + 0.5) / n
    s, t = np.meshgrid(k, k, indexing="xy")
    ids = np.arange(6 * n * n).reshape(6, n, n)
    for face in range(6):
        if not np.array_equal(direction_texel(mc.face_point_direction(face, s, t), n), ids[face]):
            sys.exit(f"cubemap face {face}: direction_texel is not the inverse of the face map")


# ------------------------------------------------------------------- scenes

def scene_toml(mesh, scale, translation, cam, width, face_res, texel_samples, spp,
               ground, texture):
    return scene_toml_objects([dict(path=mesh, scale=scale, translation=translation)], cam,
                              width, face_res, texel_samples, spp, ground, texture)


def scene_toml_objects(objects, cam, width, face_res, texel_samples, spp, ground, texture,
                       ground_size=8.0):
    """A scene TOML of several meshes (dicts of path, scale, translation),
    all of the mesh albedo, on a ground quad of side `ground_size` (or
    none). `texture` (or None for an image-space bake): size,
    parameterization, spp and optionally mesh (an index or "all")."""
    s = f"""[camera]
eye = {list(cam['eye'])}
target = {list(cam['target'])}
fov = {cam['fov']}
width = {width}
height = {width}
spp = {spp}

[lighting]
face_res = {face_res}
texel_samples = {texel_samples}

[materials.ground]
type = "lambert"
albedo = {GROUND}

[materials.clay]
type = "lambert"
albedo = {ALBEDO}
"""
    for o in objects:
        s += f"""
[[meshes]]
path = "{o['path']}"
material = "clay"
smooth = false
scale = {o['scale']}
translation = {list(o['translation'])}
"""
    if ground:
        s += f"""
[[quads]]
center = [0.0, 0.0, 0.0]
size = [{ground_size}, {ground_size}]
material = "ground"
"""
    if texture:
        mesh = texture.get("mesh", 0)
        mesh = f'"{mesh}"' if isinstance(mesh, str) else mesh
        s += f"""
[texture]
mesh = {mesh}
size = {texture['size']}
parameterization = "{texture['parameterization']}"
spp = {texture['spp']}
"""
    return s


def mitsuba_dict(mi, mesh, scale, translation, cam, width, env, spp, ground):
    return mitsuba_dict_objects(mi, [dict(path=mesh, scale=scale, translation=translation)],
                                cam, width, env, spp, ground)


def sensor_dict(mi, cam, width, spp, sampler="independent"):
    return {"type": "perspective", "fov": cam["fov"], "fov_axis": "y",
            "to_world": mi.ScalarTransform4f().look_at(origin=cam["eye"], target=cam["target"],
                                                       up=[0, 1, 0]),
            "film": {"type": "hdrfilm", "width": width, "height": width,
                     "rfilter": {"type": "box"}, "pixel_format": "rgb"},
            "sampler": {"type": sampler, "sample_count": spp}}


def shape_dict(mi, o, albedo):
    mesh = o["path"]
    return {"type": os.path.splitext(mesh)[1][1:].lower(), "filename": mesh,
            "to_world": mi.ScalarTransform4f().translate(list(o["translation"])).scale(o["scale"]),
            "face_normals": True,
            "bsdf": {"type": "twosided", "material": {
                "type": "diffuse", "reflectance": {"type": "rgb", "value": albedo}}}}


def ground_dict(mi, size=8.0):
    return {"type": "rectangle", "bsdf": {"type": "twosided", "material": {
        "type": "diffuse", "reflectance": {"type": "rgb", "value": GROUND}}},
        "to_world": mi.ScalarTransform4f().rotate([1, 0, 0], -90).scale(
            [size / 2, size / 2, 1])}


def mitsuba_dict_objects(mi, objects, cam, width, env, spp, ground, ground_size=8.0):
    """The Mitsuba scene of scene_toml_objects: `direct` integrator, the
    lat-long map `env` as the only emitter."""
    d = {
        "type": "scene",
        "integrator": {"type": "direct", "hide_emitters": True},
        "sensor": sensor_dict(mi, cam, width, spp),
        "env": {"type": "envmap", "bitmap": mi.Bitmap(env.astype(np.float32))},
    }
    for i, o in enumerate(objects):
        d[f"mesh{i}"] = shape_dict(mi, o, ALBEDO)
    if ground:
        d["quad"] = ground_dict(mi, ground_size)
    return d


def coverage_render(mi, objects, cam, width, q=4, ground_size=None):
    """Fraction of each pixel covered by `objects` (and a ground quad of
    side ground_size, if given), from q x q stratified samples: the objects
    are black and a white sky is seen past them."""
    d = {"type": "scene",
         "integrator": {"type": "direct", "hide_emitters": False},
         "sensor": sensor_dict(mi, cam, width, q * q, sampler="stratified"),
         "env": {"type": "constant", "radiance": {"type": "rgb", "value": 1.0}}}
    for i, o in enumerate(objects):
        d[f"mesh{i}"] = shape_dict(mi, o, [0.0, 0.0, 0.0])
    if ground_size:
        d["quad"] = ground_dict(mi, ground_size)
        d["quad"]["bsdf"]["material"]["reflectance"]["value"] = [0.0, 0.0, 0.0]
    sky = np.array(mi.render(mi.load_dict(d), seed=7), dtype=np.float64)[..., 0]
    return np.clip(1.0 - sky, 0.0, 1.0)


def coverage(mi, mesh, scale, translation, cam, width, q=4):
    """Fraction of q x q sub-pixel rays through each pixel that hit the mesh."""
    sc = mi.load_dict({
        "type": "scene",
        "sensor": {"type": "perspective", "fov": cam["fov"], "fov_axis": "y",
                   "to_world": mi.ScalarTransform4f().look_at(
                       origin=cam["eye"], target=cam["target"], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": width, "height": width}},
        "mesh": {"type": os.path.splitext(mesh)[1][1:].lower(), "filename": mesh,
                 "to_world": mi.ScalarTransform4f().translate(translation).scale(scale)},
    })
    sensor = sc.sensors()[0]
    cov = np.zeros((width, width))
    for y in range(width):
        for x in range(width):
            hits = 0
            for j in range(q):
                for i in range(q):
                    p = mi.Point2f((x + (i + 0.5) / q) / width, (y + (j + 0.5) / q) / width)
                    ray, _ = sensor.sample_ray(0.0, 0.5, p, mi.Point2f(0.5, 0.5))
                    hits += bool(sc.ray_test(ray))
            cov[y, x] = hits / (q * q)
    return cov


def interior(cov):
    """Pixels wholly on the mesh whose 8 neighbours are too (> 1 px from a
    silhouette)."""
    full = cov >= 1.0
    pad = np.pad(full, 1)
    out = full.copy()
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            out &= pad[1 + dy:1 + dy + full.shape[0], 1 + dx:1 + dx + full.shape[1]]
    return out


# --------------------------------------------------------------------- main

def run(cmd):
    t0 = time.time()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return time.time() - t0


def read_exr(mi, path):
    return np.array(mi.Bitmap(path), dtype=np.float64)[..., :3]


def rel(a, b, mask):
    return float(np.linalg.norm((a - b)[mask]) / np.linalg.norm(b[mask]))


DEFAULT_CAMERAS = [
    dict(eye=[0.0, 0.9, 3.0], target=[0.0, 0.45, 0.0], fov=28.0),
    dict(eye=[2.4, 1.7, -1.6], target=[0.0, 0.45, 0.0], fov=28.0),
    dict(eye=[-2.2, 0.6, -1.9], target=[0.0, 0.45, 0.0], fov=28.0),
]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mesh", default="bunny", help="bunny, limbs, sphere or a mesh file")
    ap.add_argument("--env", default=os.path.join(ROOT, "assets/envmaps/courtyard.exr"))
    ap.add_argument("--constant", action="store_true",
                    help="white environment of radiance 1 and no ground (known answer)")
    ap.add_argument("--ltm", default=os.path.join(ROOT, "target/release/ltm"))
    ap.add_argument("--parameterization", default="sphere", choices=["sphere", "uv"])
    ap.add_argument("--size", type=int, default=256, help="texture side S")
    ap.add_argument("--texel-spp", type=int, default=16, help="bake sub-samples per texel")
    ap.add_argument("--face-res", type=int, default=32)
    ap.add_argument("--texel-samples", type=int, default=4)
    ap.add_argument("--width", type=int, default=128, help="view side in pixels")
    ap.add_argument("--cameras", type=int, default=2, help="how many of the preset cameras")
    ap.add_argument("--spp", type=int, default=4096, help="Mitsuba samples per pixel")
    ap.add_argument("--pixel-spp", type=int, default=64,
                    help="image-space bake sub-samples per pixel")
    ap.add_argument("--no-image-bake", action="store_true",
                    help="skip the image-space bakes (the resampling comparison)")
    ap.add_argument("--env-height", type=int, default=2048)
    ap.add_argument("--out", default=None)
    ap.add_argument("--limit", type=float, default=0.03)
    ap.add_argument("--variant", default="scalar_rgb")
    args = ap.parse_args()

    import mitsuba as mi
    mi.set_variant(args.variant)
    out = args.out or tempfile.mkdtemp(prefix="ltm-mitsuba-texture-")
    os.makedirs(out, exist_ok=True)
    mesh, scale, translation = mesh_setup(args.mesh, out)
    ground = not args.constant
    n = args.face_res
    check_faces(n)

    # The lighting: cubemap texels L, written back as a piecewise-constant map.
    if args.constant:
        light = np.ones((6 * n * n, 3))
    else:
        src = np.maximum(np.array(mi.Bitmap(args.env)), 0.0)[..., :3].astype(np.float64)
        light = mc.texel_radiance(src, n, 16)
    env = latlong_from_cubemap(light, n, args.env_height)
    env_path = os.path.join(out, "env.exr")
    mi.Bitmap(env.astype(np.float32)).write(env_path)
    # What Mitsuba's bilinear interpolant of E averages to over each texel.
    back = mc.texel_radiance(env, n, 8)
    env_diff = float(np.linalg.norm(back - light) / np.linalg.norm(light))

    cams = DEFAULT_CAMERAS[:args.cameras]
    texture = dict(size=args.size, parameterization=args.parameterization, spp=args.texel_spp)
    toml = scene_toml(mesh, scale, translation, cams[0], args.width, n, args.texel_samples,
                      args.pixel_spp, ground, texture)
    tex_scene = os.path.join(out, "texture.toml")
    with open(tex_scene, "w") as f:
        f.write(toml)
    tex_raw, tex_ltm = os.path.join(out, "texture.raw"), os.path.join(out, "texture.ltm")
    bake_s = run([args.ltm, "bake", tex_scene, "-o", tex_raw])
    run([args.ltm, "compress", tex_raw, "-o", tex_ltm, "--bits", "16", "--max-error", "0.001"])
    os.remove(tex_raw)

    results = []
    for c, cam in enumerate(cams):
        view = os.path.join(out, f"cam{c}_ltm_texture.exr")
        run([args.ltm, "render", tex_ltm, "--env", env_path, "--terms", "all",
             "--camera", ",".join(map(str, cam["eye"])),
             "--target", ",".join(map(str, cam["target"])),
             "--fov", str(cam["fov"]), "--size", f"{args.width}x{args.width}",
             "--supersample", "8", "-o", view])
        ours = read_exr(mi, view)
        image = None
        if not args.no_image_bake:
            img_scene = os.path.join(out, f"cam{c}.toml")
            with open(img_scene, "w") as f:
                f.write(scene_toml(mesh, scale, translation, cam, args.width, n,
                                   args.texel_samples, args.pixel_spp, ground, None))
            raw, ltm = os.path.join(out, f"cam{c}.raw"), os.path.join(out, f"cam{c}.ltm")
            run([args.ltm, "bake", img_scene, "-o", raw])
            run([args.ltm, "compress", raw, "-o", ltm, "--bits", "16", "--max-error", "0.001"])
            os.remove(raw)
            img_path = os.path.join(out, f"cam{c}_ltm_image.exr")
            run([args.ltm, "relight", ltm, "--env", env_path, "--terms", "all", "-o", img_path])
            image = read_exr(mi, img_path)
        sc = mi.load_dict(mitsuba_dict(mi, mesh, scale, translation, cam, args.width, env,
                                       args.spp, ground))
        t0 = time.time()
        ref = np.array(mi.render(sc, seed=1), dtype=np.float64)[..., :3]
        render_s = time.time() - t0
        ref2 = np.array(mi.render(sc, seed=2), dtype=np.float64)[..., :3]
        mask = interior(coverage(mi, mesh, scale, translation, cam, args.width))
        res = dict(camera=c, eye=cam["eye"], pixels=int(mask.sum()),
                   rel_l2_texture=rel(ours, ref, mask),
                   mitsuba_noise=rel(ref2, ref, mask) / math.sqrt(2),
                   mitsuba_render_s=render_s)
        # The residual with Mitsuba's noise removed (independent errors add
        # in quadrature).
        res["rel_l2_texture_noise_removed"] = math.sqrt(
            max(res["rel_l2_texture"] ** 2 - res["mitsuba_noise"] ** 2, 0.0))
        if image is not None:
            res["rel_l2_image"] = rel(image, ref, mask)
            res["rel_l2_image_noise_removed"] = math.sqrt(
                max(res["rel_l2_image"] ** 2 - res["mitsuba_noise"] ** 2, 0.0))
            res["rel_l2_texture_vs_image"] = rel(ours, image, mask)
        if args.constant:
            res["rel_l2_texture_vs_albedo"] = rel(ours, np.broadcast_to(ALBEDO, ours.shape), mask)
        results.append(res)
        print(json.dumps(res), flush=True)
        peak = np.percentile(ref[mask], 99.5) if mask.any() else 1.0
        mc.save_png(os.path.join(out, f"cam{c}_ltm_texture.png"), ours / peak)
        mc.save_png(os.path.join(out, f"cam{c}_mitsuba.png"), ref / peak)
        diff = np.abs(ours - ref).sum(-1) / peak * mask
        mc.save_png(os.path.join(out, f"cam{c}_absdiff_x10.png"),
                    np.repeat(np.clip(10 * diff, 0, 1)[..., None], 3, -1))
        np.save(os.path.join(out, f"cam{c}_mitsuba.npy"), ref.astype(np.float32))
        np.save(os.path.join(out, f"cam{c}_mask.npy"), mask)

    summary = dict(mitsuba_version=mi.__version__, variant=args.variant, spp=args.spp,
                   mesh=args.mesh, constant=args.constant, parameterization=args.parameterization,
                   size=args.size, texel_spp=args.texel_spp, face_res=n,
                   texel_samples=args.texel_samples, width=args.width,
                   env=None if args.constant else os.path.relpath(args.env, ROOT),
                   env_texel_mean_rel_diff=env_diff, texture_bake_s=bake_s, results=results)
    with open(os.path.join(out, "summary.json"), "w") as f:
        json.dump(summary, f, indent=2)
    print(f"images and summary.json in {out}")
    worst = max(r["rel_l2_texture"] for r in results)
    verdict = "PASS" if worst <= args.limit else "FAIL"
    print(f"{verdict}: worst relative L2 error {worst:.4f} (limit {args.limit})")
    return 0 if worst <= args.limit else 1


if __name__ == "__main__":
    sys.exit(main())
